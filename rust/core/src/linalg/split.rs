//! The Cholesky (or L D L^T) factorization of a large net's Newton matrix in two halves, on two
//! cores where there are two.
//!
//! In nested-dissection order, take the top separator and, to balance the work, a few of the
//! separators below it (S): what is left falls into pieces that share no entry, dealt into two
//! halves A and B of about equal work. In the order A, B, S the matrix is
//! `[[K_A, 0, K_AS], [0, K_B, K_BS], [K_SA, K_SB, K_S]]`. Each half is factored with the
//! separators' rows appended and a diagonal `C = diag(c)` in place of K_S,
//!
//! ```text
//! [[K_A, K_AS], [K_SA, C]] = [[L_A, 0], [L_SA, G_A]] [[L_A, 0], [L_SA, G_A]]^T,
//! ```
//!
//! by faer's sparse supernodal factorization, the two halves at the same time on two threads. The
//! last block gives `G_A G_A^T = C - L_SA L_SA^T`, so the separators' Schur complement is
//! `K_S - 2 C + G_A G_A^T + G_B G_B^T`, dense, factored by faer's dense Cholesky. `c_j`, the
//! absolute sum of row j of K_S, makes `C - K_S` diagonally dominant, so `C - L_SA L_SA^T` is
//! positive definite whenever the whole matrix is, and where a half fails the whole matrix is not
//! positive definite: in exact arithmetic the factorization succeeds exactly where the one of the
//! whole matrix would, and each row of S loses only its own size to rounding. L D L^T (the
//! polish's condensed system) takes `-C` instead, whose block stays negative definite, far from a
//! pivot that would need regularizing (where it is not, the whole matrix is factored instead). A
//! solve runs the halves' triangular solves (again two at a time) around the dense one of S.
//!
//! Every sum is the same whatever the number of threads: the threads take whole halves, and the
//! halves' contributions are added in one fixed order afterwards. One thread or two give the same
//! bits. The price on one core is S's block factored three times instead of once and the two
//! products `G G^T`: 10 to 20 per cent more time on the benchmark's grids.

use faer::dyn_stack::StackReq;
use faer::linalg::cholesky::ldlt::factor as ldlt;
use faer::linalg::cholesky::llt::factor::{self as llt, LltRegularization};
use faer::linalg::matmul::matmul as dense_matmul;
use faer::linalg::matmul::triangular::{matmul, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_unit_lower_triangular_in_place,
    solve_unit_upper_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{self, supernodal::SupernodalLltRef, SymbolicCholeskyRaw};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Accum, Conj, Mat, MatMut, Par};

use super::order::Part;
use super::sparse::{factor_numeric, factor_scratch, FactorKind, Scratch};
use std::sync::atomic::{AtomicBool, Ordering};

const NONE: usize = usize::MAX;

/// The cores a large net's factorization may use: `FUNICULAR_THREADS` where it is a whole number
/// of at least 1 (the Python package rejects anything else before a solve starts), else the cores
/// available. More than two are not used.
pub fn threads() -> usize {
    std::env::var("FUNICULAR_THREADS")
        .ok()
        .and_then(|value| value.trim().parse::<usize>().ok())
        .filter(|&count| count >= 1)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |count| count.get()))
}

/// The most separators taken into S to balance the halves' work.
const MOST_SEPARATORS: usize = 8;

/// `x = L^-1 x` (`transpose`: `L^-T x`) for a supernodal L D L^T factor's unit lower triangle L
/// (faer solves with it only as a whole): by supernodes, a dense unit triangular solve with the
/// diagonal block and a product with the rows below it.
fn unit_solve(
    symbolic: &SymbolicSupernodalCholesky<usize>,
    lower: &[f64],
    x: &mut [f64],
    below: &mut Vec<f64>,
    transpose: bool,
) {
    let factor = SupernodalLltRef::new(symbolic, lower);
    let supernodes = symbolic.n_supernodes();
    for index in 0..supernodes {
        let supernode = factor.supernode(if transpose { supernodes - 1 - index } else { index });
        let (start, values) = (supernode.start(), supernode.val());
        let columns = values.ncols();
        let (diagonal, rest) = values.split_at_row(columns);
        let rows = supernode.pattern();
        below.clear();
        if transpose {
            below.extend(rows.iter().map(|&row| x[row]));
            let top = MatMut::from_column_major_slice_mut(&mut x[start..start + columns], columns, 1);
            dense_matmul(
                top,
                Accum::Add,
                rest.transpose(),
                faer::MatRef::from_column_major_slice(below, rows.len(), 1),
                -1.0,
                Par::Seq,
            );
            let top = MatMut::from_column_major_slice_mut(&mut x[start..start + columns], columns, 1);
            solve_unit_upper_triangular_in_place(diagonal.transpose(), top, Par::Seq);
        } else {
            let top = MatMut::from_column_major_slice_mut(&mut x[start..start + columns], columns, 1);
            solve_unit_lower_triangular_in_place(diagonal, top, Par::Seq);
            below.resize(rows.len(), 0.0);
            dense_matmul(
                MatMut::from_column_major_slice_mut(below, rows.len(), 1),
                Accum::Replace,
                rest,
                faer::MatRef::from_column_major_slice(&x[start..start + columns], columns, 1),
                1.0,
                Par::Seq,
            );
            for (&row, &value) in rows.iter().zip(below.iter()) {
                x[row] -= value;
            }
        }
    }
}

/// One half's matrix `[[K_A, K_AS], [K_SA, C]]`: its own columns of the whole matrix, its upper
/// triangle by columns (its own columns, then the separators') and, for each entry, where it is in
/// the whole matrix's values (NONE for C's diagonal, in the separators' order).
#[derive(Debug)]
struct HalfPattern {
    columns: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    source: Vec<usize>,
    symbolic: cholesky::SymbolicCholesky<usize>,
}

impl HalfPattern {
    fn supernodal(&self) -> &cholesky::supernodal::SymbolicSupernodalCholesky<usize> {
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(supernodal) => supernodal,
            SymbolicCholeskyRaw::Simplicial(_) => unreachable!("the halves are made supernodal"),
        }
    }

    fn size(&self) -> usize {
        self.col_ptr.len() - 1
    }
}

/// The pieces of a nested dissection dealt into two halves, and the separators above them (node
/// places: the pieces by their index in the tree, the separators as ranges).
struct Deal {
    halves: [Vec<usize>; 2],
    separators: Vec<(usize, usize)>,
}

/// The deal whose factorization on two cores should take the least time: from the top separator
/// down, the piece with the most work is replaced by its parts and its separator, the pieces each
/// time dealt into two halves (the heaviest first, each to the lighter half). A deal is estimated
/// at its heavier half's multiply-adds plus S's dense work, about `s^3 / 2` for s unknowns in S
/// (S's block in each half and the product `G G^T`, two at a time, then S's own factorization):
/// more separators balance the halves but make S larger.
fn deal(parts: &[Part], node_work: &[u64], d: usize) -> Option<Deal> {
    let work = |part: usize| -> u64 { node_work[parts[part].start..parts[part].end].iter().sum() };
    let root = &parts[0];
    let mut separators = vec![(root.separator, root.end)];
    let mut pieces = root.children.clone();
    let mut best: Option<(f64, Deal)> = None;
    while pieces.len() >= 2 && separators.len() <= MOST_SEPARATORS {
        let mut by_work = pieces.clone();
        by_work.sort_by_key(|&piece| (std::cmp::Reverse(work(piece)), parts[piece].start));
        let mut halves: [Vec<usize>; 2] = [Vec::new(), Vec::new()];
        let mut loads = [0u64; 2];
        for &piece in &by_work {
            let lighter = usize::from(loads[1] < loads[0]);
            halves[lighter].push(piece);
            loads[lighter] += work(piece);
        }
        let s = (d * separators.iter().map(|&(a, b)| b - a).sum::<usize>()) as f64;
        let estimate = loads[0].max(loads[1]) as f64 + s * s * s / 2.0;
        if best.as_ref().is_none_or(|(least, _)| estimate < *least) {
            let separators = separators.clone();
            best = Some((estimate, Deal { halves, separators }));
        }
        let heaviest = by_work[0];
        let part = &parts[heaviest];
        if part.children.is_empty() {
            break;
        }
        separators.push((part.separator, part.end));
        pieces.retain(|&piece| piece != heaviest);
        pieces.extend(part.children.iter().copied());
    }
    best.map(|(_, deal)| deal)
}

/// How a matrix in nested-dissection order splits: two halves that share no entry, and the
/// separators above them (S), with the halves' patterns and symbolic factorizations and the
/// separators' own block.
#[derive(Debug)]
pub struct SplitPattern {
    halves: [HalfPattern; 2],
    /// The separators' columns of the whole matrix, ascending.
    top: Vec<usize>,
    /// The separators' own block: (row, column) in S, row >= column, and where the entry is in
    /// the whole matrix's values.
    corner: Vec<(usize, usize, usize)>,
}

impl SplitPattern {
    /// The split of the upper triangle `col_ptr`, `row_idx` (n d columns in nested-dissection order,
    /// rows ascending) by the separator tree `parts` (in node places; d columns a node), whose
    /// node places' columns take `node_work` multiply-adds. None where the net was not cut in two
    /// or more pieces.
    pub fn new(
        col_ptr: &[usize],
        row_idx: &[usize],
        parts: &[Part],
        node_work: &[u64],
        d: usize,
    ) -> Option<Self> {
        let Deal {
            halves: groups,
            separators,
        } = deal(parts, node_work, d)?;
        let size = col_ptr.len() - 1;
        // each column's owner (half 0, half 1 or S) and its index there
        const TOP: u8 = 2;
        let mut owner = vec![TOP; size];
        let mut index = vec![0usize; size];
        let mut columns: [Vec<usize>; 2] = [Vec::new(), Vec::new()];
        for (h, group) in groups.iter().enumerate() {
            for &piece in group {
                columns[h].extend(parts[piece].start * d..parts[piece].end * d);
            }
            columns[h].sort_unstable();
            for (i, &c) in columns[h].iter().enumerate() {
                owner[c] = h as u8;
                index[c] = i;
            }
        }
        let mut top: Vec<usize> = separators.iter().flat_map(|&(a, b)| a * d..b * d).collect();
        top.sort_unstable();
        for (i, &c) in top.iter().enumerate() {
            index[c] = i;
        }
        // the entries by half: (column, row, source) in the half's numbering
        let mut entries: [Vec<(usize, usize, usize)>; 2] = [Vec::new(), Vec::new()];
        let mut corner = Vec::new();
        for c in 0..size {
            for p in col_ptr[c]..col_ptr[c + 1] {
                let r = row_idx[p];
                match (owner[r], owner[c]) {
                    (TOP, TOP) => corner.push((index[c].max(index[r]), index[c].min(index[r]), p)),
                    (h, TOP) | (TOP, h) => {
                        let (own, separator) = if owner[r] == TOP { (c, r) } else { (r, c) };
                        let h = usize::from(h);
                        entries[h].push((columns[h].len() + index[separator], index[own], p));
                    }
                    (h, g) => {
                        assert_eq!(h, g, "the halves share no entry");
                        entries[usize::from(h)].push((index[c], index[r], p));
                    }
                }
            }
        }
        let s = top.len();
        let [first, second] = entries;
        let [first_columns, second_columns] = columns;
        let halves = [(first, first_columns), (second, second_columns)].map(|(mut entries, columns)| {
            let len = columns.len();
            entries.extend((0..s).map(|j| (len + j, len + j, NONE)));
            entries.sort_unstable();
            let n = len + s;
            let mut half_ptr = vec![0usize; n + 1];
            for &(column, _, _) in &entries {
                half_ptr[column + 1] += 1;
            }
            for c in 0..n {
                half_ptr[c + 1] += half_ptr[c];
            }
            let row_idx = entries.iter().map(|&(_, row, _)| row).collect::<Vec<_>>();
            let params = cholesky::CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            };
            let symbolic = cholesky::factorize_symbolic_cholesky(
                SymbolicSparseColMatRef::new_checked(n, n, &half_ptr, None, &row_idx),
                faer::Side::Upper,
                cholesky::SymmetricOrdering::Identity,
                params,
            )
            .expect("a symbolic factorization that fits in memory");
            HalfPattern {
                columns,
                col_ptr: half_ptr,
                row_idx,
                source: entries.iter().map(|&(_, _, p)| p).collect(),
                symbolic,
            }
        });
        Some(SplitPattern { halves, top, corner })
    }
}

/// One half's factors and working memory.
#[derive(Debug)]
struct HalfFactors {
    values: Vec<f64>,
    lower: Vec<f64>,
    /// G: the last block of its factor, the separators' (lower triangle).
    block: Mat<f64>,
    /// G G^T (lower triangle); for L D L^T, G D_S G^T, G with its unit diagonal.
    product: Mat<f64>,
    /// For L D L^T, G D_S.
    scaled: Mat<f64>,
    /// For L D L^T, the pivots D of the half's own columns and of the separators' block.
    pivots: Vec<f64>,
    separator_pivots: Vec<f64>,
    /// A supernode's rows below its diagonal block, in a solve.
    below: Vec<f64>,
    factor_scratch: Scratch,
    /// The solves' right-hand side (the half's columns, then the separators') and scratch.
    work: Vec<f64>,
    solve_scratch: Scratch,
}

impl HalfFactors {
    fn new() -> Self {
        HalfFactors {
            values: Vec::new(),
            lower: Vec::new(),
            block: Mat::new(),
            product: Mat::new(),
            scaled: Mat::new(),
            pivots: Vec::new(),
            separator_pivots: Vec::new(),
            below: Vec::new(),
            factor_scratch: Scratch::default(),
            work: Vec::new(),
            solve_scratch: Scratch::default(),
        }
    }

    /// Factors the half's matrix with `c` (C's diagonal) on the separators' diagonal, from the whole matrix's
    /// `values`; false where it fails (L L^T: not positive definite).
    fn factor(&mut self, pattern: &HalfPattern, values: &[f64], c: &[f64], kind: FactorKind) -> bool {
        self.values.clear();
        let mut next = c.iter();
        self.values.extend(pattern.source.iter().map(|&p| {
            if p == NONE {
                *next.next().expect("one c per separator row")
            } else {
                values[p]
            }
        }));
        let symbolic = &pattern.symbolic;
        self.lower.resize(symbolic.len_val(), 0.0);
        let n = pattern.size();
        let a = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx),
            &self.values,
        );
        let stack = self.factor_scratch.stack(|| factor_scratch(symbolic));
        let factored = factor_numeric(symbolic, &mut self.lower, a, kind, stack);
        if factored {
            self.read_separator_block(pattern, kind);
        }
        factored
    }

    /// G, read from the supernodes that hold the separators' columns, and its product with its
    /// transpose (for L D L^T the pivots too, on the factor's diagonal).
    fn read_separator_block(&mut self, pattern: &HalfPattern, kind: FactorKind) {
        let n = pattern.size();
        let len = pattern.columns.len();
        let s = n - len;
        zero(&mut self.block, s);
        self.pivots.clear();
        let factor = SupernodalLltRef::new(pattern.supernodal(), &self.lower);
        for index in 0..pattern.supernodal().n_supernodes() {
            let supernode = factor.supernode(index);
            let (start, values) = (supernode.start(), supernode.val());
            let columns = values.ncols();
            if kind != FactorKind::Cholesky {
                self.pivots
                    .extend((0..columns.min(len.saturating_sub(start))).map(|k| values[(k, k)]));
            }
            if start + columns <= len {
                continue;
            }
            for k in len.saturating_sub(start)..columns {
                let column = start + k - len;
                for i in k..columns {
                    self.block[(start + i - len, column)] = values[(i, k)];
                }
                for (i, &row) in supernode.pattern().iter().enumerate() {
                    self.block[(row - len, column)] = values[(columns + i, k)];
                }
            }
        }
        zero(&mut self.product, s);
        let left = if kind == FactorKind::Cholesky {
            self.block.as_ref()
        } else {
            zero(&mut self.scaled, s);
            self.separator_pivots.clear();
            self.separator_pivots.extend((0..s).map(|j| self.block[(j, j)]));
            for j in 0..s {
                self.block[(j, j)] = 1.0;
                for i in j..s {
                    self.scaled[(i, j)] = self.block[(i, j)] * self.separator_pivots[j];
                }
            }
            self.scaled.as_ref()
        };
        matmul(
            self.product.as_mut(),
            BlockStructure::TriangularLower,
            Accum::Replace,
            left,
            BlockStructure::TriangularLower,
            self.block.transpose(),
            BlockStructure::TriangularUpper,
            1.0,
            Par::Seq,
        );
    }

    /// `[y; z]` = L^-1 `[b; 0]` of the half's factor, `b` its columns of the right-hand side `x`
    /// (the whole matrix's order), which `y` replaces; z stays in `work` (`G z = -L_SA y`).
    fn forward(&mut self, pattern: &HalfPattern, x: &[f64], kind: FactorKind) {
        let n = pattern.size();
        self.work.clear();
        self.work.extend(pattern.columns.iter().map(|&c| x[c]));
        self.work.resize(n, 0.0);
        self.solve_with_l(pattern, kind, false);
    }

    /// `[x; _]` = L^-T `[y; G^T x_S]`, y left in `work` by [`HalfFactors::forward`] (for
    /// L D L^T, divided by the pivots first).
    fn backward(&mut self, pattern: &HalfPattern, x_separators: &[f64], kind: FactorKind) {
        let n = pattern.size();
        let len = pattern.columns.len();
        if kind != FactorKind::Cholesky {
            for (value, pivot) in self.work.iter_mut().zip(&self.pivots) {
                *value /= pivot;
            }
        }
        matmul(
            MatMut::from_column_major_slice_mut(&mut self.work[len..], n - len, 1),
            BlockStructure::Rectangular,
            Accum::Replace,
            self.block.transpose(),
            BlockStructure::TriangularUpper,
            faer::MatRef::from_column_major_slice(x_separators, n - len, 1),
            BlockStructure::Rectangular,
            1.0,
            Par::Seq,
        );
        self.solve_with_l(pattern, kind, true);
    }

    /// `work = L^-1 work` (`transpose`: `L^-T work`), L the half's factor (unit lower for
    /// L D L^T).
    fn solve_with_l(&mut self, pattern: &HalfPattern, kind: FactorKind, transpose: bool) {
        let supernodal = pattern.supernodal();
        if kind != FactorKind::Cholesky {
            unit_solve(
                supernodal,
                &self.lower,
                &mut self.work,
                &mut self.below,
                transpose,
            );
            return;
        }
        let stack = self
            .solve_scratch
            .stack(|| supernodal.solve_in_place_scratch::<f64>(1, Par::Seq));
        let factor = SupernodalLltRef::new(supernodal, &self.lower);
        let n = pattern.size();
        let work = MatMut::from_column_major_slice_mut(&mut self.work, n, 1);
        if transpose {
            factor.l_transpose_solve_with_conj(Conj::No, work, Par::Seq, stack);
        } else {
            factor.l_solve_with_conj(Conj::No, work, Par::Seq, stack);
        }
    }
}

/// `matrix` as the s x s zero matrix, its storage kept where it has that size.
fn zero(matrix: &mut Mat<f64>, s: usize) {
    if matrix.nrows() == s && matrix.ncols() == s {
        matrix.as_mut().fill(0.0);
    } else {
        *matrix = Mat::zeros(s, s);
    }
}

/// Runs `a` and `b`, on two threads where `threads` is 2 or more (else `a` first).
fn both<T: Send>(threads: usize, a: impl FnOnce() -> T + Send, b: impl FnOnce() -> T + Send) -> (T, T) {
    if threads < 2 {
        let first = a();
        return (first, b());
    }
    std::thread::scope(|scope| {
        let other = scope.spawn(b);
        let first = a();
        (first, other.join().expect("a half's work does not panic"))
    })
}

/// The Cholesky (or L D L^T) factors of a matrix split by a [`SplitPattern`].
#[derive(Debug)]
pub struct SplitFactors {
    halves: [HalfFactors; 2],
    /// The separators' Schur complement, then its Cholesky (or L D L^T) factor (lower triangle).
    corner: Mat<f64>,
    corner_scratch: Scratch,
    /// The separators' part of a right-hand side.
    top: Vec<f64>,
    /// c per row of S (negative for L D L^T).
    c: Vec<f64>,
    threads: usize,
    /// The factors it holds.
    kind: FactorKind,
}

impl SplitFactors {
    pub fn new(threads: usize) -> Self {
        SplitFactors {
            halves: [HalfFactors::new(), HalfFactors::new()],
            corner: Mat::new(),
            corner_scratch: Scratch::default(),
            top: Vec::new(),
            c: Vec::new(),
            threads,
            kind: FactorKind::Cholesky,
        }
    }

    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads;
    }

    /// Factors the matrix whose upper triangle has the values `values` (in the whole matrix's
    /// pattern) as `kind` says: whether that succeeded (L L^T: the matrix is positive definite; a
    /// NaN fails), or None where L D L^T is not to be trusted split and the whole matrix should be
    /// factored instead.
    ///
    /// c is per row of S: `c_j`, the absolute sum of row j of K_S, bounds K_S by `diag(c)`
    /// (diagonally dominant difference), and each row loses only its own size to the cancellation
    /// in `K_S - 2 diag(c) + ...`. L D L^T puts `-diag(c)`: with the halves' own blocks positive
    /// definite (the polish's condensed matrix but in rare cases) the block
    /// `-diag(c) - L_SA D_A L_SA^T` is negative definite, its pivots at most `-c_j`; a pivot
    /// above `-c_j / 2`, or a zero row of K_S, sends the matrix to the whole factorization.
    pub fn factor(&mut self, pattern: &SplitPattern, values: &[f64], kind: FactorKind) -> Option<bool> {
        self.kind = kind;
        let s = pattern.top.len();
        let sign = if kind == FactorKind::Cholesky { 1.0 } else { -1.0 };
        self.c.clear();
        self.c.resize(s, 0.0);
        for &(i, k, p) in &pattern.corner {
            self.c[i] += values[p].abs();
            if i != k {
                self.c[k] += values[p].abs();
            }
        }
        if !self.c.iter().all(|&c| c > 0.0 && c.is_finite()) {
            return (kind == FactorKind::Cholesky).then_some(false);
        }
        self.c.iter_mut().for_each(|c| *c *= sign);
        let c = &self.c;
        let [first, second] = &mut self.halves;
        let [first_pattern, second_pattern] = &pattern.halves;
        // On one thread the second half is not factored after the first failed (its work would
        // not be used); on two it may be, and the answer is the same.
        let first_failed = AtomicBool::new(false);
        let (a, b) = both(
            self.threads,
            || {
                let factored = first.factor(first_pattern, values, c, kind);
                first_failed.store(!factored, Ordering::Relaxed);
                factored
            },
            || !first_failed.load(Ordering::Relaxed) && second.factor(second_pattern, values, c, kind),
        );
        if !(a && b) {
            return Some(false);
        }
        if kind != FactorKind::Cholesky
            && self.halves.iter().any(|half| {
                half.separator_pivots
                    .iter()
                    .zip(c)
                    .any(|(&d, &c)| !(d <= 0.5 * c))
            })
        {
            return None;
        }
        // K_S - 2 diag(c) + G_A G_A^T + G_B G_B^T
        zero(&mut self.corner, s);
        for &(i, k, p) in &pattern.corner {
            self.corner[(i, k)] = values[p];
        }
        for (j, c) in c.iter().enumerate() {
            self.corner[(j, j)] -= 2.0 * c;
        }
        for half in &self.halves {
            for k in 0..s {
                for i in k..s {
                    self.corner[(i, k)] += half.product[(i, k)];
                }
            }
        }
        Some(self.factor_corner(s, kind))
    }

    /// Factors S's Schur complement in place.
    fn factor_corner(&mut self, s: usize, kind: FactorKind) -> bool {
        let stack = self.corner_scratch.stack(|| {
            StackReq::any_of(&[
                llt::cholesky_in_place_scratch::<f64>(s, Par::Seq, Default::default()),
                ldlt::cholesky_in_place_scratch::<f64>(s, Par::Seq, Default::default()),
            ])
        });
        let factored = match kind {
            FactorKind::Cholesky => llt::cholesky_in_place(
                self.corner.as_mut(),
                LltRegularization::default(),
                Par::Seq,
                stack,
                Default::default(),
            )
            .is_ok(),
            FactorKind::Ldlt { .. } => ldlt::cholesky_in_place(
                self.corner.as_mut(),
                kind.ldlt_regularization(),
                Par::Seq,
                stack,
                Default::default(),
            )
            .is_ok(),
        };
        factored && (0..s).all(|j| (0..=j).all(|k| self.corner[(j, k)].is_finite()))
    }

    /// Solves with the factors in place; `x` in the whole matrix's order.
    pub fn solve_in_place(&mut self, pattern: &SplitPattern, x: &mut [f64]) {
        let s = pattern.top.len();
        let kind = self.kind;
        let [first, second] = &mut self.halves;
        let [first_pattern, second_pattern] = &pattern.halves;
        {
            let x: &[f64] = x;
            both(
                self.threads,
                || first.forward(first_pattern, x, kind),
                || second.forward(second_pattern, x, kind),
            );
        }
        // b_S - L_SA y_A - L_SB y_B = b_S + G_A z_A + G_B z_B
        self.top.clear();
        self.top.extend(pattern.top.iter().map(|&c| x[c]));
        for half in [&*first, &*second] {
            let z = faer::MatRef::from_column_major_slice(&half.work[half.work.len() - s..], s, 1);
            matmul(
                MatMut::from_column_major_slice_mut(&mut self.top, s, 1),
                BlockStructure::Rectangular,
                Accum::Add,
                half.block.as_ref(),
                BlockStructure::TriangularLower,
                z,
                BlockStructure::Rectangular,
                1.0,
                Par::Seq,
            );
        }
        let mut top = MatMut::from_column_major_slice_mut(&mut self.top, s, 1);
        if kind == FactorKind::Cholesky {
            solve_lower_triangular_in_place(self.corner.as_ref(), top.as_mut(), Par::Seq);
            solve_upper_triangular_in_place(self.corner.transpose(), top.as_mut(), Par::Seq);
        } else {
            solve_unit_lower_triangular_in_place(self.corner.as_ref(), top.as_mut(), Par::Seq);
            for j in 0..s {
                top[(j, 0)] /= self.corner[(j, j)];
            }
            solve_unit_upper_triangular_in_place(self.corner.transpose(), top.as_mut(), Par::Seq);
        }
        let top: &[f64] = &self.top;
        both(
            self.threads,
            || first.backward(first_pattern, top, kind),
            || second.backward(second_pattern, top, kind),
        );
        for (&c, &value) in pattern.top.iter().zip(top) {
            x[c] = value;
        }
        for (half, half_pattern) in [(&*first, first_pattern), (&*second, second_pattern)] {
            for (&c, &value) in half_pattern.columns.iter().zip(&half.work) {
                x[c] = value;
            }
        }
    }
}
