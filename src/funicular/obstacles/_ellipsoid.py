"""The exact distance from points to an ellipse's or ellipsoid's boundary, and its gradient:
the ``depth`` of :class:`~funicular.obstacles.Ellipse` and :class:`~funicular.obstacles.Ellipsoid`."""

from __future__ import annotations

import numpy as np

from funicular._types import FloatArray

ELLIPSOID_STEPS = 100  # most root-finding steps per point: a handful usually (Newton's and the secant's)
_EPS = float(np.finfo(np.float64).eps)


def _ellipsoid_depth(local: FloatArray, axes: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Signed distance from points (k, d) in an ellipse's or ellipsoid's own axes to its boundary,
    positive inside, and its gradient (k, d) in those axes: the unit inward normal at the nearest
    boundary point (of the two nearest to a point inside on the plane of the longer axes, where
    the distance has a ridge, the one on the positive side).

    The nearest boundary point is ``x_i = e_i^2 y_i / (t + e_i^2)`` (y = |local|, e the semi-axes)
    with t the root above ``-e_min^2`` of ``F(t) = sum_i (e_i y_i / (t + e_i^2))^2 - 1``, convex
    and decreasing there (D. Eberly, "Distance from a point to an ellipse, an ellipsoid, or a
    hyperellipsoid"). A bracket of the root narrows from both sides: Newton's step from its left
    end stays left of the root and the secant of the bracket right of it (F is convex); their
    midpoint and the bracket's own (at least a halving) keep a step from stalling where rounding
    or a pole of F slows those two. The axes as long as
    the smallest count together (their coordinates' norm), and the nearest point's component along
    them comes from x lying on the boundary: near the plane of the longer axes t nears ``-e_min^2``,
    where ``e_min^2 y / (t + e_min^2)`` would be 0 / 0 (and is, on that plane, for a point inside).
    """
    y = np.abs(np.asarray(local, dtype=np.float64))
    smallest = float(axes.min())
    least = axes == smallest
    rho = np.sqrt(np.sum(y[:, least] ** 2, axis=1))  # along the smallest axes
    others, longer = y[:, ~least], axes[~least]
    longer2, least2 = longer**2, smallest**2

    def excess(t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """F and F' at each point's t (any shape (k, ...))."""
        u = t[..., None] + longer2
        ratio = longer * others.reshape(others.shape[:1] + (1,) * (t.ndim - 1) + others.shape[1:]) / u
        scale = rho.reshape(rho.shape + (1,) * (t.ndim - 1))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # (rho = 0 at t = -e_min^2: no term)
            own = np.where(scale > 0.0, smallest * scale / (t + least2), 0.0)
            own_slope = np.where(scale > 0.0, own**2 / (t + least2), 0.0)
            value = np.sum(ratio**2, axis=-1) + own**2 - 1.0
            return value, -2.0 * (np.sum(ratio**2 / u, axis=-1) + own_slope)

    # F(low) >= 0 (the smallest axes' term alone is 1 there), F(high) <= 0 (every term is below
    # (e_i y_i / t)^2, and they sum to at most 1). Where F(low) <= 0 already (a point inside, on
    # the plane of the longer axes), the nearest point lies off that plane, with t = -e_min^2.
    low = -least2 + smallest * rho
    high = np.maximum(np.sqrt(np.sum((axes * y) ** 2, axis=1)), low)
    # Any Newton step lands left of the root (F is convex): one from t = 0, right of it for a point
    # inside, starts a point near the boundary next to the root.
    zero = np.zeros_like(low)
    f_zero, s_zero = excess(zero)
    with np.errstate(divide="ignore", invalid="ignore"):  # (the centre: F'(0) = 0)
        start = zero - f_zero / s_zero
    low = np.where(np.isfinite(start), np.clip(start, low, high), low)
    high = np.where(f_zero <= 0.0, np.clip(zero, low, high), high)
    f_low, s_low = excess(low)
    f_high = excess(high)[0]
    high = np.where(f_low <= 0.0, low, high)
    for _ in range(ELLIPSOID_STEPS):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            newton = low - f_low / s_low
            secant = high - f_high * (high - low) / (f_high - f_low)
        newton = np.where(np.isfinite(newton), np.clip(newton, low, high), low)
        secant = np.where(np.isfinite(secant), np.clip(secant, newton, high), high)
        middles = (0.5 * (newton + secant), 0.5 * (low + high))
        points = np.sort(np.stack((low, newton, *middles, secant, high), axis=1), axis=1)
        values, slopes = excess(points)
        values[:, 0], values[:, -1] = np.maximum(f_low, 0.0), np.minimum(f_high, 0.0)  # (as bracketed)
        rows = np.arange(low.size)
        left = np.maximum(np.count_nonzero(values >= 0.0, axis=1) - 1, 0)  # F decreases along the row
        right = np.minimum(np.count_nonzero(values > 0.0, axis=1), points.shape[1] - 1)
        low, f_low, s_low = points[rows, left], values[rows, left], slopes[rows, left]
        high, f_high = points[rows, right], values[rows, right]
        # Done where the bracket has closed to rounding (of t, or of the distance it gives, |t x / e^2|
        # with |x / e^2| about 1 / e_min) or F at its left end is rounding (its terms sum to 1).
        if np.all((high - low <= 16.0 * _EPS * (np.abs(low) + least2)) | (f_low <= 16.0 * _EPS)):
            break
    nearest = np.empty_like(y)
    nearest[:, ~least] = longer2 * others / (low[:, None] + longer2)
    along = smallest * np.sqrt(np.maximum(1.0 - np.sum((nearest[:, ~least] / longer) ** 2, axis=1), 0.0))
    distance = np.sqrt(np.sum((nearest[:, ~least] - others) ** 2, axis=1) + (along - rho) ** 2)
    inside = np.sum((y / axes) ** 2, axis=1) <= 1.0
    # Along the smallest axes the nearest point lies in the point's direction (the first axis on the plane).
    first = np.eye(int(least.sum()))[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        direction = np.where(rho[:, None] > 0.0, y[:, least] / rho[:, None], first)
    nearest[:, least] = along[:, None] * direction
    normal = np.where(local < 0.0, -1.0, 1.0) * nearest / axes**2  # outward, at the nearest point
    gradient = -normal / np.linalg.norm(normal, axis=1, keepdims=True)
    return np.where(inside, distance, -distance), gradient
