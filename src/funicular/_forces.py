"""Multipliers -> forces: link forces on nodes, gravity, support reactions.

Sign conventions (``docs/model.md``): a force is what acts *on* the chain's node.
Link tension ``T_k >= 0`` pulls node k towards node k+1 and node k+1 towards node k.
The contact force of obstacle j on node i is ``-nu_ji grad phi_j(p_i)``, pointing out of the obstacle.
With ``contact = "links"`` obstacle j pushes link k at the point ``p* = (1-t) p_k + t p_{k+1}`` where
phi_j is largest along it (:func:`funicular.obstacles.link_contact`) with ``F = -nu_jk grad phi_j(p*)``;
the nodes carry its statically equivalent shares ``(1-t) F`` (node k) and ``t F`` (node k+1).
Supports are eliminated from the unknowns and carry no contact constraint: a support touching
an obstacle has its contact force included in its reaction.
The support reaction ``R_i = -lambda_i`` is the force the support exerts on node i; it follows
from force balance at that node: ``R_i = -(gravity + link forces [+ contact forces])``.
"""

from __future__ import annotations

import numpy as np

from funicular._constraints import link_deltas, link_distances, link_gradients
from funicular.model import FloatArray, Formulation, Problem
from funicular.obstacles import link_contact, link_contact_ends


def gravity_forces(problem: Problem) -> FloatArray:
    """Weight of every node, ``(0, -g m_i)``, shape (N, 2)."""
    forces = np.zeros((problem.n_nodes, 2))
    forces[:, 1] = -problem.gravity * problem.masses
    return forces


def link_forces(formulation: Formulation, positions: FloatArray, multipliers: FloatArray) -> FloatArray:
    """Net force all links exert on every node, ``-J^T mu`` (shape (N, 2)).

    With ``q_k`` the gradient of c_k w.r.t. p_k, link k pushes node k with ``-mu_k q_k`` and
    node k+1 with ``+mu_k q_k``; for the norm form ``mu_k q_k`` is the tension times the unit
    vector from node k+1 to node k, so both nodes are pulled towards each other.
    """
    delta = link_deltas(positions)
    q = link_gradients(formulation, delta, link_distances(positions))
    pull = multipliers[:, None] * q
    forces = np.zeros_like(positions)
    forces[:-1] -= pull
    forces[1:] += pull
    return forces


@np.errstate(over="ignore")  # (a solve gone far astray, multipliers near 1e300: its forces are inf)
def contact_forces(problem: Problem, positions: FloatArray, obstacle_multipliers: FloatArray | None) -> FloatArray:
    """Total force all obstacles exert on every node, ``-sum_j nu_ji grad phi_j(p_i)`` (N, 2).

    It points out of the obstacles and is unchanged when phi is multiplied by a positive constant.
    With ``contact = "links"`` the multipliers are per link (n_obstacles, N-1) and each link's
    contact force is shared between its two nodes (see the module docstring).
    """
    total = np.zeros_like(positions)
    if obstacle_multipliers is None:
        return total
    if problem.contact == "links":
        return _link_contact_forces(problem, positions, obstacle_multipliers)
    for obstacle, nu in zip(problem.obstacles, obstacle_multipliers, strict=True):
        touching = nu != 0
        if np.any(touching):
            _, gradient, _ = obstacle.evaluate(positions[touching])
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
    """Gravity + link forces (+ contact forces) on every node, before the supports act."""
    total = gravity_forces(problem) + link_forces(problem.formulation, positions, link_multipliers)
    if contact is not None:
        total += contact
    return total


def support_reactions(
    problem: Problem, positions: FloatArray, link_multipliers: FloatArray, contact: FloatArray | None = None
) -> FloatArray:
    """Force each support exerts on its node (S, 2), from force balance at that node."""
    return -applied_forces(problem, positions, link_multipliers, contact)[problem.support_nodes]
