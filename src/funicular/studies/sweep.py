"""``funicular sweep``: solve a scenario over a range (or a grid) of one or two of its values.

A KEY is a dotted path into the scenario's TOML document, with ``[i]`` for array entries:
``chain.length``, ``chain.nodes``, ``supports[1].position[0]``, ``obstacles[0].radius``,
``gravity``. It must exist in the scenario, and hold a number. ``START:STOP:COUNT`` gives COUNT
evenly spaced values from START to STOP (COUNT = 1: START alone); an integer key (``chain.nodes``)
takes integer values only. Each step edits a copy of the document, re-parses it (so every
scenario check applies) and solves, warm-started from the previous step's equilibrium when the
node count is the same (for two keys: the previous step along the second key, or at the start of
a row the first step of the row before). A warm-started solve that does not converge (typically
where the previous branch ends in a fold) is repeated from the default guess; the step's message
says so. A step that still fails to converge, or whose values make the scenario invalid or
infeasible, is marked and the sweep goes on.

Jumps between equilibria. Let ``delta_i`` be the largest distance any node moves from the
previous converged step of the row to step i (both converged, same node count; steps that failed
in between are skipped). Step i is flagged as a jump when

* ``delta_i`` is larger than the moves of the neighbouring steps (``delta_{i-1}`` and
  ``delta_{i+1}``, where they exist): a local maximum;
* ``delta_i > JUMP_FACTOR * median`` of the moves of up to ``JUMP_WINDOW`` steps either side of
  step i (step i itself excluded): the chain moves several times more in that step than it
  typically does around it;
* ``delta_i > JUMP_FLOOR * L`` (L: the chain length): by a visible amount.

On a smooth branch ``delta`` changes slowly from step to step, so this picks out a switch to
another equilibrium; it needs at least two moves in the row (three converged steps) to judge
anything. Why the median and not the larger neighbour: right after a jump the new branch can
itself move fast, and one fast neighbour must not hide the jump. ``disk-drape`` with its disk moved
sideways across the middle in steps of 0.01 switches between its two mirror-image drapes with a
move of 0.127 (0.0929 in steps of 0.0005: a genuine discontinuity), but the step after it moves
0.038, so "more than 4 x both neighbours" missed it. Why the local maximum: a steep step next to a
jump (the branch steepens like a square root as it approaches a fold) is not a second jump.

In parallel (a :class:`~funicular.studies._parallel.Pool` of processes or a Dask cluster) the
warm starts stay as they are, so the results are the serial ones, bit for bit: the first step of
every row is solved first, in the calling process, down the rows (each warm-started from the one
above), then each row is one task, its steps warm-started one from the next. A one-key sweep is a
single row, so a single task. A row whose worker died (twice) has its steps after the first marked
``failed``.
"""

from __future__ import annotations

import copy
import itertools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from funicular._progress import Advance, no_progress
from funicular._solver import solve
from funicular._units import Quantity, declared, force_unit, label, unit
from funicular.errors import FunicularError, ScenarioError
from funicular.model import FloatArray, Problem
from funicular.plot import save_figure
from funicular.scenario import ScenarioDocument
from funicular.solution import Solution
from funicular.studies import format_number, format_table
from funicular.studies._parallel import Lost, Pool

JUMP_FACTOR = 4.0
JUMP_FLOOR = 0.01
JUMP_WINDOW = 2  # moves on each side whose median a jump is compared with
CONTACT_RTOL = 1e-8  # a node is in contact when its contact force exceeds this fraction of the weight
JUMP_RULE = (
    "the largest node move since the previous converged step exceeds the moves of the neighbouring steps, "
    f"{JUMP_FACTOR:g} x the median move of the {JUMP_WINDOW} steps either side and {JUMP_FLOOR:g} x the chain length"
)

KeyPath = tuple[str | int, ...]  # a key split into table names and array indices


@dataclass(frozen=True)
class Parameter:
    """One ``--set KEY=START:STOP:COUNT``: the key, its path in the document, and its values."""

    key: str
    path: KeyPath
    values: tuple[float, ...]


@dataclass
class SweepStep:
    """The outcome of one step (``status``: a solver status, ``invalid``, ``infeasible``, or ``failed``:
    the worker solving it died)."""

    values: tuple[float, ...]
    status: str
    message: str = ""
    energy: float | None = None
    max_tension: float | None = None
    contact_force: float = 0.0  # sum over nodes of |contact force|
    contacts: int = 0
    taut_links: int | None = None
    jump: bool = False
    move: float | None = None  # delta: largest node displacement since the previous step of the row
    positions: FloatArray | None = field(default=None, repr=False)
    length: float = math.nan

    @property
    def converged(self) -> bool:
        return self.status == "optimal"

    @property
    def force_columns(self) -> tuple[float, int, int | None]:
        return self.contact_force, self.contacts, self.taut_links

    def as_dict(self, keys: list[str]) -> dict[str, Any]:
        return {
            "values": dict(zip(keys, self.values, strict=True)),
            "status": self.status,
            "message": self.message,
            "energy": self.energy,
            "max_tension": self.max_tension,
            "contact_force": self.contact_force,
            "contacts": self.contacts,
            "taut_links": self.taut_links,
            "largest_move": self.move,
            "jump": self.jump,
        }


@dataclass(frozen=True)
class Sweep:
    name: str
    parameters: list[Parameter]
    rows: list[list[SweepStep]]  # one row per value of the first key (a single row for one key)
    units: str | None = None  # the scenario's declared unit system: the table's and plot's labels

    @property
    def steps(self) -> list[SweepStep]:
        return [step for row in self.rows for step in row]

    def as_dict(self) -> dict[str, Any]:
        keys = [p.key for p in self.parameters]
        return {
            "scenario": self.name,
            "parameters": [{"key": p.key, "values": list(p.values)} for p in self.parameters],
            "jump_rule": JUMP_RULE,
            "steps": [step.as_dict(keys) for step in self.steps],
        }


# --------------------------------------------------------------------------- parsing --set
def parse_key(key: str) -> KeyPath:
    """``"supports[1].position[0]"`` -> ``("supports", 1, "position", 0)``."""
    path: list[str | int] = []
    for piece in key.split("."):
        match = re.fullmatch(r"([A-Za-z0-9_-]+)((?:\[\d+\])*)", piece)
        if match is None:
            raise ScenarioError(
                f"--set: {key!r} is not a key path; write it like chain.length or supports[1].position[0]."
            )
        path.append(match[1])
        path.extend(int(index) for index in re.findall(r"\[(\d+)\]", match[2]))
    return tuple(path)


def parse_range(text: str) -> tuple[str, float, float, int]:
    """``"KEY=START:STOP:COUNT"`` -> (KEY, START, STOP, COUNT)."""
    usage = f"--set {text!r}: expected KEY=START:STOP:COUNT, e.g. chain.length=1.2:2.0:9."
    key, equals, spec = text.partition("=")
    pieces = spec.split(":")
    if not equals or not key.strip() or len(pieces) != 3:
        raise ScenarioError(usage)
    try:
        start, stop = float(pieces[0]), float(pieces[1])
        count = int(pieces[2])
    except ValueError:
        raise ScenarioError(usage) from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise ScenarioError(f"--set {text!r}: START and STOP must be finite numbers.")
    if count < 1:
        raise ScenarioError(f"--set {text!r}: COUNT = {count}; a sweep needs at least 1 value.")
    return key.strip(), start, stop, count


def _shown(path: KeyPath) -> str:
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else part)
    return text


def lookup(document: dict[str, Any], path: KeyPath, key: str) -> Any:
    """The value at ``path``; a ScenarioError if any part of it is not in the document."""
    value: Any = document
    for depth, part in enumerate(path):
        here = _shown(path[: depth + 1])
        if isinstance(part, str):
            if isinstance(value, list):  # (obstacles.0.radius, say: an entry is named by its index)
                array, entries = _shown(path[:depth]), "1 entry" if len(value) == 1 else f"{len(value)} entries"
                raise ScenarioError(
                    f"--set {key}: {array} is an array ({entries}); name an entry by its index, as in {array}[0]."
                )
            if not isinstance(value, dict) or part not in value:
                raise ScenarioError(
                    f"--set {key}: {here} does not exist in the scenario; only keys it sets can be swept."
                )
        elif not isinstance(value, list) or part >= len(value):
            size = f"it has {len(value)} entries" if isinstance(value, list) else "it is not an array"
            raise ScenarioError(f"--set {key}: {here} does not exist in the scenario ({size}).")
        value = value[part]
    return value


def assign(document: dict[str, Any], path: KeyPath, value: float) -> None:
    """Set the value at ``path`` (which :func:`lookup` has checked)."""
    parent: Any = document
    for part in path[:-1]:
        parent = parent[part]
    parent[path[-1]] = value


def parameter(document: dict[str, Any], text: str) -> Parameter:
    """Parse one ``--set`` against the scenario document."""
    key, start, stop, count = parse_range(text)
    path = parse_key(key)
    current = lookup(document, path, key)
    if isinstance(current, bool) or not isinstance(current, (int, float)):
        raise ScenarioError(f"--set {key}: the scenario's value {current!r} is not a number, so it cannot be swept.")
    values = np.linspace(start, stop, count).tolist()
    if isinstance(current, int):
        whole = [round(v) for v in values]
        if any(abs(v - w) > 1e-9 * max(1.0, abs(v)) for v, w in zip(values, whole, strict=True)):
            raise ScenarioError(
                f"--set {key}: {key} takes integers, but {start:g}:{stop:g}:{count} gives "
                f"{', '.join(format_number(v, 4) for v in values)}."
            )
        values = whole
    return Parameter(key=key, path=path, values=tuple(values))


def parameters_of(document: dict[str, Any], settings: list[str]) -> list[Parameter]:
    """The one or two ``--set`` texts of a sweep, parsed and checked against the scenario document."""
    if not 1 <= len(settings) <= 2:
        raise ScenarioError(f"give one or two --set KEY=START:STOP:COUNT, not {len(settings)}.")
    parameters = [parameter(document, text) for text in settings]
    if len(parameters) == 2 and parameters[0].path == parameters[1].path:
        raise ScenarioError(f"--set {parameters[0].key} is given twice; sweep two different keys.")
    return parameters


# --------------------------------------------------------------------------- the sweep
COLD_RESTART = "the warm start did not converge; solved from the default initial guess"


def _measure(values: tuple[float, ...], problem: Problem, solution: Solution) -> SweepStep:
    contact = np.linalg.norm(solution.contact_forces, axis=1)
    return SweepStep(
        values=values,
        status=solution.status.value,
        message="" if solution.converged else solution.status.message,
        energy=solution.objective,
        max_tension=float(np.max(solution.link_tension, initial=0.0)),
        contact_force=float(contact.sum()),
        contacts=int(np.count_nonzero(contact > CONTACT_RTOL * problem.force_scale)),
        taut_links=int(np.count_nonzero(solution.link_taut)),
        positions=solution.positions,
        length=problem.total_length,
    )


def run_step(
    scenario: ScenarioDocument,
    parameters: list[Parameter],
    values: tuple[float, ...],
    start: SweepStep | None,
    adjust: Callable[[Problem], Problem],
    tol: float,
) -> SweepStep:
    """Edit, re-parse and solve one step, warm-started from ``start`` when it fits."""
    document = copy.deepcopy(scenario.document)
    for p, value in zip(parameters, values, strict=True):
        assign(document, p.path, value)
    try:
        problem = adjust(ScenarioDocument(document, scenario.source, scenario.default_name).problem())
    except ScenarioError as error:
        return SweepStep(values=values, status="invalid", message=str(error))
    warm = None
    if start is not None and start.positions is not None and start.positions.shape[0] == problem.n_nodes:
        warm = start.positions
    try:
        solution = solve(problem, tol=tol, initial_positions=warm)
        restarted = warm is not None and not solution.converged
        if restarted:
            # At a fold the warm start's branch ends, and the solve can wander; the default guess,
            # which knows nothing of that branch, usually converges (to some equilibrium).
            solution = solve(problem, tol=tol)
    except FunicularError as error:
        return SweepStep(values=values, status="infeasible", message=str(error))
    step = _measure(values, problem, solution)
    if restarted and solution.converged:
        step.message = COLD_RESTART
    return step


def largest_move(before: SweepStep, after: SweepStep) -> float | None:
    """The largest distance a node moves from ``before`` to ``after`` (None unless both have equal N)."""
    if before.positions is None or after.positions is None:
        return None
    if before.positions.shape != after.positions.shape:
        return None
    return float(np.max(np.linalg.norm(after.positions - before.positions, axis=1)))


def flag_jumps(row: list[SweepStep]) -> None:
    """Set ``move`` and ``jump`` on the steps of one row (the rule in the module docstring)."""
    converged = [step for step in row if step.converged]
    for before, after in itertools.pairwise(converged):
        after.move = largest_move(before, after)
    moved = [(step, step.move) for step in converged if step.move is not None]
    moves = [move for _, move in moved]
    for i, (step, move) in enumerate(moved):
        neighbours = moves[max(i - 1, 0) : i] + moves[i + 1 : i + 2]
        window = moves[max(i - JUMP_WINDOW, 0) : i] + moves[i + 1 : i + 1 + JUMP_WINDOW]
        step.jump = (
            bool(neighbours)
            and move > JUMP_FLOOR * step.length
            and all(move > other for other in neighbours)
            and move > JUMP_FACTOR * float(np.median(window))
        )


def _unchanged(problem: Problem) -> Problem:
    return problem


@dataclass(frozen=True)
class RowJob:
    """One row of a sweep as a task: its steps' values, and its first step, already solved."""

    scenario: ScenarioDocument
    parameters: tuple[Parameter, ...]
    values: tuple[tuple[float, ...], ...]  # of every step of the row, the first included
    first: SweepStep
    adjust: Callable[[Problem], Problem]  # picklable, for workers: a top-level function or a partial of one
    tol: float
    row: int  # its index among the rows


def solve_row(job: RowJob, on_step: Advance = no_progress) -> list[SweepStep]:
    """The steps of ``job``'s row after the first, each warm-started from the row's last converged step."""
    row = [job.first]
    for values in job.values[1:]:
        start = next((step for step in reversed(row) if step.converged), None)
        row.append(run_step(job.scenario, list(job.parameters), values, start, job.adjust, job.tol))
        on_step(1)
    return row[1:]


ROW_TASK: Callable[[RowJob], list[SweepStep]] = solve_row  # what a worker runs for a row (tests wrap it)


def sweep(
    scenario: ScenarioDocument,
    settings: list[str],
    *,
    adjust: Callable[[Problem], Problem] = _unchanged,
    tol: float = 1e-10,
    on_step: Advance = no_progress,
    pool: Pool | None = None,
) -> Sweep:
    """Sweep one or two values of ``scenario`` (``settings``: the ``--set`` texts).

    ``adjust`` maps each parsed problem before it is solved (the command line's --nodes and
    --formulation); ``on_step(count)`` is called as steps finish (a progress bar). ``pool``: where
    the rows are solved (default: in this process); the result is the same wherever they are.
    """
    parameters = parameters_of(scenario.document, settings)
    outer = parameters[0].values if len(parameters) == 2 else (None,)
    grid = [tuple((v,) if first is None else (first, v) for v in parameters[-1].values) for first in outer]
    firsts: list[SweepStep] = []
    for values in grid:  # down the first column, each step warm-started from the one above
        start = firsts[-1] if firsts and firsts[-1].converged else None
        firsts.append(run_step(scenario, parameters, values[0], start, adjust, tol))
        on_step(1)
    jobs = [
        RowJob(scenario, tuple(parameters), values, first, adjust, tol, row)
        for row, (values, first) in enumerate(zip(grid, firsts, strict=True))
    ]
    pool = pool or Pool()
    if pool.runs_here(len(jobs)):  # (step by step, for the progress bar)
        rests: list[list[SweepStep] | Lost] = [solve_row(job, on_step) for job in jobs]
    else:
        rests = pool.run(ROW_TASK, jobs, lambda index, rest: on_step(len(jobs[index].values) - 1))
    rows: list[list[SweepStep]] = []
    for job, rest in zip(jobs, rests, strict=True):
        if isinstance(rest, Lost):
            rest = [SweepStep(values=values, status="failed", message=rest.message) for values in job.values[1:]]
        rows.append([job.first, *rest])
        flag_jumps(rows[-1])
    units = declared(scenario.document.get("units"))
    return Sweep(name=scenario.default_name, parameters=parameters, rows=rows, units=units)


# --------------------------------------------------------------------------- output
def sweep_table(result: Sweep) -> str:
    force = force_unit(result)
    headers = [p.key for p in result.parameters]
    headers += ["status", label("energy", unit(result, "energy")), label("max tension", force)]
    headers += [label("contact force", force), "contacts", "taut links", "jump"]
    rows = [
        [*step.values, step.status, step.energy, step.max_tension, *step.force_columns, "JUMP" if step.jump else ""]
        for step in result.steps
    ]
    return format_table(headers, rows)


def sweep_text(result: Sweep) -> str:
    steps = result.steps
    failed = [step for step in steps if not step.converged]
    lines = [f"{result.name}: sweep of {' x '.join(p.key for p in result.parameters)} ({len(steps)} steps)", ""]
    lines.append(sweep_table(result))
    lines.append("")
    lines.append("  contact force: sum over nodes of |force the obstacles exert|; contacts: nodes touching an obstacle")
    lines.append(f"  JUMP: {JUMP_RULE}")
    for step in failed:
        where = ", ".join(f"{p.key} = {format_number(v)}" for p, v in zip(result.parameters, step.values, strict=True))
        lines.append(f"  not solved at {where}: {step.status}: {step.message}")
    return "\n".join(lines)


QUANTITIES: tuple[tuple[str, str, Quantity | None], ...] = (  # each drawn quantity, its label, its unit's quantity
    ("energy", "energy g m^T y", "energy"),
    ("max_tension", "max tension", "force"),
    ("contact_force", "total contact force", "force"),
    ("taut_links", "taut links", None),
)


def draw_sweep(result: Sweep, figure: Any) -> None:
    """One panel per quantity against the last key (one curve per value of the first key, for two)."""
    axes = figure.subplots(len(QUANTITIES), 1, sharex=True)
    last = result.parameters[-1]
    for ax, (name, axis_label, quantity) in zip(axes, QUANTITIES, strict=True):
        for row in result.rows:
            x = np.array([step.values[-1] for step in row], dtype=np.float64)
            y = np.array(
                [np.nan if getattr(step, name) is None or not step.converged else getattr(step, name) for step in row],
                dtype=float,
            )  # (a step that was not solved has no value to draw: it is marked below instead)
            curve_label = None
            if len(result.parameters) == 2:
                curve_label = f"{result.parameters[0].key} = {format_number(row[0].values[0], 4)}"
            (line,) = ax.plot(x, y, ".-", label=curve_label)
            failed = [step.values[-1] for step in row if not step.converged]
            if failed:  # on a strip along the bottom edge, apart from the data (their values mean nothing)
                ax.plot(
                    failed,
                    np.full(len(failed), 0.04),
                    "x",
                    color="crimson",
                    markersize=8,
                    transform=ax.get_xaxis_transform(),
                    label="not solved" if ax is axes[0] and row is result.rows[0] else None,
                )
            for before, step in itertools.pairwise(row):
                if step.jump:
                    ax.axvline(0.5 * (before.values[-1] + step.values[-1]), color=line.get_color(), linestyle="--")
        ax.set_ylabel(axis_label if quantity is None else label(axis_label, unit(result, quantity)))
    axes[0].set_title(f"{result.name}: sweep of {last.key} (dashed: jump)")
    if len(result.parameters) == 2 or any(not step.converged for step in result.steps):
        axes[0].legend(fontsize=8)
    axes[-1].set_xlabel(last.key)


def save_sweep_plot(result: Sweep, path: str) -> None:
    save_figure(path, lambda figure: draw_sweep(result, figure), size=(8, 9))
