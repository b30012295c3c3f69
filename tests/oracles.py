"""Exact answers for hanging chains, derived independently of ``funicular``.

Only numpy and scipy are used here: nothing from the package (no solver, no force code), so
that the tests compare the package against an independent derivation. Conventions follow
``docs/model.md``: nodes 0..N-1, link k joins nodes k and k+1, gravity ``g`` in -y,
a force is what acts *on* a node, a support reaction is the force the support exerts on its node.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import brentq

# --------------------------------------------------------------------------- dangling chain
#
# One support at node 0, N equal masses M/N, all links taut and vertical. Cutting link k
# (0-based, joining nodes k and k+1) leaves nodes k+1..N-1 below it: N-1-k nodes of weight
# M g / N each, so the link carries T_k = M g (N-1-k)/N (the seed's 1-based T_k = M g (N-k)/N).
# The squared-form multiplier is mu_k = T_k / (2 d_k) with d_k = l = L/(N-1).


def dangling_tensions(n: int, total_mass: float, g: float) -> np.ndarray:
    """Norm-form tension of link k = 0..n-2 of a chain of n equal masses hanging from node 0."""
    k = np.arange(n - 1, dtype=np.float64)
    return total_mass * g * (n - 1 - k) / n


def dangling_squared_multipliers(n: int, total_mass: float, total_length: float, g: float) -> np.ndarray:
    """Squared-form multipliers ``T_k / (2 l)``, ``l = total_length / (n - 1)``, of the dangling chain."""
    link = total_length / (n - 1)
    return dangling_tensions(n, total_mass, g) / (2.0 * link)


def dangling_positions(n: int, total_length: float, top: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Node k hangs at ``top - (0, k l)``: straight down with spacing ``l = total_length / (n - 1)``."""
    link = total_length / (n - 1)
    positions = np.zeros((n, 2))
    positions[:, 0] = top[0]
    positions[:, 1] = top[1] - link * np.arange(n)
    return positions


# --------------------------------------------------------------------------- the seed's hand computations
#
# Seed exercise 3.1 (iii), formulation CHAIN-V1 (squared links), dangling chain with M = 1,
# L = 1.5, m_i = 1/N, all links taut at l = L/(N-1). Balance of the y-forces (seed, 1-based):
#
#   N = 2, l = 1.5:   g/2 - 2 mu_1 l = 0 at node 2        =>  mu_1 = g/(4 l) = g/6
#                     g/2 + lambda + 2 mu_1 l = 0 at node 1  =>  lambda = -g,  reaction R = -lambda = g
#   N = 3, l = 0.75:  g/3 - 2 mu_2 l = 0 at node 3        =>  mu_2 = g/(6 l) = 2g/9
#                     g/3 + 2 mu_2 l - 2 mu_1 l = 0 at node 2  =>  mu_1 = 2 mu_2 = 4g/9
#                     g/3 + lambda + 2 mu_1 l = 0 at node 1  =>  lambda = -g,  reaction R = -lambda = g
#
# The values below are these literal numbers (per unit g), listed 0-based by link.
SEED_TOTAL_MASS = 1.0
SEED_TOTAL_LENGTH = 1.5
SEED_SQUARED_MULTIPLIERS_PER_G: dict[int, tuple[float, ...]] = {
    2: (1.0 / 6.0,),  # mu_1 = 1/(4 * 1.5)
    3: (4.0 / 9.0, 2.0 / 9.0),  # mu_1 = 2 mu_2, mu_2 = 1/(6 * 0.75)
}
SEED_SUPPORT_REACTION_PER_G = (0.0, 1.0)  # R = (0, M g) with M = 1


def seed_squared_multipliers(n: int, g: float) -> np.ndarray:
    """The seed's hand-computed squared-form multipliers for N = 2 or 3 (0-based by link)."""
    return g * np.array(SEED_SQUARED_MULTIPLIERS_PER_G[n])


def seed_support_reaction(g: float) -> np.ndarray:
    """The seed's support reaction ``-lambda = (0, M g)``, M = 1."""
    return g * np.array(SEED_SUPPORT_REACTION_PER_G)


# --------------------------------------------------------------------------- discrete catenary


@dataclass(frozen=True)
class CatenaryResult:
    """Equilibrium of a chain between supports at node 0 and node N-1, every link taut.

    positions: (N, 2) node positions.
    tension: (N-1,) link tensions ``T_k = hypot(H, V_k)``.
    H: horizontal component of every link force (the same in all links, > 0).
    V: (N-1,) vertical component of the force in link k, as a vector pointing from node k to k+1.
    reaction_left, reaction_right: (2,) forces the supports exert on nodes 0 and N-1.
    """

    positions: np.ndarray
    tension: np.ndarray
    H: float
    V: np.ndarray
    reaction_left: np.ndarray
    reaction_right: np.ndarray


def _expand_bracket(f, lo: float, hi: float, *, max_doublings: int = 2000) -> tuple[float, float]:
    """Move ``lo`` down and ``hi`` up (doubling the step) until ``f(lo) < 0 < f(hi)`` for increasing ``f``."""
    step = hi - lo
    for _ in range(max_doublings):
        if f(lo) < 0.0:
            break
        lo -= step
        step *= 2.0
    else:
        raise ValueError("discrete_catenary: could not bracket the root from below")
    step = hi - lo
    for _ in range(max_doublings):
        if f(hi) > 0.0:
            break
        hi += step
        step *= 2.0
    else:
        raise ValueError("discrete_catenary: could not bracket the root from above")
    return lo, hi


def discrete_catenary(
    masses: ArrayLike,
    link_lengths: ArrayLike,
    g: float,
    left: ArrayLike,
    right: ArrayLike,
    axial_stiffness: ArrayLike | None = None,
) -> CatenaryResult:
    """Exact equilibrium of a chain hanging between ``left`` (node 0) and ``right`` (node N-1).

    With ``axial_stiffness`` (EA per link, or one for all) the links are elastic: a link of
    unstretched length l_k pulling with T_k is ``l_k (1 + T_k / EA_k)`` long, in place of ``l_k``
    below (span and height still increase with H and V_0, so the same root-finds apply), and the
    chain may be stretched between supports farther apart than its unstretched length.

    Derivation (``docs/model.md``, "The discrete catenary"). Write the force in link k as the vector
    ``(H, V_k)`` pointing from node k to node k+1 (the pull it exerts on node k). Force balance
    at a free node i: gravity ``(0, -g m_i)`` + link i pulls ``(H, V_i)`` + link i-1 pulls
    ``-(H, V_{i-1})`` = 0, so H is the same in every link and ``V_i = V_{i-1} + g m_i``:
    ``V_k = V_0 + g sum_{i=1..k} m_i``. A taut link lies along its force, so
    ``p_{k+1} - p_k = l_k (H, V_k) / T_k`` with ``T_k = hypot(H, V_k)``, and the chain closes on
    the right support when

        span(H, V_0)   = sum_k l_k H   / T_k = x_right - x_left
        height(H, V_0) = sum_k l_k V_k / T_k = y_right - y_left.

    For fixed H the height is strictly increasing in V_0 (from -L to +L), so it fixes V_0(H)
    by a bracketed root-find; the span at V_0(H) then increases with H (from 0 to L), which
    fixes H by a second bracketed root-find in log H. Both run to the limits of double precision.

    Reactions from balance at the support nodes (whose own masses go straight into them):
    node 0: ``(0, -g m_0) + (H, V_0) + R_left = 0``; node N-1: ``(0, -g m_{N-1}) - (H, V_{N-2}) + R_right = 0``.

    Requires ``x_right > x_left`` and a chain longer than the distance between the supports.
    """
    m = np.asarray(masses, dtype=np.float64)
    lengths = np.asarray(link_lengths, dtype=np.float64)
    p_left = np.asarray(left, dtype=np.float64)
    p_right = np.asarray(right, dtype=np.float64)
    n = m.size
    if n < 2 or lengths.shape != (n - 1,):
        raise ValueError("discrete_catenary: need N >= 2 masses and N-1 link lengths")
    if np.any(m < 0) or np.any(lengths <= 0) or not g > 0:
        raise ValueError("discrete_catenary: masses must be >= 0, link lengths and g > 0")
    dx, dy = p_right - p_left
    total_length = float(lengths.sum())
    if not dx > 0:
        raise ValueError("discrete_catenary: the right support must lie to the right of the left one")
    compliance = np.zeros(n - 1) if axial_stiffness is None else 1.0 / np.broadcast_to(axial_stiffness, (n - 1,))
    if axial_stiffness is None and not math.hypot(dx, dy) < total_length:
        raise ValueError("discrete_catenary: the chain is too short to be slack between its supports")

    # V_k - V_0 = g * (m_1 + ... + m_k): the weight of the free nodes 1..k.
    offsets = np.concatenate(([0.0], g * np.cumsum(m[1 : n - 1])))
    weight = g * float(m.sum())
    force_scale = weight if weight > 0 else 1.0

    def directions(h: float, v0: float) -> tuple[np.ndarray, np.ndarray]:
        v = v0 + offsets
        t = np.hypot(h, v)
        return v, t

    def height_residual(h: float, v0: float) -> float:
        v, t = directions(h, v0)
        return float(np.sum(lengths * (1.0 + t * compliance) * (v / t))) - dy

    def v0_of(h: float) -> float:
        scale = force_scale + h
        lo, hi = _expand_bracket(lambda v0: height_residual(h, v0), -offsets[-1] - scale, scale)
        return float(
            brentq(lambda v0: height_residual(h, v0), lo, hi, xtol=1e-16 * scale, rtol=4 * np.finfo(float).eps)
        )

    def span_residual(log_h: float) -> float:
        h = math.exp(log_h)
        _, t = directions(h, v0_of(h))
        return float(np.sum(lengths * (1.0 + t * compliance) * (h / t))) - dx

    log_scale = math.log(force_scale)
    lo, hi = _expand_bracket(span_residual, log_scale - 1.0, log_scale + 1.0)
    log_h = float(brentq(span_residual, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps))
    h = math.exp(log_h)
    v0 = v0_of(h)
    v, t = directions(h, v0)

    steps = (lengths * (1.0 + t * compliance))[:, None] * np.column_stack((h / t, v / t))
    positions = np.vstack((p_left, p_left + np.cumsum(steps, axis=0)))
    reaction_left = np.array([-h, g * m[0] - v[0]])
    reaction_right = np.array([h, g * m[-1] + v[-1]])
    return CatenaryResult(
        positions=positions,
        tension=t,
        H=h,
        V=v,
        reaction_left=reaction_left,
        reaction_right=reaction_right,
    )


@dataclass(frozen=True)
class ElasticCatenary:
    """The continuous elastic catenary (Irvine, *Cable Structures*, 1981): a cable of unstretched
    length ``L0``, axial stiffness ``EA`` and weight ``w`` per unstretched length between a lower end
    A at the origin and an end B at ``(span, rise)``. ``H``: the horizontal tension (the same
    everywhere), ``V_A``: the vertical component of the tension at A (pointing along the cable from A
    to B); at unstretched arclength s from A the tension is ``(H, V_A + w s)``."""

    L0: float
    EA: float
    w: float
    H: float
    V_A: float

    def point(self, s: ArrayLike) -> np.ndarray:
        """Where the material point at unstretched arclength ``s`` from A lies, (k, 2)."""
        s = np.asarray(s, dtype=np.float64)
        h, v_a, w, ea = self.H, self.V_A, self.w, self.EA
        v = v_a + w * s
        x = h * s / ea + (h / w) * (np.arcsinh(v / h) - np.arcsinh(v_a / h))
        y = (v_a * s + 0.5 * w * s * s) / ea + (np.hypot(h, v) - np.hypot(h, v_a)) / w
        return np.column_stack((x, y))

    def tension(self, s: ArrayLike) -> np.ndarray:
        return np.hypot(self.H, self.V_A + self.w * np.asarray(s, dtype=np.float64))


def elastic_catenary(L0: float, EA: float, w: float, span: float, rise: float) -> ElasticCatenary:
    """The elastic catenary between (0, 0) and (span, rise), span > 0: for fixed H the end's height
    increases with V_A, which fixes V_A(H) by a bracketed root-find; the end's horizontal position
    then increases with H, which fixes H (both to double precision)."""

    def end(h: float, v_a: float) -> np.ndarray:
        return ElasticCatenary(L0, EA, w, h, v_a).point([L0])[0]

    def v_a_of(h: float) -> float:
        scale = w * L0 + h
        lo, hi = _expand_bracket(lambda v: end(h, v)[1] - rise, -w * L0 - scale, scale)
        return float(brentq(lambda v: end(h, v)[1] - rise, lo, hi, xtol=1e-15 * scale, rtol=4 * np.finfo(float).eps))

    def span_residual(log_h: float) -> float:
        h = math.exp(log_h)
        return float(end(h, v_a_of(h))[0]) - span

    start = math.log(w * L0)
    lo, hi = _expand_bracket(span_residual, start - 1.0, start + 1.0)
    h = math.exp(brentq(span_residual, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps))
    return ElasticCatenary(L0, EA, w, h, v_a_of(h))
