"""An exact start for a chain that touches nothing: each span a discrete catenary.

Between two consecutive supports a and b, a chain that touches no obstacle and carries weight
on its interior nodes has every link taut, the same horizontal force H in every link, and the
vertical force ``V_k = V_0 + g (m_{a+1} + ... + m_{a+k})`` in link a+k (docs/model.md, "The
discrete catenary"). Two conditions close it: the links, each pointing along its force, reach support b,

    F_1 = sum_k l_k H / T_k - D = 0,   F_2 = sum_k l_k V_k / T_k - h = 0,   T_k = hypot(H, V_k)

(D the span, h the rise). Newton's method on ``(log H, psi)`` with ``V_0 = H kappa + W psi``
(``hanging_span``), from the continuous catenary of the same length and weight, solves them in a
handful of O(n) passes (``studies.catenary``'s nested scalar root-find, written as an oracle,
takes about a thousand). A free end hangs straight down, each link carrying the weight below it.

When every span is solved this way and every free node is outside every obstacle, this is the
equilibrium, and the solver starts from it with its tensions: the polish confirms it in one Newton
step. (An almost taut span, 1e-9 of slack on a slant, has tensions 10^4 times the weight; the
interior-point method from the sagging guess stopped at 200 steps without converging.)
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from funicular.errors import ScenarioError
from funicular.model import FloatArray, IntArray, Problem
from funicular.obstacles import Obstacle, depth, has_segment_max, link_contact, link_contact_ends
from funicular.solver.initial import POINTWISE, _massless_ends, along_chord, is_taut
from funicular.studies.catenary import ContinuousCatenary

NEWTON_STEPS = 60
BACKTRACKS = 30
SPAN_RTOL = 1e-14  # F_1 and F_2 relative to the span's length: converged
ACCEPT_RTOL = 1e-11  # ... good enough to start from when Newton stalls at rounding
MAX_STEP = 2.0  # largest Newton step in log H and in psi (see hanging_span)
MAX_LOG = 700.0  # |log H| beyond this over- or underflows
# hanging_span gives up when its starting rope lies deeper in an obstacle than CLEARANCE of its
# length or CLEARANCE_LINKS of its longest link, whichever is less (a uniform chain's nodes lie
# within about a link of the rope; a chain whose masses are far from uniform may be skipped
# although it is clear: it then takes the general path)
CLEARANCE = 0.02
CLEARANCE_LINKS = 4.0
ROPE_POINTS = 1024  # points of the starting rope checked against the obstacles
# Where every obstacle is POINTWISE (``initial``: a point's verdict does not depend on the points
# evaluated with it), the rope's lowest point is one of the points checked, and the first, then
# every ROPE_PRECHECK-th of the others: a rope through an obstacle is usually caught there, and a
# small chain's check costs the numpy calls, not the points (the disk at 50 nodes gave up in
# 0.25 ms, half of it checking all the points; at its lowest point alone, in a quarter of the 64
# points' time). The verdict is that of all of them, which with the lowest point is a little
# stricter than the samples' alone: a rope deeper than the limit only between two samples gives up
# too (the solver then finds the same equilibrium without the exact start).
ROPE_PRECHECK = 16
VERTICAL_RTOL = 1e-6  # a span this much narrower than long folds up: left to the solver


def exact_start(problem: Problem) -> tuple[FloatArray, FloatArray] | None:
    """Positions (N, 2) and link tensions (N-1,) of ``problem``'s equilibrium if no node touches an
    obstacle (see the module docstring), else ``None``. Also ``None`` where this construction does
    not apply and the solver must work: a span with no weight on its interior nodes (its links may
    hang slack), a nearly vertical span (it folds). With ``contact = "links"`` the links, not only
    the nodes, must clear every obstacle.

    Two parts are left to the presolve, which replaces them: an exactly taut span gets its chord
    and zero tensions here (the presolve fixes it with its own tensions), and massless free ends
    hang straight down (the presolve rests them on the node they hang from; they are not checked
    against the obstacles)."""
    if problem.obstacles and problem.contact == "links" and not all(map(has_segment_max, problem.obstacles)):
        return None  # (the solver refuses these itself, with a sentence)
    n, g = problem.n_nodes, problem.gravity
    masses, lengths = problem.masses, problem.link_lengths
    nodes = problem.support_nodes
    positions, tension = np.empty((n, 2)), np.zeros(n - 1)
    positions[nodes] = problem.support_positions
    for a, b in itertools.pairwise(nodes.tolist()):
        if b == a + 1:
            continue
        chord = positions[b] - positions[a]
        if is_taut(math.hypot(*chord), problem.length_between(a, b)):
            # The presolve fixes an exactly taut span on its chord, with its own tensions.
            positions[a + 1 : b] = along_chord(positions[a], chord, lengths[a:b])
            continue
        span = hanging_span(masses[a + 1 : b], lengths[a:b], g, positions[a], positions[b], problem.obstacles)
        if span is None:
            return None
        positions[a + 1 : b], tension[a:b] = span
    first, last = int(nodes[0]), int(nodes[-1])
    # Free ends straight down: link k of the head carries nodes 0..k, link k of the tail nodes k+1..N-1.
    drop = np.cumsum(lengths[:first][::-1])
    positions[:first] = positions[first] - np.column_stack((np.zeros(first), drop))[::-1]
    tension[:first] = g * np.cumsum(masses[:first])
    drop = np.cumsum(lengths[last:])
    positions[last + 1 :] = positions[last] - np.column_stack((np.zeros(n - 1 - last), drop))
    tension[last:] = g * np.cumsum(masses[last + 1 :][::-1])[::-1]
    detached, _ = _massless_ends(problem)
    if problem.obstacles and not _clear(problem.obstacles, np.delete(positions, np.union1d(nodes, detached), axis=0)):
        return None
    if problem.obstacles and problem.contact == "links" and not _links_clear(problem, positions, detached):
        return None
    return positions, tension


def _links_clear(problem: Problem, positions: FloatArray, detached: IntArray) -> bool:
    """With ``contact = "links"``: every link the solver keeps out of the obstacles (one with a
    movable end and no detached massless end, as in ``ipm._scale``) has its contact row ``psi``
    (``link_contact``: phi's largest value along it, or at its free end) below zero."""
    end, pinned = link_contact_ends(problem.is_support)
    movable, left_out = ~problem.is_support, np.zeros(problem.n_nodes, dtype=bool)
    left_out[detached] = True
    rows = np.flatnonzero((movable[:-1] | movable[1:]) & ~left_out[:-1] & ~left_out[1:])
    for obstacle in problem.obstacles:
        psi = link_contact(obstacle, positions[rows], positions[rows + 1], end[rows], pinned[rows]).psi
        if not np.all(psi < 0.0):
            return False
    return True


def _clear(obstacles: tuple[Obstacle, ...], points: FloatArray) -> bool:
    """Every point strictly outside every obstacle."""
    return all(bool((obstacle.evaluate(points)[0] < 0.0).all()) for obstacle in obstacles)


def _deeper_than(obstacles: tuple[Obstacle, ...], points: FloatArray, limit: float) -> bool:
    """Some point inside an obstacle by more than ``limit`` (``obstacles.depth``)."""
    return any(bool((depth(obstacle, points) > limit).any()) for obstacle in obstacles)


def hanging_span(
    interior_masses: FloatArray,
    lengths: FloatArray,
    g: float,
    left: FloatArray,
    right: FloatArray,
    obstacles: tuple[Obstacle, ...] = (),
) -> tuple[FloatArray, FloatArray] | None:
    """Interior node positions (n-1, 2) and link tensions (n,) of n links hanging between ``left``
    and ``right`` with every link taut, or ``None`` if there is no weight between them, the span
    is nearly vertical, or Newton's method does not converge. With ``obstacles``, also ``None``
    at once if the uniform rope it starts from (ROPE_POINTS points of it, and its lowest point
    where every obstacle is POINTWISE) goes deeper into one than CLEARANCE of its length or
    CLEARANCE_LINKS links: the chain would too, and the Newton steps would be wasted (0.2 s at
    10^6 nodes). The caller checks the answer against the obstacles either way."""
    total = float(lengths.sum())
    span, rise = float(right[0] - left[0]), float(right[1] - left[1])
    direction = 1.0 if span >= 0.0 else -1.0  # solved for span > 0, mirrored back
    span = abs(span)
    distance = math.hypot(span, rise)
    unit = g * float(interior_masses.sum())
    if not (span > VERTICAL_RTOL * total and distance < total and unit > 0.0 and math.isfinite(unit)):
        return None
    # Forces in units of the span's weight W (the tensions are scaled back at the end): l / T^3 in
    # the Jacobian over- or underflowed for weights beyond 1e+-100, which the model allows up to
    # 1e+-150. The start: the uniform rope of the same length and weight between the same points.
    try:
        rope = ContinuousCatenary.between((0.0, 0.0), (span, rise), total, 1.0 / total)
    except ScenarioError:  # (a chord within rounding of the length: left to the solver)
        return None
    if obstacles:
        limit = min(CLEARANCE * total, CLEARANCE_LINKS * float(lengths.max()))
        pointwise = all(type(obstacle) in POINTWISE for obstacle in obstacles)
        if pointwise:  # (a chain draped over an obstacle below: caught at its lowest point alone)
            x, y = rope.lowest_point
            if _deeper_than(obstacles, left + np.array([[direction * x, y]]), limit):
                return None
        arclength = np.arange(ROPE_POINTS) * (total / (ROPE_POINTS - 1))  # (np.linspace's wrapper: 10 us)
        mirror = np.array([direction, 1.0])
        for sample in (arclength[::ROPE_PRECHECK], arclength) if pointwise else (arclength,):
            if _deeper_than(obstacles, left + rope.position_at_arclength(sample) * mirror, limit):
                return None
    lifted = (g / unit) * np.concatenate(([0.0], np.cumsum(interior_masses)))  # (V_k - V_0) / W
    # V_0 = H kappa + W psi: for a fixed psi the links turn towards the chord as H grows, so the
    # Jacobian in (log H, psi) stays well conditioned for a nearly taut span (in (log H, V_0) the
    # two columns become parallel and Newton's steps overshoot). The solution has -1 <= psi <= 0.
    kappa = rise / math.sqrt((total - rise) * (total + rise))
    log_h = math.log(rope.horizontal_force)
    psi = rope.weight_per_length * rope.arc_left - rope.horizontal_force * kappa  # V_0 of the rope

    Forces = tuple[float, float, float, FloatArray, FloatArray]  # F_1, F_2, H, V_k, 1 / T_k

    def forces(log_h: float, psi: float) -> Forces | None:
        """The residuals and the forces there; ``None`` where they are not finite numbers."""
        if not abs(log_h) < MAX_LOG:  # H over- or underflows: no equilibrium there
            return None
        h = math.exp(log_h)
        with np.errstate(all="ignore"):  # a wild step may overflow V: rejected
            v = (h * kappa + psi) + lifted
            inverse = v * v
            inverse += h * h
            np.sqrt(inverse, out=inverse)
            np.divide(1.0, inverse, out=inverse)
            f1, f2 = h * float(lengths @ inverse) - span, float(lengths @ (v * inverse)) - rise
        return (f1, f2, h, v, inverse) if math.isfinite(f1) and math.isfinite(f2) else None

    def nodes(here: Forces) -> FloatArray:
        """The interior nodes the links reach, each pointing along its force."""
        _, _, h, v, inverse = here
        positions = np.empty((lengths.size - 1, 2))
        positions[:, 0] = np.cumsum((direction * h) * (lengths[:-1] * inverse[:-1]))
        positions[:, 1] = np.cumsum(lengths[:-1] * v[:-1] * inverse[:-1])
        positions += left
        return positions

    here = forces(log_h, psi)
    for _ in range(NEWTON_STEPS):
        if here is None:
            return None
        f1, f2, h, v, inverse = here
        size = max(abs(f1), abs(f2))
        if size <= SPAN_RTOL * total:
            break
        with np.errstate(all="ignore"):  # T^3 may overflow or underflow: a non-finite det stops
            cubed = inverse * inverse
            cubed *= inverse
            cubed *= lengths  # l_k / T_k^3
            a, b, c = float(cubed @ (v * v)), h * float(cubed @ v), h * h * float(cubed.sum())
            # d(F_1, F_2)/d(log H, V_0) = [[H a, -b], [-H b, c]], and dV_0 = H kappa dlog H + dpsi (W = 1)
            j11, j12, j21, j22 = h * (a - kappa * b), -b, h * (kappa * c - b), c
            det = j11 * j22 - j12 * j21
        if not (math.isfinite(det) and det != 0.0):
            break
        d_log_h = -(j22 * f1 - j12 * f2) / det
        d_psi = -(j11 * f2 - j21 * f1) / det
        # At most a factor e^2 on H and a whole weight on V_0 per step: far from the solution the
        # linear model is poor, and a full step can throw H to 1e-67.
        fraction = min(1.0, MAX_STEP / max(abs(d_log_h), abs(d_psi), 1e-300))
        for _ in range(BACKTRACKS):
            trial = forces(log_h + fraction * d_log_h, psi + fraction * d_psi)
            if trial is not None and trial[0] ** 2 + trial[1] ** 2 < f1 * f1 + f2 * f2:
                log_h, psi, here = log_h + fraction * d_log_h, psi + fraction * d_psi, trial
                break
            fraction *= 0.5
        else:
            break
    if here is None or not max(abs(here[0]), abs(here[1])) <= ACCEPT_RTOL * total:
        return None
    return nodes(here), unit / here[4]
