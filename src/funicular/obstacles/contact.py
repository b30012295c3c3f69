"""Links against obstacles: ``contact = "links"`` and how deep a link reaches.

For ``contact = "links"`` the convex built-ins in the plane (disk, ellipse, box, half-plane) give
phi's largest value along a segment, its maximiser and derivatives (:func:`segment_max`), and the
link-contact constraint built on it (:func:`link_contact`, with :func:`link_contact_ends`): the one
place these live. Every built-in shape also tells how deep a segment reaches into it
(:func:`segment_depth`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from funicular._types import FloatArray
from funicular.errors import ScenarioError
from funicular.obstacles.base import Obstacle, depth
from funicular.obstacles.shapes import Box, Cuboid, Disk, Ellipse, Ellipsoid, HalfPlane, HalfSpace, Sphere

# ----------------------------------------------------------------- phi's largest value along a segment
SEGMENT_SHAPES = (Disk, Ellipse, Box, HalfPlane)
SEGMENT_BISECTIONS = 60  # a box's maximiser to 2^-60 of the segment
_TIE = 1e-12  # |slope| below this (relative to |grad phi| |b - a|) is a flat segment: no preferred end


class SegmentMax(NamedTuple):
    """The largest phi along segments ``[a, b]``: ``psi = max_{t in [0,1]} phi((1-t) a + t b)``.

    psi (k,); t (k,) the maximiser; gradient (k, 2) grad phi at ``p* = (1-t) a + t b``, so that
    ``d psi/da = (1-t) gradient`` and ``d psi/db = t gradient`` (envelope theorem); hessian
    (k, 4, 4) the exact Hessian of psi in ``(a_x, a_y, b_x, b_y)`` where the maximiser is unique.
    """

    psi: FloatArray
    t: FloatArray
    gradient: FloatArray
    hessian: FloatArray


def has_segment_max(obstacle: Obstacle) -> bool:
    """Whether :func:`segment_max` works for this obstacle: the convex built-in shapes."""
    return isinstance(obstacle, SEGMENT_SHAPES)


def _derivative_argmax(obstacle: Obstacle, a: FloatArray, d: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """Maximiser of the concave ``phi(a + t d)`` on [0, 1] by bisection on the sign of its slope
    (a box's phi is only C1, so no Newton): monotone, so it cannot miss or leave the interval.
    Also whether it is strictly interior (the slope changes sign along the segment)."""

    def slope(t: FloatArray) -> FloatArray:
        _, gradient, _ = obstacle.evaluate(a + t[:, None] * d)
        result: FloatArray = np.einsum("ij,ij->i", gradient, d)
        return result

    low, high = np.zeros(a.shape[0]), np.ones(a.shape[0])
    rising_at_end = slope(high) >= 0.0
    falling_at_start = slope(low) <= 0.0
    for _ in range(SEGMENT_BISECTIONS):
        middle = 0.5 * (low + high)
        up = slope(middle) > 0.0
        low, high = np.where(up, middle, low), np.where(up, high, middle)
    t = np.where(falling_at_start, 0.0, np.where(rising_at_end, 1.0, 0.5 * (low + high)))
    return t, ~falling_at_start & ~rising_at_end


def _quadratic_argmax(obstacle: Obstacle, a: FloatArray, d: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """Maximiser of ``phi(a + t d)`` on [0, 1] when phi is quadratic (disk, ellipse, half-plane):
    ``phi(a) + s t + c t^2 / 2`` with slope ``s = grad phi(a).d`` and curvature ``c = d.H d <= 0``.
    Also whether it is strictly interior."""
    _, gradient, hessian = obstacle.evaluate(a)
    s = np.einsum("ij,ij->i", gradient, d)
    c = np.einsum("ij,ijk,ik->i", d, hessian, d)
    flat = np.abs(s) <= _TIE * np.hypot(*gradient.T) * np.hypot(*d.T)
    end = np.where(flat, 0.5, np.where(s > 0.0, 1.0, 0.0))  # linear along the segment: the higher end
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = -s / c
    interior = (c < 0.0) & (vertex > 0.0) & (vertex < 1.0)
    return np.where(c < 0.0, np.clip(vertex, 0.0, 1.0), end), interior


def _argmax(obstacle: Obstacle, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray]:
    """``(a, b, t, interior)``: the segments as (k, 2) arrays, phi's maximiser along them and
    whether it is strictly interior."""
    if not has_segment_max(obstacle):
        raise ScenarioError(
            f"obstacle {obstacle.name!r}: keeping whole links out needs a convex built-in shape "
            "(disk, ellipse, box, halfplane)."
        )
    a, b = np.asarray(a, dtype=np.float64).reshape(-1, 2), np.asarray(b, dtype=np.float64).reshape(-1, 2)
    argmax = _derivative_argmax if isinstance(obstacle, Box) else _quadratic_argmax
    t, interior = argmax(obstacle, a, b - a)
    return a, b, t, interior


def _at(obstacle: Obstacle, a: FloatArray, b: FloatArray, t: FloatArray, interior: np.ndarray) -> SegmentMax:
    """phi at ``p* = (1-t) a + t b`` with the derivatives of ``psi(a, b) = phi(p*)``: t moves with
    (a, b) where it is an interior maximiser (``interior``), and is fixed elsewhere."""
    d = b - a
    psi, g, h = obstacle.evaluate(a + t[:, None] * d)
    w = np.stack((1.0 - t, t), axis=1)
    hessian = np.einsum("nr,nc,nij->nricj", w, w, h).reshape(-1, 4, 4)
    hd = np.einsum("kij,kj->ki", h, d)
    curvature = np.einsum("ki,ki->k", d, hd)
    moving = interior & (curvature < 0.0)
    if np.any(moving):
        v = np.concatenate(((1.0 - t)[:, None] * hd - g, t[:, None] * hd + g), axis=1)[moving]
        hessian[moving] += v[:, :, None] * v[:, None, :] / -curvature[moving, None, None]
    return SegmentMax(psi, t, g, hessian)


def segment_max(obstacle: Obstacle, a: FloatArray, b: FloatArray) -> SegmentMax:
    """psi, the maximiser and the derivatives of phi's maximum over each segment ``[a_k, b_k]``.

    Only for :func:`has_segment_max` shapes, whose phi is concave, so phi along a segment has one
    maximum. Where it is attained on a whole interval (a segment along a straight edge or a
    half-plane's boundary) the midpoint or an end of that interval is taken: psi is exact, its
    gradient one of the subgradients. The Hessian is ``w w^T (x) H`` (w = (1-t, t), H = Hess phi at
    ``p*``) plus, for an interior maximiser, the term from the maximiser moving,
    ``v v^T / (-d.H d)`` with ``v = ((1-t) H d - g, t H d + g)``, ``d = b - a``, ``g = grad phi(p*)``.
    """
    a, b, t, interior = _argmax(obstacle, a, b)
    return _at(obstacle, a, b, t, interior)


# ----------------------------------------------------------------- the link-contact constraint
def link_contact_ends(is_support: NDArray[np.bool_]) -> tuple[FloatArray, NDArray[np.bool_]]:
    """For every link, ``(end, pinned)``: ``end`` (0: p_k, 1: p_{k+1}) is the end whose phi is the
    link's contact row when phi has no interior maximum along it (see :func:`link_contact`), and
    ``pinned`` says whether the link has a support end. ``end`` is the free end of a link next to a
    support, else the end away from the first support: every free node is ``end`` of some link."""
    first = int(np.argmax(is_support))
    end = np.where(np.arange(is_support.size - 1) < first, 0.0, 1.0)
    end = np.where(is_support[:-1], 1.0, np.where(is_support[1:], 0.0, end))
    return end, is_support[:-1] | is_support[1:]


def link_contact(
    obstacle: Obstacle, a: FloatArray, b: FloatArray, end: FloatArray, pinned: NDArray[np.bool_]
) -> SegmentMax:
    """The contact row of ``contact = "links"`` for links ``[a_k, b_k]``: ``psi = phi(p*)`` with its
    derivatives, ``p* = (1-t) a + t b``; ``end`` and ``pinned`` from :func:`link_contact_ends`.

    A disk's or ellipse's phi is strictly concave along a link, so psi = :func:`segment_max` is
    C1. A half-plane's or a box side's phi is affine along a link, and its maximum jumps from
    one end to the other as a link lying along the boundary tilts: psi is not differentiable
    there and Newton's method stalls. For those shapes, and for links with a support end (a
    contact at the support is the support's, as in ``contact = "nodes"``, so a support on the
    surface does not pin the row at 0), the row is phi at the maximiser only where it is strictly
    inside the link, and phi at ``end`` otherwise. Every free node is some link's ``end``, so the
    rows together still keep every link out, and at a solution a row with ``nu > 0`` has psi = 0,
    so p* is still where phi is largest along the link.
    """
    a, b, t, interior = _argmax(obstacle, a, b)
    ends_only = np.asarray(pinned) | (not isinstance(obstacle, (Disk, Ellipse)))
    t = np.where(interior | ~ends_only, t, np.asarray(end, dtype=np.float64))
    return _at(obstacle, a, b, t, interior)


# ----------------------------------------------------------------- how deep a segment reaches
DEPTH_SHAPES = (Disk, Sphere, HalfPlane, HalfSpace, Ellipse, Ellipsoid, Box, Cuboid)
SEGMENT_DEPTH_STEPS = 60  # most steps of the search along a segment (each at least halves its bracket)
DEPTH_BRACKET = 1e-13  # a bracket this narrow (a fraction of the segment) holds the deepest point
DEPTH_SLOPE = 1e-10  # a slope this small (relative to the segment's length) is the deepest point's


def has_segment_depth(obstacle: Obstacle) -> bool:
    """Whether :func:`segment_depth` knows how deep a segment reaches into ``obstacle``: the
    built-in shapes (exactly those types: a subclass may change ``evaluate``)."""
    return type(obstacle) in DEPTH_SHAPES


def segment_depth(obstacle: Obstacle, a: FloatArray, b: FloatArray) -> FloatArray:
    """How deep each segment ``[a_k, b_k]`` (k, d) reaches into a built-in obstacle
    (:func:`has_segment_depth`): the largest distance from a point of the segment to the
    obstacle's boundary, over its points inside; 0 for a segment that stays out.

    A disk's or a sphere's is the depth of the segment's point nearest the centre, a half-plane's
    or a half-space's that of its deeper end. The others' depth (minus the signed distance to a
    convex set) is concave along the segment, and :func:`_concave_peak` finds its largest value.
    """
    if not has_segment_depth(obstacle):
        raise ScenarioError(f"obstacle {obstacle.name!r}: how deep a link reaches is known for built-in shapes only.")
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if isinstance(obstacle, Disk | Sphere):
        d = b - a
        with np.errstate(divide="ignore", invalid="ignore"):  # (a segment of length 0: its end)
            t = np.sum((np.asarray(obstacle.center) - a) * d, axis=1) / np.sum(d * d, axis=1)
        deepest = depth(obstacle, a + np.clip(np.nan_to_num(t), 0.0, 1.0)[:, None] * d)
    elif isinstance(obstacle, HalfPlane | HalfSpace):
        deepest = np.maximum(depth(obstacle, a), depth(obstacle, b))
    elif isinstance(obstacle, Ellipse | Ellipsoid):
        deepest = _concave_peak(obstacle.depth_and_gradient, a, b)
    else:  # a box or a cuboid: phi is the depth itself
        deepest = _concave_peak(lambda points: obstacle.evaluate(points)[:2], a, b)
    result: FloatArray = np.maximum(deepest, 0.0)
    return result


def _concave_peak(
    depth_and_gradient: Callable[[FloatArray], tuple[FloatArray, FloatArray]], a: FloatArray, b: FloatArray
) -> FloatArray:
    """The largest value along each segment ``[a_k, b_k]`` of a depth concave along it, given its
    values and gradients at points.

    Its slope along a segment decreases: the largest value is at an end where the slope there
    does not point into the segment, else where the slope changes sign. A bracket of that point
    narrows at each step to three points: the secant's root of the slope (fast where the depth is
    smooth), where the tangents at the bracket's ends meet (fast where the slope jumps: the ridge
    of an ellipse's distance, a box's inner diagonals) and the midpoint (at least a halving). The
    largest depth evaluated is returned: exact at an end, within DEPTH_BRACKET of the segment's
    length times the slope at a ridge, and within the square of the slope left (DEPTH_SLOPE) at a
    smooth maximum."""
    d = b - a
    k = a.shape[0]
    values, gradients = depth_and_gradient(np.concatenate((a, b)))
    slopes = np.einsum("ij,ij->i", gradients, np.concatenate((d, d)))
    best = np.maximum(values[:k], values[k:])
    rows = np.flatnonzero((slopes[:k] > 0.0) & (slopes[k:] < 0.0))  # deepest strictly inside
    low, high = np.zeros(rows.size), np.ones(rows.size)
    rise, fall = slopes[:k][rows], slopes[k:][rows]
    at_low, at_high = values[:k][rows], values[k:][rows]
    for _ in range(SEGMENT_DEPTH_STEPS):
        if not rows.size:
            break
        n = rows.size
        steep = rise - fall  # > 0
        secant = low + rise * (high - low) / steep
        meet = (at_high - at_low + rise * low - fall * high) / steep
        at = np.clip(np.concatenate((secant, meet, 0.5 * (low + high))), np.tile(low, 3), np.tile(high, 3))
        thrice = np.tile(rows, 3)
        values, gradients = depth_and_gradient(a[thrice] + at[:, None] * d[thrice])
        slope = np.einsum("ij,ij->i", gradients, d[thrice])
        best[rows] = np.maximum(best[rows], values.reshape(3, n).max(axis=0))
        for t, slope_t, value_t in zip(at.reshape(3, n), slope.reshape(3, n), values.reshape(3, n), strict=True):
            up, down = (slope_t > 0.0) & (t > low), (slope_t < 0.0) & (t < high)
            low, rise, at_low = np.where(up, t, low), np.where(up, slope_t, rise), np.where(up, value_t, at_low)
            high, fall = np.where(down, t, high), np.where(down, slope_t, fall)
            at_high = np.where(down, value_t, at_high)
        flat = np.abs(slope).reshape(3, n).min(axis=0) <= DEPTH_SLOPE * np.linalg.norm(d[rows], axis=1)
        going = ~flat & (high - low > DEPTH_BRACKET)
        rows, low, high = rows[going], low[going], high[going]
        rise, fall, at_low, at_high = rise[going], fall[going], at_low[going], at_high[going]
    return best
