"""Studies built on the solver: exact catenaries, refinement in N, parameter sweeps.

This module holds the small helpers they share: aligned text tables, number formatting and the
log-log slope fit behind every "observed order".
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

TINY_ERROR = 1e-13  # relative errors below this are rounding, not discretisation: left out of order fits


def format_number(value: object, digits: int = 6) -> str:
    """A table cell: floats in ``digits`` significant digits, None as '-', anything else as str()."""
    if value is None:
        return "-"
    if isinstance(value, (float, np.floating)):
        return f"{float(value) + 0.0:.{digits}g}"  # + 0.0 turns -0.0 into 0.0
    return str(value)


def format_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A plain-text table: right-aligned columns separated by two spaces, a rule under the header."""
    cells = [[format_number(cell) for cell in row] for row in rows]
    widths = [max([len(h), *(len(row[i]) for row in cells)]) for i, h in enumerate(headers)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines.extend("  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in cells)
    return "\n".join(lines)


def loglog_slope(x: Sequence[float], y: Sequence[float | None], points: int, floor: float = 0.0) -> float | None:
    """Least-squares slope of ``log y`` against ``log x`` over the last ``points`` usable pairs.

    Pairs with y missing, non-finite or not above ``floor`` are skipped (pass ``TINY_ERROR`` for
    errors, which reach rounding level). None if fewer than two remain.
    """
    pairs = [(xi, yi) for xi, yi in zip(x, y, strict=True) if yi is not None and math.isfinite(yi) and yi > floor]
    pairs = pairs[-points:]
    if len(pairs) < 2:
        return None
    logs = np.log(np.array(pairs, dtype=np.float64))
    return float(np.polyfit(logs[:, 0], logs[:, 1], 1)[0])
