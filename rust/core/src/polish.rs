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
use crate::kkt::BlockKkt;
use crate::linalg::BandedLu;
use crate::network::{Network, NOT_FREE};

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
        }
    }

    /// Solves the KKT system in place: a chain's by block elimination over its nodes, falling back
    /// to the banded LU (row pivoting across the whole band) where that elimination is not to be
    /// trusted (`kkt::UPDATE_LIMIT`); another network's by the banded LU. False if singular.
    fn solve(&mut self, network: &Network, point: &Point, mu: &[f64], rhs: &mut [f64]) -> bool {
        let Layout {
            coordinate,
            row: row_of,
            block_sizes,
            ..
        } = &self.layout;
        if network.path {
            self.blocks.reset(block_sizes);
            entries(network, point, mu, coordinate, row_of, &mut |r, c, v| {
                self.blocks.add(r, c, v)
            });
            if self.blocks.factor() {
                self.blocks.solve(rhs);
                return true;
            }
        }
        let mut bandwidth = 0;
        entries(network, point, mu, coordinate, row_of, &mut |r, c, _| {
            bandwidth = bandwidth.max(r.abs_diff(c))
        });
        self.banded.reset(rhs.len(), bandwidth, bandwidth);
        entries(network, point, mu, coordinate, row_of, &mut |r, c, v| {
            self.banded.add(r, c, v)
        });
        if !self.banded.factor() {
            return false;
        }
        self.banded.solve(rhs);
        true
    }
}

/// Every entry of the KKT matrix, given to `emit(row, column, value)` (duplicates add up).
fn entries<F: FnMut(usize, usize, f64)>(
    network: &Network,
    point: &Point,
    mu: &[f64],
    coordinate: &[usize],
    row_of: &[usize],
    emit: &mut F,
) {
    let d = network.dim;
    let (n, n_links) = (network.n_free(), network.n_links());
    let n_obstacles = network.n_obstacles();
    let index = |node: usize| {
        let f = network.free_index[node];
        if f == NOT_FREE {
            NONE
        } else {
            coordinate[f]
        }
    };
    for (r, &[a, b]) in network.links.iter().enumerate() {
        let var = row_of[r];
        if var == NONE {
            continue;
        }
        let q = &point.q[r * d..r * d + d];
        let (ia, ib) = (index(a), index(b));
        if mu[r] != 0.0 {
            let stiffness = network.link_stiffness(r, &point.positions, q);
            for (x, sx) in [(ia, 1.0), (ib, -1.0)] {
                for (y, sy) in [(ia, 1.0), (ib, -1.0)] {
                    if x != NONE && y != NONE {
                        for i in 0..d {
                            for k in 0..d {
                                emit(x + i, y + k, sx * sy * mu[r] * stiffness[i * d + k]);
                            }
                        }
                    }
                }
            }
        }
        for (x, sign) in [(ia, 1.0), (ib, -1.0)] {
            if x != NONE {
                for i in 0..d {
                    emit(x + i, var, sign * q[i]);
                    emit(var, x + i, sign * q[i]);
                }
            }
        }
    }
    for f in 0..n {
        for i in 0..d {
            emit(coordinate[f] + i, coordinate[f] + i, PROXIMAL);
        }
    }
    if n_obstacles == 0 {
        return;
    }
    if network.contact_links() {
        let size = 2 * d;
        for j in 0..n_obstacles {
            for (r, &[a, b]) in network.links.iter().enumerate() {
                let row = n_links + j * n_links + r;
                let var = row_of[row];
                if var == NONE {
                    continue;
                }
                let t = point.contact_t[j * n_links + r];
                let g = &point.contact_gradient[(j * n_links + r) * d..(j * n_links + r) * d + d];
                let hessian = network.contact_hessian(point, j, r);
                let ends = [(index(a), 0, 1.0 - t), (index(b), d, t)];
                for (x, ox, share) in ends {
                    if x == NONE {
                        continue;
                    }
                    for (y, oy, _) in ends {
                        if y != NONE && mu[row] != 0.0 {
                            for i in 0..d {
                                for k in 0..d {
                                    emit(x + i, y + k, mu[row] * hessian[(ox + i) * size + oy + k]);
                                }
                            }
                        }
                    }
                    for i in 0..d {
                        emit(x + i, var, share * g[i]);
                        emit(var, x + i, share * g[i]);
                    }
                }
            }
        }
        return;
    }
    for j in 0..n_obstacles {
        for f in 0..n {
            let row = n_links + j * n + f;
            let var = row_of[row];
            if var == NONE {
                continue;
            }
            let x = coordinate[f];
            let g = &point.contact_gradient[(j * n + f) * d..(j * n + f) * d + d];
            if mu[row] != 0.0 {
                let hessian = network.contact_hessian(point, j, f);
                for i in 0..d {
                    for k in 0..d {
                        emit(x + i, x + k, mu[row] * hessian[i * d + k]);
                    }
                }
            }
            for i in 0..d {
                emit(x + i, var, g[i]);
                emit(var, x + i, g[i]);
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
    let Layout {
        coordinate,
        row: row_of,
        size,
        ..
    } = &workspace.layout;
    let size = *size;

    // The right-hand side: minus the gradient of the Lagrangian at the free nodes, minus the rows' values.
    // (not point.dual: that was evaluated with its iterate's multipliers, some of which may have
    // left the active set since)
    let mut gradient = vec![0.0; network.n_free() * d];
    for (f, &node) in network.free.iter().enumerate() {
        gradient[f * d + d - 1] = network.load[node];
    }
    network.add_transpose_times(point, mu, &mut gradient);
    let mut rhs = vec![0.0; size];
    for f in 0..network.n_free() {
        for i in 0..d {
            rhs[coordinate[f] + i] = -gradient[f * d + i];
        }
    }
    for (row, &var) in row_of.iter().enumerate() {
        if var != NONE {
            rhs[var] = -point.c[row];
        }
    }
    if !workspace.solve(network, point, mu, &mut rhs) {
        return None;
    }
    let Layout {
        coordinate,
        row: row_of,
        ..
    } = &workspace.layout;
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
