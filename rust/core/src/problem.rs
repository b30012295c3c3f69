//! The problem types: a chain or a net in the problem's units as the caller gives it, with its
//! obstacles ([`Chain`], [`Net`], their common view [`Structure`], the formulation and obstacles in
//! [`Setup`]), and the same problem in the solver's units, which the iteration works on
//! ([`Network`]).
//!
//! Positions are (N, d) arrays stored row by row (d = 2 or 3); gravity acts along the last axis.
//! Links are node pairs with a length each, any graph (a cable net): a chain is the path graph, link
//! k joining nodes k and k + 1, which the linear algebra treats by its own fast paths
//! (`Network::path`).
//!
//! In the solver's units lengths are in units of the longest link, forces in units of the total
//! weight, and each obstacle's phi is divided by a typical |grad phi| so that it is roughly a
//! distance. Constraint rows, in this order: the links (`c_r <= 0`), then for every obstacle j its
//! contact rows, one per free node (node contact) or one per link (link contact): row
//! `n_links + j R + r`.

use std::cell::RefCell;
use std::rc::Rc;

use crate::linalg::norm;

/// Below this fraction of its length a norm link's constraint is replaced by a parabola (see
/// [`crate::evaluate`]): the barrier is then smooth where two nodes meet.
pub const SMOOTH_RATIO: f64 = 0.5;

/// Which link constraint the problem uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Formulation {
    /// `c = ||p_a - p_b|| - l`: its multiplier is the link's tension.
    Norm,
    /// `c = ||p_a - p_b||^2 - l^2`: its multiplier is the tension over twice the link's length.
    Squared,
}

/// Why an obstacle evaluation defined outside the core did not deliver: the caller keeps the reason
/// (an exception of its own, an interrupt) and the iteration stops at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Interrupted;

/// Obstacles evaluated at points, all at once: phi (J, n), its gradient (J, n, d) and Hessian
/// (J, n, d, d) at the n points given as an (n, d) array, each obstacle's rows after the other's.
pub trait NodeField {
    fn count(&self) -> usize;
    fn evaluate(
        &mut self,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted>;
}

/// Obstacles evaluated along links (link contact): for every obstacle j and link r, phi_j's largest
/// value psi along the link, where it is (`t` in [0, 1] from the link's first node), the gradient of
/// phi there (J, L, d), and the Hessian of psi over both nodes' coordinates (J, L, 2d, 2d).
/// `positions` holds every node (N, d).
pub trait SegmentField {
    fn count(&self) -> usize;
    fn evaluate(
        &mut self,
        positions: &[f64],
        psi: &mut [f64],
        t: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted>;
}

/// Obstacles whose phi is a quadratic (disks, ellipses, half-planes, spheres, ellipsoids,
/// half-spaces): `phi(p) = value + (g(p) + b) . (p - centre) / 2` with `g(p) = b + H (p - centre)`.
#[derive(Clone, Debug, Default)]
pub struct Quadratics {
    pub centres: Vec<f64>,
    pub values: Vec<f64>,
    pub gradients: Vec<f64>,
    pub hessians: Vec<f64>,
}

impl Quadratics {
    /// phi_j at `point` (d coordinates), and its gradient into `gradient`.
    #[inline(always)]
    pub fn value_and_gradient(&self, j: usize, d: usize, point: &[f64], gradient: &mut [f64]) -> f64 {
        let centre = &self.centres[j * d..j * d + d];
        let b = &self.gradients[j * d..j * d + d];
        let h = &self.hessians[j * d * d..(j + 1) * d * d];
        let mut offset = [0.0; 3];
        for i in 0..d {
            offset[i] = point[i] - centre[i];
        }
        let mut phi = 0.0;
        for k in 0..d {
            let mut g = b[k];
            for i in 0..d {
                g += offset[i] * h[i * d + k];
            }
            gradient[k] = g;
            phi += offset[k] * (g + b[k]);
        }
        self.values[j] + 0.5 * phi
    }
}

/// The obstacles of a problem and how they are evaluated.
pub enum ScaledObstacles {
    /// Quadratics evaluated here, node contact (none at all: empty quadratics).
    Quadratic(Quadratics),
    /// Node contact, evaluated by the caller.
    Nodes(Box<dyn NodeField>),
    /// Link contact, evaluated by the caller.
    Links(Box<dyn SegmentField>),
}

impl ScaledObstacles {
    pub fn none() -> Self {
        ScaledObstacles::Quadratic(Quadratics::default())
    }
}

/// What the iteration spent, counted as it goes (since the network was made or last `reset`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Statistics {
    pub interior_point_steps: usize,
    pub polish_steps: usize,
    pub evaluations: usize,
    pub factorizations: usize,
    /// Seconds evaluating constraints, gradients and the residual of stationarity.
    pub evaluation_seconds: f64,
    /// Seconds assembling, factorizing and solving the interior-point Newton systems.
    pub newton_seconds: f64,
    /// Seconds assembling, factorizing and solving the polish's KKT systems.
    pub polish_seconds: f64,
    /// Seconds in the iteration altogether (the rest: line searches, tests, starts).
    pub total_seconds: f64,
}

impl Statistics {
    /// Adds what another iteration spent.
    pub fn add(&mut self, more: &Statistics) {
        self.interior_point_steps += more.interior_point_steps;
        self.polish_steps += more.polish_steps;
        self.evaluations += more.evaluations;
        self.factorizations += more.factorizations;
        self.evaluation_seconds += more.evaluation_seconds;
        self.newton_seconds += more.newton_seconds;
        self.polish_seconds += more.polish_seconds;
        self.total_seconds += more.total_seconds;
    }
}

/// A problem in the solver's units.
pub struct Network {
    pub dim: usize,
    pub formulation: Formulation,
    /// (N, d); the fixed nodes hold their final positions.
    pub positions: Vec<f64>,
    /// The movable nodes, ascending.
    pub free: Vec<usize>,
    /// The optimised links (at least one end free) and their lengths.
    pub links: Vec<[usize; 2]>,
    pub lengths: Vec<f64>,
    /// Each node's weight, g m_i / W.
    pub load: Vec<f64>,
    /// Point loads (N, d), applied forces in units of W beside the weights; empty: none.
    pub point_loads: Vec<f64>,
    /// The physical origin in the solver's units (positions are measured from it): how far from
    /// the origin of the numbers the nodes are, for the rounding floor.
    pub origin: Vec<f64>,
    pub obstacles: ScaledObstacles,
    /// Each link's stretch per unit of tension (`L0 / EA` in the solver's units), 0 for an
    /// inextensible link; empty: every link is. An elastic link's row reads `c + s - e = 0` with its
    /// stretch `e = compliance mu` (see [`crate::ipm`]).
    pub compliance: Vec<f64>,
    /// Each node's place among the free nodes, `NOT_FREE` for a fixed node.
    pub free_index: Vec<usize>,
    /// Whether every link joins two consecutive nodes (a chain): its KKT system is then block
    /// tridiagonal over the nodes, and the driver runs the iteration with a chain's linear algebra
    /// and policy; otherwise with a net's (see [`crate::ipm::Kind`]). Set once by `new`; a test may
    /// clear it to send a chain through the net's.
    pub path: bool,
    /// What the iterations on this network spent.
    pub statistics: Statistics,
    /// The links by their later node: those of node i are `ending[ending_start[i]..ending_start[i + 1]]`.
    ending: Vec<usize>,
    ending_start: Vec<usize>,
    /// The free nodes' positions handed to a caller's node field, kept from one evaluation to the next.
    pub(crate) points: Vec<f64>,
}

/// `free_index` of a fixed node.
pub const NOT_FREE: usize = usize::MAX;

impl Network {
    /// Checks the arrays' shapes and the links (two distinct nodes, at least one free, a positive
    /// length); any graph is allowed. Errors name what is wrong.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        dim: usize,
        formulation: Formulation,
        positions: Vec<f64>,
        free: Vec<usize>,
        links: Vec<[usize; 2]>,
        lengths: Vec<f64>,
        load: Vec<f64>,
        origin: Vec<f64>,
        obstacles: ScaledObstacles,
    ) -> Result<Self, String> {
        if !(1..=3).contains(&dim) {
            return Err(format!("dimension must be 1, 2 or 3, not {dim}"));
        }
        if positions.len() % dim != 0 {
            return Err("positions must be an (N, d) array".into());
        }
        let n_nodes = positions.len() / dim;
        if load.len() != n_nodes {
            return Err(format!("load has {} entries for {n_nodes} nodes", load.len()));
        }
        if origin.len() != dim {
            return Err("origin must have d entries".into());
        }
        if lengths.len() != links.len() {
            return Err("links and lengths differ in number".into());
        }
        let mut free_index = vec![NOT_FREE; n_nodes];
        for (f, &node) in free.iter().enumerate() {
            if node >= n_nodes || (f > 0 && node <= free[f - 1]) {
                return Err("free nodes must be ascending node indices".into());
            }
            free_index[node] = f;
        }
        for (r, link) in links.iter().enumerate() {
            let [a, b] = *link;
            if a >= n_nodes || b >= n_nodes || a == b {
                return Err(format!("link {r} joins nodes {a} and {b} of {n_nodes}"));
            }
            let (fa, fb) = (free_index[a], free_index[b]);
            if fa == NOT_FREE && fb == NOT_FREE {
                return Err(format!("link {r} has no free end"));
            }
            if !(lengths[r] > 0.0 && lengths[r].is_finite()) {
                return Err(format!("link {r} has length {}", lengths[r]));
            }
        }
        if let ScaledObstacles::Quadratic(q) = &obstacles {
            let j = q.values.len();
            if q.centres.len() != j * dim || q.gradients.len() != j * dim || q.hessians.len() != j * dim * dim
            {
                return Err("quadratic obstacles' arrays do not match their number".into());
            }
        }
        let path = links.iter().all(|&[a, b]| a.abs_diff(b) == 1);
        // (a counting sort: a chain's links are in order already)
        let mut ending_start = vec![0usize; n_nodes + 1];
        for link in &links {
            ending_start[link[0].max(link[1]) + 1] += 1;
        }
        for i in 0..n_nodes {
            ending_start[i + 1] += ending_start[i];
        }
        let mut ending = vec![0usize; links.len()];
        let mut next = ending_start.clone();
        for (r, link) in links.iter().enumerate() {
            let later = link[0].max(link[1]);
            ending[next[later]] = r;
            next[later] += 1;
        }
        Ok(Network {
            statistics: Statistics::default(),
            path,
            ending,
            ending_start,
            points: Vec::new(),
            dim,
            formulation,
            positions,
            free,
            links,
            lengths,
            load,
            point_loads: Vec::new(),
            origin,
            obstacles,
            compliance: Vec::new(),
            free_index,
        })
    }

    /// The same network with elastic links: `compliance` (L,) each link's stretch per unit of
    /// tension.
    pub fn with_compliance(mut self, compliance: Vec<f64>) -> Result<Self, String> {
        if compliance.len() != self.n_links() || !compliance.iter().all(|c| *c >= 0.0 && c.is_finite()) {
            return Err("compliance needs one finite value >= 0 per link".into());
        }
        if compliance.iter().any(|c| *c > 0.0) {
            self.compliance = compliance;
        }
        Ok(self)
    }

    /// Row r's stretch per unit of its multiplier: a link's compliance, 0 for a contact row.
    #[inline]
    pub fn row_compliance(&self, r: usize) -> f64 {
        self.compliance.get(r).copied().unwrap_or(0.0)
    }

    /// The same network with point loads `loads` (N, d), applied forces in units of W.
    pub fn with_point_loads(mut self, loads: Vec<f64>) -> Result<Self, String> {
        if loads.is_empty() {
            return Ok(self);
        }
        if loads.len() != self.positions.len() {
            return Err(format!(
                "point loads have {} entries for {} coordinates",
                loads.len(),
                self.positions.len()
            ));
        }
        self.point_loads = loads;
        Ok(self)
    }

    /// The energy's gradient at `node` along axis `k`: the node's weight along the last axis, less
    /// its point load (the energy is `sum_i (W_i e_last - P_i) . p_i`).
    #[inline]
    pub fn energy_gradient(&self, node: usize, k: usize) -> f64 {
        let weight = if k + 1 == self.dim { self.load[node] } else { 0.0 };
        if self.point_loads.is_empty() {
            weight
        } else {
            weight - self.point_loads[node * self.dim + k]
        }
    }

    /// The links whose later node is `node`.
    pub fn links_ending_at(&self, node: usize) -> &[usize] {
        &self.ending[self.ending_start[node]..self.ending_start[node + 1]]
    }

    pub fn n_nodes(&self) -> usize {
        self.load.len()
    }

    pub fn n_free(&self) -> usize {
        self.free.len()
    }

    pub fn n_links(&self) -> usize {
        self.links.len()
    }

    pub fn n_obstacles(&self) -> usize {
        match &self.obstacles {
            ScaledObstacles::Quadratic(q) => q.values.len(),
            ScaledObstacles::Nodes(field) => field.count(),
            ScaledObstacles::Links(field) => field.count(),
        }
    }

    pub fn contact_links(&self) -> bool {
        matches!(self.obstacles, ScaledObstacles::Links(_))
    }

    /// Contact rows per obstacle: one per free node, or one per link.
    pub fn contact_rows(&self) -> usize {
        if self.contact_links() {
            self.n_links()
        } else {
            self.n_free()
        }
    }

    pub fn n_constraints(&self) -> usize {
        self.n_links() + self.n_obstacles() * self.contact_rows()
    }

    pub fn squared(&self) -> bool {
        self.formulation == Formulation::Squared
    }

    /// The positions with the free nodes at `z` (flat free coordinates).
    pub fn placed(&self, z: &[f64], out: &mut Vec<f64>) {
        out.clear();
        out.extend_from_slice(&self.positions);
        let d = self.dim;
        for (f, &node) in self.free.iter().enumerate() {
            out[node * d..node * d + d].copy_from_slice(&z[f * d..f * d + d]);
        }
    }

    /// The free coordinates of the stored positions.
    pub fn free_coordinates(&self) -> Vec<f64> {
        let d = self.dim;
        let mut z = Vec::with_capacity(self.n_free() * d);
        for &node in &self.free {
            z.extend_from_slice(&self.positions[node * d..node * d + d]);
        }
        z
    }
}

/// A chain in the problem's units: N nodes, N - 1 links, the supports ascending.
pub struct Chain {
    pub dim: usize,
    pub masses: Vec<f64>,
    pub lengths: Vec<f64>,
    pub gravity: f64,
    pub supports: Vec<usize>,
    /// (S, d), the supports' positions in the order of `supports`.
    pub support_positions: Vec<f64>,
    /// Each link's axial stiffness EA, infinite for an inextensible link; empty: none is elastic.
    pub stiffness: Vec<f64>,
}

impl Chain {
    pub fn n_nodes(&self) -> usize {
        self.masses.len()
    }

    pub fn structure(&self) -> Structure<'_> {
        Structure {
            dim: self.dim,
            masses: &self.masses,
            lengths: &self.lengths,
            gravity: self.gravity,
            pairs: None,
            loads: &[],
            stiffness: &self.stiffness,
        }
    }

    /// The length of chain between nodes a < b.
    pub fn length_between(&self, a: usize, b: usize) -> f64 {
        self.lengths[a..b].iter().sum()
    }

    /// Whether a link between nodes a < b is elastic: the chain between them stretches.
    pub fn elastic_between(&self, a: usize, b: usize) -> bool {
        (a..b).any(|k| self.structure().elastic(k))
    }
}

/// Obstacles in the problem's units, one at a time: phi (n) and its gradient (n, d) of obstacle j
/// at n points (n, d).
pub trait Shapes {
    fn count(&self) -> usize;
    fn evaluate(
        &mut self,
        j: usize,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
    ) -> Result<(), Interrupted>;
}

/// Quadratic obstacles evaluated here (`network::Quadratics` in the problem's units).
pub struct QuadraticShapes<'a> {
    pub dim: usize,
    pub quadratics: &'a Quadratics,
}

impl Shapes for QuadraticShapes<'_> {
    fn count(&self) -> usize {
        self.quadratics.values.len()
    }

    fn evaluate(
        &mut self,
        j: usize,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
    ) -> Result<(), Interrupted> {
        let d = self.dim;
        for (i, point) in points.chunks_exact(d).enumerate() {
            phi[i] = self
                .quadratics
                .value_and_gradient(j, d, point, &mut gradient[i * d..i * d + d]);
        }
        Ok(())
    }
}

/// A net in the problem's units. Positions are (N, d), gravity acts along the last axis.
#[derive(Clone, Debug)]
pub struct Net {
    pub dim: usize,
    pub masses: Vec<f64>,
    /// Node pairs, each with its length.
    pub links: Vec<[usize; 2]>,
    pub lengths: Vec<f64>,
    pub gravity: f64,
    /// Ascending.
    pub supports: Vec<usize>,
    /// (S, d), in the order of `supports`.
    pub support_positions: Vec<f64>,
    /// Point loads (N, d), applied forces beside the weights; empty: none.
    pub loads: Vec<f64>,
    /// Each link's axial stiffness EA, infinite for an inextensible link; empty: all are.
    pub stiffness: Vec<f64>,
}

impl Net {
    pub fn n_nodes(&self) -> usize {
        self.masses.len()
    }

    pub fn structure(&self) -> Structure<'_> {
        Structure {
            dim: self.dim,
            masses: &self.masses,
            lengths: &self.lengths,
            gravity: self.gravity,
            pairs: Some(&self.links),
            loads: &self.loads,
            stiffness: &self.stiffness,
        }
    }

    /// The nodes that are not supports, ascending.
    pub fn free(&self) -> Vec<usize> {
        let mut support = vec![false; self.n_nodes()];
        self.supports.iter().for_each(|&s| support[s] = true);
        (0..self.n_nodes()).filter(|&i| !support[i]).collect()
    }

    /// `positions` (N, d) with the supports where they are held.
    pub fn held(&self, mut positions: Vec<f64>) -> Vec<f64> {
        let d = self.dim;
        for (j, &s) in self.supports.iter().enumerate() {
            positions[s * d..s * d + d].copy_from_slice(&self.support_positions[j * d..j * d + d]);
        }
        positions
    }
}

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

/// What the iteration needs of a chain or a net besides its supports: the nodes' masses, the links
/// (node pairs: a chain's link k joins k and k + 1) with their lengths, gravity.
#[derive(Clone, Copy, Debug)]
pub struct Structure<'a> {
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

impl Structure<'_> {
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

    /// The potential energy `g m . (last coordinates) - P . p` (P the point loads), with the elastic
    /// links' strain energy `EA / (2 L0) max(d - L0, 0)^2`.
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
