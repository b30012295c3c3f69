"""The boundary with the compiled solver core: its stub (``src/funicular/_core.pyi``) says what the
module holds, and every error the core raises reaches the user as one of the package's errors.

* mypy's stubtest compares every name, class, method, property and signature of ``funicular._core``
  with the stub.
* The core's errors carry what they are about in named attributes, checked against numbers worked
  out here from the problem (the supports' distance, the chain's length between them).
* Every core error class, and one the package has never seen, becomes a ``FunicularError``.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from funicular import Problem, _core, solve
from funicular._solver.core_problem import core_chain, package_error
from funicular.errors import FunicularError, InfeasibleError, SolverError


def test_the_stub_matches_the_compiled_module(tmp_path: Path) -> None:
    # (from a directory of its own: mypy leaves its cache where it runs)
    source = str(Path(__file__).resolve().parents[1] / "src")
    path = os.pathsep.join(filter(None, [os.environ.get("PYTHONPATH"), source]))
    result = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "funicular._core"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": path},
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def _too_far() -> Problem:
    """Supports (0, 0) and (3, 4), 5 apart, with 4 links of 1.2 (4.8 of chain) between them."""
    return Problem.build(nodes=5, supports=[(0, (0.0, 0.0)), (4, (3.0, 4.0))], link_length=1.2, mass=1.0)


def test_supports_too_far_apart_are_named_with_their_distance_and_the_chain_between() -> None:
    problem = _too_far()
    settings = _core.Settings(tol=1e-10, max_iterations=200, escape_saddles=True, exact_start=True)
    with pytest.raises(_core.SupportsTooFar) as raised:
        core_chain(problem).solve(settings=settings, start=None, judge=False)
    error = raised.value
    assert (error.a, error.b) == (0, 4)
    assert error.distance == pytest.approx(math.hypot(3.0, 4.0), rel=1e-15)
    assert error.length == pytest.approx(4 * 1.2, rel=1e-15)
    with pytest.raises(InfeasibleError, match=r"supports at nodes 0 \(0\.0, 0\.0\) and 4 \(3\.0, 4\.0\) are 5 apart"):
        solve(problem)


def test_every_core_error_becomes_one_of_the_packages() -> None:
    problem = _too_far()
    classes = [
        _core.CoreError,
        _core.SupportsTooFar,
        _core.TautNotVertical,
        _core.NotFactored,
        _core.ObstacleNotFinite,
        _core.InternalError,
    ]
    assert all(issubclass(error, _core.CoreError) for error in classes)
    fields = {"a": 0, "b": 4, "distance": 5.0, "length": 4.8, "obstacle": 0, "index": 1, "at_start": True}

    class Unheard(_core.CoreError):
        pass

    for cls in [*classes, Unheard]:
        error = cls("why")
        for name, value in fields.items():
            setattr(error, name, value)
        if cls is _core.ObstacleNotFinite:  # (a problem with an obstacle to name)
            continue
        assert isinstance(package_error(problem, error), FunicularError), cls
    internal = package_error(problem, _core.InternalError("index out of bounds"))
    assert isinstance(internal, SolverError) and "index out of bounds" in str(internal)
    assert isinstance(package_error(problem, Unheard("why")), SolverError)


def test_a_solves_answer_has_named_fields() -> None:
    problem = Problem.build(nodes=11, supports=[(0, (0.0, 0.0)), (10, (1.0, 0.0))], length=1.5, mass=1.0)
    settings = _core.Settings(tol=1e-10, max_iterations=200, escape_saddles=True, exact_start=True)
    answer = core_chain(problem).solve(settings=settings, start=None, judge=True)
    assert answer.status == "optimal" and answer.curvature is not None
    assert answer.positions.shape == (22,) and answer.link_multipliers.shape == (10,)
    # the end links pull the supports down by the free nodes' weight (their tensions along them)
    positions = answer.positions.reshape(11, 2)
    first = (positions[1] - positions[0]) / np.linalg.norm(positions[1] - positions[0])
    last = (positions[9] - positions[10]) / np.linalg.norm(positions[9] - positions[10])
    pull = answer.link_multipliers[0] * first[1] + answer.link_multipliers[9] * last[1]
    assert -pull == pytest.approx(problem.gravity * problem.masses[1:10].sum(), rel=1e-8)
