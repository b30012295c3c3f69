"""The checker's entry points: the full check of a point of any problem, and the pieces a solve
needs of it."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from funicular._diagnostics import KKTResiduals, kkt_residuals, scaled
from funicular._forces import node_loads
from funicular.checks._active import _active, _contact_distances, _evaluate, _Point, _point_of, _worst_violation
from funicular.checks._jacobian import (
    _Hessian,
    _hessian,
    _jacobian,
    _row_scales,
    _Rows,
    as_stiffness,
    elastic_rows,
    elastic_tensions,
)
from funicular.checks._licq import _licq, _mfcq, _null
from funicular.checks._multipliers import _ranges, _recover
from funicular.checks._report import (
    LICQ,
    ActiveSet,
    CheckReport,
    MultiplierRange,
    Multipliers,
    SecondOrder,
    Statics,
    Violation,
)
from funicular.checks._second_order import _proves_minimum, _second_order
from funicular.checks._tolerances import DEFAULT_TOL
from funicular.errors import ScenarioError, shown
from funicular.model import FloatArray, Problem
from funicular.solution import Solution


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


def refuse_unchecked(problem: Problem) -> None:
    """Raise :class:`ScenarioError` for what the check does not cover (``contact = "links"`` with
    obstacles), so that a caller can say so before it solves."""
    if _links_mode(problem):
        raise ScenarioError(LINKS_NOT_CHECKED)


def _check_tol(tol: object) -> None:
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < 1:
        raise ScenarioError(f"tol = {shown(tol)} must be a number between 0 and 1.")


def free_load(problem: Problem) -> FloatArray:
    """The applied load (weights and point loads) over the free coordinates, ``-grad E``: what the
    active forces balance (stationarity reads ``A^T t = -grad E``)."""
    return np.asarray(node_loads(problem)[problem.free_nodes].ravel())


@dataclass(frozen=True)
class _Linearization:
    """The active constraints at a feasible point and their Jacobian rows on the free coordinates
    (and each row's scale, when asked: the LICQ block of a result file needs the rows only)."""

    problem: Problem
    point: _Point
    active: ActiveSet
    rows: _Rows

    @cached_property
    def scale(self) -> FloatArray:
        return _row_scales(self.problem, self.point, self.active)


def _point_at(problem: Problem, solution: Solution) -> _Point:
    """``solution``'s point evaluated for ``problem``: from what the solution has evaluated where
    it is the solution of this very problem, else afresh."""
    return _point_of(solution) if problem is solution.problem else _evaluate(problem, solution.positions)


def _linearized(problem: Problem, point: _Point, tol: float) -> Violation | _Linearization:
    """The worst violation if the point is infeasible, else the active constraints linearized."""
    distance = _contact_distances(problem, point)
    length_tol = tol * float(problem.link_lengths.max())
    violation = _worst_violation(problem, point, distance, length_tol)
    if violation is not None:
        return violation
    return _active_rows(problem, point, distance, length_tol)


def _active_rows(problem: Problem, point: _Point, distance: FloatArray, length_tol: float) -> _Linearization:
    active = _active(problem, point, distance, length_tol)
    return _Linearization(problem, point, active, _jacobian(problem, point, active))


def _positions(problem: Problem, positions: FloatArray) -> FloatArray:
    positions = np.asarray(positions, dtype=np.float64)
    shape = (problem.n_nodes, problem.dimension)
    if positions.shape != shape or not np.all(np.isfinite(positions)):
        axes = ", ".join("xyz"[: problem.dimension])
        raise ScenarioError(f"positions must be {shape[0]} finite ({axes}) points, got shape {positions.shape}.")
    return positions


def not_a_kkt_point(problem: Problem, kkt: KKTResiduals, tol: float) -> SecondOrder | None:
    """The verdict "undecided" at a point whose scaled KKT residuals exceed ``tol`` (second-order
    conditions are stated at a KKT point only); None at a KKT point."""
    worst = scaled(kkt, problem).max()
    if worst > tol:
        return SecondOrder("undecided", math.nan, f"not a KKT point: its largest scaled residual is {worst:.2e}")
    return None


def check(
    problem: Problem,
    positions: FloatArray,
    multipliers: Multipliers | None = None,
    tol: float = DEFAULT_TOL,
) -> CheckReport:
    """Diagnose ``positions`` (N, d) of any problem, a chain or a net, in the plane or in space:
    feasibility, active set, multipliers, KKT, LICQ and the statics, MFCQ, force ranges, second order.

    ``multipliers`` are in the problem's formulation (obstacle multipliers per node); if None they
    are recovered from the positions. Raises :class:`ScenarioError` for positions or multipliers of
    the wrong shape or not finite, and for ``contact = "links"`` with obstacles (not checked yet).
    """
    started = time.perf_counter()
    refuse_unchecked(problem)
    positions = _positions(problem, positions)
    _check_tol(tol)
    given = _as_multipliers(problem, multipliers)
    source = "none" if given is None else "given"
    linear = _linearized(problem, _evaluate(problem, positions), tol)
    if isinstance(linear, Violation):
        kkt = None if given is None else kkt_residuals(problem, positions, given.link, given.obstacle)
        elapsed = time.perf_counter() - started
        return CheckReport(problem, tol, False, linear, None, given, source, kkt, None, None, None, None, elapsed)
    active, rows, scale = linear.active, linear.rows, linear.scale
    licq, null = _licq(problem, linear.point, active, rows)
    mfcq = _mfcq(null)
    if given is None:
        forces = recovered_forces(problem, linear.point, active, rows, null, tol)
        used, source = _to_multipliers(problem, active, forces, scale), "recovered"
    else:
        used, forces = given, _to_forces(active, given, scale)
    kkt = kkt_residuals(problem, positions, used.link, used.obstacle if problem.obstacles else None)
    names = active.names(problem)
    ranges = None if null is None else _ranges(forces, null, problem.force_scale)
    varying = None
    if ranges is not None:
        lower, upper, moving = ranges
        varying = tuple(MultiplierRange(names[k], float(lower[k]), float(upper[k])) for k in moving)
    second = not_a_kkt_point(problem, kkt, tol)
    if second is None:
        hessian, kept = as_stiffness(problem, active, _hessian(problem, linear.point, used), rows)
        soft = kept.size < rows.m  # (elastic rows: their dependencies with the others no longer count)
        kept_null = None if soft or null is None else null
        second = _second_order(problem, linear.point, hessian, rows.take(kept), forces[kept], kept_null, tol)
    statics = Statics.found(names, licq, ranges, mfcq, stiffness_decides(null, elastic_rows(problem, active)))
    elapsed = time.perf_counter() - started
    return CheckReport(
        problem, tol, True, None, active, used, source, kkt, licq, mfcq, varying, second, elapsed, statics
    )


def recover_multipliers(problem: Problem, positions: FloatArray, tol: float = DEFAULT_TOL) -> Multipliers:
    """Multipliers that best satisfy stationarity at ``positions`` (nonnegative, least total force
    where several do), for any problem."""
    point = _evaluate(problem, _positions(problem, positions))
    linear = _active_rows(problem, point, _contact_distances(problem, point), tol * float(problem.link_lengths.max()))
    rows = linear.rows
    forces = recovered_forces(problem, linear.point, linear.active, rows, _null(rows), tol)
    return _to_multipliers(problem, linear.active, forces, linear.scale)


def recovered_forces(
    problem: Problem, point: _Point, active: ActiveSet, rows: _Rows, null: FloatArray | None, tol: float
) -> FloatArray:
    """The active rows' forces recovered from stationarity: an elastic link's as its stretch
    decides it, the others the nonnegative ones that best balance the rest of the load (the least
    total force where several do; ``null``: all the rows' dependencies, if known)."""
    soft = elastic_rows(problem, active)
    tiny = tol * problem.force_scale
    if not soft.any():
        return _recover(rows.sparse(), free_load(problem), null, tiny)
    forces = np.empty(rows.m)
    forces[soft] = elastic_tensions(problem, point, active)
    stiff = rows.take(np.flatnonzero(~soft))
    rest = free_load(problem) - rows.take(np.flatnonzero(soft)).sparse().T @ forces[soft]
    forces[~soft] = _recover(stiff.sparse(), rest, _null(stiff), tiny)
    return forces


def stiffness_decides(null: FloatArray | None, soft: NDArray[np.bool_]) -> bool | None:
    """Whether the links' stiffness makes indeterminate forces unique: no self-stress (a column
    combination of ``null``) leaves every elastic row (``soft``) unstretched. None where there is
    nothing to decide (no elastic row, or the forces unique already) or the dependencies are not known."""
    if null is None or null.shape[1] == 0 or not soft.any():
        return None
    part = null[soft]
    if part.shape[0] < part.shape[1]:
        return False
    values = np.linalg.svd(part, compute_uv=False)
    return bool(values.min() > 1e-8 * max(values.max(), 1e-300))


def check_solution(solution: Solution, tol: float = DEFAULT_TOL) -> CheckReport:
    """:func:`check` of a solver's result, with the solver's multipliers."""
    problem = solution.problem
    refuse_unchecked(problem)
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
    linear = _linearized(problem, _point_at(problem, solution), tol)
    if isinstance(linear, Violation):
        return SecondOrder("undecided", math.nan, f"infeasible: {linear.text}")
    forces = _to_forces(linear.active, multipliers, linear.scale)
    hessian, kept = as_stiffness(problem, linear.active, _hessian(problem, linear.point, multipliers), linear.rows)
    return linear.point, hessian, linear.rows.take(kept), forces[kept]


def second_order(problem: Problem, solution: Solution, tol: float = DEFAULT_TOL, proof: bool = False) -> SecondOrder:
    """The second-order verdict at a solver's result ("undecided" at an infeasible point), for any
    problem: the check's own test, on the returned positions and multipliers.

    With ``proof``, the cheap sufficient test of :func:`proves_strict_minimum` comes first: where
    it proves a strict local minimum, that is the verdict, without the curvature
    (``min_eigenvalue`` nan) or the eigenvalue problem it costs.
    """
    # Only what the verdict needs (the full check also runs MFCQ and the multiplier ranges, linear
    # programs that cost far more than the solve for a small chain).
    at = _at_solution(problem, solution, tol)
    if isinstance(at, SecondOrder):
        return at
    point, hessian, rows, forces = at
    return _second_order(problem, point, hessian, rows, forces, None, tol, proof)


def proves_strict_minimum(problem: Problem, solution: Solution, tol: float = DEFAULT_TOL) -> bool:
    """A cheap sufficient test: True only where :func:`second_order` says "strict local minimum"
    (one sparse Cholesky factorization, O(N) for a chain; no eigenvalue, no direction); False
    where it is not proven, which the full check then decides."""
    at = _at_solution(problem, solution, tol)
    if isinstance(at, SecondOrder):
        return False
    _, hessian, rows, forces = at
    return _proves_minimum(problem, hessian, rows, forces, tol)


def licq_of(solution: Solution, tol: float = DEFAULT_TOL) -> LICQ | None:
    """LICQ at a solver's result (None if the point is infeasible or ``contact = "links"``, not checked
    yet): the ``licq`` block of a planar chain's ``solve --json``."""
    problem = solution.problem
    if _links_mode(problem):
        return None
    linear = _linearized(problem, _point_of(solution), tol)
    return None if isinstance(linear, Violation) else _licq(problem, linear.point, linear.active, linear.rows)[0]
