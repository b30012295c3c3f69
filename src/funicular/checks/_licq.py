"""LICQ (the rank of the active rows, their dependent combinations) and MFCQ."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.linalg import lapack
from scipy.optimize import linprog

from funicular import _core
from funicular._constraints import (
    link_deltas,
    link_distances,
    link_gradients,
)
from funicular.checks import _tolerances
from funicular.checks._jacobian import _banded_lu, _Rows
from funicular.checks._report import LICQ, MFCQ, ActiveSet, Dependency
from funicular.checks._tolerances import CERTIFY, MAX_BAND, NULL_BLOCK, RANK_TOL, SHIFT, ZERO_WEIGHT, Matrix
from funicular.model import FloatArray, Formulation, IntArray, Problem


# ----------------------------------------------------------------- LICQ
def _independent(rows: _Rows) -> bool:
    """A cheap proof that no singular value of the rows is ``<= RANK_TOL``: a Cholesky
    factorization of ``A A^T - CERTIFY I`` exists, so ``sigma_min^2 > CERTIFY`` (up to its rounding
    error: ~1e-15 for a chain's banded rows, far below CERTIFY = (100 RANK_TOL)^2; a net's sparse
    factorization lowers the diagonal by a bound on its own). False means "not proven" (compute)."""
    if rows.m == 0:
        return True
    if rows.n <= _tolerances.DENSE_LIMIT:
        dense = rows.dense()
        try:
            np.linalg.cholesky(dense @ dense.T - CERTIFY * np.eye(rows.m))
        except np.linalg.LinAlgError:
            return False
        return True
    return proven_independent(rows.nodes, rows.vectors)


def proven_independent(nodes: IntArray, vectors: FloatArray) -> bool:
    """:func:`_independent` of rows of ``+vectors[r]`` (m, d) at free node ``nodes[r, 0]`` and
    ``-vectors[r]`` at ``nodes[r, 1]`` (-1: none), factored by the solver core: band by band in the
    order of their first nodes where that is banded (a chain's rows: O(m) time, the band's entries
    computed as it goes, no matrix in memory), by a sparse Cholesky factorization otherwise (a net's)."""
    nodes, vectors = np.ascontiguousarray(nodes, dtype=np.int64), np.ascontiguousarray(vectors, dtype=np.float64)
    return _core.gram_positive_definite(nodes, vectors, -CERTIFY, MAX_BAND)


def shifted_gram(matrix: Matrix, shift: float) -> Matrix:
    """``A A^T + shift I`` of sparse rows A."""
    return Matrix(matrix @ matrix.T + shift * sparse.identity(matrix.shape[0], format="csr"))


def _gram(rows: _Rows, shift: float) -> tuple[IntArray, IntArray, FloatArray]:
    """Row, column and value of every entry of ``A A^T + shift I`` (each position once)."""
    gram = shifted_gram(rows.sparse(), shift).tocoo()
    return gram.row.astype(np.intp), gram.col.astype(np.intp), np.asarray(gram.data, dtype=np.float64)


def _left_null_space(rows: _Rows) -> tuple[float, FloatArray]:
    """Smallest singular value of the rows and an orthonormal basis (m, r) of their dependencies."""
    m, n = rows.m, rows.n
    if m == 0:
        return math.inf, np.zeros((0, 0))
    if n == 0:
        return 0.0, np.eye(m)
    if n <= _tolerances.DENSE_LIMIT or m <= NULL_BLOCK + 1:
        return _dense_null_space(rows.dense())
    found = lanczos_null_space(rows.sparse(), _banded_lu(rows.anchors(), *_gram(rows, SHIFT)))
    assert found is not None  # (without a limit every dependency is sought)
    return found


def _dense_null_space(rows: FloatArray) -> tuple[float, FloatArray]:
    """Smallest singular value of dense rows (m, n) and an orthonormal basis (m, r) of their
    dependencies, by their SVD."""
    m, n = rows.shape
    u, s, _ = np.linalg.svd(rows, full_matrices=m > n)  # u is (m, m) either way
    s = np.concatenate([s, np.zeros(max(m - n, 0))])
    return float(s.min(initial=math.inf)), u[:, s <= RANK_TOL]


def lanczos_null_space(
    matrix: Matrix, solve: Callable[[FloatArray], FloatArray], most: int | None = None
) -> tuple[float, FloatArray] | None:
    """Smallest singular value of sparse rows A (m, n) and an orthonormal basis (m, r) of their
    dependencies, from the largest eigenvalues of ``(A A^T + SHIFT I)^-1`` (``solve``; shift-invert
    Lanczos), NULL_BLOCK at a time and twice as many while all found are dependent (a few rows:
    their SVD). None where there are more than ``most`` (not sought further)."""
    m = matrix.shape[0]
    if m <= NULL_BLOCK + 1:
        found = _dense_null_space(matrix.toarray())
        return None if most is not None and found[1].shape[1] > most else found
    inverse = sparse_linalg.LinearOperator((m, m), matvec=solve, dtype=np.float64)
    k = NULL_BLOCK
    while True:
        _, vectors = sparse_linalg.eigsh(inverse, k=k, which="LA")
        _, s, vt = np.linalg.svd(matrix.T @ vectors, full_matrices=False)  # refine: A^T W = U S V^T
        vectors = vectors @ vt.T
        dependent = s <= RANK_TOL
        if not dependent.all() or k >= m - 1:
            return float(s.min()), vectors[:, dependent]
        if most is not None and k > most:
            return None
        k = min(2 * k, m - 1) if most is None else min(2 * k, m - 1, most + 1)


def _null(rows: _Rows) -> FloatArray:
    """A basis (m, r) of the rows' dependencies, without computing any when they are provably none."""
    return np.zeros((rows.m, 0)) if _independent(rows) else _left_null_space(rows)[1]


def _independent_triangle(r: FloatArray) -> bool:
    """Whether the rows of A, with ``A^T = Q R``, are provably independent: ``sigma_min(R) >=
    1 / ||R^-1||_F`` exceeds ``sqrt(CERTIFY)``."""
    # dtrtri reads and writes the upper triangle; below it stay the Householder vectors of geqrf
    # (entries <= 1), which only make the norm, and so the proof, more cautious (by <= m / sqrt(2)
    # against a limit of 1 / (100 RANK_TOL) = 1e6).
    inverse, info = lapack.dtrtri(r)
    return bool(info == 0 and float(np.linalg.norm(inverse)) * math.sqrt(CERTIFY) < 1.0)


def _dependent_rows(null: FloatArray) -> IntArray:
    """Rows whose removal leaves independent rows: one pivot per null vector (pivoted QR)."""
    if null.shape[1] == 0:
        return np.zeros(0, dtype=np.intp)
    _, _, pivots = scipy.linalg.qr(null.T, mode="economic", pivoting=True)
    return np.sort(pivots[: null.shape[1]])


def _describe(problem: Problem, positions: FloatArray, active: ActiveSet, vector: FloatArray) -> Dependency:
    """A null vector in words: which forces, and how the supports' reactions change."""
    vector = vector / vector[int(np.argmax(np.abs(vector)))]
    names = active.names(problem)
    shares = {names[c]: float(vector[c]) for c in np.flatnonzero(np.abs(vector) > ZERO_WEIGHT)}
    # Extra tension w in link k pulls node k by -w u_k and node k+1 by +w u_k; a support balances it.
    # The unit vector along each link; 0 for a link of zero length (a detached massless end resting
    # on its neighbour), which carries no force and is never active.
    unit = link_gradients(Formulation.NORM, link_deltas(positions), link_distances(positions))
    is_support = problem.is_support
    reaction: dict[int, FloatArray] = {}
    for c, k in enumerate(active.links):
        for node, sign in ((int(k), 1.0), (int(k) + 1, -1.0)):
            if is_support[node] and abs(vector[c]) > ZERO_WEIGHT:
                reaction[node] = reaction.get(node, np.zeros(2)) + sign * vector[c] * unit[k]
    supports = {node: (float(f[0]), float(f[1])) for node, f in sorted(reaction.items())}
    if len(shares) <= 4:
        text = ", ".join(f"{name} ({share:+.3g})" for name, share in shares.items())
    else:
        first, *_, last = shares
        text = f"{len(shares)} forces from {first} to {last} (shares {min(shares.values()):+.3g} to +1)"
    if supports:
        changes = ", ".join(f"({f[0]:+.3g}, {f[1]:+.3g}) at node {node}" for node, f in supports.items())
        text += f" and the supports at nodes {', '.join(map(str, supports))} (reactions change by {changes})"
    text += " can carry any multiple of these forces in equilibrium with each other: the multipliers are not unique."
    return Dependency(shares, supports, text)


def _licq(problem: Problem, positions: FloatArray, active: ActiveSet, rows: _Rows) -> tuple[LICQ, FloatArray]:
    """LICQ of the active rows, and their dependencies as a basis (m, r) with one pivot row each."""
    sigma_min, null = _left_null_space(rows)
    pivots = _dependent_rows(null)
    if pivots.size:  # the basis that is 1 on its own pivot row and 0 on the others: one dependency each
        null = np.asarray(np.linalg.solve(null[pivots].T, null.T).T, dtype=np.float64)
    dependencies = tuple(_describe(problem, positions, active, null[:, j]) for j in range(null.shape[1]))
    m = rows.m
    licq = LICQ(null.shape[1] == 0, m - null.shape[1], m, sigma_min, dependencies)
    return licq, null


# ----------------------------------------------------------------- the multiplier set {t + W c >= 0}
@dataclass(frozen=True)
class _Directions:
    """The rows of the null basis W grouped by direction: ``t + W c >= 0`` iff ``U c >= lower``.

    Rows of W that are zero belong to determined forces; the others have ``W_k = |W_k| U_j``
    for their direction j (``group[k]``, -1 for determined). Merging parallel rows keeps the LPs
    small: a taut segment's dependency gives every link in it the same direction.
    """

    units: FloatArray  # (d, r)
    lower: FloatArray  # (d,)
    group: IntArray  # (m,)
    norm: FloatArray  # (m,)


def _directions(null: FloatArray, t: FloatArray) -> _Directions:
    norm = np.linalg.norm(null, axis=1)
    varying = np.flatnonzero(norm > ZERO_WEIGHT)
    unit = null[varying] / norm[varying, None]
    units, inverse = np.unique(np.round(unit, 9), axis=0, return_inverse=True)
    lower = np.full(units.shape[0], -np.inf)
    np.maximum.at(lower, inverse.ravel(), -t[varying] / norm[varying])
    group = np.full(null.shape[0], -1, dtype=np.intp)
    group[varying] = inverse.ravel()
    return _Directions(units, lower, group, norm)


def _mfcq(null: FloatArray) -> MFCQ:
    """Gordan: MFCQ fails iff some ``w = W c >= 0`` with ``sum(w) = 1`` (a vanishing nonnegative combination)."""
    if null.shape[1] == 0:
        return MFCQ(True, "implied by LICQ")
    units = _directions(null, np.zeros(null.shape[0])).units
    result = linprog(
        np.zeros(null.shape[1]),
        A_ub=-units,
        b_ub=np.zeros(units.shape[0]),
        A_eq=null.sum(axis=0)[None, :],
        b_eq=[1.0],
        bounds=(None, None),
    )
    if result.status == 0:
        return MFCQ(
            False,
            "a nonnegative combination of the active constraint gradients vanishes, so no direction "
            "decreases every active constraint",
        )
    return MFCQ(True, "the dependent combinations mix signs: some direction decreases every active constraint")
