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
//! node (`layout`): for a chain the matrix is block tridiagonal over the nodes, and banded. A chain
//! with node contact is assembled and solved in one pass over its nodes (`chain_step`); the other
//! networks, and the chains that pass refuses, through the assembled matrix.

use crate::evaluate::Point;
use crate::kkt::{larger, BlockKkt, Window, UPDATE_LIMIT};
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
    /// `chain_step`'s X_i and y_i.
    chain: Vec<f64>,
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
            chain: Vec::new(),
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
        fresh(gradient, network.n_free() * d);
        gradient.clear();
        gradient.resize(network.n_free() * d, 0.0);
        for (f, &node) in network.free.iter().enumerate() {
            for k in 0..d {
                gradient[f * d + k] = network.energy_gradient(node, k);
            }
        }
        network.add_transpose_times(point, mu, gradient);
        // (no zeroing: the layout places every unknown once, so every entry is written below)
        let rhs = &mut self.rhs;
        fresh(rhs, *size);
        rhs.resize(*size, 0.0);
        for (f, &x) in coordinate.iter().enumerate() {
            for i in 0..d {
                rhs[x + i] = -gradient[f * d + i];
            }
        }
        for (row, &var) in row_of.iter().enumerate() {
            if var != NONE {
                rhs[var] = match network.row_compliance(row) {
                    0.0 => -point.c[row],
                    compliance => -(point.c[row] - compliance * mu[row]),
                };
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

/// Replaces `vector` by `len` zeros if it has room for fewer: a zeroed allocation leaves its fresh
/// pages to be zeroed by the system on first touch, where growing the vector would write them twice.
fn fresh(vector: &mut Vec<f64>, len: usize) {
    if vector.capacity() < len {
        *vector = vec![0.0; len];
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
/// coordinates written to `z` and the new multipliers to `mu`, in place (fresh vectors each step
/// would cost a page fault per page). False, `z` and `mu` then unspecified, if the system is
/// singular.
///
/// A chain with node contact, no node touching more than one obstacle, is solved by `chain_step`;
/// where that refuses, and for other networks, the system is assembled by `node_entries` and solved
/// by `Workspace::solve`.
pub fn polish_step(
    network: &Network,
    point: &Point,
    z: &mut [f64],
    mu: &mut [f64],
    active: &[bool],
    workspace: &mut Workspace,
) -> bool {
    if network.path && !network.contact_links() {
        let chain = &mut workspace.chain;
        let solved = match network.dim {
            1 => chain_step::<1, 2, 3>(network, point, z, mu, active, chain),
            2 => chain_step::<2, 3, 4>(network, point, z, mu, active, chain),
            3 => chain_step::<3, 4, 5>(network, point, z, mu, active, chain),
            _ => None,
        };
        if let Some(solved) = solved {
            return solved;
        }
    }
    assembled_step(network, point, z, mu, active, workspace)
}

/// `polish_step` by the assembled KKT system.
fn assembled_step(
    network: &Network,
    point: &Point,
    z: &mut [f64],
    mu: &mut [f64],
    active: &[bool],
    workspace: &mut Workspace,
) -> bool {
    let d = network.dim;
    workspace.layout.arrange(network, active);
    workspace.right_hand_side(network, point, mu);
    if !workspace.solve(network, point, mu) {
        return false;
    }
    let Workspace { layout, rhs, .. } = &*workspace;
    let Layout {
        coordinate,
        row: row_of,
        ..
    } = layout;
    if !rhs.iter().all(|v| v.is_finite()) {
        return false;
    }
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

/// What a link brings to the blocks of its two nodes in a chain (all zero for a slack link).
#[derive(Clone, Copy)]
struct LinkTerms<const D: usize> {
    /// The link's row if it is active, else NONE.
    row: usize,
    /// Its gradient with respect to its later node (minus that with respect to the earlier one).
    later: [f64; D],
    value: f64,
    mu: f64,
    /// mu K, at either end (minus it between them); zero where mu is.
    stiffness: [[f64; D]; D],
}

impl<const D: usize> LinkTerms<D> {
    const SLACK: Self = LinkTerms {
        row: NONE,
        later: [0.0; D],
        value: 0.0,
        mu: 0.0,
        stiffness: [[0.0; D]; D],
    };

    /// The terms of the link ending at `node`; None if more than one does.
    #[inline(always)]
    fn ending_at(network: &Network, point: &Point, mu: &[f64], active: &[bool], node: usize) -> Option<Self> {
        let (r, [a, _]) = match network.links_ending_at(node) {
            [] => return Some(Self::SLACK),
            &[r] => (r, network.links[r]),
            _ => return None,
        };
        if !active[r] {
            return Some(Self::SLACK);
        }
        let q = &point.q[r * D..r * D + D];
        let sign = if a == node { 1.0 } else { -1.0 };
        let mut terms = LinkTerms {
            row: r,
            later: std::array::from_fn(|k| sign * q[k]),
            value: point.c[r],
            mu: mu[r],
            stiffness: [[0.0; D]; D],
        };
        if mu[r] != 0.0 {
            let stiffness = network.link_stiffness(r, &point.positions, q);
            terms.stiffness = std::array::from_fn(|i| std::array::from_fn(|k| mu[r] * stiffness[i * D + k]));
        }
        Some(terms)
    }
}

/// The active contact row of free node `f` (NONE if it has none); None if it has more than one.
#[inline(always)]
fn contact_of(network: &Network, active: &[bool], f: usize) -> Option<usize> {
    let (n, n_links) = (network.n_free(), network.n_links());
    let mut found = NONE;
    for j in 0..network.n_obstacles() {
        let row = n_links + j * n + f;
        if active[row] {
            if found != NONE {
                return None;
            }
            found = row;
        }
    }
    Some(found)
}

/// What block i-1 passes on to block i in `chain_step`: the rows of node i-1's coordinates in
/// X_{i-1} (D x W) and in y_{i-1}.
struct Carry<const D: usize, const W: usize> {
    x: [[f64; W]; D],
    y: [f64; D],
}

/// Node i's block row as assembled: D_i, U_i (its columns those of the next block's first W
/// unknowns), the right-hand side, and L_i (the first W rows: the link row, then the coordinates;
/// the columns those of the previous node's coordinates), with whether block i-1 is coupled
/// (L_i not zero).
struct BlockRow<const D: usize, const W: usize, const S: usize> {
    d: [[f64; S]; S],
    u: [[f64; W]; S],
    b: [f64; S],
    l: [[f64; D]; W],
    coupled: bool,
    /// No active link ends at the node; the node is fixed: rows `1 u = 0` for those unknowns.
    slack: bool,
    fixed: bool,
}

/// One polish step (see `polish_step`) for a chain with node contact in dimension D (W = D + 1,
/// X = D + 2), assembled and solved node by node in one pass: block elimination over the nodes
/// (`kkt::BlockKkt`'s, the unknowns ordered as there) with each block in registers, eliminated with
/// partial pivoting inside the block, carrying X_i = S_i^{-1} U_i over the W unknowns of the next
/// block it is coupled to; `records` keeps the X_i and y_i for the backward substitution.
///
/// The unknowns of node i's block, at these places: the multiplier of the link ending at the node
/// (0), its coordinates (1..=D), the multiplier of its contact (D + 1, if it has one). An unknown
/// that is not in the system (a slack link's multiplier, a fixed node's coordinates) gets the row
/// `1 u = 0`. Only the first W unknowns of a block are coupled to the block before.
///
/// None, with `z` and `mu` untouched, where it does not apply (a node touching two obstacles, two
/// links ending at one node) or refuses as `BlockKkt::solve` does (a zero or non-finite pivot, a
/// number not finite, a carried multiplier above `kkt::UPDATE_LIMIT` times the largest entry
/// assembled); else whether the step is finite.
fn chain_step<const D: usize, const W: usize, const X: usize>(
    network: &Network,
    point: &Point,
    z: &mut [f64],
    mu: &mut [f64],
    active: &[bool],
    records: &mut Vec<f64>,
) -> Option<bool> {
    debug_assert!(W == D + 1 && X == D + 2);
    let n_nodes = network.n_nodes();
    if records.len() < n_nodes * X * (W + 1) {
        // (a zeroed allocation: its pages are zeroed by the system on first touch, not twice)
        *records = vec![0.0; n_nodes * X * (W + 1)];
    }
    let mut carry = Carry::<D, W> {
        x: [[0.0; W]; D],
        y: [0.0; D],
    };
    let mut seen = Seen::default();
    let mut at = 0;
    let mut this = LinkTerms::<D>::ending_at(network, point, mu, active, 0)?;
    let mut previous_free = false;
    for node in 0..n_nodes {
        let next = if node + 1 < n_nodes {
            LinkTerms::<D>::ending_at(network, point, mu, active, node + 1)?
        } else {
            LinkTerms::SLACK
        };
        let f = network.free_index[node];
        let contact = if f == NOT_FREE {
            NONE
        } else {
            contact_of(network, active, f)?
        };
        let record = &mut records[at..];
        let size = if contact == NONE {
            let row = block_row::<D, W, W>(network, point, mu, node, contact, &this, &next, previous_free);
            eliminate_block(row, &mut carry, record, &mut seen)
        } else {
            let row = block_row::<D, W, X>(network, point, mu, node, contact, &this, &next, previous_free);
            eliminate_block(row, &mut carry, record, &mut seen)
        };
        at += size?;
        this = next;
        previous_free = f != NOT_FREE;
    }
    if seen.probe != 0.0 || seen.carried > UPDATE_LIMIT * seen.assembled {
        return None;
    }
    // backward: u_i = y_i - X_i u_{i+1} (the first W unknowns of u_{i+1}), written out as it goes
    let mut after = [0.0; W];
    // (a lane for each place in the block: no chain of dependent sums from node to node)
    let mut finite = [0.0; X];
    for node in (0..n_nodes).rev() {
        let f = network.free_index[node];
        // (as found on the way forward)
        let contact = if f == NOT_FREE {
            NONE
        } else {
            contact_of(network, active, f).unwrap_or(NONE)
        };
        // (the block's size a constant: `u` stays in registers)
        let mut u = [0.0; X];
        if contact == NONE {
            at -= W * (W + 1);
            u[..W].copy_from_slice(&substitute::<W, W>(&records[at..], &after));
        } else {
            at -= X * (W + 1);
            u = substitute::<W, X>(&records[at..], &after);
        }
        for r in 0..X {
            finite[r] += u[r] * 0.0;
        }
        after = std::array::from_fn(|c| u[c]);
        for &r in network.links_ending_at(node) {
            mu[r] = if active[r] { mu[r] + u[0] } else { 0.0 };
        }
        if f != NOT_FREE {
            for k in 0..D {
                z[f * D + k] = point.positions[node * D + k] + u[1 + k];
            }
            let (n, n_links) = (network.n_free(), network.n_links());
            for j in 0..network.n_obstacles() {
                let row = n_links + j * n + f;
                mu[row] = if row == contact { mu[row] + u[W] } else { 0.0 };
            }
        }
    }
    Some(finite.iter().all(|&value| value == 0.0))
}

/// `y_i - X_i after` for the record of a block of size S (X_i, S x W row-major, then y_i).
#[inline(always)]
fn substitute<const W: usize, const S: usize>(record: &[f64], after: &[f64; W]) -> [f64; S] {
    let (x, y) = record[..S * (W + 1)].split_at(S * W);
    std::array::from_fn(|r| {
        let mut value = y[r];
        for c in 0..W {
            value -= x[r * W + c] * after[c];
        }
        value
    })
}

/// Node `node`'s block row (see `BlockRow`), its contact row `contact` (NONE if none, S = W; else
/// S = W + 1): the link ending at it (`this`), its coordinates with the proximal term, its contact,
/// the stiffness and the pull of both its links, and the coupling through the link ending at the
/// next node (`next`). Sums in the order of `node_entries` and `Network::add_transpose_times`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn block_row<const D: usize, const W: usize, const S: usize>(
    network: &Network,
    point: &Point,
    mu: &[f64],
    node: usize,
    contact: usize,
    this: &LinkTerms<D>,
    next: &LinkTerms<D>,
    previous_free: bool,
) -> BlockRow<D, W, S> {
    let f = network.free_index[node];
    let mut row = BlockRow {
        d: [[0.0; S]; S],
        u: [[0.0; W]; S],
        b: [0.0; S],
        l: [[0.0; D]; W],
        coupled: this.row != NONE && previous_free,
        slack: this.row == NONE,
        fixed: f == NOT_FREE,
    };
    if this.row != NONE {
        row.b[0] = -this.value;
        if previous_free {
            for k in 0..D {
                row.l[0][k] = -this.later[k];
            }
        }
    }
    if f == NOT_FREE {
        return row;
    }
    for i in 0..D {
        row.d[1 + i][1 + i] = PROXIMAL;
    }
    // the pull of the links in the order of their rows, then the contact's
    let mut gradient = [0.0; D];
    for (k, value) in gradient.iter_mut().enumerate() {
        *value = network.energy_gradient(node, k);
    }
    let pulls = [(this, 1.0), (next, -1.0)];
    let order = if this.row <= next.row { [0, 1] } else { [1, 0] };
    for which in order {
        let (link, sign) = pulls[which];
        if link.mu != 0.0 {
            for k in 0..D {
                gradient[k] += link.mu * sign * link.later[k];
            }
        }
    }
    if contact != NONE {
        let (n, n_links) = (network.n_free(), network.n_links());
        let j = (contact - n_links) / n;
        let g = &point.contact_gradient[(j * n + f) * D..(j * n + f) * D + D];
        let nu = mu[contact];
        if nu != 0.0 {
            let hessian = network.contact_hessian(point, j, f);
            for i in 0..D {
                for k in 0..D {
                    row.d[1 + i][1 + k] += nu * hessian[i * D + k];
                }
            }
            for k in 0..D {
                gradient[k] += nu * g[k];
            }
        }
        for k in 0..D {
            row.d[1 + k][S - 1] = g[k];
            row.d[S - 1][1 + k] = g[k];
        }
        row.b[S - 1] = -point.c[contact];
    }
    for i in 0..D {
        row.b[1 + i] = -gradient[i];
        row.d[0][1 + i] = this.later[i];
        row.d[1 + i][0] = this.later[i];
        row.u[1 + i][0] = -next.later[i];
    }
    for i in 0..D {
        for k in 0..D {
            row.d[1 + i][1 + k] += this.stiffness[i][k];
        }
    }
    let next_free = node + 1 < network.n_nodes() && network.free_index[node + 1] != NOT_FREE;
    for i in 0..D {
        for k in 0..D {
            row.d[1 + i][1 + k] += next.stiffness[i][k];
            if next_free {
                row.u[1 + i][1 + k] = -next.stiffness[i][k];
            }
            if previous_free {
                row.l[1 + i][k] = -this.stiffness[i][k];
            }
        }
    }
    row
}

/// What the elimination of some blocks saw: the largest magnitudes assembled and carried (in the
/// X_i), and the sum of the numbers computed times zero (NaN once one is not finite).
#[derive(Default)]
struct Seen {
    assembled: f64,
    carried: f64,
    probe: f64,
}

/// Eliminates a block row: `S_i = D_i - L_i X_{i-1}` (and the same on the right-hand side), then
/// Gaussian elimination with partial pivoting on `[S_i | U_i | b_i]` and back substitution, to
/// `[I | X_i | y_i]`. Writes X_i (S x W, row-major) and y_i to `record`, passes their coordinate
/// rows on in `carry`, and returns the length written; None if a pivot is zero or not finite.
#[inline(always)]
fn eliminate_block<const D: usize, const W: usize, const S: usize>(
    row: BlockRow<D, W, S>,
    carry: &mut Carry<D, W>,
    record: &mut [f64],
    seen: &mut Seen,
) -> Option<usize> {
    let BlockRow {
        mut d,
        mut u,
        mut b,
        l,
        coupled,
        slack,
        fixed,
    } = row;
    let largest = larger(larger(scan(&d).0, scan(&u).0), scan(&l).0);
    seen.assembled = larger(seen.assembled, largest);
    if slack {
        d[0][0] = 1.0;
    }
    if fixed {
        for k in 0..D {
            d[1 + k][1 + k] = 1.0;
        }
    }
    if coupled {
        for k in 0..D {
            for r in 0..W {
                let factor = l[r][k];
                for c in 0..W {
                    d[r][c] -= factor * carry.x[k][c];
                }
                b[r] -= factor * carry.y[k];
            }
        }
    }
    // the steps one by one, k a constant in each (a loop over k would not unroll, and the block
    // would not stay in registers)
    macro_rules! steps {
        ($($k:literal)*) => {
            $(
                if $k < S && !elimination_step(&mut d, &mut u, &mut b, $k) {
                    return None;
                }
            )*
        };
    }
    steps!(0 1 2 3 4);
    // back substitution: the unit upper triangle of the steps
    for k in (1..S).rev() {
        for r in 0..k {
            let factor = d[r][k];
            for c in 0..W {
                u[r][c] -= factor * u[k][c];
            }
            b[r] -= factor * b[k];
        }
    }
    for r in 0..S {
        record[r * W..(r + 1) * W].copy_from_slice(&u[r]);
        record[S * W + r] = b[r];
    }
    carry.x.copy_from_slice(&u[1..W]);
    carry.y.copy_from_slice(&b[1..W]);
    let (largest, probe) = scan(&u);
    seen.carried = larger(seen.carried, largest);
    seen.probe += probe + scan(&[b]).1;
    Some(S * (W + 1))
}

/// The largest magnitude in `block` (NaNs aside), and the sum of its entries times zero (zero while
/// all are finite, NaN once one is not): a column a lane, off one long chain of dependent steps.
#[inline(always)]
fn scan<const R: usize, const C: usize>(block: &[[f64; C]; R]) -> (f64, f64) {
    let mut largest = [0.0; C];
    let mut probe = [0.0; C];
    for row in block {
        for c in 0..C {
            largest[c] = larger(largest[c], row[c].abs());
            probe[c] += row[c] * 0.0;
        }
    }
    (largest.into_iter().fold(0.0, larger), probe.into_iter().sum())
}

/// Step k of Gaussian elimination with partial pivoting on `[d | u | b]`: the pivot (the first of
/// the largest magnitudes in column k from row k down), the row swap, the pivot row divided by the
/// pivot, column k cleared below it (columns of `d` up to k are not read again). False if the
/// pivot is zero or not finite.
#[inline(always)]
fn elimination_step<const S: usize, const W: usize>(
    d: &mut [[f64; S]; S],
    u: &mut [[f64; W]; S],
    b: &mut [f64; S],
    k: usize,
) -> bool {
    let mut best = k;
    let mut largest = d[k][k].abs();
    for r in k + 1..S {
        if d[r][k].abs() > largest {
            largest = d[r][k].abs();
            best = r;
        }
    }
    // (zero, infinite or NaN, in one test)
    if !(largest > 0.0 && largest <= f64::MAX) {
        return false;
    }
    for r in k + 1..S {
        if r == best {
            d.swap(k, r);
            u.swap(k, r);
            b.swap(k, r);
        }
    }
    let reciprocal = 1.0 / d[k][k];
    for c in k + 1..S {
        d[k][c] *= reciprocal;
    }
    for c in 0..W {
        u[k][c] *= reciprocal;
    }
    b[k] *= reciprocal;
    for r in k + 1..S {
        let factor = d[r][k];
        for c in k + 1..S {
            d[r][c] -= factor * d[k][c];
        }
        for c in 0..W {
            u[r][c] -= factor * u[k][c];
        }
        b[r] -= factor * b[k];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::network::{Formulation, Obstacles, Quadratics};
    use crate::test_support::Rng;

    /// A chain of `nodes` nodes in dimension `d` along the first axis (links in either orientation,
    /// some shorter than their length), both ends and sometimes a node between fixed, two
    /// quadratic obstacles (a sphere and a general one), evaluated at random multipliers on a
    /// random active set: links taut with probability `taut`, a free node touching one obstacle
    /// with probability 0.4 (both with probability `both`).
    fn case(d: usize, formulation: Formulation, nodes: usize, taut: f64, both: f64, seed: u64) -> Case {
        let mut rng = Rng::new(seed);
        let mut positions = Vec::new();
        for i in 0..nodes {
            positions.push(0.5 * i as f64 + rng.between(-0.1, 0.1));
            positions.extend((1..d).map(|_| rng.between(-0.3, 0.3)));
        }
        // (a fixed node between two free ones)
        let mut free: Vec<usize> = (1..nodes - 1).collect();
        if rng.chance(0.5) {
            free.remove(1 + rng.below(nodes - 5));
        }
        let links: Vec<[usize; 2]> = (0..nodes - 1)
            .map(|k| if rng.chance(0.5) { [k, k + 1] } else { [k + 1, k] })
            .collect();
        let lengths = (0..nodes - 1).map(|_| rng.between(0.4, 1.4)).collect();
        let load = (0..nodes).map(|_| rng.between(0.02, 0.2)).collect();
        let mut quadratics = Quadratics::default();
        for _ in 0..2 {
            quadratics.centres.extend((0..d).map(|_| rng.between(-1.0, 1.0)));
            quadratics.values.push(rng.between(-0.5, 0.5));
            quadratics.gradients.extend((0..d).map(|_| rng.uniform()));
            let mut h = vec![0.0; d * d];
            for i in 0..d {
                for k in i..d {
                    h[i * d + k] = rng.uniform();
                    h[k * d + i] = h[i * d + k];
                }
            }
            quadratics.hessians.extend(h);
        }
        let mut network = Network::new(
            d,
            formulation,
            positions,
            free,
            links,
            lengths,
            load,
            vec![0.0; d],
            Obstacles::Quadratic(quadratics),
        )
        .expect("a valid chain");
        let (n, n_links) = (network.n_free(), network.n_links());
        let mut active = vec![false; network.n_constraints()];
        for r in 0..n_links {
            active[r] = rng.chance(taut);
        }
        for f in 0..n {
            if rng.chance(0.4) {
                active[n_links + rng.below(2) * n + f] = true;
            } else if rng.chance(both) {
                active[n_links + f] = true;
                active[n_links + n + f] = true;
            }
        }
        let mu: Vec<f64> = active
            .iter()
            .map(|&a| if a { rng.between(0.2, 1.5) } else { 0.0 })
            .collect();
        let z = network.free_coordinates();
        let mut point = Point::default();
        network.evaluate(&z, &mu, &mut point).expect("evaluated");
        Case {
            network,
            point,
            z,
            mu,
            active,
        }
    }

    struct Case {
        network: Network,
        point: Point,
        z: Vec<f64>,
        mu: Vec<f64>,
        active: Vec<bool>,
    }

    impl Case {
        /// `chain_step`'s new coordinates and multipliers, None if it declines.
        fn chain(&self) -> Option<(Vec<f64>, Vec<f64>)> {
            let Case {
                network,
                point,
                z,
                mu,
                active,
            } = self;
            let (mut z, mut mu) = (z.clone(), mu.clone());
            let mut records = Vec::new();
            let finite = match network.dim {
                1 => chain_step::<1, 2, 3>(network, point, &mut z, &mut mu, active, &mut records),
                2 => chain_step::<2, 3, 4>(network, point, &mut z, &mut mu, active, &mut records),
                _ => chain_step::<3, 4, 5>(network, point, &mut z, &mut mu, active, &mut records),
            }?;
            assert!(finite);
            Some((z, mu))
        }

        /// The same by the assembled system (which must solve it).
        fn assembled(&self) -> (Vec<f64>, Vec<f64>) {
            let (mut z, mut mu) = (self.z.clone(), self.mu.clone());
            let mut workspace = Workspace::new();
            assert!(assembled_step(
                &self.network,
                &self.point,
                &mut z,
                &mut mu,
                &self.active,
                &mut workspace
            ));
            (z, mu)
        }
    }

    struct Dense(usize, Vec<f64>);

    impl Assemble for Dense {
        fn add(&mut self, row: usize, col: usize, value: f64) {
            self.1[row * self.0 + col] += value;
        }
    }

    impl Case {
        /// The same by dense elimination with partial pivoting.
        fn dense(&self) -> (Vec<f64>, Vec<f64>) {
            let mut workspace = Workspace::new();
            workspace.layout.arrange(&self.network, &self.active);
            workspace.right_hand_side(&self.network, &self.point, &self.mu);
            let n = workspace.layout.size;
            let mut dense = Dense(n, vec![0.0; n * n]);
            entries(
                &self.network,
                &self.point,
                &self.mu,
                &workspace.layout,
                &mut dense,
            );
            let step = crate::test_support::dense_solve(n, &dense.1, &workspace.rhs).expect("solved");
            let d = self.network.dim;
            let mut z = self.z.clone();
            for (f, &node) in self.network.free.iter().enumerate() {
                for i in 0..d {
                    z[f * d + i] =
                        self.point.positions[node * d + i] + step[workspace.layout.coordinate[f] + i];
                }
            }
            let mu = workspace
                .layout
                .row
                .iter()
                .zip(&self.mu)
                .map(|(&var, m)| if var == NONE { 0.0 } else { m + step[var] })
                .collect();
            (z, mu)
        }
    }

    /// max |a - b| / max |b|.
    fn relative_difference(a: &[f64], b: &[f64]) -> f64 {
        let largest = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / largest
    }

    #[test]
    fn chain_step_agrees_with_the_assembled_system() {
        let mut compared = 0;
        for d in 1..=3 {
            for formulation in [Formulation::Norm, Formulation::Squared] {
                for seed in 0..40 {
                    let case = case(d, formulation, 8 + seed as usize % 30, 0.9, 0.0, seed);
                    // (a slack link before a taut one can trip the guard, as in `BlockKkt`)
                    let Some((z_chain, mu_chain)) = case.chain() else {
                        continue;
                    };
                    // against dense elimination with partial pivoting over the whole matrix, as
                    // close as the assembled system's solution (some random systems are poorly
                    // conditioned)
                    let (z, mu) = case.dense();
                    let (z_assembled, mu_assembled) = case.assembled();
                    for (chain, assembled, reference) in
                        [(&z_chain, &z_assembled, &z), (&mu_chain, &mu_assembled, &mu)]
                    {
                        let (error, assembled_error) = (
                            relative_difference(chain, reference),
                            relative_difference(assembled, reference),
                        );
                        assert!(
                            error < (10.0 * assembled_error).max(1e-14),
                            "d {d}, seed {seed}: {error:e} (assembled: {assembled_error:e})"
                        );
                    }
                    // zero off the active set
                    assert!(mu_chain.iter().zip(&case.active).all(|(m, a)| *a || *m == 0.0));
                    compared += 1;
                }
            }
        }
        assert!(compared > 100, "only {compared} compared");
    }

    #[test]
    fn chain_step_declines_a_node_on_two_obstacles() {
        for seed in 0..10 {
            let case = case(2, Formulation::Norm, 20, 1.0, 1.0, seed);
            let (n, n_links) = (case.network.n_free(), case.network.n_links());
            assert!((0..n).any(|f| case.active[n_links + f] && case.active[n_links + n + f]));
            assert!(case.chain().is_none());
        }
    }

    #[test]
    fn chain_step_refuses_numbers_not_finite() {
        let healthy = case(2, Formulation::Norm, 12, 1.0, 0.0, 5);
        assert!(healthy.chain().is_some());
        let (n, n_links) = (healthy.network.n_free(), healthy.network.n_links());
        let f = (0..n).find(|&f| healthy.active[n_links + f] || healthy.active[n_links + n + f]);
        let contact = f
            .map(|f| if healthy.active[n_links + f] { f } else { n + f })
            .expect("a contact");
        for bad in [f64::NAN, f64::INFINITY] {
            for place in 0..4 {
                let mut broken = case(2, Formulation::Norm, 12, 1.0, 0.0, 5);
                match place {
                    0 => broken.point.q[2 * 3 + 1] = bad,
                    1 => broken.point.c[4] = bad,
                    2 => broken.point.contact_gradient[2 * contact] = bad,
                    _ => broken.mu[n_links + contact] = bad,
                }
                assert!(broken.chain().is_none(), "{bad} at {place} accepted");
            }
        }
    }

    #[test]
    fn chain_step_refuses_a_proximal_block() {
        // a free node after a slack link and before a taut one, without contact: along the taut
        // link only the proximal term holds it in its own block (see `kkt`)
        let mut case = case(2, Formulation::Norm, 12, 1.0, 0.0, 3);
        let n_links = case.network.n_links();
        case.active[n_links..].fill(false);
        case.mu[n_links..].fill(0.0);
        case.active[4] = false;
        case.mu[4] = 0.0;
        let mut point = Point::default();
        case.network
            .evaluate(&case.z, &case.mu, &mut point)
            .expect("evaluated");
        case.point = point;
        assert!(case.chain().is_none());
        let (z, mu) = case.assembled();
        assert!(z.iter().chain(&mu).all(|v| v.is_finite()));
        // and `polish_step` takes the assembled system's answer
        let (mut z_step, mut mu_step) = (case.z.clone(), case.mu.clone());
        let mut workspace = Workspace::new();
        assert!(polish_step(
            &case.network,
            &case.point,
            &mut z_step,
            &mut mu_step,
            &case.active,
            &mut workspace
        ));
        assert!(z_step == z && mu_step == mu);
    }
}
