"""The second-order conditions, for any problem: the curvature of the Lagrangian on the critical
cone, and a cheap proof of a strict minimum."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.sparse.linalg as sparse_linalg
from scipy.linalg import lapack

from funicular._core import penalty_and_shift, zero_curvature
from funicular.checks import _tolerances
from funicular.checks._active import _Point
from funicular.checks._jacobian import _factor, _Hessian, _Rows
from funicular.checks._licq import _dependent_rows, _independent_triangle, _null
from funicular.checks._report import SecondOrder
from funicular.checks._tolerances import LANCZOS_VECTORS
from funicular.model import FloatArray, Problem

MINIMUM = "strict local minimum"
PROVEN = (
    "the Hessian of the Lagrangian plus a penalty on the strictly active constraints is positive "
    "definite (a Cholesky factorization), so it is on their null space (second-order sufficient "
    "condition; the curvature was not computed)"
)


# ----------------------------------------------------------------- the curvature on a null space
def _min_curvature(
    hessian: _Hessian, rows: _Rows, null: FloatArray, threshold: float
) -> tuple[float, FloatArray | None]:
    """Smallest eigenvalue of ``H`` on the null space of the rows (inf if that space is {0}), and
    its eigenvector (in that null space); nan where the eigenvalue solver fails."""
    if null.shape[1]:
        rows = rows.take(np.setdiff1d(np.arange(rows.m), _dependent_rows(null)))
    m, n = rows.m, rows.n
    if m >= n:
        return math.inf, None
    if n <= _tolerances.DENSE_LIMIT:
        # The kept rows are independent, so the last n - m columns of a complete QR of their
        # transpose span the null space (a QR costs a fraction of an SVD).
        basis: FloatArray = np.eye(n)
        if m:
            basis = np.asarray(scipy.linalg.qr(rows.dense().T, mode="full", check_finite=False)[0][:, m:])
        reduced = basis.T @ hessian.times(basis)
        values, vectors = scipy.linalg.eigh(reduced, subset_by_index=(0, 0), check_finite=False)
        return float(values[0]), basis @ vectors[:, 0]
    # The bordered matrix [[H - s I, A^T], [A, 0]], each row next to its first node: banded for a
    # chain, sparse for a net. Its inverse restricted to the positions is Z (Z^T H Z - s I)^-1 Z^T.
    shift = hessian.bound() - threshold
    h_rows, h_cols, h_values = hessian.entries()
    a_rows, a_cols, a_values = rows.entries()
    d = rows.d
    key = np.concatenate([np.arange(n) // d * 2, 2 * rows.anchors() + 1])
    try:
        solve = _factor(
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
        # eigenvalue is well separated after the shift-invert (10-20 solves).
        start = np.random.default_rng(0).standard_normal(n)
        ncv = min(LANCZOS_VECTORS, n)
        theta, vectors = sparse_linalg.eigsh(operator, k=1, which="LA", tol=1e-10, ncv=ncv, v0=start)
    except (sparse_linalg.ArpackNoConvergence, sparse_linalg.ArpackError):
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
    dense QR or the bordered matrix (:func:`_min_curvature`)."""

    def curvature(k: int) -> tuple[float, FloatArray | None]:
        if k == rows.m:
            return _min_curvature(hessian, rows, null, threshold)
        first = rows.take(np.arange(k))
        # Some of a set of independent rows are independent (their singular values interlace).
        dependencies = np.zeros((k, 0)) if null.shape[1] == 0 else _null(first)
        if dependencies is None:
            return math.nan, None
        return _min_curvature(hessian, first, dependencies, threshold)

    return curvature


def _zero_curvature(problem: Problem, tol: float) -> float:
    """The curvature below which an eigenvalue counts as zero (module doc, Second order)."""
    return zero_curvature(tol, problem.force_scale, problem.n_nodes, problem.total_length)


def _second_order(
    problem: Problem,
    point: _Point,
    hessian: _Hessian,
    rows: _Rows,
    forces: FloatArray,
    null: FloatArray | None,
    tol: float,
    proof: bool = False,
) -> SecondOrder:
    """The second-order verdict of any problem at a point with these multipliers (``hessian``, and
    ``forces`` of the active ``rows``). ``null``: the rows' dependencies if known (None: found
    here, only if needed). ``proof``: the cheap sufficient test of :func:`_proves_minimum` first;
    where it proves a strict local minimum that is the verdict, without the curvature."""
    force_tol = tol * problem.force_scale
    if forces.min(initial=0.0) < -force_tol:
        return SecondOrder("undecided", math.nan, "some multipliers are negative (not dual feasible)")
    if proof and _proves_minimum(problem, hessian, rows, forces, tol):
        return SecondOrder(MINIMUM, math.nan, PROVEN)
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
        if null is None:  # (a large net's dependencies, not decided: only the proof is left)
            if not proof and _proves_minimum(problem, hessian, rows, forces[order], tol):
                return SecondOrder(MINIMUM, math.nan, PROVEN)
            return SecondOrder(
                "undecided", math.nan, "the active constraints' dependencies are not decided (LICQ), nor the cone"
            )
        licq_holds = null.shape[1] == 0
        curvature_on = _general_curvature(hessian, rows, null, threshold)
    curvature, direction = curvature_on(count)
    if math.isnan(curvature):
        return SecondOrder("undecided", curvature, "the eigenvalue solver did not converge")
    if curvature > threshold:
        shown = "" if math.isinf(curvature) else f", smallest curvature {curvature:.6g}"
        return SecondOrder(
            MINIMUM,
            curvature,
            f"the Hessian of the Lagrangian is positive definite on the null space of the {count} strictly "
            f"active constraints{shown} (second-order sufficient condition)",
        )
    weak = rows.m - count
    if weak:
        curvature, direction = curvature_on(rows.m)
    if curvature < -threshold and licq_holds:
        moves = None
        if direction is not None:
            moves = np.zeros((problem.n_nodes, problem.dimension))
            moves[point.free] = direction.reshape(-1, problem.dimension)
        return SecondOrder(
            "not a minimum",
            curvature,
            f"negative curvature {curvature:.6g} along a direction that keeps every active constraint active "
            "(the second-order necessary condition fails)",
            moves,
        )
    if math.isnan(curvature):
        reason = "the eigenvalue solver did not converge"
    elif curvature < -threshold:
        reason = "negative curvature for these multipliers, but the multipliers are not unique (LICQ fails)"
    elif weak:
        reason = f"zero curvature, or the answer depends on the {weak} weakly active constraints"
    else:
        reason = "zero curvature on the critical cone: higher-order terms decide"
    return SecondOrder("undecided", curvature, reason)


# ----------------------------------------------------------------- a cheap proof of a strict minimum
def _proves_minimum(problem: Problem, hessian: _Hessian, rows: _Rows, forces: FloatArray, tol: float) -> bool:
    """True only where :func:`_second_order` says "strict local minimum", without its curvature:
    ``H + rho A^T A - s I`` (A the strictly active rows) is positive definite, so
    ``z^T H z > s |z|^2`` for every z with ``A z = 0`` (a large enough rho succeeds wherever that
    curvature is positive: Finsler), and s covers the zero-curvature threshold and the
    factorization's rounding. One sparse Cholesky factorization (O(N) for a chain's block
    tridiagonal matrix). False: not proven here (a rho too small, a curvature near the threshold,
    or not a minimum)."""
    weight = problem.force_scale
    if forces.min(initial=0.0) < -tol * weight:
        return False  # not dual feasible: "undecided"
    if rows.n == 0:
        return True  # nothing can move
    stiffest = float(np.abs(hessian.node).max(initial=0.0))
    degree = int(np.bincount(problem.link_nodes.ravel(), minlength=problem.n_nodes).max(initial=0))
    rho, shift = penalty_and_shift(
        stiffest,
        weight / problem.total_length,
        degree,
        len(problem.obstacles),
        _zero_curvature(problem, tol),
        _tolerances.PENALTY,
    )
    return hessian.penalized(rows, np.where(forces > tol * weight, rho, 0.0), shift).positive_definite()
