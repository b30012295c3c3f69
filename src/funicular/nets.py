"""Cable nets generated from a few numbers: a rectangular grid, a radial net, a triangulated disk,
or the edges of a mesh (OBJ), each hung in 3-D (gravity in -z) from supports at its own plan
positions (z = 0).

Every generator returns a validated :class:`~funicular.model.Problem`. Each link's maximum length
is either one ``link_length`` for all links or ``slack`` times the link's length in the flat plan
(so ``slack = 1.2`` lets every link be 20 % longer than its spacing). Errors are
:class:`~funicular.errors.ScenarioError` naming the argument (``rows``, ``slack``, ``supports``, ...).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from funicular.errors import ScenarioError, shown
from funicular.model import DEFAULT_GRAVITY, MAX_NODES, FloatArray, Formulation, IntArray, Problem
from funicular.obstacles import Obstacle

__all__ = [
    "GRID_SUPPORTS",
    "RADIAL_SUPPORTS",
    "disk",
    "grid",
    "grid_nodes",
    "mesh",
    "radial",
    "radial_nodes",
    "read_obj",
]

GRID_SUPPORTS = ("corners", "edges")
RADIAL_SUPPORTS = ("outer",)
MESH_SUPPORTS = ("boundary",)

SupportChoice = str | Sequence[int]


def _count(value: object, key: str, least: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ScenarioError(f"{key} must be an integer >= {least} ({what}), got {shown(value)}.", key=key)
    if not least <= value <= MAX_NODES:
        raise ScenarioError(f"{key} = {value}; {what} must be between {least} and {MAX_NODES}.", key=key)
    return int(value)


def _positive(value: object, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ScenarioError(f"{key} must be a number > 0, got {shown(value)}.", key=key)
    number = float(value)
    if not (math.isfinite(number) and number > 0):
        raise ScenarioError(f"{key} = {shown(value)}; it must be a finite number > 0.", key=key)
    return number


def _lengths(plan: FloatArray, slack: float | None, link_length: float | None) -> FloatArray:
    """Each link's maximum length: ``slack`` times its plan length, or ``link_length`` for all."""
    if (slack is None) == (link_length is None):
        raise ScenarioError("slack: give exactly one of slack (times each link's spacing) or link_length.", key="slack")
    if slack is not None:
        return _positive(slack, "slack") * plan
    return np.full(plan.size, _positive(link_length, "link_length"))


def _chosen_supports(supports: SupportChoice, named: dict[str, IntArray], n_nodes: int) -> IntArray:
    """The support nodes: a named set (``"corners"``, ...) or a list of node indices."""
    if isinstance(supports, str):
        if supports not in named:
            raise ScenarioError(
                f"supports = {shown(supports)} is not known; use {' or '.join(map(repr, named))}, or a list of nodes.",
                key="supports",
            )
        return named[supports]
    try:
        nodes = np.asarray(list(supports))
    except TypeError:
        raise ScenarioError(
            f"supports must be {' or '.join(map(repr, named))} or a list of node indices, got {shown(supports)}.",
            key="supports",
        ) from None
    if nodes.size == 0 or nodes.dtype == bool or not np.issubdtype(nodes.dtype, np.integer) or nodes.ndim != 1:
        raise ScenarioError(
            f"supports must be {' or '.join(map(repr, named))} or a non-empty list of node indices, "
            f"got {shown(supports)}.",
            key="supports",
        )
    bad = nodes[(nodes < 0) | (nodes >= n_nodes)]
    if bad.size:
        raise ScenarioError(
            f"supports: node {int(bad[0])} is out of range; with {n_nodes} nodes use 0..{n_nodes - 1}.",
            key="supports",
        )
    return np.unique(nodes.astype(np.intp))


@dataclass(frozen=True)
class Cable:
    """What a generated net's links are made of: their axial stiffness and linear density (see
    :meth:`Problem.build`), and the units the numbers are in."""

    axial_stiffness: ArrayLike | None = None
    linear_density: ArrayLike | None = None
    units: str | None = None


def _problem(
    plan: FloatArray,
    pairs: IntArray,
    lengths: FloatArray,
    support_nodes: IntArray,
    *,
    mass: float | None,
    masses: ArrayLike | None,
    gravity: float,
    obstacles: Iterable[Obstacle],
    formulation: Formulation | str,
    name: str,
    cable: Cable,
) -> Problem:
    """The 3-D problem of a net laid out flat at ``plan`` (N, 2), supported where it lies (z = 0)."""
    positions = np.column_stack([plan, np.zeros(plan.shape[0])])
    if masses is None and mass is None and cable.linear_density is None:
        mass = 1.0
    return Problem.build(
        nodes=plan.shape[0],
        links=pairs,
        link_lengths=lengths,
        supports=[(int(node), positions[node]) for node in support_nodes],
        mass=mass,
        masses=masses,
        gravity=gravity,
        formulation=formulation,
        name=name,
        obstacles=obstacles,
        dimension=3,
        axial_stiffness=cable.axial_stiffness,
        linear_density=cable.linear_density,
        units=cable.units,
    )


def _size(size: Sequence[float]) -> tuple[float, float]:
    if isinstance(size, (str, bytes)) or not isinstance(size, Sequence) or len(size) != 2:
        raise ScenarioError(f"size must be two numbers [sx, sy], got {shown(size)}.", key="size")
    sx, sy = (_positive(value, "size") for value in size)
    return sx, sy


def grid_nodes(rows: int, columns: int) -> int:
    """How many nodes :func:`grid` makes: ``rows * columns``."""
    return rows * columns


def radial_nodes(rings: int, spokes: int) -> int:
    """How many nodes :func:`radial` and :func:`disk` make: a centre and ``rings`` rings of ``spokes``."""
    return 1 + rings * spokes


def grid(
    rows: int,
    columns: int,
    *,
    size: Sequence[float] = (1.0, 1.0),
    slack: float | None = None,
    link_length: float | None = None,
    mass: float | None = None,
    masses: ArrayLike | None = None,
    supports: SupportChoice = "corners",
    gravity: float = DEFAULT_GRAVITY,
    obstacles: Iterable[Obstacle] = (),
    formulation: Formulation | str = Formulation.NORM,
    name: str = "grid",
    axial_stiffness: ArrayLike | None = None,
    linear_density: ArrayLike | None = None,
    units: str | None = None,
) -> Problem:
    """A ``rows`` x ``columns`` grid of nodes over ``size`` = (sx, sy) in x and y, each node linked
    to its right and upper neighbours (``2 r c - r - c`` links); node ``r * columns + c`` lies at
    ``(c sx / (columns - 1), r sy / (rows - 1))``. ``supports``: ``"corners"`` (4 nodes),
    ``"edges"`` (every boundary node) or a list of node indices, each held at its plan position,
    z = 0. ``mass`` is the total (1 unless ``masses`` gives each node's)."""
    rows = _count(rows, "rows", 2, "a grid's rows")
    columns = _count(columns, "columns", 2, "a grid's columns")
    if grid_nodes(rows, columns) > MAX_NODES:
        raise ScenarioError(f"rows: {rows} x {columns} nodes is too many; use at most {MAX_NODES}.", key="rows")
    sx, sy = _size(size)
    dx, dy = sx / (columns - 1), sy / (rows - 1)
    r, c = np.divmod(np.arange(rows * columns), columns)
    plan = np.column_stack([c * dx, r * dy])
    index = np.arange(rows * columns).reshape(rows, columns)
    across = np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()])
    up = np.column_stack([index[:-1, :].ravel(), index[1:, :].ravel()])
    pairs = np.vstack([across, up])
    spacing = np.concatenate([np.full(across.shape[0], dx), np.full(up.shape[0], dy)])
    # (ascending without np.unique, whose check for masked arrays imports numpy.ma: 5 ms of a solve)
    edge = np.zeros((rows, columns), dtype=bool)
    edge[[0, -1], :] = edge[:, [0, -1]] = True
    boundary = np.flatnonzero(edge)
    corners = index[[0, 0, -1, -1], [0, -1, 0, -1]]
    support_nodes = _chosen_supports(supports, {"corners": corners, "edges": boundary}, rows * columns)
    return _problem(
        plan,
        pairs,
        _lengths(spacing, slack, link_length),
        support_nodes,
        mass=mass,
        masses=masses,
        gravity=gravity,
        obstacles=obstacles,
        formulation=formulation,
        name=name,
        cable=Cable(axial_stiffness, linear_density, units),
    )


def _radial_layout(rings: int, spokes: int, radius: float) -> tuple[FloatArray, IntArray, IntArray]:
    """Nodes (centre 0, then ring k's spoke s at ``1 + (k-1) spokes + s``), the spoke links
    (centre outwards) and the ring links."""
    k, s = np.divmod(np.arange(rings * spokes), spokes)
    angle = 2.0 * np.pi * s / spokes
    ring_radius = (k + 1) * radius / rings
    plan = np.vstack([[0.0, 0.0], np.column_stack([ring_radius * np.cos(angle), ring_radius * np.sin(angle)])])
    node = 1 + np.arange(rings * spokes).reshape(rings, spokes)
    inner = np.vstack([np.zeros((1, spokes), dtype=np.intp), node[:-1]])
    spoke_links = np.column_stack([inner.ravel(), node.ravel()])
    ring_links = np.column_stack([node.ravel(), np.roll(node, -1, axis=1).ravel()])
    return plan, spoke_links, ring_links


def radial(
    rings: int,
    spokes: int,
    *,
    radius: float = 1.0,
    slack: float | None = None,
    link_length: float | None = None,
    mass: float | None = None,
    masses: ArrayLike | None = None,
    supports: SupportChoice = "outer",
    gravity: float = DEFAULT_GRAVITY,
    obstacles: Iterable[Obstacle] = (),
    formulation: Formulation | str = Formulation.NORM,
    name: str = "radial",
    triangulated: bool = False,
    axial_stiffness: ArrayLike | None = None,
    linear_density: ArrayLike | None = None,
    units: str | None = None,
) -> Problem:
    """A radial net: a centre node and ``rings`` rings of ``spokes`` nodes each, equally spaced out
    to ``radius``, joined along the rings and along the spokes (``triangulated``: also across each
    quadrilateral, making triangles). ``supports``: ``"outer"`` (the outer ring) or a list of nodes."""
    rings = _count(rings, "rings", 1, "a radial net's rings")
    spokes = _count(spokes, "spokes", 3, "a radial net's spokes")
    if radial_nodes(rings, spokes) > MAX_NODES:
        raise ScenarioError(f"rings: {rings} x {spokes} nodes is too many; use at most {MAX_NODES}.", key="rings")
    radius = _positive(radius, "radius")
    plan, spoke_links, ring_links = _radial_layout(rings, spokes, radius)
    pairs = [spoke_links, ring_links]
    if triangulated and rings > 1:
        node = 1 + np.arange(rings * spokes).reshape(rings, spokes)
        pairs.append(np.column_stack([node[:-1].ravel(), np.roll(node[1:], -1, axis=1).ravel()]))
    links = np.vstack(pairs)
    plan_length = np.linalg.norm(plan[links[:, 0]] - plan[links[:, 1]], axis=1)
    outer = 1 + (rings - 1) * spokes + np.arange(spokes)
    support_nodes = _chosen_supports(supports, {"outer": outer}, plan.shape[0])
    return _problem(
        plan,
        links,
        _lengths(plan_length, slack, link_length),
        support_nodes,
        mass=mass,
        masses=masses,
        gravity=gravity,
        obstacles=obstacles,
        formulation=formulation,
        name=name,
        cable=Cable(axial_stiffness, linear_density, units),
    )


def disk(rings: int, spokes: int, **options: object) -> Problem:
    """A triangulated disk: :func:`radial` with each quadrilateral split into two triangles."""
    options.setdefault("name", "disk")
    return radial(rings, spokes, triangulated=True, **options)  # type: ignore[arg-type]


def read_obj(text: str, key: str = "mesh") -> tuple[FloatArray, IntArray, IntArray]:
    """The vertices (N, 3), the unique edges (L, 2) of the faces of an OBJ mesh (``v`` and ``f``
    lines; texture and normal indices after ``/`` and negative indices are understood) and its
    boundary nodes (those on an edge of a single face)."""
    vertices: list[list[float]] = []
    edges: dict[tuple[int, int], int] = {}  # each edge: how many faces share it
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if fields[0] == "v":
            try:
                vertices.append([float(value) for value in fields[1:4]])
            except ValueError:
                raise ScenarioError(
                    f"{key}: line {number} has a vertex that is not numbers: {shown(line)}.", key=key
                ) from None
            if len(vertices[-1]) != 3 or not all(map(math.isfinite, vertices[-1])):
                raise ScenarioError(f"{key}: line {number} must give a vertex as v x y z, got {shown(line)}.", key=key)
        elif fields[0] == "f":
            try:
                corners = [int(value.split("/")[0]) for value in fields[1:]]
            except ValueError:
                raise ScenarioError(
                    f"{key}: line {number} has a face that is not vertex numbers: {shown(line)}.", key=key
                ) from None
            # OBJ counts from 1; a negative index counts back from the last vertex read so far.
            face = [c - 1 if c > 0 else len(vertices) + c for c in corners]
            if len(face) < 3 or any(not 0 <= c < len(vertices) for c in face) or 0 in corners:
                raise ScenarioError(
                    f"{key}: line {number} must name at least 3 vertices among the {len(vertices)} read so far, "
                    f"got {shown(line)}.",
                    key=key,
                )
            for a, b in zip(face, face[1:] + face[:1], strict=True):
                if a != b:
                    edge = (min(a, b), max(a, b))
                    edges[edge] = edges.get(edge, 0) + 1
    if not edges:
        raise ScenarioError(f"{key} has no faces (f lines); a net needs at least one.", key=key)
    boundary = np.unique([node for edge, count in edges.items() if count == 1 for node in edge]).astype(np.intp)
    return np.asarray(vertices, dtype=np.float64), np.asarray(sorted(edges), dtype=np.intp), boundary


def mesh(
    source: str | os.PathLike[str],
    *,
    slack: float | None = None,
    link_length: float | None = None,
    mass: float | None = None,
    masses: ArrayLike | None = None,
    supports: SupportChoice = "boundary",
    gravity: float = DEFAULT_GRAVITY,
    obstacles: Iterable[Obstacle] = (),
    formulation: Formulation | str = Formulation.NORM,
    name: str | None = None,
    axial_stiffness: ArrayLike | None = None,
    linear_density: ArrayLike | None = None,
    units: str | None = None,
) -> Problem:
    """A net made of the edges of the faces in an OBJ file: each edge a link ``slack`` times its
    length in the mesh (or ``link_length``); ``supports``: ``"boundary"`` (the nodes on edges of
    a single face) or a list of node indices, each held where the mesh puts it."""
    path = Path(source)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise ScenarioError(f"mesh: cannot read {str(path)!r} ({error}).", key="mesh") from None
    vertices, edges, boundary = read_obj(text)
    used = np.unique(edges)
    # Vertices no face uses would hang from nothing: renumber the used ones 0..N-1.
    renumber = np.full(vertices.shape[0], -1, dtype=np.intp)
    renumber[used] = np.arange(used.size)
    vertices, boundary = vertices[used], renumber[boundary]
    edges = renumber[edges]
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    support_nodes = _chosen_supports(supports, {"boundary": boundary}, vertices.shape[0])
    if masses is None and mass is None and linear_density is None:
        mass = 1.0
    return Problem.build(
        nodes=vertices.shape[0],
        links=edges,
        link_lengths=_lengths(length, slack, link_length),
        supports=[(int(node), vertices[node]) for node in support_nodes],
        mass=mass,
        masses=masses,
        gravity=gravity,
        formulation=formulation,
        name=path.stem if name is None else name,
        obstacles=obstacles,
        dimension=3,
        axial_stiffness=axial_stiffness,
        linear_density=linear_density,
        units=units,
    )
