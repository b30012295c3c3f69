"""A primal-dual interior-point method for the hanging chain, O(N) per iteration.

Problem (after eliminating supports and exactly taut segments, in scaled units)::

    minimize  w^T y   over the free nodes        s.t.  c(p) + s = 0,  s >= 0

with multipliers ``mu >= 0`` for ``c + s = 0``. Each iteration solves the Newton system of the
perturbed KKT conditions ``grad E + J^T mu = 0``, ``c + s = 0``, ``S mu = sigma tau omega``
condensed onto the positions::

    (W + J^T Sigma J) dz = -(r_d + J^T (Sigma r_p - r_c / s)),   Sigma = diag(mu / s)

which is block tridiagonal in the interleaved free coordinates. Step control: Mehrotra's
predictor-corrector for sigma, fraction-to-boundary 0.995, and a backtracking line search on the
norm of the perturbed KKT residual. If the matrix is not positive definite (it is for the convex
chain; obstacles will make it indefinite) a multiple of the identity is added until it is.

With ``contact = "links"`` the contact rows are per obstacle and link (see ``chain``); only the
convex built-in shapes are accepted there.

Scaling: lengths are divided by the longest link, forces by the total weight, and positions are
measured from the first support, so the stopping test ``max scaled residual <= tol`` does not
depend on the units or the size of the coordinates.

Barrier weights ``omega`` (``_barrier_weights``): a link's scaled length, 1 for a contact; the
barrier is ``-tau sum omega_i log s_i``. A link's slack is at most its length, so an unweighted
barrier pulls a link together with a force of at least ``tau / l_k``: for a link 100 times shorter
than the others that outweighs its tension long before tau is small, and the link collapses onto
the point where the norm constraint is not differentiable, and stays there. Weighted, every link
feels at most ``tau`` (as a fraction of the weight) whatever its length. For equal links omega = 1
and nothing changes. The starting multipliers and slacks, and the active-set test, measure each
link in its own units likewise (``_row_units``: a squared link's multiplier is ``T / (2 d)``).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from funicular.constraints import link_distances, multipliers_from_tension, smoothed_tension
from funicular.errors import FunicularError, ScenarioError
from funicular.model import FloatArray, Formulation, IntArray, Problem
from funicular.obstacles import Obstacle, has_segment_max, link_contact_ends
from funicular.solution import Solution, Status
from funicular.solver import fused
from funicular.solver.banded import BlockTridiagonal, LinearSolver, Solve
from funicular.solver.chain import (
    Point,
    ScaledChain,
    as_slice,
    driver_point,
    evaluate,
    evaluate_obstacles,
    jacobian_times,
    jacobian_transpose_times,
    newton_matrix,
)
from funicular.solver.compiled import HAVE_NUMBA, default_linear_solver, jit
from funicular.solver.compiled import driver as compiled_driver
from funicular.solver.curvature import Curvature, escape_test
from funicular.solver.initial import Presolve, presolve, repositioned
from funicular.solver.polish import PROXIMAL, polish_step
from funicular.solver.spans import exact_start

STEP_TO_BOUNDARY = 0.995
PENALTY_DECAY = 100.0  # per step, of the barrier merit's penalty
ARMIJO = 1e-4
MAX_BACKTRACKS = 40
INITIAL_MULTIPLIER = 1.0
MIN_INITIAL_SLACK = 1e-2
POLISH_FROM = 1e-8  # try the active-set polish once the scaled KKT error is below this,
POLISH_STALLED = 1e-5  # or below this when the interior-point steps stop gaining a factor 10
POLISH_STEPS = 25
POLISH_PATIENCE = 3
POLISH_CORRECTING = 10
POLISH_FROM_GUESS = 6  # steps of the polish from a coarse level's active set
POLISH_DIVERGENCE = 1e3  # give up polishing when the KKT error grows by this factor
CENTRING_FLOOR = 0.1
COARSE_ABOVE = 200  # chains with obstacles longer than this start from a coarse solve (_coarse_guess)
COARSE_FACTOR = 8
# With obstacles the fine level spends a step correcting the contact near the lift-off points
# whatever the coarse level (they move by a few coarse links from level to level), so a coarse
# level finer than it needs costs more than it saves: it has N / COARSE_FACTOR nodes up to
# COARSE_CAP, then COARSE_CAP until that is N / COARSE_FACTOR_MAX. The same steps on the fine chain
# (3 at 10^5..10^6 with the disk), less time (interleaved runs: 10^5 0.26 -> 0.19 s, 3 10^5
# 0.53 -> 0.34 s, 10^6 1.26 -> 1.21 s). Without obstacles a finer coarse level does pay: 10^6
# nodes from 125,000 take 2 steps, from 31,250 take 3.
COARSE_CAP = 5000
COARSE_FACTOR_MAX = 32
COARSE_ABOVE_FREE = 4000  # the same without obstacles (below, one direct solve is as fast)
CENTRALITY = 1e3
# A contact is active when its force exceeds this many node weights per link length of slack. On
# the central path (s nu = tau) that means a slack below sqrt(tau / (ACTIVE_CONTACT w)): too large
# and a long chain's true contacts, still 1e-3 link lengths off the obstacle when the iteration
# stalls at N = 10^6, are missed; too small and hundreds of nodes near the lift-off points are
# taken for touching. 100 leaves tens (see _lifting_off) and keeps N <= 10^5 at 7-9 Newton steps.
ACTIVE_CONTACT = 1e2
ROUNDING_FLOOR = 4.0
ESCAPE_UP_TO = 20_000  # nodes; the second-order check costs about a second at 10^5
ESCAPE_STEP = 0.05  # of the chain length, for the node that moves most
ESCAPES = 2
WARM_SLACK = 1e-6  # smallest slack of a warm start (scaled length)
WARM_CENTRING = 1e-8  # s_i mu_i of a warm start
SCALE_SAMPLE = 4096  # nodes (_obstacle_scale)
TINY = float(np.finfo(np.float64).tiny)  # slacks stay positive even when a step underflows
EPS = float(np.finfo(np.float64).eps)


State = tuple[FloatArray, FloatArray, FloatArray, Point]  # positions z, slacks s, multipliers mu, evaluation
Polished = tuple[FloatArray, FloatArray, int, Point]  # positions z, multipliers mu, steps taken, evaluation
Step = tuple[FloatArray, FloatArray, FloatArray]  # dz, ds, dmu
Judge = Callable[[], Curvature]  # the escape's second-order test at a solve's result (``curvature``)
LineSearch = Callable[[ScaledChain, State, Step, FloatArray, float], tuple[State, float] | None]


@dataclass(frozen=True)
class SolverOptions:
    """Settings of the interior-point method.

    tol: stop when every scaled KKT residual (force / total weight, length / longest link) is below it
        (or below the rounding floor ``4 eps X F``, if that is larger, where X is the largest
        coordinate in link lengths and F the largest force in units of the weight, at least 1: a
        node 1e6 link lengths from the origin cannot be placed to better than 1e-10 of a link, and
        a link pulling with 100 times the weight turns that into 1e-8 of the weight; see
        ``_rounding_floor``).
    max_iterations: give up (status ``max_iterations``) after this many Newton steps.
    linear_solver: ``factor(matrix) -> solve`` for the block-tridiagonal Newton matrix (see
        ``solver.banded``). ``None`` (default): the compiled block Cholesky where the solve is
        compiled (below) and numba is installed, else LAPACK's banded Cholesky.
    compiled: the interior-point loop (``solver.driver``, node contact with no obstacles or only
        disks, ellipses and half-planes), or else the links' per-iteration terms, quadratic
        obstacles' contact rows and the KKT error, and the polish's elimination, by the compiled
        loops of numba instead of vectorized numpy; the two agree to rounding. ``None`` (default):
        compiled when numba is installed. The first compiled solve in a process loads numba and
        the kernels (about half a second); on a fresh install numba first compiles them, about a
        minute once (``make`` does it while installing: ``python -m funicular.solver.warm_up``).
    escape_saddles: with obstacles (node contact, up to ESCAPE_UP_TO nodes), check the second-order
        conditions at the result (on the solver's own Newton matrix, ``solver.curvature``) and, at a
        saddle, move off it and solve again (``_escape_saddles``).
        A chain solved coarse-to-fine is checked on its coarsest level only: each finer level
        starts next to the minimum the level below found.
    exact_start: start a chain that touches nothing from its discrete catenary with its tensions
        (``spans.exact_start``), which the polish then confirms in one Newton step. False: the
        general path (interior-point steps, coarse to fine), e.g. to watch the method work.
    """

    tol: float = 1e-10
    max_iterations: int = 200
    linear_solver: LinearSolver | None = None
    compiled: bool | None = None
    escape_saddles: bool = True
    exact_start: bool = True


def _step_to_boundary(values: FloatArray, steps: FloatArray, compiled: bool = False) -> float:
    """Largest alpha in (0, 1] with ``values + alpha * steps >= (1 - STEP_TO_BOUNDARY) * values``."""
    if compiled:
        return float(jit(fused.step_to_boundary)(values, steps, STEP_TO_BOUNDARY))
    shrinking = steps < 0
    if not shrinking.any():
        return 1.0
    return float(min(1.0, STEP_TO_BOUNDARY * (-values[shrinking] / steps[shrinking]).min()))


def _residual_merit(point: Point, s: FloatArray, mu: FloatArray, target: FloatArray) -> float:
    """Squared norm of the perturbed KKT residual."""
    r_p = point.c + s
    return float((point.dual_residual**2).sum() + r_p @ r_p + ((s * mu - target) ** 2).sum())


def _residual_line_search(
    chain: ScaledChain,
    state: State,
    step: tuple[FloatArray, FloatArray, FloatArray],
    target: FloatArray,
    penalty: float,
) -> tuple[State, float] | None:
    """Backtrack primal and dual steps together until the perturbed KKT residual decreases."""
    z, s, mu, point = state
    dz, ds, dmu = step
    alpha_p, alpha_d = _step_to_boundary(s, ds, chain.compiled), _step_to_boundary(mu, dmu, chain.compiled)
    current = _residual_merit(point, s, mu, target)
    fraction = 1.0
    for _ in range(MAX_BACKTRACKS):
        z_new = z + fraction * alpha_p * dz
        s_new = np.maximum(s + fraction * alpha_p * ds, TINY)
        mu_new = mu + fraction * alpha_d * dmu
        trial = evaluate(chain, z_new, mu_new)
        value = _residual_merit(trial, s_new, mu_new, target)
        if math.isfinite(value) and value <= (1.0 - ARMIJO * fraction) * current:
            return (z_new, s_new, mu_new, trial), penalty
        fraction *= 0.5
    return None


def _merit(
    chain: ScaledChain, point: Point, s: FloatArray, tau: FloatArray, penalty: float, infeasibility: float | None = None
) -> float:
    """LOQO's merit: energy - sum(tau_i log s_i) + penalty/2 ||c + s||^2 (tau_i = tau omega_i);
    ``infeasibility``: ||c + s||^2, if already at hand."""
    if infeasibility is None:
        r_p = point.c + s
        infeasibility = float(r_p @ r_p)
    energy = float(chain.load @ point.positions[:, 1])
    return energy - float(tau @ np.log(s)) + 0.5 * penalty * infeasibility


def _infeasibility(point: Point) -> float:
    """Largest stationarity or primal residual (what the barrier must not outrun)."""
    stationarity = float(np.abs(point.dual_residual).max(initial=0.0))
    # The largest positive c_i (fmax skips a NaN, as would selecting c > 0 first).
    return max(stationarity, float(np.fmax.reduce(point.c, initial=0.0)))


def _recentred(s: FloatArray, mu: FloatArray, weight: FloatArray, total_weight: float) -> FloatArray:
    """Keep every product s_i mu_i within a factor CENTRALITY of ``omega_i tau``, its share of the
    mean (a wide neighbourhood of the central path), so no slack is left pinned to its bound by a
    stray multiplier (``total_weight``: the sum of the weights omega)."""
    tau = float(s @ mu) / total_weight
    return np.clip(mu, weight * tau / (CENTRALITY * s), CENTRALITY * weight * tau / s)


def _kkt_error(chain: ScaledChain, point: Point, mu: FloatArray) -> float:
    """Largest scaled KKT residual (``_kkt_parts``), NaN if any is."""
    forces, lengths = _kkt_parts(chain, point, mu)
    return max(forces, lengths)  # (both NaN if either is: _kkt_parts)


def _kkt_parts(chain: ScaledChain, point: Point, mu: FloatArray) -> tuple[float, float]:
    """The largest scaled KKT residuals in units of force (stationarity, the net force left on the
    free nodes, the sign of mu, complementarity) and of length (a link's overstretch); both NaN if
    any residual is not a number (``_Tolerance`` holds them to different floors).

    The net force (chains without obstacles) is what the supports fail to carry: the sum of the
    nodes' stationarity residuals. Each node's is below tol, but they can share a sign: a
    6,000-node chain polished from a coarse level stopped with every node within 1.3e-11 of the
    weight and the reactions 3.7e-10 of the weight short; one more Newton step fixes that. With
    obstacles it is left out: asked for, the polish failed near lift-off points (a 1.25e5-node
    drape fell back to 30 interior-point steps), and the reactions and contact forces there carry
    the weight to the sum of the nodes' residuals.

    A link's overstretch is measured as a length, ``d_k - l_k``, in either formulation: the squared
    form's ``c_k = d_k^2 - l_k^2`` is ``(d_k + l_k)`` times it, which would let a link 100 times
    shorter than the longest stretch 5000 times more (relative to its length) than tol."""
    if chain.compiled:
        stationarity, *net, primal, dual, complementarity = jit(fused.kkt_parts)(
            chain.squared, point.dual_residual, point.c, mu, chain.lengths, chain.links
        )
        net_force = 0.0 if chain.obstacles else max(abs(net[0]), abs(net[1]))
        return float(max(stationarity, net_force, dual, complementarity)), float(primal)  # all NaN if any
    # (array methods: np.max's and np.sum's wrappers cost as much as a small chain's reductions)
    stationarity = float(np.abs(point.dual_residual).max(initial=0.0))
    net_force = 0.0 if chain.obstacles else float(np.abs(point.dual_residual.sum(axis=0)).max(initial=0.0))
    c = point.c
    if chain.formulation is Formulation.SQUARED and chain.links.size:
        lengths = chain.lengths[chain.links]
        n_links = lengths.size
        stretch = np.maximum(c[:n_links], 0.0)
        stretch = stretch / (np.sqrt(stretch + lengths * lengths) + lengths)  # d - l = c / (d + l)
        c = np.concatenate((stretch, c[n_links:]))
    primal = float(c.max(initial=0.0))
    dual = float((-mu).max(initial=0.0))
    with np.errstate(over="ignore"):  # (an iterate far astray: its error is inf)
        complementarity = float(np.abs(mu * point.c).max(initial=0.0))
    parts = (stationarity, net_force, dual, complementarity, primal)
    if any(part != part for part in parts):  # (max() skips a NaN that is not first)
        return math.nan, math.nan
    return max(parts[:4]), primal


def _obstacle_scale(
    obstacle: Obstacle, positions: FloatArray, nodes: IntArray, gradient: FloatArray | None = None
) -> float:
    """A typical |grad phi| near the ``nodes``: phi / scale is then roughly a distance. (A median
    over at most 2 * SCALE_SAMPLE evenly spaced nodes: enough for "typical", and a long chain's
    median over every node cost a tenth of a second.) ``gradient``: grad phi at ``positions[nodes]``,
    if already evaluated there (used where the sample is every node: the same evaluation)."""
    stride = max(1, nodes.size // SCALE_SAMPLE)
    if gradient is None or stride > 1:
        at = as_slice(nodes) if stride == 1 else nodes[::stride]  # (a slice: no copy)
        _, gradient, _ = obstacle.evaluate(positions[at])
    norms = np.hypot(gradient[:, 0], gradient[:, 1])
    norms = norms[np.isfinite(norms) & (norms > 0)]
    return fused.median(norms) if norms.size else 1.0


def _scale(problem: Problem, start: Presolve, compiled: bool = False) -> ScaledChain:
    length_unit = float(problem.link_lengths.max())
    origin = problem.support_positions[0].copy()
    free = start.movable
    touches_free = np.zeros(problem.n_nodes, dtype=bool)
    touches_free[free] = True
    optimised = touches_free[:-1] | touches_free[1:]
    if start.detached.size:
        detached = np.zeros(problem.n_nodes, dtype=bool)
        detached[start.detached] = True
        optimised &= ~detached[:-1] & ~detached[1:]
    links = np.flatnonzero(optimised)
    contact_links = problem.contact == "links" and bool(problem.obstacles)
    gradients = start.obstacle_gradients or (None,) * len(problem.obstacles)
    return ScaledChain(
        formulation=problem.formulation,
        positions=(start.positions - origin) / length_unit,
        free=free,
        links=links,
        lengths=problem.link_lengths / length_unit,
        load=problem.gravity * problem.masses / problem.weight,
        both_free=(free[1:] - free[:-1] == 1).astype(np.float64),
        obstacles=problem.obstacles,
        obstacle_scale=np.array(
            [_obstacle_scale(o, start.positions, free, g) for o, g in zip(problem.obstacles, gradients, strict=True)]
        ),
        length_unit=length_unit,
        origin=origin,
        quadratics=problem.quadratic_obstacles,
        contact_links=contact_links,
        contact_ends=link_contact_ends(problem.is_support) if contact_links else None,
        compiled=compiled,
    )


def _link_multiplier_unit(problem: Problem, length_unit: float) -> float:
    """Physical link multiplier per scaled multiplier: W (norm) or W / length_unit (squared)."""
    if problem.formulation is Formulation.NORM:
        return problem.weight
    return problem.weight / length_unit


def _check_finite_obstacles(chain: ScaledChain, z: FloatArray, where: str, point: Point | None = None) -> None:
    """phi must be a finite number with a finite gradient wherever the chain is. ``point``: the
    iterate at ``z`` if already evaluated (node contact: it holds phi and its derivatives).
    Disks, ellipses and half-planes are left out: their phi is a quadratic with finite coefficients
    (``quadratic_coefficients``), finite wherever the chain is (8 numpy calls a check, four checks a
    solve: 2% of a 50-node solve)."""
    if not chain.obstacles or chain.quadratic_coefficients is not None:
        return
    if point is not None and not chain.contact_links:
        phi = point.c[chain.links.size :].reshape(len(chain.obstacles), -1)
        gradient, hessian = point.obstacle_gradient, point.obstacle_hessian
    else:
        phi, gradient, hessian = evaluate_obstacles(chain, z.reshape(-1, 2))
    if np.isfinite(phi).all() and np.isfinite(gradient).all() and _finite_blocks(hessian):
        return
    for j, obstacle in enumerate(chain.obstacles):
        bad = ~(np.isfinite(phi[j]) & np.isfinite(gradient[j]).all(axis=1) & np.isfinite(hessian[j]).all(axis=(1, 2)))
        if np.any(bad):
            node = int(chain.free[np.argmax(bad)])
            raise ScenarioError(
                f"obstacle {obstacle.name!r}: phi or its derivatives are not finite at node {node} {where}; "
                "phi must be twice differentiable wherever the chain can go."
            )


def _finite_blocks(hessian: FloatArray) -> bool:
    """Every Hessian block finite; a broadcast view (constant Hessians) is checked block by block."""
    blocks = hessian[:, :1] if hessian.shape[1] and hessian.strides[1] == 0 else hessian
    return bool(np.isfinite(blocks).all())


def _newton_direction(
    chain: ScaledChain, point: Point, solve: Solve, s: FloatArray, mu: FloatArray, r_c: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(dz, ds, dmu) of the condensed Newton system for complementarity residual ``r_c``."""
    if chain.compiled and not chain.contact_links:  # the same formulas in two passes (fused.newton_*)
        rhs = np.empty(2 * chain.free.size)
        gradient = point.obstacle_gradient
        jit(fused.newton_rhs)(
            point.q, chain.link_row, chain.free, gradient, point.dual_residual, point.c, s, mu, r_c, rhs
        )
        dz = solve(rhs)
        dmu, ds = np.empty_like(mu), np.empty_like(mu)
        jit(fused.newton_update)(point.q, chain.links, chain.free_index, gradient, dz, point.c, s, mu, r_c, dmu, ds)
        return dz, ds, dmu
    sigma = mu / s
    r_p = point.c + s
    rhs = -(point.dual_residual.ravel() + jacobian_transpose_times(chain, point, sigma * r_p - r_c / s))
    dz = solve(rhs)
    dmu = sigma * (jacobian_times(chain, point, dz) + r_p) - r_c / s
    ds = -(r_c + s * dmu) / mu
    return dz, ds, dmu


def _active_set(s: FloatArray, mu: FloatArray, unit: FloatArray) -> np.ndarray:
    """Constraints whose multiplier outweighs their slack, ``mu > s * unit`` (``_active_units``)."""
    active: np.ndarray = mu > s * unit
    return active


def _active_units(chain: ScaledChain, row_units: FloatArray) -> FloatArray:
    """``_active_set``'s multiplier per unit of slack, each constraint measured in its natural unit:
    a link's tension against the total weight and its slack against its own length, a contact
    force against a node's weight (slacks are lengths in link units). Comparing raw ``mu > s``
    would miss every contact of a long chain, whose contact forces are O(1/N) of the weight, and
    take every link 100 times shorter than the longest for taut. (``row_units``: ``_row_units``.)"""
    n_links = chain.links.size
    unit = row_units.copy()
    unit[:n_links] = unit[:n_links] ** 2 / chain.lengths[chain.links]
    loads = chain.load[chain.free]
    # (sum / size: np.mean's wrapper costs 10 us)
    node_weight = float(loads.sum()) / loads.size if (loads > 0).any() else 1.0 / max(chain.free.size, 1)
    unit[n_links:] = node_weight * ACTIVE_CONTACT
    return unit


def _polish(
    chain: ScaledChain,
    z: FloatArray,
    mu: FloatArray,
    tolerance: _Tolerance,
    active: np.ndarray,
    start: Point | None = None,
    max_steps: int = POLISH_STEPS,
) -> Polished | None:
    """Newton on the active-set KKT system (see ``polish``), with active-set corrections: a
    constraint the step violates joins the set, one whose multiplier turns negative leaves it.

    Stops at the first point that meets ``tolerance`` (each further step costs as much as an
    interior-point step, for digits nobody asked for) and returns it with its step count and its
    evaluation, or ``None`` if no point does. Counting only steps after which the active set
    stayed the same, gives up after two such steps that multiply the error by POLISH_DIVERGENCE, or POLISH_PATIENCE
    such steps that never beat the starting error: the guess was bad, and correcting it did not
    help; after ``max_steps``; and after POLISH_CORRECTING steps of any kind that never beat it (a guess that misses
    most of a long contact is corrected in steps of ever smaller gains, each as dear as an
    interior-point step, while two of those would give a good guess). ``active``: the active set to
    start from (the iterate's, ``_active_set``, or a coarse level's); ``start``: the point evaluated
    at ``z`` with those multipliers, if already at hand (``mu`` zero off ``active``).
    """
    mu = np.where(active, mu, 0.0)
    point = evaluate(chain, z, mu) if start is None else start
    start_error = _kkt_error(chain, point, mu)
    best_error = np.inf
    diverging = settled = 0
    n_links = chain.links.size
    for steps in range(1, max_steps + 1):
        step = polish_step(chain, point, mu, active)
        if step is None:
            break
        z, mu = step
        point = evaluate(chain, z, mu)
        done, error = tolerance.check(chain, point, mu)
        if done:
            return z, mu, steps, point
        best_error = min(best_error, error)
        if steps >= POLISH_CORRECTING and not best_error < start_error:
            break
        leaving = active & (mu < 0.0)
        joining = ~active & (point.c > tolerance.plain)
        # Judge the guess only on steps that kept the active set: while it is still being corrected
        # (a long chain's contacts can take a dozen steps) the error says little.
        if not np.any(leaving | joining):
            settled += 1
            diverging = diverging + 1 if not error < POLISH_DIVERGENCE * start_error else 0
            if diverging == 2 or (settled >= POLISH_PATIENCE and not best_error < start_error):
                break
        if np.any(leaving[n_links:]):
            shape = (len(chain.obstacles), chain.n_contact_rows)
            touching, nu = active[n_links:].reshape(shape), mu[n_links:].reshape(shape)
            lifting = _lifting_off(touching, nu, leaving[n_links:].reshape(shape))
            leaving[n_links:] = lifting.ravel() & ~joining[n_links:]  # a node the step pushed inside stays in
        active = (active | joining) & ~leaving
        mu = np.where(active, mu, 0.0)
    return None


def _lifting_off(active: np.ndarray, nu: FloatArray, leaving: np.ndarray) -> np.ndarray:
    """``leaving`` (n_obstacles, rows) with, at each end of a run of touching nodes, as many nodes
    as the end's negative force says the run is too long.

    Where a chain lifts off an obstacle, a run of touching nodes k nodes too long holds the chain
    on the obstacle over those k nodes, and only its last node feels it: its force is the kink's,
    ``nu_end = nu_0 (1 - k)`` in units of the force ``nu_0`` on the touching nodes just inside (on a
    disk of radius R, ``nu_0 = T h (1/R - kappa)`` and the kink ``T k h (1/R - kappa)``, kappa the free
    chain's curvature; on flat ground ``nu_0`` is the node's weight). Dropping ``floor(1 - nu_end /
    nu_0)`` nodes at once finds the lift-off point in one step instead of one node per step
    (rounded down: one too few costs a step, one too many lets the chain sag into the obstacle and
    two). A leaving node inside a run, or without touching neighbours to compare with, leaves alone;
    no more than half the run leaves at once. (A run can be far too long: started from an active
    set that misses most of the contact, the first step pushes the chain into the obstacle and every
    node it pushed in joins; at 10^6 nodes, 14,000 too many at one end.)"""
    lifting = leaving.copy()
    for j in range(active.shape[0]):
        edges = np.flatnonzero(np.diff(np.concatenate(([False], active[j], [False])).astype(np.int8)))
        first, last = edges[0::2], edges[1::2] - 1  # each run of touching nodes, both ends included
        runs = (first < last) & (leaving[j, first] | leaving[j, last])
        for a, b in zip(first[runs].tolist(), last[runs].tolist(), strict=True):
            # (end node, the touching nodes 2..11 inside it, the run's nodes from that end inwards)
            for end, inside, run in (
                (a, nu[j, a + 2 : min(a + 12, b + 1)], slice(a, b + 1)),
                (b, nu[j, max(b - 11, a) : b - 1], slice(b, a - 1 if a > 0 else None, -1)),
            ):
                reference = fused.median(inside) if inside.size else 0.0
                if leaving[j, end] and reference > 0.0:
                    drop = max(1, int(min(1.0 - nu[j, end] / reference, (b - a + 1) // 2)))
                    lifting[j, run][:drop] = True
    return lifting


def _rounding_floor(chain: ScaledChain) -> float:
    """The smallest scaled KKT residual floating point can certify. A node X link lengths from
    the origin is only placed to eps * X link lengths, so a link's direction, and the force it
    applies, is only known to that relative accuracy: X is ~N for a long chain (1.5e-10 at
    N = 10^6) and ~1e6 for a chain moved 1e6 link lengths away. ROUNDING_FLOOR covers the few
    such errors that add up in one residual. Negligible for chains of up to 10^4 nodes whose forces
    are of the order of their weight; ``_Tolerance`` multiplies it by the largest force."""
    if not chain.positions.size:
        return 0.0
    # The farthest node from the physical origin lies on the positions' bounding box (column by
    # column: numpy reduces an (N, 2) array along axis 0 nine times slower).
    origin: list[float] = (chain.origin / chain.length_unit).tolist()
    x0, y0 = origin
    x, y = chain.positions[:, 0], chain.positions[:, 1]
    extent = max(abs(float(x.min()) + x0), abs(float(x.max()) + x0), abs(float(y.min()) + y0), abs(float(y.max()) + y0))
    return ROUNDING_FLOOR * EPS * extent


@dataclass(frozen=True)
class _Tolerance:
    """When the iteration may stop: every scaled KKT residual below ``tol`` (``SolverOptions.tol``)
    or below the rounding floor (``_rounding_floor``), whichever is larger. For the polish's points
    the floor of the force residuals is multiplied by the largest force at the point, in units of
    the weight (at least 1; ``mu / unit``, see ``_row_units``): a direction known to eps X turns a
    force F into a residual of eps X F, and a taut cable of 10^4 nodes pulling with 120 times its
    weight stalled at 2e-10 against a floor of 7e-12 (and ran to max_iterations). A link's
    overstretch, a length, keeps the plain floor; so does the interior-point method's own test,
    since its multipliers can be far from the solution's forces."""

    tol: float
    floor: float
    unit: FloatArray

    @property
    def plain(self) -> float:
        return max(self.tol, self.floor)

    def check(self, chain: ScaledChain, point: Point, mu: FloatArray) -> tuple[bool, float]:
        """Whether the polished ``point`` with multipliers ``mu`` is done, and its KKT error
        (``_kkt_error``)."""
        forces, lengths = _kkt_parts(chain, point, mu)
        error = max(forces, lengths)  # (both NaN if either is: _kkt_parts)
        if not lengths <= self.plain or not forces > self.plain:  # (the forces only matter if too large)
            return error <= self.plain, error
        largest = float(np.max(np.abs(mu) / self.unit, initial=1.0))
        return math.isfinite(largest) and forces <= self.floor * largest, error


def _barrier_weights(chain: ScaledChain) -> FloatArray:
    """The share of the barrier each constraint gets: a link's scaled length, 1 for a contact."""
    weight = np.ones(chain.n_constraints)
    weight[: chain.links.size] = chain.lengths[chain.links]
    return weight


def _row_units(chain: ScaledChain) -> FloatArray:
    """Each constraint's multiplier per unit of force (total weight): 1 for a norm link or a contact,
    ``1 / l_k`` for a squared link (``grad c_k = 2 delta_k``, of size ``2 l_k`` when taut)."""
    unit = np.ones(chain.n_constraints)
    if chain.formulation is Formulation.SQUARED:
        unit[: chain.links.size] = 1.0 / chain.lengths[chain.links]
    return unit


def _cold_start(
    chain: ScaledChain, c: FloatArray, weight: FloatArray, unit: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Slacks and multipliers without any knowledge of the forces (``c``: the constraint values;
    ``unit``: ``_row_units``)."""
    m = chain.n_constraints
    mu = INITIAL_MULTIPLIER * unit
    s = np.maximum(-c, MIN_INITIAL_SLACK * weight / unit)
    # Contacts start on the central path of the links' complementarity: a node far from an
    # obstacle gets a tiny contact force instead of one the size of the whole weight.
    n_links = chain.links.size
    if m > n_links:
        tau = fused.median((s * mu / weight)[:n_links]) if n_links else MIN_INITIAL_SLACK
        mu[n_links:] = np.minimum(INITIAL_MULTIPLIER, tau / s[n_links:])
    return s, mu


def _warm_start(
    chain: ScaledChain, c: FloatArray, weight: FloatArray, guess: FloatArray, unit: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Slacks and multipliers near a guess of the multipliers (from a coarser chain); ``c``: the
    constraint values.

    Every product s_i mu_i starts at WARM_CENTRING: active constraints keep their multipliers and
    get small slacks, inactive ones keep their slacks and get small multipliers.
    """
    s = np.maximum(-c, WARM_SLACK * weight / unit)
    mu = np.maximum(guess, WARM_CENTRING * weight / s)
    s = np.maximum(s, WARM_CENTRING * weight / mu)
    return s, mu


class _Rows(NamedTuple):
    """Per-constraint constants of a chain (they do not depend on its positions, so the saddle
    escape's solves from a moved chain take them from the first solve): ``_row_units``,
    ``_barrier_weights`` and their sum, ``_active_units``."""

    units: FloatArray
    weight: FloatArray
    total_weight: float
    active_unit: FloatArray


def _rows(chain: ScaledChain, units: FloatArray | None = None) -> _Rows:
    """The chain's ``_Rows`` (``units``: its ``_row_units``, if already made)."""
    units = _row_units(chain) if units is None else units
    weight = _barrier_weights(chain)
    return _Rows(units, weight, float(weight.sum()), _active_units(chain, units))


def _iterate(
    chain: ScaledChain, options: SolverOptions, multipliers: FloatArray | None = None, rows: _Rows | None = None
) -> tuple[FloatArray, FloatArray, int, Status, Point]:
    """The driver loop: free positions (flat), link multipliers, Newton steps (interior-point and
    polish), status and the point evaluated at the result. ``multipliers`` (scaled), if given, is a
    guess to start from; ``rows``: the chain's ``_rows``, if already at hand."""
    z = chain.positions[chain.free].ravel()
    row_units = _row_units(chain) if rows is None else rows.units
    tolerance = _Tolerance(options.tol, _rounding_floor(chain), row_units)
    if multipliers is None and _loop_compiles(chain, options):
        # The compiled loop evaluates the start and makes its slacks and multipliers itself
        # (``driver._cold_start``); its obstacles are quadratics, finite wherever the chain is.
        _, weight, total_weight, active_unit = rows or _rows(chain, row_units)
        return _compiled_loop(chain, options, tolerance, (z, None, None), (weight, total_weight), active_unit)
    guess = np.zeros(chain.n_constraints) if multipliers is None else np.maximum(multipliers, 0.0)
    point = evaluate(chain, z, guess)
    _check_finite_obstacles(chain, z, "of the initial guess", point)
    if multipliers is not None:
        # A coarser chain's answer knows the active set (its taut links and touching nodes, to a few
        # nodes where the chain lifts off): polish from the start, before any interior-point step.
        # At 10^6 nodes with the disk 3 polish steps instead of 3 interior-point and 4 polish steps.
        polished = _polish(chain, z, guess, tolerance, guess > 0, start=point, max_steps=POLISH_FROM_GUESS)
        if polished is not None:
            return *polished[:3], Status.OPTIMAL, polished[3]
    # Per-constraint constants, made once (after the polish above: 30 ms at 10^6 nodes).
    _, weight, total_weight, active_unit = rows or _rows(chain, row_units)
    if multipliers is None:
        s, mu = _cold_start(chain, point.c, weight, row_units)
    else:
        s, mu = _warm_start(chain, point.c, weight, multipliers, row_units)
    if _loop_compiles(chain, options):  # (from a coarse level's multipliers: _warm_start)
        return _compiled_loop(chain, options, tolerance, (z, s, mu), (weight, total_weight), active_unit)
    point = evaluate(chain, z, mu)
    linear_solver = options.linear_solver or default_linear_solver(chain.compiled)
    regularization = 0.0
    penalty = 1.0

    # After a failed polish, retry only once the active set has changed or the error has halved.
    failed_polish: tuple[np.ndarray, float] | None = None
    previous_error = np.inf
    for iteration in range(options.max_iterations + 1):
        if not (np.isfinite(z).all() and np.isfinite(mu).all() and np.isfinite(s).all()):
            return z, mu, iteration, Status.NONFINITE, point
        error = _kkt_error(chain, point, mu)
        active = _active_set(s, mu, active_unit)
        retry = failed_polish is None or error < failed_polish[1] / 2 or np.any(active != failed_polish[0])
        # Polishing too early guesses the active set wrongly and wastes whole Newton steps; the
        # interior-point steps can only go so far (rounding in mu / s), so a stall also triggers it.
        # (Without obstacles the active set is the taut links, settled early: a tenfold larger error will do.)
        polish_from = POLISH_FROM if chain.obstacles else 10.0 * POLISH_FROM
        ready = error <= polish_from or (error <= POLISH_STALLED and error > 0.1 * previous_error)
        previous_error = error
        if ready and retry:
            # Near the solution a few active-set Newton steps take the residuals to rounding level.
            polished = _polish(chain, z, mu, tolerance, active)
            if polished is not None:
                return polished[0], polished[1], iteration + polished[2], Status.OPTIMAL, polished[3]
            failed_polish = (active, error)
        if error <= tolerance.plain:
            return z, mu, iteration, Status.OPTIMAL, point
        if iteration == options.max_iterations:
            break
        # The merit's penalty grows to make each step a descent direction (_barrier_line_search)
        # and decays by PENALTY_DECAY per step. Kept for good, a single long step at a massless node
        # (its barrier slope in the thousands) left it at 1e10: the merit became ||c + s||^2 alone
        # and the iteration crawled, 200 steps at a scaled KKT error of 1e-2. Reset to 1 each step,
        # other chains (links 10 and 0.1 mixed, three obstacles) lost the feasibility they had.
        penalty = max(1.0, penalty / PENALTY_DECAY)
        # One step per call: its Newton matrix and factorization (a few hundred MB at 10^6 nodes)
        # are gone before the next step or a polish allocates its own. An iterate gone far astray
        # can overflow a merit or a residual: that inf is rejected like any other non-finite value
        # (line searches, NONFINITE), and numpy's warning must not reach the user.
        with np.errstate(over="ignore"):
            taken = _interior_point_step(
                chain, (z, s, mu, point), weight, total_weight, linear_solver, regularization, penalty
            )
        if isinstance(taken, Status):
            if taken is Status.STALLED:
                polished = _polish(chain, z, mu, tolerance, _active_set(s, mu, active_unit))
                if polished is not None:
                    return polished[0], polished[1], iteration + polished[2], Status.OPTIMAL, polished[3]
            return z, mu, iteration, taken, point
        (z, s, mu, point), regularization, penalty = taken
    return z, mu, options.max_iterations, Status.MAX_ITERATIONS, point


def _loop_compiles(chain: ScaledChain, options: SolverOptions) -> bool:
    """Whether ``driver`` can run the whole loop: every per-iteration term has a compiled kernel
    (``ScaledChain.driver_arrays``) and the linear solver is the default."""
    return chain.driver_arrays is not None and options.linear_solver is None


@functools.cache
def _driver_constants() -> FloatArray:
    """The ``settings`` of ``driver.interior_point_steps`` that are this module's constants (the
    tolerance, the floor and the iteration limit are the solve's)."""
    driver = compiled_driver()
    constants = {
        driver.POLISH_FROM: POLISH_FROM,
        driver.POLISH_STALLED: POLISH_STALLED,
        driver.PENALTY_DECAY: PENALTY_DECAY,
        driver.STEP_TO_BOUNDARY: STEP_TO_BOUNDARY,
        driver.CENTRING_FLOOR: CENTRING_FLOOR,
        driver.CENTRALITY: CENTRALITY,
        driver.ARMIJO: ARMIJO,
        driver.MAX_BACKTRACKS: MAX_BACKTRACKS,
        driver.TINY: TINY,
        driver.POLISH_STEPS: POLISH_STEPS,
        driver.POLISH_PATIENCE: POLISH_PATIENCE,
        driver.POLISH_CORRECTING: POLISH_CORRECTING,
        driver.POLISH_DIVERGENCE: POLISH_DIVERGENCE,
        driver.PROXIMAL: PROXIMAL,
        driver.INITIAL_MULTIPLIER: INITIAL_MULTIPLIER,
        driver.MIN_INITIAL_SLACK: MIN_INITIAL_SLACK,
    }
    settings = np.zeros(driver.SETTINGS)
    settings[list(constants)] = list(constants.values())
    settings.flags.writeable = False
    return settings


def _compiled_loop(
    chain: ScaledChain,
    options: SolverOptions,
    tolerance: _Tolerance,
    start: tuple[FloatArray, FloatArray | None, FloatArray | None],
    weights: tuple[FloatArray, float],
    active_unit: FloatArray,
) -> tuple[FloatArray, FloatArray, int, Status, Point]:
    """The loop of ``_iterate`` run by the compiled ``driver.interior_point_steps`` from ``start``
    (z, s, mu; s and mu None for the driver's cold start), with ipm's polish wherever the driver
    leaves it to ipm. ``weights``: the barrier weights and their sum."""
    driver = compiled_driver()
    kernel = jit(driver.interior_point_steps)
    assert chain.driver_arrays is not None  # (_loop_compiles)
    arrays, quadratic = chain.driver_arrays
    settings = _driver_constants().copy()
    settings[driver.TOL], settings[driver.FLOOR] = tolerance.plain, tolerance.floor  # (not a fancy index: 3 us)
    settings[driver.MAX_ITER] = options.max_iterations
    polish_arrays = (tolerance.unit, chain.quadratic_hessians, *chain.polish_workspace)
    # iteration, error, previous error, penalty, regularization, polish steps
    numbers = np.array([0.0, math.nan, math.inf, 1.0, 0.0, 0.0])
    z, given_s, given_mu = start
    if given_s is None or given_mu is None:
        cold, s, mu = True, np.zeros(0), np.zeros(0)
    else:
        cold, s, mu = False, given_s, given_mu
    failed_active, failed, check_polish = np.zeros(chain.n_constraints, dtype=bool), False, True
    weight, total_weight = weights
    while True:
        code, (z, s, mu, values) = kernel(
            arrays,
            quadratic,
            settings,
            weight,
            total_weight,
            active_unit,
            polish_arrays,
            failed_active,
            failed,
            check_polish,
            cold,
            z,
            s,
            mu,
            numbers,
        )
        cold = False
        iteration = int(numbers[driver.ITERATION])
        if code == driver.POLISHED:
            steps = iteration + int(numbers[driver.POLISH_TAKEN])
            return z, mu, steps, Status.OPTIMAL, driver_point(chain, values)
        # The compiled polish met a step its elimination cannot take: this polish falls back to the
        # banded LU for it (``polish_step``).
        if code in (driver.POLISH, driver.STALLED):
            active = _active_set(s, mu, active_unit)
            polished = _polish(chain, z, mu, tolerance, active)
            if polished is not None:
                return polished[0], polished[1], iteration + polished[2], Status.OPTIMAL, polished[3]
            if code == driver.POLISH:
                failed_active, failed, settings[driver.FAILED_ERROR] = active, True, numbers[driver.ERROR]
                check_polish = False
                continue
        if code == driver.NOT_FACTORED:
            raise np.linalg.LinAlgError("the Newton matrix stayed indefinite under every inertia correction")
        status = {
            driver.OPTIMAL: Status.OPTIMAL,
            driver.MAX_ITERATIONS: Status.MAX_ITERATIONS,
            driver.STALLED: Status.STALLED,
            driver.STUCK: Status.STALLED,
            driver.NONFINITE: Status.NONFINITE,
        }[code]
        return z, mu, iteration, status, driver_point(chain, values)


def _interior_point_step(
    chain: ScaledChain,
    state: State,
    weight: FloatArray,
    total_weight: float,
    linear_solver: LinearSolver,
    regularization: float,
    penalty: float,
) -> tuple[State, float, float] | Status:
    """One predictor-corrector step from ``state``: the new state (multipliers recentred), the
    inertia correction and merit penalty to carry on with; or NONFINITE (multipliers diverging
    against vanishing slacks) or STALLED (no line search accepts a step). ``weight``: the barrier
    weights (``_barrier_weights``), ``total_weight`` their sum."""
    z, s, mu, point = state
    with np.errstate(over="ignore"):
        sigma = mu / s
    if not np.isfinite(sigma).all():
        return Status.NONFINITE
    matrix = newton_matrix(chain, point, mu, sigma)
    if not matrix.is_finite():  # an obstacle's infinite gradient or curvature here
        return Status.NONFINITE
    solve, regularization = _factor(matrix, linear_solver, regularization)
    del matrix
    tau = float(s @ mu) / total_weight

    # Mehrotra predictor: the pure Newton (affine) step decides how much to centre.
    products = s * mu
    _, ds_a, dmu_a = _newton_direction(chain, point, solve, s, mu, products)
    alpha_p, alpha_d = _step_to_boundary(s, ds_a, chain.compiled), _step_to_boundary(mu, dmu_a, chain.compiled)
    tau_affine = float((s + alpha_p * ds_a) @ (mu + alpha_d * dmu_a)) / total_weight
    target = min(1.0, (tau_affine / tau) ** 3) * tau if tau > 0 else 0.0
    # Do not let the barrier fall faster than the iterate approaches stationarity and feasibility:
    # on non-convex obstacles an aggressive target jams the slacks against their bounds.
    target = max(target, min(tau, CENTRING_FLOOR * _infeasibility(point)))
    targets = target * weight

    # Globalisation. Convex chain (no obstacles): the KKT residual first, fast near the solution;
    # where it has a spurious local minimum (folded, degenerate chains), LOQO's barrier merit.
    # With obstacles the residual also has minima at saddles and maxima of the energy, so the
    # barrier merit, which follows the energy downhill, goes first. Mehrotra's corrected step
    # first; the plain centred step when the correction spoils descent.
    searches: tuple[LineSearch, ...] = (_barrier_line_search, _residual_line_search)
    if not chain.obstacles:
        searches = searches[::-1]
    for correction in (ds_a * dmu_a, 0.0):
        step = _newton_direction(chain, point, solve, s, mu, products + correction - targets)
        for search in searches:
            accepted = search(chain, state, step, targets, penalty)
            if accepted is not None:
                (z, s, mu, point), penalty = accepted
                return (z, s, _recentred(s, mu, weight, total_weight), point), regularization, penalty
    return Status.STALLED


def _factor(matrix: BlockTridiagonal, linear_solver: LinearSolver, previous: float) -> tuple[Solve, float]:
    """Factor ``matrix + delta I``; grow delta until it is positive definite (inertia correction)."""
    scale = max(matrix.max_diagonal(), 1e-300)
    delta = 0.0 if previous == 0.0 else previous / 4.0
    while True:
        try:
            return linear_solver(matrix.shifted(delta + 1e-14 * scale)), (0.0 if delta < 1e-12 * scale else delta)
        except np.linalg.LinAlgError:
            delta = max(1e-10 * scale, 10.0 * delta)
            if not delta <= 1e20 * scale:  # (a NaN scale never grows past the bound; infinite matrices
                # are kept out by _interior_point_step, where delta = inf <= inf would loop)
                raise


def _barrier_line_search(
    chain: ScaledChain,
    state: State,
    step: tuple[FloatArray, FloatArray, FloatArray],
    tau: FloatArray,
    penalty: float,
) -> tuple[State, float] | None:
    """Backtrack the primal step on the merit; the dual takes its full step to the boundary."""
    z, s, mu, point = state
    dz, ds, dmu = step
    alpha_p, alpha_d = _step_to_boundary(s, ds, chain.compiled), _step_to_boundary(mu, dmu, chain.compiled)
    r_p = point.c + s
    infeasibility = float(r_p @ r_p)
    slope_barrier = float(chain.load[chain.free_at] @ dz.reshape(-1, 2)[:, 1]) - float(tau @ (ds / s))
    if slope_barrier > 0.0 and infeasibility > 0.0:  # raise the penalty until we descend
        penalty = max(penalty, 10.0 * slope_barrier / infeasibility)
    slope = slope_barrier - penalty * infeasibility
    current = _merit(chain, point, s, tau, penalty, infeasibility)
    mu_new = mu + alpha_d * dmu
    fraction = 1.0
    for _ in range(MAX_BACKTRACKS):
        alpha = fraction * alpha_p
        z_new, s_new = z + alpha * dz, np.maximum(s + alpha * ds, TINY)
        trial = evaluate(chain, z_new, mu_new)
        value = _merit(chain, trial, s_new, tau, penalty)
        if math.isfinite(value) and value <= current + ARMIJO * alpha * min(slope, 0.0):
            return (z_new, s_new, mu_new, trial), penalty
        fraction *= 0.5
    return None


@dataclass(frozen=True)
class _Guess:
    """A start for the iteration: positions (N, 2) and, when known, physical multipliers."""

    positions: FloatArray
    link_multipliers: FloatArray | None = None  # (N-1,)
    obstacle_multipliers: FloatArray | None = None  # (n_obstacles, N), or (n_obstacles, N-1) per link


def _node_shares(problem: Problem) -> FloatArray:
    """The length of chain each node stands for: half of each link next to it."""
    shares = np.zeros(problem.n_nodes)
    shares[:-1] += 0.5 * problem.link_lengths
    shares[1:] += 0.5 * problem.link_lengths
    return shares


def _coarse_guess(problem: Problem, options: SolverOptions) -> _Guess | None:
    """Grid sequencing for long chains: solve the same chain with fewer nodes (``_coarse_nodes``:
    N/8, with obstacles at most 5,000 or N/32, see COARSE_CAP) and interpolate it
    along the arclength. The coarse chain already drapes over the obstacles, so the fine solve
    starts near its answer instead of travelling there in many short steps. Its forces come along:
    tensions interpolated along the chain, contact forces as a force per length; with them the
    fine level starts with the polish (``_iterate``), and usually needs nothing else: without
    obstacles 1-2 Newton steps at the finest level of 10^5 or 10^6 nodes instead of 6-9."""
    if problem.n_nodes <= (COARSE_ABOVE if problem.obstacles else COARSE_ABOVE_FREE):
        return None
    try:
        coarse = problem.with_nodes(max(COARSE_ABOVE // 2, _coarse_nodes(problem)))
    except ScenarioError:  # two supports would share a coarse node
        return None
    try:
        solution = solve(coarse, options)
    except FunicularError:  # moving a support to a coarse node can make a nearly taut span infeasible
        return None
    if not solution.converged:
        return None
    # with_nodes moves an interior support to the nearest coarse node: line the coarse supports up
    # with the fine ones, or the nodes next to a support start up to half a coarse link off it (and
    # the polish from that guess fails; a 8,001-node three-support chain took 64 steps instead of 3).
    fine_nodes = problem.arc_fractions
    coarse_nodes = np.interp(coarse.arc_fractions, *_support_fractions(coarse, problem, fine_nodes))
    coarse_links = 0.5 * (coarse_nodes[:-1] + coarse_nodes[1:])
    fine_links = 0.5 * (fine_nodes[:-1] + fine_nodes[1:])
    positions = np.empty((problem.n_nodes, 2))
    for d in range(2):
        positions[:, d] = np.interp(fine_nodes, coarse_nodes, solution.positions[:, d])
    tension = np.interp(fine_links, coarse_links, solution.link_tension)
    distances = link_distances(positions)
    link_multipliers = multipliers_from_tension(problem.formulation, tension, distances)
    if not problem.obstacles:
        contact = np.zeros((0, problem.n_nodes))
    elif problem.contact == "links":  # per link: a force per length of link
        density = solution.obstacle_multipliers / coarse.link_lengths
        contact = np.stack([np.interp(fine_links, coarse_links, row) for row in density]) * problem.link_lengths
    else:
        density = solution.obstacle_multipliers / _node_shares(coarse)
        contact = np.stack([np.interp(fine_nodes, coarse_nodes, row) for row in density]) * _node_shares(problem)
    return _Guess(positions, link_multipliers, contact)


def _exact_guess(problem: Problem) -> _Guess | None:
    """The equilibrium with its forces, where ``spans.exact_start`` knows it (a chain touching
    nothing): the polish then only confirms it, in one Newton step, instead of a coarse level or
    some 10 interior-point steps."""
    exact = exact_start(problem)
    if exact is None:
        return None
    positions, tension = exact
    distances = link_distances(positions)
    link_multipliers = multipliers_from_tension(problem.formulation, tension, distances)
    return _Guess(positions, link_multipliers, np.zeros((len(problem.obstacles), _contact_columns(problem))))


def _coarse_nodes(problem: Problem) -> int:
    """How many nodes the coarse level of ``problem`` gets (see COARSE_CAP)."""
    n = problem.n_nodes
    if not problem.obstacles:
        return n // COARSE_FACTOR
    return max(n // COARSE_FACTOR_MAX, min(n // COARSE_FACTOR, COARSE_CAP))


def _support_fractions(coarse: Problem, fine: Problem, fine_fractions: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The supports' arclength fractions on the coarse and on the fine chain (``fine_fractions``:
    its ``arc_fractions``), with both ends: the piecewise-linear map between them takes each coarse
    support onto its fine support."""
    xp = np.concatenate(([0.0], coarse.arc_fractions[coarse.support_nodes], [1.0]))
    fp = np.concatenate(([0.0], fine_fractions[fine.support_nodes], [1.0]))
    first = np.diff(xp, prepend=-1.0) > 0.0  # a support at either end is there twice
    return xp[first], fp[first]


def _scaled_multipliers(problem: Problem, chain: ScaledChain, guess: _Guess) -> FloatArray | None:
    """The guess's physical multipliers in the iteration's units and order (inverse of ``solve``'s)."""
    if guess.link_multipliers is None or guess.obstacle_multipliers is None:
        return None
    scaled = np.empty(chain.n_constraints)
    n_links = chain.links.size
    unit = _link_multiplier_unit(problem, chain.length_unit)
    np.divide(guess.link_multipliers[chain.links_at], unit, out=scaled[:n_links])
    contacts = guess.obstacle_multipliers[:, chain.contact_rows_at] * (chain.obstacle_scale[:, None] / problem.weight)
    scaled[n_links:] = contacts.ravel()
    return scaled


def _contact_columns(problem: Problem) -> int:
    """Contact multipliers per obstacle: one per node (``contact = "nodes"``) or per link (``"links"``)."""
    return problem.n_links if problem.contact == "links" else problem.n_nodes


def _check_segment_shapes(problem: Problem) -> None:
    """contact = "links" needs phi's maximum along a segment, which only the convex built-ins provide."""
    for obstacle in problem.obstacles:
        if not has_segment_max(obstacle):
            raise ScenarioError(
                f"contact = 'links' needs a convex built-in shape (disk, ellipse, box, halfplane), "
                f"but obstacle {obstacle.name!r} is a {type(obstacle).__name__}; use contact = 'nodes' for it."
            )


def solve(
    problem: Problem,
    options: SolverOptions | None = None,
    *,
    tol: float | None = None,
    max_iterations: int | None = None,
    initial_positions: FloatArray | None = None,
) -> Solution:
    """Equilibrium of ``problem`` with its forces (see :class:`funicular.solution.Solution`).

    ``initial_positions`` (N, 2), e.g. a previous solution, replaces the built-in initial guess
    for the free nodes (warm start; it decides which equilibrium a non-convex problem finds).
    Raises :class:`funicular.errors.InfeasibleError` when two supports are farther apart than the
    chain between them, a support lies inside an obstacle, or an exactly taut, non-vertical
    segment would need infinite tension. A solve that does not converge returns a ``Solution``
    whose ``status`` says so.
    """
    options = options or SolverOptions()
    if tol is not None or max_iterations is not None:
        options = replace(
            options,
            tol=options.tol if tol is None else tol,
            max_iterations=options.max_iterations if max_iterations is None else max_iterations,
        )
    escape = options.escape_saddles and bool(problem.obstacles) and problem.contact == "nodes"
    escape = escape and problem.n_nodes <= ESCAPE_UP_TO
    started = time.perf_counter()
    once = _solve_once(problem, options, initial_positions, escape)
    # A solve seeded by a coarse solve starts next to the coarse chain's minimum, which has been
    # checked (and escaped) on its own level: only the coarsest level pays for the check. That the
    # fine solve then ends at a minimum too is expected, not guaranteed (the benchmark's checker
    # confirms it on its chains). One seeded by the exact start touches no obstacle and is the free
    # chain's minimum, which is convex: nothing to check.
    if escape and not once.seeded:
        once, iterations = _escape_saddles(problem, options, once)
    else:
        iterations = once.outcome.iterations
    return once.outcome.solution(iterations, time.perf_counter() - started)


def _compiled(options: SolverOptions) -> bool:
    """Whether a solve runs the compiled loops (``SolverOptions.compiled``)."""
    return HAVE_NUMBA if options.compiled is None else options.compiled


def _escape_saddles(problem: Problem, options: SolverOptions, once: _Once) -> tuple[_Once, int]:
    """Leave a KKT point that is not a minimum (a chain balanced on the symmetric top of an
    obstacle, say): move the chain along a direction of negative curvature (``curvature``, on the
    solver's own Newton matrix; ``judge`` runs it at the result), by ESCAPE_STEP of its length at
    the node that moves most (towards +x first, then the other way), and solve again from there;
    keep the first result with a lower energy. A proven strict local minimum needs no direction.
    The solves from the moved chain reuse the first one's presolve, scaling and per-row constants.
    Returns the solve kept and the Newton steps of all of them."""
    iterations = once.outcome.iterations
    for _ in range(ESCAPES):
        if not once.outcome.converged or once.judge is None:
            break
        verdict = once.judge()
        if verdict.direction is None:
            break
        # An eigenvector's sign is arbitrary: point it towards +x (or +y) so that the same problem
        # (phi scaled, another linear solver) always leaves its saddle the same way.
        direction = verdict.direction
        size = np.abs(direction)
        lean = float(np.sum(direction[:, 0]))
        if abs(lean) <= 1e-6 * float(np.sum(size)):
            lean = float(np.sum(direction[:, 1]))
        direction = direction if lean >= 0.0 else -direction
        step = ESCAPE_STEP * problem.total_length / max(float(np.max(size)), 1e-300)
        lower = 1e-12 * problem.weight * problem.total_length
        for sign in (1.0, -1.0):
            positions = once.outcome.positions + sign * step * direction
            again = _solve_once(problem, options, positions, True, once)
            iterations += again.outcome.iterations
            if again.outcome.converged and again.outcome.objective < once.outcome.objective - lower:
                once = again
                break
        else:
            break
    return once, iterations


@dataclass(frozen=True)
class _Outcome:
    """Where one solve ended, in the problem's units, before its forces are worked out: the saddle
    escape compares and discards solves by their positions and energy alone."""

    problem: Problem
    status: Status
    positions: FloatArray  # (N, 2); massless free ends as the solver left them (``solution`` rests them)
    iterations: int
    start: Presolve
    chain: ScaledChain
    mu: FloatArray  # the solver's multipliers (scaled), empty if no node is free

    @property
    def converged(self) -> bool:
        return self.status is Status.OPTIMAL

    @property
    def objective(self) -> float:
        """Potential energy ``g m^T y`` (``Solution.objective``)."""
        return self.problem.energy(self.positions)

    def solution(self, iterations: int, seconds: float) -> Solution:
        """The :class:`Solution`, its multipliers in the problem's units."""
        problem, chain, mu, positions = self.problem, self.chain, self.mu, self.positions
        distances = link_distances(positions)  # (links between fixed nodes: as presolve placed them)
        detached = self.start.detached
        if detached.size:  # (indexing with empty arrays costs a few microseconds too)
            positions = positions.copy()
            positions[detached] = positions[self.start.attach]
        link_multipliers = multipliers_from_tension(problem.formulation, self.start.fixed_tension, distances)
        obstacle_multipliers = np.zeros((len(problem.obstacles), _contact_columns(problem)))
        if chain.free.size:
            n_links = chain.links.size
            # The iteration's link multipliers are the smooth stand-in's (constraints.py); as the
            # norm's they apply the same force (they differ only on links shorter than r_k, all slack).
            k = chain.links_at
            smoothed = smoothed_tension(problem.formulation, mu[:n_links], distances[k], problem.link_lengths[k])
            link_multipliers[k] = smoothed * _link_multiplier_unit(problem, chain.length_unit)
            # Nothing to copy without obstacles; with contact = "links" the chain's contact rows are
            # then its free nodes, which do not slice the per-link columns (a dangling chain failed).
            if problem.obstacles:
                nu = mu[n_links:].reshape(len(problem.obstacles), chain.n_contact_rows)
                obstacle_multipliers[:, chain.contact_rows_at] = nu * (problem.weight / chain.obstacle_scale[:, None])
        return Solution(
            problem=problem,
            status=self.status,
            positions=positions,
            link_multipliers=link_multipliers,
            obstacle_multipliers=obstacle_multipliers,
            iterations=iterations,
            solve_seconds=seconds,
        )


class _Once(NamedTuple):
    """One solve's outcome, whether it started from a coarse solve, and if asked for (``judged``)
    the escape's second-order test at the result (None where nothing moved) and the chain's
    ``_rows`` (the escape's solves from a moved chain take them, with the outcome's presolve and
    scaled chain)."""

    outcome: _Outcome
    seeded: bool
    judge: Judge | None = None
    rows: _Rows | None = None


def _solve_once(
    problem: Problem,
    options: SolverOptions,
    initial_positions: FloatArray | None,
    judged: bool = False,
    previous: _Once | None = None,
) -> _Once:
    """One solve (interior-point steps, the polish, or both), from ``initial_positions`` or the
    built-in (coarse-to-fine) guess. ``previous``: a judged solve of the same problem, whose
    presolve, scaled chain and rows serve ``initial_positions`` instead of presolving and scaling
    again."""
    if problem.contact == "links":
        _check_segment_shapes(problem)
    if initial_positions is None:
        exact = _exact_guess(problem) if options.exact_start else None
        guess = exact or _coarse_guess(problem, options)
    else:
        guess = _Guess(initial_positions)
    seeded = initial_positions is None and guess is not None
    # Link contact is left out: its step counts from a settled guess went both ways (301 nodes 13
    # steps instead of 6, 2,001 nodes 15 instead of 25).
    settled = seeded and problem.contact == "nodes"
    compiled = _compiled(options)
    if previous is not None and previous.rows is not None and initial_positions is not None:
        start = repositioned(problem, previous.outcome.start, initial_positions, compiled=compiled)
        before = previous.outcome.chain
        chain = before.moved((start.positions - before.origin) / before.length_unit)
        rows: _Rows | None = previous.rows
    else:
        start = presolve(problem, None if guess is None else guess.positions, settled, compiled)
        chain = _scale(problem, start, compiled)
        rows = _rows(chain) if judged else None  # (the escape's solves from a moved chain take them)
    z, mu, iterations, status = np.zeros(0), np.zeros(0), 0, Status.OPTIMAL
    judge: Judge | None = None
    if chain.free.size:
        warm = None if guess is None else _scaled_multipliers(problem, chain, guess)
        del guess  # the coarse chain's answer, interpolated: tens of MB at 10^6 nodes, not needed any more
        z, mu, iterations, status, point = _iterate(chain, options, warm, rows)
        _check_finite_obstacles(chain, z, "of the solution", point)
        if judged:  # (a proof needs a faithful linear solver: not options.linear_solver)
            judge = functools.partial(escape_test, chain, point, mu, default_linear_solver(compiled))
        del point
    positions = start.positions  # (the presolve's own array, not needed any more: no copy)
    if chain.free.size:
        positions[chain.free_at] = chain.physical(z.reshape(-1, 2))
    outcome = _Outcome(problem, status, positions, iterations, start, chain, mu)
    return _Once(outcome, seeded, judge, rows)


__all__ = ["SolverOptions", "solve"]
