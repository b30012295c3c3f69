"""The saddle escape's second-order test on the solver core's own Newton matrix: its verdicts and
directions against the checker's (``checks.second_order``), which evaluates the point on its own,
in physical units. (Its eigenvalue search is tested against a dense eigensolver in the core's own
tests, ``rust/core/tests``.)"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from bench.run import family

from funicular import Problem, Solution, SolverOptions, checks
from funicular._solver import front_end
from funicular._solver.front_end import Curvature
from funicular.scenario import builtin_scenarios, load_scenario

MINIMUM = "strict local minimum"


# ----------------------------------------------------------------- against the checker
@functools.cache
def _judged(name: str, nodes: int | None) -> tuple[Problem, Solution, Curvature]:
    problem = family(nodes or 0, "disk") if name == "family" else load_scenario(name)
    solution, curvature = front_end._solve(problem, SolverOptions(escape_saddles=False), judge=True)
    assert curvature is not None
    return problem, solution, curvature


CASES = [("family", n) for n in (20, 50, 51, 200)] + [
    (name, None)
    for name in sorted(builtin_scenarios())
    if load_scenario(name).obstacles
    and load_scenario(name).contact == "nodes"
    # (the checker compared with is the planar chains')
    and load_scenario(name).is_planar_chain
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
