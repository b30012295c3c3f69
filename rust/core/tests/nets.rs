//! The iteration on networks that are not chains (cable nets), through the sparse solvers.
//!
//! * Small nets in the plane and in space, solved to optimal: every free node's force balance (its
//!   load and the link tensions along the unit link directions, recomputed here from the returned
//!   positions and multipliers), every link within its length, and complementarity.
//! * A chain solved through the sparse solvers, once with the chain's fast path switched off and
//!   once with its nodes numbered out of order, gives the chain path's answer.
//! * A statically indeterminate net (more taut links at a node than it has coordinates) solves,
//!   its multipliers not being unique.
//! * The second-order test on a net.

mod common;

use common::{symmetric_eigen, Rng};
use funicular_core::curvature::{lowest_eigenpair, start_vector, Verdict};
use funicular_core::driver::{escape_test, iterate};
use funicular_core::evaluate::Point;
use funicular_core::ipm::{Outcome, Settings, Status};
use funicular_core::linalg::NewtonMatrix;
use funicular_core::linalg::SparseMatrix;
use funicular_core::problem::{Formulation, Network, ScaledObstacles};

const TOL: f64 = 1e-12;
const SETTINGS: Settings = Settings {
    tol: TOL,
    max_iterations: 300,
};

/// A network from its nodes (each `dim` coordinates), the fixed ones, links and lengths; the free
/// nodes share a unit weight.
fn network(
    dim: usize,
    nodes: &[Vec<f64>],
    fixed: &[usize],
    links: &[[usize; 2]],
    lengths: &[f64],
) -> Network {
    let n_nodes = nodes.len();
    let free: Vec<usize> = (0..n_nodes).filter(|i| !fixed.contains(i)).collect();
    let mut load = vec![0.0; n_nodes];
    for &node in &free {
        load[node] = 1.0 / free.len() as f64;
    }
    Network::new(
        dim,
        Formulation::Norm,
        nodes.concat(),
        free,
        links.to_vec(),
        lengths.to_vec(),
        load,
        vec![0.0; dim],
        ScaledObstacles::none(),
    )
    .expect("a valid network")
}

fn solve(network: &mut Network) -> Outcome {
    let z = network.free_coordinates();
    iterate(network, SETTINGS, z, None, &mut || true).expect("the iteration runs")
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// Force balance at every free node, lengths and complementarity, from the outcome's z and mu alone
/// (a taut link's multiplier is its tension: the norm formulation). Returns the taut links.
fn check_equilibrium(network: &Network, outcome: &Outcome) -> usize {
    assert_eq!(
        outcome.status,
        Status::Optimal,
        "after {} iterations",
        outcome.iterations
    );
    let d = network.dim;
    let mut positions = Vec::new();
    network.placed(&outcome.z, &mut positions);
    let node = |i: usize| &positions[i * d..i * d + d];
    let total_weight: f64 = network.free.iter().map(|&i| network.load[i]).sum();
    let mut force = vec![0.0; network.n_nodes() * d];
    for &i in &network.free {
        force[i * d + d - 1] -= network.load[i];
    }
    let mut taut = 0;
    for (r, &[a, b]) in network.links.iter().enumerate() {
        let (length, tension) = (network.lengths[r], outcome.mu[r]);
        let span = distance(node(a), node(b));
        assert!(
            span <= length * (1.0 + 1e-12),
            "link {r} is {span} long, over its length {length}"
        );
        assert!(tension >= -1e-12, "link {r} pushes: tension {tension:e}");
        if span < length * (1.0 - 1e-6) {
            assert!(
                tension <= 1e-9 * total_weight,
                "slack link {r} ({span} of {length}) carries {tension:e}"
            );
        } else {
            taut += 1;
        }
        // the tension pulls each end towards the other
        for k in 0..d {
            let along = (node(b)[k] - node(a)[k]) / span;
            force[a * d + k] += tension * along;
            force[b * d + k] -= tension * along;
        }
    }
    for &i in &network.free {
        for k in 0..d {
            let left = force[i * d + k];
            assert!(
                left.abs() <= 1e-9 * total_weight,
                "node {i} is left with a force {left:e} along axis {k}"
            );
        }
    }
    taut
}

/// A 2-D "square with diagonals": supports 0 and 3 at the top, free nodes 1 and 2 below; the sides
/// and both diagonals linked, numbered so that the links do not form a path.
fn square_with_diagonals() -> Network {
    let nodes = vec![vec![0.0, 0.0], vec![0.2, -0.5], vec![1.1, -0.4], vec![1.3, 0.0]];
    let links = [[0, 1], [1, 2], [2, 3], [0, 2], [1, 3]];
    let lengths = [1.0, 0.9, 1.0, 1.5, 1.6];
    network(2, &nodes, &[0, 3], &links, &lengths)
}

/// An n x n grid in space, spacing `1 / 1.2`, its corners fixed at z = 0, neighbours linked with
/// length 1 (1.2 times the spacing), unit total weight; started flat (every link slack), or
/// sagging by `sag` times the most that keeps every link slack (`-sag h sin(pi u) sin(pi v)`).
fn grid(n: usize) -> Network {
    sagging_grid(n, 0.0)
}

fn sagging_grid(n: usize, sag: f64) -> Network {
    let spacing = 1.0 / 1.2;
    // a link's rise is at most pi h / (n - 1): keep it below 0.5 (the link at 0.98 of its length)
    let height = sag * 0.5 * (n - 1) as f64 / std::f64::consts::PI;
    let mut nodes = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (u, v) = (i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
            let z = -height * (std::f64::consts::PI * u).sin() * (std::f64::consts::PI * v).sin();
            nodes.push(vec![i as f64 * spacing, j as f64 * spacing, z]);
        }
    }
    let mut links = Vec::new();
    for i in 0..n {
        for j in 0..n {
            if i + 1 < n {
                links.push([i * n + j, (i + 1) * n + j]);
            }
            if j + 1 < n {
                links.push([i * n + j, i * n + j + 1]);
            }
        }
    }
    let corners = [0, n - 1, n * (n - 1), n * n - 1];
    let lengths = vec![1.0; links.len()];
    network(3, &nodes, &corners, &links, &lengths)
}

#[test]
fn square_with_diagonals_in_the_plane() {
    let mut network = square_with_diagonals();
    assert!(!network.path);
    let outcome = solve(&mut network);
    let taut = check_equilibrium(&network, &outcome);
    assert!(taut >= 2, "only {taut} taut links");
}

#[test]
fn triangle_in_the_plane() {
    // two supports and one free node: a triangle of links, the support-to-support link left out
    // (it has no free end); plus a second free node hanging from the first and a support
    let nodes = vec![vec![0.0, 0.0], vec![0.6, -0.4], vec![1.5, 0.0], vec![0.8, -0.5]];
    let links = [[0, 1], [1, 2], [1, 3], [3, 2], [0, 3]];
    let lengths = [0.8, 1.0, 0.7, 0.9, 1.0];
    let mut network = network(2, &nodes, &[0, 2], &links, &lengths);
    assert!(!network.path);
    let outcome = solve(&mut network);
    check_equilibrium(&network, &outcome);
}

#[test]
fn grid_in_space_hangs_from_its_corners() {
    let mut network = grid(3);
    let outcome = solve(&mut network);
    let taut = check_equilibrium(&network, &outcome);
    assert!(taut >= 8, "only {taut} taut links");
    // symmetric: the centre hangs lowest, below the edge midpoints
    let mut positions = Vec::new();
    network.placed(&outcome.z, &mut positions);
    let centre = positions[4 * 3 + 2];
    for edge in [1, 3, 5, 7] {
        assert!(centre < positions[edge * 3 + 2]);
    }
}

#[test]
fn larger_grid_in_space() {
    let mut network = grid(8);
    let outcome = solve(&mut network);
    check_equilibrium(&network, &outcome);
}

/// A chain of `links` random links between two supports, its nodes numbered by `label` (node k of
/// the chain is node `label[k]` of the network), started on the straight line between the
/// supports (every link at 0.75 of its length).
fn chain(links: usize, seed: u64, label: &[usize], dim: usize) -> Network {
    let mut rng = Rng::new(seed);
    let lengths: Vec<f64> = (0..links)
        .map(|k| if k == 0 { 1.0 } else { rng.range(0.6, 1.0) })
        .collect();
    let weights: Vec<f64> = (0..=links).map(|_| rng.range(0.5, 1.5)).collect();
    let total: f64 = weights[1..links].iter().sum();
    let n = links + 1;
    let mut nodes = vec![Vec::new(); n];
    let mut load = vec![0.0; n];
    let mut along = 0.0;
    for k in 0..n {
        let mut node = vec![0.3 + 0.75 * along, -0.2 + 0.1 * along];
        if dim == 3 {
            node.insert(1, 0.4);
        }
        nodes[label[k]] = node;
        load[label[k]] = weights[k] / total;
        if k < links {
            along += lengths[k];
        }
    }
    let mut free: Vec<usize> = (1..n - 1).map(|k| label[k]).collect();
    free.sort_unstable();
    let network_links: Vec<[usize; 2]> = (0..links).map(|k| [label[k], label[k + 1]]).collect();
    Network::new(
        dim,
        Formulation::Norm,
        nodes.concat(),
        free,
        network_links,
        lengths,
        load,
        vec![0.0; dim],
        ScaledObstacles::none(),
    )
    .expect("a valid chain")
}

/// Every node's position, in the chain's order.
fn chain_positions(network: &Network, outcome: &Outcome, label: &[usize]) -> Vec<f64> {
    let d = network.dim;
    let mut positions = Vec::new();
    network.placed(&outcome.z, &mut positions);
    label
        .iter()
        .flat_map(|&node| positions[node * d..node * d + d].to_vec())
        .collect()
}

fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// The strongest check that the sparse solvers agree with the chain's: the same chain solved
/// through the chain path, through the sparse path (the fast path switched off), and numbered out
/// of order (so that it is not a path at all), to 1e-9.
#[test]
fn chain_through_the_sparse_path_matches_the_chain_path() {
    for (links, seed, dim) in [(10, 1, 2), (30, 2, 2), (25, 3, 3)] {
        let n = links + 1;
        let identity: Vec<usize> = (0..n).collect();
        // an interleaving: chain node 2i is node i, chain node 2i + 1 is node n - 1 - i
        let shuffled: Vec<usize> = (0..n)
            .map(|k| if k % 2 == 0 { k / 2 } else { n - 1 - k / 2 })
            .collect();

        let mut reference = chain(links, seed, &identity, dim);
        assert!(reference.path);
        let expected = solve(&mut reference);
        assert_eq!(expected.status, Status::Optimal);
        let expected_positions = chain_positions(&reference, &expected, &identity);

        let mut switched = chain(links, seed, &identity, dim);
        switched.path = false; // the sparse Newton matrix and KKT solve for the same chain
        let outcome = solve(&mut switched);
        check_equilibrium(&switched, &outcome);
        let positions = max_difference(
            &chain_positions(&switched, &outcome, &identity),
            &expected_positions,
        );
        assert!(positions <= 1e-9, "positions differ by {positions:e}");
        let forces = max_difference(&outcome.mu, &expected.mu);
        assert!(forces <= 1e-9, "tensions differ by {forces:e}");

        let mut relabelled = chain(links, seed, &shuffled, dim);
        assert!(!relabelled.path);
        let outcome = solve(&mut relabelled);
        check_equilibrium(&relabelled, &outcome);
        let positions = max_difference(
            &chain_positions(&relabelled, &outcome, &shuffled),
            &expected_positions,
        );
        assert!(positions <= 1e-9, "positions differ by {positions:e}");
        let forces = max_difference(&outcome.mu, &expected.mu);
        assert!(forces <= 1e-9, "tensions differ by {forces:e}");
    }
}

/// A node hanging from three supports in the plane whose links are all exactly taut at its lowest
/// point: three tensions for two equations of balance, so no unique multipliers (and a KKT matrix
/// whose constraint rows are dependent). Its position is known: straight below the middle support.
#[test]
fn statically_indeterminate_node_in_the_plane() {
    let supports = [[-1.0, 0.0], [1.0, 0.0], [0.0, 0.5]];
    let bottom = [0.0, -1.0];
    let mut nodes: Vec<Vec<f64>> = supports.iter().map(|s| s.to_vec()).collect();
    nodes.push(vec![0.1, -0.3]);
    let links = [[0, 3], [1, 3], [2, 3]];
    let lengths: Vec<f64> = supports.iter().map(|s| distance(s, &bottom)).collect();
    let longest = lengths.iter().cloned().fold(0.0, f64::max);
    let scaled: Vec<Vec<f64>> = nodes
        .iter()
        .map(|p| p.iter().map(|x| x / longest).collect())
        .collect();
    let lengths: Vec<f64> = lengths.iter().map(|l| l / longest).collect();
    let mut network = network(2, &scaled, &[0, 1, 2], &links, &lengths);
    let outcome = solve(&mut network);
    assert_eq!(check_equilibrium(&network, &outcome), 3);
    let position = [outcome.z[0] * longest, outcome.z[1] * longest];
    assert!(distance(&position, &bottom) <= 1e-9, "at {position:?}");
}

/// The same in space: a net of two free nodes, each hanging from four supports around it by
/// links exactly taut at its lowest point, and linked to each other (a slack link); more taut
/// links than coordinates at both nodes.
#[test]
fn statically_indeterminate_net_in_space() {
    let bottoms = [[0.0, 0.0, -1.0], [1.0, 0.0, -1.0]];
    let mut nodes = Vec::new();
    let mut links = Vec::new();
    let mut lengths = Vec::new();
    for (b, bottom) in bottoms.iter().enumerate() {
        for (k, offset) in [[-0.6, 0.0], [0.6, 0.0], [0.0, -0.6], [0.0, 0.7]]
            .iter()
            .enumerate()
        {
            let support = [bottom[0] + offset[0], bottom[1] + offset[1], 0.0];
            nodes.push(support.to_vec());
            links.push([b * 5 + k, b * 5 + 4]);
            lengths.push(distance(&support, bottom));
        }
        nodes.push(vec![bottom[0] + 0.05, bottom[1] - 0.05, -0.5]);
    }
    links.push([4, 9]);
    lengths.push(1.1);
    let fixed: Vec<usize> = (0..10).filter(|i| i % 5 != 4).collect();
    let mut network = network(3, &nodes, &fixed, &links, &lengths);
    assert!(!network.path);
    let outcome = solve(&mut network);
    assert_eq!(check_equilibrium(&network, &outcome), 8);
    for (b, bottom) in bottoms.iter().enumerate() {
        let position = &outcome.z[b * 3..b * 3 + 3];
        assert!(distance(position, bottom) <= 1e-9, "node {b} at {position:?}");
    }
}

/// A hanging grid is a strict local minimum; the test runs on the sparse Newton matrix.
#[test]
fn hanging_grid_passes_the_second_order_test() {
    let mut network = grid(4);
    let outcome = solve(&mut network);
    check_equilibrium(&network, &outcome);
    let mut point = Point::default();
    network
        .evaluate(&outcome.z, &outcome.mu, &mut point)
        .expect("no caller's field");
    let total_length: f64 = network.lengths.iter().sum();
    assert_eq!(
        escape_test(&network, &point, &outcome.mu, 1e-9, total_length),
        Verdict::Minimum
    );
}

/// The second-order test's eigenvalue search on a net's sparse matrix: a random symmetric matrix
/// on a grid's pattern (nodes out of order, so its minimum-degree order is not the identity) has
/// the lowest eigenvalue and eigenvector of the dense Jacobi solver.
#[test]
fn lowest_eigenpair_of_a_sparse_matrix() {
    let mut rng = Rng::new(7);
    for (side, d) in [(3, 2), (4, 3), (6, 3)] {
        let n = side * side;
        let label = |i: usize, j: usize| (i * side + j) * 7 % n; // (7 is prime to these n)
        let mut pairs = Vec::new();
        for i in 0..side {
            for j in 0..side {
                if i + 1 < side {
                    pairs.push([label(i, j), label(i + 1, j)]);
                }
                if j + 1 < side {
                    pairs.push([label(i, j), label(i, j + 1)]);
                }
            }
        }
        let mut matrix = SparseMatrix::with_pairs(n, d, pairs.clone());
        matrix.reset(n, d);
        for f in 0..n {
            let mut block = vec![0.0; d * d];
            for a in 0..d {
                for b in 0..=a {
                    let value = rng.range(-1.0, 1.0);
                    block[a * d + b] = value;
                    block[b * d + a] = value;
                }
            }
            matrix.add_node(f, &block);
        }
        for &[f, g] in &pairs {
            let block: Vec<f64> = (0..d * d).map(|_| rng.range(-1.0, 1.0)).collect();
            matrix.add_pair(f, g, &block);
        }
        let size = n * d;
        let dense = matrix.to_dense();
        let (values, vectors) = symmetric_eigen(&dense, size);
        let scale = values.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let (value, vector) = lowest_eigenpair(
            &matrix,
            values[0] - 0.1 * scale,
            values[0] + 0.5 * (values[1] - values[0]),
            start_vector(size),
        )
        .expect("found");
        assert!(
            (value - values[0]).abs() <= 1e-9 * scale,
            "{value} vs {}",
            values[0]
        );
        let along: f64 = vector.iter().zip(&vectors[0]).map(|(x, y)| x * y).sum();
        assert!(1.0 - along.abs() <= 1e-12, "eigenvector off: cosine {along}");
    }
}

/// Solve times of square grids in space (run with `--release --ignored --nocapture`; the sizes
/// from GRID_SIZES, e.g. `GRID_SIZES=20,50,100`, the start's sag from GRID_SAG, 0 to 1).
#[test]
#[ignore]
fn grid_timings() {
    let sizes: Vec<usize> = std::env::var("GRID_SIZES")
        .map(|s| s.split(',').map(|v| v.parse().expect("sizes")).collect())
        .unwrap_or(vec![20, 50]);
    let sag: f64 = std::env::var("GRID_SAG")
        .map(|s| s.parse().expect("a sag"))
        .unwrap_or(0.0);
    for n in sizes {
        let mut network = sagging_grid(n, sag);
        let started = std::time::Instant::now();
        let outcome = solve(&mut network);
        let seconds = started.elapsed().as_secs_f64();
        let s = network.statistics;
        println!(
            "{n}x{n}: {:?} in {seconds:.3} s, {} steps ({} interior point, {} polish), {} factorizations; newton {:.3} s, polish {:.3} s, evaluation {:.3} s",
            outcome.status,
            outcome.iterations,
            s.interior_point_steps,
            s.polish_steps,
            s.factorizations,
            s.newton_seconds,
            s.polish_seconds,
            s.evaluation_seconds
        );
        if outcome.status == Status::Optimal {
            check_equilibrium(&network, &outcome);
        }
    }
}
