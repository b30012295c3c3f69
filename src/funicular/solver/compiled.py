"""Compiled (numba) kernels for the O(N) linear algebra, with LAPACK as the fallback.

The Newton matrix is block tridiagonal with 2x2 blocks. LAPACK's ``pbtrf`` treats it as a
general band of width 3 and pays a per-column overhead that dominates at such a small width
(0.3 s for N = 10^6 nodes). :func:`block_cholesky` factors it block by block as ``L D L^T``
with unit lower block-bidiagonal L and block-diagonal D,

    S_0 = D_0,   C_f = S_f^{-1} B_f,   S_{f+1} = D_{f+1} - B_f^T C_f,

keeping the explicit 2x2 inverses S_f^{-1}: no square roots, and no division on the solve's
critical path, which runs node after node (a Cholesky's two divisions per node made the solve
three times slower). Every 2x2 operation is written out, compiled by numba and streamed through
memory once. A pivot block that is not positive definite (``S_00 <= 0`` or ``det S <= 0``) is
exactly where a Cholesky factorization fails, so the driver's inertia correction works the same.

numba is optional (the ``fast`` extra). Without it :func:`default_linear_solver` is LAPACK's
:func:`funicular.solver.banded.banded_cholesky`; the two agree to rounding, which the tests
check on every built-in scenario.
"""

from __future__ import annotations

import functools
import importlib.util
from collections.abc import Callable
from typing import Any

import numpy as np

from funicular.model import FloatArray
from funicular.solver.banded import BlockTridiagonal, LinearSolver, Solve, banded_cholesky

HAVE_NUMBA = importlib.util.find_spec("numba") is not None


def _factor_kernel(diagonal: Any, off_diagonal: Any, inverse: Any, coupling: Any) -> int:  # pragma: no cover
    """``inverse[f] = (a, b, c)``, the symmetric S_f^{-1} = [[a, b], [b, c]], and ``coupling[f] = C_f``;
    returns -1, or the first free node whose pivot block S_f is not positive definite."""
    s00, s01, s11 = diagonal[0, 0, 0], diagonal[0, 0, 1], diagonal[0, 1, 1]
    n = diagonal.shape[0]
    for f in range(n):
        det = s00 * s11 - s01 * s01
        if not (s00 > 0.0 and det > 0.0):
            return f
        scale = 1.0 / det
        a, b, c = s11 * scale, -s01 * scale, s00 * scale
        inverse[f, 0], inverse[f, 1], inverse[f, 2] = a, b, c
        if f + 1 == n:
            break
        # C_f = S_f^{-1} B_f, then S_{f+1} = D_{f+1} - B_f^T C_f
        b00, b01 = off_diagonal[f, 0, 0], off_diagonal[f, 0, 1]
        b10, b11 = off_diagonal[f, 1, 0], off_diagonal[f, 1, 1]
        c00, c01 = a * b00 + b * b10, a * b01 + b * b11
        c10, c11 = b * b00 + c * b10, b * b01 + c * b11
        coupling[f, 0, 0], coupling[f, 0, 1], coupling[f, 1, 0], coupling[f, 1, 1] = c00, c01, c10, c11
        s00 = diagonal[f + 1, 0, 0] - (b00 * c00 + b10 * c10)
        s01 = diagonal[f + 1, 0, 1] - (b00 * c01 + b10 * c11)
        s11 = diagonal[f + 1, 1, 1] - (b01 * c01 + b11 * c11)
    return -1


def _solve_kernel(inverse: Any, coupling: Any, rhs: Any, x: Any) -> None:  # pragma: no cover
    """``L D L^T x = rhs``: forward ``u_f = b_f - C_{f-1}^T u_{f-1}``, ``v_f = S_f^{-1} u_f``, then
    backward ``x_f = v_f - C_f x_{f+1}``."""
    n = inverse.shape[0]
    u0, u1 = 0.0, 0.0
    for f in range(n):
        r0, r1 = rhs[2 * f], rhs[2 * f + 1]
        if f > 0:
            r0 -= coupling[f - 1, 0, 0] * u0 + coupling[f - 1, 1, 0] * u1
            r1 -= coupling[f - 1, 0, 1] * u0 + coupling[f - 1, 1, 1] * u1
        u0, u1 = r0, r1
        x[2 * f] = inverse[f, 0] * r0 + inverse[f, 1] * r1
        x[2 * f + 1] = inverse[f, 1] * r0 + inverse[f, 2] * r1
    for f in range(n - 2, -1, -1):
        x0, x1 = x[2 * f + 2], x[2 * f + 3]
        x[2 * f] -= coupling[f, 0, 0] * x0 + coupling[f, 0, 1] * x1
        x[2 * f + 1] -= coupling[f, 1, 0] * x0 + coupling[f, 1, 1] * x1


@functools.cache
def jit(kernel: Callable[..., Any]) -> Callable[..., Any]:
    """``kernel`` compiled by numba on first use (importing numba costs half a second; the command
    line should not pay it for a command that never solves), cached on disk. Without numba the
    plain Python function: correct, but only fit for small systems (tests)."""
    if not HAVE_NUMBA:
        return kernel
    import numba

    return numba.njit(cache=True, nogil=True)(kernel)  # type: ignore[no-any-return]


def block_cholesky(matrix: BlockTridiagonal) -> Solve:
    """Factor with the 2x2 block ``L D L^T`` (a block Cholesky without square roots); raises ``LinAlgError`` if the matrix is not positive
    definite (the driver's inertia correction relies on that), like LAPACK."""
    factor_kernel, solve_kernel = jit(_factor_kernel), jit(_solve_kernel)
    n = matrix.diagonal.shape[0]
    inverse, coupling = np.empty((n, 3)), np.zeros((max(n - 1, 0), 2, 2))
    failed = factor_kernel(
        np.ascontiguousarray(matrix.diagonal), np.ascontiguousarray(matrix.off_diagonal), inverse, coupling
    )
    if failed >= 0:
        raise np.linalg.LinAlgError(f"the Newton matrix is not positive definite (free node {failed})")

    def solve(rhs: FloatArray) -> FloatArray:
        x = np.empty(2 * n)
        solve_kernel(inverse, coupling, np.ascontiguousarray(rhs, dtype=np.float64), x)
        return x

    return solve


def default_linear_solver() -> LinearSolver:
    """The compiled block Cholesky when numba is installed, LAPACK's banded Cholesky otherwise."""
    return block_cholesky if HAVE_NUMBA else banded_cholesky


__all__ = ["HAVE_NUMBA", "block_cholesky", "default_linear_solver", "jit"]
