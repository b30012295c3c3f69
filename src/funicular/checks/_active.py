"""A point evaluated once: its worst violation (if infeasible) and its active constraints."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from funicular._constraints import link_deltas, norms
from funicular.checks._report import ActiveSet, Violation
from funicular.checks._tolerances import DEFAULT_TOL
from funicular.model import FloatArray, IntArray, Problem
from funicular.solution import Solution


# ----------------------------------------------------------------- the point, evaluated once
@dataclass(frozen=True)
class _Point:
    """A point's geometry, evaluated once and shared by the violation check, the active set, the
    Jacobian and the Hessian (each obstacle is evaluated once per point, at the free nodes)."""

    problem: Problem
    positions: FloatArray
    free: IntArray  # the free nodes, ascending
    column: IntArray  # (N,): each node's position among the free nodes, -1 at supports
    delta: FloatArray  # (L, d): p_a - p_b of every link (a, b)
    distances: FloatArray  # (L,)
    phi: FloatArray  # (n_obstacles, n_free)
    gradient: FloatArray  # (n_obstacles, n_free, d)
    evaluated_hessian: FloatArray | None  # the obstacles' Hessians if evaluated with phi

    @cached_property
    def hessian(self) -> FloatArray:
        """The obstacles' Hessians (n_obstacles, n_free, d, d), evaluated here when the point came
        without them (the active set and the Jacobian rows do not need them)."""
        if self.evaluated_hessian is not None:
            return self.evaluated_hessian
        d = self.positions.shape[1]
        points = self.positions[self.problem.free_rows]
        hessians = [obstacle.evaluate(points)[2] for obstacle in self.problem.obstacles]
        return _stacked(hessians, (self.free.size, d, d))


def _columns(problem: Problem) -> tuple[IntArray, IntArray]:
    """The free nodes and each node's position among them (-1 at supports)."""
    free = problem.free_nodes
    column = np.full(problem.n_nodes, -1, dtype=np.intp)
    column[free] = np.arange(free.size)
    return free, column


def _evaluate(problem: Problem, positions: FloatArray) -> _Point:
    free, column = _columns(problem)
    delta = link_deltas(positions, problem.links)
    d = problem.dimension
    points = positions[problem.free_rows]
    evaluations = [obstacle.evaluate(points) for obstacle in problem.obstacles]
    phi, gradient, hessian = (
        _stacked([evaluation[i] for evaluation in evaluations], (free.size, *tail))
        for i, tail in enumerate(((), (d,), (d, d)))
    )
    distances = norms(delta)
    return _Point(problem, positions, free, column, delta, distances, phi, gradient, hessian)


def _point_of(solution: Solution) -> _Point:
    """A solver's result as a point, from what the solution has already evaluated (its link
    lengths and its obstacles' phi and gradient at every node): the result files' LICQ block and
    the document's forces then share one evaluation. Node contact only."""
    problem, positions = solution.problem, solution.positions
    free, column = _columns(problem)
    fields = solution.node_fields or []
    d = problem.dimension
    rows = problem.free_rows  # (views, not copies, where the free nodes are consecutive)
    phi = _stacked([field[0][rows] for field in fields], (free.size,))
    gradient = _stacked([field[1][rows] for field in fields], (free.size, d))
    delta = link_deltas(positions, problem.links)
    return _Point(problem, positions, free, column, delta, solution.link_distance, phi, gradient, None)


def _stacked(arrays: list[FloatArray], shape: tuple[int, ...]) -> FloatArray:
    """The arrays as one of shape (len(arrays), *shape); one array as it is, not copied (at a large
    chain each obstacle's evaluation is tens of MB)."""
    if len(arrays) == 1:
        return arrays[0].reshape(1, *shape)
    return np.stack(arrays) if arrays else np.empty((0, *shape))


# ----------------------------------------------------------------- feasibility and active set
def _contact_distances(problem: Problem, point: _Point) -> FloatArray:
    """``phi / |grad phi|`` (n_obstacles, N) at every node (supports: -inf)."""
    distance = np.full((len(problem.obstacles), problem.n_nodes), -np.inf)
    norm = norms(point.gradient.reshape(-1, point.gradient.shape[-1])).reshape(point.phi.shape)
    np.maximum(norm, 1e-300, out=norm)
    np.divide(point.phi, norm, out=norm)  # (in place: a large chain's arrays are tens of MB)
    distance[:, point.free] = norm
    return distance


def _worst_violation(problem: Problem, point: _Point, distance: FloatArray, length_tol: float) -> Violation | None:
    moved = point.positions[problem.support_nodes] - problem.support_positions
    offset = norms(moved)
    s = int(offset.argmax())
    over = point.distances - problem.link_lengths
    if problem.axial_stiffness is not None:  # (an elastic link may be any length: it stretches)
        over = np.where(problem.elastic, -np.inf, over)
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
