//! Presolve: feasibility of the supports, exactly taut spans, and a safe initial guess, in the
//! problem's own units (before scaling).
//!
//! Between two consecutive supports a < b the chain has length `L_ab = sum l_k` and the supports
//! are `D_ab` apart. `D_ab > L_ab` is infeasible. `D_ab = L_ab` (to a relative [`TAUT_RTOL`])
//! leaves exactly one feasible position for the nodes between them: the straight segment. The
//! interior-point method cannot work there (the feasible set has no interior), so those nodes are
//! fixed here and their tensions follow from force balance along the segment.
//!
//! A span with an elastic link stretches: it is neither too far nor fixed, and where its supports
//! are as far apart as its unstretched length or farther its nodes start on the chord.
//!
//! The initial guess keeps every pair of neighbouring nodes apart (the norm constraint is not
//! differentiable where they coincide) and every link strictly shorter than its length: free ends
//! hang straight down at [`HANG_RATIO`] of their link lengths; a span between supports sags as a
//! parabola as deep as possible with the longest link ratio `d_k / l_k` at a target between
//! `D_ab / L_ab` and 1 (a quadratic equation per link). Nodes that start inside an obstacle are
//! pushed out to just outside it.
//!
//! Positions are (N, d) arrays row by row; gravity acts along the last axis, and a vertical span
//! leans along the first.

use crate::linalg::norm;
use crate::problem::{Chain, Interrupted, Shapes};

/// Supports this close (relative to the chain between them) to the chain's length apart hold it
/// exactly taut.
pub const TAUT_RTOL: f64 = 1e-10;
/// A free end's links hang at this fraction of their lengths.
pub const HANG_RATIO: f64 = 0.95;
const POSITIONING_ROUNDS: usize = 20;
/// A node within this fraction of the margin from -margin is placed.
const MARGIN_RTOL: f64 = 1e-9;
/// The sag depth clear of obstacles to 1e-12 of the chain length.
const BISECTIONS: usize = 40;
/// A little below the root; the positions are checked against the target too.
const DEPTH_MARGIN: f64 = 1e-12;

/// Why there is no presolve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Infeasible {
    /// Supports at nodes a and b are `distance` apart with only `length` of chain between them.
    TooFar {
        a: usize,
        b: usize,
        distance: f64,
        length: f64,
    },
    /// The chain between the supports at nodes a and b is exactly taut, not vertical, and carries
    /// weight: no finite tension holds it.
    TautNotVertical { a: usize, b: usize },
    /// An obstacle's evaluation outside the core failed.
    Interrupted,
}

impl From<Interrupted> for Infeasible {
    fn from(_: Interrupted) -> Self {
        Infeasible::Interrupted
    }
}

/// Positions to start from, which nodes the interior-point method may move, and known tensions.
#[derive(Clone, Debug)]
pub struct Presolved {
    /// (N, d) initial guess; exact for fixed nodes.
    pub positions: Vec<f64>,
    /// Nodes the interior-point method moves, ascending.
    pub movable: Vec<usize>,
    /// (N - 1) tensions of links between two fixed nodes (0 where undetermined).
    pub fixed_tension: Vec<f64>,
    /// Massless free ends: no force reaches them; they rest on their neighbour, `attach`.
    pub detached: Vec<usize>,
    pub attach: Vec<usize>,
    /// Each obstacle's grad phi at the movable nodes (n_obstacles, n_movable, d), where the push-out
    /// evaluated them there and moved none (the scaling needs them next).
    pub gradients: Option<Vec<f64>>,
}

/// Supports `distance` apart with `length` of chain between them hold it exactly taut (to
/// TAUT_RTOL): its interior nodes have one feasible position, on the chord.
pub fn is_taut(distance: f64, length: f64) -> bool {
    distance >= length * (1.0 - TAUT_RTOL)
}

/// The interior nodes of links `lengths` laid along `chord` from `start`, each at its share of the
/// arclength, into `out` ((lengths - 1) x d).
pub fn along_chord(start: &[f64], chord: &[f64], lengths: &[f64], out: &mut [f64]) {
    let d = start.len();
    let total: f64 = lengths.iter().sum();
    let mut arc = 0.0;
    for (k, point) in out.chunks_exact_mut(d).enumerate() {
        arc += lengths[k];
        for i in 0..d {
            point[i] = start[i] + (arc / total) * chord[i];
        }
    }
}

/// Whether no point is strictly inside any obstacle.
fn outside(shapes: &mut dyn Shapes, d: usize, points: &[f64]) -> Result<bool, Interrupted> {
    let n = points.len() / d;
    let (mut phi, mut gradient) = (vec![0.0; n], vec![0.0; n * d]);
    for j in 0..shapes.count() {
        shapes.evaluate(j, points, &mut phi, &mut gradient)?;
        if !phi.iter().all(|&value| value <= 0.0) {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Tensions of links a..b-1 of a straight taut span along unit `direction`, with the least
/// pre-tension. Force balance at an interior node i along the span: `(T_i - T_{i-1}) u = g m_i`
/// upwards. That needs u vertical unless the interior nodes are massless; the tensions are then
/// fixed up to a constant (the multipliers are not unique: LICQ fails), and the smallest one that
/// keeps every tension >= 0 is reported.
fn taut_tensions(
    chain: &Chain,
    a: usize,
    b: usize,
    direction: &[f64],
    out: &mut [f64],
) -> Result<(), Infeasible> {
    let d = chain.dim;
    let weights = chain.masses[a + 1..b].iter().map(|m| chain.gravity * m);
    let horizontal = norm(&direction[..d - 1]);
    if weights.clone().any(|w| w > 0.0) && horizontal > 1e-12 {
        return Err(Infeasible::TautNotVertical { a, b });
    }
    let up = if direction[d - 1].abs() > 0.5 {
        direction[d - 1]
    } else {
        1.0
    };
    out[0] = 0.0;
    let mut total = 0.0;
    for (k, w) in weights.enumerate() {
        total += w / up;
        out[k + 1] = total;
    }
    let least = out.iter().copied().fold(f64::INFINITY, f64::min);
    for t in out.iter_mut() {
        *t -= least;
    }
    Ok(())
}

/// The largest h in [0, high] with `acceptable(h)`, by bisection (0 assumed acceptable).
fn deepest<F: FnMut(f64) -> Result<bool, Interrupted>>(
    mut acceptable: F,
    mut high: f64,
) -> Result<f64, Interrupted> {
    let mut low = 0.0;
    for _ in 0..BISECTIONS {
        let mid = 0.5 * (low + high);
        if acceptable(mid)? {
            low = mid;
        } else {
            high = mid;
        }
    }
    Ok(low)
}

/// The deepest sag `h` of a span's `nodes` (ends included, on the chord) along `shape` with every
/// link at most `target` of its length (`lengths`), from the roots of one quadratic per link: link k
/// at depth h is its chord piece plus h times the change of shape across it, and the deepest sag
/// with every |b_k + h s_k| <= target l_k is the smallest larger root of those quadratics (each
/// holds at h = 0, as target >= distance / total there). The span's length if none binds.
fn deepest_root(nodes: &[f64], shape: &[f64], lengths: &[f64], target: f64, d: usize) -> f64 {
    let mut root: f64 = lengths.iter().sum();
    for k in 0..lengths.len() {
        let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
        for i in 0..d {
            let step = nodes[(k + 1) * d + i] - nodes[k * d + i];
            let bend = shape[(k + 1) * d + i] - shape[k * d + i];
            a += bend * bend;
            b += 2.0 * step * bend;
            c += step * step;
        }
        let c = (c - (target * lengths[k]).powi(2)).min(0.0);
        if a > 0.0 {
            root = root.min((-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a));
        }
    }
    root
}

/// Interior nodes of a span hanging between two points, every link shorter than its length, into
/// `out` ((lengths - 1) x d). With obstacles, the sag is made shallower until the nodes are
/// outside them, if the straight chord allows it: the chain then settles onto the obstacles from
/// above instead of starting tangled in them.
fn sag(
    start: &[f64],
    end: &[f64],
    lengths: &[f64],
    shapes: &mut dyn Shapes,
    out: &mut [f64],
) -> Result<(), Interrupted> {
    let d = start.len();
    let m = lengths.len() - 1; // interior nodes
    let total: f64 = lengths.iter().sum();
    let chord: Vec<f64> = (0..d).map(|i| end[i] - start[i]).collect();
    let distance = norm(&chord);
    // the nodes (ends included) on the chord, and the sag's shape (zero at the ends)
    let mut nodes = vec![0.0; (m + 2) * d];
    let mut shape = vec![0.0; (m + 2) * d];
    nodes[..d].copy_from_slice(start);
    nodes[(m + 1) * d..].copy_from_slice(end);
    along_chord(start, &chord, lengths, &mut nodes[d..(m + 1) * d]);
    // a vertical or zero chord: lean the sag slightly sideways so that the nodes advance along the
    // first axis and no two coincide (those at t and 1 - t would, with a zero chord)
    let lean = norm(&chord[..d - 1]) <= 1e-3 * total;
    let mut arc = 0.0;
    for k in 1..=m {
        arc += lengths[k - 1];
        let t = arc / total;
        shape[k * d + d - 1] = -4.0 * t * (1.0 - t);
        if lean {
            shape[k * d] = 0.05 * t;
        }
    }
    let target = 1.0 - 0.05 * (1.0 - distance / total);
    let mut depth = deepest_root(&nodes, &shape, lengths, target, d).min(total) * (1.0 - DEPTH_MARGIN);
    let sagged = |h: f64, out: &mut [f64]| {
        for (k, point) in out.chunks_exact_mut(d).enumerate() {
            for i in 0..d {
                point[i] = nodes[(k + 1) * d + i] + h * shape[(k + 1) * d + i];
            }
        }
    };
    let mut trial = vec![0.0; m * d];
    // The roots carry the rounding of |b|^2 - (target l)^2, which matters for nearly taut spans far
    // from the origin: check the positions themselves, and bisect below the root if needed.
    let mut within_target = |h: f64| -> Result<bool, Interrupted> {
        sagged(h, &mut trial);
        let mut worst = 0.0f64;
        for k in 0..=m {
            let point = |k: usize| -> &[f64] {
                if k == 0 {
                    start
                } else if k == m + 1 {
                    end
                } else {
                    &trial[(k - 1) * d..k * d]
                }
            };
            let (p, q) = (point(k), point(k + 1));
            let link: Vec<f64> = (0..d).map(|i| q[i] - p[i]).collect();
            worst = worst.max(norm(&link) / lengths[k]);
        }
        Ok(worst <= target)
    };
    if !within_target(depth)? {
        depth = deepest(&mut within_target, depth)?;
    }
    sagged(depth, out);
    // (the sag first: it is usually clear, and one evaluation is what a short span pays for)
    if shapes.count() > 0 && !outside(shapes, d, out)? {
        let mut base = vec![0.0; m * d];
        sagged(0.0, &mut base);
        if outside(shapes, d, &base)? {
            let mut points = vec![0.0; m * d];
            depth = deepest(
                |h| {
                    sagged(h, &mut points);
                    outside(shapes, d, &points)
                },
                depth,
            )?;
            sagged(depth, out);
        }
    }
    Ok(())
}

/// Nodes of a free end hanging from `anchor`, link k at HANG_RATIO of its length (`lengths` in
/// order away from the anchor), into `out`.
///
/// Straight down, unless that puts a node inside an obstacle: then the first direction, turning
/// alternately to either side in steps of 15 degrees in the plane of the first and the last axis
/// (first towards the side the obstacle's surface faces there), that keeps every node outside.
/// (Pushing a node straight out of an obstacle below its support would move it through to the far
/// side, beyond the reach of its link, with nothing to break the left-right symmetry.)
fn hang(
    anchor: &[f64],
    lengths: &[f64],
    shapes: &mut dyn Shapes,
    away: f64,
    out: &mut [f64],
) -> Result<(), Interrupted> {
    let d = anchor.len();
    let n = lengths.len();
    let mut drop = Vec::with_capacity(n);
    let mut total = 0.0;
    for &l in lengths {
        total += l;
        drop.push(HANG_RATIO * total);
    }
    let place = |sine: f64, cosine: f64, out: &mut [f64]| {
        for (k, point) in out.chunks_exact_mut(d).enumerate() {
            point.copy_from_slice(anchor);
            point[0] += drop[k] * sine;
            point[d - 1] -= drop[k] * cosine;
        }
    };
    place(0.0, 1.0, out);
    if shapes.count() == 0 || n == 0 || outside(shapes, d, out)? {
        return Ok(());
    }
    // Turn first to the side the obstacle's surface faces, or, right above its top, to the side
    // `away` from the other supports (so mirroring the scene mirrors the guess).
    let mut side = away;
    let (mut phi, mut gradient) = (vec![0.0; n], vec![0.0; n * d]);
    for j in 0..shapes.count() {
        shapes.evaluate(j, out, &mut phi, &mut gradient)?;
        if let Some(first) = phi.iter().position(|&value| value > 0.0) {
            let facing = -gradient[first * d]; // -grad phi points out of the obstacle
            side = if facing != 0.0 { facing.signum() } else { away };
            break;
        }
    }
    let mut hanging = vec![0.0; n * d];
    for degrees in (15..180).step_by(15) {
        for sign in [side, -side] {
            let angle = (sign * degrees as f64).to_radians();
            place(angle.sin(), angle.cos(), &mut hanging);
            if outside(shapes, d, &hanging)? {
                out.copy_from_slice(&hanging);
                return Ok(());
            }
        }
    }
    Ok(())
}

/// Free end nodes beyond the last (before the first) massive node or support, and the node each
/// rests on. Nothing pulls them, so every position within reach is optimal, and the barrier's
/// centre of `|p_k - p_{k+1}| <= l` would put them on their neighbour, where the norm is not
/// differentiable. They are left out of the solve and placed on the node they hang from, with zero
/// tension.
pub fn massless_ends(chain: &Chain) -> (Vec<usize>, Vec<usize>) {
    let n = chain.n_nodes();
    if chain.masses[0] > 0.0 && chain.masses[n - 1] > 0.0 {
        return (Vec::new(), Vec::new());
    }
    let mut anchored: Vec<bool> = chain.masses.iter().map(|&m| m > 0.0).collect();
    for &s in &chain.supports {
        anchored[s] = true;
    }
    let first = anchored.iter().position(|&a| a).unwrap_or(0);
    let last = anchored.iter().rposition(|&a| a).unwrap_or(n - 1);
    let mut detached: Vec<usize> = (0..first).collect();
    detached.extend(last + 1..n);
    let attach = detached
        .iter()
        .map(|&i| if i < first { first } else { last })
        .collect();
    (detached, attach)
}

/// A chain's push-out margin: a twentieth of its shortest link.
fn margin(chain: &Chain) -> f64 {
    0.05 * chain.lengths.iter().copied().fold(f64::INFINITY, f64::min)
}

/// Moves the `movable` nodes of `positions` (N, d) that start inside an obstacle, or less than
/// `margin` outside it, to `margin` outside (Newton on phi = -margin, obstacle by obstacle).
///
/// `settled`: the guess is a solved chain (a coarser level's), whose touching nodes lie on the
/// surfaces give or take interpolation: only nodes more than the margin deep are moved (pushing
/// every node on a surface out by the margin would undo the contact the polish starts from).
///
/// Returns each obstacle's gradient at the movable nodes if no node moved (see `Presolved`).
pub(crate) fn push_out(
    d: usize,
    margin: f64,
    shapes: &mut dyn Shapes,
    positions: &mut [f64],
    movable: &[usize],
    settled: bool,
) -> Result<Option<Vec<f64>>, Interrupted> {
    if shapes.count() == 0 {
        return Ok(Some(Vec::new()));
    }
    let deeper_than = if settled {
        margin
    } else {
        -margin * (1.0 - MARGIN_RTOL)
    };
    // a node that is clear of every obstacle and did not move stays clear
    let mut candidates = movable.to_vec();
    let mut first = Vec::new();
    for round in 0..POSITIONING_ROUNDS {
        let n = candidates.len();
        let mut moved = vec![false; n];
        let (mut points, mut phi, mut gradient) = (vec![0.0; n * d], vec![0.0; n], vec![0.0; n * d]);
        for j in 0..shapes.count() {
            for (k, &node) in candidates.iter().enumerate() {
                points[k * d..k * d + d].copy_from_slice(&positions[node * d..node * d + d]);
            }
            shapes.evaluate(j, &points, &mut phi, &mut gradient)?;
            if round == 0 {
                first.extend_from_slice(&gradient);
            }
            for (k, &node) in candidates.iter().enumerate() {
                let g = &gradient[k * d..k * d + d];
                let norm2: f64 = g.iter().map(|x| x * x).sum();
                let distance = phi[k] / norm2.max(1e-300).sqrt();
                // A pushed node comes back at -margin give or take rounding: it has arrived.
                if distance.is_finite() && distance > deeper_than && norm2 > 0.0 {
                    let step = (phi[k] + margin * norm2.sqrt()) / norm2;
                    for i in 0..d {
                        positions[node * d + i] = points[k * d + i] - step * g[i];
                    }
                    moved[k] = true;
                }
            }
        }
        if !moved.iter().any(|&m| m) {
            return Ok(if round == 0 { Some(first) } else { None });
        }
        candidates = candidates
            .iter()
            .zip(&moved)
            .filter(|(_, &m)| m)
            .map(|(&c, _)| c)
            .collect();
    }
    Ok(None)
}

/// The free ends of `chain` hanging from its first and last supports (see `hang`), into
/// `positions` (N, d).
fn hang_ends(chain: &Chain, shapes: &mut dyn Shapes, positions: &mut [f64]) -> Result<(), Interrupted> {
    let (d, n) = (chain.dim, chain.n_nodes());
    let (first, last) = (chain.supports[0], chain.supports[chain.supports.len() - 1]);
    let supports = chain.supports.len() as f64;
    let centre = chain.support_positions.chunks_exact(d).map(|p| p[0]).sum::<f64>() / supports;
    let away = |node: usize, positions: &[f64]| if positions[node * d] < centre { -1.0 } else { 1.0 };
    if first > 0 {
        let anchor = positions[first * d..first * d + d].to_vec();
        let lengths: Vec<f64> = chain.lengths[..first].iter().rev().copied().collect();
        let mut hanging = vec![0.0; first * d];
        hang(&anchor, &lengths, shapes, away(first, positions), &mut hanging)?;
        // node first - 1 - k is the k-th away from the anchor
        for k in 0..first {
            let node = first - 1 - k;
            positions[node * d..node * d + d].copy_from_slice(&hanging[k * d..k * d + d]);
        }
    }
    if last < n - 1 {
        let anchor = positions[last * d..last * d + d].to_vec();
        let mut hanging = vec![0.0; (n - 1 - last) * d];
        hang(
            &anchor,
            &chain.lengths[last..],
            shapes,
            away(last, positions),
            &mut hanging,
        )?;
        positions[(last + 1) * d..].copy_from_slice(&hanging);
    }
    Ok(())
}

/// Every span between consecutive supports: checks its distance, fixes it where exactly taut, and
/// (unless `guessed`: a guess replaces every movable node's position) lays its nodes out.
fn spans(
    chain: &Chain,
    shapes: &mut dyn Shapes,
    guessed: bool,
    positions: &mut [f64],
    movable: &mut [bool],
    fixed_tension: &mut [f64],
) -> Result<(), Infeasible> {
    let d = chain.dim;
    for pair in chain.supports.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let (pa, pb) = (&positions[a * d..a * d + d], &positions[b * d..b * d + d]);
        let chord: Vec<f64> = (0..d).map(|i| pb[i] - pa[i]).collect();
        let distance = norm(&chord);
        let length = chain.length_between(a, b);
        // A span with an elastic link stretches to any distance: its interior nodes stay free.
        let elastic = chain.elastic_between(a, b);
        if !elastic && distance > length * (1.0 + TAUT_RTOL) {
            return Err(Infeasible::TooFar {
                a,
                b,
                distance,
                length,
            });
        }
        if b == a + 1 {
            continue;
        }
        let (start, end) = (pa.to_vec(), pb.to_vec());
        let interior = &mut positions[(a + 1) * d..b * d];
        let taut = is_taut(distance, length);
        if taut && elastic {
            if !guessed {
                along_chord(&start, &chord, &chain.lengths[a..b], interior);
            }
        } else if taut {
            let direction: Vec<f64> = chord.iter().map(|c| c / distance).collect();
            along_chord(&start, &chord, &chain.lengths[a..b], interior);
            movable[a + 1..b].fill(false);
            taut_tensions(chain, a, b, &direction, &mut fixed_tension[a..b])?;
        } else if !guessed {
            sag(&start, &end, &chain.lengths[a..b], shapes, interior)?;
        }
    }
    Ok(())
}

/// Checks the supports' distances, fixes exactly taut spans, and builds (or, from `guess` (N, d),
/// takes) the initial guess. `settled`: `guess` is a solved chain (see `push_out`).
pub fn presolve(
    chain: &Chain,
    shapes: &mut dyn Shapes,
    guess: Option<&[f64]>,
    settled: bool,
) -> Result<Presolved, Infeasible> {
    let d = chain.dim;
    let n = chain.n_nodes();
    let mut positions = vec![0.0; n * d];
    let mut movable = vec![true; n];
    for (s, &node) in chain.supports.iter().enumerate() {
        positions[node * d..node * d + d].copy_from_slice(&chain.support_positions[s * d..s * d + d]);
        movable[node] = false;
    }
    let mut fixed_tension = vec![0.0; n - 1];
    spans(
        chain,
        shapes,
        guess.is_some(),
        &mut positions,
        &mut movable,
        &mut fixed_tension,
    )?;
    let (first, last) = (chain.supports[0], chain.supports[chain.supports.len() - 1]);
    if guess.is_none() && (first > 0 || last < n - 1) {
        hang_ends(chain, shapes, &mut positions)?;
    }
    let (detached, attach) = massless_ends(chain);
    for &node in &detached {
        movable[node] = false;
    }
    let movable: Vec<usize> = (0..n).filter(|&i| movable[i]).collect();
    let start = Presolved {
        positions,
        movable,
        fixed_tension,
        detached,
        attach,
        gradients: None,
    };
    match guess {
        Some(guess) => Ok(repositioned(chain, shapes, &start, guess, settled)?),
        None => {
            let mut start = start;
            start.gradients = push_out(
                chain.dim,
                margin(chain),
                shapes,
                &mut start.positions,
                &start.movable,
                false,
            )?;
            Ok(start)
        }
    }
}

/// `presolve` of the same chain from `guess` (N, d), given one of its results: its supports, taut
/// spans and detached ends stay where `start` put them (the saddle escape solves again from a
/// moved chain).
pub fn repositioned(
    chain: &Chain,
    shapes: &mut dyn Shapes,
    start: &Presolved,
    guess: &[f64],
    settled: bool,
) -> Result<Presolved, Interrupted> {
    let d = chain.dim;
    let n = chain.n_nodes();
    let mut positions = guess.to_vec();
    let mut is_movable = vec![false; n];
    for &node in &start.movable {
        is_movable[node] = true;
    }
    for node in (0..n).filter(|&i| !is_movable[i]) {
        positions[node * d..node * d + d].copy_from_slice(&start.positions[node * d..node * d + d]);
    }
    // Detached nodes rest on their neighbour, where the solve puts them anyway; a guess for them
    // could be anywhere (1e9 away, it raised the rounding floor and loosened the tolerance).
    for (&node, &on) in start.detached.iter().zip(&start.attach) {
        let anchor = positions[on * d..on * d + d].to_vec();
        positions[node * d..node * d + d].copy_from_slice(&anchor);
    }
    let gradients = push_out(d, margin(chain), shapes, &mut positions, &start.movable, settled)?;
    Ok(Presolved {
        positions,
        movable: start.movable.clone(),
        fixed_tension: start.fixed_tension.clone(),
        detached: start.detached.clone(),
        attach: start.attach.clone(),
        gradients,
    })
}
