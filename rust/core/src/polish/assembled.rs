//! The polish's KKT system assembled node by node (`node_entries`, in the order of `Layout`) and
//! solved by a [`KktSolver`].

use super::{PolishSolver, NONE, PROXIMAL};
use crate::evaluate::Point;
use crate::linalg::{Assemble, KktRows, KktSolver, SparseKkt};
use crate::problem::{Network, NOT_FREE};

/// A net's polish step by the sparse L D L^T of its KKT system (where the condensed one of
/// [`super::NetPolish`] does not factor).
pub type NetKktPolish = Assembled<SparseKkt>;

/// Where the unknowns are.
#[derive(Default)]
pub(super) struct Layout {
    /// The first coordinate of every free node.
    pub(super) coordinate: Vec<usize>,
    /// Every active row's multiplier (NONE off the active set).
    pub(super) row: Vec<usize>,
    /// The unknowns of each node, in order: the active rows of the links it is the later node of
    /// (the link's own row, then its link-contact rows), its coordinates if it is free, its active
    /// contact rows (node contact).
    pub(super) block_sizes: Vec<usize>,
    pub(super) size: usize,
}

impl Layout {
    /// The node-by-node order of the unknowns of `network` with the rows `active`. A link's rows
    /// couple its two nodes' coordinates only, so for a chain the matrix is block tridiagonal over
    /// the nodes (and banded).
    pub(super) fn arrange(&mut self, network: &Network, active: &[bool]) {
        let d = network.dim;
        let (n, n_links, n_nodes) = (network.n_free(), network.n_links(), network.n_nodes());
        let n_obstacles = network.n_obstacles();
        let (coordinate, row, block_sizes) = (&mut self.coordinate, &mut self.row, &mut self.block_sizes);
        coordinate.clear();
        coordinate.resize(n, NONE);
        row.clear();
        row.resize(active.len(), NONE);
        block_sizes.clear();
        block_sizes.resize(n_nodes, 0);
        let mut size = 0;
        for node in 0..n_nodes {
            let start = size;
            for &r in network.links_ending_at(node) {
                if active[r] {
                    row[r] = size;
                    size += 1;
                }
                if network.contact_links() {
                    for j in 0..n_obstacles {
                        let contact = n_links + j * n_links + r;
                        if active[contact] {
                            row[contact] = size;
                            size += 1;
                        }
                    }
                }
            }
            let f = network.free_index[node];
            if f != NOT_FREE {
                coordinate[f] = size;
                size += d;
                if !network.contact_links() {
                    for j in 0..n_obstacles {
                        let r = n_links + j * n + f;
                        if active[r] {
                            row[r] = size;
                            size += 1;
                        }
                    }
                }
            }
            block_sizes[node] = size - start;
        }
        self.size = size;
    }
}

/// The polish step by the KKT system assembled in the order of `Layout` and solved by `K`, with its
/// storage kept from step to step.
#[derive(Default)]
pub struct Assembled<K> {
    layout: Layout,
    /// The right-hand side, then the step.
    rhs: Vec<f64>,
    /// The gradient of the Lagrangian at the free nodes.
    gradient: Vec<f64>,
    solver: K,
}

/// The KKT system of the active set at a point, node by node, as the KKT solvers read it.
pub(super) struct ActiveRows<'a> {
    pub network: &'a Network,
    pub point: &'a Point,
    pub mu: &'a [f64],
    pub layout: &'a Layout,
    /// The gradient of the Lagrangian at the free nodes.
    pub gradient: &'a [f64],
}

impl KktRows for ActiveRows<'_> {
    fn block_sizes(&self) -> &[usize] {
        &self.layout.block_sizes
    }

    #[inline(always)]
    fn add_block_row<A: Assemble>(&self, node: usize, matrix: &mut A) {
        node_entries(self.network, self.point, self.mu, self.layout, node, matrix);
    }

    /// Minus the gradient of the Lagrangian at the free nodes, minus the active rows' values.
    fn right_hand_side(&self, rhs: &mut [f64]) {
        let d = self.network.dim;
        let Layout {
            coordinate,
            row: row_of,
            ..
        } = self.layout;
        // (no zeroing: the layout places every unknown once, so every entry is written below)
        for (f, &x) in coordinate.iter().enumerate() {
            for i in 0..d {
                rhs[x + i] = -self.gradient[f * d + i];
            }
        }
        for (row, &var) in row_of.iter().enumerate() {
            if var != NONE {
                rhs[var] = match self.network.row_compliance(row) {
                    0.0 => -self.point.c[row],
                    compliance => -(self.point.c[row] - compliance * self.mu[row]),
                };
            }
        }
    }
}

/// The gradient of the Lagrangian at the free nodes into `gradient` (not `point.dual`: that was
/// evaluated with its iterate's multipliers, some of which may have left the active set since).
pub(super) fn lagrangian_gradient(network: &Network, point: &Point, mu: &[f64], gradient: &mut Vec<f64>) {
    let d = network.dim;
    fresh(gradient, network.n_free() * d);
    gradient.clear();
    gradient.resize(network.n_free() * d, 0.0);
    for (f, &node) in network.free.iter().enumerate() {
        for k in 0..d {
            gradient[f * d + k] = network.energy_gradient(node, k);
        }
    }
    network.add_transpose_times(point, mu, gradient);
}

impl<K: KktSolver> PolishSolver for Assembled<K> {
    fn step(
        &mut self,
        network: &Network,
        point: &Point,
        z: &mut [f64],
        mu: &mut [f64],
        active: &[bool],
    ) -> bool {
        let d = network.dim;
        self.layout.arrange(network, active);
        lagrangian_gradient(network, point, mu, &mut self.gradient);
        let rows = ActiveRows {
            network,
            point,
            mu,
            layout: &self.layout,
            gradient: &self.gradient,
        };
        fresh(&mut self.rhs, self.layout.size);
        self.rhs.resize(self.layout.size, 0.0);
        rows.right_hand_side(&mut self.rhs);
        if !self.solver.solve_rows(&rows, &mut self.rhs) {
            return false;
        }
        let rhs = &self.rhs;
        if !rhs.iter().all(|v| v.is_finite()) {
            return false;
        }
        let Layout {
            coordinate,
            row: row_of,
            ..
        } = &self.layout;
        for (f, &node) in network.free.iter().enumerate() {
            for i in 0..d {
                z[f * d + i] = point.positions[node * d + i] + rhs[coordinate[f] + i];
            }
        }
        for (m, &var) in mu.iter_mut().zip(row_of) {
            *m = if var == NONE { 0.0 } else { *m + rhs[var] };
        }
        true
    }
}

/// Replaces `vector` by `len` zeros if it has room for fewer: a zeroed allocation leaves its fresh
/// pages to be zeroed by the system on first touch, where growing the vector would write them twice.
fn fresh(vector: &mut Vec<f64>, len: usize) {
    if vector.capacity() < len {
        *vector = vec![0.0; len];
    }
}

/// Every entry of the KKT matrix, node by node (`node_entries`).
#[cfg(test)]
pub(super) fn entries<A: Assemble>(
    network: &Network,
    point: &Point,
    mu: &[f64],
    layout: &Layout,
    matrix: &mut A,
) {
    for node in 0..network.n_nodes() {
        node_entries(network, point, mu, layout, node, matrix);
    }
}

/// The entries of the KKT matrix that `node` brings: the proximal term and the node contact rows
/// of its coordinates if it is free, and the rows of the links ending at it (see `Layout`) with
/// their stiffness. In the layout's order they lie in the node's block and those of the links'
/// earlier ends: for a chain, the block of `node` and the one before it.
#[inline(always)]
fn node_entries<A: Assemble>(
    network: &Network,
    point: &Point,
    mu: &[f64],
    layout: &Layout,
    node: usize,
    matrix: &mut A,
) {
    // (the dimension a constant: the loops over the small blocks unroll)
    match network.dim {
        1 => node_entries_in::<A, 1>(network, point, mu, layout, node, matrix),
        2 => node_entries_in::<A, 2>(network, point, mu, layout, node, matrix),
        _ => node_entries_in::<A, 3>(network, point, mu, layout, node, matrix),
    }
}

/// `node_entries` in dimension D.
#[inline(always)]
fn node_entries_in<A: Assemble, const D: usize>(
    network: &Network,
    point: &Point,
    mu: &[f64],
    layout: &Layout,
    node: usize,
    matrix: &mut A,
) {
    let d = D;
    let (n, n_links) = (network.n_free(), network.n_links());
    let n_obstacles = network.n_obstacles();
    let Layout {
        coordinate,
        row: row_of,
        ..
    } = layout;
    let index = |node: usize| {
        let f = network.free_index[node];
        if f == NOT_FREE {
            NONE
        } else {
            coordinate[f]
        }
    };
    // a column vector g at (x, var) and its transpose at (var, x)
    let add_gradient = |matrix: &mut A, x: usize, var: usize, g: &[f64], scale: f64| {
        matrix.add_block(x, var, d, 1, |i, _| scale * g[i]);
        matrix.add_block(var, x, 1, d, |_, k| scale * g[k]);
    };
    let f = network.free_index[node];
    if f != NOT_FREE {
        let x = coordinate[f];
        matrix.add_block(x, x, d, d, |i, k| if i == k { PROXIMAL } else { 0.0 });
        if !network.contact_links() {
            for j in 0..n_obstacles {
                let row = n_links + j * n + f;
                let var = row_of[row];
                if var == NONE {
                    continue;
                }
                if mu[row] != 0.0 {
                    let hessian = network.contact_hessian(point, j, f);
                    matrix.add_block(x, x, d, d, |i, k| mu[row] * hessian[i * d + k]);
                }
                let g = &point.contact_gradient[(j * n + f) * d..(j * n + f) * d + d];
                add_gradient(matrix, x, var, g, 1.0);
            }
        }
    }
    for &r in network.links_ending_at(node) {
        let [a, b] = network.links[r];
        let ends = [(index(a), 1.0), (index(b), -1.0)];
        let var = row_of[r];
        if var != NONE {
            let compliance = network.row_compliance(r);
            if compliance > 0.0 {
                // (an elastic link's row: J dz - compliance dmu = -(c - compliance mu))
                matrix.add_block(var, var, 1, 1, |_, _| -compliance);
            }
            let q = &point.q[r * d..r * d + d];
            if mu[r] != 0.0 {
                let stiffness = network.link_stiffness(r, &point.positions, q);
                for (x, sx) in ends {
                    for (y, sy) in ends {
                        if x != NONE && y != NONE {
                            let factor = sx * sy * mu[r];
                            matrix.add_block(x, y, d, d, |i, k| factor * stiffness[i * d + k]);
                        }
                    }
                }
            }
            for (x, sign) in ends {
                if x != NONE {
                    add_gradient(matrix, x, var, q, sign);
                }
            }
        }
        if network.contact_links() {
            link_contact_entries::<A, D>(network, point, mu, row_of, r, [ends[0].0, ends[1].0], matrix);
        }
    }
}

/// Link r's contact rows in the polish matrix (`ends`: its nodes' first unknowns, NONE if fixed).
#[inline(always)]
fn link_contact_entries<A: Assemble, const D: usize>(
    network: &Network,
    point: &Point,
    mu: &[f64],
    row_of: &[usize],
    r: usize,
    ends: [usize; 2],
    matrix: &mut A,
) {
    let d = D;
    let (n_links, size) = (network.n_links(), 2 * D);
    for j in 0..network.n_obstacles() {
        let row = n_links + j * n_links + r;
        let var = row_of[row];
        if var == NONE {
            continue;
        }
        let t = point.contact_t[j * n_links + r];
        let g = &point.contact_gradient[(j * n_links + r) * d..(j * n_links + r) * d + d];
        let hessian = network.contact_hessian(point, j, r);
        let ends = [(ends[0], 0, 1.0 - t), (ends[1], d, t)];
        for (x, ox, share) in ends {
            if x == NONE {
                continue;
            }
            for (y, oy, _) in ends {
                if y != NONE && mu[row] != 0.0 {
                    matrix.add_block(x, y, d, d, |i, k| mu[row] * hessian[(ox + i) * size + oy + k]);
                }
            }
            matrix.add_block(x, var, d, 1, |i, _| share * g[i]);
            matrix.add_block(var, x, 1, d, |_, k| share * g[k]);
        }
    }
}
