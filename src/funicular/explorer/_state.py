"""The explorer's domain: the page's state (a scenario document as JSON) -> a Problem -> a solve -> the
JSON the page draws, then the checks of that answer. No web framework here, so it is tested and used
without one.

The answer comes in two parts, so that the picture never waits for a check: :func:`solve_state`
gives the equilibrium and its forces, and :func:`check_state`, given the state and the point that
solve found (its positions and multipliers, sent back by the page), gives LICQ and the second order.

The state is a scenario file's document (``name``, ``formulation``, ``gravity``, ``dimension``,
``[chain]`` or ``[net]`` with the links' ``axial_stiffness``, ``[[supports]]``, ``[[loads]]``,
``[[obstacles]]``), so the scenario reader validates it and says what is wrong in the words of a
scenario file. Only the size is checked here first (at most MAX_NODES nodes, counted from the keys
before anything is built).

Every problem, a chain or a net, in the plane or in space, is checked by the checker
(:mod:`funicular.checks`) as ``funicular check`` checks it: LICQ as static determinacy, with the
degree of indeterminacy and the dependent forces (a self-stress) in words where it fails, and the
second-order verdict, the cheap proof of a strict minimum first.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from funicular._solver import solve
from funicular._text import largest_strain
from funicular._uniqueness import multipliers_may_not_be_unique
from funicular._units import multiplier_unit, unit_labels
from funicular.checks import DEFAULT_TOL, licq_of, second_order, statics_of
from funicular.checks._check import not_a_kkt_point
from funicular.checks._files import _point
from funicular.errors import ScenarioError, shown
from funicular.model import FloatArray, Problem
from funicular.nets import grid_nodes, radial_nodes
from funicular.scenario import builtin_scenarios, load_document, parse_scenario, scenario_toml
from funicular.solution import Solution, Status

SOURCE = "the explorer's scenario"
POINT = "the explorer's point to check"
MAX_NODES = 2000  # a solve, LICQ and the page's drawing stay well under a second
PRESETS = {
    "dangling": "A chain hanging from one support: change N with the slider; every link is taut and vertical.",
    "seed-licq": "Three nodes, supports two links apart vertically: LICQ fails, the tensions are not unique.",
    "disk-drape": "A chain draped over a disk: drag or resize the disk and watch the contact forces.",
}


def scenarios() -> dict[str, str]:
    """The built-in scenarios the page can load (every one), with their descriptions."""
    return builtin_scenarios()


def _integer(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _check_size(document: Mapping[str, Any], where: str) -> None:
    """At most MAX_NODES nodes, counted from the keys before anything is built (ScenarioError, one
    sentence naming the key); a mesh file is not read. Keys of the wrong type are left to the reader."""
    chain, net = document.get("chain"), document.get("net")
    if isinstance(chain, Mapping) and _integer(chain.get("nodes")) and chain["nodes"] > MAX_NODES:
        raise ScenarioError(
            f"{where}: chain.nodes = {chain['nodes']} is too large for the explorer; use at most {MAX_NODES}."
        )
    if not isinstance(net, Mapping):
        return
    if "mesh" in net:
        raise ScenarioError(
            f"{where}: net.mesh reads a mesh file, which the explorer does not; use net.grid, net.radial, net.disk "
            "or listed links (funicular report shows a mesh net in 3-D)."
        )
    if _integer(net.get("nodes")) and net["nodes"] > MAX_NODES:
        raise ScenarioError(
            f"{where}: net.nodes = {net['nodes']} is too large for the explorer; use at most {MAX_NODES}."
        )
    grid = net.get("grid")
    if isinstance(grid, list) and len(grid) == 2 and all(_integer(n) for n in grid):
        nodes = grid_nodes(*grid)
        if min(grid) < 2 or nodes > MAX_NODES:
            what = (
                f"makes {nodes} nodes, too many for the explorer"
                if min(grid) >= 2
                else "has fewer than 2 rows or columns"
            )
            raise ScenarioError(
                f"{where}: net.grid = {grid} {what}; use rows and columns of at least 2 with rows x columns at most "
                f"{MAX_NODES} (e.g. [40, 40])."
            )
    for generator in ("radial", "disk"):
        table = net.get(generator)
        if isinstance(table, Mapping) and _integer(table.get("rings")) and _integer(table.get("spokes")):
            nodes = radial_nodes(table["rings"], table["spokes"])
            if nodes > MAX_NODES:
                raise ScenarioError(
                    f"{where}: net.{generator} makes 1 + rings x spokes = {nodes} nodes, too many for the explorer; "
                    f"use at most {MAX_NODES}."
                )


def served_entry(source: str) -> dict[str, str | None]:
    """What the page's scenario menu shows for the scenario ``funicular serve`` was given: a built-in
    by its name (``builtin``), a file (which wins over a built-in of the same name, as the scenario
    reader has it) by its file name (``file``)."""
    if Path(source).is_file():
        return {"builtin": None, "file": Path(source).name}
    return {"builtin": source, "file": None}


def state_of_scenario(source: str) -> dict[str, Any]:
    """The state of a scenario file or built-in (checked: it must build, with at most MAX_NODES nodes)."""
    scenario = load_document(source)
    _check_size(scenario.document, scenario.source)
    scenario.problem()  # (validates: a scenario error names the file)
    state = copy.deepcopy(scenario.document)
    state.setdefault("name", scenario.default_name)
    return state


def problem_of_state(state: object) -> Problem:
    """The problem the page's state describes; ScenarioError (one sentence) for anything malformed."""
    if not isinstance(state, Mapping):
        raise ScenarioError(f"{SOURCE}: the state must be a JSON object (a scenario's tables), got {shown(state)}.")
    _check_size(state, SOURCE)
    return parse_scenario(state, SOURCE)


def _start(value: object, problem: Problem) -> FloatArray | None:
    """The warm start the page sent (the last positions it drew): None if absent, or of another
    number of nodes or dimension (the state has changed shape since)."""
    if value is None:
        return None
    try:
        start = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ScenarioError(f"start must be a list of [x, y] or [x, y, z] points, got {shown(value)}.") from None
    if start.ndim != 2 or start.shape[1] not in (2, 3) or not np.all(np.isfinite(start)):
        raise ScenarioError(f"start must be a list of finite [x, y] or [x, y, z] points, got {shown(value)}.")
    return start if start.shape == (problem.n_nodes, problem.dimension) else None


def solve_state(state: object, start: object = None) -> dict[str, Any]:
    """Solve the state, warm-started from ``start`` when it has the same number of nodes (a warm start
    that does not converge is retried from the built-in start), and return what the page draws
    (:func:`result`; the checks come from :func:`check_state`)."""
    problem = problem_of_state(state)
    initial = _start(start, problem)
    solution = solve(problem, initial_positions=initial)
    if initial is not None and not solution.converged:
        solution = solve(problem)
    return result(solution)


def check_state(state: object, point: object) -> dict[str, Any]:
    """LICQ (or a structure's statics) and the second-order verdict at the converged point a solve of
    ``state`` returned: ``point`` holds its ``positions`` and ``multipliers`` (``link``, and
    ``obstacle`` by name) as :func:`result` gave them. ScenarioError (one sentence) for a malformed
    state or a point of another shape."""
    problem = problem_of_state(state)
    if not isinstance(point, Mapping):
        raise ScenarioError(f"{POINT}: the point must be a JSON object with positions and multipliers.")
    positions, multipliers = _point(problem, dict(point), POINT, DEFAULT_TOL, per_link=problem.contact == "links")
    if multipliers is None:
        raise ScenarioError(f"{POINT}: multipliers is missing; send the link and obstacle multipliers the solve gave.")
    solution = Solution(
        problem=problem,
        status=Status.OPTIMAL,
        positions=positions,
        link_multipliers=multipliers.link,
        obstacle_multipliers=multipliers.obstacle,
        iterations=0,
        solve_seconds=0.0,
    )
    licq, second = _checks(solution)
    return {"licq": licq, "second_order": second}


def _number(value: float) -> float | None:
    """A float JSON can carry (NaN and infinities become null)."""
    return float(value) if math.isfinite(value) else None


def _licq(solution: Solution) -> dict[str, Any]:
    """LICQ in the words of ``funicular check``: the rank of the active constraints, and whether the
    forces are unique (statically determinate) or not (the degree of indeterminacy and the
    dependent forces in words); where some link is elastic, whether its stiffness makes them unique."""
    elastic = solution.problem.axial_stiffness is not None
    # The cheap, certain answer comes first; not for elastic links, whose chain is solved as a net:
    # the net's count of links per node misses two taut links in line at a node, which stretching
    # makes common (seed-licq-elastic).
    if not elastic and not multipliers_may_not_be_unique(solution):
        return {
            "holds": True,
            "text": "holds: the active constraint gradients are independent; statically determinate: the forces "
            "are unique",
        }
    licq = licq_of(solution)
    if licq is None:
        return {"holds": None, "text": "not checked (contact = 'links' or an infeasible point)"}
    if licq.statics is None:
        return {"holds": None, "text": licq.verdict}
    head = f"{'holds' if licq.holds else 'fails'}: rank {licq.rank} of {licq.active_constraints} active constraints"
    meaning = licq.statics
    if elastic and not licq.holds:  # (as funicular check's statics line: the stiffness may decide the forces)
        meaning = statics_of(solution).verdict or meaning
    words = "".join(f" {d.text}" for d in licq.dependencies[:3])
    return {"holds": licq.holds, "text": f"{head}; {meaning}.{words}"}


def _second_order(solution: Solution) -> dict[str, Any]:
    """The check's second-order verdict at a KKT point, the cheap proof of a strict minimum first
    (milliseconds for the nets and chains the explorer takes)."""
    problem = solution.problem
    verdict = not_a_kkt_point(problem, solution.kkt, DEFAULT_TOL) or second_order(problem, solution, proof=True)
    return {"verdict": verdict.verdict, "reason": verdict.reason}


def _checks(solution: Solution) -> tuple[dict[str, Any], dict[str, Any]]:
    return _licq(solution), _second_order(solution)


def _largest_strain(solution: Solution) -> dict[str, Any] | None:
    """The summary's ``max strain`` line as the page shows it: the largest strain of an elastic link,
    its link and stretch, and how many links are elastic; None where none is."""
    problem, k = solution.problem, largest_strain(solution)
    if k is None:
        return None
    return {
        "strain": float(solution.link_strain[k]),
        "link": k,
        "nodes": problem.link_nodes[k].tolist(),
        "stretch": float(solution.link_stretch[k]),
        "elastic": int(np.count_nonzero(problem.elastic)),
    }


def result(solution: Solution) -> dict[str, Any]:
    """The JSON the page draws: the chain or net, its forces and the residuals, with the multipliers
    that :func:`check_state` takes back (``multiplier``: the links'; ``obstacle_multiplier`` by
    obstacle name, per node, or per link with ``contact = "links"``; ``units``: the declared system
    and each quantity's unit, the links' multipliers' too, "" where none is declared: the page's labels).
    Where some link is elastic, ``strain`` holds every link's strain (the page colours the links by it
    on request) and ``max_strain`` the largest (:func:`_largest_strain`); both are None where none is."""
    problem = solution.problem
    kkt = solution.kkt.as_dict()
    tension = solution.link_tension
    loads = problem.loads
    return {
        "name": problem.name,
        "status": solution.status.value,
        "message": solution.status.message,
        "converged": solution.converged,
        "formulation": problem.formulation.value,
        "dimension": problem.dimension,
        "energy": solution.objective,
        "iterations": solution.iterations,
        "kkt": {key: _number(value) for key, value in kkt.items()},
        "positions": solution.positions.tolist(),
        "links": problem.link_nodes.tolist(),
        "tension": tension.tolist(),
        "multiplier": solution.link_multipliers.tolist(),
        "obstacle_multiplier": {
            o.name: nu.tolist() for o, nu in zip(problem.obstacles, solution.obstacle_multipliers, strict=True)
        },
        "taut": solution.link_taut.tolist(),
        "max_tension": float(tension.max(initial=0.0)),
        "strain": None if problem.axial_stiffness is None else solution.link_strain.tolist(),
        "max_strain": _largest_strain(solution),
        "length": float(problem.link_lengths.sum()),
        "mass": float(problem.masses.sum()),
        "reactions": [
            {"node": int(node), "force": force.tolist()}
            for node, force in zip(problem.support_nodes, solution.support_reactions, strict=True)
        ],
        "contacts": [
            {"node": i, "force": force.tolist()}
            for i, force in enumerate(solution.contact_forces)
            if np.any(force != 0)
        ],
        "loads": [] if loads is None else [{"node": int(i), "force": loads[i].tolist()} for i in problem.loaded_nodes],
        "units": {**unit_labels(problem), "multiplier": multiplier_unit(problem, problem.formulation.value)},
    }


def toml_of_state(state: object) -> str:
    """The state as a scenario file that ``funicular solve`` reads back to the same problem."""
    text = scenario_toml(problem_of_state(state))
    if text is None:  # (the state holds scenario tables only, so every obstacle can be written)
        raise ScenarioError(f"{SOURCE}: an obstacle cannot be written to a scenario file.")
    return text
