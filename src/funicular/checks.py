"""Diagnostics of any point: active set, multipliers, KKT residuals, LICQ, MFCQ and second order.

:func:`check` takes a problem, positions and (optionally) multipliers, from funicular's solver,
another solver or a file, and reports what holds there. Methods, in the problem's words:

* **Tolerance.** ``tol`` is relative; lengths compare with ``tol * l`` (``l`` the longest link),
  forces with ``tol * W`` (``W`` the total weight). A link is *taut* when ``d_k >= l_k - tol l``; a
  free node *touches* an obstacle when ``phi / |grad phi| >= -tol l``. A point that violates a
  constraint by more than ``tol l`` is *infeasible*: the report names the worst violation and
  stops there (no LICQ or second-order check of a point that is not in the feasible set).
  Contacts are node contacts (``contact = "nodes"``); supports carry no contact constraint (see
  :mod:`funicular.forces`). ``contact = "links"`` with obstacles is not checked yet: :func:`check`
  says so (``ScenarioError``), :func:`licq_of` returns None and :func:`second_order` "undecided".
* **Jacobian.** Supports are eliminated: the support rows are unit rows, always independent,
  and only add their own columns, so LICQ of the full problem is equivalent to full row rank of
  the active link and contact rows restricted to the free coordinates. Each row is scaled so
  that its multiplier is a force: a link row holds the unit vectors ``+u_k`` at node k and
  ``-u_k`` at node k+1 (``u_k = (p_k - p_{k+1}) / d_k``), its multiplier is the tension ``T_k``; a
  contact row holds the unit normal ``grad phi / |grad phi|``, its multiplier is the contact
  force ``nu |grad phi|``. These rows are dimensionless and the same in both formulations.
* **LICQ.** The rows are dependent when a singular value of this matrix is ``<= RANK_TOL``. A
  chain of N taut links has ``sigma_min ~ 1 / N`` even where LICQ holds, so a fixed ``1e-8``
  separates "independent" from "dependent up to rounding" for N up to ~1e7. Small problems use a
  dense SVD; large ones the smallest eigenvalues of ``A A^T`` by shift-invert Lanczos (``eigsh``
  on a banded LU: sorted by their first node, the rows couple only neighbours), refined by an SVD
  of ``A^T W`` on the vectors found, so ``sigma_min`` is not limited to the square root of the
  rounding error. The left null vectors found are the dependent combinations: self-balanced sets
  of link and contact forces. Where only the verdict of independence is needed (the second-order
  check of a solver's result), a cheaper proof comes first: a Cholesky factorization of
  ``A A^T - (100 RANK_TOL)^2 I`` (banded for large problems), or ``1 / ||R^-1||_F`` of the QR
  ``A^T = Q R`` the second-order check needs anyway, shows every singular value above
  ``100 RANK_TOL``; only if that fails are the singular values computed.
* **Multipliers.** If none are given they are recovered from the positions: the least-squares
  solution of stationarity ``A^T t = -grad E`` over the active set (dense ``lstsq``, or sparse
  normal equations with one refinement step), moved along the null vectors to the smallest total
  force that keeps every force ``>= 0`` (a ``linprog``); if no exact nonnegative solution exists,
  a nonnegative least-squares fit (``nnls``, or ``lsq_linear`` for large problems).
* **MFCQ.** With supports eliminated every active constraint is an inequality, and by Gordan's
  theorem MFCQ fails iff a nonzero nonnegative combination of the active rows vanishes, i.e. iff
  the left null space holds a vector ``w >= 0``: a ``linprog`` in the null-space coordinates.
* **Multiplier ranges.** The multiplier set is ``{t0 + W c >= 0}`` (``t0`` the multipliers used,
  ``W`` the null vectors). Rows of W with the same direction are merged (a taut segment's links
  all share one), and each force's range comes from two ``linprog`` calls per direction. An
  unbounded range has ``max = inf`` (``null`` in JSON).
* **Second order.** ``H`` is the Hessian of the Lagrangian over the free coordinates. Strictly
  active constraints (force ``> tol W``) are equalities of the critical cone; weakly active
  ones make it a cone. If ``H`` is positive definite on the null space of the strictly active
  rows (a superset of the cone) the point is a strict local minimum (SOSC; valid for the
  multiplier used even when LICQ fails). If it has negative curvature on the null space of all
  active rows (a subset of the cone) and LICQ holds, the point is not a minimum (the necessary
  condition fails). Anything else is "undecided". The smallest eigenvalue of ``Z^T H Z`` comes
  from a dense null-space basis for small problems (one Householder QR of the rows, strictly
  active first, serves both null spaces); for large ones from shift-invert Lanczos on the
  bordered matrix ``[[H - s I, A^T], [A, 0]]`` (a banded LU, each row next to its first node;
  dependent rows dropped), whose inverse restricted to the positions is
  ``Z (Z^T H Z - s I)^{-1} Z^T``; the shift ``s`` lies below the spectrum because the link
  terms of ``H`` are positive semidefinite and the contact terms are 2x2 blocks whose
  eigenvalues bound the rest. An eigenvalue counts as zero below
  ``tol W / (N L)``: a curvature that changes the energy by less than ``tol W L`` when every
  node moves by the chain length ``L``.
* **A cheap proof of a strict minimum.** If ``H + rho A^T A - s I`` (A the strictly active rows,
  s the zero threshold plus rounding) is positive definite, H exceeds s on the null space of A:
  the sufficient condition without an eigenvalue. Links and contacts touch one or two
  neighbouring nodes, so the matrix is block tridiagonal like H and one O(N) Cholesky
  factorization decides; a failure only means "not proven". (The solver's saddle escape runs the
  same test, and looks for its direction, on its own Newton matrix: the core's ``curvature`` module.)
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.linalg import lapack
from scipy.optimize import linprog, lsq_linear, nnls

from funicular._core import CURVATURE_PENALTY, penalty_and_shift, zero_curvature
from funicular.constraints import (
    link_deltas,
    link_distances,
    link_gradients,
    link_hessian_blocks,
    multipliers_from_tension,
    tension_from_multipliers,
)
from funicular.diagnostics import KKTResiduals, kkt_residuals, scaled
from funicular.errors import ScenarioError, shown
from funicular.model import FloatArray, Formulation, IntArray, Problem
from funicular.solution import Solution
from funicular.solver.banded import BlockTridiagonal, LinearSolver, banded_cholesky, eigenvalue_floor

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


Matrix = sparse.csr_matrix


@dataclass(frozen=True)
class Multipliers:
    """Multipliers in the problem's formulation: ``link`` (N-1,) and ``obstacle`` (n_obstacles, N)."""

    link: FloatArray
    obstacle: FloatArray


@dataclass(frozen=True)
class Violation:
    """The worst constraint violation of an infeasible point (a length)."""

    constraint: str
    amount: float
    text: str


@dataclass(frozen=True)
class ActiveSet:
    """Constraints that hold with equality, to within ``tolerance`` (a length)."""

    tolerance: float
    links: IntArray  # taut links
    contacts: IntArray  # (k, 2): obstacle index, node
    supports: IntArray  # support nodes (always active)

    def names(self, problem: Problem) -> list[str]:
        links = [f"link {k}" for k in self.links]
        return links + [f"contact of node {i} with {problem.obstacles[j].name!r}" for j, i in self.contacts]


@dataclass(frozen=True)
class Dependency:
    """A left null vector of the active Jacobian: forces in equilibrium with each other.

    ``forces`` maps constraint names to their share (largest 1); ``support_reactions`` maps
    support nodes to the change of their reaction per unit of the combination (the support
    multipliers change by minus that).
    """

    forces: dict[str, float]
    support_reactions: dict[int, tuple[float, float]]
    text: str


@dataclass(frozen=True)
class LICQ:
    holds: bool
    rank: int
    active_constraints: int
    sigma_min: float
    dependencies: tuple[Dependency, ...]


@dataclass(frozen=True)
class MFCQ:
    holds: bool
    reason: str


@dataclass(frozen=True)
class MultiplierRange:
    constraint: str
    min: float
    max: float


@dataclass(frozen=True)
class SecondOrder:
    verdict: str  # "strict local minimum", "not a minimum" or "undecided"
    min_eigenvalue: float
    reason: str
    # (N, 2), zero at supports: a unit direction of negative curvature along which every active
    # constraint stays active, when the verdict is "not a minimum" (the solver escapes saddles by it).
    direction: FloatArray | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class CheckReport:
    """What holds at a point; ``None`` for what was not computed (e.g. at an infeasible point)."""

    problem: Problem
    tolerance: float
    feasible: bool
    violation: Violation | None
    active: ActiveSet | None
    multipliers: Multipliers | None
    multiplier_source: str  # "given", "recovered" or "none"
    kkt: KKTResiduals | None
    licq: LICQ | None
    mfcq: MFCQ | None
    multiplier_ranges: tuple[MultiplierRange, ...] | None  # only the forces that are not determined
    second_order: SecondOrder | None
    seconds: float

    @property
    def kkt_holds(self) -> bool:
        return self.kkt is not None and scaled(self.kkt, self.problem).max() <= self.tolerance

    def to_dict(self) -> dict[str, Any]:
        p = self.problem
        return {
            "name": p.name,
            "nodes": p.n_nodes,
            "formulation": p.formulation.value,
            "tolerance": self.tolerance,
            "feasible": self.feasible,
            "violation": None if self.violation is None else vars(self.violation),
            "active_set": None if self.active is None else _active_dict(p, self.active),
            "multipliers": None if self.multipliers is None else _multipliers_dict(p, self),
            "kkt": None if self.kkt is None else self.kkt.as_dict(),
            "kkt_scaled": None if self.kkt is None else scaled(self.kkt, p).as_dict(),
            "kkt_holds": self.kkt_holds,
            "licq": None if self.licq is None else licq_dict(self.licq),
            "mfcq": None if self.mfcq is None else vars(self.mfcq),
            "multiplier_ranges": None if self.multiplier_ranges is None else [vars(r) for r in self.multiplier_ranges],
            "second_order": None if self.second_order is None else vars(self.second_order),
            "seconds": self.seconds,
        }

    def summary(self) -> str:
        p = self.problem
        lines = [f"{p.name}: {p.n_nodes} nodes, {p.formulation.value} formulation, tolerance {self.tolerance:g}"]
        if self.violation is not None:
            lines.append(f"  feasible          no: {self.violation.text}")
            return "\n".join(lines)
        active = self.active
        assert active is not None
        lines.append(
            f"  active set        {active.links.size} taut links, {len(active.contacts)} contacts, "
            f"{active.supports.size} supports (within {active.tolerance:.3g})"
        )
        if self.kkt is not None:
            k = self.kkt
            lines.append(f"  multipliers       {self.multiplier_source}")
            lines.append(
                f"  KKT residuals     stationarity {k.stationarity:.2e}, primal {k.primal_feasibility:.2e}, "
                f"dual {k.dual_feasibility:.2e}, complementarity {k.complementarity:.2e}"
                f" ({'a KKT point' if self.kkt_holds else 'NOT a KKT point'} at this tolerance)"
            )
        if self.licq is not None:
            licq = self.licq
            lines.append(
                f"  LICQ              {'holds' if licq.holds else 'fails'}: rank {licq.rank} of "
                f"{licq.active_constraints} active constraints, smallest singular value {licq.sigma_min:.3g}"
            )
            lines += [f"                    {d.text}" for d in licq.dependencies[:5]]
        if self.mfcq is not None:
            lines.append(f"  MFCQ              {'holds' if self.mfcq.holds else 'fails'}: {self.mfcq.reason}")
        if self.multiplier_ranges:
            shown = ", ".join(f"{r.constraint} in [{r.min:.6g}, {r.max:.6g}]" for r in self.multiplier_ranges[:6])
            more = f" and {len(self.multiplier_ranges) - 6} more" if len(self.multiplier_ranges) > 6 else ""
            lines.append(f"  force ranges      {shown}{more}; the other forces are determined")
        if self.second_order is not None:
            so = self.second_order
            lines.append(f"  second order      {so.verdict}: {so.reason}")
        lines.append(f"  checked in        {self.seconds:.3g} s")
        return "\n".join(lines)


# ----------------------------------------------------------------- JSON pieces
def licq_dict(licq: LICQ) -> dict[str, Any]:
    """The ``licq`` block of the JSON documents (``check`` and ``solve --json``)."""
    return {
        "holds": licq.holds,
        "rank": licq.rank,
        "active_constraints": licq.active_constraints,
        "sigma_min": licq.sigma_min,
        "jacobian": "active link and contact rows over the free coordinates (supports eliminated), unit-force rows",
        "dependencies": [
            {
                "forces": d.forces,
                "support_reactions": {str(node): list(force) for node, force in d.support_reactions.items()},
                "text": d.text,
            }
            for d in licq.dependencies
        ],
    }


def _active_dict(problem: Problem, active: ActiveSet) -> dict[str, Any]:
    return {
        "tolerance": active.tolerance,
        "links": active.links.tolist(),
        "supports": active.supports.tolist(),
        "contacts": [{"obstacle": problem.obstacles[j].name, "node": int(i)} for j, i in active.contacts],
    }


def _multipliers_dict(problem: Problem, report: CheckReport) -> dict[str, Any]:
    assert report.multipliers is not None and report.kkt is not None
    return {
        "source": report.multiplier_source,
        "fit_residual": report.kkt.stationarity,
        "link": report.multipliers.link.tolist(),
        "obstacle": {o.name: nu.tolist() for o, nu in zip(problem.obstacles, report.multipliers.obstacle, strict=True)},
    }


# ----------------------------------------------------------------- the point, evaluated once
@dataclass(frozen=True)
class _Point:
    """A point's geometry, evaluated once and shared by the violation check, the active set, the
    Jacobian and the Hessian (each obstacle is evaluated once per point, at the free nodes)."""

    positions: FloatArray
    free: IntArray  # the free nodes, ascending
    column: IntArray  # (N,): each node's position among the free nodes, -1 at supports
    delta: FloatArray  # (N-1, 2): p_k - p_{k+1}
    distances: FloatArray  # (N-1,)
    phi: FloatArray  # (n_obstacles, n_free)
    gradient: FloatArray  # (n_obstacles, n_free, 2)
    hessian: FloatArray  # (n_obstacles, n_free, 2, 2)


def _evaluate(problem: Problem, positions: FloatArray) -> _Point:
    free = problem.free_nodes
    column = np.full(problem.n_nodes, -1, dtype=np.intp)
    column[free] = np.arange(free.size)
    delta = link_deltas(positions)
    k = len(problem.obstacles)
    phi, gradient, hessian = np.empty((k, free.size)), np.empty((k, free.size, 2)), np.empty((k, free.size, 2, 2))
    points = positions[free]
    for j, obstacle in enumerate(problem.obstacles):
        phi[j], gradient[j], hessian[j] = obstacle.evaluate(points)
    distances = np.hypot(delta[:, 0], delta[:, 1])
    return _Point(positions, free, column, delta, distances, phi, gradient, hessian)


# ----------------------------------------------------------------- feasibility and active set
def _contact_distances(problem: Problem, point: _Point) -> FloatArray:
    """``phi / |grad phi|`` (n_obstacles, N) at every node (supports: -inf)."""
    distance = np.full((len(problem.obstacles), problem.n_nodes), -np.inf)
    norm = np.hypot(point.gradient[..., 0], point.gradient[..., 1])
    distance[:, point.free] = point.phi / np.maximum(norm, 1e-300)
    return distance


def _worst_violation(problem: Problem, point: _Point, distance: FloatArray, length_tol: float) -> Violation | None:
    moved = point.positions[problem.support_nodes] - problem.support_positions
    offset = np.hypot(moved[:, 0], moved[:, 1])
    s = int(offset.argmax())
    over = point.distances - problem.link_lengths
    k = int(over.argmax())
    amounts = [float(offset[s]), float(over[k])]
    if distance.size:
        j, i = (int(index) for index in np.unravel_index(int(distance.argmax()), distance.shape))
        amounts.append(float(distance[j, i]))
    worst = max(range(len(amounts)), key=amounts.__getitem__)  # the first of equal amounts
    amount = amounts[worst]
    if not amount > length_tol:
        return None
    if worst == 0:  # the texts only for the worst (formatting them all costs more than the check)
        node, target = int(problem.support_nodes[s]), problem.support_positions[s]
        return Violation(f"support {node}", amount, f"support node {node} is {offset[s]:.3g} away from {target}")
    if worst == 1:
        length, allowed = over[k] + problem.link_lengths[k], problem.link_lengths[k]
        text = f"link {k} is overstretched by {over[k]:.3g} (length {length:.6g}, allowed {allowed:.6g})"
        return Violation(f"link {k}", amount, text)
    text = f"node {i} is {distance[j, i]:.3g} inside obstacle {problem.obstacles[j].name!r}"
    return Violation(f"node {i}", amount, text)


def _active(problem: Problem, point: _Point, distance: FloatArray, length_tol: float) -> ActiveSet:
    taut = (point.distances >= problem.link_lengths - length_tol).nonzero()[0]
    contacts = np.argwhere(distance >= -length_tol)  # (k, 2) intp, also for k = 0 or no obstacles
    return ActiveSet(length_tol, taut, contacts, problem.support_nodes.copy())


def active_set(problem: Problem, positions: FloatArray, tol: float = DEFAULT_TOL) -> ActiveSet:
    point = _evaluate(problem, positions)
    return _active(problem, point, _contact_distances(problem, point), tol * float(problem.link_lengths.max()))


# ----------------------------------------------------------------- Jacobian and Hessian
@dataclass(frozen=True)
class _Rows:
    """Active constraint rows over the free coordinates, at most two 2-vectors each: row r holds
    ``values[r, s]`` at the two coordinates of free node ``nodes[r, s]`` (s = 0, 1), nothing where
    that node is -1 (a support, or a contact row's unused second slot)."""

    nodes: IntArray  # (m, 2)
    values: FloatArray  # (m, 2, 2)
    n: int  # free coordinates

    @property
    def m(self) -> int:
        return int(self.nodes.shape[0])

    def take(self, index: IntArray) -> _Rows:
        return _Rows(self.nodes[index], self.values[index], self.n)

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


def _jacobian(problem: Problem, point: _Point, active: ActiveSet) -> tuple[_Rows, FloatArray]:
    """Force-unit rows of the active constraints over the free coordinates, and each row's scale.

    A row's multiplier is a force ``t``; the formulation's multiplier is ``t / scale`` with scale
    ``|q_k|`` (the link constraint's gradient at node k) or ``|grad phi|``.
    """
    links, contacts = active.links, active.contacts
    contact_columns = point.column[contacts[:, 1]]  # contacts are never at supports
    vectors = np.concatenate(
        [
            link_gradients(problem.formulation, point.delta[links], point.distances[links]),
            point.gradient[contacts[:, 0], contact_columns],
        ]
    )
    scale = np.hypot(vectors[:, 0], vectors[:, 1])
    nodes = np.full((scale.size, 2), -1, dtype=np.intp)  # a contact row's second node: none
    nodes[: links.size] = point.column[links[:, None] + np.arange(2)]
    nodes[links.size :, 0] = contact_columns
    values = np.zeros((scale.size, 2, 2))
    values[:, 0] = vectors / np.where(scale > 0, scale, 1.0)[:, None]
    values[: links.size, 1] = -values[: links.size, 0]
    return _Rows(nodes, values, 2 * point.free.size), scale


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


# ----------------------------------------------------------------- LICQ
def _independent(rows: _Rows) -> bool:
    """A cheap proof that no singular value of the rows is ``<= RANK_TOL``: a Cholesky
    factorization of ``A A^T - CERTIFY I`` exists, so ``sigma_min^2 > CERTIFY`` (up to its rounding
    error, ~1e-15, far below CERTIFY = (100 RANK_TOL)^2). False means "not proven" (compute)."""
    if rows.m == 0:
        return True
    if rows.n <= DENSE_LIMIT:
        dense = rows.dense()
        try:
            np.linalg.cholesky(dense @ dense.T - CERTIFY * np.eye(rows.m))
        except np.linalg.LinAlgError:
            return False
        return True
    first, second, value = _gram(rows, -CERTIFY)
    position = _band_positions(rows.anchors())
    i, j = position[first], position[second]
    upper = i <= j
    k = int(np.max(j[upper] - i[upper], initial=0))
    band = np.zeros((k + 1, rows.m))  # pbtrf's upper storage
    band[k + i[upper] - j[upper], j[upper]] = value[upper]
    _, info = lapack.dpbtrf(band, overwrite_ab=True)
    return bool(info == 0)


def _gram(rows: _Rows, shift: float) -> tuple[IntArray, IntArray, FloatArray]:
    """Row, column and value of every entry of ``A A^T + shift I`` (each position once: two rows
    share at most one node, so each pair of entries at one node is a position of its own)."""
    r, s = np.nonzero(rows.nodes >= 0)
    node, vector = rows.nodes[r, s], rows.values[r, s]
    order = np.argsort(node, kind="stable")
    r, node, vector = r[order], node[order], vector[order]
    index = np.arange(rows.m)
    firsts, seconds = [index], [index]
    values = [np.bincount(r, weights=np.einsum("ij,ij->i", vector, vector), minlength=rows.m) + shift]
    for offset in range(1, int(np.max(np.bincount(node), initial=0))):  # up to the most entries at a node
        same = np.flatnonzero(node[offset:] == node[:-offset])
        value = np.einsum("ij,ij->i", vector[same], vector[same + offset])
        firsts += [r[same], r[same + offset]]
        seconds += [r[same + offset], r[same]]
        values += [value, value]
    return np.concatenate(firsts), np.concatenate(seconds), np.concatenate(values)


def _left_null_space(rows: _Rows) -> tuple[float, FloatArray]:
    """Smallest singular value of the rows and an orthonormal basis (m, r) of their dependencies."""
    m, n = rows.m, rows.n
    if m == 0:
        return math.inf, np.zeros((0, 0))
    if n == 0:
        return 0.0, np.eye(m)
    if n <= DENSE_LIMIT or m <= NULL_BLOCK + 1:
        u, s, _ = np.linalg.svd(rows.dense(), full_matrices=m > n)  # u is (m, m) either way
        s = np.concatenate([s, np.zeros(max(m - n, 0))])
        return float(s.min()), u[:, s <= RANK_TOL]
    solve = _banded_lu(rows.anchors(), *_gram(rows, SHIFT))
    inverse = sparse_linalg.LinearOperator((m, m), matvec=solve, dtype=np.float64)
    matrix = rows.sparse()
    k = NULL_BLOCK
    while True:
        _, vectors = sparse_linalg.eigsh(inverse, k=k, which="LA")
        _, s, vt = np.linalg.svd(matrix.T @ vectors, full_matrices=False)  # refine: A^T W = U S V^T
        vectors = vectors @ vt.T
        dependent = s <= RANK_TOL
        if not dependent.all() or k >= m - 1:
            return float(s.min()), vectors[:, dependent]
        k = min(2 * k, m - 1)


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


# ----------------------------------------------------------------- multipliers
def _least_squares(rows: Matrix, rhs: FloatArray, null: FloatArray) -> FloatArray:
    """Least-squares ``t`` of ``A^T t = rhs`` orthogonal to the null vectors."""
    m, n = rows.shape
    if n <= DENSE_LIMIT:
        return np.asarray(np.linalg.lstsq(rows.toarray().T, rhs, rcond=None)[0])
    factor = sparse_linalg.splu((rows @ rows.T + SHIFT * sparse.identity(m)).tocsc())
    basis = np.linalg.qr(null)[0] if null.shape[1] else null

    def solve(vector: FloatArray) -> FloatArray:
        t = np.asarray(factor.solve(rows @ vector))
        return np.asarray(t - basis @ (basis.T @ t), dtype=np.float64)

    t = solve(rhs)
    return t + solve(rhs - rows.T @ t)  # one step of iterative refinement


def _least_total_force(t: FloatArray, null: FloatArray, tiny: float) -> FloatArray | None:
    """The element of ``{t + W c >= 0}`` with the least total force; None if the set is empty."""
    directions = _directions(null, t)
    if np.any(t[directions.group < 0] < -tiny):  # a determined force is negative
        return None
    if null.shape[1] == 0:
        return t
    result = linprog(null.sum(axis=0), A_ub=-directions.units, b_ub=-directions.lower, bounds=(None, None))
    return t + null @ np.asarray(result.x) if result.status == 0 else None


def _recover(rows: Matrix, rhs: FloatArray, null: FloatArray, tiny: float) -> FloatArray:
    """Nonnegative forces ``t`` that best satisfy stationarity ``A^T t = rhs``."""
    if rows.shape[0] == 0:
        return np.zeros(0)
    exact = _least_total_force(_least_squares(rows, rhs, null), null, tiny)
    if exact is not None:
        return np.maximum(exact, 0.0)
    if rows.shape[1] <= DENSE_LIMIT:
        return np.asarray(nnls(rows.toarray().T, rhs)[0])
    return np.asarray(lsq_linear(rows.T.tocsr(), rhs, bounds=(0.0, np.inf), method="trf").x)


def _ranges(names: list[str], t: FloatArray, null: FloatArray) -> tuple[MultiplierRange, ...] | None:
    """Range of every force that is not determined, over the multiplier set ``{t + W c >= 0}``.

    Force k is ``t_k + |W_k| (u_j . c)`` with u_j its direction: two LPs per direction.
    """
    directions = _directions(null, t)
    if directions.units.shape[0] > MAX_RANGE_LPS:
        return None
    ends = np.empty((directions.units.shape[0], 2))
    for j, unit in enumerate(directions.units):
        for end, sign in ((0, 1.0), (1, -1.0)):
            result = linprog(sign * unit, A_ub=-directions.units, b_ub=-directions.lower, bounds=(None, None))
            ends[j, end] = float(unit @ result.x) if result.status == 0 else -sign * np.inf
    varying = np.flatnonzero(directions.group >= 0)
    lower = t[varying] + directions.norm[varying] * ends[directions.group[varying], 0]
    upper = t[varying] + directions.norm[varying] * ends[directions.group[varying], 1]
    return tuple(
        MultiplierRange(names[k], float(lo), float(hi)) for k, lo, hi in zip(varying, lower, upper, strict=True)
    )


# ----------------------------------------------------------------- second order
def _min_curvature(
    hessian: _Hessian, rows: _Rows, null: FloatArray, threshold: float
) -> tuple[float, FloatArray | None]:
    """Smallest eigenvalue of ``H`` on the null space of the rows (inf if that space is {0}), and
    its eigenvector (in that null space)."""
    if null.shape[1]:
        rows = rows.take(np.setdiff1d(np.arange(rows.m), _dependent_rows(null)))
    m, n = rows.m, rows.n
    if m >= n:
        return math.inf, None
    if n <= DENSE_LIMIT:
        # The kept rows are independent, so the last n - m columns of a complete QR of their
        # transpose span the null space (a QR costs a fraction of an SVD).
        basis = scipy.linalg.qr(rows.dense().T, mode="full", check_finite=False)[0][:, m:] if m else np.eye(n)
        reduced = basis.T @ hessian.dense() @ basis
        values, vectors = scipy.linalg.eigh(reduced, subset_by_index=(0, 0), check_finite=False)
        return float(values[0]), basis @ vectors[:, 0]
    # The bordered matrix [[H - s I, A^T], [A, 0]] with each row next to its first node: banded.
    shift = hessian.bound() - threshold
    h_rows, h_cols, h_values = hessian.entries()
    a_rows, a_cols, a_values = rows.entries()
    key = np.concatenate([np.arange(n) // 2 * 2, 2 * rows.anchors() + 1])
    try:
        solve = _banded_lu(
            key,
            np.concatenate([h_rows, n + a_rows, a_cols]),
            np.concatenate([h_cols, a_cols, n + a_rows]),
            np.concatenate([h_values - shift * (h_rows == h_cols), a_values, a_values]),
        )
    except np.linalg.LinAlgError:  # exactly singular: the shift hit an eigenvalue (or the scales underflow)
        return math.nan, None

    def apply(vector: FloatArray) -> FloatArray:
        return solve(np.concatenate([vector, np.zeros(m)]))[:n]

    operator = sparse_linalg.LinearOperator((n, n), matvec=apply, dtype=np.float64)
    try:
        # A fixed start (the same problem, the same direction) and a short basis: the wanted
        # eigenvalue is well separated after the shift-invert (10-15 solves instead of 20-odd).
        start = np.random.default_rng(0).standard_normal(n)
        theta, vectors = sparse_linalg.eigsh(operator, k=1, which="LA", tol=1e-10, ncv=LANCZOS_VECTORS, v0=start)
    except sparse_linalg.ArpackNoConvergence:
        return math.nan, None
    # The operator's range lies in the null space of the rows, so a converged eigenvector (residual
    # below 1e-10 theta) is in it but for a part below 1e-10: no further solve to project it.
    direction = vectors[:, 0]
    return float(shift + 1.0 / theta[0]), direction / max(float(np.linalg.norm(direction)), 1e-300)


# The smallest eigenvalue of H on the null space of the first k rows (inf if that space is {0}),
# and its eigenvector.
Curvature = Callable[[int], tuple[float, FloatArray | None]]


def _dense_curvature(hessian: _Hessian, rows: _Rows, first: int) -> Curvature | None:
    """For a small problem whose rows are provably independent: with ``A^T = Q R`` (Householder),
    the columns of Q from k on span the null space of the first k rows, for every k >= ``first``,
    so the strictly active rows and all rows share one QR (whose R proves the independence). Only
    those columns of Q are formed. None if independence is not proven: the rows then go the
    general way (an SVD for their dependencies)."""
    m, n = rows.m, rows.n
    if m > n:
        return None
    basis: FloatArray = np.eye(n)[:, first:]
    if m:
        factors, tau, _, _ = lapack.dgeqrf(rows.dense().T)
        if not _independent_triangle(factors[:m]):
            return None
        if basis.shape[1]:
            basis, _, _ = lapack.dormqr("L", "N", factors, tau, basis, 64 * basis.shape[1])
    reduced = basis.T @ hessian.times(basis)

    def curvature(k: int) -> tuple[float, FloatArray | None]:
        if k >= n:
            return math.inf, None
        j = k - first
        values, vectors, _, _, info = lapack.dsyevr(reduced[j:, j:], range="I", il=1, iu=1)  # the smallest only
        if info:
            raise np.linalg.LinAlgError(f"dsyevr: no convergence ({info})")
        return float(values[0]), basis[:, j:] @ vectors[:, 0]

    return curvature


def _general_curvature(hessian: _Hessian, rows: _Rows, null: FloatArray, threshold: float) -> Curvature:
    """Through the dependencies of the first k rows (``null`` those of all rows), dropped before a
    dense QR or the banded bordered matrix (:func:`_min_curvature`)."""

    def curvature(k: int) -> tuple[float, FloatArray | None]:
        if k == rows.m:
            return _min_curvature(hessian, rows, null, threshold)
        first = rows.take(np.arange(k))
        # Some of a set of independent rows are independent (their singular values interlace).
        return _min_curvature(hessian, first, np.zeros((k, 0)) if null.shape[1] == 0 else _null(first), threshold)

    return curvature


def _zero_curvature(problem: Problem, tol: float) -> float:
    """The curvature below which an eigenvalue counts as zero (module doc, Second order)."""
    return zero_curvature(tol, problem.weight, problem.n_nodes, problem.total_length)


def _second_order(
    problem: Problem,
    point: _Point,
    hessian: _Hessian,
    rows: _Rows,
    forces: FloatArray,
    null: FloatArray | None,
    tol: float,
) -> SecondOrder:
    """The verdict; ``null`` is the rows' dependencies if known (None: found here, only if needed)."""
    force_tol = tol * problem.weight
    if forces.min(initial=0.0) < -force_tol:
        return SecondOrder("undecided", math.nan, "some multipliers are negative (not dual feasible)")
    threshold = _zero_curvature(problem, tol)
    strict = forces > force_tol
    # The strictly active rows first: the critical cone's equalities are the first `count` rows.
    order = np.argsort(~strict, kind="stable")
    rows, count = rows.take(order), int(np.count_nonzero(strict))
    curvature_on = None
    if rows.n <= DENSE_LIMIT and (null is None or null.shape[1] == 0):
        curvature_on = _dense_curvature(hessian, rows, count)
    licq_holds = curvature_on is not None
    if curvature_on is None:
        null = _null(rows) if null is None else null[order]
        licq_holds = null.shape[1] == 0
        curvature_on = _general_curvature(hessian, rows, null, threshold)
    curvature, direction = curvature_on(count)
    if math.isnan(curvature):
        return SecondOrder("undecided", curvature, "the eigenvalue solver did not converge")
    if curvature > threshold:
        return SecondOrder(
            "strict local minimum",
            curvature,
            f"the Hessian of the Lagrangian is positive definite on the null space of the {strict.sum()} "
            "strictly active constraints (second-order sufficient condition)",
        )
    weak = rows.m - count
    if weak:
        curvature, direction = curvature_on(rows.m)
    if curvature < -threshold and licq_holds:
        moves = np.zeros((problem.n_nodes, 2))
        if direction is not None:
            moves[point.free] = direction.reshape(-1, 2)
        return SecondOrder(
            "not a minimum",
            curvature,
            "negative curvature along a direction that keeps every active constraint active "
            "(the second-order necessary condition fails)",
            moves if direction is not None else None,
        )
    if curvature < -threshold:
        reason = "negative curvature for these multipliers, but the multipliers are not unique (LICQ fails)"
    elif weak:
        reason = f"zero curvature, or the answer depends on the {weak} weakly active constraints"
    else:
        reason = "zero curvature on the critical cone: higher-order terms decide"
    return SecondOrder("undecided", curvature, reason)


# ----------------------------------------------------------------- a cheap proof of a strict minimum
def _penalized(hessian: _Hessian, rows: _Rows, weights: FloatArray, shift: float) -> BlockTridiagonal:
    """``H - shift I + A^T diag(weights) A`` as 2x2 blocks. A row is a contact's unit normal n at one
    free node, or a link's +u and -u at its two nodes (either may be a support): it adds ``w n n^T``
    or ``w u u^T`` to each of its free nodes, and a link between free nodes c and c + 1 adds
    ``-w u u^T`` to their coupling, so ``A^T A`` is block tridiagonal like H."""
    first = rows.values[:, 0]
    outer = weights[:, None, None] * first[:, :, None] * first[:, None, :]
    node = rows.nodes.T.ravel()  # every row's first node, then every row's second
    touched = (node >= 0).nonzero()[0]
    diagonal = hessian.diagonal.copy()
    diagonal[:, (0, 1), (0, 1)] -= shift
    np.add.at(diagonal, node[touched], outer[touched % rows.m])
    link = ((rows.nodes[:, 0] >= 0) & (rows.nodes[:, 1] >= 0)).nonzero()[0]
    coupling = hessian.coupling.copy()
    coupling[rows.nodes[link, 0]] -= outer[link]  # one link per pair of neighbours: no repeats
    return BlockTridiagonal(diagonal, coupling)


def _proves_minimum(
    problem: Problem, hessian: _Hessian, rows: _Rows, forces: FloatArray, tol: float, linear_solver: LinearSolver
) -> bool:
    """True only where :func:`_second_order` says "strict local minimum", in O(N) and without its
    curvature: ``H + rho A^T A - s I`` (A the strictly active rows) is positive definite, so
    ``z^T H z > s |z|^2`` for every z with ``A z = 0``, and s covers the zero-curvature threshold
    and the factorization's rounding. False: not proven here (a rho too small, a curvature near
    the threshold, or not a minimum)."""
    weight = problem.weight
    if forces.min(initial=0.0) < -tol * weight:
        return False  # not dual feasible: "undecided"
    if rows.n == 0:
        return True  # nothing can move
    stiffest = float(np.abs(hessian.diagonal).max(initial=0.0))
    threshold = _zero_curvature(problem, tol)
    rho, shift = penalty_and_shift(
        stiffest, weight / problem.total_length, 2, len(problem.obstacles), threshold, PENALTY
    )
    matrix = _penalized(hessian, rows, np.where(forces > tol * weight, rho, 0.0), shift)
    try:
        linear_solver(matrix)
    except np.linalg.LinAlgError:
        return False
    return True


# ----------------------------------------------------------------- the check
def _as_multipliers(problem: Problem, multipliers: Multipliers | None) -> Multipliers | None:
    if multipliers is None:
        return None
    link = np.asarray(multipliers.link, dtype=np.float64)
    obstacle = np.asarray(multipliers.obstacle, dtype=np.float64)
    expected = (len(problem.obstacles), problem.n_nodes)
    if link.shape != (problem.n_links,) or obstacle.size != expected[0] * expected[1]:
        raise ScenarioError(
            f"multipliers must have {problem.n_links} link and {expected[0]} x {expected[1]} "
            f"obstacle entries, got shapes {link.shape} and {obstacle.shape}."
        )
    obstacle = obstacle.reshape(expected)
    if not (np.all(np.isfinite(link)) and np.all(np.isfinite(obstacle))):
        raise ScenarioError("the multipliers contain a number that is not finite.")
    return Multipliers(link, obstacle)


def _to_multipliers(problem: Problem, active: ActiveSet, forces: FloatArray, scale: FloatArray) -> Multipliers:
    link = np.zeros(problem.n_links)
    obstacle = np.zeros((len(problem.obstacles), problem.n_nodes))
    raw = forces / np.where(scale > 0, scale, 1.0)
    link[active.links] = raw[: active.links.size]
    obstacle[active.contacts[:, 0], active.contacts[:, 1]] = raw[active.links.size :]
    return Multipliers(link, obstacle)


def _to_forces(active: ActiveSet, multipliers: Multipliers, scale: FloatArray) -> FloatArray:
    contacts = multipliers.obstacle[active.contacts[:, 0], active.contacts[:, 1]]
    return np.concatenate([multipliers.link[active.links], contacts]) * scale


LINKS_NOT_CHECKED = (
    "funicular check supports contact = 'nodes' only: the link-contact constraints of contact = 'links' "
    "are not checked yet (the solve's KKT residuals do include them)."
)


def _links_mode(problem: Problem) -> bool:
    """Link-contact rows (one per obstacle and link) are not assembled here yet."""
    return problem.contact == "links" and bool(problem.obstacles)


def _check_tol(tol: object) -> None:
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < 1:
        raise ScenarioError(f"tol = {shown(tol)} must be a number between 0 and 1.")


@dataclass(frozen=True)
class _Linearization:
    """The active constraints at a feasible point and their Jacobian rows on the free coordinates
    (with each row's scale)."""

    point: _Point
    active: ActiveSet
    rows: _Rows
    scale: FloatArray


def _linearize(problem: Problem, positions: FloatArray, tol: float) -> Violation | _Linearization:
    """The worst violation if ``positions`` is infeasible, else the active constraints linearized."""
    point = _evaluate(problem, positions)
    distance = _contact_distances(problem, point)
    length_tol = tol * float(problem.link_lengths.max())
    violation = _worst_violation(problem, point, distance, length_tol)
    if violation is not None:
        return violation
    active = _active(problem, point, distance, length_tol)
    rows, scale = _jacobian(problem, point, active)
    return _Linearization(point, active, rows, scale)


def check(
    problem: Problem,
    positions: FloatArray,
    multipliers: Multipliers | None = None,
    tol: float = DEFAULT_TOL,
) -> CheckReport:
    """Diagnose ``positions`` (N, 2): feasibility, active set, multipliers, KKT, LICQ, MFCQ, second order.

    ``multipliers`` are in the problem's formulation; if None they are recovered from the positions.
    Raises :class:`ScenarioError` for positions or multipliers of the wrong shape or not finite.
    """
    started = time.perf_counter()
    if _links_mode(problem):
        raise ScenarioError(LINKS_NOT_CHECKED)
    positions = np.asarray(positions, dtype=np.float64)
    if positions.shape != (problem.n_nodes, 2) or not np.all(np.isfinite(positions)):
        raise ScenarioError(f"positions must be {problem.n_nodes} finite (x, y) pairs, got shape {positions.shape}.")
    _check_tol(tol)
    given = _as_multipliers(problem, multipliers)
    source = "none" if given is None else "given"
    linear = _linearize(problem, positions, tol)
    if isinstance(linear, Violation):
        kkt = None if given is None else kkt_residuals(problem, positions, given.link, given.obstacle)
        elapsed = time.perf_counter() - started
        return CheckReport(problem, tol, False, linear, None, given, source, kkt, None, None, None, None, elapsed)
    active, rows, scale = linear.active, linear.rows, linear.scale
    licq, null = _licq(problem, positions, active, rows)
    mfcq = _mfcq(null)
    if given is None:
        forces = _recover(rows.sparse(), _minus_energy_gradient(problem), null, tol * problem.weight)
        used, source = _to_multipliers(problem, active, forces, scale), "recovered"
    else:
        used, forces = given, _to_forces(active, given, scale)
    kkt = kkt_residuals(problem, positions, used.link, used.obstacle if problem.obstacles else None)
    ranges = _ranges(active.names(problem), forces, null) if null.shape[1] else ()
    second = _second_order(problem, linear.point, _hessian(problem, linear.point, used), rows, forces, null, tol)
    elapsed = time.perf_counter() - started
    return CheckReport(problem, tol, True, None, active, used, source, kkt, licq, mfcq, ranges, second, elapsed)


def _minus_energy_gradient(problem: Problem) -> FloatArray:
    """``-grad E`` over the free coordinates: stationarity reads ``A^T t = -grad E``."""
    minus_gradient = np.zeros(2 * problem.free_nodes.size)
    minus_gradient[1::2] = -problem.gravity * problem.masses[problem.free_nodes]
    return minus_gradient


def recover_multipliers(problem: Problem, positions: FloatArray, tol: float = DEFAULT_TOL) -> Multipliers:
    """Multipliers that best satisfy stationarity at ``positions`` (nonnegative, least total force)."""
    point = _evaluate(problem, positions)
    active = _active(problem, point, _contact_distances(problem, point), tol * float(problem.link_lengths.max()))
    rows, scale = _jacobian(problem, point, active)
    forces = _recover(rows.sparse(), _minus_energy_gradient(problem), _null(rows), tol * problem.weight)
    return _to_multipliers(problem, active, forces, scale)


def check_solution(solution: Solution, tol: float = DEFAULT_TOL) -> CheckReport:
    """:func:`check` of a solver's result, with the solver's multipliers."""
    problem = solution.problem
    if _links_mode(problem):
        raise ScenarioError(LINKS_NOT_CHECKED)
    obstacle = solution.obstacle_multipliers.reshape(len(problem.obstacles), problem.n_nodes)
    return check(problem, solution.positions, Multipliers(solution.link_multipliers, obstacle), tol)


def _at_solution(
    problem: Problem, solution: Solution, tol: float
) -> SecondOrder | tuple[_Point, _Hessian, _Rows, FloatArray]:
    """A solver's result evaluated, its Hessian of the Lagrangian, active rows and their forces; or
    the verdict "undecided" where there is nothing to check (``contact = "links"``, an infeasible
    point)."""
    if _links_mode(problem):
        return SecondOrder("undecided", math.nan, "contact = 'links' is not checked yet")
    _check_tol(tol)
    obstacle = solution.obstacle_multipliers.reshape(len(problem.obstacles), problem.n_nodes)
    multipliers = Multipliers(solution.link_multipliers, obstacle)
    linear = _linearize(problem, solution.positions, tol)
    if isinstance(linear, Violation):
        return SecondOrder("undecided", math.nan, f"infeasible: {linear.text}")
    forces = _to_forces(linear.active, multipliers, linear.scale)
    return linear.point, _hessian(problem, linear.point, multipliers), linear.rows, forces


def second_order(
    problem: Problem, solution: Solution, tol: float = DEFAULT_TOL, proof: LinearSolver | None = None
) -> SecondOrder:
    """The second-order verdict at a solver's result ("undecided" at an infeasible point).

    Given a ``proof`` (a linear solver of :mod:`funicular.solver.banded`), the cheap sufficient test
    of :func:`proves_strict_minimum` comes first: where it proves a strict local minimum, that is the
    verdict, without the curvature (``min_eigenvalue`` nan) or the eigenvalue problem it costs.
    """
    # Only what the verdict needs (the full check also runs MFCQ and the multiplier ranges, linear
    # programs that cost far more than the solve for a small chain).
    at = _at_solution(problem, solution, tol)
    if isinstance(at, SecondOrder):
        return at
    point, hessian, rows, forces = at
    if proof is not None and _proves_minimum(problem, hessian, rows, forces, tol, proof):
        reason = (
            "the Hessian of the Lagrangian plus a penalty on the strictly active constraints is positive "
            "definite (a Cholesky factorization), so it is on their null space (second-order sufficient "
            "condition; the curvature was not computed)"
        )
        return SecondOrder("strict local minimum", math.nan, reason)
    return _second_order(problem, point, hessian, rows, forces, None, tol)


def proves_strict_minimum(
    problem: Problem, solution: Solution, tol: float = DEFAULT_TOL, linear_solver: LinearSolver = banded_cholesky
) -> bool:
    """A cheap sufficient test: True only where :func:`second_order` says "strict local minimum"
    (one block-tridiagonal Cholesky factorization, no eigenvalue, no direction); False where it is
    not proven, which the full check then decides. ``linear_solver`` factors the penalized Hessian
    (:mod:`funicular.solver.banded`; raises ``LinAlgError`` where it is not positive definite)."""
    at = _at_solution(problem, solution, tol)
    if isinstance(at, SecondOrder):
        return False
    _, hessian, rows, forces = at
    return _proves_minimum(problem, hessian, rows, forces, tol, linear_solver)


def licq_of(solution: Solution, tol: float = DEFAULT_TOL) -> LICQ | None:
    """LICQ at a solver's result (None if the point is infeasible or ``contact = "links"``, not checked
    yet): the ``licq`` block of ``solve --json``."""
    problem, positions = solution.problem, solution.positions
    if _links_mode(problem):
        return None
    linear = _linearize(problem, positions, tol)
    return None if isinstance(linear, Violation) else _licq(problem, positions, linear.active, linear.rows)[0]


# ----------------------------------------------------------------- solution files
def _numbers(document: dict[str, Any], key: str, length: int, source: str, what: str) -> FloatArray:
    value = document.get(key)
    if not isinstance(value, list):
        raise ScenarioError(f"{source}: {key} must be a list of {length} numbers, one per {what}.")
    if len(value) != length:
        raise ScenarioError(
            f"{source}: {key} has {len(value)} entries, but the scenario has {length} {what}s; "
            "is it a solution of this scenario?"
        )
    for i, item in enumerate(value):
        if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
            raise ScenarioError(f"{source}: {key}[{i}] = {shown(item)} is not a finite number.")
    return np.array(value, dtype=np.float64)


def read_solution(
    problem: Problem, path: str | Path, tol: float = DEFAULT_TOL
) -> tuple[FloatArray, Multipliers | None]:
    """Positions and (if present) multipliers from a JSON solution file, as ``funicular solve --json`` writes.

    Needs ``x`` and ``y`` (N numbers each); optional ``multipliers.link`` (N-1) and, for each
    obstacle, ``multipliers.obstacle[name]`` (N), in the formulation named by ``formulation``
    (default: the problem's). Raises :class:`ScenarioError` for an unreadable file, invalid JSON,
    wrong lengths, numbers that are not finite, or supports away from their positions.
    """
    _check_tol(tol)
    source = str(path)
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as error:
        raise ScenarioError(f"cannot read solution file {source!r}: {error.strerror or error}.") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ScenarioError(f"solution file {source!r} is not valid JSON: {error}.") from None
    if not isinstance(document, dict):
        raise ScenarioError(f"{source}: a solution file must be a JSON object with x and y lists.")
    n = problem.n_nodes
    positions = np.column_stack([_numbers(document, key, n, source, "node") for key in ("x", "y")])
    offset = positions[problem.support_nodes] - problem.support_positions
    distance = np.hypot(offset[:, 0], offset[:, 1])
    j = int(np.argmax(distance))
    if distance[j] > tol * float(problem.link_lengths.max()):
        node, (x, y) = int(problem.support_nodes[j]), problem.support_positions[j]
        raise ScenarioError(
            f"{source}: node {node} is a support at ({x:g}, {y:g}), but the file puts it {distance[j]:.3g} away "
            f"(offset ({offset[j, 0]:.3g}, {offset[j, 1]:.3g})); is it a solution of this scenario?"
        )
    block = document.get("multipliers")
    if block is None:
        return positions, None
    if not isinstance(block, dict):
        raise ScenarioError(f"{source}: multipliers must be an object with a link list.")
    link = _numbers(block, "link", problem.n_links, source, "link")
    formulation = Formulation.parse(document.get("formulation", problem.formulation.value), f"{source}: formulation")
    if formulation is not problem.formulation:  # through the tensions, which both formulations share
        distances = link_distances(positions)
        tension = tension_from_multipliers(formulation, link, distances)
        link = multipliers_from_tension(problem.formulation, tension, distances)
    obstacles = block.get("obstacle", {})
    if not isinstance(obstacles, dict):
        raise ScenarioError(f"{source}: multipliers.obstacle must map obstacle names to lists.")
    nu = np.zeros((len(problem.obstacles), n))
    for j, obstacle in enumerate(problem.obstacles):
        if obstacle.name not in obstacles:
            raise ScenarioError(f"{source}: multipliers.obstacle has no entry for obstacle {obstacle.name!r}.")
        nu[j] = _numbers(obstacles, obstacle.name, n, source, "node")
    return positions, Multipliers(link, nu)


# ----------------------------------------------------------------- command line
def solution_document(solution: Solution) -> dict[str, Any]:
    """``solution.to_dict()`` with the ``licq`` block (None at an infeasible point): ``solve --json``."""
    document = solution.to_dict()
    licq = licq_of(solution)
    document["licq"] = None if licq is None else licq_dict(licq)
    return document


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from funicular.cli import add_scenario_argument

    add_scenario_argument(parser)
    parser.add_argument(
        "--solution",
        metavar="FILE.json",
        help="check this point (JSON with x and y, as solve --json writes) instead of funicular's solution",
    )
    parser.add_argument("--json", metavar="PATH", help="write the report as JSON")
    parser.add_argument(
        "--tol", type=float, default=DEFAULT_TOL, help=f"relative tolerance of every test (default {DEFAULT_TOL:g})"
    )


def run(args: argparse.Namespace) -> int:
    """Exit 0 at a feasible KKT point, 1 at an infeasible point or one whose residuals exceed tol."""
    from funicular.cli import EXIT_NOT_CONVERGED, EXIT_OK, load_problem
    from funicular.io import atomic_write_text
    from funicular.report import to_json
    from funicular.solver import solve

    _check_tol(args.tol)
    problem = load_problem(args)
    if args.solution is None:
        solution = solve(problem)
        print(f"checking funicular's solution ({solution.status.value})")
        report = check_solution(solution, args.tol)
    else:
        positions, multipliers = read_solution(problem, args.solution, args.tol)
        print(f"checking {args.solution} ({'with' if multipliers else 'without'} multipliers)")
        report = check(problem, positions, multipliers, args.tol)
    print(report.summary())
    if args.json is not None:
        atomic_write_text(args.json, to_json(report.to_dict()))
        print(f"  wrote {args.json}")
    return EXIT_OK if report.feasible and report.kkt_holds else EXIT_NOT_CONVERGED
