"""The solver on its own terms: the banded Newton matrix, degenerate inputs, invariances, failures."""

from __future__ import annotations

import numpy as np
import pytest

from funicular import InfeasibleError, Problem, SolverOptions, Status, solve
from funicular._solver.initial import presolve
from funicular.scenario import builtin_scenarios, load_scenario


def two_supports(nodes: int = 21, length: float = 1.5, formulation: str = "norm", **kw: object) -> Problem:
    return Problem.build(
        nodes=nodes,
        length=length,
        mass=1.0,
        gravity=1.0,
        formulation=formulation,
        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.2))],
        **kw,  # type: ignore[arg-type]
    )


ELASTIC = {name for name in builtin_scenarios() if load_scenario(name).axial_stiffness is not None}


@pytest.mark.parametrize(
    ("name", "formulation"),
    [
        (name, formulation)
        for name in sorted(builtin_scenarios())
        for formulation in ("norm", "squared")
        if formulation == "norm" or name not in ELASTIC  # (elastic links: the norm formulation only)
    ],
)
def test_builtin_scenarios_reach_kkt_tolerance(name: str, formulation: str) -> None:
    """Every built-in solves to scaled KKT residuals <= 1e-9, no node is inside an obstacle, and
    supports plus obstacles carry the whole weight and the point loads (the sum of all forces on
    the structure vanishes)."""
    problem = load_scenario(name).with_formulation(formulation)
    solution = solve(problem)
    assert solution.status is Status.OPTIMAL
    assert solution.kkt_scaled.max() <= 1e-9, solution.kkt_scaled
    total = solution.support_reactions.sum(axis=0) + solution.contact_forces.sum(axis=0)
    carried = np.zeros(problem.dimension)
    carried[-1] = problem.weight  # gravity acts along the last axis
    if problem.loads is not None:
        carried -= problem.loads.sum(axis=0)
    np.testing.assert_allclose(total, carried, atol=1e-9 * problem.force_scale)
    for obstacle in problem.obstacles:
        assert np.all(obstacle.evaluate(solution.positions)[0] <= 1e-12)


def test_supports_too_far_apart_name_both_supports() -> None:
    problem = Problem.build(nodes=5, length=1.0, mass=1.0, supports=[(0, (0, 0)), (2, (0.4, 0)), (4, (1.2, 0))])
    with pytest.raises(InfeasibleError, match=r"nodes 2 .* and 4 .* are 0\.8 apart.* only 0\.5 long"):
        solve(problem)


def test_taut_slanted_chain_has_no_finite_equilibrium() -> None:
    """A straight taut chain with mass on a slant would need infinite tension: say so, don't pretend."""
    problem = Problem.build(nodes=4, link_length=0.5, mass=1.0, supports=[(0, (0, 0)), (-1, (0.9, 1.2))])
    with pytest.raises(InfeasibleError, match="infinite tension"):
        solve(problem)


def test_taut_vertical_chain_tensions_follow_the_weights() -> None:
    """Vertical taut chain: nodes evenly spaced; link k carries the weight of the interior nodes below it
    (the least pre-tension choice: the lowest link is slack in force), and the supports carry the rest."""
    n, m = 6, 0.25
    problem = Problem.build(nodes=n, link_length=0.2, masses=m, gravity=2.0, supports=[(0, (1, 0)), (-1, (1, -1))])
    solution = solve(problem)
    assert solution.converged
    np.testing.assert_allclose(solution.y, -0.2 * np.arange(n), atol=1e-15)
    expected = 2.0 * m * np.array([4, 3, 2, 1, 0])
    np.testing.assert_allclose(solution.link_tension, expected, atol=1e-12)
    np.testing.assert_allclose(solution.support_reactions[:, 1], [2.0 * m * 5, 2.0 * m], atol=1e-12)


def test_zero_masses_single_free_node_and_supports_everywhere() -> None:
    single = Problem.build(
        nodes=3, link_length=1.0, masses=[0, 2, 0], gravity=1.0, supports=[(0, (0, 0)), (2, (1.2, 0))]
    )
    s = solve(single)
    # One free node hanging from two links of length 1 between supports 1.2 apart: it sits at depth 0.8.
    np.testing.assert_allclose(s.positions[1], [0.6, -0.8], atol=1e-10)
    np.testing.assert_allclose(s.link_tension, [1.0 / 0.8 * 1.0, 1.0 / 0.8 * 1.0], rtol=1e-9)
    everywhere = Problem.build(nodes=3, link_length=1.0, mass=1.0, supports=[(0, (0, 0)), (1, (0.5, 0)), (2, (1, 0))])
    e = solve(everywhere)
    assert e.converged and e.iterations == 0
    np.testing.assert_allclose(e.support_reactions[:, 1], everywhere.gravity * everywhere.masses)


@pytest.mark.parametrize(
    "nodes",
    [
        3,
        11,
        20,
        101,
        21,
    ],
)
def test_coincident_supports_hang_a_loop(nodes: int) -> None:
    """Both ends at one point: the chain folds into a double vertical line; the supports carry the weight
    together with no horizontal force (how they share it is not unique: the two branches are parallel)."""
    problem = Problem.build(nodes=nodes, length=2.0, mass=1.0, gravity=1.0, supports=[(0, (0, 0)), (-1, (0, 0))])
    solution = solve(problem)
    assert solution.converged and solution.kkt.max() <= 1e-9
    np.testing.assert_allclose(solution.support_reactions.sum(axis=0), [0.0, 1.0], atol=1e-9)


@pytest.mark.parametrize(("scale", "offset"), [(1e-6, 0.0), (1e6, 0.0), (1.0, 1e6), (1e6, 1e6)])
def test_units_and_offsets_do_not_matter(scale: float, offset: float) -> None:
    """Scaling all lengths by s and shifting by an offset scales positions and keeps forces.

    (A tiny chain far from the origin is not in the list: its positions cannot even be represented
    to the accuracy asked for, 1e6 + 1e-8 being rounded to 1e-10.)"""
    base = two_supports(nodes=31)
    moved = Problem.build(
        nodes=31,
        length=1.5 * scale,
        mass=1.0,
        gravity=1.0,
        supports=[(0, (offset, offset)), (-1, (offset + scale, offset + 0.2 * scale))],
    )
    a, b = solve(base), solve(moved)
    assert b.converged
    assert b.kkt_scaled.max() <= 1e-8
    np.testing.assert_allclose((b.positions - offset) / scale, a.positions, atol=1e-7)
    np.testing.assert_allclose(b.link_tension, a.link_tension, rtol=1e-7)


def test_iteration_limit_is_reported_not_hidden() -> None:
    # (On a disk: a chain that touches nothing starts from its exact answer, see spans.exact_start.)
    solution = solve(load_scenario("disk-drape"), max_iterations=1)
    assert solution.status is Status.MAX_ITERATIONS
    assert not solution.converged
    assert solution.kkt.max() > 1e-6
    assert solution.to_dict()["status"] == "max_iterations"


def test_coarse_to_fine_on_chains_that_once_failed_it() -> None:
    """Chains above the coarse-to-fine threshold without obstacles:
    a nearly taut span that the coarse chain cannot span (its support moves to a coarse node),
    link contact without obstacles, and an interior support, whose coarse answer must be lined up
    with the fine supports (the polish from it failed and the solve took 64 steps)."""
    nearly_taut = Problem.build(
        nodes=4001, length=2.0, mass=1.0, supports=[(0, (0.0, 0.0)), (2000, (0.9995, 0.0)), (-1, (1.999, 0.0))]
    )
    links_mode = Problem.build(
        nodes=4001, length=1.5, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))], contact="links"
    )
    three = load_scenario("three-supports").with_nodes(8001)
    for problem in (nearly_taut, links_mode, three):
        solution = solve(problem)
        direct = solve(problem, initial_positions=presolve(problem).positions)  # no coarse level
        assert solution.converged and direct.converged
        np.testing.assert_allclose(solution.positions, direct.positions, rtol=0, atol=1e-8)
        np.testing.assert_allclose(solution.link_tension, direct.link_tension, rtol=0, atol=1e-8 * problem.weight)
    assert solve(three).iterations < solve(three, initial_positions=presolve(three).positions).iterations


def test_a_guess_for_massless_end_nodes_is_ignored() -> None:
    """Massless free ends are left out of the solve; a far-off guess for them must not loosen the
    tolerance (it entered the rounding floor: 6.5e-5 off in position)."""
    masses = np.ones(60)
    masses[-5:] = 0.0
    problem = Problem.build(nodes=60, length=1.5, masses=masses, supports=[(0, (0.0, 0.0)), (50, (1.0, 0.0))])
    guess = presolve(problem).positions.copy()
    guess[-5:] = 1e9
    reference, guessed = solve(problem), solve(problem, initial_positions=guess)
    np.testing.assert_allclose(guessed.positions, reference.positions, rtol=0, atol=1e-10)
    np.testing.assert_allclose(guessed.link_tension, reference.link_tension, rtol=0, atol=1e-10)


def test_a_stale_large_multiplier_does_not_loosen_the_polishs_test() -> None:
    """The polish's force floor grows with the largest force at the polished point, not at its
    start: a guess with one link's multiplier 10^5 times too large (as a stale guess could have)
    must still end below the plain rounding floor."""
    from funicular._constraints import link_distances, multipliers_from_tension
    from funicular._solver import front_end
    from funicular._solver.spans import exact_start

    offset = 1e6  # a floor of 9e-9, large enough to matter
    problem = Problem.build(
        nodes=21, link_lengths=0.1, mass=1.0, supports=[(0, (offset, offset)), (-1, (offset + 1.5, offset + 0.3))]
    )
    exact = exact_start(problem)
    assert exact is not None
    positions = exact[0].copy()
    positions[1:-1] += 1e-3 * np.random.default_rng(0).standard_normal((19, 2))
    multipliers = multipliers_from_tension(problem.formulation, exact[1], link_distances(positions))
    multipliers[3] *= 1e5
    solution, _ = front_end._solve(
        problem, SolverOptions(), positions, multipliers, np.zeros((0, problem.n_nodes)), True
    )
    assert solution.status is Status.OPTIMAL
    assert solution.kkt_scaled.max() <= 1e-7  # (the stale multiplier's floor stopped it at 2.6e-5)
