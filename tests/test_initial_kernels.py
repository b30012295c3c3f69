"""The compiled presolve (``solver.initial_kernels``) against the numpy functions it repeats
(``initial._sag``, ``initial._push_out_of_obstacles``): the same nodes, placed the same way."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from funicular import Problem
from funicular.benchmark import family
from funicular.obstacles import Disk, Ellipse, HalfPlane, Obstacle
from funicular.scenario import builtin_scenarios, load_scenario
from funicular.solver import initial
from funicular.solver.compiled import HAVE_NUMBA, initial_kernels

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")

coordinate = st.floats(-2.0, 2.0)
obstacle = st.one_of(
    st.builds(Disk, st.tuples(coordinate, coordinate), st.floats(0.05, 1.0)),
    st.builds(
        Ellipse, st.tuples(coordinate, coordinate), st.tuples(st.floats(0.05, 1.0), st.floats(0.05, 1.0)), coordinate
    ),
    st.builds(
        HalfPlane,
        st.tuples(coordinate, coordinate),
        st.floats(0.0, 2.0 * math.pi).map(lambda angle: (math.cos(angle), math.sin(angle))),
    ),
)


def _problem(obstacles: list[Obstacle], nodes: int = 5) -> Problem:
    """A stand-in for what the kernels read of a problem: its obstacles' quadratics, link lengths."""
    supports = [(0, (0.0, 0.0)), (-1, (1.0, 0.0))]
    return Problem.build(nodes=nodes, length=1.5, mass=1.0, gravity=1.0, supports=supports, obstacles=obstacles)


def examples(factor: float) -> int:
    """``factor`` times the profile's ``max_examples`` (conftest: default 20, long 250)."""
    return max(3, round(factor * settings().max_examples))


def _assert_same_sag(left: np.ndarray, right: np.ndarray, span: np.ndarray, obstacles: list[Obstacle]) -> None:
    """The kernel's sag is the numpy one's (the bisections end 2^-40 of a depth apart: a slip to
    their other end would show)."""
    quadratic = _problem(obstacles).quadratic_obstacles
    assert quadratic is not None
    total = float(span.sum())
    expected = initial._sag(left, right, span, tuple(obstacles))
    placed = np.empty((span.size - 1, 2))
    initial_kernels().sag(left, right, span, total, quadratic, initial.DEPTH_MARGIN, initial.BISECTIONS, placed)
    np.testing.assert_allclose(placed, expected, rtol=0.0, atol=1e-14 * total)


lengths = st.lists(st.floats(0.01, 1.0), min_size=2, max_size=30)


@settings(max_examples=examples(10), deadline=None)
@given(
    start=st.tuples(st.sampled_from([0.0, 1e6, -3e7]), st.sampled_from([0.0, 1e6])).flatmap(
        lambda far: st.tuples(st.floats(far[0] - 2.0, far[0] + 2.0), st.floats(far[1] - 2.0, far[1] + 2.0))
    ),
    chord=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
    lengths=lengths,
    slack=st.sampled_from([1e-12, 1e-9, 1e-6]) | st.floats(1e-12, 2.0),
    obstacles=st.lists(obstacle, max_size=2),
)
def test_the_compiled_sag_places_the_numpy_nodes(
    start: tuple[float, float],
    chord: tuple[float, float],
    lengths: list[float],
    slack: float,
    obstacles: list[Obstacle],
) -> None:
    """Spans from almost taut to slack, vertical ones among them, near and far from the origin
    (where the sag's depth is bisected against the links' rounding), under any quadratic obstacles."""
    span = np.array(lengths)
    direction = np.array(chord)
    size = float(np.hypot(*direction))
    if size == 0.0:
        direction, size = np.array([0.0, -1.0]), 1.0
    left = np.array(start)
    _assert_same_sag(left, left + direction / size * float(span.sum()) / (1.0 + slack), span, obstacles)


@settings(max_examples=examples(5), deadline=None)
@given(
    lengths=lengths,
    slack=st.floats(0.01, 2.0),
    angle=st.floats(-0.6, 0.6),
    under=st.floats(0.05, 0.95),
    radius=st.floats(0.01, 1.0),
)
def test_the_compiled_sag_clears_a_disk_like_the_numpy_one(
    lengths: list[float], slack: float, angle: float, under: float, radius: float
) -> None:
    """A disk whose top lies between the chord and the lowest node of the sag without it (``under``
    of the way down): where the chord clears it, both sags are made shallower by the obstacle
    bisection."""
    span = np.array(lengths)
    total = float(span.sum())
    left, right = np.zeros(2), total / (1.0 + slack) * np.array([math.cos(angle), math.sin(angle)])
    free = initial._sag(left, right, span, ())
    x, y = free[int(np.argmin(free[:, 1]))]
    chord_y = left[1] + (x - left[0]) * (right[1] - left[1]) / (right[0] - left[0])
    top = chord_y - under * (chord_y - y)
    _assert_same_sag(left, right, span, [Disk((float(x), float(top) - radius * total), radius * total)])


@settings(max_examples=examples(10), deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    nodes=st.integers(3, 40),
    obstacles=st.lists(obstacle, min_size=1, max_size=3),
    settled=st.booleans(),
)
def test_the_compiled_push_out_moves_the_numpy_nodes(
    seed: int, nodes: int, obstacles: list[Obstacle], settled: bool
) -> None:
    """Nodes scattered over the obstacles, some deep inside, some on or near a surface."""
    problem = _problem(obstacles, nodes)
    rng = np.random.default_rng(seed)
    guess = rng.uniform(-2.5, 2.5, size=(nodes, 2))
    movable = np.sort(rng.choice(nodes, size=rng.integers(1, nodes + 1), replace=False))
    numpy_positions, compiled_positions = guess.copy(), guess.copy()
    expected = initial._push_out_of_obstacles(problem, numpy_positions, movable, settled)
    found = initial._push_out_of_obstacles(problem, compiled_positions, movable, settled, compiled=True)
    np.testing.assert_allclose(compiled_positions, numpy_positions, rtol=0.0, atol=1e-14)
    assert (expected is None) == (found is None)
    if expected is not None and found is not None:
        np.testing.assert_allclose(np.array(found), np.array(expected), rtol=0.0, atol=1e-14)


def _presolve_cases() -> dict[str, Problem]:
    cases = {name: load_scenario(name) for name in builtin_scenarios()}
    cases.update({"bench disk 50": family(50, "disk"), "bench free 50": family(50, "free")})
    return cases


@pytest.mark.parametrize("name", sorted(_presolve_cases()))
def test_both_presolves_start_every_built_in_scenario_alike(name: str) -> None:
    """Where the kernels do not cover a scenario (a box, an expression) both runs are numpy's."""
    problem = _presolve_cases()[name]
    expected, found = initial.presolve(problem), initial.presolve(problem, compiled=True)
    np.testing.assert_allclose(found.positions, expected.positions, rtol=0.0, atol=1e-13)
    np.testing.assert_array_equal(found.movable, expected.movable)
    if expected.obstacle_gradients is None or found.obstacle_gradients is None:
        assert expected.obstacle_gradients is found.obstacle_gradients is None
    else:
        np.testing.assert_allclose(
            np.array(found.obstacle_gradients), np.array(expected.obstacle_gradients), rtol=0.0, atol=1e-13
        )
