"""Compiled (numba) loops for the per-iteration work on the links (and on the contact rows of
quadratic obstacles, the KKT error, the Newton direction and the polish): the vectorized numpy in
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

UPDATE_LIMIT = 1e9  # polish_solve: a larger Schur complement update hands over to the banded LU
LINK_CHUNK = 256  # polish_solve: links whose terms are computed ahead of the elimination


def median(values: Any) -> float:
    """``np.median`` of a non-empty 1-D array of numbers (the middle value, or the mean of the
    middle two), without its wrapper's 20 us; the numpy path calls it as it is, ``driver``
    compiled."""
    ordered = np.sort(values)
    middle = ordered.size // 2
    return float(ordered[middle]) if ordered.size % 2 else 0.5 * float(ordered[middle - 1] + ordered[middle])


def link_terms(
    squared: bool, positions: Any, lengths: Any, links: Any, mu: Any, c: Any, q: Any, force: Any
) -> None:  # pragma: no cover - compiled
    """For the link ``k = links[r]``: ``c[r]`` its constraint value and ``q[k]`` its gradient w.r.t.
    p_k (``q`` (N-1, 2) zeroed: other links keep 0), and ``force`` (N, 2, zeroed) += the links'
    ``J^T mu`` on every node (``mu[r]`` the multiplier of row r)."""
    for r in range(links.shape[0]):
        k = links[r]
        dx, dy = positions[k, 0] - positions[k + 1, 0], positions[k, 1] - positions[k + 1, 1]
        d, length = math.hypot(dx, dy), lengths[k]
        if squared:
            q0, q1 = 2.0 * dx, 2.0 * dy
            c[r] = (d - length) * (d + length)
        else:  # the norm, or below r = SMOOTH_RATIO l its smooth stand-in
            radius = SMOOTH_RATIO * length
            reach = max(d, radius)
            q0, q1 = dx / reach, dy / reach
            c[r] = d - length if d >= radius else (d * d + radius * radius) / (2.0 * radius) - length
        q[k, 0], q[k, 1] = q0, q1
        force[k, 0] += mu[r] * q0
        force[k, 1] += mu[r] * q1
        force[k + 1, 0] -= mu[r] * q0
        force[k + 1, 1] -= mu[r] * q1


def quadratic_contacts(
    positions: Any,
    free: Any,
    offset: int,
    centres: Any,
    values: Any,
    gradients: Any,
    hessians: Any,
    mu: Any,
    c: Any,
    gradient: Any,
    force: Any,
) -> None:  # pragma: no cover - compiled
    """Contact rows of obstacles whose phi is quadratic (``obstacles.Quadratic``, scaled), at the free
    nodes ``free``: ``c[offset + j n + f]`` phi_j at free node f, ``gradient[j, f]`` its gradient,
    and ``force[f] += mu[offset + j n + f] * gradient[j, f]`` (``force`` per free node). The same
    formula as ``Quadratic.evaluate``: ``g = b + H d``, ``phi = value + (g + b) . d / 2``."""
    n = free.shape[0]
    for j in range(centres.shape[0]):
        cx, cy, value, b0, b1 = centres[j, 0], centres[j, 1], values[j], gradients[j, 0], gradients[j, 1]
        h00, h01, h10, h11 = hessians[j, 0, 0], hessians[j, 0, 1], hessians[j, 1, 0], hessians[j, 1, 1]
        for f in range(n):
            i = free[f]
            d0, d1 = positions[i, 0] - cx, positions[i, 1] - cy
            g0, g1 = b0 + (d0 * h00 + d1 * h10), b1 + (d0 * h01 + d1 * h11)
            row = offset + j * n + f
            c[row] = value + 0.5 * (d0 * (g0 + b0) + d1 * (g1 + b1))
            gradient[j, f, 0], gradient[j, f, 1] = g0, g1
            force[f, 0] += mu[row] * g0
            force[f, 1] += mu[row] * g1


def kkt_parts(
    squared: bool, dual: Any, c: Any, mu: Any, lengths: Any, links: Any
) -> tuple[float, float, float, float, float, float]:  # pragma: no cover - compiled
    """What ``ipm._kkt_error`` takes the largest of, in one pass: max |dual residual|, its sum over
    the nodes (x, y), the largest constraint value (a link's as its overstretch ``d - l``), max -mu
    and max |mu c|; all NaN if any entry is not finite (``max`` would skip a NaN)."""
    stationarity, net0, net1, size = 0.0, 0.0, 0.0, 0.0
    for f in range(dual.shape[0]):
        stationarity = max(stationarity, abs(dual[f, 0]), abs(dual[f, 1]))
        net0 += dual[f, 0]
        net1 += dual[f, 1]
        size += abs(dual[f, 0]) + abs(dual[f, 1])
    primal, negative, complementarity = 0.0, 0.0, 0.0
    n_links = links.shape[0]
    for r in range(c.shape[0]):
        value = c[r]
        if squared and r < n_links and value > 0.0:
            length = lengths[links[r]]
            value = value / (math.sqrt(value + length * length) + length)  # d - l = c / (d + l)
        primal = max(primal, value)
        negative = max(negative, -mu[r])
        complementarity = max(complementarity, abs(mu[r] * c[r]))
        size += abs(c[r]) + abs(mu[r])
    if not math.isfinite(size):
        return math.nan, math.nan, math.nan, math.nan, math.nan, math.nan
    return stationarity, net0, net1, primal, negative, complementarity


def link_blocks(
    squared: bool,
    positions: Any,
    lengths: Any,
    links: Any,
    mu_links: Any,
    sigma_links: Any,
    q: Any,
    node_index: Any,
    diagonal: Any,
    off_diagonal: Any,
) -> None:  # pragma: no cover - compiled
    """The links' part of the Newton matrix: for the link ``k = links[r]``, ``B = mu_r K_k +
    sigma_r q_k q_k^T`` (its Hessian block and barrier term) is added to the diagonal blocks of both
    its nodes and, negated, is the block between them. ``node_index`` (N,): where each node's
    block is in ``diagonal`` (zeroed), or -1 for a node without one; two consecutive nodes f,
    f+1 are coupled by ``off_diagonal[f]`` (zeroed where no link joins them)."""
    for r in range(links.shape[0]):
        k = links[r]
        q0, q1 = q[k, 0], q[k, 1]
        if squared:
            k00, k01, k11 = 2.0, 0.0, 2.0
        else:
            dx, dy = positions[k, 0] - positions[k + 1, 0], positions[k, 1] - positions[k + 1, 1]
            d, radius = math.hypot(dx, dy), SMOOTH_RATIO * lengths[k]
            if d >= radius:
                k00, k01, k11 = (1.0 - q0 * q0) / d, -q0 * q1 / d, (1.0 - q1 * q1) / d
            else:
                k00, k01, k11 = 1.0 / radius, 0.0, 1.0 / radius
        mu, sigma = mu_links[r], sigma_links[r]
        b00, b01, b11 = mu * k00 + sigma * q0 * q0, mu * k01 + sigma * q0 * q1, mu * k11 + sigma * q1 * q1
        first, second = node_index[k], node_index[k + 1]
        for f in (first, second):
            if f >= 0:
                diagonal[f, 0, 0] += b00
                diagonal[f, 0, 1] += b01
                diagonal[f, 1, 0] += b01
                diagonal[f, 1, 1] += b11
        if first >= 0 and second >= 0:
            off_diagonal[first, 0, 0], off_diagonal[first, 0, 1] = -b00, -b01
            off_diagonal[first, 1, 0], off_diagonal[first, 1, 1] = -b01, -b11


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


def newton_rhs(
    q: Any, link_row: Any, free: Any, gradient: Any, dual: Any, c: Any, s: Any, mu: Any, r_c: Any, rhs: Any
) -> None:  # pragma: no cover - compiled
    """The condensed Newton system's right-hand side (``ipm._newton_direction``), node contact:
    ``rhs = -(dual + J^T w)`` over the free coordinates (flat), ``w = (mu/s)(c + s) - r_c/s`` per
    constraint. ``link_row`` (N-1,): each link's constraint row, or -1; contact row of obstacle j
    and free node f: ``n_links + j n + f``. Sums in the order of the numpy path."""
    n, n_obstacles = free.shape[0], gradient.shape[0]
    n_links = c.shape[0] - n_obstacles * n
    for f in range(n):
        p = free[f]
        t0, t1 = 0.0, 0.0
        if p > 0 and link_row[p - 1] >= 0:
            r = link_row[p - 1]
            w = (mu[r] / s[r]) * (c[r] + s[r]) - r_c[r] / s[r]
            t0 -= w * q[p - 1, 0]
            t1 -= w * q[p - 1, 1]
        if p < q.shape[0] and link_row[p] >= 0:
            r = link_row[p]
            w = (mu[r] / s[r]) * (c[r] + s[r]) - r_c[r] / s[r]
            t0 += w * q[p, 0]
            t1 += w * q[p, 1]
        for j in range(n_obstacles):
            r = n_links + j * n + f
            w = (mu[r] / s[r]) * (c[r] + s[r]) - r_c[r] / s[r]
            t0 += w * gradient[j, f, 0]
            t1 += w * gradient[j, f, 1]
        rhs[2 * f] = -(dual[f, 0] + t0)
        rhs[2 * f + 1] = -(dual[f, 1] + t1)


def newton_update(
    q: Any,
    links: Any,
    free_index: Any,
    gradient: Any,
    dz: Any,
    c: Any,
    s: Any,
    mu: Any,
    r_c: Any,
    dmu: Any,
    ds: Any,
) -> None:  # pragma: no cover - compiled
    """The multipliers' and slacks' Newton steps from the positions' ``dz`` (node contact):
    ``dmu = (mu/s)(J dz + c + s) - r_c/s``, ``ds = -(r_c + s dmu) / mu``. ``free_index`` (N,):
    each node's place among the free nodes, or -1."""
    n_links, n_obstacles, n = links.shape[0], gradient.shape[0], gradient.shape[1]
    for r in range(n_links + n_obstacles * n):
        if r < n_links:
            k = links[r]
            a, b = free_index[k], free_index[k + 1]
            d0 = (dz[2 * a] if a >= 0 else 0.0) - (dz[2 * b] if b >= 0 else 0.0)
            d1 = (dz[2 * a + 1] if a >= 0 else 0.0) - (dz[2 * b + 1] if b >= 0 else 0.0)
            product = q[k, 0] * d0 + q[k, 1] * d1
        else:
            j, f = (r - n_links) // n, (r - n_links) % n
            product = gradient[j, f, 0] * dz[2 * f] + gradient[j, f, 1] * dz[2 * f + 1]
        dmu[r] = (mu[r] / s[r]) * (product + (c[r] + s[r])) - r_c[r] / s[r]
        ds[r] = -(r_c[r] + s[r] * dmu[r]) / mu[r]


def step_to_boundary(values: Any, steps: Any, fraction: float) -> float:  # pragma: no cover - compiled
    """``min(1, fraction * min(-values / steps over steps < 0))`` (``ipm._step_to_boundary``)."""
    smallest = math.inf
    for i in range(values.shape[0]):
        if steps[i] < 0.0:
            smallest = min(smallest, -values[i] / steps[i])
    return min(1.0, fraction * smallest)


def polish_solve(
    squared: bool,
    positions: Any,
    lengths: Any,
    load: Any,
    free: Any,
    links: Any,
    active: Any,
    mu: Any,
    c: Any,
    contact_gradient: Any,
    contact_hessian: Any,
    proximal: float,
    new_z: Any,
    new_mu: Any,
    coupling: Any,
    contact_coupling: Any,
) -> int:  # pragma: no cover - compiled
    """One Newton step of ``polish`` (node contact), assembled and solved node by node in one pass.

    Unknowns of node i, one block: (mu_{i-1}, x_i, y_i, the multipliers of node i's active
    contacts). Link i-1's row couples nodes i-1 and i; putting its multiplier in node i's block keeps
    the matrix block tridiagonal with only (x_i, y_i) of block i coupled to (mu_i, x_{i+1}, y_{i+1})
    of block i+1 (the coupling ``B_i``, 2x3). Unknowns that are not in the system (a fixed node's
    coordinates, a slack link's multiplier) get the row ``1 * u = 0``; an inactive contact's row
    would be such a row too, decoupled from the rest, so it is left out. Block elimination:
    ``S_i = D_i - B_{i-1}^T S_{i-1}^{-1} B_{i-1}``, each S_i solved by Gauss-Jordan with partial
    pivoting. Without pivoting across blocks this is not always stable: a node whose link before is
    slack and link after taut has no constraint across that link in its own block, and in the norm
    form its curvature there is only the proximal term, so the elimination would pass on a Schur
    complement of order 1/proximal = 1e10 and cancel it in the next block (residuals of 1e-6 where
    the banded LU reaches 1e-15). An update larger than UPDATE_LIMIT (in scaled units; a long taut
    chain's compliance stays below 1e7, a run of thousands of nodes lying on a disk reaches 1e8-1e9,
    where 1e8 handed every step of a 12,500-node drape over to the LU, 30 times slower) therefore
    returns the failing node, as does an exactly zero pivot or a non-finite step, and the caller
    uses the banded LU.

    The links' values, gradients and Hessian blocks (``link_terms``, ``link_blocks``), the node
    Hessians (``sum_j nu_j Hess phi_j + proximal I``) and the right-hand side are computed as the
    elimination goes (the links' a chunk of LINK_CHUNK ahead), with the same arithmetic as the
    separate kernels, instead of being stored for all nodes first: at 10^6 nodes the temporaries
    cost more than the elimination. A block with at most one contact (almost every node) is
    eliminated in registers. ``free`` and ``links`` (ascending) are walked alongside the nodes;
    ``active``, ``mu`` and ``c`` are the constraint vectors (links, then contacts obstacle by
    obstacle), the contact derivatives are per free node. Writes the new free positions (flat) to
    ``new_z`` and the new multipliers (zero where inactive) to ``new_mu``, which also hold the
    forward pass's solutions ``y_i``; ``coupling`` (N, 3, 3) and ``contact_coupling`` (n_obstacles,
    n, 3) are workspace for ``C_i = S_i^{-1} B_i``. Returns -1 on success, else the node where it
    gave up (N if ``free`` or ``links`` is not ascending).
    """

    def scaled(row: Any, factor: float) -> Any:
        """A row (B_i | w_i | S_i, up to 4 columns of S_i) times ``factor``."""
        b0, b1, b2, w, a0, a1, a2, a3 = row
        return b0 * factor, b1 * factor, b2 * factor, w * factor, a0 * factor, a1 * factor, a2 * factor, a3 * factor

    def minus(row: Any, factor: float, pivot: Any) -> Any:
        """``row - factor * pivot``."""
        b0, b1, b2, w, a0, a1, a2, a3 = row
        p0, p1, p2, pw, q0, q1, q2, q3 = pivot
        return (
            b0 - factor * p0,
            b1 - factor * p1,
            b2 - factor * p2,
            w - factor * pw,
            a0 - factor * q0,
            a1 - factor * q1,
            a2 - factor * q2,
            a3 - factor * q3,
        )

    n_nodes: int = positions.shape[0]
    n_free: int = free.shape[0]
    n_links: int = links.shape[0]
    n_obstacles = contact_gradient.shape[0]
    # [B_i (3 columns) | w_i | S_i]: rows (mu_{i-1}, x_i, y_i, active contacts of node i)
    s = np.zeros((3 + n_obstacles, 7 + n_obstacles))
    contact_rows = np.zeros(n_obstacles, dtype=np.int64)  # their rows in c, mu
    terms = np.zeros((LINK_CHUNK, 7))  # value, mu, q and mu K of the links of this chunk that are active
    link_rows = np.zeros(LINK_CHUNK, dtype=np.int64)  # their rows in links (-1: not optimised)
    # B_{i-1}^T S_{i-1}^{-1} B_{i-1} and B_{i-1}^T S_{i-1}^{-1} w_{i-1}
    u00, u01, u02, u10, u11, u12, u20, u21, u22 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    carried0, carried1, carried2 = 0.0, 0.0, 0.0
    # link i-1: taut (active), its row, value, gradient q, multiplier and mu K (its Hessian block)
    before, before_row, before_c, before_mu = False, -1, 0.0, 0.0
    before_q0, before_q1, before_h00, before_h01, before_h11 = 0.0, 0.0, 0.0, 0.0, 0.0

    def prepare_links(start: int, k: int) -> int:
        """``link_rows`` and ``terms`` of the links from ``start`` on, the next entry of ``links``
        being ``k``; returns the one after them. A loop of its own: calling hypot in the
        elimination loop would spill its registers."""
        for link in range(start, min(start + LINK_CHUNK, n_nodes)):
            slot, row = link - start, -1
            if k < n_links and links[k] == link:
                row, k = k, k + 1
            link_rows[slot] = row
            if row < 0 or not active[row]:
                continue
            dx, dy = positions[link, 0] - positions[link + 1, 0], positions[link, 1] - positions[link + 1, 1]
            d, length, tension = math.hypot(dx, dy), lengths[link], mu[row]
            if squared:
                q0, q1 = 2.0 * dx, 2.0 * dy
                value = (d - length) * (d + length)
                h00, h01, h11 = tension * 2.0, tension * 0.0, tension * 2.0
            else:  # the norm, or below r = SMOOTH_RATIO l its smooth stand-in
                r = SMOOTH_RATIO * length
                reach = max(d, r)
                q0, q1 = dx / reach, dy / reach
                if d >= r:
                    value = d - length
                    h00, h01, h11 = (1.0 - q0 * q0) / d, -q0 * q1 / d, (1.0 - q1 * q1) / d
                else:
                    value = (d * d + r * r) / (2.0 * r) - length
                    h00, h01, h11 = 1.0 / r, 0.0, 1.0 / r
                h00, h01, h11 = tension * h00, tension * h01, tension * h11
            terms[slot, 0], terms[slot, 1], terms[slot, 2], terms[slot, 3] = value, tension, q0, q1
            terms[slot, 4], terms[slot, 5], terms[slot, 6] = h00, h01, h11
        return k

    f, k = 0, 0  # the next entries of free and links
    for i in range(n_nodes):
        if i % LINK_CHUNK == 0:
            k = prepare_links(i, k)
        here = f < n_free and free[f] == i
        # link i: taut (active), its row, value, gradient, multiplier and Hessian block
        slot = i % LINK_CHUNK
        row = link_rows[slot]
        taut = row >= 0 and active[row]
        value, tension, q0, q1, h00, h01, h11 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        if taut:
            value, tension, q0, q1 = terms[slot, 0], terms[slot, 1], terms[slot, 2], terms[slot, 3]
            h00, h01, h11 = terms[slot, 4], terms[slot, 5], terms[slot, 6]
        size = 3
        if here:
            for j in range(n_obstacles):
                index = n_links + j * n_free + f
                if active[index]:
                    contact_rows[size - 3] = index
                    size += 1
        # D_i - update and w_i - carried as rows (B_i | w_i | S_i) of node i's unknowns (mu_{i-1}, x_i, y_i):
        # the multiplier of link i-1 against (x_i, y_i) with -q_{i-1}
        w0, s00, s01, s02 = 0.0, 1.0, 0.0, 0.0
        w1, s10, s11, s12, w2, s20, s21, s22 = 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0
        if before:
            s00, w0 = 0.0, -before_c
            if here:
                s01, s02, s10, s20 = -before_q0, -before_q1, -before_q0, -before_q1
        if here:
            n00, n01, n10, n11 = 0.0, 0.0, 0.0, 0.0  # sum_j nu_j Hess phi_j
            e0, e1 = 0.0, 0.0  # sum_j nu_j grad phi_j
            for a in range(3, size):
                index = contact_rows[a - 3]
                j, nu = (index - n_links) // n_free, mu[index]
                n00 += nu * contact_hessian[j, f, 0, 0]
                n01 += nu * contact_hessian[j, f, 0, 1]
                n10 += nu * contact_hessian[j, f, 1, 0]
                n11 += nu * contact_hessian[j, f, 1, 1]
                e0 += nu * contact_gradient[j, f, 0]
                e1 += nu * contact_gradient[j, f, 1]
            n00 += proximal
            n11 += proximal
            if before:
                n00, n01, n10, n11 = n00 + before_h00, n01 + before_h01, n10 + before_h01, n11 + before_h11
            if taut:
                n00, n01, n10, n11 = n00 + h00, n01 + h01, n10 + h01, n11 + h11
            s11, s12, s21, s22 = n00, n01, n10, n11
            # grad E + J^T mu, in the order of link_terms and polish_step
            force0, force1 = 0.0, 0.0
            if before:
                force0 -= before_mu * before_q0
                force1 -= before_mu * before_q1
            if taut:
                force0 += tension * q0
                force1 += tension * q1
            force1 += load[i]
            w1, w2 = -(force0 + e0), -(force1 + e1)
        # minus the Schur complement of the blocks before
        s00, s01, s02, w0 = s00 - u00, s01 - u01, s02 - u02, w0 - carried0
        s10, s11, s12, w1 = s10 - u10, s11 - u11, s12 - u12, w1 - carried1
        s20, s21, s22, w2 = s20 - u20, s21 - u21, s22 - u22, w2 - carried2
        # B_i: (x_i, y_i) against (mu_i, x_{i+1}, y_{i+1})
        coupled = taut and here
        after = f + here < n_free and free[f + here] == i + 1
        b01, b02, b11, b12 = 0.0, 0.0, 0.0, 0.0
        if coupled and after:
            b01, b02, b11, b12 = -h00, -h01, -h01, -h11
        b10, b20 = (q0, q1) if coupled else (0.0, 0.0)
        # Gauss-Jordan with partial pivoting on the rows [B_i | w_i | S_i] -> [C_i | y_i | I]; a pivot row
        # is the first with the largest entry, as in a loop over the rows. One contact or none: in
        # registers, column by column; more: in ``s``.
        g0, g1, phi = 0.0, 0.0, 0.0  # one contact: its gradient and value
        if size == 4:
            index = contact_rows[0]
            j = (index - n_links) // n_free
            g0, g1, phi = contact_gradient[j, f, 0], contact_gradient[j, f, 1], c[index]
        row0 = (0.0, 0.0, 0.0, w0, s00, s01, s02, 0.0)
        row1 = (b10, b01, b02, w1, s10, s11, s12, g0)
        row2 = (b20, b11, b12, w2, s20, s21, s22, g1)
        row3 = (0.0, 0.0, 0.0, -phi, 0.0, g0, g1, 0.0)  # the contact's (size 4)
        if size <= 4:
            # column 0 (the contact's row has a zero there)
            largest, pivot = abs(row0[4]), 0
            if abs(row1[4]) > largest:
                largest, pivot = abs(row1[4]), 1
            if abs(row2[4]) > largest:
                largest, pivot = abs(row2[4]), 2
            if largest == 0.0:
                return i
            if pivot == 1:
                row0, row1 = row1, row0
            elif pivot == 2:
                row0, row2 = row2, row0
            row0 = scaled(row0, 1.0 / row0[4])
            row1, row2 = minus(row1, row1[4], row0), minus(row2, row2[4], row0)
            # column 1
            largest, pivot = abs(row1[5]), 1
            if abs(row2[5]) > largest:
                largest, pivot = abs(row2[5]), 2
            if size == 4 and abs(row3[5]) > largest:
                largest, pivot = abs(row3[5]), 3
            if largest == 0.0:
                return i
            if pivot == 2:
                row1, row2 = row2, row1
            elif pivot == 3:
                row1, row3 = row3, row1
            row1 = scaled(row1, 1.0 / row1[5])
            row0, row2 = minus(row0, row0[5], row1), minus(row2, row2[5], row1)
            if size == 4:
                row3 = minus(row3, row3[5], row1)
            # column 2
            largest, pivot = abs(row2[6]), 2
            if size == 4 and abs(row3[6]) > largest:
                largest, pivot = abs(row3[6]), 3
            if largest == 0.0:
                return i
            if pivot == 3:
                row2, row3 = row3, row2
            row2 = scaled(row2, 1.0 / row2[6])
            row0, row1 = minus(row0, row0[6], row2), minus(row1, row1[6], row2)
            if size == 4:
                row3 = minus(row3, row3[6], row2)
                # column 3
                if row3[7] == 0.0:
                    return i
                row3 = scaled(row3, 1.0 / row3[7])
                row0, row1, row2 = minus(row0, row0[7], row3), minus(row1, row1[7], row3), minus(row2, row2[7], row3)
                new_mu[index] = row3[3]
                contact_coupling[j, f, 0], contact_coupling[j, f, 1], contact_coupling[j, f, 2] = row3[:3]
        else:
            width = 4 + size
            for a in range(size):
                for b in range(width):
                    s[a, b] = 0.0
            for b in range(7):
                s[0, b], s[1, b], s[2, b] = row0[b], row1[b], row2[b]
            for a in range(3, size):
                index = contact_rows[a - 3]
                j = (index - n_links) // n_free
                g0, g1 = contact_gradient[j, f, 0], contact_gradient[j, f, 1]
                s[a, 5], s[a, 6], s[1, 4 + a], s[2, 4 + a] = g0, g1, g0, g1
                s[a, 3] = -c[index]
            for col in range(size):
                pivot, largest = col, abs(s[col, 4 + col])
                for r in range(col + 1, size):
                    if abs(s[r, 4 + col]) > largest:
                        pivot, largest = r, abs(s[r, 4 + col])
                if largest == 0.0:
                    return i
                inverse = 1.0 / s[pivot, 4 + col]
                if pivot != col:
                    for b in range(4):
                        s[col, b], s[pivot, b] = s[pivot, b], s[col, b]
                    for b in range(4 + col, width):
                        s[col, b], s[pivot, b] = s[pivot, b], s[col, b]
                for b in range(4):
                    s[col, b] *= inverse
                for b in range(5 + col, width):
                    s[col, b] *= inverse
                for r in range(size):
                    factor = s[r, 4 + col]
                    if r != col and factor != 0.0:
                        for b in range(4):
                            s[r, b] -= factor * s[col, b]
                        for b in range(5 + col, width):
                            s[r, b] -= factor * s[col, b]
            for a in range(3, size):
                index = contact_rows[a - 3]
                new_mu[index] = s[a, 3]
                j = (index - n_links) // n_free
                for b in range(3):
                    contact_coupling[j, f, b] = s[a, b]
            row0 = (s[0, 0], s[0, 1], s[0, 2], s[0, 3], 1.0, 0.0, 0.0, 0.0)
            row1 = (s[1, 0], s[1, 1], s[1, 2], s[1, 3], 0.0, 1.0, 0.0, 0.0)
            row2 = (s[2, 0], s[2, 1], s[2, 2], s[2, 3], 0.0, 0.0, 1.0, 0.0)
        coupling[i, 0, 0], coupling[i, 0, 1], coupling[i, 0, 2] = row0[0], row0[1], row0[2]
        coupling[i, 1, 0], coupling[i, 1, 1], coupling[i, 1, 2] = row1[0], row1[1], row1[2]
        coupling[i, 2, 0], coupling[i, 2, 1], coupling[i, 2, 2] = row2[0], row2[1], row2[2]
        if before:
            new_mu[before_row] = row0[3]
        if here:
            new_z[2 * f], new_z[2 * f + 1] = row1[3], row2[3]
        # what block i passes on: B_i^T C_i and B_i^T y_i (B_i's nonzero rows are x_i, y_i)
        if coupled:
            carried0, carried1, carried2 = (
                q0 * row1[3] + q1 * row2[3],
                b01 * row1[3] + b11 * row2[3],
                b02 * row1[3] + b12 * row2[3],
            )
            u00, u01, u02 = q0 * row1[0] + q1 * row2[0], q0 * row1[1] + q1 * row2[1], q0 * row1[2] + q1 * row2[2]
            u10, u11, u12 = b01 * row1[0] + b11 * row2[0], b01 * row1[1] + b11 * row2[1], b01 * row1[2] + b11 * row2[2]
            u20, u21, u22 = b02 * row1[0] + b12 * row2[0], b02 * row1[1] + b12 * row2[1], b02 * row1[2] + b12 * row2[2]
            for update in (u00, u01, u02, u10, u11, u12, u20, u21, u22):
                if not abs(update) <= UPDATE_LIMIT:
                    return i
        else:
            u00, u01, u02, u10, u11, u12, u20, u21, u22 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            carried0, carried1, carried2 = 0.0, 0.0, 0.0
        before, before_row, before_c, before_mu = taut, row, value, tension
        before_q0, before_q1, before_h00, before_h01, before_h11 = q0, q1, h00, h01, h11
        f += here
    if f < n_free or k < n_links:
        return n_nodes
    # back substitution: u_i = y_i - C_i (mu_i, x_{i+1}, y_{i+1}), then the new point
    next_mu, next_x, next_y = 0.0, 0.0, 0.0
    for i in range(n_nodes - 1, -1, -1):
        here = f > 0 and free[f - 1] == i
        f -= here
        row = -1
        if i > 0 and k > 0 and links[k - 1] == i - 1:
            k -= 1
            row = k
        step_mu, step_x, step_y = 0.0, 0.0, 0.0
        if row >= 0 and active[row]:
            step_mu = new_mu[row] - (
                coupling[i, 0, 0] * next_mu + coupling[i, 0, 1] * next_x + coupling[i, 0, 2] * next_y
            )
            new_mu[row] = mu[row] + step_mu
        elif row >= 0:
            new_mu[row] = 0.0
        if here:
            step_x = new_z[2 * f] - (
                coupling[i, 1, 0] * next_mu + coupling[i, 1, 1] * next_x + coupling[i, 1, 2] * next_y
            )
            step_y = new_z[2 * f + 1] - (
                coupling[i, 2, 0] * next_mu + coupling[i, 2, 1] * next_x + coupling[i, 2, 2] * next_y
            )
            new_z[2 * f], new_z[2 * f + 1] = positions[i, 0] + step_x, positions[i, 1] + step_y
            for j in range(n_obstacles):
                index = n_links + j * n_free + f
                if active[index]:
                    step = new_mu[index] - (
                        contact_coupling[j, f, 0] * next_mu
                        + contact_coupling[j, f, 1] * next_x
                        + contact_coupling[j, f, 2] * next_y
                    )
                    if not math.isfinite(step):
                        return i
                    new_mu[index] = mu[index] + step
                else:
                    new_mu[index] = 0.0
        if not (math.isfinite(step_mu) and math.isfinite(step_x) and math.isfinite(step_y)):
            return i
        next_mu, next_x, next_y = step_mu, step_x, step_y
    return -1
