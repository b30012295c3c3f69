"""Rigid obstacles: each occupies ``{phi >= 0}``; every free node must satisfy ``phi(x, y) <= 0``.

An obstacle is anything with a ``name``, a ``convex`` flag and ``evaluate(points)`` returning
``phi`` (k,), its gradient (k, 2) and its Hessian (k, 2, 2) at the points (k, 2), vectorised.
The contact force obstacle j exerts on node i is ``-nu_ji grad phi_j(p_i)``: it points out of
the obstacle and does not change when phi is multiplied by a positive constant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from funicular.errors import ScenarioError
from funicular.model import FloatArray

Evaluation = tuple[FloatArray, FloatArray, FloatArray]


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


@dataclass(frozen=True)
class Disk:
    """A disk; ``phi = (r^2 - |p - c|^2) / (2 r)``: smooth everywhere, unit gradient on the rim."""

    center: tuple[float, float]
    radius: float
    name: str = "disk"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ScenarioError(f"obstacle {self.name!r}: radius = {self.radius} must be a positive number.")

    @property
    def convex(self) -> bool:
        return True

    def evaluate(self, points: FloatArray) -> Evaluation:
        offset = points - np.asarray(self.center)
        phi = (self.radius**2 - np.einsum("ij,ij->i", offset, offset)) / (2.0 * self.radius)
        gradient = -offset / self.radius
        hessian = np.broadcast_to(-np.eye(2) / self.radius, (points.shape[0], 2, 2))
        return phi, gradient, hessian


@dataclass(frozen=True)
class HalfPlane:
    """The half-plane behind a line through ``point`` whose unit ``normal`` points out into free space."""

    point: tuple[float, float]
    normal: tuple[float, float]
    name: str = "halfplane"

    def __post_init__(self) -> None:
        length = float(np.hypot(*self.normal))
        if not (np.isfinite(length) and length > 0):
            raise ScenarioError(f"obstacle {self.name!r}: normal = {list(self.normal)} must be a nonzero vector.")

    @property
    def convex(self) -> bool:
        return True

    def evaluate(self, points: FloatArray) -> Evaluation:
        normal = np.asarray(self.normal, dtype=np.float64)
        normal = normal / np.hypot(*normal)
        phi = -(points - np.asarray(self.point)) @ normal
        gradient = np.broadcast_to(-normal, points.shape)
        hessian = np.zeros((points.shape[0], 2, 2))
        return phi, gradient, hessian
