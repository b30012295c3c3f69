"""The second-order conditions: the curvature of the Lagrangian on the critical cone, and a cheap
proof of a strict minimum."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from numpy.typing import NDArray
from scipy.linalg import lapack

from funicular._constraints import link_hessian_blocks
from funicular._core import blocks_positive_definite, penalty_and_shift, zero_curvature
from funicular._solver.banded import BlockTridiagonal, LinearSolver
from funicular.checks import _tolerances
from funicular.checks._active import _Point
from funicular.checks._jacobian import _banded_lu, _Hessian, _Rows
from funicular.checks._licq import _dependent_rows, _independent_triangle, _null, shifted_gram
from funicular.checks._report import Multipliers, SecondOrder
from funicular.checks._statics import _Active as StaticsActive
from funicular.checks._statics import _free_columns, free_index
from funicular.checks._statics import _Rows as StaticsRows
from funicular.checks._tolerances import LANCZOS_VECTORS, SHIFT, Matrix
from funicular.model import FloatArray, IntArray, Problem


# ----------------------------------------------------------------- second order
def _min_curvature(
    hessian: _Hessian, rows: _Rows, null: FloatArray, threshold: float
) -> tuple[float, FloatArray | None]:
    """Smallest eigenvalue of ``H`` on the null space of the rows (inf if that space is {0}), and
    its eigenvector (in that null space)."""
    if null.shape[1]:
        rows = rows.take(np.setdiff1d(np.arange(rows.m), _dependent_rows(null)))
    m, n = rows.m, rows.n
    if m >= n:
        return math.inf, None
    if n <= _tolerances.DENSE_LIMIT:
        # The kept rows are independent, so the last n - m columns of a complete QR of their
        # transpose span the null space (a QR costs a fraction of an SVD).
        basis = scipy.linalg.qr(rows.dense().T, mode="full", check_finite=False)[0][:, m:] if m else np.eye(n)
        reduced = basis.T @ hessian.dense() @ basis
        values, vectors = scipy.linalg.eigh(reduced, subset_by_index=(0, 0), check_finite=False)
        return float(values[0]), basis @ vectors[:, 0]
    # The bordered matrix [[H - s I, A^T], [A, 0]] with each row next to its first node: banded.
    shift = hessian.bound() - threshold
    h_rows, h_cols, h_values = hessian.entries()
    a_rows, a_cols, a_values = rows.entries()
    key = np.concatenate([np.arange(n) // 2 * 2, 2 * rows.anchors() + 1])
    try:
        solve = _banded_lu(
            key,
            np.concatenate([h_rows, n + a_rows, a_cols]),
            np.concatenate([h_cols, a_cols, n + a_rows]),
            np.concatenate([h_values - shift * (h_rows == h_cols), a_values, a_values]),
        )
    except np.linalg.LinAlgError:  # exactly singular: the shift hit an eigenvalue (or the scales underflow)
        return math.nan, None

    def apply(vector: FloatArray) -> FloatArray:
        return solve(np.concatenate([vector, np.zeros(m)]))[:n]

    operator = sparse_linalg.LinearOperator((n, n), matvec=apply, dtype=np.float64)
    try:
        # A fixed start (the same problem, the same direction) and a short basis: the wanted
        # eigenvalue is well separated after the shift-invert (10-15 solves instead of 20-odd).
        start = np.random.default_rng(0).standard_normal(n)
        theta, vectors = sparse_linalg.eigsh(operator, k=1, which="LA", tol=1e-10, ncv=LANCZOS_VECTORS, v0=start)
    except sparse_linalg.ArpackNoConvergence:
        return math.nan, None
    # The operator's range lies in the null space of the rows, so a converged eigenvector (residual
    # below 1e-10 theta) is in it but for a part below 1e-10: no further solve to project it.
    direction = vectors[:, 0]
    return float(shift + 1.0 / theta[0]), direction / max(float(np.linalg.norm(direction)), 1e-300)


# The smallest eigenvalue of H on the null space of the first k rows (inf if that space is {0}),
# and its eigenvector.
Curvature = Callable[[int], tuple[float, FloatArray | None]]


def _dense_curvature(hessian: _Hessian, rows: _Rows, first: int) -> Curvature | None:
    """For a small problem whose rows are provably independent: with ``A^T = Q R`` (Householder),
    the columns of Q from k on span the null space of the first k rows, for every k >= ``first``,
    so the strictly active rows and all rows share one QR (whose R proves the independence). Only
    those columns of Q are formed. None if independence is not proven: the rows then go the
    general way (an SVD for their dependencies)."""
    m, n = rows.m, rows.n
    if m > n:
        return None
    basis: FloatArray = np.eye(n)[:, first:]
    if m:
        factors, tau, _, _ = lapack.dgeqrf(rows.dense().T)
        if not _independent_triangle(factors[:m]):
            return None
        if basis.shape[1]:
            basis, _, _ = lapack.dormqr("L", "N", factors, tau, basis, 64 * basis.shape[1])
    reduced = basis.T @ hessian.times(basis)

    def curvature(k: int) -> tuple[float, FloatArray | None]:
        if k >= n:
            return math.inf, None
        j = k - first
        values, vectors, _, _, info = lapack.dsyevr(reduced[j:, j:], range="I", il=1, iu=1)  # the smallest only
        if info:
            raise np.linalg.LinAlgError(f"dsyevr: no convergence ({info})")
        return float(values[0]), basis[:, j:] @ vectors[:, 0]

    return curvature


def _general_curvature(hessian: _Hessian, rows: _Rows, null: FloatArray, threshold: float) -> Curvature:
    """Through the dependencies of the first k rows (``null`` those of all rows), dropped before a
    dense QR or the banded bordered matrix (:func:`_min_curvature`)."""

    def curvature(k: int) -> tuple[float, FloatArray | None]:
        if k == rows.m:
            return _min_curvature(hessian, rows, null, threshold)
        first = rows.take(np.arange(k))
        # Some of a set of independent rows are independent (their singular values interlace).
        return _min_curvature(hessian, first, np.zeros((k, 0)) if null.shape[1] == 0 else _null(first), threshold)

    return curvature


def _zero_curvature(problem: Problem, tol: float) -> float:
    """The curvature below which an eigenvalue counts as zero (module doc, Second order)."""
    return zero_curvature(tol, problem.weight, problem.n_nodes, problem.total_length)


def _second_order(
    problem: Problem,
    point: _Point,
    hessian: _Hessian,
    rows: _Rows,
    forces: FloatArray,
    null: FloatArray | None,
    tol: float,
) -> SecondOrder:
    """The verdict; ``null`` is the rows' dependencies if known (None: found here, only if needed)."""
    force_tol = tol * problem.weight
    if forces.min(initial=0.0) < -force_tol:
        return SecondOrder("undecided", math.nan, "some multipliers are negative (not dual feasible)")
    threshold = _zero_curvature(problem, tol)
    strict = forces > force_tol
    # The strictly active rows first: the critical cone's equalities are the first `count` rows.
    order = np.argsort(~strict, kind="stable")
    rows, count = rows.take(order), int(np.count_nonzero(strict))
    curvature_on = None
    if rows.n <= _tolerances.DENSE_LIMIT and (null is None or null.shape[1] == 0):
        curvature_on = _dense_curvature(hessian, rows, count)
    licq_holds = curvature_on is not None
    if curvature_on is None:
        null = _null(rows) if null is None else null[order]
        licq_holds = null.shape[1] == 0
        curvature_on = _general_curvature(hessian, rows, null, threshold)
    curvature, direction = curvature_on(count)
    if math.isnan(curvature):
        return SecondOrder("undecided", curvature, "the eigenvalue solver did not converge")
    if curvature > threshold:
        return SecondOrder(
            "strict local minimum",
            curvature,
            f"the Hessian of the Lagrangian is positive definite on the null space of the {strict.sum()} "
            "strictly active constraints (second-order sufficient condition)",
        )
    weak = rows.m - count
    if weak:
        curvature, direction = curvature_on(rows.m)
    if curvature < -threshold and licq_holds:
        moves = np.zeros((problem.n_nodes, 2))
        if direction is not None:
            moves[point.free] = direction.reshape(-1, 2)
        return SecondOrder(
            "not a minimum",
            curvature,
            "negative curvature along a direction that keeps every active constraint active "
            "(the second-order necessary condition fails)",
            moves if direction is not None else None,
        )
    if curvature < -threshold:
        reason = "negative curvature for these multipliers, but the multipliers are not unique (LICQ fails)"
    elif weak:
        reason = f"zero curvature, or the answer depends on the {weak} weakly active constraints"
    else:
        reason = "zero curvature on the critical cone: higher-order terms decide"
    return SecondOrder("undecided", curvature, reason)


# ----------------------------------------------------------------- a cheap proof of a strict minimum
def _penalized(hessian: _Hessian, rows: _Rows, weights: FloatArray, shift: float) -> BlockTridiagonal:
    """``H - shift I + A^T diag(weights) A`` as 2x2 blocks. A row is a contact's unit normal n at one
    free node, or a link's +u and -u at its two nodes (either may be a support): it adds ``w n n^T``
    or ``w u u^T`` to each of its free nodes, and a link between free nodes c and c + 1 adds
    ``-w u u^T`` to their coupling, so ``A^T A`` is block tridiagonal like H."""
    vectors = rows.vectors
    outer = weights[:, None, None] * vectors[:, :, None] * vectors[:, None, :]
    node = rows.nodes.T.ravel()  # every row's first node, then every row's second
    touched = (node >= 0).nonzero()[0]
    diagonal = hessian.diagonal.copy()
    diagonal[:, (0, 1), (0, 1)] -= shift
    np.add.at(diagonal, node[touched], outer[touched % rows.m])
    link = ((rows.nodes[:, 0] >= 0) & (rows.nodes[:, 1] >= 0)).nonzero()[0]
    coupling = hessian.coupling.copy()
    coupling[rows.nodes[link, 0]] -= outer[link]  # one link per pair of neighbours: no repeats
    return BlockTridiagonal(diagonal, coupling)


def _proves_minimum(
    problem: Problem, hessian: _Hessian, rows: _Rows, forces: FloatArray, tol: float, linear_solver: LinearSolver
) -> bool:
    """True only where :func:`_second_order` says "strict local minimum", in O(N) and without its
    curvature: ``H + rho A^T A - s I`` (A the strictly active rows) is positive definite, so
    ``z^T H z > s |z|^2`` for every z with ``A z = 0``, and s covers the zero-curvature threshold
    and the factorization's rounding. False: not proven here (a rho too small, a curvature near
    the threshold, or not a minimum)."""
    weight = problem.weight
    if forces.min(initial=0.0) < -tol * weight:
        return False  # not dual feasible: "undecided"
    if rows.n == 0:
        return True  # nothing can move
    stiffest = float(np.abs(hessian.diagonal).max(initial=0.0))
    threshold = _zero_curvature(problem, tol)
    rho, shift = penalty_and_shift(
        stiffest, weight / problem.total_length, 2, len(problem.obstacles), threshold, _tolerances.PENALTY
    )
    matrix = _penalized(hessian, rows, np.where(forces > tol * weight, rho, 0.0), shift)
    try:
        linear_solver(matrix)
    except np.linalg.LinAlgError:
        return False
    return True


# ----------------------------------------------------------------- a net or a chain in space
CURVATURE_UP_TO = 1500  # free coordinates up to which a net's curvature is computed (dense, O(n^3))
_NOT_A_MINIMUM = (
    "not a minimum: the energy curves down ({curvature:.6g}) along a direction that keeps every "
    "active constraint active"
)


@dataclass(frozen=True)
class _Blocks:
    """A symmetric matrix over the free coordinates by d x d blocks: ``node`` (f, d, d) on the
    diagonal and ``pair`` (p, d, d) at free nodes ``pairs`` (p, 2), mirrored (repeats add up)."""

    node: FloatArray
    pairs: IntArray
    pair: FloatArray

    def plus(self, other: _Blocks) -> _Blocks:
        return _Blocks(self.node + other.node, np.vstack([self.pairs, other.pairs]), np.vstack([self.pair, other.pair]))

    def dense(self) -> FloatArray:
        dense: FloatArray = self.sparse().toarray()
        return dense

    def sparse(self) -> Matrix:
        f, d = self.node.shape[:2]
        i, k = np.arange(d)[:, None], np.arange(d)[None, :]
        a, b = self.pairs[:, 0, None, None], self.pairs[:, 1, None, None]
        nodes = np.arange(f)[:, None, None]
        rows = [nodes * d + i + 0 * k, a * d + i + 0 * k, b * d + k + 0 * i]
        cols = [nodes * d + k + 0 * i, b * d + k + 0 * i, a * d + i + 0 * k]
        values = [self.node, self.pair, self.pair]
        coo = sparse.coo_matrix(
            (
                np.concatenate([v.ravel() for v in values]),
                (np.concatenate([r.ravel() for r in rows]), np.concatenate([c.ravel() for c in cols])),
            ),
            shape=(f * d, f * d),
        )
        return Matrix(coo)  # (repeated entries add up)

    def positive_definite(self, shift: float) -> bool:
        """Whether the matrix plus ``shift`` I is positive definite: one sparse Cholesky
        factorization in the solver core."""
        return blocks_positive_definite(
            np.ascontiguousarray(self.node),
            np.ascontiguousarray(self.pairs, dtype=np.int64),
            np.ascontiguousarray(self.pair),
            shift,
        )


def _pair_terms(problem: Problem, first: IntArray, second: IntArray, blocks: FloatArray) -> _Blocks:
    """``[[B, -B], [-B, B]]`` of each block B on its nodes ``first`` and ``second`` (-1 or a support:
    that end dropped), over the free nodes."""
    d = problem.dimension
    column = free_index(problem)
    a, b = column[first], column[second]
    node = np.zeros((problem.free_nodes.size, d, d))
    for end in (a, b):
        kept = end >= 0
        np.add.at(node, end[kept], blocks[kept])
    both = (a >= 0) & (b >= 0)
    return _Blocks(node, np.column_stack([a[both], b[both]]), -blocks[both])


def _structure_hessian(problem: Problem, active: StaticsActive, multipliers: Multipliers) -> _Blocks:
    """The Hessian of the Lagrangian of a net or a chain in space over the free coordinates, by
    blocks (the energy is linear: only the link and contact terms curve), from the point as the
    active set evaluated it."""
    blocks = link_hessian_blocks(problem.formulation, active.delta, active.distances, problem.link_lengths)
    blocks *= np.maximum(multipliers.link, 0.0)[:, None, None]
    hessian = _pair_terms(problem, problem.link_nodes[:, 0], problem.link_nodes[:, 1], blocks)
    free = problem.free_nodes
    for curvature, nu in zip(active.obstacle_hessians, multipliers.obstacle, strict=True):
        hessian.node[...] += np.maximum(nu[free], 0.0)[:, None, None] * curvature
    return hessian


def _penalized_blocks(
    problem: Problem, hessian: _Blocks, rows: StaticsRows, strict: NDArray[np.bool_], tol: float
) -> tuple[_Blocks, float]:
    """``H + rho A^T A`` (A the strictly active rows) and the shift s of the penalty test: where
    ``H + rho A^T A - s I`` is positive definite, ``z^T H z > s |z|^2`` for every z with ``A z = 0``
    (a large enough rho succeeds wherever that curvature is positive: Finsler), s covering the
    zero-curvature threshold and the factorization's rounding (the planar checker's cheap proof,
    :func:`_proves_minimum`, by sparse blocks)."""
    weight = problem.weight
    stiffest = float(np.abs(np.diagonal(hessian.node, axis1=1, axis2=2)).max(initial=0.0))
    degree = int(np.bincount(problem.link_nodes.ravel(), minlength=problem.n_nodes).max(initial=0))
    rho, shift = penalty_and_shift(
        stiffest, weight / problem.total_length, degree, len(problem.obstacles), _zero_curvature(problem, tol)
    )
    vectors = rows.vectors[strict]
    outer = rho * vectors[:, :, None] * vectors[:, None, :]
    return hessian.plus(_pair_terms(problem, rows.first[strict], rows.second[strict], outer)), shift


def _curvature_down(problem: Problem, hessian: _Blocks, penalized: _Blocks, rows: StaticsRows) -> float:
    """The curvature ``z^T H z / |z|^2`` along the eigenvector z of ``H + rho A^T A`` with the most
    negative eigenvalue (Lanczos), first projected onto the null space of every active row (so that
    the move keeps every active constraint active; the rows independent): negative, it shows that
    the point is not a minimum. nan where there is no such eigenvalue or it is not found."""
    try:
        values, vectors = sparse_linalg.eigsh(penalized.sparse(), k=1, which="SA", tol=1e-8)
    except (sparse_linalg.ArpackNoConvergence, sparse_linalg.ArpackError):
        return math.nan
    if not values[0] < 0.0:
        return math.nan
    move = vectors[:, 0]
    active = rows.sparse(problem)
    if active.shape[0]:
        try:
            move = move - active.T @ sparse_linalg.splu(shifted_gram(active, SHIFT).tocsc()).solve(active @ move)
        except RuntimeError:  # (an exactly singular factorization: the rows are not independent)
            return math.nan
    size = float(move @ move)
    if not size > 1e-12:  # (the eigenvector lay across the active rows: nothing is left of it)
        return math.nan
    return float(move @ (hessian.sparse() @ move)) / size


def _smallest_on_null(hessian: FloatArray, rows: FloatArray) -> float:
    """The smallest eigenvalue of ``H`` on the null space of the rows (inf if that space is {0})."""
    n = hessian.shape[0]
    basis: FloatArray = np.eye(n)
    if rows.shape[0] and n:
        # A pivoted QR of the rows' transpose reveals their rank at a fraction of an SVD's cost.
        q, r, _ = scipy.linalg.qr(rows.T, mode="full", pivoting=True, check_finite=False)
        diagonal = np.abs(np.diag(r))
        rank = int(np.count_nonzero(diagonal > _tolerances.RANK_TOL * max(float(diagonal[0]), 1e-300)))
        basis = np.asarray(q[:, rank:], dtype=np.float64)
    if basis.shape[1] == 0:
        return math.inf
    reduced = basis.T @ hessian @ basis
    return float(scipy.linalg.eigh(reduced, eigvals_only=True, subset_by_index=(0, 0), check_finite=False)[0])


def structure_verdict(
    problem: Problem,
    active: StaticsActive,
    multipliers: Multipliers,
    forces: FloatArray,
    licq_holds: bool | None,
    tol: float,
    dense_up_to: int | None = None,
) -> tuple[str, float]:
    """The second-order verdict in words, and the curvature that decided it (nan: none), at a point
    of a net or a chain in space with its multipliers: the planar checker's test
    (:func:`_second_order`) on dense matrices. ``active``: the active constraints (their rows in
    force units), ``forces`` their forces. Above ``dense_up_to`` free coordinates (None:
    CURVATURE_UP_TO) by sparse matrices: a strict minimum by the penalty test
    (:func:`_penalized_blocks`), a saddle by :func:`_curvature_down`."""
    force_tol = tol * problem.weight
    if forces.min(initial=0.0) < -force_tol:
        return "undecided (some forces are negative: not dual feasible)", math.nan
    blocks, rows = _structure_hessian(problem, active, multipliers), active.rows
    strict = forces > force_tol
    threshold = _zero_curvature(problem, tol)
    dense_up_to = CURVATURE_UP_TO if dense_up_to is None else dense_up_to
    if problem.free_nodes.size * problem.dimension > dense_up_to:
        penalized, shift = _penalized_blocks(problem, blocks, rows, strict, tol)
        if penalized.positive_definite(-shift):
            return (
                "strict local minimum (the Hessian of the Lagrangian plus a penalty on the "
                f"{int(strict.sum())} strictly active constraints is positive definite)",
                math.nan,
            )
        curvature = _curvature_down(problem, blocks, penalized, rows) if licq_holds else math.nan
        if curvature < -threshold:
            return _NOT_A_MINIMUM.format(curvature=curvature), curvature
        return (
            f"undecided (not proven by the penalty test; the curvature is computed for up to {dense_up_to} "
            f"free coordinates and {problem.dimension} x {problem.free_nodes.size} are free here)",
            math.nan,
        )
    hessian = blocks.dense()
    dense_rows = rows.dense(problem.n_nodes)[:, _free_columns(problem)]
    curvature = _smallest_on_null(hessian, dense_rows[strict])
    if curvature > threshold:
        return (
            "strict local minimum (the Hessian of the Lagrangian is positive definite on the null space of "
            f"the {int(strict.sum())} strictly active constraints, smallest curvature {curvature:.6g})",
            curvature,
        )
    weak = dense_rows.shape[0] - int(strict.sum())
    if weak:
        curvature = _smallest_on_null(hessian, dense_rows)
    if curvature < -threshold and licq_holds:
        return _NOT_A_MINIMUM.format(curvature=curvature), curvature
    if curvature < -threshold:
        return "undecided (negative curvature for these forces, but the forces are not unique: LICQ fails)", curvature
    if weak:
        return f"undecided (zero curvature, or the answer depends on the {weak} weakly active constraints)", curvature
    return "undecided (zero curvature on the critical cone: higher-order terms decide)", curvature
