"""Diagnostics of any point: feasibility, multipliers, KKT, LICQ, MFCQ, multiplier ranges, second order."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from bench.run import family

import funicular.cli.check
import oracles
from funicular import Problem, ScenarioError, SolverOptions, checks, solve
from funicular.checks import Multipliers, check, check_solution, read_solution
from funicular.cli import main
from funicular.obstacles import Disk, HalfPlane
from funicular.scenario import load_scenario
from funicular.solution import Solution


# ----------------------------------------------------------------- the seed's LICQ failure
@pytest.mark.parametrize("given", [True, False], ids=["solver multipliers", "recovered"])
def test_seed_licq_failure_is_the_vertical_pre_tension(given: bool) -> None:
    problem = load_scenario("seed-licq")  # supports (0, 0) and (0, -1), two links of 0.5, masses 1/3, g = 1
    solution = solve(problem)
    report = check_solution(solution) if given else check(problem, solution.positions)
    licq = report.licq
    assert licq is not None and not licq.holds
    assert (licq.rank, licq.active_constraints) == (1, 2)
    assert licq.sigma_min < 1e-12
    (dependency,) = licq.dependencies
    # Both links carry the same extra tension; the supports take it up vertically (seed: (0, a, 0, -a, -a, -a)).
    assert dependency.forces == pytest.approx({"link 0": 1.0, "link 1": 1.0})
    assert dependency.support_reactions[0] == pytest.approx((0.0, 1.0), abs=1e-12)
    assert dependency.support_reactions[2] == pytest.approx((0.0, -1.0), abs=1e-12)
    assert "not unique" in dependency.text and "supports at nodes 0, 2" in dependency.text
    # The feasible set is a single point: no direction decreases both active constraints.
    assert report.mfcq is not None and not report.mfcq.holds
    ranges = {r.constraint: (r.min, r.max) for r in report.multiplier_ranges or ()}
    assert ranges["link 0"] == pytest.approx((1 / 3, math.inf))  # node 1's weight plus any pre-tension
    assert ranges["link 1"] == pytest.approx((0.0, math.inf), abs=1e-12)
    assert report.kkt_holds
    assert report.second_order is not None and report.second_order.verdict == "strict local minimum"


def test_recovered_multipliers_carry_the_least_pre_tension() -> None:
    problem = load_scenario("seed-licq")
    report = check(problem, solve(problem).positions)
    assert report.multiplier_source == "recovered"
    assert report.multipliers is not None
    assert report.multipliers.link == pytest.approx([1 / 3, 0.0], abs=1e-12)


def test_report_json_blocks() -> None:
    document = check_solution(solve(load_scenario("seed-licq"))).to_dict()
    assert {"holds", "rank", "active_constraints", "sigma_min"} <= set(document["licq"])
    assert document["licq"]["holds"] is False
    assert document["mfcq"]["holds"] is False
    assert {"verdict", "min_eigenvalue"} <= set(document["second_order"])
    json.dumps(document["licq"])  # plain JSON types


# ----------------------------------------------------------------- regular points
def test_slack_catenary_is_a_strict_local_minimum_with_licq() -> None:
    report = check_solution(solve(load_scenario("two-supports")))
    assert report.feasible and report.kkt_holds
    assert report.licq is not None and report.licq.holds and report.licq.rank == 50
    assert report.licq.sigma_min > 1e-3
    assert report.mfcq is not None and report.mfcq.holds
    assert report.multiplier_ranges == ()
    assert report.second_order is not None and report.second_order.verdict == "strict local minimum"
    assert report.second_order.min_eigenvalue > 0


def test_recovery_from_exact_catenary_positions_gives_exact_tensions() -> None:
    n, g = 31, 9.81
    masses = np.linspace(0.5, 1.5, n)
    lengths = np.full(n - 1, 0.06)
    exact = oracles.discrete_catenary(masses, lengths, g, (0.0, 0.0), (1.2, 0.3))
    problem = Problem.build(
        nodes=n, masses=masses, link_lengths=lengths, gravity=g, supports=[(0, (0.0, 0.0)), (-1, (1.2, 0.3))]
    )
    for formulation in ("norm", "squared"):
        report = check(problem.with_formulation(formulation), exact.positions)
        assert report.multipliers is not None and report.multiplier_source == "recovered"
        distances = np.hypot(*np.diff(exact.positions, axis=0).T)
        tension = report.multipliers.link if formulation == "norm" else 2 * distances * report.multipliers.link
        np.testing.assert_allclose(tension, exact.tension, rtol=0, atol=1e-8)
        assert report.licq is not None and report.licq.holds


def test_sparse_and_dense_paths_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    cases = [
        load_scenario("two-supports").with_nodes(60),
        load_scenario("taut").with_nodes(60),
        load_scenario("peg-two-ways").with_nodes(50),
    ]
    for problem in cases:
        solution = solve(problem)
        monkeypatch.setattr(checks._tolerances, "DENSE_LIMIT", 10**6)
        dense = check_solution(solution)
        recovered_dense = check(problem, solution.positions)
        monkeypatch.setattr(checks._tolerances, "DENSE_LIMIT", 0)
        sparse = check_solution(solution)
        recovered_sparse = check(problem, solution.positions)
        for a, b in ((dense, sparse), (recovered_dense, recovered_sparse)):
            assert a.licq is not None and b.licq is not None and a.second_order and b.second_order
            assert (a.licq.holds, a.licq.rank) == (b.licq.holds, b.licq.rank)
            assert a.licq.sigma_min == pytest.approx(b.licq.sigma_min, rel=1e-6, abs=1e-12)
            assert a.second_order.verdict == b.second_order.verdict
            assert a.second_order.min_eigenvalue == pytest.approx(b.second_order.min_eigenvalue, rel=1e-6)
            assert a.multipliers is not None and b.multipliers is not None
            np.testing.assert_allclose(a.multipliers.link, b.multipliers.link, atol=1e-9)


# ----------------------------------------------------------------- MFCQ without LICQ
def test_duplicated_ground_fails_licq_but_satisfies_mfcq() -> None:
    # Node 1 rests on the ground (slack link), which is given twice: two identical contact rows.
    grounds = [HalfPlane((0.0, 0.0), (0.0, 1.0), name=name) for name in ("ground", "ground again")]
    problem = Problem.build(
        nodes=2, link_length=1.0, masses=[1.0, 2.0], gravity=1.0, supports=[(0, (0.0, 0.5))], obstacles=grounds
    )
    report = check(problem, np.array([[0.0, 0.5], [0.0, 0.0]]))
    assert report.licq is not None and not report.licq.holds and report.licq.rank == 1
    (dependency,) = report.licq.dependencies
    assert sorted(dependency.forces.values()) == pytest.approx([-1.0, 1.0])
    assert report.mfcq is not None and report.mfcq.holds  # moving up leaves both grounds
    ranges = {r.constraint: (r.min, r.max) for r in report.multiplier_ranges or ()}
    assert list(ranges.values()) == [pytest.approx((0.0, 2.0), abs=1e-12)] * 2  # the weight 2, shared any way
    assert report.kkt_holds


# ----------------------------------------------------------------- a saddle point
def test_chain_balanced_on_top_of_a_disk_is_not_a_minimum() -> None:
    # Node 1 hangs from the support on a taut link, node 2 sits on top of the disk on a slack link:
    # a critical point (gravity against the contact force), but node 2 rolls off either way.
    disk = Disk((0.0, 0.0), 1.0)
    problem = Problem.build(
        nodes=3, link_length=0.5, masses=1.0, gravity=1.0, supports=[(0, (0.0, 1.6))], obstacles=[disk]
    )
    positions = np.array([[0.0, 1.6], [0.0, 1.1], [0.0, 1.0]])
    for report in (
        check(problem, positions),
        check(problem, positions, Multipliers(np.array([1.0, 0.0]), np.array([[0, 0, 1.0]]))),
    ):
        assert report.kkt_holds and report.licq is not None and report.licq.holds
        assert report.second_order is not None
        assert report.second_order.verdict == "not a minimum"
        assert report.second_order.min_eigenvalue == pytest.approx(-1.0)  # -(contact force) / radius


def test_symmetric_drape_saddle_is_never_called_a_minimum() -> None:
    # The same disk-top balance with the chain held on both sides by slack links.
    disk = Disk((0.0, 0.0), 1.0)
    problem = Problem.build(
        nodes=3,
        link_length=2.0,
        masses=[0.0, 1.0, 0.0],
        gravity=1.0,
        supports=[(0, (-1.5, 0.0)), (2, (1.5, 0.0))],
        obstacles=[disk],
    )
    report = check(problem, np.array([[-1.5, 0.0], [0.0, 1.0], [1.5, 0.0]]))
    assert report.second_order is not None and report.second_order.verdict in ("not a minimum", "undecided")


# ----------------------------------------------------------------- infeasible points
def test_overstretched_link_is_reported_as_infeasible() -> None:
    problem = load_scenario("dangling")
    positions = solve(problem).positions.copy()
    positions[5:, 1] -= 0.01  # stretches link 4
    report = check(problem, positions)
    assert not report.feasible and report.licq is None and report.second_order is None
    assert report.violation is not None and report.violation.constraint == "link 4"
    assert report.violation.amount == pytest.approx(0.01)
    assert "link 4 is overstretched by 0.01" in report.summary()


def test_node_inside_an_obstacle_is_reported_as_infeasible() -> None:
    problem = load_scenario("disk-drape")
    positions = solve(problem).positions.copy()
    positions[30] += (0.0, -0.02)  # into the disk below it (and stretching its links less than that)
    report = check(problem, positions)
    assert not report.feasible and report.violation is not None
    assert report.violation.text.startswith("node 30 is") and "inside obstacle 'disk'" in report.violation.text


# ----------------------------------------------------------------- command line and files
def test_check_command_writes_the_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "check.json"
    assert main(["check", "seed-licq", "--json", str(out)]) == 0
    assert "LICQ              fails" in capsys.readouterr().out
    document = json.loads(out.read_text())
    assert document["licq"]["holds"] is False and document["mfcq"]["holds"] is False
    assert document["multiplier_ranges"][0]["max"] is None  # infinity is null in JSON


def test_check_refuses_link_contact_in_one_sentence_before_it_solves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    scenario = tmp_path / "drum.toml"
    scenario.write_text(
        'contact = "links"\n[chain]\nnodes = 7\nlength = 1.5\nmass = 1.0\n'
        "[[supports]]\nnode = 0\nposition = [0.0, 0.0]\n[[supports]]\nnode = -1\nposition = [1.0, 0.0]\n"
        '[[obstacles]]\nshape = "disk"\nname = "drum"\ncenter = [0.5, -0.45]\nradius = 0.25\n'
    )

    def no_solve(*args: object, **kwargs: object) -> None:
        raise AssertionError("solved before refusing")

    monkeypatch.setattr(funicular.cli.check, "solve", no_solve)
    assert main(["check", str(scenario)]) == 2
    error = capsys.readouterr().err.strip()
    assert "supports contact = 'nodes' only" in error and error.count("\n") == 0


def test_check_of_a_solution_file_and_solve_json_licq(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = tmp_path / "solution.json"
    assert main(["solve", "two-supports", "--json", str(result)]) == 0
    document = json.loads(result.read_text())
    assert document["licq"]["holds"] is True and document["licq"]["rank"] == 50
    assert main(["check", "two-supports", "--solution", str(result)]) == 0
    assert "strict local minimum" in capsys.readouterr().out
    del document["multipliers"]
    result.write_text(json.dumps(document))
    assert main(["check", "two-supports", "--solution", str(result)]) == 0
    assert "recovered" in capsys.readouterr().out


def test_check_of_an_infeasible_file_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problem = load_scenario("two-supports")
    solution = solve(problem)
    y = solution.y.copy()
    y[26:50] -= 0.05  # links 25 and 49 get longer
    document = {"x": solution.x.tolist(), "y": y.tolist()}
    path = tmp_path / "far.json"
    path.write_text(json.dumps(document))
    assert main(["check", "two-supports", "--solution", str(path)]) == 1
    output = capsys.readouterr().out
    assert "feasible          no: link" in output and "is overstretched by" in output


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{not json", "is not valid JSON"),
        ("[1, 2]", "must be a JSON object"),
        ('{"x": [0, 1], "y": [0, 0]}', "x has 2 entries, but the scenario has 51 nodes"),
        ("X_NAN", "is not a finite number"),
        ("X_NULL", "y[3] = None is not a finite number"),
        ("X_SUPPORT", "node 50 is a support at (1, 0), but the file puts it 0.1 away"),
    ],
)
def test_bad_solution_files_exit_2_with_one_sentence(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    x, y = np.linspace(0.0, 1.0, 51).tolist(), np.zeros(51).tolist()
    if text == "X_NAN":
        text = json.dumps({"x": x, "y": y}).replace("0.02,", "NaN,", 1)
    elif text == "X_NULL":
        text = json.dumps({"x": x, "y": [*y[:3], None, *y[4:]]})
    elif text == "X_SUPPORT":
        text = json.dumps({"x": x, "y": [*y[:-1], 0.1]})
    path = tmp_path / "bad.json"
    path.write_text(text)
    assert main(["check", "two-supports", "--solution", str(path)]) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and error.count("\n") == 0 and error.startswith("funicular: error:")


def test_missing_solution_file_is_a_scenario_error(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="cannot read solution file"):
        read_solution(load_scenario("two-supports"), tmp_path / "missing.json")


# ----------------------------------------------------------------- second order against a dense reference
def _dense_second_order(
    problem: Problem, positions: np.ndarray, link_multipliers: np.ndarray, nu: np.ndarray, tol: float
) -> tuple[str, float, np.ndarray, np.ndarray]:
    """The second-order test of the module docstring written out densely, from the problem's own
    formulas: active rows as unit vectors over the free coordinates, the Hessian of the Lagrangian
    assembled link by link and node by node, ``scipy.linalg.null_space`` and ``eigvalsh``. Returns
    the verdict, the curvature, the active rows and the Hessian."""
    free = problem.free_nodes
    column = {int(node): c for c, node in enumerate(free)}
    n = 2 * free.size
    length_tol = tol * float(problem.link_lengths.max())
    hessian = np.zeros((n, n))
    rows: list[np.ndarray] = []
    forces: list[float] = []
    for k in range(problem.n_links):
        delta = positions[k] - positions[k + 1]
        d = float(np.linalg.norm(delta))
        u = delta / d
        mu = float(link_multipliers[k])
        if problem.formulation.value == "norm":  # c = d - l: Hessian (I - u u^T) / d per node pair
            block, tension = max(mu, 0.0) * (np.eye(2) - np.outer(u, u)) / d, mu
        else:  # c = d^2 - l^2: Hessian 2 I per node pair, tension 2 d mu
            block, tension = max(mu, 0.0) * 2.0 * np.eye(2), 2.0 * d * mu
        for i, si in ((k, 1.0), (k + 1, -1.0)):
            for j, sj in ((k, 1.0), (k + 1, -1.0)):
                if i in column and j in column:
                    hessian[2 * column[i] : 2 * column[i] + 2, 2 * column[j] : 2 * column[j] + 2] += si * sj * block
        if d >= problem.link_lengths[k] - length_tol:
            row = np.zeros(n)
            for i, sign in ((k, 1.0), (k + 1, -1.0)):
                if i in column:
                    row[2 * column[i] : 2 * column[i] + 2] = sign * u
            rows.append(row)
            forces.append(tension)
    for j, obstacle in enumerate(problem.obstacles):
        phi, gradient, second = obstacle.evaluate(positions[free])
        for c, node in enumerate(free):
            hessian[2 * c : 2 * c + 2, 2 * c : 2 * c + 2] += max(nu[j, node], 0.0) * second[c]
            size = float(np.linalg.norm(gradient[c]))
            if phi[c] / size >= -length_tol:
                row = np.zeros(n)
                row[2 * c : 2 * c + 2] = gradient[c] / size
                rows.append(row)
                forces.append(float(nu[j, node]) * size)
    active = np.array(rows).reshape(-1, n)
    strict = np.array(forces) > tol * problem.weight
    threshold = tol * problem.weight / (problem.n_nodes * problem.total_length)

    def curvature(a: np.ndarray) -> float:
        basis = scipy.linalg.null_space(a) if a.shape[0] else np.eye(n)
        return float(np.linalg.eigvalsh(basis.T @ hessian @ basis)[0]) if basis.shape[1] else math.inf

    value = curvature(active[strict])
    if value > threshold:
        return "strict local minimum", value, active, hessian
    if not strict.all():
        value = curvature(active)
    licq = active.shape[0] == 0 or (active.shape[0] <= n and np.linalg.svd(active, compute_uv=False).min() > 1e-8)
    return ("not a minimum" if value < -threshold and licq else "undecided"), value, active, hessian


@functools.cache
def _solved(name: str, nodes: int | None, escape: bool) -> tuple[Problem, Solution]:
    problem = family(nodes or 0, "disk") if name == "family" else load_scenario(name)
    if nodes is not None and name != "family":
        problem = problem.with_nodes(nodes)
    return problem, solve(problem, SolverOptions(escape_saddles=escape))


@pytest.mark.parametrize("tol", [1e-6, 1e-2], ids=["tol 1e-6", "tol 1e-2 (weakly active rows)"])
@pytest.mark.parametrize(
    ("name", "nodes", "escape", "licq"),
    [
        ("family", 50, False, True),  # balanced on the disk: not a minimum (dense QR)
        ("family", 50, True, True),  # draped to one side: a strict minimum
        ("family", 200, False, True),  # the same two on the banded path
        ("family", 200, True, True),
        ("disk-drape", None, False, True),  # weakly active contacts change the curvature at tol 1e-2
        ("seed-licq", None, True, False),  # two links between supports 2 l apart: dependent (dense SVD)
        ("taut", 130, True, False),  # a straight taut chain between supports: dependent (banded path)
        ("three-supports", None, True, True),  # an interior support
        ("squared-dangling", None, True, True),
    ],
)
def test_second_order_matches_a_dense_reference(
    name: str, nodes: int | None, escape: bool, licq: bool, tol: float
) -> None:
    problem, solution = _solved(name, nodes, escape)
    licq_block = checks.licq_of(solution)
    assert licq_block is not None and licq_block.holds == licq
    nu = solution.obstacle_multipliers.reshape(len(problem.obstacles), problem.n_nodes)
    verdict, value, active, hessian = _dense_second_order(
        problem, solution.positions, solution.link_multipliers, nu, tol
    )
    result = checks.second_order(problem, solution, tol)
    assert result.verdict == verdict
    assert result.min_eigenvalue == pytest.approx(value, rel=1e-8, abs=1e-12 * problem.weight)
    if verdict != "not a minimum":
        return
    assert result.direction is not None
    direction = result.direction
    assert np.all(direction[problem.support_nodes] == 0.0)
    v = direction[problem.free_nodes].ravel()
    assert np.linalg.norm(v) == pytest.approx(1.0)
    np.testing.assert_allclose(active @ v, 0.0, atol=1e-9)  # every active constraint stays active
    assert v @ hessian @ v == pytest.approx(value, rel=1e-8)  # and the curvature is the smallest one


def test_duplicated_contact_rows_match_the_dense_reference() -> None:
    # LICQ fails through two identical contact rows (the duplicated ground of the MFCQ test above),
    # with the given multipliers carrying the weight on one of them.
    grounds = [HalfPlane((0.0, 0.0), (0.0, 1.0), name=name) for name in ("ground", "ground again")]
    problem = Problem.build(
        nodes=3, link_length=1.0, masses=[0.0, 1.0, 2.0], gravity=1.0, supports=[(0, (0.0, 0.5))], obstacles=grounds
    )
    positions = np.array([[0.0, 0.5], [0.6, 0.0], [1.6, 0.0]])
    link, nu = np.zeros(2), np.array([[0.0, 1.0, 2.0], [0.0, 0.0, 0.0]])
    report = check(problem, positions, Multipliers(link, nu))
    assert report.licq is not None and not report.licq.holds
    verdict, value, _, _ = _dense_second_order(problem, positions, link, nu, checks.DEFAULT_TOL)
    assert report.second_order is not None
    assert (report.second_order.verdict, report.second_order.min_eigenvalue) == (verdict, pytest.approx(value))


@pytest.mark.parametrize("nodes", [50, 200], ids=["dense", "banded"])
def test_a_weakly_active_link_before_strict_rows_matches_the_dense_reference(nodes: int) -> None:
    # At the draped minimum, one taut link's multiplier set to zero: a weakly active row among the
    # strictly active ones. Stretching that link costs no curvature, so the strict cone decides
    # nothing and the curvature on all active rows is positive: "undecided". (Second order does
    # not need stationarity; the reference uses the same multipliers.)
    problem, solution = _solved("family", nodes, True)
    link = solution.link_multipliers.copy()
    link[3 * nodes // 10] = 0.0
    nu = solution.obstacle_multipliers.reshape(len(problem.obstacles), problem.n_nodes)
    verdict, value, _, _ = _dense_second_order(problem, solution.positions, link, nu, checks.DEFAULT_TOL)
    assert verdict == "undecided" and value > 0
    result = checks.second_order(problem, dataclasses.replace(solution, link_multipliers=link))
    assert (result.verdict, result.min_eigenvalue) == (verdict, pytest.approx(value, rel=1e-8))


def test_as_many_dependent_strict_rows_as_coordinates_are_not_a_proof_of_a_minimum() -> None:
    # One free node resting on two identical grounds, each carrying half its weight: two strictly
    # active rows for two coordinates, but dependent, so the critical cone is the horizontal line,
    # where nothing curves (flat ground, slack link): undecided, not "strict local minimum".
    grounds = [HalfPlane((0.0, 0.0), (0.0, 1.0), name=name) for name in ("ground", "ground again")]
    problem = Problem.build(
        nodes=2, link_length=1.0, masses=[1.0, 2.0], gravity=1.0, supports=[(0, (0.0, 0.5))], obstacles=grounds
    )
    positions = np.array([[0.0, 0.5], [0.0, 0.0]])
    link, nu = np.zeros(1), np.array([[0.0, 1.0], [0.0, 1.0]])
    verdict, value, _, _ = _dense_second_order(problem, positions, link, nu, checks.DEFAULT_TOL)
    assert (verdict, value) == ("undecided", pytest.approx(0.0, abs=1e-12))
    solution = dataclasses.replace(
        solve(problem), positions=positions, link_multipliers=link, obstacle_multipliers=nu.ravel()
    )
    for result in (
        checks.second_order(problem, solution),
        check(problem, positions, Multipliers(link, nu)).second_order,
    ):
        assert result is not None
        assert (result.verdict, result.min_eigenvalue) == (verdict, pytest.approx(value, abs=1e-12))
