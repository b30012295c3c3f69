"""Compiled (numba) loops for the per-iteration work on the links: the vectorized numpy in
``chain`` makes a dozen passes over (N, 2) and (N, 2, 2) temporaries for what one loop over the
links does in one pass. Same formulas as :mod:`funicular.constraints` with ``smooth=True`` (norm:
``q = delta / max(d, r)``, ``r = SMOOTH_RATIO l``, Hessian block ``(I - q q^T) / d`` for ``d >= r``
and ``I / r`` below; squared: ``q = 2 delta``, block ``2 I``), written out per link; the tests check
both paths agree to rounding on every built-in scenario.

Each kernel is plain Python over arrays, compiled on first use when numba is installed
(:func:`funicular.solver.compiled.jit`); ``chain`` calls them only then (see ``ScaledChain.compiled``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from funicular.constraints import SMOOTH_RATIO

UPDATE_LIMIT = 1e8  # polish_solve: a larger Schur complement update hands over to the banded LU


def link_terms(
    squared: bool, positions: Any, lengths: Any, optimised: Any, mu_links: Any, c: Any, q: Any, force: Any
) -> None:  # pragma: no cover - compiled
    """For every link k: ``c[k]`` its constraint value and ``q[k]`` its gradient w.r.t. p_k (zero
    unless ``optimised[k]``), and ``force`` (N, 2, zeroed) += the links' ``J^T mu`` on every node."""
    n_links = positions.shape[0] - 1
    for k in range(n_links):
        if not optimised[k]:
            c[k], q[k, 0], q[k, 1] = 0.0, 0.0, 0.0
            continue
        dx, dy = positions[k, 0] - positions[k + 1, 0], positions[k, 1] - positions[k + 1, 1]
        d, length = math.hypot(dx, dy), lengths[k]
        if squared:
            q0, q1 = 2.0 * dx, 2.0 * dy
            c[k] = (d - length) * (d + length)
        else:  # the norm, or below r = SMOOTH_RATIO l its smooth stand-in
            r = SMOOTH_RATIO * length
            reach = max(d, r)
            q0, q1 = dx / reach, dy / reach
            c[k] = d - length if d >= r else (d * d + r * r) / (2.0 * r) - length
        q[k, 0], q[k, 1] = q0, q1
        force[k, 0] += mu_links[k] * q0
        force[k, 1] += mu_links[k] * q1
        force[k + 1, 0] -= mu_links[k] * q0
        force[k + 1, 1] -= mu_links[k] * q1


def link_blocks(
    squared: bool,
    positions: Any,
    lengths: Any,
    optimised: Any,
    mu_links: Any,
    sigma_links: Any,
    q: Any,
    per_node: Any,
    blocks: Any,
) -> None:  # pragma: no cover - compiled
    """``blocks[k] = mu_k K_k + sigma_k q_k q_k^T`` (the Hessian block of link k and its barrier
    term; zero unless optimised) and ``per_node`` (N, 2, 2, zeroed) += blocks on both ends."""
    n_links = positions.shape[0] - 1
    for k in range(n_links):
        if not optimised[k]:
            blocks[k, 0, 0], blocks[k, 0, 1], blocks[k, 1, 0], blocks[k, 1, 1] = 0.0, 0.0, 0.0, 0.0
            continue
        q0, q1 = q[k, 0], q[k, 1]
        if squared:
            k00, k01, k11 = 2.0, 0.0, 2.0
        else:
            dx, dy = positions[k, 0] - positions[k + 1, 0], positions[k, 1] - positions[k + 1, 1]
            d, r = math.hypot(dx, dy), SMOOTH_RATIO * lengths[k]
            if d >= r:
                k00, k01, k11 = (1.0 - q0 * q0) / d, -q0 * q1 / d, (1.0 - q1 * q1) / d
            else:
                k00, k01, k11 = 1.0 / r, 0.0, 1.0 / r
        mu, sigma = mu_links[k], sigma_links[k]
        b00, b01, b11 = mu * k00 + sigma * q0 * q0, mu * k01 + sigma * q0 * q1, mu * k11 + sigma * q1 * q1
        blocks[k, 0, 0], blocks[k, 0, 1], blocks[k, 1, 0], blocks[k, 1, 1] = b00, b01, b01, b11
        for node in (k, k + 1):
            per_node[node, 0, 0] += b00
            per_node[node, 0, 1] += b01
            per_node[node, 1, 0] += b01
            per_node[node, 1, 1] += b11


def contact_blocks(nu: Any, sigma: Any, gradient: Any, hessian: Any, diagonal: Any) -> None:  # pragma: no cover
    """``diagonal[f] += sum_j nu_jf Hess phi_j + sigma_jf grad phi_j grad phi_j^T`` (node contacts)."""
    for j in range(nu.shape[0]):
        for f in range(nu.shape[1]):
            g0, g1, w = gradient[j, f, 0], gradient[j, f, 1], sigma[j, f]
            diagonal[f, 0, 0] += nu[j, f] * hessian[j, f, 0, 0] + w * g0 * g0
            diagonal[f, 0, 1] += nu[j, f] * hessian[j, f, 0, 1] + w * g0 * g1
            diagonal[f, 1, 0] += nu[j, f] * hessian[j, f, 1, 0] + w * g1 * g0
            diagonal[f, 1, 1] += nu[j, f] * hessian[j, f, 1, 1] + w * g1 * g1


def link_products(q: Any, dp: Any, out: Any) -> None:  # pragma: no cover - compiled
    """``out[k] = q_k . (dp_k - dp_{k+1})``: the links' rows of ``J dp`` (dp (N, 2))."""
    for k in range(q.shape[0]):
        out[k] = q[k, 0] * (dp[k, 0] - dp[k + 1, 0]) + q[k, 1] * (dp[k, 1] - dp[k + 1, 1])


def link_transpose_products(q: Any, v: Any, total: Any) -> None:  # pragma: no cover - compiled
    """``total`` (N, 2, zeroed) += ``v_k q_k`` on node k and ``-v_k q_k`` on node k+1."""
    for k in range(q.shape[0]):
        total[k, 0] += v[k] * q[k, 0]
        total[k, 1] += v[k] * q[k, 1]
        total[k + 1, 0] -= v[k] * q[k, 0]
        total[k + 1, 1] -= v[k] * q[k, 1]


def polish_solve(
    is_free: Any,
    link_active: Any,
    q: Any,
    link_hessian: Any,
    contact_active: Any,
    contact_gradient: Any,
    node_hessian: Any,
    rhs_nodes: Any,
    rhs_links: Any,
    rhs_contacts: Any,
    step_nodes: Any,
    step_links: Any,
    step_contacts: Any,
    y: Any,
    coupling: Any,
) -> int:  # pragma: no cover - compiled
    """Solve the active-set KKT system of ``polish`` (node contact) node by node.

    Unknowns of node i, one block of size m = 3 + n_obstacles: (mu_{i-1}, x_i, y_i, nu_{0,i}, ...).
    Link i-1's row couples nodes i-1 and i; putting its multiplier in node i's block keeps the
    matrix block tridiagonal with only (x_i, y_i) of block i coupled to (mu_i, x_{i+1}, y_{i+1}) of
    block i+1 (the coupling ``B_i``, 2x3). Unknowns that are not in the system (a fixed node's
    coordinates, an inactive constraint's multiplier) get the row ``1 * u = 0``. Block
    elimination: ``S_i = D_i - B_{i-1}^T S_{i-1}^{-1} B_{i-1}`` with each S_i solved densely with
    partial pivoting. Without pivoting across blocks this is not always stable: a node whose link
    before is slack and link after taut has no constraint across that link in its own block, and
    in the norm form its curvature there is only the polish's proximal term, so the elimination
    would pass on a Schur complement of order 1/PROXIMAL = 1e10 and cancel it in the next block
    (residuals of 1e-6 where the banded LU reaches 1e-15). An update larger than UPDATE_LIMIT (in
    scaled units, where a long taut chain's compliance stays below 1e7) therefore returns the
    failing node, as does an exactly zero pivot, and the caller uses the banded LU. Inputs are per
    node (N) or per link (N-1); ``y`` (N, m) and ``coupling`` (N, m, 3) are workspace. Returns -1
    on success.
    """
    n_nodes, n_obstacles = is_free.shape[0], contact_active.shape[0]
    m = 3 + n_obstacles
    s = np.zeros((m, m + 4))  # [S_i | B_i columns | w_i]
    update = np.zeros((3, 3))  # B_{i-1}^T S_{i-1}^{-1} B_{i-1}
    carried = np.zeros(3)  # B_{i-1}^T S_{i-1}^{-1} w_{i-1}
    b_rows = np.zeros((2, 3))  # the nonzero rows (x_i, y_i) of B_i
    for i in range(n_nodes):
        s[:, :] = 0.0
        free = is_free[i]
        # D_i: the multiplier of link i-1 against (x_i, y_i) with -q_{i-1}
        if i > 0 and link_active[i - 1]:
            if free:
                s[0, 1], s[0, 2] = -q[i - 1, 0], -q[i - 1, 1]
                s[1, 0], s[2, 0] = -q[i - 1, 0], -q[i - 1, 1]
            s[0, m + 3] = rhs_links[i - 1]
        else:
            s[0, 0] = 1.0
        if free:
            for a in range(2):
                for b in range(2):
                    s[1 + a, 1 + b] = node_hessian[i, a, b]
                    if i > 0 and link_active[i - 1]:
                        s[1 + a, 1 + b] += link_hessian[i - 1, a, b]
                    if i + 1 < n_nodes and link_active[i]:
                        s[1 + a, 1 + b] += link_hessian[i, a, b]
                s[1 + a, m + 3] = rhs_nodes[i, a]
        else:
            s[1, 1], s[2, 2] = 1.0, 1.0
        for j in range(n_obstacles):
            r = 3 + j
            if free and contact_active[j, i]:
                s[r, 1], s[r, 2] = contact_gradient[j, i, 0], contact_gradient[j, i, 1]
                s[1, r], s[2, r] = contact_gradient[j, i, 0], contact_gradient[j, i, 1]
                s[r, m + 3] = rhs_contacts[j, i]
            else:
                s[r, r] = 1.0
        # minus the Schur complement of the blocks before
        if i > 0:
            for a in range(3):
                s[a, m + 3] -= carried[a]
                for b in range(3):
                    s[a, b] -= update[a, b]
        # B_i: (x_i, y_i) against (mu_i, x_{i+1}, y_{i+1})
        if i + 1 < n_nodes and link_active[i] and free:
            s[1, m], s[2, m] = q[i, 0], q[i, 1]
            if is_free[i + 1]:
                for a in range(2):
                    for b in range(2):
                        s[1 + a, m + 1 + b] = -link_hessian[i, a, b]
        # Gauss-Jordan with partial pivoting on [S_i | B_i | w_i] -> [I | C_i | y_i]
        for col in range(m):
            pivot = col
            for r in range(col + 1, m):
                if abs(s[r, col]) > abs(s[pivot, col]):
                    pivot = r
            if s[pivot, col] == 0.0:
                return i
            if pivot != col:
                for c in range(m + 4):
                    s[col, c], s[pivot, c] = s[pivot, c], s[col, c]
            inverse = 1.0 / s[col, col]
            for c in range(m + 4):
                s[col, c] *= inverse
            for r in range(m):
                if r != col and s[r, col] != 0.0:
                    factor = s[r, col]
                    for c in range(col, m + 4):
                        s[r, c] -= factor * s[col, c]
        for a in range(m):
            y[i, a] = s[a, m + 3]
            for b in range(3):
                coupling[i, a, b] = s[a, m + b]
        # what block i passes on: B_i^T C_i and B_i^T y_i (B_i's nonzero rows are x_i, y_i)
        update[:, :] = 0.0
        carried[:] = 0.0
        if i + 1 < n_nodes and link_active[i] and free:
            b_rows[:, :] = 0.0
            b_rows[0, 0], b_rows[1, 0] = q[i, 0], q[i, 1]
            if is_free[i + 1]:
                for a in range(2):
                    for b in range(2):
                        b_rows[a, 1 + b] = -link_hessian[i, a, b]
            for a in range(3):
                for r in range(2):
                    carried[a] += b_rows[r, a] * y[i, 1 + r]
                    for b in range(3):
                        update[a, b] += b_rows[r, a] * coupling[i, 1 + r, b]
            for a in range(3):
                for b in range(3):
                    if not abs(update[a, b]) <= UPDATE_LIMIT:
                        return i
    # back substitution: u_i = y_i - C_i (mu_i, x_{i+1}, y_{i+1})
    next_mu, next_x, next_y = 0.0, 0.0, 0.0
    for i in range(n_nodes - 1, -1, -1):
        for a in range(m):
            y[i, a] -= coupling[i, a, 0] * next_mu + coupling[i, a, 1] * next_x + coupling[i, a, 2] * next_y
        next_mu, next_x, next_y = y[i, 0], y[i, 1], y[i, 2]
        if i > 0:
            step_links[i - 1] = y[i, 0]
        step_nodes[i, 0], step_nodes[i, 1] = y[i, 1], y[i, 2]
        for j in range(n_obstacles):
            step_contacts[j, i] = y[i, 3 + j]
    return -1
