//! Everything evaluated at one iterate: constraint values, their gradients, the residual of
//! stationarity, and the Newton matrix `W + J^T Sigma J` over the free coordinates.
//!
//! Link constraints (`delta = p_a - p_b`, `d = |delta|`, gradient `q` with respect to `p_a`, `-q`
//! with respect to `p_b`, Hessian `[[K, -K], [-K, K]]`):
//!
//! * norm: `c = d - l`, `q = delta / d`, `K = (I - q q^T) / d`; below `r = SMOOTH_RATIO l` the
//!   parabola with the same value and slope at `d = r`: `c = (d^2 + r^2) / (2 r) - l`,
//!   `q = delta / r`, `K = I / r`. The barrier of a norm link has its kink at `d = 0`, where a link
//!   lighter than the barrier's pull would be dragged and stall; the parabola is a weak spring
//!   there. A link shorter than `r` is slack in both forms, so the KKT points are the same.
//! * squared: `c = (d - l)(d + l)`, `q = 2 delta`, `K = 2 I`.

use std::time::Instant;

use crate::linalg::{norm, BlockTridiagonal, NewtonMatrix, SparseMatrix};
use crate::problem::{Interrupted, Network, ScaledObstacles, NOT_FREE, SMOOTH_RATIO};

/// A Newton matrix with a network's pattern: a d x d block per free node and per pair of free
/// nodes a link joins (a link-contact row couples the same two nodes).
pub trait NetworkMatrix: NewtonMatrix {
    /// The zero Newton matrix of `network` (a sparse one with its ordering and symbolic
    /// factorization).
    fn for_network(network: &Network) -> Self;
}

impl NetworkMatrix for BlockTridiagonal {
    /// Only consecutive free nodes are coupled: a chain's.
    fn for_network(network: &Network) -> Self {
        BlockTridiagonal::new(network.n_free(), network.dim)
    }
}

impl NetworkMatrix for SparseMatrix {
    fn for_network(network: &Network) -> Self {
        let mut pairs = Vec::with_capacity(network.n_links());
        for &[a, b] in &network.links {
            let (fa, fb) = (network.free_index[a], network.free_index[b]);
            if fa != NOT_FREE && fb != NOT_FREE {
                pairs.push([fa, fb]);
            }
        }
        SparseMatrix::with_pairs(network.n_free(), network.dim, pairs)
    }
}

/// An iterate and what is evaluated there.
#[derive(Clone, Debug, Default)]
pub struct Point {
    /// (N, d), the free nodes at the iterate.
    pub positions: Vec<f64>,
    /// Constraint values (links, then contacts obstacle by obstacle).
    pub c: Vec<f64>,
    /// (L, d): each link's gradient with respect to its first node.
    pub q: Vec<f64>,
    /// (J, R, d): grad phi at each contact row's point.
    pub contact_gradient: Vec<f64>,
    /// (J, L): where along each link its contact row's point is (link contact only).
    pub contact_t: Vec<f64>,
    /// Contact Hessians: (J, n, d, d) node contact evaluated by the caller, (J, L, 2d, 2d) link
    /// contact; empty for quadratics, whose Hessian is their constant one.
    pub contact_hessian: Vec<f64>,
    /// (n, d): `grad E + J^T mu` at the free nodes.
    pub dual: Vec<f64>,
}

impl Network {
    /// The contact Hessian of row r of obstacle j (d x d at a node, 2d x 2d along a link).
    pub fn contact_hessian<'a>(&'a self, point: &'a Point, j: usize, r: usize) -> &'a [f64] {
        let d = self.dim;
        match &self.obstacles {
            ScaledObstacles::Quadratic(q) => &q.hessians[j * d * d..(j + 1) * d * d],
            ScaledObstacles::Nodes(_) => {
                let at = (j * self.n_free() + r) * d * d;
                &point.contact_hessian[at..at + d * d]
            }
            ScaledObstacles::Links(_) => {
                let size = 4 * d * d;
                let at = (j * self.n_links() + r) * size;
                &point.contact_hessian[at..at + size]
            }
        }
    }

    /// Evaluates the iterate `z` (flat free coordinates) with multipliers `mu` into `point`.
    pub fn evaluate(&mut self, z: &[f64], mu: &[f64], point: &mut Point) -> Result<(), Interrupted> {
        let started = Instant::now();
        let evaluated = self.evaluate_into(z, mu, point);
        self.statistics.evaluations += 1;
        self.statistics.evaluation_seconds += started.elapsed().as_secs_f64();
        evaluated
    }

    fn evaluate_into(&mut self, z: &[f64], mu: &[f64], point: &mut Point) -> Result<(), Interrupted> {
        let d = self.dim;
        let (n, n_links, n_obstacles) = (self.n_free(), self.n_links(), self.n_obstacles());
        let rows = self.contact_rows();
        self.placed(z, &mut point.positions);
        let positions = &point.positions;
        // (every entry of c and q is written below: no zeros first, only the length)
        point.c.resize(n_links + n_obstacles * rows, 0.0);
        point.q.resize(n_links * d, 0.0);
        point.dual.clear();
        point.dual.resize(n * d, 0.0);
        let squared = self.squared();
        let mut delta = [0.0; 3];
        for (r, &[a, b]) in self.links.iter().enumerate() {
            for i in 0..d {
                delta[i] = positions[a * d + i] - positions[b * d + i];
            }
            let distance = norm(&delta[..d]);
            let length = self.lengths[r];
            let q = &mut point.q[r * d..r * d + d];
            if squared {
                for i in 0..d {
                    q[i] = 2.0 * delta[i];
                }
                point.c[r] = (distance - length) * (distance + length);
            } else {
                let radius = SMOOTH_RATIO * length;
                let reach = distance.max(radius);
                for i in 0..d {
                    q[i] = delta[i] / reach;
                }
                point.c[r] = if distance >= radius {
                    distance - length
                } else {
                    (distance * distance + radius * radius) / (2.0 * radius) - length
                };
            }
            let (fa, fb) = (self.free_index[a], self.free_index[b]);
            for i in 0..d {
                let force = mu[r] * q[i];
                if fa != NOT_FREE {
                    point.dual[fa * d + i] += force;
                }
                if fb != NOT_FREE {
                    point.dual[fb * d + i] -= force;
                }
            }
        }
        for (f, &node) in self.free.iter().enumerate() {
            for k in 0..d {
                point.dual[f * d + k] += self.energy_gradient(node, k);
            }
        }
        self.evaluate_contacts(mu, point)
    }

    /// The contact rows' values and gradients at `point.positions` (and their Hessians where the
    /// caller evaluates them), and their forces added to `point.dual`.
    fn evaluate_contacts(&mut self, mu: &[f64], point: &mut Point) -> Result<(), Interrupted> {
        let d = self.dim;
        let (n, n_links, n_obstacles) = (self.n_free(), self.n_links(), self.n_obstacles());
        let positions = &point.positions;
        let free = &self.free;
        match &mut self.obstacles {
            ScaledObstacles::Quadratic(quadratics) => {
                point.contact_gradient.resize(n_obstacles * n * d, 0.0); // (written below)
                point.contact_hessian.clear();
                for j in 0..n_obstacles {
                    for (f, &node) in free.iter().enumerate() {
                        let row = n_links + j * n + f;
                        let gradient = &mut point.contact_gradient[(j * n + f) * d..(j * n + f) * d + d];
                        point.c[row] =
                            quadratics.value_and_gradient(j, d, &positions[node * d..node * d + d], gradient);
                        for k in 0..d {
                            point.dual[f * d + k] += mu[row] * gradient[k];
                        }
                    }
                }
            }
            ScaledObstacles::Nodes(field) => {
                let points = &mut self.points;
                points.clear();
                for &node in free.iter() {
                    points.extend_from_slice(&positions[node * d..node * d + d]);
                }
                point.contact_gradient.clear();
                point.contact_gradient.resize(n_obstacles * n * d, 0.0);
                point.contact_hessian.clear();
                point.contact_hessian.resize(n_obstacles * n * d * d, 0.0);
                field.evaluate(
                    points,
                    &mut point.c[n_links..],
                    &mut point.contact_gradient,
                    &mut point.contact_hessian,
                )?;
                for j in 0..n_obstacles {
                    for f in 0..n {
                        let row = n_links + j * n + f;
                        for k in 0..d {
                            point.dual[f * d + k] += mu[row] * point.contact_gradient[(j * n + f) * d + k];
                        }
                    }
                }
            }
            ScaledObstacles::Links(field) => {
                point.contact_gradient.clear();
                point.contact_gradient.resize(n_obstacles * n_links * d, 0.0);
                point.contact_t.clear();
                point.contact_t.resize(n_obstacles * n_links, 0.0);
                point.contact_hessian.clear();
                point
                    .contact_hessian
                    .resize(n_obstacles * n_links * 4 * d * d, 0.0);
                field.evaluate(
                    positions,
                    &mut point.c[n_links..],
                    &mut point.contact_t,
                    &mut point.contact_gradient,
                    &mut point.contact_hessian,
                )?;
                let free_index = &self.free_index;
                for j in 0..n_obstacles {
                    for (r, &[a, b]) in self.links.iter().enumerate() {
                        let row = n_links + j * n_links + r;
                        let t = point.contact_t[j * n_links + r];
                        let g = &point.contact_gradient[(j * n_links + r) * d..(j * n_links + r) * d + d];
                        for (node, share) in [(a, 1.0 - t), (b, t)] {
                            let f = free_index[node];
                            if f != NOT_FREE {
                                for k in 0..d {
                                    point.dual[f * d + k] += mu[row] * share * g[k];
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// The gradient of row `row` at its nodes: up to two (free index, weight, vector) terms, the
    /// row's gradient with respect to that node being `weight * vector`.
    fn row_terms<'a>(&self, point: &'a Point, row: usize) -> [(usize, f64, &'a [f64]); 2] {
        let d = self.dim;
        let n_links = self.n_links();
        if row < n_links {
            let [a, b] = self.links[row];
            let q = &point.q[row * d..row * d + d];
            return [(self.free_index[a], 1.0, q), (self.free_index[b], -1.0, q)];
        }
        let contact = row - n_links;
        let g = &point.contact_gradient[contact * d..contact * d + d];
        if self.contact_links() {
            let [a, b] = self.links[contact % n_links];
            let t = point.contact_t[contact];
            [(self.free_index[a], 1.0 - t, g), (self.free_index[b], t, g)]
        } else {
            [(contact % self.n_free(), 1.0, g), (NOT_FREE, 0.0, g)]
        }
    }

    /// The largest |entry| of row `row` of J.
    pub fn row_largest_entry(&self, point: &Point, row: usize) -> f64 {
        let mut largest = 0.0_f64;
        for (f, weight, vector) in self.row_terms(point, row) {
            if f != NOT_FREE {
                largest = vector.iter().fold(largest, |m, v| m.max((weight * v).abs()));
            }
        }
        largest
    }

    /// `(J dz)_row`.
    pub fn row_times(&self, point: &Point, row: usize, dz: &[f64]) -> f64 {
        let d = self.dim;
        let mut total = 0.0;
        for (f, weight, vector) in self.row_terms(point, row) {
            if f != NOT_FREE {
                let mut along = 0.0;
                for k in 0..d {
                    along += vector[k] * dz[f * d + k];
                }
                total += weight * along;
            }
        }
        total
    }

    /// `out += J^T v` over the free coordinates.
    pub fn add_transpose_times(&self, point: &Point, v: &[f64], out: &mut [f64]) {
        // (`row_terms` spelled out by the kind of row, the rows in the same order: it would find
        // a contact row's node or link by a division)
        let d = self.dim;
        let (n, n_links) = (self.n_free(), self.n_links());
        let mut add = |f: usize, value: f64, weight: f64, vector: &[f64]| {
            if f != NOT_FREE {
                for k in 0..d {
                    out[f * d + k] += value * weight * vector[k];
                }
            }
        };
        for (r, (&[a, b], &value)) in self.links.iter().zip(v).enumerate() {
            if value != 0.0 {
                let q = &point.q[r * d..r * d + d];
                add(self.free_index[a], value, 1.0, q);
                add(self.free_index[b], value, -1.0, q);
            }
        }
        let rows = self.contact_rows();
        let contacts = v.get(n_links..).unwrap_or_default();
        for (j, values) in contacts.chunks(rows.max(1)).enumerate() {
            for (r, &value) in values.iter().enumerate() {
                if value == 0.0 {
                    continue;
                }
                let contact = j * rows + r;
                let g = &point.contact_gradient[contact * d..contact * d + d];
                if self.contact_links() {
                    let [a, b] = self.links[r];
                    let t = point.contact_t[contact];
                    add(self.free_index[a], value, 1.0 - t, g);
                    add(self.free_index[b], value, t, g);
                } else {
                    debug_assert!(r < n);
                    add(r, value, 1.0, g);
                }
            }
        }
    }

    /// The length of each row's gradient (links: |q|; contacts: |grad phi|).
    pub fn row_norms(&self, point: &Point) -> Vec<f64> {
        let d = self.dim;
        let n_links = self.n_links();
        let mut norms = Vec::with_capacity(point.c.len());
        for r in 0..n_links {
            norms.push(norm(&point.q[r * d..r * d + d]));
        }
        for g in point.contact_gradient.chunks_exact(d) {
            norms.push(norm(g));
        }
        norms
    }

    /// `K` of link r at `positions` (d x d, row by row): its constraint's Hessian is
    /// `[[K, -K], [-K, K]]` over its two nodes. `q`: the link's gradient there.
    #[inline]
    pub fn link_stiffness(&self, r: usize, positions: &[f64], q: &[f64]) -> [f64; 9] {
        // (the dimension a constant: the loops unroll)
        match self.dim {
            1 => self.link_stiffness_in::<1>(r, positions, q),
            2 => self.link_stiffness_in::<2>(r, positions, q),
            _ => self.link_stiffness_in::<3>(r, positions, q),
        }
    }

    /// `link_stiffness` in dimension D.
    #[inline(always)]
    fn link_stiffness_in<const D: usize>(&self, r: usize, positions: &[f64], q: &[f64]) -> [f64; 9] {
        let d = D;
        let mut stiffness = [0.0; 9];
        if self.squared() {
            for i in 0..d {
                stiffness[i * d + i] = 2.0;
            }
            return stiffness;
        }
        let [a, b] = self.links[r];
        let mut delta = [0.0; D];
        for i in 0..d {
            delta[i] = positions[a * d + i] - positions[b * d + i];
        }
        let distance = norm(&delta);
        let radius = SMOOTH_RATIO * self.lengths[r];
        for i in 0..d {
            for k in 0..d {
                let identity = if i == k { 1.0 } else { 0.0 };
                stiffness[i * d + k] = if distance >= radius {
                    (identity - q[i] * q[k]) / distance
                } else {
                    identity / radius
                };
            }
        }
        stiffness
    }

    /// `W + J^T Sigma J` over the free coordinates into `matrix` (sized and zeroed here), where W is
    /// the Hessian of the Lagrangian with multipliers `mu`. Every term is a d x d block at a free
    /// node or between the two free nodes of a link ([`NewtonMatrix`]): the matrix's structure is
    /// the network's.
    pub fn newton_matrix<M: NewtonMatrix>(&self, point: &Point, mu: &[f64], sigma: &[f64], matrix: &mut M) {
        let d = self.dim;
        let dd = d * d;
        let (n, n_links) = (self.n_free(), self.n_links());
        matrix.reset(n, d);
        let mut block = [0.0; 9];
        let mut coupling = [0.0; 9];
        for (r, &[a, b]) in self.links.iter().enumerate() {
            let q = &point.q[r * d..r * d + d];
            let stiffness = self.link_stiffness(r, &point.positions, q);
            for i in 0..d {
                for k in 0..d {
                    block[i * d + k] = mu[r] * stiffness[i * d + k] + sigma[r] * q[i] * q[k];
                    coupling[i * d + k] = -block[i * d + k];
                }
            }
            self.add_link_blocks(matrix, a, b, &block[..dd], &block[..dd], &coupling[..dd]);
        }
        let n_obstacles = self.n_obstacles();
        if n_obstacles == 0 {
            return;
        }
        if self.contact_links() {
            let size = 2 * d;
            let mut row_vector = [0.0; 6];
            let (mut first, mut second) = ([0.0; 9], [0.0; 9]);
            for j in 0..n_obstacles {
                for (r, &[a, b]) in self.links.iter().enumerate() {
                    let row = n_links + j * n_links + r;
                    let t = point.contact_t[j * n_links + r];
                    let g = &point.contact_gradient[(j * n_links + r) * d..(j * n_links + r) * d + d];
                    for i in 0..d {
                        row_vector[i] = (1.0 - t) * g[i];
                        row_vector[d + i] = t * g[i];
                    }
                    let hessian = self.contact_hessian(point, j, r);
                    let (nu, w) = (mu[row], sigma[row]);
                    let entry =
                        |i: usize, k: usize| nu * hessian[i * size + k] + w * row_vector[i] * row_vector[k];
                    for i in 0..d {
                        for k in 0..d {
                            first[i * d + k] = entry(i, k);
                            second[i * d + k] = entry(d + i, d + k);
                            coupling[i * d + k] = entry(i, d + k);
                        }
                    }
                    self.add_link_blocks(matrix, a, b, &first[..dd], &second[..dd], &coupling[..dd]);
                }
            }
            return;
        }
        for j in 0..n_obstacles {
            for f in 0..n {
                let row = n_links + j * n + f;
                let (nu, w) = (mu[row], sigma[row]);
                let g = &point.contact_gradient[(j * n + f) * d..(j * n + f) * d + d];
                let hessian = self.contact_hessian(point, j, f);
                for i in 0..d {
                    for k in 0..d {
                        block[i * d + k] = nu * hessian[i * d + k] + w * g[i] * g[k];
                    }
                }
                matrix.add_node(f, &block[..dd]);
            }
        }
    }

    /// A term over the nodes a and b: `first` at a, `second` at b, `coupling` between them (row a,
    /// column b), the fixed nodes' parts left out.
    fn add_link_blocks<M: NewtonMatrix>(
        &self,
        matrix: &mut M,
        a: usize,
        b: usize,
        first: &[f64],
        second: &[f64],
        coupling: &[f64],
    ) {
        let (fa, fb) = (self.free_index[a], self.free_index[b]);
        if fa != NOT_FREE {
            matrix.add_node(fa, first);
        }
        if fb != NOT_FREE {
            matrix.add_node(fb, second);
        }
        if fa != NOT_FREE && fb != NOT_FREE {
            matrix.add_pair(fa, fb, coupling);
        }
    }
}

/// The largest scaled KKT residuals: in units of force (stationarity, the net force left on the
/// free nodes when there is no obstacle, the sign of mu, complementarity) and of length (a link's
/// overstretch `d - l`, in either formulation); both NaN if any residual is not a number.
///
/// The net force is what the supports fail to carry: each node's residual can be below tol while
/// they share a sign. With obstacles the contact forces carry it and it is left out. It is divided
/// by `net_force_share` (see [`crate::policy::Policy::net_force_share`]): 1 for a chain, whose
/// polish reaches it; the square root of a net's free nodes.
pub fn kkt_parts(network: &Network, point: &Point, mu: &[f64], net_force_share: f64) -> (f64, f64) {
    let d = network.dim;
    let mut stationarity: f64 = 0.0;
    let mut net = [0.0; 3];
    let mut size = 0.0;
    for node in point.dual.chunks_exact(d) {
        for k in 0..d {
            stationarity = stationarity.max(node[k].abs());
            net[k] += node[k];
            size += node[k].abs();
        }
    }
    let n_links = network.n_links();
    let squared = network.squared();
    let (mut primal, mut negative, mut complementarity): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for (r, (&c, &m)) in point.c.iter().zip(mu).enumerate() {
        // (an elastic link's constraint reads c - compliance mu <= 0: its tension stretches it)
        let c = match network.row_compliance(r) {
            0.0 => c,
            compliance => c - compliance * m,
        };
        let mut value = c;
        if squared && r < n_links && value > 0.0 {
            let length = network.lengths[r];
            value /= (value + length * length).sqrt() + length; // d - l = c / (d + l)
        }
        primal = primal.max(value);
        negative = negative.max(-m);
        complementarity = complementarity.max((m * c).abs());
        size += c.abs() + m.abs();
    }
    if !size.is_finite() {
        return (f64::NAN, f64::NAN);
    }
    let mut forces = stationarity.max(negative).max(complementarity);
    if network.n_obstacles() == 0 {
        for value in &net[..d] {
            forces = forces.max(value.abs() / net_force_share);
        }
    }
    (forces, primal)
}

/// The largest scaled KKT residual, NaN if any is.
pub fn kkt_error(network: &Network, point: &Point, mu: &[f64], net_force_share: f64) -> f64 {
    let (forces, lengths) = kkt_parts(network, point, mu, net_force_share);
    if lengths.is_nan() {
        return f64::NAN;
    }
    forces.max(lengths)
}
