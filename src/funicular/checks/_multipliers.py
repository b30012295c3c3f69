"""Multipliers recovered from the positions, and the range of each force the positions leave open."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.optimize import linprog, lsq_linear, nnls

from funicular.checks import _tolerances
from funicular.checks._tolerances import LP_SECONDS, MAX_RANGE_LPS, SHIFT, ZERO_FORCE_RTOL, ZERO_WEIGHT
from funicular.model import FloatArray, IntArray

if TYPE_CHECKING:
    from funicular.checks._tolerances import Matrix


# ----------------------------------------------------------------- the multiplier set {t + W c >= 0}
@dataclass(frozen=True)
class _Directions:
    """The rows of the null basis W grouped by direction: ``t + W c >= 0`` iff ``U c >= lower``.

    Rows of W that are zero belong to determined forces; the others have ``W_k = |W_k| U_j``
    for their direction j (``group[k]``, -1 for determined). Merging parallel rows keeps the LPs
    small: a taut segment's dependency gives every link in it the same direction.
    """

    units: FloatArray  # (d, r)
    lower: FloatArray  # (d,)
    group: IntArray  # (m,)
    norm: FloatArray  # (m,)


def _directions(null: FloatArray, t: FloatArray) -> _Directions:
    norm = np.linalg.norm(null, axis=1)
    varying = np.flatnonzero(norm > ZERO_WEIGHT)
    unit = null[varying] / norm[varying, None]
    units, inverse = np.unique(np.round(unit, 9), axis=0, return_inverse=True)
    lower = np.full(units.shape[0], -np.inf)
    np.maximum.at(lower, inverse.ravel(), -t[varying] / norm[varying])
    group = np.full(null.shape[0], -1, dtype=np.intp)
    group[varying] = inverse.ravel()
    return _Directions(units, lower, group, norm)


# ----------------------------------------------------------------- multipliers
def _least_squares(rows: Matrix, rhs: FloatArray, null: FloatArray) -> FloatArray:
    """Least-squares ``t`` of ``A^T t = rhs`` orthogonal to the null vectors."""
    m, n = rows.shape
    if n <= _tolerances.DENSE_LIMIT:
        return np.asarray(np.linalg.lstsq(rows.toarray().T, rhs, rcond=None)[0])
    factor = sparse_linalg.splu((rows @ rows.T + SHIFT * sparse.identity(m)).tocsc())
    basis = np.linalg.qr(null)[0] if null.shape[1] else null

    def solve(vector: FloatArray) -> FloatArray:
        t = np.asarray(factor.solve(rows @ vector))
        return np.asarray(t - basis @ (basis.T @ t), dtype=np.float64)

    t = solve(rhs)
    return t + solve(rhs - rows.T @ t)  # one step of iterative refinement


def _least_total_force(t: FloatArray, null: FloatArray, tiny: float) -> FloatArray | None:
    """The element of ``{t + W c >= 0}`` with the least total force; None if the set is empty."""
    directions = _directions(null, t)
    if np.any(t[directions.group < 0] < -tiny):  # a determined force is negative
        return None
    if null.shape[1] == 0:
        return t
    result = linprog(null.sum(axis=0), A_ub=-directions.units, b_ub=-directions.lower, bounds=(None, None))
    return t + null @ np.asarray(result.x) if result.status == 0 else None


def _recover(rows: Matrix, rhs: FloatArray, null: FloatArray | None, tiny: float) -> FloatArray:
    """Nonnegative forces ``t`` that best satisfy stationarity ``A^T t = rhs``: the least total force
    among the exact ones; where none is exact, a nonnegative least-squares fit (also where the
    rows' dependencies ``null`` are not known: None)."""
    if rows.shape[0] == 0:
        return np.zeros(0)
    if null is not None:
        exact = _least_total_force(_least_squares(rows, rhs, null), null, tiny)
        if exact is not None:
            return np.maximum(exact, 0.0)
    if rows.shape[1] <= _tolerances.DENSE_LIMIT:
        return np.asarray(nnls(rows.toarray().T, rhs)[0])
    return np.asarray(lsq_linear(rows.T.tocsr(), rhs, bounds=(0.0, np.inf), method="trf").x)


def _ranges(t: FloatArray, null: FloatArray, scale: float) -> tuple[FloatArray, FloatArray, IntArray] | None:
    """Every force's smallest and largest value over the multiplier set ``{t + W c >= 0}`` (a
    determined force: its own value), and the forces that vary. A varying force k is
    ``t_k + |W_k| (u_j . c)`` with u_j its direction: two LPs per direction. A bound within
    ZERO_FORCE_RTOL of zero, relative to ``scale`` or the largest force, is 0. None where not
    computed: more than MAX_RANGE_LPS directions, linear programs that take more than LP_SECONDS
    in all, or an empty set (forces that no self-stress makes nonnegative)."""
    zero = ZERO_FORCE_RTOL * max(scale, float(np.max(np.abs(t), initial=0.0)))

    def snapped(values: FloatArray) -> FloatArray:
        return np.where(np.abs(values) <= zero, 0.0, values)  # (a negative zero too)

    if null.shape[1] == 0:
        return snapped(t), snapped(t), np.zeros(0, dtype=np.intp)
    # A self-stress's entry at rounding level (relative to its largest) is zero: a force that no
    # self-stress moves is determined, and its programs would only weigh rounding.
    null = np.where(np.abs(null) > ZERO_WEIGHT * np.abs(null).max(axis=0, initial=0.0), null, 0.0)
    directions = _directions(null, t)
    if directions.units.shape[0] > MAX_RANGE_LPS:
        return None
    deadline = time.monotonic() + LP_SECONDS
    ends = np.empty((directions.units.shape[0], 2))
    for j, unit in enumerate(directions.units):
        for end, sign in ((0, 1.0), (1, -1.0)):
            left = deadline - time.monotonic()
            if left <= 0.0:
                return None
            result = linprog(
                sign * unit,
                A_ub=-directions.units,
                b_ub=-directions.lower,
                bounds=(None, None),
                method="highs",
                options={"time_limit": left},
            )
            if result.status == 3:  # unbounded
                ends[j, end] = -sign * np.inf
            elif result.status == 0:
                ends[j, end] = float(unit @ result.x)
            else:  # (1: out of time, 2: an empty set, 4: numerical trouble)
                return None
    lower, upper = t.copy(), t.copy()
    varying = np.flatnonzero(directions.group >= 0)
    lower[varying] += directions.norm[varying] * ends[directions.group[varying], 0]
    upper[varying] += directions.norm[varying] * ends[directions.group[varying], 1]
    return snapped(lower), snapped(upper), varying
