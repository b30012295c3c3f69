//! What the solves of chains and nets share, in the problem's units: the solver's units (scaling),
//! one solve on the network (the iteration and its errors), the second-order test at a result, the
//! saddle escape, and the multipliers back in the problem's units. [`crate::chain`] and
//! [`crate::net`] add what differs: where a solve starts.
//!
//! Scaling: positions `(p - origin) / length_unit` (the first support is the origin, the longest
//! link the unit of length), forces / total weight W, and obstacle j's phi divided by
//! `scale_j * length_unit` where `scale_j` is a typical |grad phi_j| near the free nodes: multiplying
//! phi by a constant leaves every iterate unchanged, and the stopping test does not depend on the
//! units.
//!
//! The saddle escape: with obstacles a KKT point may be a saddle of the energy (a chain balanced
//! on the top of a disk). At the result the second-order test on the solver's own Newton matrix
//! (`curvature::escape_test`) gives a direction of negative curvature, if there is one; the
//! structure moves along it and is solved again, and the lower energy is kept.

use std::cell::RefCell;
use std::rc::Rc;

use crate::curvature::{self, Verdict};
use crate::evaluate::NetworkMatrix;
use crate::evaluate::Point;
use crate::ipm::{self, ChainKind, Failure, NetKind, Outcome, Settings, Status};
use crate::linalg::norm;
use crate::linalg::{BlockTridiagonal, SparseMatrix};
use crate::presolve::Infeasible;
use crate::problem::{
    Formulation, Interrupted, Network, NodeField, OneByOne, Quadratics, ScaledObstacles, SegmentField,
    Segments, Setup, Shapes, Statistics, Structure, SMOOTH_RATIO,
};

/// The escape's move, of the structure's length, for the node that moves most.
const ESCAPE_STEP: f64 = 0.05;
/// Escapes at most, one after the other.
const ESCAPES: usize = 2;
/// The second-order test's relative tolerance: the checker's.
pub const ESCAPE_TOL: f64 = 1e-6;
/// The obstacle scale is a median over at most twice this many evenly spaced nodes.
const SCALE_SAMPLE: usize = 4096;

/// What a solve may be asked: the tolerance of the stopping test, the iteration limit, whether to
/// leave a saddle and up to how many nodes (None: the structure's own cap, a chain's
/// [`crate::chain::ESCAPE_UP_TO`] or a net's [`crate::net::NET_ESCAPE_UP_TO`]), and (a chain)
/// whether to start from the exact catenary where it applies.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    pub tol: f64,
    pub max_iterations: usize,
    pub escape_saddles: bool,
    pub escape_up_to: Option<usize>,
    pub exact_start: bool,
}

/// A start: positions (N, d) and, when known, the multipliers in the problem's units (every link's,
/// and every obstacle's contact columns, per node or per link). `settled`: the positions are a
/// solved chain's (nodes on a surface stay there).
#[derive(Clone, Debug, Default)]
pub struct Guess {
    pub positions: Vec<f64>,
    pub link_multipliers: Option<Vec<f64>>,
    pub obstacle_multipliers: Option<Vec<f64>>,
    pub settled: bool,
    /// What the solves that made it spent (coarse levels).
    pub statistics: Statistics,
}

/// The escape's second-order test at a result: a proven minimum, or a direction of negative
/// curvature (scaled units) as moves of every node (N, d), zero at the fixed ones; or neither.
#[derive(Clone, Debug)]
pub enum Judged {
    Minimum,
    Direction(f64, Vec<f64>),
    Undecided,
}

/// A solve's answer in the problem's units.
#[derive(Clone, Debug)]
pub struct Solved {
    pub status: Status,
    /// (N, d); massless free ends rest on the node they hang from.
    pub positions: Vec<f64>,
    /// Every link's multiplier (N - 1) in the problem's formulation.
    pub link_multipliers: Vec<f64>,
    /// Every obstacle's contact multipliers, per node (N) or per link (N - 1), obstacle after obstacle.
    pub obstacle_multipliers: Vec<f64>,
    pub iterations: usize,
    pub statistics: Statistics,
    /// The second-order test at the result, if asked for.
    pub judged: Option<Judged>,
}

/// Why a solve has no answer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SolveError {
    Infeasible(Infeasible),
    /// The Newton matrix stayed indefinite under every inertia correction.
    NotFactored,
    /// Obstacle j's phi or derivatives are not finite at node (or link) `index` of the start or
    /// of the result.
    ObstacleNotFinite {
        obstacle: usize,
        index: usize,
        at_start: bool,
    },
    /// The caller's obstacle evaluation or its interrupt check stopped it.
    Interrupted,
}

impl From<Interrupted> for SolveError {
    fn from(_: Interrupted) -> Self {
        SolveError::Interrupted
    }
}

impl From<Infeasible> for SolveError {
    fn from(infeasible: Infeasible) -> Self {
        match infeasible {
            Infeasible::Interrupted => SolveError::Interrupted,
            other => SolveError::Infeasible(other),
        }
    }
}

/// The solver's units for one problem and presolve, and which rows it has.
#[derive(Clone, Debug)]
pub(crate) struct Scaling {
    pub length_unit: f64,
    pub origin: Vec<f64>,
    pub weight: f64,
    /// Movable nodes, ascending.
    pub free: Vec<usize>,
    /// Optimised links (a movable end, no detached end), by index (a chain's: by their first node).
    pub links: Vec<usize>,
    /// Each obstacle's typical |grad phi| near the free nodes.
    pub obstacle_scale: Vec<f64>,
}

impl Scaling {
    /// Link multipliers in the problem's units per scaled one: W (norm) or W / length_unit (squared).
    pub(crate) fn link_unit(&self, setup: &Setup) -> f64 {
        match setup.formulation {
            Formulation::Norm => self.weight,
            Formulation::Squared => self.weight / self.length_unit,
        }
    }

    /// The free nodes' positions in `positions` (N, d) from the iteration's coordinates `z`.
    pub(crate) fn place(&self, z: &[f64], positions: &mut [f64]) {
        let d = self.origin.len();
        for (f, &node) in self.free.iter().enumerate() {
            for i in 0..d {
                positions[node * d + i] = z[f * d + i] * self.length_unit + self.origin[i];
            }
        }
    }

    /// What each obstacle's contact rows stand for: optimised links or free nodes.
    pub(crate) fn contact_rows<'a>(&'a self, setup: &Setup) -> &'a [usize] {
        if setup.links_contact {
            &self.links
        } else {
            &self.free
        }
    }
}

/// The median of the finite positive values (1 if there are none), as numpy's.
fn median_of_positive(mut values: Vec<f64>) -> f64 {
    values.retain(|v| v.is_finite() && *v > 0.0);
    if values.is_empty() {
        return 1.0;
    }
    values.sort_by(f64::total_cmp);
    let m = values.len();
    if m % 2 == 1 {
        values[m / 2]
    } else {
        // numpy's mean of the two middle values
        (values[m / 2 - 1] + values[m / 2]) / 2.0
    }
}

/// Each obstacle's typical |grad phi| near the `free` nodes of `positions` (N, d): the median over
/// at most twice SCALE_SAMPLE evenly spaced ones; `gradients` (J, free, d), if known already.
pub(crate) fn obstacle_scales(
    setup: &Setup,
    d: usize,
    free: &[usize],
    positions: &[f64],
    gradients: Option<&[f64]>,
) -> Result<Vec<f64>, Interrupted> {
    let count = setup.obstacles.count;
    let mut obstacle_scale = vec![1.0; count];
    if count == 0 || free.is_empty() {
        return Ok(obstacle_scale);
    }
    let stride = (free.len() / SCALE_SAMPLE).max(1);
    let sample: Vec<usize> = free.iter().copied().step_by(stride).collect();
    let m = sample.len();
    let fresh;
    let gradients: &[f64] = match gradients {
        Some(gradients) if stride == 1 => gradients,
        _ => {
            let points: Vec<f64> = sample
                .iter()
                .flat_map(|&i| positions[i * d..i * d + d].to_vec())
                .collect();
            let mut shapes = OneByOne {
                dim: d,
                obstacles: &setup.obstacles,
            };
            let (mut phi, mut gradient) = (vec![0.0; m], vec![0.0; m * d]);
            let mut all = Vec::with_capacity(count * m * d);
            for j in 0..count {
                shapes.evaluate(j, &points, &mut phi, &mut gradient)?;
                all.extend_from_slice(&gradient);
            }
            fresh = all;
            &fresh
        }
    };
    for (j, scale) in obstacle_scale.iter_mut().enumerate() {
        let norms = gradients[j * m * d..(j + 1) * m * d]
            .chunks_exact(d)
            .map(norm)
            .collect();
        *scale = median_of_positive(norms);
    }
    Ok(obstacle_scale)
}

/// From the solver's units to the problem's and back, for the caller's obstacle evaluations:
/// `p = length_unit s + origin`, obstacle j's phi divided by `scale_j length_unit`.
#[derive(Clone, Debug)]
struct Units {
    dim: usize,
    length_unit: f64,
    origin: Vec<f64>,
    scale: Vec<f64>,
}

impl Units {
    /// Scaled points (n, d) in the problem's units, into `physical`.
    fn physical(&self, points: &[f64], physical: &mut Vec<f64>) {
        physical.clear();
        physical.extend(
            points
                .iter()
                .enumerate()
                .map(|(i, s)| s * self.length_unit + self.origin[i % self.dim]),
        );
    }

    /// Each obstacle's rows (`rows` of them, obstacle after obstacle) of values, gradients (d each)
    /// and Hessians (`hessian_size` each) in the problem's units, into the solver's.
    fn scale_back(
        &self,
        rows: usize,
        value: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
        hessian_size: usize,
    ) {
        let d = self.dim;
        for (j, &unit) in self.scale.iter().enumerate() {
            value[j * rows..(j + 1) * rows]
                .iter_mut()
                .for_each(|v| *v /= unit * self.length_unit);
            gradient[j * rows * d..(j + 1) * rows * d]
                .iter_mut()
                .for_each(|v| *v /= unit);
            hessian[j * rows * hessian_size..(j + 1) * rows * hessian_size]
                .iter_mut()
                .for_each(|v| *v *= self.length_unit / unit);
        }
    }
}

/// The caller's node field in the solver's units.
struct ScaledNodes {
    field: Rc<RefCell<dyn NodeField>>,
    units: Units,
    /// The points in the problem's units, kept from one evaluation to the next.
    physical: Vec<f64>,
}

impl NodeField for ScaledNodes {
    fn count(&self) -> usize {
        self.units.scale.len()
    }

    fn evaluate(
        &mut self,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        let d = self.units.dim;
        self.units.physical(points, &mut self.physical);
        self.field
            .borrow_mut()
            .evaluate(&self.physical, phi, gradient, hessian)?;
        self.units
            .scale_back(points.len() / d, phi, gradient, hessian, d * d);
        Ok(())
    }
}

/// The caller's segments in the solver's units, for the optimised links.
struct ScaledSegments {
    segments: Rc<RefCell<dyn Segments>>,
    links: Vec<usize>,
    units: Units,
    /// Every node's position in the problem's units, kept from one evaluation to the next.
    physical: Vec<f64>,
}

impl SegmentField for ScaledSegments {
    fn count(&self) -> usize {
        self.units.scale.len()
    }

    fn evaluate(
        &mut self,
        positions: &[f64],
        psi: &mut [f64],
        t: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        let d = self.units.dim;
        self.units.physical(positions, &mut self.physical);
        self.segments
            .borrow_mut()
            .evaluate(&self.physical, &self.links, psi, t, gradient, hessian)?;
        self.units
            .scale_back(self.links.len(), psi, gradient, hessian, 4 * d * d);
        Ok(())
    }
}

/// The network the iteration works on: the structure in the solver's units from `positions` (N, d).
pub(crate) fn network(structure: &Structure, setup: &Setup, scaling: &Scaling, positions: &[f64]) -> Network {
    let d = structure.dim;
    let Scaling {
        length_unit: unit,
        origin,
        weight,
        free,
        links,
        ..
    } = scaling;
    let scaled: Vec<f64> = positions
        .iter()
        .enumerate()
        .map(|(i, p)| (p - origin[i % d]) / unit)
        .collect();
    let obstacles = scaled_obstacles(setup, scaling, d);
    Network::new(
        d,
        setup.formulation,
        scaled,
        free.clone(),
        links.iter().map(|&k| structure.pair(k)).collect(),
        links.iter().map(|&k| structure.lengths[k] / unit).collect(),
        structure
            .masses
            .iter()
            .map(|m| structure.gravity * m / weight)
            .collect(),
        origin.iter().map(|o| o / unit).collect(),
        obstacles,
    )
    .and_then(|network| network.with_point_loads(structure.loads.iter().map(|f| f / weight).collect()))
    .and_then(|network| {
        if structure.stiffness.is_empty() {
            return Ok(network);
        }
        // a link's stretch per unit of tension, L0 / EA, in the solver's units (length per force)
        network.with_compliance(
            links
                .iter()
                .map(|&k| structure.lengths[k] / structure.stiffness[k] * weight / unit)
                .collect(),
        )
    })
    .expect("the optimised links join two nodes, at least one of them free; point loads (N, d)")
}

/// The obstacles in the solver's units (see [`Scaling`]).
fn scaled_obstacles(setup: &Setup, scaling: &Scaling, d: usize) -> ScaledObstacles {
    let Scaling {
        length_unit: unit,
        origin,
        links,
        obstacle_scale: scale,
        ..
    } = scaling;
    let count = setup.obstacles.count;
    let units = Units {
        dim: d,
        length_unit: *unit,
        origin: origin.clone(),
        scale: scale.clone(),
    };
    if count == 0 {
        ScaledObstacles::none()
    } else if setup.links_contact {
        let segments = setup
            .obstacles
            .segments
            .clone()
            .expect("link contact needs the caller's segments");
        ScaledObstacles::Links(Box::new(ScaledSegments {
            segments,
            links: links.clone(),
            units,
            physical: Vec::new(),
        }))
    } else if let Some(q) = &setup.obstacles.quadratics {
        // p = length_unit s + origin; phi / (scale length_unit) over s
        ScaledObstacles::Quadratic(Quadratics {
            centres: q
                .centres
                .iter()
                .enumerate()
                .map(|(i, c)| (c - origin[i % d]) / unit)
                .collect(),
            values: q.values.iter().zip(scale).map(|(v, s)| v / (s * unit)).collect(),
            gradients: q
                .gradients
                .iter()
                .enumerate()
                .map(|(i, g)| g / scale[i / d])
                .collect(),
            hessians: q
                .hessians
                .iter()
                .enumerate()
                .map(|(i, h)| h * (unit / scale[i / (d * d)]))
                .collect(),
        })
    } else {
        let field = setup
            .obstacles
            .nodes
            .clone()
            .expect("obstacles need quadratics or the caller's field");
        ScaledObstacles::Nodes(Box::new(ScaledNodes {
            field,
            units,
            physical: Vec::new(),
        }))
    }
}

/// Link tension from a multiplier: mu (norm) or 2 d mu (squared).
pub(crate) fn tension(formulation: Formulation, mu: f64, distance: f64) -> f64 {
    match formulation {
        Formulation::Norm => mu,
        Formulation::Squared => 2.0 * distance * mu,
    }
}

/// A link's multiplier from its tension (a link of zero length carries no force).
pub(crate) fn multiplier(formulation: Formulation, tension: f64, distance: f64) -> f64 {
    match formulation {
        Formulation::Norm => tension,
        Formulation::Squared if distance > 0.0 => tension / (2.0 * distance),
        Formulation::Squared => 0.0,
    }
}

/// The iteration's multipliers `mu` (scaled, its rows' order) in the problem's units: the optimised
/// links' into `link_multipliers` (every link, by index), the contact rows' into
/// `obstacle_multipliers` (obstacle after obstacle, a column per node or per link). `distances`:
/// every link's length at the result.
pub(crate) fn multipliers_in_units(
    structure: &Structure,
    setup: &Setup,
    scaling: &Scaling,
    mu: &[f64],
    distances: &[f64],
    link_multipliers: &mut [f64],
    obstacle_multipliers: &mut [f64],
) {
    // (an elastic link between two supports pulls as its stretch says; the others get theirs below)
    for k in (0..structure.lengths.len()).filter(|&k| structure.elastic(k)) {
        let stretch = (distances[k] - structure.lengths[k]).max(0.0);
        link_multipliers[k] = structure.stiffness[k] / structure.lengths[k] * stretch;
    }
    if scaling.free.is_empty() {
        return;
    }
    let unit = scaling.link_unit(setup);
    for (r, &k) in scaling.links.iter().enumerate() {
        // The iteration's multiplier is the smooth stand-in's: as the norm's it applies the
        // same force mu q, mu d / max(d, r) (they differ only on links shorter than r, all slack).
        let mut m = mu[r];
        let radius = SMOOTH_RATIO * structure.lengths[k];
        if setup.formulation == Formulation::Norm && distances[k] < radius {
            m *= distances[k] / radius;
        }
        link_multipliers[k] = m * unit;
    }
    let rows = scaling.contact_rows(setup);
    let n_links = scaling.links.len();
    let count = setup.obstacles.count;
    let columns = obstacle_multipliers.len() / count.max(1);
    for j in 0..count {
        let factor = scaling.weight / scaling.obstacle_scale[j];
        for (r, &i) in rows.iter().enumerate() {
            obstacle_multipliers[j * columns + i] = mu[n_links + j * rows.len() + r] * factor;
        }
    }
}

/// The iteration's failure as a solve's error; `index` names the node or link of a contact row.
pub(crate) fn solve_error(failure: Failure, index: impl Fn(usize) -> usize) -> SolveError {
    match failure {
        Failure::Interrupted => SolveError::Interrupted,
        Failure::NotFactored => SolveError::NotFactored,
        Failure::ObstacleNotFinite {
            obstacle,
            row,
            at_start,
        } => SolveError::ObstacleNotFinite {
            obstacle,
            index: index(row),
            at_start,
        },
    }
}

/// The escape's move along a direction of negative curvature (N, d), turned (an eigenvector's sign
/// is arbitrary) to point towards +x, or +y, so that the same problem always leaves its saddle the
/// same way; returns the step that moves the node that moves most by ESCAPE_STEP of `total_length`.
pub(crate) fn escape_step(direction: &mut [f64], d: usize, total_length: f64) -> f64 {
    let size: f64 = direction.iter().map(|v| v.abs()).sum();
    let mut lean: f64 = direction.iter().step_by(d).sum();
    if lean.abs() <= 1e-6 * size {
        lean = direction.iter().skip(1).step_by(d).sum();
    }
    if lean < 0.0 {
        direction.iter_mut().for_each(|v| *v = -*v);
    }
    let largest = direction.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    ESCAPE_STEP * total_length / largest.max(1e-300)
}

/// The iteration on `network` (see [`ipm::iterate`]) with the linear algebra of its kind: a chain's
/// where every link joins consecutive nodes, a net's otherwise.
pub fn iterate(
    network: &mut Network,
    settings: Settings,
    z: Vec<f64>,
    guess: Option<&[f64]>,
    check: &mut dyn FnMut() -> bool,
) -> Result<Outcome, Failure> {
    if network.path {
        ipm::iterate::<ChainKind>(network, settings, z, guess, check)
    } else {
        ipm::iterate::<NetKind>(network, settings, z, guess, check)
    }
}

/// The second-order test at a result (see [`curvature::escape_test`]) on the Newton matrix of the
/// network's kind.
pub fn escape_test(network: &Network, point: &Point, mu: &[f64], tol: f64, total_length: f64) -> Verdict {
    if network.path {
        curvature::escape_test::<ChainKind>(network, point, mu, tol, total_length)
    } else {
        curvature::escape_test::<NetKind>(network, point, mu, tol, total_length)
    }
}

/// The Newton matrix `W + J^T diag(sigma) J` at `point` with multipliers `mu`, of the network's kind,
/// as a dense array row by row (for tests on small problems).
pub fn dense_newton_matrix(network: &Network, point: &Point, mu: &[f64], sigma: &[f64]) -> Vec<f64> {
    fn dense<M: NetworkMatrix>(network: &Network, point: &Point, mu: &[f64], sigma: &[f64]) -> Vec<f64> {
        let mut matrix = M::for_network(network);
        network.newton_matrix(point, mu, sigma, &mut matrix);
        matrix.to_dense()
    }
    if network.path {
        dense::<BlockTridiagonal>(network, point, mu, sigma)
    } else {
        dense::<SparseMatrix>(network, point, mu, sigma)
    }
}

/// One solve's result in the solver's units, before the escape compares it with others.
pub(crate) struct Once {
    pub status: Status,
    /// (N, d): the free nodes where the iteration left them, the others where the start held them.
    pub positions: Vec<f64>,
    pub iterations: usize,
    /// The multipliers in the iteration's units and rows.
    pub mu: Vec<f64>,
    /// What the iteration spent.
    pub statistics: Statistics,
    /// The network and point for the second-order test, if asked for.
    judge: Option<(Network, Point)>,
}

impl Once {
    /// The answer where nothing is free to move: the start itself.
    pub fn still(positions: Vec<f64>) -> Self {
        Once {
            status: Status::Optimal,
            positions,
            iterations: 0,
            mu: Vec::new(),
            statistics: Statistics::default(),
            judge: None,
        }
    }

    pub fn converged(&self) -> bool {
        self.status == Status::Optimal
    }

    /// The escape's second-order test at the result of a solve of `structure` in the `scaling`'s
    /// units, if it was asked for: a direction of negative curvature as moves of every node (N, d),
    /// zero at the fixed ones.
    pub fn judged(&self, structure: &Structure, scaling: &Scaling) -> Option<Judged> {
        let (network, point) = self.judge.as_ref()?;
        let total_length = structure.total_length() / scaling.length_unit;
        let d = structure.dim;
        Some(
            match escape_test(network, point, &self.mu, ESCAPE_TOL, total_length) {
                Verdict::Minimum => Judged::Minimum,
                Verdict::Undecided => Judged::Undecided,
                Verdict::Direction(value, vector) => {
                    let mut moves = vec![0.0; structure.masses.len() * d];
                    for (f, &node) in scaling.free.iter().enumerate() {
                        moves[node * d..node * d + d].copy_from_slice(&vector[f * d..f * d + d]);
                    }
                    Judged::Direction(value, moves)
                }
            },
        )
    }
}

/// One solve of `structure` from `positions` (N, d; the fixed nodes where they are held) in the
/// `scaling`'s units, from the multipliers `warm` (in the iteration's units and rows) if known;
/// `judged`: keep what the second-order test needs.
#[allow(clippy::too_many_arguments)]
pub(crate) fn solve_once(
    structure: &Structure,
    setup: &Setup,
    options: &Options,
    scaling: &Scaling,
    mut positions: Vec<f64>,
    warm: Option<&[f64]>,
    judged: bool,
    check: &mut dyn FnMut() -> bool,
) -> Result<Once, SolveError> {
    let mut network = network(structure, setup, scaling, &positions);
    let z0 = network.free_coordinates();
    let settings = Settings {
        tol: options.tol,
        max_iterations: options.max_iterations,
    };
    let outcome = iterate(&mut network, settings, z0, warm, check);
    let statistics = network.statistics;
    let rows = scaling.contact_rows(setup);
    let outcome = outcome.map_err(|failure| solve_error(failure, |row| rows[row]))?;
    scaling.place(&outcome.z, &mut positions);
    Ok(Once {
        status: outcome.status,
        positions,
        iterations: outcome.iterations,
        mu: outcome.mu,
        statistics,
        judge: judged.then_some((network, outcome.point)),
    })
}

/// The saddle escape of chains and nets: while the last solve `once` converged where its
/// second-order test (`judged`) found a direction of negative curvature, solve again (`again`) from
/// a step along it, one way and then the other, and keep the first that converges more than
/// 1e-12 W L lower; at most ESCAPES times.
pub(crate) fn escape(
    mut once: Once,
    structure: &Structure,
    judged: impl Fn(&Once) -> Option<Judged>,
    mut again: impl FnMut(Vec<f64>) -> Result<Once, SolveError>,
) -> Result<Once, SolveError> {
    let total = structure.total_length();
    let lower = 1e-12 * structure.weight() * total;
    for _ in 0..ESCAPES {
        if !once.converged() {
            break;
        }
        let Some(Judged::Direction(_, mut moves)) = judged(&once) else {
            break;
        };
        let step = escape_step(&mut moves, structure.dim, total);
        let mut better = None;
        for sign in [1.0, -1.0] {
            let moved = once
                .positions
                .iter()
                .zip(&moves)
                .map(|(p, v)| p + sign * step * v)
                .collect();
            let next = again(moved)?;
            if next.converged()
                && structure.energy(&next.positions) < structure.energy(&once.positions) - lower
            {
                better = Some(next);
                break;
            }
        }
        match better {
            Some(next) => once = next,
            None => break,
        }
    }
    Ok(once)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_obstacle_scale_is_the_median_of_the_finite_positive_norms() {
        assert_eq!(
            median_of_positive(vec![3.0, f64::NAN, 1.0, 0.0, 2.0, f64::INFINITY]),
            2.0
        );
        assert_eq!(median_of_positive(vec![4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median_of_positive(vec![0.0, f64::NAN]), 1.0);
    }
}
