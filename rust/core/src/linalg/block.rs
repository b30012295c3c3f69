//! A chain's Newton matrix: symmetric block tridiagonal over its free nodes
//! ([`BlockTridiagonal`]), and its block Cholesky factors plus a shift of the identity
//! ([`BlockCholesky`]).

// Index loops mirror the formulas (blocks, rows, columns) and read better than iterator chains.
#![allow(clippy::needless_range_loop)]

use super::{Factorization, NewtonMatrix};

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

    /// The largest `|A[i][i]|` (0.0 for an empty matrix; NaN if any diagonal entry is NaN): the
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
