"""The check (``funicular.check``, the one checker of every problem) of a net or a chain in space at a
point read from positions alone: tensions and contact forces recovered from force balance, the KKT
residuals with them, the statics and the second-order verdict, against hand calculations (statics
of strings at known angles, a pendulum's and a ball's curvature)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import funicular
import funicular.checks._tolerances
from funicular.checks import check, recover_multipliers
from funicular.cli import main
from funicular.obstacles import Sphere

# A weight hung from supports 0.8 above it and 0.6 to the side, by strings of length 1: each string
# rises at sin = 0.8, so n strings sharing the weight W equally carry W / (0.8 n) each.
RISE = 0.8


def _strings(supports: list[tuple[float, ...]], weight: float = 1.0) -> funicular.Problem:
    """A weight at the origin (the last node) on a string of length 1 from each support."""
    n = len(supports)
    return funicular.Problem.build(
        nodes=n + 1,
        links=[[k, n, 1.0] for k in range(n)],
        supports=list(enumerate(supports)),
        masses=[0.0] * n + [weight],
        gravity=1.0,
        dimension=len(supports[0]),
    )


def _at_rest(problem: funicular.Problem) -> np.ndarray:
    """The supports where they are held, every free node at the origin."""
    positions = np.zeros((problem.n_nodes, problem.dimension))
    positions[problem.support_nodes] = problem.support_positions
    return positions


def _unbalanced(problem: funicular.Problem, positions: np.ndarray, tension: np.ndarray) -> np.ndarray:
    """Gravity plus the pull of every link on each free node, summed here link by link."""
    force = np.zeros_like(positions)
    force[:, -1] -= problem.gravity * problem.masses
    for (a, b), t in zip(problem.link_nodes, tension, strict=True):
        unit = (positions[b] - positions[a]) / np.linalg.norm(positions[b] - positions[a])
        force[a] += t * unit  # a link pulls each of its nodes towards the other
        force[b] -= t * unit
    return force[problem.free_nodes]


def test_a_tripod_gets_its_tensions_from_the_positions_alone() -> None:
    angles = np.radians([90.0, 210.0, 330.0])
    problem = _strings([(0.6 * np.cos(a), 0.6 * np.sin(a), RISE) for a in angles], weight=3.0)
    positions = _at_rest(problem)
    report = check(problem, positions)
    assert report.multiplier_source == "recovered" and report.kkt_holds
    np.testing.assert_allclose(report.multipliers.link, 3.0 / (3 * RISE), rtol=1e-12)
    np.testing.assert_allclose(_unbalanced(problem, positions, report.multipliers.link), 0.0, atol=1e-12)
    assert report.statics is not None and report.statics.holds is True


def _triple(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """The determinant of the columns a, b, c: a . (b x c)."""
    return float(np.dot(a, np.cross(b, c)))


def test_a_hub_on_three_uneven_supports_carries_the_tensions_cramers_rule_gives() -> None:
    """A weight of 2 at the origin on three strings, each exactly as long as the way to its support:
    the tensions T solve sum_i T_i u_i = (0, 0, 2), u_i the unit vectors towards the supports (three
    equations, three unknowns: Cramer's rule here). The supports' plan surrounds the origin, so
    every T_i > 0; the strings fix the hub (three independent rows in three coordinates): LICQ holds,
    the forces are unique, and no move is left, so the point is a strict minimum."""
    supports = np.array([[1.0, 0.0, 1.0], [-0.5, 1.0, 2.0], [-0.4, -1.2, 1.5]])
    lengths = np.linalg.norm(supports, axis=1)
    problem = funicular.Problem.build(
        nodes=4,
        links=[[k, 3, float(lengths[k])] for k in range(3)],
        supports=[(k, tuple(supports[k])) for k in range(3)],
        masses=[0.0, 0.0, 0.0, 2.0],
        gravity=1.0,
        dimension=3,
    )
    u = supports / lengths[:, None]
    load = np.array([0.0, 0.0, 2.0])
    det = _triple(u[0], u[1], u[2])
    tension = np.array([_triple(load, u[1], u[2]), _triple(u[0], load, u[2]), _triple(u[0], u[1], load)]) / det
    assert np.all(tension > 0.1)
    recovered = check(problem, np.vstack([supports, np.zeros(3)]))
    solved = funicular.checks.check_solution(funicular.solve(problem))
    for report, rtol in ((recovered, 1e-12), (solved, 1e-9)):
        assert report.kkt_holds and report.multipliers is not None
        np.testing.assert_allclose(report.multipliers.link, tension, rtol=rtol)
        assert report.licq is not None and report.licq.holds and report.licq.rank == 3
        assert report.statics is not None and report.statics.degree_of_indeterminacy == 0
        assert report.mfcq is not None and report.mfcq.holds and report.multiplier_ranges == ()
        assert report.second_order is not None and report.second_order.verdict == "strict local minimum"
        assert report.second_order.min_eigenvalue == np.inf  # (nothing can move)


def test_the_net_over_the_sphere_is_checked_from_its_positions_alone() -> None:
    """The built-in net-over-sphere, from the solver's positions alone: its taut links and contacts
    are independent (LICQ), so the forces that balance every free node are unique, and the ones
    recovered here are the solver's; the balance is recomputed here node by node, contact forces
    along the sphere's outward normal included."""
    solution = funicular.solve(funicular.load_scenario("net-over-sphere"))
    problem, positions = solution.problem, solution.positions
    report = check(problem, positions)
    assert report.multiplier_source == "recovered" and report.kkt_holds and report.multipliers is not None
    assert report.licq is not None and report.licq.holds and report.mfcq is not None and report.mfcq.holds
    assert report.active is not None and report.licq.rank == report.active.links.size + len(report.active.contacts)
    tension = report.multipliers.link
    np.testing.assert_allclose(tension, solution.link_multipliers, atol=1e-9 * problem.weight)
    (sphere,) = problem.obstacles
    outward = positions - np.asarray(sphere.center)
    outward /= np.linalg.norm(outward, axis=1)[:, None]
    force = np.zeros_like(positions)
    force[:, -1] -= problem.gravity * problem.masses
    for (a, b), t in zip(problem.link_nodes, tension, strict=True):
        unit = (positions[b] - positions[a]) / np.linalg.norm(positions[b] - positions[a])
        force[a] += t * unit
        force[b] -= t * unit
    contact = report.multipliers.obstacle[0] * np.linalg.norm(sphere.evaluate(positions)[1], axis=1)
    force += contact[:, None] * outward
    np.testing.assert_allclose(force[problem.free_nodes], 0.0, atol=1e-9 * problem.weight)
    assert report.second_order is not None and report.second_order.verdict == "strict local minimum"
    assert report.second_order.min_eigenvalue > 0


def test_four_strings_share_a_weight_within_the_range_statics_allow() -> None:
    """Opposite strings carry equal tensions a and b (horizontal balance) and 2 (0.8)(a + b) = 1
    (vertical): one equation for two unknowns, so each tension lies in [0, 1 / 1.6]."""
    problem = _strings([(0.6, 0.0, RISE), (-0.6, 0.0, RISE), (0.0, 0.6, RISE), (0.0, -0.6, RISE)])
    positions = _at_rest(problem)
    report = check(problem, positions)
    t = report.multipliers.link
    assert report.statics is not None and report.statics.degree_of_indeterminacy == 1 and report.kkt_holds
    assert np.all(t >= 0.0) and np.all(t <= 1.0 / (2 * RISE) + 1e-12)
    assert t[0] == pytest.approx(t[1], abs=1e-12) and t[2] == pytest.approx(t[3], abs=1e-12)
    assert 2 * RISE * (t[0] + t[2]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(_unbalanced(problem, positions, t), 0.0, atol=1e-12)


def test_an_indeterminate_net_gets_the_least_total_force() -> None:
    """Three strings in the plane, the middle one vertical: T0 = T2 = T and 1.6 T + T1 = 1, so the
    total 2 T + T1 = 1 + 0.4 T is least with the middle string alone: (0, 1, 0)."""
    problem = _strings([(-0.6, RISE), (0.0, 1.0), (0.6, RISE)])
    report = check(problem, _at_rest(problem))
    np.testing.assert_allclose(report.multipliers.link, [0.0, 1.0, 0.0], atol=1e-12)
    assert report.statics is not None and report.statics.ranges is not None
    for t, (low, high) in zip(report.multipliers.link, report.statics.ranges, strict=True):
        assert low - 1e-12 <= t <= high + 1e-12


def test_a_chain_in_space_recovers_its_tensions_in_the_squared_formulation() -> None:
    """A 3-D chain of two links of length 1 from (+-0.6, 0, 0.8), its middle node of unit weight at
    the origin: T = 1 / 1.6 in each link, mu = T / (2 d) = T / 2 in the squared formulation."""
    problem = funicular.Problem.build(
        nodes=3,
        supports=[(0, (-0.6, 0.0, RISE)), (2, (0.6, 0.0, RISE))],
        link_length=1.0,
        masses=[0.0, 1.0, 0.0],
        gravity=1.0,
        formulation="squared",
        dimension=3,
    )
    positions = np.array([[-0.6, 0.0, RISE], [0.0, 0.0, 0.0], [0.6, 0.0, RISE]])
    multipliers = recover_multipliers(problem, positions)
    np.testing.assert_allclose(multipliers.link, 1.0 / (2 * RISE) / 2, rtol=1e-12)
    report = check(problem, positions)
    assert report.kkt_holds and report.licq is not None and report.licq.holds and report.licq.rank == 2
    # The two links fix the middle node but for its swing across their plane (along y), where each
    # link curves the energy by T / d = 0.625 (in both formulations: the squared one's 2 mu = T / d).
    assert report.second_order is not None and report.second_order.verdict == "strict local minimum"
    assert report.second_order.min_eigenvalue == pytest.approx(2 * 0.625, rel=1e-12)


def test_a_pendulum_out_of_balance_is_not_a_kkt_point() -> None:
    """Swung 30 degrees about the line through its two supports, the weight keeps both strings taut,
    but they can only pull in their own plane: the part of its weight across that plane, 0.5 along
    (0, cos 30, sin 30), is left unbalanced (the residual is its largest component)."""
    problem = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    positions = _at_rest(problem)
    swing = np.radians(30.0)
    positions[2] = [0.0, RISE * np.sin(swing), RISE - RISE * np.cos(swing)]
    report = check(problem, positions)
    assert report.feasible and not report.kkt_holds
    assert np.all(report.multipliers.link >= 0.0)
    (unbalanced,) = _unbalanced(problem, positions, report.multipliers.link)
    np.testing.assert_allclose(unbalanced, -0.5 * np.array([0.0, np.cos(swing), np.sin(swing)]), atol=1e-12)
    assert report.kkt is not None  # (unit weight: the residual in force units is the scaled one)
    assert report.kkt.stationarity == pytest.approx(0.5 * np.cos(swing), abs=1e-12)


def test_a_pendulum_in_space_is_a_strict_minimum() -> None:
    """Hung by two strings in the plane y = 0, the weight swings across it: the strings' curvature
    along y is 2 T / l = 2 (0.625) / 1."""
    problem = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    report = check(problem, _at_rest(problem))
    assert report.second_order is not None and report.second_order.verdict == "strict local minimum"
    assert report.second_order.min_eigenvalue == pytest.approx(2 * 0.625, rel=1e-12)


def _pair_on_a_ball() -> tuple[funicular.Problem, np.ndarray]:
    """Two unit weights on the unit sphere at (+-0.6, 0, 0.8), tied by a taut link of length 1.2,
    with slack links to far supports: each node's contact force 1 / 0.8 along its normal balances
    its weight and the link's tension 0.6 / 0.8."""
    ball = Sphere(name="ball", center=(0.0, 0.0, 0.0), radius=1.0)
    problem = funicular.Problem.build(
        nodes=4,
        links=[[0, 2, 5.0], [1, 3, 5.0], [2, 3, 1.2]],
        supports=[(0, (-3.0, 0.0, 0.0)), (1, (3.0, 0.0, 0.0))],
        masses=[0.0, 0.0, 1.0, 1.0],
        gravity=1.0,
        dimension=3,
        obstacles=[ball],
    )
    positions = np.array([[-3.0, 0.0, 0.0], [3.0, 0.0, 0.0], [-0.6, 0.0, RISE], [0.6, 0.0, RISE]])
    return problem, positions


def test_a_pair_on_a_balls_top_gets_its_contact_forces_and_rolls_off() -> None:
    """A common sideways move y of both nodes keeps the link's length; on each node the contact adds
    -nu |y|^2 to the curvature, nu = (1 / 0.8) / |grad phi| = 1.25 (phi = (1 - |p|^2) / 2): the
    smallest curvature is -1.25, and the point is a saddle."""
    problem, positions = _pair_on_a_ball()
    report = check(problem, positions)
    assert report.kkt_holds and report.statics is not None and report.statics.holds
    assert report.multipliers is not None
    np.testing.assert_allclose(report.multipliers.link, [0.0, 0.0, 0.6 / RISE], atol=1e-12)
    np.testing.assert_allclose(report.multipliers.obstacle[0], [0.0, 0.0, 1 / RISE, 1 / RISE], atol=1e-12)
    assert report.second_order is not None and report.second_order.verdict == "not a minimum"
    assert report.second_order.min_eigenvalue == pytest.approx(-1.25, rel=1e-9)
    # A saddle indeed: turning both nodes about the x axis keeps them on the sphere and the link's
    # length, and lowers them.
    turn = np.radians(1.0)
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(turn), -np.sin(turn)], [0.0, np.sin(turn), np.cos(turn)]])
    turned = positions.copy()
    turned[2:] = positions[2:] @ rotation.T
    assert np.linalg.norm(turned[3] - turned[2]) == pytest.approx(1.2, abs=1e-12)
    assert problem.energy(turned) < problem.energy(positions)


def _held_at_rise(last: int) -> str:
    """A scenario's header and its two supports at (-0.6, 0, RISE) and (0.6, 0, RISE): nodes 0 and ``last``."""
    return (
        "dimension = 3\ngravity = 1.0\n"
        "[[supports]]\nnode = 0\nposition = [-0.6, 0.0, 0.8]\n"
        f"[[supports]]\nnode = {last}\nposition = [0.6, 0.0, 0.8]\n"
    )


def _check_files(tmp_path: Path, scenario: str, point: dict[str, Any], *options: str) -> int:
    """``funicular check`` of ``scenario`` (its TOML) at ``point`` (a JSON document): the exit status."""
    (tmp_path / "scenario.toml").write_text(scenario, encoding="utf-8")
    (tmp_path / "point.json").write_text(json.dumps(point), encoding="utf-8")
    return main(["check", str(tmp_path / "scenario.toml"), "--solution", str(tmp_path / "point.json"), *options])


def test_check_of_a_nets_point_without_multipliers_recovers_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _held_at_rise(1) + "[net]\nnodes = 3\nmasses = [0.0, 0.0, 1.0]\nlinks = [[0, 2, 1.0], [1, 2, 1.0]]\n"
    point = {"positions": [[-0.6, 0.0, 0.8], [0.6, 0.0, 0.8], [0.0, 0.0, 0.0]]}
    report = tmp_path / "report.json"
    assert _check_files(tmp_path, scenario, point, "--json", str(report)) == 0
    assert "without multipliers" in capsys.readouterr().out
    document = json.loads(report.read_text(encoding="utf-8"))
    assert document["multipliers"]["source"] == "recovered" and document["kkt_holds"]
    np.testing.assert_allclose(document["multipliers"]["link"], [0.625, 0.625], rtol=1e-12)
    assert document["second_order"]["verdict"] == "strict local minimum"


def test_check_of_a_points_given_multipliers_gets_a_second_order_verdict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _held_at_rise(-1) + "[chain]\nnodes = 3\nlink_length = 1.0\nmasses = [0.0, 1.0, 0.0]\n"
    given = {"x": [-0.6, 0.0, 0.6], "y": [0.0, 0.0, 0.0], "z": [0.8, 0.0, 0.8], "multipliers": {"link": [0.625, 0.625]}}
    assert _check_files(tmp_path, scenario, given) == 0
    out = capsys.readouterr().out
    assert "with multipliers" in out and "multipliers       given" in out
    assert "strict local minimum" in out and "smallest curvature 1.25" in out


def _flat_grid(side: int) -> funicular.Problem:
    """A side x side net of unit weight, hung from its corners, its links far longer than the spacing."""
    index = np.arange(side * side).reshape(side, side)
    pairs = np.concatenate(
        [
            np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()]),
            np.column_stack([index[:-1].ravel(), index[1:].ravel()]),
        ]
    )
    corners = [(int(index[i, j]), (float(j), float(i), 0.0)) for i in (0, side - 1) for j in (0, side - 1)]
    return funicular.Problem.build(
        nodes=side * side,
        links=[[int(a), int(b)] for a, b in pairs],
        link_length=2.0,
        supports=corners,
        mass=1.0,
        gravity=1.0,
        dimension=3,
    )


def test_a_large_nets_second_order_away_from_a_kkt_point_is_undecided_and_says_why() -> None:
    side = 25  # 621 free nodes: more free coordinates than the dense curvature takes
    problem = _flat_grid(side)
    assert 3 * (side * side - 4) > funicular.checks._tolerances.DENSE_LIMIT
    x, y = np.meshgrid(np.arange(side, dtype=float), np.arange(side, dtype=float))
    positions = np.column_stack([x.ravel(), y.ravel(), np.zeros(side * side)])
    report = check(problem, positions)
    # Every link is slack: nothing holds the weight up, and no force is recovered.
    assert report.statics is not None and report.statics.active_constraints == 0 and not report.kkt_holds
    assert report.kkt is not None  # (unit weight: the residual in force units is the scaled one)
    assert report.kkt.stationarity == pytest.approx(1.0 / (side * side), rel=1e-12)
    # Second-order conditions are stated at KKT points: this one is not (its residual is the weight
    # of a node, 1 / 25^2, scaled by the weight 1).
    assert report.second_order is not None and report.second_order.verdict == "undecided"
    assert report.second_order.reason.startswith("not a KKT point") and "1.60e-03" in report.second_order.reason
    assert np.isnan(report.second_order.min_eigenvalue)


def _dense_and_sparse(
    monkeypatch: pytest.MonkeyPatch, second_order: Callable[..., funicular.checks.SecondOrder | None], *args: Any
) -> tuple[funicular.checks.SecondOrder, funicular.checks.SecondOrder]:
    """``second_order(*args)``, a verdict of the checker, on dense matrices at any size, then by the
    sparse method at any size (the bordered matrix's shift-invert Lanczos)."""
    found = []
    for limit in (10**6, 0):
        with monkeypatch.context() as patch:
            patch.setattr(funicular.checks._tolerances, "DENSE_LIMIT", limit)
            second = second_order(*args)
        assert second is not None
        found.append(second)
    return found[0], found[1]


def _checked_verdict(problem: funicular.Problem, positions: np.ndarray) -> funicular.checks.SecondOrder | None:
    return check(problem, positions).second_order


def test_the_sparse_curvature_is_the_dense_one_and_the_hand_computed_one(monkeypatch: pytest.MonkeyPatch) -> None:
    """The pendulum (curvature 1.25, above) and the pair on the ball's top (-1.25, above) by the
    dense and the sparse method alike, and a hung 20 x 20 net's curvature the same by both."""
    pendulum = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    pair, on_the_ball = _pair_on_a_ball()
    for problem, positions, expected, verdict in (
        (pendulum, _at_rest(pendulum), 1.25, "strict local minimum"),
        (pair, on_the_ball, -1.25, "not a minimum"),
    ):
        for second in _dense_and_sparse(monkeypatch, _checked_verdict, problem, positions):
            assert second.verdict == verdict
            assert second.min_eigenvalue == pytest.approx(expected, rel=1e-9)
    net = funicular.solve(funicular.nets.grid(20, 20, slack=1.2))
    dense, sparse = _dense_and_sparse(monkeypatch, funicular.checks.second_order, net.problem, net)
    assert dense.verdict == sparse.verdict == "strict local minimum"
    assert sparse.min_eigenvalue == pytest.approx(dense.min_eigenvalue, rel=1e-8) and dense.min_eigenvalue > 0
    assert funicular.checks.proves_strict_minimum(net.problem, net)  # (and the penalty test proves it)


def test_the_net_over_the_sphere_has_the_same_curvature_by_the_dense_and_the_sparse_method(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With contacts (their rows in the bordered matrix and the penalty, the sphere's curvature in
    the Hessian and the shift below it)."""
    solution = funicular.solve(funicular.load_scenario("net-over-sphere"))
    dense, sparse = _dense_and_sparse(monkeypatch, funicular.checks.second_order, solution.problem, solution)
    assert dense.verdict == sparse.verdict == "strict local minimum" and dense.min_eigenvalue > 0
    assert sparse.min_eigenvalue == pytest.approx(dense.min_eigenvalue, rel=1e-8)
    assert funicular.checks.proves_strict_minimum(solution.problem, solution)
    proven = funicular.checks.second_order(solution.problem, solution, proof=True)
    assert proven.verdict == "strict local minimum" and "penalty" in proven.reason


def test_tripled_tensions_are_not_a_kkt_point_and_get_no_second_order_verdict() -> None:
    """Three times the equilibrium's tensions pull every free node of a hung net off balance (by twice
    the link forces): no KKT point, so no second-order verdict, planar or in space."""
    net = funicular.solve(funicular.nets.grid(10, 10, slack=1.2))
    tripled = funicular.checks.Multipliers(3 * net.link_multipliers, net.obstacle_multipliers)
    report = check(net.problem, net.positions, tripled)
    assert not report.kkt_holds and report.second_order is not None and report.second_order.verdict == "undecided"
    assert report.second_order.reason.startswith("not a KKT point")
    chain = funicular.solve(funicular.load_scenario("two-supports"))
    planar = funicular.check(
        chain.problem,
        chain.positions,
        funicular.checks.Multipliers(3 * chain.link_multipliers, chain.obstacle_multipliers),
    )
    assert not planar.kkt_holds and planar.second_order is not None
    assert planar.second_order.verdict == "undecided" and "not a KKT point" in planar.second_order.reason


def test_the_check_refuses_points_and_multipliers_of_the_wrong_shape() -> None:
    problem = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    with pytest.raises(funicular.ScenarioError, match=r"positions must be 3 finite \(x, y, z\) points"):
        check(problem, np.zeros((3, 2)))
    wrong = funicular.checks.Multipliers(np.zeros(3), np.zeros((0, 3)))
    with pytest.raises(funicular.ScenarioError, match="multipliers must have 2 link"):
        check(problem, _at_rest(problem), wrong)


def test_check_of_a_nets_point_of_the_wrong_size_is_refused_in_one_sentence(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = (
        "gravity = 1.0\n[net]\nnodes = 3\nmasses = [0.0, 0.0, 1.0]\nlinks = [[0, 2, 1.0], [1, 2, 1.0]]\n"
        "[[supports]]\nnode = 0\nposition = [-0.6, 0.8]\n[[supports]]\nnode = 1\nposition = [0.6, 0.8]\n"
    )
    assert _check_files(tmp_path, scenario, {"x": [-0.6, 0.6], "y": [0.8, 0.8]}) == 2
    err = capsys.readouterr().err
    assert "x has 2 entries, but the scenario has 3 nodes" in err and "Traceback" not in err
