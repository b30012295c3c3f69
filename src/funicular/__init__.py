"""funicular: equilibria of hanging chains, with the forces read off the Lagrange multipliers.

The public API::

    problem = funicular.load_scenario("two-supports")      # or funicular.Problem.build(...)
    solution = funicular.solve(problem)                      # positions, tensions, reactions, ...
    report = funicular.check(problem, solution.positions)   # KKT, LICQ, statics, MFCQ, second order
    again = funicular.load_solution("result.json")          # what `funicular solve --json` wrote

Names are loaded on first use, so ``import funicular`` stays cheap (the checker alone loads SciPy).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from funicular.errors import (
    FunicularError,
    InfeasibleError,
    OutputError,
    ParameterError,
    ScenarioError,
    SolverError,
)

if TYPE_CHECKING:
    from funicular._solver import SolverOptions, solve
    from funicular.checks import check, load_solution
    from funicular.model import Formulation, Problem, Support
    from funicular.obstacles import (
        Box,
        CallableObstacle,
        Cuboid,
        Disk,
        Ellipse,
        Ellipsoid,
        Expression,
        Graph,
        HalfPlane,
        HalfSpace,
        Obstacle,
        Sphere,
        Surface,
    )
    from funicular.scenario import load_scenario
    from funicular.solution import Solution, Status

__version__ = "0.6.0"

# Each lazily loaded name and the module it comes from.
_LAZY = {
    "solve": "funicular._solver",
    "SolverOptions": "funicular._solver",
    "Problem": "funicular.model",
    "Support": "funicular.model",
    "Formulation": "funicular.model",
    "Solution": "funicular.solution",
    "Status": "funicular.solution",
    "load_scenario": "funicular.scenario",
    "check": "funicular.checks",
    "load_solution": "funicular.checks",
    **dict.fromkeys(
        (
            *("Obstacle", "Disk", "Ellipse", "Box", "HalfPlane", "Graph", "Expression", "CallableObstacle"),
            *("Sphere", "Ellipsoid", "HalfSpace", "Cuboid", "Surface"),  # (in space)
        ),
        "funicular.obstacles",
    ),
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'funicular' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value  # (looked up once)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "Box",
    "CallableObstacle",
    "Cuboid",
    "Disk",
    "Ellipse",
    "Ellipsoid",
    "Expression",
    "Formulation",
    "FunicularError",
    "Graph",
    "HalfPlane",
    "HalfSpace",
    "InfeasibleError",
    "Obstacle",
    "OutputError",
    "ParameterError",
    "Problem",
    "ScenarioError",
    "Solution",
    "SolverError",
    "SolverOptions",
    "Sphere",
    "Status",
    "Support",
    "Surface",
    "__version__",
    "check",
    "load_scenario",
    "load_solution",
    "solve",
]
