"""Elastic links: each against an oracle of its own (the discrete and the continuous elastic
catenary, MoorPy's mooring line, a conic solver, compatibility worked out in the test), and the
bad input that names its key.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq, fsolve

import funicular
import oracles
from funicular import FunicularError, HalfPlane, Problem, ScenarioError, solve
from funicular.nets import grid
from test_properties import examples


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "funicular.cli", *args], capture_output=True, text=True, check=False, timeout=300
    )


def lumped(n: int, total: float) -> np.ndarray:
    """A cable's weight lumped at its nodes: a link's half at each end."""
    masses = np.full(n, total / (n - 1))
    masses[[0, -1]] /= 2.0
    return masses


def tensions_from_positions(problem: Problem, positions: np.ndarray) -> np.ndarray:
    """An elastic link's tension from its stretch, EA (d - L0) / L0 (0 where slack)."""
    a, b = problem.link_nodes.T
    d = np.linalg.norm(positions[a] - positions[b], axis=1)
    assert problem.axial_stiffness is not None
    tension = np.full(problem.n_links, np.nan)  # (an inextensible link's is not its stretch's)
    elastic = problem.elastic
    stretch = np.maximum(d[elastic] - problem.link_lengths[elastic], 0.0)
    tension[elastic] = problem.axial_stiffness[elastic] / problem.link_lengths[elastic] * stretch
    return tension


def unbalanced(problem: Problem, solution: funicular.Solution) -> np.ndarray:
    """Weight, point loads, link and contact forces at every node, added up here (N, d)."""
    total = np.zeros((problem.n_nodes, problem.dimension))
    total[:, -1] -= problem.gravity * problem.masses
    if problem.loads is not None:
        total += problem.loads
    for (a, b), tension in zip(problem.link_nodes, solution.link_tension, strict=True):
        along = solution.positions[b] - solution.positions[a]
        total[a] += tension * along / np.linalg.norm(along)
        total[b] -= tension * along / np.linalg.norm(along)
    return total + solution.contact_forces


# ----------------------------------------------------------------- a cable between two supports
@pytest.mark.parametrize("right", [(8.0, 1.0), (9.9, -3.0), (10.05, 0.0)], ids=["sagging", "slanted", "taut"])
def test_an_elastic_cable_is_the_discrete_elastic_catenary(right: tuple[float, float]) -> None:
    """Supports 8-10 apart on a cable of 10 unstretched: the 'taut' one is farther apart than the cable
    is long, which only an elastic cable reaches."""
    n, length, ea = 41, 10.0, 500.0
    masses = lumped(n, 2.0 * length)
    problem = Problem.build(
        nodes=n, length=length, masses=masses, gravity=1.0, supports=[(0, (0.0, 0.0)), (-1, right)], axial_stiffness=ea
    )
    solution = solve(problem)
    exact = oracles.discrete_catenary(masses, problem.link_lengths, 1.0, (0.0, 0.0), right, axial_stiffness=ea)
    assert solution.status == "optimal"
    np.testing.assert_allclose(solution.positions, exact.positions, rtol=0, atol=1e-11 * length)
    np.testing.assert_allclose(solution.link_tension, exact.tension, rtol=1e-10)
    np.testing.assert_allclose(solution.link_tension, tensions_from_positions(problem, solution.positions), rtol=1e-9)
    np.testing.assert_allclose(solution.link_strain, exact.tension / ea, rtol=1e-9)


def test_the_discrete_cable_converges_to_irvines_elastic_catenary_at_second_order() -> None:
    length, ea, w, span, rise = 10.0, 200.0, 2.0, 8.0, 1.5
    exact = oracles.elastic_catenary(length, ea, w, span, rise)
    sizes, errors = [11, 21, 41, 81], []
    for n in sizes:
        problem = Problem.build(
            nodes=n,
            length=length,
            linear_density=w,
            gravity=1.0,
            supports=[(0, (0.0, 0.0)), (-1, (span, rise))],
            axial_stiffness=ea,
        )
        solution = solve(problem)
        arclength = np.linspace(0.0, length, n)
        errors.append(np.abs(solution.positions - exact.point(arclength)).max())
    slope = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.15)


def test_an_elastic_cable_tends_to_the_inextensible_one_as_ea_grows() -> None:
    """The cable's positions differ from the inextensible cable's by O(1 / EA)."""
    n, length = 31, 10.0
    masses = lumped(n, length)
    supports = [(0, (0.0, 0.0)), (n - 1, (8.0, 1.0))]
    rigid = solve(Problem.build(nodes=n, length=length, masses=masses, gravity=1.0, supports=supports))
    stiffnesses, errors = [1e3, 1e4, 1e5, 1e6], []
    for ea in stiffnesses:
        elastic = solve(
            Problem.build(nodes=n, length=length, masses=masses, gravity=1.0, supports=supports, axial_stiffness=ea)
        )
        errors.append(np.abs(elastic.positions - rigid.positions).max())
    slope = np.polyfit(np.log(stiffnesses), np.log(errors), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.05)


# ----------------------------------------------------------------- a mooring line on the seabed
def mooring(n: int) -> Problem:
    """800 m out and 200 m up from a seabed anchor, 950 m of line of 1000 N/m wet weight, EA 5e8 N."""
    return Problem.build(
        nodes=n,
        length=950.0,
        linear_density=1000.0 / 9.81,
        gravity=9.81,
        supports=[(0, (0.0, 0.0)), (n - 1, (800.0, 200.0))],
        axial_stiffness=5e8,
        obstacles=[HalfPlane(point=(0.0, 0.0), normal=(0.0, 1.0), name="seabed")],
        units="SI",
    )


def test_a_mooring_line_on_the_seabed_converges_to_moorpys_catenary() -> None:
    """Against MoorPy's catenary with seabed contact and no friction: the fairlead's and the anchor's
    forces converge as the line gets more nodes (the touchdown point falls between two nodes, so the
    error is not smooth in N: these sizes show it falling), and the grounded length is within a link."""
    catenary = pytest.importorskip("moorpy.Catenary")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        anchor_h, _, fairlead_h, fairlead_v, info = catenary.catenary(800.0, 200.0, 950.0, 5e8, 1000.0, CB=0)
    expected = np.array([-fairlead_h, -fairlead_v, anchor_h])  # (the line's pulls, reversed: the reactions)
    errors = []
    for n in (26, 101, 401, 1601):
        problem = mooring(n)
        solution = solve(problem)
        assert solution.status == "optimal"
        (anchor_x, _), (fairlead_x, fairlead_y) = solution.support_reactions
        errors.append(np.abs(np.array([fairlead_x, fairlead_y, -anchor_x]) / expected - 1.0).max())
        touching = np.flatnonzero(np.linalg.norm(solution.contact_forces, axis=1) > 0)
        grounded = problem.link_lengths[: touching.max()].sum()  # (the line lies on the seabed up to there)
        assert abs(grounded - info["LBot"]) <= problem.link_lengths[0]
    assert all(later < earlier for earlier, later in itertools.pairwise(errors))
    assert errors[-1] < 5e-5


def test_a_long_mooring_line_started_from_coarser_lines_keeps_moorpys_forces() -> None:
    """20,001 nodes: the line is solved coarse to fine (each level an elastic line of fewer nodes
    as stretchy as the whole), and its forces are MoorPy's to the discretisation's error."""
    catenary = pytest.importorskip("moorpy.Catenary")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        anchor_h, _, fairlead_h, fairlead_v, _ = catenary.catenary(800.0, 200.0, 950.0, 5e8, 1000.0, CB=0)
    solution = solve(mooring(20_001))
    assert solution.status == "optimal"
    (anchor_x, _), (fairlead_x, fairlead_y) = solution.support_reactions
    got = np.array([fairlead_x, fairlead_y, -anchor_x])
    assert np.abs(got / np.array([-fairlead_h, -fairlead_v, anchor_h]) - 1.0).max() < 1e-5


def test_an_elastic_chain_on_a_seabed_with_a_stretched_span_reaches_the_convex_programs_optimum() -> None:
    """Elastic and inextensible links on a seabed, one span stretched beyond its unstretched length:
    the conic program's energy (Clarabel), every node in balance and every taut elastic link at the
    tension its stretch gives, all recomputed here."""
    n = 61
    stiffness = np.where(np.arange(n - 1) % 3 == 0, np.inf, 40.0)
    problem = Problem.build(
        nodes=n,
        link_length=0.1,  # (the second span: 3 long, its supports 4.72 apart)
        mass=2.0,
        gravity=9.81,
        supports=[(0, (0.0, 0.0)), (30, (2.5, 0.4)), (n - 1, (7.2, 1.0))],
        axial_stiffness=stiffness,
        obstacles=[HalfPlane(point=(0.0, -0.3), normal=(0.0, 1.0))],
    )
    solution = solve(problem)
    assert solution.status == "optimal"
    assert solution.link_strain[30:][problem.elastic[30:]].min() > 0.5  # (stretched by its supports)
    assert abs(solution.objective - clarabel_energy(problem, floor=-0.3)) < 1e-7 * abs(solution.objective)
    largest = solution.link_tension.max()
    free = np.setdiff1d(np.arange(n), problem.support_nodes)
    assert np.abs(unbalanced(problem, solution)[free]).max() < 1e-8 * largest
    by_stretch = tensions_from_positions(problem, solution.positions)
    elastic = problem.elastic
    assert np.abs(solution.link_tension[elastic] - by_stretch[elastic]).max() < 1e-8 * largest


# ----------------------------------------------------------------- nets against the conic program
def clarabel_energy(problem: Problem, floor: float | None = None) -> float:
    """min g m . z - P . p + sum EA / (2 L0) e^2 over ||p_a - p_b|| <= L0 + e, e >= 0 (elastic) and
    ||p_a - p_b|| <= L0 (inextensible): second-order cones and a convex quadratic; with ``floor``,
    every node at or above that height too (a seabed)."""
    cp = pytest.importorskip("cvxpy")
    pytest.importorskip("clarabel")
    positions = cp.Variable((problem.n_nodes, problem.dimension))
    a, b = problem.link_nodes.T
    elastic = problem.elastic
    stretch = cp.Variable(int(elastic.sum()), nonneg=True)
    lengths = problem.link_lengths
    constraints = [
        positions[problem.support_nodes] == problem.support_positions,
        cp.SOC(lengths[elastic] + stretch, positions[a[elastic]] - positions[b[elastic]], axis=1),
    ]
    if (~elastic).any():
        constraints.append(cp.SOC(lengths[~elastic], positions[a[~elastic]] - positions[b[~elastic]], axis=1))
    if floor is not None:
        constraints.append(positions[:, -1] >= floor)
    stiffness = problem.axial_stiffness[elastic] / lengths[elastic]
    energy = problem.gravity * problem.masses @ positions[:, -1] + 0.5 * stiffness @ cp.square(stretch)
    if problem.loads is not None:
        energy -= cp.sum(cp.multiply(problem.loads, positions))
    program = cp.Problem(cp.Minimize(energy), constraints)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        program.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    assert program.status == "optimal"
    return float(program.value)


@pytest.mark.parametrize("stiffness", [30.0, 1e3, 1e5])
def test_an_elastic_net_reaches_the_convex_programs_optimum(stiffness: float) -> None:
    problem = grid(12, 12, slack=1.05, axial_stiffness=stiffness, mass=1.0, gravity=9.81)
    solution = solve(problem)
    assert solution.status == "optimal"
    assert solution.objective == pytest.approx(clarabel_energy(problem), rel=1e-7)
    assert np.abs(unbalanced(problem, solution)[problem.free_nodes]).max() <= 1e-9 * problem.weight


def test_a_net_of_elastic_and_inextensible_links_with_point_loads_reaches_the_optimum() -> None:
    base = grid(10, 10, slack=1.02, mass=1.0, gravity=9.81)
    stiffness = np.where(np.arange(base.n_links) % 3 == 0, np.inf, 40.0)  # every third link inextensible
    problem = grid(10, 10, slack=1.02, mass=1.0, gravity=9.81, axial_stiffness=stiffness).with_loads(
        [(44, (0.0, 0.0, -3.0)), (55, (1.0, 0.5, -2.0))]
    )
    solution = solve(problem)
    assert solution.status == "optimal"
    assert solution.objective == pytest.approx(clarabel_energy(problem), rel=1e-7)
    assert np.abs(unbalanced(problem, solution)[problem.free_nodes]).max() <= 1e-9 * problem.force_scale
    elastic = problem.elastic
    np.testing.assert_allclose(
        solution.link_tension[elastic],
        tensions_from_positions(problem, solution.positions)[elastic],
        rtol=0,
        atol=1e-9 * solution.link_tension.max(),
    )


# ----------------------------------------------------------------- statically indeterminate: stiffness decides
def test_four_elastic_strings_at_a_loaded_node_share_its_load_by_compatibility() -> None:
    """A node hung from four corners of a square (two strings stiffer than the others) carries a
    weight W: four unknown tensions, three equations of balance. Compatibility decides: each string
    stretches as its tension says, and the node sits where the four lengths meet. The node's place is
    found here by Newton's method on the three balance equations (scipy's fsolve)."""
    corners = np.array([[1.0, 1.0, 0.0], [-1.0, 1.0, 0.0], [-1.0, -1.0, 0.0], [1.0, -1.0, 0.0]])
    rest, stiffness, weight = 1.5, np.array([100.0, 100.0, 300.0, 300.0]), 20.0

    def balance(x: np.ndarray) -> np.ndarray:
        along = corners - x
        d = np.linalg.norm(along, axis=1)
        tension = stiffness / rest * np.maximum(d - rest, 0.0)
        return (tension[:, None] * along / d[:, None]).sum(axis=0) + np.array([0.0, 0.0, -weight])

    hub = fsolve(balance, np.array([0.0, 0.0, -1.2]), xtol=1e-13)
    d = np.linalg.norm(corners - hub, axis=1)
    expected = stiffness / rest * (d - rest)
    problem = Problem.build(
        nodes=5,
        links=[[k, 4, rest, ea] for k, ea in enumerate(stiffness)],
        masses=[0, 0, 0, 0, weight],
        gravity=1.0,
        supports=[(k, tuple(corner)) for k, corner in enumerate(corners)],
        dimension=3,
    )
    solution = solve(problem)
    assert solution.status == "optimal"
    np.testing.assert_allclose(solution.positions[4], hub, rtol=0, atol=1e-10)
    np.testing.assert_allclose(solution.link_tension, expected, rtol=1e-9)
    assert expected[2] > expected[0]  # (the stiffer strings carry more)


def test_a_symmetric_hub_has_its_closed_form() -> None:
    """Four equal strings from the corners of a square of half side a to a hub of weight W: by
    symmetry the hub sits on the axis, h below, and 4 T h / d = W with T = k (d - L), d = sqrt(2a^2 + h^2)."""
    a, rest, ea, weight = 1.0, 1.3, 50.0, 8.0
    k = ea / rest

    def vertical(h: float) -> float:
        d = math.hypot(math.sqrt(2.0) * a, h)
        return 4.0 * k * max(d - rest, 0.0) * h / d - weight

    h = brentq(vertical, 1e-9, 10.0, xtol=1e-15)
    corners = [(a, a, 0.0), (-a, a, 0.0), (-a, -a, 0.0), (a, -a, 0.0)]
    problem = Problem.build(
        nodes=5,
        links=[[i, 4, rest] for i in range(4)],
        masses=[0, 0, 0, 0, weight],
        gravity=1.0,
        supports=list(enumerate(corners)),
        dimension=3,
        axial_stiffness=ea,
    )
    solution = solve(problem)
    np.testing.assert_allclose(solution.positions[4], [0.0, 0.0, -h], rtol=0, atol=1e-12)
    d = math.hypot(math.sqrt(2.0) * a, h)
    np.testing.assert_allclose(solution.link_tension, k * (d - rest), rtol=1e-10)


# ----------------------------------------------------------------- pretension, no weight
def saddle(n: int = 9) -> Problem:
    """A weightless hyperbolic-paraboloid net: its boundary held on the saddle z = (x^2 - y^2) / 2 over
    [-1, 1]^2 (two corners high, two low), every link 2 % shorter than its span there: pretensioned.
    Two point loads push down."""
    plan = np.linspace(-1.0, 1.0, n)
    x, y = np.meshgrid(plan, plan)
    z = 0.5 * (x**2 - y**2)
    points = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    index = np.arange(n * n).reshape(n, n)
    pairs = np.vstack(
        [
            np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()]),
            np.column_stack([index[:-1, :].ravel(), index[1:, :].ravel()]),
        ]
    )
    span = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    boundary = np.unique(np.concatenate([index[0], index[-1], index[:, 0], index[:, -1]]))
    return Problem.build(
        nodes=n * n,
        links=[[int(i), int(j), 0.98 * s, 1e3] for (i, j), s in zip(pairs, span, strict=True)],
        masses=0.0,
        gravity=9.81,
        supports=[(int(i), tuple(points[i])) for i in boundary],
        dimension=3,
        loads=[(int(index[n // 2, n // 2]), (0.0, 0.0, -5.0)), (int(index[n // 3, n // 2]), (0.0, 0.0, -5.0))],
    )


def test_a_weightless_pretensioned_saddle_carries_point_loads_in_balance() -> None:
    problem = saddle()
    assert problem.weight == 0.0
    solution = solve(problem)
    assert solution.status == "optimal"
    assert np.abs(unbalanced(problem, solution)[problem.free_nodes]).max() <= 1e-9 * problem.force_scale
    assert solution.link_tension.min() > 0.0  # (pretensioned: every link pulls)
    np.testing.assert_allclose(solution.link_tension, tensions_from_positions(problem, solution.positions), rtol=1e-9)
    carried = solution.support_reactions.sum(axis=0)
    np.testing.assert_allclose(carried, [0.0, 0.0, 10.0], rtol=0, atol=1e-9 * 10.0)


# ----------------------------------------------------------------- random elastic nets
@st.composite
def elastic_nets(draw: st.DrawFn) -> Problem:
    rows, columns = draw(st.integers(3, 8)), draw(st.integers(3, 8))
    slack = draw(st.floats(0.97, 1.3))  # (below 1: pretensioned)
    stiffness = draw(st.sampled_from([1.0, 30.0, 1e3, 1e6]))
    mixed = draw(st.booleans())
    base = grid(rows, columns, slack=slack, mass=1.0)
    ea = np.full(base.n_links, stiffness)
    if mixed:
        ea[:: draw(st.integers(2, 5))] = np.inf
    return grid(rows, columns, slack=slack, mass=draw(st.sampled_from([0.0, 1.0])) or 1.0, axial_stiffness=ea)


@settings(max_examples=examples(1))
@given(elastic_nets())
def test_a_random_elastic_net_is_in_verified_balance_or_says_why_not(problem: Problem) -> None:
    try:
        solution = solve(problem)
    except FunicularError:
        return
    if solution.status != "optimal":
        assert solution.kkt_scaled.max() > 1e-10
        return
    assert np.abs(unbalanced(problem, solution)[problem.free_nodes]).max() <= 1e-8 * problem.force_scale
    elastic = problem.elastic
    # (the solver meets each link's law d - L0 - T L0 / EA = 0 to its tolerance, 1e-10 of the longest
    # link: a stiff link's tension read back from its stretch is that much times EA / L0 off)
    assert problem.axial_stiffness is not None
    stiffest = float((problem.axial_stiffness[elastic] / problem.link_lengths[elastic]).max())
    rounding = stiffest * 1e-10 * float(problem.link_lengths.max())
    np.testing.assert_allclose(
        solution.link_tension[elastic],
        tensions_from_positions(problem, solution.positions)[elastic],
        rtol=0,
        atol=1e-8 * max(solution.link_tension.max(), problem.force_scale) + rounding,
    )


# ----------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("keywords", "key"),
    [
        ({"axial_stiffness": 0.0}, "axial_stiffness"),
        ({"axial_stiffness": -5.0}, "axial_stiffness"),
        ({"axial_stiffness": math.nan}, "axial_stiffness"),
        ({"axial_stiffness": [1.0, 2.0]}, "axial_stiffness"),
        ({"units": "imperial"}, "units"),
        ({"mass": 1.0, "linear_density": 1.0}, "Problem.build"),
        ({"axial_stiffness": 10.0, "formulation": "squared"}, "axial_stiffness"),
    ],
)
def test_bad_elastic_input_is_one_sentence_naming_the_key(keywords: dict[str, object], key: str) -> None:
    arguments: dict[str, object] = {"nodes": 4, "link_length": 1.0, "supports": [(0, (0.0, 0.0))]}
    if "linear_density" not in keywords:
        arguments["mass"] = 1.0
    with pytest.raises(ScenarioError) as error:
        Problem.build(**(arguments | keywords))  # type: ignore[arg-type]
    assert error.value.key == key
    assert str(error.value).count(". ") <= 1 and "\n" not in str(error.value)


def test_weightless_and_unloaded_rigid_links_are_refused() -> None:
    with pytest.raises(ScenarioError, match="every node has mass 0") as error:
        Problem.build(nodes=3, link_length=1.0, masses=0.0, supports=[(0, (0.0, 0.0))])
    assert error.value.key == "masses"


@pytest.mark.parametrize(
    ("table", "needle"),
    [
        ("[chain]\nnodes = 3\nlink_length = 1.0\nmass = 1.0\naxial_stiffness = -1.0\n", "chain.axial_stiffness"),
        ("[chain]\nnodes = 3\nlink_length = 1.0\nmass = 1.0\nlinear_density = 1.0\n", "linear_density"),
        ('units = "feet"\n[chain]\nnodes = 3\nlink_length = 1.0\nmass = 1.0\n', "units"),
        ("[chain]\nnodes = 3\nlink_length = 1.0\nmass = 1.0\naxial_stiffness = [1.0, 2.0]\n", "axial_stiffnesses"),
    ],
)
def test_a_bad_elastic_scenario_file_exits_2_naming_the_key(tmp_path: Path, table: str, needle: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(table + "[[supports]]\nnode = 0\nposition = [0.0, 0.0]\n")
    result = cli("solve", str(path))
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and needle in result.stderr
    assert result.stderr.strip().count("\n") == 0


def test_a_net_link_row_of_the_wrong_length_is_named(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(
        "dimension = 3\n[net]\nnodes = 3\nmass = 1.0\nlinks = [[0, 1, 1.0, 10.0, 3.0], [1, 2, 1.0]]\n"
        "[[supports]]\nnode = 0\nposition = [0.0, 0.0, 0.0]\n"
    )
    result = cli("solve", str(path))
    assert result.returncode == 2 and "net.links[0]" in result.stderr and "[i, j, length, EA]" in result.stderr


# ----------------------------------------------------------------- reach
def test_an_elastic_line_reaches_supports_farther_apart_than_its_length_and_a_rigid_one_does_not() -> None:
    taut = {"nodes": 11, "length": 10.0, "mass": 1.0, "gravity": 1.0, "supports": [(0, (0.0, 0.0)), (-1, (10.5, 0.0))]}
    solution = solve(Problem.build(**taut, axial_stiffness=1e3))  # type: ignore[arg-type]
    assert solution.status == "optimal"
    assert solution.link_strain.min() > 0.04  # (stretched 5 %, and a little more by its weight)
    with pytest.raises(funicular.InfeasibleError, match="apart"):
        solve(Problem.build(**taut))  # type: ignore[arg-type]
