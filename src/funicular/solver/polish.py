"""Active-set Newton polish: accurate multipliers once the interior-point method knows the active set.

Close to the solution the interior-point Newton matrix carries ``mu/s ~ 1/tau``, so the
multiplier update ``dmu = Sigma (J dz + r_p) - ...`` amplifies rounding errors in the link
lengths; the iteration stalls long before the residuals reach 1e-10 for large N. With the
active set A (constraints with ``mu > s``: taut links and touching contacts) fixed, the KKT
conditions are a square system

    [ W_A   J_A^T ] [dz  ]     [ grad E + J_A^T mu_A ]
    [ J_A    0    ] [dmu ] = - [ c_A                 ]

which Newton solves without any 1/s. With compiled loops and node contact it is assembled and
solved node by node in one pass (``_compiled_step``, ``fused.polish_solve``: a block elimination,
0.12 s at 10^6 nodes). Otherwise, or if that elimination meets a singular block or an unstable
Schur complement update, it is assembled ordered node by node as
(x_i, y_i, contact multipliers of node i, multiplier of link i, link-contact multipliers of link
i), which is banded (bandwidth 4 plus the number of obstacles), and factorized by LAPACK's banded
LU (``scipy.linalg.solve_banded``). With ``contact = "links"`` a node has no contact rows and
link i carries one per obstacle.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_banded

from funicular.constraints import link_deltas, link_gradients, link_hessian_blocks, link_values
from funicular.model import FloatArray, IntArray
from funicular.solver import fused
from funicular.solver.chain import Point, ScaledChain, SegmentRows, segment_node_sum
from funicular.solver.compiled import jit

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
    chain: ScaledChain, point: Point, mu: FloatArray, active: np.ndarray
) -> tuple[FloatArray, FloatArray] | None:
    """One Newton step on the active-set KKT system from the iterate ``point`` (its obstacle
    values and derivatives are used as they are); new free positions (flat) and multipliers, or
    ``None`` if the system is singular."""
    if chain.compiled and not chain.contact_links:
        compiled = _compiled_step(chain, point, mu, active)
        if compiled is not None:
            return compiled

    n_nodes = chain.positions.shape[0]
    n_free, n_obstacles, n_links = chain.free.size, len(chain.obstacles), chain.links.size
    positions = point.positions
    z = positions[chain.free_at].ravel()

    is_free = np.zeros(n_nodes, dtype=bool)
    is_free[chain.free] = True
    link_active = np.zeros(n_nodes - 1, dtype=bool)
    link_active[chain.links[active[:n_links]]] = True
    mu_links = np.zeros(n_nodes - 1)
    mu_links[chain.links[active[:n_links]]] = mu[:n_links][active[:n_links]]
    n_rows = chain.n_contact_rows
    contact_active = active[n_links:].reshape(n_obstacles, n_rows)
    nu = np.where(contact_active, mu[n_links:].reshape(n_obstacles, n_rows), 0.0)
    phi = point.c[n_links:].reshape(n_obstacles, n_rows)

    # Variable layout, node by node: (x_i, y_i) if free, its active contacts, then mu_i if link i is
    # active, then the active contacts of link i (contact = "links").
    delta = link_deltas(positions)
    distances = np.hypot(delta[:, 0], delta[:, 1])
    contacts_at = np.zeros(n_nodes, dtype=np.intp)
    segment_contacts_at = np.zeros(n_nodes, dtype=np.intp)
    if chain.contact_links:
        segment_contacts_at[chain.links] = contact_active.sum(axis=0)
    else:
        contacts_at[chain.free] = contact_active.sum(axis=0)
    counts = 2 * is_free.astype(np.intp) + contacts_at + segment_contacts_at
    counts[:-1] += link_active
    start = np.concatenate(([0], np.cumsum(counts)[:-1]))
    size = int(counts.sum())
    xy = start  # x_i; y_i = x_i + 1
    mu_index = start[:-1] + 2 * is_free[:-1] + contacts_at[:-1]
    if chain.contact_links:  # (n_obstacles, n_links), after link k's own multiplier
        contact_index = start[chain.links] + 2 * is_free[chain.links] + link_active[chain.links]
    else:  # (n_obstacles, n_free)
        contact_index = start[chain.free] + 2
    contact_index = contact_index + np.cumsum(contact_active, axis=0) - 1

    k = np.flatnonzero(link_active)
    q = link_gradients(chain.formulation, delta[k], distances[k], chain.lengths[k])
    hess = mu_links[k, None, None] * link_hessian_blocks(
        chain.formulation, delta[k], distances[k], chain.lengths[k], smooth=True
    )
    ends = ((k, is_free[k], 1.0), (k + 1, is_free[k + 1], -1.0))
    segments = point.segments
    if segments is not None:  # contact = "links"
        obstacle_gradient, node_hessian = np.zeros((n_obstacles, n_free, 2)), np.zeros((n_free, 2, 2))
    else:
        obstacle_gradient = point.obstacle_gradient
        node_hessian = np.einsum("jn,jnab->nab", nu, point.obstacle_hessian)

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
            if segments is not None:
                break  # link-contact rows: _add_segment_entries
            touching = contact_active[obstacle]
            entries.add(
                xy[chain.free[touching]] + i,
                contact_index[obstacle, touching],
                obstacle_gradient[obstacle, touching, i],
                symmetric=True,
            )
    if segments is not None:
        _add_segment_entries(chain, segments, nu, contact_active, contact_index, xy, is_free, entries)
    bandwidth, ab = entries.banded(size)

    gradient = np.zeros((n_nodes, 2))
    pull = mu_links[:, None] * link_gradients(chain.formulation, delta, distances, chain.lengths)
    gradient[:-1] += pull
    gradient[1:] -= pull
    gradient[:, 1] += chain.load
    if segments is None:
        gradient[chain.free] += np.einsum("jn,jnd->nd", nu, obstacle_gradient)
    else:
        gradient[chain.free] += segment_node_sum(chain, segments, nu)
    rhs = np.zeros(size)
    rhs[xy[chain.free]] = -gradient[chain.free, 0]
    rhs[xy[chain.free] + 1] = -gradient[chain.free, 1]
    rhs[mu_index[k]] = -link_values(chain.formulation, distances[k], chain.lengths[k], smooth=True)
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
    new_nu = np.zeros((n_obstacles, n_rows))
    new_nu[contact_active] = nu[contact_active] + step[contact_index[contact_active]]
    new_mu[n_links:] = new_nu.ravel()
    return z + dz, new_mu


def _compiled_step(
    chain: ScaledChain, point: Point, mu: FloatArray, active: np.ndarray
) -> tuple[FloatArray, FloatArray] | None:
    """The same Newton step by the compiled node-by-node elimination (``fused.polish_solve``), which
    reads the iterate and the constraint vectors as they are: new free positions (flat) and
    multipliers. ``None`` if the elimination meets a singular block, an unstable Schur complement
    update or a non-finite step (the caller then assembles the banded system)."""
    new_z, new_mu = np.empty(2 * chain.free.size), np.empty_like(mu)
    failed = jit(fused.polish_solve)(
        chain.squared,
        point.positions,
        chain.lengths,
        chain.load,
        chain.free,
        chain.links,
        active,
        mu,
        point.c,
        point.obstacle_gradient,
        point.obstacle_hessian,
        PROXIMAL,
        new_z,
        new_mu,
        *chain.polish_workspace,
    )
    return None if failed >= 0 else (new_z, new_mu)


def _add_segment_entries(
    chain: ScaledChain,
    segments: SegmentRows,
    nu: FloatArray,
    active: np.ndarray,
    index: IntArray,
    xy: IntArray,
    is_free: np.ndarray,
    entries: _Triplets,
) -> None:
    """Link-contact rows: ``(1-t) grad phi`` at node k and ``t grad phi`` at node k+1 against their
    multiplier, and ``nu Hess psi`` over the free coordinates of both nodes."""
    k = chain.links
    hessian = np.einsum("jl,jlab->lab", nu, segments.hessian)
    ends = ((k, 0, 1.0 - segments.t), (k + 1, 2, segments.t))
    for end_r, offset_r, weight in ends:
        for end_c, offset_c, _ in ends:
            both = is_free[end_r] & is_free[end_c]
            for i in range(2):
                for j in range(2):
                    entries.add(xy[end_r[both]] + i, xy[end_c[both]] + j, hessian[both, offset_r + i, offset_c + j])
        for obstacle in range(len(chain.obstacles)):
            rows = active[obstacle] & is_free[end_r]
            for i in range(2):
                values = weight[obstacle, rows] * segments.gradient[obstacle, rows, i]
                entries.add(xy[end_r[rows]] + i, index[obstacle, rows], values, symmetric=True)
