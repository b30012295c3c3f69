"""The package's exception hierarchy: every error a user can cause is a `FunicularError`."""

from __future__ import annotations

import reprlib
from typing import Self

# Short reprs keep every message on one line even for a long list, string or deeply nested table.
_repr = reprlib.Repr()
_repr.maxstring = 40
_repr.maxother = 40
MAX_SHOWN = 100  # characters; reprlib limits each level, not the nested whole


def shown(value: object) -> str:
    """``value`` as it is quoted in an error message: a short repr, at most MAX_SHOWN characters."""
    text = _repr.repr(value)
    return text if len(text) <= MAX_SHOWN else text[: MAX_SHOWN - 3] + "..."


class FunicularError(Exception):
    """Base class of every error funicular raises on purpose.

    The message is one sentence that names the key, node, link or obstacle
    concerned, the offending value, and what would be valid. ``key`` is the name of the argument
    the message starts with (an API argument such as ``n_nodes``), if any: the scenario reader
    and the command line rename it into a file key or a flag with :meth:`renamed`.
    """

    def __init__(self, message: str, *, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key

    def renamed(self, key: str) -> Self:
        """The same error naming ``key`` where it named its own key (itself if it names none)."""
        text = str(self)
        if self.key is None or not text.startswith(self.key):
            return self
        return type(self)(key + text[len(self.key) :], key=key)


class ScenarioError(FunicularError):
    """The problem description is invalid: a missing, unknown or ill-typed key or an impossible value."""


class InfeasibleError(FunicularError):
    """No configuration satisfies the constraints (detected before or during the solve)."""


class SolverError(FunicularError):
    """The solver could not be run on this problem (not: it ran and did not converge)."""


class ParameterError(FunicularError):
    """A solver setting is out of range (the problem itself may be fine)."""


class OutputError(FunicularError):
    """An output file cannot be written (a directory, a missing directory, no permission)."""
