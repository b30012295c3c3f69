"""Obstacles in space beyond the quadratics: the rounded box (Cuboid), terrain below a height field
(Surface) and expressions in x, y and z. phi is checked against distances worked out here and its
derivatives against finite differences; scenario files with each shape parse, nets and a chain
over them solve with every node outside and every node in balance; bad input names its key."""

from __future__ import annotations

import importlib.util
import math
import pickle
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure

import funicular
from funicular import nets
from funicular.errors import ScenarioError
from funicular.model import Problem
from funicular.obstacles import Cuboid, Expression, Obstacle, Surface, depth, native_shape, obstacle_dimension
from funicular.scenario import load_scenario, parse_scenario, problem_from_table, problem_table, scenario_toml
from funicular.solution import Solution

needs_sympy = pytest.mark.skipif(importlib.util.find_spec("sympy") is None, reason="needs sympy (the expr extra)")

CENTRE = np.array([1.0, -0.5, 2.0])
HALF = np.array([0.6, 0.4, 0.3])
ANGLE = 30.0
RADIUS = 0.1


def _turn(degrees: float) -> np.ndarray:
    """The box's axes (columns) in world coordinates: a turn about z, counter-clockwise from above."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _world(local: list[float]) -> np.ndarray:
    """A point given in the box's own frame (centre at 0, axes along its sides) in world coordinates."""
    return CENTRE + _turn(ANGLE) @ np.asarray(local)


# Points in the box's frame and phi there, by hand. The rounded box is the inner box of half sizes
# h - r = (0.5, 0.3, 0.2) grown by r = 0.1: outside, the distance to it is the distance to the inner
# box minus r; inside, away from the rounded parts, the distance to the nearest face.
CASES = {
    # beyond the +x face, within its flat part (|y| <= 0.3, |z| <= 0.2): 0.25 past the face
    "face": ([0.6 + 0.25, 0.1, -0.05], -0.25),
    # beyond the edge along z at (+x, +y): offsets (0.3, 0.4) from the inner box, 0.5 away, minus r
    "edge": ([0.5 + 0.3, 0.3 + 0.4, 0.0], -(0.5 - 0.1)),
    # beyond the corner (+x, -y, +z): offsets (0.2, 0.3, 0.6), 0.7 away, minus r
    "corner": ([0.5 + 0.2, -(0.3 + 0.3), 0.2 + 0.6], -(0.7 - 0.1)),
    # inside, nearest the -y face (0.2 away; the +z face is 0.25 and the +x face 0.5 away)
    "inside": ([0.1, -0.2, 0.05], 0.2),
    # inside the rounded corner: 0.05 beyond the inner box along each axis, sqrt(3) 0.05 from it
    "inside the rounding": ([0.55, 0.35, 0.25], 0.1 - math.sqrt(3) * 0.05),
}


def _cuboid(radius: float = RADIUS) -> Cuboid:
    return Cuboid(tuple(CENTRE), tuple(HALF), radius=radius, angle=ANGLE, name="block")


@pytest.mark.parametrize("case", sorted(CASES))
def test_cuboid_phi_is_minus_the_signed_distance(case: str) -> None:
    local, expected = CASES[case]
    cuboid = _cuboid()
    phi, gradient, _ = cuboid.evaluate(_world(local)[None, :])
    assert phi[0] == pytest.approx(expected, abs=1e-12)
    assert depth(cuboid, _world(local)[None, :])[0] == pytest.approx(expected, abs=1e-12)
    # A distance has a unit gradient wherever it is differentiable.
    assert np.linalg.norm(gradient[0]) == pytest.approx(1.0, abs=1e-12)


def test_cuboid_gradient_points_out_through_the_turned_face() -> None:
    # Beyond the +x face the nearest point is straight back along the box's first axis, which the
    # turn by 30 degrees carries to (cos 30, sin 30, 0): phi falls fastest that way.
    _, gradient, _ = _cuboid().evaluate(_world(CASES["face"][0])[None, :])
    np.testing.assert_allclose(gradient[0], -np.array([math.cos(math.pi / 6), math.sin(math.pi / 6), 0.0]), atol=1e-12)


def test_sharp_cuboid_distances() -> None:
    sharp = _cuboid(radius=0.0)
    # corner: offsets (0.2, 0.3, 0.6) from the sharp corner at h = (0.6, 0.4, 0.3)
    points = np.array([_world([0.8, -0.7, 0.9]), _world([0.0, 0.0, 0.0]), _world([0.7, 0.0, 0.0])])
    phi, _, _ = sharp.evaluate(points)
    np.testing.assert_allclose(phi, [-0.7, 0.3, -0.1], atol=1e-12)


def _central_gradient(obstacle: Obstacle, point: np.ndarray, h: float = 1e-6) -> np.ndarray:
    steps = np.eye(3) * h
    plus = obstacle.evaluate(point + steps)[0]
    minus = obstacle.evaluate(point - steps)[0]
    result: np.ndarray = (plus - minus) / (2 * h)
    return result


def _central_hessian(obstacle: Obstacle, point: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """Second central differences of phi alone (the four-point rule off the diagonal)."""

    def phi(offset: np.ndarray) -> float:
        return float(obstacle.evaluate((point + offset)[None, :])[0][0])

    e = np.eye(3) * h
    hessian = np.empty((3, 3))
    for i in range(3):
        hessian[i, i] = (phi(e[i]) - 2 * phi(np.zeros(3)) + phi(-e[i])) / h**2
        for j in range(i + 1, 3):
            mixed = phi(e[i] + e[j]) - phi(e[i] - e[j]) - phi(-e[i] + e[j]) + phi(-e[i] - e[j])
            hessian[i, j] = hessian[j, i] = mixed / (4 * h**2)
    return hessian


def _check_derivatives(obstacle: Obstacle, points: np.ndarray) -> None:
    _, gradient, hessian = obstacle.evaluate(points)
    assert gradient.shape == (len(points), 3) and hessian.shape == (len(points), 3, 3)
    for k, point in enumerate(points):
        np.testing.assert_allclose(gradient[k], _central_gradient(obstacle, point), atol=1e-7)
        np.testing.assert_allclose(hessian[k], _central_hessian(obstacle, point), atol=2e-5)


def test_cuboid_derivatives_match_finite_differences() -> None:
    # One point inside each kind of region (each well away from where the regions meet).
    _check_derivatives(_cuboid(), np.array([_world(local) for local, _ in CASES.values()]))


@needs_sympy
def test_surface_derivatives_match_finite_differences() -> None:
    surface = Surface("0.1*sin(3*x) - 0.5 + 0.2*x*y**2", name="hills")
    points = np.random.default_rng(3).uniform(-1.0, 1.0, (6, 3))
    _check_derivatives(surface, points)
    phi, _, _ = surface.evaluate(points)
    x, y, z = points.T
    np.testing.assert_allclose(phi, 0.1 * np.sin(3 * x) - 0.5 + 0.2 * x * y**2 - z, atol=1e-14)


@needs_sympy
def test_expression_in_space_derivatives_match_finite_differences() -> None:
    expression = Expression("x**2*y + sin(z)*y - exp(0.3*x*z)", name="lump", dimension=3)
    points = np.random.default_rng(4).uniform(-1.0, 1.0, (6, 3))
    _check_derivatives(expression, points)
    phi, _, _ = expression.evaluate(points)
    x, y, z = points.T
    np.testing.assert_allclose(phi, x**2 * y + np.sin(z) * y - np.exp(0.3 * x * z), atol=1e-14)


@needs_sympy
def test_new_shapes_are_3d_and_only_the_box_is_native() -> None:
    cuboid = _cuboid()
    surface = Surface("0*x - 1")
    expression = Expression("1 - x**2 - y**2 - z**2", dimension=3)
    assert [obstacle_dimension(o) for o in (cuboid, surface, expression)] == [3, 3, 3]
    assert obstacle_dimension(Expression("1 - x**2 - y**2")) == 2
    assert native_shape(cuboid) is not None and native_shape(surface) is None and native_shape(expression) is None
    assert cuboid.convex and not surface.convex and not expression.convex
    for obstacle in (surface, expression):  # text shapes rebuild from their text in another process
        assert pickle.loads(pickle.dumps(obstacle)) == obstacle
    assert funicular.Cuboid is Cuboid and funicular.Surface is Surface


# ----------------------------------------------------------------- scenario files
def _net_file(obstacle: str, grid: int = 8) -> str:
    return f"""
dimension = 3
gravity = 1.0
[net]
grid = [{grid}, {grid}]
slack = 1.2
mass = 1.0
supports = "corners"
[[obstacles]]
name = "obstacle"
{obstacle}
"""


SHAPES = {
    # a block under the middle, turned, its edges rounded
    "box": (
        'shape = "box"\ncenter = [0.5, 0.5, -0.6]\nhalf_sizes = [0.2, 0.15, 0.3]\nradius = 0.05\nangle = 30',
        Cuboid((0.5, 0.5, -0.6), (0.2, 0.15, 0.3), radius=0.05, angle=30.0, name="obstacle"),
    ),
    # the same block with sharp edges (radius and angle left out)
    "sharp box": (
        'shape = "box"\ncenter = [0.5, 0.5, -0.6]\nhalf_sizes = [0.2, 0.15, 0.3]',
        Cuboid((0.5, 0.5, -0.6), (0.2, 0.15, 0.3), name="obstacle"),
    ),
    # rolling ground the middle of the net rests on
    "surface": ('shape = "surface"\nheight = "0.1*sin(3*x) - 0.5"', None),
    # a horizontal bar along y (a cylinder in x and z) the net drapes over
    "expression": ('shape = "expression"\nphi = "0.15**2 - (x - 0.5)**2 - (z + 0.55)**2"', None),
}


def _expected(shape: str) -> Obstacle:
    made = SHAPES[shape][1]
    if made is not None:
        return made
    if shape == "surface":
        return Surface("0.1*sin(3*x) - 0.5", name="obstacle")
    return Expression("0.15**2 - (x - 0.5)**2 - (z + 0.55)**2", name="obstacle", dimension=3)


def _shape_params(shapes: list[str]) -> list[Any]:
    return [pytest.param(s, marks=[needs_sympy] if s in ("surface", "expression") else []) for s in shapes]


@pytest.mark.parametrize("shape", _shape_params(sorted(SHAPES)))
def test_scenario_file_makes_the_shape(shape: str, tmp_path: Path) -> None:
    path = tmp_path / "net.toml"
    path.write_text(_net_file(SHAPES[shape][0]))
    problem = load_scenario(path)
    assert problem.dimension == 3
    (obstacle,) = problem.obstacles
    assert obstacle == _expected(shape)
    # and back: the problem's table (result files) and its scenario text give the same obstacle
    table = problem_table(problem)
    assert table is not None
    assert problem_from_table(table, "result").obstacles == problem.obstacles
    text = scenario_toml(problem)
    assert text is not None
    again = tmp_path / "again.toml"
    again.write_text(text)
    assert load_scenario(again).obstacles == problem.obstacles


def _check_equilibrium(problem: Problem, solution: Solution) -> None:
    """Status optimal, every free node outside every obstacle, and each free node in balance:
    the links' pulls (tension along each link, from the positions) plus the contact force equal
    the weight, the contact force pointing along -grad phi and only where the node touches; the
    supports and the obstacles together carry the whole weight, straight up."""
    assert solution.status.value == "optimal"
    positions = solution.positions
    free = ~problem.is_support
    for obstacle in problem.obstacles:
        phi, _, _ = obstacle.evaluate(positions)
        assert phi[free].max() <= 1e-9
    pull = np.zeros_like(positions)
    (i, j) = problem.link_nodes.T
    along = positions[j] - positions[i]
    along /= np.linalg.norm(along, axis=1)[:, None]
    np.add.at(pull, i, solution.link_tension[:, None] * along)
    np.add.at(pull, j, -solution.link_tension[:, None] * along)
    weight = problem.gravity * problem.masses
    contact = np.zeros_like(positions)
    contact[:, 2] = weight
    contact -= pull  # what the obstacle must push for balance
    scale = problem.weight
    np.testing.assert_allclose(solution.contact_forces[free], contact[free], atol=1e-7 * scale)
    (obstacle,) = problem.obstacles
    phi, gradient, _ = obstacle.evaluate(positions)
    pushes = np.linalg.norm(contact, axis=1) > 1e-6 * scale
    assert np.any(pushes & free)
    touching = free & pushes
    assert np.all(phi[touching] > -1e-6)  # only nodes on the surface are pushed
    normal = -gradient[touching] / np.linalg.norm(gradient[touching], axis=1)[:, None]
    cosine = np.einsum("ij,ij->i", contact[touching], normal) / np.linalg.norm(contact[touching], axis=1)
    np.testing.assert_allclose(cosine, 1.0, atol=1e-6)
    total = solution.support_reactions.sum(axis=0) + solution.contact_forces.sum(axis=0)
    np.testing.assert_allclose(total, [0.0, 0.0, problem.weight], atol=1e-8 * scale)


@pytest.mark.parametrize("shape", _shape_params(sorted(SHAPES)))
def test_net_over_each_shape_solves_outside_and_in_balance(shape: str, tmp_path: Path) -> None:
    path = tmp_path / "net.toml"
    path.write_text(_net_file(SHAPES[shape][0]))
    problem = load_scenario(path)
    _check_equilibrium(problem, funicular.solve(problem))


def test_chain_over_a_block_in_space() -> None:
    # A chain between two supports 1.2 apart, its sag crossing a block's top edge at z = -0.3.
    block = Cuboid((0.6, 0.1, -0.6), (0.25, 0.25, 0.3), radius=0.05, angle=20.0)
    problem = Problem.build(
        nodes=41,
        length=2.0,
        mass=1.0,
        supports=[(0, (0.0, 0.0, 0.0)), (-1, (1.2, 0.0, 0.0))],
        gravity=1.0,
        obstacles=[block],
        dimension=3,
    )
    solution = funicular.solve(problem)
    _check_equilibrium(problem, solution)
    assert solution.z.min() < -0.3  # it would hang lower without the block, which holds it up


def test_net_over_a_block_in_python() -> None:
    block = Cuboid((0.5, 0.5, -0.5), (0.15, 0.15, 0.3), radius=0.05)
    problem = nets.grid(10, 10, slack=1.2, supports="corners", gravity=1.0, obstacles=[block])
    solution = funicular.solve(problem)
    _check_equilibrium(problem, solution)
    # The block's top is at z = -0.2; the nodes on it rest on it.
    assert solution.z.min() < -0.2 < solution.z.max()


# ----------------------------------------------------------------- bad input
BAD = {
    "planar box keys in space": (
        'shape = "box"\ncenter = [0.5, 0.5, -0.6]\nhalf_size = [0.2, 0.2]\ncorner_radius = 0.05',
        "obstacles[0].half_size",
    ),
    "negative half size": (
        'shape = "box"\ncenter = [0.5, 0.5, -0.6]\nhalf_sizes = [0.2, -0.2, 0.3]',
        "obstacles[0].half_sizes",
    ),
    "two half sizes": ('shape = "box"\ncenter = [0.5, 0.5, -0.6]\nhalf_sizes = [0.2, 0.2]', "obstacles[0].half_sizes"),
    "radius beyond a half size": (
        'shape = "box"\ncenter = [0.5, 0.5, -0.6]\nhalf_sizes = [0.2, 0.2, 0.3]\nradius = 0.25',
        "obstacles[0].radius",
    ),
    "expression with an unknown variable": ('shape = "expression"\nphi = "x + y + t"', "obstacles[0].phi"),
    "surface in z": ('shape = "surface"\nheight = "z - 1"', "obstacles[0].height"),
    "surface without height": ('shape = "surface"\nf = "x"', "obstacles[0].f"),
}


TEXT_CASES = {"expression with an unknown variable", "surface in z"}  # (sympy reads the text)


@pytest.mark.parametrize(
    "case", [pytest.param(case, marks=[needs_sympy] if case in TEXT_CASES else []) for case in sorted(BAD)]
)
def test_bad_input_names_the_key(case: str, tmp_path: Path) -> None:
    text, key = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(_net_file(text))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key}"), message
    assert "\n" not in message and message.endswith("."), message


@needs_sympy
def test_unknown_variables_say_which_are_allowed(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(_net_file(BAD["expression with an unknown variable"][0]))
    with pytest.raises(ScenarioError, match=r"unknown name 't'; use the variables x, y, z,"):
        load_scenario(path)
    path.write_text(_net_file(BAD["surface in z"][0]))
    with pytest.raises(ScenarioError, match=r"unknown name 'z'; use the variables x, y,"):
        load_scenario(path)


def test_a_planar_file_refuses_the_box_in_space_keys() -> None:
    document = {
        "chain": {"nodes": 5, "length": 2.0, "mass": 1.0},
        "supports": [{"node": 0, "position": [0.0, 0.0]}],
        "obstacles": [{"shape": "box", "center": [0.0, -1.0], "half_sizes": [1.0, 1.0, 1.0]}],
    }
    with pytest.raises(ScenarioError, match=r"^<scenario>: obstacles\[0\]\.half_sizes is a key of a box in space"):
        parse_scenario(document)
    document["obstacles"] = [{"shape": "surface", "height": "0*x"}]
    with pytest.raises(ScenarioError, match=r"^<scenario>: obstacles\[0\]\.shape = 'surface' is a 3-D shape"):
        parse_scenario(document)


@pytest.mark.parametrize(
    "case",
    [
        "planar box keys in space",
        "negative half size",
        pytest.param("expression with an unknown variable", marks=needs_sympy),
    ],
)
def test_cli_bad_input_exits_2_with_one_sentence(case: str, tmp_path: Path) -> None:
    text, key = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(_net_file(text))
    run = subprocess.run(
        [sys.executable, "-m", "funicular", "solve", str(path)], capture_output=True, text=True, check=False
    )
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and lines[0].endswith("."), run.stderr
    assert "Traceback" not in run.stderr


# ----------------------------------------------------------------- pictures
@needs_sympy
def test_a_3d_drawing_shows_a_block_and_a_surface() -> None:
    from funicular.plot import draw_solution_3d

    block = Cuboid((0.5, 0.5, -0.6), (0.2, 0.15, 0.3), radius=0.05, angle=30.0, name="block")
    ground = Surface("0.1*sin(3*x) - 0.85", name="ground")
    solution = funicular.solve(nets.grid(8, 8, slack=1.2, gravity=1.0, obstacles=[block, ground]))
    ax: Any = draw_solution_3d(solution, Figure())
    labels = ax.get_legend_handles_labels()[1]
    assert "block" in labels and "ground" in labels
    # The block (its bottom at z = -0.9) is shown whole.
    assert ax.get_zlim()[0] <= -0.9
    sheets = [c for c in ax.collections if type(c).__name__ == "Poly3DCollection"]
    assert len(sheets) >= 2 and all(sheet.get_alpha() < 1 for sheet in sheets)
