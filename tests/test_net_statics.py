"""A net's statics at its equilibrium: whether its forces are unique (LICQ), the degree of static
indeterminacy, the self-stress states and the range of every tension, against hand calculations."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import funicular
import funicular.checks._statics
import funicular.checks._tolerances
import funicular.cli.solve
from funicular._uniqueness import multipliers_may_not_be_unique
from funicular.checks import statics_of
from funicular.cli import main


def _three_strings() -> funicular.Problem:
    """A unit weight on three strings of length 1 from (-0.6, 0.8), (0, 1) and (0.6, 0.8): all three
    reach the origin exactly, so all are taut there and the weight hangs at the origin."""
    return funicular.Problem.build(
        nodes=4,
        links=[[0, 3, 1.0], [1, 3, 1.0], [2, 3, 1.0]],
        supports=[(0, (-0.6, 0.8)), (1, (0.0, 1.0)), (2, (0.6, 0.8))],
        masses=[0.0, 0.0, 0.0, 1.0],
        gravity=1.0,
    )


def test_a_weight_on_three_taut_strings_is_indeterminate_to_degree_one() -> None:
    solution = funicular.solve(_three_strings())
    assert solution.status == "optimal"
    np.testing.assert_allclose(solution.positions[3], [0.0, 0.0], atol=1e-9)
    statics = statics_of(solution)
    assert statics.active_constraints == 3 and statics.rank == 2
    assert statics.degree_of_indeterminacy == 1 and statics.holds is False
    # Symmetric tensions T0 = T2 = T and 2 (0.8) T + T1 = 1 (vertical balance): the self-stress
    # state is (-1/1.6, 1, -1/1.6); T1 runs over [0, 1] and T over [0, 1/1.6].
    (state,) = statics.self_stress
    np.testing.assert_allclose([state["link 0"], state["link 1"], state["link 2"]], [-0.625, 1.0, -0.625], atol=1e-12)
    assert statics.ranges is not None
    np.testing.assert_allclose(statics.ranges, [[0.0, 0.625], [0.0, 1.0], [0.0, 0.625]], atol=1e-9)


def test_a_self_stress_state_balances_itself_at_every_free_node() -> None:
    solution = funicular.solve(_three_strings())
    (state,) = statics_of(solution).self_stress
    positions, links = solution.positions, solution.problem.link_nodes
    force = np.zeros(2)
    for k in range(3):
        a, b = links[k]
        unit = (positions[b] - positions[a]) / np.linalg.norm(positions[b] - positions[a])
        force += -state[f"link {k}"] * unit  # on node b = 3, pulled towards a
    np.testing.assert_allclose(force, 0.0, atol=1e-12)


def test_a_weight_on_two_strings_has_unique_forces() -> None:
    problem = funicular.Problem.build(
        nodes=3,
        links=[[0, 2, 1.0], [1, 2, 1.0]],
        supports=[(0, (-0.6, 0.8)), (1, (0.6, 0.8))],
        masses=[0.0, 0.0, 1.0],
        gravity=1.0,
    )
    statics = statics_of(funicular.solve(problem))
    assert statics.holds is True and statics.degree_of_indeterminacy == 0 and statics.self_stress == ()
    # each string carries 1 / (2 * 0.8) of the weight
    assert statics.ranges is not None
    np.testing.assert_allclose(statics.ranges, [[0.625, 0.625], [0.625, 0.625]], rtol=1e-9)


def test_the_full_check_of_a_net_reports_its_statics() -> None:
    """The check from the positions alone finds what the statics do (above, by hand): degree 1, the
    self-stress (-1/1.6, 1, -1/1.6), each tension's range; and the least total force among the
    tensions, the middle string alone (2 T + T1 = 1 + 0.4 T)."""
    solution = funicular.solve(_three_strings())
    report = funicular.check(solution.problem, solution.positions)
    assert report.licq is not None and report.licq.degree_of_indeterminacy == 1 and report.kkt_holds
    assert report.statics is not None and report.statics.degree_of_indeterminacy == 1
    (state,) = report.statics.self_stress
    np.testing.assert_allclose([state["link 0"], state["link 1"], state["link 2"]], [-0.625, 1.0, -0.625], atol=1e-12)
    assert report.statics.ranges is not None
    np.testing.assert_allclose(report.statics.ranges, [[0.0, 0.625], [0.0, 1.0], [0.0, 0.625]], atol=1e-9)
    varying = report.multiplier_ranges or ()
    assert [r.constraint for r in varying] == ["link 0", "link 1", "link 2"]
    np.testing.assert_allclose([(r.min, r.max) for r in varying], report.statics.ranges, atol=1e-12)
    assert report.multipliers is not None
    np.testing.assert_allclose(report.multipliers.link, [0.0, 1.0, 0.0], atol=1e-9)
    assert report.mfcq is not None and report.mfcq.holds  # (the self-stress mixes signs)


def _three_strings_file(tmp_path: Path) -> Path:
    scenario = tmp_path / "three.toml"
    scenario.write_text(
        "gravity = 1.0\n[net]\nnodes = 4\nmasses = [0.0, 0.0, 0.0, 1.0]\n"
        "links = [[0, 3, 1.0], [1, 3, 1.0], [2, 3, 1.0]]\n"
        + "".join(
            f"[[supports]]\nnode = {node}\nposition = [{x}, {y}]\n"
            for node, (x, y) in enumerate([(-0.6, 0.8), (0.0, 1.0), (0.6, 0.8)])
        ),
        encoding="utf-8",
    )
    return scenario


def test_solve_says_a_nets_forces_are_one_choice_among_many(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solve", str(_three_strings_file(tmp_path))]) == 0
    assert "statically indeterminate to degree 1" in capsys.readouterr().out


def test_solve_with_a_result_file_notes_the_statics_it_writes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[object] = []
    statics = funicular.checks._statics.statics

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(args)
        return statics(*args, **kwargs)

    monkeypatch.setattr(funicular.checks._statics, "statics", counted)
    path = tmp_path / "r.json"
    assert main(["solve", str(_three_strings_file(tmp_path)), "--output", str(path)]) == 0
    assert "statically indeterminate to degree 1" in capsys.readouterr().out
    assert json.loads(path.read_text())["licq"]["degree_of_indeterminacy"] == 1
    assert len(calls) == 1  # the note reads the file's statics


def test_above_the_notes_limit_solve_notes_only_what_the_sparse_proof_leaves_open(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(funicular.cli.solve, "CHECK_LICQ_UP_TO", 2)  # (every net is "large" here)
    # Three strings on one weight (degree 1, above): not proven unique, so the note says "may".
    assert main(["solve", str(_three_strings_file(tmp_path))]) == 0
    assert "may not be unique" in capsys.readouterr().out
    # A hung 8 x 8 grid: its taut links are independent (the rank of their Jacobian, built here),
    # which the proof shows: no note.
    solution = funicular.solve(funicular.nets.grid(8, 8, slack=1.2))
    m, rank, _ = _taut_jacobian_and_rank(solution.problem, solution.positions)
    assert rank == m
    grid = tmp_path / "grid.toml"
    grid.write_text('dimension = 3\n[net]\ngrid = [8, 8]\nslack = 1.2\nmass = 1.0\nsupports = "corners"\n')
    assert main(["solve", str(grid)]) == 0
    assert "multipliers " not in capsys.readouterr().out


def _solve_in_a_fresh_process(scenario: Path) -> tuple[str, set[str]]:
    """What ``funicular solve SCENARIO`` prints, and every module its process has loaded by the end."""
    code = (
        "import contextlib, io, sys\n"
        "from funicular.cli import main\n"
        "out = io.StringIO()\n"
        "with contextlib.redirect_stdout(out):\n"
        f"    assert main(['solve', {str(scenario)!r}]) == 0\n"
        "print(' '.join(sorted(sys.modules)))\n"
        "print(out.getvalue())\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    modules, _, printed = result.stdout.partition("\n")
    return printed, set(modules.split())


# The checker's modules that load SciPy's optimize: the search for self-stress states and the rest
# of the check. Deciding that a net's forces are unique needs none of them.
SEARCH_MODULES = (
    "funicular.checks._check",
    "funicular.checks._licq",
    "funicular.checks._multipliers",
    "funicular.checks._second_order",
    "scipy.optimize",
)


def test_solve_of_a_net_whose_counts_settle_its_forces_loads_no_checker(tmp_path: Path) -> None:
    """A weight on three taut strings in space from supports around it: three independent
    directions at the one free node, which the cheap count settles, so no part of the checker is
    loaded and no note printed."""
    supports = [(1.0, 0.0, 0.0), (-0.5, 0.75**0.5, 0.0), (-0.5, -(0.75**0.5), 0.0)]
    scenario = tmp_path / "hub.toml"
    scenario.write_text(
        "dimension = 3\ngravity = 1.0\n[net]\nnodes = 4\nmasses = [0.0, 0.0, 0.0, 1.0]\n"
        "links = [[0, 3, 1.2], [1, 3, 1.2], [2, 3, 1.2]]\n"
        + "".join(f"[[supports]]\nnode = {k}\nposition = {list(p)}\n" for k, p in enumerate(supports)),
        encoding="utf-8",
    )
    solution = funicular.solve(funicular.load_scenario(str(scenario)))
    # the hub hangs below the supports' centre at the depth where each 1.2 string reaches a support 1 away
    np.testing.assert_allclose(solution.positions[3], [0.0, 0.0, -((1.2**2 - 1.0) ** 0.5)], atol=1e-9)
    assert _taut_jacobian_and_rank(solution.problem, solution.positions)[:2] == (3, 3)
    assert not multipliers_may_not_be_unique(solution)
    printed, loaded = _solve_in_a_fresh_process(scenario)
    assert "status            optimal" in printed and "unique" not in printed
    assert "funicular._solver.front_end" in loaded  # (the process's modules are seen)
    assert not {module for module in loaded if module.startswith("funicular.checks")}


def test_solve_proves_a_hung_grids_forces_unique_without_searching_for_self_stress(tmp_path: Path) -> None:
    """A 20 x 20 grid hung from its corners: every free node has four taut links, more than its three
    coordinates, so counting cannot settle it; its taut links are independent (their rank, computed
    here), which one factorization proves, with none of the self-stress search loaded. Nor any of
    SciPy: the supports' reach is searched in Python, the proof factored by the solver core."""
    solution = funicular.solve(funicular.nets.grid(20, 20, slack=1.05, mass=1.0))
    m, rank, _ = _taut_jacobian_and_rank(solution.problem, solution.positions)
    assert m == solution.problem.n_links and rank == m
    assert multipliers_may_not_be_unique(solution)
    scenario = tmp_path / "grid.toml"
    scenario.write_text(
        'dimension = 3\n[net]\ngrid = [20, 20]\nslack = 1.05\nmass = 1.0\nsupports = "corners"\n', encoding="utf-8"
    )
    printed, loaded = _solve_in_a_fresh_process(scenario)
    assert "status            optimal" in printed and "unique" not in printed
    assert "funicular.checks._statics" in loaded  # (the proof ran)
    assert "funicular._solver.initial" in loaded  # (and the reach check with it)
    assert sorted(loaded.intersection(SEARCH_MODULES)) == []
    assert sorted(module for module in loaded if module.split(".")[0] == "scipy") == []


def test_a_weight_held_between_two_supports_above_and_below_has_unbounded_forces() -> None:
    """Strings of length 1 from (0, 1) and (0, -1) both reach the weight at the origin: any extra
    tension t in both balances itself (a pure-tension self-stress), so MFCQ fails and the upper
    string carries [1, inf), the lower [0, inf)."""
    problem = funicular.Problem.build(
        nodes=3,
        links=[[0, 2, 1.0], [1, 2, 1.0]],
        supports=[(0, (0.0, 1.0)), (1, (0.0, -1.0))],
        masses=[0.0, 0.0, 1.0],
        gravity=1.0,
    )
    solution = funicular.solve(problem)
    assert solution.status == "optimal"
    statics = statics_of(solution)
    assert statics.degree_of_indeterminacy == 1 and statics.mfcq is False
    assert statics.ranges is not None
    (upper_low, upper_high), (lower_low, lower_high) = statics.ranges
    assert upper_low == pytest.approx(1.0, abs=1e-9) and upper_high == np.inf
    assert lower_low == pytest.approx(0.0, abs=1e-9) and lower_high == np.inf


def test_mixed_sign_self_stress_keeps_mfcq() -> None:
    assert statics_of(funicular.solve(_three_strings())).mfcq is True


def test_check_of_a_net_reports_its_statics_and_second_order(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _three_strings_file(tmp_path)
    report = tmp_path / "report.json"
    assert main(["check", str(scenario), "--json", str(report)]) == 0
    out = capsys.readouterr().out
    assert "statically indeterminate to degree 1" in out and "MFCQ              holds" in out
    document = json.loads(report.read_text(encoding="utf-8"))
    assert document["kkt_holds"] and document["statics"]["degree_of_indeterminacy"] == 1
    # one free node held by its three strings: no feasible direction is left, a strict minimum
    assert document["second_order"]["verdict"] == "strict local minimum"


@pytest.mark.parametrize("degrees", [[137.9, 162.8, 35.1, 87.2], [15.0, 50.0, 95.0, 130.0, 170.0]])
def test_a_force_range_that_reaches_zero_says_0_not_a_rounding_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], degrees: list[float]
) -> None:
    """A weight of 2 * 9.81 hung at the origin by strings of length 1 from supports at those angles
    (all taut): each string's range is the least and the largest it carries over the vertices of
    {t >= 0, sum t_k u_k = (0, W)}, here from every pair of strings alone (a 2 x 2 system each).
    A bound that is 0 there is written and printed as 0 (it was -2.2e-16 and -0.0)."""
    angles = np.radians(degrees)
    units = np.column_stack([np.cos(angles), np.sin(angles)])
    weight = 2.0 * 9.81
    vertices = []
    for i in range(len(degrees)):
        for j in range(i + 1, len(degrees)):
            pair = np.linalg.solve(units[[i, j]].T, [0.0, weight])
            if np.all(pair >= 0.0):
                t = np.zeros(len(degrees))
                t[[i, j]] = pair
                vertices.append(t)
    low, high = np.min(vertices, axis=0), np.max(vertices, axis=0)
    assert np.count_nonzero(low == 0.0) >= 2
    lines = ["gravity = 9.81", "[net]", f"nodes = {len(degrees) + 1}", f"masses = [2.0{', 0.0' * len(degrees)}]"]
    lines.append("links = [" + ", ".join(f"[0, {k + 1}, 1.0]" for k in range(len(degrees))) + "]")
    for k, (x, y) in enumerate(units):
        lines += ["[[supports]]", f"node = {k + 1}", f"position = [{float(x)!r}, {float(y)!r}]"]
    scenario = tmp_path / "strings.toml"
    scenario.write_text("\n".join(lines) + "\n")
    out = tmp_path / "result.json"
    assert main(["solve", str(scenario), "--json", str(out)]) == 0
    ranges = json.loads(out.read_text())["licq"]["force_ranges"]
    written = np.array([ranges[f"link {k}"] for k in range(len(degrees))])
    np.testing.assert_allclose(written, np.column_stack([low, high]), rtol=1e-9, atol=1e-9 * weight)
    zeros = written[np.column_stack([low, high]) == 0.0]
    assert zeros.size >= 2 and np.all(zeros == 0.0) and not np.any(np.signbit(zeros))
    assert '"-0.0"' not in out.read_text() and "-0.0," not in out.read_text()
    capsys.readouterr()
    assert main(["check", str(scenario)]) == 0
    printed = re.findall(r"link \d+ in \[(\S+), (\S+)\]", capsys.readouterr().out)
    assert len(printed) == len(degrees)
    assert sorted(float(lo) for lo, _ in printed) == pytest.approx(sorted(low), abs=1e-9 * weight)
    assert all(lo == "0" for lo, _ in printed if abs(float(lo)) < 1e-6)


def _taut_jacobian_and_rank(problem: funicular.Problem, positions: np.ndarray) -> tuple[int, int, np.ndarray]:
    """The taut links' rows in force units over the free coordinates, built here from the
    positions: their count, their rank (dense SVD) and the matrix."""
    links = problem.link_nodes
    delta = positions[links[:, 0]] - positions[links[:, 1]]
    distance = np.linalg.norm(delta, axis=1)
    taut = np.flatnonzero(distance >= (1 - 1e-6) * problem.link_lengths)
    d = problem.dimension
    jacobian = np.zeros((taut.size, problem.n_nodes, d))
    for row, k in enumerate(taut):
        a, b = links[k]
        jacobian[row, a] += delta[k] / distance[k]
        jacobian[row, b] -= delta[k] / distance[k]
    jacobian = jacobian[:, problem.free_nodes].reshape(taut.size, -1)
    return taut.size, int(np.linalg.matrix_rank(jacobian, tol=1e-8)), jacobian


def _flat_grid(n: int) -> tuple[funicular.Problem, np.ndarray]:
    """An n x n grid net laid flat at z = 0 with every link at its length (all taut), held at its
    corners: a tension along an edge, from corner to corner, balances itself at every node."""
    problem = funicular.nets.grid(n, n, slack=1.0)
    plan = np.column_stack(np.divmod(np.arange(n * n), n)[::-1]) / (n - 1)
    return problem, np.column_stack([plan, np.zeros(n * n)])


def test_a_flat_grid_beyond_the_dense_limit_names_its_self_stress_states(monkeypatch: pytest.MonkeyPatch) -> None:
    problem, positions = _flat_grid(9)
    m, rank, jacobian = _taut_jacobian_and_rank(problem, positions)
    assert m - rank >= 4  # (at least the four edges)
    monkeypatch.setattr(funicular.checks._tolerances, "DENSE_LIMIT", 0)  # the sparse search at any size
    found = funicular.checks.statics(problem, positions)
    assert found.active_constraints == m and found.rank == rank
    assert found.degree_of_indeterminacy == m - rank and found.holds is False
    assert len(found.self_stress) == min(m - rank, 10)
    taut = [f"link {k}" for k in range(problem.n_links)]
    for state in found.self_stress:
        weights = np.array([state.get(name, 0.0) for name in taut])
        np.testing.assert_allclose(jacobian.T @ weights, 0.0, atol=1e-9)  # balanced at every free node
        assert np.max(np.abs(weights)) == pytest.approx(1.0)


def test_a_hung_grid_beyond_the_dense_limit_is_proven_determinate(monkeypatch: pytest.MonkeyPatch) -> None:
    solution = funicular.solve(funicular.nets.grid(10, 10, slack=1.2))
    m, rank, _ = _taut_jacobian_and_rank(solution.problem, solution.positions)
    assert rank == m  # the hanging net's taut links are independent
    monkeypatch.setattr(funicular.checks._tolerances, "DENSE_LIMIT", 0)
    found = statics_of(solution)
    assert found.active_constraints == m and found.rank == m and found.holds is True
    assert found.degree_of_indeterminacy == 0 and found.mfcq is True and found.self_stress == ()


def test_the_sparse_statics_agree_with_the_dense_on_strings_a_link_between_supports_and_a_sphere(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The same statics by the dense decomposition and (DENSE_LIMIT = 0) by the sparse one: three
    strings on a weight (degree 1, a few rows: their SVD), a taut link between two supports (a
    self-stress of its own, a pure tension: MFCQ fails) beside a weight on a string, and the net over
    the sphere (links and contacts, all independent)."""
    between = funicular.Problem.build(
        nodes=3,
        links=[[0, 1, 1.0], [0, 2, 1.0]],
        supports=[(0, (0.0, 0.0, 0.0)), (1, (1.0, 0.0, 0.0))],
        masses=[0.0, 0.0, 1.0],
        gravity=1.0,
        dimension=3,
    )
    cases = [
        (_three_strings(), funicular.solve(_three_strings()).positions),
        (between, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])),
    ]
    sphere = funicular.solve(funicular.load_scenario("net-over-sphere"))
    cases.append((sphere.problem, sphere.positions))
    dense = [funicular.checks.statics(problem, positions) for problem, positions in cases]
    monkeypatch.setattr(funicular.checks._tolerances, "DENSE_LIMIT", 0)
    sparse = [funicular.checks.statics(problem, positions) for problem, positions in cases]
    for a, b in zip(dense, sparse, strict=True):
        assert (a.active_constraints, a.rank, a.mfcq) == (b.active_constraints, b.rank, b.mfcq)
        assert len(a.self_stress) == len(b.self_stress)
    strings, link, net = sparse
    assert strings.degree_of_indeterminacy == 1
    (state,) = strings.self_stress
    np.testing.assert_allclose([state["link 0"], state["link 1"], state["link 2"]], [-0.625, 1.0, -0.625], atol=1e-12)
    assert link.rank == 1 and link.self_stress == ({"link 0": 1.0},) and link.mfcq is False
    assert net.holds is True and any(name.startswith("sphere") for name in net.names)


def test_a_thirty_by_thirty_net_is_decided_without_the_dense_decomposition() -> None:
    solution = funicular.solve(funicular.nets.grid(30, 30, slack=1.2))
    links = solution.problem.link_nodes
    delta = solution.positions[links[:, 0]] - solution.positions[links[:, 1]]
    distance = np.linalg.norm(delta, axis=1)
    taut = np.flatnonzero(distance >= (1 - 1e-6) * solution.problem.link_lengths)
    assert funicular.checks._tolerances.DENSE_LIMIT < 3 * (30 * 30 - 4)  # (past the dense limit)
    # Full row rank from the Gram matrix of the unit rows, built here: links k and l share a node
    # with signs +-1 on either end; the smallest eigenvalue is far from zero.
    unit = delta[taut] / distance[taut, None]
    free = ~solution.problem.is_support
    gram = np.zeros((taut.size, taut.size))
    for end_k, sign_k in ((0, 1.0), (1, -1.0)):
        for end_l, sign_l in ((0, 1.0), (1, -1.0)):
            nodes_k, nodes_l = links[taut, end_k], links[taut, end_l]
            shared = (nodes_k[:, None] == nodes_l[None, :]) & free[nodes_k][:, None]
            gram += sign_k * sign_l * shared * (unit @ unit.T)
    assert np.linalg.eigvalsh(gram)[0] > 1e-6
    found = statics_of(solution)
    assert found.active_constraints == taut.size and found.rank == taut.size and found.holds is True
