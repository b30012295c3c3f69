"""The saddle escape's second-order test, on the solver's own Newton matrix (scaled units).

At the solver's result (positions z, multipliers mu) the Hessian of the Lagrangian W is the Newton
matrix without its barrier term. With ``sigma_r = rho / |g_r|^2`` on chosen rows r (``g_r`` the
row's gradient) the same assembly (``chain.newton_matrix``) gives ``P = W + rho A^T A``, A those
rows scaled to unit length, so no evaluation beyond the solver's own is needed. The test mirrors
:func:`funicular.checks.second_order` with its cheap proof, in the solver's units (positions in
link lengths, forces in the total weight), and its tolerances:

* **Strict local minimum** if ``P_S - s I`` is positive definite (S the strictly active rows,
  force ``> tol``; s the zero-curvature threshold plus the factorization's rounding): W exceeds s
  on the null space of S (:func:`penalty_and_shift` says why rho and s are safe). One Cholesky.
* **A direction of negative curvature** otherwise, if ``P_A`` (A every active row, strict or weak)
  has an eigenvalue below minus the threshold: its eigenvector, found by inverse iteration whose
  shift the Cholesky keeps below the eigenvalue (:func:`lowest_eigenpair`). Its component off the
  null space of A is O(1 / rho): to first order the move keeps the active constraints active.
  The checker asks LICQ too before it says "not a minimum"; the escape only needs a way down, and
  keeps the result only if its energy is lower.
* **Neither** (undecided): a curvature near zero, an infeasible point, negative multipliers.

Both paths (compiled or numpy) run the same steps; only the linear solver passed in differs. For
the chains the compiled loop solves, with the block Cholesky, ``driver.escape_curvature`` runs
those steps in one kernel call (the numpy steps cost a 50-node saddle 0.3 ms).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from funicular.model import FloatArray
from funicular.solver.banded import BlockTridiagonal, LinearSolver, Solve, eigenvalue_floor
from funicular.solver.chain import Point, ScaledChain, newton_matrix
from funicular.solver.compiled import block_cholesky, driver, jit

ESCAPE_TOL = 1e-6  # relative tolerance of the test: the checker's default (checks.DEFAULT_TOL)
PENALTY = 1e3  # rho, in units of the largest entry of H's diagonal blocks (penalty_and_shift)
ROUNDING = 64 * float(np.finfo(np.float64).eps)  # a banded Cholesky's rounding, relative to the largest entry
MAX_SHIFTS = 80  # factorizations of the eigenvalue search (each halves its bracket at least every other step)
MAX_STEPS = 20  # inverse-iteration steps at one shift
# The eigenvector's last change (2-norm of unit vectors) at which the search stops: from the cosine
# of the two, so no finer than ~1e-8.
VECTOR_TOL = 1e-7
BRACKET = 1e-8  # the search stops when the eigenvalue is known to this, relative to its bracket's start
ROW_FLOOR = 1e-100  # a row gradient shorter than this (scaled) gets no penalty (rho / |g|^2 would overflow)
CLOSER = 1e-2  # after a shift that converges slowly, the next this fraction of the bracket below its top
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))  # the start vector's (``_start``)


@dataclass(frozen=True)
class Curvature:
    """The escape test's answer: ``minimum`` (proven strict local minimum) or a ``direction`` of
    negative curvature ``value`` (scaled units), a unit vector of moves (N, 2), zero at the fixed
    nodes; or neither."""

    minimum: bool
    direction: FloatArray | None = None
    value: float = math.nan


def zero_curvature(tol: float, weight: float, n_nodes: int, total_length: float) -> float:
    """The curvature below which an eigenvalue counts as zero: one that changes the energy by less
    than ``tol W L`` when every node moves by the chain length L (checks' module doc, Second order)."""
    return tol * weight / (n_nodes * total_length)


def penalty_and_shift(stiffest: float, stiffness: float, n_obstacles: int, threshold: float) -> tuple[float, float]:
    """rho and the shift s of the sufficient test ``H + rho A^T A - s I`` positive definite.

    ``stiffest``: the largest entry of H's diagonal blocks; ``stiffness``: the weight per chain
    length. Above some rho*, H + rho A^T A is positive definite iff H is on null(A) (Finsler), so a
    larger rho is safer, but the rounding the shift must cover grows with it. A's rows are unit
    vectors (A^T A is O(1)), so rho is a stiffness: PENALTY times the larger of the two. rho* is 2-4
    such entries on the benchmark's chain draped over its disk (20 to 2,000 nodes) and below 0.1 on
    random chains over disks; 1000 leaves a factor of 300, at a rounding margin ~1e-10 of H's scale.
    A banded Cholesky that completes is exact for a matrix within ~(bandwidth + 1) eps of its
    largest entry (Demmel): ROUNDING of a bound on the largest diagonal entry covers that. Each unit
    row adds at most rho to a diagonal entry, and a node has two links and one contact per obstacle
    at most.
    """
    rho = PENALTY * max(stiffest, stiffness)
    largest = stiffest + (2 + n_obstacles) * rho
    return rho, threshold + ROUNDING * largest


def escape_test(
    chain: ScaledChain, point: Point, mu: FloatArray, linear_solver: LinearSolver, tol: float = ESCAPE_TOL
) -> Curvature:
    """The second-order test at the solver's result (module doc); ``point`` evaluated there."""
    if not chain.free.size:
        return Curvature(minimum=True)  # nothing can move
    total_length = float(chain.lengths.sum())  # (scaled: the weight is 1)
    threshold = zero_curvature(tol, 1.0, chain.positions.shape[0], total_length)
    if chain.driver_arrays is not None and linear_solver is block_cholesky:
        return _compiled_test(chain, point, mu, tol, total_length, threshold)
    n_links = chain.links.size
    norms = np.empty(mu.size)
    q = point.q[chain.links]
    norms[:n_links] = np.hypot(q[:, 0], q[:, 1])
    g = point.obstacle_gradient.reshape(-1, 2)
    norms[n_links:] = np.hypot(g[:, 0], g[:, 1])
    # A row of (almost) no length (a squared link collapsed to a point) has no direction: no penalty.
    # Leaving a strict row out of the proof only enlarges the null space it covers.
    directed = norms > ROW_FLOOR
    norms = np.where(directed, norms, ROW_FLOOR)
    forces = mu * norms  # in units of the weight
    distances = point.c / norms  # in link lengths; > 0 violates
    if forces.min(initial=0.0) < -tol or distances.max(initial=-math.inf) > tol:
        return Curvature(minimum=False)  # not dual feasible, or infeasible: undecided
    active = distances >= -tol
    strict = active & (forces > tol)

    hessian = newton_matrix(chain, point, mu, np.zeros(mu.size))
    stiffest = float(np.abs(hessian.diagonal).max(initial=0.0))
    rho, shift = penalty_and_shift(stiffest, 1.0 / total_length, len(chain.obstacles), threshold)
    penalty = np.where(directed, rho / norms**2, 0.0)
    proof = newton_matrix(chain, point, mu, np.where(strict, penalty, 0.0))
    try:
        linear_solver(proof.shifted(-shift))
    except np.linalg.LinAlgError:
        pass
    else:
        return Curvature(minimum=True)

    # Not proven: is there negative curvature beyond the threshold that keeps every active row active?
    margin = shift - threshold  # the rounding
    matrix = newton_matrix(chain, point, mu, np.where(active, penalty, 0.0))
    below = _lower_bound(chain, point, mu) - threshold - 2.0 * margin
    found = lowest_eigenpair(matrix, below, -threshold - margin, linear_solver, _start(matrix.size))
    if found is None:
        return Curvature(minimum=False)  # no curvature below -threshold: undecided
    value, vector = found
    moves = np.zeros_like(chain.positions)
    moves[chain.free_at] = vector.reshape(-1, 2)
    return Curvature(minimum=False, direction=moves, value=value)


def _compiled_test(
    chain: ScaledChain, point: Point, mu: FloatArray, tol: float, total_length: float, threshold: float
) -> Curvature:
    """The same test in one kernel call (``driver.escape_curvature``), for a chain the compiled
    loop solves with the block Cholesky."""
    kernels = driver()
    assert chain.driver_arrays is not None  # (escape_test)
    arrays, quadratic = chain.driver_arrays
    values = (point.positions, point.c, point.q, point.obstacle_gradient, point.dual_residual)
    found, value, vector = jit(kernels.escape_curvature)(
        arrays, quadratic, values, mu, tol, total_length, threshold, _search_constants(), _start(2 * chain.free.size)
    )
    if found != kernels.DIRECTION:
        return Curvature(minimum=found == kernels.MINIMUM)
    moves = np.zeros_like(chain.positions)
    moves[chain.free_at] = vector.reshape(-1, 2)
    return Curvature(minimum=False, direction=moves, value=float(value))


def _lower_bound(chain: ScaledChain, point: Point, mu: FloatArray) -> float:
    """A lower bound of the penalized matrices' eigenvalues: their link and penalty terms are
    positive semidefinite (for mu >= 0), so the smallest eigenvalue of the contact terms, 2x2
    blocks node by node, with a tenth more for the rounding (0 if there are none)."""
    if not chain.obstacles:
        return 0.0
    nu = np.maximum(mu[chain.links.size :], 0.0).reshape(point.obstacle_gradient.shape[:2])
    return 1.1 * eigenvalue_floor(np.einsum("jn,jnab->nab", nu, point.obstacle_hessian))


@functools.cache
def _search_constants() -> FloatArray:
    """``driver.escape_curvature``'s ``search``: this module's constants (read-only, made once)."""
    kernels = driver()
    search = np.empty(6)
    search[[kernels.ROW_FLOOR, kernels.MAX_SHIFTS, kernels.MAX_STEPS]] = ROW_FLOOR, MAX_SHIFTS, MAX_STEPS
    search[[kernels.VECTOR_TOL, kernels.BRACKET, kernels.CLOSER]] = VECTOR_TOL, BRACKET, CLOSER
    search.flags.writeable = False
    return search


@functools.lru_cache(maxsize=16)
def _start(size: int) -> FloatArray:
    """The inverse iteration's first vector: fixed (the same problem leaves its saddle the same way)
    and generic (neither symmetric nor antisymmetric along the chain, which would miss half the
    eigenvectors): cosines at the golden angle. Read-only, kept for the last few sizes."""
    start: FloatArray = np.cos(GOLDEN_ANGLE * np.arange(1, size + 1))
    start.flags.writeable = False
    return start


def lowest_eigenpair(
    matrix: BlockTridiagonal, below: float, above: float, linear_solver: LinearSolver, start: FloatArray
) -> tuple[float, FloatArray] | None:
    """The smallest eigenvalue of ``matrix`` and a unit eigenvector, given ``matrix - below I``
    positive definite; None if that is not so after all, or if the eigenvalue is not below ``above``.

    Inverse iteration with a shift sigma that the factorization keeps below the eigenvalue (it
    fails above it). Each factorization that succeeds raises the bracket's bottom to sigma, and
    its steps lower the top to their Rayleigh quotient (never below the eigenvalue); one that fails
    lowers the top to sigma. At one shift the steps go on while each changes the vector ten times
    less than the one before (the error is then about the last change), until the change is below
    VECTOR_TOL; slower, the next shift goes just below the top, halfway after a failure. Each
    factorization and each step is O(N).
    """
    bottom, top = below, above
    sigma, vector, value = below, start / np.linalg.norm(start), math.inf
    for _ in range(MAX_SHIFTS):
        try:
            solve = linear_solver(matrix.shifted(-sigma))
        except np.linalg.LinAlgError:
            if sigma == below:
                return None
            top = sigma
            sigma = bottom + 0.5 * (top - bottom)
            continue
        bottom, previous = sigma, math.inf
        for _ in range(MAX_STEPS):
            vector, value, change = _inverse_iteration(solve, vector, sigma)
            top = min(top, value)
            if change <= VECTOR_TOL:
                return (value, vector) if value < above else None
            if change > 0.1 * previous:
                break
            previous = change
        if top - bottom <= BRACKET * (above - below):
            break
        sigma = top - CLOSER * (top - bottom)
    return (value, vector) if value < above else None


def _inverse_iteration(solve: Solve, vector: FloatArray, sigma: float) -> tuple[FloatArray, float, float]:
    """``w = (M - sigma I)^-1 v`` for a unit v, normalized; its Rayleigh quotient ``sigma + w.v / w.w``
    (since ``w^T (M - sigma I) w = w.v``: no product with M); and how far it moved from v (either
    sign), ``sqrt(2 (1 - |cos|))``, from the same products."""
    w = solve(vector)
    squared, along = float(w @ w), float(w @ vector)
    length = math.sqrt(squared)
    cosine = min(abs(along) / length, 1.0)
    return w / length, sigma + along / squared, math.sqrt(2.0 * (1.0 - cosine))


__all__ = ["Curvature", "escape_test", "lowest_eigenpair", "penalty_and_shift", "zero_curvature"]
