"""Active-set Newton polish: accurate multipliers once the interior-point method knows the active set.

Close to the solution the interior-point Newton matrix carries ``mu/s ~ 1/tau``, so the
multiplier update ``dmu = Sigma (J dz + r_p) - ...`` amplifies rounding errors in the link
lengths; the iteration stalls long before the residuals reach 1e-10 for large N. With the
active set A (constraints with ``mu > s``: taut links and touching contacts) fixed, the KKT
conditions are a square system

    [ W_A   J_A^T ] [dz  ]     [ grad E + J_A^T mu_A ]
    [ J_A    0    ] [dmu ] = - [ c_A                 ]

which Newton solves without any 1/s. Ordered node by node as (x_i, y_i, contact multipliers
of node i, multiplier of link i), it is banded (bandwidth 4 plus the number of obstacles) and is
factorized by LAPACK's banded LU (``scipy.linalg.solve_banded``).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_banded

from funicular.constraints import link_deltas, link_gradients, link_hessian_blocks, link_values
from funicular.model import FloatArray, IntArray
from funicular.solver.chain import ScaledChain, evaluate_obstacles

# A tiny proximal term on the positions: directions the active constraints leave free (a node lying
# on the ground between slack links may slide) get a zero step instead of a singular matrix.
PROXIMAL = 1e-10


class _Triplets:
    """Sparse (row, column, value) entries, collected as whole arrays."""

    def __init__(self) -> None:
        self.rows: list[IntArray] = []
        self.cols: list[IntArray] = []
        self.vals: list[FloatArray] = []

    def add(self, rows: IntArray, cols: IntArray, vals: FloatArray, symmetric: bool = False) -> None:
        self.rows.append(rows)
        self.cols.append(cols)
        self.vals.append(vals)
        if symmetric:
            self.rows.append(cols)
            self.cols.append(rows)
            self.vals.append(vals)

    def banded(self, size: int) -> tuple[int, FloatArray]:
        r, c, v = np.concatenate(self.rows), np.concatenate(self.cols), np.concatenate(self.vals)
        bandwidth = int(np.max(np.abs(r - c))) if r.size else 0
        rows = 2 * bandwidth + 1
        flat = np.bincount((bandwidth + r - c) * size + c, weights=v, minlength=rows * size)  # sums duplicates
        return bandwidth, np.asarray(flat, dtype=np.float64).reshape(rows, size)


def polish_step(
    chain: ScaledChain, z: FloatArray, mu: FloatArray, active: np.ndarray
) -> tuple[FloatArray, FloatArray] | None:
    """One Newton step on the active-set KKT system; ``None`` if the system is singular."""
    n_nodes = chain.positions.shape[0]
    n_free, n_obstacles, n_links = chain.free.size, len(chain.obstacles), chain.links.size
    positions = chain.positions.copy()
    positions[chain.free] = z.reshape(-1, 2)
    delta = link_deltas(positions)
    distances = np.hypot(delta[:, 0], delta[:, 1])

    is_free = np.zeros(n_nodes, dtype=bool)
    is_free[chain.free] = True
    link_active = np.zeros(n_nodes - 1, dtype=bool)
    link_active[chain.links[active[:n_links]]] = True
    mu_links = np.zeros(n_nodes - 1)
    mu_links[chain.links[active[:n_links]]] = mu[:n_links][active[:n_links]]
    contact_active = active[n_links:].reshape(n_obstacles, n_free)
    nu = np.where(contact_active, mu[n_links:].reshape(n_obstacles, n_free), 0.0)

    # Variable layout, node by node: (x_i, y_i) if free, its active contacts, then mu_i if link i is active.
    contacts_at = np.zeros(n_nodes, dtype=np.intp)
    contacts_at[chain.free] = contact_active.sum(axis=0)
    counts = 2 * is_free.astype(np.intp) + contacts_at
    counts[:-1] += link_active
    start = np.concatenate(([0], np.cumsum(counts)[:-1]))
    size = int(counts.sum())
    xy = start  # x_i; y_i = x_i + 1
    contact_index = start[chain.free] + 2 + np.cumsum(contact_active, axis=0) - 1  # (n_obstacles, n_free)
    mu_index = start[:-1] + 2 * is_free[:-1] + contacts_at[:-1]

    k = np.flatnonzero(link_active)
    q = link_gradients(chain.formulation, delta[k], distances[k])
    hess = mu_links[k, None, None] * link_hessian_blocks(chain.formulation, delta[k], distances[k], chain.lengths[k])
    ends = ((k, is_free[k], 1.0), (k + 1, is_free[k + 1], -1.0))
    phi, obstacle_gradient, obstacle_hessian = evaluate_obstacles(chain, positions[chain.free])
    node_hessian = np.einsum("jn,jnab->nab", nu, obstacle_hessian)

    entries = _Triplets()
    for i in range(2):
        for j in range(2):
            for end_r, mask_r, sign_r in ends:
                for end_c, mask_c, sign_c in ends:
                    both = mask_r & mask_c
                    entries.add(xy[end_r[both]] + i, xy[end_c[both]] + j, sign_r * sign_c * hess[both, i, j])
            entries.add(xy[chain.free] + i, xy[chain.free] + j, node_hessian[:, i, j] + PROXIMAL * (i == j))
        for end, mask, sign in ends:
            entries.add(xy[end[mask]] + i, mu_index[k[mask]], sign * q[mask, i], symmetric=True)
        for obstacle in range(n_obstacles):
            touching = contact_active[obstacle]
            entries.add(
                xy[chain.free[touching]] + i,
                contact_index[obstacle, touching],
                obstacle_gradient[obstacle, touching, i],
                symmetric=True,
            )
    bandwidth, ab = entries.banded(size)

    gradient = np.zeros((n_nodes, 2))
    pull = mu_links[:, None] * link_gradients(chain.formulation, delta, distances)
    gradient[:-1] += pull
    gradient[1:] -= pull
    gradient[:, 1] += chain.load
    gradient[chain.free] += np.einsum("jn,jnd->nd", nu, obstacle_gradient)
    rhs = np.zeros(size)
    rhs[xy[chain.free]] = -gradient[chain.free, 0]
    rhs[xy[chain.free] + 1] = -gradient[chain.free, 1]
    rhs[mu_index[k]] = -link_values(chain.formulation, distances[k], chain.lengths[k])
    rhs[contact_index[contact_active]] = -phi[contact_active]
    try:
        step = solve_banded((bandwidth, bandwidth), ab, rhs, check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(step)):
        return None
    dz = np.stack((step[xy[chain.free]], step[xy[chain.free] + 1]), axis=1).ravel()
    new_mu = np.zeros_like(mu)
    link_rows = np.flatnonzero(active[:n_links])
    new_mu[link_rows] = mu[link_rows] + step[mu_index[chain.links[link_rows]]]
    new_nu = np.zeros((n_obstacles, n_free))
    new_nu[contact_active] = nu[contact_active] + step[contact_index[contact_active]]
    new_mu[n_links:] = new_nu.ravel()
    return z + dz, new_mu
