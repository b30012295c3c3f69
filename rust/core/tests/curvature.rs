//! The second-order test's eigen-solvers against a dense cyclic-Jacobi eigen-solver written here.
//!
//! * `lowest_eigenpair` on random symmetric block-tridiagonal matrices (d = 2 and 3, 1 to 30
//!   blocks), its bracket's bottom below the lowest eigenvalue by margins from 1e-6 to 3 times the
//!   spectral radius and its top either just above the lowest eigenvalue or above the whole
//!   spectrum: the eigenvalue to 1e-9 of the spectral radius, the eigenvector to [`VECTOR_ERROR`]
//!   where the gap to the next eigenvalue exceeds 1e-3 of the spectral radius; `None` when the
//!   bottom is not below the spectrum or the eigenvalue is not below the top.
//! * `eigenvalue_floor`: the lowest eigenvalue (or 0) of a 2 x 2 block exactly, a lower bound of it
//!   for 3 x 3 and 6 x 6 blocks.

mod common;

use common::{max_abs, symmetric_eigen, Rng};
use funicular_core::curvature::{eigenvalue_floor, lowest_eigenpair, start_vector, VECTOR_TOL};
use funicular_core::linalg::BlockTridiagonal;

/// How far the returned eigenvector may be from the true one: the search stops once a step changes
/// the vector by at most VECTOR_TOL (1e-7), and it stays at one shift only while each step
/// converges tenfold, so what is left is at most about VECTOR_TOL 0.1 / (1 - 0.1) = 1.1e-8 (the
/// largest seen in these tests: 9.7e-9).
const VECTOR_ERROR: f64 = 0.12 * VECTOR_TOL;

/// A symmetric block-tridiagonal matrix with entries uniform in [-1, 1) and its dense form.
fn random_matrix(n: usize, d: usize, rng: &mut Rng) -> (BlockTridiagonal, Vec<f64>) {
    let mut matrix = BlockTridiagonal::new(n, d);
    for block in matrix.diagonal.chunks_exact_mut(d * d) {
        for a in 0..d {
            for b in a..d {
                let value = rng.range(-1.0, 1.0);
                block[a * d + b] = value;
                block[b * d + a] = value;
            }
        }
    }
    for value in &mut matrix.coupling {
        *value = rng.range(-1.0, 1.0);
    }
    let dense = matrix.to_dense();
    (matrix, dense)
}

/// The spectrum of a dense symmetric matrix, ascending, with its eigenvectors and its spectral
/// radius.
struct Spectrum {
    values: Vec<f64>,
    vectors: Vec<Vec<f64>>,
    radius: f64,
}

impl Spectrum {
    fn of(dense: &[f64], size: usize) -> Self {
        let (values, vectors) = symmetric_eigen(dense, size);
        let radius = max_abs(&values);
        Spectrum {
            values,
            vectors,
            radius,
        }
    }

    /// The distance from the lowest eigenvalue to the next (every test matrix has two rows at
    /// least).
    fn gap(&self) -> f64 {
        self.values[1] - self.values[0]
    }
}

/// `|A v - lambda v|` of the dense matrix, to check the oracle itself.
fn residual(dense: &[f64], size: usize, value: f64, vector: &[f64]) -> f64 {
    (0..size)
        .map(|i| (0..size).map(|k| dense[i * size + k] * vector[k]).sum::<f64>() - value * vector[i])
        .map(|r| r * r)
        .sum::<f64>()
        .sqrt()
}

/// The distance between two unit vectors up to sign.
fn vector_error(a: &[f64], b: &[f64]) -> f64 {
    let minus: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt();
    let plus: f64 = a.iter().zip(b).map(|(x, y)| (x + y).powi(2)).sum::<f64>().sqrt();
    minus.min(plus)
}

/// The oracle itself: Jacobi's eigenpairs solve `A v = lambda v` and its vectors are orthonormal.
#[test]
fn jacobi_oracle_is_an_eigen_decomposition() {
    let mut rng = Rng::new(1);
    for (n, d) in [(1, 2), (5, 3), (30, 3)] {
        let (_, dense) = random_matrix(n, d, &mut rng);
        let size = n * d;
        let spectrum = Spectrum::of(&dense, size);
        for (value, vector) in spectrum.values.iter().zip(&spectrum.vectors) {
            assert!(residual(&dense, size, *value, vector) <= 1e-13 * spectrum.radius.max(1.0));
        }
        for i in 0..size {
            for k in 0..size {
                let dot: f64 = spectrum.vectors[i]
                    .iter()
                    .zip(&spectrum.vectors[k])
                    .map(|(x, y)| x * y)
                    .sum();
                let expected = if i == k { 1.0 } else { 0.0 };
                assert!((dot - expected).abs() <= 1e-13, "vectors {i} and {k}: {dot}");
            }
        }
    }
}

/// The lowest eigenpair of every test matrix from brackets of every margin and both tops.
#[test]
fn lowest_eigenpair_matches_the_dense_solver() {
    let mut rng = Rng::new(2);
    for d in [2, 3] {
        for n in 1..=30 {
            let (matrix, dense) = random_matrix(n, d, &mut rng);
            let size = n * d;
            let spectrum = Spectrum::of(&dense, size);
            let (lowest, scale) = (spectrum.values[0], spectrum.radius);
            for margin in [1e-6, 1e-3, 0.1, 1.0, 3.0] {
                let below = lowest - margin * scale;
                for above in [
                    lowest + 0.5 * spectrum.gap().max(1e-3 * scale),
                    spectrum.values[size - 1] + scale,
                ] {
                    let label = format!("d = {d}, n = {n}, margin {margin}, above {above} (lowest {lowest})");
                    let (value, vector) = lowest_eigenpair(&matrix, below, above, start_vector(size))
                        .unwrap_or_else(|| panic!("{label}: None"));
                    assert!(
                        (value - lowest).abs() <= 1e-9 * scale,
                        "{label}: eigenvalue {value}"
                    );
                    let length: f64 = vector.iter().map(|x| x * x).sum::<f64>().sqrt();
                    assert!((length - 1.0).abs() <= 1e-12, "{label}: |v| = {length}");
                    if spectrum.gap() > 1e-3 * scale {
                        let error = vector_error(&vector, &spectrum.vectors[0]);
                        assert!(
                            error <= VECTOR_ERROR,
                            "{label}: eigenvector off by {error:e} (gap {})",
                            spectrum.gap()
                        );
                    }
                }
            }
        }
    }
}

/// Starting vectors other than the golden-angle one (random ones) reach the same pair.
#[test]
fn lowest_eigenpair_does_not_depend_on_the_start() {
    let mut rng = Rng::new(3);
    for (n, d) in [(4, 2), (17, 3), (30, 2)] {
        let (matrix, dense) = random_matrix(n, d, &mut rng);
        let size = n * d;
        let spectrum = Spectrum::of(&dense, size);
        for _ in 0..3 {
            let start: Vec<f64> = (0..size).map(|_| rng.range(-1.0, 1.0)).collect();
            let below = spectrum.values[0] - 0.5 * spectrum.radius;
            let (value, vector) = lowest_eigenpair(&matrix, below, spectrum.radius, start).expect("found");
            assert!((value - spectrum.values[0]).abs() <= 1e-9 * spectrum.radius);
            if spectrum.gap() > 1e-3 * spectrum.radius {
                assert!(vector_error(&vector, &spectrum.vectors[0]) <= VECTOR_ERROR);
            }
        }
    }
}

/// `None` when `matrix - below I` is not positive definite: the bracket's bottom at or above the
/// lowest eigenvalue (just above it, between the two lowest, above every eigenvalue).
#[test]
fn lowest_eigenpair_refuses_a_bottom_above_the_lowest_eigenvalue() {
    let mut rng = Rng::new(4);
    for d in [2, 3] {
        for n in [1, 2, 7, 30] {
            let (matrix, dense) = random_matrix(n, d, &mut rng);
            let size = n * d;
            let spectrum = Spectrum::of(&dense, size);
            let (lowest, scale) = (spectrum.values[0], spectrum.radius);
            let top = spectrum.values[size - 1] + 2.0 * scale;
            for below in [
                lowest + 1e-6 * scale,
                lowest + 0.5 * spectrum.gap(),
                0.5 * (spectrum.values[size - 1] + top),
            ] {
                assert_eq!(
                    lowest_eigenpair(&matrix, below, top, start_vector(size)),
                    None,
                    "d = {d}, n = {n}, below = {below}, lowest {lowest}"
                );
            }
        }
    }
}

/// `None` when the lowest eigenvalue is not below the bracket's top.
#[test]
fn lowest_eigenpair_refuses_an_eigenvalue_above_the_top() {
    let mut rng = Rng::new(5);
    for d in [2, 3] {
        for n in [1, 2, 7, 30] {
            let (matrix, dense) = random_matrix(n, d, &mut rng);
            let size = n * d;
            let spectrum = Spectrum::of(&dense, size);
            let (lowest, scale) = (spectrum.values[0], spectrum.radius);
            for above in [lowest - 1e-6 * scale, lowest - 0.1 * scale] {
                assert_eq!(
                    lowest_eigenpair(&matrix, lowest - scale, above, start_vector(size)),
                    None,
                    "d = {d}, n = {n}, above = {above}, lowest {lowest}"
                );
            }
        }
    }
}

/// A random symmetric `size` x `size` block, row-major, entries uniform in [-1, 1) plus `shift` on
/// the diagonal.
fn random_block(size: usize, shift: f64, rng: &mut Rng) -> Vec<f64> {
    let mut block = vec![0.0; size * size];
    for i in 0..size {
        for k in i..size {
            let value = rng.range(-1.0, 1.0) + if i == k { shift } else { 0.0 };
            block[i * size + k] = value;
            block[k * size + i] = value;
        }
    }
    block
}

/// 2 x 2: `eigenvalue_floor` is `min(lambda_min, 0)` to rounding, for indefinite, negative definite
/// and positive definite blocks.
#[test]
fn eigenvalue_floor_is_exact_for_two_by_two() {
    let mut rng = Rng::new(6);
    for shift in [-3.0, -0.5, 0.0, 0.5, 3.0] {
        for _ in 0..50 {
            let block = random_block(2, shift, &mut rng);
            let lowest = symmetric_eigen(&block, 2).0[0];
            let floor = eigenvalue_floor(&block, 2);
            assert!(
                (floor - lowest.min(0.0)).abs() <= 1e-14 * (1.0 + lowest.abs()),
                "{block:?}: {floor} vs {lowest}"
            );
        }
    }
}

/// 3 x 3 and 6 x 6: a lower bound of the lowest eigenvalue, never above 0; 0 for a positive definite
/// diagonally dominant block and exact for a diagonal one.
#[test]
fn eigenvalue_floor_bounds_larger_blocks_from_below() {
    let mut rng = Rng::new(7);
    for size in [3, 6] {
        for shift in [-3.0, -0.5, 0.0, 0.5, 3.0] {
            for _ in 0..50 {
                let block = random_block(size, shift, &mut rng);
                let lowest = symmetric_eigen(&block, size).0[0];
                let floor = eigenvalue_floor(&block, size);
                assert!(floor <= 0.0, "{block:?}: floor {floor}");
                assert!(
                    floor <= lowest + 1e-13,
                    "{block:?}: floor {floor} above the lowest eigenvalue {lowest}"
                );
            }
        }
        // diagonally dominant with a positive diagonal: nothing negative to bound
        let dominant = random_block(size, 2.0 * size as f64, &mut rng);
        assert_eq!(eigenvalue_floor(&dominant, size), 0.0);
        // diagonal: Gershgorin's discs are points
        let mut diagonal = vec![0.0; size * size];
        for i in 0..size {
            diagonal[i * size + i] = i as f64 - 1.5;
        }
        assert_eq!(eigenvalue_floor(&diagonal, size), -1.5);
    }
}
