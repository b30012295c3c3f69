"""Degenerate but valid input (robustness), and the minimal reproducers the property tests found.

Each case either converges to scaled KKT residuals <= 1e-8 (checked independently by
``check_equilibrium``: force balance at every free node from positions, tensions and contact
forces) or raises a FunicularError whose message is one clear sentence. tests/test_solver.py
already covers: a single free node between two supports, supports on every node (3 nodes),
a taut vertical chain, both ends at one point, and unit changes of 1e-6 and 1e6 without
obstacles; the cases here extend those.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import oracles
from funicular import FunicularError, InfeasibleError, Problem, Solution, Status, solve
from funicular._constraints import link_distances
from funicular.obstacles import Disk, HalfPlane, Obstacle

try:
    from test_properties import check_equilibrium
except ImportError:  # pragma: no cover - when tests/ is imported as a package
    from tests.test_properties import check_equilibrium


def solved(problem: Problem, **kwargs: object) -> Solution:
    """Solve with every numpy warning turned into an error (a warning escaping the solver is a bug:
    the CLI would print it), and check the result is a KKT point."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solution = solve(problem, **kwargs)  # type: ignore[arg-type]
    check_equilibrium(solution)
    return solution


def chain(
    link_lengths: list[float],
    masses: float | list[float],
    supports: list[tuple[int, tuple[float, float]]],
    formulation: str = "norm",
    obstacles: tuple[Obstacle, ...] = (),
    gravity: float = 1.0,
) -> Problem:
    return Problem.build(
        nodes=len(link_lengths) + 1,
        link_lengths=link_lengths,
        masses=masses,
        gravity=gravity,
        formulation=formulation,
        supports=supports,
        obstacles=obstacles,
    )


FORMULATIONS = pytest.mark.parametrize("formulation", ["norm", "squared"])


# ----------------------------------------------------------------- zero masses
@FORMULATIONS
def test_only_one_node_has_mass(formulation: str) -> None:
    """Massless nodes either side of one heavy node: two straight taut segments meeting at it (a V)."""
    problem = chain([1.0] * 6, [0, 0, 0, 2.0, 0, 0, 0], [(0, (0.0, 0.0)), (6, (4.0, 0.0))], formulation)
    solution = solved(problem)
    depth = math.sqrt(3.0**2 - 2.0**2)
    np.testing.assert_allclose(solution.positions[3], [2.0, -depth], atol=1e-9)
    np.testing.assert_allclose(solution.link_tension, 2.0 / 2 * 3.0 / depth, rtol=1e-8)  # T = (W/2) / sin(angle)


@FORMULATIONS
def test_alternating_zero_masses(formulation: str) -> None:
    problem = chain([0.5] * 10, [1.0, 0.0] * 5 + [1.0], [(0, (0.0, 0.0)), (10, (3.0, 1.0))], formulation)
    solved(problem)


@FORMULATIONS
def test_massless_free_end_hanging_from_a_single_support(formulation: str) -> None:
    """The massless end may sit anywhere within reach; any such point is an equilibrium."""
    problem = chain([1.0, 1.0], [1.0, 1.0, 0.0], [(0, (0.0, 0.0))], formulation)
    solution = solved(problem)
    np.testing.assert_allclose(solution.link_tension, [1.0, 0.0], atol=1e-9)


@FORMULATIONS
def test_massless_free_end_next_to_two_supports(formulation: str) -> None:
    """Currently FAILS for the norm formulation (max_iterations after 200 steps, scaled KKT 1.4e-3):
    the massless node 0 is driven onto its neighbour, the support at node 1 (d_0 = 1.6e-11 l), where
    the norm constraint is not differentiable, and the iteration never recovers. Without a load the
    barrier's analytic centre of {|p_0 - p_1| <= l_0} is p_0 = p_1 itself. Exact answer: node 2 at
    (0.5, -sqrt(0.75)), tensions (0, 1/sqrt(3), 1/sqrt(3))."""
    problem = chain([1.0, 1.0, 1.0], [0.0, 1.0, 1.0, 1.0], [(1, (0.0, 0.0)), (3, (1.0, 0.0))], formulation)
    solution = solved(problem)
    np.testing.assert_allclose(solution.positions[2], [0.5, -math.sqrt(0.75)], atol=1e-9)
    np.testing.assert_allclose(solution.link_tension, [0.0, 1 / math.sqrt(3), 1 / math.sqrt(3)], atol=1e-9)


# ----------------------------------------------------------------- slack links next to massless nodes
# A slack link carries no force, so the barrier's pull (towards d = 0, where the norm has its kink)
# is all it feels; before the smooth stand-in (constraints.SMOOTH_RATIO) such a link collapsed onto
# the kink and the norm solves below stalled (random-chains property test, 4-5 of 120 examples).
GROUND = HalfPlane(point=(0.0, -9.0), normal=(0.0, 1.0))


def test_massless_nodes_between_slack_links_100_apart_above_the_ground() -> None:
    """Was ``stalled`` (scaled KKT 1.5e-2): nodes 1 and 2 are massless, so links 0-2 are slack and
    nodes 1, 2 may rest anywhere within reach; node 3 hangs 0.1 straight below the support at node 4
    and its link carries its whole weight. Reactions: each support carries its own weight, node 4 also
    node 3's."""
    problem = chain(
        [10.0, 10.0, 10.0, 0.1], [1.0, 0.0, 0.0, 1.0, 1.0], [(0, (0.0, 0.0)), (4, (1.0, 0.0))], obstacles=(GROUND,)
    )
    solution = solved(problem)
    assert solution.iterations <= 30
    np.testing.assert_allclose(solution.positions[3], [1.0, -0.1], atol=1e-9)
    np.testing.assert_allclose(solution.link_tension, [0.0, 0.0, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(solution.support_reactions, [[0.0, 1.0], [0.0, 2.0]], atol=1e-9)


def test_massless_nodes_between_slack_links_with_a_disk_and_the_ground() -> None:
    """Was ``stalled`` at a scaled KKT error of 6e-2 (the massless node 2 collapsed onto node 1,
    0.1 away). Same answer as without obstacles: only the last link, holding node 4, is taut."""
    problem = chain(
        [10.0, 0.1, 10.0, 10.0, 0.1],
        [1.0, 0.0, 0.0, 0.0, 1.0, 1.0],
        [(0, (0.0, 0.0)), (5, (1.0, 0.0))],
        obstacles=(Disk((0.5, -12.0), 2.0), GROUND),
    )
    solution = solved(problem)
    np.testing.assert_allclose(solution.positions[4], [1.0, -0.1], atol=1e-9)
    np.testing.assert_allclose(solution.link_tension, [0.0, 0.0, 0.0, 0.0, 1.0], atol=1e-9)


def test_random_chain_whose_massless_node_collapsed_onto_its_heavy_neighbour() -> None:
    """The smallest of the property test's failing examples (was ``max_iterations``, scaled KKT 4.8e-2):
    the massless node 3 between two slack links of 10 landed on node 4 (d = 7e-7 of a link)."""
    problem = Problem.build(
        nodes=25,
        link_lengths=[
            10.0,
            10.0,
            10.0,
            10.0,
            0.1,
            10.0,
            0.1,
            10.0,
            0.1,
            0.1,
            10.0,
            10.0,
            10.0,
            10.0,
            10.0,
            10.0,
            0.1,
            10.0,
            10.0,
            0.1,
            0.1,
            0.1,
            0.1,
            10.0,
        ],
        masses=[0.1, 0.1, 0, 0, 0.1, 0, 0.1, 0, 0, 0, 0, 0.1, 0, 0, 0, 0.1, 0.1, 0, 0, 0, 0.1, 0.1, 0.1, 0, 0.1],
        gravity=9.81,
        supports=[
            (1, (-3.2836505635879583, -8.992732366489916)),
            (2, (-3.2836505635879583, -8.992732366489916)),
            (5, (-3.031082958858369, -7.099707528412005)),
            (8, (6.96891704114163, -8.669229878995317)),
        ],
        obstacles=[
            Disk(center=(84.9178884462887, -119.3865410349805), radius=55.92836207550819),
            Disk(center=(17.385312068373445, -69.08981984841965), radius=22.518468286699868),
            HalfPlane(point=(-15.202523513810071, 0.0), normal=(1.0, 0.0)),
        ],
    )
    solved(problem)


def test_the_smooth_stand_in_meets_the_norm_and_reports_the_same_force() -> None:
    """Below r = SMOOTH_RATIO l the solver's link constraint is a parabola with the norm's value and
    slope at r (finite differences check its gradient and Hessian); as a norm-form tension its
    multiplier applies the same force ``mu q``. Checked on the solver core's own evaluation of a
    link from a support at the origin to one free node."""
    from funicular import _core

    length, mu = 2.0, np.array([0.7])
    r = _core.SMOOTH_RATIO * length

    def network(node: np.ndarray) -> _core.Network:
        positions = np.array([[0.0, 0.0], node])
        one = np.array([1], dtype=np.int64)
        link = np.array([[0, 1]], dtype=np.int64)
        return _core.Network(
            dim=2,
            squared=False,
            positions=positions.ravel(),
            free=one,
            links=link,
            lengths=np.array([length]),
            load=np.zeros(2),
            origin=np.zeros(2),
            quadratics=None,
        )

    def evaluated(node: np.ndarray) -> tuple[float, np.ndarray]:
        evaluated = network(node).evaluate(z=node, mu=mu)
        c, dual = evaluated.c, evaluated.dual
        return float(c[0]), -dual / mu[0]  # (the link's gradient q w.r.t. the support's end: the node feels -mu q)

    for d in (0.0, 0.3 * r, r, 1.5 * r):
        node = np.array([0.6 * d, -0.8 * d])
        value, q = evaluated(node)
        if d >= r:
            assert value == pytest.approx(d - length, rel=1e-15)
            np.testing.assert_allclose(q, -node / d, rtol=1e-15)
        else:
            assert value > d - length
        hessian = network(node).newton_matrix(z=node, mu=mu, sigma=np.zeros(1)).reshape(2, 2) / mu[0]
        for axis in range(2):
            h = np.zeros(2)
            h[axis] = 1e-7
            (plus, q_plus), (minus, q_minus) = evaluated(node + h), evaluated(node - h)
            assert (plus - minus) / 2e-7 == pytest.approx(-q[axis], abs=1e-7)  # d c / d p_node = -q
            if d != r:  # the curvature jumps at r (radially, from 1/r to 0)
                np.testing.assert_allclose(-(q_plus - q_minus) / 2e-7, hessian[axis], atol=1e-6)
        tension = mu[0] * d / max(d, r)  # the norm form's tension the core reports for it
        unit = -node / d if d > 0 else np.zeros(2)
        np.testing.assert_allclose(tension * unit, mu[0] * q, atol=1e-15)


def test_a_detached_massless_end_does_not_upset_the_licq_check() -> None:
    """The check describes the dependent taut links (LICQ fails: two supports 2 l apart vertically)
    with unit vectors along every link, including the zero-length one of the massless end resting on
    the support at node 2 (was: a divide-by-zero RuntimeWarning, an error under pytest)."""
    from funicular.checks import check_solution

    problem = chain([1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 0.0], [(0, (0.0, 0.0)), (2, (0.0, -2.0))])
    solution = solved(problem)
    np.testing.assert_array_equal(solution.positions[3], [0.0, -2.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = check_solution(solution)
    assert report.licq is not None and not report.licq.holds
    (dependency,) = report.licq.dependencies
    assert dependency.support_reactions.keys() == {0, 2}


# ----------------------------------------------------------------- taut vertical segments
@FORMULATIONS
def test_taut_vertical_segment_with_a_free_end_below(formulation: str) -> None:
    problem = chain([0.1] * 7, 1.0, [(0, (0.0, 0.0)), (4, (0.0, -0.4))], formulation)
    solution = solved(problem)
    np.testing.assert_allclose(solution.x, 0.0, atol=1e-12)
    np.testing.assert_allclose(solution.y[5:], [-0.5, -0.6, -0.7], atol=1e-9)


@FORMULATIONS
def test_taut_vertical_segment_going_up(formulation: str) -> None:
    """The second support above the first: the segment hangs from the upper one."""
    problem = chain([0.1] * 4, 1.0, [(0, (0.0, 0.0)), (4, (0.0, 0.4))], formulation)
    solution = solved(problem)
    np.testing.assert_allclose(solution.support_reactions.sum(axis=0), [0.0, problem.weight], atol=1e-12)


def test_taut_vertical_segment_with_massless_interior() -> None:
    problem = chain([0.1] * 4, [1.0, 0.0, 0.0, 0.0, 1.0], [(0, (0.0, 0.0)), (4, (0.0, -0.4))])
    solution = solved(problem)
    np.testing.assert_allclose(solution.link_tension, 0.0, atol=1e-12)


def test_taut_slanted_segment_with_massless_interior_is_fine() -> None:
    """Straight and slanted is only impossible with a load on the interior nodes."""
    problem = chain([0.1] * 4, [1.0, 0.0, 0.0, 0.0, 1.0], [(0, (0.0, 0.0)), (4, (0.24, 0.32))])
    solved(problem)


def test_almost_taut_vertical_segment() -> None:
    """One part in 1e9 of slack: outside the presolve's exactly-taut tolerance, so the solver works."""
    problem = chain([0.1] * 10, 0.1, [(0, (0.0, 0.0)), (10, (0.0, -(1 - 1e-9)))])
    solved(problem)


def test_almost_taut_slanted_segment() -> None:
    """One part in 1e9 of slack on a slant: a valid problem whose tensions are ~1e4 times the weight.
    The interior-point method from the sagging guess stopped at 200 steps (scaled KKT 3.8e-4); the
    exact start (solver.spans) is confirmed by one polish step."""
    end = (1 - 1e-9) * np.array([0.6, 0.8])
    problem = chain([0.1] * 10, 0.1, [(0, (0.0, 0.0)), (10, (float(end[0]), float(end[1])))], gravity=9.81)
    solved(problem)


def test_exactly_taut_slanted_segment_is_refused_in_one_sentence() -> None:
    problem = chain([0.1] * 10, 0.1, [(0, (0.0, 0.0)), (10, (1.0 - 1e-12, 0.0))])
    with pytest.raises(
        InfeasibleError, match=r"^the chain between the supports at nodes 0 and 10 is exactly taut"
    ) as info:
        solve(problem)
    assert "\n" not in str(info.value)


# ----------------------------------------------------------------- supports everywhere, coincident supports
@FORMULATIONS
def test_supports_on_every_node_with_an_obstacle(formulation: str) -> None:
    """No free node: nothing to solve; each support carries its own node's weight, links carry nothing."""
    problem = chain(
        [1.0] * 3,
        [1.0, 2.0, 3.0, 4.0],
        [(i, (0.5 * i, 0.0)) for i in range(4)],
        formulation,
        obstacles=(Disk((0.75, -1.0), 1.0),),  # just below the supports at nodes 1 and 2
    )
    solution = solved(problem)
    assert solution.iterations == 0
    np.testing.assert_allclose(solution.link_tension, 0.0)
    np.testing.assert_allclose(solution.support_reactions, [[0.0, m] for m in (1.0, 2.0, 3.0, 4.0)], atol=1e-15)


@FORMULATIONS
def test_two_nodes_both_supported_at_one_point(formulation: str) -> None:
    """A link of length zero between two supports: its direction is undefined, and must not make NaNs."""
    problem = chain([1.0], 1.0, [(0, (2.0, 3.0)), (1, (2.0, 3.0))], formulation)
    solution = solved(problem)
    assert np.all(np.isfinite(solution.support_reactions))
    np.testing.assert_allclose(solution.support_reactions, [[0.0, 1.0], [0.0, 1.0]])


@FORMULATIONS
def test_adjacent_supports_at_one_point_with_a_free_span(formulation: str) -> None:
    problem = chain([1.0] * 4, 1.0, [(0, (0.0, 0.0)), (1, (0.0, 0.0)), (4, (2.0, 0.0))], formulation)
    solution = solved(problem)
    assert np.all(np.isfinite(solution.to_dict()["link_tension"]))


def test_coincident_supports_in_the_middle_of_a_chain() -> None:
    """Nodes 2 and 6 held at one point, the loop between them folds (README: a known limitation, the
    solver may stall there); the rest of the chain is ordinary. It must converge or say it did not."""
    problem = chain([0.25] * 10, 1.0, [(0, (-0.4, 0.0)), (2, (0.0, 0.0)), (6, (0.0, 0.0)), (10, (0.8, 0.0))])
    solution = solve(problem)
    if solution.converged:
        check_equilibrium(solution)
    else:
        assert solution.kkt_scaled.max() > 1e-10


# ----------------------------------------------------------------- a single free node
@FORMULATIONS
@pytest.mark.parametrize("mass", [1.0, 0.0])
def test_a_single_free_node_hanging(formulation: str, mass: float) -> None:
    problem = chain([2.0], [3.0, mass], [(0, (1.0, 1.0))], formulation)
    solution = solved(problem)
    if mass:
        np.testing.assert_allclose(solution.positions[1], [1.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(solution.link_tension, [mass], atol=1e-9)
    np.testing.assert_allclose(solution.support_reactions, [[0.0, 3.0 + mass]], atol=1e-9)


def test_a_single_free_node_at_the_end_of_a_supported_chain() -> None:
    problem = chain([1.0] * 4, 1.0, [(i, (float(i), 0.0)) for i in range(4)])
    solution = solved(problem)
    np.testing.assert_allclose(solution.positions[4], [3.0, -1.0], atol=1e-9)


# ----------------------------------------------------------------- link lengths far apart
@FORMULATIONS
def test_dangling_chain_with_lengths_1e4_apart(formulation: str) -> None:
    """Three nodes, links (0.01, 100), one support: both links hang straight down, tensions 2 and 1.
    Each link's barrier term is weighted by its length, so the short link's slack is not held to its
    own size (it used to take 977 Newton steps in the squared form and 41 in the norm form; now 5-7)."""
    problem = chain([1e-2, 1e2], 1.0, [(0, (0.0, 0.0))], formulation)
    solution = solved(problem)
    assert solution.iterations <= 20
    np.testing.assert_allclose(solution.y, [0.0, -1e-2, -1e-2 - 1e2], rtol=1e-9)
    np.testing.assert_allclose(solution.link_tension, [2.0, 1.0], rtol=1e-8)


@FORMULATIONS
def test_two_supports_with_lengths_1e4_apart(formulation: str) -> None:
    """Links 1e-2, 1e2, 1e-2 between supports 50 apart: the short links hang straight down, the long one
    is slack, and each support carries its own node and its neighbour (it used to fail in the squared
    form, max_iterations, and take 79 steps in the norm form; now 8)."""
    problem = chain([1e-2, 1e2, 1e-2], 1.0, [(0, (0.0, 0.0)), (3, (50.0, 0.0))], formulation)
    solution = solved(problem)
    assert solution.iterations <= 20
    np.testing.assert_allclose(solution.support_reactions, [[0.0, 2.0], [0.0, 2.0]], atol=1e-8)


def test_dangling_chain_with_a_short_last_link() -> None:
    """Links (100, 100, 100, 1), unit masses, one support: every link hangs straight down and taut.
    The short link must not collapse (its last node onto its neighbour, where the norm is not
    differentiable): an unweighted barrier pulls a link with a force tau / slack, which exceeds the
    short link's tension while its whole slack is 1 % of the others'. It used to stall there for any
    ratio above about 50 (max_iterations, d_3 = 8e-4 l_3); with the barrier weighted by link length it
    converges in 5 steps."""
    problem = chain([100.0, 100.0, 100.0, 1.0], 1.0, [(0, (0.0, 0.0))])
    solution = solved(problem)
    assert solution.iterations <= 20
    np.testing.assert_allclose(solution.y, [0.0, -100.0, -200.0, -300.0, -301.0], atol=1e-7)
    np.testing.assert_allclose(solution.link_tension, [4.0, 3.0, 2.0, 1.0], atol=1e-8)


def test_two_supports_with_a_short_first_link() -> None:
    """Links (1, 100, 1, 1), unit masses, supports (0, 0) and (70, 0): node 1 must not collapse onto
    the support at node 0 (it used to, d_0 = 1.8e-12, and stall at scaled KKT 6e-2; the squared form
    took 50 steps). Both forms now converge in 9."""
    for formulation in ("norm", "squared"):
        solution = solved(chain([1.0, 100.0, 1.0, 1.0], 1.0, [(0, (0.0, 0.0)), (4, (70.0, 0.0))], formulation))
        assert solution.iterations <= 20


@FORMULATIONS
@pytest.mark.parametrize(("scale", "offset"), [(1e6, 0.0), (1e-6, 0.0), (1.0, 1e6)])
def test_short_links_at_any_scale_and_offset(formulation: str, scale: float, offset: float) -> None:
    """The barrier weights are link lengths relative to the longest link: scaling the scenario or
    moving it changes neither the Newton steps nor the answer (links (1, 100, 1, 1), supports 70 apart:
    node 1 hangs 1 below node 0, nodes 2 and 3 hang below the other support, the long link is slack)."""

    def problem(s: float, o: float) -> Problem:
        return chain([s, 100.0 * s, s, s], 1.0, [(0, (o, o)), (4, (o + 70.0 * s, o))], formulation)

    reference, moved = solved(problem(1.0, 0.0)), solved(problem(scale, offset))
    assert moved.iterations == reference.iterations
    np.testing.assert_allclose(reference.positions[1:4], [[0.0, -1.0], [70.0, -2.0], [70.0, -1.0]], atol=1e-9)
    np.testing.assert_allclose((moved.positions - offset) / scale, reference.positions, atol=1e-9)
    np.testing.assert_allclose(moved.link_tension, reference.link_tension, atol=1e-9)


def test_squared_dangling_chain_with_lengths_1000_apart() -> None:
    """Links (1, 1000, 1, 1), squared formulation, one support: every link hangs taut, tensions 4..1.
    It used to take 464 Newton steps (the short links' multipliers, T / (2 l), start 1000 times too
    small and their slacks far above the range of d^2 - l^2); now 7 (norm: 5)."""
    problem = chain([1.0, 1000.0, 1.0, 1.0], 1.0, [(0, (0.0, 0.0))], "squared")
    solution = solved(problem)
    assert solution.iterations <= 20
    np.testing.assert_allclose(solution.link_tension, [4.0, 3.0, 2.0, 1.0], atol=1e-8)


def test_squared_short_links_are_not_overstretched_by_the_stopping_test() -> None:
    """Found by the long hypothesis profile: links of 1 and 100, squared formulation, the ground and
    a wall. The solver stopped with scaled residuals of 3e-12 while link 6 (length 1) was 1.5e-8 of
    its length too long: the squared form's violation d^2 - l^2 = (d + l)(d - l), scaled by the
    longest link squared, let a link 100 times shorter than the longest stretch 5000 tol of its
    length. The violation is now measured as the length d - l in either formulation."""
    problem = Problem.build(
        nodes=11,
        link_lengths=[1.0, 100.0, 100.0, 1.0, 1.0, 100.0, 1.0, 100.0, 1.0, 100.0],
        masses=[0.0516466, 0.0, 0.0, 9.9997697, 0.0, 0.0300162, 0.0605138, 0.0, 2.5925551, 0.4767908, 0.1],
        gravity=1.0,
        formulation="squared",
        supports=[
            (1, (9.906470165551642, -0.99999)),
            (4, (82.67442620010405, -101.71499622013049)),
            (5, (82.67442620010405, -101.71499622013049)),
        ],
        obstacles=[
            HalfPlane(point=(0.0, -131.39906435299275), normal=(0.0, 1.0)),
            HalfPlane(point=(-142.59352983444833, 0.0), normal=(1.0, 0.0)),
        ],
    )
    solution = solved(problem)
    d = np.hypot(*np.diff(solution.positions, axis=0).T)
    # What the stopping test guarantees: no link longer than its length by more than tol (1e-10)
    # times the longest link (was: 1.5e-8, one and a half times that, on a link of length 1).
    assert np.all(d <= problem.link_lengths + 1e-10 * 100.0)
    # The reported violation is that length, in units of the longest link.
    stretch = float(np.max(d - problem.link_lengths)) / 100.0
    assert solution.kkt_scaled.primal_feasibility == pytest.approx(max(stretch, 0.0), abs=1e-15)


# ----------------------------------------------------------------- coordinates of size 1e6 and 1e-6
OBSTACLES_AT_SCALE = [
    pytest.param(1.0, 1e6, "disk", id="unit chain at 1e6, disk"),
    pytest.param(1.0, 1e6, "ground", id="unit chain at 1e6, ground"),
    pytest.param(1e-6, 0.0, "disk", id="chain of 1e-6, disk"),
    pytest.param(1e-6, 0.0, "ground", id="chain of 1e-6, ground"),
    pytest.param(1e6, 0.0, "disk", id="chain of 1e6, disk"),
    pytest.param(1e6, -1e6, "ground", id="chain of 1e6 at -1e6, ground"),
]


@pytest.mark.parametrize(("scale", "offset", "shape"), OBSTACLES_AT_SCALE)
def test_obstacles_at_any_scale_and_offset(scale: float, offset: float, shape: str) -> None:
    """The disk-drape and ground scenarios, scaled by s and moved by an offset: the same forces."""

    def problem(s: float, o: float) -> Problem:
        obstacle: Obstacle
        if shape == "disk":
            obstacle = Disk((o + 0.5 * s, o - 0.55 * s), 0.25 * s)
            span, length, height = 1.0, 1.5, 0.0
        else:
            obstacle = HalfPlane((o, o), (0.0, 1.0))
            span, length, height = 2.0, 3.5, 1.0
        return Problem.build(
            nodes=41,
            length=length * s,
            mass=1.0,
            gravity=1.0,
            supports=[(0, (o, o + height * s)), (-1, (o + span * s, o + height * s))],
            obstacles=[obstacle],
        )

    reference, moved = solved(problem(1.0, 0.0)), solved(problem(scale, offset))
    np.testing.assert_allclose((moved.positions - offset) / scale, reference.positions, atol=1e-7)
    np.testing.assert_allclose(moved.link_tension, reference.link_tension, atol=1e-7)
    np.testing.assert_allclose(moved.contact_forces, reference.contact_forces, atol=1e-7)


# ----------------------------------------------------------------- obstacles: hard starts
@pytest.mark.parametrize("x", [0.0, 1e-3], ids=["on top", "1e-3 off the top"])
def test_chain_hanging_from_the_top_of_a_disk(x: float) -> None:
    """A chain (11 nodes, links 0.2) hanging from a support on top of a unit disk must slide down one
    side of it. Hanging straight down is a symmetric saddle inside the disk; it used to overflow
    (x = 0) or stall (x = 1e-3). The free end now starts in a direction that clears the disk."""
    problem = chain([0.2] * 10, 1.0, [(0, (x, 1.0))], obstacles=(Disk((0.0, 0.0), 1.0),))
    solved(problem)


def test_translation_does_not_change_whether_a_solve_converges() -> None:
    """A 48-node chain hung from node 31 over a large disk. It used to converge or stall depending on
    a translation by (123.4, -56.7): the free ends hung straight down into the disk and were pushed
    out through its far side. They now hang in a direction that clears the disk."""

    def problem(dx: float, dy: float) -> Problem:
        return Problem.build(
            nodes=48,
            link_length=8.93886684664323,
            masses=1.0,
            gravity=1.0,
            supports=[(31, (35.67570437723743 + dx, -31.907517549398463 + dy))],
            obstacles=[Disk(center=(12.120701484304481 + dx, -193.7294610113652 + dy), radius=153.196435715342)],
        )

    reference = solved(problem(0.0, 0.0))
    moved = solved(problem(123.4, -56.7))
    np.testing.assert_allclose(moved.positions - [123.4, -56.7], reference.positions, atol=1e-7)


# ----------------------------------------------------------------- refusals are one sentence
@pytest.mark.parametrize(
    "make",
    [
        lambda: chain([1.0], 1.0, [(0, (0.0, 0.0)), (1, (1.5, 0.0))]),
        lambda: chain([1.0] * 3, 1.0, [(0, (0.0, 0.0))], obstacles=(Disk((0.0, 0.0), 0.5),)),
        lambda: chain([0.1] * 4, 1.0, [(0, (0.0, 0.0)), (4, (0.4, 0.0))]),
    ],
    ids=["too far apart", "support inside a disk", "taut and slanted"],
)
def test_refusals_are_one_clear_sentence(make: object) -> None:
    with pytest.raises(FunicularError) as info:
        solve(make())  # type: ignore[operator]
    message = str(info.value)
    assert "\n" not in message and message.endswith(".") and len(message) < 400, message


@pytest.mark.parametrize("offset", [3.6e-9, 0.0])
def test_a_chain_hanging_above_a_disk_centre_mirrors_with_the_scene(offset: float) -> None:
    """A free end hanging from a support (almost) straight above a disk's centre must start off to one
    side; the mirrored scene must start off to the other side and find the mirrored equilibrium
    (found by the property test: both used to turn the same way)."""

    def problem(sign: float) -> Problem:
        return chain(
            [0.3] * 12,
            1.0,
            [(0, (sign * offset, 0.0))],
            obstacles=(Disk((0.0, -2.0), 1.5),),
        )

    right, left = solved(problem(1.0)), solved(problem(-1.0))
    if offset == 0.0:  # exact symmetry: either side is right, but the ends must not stay on the axis
        assert abs(right.positions[-1, 0]) > 0.5
    else:
        np.testing.assert_allclose(left.positions * [-1.0, 1.0], right.positions, atol=1e-7)
        np.testing.assert_allclose(left.link_tension, right.link_tension, atol=1e-7)


def test_a_free_end_right_above_a_disk_hangs_away_from_the_other_support_in_both_mirror_images() -> None:
    """Found by the long hypothesis profile: node 4 is a support exactly above a disk's centre, so the
    disk's surface favours neither side for the free end (nodes 0-3); the other support (node 5) is to
    the right. The start turns away from it, so the mirrored scene mirrors the equilibrium exactly."""

    def problem(sign: float) -> Problem:
        lengths = [0.1, 0.1, 0.7124749240263761, 0.23184853521559265, 0.2490968750707306, 0.3928, 1.0, 0.95]
        return chain(
            lengths,
            [1.75, 0.0756, 1.0, 1.0, 0.0133, 1.0, 1.0, 0.183, 0.538],
            [(4, (sign * 7.942387469796946, 2.431)), (5, (sign * 7.96729715730402, 2.431))],
            obstacles=(Disk((sign * 7.942387469796946, 1.6205007915776257), 0.1357241354428934),),
            gravity=9.81,
        )

    right, left = solved(problem(1.0)), solved(problem(-1.0))
    np.testing.assert_allclose(left.positions * [-1.0, 1.0], right.positions, atol=1e-9)
    assert right.positions[0, 0] < 7.942387469796946  # the free end went left, away from node 5


# -------------------------------------------- the long property profile's max_iterations examples
def _long_profile_failures(file_name: str = "long_profile_failures.json") -> dict[str, dict[str, object]]:
    shapes = {"Disk": Disk, "HalfPlane": HalfPlane}
    with open(Path(__file__).parent / "data" / file_name) as file:
        raw = json.load(file)
    problems = {}
    for name, kwargs in raw.items():
        obstacles = [shapes[o.pop("shape")](**o) for o in kwargs.pop("obstacles")]
        kwargs["supports"] = [(node, tuple(at)) for node, at in kwargs["supports"]]
        problems[name] = {**kwargs, "obstacles": obstacles}
    return problems


@pytest.mark.parametrize("name", sorted(_long_profile_failures()))
def test_massless_nodes_next_to_disks_and_sloped_half_planes(name: str) -> None:
    """Random chains from the long hypothesis profile that reached ``max_iterations`` (scaled KKT
    1e-5..4e-2): massless nodes between light or slack links next to disks or sloped half-planes.
    The merit's penalty, once raised to 1e10 by one long step at such a node, made the merit
    ||c + s||^2 alone for good, and the line search kept 1e-4 of every step; it now decays.
    ("penalty_reset": a chain the long profile found when the penalty was reset to 1 every step
    instead, links 10 and 0.1, three obstacles.) ``solved`` checks the KKT residuals, every free
    node's force balance, and that no node is inside an obstacle, independently of the solver."""
    problem = Problem.build(**_long_profile_failures()[name])  # type: ignore[arg-type]
    solution = solved(problem)
    assert solution.iterations < 200
    for obstacle in problem.obstacles:
        phi, _, _ = obstacle.evaluate(solution.positions)
        assert np.all(phi <= 1e-9 * float(problem.link_lengths.max()))


@pytest.mark.parametrize("name", sorted(_long_profile_failures("long_profile_open.json")))
def test_hard_long_profile_chains_claim_nothing_false(name: str) -> None:
    """Random chains of the long hypothesis profile that have been hard to solve (README, Known
    limitations): a 12-node chain, half of it massless, on a slope between two disks; a chain whose
    lower end rests against the nearly vertical side of a disk below a link 100 times longer than its
    neighbours; a 6-node chain, four of its nodes supports, two of them 1e-14 apart, between two
    disks; 43 nodes in the squared form, most of them massless, links from 0.1 to 10, three
    supports, two small disks and a vertical half-plane. Whether they converge can depend on
    rounding; what may not happen is a false claim: a solve that says optimal is a KKT point, checked
    independently of the solver (``check_equilibrium``), and one that is not says so in its status."""
    problem = Problem.build(**_long_profile_failures("long_profile_open.json")[name])  # type: ignore[arg-type]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solution = solve(problem)
    if solution.converged:
        check_equilibrium(solution)
    else:
        assert solution.status is not Status.OPTIMAL and solution.iterations > 0


def test_link_distances_match_hypot_at_every_scale() -> None:
    """The square root where its squares are normal numbers, np.hypot elsewhere: equal to hypot to
    rounding for tiny, huge, zero and non-finite links alike."""
    rng = np.random.default_rng(3)
    scales = 10.0 ** rng.uniform(-300, 300, 400)
    steps = rng.normal(size=(400, 2)) * scales[:, None]
    steps[:4] = [[0.0, 0.0], [np.inf, 1.0], [np.nan, 0.0], [1e-320, -1e-320]]
    positions = np.zeros((801, 2))
    positions[1::2] = steps  # every link is one step, out from the origin or back to it
    delta = positions[:-1] - positions[1:]
    with np.errstate(invalid="ignore"):
        expected = np.hypot(delta[:, 0], delta[:, 1])
    np.testing.assert_allclose(link_distances(positions), expected, rtol=4e-16, atol=0)


def test_a_taut_cable_of_10_000_nodes_converges_to_its_rounding_floor() -> None:
    """1e-6 of slack on a slant, 10^4 nodes: the cable pulls with about 120 times its weight, so
    the positions' rounding (eps times 10^5 link lengths) leaves force residuals of about 3e-10 of
    the weight. Against a floor that ignored the force size the polish ran to max_iterations."""
    n, slack = 10_001, 1e-6
    end = (1.0 - slack) * np.array([600.0, 800.0])
    problem = chain([0.1] * (n - 1), 1.0 / n, [(0, (0.0, 0.0)), (n - 1, (float(end[0]), float(end[1])))])
    solution = solved(problem)
    exact = oracles.discrete_catenary(problem.masses, problem.link_lengths, 1.0, (0.0, 0.0), end)
    assert solution.link_tension.max() > 100.0 * problem.weight
    np.testing.assert_allclose(solution.positions, exact.positions, rtol=0, atol=1e-9 * 1000.0)
    np.testing.assert_allclose(solution.link_tension, exact.tension, rtol=1e-7)


# Two random chains from the review's fuzzing (tests/data/far_astray.json) on which the solver does
# not converge (see Known limitations in the README). On the first (far from the origin, links
# hundreds long, g = 658) the line search's merit and the KKT error overflowed with RuntimeWarnings,
# which the command line would have printed; they are now inf, and the status says what happened.
# The second (four supports around a disk) ran its multipliers off to 1e228 without overflowing; it
# now stops as "diverged" and returns its best iterate.
FAR_ASTRAY = json.loads((Path(__file__).parent / "data" / "far_astray.json").read_text())


@pytest.mark.parametrize("case", range(len(FAR_ASTRAY)))
def test_a_solve_gone_far_astray_warns_nothing(case: int) -> None:
    from funicular._text import summary

    keywords = dict(FAR_ASTRAY[case])
    keywords["supports"] = [(node, tuple(position)) for node, position in keywords["supports"]]
    keywords["obstacles"] = [Disk(tuple(o["center"]), o["radius"]) for o in keywords["obstacles"]]
    problem = Problem.build(**keywords)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solution = solve(problem)
        summary(solution)  # the command line's report reads every residual
    assert solution.status.value in {"optimal", "max_iterations", "stalled", "nonfinite", "diverged"}
    assert np.isfinite(solution.positions).all()


def test_a_warm_start_from_a_solution_stays_there() -> None:
    """Found by the mirroring property test: a
    chain hung from one support right above a disk's centre, its last node nearly massless (0.01
    against 1-7) resting on the disk's side. Warm-started from its own solution, the solve ends on
    the disk's other side (equal energy, the scene is symmetric): the interior-point start lifts
    every contact by its initial slack, and so light a node follows the barrier, not its weight.
    Both are equilibria; the warm start must end at one, and at no higher energy than it started
    (README, Known limitations: it may end on the other side)."""
    masses = [1.0, 1.0, 7.073711701469328, 1.0, 0.013497149926042843, 1.198833220368983, 2.899117546948565]
    problem = Problem.build(
        nodes=11,
        link_lengths=[1.0] * 10,
        masses=[*masses, 0.010187116621736879, 1.0, 1.0, 0.010341045509460037],
        gravity=9.81,
        supports=[(4, (0.22051397060126005, 0.3172914740532507))],
        obstacles=[Disk(center=(0.22051397060126005, -5.947073113026372), radius=1.206814626373954)],
    )
    first = solved(problem)
    again = solved(problem, initial_positions=first.positions)
    assert again.objective <= first.objective + 1e-8 * problem.weight * problem.total_length
