//! funicular's solver core: the equilibrium of a hanging chain or a cable net by a primal-dual
//! interior-point method with an active-set polish, and the second-order test the saddle escape
//! asks at its result. The modules from the top down, each using only those below it:
//!
//! * [`chain`] and [`net`]: the whole solve of a chain (its starts: the exact catenary, coarse to
//!   fine, the presolve's guess; its answer with the fixed links' tensions) and of a cable net (its
//!   force-density start).
//! * [`driver`]: what the solves of chains and nets share, in the problem's units: the solver's
//!   units, one solve on the network and its errors, the second-order test at a result, the saddle
//!   escape, the multipliers back in the problem's units; where a network's kind picks its linear
//!   algebra and policy.
//! * [`presolve`] and [`catenary`]: a chain's supports checked, its exactly taut spans and its
//!   initial guess, in the problem's units; the exact start of a chain that touches nothing (each
//!   span a discrete catenary).
//! * [`ipm`]: the iteration (Mehrotra predictor-corrector, two line searches, inertia correction,
//!   recentring) and the polish's driver, written once for every kind of network ([`ipm::Kind`]).
//! * [`curvature`]: the second-order test.
//! * [`polish`]: one Newton step on the active-set KKT system, by the solver of the network's kind.
//! * [`policy`]: what the iteration decides differently on a chain and on a net, decided once.
//! * [`evaluate`]: constraint values, Jacobian products, the Newton matrix, the KKT residuals.
//! * [`gram`]: whether the Gram matrix of a chain's active rows, shifted, is positive definite (the
//!   result files' proof of LICQ).
//! * [`shapes`]: the built-in obstacles evaluated here (quadratics, rounded boxes).
//! * [`problem`]: the problem types: a chain or a net in the problem's units, and the problem in
//!   the solver's units that the iteration works on (positions (N, d), links between any node
//!   pairs, obstacles evaluated here or by the caller).
//! * [`linalg`]: the linear algebra behind two traits, the Newton matrix with its factorization (a
//!   chain's block-tridiagonal Cholesky, a net's sparse one) and the polish's KKT solver (a chain's
//!   block elimination with a banded LU behind it, a net's regularized sparse L D L^T).

// Index loops over the d coordinates read like the formulas they compute; negated comparisons
// (`!(error <= tol)`) are how a NaN is made to fail a test.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod catenary;
pub mod chain;
pub mod curvature;
pub mod driver;
pub mod evaluate;
pub mod gram;
pub mod ipm;
pub mod linalg;
pub mod net;
pub mod policy;
pub mod polish;
pub mod presolve;
pub mod problem;
pub mod shapes;
#[cfg(test)]
mod test_support;
