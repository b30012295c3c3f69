"""Scenarios on which funicular once answered wrongly, misleadingly or not at all
(tests/data/cases/, with what a right answer is in its README): each answer is checked against
force balance recomputed here, the geometry of the obstacles, or a conic solver.
"""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import funicular
from funicular import InfeasibleError, Problem, Sphere, load_scenario, solve
from funicular.obstacles import HalfSpace
from test_nets import assert_equilibrium, assert_sphere_contacts, clarabel_optimum, delaunay_net

CASES = Path(__file__).parent / "data" / "cases"


def case(name: str) -> Problem:
    return load_scenario(str(CASES / f"{name}.toml"))


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "funicular.cli", *args], capture_output=True, text=True, check=False, timeout=300
    )


# ----------------------------------------------------------------- contacts and slack links as they are
def test_only_the_nodes_on_the_sphere_carry_a_contact_force_and_slack_links_no_tension() -> None:
    problem = case("phantom-contacts-grid-12x20")
    (sphere,) = problem.obstacles
    assert isinstance(sphere, Sphere)
    solution = solve(problem)
    assert solution.status == "optimal"
    assert_equilibrium(problem, solution, tol=1e-9)
    assert_sphere_contacts(problem, solution, sphere, tol=1e-9)
    longest = float(problem.link_lengths.max())
    free = problem.free_nodes
    distance = np.linalg.norm(solution.positions[free] - np.asarray(sphere.center), axis=1) - sphere.radius
    on_sphere = free[distance <= 1e-9 * longest]
    force = np.linalg.norm(solution.contact_forces, axis=1)
    assert on_sphere.size == 28  # (what the grid's symmetry and the reviewer's count give)
    np.testing.assert_array_equal(np.flatnonzero(force > 0), on_sphere)
    slack = solution.link_distance < (1.0 - 1e-6) * problem.link_lengths
    assert slack.any()
    assert np.all(solution.link_tension[slack] == 0.0)


def test_the_summary_and_the_checker_count_the_same_contacts() -> None:
    result = cli("solve", str(CASES / "phantom-contacts-grid-12x20.toml"))
    assert result.returncode == 0, result.stderr
    assert "28 nodes touch 1 obstacle" in result.stdout
    result = cli("check", str(CASES / "phantom-contacts-grid-12x20.toml"))
    assert result.returncode == 0, result.stderr
    (line,) = [line for line in result.stdout.splitlines() if line.strip().startswith("nu of")]
    assert line.endswith("(28 in all)}")


# ----------------------------------------------------------------- no equilibrium: refused with one sentence
def test_supports_out_of_the_links_reach_are_refused_naming_them() -> None:
    problem = case("infeasible-net-runs-away")
    # no point is within 1.05 of all three supports: their circumradius is larger
    supports = problem.support_positions
    assert np.linalg.norm(supports - supports.mean(axis=0), axis=1).min() > 1.05
    with pytest.raises(InfeasibleError, match=r"links 0 \(nodes 0-3\), 1 \(nodes 1-3\) and 2 \(nodes 2-3\)"):
        solve(problem)
    result = cli("solve", str(CASES / "infeasible-net-runs-away.toml"))
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.count("\n") == 1 and "supports at nodes 0, 1, 2" in result.stderr


def test_a_flat_taut_net_carrying_weight_is_refused() -> None:
    problem = case("flat-taut-net-on-floor")
    # every link is exactly as long as the spacing of the supports that hold the net flat
    laid = problem.support_positions
    assert np.ptp(laid[:, 2]) == 0.0
    with pytest.raises(InfeasibleError, match="taut where it carries weight"):
        solve(problem)
    result = cli("solve", str(CASES / "flat-taut-net-on-floor.toml"))
    assert result.returncode == 2 and "Traceback" not in result.stderr


# ----------------------------------------------------------------- runaway iterates
@pytest.mark.parametrize("name", ["squared-chain-diverges-25", "squared-chain-diverges-184"])
def test_a_chain_that_cannot_reach_around_its_obstacles_stops_with_its_best_iterate(name: str) -> None:
    """Both chains must pass an obstacle their span cannot reach around (the way round the
    obstacle is longer than the chain between the supports): the forces grow without bound. The
    solve stops early and returns the iterate nearest to equilibrium, with finite residuals."""
    problem = case(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solution = solve(problem)
    assert solution.status == "diverged"
    assert solution.iterations < 50
    assert np.isfinite(solution.positions).all()
    assert solution.link_tension.max() < 1e3 * problem.weight
    assert np.isfinite(solution.kkt_scaled.max()) and solution.kkt_scaled.max() < 1e3
    assert solution.unsettled is not None and "node" in solution.unsettled


def test_the_way_round_the_box_is_longer_than_the_chain_between_its_supports() -> None:
    """The independent reason the 184-node chain diverges: between the supports at nodes 50 and 131
    the chain must pass the box's corner, and the two straight pieces through that corner are
    already longer than the chain (a shortest path round a convex corner)."""
    problem = case("squared-chain-diverges-184")
    box = problem.obstacles[1]
    a, b = (problem.support_positions[list(problem.support_nodes).index(n)] for n in (50, 131))
    corner = np.array([0.01101, -0.00020])  # the box's upper right corner (drawn from its parameters)
    phi = box.evaluate(corner[None, :])[0][0]
    assert abs(phi) < 1e-4  # the corner is on the box's edge, to the drawing's accuracy
    around = np.linalg.norm(corner - a) + np.linalg.norm(b - corner)
    assert around > problem.link_lengths[50:131].sum()


# ----------------------------------------------------------------- stalls
def halfspace_clarabel_optimum(problem: Problem, ground: HalfSpace) -> float:
    """The convex program of a net over a half-space: second-order cones for the links (the same
    feasible set in either formulation), one linear inequality per free node."""
    cp = pytest.importorskip("cvxpy")
    pytest.importorskip("clarabel")
    positions = cp.Variable((problem.n_nodes, problem.dimension))
    a, b = problem.link_nodes[:, 0], problem.link_nodes[:, 1]
    normal = np.asarray(ground.normal) / np.linalg.norm(ground.normal)
    free = problem.free_nodes
    constraints = [
        positions[problem.support_nodes] == problem.support_positions,
        cp.SOC(problem.link_lengths, positions[a] - positions[b], axis=1),
        positions[free] @ normal >= float(np.asarray(ground.point) @ normal),  # (the normal points out of it)
    ]
    program = cp.Problem(cp.Minimize(problem.gravity * problem.masses @ positions[:, -1]), constraints)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        program.solve(solver="CLARABEL", tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-10)
    assert program.status == "optimal"
    return float(program.value)


def test_a_free_radial_net_that_stalled_reaches_the_convex_optimum() -> None:
    problem = case("convex-net-stalls-a")
    solution = solve(problem)
    assert solution.status == "optimal"
    assert_equilibrium(problem, solution, tol=1e-8)
    energy, _ = clarabel_optimum(problem)
    assert solution.objective == pytest.approx(energy, rel=1e-7)


def test_a_tree_over_a_half_space_that_stalled_reaches_the_convex_optimum() -> None:
    problem = case("convex-net-stalls-b")
    (ground,) = problem.obstacles
    assert isinstance(ground, HalfSpace)
    solution = solve(problem)
    assert solution.status == "optimal"
    assert solution.objective == pytest.approx(halfspace_clarabel_optimum(problem, ground), rel=1e-7)


def test_a_random_triangulated_net_reaches_the_convex_optimum() -> None:
    rng = np.random.default_rng(361)
    plan, pairs = delaunay_net(rng, 361)
    shape = np.column_stack((plan, np.zeros(plan.shape[0])))
    lengths = 1.0908 * np.linalg.norm(shape[pairs[:, 0]] - shape[pairs[:, 1]], axis=1)
    corners = [int(np.argmin(np.linalg.norm(plan - c, axis=1))) for c in ((0, 0), (1, 0), (1, 1), (0, 1))]
    problem = Problem.build(
        nodes=plan.shape[0],
        links=[[int(a), int(b), float(length)] for (a, b), length in zip(pairs, lengths, strict=True)],
        supports=[(i, tuple(float(c) for c in shape[i])) for i in corners],
        mass=1.0,
        gravity=9.81,
        dimension=3,
    )
    solution = solve(problem)
    assert solution.status == "optimal"
    assert solution.objective == pytest.approx(clarabel_optimum(problem)[0], rel=1e-7)


@pytest.mark.parametrize("name", ["radial-net-over-ellipsoid-stalls", "links-mode-chain-stalls"])
def test_a_solve_that_does_not_settle_says_where(name: str) -> None:
    """No equilibrium is reached on these (a net draped over a flat ellipsoid, a chain in link
    contact against four obstacles with links 70 times apart): the status says so and one sentence
    names the node farthest from balance, measured here too."""
    problem = case(name)
    solution = solve(problem)
    assert solution.status != "optimal"
    assert solution.kkt_scaled.max() > 1e-6  # (it did not converge: the residuals say so too)
    sentence = solution.unsettled
    assert sentence is not None
    node = int(sentence.split()[1])
    assert node in problem.free_nodes
    assert f"{np.linalg.norm(_unbalanced(problem, solution)[node]):.3g}" in sentence
    result = cli("solve", str(CASES / f"{name}.toml"))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "not settled" in result.stdout and f"node {node}" in result.stdout


def _unbalanced(problem: Problem, solution: funicular.Solution) -> np.ndarray:
    """Every node's weight, link forces and contact forces added up (N, d), recomputed here."""
    total = np.zeros((problem.n_nodes, problem.dimension))
    total[:, -1] -= problem.gravity * problem.masses
    for (a, b), tension in zip(problem.link_nodes, solution.link_tension, strict=True):
        along = solution.positions[b] - solution.positions[a]
        pull = tension * along / np.linalg.norm(along)
        total[a] += pull
        total[b] -= pull
    return total + solution.contact_forces


# ----------------------------------------------------------------- where a structure stands
def test_a_net_moved_far_from_the_origin_has_the_same_answer_up_to_the_shift() -> None:
    """The same net, supports and ground moved by 1e6 in x. Writing 1e6 + x rounds x to 1.2e-10,
    and this net's answer moves by up to 1.2e-8 of its size for such a change (measured by
    perturbing the near net's supports by 1.2e-10): that is the agreement to expect."""
    near, far = case("net-near-origin"), case("net-far-from-origin")
    shift = far.support_positions[0] - near.support_positions[0]
    np.testing.assert_allclose(shift, [1e6, 0.0, 0.0])
    a, b = solve(near), solve(far)
    assert a.status == b.status == "optimal"
    size = float(np.ptp(a.positions, axis=0).max())
    assert np.abs(b.positions - shift - a.positions).max() <= 1e-7 * size
    assert abs(b.objective - a.objective) <= 1e-8 * near.weight * size  # (a shift in x does no work)


def test_a_hub_on_horizontal_spokes_has_force_ranges_in_either_formulation(tmp_path: Path) -> None:
    """The hub rests on the ball's top with its six spokes horizontal: they cannot carry its
    weight, so the ball carries all of it (1), and any equal pull in opposite spokes balances
    itself, so each spoke's tension ranges over [0, inf)."""
    for formulation in ("squared", "norm"):
        scenario = (CASES / "squared-hub-force-ranges.toml").read_text()
        path = tmp_path / f"hub-{formulation}.toml"
        path.write_text(scenario.replace('formulation = "squared"', f'formulation = "{formulation}"'))
        output = tmp_path / f"hub-{formulation}.json"
        result = cli("solve", str(path), "--json", str(output))
        assert result.returncode == 0, result.stderr
        ranges = json.loads(output.read_text())["licq"]["force_ranges"]
        assert ranges is not None, formulation
        for k in range(6):  # (JSON writes an infinite bound as null)
            assert ranges[f"link {k}"] == [0.0, None], formulation
        assert ranges["ball at node 0"] == pytest.approx([1.0, 1.0], abs=1e-9)
