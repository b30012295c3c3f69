"""Nets in the studies and front ends: explore from several starts, the other solvers' scope, refinement."""

from __future__ import annotations

import numpy as np
import pytest

from funicular import nets
from funicular.backends import solve_with
from funicular.cli import main
from funicular.errors import ScenarioError, SolverError
from funicular.model import Problem
from funicular.obstacles import Sphere
from funicular.scenario import load_scenario
from funicular.studies.explore import explore, starting_shapes
from funicular.studies.refine import convergence_columns, refine


def _net_over_sphere() -> Problem:
    return nets.grid(6, 6, slack=1.2, mass=1.0, gravity=1.0, obstacles=[Sphere(center=(0.5, 0.5, -0.45), radius=0.3)])


def test_a_nets_starts_differ_and_keep_its_supports_in_place() -> None:
    problem = _net_over_sphere()
    shapes = starting_shapes(problem, 4, seed=1)
    assert len(shapes) == 4 and all(shape.shape == (36, 3) for shape in shapes)
    assert not np.allclose(shapes[0], shapes[1])


def test_exploring_a_net_finds_equilibria_that_balance_its_weight() -> None:
    problem = _net_over_sphere()
    exploration = explore(problem, starts=3, seed=0)
    assert exploration.equilibria
    for equilibrium in exploration.equilibria:
        solution = equilibrium.solution
        assert solution.status == "optimal"
        carried = solution.support_reactions.sum(axis=0) + solution.contact_forces.sum(axis=0)
        np.testing.assert_allclose(carried, [0.0, 0.0, problem.weight], atol=1e-9 * problem.weight)


def test_the_other_solvers_say_they_solve_planar_chains(capsys: pytest.CaptureFixture[str]) -> None:
    problem = _net_over_sphere()
    with pytest.raises(SolverError, match="solves planar chains"):
        solve_with(problem, "slsqp")
    assert main(["solve", "net-over-sphere", "--solver", "slsqp"]) == 2
    assert "solves planar chains" in capsys.readouterr().err


def test_refinement_studies_a_chain_in_space_but_not_a_net() -> None:
    with pytest.raises(ScenarioError, match="a net has no N to refine"):
        refine(_net_over_sphere(), [5, 9])
    study = refine(load_scenario("chain-around-post"), [9, 17])
    headers, rows = convergence_columns(study)
    assert "R0 z" in headers and all(len(row) == len(headers) for row in rows)
