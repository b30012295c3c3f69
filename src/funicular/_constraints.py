"""Link constraints, their gradients and Hessians as the checks, the forces and the other backends
read them: the exact norm. (The solver core evaluates its own smooth stand-in, below.)

For link k with ``delta_k = p_k - p_{k+1}`` and ``d_k = ||delta_k||``:

* norm:    ``c_k = d_k - l_k``,     gradient w.r.t. p_k ``q_k = delta_k / d_k``, Hessian block ``(I - q q^T) / d_k``
* squared: ``c_k = d_k^2 - l_k^2``,   gradient w.r.t. p_k ``q_k = 2 delta_k``,    Hessian block ``K_k = 2 I``

The gradient w.r.t. p_{k+1} is ``-q_k`` and the full Hessian of c_k is ``[[K, -K], [-K, K]]``.

The norm is not differentiable where two neighbouring nodes coincide (d_k = 0). There we take
``q_k = 0``, which is a valid subgradient, and cap the curvature ``1/d_k`` at ``1/(MIN_RATIO * l_k)``.

The solver core (norm form only) replaces the norm below ``r_k = SMOOTH_RATIO * l_k`` by the
parabola that meets it with the same value and slope at ``d_k = r_k``, so that the barrier is
smooth where two nodes meet (the core's ``evaluate`` module says why). A link shorter than ``r_k``
is slack in both forms and the KKT points are the same; the core's multiplier of such a link
applies the force ``mu_k delta_k / r_k``, which is the norm-form tension ``mu_k d_k / r_k`` (the
core reports that).
"""

from __future__ import annotations

import numpy as np

from funicular.model import FloatArray, Formulation

MIN_RATIO = 1e-8
SAFE_NORM_MIN, SAFE_NORM_MAX = 1e-150, 1e150  # link_distances: their squares are normal numbers
HYPOT_UP_TO = 1000  # links up to which link_distances uses np.hypot throughout


def link_deltas(positions: FloatArray) -> FloatArray:
    """``delta_k = p_k - p_{k+1}`` for every link, shape (N-1, 2)."""
    return positions[:-1] - positions[1:]


def link_distances(positions: FloatArray) -> FloatArray:
    """Current link lengths ``d_k = ||p_k - p_{k+1}||``.

    As ``sqrt(dx^2 + dy^2)``, and by ``np.hypot`` only where that could lose accuracy to underflow
    or overflow (a distance outside 1e-150..1e150, or not finite): np.hypot guards every element and
    costs 15-35 ms per 10^6 links, several times the square root. (For a short chain np.hypot
    alone: the guards cost less than the checks, and np.errstate's context alone costs more.)"""
    delta = link_deltas(positions)
    x, y = delta[:, 0], delta[:, 1]
    if x.size <= HYPOT_UP_TO:
        distances: FloatArray = np.hypot(x, y)
        return distances
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        distances = np.sqrt(x * x + y * y)
    unsafe = ~((distances > SAFE_NORM_MIN) & (distances < SAFE_NORM_MAX))  # (NaN is unsafe too)
    if unsafe.any():
        distances[unsafe] = np.hypot(x[unsafe], y[unsafe])
    return distances


def link_values(formulation: Formulation, distances: FloatArray, lengths: FloatArray) -> FloatArray:
    """Constraint values ``c_k`` (feasible where <= 0)."""
    if formulation is Formulation.NORM:
        return distances - lengths
    return (distances - lengths) * (distances + lengths)  # d^2 - l^2 without cancellation


def link_gradients(formulation: Formulation, delta: FloatArray, distances: FloatArray) -> FloatArray:
    """``q_k``: gradient of ``c_k`` with respect to ``p_k`` (shape (N-1, 2))."""
    if formulation is Formulation.NORM:
        safe = np.where(distances > 0, distances, 1.0)
        return np.where((distances > 0)[:, None], delta / safe[:, None], 0.0)
    return 2.0 * delta


def link_hessian_blocks(
    formulation: Formulation, delta: FloatArray, distances: FloatArray, lengths: FloatArray
) -> FloatArray:
    """``K_k`` (shape (N-1, 2, 2)) so that the Hessian of c_k is ``[[K, -K], [-K, K]]``."""
    m = delta.shape[0]
    if formulation is Formulation.SQUARED:
        return np.broadcast_to(2.0 * np.eye(2), (m, 2, 2)).copy()
    capped = np.maximum(distances, MIN_RATIO * lengths)
    q = link_gradients(formulation, delta, distances)
    blocks = np.empty((m, 2, 2))
    blocks[:, 0, 0] = 1.0 - q[:, 0] * q[:, 0]
    blocks[:, 0, 1] = blocks[:, 1, 0] = -q[:, 0] * q[:, 1]
    blocks[:, 1, 1] = 1.0 - q[:, 1] * q[:, 1]
    return blocks / capped[:, None, None]


def tension_from_multipliers(formulation: Formulation, multipliers: FloatArray, distances: FloatArray) -> FloatArray:
    """Link tension ``T_k``: ``mu_k`` (norm) or ``2 d_k mu_k`` (squared)."""
    if formulation is Formulation.NORM:
        return np.asarray(multipliers, dtype=np.float64).copy()
    return 2.0 * distances * multipliers


def multipliers_from_tension(formulation: Formulation, tension: FloatArray, distances: FloatArray) -> FloatArray:
    """Inverse of :func:`tension_from_multipliers` (a link of zero length carries no force)."""
    if formulation is Formulation.NORM:
        return np.asarray(tension, dtype=np.float64).copy()
    safe = np.where(distances > 0, distances, 1.0)
    return np.where(distances > 0, tension / (2.0 * safe), 0.0)
