"""The package's exception hierarchy: every error a user can cause is a `FunicularError`."""

from __future__ import annotations


class FunicularError(Exception):
    """Base class of every error funicular raises on purpose.

    The message is one sentence that names the key, node, link or obstacle
    concerned, the offending value, and what would be valid.
    """


class ScenarioError(FunicularError):
    """The problem description is invalid: a missing, unknown or ill-typed key or an impossible value."""


class InfeasibleError(FunicularError):
    """No configuration satisfies the constraints (detected before or during the solve)."""


class SolverError(FunicularError):
    """The solver could not be run on this problem (not: it ran and did not converge)."""
