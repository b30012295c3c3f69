"""The check of a net or a chain in space at a point read from positions alone: tensions and contact
forces recovered from force balance, the KKT residuals with them, and the second-order verdict,
against hand calculations (statics of strings at known angles, a pendulum's and a ball's curvature)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import funicular
from funicular.checks import check_structure, recover_multipliers
from funicular.checks._second_order import CURVATURE_UP_TO
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
    report = check_structure(problem, positions)
    assert report.multiplier_source == "recovered" and report.kkt_holds
    np.testing.assert_allclose(report.multipliers.link, 3.0 / (3 * RISE), rtol=1e-12)
    np.testing.assert_allclose(_unbalanced(problem, positions, report.multipliers.link), 0.0, atol=1e-12)
    assert report.statics.holds is True


def test_four_strings_share_a_weight_within_the_range_statics_allow() -> None:
    """Opposite strings carry equal tensions a and b (horizontal balance) and 2 (0.8)(a + b) = 1
    (vertical): one equation for two unknowns, so each tension lies in [0, 1 / 1.6]."""
    problem = _strings([(0.6, 0.0, RISE), (-0.6, 0.0, RISE), (0.0, 0.6, RISE), (0.0, -0.6, RISE)])
    positions = _at_rest(problem)
    report = check_structure(problem, positions)
    t = report.multipliers.link
    assert report.statics.degree_of_indeterminacy == 1 and report.kkt_holds
    assert np.all(t >= 0.0) and np.all(t <= 1.0 / (2 * RISE) + 1e-12)
    assert t[0] == pytest.approx(t[1], abs=1e-12) and t[2] == pytest.approx(t[3], abs=1e-12)
    assert 2 * RISE * (t[0] + t[2]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(_unbalanced(problem, positions, t), 0.0, atol=1e-12)


def test_an_indeterminate_net_gets_the_least_total_force() -> None:
    """Three strings in the plane, the middle one vertical: T0 = T2 = T and 1.6 T + T1 = 1, so the
    total 2 T + T1 = 1 + 0.4 T is least with the middle string alone: (0, 1, 0)."""
    problem = _strings([(-0.6, RISE), (0.0, 1.0), (0.6, RISE)])
    report = check_structure(problem, _at_rest(problem))
    np.testing.assert_allclose(report.multipliers.link, [0.0, 1.0, 0.0], atol=1e-12)
    assert report.statics.ranges is not None
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
    assert check_structure(problem, positions).kkt_holds


def test_a_pendulum_out_of_balance_is_not_a_kkt_point() -> None:
    """Swung 30 degrees about the line through its two supports, the weight keeps both strings taut,
    but they can only pull in their own plane: the part of its weight across that plane, 0.5 along
    (0, cos 30, sin 30), is left unbalanced (the residual is its largest component)."""
    problem = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    positions = _at_rest(problem)
    swing = np.radians(30.0)
    positions[2] = [0.0, RISE * np.sin(swing), RISE - RISE * np.cos(swing)]
    report = check_structure(problem, positions)
    assert report.feasible and not report.kkt_holds
    assert np.all(report.multipliers.link >= 0.0)
    (unbalanced,) = _unbalanced(problem, positions, report.multipliers.link)
    np.testing.assert_allclose(unbalanced, -0.5 * np.array([0.0, np.cos(swing), np.sin(swing)]), atol=1e-12)
    assert report.residuals.stationarity == pytest.approx(0.5 * np.cos(swing), abs=1e-12)


def test_a_pendulum_in_space_is_a_strict_minimum() -> None:
    """Hung by two strings in the plane y = 0, the weight swings across it: the strings' curvature
    along y is 2 T / l = 2 (0.625) / 1."""
    problem = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    report = check_structure(problem, _at_rest(problem))
    assert report.second_order.startswith("strict local minimum")
    assert report.curvature == pytest.approx(2 * 0.625, rel=1e-12)


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
    report = check_structure(problem, positions)
    assert report.kkt_holds and report.statics.holds
    np.testing.assert_allclose(report.multipliers.link, [0.0, 0.0, 0.6 / RISE], atol=1e-12)
    np.testing.assert_allclose(report.multipliers.obstacle[0], [0.0, 0.0, 1 / RISE, 1 / RISE], atol=1e-12)
    assert report.second_order.startswith("not a minimum")
    assert report.curvature == pytest.approx(-1.25, rel=1e-9)
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
    assert document["second_order"].startswith("strict local minimum")


def test_check_of_a_points_given_multipliers_gets_a_second_order_verdict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _held_at_rise(-1) + "[chain]\nnodes = 3\nlink_length = 1.0\nmasses = [0.0, 1.0, 0.0]\n"
    given = {"x": [-0.6, 0.0, 0.6], "y": [0.0, 0.0, 0.0], "z": [0.8, 0.0, 0.8], "multipliers": {"link": [0.625, 0.625]}}
    assert _check_files(tmp_path, scenario, given) == 0
    out = capsys.readouterr().out
    assert "with multipliers" in out and "multipliers             given" in out
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
    assert 3 * (side * side - 4) > CURVATURE_UP_TO
    x, y = np.meshgrid(np.arange(side, dtype=float), np.arange(side, dtype=float))
    positions = np.column_stack([x.ravel(), y.ravel(), np.zeros(side * side)])
    report = check_structure(problem, positions)
    # Every link is slack: nothing holds the weight up, and no force is recovered.
    assert report.statics.active_constraints == 0 and not report.kkt_holds
    assert report.residuals.stationarity == pytest.approx(1.0 / (side * side), rel=1e-12)
    # Second-order conditions are stated at KKT points: this one is not (its residual is the weight
    # of a node, 1 / 25^2, scaled by the weight 1).
    assert report.second_order.startswith("undecided (not a KKT point") and "1.60e-03" in report.second_order
    assert report.curvature is None


def test_above_the_dense_limit_the_sparse_tests_tell_the_minima_from_a_saddle(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With the dense curvature switched off, the pendulum (curvature 1.25, above) and a hung
    20 x 20 net (a minimum by the dense test first) are proven strict minima by the sparse penalty
    test, and the pair on the ball's top is found to curve down by -1.25, as worked out above."""
    pendulum = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    net = funicular.solve(funicular.nets.grid(20, 20, slack=1.2))
    given = funicular.checks.Multipliers(net.link_multipliers, net.obstacle_multipliers)
    assert check_structure(net.problem, net.positions, given).second_order.startswith("strict local minimum")
    pair, on_the_ball = _pair_on_a_ball()
    monkeypatch.setattr(funicular.checks._second_order, "CURVATURE_UP_TO", 0)
    for report in (
        check_structure(pendulum, _at_rest(pendulum)),
        check_structure(net.problem, net.positions, given),
    ):
        assert report.second_order.startswith("strict local minimum") and "penalty" in report.second_order
    saddle = check_structure(pair, on_the_ball)
    assert saddle.second_order.startswith("not a minimum")
    assert saddle.curvature == pytest.approx(-1.25, rel=1e-9)


def test_the_penalty_test_proves_the_net_over_the_sphere_a_minimum_as_the_dense_test_does(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With contacts (their rows in the penalty, the sphere's curvature in the Hessian)."""
    solution = funicular.solve(funicular.load_scenario("net-over-sphere"))
    given = funicular.checks.Multipliers(solution.link_multipliers, solution.obstacle_multipliers)
    dense = check_structure(solution.problem, solution.positions, given)
    assert dense.second_order.startswith("strict local minimum") and dense.curvature is not None
    monkeypatch.setattr(funicular.checks._second_order, "CURVATURE_UP_TO", 0)
    sparse = check_structure(solution.problem, solution.positions, given)
    assert sparse.second_order.startswith("strict local minimum") and "penalty" in sparse.second_order


def test_tripled_tensions_are_not_a_kkt_point_and_get_no_second_order_verdict() -> None:
    """Three times the equilibrium's tensions pull every free node of a hung net off balance (by twice
    the link forces): no KKT point, so no second-order verdict, planar or in space."""
    net = funicular.solve(funicular.nets.grid(10, 10, slack=1.2))
    tripled = funicular.checks.Multipliers(3 * net.link_multipliers, net.obstacle_multipliers)
    report = check_structure(net.problem, net.positions, tripled)
    assert not report.kkt_holds and report.second_order.startswith("undecided (not a KKT point")
    chain = funicular.solve(funicular.load_scenario("two-supports"))
    planar = funicular.check(
        chain.problem,
        chain.positions,
        funicular.checks.Multipliers(3 * chain.link_multipliers, chain.obstacle_multipliers),
    )
    assert not planar.kkt_holds and planar.second_order is not None
    assert planar.second_order.verdict == "undecided" and "not a KKT point" in planar.second_order.reason


def test_check_structure_refuses_points_and_multipliers_of_the_wrong_shape() -> None:
    problem = _strings([(-0.6, 0.0, RISE), (0.6, 0.0, RISE)])
    with pytest.raises(funicular.ScenarioError, match="positions must be 3 finite points of 3 coordinates"):
        check_structure(problem, np.zeros((3, 2)))
    wrong = funicular.checks.Multipliers(np.zeros(3), np.zeros((0, 3)))
    with pytest.raises(funicular.ScenarioError, match="multipliers must have 2 link"):
        check_structure(problem, _at_rest(problem), wrong)


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
