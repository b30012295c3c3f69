"""The front end of funicular's own solver, whose iteration runs in the compiled core.

``front_end``: the settings, the checks a solve makes before any work, ``solve`` and the
``Solution`` built from the core's answer; ``core_problem``: a ``Problem`` as the core's chain or
net, and the core's errors as the package's; ``initial`` and ``spans``: the presolve, the starts
and the exact catenary of a span.
"""

from funicular._solver.front_end import SolverOptions, solve

__all__ = ["SolverOptions", "solve"]
