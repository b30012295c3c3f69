"""Several equilibria: explore finds the chain's two ways round a peg, reproducibly."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from funicular.cli import main
from funicular.scenario import load_scenario
from funicular.studies.explore import explore, starting_shapes


def test_starting_shapes_are_reproducible() -> None:
    problem = load_scenario("peg-two-ways")
    a, b = starting_shapes(problem, 3, seed=7), starting_shapes(problem, 3, seed=7)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], starting_shapes(problem, 1, seed=8)[0])


def test_explore_finds_both_sides_of_the_peg() -> None:
    """The peg (centre x = 0.03) sits under the support at x = 0: the chain passes it on the left or on
    the right. Both are KKT points touching the peg, with the chain's lowest part on opposite sides."""
    problem = load_scenario("peg-two-ways")
    exploration = explore(problem, starts=12, seed=0)
    assert len(exploration.equilibria) == 2
    sides = set()
    for equilibrium in exploration.equilibria:
        solution = equilibrium.solution
        assert solution.kkt.max() <= 1e-9
        assert np.hypot(*solution.contact_forces.T).max() > 0  # it rests on the peg
        sides.add(bool(solution.x[-1] < 0.03))
    assert sides == {True, False}
    energies = [eq.energy for eq in exploration.equilibria]
    assert energies == sorted(energies) and energies[1] - energies[0] > 1e-4


def test_explore_cli_writes_json_and_plot(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out_json, out_png = tmp_path / "e.json", tmp_path / "e.png"
    code = main(
        ["explore", "peg-two-ways", "--starts", "12", "--seed", "0", "--json", str(out_json), "--plot", str(out_png)]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "2 distinct equilibria from 12 starts" in text
    document = json.loads(out_json.read_text())
    assert len(document["equilibria"]) == 2
    assert out_png.read_bytes()[:4] == b"\x89PNG"


def test_explore_refuses_more_starts_than_it_takes_at_once(tmp_path: Path) -> None:
    """`funicular explore --starts 100000000` ran until killed: more than 10,000 starts are refused
    in one sentence naming --starts and its range, exit 2, before the scenario is even solved."""
    import resource
    import subprocess
    import sys

    def cap() -> None:  # (a regression would fail fast, not fill the machine)
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))

    out = tmp_path / "explore.json"
    for starts in ("100000000", "10001"):
        result = subprocess.run(
            [sys.executable, "-m", "funicular.cli", "explore", "--starts", starts, "--json", str(out)],
            capture_output=True, text=True, check=False, timeout=60, preexec_fn=cap,
        )  # fmt: skip
        assert result.returncode == 2 and "Traceback" not in result.stderr and result.stderr.count("\n") == 1
        assert f"--starts = {int(starts):,}; give from 1 to 10,000 starting shapes." in result.stderr
        assert not out.exists()


def test_explore_rejects_zero_starts(capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["explore", "peg-two-ways", "--starts", "0"]) == 2
    assert "--starts" in capsys.readouterr().err
