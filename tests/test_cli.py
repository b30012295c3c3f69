"""The command line: summaries, JSON schema, plots, exit statuses and one-sentence errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from funicular import SolverOptions, load_scenario, solve
from funicular.checks import second_order
from funicular.cli import main
from funicular.scenario import builtin_scenarios


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "funicular.cli", *args], capture_output=True, text=True, check=False, timeout=120
    )


def test_solve_prints_summary_and_writes_json_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_json, out_png = tmp_path / "r.json", tmp_path / "r.png"
    assert main(["solve", "dangling", "--json", str(out_json), "--plot", str(out_png)]) == 0
    text = capsys.readouterr().out
    assert "optimal" in text and "support reactions" in text and "KKT residuals" in text
    result = json.loads(out_json.read_text())
    for key in (
        "status", "formulation", "objective", "x", "y", "link_tension", "multipliers",
        "support_reactions", "kkt", "iterations", "solve_seconds",
    ):  # fmt: skip
        assert key in result
    assert set(result["kkt"]) == {"stationarity", "primal_feasibility", "dual_feasibility", "complementarity"}
    assert set(result["multipliers"]) >= {"link", "support"}
    n = len(result["x"])
    assert len(result["y"]) == n and len(result["link_tension"]) == n - 1
    # Dangling chain, total mass 1, g = 1: the single support holds the whole weight, pointing up,
    # and its multiplier is minus that force.
    assert result["support_reactions"] == [{"node": 0, "force": pytest.approx([0.0, 1.0], abs=1e-12)}]
    assert result["multipliers"]["support"][0] == pytest.approx([0.0, -1.0], abs=1e-12)
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_nodes_and_formulation_overrides(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    assert main(["solve", "two-supports", "--nodes", "7", "--formulation", "squared", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["formulation"] == "squared" and len(result["x"]) == 7
    # 2 d_k mu_k is the tension (docs/model.md), independently of how the solver computed it.
    distances = np.hypot(np.diff(result["x"]), np.diff(result["y"]))
    np.testing.assert_allclose(2 * distances * np.array(result["multipliers"]["link"]), result["link_tension"])


def test_scenarios_lists_every_builtin(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenarios"]) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert listed == sorted(builtin_scenarios())
    assert {"dangling", "two-supports", "uneven-supports", "three-supports", "taut"} <= set(listed)


BAD = """
[chain]
nodes = 3
length = 1.0
mass = 1.0
[[supports]]
node = 0
position = [0.0, 0.0]
[[supports]]
node = 2
position = [3.0, 0.0]
"""


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["solve", "no-such-scenario"], "no-such-scenario"),
        (["solve", "{infeasible}"], "nodes 0"),
        (["solve", "dangling", "--plot", "{tmp}/x.gif"], ".png"),
        (["solve", "dangling", "--json", "{tmp}/missing-dir/x.json"], "missing-dir"),
    ],
)
def test_bad_input_is_one_sentence_and_exit_2(args: list[str], needle: str, tmp_path: Path) -> None:
    infeasible = tmp_path / "infeasible.toml"
    infeasible.write_text(BAD)
    args = [a.format(tmp=tmp_path, infeasible=infeasible) for a in args]
    result = run(*args)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("funicular: error:") and needle in lines[0]
    assert not (tmp_path / "x.gif").exists()


def test_infeasible_error_names_distance_and_length(tmp_path: Path) -> None:
    path = tmp_path / "far.toml"
    path.write_text(BAD)
    stderr = run("solve", str(path)).stderr
    assert "nodes 0" in stderr and "and 2" in stderr and "3 apart" in stderr and "only 1 long" in stderr


def test_existing_json_is_kept_when_the_run_fails(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    out.write_text("previous")
    assert run("solve", "no-such-scenario", "--json", str(out)).returncode == 2
    assert out.read_text() == "previous"


def test_non_convergence_exits_1_and_says_so(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(
        BAD.replace("[3.0, 0.0]", "[0.5, 0.0]").replace("nodes = 3", "nodes = 40").replace("node = 2", "node = -1")
        + '[[obstacles]]\nshape = "disk"\ncenter = [0.25, -0.3]\nradius = 0.2\n'
    )
    # Three Newton steps cannot reach 1e-10 from the initial guess (on the disk: a chain touching
    # nothing would start from its exact answer).
    result = run("solve", str(path), "--max-iterations", "3")
    assert result.returncode == 1
    assert "did not converge" in result.stdout


def test_escape_up_to_below_the_chains_nodes_leaves_it_at_its_saddle(capsys: pytest.CaptureFixture[str]) -> None:
    """disk-drape (61 nodes) balances a node on top of its disk: a saddle, which the escape leaves for
    a lower energy; told to escape up to 60 nodes, the solve keeps the saddle, which the checker's
    second-order test finds is not a minimum."""
    energies = []
    for extra in ([], ["--escape-up-to", "60"]):
        assert main(["solve", "disk-drape", *extra]) == 0
        out = capsys.readouterr().out
        energies.append(float(re.search(r"energy\s+(\S+)", out).group(1)))  # type: ignore[union-attr]
    assert energies[0] < energies[1] - 1e-6
    problem = load_scenario("disk-drape")
    assert second_order(problem, solve(problem, SolverOptions(escape_up_to=60))).verdict == "not a minimum"


def test_no_exact_start_lets_the_interior_point_method_work(capsys: pytest.CaptureFixture[str]) -> None:
    """The same chain either way; without the exact start it takes several Newton steps, not one."""
    steps, energies = [], []
    for extra in ([], ["--no-exact-start"]):
        assert main(["solve", "two-supports", *extra]) == 0
        out = capsys.readouterr().out
        steps.append(int(re.search(r"iterations\s+(\d+)", out).group(1)))  # type: ignore[union-attr]
        energies.append(float(re.search(r"energy\s+(\S+)", out).group(1)))  # type: ignore[union-attr]
    assert steps[0] == 1 and steps[1] > 3
    assert abs(energies[0] - energies[1]) <= 1e-9


def test_solve_loads_only_what_it_runs() -> None:
    """``funicular solve`` imports neither the other commands' modules nor their dependencies (the
    checker, the studies, SciPy, matplotlib): a fresh process starts fast."""
    code = (
        "import sys, contextlib, io\n"
        "from funicular.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    assert main(['solve', 'two-supports']) == 0\n"
        "print(' '.join(sorted(sys.modules)))\n"
    )
    loaded = set(
        subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    )
    assert "funicular._solver.front_end" in loaded  # (the check sees the modules)
    for module in (
        "funicular.cli.check",
        "funicular.checks",
        "funicular.studies.sweep",
        "scipy",
        "matplotlib",
    ):
        assert module not in loaded, module


def test_the_largest_tension_of_a_symmetric_chain_is_named_in_its_first_link() -> None:
    """two-supports hangs symmetrically from supports at the same height: its end links carry the
    same tension (equal to rounding), the largest, and the summary names the first of them, link
    0, not link 49 because rounding put 1e-16 more in it. The value printed is the mirror pair's."""
    from funicular import load_scenario, solve

    result = run("solve", "two-supports")
    assert result.returncode == 0, result.stderr
    line = next(line for line in result.stdout.splitlines() if "max tension" in line)
    assert re.search(r"max tension +\S+ in link 0 \(", line), line
    tension = solve(load_scenario("two-supports")).link_tension
    np.testing.assert_allclose(tension, tension[::-1], rtol=1e-12)  # the mirror symmetry
    assert float(line.split()[2]) == pytest.approx(tension.max(), rel=1e-10)
