"""Array types, the size limit shared by the problem and its obstacles, and the reading of a list
of numbers at once."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# Lengths, coordinates and forces stay between 1 / MAX_SIZE and MAX_SIZE: their squares and
# products must be finite, nonzero numbers (phi of a disk, the squared form, energy scales).
MAX_SIZE = 1e150


def finite_numbers(items: Sequence[object] | np.ndarray) -> FloatArray | None:
    """``items`` as an array at once (one C loop: 10^6 numbers cost ~50x less than entry by entry)
    where every one is an int or a float (exact types: a bool is not a number here), or a 1-D array
    of integers or floats, and finite; else None, and the caller names the bad entry."""
    if isinstance(items, np.ndarray):
        if items.ndim != 1 or items.dtype.kind not in "iuf":
            return None
        array = items.astype(np.float64)
    else:
        if not set(map(type, items)) <= {int, float}:
            return None
        try:
            array = np.array(items, dtype=np.float64)
        except OverflowError:  # an integer beyond the floats
            return None
    return array if np.isfinite(array).all() else None
