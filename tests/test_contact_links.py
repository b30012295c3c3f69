"""contact = "links": whole link segments kept out of convex obstacles, checked against hand
calculations, force balance and the geometry of the disk (never against the solver's own output)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from funicular import Problem, ScenarioError, SolverError, SolverOptions, solve
from funicular._solver.core_problem import core_chain
from funicular._text import summary, to_json
from funicular.backends import solve_with
from funicular.checks import check_solution, licq_of
from funicular.model import FloatArray
from funicular.obstacles import Disk, Ellipse, Evaluation, Expression, HalfPlane
from funicular.scenario import load_scenario
from funicular.solution import Solution

CENTER, RADIUS = (0.5, -0.45), 0.25


def draped(contact: str, shift: tuple[float, float] = (0.0, 0.0), disk: Disk | None = None) -> Problem:
    """7 nodes, links of 0.25 over a disk of radius 0.25: node contact lets links cut deep into it."""
    x, y = shift
    return Problem.build(
        nodes=7, length=1.5, mass=1.0, gravity=1.0, supports=[(0, (x, y)), (-1, (1.0 + x, y))],
        obstacles=[disk or Disk((CENTER[0] + x, CENTER[1] + y), RADIUS, name="drum")], contact=contact,
    )  # fmt: skip


def unbalanced(solution: Solution) -> FloatArray:
    """Gravity + link tensions (from positions) + reported contact forces at every free node."""
    problem, p = solution.problem, solution.positions
    delta = p[1:] - p[:-1]
    pull = solution.link_tension[:, None] * delta / np.hypot(*delta.T)[:, None]
    total = solution.contact_forces.copy()
    total[:-1] += pull
    total[1:] -= pull
    total[:, 1] -= problem.gravity * problem.masses
    result: FloatArray = total[problem.free_nodes]
    return result


def disk_contact_forces(solution: Solution, center: tuple[float, float], radius: float) -> FloatArray:
    """Nodal shares of each link's contact force, from the disk's geometry: the force acts at the
    point of the link nearest the centre, along the outward normal, with magnitude nu |grad phi| = nu."""
    p, c = solution.positions, np.asarray(center)
    a, d = p[:-1], p[1:] - p[:-1]
    t = np.clip(np.einsum("ij,ij->i", c - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    normal = (a + t[:, None] * d - c) / radius
    force = solution.obstacle_multipliers[0][:, None] * normal
    nodal = np.zeros_like(p)
    nodal[:-1] += (1.0 - t)[:, None] * force
    nodal[1:] += t[:, None] * force
    return nodal


def test_links_stay_out_where_node_contact_lets_them_cut() -> None:
    nodes = solve(draped("nodes"))
    assert nodes.converged and nodes.link_penetration.max() > 0.01 and nodes.links_cross_obstacles
    links = solve(draped("links"))
    problem, length = links.problem, 0.25
    assert links.converged and links.kkt_scaled.max() <= 1e-9
    assert links.link_penetration.max() <= 1e-9 * length and not links.links_cross_obstacles
    # Every node outside, and every link at least the radius from the centre (segment distance).
    p, c = links.positions, np.asarray(CENTER)
    assert np.all(np.hypot(*(p - c).T) >= RADIUS * (1.0 - 1e-9))
    a, d = p[:-1], p[1:] - p[:-1]
    t = np.clip(np.einsum("ij,ij->i", c - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    gap = np.hypot(*(a + t[:, None] * d - c).T) - RADIUS
    assert np.all(gap >= -1e-9 * length)
    touching = links.obstacle_multipliers[0] > 0
    assert touching.sum() >= 1 and np.all(np.abs(gap[touching]) <= 1e-9)
    assert np.all((t[touching] > 0.0) & (t[touching] < 1.0))  # tangent inside the link, not at a node
    # Force balance and the contact forces' geometry, both to 1e-9 of the weight.
    assert np.abs(unbalanced(links)).max() <= 1e-9 * problem.weight
    np.testing.assert_allclose(links.contact_forces, disk_contact_forces(links, CENTER, RADIUS), atol=1e-9)
    assert links.objective > nodes.objective  # a smaller feasible set


def test_tent_over_a_drum_matches_the_hand_solution() -> None:
    """One free node (mass m) held up by its two slack links resting on a disk of radius r centred
    between supports at (-1, 0) and (1, 0). The links are tangent to the disk, so with
    sin(theta) = r the node sits at (0, tan(theta)), each link touches at t = cos^2(theta) of its
    length, and vertical balance at the node, 2 t f cos(theta) = m g, gives the contact force
    f = m g / (2 cos^3 theta) on each link, acting along the outward normal (-+sin, cos)."""
    m, g, r = 2.0, 1.0, 0.6
    problem = Problem.build(
        nodes=3, link_length=1.4, masses=[1.0, m, 1.0], gravity=g, supports=[(0, (-1.0, 0.0)), (2, (1.0, 0.0))],
        obstacles=[Disk((0.0, 0.0), r, name="drum")], contact="links",
    )  # fmt: skip
    solution = solve(problem, initial_positions=np.array([[-1.0, 0.0], [0.0, 1.2], [1.0, 0.0]]))
    assert solution.converged
    sin, cos = r, np.sqrt(1.0 - r * r)
    t, f = cos**2, m * g / (2.0 * cos**3)
    np.testing.assert_allclose(solution.positions[1], [0.0, sin / cos], atol=1e-8)
    np.testing.assert_allclose(solution.link_tension, 0.0, atol=1e-8)  # 1.25 < 1.4: slack
    np.testing.assert_allclose(solution.obstacle_multipliers, [[f, f]], rtol=1e-8)  # |grad phi| = 1 on the rim
    left, right = f * np.array([-sin, cos]), f * np.array([sin, cos])
    expected = np.array([(1 - t) * left, t * (left + right), (1 - t) * right])
    np.testing.assert_allclose(solution.contact_forces, expected, atol=1e-8)
    weights = np.array([[0.0, -1.0], [0.0, -1.0]]) * g
    np.testing.assert_allclose(solution.support_reactions, -(weights + expected[[0, 2]]), atol=1e-8)
    # With node contact the node falls onto the top of the disk and both links cut through it. (The top
    # is a saddle, where the node balances; the default solve would roll it off to one side.)
    nodes = solve(
        dataclasses.replace(problem, contact="nodes"),
        SolverOptions(escape_saddles=False),
        initial_positions=solution.positions,
    )
    assert nodes.converged and nodes.positions[1, 1] == pytest.approx(r, abs=1e-8) and nodes.links_cross_obstacles


def test_translation_moves_positions_and_keeps_forces() -> None:
    base, moved = solve(draped("links")), solve(draped("links", shift=(3.7, -2.1)))
    assert base.converged and moved.converged
    np.testing.assert_allclose(moved.positions - [3.7, -2.1], base.positions, atol=1e-10)
    np.testing.assert_allclose(moved.contact_forces, base.contact_forces, atol=1e-10)
    np.testing.assert_allclose(moved.link_tension, base.link_tension, atol=1e-10)


class ScaledDisk(Disk):
    """The disk with phi (and its derivatives) multiplied by 7: the same obstacle."""

    def evaluate(self, points: FloatArray) -> Evaluation:
        phi, gradient, hessian = super().evaluate(points)
        return 7.0 * phi, 7.0 * gradient, 7.0 * hessian


def test_scaling_phi_changes_neither_positions_nor_contact_forces() -> None:
    base = solve(draped("links"))
    scaled = solve(draped("links", disk=ScaledDisk(CENTER, RADIUS, name="drum")))
    assert base.converged and scaled.converged
    np.testing.assert_allclose(scaled.positions, base.positions, atol=1e-10)
    np.testing.assert_allclose(scaled.contact_forces, base.contact_forces, atol=1e-10)
    np.testing.assert_allclose(7.0 * scaled.obstacle_multipliers, base.obstacle_multipliers, atol=1e-9)


def test_a_support_on_a_disk_surface_is_fine() -> None:
    """The left support sits on the rim of one disk and the chain leaves it outwards: no row is stuck
    at phi = 0 at the support (a contact there is the support's), and the chain rests on a second disk."""
    problem = Problem.build(
        nodes=7, length=1.5, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Disk((-0.25, 0.0), 0.25, name="rim"), Disk(CENTER, RADIUS, name="drum")], contact="links",
    )  # fmt: skip
    solution = solve(problem)
    assert solution.converged and solution.kkt_scaled.max() <= 1e-9
    assert solution.link_penetration.max() <= 1e-9 * 0.25
    np.testing.assert_allclose(solution.obstacle_multipliers[0], 0.0, atol=1e-9)
    assert np.any(solution.obstacle_multipliers[1] > 0.01)
    assert np.abs(unbalanced(solution)).max() <= 1e-9 * problem.weight


def test_on_a_half_plane_links_mode_is_node_mode() -> None:
    """A segment is out of a half-plane exactly when its ends are: both modes give the same equilibrium
    and the same nodal contact forces (each resting node carries its own weight)."""
    ground = load_scenario("ground")
    nodes, links = solve(ground), solve(dataclasses.replace(ground, contact="links"))
    assert nodes.converged and links.converged and links.kkt_scaled.max() <= 1e-9
    np.testing.assert_allclose(links.positions, nodes.positions, atol=1e-9)
    np.testing.assert_allclose(links.contact_forces, nodes.contact_forces, atol=1e-9 * ground.weight)
    assert links.obstacle_multipliers.shape == (1, ground.n_links)


def test_a_chain_over_the_rounded_corner_of_a_box() -> None:
    problem = dataclasses.replace(load_scenario("box-edge").with_nodes(31), contact="links")
    solution = solve(problem)
    assert solution.converged and solution.kkt_scaled.max() <= 1e-9
    assert not solution.links_cross_obstacles
    assert np.abs(unbalanced(solution)).max() <= 1e-9 * problem.weight


def test_a_long_chain_starts_from_a_coarse_links_mode_solve() -> None:
    problem = dataclasses.replace(load_scenario("disk-drape").with_nodes(241), contact="links")
    solution = solve(problem)
    assert solution.converged and solution.kkt_scaled.max() <= 1e-9 and not solution.links_cross_obstacles
    assert np.abs(unbalanced(solution)).max() <= 1e-9 * problem.weight


def test_newton_matrix_is_the_hessian_of_the_lagrangian() -> None:
    """Exact second derivatives: the condensed matrix with sigma = 0 is the derivative of the dual
    residual, and J dz the derivative of the constraints (central differences), at a point where the
    links touch the disk inside (moving maximiser) and with every multiplier positive."""
    problem = draped("links")
    network = core_chain(problem).network(guess=np.ascontiguousarray(solve(problem).positions.ravel()))
    z = network.free_coordinates()
    rng = np.random.default_rng(3)
    z = z + 1e-3 * rng.standard_normal(z.size)
    mu = rng.uniform(0.5, 1.5, network.n_constraints)
    size = z.size
    dense = network.newton_matrix(z=z, mu=mu, sigma=np.zeros_like(mu)).reshape(size, size)
    h = 1e-6
    for i in range(size):
        e = np.zeros_like(z)
        e[i] = h
        plus, minus = network.evaluate(z=z + e, mu=mu), network.evaluate(z=z - e, mu=mu)
        np.testing.assert_allclose(dense[:, i], (plus.dual - minus.dual) / (2 * h), atol=1e-6)
        np.testing.assert_allclose(network.jacobian_times(z=z, dz=e / h), (plus.c - minus.c) / (2 * h), atol=1e-6)


def test_other_shapes_are_refused_naming_the_obstacle() -> None:
    pytest.importorskip("sympy")
    problem = Problem.build(
        nodes=7, length=1.5, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Expression("0.0625 - (x - 0.5)**2 - (y + 0.45)**2", name="bowl")], contact="links",
    )  # fmt: skip
    with pytest.raises(ScenarioError, match=r"contact = 'links' needs a convex built-in shape .* 'bowl'"):
        solve(problem)


def test_results_and_their_consumers_handle_per_link_multipliers() -> None:
    solution = solve(draped("links"))
    document = solution.to_dict()
    assert document["contact"] == "links" and len(document["multipliers"]["obstacle"]["drum"]) == 6
    assert "optimal" in summary(solution) and to_json(document)
    assert licq_of(solution) is None
    with pytest.raises(ScenarioError, match="supports contact = 'nodes' only"):
        check_solution(solution)
    with pytest.raises(SolverError, match="supports contact = 'nodes' only"):
        solve_with(draped("links"), "slsqp")


def test_free_ends_on_either_side_of_the_support_rest_on_the_ground() -> None:
    """Both free ends hang from a middle support onto the ground: every node, on either side of the
    first support, is kept out by some link's row, and the answer is node mode's."""
    problem = Problem.build(
        nodes=9, length=2.0, mass=1.0, gravity=1.0, supports=[(4, (0.0, 0.0))],
        obstacles=[HalfPlane((0.0, -0.6), (0.0, 1.0), name="ground")], contact="links",
    )  # fmt: skip
    links, nodes = solve(problem), solve(dataclasses.replace(problem, contact="nodes"))
    assert links.converged and nodes.converged and links.kkt_scaled.max() <= 1e-9
    assert np.all(links.y >= -0.6 - 1e-12) and np.sum(np.abs(links.y + 0.6) <= 1e-9) >= 4
    np.testing.assert_allclose(links.positions, nodes.positions, atol=1e-8)
    np.testing.assert_allclose(links.contact_forces, nodes.contact_forces, atol=1e-8)


def test_a_dangling_chain_pushed_aside_by_a_tilted_ellipse() -> None:
    """One support, a free end: the last node is covered by its link's row. The egg pushes one link
    sideways; no link enters it (node contact lets one cut in), and every free node is in balance."""

    def problem(contact: str) -> Problem:
        return Problem.build(
            nodes=21, length=1.0, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0))],
            obstacles=[Ellipse((0.12, -0.5), (0.1, 0.25), angle=20.0, name="egg")], contact=contact,
        )  # fmt: skip

    links, nodes = solve(problem("links")), solve(problem("nodes"))
    assert links.converged and nodes.converged and links.kkt_scaled.max() <= 1e-9
    assert nodes.link_penetration.max() > 1e-4 and links.link_penetration.max() <= 1e-9 * 0.05
    assert np.abs(unbalanced(links)).max() <= 1e-9 * links.problem.weight
    pushed = np.flatnonzero(np.hypot(*links.contact_forces.T) > 0)
    assert pushed.size >= 1 and np.all(links.contact_forces[pushed, 0] < 0)  # pushed to the left, away from the egg
    assert links.positions[-1, 0] < 0.0
