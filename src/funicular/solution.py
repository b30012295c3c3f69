"""The result of a solve: positions, forces, multipliers, KKT residuals, status."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from functools import cached_property
from typing import Any

import numpy as np

from funicular._constraints import link_distances, norms, tension_from_multipliers
from funicular._diagnostics import KKTResiduals, kkt_residuals, link_penetration, scaled
from funicular._forces import applied_forces, contact_forces
from funicular.model import FloatArray, Problem
from funicular.obstacles import NodeFields

TAUT_RTOL = 1e-6  # a link counts as taut when d_k >= (1 - TAUT_RTOL) l_k


class Status(StrEnum):
    """How a solve ended."""

    OPTIMAL = "optimal"
    MAX_ITERATIONS = "max_iterations"
    STALLED = "stalled"
    NONFINITE = "nonfinite"
    DIVERGED = "diverged"

    @property
    def message(self) -> str:
        return {
            Status.OPTIMAL: "converged: the scaled KKT residuals are below the tolerance",
            Status.MAX_ITERATIONS: "did not converge: the iteration limit was reached",
            Status.STALLED: "did not converge: the iteration stopped making progress (the line search refused "
            "every step, or the residual stopped falling near the tolerance)",
            Status.NONFINITE: "did not converge: a non-finite number appeared in the iteration",
            Status.DIVERGED: "did not converge: the forces grew without bound (no equilibrium with finite forces "
            "was in reach); the iterate nearest to one is returned",
        }[self]


@dataclass(frozen=True, eq=False)
class Solution:
    """An equilibrium (or the last iterate of a failed solve) with its forces.

    Sign conventions (all forces act on the chain):

    * ``link_multipliers[k] = mu_k >= 0`` multiplies ``c_k(p) <= 0`` in the Lagrangian
      ``L = g m^T y + sum_i lambda_i.(p_i - pbar_i) + sum_k mu_k c_k(p)``. For the ``norm``
      formulation ``mu_k`` is the tension of link k; for ``squared`` it is ``T_k / (2 d_k)``.
    * ``link_tension[k] = T_k >= 0``: the pulling force in link k, in either formulation.
    * ``support_reactions[j]``: the force the support at ``problem.support_nodes[j]`` exerts
      on the chain, ``R = -lambda``. For a chain hanging from one support it is ``(0, W)``.
    * ``support_multipliers = lambda = -support_reactions``.
    * ``obstacle_multipliers[j, i] = nu_ji >= 0`` multiplies ``phi_j(p_i) <= 0``; its units depend on
      how phi is scaled. ``contact_forces[i] = -sum_j nu_ji grad phi_j(p_i)`` (N, 2) does not: it is
      the force the obstacles exert on node i, pointing out of them. Support nodes carry no
      contact constraint (they are fixed); what an obstacle pushes on a support is in its reaction.
    * With ``problem.contact == "links"``, ``obstacle_multipliers`` has shape (n_obstacles, N-1):
      ``nu_jk >= 0`` multiplies ``psi_jk = phi_j(p*) <= 0``, phi_j's largest value along link k,
      at ``p* = (1-t) p_k + t p_{k+1}`` (see :func:`funicular.obstacles.link_contact`). The force
      ``F = -nu_jk grad phi_j(p*)`` acts at p*; ``contact_forces`` holds its statically equivalent
      nodal shares, ``(1-t) F`` on node k and ``t F`` on node k+1. The JSON's
      ``multipliers.obstacle`` lists are then per link (N-1 entries) instead of per node.

    ``kkt`` holds the four KKT residuals (max-norms, physical units) recomputed from the
    returned point alone; ``kkt_scaled`` the same divided by the force and length scales.
    """

    problem: Problem
    status: Status
    positions: FloatArray
    link_multipliers: FloatArray
    iterations: int
    solve_seconds: float
    obstacle_multipliers: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    # What the solver core spent, coarse levels and saddle escapes included:
    # counts of its steps, evaluations and factorizations, and seconds by phase.
    statistics: Mapping[str, float] = field(default_factory=dict, compare=False)

    @property
    def converged(self) -> bool:
        return self.status is Status.OPTIMAL

    @property
    def x(self) -> FloatArray:
        return self.positions[:, 0]

    @property
    def y(self) -> FloatArray:
        return self.positions[:, 1]

    @property
    def z(self) -> FloatArray:
        """The third coordinate (3-D problems only)."""
        if self.problem.dimension != 3:
            raise AttributeError("z: a planar problem's positions have x and y only")
        return self.positions[:, 2]

    @cached_property
    def link_distance(self) -> FloatArray:
        """Current length ``d_k`` of every link."""
        return link_distances(self.positions, self.problem.links)

    @cached_property
    def link_tension(self) -> FloatArray:
        return tension_from_multipliers(self.problem.formulation, self.link_multipliers, self.link_distance)

    @cached_property
    def link_stretch(self) -> FloatArray:
        """How much longer than its (unstretched) length each link is, ``d_k - L0_k`` where taut, 0
        where slack: an elastic link's elongation (an inextensible one's is 0 to the tolerance)."""
        return np.maximum(self.link_distance - self.problem.link_lengths, 0.0)

    @cached_property
    def link_strain(self) -> FloatArray:
        """``link_stretch / L0``: each link's strain."""
        return self.link_stretch / self.problem.link_lengths

    @cached_property
    def link_taut(self) -> np.ndarray:
        return self.link_distance >= (1.0 - TAUT_RTOL) * self.problem.link_lengths

    @cached_property
    def node_fields(self) -> NodeFields | None:
        """The obstacles' phi and gradient at every node, evaluated once for the contact forces, the
        KKT residuals and the links' depths (None for link contact, whose rows are along the links)."""
        if self.problem.contact == "links":
            return None
        return [obstacle.evaluate(self.positions)[:2] for obstacle in self.problem.obstacles]

    @cached_property
    def contact_forces(self) -> FloatArray:
        """Total force the obstacles exert on each node (N, d), pointing out of them."""
        return contact_forces(self.problem, self.positions, self._obstacle_multipliers, self.node_fields)

    @property
    def _obstacle_multipliers(self) -> FloatArray | None:
        return self.obstacle_multipliers if self.problem.obstacles else None

    @cached_property
    def _applied_forces(self) -> FloatArray:
        """Loads (weights and point loads), links and contacts on every node (N, d), before the
        supports act: the supports' reactions balance it, and what is left of it at the free nodes
        is the stationarity residual."""
        return applied_forces(self.problem, self.positions, self.link_multipliers, self.contact_forces)

    @cached_property
    def support_reactions(self) -> FloatArray:
        """The force each support exerts on its node (S, d), from force balance there."""
        return -self._applied_forces[self.problem.support_nodes]

    @property
    def support_multipliers(self) -> FloatArray:
        return -self.support_reactions

    @property
    def objective(self) -> float:
        """Potential energy ``g m^T h`` (h: y in 2-D, z in 3-D)."""
        return self.problem.energy(self.positions)

    @cached_property
    def kkt(self) -> KKTResiduals:
        return kkt_residuals(
            self.problem,
            self.positions,
            self.link_multipliers,
            self._obstacle_multipliers,
            applied=self._applied_forces,
            distances=self.link_distance,
            fields=self.node_fields,
        )

    @cached_property
    def link_penetration(self) -> FloatArray:
        """Depth (about a distance, 0 if none) to which each link segment cuts into an obstacle."""
        return link_penetration(self.problem, self.positions, fields=self.node_fields)

    @property
    def links_cross_obstacles(self) -> bool:
        """Whether some link segment enters an obstacle (by more than 1e-9 of the longest link)."""
        return bool(np.any(self.link_penetration > 1e-9 * float(self.problem.link_lengths.max())))

    @cached_property
    def unsettled(self) -> str | None:
        """Where a solve that did not converge is farthest from equilibrium, in one sentence: the
        free node with the largest unbalanced force, the link stretched most beyond its length, or
        the node deepest inside an obstacle, whichever is largest against the weight or the longest
        link (None when it converged)."""
        if self.converged:
            return None
        p = self.problem
        weight, longest = p.force_scale, float(p.link_lengths.max())
        free = p.free_nodes
        unbalanced = norms(self._applied_forces[free]) if free.size else np.zeros(0)
        stretch = self.link_distance - p.link_lengths
        candidates = [(-np.inf, "")]
        if unbalanced.size:
            i = int(np.argmax(unbalanced))
            node = int(free[i])
            where = ""
            if p.obstacles:  # the nearest obstacle and how far the node is from it (negative: inside)
                gaps = [
                    float(-phi[0] / norms(g)[0])
                    for phi, g, _ in (o.evaluate(self.positions[node : node + 1]) for o in p.obstacles)
                ]
                j = int(np.argmin(np.abs(gaps)))
                where = f", {gaps[j]:.3g} from obstacle {p.obstacles[j].name!r}"
            candidates.append(
                (
                    unbalanced[i] / weight,
                    f"node {node} is farthest from balance: a force of {unbalanced[i]:.3g} "
                    f"({100 * unbalanced[i] / weight:.2g}% of the weight) is left over there{where}",
                )
            )
        if p.n_links:
            k = int(np.argmax(stretch))
            nodes = f"nodes {int(p.link_nodes[k, 0])}-{int(p.link_nodes[k, 1])}"
            candidates.append((stretch[k] / longest, f"link {k} ({nodes}) is {stretch[k]:.3g} longer than its length"))
        if p.obstacles and p.contact == "nodes" and self.node_fields is not None:
            for obstacle, (phi, gradient) in zip(p.obstacles, self.node_fields, strict=True):
                depth = phi[free] / np.maximum(norms(gradient[free]), 1e-300)
                i = int(np.argmax(depth))
                candidates.append(
                    (depth[i] / longest, f"node {int(free[i])} is {depth[i]:.3g} inside obstacle {obstacle.name!r}")
                )
        elif p.obstacles:  # link contact: the deepest link, in the obstacle whose contact it carries most
            depth = self.link_penetration
            k = int(np.argmax(depth))
            j = int(np.argmax(self.obstacle_multipliers[:, k]))
            candidates.append(
                (depth[k] / longest, f"link {k} reaches {depth[k]:.3g} into obstacle {p.obstacles[j].name!r}")
            )
        return max(candidates, key=lambda candidate: candidate[0])[1] or None

    @property
    def kkt_scaled(self) -> KKTResiduals:
        return scaled(self.kkt, self.problem)

    def primal_residual(self) -> float:
        return self.kkt.primal_feasibility

    def dual_residual(self) -> float:
        return self.kkt.stationarity

    def _elastic_entries(self) -> dict[str, Any]:
        """``link_stretch`` and ``link_strain`` where some link is elastic (an inextensible link's is 0
        to the tolerance: the files of inextensible structures leave them out)."""
        if self.problem.axial_stiffness is None:
            return {}
        return {"link_stretch": self.link_stretch, "link_strain": self.link_strain}

    def to_dict(self) -> dict[str, Any]:
        """The JSON result schema (see README). The long per-node and per-link entries are numpy
        arrays (the result writers take them as they are: converting 10^6 positions to Python lists
        costs more than writing them); the rest are Python objects."""
        p = self.problem
        coordinates = {axis: self.positions[:, i] for i, axis in enumerate("xyz"[: p.dimension])}
        return {
            "name": p.name,
            "status": self.status.value,
            "message": self.status.message,
            "formulation": p.formulation.value,
            "dimension": p.dimension,
            "nodes": p.n_nodes,
            "gravity": p.gravity,
            "objective": self.objective,
            **coordinates,
            "positions": self.positions,
            "links": p.link_nodes,
            "link_tension": self.link_tension,
            "link_taut": self.link_taut,
            **self._elastic_entries(),
            "multipliers": {
                "link": self.link_multipliers,
                "support": self.support_multipliers.tolist(),
                "obstacle": {o.name: nu for o, nu in zip(p.obstacles, self.obstacle_multipliers, strict=True)},
            },
            "contact_forces": self.contact_forces,
            "contact": p.contact,
            "links_cross_obstacles": self.links_cross_obstacles,
            "max_link_penetration": float(self.link_penetration.max(initial=0.0)),
            "support_reactions": [
                {"node": int(node), "force": force.tolist()}
                for node, force in zip(p.support_nodes, self.support_reactions, strict=True)
            ],
            "kkt": self.kkt.as_dict(),
            "kkt_scaled": self.kkt_scaled.as_dict(),
            "iterations": self.iterations,
            "solve_seconds": self.solve_seconds,
        }
