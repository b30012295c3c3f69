"""The built-in shapes as the solver core evaluates them.

A built-in shape is a ``NativeShape``, its kind and parameters, and :func:`evaluate_native` asks
the core for its phi, gradient and Hessian (the one implementation of those formulas). A phi that
is exactly quadratic (disk, ellipse, half-plane, sphere, ellipsoid, half-space) is given by its
coefficients (:class:`Quadratic`); ``_QuadraticShape`` and ``_SpatialQuadratic`` give those shapes
their ``evaluate``.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from funicular import _core
from funicular._types import FloatArray
from funicular.obstacles.base import Evaluation

NativeShape = tuple[str, list[float]]  # a built-in shape as the solver core evaluates it


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


def evaluate_native(shape: NativeShape, points: FloatArray, dimension: int = 2) -> Evaluation:
    """phi, gradient and Hessian of a built-in shape at ``points`` (k, d), evaluated by the solver
    core (the one implementation of these formulas)."""
    d = dimension
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, d)
    fields = _core.evaluate_shapes(shapes=[_core.Shape(kind=shape[0], parameters=shape[1])], points=points, dim=d)
    k = points.shape[0]
    return fields.phi.reshape(k), fields.gradient.reshape(k, d), fields.hessian.reshape(k, d, d)


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
