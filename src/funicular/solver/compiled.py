"""Compiled (numba) kernels for the O(N) linear algebra, with LAPACK as the fallback.

The Newton matrix is block tridiagonal with 2x2 blocks. LAPACK's ``pbtrf`` treats it as a
general band of width 3 and pays a per-column overhead that dominates at such a small width
(0.3 s for N = 10^6 nodes). :func:`block_cholesky` factors it block by block,

    S_0 = D_0,   L_f = chol(S_f),   C_f = L_f^{-1} B_f,   S_{f+1} = D_{f+1} - C_f^T C_f,

with every 2x2 operation written out, compiled by numba and streamed through memory once. It
keeps the reciprocals of L_f's diagonal, so the solve, whose recurrence runs node after node,
multiplies instead of dividing (twice as fast). An ``L D L^T`` with explicit 2x2 inverses would
be faster still, but is not backward stable: late in the iteration a block's eigenvalues are
10^12 apart, and its inverse loses the small ones (the 10^5-node disk then never converged).

numba is optional (the ``fast`` extra). Without it :func:`default_linear_solver` is LAPACK's
:func:`funicular.solver.banded.banded_cholesky`; the two agree to rounding, which the tests
check on every built-in scenario.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import math
import signal
import threading
from collections.abc import Callable, Iterator
from types import ModuleType
from typing import Any

import numpy as np

from funicular.model import FloatArray
from funicular.solver.banded import BlockTridiagonal, LinearSolver, Solve, banded_cholesky

HAVE_NUMBA = importlib.util.find_spec("numba") is not None


def factor_blocks(diagonal: Any, off_diagonal: Any, lower: Any, coupling: Any) -> int:  # pragma: no cover
    """``lower[f] = (1/l00, l10, 1/l11)`` of L_f and ``coupling[f] = C_f``; returns -1, or the first
    free node whose block is not positive definite."""
    s00, s01, s11 = diagonal[0, 0, 0], diagonal[0, 0, 1], diagonal[0, 1, 1]
    n = diagonal.shape[0]
    for f in range(n):
        if not s00 > 0.0:
            return f
        i00 = 1.0 / math.sqrt(s00)
        l10 = s01 * i00
        rest = s11 - l10 * l10
        if not rest > 0.0:
            return f
        i11 = 1.0 / math.sqrt(rest)
        lower[f, 0], lower[f, 1], lower[f, 2] = i00, l10, i11
        if f + 1 == n:
            break
        # C_f = L_f^{-1} B_f by forward substitution, column by column.
        b00, b01 = off_diagonal[f, 0, 0], off_diagonal[f, 0, 1]
        b10, b11 = off_diagonal[f, 1, 0], off_diagonal[f, 1, 1]
        c00, c01 = b00 * i00, b01 * i00
        c10, c11 = (b10 - l10 * c00) * i11, (b11 - l10 * c01) * i11
        coupling[f, 0, 0], coupling[f, 0, 1], coupling[f, 1, 0], coupling[f, 1, 1] = c00, c01, c10, c11
        # S_{f+1} = D_{f+1} - C_f^T C_f
        s00 = diagonal[f + 1, 0, 0] - (c00 * c00 + c10 * c10)
        s01 = diagonal[f + 1, 0, 1] - (c00 * c01 + c10 * c11)
        s11 = diagonal[f + 1, 1, 1] - (c01 * c01 + c11 * c11)
    return -1


def solve_blocks(lower: Any, coupling: Any, rhs: Any, x: Any) -> None:  # pragma: no cover
    """``L L^T x = rhs``: forward ``y_f = L_f^{-1} (b_f - C_{f-1}^T y_{f-1})``, then backward
    ``x_f = L_f^{-T} (y_f - C_f x_{f+1})``."""
    n = lower.shape[0]
    y0, y1 = 0.0, 0.0
    for f in range(n):
        r0, r1 = rhs[2 * f], rhs[2 * f + 1]
        if f > 0:
            r0 -= coupling[f - 1, 0, 0] * y0 + coupling[f - 1, 1, 0] * y1
            r1 -= coupling[f - 1, 0, 1] * y0 + coupling[f - 1, 1, 1] * y1
        y0 = r0 * lower[f, 0]
        y1 = (r1 - lower[f, 1] * y0) * lower[f, 2]
        x[2 * f], x[2 * f + 1] = y0, y1
    for f in range(n - 1, -1, -1):
        r0, r1 = x[2 * f], x[2 * f + 1]
        if f + 1 < n:
            r0 -= coupling[f, 0, 0] * x[2 * f + 2] + coupling[f, 0, 1] * x[2 * f + 3]
            r1 -= coupling[f, 1, 0] * x[2 * f + 2] + coupling[f, 1, 1] * x[2 * f + 3]
        x1 = r1 * lower[f, 2]
        x[2 * f + 1] = x1
        x[2 * f] = (r0 - lower[f, 1] * x1) * lower[f, 0]


HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block ends (main thread only; elsewhere a no-op).

    Importing numba and compiling a kernel import dozens of modules mid-solve. A Ctrl-C whose
    KeyboardInterrupt is raised inside one of the import system's weakref callbacks is printed as
    "Exception ignored" and lost: the run goes on and exits 0. Inside the block a signal is only
    recorded (a signal mask would not do: numpy's BLAS threads would take the signal instead); after
    it, the previous handler runs, raising an ordinary KeyboardInterrupt that the command line turns
    into "funicular: interrupted"."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[tuple[int, Any]] = []
    previous: dict[int, Any] = {}
    for number in HELD_SIGNALS:
        handler = signal.getsignal(number)
        if handler is not None:  # None: installed outside Python, cannot be restored
            previous[number] = handler
            signal.signal(number, lambda signum, frame: caught.append((signum, frame)))
    try:
        yield
    finally:
        for held, handler in previous.items():
            signal.signal(held, handler)
        # Delivered even when the block raised (the interrupt then wins); SIGTERM before SIGINT.
        for signum, frame in sorted(caught, key=lambda item: item[0] != signal.SIGTERM)[:1]:
            handler = previous[signum]
            if callable(handler):
                handler(signum, frame)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)


@functools.cache
def jit(kernel: Callable[..., Any]) -> Callable[..., Any]:
    """``kernel`` compiled by numba on first use (importing numba costs half a second; the command
    line should not pay it for a command that never solves), cached on disk; signals are held while
    numba is imported and while a kernel first compiles or loads from the cache (``_signals_held``;
    a later compile for new argument types, e.g. a broadcast Hessian, runs without).
    Without numba the plain Python function: correct, but only fit for small systems (tests)."""
    if not HAVE_NUMBA:
        return kernel
    with _signals_held():
        import numba

    # (a kernel of ``driver`` is a dispatcher already: it calls other kernels, which must be compiled too)
    dispatcher = (
        kernel if hasattr(kernel, "overloads") else numba.njit(cache=True, nogil=True, error_model="numpy")(kernel)
    )

    def call(*args: Any) -> Any:
        if dispatcher.overloads:  # compiled or loaded (``signatures`` would hash every type: 30 us a call)
            return dispatcher(*args)
        with _signals_held():
            return dispatcher(*args)

    # One code object per kernel: cProfile keys functions by it, and a wrapper shared by every kernel
    # would merge their callers (``funicular bench --profile`` put the polish's elimination under
    # evaluation).
    call.__code__ = call.__code__.replace(co_name=kernel.__name__)
    return functools.wraps(kernel)(call)


@functools.cache
def driver() -> ModuleType:
    """The ``solver.driver`` module (the compiled loop), imported on first use: it imports numba."""
    with _signals_held():
        return importlib.import_module("funicular.solver.driver")


@functools.cache
def initial_kernels() -> ModuleType:
    """The ``solver.initial_kernels`` module (the presolve compiled), imported on first use: it imports numba."""
    with _signals_held():
        return importlib.import_module("funicular.solver.initial_kernels")


def block_cholesky(matrix: BlockTridiagonal) -> Solve:
    """Factor with the 2x2 block Cholesky; raises ``LinAlgError`` if the matrix is not positive
    definite (the driver's inertia correction relies on that), like LAPACK."""
    factor_kernel, solve_kernel = jit(factor_blocks), jit(solve_blocks)
    n = matrix.diagonal.shape[0]
    lower, coupling = np.empty((n, 3)), np.empty((max(n - 1, 0), 2, 2))
    failed = factor_kernel(
        np.ascontiguousarray(matrix.diagonal), np.ascontiguousarray(matrix.off_diagonal), lower, coupling
    )
    if failed >= 0:
        raise np.linalg.LinAlgError(f"the Newton matrix is not positive definite (free node {failed})")

    def solve(rhs: FloatArray) -> FloatArray:
        x = np.empty(2 * n)
        solve_kernel(lower, coupling, np.ascontiguousarray(rhs, dtype=np.float64), x)
        return x

    return solve


def default_linear_solver(compiled: bool = True) -> LinearSolver:
    """The compiled block Cholesky for a compiled solve when numba is installed, LAPACK's banded
    Cholesky otherwise (without numba the block Cholesky would run as plain Python)."""
    return block_cholesky if compiled and HAVE_NUMBA else banded_cholesky


__all__ = ["HAVE_NUMBA", "block_cholesky", "default_linear_solver", "jit"]
