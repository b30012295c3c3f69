"""Active-set Newton polish: accurate multipliers once the interior-point method knows which links are taut.

Close to the solution the interior-point Newton matrix carries ``mu/s ~ 1/tau``, so the
multiplier update ``dmu = Sigma (J dz + r_p) - ...`` amplifies rounding errors in the link
lengths; the iteration stalls long before the residuals reach 1e-10 for large N. With the
active set A (links with ``mu_k > s_k``) fixed, the KKT conditions are a square system

    [ W_A   J_A^T ] [dz  ]     [ grad E + J_A^T mu_A ]
    [ J_A    0    ] [dmu ] = - [ c_A                 ]

which Newton solves without any 1/s. Ordered node by node as (x_i, y_i, mu_i), it is banded
with bandwidth 4 and factorized by LAPACK's banded LU (``scipy.linalg.solve_banded``).
The polished point is kept only if it is better and still satisfies the sign conditions.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_banded

from funicular.constraints import link_deltas, link_gradients, link_hessian_blocks, link_values
from funicular.model import FloatArray, IntArray
from funicular.solver.chain import ScaledChain


def polish_step(
    chain: ScaledChain,
    z: FloatArray,
    mu: FloatArray,
    active_mask: np.ndarray,
) -> tuple[FloatArray, FloatArray] | None:
    """One Newton step on the active-set KKT system; ``None`` if the system is singular."""
    n_nodes = chain.positions.shape[0]
    positions = chain.positions.copy()
    positions[chain.free] = z.reshape(-1, 2)
    delta = link_deltas(positions)
    distances = np.hypot(delta[:, 0], delta[:, 1])

    free = np.zeros(n_nodes, dtype=bool)
    free[chain.free] = True
    link_active = np.zeros(n_nodes - 1, dtype=bool)
    link_active[chain.links[active_mask]] = True
    mu_full = np.zeros(n_nodes - 1)
    mu_full[chain.links[active_mask]] = mu[active_mask]

    # Variable layout: node i contributes (x_i, y_i) if free, then mu_i if link i is active.
    counts = 2 * free.astype(np.intp)
    counts[:-1] += link_active
    start = np.concatenate(([0], np.cumsum(counts)[:-1]))
    size = int(counts.sum())
    xy = start  # index of x_i (y_i = x_i + 1) for free nodes
    mu_index = start[:-1] + 2 * free[:-1]

    k = np.flatnonzero(link_active)
    q = link_gradients(chain.formulation, delta[k], distances[k])
    hess = mu_full[k, None, None] * link_hessian_blocks(chain.formulation, delta[k], distances[k], chain.lengths[k])
    a_free, b_free = free[k], free[k + 1]

    rows: list[IntArray] = []
    cols: list[IntArray] = []
    vals: list[FloatArray] = []

    def add(r: IntArray, c: IntArray, v: FloatArray) -> None:
        rows.append(r)
        cols.append(c)
        vals.append(v)

    for i in range(2):
        for j in range(2):
            for end_r, mask_r, sign_r in ((k, a_free, 1.0), (k + 1, b_free, -1.0)):
                for end_c, mask_c, sign_c in ((k, a_free, 1.0), (k + 1, b_free, -1.0)):
                    both = mask_r & mask_c
                    add(xy[end_r[both]] + i, xy[end_c[both]] + j, sign_r * sign_c * hess[both, i, j])
        for end, mask, sign in ((k, a_free, 1.0), (k + 1, b_free, -1.0)):
            add(xy[end[mask]] + i, mu_index[k[mask]], sign * q[mask, i])
            add(mu_index[k[mask]], xy[end[mask]] + i, sign * q[mask, i])

    r = np.concatenate(rows)
    c = np.concatenate(cols)
    v = np.concatenate(vals)
    bandwidth = int(np.max(np.abs(r - c))) if r.size else 0
    ab = np.zeros((2 * bandwidth + 1, size))
    np.add.at(ab, (bandwidth + r - c, c), v)

    rhs = np.zeros(size)
    gradient = np.zeros((n_nodes, 2))
    all_q = link_gradients(chain.formulation, delta, distances)
    pull = mu_full[:, None] * all_q
    gradient[:-1] += pull
    gradient[1:] -= pull
    gradient[:, 1] += chain.load
    rhs[xy[free]] = -gradient[free, 0]
    rhs[xy[free] + 1] = -gradient[free, 1]
    rhs[mu_index[k]] = -link_values(chain.formulation, distances[k], chain.lengths[k])
    try:
        step = solve_banded((bandwidth, bandwidth), ab, rhs, check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(step)):
        return None
    dz = np.stack((step[xy[chain.free]], step[xy[chain.free] + 1]), axis=1).ravel()
    new_mu = np.zeros_like(mu)
    new_mu[active_mask] = mu[active_mask] + step[mu_index[chain.links[active_mask]]]
    return z + dz, new_mu
