//! Deterministic test data for the modules' own tests (no crates).

/// A xorshift64* generator: deterministic test data without crates.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [-1, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// Uniform in [lo, hi).
    pub fn between(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * 0.5 * (self.uniform() + 1.0)
    }

    /// Uniform in 0..bound.
    pub fn below(&mut self, bound: usize) -> usize {
        (self.next_u64() % bound as u64) as usize
    }

    pub fn chance(&mut self, probability: f64) -> bool {
        self.between(0.0, 1.0) < probability
    }

    /// A random unit vector of dimension d (the rest zero).
    pub fn direction(&mut self, d: usize) -> [f64; 3] {
        loop {
            let mut v = [0.0; 3];
            for value in &mut v[..d] {
                *value = self.uniform();
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 0.1 {
                return v.map(|x| x / norm);
            }
        }
    }
}

/// The oracle: dense Gaussian elimination with partial pivoting (None if a pivot column is zero).
pub fn dense_solve(n: usize, a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    for k in 0..n {
        let mut p = k;
        for r in k + 1..n {
            if m[r * n + k].abs() > m[p * n + k].abs() {
                p = r;
            }
        }
        if m[p * n + k] == 0.0 {
            return None;
        }
        if p != k {
            for c in 0..n {
                m.swap(k * n + c, p * n + c);
            }
            x.swap(k, p);
        }
        for r in k + 1..n {
            let f = m[r * n + k] / m[k * n + k];
            if f != 0.0 {
                for c in k..n {
                    m[r * n + c] -= f * m[k * n + c];
                }
                x[r] -= f * x[k];
            }
        }
    }
    for k in (0..n).rev() {
        let mut sum = x[k];
        for c in k + 1..n {
            sum -= m[k * n + c] * x[c];
        }
        x[k] = sum / m[k * n + k];
    }
    Some(x)
}

/// The pairs of an a x b grid of nodes (node i b + j at row i, column j), each joined to its 4
/// neighbours.
pub fn grid_pairs(a: usize, b: usize) -> Vec<[usize; 2]> {
    let mut pairs = Vec::new();
    for i in 0..a {
        for j in 0..b {
            if i + 1 < a {
                pairs.push([i * b + j, (i + 1) * b + j]);
            }
            if j + 1 < b {
                pairs.push([i * b + j, i * b + j + 1]);
            }
        }
    }
    pairs
}
