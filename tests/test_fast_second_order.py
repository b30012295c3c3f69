"""The cheap sufficient test of a strict local minimum (``checks.proves_strict_minimum``): it may
only say "minimum" where the full second-order check does, and it must say so at the benchmark's
draped minima, where the Hessian of the Lagrangian is indefinite and only the penalty makes the
factorization succeed."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
import scipy.linalg
from bench.run import family
from hypothesis import event, given, note, settings
from hypothesis import strategies as st

from funicular import Problem, Solution, SolverOptions, _core, checks, solve
from funicular.checks._check import _at_solution
from funicular.obstacles import Disk
from funicular.scenario import builtin_scenarios, load_scenario
from test_properties import Chain, chains, examples, solve_or_error

MINIMUM = "strict local minimum"


@functools.cache
def _solved(name: str, nodes: int | None, escape: bool) -> tuple[Problem, Solution]:
    problem = family(nodes or 0, "disk") if name == "family" else load_scenario(name)
    return problem, solve(problem, SolverOptions(escape_saddles=escape))


@pytest.mark.parametrize("name", sorted(builtin_scenarios()))
def test_agrees_with_the_full_check_on_every_builtin(name: str) -> None:
    problem, solution = _solved(name, None, True)
    full = checks.second_order(problem, solution)
    proven = checks.proves_strict_minimum(problem, solution)
    assert proven == (full.verdict == MINIMUM)
    # The explorer's call: the proof first, the full check where it proves nothing.
    first = checks.second_order(problem, solution, proof=True)
    assert first.verdict == full.verdict
    assert math.isnan(first.min_eigenvalue) == proven


@pytest.mark.parametrize("nodes", [50, 51, 200])
def test_benchmark_saddle_is_not_claimed_and_its_minimum_is_proven(nodes: int) -> None:
    # The symmetric start lands on the chain balanced over the disk's top (a saddle); the default
    # solve escapes it to a drape on one side (a strict minimum).
    problem, saddle = _solved("family", nodes, False)
    full = checks.second_order(problem, saddle)
    assert full.verdict == "not a minimum"
    assert not checks.proves_strict_minimum(problem, saddle)
    first = checks.second_order(problem, saddle, proof=True)  # the same verdict and direction
    assert (first.verdict, first.min_eigenvalue) == (full.verdict, full.min_eigenvalue)
    assert first.direction is not None and full.direction is not None
    np.testing.assert_array_equal(first.direction, full.direction)
    problem, minimum = _solved("family", nodes, True)
    assert checks.second_order(problem, minimum).verdict == MINIMUM
    assert checks.proves_strict_minimum(problem, minimum)
    assert checks.second_order(problem, minimum, proof=True).verdict == MINIMUM


@pytest.mark.parametrize(
    ("name", "nodes"), [("family", 50), ("three-supports", None), ("two-pegs", None), ("net-over-sphere", None)]
)
def test_the_penalized_hessian_is_h_plus_a_weighted_gram_matrix(name: str, nodes: int | None) -> None:
    # The block assembly against the dense product, with a support inside the chain (three-supports:
    # links that touch one free node), two obstacles (two-pegs) and a net in space over a sphere
    # (3 x 3 blocks, four links at a node).
    problem, solution = _solved(name, nodes, True)
    at = _at_solution(problem, solution, checks.DEFAULT_TOL)
    assert not isinstance(at, checks.SecondOrder)
    _, hessian, rows, _ = at
    weights = np.random.default_rng(0).uniform(0.0, 10.0, rows.m)
    a = rows.dense()
    expected = hessian.dense() - 0.5 * np.eye(rows.n) + a.T @ np.diag(weights) @ a
    np.testing.assert_allclose(hessian.penalized(rows, weights, 0.5).dense(), expected, atol=1e-12)


# ----------------------------------------------------------------- a pendulum hung from a disk
# Unit disk at the origin, g = 1, unit masses, norm formulation. Node 1 rests on the rim at 45
# degrees, p1 = (c, c) with c = 1/sqrt(2); the support (node 0) sits one link length up the
# tangent t = (-c, c), at (0, 2c); node 2 hangs 2 below node 1, outside the disk. Node 1 carries
# the weight 2 of both nodes: (0, 2) = 2c t + 2c n (n = (c, c) the normal), so the tangent link
# pulls with sqrt(2) and the disk pushes with sqrt(2); link 1-2 carries 1.
#
# Hessian over (node 1, node 2): the tangent link adds sqrt(2) n n^T / 1 at node 1, link 1-2 adds
# (1/2) e_x e_x^T in [[K, -K], [-K, K]], the contact sqrt(2) * (-I / r). Along t at node 1 that is
# 1/4 - sqrt(2) < 0: indefinite. The active rows fix node 1 (t and n) and the height of node 2,
# so null(A) is node 2 moving sideways, a pendulum of curvature 1/2 > 0: a strict minimum.
C = 1.0 / math.sqrt(2.0)


def _pendulum() -> tuple[Problem, Solution]:
    problem = Problem.build(
        nodes=3,
        link_lengths=[1.0, 2.0],
        masses=[1.0, 1.0, 1.0],
        gravity=1.0,
        supports=[(0, (0.0, 2 * C))],
        obstacles=[Disk(center=(0.0, 0.0), radius=1.0)],
    )
    positions = np.array([[0.0, 2 * C], [C, C], [C, C - 2.0]])
    solution = dataclasses.replace(
        solve(problem),
        positions=positions,
        link_multipliers=np.array([math.sqrt(2.0), 1.0]),
        obstacle_multipliers=np.array([0.0, math.sqrt(2.0), 0.0]),
    )
    return problem, solution


def _pendulum_matrices() -> tuple[np.ndarray, np.ndarray]:
    """The Hessian and the strictly active rows of the pendulum, from the formulas above."""
    n, t, e_x = np.array([C, C]), np.array([-C, C]), np.array([1.0, 0.0])
    hessian = np.zeros((4, 4))
    hessian[:2, :2] = math.sqrt(2.0) * np.outer(n, n) - math.sqrt(2.0) * np.eye(2)
    k = 0.5 * np.outer(e_x, e_x)
    hessian[:2, :2] += k
    hessian[2:, 2:] += k
    hessian[:2, 2:] = hessian[2:, :2] = -k
    rows = np.array([[*-t, 0.0, 0.0], [0.0, 1.0, 0.0, -1.0], [*n, 0.0, 0.0]])
    return hessian, rows


def test_pendulum_matrices_are_what_the_check_sees() -> None:
    # The hand-derived numbers: an indefinite Hessian, positive (1/2) on the null space.
    hessian, rows = _pendulum_matrices()
    assert np.linalg.eigvalsh(hessian)[0] < 0
    basis = scipy.linalg.null_space(rows)
    assert np.linalg.eigvalsh(basis.T @ hessian @ basis) == pytest.approx([0.5])
    problem, solution = _pendulum()
    full = checks.second_order(problem, solution)
    assert (full.verdict, full.min_eigenvalue) == (MINIMUM, pytest.approx(0.5))


def _smallest_penalty(hessian: np.ndarray, rows: np.ndarray, shift: float) -> float:
    """The least rho with ``H - shift I + rho A^T A`` positive definite (bisection, to 1 %)."""

    def definite(rho: float) -> bool:
        return bool(np.linalg.eigvalsh(hessian - shift * np.eye(len(hessian)) + rho * rows.T @ rows)[0] > 0)

    low, high = 0.0, 1.0
    while not definite(high):
        low, high = high, 2 * high
    while high - low > 0.01 * high:
        low, high = (low, (low + high) / 2) if definite((low + high) / 2) else ((low + high) / 2, high)
    return high


def test_the_penalty_proves_the_pendulum_where_the_hessian_alone_cannot(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    problem, solution = _pendulum()
    assert checks.proves_strict_minimum(problem, solution)
    hessian, rows = _pendulum_matrices()
    # rho = PENALTY times the larger of the largest entry of H's diagonal blocks and the weight per
    # chain length (here 1/sqrt(2) at node 1 against 3 / 3): far above the least rho that works.
    rho = _core.CURVATURE_PENALTY * max(np.abs(hessian[:2, :2]).max(), np.abs(hessian[2:, 2:]).max(), 3.0 / 3.0)
    assert rho > 10 * _smallest_penalty(hessian, rows, 0.0)
    monkeypatch.setattr(checks._tolerances, "PENALTY", 1e-3)  # too small: the factorization fails, "not proven"
    assert not checks.proves_strict_minimum(problem, solution)


@pytest.mark.parametrize("nodes", [50, 200])
def test_the_penalty_is_well_above_the_least_that_proves_the_draped_minimum(nodes: int) -> None:
    # The benchmark's draped chain needs rho ~ 3 times the largest entry of H's diagonal blocks
    # (computed here densely, from the check's own matrices): the chosen factor leaves a wide margin.
    problem, solution = _solved("family", nodes, True)
    at = _at_solution(problem, solution, checks.DEFAULT_TOL)
    assert not isinstance(at, checks.SecondOrder)
    _, blocks, active, forces = at
    hessian = blocks.dense()
    rows = active.dense()[forces > checks.DEFAULT_TOL * problem.weight]
    assert np.linalg.eigvalsh(hessian)[0] < 0  # indefinite: rho = 0 would not do
    stiffness = max(np.abs(blocks.node).max(), problem.weight / problem.total_length)
    assert _core.CURVATURE_PENALTY * stiffness > 100 * _smallest_penalty(hessian, rows, 0.0)


def test_a_positive_curvature_below_the_threshold_is_not_proven() -> None:
    # One free node of unit mass on top of a disk of radius R = 1 + d, hanging from a support a link
    # length 1 straight above: the link and the contact share its weight (T = F = 1/2; their rows
    # coincide, so any split will do), and sideways the link's pendulum stiffness T / 1 nearly
    # cancels the rim's -F / R: a curvature of d / (2 (1 + d)) = 5e-8 on the null space, below the
    # threshold tol W / (N L) = 1e-6 / 2. The full check calls it zero ("undecided"); without the
    # threshold in its shift the penalized matrix would be positive definite.
    d = 1e-7
    problem = Problem.build(
        nodes=2,
        link_length=1.0,
        masses=[0.0, 1.0],
        gravity=1.0,
        supports=[(0, (0.0, 2.0 + d))],
        obstacles=[Disk(center=(0.0, 0.0), radius=1.0 + d)],
    )
    solution = dataclasses.replace(
        solve(problem),
        positions=np.array([[0.0, 2.0 + d], [0.0, 1.0 + d]]),
        link_multipliers=np.array([0.5]),
        obstacle_multipliers=np.array([0.0, 0.5]),
    )
    full = checks.second_order(problem, solution)
    assert (full.verdict, full.min_eigenvalue) == ("undecided", pytest.approx(d / (2 * (1 + d)), rel=1e-6))
    assert not checks.proves_strict_minimum(problem, solution)


def test_weakly_active_constraints_are_not_taken_for_equalities() -> None:
    # At the draped minimum, one taut link's multiplier set to zero: stretching it costs no
    # curvature, so the strict rows prove nothing (the full check: "undecided"), although the
    # curvature on all active rows is positive.
    problem, solution = _solved("family", 50, True)
    link = solution.link_multipliers.copy()
    link[15] = 0.0
    weak = dataclasses.replace(solution, link_multipliers=link)
    assert checks.second_order(problem, weak).verdict == "undecided"
    assert not checks.proves_strict_minimum(problem, weak)


def test_nothing_is_proven_where_the_full_check_has_nothing_to_check() -> None:
    problem, solution = _pendulum()
    # Negative multipliers (not dual feasible), an infeasible point and contact = "links".
    negative = dataclasses.replace(solution, obstacle_multipliers=np.array([0.0, -1.0, 0.0]))
    inside = dataclasses.replace(solution, positions=solution.positions * [[1.0], [0.5], [1.0]])
    for point in (negative, inside):
        assert checks.second_order(problem, point).verdict == "undecided"
        assert not checks.proves_strict_minimum(problem, point)
    links = dataclasses.replace(problem, contact="links")
    assert not checks.proves_strict_minimum(links, dataclasses.replace(solution, problem=links))


def test_a_chain_of_supports_only_is_a_strict_minimum_both_ways() -> None:
    # No free coordinates: nothing can move (the full check's null space is {0}).
    problem = Problem.build(
        nodes=3,
        link_length=1.0,
        mass=1.0,
        supports=[(0, (0.0, 0.0)), (1, (0.5, 0.0)), (2, (1.0, 0.0))],
        obstacles=[Disk(center=(0.5, -1.0), radius=0.5)],
    )
    solution = solve(problem)
    assert checks.second_order(problem, solution).verdict == MINIMUM
    assert checks.proves_strict_minimum(problem, solution)


# ----------------------------------------------------------------- random chains over disks
@st.composite
def symmetric_drapes(draw: st.DrawFn) -> Problem:
    """The benchmark's shape at random: two supports at the same height, a disk under their
    midpoint, equal masses. The symmetric start lands on the symmetric equilibrium, a saddle when
    the chain sags far enough over the disk, else a minimum."""
    radius = draw(st.floats(0.05, 0.4))
    return Problem.build(
        nodes=draw(st.integers(5, 45)),
        length=1.5,
        mass=1.0,
        gravity=1.0,
        formulation=draw(st.sampled_from(["norm", "squared"])),
        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Disk((0.5, -draw(st.floats(0.15, 0.45)) - radius), radius)],
    )


def _never_a_minimum_where_the_full_check_says_otherwise(problem: Problem, escape: bool) -> None:
    solution = solve_or_error(problem, options=SolverOptions(escape_saddles=escape))
    if solution is None or not solution.converged:
        return
    full = checks.second_order(problem, solution)
    note(f"full check: {full.verdict}, {full.reason}")
    proven = checks.proves_strict_minimum(problem, solution)
    event(f"{full.verdict}, {'proven' if proven else 'not proven'}")
    if proven:
        assert full.verdict == MINIMUM


@settings(max_examples=examples(3))
@given(
    st.one_of(
        chains(max_nodes=40, min_obstacles=1, max_obstacles=2, obstacle_kinds=("disk",)),
        chains(max_nodes=40, min_obstacles=1, obstacle_kinds=("disk",), degenerate=False),
    ),
    st.booleans(),
)
def test_random_chains_are_never_called_a_minimum_where_the_full_check_says_otherwise(
    chain: Chain, escape: bool
) -> None:
    _never_a_minimum_where_the_full_check_says_otherwise(chain.problem, escape)


@settings(max_examples=examples(2))
@given(symmetric_drapes())
def test_symmetric_drapes_are_never_called_a_minimum_where_the_full_check_says_otherwise(problem: Problem) -> None:
    _never_a_minimum_where_the_full_check_says_otherwise(problem, escape=False)
