"""The chain solver: presolve, scaling, the solver core's iteration, coarse-to-fine sequencing,
the saddle escape, and the forces in the problem's units.

The iteration itself (a primal-dual interior-point method with Mehrotra's predictor-corrector,
two line searches, inertia correction and an active-set polish, O(N) per step) runs in the
compiled core, :mod:`funicular._core` (``rust/core``); its module documentation describes the
method. This module prepares its input (:mod:`funicular.solver.chain`), chooses where it starts
(the exact catenary of a chain touching nothing, a coarser chain's answer, or the presolve's
guess), asks the core's second-order test at an equilibrium on an obstacle and leaves a saddle,
and turns the core's scaled multipliers into the problem's forces.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from funicular import _core
from funicular.constraints import link_distances, multipliers_from_tension, smoothed_tension
from funicular.errors import FunicularError, ParameterError, ScenarioError, SolverError
from funicular.model import FloatArray, Formulation, IntArray, Problem
from funicular.obstacles import Obstacle, has_segment_max, link_contact_ends
from funicular.solution import Solution, Status
from funicular.solver.chain import ScaledChain
from funicular.solver.initial import Presolve, as_slice, core_chain, presolve, repositioned
from funicular.solver.spans import exact_start

COARSE_ABOVE = 200  # chains with obstacles longer than this start from a coarse solve (_coarse_guess)
COARSE_FACTOR = 8
# With obstacles the fine level spends a step correcting the contact near the lift-off points
# whatever the coarse level (they move by a few coarse links from level to level), so a coarse
# level finer than it needs costs more than it saves: it has N / COARSE_FACTOR nodes up to
# COARSE_CAP, then COARSE_CAP until that is N / COARSE_FACTOR_MAX. Without obstacles a finer
# coarse level does pay.
COARSE_CAP = 5000
COARSE_FACTOR_MAX = 32
COARSE_ABOVE_FREE = 4000  # the same without obstacles (below, one direct solve is as fast)
ESCAPE_UP_TO = 20_000  # nodes; the second-order check costs about a second at 10^5
ESCAPE_STEP = 0.05  # of the chain length, for the node that moves most
ESCAPES = 2
ESCAPE_TOL = 1e-6  # relative tolerance of the second-order test: the checker's default (checks.DEFAULT_TOL)
SCALE_SAMPLE = 4096  # nodes (_obstacle_scale)
_STATUS = {status.value: status for status in Status}


@dataclass(frozen=True)
class SolverOptions:
    """Settings of the solver.

    tol: stop when every scaled KKT residual (force / total weight, length / longest link) is below it
        (or below the rounding floor ``4 eps X F``, if that is larger, where X is the largest
        coordinate in link lengths and F the largest force in units of the weight, at least 1: a
        node 1e6 link lengths from the origin cannot be placed to better than 1e-10 of a link, and
        a link pulling with 100 times the weight turns that into 1e-8 of the weight).
    max_iterations: give up (status ``max_iterations``) after this many Newton steps.
    escape_saddles: with obstacles (node contact, up to ESCAPE_UP_TO nodes), check the second-order
        conditions at the result (on the solver's own Newton matrix) and, at a saddle, move off it
        and solve again (``_escape_saddles``). A chain solved coarse-to-fine is checked on its
        coarsest level only: each finer level starts next to the minimum the level below found.
    exact_start: start a chain that touches nothing from its discrete catenary with its tensions
        (``spans.exact_start``), which the polish then confirms in one Newton step. False: the
        general path (interior-point steps, coarse to fine), e.g. to watch the method work.
    """

    tol: float = 1e-10
    max_iterations: int = 200
    escape_saddles: bool = True
    exact_start: bool = True


@dataclass(frozen=True)
class Curvature:
    """The escape's second-order test: ``minimum`` (a proven strict local minimum) or a
    ``direction`` of negative curvature ``value`` (scaled units), a unit vector of moves (N, 2),
    zero at the fixed nodes; or neither."""

    minimum: bool
    direction: FloatArray | None = None
    value: float = math.nan


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
    return float(np.median(norms)) if norms.size else 1.0


def _scale(problem: Problem, start: Presolve) -> ScaledChain:
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
        obstacles=problem.obstacles,
        obstacle_scale=np.array(
            [_obstacle_scale(o, start.positions, free, g) for o, g in zip(problem.obstacles, gradients, strict=True)]
        ),
        length_unit=length_unit,
        origin=origin,
        quadratics=problem.quadratic_obstacles,
        contact_links=contact_links,
        contact_ends=link_contact_ends(problem.is_support) if contact_links else None,
    )


def _link_multiplier_unit(problem: Problem, length_unit: float) -> float:
    """Physical link multiplier per scaled multiplier: W (norm) or W / length_unit (squared)."""
    if problem.formulation is Formulation.NORM:
        return problem.weight
    return problem.weight / length_unit


def _iterate(
    chain: ScaledChain, network: _core.Network, options: SolverOptions, multipliers: FloatArray | None
) -> tuple[FloatArray, FloatArray, int, Status]:
    """The core's iteration from the chain's positions (and the scaled ``multipliers``, a guess):
    free positions (flat), multipliers, Newton steps and status."""
    z = np.ascontiguousarray(chain.positions[chain.free].ravel())
    guess = None if multipliers is None else np.ascontiguousarray(multipliers, dtype=np.float64)
    status, z, mu, iterations, detail = network.iterate(z, guess, float(options.tol), int(options.max_iterations))
    if status == "not_factored":
        raise SolverError("the Newton matrix stayed indefinite under every inertia correction")
    if status == "obstacle_not_finite" and detail is not None:
        obstacle, row, at_start = detail
        node = int((chain.links if chain.contact_links else chain.free)[row])
        where = "of the initial guess" if at_start else "of the solution"
        what = f"link {node}" if chain.contact_links else f"node {node}"
        raise ScenarioError(
            f"obstacle {chain.obstacles[obstacle].name!r}: phi or its derivatives are not finite at {what} {where}; "
            "phi must be twice differentiable wherever the chain can go."
        )
    return z, mu, iterations, _STATUS[status]


@dataclass(frozen=True)
class _Guess:
    """A start for the iteration: positions (N, 2) and, when known, physical multipliers."""

    positions: FloatArray
    link_multipliers: FloatArray | None = None  # (N-1,)
    obstacle_multipliers: FloatArray | None = None  # (n_obstacles, N), or (n_obstacles, N-1) per link
    statistics: Mapping[str, float] = field(default_factory=dict)  # the solves that made it (coarse levels)


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
    return _Guess(positions, link_multipliers, contact, solution.statistics)


def _exact_guess(problem: Problem, presolver: _core.Chain) -> _Guess | None:
    """The equilibrium with its forces, where ``spans.exact_start`` knows it (a chain touching
    nothing): the polish then only confirms it, in one Newton step, instead of a coarse level or
    some 10 interior-point steps."""
    exact = exact_start(problem, presolver)
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


def _add(total: dict[str, float], more: Mapping[str, float]) -> None:
    """Adds the core's statistics ``more`` into ``total``."""
    for key, value in more.items():
        total[key] = total.get(key, 0.0) + value


def _check_options(options: SolverOptions) -> None:
    """The settings a solve can work with, checked before any work."""
    if not (isinstance(options.tol, (int, float)) and options.tol > 0 and math.isfinite(options.tol)):
        raise ParameterError(f"tol must be a positive finite number, not {options.tol!r}.")
    if not (isinstance(options.max_iterations, int) and options.max_iterations >= 0):
        raise ParameterError(f"max_iterations must be a whole number >= 0, not {options.max_iterations!r}.")


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
    segment would need infinite tension; :class:`funicular.errors.SolverError` when the Newton
    matrix stays indefinite under every inertia correction. A solve that does not converge returns a ``Solution``
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
    _check_options(options)
    started = time.perf_counter()
    once = _solve_once(problem, options, initial_positions, escape)
    # A solve seeded by a coarse solve starts next to the coarse chain's minimum, which has been
    # checked (and escaped) on its own level: only the coarsest level pays for the check. That the
    # fine solve then ends at a minimum too is expected, not guaranteed (the benchmark's checker
    # confirms it on its chains). One seeded by the exact start touches no obstacle and is the free
    # chain's minimum, which is convex: nothing to check.
    if escape and not once.seeded:
        once, iterations, statistics = _escape_saddles(problem, options, once)
    else:
        iterations, statistics = once.outcome.iterations, dict(once.outcome.statistics)
    return once.outcome.solution(iterations, time.perf_counter() - started, statistics)


def _escape_saddles(problem: Problem, options: SolverOptions, once: _Once) -> tuple[_Once, int, dict[str, float]]:
    """Leave a KKT point that is not a minimum (a chain balanced on the symmetric top of an
    obstacle, say): move the chain along a direction of negative curvature (``curvature``, on the
    solver's own Newton matrix; ``judge`` runs it at the result), by ESCAPE_STEP of its length at
    the node that moves most (towards +x first, then the other way), and solve again from there;
    keep the first result with a lower energy. A proven strict local minimum needs no direction.
    The solves from the moved chain reuse the first one's presolve and scaling.
    Returns the solve kept, and the Newton steps and the core's statistics of all of them."""
    iterations, statistics = once.outcome.iterations, dict(once.outcome.statistics)
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
            _add(statistics, again.outcome.statistics)
            if again.outcome.converged and again.outcome.objective < once.outcome.objective - lower:
                once = again
                break
        else:
            break
    return once, iterations, statistics


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
    statistics: Mapping[str, float]  # the core's (``_core.Network.statistics``), coarse levels included

    @property
    def converged(self) -> bool:
        return self.status is Status.OPTIMAL

    @property
    def objective(self) -> float:
        """Potential energy ``g m^T y`` (``Solution.objective``)."""
        return self.problem.energy(self.positions)

    def solution(self, iterations: int, seconds: float, statistics: Mapping[str, float] | None = None) -> Solution:
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
            statistics=self.statistics if statistics is None else statistics,
        )


class _Once(NamedTuple):
    """One solve's outcome, the problem as the core's presolve saw it, whether it started from a
    coarse solve, and if asked for (``judged``) the escape's second-order test at the result (None
    where nothing moved)."""

    outcome: _Outcome
    presolver: _core.Chain
    seeded: bool
    judge: _Judge | None = None


def _solve_once(
    problem: Problem,
    options: SolverOptions,
    initial_positions: FloatArray | None,
    judged: bool = False,
    previous: _Once | None = None,
) -> _Once:
    """One solve from ``initial_positions`` or the built-in (coarse-to-fine) guess. ``previous``: a
    judged solve of the same problem, whose presolve and scaling serve ``initial_positions``
    instead of presolving and scaling again."""
    if problem.contact == "links":
        _check_segment_shapes(problem)
    # the problem as the core's presolve and exact start see it (made once, reused by the escape)
    presolver = previous.presolver if previous is not None else core_chain(problem)
    if initial_positions is None:
        exact = _exact_guess(problem, presolver) if options.exact_start else None
        guess = exact or _coarse_guess(problem, options)
    else:
        guess = _Guess(initial_positions)
    seeded = initial_positions is None and guess is not None
    # Link contact is left out: its step counts from a settled guess went both ways.
    settled = seeded and problem.contact == "nodes"
    if previous is not None and initial_positions is not None:
        start = repositioned(problem, previous.outcome.start, initial_positions, chain=presolver)
        before = previous.outcome.chain
        chain = before.moved((start.positions - before.origin) / before.length_unit)
    else:
        start = presolve(problem, None if guess is None else guess.positions, settled, presolver)
        chain = _scale(problem, start)
    z, mu, iterations, status = np.zeros(0), np.zeros(0), 0, Status.OPTIMAL
    statistics = dict(guess.statistics) if guess is not None else {}
    judge: _Judge | None = None
    if chain.free.size:
        warm = None if guess is None else _scaled_multipliers(problem, chain, guess)
        del guess  # the coarse chain's answer, interpolated: tens of MB at 10^6 nodes, not needed any more
        network = chain.core()
        z, mu, iterations, status = _iterate(chain, network, options, warm)
        _add(statistics, network.statistics)
        if judged:
            judge = _Judge(chain, network, z, mu)
    positions = start.positions  # (the presolve's own array, not needed any more: no copy)
    if chain.free.size:
        positions[chain.free_at] = chain.physical(z.reshape(-1, 2))
    outcome = _Outcome(problem, status, positions, iterations, start, chain, mu, statistics)
    return _Once(outcome, presolver, seeded, judge)


class _Judge(NamedTuple):
    """The core's second-order test at one result (``ESCAPE_TOL``), run only if the escape asks."""

    chain: ScaledChain
    network: _core.Network
    z: FloatArray
    mu: FloatArray

    def __call__(self) -> Curvature:
        verdict, value, vector = self.network.escape(self.z, self.mu, ESCAPE_TOL, float(self.chain.lengths.sum()))
        if verdict != "direction":
            return Curvature(minimum=verdict == "minimum")
        moves = np.zeros_like(self.chain.positions)
        moves[self.chain.free_at] = vector.reshape(-1, 2)
        return Curvature(minimum=False, direction=moves, value=float(value))


__all__ = ["SolverOptions", "solve"]
