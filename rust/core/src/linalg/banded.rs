//! LU with partial pivoting of a general square banded matrix ([`BandedLu`], as LAPACK's
//! `dgbtrf`/`dgbtrs`): the polish's KKT system of a chain, ordered node by node, where the block
//! elimination ([`super::BlockKkt`]) does not trust its pivots.

// Index loops mirror the formulas (blocks, rows, columns) and read better than iterator chains.
#![allow(clippy::needless_range_loop)]

use super::{Assemble, KktRows, KktSolver};

/// A general square banded matrix with `lower` sub-diagonals and `upper` super-diagonals,
/// factored by LU with partial (row) pivoting as LAPACK's `dgbtrf` does and solved as `dgbtrs`
/// does: for saddle-point systems, whose zeros on the diagonal need the pivoting.
///
/// The band is stored by columns as in LAPACK, with `lower` extra rows on top of each column for
/// the fill-in of pivoting: `A[i][j]` lives at `j * height + lower + upper + i - j`, where
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
    pub(super) pivots: Vec<usize>,
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

    /// `A[row][col] += value` (duplicates sum). The entry must lie inside the band:
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

impl Default for BandedLu {
    fn default() -> Self {
        BandedLu::new(0, 0, 0)
    }
}

/// The system's bandwidth first (its largest |row - col|), then the system in a band that wide.
impl KktSolver for BandedLu {
    fn solve_rows<R: KktRows>(&mut self, rows: &R, rhs: &mut [f64]) -> bool {
        let blocks = rows.block_sizes().len();
        let mut bandwidth = Bandwidth::default();
        for i in 0..blocks {
            rows.add_block_row(i, &mut bandwidth);
        }
        self.reset(rhs.len(), bandwidth.0, bandwidth.0);
        for i in 0..blocks {
            rows.add_block_row(i, self);
        }
        if !self.factor() {
            return false;
        }
        self.solve(rhs);
        true
    }
}
