//! A fast solver for the active-set polish's KKT system of a chain: block elimination over the nodes,
//! streamed.
//!
//! Ordered node by node (the multiplier of the link ending at the node if that link is active, the
//! node's coordinates if it is free, the multipliers of its active contacts), the KKT matrix
//! `[[H, J^T], [J, 0]]` of a chain is block tridiagonal with small blocks of varying size (0 to
//! about 8). [`BlockKkt::solve`] takes the matrix block row by block row from its caller and
//! eliminates each block as soon as it is complete, pivoting (by rows) inside the block only, with
//! the forward substitution of the right-hand side alongside: only the carried multipliers
//! `X_i = S_i^{-1} U_i` are stored for the backward substitution. O(n) work on data streamed in
//! order, most of it in two blocks' worth of scratch that stays in the cache, where the banded LU
//! (`linalg::BandedLu`) works on a band several times as wide.
//!
//! Pivoting inside the blocks only is not always stable. When a block's Schur complement is tiny
//! against the rest of the matrix (e.g. a node whose only stiffness in some direction is the 1e-10
//! proximal term, that direction being held instead by a row of the *next* block: a free node
//! without contact between a slack link and a taut one), its inverse carries huge multipliers
//! `S_i^{-1} U_i` on to the next block, whose Schur complement then cancels them: many digits are
//! lost where the banded LU, free to take its pivot from the next block's rows, loses none.
//! [`BlockKkt::solve`] therefore refuses (returns `false`) when a carried multiplier exceeds
//! [`UPDATE_LIMIT`] times the largest entry of the matrix, and the caller falls back to the banded
//! LU.
//!
//! Speed: the elimination is a chain, each block waiting for the previous one, and the blocks are
//! small, so loop overhead counts. Blocks of size 1 to 8 go through kernels with the size as a const
//! generic (the loops over the block unroll, and so do those over a neighbour of the same size);
//! other sizes take plain loops. Both do the same operations in the same order: the results do not
//! depend on the path (a test checks it bit for bit), nor on the CPU (no fused multiply-add).

// Index loops over the rows and columns of small dense blocks read like the formulas they compute.
#![allow(clippy::needless_range_loop)]

use super::{Assemble, KktRows, KktSolver};

/// The largest entry of a carried multiplier matrix `S_i^{-1} U_i`, relative to the largest entry of
/// the matrix as assembled, that [`BlockKkt::solve`] accepts.
pub const UPDATE_LIMIT: f64 = 1e9;

/// A square block-tridiagonal system with blocks of varying size (general, not assumed symmetric),
/// solved by block elimination: `S_0 = D_0`, `S_i = D_i - L_i S_{i-1}^{-1} U_{i-1}`, each `S_i` by
/// dense LU with partial pivoting. `D_i` is the diagonal block i, `U_i` = A[block i, block i+1] and
/// `L_i` = A[block i, block i-1].
///
/// One object is meant to be reused from Newton step to Newton step: its storage is kept, and a
/// solve allocates only where a system needs more than any before it.
#[derive(Clone, Debug, Default)]
pub struct BlockKkt {
    /// The X_i = S_i^{-1} U_i, block after block, each s_i x s_{i+1} row-major.
    upper: Vec<f64>,
    /// The blocks in the window as assembled, each row-major in storage the size of the largest
    /// block squared, and zero between uses (the elimination clears what it reads): D_i and L_i
    /// (s_i x s_{i-1}) of the two blocks in the window (block i in slot i % 2), and U_{i-1}
    /// (s_{i-1} x s_i).
    diagonal: [Vec<f64>; 2],
    lower: [Vec<f64>; 2],
    coupling: Vec<f64>,
    /// The last block's pivots: the row (local to the block) swapped with row k at step k.
    pivots: Vec<u32>,
}

/// Where [`BlockKkt::solve`]'s caller adds the entries of block row i: those joining blocks i-1
/// and i (either way round) and those inside either.
pub struct Window<'a> {
    /// The first unknown of block i-1 (that of block i for i = 0), of block i, and one past block i.
    first: usize,
    middle: usize,
    end: usize,
    previous: &'a mut [f64],
    current: &'a mut [f64],
    upper: &'a mut [f64],
    lower: &'a mut [f64],
    /// Whether an entry outside the window was added (in a release build, where `add` does not
    /// panic on it): the solve then refuses.
    misplaced: bool,
}

impl Window<'_> {
    /// The storage of the block holding (row, col) and the entry's index in it, if (row, col)
    /// lies in blocks i-1 or i, with room for `rows` x `cols` from there.
    #[inline(always)]
    fn place(
        &mut self,
        row: usize,
        col: usize,
        rows: usize,
        cols: usize,
    ) -> Option<(&mut [f64], usize, usize)> {
        let inside = |k: usize, count: usize| k >= self.first && k + count <= self.end;
        if !(inside(row, rows) && inside(col, cols)) {
            debug_assert!(false, "entry ({row}, {col}) lies outside blocks i-1 and i");
            self.misplaced = true;
            return None;
        }
        let (p, s) = (self.middle - self.first, self.end - self.middle);
        Some(match (row >= self.middle, col >= self.middle) {
            (true, true) => (&mut *self.current, (row - self.middle) * s + col - self.middle, s),
            (false, false) => (&mut *self.previous, (row - self.first) * p + col - self.first, p),
            (false, true) => (&mut *self.upper, (row - self.first) * s + col - self.middle, s),
            (true, false) => (&mut *self.lower, (row - self.middle) * p + col - self.first, p),
        })
    }
}

/// Entries must lie in blocks i-1 or i (a block given to `add_block` in one of them): checked in
/// debug builds; in release builds an entry outside is dropped and the solve returns false.
impl Assemble for Window<'_> {
    #[inline(always)]
    fn add(&mut self, row: usize, col: usize, value: f64) {
        if let Some((matrix, at, _)) = self.place(row, col, 1, 1) {
            matrix[at] += value;
        }
    }

    #[inline(always)]
    fn add_block<F: Fn(usize, usize) -> f64>(
        &mut self,
        row: usize,
        col: usize,
        rows: usize,
        cols: usize,
        value: F,
    ) {
        if let Some((matrix, at, width)) = self.place(row, col, rows, cols) {
            for i in 0..rows {
                let line = &mut matrix[at + i * width..][..cols];
                for k in 0..cols {
                    line[k] += value(i, k);
                }
            }
        }
    }
}

/// The largest magnitude among `values` (NaNs aside), and a probe of their finiteness: the sum of
/// every value times zero, which is zero while all are finite and NaN once one is not (infinity
/// times zero is NaN). Four lanes keep the comparisons and sums off one long chain.
#[inline(always)]
fn scan(values: &[f64]) -> (f64, f64) {
    let mut largest = [0.0f64; 4];
    let mut sums = [0.0f64; 4];
    let mut take = |lane: usize, value: f64| {
        let magnitude = value.abs();
        if magnitude > largest[lane] {
            largest[lane] = magnitude;
        }
        sums[lane] += value * 0.0;
    };
    let chunks = values.chunks_exact(4);
    let rest = chunks.remainder();
    for chunk in chunks {
        for lane in 0..4 {
            take(lane, chunk[lane]);
        }
    }
    for (lane, &value) in rest.iter().enumerate() {
        take(lane, value);
    }
    (
        larger(larger(largest[0], largest[1]), larger(largest[2], largest[3])),
        (sums[0] + sums[1]) + (sums[2] + sums[3]),
    )
}

/// The larger of two magnitudes, neither of them NaN (cheaper than `f64::max`, which handles NaNs).
#[inline(always)]
pub(crate) fn larger(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

/// `$kernel::<S>($args)` for the block size `$size` = S in 1..=8, else `$otherwise`.
macro_rules! by_size {
    ($size:expr, $kernel:ident($($arg:expr),*), $otherwise:expr) => {
        match $size {
            1 => $kernel::<1>($($arg),*),
            2 => $kernel::<2>($($arg),*),
            3 => $kernel::<3>($($arg),*),
            4 => $kernel::<4>($($arg),*),
            5 => $kernel::<5>($($arg),*),
            6 => $kernel::<6>($($arg),*),
            7 => $kernel::<7>($($arg),*),
            8 => $kernel::<8>($($arg),*),
            _ => $otherwise,
        }
    };
}

impl BlockKkt {
    /// An object without storage; the first solve allocates it.
    pub fn new() -> Self {
        Self::default()
    }

    /// Solves A x = rhs in place, for the matrix with blocks of `sizes` (their sum is the order of
    /// A and the length of `rhs`; a block may be empty) given block row by block row:
    /// `assemble(i, window)` adds the entries of A joining blocks i-1 and i and those inside block i
    /// (and may add more inside block i-1), after which block i-1 is eliminated.
    ///
    /// Returns false, `rhs` then holding no solution, if a pivot is exactly zero or not finite, if
    /// an entry was added outside its window, or if the elimination is not to be trusted: an entry
    /// of some `S_{i-1}^{-1} U_{i-1}` (the multiplier matrix carried to the next block) larger in
    /// absolute value than [`UPDATE_LIMIT`] times the largest absolute entry of the matrix as
    /// assembled, or any number (assembled or computed) that is not finite. Without pivoting
    /// across blocks a tiny Schur complement (say a block whose only stiffness is a 1e-10 proximal
    /// term) passes a huge update on to the next block, which cancels it and loses the digits a
    /// banded LU with row pivoting would have kept: the limit catches that.
    pub fn solve<F: FnMut(usize, &mut Window)>(
        &mut self,
        sizes: &[usize],
        rhs: &mut [f64],
        assemble: F,
    ) -> bool {
        self.solve_with(sizes, rhs, assemble, UPDATE_LIMIT, true)
    }

    /// `solve` with the given limit on the carried multipliers, by the size-specialized kernels or
    /// not (the tests lift the limit, and compare the two ways).
    fn solve_with<F: FnMut(usize, &mut Window)>(
        &mut self,
        sizes: &[usize],
        rhs: &mut [f64],
        mut assemble: F,
        limit: f64,
        specialize: bool,
    ) -> bool {
        let n: usize = sizes.iter().sum();
        assert_eq!(rhs.len(), n, "rhs has the wrong length");
        let coupling = self.prepare(sizes);
        let Self {
            upper,
            diagonal: [diagonal_even, diagonal_odd],
            lower: [lower_even, lower_odd],
            coupling: assembled_u,
            pivots,
        } = self;
        let size = |i: usize| if i < sizes.len() { sizes[i] } else { 0 };
        // The largest magnitudes assembled and carried (in the X_i), and the sum of every number
        // computed times zero (NaN if one is not finite, else zero). A number assembled that is
        // not finite makes one computed so: D_i and L_i enter S_i, which enters its LU factors
        // (where a NaN or an infinity stays one), and those and U_i enter X_i (every factor enters
        // every column), so the probe looks at the X_i, and at the factors of a block without X.
        let mut seen = Seen::default();
        let mut misplaced = false;
        // The first unknown of blocks i-2, i-1 and i, and where X_{i-2} and X_{i-1} begin in `upper`.
        let (mut start_2, mut start_1, mut start) = (0, 0, 0);
        let (mut coupling_2, mut coupling_1) = (0, 0);
        for i in 0..=sizes.len() {
            let (p, s) = (if i > 0 { size(i - 1) } else { 0 }, size(i));
            let (previous, current, lower_previous, lower_current) = if i % 2 == 0 {
                (
                    &mut *diagonal_odd,
                    &mut *diagonal_even,
                    &mut *lower_odd,
                    &mut *lower_even,
                )
            } else {
                (
                    &mut *diagonal_even,
                    &mut *diagonal_odd,
                    &mut *lower_even,
                    &mut *lower_odd,
                )
            };
            if i < sizes.len() {
                let mut window = Window {
                    first: start_1,
                    middle: start,
                    end: start + s,
                    previous: &mut previous[..p * p],
                    current: &mut current[..s * s],
                    upper: &mut assembled_u[..p * s],
                    lower: &mut lower_current[..s * p],
                    misplaced: false,
                };
                assemble(i, &mut window);
                misplaced |= window.misplaced;
            }
            if p > 0 {
                // block i-1 is complete: eliminate it, and substitute forward
                let q = if i > 1 { size(i - 2) } else { 0 };
                let (done, rest) = upper.split_at_mut(coupling_1);
                let (before, block) = rhs.split_at_mut(start_1);
                let step = Step {
                    d: &mut previous[..p * p],
                    l: &mut lower_previous[..p * q],
                    u: &mut assembled_u[..p * s],
                    x: &done[coupling_2..][..q * p],
                    y: &before[start_2..],
                    b: &mut block[..p],
                    carried: &mut rest[..p * s],
                    pivots: &mut pivots[..p],
                };
                let regular = if specialize {
                    by_size!(p, eliminate(step, &mut seen), eliminate_any(p, step, &mut seen))
                } else {
                    eliminate_any(p, step, &mut seen)
                };
                if !regular {
                    return false;
                }
            }
            (start_2, start_1, start) = (start_1, start, start + s);
            (coupling_2, coupling_1) = (coupling_1, coupling_1 + p * s);
        }
        if misplaced || seen.probe != 0.0 || seen.carried > limit * seen.assembled {
            return false;
        }
        backward(upper, sizes, rhs, coupling, specialize);
        true
    }

    /// Storage for blocks of `sizes`: room for the X_i, and the scratch zeroed (a refused solve
    /// leaves numbers behind in it). Returns the entries of the X_i.
    fn prepare(&mut self, sizes: &[usize]) -> usize {
        let coupling: usize = sizes.windows(2).map(|pair| pair[0] * pair[1]).sum();
        if self.upper.len() < coupling {
            // (every entry is written before it is read; a zeroed allocation leaves fresh pages to
            // be zeroed by the system on first touch instead of written twice)
            self.upper = vec![0.0; coupling];
        }
        let largest_block = sizes.iter().copied().max().unwrap_or(0);
        let [diagonal_even, diagonal_odd] = &mut self.diagonal;
        let [lower_even, lower_odd] = &mut self.lower;
        for scratch in [
            diagonal_even,
            diagonal_odd,
            lower_even,
            lower_odd,
            &mut self.coupling,
        ] {
            scratch.clear();
            scratch.resize(largest_block * largest_block, 0.0);
        }
        self.pivots.clear();
        self.pivots.resize(largest_block, 0);
        coupling
    }
}

/// The backward substitution `x_i = y_i - X_i x_{i+1}`, from the last block but one, in `rhs`
/// (holding the y_i); `upper` holds the X_i (`coupling` entries), blocks of `sizes`.
fn backward(upper: &[f64], sizes: &[usize], rhs: &mut [f64], coupling: usize, specialize: bool) {
    let size = |i: usize| if i < sizes.len() { sizes[i] } else { 0 };
    let (mut start, mut coupling) = (rhs.len(), coupling);
    for i in (0..sizes.len()).rev() {
        let (s, t) = (size(i), size(i + 1));
        let next_start = start;
        start -= s;
        coupling -= s * t;
        if s == 0 || t == 0 {
            continue;
        }
        let (head, tail) = rhs.split_at_mut(next_start);
        let (y, next) = (&mut head[start..], &tail[..t]);
        let x = &upper[coupling..][..s * t];
        if specialize {
            by_size!(s, backward_block(x, next, y), backward_block_any(s, x, next, y));
        } else {
            backward_block_any(s, x, next, y);
        }
    }
}

/// The block elimination, refusing (false) where it does not trust its pivots (see
/// [`BlockKkt::solve`]).
impl KktSolver for BlockKkt {
    fn solve_rows<R: KktRows>(&mut self, rows: &R, rhs: &mut [f64]) -> bool {
        self.solve(rows.block_sizes(), rhs, |i, window| rows.add_block_row(i, window))
    }
}

/// Block i's elimination and forward substitution, of size s: its blocks as assembled, row-major,
/// `d` = D_i (s x s), `l` = L_i (s x p) and `u` = U_i (s x t), all three cleared on the way; `x` =
/// X_{i-1} (p x s) and `y` = y_{i-1}; `b`, the block's right-hand side, gets y_i, `carried` gets
/// X_i, and `pivots` the block's pivots.
struct Step<'a> {
    d: &'a mut [f64],
    l: &'a mut [f64],
    u: &'a mut [f64],
    x: &'a [f64],
    y: &'a [f64],
    b: &'a mut [f64],
    carried: &'a mut [f64],
    pivots: &'a mut [u32],
}

/// What the elimination of some blocks saw: the largest magnitudes assembled (in their D, L and
/// U) and carried (in their X), and the sum of the numbers they computed times zero.
#[derive(Clone, Copy, Default)]
struct Seen {
    assembled: f64,
    carried: f64,
    probe: f64,
}

impl Seen {
    #[inline(always)]
    fn add(&mut self, assembled: f64, (carried, probe): (f64, f64)) {
        self.assembled = larger(self.assembled, assembled);
        self.carried = larger(self.carried, carried);
        self.probe += probe;
    }
}

/// Eliminates block i, of size S: `S_i = D_i - L_i X_{i-1}`, then `P S_i = L U` by Gaussian
/// elimination with partial pivoting (reciprocal pivots on the diagonal), `y_i = S_i^{-1} (b -
/// L_i y_{i-1})` and `X_i = S_i^{-1} U_i`, what it saw added to `seen`. False if a pivot is zero or
/// not finite.
fn eliminate<const S: usize>(step: Step, seen: &mut Seen) -> bool {
    let Step {
        d,
        l,
        u,
        x,
        y,
        b,
        carried,
        pivots,
    } = step;
    let d = &mut d[..S * S];
    let mut a = [[0.0; S]; S];
    for r in 0..S {
        a[r].copy_from_slice(&d[r * S..(r + 1) * S]);
    }
    d.fill(0.0);
    // The largest magnitudes assembled: place by place over the S x S blocks (reduced once, at
    // the end), and over blocks of other shapes. All in registers, as are the scans below.
    let mut largest = a.map(|row| row.map(|value| larger(0.0, value.abs())));
    let mut assembled = 0.0;
    let mut w: [[f64; 1]; S] = std::array::from_fn(|k| [b[k]]);
    // (a constant when the previous block has the same size: the loops unroll)
    let p = x.len() / S;
    if p == S {
        let l = &mut l[..S * S];
        take_largest(&mut largest, l);
        subtract_product(&mut a, l, x, S);
        subtract_product(&mut w, l, y, S);
        l.fill(0.0);
    } else {
        assembled = larger(assembled, scan(l).0);
        subtract_product(&mut a, l, x, p);
        subtract_product(&mut w, l, y, p);
        l.fill(0.0);
    }
    // `perm`: the row of S_i at each row of P S_i
    let mut perm: [usize; S] = std::array::from_fn(|k| k);
    // the steps of the elimination one by one, k a constant in each (a loop over k would not
    // unroll, and `a` would not stay in registers)
    macro_rules! steps {
        ($($k:literal)*) => {
            $(
                if $k < S && !elimination_step(&mut a, &mut perm, pivots, $k) {
                    return false;
                }
            )*
        };
    }
    steps!(0 1 2 3 4 5 6 7);
    let mut v: [[f64; 1]; S] = std::array::from_fn(|k| w[perm[k]]);
    lu_solve(&a, &mut v);
    for r in 0..S {
        b[r] = v[r][0];
    }
    // X_i: all columns at once when there are S (scanned before they are stored), else column by
    // column
    let t = u.len() / S;
    if t == S {
        let u = &mut u[..S * S];
        take_largest(&mut largest, u);
        let mut v = [[0.0; S]; S];
        for k in 0..S {
            v[k].copy_from_slice(&u[perm[k] * S..(perm[k] + 1) * S]);
        }
        u.fill(0.0);
        lu_solve(&a, &mut v);
        for r in 0..S {
            carried[r * S..(r + 1) * S].copy_from_slice(&v[r]);
        }
        seen.add(larger(assembled, scan_block(&largest).0), scan_block(&v));
    } else {
        assembled = larger(assembled, scan(u).0);
        for c in 0..t {
            let mut v: [[f64; 1]; S] = std::array::from_fn(|k| [u[perm[k] * t + c]]);
            lu_solve(&a, &mut v);
            for r in 0..S {
                carried[r * t + c] = v[r][0];
            }
        }
        u.fill(0.0);
        let (largest_x, finite) = scan(carried);
        let probe = if t > 0 { finite } else { scan(a.as_flattened()).1 };
        let assembled = larger(assembled, scan_block(&largest).0);
        seen.add(assembled, (largest_x, probe));
    }
    true
}

/// `scan` of a block held in registers (a column a lane: a slice of it would go through memory).
#[inline(always)]
fn scan_block<const S: usize, const W: usize>(block: &[[f64; W]; S]) -> (f64, f64) {
    let mut largest = [0.0f64; W];
    let mut sums = [0.0f64; W];
    for row in block {
        for c in 0..W {
            largest[c] = larger(largest[c], row[c].abs());
            sums[c] += row[c] * 0.0;
        }
    }
    (largest.into_iter().fold(0.0, larger), sums.into_iter().sum())
}

/// `largest` = the larger magnitude place by place of itself and `block` (S x S, row-major; NaNs
/// aside).
#[inline(always)]
fn take_largest<const S: usize>(largest: &mut [[f64; S]; S], block: &[f64]) {
    for r in 0..S {
        for c in 0..S {
            largest[r][c] = larger(largest[r][c], block[r * S + c].abs());
        }
    }
}

/// Step k of the Gaussian elimination of `a` with partial pivoting: the pivot (the first of the
/// largest magnitudes in column k from row k down), the row swap (recorded in `pivots` and `perm`),
/// the reciprocal pivot in the pivot's place, the multipliers below it and the update of the rows
/// below. False if the pivot is zero or not finite.
#[inline(always)]
fn elimination_step<const S: usize>(
    a: &mut [[f64; S]; S],
    perm: &mut [usize; S],
    pivots: &mut [u32],
    k: usize,
) -> bool {
    let mut best = k;
    let mut largest = a[k][k].abs();
    for r in k + 1..S {
        if a[r][k].abs() > largest {
            largest = a[r][k].abs();
            best = r;
        }
    }
    // (zero, infinite or NaN, in one test)
    if !(largest > 0.0 && largest <= f64::MAX) {
        return false;
    }
    pivots[k] = best as u32;
    perm.swap(k, best);
    for r in k + 1..S {
        if r == best {
            a.swap(k, r);
        }
    }
    let reciprocal = 1.0 / a[k][k];
    a[k][k] = reciprocal;
    for r in k + 1..S {
        let m = a[r][k] * reciprocal;
        a[r][k] = m;
        for c in k + 1..S {
            a[r][c] -= m * a[k][c];
        }
    }
    true
}

/// `v = U^{-1} L^{-1} v` for the factors `a` of P S (unit L below the diagonal, U above it with the
/// reciprocals of its diagonal), on W columns at once.
#[inline(always)]
fn lu_solve<const S: usize, const W: usize>(a: &[[f64; S]; S], v: &mut [[f64; W]; S]) {
    // (constant bounds, so that the loops unroll completely)
    for r in 0..S {
        for k in 0..S {
            if k < r {
                for c in 0..W {
                    v[r][c] -= a[r][k] * v[k][c];
                }
            }
        }
    }
    for r in (0..S).rev() {
        for k in 0..S {
            if k > r {
                for c in 0..W {
                    v[r][c] -= a[r][k] * v[k][c];
                }
            }
        }
        for c in 0..W {
            v[r][c] *= a[r][r];
        }
    }
}

/// `a -= m b`, each entry with the k in increasing order (`a` S x W, `m` S x p, `b` p x W), the
/// columns of `m` that are zero skipped (a chain's KKT matrix has many: a link's or a contact's
/// row has no entry in the next block; a product with a zero would change nothing unless `b` held
/// an infinity or a NaN, which the solve refuses anyway).
#[inline(always)]
fn subtract_product<const S: usize, const W: usize>(a: &mut [[f64; W]; S], m: &[f64], b: &[f64], p: usize) {
    let (m, b) = (&m[..S * p], &b[..p * W]);
    for k in 0..p {
        if zero_column(m, S, p, k) {
            continue;
        }
        for r in 0..S {
            let factor = m[r * p + k];
            for c in 0..W {
                a[r][c] -= factor * b[k * W + c];
            }
        }
    }
}

/// Whether column k of `m` (rows x width, row-major) is zero (without a branch per entry).
#[inline(always)]
fn zero_column(m: &[f64], rows: usize, width: usize, k: usize) -> bool {
    (0..rows).fold(true, |zero, r| zero & (m[r * width + k] == 0.0))
}

/// `eliminate` for any size s, in plain loops (the row operations on X_i along with those on
/// S_i), with the same arithmetic in the same order.
fn eliminate_any(s: usize, step: Step, seen: &mut Seen) -> bool {
    let Step {
        d,
        l,
        u,
        x,
        y,
        b,
        carried,
        pivots,
    } = step;
    let (p, t) = (x.len() / s, u.len() / s);
    let assembled = larger(larger(scan(d).0, scan(l).0), scan(u).0);
    for k in 0..p {
        if zero_column(l, s, p, k) {
            continue;
        }
        for r in 0..s {
            let factor = l[r * p + k];
            for c in 0..s {
                d[r * s + c] -= factor * x[k * s + c];
            }
            b[r] -= factor * y[k];
        }
    }
    carried.copy_from_slice(u);
    for k in 0..s {
        let mut best = k;
        let mut largest = d[k * s + k].abs();
        for r in k + 1..s {
            let magnitude = d[r * s + k].abs();
            if magnitude > largest {
                largest = magnitude;
                best = r;
            }
        }
        if largest == 0.0 || !largest.is_finite() {
            return false;
        }
        pivots[k] = best as u32;
        for (matrix, width) in [(&mut *d, s), (&mut *carried, t)] {
            for c in 0..width {
                matrix.swap(k * width + c, best * width + c);
            }
        }
        b.swap(k, best);
        let reciprocal = 1.0 / d[k * s + k];
        d[k * s + k] = reciprocal;
        for r in k + 1..s {
            let m = d[r * s + k] * reciprocal;
            d[r * s + k] = m;
            for c in k + 1..s {
                d[r * s + c] -= m * d[k * s + c];
            }
            for c in 0..t {
                carried[r * t + c] -= m * carried[k * t + c];
            }
            b[r] -= m * b[k];
        }
    }
    for r in (0..s).rev() {
        for k in r + 1..s {
            for c in 0..t {
                carried[r * t + c] -= d[r * s + k] * carried[k * t + c];
            }
            b[r] -= d[r * s + k] * b[k];
        }
        for c in 0..t {
            carried[r * t + c] *= d[r * s + r];
        }
        b[r] *= d[r * s + r];
    }
    let (largest, finite) = scan(carried);
    let probe = if t > 0 { finite } else { scan(d).1 };
    for scratch in [d, l, u] {
        scratch.fill(0.0);
    }
    seen.add(assembled, (largest, probe));
    true
}

/// The backward step of the solve for block i, of size S: `y -= X_i next`, with `x` = X_i (S x t)
/// and `next` = x_{i+1}.
fn backward_block<const S: usize>(x: &[f64], next: &[f64], y: &mut [f64]) {
    let mut v: [[f64; 1]; S] = std::array::from_fn(|r| [y[r]]);
    let t = next.len();
    if t == S {
        subtract_product(&mut v, x, next, S);
    } else {
        subtract_product(&mut v, x, next, t);
    }
    for r in 0..S {
        y[r] = v[r][0];
    }
}

/// `backward_block` for any size s.
fn backward_block_any(s: usize, x: &[f64], next: &[f64], y: &mut [f64]) {
    let t = next.len();
    for k in 0..t {
        if zero_column(x, s, t, k) {
            continue;
        }
        for r in 0..s {
            y[r] -= x[r * t + k] * next[k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_support::{dense_solve, Rng};

    /// A test system: its block sizes and its entries (duplicates allowed, they sum).
    struct System {
        sizes: Vec<usize>,
        entries: Vec<(usize, usize, f64)>,
    }

    impl System {
        fn order(&self) -> usize {
            self.sizes.iter().sum()
        }

        /// The first unknown of every block.
        fn starts(&self) -> Vec<usize> {
            let mut starts = vec![0];
            for &s in &self.sizes {
                starts.push(starts.last().unwrap() + s);
            }
            starts
        }

        /// The matrix, dense and row-major.
        fn dense(&self) -> Vec<f64> {
            let n = self.order();
            let mut a = vec![0.0; n * n];
            for &(r, c, v) in &self.entries {
                a[r * n + c] += v;
            }
            a
        }

        /// Solves A x = rhs in place by `kkt` (see `BlockKkt::solve_with`), the entries given
        /// block row by block row: those of row i join blocks i-1 and i or lie inside block i.
        fn solve_with(&self, kkt: &mut BlockKkt, rhs: &mut [f64], limit: f64, specialize: bool) -> bool {
            let starts = self.starts();
            let block_of = |k: usize| starts.partition_point(|&start| start <= k) - 1;
            let mut rows = vec![Vec::new(); self.sizes.len()];
            for &(r, c, v) in &self.entries {
                rows[block_of(r).max(block_of(c))].push((r, c, v));
            }
            let assemble = |i: usize, window: &mut Window| {
                for &(r, c, v) in &rows[i] {
                    window.add(r, c, v);
                }
            };
            kkt.solve_with(&self.sizes, rhs, assemble, limit, specialize)
        }

        fn solve(&self, kkt: &mut BlockKkt, rhs: &mut [f64]) -> bool {
            self.solve_with(kkt, rhs, UPDATE_LIMIT, true)
        }

        /// Whether `kkt` solves the system (for some right-hand side).
        fn solves(&self, kkt: &mut BlockKkt) -> bool {
            self.solve(kkt, &mut vec![1.0; self.order()])
        }
    }

    fn norm_inf(v: &[f64]) -> f64 {
        v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
    }

    /// ||A x - b|| / (||A|| ||x|| + ||b||) in the infinity norms.
    fn residual(n: usize, a: &[f64], x: &[f64], b: &[f64]) -> f64 {
        let mut r = 0.0f64;
        let mut norm_a = 0.0f64;
        for i in 0..n {
            let row = &a[i * n..(i + 1) * n];
            let ax: f64 = row.iter().zip(x).map(|(a, x)| a * x).sum();
            r = r.max((ax - b[i]).abs());
            norm_a = norm_a.max(row.iter().map(|a| a.abs()).sum());
        }
        r / (norm_a * norm_inf(x) + norm_inf(b))
    }

    fn relative_difference(x: &[f64], reference: &[f64]) -> f64 {
        let difference: Vec<f64> = x.iter().zip(reference).map(|(a, b)| a - b).collect();
        norm_inf(&difference) / norm_inf(reference)
    }

    /// Loads `system`, factors it (which must succeed), solves it for a random right-hand side, and
    /// checks the residual and the agreement with the dense solution.
    fn check(kkt: &mut BlockKkt, system: &System, rng: &mut Rng, agreement: f64) {
        let n = system.order();
        let b: Vec<f64> = (0..n).map(|_| rng.uniform()).collect();
        let mut x = b.clone();
        assert!(system.solve(kkt, &mut x), "solve failed");
        if n == 0 {
            return;
        }
        let a = system.dense();
        let r = residual(n, &a, &x, &b);
        assert!(r < 1e-12, "residual {r:e}");
        let reference = dense_solve(n, &a, &b).expect("the oracle finds the matrix singular");
        let e = relative_difference(&x, &reference);
        assert!(e < agreement, "difference from the dense solution {e:e}");
    }

    #[derive(Clone, Copy, PartialEq)]
    enum Kind {
        /// Random entries, each row's diagonal entry larger than the rest of the row together.
        Dominant,
        /// Symmetric, diagonal entries of both signs dominating their rows.
        Indefinite,
        /// Random entries, nothing else.
        General,
    }

    /// A random block-tridiagonal system with block sizes drawn in 0..=max_size.
    fn random_blocks(rng: &mut Rng, blocks: usize, max_size: usize, kind: Kind) -> System {
        let sizes: Vec<usize> = (0..blocks).map(|_| rng.below(max_size + 1)).collect();
        let starts = {
            let mut starts = vec![0];
            for &s in &sizes {
                starts.push(starts.last().unwrap() + s);
            }
            starts
        };
        let mut entries = Vec::new();
        let value = |rng: &mut Rng| rng.uniform();
        for i in 0..blocks {
            let rows = starts[i]..starts[i + 1];
            let columns = starts[i.saturating_sub(1)]..starts[(i + 2).min(blocks)];
            for r in rows {
                for c in columns.clone() {
                    if kind == Kind::Indefinite {
                        if c <= r {
                            let v = value(rng);
                            entries.push((r, c, v));
                            if c != r {
                                entries.push((c, r, v));
                            }
                        }
                    } else {
                        entries.push((r, c, value(rng)));
                    }
                }
                // every row has at most 3 * max_size entries of magnitude at most 1
                let dominance = (3 * max_size + 1) as f64;
                match kind {
                    Kind::Dominant => entries.push((r, r, dominance)),
                    Kind::Indefinite => {
                        let sign = if rng.chance(0.5) { 1.0 } else { -1.0 };
                        entries.push((r, r, sign * dominance));
                    }
                    Kind::General => {}
                }
            }
        }
        System { sizes, entries }
    }

    #[test]
    fn random_diagonally_dominant_systems() {
        let mut rng = Rng::new(1);
        let mut kkt = BlockKkt::new();
        for blocks in [1, 2, 3, 10, 100] {
            for _ in 0..5 {
                let system = random_blocks(&mut rng, blocks, 6, Kind::Dominant);
                check(&mut kkt, &system, &mut rng, 1e-12);
            }
        }
    }

    #[test]
    fn random_indefinite_systems() {
        let mut rng = Rng::new(2);
        let mut kkt = BlockKkt::new();
        for blocks in [1, 2, 3, 10, 100] {
            for _ in 0..5 {
                let system = random_blocks(&mut rng, blocks, 6, Kind::Indefinite);
                check(&mut kkt, &system, &mut rng, 1e-12);
            }
        }
    }

    #[test]
    fn random_general_systems_are_solved_or_refused() {
        let mut rng = Rng::new(3);
        let mut kkt = BlockKkt::new();
        let mut solved = 0;
        for blocks in [1, 2, 3, 10, 50] {
            for _ in 0..10 {
                let system = random_blocks(&mut rng, blocks, 6, Kind::General);
                let n = system.order();
                let b: Vec<f64> = (0..n).map(|_| rng.uniform()).collect();
                let mut x = b.clone();
                if !system.solve(&mut kkt, &mut x) {
                    continue;
                }
                solved += 1;
                if n > 0 {
                    let r = residual(n, &system.dense(), &x, &b);
                    assert!(r < 1e-12, "residual {r:e}");
                }
            }
        }
        // random matrices this small are rarely singular (or near enough to trip the guard)
        assert!(solved >= 45, "only {solved} of 50 factored");
    }

    /// A chain as the polish sees it: per link its unit direction q, multiplier mu, length and
    /// whether it is active; per node whether it is free and the gradients of its active contacts.
    struct Chain {
        d: usize,
        q: Vec<[f64; 3]>,
        mu: Vec<f64>,
        length: Vec<f64>,
        active: Vec<bool>,
        free: Vec<bool>,
        contacts: Vec<Vec<[f64; 3]>>,
    }

    const NONE: usize = usize::MAX;
    const PROXIMAL: f64 = 1e-10;

    /// Where the unknowns are, in the polish's order.
    struct Layout {
        sizes: Vec<usize>,
        /// Every link's multiplier (NONE if inactive).
        link: Vec<usize>,
        /// Every node's first coordinate (NONE if fixed).
        coordinate: Vec<usize>,
        /// Every node's first contact multiplier.
        contact: Vec<usize>,
    }

    impl Chain {
        fn nodes(&self) -> usize {
            self.free.len()
        }

        fn layout(&self) -> Layout {
            let nodes = self.nodes();
            let mut layout = Layout {
                sizes: vec![0; nodes],
                link: vec![NONE; nodes - 1],
                coordinate: vec![NONE; nodes],
                contact: vec![NONE; nodes],
            };
            let mut size = 0;
            for i in 0..nodes {
                let start = size;
                if i > 0 && self.active[i - 1] {
                    layout.link[i - 1] = size;
                    size += 1;
                }
                if self.free[i] {
                    layout.coordinate[i] = size;
                    size += self.d;
                    layout.contact[i] = size;
                    size += self.contacts[i].len();
                }
                layout.sizes[i] = size - start;
            }
            layout
        }

        /// Every entry of the KKT matrix, built as the polish builds it.
        fn entries(&self, layout: &Layout, emit: &mut dyn FnMut(usize, usize, f64)) {
            let d = self.d;
            for k in 0..self.nodes() - 1 {
                let row = layout.link[k];
                if row == NONE {
                    continue;
                }
                let q = &self.q[k];
                let ends = [(layout.coordinate[k], 1.0), (layout.coordinate[k + 1], -1.0)];
                for (x, sx) in ends {
                    for (y, sy) in ends {
                        if x != NONE && y != NONE {
                            for i in 0..d {
                                for j in 0..d {
                                    let identity = if i == j { 1.0 } else { 0.0 };
                                    let stiffness = (identity - q[i] * q[j]) / self.length[k];
                                    emit(x + i, y + j, sx * sy * self.mu[k] * stiffness);
                                }
                            }
                        }
                    }
                }
                for (x, sign) in ends {
                    if x != NONE {
                        for i in 0..d {
                            emit(x + i, row, sign * q[i]);
                            emit(row, x + i, sign * q[i]);
                        }
                    }
                }
            }
            for node in 0..self.nodes() {
                let x = layout.coordinate[node];
                if x == NONE {
                    continue;
                }
                for i in 0..d {
                    emit(x + i, x + i, PROXIMAL);
                }
                for (j, g) in self.contacts[node].iter().enumerate() {
                    for i in 0..d {
                        emit(x + i, layout.contact[node] + j, g[i]);
                        emit(layout.contact[node] + j, x + i, g[i]);
                    }
                }
            }
        }

        fn system(&self) -> System {
            let layout = self.layout();
            let mut entries = Vec::new();
            self.entries(&layout, &mut |r, c, v| entries.push((r, c, v)));
            System {
                sizes: layout.sizes,
                entries,
            }
        }
    }

    /// A random chain with fixed ends (and the nodes in `fixed`), links inactive with probability
    /// `slack`, contacts at a free node with probability `touching`. The active rows are kept
    /// independent (each free node carries at most d rows: its contacts, the row of the link ending
    /// at it, and that of the link starting at it if the next node is fixed), and a free node after
    /// an inactive link, before an active one, gets a contact: else its only stiffness along the
    /// next link would be the proximal term (`guard_trips_on_a_proximal_block` is that case).
    fn random_chain(
        rng: &mut Rng,
        d: usize,
        nodes: usize,
        fixed: &[usize],
        slack: f64,
        touching: f64,
    ) -> Chain {
        let free: Vec<bool> = (0..nodes)
            .map(|i| i != 0 && i != nodes - 1 && !fixed.contains(&i))
            .collect();
        let mut active: Vec<bool> = (0..nodes - 1).map(|_| !rng.chance(slack)).collect();
        // anchor every run of two or more free nodes joined by active links: through an active link
        // to a fixed node at either end, else by the link before it (to an anchored run)
        let mut a = 1;
        while a < nodes {
            if !free[a] {
                a += 1;
                continue;
            }
            let mut b = a;
            while free[b + 1] && active[b] {
                b += 1;
            }
            let anchored = (!free[a - 1] && active[a - 1]) || (!free[b + 1] && active[b]);
            if b > a && !anchored {
                active[a - 1] = true;
            }
            a = b + 1;
        }
        let mut contacts = vec![Vec::new(); nodes];
        for i in 0..nodes {
            if !free[i] {
                continue;
            }
            let rows_in = usize::from(active[i - 1]) + usize::from(active[i] && !free[i + 1]);
            let budget = (d - rows_in).min(2);
            let mut count = if rng.chance(touching) {
                1 + rng.below(budget.max(1))
            } else {
                0
            };
            if !active[i - 1] && active[i] {
                count = count.max(1);
            }
            count = count.min(budget);
            contacts[i] = (0..count).map(|_| rng.direction(d)).collect();
        }
        Chain {
            d,
            q: (0..nodes - 1).map(|_| rng.direction(d)).collect(),
            mu: (0..nodes - 1).map(|_| rng.between(0.5, 2.0)).collect(),
            length: (0..nodes - 1).map(|_| rng.between(0.5, 1.5)).collect(),
            active,
            free,
            contacts,
        }
    }

    #[test]
    fn chain_kkt_systems() {
        let mut rng = Rng::new(4);
        let mut kkt = BlockKkt::new();
        for d in [2, 3] {
            for (slack, touching) in [(0.0, 0.0), (0.0, 0.5), (0.2, 0.3), (0.4, 0.6)] {
                for nodes in [3, 4, 10, 40] {
                    let chain = random_chain(&mut rng, d, nodes, &[], slack, touching);
                    check(&mut kkt, &chain.system(), &mut rng, 1e-10);
                }
            }
        }
    }

    #[test]
    fn chain_with_fixed_middle_nodes_and_empty_blocks() {
        let mut rng = Rng::new(5);
        let mut kkt = BlockKkt::new();
        for d in [2, 3] {
            let mut chain = random_chain(&mut rng, d, 30, &[10, 11, 20], 0.2, 0.5);
            // empty blocks in the middle: the link into a fixed node inactive
            chain.active[9] = false;
            chain.active[10] = false;
            chain.active[19] = false;
            let system = chain.system();
            assert_eq!(&system.sizes[10..12], &[0, 0]);
            assert_eq!(system.sizes[20], 0);
            check(&mut kkt, &system, &mut rng, 1e-10);
        }
    }

    #[test]
    fn empty_blocks_anywhere() {
        let mut rng = Rng::new(6);
        let mut kkt = BlockKkt::new();
        for sizes in [
            vec![0, 2, 0, 0, 3, 0, 1, 0],
            vec![0],
            vec![],
            vec![0, 0, 3],
            vec![4, 0],
        ] {
            let starts = {
                let mut starts = vec![0];
                for &s in &sizes {
                    starts.push(starts.last().unwrap() + s);
                }
                starts
            };
            let mut entries = Vec::new();
            for i in 0..sizes.len() {
                for r in starts[i]..starts[i + 1] {
                    for c in starts[i.saturating_sub(1)]..starts[(i + 2).min(sizes.len())] {
                        entries.push((r, c, rng.uniform()));
                    }
                    entries.push((r, r, 10.0));
                }
            }
            check(&mut kkt, &System { sizes, entries }, &mut rng, 1e-12);
        }
    }

    #[test]
    fn pivoting_inside_a_block() {
        // zero diagonal entries: a saddle point in one block, then in a block coupled to another
        let mut rng = Rng::new(7);
        let mut kkt = BlockKkt::new();
        let system = System {
            sizes: vec![2],
            entries: vec![(0, 1, 2.0), (1, 0, 3.0), (1, 1, 1.0)],
        };
        check(&mut kkt, &system, &mut rng, 1e-15);
        let system = System {
            sizes: vec![3, 2],
            entries: vec![
                (0, 1, 1.0),
                (0, 2, 1.0),
                (1, 0, 1.0),
                (2, 0, 1.0),
                (1, 1, 2.0),
                (2, 2, 3.0),
                (1, 3, 1.0),
                (3, 1, 1.0),
                (2, 4, -1.0),
                (4, 2, -1.0),
                (3, 4, 1.0),
                (4, 3, 1.0),
            ],
        };
        check(&mut kkt, &system, &mut rng, 1e-14);
        // the pivot is the first of the largest entries of the column
        let system = System {
            sizes: vec![3],
            entries: vec![(0, 1, 1.0), (1, 0, 2.0), (1, 2, 1.0), (2, 0, -2.0), (2, 1, 1.0)],
        };
        check(&mut kkt, &system, &mut rng, 1e-15);
        assert_eq!(kkt.pivots[0], 1);
    }

    #[test]
    fn singular_matrices_are_refused() {
        let mut kkt = BlockKkt::new();
        // a singular diagonal block
        let system = System {
            sizes: vec![2, 2],
            entries: vec![
                (0, 0, 1.0),
                (0, 1, 2.0),
                (1, 0, 2.0),
                (1, 1, 4.0),
                (2, 2, 1.0),
                (3, 3, 1.0),
            ],
        };
        assert!(!system.solves(&mut kkt));
        // singular only through the coupling: S_1 = 1 - 1 * 1 / 1 = 0
        let system = System {
            sizes: vec![1, 1],
            entries: vec![(0, 0, 1.0), (0, 1, 1.0), (1, 0, 1.0), (1, 1, 1.0)],
        };
        assert!(!system.solves(&mut kkt));
        // a zero row; the zero matrix
        let system = System {
            sizes: vec![3],
            entries: vec![(0, 0, 1.0), (0, 2, 1.0), (2, 2, 1.0)],
        };
        assert!(!system.solves(&mut kkt));
        let zero = System {
            sizes: vec![2, 3],
            entries: vec![],
        };
        assert!(!zero.solves(&mut kkt));
        // not singular, but block elimination meets an exact zero pivot: the caller falls back
        let system = System {
            sizes: vec![1, 1],
            entries: vec![(0, 1, 1.0), (1, 0, 1.0)],
        };
        assert!(dense_solve(2, &system.dense(), &[1.0, 2.0]).is_some());
        assert!(!system.solves(&mut kkt));
        // a chain link row with both nodes fixed: a zero row and column
        let mut rng = Rng::new(8);
        let mut chain = random_chain(&mut rng, 2, 6, &[2, 3], 0.0, 0.0);
        chain.active[2] = true;
        let system = chain.system();
        assert!(!system.solves(&mut kkt));
    }

    #[test]
    fn non_finite_entries_are_refused() {
        // every entry of the pattern in turn
        let system = System {
            sizes: vec![2, 3, 1],
            entries: vec![],
        };
        let starts = system.starts();
        let mut kkt = BlockKkt::new();
        let mut positions = 0;
        for i in 0..3 {
            for r in starts[i]..starts[i + 1] {
                for c in starts[i.saturating_sub(1)]..starts[(i + 2).min(3)] {
                    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                        let mut entries: Vec<_> = (0..6).map(|k| (k, k, 10.0)).collect();
                        entries.push((r, c, bad));
                        let system = System {
                            sizes: system.sizes.clone(),
                            entries,
                        };
                        assert!(!system.solves(&mut kkt), "({r}, {c}) = {bad} accepted");
                    }
                    positions += 1;
                }
            }
        }
        assert_eq!(positions, 2 * 5 + 3 * 6 + 4);
        // overflow in the elimination
        let system = System {
            sizes: vec![2],
            entries: vec![(0, 0, 1.0), (0, 1, 1e308), (1, 0, -1.0), (1, 1, 1e308)],
        };
        assert!(!system.solves(&mut kkt));
    }

    #[test]
    fn guard_trips_on_a_tiny_schur_complement() {
        // [[eps, 1], [1, 0]] in blocks of 1: S_0 = eps carries 1 / eps ~ 1e12 to the next block
        let system = System {
            sizes: vec![1, 1],
            entries: vec![(0, 0, 1.3e-12), (0, 1, 1.0), (1, 0, 1.0)],
        };
        let mut kkt = BlockKkt::new();
        assert!(!system.solves(&mut kkt));
        // what the guard prevents: x_0 = b_1 computed as b_0 / eps - (b_0 - b_1 eps) / eps
        let b = [0.7, 0.3];
        let reference = dense_solve(2, &system.dense(), &b).unwrap();
        assert!((reference[0] - 0.3).abs() < 1e-15);
        let mut x = b;
        assert!(system.solve_with(&mut kkt, &mut x, f64::INFINITY, true));
        assert!(relative_difference(&x, &reference) > 1e-6);
        // a larger system: blocks of 2 with one tiny direction
        let system = System {
            sizes: vec![2, 2],
            entries: vec![(0, 0, 1.0), (1, 1, 1e-12), (1, 3, 1.0), (3, 1, 1.0), (2, 2, 1.0)],
        };
        assert!(!system.solves(&mut kkt));
    }

    #[test]
    fn guard_trips_on_a_proximal_block() {
        // a free node after an inactive link, before an active one, without contacts: along the
        // next link only the proximal term holds it in its block, and the next block's row fixes it
        let mut rng = Rng::new(11);
        let mut chain = random_chain(&mut rng, 2, 8, &[], 0.0, 0.0);
        chain.active[2] = false;
        let system = chain.system();
        let n = system.order();
        let mut kkt = BlockKkt::new();
        assert!(!system.solves(&mut kkt));
        // the dense LU solves it (as the banded one does, its pivots taken from any row)
        let b: Vec<f64> = (0..n).map(|_| rng.uniform()).collect();
        let a = system.dense();
        let reference = dense_solve(n, &a, &b).unwrap();
        assert!(residual(n, &a, &reference, &b) < 1e-12);
        // block elimination without the guard loses digits
        let mut x = b.clone();
        assert!(system.solve_with(&mut kkt, &mut x, f64::INFINITY, true));
        assert!(relative_difference(&x, &reference) > 1e-10);
    }

    #[test]
    fn one_object_for_many_systems() {
        let mut rng = Rng::new(12);
        let mut kkt = BlockKkt::new();
        let big = random_blocks(&mut rng, 200, 6, Kind::Indefinite);
        check(&mut kkt, &big, &mut rng, 1e-12);
        let capacities = |kkt: &BlockKkt| {
            [
                (kkt.upper.as_ptr() as usize, kkt.upper.capacity()),
                (kkt.diagonal[0].as_ptr() as usize, kkt.diagonal[0].capacity()),
                (kkt.diagonal[1].as_ptr() as usize, kkt.diagonal[1].capacity()),
                (kkt.lower[0].as_ptr() as usize, kkt.lower[0].capacity()),
                (kkt.lower[1].as_ptr() as usize, kkt.lower[1].capacity()),
                (kkt.coupling.as_ptr() as usize, kkt.coupling.capacity()),
                (kkt.pivots.as_ptr() as usize, kkt.pivots.capacity()),
            ]
        };
        let allocated = capacities(&kkt);
        for d in [2, 3] {
            let chain = random_chain(&mut rng, d, 30, &[], 0.2, 0.5);
            check(&mut kkt, &chain.system(), &mut rng, 1e-10);
        }
        check(
            &mut kkt,
            &random_blocks(&mut rng, 3, 6, Kind::Dominant),
            &mut rng,
            1e-12,
        );
        check(
            &mut kkt,
            &System {
                sizes: vec![],
                entries: vec![],
            },
            &mut rng,
            1e-12,
        );
        check(
            &mut kkt,
            &random_blocks(&mut rng, 50, 2, Kind::Indefinite),
            &mut rng,
            1e-12,
        );
        // a failed factor, then the big system again
        let zero = System {
            sizes: vec![3, 3],
            entries: vec![],
        };
        assert!(!zero.solves(&mut kkt));
        check(&mut kkt, &big, &mut rng, 1e-12);
        assert!(capacities(&kkt) == allocated, "storage reallocated");
        // the same structure with other entries
        let mut other = random_blocks(&mut Rng::new(12), 200, 6, Kind::Indefinite);
        assert_eq!(other.sizes, big.sizes);
        for entry in &mut other.entries {
            entry.2 *= 1.0 + 0.5 * rng.uniform();
        }
        check(&mut kkt, &other, &mut rng, 1e-12);
        assert!(capacities(&kkt) == allocated, "storage reallocated");
    }

    #[test]
    fn size_specialized_kernels_match_the_plain_loops_exactly() {
        let mut rng = Rng::new(16);
        let mut systems = Vec::new();
        for kind in [Kind::Dominant, Kind::Indefinite, Kind::General] {
            systems.push(random_blocks(&mut rng, 100, 10, kind));
        }
        for d in [2, 3] {
            systems.push(random_chain(&mut rng, d, 60, &[20], 0.2, 0.5).system());
        }
        // blocks of size 9 and 10 take the plain loops on both sides
        assert!(systems[0].sizes.iter().any(|&s| s > 8));
        let (mut special, mut plain) = (BlockKkt::new(), BlockKkt::new());
        for system in &systems {
            let n = system.order();
            let b: Vec<f64> = (0..n).map(|_| rng.uniform()).collect();
            let (mut x, mut y) = (b.clone(), b.clone());
            assert!(system.solve_with(&mut special, &mut x, f64::INFINITY, true));
            assert!(system.solve_with(&mut plain, &mut y, f64::INFINITY, false));
            let same =
                |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(a, b)| a.to_bits() == b.to_bits() || a == b);
            assert!(same(&special.upper, &plain.upper), "carried multipliers differ");
            assert!(same(&x, &y), "solutions differ");
            let r = residual(n, &system.dense(), &x, &b);
            assert!(r < 1e-12, "residual {r:e}");
        }
    }

    #[test]
    #[cfg(debug_assertions)]
    #[should_panic(expected = "outside blocks i-1 and i")]
    fn entries_between_distant_blocks_panic_in_debug_builds() {
        let system = System {
            sizes: vec![1, 1, 1],
            entries: vec![(0, 0, 1.0), (1, 1, 1.0), (2, 2, 1.0), (0, 2, 1.0)],
        };
        system.solves(&mut BlockKkt::new());
    }

    #[test]
    #[cfg(not(debug_assertions))]
    fn entries_between_distant_blocks_are_refused_in_release_builds() {
        let mut kkt = BlockKkt::new();
        let mut system = System {
            sizes: vec![1, 1, 1],
            entries: vec![(0, 0, 1.0), (1, 1, 1.0), (2, 2, 1.0), (0, 2, 1.0)],
        };
        assert!(!system.solves(&mut kkt));
        // and the next solve forgets it
        system.entries.pop();
        assert!(system.solves(&mut kkt));
    }

    /// The 2-D chain of the timing: node 0 fixed, every link active, one contact at every other
    /// node (the last node free, so the rows are independent): blocks of size 0, then 4, 4, ...
    fn timing_chain(nodes: usize) -> Chain {
        let mut rng = Rng::new(13);
        let mut free = vec![true; nodes];
        free[0] = false;
        let contacts = (0..nodes)
            .map(|i| {
                if i == 0 {
                    vec![]
                } else {
                    let angle = rng.between(-0.3, 0.3);
                    vec![[angle.sin(), angle.cos(), 0.0]]
                }
            })
            .collect();
        let q = (0..nodes - 1)
            .map(|_| {
                let angle = rng.between(-1.0, 1.0);
                [angle.cos(), angle.sin(), 0.0]
            })
            .collect();
        Chain {
            d: 2,
            q,
            mu: (0..nodes - 1).map(|_| rng.between(0.5, 2.0)).collect(),
            length: vec![1.0; nodes - 1],
            active: vec![true; nodes - 1],
            free,
            contacts,
        }
    }

    #[test]
    fn timing_chain_is_solved() {
        let chain = timing_chain(50);
        let system = chain.system();
        assert!(system.sizes[1..].iter().all(|&s| s == 4));
        check(&mut BlockKkt::new(), &system, &mut Rng::new(14), 1e-10);
    }

    /// `cargo test --release -- --ignored --nocapture timing`
    #[test]
    #[ignore]
    fn timing_million_node_chain() {
        use std::time::Instant;
        let nodes = 1_000_000;
        let chain = timing_chain(nodes);
        let layout = chain.layout();
        let n: usize = layout.sizes.iter().sum();
        let mut rng = Rng::new(15);
        let b: Vec<f64> = (0..n).map(|_| rng.uniform()).collect();
        let system = chain.system();
        let mut kkt = BlockKkt::new();
        for round in 0..3 {
            let mut x = b.clone();
            let t0 = Instant::now();
            assert!(system.solve(&mut kkt, &mut x));
            let t1 = Instant::now();
            // the residual, from the entries again
            let mut r = b.clone();
            let mut row_norm = vec![0.0; n];
            chain.entries(&layout, &mut |i, j, v| {
                r[i] -= v * x[j];
                row_norm[i] += v.abs();
            });
            let relative = norm_inf(&r) / (norm_inf(&row_norm) * norm_inf(&x) + norm_inf(&b));
            let ms = (t1 - t0).as_secs_f64() * 1e3;
            println!(
                "round {round}: n = {n}: assembly, factor and solve {ms:.1} ms, residual {relative:.1e}"
            );
            assert!(relative < 1e-12);
        }
    }
}
