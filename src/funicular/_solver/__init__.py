"""funicular's own interior-point solver (block-tridiagonal Newton systems, O(N) per iteration)."""

from funicular._solver.ipm import SolverOptions, solve

__all__ = ["SolverOptions", "solve"]
