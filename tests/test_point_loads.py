"""Point loads: forces applied to nodes beside their weights, on chains and nets, in 2-D and 3-D.

The expected numbers come from statics worked out here (a node hung by two or three taut links,
whose position the link lengths fix), from another formulation of the same problem (a vertical
point load is an extra mass), or from force balance recomputed from the returned point."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import funicular
from funicular import Problem, ScenarioError
from funicular.checks import load_solution
from funicular.checks._files import write_solution
from funicular.inversion import invert
from funicular.obstacles import Sphere
from funicular.scenario import load_scenario, parse_scenario, scenario_toml

pytestmark = pytest.mark.filterwarnings("error")


def pulls(positions: np.ndarray, links: np.ndarray, force: np.ndarray) -> np.ndarray:
    """The links' forces on every node: link k pulls its nodes towards each other with ``force[k]``
    (a negative force, a compression, pushes them apart)."""
    delta = positions[links[:, 1]] - positions[links[:, 0]]
    pull = force[:, None] * delta / np.linalg.norm(delta, axis=1)[:, None]
    forces = np.zeros_like(positions)
    np.add.at(forces, links[:, 0], pull)
    np.add.at(forces, links[:, 1], -pull)
    return forces


def link_pull(solution: funicular.Solution) -> np.ndarray:
    """The links' forces on every node, recomputed from the positions and the tensions."""
    return pulls(solution.positions, solution.problem.link_nodes, solution.link_tension)


def loads_of(problem: Problem) -> np.ndarray:
    """Weight along the last axis plus the point loads, written out here."""
    forces = np.zeros((problem.n_nodes, problem.dimension))
    forces[:, -1] = -problem.gravity * problem.masses
    if problem.loads is not None:
        forces += problem.loads
    return forces


def two_strings(sideways: float) -> Problem:
    """Supports (0, 0) and (2, 0), links sqrt(2), weight 1 at the middle node, pushed right by
    ``sideways``: the node sits at (1, -1), the links at 45 degrees, and
    T1 (-1, 1)/sqrt2 + T2 (1, 1)/sqrt2 + (H, -1) = 0 gives T1 = (1 + H)/sqrt2, T2 = (1 - H)/sqrt2."""
    return Problem.build(
        nodes=3,
        supports=[(0, (0.0, 0.0)), (2, (2.0, 0.0))],
        link_length=math.sqrt(2.0),
        masses=[0.0, 1.0, 0.0],
        gravity=1.0,
        loads=[(1, (sideways, 0.0))],
    )


def test_a_node_hung_by_two_links_takes_a_sideways_load_by_statics() -> None:
    h = 0.3
    problem = two_strings(h)
    solution = funicular.solve(problem)
    assert solution.status.value == "optimal"
    np.testing.assert_allclose(solution.positions[1], [1.0, -1.0], atol=1e-9)
    t1, t2 = (1.0 + h) / math.sqrt(2.0), (1.0 - h) / math.sqrt(2.0)
    np.testing.assert_allclose(solution.link_tension, [t1, t2], rtol=1e-8)
    # Each support pulls its link's end back: R = -T u (u from the support to the node).
    np.testing.assert_allclose(
        solution.support_reactions,
        [[-t1 / math.sqrt(2), t1 / math.sqrt(2)], [t2 / math.sqrt(2), t2 / math.sqrt(2)]],
        rtol=1e-8,
    )


def test_a_node_hung_by_three_links_in_space_takes_a_load_by_statics() -> None:
    """Three supports on a circle of radius 1 at z = 0, links sqrt(2): the node sits at (0, 0, -1).
    The tensions solve the 3 x 3 balance U T = -(P + W), U's columns the unit vectors to the supports."""
    angles = np.array([0.0, 2.0, 4.0]) * math.pi / 3.0
    anchors = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(3)])
    load = np.array([0.2, -0.1, -0.4])
    problem = Problem.build(
        nodes=4,
        links=[[0, 3, math.sqrt(2.0)], [1, 3, math.sqrt(2.0)], [2, 3, math.sqrt(2.0)]],
        supports=[(k, tuple(anchors[k])) for k in range(3)],
        masses=[0.0, 0.0, 0.0, 1.0],
        gravity=1.0,
        dimension=3,
        loads=[(3, tuple(load))],
    )
    solution = funicular.solve(problem)
    node = np.array([0.0, 0.0, -1.0])
    np.testing.assert_allclose(solution.positions[3], node, atol=1e-9)
    units = (anchors - node) / math.sqrt(2.0)
    weight = np.array([0.0, 0.0, -1.0])
    tensions = np.linalg.solve(units.T, -(load + weight))
    assert np.all(tensions > 0)
    np.testing.assert_allclose(solution.link_tension, tensions, rtol=1e-8)


def test_a_downward_point_load_is_an_extra_mass() -> None:
    """A load (0, -P) at node k equals the mass m_k + P / g there: the same chain solved as a chain
    (the chain's own solver) and, with the point load, as a net."""
    nodes, k, extra = 21, 7, 0.4
    supports = [(0, (0.0, 0.0)), (nodes - 1, (1.0, 0.2))]
    masses = np.full(nodes, 1.0 / nodes)
    loaded = Problem.build(
        nodes=nodes, supports=supports, length=1.6, masses=masses, gravity=9.81, loads=[(k, (0.0, -extra))]
    )
    heavier = masses.copy()
    heavier[k] += extra / 9.81
    plain = Problem.build(nodes=nodes, supports=supports, length=1.6, masses=heavier, gravity=9.81)
    assert plain.is_chain and not loaded.is_chain
    a, b = funicular.solve(loaded), funicular.solve(plain)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-7)
    np.testing.assert_allclose(a.link_tension, b.link_tension, rtol=1e-6)
    np.testing.assert_allclose(a.support_reactions, b.support_reactions, rtol=1e-6)


def grid_with_loads(sphere: bool) -> Problem:
    rng = np.random.default_rng(7)
    n = 9
    idx = np.arange(n * n).reshape(n, n)
    pairs = np.concatenate(
        [np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1), np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)]
    )
    h = 1.0 / (n - 1)
    links = np.column_stack([pairs, np.full(len(pairs), 1.25 * h)]).tolist()
    corners = [(int(idx[0, 0]), (0.0, 0.0, 0.0)), (int(idx[0, -1]), (1.0, 0.0, 0.0))]
    corners += [(int(idx[-1, 0]), (0.0, 1.0, 0.0)), (int(idx[-1, -1]), (1.0, 1.0, 0.0))]
    nodes = rng.choice(np.setdiff1d(np.arange(n * n), [c for c, _ in corners]), size=6, replace=False)
    down = np.array([0.0, 0.0, -0.05])
    loads = [(int(i), tuple(rng.uniform(-0.05, 0.05, 3) + down)) for i in nodes]
    obstacles = [Sphere(center=(0.5, 0.5, -0.6), radius=0.3)] if sphere else []
    return Problem.build(
        nodes=n * n, links=links, supports=corners, mass=1.0, gravity=1.0, dimension=3, obstacles=obstacles, loads=loads
    )


@pytest.mark.parametrize("sphere", [False, True], ids=["free", "over-a-sphere"])
def test_every_free_node_balances_its_point_load(sphere: bool) -> None:
    problem = grid_with_loads(sphere)
    solution = funicular.solve(problem)
    assert solution.status.value == "optimal"
    total = link_pull(solution) + loads_of(problem) + solution.contact_forces
    free = problem.free_nodes
    np.testing.assert_allclose(total[free], 0.0, atol=1e-7)
    # The supports carry what the free nodes do not: every load, less what the obstacle holds.
    np.testing.assert_allclose(
        solution.support_reactions.sum(axis=0) + loads_of(problem).sum(axis=0) + solution.contact_forces.sum(axis=0),
        0.0,
        atol=1e-7,
    )
    energy = problem.gravity * problem.masses @ solution.positions[:, 2] - np.sum(problem.loads * solution.positions)
    assert solution.objective == pytest.approx(energy, rel=1e-12, abs=1e-14)


def test_the_inverted_form_balances_the_mirrored_point_loads() -> None:
    problem = grid_with_loads(False)
    inverted = invert(funicular.solve(problem))
    forces = pulls(inverted.positions, problem.link_nodes, inverted.axial_force)
    mirror = np.array([1.0, 1.0, -1.0])
    expected_loads = np.zeros_like(forces)
    expected_loads[:, 2] = -problem.gravity * problem.masses
    expected_loads -= problem.loads * mirror
    np.testing.assert_allclose(inverted.loads, expected_loads, rtol=1e-15)
    np.testing.assert_allclose((forces + inverted.loads)[problem.free_nodes], 0.0, atol=1e-7)


LOADED = """
name = "loaded"
dimension = 3
gravity = 1.0

[net]
grid = [6, 6]
mass = 1.0
slack = 1.2
supports = "corners"

[[loads]]
node = 14
force = [0.1, 0.0, -0.3]

[[loads]]
node = 14
force = [0.0, 0.1, 0.0]
"""


def test_a_scenario_lists_its_point_loads_and_they_survive_every_file(tmp_path: Path) -> None:
    path = tmp_path / "loaded.toml"
    path.write_text(LOADED)
    problem = load_scenario(path)
    assert problem.loads is not None
    np.testing.assert_array_equal(problem.loads[14], [0.1, 0.1, -0.3])  # a node named twice: the sum
    assert np.count_nonzero(problem.loads.any(axis=1)) == 1
    again = tmp_path / "again.toml"
    again.write_text(scenario_toml(problem) or "")
    np.testing.assert_array_equal(load_scenario(again).loads, problem.loads)
    solution = funicular.solve(problem)
    for suffix in (".json", ".npz", ".parquet"):
        written = tmp_path / f"result{suffix}"
        write_solution(solution, written)
        read = load_solution(written)
        np.testing.assert_array_equal(read.problem.loads, problem.loads)
        assert read.objective == solution.objective


@pytest.mark.parametrize(
    ("loads", "words"),
    [
        ([{"node": 99, "force": [0.0, 0.0, 1.0]}], "loads[0].node = 99 is not a node"),
        ([{"node": 3, "force": [0.0, 1.0]}], "loads[0].force must be a list of 3 numbers"),
        ([{"node": 3, "force": [0.0, 0.0, "up"]}], "loads[0].force[2]"),
        ([{"node": 3, "forces": [0.0, 0.0, 1.0]}], "loads[0].forces is not a known key"),
        ({"node": 3}, "loads must be an array of tables"),
    ],
)
def test_bad_point_loads_get_one_sentence(loads: object, words: str) -> None:
    document = {"dimension": 3, "net": {"grid": [4, 4], "mass": 1.0, "slack": 1.2}, "loads": loads}
    with pytest.raises(ScenarioError, match=words.replace("[", r"\[").replace("]", r"\]").replace(".", r"\.")):
        parse_scenario(document, "net.toml")


def test_the_command_line_names_a_bad_point_load_and_exits_2(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(LOADED.replace("node = 14", "node = 40", 1))
    result = subprocess.run(
        [sys.executable, "-m", "funicular", "solve", str(path)], capture_output=True, text=True, check=False
    )
    assert result.returncode == 2
    assert "loads[0].node = 40 is not a node" in result.stderr and "Traceback" not in result.stderr


def test_refining_a_chain_with_point_loads_is_refused() -> None:
    problem = Problem.build(
        nodes=5, supports=[(0, (0.0, 0.0)), (4, (1.0, 0.0))], length=1.2, mass=1.0, loads=[(2, (0.1, 0.0))]
    )
    with pytest.raises(ScenarioError, match="without point loads"):
        problem.with_nodes(9)
    # Loads that are all zero are no loads: the chain stays a chain.
    assert Problem.build(
        nodes=5, supports=[(0, (0.0, 0.0)), (4, (1.0, 0.0))], length=1.2, mass=1.0, loads=[(2, (0.0, 0.0))]
    ).is_chain


def test_the_summary_counts_the_point_loads_and_names_the_energy(tmp_path: Path) -> None:
    path = tmp_path / "loaded.toml"
    path.write_text(LOADED)
    result = subprocess.run(
        [sys.executable, "-m", "funicular", "solve", str(path)], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    assert "36 nodes, 60 links, 3-D, 1 point load," in result.stdout
    assert "(g m^T z - P . p)" in result.stdout


BALANCED = {
    # the user's net: weight 2 * 9.81 = 19.62 and a 5 N load pressing down on its middle
    "net": """
gravity = 9.81
[net]
grid = [5, 5]
mass = 2.0
slack = 1.2
[[loads]]
node = 12
force = [0.0, 0.0, -5.0]
""",
    # a chain pushed sideways and down onto the ground (a node on it, the load's node too)
    "chain on the ground": """
gravity = 1.0
[chain]
nodes = 21
length = 3.0
mass = 1.0
[[supports]]
node = 0
position = [0.0, 1.0]
[[supports]]
node = -1
position = [2.0, 1.0]
[[loads]]
node = 10
force = [0.5, -3.0]
[[obstacles]]
shape = "halfplane"
name = "ground"
point = [0.0, 0.0]
normal = [0.0, 1.0]
""",
    # a net over a sphere, pulled sideways at one node and up at another
    "net over a sphere": """
gravity = 1.0
[net]
grid = [8, 8]
mass = 1.0
slack = 1.3
[[loads]]
node = 27
force = [0.4, -0.2, 0.0]
[[loads]]
node = 0
force = [0.0, 0.0, 0.7]
[[obstacles]]
shape = "sphere"
name = "ball"
center = [0.5, 0.5, -0.45]
radius = 0.3
""",
}
NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?"


@pytest.mark.parametrize("case", BALANCED, ids=list(BALANCED))
def test_the_support_reactions_total_names_the_weight_loads_and_contacts_that_add_up_to_it(
    tmp_path: Path, case: str
) -> None:
    """The total of the support reactions says what it balances, and the parts printed add up to
    it component by component: the weight held up, minus the point loads' sum, minus the contact
    forces' sum (a 5 N load on a net of weight 19.62 makes the total 24.62). The loads' sum is
    also checked against the scenario, and the contact forces' against the summary's own line."""
    import re

    path = tmp_path / "balanced.toml"
    path.write_text(BALANCED[case])
    result = subprocess.run(
        [sys.executable, "-m", "funicular", "solve", str(path)], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    line = next(line for line in result.stdout.splitlines() if line.lstrip().startswith("total "))
    total = np.array([float(v) for v in re.findall(rf"F[xyz] = +({NUMBER})", line)])
    weight = float(re.search(rf"\(weight ({NUMBER}) held up", line)[1])  # type: ignore[index]
    loads = np.array([float(v) for v in re.search(r"minus point loads \(([^)]*)\)", line)[1].split(",")])  # type: ignore[index]
    problem = load_scenario(path)
    assert weight == pytest.approx(problem.weight, rel=1e-10)
    np.testing.assert_allclose(loads, problem.loads.sum(axis=0), rtol=1e-10, atol=1e-12)  # type: ignore[union-attr]
    up = np.zeros(total.size)
    up[-1] = weight
    parts = up - loads
    contacts = re.search(r"minus contact forces \(([^)]*)\)", line)
    if problem.obstacles:
        assert contacts is not None
        contact = np.array([float(v) for v in contacts[1].split(",")])
        touching = next(line for line in result.stdout.splitlines() if "contact forces" in line)
        shown = [float(v) for v in re.findall(rf"F[xyz] = ({NUMBER})", touching)]
        np.testing.assert_allclose(contact, shown, rtol=1e-9, atol=1e-12)
        assert np.abs(contact).max() > 0.05  # (the obstacle carries something)
        parts -= contact
    else:
        assert contacts is None
    np.testing.assert_allclose(total, parts, rtol=1e-9, atol=1e-9 * problem.weight)
    if case == "net":
        assert total[-1] == pytest.approx(24.62, rel=1e-9) and weight == pytest.approx(19.62)


def test_the_check_recovers_the_tensions_a_sideways_load_calls_for() -> None:
    """The two strings, checked from the positions alone: the recovered tensions are the
    hand-computed ones; without the load the same positions balance only with equal tensions."""
    h = 0.3
    positions = np.array([[0.0, 0.0], [1.0, -1.0], [2.0, 0.0]])
    report = funicular.check(two_strings(h), positions)
    assert report.multiplier_source == "recovered" and report.kkt_holds and report.multipliers is not None
    np.testing.assert_allclose(
        report.multipliers.link, [(1.0 + h) / math.sqrt(2.0), (1.0 - h) / math.sqrt(2.0)], rtol=1e-9
    )
    # Two links at right angles fix the node: independent rows, unique forces, nothing left to move.
    assert report.licq is not None and report.licq.holds and report.licq.rank == 2
    assert report.second_order is not None and report.second_order.verdict == "strict local minimum"
    unloaded = funicular.check(two_strings(0.0), positions)
    assert unloaded.multipliers is not None
    np.testing.assert_allclose(unloaded.multipliers.link, [1.0 / math.sqrt(2.0)] * 2, rtol=1e-9)


def test_the_pictures_draw_the_point_loads(tmp_path: Path) -> None:
    """A 2-D and a 3-D problem with point loads are drawn, the loads with a legend entry of their
    own naming the largest (0.3, sqrt(0.1^2 + 0.1^2 + 0.3^2); no units declared, so none named)."""
    figure = pytest.importorskip("matplotlib.figure")
    from funicular.plot import draw_solution, draw_solution_3d

    ax = draw_solution(funicular.solve(two_strings(0.3)))
    assert any(text.get_text() == "point loads (largest 0.3, own scale)" for text in ax.get_legend().get_texts())
    si = draw_solution(funicular.solve(dataclasses.replace(two_strings(0.3), units="SI")))
    assert "point loads (largest 0.3 N, own scale)" in [text.get_text() for text in si.get_legend().get_texts()]
    path = tmp_path / "loaded.toml"
    path.write_text(LOADED)
    axes = draw_solution_3d(funicular.solve(load_scenario(path)), figure.Figure())
    labels = [text.get_text() for text in axes.get_legend().get_texts()]
    assert f"point loads (largest {math.sqrt(0.11):.3g}, own scale)" in labels
