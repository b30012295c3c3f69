"""Compiled (numba) loops for the per-iteration work on the links: the vectorized numpy in
``chain`` makes a dozen passes over (N, 2) and (N, 2, 2) temporaries for what one loop over the
links does in one pass. Same formulas as :mod:`funicular.constraints` (norm: ``q = delta / d``,
Hessian block ``(I - q q^T) / max(d, MIN_RATIO l)``; squared: ``q = 2 delta``, block ``2 I``),
written out per link; the tests check both paths agree to rounding on every built-in scenario.

Each kernel is plain Python over arrays, compiled on first use when numba is installed
(:func:`funicular.solver.compiled.jit`); ``chain`` calls them only then (see ``ScaledChain.compiled``).
"""

from __future__ import annotations

import math
from typing import Any

from funicular.constraints import MIN_RATIO


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
        else:
            q0, q1 = (dx / d, dy / d) if d > 0.0 else (0.0, 0.0)
            c[k] = d - length
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
            capped = max(math.hypot(dx, dy), MIN_RATIO * lengths[k])
            k00, k01, k11 = (1.0 - q0 * q0) / capped, -q0 * q1 / capped, (1.0 - q1 * q1) / capped
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
