//! A net's polish step through its Newton matrix.
//!
//! Give the active rows' diagonal a small regularization `delta` and the KKT system
//!
//! ```text
//! [ W_A + eps I   J_A^T  ] [dz ]   [ r_z ]
//! [ J_A           -D     ] [dmu] = [ r_mu ],   D = C + delta I  (C: the elastic rows' compliance)
//! ```
//!
//! is quasi-definite, and its multipliers eliminate: `dmu = D^-1 (J_A dz - r_mu)` and
//! `(W_A + eps I + J_A^T D^-1 J_A) dz = r_z + J_A^T D^-1 r_mu`. That matrix is the Newton matrix
//! of the interior-point steps with the weights `1 / D` on the active rows and 0 on the others: the
//! same pattern, order and symbolic factorization, the coordinates alone for unknowns (three
//! fifths of the KKT system's order on a grid whose links are taut), and positive definite where
//! W_A is positive on the null space of J_A (Finsler); its L D L^T (no pivoting) takes it either
//! way. Iterative refinement on the unregularized system then removes delta's
//! error, as in [`crate::linalg::SparseKkt`], which solves the step where the factorization fails
//! or the refined residual stays above ACCEPTED_RESIDUAL.

use super::assembled::lagrangian_gradient;
use super::{NetKktPolish, PolishSolver, PROXIMAL};
use crate::evaluate::Point;
use crate::linalg::sparse::{DUAL_REGULARIZATION, REFINEMENT_STEPS};
use crate::linalg::{Factorization, NewtonMatrix, SparseCholesky, SparseMatrix};
use crate::problem::Network;

/// The largest residual, relative to the system's scale, of a step taken from the condensed system:
/// refinement takes a step it can solve to about the rounding. Beyond it the condensed matrix has
/// lost the step (rows weighted 1 / delta beside a node held by the proximal term alone, or an
/// indefinite matrix whose pivot came out tiny), and the KKT system's L D L^T solves it.
const ACCEPTED_RESIDUAL: f64 = 1e3 * f64::EPSILON;

/// A net's polish step: the condensed system in the Newton matrix's factorization, else the KKT
/// system's L D L^T.
pub struct NetPolish {
    /// W_A, then W_A + J_A^T D^-1 J_A, both in the Newton matrix's pattern.
    hessian: SparseMatrix,
    condensed: SparseMatrix,
    factors: SparseCholesky,
    fallback: NetKktPolish,
    /// The active rows' weights 1 / D (0 off the active set), and the multipliers with those off
    /// the active set zeroed (the Hessian of the Lagrangian is the active rows', as in the KKT
    /// system's assembly).
    sigma: Vec<f64>,
    active_mu: Vec<f64>,
    /// The right-hand side, the step, the residual and the correction, coordinates then rows.
    rhs: Step,
    step: Step,
    residual: Step,
    correction: Step,
    zeros: Vec<f64>,
    /// Scratch: the weighted right-hand side of the rows, the products with W.
    weighted: Vec<f64>,
    product: Vec<f64>,
}

/// A vector of the KKT system: the free coordinates and a value per row (zero off the active set).
#[derive(Default, Clone)]
struct Step {
    z: Vec<f64>,
    mu: Vec<f64>,
}

impl Step {
    fn zeroed(&mut self, coordinates: usize, rows: usize) {
        self.z.clear();
        self.z.resize(coordinates, 0.0);
        self.mu.clear();
        self.mu.resize(rows, 0.0);
    }

    fn largest(&self) -> f64 {
        self.z.iter().chain(&self.mu).fold(0.0_f64, |m, v| m.max(v.abs()))
    }
}

impl NetPolish {
    /// The polish for the net whose Newton matrix is `matrix` (its analysis is shared).
    pub fn new(matrix: &SparseMatrix) -> Self {
        let hessian = matrix.clone();
        NetPolish {
            factors: hessian.new_factors(),
            condensed: hessian.clone(),
            hessian,
            fallback: NetKktPolish::default(),
            sigma: Vec::new(),
            active_mu: Vec::new(),
            rhs: Step::default(),
            step: Step::default(),
            residual: Step::default(),
            correction: Step::default(),
            zeros: Vec::new(),
            weighted: Vec::new(),
            product: Vec::new(),
        }
    }

    /// The regularized system's solution for `rhs` into `out` (the factors of `condensed` made).
    fn solve_regularized(&mut self, network: &Network, point: &Point, rhs: &Step, out: &mut Step) {
        out.z.clone_from(&rhs.z);
        self.weighted.clear();
        self.weighted
            .extend(rhs.mu.iter().zip(&self.sigma).map(|(r, s)| s * r));
        network.add_transpose_times(point, &self.weighted, &mut out.z);
        self.factors.solve_in_place(&mut out.z);
        out.mu.clear();
        out.mu.extend((0..rhs.mu.len()).map(|r| match self.sigma[r] {
            0.0 => 0.0,
            sigma => sigma * (network.row_times(point, r, &out.z) - rhs.mu[r]),
        }));
    }

    /// `rhs - K x` with the unregularized system K of the rows `active` into `out`.
    fn residual_of(
        &mut self,
        network: &Network,
        point: &Point,
        active: &[bool],
        x: &Step,
        rhs: &Step,
        out: &mut Step,
    ) {
        out.z.clear();
        out.z.resize(x.z.len(), 0.0);
        self.hessian.multiply_add(&x.z, &mut out.z, &mut self.product);
        network.add_transpose_times(point, &x.mu, &mut out.z);
        for ((value, b), dz) in out.z.iter_mut().zip(&rhs.z).zip(&x.z) {
            *value = b - (*value + PROXIMAL * dz);
        }
        out.mu.clear();
        out.mu.extend((0..rhs.mu.len()).map(|r| {
            if active[r] {
                let compliance = network.row_compliance(r);
                rhs.mu[r] - (network.row_times(point, r, &x.z) - compliance * x.mu[r])
            } else {
                0.0
            }
        }));
    }

    /// The step into `self.step`; false where the condensed matrix does not factor or its refined
    /// step does not solve the KKT system.
    pub(super) fn condensed_step(
        &mut self,
        network: &Network,
        point: &Point,
        mu: &[f64],
        active: &[bool],
    ) -> bool {
        let (coordinates, rows) = (network.n_free() * network.dim, active.len());
        self.zeros.clear();
        self.zeros.resize(rows, 0.0);
        self.active_mu.clear();
        self.active_mu
            .extend(mu.iter().zip(active).map(|(m, a)| if *a { *m } else { 0.0 }));
        network.newton_matrix(point, &self.active_mu, &self.zeros, &mut self.hessian);
        // delta relative to the largest entry of W_A and of the active rows' gradients
        let largest_gradient = (0..rows)
            .filter(|&r| active[r])
            .fold(0.0_f64, |m, r| m.max(network.row_largest_entry(point, r)));
        let scale = self
            .hessian
            .largest_entry()
            .max(largest_gradient)
            .max(f64::MIN_POSITIVE);
        let delta = DUAL_REGULARIZATION * scale;
        self.sigma.clear();
        self.sigma.extend((0..rows).map(|r| {
            if active[r] {
                1.0 / (network.row_compliance(r) + delta)
            } else {
                0.0
            }
        }));
        network.newton_matrix(point, &self.active_mu, &self.sigma, &mut self.condensed);
        // (L D L^T: where W_A has negative curvature (a node on a convex obstacle's far side) the
        // matrix may be indefinite, and the step is still Newton's on the KKT conditions)
        if !self.condensed.is_finite()
            || !self
                .factors
                .factor_indefinite(&self.condensed, PROXIMAL, delta, f64::EPSILON * scale)
        {
            return false;
        }
        // r_z = -(grad E + J^T mu), r_mu = -(c - C mu) on the active rows
        let mut rhs = std::mem::take(&mut self.rhs);
        rhs.zeroed(coordinates, rows);
        lagrangian_gradient(network, point, mu, &mut rhs.z);
        for value in &mut rhs.z {
            *value = -*value;
        }
        for r in (0..rows).filter(|&r| active[r]) {
            rhs.mu[r] = -(point.c[r] - network.row_compliance(r) * mu[r]);
        }
        let mut step = std::mem::take(&mut self.step);
        let mut residual = std::mem::take(&mut self.residual);
        let mut correction = std::mem::take(&mut self.correction);
        self.solve_regularized(network, point, &rhs, &mut step);
        // refined while the residual keeps halving and is above the rounding of K x (K's norm taken
        // as its largest entry), REFINEMENT_STEPS times at most; the last residual is the verdict
        let (mut previous, mut refinements) = (f64::INFINITY, 0);
        let (size, bound) = loop {
            self.residual_of(network, point, active, &step, &rhs, &mut residual);
            let (size, bound) = (residual.largest(), scale * step.largest() + rhs.largest());
            let refine = size > 4.0 * f64::EPSILON * bound && size <= 0.5 * previous;
            if !refine || refinements == REFINEMENT_STEPS {
                break (size, bound);
            }
            (previous, refinements) = (size, refinements + 1);
            self.solve_regularized(network, point, &residual, &mut correction);
            for (x, dx) in step.z.iter_mut().zip(&correction.z) {
                *x += dx;
            }
            for (x, dx) in step.mu.iter_mut().zip(&correction.mu) {
                *x += dx;
            }
        };
        (self.rhs, self.step, self.residual, self.correction) = (rhs, step, residual, correction);
        size <= ACCEPTED_RESIDUAL * bound && self.step.z.iter().chain(&self.step.mu).all(|v| v.is_finite())
    }
}

impl PolishSolver for NetPolish {
    fn step(
        &mut self,
        network: &Network,
        point: &Point,
        z: &mut [f64],
        mu: &mut [f64],
        active: &[bool],
    ) -> bool {
        if !self.condensed_step(network, point, mu, active) {
            return self.fallback.step(network, point, z, mu, active);
        }
        let d = network.dim;
        for (f, &node) in network.free.iter().enumerate() {
            for i in 0..d {
                z[f * d + i] = point.positions[node * d + i] + self.step.z[f * d + i];
            }
        }
        for (r, m) in mu.iter_mut().enumerate() {
            *m = if active[r] { *m + self.step.mu[r] } else { 0.0 };
        }
        true
    }
}
