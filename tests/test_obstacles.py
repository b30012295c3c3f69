"""Obstacles: exact derivatives, signs, the box's smoothness, expressions, validation and scenarios."""

from __future__ import annotations

import importlib.util
import math
import pickle
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from funicular._extras import install_command
from funicular._solver import SolverOptions, solve
from funicular.errors import FunicularError, ScenarioError
from funicular.model import Problem
from funicular.obstacles import (
    Box,
    CallableObstacle,
    Disk,
    Ellipse,
    Expression,
    Graph,
    HalfPlane,
    Obstacle,
    outline,
)
from funicular.scenario import load_scenario, parse_obstacle, parse_scenario

needs_sympy = pytest.mark.skipif(importlib.util.find_spec("sympy") is None, reason="needs sympy (the expr extra)")

NEW_BUILTINS = ["box-edge", "disk-drape", "ground", "peg-two-ways", "slope", "terrain", "two-pegs"]
BUMP = "-0.6 + 0.25*exp(-40*(x-0.5)**2)"
WAVY = "0.3 - (x - 0.2)**2 - 2*(y + 0.1)**2 + 0.1*sin(3*x*y)"


def disk_function(points: Any) -> tuple[Any, Any, Any]:
    return Disk((0.2, -0.1), 0.7).evaluate(points)


def box_away_from_kinks(box: Box, points: Any, margin: float = 1e-3) -> Any:
    """Points where the box's phi is C2: off its region boundaries and its inner medial axis."""
    angle = math.radians(box.angle)
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    q = (points - np.asarray(box.center)) @ rotation
    d = np.abs(q) - (np.asarray(box.half_size) - box.corner_radius)
    far = (np.abs(d).min(axis=1) > margin) & (np.abs(d[:, 0] - d[:, 1]) > margin) & (np.abs(q).min(axis=1) > margin)
    return points[far]


SHAPES: list[tuple[str, Callable[[], Obstacle]]] = [
    ("disk", lambda: Disk((0.2, -0.1), 0.7)),
    ("halfplane", lambda: HalfPlane((0.1, 0.2), (-0.3, 1.0))),
    ("ellipse", lambda: Ellipse((0.1, -0.2), (1.2, 0.5), angle=25.0)),
    ("box", lambda: Box((0.1, -0.2), (1.0, 0.6), corner_radius=0.3, angle=-35.0)),
    ("graph", lambda: Graph(BUMP)),
    ("expression", lambda: Expression(WAVY)),
    ("callable", lambda: CallableObstacle(disk_function)),
]
SYMPY_SHAPES = {"graph", "expression"}


def shape_params() -> list[Any]:
    return [pytest.param(make, id=name, marks=[needs_sympy] if name in SYMPY_SHAPES else []) for name, make in SHAPES]


# ----------------------------------------------------------------- derivatives
@pytest.mark.parametrize("make", shape_params())
def test_gradient_and_hessian_match_central_differences(make: Callable[[], Obstacle]) -> None:
    obstacle = make()
    points = np.random.default_rng(7).uniform(-1.5, 1.5, size=(200, 2))
    if isinstance(obstacle, Box):
        points = box_away_from_kinks(obstacle, points)
        assert len(points) > 100
    phi, gradient, hessian = obstacle.evaluate(points)
    assert (phi.shape, gradient.shape, hessian.shape) == ((len(points),), (len(points), 2), (len(points), 2, 2))
    h = 1e-6
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = h
        plus, minus = obstacle.evaluate(points + step), obstacle.evaluate(points - step)
        np.testing.assert_allclose((plus[0] - minus[0]) / (2 * h), gradient[:, axis], rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose((plus[1] - minus[1]) / (2 * h), hessian[:, :, axis], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(hessian, hessian.transpose(0, 2, 1), atol=1e-12)


@pytest.mark.parametrize("make", shape_params())
def test_every_shape_is_an_obstacle_and_handles_no_points(make: Callable[[], Obstacle]) -> None:
    obstacle = make()
    assert isinstance(obstacle, Obstacle)
    assert isinstance(obstacle.convex, bool)
    phi, gradient, hessian = obstacle.evaluate(np.empty((0, 2)))
    assert (phi.shape, gradient.shape, hessian.shape) == ((0,), (0, 2), (0, 2, 2))
    problem = Problem.build(nodes=3, length=2.0, mass=1.0, supports=[(0, (0, 5))], obstacles=[obstacle])
    assert problem.obstacles == (obstacle,)


# (obstacle, points inside, points outside)
SIGNS: list[Any] = [
    (lambda: Disk((1.0, 0.0), 0.5), [[1, 0], [1.4, 0.1]], [[0.4, 0], [1, 0.6]]),
    (lambda: HalfPlane((0.0, 0.0), (-0.3, 1.0)), [[1, 0.2], [-1, -0.5]], [[0, 0.1], [1, 0.4]]),
    (lambda: Ellipse((0.0, 0.0), (2.0, 0.5), angle=90.0), [[0, 1.9], [0.4, 0]], [[1.9, 0], [0, 2.1]]),
    (lambda: Box((0.0, 0.0), (1.0, 0.5), 0.2), [[0.99, 0.49 - 0.2], [0.9, 0.4]], [[0.99, 0.49], [1.1, 0]]),
    (lambda: Box((0.0, 0.0), (1.0, 0.5), 0.2, angle=90.0), [[0, 0.9], [0.45, 0]], [[0.9, 0], [0, 1.1]]),
]


@pytest.mark.parametrize(("make", "inside", "outside"), SIGNS)
def test_phi_is_positive_inside_and_negative_outside(make: Callable[[], Obstacle], inside: Any, outside: Any) -> None:
    obstacle = make()
    assert np.all(obstacle.evaluate(np.array(inside, dtype=float))[0] > 0)
    assert np.all(obstacle.evaluate(np.array(outside, dtype=float))[0] < 0)


@needs_sympy
def test_graph_and_expression_signs() -> None:
    assert Graph(BUMP).evaluate(np.array([[0.5, -0.36], [0.0, -0.61]]))[0].min() > 0
    assert Graph(BUMP).evaluate(np.array([[0.5, -0.34], [0.0, -0.59]]))[0].max() < 0
    circle = Expression("1 - x**2 - y**2")
    np.testing.assert_array_less([0.0, 0.0], circle.evaluate(np.array([[0, 0], [0.5, 0.5]]))[0])
    np.testing.assert_array_less(circle.evaluate(np.array([[1, 1], [0, -1.1]]))[0], [0.0, 0.0])


def test_disk_and_halfplane_gradients_are_unit_on_the_boundary() -> None:
    rim = np.array([[1.5, 0.0], [1.0, 0.5], [1.0 - 0.5 / math.sqrt(2), -0.5 / math.sqrt(2)]])
    phi, gradient, _ = Disk((1.0, 0.0), 0.5).evaluate(rim)
    np.testing.assert_allclose(phi, 0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(gradient, axis=1), 1)
    # The gradient points into the obstacle, so the contact force -nu grad phi points out of it.
    np.testing.assert_allclose(gradient, -(rim - [1.0, 0.0]) / 0.5)
    _, gradient, _ = HalfPlane((0, 0), (0, 2)).evaluate(np.zeros((1, 2)))
    np.testing.assert_allclose(gradient, [[0, -1]])


def test_ellipse_with_equal_axes_is_the_disk() -> None:
    points = np.random.default_rng(1).normal(size=(20, 2))
    for got, want in zip(
        Ellipse((0.3, 0.1), (0.6, 0.6), 40).evaluate(points), Disk((0.3, 0.1), 0.6).evaluate(points), strict=True
    ):
        np.testing.assert_allclose(got, want, atol=1e-14)


# ----------------------------------------------------------------- the box
BOX = Box((0.3, -0.2), (1.0, 0.5), corner_radius=0.2, angle=30.0)


def world(box: Box, q: Any) -> Any:
    """Box coordinates to world coordinates."""
    angle = math.radians(box.angle)
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return np.asarray(box.center) + np.asarray(q, dtype=float) @ rotation.T


def test_box_phi_is_zero_on_its_rounded_outline_with_unit_gradient() -> None:
    t = np.linspace(0, np.pi / 2, 7)
    corner = np.column_stack([0.8 + 0.2 * np.cos(t), 0.3 + 0.2 * np.sin(t)])
    edges = np.array([[1.0, 0.0], [0.0, 0.5], [-1.0, -0.1], [0.5, -0.5]])
    phi, gradient, _ = BOX.evaluate(world(BOX, np.vstack([corner, edges])))
    np.testing.assert_allclose(phi, 0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(gradient, axis=1), 1)
    # Deep inside, phi is the distance to the nearest edge.
    np.testing.assert_allclose(BOX.evaluate(world(BOX, [[0.0, 0.0], [0.9, 0.0]]))[0], [0.5, 0.1])


# Points on the boundaries between the corner, edge and inside regions (box coordinates), and
# the direction to step across them.
CROSSINGS = [
    ([0.8, 0.4], [1, 0]),  # corner | top-edge region
    ([0.9, 0.3], [0, 1]),  # corner | side-edge region
    ([0.8, 0.6], [1, 0]),  # the same line, outside
    ([0.8, 0.1], [1, 0]),  # inside | side-edge region (both the side's half-plane)
    ([-0.9, -0.3], [0, 1]),  # corner | side-edge region, lower left
    ([0.5, 0.5], [0, 1]),  # on the top edge itself
]


@pytest.mark.parametrize(("q", "direction"), CROSSINGS)
def test_box_is_c1_across_its_regions(q: list[float], direction: list[float]) -> None:
    delta = 1e-9 * np.asarray(direction, dtype=float)
    points = world(BOX, np.array([np.asarray(q) - delta, np.asarray(q) + delta]))
    phi, gradient, _ = BOX.evaluate(points)
    assert abs(phi[1] - phi[0]) < 1e-8
    np.testing.assert_allclose(gradient[1], gradient[0], atol=1e-7)


def test_box_phi_is_continuous_everywhere() -> None:
    # Along a fine line through every region (and the medial axis, where only phi is continuous).
    q = np.column_stack([np.linspace(-1.5, 1.5, 30001), np.linspace(-0.9, 1.1, 30001)])
    phi = BOX.evaluate(world(BOX, q))[0]
    assert np.max(np.abs(np.diff(phi))) < 2e-4


def test_quadratic_shapes_equal_their_closed_forms() -> None:
    """Disk, half-plane and turned ellipse (evaluated through ``Quadratic``) against their formulas."""
    points = np.random.default_rng(5).uniform(-3, 3, size=(40, 2))
    x, y = points.T
    phi, gradient, hessian = Disk((1.0, -2.0), 0.7).evaluate(points)
    np.testing.assert_allclose(phi, (0.49 - (x - 1) ** 2 - (y + 2) ** 2) / 1.4, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(gradient, -np.column_stack([x - 1, y + 2]) / 0.7, rtol=1e-14)
    np.testing.assert_allclose(hessian, np.broadcast_to(-np.eye(2) / 0.7, (40, 2, 2)), rtol=1e-14)
    phi, gradient, hessian = HalfPlane((0.5, 1.0), (3.0, 4.0)).evaluate(points)
    np.testing.assert_allclose(phi, -(0.6 * (x - 0.5) + 0.8 * (y - 1.0)), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(gradient, np.broadcast_to([-0.6, -0.8], (40, 2)), rtol=1e-14)
    np.testing.assert_array_equal(hessian, 0.0)
    # Semi-axes (2, 0.5) turned 30 degrees: u, v along the turned axes; phi scaled by min(a, b) / 2.
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    u, v = c * (x - 1) + s * y, -s * (x - 1) + c * y
    phi, gradient, _ = Ellipse((1.0, 0.0), (2.0, 0.5), angle=30.0).evaluate(points)
    np.testing.assert_allclose(phi, 0.25 * (1 - u**2 / 4 - v**2 / 0.25), rtol=1e-12, atol=1e-14)
    du, dv = -0.25 * 2 * u / 4, -0.25 * 2 * v / 0.25  # d phi / du, d phi / dv
    np.testing.assert_allclose(gradient, np.column_stack([c * du - s * dv, s * du + c * dv]), rtol=1e-12, atol=1e-14)


def test_a_stadium_box_is_allowed() -> None:
    stadium = Box((0, 0), (1.0, 0.5), corner_radius=0.5)
    np.testing.assert_allclose(stadium.evaluate(np.array([[1.0, 0.0], [0.5, 0.5]]))[0], [0.0, 0.0], atol=1e-15)


# ----------------------------------------------------------------- expressions
@needs_sympy
def test_expression_equals_its_closed_form() -> None:
    points = np.random.default_rng(2).normal(size=(30, 2))
    x, y = points.T
    phi, gradient, hessian = Expression("-y - 0.1*x**2").evaluate(points)
    np.testing.assert_allclose(phi, -y - 0.1 * x**2, rtol=1e-14)
    np.testing.assert_allclose(gradient, np.column_stack([-0.2 * x, -np.ones_like(x)]), rtol=1e-14)
    np.testing.assert_allclose(hessian, np.broadcast_to([[-0.2, 0], [0, 0]], (30, 2, 2)), rtol=1e-14)
    # ^ means power, as a user writing formulas expects.
    np.testing.assert_allclose(Expression("-y - 0.1*x^2").evaluate(points)[0], phi, rtol=1e-14)


@needs_sympy
def test_expression_and_graph_equal_the_built_in_shapes() -> None:
    points = np.random.default_rng(3).normal(size=(30, 2))
    for got, want in zip(
        Expression("0.25 - (x - 1)**2 - y**2").evaluate(points), Disk((1, 0), 0.5).evaluate(points), strict=True
    ):
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
    # Graph(0.3 x) is the half-plane below the line with normal (-0.3, 1), scaled by |(-0.3, 1)|.
    scale = math.hypot(0.3, 1.0)
    for got, want in zip(Graph("0.3*x").evaluate(points), HalfPlane((0, 0), (-0.3, 1)).evaluate(points), strict=True):
        np.testing.assert_allclose(got, scale * want, rtol=1e-13, atol=1e-15)


@needs_sympy
def test_graph_equals_its_closed_form() -> None:
    points = np.random.default_rng(4).uniform(-1, 2, size=(30, 2))
    x, y = points.T
    bump = 0.25 * np.exp(-40 * (x - 0.5) ** 2)
    phi, gradient, hessian = Graph(BUMP).evaluate(points)
    np.testing.assert_allclose(phi, -0.6 + bump - y, rtol=1e-13)
    np.testing.assert_allclose(gradient[:, 0], -80 * (x - 0.5) * bump, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(gradient[:, 1], -1.0)
    np.testing.assert_allclose(hessian[:, 0, 0], (6400 * (x - 0.5) ** 2 - 80) * bump, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(hessian[:, 1, :], 0.0)


@needs_sympy
@pytest.mark.parametrize("make", [lambda: Expression("1"), lambda: Expression("-x"), lambda: Graph("2")])
def test_constant_terms_come_back_as_arrays(make: Callable[[], Obstacle]) -> None:
    for k in (0, 1, 5):
        phi, gradient, hessian = make().evaluate(np.zeros((k, 2)))
        assert (phi.shape, gradient.shape, hessian.shape) == ((k,), (k, 2), (k, 2, 2))
        assert phi.flags.writeable


@needs_sympy
def test_a_kink_has_zero_curvature_away_from_it() -> None:
    phi, gradient, hessian = Graph("-Abs(x)").evaluate(np.array([[-1.0, 0.0], [2.0, -3.0]]))
    np.testing.assert_allclose(phi, [-1.0, 1.0])
    np.testing.assert_allclose(gradient, [[1.0, -1.0], [-1.0, -1.0]])
    np.testing.assert_array_equal(hessian, 0.0)


@needs_sympy
@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda: Expression("sin(x", name="terrain"), "not a valid expression"),
        (lambda: Expression("x + z", name="terrain"), "unknown name 'z'"),
        (lambda: Graph("y", name="terrain"), "unknown name 'y'"),
        (lambda: Graph("x.__class__", name="terrain"), "'.'"),
        (lambda: Expression("x; y", name="terrain"), "';'"),
        (lambda: Expression("'x'", name="terrain"), "uses"),
        (lambda: Expression("__import__('os')", name="terrain"), "unknown name '__import__'"),
        (lambda: Expression("sqrt(-1) + x", name="terrain"), "not a real-valued"),
        (lambda: Graph("log(0)", name="terrain"), "not a real-valued"),
        (lambda: Expression("sin", name="terrain"), "not a real-valued"),
        (lambda: Expression("", name="terrain"), "not a valid expression"),
        (lambda: Graph(3, name="terrain"), "must be a string"),  # type: ignore[arg-type]
    ],
)
def test_bad_expressions_name_the_obstacle(make: Callable[[], Obstacle], words: str) -> None:
    with pytest.raises(ScenarioError, match="obstacle 'terrain'") as info:
        make()
    assert words in str(info.value)
    assert "\n" not in str(info.value)


@needs_sympy
def test_an_undefined_value_is_reported_where_it_happens() -> None:
    """Evaluation passes a NaN through (a line-search trial may stray there); the solver names the
    obstacle and the node when phi is undefined where the chain actually is."""
    terrain = Graph("log(x) - 5", name="terrain")
    phi = terrain.evaluate(np.array([[1.0, 0.0], [-1.0, 2.0]]))[0]
    assert phi[0] == pytest.approx(-5.0) and np.isnan(phi[1])
    problem = Problem.build(
        nodes=5, length=2.0, mass=1.0, gravity=1.0, supports=[(0, (-1.0, 0.0))], obstacles=[terrain]
    )
    with pytest.raises(ScenarioError, match=r"obstacle 'terrain': phi or its derivatives are not finite at node 1"):
        solve(problem)


@dataclass(frozen=True)
class _LoweredDisk(Disk):
    """A disk subclass whose ``evaluate`` moves it 0.2 up: the solver must follow ``evaluate``."""

    def evaluate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return super().evaluate(np.asarray(points) - [0.0, 0.2])


class _DiskWithAnAttribute:
    """A plain disk with an unrelated attribute named ``quadratic``."""

    name, convex, quadratic = "bump", True, 0.5

    def evaluate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return Disk((0.5, -0.55), 0.25).evaluate(points)


@pytest.mark.parametrize("obstacle", [_LoweredDisk((0.5, -0.55), 0.25), _DiskWithAnAttribute()])
def test_the_solver_follows_evaluate_not_a_quadratic_attribute(obstacle: Obstacle) -> None:
    """Only the built-in shapes themselves are evaluated from their quadratic form: a subclass's
    override is followed, and an unrelated attribute named ``quadratic`` is ignored."""
    problem = Problem.build(
        nodes=61, length=1.5, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))], obstacles=[obstacle]
    )
    solution = solve(problem, SolverOptions(escape_saddles=False))
    assert solution.converged and solution.kkt_scaled.max() < 1e-8  # residuals recomputed through evaluate
    phi = obstacle.evaluate(solution.positions)[0]
    assert abs(float(phi.max())) < 1e-9  # resting on the obstacle evaluate describes
    assert float(solution.contact_forces.sum(axis=0)[1]) > 0.1 * problem.weight


def test_an_infinite_gradient_at_the_solution_is_named_not_a_hang() -> None:
    """phi finite but its gradient infinite below y = -0.3: the inertia correction must not loop
    for ever on an infinite Newton matrix."""

    def phi(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        offset = points - np.array([0.5, -2.0])
        gradient = -offset / 0.1
        gradient[points[:, 1] < -0.3] = np.inf
        return (0.01 - (offset**2).sum(axis=1)) / 0.2, gradient, np.broadcast_to(-np.eye(2) / 0.1, (len(points), 2, 2))

    problem = Problem.build(
        nodes=61,
        length=1.5,
        mass=1.0,
        gravity=1.0,
        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[CallableObstacle(phi, name="bad")],
    )
    with pytest.raises(ScenarioError, match=r"obstacle 'bad': phi or its derivatives are not finite at node"):
        solve(problem)


@needs_sympy
def test_expressions_pickle() -> None:
    points = np.random.default_rng(5).normal(size=(5, 2))
    for obstacle in (Graph(BUMP, name="g"), Expression(WAVY, name="e")):
        copy = pickle.loads(pickle.dumps(obstacle))
        assert copy == obstacle
        np.testing.assert_array_equal(copy.evaluate(points)[2], obstacle.evaluate(points)[2])


def test_missing_sympy_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sympy", None)  # makes `import sympy` fail
    with pytest.raises(FunicularError, match=re.escape(install_command("expr"))):
        Graph("x")


# ----------------------------------------------------------------- callables
def test_callable_obstacle_passes_values_through() -> None:
    points = np.random.default_rng(6).normal(size=(8, 2))
    wrapped = CallableObstacle(disk_function, name="mine", convex=True)
    assert wrapped.convex
    for got, want in zip(wrapped.evaluate(points), Disk((0.2, -0.1), 0.7).evaluate(points), strict=True):
        np.testing.assert_array_equal(got, want)


BAD_RETURNS = [
    ("one value", lambda p: np.zeros(len(p)), "not (phi, gradient, hessian)"),
    ("two values", lambda p: (np.zeros(len(p)), np.zeros((len(p), 2))), "not (phi, gradient, hessian)"),
    ("phi column", lambda p: (np.zeros((len(p), 1)), np.zeros((len(p), 2)), np.zeros((len(p), 2, 2))), "phi"),
    ("flat gradient", lambda p: (np.zeros(len(p)), np.zeros(len(p)), np.zeros((len(p), 2, 2))), "gradient"),
    ("hessian rows", lambda p: (np.zeros(len(p)), np.zeros((len(p), 2)), np.zeros((len(p), 4))), "Hessian"),
    ("strings", lambda p: ("a", "b", "c"), "non-numeric"),
]


@pytest.mark.parametrize(("function", "words"), [pytest.param(f, w, id=i) for i, f, w in BAD_RETURNS])
def test_callable_obstacle_checks_what_comes_back(function: Callable[[Any], Any], words: str) -> None:
    with pytest.raises(ScenarioError, match="obstacle 'mine'") as info:
        CallableObstacle(function, name="mine").evaluate(np.zeros((3, 2)))
    assert words in str(info.value)
    assert "\n" not in str(info.value)


# ----------------------------------------------------------------- construction checks
CONSTRUCTION = [
    (lambda: Disk((0, 0), -1, name="peg"), "obstacle 'peg': radius = -1 must be a positive number."),
    (lambda: Disk((0, 0), True, name="peg"), "obstacle 'peg': radius = True must be"),
    (lambda: Disk((0, math.nan), 1, name="peg"), "obstacle 'peg': center = (0, nan) must be two finite numbers"),
    (lambda: Disk((0, 0, 0), 1, name="peg"), "obstacle 'peg': center"),  # type: ignore[arg-type]
    (lambda: HalfPlane((0, 0), (0, 0), name="floor"), "obstacle 'floor': normal = (0, 0) must be a nonzero"),
    (lambda: Ellipse((0, 0), (1, 0), name="egg"), "obstacle 'egg': semi_axes = (1, 0) must be two positive"),
    (lambda: Ellipse((0, 0), (1, 1), math.inf, name="egg"), "obstacle 'egg': angle = inf must be a finite number"),
    (lambda: Box((0, 0), (1, 0.5), 0.6, name="crate"), "obstacle 'crate': corner_radius = 0.6 must be at most"),
    (lambda: Box((0, 0), (1, 0.5), 0, name="crate"), "obstacle 'crate': corner_radius = 0 must be a positive"),
    (lambda: Box((0, 0), (-1, 0.5), 0.1, name="crate"), "obstacle 'crate': half_size"),
]


@pytest.mark.parametrize(("make", "message"), CONSTRUCTION)
def test_bad_shape_names_the_obstacle_and_field(make: Callable[[], Obstacle], message: str) -> None:
    with pytest.raises(ScenarioError) as info:
        make()
    assert str(info.value).startswith(message)


def test_shapes_store_plain_float_tuples() -> None:
    disk = Disk(np.array([1, 2]), 3)  # type: ignore[arg-type]
    assert disk.center == (1.0, 2.0) and isinstance(disk.radius, float)
    assert disk == Disk((1.0, 2.0), 3.0)
    assert hash(disk) == hash(Disk((1.0, 2.0), 3.0))


# ----------------------------------------------------------------- outlines
BOUNDS = (-2.0, 2.0, -1.5, 1.5)


@pytest.mark.parametrize(
    "obstacle",
    [Disk((0.5, 0.2), 0.5), Ellipse((0, 0), (1.0, 0.4), 30), Box((0, 0), (1.0, 0.5), 0.2, 20)],
    ids=["disk", "ellipse", "box"],
)
def test_outline_of_a_shape_inside_the_bounds_lies_on_its_boundary(obstacle: Obstacle) -> None:
    polygon = outline(obstacle, BOUNDS, samples=100)
    assert len(polygon) >= 100
    np.testing.assert_array_equal(polygon[0], polygon[-1])
    np.testing.assert_allclose(obstacle.evaluate(polygon)[0], 0, atol=1e-12)


def in_bounds(polygon: Any, bounds: tuple[float, float, float, float]) -> bool:
    xmin, xmax, ymin, ymax = bounds
    x, y = polygon.T
    tol = 1e-12
    return bool(np.all((x >= xmin - tol) & (x <= xmax + tol) & (y >= ymin - tol) & (y <= ymax + tol)))


def test_outline_is_clipped_to_the_bounds() -> None:
    polygon = outline(Disk((2.0, 0.0), 1.0), BOUNDS)
    assert in_bounds(polygon, BOUNDS)
    assert polygon[:, 0].min() == pytest.approx(1.0, abs=1e-3)
    assert outline(Disk((5.0, 0.0), 1.0), BOUNDS).shape == (0, 2)  # entirely outside


def test_halfplane_outline_fills_to_the_edge() -> None:
    polygon = outline(HalfPlane((0, 0), (-0.3, 1)), BOUNDS)
    assert in_bounds(polygon, BOUNDS)
    np.testing.assert_array_equal(polygon[0], polygon[-1])
    # Corners of the bounds below the line are in it, those above are not.
    vertices = {tuple(np.round(v, 12)) for v in polygon}
    assert {(-2.0, -1.5), (2.0, -1.5)} <= vertices
    assert (2.0, 1.5) not in vertices and (-2.0, 1.5) not in vertices
    assert np.all(HalfPlane((0, 0), (-0.3, 1)).evaluate(polygon)[0] >= -1e-12)


@needs_sympy
def test_graph_outline_fills_below_the_curve() -> None:
    polygon = outline(Graph(BUMP), BOUNDS, samples=50)
    assert in_bounds(polygon, BOUNDS)
    np.testing.assert_array_equal(polygon[0], polygon[-1])
    np.testing.assert_allclose(Graph(BUMP).evaluate(polygon[:50])[0], 0, atol=1e-15)
    assert polygon[50:52].tolist() == [[2.0, -1.5], [-2.0, -1.5]]


@needs_sympy
def test_expression_and_callable_outlines_are_empty() -> None:
    assert outline(Expression(WAVY), BOUNDS).shape == (0, 2)
    assert outline(CallableObstacle(disk_function), BOUNDS).shape == (0, 2)

    class Bare:
        name = "bare"
        convex = True

        def evaluate(self, points: Any) -> Any:
            return disk_function(points)

    assert outline(Bare(), BOUNDS).shape == (0, 2)


# ----------------------------------------------------------------- scenario files
def doc(*obstacles: Any, **top: Any) -> dict[str, Any]:
    document: dict[str, Any] = {
        "chain": {"nodes": 5, "length": 2.0, "mass": 1.0},
        "supports": [{"node": 0, "position": [0.0, 0.0]}, {"node": -1, "position": [1.0, 0.0]}],
        "obstacles": list(obstacles),
    }
    document.update(top)
    return document


DISK = {"shape": "disk", "center": [0.5, -1.0], "radius": 0.2}


def disk(**changes: Any) -> dict[str, Any]:
    table = {**DISK, **changes}
    return {key: value for key, value in table.items() if value is not None}


@needs_sympy
def test_every_shape_parses_from_toml() -> None:
    problem = parse_scenario(
        doc(
            {"shape": "halfplane", "point": [0, -2], "normal": [0, 1]},
            DISK,
            {"shape": "ellipse", "center": [0, -3], "semi_axes": [1, 0.5], "angle": 30, "name": "egg"},
            {"shape": "box", "center": [0, -3], "half_size": [1, 0.5], "corner_radius": 0.1},
            {"shape": "graph", "f": "-5 + 0.1*x"},
            {"shape": "expression", "phi": "-y - 10"},
            contact="links",
        )
    )
    assert [type(o).__name__ for o in problem.obstacles] == [
        "HalfPlane",
        "Disk",
        "Ellipse",
        "Box",
        "Graph",
        "Expression",
    ]
    assert [o.name for o in problem.obstacles] == ["halfplane 0", "disk 1", "egg", "box 3", "graph 4", "expression 5"]
    assert problem.obstacles[1] == Disk((0.5, -1.0), 0.2, name="disk 1")
    assert problem.obstacles[2] == Ellipse((0, -3), (1, 0.5), 30.0, name="egg")
    assert problem.contact == "links"


def test_no_obstacles_by_default() -> None:
    problem = parse_scenario({k: v for k, v in doc().items() if k != "obstacles"})
    assert problem.obstacles == () and problem.contact == "nodes"
    assert parse_scenario(doc()).obstacles == ()


def test_parse_obstacle_directly() -> None:
    assert parse_obstacle(DISK, 4) == Disk((0.5, -1.0), 0.2, name="disk 4")
    with pytest.raises(ScenarioError, match=r"^obstacles\[4\]\.radius = -1.0 must be a positive number\.$"):
        parse_obstacle(disk(radius=-1), 4)


BAD = [
    # (id, document, key path the message must name)
    ("not-a-list", doc() | {"obstacles": DISK}, "obstacles"),
    ("item-not-table", doc(1), "obstacles[0]"),
    ("missing-shape", doc(disk(shape=None)), "obstacles[0].shape"),
    ("shape-not-string", doc(disk(shape=3)), "obstacles[0].shape"),
    ("unknown-shape", doc(disk(shape="triangle")), "obstacles[0].shape"),
    ("unknown-key", doc(disk(radiu=1)), "obstacles[0].radiu"),
    ("other-shapes-key", doc(disk(normal=[0, 1])), "obstacles[0].normal"),
    ("missing-radius", doc(disk(radius=None)), "obstacles[0].radius"),
    ("string-radius", doc(disk(radius="1")), "obstacles[0].radius"),
    ("bool-radius", doc(disk(radius=True)), "obstacles[0].radius"),
    ("negative-radius", doc(disk(radius=-1)), "obstacles[0].radius"),
    ("nan-radius", doc(disk(radius=math.nan)), "obstacles[0].radius"),
    ("short-center", doc(disk(center=[0])), "obstacles[0].center"),
    ("number-center", doc(disk(center=0)), "obstacles[0].center"),
    ("string-in-center", doc(disk(center=[0, "1"])), "obstacles[0].center[1]"),
    ("inf-in-center", doc(disk(center=[math.inf, 1])), "obstacles[0].center[0]"),
    ("name-not-string", doc(disk(name=1)), "obstacles[0].name"),
    ("same-name", doc(disk(name="peg"), disk(name="peg")), "obstacles[1].name"),
    ("zero-normal", doc({"shape": "halfplane", "point": [0, 0], "normal": [0, 0]}), "obstacles[0].normal"),
    ("missing-point", doc({"shape": "halfplane", "normal": [0, 1]}), "obstacles[0].point"),
    ("flat-ellipse", doc({"shape": "ellipse", "center": [0, 0], "semi_axes": [1, -1]}), "obstacles[0].semi_axes"),
    ("ellipse-angle", doc({"shape": "ellipse", "center": [0, 0], "semi_axes": [1, 1], "angle": "90"}), "angle"),
    ("sharp-box", doc({"shape": "box", "center": [0, 0], "half_size": [1, 1]}), "obstacles[0].corner_radius"),
    (
        "round-box",
        doc(DISK, {"shape": "box", "center": [0, 0], "half_size": [1, 0.5], "corner_radius": 0.7}),
        "obstacles[1].corner_radius",
    ),
    ("graph-number", doc({"shape": "graph", "f": 1.0}), "obstacles[0].f"),
    ("bad-contact", doc(contact="edges"), "contact"),
    ("number-contact", doc(contact=3), "contact"),
]
BAD_SYMPY = [
    ("graph-syntax", doc({"shape": "graph", "f": "exp(-x"}), "obstacles[0].f"),
    ("graph-y", doc({"shape": "graph", "f": "x + y"}), "obstacles[0].f"),
    ("expression-z", doc(DISK, {"shape": "expression", "phi": "x + z"}), "obstacles[1].phi"),
    ("expression-complex", doc({"shape": "expression", "phi": "sqrt(-2)*x"}), "obstacles[0].phi"),
]


@pytest.mark.parametrize(
    ("document", "key"),
    [pytest.param(d, k, id=i) for i, d, k in BAD]
    + [pytest.param(d, k, id=i, marks=needs_sympy) for i, d, k in BAD_SYMPY],
)
def test_bad_obstacle_document_names_the_key(document: dict[str, Any], key: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(document, source="bad.toml")
    message = str(info.value)
    assert message.startswith("bad.toml: ")
    assert key in message
    assert "\n" not in message


# ----------------------------------------------------------------- built-ins
@pytest.mark.parametrize("name", [pytest.param(n, marks=[needs_sympy] if n == "terrain" else []) for n in NEW_BUILTINS])
def test_obstacle_builtins_load(name: str) -> None:
    problem = load_scenario(name)
    assert problem.name == name
    assert problem.obstacles
    assert problem.gravity == 1.0
    assert problem.total_mass == pytest.approx(1.0, abs=1e-12)
    # The supports are outside every obstacle (they are fixed; the solver cannot move them out).
    for obstacle in problem.obstacles:
        assert np.all(obstacle.evaluate(problem.support_positions)[0] < 0)


def test_obstacle_builtins_have_one_line_descriptions() -> None:
    from funicular.scenario import builtin_scenarios

    descriptions = builtin_scenarios()
    for name in NEW_BUILTINS:
        assert descriptions[name] and "\n" not in descriptions[name]


@pytest.mark.parametrize("text", ["9**9**9", "x**2000 - y", "x^(2^11) - y", "2**-9**9 - y"])
def test_huge_constant_exponents_are_refused_before_sympy_computes_them(text: str) -> None:
    """sympy would compute 9**9**9 exactly (370 million digits); the parser refuses it in one sentence."""
    with pytest.raises(ScenarioError, match=r"has the exponent .*; exponents must be at most 1000 in size"):
        Expression(phi=text, name="tower").evaluate(np.zeros((1, 2)))


def test_moderate_exponents_still_work() -> None:
    phi, _, _ = Expression(phi="x**4 + y**2 - 2**10").evaluate(np.array([[2.0, 3.0]]))
    assert phi[0] == 16.0 + 9.0 - 1024.0


@pytest.mark.parametrize(
    "make", [lambda: Disk((0.5, -0.55), 1e308), lambda: Disk((1e200, 0.0), 1.0)], ids=["radius", "centre"]
)
def test_obstacle_sizes_whose_squares_overflow_are_refused(make: Callable[[], Obstacle]) -> None:
    """A radius of 1e308 used to raise OverflowError from radius**2 (found by the long fuzz profile)."""
    with pytest.raises(ScenarioError, match="is too large"):
        make()


@pytest.mark.parametrize(
    ("make", "key"),
    [
        (lambda: Disk((0.5, -0.55), 1e-320), "radius"),
        (lambda: Ellipse((0.0, 0.0), (1.0, 1e-200)), "semi_axes"),
        (lambda: Box((0.0, 0.0), (1.0, 1.0), corner_radius=1e-160), "corner_radius"),
    ],
)
def test_obstacle_sizes_whose_reciprocals_overflow_are_refused(make: Callable[[], Obstacle], key: str) -> None:
    """A radius of 1e-320 made phi's curvature -1/r overflow (found by the long fuzz profile)."""
    with pytest.raises(ScenarioError, match=rf"{key} = .* is too small; sizes must be at least 1e-150"):
        make()


@pytest.mark.parametrize(
    "shape",
    [
        Disk(center=(0.5, -0.5), radius=0.3),
        Ellipse(center=(0.0, 1.0), semi_axes=(2.0, 0.5), angle=0.4),
        HalfPlane(point=(0.0, -1.0), normal=(0.3, 1.0)),
    ],
    ids=["disk", "ellipse", "halfplane"],
)
def test_quadratic_shapes_evaluate_like_their_formula(shape: Obstacle) -> None:
    # The quadratic shapes as the solver core evaluates them against phi's formula evaluated with
    # numpy's own matrix products.
    form = shape.quadratic()  # type: ignore[attr-defined]
    points = np.random.default_rng(3).uniform(-2.0, 2.0, (7, 2))
    phi, gradient, hessian = shape.evaluate(points)
    d = points - form.centre
    expected = form.value + d @ form.gradient + 0.5 * np.einsum("ka,ab,kb->k", d, form.hessian, d)
    np.testing.assert_allclose(phi, expected, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(gradient, form.gradient + d @ form.hessian.T, rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(hessian, np.broadcast_to(form.hessian, (7, 2, 2)))
    assert shape.evaluate(points[:0])[2].shape == (0, 2, 2)
