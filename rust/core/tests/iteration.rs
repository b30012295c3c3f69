//! `ipm::iterate` on chains whose equilibrium the test knows by other means.
//!
//! * Without obstacles: the discrete catenary, solved here by Newton's method on its two span
//!   conditions (every link along `(H, V_k)`, `V_k = V_0 + sum_{i=1..k} w_i`, w the node weights):
//!   positions to 1e-9 link lengths and multipliers to 1e-8 of the weight, in 2-D, rotated into a
//!   vertical plane in 3-D, and in the squared formulation (multiplier `T / (2 l)`).
//! * Draped over a disk: every free node's force balance, the disk's exclusion and complementarity
//!   recomputed here from the returned z and mu.
//! * The status rule: `Optimal` only where the KKT error at the returned point is within tol,
//!   including with `max_iterations = 0`.

mod common;

use common::{max_difference, Rng};
use funicular_core::curvature::Verdict;
use funicular_core::driver::{escape_test, iterate};
use funicular_core::evaluate::{kkt_error, Point};
use funicular_core::ipm::{Outcome, Settings, Status};
use funicular_core::policy::Policy;
use funicular_core::problem::{Formulation, Network, Quadratics, ScaledObstacles};

const TOL: f64 = 1e-12;
const SETTINGS: Settings = Settings {
    tol: TOL,
    max_iterations: 200,
};

/// A chain between two supports: link k joins nodes k and k + 1; nodes 0 and N - 1 are fixed.
struct Chain {
    /// Link lengths, the longest 1 (the solver's unit).
    lengths: Vec<f64>,
    /// Node weights g m_i / W (the supports' are never used).
    load: Vec<f64>,
    /// The supports in the vertical plane (horizontal, vertical).
    start: [f64; 2],
    end: [f64; 2],
    /// The start's sag at most (less if a link would be too long).
    sag: f64,
}

impl Chain {
    /// `links` links of random lengths in [0.6, 1] (the first exactly 1) and random weights summing
    /// to 1 over the free nodes; the supports 0.75 and 0.2 of the chain's length apart.
    fn random(links: usize, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let mut lengths: Vec<f64> = (0..links).map(|_| rng.range(0.6, 1.0)).collect();
        lengths[0] = 1.0;
        let mut load: Vec<f64> = (0..=links).map(|_| rng.range(0.5, 1.5)).collect();
        let total: f64 = load[1..links].iter().sum();
        load.iter_mut().for_each(|w| *w /= total);
        let span: f64 = lengths.iter().sum();
        let (start, end) = ([0.3, -0.2], [0.3 + 0.75 * span, -0.2 + 0.2 * span]);
        Chain {
            lengths,
            load,
            start,
            end,
            sag: 0.3 * span,
        }
    }

    fn n_nodes(&self) -> usize {
        self.load.len()
    }

    /// Free nodes on a parabola between the supports, spaced by link length and sagging by `sag` or
    /// as much less as keeps every link shorter than its length (at most 0.99 of it), in the
    /// vertical plane.
    fn sagging_start(&self) -> Vec<[f64; 2]> {
        let total: f64 = self.lengths.iter().sum();
        let mut sag = self.sag;
        loop {
            let mut along = 0.0;
            let mut nodes = vec![self.start];
            for length in &self.lengths {
                along += length / total;
                let mut node = [0.0; 2];
                for (i, value) in node.iter_mut().enumerate() {
                    *value = self.start[i] + along * (self.end[i] - self.start[i]);
                }
                node[1] -= 4.0 * sag * along * (1.0 - along);
                nodes.push(node);
            }
            let fits = self.lengths.iter().enumerate().all(|(k, &length)| {
                let (a, b) = (nodes[k], nodes[k + 1]);
                (a[0] - b[0]).hypot(a[1] - b[1]) < 0.99 * length
            });
            if fits {
                return nodes;
            }
            sag *= 0.8;
        }
    }
}

/// The discrete catenary of `chain`: node positions in the vertical plane and link tensions.
///
/// Newton's method (with step halving that keeps H > 0 and lowers the residual) on the span
/// conditions `sum_k l_k (H, V_k) / T_k = end - start` in the unknowns H (the horizontal force,
/// the same in every link) and V_0 (the first link's vertical force).
fn catenary(chain: &Chain) -> (Vec<[f64; 2]>, Vec<f64>) {
    let links = chain.lengths.len();
    let span = [chain.end[0] - chain.start[0], chain.end[1] - chain.start[1]];
    let vertical = |v0: f64| -> Vec<f64> {
        let mut v = vec![v0];
        for k in 1..links {
            v.push(v[k - 1] + chain.load[k]);
        }
        v
    };
    // residual and Jacobian of the span conditions at (H, V_0)
    let conditions = |h: f64, v0: f64| -> ([f64; 2], [[f64; 2]; 2]) {
        let mut residual = [-span[0], -span[1]];
        let mut jacobian = [[0.0; 2]; 2];
        for (k, v) in vertical(v0).into_iter().enumerate() {
            let (l, t) = (chain.lengths[k], h.hypot(v));
            let t3 = t * t * t;
            residual[0] += l * h / t;
            residual[1] += l * v / t;
            jacobian[0][0] += l * v * v / t3;
            jacobian[0][1] -= l * h * v / t3;
            jacobian[1][0] -= l * h * v / t3;
            jacobian[1][1] += l * h * h / t3;
        }
        (residual, jacobian)
    };
    let size = |r: [f64; 2]| r[0].hypot(r[1]);
    let (mut h, mut v0) = (0.5, -0.5);
    let (mut residual, mut jacobian) = conditions(h, v0);
    for _ in 0..200 {
        if size(residual) <= 1e-15 * chain.lengths.iter().sum::<f64>() {
            break;
        }
        let det = jacobian[0][0] * jacobian[1][1] - jacobian[0][1] * jacobian[1][0];
        let dh = -(jacobian[1][1] * residual[0] - jacobian[0][1] * residual[1]) / det;
        let dv = -(jacobian[0][0] * residual[1] - jacobian[1][0] * residual[0]) / det;
        let mut fraction = 1.0;
        loop {
            let (h_new, v_new) = (h + fraction * dh, v0 + fraction * dv);
            if h_new > 0.0 {
                let (r, j) = conditions(h_new, v_new);
                if size(r) < size(residual) || fraction < 1e-12 {
                    (h, v0, residual, jacobian) = (h_new, v_new, r, j);
                    break;
                }
            }
            fraction *= 0.5;
        }
    }
    assert!(
        size(residual) <= 1e-13,
        "the catenary's Newton did not converge: {residual:?}"
    );
    let mut nodes = vec![chain.start];
    let mut tensions = Vec::with_capacity(links);
    for (k, v) in vertical(v0).into_iter().enumerate() {
        let t = h.hypot(v);
        let last = nodes[k];
        nodes.push([
            last[0] + chain.lengths[k] * h / t,
            last[1] + chain.lengths[k] * v / t,
        ]);
        tensions.push(t);
    }
    (nodes, tensions)
}

/// The network of `chain` in `dim` dimensions, its nodes placed by `place` from the vertical
/// plane (the supports at their final positions, the free nodes at the start).
fn network(
    chain: &Chain,
    dim: usize,
    formulation: Formulation,
    place: &dyn Fn([f64; 2]) -> Vec<f64>,
    obstacles: ScaledObstacles,
) -> Network {
    let n = chain.n_nodes();
    let positions: Vec<f64> = chain.sagging_start().into_iter().flat_map(place).collect();
    let links: Vec<[usize; 2]> = (0..n - 1).map(|k| [k, k + 1]).collect();
    Network::new(
        dim,
        formulation,
        positions,
        (1..n - 1).collect(),
        links,
        chain.lengths.clone(),
        chain.load.clone(),
        vec![0.0; dim],
        obstacles,
    )
    .expect("a valid chain")
}

fn solve(network: &mut Network, settings: Settings, guess: Option<&[f64]>) -> Outcome {
    let z = network.free_coordinates();
    iterate(network, settings, z, guess, &mut || true).expect("the iteration runs")
}

/// The point at the outcome's z and mu, evaluated afresh.
fn evaluated(network: &mut Network, outcome: &Outcome) -> Point {
    let mut point = Point::default();
    network
        .evaluate(&outcome.z, &outcome.mu, &mut point)
        .expect("no caller's field");
    point
}

/// The documented rule: the status is Optimal only when the KKT error at the returned point is
/// within tol.
fn assert_status_rule(network: &mut Network, outcome: &Outcome, tol: f64) {
    let point = evaluated(network, outcome);
    let error = kkt_error(
        network,
        &point,
        &outcome.mu,
        Policy::chain(network).net_force_share,
    );
    if outcome.status == Status::Optimal {
        assert!(
            error <= tol,
            "Optimal with a KKT error of {error:e} > tol = {tol:e}"
        );
    }
}

/// The free nodes of `expected` (all nodes) placed by `place`, flat.
fn free_part(expected: &[[f64; 2]], place: &dyn Fn([f64; 2]) -> Vec<f64>) -> Vec<f64> {
    expected[1..expected.len() - 1]
        .iter()
        .flat_map(|&node| place(node))
        .collect()
}

fn in_plane(node: [f64; 2]) -> Vec<f64> {
    node.to_vec()
}

/// A vertical plane at 0.6 rad from the x axis, shifted so that the supports differ in x and y.
fn rotated(node: [f64; 2]) -> Vec<f64> {
    let angle: f64 = 0.6;
    vec![
        -0.7 + node[0] * angle.cos(),
        1.1 + node[0] * angle.sin(),
        0.4 + node[1],
    ]
}

/// Solves the chain in `dim` dimensions and checks it against the catenary: positions to 1e-9, the
/// multipliers to 1e-8 (`unit(k)` converts link k's tension to its multiplier).
fn check_catenary(
    chain: &Chain,
    dim: usize,
    formulation: Formulation,
    place: &dyn Fn([f64; 2]) -> Vec<f64>,
    unit: &dyn Fn(usize) -> f64,
) {
    let (nodes, tensions) = catenary(chain);
    let mut network = network(chain, dim, formulation, place, ScaledObstacles::none());
    let outcome = solve(&mut network, SETTINGS, None);
    assert_eq!(
        outcome.status,
        Status::Optimal,
        "after {} iterations",
        outcome.iterations
    );
    assert_status_rule(&mut network, &outcome, TOL);
    let positions = max_difference(&outcome.z, &free_part(&nodes, place));
    assert!(positions <= 1e-9, "positions off the catenary by {positions:e}");
    let expected: Vec<f64> = tensions.iter().enumerate().map(|(k, t)| t * unit(k)).collect();
    let forces = max_difference(&outcome.mu, &expected);
    assert!(
        forces <= 1e-8,
        "multipliers off the catenary's tensions by {forces:e}"
    );
}

/// (a) A 2-D chain of mixed link lengths and node weights converges to the discrete catenary, the
/// norm form's multipliers being the tensions.
#[test]
fn chain_in_the_plane_is_the_discrete_catenary() {
    for (links, seed) in [(12, 1), (40, 2)] {
        check_catenary(
            &Chain::random(links, seed),
            2,
            Formulation::Norm,
            &in_plane,
            &|_| 1.0,
        );
    }
}

/// (b) The same chain in a vertical plane of 3-D space, its supports differing in x and y: the
/// rotated positions and the same tensions.
#[test]
fn chain_in_a_vertical_plane_of_space_is_the_rotated_catenary() {
    for (links, seed) in [(12, 1), (40, 2)] {
        check_catenary(
            &Chain::random(links, seed),
            3,
            Formulation::Norm,
            &rotated,
            &|_| 1.0,
        );
    }
}

/// (c) The squared formulation: the same positions, multipliers `T / (2 l)` (a taut link's
/// gradient is `2 l` long).
#[test]
fn squared_formulation_has_multipliers_tension_over_twice_the_length() {
    let chain = Chain::random(20, 3);
    let lengths = chain.lengths.clone();
    let unit = move |k: usize| 1.0 / (2.0 * lengths[k]);
    check_catenary(&chain, 2, Formulation::Squared, &in_plane, &unit);
    check_catenary(&chain, 3, Formulation::Squared, &rotated, &unit);
}

/// The catenary passes the second-order test: a hanging chain with every link taut is a strict
/// local minimum (W = sum T_k (I - q q^T) / l_k is positive on the motions that keep the lengths).
#[test]
fn catenary_is_a_strict_local_minimum() {
    let chain = Chain::random(15, 4);
    let mut network = network(&chain, 2, Formulation::Norm, &in_plane, ScaledObstacles::none());
    let outcome = solve(&mut network, SETTINGS, None);
    assert_eq!(outcome.status, Status::Optimal);
    let point = evaluated(&mut network, &outcome);
    let total_length: f64 = chain.lengths.iter().sum();
    assert_eq!(
        escape_test(&network, &point, &outcome.mu, 1e-9, total_length),
        Verdict::Minimum
    );
}

/// (d) A chain draped over a disk, started above it: converged; at every free node the load, the link forces
/// `mu_r q_r` and the contact force `nu grad phi` (all recomputed here from z and mu, phi the disk's
/// `(R^2 - |p - c|^2) / (2 R)`) cancel to 1e-8; no node inside the disk; the multipliers are
/// non-negative and complementary to their constraints; and the disk does carry the chain.
#[test]
fn chain_draped_over_a_disk_balances_its_forces() {
    // The free chain would sag 5 below its supports, through the disk; too short to pass below
    // it (that takes some 27 link lengths), it must rest on it.
    let links = 20;
    let chain = Chain {
        lengths: vec![1.0; links],
        load: vec![1.0 / (links - 1) as f64; links + 1],
        start: [0.0, 0.0],
        end: [16.0, 0.0],
        sag: 0.5,
    };
    let (centre, radius) = ([8.0, -6.0], 5.0);
    let disk = Quadratics {
        centres: centre.to_vec(),
        values: vec![radius / 2.0],
        gradients: vec![0.0, 0.0],
        hessians: vec![-1.0 / radius, 0.0, 0.0, -1.0 / radius],
    };
    let mut network = network(
        &chain,
        2,
        Formulation::Norm,
        &in_plane,
        ScaledObstacles::Quadratic(disk),
    );
    let outcome = solve(&mut network, SETTINGS, None);
    assert_eq!(
        outcome.status,
        Status::Optimal,
        "after {} iterations",
        outcome.iterations
    );
    assert_status_rule(&mut network, &outcome, TOL);

    let node = |i: usize| -> [f64; 2] {
        match i {
            0 => chain.start,
            i if i == links => chain.end,
            i => [outcome.z[2 * (i - 1)], outcome.z[2 * (i - 1) + 1]],
        }
    };
    let mut residual: Vec<[f64; 2]> = (1..links).map(|i| [0.0, chain.load[i]]).collect();
    for k in 0..links {
        let (a, b) = (node(k), node(k + 1));
        let distance = (a[0] - b[0]).hypot(a[1] - b[1]);
        let c = distance - chain.lengths[k];
        let mu = outcome.mu[k];
        assert!(
            mu >= -1e-12 && c <= 1e-10 && (mu * c).abs() <= 1e-10,
            "link {k}: mu {mu}, c {c}"
        );
        // (norm form; below half its length a link would be slack and on the parabola: mu ~ 0)
        let reach = distance.max(0.5 * chain.lengths[k]);
        let q = [(a[0] - b[0]) / reach, (a[1] - b[1]) / reach];
        for i in 0..2 {
            if k > 0 {
                residual[k - 1][i] += mu * q[i]; // node k is the link's first node
            }
            if k + 1 < links {
                residual[k][i] -= mu * q[i];
            }
        }
    }
    let mut touching = 0;
    for (f, balance) in residual.iter_mut().enumerate() {
        let p = node(f + 1);
        let offset = [p[0] - centre[0], p[1] - centre[1]];
        let phi = (radius * radius - offset[0] * offset[0] - offset[1] * offset[1]) / (2.0 * radius);
        let nu = outcome.mu[links + f];
        assert!(phi <= 1e-10, "node {} inside the disk: phi = {phi:e}", f + 1);
        assert!(
            nu >= -1e-12 && (nu * phi).abs() <= 1e-10,
            "node {}: nu {nu}, phi {phi}",
            f + 1
        );
        for i in 0..2 {
            balance[i] -= nu * offset[i] / radius; // grad phi = -(p - c) / R
        }
        if nu > 1e-3 {
            touching += 1;
        }
    }
    for (f, r) in residual.iter().enumerate() {
        assert!(
            r[0].abs() <= 1e-8 && r[1].abs() <= 1e-8,
            "node {}: net force {r:?}",
            f + 1
        );
    }
    assert!(touching >= 3, "only {touching} nodes lean on the disk");
}

/// (e) With `max_iterations = 0` from a cold start the iteration takes no step and stops with
/// MaxIterations, at the start, its KKT error above tol. From the solution and its multipliers as
/// the guess it is Optimal at once, with the KKT error within tol: in both, the status follows the
/// documented rule.
#[test]
fn no_iterations_allowed_gives_optimal_only_within_tol() {
    let chain = Chain::random(12, 5);
    let mut network = network(&chain, 2, Formulation::Norm, &in_plane, ScaledObstacles::none());
    let start = network.free_coordinates();
    let none = Settings {
        tol: TOL,
        max_iterations: 0,
    };
    let outcome = solve(&mut network, none, None);
    assert_status_rule(&mut network, &outcome, TOL);
    assert_eq!(outcome.status, Status::MaxIterations);
    assert_eq!(outcome.iterations, 0);
    assert_eq!(outcome.z, start, "no step was allowed");
    let point = evaluated(&mut network, &outcome);
    assert!(
        kkt_error(
            &network,
            &point,
            &outcome.mu,
            Policy::chain(&network).net_force_share
        ) > TOL
    );

    let solved = solve(&mut network, SETTINGS, None);
    assert_eq!(solved.status, Status::Optimal);
    let again = iterate(
        &mut network,
        none,
        solved.z.clone(),
        Some(&solved.mu),
        &mut || true,
    )
    .expect("runs");
    assert_status_rule(&mut network, &again, TOL);
    assert_eq!(again.status, Status::Optimal);
    assert!(max_difference(&again.z, &solved.z) <= 1e-12);
}
