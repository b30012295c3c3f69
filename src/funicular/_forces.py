"""Multipliers -> forces: link forces on nodes, gravity, support reactions.

Sign conventions (``docs/model.md``): a force is what acts *on* a node.
Link tension ``T_k >= 0`` pulls each of the link's two nodes towards the other (a chain's link k joins
nodes k and k+1).
The contact force of obstacle j on node i is ``-nu_ji grad phi_j(p_i)``, pointing out of the obstacle.
With ``contact = "links"`` obstacle j pushes link k at the point ``p* = (1-t) p_k + t p_{k+1}`` where
phi_j is largest along it (:func:`funicular.obstacles.link_contact`) with ``F = -nu_jk grad phi_j(p*)``;
the nodes carry its statically equivalent shares ``(1-t) F`` (node k) and ``t F`` (node k+1).
Supports are eliminated from the unknowns and carry no contact constraint: a support touching
an obstacle has its contact force included in its reaction.
The support reaction ``R_i = -lambda_i`` is the force the support exerts on node i; it follows
from force balance at that node: ``R_i = -(weight + point load + link forces [+ contact forces])``.
"""

from __future__ import annotations

import numpy as np

from funicular._constraints import link_deltas, link_gradients, norms
from funicular.model import FloatArray, Formulation, IntArray, Problem
from funicular.obstacles.base import NodeFields
from funicular.obstacles.contact import link_contact, link_contact_ends


def node_loads(problem: Problem) -> FloatArray:
    """The loads on every node, shape (N, d): its weight ``-g m_i`` along the last axis plus its
    point load, if any."""
    forces = np.zeros((problem.n_nodes, problem.dimension)) if problem.loads is None else problem.loads.copy()
    forces[:, -1] -= problem.gravity * problem.masses
    return forces


def link_forces(
    formulation: Formulation, positions: FloatArray, multipliers: FloatArray, links: IntArray | None = None
) -> FloatArray:
    """Net force all links exert on every node, ``-J^T mu`` (shape (N, d)); ``links`` the node
    pairs (L, 2), None for a chain.

    With ``q_k`` the gradient of c_k w.r.t. the link's first node a, link k pushes node a with
    ``-mu_k q_k`` and its second node b with ``+mu_k q_k``; for the norm form ``mu_k q_k`` is the
    tension times the unit vector from b to a, so both nodes are pulled towards each other.
    """
    delta = link_deltas(positions, links)
    pull = link_gradients(formulation, delta, norms(delta))  # (a new array: scaled in place)
    pull *= multipliers[:, None]
    forces = np.zeros_like(positions)
    if links is None:
        forces[:-1] -= pull
        forces[1:] += pull
        return forces
    n = positions.shape[0]
    for i in range(positions.shape[1]):
        forces[:, i] = np.bincount(links[:, 1], pull[:, i], n) - np.bincount(links[:, 0], pull[:, i], n)
    return forces


@np.errstate(over="ignore")  # (a solve gone far astray, multipliers near 1e300: its forces are inf)
def contact_forces(
    problem: Problem, positions: FloatArray, obstacle_multipliers: FloatArray | None, fields: NodeFields | None = None
) -> FloatArray:
    """Total force all obstacles exert on every node, ``-sum_j nu_ji grad phi_j(p_i)`` (N, d);
    ``fields``: the obstacles already evaluated at every node, if at hand.

    It points out of the obstacles and is unchanged when phi is multiplied by a positive constant.
    With ``contact = "links"`` the multipliers are per link (n_obstacles, N-1) and each link's
    contact force is shared between its two nodes (see the module docstring).
    """
    total = np.zeros_like(positions)
    if obstacle_multipliers is None:
        return total
    if problem.contact == "links":
        return _link_contact_forces(problem, positions, obstacle_multipliers)
    for j, (obstacle, nu) in enumerate(zip(problem.obstacles, obstacle_multipliers, strict=True)):
        touching = nu != 0
        if np.any(touching):
            gradient = obstacle.evaluate(positions[touching])[1] if fields is None else fields[j][1][touching]
            total[touching] -= nu[touching, None] * gradient
    return total


def _link_contact_forces(problem: Problem, positions: FloatArray, obstacle_multipliers: FloatArray) -> FloatArray:
    total = np.zeros_like(positions)
    end, pinned = link_contact_ends(problem.is_support)
    for obstacle, nu in zip(problem.obstacles, obstacle_multipliers, strict=True):
        touching = np.flatnonzero(nu != 0)
        if touching.size:
            a, b = positions[touching], positions[touching + 1]
            segment = link_contact(obstacle, a, b, end[touching], pinned[touching])
            force = -nu[touching, None] * segment.gradient
            total[touching] += (1.0 - segment.t)[:, None] * force
            total[touching + 1] += segment.t[:, None] * force
    return total


def applied_forces(
    problem: Problem, positions: FloatArray, link_multipliers: FloatArray, contact: FloatArray | None = None
) -> FloatArray:
    """Loads (weights and point loads) + link forces (+ contact forces) on every node, before the supports act."""
    total = link_forces(problem.formulation, positions, link_multipliers, problem.links)
    total += node_loads(problem)
    if contact is not None:
        total += contact
    return total
