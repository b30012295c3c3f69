"""What a student asks of the command line and the plots: every multiplier in a table, a warning
where the multipliers are not unique, the checker's multipliers, JSON on standard output, the
version, readable plots, and solutions read back through the public API."""

from __future__ import annotations

import dataclasses
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

import funicular
from funicular import Problem, load_scenario, load_solution, solve
from funicular.backends import Row
from funicular.cli import main
from funicular.cli._common import announce_slow_start
from funicular.cli.compare import disagreement_note
from funicular.plot import CONTACT_FRACTION, draw_solution
from funicular.studies.sweep import Parameter, Sweep, SweepStep, draw_sweep


def dangling(nodes: int = 6) -> Problem:
    """A chain hanging from node 0, total mass 1, g = 1: link k carries the weight below it, (N-1-k)/N."""
    return Problem.build(nodes=nodes, length=1.0, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0))])


def test_table_lists_every_links_multiplier_tension_length_and_state(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = tmp_path / "hang.toml"
    scenario.write_text("[chain]\nnodes = 6\nlength = 1.0\nmass = 1.0\n[[supports]]\nnode = 0\nposition = [0, 0]\n")
    assert main(["solve", str(scenario), "--table"]) == 0  # (the file's g is 9.81)
    rows = [line.split() for line in capsys.readouterr().out.splitlines() if re.match(r"\s+\d+\s+\S+\s+\S+\s+\S", line)]
    links = [row for row in rows if row[-1] in ("taut", "slack")]
    assert [int(row[0]) for row in links] == [0, 1, 2, 3, 4]
    expected = 9.81 * (5 - np.arange(5)) / 6
    np.testing.assert_allclose([float(row[2]) for row in links], expected, rtol=1e-8)  # tension
    np.testing.assert_allclose([float(row[1]) for row in links], expected, rtol=1e-8)  # norm form: mu = T
    np.testing.assert_allclose([float(row[3]) for row in links], 0.2, rtol=1e-8)  # hanging straight: d = l
    assert {row[-1] for row in links} == {"taut"}


def test_solve_says_when_the_multipliers_are_not_unique(capsys: pytest.CaptureFixture[str]) -> None:
    # seed-licq: both links taut along one straight line between the supports, so any tension added
    # to both is carried by the supports alone.
    assert main(["solve", "seed-licq"]) == 0
    assert "NOT unique: LICQ fails (rank 1 of 2" in capsys.readouterr().out
    assert main(["solve", "two-supports"]) == 0
    assert "unique" not in capsys.readouterr().out


def test_compare_says_a_tension_difference_is_a_choice_where_licq_fails() -> None:
    reference = solve(load_scenario("seed-licq"))
    shifted = reference.link_multipliers + 0.25  # the same equilibrium: both links pull 0.25 harder
    other = dataclasses.replace(reference, link_multipliers=shifted)
    rows = [Row("funicular", reference, None, 0.0), Row("other", other, None, 0.0)]
    note = disagreement_note(rows)
    assert note is not None and "not unique" in note and "other" in note
    regular = solve(load_scenario("two-supports"))
    changed = dataclasses.replace(regular, link_multipliers=regular.link_multipliers + 0.25)
    assert disagreement_note([Row("funicular", regular, None, 0.0), Row("other", changed, None, 0.0)]) is None


def test_check_prints_the_multipliers_it_recovered(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = dangling()
    solution = solve(problem)
    point = tmp_path / "point.json"
    point.write_text(json.dumps({"x": solution.x.tolist(), "y": solution.y.tolist()}))  # positions only
    scenario = tmp_path / "hang.toml"
    scenario.write_text(
        "gravity = 1.0\n[chain]\nnodes = 6\nlength = 1.0\nmass = 1.0\n[[supports]]\nnode = 0\nposition = [0, 0]\n"
    )
    assert main(["check", str(scenario), "--solution", str(point)]) == 0
    out = capsys.readouterr().out
    assert "multipliers       recovered" in out
    listed = re.search(r"link mu_k\s+\[([^\]]*)\]", out)
    assert listed is not None
    np.testing.assert_allclose([float(v) for v in listed.group(1).split(",")], (5 - np.arange(5)) / 6, rtol=1e-5)


def test_version() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "funicular", "--version"], capture_output=True, text=True, check=False, timeout=60
    )
    import tomllib

    version = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]["version"]
    assert result.returncode == 0 and result.stdout.strip() == f"funicular {version}"


def test_a_solution_file_reads_back_with_its_problem(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    assert main(["solve", "disk-drape", "--json", str(out)]) == 0
    original = solve(load_scenario("disk-drape"))
    again = load_solution(out)
    assert again.problem.n_nodes == original.problem.n_nodes and again.problem.obstacles == original.problem.obstacles
    np.testing.assert_array_equal(again.positions, original.positions)
    np.testing.assert_allclose(again.support_reactions, original.support_reactions, atol=1e-12)
    assert again.converged


def test_a_solution_file_without_its_problem_is_named(tmp_path: Path) -> None:
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"x": [0.0, 1.0], "y": [0.0, 0.0]}))
    with pytest.raises(funicular.ScenarioError, match=r"old\.json: problem is missing"):
        load_solution(old)


def test_import_funicular_loads_no_numerical_library() -> None:
    code = "import sys, funicular; print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'scipy')))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    assert result.stdout.strip() == "[]"
    assert set(funicular.__all__) <= set(dir(funicular))
    assert all(getattr(funicular, name) is not None for name in funicular.__all__)


def test_a_slow_first_import_is_announced(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr("importlib.util.find_spec", lambda name: object())  # as if CasADi were installed
    monkeypatch.delitem(sys.modules, "casadi", raising=False)
    announce_slow_start(["funicular", "ipopt"])
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "casadi" in lines[0] and "ipopt" in lines[0]


# ----------------------------------------------------------------- plots
def test_contact_forces_are_labelled_and_visible_on_flat_ground() -> None:
    solution = solve(load_scenario("ground"))
    ax = draw_solution(solution, Figure().add_subplot())
    labels = ax.get_legend_handles_labels()[1]
    assert "support reactions" in labels and any(label.startswith("contact forces") for label in labels)
    # The largest contact arrow is CONTACT_FRACTION of the chain's extent, however small the force.
    extent = max(np.ptp(solution.x), np.ptp(solution.y))
    arrows = [q for q in ax.collections if getattr(q, "U", None) is not None and q.get_label().startswith("contact")]
    assert float(np.hypot(arrows[0].U, arrows[0].V).max()) == pytest.approx(CONTACT_FRACTION * extent)


def test_obstacles_reach_the_edges_and_a_disk_is_whole() -> None:
    for name in ("ground", "disk-drape"):
        solution = solve(load_scenario(name))
        figure = Figure()
        ax = draw_solution(solution, figure.add_subplot())
        figure.canvas.draw()
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        fills = [patch.get_path().vertices for patch in ax.patches]
        low, high = np.min([f.min(axis=0) for f in fills], axis=0), np.max([f.max(axis=0) for f in fills], axis=0)
        if name == "ground":  # a half-plane: filled past both sides and the bottom of the view
            assert low[0] <= x0 and high[0] >= x1 and low[1] <= y0
        else:  # the disk (centre (0.5, -0.55), radius 0.25) lies wholly in the view
            assert x0 <= 0.25 and x1 >= 0.75 and y0 <= -0.8 and y1 >= -0.3


def test_steps_not_solved_are_marked_apart_from_the_data() -> None:
    row = [
        SweepStep(values=(1.0,), status="optimal", energy=1.0, max_tension=2.0, taut_links=3),
        SweepStep(values=(2.0,), status="max_iterations", energy=50.0, max_tension=90.0, taut_links=3),
        SweepStep(values=(3.0,), status="optimal", energy=1.5, max_tension=2.5, taut_links=3),
    ]
    result = Sweep("chain", [Parameter("chain.length", ("chain", "length"), (1.0, 2.0, 3.0))], [row])
    figure = Figure()
    draw_sweep(result, figure)
    top = figure.axes[0]
    data, *others = top.get_lines()
    assert np.isnan(data.get_ydata()[1])  # the unsolved step's energy (50) is not drawn as data
    marks = [line for line in others if line.get_label() == "not solved"]
    assert len(marks) == 1 and list(marks[0].get_xdata()) == [2.0]
    assert marks[0].get_transform() == top.get_xaxis_transform()  # on a strip in axes units, not at a value
