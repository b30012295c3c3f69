//! The whole solve of a chain, in the problem's units: presolve, where to start (the exact catenary,
//! a coarser chain's answer, or the presolve's guess), scaling, the iteration, the saddle escape, and
//! the multipliers back in the problem's units.
//!
//! Scaling: positions `(p - origin) / length_unit` (the first support is the origin, the longest
//! link the unit of length), forces / total weight W, and obstacle j's phi divided by
//! `scale_j * length_unit` where `scale_j` is a typical |grad phi_j| near the free nodes: multiplying
//! phi by a constant leaves every iterate unchanged, and the stopping test does not depend on the
//! units.
//!
//! Coarse to fine: a long chain with obstacles (or a very long one without) is first solved with
//! fewer nodes, and that answer, interpolated along the arclength with its forces, is the start:
//! the coarse chain already drapes over the obstacles, so the fine solve starts next to its answer
//! instead of travelling there in many short steps, and usually needs only the polish.
//!
//! The saddle escape: with obstacles a KKT point may be a saddle of the energy (a chain balanced
//! on the top of a disk). At the result the second-order test on the solver's own Newton matrix
//! (`curvature::escape_test`) gives a direction of negative curvature, if there is one; the chain
//! moves along it and is solved again, and the lower energy is kept.

use std::cell::RefCell;
use std::rc::Rc;

use crate::catenary::exact_start;
use crate::curvature::{escape_test, Verdict};
use crate::evaluate::{norm, Point};
use crate::ipm::{iterate, Failure, Settings, Status};
use crate::network::{
    Formulation, Interrupted, Network, NodeField, Obstacles as Evaluated, Quadratics, SegmentField,
    Statistics, SMOOTH_RATIO,
};
use crate::presolve::{presolve, repositioned, Chain, Infeasible, Presolved, QuadraticShapes, Shapes};

/// Chains with obstacles longer than this start from a coarse solve.
pub const COARSE_ABOVE: usize = 200;
/// The same without obstacles (below, one direct solve is as fast).
pub const COARSE_ABOVE_FREE: usize = 4000;
/// The coarse level has N / COARSE_FACTOR nodes, with obstacles at most COARSE_CAP until that is
/// N / COARSE_FACTOR_MAX: there the fine level spends a step correcting the contact near the
/// lift-off points whatever the coarse level, so a finer coarse level costs more than it saves.
const COARSE_FACTOR: usize = 8;
const COARSE_CAP: usize = 5000;
const COARSE_FACTOR_MAX: usize = 32;
/// Nodes up to which the escape checks the result (the test costs about a second at 10^5).
pub const ESCAPE_UP_TO: usize = 20_000;
/// The escape's move, of the chain's length, for the node that moves most.
const ESCAPE_STEP: f64 = 0.05;
pub(crate) const ESCAPES: usize = 2;
/// The second-order test's relative tolerance: the checker's.
pub const ESCAPE_TOL: f64 = 1e-6;
/// The obstacle scale is a median over at most twice this many evenly spaced nodes.
const SCALE_SAMPLE: usize = 4096;

/// Link contact evaluated by the caller, in the problem's units: for every obstacle j and every link
/// k in `links` (given by its first node; it joins k and k + 1), phi_j's largest value psi along
/// the link, where it is (t in [0, 1] from node k), the gradient of phi there (J, L, d) and the
/// Hessian of psi over both nodes' coordinates (J, L, 2d, 2d), from every node's positions (N, d).
pub trait Segments {
    fn evaluate(
        &mut self,
        positions: &[f64],
        links: &[usize],
        psi: &mut [f64],
        t: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted>;
}

/// The obstacles in the problem's units: quadratics evaluated here, or a field evaluated by the
/// caller; with link contact, the caller's segments too.
pub struct Obstacles {
    pub count: usize,
    pub quadratics: Option<Quadratics>,
    pub nodes: Option<Rc<RefCell<dyn NodeField>>>,
    pub segments: Option<Rc<RefCell<dyn Segments>>>,
}

/// What does not change from level to level: the formulation and the obstacles.
pub struct Setup {
    pub formulation: Formulation,
    pub obstacles: Obstacles,
    /// Contact rows per link instead of per node.
    pub links_contact: bool,
}

#[derive(Clone, Copy, Debug)]
pub struct Options {
    pub tol: f64,
    pub max_iterations: usize,
    pub escape_saddles: bool,
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

/// The obstacles one at a time, for the presolve and the exact start.
pub struct OneByOne<'a> {
    pub dim: usize,
    pub obstacles: &'a Obstacles,
}

impl Shapes for OneByOne<'_> {
    fn count(&self) -> usize {
        self.obstacles.count
    }

    fn evaluate(
        &mut self,
        j: usize,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
    ) -> Result<(), Interrupted> {
        let d = self.dim;
        if let Some(quadratics) = &self.obstacles.quadratics {
            return QuadraticShapes { dim: d, quadratics }.evaluate(j, points, phi, gradient);
        }
        let Some(field) = &self.obstacles.nodes else {
            return Ok(());
        };
        let (n, k) = (points.len() / d, self.obstacles.count);
        let (mut all_phi, mut all_gradient, mut hessian) =
            (vec![0.0; k * n], vec![0.0; k * n * d], vec![0.0; k * n * d * d]);
        field
            .borrow_mut()
            .evaluate(points, &mut all_phi, &mut all_gradient, &mut hessian)?;
        phi.copy_from_slice(&all_phi[j * n..(j + 1) * n]);
        gradient.copy_from_slice(&all_gradient[j * n * d..(j + 1) * n * d]);
        Ok(())
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
    fn link_unit(&self, setup: &Setup) -> f64 {
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

    /// The escape's second-order test at a result (`network`, `point`, `mu` in the solver's units)
    /// of a structure `total_length` long with `n_nodes` nodes: a direction of negative curvature as
    /// moves of every node (N, d), zero at the fixed ones.
    pub(crate) fn judged(
        &self,
        network: &Network,
        point: &Point,
        mu: &[f64],
        total_length: f64,
        n_nodes: usize,
    ) -> Judged {
        let d = self.origin.len();
        match escape_test(network, point, mu, ESCAPE_TOL, total_length / self.length_unit) {
            Verdict::Minimum => Judged::Minimum,
            Verdict::Undecided => Judged::Undecided,
            Verdict::Direction(value, vector) => {
                let mut moves = vec![0.0; n_nodes * d];
                for (f, &node) in self.free.iter().enumerate() {
                    moves[node * d..node * d + d].copy_from_slice(&vector[f * d..f * d + d]);
                }
                Judged::Direction(value, moves)
            }
        }
    }

    /// What each obstacle's contact rows stand for: optimised links or free nodes.
    fn contact_rows<'a>(&'a self, setup: &Setup) -> &'a [usize] {
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

fn scaling(chain: &Chain, setup: &Setup, start: &Presolved) -> Result<Scaling, Interrupted> {
    let d = chain.dim;
    let n = chain.n_nodes();
    let length_unit = chain.lengths.iter().copied().fold(0.0, f64::max);
    let origin = chain.support_positions[..d].to_vec();
    let weight = chain.gravity * chain.masses.iter().sum::<f64>();
    let mut movable = vec![false; n];
    for &node in &start.movable {
        movable[node] = true;
    }
    let mut detached = vec![false; n];
    for &node in &start.detached {
        detached[node] = true;
    }
    let links: Vec<usize> = (0..n - 1)
        .filter(|&k| (movable[k] || movable[k + 1]) && !detached[k] && !detached[k + 1])
        .collect();
    let free = start.movable.clone();
    let obstacle_scale = obstacle_scales(setup, d, &free, &start.positions, start.gradients.as_deref())?;
    Ok(Scaling {
        length_unit,
        origin,
        weight,
        free,
        links,
        obstacle_scale,
    })
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
    /// Scaled points (n, d) in the problem's units.
    fn physical(&self, points: &[f64]) -> Vec<f64> {
        points
            .iter()
            .enumerate()
            .map(|(i, s)| s * self.length_unit + self.origin[i % self.dim])
            .collect()
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
        self.field
            .borrow_mut()
            .evaluate(&self.units.physical(points), phi, gradient, hessian)?;
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
        let physical = self.units.physical(positions);
        self.segments
            .borrow_mut()
            .evaluate(&physical, &self.links, psi, t, gradient, hessian)?;
        self.units
            .scale_back(self.links.len(), psi, gradient, hessian, 4 * d * d);
        Ok(())
    }
}

/// What the iteration needs of a chain or a net besides its supports: the nodes' masses, the links
/// (node pairs: a chain's link k joins k and k + 1) with their lengths, gravity.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Structure<'a> {
    pub dim: usize,
    pub masses: &'a [f64],
    pub lengths: &'a [f64],
    pub gravity: f64,
    /// The links' node pairs; None: the path graph.
    pub pairs: Option<&'a [[usize; 2]]>,
    /// Point loads (N, d), applied forces beside the weights; empty: none.
    pub loads: &'a [f64],
    /// Each link's axial stiffness EA, infinite for an inextensible link; empty: none is elastic.
    pub stiffness: &'a [f64],
}

impl<'a> Structure<'a> {
    pub fn of_chain(chain: &'a Chain) -> Self {
        Structure {
            dim: chain.dim,
            masses: &chain.masses,
            lengths: &chain.lengths,
            gravity: chain.gravity,
            pairs: None,
            loads: &[],
            stiffness: &[],
        }
    }

    /// Whether link k is elastic (a finite axial stiffness).
    pub fn elastic(&self, k: usize) -> bool {
        self.stiffness.get(k).is_some_and(|ea| ea.is_finite())
    }

    /// The solver's unit of force: the weight; without any, the point loads' sum of magnitudes;
    /// without either, the smallest axial stiffness (a weightless, unloaded net held by its
    /// pretension).
    pub fn force_scale(&self) -> f64 {
        let weight = self.weight();
        if weight > 0.0 {
            return weight;
        }
        let d = self.dim;
        let loads: f64 = self.loads.chunks_exact(d).map(norm).sum();
        if loads > 0.0 {
            return loads;
        }
        self.stiffness
            .iter()
            .copied()
            .filter(|ea| ea.is_finite())
            .fold(f64::INFINITY, f64::min)
    }

    pub fn pair(&self, k: usize) -> [usize; 2] {
        match self.pairs {
            Some(pairs) => pairs[k],
            None => [k, k + 1],
        }
    }

    pub fn weight(&self) -> f64 {
        self.gravity * self.masses.iter().sum::<f64>()
    }

    pub fn total_length(&self) -> f64 {
        self.lengths.iter().sum()
    }

    /// Every link's length at `positions` (N, d).
    pub fn distances(&self, positions: &[f64]) -> Vec<f64> {
        let d = self.dim;
        (0..self.lengths.len())
            .map(|k| {
                let [a, b] = self.pair(k);
                let mut delta = [0.0; 3];
                for i in 0..d {
                    delta[i] = positions[a * d + i] - positions[b * d + i];
                }
                norm(&delta[..d])
            })
            .collect()
    }

    /// The potential energy `g m . (last coordinates) - P . p` (P the point loads).
    pub fn energy(&self, positions: &[f64]) -> f64 {
        let d = self.dim;
        let weights: f64 = self
            .masses
            .iter()
            .enumerate()
            .map(|(i, m)| self.gravity * m * positions[i * d + d - 1])
            .sum();
        let loads: f64 = self.loads.iter().zip(positions).map(|(f, p)| f * p).sum();
        let distances = if self.stiffness.is_empty() {
            Vec::new()
        } else {
            self.distances(positions)
        };
        let springs: f64 = (0..distances.len())
            .filter(|&k| self.elastic(k))
            .map(|k| {
                let stretch = (distances[k] - self.lengths[k]).max(0.0);
                0.5 * self.stiffness[k] / self.lengths[k] * stretch * stretch
            })
            .sum();
        weights - loads + springs
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
        obstacle_scale: scale,
    } = scaling;
    let count = setup.obstacles.count;
    let units = Units {
        dim: d,
        length_unit: *unit,
        origin: origin.clone(),
        scale: scale.clone(),
    };
    let scaled: Vec<f64> = positions
        .iter()
        .enumerate()
        .map(|(i, p)| (p - origin[i % d]) / unit)
        .collect();
    let obstacles = if count == 0 {
        Evaluated::none()
    } else if setup.links_contact {
        let segments = setup
            .obstacles
            .segments
            .clone()
            .expect("link contact needs the caller's segments");
        Evaluated::Links(Box::new(ScaledSegments {
            segments,
            links: links.clone(),
            units,
        }))
    } else if let Some(q) = &setup.obstacles.quadratics {
        // p = length_unit s + origin; phi / (scale length_unit) over s
        Evaluated::Quadratic(Quadratics {
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
        Evaluated::Nodes(Box::new(ScaledNodes { field, units }))
    };
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

/// The network the iteration would start from at `guess` (N, d), through the presolve and the
/// scaling (for tests of the iteration's derivatives).
pub fn network_at(chain: &Chain, setup: &Setup, guess: &[f64]) -> Result<Network, SolveError> {
    let mut shapes = OneByOne {
        dim: chain.dim,
        obstacles: &setup.obstacles,
    };
    let start = presolve(chain, &mut shapes, Some(guess), false)?;
    let scaling = scaling(chain, setup, &start)?;
    Ok(network(
        &Structure::of_chain(chain),
        setup,
        &scaling,
        &start.positions,
    ))
}

/// Link tension from a multiplier: mu (norm) or 2 d mu (squared).
fn tension(formulation: Formulation, mu: f64, distance: f64) -> f64 {
    match formulation {
        Formulation::Norm => mu,
        Formulation::Squared => 2.0 * distance * mu,
    }
}

/// A link's multiplier from its tension (a link of zero length carries no force).
fn multiplier(formulation: Formulation, tension: f64, distance: f64) -> f64 {
    match formulation {
        Formulation::Norm => tension,
        Formulation::Squared if distance > 0.0 => tension / (2.0 * distance),
        Formulation::Squared => 0.0,
    }
}

/// The guess's multipliers in the iteration's units and order (links, then contact rows obstacle by
/// obstacle).
fn scaled_multipliers(chain: &Chain, setup: &Setup, scaling: &Scaling, guess: &Guess) -> Option<Vec<f64>> {
    let (links, contacts) = (
        guess.link_multipliers.as_ref()?,
        guess.obstacle_multipliers.as_ref()?,
    );
    let unit = scaling.link_unit(setup);
    let mut scaled: Vec<f64> = scaling.links.iter().map(|&k| links[k] / unit).collect();
    let columns = if setup.links_contact {
        chain.n_nodes() - 1
    } else {
        chain.n_nodes()
    };
    for j in 0..setup.obstacles.count {
        let factor = scaling.obstacle_scale[j] / scaling.weight;
        scaled.extend(
            scaling
                .contact_rows(setup)
                .iter()
                .map(|&i| contacts[j * columns + i] * factor),
        );
    }
    Some(scaled)
}

/// One solve's result, before the escape compares it with others.
struct Once {
    status: Status,
    /// (N, d), massless free ends as the iteration left them.
    positions: Vec<f64>,
    iterations: usize,
    start: Presolved,
    scaling: Scaling,
    mu: Vec<f64>,
    statistics: Statistics,
    seeded: bool,
    /// The network and point for the escape's test, if asked for.
    judge: Option<(Network, Point)>,
}

impl Once {
    fn converged(&self) -> bool {
        self.status == Status::Optimal
    }

    /// The escape's second-order test at the result.
    fn judged(&self, chain: &Chain) -> Option<Judged> {
        let (network, point) = self.judge.as_ref()?;
        let total: f64 = chain.lengths.iter().sum();
        Some(
            self.scaling
                .judged(network, point, &self.mu, total, chain.n_nodes()),
        )
    }

    /// The answer in the problem's units.
    fn solved(
        self,
        chain: &Chain,
        setup: &Setup,
        iterations: usize,
        statistics: Statistics,
        judged: Option<Judged>,
    ) -> Solved {
        let d = chain.dim;
        let n = chain.n_nodes();
        let mut positions = self.positions;
        // (links between fixed nodes: as the presolve placed them)
        let lengths = Structure::of_chain(chain).distances(&positions);
        for (&node, &on) in self.start.detached.iter().zip(&self.start.attach) {
            let anchor = positions[on * d..on * d + d].to_vec();
            positions[node * d..node * d + d].copy_from_slice(&anchor);
        }
        let mut link_multipliers: Vec<f64> = (0..n - 1)
            .map(|k| multiplier(setup.formulation, self.start.fixed_tension[k], lengths[k]))
            .collect();
        let columns = if setup.links_contact { n - 1 } else { n };
        let count = setup.obstacles.count;
        let mut obstacle_multipliers = vec![0.0; count * columns];
        multipliers_in_units(
            &Structure::of_chain(chain),
            setup,
            &self.scaling,
            &self.mu,
            &lengths,
            &mut link_multipliers,
            &mut obstacle_multipliers,
        );
        Solved {
            status: self.status,
            positions,
            link_multipliers,
            obstacle_multipliers,
            iterations,
            statistics,
            judged,
        }
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

/// The pieces of a solve that stay fixed while the escape moves the chain: its presolve and
/// scaling.
struct Previous<'a> {
    start: &'a Presolved,
    scaling: &'a Scaling,
}

/// One solve from `initial` or the built-in guess (the exact start, or coarse to fine).
fn solve_once(
    chain: &Chain,
    setup: &Setup,
    options: &Options,
    initial: Option<&Guess>,
    judged: bool,
    previous: Option<Previous>,
    check: &mut dyn FnMut() -> bool,
) -> Result<Once, SolveError> {
    let d = chain.dim;
    let mut shapes = OneByOne {
        dim: d,
        obstacles: &setup.obstacles,
    };
    let built;
    let guess: Option<&Guess> = match initial {
        Some(guess) => Some(guess),
        None => {
            built = match if options.exact_start {
                exact_guess(chain, setup, &mut shapes)?
            } else {
                None
            } {
                Some(exact) => Some(exact),
                None => coarse_guess(chain, setup, options, check)?,
            };
            built.as_ref()
        }
    };
    let seeded = initial.is_none() && guess.is_some();
    // Link contact is left out: its step counts from a settled guess went both ways.
    let settled = guess.is_some_and(|g| g.settled) && !setup.links_contact;
    let (start, scaling) = match previous {
        Some(previous) => {
            let guess = guess.expect("the escape solves again from a moved chain");
            let start = repositioned(chain, &mut shapes, previous.start, &guess.positions, false)?;
            (start, previous.scaling.clone())
        }
        None => {
            let start = presolve(chain, &mut shapes, guess.map(|g| g.positions.as_slice()), settled)?;
            let scaling = scaling(chain, setup, &start)?;
            (start, scaling)
        }
    };
    let mut statistics = guess.map(|g| g.statistics).unwrap_or_default();
    let mut positions = start.positions.clone();
    let (mut mu, mut iterations, mut status) = (Vec::new(), 0, Status::Optimal);
    let mut judge = None;
    if !scaling.free.is_empty() {
        let warm = guess.and_then(|g| scaled_multipliers(chain, setup, &scaling, g));
        let mut net = network(&Structure::of_chain(chain), setup, &scaling, &start.positions);
        let z0 = net.free_coordinates();
        let settings = Settings {
            tol: options.tol,
            max_iterations: options.max_iterations,
        };
        let outcome = iterate(&mut net, settings, z0, warm.as_deref(), check);
        add(&mut statistics, &net.statistics);
        let outcome = outcome.map_err(|failure| {
            solve_error(failure, |row| {
                if setup.links_contact {
                    scaling.links[row]
                } else {
                    scaling.free[row]
                }
            })
        })?;
        (mu, iterations, status) = (outcome.mu, outcome.iterations, outcome.status);
        scaling.place(&outcome.z, &mut positions);
        if judged {
            judge = Some((net, outcome.point));
        }
    }
    Ok(Once {
        status,
        positions,
        iterations,
        start,
        scaling,
        mu,
        statistics,
        seeded,
        judge,
    })
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

pub(crate) fn add(total: &mut Statistics, more: &Statistics) {
    total.interior_point_steps += more.interior_point_steps;
    total.polish_steps += more.polish_steps;
    total.evaluations += more.evaluations;
    total.factorizations += more.factorizations;
    total.evaluation_seconds += more.evaluation_seconds;
    total.newton_seconds += more.newton_seconds;
    total.polish_seconds += more.polish_seconds;
    total.total_seconds += more.total_seconds;
}

/// The equilibrium with its forces where `catenary::exact_start` knows it (a chain touching
/// nothing): the polish then only confirms it, in one Newton step. With link contact every link
/// the solver keeps out of the obstacles (a movable end, no detached end) must clear them too.
fn exact_guess(chain: &Chain, setup: &Setup, shapes: &mut dyn Shapes) -> Result<Option<Guess>, SolveError> {
    let Some((positions, tensions)) = exact_start(chain, shapes)? else {
        return Ok(None);
    };
    let n = chain.n_nodes();
    if setup.links_contact && setup.obstacles.count > 0 {
        let (detached, _) = crate::presolve::massless_ends(chain);
        let (mut support, mut left_out) = (vec![false; n], vec![false; n]);
        chain.supports.iter().for_each(|&s| support[s] = true);
        detached.iter().for_each(|&i| left_out[i] = true);
        let links: Vec<usize> = (0..n - 1)
            .filter(|&k| (!support[k] || !support[k + 1]) && !left_out[k] && !left_out[k + 1])
            .collect();
        let (l, d, count) = (links.len(), chain.dim, setup.obstacles.count);
        let (mut psi, mut t) = (vec![0.0; count * l], vec![0.0; count * l]);
        let (mut gradient, mut hessian) = (vec![0.0; count * l * d], vec![0.0; count * l * 4 * d * d]);
        let segments = setup
            .obstacles
            .segments
            .as_ref()
            .expect("link contact needs the caller's segments");
        segments
            .borrow_mut()
            .evaluate(&positions, &links, &mut psi, &mut t, &mut gradient, &mut hessian)?;
        if !psi.iter().all(|&v| v < 0.0) {
            return Ok(None);
        }
    }
    let lengths = Structure::of_chain(chain).distances(&positions);
    let links = tensions
        .iter()
        .zip(&lengths)
        .map(|(&t, &l)| multiplier(setup.formulation, t, l))
        .collect();
    let columns = n - usize::from(setup.links_contact);
    Ok(Some(Guess {
        positions,
        link_multipliers: Some(links),
        obstacle_multipliers: Some(vec![0.0; setup.obstacles.count * columns]),
        settled: true,
        statistics: Statistics::default(),
    }))
}

/// `np.interp(x, xp, fp)` for ascending x and xp: piecewise linear, constant beyond the ends.
fn interpolate(x: &[f64], xp: &[f64], fp: &[f64]) -> Vec<f64> {
    let last = xp.len() - 1;
    let mut j = 0;
    x.iter()
        .map(|&v| {
            while j < last && xp[j + 1] <= v {
                j += 1;
            }
            if v <= xp[0] {
                fp[0]
            } else if j == last {
                fp[last]
            } else {
                let slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]);
                slope * (v - xp[j]) + fp[j]
            }
        })
        .collect()
}

/// Each node's arclength position along the chain, from 0 to 1.
fn arc_fractions(chain: &Chain) -> Vec<f64> {
    let total: f64 = chain.lengths.iter().sum();
    let mut arc = 0.0;
    let mut fractions = vec![0.0];
    for l in &chain.lengths {
        arc += l;
        fractions.push(arc / total);
    }
    fractions
}

/// The same chain with `nodes` nodes: total mass and length kept, spread equally; each support on
/// the node nearest its arclength position (None if two would share one).
fn with_nodes(chain: &Chain, nodes: usize) -> Option<Chain> {
    let arc = arc_fractions(chain);
    let supports: Vec<usize> = chain
        .supports
        .iter()
        .map(|&s| (arc[s] * (nodes - 1) as f64).round_ties_even() as usize)
        .collect();
    if supports.windows(2).any(|pair| pair[0] >= pair[1]) {
        return None;
    }
    let (mass, length): (f64, f64) = (chain.masses.iter().sum(), chain.lengths.iter().sum());
    Some(Chain {
        dim: chain.dim,
        masses: vec![mass / nodes as f64; nodes],
        lengths: vec![length / (nodes - 1) as f64; nodes - 1],
        gravity: chain.gravity,
        supports,
        support_positions: chain.support_positions.clone(),
    })
}

/// How many nodes the coarse level of a chain of n nodes gets.
fn coarse_nodes(n: usize, obstacles: bool) -> usize {
    if !obstacles {
        return n / COARSE_FACTOR;
    }
    (n / COARSE_FACTOR_MAX).max((n / COARSE_FACTOR).min(COARSE_CAP))
}

/// The length of chain each node stands for: half of each link next to it.
fn node_shares(chain: &Chain) -> Vec<f64> {
    let n = chain.n_nodes();
    let mut shares = vec![0.0; n];
    for (k, l) in chain.lengths.iter().enumerate() {
        shares[k] += 0.5 * l;
        shares[k + 1] += 0.5 * l;
    }
    shares
}

/// Grid sequencing for long chains: the same chain solved with fewer nodes (`coarse_nodes`), its
/// answer interpolated along the arclength, its forces too (tensions along the chain, contact
/// forces as a force per length). None where there is no coarse level or it did not converge.
fn coarse_guess(
    chain: &Chain,
    setup: &Setup,
    options: &Options,
    check: &mut dyn FnMut() -> bool,
) -> Result<Option<Guess>, SolveError> {
    let n = chain.n_nodes();
    let count = setup.obstacles.count;
    if n <= if count > 0 {
        COARSE_ABOVE
    } else {
        COARSE_ABOVE_FREE
    } {
        return Ok(None);
    }
    let Some(coarse) = with_nodes(chain, (COARSE_ABOVE / 2).max(coarse_nodes(n, count > 0))) else {
        return Ok(None);
    };
    let solved = match solve(&coarse, setup, options, None, false, check) {
        Ok(solved) if solved.status == Status::Optimal => solved,
        // (moving a support to a coarse node can make a nearly taut span infeasible; the fine
        // level reports what is wrong with the chain itself)
        Ok(_)
        | Err(SolveError::Infeasible(_) | SolveError::NotFactored | SolveError::ObstacleNotFinite { .. }) => {
            return Ok(None)
        }
        Err(SolveError::Interrupted) => return Err(SolveError::Interrupted),
    };
    let d = chain.dim;
    // The coarse supports lined up with the fine ones: the map between the supports' arclength
    // fractions on either chain (with both ends) takes each coarse support onto its fine support,
    // or the nodes next to a support start up to half a coarse link off it.
    let (fine_arc, coarse_arc) = (arc_fractions(chain), arc_fractions(&coarse));
    let (mut xp, mut fp) = (vec![0.0], vec![0.0]);
    for (&c, &f) in coarse.supports.iter().zip(&chain.supports) {
        if coarse_arc[c] > *xp.last().unwrap() {
            xp.push(coarse_arc[c]);
            fp.push(fine_arc[f]);
        }
    }
    if *xp.last().unwrap() < 1.0 {
        xp.push(1.0);
        fp.push(1.0);
    }
    let coarse_at = interpolate(&coarse_arc, &xp, &fp);
    let middles = |a: &[f64]| -> Vec<f64> { a.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect() };
    let (coarse_links, fine_links) = (middles(&coarse_at), middles(&fine_arc));
    let mut positions = vec![0.0; n * d];
    for i in 0..d {
        let coordinate: Vec<f64> = solved.positions.iter().skip(i).step_by(d).copied().collect();
        for (k, v) in interpolate(&fine_arc, &coarse_at, &coordinate)
            .into_iter()
            .enumerate()
        {
            positions[k * d + i] = v;
        }
    }
    let coarse_lengths = Structure::of_chain(&coarse).distances(&solved.positions);
    let tensions: Vec<f64> = (0..coarse.n_nodes() - 1)
        .map(|k| tension(setup.formulation, solved.link_multipliers[k], coarse_lengths[k]))
        .collect();
    let fine_lengths = Structure::of_chain(chain).distances(&positions);
    let links = interpolate(&fine_links, &coarse_links, &tensions)
        .iter()
        .zip(&fine_lengths)
        .map(|(&t, &l)| multiplier(setup.formulation, t, l))
        .collect();
    let mut contacts = Vec::new();
    let coarse_columns = solved.obstacle_multipliers.len() / count.max(1);
    for j in 0..count {
        let row = &solved.obstacle_multipliers[j * coarse_columns..(j + 1) * coarse_columns];
        if setup.links_contact {
            // per link: a force per length of link
            let density: Vec<f64> = row.iter().zip(&coarse.lengths).map(|(m, l)| m / l).collect();
            let fine = interpolate(&fine_links, &coarse_links, &density);
            contacts.extend(fine.iter().zip(&chain.lengths).map(|(f, l)| f * l));
        } else {
            let (coarse_shares, fine_shares) = (node_shares(&coarse), node_shares(chain));
            let density: Vec<f64> = row.iter().zip(&coarse_shares).map(|(m, s)| m / s).collect();
            let fine = interpolate(&fine_arc, &coarse_at, &density);
            contacts.extend(fine.iter().zip(&fine_shares).map(|(f, s)| f * s));
        }
    }
    Ok(Some(Guess {
        positions,
        link_multipliers: Some(links),
        obstacle_multipliers: Some(contacts),
        settled: true,
        statistics: solved.statistics,
    }))
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

/// The saddle escape of chains and nets: while the last solve `once` converged (`converged`) where
/// its second-order test found a direction of negative curvature (`direction`, over its positions
/// (N, d)), solve again (`again`) from a step along it, one way and then the other, and keep the
/// first that converges more than 1e-12 W L lower (`energy`); at most ESCAPES times.
pub(crate) fn escape<S, E>(
    mut once: S,
    structure: &Structure,
    converged: impl Fn(&S) -> bool,
    direction: impl Fn(&S) -> Option<Judged>,
    positions: impl Fn(&S) -> &[f64],
    mut again: impl FnMut(&S, Vec<f64>) -> Result<S, E>,
) -> Result<S, E> {
    let total = structure.total_length();
    let lower = 1e-12 * structure.weight() * total;
    for _ in 0..ESCAPES {
        if !converged(&once) {
            break;
        }
        let Some(Judged::Direction(_, mut moves)) = direction(&once) else {
            break;
        };
        let step = escape_step(&mut moves, structure.dim, total);
        let mut better = None;
        for sign in [1.0, -1.0] {
            let moved = positions(&once)
                .iter()
                .zip(&moves)
                .map(|(p, v)| p + sign * step * v)
                .collect();
            let next = again(&once, moved)?;
            let energy = |s: &S| structure.energy(positions(s));
            if converged(&next) && energy(&next) < energy(&once) - lower {
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

/// The equilibrium of `chain` with its forces, from `initial` or the built-in guess; `judge`: the
/// escape's second-order test at the result too.
///
/// With obstacles (node contact, up to ESCAPE_UP_TO nodes) and `options.escape_saddles`, a result
/// that is not a minimum is left along a direction of negative curvature (see the module
/// documentation). A chain solved coarse to fine is checked on its coarsest level only: each finer
/// level starts next to the minimum the level below found. One that starts from the exact catenary
/// touches no obstacle and is the free chain's minimum, which is convex: nothing to check.
pub fn solve(
    chain: &Chain,
    setup: &Setup,
    options: &Options,
    initial: Option<&Guess>,
    judge: bool,
    check: &mut dyn FnMut() -> bool,
) -> Result<Solved, SolveError> {
    let escape = options.escape_saddles
        && setup.obstacles.count > 0
        && !setup.links_contact
        && chain.n_nodes() <= ESCAPE_UP_TO;
    let mut once = solve_once(chain, setup, options, initial, escape || judge, None, check)?;
    let (mut iterations, mut statistics) = (once.iterations, once.statistics);
    if escape && !once.seeded {
        once = self::escape(
            once,
            &Structure::of_chain(chain),
            Once::converged,
            |once| once.judged(chain),
            |once| &once.positions,
            |once, positions| {
                let moved = Guess {
                    positions,
                    ..Guess::default()
                };
                let previous = Previous {
                    start: &once.start,
                    scaling: &once.scaling,
                };
                let again = solve_once(chain, setup, options, Some(&moved), true, Some(previous), check)?;
                iterations += again.iterations;
                add(&mut statistics, &again.statistics);
                Ok::<_, SolveError>(again)
            },
        )?;
    }
    let judged = if judge { once.judged(chain) } else { None };
    Ok(once.solved(chain, setup, iterations, statistics, judged))
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

    #[test]
    fn interpolation_is_piecewise_linear_and_constant_beyond_the_ends() {
        let (xp, fp) = ([0.0, 1.0, 1.0, 3.0], [0.0, 2.0, 5.0, 9.0]);
        let y = interpolate(&[-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 4.0], &xp, &fp);
        assert_eq!(y, vec![0.0, 0.0, 1.0, 5.0, 7.0, 9.0, 9.0]);
    }

    #[test]
    fn a_coarser_chain_keeps_its_mass_length_and_supports_in_order() {
        let chain = Chain {
            dim: 2,
            masses: vec![1.0; 101],
            lengths: vec![0.01; 100],
            gravity: 1.0,
            supports: vec![0, 50, 100],
            support_positions: vec![0.0, 0.0, 0.4, 0.0, 0.8, 0.0],
        };
        let coarse = with_nodes(&chain, 11).unwrap();
        assert_eq!(coarse.supports, vec![0, 5, 10]);
        assert!((coarse.masses.iter().sum::<f64>() - 101.0).abs() < 1e-12);
        assert!((coarse.lengths.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // two supports on one coarse node: no coarse level
        let close = Chain {
            supports: vec![0, 1, 100],
            ..chain
        };
        assert!(with_nodes(&close, 11).is_none());
    }
}
