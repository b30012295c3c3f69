"""Obstacles in the solve: contact forces against force balance, invariances, the catenary oracle."""

from __future__ import annotations

import numpy as np
import pytest

from funicular import InfeasibleError, Problem, ScenarioError, SolverOptions, solve
from funicular._diagnostics import link_penetration
from funicular.checks import second_order
from funicular.cli import main
from funicular.obstacles import (
    Box,
    CallableObstacle,
    Cuboid,
    Disk,
    Ellipse,
    Ellipsoid,
    Expression,
    HalfPlane,
    HalfSpace,
    Obstacle,
    Sphere,
)
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


def _turned(degrees: float) -> np.ndarray:
    """Columns: a shape's own axes, turned ``degrees`` counter-clockwise."""
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, -s], [s, c]])


def _outline(obstacle: Obstacle) -> np.ndarray:
    """A closed polygon of 2000 points on the obstacle's boundary, drawn by hand from its parameters."""
    t = np.linspace(0.0, 2.0 * np.pi, 2000)
    if isinstance(obstacle, Disk):
        return np.asarray(obstacle.center) + obstacle.radius * np.column_stack([np.cos(t), np.sin(t)])
    if isinstance(obstacle, Ellipse):
        local = np.asarray(obstacle.semi_axes) * np.column_stack([np.cos(t), np.sin(t)])
        return np.asarray(obstacle.center) + local @ _turned(obstacle.angle).T
    assert isinstance(obstacle, Box)
    r, (hx, hy) = obstacle.corner_radius, obstacle.half_size
    # the rounded rectangle: each corner's quarter circle, joined by the straight sides
    corners = [((hx - r, hy - r), 0.0), ((r - hx, hy - r), 90.0), ((r - hx, r - hy), 180.0), ((hx - r, r - hy), 270.0)]
    arcs = [
        np.asarray(centre) + r * np.column_stack([np.cos(a), np.sin(a)])
        for centre, start in corners
        for a in [np.radians(np.linspace(start, start + 90.0, 500))]
    ]
    return np.asarray(obstacle.center) + np.vstack([*arcs, arcs[0][:1]]) @ _turned(obstacle.angle).T


def _distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Each point's distance to the closed polygon (its nearest edge)."""
    start, edge = polygon[:-1], np.diff(polygon, axis=0)
    offset = points[:, None, :] - start[None, :, :]
    t = np.clip(np.einsum("pkd,kd->pk", offset, edge) / np.einsum("kd,kd->k", edge, edge), 0.0, 1.0)
    return np.min(np.linalg.norm(offset - t[:, :, None] * edge[None, :, :], axis=2), axis=1)


@pytest.mark.parametrize(
    "obstacle",
    [
        Disk((0.0, 0.0), 1.0),
        Ellipse((0.0, 0.0), (1.5, 0.7), 30.0),
        Ellipse((0.3, -0.2), (2.0, 0.3), -10.0),
        Box((0.0, 0.0), (1.0, 0.6), 0.2, 20.0),
    ],
    ids=["disk", "ellipse", "flat-ellipse", "box"],
)
def test_each_links_depth_is_its_largest_distance_to_the_boundary_inside(obstacle: Obstacle) -> None:
    """Links at random near an obstacle, some outside it, some cutting it, some through it: a
    link's depth is the largest distance from a point of the link to the boundary, over its points
    inside (0 if none), here from the distances of 201 points of each link to a polygon of the
    boundary drawn by hand (2000 points; it lies inside the curve by its sagitta, below 1e-5)."""
    n = 80
    positions = np.random.default_rng(5).uniform(-2.0, 2.0, size=(n, 2))
    problem = Problem.build(
        nodes=n, supports=[(0, tuple(positions[0]))], link_length=10.0, mass=1.0, obstacles=[obstacle]
    )
    depth = link_penetration(problem, positions)
    polygon = _outline(obstacle)
    t = np.linspace(0.0, 1.0, 201)
    expected = np.zeros(n - 1)
    for k in range(n - 1):
        points = positions[k] + t[:, None] * (positions[k + 1] - positions[k])
        inside = obstacle.evaluate(points)[0] > 0.0
        if inside.any():
            expected[k] = _distance_to_polygon(points[inside], polygon).max()
    assert np.count_nonzero(expected > 0.2) > 5 and np.count_nonzero(expected == 0.0) > 10  # both kinds
    # The sampled largest distance is below the true one by at most a slope (<= 1) times half a step.
    step = np.linalg.norm(np.diff(positions, axis=0), axis=1) / 200
    assert np.all(depth >= expected - 1e-5)
    assert np.all(depth <= expected + step / 2 + 1e-5)


def test_a_disk_through_a_link_is_reported_as_deep_as_it_reaches(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The user's scenarios: a 3-node chain (links 1.2, supports 2 apart) hangs as a V with its
    middle node at (0, -sqrt(1.2^2 - 1)); a disk (sphere) of radius 0.3 that touches no node sits
    on the second link. Its depth is the radius less the centre's distance to that link:
    0.3 - 0.05 = 0.25 and 0.3 through the centre (not phi / |grad phi| there, which is 0.875, or
    7.5e13 at the centre), in the summary's note and the result file."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    cases = Path(__file__).parent / "data" / "cases"
    middle = np.array([0.0, -np.sqrt(1.2**2 - 1.0)])
    end = np.array([1.0, 0.0])
    for name, centre, dimension in (
        ("link-depth-disk", (0.47236146008037166, -0.2899958123688733), 2),
        ("link-depth-disk-centre", (0.5, -0.33166247903554), 2),
        ("link-depth-sphere-net", (0.5, -0.33166247903554), 3),  # (x, z): the net hangs in y = 0
    ):
        c = np.asarray(centre)
        along = np.clip((c - middle) @ (end - middle) / np.sum((end - middle) ** 2), 0.0, 1.0)
        expected = 0.3 - np.linalg.norm(middle + along * (end - middle) - c)
        assert expected == pytest.approx(0.25 if name == "link-depth-disk" else 0.3, abs=1e-9)
        out = tmp_path / f"{name}.json"
        run = subprocess.run(
            [sys.executable, "-m", "funicular.cli", "solve", str(cases / f"{name}.toml"), "--json", str(out)],
            capture_output=True, text=True, check=False, timeout=120,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr
        assert f"some links cut into an obstacle (deepest {expected:.3g})" in run.stdout, (dimension, run.stdout)
        assert json.loads(out.read_text())["max_link_penetration"] == pytest.approx(expected, rel=1e-9)


def _local(centre: tuple[float, ...], degrees: float, *points: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    """Points given in a shape's own axes (turned ``degrees`` about z, or in the plane), in the world."""
    d = len(centre)
    turn = np.eye(d)
    turn[:2, :2] = _turned(degrees)
    return tuple(np.asarray(centre) + np.asarray(point) @ turn.T for point in points)


EGG = Ellipsoid((0.1, 0.2, 1.0), (2.0, 1.5, 1.0))
# (obstacle, link ends in the shape's own axes, depth by hand)
HAND_DEPTHS = {
    # a chord 0.6 from the centre of a unit disk: 1 - 0.6
    "disk chord": (Disk((0.1, 0.2), 1.0), ((-2.0, 0.6), (2.0, 0.6)), 0.4),
    # a link ending 0.5 from the centre: its end is its deepest point
    "disk end": (Disk((0.1, 0.2), 1.0), ((0.0, 0.5), (0.0, 3.0)), 0.5),
    "disk outside": (Disk((0.1, 0.2), 1.0), ((-2.0, 1.5), (2.0, 1.5)), 0.0),
    # a chord of a unit ball 0.5 from its centre
    "sphere chord": (Sphere((0.0, 0.0, 1.0), 1.0), ((-2.0, 0.3, 0.4), (2.0, 0.3, 0.4)), 0.5),
    # behind the line 3x + 4y = 0: a point's depth is -(3x + 4y)/5; (0, -1) is 0.8 deep, (1, 1) outside
    "halfplane": (HalfPlane((0.0, 0.0), (3.0, 4.0)), ((0.0, -1.0), (1.0, 1.0)), 0.8),
    "halfspace": (HalfSpace((0.0, 0.0, 1.0), (0.0, 0.0, 1.0)), ((0.0, 0.0, -0.75), (0.3, 0.0, 1.0)), 0.75),
    # semi-axes (2, 1): a point (0, v) on the minor axis is 1 - |v| from the boundary; a point
    # (u, 0) on the major axis with |u| < (a^2 - b^2)/a is b sqrt(1 - u^2/(a^2 - b^2)) from it (its
    # nearest points lie off the axis, on both sides); both are the deepest points of their links.
    "ellipse parallel": (Ellipse((1.0, 2.0), (2.0, 1.0), 30.0), ((-3.0, 0.5), (3.0, 0.5)), 0.5),
    "ellipse across": (Ellipse((1.0, 2.0), (2.0, 1.0), 30.0), ((0.5, -3.0), (0.5, 3.0)), np.sqrt(1 - 0.25 / 3)),
    "ellipse centre": (Ellipse((1.0, 2.0), (2.0, 1.0), 30.0), ((-3.0, 0.0), (3.0, 0.0)), 1.0),
    "ellipse outside": (Ellipse((1.0, 2.0), (2.0, 1.0), 30.0), ((-3.0, 1.2), (3.0, 1.2)), 0.0),
    # semi-axes (2, 1.5, 1): (0.5, 0, 0) is sqrt(1 - 0.25/3) from the surface (nearest points off
    # the x axis in the xz plane, as in the ellipse's plane); the centre is 1 from it
    "ellipsoid across": (EGG, ((0.5, 0.0, -3.0), (0.5, 0.0, 3.0)), np.sqrt(1 - 0.25 / 3)),
    "ellipsoid centre": (EGG, ((-3.0, 0.0, 0.0), (3.0, 0.0, 0.0)), 1.0),
    # half sizes (1, 0.6): along the long axis the depth is 0.6 (the nearer long sides); across at
    # u = 0.9 it is 0.1 (the short side)
    "box along": (Box((0.5, -0.2), (1.0, 0.6), 0.2, 20.0), ((-2.0, 0.0), (2.0, 0.0)), 0.6),
    "box across": (Box((0.5, -0.2), (1.0, 0.6), 0.2, 20.0), ((0.9, -2.0), (0.9, 2.0)), 0.1),
    "cuboid along": (Cuboid((0.0, 0.0, 1.0), (1.0, 0.8, 0.5), 0.1, 25.0), ((-2.0, 0.0, 0.0), (2.0, 0.0, 0.0)), 0.5),
    "cuboid across": (Cuboid((0.0, 0.0, 1.0), (1.0, 0.8, 0.5), 0.1, 25.0), ((0.95, 0.0, -2.0), (0.95, 0.0, 2.0)), 0.05),
}


@pytest.mark.parametrize("case", HAND_DEPTHS, ids=list(HAND_DEPTHS))
def test_a_link_through_each_built_in_shape_reports_its_true_depth(case: str) -> None:
    """One link into each built-in shape family, its depth computed by hand (see HAND_DEPTHS)."""
    obstacle, ends, expected = HAND_DEPTHS[case]
    centre = getattr(obstacle, "center", getattr(obstacle, "point", None))
    degrees = float(getattr(obstacle, "angle", 0.0))
    a, b = _local(tuple(centre), degrees, *ends)
    d = a.size
    problem = Problem.build(
        nodes=2, supports=[(0, tuple(a))], link_length=10.0, mass=1.0, obstacles=[obstacle], dimension=d
    )
    depth = link_penetration(problem, np.array([a, b]))
    assert depth[0] == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_a_user_defined_obstacle_says_its_link_depth_is_an_estimate(capsys) -> None:  # type: ignore[no-untyped-def]
    """Terrain is given by its phi: how deep the chords over its bump reach is estimated (phi /
    |grad phi|), and the summary says so, naming the obstacle; a built-in shape's depth is not."""
    assert main(["solve", "terrain"]) == 0
    note = next(line for line in capsys.readouterr().out.splitlines() if "cut into an obstacle" in line)
    assert "estimated as phi / |grad phi| for obstacle 'terrain'" in note
    assert main(["solve", "disk-drape"]) == 0
    note = next(line for line in capsys.readouterr().out.splitlines() if "cut into an obstacle" in line)
    assert "estimated" not in note


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
