"""The compiled interior-point loop (``solver.driver``) against the Python loop of ``ipm._iterate``
running the same compiled kernels: the same steps, the same stops, the same equilibria."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from funicular import Problem, SolverOptions, solve
from funicular.benchmark import family
from funicular.obstacles import Disk
from funicular.scenario import builtin_scenarios, load_scenario
from funicular.solution import Solution
from funicular.solver import ipm
from funicular.solver.compiled import HAVE_NUMBA, block_cholesky, driver
from funicular.solver.initial import presolve

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")

# The compiled loop runs whenever the linear solver is the default; naming the same compiled block
# Cholesky explicitly sends the solve through the Python loop with every kernel unchanged.
LOOPS = {"compiled loop": {}, "python loop": {"linear_solver": block_cholesky}}


def _problems() -> dict[str, Problem]:
    problems = {name: load_scenario(name) for name in builtin_scenarios()}
    problems["bench disk 50"] = family(50, "disk")
    problems["bench disk 201"] = family(201, "disk")
    problems["bench free 120"] = family(120)
    return problems


PROBLEMS = _problems()


def _solve(problem: Problem, loop: str, **settings: object) -> Solution:
    options = SolverOptions(compiled=True, exact_start=False, **LOOPS[loop], **settings)  # type: ignore[arg-type]
    return solve(problem, options)


def test_the_compiled_loop_is_the_one_taken() -> None:
    """Without this the comparisons below would compare the Python loop with itself."""
    problem = family(50, "disk")
    chain = ipm._scale(problem, presolve(problem), compiled=True)
    assert ipm._loop_compiles(chain, SolverOptions(compiled=True))
    assert not ipm._loop_compiles(chain, SolverOptions(compiled=True, linear_solver=block_cholesky))
    assert not ipm._loop_compiles(ipm._scale(problem, presolve(problem), compiled=False), SolverOptions())


@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_both_loops_take_the_same_steps_to_the_same_equilibrium(name: str) -> None:
    problem = PROBLEMS[name]
    compiled, python = (_solve(problem, loop) for loop in LOOPS)
    assert compiled.converged and python.converged
    assert compiled.iterations == python.iterations
    size, weight = float(problem.link_lengths.sum()), problem.weight
    for name_, unit in (("positions", size), ("link_tension", weight), ("contact_forces", weight)):
        np.testing.assert_allclose(
            getattr(compiled, name_), getattr(python, name_), rtol=0, atol=1e-12 * unit, err_msg=name_
        )


@pytest.mark.parametrize("steps", [0, 1, 4])
def test_both_loops_stop_at_the_iteration_limit_at_the_same_point(steps: int) -> None:
    """Stopped early, the iterate itself (not a converged answer) must be the same."""
    problem = family(60, "disk")
    compiled, python = (_solve(problem, loop, max_iterations=steps, escape_saddles=False) for loop in LOOPS)
    for result in (compiled, python):
        assert result.status.value == "max_iterations"
        assert result.iterations == steps
    np.testing.assert_allclose(compiled.positions, python.positions, rtol=0, atol=1e-12)


def test_the_compiled_loop_with_two_obstacles_and_a_middle_support() -> None:
    """Two disks, one support in the middle, a squared formulation: every row kind of the loop."""
    problem = Problem.build(
        nodes=81,
        length=3.0,
        mass=2.0,
        gravity=9.81,
        formulation="squared",
        supports=[(0, (0.0, 0.0)), (40, (1.0, -0.2)), (-1, (2.0, 0.1))],
        obstacles=[Disk((0.45, -0.75), 0.3), Disk((1.5, -0.8), 0.35)],
    )
    compiled, python = (_solve(problem, loop) for loop in LOOPS)
    assert compiled.converged and python.converged
    assert compiled.iterations == python.iterations
    np.testing.assert_allclose(compiled.positions, python.positions, rtol=0, atol=1e-12 * 3.0)
    assert np.max(compiled.contact_forces) > 0.0  # (it does touch)


def test_the_compiled_loop_polishes_on_its_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without this the loops above could agree because both ran ipm's polish: the compiled loop
    runs its own (``driver._polish``) and leaves ipm's to the steps its elimination cannot take."""

    polish = ipm._polish

    def refuse(*args: object, **kwargs: object) -> object:
        # (a coarse level's guess is polished before the loop, by ipm: ``start`` given)
        assert "start" in kwargs, "ipm._polish ran inside the compiled loop"
        return polish(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(ipm, "_polish", refuse)
    for problem in (family(50, "disk"), family(120), PROBLEMS["bench disk 201"]):
        assert _solve(problem, "compiled loop").converged


@st.composite
def _contact_runs(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Touching nodes in runs, contact forces of either sign, and which nodes leave."""
    shape = (draw(st.integers(1, 2)), draw(st.integers(1, 40)))
    active = draw(hnp.arrays(np.bool_, shape))
    forces = draw(hnp.arrays(np.float64, shape, elements=st.floats(-5.0, 5.0)))
    nu = np.where(active, forces, 0.0)
    return active, nu, active & (nu < 0.0)


@settings(max_examples=200, deadline=None)
@given(_contact_runs())
def test_the_compiled_lift_off_drops_the_nodes_ipm_drops(runs: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    """``driver._lifting_off`` walks the runs node by node; ``ipm._lifting_off`` finds them with
    numpy: the same nodes leave (the hand-made cases are in test_contact)."""
    active, nu, leaving = runs
    np.testing.assert_array_equal(driver()._lifting_off(active, nu, leaving), ipm._lifting_off(active, nu, leaving))


def test_both_loops_go_on_alike_after_a_polish_that_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    """A polish tried far too early (from a scaled KKT error of 0.1) guesses the active set wrongly
    and gives up; both loops must then take the same interior-point steps to the same point."""
    monkeypatch.setattr(ipm, "POLISH_FROM", 0.1)
    ipm._driver_constants.cache_clear()  # (the compiled loop's copy of the constants)
    try:
        polish, failures = ipm._polish, []

        def counted(*args: object, **kwargs: object) -> object:
            result = polish(*args, **kwargs)  # type: ignore[arg-type]
            failures.append(result is None)
            return result

        monkeypatch.setattr(ipm, "_polish", counted)
        problem = family(60, "disk")
        compiled, python = (_solve(problem, loop, escape_saddles=False) for loop in LOOPS)
        assert any(failures), "no polish failed: the test does not reach the path it is for"
        assert compiled.converged and python.converged
        assert compiled.iterations == python.iterations
        np.testing.assert_allclose(compiled.positions, python.positions, rtol=0, atol=1e-12 * 1.5)
    finally:
        monkeypatch.undo()
        ipm._driver_constants.cache_clear()
