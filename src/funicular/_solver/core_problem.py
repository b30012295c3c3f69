"""A problem as the solver core's chain (``_core.Chain``) or net (``_core.Net``): masses, links and
their lengths, supports, the formulation and the obstacles, all in the problem's units (the core
scales them itself); and the core's errors as the package's (``package_error``: the one place they
are translated).

Disks, ellipses, half-planes, boxes, spheres, ellipsoids and half-spaces reach the core as their
parameters and are evaluated there (``obstacles.native_shape``). Every other obstacle is evaluated
here, by one call of its ``evaluate`` per evaluation of the core with every point at once
(``node_field``); with ``contact = "links"`` the
largest phi along each link comes from :func:`funicular.obstacles.link_contact` (``_link_field``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from funicular import _core
from funicular.errors import FunicularError, InfeasibleError, ScenarioError, SolverError
from funicular.model import FloatArray, Formulation, IntArray, Problem
from funicular.obstacles import Obstacle, link_contact, link_contact_ends


def core_chain(problem: Problem) -> _core.Chain:
    """``problem`` as the core's chain."""
    links = problem.contact == "links" and bool(problem.obstacles)
    return _core.Chain(
        dim=problem.dimension,
        masses=_floats(problem.masses),
        lengths=_floats(problem.link_lengths),
        gravity=float(problem.gravity),
        supports=problem.support_nodes.astype(np.int64),
        support_positions=_floats(problem.support_positions),
        squared=problem.formulation is Formulation.SQUARED,
        obstacles=_obstacles(problem, _link_field(problem) if links else None),
        stiffness=None if problem.axial_stiffness is None else _floats(problem.axial_stiffness),
    )


def core_net(problem: Problem) -> _core.Net:
    """``problem`` (a net: its links join any nodes; or a chain with point loads) as the core's net."""
    return _core.Net(
        dim=problem.dimension,
        masses=_floats(problem.masses),
        links=np.ascontiguousarray(problem.link_nodes, dtype=np.int64),
        lengths=_floats(problem.link_lengths),
        gravity=float(problem.gravity),
        supports=problem.support_nodes.astype(np.int64),
        support_positions=_floats(problem.support_positions),
        squared=problem.formulation is Formulation.SQUARED,
        obstacles=_obstacles(problem, None),
        loads=None if problem.loads is None else _floats(problem.loads).ravel(),
        stiffness=None if problem.axial_stiffness is None else _floats(problem.axial_stiffness),
    )


def _floats(array: FloatArray) -> FloatArray:
    return np.ascontiguousarray(array, dtype=np.float64)


def _obstacles(
    problem: Problem, links: Callable[[FloatArray, IntArray], _core.SegmentFields] | None
) -> _core.Obstacles:
    """The problem's obstacles as built-in shapes, or as a field evaluated here; with link contact
    also ``links``, their fields along the links."""
    native = problem.native_obstacles
    shapes = None if native is None else [_core.Shape(kind=kind, parameters=list(p)) for kind, p in native]
    field = node_field(problem.obstacles) if problem.obstacles and native is None else None
    return _core.Obstacles(count=len(problem.obstacles), shapes=shapes, field=field, links=links)


def node_field(obstacles: tuple[Obstacle, ...]) -> Callable[[FloatArray], _core.NodeFields]:
    """Every obstacle's phi, gradient and Hessian at points (n, d), stacked obstacle by obstacle."""

    def field(points: FloatArray) -> _core.NodeFields:
        k, (n, d) = len(obstacles), points.shape
        phi, gradient, hessian = np.empty((k, n)), np.empty((k, n, d)), np.empty((k, n, d, d))
        for j, obstacle in enumerate(obstacles):
            phi[j], gradient[j], hessian[j] = obstacle.evaluate(points)
        return _core.NodeFields(phi=phi, gradient=gradient, hessian=hessian)

    return field


def _link_field(problem: Problem) -> Callable[[FloatArray, IntArray], _core.SegmentFields]:
    """Every obstacle's psi, t, gradient and Hessian of psi (4 x 4) along the links given by their
    first nodes, from every node's positions (N, 2)."""
    obstacles = problem.obstacles
    end, pinned = link_contact_ends(problem.is_support)

    def field(points: FloatArray, links: IntArray) -> _core.SegmentFields:
        k, m = len(obstacles), links.size
        psi, t = np.empty((k, m)), np.empty((k, m))
        gradient, hessian = np.empty((k, m, 2)), np.empty((k, m, 4, 4))
        for j, obstacle in enumerate(obstacles):
            segment = link_contact(obstacle, points[links], points[links + 1], end[links], pinned[links])
            psi[j], t[j], gradient[j], hessian[j] = segment.psi, segment.t, segment.gradient, segment.hessian
        return _core.SegmentFields(psi=psi, t=t, gradient=gradient, hessian=hessian)

    return field


def package_error(problem: Problem, error: _core.CoreError) -> FunicularError:
    """The core's reason a solve (or its presolve) has no answer as the package's error, in one
    sentence about ``problem``; an error the core does not name is a :class:`SolverError`."""
    if isinstance(error, _core.SupportsTooFar):
        a, b = error.a, error.b
        pa, pb = problem.support_positions[np.searchsorted(problem.support_nodes, [a, b])]
        return InfeasibleError(
            f"supports at nodes {a} {tuple(pa.tolist())} and {b} {tuple(pb.tolist())} are {error.distance:.6g} apart, "
            f"but the chain between them is only {error.length:.6g} long; move them closer or lengthen the chain."
        )
    if isinstance(error, _core.TautNotVertical):
        return InfeasibleError(
            f"the chain between the supports at nodes {error.a} and {error.b} is exactly taut and not vertical, so its "
            "weight would need an infinite tension and no equilibrium with finite forces exists; lengthen the chain or "
            "align the supports vertically."
        )
    if isinstance(error, _core.NotFactored):
        return SolverError("the Newton matrix stayed indefinite under every inertia correction")
    if isinstance(error, _core.ObstacleNotFinite):
        what = f"link {error.index}" if problem.contact == "links" else f"node {error.index}"
        where = "of the initial guess" if error.at_start else "of the solution"
        return ScenarioError(
            f"obstacle {problem.obstacles[error.obstacle].name!r}: phi or its derivatives are not finite at {what} "
            f"{where}; phi must be twice differentiable wherever the chain can go."
        )
    return SolverError(f"the solver core stopped on an internal error ({error}); please report it")


@contextmanager
def core_errors(problem: Problem) -> Iterator[None]:
    """The core's errors raised as the package's (:func:`package_error`)."""
    try:
        yield
    except _core.CoreError as error:
        raise package_error(problem, error) from None
