"""A net's statics at an equilibrium: LICQ at the scale of a structure.

The active constraints (taut links, touching nodes) carry the forces ``t >= 0`` (tensions, contact
forces) that balance gravity at the free nodes: ``J^T t = F``, J the active rows in force units (a
taut link's row holds its unit vector u at its first node and -u at its second; a contact's the
unit outward normal). LICQ holds when J has full row rank: the forces are then unique. Where it
fails the structure is *statically indeterminate*: the forces form a set of dimension
``m - rank(J)`` (the degree of indeterminacy), and each vector of the left null space of J is a
*self-stress*, tensions in equilibrium with each other and no load, that can be added to any
solution as long as the tensions stay >= 0. The range of every force over that set comes from two
linear programs per force. MFCQ fails where a self-stress is a pure tension (every force >= 0):
adding it without bound keeps every force >= 0, so the forces are unbounded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg

from funicular._constraints import (
    link_deltas,
    multipliers_from_tension,
    norms,
    tension_from_multipliers,
)
from funicular._forces import node_loads
from funicular.checks._licq import lanczos_null_space, proven_independent, shifted_gram
from funicular.checks._multipliers import _recover
from funicular.checks._report import Multipliers
from funicular.checks._tolerances import DEFAULT_TOL, RANK_TOL, SHIFT, ZERO_WEIGHT, Matrix
from funicular.model import FloatArray, IntArray, Problem
from funicular.solution import Solution

DENSE_UP_TO = 4_000_000  # entries of J up to which its singular values are computed (dense)
LANCZOS_UP_TO = 100_000  # active rows up to which sparse dependencies are sought where LICQ is not proven
SELF_STRESS_SOUGHT = 64  # self-stress states sought at most by the sparse search
LP_SECONDS = 10.0  # the force ranges' linear programs (in all), and MFCQ's, take at most this long
RANGES_UP_TO = 300  # active constraints up to which each force's range is computed (two LPs each)
# A range's bound this small, relative to the largest force or load, is 0 to rounding (the
# programs' answers are sums and differences of forces: -2.2e-16 for a force that can vanish).
ZERO_FORCE_RTOL = 1e-12
SELF_STRESS_SHOWN = 10  # self-stress states listed at most


@dataclass(frozen=True)
class Statics:
    """The active constraints of a net at a point, and whether their forces are unique.

    ``rank`` and everything after it are None where it is not decided (see :func:`_decompose`).
    ``self_stress``: a basis of the self-stress states (at most SELF_STRESS_SHOWN), each as the
    constraints it involves with their relative forces (the largest 1). ``ranges``: each active
    constraint's smallest and largest force over all equilibria, None where not computed.
    """

    names: tuple[str, ...]
    rank: int | None
    self_stress: tuple[dict[str, float], ...]
    ranges: tuple[tuple[float, float], ...] | None
    # MFCQ: no self-stress is a pure tension (forces >= 0, not all zero); where one is, it can be
    # added to any equilibrium without bound, and the forces are unbounded. None: not decided.
    mfcq: bool | None = None

    @property
    def active_constraints(self) -> int:
        return len(self.names)

    @property
    def degree_of_indeterminacy(self) -> int | None:
        return None if self.rank is None else self.active_constraints - self.rank

    @property
    def holds(self) -> bool | None:
        """LICQ: the active rows are independent, the forces unique (None: not decided)."""
        return None if self.rank is None else self.rank == self.active_constraints

    def as_dict(self) -> dict[str, Any]:
        """The ``licq`` block of a net's result file."""
        return {
            "holds": self.holds,
            "rank": self.rank,
            "active_constraints": self.active_constraints,
            "degree_of_indeterminacy": self.degree_of_indeterminacy,
            "mfcq": self.mfcq,
            "self_stress": [dict(state) for state in self.self_stress],
            "force_ranges": None
            if self.ranges is None
            else {name: list(bounds) for name, bounds in zip(self.names, self.ranges, strict=True)},
        }


@dataclass(frozen=True)
class _Active:
    """The active constraints at a point: their names and rows, the taut links (the first rows),
    then each contact's obstacle and node, with the length of the obstacle's gradient there (a
    contact force is ``nu`` times it)."""

    names: list[str]
    rows: _Rows
    links: IntArray
    delta: FloatArray  # (L, d): every link's p_a - p_b at the point
    distances: FloatArray  # (L,): every link's length at the point
    obstacle_hessians: FloatArray  # (n_obstacles, n_free, d, d): each obstacle's at the free nodes
    contacts: IntArray  # (c, 2): obstacle, node
    normal_sizes: FloatArray  # (c,)

    @property
    def m(self) -> int:
        return len(self.names)


def _active_rows(problem: Problem, positions: FloatArray, tol: float) -> _Active:
    """The active constraints and their rows in force units, over every node: the links and contacts
    within ``tol`` times the longest link of their bounds, the planar checker's rule."""
    links = problem.link_nodes
    length = float(problem.link_lengths.max())
    delta = link_deltas(positions, problem.links)
    distances = norms(delta)
    taut = np.flatnonzero(distances >= problem.link_lengths - tol * length)
    names = [f"link {k}" for k in taut]
    unit = delta[taut] / np.maximum(distances[taut], 1e-300)[:, None]
    first, second, vectors = [links[taut, 0]], [links[taut, 1]], [unit]
    contacts, sizes = [np.zeros((0, 2), dtype=np.intp)], [np.zeros(0)]
    free = problem.free_nodes
    d = problem.dimension
    hessians = np.empty((len(problem.obstacles), free.size, d, d))
    for j, obstacle in enumerate(problem.obstacles):
        phi, gradient, hessians[j] = obstacle.evaluate(positions[free])
        size = norms(gradient)
        touching = np.flatnonzero(phi / np.maximum(size, 1e-300) >= -tol * length)
        first.append(free[touching])
        second.append(np.full(touching.size, -1))  # a contact row has one node
        vectors.append(gradient[touching] / np.maximum(size[touching], 1e-300)[:, None])
        names.extend(f"{obstacle.name} at node {free[i]}" for i in touching)
        contacts.append(np.column_stack([np.full(touching.size, j), free[touching]]))
        sizes.append(size[touching])
    rows = _Rows(np.concatenate(first), np.concatenate(second), np.concatenate(vectors))
    return _Active(names, rows, taut, delta, distances, hessians, np.concatenate(contacts), np.concatenate(sizes))


@dataclass(frozen=True)
class _Rows:
    """Active rows, each ``+vector`` at node ``first`` and ``-vector`` at node ``second`` (-1: none);
    kept this way (not as an m x N d matrix) so a large net's rows cost O(m) until they are known
    to be small enough to decompose."""

    first: IntArray
    second: IntArray
    vectors: FloatArray  # (m, d)

    def dense(self, n: int) -> FloatArray:
        m, d = self.vectors.shape
        matrix = np.zeros((m, n, d))
        r = np.arange(m)
        matrix[r, self.first] += self.vectors
        other = self.second >= 0
        matrix[r[other], self.second[other]] -= self.vectors[other]
        return matrix.reshape(m, n * d)

    def sparse(self, problem: Problem) -> Matrix:
        """The rows over the free coordinates (a support's columns dropped), sparse."""
        m, d = self.vectors.shape
        column = free_index(problem)
        rows, cols, values = [], [], []
        for nodes, sign in ((self.first, 1.0), (self.second, -1.0)):
            at = column[nodes]
            kept = np.flatnonzero(at >= 0)
            rows.append(np.repeat(kept, d))
            cols.append((at[kept, None] * d + np.arange(d)).ravel())
            values.append(sign * self.vectors[kept].ravel())
        shape = (m, problem.free_nodes.size * d)
        return sparse.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=shape)


def _free_columns(problem: Problem) -> IntArray:
    d = problem.dimension
    return (problem.free_nodes[:, None] * d + np.arange(d)).ravel()


@dataclass(frozen=True)
class _Decomposition:
    """The active rows over the free coordinates (dense), their rank and a basis of their left
    null space (m, m - rank): the self-stress states."""

    jacobian: FloatArray
    rank: int
    null: FloatArray


@dataclass(frozen=True)
class _SparseDecomposition:
    """The rank of active rows too many for the dense decomposition and a basis of their left null
    space (m, m - rank), found by sparse linear algebra (no Jacobian kept)."""

    rank: int
    null: FloatArray


def _decompose(problem: Problem, active: _Active) -> _Decomposition | _SparseDecomposition | None:
    """Dense up to DENSE_UP_TO entries of J, sparse beyond (:func:`_sparse_decomposition`; None where
    it does not decide). Where the force ranges are not computed anyway (more than RANGES_UP_TO
    rows), the sparse proof of full rank comes first: milliseconds where the dense decomposition of
    a few hundred nodes takes a second."""
    m = active.m
    large = m * problem.free_nodes.size * problem.dimension > DENSE_UP_TO
    if large or m > RANGES_UP_TO:
        found = _sparse_decomposition(problem, active, search=large)
        if found is not None or large:
            return found
    jacobian = active.rows.dense(problem.n_nodes)[:, _free_columns(problem)]
    if m == 0 or jacobian.shape[1] == 0:
        return _Decomposition(jacobian, 0, np.eye(m))
    left, sigma, _ = np.linalg.svd(jacobian, full_matrices=True)
    rank = int(np.count_nonzero(sigma > RANK_TOL))  # (force-unit rows: the planar checker's absolute rule)
    return _Decomposition(jacobian, rank, left[:, rank:])


def free_index(problem: Problem) -> IntArray:
    """Each node's place among the free nodes, -1 at a support, and -1 at index -1 too (N + 1
    entries): a row's "no node" slot maps to -1."""
    column = np.full(problem.n_nodes + 1, -1)
    column[problem.free_nodes] = np.arange(problem.free_nodes.size)
    return column


def _sparse_decomposition(problem: Problem, active: _Active, search: bool) -> _SparseDecomposition | None:
    """The rows' rank and self-stress states by sparse linear algebra. A taut link between two
    supports (a row with no free coordinate) is a self-stress state of its own; the other rows are
    proven independent by one sparse Cholesky factorization of ``J J^T - CERTIFY I`` in the core
    (the usual answer: a net's taut links are independent unless braced or held flat), or, with
    ``search``, their dependencies are the eigenvectors of ``J J^T`` with the smallest eigenvalues
    (shift-invert Lanczos over a sparse LU of ``J J^T + SHIFT I``). None where that is not
    decided: not proven without ``search``, more than LANCZOS_UP_TO rows to search or more than
    SELF_STRESS_SOUGHT states, or the search failed."""
    rows, m = active.rows, active.m
    column = free_index(problem)
    nodes = np.column_stack([column[rows.first], column[rows.second]])
    zero = np.flatnonzero((nodes < 0).all(axis=1))
    kept = np.flatnonzero((nodes >= 0).any(axis=1))
    if zero.size > SELF_STRESS_SOUGHT:
        return None
    if proven_independent(nodes[kept], rows.vectors[kept]):
        rest: FloatArray | None = np.zeros((kept.size, 0))
    elif not search or kept.size > LANCZOS_UP_TO:
        return None
    else:
        rest = _searched_null_space(rows.sparse(problem)[kept], SELF_STRESS_SOUGHT - zero.size)
    if rest is None or zero.size + rest.shape[1] > SELF_STRESS_SOUGHT:
        return None
    null = np.zeros((m, zero.size + rest.shape[1]))
    null[zero, np.arange(zero.size)] = 1.0
    null[kept, zero.size :] = rest
    return _SparseDecomposition(m - null.shape[1], null)


def _searched_null_space(matrix: Matrix, most: int) -> FloatArray | None:
    """A basis of the sparse rows' dependencies (at most ``most``), None if there are more or the
    factorization or the eigenvalue iteration fails."""
    try:
        found = lanczos_null_space(matrix, sparse_linalg.splu(shifted_gram(matrix, SHIFT).tocsc()).solve, most)
    except (RuntimeError, sparse_linalg.ArpackNoConvergence, sparse_linalg.ArpackError):
        return None  # (an exactly singular LU or no convergence: not decided)
    return None if found is None else found[1]


def statics(problem: Problem, positions: FloatArray, tol: float = DEFAULT_TOL) -> Statics:
    """The statics of ``problem`` at ``positions`` (see the module documentation)."""
    active = _active_rows(problem, np.asarray(positions, dtype=np.float64), tol)
    return _statics(problem, active, _decompose(problem, active))


def _statics(problem: Problem, active: _Active, decomposition: _Decomposition | _SparseDecomposition | None) -> Statics:
    names, m = active.names, active.m
    if m == 0:
        return Statics((), 0, (), (), mfcq=True)
    if decomposition is None:
        return Statics(tuple(names), None, (), None)
    rank, null = decomposition.rank, decomposition.null
    states = []
    for vector in null.T[:SELF_STRESS_SHOWN]:
        largest = float(np.max(np.abs(vector)))
        vector = vector / (largest if vector[np.argmax(np.abs(vector))] > 0 else -largest)
        states.append({names[r]: float(vector[r]) for r in np.flatnonzero(np.abs(vector) > 1e-9)})
    ranges = None
    if m <= RANGES_UP_TO and isinstance(decomposition, _Decomposition):
        ranges = _force_ranges(decomposition.jacobian, free_load(problem), rank, null)
    return Statics(tuple(names), rank, tuple(states), ranges, _no_tension_self_stress(null))


def free_load(problem: Problem) -> FloatArray:
    """The applied load (weights and point loads) over the free coordinates, ``-grad E``: what the
    active forces balance (stationarity reads ``A^T t = -grad E``)."""
    return np.asarray(node_loads(problem)[problem.free_nodes].ravel())


def _no_tension_self_stress(null: FloatArray) -> bool | None:
    """MFCQ (Gordan): no ``t = null y >= 0`` with ``sum(t) = 1`` (a linear program; None where it
    is not solved within LP_SECONDS)."""
    if null.shape[1] == 0:
        return True
    from scipy.optimize import linprog

    k = null.shape[1]
    result = linprog(
        np.zeros(k),
        A_ub=-null,
        b_ub=np.zeros(null.shape[0]),
        A_eq=null.sum(axis=0)[None, :],
        b_eq=[1.0],
        bounds=[(None, None)] * k,
        method="highs",
        options={"time_limit": LP_SECONDS},
    )
    if result.status not in (0, 2):  # (1: out of time)
        return None
    return bool(result.status == 2)  # infeasible: no such self-stress


def _force_ranges(
    jacobian: FloatArray, load: FloatArray, rank: int, null: FloatArray
) -> tuple[tuple[float, float], ...] | None:
    """Each force's smallest and largest value over ``J^T t = F`` with ``t >= 0``: its own
    value where the forces are unique, else two linear programs (HiGHS). None where the equations
    have no nonnegative solution (the point is not an equilibrium), or where the programs take more
    than LP_SECONDS in all (not computed)."""
    from scipy.optimize import linprog

    deadline = time.monotonic() + LP_SECONDS
    m = jacobian.shape[0]
    forces, *_ = np.linalg.lstsq(jacobian.T, load, rcond=None)
    zero = ZERO_FORCE_RTOL * max(float(np.max(np.abs(load), initial=0.0)), float(np.max(np.abs(forces), initial=0.0)))

    def bound(value: float) -> float:
        """A bound as reported: 0 where it is 0 to rounding (a negative zero too)."""
        return 0.0 if abs(value) <= zero else float(value)

    if null.shape[1] == 0:
        return tuple((bound(t), bound(t)) for t in forces)
    # A self-stress's entry at rounding level (relative to its largest) is zero: a force that no
    # self-stress moves is determined, and its programs would only weigh rounding (HiGHS then
    # reports numerical trouble).
    null = np.where(np.abs(null) > ZERO_WEIGHT * np.abs(null).max(axis=0, initial=0.0), null, 0.0)
    # t = forces + null y, t >= 0: bounds of each t_r over y
    ranges = []
    for r in range(m):
        if not null[r].any():
            ranges.append((bound(forces[r]), bound(forces[r])))
            continue
        bounds = []
        for sign in (1.0, -1.0):
            left = deadline - time.monotonic()
            if left <= 0.0:
                return None
            result = linprog(
                sign * null[r],
                A_ub=-null,
                b_ub=forces,
                bounds=[(None, None)] * null.shape[1],
                method="highs",
                options={"time_limit": left},
            )
            if result.status in (1, 2, 4):  # out of time, no nonnegative forces balance the load, numerical trouble
                return None
            if result.status == 3 or result.fun is None:  # unbounded
                bounds.append(-np.inf * sign)
            else:
                bounds.append(bound(forces[r] + sign * result.fun))
        ranges.append((bounds[0], bounds[1]))
    return tuple(ranges)


def _recovered_forces(
    problem: Problem, active: _Active, decomposition: _Decomposition | _SparseDecomposition | None, tol: float
) -> FloatArray:
    """Nonnegative forces that best balance the load at every free node, the least total force
    where several do: the planar checker's recovery on these rows. Where the rows' dependencies
    are not known (``decomposition`` None), a least-squares answer is one of the balancing sets."""
    null = np.zeros((active.m, 0)) if decomposition is None else decomposition.null
    return _recover(active.rows.sparse(problem), free_load(problem), null, tol * problem.weight)


def _to_multipliers(problem: Problem, active: _Active, forces: FloatArray) -> Multipliers:
    """Forces of the active rows (tensions, contact forces) as the formulation's multipliers."""
    taut = active.links
    link = np.zeros(problem.n_links)
    link[taut] = multipliers_from_tension(problem.formulation, forces[: taut.size], active.distances[taut])
    obstacle = np.zeros((len(problem.obstacles), problem.n_nodes))
    obstacle[active.contacts[:, 0], active.contacts[:, 1]] = forces[taut.size :] / np.maximum(
        active.normal_sizes, 1e-300
    )
    return Multipliers(link, obstacle)


def _to_forces(problem: Problem, active: _Active, multipliers: Multipliers) -> FloatArray:
    """The formulation's multipliers as the forces of the active rows."""
    taut = active.links
    tension = tension_from_multipliers(problem.formulation, multipliers.link[taut], active.distances[taut])
    contact = multipliers.obstacle[active.contacts[:, 0], active.contacts[:, 1]] * active.normal_sizes
    return np.concatenate([tension, contact])


def recovered_multipliers(problem: Problem, positions: FloatArray, tol: float = DEFAULT_TOL) -> Multipliers:
    """Multipliers of a net or a chain in space recovered from ``positions`` alone: nonnegative
    tensions and contact forces that best balance the load at every free node (the least total
    force where several do)."""
    positions = np.asarray(positions, dtype=np.float64)
    active = _active_rows(problem, positions, tol)
    forces = _recovered_forces(problem, active, _decompose(problem, active), tol)
    return _to_multipliers(problem, active, forces)


def statics_of(solution: Solution, tol: float = DEFAULT_TOL) -> Statics:
    """:func:`statics` at a solver's result."""
    return statics(solution.problem, solution.positions, tol)


def proven_determinate(solution: Solution, tol: float = DEFAULT_TOL) -> bool:
    """Whether a solver's result is proven statically determinate (its forces unique) by the sparse
    proof alone: one Cholesky factorization, cheap at any size; False means not proven."""
    active = _active_rows(solution.problem, solution.positions, tol)
    found = _sparse_decomposition(solution.problem, active, search=False)
    return found is not None and found.rank == active.m
