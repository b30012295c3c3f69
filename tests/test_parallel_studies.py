"""Sweeps and explorations in parallel: the same results as in one process, a dead worker's task retried
or reported, the progress bar, and the options' mistakes.

Every comparison is against the serial run of the same study: each solve is deterministic, so the
parallel results must equal it bit for bit, in the same order.
"""

from __future__ import annotations

import io
import json
import os
import socket
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import funicular.studies._parallel as parallel
import funicular.studies.explore as explore_module
import funicular.studies.sweep as sweep_module
from funicular._extras import install_command
from funicular.cli import main
from funicular.errors import ParameterError
from funicular.scenario import load_document, load_scenario
from funicular.solution import Solution
from funicular.studies.explore import Exploration, StartJob, explore, solve_start
from funicular.studies.sweep import RowJob, Sweep, SweepStep, solve_row, sweep

GRID = ["supports[1].position[0]=0.8:1.1:3", "chain.length=1.0:1.6:4"]  # 3 rows of 4; the first steps are infeasible
GRID_ARGS = ["sweep", "two-supports", "--nodes", "11", *(word for s in GRID for word in ("--set", s))]
EXPLORE_ARGS = ["explore", "peg-two-ways", "--starts", "8", "--seed", "3"]
DIE = "FUNICULAR_TEST_DIE"  # "INDEX" or "INDEX:MARKER": the task of that index kills its worker process


# --------------------------------------------------------------------------- test-only task functions
def _die_if_named(index: int) -> None:
    """End this process abruptly if DIE names task ``index`` (only once if it names a marker file:
    the first death leaves the marker)."""
    named = os.environ.get(DIE)
    if named is None:
        return
    target, _, marker = named.partition(":")
    if int(target) != index:
        return
    if marker:
        if Path(marker).exists():
            return
        Path(marker).touch()
    os._exit(17)


def dying_row(job: RowJob) -> list[SweepStep]:
    _die_if_named(job.row)
    return solve_row(job)


def dying_start(job: StartJob) -> Solution:
    _die_if_named(job.start)
    return solve_start(job)


# --------------------------------------------------------------------------- helpers
def run_cli(args: list[str], capsys: pytest.CaptureFixture[str], tmp_path: Path, name: str) -> tuple[int, str, Any]:
    """Exit status, standard output (the ``wrote`` line dropped) and the --json document of one command."""
    out = tmp_path / f"{name}.json"
    status = main([*args, "--json", str(out)])
    text = capsys.readouterr().out.replace(f"  wrote {out}\n", "")
    return status, text, json.loads(out.read_text())


def without_timings(document: Any) -> Any:
    """``document`` without its wall-clock times (which differ from run to run)."""
    if isinstance(document, dict):
        return {key: without_timings(value) for key, value in document.items() if key != "solve_seconds"}
    if isinstance(document, list):
        return [without_timings(value) for value in document]
    return document


def assert_same_steps(a: list[SweepStep], b: list[SweepStep]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert (x.values, x.status, x.message, x.energy, x.max_tension, x.jump, x.move) == (
            y.values,
            y.status,
            y.message,
            y.energy,
            y.max_tension,
            y.jump,
            y.move,
        )
        assert (x.positions is None) == (y.positions is None)
        if x.positions is not None and y.positions is not None:
            assert np.array_equal(x.positions, y.positions)


def grid_sweep(pool: parallel.Pool | None = None) -> Sweep:
    return sweep(load_document("two-supports"), GRID, pool=pool)


def assert_same_exploration(a: Exploration, b: Exploration) -> None:
    assert (a.failed, a.starts, a.seed, a.lost) == (b.failed, b.starts, b.seed, b.lost)
    assert [(e.starts, e.verdict) for e in a.equilibria] == [(e.starts, e.verdict) for e in b.equilibria]
    for x, y in zip(a.equilibria, b.equilibria, strict=True):
        assert np.array_equal(x.solution.positions, y.solution.positions)
        assert np.array_equal(x.solution.link_multipliers, y.solution.link_multipliers)


@pytest.fixture(scope="module")
def serial_grid() -> Sweep:
    return grid_sweep()


@pytest.fixture(scope="module")
def cluster() -> Iterator[str]:
    """A Dask cluster of two worker processes on this machine; its scheduler's address."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as local:
        yield local.scheduler_address


class FakeTerminal(io.StringIO):
    """A standard error that says it is a terminal."""

    def isatty(self) -> bool:
        return True


# --------------------------------------------------------------------------- same results
def test_grid_in_two_processes_is_the_serial_grid(
    serial_grid: Sweep, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """The rows of a grid, each on its own process, give the serial table, statuses and positions."""
    with parallel.open_pool(2) as pool:
        assert not pool.runs_here(3)
        assert_same_steps(grid_sweep(pool).steps, serial_grid.steps)
    assert {step.status for step in serial_grid.steps} >= {"optimal", "infeasible"}
    serial = run_cli([*GRID_ARGS, "--workers", "1"], capsys, tmp_path, "serial")
    assert run_cli([*GRID_ARGS, "--workers", "2"], capsys, tmp_path, "parallel") == serial


def test_one_key_sweep_in_two_processes_is_the_serial_sweep(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """A one-key sweep is a single chain of warm starts: the same table whatever --workers says."""
    args = ["sweep", "disk-drape", "--nodes", "21", "--set", "obstacles[0].center[0]=-0.1:0.1:9"]
    serial = run_cli([*args, "--workers", "1"], capsys, tmp_path, "serial")
    assert serial[0] == 0
    assert run_cli([*args, "--workers", "2"], capsys, tmp_path, "parallel") == serial


def test_explore_in_two_processes_is_the_serial_exploration(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """The starts are grouped in their own order after they are solved: the same equilibria, counts
    and positions as in one process."""
    problem = load_scenario("peg-two-ways")
    serial = explore(problem, 8, seed=3)
    with parallel.open_pool(2) as pool:
        assert_same_exploration(explore(problem, 8, seed=3, pool=pool), serial)
    status, text, document = run_cli([*EXPLORE_ARGS, "--workers", "1"], capsys, tmp_path, "serial")
    again = run_cli([*EXPLORE_ARGS, "--workers", "2"], capsys, tmp_path, "parallel")
    assert (status, text, without_timings(document)) == (again[0], again[1], without_timings(again[2]))


def test_a_dask_cluster_gives_the_serial_results(
    cluster: str, serial_grid: Sweep, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """The grid and the exploration on a Dask cluster (--scheduler): the serial results again."""
    with parallel.open_pool(scheduler=cluster) as pool:
        assert_same_steps(grid_sweep(pool).steps, serial_grid.steps)
    serial = run_cli([*GRID_ARGS, "--workers", "1"], capsys, tmp_path, "serial")
    assert run_cli([*GRID_ARGS, "--scheduler", cluster], capsys, tmp_path, "cluster") == serial
    status, text, document = run_cli([*EXPLORE_ARGS, "--workers", "1"], capsys, tmp_path, "serial-explore")
    again = run_cli([*EXPLORE_ARGS, "--scheduler", cluster], capsys, tmp_path, "cluster-explore")
    assert (status, text, without_timings(document)) == (again[0], again[1], without_timings(again[2]))


# --------------------------------------------------------------------------- dead workers
def test_a_row_whose_worker_dies_once_is_solved_again(
    serial_grid: Sweep, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(sweep_module, "ROW_TASK", dying_row)
    marker = tmp_path / "died"
    monkeypatch.setenv(DIE, f"1:{marker}")
    with parallel.open_pool(2) as pool:
        result = grid_sweep(pool)
    assert marker.exists()  # the worker of row 1 did die
    assert_same_steps(result.steps, serial_grid.steps)


def test_a_row_whose_worker_dies_twice_is_reported_failed(
    serial_grid: Sweep, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Row 1's worker dies on both attempts: its steps after the first (solved before the rows are
    handed out) are "failed", saying why; the other rows are the serial ones; exit status 1."""
    monkeypatch.setattr(sweep_module, "ROW_TASK", dying_row)
    monkeypatch.setenv(DIE, "1")
    with parallel.open_pool(2) as pool:
        result = grid_sweep(pool)
    for index, (row, serial_row) in enumerate(zip(result.rows, serial_grid.rows, strict=True)):
        if index != 1:
            assert_same_steps(row, serial_row)
            continue
        assert_same_steps(row[:1], serial_row[:1])
        assert [step.status for step in row[1:]] == ["failed"] * 3
        assert all("worker process died" in step.message for step in row[1:])
        assert [step.values for step in row] == [step.values for step in serial_row]
    assert main([*GRID_ARGS, "--workers", "2"]) == 1
    assert "failed: its worker process died" in capsys.readouterr().out


def test_a_start_whose_worker_dies_twice_is_reported_failed(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(explore_module, "START_TASK", dying_start)
    monkeypatch.setenv(DIE, "2")
    with parallel.open_pool(2) as pool:
        exploration = explore(load_scenario("peg-two-ways"), 6, pool=pool)
    assert [start for start, _ in exploration.lost] == [2]
    assert sum(eq.starts for eq in exploration.equilibria) + exploration.failed == 6 - 1
    assert main(["explore", "peg-two-ways", "--starts", "6", "--workers", "2"]) == 0
    assert "start 2 failed: its worker process died" in capsys.readouterr().out


# --------------------------------------------------------------------------- progress
PROGRESS_COMMANDS = [
    pytest.param(["sweep", "two-supports", "--set", "chain.length=1.1:2.0:12", "--workers", "1"], "sweep", id="sweep"),
    pytest.param(["explore", "peg-two-ways", "--starts", "10", "--workers", "1"], "explore", id="explore"),
    pytest.param(["study", "refine", "dangling", "--nodes", "3,5,9,17,33"], "refine", id="refine"),
]


@pytest.mark.parametrize(("args", "label"), PROGRESS_COMMANDS)
def test_progress_bar_on_a_terminal_and_quiet(
    args: list[str], label: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """On a terminal the bar is drawn on standard error, counting the solves; --quiet draws nothing."""
    monkeypatch.setenv("TERM", "xterm")  # (a "dumb" terminal gets no live display)
    for quiet in (False, True):
        terminal = FakeTerminal()
        monkeypatch.setattr(sys, "stderr", terminal)
        assert main([*args, *(["--quiet"] if quiet else [])]) == 0
        drawn = terminal.getvalue()
        assert (drawn == "") if quiet else (label in drawn and "time left" in drawn)
    assert capsys.readouterr().err == ""


def test_benchmark_progress_bar(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from bench import run as benchmark

    monkeypatch.setenv("TERM", "xterm")
    args = ["--nodes", "5,9", "--problem", "free", "--solvers", "funicular", "--repeats", "1", "--back-to-back", "2"]
    for quiet in (False, True):
        terminal = FakeTerminal()
        monkeypatch.setattr(sys, "stderr", terminal)
        assert benchmark.main([*args, *(["--quiet"] if quiet else [])]) == 0
        assert (terminal.getvalue() == "") if quiet else ("benchmark" in terminal.getvalue())
    assert "| 9 |" in capsys.readouterr().out  # the table still goes to standard output


def test_no_bar_without_rich(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rich.progress", None)  # import rich.progress fails
    terminal = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert main(["sweep", "two-supports", "--set", "chain.length=1.1:2.0:12", "--workers", "1"]) == 0
    assert terminal.getvalue() == ""


# --------------------------------------------------------------------------- mistakes
def _no_solve(*args: object, **kwargs: object) -> None:
    raise AssertionError("nothing may be solved before the options are checked")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


BAD_OPTIONS = [
    pytest.param(["--workers", "0"], "--workers 0 is too few; give 1 or more", id="no-workers"),
    pytest.param(["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "give one of the two", id="both"),
    pytest.param(["--scheduler", "tcp://x:y:z"], "is not an address", id="bad-address"),
]


@pytest.mark.parametrize(("options", "message"), BAD_OPTIONS)
@pytest.mark.parametrize("command", [GRID_ARGS, EXPLORE_ARGS], ids=["sweep", "explore"])
def test_bad_parallel_options_exit_2(
    command: list[str],
    options: list[str],
    message: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setattr(sweep_module, "run_step", _no_solve)
    monkeypatch.setattr(explore_module, "starting_shapes", _no_solve)
    assert main([*command, *options]) == 2
    err = capsys.readouterr().err
    assert err.startswith("funicular: error: ") and message in err and err.count("\n") == 1


def test_the_api_names_its_own_arguments() -> None:
    with pytest.raises(ParameterError, match=r"^workers 0 is too few"):
        parallel.open_pool(0)
    with pytest.raises(ParameterError, match=r"^workers 2: with a scheduler"):
        parallel.open_pool(2, "tcp://127.0.0.1:1")


def test_without_dask_the_scheduler_option_says_what_to_install(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    monkeypatch.setattr(sweep_module, "run_step", _no_solve)
    assert main([*GRID_ARGS, "--scheduler", "tcp://127.0.0.1:8786"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--scheduler tcp://127.0.0.1:8786" in err
    assert install_command("cluster") in err


def test_an_unreachable_scheduler_is_named(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed")
    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT", 0.5)
    monkeypatch.setattr(explore_module, "starting_shapes", _no_solve)
    address = f"tcp://127.0.0.1:{free_port()}"
    assert main([*EXPLORE_ARGS, "--scheduler", address]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--scheduler {address}: no Dask scheduler answered within 0.5 s" in err
