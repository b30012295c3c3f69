"""Several equilibria: solve from many seeded starting shapes and group what comes out.

With obstacles the feasible set is not convex, and the equilibrium found depends on the start
(a chain may drape left or right of a peg). ``explore`` perturbs the solver's own initial guess,
and (every other start) its mirror image about the supports' mean x, by a few random smooth
modes along the chain (reproducible from the seed), solves from each,
and groups the converged results whose node positions agree within ``tolerance`` times the
chain length.

The starts are independent: in parallel (a :class:`~funicular.studies._parallel.Pool`) each is a
task, and the grouping is done afterwards in the order of the starts, so the result is the
serial one. A start whose worker died (twice) is listed as failed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from funicular._progress import Advance, no_progress
from funicular._solver import solve
from funicular._solver.initial import net_start, presolve
from funicular._units import force_unit, label, unit
from funicular.model import FloatArray, Problem
from funicular.solution import Solution
from funicular.studies._parallel import Lost, Pool

MODES = 3  # smooth modes sin(k pi s / L), k = 1..MODES, in each coordinate (a net: over its plan)
AMPLITUDE = 0.3  # of the chain length (a net: of its plan's diagonal)
GROUP_TOLERANCE = 1e-6  # positions within this fraction of the chain length are one equilibrium


@dataclass(frozen=True)
class Equilibrium:
    """One distinct equilibrium and how often it was reached."""

    solution: Solution
    starts: int
    verdict: str  # second-order verdict, or "unchecked"

    @property
    def energy(self) -> float:
        return self.solution.objective

    @property
    def max_tension(self) -> float:
        return float(self.solution.link_tension.max(initial=0.0))

    @property
    def total_contact_force(self) -> float:
        return float(np.linalg.norm(self.solution.contact_forces, axis=1).sum())


@dataclass(frozen=True)
class Exploration:
    equilibria: tuple[Equilibrium, ...]  # sorted by energy
    failed: int  # starts whose solve did not converge
    starts: int
    seed: int
    lost: tuple[tuple[int, str], ...] = ()  # (start, what happened) of the starts whose worker died
    units: str | None = None  # the scenario's declared unit system: the table's labels


def starting_shapes(problem: Problem, count: int, seed: int) -> list[FloatArray]:
    """``count`` reproducible starting configurations: the default guess, or its mirror image
    (every other start: a guess that leans one way around an obstacle should not bias them
    all), plus random smooth modes (along a chain's arclength, over a net's plan)."""
    rng = np.random.default_rng(seed)
    if problem.is_chain:
        guess = presolve(problem).positions
        modes = np.sin(np.pi * np.outer(problem.arc_fractions, np.arange(1, MODES + 1)))  # (N, MODES)
        size = problem.total_length
    else:
        # a net: its force-density start, and modes over its plan (the start's bounding box)
        guess = net_start(problem)
        low, high = guess[:, :2].min(axis=0), guess[:, :2].max(axis=0)
        plan = (guess[:, :2] - low) / np.where(high > low, high - low, 1.0)
        k = np.arange(1, MODES + 1)
        modes = np.sin(np.pi * plan[:, :1] * k) * np.sin(np.pi * plan[:, 1:] * k)  # (N, MODES)
        size = float(np.linalg.norm(high - low))
    mirrored = guess.copy()  # about the vertical plane x = the supports' mean x
    mirrored[:, 0] = 2.0 * float(np.mean(problem.support_positions[:, 0])) - guess[:, 0]
    shapes = []
    for start in range(count):
        weights = rng.normal(scale=AMPLITUDE * size / MODES, size=(MODES, guess.shape[1]))
        shapes.append((mirrored if start % 2 else guess) + modes @ weights)
    return shapes


def _same(a: Solution, b: Solution, tolerance: float) -> bool:
    return bool(np.max(np.abs(a.positions - b.positions)) <= tolerance)


@dataclass(frozen=True)
class StartJob:
    """One start as a task: the problem and the starting shape."""

    problem: Problem
    shape: FloatArray
    start: int  # its index among the starts


def solve_start(job: StartJob) -> Solution:
    return solve(job.problem, initial_positions=job.shape)


START_TASK: Callable[[StartJob], Solution] = solve_start  # what a worker runs for a start (tests wrap it)


def explore(
    problem: Problem,
    starts: int,
    seed: int = 0,
    classify: Callable[[Solution], str] | None = None,
    *,
    on_start: Advance = no_progress,
    pool: Pool | None = None,
) -> Exploration:
    """Solve from ``starts`` starting shapes and group the distinct equilibria (lowest energy first).

    ``classify`` gives each equilibrium a second-order verdict (e.g. "strict local minimum").
    ``on_start(1)`` is called as each start is solved (a progress bar); ``pool``: where the starts
    are solved (default: in this process), the result is the same wherever they are.
    """
    tolerance = GROUP_TOLERANCE * problem.total_length
    jobs = [StartJob(problem, shape, start) for start, shape in enumerate(starting_shapes(problem, starts, seed))]
    solutions = (pool or Pool()).run(START_TASK, jobs, lambda index, solution: on_start(1))
    groups: list[tuple[Solution, int]] = []
    failed = 0
    for solution in solutions:  # in the order of the starts: the first of a group represents it
        if isinstance(solution, Lost):
            continue
        if not solution.converged:
            failed += 1
            continue
        for index, (representative, count) in enumerate(groups):
            if _same(representative, solution, tolerance):
                groups[index] = (representative, count + 1)
                break
        else:
            groups.append((solution, 1))
    groups.sort(key=lambda group: group[0].objective)
    equilibria = tuple(
        Equilibrium(solution, count, classify(solution) if classify else "unchecked") for solution, count in groups
    )
    lost = tuple((start, solution.message) for start, solution in enumerate(solutions) if isinstance(solution, Lost))
    return Exploration(equilibria=equilibria, failed=failed, starts=starts, seed=seed, lost=lost, units=problem.units)


def table(exploration: Exploration) -> str:
    """The equilibria as an aligned text table."""
    force = force_unit(exploration)
    energy, tension, contact = (
        label("energy", unit(exploration, "energy")),
        label("max tension", force),
        label("contact force", force),
    )
    wide, wider = max(14, len(tension)), max(14, len(contact))  # (a header with its unit may be longer)
    header = f"{'#':>3}  {energy:>16}  {'starts':>6}  {tension:>{wide}}  {contact:>{wider}}  second order"
    lines = [header, "-" * len(header)]
    for i, eq in enumerate(exploration.equilibria):
        lines.append(
            f"{i:>3}  {eq.energy:>16.10g}  {eq.starts:>6d}  {eq.max_tension:>{wide}.8g}  "
            f"{eq.total_contact_force:>{wider}.8g}  {eq.verdict}"
        )
    lines.append(
        f"{len(exploration.equilibria)} distinct equilibria from {exploration.starts} starts (seed {exploration.seed})"
        + (f"; {exploration.failed} starts did not converge" if exploration.failed else "")
    )
    lines += [f"start {start} failed: {message}" for start, message in exploration.lost]
    return "\n".join(lines)


def to_dict(exploration: Exploration) -> dict[str, object]:
    return {
        "starts": exploration.starts,
        "seed": exploration.seed,
        "failed": exploration.failed,
        "lost": [{"start": start, "message": message} for start, message in exploration.lost],
        "equilibria": [
            {
                "energy": eq.energy,
                "starts": eq.starts,
                "max_tension": eq.max_tension,
                "total_contact_force": eq.total_contact_force,
                "second_order": eq.verdict,
                "solution": eq.solution.to_dict(),
            }
            for eq in exploration.equilibria
        ],
    }


__all__: Sequence[str] = ["Equilibrium", "Exploration", "StartJob", "explore", "starting_shapes", "table"]
