"""Every built-in scenario solves to the same status, Newton steps, energy and largest tension on
every machine (``tests/data/golden.json``, written by ``scripts/golden.py``): the solver core is
compiled for the baseline x86-64 target, without fast-math or contracted multiply-adds, and the
built-in nets are small enough for the sparse factorizations' scalar (simplicial) form, so nothing
it computes for them depends on the CPU it runs on."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from funicular import solve
from funicular.scenario import builtin_scenarios, load_scenario

GOLDEN = json.loads((Path(__file__).parent / "data" / "golden.json").read_text(encoding="utf-8"))


def test_every_builtin_scenario_is_in_the_file() -> None:
    assert sorted(GOLDEN) == sorted(builtin_scenarios())


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_builtin_scenario_matches_the_golden_results(name: str) -> None:
    expected = GOLDEN[name]
    solution = solve(load_scenario(name))
    assert solution.status.value == expected["status"]
    assert solution.iterations == expected["iterations"]
    assert solution.objective == pytest.approx(expected["objective"], rel=1e-12, abs=1e-300)
    assert float(solution.link_tension.max()) == pytest.approx(expected["max_tension"], rel=1e-12)
