"""Solution files (``funicular solve --output``, ``--json``): the document with its ``licq`` block,
and reading a point, its multipliers and its :class:`Solution` back from a document of any format
(:mod:`funicular._results` reads and writes the formats)."""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from funicular._constraints import (
    link_distances,
    multipliers_from_tension,
    tension_from_multipliers,
)
from funicular._results import check_output, read_document, write_document
from funicular._types import finite_numbers
from funicular.checks._active import _point_of
from funicular.checks._check import _check_tol, _linearized
from funicular.checks._licq import _licq
from funicular.checks._report import LICQ, Multipliers, Violation, licq_dict
from funicular.checks._statics import _independent, statics_of
from funicular.checks._tolerances import CERTIFY, DEFAULT_TOL
from funicular.errors import ScenarioError, shown
from funicular.model import FloatArray, Formulation, Problem
from funicular.scenario import problem_from_table, problem_table
from funicular.solution import Solution, Status

# ----------------------------------------------------------------- solution files
SCHEMA_VERSION = 4
# 2: the problem itself is in the file (``problem``), so it can be read back alone.
# 3: .npz and .parquet files; above EXACT_LICQ_UP_TO nodes ``licq.sigma_min`` may be null, with the
#    bound ``licq.sigma_min_above`` that proves LICQ instead.
# 4: a .parquet column is written once; an array's placeholder may name the columns holding it.
EXACT_LICQ_UP_TO = 10_000  # nodes: above, a proof of LICQ replaces the smallest singular value when it can


def _is_number(item: object) -> bool:
    return not isinstance(item, bool) and isinstance(item, (int, float)) and math.isfinite(item)


def _numbers(document: dict[str, Any], key: str, length: int, source: str, what: str) -> FloatArray:
    """``document[key]``: ``length`` finite numbers, a list (JSON) or a 1-D numeric array (.npz, .parquet)."""
    value = document.get(key)
    if isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind in "iuf":
        items: Any = value
    elif isinstance(value, list):
        items = value
    else:
        raise ScenarioError(f"{source}: {key} must be a list of {length} numbers, one per {what}.")
    if len(items) != length:
        raise ScenarioError(
            f"{source}: {key} has {len(items)} entries, but the scenario has {length} {what}s; "
            "is it a solution of this scenario?"
        )
    array = finite_numbers(items)
    if array is not None:
        return array
    i = next(i for i, item in enumerate(items) if not _is_number(item))
    item = items[i].item() if isinstance(items[i], np.generic) else items[i]
    raise ScenarioError(f"{source}: {key}[{i}] = {shown(item)} is not a finite number.")


def _document(path: str | Path) -> dict[str, Any]:
    """The document of a result file of any format, of a schema_version this package reads."""
    source = str(path)
    document = read_document(path)
    version = document.get("schema_version")
    if version is None and "problem" not in document:  # a point written by hand or by another program
        return document
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ScenarioError(f"{source}: schema_version = {shown(version)} must be a positive integer.")
    if version > SCHEMA_VERSION:
        raise ScenarioError(
            f"{source}: schema_version {version} is newer than this funicular reads (up to {SCHEMA_VERSION}); "
            "upgrade funicular to read it."
        )
    return document


def _positions(document: dict[str, Any], n: int, d: int, source: str) -> FloatArray:
    """The (n, d) positions of ``document``: its coordinate lists ``x``, ``y`` (and ``z`` in 3-D), or,
    without them, ``positions`` (n rows of d numbers), which a point written by another program
    may hold instead."""
    axes = "xyz"[:d]
    if "x" in document or "positions" not in document:
        return np.column_stack([_numbers(document, key, n, source, "node") for key in axes])
    value = document["positions"]
    if isinstance(value, np.ndarray) and value.ndim == 2 and value.shape[1] == d and value.dtype.kind in "iuf":
        rows: Any = value
    elif isinstance(value, list) and all(isinstance(row, list) and len(row) == d for row in value):
        rows = value
    else:
        raise ScenarioError(f"{source}: positions must be a list of {n} [{', '.join(axes)}] rows, one per node.")
    if len(rows) != n:
        raise ScenarioError(
            f"{source}: positions has {len(rows)} rows, but the scenario has {n} nodes; "
            "is it a solution of this scenario?"
        )
    columns = []
    for c in range(d):  # each column read as a coordinate list would be; a bad entry named by its row
        column = rows[:, c] if isinstance(rows, np.ndarray) else [row[c] for row in rows]
        try:
            columns.append(_numbers({"column": column}, "column", n, source, "node"))
        except ScenarioError:
            i = next(i for i, item in enumerate(column) if not _is_number(_plain(item)))
            raise ScenarioError(
                f"{source}: positions[{i}][{c}] = {shown(_plain(column[i]))} is not a finite number."
            ) from None
    return np.column_stack(columns)


def _plain(item: object) -> object:
    return item.item() if isinstance(item, np.generic) else item


def _point(
    problem: Problem, document: dict[str, Any], source: str, tol: float, per_link: bool
) -> tuple[FloatArray, Multipliers | None]:
    """Positions and multipliers of ``document`` for ``problem``; obstacle multipliers per link
    (``per_link``: ``contact = "links"``) or per node."""
    n, d = problem.n_nodes, problem.dimension
    positions = _positions(document, n, d, source)
    offset = positions[problem.support_nodes] - problem.support_positions
    distance = np.linalg.norm(offset, axis=1)
    j = int(np.argmax(distance))
    if distance[j] > tol * float(problem.link_lengths.max()):
        node, at = int(problem.support_nodes[j]), problem.support_positions[j]
        raise ScenarioError(
            f"{source}: node {node} is a support at ({', '.join(f'{c:g}' for c in at)}), but the file puts it "
            f"{distance[j]:.3g} away (offset ({', '.join(f'{c:.3g}' for c in offset[j])})); "
            "is it a solution of this scenario?"
        )
    block = document.get("multipliers")
    if block is None:
        return positions, None
    if not isinstance(block, dict):
        raise ScenarioError(f"{source}: multipliers must be an object with a link list.")
    link = _numbers(block, "link", problem.n_links, source, "link")
    formulation = Formulation.parse(document.get("formulation", problem.formulation.value), f"{source}: formulation")
    if formulation is not problem.formulation:  # through the tensions, which both formulations share
        distances = link_distances(positions, problem.links)
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
    """Positions and (if present) multipliers from a solution file: JSON, or the ``.npz`` or
    ``.parquet`` that ``funicular solve --output`` writes (told by the file's content).

    Needs ``x`` and ``y`` (and ``z`` in 3-D; N numbers each), or ``positions`` (N rows of 2 or 3
    numbers); optional ``multipliers.link`` (one per link: N-1 for a chain, L for a net) and, for each
    obstacle, ``multipliers.obstacle[name]`` (N, or one per link with ``contact = "links"``), in the
    formulation named by ``formulation`` (default: the problem's). Raises :class:`ScenarioError`
    for an unreadable, truncated or foreign file, invalid JSON, a newer ``schema_version``, wrong
    lengths, numbers that are not finite, or supports away from their positions.
    """
    _check_tol(tol)
    return _point(problem, _document(path), str(path), tol, per_link=problem.contact == "links")


def load_solution(path: str | Path) -> Solution:
    """The :class:`Solution` a ``funicular solve --output`` (or ``--json``) file holds, with its
    :class:`Problem`: ``.json``, ``.npz`` or ``.parquet``, told by the file's content.

    The file must hold the problem (``problem``, written since ``schema_version`` 2); raises
    :class:`ScenarioError` naming the file and the key for anything missing or invalid, and for a
    truncated or foreign file or one of a newer ``schema_version``.
    """
    source = str(path)
    return solution_from_document(_document(path), source)


def solution_from_document(document: dict[str, Any], source: str) -> Solution:
    """The :class:`Solution` of a document of any format (lists or arrays); errors start with ``source``."""
    table = document.get("problem")
    if not isinstance(table, dict):
        raise ScenarioError(
            f"{source}: problem is missing; the file must be written by funicular solve --output "
            "(schema_version 2 or later) for a chain described by a scenario's keys."
        )
    # The scenario reader takes a list of numbers as a list or a numeric 1-D array; anything else as
    # lists (a net's links, node pairs), so that it names a bad entry as in a JSON file.
    table = {key: _listed(value) for key, value in table.items()}
    problem = problem_from_table(table, f"{source}: problem")
    positions, multipliers = _point(problem, document, source, DEFAULT_TOL, per_link=problem.contact == "links")
    if multipliers is None:
        raise ScenarioError(f"{source}: multipliers is missing; a solution holds them (funicular solve --output).")
    status = document.get("status")
    if status not in {member.value for member in Status}:
        raise ScenarioError(f"{source}: status = {shown(status)} is not one of {', '.join(s.value for s in Status)}.")
    return Solution(
        problem=problem,
        status=Status(status),
        positions=positions,
        link_multipliers=multipliers.link,
        obstacle_multipliers=multipliers.obstacle,  # (0, N) without obstacles, as the solver's
        iterations=_count(document, "iterations", source),
        solve_seconds=_seconds(document, source),
    )


def _listed(value: object) -> object:
    numeric = isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind in "iuf"
    return value.tolist() if isinstance(value, np.ndarray) and not numeric else value


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
    """``solution.to_dict()`` with the ``licq`` block (None at an infeasible point or with
    ``contact = "links"``), the problem (None for an obstacle a scenario cannot describe) and
    ``schema_version``: what every result file holds."""
    # The LICQ block is built beside the rest, in a thread (numpy and the core release the GIL), from
    # the link lengths and obstacle fields the solution evaluates here first, once for both.
    _ = solution.link_distance, solution.node_fields
    with ThreadPoolExecutor(1) as pool:
        licq = pool.submit(licq_block, solution)
        document = {"schema_version": SCHEMA_VERSION, **solution.to_dict()}
        document["licq"] = licq.result()
    document["problem"] = problem_table(solution.problem, arrays=True)
    return document


def licq_block(solution: Solution) -> dict[str, Any] | None:
    """The ``licq`` block of a result file. For a net (and a 3-D chain, whose rows the chain checker
    does not assemble), its statics (:func:`funicular.checks.statics`): ``holds``, ``rank``,
    ``active_constraints``, ``degree_of_indeterminacy``, ``self_stress`` and ``force_ranges``.
    For a planar chain, above EXACT_LICQ_UP_TO nodes, a proof that every
    singular value exceeds ``100 RANK_TOL`` (one banded Cholesky factorization) settles LICQ
    without computing them: then ``sigma_min`` is null and ``sigma_min_above`` the bound proven,
    and ``holds``, ``rank``, ``active_constraints`` and ``dependencies`` (none) are exact. Where
    the proof fails (dependent or nearly dependent rows), the singular values are computed."""
    problem = solution.problem
    if problem.contact == "links" and problem.obstacles:
        return None
    if not problem.is_planar_chain:
        return statics_of(solution).as_dict()
    linear = _linearized(problem, _point_of(solution), DEFAULT_TOL)
    if isinstance(linear, Violation):
        return None
    if problem.n_nodes > EXACT_LICQ_UP_TO and _independent(linear.rows):
        m = linear.rows.m
        block = licq_dict(LICQ(True, m, m, math.nan, ()))
        block["sigma_min_above"] = math.sqrt(CERTIFY)
        return block
    return licq_dict(_licq(problem, linear.point, linear.active, linear.rows)[0])


def write_solution(solution: Solution, path: str | Path, indent: bool = False) -> None:
    """Write ``solution`` to ``path`` as ``.json`` (indented if ``indent``), ``.npz`` or ``.parquet``,
    by its extension; atomically (an existing file keeps its content if anything fails).
    Raises :class:`funicular.errors.OutputError` for another extension or a path that cannot be written."""
    check_output(path)
    write_document(solution_document(solution), path, indent)
