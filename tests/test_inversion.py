"""``funicular invert`` and :mod:`funicular.inversion`: the mirror geometry, the sign of the link forces,
the balance of the inverted form recomputed here from its own geometry, the OBJ and CSV read back,
and bad input refused before solving."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from funicular import load_scenario, solve
from funicular.cli import main
from funicular.errors import ScenarioError
from funicular.inversion import Inverted, check_obj_path, invert, write_obj
from funicular.model import FloatArray, Problem
from funicular.nets import grid
from funicular.solution import Solution


@pytest.fixture(scope="module")
def raised_net() -> Solution:
    """A 6 x 5 grid net hung from its corners set at four different heights (mean 0.25)."""
    net = grid(6, 5, slack=1.15, mass=2.0, gravity=9.81, supports="corners")
    heights = np.array([0.1, 0.3, 0.2, 0.4])
    supports = net.support_positions.copy()
    supports[:, 2] = heights
    solution = solve(replace(net, support_positions=supports))
    assert solution.converged
    return solution


def unit_pushes(inverted: Inverted) -> FloatArray:
    """The force every link exerts on its nodes, ``N_k u_ij`` summed at each node (N, d), from the
    inverted positions and axial forces alone."""
    p = inverted.positions
    total = np.zeros_like(p)
    for (i, j), force in zip(inverted.links, inverted.axial_force, strict=True):
        u = (p[j] - p[i]) / np.linalg.norm(p[j] - p[i])
        total[i] += force * u
        total[j] -= force * u
    return total


def own_weight(problem: Problem) -> FloatArray:
    weight = np.zeros((problem.n_nodes, problem.dimension))
    weight[:, -1] = -problem.gravity * problem.masses
    return weight


def test_positions_are_mirrored_exactly_in_the_supports_mean_height(raised_net: Solution) -> None:
    inverted = invert(raised_net)
    assert inverted.mirror_height == pytest.approx(0.25, abs=1e-15)
    z0 = inverted.mirror_height
    np.testing.assert_array_equal(inverted.positions[:, :2], raised_net.positions[:, :2])
    np.testing.assert_array_equal(inverted.positions[:, 2], 2 * z0 - raised_net.positions[:, 2])
    # Hung below its supports, the net stands above them once inverted.
    free = np.setdiff1d(np.arange(raised_net.problem.n_nodes), raised_net.problem.support_nodes)
    assert np.all(inverted.positions[free, 2] > z0)


def test_link_forces_are_the_tensions_as_compressions(raised_net: Solution) -> None:
    inverted = invert(raised_net)
    np.testing.assert_array_equal(inverted.axial_force, -raised_net.link_tension)
    assert np.all(inverted.axial_force <= 0) and inverted.axial_force.min() < 0
    # Mirroring keeps every link's length.
    ends = raised_net.positions[raised_net.problem.link_nodes]
    np.testing.assert_allclose(inverted.link_lengths, np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1), rtol=1e-14)


def test_the_inverted_form_carries_its_weight_in_compression(raised_net: Solution) -> None:
    """The convention of the module: the weight still acts downwards; at a free node the
    compressions balance it, at a support the reaction closes the balance."""
    problem = raised_net.problem
    inverted = invert(raised_net)
    weight = own_weight(problem)
    scale = problem.weight
    residual = unit_pushes(inverted) + weight
    free = np.setdiff1d(np.arange(problem.n_nodes), problem.support_nodes)
    np.testing.assert_allclose(residual[free], 0.0, atol=1e-8 * scale)
    np.testing.assert_allclose(residual[problem.support_nodes] + inverted.support_reactions, 0.0, atol=1e-8 * scale)
    np.testing.assert_array_equal(inverted.loads, weight)  # no obstacle: the loads are the weight alone
    # The supports carry the whole weight, pushed down into them (and outwards, the thrust).
    forces = inverted.support_forces
    assert np.all(forces[:, 2] < 0)
    assert forces[:, 2].sum() == pytest.approx(-scale, rel=1e-9)
    np.testing.assert_allclose(forces[:, :2].sum(axis=0), 0.0, atol=1e-9 * scale)
    centre = problem.support_positions[:, :2].mean(axis=0)
    outwards = problem.support_positions[:, :2] - centre
    assert np.all(np.einsum("ij,ij->i", forces[:, :2], outwards) > 0)


def test_read_the_other_way_the_tensions_balance_the_reversed_loads(raised_net: Solution) -> None:
    """The same numbers: tensions T on the mirrored form, weights acting upwards, held by the
    supports' forces (the hung reactions mirrored, pointing down)."""
    problem = raised_net.problem
    inverted = invert(raised_net)
    as_tension = replace(inverted, axial_force=-inverted.axial_force)
    residual = unit_pushes(as_tension) - own_weight(problem)
    residual[problem.support_nodes] += inverted.support_forces
    np.testing.assert_allclose(residual, 0.0, atol=1e-8 * problem.weight)
    mirrored = raised_net.support_reactions * np.array([1.0, 1.0, -1.0])
    np.testing.assert_allclose(inverted.support_forces, mirrored, rtol=1e-15)


def test_contact_forces_become_reversed_loads() -> None:
    solution = solve(load_scenario("net-over-sphere"))
    inverted = invert(solution)
    problem = solution.problem
    contact = solution.contact_forces * np.array([1.0, 1.0, -1.0])
    assert np.abs(contact).max() > 0
    loads = own_weight(problem) - contact
    residual = unit_pushes(inverted) + loads
    residual[problem.support_nodes] += inverted.support_reactions
    np.testing.assert_allclose(residual, 0.0, atol=1e-7 * problem.weight)


def test_a_planar_chain_is_mirrored_in_y() -> None:
    solution = solve(load_scenario("uneven-supports"))
    problem = solution.problem
    inverted = invert(solution)
    y0 = float(problem.support_positions[:, 1].mean())
    assert inverted.mirror_height == pytest.approx(y0, rel=1e-15)
    np.testing.assert_array_equal(inverted.positions[:, 0], solution.x)
    np.testing.assert_array_equal(inverted.positions[:, 1], 2 * inverted.mirror_height - solution.y)
    residual = unit_pushes(inverted) + own_weight(problem)
    residual[problem.support_nodes] += inverted.support_reactions
    np.testing.assert_allclose(residual, 0.0, atol=1e-8 * problem.weight)
    assert inverted.faces.shape == (0, 4)


def read_obj(path: Path) -> tuple[FloatArray, list[tuple[int, int]], list[list[int]], dict[int, float]]:
    vertices, lines, faces, forces = [], [], [], {}
    for line in path.read_text(encoding="utf-8").splitlines():
        fields = line.split()
        if not fields:
            continue
        if fields[0] == "v":
            vertices.append([float(value) for value in fields[1:]])
        elif fields[0] == "l":
            lines.append((int(fields[1]) - 1, int(fields[2]) - 1))
        elif fields[0] == "f":
            faces.append([int(value) - 1 for value in fields[1:]])
        elif fields[:2] == ["#", "axial_force"]:
            forces[int(fields[2])] = float(fields[3])
    return np.array(vertices), lines, faces, forces


def test_the_obj_and_the_csv_read_back(raised_net: Solution, tmp_path: Path) -> None:
    inverted = invert(raised_net)
    path = tmp_path / "shell.obj"
    csv_path = write_obj(inverted, path)
    assert csv_path == tmp_path / "shell.csv"
    vertices, lines, faces, forces = read_obj(path)
    problem = raised_net.problem
    assert vertices.shape == (problem.n_nodes, 3) and len(lines) == problem.n_links
    np.testing.assert_allclose(vertices, inverted.positions, rtol=0, atol=1e-12)
    assert lines == [tuple(map(int, pair)) for pair in problem.link_nodes]
    assert forces == {k: pytest.approx(float(f), abs=1e-15) for k, f in enumerate(inverted.axial_force)}
    # A 6 x 5 grid has 5 x 4 cells, each bounded by four of its links.
    assert len(faces) == 5 * 4
    edges = {frozenset(pair) for pair in lines}
    for face in faces:
        assert all(frozenset((a, b)) in edges for a, b in zip(face, face[1:] + face[:1], strict=True))
    with csv_path.open(newline="", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert list(rows[0]) == ["link", "node_i", "node_j", "length", "axial_force"]
    assert [int(row["link"]) for row in rows] == list(range(problem.n_links))
    for row, (i, j) in zip(rows, lines, strict=True):
        assert (int(row["node_i"]), int(row["node_j"])) == (i, j)
        assert float(row["length"]) == pytest.approx(float(np.linalg.norm(vertices[j] - vertices[i])), abs=1e-12)
        assert float(row["axial_force"]) == forces[int(row["link"])]


def test_a_planar_chain_is_written_z_up_in_the_plane_y_0(tmp_path: Path) -> None:
    inverted = invert(solve(load_scenario("two-supports")))
    write_obj(inverted, tmp_path / "arch.obj")
    vertices, lines, faces, _ = read_obj(tmp_path / "arch.obj")
    np.testing.assert_allclose(vertices[:, 0], inverted.positions[:, 0], atol=1e-12)
    np.testing.assert_array_equal(vertices[:, 1], 0.0)
    np.testing.assert_allclose(vertices[:, 2], inverted.positions[:, 1], atol=1e-12)
    assert len(lines) == inverted.links.shape[0] and faces == []


def test_scaling_multiplies_the_coordinates_and_keeps_the_forces(raised_net: Solution) -> None:
    inverted = invert(raised_net)
    scaled = inverted.scaled(100.0)
    np.testing.assert_allclose(scaled.positions, 100.0 * inverted.positions, rtol=1e-15)
    np.testing.assert_array_equal(scaled.axial_force, inverted.axial_force)
    assert scaled.mirror_height == pytest.approx(25.0)
    with pytest.raises(ScenarioError, match="scale"):
        inverted.scaled(-1.0)


def test_the_command_writes_the_hanging_model_inverted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x.obj"
    assert main(["invert", "hanging-model", "--output", str(out)]) == 0
    text = capsys.readouterr().out
    assert "wrote" in text and str(out) in text
    problem = load_scenario("hanging-model")
    vertices, lines, faces, forces = read_obj(out)
    assert vertices.shape == (problem.n_nodes, 3) and len(lines) == problem.n_links
    assert len(faces) == 14 * 14  # the 15 x 15 grid's cells
    # Hung from its edges at z = 0, the inverted form stands above z = 0; no higher than the apex of
    # a middle row 1.1 long spanning 1 pulled into two straight halves, sqrt(0.55^2 - 0.5^2).
    assert vertices[:, 2].min() == 0.0
    assert 0.0 < vertices[:, 2].max() <= math.sqrt(0.55**2 - 0.5**2)
    assert max(forces.values()) <= 0.0
    assert (tmp_path / "x.csv").is_file()


def test_the_scale_option_scales_the_file(tmp_path: Path) -> None:
    plain, scaled = tmp_path / "a.obj", tmp_path / "b.obj"
    assert main(["invert", "chain-around-post", "--output", str(plain)]) == 0
    assert main(["invert", "chain-around-post", "--output", str(scaled), "--scale", "20"]) == 0
    np.testing.assert_allclose(read_obj(scaled)[0], 20.0 * read_obj(plain)[0], rtol=1e-14, atol=1e-13)
    assert read_obj(scaled)[3] == read_obj(plain)[3]


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "funicular.cli", *args], capture_output=True, text=True, check=False, timeout=120
    )


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--output", "{tmp}/shell.stl"], ".obj"),
        (["--output", "{tmp}/missing-dir/shell.obj"], "missing-dir"),
        (["--output", "{tmp}/.."], ".obj"),
        (["--output", "{tmp}/shell.obj", "--scale", "0"], "--scale"),
        (["--output", "{tmp}/shell.obj", "--scale", "nan"], "--scale"),
        (["--output", "{tmp}/shell.obj", "--tol", "-1"], "--tol"),
    ],
)
def test_bad_input_is_one_sentence_exit_2_and_writes_nothing(args: list[str], needle: str, tmp_path: Path) -> None:
    result = run("invert", "hanging-model", *[a.format(tmp=tmp_path) for a in args])
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert "Traceback" not in result.stderr and needle in lines[-1]
    assert list(tmp_path.iterdir()) == []


def test_an_unwritable_companion_csv_is_refused_before_solving(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "shell.csv").mkdir()  # the CSV's name is taken by a directory

    def never(*args: object, **kwargs: object) -> Solution:
        raise AssertionError("solved before the outputs were checked")

    monkeypatch.setattr("funicular.cli.invert.solve", never)
    assert main(["invert", "hanging-model", "--output", str(tmp_path / "shell.obj")]) == 2
    message = capsys.readouterr().err.strip()
    assert len(message.splitlines()) == 1 and "shell.csv" in message and message.endswith(".")
    assert not (tmp_path / "shell.obj").exists()
    with pytest.raises(ScenarioError, match=r"\.obj"):
        check_obj_path(tmp_path / "shell.OBJX")


def test_a_solve_that_does_not_converge_exits_1_and_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "shell.obj"
    out.write_text("previous")
    result = run("invert", "hanging-model", "--output", str(out), "--max-iterations", "2")
    assert result.returncode == 1
    assert "max_iterations" in result.stdout and "did not converge" in result.stdout
    assert out.read_text() == "previous" and not (tmp_path / "shell.csv").exists()


def test_mirror_of_the_mirror_is_the_hung_form(raised_net: Solution) -> None:
    """Inverting twice (by hand: the same mirror again) gives back the hung positions."""
    inverted = invert(raised_net)
    again = inverted.positions.copy()
    again[:, 2] = 2 * inverted.mirror_height - again[:, 2]
    np.testing.assert_allclose(again, raised_net.positions, rtol=0, atol=4 * math.ulp(1.0))
