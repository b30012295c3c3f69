"""What the per-solve overhead's shortcuts rely on: the problem's cached quantities equal a fresh
computation, the presolve's obstacle gradients equal a fresh evaluation, and solves still end at
balanced equilibria (checked independently of the solver's own
multipliers)."""

from __future__ import annotations

import dataclasses
from importlib.util import find_spec

import numpy as np
import pytest
from bench.run import family

from funicular import Problem, SolverOptions, solve
from funicular._solver.initial import presolve
from funicular.checks import recover_multipliers, second_order
from funicular.obstacles import Box, Disk, Ellipse, Expression, Graph, HalfPlane, Obstacle, depth
from funicular.scenario import builtin_scenarios, load_scenario

SCENARIOS = sorted(builtin_scenarios())


def _obstacle(kind: str, x: float, y: float, size: float) -> Obstacle:
    if kind == "disk":
        return Disk((x, y), size)
    if kind == "ellipse":
        return Ellipse((x, y), (size, 0.4 * size), 30.0)
    if kind == "halfplane":
        return HalfPlane((x, y), (0.3, 1.0))
    if kind == "graph":  # a bump of height `size` at x on the ground at y
        return Graph(f"{y!r} + {size!r} * exp(-(x - {x!r})**2 / {size!r}**2)")
    if kind == "expression":  # an ellipse written out, and turned
        return Expression(
            f"1 - ((x - {x!r}) + 0.3 * (y - {y!r}))**2 / {size!r}**2 - (y - {y!r})**2 / (0.5 * {size!r})**2"
        )
    return Box((x, y), (size, 0.5 * size), 0.2 * size, 15.0)


KINDS = ["disk", "ellipse", "halfplane", "box"] + (["graph", "expression"] if find_spec("sympy") else [])


# ----------------------------------------------------------------- the problem's caches
@pytest.mark.parametrize("name", SCENARIOS)
def test_cached_quantities_equal_a_fresh_computation(name: str) -> None:
    problem = load_scenario(name)
    n = problem.n_nodes
    assert problem.total_mass == float(np.sum(problem.masses))
    assert problem.total_length == float(np.sum(problem.link_lengths))
    assert problem.weight == problem.gravity * float(np.sum(problem.masses))
    arc = np.concatenate(([0.0], np.cumsum(problem.link_lengths))) / float(np.sum(problem.link_lengths))
    np.testing.assert_array_equal(problem.arc_fractions, arc)
    support = np.isin(np.arange(n), problem.support_nodes)
    np.testing.assert_array_equal(problem.is_support, support)
    np.testing.assert_array_equal(problem.free_nodes, np.flatnonzero(~support))
    assert problem.free_nodes.dtype == np.intp
    positions = np.arange(2.0 * n).reshape(n, 2)  # (a slice of consecutive free nodes, or their indices)
    np.testing.assert_array_equal(positions[problem.free_rows], positions[np.flatnonzero(~support)])
    assert problem.support_depths.shape == (len(problem.obstacles), problem.support_nodes.size)
    for j, obstacle in enumerate(problem.obstacles):
        np.testing.assert_array_equal(problem.support_depths[j], depth(obstacle, problem.support_positions))
    for array in (problem.arc_fractions, problem.is_support, problem.free_nodes, problem.support_depths):
        assert not array.flags.writeable  # shared by every caller: nobody may change it


def test_a_changed_copy_computes_its_own() -> None:
    problem = family(20, "disk")
    assert problem.total_length == pytest.approx(1.5)
    finer = problem.with_nodes(41)
    assert finer.free_nodes.size == 39 and finer.arc_fractions.size == 41
    assert problem.support_depths[0, 0] < 0.0
    moved = dataclasses.replace(problem, obstacles=(Disk((0.0, -0.1), 0.5),))
    assert moved.support_depths[0, 0] > 0.0  # support 0 inside the moved disk


# ----------------------------------------------------------------- presolve
@pytest.mark.parametrize("name", ["disk-drape", "box-edge", "two-pegs", "terrain", "three-supports", "slope"])
def test_the_presolves_obstacle_gradients_are_a_fresh_evaluations(name: str) -> None:
    """The push-out's gradients, which the solver's scaling takes instead of evaluating again, are
    the obstacles' at the final movable positions."""
    problem = load_scenario(name)
    solution = solve(problem)
    for guess in (None, solution.positions, solution.positions + 0.1 * float(problem.link_lengths.max())):
        start = presolve(problem, guess)
        if start.obstacle_gradients is not None:
            for obstacle, gradient in zip(problem.obstacles, start.obstacle_gradients, strict=True):
                np.testing.assert_array_equal(gradient, obstacle.evaluate(start.positions[start.movable])[1])


def test_no_gradients_after_a_push() -> None:
    """A guess with a node inside the disk is pushed out: its gradients are stale, none are kept."""
    problem = family(50, "disk")
    inside = presolve(problem).positions.copy()
    inside[25] = (0.5, -0.5)
    assert presolve(problem, inside).obstacle_gradients is None
    assert presolve(problem).obstacle_gradients is not None


# ----------------------------------------------------------------- solves
def test_the_benchmark_disk_is_a_balanced_minimum() -> None:
    """family(50, "disk") drapes over the disk: converged, a strict local minimum, and the solver's
    forces are the ones recovered from its positions alone."""
    problem = family(50, "disk")
    solution = solve(problem)
    assert solution.converged and solution.kkt_scaled.max() <= 1e-9
    assert second_order(problem, solution).verdict == "strict local minimum"
    recovered = recover_multipliers(problem, solution.positions)
    np.testing.assert_allclose(solution.link_multipliers, recovered.link, rtol=0, atol=1e-7 * problem.weight)
    np.testing.assert_allclose(solution.obstacle_multipliers, recovered.obstacle, rtol=0, atol=1e-7 * problem.weight)
    assert np.count_nonzero(solution.obstacle_multipliers > 1e-6) >= 5  # it rests on the disk


@pytest.mark.parametrize("formulation", ["norm", "squared"])
def test_link_contact_without_obstacles_solves_a_dangling_chain(formulation: str) -> None:
    """contact = "links" with no obstacle and one support: the solver's obstacle multipliers have
    no rows but N - 1 columns (their copy from the node rows failed on the shapes). The tensions
    are the weights below each link (docs/model.md, "The dangling chain")."""
    n, mass, g = 20, 2.0, 9.81
    problem = Problem.build(
        nodes=n, length=1.5, mass=mass, gravity=g, supports=[(0, (0.0, 0.0))], contact="links", formulation=formulation
    )
    for options in (SolverOptions(), SolverOptions(exact_start=False)):
        solution = solve(problem, options=options)
        assert solution.converged
        assert solution.obstacle_multipliers.shape == (0, n - 1)
        expected = mass * g * (n - 1 - np.arange(n - 1)) / n
        np.testing.assert_allclose(solution.link_tension, expected, rtol=1e-9)
