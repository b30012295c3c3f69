"""Scenario files for nets and 3-D chains: the [net] syntax, the generators, the 3-D built-ins
(force balance recomputed here from positions and tensions) and bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import funicular
from funicular import nets
from funicular.errors import ScenarioError
from funicular.obstacles import Sphere
from funicular.scenario import load_scenario, parse_scenario, problem_from_table, problem_table
from funicular.solution import Solution

SQUARE = """
dimension = 3
gravity = 1.0
[net]
nodes = 4
mass = 1.0
links = [[0, 1, 0.6], [1, 2, 0.6], [2, 3, 0.6], [3, 0, 0.6]]
[[supports]]
node = 0
position = [0.0, 0.0, 0.0]
[[obstacles]]
shape = "sphere"
center = [0.5, 0.5, -0.45]
radius = 0.3
"""
NEW_BUILTINS = ("net-over-sphere", "chain-around-post", "hanging-model")


def _write(tmp_path: Path, text: str, name: str = "net.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_listed_net_parses_to_its_problem(tmp_path: Path) -> None:
    problem = load_scenario(_write(tmp_path, SQUARE))
    assert problem.dimension == 3
    assert not problem.is_chain
    assert problem.link_nodes.tolist() == [[0, 1], [1, 2], [2, 3], [3, 0]]
    np.testing.assert_array_equal(problem.link_lengths, [0.6] * 4)
    np.testing.assert_array_equal(problem.masses, [0.25] * 4)
    assert problem.support_nodes.tolist() == [0]
    np.testing.assert_array_equal(problem.support_positions, [[0.0, 0.0, 0.0]])
    assert problem.gravity == 1.0
    (sphere,) = problem.obstacles
    assert isinstance(sphere, Sphere) and sphere.center == (0.5, 0.5, -0.45) and sphere.radius == 0.3


def test_chain_file_in_3d(tmp_path: Path) -> None:
    text = (
        "dimension = 3\n[chain]\nnodes = 5\nlength = 2.0\nmass = 1.0\n"
        "[[supports]]\nnode = 0\nposition = [0.0, 0.0, 0.0]\n[[supports]]\nnode = -1\nposition = [1.0, 0.5, 0.0]\n"
    )
    problem = load_scenario(_write(tmp_path, text))
    assert problem.is_chain and problem.dimension == 3
    np.testing.assert_array_equal(problem.support_positions, [[0, 0, 0], [1, 0.5, 0]])


@pytest.mark.parametrize(("rows", "columns"), [(2, 2), (3, 5), (20, 20)])
def test_grid_counts_and_lengths(rows: int, columns: int) -> None:
    problem = nets.grid(rows, columns, size=(2.0, 1.0), slack=1.5, supports="edges")
    assert problem.n_nodes == rows * columns
    assert problem.n_links == 2 * rows * columns - rows - columns
    pairs = problem.link_nodes
    across = pairs[:, 1] - pairs[:, 0] == 1
    assert np.count_nonzero(across) == rows * (columns - 1)
    np.testing.assert_allclose(problem.link_lengths[across], 1.5 * 2.0 / (columns - 1))
    np.testing.assert_allclose(problem.link_lengths[~across], 1.5 * 1.0 / (rows - 1))
    assert problem.total_mass == pytest.approx(1.0)
    boundary = [
        r * columns + c for r in range(rows) for c in range(columns) if r in (0, rows - 1) or c in (0, columns - 1)
    ]
    assert problem.support_nodes.tolist() == boundary
    r, c = np.divmod(problem.support_nodes, columns)
    expected = np.column_stack([2.0 * c / (columns - 1), 1.0 * r / (rows - 1), np.zeros(r.size)])
    np.testing.assert_allclose(problem.support_positions, expected)


def test_grid_corners_and_link_length() -> None:
    problem = nets.grid(4, 6, link_length=0.5)
    assert problem.support_nodes.tolist() == [0, 5, 18, 23]
    np.testing.assert_allclose(problem.support_positions, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    np.testing.assert_array_equal(problem.link_lengths, 0.5)


def test_radial_and_disk_counts() -> None:
    rings, spokes = 6, 12
    radial = nets.radial(rings, spokes, radius=2.0, slack=1.1)
    assert radial.n_nodes == 1 + rings * spokes
    assert radial.n_links == 2 * rings * spokes
    assert radial.support_nodes.size == spokes
    np.testing.assert_allclose(np.linalg.norm(radial.support_positions, axis=1), 2.0)
    disk = nets.disk(rings, spokes, slack=1.1)
    assert disk.n_links == 2 * rings * spokes + (rings - 1) * spokes


def test_mesh_reads_the_edges_of_its_faces(tmp_path: Path) -> None:
    # Two triangles sharing an edge: 5 edges, 4 of them on the boundary, every node on it.
    path = _write(tmp_path, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n", "square.obj")
    problem = nets.mesh(path, slack=1.2, supports=[0, 2])
    assert problem.n_links == 5
    np.testing.assert_allclose(sorted(problem.link_lengths), sorted([1.2] * 4 + [1.2 * np.sqrt(2)]))
    assert problem.name == "square"


def test_grid_scenario_file_matches_the_generator(tmp_path: Path) -> None:
    text = 'gravity = 1.0\n[net]\ngrid = [5, 4]\nslack = 1.2\nmass = 2.0\nsupports = "edges"\n'
    problem = load_scenario(_write(tmp_path, text))
    expected = nets.grid(5, 4, slack=1.2, mass=2.0, supports="edges", gravity=1.0)
    assert problem.dimension == 3
    np.testing.assert_array_equal(problem.link_nodes, expected.link_nodes)
    np.testing.assert_array_equal(problem.link_lengths, expected.link_lengths)
    np.testing.assert_array_equal(problem.support_positions, expected.support_positions)


def _free_node_imbalance(solution: Solution) -> float:
    """The largest residual force on a free node: weight + link tensions + contact force."""
    problem = solution.problem
    d = problem.dimension
    positions = solution.positions
    pairs = problem.link_nodes
    delta = positions[pairs[:, 1]] - positions[pairs[:, 0]]
    direction = delta / np.linalg.norm(delta, axis=1)[:, None]
    pull = solution.link_tension[:, None] * direction  # on node i towards j, on j towards i
    force = np.zeros_like(positions)
    np.add.at(force, pairs[:, 0], pull)
    np.add.at(force, pairs[:, 1], -pull)
    force[:, d - 1] -= problem.gravity * problem.masses
    force += solution.contact_forces
    return float(np.abs(force[problem.free_nodes]).max())


@pytest.mark.parametrize("name", NEW_BUILTINS)
def test_new_builtins_solve_and_balance(name: str) -> None:
    problem = load_scenario(name)
    solution = funicular.solve(problem)
    assert solution.status.value == "optimal"
    weight = problem.gravity * problem.total_mass
    assert _free_node_imbalance(solution) < 1e-8 * weight
    vertical = solution.support_reactions[:, -1].sum() + solution.contact_forces[:, -1].sum()
    assert vertical == pytest.approx(weight, rel=1e-8)
    horizontal = solution.support_reactions.sum(axis=0) + solution.contact_forces.sum(axis=0)
    np.testing.assert_allclose(horizontal[:-1], 0.0, atol=1e-8 * weight)
    if problem.obstacles:
        assert np.count_nonzero(np.linalg.norm(solution.contact_forces, axis=1)) > 0


def test_chain_around_post_leaves_its_plane() -> None:
    solution = funicular.solve(load_scenario("chain-around-post"))
    assert load_scenario("chain-around-post").support_positions[:, 1].tolist() == [0.0, 0.0]
    assert solution.y.min() < -0.01  # pushed away from the post, which stands at y > 0


@pytest.mark.parametrize("name", ["net-over-sphere", "hanging-model"])
def test_symmetric_net_corner_reactions_are_equal(name: str) -> None:
    problem = load_scenario(name)
    solution = funicular.solve(problem)
    corners = [0, 14, 210, 224] if name == "hanging-model" else [0, 19, 380, 399]
    index = [problem.support_nodes.tolist().index(node) for node in corners]
    reactions = solution.support_reactions[index]
    magnitude = np.linalg.norm(reactions, axis=1)
    np.testing.assert_allclose(magnitude, magnitude[0], rtol=1e-8, atol=1e-12 * problem.weight)
    # The mirror images agree component by component: the x of two corners across x = 0.5 are opposite.
    np.testing.assert_allclose(reactions[:, -1], reactions[0, -1], rtol=1e-8, atol=1e-12 * problem.weight)
    np.testing.assert_allclose(reactions[0, 0], -reactions[1, 0], rtol=1e-8, atol=1e-12 * problem.weight)


def test_net_problem_round_trips_through_its_table() -> None:
    problem = load_scenario("net-over-sphere")
    table = problem_table(problem)
    assert table is not None
    back = problem_from_table(json.loads(json.dumps(table)), "result")
    assert back.dimension == 3
    np.testing.assert_array_equal(back.link_nodes, problem.link_nodes)
    np.testing.assert_array_equal(back.link_lengths, problem.link_lengths)
    np.testing.assert_array_equal(back.support_positions, problem.support_positions)
    assert back.obstacles == problem.obstacles


BAD = {
    "wrong key": ("[net]\ngrid = [3, 3]\nslak = 1.2\n", "net.slak"),
    "2-D shape in 3-D": (
        '[net]\ngrid = [3, 3]\nslack = 1.2\n[[obstacles]]\nshape = "disk"\ncenter = [0, 0]\nradius = 1\n',
        "obstacles[0].shape",
    ),
    "3-D shape in 2-D": (
        "[chain]\nnodes = 3\nlength = 1.0\nmass = 1.0\n[[supports]]\nnode = 0\nposition = [0, 0]\n"
        '[[obstacles]]\nshape = "sphere"\ncenter = [0, 0, 0]\nradius = 1\n',
        "obstacles[0].shape",
    ),
    "link out of range": (
        "dimension = 3\n[net]\nnodes = 3\nmass = 1.0\nlinks = [[0, 1, 1.0], [1, 5, 1.0]]\n"
        "[[supports]]\nnode = 0\nposition = [0, 0, 0]\n",
        "net.links[1]",
    ),
    "node not connected": (
        "dimension = 3\n[net]\nnodes = 4\nmass = 1.0\nlinks = [[0, 1, 1.0], [2, 3, 1.0]]\n"
        "[[supports]]\nnode = 0\nposition = [0, 0, 0]\n",
        "net.links",
    ),
    "negative length in a link": (
        "dimension = 3\n[net]\nnodes = 3\nmass = 1.0\nlinks = [[0, 1, 1.0], [1, 2, -1.0]]\n"
        "[[supports]]\nnode = 0\nposition = [0, 0, 0]\n",
        "net.links: link 1",
    ),
    "zero length for every link": (
        "dimension = 3\n[net]\nnodes = 3\nmass = 1.0\nlinks = [[0, 1], [1, 2]]\nlink_length = 0.0\n"
        "[[supports]]\nnode = 0\nposition = [0, 0, 0]\n",
        "net.link_length",
    ),
    "grid of one row": ("[net]\ngrid = [1, 5]\nslack = 1.2\n", "net.grid"),
    "unknown supports": ('[net]\ngrid = [3, 3]\nslack = 1.2\nsupports = "middle"\n', "net.supports"),
    "grid in 2-D": ("dimension = 2\n[net]\ngrid = [3, 3]\nslack = 1.2\n", "dimension"),
    "no length": ("[net]\ngrid = [3, 3]\n", "net.slack"),
    "links on a 2-D chain": (
        'dimension = 3\ncontact = "links"\n[chain]\nnodes = 3\nlength = 1.0\nmass = 1.0\n'
        "[[supports]]\nnode = 0\nposition = [0, 0, 0]\n",
        "contact",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_names_the_key(case: str, tmp_path: Path) -> None:
    text, key = BAD[case]
    path = _write(tmp_path, text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key}"), message
    assert "\n" not in message and message.endswith(".")


@pytest.mark.parametrize("case", ["wrong key", "2-D shape in 3-D", "unknown supports"])
def test_bad_input_exits_2_without_traceback(case: str, tmp_path: Path) -> None:
    path = _write(tmp_path, BAD[case][0])
    run = subprocess.run(
        [sys.executable, "-m", "funicular", "solve", str(path)], capture_output=True, text=True, check=False
    )
    assert run.returncode == 2
    assert "Traceback" not in run.stderr and BAD[case][1] in run.stderr


def test_generator_errors_name_their_argument() -> None:
    with pytest.raises(ScenarioError, match=r"^rows = 1"):
        nets.grid(1, 4, slack=1.1)
    with pytest.raises(ScenarioError, match=r"^supports = 'middle'"):
        nets.grid(3, 3, slack=1.1, supports="middle")
    with pytest.raises(ScenarioError, match=r"^slack"):
        nets.grid(3, 3)


def test_solve_writes_a_net_json(tmp_path: Path) -> None:
    out = tmp_path / "out.json"
    run = subprocess.run(
        [sys.executable, "-m", "funicular", "solve", "net-over-sphere", "--json", str(out)],
        capture_output=True,
        text=True,
        check=False,
        cwd=tmp_path,
    )
    assert run.returncode == 0, run.stderr
    assert "760 links" in run.stdout + run.stderr
    document = json.loads(out.read_text())
    assert document["dimension"] == 3
    positions = np.asarray(document["positions"])
    assert positions.shape == (400, 3)
    assert len(document["links"]) == 760
    np.testing.assert_array_equal(document["z"], positions[:, 2])
    back = problem_from_table(document["problem"], str(out))
    assert back.dimension == 3 and back.n_links == 760


def test_scenarios_lists_the_new_builtins() -> None:
    run = subprocess.run([sys.executable, "-m", "funicular", "scenarios"], capture_output=True, text=True, check=True)
    for name in NEW_BUILTINS:
        assert name in run.stdout


def test_parse_scenario_document_with_net() -> None:
    problem = parse_scenario({"net": {"radial": {"rings": 2, "spokes": 6}, "slack": 1.1}})
    assert problem.n_nodes == 13 and problem.support_nodes.size == 6


def test_plot_of_a_3d_net(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    out = tmp_path / "net.png"
    run = subprocess.run(
        [sys.executable, "-m", "funicular", "solve", "hanging-model", "--plot", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    assert out.read_bytes().startswith(b"\x89PNG")


@pytest.mark.parametrize(("rows", "columns"), [(2, 2), (3, 7), (20, 20)])
def test_grid_nodes_counts_the_grids_nodes(rows: int, columns: int) -> None:
    problem = nets.grid(rows, columns, slack=1.2)
    assert nets.grid_nodes(rows, columns) == problem.n_nodes == len(np.unique(problem.link_nodes))


@pytest.mark.parametrize(("rings", "spokes"), [(1, 3), (3, 8)])
def test_radial_nodes_counts_the_radial_and_disk_nets_nodes(rings: int, spokes: int) -> None:
    for make in (nets.radial, nets.disk):
        problem = make(rings, spokes, slack=1.2)
        assert nets.radial_nodes(rings, spokes) == problem.n_nodes == len(np.unique(problem.link_nodes))
