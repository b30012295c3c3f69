"""Block-tridiagonal matrices of the checker's second-order test, and LAPACK's banded Cholesky.

The penalized Hessian of a chain couples each free node only with its neighbours, so with the
unknowns in interleaved order (x_0, y_0, x_1, y_1, ...) it is block tridiagonal with 2x2 blocks:
:class:`BlockTridiagonal` holds the diagonal blocks and the blocks coupling free node f with free
node f+1. As a band matrix it has 3 super-diagonals. A *linear solver* is any function
``factor(matrix) -> solve`` that raises ``numpy.linalg.LinAlgError`` when the matrix is not positive
definite: :func:`banded_cholesky` (LAPACK ``pbtrf`` through scipy, O(N)). The solver itself uses
the compiled core's linear algebra; this module is the checker's own, independent of it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from funicular.model import FloatArray

BANDWIDTH = 3


@dataclass(frozen=True)
class BlockTridiagonal:
    """A symmetric block-tridiagonal matrix with 2x2 blocks.

    ``diagonal`` (n, 2, 2): the symmetric diagonal blocks ``A[f, f]``; ``off_diagonal`` (n-1, 2, 2):
    the blocks ``A[f, f+1]`` (zero where free nodes f and f+1 are not linked).
    """

    diagonal: FloatArray
    off_diagonal: FloatArray

    def to_banded(self) -> FloatArray:
        """LAPACK upper band storage (4, 2n): ``ab[3 + i - j, j] = A[i, j]``."""
        n = self.diagonal.shape[0]
        ab = np.zeros((BANDWIDTH + 1, 2 * n))
        ab[3, 0::2] = self.diagonal[:, 0, 0]
        ab[3, 1::2] = self.diagonal[:, 1, 1]
        ab[2, 1::2] = self.diagonal[:, 0, 1]
        if n > 1:
            ab[1, 2::2] = self.off_diagonal[:, 0, 0]
            ab[2, 2::2] = self.off_diagonal[:, 1, 0]
            ab[0, 3::2] = self.off_diagonal[:, 0, 1]
            ab[1, 3::2] = self.off_diagonal[:, 1, 1]
        return ab

    def to_dense(self) -> FloatArray:
        """The dense matrix (for tests and small problems only)."""
        n = self.diagonal.shape[0]
        dense = np.zeros((2 * n, 2 * n))
        for f in range(n):
            dense[2 * f : 2 * f + 2, 2 * f : 2 * f + 2] = self.diagonal[f]
            if f + 1 < n:
                dense[2 * f : 2 * f + 2, 2 * f + 2 : 2 * f + 4] = self.off_diagonal[f]
                dense[2 * f + 2 : 2 * f + 4, 2 * f : 2 * f + 2] = self.off_diagonal[f].T
        return dense


def eigenvalue_floor(blocks: FloatArray) -> float:
    """The smallest eigenvalue of symmetric 2x2 blocks (k, 2, 2), or 0 if none is negative (or k = 0):
    for each block, half its trace minus the radius ``hypot((a - d) / 2, b)``."""
    half_trace = (blocks[:, 0, 0] + blocks[:, 1, 1]) / 2
    radius = np.hypot((blocks[:, 0, 0] - blocks[:, 1, 1]) / 2, blocks[:, 0, 1])
    return min(0.0, float(np.min(half_trace - radius, initial=0.0)))


Solve = Callable[[FloatArray], FloatArray]
LinearSolver = Callable[[BlockTridiagonal], Solve]


def banded_cholesky(matrix: BlockTridiagonal) -> Solve:
    """Factor with LAPACK ``pbtrf``, solve with ``pbtrs``; O(N) time and memory. (Called directly:
    scipy's ``cholesky_banded`` and ``cho_solve_banded`` run the same routines, and their argument
    checks cost a small chain's solve several times over.)"""
    from scipy.linalg import lapack  # (here: the checker's modules on the solve's path load no SciPy)

    factor, info = lapack.dpbtrf(matrix.to_banded(), lower=0)
    if info > 0:
        raise np.linalg.LinAlgError(f"{info}-th leading minor not positive definite")
    if info < 0:  # (an argument LAPACK refused: not expected from to_banded)
        raise ValueError(f"illegal value in {-info}-th argument of internal pbtrf")

    def solve(rhs: FloatArray) -> FloatArray:
        x, info = lapack.dpbtrs(factor, rhs, lower=0)
        if info != 0:
            raise ValueError(f"illegal value in {-info}-th argument of internal pbtrs")
        return np.asarray(x, dtype=np.float64)

    return solve
