//! The derivatives `Network::evaluate` and `Network::newton_matrix` deliver, against closed forms and
//! central finite differences of the core's own values.
//!
//! Every check runs over small chains (6 to 10 nodes, both ends fixed, the nodes between free) in
//! 2-D and 3-D, in both formulations, without obstacles, with two quadratic obstacles (a disk or
//! sphere and a general quadratic), with two obstacles of a test-defined, non-quadratic
//! `NodeField`, and with two disks (spheres) in link contact through a test-defined
//! `SegmentField`. Links point either way along the chain, and their lengths are set so that some
//! norm links are shorter than `SMOOTH_RATIO l` (the parabola branch) and some longer, every one at
//! least 0.1 l from the kink at `d = SMOOTH_RATIO l` (finite differences of size 1e-5 never cross
//! it).
//!
//! * the constraint values are the documented formulas;
//! * `row_times` (J dz) and `add_transpose_times` (J^T v) are the finite-difference Jacobian of c;
//! * `dual` is `grad E + J^T mu` with that Jacobian;
//! * the Newton matrix with sigma = 0 is the finite-difference Jacobian of `dual` (the energy is
//!   linear, so that is W, the Hessian of the Lagrangian), and with sigma > 0 it is
//!   `W + J^T diag(sigma) J` assembled densely here.

mod common;

use common::{max_abs, Rng};
use funicular_core::evaluate::Point;
use funicular_core::linalg::BlockTridiagonal;
use funicular_core::problem::{
    Formulation, Interrupted, Network, NodeField, Quadratics, ScaledObstacles, SegmentField, SMOOTH_RATIO,
};

/// The finite-difference step, in units of the longest link (about 1).
const STEP: f64 = 1e-5;
/// Agreement with a central difference, relative to the largest entry compared.
const RELATIVE: f64 = 1e-6;
/// The height of the [`Bumps`] field's wavy floor.
const FLOOR: f64 = -0.4;

#[derive(Clone, Copy, Debug)]
enum Kind {
    /// No obstacle.
    Free,
    /// A disk (sphere) of radius 0.8 and a general quadratic with a linear term.
    Quadratic,
    /// The test's own node field, [`Bumps`].
    Field,
    /// Link contact: the test's own segment field, [`Spheres`].
    Segments,
}

/// One test chain: its description for failure messages, the network, an iterate and multipliers.
struct Case {
    label: String,
    network: Network,
    z: Vec<f64>,
    mu: Vec<f64>,
    /// The Gaussian bump's centre (Kind::Field only).
    bump_centre: Vec<f64>,
    /// The spheres' centres, (J, d) (Kind::Segments only).
    sphere_centres: Vec<f64>,
}

/// Two non-quadratic obstacles evaluated by the test, with their exact derivatives:
///
/// * a wavy floor `phi_0 = h - p_last + 0.1 sin(3 p_0)` (inside below the curve);
/// * a Gaussian bump `phi_1 = exp(-|p - c|^2) - 1/2` (inside where it exceeds 1/2), whose Hessian
///   `(4 (p - c)(p - c)^T - 2 I) exp(-|p - c|^2)` couples every pair of coordinates.
struct Bumps {
    dim: usize,
    floor: f64,
    centre: Vec<f64>,
}

impl NodeField for Bumps {
    fn count(&self) -> usize {
        2
    }

    fn evaluate(
        &mut self,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        let d = self.dim;
        let n = points.len() / d;
        for (f, p) in points.chunks_exact(d).enumerate() {
            // the wavy floor, obstacle 0
            phi[f] = self.floor - p[d - 1] + 0.1 * (3.0 * p[0]).sin();
            let g = &mut gradient[f * d..f * d + d];
            g.fill(0.0);
            g[0] = 0.3 * (3.0 * p[0]).cos();
            g[d - 1] = -1.0;
            let h = &mut hessian[f * d * d..(f + 1) * d * d];
            h.fill(0.0);
            h[0] = -0.9 * (3.0 * p[0]).sin();
            // the Gaussian bump, obstacle 1
            let offset: Vec<f64> = (0..d).map(|i| p[i] - self.centre[i]).collect();
            let bump = (-offset.iter().map(|x| x * x).sum::<f64>()).exp();
            let row = n + f;
            phi[row] = bump - 0.5;
            for i in 0..d {
                gradient[row * d + i] = -2.0 * offset[i] * bump;
                for k in 0..d {
                    let identity = if i == k { 1.0 } else { 0.0 };
                    hessian[row * d * d + i * d + k] = (4.0 * offset[i] * offset[k] - 2.0 * identity) * bump;
                }
            }
        }
        Ok(())
    }
}

/// Disks (spheres) of radius [`RADIUS`] in link contact: each link's row is the largest
/// `phi = (R^2 - |p - c|^2) / (2 R)` along it, at its point closest to the centre. With `u = b - a`,
/// `e = p - c` at that point `p = a + t u` and `g = -e / R`, the envelope theorem gives the gradient
/// `((1 - t) g, t g)`; differentiating once more, with `dt/da = (e - (1 - t) u) / |u|^2` and
/// `dt/db = -(e + t u) / |u|^2` (from `e . u = 0`), the Hessian's block (i, j) over the nodes
/// `x_a = a, x_b = b` is `sign_i g (dt/dx_j)^T - s_i (dp/dx_j) / R`, with `s = (1 - t, t)`,
/// `sign = (-1, 1)`, `dp/da = (1 - t) I + u (dt/da)^T`, `dp/db = t I + u (dt/db)^T`. Where the
/// closest point is a link's end (t clamped to 0 or 1) the row is phi at that node: Hessian
/// `-I / R` on its block alone. The test chains keep every link's unclamped t at least 0.03 from
/// 0 and 1, where the row is not twice differentiable.
struct Spheres {
    dim: usize,
    links: Vec<[usize; 2]>,
    centres: Vec<f64>,
}

const RADIUS: f64 = 0.8;

/// Where along the line through a and b (from a) the point closest to `centre` is, unclamped.
fn closest_along(a: &[f64], b: &[f64], centre: &[f64]) -> f64 {
    let d = a.len();
    let (mut along, mut squared) = (0.0, 0.0);
    for i in 0..d {
        let u = b[i] - a[i];
        along -= (a[i] - centre[i]) * u;
        squared += u * u;
    }
    along / squared
}

impl SegmentField for Spheres {
    fn count(&self) -> usize {
        self.centres.len() / self.dim
    }

    fn evaluate(
        &mut self,
        positions: &[f64],
        psi: &mut [f64],
        t: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        let d = self.dim;
        let (n_links, size) = (self.links.len(), 2 * d);
        for (j, centre) in self.centres.chunks_exact(d).enumerate() {
            for (r, &[a, b]) in self.links.iter().enumerate() {
                let row = j * n_links + r;
                let (pa, pb) = (&positions[a * d..a * d + d], &positions[b * d..b * d + d]);
                let along = closest_along(pa, pb, centre).clamp(0.0, 1.0);
                let u: Vec<f64> = (0..d).map(|i| pb[i] - pa[i]).collect();
                let e: Vec<f64> = (0..d).map(|i| pa[i] + along * u[i] - centre[i]).collect();
                let squared_u: f64 = u.iter().map(|x| x * x).sum();
                t[row] = along;
                psi[row] = (RADIUS * RADIUS - e.iter().map(|x| x * x).sum::<f64>()) / (2.0 * RADIUS);
                for i in 0..d {
                    gradient[row * d + i] = -e[i] / RADIUS;
                }
                let block = &mut hessian[row * size * size..(row + 1) * size * size];
                block.fill(0.0);
                if along == 0.0 || along == 1.0 {
                    let offset = if along == 0.0 { 0 } else { d };
                    for i in 0..d {
                        block[(offset + i) * size + offset + i] = -1.0 / RADIUS;
                    }
                    continue;
                }
                // dt/da and dt/db, then dp/dx_j and the blocks
                let dt: [Vec<f64>; 2] = [
                    (0..d)
                        .map(|i| (e[i] - (1.0 - along) * u[i]) / squared_u)
                        .collect(),
                    (0..d).map(|i| -(e[i] + along * u[i]) / squared_u).collect(),
                ];
                let share = [1.0 - along, along];
                let sign = [-1.0, 1.0];
                for x in 0..2 {
                    for y in 0..2 {
                        for i in 0..d {
                            for k in 0..d {
                                let identity = if i == k { share[y] } else { 0.0 };
                                let dp = identity + u[i] * dt[y][k];
                                block[(x * d + i) * size + y * d + k] =
                                    sign[x] * (-e[i] / RADIUS) * dt[y][k] - share[x] * dp / RADIUS;
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// Centres for [`Spheres`] below the chain: drawn until every link's closest point to each is at
/// least 0.03 (in t) from its ends' kinks, and some link's lies inside the link.
fn sphere_centres(dim: usize, positions: &[f64], links: &[[usize; 2]], rng: &mut Rng) -> Vec<f64> {
    let span = positions[positions.len() - dim];
    for _ in 0..1000 {
        let mut centres = Vec::new();
        for _ in 0..2 {
            centres.push(rng.range(0.0, span));
            centres.extend((1..dim - 1).map(|_| rng.range(-0.5, 0.5)));
            centres.push(rng.range(-1.2, -0.6));
        }
        let along: Vec<f64> = centres
            .chunks_exact(dim)
            .flat_map(|c| {
                links.iter().map(move |&[a, b]| {
                    closest_along(
                        &positions[a * dim..a * dim + dim],
                        &positions[b * dim..b * dim + dim],
                        c,
                    )
                })
            })
            .collect();
        let clear = along.iter().all(|t| t.abs() > 0.03 && (t - 1.0).abs() > 0.03);
        if clear && along.iter().any(|t| (0.0..1.0).contains(t)) {
            return centres;
        }
    }
    panic!("no centres clear of the links' ends");
}

/// phi of the test's quadratics, from the expanded form `value + b.(p - c) + (p - c)^T H (p - c) / 2`
/// (the same function as the documented `value + (g(p) + b).(p - c) / 2`, written differently).
fn quadratic_phi(quadratics: &Quadratics, j: usize, p: &[f64]) -> f64 {
    let d = p.len();
    let centre = &quadratics.centres[j * d..j * d + d];
    let b = &quadratics.gradients[j * d..j * d + d];
    let h = &quadratics.hessians[j * d * d..(j + 1) * d * d];
    let offset: Vec<f64> = (0..d).map(|i| p[i] - centre[i]).collect();
    let mut value = quadratics.values[j];
    for i in 0..d {
        value += b[i] * offset[i];
        for k in 0..d {
            value += 0.5 * offset[i] * h[i * d + k] * offset[k];
        }
    }
    value
}

/// A disk (sphere) of radius 0.8 below the chain's middle and a general quadratic.
fn quadratics(dim: usize, middle: f64, rng: &mut Rng) -> Quadratics {
    let radius = 0.8;
    let mut q = Quadratics::default();
    // the disk: value R/2, b = 0, H = -I/R
    q.centres.push(middle);
    q.centres.extend((1..dim).map(|_| -0.9));
    q.values.push(radius / 2.0);
    q.gradients.extend((0..dim).map(|_| 0.0));
    for i in 0..dim {
        q.hessians
            .extend((0..dim).map(|k| if i == k { -1.0 / radius } else { 0.0 }));
    }
    // a general quadratic: random centre, value, linear term and symmetric Hessian
    q.centres.extend((0..dim).map(|_| rng.range(-1.0, 1.0)));
    q.values.push(rng.range(-0.5, 0.5));
    q.gradients.extend((0..dim).map(|_| rng.range(-1.0, 1.0)));
    let mut h = vec![0.0; dim * dim];
    for i in 0..dim {
        for k in i..dim {
            let value = rng.range(-1.0, 1.0);
            h[i * dim + k] = value;
            h[k * dim + i] = value;
        }
    }
    q.hessians.extend(h);
    q
}

/// A chain of 6 to 10 nodes with both ends fixed; see the module's documentation.
fn case(dim: usize, formulation: Formulation, kind: Kind, seed: u64) -> Case {
    let mut rng = Rng::new(seed * 31 + dim as u64 * 7 + kind as u64);
    let n_nodes = 6 + rng.below(5);
    let mut positions = Vec::with_capacity(n_nodes * dim);
    for i in 0..n_nodes {
        positions.push(0.6 * i as f64 + rng.range(-0.15, 0.15));
        positions.extend((1..dim).map(|_| rng.range(-0.3, 0.3)));
    }
    let free: Vec<usize> = (1..n_nodes - 1).collect();
    // d / l cycles through both sides of SMOOTH_RATIO = 0.5, each at least 0.1 away from it
    let ratios = [0.3, 0.8, 1.3, 0.38, 0.65, 0.2, 1.05, 0.9, 0.35];
    assert!(ratios.iter().all(|r| (r - SMOOTH_RATIO).abs() >= 0.1));
    let mut links = Vec::new();
    let mut lengths = Vec::new();
    for k in 0..n_nodes - 1 {
        let link = if rng.unit() < 0.5 { [k, k + 1] } else { [k + 1, k] };
        let distance = distance(&positions, dim, link);
        links.push(link);
        lengths.push(distance / ratios[(k + seed as usize) % ratios.len()]);
    }
    let load: Vec<f64> = (0..n_nodes).map(|_| rng.range(0.02, 0.2)).collect();
    let middle = 0.3 * n_nodes as f64;
    let sphere_centres = sphere_centres(dim, &positions, &links, &mut rng);
    let mut bump_centre = vec![middle];
    bump_centre.extend((1..dim).map(|_| rng.range(-0.3, 0.3)));
    let obstacles = match kind {
        Kind::Free => ScaledObstacles::none(),
        Kind::Quadratic => ScaledObstacles::Quadratic(quadratics(dim, middle, &mut rng)),
        Kind::Field => ScaledObstacles::Nodes(Box::new(Bumps {
            dim,
            floor: FLOOR,
            centre: bump_centre.clone(),
        })),
        Kind::Segments => ScaledObstacles::Links(Box::new(Spheres {
            dim,
            links: links.clone(),
            centres: sphere_centres.clone(),
        })),
    };
    let mut network = Network::new(
        dim,
        formulation,
        positions,
        free,
        links,
        lengths,
        load,
        vec![0.0; dim],
        obstacles,
    )
    .expect("a valid chain");
    let z = network.free_coordinates();
    let mu: Vec<f64> = (0..network.n_constraints())
        .map(|r| {
            if r < network.n_links() {
                rng.range(0.2, 1.5)
            } else {
                rng.range(0.1, 1.0)
            }
        })
        .collect();
    let label = format!("d = {dim}, {formulation:?}, {kind:?}, {n_nodes} nodes (seed {seed})");
    // the point must lie on both branches of the norm form
    let point = evaluated(&mut network, &z, &mu);
    let short = (0..network.n_links())
        .filter(|&r| distance(&point.positions, dim, network.links[r]) < SMOOTH_RATIO * network.lengths[r])
        .count();
    assert!(
        short > 0 && short < network.n_links(),
        "{label}: {short} short links"
    );
    Case {
        label,
        network,
        z,
        mu,
        bump_centre,
        sphere_centres,
    }
}

/// Where on the segment from a to b (in t from a) the point nearest `centre` is: the best of 101
/// grid points, refined by golden-section search on the squared distance (convex in t).
fn nearest_by_search(a: &[f64], b: &[f64], centre: &[f64]) -> f64 {
    let squared = |t: f64| -> f64 {
        (0..a.len())
            .map(|i| (a[i] + t * (b[i] - a[i]) - centre[i]).powi(2))
            .sum()
    };
    let best = (0..=100)
        .map(|k| k as f64 / 100.0)
        .min_by(|x, y| squared(*x).total_cmp(&squared(*y)))
        .unwrap();
    let (mut low, mut high) = ((best - 0.01).max(0.0), (best + 0.01).min(1.0));
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..100 {
        let (x, y) = (high - ratio * (high - low), low + ratio * (high - low));
        if squared(x) < squared(y) {
            high = y;
        } else {
            low = x;
        }
    }
    0.5 * (low + high)
}

/// Every test chain: d = 2 and 3, both formulations, the four obstacle set-ups, two sizes each.
fn cases() -> Vec<Case> {
    let mut all = Vec::new();
    for dim in [2, 3] {
        for formulation in [Formulation::Norm, Formulation::Squared] {
            for kind in [Kind::Free, Kind::Quadratic, Kind::Field, Kind::Segments] {
                for seed in 0..2 {
                    all.push(case(dim, formulation, kind, seed));
                }
            }
        }
    }
    all
}

fn distance(positions: &[f64], dim: usize, [a, b]: [usize; 2]) -> f64 {
    (0..dim)
        .map(|i| (positions[a * dim + i] - positions[b * dim + i]).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn evaluated(network: &mut Network, z: &[f64], mu: &[f64]) -> Point {
    let mut point = Point::default();
    network
        .evaluate(z, mu, &mut point)
        .expect("the test's fields never interrupt");
    point
}

/// Central differences of `of(point)` over every free coordinate: a row-major (len x n d) matrix.
fn finite_difference(case: &mut Case, of: fn(&Point) -> &[f64]) -> Vec<f64> {
    let size = case.z.len();
    let mut columns = Vec::with_capacity(size);
    for j in 0..size {
        let mut z = case.z.clone();
        z[j] = case.z[j] + STEP;
        let plus = of(&evaluated(&mut case.network, &z, &case.mu)).to_vec();
        z[j] = case.z[j] - STEP;
        let minus = of(&evaluated(&mut case.network, &z, &case.mu)).to_vec();
        columns.push(
            plus.iter()
                .zip(&minus)
                .map(|(p, m)| (p - m) / (2.0 * STEP))
                .collect::<Vec<f64>>(),
        );
    }
    let rows = columns[0].len();
    (0..rows)
        .flat_map(|r| columns.iter().map(move |column| column[r]))
        .collect()
}

/// The finite-difference Jacobian of c, (m x n d).
fn jacobian(case: &mut Case) -> Vec<f64> {
    finite_difference(case, |point| &point.c)
}

/// The finite-difference W: the Jacobian of `dual`, (n d x n d).
fn hessian(case: &mut Case) -> Vec<f64> {
    finite_difference(case, |point| &point.dual)
}

/// Asserts `actual` is `expected` to RELATIVE of the largest expected entry (at least 1).
fn assert_close(actual: &[f64], expected: &[f64], what: &str, label: &str) {
    assert_eq!(actual.len(), expected.len(), "{label}: {what} has the wrong size");
    let scale = max_abs(expected).max(1.0);
    for (i, (a, e)) in actual.iter().zip(expected).enumerate() {
        assert!(
            (a - e).abs() <= RELATIVE * scale,
            "{label}: {what}[{i}] = {a}, finite differences {e}"
        );
    }
}

/// The constraint values are the documented closed forms: `d - l` (the parabola
/// `(d^2 + r^2) / (2 r) - l` below `r = SMOOTH_RATIO l`) or `d^2 - l^2`, then phi at every free
/// node (node contact) or its largest value along every link (link contact), obstacle by obstacle.
#[test]
fn constraint_values_follow_their_closed_forms() {
    for mut case in cases() {
        let point = evaluated(&mut case.network, &case.z, &case.mu);
        let network = &case.network;
        let d = network.dim;
        let mut expected = Vec::new();
        for (r, &link) in network.links.iter().enumerate() {
            let (distance, length) = (distance(&point.positions, d, link), network.lengths[r]);
            let radius = SMOOTH_RATIO * length;
            expected.push(match network.formulation {
                Formulation::Squared => distance * distance - length * length,
                Formulation::Norm if distance >= radius => distance - length,
                Formulation::Norm => (distance * distance + radius * radius) / (2.0 * radius) - length,
            });
        }
        let nodes: Vec<&[f64]> = network
            .free
            .iter()
            .map(|&i| &point.positions[i * d..i * d + d])
            .collect();
        match &network.obstacles {
            ScaledObstacles::Quadratic(q) => {
                for j in 0..q.values.len() {
                    expected.extend(nodes.iter().map(|p| quadratic_phi(q, j, p)));
                }
            }
            ScaledObstacles::Nodes(_) => {
                expected.extend(nodes.iter().map(|p| FLOOR - p[d - 1] + 0.1 * (3.0 * p[0]).sin()));
                expected.extend(nodes.iter().map(|p| {
                    let squared: f64 = (0..d).map(|i| (p[i] - case.bump_centre[i]).powi(2)).sum();
                    (-squared).exp() - 0.5
                }));
            }
            ScaledObstacles::Links(_) => {
                // phi at each link's point closest to the centre, found by minimising the distance
                // over t on a grid and then by golden-section search (not by projection)
                for centre in case.sphere_centres.chunks_exact(d) {
                    for &[a, b] in &network.links {
                        let (pa, pb) = (
                            &point.positions[a * d..a * d + d],
                            &point.positions[b * d..b * d + d],
                        );
                        let t = nearest_by_search(pa, pb, centre);
                        let squared: f64 = (0..d)
                            .map(|i| (pa[i] + t * (pb[i] - pa[i]) - centre[i]).powi(2))
                            .sum();
                        expected.push((RADIUS * RADIUS - squared) / (2.0 * RADIUS));
                    }
                }
            }
        }
        for (r, (c, e)) in point.c.iter().zip(&expected).enumerate() {
            assert!(
                (c - e).abs() <= 1e-13 * e.abs().max(1.0),
                "{}: c[{r}] = {c}, expected {e}",
                case.label
            );
        }
        assert_eq!(point.c.len(), expected.len(), "{}", case.label);
    }
}

/// `row_times(point, r, dz)` is `(J dz)_r` and `add_transpose_times` is `J^T v`, J the
/// finite-difference Jacobian of c: checked on every unit vector (the whole Jacobian) and on random
/// vectors.
#[test]
fn row_times_is_the_derivative_of_the_constraints() {
    let mut rng = Rng::new(11);
    for mut case in cases() {
        let jacobian = jacobian(&mut case);
        let point = evaluated(&mut case.network, &case.z, &case.mu);
        let (m, size) = (point.c.len(), case.z.len());
        let mut products = vec![0.0; m * size];
        let mut unit = vec![0.0; size];
        for j in 0..size {
            unit[j] = 1.0;
            for r in 0..m {
                products[r * size + j] = case.network.row_times(&point, r, &unit);
            }
            unit[j] = 0.0;
        }
        assert_close(&products, &jacobian, "row_times on unit vectors", &case.label);

        let dz: Vec<f64> = (0..size).map(|_| rng.range(-1.0, 1.0)).collect();
        let along: Vec<f64> = (0..m).map(|r| case.network.row_times(&point, r, &dz)).collect();
        let expected: Vec<f64> = (0..m)
            .map(|r| (0..size).map(|j| jacobian[r * size + j] * dz[j]).sum())
            .collect();
        assert_close(&along, &expected, "row_times on a random vector", &case.label);

        let v: Vec<f64> = (0..m).map(|_| rng.range(-1.0, 1.0)).collect();
        let mut transposed = vec![0.0; size];
        case.network.add_transpose_times(&point, &v, &mut transposed);
        let expected: Vec<f64> = (0..size)
            .map(|j| (0..m).map(|r| jacobian[r * size + j] * v[r]).sum())
            .collect();
        assert_close(&transposed, &expected, "add_transpose_times", &case.label);
    }
}

/// `J^T mu` with the finite-difference Jacobian `jacobian` (rows by constraint).
fn transpose_times_mu(case: &Case, jacobian: &[f64]) -> Vec<f64> {
    let size = case.z.len();
    (0..size)
        .map(|j| {
            (0..case.mu.len())
                .map(|r| jacobian[r * size + j] * case.mu[r])
                .sum()
        })
        .collect()
}

/// `dual` is the gradient of the Lagrangian: the load along the last axis plus `J^T mu`, J from
/// finite differences.
#[test]
fn dual_is_the_load_plus_the_jacobian_transpose_times_mu() {
    for mut case in cases() {
        let jacobian = jacobian(&mut case);
        let point = evaluated(&mut case.network, &case.z, &case.mu);
        let d = case.network.dim;
        let mut expected = transpose_times_mu(&case, &jacobian);
        for (f, &node) in case.network.free.iter().enumerate() {
            expected[f * d + d - 1] += case.network.load[node];
        }
        assert_close(&point.dual, &expected, "dual", &case.label);
    }
}

/// With point loads P, `dual` is the load along the last axis, less P, plus `J^T mu`.
#[test]
fn dual_subtracts_the_point_loads() {
    for mut case in cases() {
        let jacobian = jacobian(&mut case);
        let (d, size) = (case.network.dim, case.z.len());
        let mut rng = Rng::new(size as u64 + 17);
        let loads: Vec<f64> = (0..case.network.positions.len())
            .map(|_| rng.range(-0.3, 0.3))
            .collect();
        case.network.point_loads = loads.clone();
        let point = evaluated(&mut case.network, &case.z, &case.mu);
        let mut expected = transpose_times_mu(&case, &jacobian);
        for (f, &node) in case.network.free.iter().enumerate() {
            expected[f * d + d - 1] += case.network.load[node];
            for k in 0..d {
                expected[f * d + k] -= loads[node * d + k];
            }
        }
        assert_close(&point.dual, &expected, "dual with point loads", &case.label);
    }
}

/// With sigma = 0 the Newton matrix is W, the derivative of `dual` (whose energy part is constant):
/// every entry against central differences, coupling blocks included.
#[test]
fn newton_matrix_without_barrier_is_the_derivative_of_dual() {
    for mut case in cases() {
        let expected = hessian(&mut case);
        let point = evaluated(&mut case.network, &case.z, &case.mu);
        let mut matrix = BlockTridiagonal::new(0, case.network.dim);
        case.network
            .newton_matrix(&point, &case.mu, &vec![0.0; case.mu.len()], &mut matrix);
        assert_eq!(
            (matrix.n, matrix.d),
            (case.network.n_free(), case.network.dim),
            "{}",
            case.label
        );
        assert_close(&matrix.to_dense(), &expected, "W", &case.label);
    }
}

/// With sigma > 0 the Newton matrix is `W + J^T diag(sigma) J`, assembled densely from the
/// finite-difference W and J (some sigma zero, the others spread over two decades). The matrix is
/// reused from the sigma = 0 assembly, so this also checks that a reassembly starts from zero.
#[test]
fn newton_matrix_adds_the_barrier_term() {
    let mut rng = Rng::new(5);
    for mut case in cases() {
        let w = hessian(&mut case);
        let jacobian = jacobian(&mut case);
        let point = evaluated(&mut case.network, &case.z, &case.mu);
        let (m, size) = (case.mu.len(), case.z.len());
        let sigma: Vec<f64> = (0..m)
            .map(|_| {
                if rng.unit() < 0.2 {
                    0.0
                } else {
                    10f64.powf(rng.range(-1.0, 1.0))
                }
            })
            .collect();
        let mut matrix = BlockTridiagonal::new(case.network.n_free(), case.network.dim);
        case.network
            .newton_matrix(&point, &case.mu, &vec![0.0; m], &mut matrix);
        case.network.newton_matrix(&point, &case.mu, &sigma, &mut matrix);
        let mut expected = w;
        for i in 0..size {
            for k in 0..size {
                expected[i * size + k] += (0..m)
                    .map(|r| jacobian[r * size + i] * sigma[r] * jacobian[r * size + k])
                    .sum::<f64>();
            }
        }
        assert_close(&matrix.to_dense(), &expected, "W + J^T sigma J", &case.label);
    }
}
