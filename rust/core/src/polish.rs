//! One Newton step on the active-set KKT system.
//!
//! With the active set A fixed (taut links and touching contacts), the KKT conditions are a square
//! system without any `1 / s`:
//!
//! ```text
//! [ W_A + eps I   J_A^T ] [dz  ]     [ grad E + J_A^T mu_A ]
//! [ J_A            0    ] [dmu ] = - [ c_A                 ]
//! ```
//!
//! `eps` (PROXIMAL) gives directions the active rows leave free (a node lying on the ground between
//! slack links may slide) a zero step instead of a singular matrix. The unknowns are ordered node by
//! node (`layout`): for a chain the matrix is block tridiagonal over the nodes, and banded.

use crate::evaluate::Point;
use crate::kkt::{BlockKkt, Window};
use crate::linalg::{Assemble, BandedLu, Bandwidth};
use crate::network::{Network, NOT_FREE};
use crate::sparse::SparseKkt;

pub const PROXIMAL: f64 = 1e-10;
const NONE: usize = usize::MAX;

/// Where the unknowns are.
#[derive(Default)]
struct Layout {
    /// The first coordinate of every free node.
    coordinate: Vec<usize>,
    /// Every active row's multiplier (NONE off the active set).
    row: Vec<usize>,
    /// The unknowns of each node, in order: the active rows of the links it is the later node of
    /// (the link's own row, then its link-contact rows), its coordinates if it is free, its active
    /// contact rows (node contact).
    block_sizes: Vec<usize>,
    size: usize,
}

impl Layout {
    /// The node-by-node order of the unknowns of `network` with the rows `active`. A link's rows
    /// couple its two nodes' coordinates only, so for a chain the matrix is block tridiagonal over
    /// the nodes (and banded).
    fn arrange(&mut self, network: &Network, active: &[bool]) {
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

/// The KKT systems' storage, kept from step to step (fresh pages cost a page fault each: at 10^6
/// nodes as much as a factorization).
pub struct Workspace {
    layout: Layout,
    blocks: BlockKkt,
    banded: BandedLu,
    sparse: SparseKkt,
    rhs: Vec<f64>,
    gradient: Vec<f64>,
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    pub fn new() -> Self {
        Workspace {
            layout: Layout::default(),
            blocks: BlockKkt::new(),
            banded: BandedLu::new(0, 0, 0),
            sparse: SparseKkt::new(),
            rhs: Vec::new(),
            gradient: Vec::new(),
        }
    }

    /// The right-hand side in `self.rhs`: minus the gradient of the Lagrangian at the free nodes,
    /// minus the active rows' values. (Not `point.dual`: that was evaluated with its iterate's
    /// multipliers, some of which may have left the active set since.)
    fn right_hand_side(&mut self, network: &Network, point: &Point, mu: &[f64]) {
        let d = network.dim;
        let Layout {
            coordinate,
            row: row_of,
            size,
            ..
        } = &self.layout;
        let gradient = &mut self.gradient;
        gradient.clear();
        gradient.resize(network.n_free() * d, 0.0);
        for (f, &node) in network.free.iter().enumerate() {
            gradient[f * d + d - 1] = network.load[node];
        }
        network.add_transpose_times(point, mu, gradient);
        // (no zeroing: the layout places every unknown once, so every entry is written below)
        let rhs = &mut self.rhs;
        rhs.resize(*size, 0.0);
        for (f, &x) in coordinate.iter().enumerate() {
            for i in 0..d {
                rhs[x + i] = -gradient[f * d + i];
            }
        }
        for (row, &var) in row_of.iter().enumerate() {
            if var != NONE {
                rhs[var] = -point.c[row];
            }
        }
    }

    /// Solves the KKT system for `self.rhs` in place: a chain's by block elimination over its
    /// nodes, falling back to the banded LU (row pivoting across the whole band) where that
    /// elimination is not to be trusted (`kkt::UPDATE_LIMIT`); another network's (a net's band
    /// is wide) by the sparse L D L^T. False if singular.
    fn solve(&mut self, network: &Network, point: &Point, mu: &[f64]) -> bool {
        let layout = &self.layout;
        if !network.path {
            self.sparse.reset(self.rhs.len());
            entries(network, point, mu, layout, &mut self.sparse);
            if !self.sparse.factor() {
                return false;
            }
            self.sparse.solve(&mut self.rhs);
            return true;
        }
        if network.path {
            let assemble =
                |node: usize, window: &mut Window| node_entries(network, point, mu, layout, node, window);
            if self.blocks.solve(&layout.block_sizes, &mut self.rhs, assemble) {
                return true;
            }
            self.right_hand_side(network, point, mu); // (the elimination overwrote it)
        }
        let layout = &self.layout;
        let mut bandwidth = Bandwidth::default();
        entries(network, point, mu, layout, &mut bandwidth);
        self.banded.reset(self.rhs.len(), bandwidth.0, bandwidth.0);
        entries(network, point, mu, layout, &mut self.banded);
        if !self.banded.factor() {
            return false;
        }
        self.banded.solve(&mut self.rhs);
        true
    }
}

/// Every entry of the KKT matrix, node by node (`node_entries`).
fn entries<A: Assemble>(network: &Network, point: &Point, mu: &[f64], layout: &Layout, matrix: &mut A) {
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
        if !network.contact_links() {
            continue;
        }
        let size = 2 * d;
        for j in 0..n_obstacles {
            let row = n_links + j * n_links + r;
            let var = row_of[row];
            if var == NONE {
                continue;
            }
            let t = point.contact_t[j * n_links + r];
            let g = &point.contact_gradient[(j * n_links + r) * d..(j * n_links + r) * d + d];
            let hessian = network.contact_hessian(point, j, r);
            let ends = [(ends[0].0, 0, 1.0 - t), (ends[1].0, d, t)];
            for (x, ox, share) in ends {
                if x == NONE {
                    continue;
                }
                for (y, oy, _) in ends {
                    if y != NONE && mu[row] != 0.0 {
                        matrix.add_block(x, y, d, d, |i, k| mu[row] * hessian[(ox + i) * size + oy + k]);
                    }
                }
                add_gradient(matrix, x, var, g, share);
            }
        }
    }
}

/// One Newton step on the active-set KKT system from `point` (its constraint values and
/// derivatives are used as they are) with multipliers `mu` (zero off the active set): the new free
/// coordinates and multipliers, or `None` if the system is singular.
pub fn polish_step(
    network: &Network,
    point: &Point,
    mu: &[f64],
    active: &[bool],
    workspace: &mut Workspace,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let d = network.dim;
    workspace.layout.arrange(network, active);
    workspace.right_hand_side(network, point, mu);
    if !workspace.solve(network, point, mu) {
        return None;
    }
    let Workspace { layout, rhs, .. } = &*workspace;
    let Layout {
        coordinate,
        row: row_of,
        ..
    } = layout;
    if !rhs.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut z = Vec::with_capacity(network.n_free() * d);
    for (f, &node) in network.free.iter().enumerate() {
        for i in 0..d {
            z.push(point.positions[node * d + i] + rhs[coordinate[f] + i]);
        }
    }
    let new_mu = row_of
        .iter()
        .enumerate()
        .map(|(row, &var)| if var == NONE { 0.0 } else { mu[row] + rhs[var] })
        .collect();
    Some((z, new_mu))
}
