//! Linear algebra for the chain's Newton systems, and the seam where a net's sparse ones
//! ([`crate::sparse`]) take their place: the traits [`NewtonMatrix`] and [`Factorization`], and
//! [`NewtonSystem`], a chain's or a net's Newton matrix chosen once per network.
//!
//! The condensed Newton matrix of a chain couples each free node only with its neighbours, so with
//! the unknowns of a node kept together it is symmetric block tridiagonal ([`BlockTridiagonal`]);
//! [`BlockCholesky`] factors it (plus a shift of the identity, for the inertia correction) in
//! O(n) and reports the first block whose Schur complement is not positive definite. The
//! active-set polish and the checks solve general banded systems instead (saddle points, with
//! zeros on the diagonal), narrow once ordered node by node: [`BandedLu`] factors those by LU with
//! partial pivoting in LAPACK's band storage, as `dgbtrf`/`dgbtrs` do.
//!
//! Everything works on flat `Vec<f64>` storage reused across calls; the block size is a const
//! generic in the kernels so the 1x1, 2x2 and 3x3 loops unroll completely.

// Index loops mirror the formulas (blocks, rows, columns) and read better than iterator chains.
#![allow(clippy::needless_range_loop)]

use crate::problem::Network;
use crate::sparse::{SparseCholesky, SparseMatrix};

/// A symmetric block-tridiagonal matrix over `n` blocks of size `d` x `d` (d = 1, 2 or 3):
/// diagonal blocks D_f and coupling blocks B_f = A[block f, block f+1] (so
/// A[block f+1, block f] = B_f^T).
///
/// Blocks are stored row-major: `diagonal[f*d*d + a*d + b] = D_f[a][b]`;
/// `coupling[f*d*d + a*d + b] = B_f[a][b]`. The diagonal blocks must be symmetric: `multiply` and
/// `to_dense` use them whole, [`BlockCholesky::factor`] reads their lower triangles.
#[derive(Clone, Debug)]
pub struct BlockTridiagonal {
    /// The block size (the unknowns per node): 1, 2 or 3.
    pub d: usize,
    /// The number of blocks (free nodes).
    pub n: usize,
    /// The n diagonal blocks D_f, each d*d row-major.
    pub diagonal: Vec<f64>,
    /// The n - 1 coupling blocks B_f = A[block f, block f+1], each d*d row-major.
    pub coupling: Vec<f64>,
}

impl BlockTridiagonal {
    /// The zero matrix with `n` blocks of size `d` x `d`; the coupling has max(n, 1) - 1 blocks.
    pub fn new(n: usize, d: usize) -> Self {
        assert!((1..=3).contains(&d), "block size {d} is not 1, 2 or 3");
        Self {
            d,
            n,
            diagonal: vec![0.0; n * d * d],
            coupling: vec![0.0; n.saturating_sub(1) * d * d],
        }
    }

    /// Zeroes every entry, keeping the sizes (to assemble the next Newton matrix in place).
    pub fn clear(&mut self) {
        self.diagonal.fill(0.0);
        self.coupling.fill(0.0);
    }

    /// The matrix's order, n * d.
    pub fn size(&self) -> usize {
        self.n * self.d
    }

    /// The largest |A[i][i]| (0.0 for an empty matrix; NaN if any diagonal entry is NaN): the
    /// scale the inertia correction sizes its first shift by.
    pub fn max_abs_diagonal(&self) -> f64 {
        let d = self.d;
        let mut largest = 0.0f64;
        for block in self.diagonal.chunks_exact(d * d) {
            for a in 0..d {
                let value = block[a * d + a];
                if value.is_nan() {
                    return f64::NAN;
                }
                largest = largest.max(value.abs());
            }
        }
        largest
    }

    /// Whether every stored entry is finite (a NaN or infinity would only surface later as a
    /// failed factorization at a misleading block).
    pub fn is_finite(&self) -> bool {
        self.diagonal
            .iter()
            .chain(&self.coupling)
            .all(|value| value.is_finite())
    }

    /// `out = A x` with the full symmetric matrix, in O(n).
    pub fn multiply(&self, x: &[f64], out: &mut [f64]) {
        self.check_storage();
        assert_eq!(x.len(), self.size(), "x has the wrong length");
        assert_eq!(out.len(), self.size(), "out has the wrong length");
        match self.d {
            1 => multiply_blocks::<1>(&self.diagonal, &self.coupling, x, out),
            2 => multiply_blocks::<2>(&self.diagonal, &self.coupling, x, out),
            3 => multiply_blocks::<3>(&self.diagonal, &self.coupling, x, out),
            d => panic!("block size {d} is not 1, 2 or 3"),
        }
    }

    /// The dense matrix, row-major size x size (for tests and small problems only).
    pub fn to_dense(&self) -> Vec<f64> {
        self.check_storage();
        let (d, size) = (self.d, self.size());
        let mut dense = vec![0.0; size * size];
        for f in 0..self.n {
            for a in 0..d {
                for b in 0..d {
                    dense[(f * d + a) * size + f * d + b] = self.diagonal[f * d * d + a * d + b];
                    if f + 1 < self.n {
                        let value = self.coupling[f * d * d + a * d + b];
                        dense[(f * d + a) * size + (f + 1) * d + b] = value;
                        dense[((f + 1) * d + b) * size + f * d + a] = value;
                    }
                }
            }
        }
        dense
    }

    /// The public fields can be set by hand: check they agree before indexing by them.
    fn check_storage(&self) {
        let block = self.d * self.d;
        assert_eq!(
            self.diagonal.len(),
            self.n * block,
            "diagonal holds the wrong number of entries"
        );
        assert_eq!(
            self.coupling.len(),
            self.n.saturating_sub(1) * block,
            "coupling holds the wrong number of entries"
        );
    }
}

/// `out = A x` for blocks of size `D`: out_f = D_f x_f + B_f x_{f+1} + B_{f-1}^T x_{f-1}.
fn multiply_blocks<const D: usize>(diagonal: &[f64], coupling: &[f64], x: &[f64], out: &mut [f64]) {
    let n = out.len() / D;
    for f in 0..n {
        let block = &diagonal[f * D * D..][..D * D];
        let xf = &x[f * D..][..D];
        let mut sum = [0.0; D];
        for a in 0..D {
            for b in 0..D {
                sum[a] += block[a * D + b] * xf[b];
            }
        }
        if f + 1 < n {
            let next = &coupling[f * D * D..][..D * D];
            let x_next = &x[(f + 1) * D..][..D];
            for a in 0..D {
                for b in 0..D {
                    sum[a] += next[a * D + b] * x_next[b];
                }
            }
        }
        if f > 0 {
            let previous = &coupling[(f - 1) * D * D..][..D * D];
            let x_previous = &x[(f - 1) * D..][..D];
            for a in 0..D {
                for k in 0..D {
                    sum[a] += previous[k * D + a] * x_previous[k];
                }
            }
        }
        out[f * D..][..D].copy_from_slice(&sum);
    }
}

/// The Cholesky factors L L^T of (A + shift I) for a [`BlockTridiagonal`] A, block by block:
/// S_0 = D_0 + shift I, L_f = chol(S_f), C_f = L_f^{-1} B_f,
/// S_{f+1} = D_{f+1} + shift I - C_f^T C_f.
///
/// One object is meant to be reused across the many factorizations of a solve: `factor` grows
/// its storage only when a larger matrix comes, and never allocates otherwise.
#[derive(Clone, Debug, Default)]
pub struct BlockCholesky {
    /// The block size of the last factorization.
    d: usize,
    /// The number of blocks of the last factorization.
    n: usize,
    /// Each L_f's lower triangle packed by rows (d(d+1)/2 entries a block), with the reciprocal
    /// 1 / L_f[a][a] in place of each diagonal entry so the solve multiplies instead of divides.
    lower: Vec<f64>,
    /// The blocks C_f = L_f^{-1} B_f, each d*d row-major (n - 1 of them).
    coupling: Vec<f64>,
    /// Whether the last `factor` succeeded (`solve` needs it to).
    factored: bool,
}

impl BlockCholesky {
    /// An empty factorization; `factor` sizes it.
    pub fn new() -> Self {
        Self::default()
    }

    /// Factors A + shift * I. `Ok(())` if it is positive definite; `Err(f)` with the first block
    /// f whose Schur complement S_f is not, which is what the inertia correction needs. A pivot
    /// fails when `!(pivot > 0.0)`, so a NaN fails too. Reads the lower triangles of the D_f.
    pub fn factor(&mut self, a: &BlockTridiagonal, shift: f64) -> Result<(), usize> {
        a.check_storage();
        let (n, d) = (a.n, a.d);
        grow(&mut self.lower, n * packed_size(d));
        grow(&mut self.coupling, n.saturating_sub(1) * d * d);
        self.n = n;
        self.d = d;
        let lower = &mut self.lower[..n * packed_size(d)];
        let coupling = &mut self.coupling[..n.saturating_sub(1) * d * d];
        let result = match d {
            1 => factor_blocks::<1>(&a.diagonal, &a.coupling, shift, lower, coupling),
            2 => factor_blocks::<2>(&a.diagonal, &a.coupling, shift, lower, coupling),
            3 => factor_blocks::<3>(&a.diagonal, &a.coupling, shift, lower, coupling),
            d => panic!("block size {d} is not 1, 2 or 3"),
        };
        self.factored = result.is_ok();
        result
    }

    /// Solves (A + shift I) x = rhs in place (rhs.len() == n*d), after a successful `factor`:
    /// forward y_f = L_f^{-1}(b_f - C_{f-1}^T y_{f-1}), backward x_f = L_f^{-T}(y_f - C_f x_{f+1}).
    pub fn solve(&self, rhs: &mut [f64]) {
        assert!(self.factored, "solve needs a successful factor first");
        assert_eq!(rhs.len(), self.n * self.d, "rhs has the wrong length");
        let lower = &self.lower[..self.n * packed_size(self.d)];
        let coupling = &self.coupling[..self.n.saturating_sub(1) * self.d * self.d];
        match self.d {
            1 => solve_blocks::<1>(lower, coupling, rhs),
            2 => solve_blocks::<2>(lower, coupling, rhs),
            3 => solve_blocks::<3>(lower, coupling, rhs),
            d => unreachable!("block size {d} was factored"),
        }
    }
}

/// The entries of a packed lower triangle of order d.
fn packed_size(d: usize) -> usize {
    d * (d + 1) / 2
}

/// Lengthens `storage` to `len` if it is shorter (it never shrinks, so reuse does not allocate).
fn grow(storage: &mut Vec<f64>, len: usize) {
    if storage.len() < len {
        storage.resize(len, 0.0);
    }
}

/// The block Cholesky recurrence for blocks of size `D` (see [`BlockCholesky`]).
fn factor_blocks<const D: usize>(
    diagonal: &[f64],
    coupling: &[f64],
    shift: f64,
    lower: &mut [f64],
    factor_coupling: &mut [f64],
) -> Result<(), usize> {
    let n = diagonal.len() / (D * D);
    let packed = packed_size(D);
    // C_{f-1}; zero before the first block, so S_0 = D_0 + shift I exactly.
    let mut previous = [[0.0; D]; D];
    for f in 0..n {
        // The Schur complement S_f = D_f + shift I - C_{f-1}^T C_{f-1}, lower triangle.
        let block = &diagonal[f * D * D..][..D * D];
        let mut schur = [[0.0; D]; D];
        for a in 0..D {
            for b in 0..=a {
                let mut value = block[a * D + b];
                if a == b {
                    value += shift;
                }
                for k in 0..D {
                    value -= previous[k][a] * previous[k][b];
                }
                schur[a][b] = value;
            }
        }

        // L_f = chol(S_f), column by column, keeping the reciprocals of its diagonal.
        let mut l = [[0.0; D]; D];
        let mut reciprocal = [0.0; D];
        for j in 0..D {
            let mut pivot = schur[j][j];
            for k in 0..j {
                pivot -= l[j][k] * l[j][k];
            }
            // (written so a NaN pivot fails too)
            let root = if pivot > 0.0 { pivot.sqrt() } else { return Err(f) };
            reciprocal[j] = 1.0 / root;
            for i in j + 1..D {
                let mut value = schur[i][j];
                for k in 0..j {
                    value -= l[i][k] * l[j][k];
                }
                l[i][j] = value * reciprocal[j];
            }
        }
        let packed_block = &mut lower[f * packed..][..packed];
        for a in 0..D {
            let row = packed_size(a);
            packed_block[row..row + a].copy_from_slice(&l[a][..a]);
            packed_block[row + a] = reciprocal[a];
        }

        // C_f = L_f^{-1} B_f by forward substitution, one column of B_f at a time.
        if f + 1 < n {
            let b_block = &coupling[f * D * D..][..D * D];
            let mut c = [[0.0; D]; D];
            for column in 0..D {
                for a in 0..D {
                    let mut value = b_block[a * D + column];
                    for k in 0..a {
                        value -= l[a][k] * c[k][column];
                    }
                    c[a][column] = value * reciprocal[a];
                }
            }
            let c_block = &mut factor_coupling[f * D * D..][..D * D];
            for a in 0..D {
                c_block[a * D..][..D].copy_from_slice(&c[a]);
            }
            previous = c;
        }
    }
    Ok(())
}

/// The two block substitutions for blocks of size `D` (see [`BlockCholesky::solve`]).
fn solve_blocks<const D: usize>(lower: &[f64], coupling: &[f64], rhs: &mut [f64]) {
    let n = rhs.len() / D;
    let packed = packed_size(D);

    // Forward: y_f = L_f^{-1} (b_f - C_{f-1}^T y_{f-1}).
    let mut previous = [0.0; D];
    for f in 0..n {
        let l = &lower[f * packed..][..packed];
        let mut y: [f64; D] = rhs[f * D..][..D].try_into().expect("a block of D entries");
        if f > 0 {
            let c = &coupling[(f - 1) * D * D..][..D * D];
            for a in 0..D {
                for k in 0..D {
                    y[a] -= c[k * D + a] * previous[k];
                }
            }
        }
        for a in 0..D {
            let row = packed_size(a);
            let mut value = y[a];
            for k in 0..a {
                value -= l[row + k] * y[k];
            }
            y[a] = value * l[row + a];
        }
        rhs[f * D..][..D].copy_from_slice(&y);
        previous = y;
    }

    // Backward: x_f = L_f^{-T} (y_f - C_f x_{f+1}).
    let mut next = [0.0; D];
    for f in (0..n).rev() {
        let l = &lower[f * packed..][..packed];
        let mut x: [f64; D] = rhs[f * D..][..D].try_into().expect("a block of D entries");
        if f + 1 < n {
            let c = &coupling[f * D * D..][..D * D];
            for a in 0..D {
                for k in 0..D {
                    x[a] -= c[a * D + k] * next[k];
                }
            }
        }
        for a in (0..D).rev() {
            let mut value = x[a];
            for k in a + 1..D {
                value -= l[packed_size(k) + a] * x[k];
            }
            x[a] = value * l[packed_size(a) + a];
        }
        rhs[f * D..][..D].copy_from_slice(&x);
        next = x;
    }
}

/// A general square banded matrix with `lower` sub-diagonals and `upper` super-diagonals,
/// factored by LU with partial (row) pivoting as LAPACK's `dgbtrf` does and solved as `dgbtrs`
/// does: for saddle-point systems, whose zeros on the diagonal need the pivoting.
///
/// The band is stored by columns as in LAPACK, with `lower` extra rows on top of each column for
/// the fill-in of pivoting: A[i][j] lives at `j * height + lower + upper + i - j`, where
/// `height = 2 * lower + upper + 1`.
#[derive(Clone, Debug)]
pub struct BandedLu {
    /// The matrix's order.
    n: usize,
    /// The sub-diagonals of A (and of L).
    lower: usize,
    /// The super-diagonals of A (U has `lower + upper`).
    upper: usize,
    /// The stored entries a column: 2 * lower + upper + 1.
    height: usize,
    /// The band, column by column; after `factor`, U above the diagonal, the multipliers of L
    /// below it and 1 / U[j][j] on it (so the solve multiplies instead of divides).
    band: Vec<f64>,
    /// The row swapped with row j at step j of the elimination.
    pivots: Vec<usize>,
    /// Whether the last `factor` succeeded (`solve` needs it to).
    factored: bool,
}

impl BandedLu {
    /// The zero n x n matrix with `lower` sub-diagonals and `upper` super-diagonals.
    pub fn new(n: usize, lower: usize, upper: usize) -> Self {
        let height = 2 * lower + upper + 1;
        Self {
            n,
            lower,
            upper,
            height,
            band: vec![0.0; n * height],
            pivots: vec![0; n],
            factored: false,
        }
    }

    /// The zero n x n matrix with this band, in the storage already allocated where it is large
    /// enough (fresh pages cost a page fault each: at 10^6 nodes as much as the factorization).
    pub fn reset(&mut self, n: usize, lower: usize, upper: usize) {
        let height = 2 * lower + upper + 1;
        self.n = n;
        self.lower = lower;
        self.upper = upper;
        self.height = height;
        self.band.clear();
        self.band.resize(n * height, 0.0);
        self.pivots.clear();
        self.pivots.resize(n, 0);
        self.factored = false;
    }

    /// Zeroes the matrix, keeping its size and band (to assemble the next system in place).
    pub fn clear(&mut self) {
        self.band.fill(0.0);
        self.factored = false;
    }

    /// A[row][col] += value (duplicates sum). The entry must lie inside the band:
    /// col <= row + upper and row <= col + lower (checked in debug builds).
    pub fn add(&mut self, row: usize, col: usize, value: f64) {
        debug_assert!(
            row < self.n && col < self.n,
            "entry ({row}, {col}) outside a matrix of order {}",
            self.n
        );
        debug_assert!(
            col <= row + self.upper && row <= col + self.lower,
            "entry ({row}, {col}) outside the band ({} below, {} above the diagonal)",
            self.lower,
            self.upper
        );
        self.band[col * self.height + self.lower + self.upper + row - col] += value;
    }

    /// The matrix's order.
    pub fn size(&self) -> usize {
        self.n
    }

    /// Factors the matrix in place (it is overwritten: `clear` and assemble again before the next
    /// factor). `false` if a pivot column is exactly zero (the matrix is singular), an entry is not
    /// finite (on entry or after the updates), or a pivot is so tiny (subnormal) that its
    /// reciprocal overflows.
    pub fn factor(&mut self) -> bool {
        let (n, kl, ku, height) = (self.n, self.lower, self.upper, self.height);
        // The row of a column's diagonal entry in the storage.
        let kv = kl + ku;
        self.factored = false;
        let band = &mut self.band[..n * height];
        let pivots = &mut self.pivots[..n];
        // The last column the row swaps so far can have filled (LAPACK's JU).
        let mut last_column = 0;
        let mut finite = true;
        for j in 0..n {
            // The sub-diagonal entries of column j (fewer at the bottom of the matrix).
            let below = kl.min(n - 1 - j);
            let diagonal = j * height + kv;

            // The pivot: the entry of largest magnitude in column j, on or below the diagonal.
            let mut offset = 0;
            let mut largest = 0.0;
            for (r, value) in band[diagonal..=diagonal + below].iter().enumerate() {
                finite &= value.is_finite();
                if value.abs() > largest {
                    largest = value.abs();
                    offset = r;
                }
            }
            if !finite || largest == 0.0 {
                return false;
            }
            pivots[j] = j + offset;
            last_column = last_column.max((j + ku + offset).min(n - 1));

            // Swap rows j and j + offset across the columns they can be non-zero in.
            if offset != 0 {
                for c in j..=last_column {
                    band.swap(c * height + kv + j - c, c * height + kv + j + offset - c);
                }
            }

            // The multipliers l = column j below the diagonal / pivot (at most 1 in magnitude, so
            // finite once the reciprocal is: a subnormal pivot's is not).
            let reciprocal = 1.0 / band[diagonal];
            if !reciprocal.is_finite() {
                return false;
            }
            band[diagonal] = reciprocal;
            let (done, rest) = band.split_at_mut((j + 1) * height);
            let multipliers = &mut done[diagonal + 1..][..below];
            for value in multipliers.iter_mut() {
                *value *= reciprocal;
            }
            let multipliers = &*multipliers;

            // The rank-1 update of the trailing columns: A[j+1.., c] -= l * U[j][c].
            for c in j + 1..=last_column {
                let start = (c - j - 1) * height + kv + j - c;
                let column = &mut rest[start..][..=below];
                let u = column[0];
                finite &= u.is_finite();
                if u != 0.0 {
                    for (value, l) in column[1..].iter_mut().zip(multipliers) {
                        *value -= l * u;
                    }
                }
            }
        }
        if !finite {
            return false;
        }
        self.factored = true;
        true
    }

    /// Solves A x = rhs in place after a successful `factor`: the row swaps and L forward, then U
    /// backward, column by column as `dgbtrs` does.
    pub fn solve(&self, rhs: &mut [f64]) {
        assert!(self.factored, "solve needs a successful factor first");
        let (n, height, kv) = (self.n, self.height, self.lower + self.upper);
        assert_eq!(rhs.len(), n, "rhs has the wrong length");
        let band = &self.band[..n * height];

        // L y = P b.
        if self.lower > 0 {
            for j in 0..n.saturating_sub(1) {
                let below = self.lower.min(n - 1 - j);
                let pivot = self.pivots[j];
                if pivot != j {
                    rhs.swap(pivot, j);
                }
                let y = rhs[j];
                if y != 0.0 {
                    let multipliers = &band[j * height + kv + 1..][..below];
                    for (value, l) in rhs[j + 1..][..below].iter_mut().zip(multipliers) {
                        *value -= l * y;
                    }
                }
            }
        }

        // U x = y, by columns; U has kv super-diagonals.
        for j in (0..n).rev() {
            let diagonal = j * height + kv;
            let x = rhs[j] * band[diagonal];
            rhs[j] = x;
            if x != 0.0 {
                let above = j.min(kv);
                let column = &band[diagonal - above..diagonal];
                for (value, u) in rhs[j - above..j].iter_mut().zip(column) {
                    *value -= u * x;
                }
            }
        }
    }
}

/// Where a matrix is assembled entry by entry or block by block (duplicates add up): the polish's
/// KKT matrix goes to [`crate::kkt::Window`] (a chain's, block row by block row), to
/// [`BandedLu`] or to [`crate::sparse::SparseKkt`] (a net's).
pub trait Assemble {
    /// A[row][col] += value.
    fn add(&mut self, row: usize, col: usize, value: f64);

    /// A[row + i][col + k] += value(i, k) for i < rows, k < cols.
    #[inline(always)]
    fn add_block<F: Fn(usize, usize) -> f64>(
        &mut self,
        row: usize,
        col: usize,
        rows: usize,
        cols: usize,
        value: F,
    ) {
        for i in 0..rows {
            for k in 0..cols {
                self.add(row + i, col + k, value(i, k));
            }
        }
    }
}

impl Assemble for BandedLu {
    fn add(&mut self, row: usize, col: usize, value: f64) {
        BandedLu::add(self, row, col, value);
    }
}

/// The bandwidth of the entries assembled (their largest |row - col|).
#[derive(Default)]
pub struct Bandwidth(pub usize);

impl Assemble for Bandwidth {
    fn add(&mut self, row: usize, col: usize, _: f64) {
        self.0 = self.0.max(row.abs_diff(col));
    }
}

/// What the Newton matrix's assembly writes to: d x d blocks at a free node and between two free
/// nodes ([`crate::problem::Network::newton_matrix`]). A chain's matrix is [`BlockTridiagonal`],
/// a net's [`crate::sparse::SparseMatrix`]; [`NewtonSystem`] is either, chosen once per network.
pub trait NewtonMatrix {
    /// The factorization that goes with this kind of matrix.
    type Factors: Factorization<Self>;
    /// Empties the matrix for `n` free nodes of dimension `d`.
    fn reset(&mut self, n: usize, d: usize);
    /// A[f][f] += block (d x d, row by row).
    fn add_node(&mut self, f: usize, block: &[f64]);
    /// A[fa][fb] += block and A[fb][fa] += block^T.
    fn add_pair(&mut self, fa: usize, fb: usize, block: &[f64]);
    /// The largest |entry| of the diagonal blocks.
    fn largest_node_entry(&self) -> f64;
    fn max_abs_diagonal(&self) -> f64;
    fn is_finite(&self) -> bool;
    /// Row by row, for tests on small problems.
    fn to_dense(&self) -> Vec<f64>;
    /// The matrix's order (n d).
    fn size(&self) -> usize;
    /// An empty factorization for this matrix (a sparse one shares the matrix's ordering).
    fn new_factors(&self) -> Self::Factors;
}

/// The Cholesky factors of a [`NewtonMatrix`] plus a shift of its diagonal.
pub trait Factorization<M: NewtonMatrix + ?Sized> {
    /// Factors `matrix + shift I`; false where that is not positive definite.
    fn factor_shifted(&mut self, matrix: &M, shift: f64) -> bool;
    /// Solves `(matrix + shift I) x = rhs` in place after a successful factorization.
    fn solve_in_place(&self, rhs: &mut [f64]);
}

/// A network's Newton matrix: block tridiagonal for a chain (its links join consecutive nodes:
/// [`crate::problem::Network::path`]), sparse for any other network. Chosen once per network, so
/// the iteration and the second-order test are written once for both.
#[derive(Clone, Debug)]
pub enum NewtonSystem {
    Chain(BlockTridiagonal),
    Net(SparseMatrix),
}

/// The factors of a [`NewtonSystem`].
#[derive(Debug)]
pub enum NewtonFactors {
    Chain(BlockCholesky),
    Net(SparseCholesky),
}

impl NewtonSystem {
    /// The zero Newton matrix of `network` (a net's with its ordering and symbolic factorization).
    pub fn for_network(network: &Network) -> Self {
        if network.path {
            NewtonSystem::Chain(BlockTridiagonal::new(network.n_free(), network.dim))
        } else {
            NewtonSystem::Net(SparseMatrix::new(network))
        }
    }
}

impl NewtonMatrix for NewtonSystem {
    type Factors = NewtonFactors;

    fn reset(&mut self, n: usize, d: usize) {
        match self {
            NewtonSystem::Chain(m) => m.reset(n, d),
            NewtonSystem::Net(m) => m.reset(n, d),
        }
    }

    #[inline]
    fn add_node(&mut self, f: usize, block: &[f64]) {
        match self {
            NewtonSystem::Chain(m) => m.add_node(f, block),
            NewtonSystem::Net(m) => m.add_node(f, block),
        }
    }

    #[inline]
    fn add_pair(&mut self, fa: usize, fb: usize, block: &[f64]) {
        match self {
            NewtonSystem::Chain(m) => m.add_pair(fa, fb, block),
            NewtonSystem::Net(m) => m.add_pair(fa, fb, block),
        }
    }

    fn largest_node_entry(&self) -> f64 {
        match self {
            NewtonSystem::Chain(m) => m.largest_node_entry(),
            NewtonSystem::Net(m) => m.largest_node_entry(),
        }
    }

    fn max_abs_diagonal(&self) -> f64 {
        match self {
            NewtonSystem::Chain(m) => NewtonMatrix::max_abs_diagonal(m),
            NewtonSystem::Net(m) => m.max_abs_diagonal(),
        }
    }

    fn is_finite(&self) -> bool {
        match self {
            NewtonSystem::Chain(m) => NewtonMatrix::is_finite(m),
            NewtonSystem::Net(m) => m.is_finite(),
        }
    }

    fn to_dense(&self) -> Vec<f64> {
        match self {
            NewtonSystem::Chain(m) => NewtonMatrix::to_dense(m),
            NewtonSystem::Net(m) => m.to_dense(),
        }
    }

    fn size(&self) -> usize {
        match self {
            NewtonSystem::Chain(m) => m.size(),
            NewtonSystem::Net(m) => m.size(),
        }
    }

    fn new_factors(&self) -> NewtonFactors {
        match self {
            NewtonSystem::Chain(m) => NewtonFactors::Chain(m.new_factors()),
            NewtonSystem::Net(m) => NewtonFactors::Net(m.new_factors()),
        }
    }
}

impl Factorization<NewtonSystem> for NewtonFactors {
    fn factor_shifted(&mut self, matrix: &NewtonSystem, shift: f64) -> bool {
        match (self, matrix) {
            (NewtonFactors::Chain(f), NewtonSystem::Chain(m)) => f.factor_shifted(m, shift),
            (NewtonFactors::Net(f), NewtonSystem::Net(m)) => f.factor_shifted(m, shift),
            _ => panic!("factors made for another kind of matrix"),
        }
    }

    fn solve_in_place(&self, rhs: &mut [f64]) {
        match self {
            NewtonFactors::Chain(f) => f.solve_in_place(rhs),
            NewtonFactors::Net(f) => f.solve_in_place(rhs),
        }
    }
}

impl NewtonMatrix for BlockTridiagonal {
    type Factors = BlockCholesky;

    fn reset(&mut self, n: usize, d: usize) {
        if self.n != n || self.d != d {
            *self = BlockTridiagonal::new(n, d);
        } else {
            self.clear();
        }
    }

    fn add_node(&mut self, f: usize, block: &[f64]) {
        let dd = self.d * self.d;
        for (entry, value) in self.diagonal[f * dd..(f + 1) * dd].iter_mut().zip(block) {
            *entry += value;
        }
    }

    /// Only consecutive free nodes are coupled in a block-tridiagonal matrix.
    fn add_pair(&mut self, fa: usize, fb: usize, block: &[f64]) {
        let d = self.d;
        assert!(
            fa.abs_diff(fb) == 1,
            "free nodes {fa} and {fb} are not consecutive"
        );
        let low = fa.min(fb);
        let coupling = &mut self.coupling[low * d * d..(low + 1) * d * d];
        for i in 0..d {
            for k in 0..d {
                // coupling[low] is A[low][low + 1]: the block itself, or its transpose
                coupling[i * d + k] += if fa < fb {
                    block[i * d + k]
                } else {
                    block[k * d + i]
                };
            }
        }
    }

    fn largest_node_entry(&self) -> f64 {
        self.diagonal.iter().fold(0.0_f64, |a, v| a.max(v.abs()))
    }

    fn max_abs_diagonal(&self) -> f64 {
        BlockTridiagonal::max_abs_diagonal(self)
    }

    fn is_finite(&self) -> bool {
        BlockTridiagonal::is_finite(self)
    }

    fn to_dense(&self) -> Vec<f64> {
        BlockTridiagonal::to_dense(self)
    }

    fn size(&self) -> usize {
        BlockTridiagonal::size(self)
    }

    fn new_factors(&self) -> BlockCholesky {
        BlockCholesky::new()
    }
}

impl Factorization<BlockTridiagonal> for BlockCholesky {
    fn factor_shifted(&mut self, matrix: &BlockTridiagonal, shift: f64) -> bool {
        self.factor(matrix, shift).is_ok()
    }

    fn solve_in_place(&self, rhs: &mut [f64]) {
        self.solve(rhs);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_support::{dense_solve, Rng};

    /// A dense row-major square matrix built alongside the structure under test.
    struct Dense {
        size: usize,
        entries: Vec<f64>,
    }

    impl Dense {
        fn zeros(size: usize) -> Self {
            Dense {
                size,
                entries: vec![0.0; size * size],
            }
        }

        fn at(&self, i: usize, j: usize) -> f64 {
            self.entries[i * self.size + j]
        }

        fn add(&mut self, i: usize, j: usize, value: f64) {
            self.entries[i * self.size + j] += value;
        }

        fn shifted(&self, shift: f64) -> Dense {
            let mut copy = Dense {
                size: self.size,
                entries: self.entries.clone(),
            };
            for i in 0..self.size {
                copy.add(i, i, shift);
            }
            copy
        }

        fn product(&self, x: &[f64]) -> Vec<f64> {
            (0..self.size)
                .map(|i| (0..self.size).map(|j| self.at(i, j) * x[j]).sum())
                .collect()
        }

        fn norm_inf(&self) -> f64 {
            (0..self.size)
                .map(|i| (0..self.size).map(|j| self.at(i, j).abs()).sum())
                .fold(0.0, f64::max)
        }

        /// The relative residual ||A x - b|| / (||A|| ||x|| + ||b||), infinity norms.
        fn relative_residual(&self, x: &[f64], b: &[f64]) -> f64 {
            let ax = self.product(x);
            let residual = ax.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max);
            residual / (self.norm_inf() * norm_inf(x) + norm_inf(b))
        }

        /// Dense Cholesky: the lower factor, or the first row whose pivot is not positive.
        fn cholesky(&self) -> Result<Vec<f64>, usize> {
            let size = self.size;
            let mut l = vec![0.0; size * size];
            for j in 0..size {
                let mut pivot = self.at(j, j);
                for k in 0..j {
                    pivot -= l[j * size + k] * l[j * size + k];
                }
                if pivot.is_nan() || pivot <= 0.0 {
                    return Err(j);
                }
                let root = pivot.sqrt();
                l[j * size + j] = root;
                for i in j + 1..size {
                    let mut value = self.at(i, j);
                    for k in 0..j {
                        value -= l[i * size + k] * l[j * size + k];
                    }
                    l[i * size + j] = value / root;
                }
            }
            Ok(l)
        }

        /// Dense Gaussian elimination with partial pivoting; None if a pivot column is zero.
        fn gauss_solve(&self, b: &[f64]) -> Option<Vec<f64>> {
            dense_solve(self.size, &self.entries, b)
        }

        /// All eigenvalues of the (symmetric) matrix by cyclic Jacobi rotations, ascending.
        fn eigenvalues(&self) -> Vec<f64> {
            let size = self.size;
            let mut a = self.entries.clone();
            for _sweep in 0..100 {
                let off: f64 = (0..size)
                    .flat_map(|i| (0..size).map(move |j| (i, j)))
                    .filter(|(i, j)| i != j)
                    .map(|(i, j)| a[i * size + j].powi(2))
                    .sum();
                let total: f64 = a.iter().map(|v| v * v).sum();
                if off <= 1e-30 * total {
                    break;
                }
                for p in 0..size {
                    for q in p + 1..size {
                        let apq = a[p * size + q];
                        if apq == 0.0 {
                            continue;
                        }
                        let theta = (a[q * size + q] - a[p * size + p]) / (2.0 * apq);
                        let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                        let t = if theta == 0.0 { 1.0 } else { t };
                        let c = 1.0 / (t * t + 1.0).sqrt();
                        let s = t * c;
                        for k in 0..size {
                            let (akp, akq) = (a[k * size + p], a[k * size + q]);
                            a[k * size + p] = c * akp - s * akq;
                            a[k * size + q] = s * akp + c * akq;
                        }
                        for k in 0..size {
                            let (apk, aqk) = (a[p * size + k], a[q * size + k]);
                            a[p * size + k] = c * apk - s * aqk;
                            a[q * size + k] = s * apk + c * aqk;
                        }
                    }
                }
            }
            let mut values: Vec<f64> = (0..size).map(|i| a[i * size + i]).collect();
            values.sort_by(f64::total_cmp);
            values
        }
    }

    fn norm_inf(x: &[f64]) -> f64 {
        x.iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    fn random_vector(rng: &mut Rng, size: usize) -> Vec<f64> {
        (0..size).map(|_| rng.uniform()).collect()
    }

    /// Adds the symmetric 2d x 2d term `g` (row-major) over the unknowns of blocks f and f+1.
    fn add_link_term(matrix: &mut BlockTridiagonal, dense: &mut Dense, f: usize, g: &[f64]) {
        let d = matrix.d;
        let width = 2 * d;
        for r in 0..width {
            for c in 0..width {
                let value = g[r * width + c];
                dense.add(f * d + r, f * d + c, value);
                match (r < d, c < d) {
                    (true, true) => matrix.diagonal[f * d * d + r * d + c] += value,
                    (false, false) => matrix.diagonal[(f + 1) * d * d + (r - d) * d + (c - d)] += value,
                    (true, false) => matrix.coupling[f * d * d + r * d + (c - d)] += value,
                    (false, true) => {} // the transpose of the coupling: implied by symmetry
                }
            }
        }
    }

    /// A random symmetric positive definite block-tridiagonal matrix and its dense twin: per link
    /// a tension-like term w e e^T with e = (g, -g) and a random PSD term M M^T (M of rank 2),
    /// some links left out so some couplings are zero; per node a random PSD block plus 0.05 I.
    fn random_spd(rng: &mut Rng, n: usize, d: usize) -> (BlockTridiagonal, Dense) {
        let mut matrix = BlockTridiagonal::new(n, d);
        let mut dense = Dense::zeros(n * d);
        let width = 2 * d;
        for f in 0..n.saturating_sub(1) {
            if rng.below(5) == 0 {
                continue;
            }
            let weight = 1.0 + rng.uniform();
            let g: Vec<f64> = (0..d).map(|_| rng.uniform()).collect();
            let e: Vec<f64> = g.iter().copied().chain(g.iter().map(|v| -v)).collect();
            let m: Vec<f64> = (0..width * 2).map(|_| rng.uniform()).collect();
            let mut term = vec![0.0; width * width];
            for r in 0..width {
                for c in 0..=r {
                    let value = weight * e[r] * e[c] + m[r * 2] * m[c * 2] + m[r * 2 + 1] * m[c * 2 + 1];
                    term[r * width + c] = value;
                    term[c * width + r] = value; // exactly symmetric, as the blocks must be
                }
            }
            add_link_term(&mut matrix, &mut dense, f, &term);
        }
        for f in 0..n {
            let m: Vec<f64> = (0..d * d).map(|_| rng.uniform()).collect();
            for a in 0..d {
                for b in 0..d {
                    let mut value: f64 = (0..d).map(|k| m[a * d + k] * m[b * d + k]).sum();
                    if a == b {
                        value += 0.05;
                    }
                    matrix.diagonal[f * d * d + a * d + b] += value;
                    dense.add(f * d + a, f * d + b, value);
                }
            }
        }
        (matrix, dense)
    }

    const SIZES: [usize; 3] = [1, 2, 50];

    #[test]
    fn new_clear_size_and_storage() {
        for d in 1..=3 {
            for n in [0, 1, 2, 7] {
                let mut matrix = BlockTridiagonal::new(n, d);
                assert_eq!(matrix.size(), n * d);
                assert_eq!(matrix.diagonal.len(), n * d * d);
                assert_eq!(matrix.coupling.len(), n.saturating_sub(1) * d * d);
                assert_eq!(matrix.max_abs_diagonal(), 0.0);
                assert!(matrix.is_finite());
                matrix.diagonal.fill(2.0);
                matrix.coupling.fill(-1.0);
                matrix.clear();
                assert!(matrix.diagonal.iter().chain(&matrix.coupling).all(|&v| v == 0.0));
                assert_eq!(matrix.diagonal.len(), n * d * d);
            }
        }
    }

    #[test]
    #[should_panic(expected = "block size")]
    fn block_size_beyond_three_is_refused() {
        let _ = BlockTridiagonal::new(3, 4);
    }

    #[test]
    fn max_abs_diagonal_reads_only_the_diagonal_and_keeps_nan() {
        let mut matrix = BlockTridiagonal::new(3, 2);
        matrix.diagonal[4] = -7.0; // D_1[0][0]
        matrix.diagonal[7] = 3.0; // D_1[1][1]
        matrix.diagonal[5] = 100.0; // D_1[0][1]: off the diagonal
        matrix.coupling[0] = 50.0;
        assert_eq!(matrix.max_abs_diagonal(), 7.0);
        matrix.diagonal[11] = f64::NAN; // D_2[1][1]
        assert!(matrix.max_abs_diagonal().is_nan());
        let mut matrix = BlockTridiagonal::new(3, 2);
        matrix.diagonal[0] = f64::NAN;
        matrix.diagonal[3] = 5.0;
        assert!(matrix.max_abs_diagonal().is_nan());
    }

    #[test]
    fn is_finite_sees_every_stored_entry() {
        for (in_coupling, bad) in [(false, f64::NAN), (true, f64::INFINITY), (true, f64::NAN)] {
            let mut matrix = BlockTridiagonal::new(4, 3);
            if in_coupling {
                matrix.coupling[20] = bad;
            } else {
                matrix.diagonal[35] = bad;
            }
            assert!(!matrix.is_finite());
        }
    }

    #[test]
    fn to_dense_matches_the_assembled_matrix() {
        let mut rng = Rng::new(1);
        for d in 1..=3 {
            for n in SIZES {
                let (matrix, dense) = random_spd(&mut rng, n, d);
                assert!(
                    matrix.to_dense() == dense.entries,
                    "to_dense differs (n {n}, d {d})"
                );
            }
        }
    }

    #[test]
    fn multiply_matches_the_dense_product() {
        let mut rng = Rng::new(2);
        for d in 1..=3 {
            for n in SIZES {
                let (mut matrix, _) = random_spd(&mut rng, n, d);
                // A non-symmetric coupling pattern shows a transposition mix-up.
                for value in matrix.coupling.iter_mut() {
                    *value = rng.uniform();
                }
                let mut dense = Dense::zeros(n * d);
                for f in 0..n {
                    for a in 0..d {
                        for b in 0..d {
                            dense.add(f * d + a, f * d + b, matrix.diagonal[f * d * d + a * d + b]);
                            if f + 1 < n {
                                let value = matrix.coupling[f * d * d + a * d + b];
                                dense.add(f * d + a, (f + 1) * d + b, value);
                                dense.add((f + 1) * d + b, f * d + a, value);
                            }
                        }
                    }
                }
                let x = random_vector(&mut rng, n * d);
                let mut out = vec![f64::NAN; n * d];
                matrix.multiply(&x, &mut out);
                let expected = dense.product(&x);
                for (got, want) in out.iter().zip(&expected) {
                    assert!(
                        (got - want).abs() <= 1e-14 * (1.0 + want.abs()),
                        "{got} vs {want}"
                    );
                }
            }
        }
    }

    /// Factors A + shift I, solves for a random right-hand side and checks the residual against
    /// the dense matrix and the solution against a dense Cholesky solve.
    fn check_solve(
        cholesky: &mut BlockCholesky,
        matrix: &BlockTridiagonal,
        dense: &Dense,
        shift: f64,
        rng: &mut Rng,
    ) {
        let shifted = dense.shifted(shift);
        assert_eq!(cholesky.factor(matrix, shift), Ok(()));
        let b = random_vector(rng, matrix.size());
        let mut x = b.clone();
        cholesky.solve(&mut x);
        let residual = shifted.relative_residual(&x, &b);
        assert!(
            residual < 1e-12,
            "relative residual {residual:e} (n {}, d {})",
            matrix.n,
            matrix.d
        );

        let l = shifted.cholesky().expect("the dense oracle factors it too");
        let size = shifted.size;
        let mut y = b.clone();
        for i in 0..size {
            for k in 0..i {
                y[i] -= l[i * size + k] * y[k];
            }
            y[i] /= l[i * size + i];
        }
        for i in (0..size).rev() {
            for k in i + 1..size {
                y[i] -= l[k * size + i] * y[k];
            }
            y[i] /= l[i * size + i];
        }
        let difference = x.iter().zip(&y).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max);
        assert!(
            difference <= 1e-8 * (1.0 + norm_inf(&y)),
            "solution off by {difference:e}"
        );
    }

    #[test]
    fn block_cholesky_solves_random_spd_systems() {
        let mut rng = Rng::new(3);
        let mut cholesky = BlockCholesky::new();
        for d in 1..=3 {
            for n in SIZES {
                let (matrix, dense) = random_spd(&mut rng, n, d);
                check_solve(&mut cholesky, &matrix, &dense, 0.0, &mut rng);
                check_solve(&mut cholesky, &matrix, &dense, 0.3, &mut rng);
            }
        }
    }

    #[test]
    fn block_cholesky_is_reused_across_sizes() {
        let mut rng = Rng::new(4);
        let mut cholesky = BlockCholesky::new();
        for (n, d) in [(50, 3), (2, 2), (50, 1), (1, 3), (30, 2), (50, 3)] {
            let (matrix, dense) = random_spd(&mut rng, n, d);
            check_solve(&mut cholesky, &matrix, &dense, 0.0, &mut rng);
        }
    }

    #[test]
    fn block_cholesky_of_an_empty_matrix() {
        let mut cholesky = BlockCholesky::new();
        assert_eq!(cholesky.factor(&BlockTridiagonal::new(0, 2), 0.0), Ok(()));
        cholesky.solve(&mut []);
    }

    #[test]
    fn factor_fails_at_the_indefinite_block() {
        let mut rng = Rng::new(5);
        let mut cholesky = BlockCholesky::new();
        for d in 1..=3 {
            for n in SIZES {
                for _ in 0..3 {
                    let (mut matrix, mut dense) = random_spd(&mut rng, n, d);
                    // Make one diagonal entry of block k far too small: the leading blocks stay
                    // positive definite, block k's Schur complement does not.
                    let k = rng.below(n);
                    let a = rng.below(d);
                    let drop = 3.0 * dense.norm_inf();
                    matrix.diagonal[k * d * d + a * d + a] -= drop;
                    dense.add(k * d + a, k * d + a, -drop);
                    let oracle = dense.cholesky().expect_err("the dense oracle fails too");
                    assert_eq!(oracle / d, k);
                    assert_eq!(cholesky.factor(&matrix, 0.0), Err(k));

                    // The lowest eigenvalue decides: a shift just past it factors, just short of
                    // it does not.
                    let lowest = dense.eigenvalues()[0];
                    assert!(lowest < 0.0);
                    let margin = 1e-6 * dense.norm_inf();
                    assert!(cholesky.factor(&matrix, -lowest - margin).is_err());
                    check_solve(&mut cholesky, &matrix, &dense, -lowest + margin, &mut rng);
                    check_solve(&mut cholesky, &matrix, &dense, -lowest + 1.0, &mut rng);
                }
            }
        }
    }

    #[test]
    fn negative_shift_up_to_the_lowest_eigenvalue() {
        let mut rng = Rng::new(6);
        let mut cholesky = BlockCholesky::new();
        for d in 1..=3 {
            for n in SIZES {
                let (matrix, dense) = random_spd(&mut rng, n, d);
                let lowest = dense.eigenvalues()[0];
                assert!(lowest > 0.0);
                check_solve(&mut cholesky, &matrix, &dense, -0.5 * lowest, &mut rng);
                let margin = 1e-6 * dense.norm_inf();
                check_solve(&mut cholesky, &matrix, &dense, -lowest + margin, &mut rng);
                assert!(cholesky.factor(&matrix, -lowest - margin).is_err());
            }
        }
    }

    #[test]
    fn factor_fails_on_nan_and_on_a_zero_matrix() {
        let mut cholesky = BlockCholesky::new();
        let mut matrix = BlockTridiagonal::new(4, 2);
        assert_eq!(cholesky.factor(&matrix, 0.0), Err(0));
        assert_eq!(cholesky.factor(&matrix, 1.0), Ok(()));
        matrix.diagonal[2 * 4 + 3] = f64::NAN; // D_2[1][1]
        assert_eq!(cholesky.factor(&matrix, 1.0), Err(2));
        let mut matrix = BlockTridiagonal::new(4, 2);
        matrix.coupling[4] = f64::NAN; // B_1 poisons S_2
        assert_eq!(cholesky.factor(&matrix, 1.0), Err(2));
    }

    #[test]
    #[should_panic(expected = "successful factor")]
    fn block_solve_after_a_failed_factor_panics() {
        let mut cholesky = BlockCholesky::new();
        let matrix = BlockTridiagonal::new(3, 2);
        assert!(cholesky.factor(&matrix, -1.0).is_err());
        cholesky.solve(&mut [0.0; 6]);
    }

    /// A random banded matrix and its dense twin; `zero_diagonal` leaves every third diagonal
    /// entry empty (A[0][0] among them) so the elimination has to pivot.
    fn random_banded(
        rng: &mut Rng,
        n: usize,
        lower: usize,
        upper: usize,
        zero_diagonal: bool,
    ) -> (BandedLu, Dense) {
        let mut lu = BandedLu::new(n, lower, upper);
        let mut dense = Dense::zeros(n);
        for i in 0..n {
            for j in i.saturating_sub(lower)..(i + upper + 1).min(n) {
                if zero_diagonal && i == j && i % 3 == 0 {
                    continue;
                }
                let value = rng.uniform();
                lu.add(i, j, value);
                dense.add(i, j, value);
            }
        }
        (lu, dense)
    }

    /// Factors, solves for a random right-hand side, and checks the residual and the dense
    /// Gaussian elimination's solution.
    fn check_banded(mut lu: BandedLu, dense: &Dense, rng: &mut Rng) -> BandedLu {
        assert!(lu.factor());
        let b = random_vector(rng, dense.size);
        let mut x = b.clone();
        lu.solve(&mut x);
        let residual = dense.relative_residual(&x, &b);
        assert!(residual < 1e-10, "relative residual {residual:e}");
        let expected = dense.gauss_solve(&b).expect("the dense oracle solves it too");
        let difference = x
            .iter()
            .zip(&expected)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        assert!(
            difference <= 1e-7 * (1.0 + norm_inf(&expected)),
            "solution off by {difference:e}"
        );
        lu
    }

    #[test]
    fn banded_lu_solves_random_banded_systems() {
        let mut rng = Rng::new(7);
        for (lower, upper) in [(0, 0), (1, 1), (2, 3), (3, 1), (4, 4), (0, 2), (5, 0), (8, 8)] {
            for n in [1, 2, 5, 60] {
                // (with a one-sided band or n = 1, a zero on the diagonal would make it singular)
                let zero_diagonal = lower > 0 && upper > 0 && n > 1;
                let (lu, dense) = random_banded(&mut rng, n, lower, upper, zero_diagonal);
                let lu = check_banded(lu, &dense, &mut rng);
                assert_eq!(lu.size(), n);
                if zero_diagonal {
                    assert!((0..n).any(|j| lu.pivots[j] != j), "no row was swapped");
                }
            }
        }
    }

    #[test]
    fn banded_lu_with_a_band_wider_than_the_matrix() {
        let mut rng = Rng::new(8);
        for n in [1, 2, 3] {
            let (lu, dense) = random_banded(&mut rng, n, 5, 4, n > 1);
            check_banded(lu, &dense, &mut rng);
        }
    }

    /// The saddle-point system [[H, J^T], [J, 0]] of a chain of `nodes` nodes in the plane with
    /// one constraint per link, ordered node by node (x_f, y_f, lambda_f) so the band is narrow:
    /// 4 sub- and 4 super-diagonals. H is block tridiagonal and indefinite.
    fn chain_kkt(rng: &mut Rng, nodes: usize) -> (BandedLu, Dense) {
        let size = 3 * nodes - 1;
        let mut lu = BandedLu::new(size, 4, 4);
        let mut dense = Dense::zeros(size);
        let mut add = |i: usize, j: usize, value: f64| {
            lu.add(i, j, value);
            dense.add(i, j, value);
        };
        for f in 0..nodes {
            let (h00, h01, h11) = (rng.uniform(), rng.uniform(), rng.uniform());
            add(3 * f, 3 * f, h00);
            add(3 * f, 3 * f + 1, h01);
            add(3 * f + 1, 3 * f, h01);
            add(3 * f + 1, 3 * f + 1, h11);
            if f + 1 < nodes {
                for (a, b) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    let value = 0.3 * rng.uniform();
                    add(3 * f + a, 3 * (f + 1) + b, value);
                    add(3 * (f + 1) + b, 3 * f + a, value);
                }
                // The link constraint's row lambda_f: gradient (g, -g) over nodes f and f+1.
                let lambda = 3 * f + 2;
                let g = [rng.uniform(), rng.uniform()];
                for a in 0..2 {
                    add(lambda, 3 * f + a, g[a]);
                    add(3 * f + a, lambda, g[a]);
                    add(lambda, 3 * (f + 1) + a, -g[a]);
                    add(3 * (f + 1) + a, lambda, -g[a]);
                }
            }
        }
        (lu, dense)
    }

    #[test]
    fn banded_lu_of_an_empty_matrix() {
        let mut lu = BandedLu::new(0, 2, 2);
        assert_eq!(lu.size(), 0);
        assert!(lu.factor());
        lu.solve(&mut []);
    }

    #[test]
    fn banded_lu_solves_saddle_point_systems() {
        let mut rng = Rng::new(9);
        for nodes in [2, 3, 40] {
            for _ in 0..5 {
                let (lu, dense) = chain_kkt(&mut rng, nodes);
                let lu = check_banded(lu, &dense, &mut rng);
                assert!((0..lu.size()).any(|j| lu.pivots[j] != j), "no row was swapped");
            }
        }
    }

    #[test]
    fn banded_lu_clear_and_refactor() {
        let mut rng = Rng::new(10);
        let (mut lu, _) = random_banded(&mut rng, 30, 2, 2, true);
        assert!(lu.factor());
        lu.clear();
        let mut dense = Dense::zeros(30);
        for i in 0..30usize {
            for j in i.saturating_sub(2)..(i + 3).min(30) {
                let value = rng.uniform();
                // Duplicates sum: add each entry in two parts.
                lu.add(i, j, 0.25 * value);
                lu.add(i, j, 0.75 * value);
                dense.add(i, j, 0.25 * value);
                dense.add(i, j, 0.75 * value);
            }
        }
        check_banded(lu, &dense, &mut rng);
    }

    #[test]
    fn banded_lu_refuses_singular_matrices() {
        // A zero column: column 1 stays zero through the elimination of column 0.
        let mut lu = BandedLu::new(4, 1, 1);
        for (i, j) in [(0, 0), (1, 0), (2, 2), (2, 3), (3, 2), (3, 3)] {
            lu.add(i, j, 1.0 + i as f64);
        }
        assert!(!lu.factor());
        // Exactly dependent rows: [[1, 2], [2, 4]] leaves a zero pivot.
        let mut lu = BandedLu::new(2, 1, 1);
        lu.add(0, 0, 1.0);
        lu.add(0, 1, 2.0);
        lu.add(1, 0, 2.0);
        lu.add(1, 1, 4.0);
        assert!(!lu.factor());
        // The zero matrix.
        assert!(!BandedLu::new(3, 1, 2).factor());
        // A subnormal pivot, whose reciprocal overflows.
        for n in [1, 3] {
            let mut lu = BandedLu::new(n, 1, 1);
            for j in 0..n {
                lu.add(j, j, if j + 1 == n { 1e-310 } else { 1.0 });
            }
            assert!(!lu.factor());
        }
    }

    #[test]
    fn banded_lu_refuses_non_finite_entries() {
        let mut rng = Rng::new(11);
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for (lower, upper) in [(2, 2), (0, 3), (3, 0)] {
                for place in 0..3 {
                    let (mut lu, _) = random_banded(&mut rng, 12, lower, upper, false);
                    // On the diagonal, the last super-diagonal entry or the last sub-diagonal
                    // entry (the ones no later step reads when the band is one-sided).
                    let (i, j) = match place {
                        0 => (11, 11),
                        1 if upper > 0 => (10, 11),
                        2 if lower > 0 => (11, 10),
                        _ => (5, 5),
                    };
                    lu.add(i, j, bad);
                    assert!(!lu.factor(), "{bad} at ({i}, {j}) with band ({lower}, {upper})");
                }
            }
        }
    }

    #[test]
    #[should_panic(expected = "successful factor")]
    fn banded_solve_after_a_failed_factor_panics() {
        let mut lu = BandedLu::new(3, 1, 1);
        assert!(!lu.factor());
        lu.solve(&mut [1.0, 2.0, 3.0]);
    }

    #[test]
    #[cfg(debug_assertions)]
    #[should_panic(expected = "outside the band")]
    fn banded_add_outside_the_band_panics_in_debug() {
        let mut lu = BandedLu::new(10, 2, 1);
        lu.add(2, 4, 1.0);
    }

    #[test]
    #[cfg(debug_assertions)]
    #[should_panic(expected = "outside the band")]
    fn banded_add_below_the_band_panics_in_debug() {
        let mut lu = BandedLu::new(10, 2, 1);
        lu.add(5, 2, 1.0);
    }
}
