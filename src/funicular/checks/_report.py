"""What the checker reports: the active set, LICQ, MFCQ, multiplier ranges, second order, and their JSON."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from funicular._diagnostics import KKTResiduals, scaled
from funicular.model import FloatArray, IntArray, Problem

MAX_LISTED = 12  # multipliers of each kind listed in a summary


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

    def _multiplier_lines(self) -> list[str]:
        return [] if self.multipliers is None else multiplier_lines(self.problem, self.multipliers)

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
            lines += self._multiplier_lines()
            lines.append(
                f"  KKT residuals     stationarity {k.stationarity:.2e}, primal {k.primal_feasibility:.2e}, "
                f"dual {k.dual_feasibility:.2e}, complementarity {k.complementarity:.2e}"
                f" ({'a KKT point' if self.kkt_holds else 'NOT a KKT point'} at this tolerance)"
            )
        if self.licq is not None:
            licq = self.licq
            sigma = max(licq.sigma_min, 0.0) + 0.0  # (a singular value: never -0)
            lines.append(
                f"  LICQ              {'holds' if licq.holds else 'fails'}: rank {licq.rank} of "
                f"{licq.active_constraints} active constraints, smallest singular value {sigma:.3g}"
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


def multiplier_lines(problem: Problem, multipliers: Multipliers) -> list[str]:
    """The multipliers, as the problem's formulation has them (the first MAX_LISTED of each kind)."""
    link = multipliers.link
    listed = ", ".join(f"{value + 0.0:.6g}" for value in link[:MAX_LISTED])
    more = f", ... ({link.size} in all)" if link.size > MAX_LISTED else ""
    lines = [f"    link mu_k        [{listed}{more}]"]
    for obstacle, nu in zip(problem.obstacles, multipliers.obstacle, strict=True):
        nodes = np.flatnonzero(nu > 0)
        pairs = ", ".join(f"node {i}: {nu[i]:.6g}" for i in nodes[:MAX_LISTED])
        extra = f", ... ({nodes.size} in all)" if nodes.size > MAX_LISTED else ""
        lines.append(
            f"    nu of {obstacle.name!r}  {{{pairs}{extra}}}" if nodes.size else f"    nu of {obstacle.name!r}  all 0"
        )
    return lines


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
