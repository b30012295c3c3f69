//! The linear algebra of the iteration, behind two seams: the Newton matrix of the interior-point
//! steps with its factorization ([`NewtonMatrix`], [`Factorization`]) and the solver of the polish's
//! KKT system ([`KktSolver`], reading the system through [`KktRows`]). A chain's and a net's
//! implementations sit side by side; the iteration is written once, generic over them.
//!
//! * [`block`]: a chain's Newton matrix. Its unknowns kept node by node, it couples each free node
//!   only with its neighbours: symmetric block tridiagonal ([`BlockTridiagonal`]), factored by a
//!   block Cholesky ([`BlockCholesky`]) plus a shift of the identity (the inertia correction), in
//!   O(n), reporting the first block whose Schur complement is not positive definite.
//! * [`kkt`] and [`banded`]: a chain's KKT systems (saddle points, with zeros on the diagonal),
//!   narrow once ordered node by node: streamed block elimination ([`BlockKkt`]), and behind it,
//!   where that is not to be trusted, LU with partial pivoting in LAPACK's band storage
//!   ([`BandedLu`], as `dgbtrf`/`dgbtrs` do); [`Fallback`] chains the two.
//! * [`sparse`]: a net's Newton matrix ([`SparseMatrix`]) with its Cholesky or L D L^T factors
//!   (the latter for the polish's condensed system, [`crate::polish::NetPolish`]), and the
//!   regularized L D L^T of its KKT system ([`SparseKkt`]), in minimum-degree orders or, for a
//!   large net's Newton matrix, nested dissection ([`order`]).
//!
//! Everything works on flat `Vec<f64>` storage reused across calls; the block size is a const
//! generic in the kernels so the 1x1, 2x2 and 3x3 loops unroll completely.

pub mod banded;
pub mod block;
pub mod kkt;
pub mod order;
pub mod sparse;
pub mod split;
#[cfg(test)]
mod tests;

pub use banded::{BandedLu, Bandwidth};
pub use block::{BlockCholesky, BlockTridiagonal};
pub use kkt::BlockKkt;
pub use sparse::{blocks_positive_definite, SparseCholesky, SparseKkt, SparseMatrix};

/// The Euclidean norm, as the square root of the sum of the squares in order: correctly rounded
/// operations only (the same on every machine, unlike a libm's `hypot`), and several times as fast.
/// The core works in scaled units (lengths of order one, forces of order the weight), where the
/// squares do not overflow, and a link short enough for them to underflow is on the smooth
/// stand-in below `SMOOTH_RATIO` times its length, which depends on the squared distance anyway.
#[inline(always)]
pub fn norm(v: &[f64]) -> f64 {
    match v.len() {
        1 => v[0].abs(),
        2 => (v[0] * v[0] + v[1] * v[1]).sqrt(),
        _ => (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
    }
}

/// Where a matrix is assembled entry by entry or block by block (duplicates add up): the polish's
/// KKT matrix goes to [`kkt::Window`] (a chain's, block row by block row), to
/// [`BandedLu`] or to [`SparseKkt`] (a net's).
pub trait Assemble {
    /// `A[row][col] += value`.
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

/// What the Newton matrix's assembly writes to: d x d blocks at a free node and between two free
/// nodes ([`crate::problem::Network::newton_matrix`]). A chain's matrix is [`BlockTridiagonal`],
/// a net's [`SparseMatrix`].
pub trait NewtonMatrix {
    /// The factorization that goes with this kind of matrix.
    type Factors: Factorization<Self>;
    /// Empties the matrix for `n` free nodes of dimension `d`.
    fn reset(&mut self, n: usize, d: usize);
    /// `A[f][f] += block` (d x d, row by row).
    fn add_node(&mut self, f: usize, block: &[f64]);
    /// `A[fa][fb] += block` and `A[fb][fa] += block^T`.
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
    /// The most entries in a row or column of a sparse Cholesky factor, which bounds the rounding
    /// of a factorization that completes; None for a block factor, whose lines are at most 2d long.
    fn factor_lines(&self) -> Option<usize> {
        None
    }
}

/// The Cholesky factors of a [`NewtonMatrix`] plus a shift of its diagonal.
pub trait Factorization<M: NewtonMatrix + ?Sized> {
    /// Factors `matrix + shift I`; false where that is not positive definite.
    fn factor_shifted(&mut self, matrix: &M, shift: f64) -> bool;
    /// Solves `(matrix + shift I) x = rhs` in place after a successful factorization.
    fn solve_in_place(&self, rhs: &mut [f64]);
}

/// The polish's KKT system as its solvers read it: square, its unknowns in blocks (a node's), given
/// block row by block row.
pub trait KktRows {
    /// The blocks' sizes, in order (their sum is the matrix's order; a block may be empty).
    fn block_sizes(&self) -> &[usize];
    /// Adds the entries block row `i` brings: those joining blocks i-1 and i (either way round) and
    /// those inside either, for a chain (block tridiagonal); anywhere for a net.
    fn add_block_row<A: Assemble>(&self, i: usize, matrix: &mut A);
    /// The right-hand side, every entry written.
    fn right_hand_side(&self, rhs: &mut [f64]);
}

/// A solver of the polish's KKT system, its storage kept from one system to the next.
pub trait KktSolver: Default {
    /// Solves the system `rows` gives for the right-hand side in `rhs`, in place; false (`rhs` then
    /// holding no solution) if it is singular or the solver does not trust its answer.
    fn solve_rows<R: KktRows>(&mut self, rows: &R, rhs: &mut [f64]) -> bool;
}

/// `First`, and where it refuses a system, `Second` from the right-hand side afresh.
#[derive(Debug, Default)]
pub struct Fallback<First, Second> {
    first: First,
    second: Second,
}

impl<First: KktSolver, Second: KktSolver> KktSolver for Fallback<First, Second> {
    fn solve_rows<R: KktRows>(&mut self, rows: &R, rhs: &mut [f64]) -> bool {
        if self.first.solve_rows(rows, rhs) {
            return true;
        }
        rows.right_hand_side(rhs); // (the first overwrote it)
        self.second.solve_rows(rows, rhs)
    }
}
