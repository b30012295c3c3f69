"""Exact hanging ropes and chains, computed without the interior-point solver.

* :class:`ContinuousCatenary`: a uniform inextensible rope between two supports, in closed form.
* :func:`dangling_rope_tension`: the continuous rope hanging from one end.
* :func:`dangling_chain`: N equal point masses hanging from node 0 (the seed's example), exact.
* :func:`discrete_catenary`: N point masses on taut links between supports at node 0 and node
  N-1, exact to machine precision by a nested scalar root-find.

Conventions follow ``docs/model.md``: gravity ``g`` acts in -y, a force is what acts
*on* the chain, a support reaction is the force the support exerts on the chain.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from funicular.errors import ScenarioError
from funicular.model import FloatArray

EPS = float(np.finfo(np.float64).eps)
SERIES_BELOW = 1.0  # sinh(z) - z by its Taylor series for z below this (no cancellation)
SINHC_STEPS = 100  # _solve_sinhc: Newton steps, bisections where a step leaves the bracket
MAX_BRACKET_STEPS = 10  # doubling steps of a bracket in log H: it reaches e^(+-1023) around the start


# --------------------------------------------------------------------------- stable scalar functions
def sinh_minus_identity(z: float) -> float:
    """``sinh(z) - z`` for ``z >= 0``, without cancellation for small z (Taylor series below 1)."""
    if z >= SERIES_BELOW:
        return math.sinh(z) - z  # sinh(z) - z >= 0.175 z here: at most a few ulps lost
    term, total, k = z, 0.0, 1
    while True:  # sum_{k >= 1} z^(2k+1) / (2k+1)!
        term *= z * z / ((2 * k) * (2 * k + 1))
        if term <= EPS * total:
            return total
        total += term
        k += 1


def log_sinhc(u: float) -> float:
    """``log(sinh(u) / u)`` for ``u > 0``, finite for every finite u.

    Small u: ``log1p((sinh(u) - u) / u)`` with the series above, so ``u^2/6`` is not lost to
    rounding. Large u: ``sinh(u) = e^u (1 - e^(-2u)) / 2`` gives ``u - log(2u) + log1p(-e^(-2u))``,
    which never evaluates sinh and so cannot overflow.
    """
    if u < SERIES_BELOW:
        return math.log1p(sinh_minus_identity(u) / u)
    return u - math.log(2.0 * u) + math.log1p(-math.exp(-2.0 * u))


def _solve_sinhc(excess: float) -> float:
    """The u > 0 with ``sinh(u)/u = 1 + excess`` (excess > 0), by Newton's method in ``log u`` on
    ``log(sinh(u)/u)``, safeguarded by bisection.

    The bracket is exact: ``1 + u^2/6 <= sinh(u)/u <= exp(u^2/6)`` for all u, so the root lies in
    ``[sqrt(6 log(1 + excess)), sqrt(6 excess)]``. Working in ``log u`` keeps the steps sensible
    from u = 1e-8 (a nearly taut rope) to u = 700 (sinh(u)/u = 1e300). (No scipy.optimize: the
    solver's exact start uses this too, and importing it slows every CLI start by 0.4 s.)
    """
    target = math.log1p(excess)
    low, high = 0.5 * math.log(6.0 * target), 0.5 * math.log(6.0 * excess)
    s = 0.5 * (low + high)
    for _ in range(SINHC_STEPS):
        u = math.exp(s)
        value = log_sinhc(u) - target
        if value > 0.0:
            high = s
        else:
            low = s
        slope = u / math.tanh(u) - 1.0 if u < 20.0 else u - 1.0  # d log(sinh(u)/u) / d log u
        step = s - value / slope if slope > 0.0 else 0.5 * (low + high)
        s_next = step if low < step < high else 0.5 * (low + high)
        if abs(s_next - s) <= 1e-15 * max(1.0, abs(s)):
            return math.exp(s_next)
        s = s_next
    return math.exp(s)


# --------------------------------------------------------------------------- continuous catenary
@dataclass(frozen=True)
class ContinuousCatenary:
    """A uniform rope of length L and weight w per length between two supports (closed form).

    Shape ``y = a cosh((x - x0)/a) + c``; horizontal force ``H = w a`` everywhere; vertical force
    ``V(s) = w (a sinh(xi_left) + s)`` at arclength s from the left support; tension
    ``T(s) = hypot(H, V(s)) = w a cosh((x - x0)/a)``.

    How ``a`` is found: the length between the supports satisfies
    ``sqrt(L^2 - h^2) = 2 a sinh(D / (2a))`` (D: horizontal span, h: height difference). With
    ``u = D/(2a)`` this is ``sinh(u)/u = sqrt(L^2 - h^2)/D``, solved in ``log u`` on
    ``log(sinh(u)/u)`` (see :func:`log_sinhc`), which cannot overflow. The right-hand side minus
    one is formed as ``(L - d)(L + d) / (D (sqrt(L^2 - h^2) + D))`` (d: support distance) so that a
    nearly taut rope keeps its few significant digits. Everything else follows without sinh or
    cosh of large arguments: ``a sinh(xi_left) = (h coth(u) - L)/2``.

    Attributes:
        left, right: the support positions, ``right[0] > left[0]``.
        length: L, longer than the distance between the supports.
        weight_per_length: w = g M / L.
        a: the catenary parameter H / w.
        x0, c: the vertex abscissa and the offset in ``y = a cosh((x - x0)/a) + c``.
        u: D / (2a).
        arc_left: ``a sinh(xi_left)``, the signed arclength from the vertex to the left support
            (negative when the vertex lies to the right of it).
    """

    left: tuple[float, float]
    right: tuple[float, float]
    length: float
    weight_per_length: float
    a: float
    x0: float
    c: float
    u: float
    arc_left: float

    @classmethod
    def between(
        cls, left: ArrayLike, right: ArrayLike, length: float, weight_per_length: float = 1.0
    ) -> ContinuousCatenary:
        """The catenary through ``left`` and ``right`` with the given length and weight per length."""
        (xl, yl), (xr, yr) = (_point(left, "left"), _point(right, "right"))
        span, rise = xr - xl, yr - yl
        if span == 0.0:
            raise ScenarioError(
                "a catenary needs supports at different x; vertically aligned supports make the rope fold "
                "into a vertical double line."
            )
        if span < 0.0:
            raise ScenarioError(f"the left support (x = {xl}) must lie to the left of the right one (x = {xr}).")
        distance = math.hypot(span, rise)
        if not (math.isfinite(length) and length > distance):
            raise ScenarioError(
                f"a catenary of length {length} cannot hang between supports {distance} apart; "
                "it must be longer than their distance."
            )
        if not (math.isfinite(weight_per_length) and weight_per_length > 0):
            raise ScenarioError(f"weight per length = {weight_per_length}; it must be > 0.")
        vertical_length = math.sqrt((length - rise) * (length + rise))  # sqrt(L^2 - h^2)
        excess = (length - distance) * (length + distance) / (span * (vertical_length + span))
        u = _solve_sinhc(excess)
        a = span / (2.0 * u)
        arc_left = 0.5 * (rise / math.tanh(u) - length)
        xi_left = math.asinh(arc_left / a)
        return cls(
            left=(xl, yl),
            right=(xr, yr),
            length=float(length),
            weight_per_length=float(weight_per_length),
            a=a,
            x0=xl - a * xi_left,
            c=yl - math.hypot(a, arc_left),
            u=u,
            arc_left=arc_left,
        )

    @property
    def horizontal_force(self) -> float:
        """H = w a, the same at every point of the rope."""
        return self.weight_per_length * self.a

    def y(self, x: ArrayLike) -> FloatArray:
        """Height of the rope above ``x`` (left[0] <= x <= right[0]), without cancellation."""
        x = np.asarray(x, dtype=np.float64)
        xi = (x - self.x0) / self.a
        xi_left = (self.left[0] - self.x0) / self.a
        # cosh(xi) - cosh(xi_left) = 2 sinh((xi + xi_left)/2) sinh((xi - xi_left)/2)
        lift = 2.0 * self.a * np.sinh(0.5 * (xi + xi_left)) * np.sinh(0.5 * (x - self.left[0]) / self.a)
        result: FloatArray = self.left[1] + lift
        return result

    def position_at_arclength(self, s: ArrayLike) -> FloatArray:
        """Points (…, 2) at arclength ``s`` (0 <= s <= L) from the left support."""
        s = np.asarray(s, dtype=np.float64)
        a, arc0 = self.a, self.arc_left
        arc = arc0 + s  # a sinh(xi) at s
        x = self.left[0] + a * (np.arcsinh(arc / a) - math.asinh(arc0 / a))
        # y - y_left = a (cosh xi - cosh xi_left) = s (arc + arc0) / (a cosh xi + a cosh xi_left)
        y = self.left[1] + s * (arc + arc0) / (np.hypot(a, arc) + math.hypot(a, arc0))
        points = np.empty((*s.shape, 2))  # (np.stack's wrapper costs more than a few points)
        points[..., 0], points[..., 1] = x, y
        return points

    def vertical_force_at_arclength(self, s: ArrayLike) -> FloatArray:
        """V(s) = w (a sinh(xi_left) + s): the upward component of the rope force pulling towards larger s."""
        result: FloatArray = self.weight_per_length * (self.arc_left + np.asarray(s, dtype=np.float64))
        return result

    def tension_at_arclength(self, s: ArrayLike) -> FloatArray:
        """T(s) = hypot(H, V(s)) = w a cosh((x(s) - x0)/a)."""
        result: FloatArray = np.hypot(self.horizontal_force, self.vertical_force_at_arclength(s))
        return result

    @property
    def reactions(self) -> FloatArray:
        """Forces the left and right supports exert on the rope, (2, 2): ``(-H, -V(0))`` and ``(H, V(L))``."""
        h = self.horizontal_force
        v = self.vertical_force_at_arclength(np.array([0.0, self.length]))
        return np.array([[-h, -v[0]], [h, v[1]]])

    @property
    def lowest_point(self) -> tuple[float, float]:
        """The rope's lowest point: its vertex ``(x0, c + a)`` where that lies on the rope (the
        vertical force vanishes there, ``0 < -arc_left < L``), else the lower support."""
        if 0.0 < -self.arc_left < self.length:
            # c + a = y_left - (a cosh(xi_left) - a), written without the cancellation for a large a
            arc = self.arc_left
            return self.x0, self.left[1] - arc * arc / (math.hypot(self.a, arc) + self.a)
        return min(self.left, self.right, key=lambda point: point[1])

    @property
    def max_tension(self) -> float:
        """The largest tension, at one of the supports."""
        return float(self.tension_at_arclength(np.array([0.0, self.length])).max())

    def height_integral(self) -> float:
        """``integral of y ds`` over the rope, in closed form without cancellation.

        Derivation: with ``xi`` from ``xi_left = m - u`` to ``xi_right = m + u``,
        ``integral (y - y_left) ds = a^2 integral (cosh xi - cosh xi_left) cosh xi dxi
        = a^2 [sinh(2m) sinh(u)^2 - (sinh(2u) - 2u)/2] = h L / 2 - a^2 (sinh(2u) - 2u)/2``,
        using ``a sinh(u) = sqrt(L^2 - h^2)/2`` and ``sinh(m) = h / sqrt(L^2 - h^2)``.
        For ``u >= 1``, ``a^2 (sinh(2u) - 2u)/2 = (L^2 - h^2)/4 coth(u) - a D/2`` (no overflow).
        """
        (xl, yl), (xr, yr) = self.left, self.right
        length, a, u = self.length, self.a, self.u
        if u < SERIES_BELOW:
            sag = 0.5 * a * a * sinh_minus_identity(2.0 * u)
        else:
            rise = yr - yl
            sag = 0.25 * (length - rise) * (length + rise) / math.tanh(u) - 0.5 * a * (xr - xl)
        return 0.5 * length * (yl + yr) - sag

    def energy(self, total_mass: float, g: float) -> float:
        """Potential energy ``g (M / L) integral y ds`` of a uniform rope of this shape and mass M."""
        return g * total_mass / self.length * self.height_integral()


def _point(value: ArrayLike, name: str) -> tuple[float, float]:
    if isinstance(value, tuple) and len(value) == 2 and all(type(v) is float and math.isfinite(v) for v in value):
        return value  # (the solver's exact start passes such pairs: numpy's checks cost 10 us a pair)
    point = np.asarray(value, dtype=np.float64)
    if point.shape != (2,) or not np.all(np.isfinite(point)):
        raise ScenarioError(f"the {name} support must be a finite point (x, y), got {value!r}.")
    return float(point[0]), float(point[1])


# --------------------------------------------------------------------------- dangling rope and chain
def dangling_rope_tension(s: ArrayLike, total_mass: float, length: float, g: float) -> FloatArray:
    """Tension of a uniform rope hanging from one end at arclength s from the top: ``M g (L - s)/L``."""
    result: FloatArray = total_mass * g * (length - np.asarray(s, dtype=np.float64)) / length
    return result


@dataclass(frozen=True)
class DanglingChain:
    """N equal masses M/N hanging from node 0 on taut vertical links of length l = L/(N-1).

    tension[k] = M g (N-1-k)/N (0-based; the seed's 1-based ``M g (N-k)/N``): the weight below link k.
    squared_multipliers[k] = tension[k] / (2 l) = M g (N-1-k)(N-1) / (2 N L); the largest,
    ``M g (N-1)^2 / (2 N L)``, grows like N. (The seed's closed forms drop the factor (N-1)/N.)
    """

    tension: FloatArray
    squared_multipliers: FloatArray
    energy: float  # g sum m_i y_i with the top at height `top`


def dangling_chain(nodes: int, total_mass: float, length: float, g: float, top: float = 0.0) -> DanglingChain:
    """The exact dangling chain (see :class:`DanglingChain`)."""
    k = np.arange(nodes - 1, dtype=np.float64)
    tension = total_mass * g * (nodes - 1 - k) / nodes
    link = length / (nodes - 1)
    heights = top - link * np.arange(nodes)
    return DanglingChain(
        tension=tension,
        squared_multipliers=tension / (2.0 * link),
        energy=float(g * total_mass / nodes * heights.sum()),
    )


# --------------------------------------------------------------------------- discrete catenary
@dataclass(frozen=True)
class DiscreteCatenary:
    """Equilibrium of point masses on taut links between supports at node 0 and node N-1.

    positions (N, 2); tension (N-1,); horizontal_force H (the same in every link);
    vertical_force (N-1,): V_k, the upward component of the force in link k pulling node k towards
    node k+1; reactions (2, 2): the forces the left and right supports exert on nodes 0 and N-1;
    energy ``g sum m_i y_i``.
    """

    positions: FloatArray
    tension: FloatArray
    horizontal_force: float
    vertical_force: FloatArray
    reactions: FloatArray
    energy: float


def discrete_catenary(
    masses: ArrayLike, link_lengths: ArrayLike, g: float, left: ArrayLike, right: ArrayLike
) -> DiscreteCatenary:
    """The exact discrete catenary: every link taut, no obstacle.

    Force balance at a free node i (gravity ``(0, -g m_i)``, link i pulling with ``(H, V_i)``, link
    i-1 with ``-(H, V_{i-1})``) makes H the same in every link and ``V_k = V_0 + g (m_1 + ... + m_k)``.
    A taut link points along its force, so the chain reaches the right support when

        sum_k l_k H / T_k = D (span)   and   sum_k l_k V_k / T_k = h (rise),   T_k = hypot(H, V_k).

    Inner root-find: for fixed H, the rise increases with V_0, and ``V_k / T_k >= sigma = h / L``
    for all k exactly when ``V_0 >= H sigma / sqrt(1 - sigma^2)``; so V_0 lies in
    ``[H kappa - W, H kappa]`` (kappa = sigma / sqrt(1 - sigma^2), W = weight of the free nodes),
    an exact bracket for brentq. Outer root-find: the span at ``V_0(H)`` increases with H from
    (nearly) 0 to L; brentq on ``log H``, bracketed by doubling steps in ``log H``.
    """
    from scipy.optimize import brentq  # imported here: scipy.optimize slows every CLI start by 0.4 s

    m = np.asarray(masses, dtype=np.float64)
    lengths = np.asarray(link_lengths, dtype=np.float64)
    (xl, yl), (xr, yr) = _point(left, "left"), _point(right, "right")
    n = m.size
    if n < 3 or lengths.shape != (n - 1,):
        raise ScenarioError("a discrete catenary needs at least 3 nodes and one link length per link.")
    if np.any(m < 0) or np.any(lengths <= 0) or not g > 0:
        raise ScenarioError("a discrete catenary needs masses >= 0, link lengths > 0 and g > 0.")
    span, rise = xr - xl, yr - yl
    total_length = float(lengths.sum())
    if not span > 0:
        raise ScenarioError(f"the left support (x = {xl}) must lie strictly left of the right one (x = {xr}).")
    if not math.hypot(span, rise) < total_length:
        raise ScenarioError("a discrete catenary needs a chain longer than the distance between its supports.")
    lifted = np.concatenate(([0.0], g * np.cumsum(m[1:-1])))  # V_k - V_0
    free_weight = float(lifted[-1])
    if not free_weight > 0:
        raise ScenarioError("a discrete catenary needs a positive mass between the supports.")
    kappa = rise / math.sqrt((total_length - rise) * (total_length + rise))

    def vertical_at_left(h: float) -> float:
        def rise_residual(v0: float) -> float:
            v = v0 + lifted
            return float(np.sum(lengths * v / np.hypot(h, v))) - rise

        hi = h * kappa
        lo = hi - free_weight
        if rise_residual(lo) >= 0.0:
            return lo
        if rise_residual(hi) <= 0.0:
            return hi
        tol = 4 * EPS * (abs(hi) + free_weight)
        return float(brentq(rise_residual, lo, hi, xtol=tol, rtol=4 * EPS, maxiter=500))

    def span_residual(log_h: float) -> float:
        h = math.exp(log_h)
        v = vertical_at_left(h) + lifted
        return float(np.sum(lengths * h / np.hypot(h, v))) - span

    lo, hi = _bracket_increasing(span_residual, math.log(free_weight))
    h = math.exp(float(brentq(span_residual, lo, hi, xtol=1e-15, rtol=4 * EPS, maxiter=500)))
    v = vertical_at_left(h) + lifted
    tension = np.hypot(h, v)
    steps = lengths[:, None] * np.column_stack((h / tension, v / tension))
    start = np.array([xl, yl])
    positions = np.vstack((start, start + np.cumsum(steps, axis=0)))
    reactions = np.array([[-h, g * m[0] - v[0]], [h, g * m[-1] + v[-1]]])
    return DiscreteCatenary(
        positions=positions,
        tension=tension,
        horizontal_force=h,
        vertical_force=v,
        reactions=reactions,
        energy=float(g * m @ positions[:, 1]),
    )


def _bracket_increasing(f: Callable[[float], float], center: float) -> tuple[float, float]:
    """``lo < hi`` around ``center`` with ``f(lo) < 0 < f(hi)`` for an increasing f, by doubling steps."""
    lo, hi, step = center - 1.0, center + 1.0, 1.0
    for _ in range(MAX_BRACKET_STEPS):
        if f(lo) < 0.0:
            break
        lo, step = lo - step, 2 * step
    else:
        raise ScenarioError(
            "discrete catenary: no equilibrium with every link taut (few nodes on a steep chord: a link hangs slack)."
        )
    step = 1.0
    for _ in range(MAX_BRACKET_STEPS):
        if f(hi) > 0.0:
            break
        hi, step = hi + step, 2 * step
    else:
        raise ScenarioError("discrete catenary: no horizontal force is large enough; is the chain nearly taut?")
    return lo, hi
