//! The block-tridiagonal Cholesky and the banded LU against dense oracles.

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
