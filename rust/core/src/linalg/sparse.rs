//! Sparse linear algebra for networks that are not chains (cable nets): the Newton matrix
//! `W + J^T Sigma J` with its Cholesky factors (or L D L^T factors, for the polish's condensed
//! system, which may be indefinite), and the polish's KKT system with its regularized L D L^T
//! factors and iterative refinement (where the condensed system fails).
//!
//! The Newton matrix is factored in a fill-reducing order of the network's nodes: approximate
//! minimum degree (faer's), or for a large net nested dissection ([`super::order`]) where the
//! factor it gives takes clearly fewer multiply-adds (counted from both symbolic factorizations:
//! on grids of 10^4 nodes and more, a fifth to a half fewer). The KKT system is factored in a
//! minimum-degree order. The Newton matrix's Cholesky factorization (and the polish's L D L^T in
//! its pattern) is faer's simplicial or supernodal one, as faer's estimate of the work per entry
//! of the factor decides; the KKT system's L D L^T likewise. Small nets (every built-in
//! scenario) take the simplicial factorizations: plain scalar loops that round the same on every
//! x86-64 machine. Large nets' Newton matrices take the supernodal one, whose dense kernels pick
//! their vector instructions (AVX2, AVX-512) by the CPU they run on: several times faster on a net
//! of 10^4 nodes, but their last bits, and so an iteration count now and then, may differ from one
//! CPU to another (the answers agree to the tolerance).
//!
//! The Newton matrix's sparsity pattern is the network's (a d x d block per free node and per pair
//! of free nodes a link joins), so its ordering and symbolic factorization are computed once, when
//! the matrix is made ([`SparseMatrix::with_pairs`]); each step only writes values. The KKT system's
//! pattern follows the active set: its ordering is recomputed when the pattern changes.

use std::cell::RefCell;
use std::sync::{Arc, OnceLock};

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{self, simplicial};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par};

use super::order::{dissect, minimum_degree, Graph, Part};
use super::split::{threads, SplitFactors, SplitPattern};
use super::{Assemble, Factorization, KktRows, KktSolver, NewtonMatrix};

const NONE: usize = usize::MAX;

/// Nets of fewer free nodes keep the minimum-degree order: their factorizations take a few
/// milliseconds at most, and on grids below about 5,000 nodes the two orders' work is within 15%
/// of each other. (Every built-in scenario is far smaller, so its answers do not depend on this.)
pub const DISSECTION_NODES: usize = 5000;

/// Nested dissection replaces minimum degree where its factor takes at most this share of the
/// multiply-adds: the count is only a proxy for the time (the supernodal kernels' speed depends
/// on the supernodes' shapes), so a near tie keeps minimum degree.
pub const DISSECTION_SHARE: f64 = 0.9;

/// The size of the Cholesky factor L of a matrix with d x d blocks on a network's node pairs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FactorWork {
    /// Entries of L, with its diagonal.
    pub entries: u64,
    /// Multiply-adds of the factorization: a column of L with c entries (with its diagonal) costs
    /// c (c - 1) / 2 in the update of the columns after it.
    pub multiply_adds: u64,
}

/// The column counts of the node pattern's Cholesky factor (with the diagonal) for the node pairs
/// `pairs` (f <= g, each node's own pair included), its nodes in the order `place` (old to new),
/// by node place.
fn node_column_counts(n: usize, pairs: &[[usize; 2]], place: &[usize]) -> Vec<usize> {
    let mut col_ptr = vec![0usize; n + 1];
    for &[f, g] in pairs {
        col_ptr[place[f].max(place[g]) + 1] += 1;
    }
    for c in 0..n {
        col_ptr[c + 1] += col_ptr[c];
    }
    let mut rows = vec![0usize; pairs.len()];
    let mut next = col_ptr.clone();
    for &[f, g] in pairs {
        let column = place[f].max(place[g]);
        rows[next[column]] = place[f].min(place[g]);
        next[column] += 1;
    }
    for c in 0..n {
        rows[col_ptr[c]..col_ptr[c + 1]].sort_unstable();
    }
    let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &rows);
    let mut memory = MemBuffer::new(simplicial::prefactorize_symbolic_cholesky_scratch::<usize>(
        n,
        rows.len(),
    ));
    let mut etree = vec![0isize; n];
    let mut counts = vec![0usize; n];
    simplicial::prefactorize_symbolic_cholesky(&mut etree, &mut counts, pattern, MemStack::new(&mut memory));
    counts
}

/// The work of a node's d columns of the scalar factor, dense below its diagonal block, from the
/// node factor's column count (the scalar factor's pattern is the node factor's, blown up).
fn node_work(d: usize, count: usize) -> FactorWork {
    let mut work = FactorWork {
        entries: 0,
        multiply_adds: 0,
    };
    for k in 0..d {
        let c = (d * count - k) as u64;
        work.entries += c;
        work.multiply_adds += c * (c - 1) / 2;
    }
    work
}

/// The work of the Cholesky factorization of a matrix with d x d blocks on the node pairs `pairs`
/// (f <= g, each node's own pair included), its nodes in the order `place` (old to new).
pub fn factor_work(n: usize, d: usize, pairs: &[[usize; 2]], place: &[usize]) -> FactorWork {
    node_column_counts(n, pairs, place)
        .into_iter()
        .map(|count| node_work(d, count))
        .fold(
            FactorWork {
                entries: 0,
                multiply_adds: 0,
            },
            |total, work| FactorWork {
                entries: total.entries + work.entries,
                multiply_adds: total.multiply_adds + work.multiply_adds,
            },
        )
}

/// The nodes' fill-reducing order (old to new) for a matrix with d x d blocks on the node pairs
/// `pairs` (f <= g, sorted, each node's own pair included), and the separator tree where the
/// order is nested dissection: minimum degree, unless the net has [`DISSECTION_NODES`] free nodes
/// or more and nested dissection's factor takes at most [`DISSECTION_SHARE`] of its multiply-adds
/// (then with the multiply-adds of each node place's columns).
#[allow(clippy::type_complexity)]
fn node_order(n: usize, d: usize, pairs: &[[usize; 2]]) -> (Vec<usize>, Option<(Vec<Part>, Vec<u64>)>) {
    // the node graph's upper triangle by columns (pairs sorted by f: each column's rows ascend)
    let mut node_ptr = vec![0usize; n + 1];
    for &[_, g] in pairs {
        node_ptr[g + 1] += 1;
    }
    for g in 0..n {
        node_ptr[g + 1] += node_ptr[g];
    }
    let mut node_rows = vec![0usize; pairs.len()];
    let mut next = node_ptr.clone();
    for &[f, g] in pairs {
        node_rows[next[g]] = f;
        next[g] += 1;
    }
    let (_, minimum) = minimum_degree(n, &node_ptr, &node_rows);
    if n < DISSECTION_NODES {
        return (minimum, None);
    }
    let mut first = vec![0usize; n + 1];
    for &[f, g] in pairs.iter().filter(|[f, g]| f != g) {
        first[f + 1] += 1;
        first[g + 1] += 1;
    }
    for f in 0..n {
        first[f + 1] += first[f];
    }
    let mut adjacent = vec![0usize; first[n]];
    let mut next = first.clone();
    for &[f, g] in pairs.iter().filter(|[f, g]| f != g) {
        adjacent[next[f]] = g;
        next[f] += 1;
        adjacent[next[g]] = f;
        next[g] += 1;
    }
    let dissection = dissect(Graph {
        first: &first,
        adjacent: &adjacent,
    });
    let by_degree = factor_work(n, d, pairs, &minimum).multiply_adds as f64;
    let node_work: Vec<u64> = node_column_counts(n, pairs, &dissection.place)
        .into_iter()
        .map(|count| node_work(d, count).multiply_adds)
        .collect();
    let by_dissection = node_work.iter().sum::<u64>() as f64;
    if by_dissection <= DISSECTION_SHARE * by_degree {
        (dissection.place, Some((dissection.parts, node_work)))
    } else {
        (minimum, None)
    }
}

/// The symbolic Cholesky factorization (elimination tree, the factor's pattern) of an upper
/// triangle by columns.
fn symbolic_cholesky(
    n: usize,
    col_ptr: &[usize],
    row_idx: &[usize],
) -> simplicial::SymbolicSimplicialCholesky<usize> {
    let pattern = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
    let mut memory = MemBuffer::new(StackReq::any_of(&[
        simplicial::prefactorize_symbolic_cholesky_scratch::<usize>(n, row_idx.len()),
        simplicial::factorize_simplicial_symbolic_cholesky_scratch::<usize>(n),
    ]));
    let stack = MemStack::new(&mut memory);
    let mut etree = vec![0isize; n];
    let mut col_counts = vec![0usize; n];
    simplicial::prefactorize_symbolic_cholesky(&mut etree, &mut col_counts, pattern, stack);
    // SAFETY: `etree` was filled by `prefactorize_symbolic_cholesky` for this pattern.
    let etree = unsafe { simplicial::EliminationTreeRef::from_inner(&etree) };
    simplicial::factorize_simplicial_symbolic_cholesky(pattern, etree, &col_counts, stack)
        .expect("a symbolic factorization that fits in memory")
}

/// The symbolic factorization (faer's, of either kind) of an upper triangle by columns already in
/// its fill-reducing order: supernodal where faer's estimate of the flops per entry of L says the
/// dense kernels pay (large nets), simplicial otherwise.
fn symbolic_factorization(
    n: usize,
    col_ptr: &[usize],
    row_idx: &[usize],
) -> cholesky::SymbolicCholesky<usize> {
    cholesky::factorize_symbolic_cholesky(
        SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx),
        faer::Side::Upper,
        cholesky::SymmetricOrdering::Identity,
        cholesky::CholeskySymbolicParams::default(),
    )
    .expect("a symbolic factorization that fits in memory")
}

/// The largest number of entries in a row or column of the factor L (with its diagonal).
fn longest_line(symbolic: &simplicial::SymbolicSimplicialCholesky<usize>) -> usize {
    let factor = symbolic.factor();
    let size = factor.ncols();
    let mut row_counts = vec![0usize; size];
    for &row in factor.row_idx() {
        row_counts[row] += 1;
    }
    let longest_column = (0..size)
        .map(|c| factor.col_ptr()[c + 1] - factor.col_ptr()[c])
        .max()
        .unwrap_or(0);
    longest_column.max(row_counts.into_iter().max().unwrap_or(0))
}

fn is_supernodal(symbolic: &cholesky::SymbolicCholesky<usize>) -> bool {
    matches!(symbolic.raw(), cholesky::SymbolicCholeskyRaw::Supernodal(_))
}

/// What the Cholesky factorization of a [`SparseMatrix`] shares with the matrix: the scalar
/// ordering and the symbolic factorization of the permuted pattern.
#[derive(Debug)]
struct Analysis {
    /// Each unknown's place in the factorization's order (old to new).
    place: Vec<usize>,
    /// The symbolic factorization of the whole matrix, made on first use: a matrix split in two
    /// halves ([`SplitPattern`]) needs it only where its L D L^T is factored whole.
    symbolic: OnceLock<cholesky::SymbolicCholesky<usize>>,
    /// The largest number of entries in a row or column of the factor L (with its diagonal): how
    /// many rounded products an entry of L L^T sums at most; made on first use.
    longest: OnceLock<usize>,
    /// Where the nodes are in nested-dissection order, its tree of separators (in node places:
    /// node place p holds the columns p d..(p + 1) d).
    separators: Option<Vec<Part>>,
    /// Where the order is nested dissection, the matrix split at its top separator, whose
    /// Cholesky factorization then takes two cores ([`SplitFactors`]).
    split: Option<SplitPattern>,
}

/// Whether the symmetric matrix with d x d blocks `node_blocks[f]` (n of them, row by row) on the
/// diagonal and `pair_blocks[p]` at `pairs[p]` = (f, g) (and its transpose at (g, f)), plus
/// `shift` I, is positive definite: its sparse Cholesky factorization completes (a NaN fails)
/// with the diagonal lowered by the factorization's rounding too ([`SparseMatrix::rounding_bound`]),
/// so that a completed factorization proves it. Repeated pairs add up.
pub fn blocks_positive_definite(
    d: usize,
    node_blocks: &[f64],
    pairs: &[[usize; 2]],
    pair_blocks: &[f64],
    shift: f64,
) -> bool {
    let n = node_blocks.len() / (d * d);
    let mut matrix = SparseMatrix::with_pairs(n, d, pairs.to_vec());
    for (f, block) in node_blocks.chunks_exact(d * d).enumerate() {
        matrix.add_node(f, block);
    }
    for (&[f, g], block) in pairs.iter().zip(pair_blocks.chunks_exact(d * d)) {
        matrix.add_pair(f, g, block);
    }
    let mut factors = matrix.new_factors();
    factors.factor_shifted(&matrix, shift - matrix.rounding_bound())
}

/// A symmetric matrix over the free coordinates of a network, with the network's sparsity: a
/// d x d block per free node and one per pair of free nodes joined by a link. Stored as the upper
/// triangle, by columns, of the matrix in a fill-reducing order of the nodes (each node's d
/// unknowns kept together), which its Cholesky factorization ([`SparseCholesky`]) reads directly.
///
/// As for [`super::BlockTridiagonal`], the diagonal blocks must be symmetric: only their
/// lower triangles are read.
#[derive(Clone, Debug)]
pub struct SparseMatrix {
    d: usize,
    n: usize,
    /// The free nodes each node is coupled with, itself first, then the others above it,
    /// ascending: those of node f are `neighbours[first[f]..first[f + 1]]`.
    first: Vec<usize>,
    neighbours: Vec<usize>,
    /// For the pair at `neighbours[p]` (nodes f <= g) and 0 <= i, k < d: where entry
    /// (f d + i, g d + k) is stored in `values` (NONE above the diagonal of a node's own block).
    slot: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<f64>,
    /// Where each column's diagonal entry is in `values`.
    diagonal: Vec<usize>,
    analysis: Arc<Analysis>,
}

impl SparseMatrix {
    /// The zero matrix over `n` nodes of dimension `d` with blocks at the node pairs `pairs`
    /// (any order, repeats allowed) and on the diagonal.
    pub fn with_pairs(n: usize, d: usize, mut pairs: Vec<[usize; 2]>) -> Self {
        assert!((1..=3).contains(&d), "block size {d} is not 1, 2 or 3");
        pairs.extend((0..n).map(|f| [f, f]));
        for pair in &mut pairs {
            assert!(pair[0] < n && pair[1] < n, "pair {pair:?} outside {n} nodes");
            *pair = [pair[0].min(pair[1]), pair[0].max(pair[1])];
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut first = vec![0usize; n + 1];
        for &[f, _] in &pairs {
            first[f + 1] += 1;
        }
        for f in 0..n {
            first[f + 1] += first[f];
        }
        let neighbours: Vec<usize> = pairs.iter().map(|&[_, g]| g).collect();

        // The nodes' order, each node's d unknowns kept together.
        let (node_place, separators) = node_order(n, d, &pairs);
        let place: Vec<usize> = (0..n * d).map(|s| node_place[s / d] * d + s % d).collect();

        // The permuted upper triangle: entry (r, c) of the original matrix lands at
        // (min, max) of (place[r], place[c]); count, then fill, the columns.
        let size = n * d;
        let upper = |r: usize, c: usize| {
            let (pr, pc) = (place[r], place[c]);
            (pr.min(pc), pr.max(pc))
        };
        let mut entries: Vec<(usize, usize, usize)> = Vec::new(); // (column, row, slot index)
        let mut slot = vec![NONE; pairs.len() * d * d];
        for (p, &[f, g]) in pairs.iter().enumerate() {
            for i in 0..d {
                for k in 0..d {
                    if f == g && k > i {
                        continue; // a node's own block: its lower triangle only
                    }
                    let (row, column) = upper(f * d + i, g * d + k);
                    entries.push((column, row, p * d * d + i * d + k));
                }
            }
        }
        entries.sort_unstable();
        let mut col_ptr = vec![0usize; size + 1];
        let mut row_idx = Vec::with_capacity(entries.len());
        let mut diagonal = vec![NONE; size];
        for (position, &(column, row, s)) in entries.iter().enumerate() {
            col_ptr[column + 1] += 1;
            row_idx.push(row);
            slot[s] = position;
            if row == column {
                diagonal[column] = position;
            }
        }
        for c in 0..size {
            col_ptr[c + 1] += col_ptr[c];
        }
        let split = separators
            .as_ref()
            .and_then(|(parts, work)| SplitPattern::new(&col_ptr, &row_idx, parts, work, d));
        let separators = separators.map(|(parts, _)| parts);
        SparseMatrix {
            d,
            n,
            first,
            neighbours,
            slot,
            values: vec![0.0; row_idx.len()],
            col_ptr,
            row_idx,
            diagonal,
            analysis: Arc::new(Analysis {
                place,
                symbolic: OnceLock::new(),
                longest: OnceLock::new(),
                separators,
                split,
            }),
        }
    }

    /// The matrix's order, n d.
    pub fn size(&self) -> usize {
        self.n * self.d
    }

    /// The symbolic factorization of the whole matrix (made on its first use).
    fn symbolic(&self) -> &cholesky::SymbolicCholesky<usize> {
        (self.analysis.symbolic)
            .get_or_init(|| symbolic_factorization(self.size(), &self.col_ptr, &self.row_idx))
    }

    /// The entries stored (the permuted upper triangle) and the factor's (L with its diagonal).
    pub fn stored_entries(&self) -> (usize, usize) {
        (self.values.len(), self.symbolic().len_val())
    }

    /// The largest number of entries in a row or column of the Cholesky factor L.
    pub fn longest_factor_line(&self) -> usize {
        *self.analysis.longest.get_or_init(|| match self.symbolic().raw() {
            cholesky::SymbolicCholeskyRaw::Simplicial(simplicial) => longest_line(simplicial),
            // (a supernodal factor's pattern is by supernodes: its lines come from the simplicial one)
            cholesky::SymbolicCholeskyRaw::Supernodal(_) => {
                longest_line(&symbolic_cholesky(self.size(), &self.col_ptr, &self.row_idx))
            }
        })
    }

    /// A bound on the 2-norm of the backward error of its Cholesky factorization, `(k + 1) k eps`
    /// times the largest diagonal entry, k the longest line of the factor: the entries of |L| |L^T|
    /// are at most that diagonal entry, and each is a sum of at most k rounded products. A
    /// factorization of `A - b I` that completes proves A positive definite.
    pub fn rounding_bound(&self) -> f64 {
        let k = self.longest_factor_line() as f64;
        (k + 1.0) * k * f64::EPSILON * self.max_abs_diagonal()
    }

    /// The tree of separators of its nodes' order where that is nested dissection (None where it is
    /// minimum degree), in node places: the columns of node place p are p d..(p + 1) d.
    pub fn separator_tree(&self) -> Option<&[Part]> {
        self.analysis.separators.as_deref()
    }

    /// Each node's place in the factorization's order.
    pub fn node_places(&self) -> Vec<usize> {
        (0..self.n)
            .map(|f| self.analysis.place[f * self.d] / self.d)
            .collect()
    }

    /// Whether its Cholesky factorization is split in two halves at the top separator of a
    /// nested-dissection order ([`SplitPattern`]).
    pub fn split_in_two(&self) -> bool {
        self.analysis.split.is_some()
    }

    /// Whether its Cholesky factorization is the supernodal one (else the simplicial one).
    pub fn supernodal(&self) -> bool {
        is_supernodal(self.symbolic())
    }

    /// The largest |entry|.
    pub fn largest_entry(&self) -> f64 {
        self.values.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
    }

    /// `y += A x`, in the original order (`work`: scratch, resized to 2 n d).
    pub fn multiply_add(&self, x: &[f64], y: &mut [f64], work: &mut Vec<f64>) {
        let place = &self.analysis.place;
        let size = place.len();
        work.clear();
        work.resize(2 * size, 0.0);
        let (permuted, product) = work.split_at_mut(size);
        for (value, &p) in x.iter().zip(place) {
            permuted[p] = *value;
        }
        for c in 0..size {
            for position in self.col_ptr[c]..self.col_ptr[c + 1] {
                let (r, value) = (self.row_idx[position], self.values[position]);
                product[r] += value * permuted[c];
                if r != c {
                    product[c] += value * permuted[r];
                }
            }
        }
        for (value, &p) in y.iter_mut().zip(place) {
            *value += product[p];
        }
    }

    /// Where the block of nodes f <= g starts in `slot`.
    fn pair(&self, f: usize, g: usize) -> usize {
        let list = &self.neighbours[self.first[f]..self.first[f + 1]];
        let at = list
            .binary_search(&g)
            .unwrap_or_else(|_| panic!("free nodes {f} and {g} are not coupled in this matrix"));
        (self.first[f] + at) * self.d * self.d
    }
}

impl NewtonMatrix for SparseMatrix {
    type Factors = SparseCholesky;

    /// The pattern is the network's: only the values are cleared.
    fn reset(&mut self, n: usize, d: usize) {
        assert!(
            n == self.n && d == self.d,
            "a sparse matrix keeps its network's pattern"
        );
        self.values.fill(0.0);
    }

    fn add_node(&mut self, f: usize, block: &[f64]) {
        let d = self.d;
        let base = self.pair(f, f);
        for i in 0..d {
            for k in 0..=i {
                self.values[self.slot[base + i * d + k]] += block[i * d + k];
            }
        }
    }

    fn add_pair(&mut self, fa: usize, fb: usize, block: &[f64]) {
        let d = self.d;
        let base = self.pair(fa.min(fb), fa.max(fb));
        for i in 0..d {
            for k in 0..d {
                // the block itself at (fa, fb), its transpose at (fb, fa)
                let value = if fa < fb {
                    block[i * d + k]
                } else {
                    block[k * d + i]
                };
                self.values[self.slot[base + i * d + k]] += value;
            }
        }
    }

    fn largest_node_entry(&self) -> f64 {
        let dd = self.d * self.d;
        let mut largest = 0.0_f64;
        for f in 0..self.n {
            let base = self.first[f] * dd; // (a node's own block comes first)
            for &s in &self.slot[base..base + dd] {
                if s != NONE {
                    largest = largest.max(self.values[s].abs());
                }
            }
        }
        largest
    }

    fn max_abs_diagonal(&self) -> f64 {
        let mut largest = 0.0_f64;
        for &s in &self.diagonal {
            let value = self.values[s];
            if value.is_nan() {
                return f64::NAN;
            }
            largest = largest.max(value.abs());
        }
        largest
    }

    fn is_finite(&self) -> bool {
        self.values.iter().all(|v| v.is_finite())
    }

    fn to_dense(&self) -> Vec<f64> {
        let size = self.size();
        let mut original = vec![0usize; size];
        for (s, &p) in self.analysis.place.iter().enumerate() {
            original[p] = s;
        }
        let mut dense = vec![0.0; size * size];
        for c in 0..size {
            for position in self.col_ptr[c]..self.col_ptr[c + 1] {
                let (i, k) = (original[self.row_idx[position]], original[c]);
                dense[i * size + k] = self.values[position];
                dense[k * size + i] = self.values[position];
            }
        }
        dense
    }

    fn size(&self) -> usize {
        SparseMatrix::size(self)
    }

    fn factor_lines(&self) -> Option<usize> {
        Some(self.longest_factor_line())
    }

    fn new_factors(&self) -> SparseCholesky {
        SparseCholesky {
            analysis: self.analysis.clone(),
            shifted: Vec::new(),
            lower: Vec::new(),
            factored: None,
            factor_scratch: Scratch::default(),
            solve_scratch: RefCell::default(),
            split: self
                .analysis
                .split
                .as_ref()
                .map(|_| RefCell::new(SplitFactors::new(threads()))),
        }
    }
}

/// Scratch memory for faer's kernels, kept from one call to the next: a buffer made anew for every
/// factorization of a large net is paged in anew every time.
#[derive(Default)]
pub(super) struct Scratch(Option<MemBuffer>);

impl Scratch {
    pub(super) fn stack(&mut self, size: impl FnOnce() -> StackReq) -> &mut MemStack {
        MemStack::new(self.0.get_or_insert_with(|| MemBuffer::new(size())))
    }
}

impl std::fmt::Debug for Scratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Scratch")
    }
}

/// The Cholesky factors L L^T of a [`SparseMatrix`] plus a shift of its diagonal, or its L D L^T
/// factors where it may be indefinite, in the matrix's fill-reducing order (faer's simplicial or
/// supernodal factorizations, as the matrix's analysis chose).
#[derive(Debug)]
pub struct SparseCholesky {
    analysis: Arc<Analysis>,
    /// The matrix's values with the shift on the diagonal.
    shifted: Vec<f64>,
    /// L's values, in the symbolic factorization's pattern (with D's on its diagonal for L D L^T).
    lower: Vec<f64>,
    factored: Option<Factored>,
    factor_scratch: Scratch,
    /// The solves' scratch and right-hand side in the factorization's order.
    solve_scratch: RefCell<(Scratch, Vec<f64>)>,
    /// The Cholesky factors in two halves, where the matrix is split ([`SplitPattern`]).
    split: Option<RefCell<SplitFactors>>,
}

/// `matrix`'s values with `shift` added to its diagonal, into `out`, for factors made with its
/// `analysis`.
fn shifted_values(analysis: &Arc<Analysis>, matrix: &SparseMatrix, shift: f64, out: &mut Vec<f64>) {
    assert!(
        Arc::ptr_eq(analysis, &matrix.analysis),
        "factors made for another matrix"
    );
    out.clear();
    out.extend_from_slice(&matrix.values);
    for &s in &matrix.diagonal {
        out[s] += shift;
    }
}

/// The scratch of either factorization.
pub(super) fn factor_scratch(symbolic: &cholesky::SymbolicCholesky<usize>) -> StackReq {
    StackReq::any_of(&[
        symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
        symbolic.factorize_numeric_ldlt_scratch::<f64>(Par::Seq, Default::default()),
    ])
}

/// Which factors: L L^T of a positive definite matrix, or L D L^T (L with a unit diagonal) of a
/// matrix that may be indefinite, without pivoting, a pivot of size at most `epsilon` replaced by
/// `delta` of its sign (faer's dynamic regularization).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FactorKind {
    Cholesky,
    Ldlt { delta: f64, epsilon: f64 },
}

impl FactorKind {
    pub(super) fn ldlt_regularization(self) -> LdltRegularization<'static, f64> {
        let FactorKind::Ldlt { delta, epsilon } = self else {
            unreachable!("only L D L^T is regularized")
        };
        LdltRegularization {
            dynamic_regularization_signs: None,
            dynamic_regularization_delta: delta,
            dynamic_regularization_epsilon: epsilon,
        }
    }
}

/// The numeric factorization of `a` (its upper triangle) into `lower` as `kind` says, with its
/// `symbolic` factorization; whether it succeeded (L L^T: positive definite; L D L^T: every
/// factor finite).
pub(super) fn factor_numeric(
    symbolic: &cholesky::SymbolicCholesky<usize>,
    lower: &mut [f64],
    a: SparseColMatRef<'_, usize, f64>,
    kind: FactorKind,
    stack: &mut MemStack,
) -> bool {
    match kind {
        FactorKind::Cholesky => symbolic
            .factorize_numeric_llt(
                lower,
                a,
                faer::Side::Upper,
                LltRegularization::default(),
                Par::Seq,
                stack,
                Default::default(),
            )
            .is_ok(),
        FactorKind::Ldlt { .. } => {
            symbolic
                .factorize_numeric_ldlt(
                    lower,
                    a,
                    faer::Side::Upper,
                    kind.ldlt_regularization(),
                    Par::Seq,
                    stack,
                    Default::default(),
                )
                .is_ok()
                && lower.iter().all(|v| v.is_finite())
        }
    }
}

/// Which factors a [`SparseCholesky`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Factored {
    /// L L^T of the whole matrix.
    Cholesky,
    /// L D L^T of the whole matrix.
    Ldlt,
    /// The split factors ([`SplitFactors`], which know their kind).
    Halves,
}

impl SparseCholesky {
    /// The threads a split factorization ([`SplitFactors`]) uses, 1 or 2 (the same bits either
    /// way); by default `FUNICULAR_THREADS` or the cores available.
    pub fn set_threads(&mut self, threads: usize) {
        if let Some(split) = &mut self.split {
            split.get_mut().set_threads(threads);
        }
    }

    /// `matrix + shift I` with the shift on the diagonal, as faer reads it.
    fn shifted<'a>(&'a mut self, matrix: &'a SparseMatrix, shift: f64) -> SparseColMatRef<'a, usize, f64> {
        shifted_values(&self.analysis, matrix, shift, &mut self.shifted);
        let size = matrix.size();
        let pattern =
            SymbolicSparseColMatRef::new_checked(size, size, &matrix.col_ptr, None, &matrix.row_idx);
        SparseColMatRef::new(pattern, &self.shifted)
    }

    /// Factors `matrix + shift I` as L D L^T without pivoting, whatever its inertia: a pivot of
    /// size at most `epsilon` is replaced by `delta` of its sign. False if a pivot is still zero
    /// or a factor not finite.
    pub fn factor_indefinite(&mut self, matrix: &SparseMatrix, shift: f64, delta: f64, epsilon: f64) -> bool {
        let kind = FactorKind::Ldlt { delta, epsilon };
        self.factor_split(matrix, shift, kind)
            .unwrap_or_else(|| self.factor(matrix, shift, kind))
    }

    /// `matrix + shift I` factored in two halves as `kind` says, where the matrix is split
    /// ([`SplitPattern`]); None where it is not, or where its L D L^T is to be factored whole.
    fn factor_split(&mut self, matrix: &SparseMatrix, shift: f64, kind: FactorKind) -> Option<bool> {
        let (Some(pattern), Some(split)) = (&self.analysis.split, &mut self.split) else {
            return None;
        };
        self.factored = None;
        shifted_values(&self.analysis, matrix, shift, &mut self.shifted);
        let factored = split.get_mut().factor(pattern, &self.shifted, kind)?;
        if factored {
            self.factored = Some(Factored::Halves);
        }
        Some(factored)
    }

    /// The whole `matrix + shift I` factored as `kind` says; whether that succeeded.
    fn factor(&mut self, matrix: &SparseMatrix, shift: f64, kind: FactorKind) -> bool {
        self.factored = None;
        let symbolic = matrix.symbolic();
        let mut scratch = std::mem::take(&mut self.factor_scratch);
        let mut lower = std::mem::take(&mut self.lower);
        lower.resize(symbolic.len_val(), 0.0);
        let a = self.shifted(matrix, shift);
        let factored = factor_numeric(
            symbolic,
            &mut lower,
            a,
            kind,
            scratch.stack(|| factor_scratch(symbolic)),
        );
        (self.lower, self.factor_scratch) = (lower, scratch);
        if factored {
            self.factored = Some(match kind {
                FactorKind::Cholesky => Factored::Cholesky,
                FactorKind::Ldlt { .. } => Factored::Ldlt,
            });
        }
        factored
    }
}

impl Factorization<SparseMatrix> for SparseCholesky {
    /// Fails (false) at the first pivot that is not positive, a NaN included.
    fn factor_shifted(&mut self, matrix: &SparseMatrix, shift: f64) -> bool {
        self.factor_split(matrix, shift, FactorKind::Cholesky)
            .unwrap_or_else(|| self.factor(matrix, shift, FactorKind::Cholesky))
    }

    fn solve_in_place(&self, rhs: &mut [f64]) {
        let factored = self.factored.expect("solve needs a successful factor first");
        let place = &self.analysis.place;
        assert_eq!(rhs.len(), place.len(), "rhs has the wrong length");
        let (scratch, permuted) = &mut *self.solve_scratch.borrow_mut();
        permuted.resize(rhs.len(), 0.0);
        for (value, &p) in rhs.iter().zip(place) {
            permuted[p] = *value;
        }
        if let (Factored::Halves, Some(pattern), Some(split)) = (factored, &self.analysis.split, &self.split)
        {
            split.borrow_mut().solve_in_place(pattern, permuted);
            for (value, &p) in rhs.iter_mut().zip(place) {
                *value = permuted[p];
            }
            return;
        }
        let symbolic = (self.analysis.symbolic.get()).expect("the whole matrix was factored");
        let size = permuted.len();
        let x = MatMut::from_column_major_slice_mut(permuted, size, 1);
        let stack = scratch.stack(|| symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        match factored {
            Factored::Cholesky => cholesky::LltRef::new(symbolic, &self.lower).solve_in_place_with_conj(
                Conj::No,
                x,
                Par::Seq,
                stack,
            ),
            Factored::Ldlt => cholesky::LdltRef::new(symbolic, &self.lower).solve_in_place_with_conj(
                Conj::No,
                x,
                Par::Seq,
                stack,
            ),
            Factored::Halves => unreachable!("the split factors are solved above"),
        }
        for (value, &p) in rhs.iter_mut().zip(place) {
            *value = permuted[p];
        }
    }
}

/// The relative size of the static regularization of a KKT system's zero diagonal (see
/// [`SparseKkt`]), against its largest entry.
pub const DUAL_REGULARIZATION: f64 = 1e-8;
/// Iterative refinement's steps at most.
pub const REFINEMENT_STEPS: usize = 10;

/// A symmetric sparse system assembled entry by entry ([`Assemble`]; duplicates add up): the
/// polish's KKT system of a net, `[[W_A + eps I, J_A^T], [J_A, 0]]`, indefinite with zeros on the
/// diagonal (its constraint rows). Solved by LDL^T (faer's simplicial or supernodal, as its
/// symbolic factorization chooses) in a minimum-degree order, without pivoting:
///
/// * The zero diagonal of the constraint rows gets `-delta` (DUAL_REGULARIZATION of the largest
///   entry): with W_A + eps I positive definite the matrix is then quasi-definite, and every
///   symmetric order factors (Vanderbei), so the order can be the sparsest one. A pivot that comes
///   out tiny all the same (an indefinite W_A) is replaced by +-delta.
/// * Iterative refinement on the assembled, unregularized matrix then removes the regularization's
///   error: each step shrinks it by about `delta / (delta + lambda_min(J_A W_A^-1 J_A^T))`. Where
///   the active rows are dependent (a statically indeterminate net) that eigenvalue is zero and the
///   regularization is a proximal term on the multipliers: the step is the one of least change in
///   them.
///
/// LU with partial pivoting (faer's simplicial one, Gilbert and Peierls') solves the same systems
/// but picks its pivots by size alone, off the diagonal of the constraint rows, which destroys the
/// order's sparsity: many times slower on grids already at a few hundred nodes.
///
/// The pattern follows the active set: the ordering and symbolic factorization are kept while the
/// assembled pattern does not change.
#[derive(Debug, Default)]
pub struct SparseKkt {
    n: usize,
    /// The entries as assembled: (row, column) and value.
    indices: Vec<[usize; 2]>,
    added: Vec<f64>,
    /// The pattern the analysis below was made for (the assembly order of `indices`).
    pattern: Vec<[usize; 2]>,
    /// The whole matrix by columns (for the refinement's products) and where each assembled entry
    /// goes in it.
    place: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<f64>,
    /// Each unknown's place in the factorization's order (old to new).
    order: Vec<usize>,
    /// The permuted upper triangle (with every diagonal entry) by columns, where each entry of
    /// the whole matrix goes in it (NONE below the permuted diagonal), and each column's diagonal.
    upper_ptr: Vec<usize>,
    upper_rows: Vec<usize>,
    upper_values: Vec<f64>,
    upper_place: Vec<usize>,
    upper_diagonal: Vec<usize>,
    /// The permuted columns whose diagonal was never assembled (constraint rows).
    zero_diagonal: Vec<bool>,
    symbolic: Option<cholesky::SymbolicCholesky<usize>>,
    lower: Vec<f64>,
    factored: bool,
}

impl SparseKkt {
    pub fn new() -> Self {
        Self::default()
    }

    /// The zero n x n matrix (keeping the storage and the last analysis).
    pub fn reset(&mut self, n: usize) {
        self.n = n;
        self.indices.clear();
        self.added.clear();
        self.factored = false;
    }

    pub fn size(&self) -> usize {
        self.n
    }

    /// The compressed columns, the order and the symbolic factorization of the assembled pattern,
    /// when it differs from the last one's.
    fn analyse(&mut self) {
        if self.symbolic.is_some() && self.pattern == self.indices && self.col_ptr.len() == self.n + 1 {
            return;
        }
        let n = self.n;
        let mut sorted: Vec<usize> = (0..self.indices.len()).collect();
        sorted.sort_unstable_by_key(|&e| (self.indices[e][1], self.indices[e][0]));
        self.place.clear();
        self.place.resize(self.indices.len(), 0);
        self.col_ptr.clear();
        self.col_ptr.resize(n + 1, 0);
        self.row_idx.clear();
        let mut last = [NONE, NONE];
        for &e in &sorted {
            let [row, column] = self.indices[e];
            if [row, column] != last {
                self.row_idx.push(row);
                self.col_ptr[column + 1] += 1;
                last = [row, column];
            }
            self.place[e] = self.row_idx.len() - 1;
        }
        for c in 0..n {
            self.col_ptr[c + 1] += self.col_ptr[c];
        }
        // Minimum degree on the upper triangle of the pattern, each diagonal entry included.
        let mut ptr = vec![0usize; n + 1];
        let mut rows = Vec::with_capacity(self.row_idx.len() + n);
        for c in 0..n {
            let column = &self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]];
            rows.extend(column.iter().copied().filter(|&row| row < c));
            rows.push(c);
            ptr[c + 1] = rows.len();
        }
        let (_, order) = minimum_degree(n, &ptr, &rows);
        // The permuted upper triangle: entry (i, k) goes to (min, max) of (order[i], order[k]),
        // taken from the whole matrix's entry with order[i] <= order[k].
        let mut entries: Vec<(usize, usize, usize)> = Vec::with_capacity(self.row_idx.len() / 2 + n);
        let mut has_diagonal = vec![false; n];
        for k in 0..n {
            for position in self.col_ptr[k]..self.col_ptr[k + 1] {
                let i = self.row_idx[position];
                if order[i] <= order[k] {
                    entries.push((order[k], order[i], position));
                }
                has_diagonal[k] |= i == k;
            }
            if !has_diagonal[k] {
                entries.push((order[k], order[k], NONE));
            }
        }
        entries.sort_unstable();
        self.upper_ptr.clear();
        self.upper_ptr.resize(n + 1, 0);
        self.upper_rows.clear();
        self.upper_place.clear();
        self.upper_place.resize(self.row_idx.len(), NONE);
        self.upper_diagonal.clear();
        self.upper_diagonal.resize(n, NONE);
        for (at, &(column, row, position)) in entries.iter().enumerate() {
            self.upper_ptr[column + 1] += 1;
            self.upper_rows.push(row);
            if position != NONE {
                self.upper_place[position] = at;
            }
            if row == column {
                self.upper_diagonal[column] = at;
            }
        }
        for c in 0..n {
            self.upper_ptr[c + 1] += self.upper_ptr[c];
        }
        self.zero_diagonal.clear();
        self.zero_diagonal.resize(n, false);
        for k in 0..n {
            self.zero_diagonal[order[k]] = !has_diagonal[k];
        }
        self.order = order;
        self.symbolic = Some(symbolic_factorization(n, &self.upper_ptr, &self.upper_rows));
        self.pattern.clone_from(&self.indices);
    }

    /// Factors the matrix assembled since `reset` (regularized, see [`SparseKkt`]); false if an
    /// entry is not finite or the factors are not.
    pub fn factor(&mut self) -> bool {
        self.factored = false;
        if !self.added.iter().all(|v| v.is_finite()) {
            return false;
        }
        self.analyse();
        let n = self.n;
        self.values.clear();
        self.values.resize(self.row_idx.len(), 0.0);
        for (&p, &value) in self.place.iter().zip(&self.added) {
            self.values[p] += value;
        }
        let scale = self
            .values
            .iter()
            .fold(0.0_f64, |m, v| m.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        let delta = DUAL_REGULARIZATION * scale;
        self.upper_values.clear();
        self.upper_values.resize(self.upper_rows.len(), 0.0);
        for (&at, &value) in self.upper_place.iter().zip(&self.values) {
            if at != NONE {
                self.upper_values[at] = value;
            }
        }
        for c in 0..n {
            if self.zero_diagonal[c] {
                self.upper_values[self.upper_diagonal[c]] = -delta;
            }
        }
        let symbolic = self.symbolic.as_ref().expect("analysed");
        self.lower.resize(symbolic.len_val(), 0.0);
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &self.upper_ptr, None, &self.upper_rows);
        let a = SparseColMatRef::new(pattern, &self.upper_values);
        let regularization = LdltRegularization {
            dynamic_regularization_signs: None,
            dynamic_regularization_delta: delta,
            dynamic_regularization_epsilon: f64::EPSILON * scale,
        };
        let mut memory =
            MemBuffer::new(symbolic.factorize_numeric_ldlt_scratch::<f64>(Par::Seq, Default::default()));
        let factored = symbolic.factorize_numeric_ldlt(
            &mut self.lower,
            a,
            faer::Side::Upper,
            regularization,
            Par::Seq,
            MemStack::new(&mut memory),
            Default::default(),
        );
        self.factored = factored.is_ok() && self.lower.iter().all(|v| v.is_finite());
        self.factored
    }

    /// `x = (L D L^T)^-1 x` in place, in the original order (`scratch`: n entries).
    fn apply_factors(&self, x: &mut [f64], scratch: &mut [f64]) {
        for (value, &p) in x.iter().zip(&self.order) {
            scratch[p] = *value;
        }
        let symbolic = self.symbolic.as_ref().expect("analysed");
        let factors = cholesky::LdltRef::new(symbolic, &self.lower);
        let n = self.n;
        let mut memory = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        factors.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(scratch, n, 1),
            Par::Seq,
            MemStack::new(&mut memory),
        );
        for (value, &p) in x.iter_mut().zip(&self.order) {
            *value = scratch[p];
        }
    }

    /// `out = b - A x` with the assembled matrix.
    fn residual(&self, x: &[f64], b: &[f64], out: &mut [f64]) {
        out.copy_from_slice(b);
        for k in 0..self.n {
            let xk = x[k];
            if xk != 0.0 {
                for position in self.col_ptr[k]..self.col_ptr[k + 1] {
                    out[self.row_idx[position]] -= self.values[position] * xk;
                }
            }
        }
    }

    /// Solves A x = rhs in place after a successful `factor`: the regularized factors' solution,
    /// refined on the assembled matrix while the residual keeps halving (REFINEMENT_STEPS at most)
    /// and is above the rounding of A x.
    pub fn solve(&self, rhs: &mut [f64]) {
        assert!(self.factored, "solve needs a successful factor first");
        let n = self.n;
        assert_eq!(rhs.len(), n, "rhs has the wrong length");
        let b = rhs.to_vec();
        let mut scratch = vec![0.0; n];
        self.apply_factors(rhs, &mut scratch);
        let largest = |v: &[f64]| v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let mut row_sums = vec![0.0; n];
        for k in 0..n {
            for position in self.col_ptr[k]..self.col_ptr[k + 1] {
                row_sums[self.row_idx[position]] += self.values[position].abs();
            }
        }
        let norm = largest(&row_sums);
        let mut residual = vec![0.0; n];
        let mut previous = f64::INFINITY;
        for _ in 0..REFINEMENT_STEPS {
            self.residual(rhs, &b, &mut residual);
            let size = largest(&residual);
            let rounding = 4.0 * f64::EPSILON * (norm * largest(rhs) + largest(&b));
            if !(size > rounding && size <= 0.5 * previous) {
                break;
            }
            previous = size;
            self.apply_factors(&mut residual, &mut scratch);
            for (x, dx) in rhs.iter_mut().zip(&residual) {
                *x += dx;
            }
        }
    }
}

impl Assemble for SparseKkt {
    fn add(&mut self, row: usize, col: usize, value: f64) {
        debug_assert!(
            row < self.n && col < self.n,
            "entry ({row}, {col}) outside {}",
            self.n
        );
        self.indices.push([row, col]);
        self.added.push(value);
    }
}

/// The whole system, then its regularized factors and the refined solve.
impl KktSolver for SparseKkt {
    fn solve_rows<R: KktRows>(&mut self, rows: &R, rhs: &mut [f64]) -> bool {
        self.reset(rhs.len());
        for i in 0..rows.block_sizes().len() {
            rows.add_block_row(i, self);
        }
        if !self.factor() {
            return false;
        }
        self.solve(rhs);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_support::{dense_solve, grid_pairs, Rng};

    /// A random graph over `n` nodes: a spanning path in a shuffled order plus `extra` random pairs.
    fn random_pairs(rng: &mut Rng, n: usize, extra: usize) -> Vec<[usize; 2]> {
        let mut order: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            order.swap(i, rng.below(i + 1));
        }
        let mut pairs: Vec<[usize; 2]> = order.windows(2).map(|w| [w[0], w[1]]).collect();
        for _ in 0..extra {
            let (a, b) = (rng.below(n), rng.below(n));
            if a != b {
                pairs.push([a, b]);
            }
        }
        pairs
    }

    /// A random symmetric positive definite matrix on the pattern of `pairs`, and its dense twin
    /// (row-major): per pair a term w e e^T (e = (g, -g)) and a random coupling block that the
    /// diagonal blocks dominate.
    fn random_spd(rng: &mut Rng, n: usize, d: usize, pairs: &[[usize; 2]]) -> (SparseMatrix, Vec<f64>) {
        let mut matrix = SparseMatrix::with_pairs(n, d, pairs.to_vec());
        matrix.reset(n, d);
        let size = n * d;
        let mut dense = vec![0.0; size * size];
        let add = |matrix: &mut SparseMatrix, dense: &mut [f64], f: usize, g: usize, block: &[f64]| {
            if f == g {
                matrix.add_node(f, block);
            } else {
                matrix.add_pair(f, g, block);
            }
            for i in 0..d {
                for k in 0..d {
                    dense[(f * d + i) * size + g * d + k] += block[i * d + k];
                    if f != g {
                        dense[(g * d + k) * size + f * d + i] += block[i * d + k];
                    }
                }
            }
        };
        for &[f, g] in pairs {
            let weight = 1.0 + rng.uniform();
            let e: Vec<f64> = (0..d).map(|_| rng.uniform()).collect();
            let outer: Vec<f64> = (0..d * d).map(|ik| weight * e[ik / d] * e[ik % d]).collect();
            let minus: Vec<f64> = outer.iter().map(|v| -v).collect();
            add(&mut matrix, &mut dense, f, f, &outer);
            add(&mut matrix, &mut dense, g, g, &outer);
            add(&mut matrix, &mut dense, f, g, &minus);
            // an unsymmetric coupling block (its transpose goes to (g, f)), 0.1 in size
            let coupling: Vec<f64> = (0..d * d).map(|_| 0.1 * rng.uniform()).collect();
            add(&mut matrix, &mut dense, f, g, &coupling);
        }
        // strict diagonal dominance (Gershgorin: positive definite), some rows only just
        for f in 0..n {
            let mut block = vec![0.0; d * d];
            for i in 0..d {
                let row = f * d + i;
                let off: f64 = (0..size)
                    .filter(|&c| c != row)
                    .map(|c| dense[row * size + c].abs())
                    .sum();
                block[i * d + i] = (off - dense[row * size + row]).max(0.0) + 0.05 * rng.between(0.1, 1.0);
            }
            add(&mut matrix, &mut dense, f, f, &block);
        }
        (matrix, dense)
    }

    fn shifted(dense: &[f64], size: usize, shift: f64) -> Vec<f64> {
        let mut copy = dense.to_vec();
        for i in 0..size {
            copy[i * size + i] += shift;
        }
        copy
    }

    /// Whether a dense symmetric matrix is positive definite (its Cholesky completes).
    fn dense_positive_definite(dense: &[f64], size: usize) -> bool {
        let mut l = vec![0.0; size * size];
        for j in 0..size {
            let mut pivot = dense[j * size + j];
            for k in 0..j {
                pivot -= l[j * size + k] * l[j * size + k];
            }
            if !(pivot > 0.0) {
                return false;
            }
            let root = pivot.sqrt();
            l[j * size + j] = root;
            for i in j + 1..size {
                let mut value = dense[i * size + j];
                for k in 0..j {
                    value -= l[i * size + k] * l[j * size + k];
                }
                l[i * size + j] = value / root;
            }
        }
        true
    }

    fn max_difference(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
    }

    fn norm_inf(x: &[f64]) -> f64 {
        x.iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    #[test]
    fn product_matches_the_dense_matrix() {
        let mut rng = Rng::new(22);
        for d in 1..=3 {
            for n in [1, 2, 9, 40] {
                let pairs = random_pairs(&mut rng, n, n);
                let (matrix, _) = random_spd(&mut rng, n, d, &pairs);
                let (size, dense) = (n * d, matrix.to_dense());
                let x: Vec<f64> = (0..size).map(|_| rng.between(-1.0, 1.0)).collect();
                let mut y = vec![1.0; size];
                matrix.multiply_add(&x, &mut y, &mut Vec::new());
                for i in 0..size {
                    let expected = 1.0 + (0..size).map(|k| dense[i * size + k] * x[k]).sum::<f64>();
                    assert!(
                        (y[i] - expected).abs() <= 1e-12 * (1.0 + expected.abs()),
                        "{i}: {} {expected}",
                        y[i]
                    );
                }
            }
        }
    }

    #[test]
    fn assembly_matches_the_dense_matrix() {
        let mut rng = Rng::new(21);
        for d in 1..=3 {
            for n in [1, 2, 9, 40] {
                let pairs = random_pairs(&mut rng, n, n);
                let (matrix, dense) = random_spd(&mut rng, n, d, &pairs);
                // (the diagonal blocks are read by their lower triangles: symmetrize the twin's)
                let size = n * d;
                let mut expected = dense.clone();
                for i in 0..size {
                    for k in 0..size {
                        if i / d == k / d && k > i {
                            expected[i * size + k] = dense[k * size + i];
                        }
                    }
                }
                assert_eq!(matrix.to_dense(), expected);
                assert_eq!(matrix.size(), size);
            }
        }
    }

    #[test]
    fn cholesky_matches_a_dense_solve() {
        let mut rng = Rng::new(22);
        for d in 1..=3 {
            for n in [1, 2, 9, 60] {
                let pairs = random_pairs(&mut rng, n, 2 * n);
                let (matrix, dense) = random_spd(&mut rng, n, d, &pairs);
                let size = n * d;
                let mut factors = matrix.new_factors();
                for shift in [0.0, 0.3] {
                    assert!(factors.factor_shifted(&matrix, shift));
                    let b: Vec<f64> = (0..size).map(|_| rng.uniform()).collect();
                    let mut x = b.clone();
                    factors.solve_in_place(&mut x);
                    let expected = dense_solve(size, &shifted(&dense, size, shift), &b).expect("regular");
                    let difference = max_difference(&x, &expected);
                    assert!(
                        difference <= 1e-10 * (1.0 + norm_inf(&expected)),
                        "off by {difference:e} (n {n}, d {d})"
                    );
                }
            }
        }
    }

    /// The pairs as `with_pairs` keeps them: f <= g, each node's own pair added, sorted, once each.
    fn normalized(n: usize, pairs: &[[usize; 2]]) -> Vec<[usize; 2]> {
        let mut all: Vec<[usize; 2]> = pairs.iter().map(|&[f, g]| [f.min(g), f.max(g)]).collect();
        all.extend((0..n).map(|f| [f, f]));
        all.sort_unstable();
        all.dedup();
        all
    }

    /// The minimum-degree order of the nodes (old to new), from faer's AMD on the node graph.
    fn minimum_degree_places(n: usize, pairs: &[[usize; 2]]) -> Vec<usize> {
        let mut columns = vec![Vec::new(); n];
        for &[f, g] in &normalized(n, pairs) {
            columns[g].push(f);
        }
        let mut col_ptr = vec![0];
        let mut rows = Vec::new();
        for column in &mut columns {
            column.sort_unstable();
            rows.extend_from_slice(column);
            col_ptr.push(rows.len());
        }
        minimum_degree(n, &col_ptr, &rows).1
    }

    /// The block count of the factor's work is the scalar factor's: entries and multiply-adds
    /// summed over the columns of the simplicial symbolic factorization of the whole matrix.
    #[test]
    fn factor_work_counts_the_scalar_factor() {
        let mut rng = Rng::new(26);
        for d in 1..=3 {
            for n in [1, 7, 60, 300] {
                let pairs = random_pairs(&mut rng, n, n);
                let matrix = SparseMatrix::with_pairs(n, d, pairs.clone());
                let size = n * d;
                let scalar = symbolic_cholesky(size, &matrix.col_ptr, &matrix.row_idx);
                let factor_ptr = scalar.factor().col_ptr();
                let (mut entries, mut multiply_adds) = (0u64, 0u64);
                for c in 0..size {
                    let count = (factor_ptr[c + 1] - factor_ptr[c]) as u64;
                    entries += count;
                    multiply_adds += count * (count - 1) / 2;
                }
                let work = factor_work(n, d, &normalized(n, &pairs), &matrix.node_places());
                assert_eq!(
                    work,
                    FactorWork {
                        entries,
                        multiply_adds
                    },
                    "n {n}, d {d}"
                );
            }
        }
    }

    /// A small net keeps the minimum-degree order (so its answers stay as they were), a large
    /// grid takes nested dissection, whose factor takes fewer multiply-adds.
    #[test]
    fn the_order_is_chosen_by_size_and_work() {
        let (n, pairs) = (30 * 30, grid_pairs(30, 30));
        let matrix = SparseMatrix::with_pairs(n, 3, pairs.clone());
        assert!(matrix.separator_tree().is_none());
        assert_eq!(matrix.node_places(), minimum_degree_places(n, &pairs));

        let (n, pairs) = (100 * 100, grid_pairs(100, 100));
        let matrix = SparseMatrix::with_pairs(n, 3, pairs.clone());
        let tree = matrix
            .separator_tree()
            .expect("a 100 x 100 grid takes nested dissection");
        assert_eq!((tree[0].start, tree[0].end), (0, n));
        let normal = normalized(n, &pairs);
        let dissected = factor_work(n, 3, &normal, &matrix.node_places());
        let by_degree = factor_work(n, 3, &normal, &minimum_degree_places(n, &pairs));
        assert!(
            dissected.multiply_adds as f64 <= DISSECTION_SHARE * by_degree.multiply_adds as f64,
            "{dissected:?} against {by_degree:?}"
        );
    }

    /// A grid's Newton system (diagonally dominant, so positive definite) in the nested-dissection
    /// order: the solution's residual, recomputed from the blocks as assembled, is at rounding level.
    #[test]
    fn nested_dissection_solves_a_grid_system() {
        let mut rng = Rng::new(27);
        let (a, b, d) = (80, 75, 3);
        let n = a * b;
        let pairs = grid_pairs(a, b);
        let mut matrix = SparseMatrix::with_pairs(n, d, pairs.clone());
        assert!(
            matrix.separator_tree().is_some(),
            "the grid should take nested dissection"
        );
        let pair_blocks: Vec<Vec<f64>> = pairs
            .iter()
            .map(|_| (0..d * d).map(|_| rng.uniform()).collect())
            .collect();
        // each row's off-diagonal sum, to dominate by the diagonal
        let mut off = vec![0.0; n * d];
        for (&[f, g], block) in pairs.iter().zip(&pair_blocks) {
            for i in 0..d {
                for k in 0..d {
                    off[f * d + i] += block[i * d + k].abs();
                    off[g * d + k] += block[i * d + k].abs();
                }
            }
        }
        let node_blocks: Vec<Vec<f64>> = (0..n)
            .map(|f| {
                let mut block = vec![0.1; d * d];
                for i in 0..d {
                    block[i * d + i] = off[f * d + i] + 0.1 * (d as f64) + rng.between(0.5, 1.0);
                }
                block
            })
            .collect();
        matrix.reset(n, d);
        for (f, block) in node_blocks.iter().enumerate() {
            matrix.add_node(f, block);
        }
        for (&[f, g], block) in pairs.iter().zip(&pair_blocks) {
            matrix.add_pair(f, g, block);
        }
        let mut factors = matrix.new_factors();
        assert!(factors.factor_shifted(&matrix, 0.0));
        let rhs: Vec<f64> = (0..n * d).map(|_| rng.uniform()).collect();
        let mut x = rhs.clone();
        factors.solve_in_place(&mut x);
        // A x from the blocks
        let mut product = vec![0.0; n * d];
        for (f, block) in node_blocks.iter().enumerate() {
            for i in 0..d {
                for k in 0..d {
                    product[f * d + i] += block[i * d + k] * x[f * d + k];
                }
            }
        }
        for (&[f, g], block) in pairs.iter().zip(&pair_blocks) {
            for i in 0..d {
                for k in 0..d {
                    product[f * d + i] += block[i * d + k] * x[g * d + k];
                    product[g * d + k] += block[i * d + k] * x[f * d + i];
                }
            }
        }
        let residual = max_difference(&product, &rhs);
        assert!(residual <= 1e-12, "residual {residual:e}");
        assert!(norm_inf(&x) > 1e-3, "a solution that is not zero");
    }

    /// `scale` times the d x d identity, row by row.
    fn scaled_identity(d: usize, scale: f64) -> Vec<f64> {
        (0..d * d)
            .map(|e| if e % (d + 1) == 0 { scale } else { 0.0 })
            .collect()
    }

    /// A grid whose rim is 10^8 times stiffer than its inside (links among the outer six rings of
    /// nodes weighted 1e8, those nodes also tied to the ground): factored in halves, its system is
    /// solved about as accurately as factored whole, and the two say alike whether the matrix less
    /// a shift just below or just above its smallest eigenvalue is positive definite.
    #[test]
    fn a_stiff_rim_is_solved_in_halves_as_accurately_as_whole() {
        let (a, b, d) = (80, 75, 3);
        let n = a * b;
        let pairs = grid_pairs(a, b);
        let rim = |f: usize| f / b < 6 || f % b < 6 || f / b >= a - 6 || f % b >= b - 6;
        let mut matrix = SparseMatrix::with_pairs(n, d, pairs.clone());
        assert!(matrix.split_in_two());
        let identity = |scale: f64| scaled_identity(d, scale);
        let mut diagonal = vec![0.0; n];
        for (f, value) in diagonal.iter_mut().enumerate() {
            *value = if rim(f) { 1.0 } else { 0.0 };
        }
        for &[f, g] in &pairs {
            let weight = if rim(f) && rim(g) { 1e8 } else { 1.0 };
            diagonal[f] += weight;
            diagonal[g] += weight;
            matrix.add_pair(f, g, &identity(-weight));
        }
        for (f, &value) in diagonal.iter().enumerate() {
            matrix.add_node(f, &identity(value));
        }
        let mut rng = Rng::new(5);
        let rhs: Vec<f64> = (0..n * d).map(|_| rng.uniform()).collect();
        let mut work = Vec::new();
        let residual = |factors: &mut SparseCholesky, work: &mut Vec<f64>| -> f64 {
            assert!(factors.factor_shifted(&matrix, 0.0));
            let mut x = rhs.clone();
            factors.solve_in_place(&mut x);
            let mut product: Vec<f64> = rhs.iter().map(|v| -v).collect();
            matrix.multiply_add(&x, &mut product, work);
            norm_inf(&product)
        };
        let mut halves = matrix.new_factors();
        let mut whole = matrix.new_factors();
        whole.split = None;
        let (split_residual, whole_residual) =
            (residual(&mut halves, &mut work), residual(&mut whole, &mut work));
        assert!(
            split_residual <= 10.0 * whole_residual,
            "in halves {split_residual:e}, whole {whole_residual:e}"
        );
        // the smallest eigenvalue by bisection on the whole factorization
        let (mut low, mut high) = (0.0, 1.0);
        while whole.factor_shifted(&matrix, -high) {
            high *= 2.0;
        }
        for _ in 0..60 {
            let middle = 0.5 * (low + high);
            if whole.factor_shifted(&matrix, -middle) {
                low = middle;
            } else {
                high = middle;
            }
        }
        assert!(halves.factor_shifted(&matrix, -low * (1.0 - 1e-6)));
        assert!(!halves.factor_shifted(&matrix, -low * (1.0 + 1e-6)));
    }

    /// A large grid's matrix is factored in two halves below its top separators, as L L^T or
    /// L D L^T: one thread or two give the same bits, the solution's residual is at rounding
    /// level, and L L^T fails exactly where the matrix stops being positive definite. The matrix is
    /// the grid's Laplacian (per coordinate; singular: moving every node alike) plus `shift I`, whose smallest
    /// eigenvalue is the shift.
    #[test]
    fn the_split_factorizations_are_the_same_on_one_or_two_threads_and_exact_about_definiteness() {
        let (a, b, d) = (80, 75, 3);
        let n = a * b;
        let pairs = grid_pairs(a, b);
        let mut matrix = SparseMatrix::with_pairs(n, d, pairs.clone());
        assert!(
            matrix.split_in_two(),
            "the grid should be split at its top separator"
        );
        let mut degree = vec![0.0; n];
        for &[f, g] in &pairs {
            degree[f] += 1.0;
            degree[g] += 1.0;
        }
        let identity = |scale: f64| scaled_identity(d, scale);
        for (f, &k) in degree.iter().enumerate() {
            matrix.add_node(f, &identity(k));
        }
        for &[f, g] in &pairs {
            matrix.add_pair(f, g, &identity(-1.0));
        }
        let mut factors = matrix.new_factors();
        assert!(
            !factors.factor_shifted(&matrix, -1e-6),
            "singular Laplacian less 1e-6 I"
        );
        assert!(factors.factor_shifted(&matrix, 1e-6), "Laplacian plus 1e-6 I");

        let mut rng = Rng::new(31);
        let rhs: Vec<f64> = (0..n * d).map(|_| rng.uniform()).collect();
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<u64>>();
        // the residual of (Laplacian + shift I) x = rhs, from the grid
        let check = |x: &[f64], shift: f64| {
            let mut product: Vec<f64> = x.iter().map(|v| shift * v).collect();
            for (f, &k) in degree.iter().enumerate() {
                for i in 0..d {
                    product[f * d + i] += k * x[f * d + i];
                }
            }
            for &[f, g] in &pairs {
                for i in 0..d {
                    product[f * d + i] -= x[g * d + i];
                    product[g * d + i] -= x[f * d + i];
                }
            }
            let residual = max_difference(&product, &rhs);
            assert!(residual <= 1e-10, "shift {shift}: residual {residual:e}");
        };
        // each factorization on one thread and on two: the same bits, and the residual
        let mut on_one_and_two = |shift: f64, factor: &dyn Fn(&mut SparseCholesky) -> bool| {
            let solutions: Vec<Vec<f64>> = [1, 2]
                .into_iter()
                .map(|threads| {
                    factors.set_threads(threads);
                    assert!(factor(&mut factors));
                    let mut x = rhs.clone();
                    factors.solve_in_place(&mut x);
                    x
                })
                .collect();
            assert_eq!(
                bits(&solutions[0]),
                bits(&solutions[1]),
                "one thread and two differ"
            );
            check(&solutions[0], shift);
        };
        on_one_and_two(0.5, &|factors| factors.factor_shifted(&matrix, 0.5));
        // L D L^T of the same matrix, and of an indefinite one (eigenvalues from -0.3 to 7.7)
        for shift in [-0.3, 0.5] {
            on_one_and_two(shift, &|factors| {
                let factored = factors.factor_indefinite(&matrix, shift, 1e-8, 1e-14);
                // (a positive definite matrix is factored in halves; an indefinite one may be
                // sent whole)
                factored && (factors.factored == Some(Factored::Halves) || shift < 0.0)
            });
        }
    }

    /// A ring of nodes in the plane, each coupled with the next by `c I` over a diagonal `a I`:
    /// eigenvalues a + 2 c cos(2 pi k / n), positive definite iff a > 2 |c| (n even).
    #[test]
    fn blocks_positive_definite_follows_the_eigenvalues_of_a_ring() {
        let (n, d) = (8, 2);
        let pairs: Vec<[usize; 2]> = (0..n).map(|f| [f, (f + 1) % n]).collect();
        for (a, c, expected) in [
            (2.1, 1.0, true),
            (1.9, 1.0, false),
            (2.1, -1.0, true),
            (1.9, -1.0, false),
        ] {
            let node_blocks: Vec<f64> = (0..n).flat_map(|_| [a, 0.0, 0.0, a]).collect();
            let pair_blocks: Vec<f64> = (0..n).flat_map(|_| [c, 0.0, 0.0, c]).collect();
            assert_eq!(
                blocks_positive_definite(d, &node_blocks, &pairs, &pair_blocks, 0.0),
                expected,
                "a {a} c {c}"
            );
        }
        // a shift moves every eigenvalue
        let node_blocks: Vec<f64> = (0..n).flat_map(|_| [2.1, 0.0, 0.0, 2.1]).collect();
        let pair_blocks: Vec<f64> = (0..n).flat_map(|_| [1.0, 0.0, 0.0, 1.0]).collect();
        assert!(!blocks_positive_definite(
            d,
            &node_blocks,
            &pairs,
            &pair_blocks,
            -0.2
        ));
    }

    /// A dense enough pattern takes the supernodal Cholesky factorization (dense kernels on blocks
    /// of columns): the same answer as a dense solve.
    #[test]
    fn supernodal_factorizations_match_a_dense_solve() {
        let mut rng = Rng::new(25);
        let (n, d) = (120, 3);
        let pairs = random_pairs(&mut rng, n, 6 * n);
        let (matrix, dense) = random_spd(&mut rng, n, d, &pairs);
        assert!(
            matrix.supernodal(),
            "the pattern should take the supernodal factorization"
        );
        let size = n * d;
        let mut factors = matrix.new_factors();
        assert!(factors.factor_shifted(&matrix, 0.1));
        let b: Vec<f64> = (0..size).map(|_| rng.uniform()).collect();
        let mut x = b.clone();
        factors.solve_in_place(&mut x);
        let expected = dense_solve(size, &shifted(&dense, size, 0.1), &b).expect("regular");
        let difference = max_difference(&x, &expected);
        assert!(
            difference <= 1e-10 * (1.0 + norm_inf(&expected)),
            "off by {difference:e}"
        );
    }

    /// The inertia correction's contract: a shift below the lowest eigenvalue fails, above it
    /// factors; the dense Cholesky decides which (bisection on the shift down to 1e-6).
    #[test]
    fn cholesky_reports_not_positive_definite() {
        let mut rng = Rng::new(23);
        for d in [2, 3] {
            for n in [3, 30] {
                let pairs = random_pairs(&mut rng, n, n);
                let (matrix, dense) = random_spd(&mut rng, n, d, &pairs);
                let size = n * d;
                let mut factors = matrix.new_factors();
                let (mut low, mut high) = (0.0, 100.0); // -low factors, -high does not
                assert!(dense_positive_definite(&dense, size));
                assert!(!dense_positive_definite(&shifted(&dense, size, -high), size));
                while high - low > 1e-6 {
                    let middle = 0.5 * (low + high);
                    if dense_positive_definite(&shifted(&dense, size, -middle), size) {
                        low = middle;
                    } else {
                        high = middle;
                    }
                }
                assert!(factors.factor_shifted(&matrix, -low + 1e-5));
                assert!(!factors.factor_shifted(&matrix, -high - 1e-5));
                assert!(!factors.factor_shifted(&matrix, -1e3));
            }
        }
        // a NaN fails too
        let mut matrix = SparseMatrix::with_pairs(3, 2, vec![[0, 2]]);
        matrix.reset(3, 2);
        matrix.add_node(1, &[f64::NAN, 0.0, 0.0, 1.0]);
        let mut factors = matrix.new_factors();
        assert!(!factors.factor_shifted(&matrix, 1.0));
    }

    /// A random KKT matrix `[[H, J^T], [J, 0]]` (H symmetric, positive definite if `definite`;
    /// J one row per pair with gradients (g, -g)), assembled into a SparseKkt with the rows after
    /// the coordinates, and its dense twin.
    fn random_kkt(
        rng: &mut Rng,
        n: usize,
        d: usize,
        pairs: &[[usize; 2]],
        definite: bool,
    ) -> (SparseKkt, Vec<f64>, usize) {
        let size = n * d + pairs.len();
        let mut kkt = SparseKkt::new();
        kkt.reset(size);
        let mut dense = vec![0.0; size * size];
        let mut add = |kkt: &mut SparseKkt, i: usize, k: usize, value: f64| {
            kkt.add(i, k, value);
            dense[i * size + k] += value;
        };
        for f in 0..n {
            for i in 0..d {
                for k in 0..=i {
                    let value = if i == k && definite {
                        2.0 + rng.uniform()
                    } else {
                        0.5 * rng.uniform()
                    };
                    add(&mut kkt, f * d + i, f * d + k, value);
                    if k != i {
                        add(&mut kkt, f * d + k, f * d + i, value);
                    }
                }
            }
        }
        for (r, &[f, g]) in pairs.iter().enumerate() {
            let row = n * d + r;
            for i in 0..d {
                let value = rng.uniform();
                add(&mut kkt, row, f * d + i, value);
                add(&mut kkt, f * d + i, row, value);
                add(&mut kkt, row, g * d + i, -value);
                add(&mut kkt, g * d + i, row, -value);
                let coupling = 0.2 * rng.uniform();
                add(&mut kkt, f * d + i, g * d + i, coupling);
                add(&mut kkt, g * d + i, f * d + i, coupling);
            }
        }
        (kkt, dense, size)
    }

    #[test]
    fn a_large_kkt_system_is_factored_by_supernodes_and_solved() {
        // a 100 x 100 grid's coordinates (d = 3) and one row per grid link: large enough for faer's
        // supernodal LDL^T; the residual recomputed from the entries as assembled
        let (n, d) = (10000, 3);
        let pairs: Vec<[usize; 2]> = (0..n)
            .flat_map(|f| {
                let right = (f % 100 < 99).then_some([f, f + 1]);
                let up = (f + 100 < n).then_some([f, f + 100]);
                right.into_iter().chain(up)
            })
            .collect();
        let size = n * d + pairs.len();
        let mut rng = Rng::new(7);
        let mut kkt = SparseKkt::new();
        kkt.reset(size);
        for f in 0..n {
            // (a node's coordinates coupled, as a link's stiffness couples them)
            for i in 0..d {
                kkt.add(f * d + i, f * d + i, 2.0 + rng.uniform());
                for k in 0..i {
                    let value = 0.3 * rng.uniform();
                    kkt.add(f * d + i, f * d + k, value);
                    kkt.add(f * d + k, f * d + i, value);
                }
            }
        }
        for (r, &[f, g]) in pairs.iter().enumerate() {
            for i in 0..d {
                for k in 0..d {
                    let value = 0.1 * rng.uniform();
                    kkt.add(f * d + i, g * d + k, value);
                    kkt.add(g * d + k, f * d + i, value);
                }
                let value = rng.between(0.5, 1.0);
                for (at, sign) in [(f * d + i, 1.0), (g * d + i, -1.0)] {
                    kkt.add(n * d + r, at, sign * value);
                    kkt.add(at, n * d + r, sign * value);
                }
            }
        }
        assert!(kkt.factor());
        assert!(is_supernodal(kkt.symbolic.as_ref().unwrap()));
        let b: Vec<f64> = (0..size).map(|_| rng.uniform()).collect();
        let mut x = b.clone();
        kkt.solve(&mut x);
        let mut residual = b.clone();
        for (&[i, k], value) in kkt.indices.iter().zip(&kkt.added) {
            residual[i] -= value * x[k];
        }
        assert!(
            norm_inf(&residual) <= 1e-10 * norm_inf(&x),
            "residual {:e}",
            norm_inf(&residual)
        );
    }

    #[test]
    fn kkt_solves_like_a_dense_solve() {
        let mut rng = Rng::new(24);
        for definite in [true, false] {
            for d in [2, 3] {
                for n in [2, 10, 50] {
                    let pairs = random_pairs(&mut rng, n, n / 2);
                    let (mut kkt, dense, size) = random_kkt(&mut rng, n, d, &pairs, definite);
                    for round in 0..2 {
                        assert!(kkt.factor(), "n {n}, d {d}");
                        let b: Vec<f64> = (0..size).map(|_| rng.uniform()).collect();
                        let mut x = b.clone();
                        kkt.solve(&mut x);
                        let expected = dense_solve(size, &dense, &b).expect("regular");
                        let difference = max_difference(&x, &expected);
                        assert!(
                            difference <= 1e-10 * (1.0 + norm_inf(&expected)),
                            "off by {difference:e} (n {n}, d {d}, round {round}, definite {definite})"
                        );
                        // the same pattern again, assembled afresh: the analysis is kept
                        let kept = kkt.order.clone();
                        let (indices, added) = (kkt.indices.clone(), kkt.added.clone());
                        kkt.reset(size);
                        for ([i, k], value) in indices.into_iter().zip(added) {
                            kkt.add(i, k, value);
                        }
                        assert!(kkt.factor());
                        assert_eq!(kkt.order, kept);
                    }
                }
            }
        }
    }

    /// Dependent constraint rows (the same row twice, a consistent right-hand side): the
    /// regularization makes the system solvable; the solution satisfies it and splits the
    /// multiplier evenly (the least change).
    #[test]
    fn kkt_with_dependent_rows() {
        let mut kkt = SparseKkt::new();
        kkt.reset(4);
        for (i, k, v) in [
            (0, 0, 2.0),
            (1, 1, 3.0),
            (2, 0, 1.0),
            (0, 2, 1.0),
            (3, 0, 1.0),
            (0, 3, 1.0),
        ] {
            kkt.add(i, k, v);
        }
        assert!(kkt.factor());
        let mut x = [1.0, 3.0, 0.5, 0.5];
        kkt.solve(&mut x);
        // x0 = 0.5 from both rows, 3 x1 = 3, 2 x0 + m1 + m2 = 1
        assert!((x[0] - 0.5).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12, "{x:?}");
        assert!((x[2] + x[3]).abs() < 1e-9 && (x[2] - x[3]).abs() < 1e-9, "{x:?}");
    }

    #[test]
    fn kkt_refuses_non_finite_systems() {
        let mut kkt = SparseKkt::new();
        kkt.reset(2);
        kkt.add(0, 0, 1.0);
        kkt.add(1, 1, f64::NAN);
        assert!(!kkt.factor());
        kkt.reset(2);
        kkt.add(0, 1, 2.0);
        kkt.add(1, 0, 2.0);
        kkt.add(0, 0, 1.0);
        assert!(kkt.factor());
        let mut x = [4.0, 2.0];
        kkt.solve(&mut x);
        assert!((x[0] - 1.0).abs() < 1e-14 && (x[1] - 1.5).abs() < 1e-14, "{x:?}");
    }
}
