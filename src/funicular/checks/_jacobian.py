"""The active constraints' force-unit Jacobian rows and the Hessian of the Lagrangian over the free
coordinates, by nodes (any graph of links, in the plane or in space), and the factorization of
matrices built from them: banded where their unknowns, ordered by node, couple only near
neighbours (a chain's), sparse otherwise (a net's)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from funicular._constraints import (
    link_directions,
    link_gradient_norms,
    link_hessian_blocks,
    norms,
)
from funicular._core import blocks_positive_definite
from funicular.checks._active import _Point
from funicular.checks._banded import eigenvalue_floor
from funicular.checks._report import ActiveSet, Multipliers
from funicular.checks._tolerances import MAX_BAND
from funicular.model import FloatArray, IntArray, Problem

if TYPE_CHECKING:
    from funicular.checks._tolerances import Matrix

# SciPy's sparse matrices and LAPACK are imported where a matrix is built or factored: the proof of
# unique forces (the rows alone, factored by the solver core) then loads none of SciPy.

Solve = Callable[[FloatArray], FloatArray]


# ----------------------------------------------------------------- Jacobian
@dataclass(frozen=True)
class _Rows:
    """Active constraint rows over the free coordinates: row r holds ``vectors[r]`` at the d
    coordinates of free node ``nodes[r, 0]`` and ``-vectors[r]`` at those of free node
    ``nodes[r, 1]`` (a link's rows), nothing where that node is -1 (a support, or a contact row's
    second slot: a contact touches one node)."""

    nodes: IntArray  # (m, 2)
    vectors: FloatArray  # (m, d)
    n: int  # free coordinates

    @property
    def m(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def d(self) -> int:
        return int(self.vectors.shape[1])

    @property
    def values(self) -> FloatArray:
        """Each slot's vector (m, 2, d): ``vectors``, then ``-vectors``."""
        return np.stack([self.vectors, -self.vectors], axis=1)

    def take(self, index: IntArray) -> _Rows:
        return _Rows(self.nodes[index], self.vectors[index], self.n)

    def anchors(self) -> IntArray:
        """The first free node of each row (-1 for a row without entries): a chain's rows in this
        order couple only neighbouring nodes, so sorting by it makes its matrices banded."""
        return np.where(self.nodes[:, 0] >= 0, self.nodes[:, 0], self.nodes[:, 1])

    def entries(self) -> tuple[IntArray, IntArray, FloatArray]:
        """Row, column and value of every entry (each position once)."""
        d = self.d
        r, s = np.nonzero(self.nodes >= 0)
        columns = d * self.nodes[r, s][:, None] + np.arange(d)
        return np.repeat(r, d), columns.ravel(), self.values[r, s].ravel()

    def dense(self) -> FloatArray:
        d = self.d
        matrix = np.zeros((self.m, self.n // d, d))  # [row, node, coordinate]
        r, s = np.nonzero(self.nodes >= 0)
        matrix[r, self.nodes[r, s]] = self.values[r, s]
        return matrix.reshape(self.m, self.n)

    def sparse(self) -> Matrix:
        import scipy.sparse as sparse

        r, c, v = self.entries()
        return sparse.csr_matrix((v, (r, c)), shape=(self.m, self.n))


def _jacobian(problem: Problem, point: _Point, active: ActiveSet) -> _Rows:
    """Force-unit rows of the active constraints over the free coordinates: each constraint's
    gradient over its norm (:func:`_row_scales`), so that a row's multiplier is a force."""
    links, contacts = active.links, active.contacts
    contact_columns = point.column[contacts[:, 1]]  # contacts are never at supports
    d = problem.dimension
    m = links.size + contact_columns.size
    vectors = np.empty((m, d))  # (filled in place: a large chain's rows are tens of MB)
    delta, distances, ends = point.delta, point.distances, problem.link_nodes
    if links.size < distances.size:  # (with every link taut, the point's arrays as they are)
        delta, distances, ends = delta[links], distances[links], ends[links]
    link_directions(delta, distances, out=vectors[: links.size])  # (a link's gradient over its norm)
    touching = vectors[links.size :]
    touching[:] = point.gradient[contacts[:, 0], contact_columns]
    scale = norms(touching)
    np.divide(touching, scale[:, None], out=touching, where=scale[:, None] > 0)  # (a zero row stays zero)
    nodes = np.full((m, 2), -1, dtype=np.intp)  # a contact row's second node: none
    nodes[: links.size] = point.column[ends]
    nodes[links.size :, 0] = contact_columns
    return _Rows(nodes, vectors, d * point.free.size)


def _row_scales(problem: Problem, point: _Point, active: ActiveSet) -> FloatArray:
    """Each active row's scale: the norm of its constraint's gradient, ``|q_k|`` for a link and
    ``|grad phi|`` for a contact. A row's force ``t`` is the multiplier ``t / scale`` of the formulation."""
    links, contacts = active.links, active.contacts
    distances = point.distances if links.size == point.distances.size else point.distances[links]
    gradients = point.gradient[contacts[:, 0], point.column[contacts[:, 1]]]
    return np.concatenate([link_gradient_norms(problem.formulation, distances), norms(gradients)])


# ----------------------------------------------------------------- Hessian
@dataclass(frozen=True)
class _Hessian:
    """The Hessian of the Lagrangian over the free coordinates by d x d blocks: ``node`` (f, d, d)
    on the diagonal, ``pair`` (p, d, d) the block of free nodes ``pairs`` (p, 2) (and its transpose
    at the mirror; blocks of the same pair add up), and ``contact`` (f, d, d) the contact terms'
    share of the diagonal. A chain's pairs are neighbours: the matrix is block tridiagonal."""

    node: FloatArray
    pairs: IntArray
    pair: FloatArray
    contact: FloatArray

    @property
    def n(self) -> int:
        return int(self.node.shape[0] * self.node.shape[1])

    def bound(self) -> float:
        """A lower bound of the eigenvalues: the link terms are positive semidefinite for
        ``mu >= 0``, so the smallest eigenvalue of the contact terms, d x d blocks node by node
        (0 if there are none)."""
        if self.contact.shape[1] == 2:
            return eigenvalue_floor(self.contact)
        touched = self.contact[np.any(self.contact != 0.0, axis=(1, 2))]
        return min(0.0, float(np.linalg.eigvalsh(touched).min(initial=0.0))) if touched.size else 0.0

    def entries(self) -> tuple[IntArray, IntArray, FloatArray]:
        """Row, column and value of every entry (a position may repeat: its values add up)."""
        f, d = self.node.shape[:2]
        i, k = np.arange(d)[:, None], np.arange(d)[None, :]
        nodes = d * np.arange(f)[:, None, None]
        a, b = d * self.pairs[:, 0, None, None], d * self.pairs[:, 1, None, None]
        shape = (d, d)
        rows = [nodes + i, a + i, b + k]  # the pair's block at (a, b), its transpose at (b, a)
        cols = [nodes + k, b + k, a + i]
        values = (self.node, self.pair, self.pair)

        def flat(parts: list[IntArray]) -> IntArray:
            return np.concatenate(
                [np.broadcast_to(a, v.shape[:1] + shape).ravel() for a, v in zip(parts, values, strict=True)]
            )

        return flat(rows), flat(cols), np.concatenate([v.ravel() for v in values])

    def times(self, vectors: FloatArray) -> FloatArray:
        """``H @ vectors`` for vectors (n, k), block by block (cheaper than building H dense)."""
        f, d = self.node.shape[:2]
        v = vectors.reshape(f, d, vectors.shape[1])
        product: FloatArray = self.node @ v
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        np.add.at(product, a, self.pair @ v[b])
        np.add.at(product, b, self.pair.transpose(0, 2, 1) @ v[a])
        return product.reshape(vectors.shape)

    def sparse(self) -> Matrix:
        import scipy.sparse as sparse

        r, c, v = self.entries()
        return sparse.csr_matrix(sparse.coo_matrix((v, (r, c)), shape=(self.n, self.n)))  # (repeats add up)

    def dense(self) -> FloatArray:
        dense: FloatArray = self.sparse().toarray()
        return dense

    def penalized(self, rows: _Rows, weights: FloatArray, shift: float) -> _Hessian:
        """``H - shift I + A^T diag(weights) A``: a row is a contact's unit normal n at one free node,
        or a link's +u and -u at its two nodes (either may be a support); it adds ``w n n^T`` or
        ``w u u^T`` to each of its free nodes, and a link between free nodes a and b adds
        ``-w u u^T`` to their pair, so the matrix has H's blocks."""
        vectors = rows.vectors
        outer = weights[:, None, None] * vectors[:, :, None] * vectors[:, None, :]
        d = vectors.shape[1]
        node = self.node - shift * np.eye(d)
        for end in (0, 1):
            touched = rows.nodes[:, end] >= 0
            node += _blocks_at(rows.nodes[touched, end], outer[touched], node.shape[0])
        both = (rows.nodes >= 0).all(axis=1)
        pairs = np.vstack([self.pairs, rows.nodes[both]])
        return _Hessian(node, pairs, np.concatenate([self.pair, -outer[both]]), self.contact)

    def positive_definite(self) -> bool:
        """Whether the matrix is positive definite: one sparse Cholesky factorization in the solver
        core (band by band for a chain's)."""
        return blocks_positive_definite(
            np.ascontiguousarray(self.node),
            np.ascontiguousarray(self.pairs, dtype=np.int64),
            np.ascontiguousarray(self.pair),
            0.0,
        )


def _blocks_at(index: IntArray, blocks: FloatArray, count: int) -> FloatArray:
    """The sum of the d x d ``blocks`` at each of ``count`` places ``index`` names (a bincount per
    entry: several times faster than ``np.add.at``)."""
    d = blocks.shape[1]
    flat = blocks.reshape(-1, d * d)
    summed = [np.bincount(index, flat[:, e], minlength=count) for e in range(d * d)]
    return np.asarray(np.stack(summed, axis=1).reshape(count, d, d), dtype=np.float64)


def _hessian(problem: Problem, point: _Point, multipliers: Multipliers) -> _Hessian:
    """Hessian of the Lagrangian over the free coordinates (the energy is linear: only the link and
    contact terms curve)."""
    blocks = link_hessian_blocks(problem.formulation, point.delta, point.distances, problem.link_lengths)
    blocks *= np.maximum(multipliers.link, 0.0)[:, None, None]  # (a new array in both formulations)
    free = point.free
    ends = point.column[problem.link_nodes]  # each link's free nodes, -1 at a support
    node = np.zeros((free.size, problem.dimension, problem.dimension))
    for end in (0, 1):  # [[K, -K], [-K, K]] of each link on its two nodes
        kept = ends[:, end] >= 0
        node += _blocks_at(ends[kept, end], blocks[kept], free.size)
    nu = np.maximum(multipliers.obstacle[:, free], 0.0)
    contact = np.einsum("jf,jfab->fab", nu, point.hessian)
    both = (ends >= 0).all(axis=1)
    return _Hessian(node + contact, ends[both], -blocks[both], contact)


# ----------------------------------------------------------------- factorization
def _band_positions(key: IntArray) -> IntArray:
    """Each unknown's place when sorted by ``key`` (stable): keys are nodes, and a chain's unknowns
    of the same or neighbouring nodes are coupled, so its sorted matrix is banded."""
    position = np.empty(key.size, dtype=np.intp)
    position[np.argsort(key, kind="stable")] = np.arange(key.size)
    return position


def _factor(key: IntArray, rows: IntArray, cols: IntArray, values: FloatArray) -> Solve:
    """A solve with the square matrix of these entries (repeated positions add up), its unknowns
    ordered by ``key`` (:func:`_band_positions`). Where that order leaves every entry within
    MAX_BAND of the diagonal (a chain's matrices), LAPACK's banded LU (``gbtrf``, partial
    pivoting: O(n) time and memory); otherwise SuperLU's sparse LU. Raises ``LinAlgError`` if the
    matrix is exactly singular."""
    import scipy.sparse as sparse
    import scipy.sparse.linalg as sparse_linalg
    from scipy.linalg import lapack

    size = key.size
    position = _band_positions(key)
    i, j = position[rows], position[cols]
    k = int(np.max(np.abs(i - j), initial=0))
    if k > MAX_BAND:
        matrix = sparse.csc_matrix((values, (rows, cols)), shape=(size, size))
        try:
            factor = sparse_linalg.splu(matrix)
        except RuntimeError as error:  # "Factor is exactly singular"
            raise np.linalg.LinAlgError(f"sparse LU: {error}") from None
        return lambda rhs: np.asarray(factor.solve(rhs), dtype=np.float64)
    height = 3 * k + 1  # gbtrf's storage: k rows of room for the pivoting's fill-in
    # LAPACK's order (column by column: no copy); a bincount adds up repeated positions
    band = np.bincount(j * height + 2 * k + i - j, values, minlength=height * size).reshape(size, height).T
    lu, pivots, info = lapack.dgbtrf(band, k, k, overwrite_ab=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"banded LU: zero pivot {info}")

    def solve(rhs: FloatArray) -> FloatArray:
        permuted = np.empty((size, 1))
        permuted[position, 0] = rhs
        x, _ = lapack.dgbtrs(lu, k, k, permuted, pivots, overwrite_b=True)
        return np.asarray(x[position, 0], dtype=np.float64)

    return solve


# ----------------------------------------------------------------- elastic links
def elastic_rows(problem: Problem, active: ActiveSet) -> NDArray[np.bool_]:
    """Which active rows are elastic links (m,): rows of taut links first, then contacts."""
    mask = np.zeros(active.links.size + active.contacts.shape[0], dtype=bool)
    if problem.axial_stiffness is not None:
        mask[: active.links.size] = problem.elastic[active.links]
    return mask


def elastic_tensions(problem: Problem, point: _Point, active: ActiveSet) -> FloatArray:
    """The elastic rows' forces as their stretch decides them, ``EA (d - L0) / L0`` (0 where slack)."""
    links = active.links[elastic_rows(problem, active)[: active.links.size]]
    if links.size == 0:
        return np.zeros(0)
    assert problem.axial_stiffness is not None
    stretch = np.maximum(point.distances[links] - problem.link_lengths[links], 0.0)
    tension: FloatArray = problem.axial_stiffness[links] / problem.link_lengths[links] * stretch
    return tension


def as_stiffness(problem: Problem, active: ActiveSet, hessian: _Hessian, rows: _Rows) -> tuple[_Hessian, IntArray]:
    """A taut elastic link is no constraint of the second-order test: its stretch eliminated, it
    adds its stiffness ``EA / L0`` along itself, ``k u u^T`` over its two nodes, to the Hessian of
    the Lagrangian. The Hessian with those terms, and the rows that stay constraints."""
    soft = elastic_rows(problem, active)
    if not soft.any():
        return hessian, np.arange(rows.m)
    assert problem.axial_stiffness is not None
    links = active.links[soft[: active.links.size]]
    stiffness = problem.axial_stiffness[links] / problem.link_lengths[links]
    return hessian.penalized(rows.take(np.flatnonzero(soft)), stiffness, 0.0), np.flatnonzero(~soft)
