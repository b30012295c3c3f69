"""The check of a net or a chain in space: the KKT residuals recomputed from the point and its
multipliers, its statics (LICQ as static determinacy, MFCQ, the self-stress states, every force's
range: :mod:`funicular.checks._statics`), and the second-order verdict of the solver's own test
at its result (the reduced Hessian on the solver's Newton matrix, as the saddle escape uses it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from funicular._diagnostics import KKTResiduals, kkt_residuals, scaled
from funicular.checks._statics import Statics, statics
from funicular.checks._tolerances import DEFAULT_TOL
from funicular.model import FloatArray, Problem

NOT_JUDGED = "undecided (the second-order test runs at funicular's own solution, not at a point read from a file)"


@dataclass(frozen=True)
class StructureCheck:
    """What :func:`check_structure` finds. ``residuals`` are scaled (force / weight, length /
    longest link); ``second_order`` is a verdict in words."""

    residuals: KKTResiduals
    statics: Statics
    second_order: str
    tol: float

    @property
    def feasible(self) -> bool:
        return self.residuals.primal_feasibility <= self.tol

    @property
    def kkt_holds(self) -> bool:
        return self.residuals.max() <= self.tol

    def summary(self) -> str:
        r, s = self.residuals, self.statics
        lines = [
            f"  KKT residuals (scaled)  stationarity {r.stationarity:.2e}, primal {r.primal_feasibility:.2e}, "
            f"dual {r.dual_feasibility:.2e}, complementarity {r.complementarity:.2e}: "
            + ("a KKT point" if self.kkt_holds else f"NOT a KKT point at tol {self.tol:g}"),
            f"  active constraints      {s.active_constraints}",
        ]
        if s.rank is None:
            lines.append("  LICQ                    not decided (too large to decompose here)")
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
            "kkt_scaled": self.residuals.as_dict(),
            "kkt_holds": self.kkt_holds,
            "feasible": self.feasible,
            "statics": self.statics.as_dict(),
            "second_order": self.second_order,
            "tol": self.tol,
        }


def check_structure(
    problem: Problem,
    positions: FloatArray,
    link_multipliers: FloatArray,
    obstacle_multipliers: FloatArray | None,
    tol: float = DEFAULT_TOL,
    second_order: str = NOT_JUDGED,
) -> StructureCheck:
    """The check of a point of a net or a chain in space with its multipliers (see the module
    documentation); ``second_order`` the verdict, where the solver's test gave one."""
    nu = None if not problem.obstacles or obstacle_multipliers is None else np.asarray(obstacle_multipliers)
    residuals = scaled(kkt_residuals(problem, positions, link_multipliers, nu), problem)
    return StructureCheck(residuals, statics(problem, positions, tol), second_order, tol)


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
    report = check_structure(
        problem, solution.positions, solution.link_multipliers, solution.obstacle_multipliers, tol, verdict
    )
    return report, solution.status.value
