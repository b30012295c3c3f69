"""LICQ (the rank of the active rows, their dependent combinations: a structure's self-stress
states) and MFCQ."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.linalg import lapack
from scipy.optimize import linprog

from funicular.checks import _tolerances
from funicular.checks._active import _Point
from funicular.checks._jacobian import _factor, _Rows
from funicular.checks._multipliers import _directions
from funicular.checks._report import LICQ, MFCQ, ActiveSet, Dependency
from funicular.checks._statics import _independent
from funicular.checks._tolerances import (
    CERTIFY,
    DENSE_ENTRIES,
    LP_SECONDS,
    NULL_BLOCK,
    RANK_TOL,
    SELF_STRESS_SOUGHT,
    SHIFT,
    ZERO_WEIGHT,
)
from funicular.model import FloatArray, IntArray, Problem

if TYPE_CHECKING:
    from funicular.checks._tolerances import Matrix


# ----------------------------------------------------------------- LICQ
def shifted_gram(matrix: Matrix, shift: float) -> Matrix:
    """``A A^T + shift I`` of sparse rows A."""
    return sparse.csr_matrix(matrix @ matrix.T + shift * sparse.identity(matrix.shape[0], format="csr"))


def _gram(rows: _Rows, shift: float) -> tuple[IntArray, IntArray, FloatArray]:
    """Row, column and value of every entry of ``A A^T + shift I`` (each position once)."""
    gram = shifted_gram(rows.sparse(), shift).tocoo()
    return gram.row.astype(np.intp), gram.col.astype(np.intp), np.asarray(gram.data, dtype=np.float64)


def _left_null_space(rows: _Rows) -> tuple[float, FloatArray] | None:
    """Smallest singular value of the rows and an orthonormal basis (m, r) of their dependencies;
    None where that is not decided (more than SELF_STRESS_SOUGHT dependencies found by the sparse
    search, or its failure, and too many entries for the dense SVD)."""
    m, n = rows.m, rows.n
    if m == 0:
        return math.inf, np.zeros((0, 0))
    if n == 0:
        return 0.0, np.eye(m)
    if n <= _tolerances.DENSE_LIMIT or m <= NULL_BLOCK + 1:
        return _dense_null_space(rows.dense())
    try:
        found = lanczos_null_space(rows.sparse(), _factor(rows.anchors(), *_gram(rows, SHIFT)), SELF_STRESS_SOUGHT)
    except (np.linalg.LinAlgError, sparse_linalg.ArpackNoConvergence, sparse_linalg.ArpackError):
        found = None  # (an exactly singular factorization or no convergence: the dense SVD or nothing)
    if found is None and m * n <= DENSE_ENTRIES:
        return _dense_null_space(rows.dense())
    return found


def _dense_null_space(rows: FloatArray) -> tuple[float, FloatArray]:
    """Smallest singular value of dense rows (m, n) and an orthonormal basis (m, r) of their
    dependencies, by their SVD."""
    m, n = rows.shape
    u, s, _ = np.linalg.svd(rows, full_matrices=m > n)  # u is (m, m) either way
    s = np.concatenate([s, np.zeros(max(m - n, 0))])
    return float(s.min(initial=math.inf)), u[:, s <= RANK_TOL]


def lanczos_null_space(
    matrix: Matrix, solve: Callable[[FloatArray], FloatArray], most: int | None = None
) -> tuple[float, FloatArray] | None:
    """Smallest singular value of sparse rows A (m, n) and an orthonormal basis (m, r) of their
    dependencies, from the largest eigenvalues of ``(A A^T + SHIFT I)^-1`` (``solve``; shift-invert
    Lanczos), NULL_BLOCK at a time and twice as many while all found are dependent (a few rows:
    their SVD). None where there are more than ``most`` (not sought further)."""
    m = matrix.shape[0]
    if m <= NULL_BLOCK + 1:
        found = _dense_null_space(matrix.toarray())
        return None if most is not None and found[1].shape[1] > most else found
    inverse = sparse_linalg.LinearOperator((m, m), matvec=solve, dtype=np.float64)
    k = NULL_BLOCK
    while True:
        _, vectors = sparse_linalg.eigsh(inverse, k=k, which="LA")
        _, s, vt = np.linalg.svd(matrix.T @ vectors, full_matrices=False)  # refine: A^T W = U S V^T
        vectors = vectors @ vt.T
        dependent = s <= RANK_TOL
        if not dependent.all() or k >= m - 1:
            return float(s.min()), vectors[:, dependent]
        if most is not None and k > most:
            return None
        k = min(2 * k, m - 1) if most is None else min(2 * k, m - 1, most + 1)


def _null(rows: _Rows) -> FloatArray | None:
    """A basis (m, r) of the rows' dependencies, without computing any when they are provably none;
    None where they are not decided."""
    if _independent(rows):
        return np.zeros((rows.m, 0))
    found = _left_null_space(rows)
    return None if found is None else found[1]


def _independent_triangle(r: FloatArray) -> bool:
    """Whether the rows of A, with ``A^T = Q R``, are provably independent: ``sigma_min(R) >=
    1 / ||R^-1||_F`` exceeds ``sqrt(CERTIFY)``."""
    # dtrtri reads and writes the upper triangle; below it stay the Householder vectors of geqrf
    # (entries <= 1), which only make the norm, and so the proof, more cautious (by <= m / sqrt(2)
    # against a limit of 1 / (100 RANK_TOL) = 1e6).
    inverse, info = lapack.dtrtri(r)
    return bool(info == 0 and float(np.linalg.norm(inverse)) * math.sqrt(CERTIFY) < 1.0)


def _dependent_rows(null: FloatArray) -> IntArray:
    """Rows whose removal leaves independent rows: one pivot per null vector (pivoted QR)."""
    if null.shape[1] == 0:
        return np.zeros(0, dtype=np.intp)
    _, _, pivots = scipy.linalg.qr(null.T, mode="economic", pivoting=True)
    return np.sort(pivots[: null.shape[1]])


def _one_per_pivot(null: FloatArray) -> FloatArray:
    """The basis of the same dependencies that is 1 on its own pivot row and 0 on the others':
    each involves as few constraints as the pivots allow."""
    pivots = _dependent_rows(null)
    if not pivots.size:
        return null
    return np.asarray(np.linalg.solve(null[pivots].T, null.T).T, dtype=np.float64)


def _describe(problem: Problem, point: _Point, active: ActiveSet, names: list[str], vector: FloatArray) -> Dependency:
    """A null vector in words: which forces, and how the supports' reactions change."""
    vector = vector / vector[int(np.argmax(np.abs(vector)))]
    involved = np.flatnonzero(np.abs(vector) > ZERO_WEIGHT)
    shares = {names[c]: float(vector[c]) for c in involved}
    # Extra tension w in link k (nodes a, b) pulls a by -w u_k and b by +w u_k (u_k the unit vector
    # from b to a); a support balances it. A link of zero length (a detached massless end resting
    # on its neighbour) carries no force and is never active.
    links = involved[involved < active.links.size]
    ends = problem.link_nodes[active.links[links]]
    unit = point.delta[active.links[links]] / np.maximum(point.distances[active.links[links]], 1e-300)[:, None]
    reaction: dict[int, FloatArray] = {}
    for end, sign in ((0, 1.0), (1, -1.0)):
        at_support = problem.is_support[ends[:, end]]
        forces = sign * vector[links[at_support], None] * unit[at_support]
        for node, force in zip(ends[at_support, end], forces, strict=True):
            reaction[int(node)] = reaction.get(int(node), np.zeros(problem.dimension)) + force
    supports = {node: tuple(float(c) for c in f) for node, f in sorted(reaction.items())}
    if len(shares) <= 4:
        text = ", ".join(f"{name} ({share:+.3g})" for name, share in shares.items())
    else:
        first, *_, last = shares
        text = f"{len(shares)} forces from {first} to {last} (shares {min(shares.values()):+.3g} to +1)"
    if supports:
        changes = ", ".join(f"({', '.join(f'{c:+.3g}' for c in f)}) at node {node}" for node, f in supports.items())
        text += f" and the supports at nodes {', '.join(map(str, supports))} (reactions change by {changes})"
    text += " can carry any multiple of these forces in equilibrium with each other: the multipliers are not unique."
    return Dependency(shares, supports, text)


def _licq(
    problem: Problem, point: _Point, active: ActiveSet, rows: _Rows, exact: bool = True
) -> tuple[LICQ, FloatArray | None]:
    """LICQ of the active rows, and their dependencies as a basis (m, r) with one pivot row each
    (None where not decided). ``exact``: the smallest singular value is computed; otherwise the
    cheap proof of independence comes first, and where it succeeds ``sigma_min`` is nan."""
    m = rows.m
    if not exact and _independent(rows):
        return LICQ(True, m, m, math.nan, ()), np.zeros((m, 0))
    found = _left_null_space(rows)
    if found is None:
        return LICQ(None, None, m, math.nan, ()), None
    sigma_min, null = found
    null = _one_per_pivot(null)
    names = active.names(problem) if null.shape[1] else []
    dependencies = tuple(_describe(problem, point, active, names, null[:, j]) for j in range(null.shape[1]))
    return LICQ(null.shape[1] == 0, m - null.shape[1], m, sigma_min, dependencies), null


# ----------------------------------------------------------------- MFCQ
def _mfcq(null: FloatArray | None) -> MFCQ | None:
    """Gordan: MFCQ fails iff some ``w = W c >= 0`` with ``sum(w) = 1`` (a vanishing nonnegative
    combination: a pure tension self-stress). None where not decided (the dependencies are not
    known, or the linear program takes more than LP_SECONDS)."""
    if null is None:
        return None
    if null.shape[1] == 0:
        return MFCQ(True, "implied by LICQ")
    units = _directions(null, np.zeros(null.shape[0])).units
    result = linprog(
        np.zeros(null.shape[1]),
        A_ub=-units,
        b_ub=np.zeros(units.shape[0]),
        A_eq=null.sum(axis=0)[None, :],
        b_eq=[1.0],
        bounds=(None, None),
        method="highs",
        options={"time_limit": LP_SECONDS},
    )
    if result.status == 0:
        return MFCQ(
            False,
            "a nonnegative combination of the active constraint gradients vanishes (a pure tension "
            "self-stress), so no direction decreases every active constraint and the forces are unbounded",
        )
    if result.status != 2:  # (1: out of time, 4: numerical trouble)
        return None
    return MFCQ(True, "the dependent combinations mix signs: some direction decreases every active constraint")
