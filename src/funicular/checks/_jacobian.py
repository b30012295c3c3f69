"""The active constraints' force-unit Jacobian rows and the Hessian of the Lagrangian over the free
coordinates, and a banded LU of matrices built from them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sparse
from scipy.linalg import lapack

from funicular._constraints import (
    link_directions,
    link_gradient_norms,
    link_hessian_blocks,
    norms,
)
from funicular._solver.banded import eigenvalue_floor
from funicular.checks._active import _Point
from funicular.checks._report import ActiveSet, Multipliers
from funicular.checks._tolerances import Matrix
from funicular.model import FloatArray, IntArray, Problem


# ----------------------------------------------------------------- Jacobian and Hessian
@dataclass(frozen=True)
class _Rows:
    """Active constraint rows over the free coordinates: row r holds ``vectors[r]`` at the two
    coordinates of free node ``nodes[r, 0]`` and ``-vectors[r]`` at those of free node
    ``nodes[r, 1]`` (a link's rows), nothing where that node is -1 (a support, or a contact row's
    second slot: a contact touches one node)."""

    nodes: IntArray  # (m, 2)
    vectors: FloatArray  # (m, 2)
    n: int  # free coordinates

    @property
    def m(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def values(self) -> FloatArray:
        """Each slot's vector (m, 2, 2): ``vectors``, then ``-vectors``."""
        return np.stack([self.vectors, -self.vectors], axis=1)

    def take(self, index: IntArray) -> _Rows:
        return _Rows(self.nodes[index], self.vectors[index], self.n)

    def anchors(self) -> IntArray:
        """The first free node of each row (-1 for a row without entries): the rows in this order
        couple only neighbouring nodes, so sorting by it makes the matrices banded."""
        return np.where(self.nodes[:, 0] >= 0, self.nodes[:, 0], self.nodes[:, 1])

    def entries(self) -> tuple[IntArray, IntArray, FloatArray]:
        """Row, column and value of every entry (each position once)."""
        r, s = np.nonzero(self.nodes >= 0)
        columns = 2 * self.nodes[r, s][:, None] + np.arange(2)
        return np.repeat(r, 2), columns.ravel(), self.values[r, s].ravel()

    def dense(self) -> FloatArray:
        matrix = np.zeros((self.m, self.n // 2, 2))  # [row, node, coordinate]
        r, s = np.nonzero(self.nodes >= 0)
        matrix[r, self.nodes[r, s]] = self.values[r, s]
        return matrix.reshape(self.m, self.n)

    def sparse(self) -> Matrix:
        r, c, v = self.entries()
        return sparse.csr_matrix((v, (r, c)), shape=(self.m, self.n))


def _jacobian(problem: Problem, point: _Point, active: ActiveSet) -> _Rows:
    """Force-unit rows of the active constraints over the free coordinates: each constraint's
    gradient over its norm (:func:`_row_scales`), so that a row's multiplier is a force."""
    links, contacts = active.links, active.contacts
    contact_columns = point.column[contacts[:, 1]]  # contacts are never at supports
    m = links.size + contact_columns.size
    vectors = np.empty((m, 2))  # (filled in place: a large chain's rows are tens of MB)
    delta, distances = point.delta, point.distances
    first, second = point.column[:-1], point.column[1:]  # each link's two nodes
    if links.size < distances.size:  # (with every link taut, the point's arrays as they are)
        delta, distances, first, second = delta[links], distances[links], first[links], second[links]
    link_directions(delta, distances, out=vectors[: links.size])  # (a link's gradient over its norm)
    touching = vectors[links.size :]
    touching[:] = point.gradient[contacts[:, 0], contact_columns]
    scale = norms(touching)
    np.divide(touching, scale[:, None], out=touching, where=scale[:, None] > 0)  # (a zero row stays zero)
    nodes = np.full((m, 2), -1, dtype=np.intp)  # a contact row's second node: none
    nodes[: links.size, 0] = first
    nodes[: links.size, 1] = second
    nodes[links.size :, 0] = contact_columns
    return _Rows(nodes, vectors, 2 * point.free.size)


def _row_scales(problem: Problem, point: _Point, active: ActiveSet) -> FloatArray:
    """Each active row's scale: the norm of its constraint's gradient, ``|q_k|`` for a link and
    ``|grad phi|`` for a contact. A row's force ``t`` is the multiplier ``t / scale`` of the formulation."""
    links, contacts = active.links, active.contacts
    distances = point.distances if links.size == point.distances.size else point.distances[links]
    gradients = point.gradient[contacts[:, 0], point.column[contacts[:, 1]]]
    return np.concatenate([link_gradient_norms(problem.formulation, distances), norms(gradients)])


@dataclass(frozen=True)
class _Hessian:
    """The Hessian of the Lagrangian over the free coordinates, block tridiagonal with 2x2 blocks:
    ``diagonal`` (f, 2, 2) for each free node, ``coupling`` (f-1, 2, 2) the block of free nodes c
    and c+1 (zero where no link joins them); ``contact`` (f, 2, 2) the contact terms' share of the
    diagonal."""

    diagonal: FloatArray
    coupling: FloatArray
    contact: FloatArray

    def bound(self) -> float:
        """A lower bound of the eigenvalues: the link terms are positive semidefinite for
        ``mu >= 0``, so the smallest eigenvalue of the contact terms, 2x2 blocks node by node (0 if
        there are none)."""
        return eigenvalue_floor(self.contact)

    def entries(self) -> tuple[IntArray, IntArray, FloatArray]:
        """Row, column and value of every entry of the band (each position once)."""
        f = self.diagonal.shape[0]
        d, e = np.arange(2)[:, None], np.arange(2)[None, :]
        node, link = 2 * np.arange(f)[:, None, None], 2 * np.arange(f - 1)[:, None, None]
        values = (self.diagonal, self.coupling, self.coupling)  # block (c, c+1) and its transpose

        def flat(parts: tuple[IntArray, ...]) -> IntArray:
            return np.concatenate([np.broadcast_to(a, v.shape).ravel() for a, v in zip(parts, values, strict=True)])

        rows = flat((node + d, link + d, link + 2 + e))
        cols = flat((node + e, link + 2 + e, link + d))
        return rows, cols, np.concatenate([v.ravel() for v in values])

    def times(self, vectors: FloatArray) -> FloatArray:
        """``H @ vectors`` for vectors (n, k), block by block (cheaper than building H dense)."""
        v = vectors.reshape(self.diagonal.shape[0], 2, vectors.shape[1])
        product: FloatArray = self.diagonal @ v
        product[:-1] += self.coupling @ v[1:]
        product[1:] += self.coupling.transpose(0, 2, 1) @ v[:-1]
        return product.reshape(vectors.shape)

    def dense(self) -> FloatArray:
        f = self.diagonal.shape[0]
        matrix = np.zeros((f, 2, f, 2))  # [node, coordinate, node, coordinate]
        node = np.arange(f)
        matrix[node, :, node, :] = self.diagonal
        matrix[node[:-1], :, node[1:], :] = self.coupling
        matrix[node[1:], :, node[:-1], :] = self.coupling.transpose(0, 2, 1)
        return matrix.reshape(2 * f, 2 * f)


def _hessian(problem: Problem, point: _Point, multipliers: Multipliers) -> _Hessian:
    """Hessian of the Lagrangian over the free coordinates."""
    blocks = link_hessian_blocks(problem.formulation, point.delta, point.distances, problem.link_lengths)
    blocks *= np.maximum(multipliers.link, 0.0)[:, None, None]  # (a new array in both formulations)
    per_node = np.zeros((problem.n_nodes, 2, 2))  # [[K, -K], [-K, K]] of each link, on its two nodes
    per_node[:-1] += blocks
    per_node[1:] += blocks
    free = point.free
    nu = np.maximum(multipliers.obstacle[:, free], 0.0)
    contact = np.einsum("jf,jfab->fab", nu, point.hessian)
    # Free nodes c and c + 1 are joined by link free[c] when they are neighbours on the chain.
    coupling = -blocks[free[:-1]]
    coupling[free[1:] != free[:-1] + 1] = 0.0
    return _Hessian(per_node[free] + contact, coupling, contact)


# ----------------------------------------------------------------- banded LU
def _band_positions(key: IntArray) -> IntArray:
    """Each unknown's place when sorted by ``key`` (stable): keys are nodes of the chain, and
    unknowns of the same or neighbouring nodes are coupled, so the sorted matrix is banded."""
    position = np.empty(key.size, dtype=np.intp)
    position[np.argsort(key, kind="stable")] = np.arange(key.size)
    return position


def _banded_lu(key: IntArray, rows: IntArray, cols: IntArray, values: FloatArray) -> Callable[[FloatArray], FloatArray]:
    """A solve with the square matrix of these entries (each position once), its unknowns in the
    order of ``key`` (:func:`_band_positions`), factored by LAPACK's banded LU (``gbtrf``, partial
    pivoting). Raises ``LinAlgError`` if the matrix is exactly singular."""
    position = _band_positions(key)
    i, j = position[rows], position[cols]
    k = int(np.max(np.abs(i - j), initial=0))
    height = 3 * k + 1  # gbtrf's storage: k rows of room for the pivoting's fill-in
    band = np.zeros((height, key.size), order="F")  # LAPACK's order: no copy
    band.ravel(order="F")[j * height + 2 * k + i - j] = values
    lu, pivots, info = lapack.dgbtrf(band, k, k, overwrite_ab=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"banded LU: zero pivot {info}")

    def solve(rhs: FloatArray) -> FloatArray:
        permuted = np.empty((key.size, 1))
        permuted[position, 0] = rhs
        x, _ = lapack.dgbtrs(lu, k, k, permuted, pivots, overwrite_b=True)
        return np.asarray(x[position, 0], dtype=np.float64)

    return solve
