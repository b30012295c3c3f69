//! Whether the Gram matrix `A A^T + shift I` of sparse rows is positive definite: one banded
//! Cholesky factorization, the rows taken in the order of their first node. A chain's active rows
//! (a link touches a node and the next, a contact one node) are then banded with a few diagonals,
//! so the factorization is O(m) time and its memory a few columns: the band's entries are
//! computed as the factorization reaches them, and no matrix is formed.

/// Rows of a chain's (or a net's) constraints: row r holds `+vectors[r dim..][..dim]` at node
/// `nodes[2 r]` and its negative at node `nodes[2 r + 1]` (a link's two ends), nothing where that
/// node is negative (a support, or a contact's second slot: a contact touches one node).
pub struct SparseRows<'a> {
    pub nodes: &'a [i64],
    pub vectors: &'a [f64],
    pub dim: usize,
}

impl SparseRows<'_> {
    pub fn len(&self) -> usize {
        self.nodes.len() / 2
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.len() < 2
    }

    /// Entry (a, b) of `A A^T`: the dot products of the two rows' vectors at the nodes they share,
    /// signed by their slots (the second is the negative).
    fn gram(&self, a: usize, b: usize) -> f64 {
        let mut sign = 0.0;
        for s in 0..2 {
            let node = self.nodes[2 * a + s];
            if node < 0 {
                continue;
            }
            for t in 0..2 {
                if self.nodes[2 * b + t] == node {
                    sign += if s == t { 1.0 } else { -1.0 };
                }
            }
        }
        if sign == 0.0 {
            return 0.0;
        }
        let (x, y) = (
            &self.vectors[a * self.dim..][..self.dim],
            &self.vectors[b * self.dim..][..self.dim],
        );
        sign * x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>()
    }

    /// A row's smallest node (None for a row without entries).
    fn first(&self, row: usize) -> Option<i64> {
        self.nodes[2 * row..2 * row + 2]
            .iter()
            .copied()
            .filter(|&node| node >= 0)
            .min()
    }
}

/// Whether `A A^T + shift I` is positive definite: its Cholesky factorization completes with
/// every pivot positive (a NaN fails). None if, in the order of the rows' first nodes, two rows
/// that share a node are more than `max_band` rows apart (then the factorization would not be
/// cheap; nothing is decided).
pub fn gram_positive_definite(rows: &SparseRows<'_>, shift: f64, max_band: usize) -> Option<bool> {
    let m = rows.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by_key(|&row| rows.first(row)); // stable; rows without entries first
    let band = bandwidth(rows, &order);
    if band > max_band {
        return None;
    }
    // U^T U = A A^T + shift I, U upper triangular with `band` diagonals above its own. Column j of
    // U is kept in slot j % w of `u`, entry (i, j) at offset i + band - j; only the last w
    // columns are ever read.
    let w = band + 1;
    let mut u = vec![0.0; w * w];
    for j in 0..m {
        let start = j.saturating_sub(band);
        let column = (j % w) * w;
        for i in start..j {
            let other = (i % w) * w;
            let mut sum = rows.gram(order[i], order[j]);
            for l in start..i {
                sum -= u[other + l + band - i] * u[column + l + band - j];
            }
            u[column + i + band - j] = sum / u[other + band];
        }
        let mut pivot = rows.gram(order[j], order[j]) + shift;
        for l in start..j {
            pivot -= u[column + l + band - j].powi(2);
        }
        if !(pivot > 0.0) {
            return Some(false);
        }
        u[column + band] = pivot.sqrt();
    }
    Some(true)
}

/// The most rows apart (in `order`) that two rows sharing a node are.
fn bandwidth(rows: &SparseRows<'_>, order: &[usize]) -> usize {
    let nodes = rows.nodes.iter().copied().max().map_or(0, |node| node + 1).max(0) as usize;
    let mut first_at = vec![usize::MAX; nodes];
    let mut band = 0;
    for (position, &row) in order.iter().enumerate() {
        for &node in &rows.nodes[2 * row..2 * row + 2] {
            if node >= 0 {
                let first = &mut first_at[node as usize];
                *first = (*first).min(position);
                band = band.max(position - *first);
            }
        }
    }
    band
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of a planar problem.
    fn planar<'a>(nodes: &'a [i64], vectors: &'a [f64]) -> SparseRows<'a> {
        SparseRows {
            nodes,
            vectors,
            dim: 2,
        }
    }

    /// `A A^T + shift I` with A formed densely from the rows' definition.
    fn dense_gram(rows: &SparseRows<'_>, shift: f64) -> Vec<Vec<f64>> {
        let (m, d) = (rows.len(), rows.dim);
        let columns = d * (rows.nodes.iter().copied().max().unwrap_or(0).max(0) as usize + 1);
        let mut a = vec![vec![0.0; columns]; m];
        for r in 0..m {
            for (s, sign) in [(0, 1.0), (1, -1.0)] {
                let node = rows.nodes[2 * r + s];
                if node >= 0 {
                    for c in 0..d {
                        a[r][node as usize * d + c] += sign * rows.vectors[r * d + c];
                    }
                }
            }
        }
        let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>();
        (0..m)
            .map(|i| {
                (0..m)
                    .map(|j| dot(&a[i], &a[j]) + if i == j { shift } else { 0.0 })
                    .collect()
            })
            .collect()
    }

    /// Positive definiteness by a dense Cholesky (the reference).
    fn dense_positive_definite(matrix: &[Vec<f64>]) -> bool {
        let m = matrix.len();
        let mut l = vec![vec![0.0; m]; m];
        for j in 0..m {
            for i in j..m {
                let sum = matrix[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
                if i == j {
                    if !(sum > 0.0) {
                        return false;
                    }
                    l[j][j] = sum.sqrt();
                } else {
                    l[i][j] = sum / l[j][j];
                }
            }
        }
        true
    }

    /// A chain of `n` nodes in the plane: link k (nodes k, k + 1) and a contact at every third
    /// node, in reversed order; `bend` turns each link by that angle from the last.
    fn chain(n: usize, bend: f64) -> (Vec<i64>, Vec<f64>) {
        let (mut nodes, mut vectors) = (Vec::new(), Vec::new());
        for k in 0..n - 1 {
            let angle = bend * k as f64;
            nodes.extend([k as i64, k as i64 + 1]);
            vectors.extend([angle.cos(), angle.sin()]);
        }
        for k in (0..n).step_by(3) {
            nodes.extend([k as i64, -1]);
            vectors.extend([0.6, -0.8]);
        }
        // reversed: the function must find the band's order itself
        let m = nodes.len() / 2;
        let nodes = (0..m)
            .rev()
            .flat_map(|r| [nodes[2 * r], nodes[2 * r + 1]])
            .collect();
        let vectors = (0..m)
            .rev()
            .flat_map(|r| [vectors[2 * r], vectors[2 * r + 1]])
            .collect();
        (nodes, vectors)
    }

    #[test]
    fn agrees_with_a_dense_cholesky() {
        let mut answers = Vec::new();
        for (n, bend, shift) in [
            (12, 0.3, -1e-12),
            (12, 0.0, -1e-12),
            (9, 0.5, -0.5),
            (10, 0.2, 0.0),
        ] {
            let (nodes, vectors) = chain(n, bend);
            let rows = planar(&nodes, &vectors);
            let expected = dense_positive_definite(&dense_gram(&rows, shift));
            assert_eq!(
                gram_positive_definite(&rows, shift, 8),
                Some(expected),
                "n {n} bend {bend} shift {shift}"
            );
            answers.push(expected);
        }
        assert!(answers.contains(&true) && answers.contains(&false)); // both answers are tested
    }

    #[test]
    fn a_contact_along_a_link_is_dependent_and_one_across_it_is_not() {
        // A free node between two supports (its links touch it only) and a contact at it.
        let nodes = [-1, 0, 0, -1, 0, -1];
        let along = [1.0, 0.0, 1.0, 0.0, -1.0, 0.0];
        let rows = planar(&nodes, &along);
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(false));
        let nodes = [-1, 0, 0, -1];
        let across = [1.0, 0.0, 0.6, 0.8];
        let rows = planar(&nodes, &across);
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(true));
    }

    #[test]
    fn a_row_without_entries_or_a_nan_is_not_positive_definite() {
        let nodes = [0, 1, -1, -1];
        let vectors = [1.0, 0.0, 0.0, 1.0];
        let rows = planar(&nodes, &vectors);
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(false));
        let nodes = [0, 1];
        let vectors = [f64::NAN, 0.0];
        let rows = planar(&nodes, &vectors);
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(false));
    }

    #[test]
    fn a_band_wider_than_allowed_decides_nothing() {
        // Rows touching node 0 and node 5: five rows apart in the order of their first nodes.
        let nodes = [0, 5, 1, -1, 2, -1, 3, -1, 4, -1, 5, -1];
        let vectors = [1.0; 6 * 2];
        let rows = planar(&nodes, &vectors);
        assert_eq!(gram_positive_definite(&rows, 0.0, 4), None);
        assert!(gram_positive_definite(&rows, 0.0, 5).is_some());
    }

    #[test]
    fn no_rows_are_independent() {
        let rows = planar(&[], &[]);
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(true));
    }
}
