"""Presolve: feasibility of the supports, exactly taut segments, and a safe initial guess.

Between two consecutive supports a < b the chain has length ``L_ab = sum l_k`` and the supports
are ``D_ab`` apart. ``D_ab > L_ab`` is infeasible. ``D_ab = L_ab`` (to a relative ``TAUT_RTOL``)
leaves exactly one feasible position for the nodes between them: the straight segment. The
interior-point method cannot work there (the feasible set has no interior), so those nodes
are fixed by the presolve and their tensions follow from force balance along the segment.

The initial guess keeps every pair of neighbouring nodes apart (the norm constraint is not
differentiable where they coincide) and every link strictly shorter than its length:
free ends hang straight down at 95 % of their link lengths; a segment between supports sags
as a parabola whose depth is found by bisection so that the longest link ratio d_k / l_k sits
between D_ab / L_ab and 1.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from funicular.errors import InfeasibleError
from funicular.model import FloatArray, IntArray, Problem

TAUT_RTOL = 1e-10
HANG_RATIO = 0.95


@dataclass(frozen=True)
class Presolve:
    """Positions to start from, which nodes the interior-point method may move, and known tensions."""

    positions: FloatArray  # (N, 2) initial guess; exact for fixed nodes
    movable: IntArray  # nodes the interior-point method moves, ascending
    fixed_tension: FloatArray  # (N-1,) tension of links between two fixed nodes (0 where undetermined)


def _check_pair(problem: Problem, a: int, b: int, distance: float, length: float) -> None:
    if distance > length * (1.0 + TAUT_RTOL):
        pa, pb = problem.support_positions[np.searchsorted(problem.support_nodes, [a, b])]
        raise InfeasibleError(
            f"supports at nodes {a} {tuple(pa.tolist())} and {b} {tuple(pb.tolist())} are {distance:.6g} apart, "
            f"but the chain between them is only {length:.6g} long; move them closer or lengthen the chain."
        )


def _taut_tensions(problem: Problem, a: int, b: int, direction: FloatArray) -> FloatArray:
    """Tensions of links a..b-1 of a straight taut segment, with the least pre-tension.

    Force balance at an interior node i along the segment: ``(T_i - T_{i-1}) u = (0, g m_i)``.
    That needs u vertical unless the interior nodes are massless; the tensions are then fixed up
    to a constant (the multipliers are not unique: LICQ fails), and we report the smallest one
    that keeps every tension >= 0.
    """
    interior = problem.masses[a + 1 : b]
    weight = problem.gravity * interior
    if np.any(weight > 0) and abs(direction[0]) > 1e-12:
        raise InfeasibleError(
            f"the chain between the supports at nodes {a} and {b} is exactly taut and not vertical, so its weight "
            "would need an infinite tension and no equilibrium with finite forces exists; lengthen the chain or "
            "align the supports vertically."
        )
    uy = direction[1] if abs(direction[1]) > 0.5 else 1.0
    tension: FloatArray = np.concatenate(([0.0], np.cumsum(weight / uy)))
    tension -= tension.min()
    return tension


def _sag(start: FloatArray, end: FloatArray, lengths: FloatArray) -> FloatArray:
    """Interior nodes of a segment hanging between two points, every link shorter than its length."""
    total = lengths.sum()
    t = np.cumsum(lengths)[:-1] / total
    chord = end - start
    distance = float(np.hypot(*chord))
    base = start + t[:, None] * chord
    shape = np.stack((np.zeros_like(t), -4.0 * t * (1.0 - t)), axis=1)
    if abs(chord[0]) <= 1e-3 * total:
        # Vertical or zero chord: lean the sag slightly sideways so that x grows along the chain
        # and no two nodes coincide (the nodes at t and 1 - t would, with a zero chord).
        shape[:, 0] = 0.05 * t
    target = 1.0 - 0.05 * (1.0 - distance / total)

    def worst_ratio(depth: float) -> float:
        nodes = np.vstack((start, base + depth * shape, end))
        d = np.hypot(*np.diff(nodes, axis=0).T)
        return float(np.max(d / lengths))

    low, high = 0.0, total
    for _ in range(60):
        mid = 0.5 * (low + high)
        if worst_ratio(mid) <= target:
            low = mid
        else:
            high = mid
    result: FloatArray = base + low * shape
    return result


def presolve(problem: Problem) -> Presolve:
    """Check the supports, fix exactly taut segments, and build the initial guess."""
    n = problem.n_nodes
    positions = np.zeros((n, 2))
    nodes = problem.support_nodes
    positions[nodes] = problem.support_positions
    movable = np.ones(n, dtype=bool)
    movable[nodes] = False
    fixed_tension = np.zeros(n - 1)
    lengths = problem.link_lengths

    for a, b in itertools.pairwise(nodes):
        chord = positions[b] - positions[a]
        distance = float(np.hypot(*chord))
        length = problem.length_between(a, b)
        _check_pair(problem, int(a), int(b), distance, length)
        if b == a + 1:
            continue
        if distance >= length * (1.0 - TAUT_RTOL):
            direction = chord / distance
            arc = np.cumsum(lengths[a : b - 1]) / length
            positions[a + 1 : b] = positions[a] + arc[:, None] * chord
            movable[a + 1 : b] = False
            fixed_tension[a:b] = _taut_tensions(problem, int(a), int(b), direction)
        else:
            positions[a + 1 : b] = _sag(positions[a], positions[b], lengths[a:b])

    first, last = int(nodes[0]), int(nodes[-1])
    drop = HANG_RATIO * np.cumsum(lengths[:first][::-1])  # nodes first-1, ..., 0
    positions[:first][::-1] = positions[first] - np.stack((np.zeros_like(drop), drop), axis=1)
    drop = HANG_RATIO * np.cumsum(lengths[last:])
    positions[last + 1 :] = positions[last] - np.stack((np.zeros_like(drop), drop), axis=1)
    return Presolve(positions=positions, movable=np.flatnonzero(movable), fixed_tension=fixed_tension)
