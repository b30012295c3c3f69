"""A structure's statics at a point: LICQ at the scale of a structure.

The active constraints (taut links, touching nodes) carry the forces ``t >= 0`` (tensions, contact
forces) that balance the load at the free nodes: ``J^T t = F``, J the active rows in force units (a
taut link's row holds its unit vector u at its first node and -u at its second; a contact's the
unit outward normal). LICQ holds when J has full row rank: the forces are then unique. Where it
fails the structure is *statically indeterminate*: the forces form a set of dimension
``m - rank(J)`` (the degree of indeterminacy), and each vector of the left null space of J is a
*self-stress*, forces in equilibrium with each other and no load, that can be added to any
solution as long as the forces stay >= 0. The range of every force over that set comes from two
linear programs per direction of the self-stresses. MFCQ fails where a self-stress is a pure
tension (every force >= 0): adding it without bound keeps every force >= 0, so the forces are
unbounded. The check (:func:`funicular.checks.check`) reports the same findings; here they come
without a second-order test and with the cheap proof of independence first (the ``licq`` block of
a net's result file).
"""

from __future__ import annotations

import numpy as np

from funicular import _core
from funicular.checks import _tolerances
from funicular.checks._active import _active, _contact_distances, _evaluate, _point_of
from funicular.checks._jacobian import _jacobian, _Rows, elastic_rows
from funicular.checks._report import Statics
from funicular.checks._tolerances import CERTIFY, DEFAULT_TOL, MAX_BAND, RANGES_UP_TO
from funicular.model import FloatArray, IntArray, Problem
from funicular.solution import Solution

# The rest of the checker, and SciPy's optimize it loads, is imported where it is used: the proof
# of unique forces (proven_determinate) needs none of it.


def statics(problem: Problem, positions: FloatArray, tol: float = DEFAULT_TOL) -> Statics:
    """The statics of ``problem`` at ``positions`` (see the module documentation): the forces
    recovered from the positions (the least total force that balances the load) and their ranges
    where they balance it. The point need not be feasible: its taut links and touching nodes are
    the active constraints."""
    from funicular.checks._check import (
        _active_rows,
        _check_tol,
        _positions,
        free_load,
        recovered_forces,
        stiffness_decides,
    )
    from funicular.checks._licq import _licq, _mfcq
    from funicular.checks._multipliers import _ranges

    positions = _positions(problem, positions)
    _check_tol(tol)
    point = _evaluate(problem, positions)
    length_tol = tol * float(problem.link_lengths.max())
    linear = _active_rows(problem, point, _contact_distances(problem, point), length_tol)
    names = linear.active.names(problem)
    licq, null = _licq(problem, point, linear.active, linear.rows, exact=False)
    if null is None:
        return Statics(tuple(names), None, (), None)
    ranges = None
    if len(names) <= RANGES_UP_TO:
        load, rows = free_load(problem), linear.rows.sparse()
        forces = recovered_forces(problem, point, linear.active, linear.rows, null, tol)
        if np.abs(rows.T @ forces - load).max(initial=0.0) <= tol * problem.force_scale:  # (else no equilibrium)
            ranges = _ranges(forces, null, problem.force_scale)
    decides = stiffness_decides(null, elastic_rows(problem, linear.active))
    return Statics.found(names, licq, ranges, _mfcq(null), decides)


def statics_of(solution: Solution, tol: float = DEFAULT_TOL) -> Statics:
    """:func:`statics` at a solver's result."""
    return statics(solution.problem, solution.positions, tol)


def proven_determinate(solution: Solution, tol: float = DEFAULT_TOL) -> bool:
    """Whether a solver's result is proven statically determinate (its forces unique) by the sparse
    proof alone: one Cholesky factorization, cheap at any size; False means not proven."""
    problem = solution.problem
    point = _point_of(solution)
    length_tol = tol * float(problem.link_lengths.max())
    return _independent(
        _jacobian(problem, point, _active(problem, point, _contact_distances(problem, point), length_tol))
    )


def _independent(rows: _Rows) -> bool:
    """A cheap proof that no singular value of the rows is ``<= RANK_TOL``: a Cholesky
    factorization of ``A A^T - CERTIFY I`` exists, so ``sigma_min^2 > CERTIFY`` (up to its rounding
    error: ~1e-15 for a chain's banded rows, far below CERTIFY = (100 RANK_TOL)^2; a net's sparse
    factorization lowers the diagonal by a bound on its own). False means "not proven" (compute)."""
    if rows.m == 0:
        return True
    if rows.n <= _tolerances.DENSE_LIMIT:
        dense = rows.dense()
        try:
            np.linalg.cholesky(dense @ dense.T - CERTIFY * np.eye(rows.m))
        except np.linalg.LinAlgError:
            return False
        return True
    return proven_independent(rows.nodes, rows.vectors)


def proven_independent(nodes: IntArray, vectors: FloatArray) -> bool:
    """:func:`_independent` of rows of ``+vectors[r]`` (m, d) at free node ``nodes[r, 0]`` and
    ``-vectors[r]`` at ``nodes[r, 1]`` (-1: none), factored by the solver core: band by band in the
    order of their first nodes where that is banded (a chain's rows: O(m) time, the band's entries
    computed as it goes, no matrix in memory), by a sparse Cholesky factorization otherwise (a net's)."""
    nodes, vectors = np.ascontiguousarray(nodes, dtype=np.int64), np.ascontiguousarray(vectors, dtype=np.float64)
    return _core.gram_positive_definite(nodes, vectors, -CERTIFY, MAX_BAND)
