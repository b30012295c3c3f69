//! The chain's one-pass polish step against the assembled system and dense elimination.

use super::assembled::{entries, lagrangian_gradient, ActiveRows, Layout};
use super::chain::chain_step;
use super::*;
use crate::linalg::{Assemble, BandedLu, BlockKkt, Fallback, KktRows};

use crate::problem::{Formulation, Quadratics, ScaledObstacles};
use crate::test_support::Rng;

/// A chain of `nodes` nodes in dimension `d` along the first axis (links in either orientation,
/// some shorter than their length), both ends and sometimes a node between fixed, two
/// quadratic obstacles (a sphere and a general one), evaluated at random multipliers on a
/// random active set: links taut with probability `taut`, a free node touching one obstacle
/// with probability 0.4 (both with probability `both`).
fn case(d: usize, formulation: Formulation, nodes: usize, taut: f64, both: f64, seed: u64) -> Case {
    case_with(d, formulation, nodes, taut, both, seed, false)
}

/// `case`, and with `elastic` every other link (about) given a random compliance.
fn case_with(
    d: usize,
    formulation: Formulation,
    nodes: usize,
    taut: f64,
    both: f64,
    seed: u64,
    elastic: bool,
) -> Case {
    let mut rng = Rng::new(seed);
    let mut positions = Vec::new();
    for i in 0..nodes {
        positions.push(0.5 * i as f64 + rng.between(-0.1, 0.1));
        positions.extend((1..d).map(|_| rng.between(-0.3, 0.3)));
    }
    // (a fixed node between two free ones)
    let mut free: Vec<usize> = (1..nodes - 1).collect();
    if rng.chance(0.5) {
        free.remove(1 + rng.below(nodes - 5));
    }
    let links: Vec<[usize; 2]> = (0..nodes - 1)
        .map(|k| if rng.chance(0.5) { [k, k + 1] } else { [k + 1, k] })
        .collect();
    let lengths = (0..nodes - 1).map(|_| rng.between(0.4, 1.4)).collect();
    let load = (0..nodes).map(|_| rng.between(0.02, 0.2)).collect();
    let mut quadratics = Quadratics::default();
    for _ in 0..2 {
        quadratics.centres.extend((0..d).map(|_| rng.between(-1.0, 1.0)));
        quadratics.values.push(rng.between(-0.5, 0.5));
        quadratics.gradients.extend((0..d).map(|_| rng.uniform()));
        let mut h = vec![0.0; d * d];
        for i in 0..d {
            for k in i..d {
                h[i * d + k] = rng.uniform();
                h[k * d + i] = h[i * d + k];
            }
        }
        quadratics.hessians.extend(h);
    }
    let mut network = Network::new(
        d,
        formulation,
        positions,
        free,
        links,
        lengths,
        load,
        vec![0.0; d],
        ScaledObstacles::Quadratic(quadratics),
    )
    .expect("a valid chain");
    if elastic {
        // (drawn apart: the active sets stay those of the inextensible cases, whose random 1-D
        // systems the test knows to be regular)
        let mut draw = Rng::new(seed + 1000);
        let compliance = (0..nodes - 1)
            .map(|_| {
                if draw.chance(0.5) {
                    draw.between(0.01, 0.5)
                } else {
                    0.0
                }
            })
            .collect();
        network = network.with_compliance(compliance).expect("valid compliances");
    }
    let (n, n_links) = (network.n_free(), network.n_links());
    let mut active = vec![false; network.n_constraints()];
    for r in 0..n_links {
        active[r] = rng.chance(taut);
    }
    for f in 0..n {
        if rng.chance(0.4) {
            active[n_links + rng.below(2) * n + f] = true;
        } else if rng.chance(both) {
            active[n_links + f] = true;
            active[n_links + n + f] = true;
        }
    }
    let mu: Vec<f64> = active
        .iter()
        .map(|&a| if a { rng.between(0.2, 1.5) } else { 0.0 })
        .collect();
    let z = network.free_coordinates();
    let mut point = Point::default();
    network.evaluate(&z, &mu, &mut point).expect("evaluated");
    Case {
        network,
        point,
        z,
        mu,
        active,
    }
}

struct Case {
    network: Network,
    point: Point,
    z: Vec<f64>,
    mu: Vec<f64>,
    active: Vec<bool>,
}

impl Case {
    /// `chain_step`'s new coordinates and multipliers, None if it declines.
    fn chain(&self) -> Option<(Vec<f64>, Vec<f64>)> {
        let Case {
            network,
            point,
            z,
            mu,
            active,
        } = self;
        let (mut z, mut mu) = (z.clone(), mu.clone());
        let mut records = Vec::new();
        let finite = match network.dim {
            1 => chain_step::<1, 2, 3>(network, point, &mut z, &mut mu, active, &mut records),
            2 => chain_step::<2, 3, 4>(network, point, &mut z, &mut mu, active, &mut records),
            _ => chain_step::<3, 4, 5>(network, point, &mut z, &mut mu, active, &mut records),
        }?;
        assert!(finite);
        Some((z, mu))
    }

    /// The same by the assembled system (which must solve it).
    fn assembled(&self) -> (Vec<f64>, Vec<f64>) {
        let (mut z, mut mu) = (self.z.clone(), self.mu.clone());
        let mut assembled = Assembled::<Fallback<BlockKkt, BandedLu>>::default();
        assert!(assembled.step(&self.network, &self.point, &mut z, &mut mu, &self.active));
        (z, mu)
    }
}

struct Dense(usize, Vec<f64>);

impl Assemble for Dense {
    fn add(&mut self, row: usize, col: usize, value: f64) {
        self.1[row * self.0 + col] += value;
    }
}

impl Case {
    /// The same by dense elimination with partial pivoting; None if it meets a zero pivot (a
    /// random system can be singular: more active rows at a few nodes than their coordinates).
    fn dense(&self) -> Option<(Vec<f64>, Vec<f64>)> {
        let (layout, matrix, rhs) = self.dense_system();
        let n = layout.size;
        let step = crate::test_support::dense_solve(n, &matrix, &rhs)?;
        let d = self.network.dim;
        let mut z = self.z.clone();
        for (f, &node) in self.network.free.iter().enumerate() {
            for i in 0..d {
                z[f * d + i] = self.point.positions[node * d + i] + step[layout.coordinate[f] + i];
            }
        }
        let mu = layout
            .row
            .iter()
            .zip(&self.mu)
            .map(|(&var, m)| if var == NONE { 0.0 } else { m + step[var] })
            .collect();
        Some((z, mu))
    }

    /// The KKT system, dense, with its layout and right-hand side.
    fn dense_system(&self) -> (Layout, Vec<f64>, Vec<f64>) {
        let mut layout = Layout::default();
        layout.arrange(&self.network, &self.active);
        let mut gradient = Vec::new();
        lagrangian_gradient(&self.network, &self.point, &self.mu, &mut gradient);
        let rows = ActiveRows {
            network: &self.network,
            point: &self.point,
            mu: &self.mu,
            layout: &layout,
            gradient: &gradient,
        };
        let n = layout.size;
        let mut rhs = vec![0.0; n];
        rows.right_hand_side(&mut rhs);
        let mut dense = Dense(n, vec![0.0; n * n]);
        entries(&self.network, &self.point, &self.mu, &layout, &mut dense);
        (layout, dense.1, rhs)
    }

    /// The backward error of the step to (z, mu): |K x - b| / (|K| |x| + |b|) in the max norm, K
    /// and b the dense KKT system.
    fn backward_error(&self, z: &[f64], mu: &[f64]) -> f64 {
        let (layout, matrix, rhs) = self.dense_system();
        let (n, d) = (layout.size, self.network.dim);
        let mut x = vec![0.0; n];
        for (f, &node) in self.network.free.iter().enumerate() {
            for i in 0..d {
                x[layout.coordinate[f] + i] = z[f * d + i] - self.point.positions[node * d + i];
            }
        }
        for (r, &var) in layout.row.iter().enumerate() {
            if var != NONE {
                x[var] = mu[r] - self.mu[r];
            }
        }
        let largest = |v: &[f64]| v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let (mut residual, mut norm) = (0.0_f64, 0.0_f64);
        for i in 0..n {
            let row = &matrix[i * n..(i + 1) * n];
            let product: f64 = row.iter().zip(&x).map(|(a, b)| a * b).sum();
            residual = residual.max((product - rhs[i]).abs());
            norm = norm.max(row.iter().map(|a| a.abs()).sum());
        }
        residual / (norm * largest(&x) + largest(&rhs))
    }
}

/// max |a - b| / max |b|.
fn relative_difference(a: &[f64], b: &[f64]) -> f64 {
    let largest = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / largest
}

#[test]
fn chain_step_agrees_with_the_assembled_system() {
    agrees_with_the_assembled_system(false);
}

#[test]
fn chain_step_with_elastic_links_agrees_with_the_assembled_system() {
    agrees_with_the_assembled_system(true);
}

fn agrees_with_the_assembled_system(elastic: bool) {
    let mut compared = 0;
    for d in 1..=3 {
        let formulations: &[Formulation] = if elastic {
            &[Formulation::Norm] // (elastic links are written in the norm formulation only)
        } else {
            &[Formulation::Norm, Formulation::Squared]
        };
        for &formulation in formulations {
            for seed in 0..40 {
                let case = case_with(d, formulation, 8 + seed as usize % 30, 0.9, 0.0, seed, elastic);
                // (a slack link before a taut one can trip the guard, as in `BlockKkt`)
                let Some((z_chain, mu_chain)) = case.chain() else {
                    continue;
                };
                // against dense elimination with partial pivoting over the whole matrix, as
                // close as the assembled system's solution (some random systems are poorly
                // conditioned)
                let Some((z, mu)) = case.dense() else {
                    continue;
                };
                let (z_assembled, mu_assembled) = case.assembled();
                for (chain, assembled, reference) in
                    [(&z_chain, &z_assembled, &z), (&mu_chain, &mu_assembled, &mu)]
                {
                    let (error, assembled_error) = (
                        relative_difference(chain, reference),
                        relative_difference(assembled, reference),
                    );
                    assert!(
                        error < (10.0 * assembled_error).max(1e-14),
                        "d {d}, seed {seed}: {error:e} (assembled: {assembled_error:e})"
                    );
                }
                // zero off the active set
                assert!(mu_chain.iter().zip(&case.active).all(|(m, a)| *a || *m == 0.0));
                compared += 1;
            }
        }
    }
    assert!(compared > 50, "only {compared} compared");
}

#[test]
fn chain_step_declines_a_node_on_two_obstacles() {
    for seed in 0..10 {
        let case = case(2, Formulation::Norm, 20, 1.0, 1.0, seed);
        let (n, n_links) = (case.network.n_free(), case.network.n_links());
        assert!((0..n).any(|f| case.active[n_links + f] && case.active[n_links + n + f]));
        assert!(case.chain().is_none());
    }
}

#[test]
fn chain_step_refuses_numbers_not_finite() {
    let healthy = case(2, Formulation::Norm, 12, 1.0, 0.0, 5);
    assert!(healthy.chain().is_some());
    let (n, n_links) = (healthy.network.n_free(), healthy.network.n_links());
    let f = (0..n).find(|&f| healthy.active[n_links + f] || healthy.active[n_links + n + f]);
    let contact = f
        .map(|f| if healthy.active[n_links + f] { f } else { n + f })
        .expect("a contact");
    for bad in [f64::NAN, f64::INFINITY] {
        for place in 0..4 {
            let mut broken = case(2, Formulation::Norm, 12, 1.0, 0.0, 5);
            match place {
                0 => broken.point.q[2 * 3 + 1] = bad,
                1 => broken.point.c[4] = bad,
                2 => broken.point.contact_gradient[2 * contact] = bad,
                _ => broken.mu[n_links + contact] = bad,
            }
            assert!(broken.chain().is_none(), "{bad} at {place} accepted");
        }
    }
}

#[test]
fn chain_step_refuses_a_proximal_block() {
    // a free node after a slack link and before a taut one, without contact: along the taut
    // link only the proximal term holds it in its own block (see `kkt`)
    let mut case = case(2, Formulation::Norm, 12, 1.0, 0.0, 3);
    let n_links = case.network.n_links();
    case.active[n_links..].fill(false);
    case.mu[n_links..].fill(0.0);
    case.active[4] = false;
    case.mu[4] = 0.0;
    let mut point = Point::default();
    case.network
        .evaluate(&case.z, &case.mu, &mut point)
        .expect("evaluated");
    case.point = point;
    assert!(case.chain().is_none());
    let (z, mu) = case.assembled();
    assert!(z.iter().chain(&mu).all(|v| v.is_finite()));
    // and the chain's polish step takes the assembled system's answer
    let (mut z_step, mut mu_step) = (case.z.clone(), case.mu.clone());
    let mut solver = ChainPolish::default();
    assert!(solver.step(
        &case.network,
        &case.point,
        &mut z_step,
        &mut mu_step,
        &case.active
    ));
    assert!(z_step == z && mu_step == mu);
}

impl Case {
    /// The step of `solver` (which must solve the system).
    fn by<P: PolishSolver>(&self, mut solver: P) -> (Vec<f64>, Vec<f64>) {
        let (mut z, mut mu) = (self.z.clone(), self.mu.clone());
        assert!(solver.step(&self.network, &self.point, &mut z, &mut mu, &self.active));
        (z, mu)
    }
}

#[test]
fn net_step_agrees_with_dense_elimination() {
    use crate::evaluate::NetworkMatrix;
    use crate::linalg::SparseMatrix;
    let (mut compared, mut by_condensed) = (0, 0);
    for elastic in [false, true] {
        for d in 1..=3 {
            for formulation in [Formulation::Norm, Formulation::Squared] {
                if elastic && formulation == Formulation::Squared {
                    continue; // (elastic links are written in the norm formulation only)
                }
                for seed in 0..30 {
                    let case = case_with(d, formulation, 8 + seed as usize % 30, 0.9, 0.2, seed, elastic);
                    let Some((z, mu)) = case.dense() else {
                        continue;
                    };
                    let matrix = SparseMatrix::for_network(&case.network);
                    let mut condensed = NetPolish::new(&matrix);
                    if condensed.condensed_step(&case.network, &case.point, &case.mu, &case.active) {
                        by_condensed += 1;
                    }
                    let (z_net, mu_net) = case.by(NetPolish::new(&matrix));
                    // as accurate as the KKT system's L D L^T, backward (residual) and forward
                    // (against dense elimination; some random systems are poorly conditioned,
                    // nodes held by the proximal term alone among them)
                    let (z_kkt, mu_kkt) = case.by(NetKktPolish::default());
                    let (error, kkt_error) = (
                        case.backward_error(&z_net, &mu_net),
                        case.backward_error(&z_kkt, &mu_kkt),
                    );
                    assert!(
                        error < (10.0 * kkt_error).max(1e-14),
                        "d {d}, seed {seed}, elastic {elastic}: backward error {error:e} (KKT system: {kkt_error:e})"
                    );
                    for (net, kkt, reference) in [(&z_net, &z_kkt, &z), (&mu_net, &mu_kkt, &mu)] {
                        let (error, kkt_error) = (
                            relative_difference(net, reference),
                            relative_difference(kkt, reference),
                        );
                        assert!(
                            error < (10.0 * kkt_error).max(1e-6),
                            "d {d}, seed {seed}, elastic {elastic}: {error:e} (KKT system: {kkt_error:e})"
                        );
                    }
                    assert!(mu_net.iter().zip(&case.active).all(|(m, a)| *a || *m == 0.0));
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 80, "only {compared} compared");
    // both ways exercised: the condensed system solves most steps (those it refuses hold nodes by
    // the proximal term alone beside rows weighted 1 / delta), the KKT system the rest
    assert!(
        4 * by_condensed >= 3 * compared && by_condensed < compared,
        "{by_condensed} of {compared} by the condensed system"
    );
}
