"""Rigid obstacles: each occupies ``{phi >= 0}``; every free node must satisfy ``phi(x, y) <= 0``.

An obstacle is anything with a ``name``, a ``convex`` flag and ``evaluate(points)`` returning
``phi`` (k,), its gradient (k, 2) and its Hessian (k, 2, 2) at the points (k, 2), vectorised.
The contact force obstacle j exerts on node i is ``-nu_ji grad phi_j(p_i)``: it points out of
the obstacle and does not change when phi is multiplied by a positive constant.

Shapes in the plane: :class:`HalfPlane`, :class:`Disk`, :class:`Ellipse`, :class:`Box` (rounded
corners), :class:`Graph` (terrain below ``y = f(x)``) and :class:`Expression` (any ``phi(x, y)``),
the last two written as text and differentiated by sympy (the ``expr`` extra);
:class:`CallableObstacle` wraps a Python function. In space (``dimension = 3``, points (k, 3)):
:class:`Sphere`, :class:`Ellipsoid`, :class:`HalfSpace`, :class:`Cuboid` (a rounded box),
:class:`Surface` (terrain below ``z = f(x, y)``) and :class:`Expression` with ``dimension = 3``
(any ``phi(x, y, z)``); an obstacle says which by its ``dimension`` attribute (2 when it has
none). Each shape's ``phi`` has a nonzero gradient on its boundary, so the contact constraint is
regular there. ``outline(bounds)`` gives a closed polygon for plotting.

For ``contact = "links"`` the convex built-ins (disk, ellipse, box, half-plane) also give phi's
largest value along a segment, its maximiser and derivatives (:func:`segment_max`), and the
link-contact constraint built on it (:func:`link_contact`): the one place these live. Every
built-in shape knows how deep a point lies inside it (``depth``, the distance to its boundary) and
how deep a segment reaches into it (:func:`segment_depth`).
"""

from __future__ import annotations

import ast
import functools
import io
import math
import tokenize
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from funicular import _core
from funicular._extras import install_command
from funicular._types import MAX_SIZE, FloatArray
from funicular.errors import FunicularError, ScenarioError, shown

Evaluation = tuple[FloatArray, FloatArray, FloatArray]
Bounds = tuple[float, float, float, float]  # xmin, xmax, ymin, ymax


@runtime_checkable
class Obstacle(Protocol):
    """What the solver needs of an obstacle."""

    @property
    def name(self) -> str: ...

    @property
    def convex(self) -> bool: ...

    def evaluate(self, points: FloatArray) -> Evaluation:
        """``phi`` (k,), gradient (k, 2), Hessian (k, 2, 2) at ``points`` (k, 2)."""
        ...


# ----------------------------------------------------------------- validation helpers
def _labeller(name: str) -> Callable[[str], str]:
    """How error messages name a field: ``obstacle 'name': field``, also the error's ``key`` (the
    scenario reader renames it into the file's key, ``obstacles[j].field``)."""
    return lambda key: f"obstacle {name!r}: {key}"


def _string(value: object, label: str) -> str:
    if not isinstance(value, str):
        raise ScenarioError(f"{label} must be a string, got {shown(value)}.", key=label)
    return value


def _positive(value: object, label: str) -> float:
    number = _finite(value, label)
    if number <= 0:
        raise ScenarioError(f"{label} = {shown(value)} must be a positive number.", key=label)
    _not_tiny(np.array([number]), value, label)
    return number


def _not_tiny(sizes: FloatArray, value: object, label: str) -> None:
    """A size the shape divides by (a radius, a semi-axis) must keep its reciprocal finite."""
    if np.any(sizes < 1.0 / MAX_SIZE):
        raise ScenarioError(
            f"{label} = {shown(value)} is too small; sizes must be at least {1.0 / MAX_SIZE:.0e}.", key=label
        )


def _finite(value: object, label: str) -> float:
    # bool is an int, but `true` is not a number.
    numeric = (int, float, np.integer, np.floating)
    if isinstance(value, bool) or not isinstance(value, numeric) or not math.isfinite(value):
        raise ScenarioError(f"{label} = {shown(value)} must be a finite number.", key=label)
    number = float(value)
    if not abs(number) <= MAX_SIZE:
        raise ScenarioError(f"{label} = {shown(value)} is too large; sizes must stay below {MAX_SIZE:.0e}.", key=label)
    return number


def _vector(value: object, label: str, size: int, positive: bool = False) -> FloatArray:
    """``size`` finite numbers (coordinates below MAX_SIZE; ``positive``: each > 0 and not tiny)."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        array = np.empty(0)
    ok = array.shape == (size,) and bool(np.all(np.isfinite(array))) and not (positive and np.any(array <= 0))
    if not ok:
        count, axes = {2: ("two", "[x, y]"), 3: ("three", "[x, y, z]")}[size]
        what = f"{count} positive numbers" if positive else f"{count} finite numbers {axes}"
        raise ScenarioError(f"{label} = {shown(value)} must be {what}.", key=label)
    if not np.all(np.abs(array) <= MAX_SIZE):
        raise ScenarioError(
            f"{label} = {shown(value)} is too large; coordinates must stay below {MAX_SIZE:.0e}.", key=label
        )
    if positive:
        _not_tiny(array, value, label)
    return array


def _pair(value: object, label: str, positive: bool = False) -> tuple[float, float]:
    x, y = (float(v) for v in _vector(value, label, 2, positive))
    return x, y


def _rotation(degrees: float) -> FloatArray:
    """Columns are the shape's own axes in world coordinates: local q = (p - c) @ R."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s], [s, c]])


def _checked(
    name: str, points: FloatArray, phi: FloatArray, gradient: FloatArray, hessian: FloatArray, dimension: int = 2
) -> Evaluation:
    """The evaluate contract, enforced where values come from user text or code: the shapes
    (``dimension`` coordinates per point).

    Non-finite values pass through: a trial point of the solver's line search may stray where phi
    is undefined and is then rejected; a non-finite phi at the initial guess or at the solution is
    reported by the solver, naming the obstacle and the node.
    """
    k, d = points.shape[0], dimension
    for label, value, shape in (("phi", phi, (k,)), ("gradient", gradient, (k, d)), ("Hessian", hessian, (k, d, d))):
        if value.shape != shape:
            raise ScenarioError(f"obstacle {name!r}: {label} has shape {value.shape} for {k} points; expected {shape}.")
    return phi, gradient, hessian


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


def outline(obstacle: Obstacle, bounds: Bounds, samples: int = 200) -> FloatArray:
    """A closed polygon (k, 2) of the obstacle inside ``bounds``; empty (0, 2) if the shape has none."""
    method = getattr(obstacle, "outline", None)
    return np.empty((0, 2)) if method is None else np.asarray(method(bounds, samples), dtype=np.float64)


# ----------------------------------------------------------------- convex shapes
class Quadratic(NamedTuple):
    """A phi that is exactly quadratic: ``value + gradient . d + d^T hessian d / 2``, d = p - centre.

    The disk, the ellipse and the half-plane are; the solver core evaluates such a phi from these
    coefficients (``native_shape``), here too."""

    centre: FloatArray  # (2,)
    value: float
    gradient: FloatArray  # (2,)
    hessian: FloatArray  # (2, 2), symmetric

    def evaluate(self, points: FloatArray) -> Evaluation:
        return evaluate_native(("quadratic", self.parameters()), points)

    def parameters(self) -> list[float]:
        """The coefficients as the solver core takes them: centre, value, gradient, Hessian."""
        return [*self.centre.tolist(), float(self.value), *self.gradient.tolist(), *self.hessian.ravel().tolist()]


NativeShape = tuple[str, list[float]]  # a built-in shape as the solver core evaluates it
# Every obstacle's phi (N,) and gradient (N, d) at every node.
NodeFields = list[tuple[FloatArray, FloatArray]]


def evaluate_native(shape: NativeShape, points: FloatArray, dimension: int = 2) -> Evaluation:
    """phi, gradient and Hessian of a built-in shape at ``points`` (k, d), evaluated by the solver
    core (the one implementation of these formulas)."""
    d = dimension
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, d)
    fields = _core.evaluate_shapes(shapes=[_core.Shape(kind=shape[0], parameters=shape[1])], points=points, dim=d)
    k = points.shape[0]
    return fields.phi.reshape(k), fields.gradient.reshape(k, d), fields.hessian.reshape(k, d, d)


def obstacle_dimension(obstacle: Obstacle) -> int:
    """Whether an obstacle lives in the plane (2, the default) or in space (3): its ``dimension``."""
    dimension = getattr(obstacle, "dimension", 2)
    return dimension if isinstance(dimension, int) else 2


class _QuadraticShape:
    """What the disk, the ellipse and the half-plane share: ``evaluate`` from their
    :class:`Quadratic`, made once (a frozen shape's coefficients do not change, and making them
    costs as much as evaluating them at a small chain)."""

    def quadratic(self) -> Quadratic:
        raise NotImplementedError  # (each shape's own)

    @functools.cached_property
    def _form(self) -> Quadratic:
        return self.quadratic()

    def evaluate(self, points: FloatArray) -> Evaluation:
        return evaluate_native(self._native, points)

    @functools.cached_property
    def _native(self) -> NativeShape:
        return ("quadratic", self._form.parameters())


class _SpatialQuadratic(_QuadraticShape):
    """A quadratic shape in space: points (k, 3)."""

    dimension = 3

    @property
    def convex(self) -> bool:
        return True

    def evaluate(self, points: FloatArray) -> Evaluation:
        return evaluate_native(self._native, points, 3)


def _triple(value: object, label: str, positive: bool = False) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in _vector(value, label, 3, positive))
    return x, y, z


ELLIPSOID_STEPS = 100  # most root-finding steps per point: a handful usually (Newton's and the secant's)
_EPS = float(np.finfo(np.float64).eps)


def _ellipsoid_depth(local: FloatArray, axes: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Signed distance from points (k, d) in an ellipse's or ellipsoid's own axes to its boundary,
    positive inside, and its gradient (k, d) in those axes: the unit inward normal at the nearest
    boundary point (of the two nearest to a point inside on the plane of the longer axes, where
    the distance has a ridge, the one on the positive side).

    The nearest boundary point is ``x_i = e_i^2 y_i / (t + e_i^2)`` (y = |local|, e the semi-axes)
    with t the root above ``-e_min^2`` of ``F(t) = sum_i (e_i y_i / (t + e_i^2))^2 - 1``, convex
    and decreasing there (D. Eberly, "Distance from a point to an ellipse, an ellipsoid, or a
    hyperellipsoid"). A bracket of the root narrows from both sides: Newton's step from its left
    end stays left of the root and the secant of the bracket right of it (F is convex); their
    midpoint and the bracket's own (at least a halving) keep a step from stalling where rounding
    or a pole of F slows those two. The axes as long as
    the smallest count together (their coordinates' norm), and the nearest point's component along
    them comes from x lying on the boundary: near the plane of the longer axes t nears ``-e_min^2``,
    where ``e_min^2 y / (t + e_min^2)`` would be 0 / 0 (and is, on that plane, for a point inside).
    """
    y = np.abs(np.asarray(local, dtype=np.float64))
    smallest = float(axes.min())
    least = axes == smallest
    rho = np.sqrt(np.sum(y[:, least] ** 2, axis=1))  # along the smallest axes
    others, longer = y[:, ~least], axes[~least]
    longer2, least2 = longer**2, smallest**2

    def excess(t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """F and F' at each point's t (any shape (k, ...))."""
        u = t[..., None] + longer2
        ratio = longer * others.reshape(others.shape[:1] + (1,) * (t.ndim - 1) + others.shape[1:]) / u
        scale = rho.reshape(rho.shape + (1,) * (t.ndim - 1))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # (rho = 0 at t = -e_min^2: no term)
            own = np.where(scale > 0.0, smallest * scale / (t + least2), 0.0)
            own_slope = np.where(scale > 0.0, own**2 / (t + least2), 0.0)
            value = np.sum(ratio**2, axis=-1) + own**2 - 1.0
            return value, -2.0 * (np.sum(ratio**2 / u, axis=-1) + own_slope)

    # F(low) >= 0 (the smallest axes' term alone is 1 there), F(high) <= 0 (every term is below
    # (e_i y_i / t)^2, and they sum to at most 1). Where F(low) <= 0 already (a point inside, on
    # the plane of the longer axes), the nearest point lies off that plane, with t = -e_min^2.
    low = -least2 + smallest * rho
    high = np.maximum(np.sqrt(np.sum((axes * y) ** 2, axis=1)), low)
    # Any Newton step lands left of the root (F is convex): one from t = 0, right of it for a point
    # inside, starts a point near the boundary next to the root.
    zero = np.zeros_like(low)
    f_zero, s_zero = excess(zero)
    with np.errstate(divide="ignore", invalid="ignore"):  # (the centre: F'(0) = 0)
        start = zero - f_zero / s_zero
    low = np.where(np.isfinite(start), np.clip(start, low, high), low)
    high = np.where(f_zero <= 0.0, np.clip(zero, low, high), high)
    f_low, s_low = excess(low)
    f_high = excess(high)[0]
    high = np.where(f_low <= 0.0, low, high)
    for _ in range(ELLIPSOID_STEPS):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            newton = low - f_low / s_low
            secant = high - f_high * (high - low) / (f_high - f_low)
        newton = np.where(np.isfinite(newton), np.clip(newton, low, high), low)
        secant = np.where(np.isfinite(secant), np.clip(secant, newton, high), high)
        middles = (0.5 * (newton + secant), 0.5 * (low + high))
        points = np.sort(np.stack((low, newton, *middles, secant, high), axis=1), axis=1)
        values, slopes = excess(points)
        values[:, 0], values[:, -1] = np.maximum(f_low, 0.0), np.minimum(f_high, 0.0)  # (as bracketed)
        rows = np.arange(low.size)
        left = np.maximum(np.count_nonzero(values >= 0.0, axis=1) - 1, 0)  # F decreases along the row
        right = np.minimum(np.count_nonzero(values > 0.0, axis=1), points.shape[1] - 1)
        low, f_low, s_low = points[rows, left], values[rows, left], slopes[rows, left]
        high, f_high = points[rows, right], values[rows, right]
        # Done where the bracket has closed to rounding (of t, or of the distance it gives, |t x / e^2|
        # with |x / e^2| about 1 / e_min) or F at its left end is rounding (its terms sum to 1).
        if np.all((high - low <= 16.0 * _EPS * (np.abs(low) + least2)) | (f_low <= 16.0 * _EPS)):
            break
    nearest = np.empty_like(y)
    nearest[:, ~least] = longer2 * others / (low[:, None] + longer2)
    along = smallest * np.sqrt(np.maximum(1.0 - np.sum((nearest[:, ~least] / longer) ** 2, axis=1), 0.0))
    distance = np.sqrt(np.sum((nearest[:, ~least] - others) ** 2, axis=1) + (along - rho) ** 2)
    inside = np.sum((y / axes) ** 2, axis=1) <= 1.0
    # Along the smallest axes the nearest point lies in the point's direction (the first axis on the plane).
    first = np.eye(int(least.sum()))[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        direction = np.where(rho[:, None] > 0.0, y[:, least] / rho[:, None], first)
    nearest[:, least] = along[:, None] * direction
    normal = np.where(local < 0.0, -1.0, 1.0) * nearest / axes**2  # outward, at the nearest point
    gradient = -normal / np.linalg.norm(normal, axis=1, keepdims=True)
    return np.where(inside, distance, -distance), gradient


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


def _rotation_z(degrees: float) -> FloatArray:
    """A turn about the vertical axis z; columns are the shape's own axes, as in :func:`_rotation`."""
    rotation = np.eye(3)
    rotation[:2, :2] = _rotation(degrees)
    return rotation


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


# ----------------------------------------------------------------- expressions (sympy)
# Names an expression may use besides its variables. Anything else is rejected before sympy sees
# the text, because parse_expr evaluates it as Python.
_FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "exp", "log", "sqrt")
_CONSTANTS = ("pi", "E")
_OPERATORS = frozenset({"+", "-", "*", "/", "**", "^", "(", ")", ","})
MAX_EXPONENT = 1000.0  # larger constant exponents only overflow, and sympy would compute them exactly
_TOKENS = frozenset({tokenize.NAME, tokenize.NUMBER, tokenize.OP, tokenize.NEWLINE, tokenize.NL, tokenize.ENDMARKER})


def _sympy() -> ModuleType:
    try:
        import sympy  # type: ignore[import-untyped]  # (an optional extra, and slow to import: only for expressions)
    except ImportError:
        raise FunicularError(f"expression obstacles need sympy: {install_command('expr')}") from None
    return sympy  # type: ignore[no-any-return]


def _check_tokens(text: str, names: frozenset[str], variables: tuple[str, ...], label: str) -> None:
    """Only numbers, the variables, known functions and arithmetic: nothing else reaches eval."""
    quoted = f"{label} = {shown(text)}"
    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (tokenize.TokenError, SyntaxError) as error:
        raise ScenarioError(f"{quoted} is not a valid expression ({error.args[0]}).", key=label) from None
    for token in tokens:
        if token.type == tokenize.NAME and token.string not in names:
            raise ScenarioError(
                f"{quoted} uses the unknown name {token.string!r}; use the variables {', '.join(variables)}, "
                f"the functions {', '.join((*_FUNCTIONS, 'Abs'))} and the constants {', '.join(_CONSTANTS)}.",
                key=label,
            )
        if token.type not in _TOKENS or (token.type == tokenize.OP and token.string not in _OPERATORS):
            raise ScenarioError(
                f"{quoted} uses {token.string!r}; use numbers, {', '.join(variables)}, functions and + - * / ** ( ).",
                key=label,
            )


def _constant(node: ast.expr) -> float | None:
    """The value of a subexpression made of numbers and arithmetic only, in floats (an overflow
    gives inf); None if it involves a variable or a function."""
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        value = _constant(node.operand)
        return None if value is None else (-value if isinstance(node.op, ast.USub) else value)
    if isinstance(node, ast.BinOp):
        left, right = _constant(node.left), _constant(node.right)
        if left is None or right is None:
            return None
        with np.errstate(all="ignore"):
            operations = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide}
            if isinstance(node.op, ast.Pow):
                return float(np.power(np.float64(left), right)) if left >= 0 or right == int(right) else float("nan")
            operation = operations.get(type(node.op))
            return None if operation is None else float(operation(np.float64(left), right))
    return None


def _check_exponents(text: str, label: str) -> None:
    """Refuse exponents like ``9**9**9`` before sympy computes them exactly (370 million digits)."""
    try:
        tree = ast.parse(text.replace("^", "**"), mode="eval")
        exponents = [
            _constant(node.right)
            for node in ast.walk(tree)
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow)
        ]
    except (SyntaxError, RecursionError, MemoryError):
        return  # sympy's parser gives the error message
    for exponent in exponents:
        if exponent is not None and not abs(exponent) <= MAX_EXPONENT:
            raise ScenarioError(
                f"{label} = {shown(text)} has the exponent {exponent:.3g}; exponents must be at most "
                f"{MAX_EXPONENT:g} in size.",
                key=label,
            )


def _parse_expression(text: object, variables: tuple[str, ...], label: str) -> tuple[Any, list[Any], Any]:
    """``(sympy, symbols, expression)`` for a real expression in the given variables."""
    text = _string(text, label).strip()
    sympy = _sympy()
    parser = sympy.parsing.sympy_parser
    symbols = {name: sympy.Symbol(name, real=True) for name in variables}
    namespace = {name: getattr(sympy, name) for name in (*_FUNCTIONS, *_CONSTANTS, "Abs")}
    namespace |= {"abs": sympy.Abs, **symbols}
    _check_tokens(text, frozenset(namespace), variables, label)
    _check_exponents(text, label)
    quoted = f"{label} = {shown(text)}"
    try:
        transformations = (*parser.standard_transformations, parser.convert_xor)
        expression = parser.parse_expr(text, local_dict=namespace, transformations=transformations, evaluate=True)
    except Exception as error:  # eval of a bad expression can raise almost any exception type
        raise ScenarioError(f"{quoted} is not a valid expression ({type(error).__name__}).", key=label) from None
    # Only evaluation can bring in I or an infinity (the names are checked): sqrt(-2), log(0).
    strange = (sympy.I, sympy.zoo, sympy.nan, sympy.oo, -sympy.oo)
    if not isinstance(expression, sympy.Expr) or expression.has(*strange) or expression.is_real is False:
        raise ScenarioError(f"{quoted} is not a real-valued expression in {', '.join(variables)}.", key=label)
    return sympy, list(symbols.values()), expression


def _derivative(sympy: Any, expression: Any, *symbols: Any) -> Any:
    # A kink (Abs) differentiates to a DiracDelta: zero away from the kink, all a Hessian can use.
    return sympy.diff(expression, *symbols).replace(sympy.DiracDelta, lambda *_: sympy.S.Zero)


def _arrays(values: list[Any], k: int) -> list[FloatArray]:
    """lambdify returns plain numbers for constant entries: broadcast every entry to (k,)."""
    return [np.broadcast_to(np.asarray(value, dtype=np.float64), (k,)).copy() for value in values]


@dataclass(frozen=True)
class Graph:
    """Terrain: the region below ``y = f(x)``, with ``phi = f(x) - y``.

    ``f`` is text in x (e.g. ``"-0.6 + 0.25*exp(-40*(x-0.5)**2)"``), differentiated by sympy.
    Whether the region is convex is not checked, so ``convex`` is False.
    """

    f: str
    name: str = "graph"
    _function: Callable[..., list[Any]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        label = _labeller(self.name)("f")
        sympy, (x,), f = _parse_expression(self.f, ("x",), label)
        derivatives = [f, _derivative(sympy, f, x), _derivative(sympy, f, x, 2)]
        object.__setattr__(self, "_function", sympy.lambdify(x, derivatives, modules="numpy"))

    def __reduce__(self) -> tuple[Any, ...]:
        # Lambdified functions do not pickle (process pools): rebuild from the text instead.
        return (type(self), (self.f, self.name))

    @property
    def convex(self) -> bool:
        return False

    def evaluate(self, points: FloatArray) -> Evaluation:
        points = np.asarray(points, dtype=np.float64)
        k = points.shape[0]
        with np.errstate(all="ignore"):  # a NaN (say log of a negative) is the solver's to report
            f, slope, curvature = _arrays(self._function(points[:, 0]), k)
        gradient = np.column_stack([slope, -np.ones(k)])
        hessian = np.zeros((k, 2, 2))
        hessian[:, 0, 0] = curvature
        return _checked(self.name, points, f - points[:, 1], gradient, hessian)

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        xmin, xmax, ymin, ymax = bounds
        x = np.linspace(xmin, xmax, samples)
        with np.errstate(all="ignore"):
            (f,) = _arrays(self._function(x)[:1], samples)
        # Where f is undefined draw no ground; the clip keeps the curve inside the plot.
        y = np.clip(np.nan_to_num(f, nan=ymin), ymin, ymax)
        return np.vstack([np.column_stack([x, y]), [[xmax, ymin], [xmin, ymin], [x[0], y[0]]]])


@dataclass(frozen=True)
class Surface:
    """Terrain in space: the region below ``z = f(x, y)``, with ``phi = f(x, y) - z``.

    ``height`` is text in x and y (e.g. ``"0.1*sin(3*x) - 0.5"``), differentiated by sympy, as
    :class:`Graph` is in the plane. Whether the region is convex is not checked, so ``convex`` is
    False.
    """

    height: str
    name: str = "surface"
    _function: Callable[..., list[Any]] = field(init=False, repr=False, compare=False)

    dimension = 3  # (a class attribute, not a field)

    def __post_init__(self) -> None:
        label = _labeller(self.name)("height")
        sympy, (x, y), f = _parse_expression(self.height, ("x", "y"), label)
        terms = [f, _derivative(sympy, f, x), _derivative(sympy, f, y)]
        terms += [_derivative(sympy, f, x, x), _derivative(sympy, f, x, y), _derivative(sympy, f, y, y)]
        object.__setattr__(self, "_function", sympy.lambdify((x, y), terms, modules="numpy"))

    def __reduce__(self) -> tuple[Any, ...]:
        # Lambdified functions do not pickle (process pools): rebuild from the text instead.
        return (type(self), (self.height, self.name))

    @property
    def convex(self) -> bool:
        return False

    def heights(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """``f(x, y)`` at points given by their coordinates (any matching shapes), for plots."""
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        with np.errstate(all="ignore"):
            (f,) = _arrays(self._function(x.ravel(), y.ravel())[:1], x.size)
        return f.reshape(x.shape)

    def evaluate(self, points: FloatArray) -> Evaluation:
        points = np.asarray(points, dtype=np.float64)
        k = points.shape[0]
        with np.errstate(all="ignore"):  # a NaN (say log of a negative) is the solver's to report
            f, fx, fy, fxx, fxy, fyy = _arrays(self._function(points[:, 0], points[:, 1]), k)
        gradient = np.column_stack([fx, fy, -np.ones(k)])
        hessian = np.zeros((k, 3, 3))
        hessian[:, 0, 0], hessian[:, 0, 1], hessian[:, 1, 0], hessian[:, 1, 1] = fxx, fxy, fxy, fyy
        return _checked(self.name, points, f - points[:, 2], gradient, hessian, 3)


_VARIABLES = ("x", "y", "z")


@dataclass(frozen=True)
class Expression:
    """Any obstacle ``{phi >= 0}`` with ``phi`` written as text: in x and y in the plane, in x, y
    and z in space (``dimension = 3``).

    Gradient and Hessian come from sympy. Convexity is not checked (``convex`` is False), and
    :meth:`outline` is empty: plot ``phi >= 0`` on a grid (e.g. ``contourf``) instead.
    """

    phi: str
    name: str = "expression"
    dimension: int = 2
    _function: Callable[..., list[Any]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        if isinstance(self.dimension, bool) or self.dimension not in (2, 3):
            raise ScenarioError(
                f"{key('dimension')} = {shown(self.dimension)}; use 2 (phi in x, y) or 3 (phi in x, y, z).",
                key=key("dimension"),
            )
        d = int(self.dimension)
        object.__setattr__(self, "dimension", d)
        sympy, symbols, phi = _parse_expression(self.phi, _VARIABLES[:d], key("phi"))
        # phi, its d first derivatives, then the Hessian's upper triangle row by row.
        terms = [phi, *(_derivative(sympy, phi, s) for s in symbols)]
        terms += [_derivative(sympy, phi, symbols[i], symbols[j]) for i in range(d) for j in range(i, d)]
        object.__setattr__(self, "_function", sympy.lambdify(symbols, terms, modules="numpy"))

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.phi, self.name, self.dimension))

    @property
    def convex(self) -> bool:
        return False

    def evaluate(self, points: FloatArray) -> Evaluation:
        d = self.dimension
        points = np.asarray(points, dtype=np.float64)
        k = points.shape[0]
        with np.errstate(all="ignore"):
            values = _arrays(self._function(*points.T[:d]), k)
        gradient = np.column_stack(values[1 : 1 + d])
        hessian = np.empty((k, d, d))
        upper = iter(values[1 + d :])
        for i in range(d):
            for j in range(i, d):
                hessian[:, i, j] = hessian[:, j, i] = next(upper)
        return _checked(self.name, points, values[0], gradient, hessian, d)

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        return np.empty((0, 2))


@dataclass(frozen=True)
class CallableObstacle:
    """Any Python ``function(points) -> (phi, gradient, hessian)``, checked on every call.

    Wrong shapes or non-finite values raise :class:`ScenarioError` naming the obstacle.
    :meth:`outline` is empty (plot ``phi >= 0`` on a grid instead).
    """

    function: Callable[[FloatArray], Any]
    name: str = "callable"
    convex: bool = False

    def evaluate(self, points: FloatArray) -> Evaluation:
        points = np.asarray(points, dtype=np.float64)
        result = self.function(points)
        if not (isinstance(result, (tuple, list)) and len(result) == 3):
            what = (
                f"{len(result)} values"
                if isinstance(result, (tuple, list))
                else f"an object of type {type(result).__name__}"
            )
            raise ScenarioError(f"obstacle {self.name!r}: the function returned {what}, not (phi, gradient, hessian).")
        try:
            phi, gradient, hessian = (np.asarray(value, dtype=np.float64) for value in result)
        except (TypeError, ValueError):
            raise ScenarioError(f"obstacle {self.name!r}: the function returned non-numeric arrays.") from None
        return _checked(self.name, points, phi, gradient, hessian)

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        return np.empty((0, 2))


# ----------------------------------------------------------------- link segments (contact = "links")
SEGMENT_SHAPES = (Disk, Ellipse, Box, HalfPlane)
SEGMENT_BISECTIONS = 60  # a box's maximiser to 2^-60 of the segment
_TIE = 1e-12  # |slope| below this (relative to |grad phi| |b - a|) is a flat segment: no preferred end


class SegmentMax(NamedTuple):
    """The largest phi along segments ``[a, b]``: ``psi = max_{t in [0,1]} phi((1-t) a + t b)``.

    psi (k,); t (k,) the maximiser; gradient (k, 2) grad phi at ``p* = (1-t) a + t b``, so that
    ``d psi/da = (1-t) gradient`` and ``d psi/db = t gradient`` (envelope theorem); hessian
    (k, 4, 4) the exact Hessian of psi in ``(a_x, a_y, b_x, b_y)`` where the maximiser is unique.
    """

    psi: FloatArray
    t: FloatArray
    gradient: FloatArray
    hessian: FloatArray


def depth(obstacle: Obstacle, points: FloatArray) -> FloatArray:
    """How deep each point lies inside ``obstacle``, a length (negative outside): exact for the
    built-in shapes (their ``depth``: the distance to the boundary), else to first order
    ``phi / |grad phi|``, infinite (with phi's sign) where the gradient vanishes, NaN where phi or
    its gradient is not finite."""
    exact = getattr(obstacle, "depth", None)
    if exact is not None:
        result: FloatArray = np.asarray(exact(np.asarray(points, dtype=np.float64)), dtype=np.float64)
        return result
    phi, gradient, _ = obstacle.evaluate(points)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):  # (inf / inf: NaN, not deeper than anything)
        result = phi / np.linalg.norm(gradient, axis=1)
    return result


def has_segment_max(obstacle: Obstacle) -> bool:
    """Whether :func:`segment_max` works for this obstacle: the convex built-in shapes."""
    return isinstance(obstacle, SEGMENT_SHAPES)


def _derivative_argmax(obstacle: Obstacle, a: FloatArray, d: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """Maximiser of the concave ``phi(a + t d)`` on [0, 1] by bisection on the sign of its slope
    (a box's phi is only C1, so no Newton): monotone, so it cannot miss or leave the interval.
    Also whether it is strictly interior (the slope changes sign along the segment)."""

    def slope(t: FloatArray) -> FloatArray:
        _, gradient, _ = obstacle.evaluate(a + t[:, None] * d)
        result: FloatArray = np.einsum("ij,ij->i", gradient, d)
        return result

    low, high = np.zeros(a.shape[0]), np.ones(a.shape[0])
    rising_at_end = slope(high) >= 0.0
    falling_at_start = slope(low) <= 0.0
    for _ in range(SEGMENT_BISECTIONS):
        middle = 0.5 * (low + high)
        up = slope(middle) > 0.0
        low, high = np.where(up, middle, low), np.where(up, high, middle)
    t = np.where(falling_at_start, 0.0, np.where(rising_at_end, 1.0, 0.5 * (low + high)))
    return t, ~falling_at_start & ~rising_at_end


def _quadratic_argmax(obstacle: Obstacle, a: FloatArray, d: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """Maximiser of ``phi(a + t d)`` on [0, 1] when phi is quadratic (disk, ellipse, half-plane):
    ``phi(a) + s t + c t^2 / 2`` with slope ``s = grad phi(a).d`` and curvature ``c = d.H d <= 0``.
    Also whether it is strictly interior."""
    _, gradient, hessian = obstacle.evaluate(a)
    s = np.einsum("ij,ij->i", gradient, d)
    c = np.einsum("ij,ijk,ik->i", d, hessian, d)
    flat = np.abs(s) <= _TIE * np.hypot(*gradient.T) * np.hypot(*d.T)
    end = np.where(flat, 0.5, np.where(s > 0.0, 1.0, 0.0))  # linear along the segment: the higher end
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = -s / c
    interior = (c < 0.0) & (vertex > 0.0) & (vertex < 1.0)
    return np.where(c < 0.0, np.clip(vertex, 0.0, 1.0), end), interior


def _argmax(obstacle: Obstacle, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray]:
    """``(a, b, t, interior)``: the segments as (k, 2) arrays, phi's maximiser along them and
    whether it is strictly interior."""
    if not has_segment_max(obstacle):
        raise ScenarioError(
            f"obstacle {obstacle.name!r}: keeping whole links out needs a convex built-in shape "
            "(disk, ellipse, box, halfplane)."
        )
    a, b = np.asarray(a, dtype=np.float64).reshape(-1, 2), np.asarray(b, dtype=np.float64).reshape(-1, 2)
    argmax = _derivative_argmax if isinstance(obstacle, Box) else _quadratic_argmax
    t, interior = argmax(obstacle, a, b - a)
    return a, b, t, interior


def _at(obstacle: Obstacle, a: FloatArray, b: FloatArray, t: FloatArray, interior: np.ndarray) -> SegmentMax:
    """phi at ``p* = (1-t) a + t b`` with the derivatives of ``psi(a, b) = phi(p*)``: t moves with
    (a, b) where it is an interior maximiser (``interior``), and is fixed elsewhere."""
    d = b - a
    psi, g, h = obstacle.evaluate(a + t[:, None] * d)
    w = np.stack((1.0 - t, t), axis=1)
    hessian = np.einsum("nr,nc,nij->nricj", w, w, h).reshape(-1, 4, 4)
    hd = np.einsum("kij,kj->ki", h, d)
    curvature = np.einsum("ki,ki->k", d, hd)
    moving = interior & (curvature < 0.0)
    if np.any(moving):
        v = np.concatenate(((1.0 - t)[:, None] * hd - g, t[:, None] * hd + g), axis=1)[moving]
        hessian[moving] += v[:, :, None] * v[:, None, :] / -curvature[moving, None, None]
    return SegmentMax(psi, t, g, hessian)


def segment_max(obstacle: Obstacle, a: FloatArray, b: FloatArray) -> SegmentMax:
    """psi, the maximiser and the derivatives of phi's maximum over each segment ``[a_k, b_k]``.

    Only for :func:`has_segment_max` shapes, whose phi is concave, so phi along a segment has one
    maximum. Where it is attained on a whole interval (a segment along a straight edge or a
    half-plane's boundary) the midpoint or an end of that interval is taken: psi is exact, its
    gradient one of the subgradients. The Hessian is ``w w^T (x) H`` (w = (1-t, t), H = Hess phi at
    ``p*``) plus, for an interior maximiser, the term from the maximiser moving,
    ``v v^T / (-d.H d)`` with ``v = ((1-t) H d - g, t H d + g)``, ``d = b - a``, ``g = grad phi(p*)``.
    """
    a, b, t, interior = _argmax(obstacle, a, b)
    return _at(obstacle, a, b, t, interior)


# ----------------------------------------------------------------- how deep a segment reaches
DEPTH_SHAPES = (Disk, Sphere, HalfPlane, HalfSpace, Ellipse, Ellipsoid, Box, Cuboid)
SEGMENT_DEPTH_STEPS = 60  # most steps of the search along a segment (each at least halves its bracket)
DEPTH_BRACKET = 1e-13  # a bracket this narrow (a fraction of the segment) holds the deepest point
DEPTH_SLOPE = 1e-10  # a slope this small (relative to the segment's length) is the deepest point's


def has_segment_depth(obstacle: Obstacle) -> bool:
    """Whether :func:`segment_depth` knows how deep a segment reaches into ``obstacle``: the
    built-in shapes (exactly those types: a subclass may change ``evaluate``)."""
    return type(obstacle) in DEPTH_SHAPES


def segment_depth(obstacle: Obstacle, a: FloatArray, b: FloatArray) -> FloatArray:
    """How deep each segment ``[a_k, b_k]`` (k, d) reaches into a built-in obstacle
    (:func:`has_segment_depth`): the largest distance from a point of the segment to the
    obstacle's boundary, over its points inside; 0 for a segment that stays out.

    A disk's or a sphere's is the depth of the segment's point nearest the centre, a half-plane's
    or a half-space's that of its deeper end. The others' depth (minus the signed distance to a
    convex set) is concave along the segment, and :func:`_concave_peak` finds its largest value.
    """
    if not has_segment_depth(obstacle):
        raise ScenarioError(f"obstacle {obstacle.name!r}: how deep a link reaches is known for built-in shapes only.")
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if isinstance(obstacle, Disk | Sphere):
        d = b - a
        with np.errstate(divide="ignore", invalid="ignore"):  # (a segment of length 0: its end)
            t = np.sum((np.asarray(obstacle.center) - a) * d, axis=1) / np.sum(d * d, axis=1)
        deepest = depth(obstacle, a + np.clip(np.nan_to_num(t), 0.0, 1.0)[:, None] * d)
    elif isinstance(obstacle, HalfPlane | HalfSpace):
        deepest = np.maximum(depth(obstacle, a), depth(obstacle, b))
    elif isinstance(obstacle, Ellipse | Ellipsoid):
        deepest = _concave_peak(obstacle.depth_and_gradient, a, b)
    else:  # a box or a cuboid: phi is the depth itself
        deepest = _concave_peak(lambda points: obstacle.evaluate(points)[:2], a, b)
    result: FloatArray = np.maximum(deepest, 0.0)
    return result


def _concave_peak(
    depth_and_gradient: Callable[[FloatArray], tuple[FloatArray, FloatArray]], a: FloatArray, b: FloatArray
) -> FloatArray:
    """The largest value along each segment ``[a_k, b_k]`` of a depth concave along it, given its
    values and gradients at points.

    Its slope along a segment decreases: the largest value is at an end where the slope there
    does not point into the segment, else where the slope changes sign. A bracket of that point
    narrows at each step to three points: the secant's root of the slope (fast where the depth is
    smooth), where the tangents at the bracket's ends meet (fast where the slope jumps: the ridge
    of an ellipse's distance, a box's inner diagonals) and the midpoint (at least a halving). The
    largest depth evaluated is returned: exact at an end, within DEPTH_BRACKET of the segment's
    length times the slope at a ridge, and within the square of the slope left (DEPTH_SLOPE) at a
    smooth maximum."""
    d = b - a
    k = a.shape[0]
    values, gradients = depth_and_gradient(np.concatenate((a, b)))
    slopes = np.einsum("ij,ij->i", gradients, np.concatenate((d, d)))
    best = np.maximum(values[:k], values[k:])
    rows = np.flatnonzero((slopes[:k] > 0.0) & (slopes[k:] < 0.0))  # deepest strictly inside
    low, high = np.zeros(rows.size), np.ones(rows.size)
    rise, fall = slopes[:k][rows], slopes[k:][rows]
    at_low, at_high = values[:k][rows], values[k:][rows]
    for _ in range(SEGMENT_DEPTH_STEPS):
        if not rows.size:
            break
        n = rows.size
        steep = rise - fall  # > 0
        secant = low + rise * (high - low) / steep
        meet = (at_high - at_low + rise * low - fall * high) / steep
        at = np.clip(np.concatenate((secant, meet, 0.5 * (low + high))), np.tile(low, 3), np.tile(high, 3))
        thrice = np.tile(rows, 3)
        values, gradients = depth_and_gradient(a[thrice] + at[:, None] * d[thrice])
        slope = np.einsum("ij,ij->i", gradients, d[thrice])
        best[rows] = np.maximum(best[rows], values.reshape(3, n).max(axis=0))
        for t, slope_t, value_t in zip(at.reshape(3, n), slope.reshape(3, n), values.reshape(3, n), strict=True):
            up, down = (slope_t > 0.0) & (t > low), (slope_t < 0.0) & (t < high)
            low, rise, at_low = np.where(up, t, low), np.where(up, slope_t, rise), np.where(up, value_t, at_low)
            high, fall = np.where(down, t, high), np.where(down, slope_t, fall)
            at_high = np.where(down, value_t, at_high)
        flat = np.abs(slope).reshape(3, n).min(axis=0) <= DEPTH_SLOPE * np.linalg.norm(d[rows], axis=1)
        going = ~flat & (high - low > DEPTH_BRACKET)
        rows, low, high = rows[going], low[going], high[going]
        rise, fall, at_low, at_high = rise[going], fall[going], at_low[going], at_high[going]
    return best


def link_contact_ends(is_support: NDArray[np.bool_]) -> tuple[FloatArray, NDArray[np.bool_]]:
    """For every link, ``(end, pinned)``: ``end`` (0: p_k, 1: p_{k+1}) is the end whose phi is the
    link's contact row when phi has no interior maximum along it (see :func:`link_contact`), and
    ``pinned`` says whether the link has a support end. ``end`` is the free end of a link next to a
    support, else the end away from the first support: every free node is ``end`` of some link."""
    first = int(np.argmax(is_support))
    end = np.where(np.arange(is_support.size - 1) < first, 0.0, 1.0)
    end = np.where(is_support[:-1], 1.0, np.where(is_support[1:], 0.0, end))
    return end, is_support[:-1] | is_support[1:]


def link_contact(
    obstacle: Obstacle, a: FloatArray, b: FloatArray, end: FloatArray, pinned: NDArray[np.bool_]
) -> SegmentMax:
    """The contact row of ``contact = "links"`` for links ``[a_k, b_k]``: ``psi = phi(p*)`` with its
    derivatives, ``p* = (1-t) a + t b``; ``end`` and ``pinned`` from :func:`link_contact_ends`.

    A disk's or ellipse's phi is strictly concave along a link, so psi = :func:`segment_max` is
    C1. A half-plane's or a box side's phi is affine along a link, and its maximum jumps from
    one end to the other as a link lying along the boundary tilts: psi is not differentiable
    there and Newton's method stalls. For those shapes, and for links with a support end (a
    contact at the support is the support's, as in ``contact = "nodes"``, so a support on the
    surface does not pin the row at 0), the row is phi at the maximiser only where it is strictly
    inside the link, and phi at ``end`` otherwise. Every free node is some link's ``end``, so the
    rows together still keep every link out, and at a solution a row with ``nu > 0`` has psi = 0,
    so p* is still where phi is largest along the link.
    """
    a, b, t, interior = _argmax(obstacle, a, b)
    ends_only = np.asarray(pinned) | (not isinstance(obstacle, (Disk, Ellipse)))
    t = np.where(interior | ~ends_only, t, np.asarray(end, dtype=np.float64))
    return _at(obstacle, a, b, t, interior)
