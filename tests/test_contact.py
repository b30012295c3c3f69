"""Obstacles in the solve: contact forces against force balance, invariances, the catenary oracle."""

from __future__ import annotations

import numpy as np
import pytest

from funicular import InfeasibleError, Problem, ScenarioError, SolverOptions, solve
from funicular._diagnostics import link_penetration
from funicular.checks import second_order
from funicular.cli import main
from funicular.obstacles import Box, CallableObstacle, Disk, Ellipse, Expression, HalfPlane, Obstacle
from funicular.scenario import load_scenario
from oracles import discrete_catenary


def ground_problem(nodes: int = 81) -> Problem:
    return Problem.build(
        nodes=nodes, length=3.5, mass=1.0, gravity=2.0,
        supports=[(0, (0.0, 1.0)), (-1, (2.0, 1.0))], obstacles=[HalfPlane((0.0, 0.0), (0.0, 1.0), name="ground")],
    )  # fmt: skip


def test_chain_lying_on_flat_ground() -> None:
    """Nodes lying on frictionless ground carry exactly their own weight as a vertical contact force;
    the hanging part is a discrete catenary; supports + contacts carry the whole weight."""
    problem = ground_problem()
    solution = solve(problem)
    assert solution.converged and solution.kkt.max() <= 1e-9
    on_ground = np.flatnonzero(np.abs(solution.y) <= 1e-12)
    assert on_ground.size > 10
    interior = on_ground[1:-1]  # the touchdown nodes also turn the chain, so only inner ones are pure
    weight = problem.gravity * problem.masses
    np.testing.assert_allclose(solution.contact_forces[interior, 1], weight[interior], rtol=1e-9)
    np.testing.assert_allclose(solution.contact_forces[:, 0], 0.0, atol=1e-12)
    total = solution.support_reactions[:, 1].sum() + solution.contact_forces[:, 1].sum()
    assert total == pytest.approx(problem.weight, rel=1e-9)

    # The free part from the left support to the first node on the ground is the discrete catenary
    # between those two points (the touchdown node's weight and contact go into its "support").
    t = int(on_ground[0])
    exact = discrete_catenary(
        problem.masses[: t + 1], problem.link_lengths[:t], problem.gravity, solution.positions[0], solution.positions[t]
    )
    np.testing.assert_allclose(solution.positions[: t + 1], exact.positions, atol=1e-8 * problem.total_length)
    np.testing.assert_allclose(solution.link_tension[:t], exact.tension, rtol=1e-8)


def test_scaling_phi_changes_neither_positions_nor_contact_forces() -> None:
    """Contact force -nu grad phi is invariant when phi is multiplied by a positive constant (nu scales inversely)."""
    disk = Disk((0.5, -0.55), 0.25)

    def scaled_disk(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        phi, gradient, hessian = disk.evaluate(points)
        return 7.0 * phi, 7.0 * gradient, 7.0 * hessian

    base = load_scenario("disk-drape")
    scaled = Problem.build(
        nodes=base.n_nodes, length=base.total_length, mass=base.total_mass, gravity=base.gravity,
        supports=list(zip(base.support_nodes.tolist(), base.support_positions.tolist(), strict=True)),
        obstacles=[CallableObstacle(scaled_disk, name="scaled disk")],
    )  # fmt: skip
    a, b = solve(base), solve(scaled)
    assert a.converged and b.converged
    np.testing.assert_allclose(b.positions, a.positions, atol=1e-10)
    np.testing.assert_allclose(b.contact_forces, a.contact_forces, atol=1e-10)
    np.testing.assert_allclose(b.obstacle_multipliers * 7.0, a.obstacle_multipliers, atol=1e-9)


def test_symmetric_scenario_gives_symmetric_forces() -> None:
    """disk-drape is symmetric about x = 0.5: at the symmetric KKT point (the interior-point method's
    answer from the symmetric start, before the saddle escape) positions, tensions, contacts and
    reactions mirror."""
    solution = solve(load_scenario("disk-drape"), SolverOptions(escape_saddles=False))
    mirrored = solution.positions[::-1].copy()
    mirrored[:, 0] = 1.0 - mirrored[:, 0]
    np.testing.assert_allclose(solution.positions, mirrored, atol=1e-9)
    np.testing.assert_allclose(solution.link_tension, solution.link_tension[::-1], atol=1e-9)
    contact = solution.contact_forces
    np.testing.assert_allclose(contact[:, 0], -contact[::-1, 0], atol=1e-9)
    np.testing.assert_allclose(contact[:, 1], contact[::-1, 1], atol=1e-9)
    left, right = solution.support_reactions
    np.testing.assert_allclose(left, [-right[0], right[1]], atol=1e-9)


def test_contact_forces_point_out_of_the_obstacle() -> None:
    solution = solve(load_scenario("disk-drape"))
    touching = np.flatnonzero(np.hypot(*solution.contact_forces.T) > 0)
    outward = solution.positions[touching] - np.array([0.5, -0.55])
    assert np.all(np.einsum("ij,ij->i", solution.contact_forces[touching], outward) > 0)


def test_support_inside_an_obstacle_is_named() -> None:
    problem = Problem.build(
        nodes=5, length=2.0, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Disk((1.0, -0.05), 0.2, name="peg")],
    )  # fmt: skip
    with pytest.raises(InfeasibleError, match=r"support at node 4 .* inside obstacle 'peg'"):
        solve(problem)


def test_support_inside_is_named_when_another_depth_is_not_a_number() -> None:
    """phi = sqrt(x) - 0.5 is NaN at the left support (x < 0) and 1 deep at the right one: the
    right one is still refused (a NaN once hid every other support from a one-reduction check)."""
    problem = Problem.build(
        nodes=5, length=3.0, mass=1.0, supports=[(0, (-1.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Expression("sqrt(x) - 0.5")],
    )  # fmt: skip
    assert np.isnan(problem.support_depths[0, 0])
    with pytest.raises(InfeasibleError, match=r"support at node 4 .* inside obstacle 'expression'"):
        solve(problem)


def test_support_on_the_surface_is_fine() -> None:
    problem = Problem.build(
        nodes=21, length=3.0, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0)), (-1, (2.0, 0.0))],
        obstacles=[HalfPlane((0.0, 0.0), (0.0, 1.0))],
    )  # fmt: skip
    solution = solve(problem)
    assert solution.converged and solution.kkt.max() <= 1e-9
    assert np.all(solution.y >= -1e-12)


def test_links_cutting_the_disk_are_reported() -> None:
    """With contact = "nodes", links between touching nodes are chords of the disk: they dip in by the
    sagitta l^2 / (8 r)."""
    solution = solve(load_scenario("disk-drape"))
    link, r = solution.problem.link_lengths[0], 0.25
    assert solution.links_cross_obstacles
    assert solution.link_penetration.max() == pytest.approx(link**2 / (8 * r), rel=0.05)


@pytest.mark.parametrize(
    "obstacle",
    [
        Disk((0.0, 0.0), 1.0),
        Ellipse((0.0, 0.0), (1.5, 0.7), 30.0),
        HalfPlane((0.0, -1.0), (0.3, 1.0)),
        Box((0.0, 0.0), (1.0, 0.6), 0.2, 20.0),
    ],
    ids=["disk", "ellipse", "halfplane", "box"],
)
def test_each_links_depth_is_phi_where_it_is_largest_along_the_link(obstacle: Obstacle) -> None:
    """Links at random near an obstacle, some outside it, some cutting it, some inside: a link's
    depth is phi / |grad phi| where phi is largest along it (0 if that is outside), here by sampling
    each link at 4001 points."""
    n = 300
    positions = np.random.default_rng(5).uniform(-2.5, 2.5, size=(n, 2))
    problem = Problem.build(
        nodes=n, supports=[(0, tuple(positions[0]))], link_length=10.0, mass=1.0, obstacles=[obstacle]
    )
    depth = link_penetration(problem, positions)
    t = np.linspace(0.0, 1.0, 4001)
    points = positions[:-1, None, :] + t[None, :, None] * (positions[1:] - positions[:-1])[:, None, :]
    phi, gradient, _ = obstacle.evaluate(points.reshape(-1, 2))
    phi, gradient = phi.reshape(n - 1, t.size), gradient.reshape(n - 1, t.size, 2)
    top = np.argmax(phi, axis=1)
    links = np.arange(n - 1)
    expected = np.maximum(phi[links, top] / np.linalg.norm(gradient[links, top], axis=1), 0.0)
    assert np.count_nonzero(expected > 1e-3) > 20 and np.count_nonzero(expected == 0.0) > 20  # both kinds
    # Near a centre phi / |grad phi| grows without bound and sampling misses its largest value.
    shallow = expected < 1.0
    np.testing.assert_allclose(depth[shallow], expected[shallow], rtol=1e-3, atol=1e-3)
    assert np.all(depth[~shallow] > 0.9)


def test_cli_reports_a_support_inside_an_obstacle(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "s.toml"
    path.write_text(
        "[chain]\nnodes = 5\nlength = 2.0\nmass = 1.0\n"
        "[[supports]]\nnode = 0\nposition = [0.0, 0.0]\n"
        "[[obstacles]]\nshape = 'disk'\nname = 'rock'\ncenter = [0.0, 0.1]\nradius = 0.5\n"
    )
    assert main(["solve", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "inside obstacle 'rock'" in err[0]


def test_contact_links_is_refused_with_a_clear_sentence() -> None:
    """Keeping whole link segments out needs phi's maximum along a segment, which only the convex
    built-in shapes provide: for any other obstacle say so instead of ignoring it."""
    disk = Disk((0.5, -0.55), 0.25)
    problem = Problem.build(
        nodes=11, length=1.5, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[CallableObstacle(disk.evaluate, name="my disk")], contact="links",
    )  # fmt: skip
    with pytest.raises(ScenarioError, match=r"contact = 'links' needs a convex built-in shape .* 'my disk'"):
        solve(problem)


def test_the_default_solve_leaves_the_symmetric_saddle_for_a_lower_minimum() -> None:
    """The symmetric drape of disk-drape is a saddle (negative curvature along a sideways roll). The
    default solve escapes it: a strict local minimum, lower in energy, and not symmetric; its mirror
    image is the other minimum, with the same energy."""
    problem = load_scenario("disk-drape")
    symmetric = solve(problem, SolverOptions(escape_saddles=False))
    assert second_order(problem, symmetric).verdict == "not a minimum"
    solution = solve(problem)
    assert solution.converged and second_order(problem, solution).verdict == "strict local minimum"
    assert solution.objective < symmetric.objective - 1e-6
    mirrored = solution.positions[::-1] * [-1.0, 1.0] + [1.0, 0.0]
    assert np.max(np.abs(solution.positions - mirrored)) > 1e-3
    other = solve(problem, SolverOptions(escape_saddles=False), initial_positions=mirrored)
    np.testing.assert_allclose(other.positions, mirrored, atol=1e-8)
    assert other.objective == pytest.approx(solution.objective, abs=1e-12)


@pytest.mark.parametrize("kind", ["free", "disk"])
def test_coarse_to_fine_polish_agrees_with_a_direct_interior_point_solve(kind: str) -> None:
    """Long chains start from a coarser chain's answer and usually finish with the active-set polish
    alone; the same chain solved by the interior-point method from the plain initial guess (no
    coarse level) reaches the same equilibrium and forces."""
    from bench.run import family

    from funicular._solver.initial import presolve

    problem = family(6000, kind)
    coarse_to_fine = solve(problem)
    direct = solve(problem, initial_positions=presolve(problem).positions)
    assert coarse_to_fine.converged and direct.converged
    assert coarse_to_fine.iterations < direct.iterations  # the polish alone, not a new solve
    np.testing.assert_allclose(coarse_to_fine.positions, direct.positions, rtol=0, atol=1e-8)
    np.testing.assert_allclose(coarse_to_fine.link_tension, direct.link_tension, rtol=0, atol=1e-8 * problem.weight)
    np.testing.assert_allclose(coarse_to_fine.contact_forces, direct.contact_forces, rtol=0, atol=1e-8 * problem.weight)
    assert second_order(problem, coarse_to_fine).verdict == "strict local minimum"


@pytest.mark.parametrize("scenario", ["disk-drape", "net-over-sphere", "two-pegs"])
def test_a_solutions_obstacle_fields_give_the_forces_residuals_and_depths_of_a_fresh_evaluation(scenario: str) -> None:
    """A solution evaluates its obstacles once at every node and indexes that for its contact
    forces, KKT residuals and link depths; evaluating each subset afresh gives the same numbers."""
    from funicular._diagnostics import kkt_residuals
    from funicular._forces import contact_forces

    solution = solve(load_scenario(scenario))
    problem, positions = solution.problem, solution.positions
    assert solution.node_fields is not None and len(solution.node_fields) == len(problem.obstacles)
    fresh = contact_forces(problem, positions, solution.obstacle_multipliers)
    np.testing.assert_array_equal(solution.contact_forces, fresh)
    np.testing.assert_array_equal(solution.link_penetration, link_penetration(problem, positions))
    alone = kkt_residuals(problem, positions, solution.link_multipliers, solution.obstacle_multipliers)
    assert solution.kkt == alone
