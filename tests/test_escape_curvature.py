"""The saddle escape's second-order test on the solver's own Newton matrix (``solver.curvature``):
its eigenvalue search against a dense eigensolver, and its verdicts and directions against the
checker's (``checks.second_order``), which evaluates the point on its own, in physical units."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from funicular import Problem, Solution, SolverOptions, checks
from funicular.benchmark import family
from funicular.scenario import builtin_scenarios, load_scenario
from funicular.solver import ipm
from funicular.solver.banded import BlockTridiagonal, LinearSolver, banded_cholesky
from funicular.solver.compiled import HAVE_NUMBA, block_cholesky
from funicular.solver.curvature import Curvature, escape_test, lowest_eigenpair

SOLVERS = [pytest.param(banded_cholesky, id="lapack")]
if HAVE_NUMBA:
    SOLVERS.append(pytest.param(block_cholesky, id="block"))

MINIMUM = "strict local minimum"


# ----------------------------------------------------------------- the eigenvalue search
def _random_matrix(blocks: int, seed: int) -> BlockTridiagonal:
    rng = np.random.default_rng(seed)
    diagonal = rng.standard_normal((blocks, 2, 2))
    diagonal = diagonal + diagonal.transpose(0, 2, 1)
    return BlockTridiagonal(diagonal, rng.standard_normal((blocks - 1, 2, 2)))


@pytest.mark.parametrize("linear_solver", SOLVERS)
@settings(max_examples=60, deadline=None)
@given(blocks=st.integers(1, 40), seed=st.integers(0, 2**32 - 1), room=st.floats(0.01, 100.0))
def test_lowest_eigenpair_matches_a_dense_eigensolver(
    linear_solver: LinearSolver, blocks: int, seed: int, room: float
) -> None:
    matrix = _random_matrix(blocks, seed)
    values, vectors = np.linalg.eigh(matrix.to_dense())
    scale = float(np.abs(values).max())
    below = values[0] - room * scale  # the search may start far below
    above = values[0] + 0.5 * (values[-1] - values[0]) if values.size > 1 else values[0] + scale
    start = np.random.default_rng(seed + 1).standard_normal(matrix.size)
    found = lowest_eigenpair(matrix, below, above, linear_solver, start)
    assert found is not None
    value, vector = found
    assert value == pytest.approx(values[0], abs=1e-9 * scale)
    assert np.linalg.norm(vector) == pytest.approx(1.0)
    gap = values[1] - values[0] if values.size > 1 else scale
    if gap > 1e-3 * scale:  # the eigenvector is well determined
        assert abs(float(vector @ vectors[:, 0])) == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize("linear_solver", SOLVERS)
def test_lowest_eigenpair_refuses_a_bracket_that_does_not_hold(linear_solver: LinearSolver) -> None:
    matrix = _random_matrix(10, 7)
    lowest = float(np.linalg.eigvalsh(matrix.to_dense())[0])
    start = np.ones(matrix.size)
    # Not below the spectrum: the first factorization fails.
    assert lowest_eigenpair(matrix, lowest + 0.1, lowest + 1.0, linear_solver, start) is None
    # The eigenvalue above the bracket: no vector gets below its top.
    assert lowest_eigenpair(matrix, lowest - 2.0, lowest - 1.0, linear_solver, start) is None


# ----------------------------------------------------------------- against the checker
@functools.cache
def _judged(name: str, nodes: int | None) -> tuple[Problem, Solution, Curvature]:
    problem = family(nodes or 0, "disk") if name == "family" else load_scenario(name)
    once = ipm._solve_once(problem, SolverOptions(escape_saddles=False), None, True)
    assert once.judge is not None
    return problem, once.outcome.solution(once.outcome.iterations, 0.0), once.judge()


CASES = [("family", n) for n in (20, 50, 51, 200)] + [
    (name, None)
    for name in sorted(builtin_scenarios())
    if load_scenario(name).obstacles and load_scenario(name).contact == "nodes"
]


@pytest.mark.parametrize(("name", "nodes"), CASES)
def test_verdicts_agree_with_the_checker(name: str, nodes: int | None) -> None:
    problem, solution, verdict = _judged(name, nodes)
    full = checks.second_order(problem, solution)
    if verdict.minimum:  # sound: only where the checker finds the sufficient condition
        assert full.verdict == MINIMUM
    if full.verdict == MINIMUM:  # and it proves the built-ins' minima (curvatures well above zero)
        assert verdict.minimum
    assert (verdict.direction is not None) == (full.verdict == "not a minimum")


@pytest.mark.parametrize(("name", "nodes"), [c for c in CASES if c[0] in ("family", "disk-drape")])
def test_saddle_directions_agree_with_the_checker(name: str, nodes: int | None) -> None:
    # The symmetric chain balanced on the disk's top: the penalized matrix's lowest eigenvector is
    # the checker's (the reduced Hessian's) up to O(1 / rho), and its eigenvalue is at most the
    # reduced curvature (the null space is one of the directions it minimizes over), within 2%.
    problem, solution, verdict = _judged(name, nodes)
    full = checks.second_order(problem, solution)
    assert full.verdict == "not a minimum" and full.direction is not None and verdict.direction is not None
    assert np.all(verdict.direction[problem.support_nodes] == 0.0)
    a, b = verdict.direction.ravel(), full.direction.ravel()
    assert abs(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b)) == pytest.approx(1.0, abs=1e-6)
    # Scaled curvature (length unit: the longest link, force unit: the weight) to physical.
    physical = verdict.value * problem.weight / float(problem.link_lengths.max())
    assert full.min_eigenvalue * 1.02 <= physical <= full.min_eigenvalue


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")
@pytest.mark.parametrize(("name", "nodes"), CASES)
def test_the_compiled_test_agrees_with_the_numpy_steps(name: str, nodes: int | None) -> None:
    """``driver.escape_curvature`` (taken with the block Cholesky) against the same test's numpy
    steps with LAPACK's Cholesky: the same verdict, curvature and direction (up to rounding)."""
    problem = family(nodes or 0, "disk") if name == "family" else load_scenario(name)
    once = ipm._solve_once(problem, SolverOptions(escape_saddles=False), None, True)
    assert isinstance(once.judge, functools.partial)
    chain, point, mu, linear_solver = once.judge.args
    assert linear_solver is block_cholesky
    compiled, steps = escape_test(chain, point, mu, block_cholesky), escape_test(chain, point, mu, banded_cholesky)
    assert compiled.minimum == steps.minimum
    assert (compiled.direction is None) == (steps.direction is None)
    if compiled.direction is not None and steps.direction is not None:
        assert compiled.value == pytest.approx(steps.value, rel=1e-8)
        a, b = compiled.direction.ravel(), steps.direction.ravel()
        assert abs(a @ b) == pytest.approx(1.0, abs=1e-10)
