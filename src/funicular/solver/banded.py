"""Block-tridiagonal Newton systems in LAPACK banded storage.

The condensed Newton matrix of the chain couples each free node only with its neighbours,
so with the unknowns in interleaved order (x_0, y_0, x_1, y_1, ...) it is block tridiagonal
with 2x2 blocks, i.e. banded with 3 super-diagonals. We store its upper triangle in LAPACK's
symmetric band format (``ab[3 + i - j, j] = A[i, j]``) and factorize it in O(N).

A *linear solver* is any function ``factor(ab) -> solve`` that raises
``numpy.linalg.LinAlgError`` when the matrix is not positive definite; the driver uses that to
trigger its inertia correction. Pass your own to :func:`funicular.solver.solve` to compare paths.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded

from funicular.model import FloatArray

BANDWIDTH = 3
Solve = Callable[[FloatArray], FloatArray]
LinearSolver = Callable[[FloatArray], Solve]


def to_banded(diagonal: FloatArray, off_diagonal: FloatArray) -> FloatArray:
    """Upper band storage (4, 2n) of the symmetric block-tridiagonal matrix.

    ``diagonal`` (n, 2, 2) holds the symmetric diagonal blocks, ``off_diagonal`` (n-1, 2, 2) the
    blocks ``A[f, f+1]`` coupling free node f with free node f+1 (zero where they are not linked).
    """
    n = diagonal.shape[0]
    ab = np.zeros((BANDWIDTH + 1, 2 * n))
    ab[3, 0::2] = diagonal[:, 0, 0]
    ab[3, 1::2] = diagonal[:, 1, 1]
    ab[2, 1::2] = diagonal[:, 0, 1]
    if n > 1:
        ab[1, 2::2] = off_diagonal[:, 0, 0]
        ab[2, 2::2] = off_diagonal[:, 1, 0]
        ab[0, 3::2] = off_diagonal[:, 0, 1]
        ab[1, 3::2] = off_diagonal[:, 1, 1]
    return ab


def banded_to_dense(ab: FloatArray) -> FloatArray:
    """Dense symmetric matrix of an upper band storage (for tests and small problems only)."""
    u, size = ab.shape[0] - 1, ab.shape[1]
    dense = np.zeros((size, size))
    for offset in range(u + 1):
        idx = np.arange(offset, size)
        dense[idx - offset, idx] = ab[u - offset, offset:]
        dense[idx, idx - offset] = ab[u - offset, offset:]
    return dense


def banded_cholesky(ab: FloatArray) -> Solve:
    """Factor with LAPACK ``pbtrf`` (scipy ``cholesky_banded``); O(N) time and memory."""
    factor = cholesky_banded(ab, lower=False, check_finite=False)

    def solve(rhs: FloatArray) -> FloatArray:
        return cho_solve_banded((factor, False), rhs, check_finite=False)

    return solve


def dense_cholesky(ab: FloatArray) -> Solve:
    """The same system solved densely with numpy: a reference path for tests (O(N^3))."""
    dense = banded_to_dense(ab)
    lower = np.linalg.cholesky(dense)

    def solve(rhs: FloatArray) -> FloatArray:
        return np.linalg.solve(lower.T, np.linalg.solve(lower, rhs))

    return solve
