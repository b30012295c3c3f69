//! `ipm::lifting_off`, the polish's estimate of how many touching nodes leave a contact run at once,
//! ported exactly from the Python tests it replaced (`tests/test_contact.py`); and `ipm::median`
//! against a plain sort.

mod common;

use common::Rng;
use funicular_core::ipm::{lifting_off, median};

/// The indices of the rows that are set.
fn set_rows(flags: &[bool]) -> Vec<usize> {
    flags
        .iter()
        .enumerate()
        .filter(|(_, &flag)| flag)
        .map(|(i, _)| i)
        .collect()
}

/// The rows whose multiplier turned negative among the active ones.
fn leaving(active: &[bool], nu: &[f64]) -> Vec<bool> {
    active.iter().zip(nu).map(|(&a, &n)| a && n < 0.0).collect()
}

/// One obstacle's `rows` rows, `touching` active with force `force`, the others inactive at 0.
fn run(rows: usize, touching: std::ops::Range<usize>, force: f64) -> (Vec<bool>, Vec<f64>) {
    let active: Vec<bool> = (0..rows).map(|r| touching.contains(&r)).collect();
    let nu = active.iter().map(|&a| if a { force } else { 0.0 }).collect();
    (active, nu)
}

/// A run of touching nodes k too long holds the chain on the obstacle with a kink at its end,
/// whose force is `nu_0 (1 - k)` for touching forces `nu_0` just inside: k nodes leave (rounded
/// down); a negative force inside the run leaves alone.
#[test]
fn lift_off_drops_as_many_nodes_as_the_end_force_says() {
    let (active, mut nu) = run(60, 10..40, 2.0);
    nu[10] = 2.0 * (1.0 - 5.0); // 5 nodes too many at the start of the run
    nu[39] = 2.0 * (1.0 - 3.0) - 0.5; // 3.25 too many at its end: rounded down to 3
    nu[25] = -1e-3; // inside the run: leaves alone
    let dropped = lifting_off(&active, &nu, &leaving(&active, &nu), 60);
    assert_eq!(set_rows(&dropped), [10, 11, 12, 13, 14, 25, 37, 38, 39]);
}

/// However negative the end's force, no more than half the run leaves at once.
#[test]
fn lift_off_never_drops_more_than_half_a_run() {
    let (active, mut nu) = run(30, 5..25, 1.0);
    nu[5] = -1e3;
    let dropped = lifting_off(&active, &nu, &leaving(&active, &nu), 30);
    assert_eq!(set_rows(&dropped), (5..15).collect::<Vec<_>>());
}

/// With two obstacles each one's rows are judged on their own: the first test's run placed in the
/// second obstacle gives the same rows shifted by one obstacle's count, and the first obstacle's
/// untouched rows stay put.
#[test]
fn lift_off_treats_each_obstacle_on_its_own() {
    let (mut active, mut nu) = run(60, 0..0, 0.0);
    let (second_active, mut second_nu) = run(60, 10..40, 2.0);
    second_nu[10] = 2.0 * (1.0 - 5.0);
    second_nu[39] = 2.0 * (1.0 - 3.0) - 0.5;
    second_nu[25] = -1e-3;
    active.extend(second_active);
    nu.extend(second_nu);
    let dropped = lifting_off(&active, &nu, &leaving(&active, &nu), 60);
    let expected: Vec<usize> = [10, 11, 12, 13, 14, 25, 37, 38, 39]
        .iter()
        .map(|r| r + 60)
        .collect();
    assert_eq!(set_rows(&dropped), expected);
}

/// The median of a sorted copy: the middle value, or the mean of the two middle ones.
fn sorted_median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
    }
}

/// `median` on hand-picked slices and on random ones of odd and even lengths 1 to 40, repeated
/// values included.
#[test]
fn median_matches_a_sort() {
    assert_eq!(median(&[3.0]), 3.0);
    assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
    assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
    assert_eq!(median(&[-1.0, 5.0]), 2.0);
    assert_eq!(median(&[2.0, 2.0, 7.0, 2.0]), 2.0);
    let mut rng = Rng::new(9);
    for length in 1..=40 {
        for _ in 0..5 {
            // some values drawn from a few levels, so that ties occur
            let values: Vec<f64> = (0..length)
                .map(|_| {
                    if rng.unit() < 0.3 {
                        rng.below(3) as f64
                    } else {
                        rng.range(-10.0, 10.0)
                    }
                })
                .collect();
            assert_eq!(median(&values), sorted_median(&values), "{values:?}");
            let below = values.iter().filter(|&&v| v < median(&values)).count();
            let above = values.iter().filter(|&&v| v > median(&values)).count();
            assert!(below <= length / 2 && above <= length / 2, "{values:?}");
        }
    }
}
