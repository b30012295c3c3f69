//! Helpers shared by the integration tests: a deterministic generator of test data and a dense
//! symmetric eigen-solver (cyclic Jacobi) that serves as an oracle independent of the core's
//! block-tridiagonal Cholesky.

// Each test file uses a different subset of these helpers.
#![allow(dead_code)]

/// A xorshift64* generator: the same test data on every run, without crates.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [low, high).
    pub fn range(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.unit()
    }

    /// Uniform in 0..bound.
    pub fn below(&mut self, bound: usize) -> usize {
        (self.next_u64() % bound as u64) as usize
    }
}

/// The eigenvalues of a dense symmetric matrix (row-major, `n` x `n`) in ascending order and the
/// matching unit eigenvectors, by cyclic Jacobi rotations (Rutishauser's form, as in Numerical
/// Recipes' `jacobi`). Accurate to a few eps of the matrix's norm.
pub fn symmetric_eigen(matrix: &[f64], n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    assert_eq!(matrix.len(), n * n);
    let mut a = matrix.to_vec();
    // the eigenvectors as rows (the transpose of the accumulated rotations), updated row by row
    let mut vt = vec![0.0; n * n];
    for i in 0..n {
        vt[i * n + i] = 1.0;
    }
    for sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|p| (p + 1..n).map(move |q| (p, q)))
            .map(|(p, q)| a[p * n + q].abs())
            .sum();
        if off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let (app, aqq, apq) = (a[p * n + p], a[q * n + q], a[p * n + q]);
                // After four sweeps an entry negligible next to both diagonal entries is set to zero
                // instead of rotated (so the sweeps end with an exactly diagonal matrix).
                let g = 100.0 * apq.abs();
                if sweep > 3 && app.abs() + g == app.abs() && aqq.abs() + g == aqq.abs() {
                    a[p * n + q] = 0.0;
                    a[q * n + p] = 0.0;
                    continue;
                }
                if apq == 0.0 {
                    continue;
                }
                // The rotation P that zeroes a[p][q] (t: the tangent of its angle, the smaller root);
                // A becomes P^T A P, which changes rows and columns p and q only.
                let theta = (aqq - app) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + theta.hypot(1.0));
                let c = 1.0 / t.hypot(1.0);
                let s = t * c;
                rotate_rows(&mut a, n, p, q, c, s);
                for k in 0..n {
                    a[k * n + p] = a[p * n + k];
                    a[k * n + q] = a[q * n + k];
                }
                a[p * n + p] = app - t * apq;
                a[q * n + q] = aqq + t * apq;
                a[p * n + q] = 0.0;
                a[q * n + p] = 0.0;
                rotate_rows(&mut vt, n, p, q, c, s);
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &k| a[i * n + i].total_cmp(&a[k * n + k]));
    let values = order.iter().map(|&i| a[i * n + i]).collect();
    let vectors = order.iter().map(|&i| vt[i * n..i * n + n].to_vec()).collect();
    (values, vectors)
}

/// Rows p < q of the row-major `n` x `n` matrix `m` become `c row_p - s row_q` and `s row_p + c row_q`.
fn rotate_rows(m: &mut [f64], n: usize, p: usize, q: usize, c: f64, s: f64) {
    let (head, tail) = m.split_at_mut(q * n);
    for (x, y) in head[p * n..p * n + n].iter_mut().zip(&mut tail[..n]) {
        let (u, w) = (*x, *y);
        *x = c * u - s * w;
        *y = s * u + c * w;
    }
}

/// The largest absolute entry.
pub fn max_abs(values: &[f64]) -> f64 {
    values.iter().fold(0.0, |a: f64, v| a.max(v.abs()))
}

/// The largest absolute difference of two equally long slices.
pub fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold(0.0, |m: f64, (x, y)| m.max((x - y).abs()))
}
