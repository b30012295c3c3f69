"""A problem as the solver core's chain (``_core.Chain``) or net (``_core.Net``): masses, links and
their lengths, supports, the formulation and the obstacles, all in the problem's units (the core
scales them itself).

Disks, ellipses, half-planes, boxes, spheres, ellipsoids and half-spaces reach the core as their
parameters and are evaluated there (``obstacles.native_shape``). Every other obstacle is evaluated
here, by one call of its ``evaluate`` per evaluation of the core with every point at once
(``node_field``); with ``contact = "links"`` the
largest phi along each link comes from :func:`funicular.obstacles.link_contact` (``_link_field``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from funicular import _core
from funicular.model import FloatArray, Formulation, IntArray, Problem
from funicular.obstacles import NativeShape, Obstacle, link_contact, link_contact_ends

Fields = tuple[FloatArray, ...]


def core_chain(problem: Problem) -> _core.Chain:
    """``problem`` as the core's chain."""
    links = problem.contact == "links" and bool(problem.obstacles)
    supports, positions, squared, shapes, field = _common(problem)
    masses, lengths = _floats(problem.masses), _floats(problem.link_lengths)
    return _core.Chain(
        problem.dimension, masses, lengths, float(problem.gravity), supports, positions, squared, shapes, field,
        _link_field(problem) if links else None, len(problem.obstacles),
    )  # fmt: skip


def core_net(problem: Problem) -> _core.Net:
    """``problem`` (a net: its links join any nodes; or a chain with point loads) as the core's net."""
    supports, positions, squared, shapes, field = _common(problem)
    masses, lengths = _floats(problem.masses), _floats(problem.link_lengths)
    ends = np.ascontiguousarray(problem.link_nodes, dtype=np.int64)
    loads = None if problem.loads is None else _floats(problem.loads).ravel()
    stiffness = None if problem.axial_stiffness is None else _floats(problem.axial_stiffness)
    return _core.Net(
        problem.dimension, masses, ends, lengths, float(problem.gravity), supports, positions, squared, shapes, field,
        len(problem.obstacles), loads, stiffness,
    )  # fmt: skip


def _floats(array: FloatArray) -> FloatArray:
    return np.ascontiguousarray(array, dtype=np.float64)


def _common(
    problem: Problem,
) -> tuple[NDArray[np.int64], FloatArray, bool, list[NativeShape] | None, Callable[[FloatArray], Fields] | None]:
    """What the core's chain and net both take: the supports, their positions, the formulation,
    and the obstacles as built-in shapes or as a field evaluated here."""
    native = problem.native_obstacles
    field = node_field(problem.obstacles) if problem.obstacles and native is None else None
    squared = problem.formulation is Formulation.SQUARED
    return problem.support_nodes.astype(np.int64), _floats(problem.support_positions), squared, native, field


def node_field(obstacles: tuple[Obstacle, ...]) -> Callable[[FloatArray], Fields]:
    """Every obstacle's phi, gradient and Hessian at points (n, d), stacked obstacle by obstacle."""

    def field(points: FloatArray) -> Fields:
        k, (n, d) = len(obstacles), points.shape
        phi, gradient, hessian = np.empty((k, n)), np.empty((k, n, d)), np.empty((k, n, d, d))
        for j, obstacle in enumerate(obstacles):
            phi[j], gradient[j], hessian[j] = obstacle.evaluate(points)
        return phi, gradient, hessian

    return field


def _link_field(problem: Problem) -> Callable[[FloatArray, IntArray], Fields]:
    """Every obstacle's psi, t, gradient and Hessian of psi (4 x 4) along the links given by their
    first nodes, from every node's positions (N, 2)."""
    obstacles = problem.obstacles
    end, pinned = link_contact_ends(problem.is_support)

    def field(points: FloatArray, links: IntArray) -> Fields:
        k, m = len(obstacles), links.size
        psi, t = np.empty((k, m)), np.empty((k, m))
        gradient, hessian = np.empty((k, m, 2)), np.empty((k, m, 4, 4))
        for j, obstacle in enumerate(obstacles):
            segment = link_contact(obstacle, points[links], points[links + 1], end[links], pinned[links])
            psi[j], t[j], gradient[j], hessian[j] = segment.psi, segment.t, segment.gradient, segment.hessian
        return psi, t, gradient, hessian

    return field
