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

from dataclasses import dataclass
from typing import Any

import numpy as np

from funicular._constraints import link_deltas, link_distances, norms
from funicular._forces import node_loads
from funicular.checks._tolerances import DEFAULT_TOL, RANK_TOL
from funicular.model import FloatArray, IntArray, Problem
from funicular.solution import Solution

DENSE_UP_TO = 4_000_000  # entries of J up to which its singular values are computed (dense)
RANGES_UP_TO = 300  # active constraints up to which each force's range is computed (two LPs each)
SELF_STRESS_SHOWN = 10  # self-stress states listed at most


@dataclass(frozen=True)
class Statics:
    """The active constraints of a net at a point, and whether their forces are unique.

    ``rank`` and everything after it are None where J is too large to decompose here.
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


def _active_rows(problem: Problem, positions: FloatArray, tol: float) -> tuple[list[str], _Rows]:
    """The active constraints' names and their rows in force units, over every node."""
    links = problem.link_nodes
    distances = link_distances(positions, problem.links)
    taut = np.flatnonzero(distances >= (1.0 - tol) * problem.link_lengths)
    names = [f"link {k}" for k in taut]
    unit = link_deltas(positions, problem.links)[taut] / np.maximum(distances[taut], 1e-300)[:, None]
    first, second, vectors = [links[taut, 0]], [links[taut, 1]], [unit]
    free = problem.free_nodes
    length = float(problem.link_lengths.max())
    for obstacle in problem.obstacles:
        phi, gradient, _ = obstacle.evaluate(positions[free])
        size = norms(gradient)
        touching = np.flatnonzero(phi / np.maximum(size, 1e-300) >= -tol * length)
        first.append(free[touching])
        second.append(np.full(touching.size, -1))  # a contact row has one node
        vectors.append(gradient[touching] / np.maximum(size[touching], 1e-300)[:, None])
        names.extend(f"{obstacle.name} at node {free[i]}" for i in touching)
    return names, _Rows(np.concatenate(first), np.concatenate(second), np.concatenate(vectors))


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


def _free_columns(problem: Problem) -> IntArray:
    d = problem.dimension
    return (problem.free_nodes[:, None] * d + np.arange(d)).ravel()


def statics(problem: Problem, positions: FloatArray, tol: float = DEFAULT_TOL) -> Statics:
    """The statics of ``problem`` at ``positions`` (see the module documentation)."""
    names, rows = _active_rows(problem, np.asarray(positions, dtype=np.float64), tol)
    m = len(names)
    if m == 0:
        return Statics((), 0, (), (), mfcq=True)
    if m * problem.free_nodes.size * problem.dimension > DENSE_UP_TO:
        return Statics(tuple(names), None, (), None)
    jacobian = rows.dense(problem.n_nodes)[:, _free_columns(problem)]
    left, sigma, _ = np.linalg.svd(jacobian, full_matrices=True)
    rank = int(np.count_nonzero(sigma > RANK_TOL * max(float(sigma[0]), 1e-300)))
    null = left[:, rank:]  # the self-stress states: J^T t = 0
    states = []
    for vector in null.T[:SELF_STRESS_SHOWN]:
        largest = float(np.max(np.abs(vector)))
        vector = vector / (largest if vector[np.argmax(np.abs(vector))] > 0 else -largest)
        states.append({names[r]: float(vector[r]) for r in np.flatnonzero(np.abs(vector) > 1e-9)})
    ranges = None
    if m <= RANGES_UP_TO:
        load = node_loads(problem).ravel()[_free_columns(problem)]
        ranges = _force_ranges(jacobian, load, rank, null)
    return Statics(tuple(names), rank, tuple(states), ranges, _no_tension_self_stress(null))


def _no_tension_self_stress(null: FloatArray) -> bool:
    """MFCQ (Gordan): no ``t = null y >= 0`` with ``sum(t) = 1`` (a linear program)."""
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
    )
    return bool(result.status == 2)  # infeasible: no such self-stress


def _force_ranges(
    jacobian: FloatArray, load: FloatArray, rank: int, null: FloatArray
) -> tuple[tuple[float, float], ...] | None:
    """Each force's smallest and largest value over ``J^T t = F`` with ``t >= 0``: its own
    value where the forces are unique, else two linear programs (HiGHS). None where the equations
    have no nonnegative solution (the point is not an equilibrium)."""
    from scipy.optimize import linprog

    m = jacobian.shape[0]
    forces, *_ = np.linalg.lstsq(jacobian.T, load, rcond=None)
    if null.shape[1] == 0:
        return tuple((float(t), float(t)) for t in forces)
    # t = forces + null y, t >= 0: bounds of each t_r over y
    ranges = []
    for r in range(m):
        bounds = []
        for sign in (1.0, -1.0):
            result = linprog(
                sign * null[r], A_ub=-null, b_ub=forces, bounds=[(None, None)] * null.shape[1], method="highs"
            )
            if result.status == 2:  # infeasible: no nonnegative forces balance the load
                return None
            if result.status == 3 or result.fun is None:  # unbounded
                bounds.append(-np.inf * sign)
            else:
                bounds.append(float(forces[r] + sign * result.fun))
        ranges.append((bounds[0], bounds[1]))
    return tuple(ranges)


def statics_of(solution: Solution, tol: float = DEFAULT_TOL) -> Statics:
    """:func:`statics` at a solver's result."""
    return statics(solution.problem, solution.positions, tol)
