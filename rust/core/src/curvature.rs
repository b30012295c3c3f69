//! The saddle escape's second-order test, on the solver's own Newton matrix (solver units): a
//! chain's block-tridiagonal one or a net's sparse one (any [`NetworkMatrix`]).
//!
//! At a result (z, mu) the Hessian of the Lagrangian W is the Newton matrix without its barrier
//! term. With `sigma_r = rho / |g_r|^2` on chosen rows r (`g_r` the row's gradient) the same
//! assembly gives `P = W + rho A^T A`, A those rows scaled to unit length:
//!
//! * **Strict local minimum** if `P_S - s I` is positive definite (S the strictly active rows, force
//!   above tol; s the zero-curvature threshold plus the factorization's rounding): W exceeds s on
//!   the null space of S. One Cholesky.
//! * **A direction of negative curvature** otherwise, if `P_A` (A every active row) has an
//!   eigenvalue below minus the threshold: its eigenvector, found by inverse iteration whose shift
//!   the Cholesky keeps below the eigenvalue. Its component off the null space of A is O(1 / rho):
//!   to first order the move keeps the active rows active.
//! * **Neither** (undecided): a curvature near zero, an infeasible point, negative multipliers.

use crate::evaluate::{NetworkMatrix, Point};
use crate::ipm::Kind;
use crate::linalg::{Factorization, NewtonMatrix};
use crate::problem::Network;

/// rho, in units of the largest entry of W's diagonal blocks (see [`penalty_and_shift`]).
pub const PENALTY: f64 = 1e3;
/// A block Cholesky's rounding, relative to the largest entry.
pub const ROUNDING: f64 = 64.0 * f64::EPSILON;
/// Factorizations of the eigenvalue search (each halves its bracket at least every other step).
pub const MAX_SHIFTS: usize = 80;
/// Inverse-iteration steps at one shift.
pub const MAX_STEPS: usize = 20;
/// The eigenvector's last change (2-norm of unit vectors) at which the search stops.
pub const VECTOR_TOL: f64 = 1e-7;
/// The search stops when the eigenvalue is known to this, relative to its bracket's start.
pub const BRACKET: f64 = 1e-8;
/// A row gradient shorter than this gets no penalty (rho / |g|^2 would overflow).
pub const ROW_FLOOR: f64 = 1e-100;
/// After a shift that converges slowly, the next this fraction of the bracket below its top.
pub const CLOSER: f64 = 1e-2;

/// The test's answer.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// A proven strict local minimum.
    Minimum,
    /// A direction of negative curvature (free coordinates, unit length) and its curvature.
    Direction(f64, Vec<f64>),
    Undecided,
}

/// The curvature below which an eigenvalue counts as zero: one that changes the energy by less
/// than `tol W L` when every node moves by the chain length L.
pub fn zero_curvature(tol: f64, weight: f64, n_nodes: usize, total_length: f64) -> f64 {
    tol * weight / (n_nodes as f64 * total_length)
}

/// rho and the shift s of the sufficient test `W + rho A^T A - s I` positive definite.
///
/// `stiffest`: the largest entry of W's diagonal blocks; `stiffness`: the weight per chain length.
/// Above some rho*, `W + rho A^T A` is positive definite iff W is on null(A) (Finsler), so a larger
/// rho is safer, but the rounding the shift must cover grows with it. A's rows are unit vectors, so
/// rho is a stiffness: `penalty` (PENALTY) times the larger of the two. A Cholesky that completes is exact for
/// a matrix within a few eps of its largest entry: ROUNDING of a bound on the largest diagonal
/// entry covers that; each unit row adds at most rho, and a node has `degree` links and one contact
/// per obstacle at most.
pub fn penalty_and_shift(
    stiffest: f64,
    stiffness: f64,
    degree: usize,
    n_obstacles: usize,
    threshold: f64,
    penalty: f64,
) -> (f64, f64) {
    let rho = penalty * stiffest.max(stiffness);
    let largest = stiffest + (degree + n_obstacles) as f64 * rho;
    (rho, threshold + ROUNDING * largest)
}

/// The inverse iteration's first vector: fixed (the same problem leaves its saddle the same way) and
/// generic (neither symmetric nor antisymmetric along the chain): cosines at the golden angle.
pub fn start_vector(size: usize) -> Vec<f64> {
    let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
    (1..=size).map(|i| (golden * i as f64).cos()).collect()
}

/// The smallest eigenvalue of the contact terms' blocks node by node, `sum_j nu_j Hess phi_j`, or 0
/// if none is negative: a lower bound of the penalized matrices' eigenvalues (their link and penalty
/// terms are positive semidefinite for mu >= 0). Exact for 2 x 2 blocks, Gershgorin's bound otherwise.
fn contact_floor(network: &Network, point: &Point, mu: &[f64]) -> f64 {
    let (d, n, n_links, n_obstacles) = (
        network.dim,
        network.n_free(),
        network.n_links(),
        network.n_obstacles(),
    );
    if n_obstacles == 0 || network.contact_links() {
        return if n_obstacles == 0 {
            0.0
        } else {
            link_contact_floor(network, point, mu)
        };
    }
    let mut lowest: f64 = 0.0;
    let mut block = [0.0; 9];
    for f in 0..n {
        block.iter_mut().for_each(|b| *b = 0.0);
        for j in 0..n_obstacles {
            let nu = mu[n_links + j * n + f].max(0.0);
            let hessian = network.contact_hessian(point, j, f);
            for (b, h) in block.iter_mut().zip(hessian) {
                *b += nu * h;
            }
        }
        lowest = lowest.min(eigenvalue_floor(&block[..d * d], d));
    }
    lowest
}

/// The same bound for link-contact rows (2d x 2d blocks, Gershgorin).
fn link_contact_floor(network: &Network, point: &Point, mu: &[f64]) -> f64 {
    let (d, n_links, n_obstacles) = (network.dim, network.n_links(), network.n_obstacles());
    let size = 2 * d;
    let mut lowest: f64 = 0.0;
    for r in 0..n_links {
        let mut block = [0.0; 36];
        for j in 0..n_obstacles {
            let nu = mu[n_links + j * n_links + r].max(0.0);
            for (b, h) in block.iter_mut().zip(network.contact_hessian(point, j, r)) {
                *b += nu * h;
            }
        }
        lowest = lowest.min(eigenvalue_floor(&block[..size * size], size));
    }
    lowest
}

/// A lower bound of the smallest eigenvalue of a symmetric block (exact for 2 x 2), at most 0.
pub fn eigenvalue_floor(block: &[f64], size: usize) -> f64 {
    let value = if size == 2 {
        let (a, b, d) = (block[0], block[1], block[3]);
        (a + d) / 2.0 - ((a - d) / 2.0).hypot(b)
    } else {
        (0..size)
            .map(|i| {
                let radius: f64 = (0..size)
                    .filter(|&k| k != i)
                    .map(|k| block[i * size + k].abs())
                    .sum();
                block[i * size + i] - radius
            })
            .fold(f64::INFINITY, f64::min)
    };
    value.min(0.0)
}

/// The most links at a free node: `known` if the policy knows it (a chain's 2), else counted.
fn largest_degree(network: &Network, known: Option<usize>) -> usize {
    if let Some(degree) = known {
        return degree;
    }
    let mut degree = vec![0usize; network.n_nodes()];
    for &[a, b] in &network.links {
        degree[a] += 1;
        degree[b] += 1;
    }
    network.free.iter().map(|&node| degree[node]).max().unwrap_or(0)
}

/// The second-order test at a result: `point` evaluated at it with multipliers `mu`;
/// `total_length`: the whole chain's (all its links'), in the solver's units.
pub fn escape_test<K: Kind>(
    network: &Network,
    point: &Point,
    mu: &[f64],
    tol: f64,
    total_length: f64,
) -> Verdict {
    if network.n_free() == 0 {
        return Verdict::Minimum; // nothing can move
    }
    let threshold = zero_curvature(tol, 1.0, network.n_nodes(), total_length);
    let mut norms = network.row_norms(point);
    let directed: Vec<bool> = norms.iter().map(|&n| n > ROW_FLOOR).collect();
    let mut lowest_force: f64 = 0.0;
    let mut farthest = f64::NEG_INFINITY;
    // (an elastic link's row reads c - compliance mu <= 0)
    let value = |r: usize| match network.row_compliance(r) {
        0.0 => point.c[r],
        compliance => point.c[r] - compliance * mu[r],
    };
    for r in 0..mu.len() {
        if !directed[r] {
            norms[r] = ROW_FLOOR;
        }
        lowest_force = lowest_force.min(mu[r] * norms[r]);
        farthest = farthest.max(value(r) / norms[r]);
    }
    if lowest_force < -tol || farthest > tol {
        return Verdict::Undecided; // not dual feasible, or infeasible
    }
    let m = mu.len();
    // A taut elastic link is no constraint of the test: it adds its stiffness 1 / compliance along
    // itself to every matrix below (the energy's curvature once its stretch is eliminated).
    let elastic: Vec<f64> = (0..m)
        .map(|r| match network.row_compliance(r) {
            0.0 => 0.0,
            compliance if directed[r] && value(r) / norms[r] >= -tol => 1.0 / compliance,
            _ => 0.0,
        })
        .collect();
    let mut matrix = K::Matrix::for_network(network);
    network.newton_matrix(point, mu, &elastic, &mut matrix);
    let stiffest = matrix.largest_node_entry();
    let (rho, mut shift) = penalty_and_shift(
        stiffest,
        1.0 / total_length,
        largest_degree(network, K::policy(network).degree),
        network.n_obstacles(),
        threshold,
        PENALTY,
    );
    if let Some(longest) = matrix.factor_lines() {
        // An entry of L L^T sums as many rounded products as the longest row or column of the
        // sparse factor L has entries, where a chain's block factor sums at most 2d: the rounding
        // bound (Demmel's |E| <= gamma_(k+1) |L| |L^T|) grows in proportion.
        let lines = longest as f64 / (2 * network.dim) as f64;
        shift = threshold + (shift - threshold) * lines.max(1.0);
    }
    let mut strict_sigma = elastic.clone();
    let mut active_sigma = elastic;
    for r in 0..m {
        if network.row_compliance(r) == 0.0 && directed[r] && point.c[r] / norms[r] >= -tol {
            active_sigma[r] = rho / (norms[r] * norms[r]);
            if mu[r] * norms[r] > tol {
                strict_sigma[r] = active_sigma[r];
            }
        }
    }
    network.newton_matrix(point, mu, &strict_sigma, &mut matrix);
    let mut factors = matrix.new_factors();
    if factors.factor_shifted(&matrix, -shift) {
        return Verdict::Minimum;
    }
    // Not proven: is there negative curvature beyond the threshold that keeps every active row active?
    let margin = shift - threshold;
    network.newton_matrix(point, mu, &active_sigma, &mut matrix);
    let below = 1.1 * contact_floor(network, point, mu) - threshold - 2.0 * margin;
    match lowest_eigenpair(&matrix, below, -threshold - margin, start_vector(matrix.size())) {
        Some((value, vector)) => Verdict::Direction(value, vector),
        None => Verdict::Undecided,
    }
}

/// The smallest eigenvalue of `matrix` and a unit eigenvector, given `matrix - below I` positive
/// definite; None if that is not so after all, or if the eigenvalue is not below `above`.
///
/// Inverse iteration with a shift sigma that the factorization keeps below the eigenvalue (it fails
/// above it). Each factorization that succeeds raises the bracket's bottom to sigma, and its steps
/// lower the top to their Rayleigh quotient (never below the eigenvalue); one that fails lowers the
/// top to sigma. At one shift the steps go on while each changes the vector ten times less than the
/// one before, until the change is below VECTOR_TOL; slower, the next shift goes just below the top,
/// halfway after a failure.
pub fn lowest_eigenpair<M: NewtonMatrix>(
    matrix: &M,
    below: f64,
    above: f64,
    start: Vec<f64>,
) -> Option<(f64, Vec<f64>)> {
    let (mut bottom, mut top) = (below, above);
    let mut sigma = below;
    let length = start.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mut vector: Vec<f64> = start.iter().map(|v| v / length).collect();
    let mut value = f64::INFINITY;
    let mut factors = matrix.new_factors();
    let mut w = vec![0.0; vector.len()];
    for _ in 0..MAX_SHIFTS {
        if !factors.factor_shifted(matrix, -sigma) {
            if sigma == below {
                return None;
            }
            top = sigma;
            sigma = bottom + 0.5 * (top - bottom);
            continue;
        }
        bottom = sigma;
        let mut previous = f64::INFINITY;
        for _ in 0..MAX_STEPS {
            // w = (M - sigma I)^-1 v; its Rayleigh quotient is sigma + w.v / w.w (w^T (M - sigma I) w = w.v)
            w.copy_from_slice(&vector);
            factors.solve_in_place(&mut w);
            let squared: f64 = w.iter().map(|x| x * x).sum();
            let along: f64 = w.iter().zip(&vector).map(|(x, y)| x * y).sum();
            let length = squared.sqrt();
            let cosine = (along.abs() / length).min(1.0);
            for (v, x) in vector.iter_mut().zip(&w) {
                *v = x / length;
            }
            value = sigma + along / squared;
            let change = (2.0 * (1.0 - cosine)).sqrt();
            top = top.min(value);
            if change <= VECTOR_TOL {
                return (value < above).then_some((value, vector));
            }
            if change > 0.1 * previous {
                break;
            }
            previous = change;
        }
        if top - bottom <= BRACKET * (above - below) {
            break;
        }
        sigma = top - CLOSER * (top - bottom);
    }
    (value < above).then_some((value, vector))
}
