"""Presolve: feasibility of the supports, exactly taut segments, and a safe initial guess.

Between two consecutive supports a < b the chain has length ``L_ab = sum l_k`` and the supports
are ``D_ab`` apart. ``D_ab > L_ab`` is infeasible. ``D_ab = L_ab`` (to a relative ``TAUT_RTOL``)
leaves exactly one feasible position for the nodes between them: the straight segment. The
interior-point method cannot work there (the feasible set has no interior), so those nodes
are fixed by the presolve and their tensions follow from force balance along the segment.

The initial guess keeps every pair of neighbouring nodes apart (the norm constraint is not
differentiable where they coincide) and every link strictly shorter than its length:
free ends hang straight down at 95 % of their link lengths; a segment between supports sags
as a parabola as deep as possible with the longest link ratio d_k / l_k at a target between
D_ab / L_ab and 1 (a quadratic equation per link).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from funicular.errors import InfeasibleError, ScenarioError
from funicular.model import FloatArray, IntArray, Problem
from funicular.obstacles import Disk, Ellipse, Expression, Graph, HalfPlane, Obstacle

TAUT_RTOL = 1e-10
HANG_RATIO = 0.95
SURFACE_RTOL = 1e-9  # a support this close to an obstacle (relative to a link) sits on its surface
POSITIONING_ROUNDS = 20
MARGIN_RTOL = 1e-9  # a node within this fraction of the margin from -margin is placed
BISECTIONS = 40  # the sag depth clear of obstacles to 1e-12 of the chain length
DEPTH_MARGIN = 1e-12  # a little below the root; the positions are checked against the target too
# Shapes whose phi at a point does not depend on the other points evaluated with it (elementwise
# numpy: ``obstacles.Quadratic``'s formula, sympy's lambdified expressions), so that point sets
# may be evaluated together; exactly these types (a box turns its points by a matrix product, whose
# rounding may depend on how many rows it has; a subclass or a callable may do anything)
POINTWISE = (Disk, Ellipse, HalfPlane, Graph, Expression)


@dataclass(frozen=True)
class Presolve:
    """Positions to start from, which nodes the interior-point method may move, and known tensions."""

    positions: FloatArray  # (N, 2) initial guess; exact for fixed nodes
    movable: IntArray  # nodes the interior-point method moves, ascending
    fixed_tension: FloatArray  # (N-1,) tension of links between two fixed nodes (0 where undetermined)
    detached: IntArray  # massless free ends: no force reaches them; they rest on their neighbour
    attach: IntArray  # for each detached node, the node it rests on
    # Each obstacle's grad phi at the movable nodes (``positions[movable]``), where the push-out
    # evaluated them there and moved none (the solver's scaling needs them next), else None.
    obstacle_gradients: tuple[FloatArray, ...] | None = None

    @functools.cached_property
    def fixed(self) -> IntArray:
        """The nodes not in ``movable`` (supports, exactly taut spans, detached ends), ascending."""
        fixed = np.ones(self.positions.shape[0], dtype=bool)
        fixed[self.movable] = False
        return np.flatnonzero(fixed)


def _massless_ends(problem: Problem) -> tuple[IntArray, IntArray]:
    """Free end nodes beyond the last (before the first) massive node or support.

    Nothing pulls them, so every position within reach is optimal, and the barrier's centre of
    ``|p_k - p_{k+1}| <= l`` would put them on their neighbour, where the norm is not differentiable.
    They are left out of the solve and placed on the node they hang from, with zero tension.
    """
    if problem.masses[0] > 0.0 and problem.masses[-1] > 0.0:  # (the usual chain: none, at once)
        return np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
    n = problem.n_nodes
    anchored = problem.is_support | (problem.masses > 0)
    first, last = int(anchored.argmax()), int(n - 1 - anchored[::-1].argmax())
    head, tail = np.arange(first), np.arange(last + 1, n)
    return np.concatenate((head, tail)), np.concatenate((np.full(first, first), np.full(tail.size, last)))


def is_taut(distance: float, length: float) -> bool:
    """Supports ``distance`` apart with ``length`` of chain between them hold it exactly taut
    (to TAUT_RTOL): its interior nodes have one feasible position, on the chord."""
    return distance >= length * (1.0 - TAUT_RTOL)


def along_chord(start: FloatArray, chord: FloatArray, lengths: FloatArray) -> FloatArray:
    """The interior nodes of links ``lengths`` laid along ``chord`` from ``start``, each at its
    share of the arclength."""
    arc = np.cumsum(lengths[:-1]) / float(lengths.sum())
    result: FloatArray = start + arc[:, None] * chord
    return result


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


def _outside(obstacles: tuple[Obstacle, ...], points: FloatArray) -> bool:
    """True when no point is strictly inside any obstacle."""
    return all(bool((obstacle.evaluate(points)[0] <= 0.0).all()) for obstacle in obstacles)


def _sag(start: FloatArray, end: FloatArray, lengths: FloatArray, obstacles: tuple[Obstacle, ...]) -> FloatArray:
    """Interior nodes of a segment hanging between two points, every link shorter than its length.

    With obstacles, the sag is made shallower until the nodes are outside them, if the straight
    chord allows it: the chain then settles onto the obstacles from above instead of starting
    tangled in them.
    """
    total = lengths.sum()
    t = np.cumsum(lengths)[:-1] / total
    chord = end - start
    distance = float(np.hypot(*chord))
    # The nodes (chord and sag shape) written between their ends, so that the changes across the
    # links are differences of neighbours (np.vstack and np.diff cost more than a short span's arithmetic).
    nodes, padded = np.empty((t.size + 2, 2)), np.zeros((t.size + 2, 2))
    nodes[0], nodes[-1] = start, end
    base, shape = nodes[1:-1], padded[1:-1]  # views
    np.add(start, t[:, None] * chord, out=base)
    shape[:, 1] = -4.0 * t * (1.0 - t)
    if abs(chord[0]) <= 1e-3 * total:
        # Vertical or zero chord: lean the sag slightly sideways so that x grows along the chain
        # and no two nodes coincide (the nodes at t and 1 - t would, with a zero chord).
        shape[:, 0] = 0.05 * t
    target = 1.0 - 0.05 * (1.0 - distance / total)

    # Link k at depth h is the chord piece plus h times the change of shape across it: the deepest
    # sag with every |b_k + h s_k| <= target l_k is the smallest larger root of those quadratics
    # (each holds at h = 0, as target >= distance / total there).
    steps = nodes[1:] - nodes[:-1]
    bends = padded[1:] - padded[:-1]
    a = np.einsum("ij,ij->i", bends, bends)
    b = 2.0 * np.einsum("ij,ij->i", steps, bends)
    c = np.minimum(np.einsum("ij,ij->i", steps, steps) - (target * lengths) ** 2, 0.0)
    bending = a > 0.0
    a, b, c = a[bending], b[bending], c[bending]
    roots = (-b + np.sqrt(b**2 - 4.0 * a * c)) / (2.0 * a)
    depth = min(float(roots.min(initial=total)), total) * (1.0 - DEPTH_MARGIN)

    def deepest(acceptable: Callable[[float], bool], high: float) -> float:
        low = 0.0
        for _ in range(BISECTIONS):
            mid = 0.5 * (low + high)
            if acceptable(mid):
                low = mid
            else:
                high = mid
        return low

    def within_target(h: float) -> bool:
        sagged = nodes.copy()
        sagged[1:-1] += h * shape
        links = sagged[1:] - sagged[:-1]
        return bool((np.hypot(links[:, 0], links[:, 1]) / lengths).max() <= target)

    # The roots carry the rounding of |b|^2 - (target l)^2, which matters for nearly taut segments
    # far from the origin: check the positions themselves, and bisect below the root if needed.
    if not within_target(depth):
        depth = deepest(within_target, depth)

    result: FloatArray = base + depth * shape
    # (the sag first: it is usually clear, and one evaluation is what a short span pays for)
    if obstacles and not _outside(obstacles, result) and _outside(obstacles, base):
        depth = deepest(lambda h: _outside(obstacles, base + h * shape), depth)
        result = base + depth * shape
    return result


def _hang(anchor: FloatArray, lengths: FloatArray, obstacles: tuple[Obstacle, ...], away: float) -> FloatArray:
    """Nodes of a free end hanging from ``anchor``, each link at HANG_RATIO of its length.

    Straight down, unless that puts a node inside an obstacle: then the first direction, turning
    alternately to either side in steps of 15 degrees (first towards the side the obstacle's
    surface faces there), that keeps every node outside. (Pushing a node straight out of an
    obstacle below its support would move it through to the far side, beyond the reach of its
    link, with nothing to break the left-right symmetry.)
    """
    drop = HANG_RATIO * np.cumsum(lengths)
    straight: FloatArray = anchor - np.stack((np.zeros_like(drop), drop), axis=1)
    if not obstacles or drop.size == 0 or _outside(obstacles, straight):
        return straight
    # Turn first to the side the obstacle's surface faces, or, right above its top, to the side
    # ``away`` from the other supports (so mirroring the scene mirrors the guess).
    side = away
    for obstacle in obstacles:
        phi, gradient, _ = obstacle.evaluate(straight)
        inside = np.flatnonzero(phi > 0.0)
        if inside.size:
            facing = -gradient[inside[0], 0]  # -grad phi points out of the obstacle
            side = float(np.sign(facing)) if facing != 0.0 else away
            break
    for degrees in itertools.chain.from_iterable((side * a, -side * a) for a in range(15, 180, 15)):
        angle = np.radians(degrees)
        hanging: FloatArray = anchor + drop[:, None] * np.array([np.sin(angle), -np.cos(angle)])
        if _outside(obstacles, hanging):
            return hanging
    return straight


def _check_supports_outside(problem: Problem) -> None:
    """A support inside an obstacle makes the problem infeasible (on the surface is fine)."""
    surface = SURFACE_RTOL * float(problem.link_lengths.max())
    if not problem.obstacles or not (problem.support_depths > surface).any():  # (usually all: one pass)
        return
    for obstacle, inside_by in zip(problem.obstacles, problem.support_depths, strict=True):
        inside = np.flatnonzero(inside_by > surface)
        if inside.size:
            j = int(inside[0])
            node = int(problem.support_nodes[j])
            raise InfeasibleError(
                f"the support at node {node} {tuple(problem.support_positions[j].tolist())} is inside obstacle "
                f"{obstacle.name!r} (about {inside_by[j]:.3g} deep); move the support or the obstacle."
            )


def as_slice(index: IntArray) -> slice | IntArray:
    """An ascending index array as the slice it is, if it is one (indexing with it copies element by element)."""
    if index.size and int(index[-1] - index[0]) + 1 == index.size:
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


def _push_out_of_obstacles(
    problem: Problem, positions: FloatArray, movable: IntArray, settled: bool = False
) -> tuple[FloatArray, ...] | None:
    """Move initial-guess nodes that start inside an obstacle to just outside it (Newton on phi = -margin).

    ``settled``: the guess is a solved chain (a coarse level's), whose touching nodes lie on the
    surfaces give or take interpolation: only nodes more than the margin deep are moved. Pushing
    every node on a surface out by the margin would undo the contact the polish starts from (and
    cost 0.15 s at 10^6 nodes).

    Returns each obstacle's gradient at ``positions[movable]`` if no node moved (see ``Presolve``)."""
    if not problem.obstacles:
        return ()
    margin = 0.05 * float(problem.link_lengths.min())
    deeper_than = margin if settled else -margin * (1.0 - MARGIN_RTOL)
    candidates = movable  # a node that is clear of every obstacle and did not move stays clear
    first: list[FloatArray] = []  # each obstacle's gradient in the first round, at every movable node
    for round_ in range(POSITIONING_ROUNDS):
        moved = np.zeros(candidates.size, dtype=bool)
        at = as_slice(candidates)  # a view where the candidates are one run (usually all free nodes)
        for obstacle in problem.obstacles:
            points = positions[at]
            phi, gradient, _ = obstacle.evaluate(points)
            if round_ == 0:
                first.append(gradient)
            norm2 = np.einsum("ij,ij->i", gradient, gradient)
            distance = phi / np.sqrt(np.maximum(norm2, 1e-300))
            # A pushed node comes back at -margin give or take rounding: it has arrived (else every
            # pushed node went round all POSITIONING_ROUNDS, 0.3 s at 10^6 nodes).
            inside = np.isfinite(distance) & (distance > deeper_than) & (norm2 > 0)
            if inside.any():
                step = ((phi[inside] + margin * np.sqrt(norm2[inside])) / norm2[inside])[:, None] * gradient[inside]
                positions[candidates[inside]] = points[inside] - step
                moved |= inside
        if not moved.any():
            return tuple(first) if round_ == 0 else None
        candidates = candidates[moved]
    return None


def presolve(problem: Problem, initial_positions: FloatArray | None = None, settled: bool = False) -> Presolve:
    """Check the supports, fix exactly taut segments, and build (or take) the initial guess
    (``settled``: ``initial_positions`` is a solved chain, see ``_push_out_of_obstacles``)."""
    _check_supports_outside(problem)
    n = problem.n_nodes
    positions = np.zeros((n, 2))
    nodes = problem.support_nodes
    positions[nodes] = problem.support_positions
    movable = np.ones(n, dtype=bool)
    movable[nodes] = False
    fixed_tension = np.zeros(n - 1)
    lengths = problem.link_lengths
    guess = None if initial_positions is None else np.asarray(initial_positions, dtype=np.float64)
    if guess is not None and (guess.shape != positions.shape or not np.isfinite(guess).all()):
        raise ScenarioError(f"initial_positions must be {n} finite (x, y) pairs, got an array of shape {guess.shape}.")

    for a, b in itertools.pairwise(nodes.tolist()):
        chord = positions[b] - positions[a]
        distance = float(np.hypot(*chord))
        length = problem.length_between(a, b)
        _check_pair(problem, a, b, distance, length)
        if b == a + 1:
            continue
        if is_taut(distance, length):
            direction = chord / distance
            positions[a + 1 : b] = along_chord(positions[a], chord, lengths[a:b])
            movable[a + 1 : b] = False
            fixed_tension[a:b] = _taut_tensions(problem, a, b, direction)
        elif guess is None:  # a given guess replaces every movable node's position below
            positions[a + 1 : b] = _sag(positions[a], positions[b], lengths[a:b], problem.obstacles)

    first, last = int(nodes[0]), int(nodes[-1])
    if guess is None and (first > 0 or last < n - 1):  # (_hang costs tens of microseconds even for no end)
        centre = float(problem.support_positions[:, 0].mean())
        if first > 0:
            away = -1.0 if positions[first, 0] < centre else 1.0
            positions[:first][::-1] = _hang(positions[first], lengths[:first][::-1], problem.obstacles, away)
        if last < n - 1:
            away = -1.0 if positions[last, 0] < centre else 1.0
            positions[last + 1 :] = _hang(positions[last], lengths[last:], problem.obstacles, away)
    detached, attach = _massless_ends(problem)
    movable[detached] = False
    movable_nodes = np.flatnonzero(movable)
    if guess is not None:
        start = Presolve(positions, movable_nodes, fixed_tension, detached, attach)
        return repositioned(problem, start, guess, settled)
    gradients = _push_out_of_obstacles(problem, positions, movable_nodes)
    return Presolve(positions, movable_nodes, fixed_tension, detached, attach, gradients)


def repositioned(problem: Problem, start: Presolve, guess: FloatArray, settled: bool = False) -> Presolve:
    """``presolve`` of the same problem from ``guess`` (N, 2), given one of its results: its
    supports, taut segments and detached ends stay where ``start`` put them (the saddle escape
    solves again from a moved chain)."""
    fixed_nodes = start.fixed  # a few nodes: the guess's copy is cheaper than copying under a mask
    positions = guess.copy()
    positions[fixed_nodes] = start.positions[fixed_nodes]
    # Detached nodes rest on their neighbour, where the solve puts them anyway; a guess for them
    # could be anywhere (1e9 away, it raised the rounding floor and loosened the tolerance).
    positions[start.detached] = positions[start.attach]
    gradients = _push_out_of_obstacles(problem, positions, start.movable, settled)
    return Presolve(positions, start.movable, start.fixed_tension, start.detached, start.attach, gradients)
