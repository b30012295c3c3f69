"""What the per-solve overhead's shortcuts rely on: the problem's cached quantities equal a fresh
computation, the exact start's early give-up gives up exactly when the full check does, the
solver's median and the presolve's shortcuts agree with the plain formulas, and solves still end
at balanced equilibria (checked independently of the solver's own multipliers)."""

from __future__ import annotations

import dataclasses
import math
from importlib.util import find_spec

import numpy as np
import pytest
from bench.run import family
from hypothesis import given, settings
from hypothesis import strategies as st

from funicular import Problem, SolverOptions, solve
from funicular.checks import recover_multipliers, second_order
from funicular.obstacles import Box, CallableObstacle, Disk, Ellipse, Expression, Graph, HalfPlane, Obstacle, depth
from funicular.scenario import builtin_scenarios, load_scenario
from funicular.solver import initial, spans
from funicular.solver.initial import BISECTIONS, DEPTH_MARGIN, _massless_ends, _sag, presolve
from funicular.solver.ipm import _obstacle_scale, _scale
from funicular.studies.catenary import ContinuousCatenary

SCENARIOS = sorted(builtin_scenarios())


def _obstacle(kind: str, x: float, y: float, size: float) -> Obstacle:
    if kind == "disk":
        return Disk((x, y), size)
    if kind == "ellipse":
        return Ellipse((x, y), (size, 0.4 * size), 30.0)
    if kind == "halfplane":
        return HalfPlane((x, y), (0.3, 1.0))
    if kind == "graph":  # a bump of height `size` at x on the ground at y
        return Graph(f"{y!r} + {size!r} * exp(-(x - {x!r})**2 / {size!r}**2)")
    if kind == "expression":  # an ellipse written out, and turned
        return Expression(
            f"1 - ((x - {x!r}) + 0.3 * (y - {y!r}))**2 / {size!r}**2 - (y - {y!r})**2 / (0.5 * {size!r})**2"
        )
    return Box((x, y), (size, 0.5 * size), 0.2 * size, 15.0)


KINDS = ["disk", "ellipse", "halfplane", "box"] + (["graph", "expression"] if find_spec("sympy") else [])


# ----------------------------------------------------------------- the problem's caches
@pytest.mark.parametrize("name", SCENARIOS)
def test_cached_quantities_equal_a_fresh_computation(name: str) -> None:
    problem = load_scenario(name)
    n = problem.n_nodes
    assert problem.total_mass == float(np.sum(problem.masses))
    assert problem.total_length == float(np.sum(problem.link_lengths))
    assert problem.weight == problem.gravity * float(np.sum(problem.masses))
    arc = np.concatenate(([0.0], np.cumsum(problem.link_lengths))) / float(np.sum(problem.link_lengths))
    np.testing.assert_array_equal(problem.arc_fractions, arc)
    support = np.isin(np.arange(n), problem.support_nodes)
    np.testing.assert_array_equal(problem.is_support, support)
    np.testing.assert_array_equal(problem.free_nodes, np.flatnonzero(~support))
    assert problem.free_nodes.dtype == np.intp
    assert problem.support_depths.shape == (len(problem.obstacles), problem.support_nodes.size)
    for j, obstacle in enumerate(problem.obstacles):
        np.testing.assert_array_equal(problem.support_depths[j], depth(obstacle, problem.support_positions))
    for array in (problem.arc_fractions, problem.is_support, problem.free_nodes, problem.support_depths):
        assert not array.flags.writeable  # shared by every caller: nobody may change it


def test_a_changed_copy_computes_its_own() -> None:
    problem = family(20, "disk")
    assert problem.total_length == pytest.approx(1.5)
    finer = problem.with_nodes(41)
    assert finer.free_nodes.size == 39 and finer.arc_fractions.size == 41
    assert problem.support_depths[0, 0] < 0.0
    moved = dataclasses.replace(problem, obstacles=(Disk((0.0, -0.1), 0.5),))
    assert moved.support_depths[0, 0] > 0.0  # support 0 inside the moved disk


# ----------------------------------------------------------------- presolve shortcuts
@settings(max_examples=100, deadline=None)
@given(masses=st.lists(st.sampled_from([0.0, 0.0, 1.0, 2.5]), min_size=2, max_size=12), data=st.data())
def test_massless_ends_are_the_nodes_beyond_the_outermost_anchored_ones(
    masses: list[float], data: st.DataObject
) -> None:
    n = len(masses)
    masses[data.draw(st.integers(0, n - 1))] = 1.0  # at least one positive mass
    nodes = sorted(data.draw(st.sets(st.integers(0, n - 1), min_size=1, max_size=n)))
    problem = Problem.build(nodes=n, length=1.0, masses=masses, supports=[(i, (float(i), 0.0)) for i in nodes])
    anchored = [i for i in range(n) if i in nodes or masses[i] > 0]
    first, last = anchored[0], anchored[-1]
    detached, attach = _massless_ends(problem)
    assert detached.tolist() == [*range(first), *range(last + 1, n)]
    assert attach.tolist() == [first] * first + [last] * (n - 1 - last)
    assert detached.dtype == attach.dtype == np.intp


def _plain_sag(start: np.ndarray, end: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The sag without obstacles written with np.vstack and np.diff, as it was."""
    total = lengths.sum()
    t = np.cumsum(lengths)[:-1] / total
    chord = end - start
    distance = float(np.hypot(*chord))
    base = start + t[:, None] * chord
    shape = np.stack((np.zeros_like(t), -4.0 * t * (1.0 - t)), axis=1)
    if abs(chord[0]) <= 1e-3 * total:
        shape[:, 0] = 0.05 * t
    target = 1.0 - 0.05 * (1.0 - distance / total)
    steps = np.diff(np.vstack((start, base, end)), axis=0)
    bends = np.diff(np.vstack(([0.0, 0.0], shape, [0.0, 0.0])), axis=0)
    a = np.einsum("ij,ij->i", bends, bends)
    b = 2.0 * np.einsum("ij,ij->i", steps, bends)
    c = np.minimum(np.einsum("ij,ij->i", steps, steps) - (target * lengths) ** 2, 0.0)
    bending = a > 0.0
    roots = (-b[bending] + np.sqrt(b[bending] ** 2 - 4.0 * a[bending] * c[bending])) / (2.0 * a[bending])
    depth = min(float(np.min(roots, initial=total)), total) * (1.0 - DEPTH_MARGIN)

    def within_target(h: float) -> bool:
        nodes = np.vstack((start, base + h * shape, end))
        return bool(np.max(np.hypot(*np.diff(nodes, axis=0).T) / lengths) <= target)

    if not within_target(depth):
        low, high = 0.0, depth
        for _ in range(BISECTIONS):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if within_target(mid) else (low, mid)
        depth = low
    result: np.ndarray = base + depth * shape
    return result


@settings(max_examples=100, deadline=None)
@given(
    n=st.integers(2, 40),
    seed=st.integers(0, 2**32 - 1),
    slack=st.sampled_from([0.0, 1e-9, 1e-4, 0.1, 0.6]),
    angle=st.floats(-math.pi, math.pi),
    offset=st.sampled_from([0.0, 1e6]),
)
def test_the_sag_is_the_plain_formulas(n: int, seed: int, slack: float, angle: float, offset: float) -> None:
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(0.1, 1.0, n)
    distance = (1.0 - slack) * float(lengths.sum()) * (1.0 - 1e-9)
    start = np.array([offset, -offset])
    end = start + distance * np.array([math.cos(angle), math.sin(angle)])
    np.testing.assert_array_equal(_sag(start, end, lengths, ()), _plain_sag(start, end, lengths))


@settings(max_examples=100, deadline=None)
@given(
    n=st.integers(2, 40),
    slack=st.sampled_from([1e-6, 0.1, 0.5]),
    kinds=st.lists(st.sampled_from(KINDS), min_size=1, max_size=2),
    place=st.lists(st.tuples(st.floats(-0.2, 1.2), st.floats(-0.8, 0.1), st.floats(0.02, 0.4)), min_size=2, max_size=2),
)
def test_the_sag_keeps_clear_of_obstacles_when_its_chord_is(
    n: int, slack: float, kinds: list[str], place: list[tuple[float, float, float]]
) -> None:
    """The sag's obstacle rule, whichever of its two checks runs first: a sag clear of the
    obstacles, or a chord that is not, leaves the obstacle-free sag; otherwise the sag is made
    shallower (the same shape, a smaller depth) until its nodes are clear."""
    lengths = np.full(n, (1.0 + slack) / n)
    start, end = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    obstacles = tuple(
        _obstacle(kind, x, y, size) for kind, (x, y, size) in zip(kinds, place[: len(kinds)], strict=True)
    )
    free = _sag(start, end, lengths, ())
    sag = _sag(start, end, lengths, obstacles)
    chord = start + (np.cumsum(lengths)[:-1] / lengths.sum())[:, None] * (end - start)
    if initial._outside(obstacles, free) or not initial._outside(obstacles, chord):
        np.testing.assert_array_equal(sag, free)
    else:
        assert initial._outside(obstacles, sag)
        full, shallower = free[:, 1] - chord[:, 1], sag[:, 1] - chord[:, 1]  # (<= 0: below the chord)
        ratio = shallower.sum() / full.sum()
        assert 0.0 <= ratio < 1.0
        np.testing.assert_allclose(shallower, ratio * full, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["disk-drape", "box-edge", "two-pegs", "terrain", "three-supports", "slope"])
def test_the_presolves_obstacle_gradients_are_a_fresh_evaluations(name: str) -> None:
    """The push-out's gradients, handed to the solver's scaling, are the obstacles' at the final
    movable positions; the scaling gives the same scales with or without them."""
    problem = load_scenario(name)
    solution = solve(problem)
    for guess in (None, solution.positions, solution.positions + 0.1 * float(problem.link_lengths.max())):
        start = presolve(problem, guess)
        if start.obstacle_gradients is not None:
            for obstacle, gradient in zip(problem.obstacles, start.obstacle_gradients, strict=True):
                np.testing.assert_array_equal(gradient, obstacle.evaluate(start.positions[start.movable])[1])
        fresh = dataclasses.replace(start, obstacle_gradients=None)
        np.testing.assert_array_equal(_scale(problem, start).obstacle_scale, _scale(problem, fresh).obstacle_scale)


def test_no_gradients_after_a_push() -> None:
    """A guess with a node inside the disk is pushed out: its gradients are stale, none are kept."""
    problem = family(50, "disk")
    inside = presolve(problem).positions.copy()
    inside[25] = (0.5, -0.5)
    assert presolve(problem, inside).obstacle_gradients is None
    assert presolve(problem).obstacle_gradients is not None


# ----------------------------------------------------------------- the solver's median
@pytest.mark.parametrize("size", [1, 2, 3, 10, 11, 4096, 4097])
def test_the_obstacle_scale_is_numpys_median(size: int) -> None:
    rng = np.random.default_rng(size)
    norms = rng.lognormal(size=size)
    norms[rng.integers(0, size, size // 5)] = rng.choice([0.0, np.inf, np.nan])  # left out

    def phi(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = points.shape[0]
        return np.zeros(k), np.column_stack((norms[:k], np.zeros(k))), np.zeros((k, 2, 2))

    kept = norms[np.isfinite(norms) & (norms > 0)]
    expected = float(np.median(kept)) if kept.size else 1.0
    scale = _obstacle_scale(CallableObstacle(phi), np.zeros((size, 2)), np.arange(size))
    assert scale == expected


# ----------------------------------------------------------------- the exact start's early give-up
def test_a_rope_point_is_the_same_computed_with_fewer_others() -> None:
    """The first pass checks every ROPE_PRECHECK-th rope point: bitwise the full pass's, for the
    rope and for the pointwise shapes' depth."""
    arclength = np.linspace(0.0, 2.0, spans.ROPE_POINTS)
    sample = arclength[:: spans.ROPE_PRECHECK]
    shapes: list[Obstacle] = [
        Disk((0.4, -0.5), 0.3),
        Ellipse((0.5, -0.4), (0.3, 0.1), 25.0),
        HalfPlane((0, -0.6), (0.2, 1)),
    ]
    if find_spec("sympy"):
        shapes += [_obstacle("graph", 0.5, -0.8, 0.3), _obstacle("expression", 0.5, -0.5, 0.3)]
    assert all(type(shape) in spans.POINTWISE for shape in shapes)
    for right in [(1.0, 0.0), (0.3, -1.2), (1.9, 0.1), (1e-3, 0.5)]:
        rope = ContinuousCatenary.between((0.0, 0.0), right, 2.0, 0.5)
        points = rope.position_at_arclength(arclength)
        np.testing.assert_array_equal(rope.position_at_arclength(sample), points[:: spans.ROPE_PRECHECK])
        for shape in shapes:
            np.testing.assert_array_equal(
                depth(shape, points[:: spans.ROPE_PRECHECK]), depth(shape, points)[:: spans.ROPE_PRECHECK]
            )


@settings(max_examples=150, deadline=None)
@given(
    n=st.integers(2, 60),
    seed=st.integers(0, 2**32 - 1),
    slack=st.sampled_from([1e-6, 1e-3, 0.05, 0.3, 0.7]),
    angle=st.floats(-1.4, 1.4),
    kinds=st.lists(st.sampled_from(KINDS), min_size=1, max_size=2),
    place=st.lists(st.tuples(st.floats(-0.2, 1.2), st.floats(-1.5, 0.3), st.floats(0.02, 0.6)), min_size=2, max_size=2),
)
def test_the_early_give_up_is_the_full_checks_verdict(
    n: int, seed: int, slack: float, angle: float, kinds: list[str], place: list[tuple[float, float, float]]
) -> None:
    """Random spans and obstacles near them (as deep as the rope, or just touching it): the span
    with the rope check's early passes (the lowest point, every ROPE_PRECHECK-th point) is bitwise
    the span whose second pass is already the full one, None or not."""
    rng = np.random.default_rng(seed)
    masses, lengths = rng.uniform(0.01, 2.0, n - 1), rng.uniform(0.1, 1.0, n)
    total = float(lengths.sum())
    distance = (1.0 - slack) * total
    left = np.zeros(2)
    right = distance * np.array([math.cos(angle), math.sin(angle)])
    obstacles = tuple(
        _obstacle(kind, x * total, y * total, s * total)
        for kind, (x, y, s) in zip(kinds, place[: len(kinds)], strict=True)
    )
    with_precheck = spans.hanging_span(masses, lengths, 9.81, left, right, obstacles)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(spans, "ROPE_PRECHECK", 1)  # the first pass is the full check
        full = spans.hanging_span(masses, lengths, 9.81, left, right, obstacles)
    assert (with_precheck is None) == (full is None)
    if with_precheck is not None and full is not None:
        np.testing.assert_array_equal(with_precheck[0], full[0])
        np.testing.assert_array_equal(with_precheck[1], full[1])


def test_the_benchmark_disk_gives_up_in_the_first_pass(monkeypatch: pytest.MonkeyPatch) -> None:
    """The 50-node chain's rope goes through the disk: its lowest point alone shows it."""
    problem = family(50, "disk")
    calls: list[int] = []
    original = spans._deeper_than

    def counting(obstacles: tuple[Obstacle, ...], points: np.ndarray, limit: float) -> bool:
        calls.append(points.shape[0])
        return original(obstacles, points, limit)

    monkeypatch.setattr(spans, "_deeper_than", counting)
    assert spans.exact_start(problem) is None
    assert calls == [1]


# ----------------------------------------------------------------- solves
def test_the_benchmark_disk_is_a_balanced_minimum() -> None:
    """family(50, "disk") drapes over the disk: converged, a strict local minimum, and the solver's
    forces are the ones recovered from its positions alone."""
    problem = family(50, "disk")
    solution = solve(problem)
    assert solution.converged and solution.kkt_scaled.max() <= 1e-9
    assert second_order(problem, solution).verdict == "strict local minimum"
    recovered = recover_multipliers(problem, solution.positions)
    np.testing.assert_allclose(solution.link_multipliers, recovered.link, rtol=0, atol=1e-7 * problem.weight)
    np.testing.assert_allclose(solution.obstacle_multipliers, recovered.obstacle, rtol=0, atol=1e-7 * problem.weight)
    assert np.count_nonzero(solution.obstacle_multipliers > 1e-6) >= 5  # it rests on the disk


@pytest.mark.parametrize("formulation", ["norm", "squared"])
def test_link_contact_without_obstacles_solves_a_dangling_chain(formulation: str) -> None:
    """contact = "links" with no obstacle and one support: the solver's obstacle multipliers have
    no rows but N - 1 columns (their copy from the node rows failed on the shapes). The tensions
    are the weights below each link (docs/model.md, "The dangling chain")."""
    n, mass, g = 20, 2.0, 9.81
    problem = Problem.build(
        nodes=n, length=1.5, mass=mass, gravity=g, supports=[(0, (0.0, 0.0))], contact="links", formulation=formulation
    )
    for options in (SolverOptions(), SolverOptions(exact_start=False)):
        solution = solve(problem, options=options)
        assert solution.converged
        assert solution.obstacle_multipliers.shape == (0, n - 1)
        expected = mass * g * (n - 1 - np.arange(n - 1)) / n
        np.testing.assert_allclose(solution.link_tension, expected, rtol=1e-9)
