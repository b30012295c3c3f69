//! Whether the Gram matrix `A A^T + shift I` of sparse rows is positive definite: one banded
//! Cholesky factorization, the rows taken in the order of their first node. A chain's active rows
//! (a link touches a node and the next, a contact one node) are then banded with a few diagonals,
//! so the factorization is O(m) time and its memory a few columns: the band's entries are
//! computed as the factorization reaches them, and no matrix is formed.

/// Rows of at most two `dim`-vectors each: row r holds `values[(2 r + s) dim..][..dim]` at node
/// `nodes[2 r + s]` (s = 0, 1), nothing where that node is negative.
pub struct SparseRows<'a> {
    pub nodes: &'a [i64],
    pub values: &'a [f64],
    pub dim: usize,
}

impl SparseRows<'_> {
    pub fn len(&self) -> usize {
        self.nodes.len() / 2
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.len() < 2
    }

    /// A row's vector in slot s.
    fn vector(&self, row: usize, slot: usize) -> &[f64] {
        &self.values[(2 * row + slot) * self.dim..][..self.dim]
    }

    /// Entry (a, b) of `A A^T`: the dot products of the two rows' vectors at the nodes they share.
    fn gram(&self, a: usize, b: usize) -> f64 {
        let mut sum = 0.0;
        for s in 0..2 {
            let node = self.nodes[2 * a + s];
            if node < 0 {
                continue;
            }
            for t in 0..2 {
                if self.nodes[2 * b + t] == node {
                    let (x, y) = (self.vector(a, s), self.vector(b, t));
                    sum += x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>();
                }
            }
        }
        sum
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

    /// The Gram matrix of `rows` formed densely, plus `shift` on the diagonal.
    fn dense_gram(rows: &SparseRows<'_>, shift: f64) -> Vec<Vec<f64>> {
        let m = rows.len();
        (0..m)
            .map(|a| {
                (0..m)
                    .map(|b| rows.gram(a, b) + if a == b { shift } else { 0.0 })
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
    /// node, in a shuffled order; `bend` turns each link by that angle from the last.
    fn chain(n: usize, bend: f64) -> (Vec<i64>, Vec<f64>) {
        let (mut nodes, mut values) = (Vec::new(), Vec::new());
        for k in 0..n - 1 {
            let angle = bend * k as f64;
            let (c, s) = (angle.cos(), angle.sin());
            nodes.extend([k as i64, k as i64 + 1]);
            values.extend([c, s, -c, -s]);
        }
        for k in (0..n).step_by(3) {
            nodes.extend([k as i64, -1]);
            values.extend([0.6, -0.8, 0.0, 0.0]);
        }
        // reverse the rows: the function must find the band's order itself
        let m = nodes.len() / 2;
        let nodes = (0..m)
            .rev()
            .flat_map(|r| [nodes[2 * r], nodes[2 * r + 1]])
            .collect();
        let values = (0..m)
            .rev()
            .flat_map(|r| values[4 * r..4 * r + 4].to_vec())
            .collect();
        (nodes, values)
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
            let (nodes, values) = chain(n, bend);
            let rows = SparseRows {
                nodes: &nodes,
                values: &values,
                dim: 2,
            };
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
        // A node between two supports' links (the supports eliminated: one node each) and a contact.
        let nodes = [-1, 0, 0, -1, 0, -1];
        let along = [9.0, 9.0, -1.0, 0.0, 1.0, 0.0, 9.0, 9.0, 1.0, 0.0, 0.0, 0.0];
        let rows = SparseRows {
            nodes: &nodes,
            values: &along,
            dim: 2,
        };
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(false));
        let nodes = [-1, 0, 0, -1];
        let across = [9.0, 9.0, -1.0, 0.0, 0.6, 0.8, 9.0, 9.0];
        let rows = SparseRows {
            nodes: &nodes,
            values: &across,
            dim: 2,
        };
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(true));
    }

    #[test]
    fn a_row_without_entries_or_a_nan_is_not_positive_definite() {
        let nodes = [0, 1, -1, -1];
        let values = [1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(
            gram_positive_definite(
                &SparseRows {
                    nodes: &nodes,
                    values: &values,
                    dim: 2
                },
                -1e-12,
                8
            ),
            Some(false)
        );
        let nodes = [0, 1];
        let values = [f64::NAN, 0.0, -1.0, 0.0];
        assert_eq!(
            gram_positive_definite(
                &SparseRows {
                    nodes: &nodes,
                    values: &values,
                    dim: 2
                },
                -1e-12,
                8
            ),
            Some(false)
        );
    }

    #[test]
    fn a_band_wider_than_allowed_decides_nothing() {
        // Rows touching node 0 and node 5: five rows apart in the order of their first nodes.
        let nodes = [0, 5, 1, -1, 2, -1, 3, -1, 4, -1, 5, -1];
        let values = [1.0; 12 * 2];
        let rows = SparseRows {
            nodes: &nodes,
            values: &values,
            dim: 2,
        };
        assert_eq!(gram_positive_definite(&rows, 0.0, 4), None);
        assert!(gram_positive_definite(&rows, 0.0, 5).is_some());
    }

    #[test]
    fn no_rows_are_independent() {
        let rows = SparseRows {
            nodes: &[],
            values: &[],
            dim: 2,
        };
        assert_eq!(gram_positive_definite(&rows, -1e-12, 8), Some(true));
    }
}
