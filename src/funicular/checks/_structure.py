"""The check of a net or a chain in space: the multipliers (given, or recovered from the positions
alone), the KKT residuals recomputed with them, the statics (LICQ as static determinacy, MFCQ, the
self-stress states, every force's range: :mod:`funicular.checks._statics`), and the second-order
verdict: the solver's own test at its result (the reduced Hessian on the solver's Newton matrix,
as the saddle escape uses it), the checker's (:func:`funicular.checks._second_order.structure_verdict`)
at any other point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from funicular._diagnostics import KKTResiduals, kkt_residuals, scaled
from funicular.checks._check import _as_multipliers, _check_tol
from funicular.checks._report import Multipliers, multiplier_lines
from funicular.checks._second_order import structure_verdict
from funicular.checks._statics import (
    Statics,
    _active_rows,
    _decompose,
    _recovered_forces,
    _statics,
    _to_forces,
    _to_multipliers,
)
from funicular.checks._tolerances import DEFAULT_TOL
from funicular.errors import ScenarioError
from funicular.model import FloatArray, Problem


@dataclass(frozen=True)
class StructureCheck:
    """What :func:`check_structure` finds. ``residuals`` are scaled (force / weight, length /
    longest link); ``second_order`` is a verdict in words."""

    residuals: KKTResiduals
    statics: Statics
    second_order: str
    tol: float
    multipliers: Multipliers
    multiplier_source: str  # "given" or "recovered"
    problem: Problem
    # the smallest curvature of the Hessian of the Lagrangian the checker's test found (force /
    # length, as the problem's units); None where none was found (the solver's verdict, a large net
    # proven a minimum)
    curvature: float | None = None

    @property
    def feasible(self) -> bool:
        return self.residuals.primal_feasibility <= self.tol

    @property
    def kkt_holds(self) -> bool:
        return self.residuals.max() <= self.tol

    def summary(self) -> str:
        r, s = self.residuals, self.statics
        lines = [
            f"  multipliers             {self.multiplier_source}",
            *multiplier_lines(self.problem, self.multipliers),
            f"  KKT residuals (scaled)  stationarity {r.stationarity:.2e}, primal {r.primal_feasibility:.2e}, "
            f"dual {r.dual_feasibility:.2e}, complementarity {r.complementarity:.2e}: "
            + ("a KKT point" if self.kkt_holds else f"NOT a KKT point at tol {self.tol:g}"),
            f"  active constraints      {s.active_constraints}",
        ]
        if s.rank is None:
            lines.append(
                "  LICQ                    not decided (not proven, and too many rows or self-stress states to search)"
            )
        elif s.holds:
            lines.append(
                f"  LICQ                    holds (rank {s.rank}): the forces are unique, statically determinate"
            )
        else:
            lines.append(
                f"  LICQ                    fails (rank {s.rank} of {s.active_constraints}): statically indeterminate "
                f"to degree {s.degree_of_indeterminacy}"
            )
            for k, state in enumerate(s.self_stress, start=1):
                shown = ", ".join(f"{name} {value:+.4g}" for name, value in state.items())
                lines.append(f"    self-stress {k}: {shown}")
        if s.mfcq is not None:
            lines.append(
                "  MFCQ                    "
                + ("holds: the forces are bounded" if s.mfcq else "fails: a pure tension self-stress, unbounded forces")
            )
        if s.ranges is not None and not s.holds:
            for name, (low, high) in zip(s.names, s.ranges, strict=True):
                if high - low > 1e-9 * max(1.0, abs(high)):
                    lines.append(f"    {name}: force in [{low:.6g}, {high:.6g}]")
        lines.append(f"  second order            {self.second_order}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "multipliers": {
                "source": self.multiplier_source,
                "link": self.multipliers.link.tolist(),
                "obstacle": {
                    o.name: nu.tolist() for o, nu in zip(self.problem.obstacles, self.multipliers.obstacle, strict=True)
                },
            },
            "kkt_scaled": self.residuals.as_dict(),
            "kkt_holds": self.kkt_holds,
            "feasible": self.feasible,
            "statics": self.statics.as_dict(),
            "second_order": self.second_order,
            "curvature": self.curvature,
            "tol": self.tol,
        }


def check_structure(
    problem: Problem,
    positions: FloatArray,
    multipliers: Multipliers | None = None,
    tol: float = DEFAULT_TOL,
    second_order: str | None = None,
    dense_up_to: int | None = None,
) -> StructureCheck:
    """The check of a point (N, d) of a net or a chain in space (see the module documentation).

    ``multipliers`` are in the problem's formulation, obstacle multipliers per node; if None they
    are recovered from the positions. ``second_order``: the solver's verdict at its own result
    (None: the checker's test decides, on dense matrices up to ``dense_up_to`` free coordinates,
    None: CURVATURE_UP_TO, and by the sparse penalty test above). Raises :class:`ScenarioError`
    for positions or multipliers of the wrong shape or not finite.
    """
    positions = np.asarray(positions, dtype=np.float64)
    shape = (problem.n_nodes, problem.dimension)
    if positions.shape != shape or not np.all(np.isfinite(positions)):
        raise ScenarioError(
            f"positions must be {shape[0]} finite points of {shape[1]} coordinates, got shape {positions.shape}."
        )
    _check_tol(tol)
    given = _as_multipliers(problem, multipliers)
    active = _active_rows(problem, positions, tol)
    decomposition = _decompose(problem, active)
    if given is None:
        forces = _recovered_forces(problem, active, decomposition, tol)
        used, source = _to_multipliers(problem, active, forces), "recovered"
    else:
        used, source = given, "given"
        forces = _to_forces(problem, active, used)
    nu = used.obstacle if problem.obstacles else None
    residuals = scaled(kkt_residuals(problem, positions, used.link, nu), problem)
    found = _statics(problem, active, decomposition)
    curvature = None
    if second_order is None:
        if residuals.primal_feasibility > tol:
            second_order = "undecided (the point is infeasible)"
        elif residuals.max() > tol:  # (second-order conditions are stated at a KKT point only)
            second_order = f"undecided (not a KKT point: its largest scaled residual is {residuals.max():.2e})"
        else:
            second_order, value = structure_verdict(problem, active, used, forces, found.holds, tol, dense_up_to)
            curvature = None if math.isnan(value) else value
    return StructureCheck(residuals, found, second_order, tol, used, source, problem, curvature)


def judged_check(problem: Problem, tol: float = DEFAULT_TOL) -> tuple[StructureCheck, str]:
    """funicular's own solution checked, with the solver's second-order test at it; and its status."""
    from funicular._solver.ipm import SolverOptions, _solve

    solution, curvature = _solve(problem, SolverOptions(), judge=True)
    if curvature is None:
        verdict = "undecided"
    elif curvature.minimum:
        verdict = "strict local minimum (the reduced Hessian is positive definite: the solver's test)"
    elif curvature.direction is not None:
        verdict = f"not a minimum: the energy curves down ({curvature.value:.3g}) along a feasible direction"
    else:
        verdict = "undecided"
    multipliers = Multipliers(solution.link_multipliers, solution.obstacle_multipliers)
    report = check_structure(problem, solution.positions, multipliers, tol, verdict)
    return report, solution.status.value
