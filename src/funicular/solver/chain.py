"""The scaled chain the iteration works on, and the residuals at one iterate."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from funicular.constraints import link_deltas, link_gradients, link_values
from funicular.model import FloatArray, Formulation, IntArray


@dataclass
class ScaledChain:
    """The scaled problem the iteration works on (free nodes and the links that touch them)."""

    formulation: Formulation
    positions: FloatArray  # (N, 2) scaled; fixed nodes hold their final positions
    free: IntArray  # movable nodes
    links: IntArray  # links with at least one movable end
    lengths: FloatArray  # (N-1,) scaled link lengths
    load: FloatArray  # (N,) scaled weight of each node, g m_i / W
    both_free: FloatArray  # (n-1,) 1.0 where free node f and f+1 are joined by a link


@dataclass
class Point:
    """Everything evaluated at one iterate."""

    positions: FloatArray
    c: FloatArray  # (m,) constraint values of the optimised links
    q: FloatArray  # (N-1, 2) gradients w.r.t. p_k (zero for links not optimised)
    dual_residual: FloatArray  # (n, 2) grad E + J^T mu at the free nodes


def node_sum(chain: ScaledChain, per_link: FloatArray) -> FloatArray:
    """Apply ``J^T``: link quantities ``v_k q_k`` (N-1, 2) summed onto the free nodes (n, 2)."""
    n_nodes = chain.positions.shape[0]
    total = np.zeros((n_nodes, 2))
    total[:-1] += per_link
    total[1:] -= per_link
    return total[chain.free]


def evaluate(chain: ScaledChain, z: FloatArray, mu: FloatArray) -> Point:
    positions = chain.positions.copy()
    positions[chain.free] = z.reshape(-1, 2)
    delta = link_deltas(positions)
    distances = np.hypot(delta[:, 0], delta[:, 1])
    q = np.zeros_like(delta)
    q[chain.links] = link_gradients(chain.formulation, delta[chain.links], distances[chain.links])
    c = link_values(chain.formulation, distances[chain.links], chain.lengths[chain.links])
    mu_full = np.zeros(delta.shape[0])
    mu_full[chain.links] = mu
    dual = node_sum(chain, mu_full[:, None] * q)
    dual[:, 1] += chain.load[chain.free]
    return Point(positions=positions, c=c, q=q, dual_residual=dual)
