//! One Newton step on the active-set KKT system.
//!
//! With the active set A fixed (taut links and touching contacts), the KKT conditions are a square
//! system without any `1 / s`:
//!
//! ```text
//! [ W_A + eps I   J_A^T ] [dz  ]     [ grad E + J_A^T mu_A ]
//! [ J_A            0    ] [dmu ] = - [ c_A                 ]
//! ```
//!
//! `eps` (PROXIMAL) gives directions the active rows leave free (a node lying on the ground between
//! slack links may slide) a zero step instead of a singular matrix. The unknowns are ordered node by
//! node (`layout`): for a chain the matrix is block tridiagonal over the nodes, and banded. A chain
//! with node contact is assembled and solved in one pass over its nodes (`chain_step`); the other
//! networks, and the chains that pass refuses, through the assembled matrix.
//!
//! The step's solver is a [`PolishSolver`], chosen once with the kind of network: a chain's
//! ([`ChainPolish`]: the fused pass, else block elimination with the banded LU behind it) or a net's
//! ([`NetPolish`]: the constraint rows eliminated, an L D L^T in the Newton matrix's symbolic
//! factorization, else the sparse L D L^T of the whole KKT system).

mod assembled;
mod chain;
mod net;
#[cfg(test)]
mod tests;

pub use assembled::{Assembled, NetKktPolish};
pub use chain::ChainPolish;
pub use net::NetPolish;

use crate::evaluate::Point;
use crate::problem::Network;

pub const PROXIMAL: f64 = 1e-10;
const NONE: usize = usize::MAX;

/// The polish's solver: one Newton step on the active-set KKT system, its storage kept from step to
/// step (fresh pages cost a page fault each: at 10^6 nodes as much as a factorization).
pub trait PolishSolver {
    /// One Newton step from `point` (its constraint values and derivatives are used as they are)
    /// with multipliers `mu` (zero off the active set `active`): the new free coordinates written
    /// to `z` and the new multipliers to `mu`, in place. False, `z` and `mu` then unspecified, if
    /// the system is singular.
    fn step(
        &mut self,
        network: &Network,
        point: &Point,
        z: &mut [f64],
        mu: &mut [f64],
        active: &[bool],
    ) -> bool;
}
