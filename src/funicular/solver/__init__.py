"""funicular's own interior-point solver (block-tridiagonal Newton systems, O(N) per iteration)."""

from funicular.solver.ipm import SolverOptions, solve

__all__ = ["SolverOptions", "solve"]
