"""Multipliers recovered from the positions, and the range of each force the positions leave open."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.optimize import linprog, lsq_linear, nnls

from funicular.checks import _tolerances
from funicular.checks._licq import _directions
from funicular.checks._report import MultiplierRange
from funicular.checks._tolerances import MAX_RANGE_LPS, SHIFT, Matrix
from funicular.model import FloatArray


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


def _recover(rows: Matrix, rhs: FloatArray, null: FloatArray, tiny: float) -> FloatArray:
    """Nonnegative forces ``t`` that best satisfy stationarity ``A^T t = rhs``."""
    if rows.shape[0] == 0:
        return np.zeros(0)
    exact = _least_total_force(_least_squares(rows, rhs, null), null, tiny)
    if exact is not None:
        return np.maximum(exact, 0.0)
    if rows.shape[1] <= _tolerances.DENSE_LIMIT:
        return np.asarray(nnls(rows.toarray().T, rhs)[0])
    return np.asarray(lsq_linear(rows.T.tocsr(), rhs, bounds=(0.0, np.inf), method="trf").x)


def _ranges(names: list[str], t: FloatArray, null: FloatArray) -> tuple[MultiplierRange, ...] | None:
    """Range of every force that is not determined, over the multiplier set ``{t + W c >= 0}``.

    Force k is ``t_k + |W_k| (u_j . c)`` with u_j its direction: two LPs per direction.
    """
    directions = _directions(null, t)
    if directions.units.shape[0] > MAX_RANGE_LPS:
        return None
    ends = np.empty((directions.units.shape[0], 2))
    for j, unit in enumerate(directions.units):
        for end, sign in ((0, 1.0), (1, -1.0)):
            result = linprog(sign * unit, A_ub=-directions.units, b_ub=-directions.lower, bounds=(None, None))
            ends[j, end] = float(unit @ result.x) if result.status == 0 else -sign * np.inf
    varying = np.flatnonzero(directions.group >= 0)
    lower = t[varying] + directions.norm[varying] * ends[directions.group[varying], 0]
    upper = t[varying] + directions.norm[varying] * ends[directions.group[varying], 1]
    return tuple(
        MultiplierRange(names[k], float(lo), float(hi)) for k, lo, hi in zip(varying, lower, upper, strict=True)
    )
