"""What every obstacle is and what any obstacle gives, whatever its shape.

The :class:`Obstacle` protocol and the types the package shares (``Evaluation``, ``Bounds``,
``NodeFields``); an obstacle's dimension (:func:`obstacle_dimension`), its outline for plots
(:func:`outline`) and how deep points lie inside it (:func:`depth`); and the checks of a shape's
parameters and of the evaluations that come from user text or code (the ``_``-named helpers), each
error naming the field or obstacle it refuses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np

from funicular._types import MAX_SIZE, FloatArray
from funicular.errors import ScenarioError, shown

Evaluation = tuple[FloatArray, FloatArray, FloatArray]
Bounds = tuple[float, float, float, float]  # xmin, xmax, ymin, ymax
# Every obstacle's phi (N,) and gradient (N, d) at every node.
NodeFields = list[tuple[FloatArray, FloatArray]]


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


def obstacle_dimension(obstacle: Obstacle) -> int:
    """Whether an obstacle lives in the plane (2, the default) or in space (3): its ``dimension``."""
    dimension = getattr(obstacle, "dimension", 2)
    return dimension if isinstance(dimension, int) else 2


def outline(obstacle: Obstacle, bounds: Bounds, samples: int = 200) -> FloatArray:
    """A closed polygon (k, 2) of the obstacle inside ``bounds``; empty (0, 2) if the shape has none."""
    method = getattr(obstacle, "outline", None)
    return np.empty((0, 2)) if method is None else np.asarray(method(bounds, samples), dtype=np.float64)


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


def _triple(value: object, label: str, positive: bool = False) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in _vector(value, label, 3, positive))
    return x, y, z


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
