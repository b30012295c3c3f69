"""funicular: equilibria of hanging chains, with the forces read off the Lagrange multipliers."""

from funicular.errors import FunicularError, InfeasibleError, ScenarioError, SolverError
from funicular.model import Formulation, Problem, Support
from funicular.solution import Solution, Status
from funicular.solver import SolverOptions, solve

__version__ = "0.2.0"

__all__ = [
    "Formulation",
    "FunicularError",
    "InfeasibleError",
    "Problem",
    "ScenarioError",
    "Solution",
    "SolverError",
    "SolverOptions",
    "Status",
    "Support",
    "__version__",
    "solve",
]
