"""The checker's tolerances and limits (see :mod:`funicular.checks` for what each decides)."""

from __future__ import annotations

import scipy.sparse as sparse

from funicular._core import CURVATURE_PENALTY

DEFAULT_TOL = 1e-6
PENALTY = CURVATURE_PENALTY  # rho of the cheap second-order proof, in units of the stiffest diagonal entry
RANK_TOL = 1e-8  # singular value of the force-unit Jacobian below which its rows count as dependent
DENSE_LIMIT = 100  # free coordinates up to which dense linear algebra is used
NULL_BLOCK = 4  # null vectors sought at a time by the sparse method
MAX_RANGE_LPS = 200  # multiplier ranges are computed for at most this many distinct null-vector directions
ZERO_WEIGHT = 1e-9  # a null vector's entry below this (relative to its largest) is zero
SHIFT = 1e-14  # keeps A A^T invertible for the shift-invert Lanczos
LANCZOS_VECTORS = 6  # Lanczos basis size of the curvature's shift-invert eigsh (ARPACK's default: 20)
CERTIFY = (100 * RANK_TOL) ** 2  # A A^T - CERTIFY I positive definite proves every singular value > RANK_TOL
MAX_BAND = 64  # rows apart (in the order of their anchors) beyond which that proof is sparse, not banded


Matrix = sparse.csr_matrix
