"""Cross-checks: SLSQP and IPOPT (CasADi) agree with funicular's solver; `solve --solver`, `compare`."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import oracles
from funicular import Problem, Solution, backends, solve
from funicular._extras import install_command
from funicular.checks import check_solution
from funicular.cli import main
from funicular.scenario import load_scenario

needs_casadi = pytest.mark.skipif(
    importlib.util.find_spec("casadi") is None, reason="casadi (the ipopt extra) is not installed"
)

SMALL = {
    "dangling": lambda: load_scenario("dangling"),
    "squared-dangling": lambda: load_scenario("squared-dangling"),
    "two-supports": lambda: load_scenario("two-supports").with_nodes(21),
    "three-supports": lambda: load_scenario("three-supports").with_nodes(21),
    "slope": lambda: load_scenario("slope").with_nodes(21),
}


def assert_agree(other: Solution, reference: Solution, position_tol: float, tension_tol: float) -> None:
    assert other.converged, other.status
    np.testing.assert_allclose(other.positions, reference.positions, rtol=0, atol=position_tol)
    np.testing.assert_allclose(other.link_tension, reference.link_tension, rtol=0, atol=tension_tol)
    assert other.objective == pytest.approx(reference.objective, rel=0, abs=position_tol)
    if reference.problem.obstacles:
        np.testing.assert_allclose(other.contact_forces, reference.contact_forces, rtol=0, atol=tension_tol)


@pytest.mark.parametrize("name", ["dangling", "squared-dangling", "two-supports", "slope"])
def test_slsqp_agrees_with_funicular(name: str) -> None:
    problem = SMALL[name]()
    # SLSQP stops near 1e-8 in positions; the recovered tensions follow. Its ftol of 1e-10 (the
    # default) is below what its line search resolves on some starts: on two-supports it stops 2e-9
    # from the answer with "positive directional derivative", depending on the 13th digit of the start.
    assert_agree(backends.solve_with(problem, "slsqp", tol=1e-9), solve(problem), 1e-6, 1e-6)


def test_slsqp_finds_funiculars_drape_over_the_disk_not_its_mirror_image() -> None:
    """disk-drape's equilibrium is not symmetric (its mirror image is the other minimum, 0.09 away
    at some node); SLSQP from the same start ends on funicular's drape, to its accuracy, as
    docs/checks.md says."""
    problem = load_scenario("disk-drape")
    reference, other = solve(problem), backends.solve_with(problem, "slsqp")
    mirrored = reference.positions[::-1] * [-1.0, 1.0] + [1.0, 0.0]  # supports at (0, 0) and (1, 0)
    assert other.converged
    assert np.max(np.abs(other.positions - reference.positions)) < 1e-5
    assert np.max(np.abs(other.positions - mirrored)) > 0.05


@needs_casadi
@pytest.mark.parametrize("name", sorted(SMALL))
def test_ipopt_agrees_with_funicular(name: str) -> None:
    problem = SMALL[name]()
    assert_agree(backends.solve_with(problem, "ipopt"), solve(problem), 1e-8, 1e-8)


@needs_casadi
def test_ipopt_multipliers_are_tensions_with_funicular_signs() -> None:
    problem = load_scenario("dangling")  # 20 nodes, total mass 1, g = 1, one support
    solution = backends.solve_with(problem, "ipopt")
    exact = oracles.dangling_tensions(problem.n_nodes, problem.total_mass, problem.gravity)
    np.testing.assert_allclose(solution.link_tension, exact, rtol=0, atol=1e-8)
    assert solution.support_reactions[0] == pytest.approx([0.0, 1.0], abs=1e-8)


@needs_casadi
def test_ipopt_obstacle_multipliers_are_contact_forces() -> None:
    problem = load_scenario("ground").with_nodes(21)
    reference, other = solve(problem), backends.solve_with(problem, "ipopt")
    assert_agree(other, reference, 1e-8, 1e-8)
    assert other.kkt.max() < 1e-9


def test_other_solvers_get_the_same_check_report() -> None:
    problem = SMALL["two-supports"]()
    for name in backends.available():
        report = check_solution(backends.solve_with(problem, name))
        assert report.kkt_holds and report.licq is not None and report.licq.holds
        assert report.second_order is not None and report.second_order.verdict == "strict local minimum"


def test_solve_with_slsqp_on_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solve", "dangling", "--solver", "slsqp"]) == 0
    assert "optimal" in capsys.readouterr().out


def test_ipopt_without_casadi_is_a_clear_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(backends, "available", lambda: ["funicular", "slsqp"])
    assert main(["solve", "dangling", "--solver", "ipopt"]) == 2
    error = capsys.readouterr().err
    assert install_command("ipopt") in error and error.count("\n") == 1


def test_slsqp_warns_about_large_chains() -> None:
    large = Problem.build(nodes=201, length=1.5, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))])
    assert backends.advice(large, "slsqp") is not None and "dense" in str(backends.advice(large, "slsqp"))
    assert backends.advice(large, "funicular") is None
    assert backends.advice(SMALL["dangling"](), "slsqp") is None


def test_compare_prints_one_row_per_solver(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compare", "dangling"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "max |dp|" in lines[1] and "max KKT" in lines[1]
    rows = {line.split()[0]: line.split() for line in lines[2:] if line and not line.startswith(" ")}
    assert set(rows) == set(backends.available())
    assert all(row[1] == "optimal" for row in rows.values())


@pytest.mark.parametrize(
    "command",
    [
        ["compare", "two-supports", "--nodes", "100000"],
        ["solve", "two-supports", "--solver", "slsqp", "--nodes", "100000"],
        ["solve", "two-supports", "--solver", "slsqp", "--nodes", "2001"],
        ["solve", "two-supports", "--solver", "ipopt", "--nodes", "50001"],
    ],
    ids=["compare", "slsqp", "slsqp-just-over", "ipopt-just-over"],
)
def test_a_chain_too_large_for_slsqp_or_ipopt_is_refused_before_anything_is_allocated(
    tmp_path: Path, command: list[str]
) -> None:
    """SLSQP's dense matrices of a 100,000-node chain would need 2.9 TiB: the command says in one
    sentence how many nodes each solver takes (backends.MAX_NODES), exits 2 at once and writes nothing."""
    out = tmp_path / "out.json"
    extra = ["--json", str(out)] if command[0] == "solve" else []
    result = subprocess.run(
        [sys.executable, "-m", "funicular.cli", *command, *extra],
        capture_output=True, text=True, check=False, timeout=60,
    )  # fmt: skip
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    nodes = f"{int(command[command.index('--nodes') + 1]):,}"
    most = backends.MAX_NODES
    limits = (f"slsqp takes at most {most['slsqp']:,} nodes", f"ipopt at most {most['ipopt']:,}")
    assert all(words in result.stderr for words in (*limits, f"the {nodes} nodes", "--nodes")), result.stderr
    assert not out.exists()


def test_the_api_refuses_a_chain_too_large_for_a_solver() -> None:
    """The same limit from Python: solve_with and compare raise ParameterError before solving."""
    from funicular.errors import ParameterError

    limit = backends.MAX_NODES["slsqp"]
    chain = Problem.build(nodes=limit + 1, length=1.5, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))])
    with pytest.raises(ParameterError, match=f"slsqp takes at most {limit:,} nodes"):
        backends.solve_with(chain, "slsqp")
    with pytest.raises(ParameterError, match=f"the {limit + 1:,} nodes"):
        backends.compare(chain)
    assert backends.solve_with(chain, "funicular").converged  # funicular's own solver takes it
