"""The hanging-chain problem: nodes, links, supports and gravity, validated and immutable.

Conventions (see ``docs/model.md``): nodes are numbered 0..N-1. A chain's link k joins nodes k and
k+1; a net's links join any pairs of nodes (``links``). Link k may not be longer than
``link_lengths[k]``. Positions are (N, d) with d = ``dimension``, 2 (the plane, gravity in -y) or 3
(space, gravity in -z); support nodes are held at fixed positions. Negative node indices count from
the end, as in Python, and are normalised on construction.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum
from functools import cached_property
from typing import Any, TypeGuard

import numpy as np
from numpy.typing import ArrayLike, NDArray

from funicular._types import MAX_SIZE as MAX_SIZE
from funicular._types import FloatArray as FloatArray
from funicular._types import IntArray as IntArray
from funicular.errors import ScenarioError, shown
from funicular.obstacles import NativeShape, Obstacle, depth, native_shapes, obstacle_dimension

DEFAULT_GRAVITY = 9.81
UNIT_SYSTEMS = (None, "SI")  # SI: forces in N, lengths in m, masses in kg, gravity in m/s^2
CONTACT_MODES = ("nodes", "links")
# Far beyond what the solver handles, but it stops a typo like 1e12 nodes from exhausting memory.
MAX_NODES = 10_000_000


class Formulation(StrEnum):
    """How the link constraint is written.

    ``NORM``: ``||p_k - p_{k+1}|| - l_k <= 0``; its multiplier is the link tension (a force).
    ``SQUARED``: ``||p_k - p_{k+1}||^2 - l_k^2 <= 0``; smooth, its multiplier is tension / (2 d_k).
    """

    NORM = "norm"
    SQUARED = "squared"

    @classmethod
    def parse(cls, value: object, key: str = "formulation") -> Formulation:
        if isinstance(value, Formulation):
            return value
        if isinstance(value, str):
            for member in cls:
                if member.value == value:
                    return member
        raise ScenarioError(f"{key} = {shown(value)} is not a formulation; use 'norm' or 'squared'.", key=key)


def _float_vector(value: ArrayLike, key: str, length: int) -> FloatArray:
    """A finite float vector of the given length; a scalar is broadcast."""
    if isinstance(value, bool) or (isinstance(value, np.ndarray) and value.dtype == bool):
        raise ScenarioError(f"{key} must be a number or a list of {length} numbers, not a boolean.", key=key)
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ScenarioError(
            f"{key} must be a number or a list of {length} numbers, got {shown(value)}.", key=key
        ) from None
    if array.ndim == 0:
        array = np.full(length, float(array))
    if array.shape != (length,):
        got = f"{array.size}" if array.ndim == 1 else f"an array of shape {array.shape}"
        raise ScenarioError(f"{key} must have {length} entries, got {got}.", key=key)
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ScenarioError(f"{key}[{bad[0]}] = {array[bad[0]]} is not a finite number.", key=key)
    return array


def _finite_float(value: object, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ScenarioError(f"{key} must be a number, got {shown(value)}.", key=key)
    try:
        number = float(value)
    except OverflowError:  # (a Python int beyond any float)
        raise ScenarioError(f"{key} = {shown(value)} is not a finite number.", key=key) from None
    if not math.isfinite(number):
        raise ScenarioError(f"{key} = {number} is not a finite number.", key=key)
    return number


def _node_count(value: object, key: str) -> int:
    """A number of nodes: an integer from 2 to MAX_NODES (checked before anything is allocated)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ScenarioError(f"{key} must be an integer >= 2, got {shown(value)}.", key=key)
    if value < 2:
        raise ScenarioError(f"{key} = {value}: a chain needs at least 2 nodes.", key=key)
    if value > MAX_NODES:
        raise ScenarioError(f"{key} = {value} is too large; use at most {MAX_NODES} nodes.", key=key)
    return int(value)


def _listed(value: Iterable[Any], key: str, what: str = "obstacles") -> list[Any]:
    """An argument that lists things (supports, obstacles, loads) as a list; a sentence naming
    ``key`` if it is not a list of them (a number, None, a string, a mapping)."""
    if isinstance(value, str | bytes | dict) or not isinstance(value, Iterable):
        raise ScenarioError(f"{key} must be a list of {what}, got {shown(value)}.", key=key)
    return list(value)


def _frozen(array: NDArray[Any]) -> NDArray[Any]:
    array = np.array(array)  # private copy, so the caller cannot mutate it behind our back
    array.setflags(write=False)
    return array


def _coordinates(dimension: int) -> str:
    return "[x, y]" if dimension == 2 else "[x, y, z]"


def _path(n: int) -> IntArray:
    """The links of a chain of n nodes: (k, k+1)."""
    k = np.arange(n - 1, dtype=np.intp)
    return np.column_stack((k, k + 1))


def _pairs_and_lengths(
    links: ArrayLike, link_lengths: ArrayLike | None
) -> tuple[IntArray, ArrayLike | None, FloatArray | None]:
    """``links`` as node pairs, the lengths (from the links' third entries if they have them) and
    the axial stiffnesses (their fourth entries: rows of three numbers are inextensible, inf)."""
    if _numeric_table(links):  # (a generated net's array: read as a whole, not row by row)
        table = np.full((links.shape[0], 4), np.inf)
        table[:, : links.shape[1]] = links
        return _split_link_table(table, links.shape[1], link_lengths)
    rows = links.tolist() if isinstance(links, np.ndarray) else links
    if isinstance(rows, str | bytes | dict) or not isinstance(rows, Iterable):
        raise ScenarioError(f"links must be a list of [i, j, length] entries, got {shown(links)}.", key="links")
    rows = list(rows)
    widths = set()
    for k, row in enumerate(rows):
        width = len(row) if isinstance(row, Sequence | np.ndarray) and not isinstance(row, str) else -1
        if width not in (2, 3, 4):
            raise ScenarioError(
                f"links[{k}] = {shown(row)} must be [i, j], [i, j, length] or [i, j, length, EA] "
                "(EA: the link's axial stiffness, a force).",
                key="links",
            )
        widths.add(min(width, 3))
    if not rows:
        raise ScenarioError("links must be a non-empty list of [i, j, length] (or [i, j]) entries.", key="links")
    if len(widths) > 1:
        raise ScenarioError("links: give every link its length ([i, j, length]) or none of them ([i, j]).", key="links")
    try:
        table = np.array([list(row) + [np.inf] * (4 - len(row)) for row in rows], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ScenarioError(
            f"links must be a list of [i, j, length] entries of numbers, got {shown(links)}.", key="links"
        ) from None
    return _split_link_table(table, max(widths), link_lengths)


def _numeric_table(links: object) -> TypeGuard[NDArray[Any]]:
    """Whether ``links`` is an array of numbers shaped as link rows, all of one width (2, 3 or 4)."""
    return (
        isinstance(links, np.ndarray)
        and links.ndim == 2
        and links.shape[0] > 0
        and links.shape[1] in (2, 3, 4)
        and links.dtype.kind in "iuf"
    )


def _split_link_table(
    table: FloatArray, width: int, link_lengths: ArrayLike | None
) -> tuple[IntArray, ArrayLike | None, FloatArray | None]:
    """:func:`_pairs_and_lengths` of the link rows as a table (L, 4): ``[i, j, length, EA]``, inf
    where a row of ``width`` < 4 numbers has none."""
    ends = table[:, :2]
    if not np.all(np.isfinite(ends)) or np.any(ends != np.round(ends)):
        raise ScenarioError("links: the first two entries of each link are node indices (integers).", key="links")
    if np.any(np.abs(ends) > MAX_NODES):
        raise ScenarioError(f"links: a node index is far out of range; use at most {MAX_NODES} nodes.", key="links")
    pairs = ends.astype(np.intp)
    stiffness = table[:, 3] if np.isfinite(table[:, 3]).any() else None
    if width >= 3:
        if link_lengths is not None:
            raise ScenarioError("links carry their lengths; give link_lengths only with [i, j] pairs.", key="links")
        return pairs, table[:, 2], stiffness
    return pairs, link_lengths, None


def _components(n: int, links: IntArray) -> IntArray:
    """Each node's connected component, named by a node of it: every round hooks each component's
    root to the smallest root a link reaches from it, then points every node at its root; a
    component that neither hooks nor is hooked to has a smaller root beside it in the next round,
    so the components at least halve every two rounds (O(log n) rounds of O(N + L) work)."""
    root = np.arange(n)
    a, b = links[:, 0], links[:, 1]
    while True:
        ra, rb = root[a], root[b]
        apart = ra != rb
        if not apart.any():
            return root
        np.minimum.at(root, np.maximum(ra, rb)[apart], np.minimum(ra, rb)[apart])
        while True:  # each node to its root (roots point only to smaller roots: no cycle)
            up = root[root]
            if np.array_equal(up, root):
                break
            root = up


def _check_connected(n: int, links: IntArray, supports: IntArray) -> None:
    """Every node must hang from a support through links, or it falls forever."""
    root = _components(n, links)
    held = np.zeros(n, dtype=bool)
    held[root[supports]] = True
    loose = np.flatnonzero(~held[root])
    if loose.size:
        raise ScenarioError(
            f"links: node {loose[0]} is not connected to any support through links"
            + (f" (nor are {loose.size - 1} other nodes)" if loose.size > 1 else "")
            + "; link it to a supported node or hold it as a support.",
            key="links",
        )


@dataclass(frozen=True)
class Support:
    """A node held at a fixed position (d coordinates). ``node`` may be negative (counted from the end)."""

    node: int
    position: tuple[float, ...]


DIMENSIONS = (2, 3)


def _point_loads(loads: Iterable[tuple[int, Sequence[float]]], n: int, dimension: int) -> FloatArray:
    """``(node, force)`` pairs as the (N, d) array of point loads (a node named twice: the sum)."""
    array = np.zeros((n, dimension if dimension in DIMENSIONS else 2))
    for j, pair in enumerate(loads):
        try:
            node, force = pair
        except (TypeError, ValueError):
            raise ScenarioError(f"loads[{j}] must be a (node, force) pair.", key="loads") from None
        if isinstance(node, bool) or not isinstance(node, (int, np.integer)) or not -n <= int(node) < n:
            raise ScenarioError(
                f"loads[{j}].node = {shown(node)} is not a node; with {n} nodes use 0..{n - 1} or -{n}..-1.",
                key="loads",
            )
        try:
            vector = np.array(force, dtype=np.float64)
        except (TypeError, ValueError):
            vector = np.empty(0)
        if vector.shape != (array.shape[1],) or not np.all(np.isfinite(vector)):
            raise ScenarioError(
                f"loads[{j}].force must be {_coordinates(array.shape[1])} finite, got {shown(force)}.", key="loads"
            )
        array[int(node)] += vector
    return array


def _link_nodes(value: object, n: int) -> IntArray:
    """Links as an (L, 2) array of node pairs, each in 0..n-1, two different nodes."""
    try:
        links = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        raise ScenarioError(f"links must be a list of [i, j] node pairs, got {shown(value)}.", key="links") from None
    if links.dtype == bool or not (links.size == 0 or np.issubdtype(links.dtype, np.integer)):
        raise ScenarioError("links must hold integer node indices [i, j].", key="links")
    if links.ndim != 2 or links.shape[1] != 2 or links.shape[0] == 0:
        raise ScenarioError(
            f"links must be a non-empty list of [i, j] node pairs, got shape {links.shape}.", key="links"
        )
    links = links.astype(np.intp)
    bad = np.flatnonzero(((links < 0) | (links >= n)).any(axis=1))
    if bad.size:
        k = int(bad[0])
        raise ScenarioError(
            f"links[{k}] = {links[k].tolist()} names a node out of range; with {n} nodes use 0..{n - 1}.",
            key="links",
        )
    loops = np.flatnonzero(links[:, 0] == links[:, 1])
    if loops.size:
        k = int(loops[0])
        raise ScenarioError(
            f"links[{k}] joins node {links[k, 0]} to itself; a link joins two different nodes.", key="links"
        )
    return links


@dataclass(frozen=True, eq=False)
class Problem:
    """A discretised hanging chain or cable net, validated on construction and immutable afterwards.

    Attributes:
        masses: node masses ``m_i >= 0`` (N,), at least one positive.
        link_lengths: maximum link lengths ``l_k > 0`` (L,): N-1 for a chain.
        support_nodes: indices of the support nodes (S,), ascending, each in 0..N-1.
        support_positions: their fixed positions (S, d), in the order of ``support_nodes``.
        gravity: ``g > 0``, acting along the last axis (-y in 2-D, -z in 3-D).
        formulation: which link constraint the solver uses.
        name: a label for reports.
        obstacles: rigid obstacles (see :mod:`funicular.obstacles`); each free node must stay out of them.
        contact: ``"nodes"`` (only the nodes are kept out, the exercise's model) or ``"links"`` (chains only).
        links: for a net, the links' node pairs (L, 2), link k joining ``links[k]``; None for a chain
            (link k joins nodes k and k+1). Links given that form exactly that path are stored as None.
        dimension: 2 (positions (N, 2), gravity in -y) or 3 (positions (N, 3), gravity in -z).
        loads: point loads (N, d), forces applied to the nodes beside their weights; None for none.
            A chain with point loads is solved and checked as a net (see :attr:`is_chain`).

    Use :meth:`Problem.build` for the keyword-style construction that scenario files use.
    """

    masses: FloatArray
    link_lengths: FloatArray
    support_nodes: IntArray
    support_positions: FloatArray
    gravity: float = DEFAULT_GRAVITY
    formulation: Formulation = Formulation.NORM
    name: str = "chain"
    obstacles: tuple[Obstacle, ...] = ()
    contact: str = "nodes"
    links: IntArray | None = None
    dimension: int = 2
    loads: FloatArray | None = None
    axial_stiffness: FloatArray | None = None
    units: str | None = None

    def __post_init__(self) -> None:
        masses = np.asarray(self.masses, dtype=np.float64).ravel()
        n = masses.size
        if n < 2:
            raise ScenarioError(f"masses has {n} entries: a chain needs at least 2 nodes.", key="masses")
        masses = _float_vector(masses, "masses", n)
        negative = np.flatnonzero(masses < 0)
        if negative.size:
            i = negative[0]
            raise ScenarioError(f"masses: node {i} has mass {masses[i]}; masses must be >= 0.", key="masses")
        with np.errstate(over="ignore"):
            total_mass = masses.sum()
        if not np.isfinite(total_mass):
            raise ScenarioError("masses: the total mass overflows; use smaller masses.", key="masses")
        if isinstance(self.dimension, bool) or self.dimension not in DIMENSIONS:
            raise ScenarioError(f"dimension = {shown(self.dimension)}; use 2 (a plane) or 3 (space).", key="dimension")
        links = None if self.links is None else _link_nodes(self.links, n)
        if links is not None and links.shape[0] == n - 1 and np.array_equal(links, _path(n)):
            links = None  # the path graph: a chain, solved by the chain's fast paths
        n_links = n - 1 if links is None else links.shape[0]
        lengths = _float_vector(self.link_lengths, "link_lengths", n_links)
        nonpositive = np.flatnonzero(lengths <= 0)
        if nonpositive.size:
            k = nonpositive[0]
            raise ScenarioError(
                f"link_lengths: link {k} has length {lengths[k]}; link lengths must be > 0.", key="link_lengths"
            )
        with np.errstate(over="ignore"):
            total_length = lengths.sum()
        # The same range as forces: a length's square, and a force times a length, must be finite and nonzero.
        if not (total_length <= MAX_SIZE and lengths.min() >= 1.0 / MAX_SIZE):
            shortest = float(lengths.min())
            size = f"{total_length:.3g} long" if total_length > MAX_SIZE else f"has a link {shortest:.3g} long"
            raise ScenarioError(
                f"link_lengths: the chain is {size}; lengths and coordinates must stay between "
                f"{1.0 / MAX_SIZE:.0e} and {MAX_SIZE:.0e} (their squares must be finite and nonzero).",
                key="link_lengths",
            )
        gravity = _finite_float(self.gravity, "gravity")
        if gravity <= 0:
            raise ScenarioError(f"gravity = {gravity}; gravity must be > 0 (it acts in -y).", key="gravity")
        with np.errstate(over="ignore"):
            weight = gravity * total_mass
        if weight != 0 and not 1.0 / MAX_SIZE <= weight <= MAX_SIZE:
            raise ScenarioError(
                f"masses: the weight g * mass = {weight:.3g} is out of range; forces must stay between "
                f"{1.0 / MAX_SIZE:.0e} and {MAX_SIZE:.0e} (products of forces must be finite and nonzero).",
                key="masses",
            )
        object.__setattr__(self, "dimension", int(self.dimension))
        object.__setattr__(self, "loads", self._validated_loads(n))
        object.__setattr__(self, "axial_stiffness", self._validated_stiffness(n_links))
        if not total_mass > 0 and self.loads is None and self.axial_stiffness is None:
            raise ScenarioError(
                "masses: every node has mass 0 and nothing else pulls the structure (no point loads, no elastic "
                "links), so every shape is an equilibrium; give a node a positive mass, a point load or an "
                "axial_stiffness.",
                key="masses",
            )
        if self.units not in UNIT_SYSTEMS:
            raise ScenarioError(
                f"units = {shown(self.units)} is not a unit system; use 'SI' (N, m, kg, m/s^2) or leave it out.",
                key="units",
            )
        nodes, positions = self._validated_supports(n)
        if links is not None:
            _check_connected(n, links, nodes)
        object.__setattr__(self, "links", None if links is None else _frozen(links))
        object.__setattr__(self, "masses", _frozen(masses))
        object.__setattr__(self, "link_lengths", _frozen(lengths))
        object.__setattr__(self, "support_nodes", _frozen(nodes))
        object.__setattr__(self, "support_positions", _frozen(positions))
        object.__setattr__(self, "gravity", gravity)
        object.__setattr__(self, "formulation", Formulation.parse(self.formulation))
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "obstacles", self._validated_obstacles())
        if self.contact not in CONTACT_MODES:
            raise ScenarioError(
                f"contact = {shown(self.contact)} is not a contact mode; use 'nodes' or 'links'.", key="contact"
            )
        if self.contact == "links" and (links is not None or self.dimension != 2):
            raise ScenarioError(
                "contact = 'links' is available for planar chains only; use contact = 'nodes' for a net or in 3-D.",
                key="contact",
            )
        if self.axial_stiffness is not None and self.contact == "links" and self.obstacles:
            raise ScenarioError(
                "contact = 'links' keeps inextensible chains' links out of the obstacles; a chain with elastic "
                "links keeps its nodes out: use contact = 'nodes'.",
                key="contact",
            )
        if self.axial_stiffness is not None and self.formulation is Formulation.SQUARED:
            raise ScenarioError(
                "axial_stiffness: elastic links are written in the norm formulation only (their tension is "
                "EA (d - L0) / L0); use formulation = 'norm'.",
                key="axial_stiffness",
            )

    def _validated_stiffness(self, n_links: int) -> FloatArray | None:
        """Each link's axial stiffness EA (L,), inf for an inextensible link; None where every link is."""
        if self.axial_stiffness is None:
            return None
        key = "axial_stiffness"
        try:
            stiffness = np.array(self.axial_stiffness, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            got = shown(self.axial_stiffness)
            raise ScenarioError(
                f"{key} must be a number or a list of {n_links} numbers (one per link), got {got}.", key=key
            ) from None
        if stiffness.ndim == 0:
            stiffness = np.full(n_links, float(stiffness))
        if stiffness.shape != (n_links,):
            raise ScenarioError(f"{key} must have {n_links} entries (one per link), got {stiffness.size}.", key=key)
        bad = np.flatnonzero(~(stiffness > 0) | (stiffness > MAX_SIZE) & np.isfinite(stiffness))
        if bad.size:
            k = int(bad[0])
            raise ScenarioError(
                f"{key}: link {k} has EA = {stiffness[k]}; an axial stiffness is a force > 0 and below "
                f"{MAX_SIZE:.0e} (inf: inextensible).",
                key=key,
            )
        return None if np.all(np.isinf(stiffness)) else _frozen(stiffness)

    def _validated_obstacles(self) -> tuple[Obstacle, ...]:
        obstacles = tuple(self.obstacles)
        for j, obstacle in enumerate(obstacles):
            if not isinstance(obstacle, Obstacle):
                raise ScenarioError(
                    f"obstacles[{j}] = {shown(obstacle)} is not an obstacle: it needs a name, a convex flag and "
                    "evaluate(points) returning phi, its gradient and its Hessian.",
                    key=f"obstacles[{j}]",
                )
            if obstacle_dimension(obstacle) != self.dimension:
                raise ScenarioError(
                    f"obstacles[{j}] ({obstacle.name!r}) is a {obstacle_dimension(obstacle)}-D shape, but the problem "
                    f"is {self.dimension}-D; use "
                    + (
                        "a disk, ellipse, halfplane, box, graph or expression."
                        if self.dimension == 2
                        else "a sphere, ellipsoid, halfspace, box, surface or expression."
                    ),
                    key=f"obstacles[{j}]",
                )
        return obstacles

    def _validated_loads(self, n: int) -> FloatArray | None:
        """The point loads as a read-only (N, d) array, None if absent or all zero."""
        if self.loads is None:
            return None
        try:
            loads = np.array(self.loads, dtype=np.float64)
        except (TypeError, ValueError):
            loads = np.empty(0)
        if loads.shape != (n, self.dimension):
            raise ScenarioError(
                f"loads must be an array of {n} point loads {_coordinates(self.dimension)}, one per node "
                f"(zeros where none), got {shown(self.loads)}.",
                key="loads",
            )
        bad = np.flatnonzero(~np.all(np.isfinite(loads) & (np.abs(loads) <= MAX_SIZE), axis=1))
        if bad.size:
            i = int(bad[0])
            raise ScenarioError(
                f"loads: node {i} has the point load {loads[i].tolist()}; a load's components must be finite "
                f"and below {MAX_SIZE:.0e}.",
                key="loads",
            )
        return _frozen(loads) if np.any(loads) else None

    def _validated_supports(self, n: int) -> tuple[IntArray, FloatArray]:
        key = "supports"
        try:
            raw_nodes = np.asarray(self.support_nodes).ravel()
        except OverflowError:
            raise ScenarioError(f"{key}: a support node index is far out of range; use 0..{n - 1}.") from None
        if raw_nodes.size == 0:
            raise ScenarioError(f"{key}: at least one support is needed, or the chain falls forever.")
        if raw_nodes.dtype == bool or not np.issubdtype(raw_nodes.dtype, np.integer):
            raise ScenarioError(f"{key}: support nodes must be integers, got {shown(raw_nodes.tolist())}.")
        positions = np.asarray(self.support_positions, dtype=np.float64)
        if positions.shape != (raw_nodes.size, self.dimension):
            raise ScenarioError(f"{key}: each support needs a position {_coordinates(self.dimension)}.")
        nodes = raw_nodes.astype(np.intp)
        within = np.isfinite(positions).all(axis=1) & (np.abs(positions) <= MAX_SIZE).all(axis=1)
        bad = np.flatnonzero((nodes < -n) | (nodes >= n) | ~within)
        if bad.size:  # the first bad support, by what is wrong with it first
            j = int(bad[0])
            if not -n <= nodes[j] < n:
                raise ScenarioError(
                    f"{key}[{j}].node = {nodes[j]} is out of range; with {n} nodes use 0..{n - 1} or -{n}..-1."
                )
            if not np.all(np.isfinite(positions[j])):
                raise ScenarioError(f"{key}[{j}].position = {positions[j].tolist()} is not finite.")
            raise ScenarioError(
                f"{key}[{j}].position = {positions[j].tolist()} is too large; coordinates must stay below "
                f"{MAX_SIZE:.0e} (their squares must be finite numbers)."
            )
        nodes = np.where(nodes < 0, nodes + n, nodes)
        unique, first, counts = np.unique(nodes, return_index=True, return_counts=True)
        if np.any(counts > 1):
            twice = unique[counts > 1][0]
            raise ScenarioError(f"{key}: node {twice} is given as a support twice; give each support node once.")
        return unique, positions[first]

    # ----------------------------------------------------------------- construction
    @classmethod
    def build(
        cls,
        *,
        nodes: int,
        supports: Iterable[Support | tuple[int, Sequence[float]]],
        link_length: float | None = None,
        length: float | None = None,
        link_lengths: ArrayLike | None = None,
        masses: ArrayLike | None = None,
        mass: float | None = None,
        gravity: float = DEFAULT_GRAVITY,
        formulation: Formulation | str = Formulation.NORM,
        name: str = "chain",
        obstacles: Iterable[Obstacle] = (),
        contact: str = "nodes",
        links: ArrayLike | None = None,
        dimension: int = 2,
        loads: Iterable[tuple[int, Sequence[float]]] | None = None,
        axial_stiffness: ArrayLike | None = None,
        linear_density: ArrayLike | None = None,
        units: str | None = None,
    ) -> Problem:
        """Build a problem the way a scenario file describes it.

        A chain: no ``links``. A net: ``links`` as ``[i, j, length]`` triples (each link's own
        length), or as ``[i, j]`` pairs with the lengths given as below. Exactly one of
        ``link_length`` (every link), ``length`` (total, spread equally) or ``link_lengths`` (per
        link), unless the links carry their lengths; exactly one of ``masses`` (a number for every
        node, or a list per node) or ``mass`` (total, spread equally). ``supports`` holds
        ``Support`` objects or ``(node, position)`` pairs, a position having ``dimension`` (2 or 3)
        coordinates; ``loads`` ``(node, force)`` pairs, a force applied to that node beside its
        weight (a node named twice carries the sum).

        Elastic links: ``axial_stiffness`` EA (a number for every link, or one per link, inf for an
        inextensible one), or a fourth number in a net's link rows ``[i, j, length, EA]``; the lengths
        are then the unstretched lengths L0, and a link's tension is ``EA (d - L0) / L0`` where it is
        stretched. ``linear_density`` (mass per unstretched length, for every link or one per link)
        replaces ``mass``/``masses``: each link's mass is shared by its two end nodes. ``units``:
        "SI" (N, m, kg, m/s^2) labels every output with its units.
        """
        nodes = _node_count(nodes, "nodes")
        pairs = None
        row_stiffness = None
        if links is not None:
            pairs, link_lengths, row_stiffness = _pairs_and_lengths(links, link_lengths)
            if row_stiffness is not None and axial_stiffness is not None:
                raise ScenarioError(
                    "axial_stiffness: the links carry their own EA (a fourth number); give axial_stiffness only "
                    "with links of three numbers.",
                    key="axial_stiffness",
                )
            axial_stiffness = axial_stiffness if row_stiffness is None else row_stiffness
        n_links = nodes - 1 if pairs is None else pairs.shape[0]
        given = [
            k
            for k, v in (("link_length", link_length), ("length", length), ("link_lengths", link_lengths))
            if v is not None
        ]
        if len(given) != 1:
            raise ScenarioError(
                "Problem.build: give exactly one of link_length, length or link_lengths"
                + (f" (got {', '.join(given)})." if given else "."),
                key="Problem.build",
            )
        if link_length is not None:
            lengths = _float_vector(_finite_float(link_length, "link_length"), "link_length", n_links)
        elif length is not None:
            total = _finite_float(length, "length")
            if total <= 0:
                raise ScenarioError(f"length = {total}; the total length must be > 0.", key="length")
            lengths = np.full(n_links, total / n_links)
        else:
            lengths = _float_vector(link_lengths, "link_lengths", n_links)  # type: ignore[arg-type]
        given_mass = [
            k for k, v in (("masses", masses), ("mass", mass), ("linear_density", linear_density)) if v is not None
        ]
        if len(given_mass) != 1:
            raise ScenarioError(
                "Problem.build: give exactly one of masses (per node), mass (total) or linear_density "
                "(mass per unstretched length)" + (f" (got {', '.join(given_mass)})." if given_mass else "."),
                key="Problem.build",
            )
        if linear_density is not None:
            density = _float_vector(linear_density, "linear_density", n_links)
            if np.any(density < 0):
                k = int(np.flatnonzero(density < 0)[0])
                raise ScenarioError(
                    f"linear_density: link {k} has {density[k]}; it must be >= 0.", key="linear_density"
                )
            ends = _path(nodes) if pairs is None else pairs
            if pairs is not None and (np.any(ends < -nodes) or np.any(ends >= nodes)):
                raise ScenarioError(
                    f"links name a node out of range; with {nodes} nodes use 0..{nodes - 1}.", key="links"
                )
            node_masses = np.zeros(nodes)
            halves = 0.5 * density * lengths
            np.add.at(node_masses, ends[:, 0], halves)
            np.add.at(node_masses, ends[:, 1], halves)
        elif mass is not None:
            total_mass = _finite_float(mass, "mass")
            if total_mass < 0:
                raise ScenarioError(f"mass = {total_mass}; the total mass must be >= 0.", key="mass")
            node_masses = np.full(nodes, total_mass / nodes)
        else:
            node_masses = _float_vector(masses, "masses", nodes)  # type: ignore[arg-type]
        supports, obstacles = _listed(supports, "supports", "(node, position) pairs"), _listed(obstacles, "obstacles")
        if not supports:
            raise ScenarioError(
                "supports is empty: a chain or net needs at least one support, a (node, position) pair, "
                "or it falls forever.",
                key="supports",
            )
        support_nodes: list[int] = []
        support_positions: list[FloatArray] = []
        for j, support in enumerate(supports):
            position: object
            if isinstance(support, Support):
                node, position = support.node, support.position
            else:
                try:
                    node, position = support
                except (TypeError, ValueError):
                    raise ScenarioError(f"supports[{j}] must be a Support or a (node, position) pair.") from None
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)):
                raise ScenarioError(f"supports[{j}].node must be an integer node index, got {shown(node)}.")
            try:
                xy = np.array(position, dtype=np.float64)
            except (TypeError, ValueError):
                xy = np.empty(0)
            if dimension in DIMENSIONS and xy.shape != (dimension,):
                raise ScenarioError(f"supports[{j}].position must be {_coordinates(dimension)}, got {shown(position)}.")
            if not -nodes <= int(node) < nodes:  # before numpy, which cannot hold a huge Python int
                raise ScenarioError(
                    f"supports[{j}].node = {node} is out of range; "
                    f"with {nodes} nodes use 0..{nodes - 1} or -{nodes}..-1."
                )
            support_nodes.append(int(node))
            support_positions.append(xy)
        point_loads = None
        if loads is not None:
            point_loads = _point_loads(_listed(loads, "loads", "(node, force) pairs"), nodes, dimension)
        try:
            return cls(
                masses=node_masses,
                link_lengths=lengths,
                support_nodes=np.array(support_nodes, dtype=np.intp),
                support_positions=np.array(support_positions, dtype=np.float64).reshape(len(support_positions), -1),
                gravity=gravity,
                formulation=Formulation.parse(formulation),
                name=name,
                obstacles=tuple(obstacles),
                contact=contact,
                links=pairs,
                dimension=dimension,
                loads=point_loads,
                axial_stiffness=axial_stiffness,  # type: ignore[arg-type]  # (checked by the problem itself)
                units=units,
            )
        except ScenarioError as error:  # named by the arguments given here, not the fields they became
            given_as = {"masses": given_mass[0], "link_lengths": given[0]}
            if row_stiffness is not None:
                given_as["axial_stiffness"] = "links"
            raise error.renamed(given_as.get(error.key or "", error.key or "")) from None

    # ----------------------------------------------------------------- derived quantities
    # Computed once: the problem is immutable, and a small chain's solve asks for these several
    # times (each a numpy call of a few microseconds). Arrays are read-only, like the fields.
    @property
    def n_nodes(self) -> int:
        return int(self.masses.size)

    @property
    def n_links(self) -> int:
        return int(self.link_lengths.size)

    @property
    def solved_as_chain(self) -> bool:
        """Whether link k joins nodes k and k+1 for every k (no ``links`` given, or exactly those)
        and no node carries a point load: what the solver solves as a chain (its supports' reach
        checked there), elastic links included. A chain with point loads is solved as a net."""
        return self.links is None and self.loads is None

    @property
    def is_chain(self) -> bool:
        """Solved as a chain (:attr:`solved_as_chain`) and no link elastic: what a chain's studies
        (refinement, ``explore``'s starts, the other back-ends) assume."""
        return self.solved_as_chain and self.axial_stiffness is None

    @property
    def kind(self) -> str:
        """ "chain" or "net", as messages name the structure."""
        return "chain" if self.links is None else "net"

    @property
    def is_planar_chain(self) -> bool:
        """A chain in the plane: what the other solvers and a planar chain's result-file LICQ block cover."""
        return self.is_chain and self.dimension == 2

    @cached_property
    def link_nodes(self) -> IntArray:
        """The node pair of every link (L, 2): ``links`` for a net, (k, k+1) for a chain."""
        pairs = _path(self.n_nodes) if self.links is None else self.links
        pairs.setflags(write=False)
        return pairs

    @cached_property
    def total_mass(self) -> float:
        return float(self.masses.sum())

    @cached_property
    def total_length(self) -> float:
        return float(self.link_lengths.sum())

    @cached_property
    def arc_fractions(self) -> FloatArray:
        """Each node's arclength position along the chain, from 0 (node 0) to 1 (the last node)."""
        arc: FloatArray = np.concatenate(([0.0], np.cumsum(self.link_lengths))) / self.total_length
        arc.setflags(write=False)
        return arc

    @cached_property
    def weight(self) -> float:
        """Total weight ``g * sum(m)``."""
        return self.gravity * self.total_mass

    @cached_property
    def force_scale(self) -> float:
        """The force that residuals and tolerances are measured against: the weight; without any
        mass, the point loads' sum of magnitudes; without either, the smallest axial stiffness (a
        weightless, unloaded net is held by its pretension, EA times a strain)."""
        if self.weight > 0:
            return self.weight
        if self.loads is not None:
            return float(np.linalg.norm(self.loads, axis=1).sum())
        assert self.axial_stiffness is not None  # (checked on construction)
        return float(self.axial_stiffness.min())

    @cached_property
    def link_compliance(self) -> FloatArray:
        """Each link's stretch per unit of tension, ``L0 / EA`` (L,): 0 for an inextensible link. A
        link's constraint reads ``d - L0 - compliance T <= 0``: an elastic link stretches by
        ``T L0 / EA`` under tension T, an inextensible one not at all."""
        compliance = (
            np.zeros(self.n_links) if self.axial_stiffness is None else self.link_lengths / self.axial_stiffness
        )
        compliance.setflags(write=False)
        return compliance

    @cached_property
    def elastic(self) -> NDArray[np.bool_]:
        """Which links are elastic (L,): those with a finite axial stiffness."""
        mask = np.zeros(self.n_links, dtype=bool) if self.axial_stiffness is None else np.isfinite(self.axial_stiffness)
        mask.setflags(write=False)
        return mask

    @cached_property
    def free_nodes(self) -> IntArray:
        """Indices of the nodes that are not supports, ascending."""
        free = np.flatnonzero(~self.is_support)
        free.setflags(write=False)
        return free

    @cached_property
    def loaded_nodes(self) -> IntArray:
        """The nodes that carry a point load, ascending (none without point loads)."""
        loaded = np.zeros(0, dtype=np.intp) if self.loads is None else np.flatnonzero(self.loads.any(axis=1))
        loaded.setflags(write=False)
        return loaded

    @cached_property
    def free_rows(self) -> slice | IntArray:
        """The free nodes as an index of positions: a slice where they are consecutive (a chain held
        at its two ends), so that ``positions[problem.free_rows]`` is a view, not a copy."""
        free = self.free_nodes
        if free.size and int(free[-1] - free[0]) + 1 == free.size:
            return slice(int(free[0]), int(free[-1]) + 1)
        return free

    @cached_property
    def is_support(self) -> NDArray[np.bool_]:
        mask = np.zeros(self.n_nodes, dtype=bool)
        mask[self.support_nodes] = True
        mask.setflags(write=False)
        return mask

    @cached_property
    def native_obstacles(self) -> list[NativeShape] | None:
        """The obstacles as the solver core evaluates them (``obstacles.native_shapes``, made once):
        None unless every obstacle is a built-in disk, ellipse, half-plane or box."""
        return native_shapes(self.obstacles)

    @cached_property
    def support_depths(self) -> FloatArray:
        """How deep each support lies inside each obstacle, (n_obstacles, S): ``obstacles.depth``
        (negative outside)."""
        depths = np.empty((len(self.obstacles), self.support_nodes.size))
        for j, obstacle in enumerate(self.obstacles):
            depths[j] = depth(obstacle, self.support_positions)
        depths.setflags(write=False)
        return depths

    def energy(self, positions: FloatArray) -> float:
        """Potential energy ``g m^T h - sum_i P_i . p_i + sum_k EA_k / (2 L0_k) max(d_k - L0_k, 0)^2``
        at ``positions`` (N, d), h the last coordinate (y or z), P the point loads, the last sum
        the elastic links' strain energy."""
        energy = float(self.gravity * self.masses @ positions[:, -1])
        if self.loads is not None:
            energy -= float(np.sum(self.loads * positions))
        if self.axial_stiffness is not None:
            elastic = self.elastic
            pairs = self.link_nodes[elastic]
            stretch = np.maximum(
                np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1) - self.link_lengths[elastic],
                0.0,
            )
            energy += float(0.5 * np.sum(self.axial_stiffness[elastic] / self.link_lengths[elastic] * stretch**2))
        return energy

    def length_between(self, a: int, b: int) -> float:
        """Chain length between nodes a < b (sum of their link lengths)."""
        self._only_chains("length_between")
        return float(self.link_lengths[a:b].sum())

    def _only_chains(self, what: str) -> None:
        if self.links is None and self.loads is not None:
            raise ScenarioError(f"{what} applies to a chain without point loads (they sit on given nodes).", key=what)
        if not self.is_chain:
            raise ScenarioError(f"{what} applies to a chain; this problem is a net of {self.n_links} links.", key=what)

    def with_loads(self, loads: Iterable[tuple[int, Sequence[float]]]) -> Problem:
        """The same problem with point loads ``loads``, ``(node, force)`` pairs (as in :meth:`build`)."""
        return replace(self, loads=_point_loads(loads, self.n_nodes, self.dimension))

    def with_formulation(self, formulation: Formulation | str) -> Problem:
        return replace(self, formulation=Formulation.parse(formulation))

    def with_nodes(self, n_nodes: int) -> Problem:
        """The same chain with ``n_nodes`` nodes: total mass and total length kept, spread equally.

        Supports move to the new node nearest to their old arc-length position along the chain.
        """
        self._only_chains("n_nodes")
        nodes = _node_count(n_nodes, "n_nodes")
        new_nodes = np.rint(self.arc_fractions[self.support_nodes] * (nodes - 1)).astype(np.intp)
        if np.unique(new_nodes).size != new_nodes.size:
            raise ScenarioError(
                f"n_nodes = {nodes} is too coarse: two supports would fall on the same node; use more nodes.",
                key="n_nodes",
            )
        return replace(
            self,
            masses=np.full(nodes, self.total_mass / nodes),
            link_lengths=np.full(nodes - 1, self.total_length / (nodes - 1)),
            support_nodes=new_nodes,
            support_positions=self.support_positions.copy(),
        )
