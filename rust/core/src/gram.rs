//! Whether the Gram matrix `A A^T + shift I` of sparse rows is positive definite: one Cholesky
//! factorization. A chain's active rows (a link touches a node and the next, a contact one node),
//! taken in the order of their first node, are banded with a few diagonals: the banded
//! factorization is O(m) time and its memory a few columns, the band's entries computed as it
//! reaches them, no matrix formed. A net's rows are not banded in any order worth finding; they take
//! the sparse Cholesky factorization of the Newton matrices (a fill-reducing order of the rows).

use crate::linalg::blocks_positive_definite;

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
/// every pivot positive (a NaN fails). Banded where, in the order of the rows' first nodes, no two
/// rows sharing a node are more than `max_band` rows apart; sparse otherwise.
pub fn gram_positive_definite(rows: &SparseRows<'_>, shift: f64, max_band: usize) -> bool {
    let m = rows.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by_key(|&row| rows.first(row)); // stable; rows without entries first
    let band = bandwidth(rows, &order);
    if band <= max_band {
        banded_positive_definite(rows, &order, band, shift)
    } else {
        sparse_positive_definite(rows, shift)
    }
}

fn banded_positive_definite(rows: &SparseRows<'_>, order: &[usize], band: usize, shift: f64) -> bool {
    // U^T U = A A^T + shift I, U upper triangular with `band` diagonals above its own. Column j of
    // U is kept in slot j % w of `u`, entry (i, j) at offset i + band - j; only the last w
    // columns are ever read.
    let w = band + 1;
    let mut u = vec![0.0; w * w];
    for j in 0..order.len() {
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
            return false;
        }
        u[column + band] = pivot.sqrt();
    }
    true
}

/// The Gram matrix as a sparse matrix over the rows (one unknown per row, rows coupled where they
/// share a node), factored by [`blocks_positive_definite`] (its rounding bound included).
fn sparse_positive_definite(rows: &SparseRows<'_>, shift: f64) -> bool {
    let m = rows.len();
    let mut touches: Vec<(i64, usize)> = (0..m)
        .flat_map(|r| rows.nodes[2 * r..2 * r + 2].iter().map(move |&node| (node, r)))
        .filter(|&(node, _)| node >= 0)
        .collect();
    touches.sort_unstable();
    let mut pairs = Vec::new();
    for group in touches.chunk_by(|a, b| a.0 == b.0) {
        for (i, &(_, a)) in group.iter().enumerate() {
            pairs.extend(
                group[i + 1..]
                    .iter()
                    .filter(|&&(_, b)| b != a)
                    .map(|&(_, b)| [a.min(b), a.max(b)]),
            );
        }
    }
    pairs.sort_unstable();
    pairs.dedup(); // (two rows sharing both nodes: one entry, its dot products summed by `gram`)
    let diagonal: Vec<f64> = (0..m).map(|r| rows.gram(r, r)).collect();
    let coupling: Vec<f64> = pairs.iter().map(|&[a, b]| rows.gram(a, b)).collect();
    blocks_positive_definite(1, &diagonal, &pairs, &coupling, shift)
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
                expected,
                "n {n} bend {bend} shift {shift}"
            );
            assert_eq!(
                sparse_positive_definite(&rows, shift),
                expected,
                "sparse: n {n} bend {bend} shift {shift}"
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
        assert!(!gram_positive_definite(&rows, -1e-12, 8));
        let nodes = [-1, 0, 0, -1];
        let across = [1.0, 0.0, 0.6, 0.8];
        let rows = planar(&nodes, &across);
        assert!(gram_positive_definite(&rows, -1e-12, 8));
    }

    #[test]
    fn a_row_without_entries_or_a_nan_is_not_positive_definite() {
        let nodes = [0, 1, -1, -1];
        let vectors = [1.0, 0.0, 0.0, 1.0];
        let rows = planar(&nodes, &vectors);
        assert!(!gram_positive_definite(&rows, -1e-12, 8));
        let nodes = [0, 1];
        let vectors = [f64::NAN, 0.0];
        let rows = planar(&nodes, &vectors);
        assert!(!gram_positive_definite(&rows, -1e-12, 8));
    }

    /// The rows of an n x n grid net in space (links between neighbours, unit vectors tilted out of
    /// the plane by up to `tilt`, no two alike), with its corners fixed (-1); and a diagonal brace
    /// per cell if `braced`.
    fn grid(n: usize, braced: bool, tilt: f64) -> (Vec<i64>, Vec<f64>) {
        let corner = |i: usize, j: usize| (i == 0 || i == n - 1) && (j == 0 || j == n - 1);
        let node = |i: usize, j: usize| if corner(i, j) { -1 } else { (i * n + j) as i64 };
        let (mut nodes, mut vectors) = (Vec::new(), Vec::new());
        let mut link = |a: (usize, usize), b: (usize, usize), k: usize| {
            let angle = 0.37 * k as f64;
            nodes.extend([node(a.0, a.1), node(b.0, b.1)]);
            let (x, y, z) = (
                b.1 as f64 - a.1 as f64,
                b.0 as f64 - a.0 as f64,
                tilt * angle.sin(),
            );
            let size = (x * x + y * y + z * z).sqrt();
            vectors.extend([x / size, y / size, z / size]);
        };
        let mut k = 0;
        for i in 0..n {
            for j in 0..n {
                for (di, dj) in [(0, 1), (1, 0), (1, 1)] {
                    if i + di < n && j + dj < n && (di + dj == 1 || braced) {
                        link((i, j), (i + di, j + dj), k);
                        k += 1;
                    }
                }
            }
        }
        (nodes, vectors)
    }

    #[test]
    fn a_net_beyond_the_band_takes_the_sparse_factorization_with_the_dense_answer() {
        // Tilted out of the plane, the 84 links of a 7 x 7 grid (45 free nodes, 135 coordinates)
        // are independent; flat and braced (120 rows in the 90 coordinates of the plane) they
        // cannot be.
        for (braced, tilt, independent) in [(false, 0.3, true), (true, 0.0, false)] {
            let (nodes, vectors) = grid(7, braced, tilt);
            let rows = SparseRows {
                nodes: &nodes,
                vectors: &vectors,
                dim: 3,
            };
            let mut order: Vec<usize> = (0..rows.len()).collect();
            order.sort_by_key(|&row| rows.first(row));
            assert!(bandwidth(&rows, &order) > 4, "the grid's rows are not banded");
            assert_eq!(dense_positive_definite(&dense_gram(&rows, -1e-12)), independent);
            assert_eq!(
                gram_positive_definite(&rows, -1e-12, 4),
                independent,
                "braced {braced}"
            );
        }
    }

    #[test]
    fn no_rows_are_independent() {
        let rows = planar(&[], &[]);
        assert!(gram_positive_definite(&rows, -1e-12, 8));
    }
}
