"""Array types and the size limit shared by the problem and its obstacles."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# Lengths, coordinates and forces stay between 1 / MAX_SIZE and MAX_SIZE: their squares and
# products must be finite, nonzero numbers (phi of a disk, the squared form, energy scales).
MAX_SIZE = 1e150
