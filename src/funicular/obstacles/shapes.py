"""The built-in shapes: in the plane :class:`Disk`, :class:`HalfPlane`, :class:`Ellipse` and
:class:`Box` (rounded corners), in space :class:`Sphere`, :class:`Ellipsoid`, :class:`HalfSpace`
and :class:`Cuboid` (a rounded box).

Each checks its parameters when made, evaluates through the solver core
(:mod:`funicular.obstacles.native`), knows how deep a point lies inside it (``depth``: the
distance to its boundary) and, in the plane, draws its ``outline`` for plots (a cuboid its
``footprint`` seen from above). :func:`native_shape` and :func:`native_shapes` give them as the
solver core takes them.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from funicular._types import MAX_SIZE, FloatArray
from funicular.errors import ScenarioError, shown
from funicular.obstacles._ellipsoid import _ellipsoid_depth
from funicular.obstacles.base import (
    Bounds,
    Evaluation,
    Obstacle,
    _finite,
    _labeller,
    _not_tiny,
    _pair,
    _positive,
    _triple,
)
from funicular.obstacles.native import NativeShape, Quadratic, _QuadraticShape, _SpatialQuadratic, evaluate_native


def _rotation(degrees: float) -> FloatArray:
    """Columns are the shape's own axes in world coordinates: local q = (p - c) @ R."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s], [s, c]])


def _rotation_z(degrees: float) -> FloatArray:
    """A turn about the vertical axis z; columns are the shape's own axes, as in :func:`_rotation`."""
    rotation = np.eye(3)
    rotation[:2, :2] = _rotation(degrees)
    return rotation


# ----------------------------------------------------------------- outlines (for plots)
def _clip(polygon: FloatArray, normal: FloatArray, offset: float) -> FloatArray:
    """The part of an open polygon where ``normal . p <= offset`` (one Sutherland-Hodgman pass)."""
    side = polygon @ normal - offset
    kept: list[FloatArray] = []
    for i in range(len(polygon)):
        p, q, sp, sq = polygon[i - 1], polygon[i], side[i - 1], side[i]
        if (sp <= 0) != (sq <= 0):
            kept.append(p + (q - p) * (sp / (sp - sq)))
        if sq <= 0:
            kept.append(q)
    return np.array(kept, dtype=np.float64).reshape(-1, 2)


def _in_bounds(polygon: FloatArray, bounds: Bounds) -> FloatArray:
    """An open polygon clipped to the plotting rectangle, returned closed (first point repeated)."""
    xmin, xmax, ymin, ymax = bounds
    for normal, offset in (((1, 0), xmax), ((-1, 0), -xmin), ((0, 1), ymax), ((0, -1), -ymin)):
        polygon = _clip(polygon, np.array(normal, dtype=np.float64), offset)
    return np.vstack([polygon, polygon[:1]])


def _rectangle(bounds: Bounds) -> FloatArray:
    xmin, xmax, ymin, ymax = bounds
    return np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=np.float64)


# ----------------------------------------------------------------- in the plane
@dataclass(frozen=True)
class Disk(_QuadraticShape):
    """A disk; ``phi = (r^2 - |p - c|^2) / (2 r)``: smooth everywhere, unit gradient on the rim."""

    center: tuple[float, float]
    radius: float
    name: str = "disk"
    # The obstacle's key path in a scenario file ("obstacles[2]"), for error messages.

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        object.__setattr__(self, "center", _pair(self.center, key("center")))
        object.__setattr__(self, "radius", _positive(self.radius, key("radius")))

    @property
    def convex(self) -> bool:
        return True

    def quadratic(self) -> Quadratic:
        return Quadratic(np.asarray(self.center), self.radius / 2.0, np.zeros(2), -np.eye(2) / self.radius)

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 2) lies inside: the radius minus its distance from the centre."""
        offset = points - np.asarray(self.center)
        result: FloatArray = self.radius - np.hypot(offset[:, 0], offset[:, 1])
        return result

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        t = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
        circle = np.asarray(self.center) + self.radius * np.column_stack([np.cos(t), np.sin(t)])
        return _in_bounds(circle, bounds)


@dataclass(frozen=True)
class HalfPlane(_QuadraticShape):
    """The half-plane behind a line through ``point`` whose ``normal`` points out into free space.

    ``phi = -n . (p - point)`` with n the unit normal: phi is the depth below the line.
    """

    point: tuple[float, float]
    normal: tuple[float, float]
    name: str = "halfplane"

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        object.__setattr__(self, "point", _pair(self.point, key("point")))
        normal = _pair(self.normal, key("normal"))
        if normal == (0.0, 0.0):
            raise ScenarioError(f"{key('normal')} = {shown(self.normal)} must be a nonzero vector.", key=key("normal"))
        object.__setattr__(self, "normal", normal)

    @property
    def convex(self) -> bool:
        return True

    def _unit_normal(self) -> FloatArray:
        normal = np.asarray(self.normal, dtype=np.float64)
        return normal / float(np.hypot(*normal))

    def quadratic(self) -> Quadratic:
        return Quadratic(np.asarray(self.point), 0.0, -self._unit_normal(), np.zeros((2, 2)))

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 2) lies below the line: phi itself (its gradient is a unit vector)."""
        return self.evaluate(points)[0]

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        normal = self._unit_normal()  # the obstacle is where normal . p <= normal . point
        inside = _clip(_rectangle(bounds), normal, float(normal @ np.asarray(self.point)))
        return _in_bounds(inside, bounds)


@dataclass(frozen=True)
class Ellipse(_QuadraticShape):
    """An ellipse with semi-axes (a, b), turned ``angle`` degrees counter-clockwise.

    ``phi = (1 - (u/a)^2 - (v/b)^2) * min(a, b) / 2`` in the ellipse's axes (u, v): smooth,
    gradient nonzero on the boundary, and the disk's phi when a = b.
    """

    center: tuple[float, float]
    semi_axes: tuple[float, float]
    angle: float = 0.0
    name: str = "ellipse"

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        object.__setattr__(self, "center", _pair(self.center, key("center")))
        object.__setattr__(self, "semi_axes", _pair(self.semi_axes, key("semi_axes"), positive=True))
        object.__setattr__(self, "angle", _finite(self.angle, key("angle")))

    @property
    def convex(self) -> bool:
        return True

    def quadratic(self) -> Quadratic:
        rotation = _rotation(self.angle)
        scale = min(self.semi_axes) / 2.0
        hessian = rotation @ np.diag(-2.0 * scale / np.asarray(self.semi_axes) ** 2) @ rotation.T
        return Quadratic(np.asarray(self.center), scale, np.zeros(2), 0.5 * (hessian + hessian.T))

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 2) lies inside: its distance to the outline (negative outside)."""
        return self.depth_and_gradient(points)[0]

    def depth_and_gradient(self, points: FloatArray) -> tuple[FloatArray, FloatArray]:
        """:meth:`depth` and its gradient (k, 2), the unit inward normal at the nearest outline point."""
        rotation = _rotation(self.angle)
        depth, gradient = _ellipsoid_depth((points - np.asarray(self.center)) @ rotation, np.asarray(self.semi_axes))
        return depth, gradient @ rotation.T

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        t = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
        local = np.asarray(self.semi_axes) * np.column_stack([np.cos(t), np.sin(t)])
        return _in_bounds(np.asarray(self.center) + local @ _rotation(self.angle).T, bounds)


@dataclass(frozen=True)
class Box:
    """A rectangle with half-sizes (hx, hy) and rounded corners, turned ``angle`` degrees.

    phi is minus the signed distance to the rounded rectangle: C1 everywhere but on the inner
    medial axis (deep inside, where no node sits), C2 away from the region boundaries. A sharp
    corner would make the contact normal jump, so ``0 < corner_radius <= min(hx, hy)``.
    """

    center: tuple[float, float]
    half_size: tuple[float, float]
    corner_radius: float
    angle: float = 0.0
    name: str = "box"

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        object.__setattr__(self, "center", _pair(self.center, key("center")))
        object.__setattr__(self, "half_size", _pair(self.half_size, key("half_size"), positive=True))
        radius = _positive(self.corner_radius, key("corner_radius"))
        if radius > min(self.half_size):
            raise ScenarioError(
                f"{key('corner_radius')} = {shown(self.corner_radius)} must be at most the smaller half size "
                f"{min(self.half_size):g}.",
                key=key("corner_radius"),
            )
        object.__setattr__(self, "corner_radius", radius)
        object.__setattr__(self, "angle", _finite(self.angle, key("angle")))

    @property
    def convex(self) -> bool:
        return True

    def evaluate(self, points: FloatArray) -> Evaluation:
        return evaluate_native(self._native, points)

    @functools.cached_property
    def _native(self) -> NativeShape:
        # (the formula, in the solver core: minus the signed distance to the rounded rectangle)
        parameters = [*self.center, *self.half_size, self.corner_radius, *_rotation(self.angle).ravel().tolist()]
        return ("box", [float(v) for v in parameters])

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 2) lies inside: phi itself (minus the signed distance to the outline)."""
        return self.evaluate(points)[0]

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        r = self.corner_radius
        inner = np.asarray(self.half_size) - r
        t = np.linspace(0.0, np.pi / 2, max(samples // 4, 2))
        arcs = []
        for k, corner in enumerate(([1, 1], [-1, 1], [-1, -1], [1, -1])):  # counter-clockwise
            angle = t + k * np.pi / 2
            arcs.append(corner * inner + r * np.column_stack([np.cos(angle), np.sin(angle)]))
        local = np.vstack(arcs)
        return _in_bounds(np.asarray(self.center) + local @ _rotation(self.angle).T, bounds)


# ----------------------------------------------------------------- in space
@dataclass(frozen=True)
class Sphere(_SpatialQuadratic):
    """A ball in space; ``phi = (r^2 - |p - c|^2) / (2 r)``: unit gradient on its surface."""

    center: tuple[float, float, float]
    radius: float
    name: str = "sphere"

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        object.__setattr__(self, "center", _triple(self.center, key("center")))
        object.__setattr__(self, "radius", _positive(self.radius, key("radius")))

    def quadratic(self) -> Quadratic:
        return Quadratic(np.asarray(self.center), self.radius / 2.0, np.zeros(3), -np.eye(3) / self.radius)

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 3) lies inside: the radius minus its distance from the centre."""
        result: FloatArray = self.radius - np.linalg.norm(points - np.asarray(self.center), axis=1)
        return result


@dataclass(frozen=True)
class Ellipsoid(_SpatialQuadratic):
    """An ellipsoid with semi-axes (a, b, c) along x, y and z:
    ``phi = (1 - (u/a)^2 - (v/b)^2 - (w/c)^2) * min(a, b, c) / 2``, the sphere's phi when a = b = c."""

    center: tuple[float, float, float]
    semi_axes: tuple[float, float, float]
    name: str = "ellipsoid"

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        object.__setattr__(self, "center", _triple(self.center, key("center")))
        object.__setattr__(self, "semi_axes", _triple(self.semi_axes, key("semi_axes"), positive=True))

    def quadratic(self) -> Quadratic:
        axes = np.asarray(self.semi_axes)
        scale = float(axes.min())
        return Quadratic(np.asarray(self.center), scale / 2.0, np.zeros(3), -np.diag(scale / axes**2))

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 3) lies inside: its distance to the surface (negative outside)."""
        return self.depth_and_gradient(points)[0]

    def depth_and_gradient(self, points: FloatArray) -> tuple[FloatArray, FloatArray]:
        """:meth:`depth` and its gradient (k, 3), the unit inward normal at the nearest surface point."""
        return _ellipsoid_depth(points - np.asarray(self.center), np.asarray(self.semi_axes))


@dataclass(frozen=True)
class HalfSpace(_SpatialQuadratic):
    """The half-space behind a plane through ``point`` whose ``normal`` points out into free space;
    ``phi = -n . (p - point)`` with n the unit normal: phi is the depth below the plane."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    name: str = "halfspace"

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        object.__setattr__(self, "point", _triple(self.point, key("point")))
        normal = _triple(self.normal, key("normal"))
        if normal == (0.0, 0.0, 0.0):
            raise ScenarioError(f"{key('normal')} = {shown(self.normal)} must be a nonzero vector.", key=key("normal"))
        object.__setattr__(self, "normal", normal)

    def quadratic(self) -> Quadratic:
        normal = np.asarray(self.normal, dtype=np.float64)
        return Quadratic(np.asarray(self.point), 0.0, -normal / float(np.linalg.norm(normal)), np.zeros((3, 3)))

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 3) lies below the plane: phi itself (its gradient is a unit vector)."""
        return self.evaluate(points)[0]


@dataclass(frozen=True)
class Cuboid:
    """A box in space with half sizes (hx, hy, hz) along its own axes, its edges and corners
    rounded by ``radius``, turned ``angle`` degrees about the vertical axis z (counter-clockwise
    seen from above).

    phi is minus the signed distance to the rounded box (evaluated by the solver core): C1 outside,
    C2 away from the region boundaries (the faces', edges' and corners' zones). The outer extent is
    the half sizes whatever the radius. ``radius = 0`` gives sharp edges, where the contact normal
    jumps from one face to the next; a node resting on an edge is better served by a small radius.
    """

    center: tuple[float, float, float]
    half_sizes: tuple[float, float, float]
    radius: float = 0.0
    angle: float = 0.0
    name: str = "box"

    dimension = 3  # (a class attribute, not a field)

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        center = _triple(self.center, key("center"))
        half_sizes = _triple(self.half_sizes, key("half_sizes"), positive=True)
        for field_name, values, given in (("center", center, self.center), ("half_sizes", half_sizes, self.half_sizes)):
            if not max(map(abs, values)) <= MAX_SIZE:  # (as in the plane: the core works in scaled units)
                raise ScenarioError(
                    f"{key(field_name)} = {shown(given)} is too large; coordinates must stay below {MAX_SIZE:.0e}.",
                    key=key(field_name),
                )
        _not_tiny(np.asarray(half_sizes), self.half_sizes, key("half_sizes"))
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "half_sizes", half_sizes)
        radius = _finite(self.radius, key("radius"))
        if not 0.0 <= radius <= min(half_sizes):
            raise ScenarioError(
                f"{key('radius')} = {shown(self.radius)} must be between 0 and the smallest half size "
                f"{min(half_sizes):g}.",
                key=key("radius"),
            )
        object.__setattr__(self, "radius", radius)
        object.__setattr__(self, "angle", _finite(self.angle, key("angle")))

    @property
    def convex(self) -> bool:
        return True

    def rotation(self) -> FloatArray:
        """The box's axes as the columns of a 3 x 3 matrix: local ``q = (p - center) @ R``."""
        return _rotation_z(self.angle)

    def evaluate(self, points: FloatArray) -> Evaluation:
        return evaluate_native(self._native, points, 3)

    @functools.cached_property
    def _native(self) -> NativeShape:
        # (the formula, in the solver core: minus the signed distance to the rounded box)
        parameters = [*self.center, *self.half_sizes, self.radius, *self.rotation().ravel().tolist()]
        return ("box", [float(v) for v in parameters])

    def depth(self, points: FloatArray) -> FloatArray:
        """How deep each point (k, 3) lies inside: phi itself (minus the signed distance to the surface)."""
        return self.evaluate(points)[0]

    def footprint(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        """The box seen from above inside ``bounds`` (x and y): a closed polygon (k, 2), its
        corners rounded by the radius (the vertical edges' rounding), for plots."""
        r = self.radius
        inner = np.asarray(self.half_sizes[:2]) - r
        t = np.linspace(0.0, np.pi / 2, max(samples // 4, 2))
        arcs = []
        for k, corner in enumerate(([1, 1], [-1, 1], [-1, -1], [1, -1])):  # counter-clockwise
            angle = t + k * np.pi / 2
            arcs.append(corner * inner + r * np.column_stack([np.cos(angle), np.sin(angle)]))
        plan = np.vstack(arcs) @ _rotation(self.angle).T
        return _in_bounds(np.asarray(self.center[:2]) + plan, bounds)


# ----------------------------------------------------------------- as the solver core evaluates them
def native_shape(obstacle: Obstacle) -> NativeShape | None:
    """The obstacle as the solver core evaluates it, if it is a built-in disk, ellipse, half-plane,
    box, sphere, ellipsoid, half-space or cuboid. Exactly those types: a subclass may override
    ``evaluate``, which the solver must then follow."""
    if type(obstacle) not in (Disk, Ellipse, HalfPlane, Box, Sphere, Ellipsoid, HalfSpace, Cuboid):
        return None
    shape: NativeShape = obstacle._native  # type: ignore[attr-defined]  # (made once)
    return shape


def native_shapes(obstacles: Sequence[Obstacle]) -> list[NativeShape] | None:
    """Every obstacle as the solver core evaluates it; None unless each is a built-in (``native_shape``)."""
    shapes = [native_shape(obstacle) for obstacle in obstacles]
    if any(shape is None for shape in shapes):
        return None
    return [shape for shape in shapes if shape is not None]
