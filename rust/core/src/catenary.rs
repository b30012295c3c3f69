//! An exact start for a chain that touches nothing: each span a discrete catenary.
//!
//! Between two consecutive supports a and b, a chain that touches no obstacle and carries weight on
//! its interior nodes has every link taut, the same horizontal force H in every link, and the
//! vertical force `V_k = V_0 + g (m_{a+1} + ... + m_{a+k})` in link a+k. Two conditions close it:
//! the links, each pointing along its force, reach support b,
//!
//! ```text
//! F_1 = sum_k l_k H / T_k - D = 0,   F_2 = sum_k l_k V_k / T_k - h = 0,   T_k = |(H, V_k)|
//! ```
//!
//! (D the horizontal span, h the rise; the span lies in the vertical plane through its supports).
//! Newton's method on `(log H, psi)` with `V_0 = H kappa + W psi` ([`hanging_span`]), from the
//! continuous catenary of the same length and weight ([`Rope`]), solves them in a handful of O(n)
//! passes. A free end hangs straight down, each link carrying the weight below it.
//!
//! When every span is solved this way and every free node is outside every obstacle, this is the
//! equilibrium, and the solver starts from it with its tensions: the polish confirms it in one
//! Newton step. (An almost taut span, 1e-9 of slack on a slant, has tensions 10^4 times the weight;
//! the interior-point method from a sagging guess does not get there in 200 steps.)

use crate::linalg::norm;
use crate::presolve::{along_chord, is_taut, massless_ends};
use crate::problem::Interrupted;
use crate::problem::{Chain, Shapes};

const NEWTON_STEPS: usize = 60;
const BACKTRACKS: usize = 30;
/// F_1 and F_2 relative to the span's length: converged ...
const SPAN_RTOL: f64 = 1e-14;
/// ... or good enough to start from when Newton stalls at rounding.
const ACCEPT_RTOL: f64 = 1e-11;
/// The largest Newton step in log H and in psi.
const MAX_STEP: f64 = 2.0;
/// |log H| beyond this over- or underflows.
const MAX_LOG: f64 = 700.0;
/// `hanging_span` gives up when its starting rope lies deeper in an obstacle than CLEARANCE of its
/// length or CLEARANCE_LINKS of its longest link, whichever is less (a uniform chain's nodes lie
/// within about a link of the rope; a chain whose masses are far from uniform may be skipped
/// although it is clear: it then takes the general path).
const CLEARANCE: f64 = 0.02;
const CLEARANCE_LINKS: f64 = 4.0;
/// Points of the starting rope checked against the obstacles.
const ROPE_POINTS: usize = 1024;
/// A span this much narrower than long folds up: left to the solver.
const VERTICAL_RTOL: f64 = 1e-6;
/// `sinh(z) - z` by its Taylor series below this (no cancellation).
const SERIES_BELOW: f64 = 1.0;
/// Newton steps of `solve_sinhc` (bisection where a step leaves the bracket).
const SINHC_STEPS: usize = 100;

/// Positions ((nodes) x d) and link tensions of a chain or a span in equilibrium.
pub type Hanging = (Vec<f64>, Vec<f64>);

/// `sinh(z) - z` for `z >= 0`, without cancellation for small z (Taylor series below 1).
fn sinh_minus_identity(z: f64) -> f64 {
    if z >= SERIES_BELOW {
        return z.sinh() - z; // >= 0.175 z here: at most a few ulps lost
    }
    let (mut term, mut total, mut k) = (z, 0.0, 1.0);
    loop {
        // sum_{k >= 1} z^(2k+1) / (2k+1)!
        term *= z * z / ((2.0 * k) * (2.0 * k + 1.0));
        if term <= f64::EPSILON * total {
            return total;
        }
        total += term;
        k += 1.0;
    }
}

/// `log(sinh(u) / u)` for `u > 0`, finite for every finite u: `log1p((sinh(u) - u) / u)` for small
/// u, `u - log(2u) + log1p(-e^(-2u))` for large u (no sinh, so no overflow).
fn log_sinhc(u: f64) -> f64 {
    if u < SERIES_BELOW {
        return (sinh_minus_identity(u) / u).ln_1p();
    }
    u - (2.0 * u).ln() + (-(-2.0 * u).exp()).ln_1p()
}

/// The u > 0 with `sinh(u)/u = 1 + excess` (excess > 0), by Newton's method in `log u` on
/// `log(sinh(u)/u)`, safeguarded by bisection. The bracket is exact: `1 + u^2/6 <= sinh(u)/u <=
/// exp(u^2/6)`, so the root lies in `[sqrt(6 log(1 + excess)), sqrt(6 excess)]`.
fn solve_sinhc(excess: f64) -> f64 {
    let target = excess.ln_1p();
    let (mut low, mut high) = (0.5 * (6.0 * target).ln(), 0.5 * (6.0 * excess).ln());
    let mut s = 0.5 * (low + high);
    for _ in 0..SINHC_STEPS {
        let u = s.exp();
        let value = log_sinhc(u) - target;
        if value > 0.0 {
            high = s;
        } else {
            low = s;
        }
        // d log(sinh(u)/u) / d log u
        let slope = if u < 20.0 { u / u.tanh() - 1.0 } else { u - 1.0 };
        let step = if slope > 0.0 {
            s - value / slope
        } else {
            0.5 * (low + high)
        };
        let next = if low < step && step < high {
            step
        } else {
            0.5 * (low + high)
        };
        if (next - s).abs() <= 1e-15 * s.abs().max(1.0) {
            return next.exp();
        }
        s = next;
    }
    s.exp()
}

/// A uniform rope of length L and weight w per length from (0, 0) to (span, rise), span > 0:
/// `y = a cosh((x - x0)/a) + c`, horizontal force `H = w a`, vertical force `w (arc_left + s)` at
/// arclength s. `a` solves `sqrt(L^2 - h^2) = 2 a sinh(D / (2a))`, written as `sinh(u)/u = 1 +
/// excess` with `u = D/(2a)` and the excess formed without cancellation for a nearly taut rope.
pub struct Rope {
    pub length: f64,
    pub weight_per_length: f64,
    pub a: f64,
    /// `a sinh(xi_left)`: the signed arclength from the vertex to the left end.
    pub arc_left: f64,
}

impl Rope {
    /// The rope, or None where the chord is within rounding of the length (or not shorter).
    pub fn between(span: f64, rise: f64, length: f64, weight_per_length: f64) -> Option<Rope> {
        let distance = span.hypot(rise);
        if !(span > 0.0 && length.is_finite() && length > distance) {
            return None;
        }
        let vertical_length = ((length - rise) * (length + rise)).sqrt(); // sqrt(L^2 - h^2)
        let excess = (length - distance) * (length + distance) / (span * (vertical_length + span));
        if !(excess > 0.0 && excess.is_finite()) {
            return None;
        }
        let u = solve_sinhc(excess);
        Some(Rope {
            length,
            weight_per_length,
            a: span / (2.0 * u),
            arc_left: 0.5 * (rise / u.tanh() - length),
        })
    }

    pub fn horizontal_force(&self) -> f64 {
        self.weight_per_length * self.a
    }

    /// The point at arclength s from the left end.
    pub fn position_at_arclength(&self, s: f64) -> (f64, f64) {
        let (a, arc0) = (self.a, self.arc_left);
        let arc = arc0 + s; // a sinh(xi) at s
        let x = a * ((arc / a).asinh() - (arc0 / a).asinh());
        // y = a (cosh xi - cosh xi_left) = s (arc + arc0) / (a cosh xi + a cosh xi_left)
        let y = s * (arc + arc0) / (a.hypot(arc) + a.hypot(arc0));
        (x, y)
    }

    /// The rope's lowest point: its vertex where that lies on the rope (the vertical force vanishes
    /// there, `0 < -arc_left < L`), else the lower end.
    pub fn lowest_point(&self, span: f64, rise: f64) -> (f64, f64) {
        let arc = self.arc_left;
        if 0.0 < -arc && -arc < self.length {
            let (x, _) = self.position_at_arclength(-arc);
            // c + a - y_left, without the cancellation for a large a
            return (x, -arc * arc / (self.a.hypot(arc) + self.a));
        }
        if rise < 0.0 {
            (span, rise)
        } else {
            (0.0, 0.0)
        }
    }
}

/// How deep each point lies inside obstacle j, to first order `phi / |grad phi|` (infinite with
/// phi's sign where the gradient vanishes, NaN where phi or its gradient is not finite).
fn deepest_point(shapes: &mut dyn Shapes, d: usize, points: &[f64]) -> Result<f64, Interrupted> {
    let n = points.len() / d;
    let (mut phi, mut gradient) = (vec![0.0; n], vec![0.0; n * d]);
    let mut deepest = f64::NEG_INFINITY;
    for j in 0..shapes.count() {
        shapes.evaluate(j, points, &mut phi, &mut gradient)?;
        for (k, g) in gradient.chunks_exact(d).enumerate() {
            let depth = phi[k] / norm(g);
            // (a NaN depth is not deeper than anything)
            if depth > deepest {
                deepest = depth;
            }
        }
    }
    Ok(deepest)
}

/// Interior node positions ((n - 1) x d) and link tensions (n) of n links hanging between `left`
/// and `right` with every link taut, or None if there is no weight between them, the span is
/// nearly vertical, or Newton's method does not converge. With obstacles, also None at once if the
/// uniform rope it starts from goes deeper into one than CLEARANCE of its length or
/// CLEARANCE_LINKS links: the chain would too, and the Newton steps would be wasted. The caller
/// checks the answer against the obstacles either way.
pub fn hanging_span(
    interior_masses: &[f64],
    lengths: &[f64],
    g: f64,
    left: &[f64],
    right: &[f64],
    shapes: &mut dyn Shapes,
) -> Result<Option<Hanging>, Interrupted> {
    let d = left.len();
    let total: f64 = lengths.iter().sum();
    // the horizontal direction from left to right, the span along it and the rise
    let across: Vec<f64> = (0..d - 1).map(|i| right[i] - left[i]).collect();
    let span = norm(&across);
    let rise = right[d - 1] - left[d - 1];
    let distance = span.hypot(rise);
    let unit = g * interior_masses.iter().sum::<f64>();
    if !(span > VERTICAL_RTOL * total && distance < total && unit > 0.0 && unit.is_finite()) {
        return Ok(None);
    }
    let plane = Plane {
        left,
        horizontal: across.iter().map(|c| c / span).collect(),
    };
    // Forces in units of the span's weight W (the tensions are scaled back at the end). The start:
    // the uniform rope of the same length and weight between the same points.
    let Some(rope) = Rope::between(span, rise, total, 1.0 / total) else {
        return Ok(None);
    };
    if shapes.count() > 0 && rope_too_deep(shapes, &plane, &rope, lengths, span, rise)? {
        return Ok(None);
    }
    let n = lengths.len();
    // (V_k - V_0) / W
    let mut lifted = Vec::with_capacity(n);
    let mut weight = 0.0;
    lifted.push(0.0);
    for &m in interior_masses {
        weight += m;
        lifted.push((g / unit) * weight);
    }
    // V_0 = H kappa + W psi: for a fixed psi the links turn towards the chord as H grows, so the
    // Jacobian in (log H, psi) stays well conditioned for a nearly taut span (in (log H, V_0) the
    // two columns become parallel and Newton's steps overshoot). The solution has -1 <= psi <= 0.
    let kappa = rise / ((total - rise) * (total + rise)).sqrt();
    let equations = SpanEquations {
        lengths,
        lifted,
        kappa,
        span,
        rise,
    };
    let log_h = rope.horizontal_force().ln();
    let psi = rope.weight_per_length * rope.arc_left - rope.horizontal_force() * kappa;
    let Some((h, v, inverse)) = equations.solve(log_h, psi, total) else {
        return Ok(None);
    };
    // the interior nodes the links reach, each pointing along its force
    let mut positions = vec![0.0; (n - 1) * d];
    let (mut x, mut y) = (0.0, 0.0);
    for k in 0..n - 1 {
        x += h * (lengths[k] * inverse[k]);
        y += lengths[k] * v[k] * inverse[k];
        plane.place(x, y, &mut positions[k * d..k * d + d]);
    }
    let tension = inverse.iter().map(|i| unit / i).collect();
    Ok(Some((positions, tension)))
}

/// The vertical plane of a span: the point `x` along the horizontal direction from `left` and `y`
/// above it.
struct Plane<'a> {
    left: &'a [f64],
    horizontal: Vec<f64>,
}

impl Plane<'_> {
    fn place(&self, x: f64, y: f64, out: &mut [f64]) {
        let d = self.left.len();
        for i in 0..d - 1 {
            out[i] = self.left[i] + x * self.horizontal[i];
        }
        out[d - 1] = self.left[d - 1] + y;
    }
}

/// Whether the uniform `rope` between the span's ends (its lowest point and ROPE_POINTS along it)
/// goes deeper into an obstacle than CLEARANCE of its length or CLEARANCE_LINKS links.
fn rope_too_deep(
    shapes: &mut dyn Shapes,
    plane: &Plane,
    rope: &Rope,
    lengths: &[f64],
    span: f64,
    rise: f64,
) -> Result<bool, Interrupted> {
    let d = plane.left.len();
    let total: f64 = lengths.iter().sum();
    let longest = lengths.iter().copied().fold(0.0, f64::max);
    let limit = (CLEARANCE * total).min(CLEARANCE_LINKS * longest);
    let mut points = vec![0.0; (ROPE_POINTS + 1) * d];
    let (x, y) = rope.lowest_point(span, rise);
    plane.place(x, y, &mut points[..d]);
    for k in 0..ROPE_POINTS {
        let s = k as f64 * (total / (ROPE_POINTS - 1) as f64);
        let (x, y) = rope.position_at_arclength(s);
        plane.place(x, y, &mut points[(k + 1) * d..(k + 2) * d]);
    }
    Ok(deepest_point(shapes, d, &points)? > limit)
}

/// The two conditions that the links reach the far end of a span, in (log H, psi) with
/// `V_0 = H kappa + psi` (forces in units of the span's weight).
struct SpanEquations<'a> {
    lengths: &'a [f64],
    /// Each link's `(V_k - V_0) / W`.
    lifted: Vec<f64>,
    kappa: f64,
    span: f64,
    rise: f64,
}

impl SpanEquations<'_> {
    /// F_1, F_2 and H at (log H, psi), each link's V_k and 1 / T_k into `v` and `inverse`; None
    /// where they are not finite.
    fn forces(&self, log_h: f64, psi: f64, v: &mut [f64], inverse: &mut [f64]) -> Option<(f64, f64, f64)> {
        if !(log_h.abs() < MAX_LOG) {
            return None; // H over- or underflows: no equilibrium there
        }
        let h = log_h.exp();
        let (mut across, mut up) = (0.0, 0.0);
        for k in 0..self.lengths.len() {
            v[k] = (h * self.kappa + psi) + self.lifted[k];
            inverse[k] = 1.0 / (v[k] * v[k] + h * h).sqrt();
            across += self.lengths[k] * inverse[k];
            up += self.lengths[k] * (v[k] * inverse[k]);
        }
        let (f1, f2) = (h * across - self.span, up - self.rise);
        (f1.is_finite() && f2.is_finite()).then_some((f1, f2, h))
    }

    /// Newton's method from (log H, psi) on a span `total` long: H, each link's V_k and 1 / T_k;
    /// None where it does not reach ACCEPT_RTOL.
    fn solve(&self, mut log_h: f64, mut psi: f64, total: f64) -> Option<(f64, Vec<f64>, Vec<f64>)> {
        let n = self.lengths.len();
        let (mut v, mut inverse) = (vec![0.0; n], vec![0.0; n]);
        let mut here = self.forces(log_h, psi, &mut v, &mut inverse);
        let (mut trial_v, mut trial_inverse) = (vec![0.0; n], vec![0.0; n]);
        for _ in 0..NEWTON_STEPS {
            let (f1, f2, h) = here?;
            if f1.abs().max(f2.abs()) <= SPAN_RTOL * total {
                break;
            }
            let Some((d_log_h, d_psi)) = self.newton_step(f1, f2, h, &v, &inverse) else {
                break;
            };
            // At most a factor e^2 on H and a whole weight on V_0 per step: far from the solution
            // the linear model is poor, and a full step can throw H to 1e-67.
            let mut fraction = (MAX_STEP / d_log_h.abs().max(d_psi.abs()).max(1e-300)).min(1.0);
            let mut improved = false;
            for _ in 0..BACKTRACKS {
                let (l, p) = (log_h + fraction * d_log_h, psi + fraction * d_psi);
                if let Some(trial) = self.forces(l, p, &mut trial_v, &mut trial_inverse) {
                    if trial.0 * trial.0 + trial.1 * trial.1 < f1 * f1 + f2 * f2 {
                        (log_h, psi, here) = (l, p, Some(trial));
                        std::mem::swap(&mut v, &mut trial_v);
                        std::mem::swap(&mut inverse, &mut trial_inverse);
                        improved = true;
                        break;
                    }
                }
                fraction *= 0.5;
            }
            if !improved {
                break;
            }
        }
        let (f1, f2, h) = here?;
        (f1.abs().max(f2.abs()) <= ACCEPT_RTOL * total).then_some((h, v, inverse))
    }

    /// Newton's step (dlog H, dpsi) at F = (f1, f2), H = `h`; None where the Jacobian is singular.
    fn newton_step(&self, f1: f64, f2: f64, h: f64, v: &[f64], inverse: &[f64]) -> Option<(f64, f64)> {
        // d(F_1, F_2)/d(log H, V_0) = [[H a, -b], [-H b, c]] with l_k / T_k^3 weights, and
        // dV_0 = H kappa dlog H + dpsi (W = 1)
        let kappa = self.kappa;
        let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
        for k in 0..self.lengths.len() {
            let cubed = inverse[k] * inverse[k] * inverse[k] * self.lengths[k];
            a += cubed * (v[k] * v[k]);
            b += cubed * v[k];
            c += cubed;
        }
        let (b, c) = (h * b, h * h * c);
        let (j11, j12, j21, j22) = (h * (a - kappa * b), -b, h * (kappa * c - b), c);
        let det = j11 * j22 - j12 * j21;
        if !(det.is_finite() && det != 0.0) {
            return None;
        }
        Some((-(j22 * f1 - j12 * f2) / det, -(j11 * f2 - j21 * f1) / det))
    }
}

/// Positions (N, d) and link tensions (N - 1) of the chain's equilibrium if no node touches an
/// obstacle (see the module documentation), else None. Also None where this construction does not
/// apply and the solver must work: a span with no weight on its interior nodes (its links may hang
/// slack), a nearly vertical span (it folds), a span with elastic links that its supports stretch.
/// Elastic links are taken at their unstretched lengths: the inextensible chain's equilibrium is
/// then a start next to the elastic one (a strain away), which the polish corrects.
///
/// Two parts are left to the presolve, which replaces them: an exactly taut span gets its chord and
/// zero tensions here (the presolve fixes it with its own tensions), and massless free ends hang
/// straight down (the presolve rests them on the node they hang from; they are not checked against
/// the obstacles).
pub fn exact_start(chain: &Chain, shapes: &mut dyn Shapes) -> Result<Option<Hanging>, Interrupted> {
    let d = chain.dim;
    let n = chain.n_nodes();
    let (masses, lengths, g) = (&chain.masses, &chain.lengths, chain.gravity);
    let mut positions = vec![0.0; n * d];
    let mut tension = vec![0.0; n - 1];
    for (s, &node) in chain.supports.iter().enumerate() {
        positions[node * d..node * d + d].copy_from_slice(&chain.support_positions[s * d..s * d + d]);
    }
    for pair in chain.supports.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if b == a + 1 {
            continue;
        }
        let (left, right) = (
            positions[a * d..a * d + d].to_vec(),
            positions[b * d..b * d + d].to_vec(),
        );
        let chord: Vec<f64> = (0..d).map(|i| right[i] - left[i]).collect();
        if is_taut(norm(&chord), chain.length_between(a, b)) {
            if chain.elastic_between(a, b) {
                return Ok(None); // (stretched by its supports: its tensions come from its stiffness)
            }
            along_chord(&left, &chord, &lengths[a..b], &mut positions[(a + 1) * d..b * d]);
            continue;
        }
        let Some((nodes, tensions)) =
            hanging_span(&masses[a + 1..b], &lengths[a..b], g, &left, &right, shapes)?
        else {
            return Ok(None);
        };
        positions[(a + 1) * d..b * d].copy_from_slice(&nodes);
        tension[a..b].copy_from_slice(&tensions);
    }
    // Free ends straight down: link k of the head carries nodes 0..=k, link k of the tail the nodes
    // after it.
    let (first, last) = (chain.supports[0], chain.supports[chain.supports.len() - 1]);
    let (mut drop, mut weight) = (0.0, 0.0);
    for node in (0..first).rev() {
        drop += lengths[node];
        for i in 0..d {
            positions[node * d + i] = positions[first * d + i];
        }
        positions[node * d + d - 1] -= drop;
    }
    for k in 0..first {
        weight += masses[k];
        tension[k] = g * weight;
    }
    drop = 0.0;
    for node in last + 1..n {
        drop += lengths[node - 1];
        for i in 0..d {
            positions[node * d + i] = positions[last * d + i];
        }
        positions[node * d + d - 1] -= drop;
    }
    weight = 0.0;
    for k in (last..n - 1).rev() {
        weight += masses[k + 1];
        tension[k] = g * weight;
    }
    if shapes.count() > 0 {
        let (detached, _) = massless_ends(chain);
        let mut checked = vec![true; n];
        for &node in chain.supports.iter().chain(&detached) {
            checked[node] = false;
        }
        let points: Vec<f64> = (0..n)
            .filter(|&i| checked[i])
            .flat_map(|i| positions[i * d..i * d + d].to_vec())
            .collect();
        let m = points.len() / d;
        let (mut phi, mut gradient) = (vec![0.0; m], vec![0.0; m * d]);
        for j in 0..shapes.count() {
            shapes.evaluate(j, &points, &mut phi, &mut gradient)?;
            if !phi.iter().all(|&value| value < 0.0) {
                return Ok(None);
            }
        }
    }
    Ok(Some((positions, tension)))
}
