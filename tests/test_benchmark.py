"""The benchmark (bench/run.py): the table, skipped competitors, profiling phases, bad options. No timing targets."""

from __future__ import annotations

import cProfile
import json
import pstats
from pathlib import Path

import numpy as np
import pytest
from bench import run as benchmark
from bench.run import PHASES, family, phase_seconds

from funicular._solver import SolverOptions, solve
from funicular.checks import check


def test_smoke_table_rows_and_checked_answer(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    markdown, document, plot = tmp_path / "b.md", tmp_path / "b.json", tmp_path / "b.png"
    args = ["--nodes", "5,9", "--problem", "free", "--solvers", "funicular", "--repeats", "2"]
    args += ["--back-to-back", "4"]
    assert benchmark.main([*args, "--markdown", str(markdown), "--json", str(document), "--plot", str(plot)]) == 0
    text = markdown.read_text()
    assert text.strip() in capsys.readouterr().out
    assert "| 5 | free | funicular |" in text and "| 9 | free | funicular |" in text
    assert "cores" in text and "numpy" in text  # the machine is described
    results = json.loads(document.read_text())["results"]
    assert [(r["nodes"], r["solver"], r["runs"]) for r in results] == [(5, "funicular", 2), (9, "funicular", 2)]
    for r in results:  # funicular's answer passes funicular.checks, multipliers recovered from the positions
        assert r["status"] == "optimal" and r["verdict"] == "strict local minimum"
        assert r["kkt"] < 1e-8 and r["energy_difference"] == 0.0
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Then funicular alone, solves in a row (a measurement, no target): every instance up to 100 nodes.
    rows = json.loads(document.read_text())["back_to_back"]
    assert [(r["nodes"], r["problem"], r["solves"]) for r in rows] == [(5, "free", 4), (9, "free", 4)]
    assert all(0 < r["p10"] <= r["median"] <= r["p90"] for r in rows)
    assert "| 5 | free |" in text.split("solves in a row")[1]


def test_missing_competitor_is_skipped_with_a_note(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(benchmark, "REQUIRES", {"ipopt": ("no_such_module_for_funicular_tests",)})
    args = ["--nodes", "5", "--problem", "free", "--solvers", "funicular,ipopt", "--repeats", "1"]
    assert benchmark.main(args) == 0
    out = capsys.readouterr().out
    assert "ipopt: not installed (no_such_module_for_funicular_tests" in out
    assert "| ipopt |" not in out and "| 5 | free | funicular |" in out


def test_slsqp_cap_and_a_failing_competitor_are_notes_not_errors(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def broken(problem: object, tol: float) -> benchmark.Outcome:
        raise RuntimeError("competitor exploded\nsecond line")

    monkeypatch.setitem(benchmark.RUNNERS, "clarabel", broken)
    monkeypatch.setattr(benchmark, "REQUIRES", {})
    monkeypatch.setitem(benchmark.MAX_NODES, "slsqp", 6)
    args = ["--nodes", "5,7", "--problem", "free", "--solvers", "funicular,slsqp,clarabel", "--repeats", "1"]
    assert benchmark.main(args) == 0
    out = capsys.readouterr().out
    assert "| 5 | free | slsqp |" in out and "| 7 | free | slsqp |" not in out
    assert "slsqp: skipped above N = 6" in out
    assert "error: RuntimeError: competitor exploded |" in out and "second line" not in out


def test_profile_on_a_small_chain_produces_phases(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    document = tmp_path / "p.json"
    assert benchmark.main(["--profile", "--nodes", "300", "--json", str(document)]) == 0
    assert "| phase | seconds | share |" in capsys.readouterr().out
    (profile,) = json.loads(document.read_text())["profiles"]
    assert profile["problem"] == "disk" and profile["nodes"] == 300
    assert list(profile["phases"]) == list(PHASES)
    assert sum(profile["phases"].values()) > 0
    assert sum(seconds for phase, seconds in profile["phases"].items() if phase != "other") > 0
    assert profile["top"] and {f["phase"] for f in profile["top"]} <= set(PHASES)


# The profiler's clock in the test below: each _busy() call takes exactly one tick, so the phases'
# shares do not depend on how busy the machine is.
_CLOCK = [0.0]


def _busy() -> int:
    _CLOCK[0] += 1.0
    return 0


def _fake_evaluate() -> int:
    return _busy()


def _fake_line_search() -> int:
    return _fake_evaluate() + _fake_evaluate()


def _mystery_renamed_function() -> int:
    return _busy()


def test_phases_follow_the_outermost_phase_function_and_unknown_names_are_other() -> None:
    profiler = cProfile.Profile(lambda: _CLOCK[0])
    profiler.enable()
    _fake_line_search()
    _fake_evaluate()
    _mystery_renamed_function()
    profiler.disable()
    seconds, split = phase_seconds(pstats.Stats(profiler))
    assert seconds["line search"] > 0 and seconds["assembly/evaluation"] > 0 and seconds["other"] > 0
    assert seconds["polish"] == 0 and seconds["factorization"] == 0
    # _fake_evaluate ran twice inside the line search and once on its own.
    shares = next(s for f, s in split.items() if f[2] == "_fake_evaluate")
    assert shares["line search"] == pytest.approx(2 / 3)
    assert shares["assembly/evaluation"] == pytest.approx(1 / 3)
    assert next(s for f, s in split.items() if f[2] == "_mystery_renamed_function") == {"other": 1.0}


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--solvers", "funicular,gurobi"], "'gurobi' is not a solver"),
        (["--nodes", "100,x"], "'x' is not an integer"),
        (["--nodes", "1"], "at least 2 nodes"),
        (["--repeats", "0"], "--repeats"),
        (["--back-to-back", "-1"], "--back-to-back"),
        (["--tol", "2"], "--tol"),
        (["--plot", "{tmp}/t.gif"], ".png"),
        (["--markdown", "{tmp}/missing-dir/b.md"], "missing-dir"),
        (["--profile", "--plot", "{tmp}/t.png"], "--profile"),
    ],
)
def test_bad_options_are_one_sentence_and_exit_2(
    args: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert benchmark.main([*(a.format(tmp=tmp_path) for a in args)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("python -m bench.run: error:") and needle in lines[0]
    assert captured.out == "" and not list(tmp_path.iterdir())


def test_unknown_problem_is_a_usage_error() -> None:
    with pytest.raises(SystemExit) as exit_info:
        benchmark.main(["--problem", "sphere"])
    assert exit_info.value.code == 2


def test_clarabel_energy_agrees_with_funicular() -> None:
    """An independent cross-check: a conic solver on the SOC program, not funicular's algorithm."""
    pytest.importorskip("cvxpy")
    pytest.importorskip("clarabel")
    problem = family(60)
    outcome = benchmark.run_clarabel(problem, 1e-8)
    reference = solve(problem)
    assert outcome.status == "optimal" and outcome.multipliers is not None
    assert problem.energy(outcome.positions) == pytest.approx(reference.objective, abs=1e-6)
    # The cones' duals, converted, are the link tensions (to about 1e-5 at this tolerance).
    np.testing.assert_allclose(outcome.multipliers.link, reference.link_tension, atol=1e-4)


def test_ipopt_model_with_the_disk_agrees_with_funicular() -> None:
    pytest.importorskip("casadi")
    problem = family(60, "disk")
    outcome = benchmark.run_ipopt(problem, 1e-8)
    assert outcome.status == "optimal"
    # IPOPT, like funicular's interior-point method alone, ends on the symmetric KKT point (a saddle);
    # funicular's default solve then escapes to a lower minimum, so compare without that escape.
    symmetric = solve(problem, SolverOptions(escape_saddles=False))
    assert problem.energy(outcome.positions) == pytest.approx(symmetric.objective, abs=1e-6)
    # IPOPT's multipliers, converted to tensions and contact multipliers, make it a KKT point for the checker.
    assert check(problem, outcome.positions, outcome.multipliers).kkt_holds
