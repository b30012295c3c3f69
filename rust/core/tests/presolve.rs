//! The presolve and the exact start on small chains, against facts derived by hand: feasibility,
//! force balance along a taut vertical span, links within their lengths, nodes clear of an
//! obstacle, and the discrete catenary's equilibrium at every node.

use funicular_core::catenary::{exact_start, hanging_span, Rope};
use funicular_core::presolve::{massless_ends, presolve, Infeasible};
use funicular_core::problem::{Chain, QuadraticShapes, Quadratics};

fn chain(masses: Vec<f64>, lengths: Vec<f64>, supports: Vec<usize>, positions: Vec<f64>) -> Chain {
    Chain {
        dim: 2,
        masses,
        lengths,
        gravity: 9.81,
        supports,
        support_positions: positions,
        stiffness: Vec::new(),
    }
}

/// A disk of radius r at c: phi = (r^2 - |p - c|^2) / (2 r).
fn disk(c: [f64; 2], r: f64) -> Quadratics {
    Quadratics {
        centres: c.to_vec(),
        values: vec![r / 2.0],
        gradients: vec![0.0, 0.0],
        hessians: vec![-1.0 / r, 0.0, 0.0, -1.0 / r],
    }
}

fn none() -> Quadratics {
    Quadratics::default()
}

#[test]
fn supports_farther_apart_than_the_chain_are_infeasible() {
    let c = chain(vec![1.0; 3], vec![1.0; 2], vec![0, 2], vec![0.0, 0.0, 2.5, 0.0]);
    let q = none();
    let result = presolve(
        &c,
        &mut QuadraticShapes {
            dim: 2,
            quadratics: &q,
        },
        None,
        false,
    );
    match result {
        Err(Infeasible::TooFar {
            a: 0,
            b: 2,
            distance,
            length,
        }) => {
            assert_eq!((distance, length), (2.5, 2.0));
        }
        other => panic!("expected TooFar, got {other:?}"),
    }
}

#[test]
fn an_elastic_span_stretches_to_supports_beyond_its_length() {
    // supports 2.5 apart, 2 of unstretched chain between them, one link elastic: neither too far
    // nor fixed; its node starts on the chord, free
    let mut c = chain(vec![1.0; 3], vec![1.0; 2], vec![0, 2], vec![0.0, 0.0, 2.5, 0.0]);
    c.stiffness = vec![f64::INFINITY, 100.0];
    let q = none();
    let presolved = presolve(
        &c,
        &mut QuadraticShapes {
            dim: 2,
            quadratics: &q,
        },
        None,
        false,
    )
    .expect("an elastic span has no reach to check");
    assert_eq!(presolved.movable, vec![1]);
    assert_eq!(presolved.positions[2..4], [1.25, 0.0]);
    assert!(presolved.fixed_tension.iter().all(|&t| t == 0.0));
}

#[test]
fn a_taut_slanted_span_with_weight_is_infeasible_and_a_vertical_one_carries_the_weight_below() {
    let q = none();
    let slanted = chain(vec![1.0; 3], vec![1.0; 2], vec![0, 2], vec![0.0, 0.0, 2.0, 0.0]);
    let result = presolve(
        &slanted,
        &mut QuadraticShapes {
            dim: 2,
            quadratics: &q,
        },
        None,
        false,
    );
    assert!(matches!(result, Err(Infeasible::TautNotVertical { a: 0, b: 2 })));
    // supports 3 apart vertically, 3 links of 1: the interior nodes on the chord, the top link
    // carrying both interior nodes' weight more than the bottom one
    let masses = vec![0.0, 2.0, 3.0, 0.0];
    let vertical = chain(masses, vec![1.0; 3], vec![0, 3], vec![0.0, 3.0, 0.0, 0.0]);
    let start = presolve(
        &vertical,
        &mut QuadraticShapes {
            dim: 2,
            quadratics: &q,
        },
        None,
        false,
    )
    .unwrap();
    assert!(start.movable.is_empty());
    assert_eq!(&start.positions[2..6], &[0.0, 2.0, 0.0, 1.0]);
    let t = &start.fixed_tension;
    assert!(t.iter().all(|&x| x >= 0.0) && t.contains(&0.0));
    assert!((t[0] - t[1] - 9.81 * 2.0).abs() < 1e-12 && (t[1] - t[2] - 9.81 * 3.0).abs() < 1e-12);
}

#[test]
fn massless_ends_are_the_nodes_beyond_the_outermost_anchored_ones() {
    let c = chain(
        vec![0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.0],
        vec![1.0; 6],
        vec![3],
        vec![0.0, 0.0],
    );
    let (detached, attach) = massless_ends(&c);
    assert_eq!(detached, vec![0, 1, 5, 6]);
    assert_eq!(attach, vec![2, 2, 4, 4]);
}

#[test]
fn the_sag_keeps_every_link_shorter_than_its_length_and_clears_a_disk_below_the_chord() {
    for (right, obstacle) in [
        ([3.0, 0.0], none()),
        ([2.0, 1.0], none()),
        ([3.0, 0.0], disk([1.5, -1.2], 0.8)),
    ] {
        let n = 12;
        let lengths: Vec<f64> = (0..n - 1).map(|k| 0.3 + 0.02 * k as f64).collect();
        let c = chain(
            vec![1.0; n],
            lengths.clone(),
            vec![0, n - 1],
            vec![0.0, 0.0, right[0], right[1]],
        );
        let mut shapes = QuadraticShapes {
            dim: 2,
            quadratics: &obstacle,
        };
        let start = presolve(&c, &mut shapes, None, false).unwrap();
        assert_eq!(start.movable, (1..n - 1).collect::<Vec<_>>());
        let p = &start.positions;
        for k in 0..n - 1 {
            let d = (p[2 * k + 2] - p[2 * k]).hypot(p[2 * k + 3] - p[2 * k + 1]);
            assert!(d < lengths[k], "link {k}: {d} of {}", lengths[k]);
        }
        if !obstacle.values.is_empty() {
            for k in 1..n - 1 {
                let (x, y) = (p[2 * k] - 1.5, p[2 * k + 1] + 1.2);
                assert!(x.hypot(y) >= 0.8 * (1.0 - 1e-9), "node {k} inside the disk");
            }
        }
    }
}

#[test]
fn a_hanging_span_balances_every_node_and_reaches_the_support() {
    let masses = [1.0, 0.5, 2.0, 1.5, 0.7];
    let lengths = [0.4, 0.3, 0.5, 0.35, 0.45, 0.3];
    let (left, right) = ([0.0, 0.0], [1.6, 0.3]);
    let q = none();
    let (nodes, tension) = hanging_span(
        &masses,
        &lengths,
        9.81,
        &left,
        &right,
        &mut QuadraticShapes {
            dim: 2,
            quadratics: &q,
        },
    )
    .unwrap()
    .unwrap();
    let mut points = vec![left.to_vec()];
    points.extend(nodes.chunks_exact(2).map(<[f64]>::to_vec));
    points.push(right.to_vec());
    // every link taut, and every interior node in equilibrium: the link forces T_k u_k balance its weight
    for k in 0..lengths.len() {
        let d = (points[k + 1][0] - points[k][0]).hypot(points[k + 1][1] - points[k][1]);
        assert!(
            (d - lengths[k]).abs() < 1e-12,
            "link {k} is {d}, not {}",
            lengths[k]
        );
    }
    for i in 1..lengths.len() {
        let mut force = [0.0, -9.81 * masses[i - 1]];
        for (k, sign) in [(i - 1, -1.0), (i, 1.0)] {
            // link k pulls node i towards its other end
            let (a, b) = (&points[k], &points[k + 1]);
            for c in 0..2 {
                force[c] += sign * tension[k] * (b[c] - a[c]) / lengths[k];
            }
        }
        assert!(force[0].abs().max(force[1].abs()) < 1e-10, "node {i}: {force:?}");
    }
}

#[test]
fn the_rope_ends_at_its_far_support() {
    for (span, rise, length) in [
        (1.0, 0.0, 1.5),
        (0.3, -1.2, 2.0),
        (1.9, 0.1, 2.0),
        (1.0, 0.5, 1.1180339887498951),
    ] {
        let Some(rope) = Rope::between(span, rise, length, 1.0) else {
            assert!(length <= (span * span + rise * rise).sqrt() * (1.0 + 1e-15));
            continue;
        };
        let (x, y) = rope.position_at_arclength(length);
        assert!(
            (x - span).abs() < 1e-9 && (y - rise).abs() < 1e-9,
            "({x}, {y}) for ({span}, {rise})"
        );
    }
}

#[test]
fn the_exact_start_refuses_a_chain_through_an_obstacle_and_hangs_free_ends_straight_down() {
    let n = 21;
    let c = chain(
        vec![1.0; n],
        vec![0.1; n - 1],
        vec![0, 15],
        vec![0.0, 0.0, 1.0, 0.0],
    );
    let q = none();
    let (positions, tension) = exact_start(
        &c,
        &mut QuadraticShapes {
            dim: 2,
            quadratics: &q,
        },
    )
    .unwrap()
    .unwrap();
    // the tail of 5 nodes hangs below node 15, link k carrying the nodes after it
    for (i, node) in (16..n).enumerate() {
        assert!((positions[2 * node] - 1.0).abs() < 1e-15);
        assert!((positions[2 * node + 1] + 0.1 * (i + 1) as f64).abs() < 1e-12);
    }
    for (k, t) in tension.iter().enumerate().skip(15) {
        assert!((t - 9.81 * (n - 1 - k) as f64).abs() < 1e-9);
    }
    let through = disk([0.5, -0.3], 0.25);
    assert!(exact_start(
        &c,
        &mut QuadraticShapes {
            dim: 2,
            quadratics: &through
        }
    )
    .unwrap()
    .is_none());
}
