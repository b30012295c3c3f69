//! A chain's polish step with node contact, assembled and solved in one pass over its nodes
//! (`chain_step`), and the chain's [`PolishSolver`] that falls back on the assembled system.

use std::cell::Cell;

use super::{Assembled, PolishSolver, NONE, PROXIMAL};
use crate::evaluate::Point;
use crate::linalg::kkt::{larger, UPDATE_LIMIT};
use crate::linalg::{BandedLu, BlockKkt, Fallback};
use crate::problem::{Network, NOT_FREE};

/// A chain's polish step: the one pass over the nodes with node contact (`chain_step`), else (link
/// contact, or where that pass refuses) the assembled system by block elimination over the nodes,
/// with the banded LU (row pivoting across the whole band) behind it where that elimination is not
/// to be trusted (`kkt::UPDATE_LIMIT`).
pub struct ChainPolish {
    /// `chain_step`'s X_i and y_i.
    records: Vec<f64>,
    assembled: Assembled<Fallback<BlockKkt, BandedLu>>,
}

thread_local! {
    /// The last chain polish's records, for the next: at 10^6 nodes they are the largest array of a
    /// solve (128 MB in the plane), and faulted in afresh they would cost a sweep's every solve a
    /// tenth of its time. Every entry is written before it is read.
    static SPARE_RECORDS: Cell<Vec<f64>> = const { Cell::new(Vec::new()) };
}

impl Default for ChainPolish {
    fn default() -> Self {
        ChainPolish {
            records: SPARE_RECORDS.take(),
            assembled: Assembled::default(),
        }
    }
}

impl Drop for ChainPolish {
    fn drop(&mut self) {
        SPARE_RECORDS.set(std::mem::take(&mut self.records));
    }
}

impl PolishSolver for ChainPolish {
    fn step(
        &mut self,
        network: &Network,
        point: &Point,
        z: &mut [f64],
        mu: &mut [f64],
        active: &[bool],
    ) -> bool {
        if !network.contact_links() {
            let records = &mut self.records;
            let solved = match network.dim {
                1 => chain_step::<1, 2, 3>(network, point, z, mu, active, records),
                2 => chain_step::<2, 3, 4>(network, point, z, mu, active, records),
                3 => chain_step::<3, 4, 5>(network, point, z, mu, active, records),
                _ => None,
            };
            if let Some(solved) = solved {
                return solved;
            }
        }
        self.assembled.step(network, point, z, mu, active)
    }
}

/// What a link brings to the blocks of its two nodes in a chain (all zero for a slack link).
#[derive(Clone, Copy)]
struct LinkTerms<const D: usize> {
    /// The link's row if it is active, else NONE.
    row: usize,
    /// Its gradient with respect to its later node (minus that with respect to the earlier one).
    later: [f64; D],
    /// The row's value: c, or an elastic link's `c - compliance mu` (its row in the step reads
    /// `J dz - compliance dmu = -(c - compliance mu)`).
    value: f64,
    mu: f64,
    /// Its stretch per unit of tension (0: inextensible).
    compliance: f64,
    /// mu K, at either end (minus it between them); zero where mu is.
    stiffness: [[f64; D]; D],
}

impl<const D: usize> LinkTerms<D> {
    const SLACK: Self = LinkTerms {
        row: NONE,
        later: [0.0; D],
        value: 0.0,
        mu: 0.0,
        compliance: 0.0,
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
        let compliance = network.row_compliance(r);
        let mut terms = LinkTerms {
            row: r,
            later: std::array::from_fn(|k| sign * q[k]),
            value: if compliance > 0.0 {
                point.c[r] - compliance * mu[r]
            } else {
                point.c[r]
            },
            mu: mu[r],
            compliance,
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

/// One polish step (see [`PolishSolver::step`]) for a chain with node contact in dimension D (W = D + 1,
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
pub(super) fn chain_step<const D: usize, const W: usize, const X: usize>(
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
        if this.compliance > 0.0 {
            row.d[0][0] = -this.compliance;
        }
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
