//! The whole solve of a cable net (links between any pairs of nodes, in the plane or in space), in
//! the problem's units: its start and its solver's units. One solve, the saddle escape and the
//! multipliers back in the problem's units are [`crate::driver`]'s, as for a chain; the iteration
//! runs on the net's sparse Newton matrix (a fill-reducing order). What differs from a chain is the
//! start, since a net has no arclength to lay its nodes along.
//!
//! The start: a force-density shape (Schek). With a force density `q_k` in every link, equilibrium
//! with the supports and gravity is linear in the free nodes' positions, `K p = B p_s + f`, with K
//! the links' weighted Laplacian (positive definite where every node reaches a support). Starting
//! from `q_k = 1 / l_k`, a few rounds of `q_k <- q_k d_k / l_k` bring every link near its length
//! (a net hung from a few points would otherwise gather towards its middle). The shape is then the
//! one without load, `h`, plus the sag under gravity, `t s`; the start takes the deepest sag that
//! keeps every link within START_STRETCH of its length (`t` by bisection), so it already hangs,
//! with the supports where they are. Nodes that start inside an obstacle are moved out along its
//! gradient. The iteration then finds which links are taut.

use crate::driver::{
    escape, multipliers_in_units, obstacle_scales, solve_once, Guess, Options, Scaling, SolveError, Solved,
};
use crate::linalg::norm;
use crate::linalg::SparseMatrix;
use crate::linalg::{Factorization, NewtonMatrix};
use crate::presolve::push_out;
use crate::problem::{Interrupted, Net, OneByOne, Setup, Shapes};

/// The start's sag: every link at most this fraction of its length.
const START_STRETCH: f64 = 0.98;
/// ... and an elastic link at most this strain beyond it: stretched, so that its stiffness shows.
const START_STRAIN: f64 = 0.03;
/// Nodes up to which the escape checks a net's result: each solve from a step off a saddle starts
/// cold and takes as many steps as the first (a 70 x 70 grid over a sphere: 2.3 times the time,
/// where it reaches the lower equilibrium; 100 x 100: 14 times).
pub const NET_ESCAPE_UP_TO: usize = 5000;
/// Rounds of the force densities' update towards links at their lengths.
const FORM_ROUNDS: usize = 10;
/// Halvings of the interval in which the start's sag is sought.
const START_BISECTIONS: usize = 40;
/// Obstacles push starting nodes out to this depth outside (of the longest link).
const START_CLEARANCE: f64 = 1e-3;

/// The force-density start (see the module documentation): the deepest sag within the links'
/// lengths that keeps every node out of the obstacles (if the shape without sag does); None where
/// some free node reaches no support (the Laplacian is singular).
pub fn hanging_start(net: &Net, setup: &Setup) -> Result<Option<Vec<f64>>, Interrupted> {
    let (d, n) = (net.dim, net.n_nodes());
    let free = net.free();
    let mut place = vec![usize::MAX; n];
    for (f, &i) in free.iter().enumerate() {
        place[i] = f;
    }
    let positions = net.held(vec![0.0; n * d]);
    if free.is_empty() {
        return Ok(Some(positions));
    }
    let structure = net.structure();
    let pairs: Vec<[usize; 2]> = net
        .links
        .iter()
        .filter(|[a, b]| place[*a] != usize::MAX && place[*b] != usize::MAX)
        .map(|[a, b]| [place[*a], place[*b]])
        .collect();
    let mut laplacian = SparseMatrix::with_pairs(free.len(), 1, pairs);
    let mut density: Vec<f64> = net.lengths.iter().map(|l| 1.0 / l).collect();
    let (mut pull, mut sag) = (Vec::new(), Vec::new());
    for round in 0..=FORM_ROUNDS {
        let Some(shape) = force_density_shape(net, &place, &positions, &density, &mut laplacian) else {
            return Ok(None);
        };
        (pull, sag) = shape;
        if round == FORM_ROUNDS {
            break;
        }
        // a link longer than its length gets a larger force density, a shorter one a smaller
        let distances = structure.distances(&shape_at(&positions, &free, &pull, &sag, 1.0));
        for ((q, distance), length) in density.iter_mut().zip(distances).zip(&net.lengths) {
            let stretch = distance / length;
            if stretch.is_finite() && stretch > 0.0 {
                *q *= stretch;
            }
        }
    }
    let at = |t: f64| shape_at(&positions, &free, &pull, &sag, t);
    // (an elastic link may start stretched: START_STRAIN more than an inextensible one)
    let stretch = |shape: &[f64]| {
        let distances = structure.distances(shape);
        distances
            .iter()
            .zip(&net.lengths)
            .enumerate()
            .map(|(k, (distance, l))| distance / l - if structure.elastic(k) { START_STRAIN } else { 0.0 })
            .fold(0.0, f64::max)
    };
    let mut shapes = OneByOne {
        dim: d,
        obstacles: &setup.obstacles,
    };
    let clearance = START_CLEARANCE * net.lengths.iter().copied().fold(0.0, f64::max);
    let mut fits = |t: f64| -> Result<bool, Interrupted> {
        let shape = at(t);
        if !(stretch(&shape) < START_STRETCH) {
            return Ok(false);
        }
        let points: Vec<f64> = free
            .iter()
            .flat_map(|&node| shape[node * d..node * d + d].to_vec())
            .collect();
        let (mut phi, mut gradient) = (vec![0.0; free.len()], vec![0.0; free.len() * d]);
        for j in 0..setup.obstacles.count {
            shapes.evaluate(j, &points, &mut phi, &mut gradient)?;
            let outside = phi
                .iter()
                .zip(gradient.chunks_exact(d))
                .all(|(&value, g)| value < -clearance * norm(g));
            if !outside {
                return Ok(false);
            }
        }
        Ok(true)
    };
    // the deepest sag that keeps the links within their lengths and the nodes out of the obstacles
    let mut t = 0.0;
    if fits(0.0)? && sag.iter().flatten().any(|&s| s != 0.0) {
        let mut high = 1.0;
        while fits(high)? && high < 1e300 {
            high *= 2.0;
        }
        let mut low = 0.0;
        for _ in 0..START_BISECTIONS {
            let middle = 0.5 * (low + high);
            if fits(middle)? {
                low = middle;
            } else {
                high = middle;
            }
        }
        t = low;
    }
    Ok(Some(at(t)))
}

/// Every node's position (N, d) in the force-density shape with sag `t`: the supports as `held`
/// holds them, free node f at `pull + t sag`.
fn shape_at(held: &[f64], free: &[usize], pull: &[Vec<f64>], sag: &[Vec<f64>], t: f64) -> Vec<f64> {
    let d = pull.len();
    let mut positions = held.to_vec();
    for (f, &node) in free.iter().enumerate() {
        for i in 0..d {
            positions[node * d + i] = pull[i][f] + t * sag[i][f];
        }
    }
    positions
}

/// One vector over the free nodes per axis.
type Axes = Vec<Vec<f64>>;

/// The free nodes' coordinates in equilibrium with force densities `density` and the supports
/// (`pull`, d of them) and with the applied loads (`sag`, d of them: gravity along the last axis
/// and the point loads): the force-density method's linear systems, `K x = B p_s` and `K x = F`.
/// None where K is singular.
fn force_density_shape(
    net: &Net,
    place: &[usize],
    positions: &[f64],
    density: &[f64],
    laplacian: &mut SparseMatrix,
) -> Option<(Axes, Axes)> {
    let d = net.dim;
    let n_free = laplacian.size();
    laplacian.reset(n_free, 1);
    let mut pull = vec![vec![0.0; n_free]; d];
    let mut sag = vec![vec![0.0; n_free]; d];
    for (node, &f) in place.iter().enumerate() {
        if f != usize::MAX {
            sag[d - 1][f] = -net.gravity * net.masses[node];
            if !net.loads.is_empty() {
                (0..d).for_each(|i| sag[i][f] += net.loads[node * d + i]);
            }
        }
    }
    for (&[a, b], &q) in net.links.iter().zip(density) {
        for (this, other) in [(a, b), (b, a)] {
            let f = place[this];
            if f == usize::MAX {
                continue;
            }
            laplacian.add_node(f, &[q]);
            match place[other] {
                usize::MAX => (0..d).for_each(|i| pull[i][f] += q * positions[other * d + i]),
                g if f < g => laplacian.add_pair(f, g, &[-q]),
                _ => {}
            }
        }
    }
    let mut factors = laplacian.new_factors();
    if !factors.factor_shifted(laplacian, 0.0) {
        return None;
    }
    pull.iter_mut()
        .chain(sag.iter_mut().filter(|rhs| rhs.iter().any(|&v| v != 0.0)))
        .for_each(|rhs| factors.solve_in_place(rhs));
    Some((pull, sag))
}

/// `positions` with the `free` nodes that lie inside an obstacle, or less than START_CLEARANCE of
/// the longest link outside, moved to that clearance outside (the chain's push-out); and each
/// obstacle's gradient at the free nodes where none moved.
fn pushed_out(
    net: &Net,
    setup: &Setup,
    free: &[usize],
    mut positions: Vec<f64>,
) -> Result<(Vec<f64>, Option<Vec<f64>>), Interrupted> {
    let clearance = START_CLEARANCE * net.lengths.iter().copied().fold(0.0, f64::max);
    let mut shapes = OneByOne {
        dim: net.dim,
        obstacles: &setup.obstacles,
    };
    let gradients = push_out(net.dim, clearance, &mut shapes, &mut positions, free, false)?;
    Ok((positions, gradients))
}

/// The solver's units of `net` started at `start` (N, d): its free nodes, the links that touch one,
/// each obstacle's scale (from `gradients` at the free nodes, if known).
fn scaling(
    net: &Net,
    setup: &Setup,
    free: Vec<usize>,
    start: &[f64],
    gradients: Option<&[f64]>,
) -> Result<Scaling, Interrupted> {
    let d = net.dim;
    Ok(Scaling {
        length_unit: net.lengths.iter().copied().fold(0.0, f64::max),
        origin: net.support_positions[..d].to_vec(),
        weight: net.structure().force_scale(),
        links: (0..net.links.len())
            .filter(|&k| {
                let [a, b] = net.links[k];
                free.binary_search(&a).is_ok() || free.binary_search(&b).is_ok()
            })
            .collect(),
        obstacle_scale: obstacle_scales(setup, d, &free, start, gradients)?,
        free,
    })
}

/// The equilibrium of `net` with its forces, from `initial` (positions (N, d); its multipliers are
/// not used) or the force-density start; `judge`: the second-order test at the result too. With
/// obstacles (node contact, up to NET_ESCAPE_UP_TO nodes or `options.escape_up_to`) and
/// `options.escape_saddles`, a saddle is left along a direction of negative curvature, as for a
/// chain. Link contact is not available for nets.
pub fn solve(
    net: &Net,
    setup: &Setup,
    options: &Options,
    initial: Option<&Guess>,
    judge: bool,
    check: &mut dyn FnMut() -> bool,
) -> Result<Solved, SolveError> {
    assert!(
        !setup.links_contact,
        "a net's obstacles are kept away from its nodes"
    );
    let structure = net.structure();
    let start = match initial {
        Some(guess) => net.held(guess.positions.clone()),
        None => hanging_start(net, setup)?.ok_or(SolveError::NotFactored)?,
    };
    let (start, gradients) = pushed_out(net, setup, &net.free(), start)?;
    let scaling = scaling(net, setup, net.free(), &start, gradients.as_deref())?;
    let escape = options.escape_saddles
        && setup.obstacles.count > 0
        && net.n_nodes() <= options.escape_up_to.unwrap_or(NET_ESCAPE_UP_TO);
    let mut once = solve_once(
        &structure,
        setup,
        options,
        &scaling,
        start,
        None,
        escape || judge,
        check,
    )?;
    let (mut iterations, mut statistics) = (once.iterations, once.statistics);
    if escape && initial.is_none() {
        once = self::escape(
            once,
            &structure,
            |once| once.judged(&structure, &scaling),
            |moved| {
                let (moved, _) = pushed_out(net, setup, &scaling.free, moved)?;
                let again = solve_once(&structure, setup, options, &scaling, moved, None, true, check)?;
                iterations += again.iterations;
                statistics.add(&again.statistics);
                Ok(again)
            },
        )?;
    }
    let judged = if judge {
        once.judged(&structure, &scaling)
    } else {
        None
    };
    let distances = structure.distances(&once.positions);
    let mut link_multipliers = vec![0.0; net.links.len()];
    let mut obstacle_multipliers = vec![0.0; setup.obstacles.count * net.n_nodes()];
    multipliers_in_units(
        &structure,
        setup,
        &scaling,
        &once.mu,
        &distances,
        &mut link_multipliers,
        &mut obstacle_multipliers,
    );
    Ok(Solved {
        status: once.status,
        positions: once.positions,
        link_multipliers,
        obstacle_multipliers,
        iterations,
        statistics,
        judged,
    })
}
