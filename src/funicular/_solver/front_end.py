"""The solver's front end: the settings, the checks a solve makes before any work, and the
forces in the problem's units.

The solve itself runs in the compiled core, :mod:`funicular._core` (``rust/core``): the presolve,
the start (the exact catenary of a chain that touches nothing, a coarser chain's answer, or the
presolve's guess), the scaling, a primal-dual interior-point method with Mehrotra's
predictor-corrector, two line searches, inertia correction and an active-set polish (O(N) per
step), and the saddle escape at a result on an obstacle. Its module documentation describes the
method; docs/solver.md tells the story.
"""

from __future__ import annotations

import math
import operator
import os
import time
from dataclasses import dataclass, replace

import numpy as np

from funicular import _core
from funicular._constraints import link_distances
from funicular._solver.core_problem import core_chain, core_errors, core_net
from funicular._solver.initial import _check_supports_outside, check_net_reach, checked_guess
from funicular.errors import InfeasibleError, ParameterError, ScenarioError
from funicular.model import MAX_NODES, FloatArray, IntArray, Problem
from funicular.obstacles import HalfPlane, HalfSpace, has_segment_max
from funicular.solution import Solution, Status

_STATUS = {status.value: status for status in Status}
UNREACHABLE = 1e-3  # a diverged iterate's links stretched by more than this are out of the supports' reach


@dataclass(frozen=True)
class SolverOptions:
    """Settings of the solver.

    tol: stop when every scaled KKT residual (force / total weight, length / longest link) is below it
        (or below the rounding floor ``4 eps X F``, if that is larger, where X is the largest
        coordinate in link lengths and F the largest force in units of the weight, at least 1: a
        node 1e6 link lengths from the origin cannot be placed to better than 1e-10 of a link, and
        a link pulling with 100 times the weight turns that into 1e-8 of the weight).
    max_iterations: give up (status ``max_iterations``) after this many Newton steps.
    escape_saddles: with obstacles (node contact, up to ``escape_up_to`` nodes), check the
        second-order conditions at the result (on the solver's own Newton matrix) and, at a saddle,
        move off it along a direction of negative curvature and solve again, keeping the lower
        energy. A chain solved coarse-to-fine is checked on its coarsest level only: each finer
        level starts next to the minimum the level below found.
    escape_up_to: the most nodes of the structure the escape runs on (a chain solved coarse-to-fine:
        its coarsest level); None: 20,000 for a chain and 5,000 for a net. Each solve off a saddle
        starts afresh, so on a large net it takes several times as many steps as the first solve
        (at 100 x 100 nodes about 4 times the time); a larger value buys the lower equilibrium
        where the user will pay for it. Any whole number >= 0 (numpy's too).
    exact_start: start a chain that touches nothing from its discrete catenary with its tensions,
        which the polish then confirms in one Newton step. False: the general path (interior-point
        steps, coarse to fine), e.g. to watch the method work.
    """

    tol: float = 1e-10
    max_iterations: int = 200
    escape_saddles: bool = True
    exact_start: bool = True
    escape_up_to: int | None = None


@dataclass(frozen=True)
class Curvature:
    """The escape's second-order test at a result: ``minimum`` (a proven strict local minimum) or a
    ``direction`` of negative curvature ``value`` (in the solver's units), a unit vector of moves
    (N, 2), zero at the fixed nodes; or neither."""

    minimum: bool
    direction: FloatArray | None = None
    value: float = math.nan


def _check_options(options: SolverOptions) -> None:
    """The settings a solve can work with, checked before any work."""
    if not (isinstance(options.tol, (int, float)) and options.tol > 0 and math.isfinite(options.tol)):
        raise ParameterError(f"tol must be a positive finite number, not {options.tol!r}.")
    if not (isinstance(options.max_iterations, int) and options.max_iterations >= 0):
        raise ParameterError(f"max_iterations must be a whole number >= 0, not {options.max_iterations!r}.")
    threads = os.environ.get("FUNICULAR_THREADS")
    if threads is not None and not (threads.strip().isdigit() and int(threads) >= 1):
        raise ParameterError(
            f"FUNICULAR_THREADS must be a whole number of threads >= 1 (or unset: the cores available), "
            f"not {threads!r}."
        )


def _escape_up_to(options: SolverOptions) -> int | None:
    """The escape's cap as the core takes it (no structure has more than MAX_NODES nodes, so a
    larger cap is the same as MAX_NODES); a ParameterError where it is not a whole number >= 0."""
    up_to = options.escape_up_to
    if up_to is None:
        return None
    try:
        whole = operator.index(up_to) if not isinstance(up_to, (bool, np.bool_)) else -1
    except TypeError:
        whole = -1
    if whole < 0:
        raise ParameterError(f"escape_up_to must be a whole number of nodes >= 0 or None, not {up_to!r}.")
    return min(whole, MAX_NODES)


def _check_segment_shapes(problem: Problem) -> None:
    """contact = "links" needs phi's maximum along a segment, which only the convex built-ins provide."""
    for obstacle in problem.obstacles:
        if not has_segment_max(obstacle):
            raise ScenarioError(
                f"contact = 'links' needs a convex built-in shape (disk, ellipse, box, halfplane), "
                f"but obstacle {obstacle.name!r} is of type {type(obstacle).__name__}; use contact = 'nodes' for it."
            )


def _columns(problem: Problem) -> int:
    """Contact multipliers per obstacle: one per node (``contact = "nodes"``) or per link (``"links"``)."""
    return problem.n_links if problem.contact == "links" else problem.n_nodes


def _convex(problem: Problem) -> bool:
    """Whether the problem is convex (no obstacle but half-planes and half-spaces): then an iteration
    whose forces grow without bound proves that no equilibrium with finite forces exists."""
    return all(isinstance(obstacle, (HalfPlane, HalfSpace)) for obstacle in problem.obstacles)


def _listed(links: IntArray, problem: Problem, most: int = 3) -> str:
    """Links by index and nodes, the first ``most`` of them and how many more."""
    named = [f"{k} (nodes {problem.link_nodes[k, 0]}-{problem.link_nodes[k, 1]})" for k in links[:most]]
    more = f" and {links.size - most} more" if links.size > most else ""
    return (", ".join(named[:-1]) + " and " + named[-1] if len(named) > 1 and not more else ", ".join(named)) + more


def _no_equilibrium(problem: Problem, positions: FloatArray) -> InfeasibleError:
    """Why a convex problem whose forces grew without bound has no equilibrium, from the iterate the
    iteration came nearest to one at: links it could not bring within their lengths (the supports are
    out of their reach), or links at their lengths where they carry weight (their tensions would be
    infinite). Below UNREACHABLE the two cannot be told apart by the iterates, and the sentence gives
    the measured stretch."""
    stretch = link_distances(positions, problem.links) / problem.link_lengths - 1.0
    at_length = np.flatnonzero(stretch > -1e-6)
    at_length = at_length[np.argsort(-stretch[at_length], kind="stable")]
    most = float(stretch[at_length[0]]) if at_length.size else 0.0
    if most > UNREACHABLE:
        ends = np.intersect1d(problem.link_nodes[at_length].ravel(), problem.support_nodes)
        supports = f"the supports at nodes {', '.join(map(str, ends))}" if ends.size else "the supports"
        return InfeasibleError(
            f"no shape of the {problem.kind} keeps every link within its length: links {_listed(at_length, problem)} "
            f"stay stretched (by up to {100 * most:.3g}%), so {supports} are out of the links' reach; "
            "move the supports closer or lengthen the links."
        )
    return InfeasibleError(
        f"no equilibrium with finite forces exists: the {problem.kind} is taut where it carries weight (links "
        f"{_listed(at_length, problem)} are at their lengths, to {100 * max(most, 0.0):.2g}%), so its tensions would "
        "be infinite; lengthen the links or move the supports."
    )


def _solve(
    problem: Problem,
    options: SolverOptions,
    initial_positions: FloatArray | None = None,
    link_multipliers: FloatArray | None = None,
    obstacle_multipliers: FloatArray | None = None,
    settled: bool = False,
    judge: bool = False,
) -> tuple[Solution, Curvature | None]:
    """``solve`` with a start that may carry its multipliers (every link's, and every obstacle's
    contact columns; ``settled``: a solved chain's positions), and if asked for (``judge``) the
    escape's second-order test at the result."""
    _check_options(options)
    escape_up_to = _escape_up_to(options)
    if problem.contact == "links":
        _check_segment_shapes(problem)
    _check_supports_outside(problem)
    check_net_reach(problem)
    guess = checked_guess(problem, initial_positions)
    n = problem.n_nodes

    def flat(array: FloatArray) -> FloatArray:
        # (aligned too: an unpickled array may not be, and the core reads it in place)
        return np.require(array, np.float64, ["C", "A"]).ravel()

    settings = _core.Settings(
        tol=float(options.tol),
        max_iterations=int(options.max_iterations),
        escape_saddles=bool(options.escape_saddles),
        exact_start=bool(options.exact_start),
        escape_up_to=escape_up_to,
    )
    start = None
    if guess is not None:  # (a net starts from its positions only; their multipliers are not used)
        start = _core.Start(
            positions=flat(guess),
            link_multipliers=None if link_multipliers is None else flat(link_multipliers),
            obstacle_multipliers=None if obstacle_multipliers is None else flat(obstacle_multipliers),
            settled=settled,
        )
    started = time.perf_counter()
    with core_errors(problem):
        core = core_chain(problem) if problem.solved_as_chain else core_net(problem)
        answer = core.solve(settings=settings, start=start, judge=judge)
    seconds = time.perf_counter() - started
    positions = answer.positions.reshape(n, problem.dimension)
    if _STATUS[answer.status] is Status.DIVERGED and _convex(problem):
        raise _no_equilibrium(problem, positions)
    solution = Solution(
        problem=problem,
        status=_STATUS[answer.status],
        positions=positions,
        link_multipliers=answer.link_multipliers,
        obstacle_multipliers=answer.obstacle_multipliers.reshape(len(problem.obstacles), _columns(problem)),
        iterations=answer.iterations,
        solve_seconds=seconds,
        statistics=answer.statistics,
    )
    curvature = None
    if answer.curvature is not None:
        judged = answer.curvature
        direction = None if judged.direction is None else judged.direction.reshape(n, problem.dimension)
        curvature = Curvature(minimum=judged.verdict == "minimum", direction=direction, value=float(judged.value))
    return solution, curvature


def solve(
    problem: Problem,
    options: SolverOptions | None = None,
    *,
    tol: float | None = None,
    max_iterations: int | None = None,
    initial_positions: FloatArray | None = None,
) -> Solution:
    """Equilibrium of ``problem`` with its forces (see :class:`funicular.solution.Solution`).

    ``initial_positions`` (N, d), e.g. a previous solution, replaces the built-in initial guess
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
    return _solve(problem, options, initial_positions)[0]


__all__ = ["SolverOptions", "solve"]
