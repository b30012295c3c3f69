"""The checker's tolerances and limits (see :mod:`funicular.checks` for what each decides)."""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeAlias

from funicular._core import CURVATURE_PENALTY

if TYPE_CHECKING:  # (a type only: the proof of unique forces on the solve's path imports no SciPy)
    from scipy.sparse import csr_matrix

    Matrix: TypeAlias = csr_matrix

DEFAULT_TOL = 1e-6
PENALTY = CURVATURE_PENALTY  # rho of the cheap second-order proof, in units of the stiffest diagonal entry
RANK_TOL = 1e-8  # singular value of the force-unit Jacobian below which its rows count as dependent
DENSE_LIMIT = 100  # free coordinates up to which dense linear algebra is used
DENSE_ENTRIES = 4_000_000  # entries of the active rows up to which their SVD is the fallback of the sparse search
NULL_BLOCK = 4  # null vectors sought at a time by the sparse method
SELF_STRESS_SOUGHT = 64  # dependencies (self-stress states) sought at most by the sparse method
MAX_RANGE_LPS = 200  # multiplier ranges are computed for at most this many distinct null-vector directions
LP_SECONDS = 10.0  # the force ranges' linear programs (in all), and MFCQ's, take at most this long
RANGES_UP_TO = 300  # active constraints up to which the statics list every force's range
ZERO_WEIGHT = 1e-9  # a null vector's entry below this (relative to its largest) is zero
# A range's bound this small, relative to the largest force or the weight, is 0 to rounding (the
# programs' answers are sums and differences of forces: -2.2e-16 for a force that can vanish).
ZERO_FORCE_RTOL = 1e-12
SELF_STRESS_SHOWN = 10  # self-stress states the statics list at most
SHIFT = 1e-14  # keeps A A^T invertible for the shift-invert Lanczos
LANCZOS_VECTORS = 6  # Lanczos basis size of the curvature's shift-invert eigsh (ARPACK's default: 20)
CERTIFY = (100 * RANK_TOL) ** 2  # A A^T - CERTIFY I positive definite proves every singular value > RANK_TOL
# Unknowns apart (in the order of their nodes) up to which a matrix is factored as banded (a chain's
# rows and Hessian: a few per node), beyond which as sparse (a net's); also the rows apart beyond
# which the proof of independence is sparse.
MAX_BAND = 64
