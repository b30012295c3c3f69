"""Link constraints, their gradients and Hessians as the checks, the forces and the other backends
read them: the exact norm. (The solver core evaluates its own smooth stand-in, below.)

For link k joining nodes a and b (a chain's: k and k+1), with ``delta_k = p_a - p_b`` and
``d_k = ||delta_k||``:

* norm:    ``c_k = d_k - l_k``,     gradient w.r.t. p_a ``q_k = delta_k / d_k``, Hessian block ``(I - q q^T) / d_k``
* squared: ``c_k = d_k^2 - l_k^2``,   gradient w.r.t. p_a ``q_k = 2 delta_k``,    Hessian block ``K_k = 2 I``

The gradient w.r.t. p_b is ``-q_k`` and the full Hessian of c_k is ``[[K, -K], [-K, K]]``.

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

from funicular.model import FloatArray, Formulation, IntArray

MIN_RATIO = 1e-8
SAFE_NORM_MIN, SAFE_NORM_MAX = 1e-150, 1e150  # link_distances: their squares are normal numbers
HYPOT_UP_TO = 1000  # links up to which link_distances uses np.hypot throughout


def link_deltas(positions: FloatArray, links: IntArray | None = None) -> FloatArray:
    """``delta_k = p_a - p_b`` for every link (L, d); ``links`` (L, 2) the node pairs, None for a
    chain's (k, k+1)."""
    if links is None:
        return positions[:-1] - positions[1:]
    return positions[links[:, 0]] - positions[links[:, 1]]


def norms(vectors: FloatArray) -> FloatArray:
    """Each row's Euclidean norm, (k, d) -> (k,), without overflow or underflow.

    As ``sqrt(sum of squares)``, and guarded (np.hypot in the plane, a rescaling in space) only where
    that could lose accuracy (a norm outside 1e-150..1e150, or not finite): np.hypot guards every
    element and costs 15-35 ms per 10^6 links, several times the square root. (For a few vectors the
    guards alone: they cost less than the checks, and np.errstate's context alone costs more.)"""
    if vectors.shape[1] == 2 and vectors.shape[0] <= HYPOT_UP_TO:
        small: FloatArray = np.hypot(vectors[:, 0], vectors[:, 1])
        return small
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        result: FloatArray = np.einsum("ij,ij->i", vectors, vectors)
        np.sqrt(result, out=result)  # (in place: one array of N, not two)
    unsafe = ~((result > SAFE_NORM_MIN) & (result < SAFE_NORM_MAX))  # (NaN is unsafe too)
    if unsafe.any():
        result[unsafe] = _guarded_norms(vectors[unsafe])
    return result


def _guarded_norms(vectors: FloatArray) -> FloatArray:
    if vectors.shape[1] == 2:
        plane: FloatArray = np.hypot(vectors[:, 0], vectors[:, 1])
        return plane
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        scale = np.max(np.abs(vectors), axis=1)
        safe = np.where((scale > 0) & np.isfinite(scale), scale, 1.0)
        scaled = vectors / safe[:, None]
        result: FloatArray = np.where(
            (scale > 0) & np.isfinite(scale), safe * np.sqrt(np.einsum("ij,ij->i", scaled, scaled)), scale
        )
    return result


def link_distances(positions: FloatArray, links: IntArray | None = None) -> FloatArray:
    """Current link lengths ``d_k = ||p_a - p_b||`` (see :func:`norms`)."""
    return norms(link_deltas(positions, links))


def link_values(formulation: Formulation, distances: FloatArray, lengths: FloatArray) -> FloatArray:
    """Constraint values ``c_k`` (feasible where <= 0)."""
    if formulation is Formulation.NORM:
        return distances - lengths
    return (distances - lengths) * (distances + lengths)  # d^2 - l^2 without cancellation


def link_gradients(
    formulation: Formulation, delta: FloatArray, distances: FloatArray, out: FloatArray | None = None
) -> FloatArray:
    """``q_k``: gradient of ``c_k`` with respect to ``p_a`` (shape (L, d)), into ``out`` if given."""
    if formulation is Formulation.NORM:
        return link_directions(delta, distances, out)
    q: FloatArray = np.empty(delta.shape) if out is None else out
    return np.multiply(delta, 2.0, out=q)


def link_directions(delta: FloatArray, distances: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """``delta_k / d_k``: each link's unit direction (L, d), zero for a link of zero length; the
    gradient ``q_k`` over its norm in both formulations. Into ``out`` if given."""
    q: FloatArray = np.empty(delta.shape) if out is None else out
    positive = distances > 0
    if positive.all():  # (the usual case: a plain division, several times faster than a masked one)
        return np.divide(delta, distances[:, None], out=q)
    np.divide(delta, distances[:, None], out=q, where=positive[:, None])
    q[~positive] = 0.0
    return q


def link_gradient_norms(formulation: Formulation, distances: FloatArray) -> FloatArray:
    """``|q_k|``: 1 (norm; 0 for a link of zero length) or ``2 d_k`` (squared)."""
    if formulation is Formulation.NORM:
        return (distances > 0).astype(np.float64)
    return 2.0 * distances


def link_hessian_blocks(
    formulation: Formulation, delta: FloatArray, distances: FloatArray, lengths: FloatArray
) -> FloatArray:
    """``K_k`` (shape (L, d, d)) so that the Hessian of c_k is ``[[K, -K], [-K, K]]``."""
    m, d = delta.shape
    if formulation is Formulation.SQUARED:
        return np.broadcast_to(2.0 * np.eye(d), (m, d, d)).copy()
    capped = np.maximum(distances, MIN_RATIO * lengths)
    q = link_gradients(formulation, delta, distances)
    blocks = np.eye(d)[None, :, :] - q[:, :, None] * q[:, None, :]
    result: FloatArray = blocks / capped[:, None, None]
    return result


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
