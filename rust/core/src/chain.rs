//! The whole solve of a chain, in the problem's units: where it starts (the exact catenary, a coarser
//! chain's answer, or the presolve's guess), its presolve, one solve ([`crate::driver`]), the saddle
//! escape, and its answer with the fixed links' tensions and the massless free ends.
//!
//! Coarse to fine: a long chain with obstacles (or a very long one without) is first solved with
//! fewer nodes, and that answer, interpolated along the arclength with its forces, is the start:
//! the coarse chain already drapes over the obstacles, so the fine solve starts next to its answer
//! instead of travelling there in many short steps, and usually needs only the polish.

use crate::catenary::exact_start;
use crate::driver::{
    escape, multiplier, multipliers_in_units, network, obstacle_scales, solve_once, tension, Guess, Judged,
    Once, Options, Scaling, SolveError, Solved,
};
use crate::ipm::Status;
use crate::presolve::{massless_ends, presolve, repositioned, Presolved};
use crate::problem::{Chain, Interrupted, Network, OneByOne, Setup, Shapes, Statistics};

/// Chains with obstacles longer than this start from a coarse solve.
pub const COARSE_ABOVE: usize = 200;
/// The same without obstacles (below, one direct solve is as fast).
pub const COARSE_ABOVE_FREE: usize = 4000;
/// The coarse level has N / COARSE_FACTOR nodes, with obstacles at most COARSE_CAP until that is
/// N / COARSE_FACTOR_MAX: there the fine level spends a step correcting the contact near the
/// lift-off points whatever the coarse level, so a finer coarse level costs more than it saves.
const COARSE_FACTOR: usize = 8;
const COARSE_CAP: usize = 5000;
const COARSE_FACTOR_MAX: usize = 32;
/// Nodes up to which the escape checks the result (the test costs about a second at 10^5).
pub const ESCAPE_UP_TO: usize = 20_000;

/// Where a chain's solve starts, and what is known there.
struct Start {
    presolved: Presolved,
    scaling: Scaling,
    /// The guess's multipliers in the iteration's units and rows, if it had them.
    warm: Option<Vec<f64>>,
    /// What making the guess spent (coarse levels).
    statistics: Statistics,
    /// The guess is the solver's own (the exact start or a coarse level's answer).
    seeded: bool,
}

/// The start from `initial` or the built-in guess (the exact start, or coarse to fine): the
/// presolve from it and the solver's units.
fn start(
    chain: &Chain,
    setup: &Setup,
    options: &Options,
    initial: Option<&Guess>,
    check: &mut dyn FnMut() -> bool,
) -> Result<Start, SolveError> {
    let mut shapes = OneByOne {
        dim: chain.dim,
        obstacles: &setup.obstacles,
    };
    let built;
    let guess: Option<&Guess> = match initial {
        Some(guess) => Some(guess),
        None => {
            built = match if options.exact_start {
                exact_guess(chain, setup, &mut shapes)?
            } else {
                None
            } {
                Some(exact) => Some(exact),
                None => coarse_guess(chain, setup, options, check)?,
            };
            built.as_ref()
        }
    };
    // Link contact is left out: its step counts from a settled guess went both ways.
    let settled = guess.is_some_and(|g| g.settled) && !setup.links_contact;
    let presolved = presolve(chain, &mut shapes, guess.map(|g| g.positions.as_slice()), settled)?;
    let scaling = scaling(chain, setup, &presolved)?;
    let warm = match guess {
        Some(guess) if !scaling.free.is_empty() => scaled_multipliers(chain, setup, &scaling, guess),
        _ => None,
    };
    Ok(Start {
        presolved,
        scaling,
        warm,
        statistics: guess.map(|g| g.statistics).unwrap_or_default(),
        seeded: initial.is_none() && guess.is_some(),
    })
}

/// One solve of `chain` from `positions` (N, d, as a presolve placed them), if anything is free.
#[allow(clippy::too_many_arguments)]
fn solve_from(
    chain: &Chain,
    setup: &Setup,
    options: &Options,
    scaling: &Scaling,
    positions: Vec<f64>,
    warm: Option<&[f64]>,
    judged: bool,
    check: &mut dyn FnMut() -> bool,
) -> Result<Once, SolveError> {
    if scaling.free.is_empty() {
        return Ok(Once::still(positions));
    }
    solve_once(
        &chain.structure(),
        setup,
        options,
        scaling,
        positions,
        warm,
        judged,
        check,
    )
}

fn scaling(chain: &Chain, setup: &Setup, start: &Presolved) -> Result<Scaling, Interrupted> {
    let d = chain.dim;
    let n = chain.n_nodes();
    let length_unit = chain.lengths.iter().copied().fold(0.0, f64::max);
    let origin = chain.support_positions[..d].to_vec();
    let weight = chain.structure().force_scale();
    let mut movable = vec![false; n];
    for &node in &start.movable {
        movable[node] = true;
    }
    let mut detached = vec![false; n];
    for &node in &start.detached {
        detached[node] = true;
    }
    let links: Vec<usize> = (0..n - 1)
        .filter(|&k| (movable[k] || movable[k + 1]) && !detached[k] && !detached[k + 1])
        .collect();
    let free = start.movable.clone();
    let obstacle_scale = obstacle_scales(setup, d, &free, &start.positions, start.gradients.as_deref())?;
    Ok(Scaling {
        length_unit,
        origin,
        weight,
        free,
        links,
        obstacle_scale,
    })
}

/// The network the iteration would start from at `guess` (N, d), through the presolve and the
/// scaling (for tests of the iteration's derivatives).
pub fn network_at(chain: &Chain, setup: &Setup, guess: &[f64]) -> Result<Network, SolveError> {
    let mut shapes = OneByOne {
        dim: chain.dim,
        obstacles: &setup.obstacles,
    };
    let start = presolve(chain, &mut shapes, Some(guess), false)?;
    let scaling = scaling(chain, setup, &start)?;
    Ok(network(&chain.structure(), setup, &scaling, &start.positions))
}

/// The guess's multipliers in the iteration's units and order (links, then contact rows obstacle by
/// obstacle).
fn scaled_multipliers(chain: &Chain, setup: &Setup, scaling: &Scaling, guess: &Guess) -> Option<Vec<f64>> {
    let (links, contacts) = (
        guess.link_multipliers.as_ref()?,
        guess.obstacle_multipliers.as_ref()?,
    );
    let unit = scaling.link_unit(setup);
    let mut scaled: Vec<f64> = scaling.links.iter().map(|&k| links[k] / unit).collect();
    let columns = if setup.links_contact {
        chain.n_nodes() - 1
    } else {
        chain.n_nodes()
    };
    for j in 0..setup.obstacles.count {
        let factor = scaling.obstacle_scale[j] / scaling.weight;
        scaled.extend(
            scaling
                .contact_rows(setup)
                .iter()
                .map(|&i| contacts[j * columns + i] * factor),
        );
    }
    Some(scaled)
}

/// The answer in the problem's units from the last solve `once` from `start`: the fixed links'
/// tensions, the massless free ends on the nodes they hang from.
fn solved(
    chain: &Chain,
    setup: &Setup,
    start: &Start,
    once: Once,
    iterations: usize,
    statistics: Statistics,
    judged: Option<Judged>,
) -> Solved {
    let d = chain.dim;
    let n = chain.n_nodes();
    let structure = chain.structure();
    let mut positions = once.positions;
    // (links between fixed nodes: as the presolve placed them)
    let lengths = structure.distances(&positions);
    let presolved = &start.presolved;
    for (&node, &on) in presolved.detached.iter().zip(&presolved.attach) {
        let anchor = positions[on * d..on * d + d].to_vec();
        positions[node * d..node * d + d].copy_from_slice(&anchor);
    }
    let mut link_multipliers: Vec<f64> = (0..n - 1)
        .map(|k| multiplier(setup.formulation, presolved.fixed_tension[k], lengths[k]))
        .collect();
    let columns = if setup.links_contact { n - 1 } else { n };
    let count = setup.obstacles.count;
    let mut obstacle_multipliers = vec![0.0; count * columns];
    multipliers_in_units(
        &structure,
        setup,
        &start.scaling,
        &once.mu,
        &lengths,
        &mut link_multipliers,
        &mut obstacle_multipliers,
    );
    Solved {
        status: once.status,
        positions,
        link_multipliers,
        obstacle_multipliers,
        iterations,
        statistics,
        judged,
    }
}

/// The equilibrium with its forces where `catenary::exact_start` knows it (a chain touching
/// nothing): the polish then only confirms it, in one Newton step. With link contact every link
/// the solver keeps out of the obstacles (a movable end, no detached end) must clear them too.
fn exact_guess(chain: &Chain, setup: &Setup, shapes: &mut dyn Shapes) -> Result<Option<Guess>, SolveError> {
    let Some((positions, tensions)) = exact_start(chain, shapes)? else {
        return Ok(None);
    };
    let n = chain.n_nodes();
    if setup.links_contact && setup.obstacles.count > 0 {
        let (detached, _) = massless_ends(chain);
        let (mut support, mut left_out) = (vec![false; n], vec![false; n]);
        chain.supports.iter().for_each(|&s| support[s] = true);
        detached.iter().for_each(|&i| left_out[i] = true);
        let links: Vec<usize> = (0..n - 1)
            .filter(|&k| (!support[k] || !support[k + 1]) && !left_out[k] && !left_out[k + 1])
            .collect();
        let (l, d, count) = (links.len(), chain.dim, setup.obstacles.count);
        let (mut psi, mut t) = (vec![0.0; count * l], vec![0.0; count * l]);
        let (mut gradient, mut hessian) = (vec![0.0; count * l * d], vec![0.0; count * l * 4 * d * d]);
        let segments = setup
            .obstacles
            .segments
            .as_ref()
            .expect("link contact needs the caller's segments");
        segments
            .borrow_mut()
            .evaluate(&positions, &links, &mut psi, &mut t, &mut gradient, &mut hessian)?;
        if !psi.iter().all(|&v| v < 0.0) {
            return Ok(None);
        }
    }
    let lengths = chain.structure().distances(&positions);
    let links = tensions
        .iter()
        .zip(&lengths)
        .map(|(&t, &l)| multiplier(setup.formulation, t, l))
        .collect();
    let columns = n - usize::from(setup.links_contact);
    Ok(Some(Guess {
        positions,
        link_multipliers: Some(links),
        obstacle_multipliers: Some(vec![0.0; setup.obstacles.count * columns]),
        settled: true,
        statistics: Statistics::default(),
    }))
}

/// `np.interp(x, xp, fp)` for ascending x and xp: piecewise linear, constant beyond the ends.
fn interpolate(x: &[f64], xp: &[f64], fp: &[f64]) -> Vec<f64> {
    let last = xp.len() - 1;
    let mut j = 0;
    x.iter()
        .map(|&v| {
            while j < last && xp[j + 1] <= v {
                j += 1;
            }
            if v <= xp[0] {
                fp[0]
            } else if j == last {
                fp[last]
            } else {
                let slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]);
                slope * (v - xp[j]) + fp[j]
            }
        })
        .collect()
}

/// Each node's arclength position along the chain, from 0 to 1.
fn arc_fractions(chain: &Chain) -> Vec<f64> {
    let total: f64 = chain.lengths.iter().sum();
    let mut arc = 0.0;
    let mut fractions = vec![0.0];
    for l in &chain.lengths {
        arc += l;
        fractions.push(arc / total);
    }
    fractions
}

/// The same chain with `nodes` nodes: total mass and length kept, spread equally; each support on
/// the node nearest its arclength position (None if two would share one).
fn with_nodes(chain: &Chain, nodes: usize) -> Option<Chain> {
    let arc = arc_fractions(chain);
    let supports: Vec<usize> = chain
        .supports
        .iter()
        .map(|&s| (arc[s] * (nodes - 1) as f64).round_ties_even() as usize)
        .collect();
    if supports.windows(2).any(|pair| pair[0] >= pair[1]) {
        return None;
    }
    let (mass, length): (f64, f64) = (chain.masses.iter().sum(), chain.lengths.iter().sum());
    // Elastic links: every coarse link as stiff as the whole chain is on average, so that the
    // chain stretches as much under the same tension (its compliance sum L0 / EA kept).
    let stiffness = if chain.stiffness.is_empty() {
        Vec::new()
    } else {
        let compliance: f64 = chain
            .lengths
            .iter()
            .zip(&chain.stiffness)
            .map(|(l, ea)| l / ea)
            .sum();
        vec![length / compliance; nodes - 1]
    };
    Some(Chain {
        dim: chain.dim,
        masses: vec![mass / nodes as f64; nodes],
        lengths: vec![length / (nodes - 1) as f64; nodes - 1],
        gravity: chain.gravity,
        supports,
        support_positions: chain.support_positions.clone(),
        stiffness,
    })
}

/// How many nodes the coarse level of a chain of n nodes gets.
fn coarse_nodes(n: usize, obstacles: bool) -> usize {
    if !obstacles {
        return n / COARSE_FACTOR;
    }
    (n / COARSE_FACTOR_MAX).max((n / COARSE_FACTOR).min(COARSE_CAP))
}

/// The length of chain each node stands for: half of each link next to it.
fn node_shares(chain: &Chain) -> Vec<f64> {
    let n = chain.n_nodes();
    let mut shares = vec![0.0; n];
    for (k, l) in chain.lengths.iter().enumerate() {
        shares[k] += 0.5 * l;
        shares[k + 1] += 0.5 * l;
    }
    shares
}

/// Grid sequencing for long chains: the same chain solved with fewer nodes (`coarse_nodes`), its
/// answer interpolated along the arclength, its forces too (tensions along the chain, contact
/// forces as a force per length). None where there is no coarse level or it did not converge.
fn coarse_guess(
    chain: &Chain,
    setup: &Setup,
    options: &Options,
    check: &mut dyn FnMut() -> bool,
) -> Result<Option<Guess>, SolveError> {
    let n = chain.n_nodes();
    let count = setup.obstacles.count;
    if n <= if count > 0 {
        COARSE_ABOVE
    } else {
        COARSE_ABOVE_FREE
    } {
        return Ok(None);
    }
    let Some(coarse) = with_nodes(chain, (COARSE_ABOVE / 2).max(coarse_nodes(n, count > 0))) else {
        return Ok(None);
    };
    let solved = match solve(&coarse, setup, options, None, false, check) {
        Ok(solved) if solved.status == Status::Optimal => solved,
        // (moving a support to a coarse node can make a nearly taut span infeasible; the fine
        // level reports what is wrong with the chain itself)
        Ok(_)
        | Err(SolveError::Infeasible(_) | SolveError::NotFactored | SolveError::ObstacleNotFinite { .. }) => {
            return Ok(None)
        }
        Err(SolveError::Interrupted) => return Err(SolveError::Interrupted),
    };
    let d = chain.dim;
    // The coarse supports lined up with the fine ones: the map between the supports' arclength
    // fractions on either chain (with both ends) takes each coarse support onto its fine support,
    // or the nodes next to a support start up to half a coarse link off it.
    let (fine_arc, coarse_arc) = (arc_fractions(chain), arc_fractions(&coarse));
    let (mut xp, mut fp) = (vec![0.0], vec![0.0]);
    for (&c, &f) in coarse.supports.iter().zip(&chain.supports) {
        if coarse_arc[c] > *xp.last().unwrap() {
            xp.push(coarse_arc[c]);
            fp.push(fine_arc[f]);
        }
    }
    if *xp.last().unwrap() < 1.0 {
        xp.push(1.0);
        fp.push(1.0);
    }
    let coarse_at = interpolate(&coarse_arc, &xp, &fp);
    let middles = |a: &[f64]| -> Vec<f64> { a.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect() };
    let (coarse_links, fine_links) = (middles(&coarse_at), middles(&fine_arc));
    let mut positions = vec![0.0; n * d];
    for i in 0..d {
        let coordinate: Vec<f64> = solved.positions.iter().skip(i).step_by(d).copied().collect();
        for (k, v) in interpolate(&fine_arc, &coarse_at, &coordinate)
            .into_iter()
            .enumerate()
        {
            positions[k * d + i] = v;
        }
    }
    let coarse_lengths = coarse.structure().distances(&solved.positions);
    let tensions: Vec<f64> = (0..coarse.n_nodes() - 1)
        .map(|k| tension(setup.formulation, solved.link_multipliers[k], coarse_lengths[k]))
        .collect();
    let fine_lengths = chain.structure().distances(&positions);
    let links = interpolate(&fine_links, &coarse_links, &tensions)
        .iter()
        .zip(&fine_lengths)
        .map(|(&t, &l)| multiplier(setup.formulation, t, l))
        .collect();
    let mut contacts = Vec::new();
    let coarse_columns = solved.obstacle_multipliers.len() / count.max(1);
    for j in 0..count {
        let row = &solved.obstacle_multipliers[j * coarse_columns..(j + 1) * coarse_columns];
        if setup.links_contact {
            // per link: a force per length of link
            let density: Vec<f64> = row.iter().zip(&coarse.lengths).map(|(m, l)| m / l).collect();
            let fine = interpolate(&fine_links, &coarse_links, &density);
            contacts.extend(fine.iter().zip(&chain.lengths).map(|(f, l)| f * l));
        } else {
            let (coarse_shares, fine_shares) = (node_shares(&coarse), node_shares(chain));
            let density: Vec<f64> = row.iter().zip(&coarse_shares).map(|(m, s)| m / s).collect();
            let fine = interpolate(&fine_arc, &coarse_at, &density);
            contacts.extend(fine.iter().zip(&fine_shares).map(|(f, s)| f * s));
        }
    }
    Ok(Some(Guess {
        positions,
        link_multipliers: Some(links),
        obstacle_multipliers: Some(contacts),
        settled: true,
        statistics: solved.statistics,
    }))
}

/// The equilibrium of `chain` with its forces, from `initial` or the built-in guess; `judge`: the
/// escape's second-order test at the result too.
///
/// With obstacles (node contact, up to ESCAPE_UP_TO nodes or `options.escape_up_to`) and
/// `options.escape_saddles`, a result that is not a minimum is left along a direction of negative
/// curvature (see the module documentation). A chain solved coarse to fine is checked on its
/// coarsest level only: each finer level starts next to the minimum the level below found. One
/// that starts from the exact catenary touches no obstacle and is the free chain's minimum, which
/// is convex: nothing to check.
pub fn solve(
    chain: &Chain,
    setup: &Setup,
    options: &Options,
    initial: Option<&Guess>,
    judge: bool,
    check: &mut dyn FnMut() -> bool,
) -> Result<Solved, SolveError> {
    let escape = options.escape_saddles
        && setup.obstacles.count > 0
        && !setup.links_contact
        && chain.n_nodes() <= options.escape_up_to.unwrap_or(ESCAPE_UP_TO);
    let start = start(chain, setup, options, initial, check)?;
    let once = solve_from(
        chain,
        setup,
        options,
        &start.scaling,
        start.presolved.positions.clone(),
        start.warm.as_deref(),
        escape || judge,
        check,
    )?;
    let mut iterations = once.iterations;
    let mut statistics = start.statistics;
    statistics.add(&once.statistics);
    let structure = chain.structure();
    let mut once = once;
    if escape && !start.seeded {
        let mut shapes = OneByOne {
            dim: chain.dim,
            obstacles: &setup.obstacles,
        };
        once = self::escape(
            once,
            &structure,
            |once| once.judged(&structure, &start.scaling),
            |positions| {
                // (the presolve's supports, taut spans and detached ends stay; so does the scaling)
                let moved = repositioned(chain, &mut shapes, &start.presolved, &positions, false)?;
                let again = solve_from(
                    chain,
                    setup,
                    options,
                    &start.scaling,
                    moved.positions,
                    None,
                    true,
                    check,
                )?;
                iterations += again.iterations;
                statistics.add(&again.statistics);
                Ok(again)
            },
        )?;
    }
    let judged = if judge {
        once.judged(&structure, &start.scaling)
    } else {
        None
    };
    Ok(solved(chain, setup, &start, once, iterations, statistics, judged))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_piecewise_linear_and_constant_beyond_the_ends() {
        let (xp, fp) = ([0.0, 1.0, 1.0, 3.0], [0.0, 2.0, 5.0, 9.0]);
        let y = interpolate(&[-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 4.0], &xp, &fp);
        assert_eq!(y, vec![0.0, 0.0, 1.0, 5.0, 7.0, 9.0, 9.0]);
    }

    #[test]
    fn a_coarser_chain_keeps_its_mass_length_and_supports_in_order() {
        let chain = Chain {
            dim: 2,
            masses: vec![1.0; 101],
            lengths: vec![0.01; 100],
            gravity: 1.0,
            supports: vec![0, 50, 100],
            support_positions: vec![0.0, 0.0, 0.4, 0.0, 0.8, 0.0],
            stiffness: Vec::new(),
        };
        let coarse = with_nodes(&chain, 11).unwrap();
        assert_eq!(coarse.supports, vec![0, 5, 10]);
        assert!((coarse.masses.iter().sum::<f64>() - 101.0).abs() < 1e-12);
        assert!((coarse.lengths.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // two supports on one coarse node: no coarse level
        let close = Chain {
            supports: vec![0, 1, 100],
            ..chain
        };
        assert!(with_nodes(&close, 11).is_none());
    }
}
