"""The presolve's sag and push-out (``initial._sag``, ``initial._push_out_of_obstacles``) compiled,
for chains whose obstacles are all disks, ellipses or half-planes (or none).

Why: a 50-node chain over the disk spent about a fifth of its solve in their numpy calls (some
hundred, each costing more than its arithmetic). The formulas and their order are the numpy
functions', line for line, and phi is ``fused.quadratic_contacts``'s, so both paths place the same
nodes; the tests check that they agree to rounding on random spans, obstacles and guesses. (The
maxima and minima are written out: numba's ``max`` and ``min`` drop a NaN where numpy keeps it.)

numba is imported with this module (``compiled.initial_kernels()`` imports it for a compiled
solve only); like ``driver``'s, numba's cache of these kernels does not notice edits to
``fused``: after changing it, delete ``__pycache__/initial_kernels.*.nb*``.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from funicular.solver import fused

_njit = numba.njit(cache=True, nogil=True, error_model="numpy")
_quadratic_contacts = _njit(fused.quadratic_contacts)


@_njit
def _phi(points: Any, rows: Any, quadratic: Any, j: int) -> Any:  # pragma: no cover - compiled
    """Obstacle j's phi at ``points[rows]`` and its gradient there, (rows,) and (rows, 2)."""
    centres, values, gradients, hessians = quadratic
    n = rows.shape[0]
    c, gradient, force = np.empty(n), np.empty((1, n, 2)), np.zeros((n, 2))
    one = slice(j, j + 1)
    _quadratic_contacts(
        points, rows, 0, centres[one], values[one], gradients[one], hessians[one], np.zeros(n), c, gradient, force
    )
    return c, gradient[0]


@_njit
def _outside(points: Any, quadratic: Any) -> bool:  # pragma: no cover - compiled
    """``initial._outside``: no point strictly inside any obstacle."""
    rows = np.arange(points.shape[0])
    for j in range(quadratic[0].shape[0]):
        phi, _ = _phi(points, rows, quadratic, j)
        for value in phi:
            if not value <= 0.0:
                return False
    return True


@_njit
def _within_target(
    start: Any, end: Any, base: Any, shape: Any, lengths: Any, h: float, target: float
) -> bool:  # pragma: no cover
    """``_sag``'s ``within_target``: every link of the sag ``h`` deep at most ``target`` of its length."""
    m = base.shape[0]
    largest = 0.0
    previous0, previous1 = start[0], start[1]
    for k in range(m + 1):
        if k < m:
            here0, here1 = base[k, 0] + h * shape[k, 0], base[k, 1] + h * shape[k, 1]
        else:
            here0, here1 = end[0], end[1]
        ratio = math.hypot(here0 - previous0, here1 - previous1) / lengths[k]
        if ratio > largest or ratio != ratio:  # (a NaN stays, as in numpy's max; Python's max drops it)
            largest = ratio
        previous0, previous1 = here0, here1
    return largest <= target


@_njit
def _sagged(base: Any, shape: Any, h: float, out: Any) -> None:  # pragma: no cover - compiled
    """``out = base + h * shape``: the interior nodes of the sag ``h`` deep."""
    for i in range(base.shape[0]):
        out[i, 0], out[i, 1] = base[i, 0] + h * shape[i, 0], base[i, 1] + h * shape[i, 1]


@_njit
def sag(
    start: Any, end: Any, lengths: Any, total: float, quadratic: Any, depth_margin: float, bisections: int, out: Any
) -> None:  # pragma: no cover - compiled
    """``initial._sag`` into ``out`` (the interior nodes, (n - 1, 2)); ``total``: ``lengths.sum()``
    (numpy's, whose pairwise order a loop would not repeat); ``quadratic``: the obstacles'
    ``Problem.quadratic_obstacles``."""
    m = lengths.shape[0] - 1
    t = np.empty(m)
    walked = 0.0
    for i in range(m):
        walked += lengths[i]
        t[i] = walked / total
    chord0, chord1 = end[0] - start[0], end[1] - start[1]
    distance = math.hypot(chord0, chord1)
    base, shape = np.empty((m, 2)), np.zeros((m, 2))
    lean = abs(chord0) <= 1e-3 * total
    for i in range(m):
        base[i, 0], base[i, 1] = start[0] + t[i] * chord0, start[1] + t[i] * chord1
        shape[i, 1] = -4.0 * t[i] * (1.0 - t[i])
        if lean:
            shape[i, 0] = 0.05 * t[i]
    target = 1.0 - 0.05 * (1.0 - distance / total)

    smallest = total
    for k in range(m + 1):
        before0, before1 = (start[0], start[1]) if k == 0 else (base[k - 1, 0], base[k - 1, 1])
        after0, after1 = (end[0], end[1]) if k == m else (base[k, 0], base[k, 1])
        bent0, bent1 = (0.0, 0.0) if k == 0 else (shape[k - 1, 0], shape[k - 1, 1])
        bend0, bend1 = (0.0, 0.0) if k == m else (shape[k, 0], shape[k, 1])
        step0, step1, bend0, bend1 = after0 - before0, after1 - before1, bend0 - bent0, bend1 - bent1
        a = bend0 * bend0 + bend1 * bend1
        if a > 0.0:
            b = 2.0 * (step0 * bend0 + step1 * bend1)
            c = step0 * step0 + step1 * step1 - (target * lengths[k]) ** 2
            c = 0.0 if c > 0.0 else c  # (np.minimum's NaN-keeping order)
            root = (-b + math.sqrt(b**2 - 4.0 * a * c)) / (2.0 * a)
            if root < smallest or root != root:  # (numpy's min keeps a NaN)
                smallest = root
    depth = (total if total < smallest else smallest) * (1.0 - depth_margin)  # (Python's min, as in _sag)

    if not _within_target(start, end, base, shape, lengths, depth, target):
        low, high = 0.0, depth
        for _ in range(bisections):
            middle = 0.5 * (low + high)
            if _within_target(start, end, base, shape, lengths, middle, target):
                low = middle
            else:
                high = middle
        depth = low

    _sagged(base, shape, depth, out)
    if quadratic[0].shape[0] and not _outside(out, quadratic) and _outside(base, quadratic):
        low, high = 0.0, depth
        for _ in range(bisections):
            middle = 0.5 * (low + high)
            _sagged(base, shape, middle, out)
            if _outside(out, quadratic):
                low = middle
            else:
                high = middle
        _sagged(base, shape, low, out)


@_njit
def push_out(
    positions: Any, movable: Any, quadratic: Any, margin: float, deeper_than: float, rounds: int, first: Any
) -> bool:  # pragma: no cover - compiled
    """``initial._push_out_of_obstacles``, moving ``positions`` in place: True if no node moved,
    and then ``first`` (n_obstacles, movable, 2) holds each obstacle's gradient at the movable nodes."""
    candidates = movable
    for round_ in range(rounds):
        moved = np.zeros(candidates.shape[0], dtype=np.bool_)
        for j in range(quadratic[0].shape[0]):
            phi, gradient = _phi(positions, candidates, quadratic, j)
            if round_ == 0:
                first[j] = gradient
            for f in range(candidates.shape[0]):
                g0, g1 = gradient[f, 0], gradient[f, 1]
                norm2 = g0 * g0 + g1 * g1
                distance = phi[f] / math.sqrt(1e-300 if norm2 < 1e-300 else norm2)  # (np.maximum keeps a NaN)
                if math.isfinite(distance) and distance > deeper_than and norm2 > 0:
                    scale = (phi[f] + margin * math.sqrt(norm2)) / norm2
                    i = candidates[f]
                    positions[i, 0], positions[i, 1] = positions[i, 0] - scale * g0, positions[i, 1] - scale * g1
                    moved[f] = True
        if not moved.any():
            return round_ == 0
        candidates = candidates[moved]
    return False
