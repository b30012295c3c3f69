"""The scaled chain the solver core works on, and how it reaches the core.

Scaling: positions ``(p - origin) / length_unit`` (the first support is the origin, the longest
link the unit of length), forces / total weight, and obstacle j's phi divided by
``scale_j * length_unit`` where ``scale_j`` is a typical ``|grad phi_j|``: multiplying phi by a
constant leaves every iterate unchanged, and the stopping test does not depend on the units.

Constraint rows, in the core's order: the optimised links (``links``: those with a free end), then
for every obstacle j its contact rows: one per free node (``contact = "nodes"``), or one per
optimised link (``contact = "links"``: ``psi_jk = phi_j(p*) <= 0`` at the point p* of link k where
phi_j is largest, see :func:`funicular.obstacles.link_contact`).

Disks, ellipses and half-planes reach the core as the coefficients of their quadratic phi and are
evaluated there. Every other obstacle is evaluated here, by one call of its ``evaluate`` per
evaluation of the core with every point at once (``_NodeField``, ``_SegmentField``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from funicular import _core
from funicular.model import FloatArray, Formulation, IntArray
from funicular.obstacles import Obstacle, Stacked, link_contact
from funicular.solver.initial import as_slice

Fields = tuple[FloatArray, ...]


@dataclass
class ScaledChain:
    """The scaled problem (free nodes, the links that touch them, obstacles)."""

    formulation: Formulation
    positions: FloatArray  # (N, 2) scaled; fixed nodes hold their final positions
    free: IntArray  # movable nodes
    links: IntArray  # links with a movable end (chain link k joins nodes k and k+1)
    lengths: FloatArray  # (N-1,) scaled link lengths
    load: FloatArray  # (N,) scaled weight of each node, g m_i / W
    obstacles: tuple[Obstacle, ...]
    obstacle_scale: FloatArray  # (n_obstacles,) typical |grad phi_j|
    length_unit: float
    origin: FloatArray
    # The obstacles' phi as stacked quadratics in the problem's units (``Problem.quadratic_obstacles``):
    # None unless every obstacle is a disk, an ellipse or a half-plane.
    quadratics: Stacked | None
    contact_links: bool = False  # contact rows per (obstacle, optimised link) instead of per (obstacle, free node)
    contact_ends: tuple[FloatArray, np.ndarray] | None = None  # per link (N-1,): obstacles.link_contact_ends

    def __post_init__(self) -> None:
        self.free_at: slice | IntArray = as_slice(self.free)
        self.links_at: slice | IntArray = as_slice(self.links)

    def moved(self, positions: FloatArray) -> ScaledChain:
        """The same chain from other (scaled) positions, its fixed nodes where they were."""
        chain = object.__new__(ScaledChain)
        chain.__dict__.update(self.__dict__)
        chain.positions = positions
        return chain

    @property
    def contact_rows_at(self) -> slice | IntArray:
        """What each obstacle's contact rows stand for, as a slice where it is one."""
        return self.links_at if self.contact_links else self.free_at

    @property
    def n_contact_rows(self) -> int:
        """Contact rows per obstacle."""
        return int(self.links.size if self.contact_links else self.free.size)

    @property
    def n_constraints(self) -> int:
        return int(self.links.size + len(self.obstacles) * self.n_contact_rows)

    def physical(self, scaled_positions: FloatArray) -> FloatArray:
        return scaled_positions * self.length_unit + self.origin

    def core(self) -> _core.Network:
        """The chain as the core's network (its positions, links and obstacles)."""
        links = np.stack((self.links, self.links + 1), axis=1).astype(np.int64)
        quadratics, field = None, None
        if self.obstacles and self.quadratics is not None and not self.contact_links:
            centres, values, gradients, hessians = self.quadratics
            unit, length = self.obstacle_scale, self.length_unit
            # p = length_unit s + origin; phi / (scale length_unit) over s
            quadratics = (
                np.ascontiguousarray((centres - self.origin) / length),
                np.ascontiguousarray(values / (unit * length)),
                np.ascontiguousarray(gradients / unit[:, None]),
                np.ascontiguousarray(hessians * (length / unit)[:, None, None]),
            )
        elif self.obstacles:
            field = _SegmentField(self) if self.contact_links else _NodeField(self)
        return _core.Network(
            2,
            self.formulation is Formulation.SQUARED,
            np.ascontiguousarray(self.positions, dtype=np.float64),
            self.free.astype(np.int64),
            links,
            np.ascontiguousarray(self.lengths[self.links]),
            np.ascontiguousarray(self.load, dtype=np.float64),
            np.ascontiguousarray(self.origin / self.length_unit),
            quadratics,
            field,
            len(self.obstacles),
            self.contact_links,
        )


class _NodeField:
    """Node contact: every obstacle's scaled phi, gradient and Hessian at the free nodes' scaled
    positions (n, 2), stacked obstacle by obstacle for the core."""

    def __init__(self, chain: ScaledChain) -> None:
        self.chain = chain

    def __call__(self, points: FloatArray) -> Fields:
        chain = self.chain
        physical = chain.physical(points)
        k, n = len(chain.obstacles), points.shape[0]
        phi, gradient, hessian = np.empty((k, n)), np.empty((k, n, 2)), np.empty((k, n, 2, 2))
        for j, obstacle in enumerate(chain.obstacles):
            value, grad, hess = obstacle.evaluate(physical)
            unit = chain.obstacle_scale[j]
            np.divide(value, unit * chain.length_unit, out=phi[j])
            np.divide(grad, unit, out=gradient[j])
            np.multiply(hess, chain.length_unit / unit, out=hessian[j])
        return phi, gradient, hessian


class _SegmentField:
    """Link contact: every obstacle's scaled psi, t, gradient and Hessian of psi (4 x 4) along the
    optimised links, from every node's scaled positions (N, 2)."""

    def __init__(self, chain: ScaledChain) -> None:
        self.chain = chain

    def __call__(self, positions: FloatArray) -> Fields:
        chain = self.chain
        assert chain.contact_ends is not None  # set whenever contact_links is
        end, pinned = chain.contact_ends
        k, n_obstacles = chain.links, len(chain.obstacles)
        points = chain.physical(positions)
        psi, t = np.empty((n_obstacles, k.size)), np.empty((n_obstacles, k.size))
        gradient, hessian = np.empty((n_obstacles, k.size, 2)), np.empty((n_obstacles, k.size, 4, 4))
        for j, obstacle in enumerate(chain.obstacles):
            segment = link_contact(obstacle, points[k], points[k + 1], end[k], pinned[k])
            unit = chain.obstacle_scale[j]
            psi[j] = segment.psi / (unit * chain.length_unit)
            t[j] = segment.t
            gradient[j] = segment.gradient / unit
            hessian[j] = segment.hessian * (chain.length_unit / unit)
        return psi, t, gradient, hessian
