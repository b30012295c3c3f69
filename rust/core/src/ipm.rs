//! A primal-dual interior-point method with an active-set polish, O(N) per step for a chain (a
//! net's Newton matrix is sparse), written once for both: generic over the [`Kind`] of network.
//!
//! In the solver's units (see [`crate::problem`]) the problem is
//!
//! ```text
//! minimize  sum_i load_i p_i[last axis]   over the free nodes,   s.t.  c(p) + s = 0,  s >= 0
//! ```
//!
//! with multipliers `mu >= 0`. Each step solves the Newton system of the perturbed KKT conditions
//! `grad E + J^T mu = 0`, `c + s = 0`, `S mu = sigma tau omega`, condensed onto the positions:
//!
//! ```text
//! (W + J^T Sigma J) dz = -(r_d + J^T (Sigma r_p - r_c / s)),   Sigma = diag(mu / s)
//! ```
//!
//! Step control: Mehrotra's predictor-corrector, fraction to the boundary 0.995, and a
//! backtracking line search on LOQO's barrier merit or on the norm of the perturbed KKT residual
//! (residual first on a chain without obstacles; barrier first with obstacles, where the residual
//! also has minima at saddles of the energy, and on nets, where the residual's full steps overshoot
//! on the links' curvature and backtracking cuts step after step to an eighth). On a net a full step
//! the barrier merit refuses for the infeasibility the links' curvature adds is tried once more
//! with a second-order correction before it is cut. Where the Newton
//! matrix is not positive definite a multiple of the identity is added until it is (inertia
//! correction).
//!
//! Barrier weights `omega`: a link's length, 1 for a contact. A link's slack is at most its length,
//! so an unweighted barrier pulls a link 100 times shorter than the others together with a force
//! that outweighs its tension long before tau is small; weighted, every link feels at most tau.
//!
//! Near the solution `Sigma ~ 1 / tau` amplifies rounding in the multipliers' update, so once the
//! active set shows (constraints whose multiplier outweighs their slack) the polish takes over: Newton
//! on the active-set KKT system `[W_A J_A^T; J_A 0]`, which has no `1 / s` (see [`crate::polish`]).

use crate::evaluate::NetworkMatrix;
use crate::evaluate::{kkt_error, kkt_parts, Point};
use crate::linalg::{BlockTridiagonal, Factorization, NewtonMatrix, SparseMatrix};
use std::time::Instant;

use crate::policy::{Policy, PolishReady, PolishRetry, Stationarity};
use crate::polish::{ChainPolish, NetPolish, PolishSolver};
use crate::problem::{Interrupted, Network, Statistics, NOT_FREE};

pub const STEP_TO_BOUNDARY: f64 = 0.995;
/// Per step, of the barrier merit's penalty: a penalty kept for good after one long step at a
/// massless node leaves the merit to the infeasibility alone; one reset every step loses the
/// feasibility of chains with mixed link lengths.
pub const PENALTY_DECAY: f64 = 100.0;
pub const ARMIJO: f64 = 1e-4;
pub const MAX_BACKTRACKS: usize = 40;
pub const INITIAL_MULTIPLIER: f64 = 1.0;
pub const MIN_INITIAL_SLACK: f64 = 1e-2;
/// Try the polish once the scaled KKT error is below this (ten times more without obstacles,
/// whose active set, the taut links, settles early) ...
pub const POLISH_FROM: f64 = 1e-8;
/// ... or below this when the interior-point steps stop gaining a factor 10.
pub const POLISH_STALLED: f64 = 1e-5;
pub const POLISH_STEPS: usize = 25;
pub const POLISH_PATIENCE: usize = 3;
pub const POLISH_CORRECTING: usize = 10;
/// Polish steps from a guess's active set (a coarser chain's answer) before the interior point.
pub const POLISH_FROM_GUESS: usize = 6;
/// Give up polishing when the KKT error grows by this factor.
pub const POLISH_DIVERGENCE: f64 = 1e3;
/// A row is undecided while its multiplier and slack are within this factor of each other.
pub const UNDECIDED: f64 = 100.0;
/// Every product `s_i mu_i` is kept within this factor of its share of the mean.
pub const CENTRALITY: f64 = 1e3;
/// A contact is active when its force exceeds this many node weights per link length of slack:
/// too large and a long chain's true contacts, still 1e-3 link lengths off the obstacle when the
/// iteration stalls, are missed; too small and hundreds of nodes near the lift-off points count
/// as touching.
pub const ACTIVE_CONTACT: f64 = 1e2;
/// A node X link lengths from the origin is placed to eps X link lengths only: this many such
/// errors may add up in one residual.
pub const ROUNDING_FLOOR: f64 = 4.0;
pub const WARM_SLACK: f64 = 1e-6;
/// A net's iteration is jammed when neither the error nor the barrier parameter has fallen below
/// STALL_PROGRESS of what it was STALL_WINDOW steps before.
pub const STALL_WINDOW: usize = 10;
pub const STALL_PROGRESS: f64 = 0.9;
/// A net's iteration that creeps near the answer ends as stalled (see `Progress::creeping`).
pub const CREEP_WINDOW: usize = 20;
/// ... or, once the error is below the polish's threshold, when it has not halved in STALL_WINDOW
/// steps (rows that stay undecided, taut links without tension, slow the steps to a crawl).
pub const CREEP: f64 = 0.5;
pub const WARM_CENTRING: f64 = 1e-8;
/// The iteration has diverged once some force exceeds this many times the weight (the solver's unit
/// of force) while its KKT error is DIVERGED_ERROR times the best one's: the multipliers of a
/// problem whose links cannot meet, or that is exactly taut where it carries weight, grow without
/// bound.
pub const DIVERGED_FORCE: f64 = 1e12;
pub const DIVERGED_ERROR: f64 = 1e6;
const TINY: f64 = f64::MIN_POSITIVE;

/// How an iteration ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Optimal,
    MaxIterations,
    Stalled,
    Nonfinite,
    /// The forces grew without bound: no equilibrium with finite forces was in reach.
    Diverged,
}

impl Status {
    pub fn name(self) -> &'static str {
        match self {
            Status::Optimal => "optimal",
            Status::MaxIterations => "max_iterations",
            Status::Stalled => "stalled",
            Status::Nonfinite => "nonfinite",
            Status::Diverged => "diverged",
        }
    }
}

/// Why an iteration stopped without an outcome.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Failure {
    /// The caller's obstacle evaluation or its interrupt check stopped it.
    Interrupted,
    /// The Newton matrix stayed indefinite under every inertia correction.
    NotFactored,
    /// An obstacle's phi or derivatives are not finite at a contact row of the start (or, after
    /// the iteration, of the result).
    ObstacleNotFinite {
        obstacle: usize,
        row: usize,
        at_start: bool,
    },
}

impl From<Interrupted> for Failure {
    fn from(_: Interrupted) -> Self {
        Failure::Interrupted
    }
}

/// The settings a solve may change.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Stop when every scaled KKT residual is below this (or below the rounding floor).
    pub tol: f64,
    pub max_iterations: usize,
}

/// Where the iteration ended.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub z: Vec<f64>,
    pub mu: Vec<f64>,
    /// Newton steps, interior-point and polish.
    pub iterations: usize,
    pub status: Status,
    pub point: Point,
}

/// Per-constraint constants.
pub struct Rows {
    /// Each row's multiplier per unit of force: 1, or `1 / l` for a squared link (`|grad c| = 2 l`
    /// when taut).
    pub units: Vec<f64>,
    /// Barrier weights: a link's length, 1 for a contact.
    pub weight: Vec<f64>,
    pub total_weight: f64,
    /// The active set's multiplier per unit of slack (`mu > s * unit`), each row in its natural
    /// unit: a link's tension against the weight and its slack against its length; a contact force
    /// against ACTIVE_CONTACT node weights.
    pub active_unit: Vec<f64>,
}

impl Rows {
    /// The barrier parameter of slacks `s` and multipliers `mu`: `s . mu` per unit of barrier weight
    /// (0 where there are no rows).
    pub fn mean_centring(&self, s: &[f64], mu: &[f64]) -> f64 {
        if self.total_weight > 0.0 {
            dot(s, mu) / self.total_weight
        } else {
            0.0
        }
    }

    pub fn new(network: &Network) -> Self {
        let m = network.n_constraints();
        let n_links = network.n_links();
        let mut units = vec![1.0; m];
        let mut weight = vec![1.0; m];
        for r in 0..n_links {
            weight[r] = network.lengths[r];
            if network.squared() {
                units[r] = 1.0 / network.lengths[r];
            }
        }
        let total_weight = weight.iter().sum();
        let mut active_unit = units.clone();
        for r in 0..n_links {
            active_unit[r] = units[r] * units[r] / network.lengths[r];
        }
        let loads: Vec<f64> = network.free.iter().map(|&node| network.load[node]).collect();
        let node_weight = if loads.iter().any(|&l| l > 0.0) {
            loads.iter().sum::<f64>() / loads.len() as f64
        } else {
            1.0 / network.n_free().max(1) as f64
        };
        for unit in &mut active_unit[n_links..] {
            *unit = node_weight * ACTIVE_CONTACT;
        }
        Rows {
            units,
            weight,
            total_weight,
            active_unit,
        }
    }
}

/// When the iteration may stop: every scaled KKT residual below `tol` or below the rounding floor,
/// whichever is larger. For the polish's points the floor of the force residuals is multiplied by
/// the largest force (in units of the weight, at least 1): a direction known to eps X turns a force
/// F into a residual of eps X F. A link's overstretch keeps the plain floor.
pub struct Tolerance {
    pub tol: f64,
    pub floor: f64,
    /// The net force's share in the KKT error (see [`Policy::net_force_share`]).
    pub net_force_share: f64,
}

impl Tolerance {
    pub fn new(network: &Network, tol: f64, net_force_share: f64) -> Self {
        Tolerance {
            tol,
            floor: rounding_floor(network),
            net_force_share,
        }
    }

    /// The largest scaled KKT residual at `point` with multipliers `mu` ([`kkt_error`]).
    pub fn error(&self, network: &Network, point: &Point, mu: &[f64]) -> f64 {
        kkt_error(network, point, mu, self.net_force_share)
    }

    pub fn plain(&self) -> f64 {
        self.tol.max(self.floor)
    }

    /// Whether the polished point is done, and its KKT error.
    pub fn check(&self, network: &Network, point: &Point, mu: &[f64], units: &[f64]) -> (bool, f64) {
        let (forces, lengths) = kkt_parts(network, point, mu, self.net_force_share);
        let error = if forces.is_nan() || lengths.is_nan() {
            f64::NAN
        } else {
            forces.max(lengths)
        };
        let plain = self.plain();
        if !(lengths <= plain) || !(forces > plain) {
            return (error <= plain, error);
        }
        let mut largest: f64 = 1.0;
        for (m, unit) in mu.iter().zip(units) {
            let force = m.abs() / unit;
            if force.is_nan() {
                return (false, error);
            }
            largest = largest.max(force);
        }
        (largest.is_finite() && forces <= self.floor * largest, error)
    }
}

/// The smallest scaled KKT residual floating point can certify: `ROUNDING_FLOOR eps X`, X the
/// farthest coordinate from the origin of the numbers, in link lengths. The iteration's numbers are
/// measured from the network's origin (a support), so where a structure stands does not change its
/// answer; only obstacles that the caller evaluates see the physical coordinates.
pub fn rounding_floor(network: &Network) -> f64 {
    let d = network.dim;
    let physical = !matches!(network.obstacles, crate::problem::ScaledObstacles::Quadratic(_));
    let mut extent: f64 = 0.0;
    for node in network.positions.chunks_exact(d) {
        for k in 0..d {
            let offset = if physical { network.origin[k] } else { 0.0 };
            extent = extent.max((node[k] + offset).abs());
        }
    }
    ROUNDING_FLOOR * f64::EPSILON * extent
}

/// The median of a non-empty slice (the mean of the middle two for an even count).
pub fn median(values: &[f64]) -> f64 {
    let mut ordered = values.to_vec();
    ordered.sort_by(|a, b| a.total_cmp(b));
    let middle = ordered.len() / 2;
    if ordered.len() % 2 == 1 {
        ordered[middle]
    } else {
        0.5 * (ordered[middle - 1] + ordered[middle])
    }
}

/// `max(x, floor)` that keeps a NaN (as numpy's maximum does).
fn at_least(x: f64, floor: f64) -> f64 {
    if x < floor {
        floor
    } else {
        x
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn all_finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

/// Largest alpha in (0, 1] with `values + alpha steps >= (1 - STEP_TO_BOUNDARY) values`.
fn step_to_boundary(values: &[f64], steps: &[f64]) -> f64 {
    let mut smallest = f64::INFINITY;
    for (v, s) in values.iter().zip(steps) {
        if *s < 0.0 {
            smallest = smallest.min(-v / s);
        }
    }
    (STEP_TO_BOUNDARY * smallest).min(1.0)
}

/// Slacks and multipliers without any knowledge of the forces (`c`: the constraint values). The
/// contacts start on the central path of the links' complementarity: a node far from an obstacle
/// gets a tiny contact force instead of one the size of the weight.
fn cold_start(network: &Network, c: &[f64], rows: &Rows) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let n_links = network.n_links();
    let mut mu: Vec<f64> = rows.units.iter().map(|u| INITIAL_MULTIPLIER * u).collect();
    let e = stretches(network, &mu);
    let s: Vec<f64> = c
        .iter()
        .zip(&e)
        .zip(rows.weight.iter().zip(&rows.units))
        .map(|((c, e), (w, u))| at_least(-(c - e), MIN_INITIAL_SLACK * w / u))
        .collect();
    if c.len() > n_links {
        let tau = if n_links > 0 {
            let centring: Vec<f64> = (0..n_links).map(|r| s[r] * mu[r] / rows.weight[r]).collect();
            median(&centring)
        } else {
            MIN_INITIAL_SLACK
        };
        for r in n_links..c.len() {
            mu[r] = INITIAL_MULTIPLIER.min(tau / s[r]);
        }
    }
    (s, mu, e)
}

/// Each row's stretch under the multipliers `mu`: `compliance mu` for an elastic link, 0 otherwise.
fn stretches(network: &Network, mu: &[f64]) -> Vec<f64> {
    mu.iter()
        .enumerate()
        .map(|(r, m)| network.row_compliance(r) * m)
        .collect()
}

/// Slacks and multipliers near a guess of the multipliers: every product `s_i mu_i` starts at
/// WARM_CENTRING, active rows keeping their multipliers, inactive ones their slacks.
fn warm_start(network: &Network, c: &[f64], rows: &Rows, guess: &[f64]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let e = stretches(network, guess);
    let mut s: Vec<f64> = c
        .iter()
        .zip(&e)
        .zip(rows.weight.iter().zip(&rows.units))
        .map(|((c, e), (w, u))| at_least(-(c - e), WARM_SLACK * w / u))
        .collect();
    let mu: Vec<f64> = guess
        .iter()
        .zip(s.iter().zip(&rows.weight))
        .map(|(g, (s, w))| at_least(*g, WARM_CENTRING * w / s))
        .collect();
    for ((s, m), w) in s.iter_mut().zip(&mu).zip(&rows.weight) {
        *s = at_least(*s, WARM_CENTRING * w / m);
    }
    (s, mu, e)
}

fn active_set(s: &[f64], mu: &[f64], unit: &[f64]) -> Vec<bool> {
    let mut active = Vec::with_capacity(mu.len());
    active_set_into(s, mu, unit, &mut active);
    active
}

/// The rows whose multiplier outweighs their slack (`mu > s unit`), into `active`.
fn active_set_into(s: &[f64], mu: &[f64], unit: &[f64], active: &mut Vec<bool>) {
    active.clear();
    active.extend(mu.iter().zip(s.iter().zip(unit)).map(|(m, (s, u))| *m > s * u));
}

/// Rows whose multiplier and slack are still within a factor UNDECIDED of each other (in the
/// rows' units): not yet clearly active (mu >> s) or clearly inactive (mu << s).
fn undecided_rows(s: &[f64], mu: &[f64], unit: &[f64]) -> usize {
    mu.iter()
        .zip(s.iter().zip(unit))
        .filter(|(m, (s, u))| {
            let ratio = *m / (*s * *u);
            ratio > 1.0 / UNDECIDED && ratio < UNDECIDED
        })
        .count()
}

/// The first contact row whose phi or derivatives are not finite, as (obstacle, row).
pub fn first_bad_contact(network: &Network, point: &Point) -> Option<(usize, usize)> {
    let n_obstacles = network.n_obstacles();
    if n_obstacles == 0 || matches!(network.obstacles, crate::problem::ScaledObstacles::Quadratic(_)) {
        return None; // (a quadratic with finite coefficients is finite wherever the chain is)
    }
    let d = network.dim;
    let rows = network.contact_rows();
    let n_links = network.n_links();
    let hessian_size = point.contact_hessian.len() / (n_obstacles * rows).max(1);
    for j in 0..n_obstacles {
        for r in 0..rows {
            let at = j * rows + r;
            let finite = point.c[n_links + at].is_finite()
                && all_finite(&point.contact_gradient[at * d..(at + 1) * d])
                && all_finite(&point.contact_hessian[at * hessian_size..(at + 1) * hessian_size]);
            if !finite {
                return Some((j, r));
            }
        }
    }
    None
}

/// The iterate: positions, slacks, multipliers and the point evaluated there.
#[derive(Clone, Default)]
struct State {
    z: Vec<f64>,
    s: Vec<f64>,
    mu: Vec<f64>,
    /// Each row's stretch: an elastic link's elongation, 0 for every other row.
    e: Vec<f64>,
    point: Point,
}

/// The linear algebra of one kind of network: its Newton matrix with the factorization, and the
/// polish's solver.
pub trait Kind {
    type Matrix: NetworkMatrix;
    type Polish: PolishSolver;
    /// What the iteration decides differently on this kind of network.
    fn policy(network: &Network) -> Policy;
    /// The polish's solver for the network whose Newton matrix is `matrix`.
    fn polish(matrix: &Self::Matrix) -> Self::Polish;
}

/// A chain's (every link joins consecutive nodes): block tridiagonal.
pub struct ChainKind;

impl Kind for ChainKind {
    type Matrix = BlockTridiagonal;
    type Polish = ChainPolish;

    fn policy(network: &Network) -> Policy {
        Policy::chain(network)
    }

    fn polish(_: &BlockTridiagonal) -> ChainPolish {
        ChainPolish::default()
    }
}

/// A net's (any graph): sparse, in a fill-reducing order.
pub struct NetKind;

impl Kind for NetKind {
    type Matrix = SparseMatrix;
    type Polish = NetPolish;

    fn policy(network: &Network) -> Policy {
        Policy::net(network)
    }

    fn polish(matrix: &SparseMatrix) -> NetPolish {
        NetPolish::new(matrix)
    }
}

/// The Newton matrix, its factors and the inertia correction carried from step to step.
struct Newton<M: NewtonMatrix> {
    matrix: M,
    factors: M::Factors,
    regularization: f64,
}

/// The driver: from the free coordinates `z` (flat) and, if given, a guess of the multipliers
/// (a coarser chain's answer, in the solver's units), iterate until the tolerance, the iteration
/// limit, a stall or a non-finite iterate. `check` is asked before every step whether to go on.
/// An obstacle that is not finite at the start or at the result is a `Failure`.
pub fn iterate<K: Kind>(
    network: &mut Network,
    settings: Settings,
    z: Vec<f64>,
    guess: Option<&[f64]>,
    check: &mut dyn FnMut() -> bool,
) -> Result<Outcome, Failure> {
    let started = Instant::now();
    let outcome = run::<K>(network, settings, z, guess, check);
    network.statistics.total_seconds += started.elapsed().as_secs_f64();
    let outcome = outcome?;
    if let Some((obstacle, row)) = first_bad_contact(network, &outcome.point) {
        return Err(Failure::ObstacleNotFinite {
            obstacle,
            row,
            at_start: false,
        });
    }
    Ok(outcome)
}

/// What stays fixed while the iteration runs: the policy of the network's kind, the rows'
/// constants and the stopping test.
pub struct Context {
    pub policy: Policy,
    pub rows: Rows,
    pub tolerance: Tolerance,
    /// The KKT error below which an interior point may be polished: POLISH_FROM, ten times more
    /// without obstacles (whose active set, the taut links, settles early).
    polish_from: f64,
}

impl Context {
    pub fn new(network: &Network, policy: Policy, tol: f64) -> Self {
        let polish_from = if network.n_obstacles() > 0 {
            POLISH_FROM
        } else {
            10.0 * POLISH_FROM
        };
        Context {
            rows: Rows::new(network),
            tolerance: Tolerance::new(network, tol, policy.net_force_share),
            policy,
            polish_from,
        }
    }
}

/// `iterate`'s loop.
fn run<K: Kind>(
    network: &mut Network,
    settings: Settings,
    z: Vec<f64>,
    guess: Option<&[f64]>,
    check: &mut dyn FnMut() -> bool,
) -> Result<Outcome, Failure> {
    let context = Context::new(network, K::policy(network), settings.tol);
    let matrix = K::Matrix::for_network(network);
    let mut solver = K::polish(&matrix);
    let mut state = match begin(network, &context, &mut solver, z, guess)? {
        Begun::Polished(outcome) => return Ok(outcome),
        Begun::At(state) => state,
    };
    let mut trial = State::default();
    let mut newton = Newton {
        factors: matrix.new_factors(),
        matrix,
        regularization: 0.0,
    };
    let mut progress = Progress::new();
    let mut work = Work::default();
    for iteration in 0..=settings.max_iterations {
        let ended = progress.look(
            network,
            &context,
            &mut solver,
            &mut state,
            &mut trial,
            iteration,
            check,
        )?;
        if let Some(outcome) = ended {
            return Ok(outcome);
        }
        if iteration == settings.max_iterations {
            break;
        }
        progress.penalty = f64::max(1.0, progress.penalty / PENALTY_DECAY);
        let penalty = &mut progress.penalty;
        let step = interior_point_step(
            network,
            &context,
            &mut state,
            &mut trial,
            &mut newton,
            penalty,
            &mut work,
        )?;
        match step {
            Step::Taken => {}
            Step::Nonfinite => return Ok(progress.best.or(state, iteration, Status::Nonfinite)),
            Step::NotFactored => return Err(Failure::NotFactored),
            Step::Stalled => return stalled(network, &context, &mut solver, state, progress.best, iteration),
        }
    }
    Ok(progress
        .best
        .or(state, settings.max_iterations, Status::MaxIterations))
}

/// How the iteration begins: polished already from the guess's active set, or at an iterate.
enum Begun {
    Polished(Outcome),
    At(State),
}

/// The first iterate: at `z` with slacks and multipliers from the guess `guess` (a coarser chain's
/// answer, which knows the active set: the polish from it first) or without it.
fn begin<P: PolishSolver>(
    network: &mut Network,
    context: &Context,
    solver: &mut P,
    z: Vec<f64>,
    guess: Option<&[f64]>,
) -> Result<Begun, Failure> {
    let m = network.n_constraints();
    let clipped: Vec<f64> = match guess {
        Some(g) => g.iter().map(|v| at_least(*v, 0.0)).collect(),
        None => vec![0.0; m],
    };
    let mut point = Point::default();
    network.evaluate(&z, &clipped, &mut point)?;
    if let Some((obstacle, row)) = first_bad_contact(network, &point) {
        return Err(Failure::ObstacleNotFinite {
            obstacle,
            row,
            at_start: true,
        });
    }
    let rows = &context.rows;
    let (s, mu, e) = match guess {
        Some(g) => {
            // A coarser chain's answer knows the active set (its taut links and touching nodes, to
            // a few nodes where the chain lifts off): polish from it before any interior-point step.
            // (Its point goes to the polish, which usually ends there: only the constraint values
            // are kept for the warm start.)
            let c = point.c.clone();
            let start = PolishStart {
                z: z.clone(),
                active: clipped.iter().map(|v| *v > 0.0).collect(),
                mu: clipped,
                slack: None,
                point: Some(std::mem::take(&mut point)),
            };
            if let Some(outcome) = polish(network, context, solver, start, POLISH_FROM_GUESS)? {
                return Ok(Begun::Polished(outcome));
            }
            warm_start(network, &c, rows, g)
        }
        None => cold_start(network, &point.c, rows),
    };
    network.evaluate(&z, &mu, &mut point)?;
    Ok(Begun::At(State { z, s, mu, e, point }))
}

/// What the loop carries from step to step besides the iterate.
struct Progress {
    /// After a failed polish: its active set and the error it started from.
    failed_polish: Option<(Vec<bool>, f64)>,
    previous_error: f64,
    /// The error and the barrier parameter at every step.
    history: Vec<(f64, f64)>,
    /// The iterate with the smallest KKT error, kept aside only once a later one is worse (it is
    /// then the one before, which the last step left in `trial`): a solve that ends without
    /// converging returns it, never a worse one.
    best: Best,
    /// The barrier merit's penalty.
    penalty: f64,
    /// The active set at the iterate.
    active: Vec<bool>,
}

impl Progress {
    fn new() -> Self {
        Progress {
            failed_polish: None,
            previous_error: f64::INFINITY,
            history: Vec::new(),
            best: Best::default(),
            penalty: 1.0,
            active: Vec::new(),
        }
    }

    /// The tests before a step at `state`: a non-finite iterate, an interrupt, divergence; the
    /// polish where the point is ready for it; the tolerance. The outcome where the iteration ends.
    #[allow(clippy::too_many_arguments)]
    fn look<P: PolishSolver>(
        &mut self,
        network: &mut Network,
        context: &Context,
        solver: &mut P,
        state: &mut State,
        trial: &mut State,
        iteration: usize,
        check: &mut dyn FnMut() -> bool,
    ) -> Result<Option<Outcome>, Failure> {
        let rows = &context.rows;
        if !(all_finite(&state.z) && all_finite(&state.mu) && all_finite(&state.s)) {
            return Ok(Some(self.end(state, iteration, Status::Nonfinite)));
        }
        if !check() {
            return Err(Failure::Interrupted);
        }
        let error = context.tolerance.error(network, &state.point, &state.mu);
        self.best.update(error, iteration > 0, trial);
        if self.best.kept.is_some()
            && error > DIVERGED_ERROR * self.best.error
            && largest_force(&state.mu, &rows.units) > DIVERGED_FORCE
        {
            return Ok(Some(self.end(state, iteration, Status::Diverged)));
        }
        let mut active = std::mem::take(&mut self.active);
        active_set_into(&state.s, &state.mu, &rows.active_unit, &mut active);
        if self.polish_now(context, state, error, &active) {
            let start = PolishStart {
                z: state.z.clone(),
                mu: state.mu.clone(),
                active: active.clone(),
                slack: Some(&state.s),
                point: None,
            };
            if let Some(outcome) = polish(network, context, solver, start, POLISH_STEPS)? {
                return Ok(Some(outcome.after(iteration)));
            }
            self.failed_polish = Some((active.clone(), error));
        }
        self.active = active;
        if error <= context.tolerance.plain() {
            let state = std::mem::take(state);
            return settle(network, context, solver, state, iteration).map(Some);
        }
        if self.creeping(context) {
            return Ok(Some(self.end(state, iteration, Status::Stalled)));
        }
        Ok(None)
    }

    /// Whether a net's iteration creeps near the answer: after a polish that failed, the best error
    /// of the last CREEP_WINDOW steps, below the polish's threshold, is no better than STALL_PROGRESS
    /// of the best of the CREEP_WINDOW steps before (the largest nets' residual creeps at a few times
    /// the tolerance for as long as the iteration limit lets it).
    fn creeping(&self, context: &Context) -> bool {
        let history = &self.history;
        if !context.policy.jam_test || self.failed_polish.is_none() || history.len() < 2 * CREEP_WINDOW {
            return false;
        }
        let best = |steps: &[(f64, f64)]| steps.iter().fold(f64::INFINITY, |m, &(error, _)| m.min(error));
        let recent = best(&history[history.len() - CREEP_WINDOW..]);
        let before = best(&history[history.len() - 2 * CREEP_WINDOW..history.len() - CREEP_WINDOW]);
        recent <= context.polish_from && recent > STALL_PROGRESS * before
    }

    /// The outcome of an iteration that ends at `state` with `status`: the best iterate.
    fn end(&mut self, state: &mut State, iterations: usize, status: Status) -> Outcome {
        std::mem::take(&mut self.best).or(std::mem::take(state), iterations, status)
    }

    /// Whether to polish at `state` (KKT error `error`, active set `active`): it is ready for it or
    /// jammed, and not too soon after a polish that failed. Polishing too early guesses the active
    /// set wrongly and wastes whole Newton steps (see [`PolishReady`]).
    fn polish_now(&mut self, context: &Context, state: &State, error: f64, active: &[bool]) -> bool {
        let (policy, rows, polish_from) = (&context.policy, &context.rows, context.polish_from);
        let retry = match (&self.failed_polish, policy.polish_retry) {
            (None, _) => true,
            (Some((_, failed_error)), PolishRetry::Tenfold) => error < failed_error / 10.0,
            (Some((set, failed_error)), PolishRetry::HalvedOrChanged) => {
                error < failed_error / 2.0 || set.as_slice() != active
            }
        };
        let ready = match policy.polish_ready {
            PolishReady::ErrorOrStall => {
                error <= polish_from || (error <= POLISH_STALLED && error > 0.1 * self.previous_error)
            }
            PolishReady::ErrorAndDecided => {
                error <= polish_from && undecided_rows(&state.s, &state.mu, &rows.active_unit) == 0
            }
        };
        self.previous_error = error;
        // Jammed: neither the error nor the barrier has moved for STALL_WINDOW steps. (Starting the
        // iteration again from a jammed point, slacks and multipliers afresh, only led back into
        // the jam.)
        let barrier = rows.mean_centring(&state.s, &state.mu);
        self.history.push((error, barrier));
        let history = &self.history;
        let jammed = policy.jam_test && history.len() > STALL_WINDOW && {
            let (old_error, old_barrier) = history[history.len() - 1 - STALL_WINDOW];
            (error > STALL_PROGRESS * old_error && barrier > STALL_PROGRESS * old_barrier)
                || (error <= polish_from && error > CREEP * old_error)
        };
        (ready || jammed) && retry
    }
}

/// An interior-point step that gained nothing: the polish from `state`'s active set, else the best
/// iterate, stalled.
fn stalled<P: PolishSolver>(
    network: &mut Network,
    context: &Context,
    solver: &mut P,
    state: State,
    best: Best,
    iteration: usize,
) -> Result<Outcome, Failure> {
    let start = PolishStart {
        z: state.z.clone(),
        mu: state.mu.clone(),
        active: active_set(&state.s, &state.mu, &context.rows.active_unit),
        slack: Some(&state.s),
        point: None,
    };
    if let Some(outcome) = polish(network, context, solver, start, POLISH_STEPS)? {
        return Ok(outcome.after(iteration));
    }
    Ok(best.or(state, iteration, Status::Stalled))
}

/// The iterate with the smallest KKT error so far, where it is not the current one.
#[derive(Default)]
struct Best {
    error: f64,
    kept: Option<State>,
}

impl Best {
    /// Takes the current iterate's `error`: the previous iterate, in `trial` when `stepped`, is kept
    /// when it was the best and this one is worse (or not a number).
    fn update(&mut self, error: f64, stepped: bool, trial: &mut State) {
        if !stepped || error < self.error || self.error.is_nan() {
            (self.error, self.kept) = (error, None);
        } else if self.kept.is_none() {
            self.kept = Some(std::mem::take(trial));
        }
    }

    /// The outcome of a solve that ends with `status` after `iterations`: the best iterate.
    fn or(self, current: State, iterations: usize, status: Status) -> Outcome {
        finish(self.kept.unwrap_or(current), iterations, status)
    }
}

/// The largest force among the multipliers, in the solver's unit of force.
fn largest_force(mu: &[f64], units: &[f64]) -> f64 {
    mu.iter().zip(units).map(|(m, u)| m / u).fold(0.0, f64::max)
}

/// An interior point that meets the tolerance, without what its barrier leaves in the rows that are
/// not active (their slack outweighs their multiplier, `tau / s`: no force): those multipliers are set
/// to 0 where the point still meets the tolerance without them; otherwise the polish from that
/// active set gives the answer; otherwise the point as it is.
fn settle<P: PolishSolver>(
    network: &mut Network,
    context: &Context,
    solver: &mut P,
    state: State,
    iterations: usize,
) -> Result<Outcome, Failure> {
    let (rows, tolerance) = (&context.rows, &context.tolerance);
    let active = active_set(&state.s, &state.mu, &rows.active_unit);
    if active.iter().all(|a| *a) {
        return Ok(finish(state, iterations, Status::Optimal));
    }
    let mu: Vec<f64> = state
        .mu
        .iter()
        .zip(&active)
        .map(|(m, a)| if *a { *m } else { 0.0 })
        .collect();
    let mut point = Point::default();
    network.evaluate(&state.z, &mu, &mut point)?;
    if tolerance.check(network, &point, &mu, &rows.units).0 {
        return Ok(Outcome {
            z: state.z,
            mu,
            iterations,
            status: Status::Optimal,
            point,
        });
    }
    let start = PolishStart {
        z: state.z.clone(),
        mu,
        active,
        slack: Some(&state.s),
        point: Some(point),
    };
    match polish(network, context, solver, start, POLISH_STEPS)? {
        Some(outcome) => Ok(outcome.after(iterations)),
        None => Ok(finish(state, iterations, Status::Optimal)),
    }
}

fn finish(state: State, iterations: usize, status: Status) -> Outcome {
    Outcome {
        z: state.z,
        mu: state.mu,
        iterations,
        status,
        point: state.point,
    }
}

enum Step {
    Taken,
    Nonfinite,
    NotFactored,
    Stalled,
}

/// Factor `matrix + delta I`, growing delta tenfold from a quarter of the last step's until it is
/// positive definite (inertia correction), plus `floor` times the largest diagonal entry. False if
/// no delta up to 1e20 times the largest diagonal entry does.
fn factor<M: NewtonMatrix>(newton: &mut Newton<M>, floor: f64, statistics: &mut Statistics) -> bool {
    let scale = newton.matrix.max_abs_diagonal().max(1e-300);
    let mut delta = if newton.regularization == 0.0 {
        0.0
    } else {
        newton.regularization / 4.0
    };
    loop {
        statistics.factorizations += 1;
        if newton
            .factors
            .factor_shifted(&newton.matrix, delta + floor * scale)
        {
            newton.regularization = if delta < 1e-12 * scale { 0.0 } else { delta };
            return true;
        }
        delta = f64::max(1e-10 * scale, 10.0 * delta);
        if !(delta <= 1e20 * scale) {
            return false;
        }
    }
}

/// (dz, ds, dmu, de) of the condensed Newton system for the complementarity residual `r_c`.
fn direction<M: NewtonMatrix>(
    network: &mut Network,
    state: &State,
    newton: &Newton<M>,
    r_c: &[f64],
    w: &mut Vec<f64>,
    out: &mut Direction,
) {
    let started = Instant::now();
    let (s, mu, point) = (&state.s, &state.mu, &state.point);
    w.clear();
    // An elastic row eliminates its stretch (`de = compliance (mu + dmu) - e`) as well as its
    // slack: its multiplier's step is `sigma (J dz + c + s - compliance mu - r_c / mu)` with the
    // condensed `sigma = mu / (s + compliance mu)` (see `condensed`).
    w.extend((0..s.len()).map(|r| match network.row_compliance(r) {
        0.0 => (mu[r] / s[r]) * (point.c[r] + s[r]) - r_c[r] / s[r],
        compliance => {
            condensed(network, state, r) * (point.c[r] + s[r] - compliance * mu[r] - r_c[r] / mu[r])
        }
    }));
    let Direction { dz, ds, dmu, de } = out;
    zeroed(dz, point.dual.len());
    network.add_transpose_times(point, w, dz);
    for (value, dual) in dz.iter_mut().zip(&point.dual) {
        *value = -(dual + *value);
    }
    newton.factors.solve_in_place(dz);
    zeroed(dmu, s.len());
    zeroed(ds, s.len());
    zeroed(de, s.len());
    for r in 0..s.len() {
        let product = network.row_times(point, r, dz);
        match network.row_compliance(r) {
            0.0 => dmu[r] = (mu[r] / s[r]) * (product + (point.c[r] + s[r])) - r_c[r] / s[r],
            compliance => {
                dmu[r] = condensed(network, state, r) * product + w[r];
                de[r] = compliance * (mu[r] + dmu[r]) - state.e[r];
            }
        }
        ds[r] = -(r_c[r] + s[r] * dmu[r]) / mu[r];
    }
    network.statistics.newton_seconds += started.elapsed().as_secs_f64();
}

/// Row r's weight in the condensed Newton matrix `W + J^T Sigma J`: `mu / s`, or for an elastic link
/// `mu / (s + compliance mu)`, which tends to its stiffness `1 / compliance` as the link turns taut.
fn condensed(network: &Network, state: &State, r: usize) -> f64 {
    state.mu[r] / (state.s[r] + network.row_compliance(r) * state.mu[r])
}

/// `vector` as `len` zeros, in its storage.
fn zeroed(vector: &mut Vec<f64>, len: usize) {
    vector.clear();
    vector.resize(len, 0.0);
}

/// A Newton direction: positions, slacks, multipliers and the elastic links' stretches.
#[derive(Default)]
struct Direction {
    dz: Vec<f64>,
    ds: Vec<f64>,
    dmu: Vec<f64>,
    de: Vec<f64>,
}

/// The interior-point steps' work vectors, allocated at the first step and reused by the others.
#[derive(Default)]
struct Work {
    /// The condensed weights (see [`condensed`]), the products `s mu`, their targets and the
    /// complementarity residual.
    sigma: Vec<f64>,
    products: Vec<f64>,
    targets: Vec<f64>,
    r_c: Vec<f64>,
    /// The weights of `J^T` in the right-hand side.
    w: Vec<f64>,
    /// Mehrotra's predictor (the affine direction) and the step.
    affine: Direction,
    step: Direction,
    correction: CorrectionWork,
}

/// The second-order correction's work vectors (see [`second_order_correction`]).
#[derive(Default)]
struct CorrectionWork {
    excess: Vec<f64>,
    weighted: Vec<f64>,
    correction: Vec<f64>,
    slacks: Vec<f64>,
}

/// The step's factors and the work vectors for a second-order correction.
struct Correcting<'a, M: NewtonMatrix> {
    newton: &'a Newton<M>,
    work: &'a mut CorrectionWork,
}

/// The barrier target of a step from `state` (barrier parameter `tau`) after Mehrotra's predictor
/// (the `affine` direction): how far the pure Newton step would bring the products `s mu` down
/// decides how much to centre.
fn centring_target(policy: &Policy, state: &State, affine: &Direction, tau: f64, total_weight: f64) -> f64 {
    let (ds_a, dmu_a) = (&affine.ds, &affine.dmu);
    let alpha_p = step_to_boundary(&state.s, ds_a);
    let alpha_d = step_to_boundary(&state.mu, dmu_a);
    let mut tau_affine = 0.0;
    for r in 0..state.s.len() {
        tau_affine += (state.s[r] + alpha_p * ds_a[r]) * (state.mu[r] + alpha_d * dmu_a[r]);
    }
    tau_affine /= total_weight.max(f64::MIN_POSITIVE); // (0 without rows)
    let target = if tau > 0.0 {
        f64::min(1.0, (tau_affine / tau).powi(3)) * tau
    } else {
        0.0
    };
    // Do not let the barrier fall faster than the iterate approaches stationarity and feasibility:
    // on non-convex obstacles an aggressive target jams the slacks against their bounds.
    let stationarity = match policy.stationarity {
        Stationarity::Largest => state.point.dual.iter().fold(0.0_f64, |a, v| a.max(v.abs())),
        Stationarity::RootMeanSquare => {
            let squares: f64 = state.point.dual.iter().map(|v| v * v).sum();
            (squares / state.point.dual.len().max(1) as f64).sqrt()
        }
    };
    let largest_c = state
        .point
        .c
        .iter()
        .zip(&state.e)
        .fold(0.0_f64, |a, (c, e)| a.max(c - e));
    target.max(tau.min(policy.centring_floor * stationarity.max(largest_c)))
}

/// One predictor-corrector step from `state`, into `state` if taken (`trial` is scratch).
fn interior_point_step<M: NewtonMatrix>(
    network: &mut Network,
    context: &Context,
    state: &mut State,
    trial: &mut State,
    newton: &mut Newton<M>,
    penalty: &mut f64,
    work: &mut Work,
) -> Result<Step, Failure> {
    let (rows, policy) = (&context.rows, &context.policy);
    let sigma = &mut work.sigma;
    sigma.clear();
    sigma.extend((0..state.s.len()).map(|r| condensed(network, state, r)));
    if !all_finite(sigma) {
        return Ok(Step::Nonfinite);
    }
    network.statistics.interior_point_steps += 1;
    let started = Instant::now();
    network.newton_matrix(&state.point, &state.mu, sigma, &mut newton.matrix);
    if !newton.matrix.is_finite() {
        return Ok(Step::Nonfinite); // an obstacle's infinite gradient or curvature here
    }
    let factored = factor(newton, policy.shift_floor, &mut network.statistics);
    network.statistics.newton_seconds += started.elapsed().as_secs_f64();
    if !factored {
        return Ok(Step::NotFactored);
    }
    let total_weight = rows.total_weight;
    let tau = rows.mean_centring(&state.s, &state.mu);

    // Mehrotra predictor: the pure Newton (affine) step decides how much to centre.
    let products = &mut work.products;
    products.clear();
    products.extend(state.s.iter().zip(&state.mu).map(|(s, m)| s * m));
    direction(network, state, newton, products, &mut work.w, &mut work.affine);
    let target = centring_target(policy, state, &work.affine, tau, total_weight);
    let targets = &mut work.targets;
    targets.clear();
    targets.extend(rows.weight.iter().map(|w| target * w));

    // (which merit first: see the module's documentation)
    let barrier_merit_first = policy.barrier_merit_first;
    for corrected in [true, false] {
        let Work {
            products,
            targets,
            r_c,
            w,
            affine,
            step,
            correction,
            ..
        } = &mut *work;
        r_c.clear();
        r_c.extend((0..products.len()).map(|r| {
            products[r]
                + if corrected {
                    affine.ds[r] * affine.dmu[r]
                } else {
                    0.0
                }
                - targets[r]
        }));
        direction(network, state, newton, r_c, w, step);
        for barrier_first in [true, false] {
            let accepted = if barrier_first == barrier_merit_first {
                let correcting = policy.second_order_correction.then_some(Correcting {
                    newton,
                    work: &mut *correction,
                });
                barrier_line_search(network, state, trial, step, targets, penalty, correcting)?
            } else {
                residual_line_search(network, state, trial, step, targets)?
            };
            if accepted {
                std::mem::swap(state, trial);
                let tau_new = rows.mean_centring(&state.s, &state.mu);
                for r in 0..state.mu.len() {
                    let low = rows.weight[r] * tau_new / (CENTRALITY * state.s[r]);
                    let high = CENTRALITY * rows.weight[r] * tau_new / state.s[r];
                    state.mu[r] = at_least(state.mu[r], low).min(high);
                }
                return Ok(Step::Taken);
            }
        }
    }
    Ok(Step::Stalled)
}

fn energy(network: &Network, positions: &[f64]) -> f64 {
    let d = network.dim;
    let weights: f64 = network
        .load
        .iter()
        .zip(positions.chunks_exact(d))
        .map(|(load, p)| load * p[d - 1])
        .sum();
    let loads: f64 = network
        .point_loads
        .iter()
        .zip(positions)
        .map(|(load, p)| load * p)
        .sum();
    weights - loads
}

/// `||c + s - e||^2` (e: the elastic links' stretches, 0 elsewhere).
fn infeasibility(c: &[f64], s: &[f64], e: &[f64]) -> f64 {
    c.iter()
        .zip(s)
        .zip(e)
        .map(|((c, s), e)| (c + s - e) * (c + s - e))
        .sum()
}

/// The elastic links' energy, `sum e^2 / (2 compliance)` over the elastic rows.
fn elastic_energy(network: &Network, e: &[f64]) -> f64 {
    network
        .compliance
        .iter()
        .zip(e)
        .filter(|(c, _)| **c > 0.0)
        .map(|(c, e)| 0.5 * e * e / c)
        .sum()
}

/// LOQO's merit: energy - sum(tau_i log s_i) + penalty/2 ||c + s - e||^2, the energy with the
/// elastic links' own.
fn merit(network: &Network, state: &State, tau: &[f64], penalty: f64, infeasibility: f64) -> f64 {
    let barrier: f64 = tau.iter().zip(&state.s).map(|(t, s)| t * s.ln()).sum();
    energy(network, &state.point.positions) + elastic_energy(network, &state.e) - barrier
        + 0.5 * penalty * infeasibility
}

/// Backtrack the primal step on the barrier merit; the dual takes its full step to the boundary.
/// The penalty grows until the step is a descent direction. With the step's factors in `correction`
/// (a net), a full step that the merit refuses for the infeasibility it adds is tried once more
/// with a second-order correction ([`second_order_correction`]) before it is cut.
fn barrier_line_search<M: NewtonMatrix>(
    network: &mut Network,
    state: &State,
    trial: &mut State,
    step: &Direction,
    tau: &[f64],
    penalty: &mut f64,
    mut correction: Option<Correcting<'_, M>>,
) -> Result<bool, Failure> {
    let Direction { dz, ds, dmu, de } = step;
    let d = network.dim;
    let alpha_p = step_to_boundary(&state.s, ds);
    let alpha_d = step_to_boundary(&state.mu, dmu);
    let infeasible = infeasibility(&state.point.c, &state.s, &state.e);
    let mut slope_barrier = 0.0;
    for (f, &node) in network.free.iter().enumerate() {
        for k in 0..d {
            slope_barrier += network.energy_gradient(node, k) * dz[f * d + k];
        }
    }
    for (r, compliance) in network.compliance.iter().enumerate() {
        if *compliance > 0.0 {
            slope_barrier += state.e[r] / compliance * de[r];
        }
    }
    let barrier_slope: f64 = (0..state.s.len()).map(|r| tau[r] * (ds[r] / state.s[r])).sum();
    slope_barrier -= barrier_slope;
    if slope_barrier > 0.0 && infeasible > 0.0 {
        *penalty = penalty.max(10.0 * slope_barrier / infeasible);
    }
    let slope = slope_barrier - *penalty * infeasible;
    let current = merit(network, state, tau, *penalty, infeasible);
    trial.mu.clear();
    trial
        .mu
        .extend(state.mu.iter().zip(dmu).map(|(m, dm)| m + alpha_d * dm));
    let mut fraction = 1.0;
    for _ in 0..MAX_BACKTRACKS {
        let alpha = fraction * alpha_p;
        trial.z.clear();
        trial
            .z
            .extend(state.z.iter().zip(dz).map(|(z, dz)| z + alpha * dz));
        trial.s.clear();
        trial.s.extend(
            state
                .s
                .iter()
                .zip(ds)
                .map(|(s, ds)| at_least(s + alpha * ds, TINY)),
        );
        trial.e.clear();
        trial
            .e
            .extend(state.e.iter().zip(de).map(|(e, de)| e + alpha * de));
        // (Armijo's condition on the merit at the trial point, evaluated; and the trial's infeasibility)
        let accepted = |network: &mut Network, trial: &mut State| -> Result<(bool, f64), Failure> {
            network.evaluate(&trial.z, &trial.mu, &mut trial.point)?;
            let infeasible = infeasibility(&trial.point.c, &trial.s, &trial.e);
            let value = merit(network, trial, tau, *penalty, infeasible);
            Ok((
                value.is_finite() && value <= current + ARMIJO * alpha * slope.min(0.0),
                infeasible,
            ))
        };
        let (taken, trial_infeasible) = accepted(network, trial)?;
        if taken {
            return Ok(true);
        }
        if let (Some(correcting), true) = (
            correction.as_mut(),
            fraction == 1.0 && trial_infeasible > infeasible,
        ) {
            // (refused too, the next cut refills the trial's positions and slacks from `state`)
            if second_order_correction(network, state, trial, dz, alpha, correcting)
                && accepted(network, trial)?.0
            {
                return Ok(true);
            }
        }
        fraction *= 0.5;
    }
    Ok(false)
}

/// The trial point of a full step, corrected for the constraints' curvature: `e`, what the
/// constraint values at the trial point exceed their linear prediction by (a straight step stretches
/// every taut link it turns), taken out by one more solve with the step's factors, `dz = -K^-1 J^T
/// Sigma e`, the slacks taking the rest, so that `c + s` keeps its linear prediction: the trial's
/// positions and slacks corrected in place. False, the trial untouched, if a slack would come
/// closer to its bound than the fraction to the boundary allows.
fn second_order_correction<M: NewtonMatrix>(
    network: &Network,
    state: &State,
    trial: &mut State,
    dz: &[f64],
    alpha: f64,
    correcting: &mut Correcting<'_, M>,
) -> bool {
    let (point, rows) = (&state.point, state.s.len());
    let CorrectionWork {
        excess,
        weighted,
        correction,
        slacks,
    } = &mut *correcting.work;
    excess.clear();
    excess.extend((0..rows).map(|r| trial.point.c[r] - point.c[r] - alpha * network.row_times(point, r, dz)));
    weighted.clear();
    weighted.extend((0..rows).map(|r| condensed(network, state, r) * excess[r]));
    zeroed(correction, dz.len());
    network.add_transpose_times(point, weighted, correction);
    correcting.newton.factors.solve_in_place(correction);
    slacks.clear();
    for r in 0..rows {
        let slack = trial.s[r] - excess[r] + network.row_times(point, r, correction);
        if !(slack >= (1.0 - STEP_TO_BOUNDARY) * state.s[r]) {
            return false;
        }
        slacks.push(slack);
    }
    for (z, c) in trial.z.iter_mut().zip(correction.iter()) {
        *z -= c;
    }
    trial.s.copy_from_slice(slacks);
    true
}

/// Squared norm of the perturbed KKT residual (with the elastic links' law, `e = compliance mu`).
fn residual_merit(network: &Network, state: &State, target: &[f64]) -> f64 {
    let (point, s, mu) = (&state.point, &state.s, &state.mu);
    let stationarity: f64 = point.dual.iter().map(|v| v * v).sum();
    let complementarity: f64 = (0..s.len()).map(|r| (s[r] * mu[r] - target[r]).powi(2)).sum();
    let elastic: f64 = network
        .compliance
        .iter()
        .enumerate()
        .map(|(r, c)| (state.e[r] - c * mu[r]).powi(2))
        .sum();
    stationarity + infeasibility(&point.c, s, &state.e) + complementarity + elastic
}

/// Backtrack primal and dual steps together until the perturbed KKT residual decreases.
fn residual_line_search(
    network: &mut Network,
    state: &State,
    trial: &mut State,
    step: &Direction,
    target: &[f64],
) -> Result<bool, Failure> {
    let Direction { dz, ds, dmu, de } = step;
    let alpha_p = step_to_boundary(&state.s, ds);
    let alpha_d = step_to_boundary(&state.mu, dmu);
    let current = residual_merit(network, state, target);
    let mut fraction = 1.0;
    for _ in 0..MAX_BACKTRACKS {
        trial.z.clear();
        trial
            .z
            .extend(state.z.iter().zip(dz).map(|(z, dz)| z + fraction * alpha_p * dz));
        trial.s.clear();
        trial.s.extend(
            state
                .s
                .iter()
                .zip(ds)
                .map(|(s, ds)| at_least(s + fraction * alpha_p * ds, TINY)),
        );
        trial.mu.clear();
        trial.mu.extend(
            state
                .mu
                .iter()
                .zip(dmu)
                .map(|(m, dm)| m + fraction * alpha_d * dm),
        );
        trial.e.clear();
        trial
            .e
            .extend(state.e.iter().zip(de).map(|(e, de)| e + fraction * alpha_p * de));
        network.evaluate(&trial.z, &trial.mu, &mut trial.point)?;
        let value = residual_merit(network, trial, target);
        if value.is_finite() && value <= (1.0 - ARMIJO * fraction) * current {
            return Ok(true);
        }
        fraction *= 0.5;
    }
    Ok(false)
}

/// The polish's result: an Optimal outcome whose iterations are its own steps.
type Polished = Option<Outcome>;

impl Outcome {
    /// The same outcome after `steps` earlier Newton steps.
    fn after(mut self, steps: usize) -> Self {
        self.iterations += steps;
        self
    }
}

/// Where a polish starts: the iterate's positions `z`, multipliers `mu` and active set; the interior
/// point's slacks, if it comes from one (its active set is then [`anchor`]ed first); the point
/// evaluated at `z` with `mu` off the active set zeroed, if it is known.
pub struct PolishStart<'a> {
    pub z: Vec<f64>,
    pub mu: Vec<f64>,
    pub active: Vec<bool>,
    pub slack: Option<&'a [f64]>,
    pub point: Option<Point>,
}

/// Newton on the active-set KKT system, with active-set corrections: a row the step violates joins
/// the set, one whose multiplier turns negative leaves it (at a run of touching nodes, as many as
/// [`lifting_off`] says, where the policy lifts off runs). Stops at the first point that meets the
/// tolerance and returns it with its step count; `None` if none does. Counting only steps that kept
/// the active set, it gives up after two that multiply the error by POLISH_DIVERGENCE or
/// POLISH_PATIENCE that never beat the starting error; after `max_steps`; and after
/// POLISH_CORRECTING steps of any kind that never beat it (where the policy restarts: after the
/// first step that multiplies it by POLISH_DIVERGENCE, or it begins again: see `Restarts`).
pub fn polish<P: PolishSolver>(
    network: &mut Network,
    context: &Context,
    solver: &mut P,
    start: PolishStart,
    max_steps: usize,
) -> Result<Polished, Failure> {
    let (rows, tolerance) = (&context.rows, &context.tolerance);
    let PolishStart {
        mut z,
        mut mu,
        mut active,
        slack,
        point,
    } = start;
    if let Some(slack) = slack {
        anchor(network, slack, &rows.weight, &mut active);
    }
    for (m, a) in mu.iter_mut().zip(&active) {
        if !a {
            *m = 0.0;
        }
    }
    let mut point = match point {
        Some(point) => point,
        None => {
            let mut point = Point::default();
            network.evaluate(&z, &mu, &mut point)?;
            point
        }
    };
    let start_error = tolerance.error(network, &point, &mu);
    let mut restarts = (context.policy.polish_restarts && start_error <= POLISH_STALLED).then(|| Restarts {
        z: z.clone(),
        mu: mu.clone(),
        point: point.clone(),
        count: 0,
    });
    let mut judge = Judge::new(start_error);
    let plain = tolerance.plain();
    let (mut leaving, mut joining) = (Vec::new(), Vec::new());
    for steps in 1..=max_steps {
        let started = Instant::now();
        let stepped = solver.step(network, &point, &mut z, &mut mu, &active);
        network.statistics.polish_steps += 1;
        network.statistics.polish_seconds += started.elapsed().as_secs_f64();
        if !stepped {
            break;
        }
        network.evaluate(&z, &mu, &mut point)?;
        let (done, error) = tolerance.check(network, &point, &mu, &rows.units);
        if done {
            return Ok(Some(Outcome {
                z,
                mu,
                iterations: steps,
                status: Status::Optimal,
                point,
            }));
        }
        judge.best_error = judge.best_error.min(error);
        if steps >= POLISH_CORRECTING && !(judge.best_error < start_error) {
            break;
        }
        leaving.clear();
        leaving.extend(active.iter().zip(&mu).map(|(a, m)| *a && *m < 0.0));
        joining.clear();
        joining.extend(active.iter().zip(&point.c).map(|(a, c)| !*a && *c > plain));
        if context.policy.polish_restarts && !(error < POLISH_DIVERGENCE * start_error) {
            let Some(restarts) = &mut restarts else {
                break;
            };
            if !restarts.again(network, rows, slack, &joining, &leaving, &mut active) {
                break;
            }
            (z, mu, point) = restarts.from();
            continue;
        }
        // Judge the guess only on steps that kept the active set: while it is still being corrected
        // the error says little.
        if !leaving.iter().zip(&joining).any(|(l, j)| *l || *j) && judge.gives_up(error) {
            break;
        }
        if context.policy.lift_off_runs {
            lift_off_runs(network, &active, &mu, &joining, &mut leaving);
        }
        for r in 0..active.len() {
            active[r] = (active[r] || joining[r]) && !leaving[r];
            if !active[r] {
                mu[r] = 0.0;
            }
        }
    }
    Ok(None)
}

/// The polish's verdict on its own progress, from steps that kept the active set.
struct Judge {
    start_error: f64,
    best_error: f64,
    /// Steps in a row that multiplied the error by POLISH_DIVERGENCE.
    diverging: usize,
    /// Steps that kept the active set.
    settled: usize,
}

impl Judge {
    fn new(start_error: f64) -> Self {
        Judge {
            start_error,
            best_error: f64::INFINITY,
            diverging: 0,
            settled: 0,
        }
    }

    /// After a step that kept the active set with KKT error `error`: whether to give up.
    fn gives_up(&mut self, error: f64) -> bool {
        self.settled += 1;
        self.diverging = if !(error < POLISH_DIVERGENCE * self.start_error) {
            self.diverging + 1
        } else {
            0
        };
        self.diverging == 2 || (self.settled >= POLISH_PATIENCE && !(self.best_error < self.start_error))
    }
}

/// Where a polish that began near the answer (a few rows misjudged) begins again after a step that
/// multiplied the error by POLISH_DIVERGENCE (a net's polish step costs several Newton steps: a
/// wrong active set, nodes left free to fly, is given up at once): the step is taken back, the rows
/// it stretched join the set, and the step is tried again, POLISH_PATIENCE times at most.
struct Restarts {
    z: Vec<f64>,
    mu: Vec<f64>,
    point: Point,
    count: usize,
}

impl Restarts {
    /// The active set corrected for another try (`joining`, `leaving`), anchored again from the
    /// interior point's `slack`; false where there is nothing to correct or no try left.
    fn again(
        &mut self,
        network: &Network,
        rows: &Rows,
        slack: Option<&[f64]>,
        joining: &[bool],
        leaving: &[bool],
        active: &mut [bool],
    ) -> bool {
        if !joining.iter().any(|j| *j) || self.count == POLISH_PATIENCE {
            return false;
        }
        self.count += 1;
        for ((a, j), l) in active.iter_mut().zip(joining).zip(leaving) {
            *a = (*a || *j) && !*l;
        }
        if let Some(slack) = slack {
            anchor(network, slack, &rows.weight, active);
        }
        true
    }

    /// The iterate the polish began from.
    fn from(&self) -> (Vec<f64>, Vec<f64>, Point) {
        (self.z.clone(), self.mu.clone(), self.point.clone())
    }
}

/// `leaving` with, at each end of a run of touching rows along the structure, as many rows as
/// [`lifting_off`] says (a row the step pushed inside stays in).
fn lift_off_runs(network: &Network, active: &[bool], mu: &[f64], joining: &[bool], leaving: &mut [bool]) {
    let n_links = network.n_links();
    if !leaving[n_links..].iter().any(|l| *l) {
        return;
    }
    let lifting = lifting_off(
        &active[n_links..],
        &mu[n_links..],
        &leaving[n_links..],
        network.contact_rows(),
    );
    for (r, lift) in lifting.into_iter().enumerate() {
        leaving[n_links + r] = lift && !joining[n_links + r];
    }
}

/// Rows joined to the active set `active` until every group of free nodes that carries a load reaches a
/// support or an obstacle through active rows: each such group that does not gets its row of smallest
/// `slack` (per unit of barrier `weight`: a link's length) that holds it, the link to a node outside it
/// or a contact of one of its nodes. A light node on a link judged slack is such a group, and
/// nothing in the active-set KKT system would hold it: the polish's step would send it off.
pub fn anchor(network: &Network, slack: &[f64], weight: &[f64], active: &mut [bool]) {
    if network.contact_links() {
        return; // (rows along links: a chain's, whose polish has its own correction)
    }
    let (n, n_free, n_links) = (network.n_nodes(), network.n_free(), network.n_links());
    let d = network.dim;
    let loaded: Vec<bool> = (0..n)
        .map(|node| (0..d).any(|k| network.energy_gradient(node, k) != 0.0))
        .collect();
    loop {
        // groups of nodes joined by active links; a fixed node, or a free one with an active contact, anchors its group
        let mut group: Vec<usize> = (0..n).collect();
        fn root(group: &mut [usize], mut i: usize) -> usize {
            while group[i] != i {
                group[i] = group[group[i]];
                i = group[i];
            }
            i
        }
        for (k, &[a, b]) in network.links.iter().enumerate() {
            if active[k] {
                let (ra, rb) = (root(&mut group, a), root(&mut group, b));
                group[ra.max(rb)] = ra.min(rb);
            }
        }
        let mut held = vec![false; n];
        let mut carries = vec![false; n];
        for node in 0..n {
            let r = root(&mut group, node);
            held[r] |= network.free_index[node] == NOT_FREE;
            carries[r] |= loaded[node];
        }
        for (row, &on) in active.iter().enumerate().skip(n_links) {
            if on {
                let node = network.free[(row - n_links) % n_free];
                let r = root(&mut group, node);
                held[r] = true;
            }
        }
        // each floating loaded group's row of smallest slack that would hold it
        let mut best: Vec<Option<(f64, usize)>> = vec![None; n];
        let offer = |r: usize, row: usize, best: &mut Vec<Option<(f64, usize)>>| {
            let value = slack[row] / weight[row];
            if best[r].is_none_or(|(v, _)| value < v) {
                best[r] = Some((value, row));
            }
        };
        for (k, &[a, b]) in network.links.iter().enumerate() {
            if !active[k] {
                let (ra, rb) = (root(&mut group, a), root(&mut group, b));
                if ra != rb {
                    for r in [ra, rb] {
                        if carries[r] && !held[r] {
                            offer(r, k, &mut best);
                        }
                    }
                }
            }
        }
        for row in n_links..active.len() {
            if !active[row] {
                let r = root(&mut group, network.free[(row - n_links) % n_free]);
                if carries[r] && !held[r] {
                    offer(r, row, &mut best);
                }
            }
        }
        let mut joined = false;
        for (_, row) in best.into_iter().flatten() {
            active[row] = true;
            joined = true;
        }
        if !joined {
            return;
        }
    }
}

/// `leaving` (obstacle by obstacle, `rows` each) with, at each end of a run of touching rows, as
/// many rows as the end's negative force says the run is too long.
///
/// Where a chain lifts off an obstacle, a run of touching nodes k nodes too long holds the chain on
/// the obstacle over those k nodes, and only its last node feels it: its force is the kink's,
/// `nu_end = nu_0 (1 - k)` in units of the force `nu_0` on the touching nodes just inside. Dropping
/// `floor(1 - nu_end / nu_0)` nodes at once finds the lift-off point in one step instead of one node
/// per step (rounded down: one too few costs a step, one too many lets the chain sag into the
/// obstacle). A leaving node inside a run, or without touching neighbours to compare with, leaves
/// alone; no more than half the run leaves at once.
pub fn lifting_off(active: &[bool], nu: &[f64], leaving: &[bool], rows: usize) -> Vec<bool> {
    let mut lifting = leaving.to_vec();
    if rows == 0 {
        return lifting;
    }
    for j in 0..active.len() / rows {
        let base = j * rows;
        let mut f = 0;
        while f < rows {
            if !active[base + f] {
                f += 1;
                continue;
            }
            let a = f;
            while f < rows && active[base + f] {
                f += 1;
            }
            let b = f - 1;
            if !(a < b && (leaving[base + a] || leaving[base + b])) {
                continue;
            }
            for from_first in [true, false] {
                let end = if from_first { a } else { b };
                // the touching nodes 2..11 inside the end
                let (low, high) = if from_first {
                    (a + 2, (a + 12).min(b + 1))
                } else {
                    ((b.saturating_sub(11)).max(a), b.saturating_sub(1))
                };
                let reference = if low < high {
                    median(&nu[base + low..base + high])
                } else {
                    0.0
                };
                if leaving[base + end] && reference > 0.0 {
                    let limit = (b - a).div_ceil(2) as f64; // half the run, rounded down
                    let drop = ((1.0 - nu[base + end] / reference).min(limit) as usize).max(1);
                    for i in 0..drop {
                        lifting[base + if from_first { a + i } else { b - i }] = true;
                    }
                }
            }
        }
    }
    lifting
}
