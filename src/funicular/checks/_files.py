"""Solution files (``funicular solve --json``): reading a point and its multipliers back, and writing
the document with its ``licq`` block."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from funicular._constraints import (
    link_distances,
    multipliers_from_tension,
    tension_from_multipliers,
)
from funicular.checks._check import _check_tol, licq_of
from funicular.checks._report import Multipliers, licq_dict
from funicular.checks._tolerances import DEFAULT_TOL
from funicular.errors import ScenarioError, shown
from funicular.model import FloatArray, Formulation, Problem
from funicular.scenario import problem_from_table, problem_table
from funicular.solution import Solution, Status


# ----------------------------------------------------------------- solution files
def _numbers(document: dict[str, Any], key: str, length: int, source: str, what: str) -> FloatArray:
    value = document.get(key)
    if not isinstance(value, list):
        raise ScenarioError(f"{source}: {key} must be a list of {length} numbers, one per {what}.")
    if len(value) != length:
        raise ScenarioError(
            f"{source}: {key} has {len(value)} entries, but the scenario has {length} {what}s; "
            "is it a solution of this scenario?"
        )
    for i, item in enumerate(value):
        if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
            raise ScenarioError(f"{source}: {key}[{i}] = {shown(item)} is not a finite number.")
    return np.array(value, dtype=np.float64)


SCHEMA_VERSION = 2  # 2: the problem itself is in the file (``problem``), so it can be read back alone


def _document(path: str | Path) -> dict[str, Any]:
    source = str(path)
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as error:
        raise ScenarioError(f"cannot read solution file {source!r}: {error.strerror or error}.") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ScenarioError(f"solution file {source!r} is not valid JSON: {error}.") from None
    if not isinstance(document, dict):
        raise ScenarioError(f"{source}: a solution file must be a JSON object with x and y lists.")
    return document


def _point(
    problem: Problem, document: dict[str, Any], source: str, tol: float, per_link: bool
) -> tuple[FloatArray, Multipliers | None]:
    """Positions and multipliers of ``document`` for ``problem``; obstacle multipliers per link
    (``per_link``: ``contact = "links"``) or per node."""
    n = problem.n_nodes
    positions = np.column_stack([_numbers(document, key, n, source, "node") for key in ("x", "y")])
    offset = positions[problem.support_nodes] - problem.support_positions
    distance = np.hypot(offset[:, 0], offset[:, 1])
    j = int(np.argmax(distance))
    if distance[j] > tol * float(problem.link_lengths.max()):
        node, (x, y) = int(problem.support_nodes[j]), problem.support_positions[j]
        raise ScenarioError(
            f"{source}: node {node} is a support at ({x:g}, {y:g}), but the file puts it {distance[j]:.3g} away "
            f"(offset ({offset[j, 0]:.3g}, {offset[j, 1]:.3g})); is it a solution of this scenario?"
        )
    block = document.get("multipliers")
    if block is None:
        return positions, None
    if not isinstance(block, dict):
        raise ScenarioError(f"{source}: multipliers must be an object with a link list.")
    link = _numbers(block, "link", problem.n_links, source, "link")
    formulation = Formulation.parse(document.get("formulation", problem.formulation.value), f"{source}: formulation")
    if formulation is not problem.formulation:  # through the tensions, which both formulations share
        distances = link_distances(positions)
        tension = tension_from_multipliers(formulation, link, distances)
        link = multipliers_from_tension(problem.formulation, tension, distances)
    obstacles = block.get("obstacle", {})
    if not isinstance(obstacles, dict):
        raise ScenarioError(f"{source}: multipliers.obstacle must map obstacle names to lists.")
    count, what = (problem.n_links, "link") if per_link else (n, "node")
    nu = np.zeros((len(problem.obstacles), count))
    for j, obstacle in enumerate(problem.obstacles):
        if obstacle.name not in obstacles:
            raise ScenarioError(f"{source}: multipliers.obstacle has no entry for obstacle {obstacle.name!r}.")
        nu[j] = _numbers(obstacles, obstacle.name, count, source, what)
    return positions, Multipliers(link, nu)


def read_solution(
    problem: Problem, path: str | Path, tol: float = DEFAULT_TOL
) -> tuple[FloatArray, Multipliers | None]:
    """Positions and (if present) multipliers from a JSON solution file, as ``funicular solve --json`` writes.

    Needs ``x`` and ``y`` (N numbers each); optional ``multipliers.link`` (N-1) and, for each
    obstacle, ``multipliers.obstacle[name]`` (N), in the formulation named by ``formulation``
    (default: the problem's). Raises :class:`ScenarioError` for an unreadable file, invalid JSON,
    wrong lengths, numbers that are not finite, or supports away from their positions.
    """
    _check_tol(tol)
    return _point(problem, _document(path), str(path), tol, per_link=False)


def load_solution(path: str | Path) -> Solution:
    """The :class:`Solution` a ``funicular solve --json`` file holds, with its :class:`Problem`.

    The file must hold the problem (``problem``, written since ``schema_version`` 2); raises
    :class:`ScenarioError` naming the file and the key for anything missing or invalid.
    """
    source = str(path)
    document = _document(path)
    table = document.get("problem")
    if not isinstance(table, dict):
        raise ScenarioError(
            f"{source}: problem is missing; the file must be written by funicular solve --json "
            f"(schema_version {SCHEMA_VERSION} or later) for a chain described by a scenario's keys."
        )
    problem = problem_from_table(table, f"{source}: problem")
    positions, multipliers = _point(problem, document, source, DEFAULT_TOL, per_link=problem.contact == "links")
    if multipliers is None:
        raise ScenarioError(f"{source}: multipliers is missing; a solution holds them (funicular solve --json).")
    status = document.get("status")
    if status not in {member.value for member in Status}:
        raise ScenarioError(f"{source}: status = {shown(status)} is not one of {', '.join(s.value for s in Status)}.")
    return Solution(
        problem=problem,
        status=Status(status),
        positions=positions,
        link_multipliers=multipliers.link,
        obstacle_multipliers=multipliers.obstacle if problem.obstacles else np.zeros((0, 0)),
        iterations=_count(document, "iterations", source),
        solve_seconds=_seconds(document, source),
    )


def _count(document: dict[str, Any], key: str, source: str) -> int:
    value = document.get(key, 0)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ScenarioError(f"{source}: {key} = {shown(value)} must be a count (an integer >= 0).")
    return value


def _seconds(document: dict[str, Any], source: str) -> float:
    value = document.get("solve_seconds", 0.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioError(f"{source}: solve_seconds = {shown(value)} must be a finite number.")
    return float(value)


def solution_document(solution: Solution) -> dict[str, Any]:
    """``solution.to_dict()`` with the ``licq`` block (None at an infeasible point), the problem
    (None for an obstacle a scenario cannot describe) and ``schema_version``: ``solve --json``."""
    document = {"schema_version": SCHEMA_VERSION, **solution.to_dict()}
    licq = licq_of(solution)
    document["licq"] = None if licq is None else licq_dict(licq)
    document["problem"] = problem_table(solution.problem)
    return document
