"""The exact start for chains that touch nothing (``solver.spans``), against the independent
oracle in ``tests/oracles.py`` and against the equations it must satisfy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import oracles
from funicular import Problem, SolverOptions, solve
from funicular._solver.spans import exact_start, hanging_span
from funicular.obstacles import Disk

CASES = {
    "uniform": (np.full(19, 1.0), np.full(20, 0.1), (0.0, 0.0), (1.2, 0.3)),
    "uneven": (np.linspace(0.1, 3.0, 29), np.linspace(0.5, 0.05, 30), (0.0, 0.0), (0.8, -0.4)),
    "some massless": (np.array([1.0, 0.0, 0.0, 2.0, 0.0, 1.0]), np.full(7, 0.2), (0.0, 0.0), (1.0, 0.2)),
    "steep": (np.full(9, 1.0), np.full(10, 0.1), (0.0, 0.0), (0.1, 0.8)),
    "almost taut 1e-9": (np.full(9, 0.1), np.full(10, 0.1), (0.0, 0.0), tuple((1 - 1e-9) * np.array([0.6, 0.8]))),
    "almost taut 1e-12": (np.full(99, 1.0), np.full(100, 1.0), (0.0, 0.0), (100.0 * (1 - 1e-12), 0.0)),
    "slack": (np.full(49, 1.0), np.full(50, 1.0), (0.0, 0.0), (5.0, 1.0)),
}


@pytest.mark.parametrize("case", CASES)
def test_a_span_equals_the_oracles_discrete_catenary(case: str) -> None:
    masses, lengths, left, right = CASES[case]
    g = 9.81
    span = hanging_span(masses, lengths, g, np.array(left), np.array(right))
    assert span is not None
    positions, tension = span
    exact = oracles.discrete_catenary(np.concatenate(([1.0], masses, [1.0])), lengths, g, left, right)
    size = float(lengths.sum())
    np.testing.assert_allclose(positions, exact.positions[1:-1], rtol=0, atol=1e-9 * size)
    # The tensions of a span with slack s are determined to about eps / s only (H ~ 1 / sqrt(s)):
    # 1e-9 of slack leaves them 7 digits.
    slack = 1.0 - math.hypot(right[0] - left[0], right[1] - left[1]) / size
    np.testing.assert_allclose(tension, exact.tension, rtol=max(1e-9, 1e-14 / slack))


def test_a_span_going_left_is_the_mirror_image() -> None:
    masses, lengths, _, (x, y) = CASES["uneven"]
    span = hanging_span(masses, lengths, 1.0, np.zeros(2), np.array([-x, y]))
    assert span is not None
    exact = oracles.discrete_catenary(np.concatenate(([1.0], masses, [1.0])), lengths, 1.0, (0.0, 0.0), (x, y))
    np.testing.assert_allclose(span[0], exact.positions[1:-1] * [-1.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(span[1], exact.tension, rtol=1e-9)


@pytest.mark.parametrize(
    ("masses", "right"),
    [
        (np.zeros(9), (1.0, 0.0)),  # no weight between the supports: links may hang slack
        (np.ones(9), (0.0, 0.5)),  # vertical chord: the chain folds
        (np.ones(9), (1.0, 0.0)),  # exactly as long as the chord: the presolve's case
    ],
)
def test_a_span_without_a_taut_catenary_is_left_to_the_solver(masses: np.ndarray, right: tuple[float, float]) -> None:
    assert hanging_span(masses, np.full(10, 0.1), 1.0, np.zeros(2), np.array(right)) is None


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(2, 60),
    seed=st.integers(0, 2**32 - 1),
    slack=st.sampled_from([1e-10, 1e-6, 1e-3, 0.05, 0.3, 0.7]),
    angle=st.floats(-1.4, 1.4),
)
def test_a_span_balances_every_node_and_reaches_the_support(n: int, seed: int, slack: float, angle: float) -> None:
    """Whatever the masses, lengths and chord: each link as long as allowed, each interior node in
    balance (its two link forces and its weight), the last link ending on the right support. A
    nearly taut span always has such an equilibrium; a slack one with few nodes may have none (a link
    hangs slack, H = 0), and then the solver takes over."""
    rng = np.random.default_rng(seed)
    masses, lengths = rng.uniform(0.01, 2.0, n - 1), rng.uniform(0.1, 1.0, n)
    distance = (1.0 - slack) * float(lengths.sum())
    left, right = np.array([0.3, -0.2]), np.array([0.3 + distance * math.cos(angle), -0.2 + distance * math.sin(angle)])
    g = 2.0
    span = hanging_span(masses, lengths, g, left, right)
    if slack <= 1e-6:
        assert span is not None
    if span is None:
        return
    positions, tension = span
    nodes = np.vstack((left, positions, right))
    delta = np.diff(nodes, axis=0)
    np.testing.assert_allclose(np.hypot(delta[:, 0], delta[:, 1]), lengths, rtol=1e-9)
    pull = tension[:, None] * delta / lengths[:, None]  # link k's force on node k, towards node k+1
    balance = pull[1:] - pull[:-1] - np.column_stack((np.zeros(n - 1), g * masses))
    np.testing.assert_allclose(balance, 0.0, atol=1e-9 * float(tension.max()))


def test_free_ends_hang_straight_down_carrying_the_weight_below() -> None:
    problem = Problem.build(
        nodes=7, link_lengths=[1.0, 2.0, 1.0, 1.0, 1.0, 3.0], masses=[1, 2, 3, 4, 5, 6, 7], gravity=2.0,
        supports=[(2, (0.0, 0.0)), (4, (1.5, 0.0))],
    )  # fmt: skip
    start = exact_start(problem)
    assert start is not None
    positions, tension = start
    np.testing.assert_allclose(positions[:2], [[0.0, -3.0], [0.0, -2.0]])
    np.testing.assert_allclose(positions[5:], [[1.5, -1.0], [1.5, -4.0]])
    np.testing.assert_allclose(tension[:2], [2.0 * 1, 2.0 * (1 + 2)])
    np.testing.assert_allclose(tension[4:], [2.0 * (6 + 7), 2.0 * 7])


def test_an_obstacle_in_the_way_leaves_the_start_to_the_solver() -> None:
    free = Problem.build(nodes=21, length=1.5, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))])
    clear = Problem.build(**_keywords(free), obstacles=[Disk((0.5, -2.0), 0.5)])
    touched = Problem.build(**_keywords(free), obstacles=[Disk((0.5, -0.55), 0.25)])
    assert exact_start(free) is not None and exact_start(clear) is not None
    assert exact_start(touched) is None
    # Clear of the disk, the chain is the free catenary and the polish confirms it in one step.
    solution = solve(clear)
    assert solution.converged and solution.iterations == 1
    np.testing.assert_allclose(solution.obstacle_multipliers, 0.0)


@pytest.mark.parametrize("gravity", [1.0, 1e-120, 1e120])
def test_an_almost_taut_chain_of_100_links_converges_in_one_step(gravity: float) -> None:
    """1e-9 of slack on a slant: tensions about 4,000 times the weight, at any scale of the weight
    (the span is solved in units of its weight: beyond 1e+-100 it used to give up)."""
    end = (1 - 1e-9) * np.array([6.0, 8.0])
    problem = Problem.build(
        nodes=101, length=10.0, mass=1.0, gravity=gravity, supports=[(0, (0.0, 0.0)), (-1, tuple(end))]
    )
    solution = solve(problem)
    assert solution.converged and solution.iterations == 1
    assert solution.link_tension.max() > 1e3 * problem.weight
    total = np.sum(solution.support_reactions, axis=0)
    np.testing.assert_allclose(total, [0.0, problem.weight], atol=1e-9 * float(solution.link_tension.max()))


def _keywords(problem: Problem) -> dict[str, object]:
    return {
        "nodes": problem.n_nodes,
        "link_lengths": problem.link_lengths.tolist(),
        "masses": problem.masses.tolist(),
        "supports": [(int(n), tuple(p)) for n, p in zip(problem.support_nodes, problem.support_positions, strict=True)],
    }


def test_without_the_exact_start_the_interior_point_method_finds_the_same_chain() -> None:
    problem = Problem.build(nodes=41, length=1.5, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.2))])
    exact = solve(problem)
    general = solve(problem, SolverOptions(exact_start=False))
    assert exact.iterations == 1 and general.iterations > 3
    np.testing.assert_allclose(general.positions, exact.positions, atol=1e-9)
    np.testing.assert_allclose(general.link_tension, exact.link_tension, rtol=1e-8)


def test_a_span_through_an_obstacle_gives_up_before_newton() -> None:
    lengths, masses = np.full(1000, 1.5e-3), np.full(999, 1e-3)
    through = hanging_span(masses, lengths, 1.0, np.zeros(2), np.array([1.0, 0.0]), (Disk((0.5, -0.55), 0.25),))
    assert through is None
    clear = hanging_span(masses, lengths, 1.0, np.zeros(2), np.array([1.0, 0.0]), (Disk((0.5, -2.0), 0.25),))
    assert clear is not None
    # The same span walked from right to left: the starting rope is mirrored with it.
    leftward = hanging_span(masses, lengths, 1.0, np.zeros(2), np.array([-1.0, 0.0]), (Disk((-0.5, -0.55), 0.25),))
    assert leftward is None


def test_with_link_contact_the_links_must_clear_the_obstacles_too() -> None:
    """Three links of 1 between supports 2 apart, weights on the two middle nodes: the middle link
    hangs level at y = -sqrt(3)/2. A small disk on that link's midpoint is clear of every node (node
    contact: the exact start applies, and it is the answer) but cut by the link (link contact: the
    solver works, and lifts the link onto the disk). A disk far away is clear of both."""
    supports = [(0, (0.0, 0.0)), (3, (2.0, 0.0))]
    keywords = {"nodes": 4, "link_lengths": 1.0, "masses": [0.0, 1.0, 1.0, 0.0], "supports": supports}
    on_the_link = Disk((1.0, -math.sqrt(0.75)), 0.05)
    nodes = Problem.build(**keywords, obstacles=[on_the_link])  # type: ignore[arg-type]
    links = Problem.build(**keywords, obstacles=[on_the_link], contact="links")  # type: ignore[arg-type]
    far = Problem.build(**keywords, obstacles=[Disk((1.0, -3.0), 0.5)], contact="links")  # type: ignore[arg-type]
    start = exact_start(nodes)
    assert start is not None
    np.testing.assert_allclose(start[0][1:3], [[0.5, -math.sqrt(0.75)], [1.5, -math.sqrt(0.75)]])
    assert exact_start(far) is not None
    solution = solve(links)  # (not from the exact start: the polish alone would confirm it in 1 step)
    assert solution.converged and solution.iterations > 1
    assert solution.positions[1, 1] > -math.sqrt(0.75)  # held up by the disk
    assert solve(far).iterations == 1
