"""The explorer's domain: the page's state (a scenario document as JSON) -> a Problem -> a solve -> the
JSON the page draws. No web framework here, so it is tested and used without one.

The state is a scenario file's document (``name``, ``formulation``, ``gravity``, ``[chain]``,
``[[supports]]``, ``[[obstacles]]``), so the scenario reader validates it and says what is wrong in
the words of a scenario file.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from funicular._solver import solve
from funicular._uniqueness import multipliers_may_not_be_unique
from funicular.checks import licq_of, second_order
from funicular.errors import ScenarioError, shown
from funicular.model import FloatArray, Problem
from funicular.scenario import builtin_scenarios, load_document, parse_scenario, scenario_toml
from funicular.solution import Solution

SOURCE = "the explorer's scenario"
MAX_NODES = 2000  # a solve, LICQ and the page's drawing stay well under a second
SECOND_ORDER_MAX_NODES = 200  # the dense second-order check stays cheap up to here
PRESETS = {
    "dangling": "A chain hanging from one support: change N with the slider; every link is taut and vertical.",
    "seed-licq": "Three nodes, supports two links apart vertically: LICQ fails, the tensions are not unique.",
    "disk-drape": "A chain draped over a disk: drag or resize the disk and watch the contact forces.",
}


def scenarios() -> dict[str, str]:
    """The built-in scenarios the page can load (the planar chains), with their descriptions."""
    return {name: text for name, text in builtin_scenarios().items() if _planar_document(load_document(name).document)}


def _planar_document(document: Mapping[str, Any]) -> bool:
    return "net" not in document and document.get("dimension", 2) == 2


PLANAR_ONLY = (
    "the explorer shows planar chains without point loads; for a net, a chain in space or a chain with point "
    "loads, funicular report gives a report (with an interactive 3-D view in space) and funicular solve --plot "
    "a picture."
)


def state_of_scenario(source: str) -> dict[str, Any]:
    """The state of a scenario file or built-in (checked: it must build a planar chain)."""
    scenario = load_document(source)
    if not scenario.problem().is_planar_chain:
        raise ScenarioError(f"{source}: {PLANAR_ONLY}")
    state = copy.deepcopy(scenario.document)
    state.setdefault("name", scenario.default_name)
    return state


def problem_of_state(state: object) -> Problem:
    """The problem the page's state describes; ScenarioError (one sentence) for anything malformed."""
    if not isinstance(state, Mapping):
        raise ScenarioError(f"{SOURCE}: the state must be a JSON object (a scenario's tables), got {shown(state)}.")
    chain = state.get("chain")
    nodes = chain.get("nodes") if isinstance(chain, Mapping) else None
    if isinstance(nodes, int) and not isinstance(nodes, bool) and nodes > MAX_NODES:
        raise ScenarioError(f"{SOURCE}: chain.nodes = {nodes} is too large for the explorer; use at most {MAX_NODES}.")
    problem = parse_scenario(state, SOURCE)
    if not problem.is_planar_chain:
        raise ScenarioError(f"{SOURCE}: {PLANAR_ONLY}")
    return problem


def _start(value: object, problem: Problem) -> FloatArray | None:
    """The warm start the page sent (the last positions it drew): None if absent or of another N."""
    if value is None:
        return None
    try:
        start = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ScenarioError(f"start must be a list of [x, y] pairs, got {shown(value)}.") from None
    if start.ndim != 2 or start.shape[1:] != (2,) or not np.all(np.isfinite(start)):
        raise ScenarioError(f"start must be a list of finite [x, y] pairs, got {shown(value)}.")
    return start if len(start) == problem.n_nodes else None


def solve_state(state: object, start: object = None) -> dict[str, Any]:
    """Solve the state, warm-started from ``start`` when it has the same number of nodes (a warm start
    that does not converge is retried from the built-in start), and return what the page shows."""
    problem = problem_of_state(state)
    initial = _start(start, problem)
    solution = solve(problem, initial_positions=initial)
    if initial is not None and not solution.converged:
        solution = solve(problem)
    return result(solution)


def _number(value: float) -> float | None:
    """A float JSON can carry (NaN and infinities become null)."""
    return float(value) if math.isfinite(value) else None


def _licq(solution: Solution) -> dict[str, Any]:
    if not multipliers_may_not_be_unique(solution):  # the cheap, certain answer comes first
        return {"holds": True, "text": "holds: the active constraint gradients are independent"}
    licq = licq_of(solution)
    if licq is None:
        return {"holds": None, "text": "not checked (contact = 'links' or an infeasible point)"}
    head = f"rank {licq.rank} of {licq.active_constraints} active constraints"
    if licq.holds:
        return {"holds": True, "text": f"holds: {head}"}
    words = " ".join(d.text for d in licq.dependencies[:3])
    return {"holds": False, "text": f"fails: {head}. {words}"}


def _second_order(solution: Solution) -> dict[str, Any]:
    if solution.problem.n_nodes > SECOND_ORDER_MAX_NODES:
        return {"verdict": "not checked", "reason": f"only checked up to {SECOND_ORDER_MAX_NODES} nodes"}
    verdict = second_order(solution.problem, solution)
    return {"verdict": verdict.verdict, "reason": verdict.reason}


def result(solution: Solution) -> dict[str, Any]:
    """The JSON the page draws: the chain, its forces, the residuals and the checks."""
    problem = solution.problem
    kkt = solution.kkt.as_dict()
    tension = solution.link_tension
    return {
        "name": problem.name,
        "status": solution.status.value,
        "message": solution.status.message,
        "converged": solution.converged,
        "formulation": problem.formulation.value,
        "energy": solution.objective,
        "iterations": solution.iterations,
        "kkt": {key: _number(value) for key, value in kkt.items()},
        "positions": solution.positions.tolist(),
        "tension": tension.tolist(),
        "multiplier": solution.link_multipliers.tolist(),
        "taut": solution.link_taut.tolist(),
        "max_tension": float(tension.max(initial=0.0)),
        "length": float(problem.link_lengths.sum()),
        "mass": float(problem.masses.sum()),
        "reactions": [
            {"node": int(node), "force": force.tolist()}
            for node, force in zip(problem.support_nodes, solution.support_reactions, strict=True)
        ],
        "contacts": [
            {"node": i, "force": force.tolist()}
            for i, force in enumerate(solution.contact_forces)
            if force[0] != 0 or force[1] != 0
        ],
        "licq": _licq(solution) if solution.converged else {"holds": None, "text": "not checked (not converged)"},
        "second_order": _second_order(solution) if solution.converged else None,
    }


def toml_of_state(state: object) -> str:
    """The state as a scenario file that ``funicular solve`` reads back to the same problem."""
    text = scenario_toml(problem_of_state(state))
    if text is None:  # (the state holds scenario tables only, so every obstacle can be written)
        raise ScenarioError(f"{SOURCE}: an obstacle cannot be written to a scenario file.")
    return text
