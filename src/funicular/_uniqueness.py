"""Whether a solution's multipliers may not be unique, from what the solve already knows (cheap:
the full answer is the checker's LICQ, which loads SciPy)."""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from funicular.solution import Solution

COLLINEAR = 1e-9  # |sin| of the angle between two links below which they count as one straight line


def multipliers_may_not_be_unique(solution: Solution) -> bool:
    """Whether the active constraints at ``solution`` may be dependent (LICQ may fail), from what the
    solve already knows, in O(N): a free node touching two obstacles, or a taut stretch between two
    supports along which every free node is straight or touches an obstacle (a tension added along it
    is then carried by the supports and contacts alone). False means LICQ holds in every such case;
    True asks the checker (:func:`funicular.checks.licq_of`) to decide."""
    problem = solution.problem
    touching = np.linalg.norm(solution.contact_forces, axis=1) > 0
    if problem.obstacles and problem.contact == "nodes":
        per_node = (solution.obstacle_multipliers > 0).sum(axis=0)
        if np.any(per_node[problem.free_nodes] >= 2):
            return True
    if problem.links is not None:  # (a chain with point loads or elastic links keeps the chain's test)
        return _net_may_be_dependent(solution, touching)
    delta = np.diff(solution.positions, axis=0)
    length = np.maximum(np.linalg.norm(delta, axis=1), 1e-300)
    if problem.dimension == 2:
        sine = np.abs(delta[:-1, 0] * delta[1:, 1] - delta[:-1, 1] * delta[1:, 0])
    else:
        sine = np.linalg.norm(np.cross(delta[:-1], delta[1:]), axis=1)
    cross = sine / (length[:-1] * length[1:])
    passes = np.zeros(problem.n_nodes, dtype=bool)  # an interior node a tension can pass unchanged
    passes[1:-1] = (cross <= COLLINEAR) | touching[1:-1]
    supports = problem.support_nodes.tolist()
    taut = solution.link_taut
    return any(bool(np.all(taut[a:b]) and np.all(passes[a + 1 : b])) for a, b in itertools.pairwise(supports))


def _net_may_be_dependent(solution: Solution, touching: NDArray[np.bool_]) -> bool:
    """A net: True when a free node has more active constraints (taut links and contacts) than its
    d coordinates, the count below which d-vectors at one node cannot be dependent. Cheap and
    pessimistic: a grid's interior nodes with four taut links in 3-D already say "may"."""
    problem = solution.problem
    pairs = problem.link_nodes[solution.link_taut]
    active = np.bincount(pairs.ravel(), minlength=problem.n_nodes) + touching
    return bool(np.any(active[problem.free_nodes] > problem.dimension))
