//! What differs between the iteration on a chain and on a net, decided once from the problem and
//! read by the loop ([`crate::ipm`]), the polish and the second-order test ([`crate::curvature`]):
//! none of them asks what kind of network it runs on.
//!
//! A chain's polish step is cheap (one pass over its nodes) and its active set settles early, so
//! its polish is tried eagerly and corrects its active set row by row, runs of touching nodes at a
//! time where it lifts off an obstacle. A net's polish step costs several Newton steps and its
//! active set changes at every step while many links approach their lengths, so its polish waits
//! until every row has told whether it is active, and gives up (or begins again) at the first step
//! that goes wrong. A net's steps overshoot on the links' curvature, which its line search
//! corrects; its residual is judged over the whole net rather than by its worst node where that is
//! what the problem allows.

use crate::problem::Network;

/// The barrier target is kept at least this fraction of the KKT residual (see `interior_point_step`) ...
pub const CENTRING_FLOOR: f64 = 0.1;
/// ... and this one on a net over obstacles, where a few nodes sliding over an obstacle hold the
/// residual up for tens of steps (measured on grids over a sphere: a fifth fewer steps than at 0.1).
pub const NET_CONTACT_CENTRING_FLOOR: f64 = 0.02;
/// Every Newton matrix is factored with at least this share of its largest diagonal entry added
/// to its diagonal, so that a semidefinite one does not meet a zero pivot ...
pub const SHIFT_FLOOR: f64 = 1e-14;
/// ... or this, about half the rounding of that entry, on a net without obstacles (see
/// [`Policy::shift_floor`]).
pub const FREE_NET_SHIFT_FLOOR: f64 = 1e-16;

/// When an interior point is ready for the polish.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolishReady {
    /// Once the KKT error is below the polish's threshold, or below `POLISH_STALLED` when the last
    /// interior-point step gained less than a factor 10 (a chain: the interior-point steps can only
    /// go so far, rounding in mu / s, so a stall triggers it too).
    ErrorOrStall,
    /// Once the KKT error is below the polish's threshold and every row has told whether it is
    /// active (a net: a wrong guess costs most, its polish correcting the active set a few links per
    /// step; a taut link without tension never tells, and such a net's answer is its interior
    /// point that meets the tolerance).
    ErrorAndDecided,
}

/// After a polish that failed, when the next may be tried.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolishRetry {
    /// Once the error has halved or the active set has changed.
    HalvedOrChanged,
    /// Once the error is ten times smaller (a net's active set changes at every step).
    Tenfold,
}

/// The stationarity residual that floors the barrier target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stationarity {
    /// The largest over the coordinates.
    Largest,
    /// The root mean square over the coordinates (a net without obstacles, a convex problem: a few
    /// nodes still falling, their links slack and their residual their whole weight, would hold up
    /// the barrier of the whole net, and they are caught only as it falls).
    RootMeanSquare,
}

/// The decisions of the iteration that depend on the kind of network.
#[derive(Clone, Debug)]
pub struct Policy {
    pub polish_ready: PolishReady,
    pub polish_retry: PolishRetry,
    /// A jam, neither the error nor the barrier moving for `STALL_WINDOW` steps (seen on nets near
    /// the answer, and where nodes slide over an obstacle), triggers the polish as a ready point
    /// does. (A chain's stalls are left to the polish its stall triggers.)
    pub jam_test: bool,
    /// The polish gives up at the first step that multiplies its error by `POLISH_DIVERGENCE` (a
    /// wrong active set: nodes left free to fly), unless it began near the answer: then the step is
    /// taken back, the rows it stretched join the set, and it tries again from where it began.
    pub polish_restarts: bool,
    /// Runs of touching rows along the structure lift off several rows at a time
    /// ([`crate::ipm::lifting_off`]): a chain's runs of touching nodes.
    pub lift_off_runs: bool,
    pub stationarity: Stationarity,
    /// The barrier target's floor, of the larger of stationarity and infeasibility.
    pub centring_floor: f64,
    /// The line search on the barrier merit first, the residual's after it (else the other way
    /// round): with obstacles, where the residual also has minima at saddles of the energy, and on
    /// nets, where the residual's full steps overshoot on the links' curvature.
    pub barrier_merit_first: bool,
    /// A full step the barrier merit refuses for the infeasibility the links' curvature adds is tried
    /// once more with a second-order correction before it is cut.
    pub second_order_correction: bool,
    /// What the net force left on the free nodes is divided by in the KKT error (without obstacles):
    /// 1, or the square root of the free nodes, the size of a sum of that many residuals of random
    /// sign (a net's interior point cannot push the sum lower at tens of thousands of nodes, and its
    /// polish does not converge where many taut links carry no tension).
    pub net_force_share: f64,
    /// The share of the Newton matrix's largest diagonal entry always added to its diagonal
    /// (SHIFT_FLOOR). A free net's is half that entry's rounding (FREE_NET_SHIFT_FLOOR): more damps
    /// the step along directions of small curvature, and near the answer of a large net, where the
    /// barrier's weights reach 1e13, the iteration then converges only linearly (316 x 316: 61 steps
    /// instead of 32). Over obstacles, whose curvature makes the matrix indefinite, that damping
    /// helps: without it a 200 x 200 net over a sphere stalls.
    pub shift_floor: f64,
    /// The most links at a free node for the second-order test's rounding bound, where it is known
    /// without counting: a chain's 2 (an end node's included, as the bound has always assumed).
    pub degree: Option<usize>,
}

impl Policy {
    /// A chain's: every link joins consecutive nodes.
    pub fn chain(network: &Network) -> Self {
        Policy {
            polish_ready: PolishReady::ErrorOrStall,
            polish_retry: PolishRetry::HalvedOrChanged,
            jam_test: false,
            polish_restarts: false,
            lift_off_runs: true,
            stationarity: Stationarity::Largest,
            centring_floor: CENTRING_FLOOR,
            barrier_merit_first: network.n_obstacles() > 0,
            second_order_correction: false,
            net_force_share: 1.0,
            shift_floor: SHIFT_FLOOR,
            degree: Some(2),
        }
    }

    /// A net's: links between any pairs of nodes.
    pub fn net(network: &Network) -> Self {
        let obstacles = network.n_obstacles() > 0;
        Policy {
            polish_ready: PolishReady::ErrorAndDecided,
            polish_retry: PolishRetry::Tenfold,
            jam_test: true,
            polish_restarts: true,
            lift_off_runs: false,
            stationarity: if obstacles {
                Stationarity::Largest
            } else {
                Stationarity::RootMeanSquare
            },
            centring_floor: if obstacles {
                NET_CONTACT_CENTRING_FLOOR
            } else {
                CENTRING_FLOOR
            },
            barrier_merit_first: true,
            second_order_correction: true,
            net_force_share: (network.n_free() as f64).sqrt(),
            shift_floor: if obstacles {
                SHIFT_FLOOR
            } else {
                FREE_NET_SHIFT_FLOOR
            },
            degree: None,
        }
    }
}
