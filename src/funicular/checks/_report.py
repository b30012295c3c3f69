"""What the checker reports: the active set, LICQ, the statics, MFCQ, multiplier ranges, second order,
and their JSON."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from funicular._diagnostics import KKTResiduals, scaled
from funicular._text import problem_shape
from funicular.checks._tolerances import RANGES_UP_TO, SELF_STRESS_SHOWN
from funicular.model import FloatArray, IntArray, Problem

MAX_LISTED = 12  # multipliers of each kind listed in a summary
DEPENDENCIES_SHOWN = 5  # dependencies listed in a summary
RANGES_SHOWN = 6  # force ranges listed in a summary


@dataclass(frozen=True)
class Multipliers:
    """Multipliers in the problem's formulation: ``link`` (one per link) and ``obstacle``
    (n_obstacles, N), per node."""

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
        """``link k`` and ``OBSTACLE at node i``, in the order of the Jacobian's rows."""
        links = [f"link {k}" for k in self.links]
        return links + [f"{problem.obstacles[j].name} at node {i}" for j, i in self.contacts]


@dataclass(frozen=True)
class Dependency:
    """A left null vector of the active Jacobian: forces in equilibrium with each other (a
    self-stress state).

    ``forces`` maps constraint names to their share (largest 1); ``support_reactions`` maps
    support nodes to the change of their reaction per unit of the combination (the support
    multipliers change by minus that).
    """

    forces: dict[str, float]
    support_reactions: dict[int, tuple[float, ...]]
    text: str


@dataclass(frozen=True)
class LICQ:
    """The rank of the active rows: ``holds`` and ``rank`` are None where it is not decided (a large
    net whose rows are not proven independent and whose dependencies are too many to seek);
    ``sigma_min`` is nan where it was not computed."""

    holds: bool | None
    rank: int | None
    active_constraints: int
    sigma_min: float
    dependencies: tuple[Dependency, ...]

    @property
    def degree_of_indeterminacy(self) -> int | None:
        """How many independent self-stress states the active constraints admit (0: the forces are
        unique); None where not decided."""
        return None if self.rank is None else self.active_constraints - self.rank

    @property
    def verdict(self) -> str:
        """LICQ in one line: holds or fails, the rank and the smallest singular value."""
        if self.rank is None:
            return (
                f"not decided: {self.active_constraints} active constraints, not proven independent, and too "
                "many dependencies to seek"
            )
        sigma = "not computed" if math.isnan(self.sigma_min) else f"{max(self.sigma_min, 0.0) + 0.0:.3g}"
        return (
            f"{'holds' if self.holds else 'fails'}: rank {self.rank} of {self.active_constraints} active "
            f"constraints, smallest singular value {sigma}"
        )

    @property
    def statics(self) -> str | None:
        """What LICQ means for the structure's forces (None where not decided)."""
        if self.rank is None:
            return None
        if self.holds:
            return "statically determinate: the forces are unique"
        return f"statically indeterminate to degree {self.degree_of_indeterminacy}: the forces are not unique"


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
    # (N, d), zero at supports: a unit direction of negative curvature along which every active
    # constraint stays active, when the verdict is "not a minimum".
    direction: FloatArray | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class Statics:
    """The active constraints of a structure at a point, and whether their forces are unique.

    ``rank`` and everything after it are None where it is not decided. ``self_stress``: a basis of
    the self-stress states (at most SELF_STRESS_SHOWN), each as the constraints it involves with
    their relative forces (the largest 1). ``ranges``: each active constraint's smallest and
    largest force over all equilibria, None where not computed (above RANGES_UP_TO active
    constraints, or where their linear programs take too long).
    """

    names: tuple[str, ...]
    rank: int | None
    self_stress: tuple[dict[str, float], ...]
    ranges: tuple[tuple[float, float], ...] | None
    # MFCQ: no self-stress is a pure tension (forces >= 0, not all zero); where one is, it can be
    # added to any equilibrium without bound, and the forces are unbounded. None: not decided.
    mfcq: bool | None = None
    # Where the structure is indeterminate and some links are elastic: whether their stiffness makes
    # the forces unique (every self-stress stretches an elastic link). None: nothing to decide.
    unique_with_stiffness: bool | None = None

    @property
    def verdict(self) -> str | None:
        """What the statics mean for the forces, in words (None where not decided)."""
        if self.rank is None:
            return None
        if self.holds:
            return "statically determinate: the forces are unique"
        degree = f"statically indeterminate to degree {self.degree_of_indeterminacy}"
        if self.unique_with_stiffness:
            return f"{degree}; with the links' axial stiffness the forces are unique (those reported)"
        if self.unique_with_stiffness is False:
            return f"{degree}: even with the elastic links' stiffness the forces are not unique"
        return f"{degree}: the forces are not unique"

    @classmethod
    def found(
        cls,
        names: list[str],
        licq: LICQ,
        ranges: tuple[FloatArray, FloatArray, IntArray] | None,
        mfcq: MFCQ | None,
        unique_with_stiffness: bool | None = None,
    ) -> Statics:
        """LICQ's findings in the words of a structure: its self-stress states (the dependencies, at
        most SELF_STRESS_SHOWN) and every force's range (``ranges``: all lower and upper bounds, and
        the forces that vary; listed up to RANGES_UP_TO active constraints)."""
        states = tuple(d.forces for d in licq.dependencies[:SELF_STRESS_SHOWN])
        listed = None
        if ranges is not None and len(names) <= RANGES_UP_TO:
            listed = tuple((float(low), float(high)) for low, high in zip(ranges[0], ranges[1], strict=True))
        return cls(tuple(names), licq.rank, states, listed, None if mfcq is None else mfcq.holds, unique_with_stiffness)

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
        """The ``licq`` block of a net's result file (and the ``statics`` block of a check)."""
        return {
            "holds": self.holds,
            "rank": self.rank,
            "active_constraints": self.active_constraints,
            "degree_of_indeterminacy": self.degree_of_indeterminacy,
            "mfcq": self.mfcq,
            "unique_with_stiffness": self.unique_with_stiffness,
            "self_stress": [dict(state) for state in self.self_stress],
            "force_ranges": None
            if self.ranges is None
            else {name: list(bounds) for name, bounds in zip(self.names, self.ranges, strict=True)},
        }


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
    statics: Statics | None = None  # the same findings as a structure's: names, self-stress states, every range

    @property
    def kkt_holds(self) -> bool:
        return self.kkt is not None and scaled(self.kkt, self.problem).max() <= self.tolerance

    def to_dict(self) -> dict[str, Any]:
        p = self.problem
        return {
            "name": p.name,
            "nodes": p.n_nodes,
            "links": p.n_links,
            "dimension": p.dimension,
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
            "statics": None if self.statics is None else self.statics.as_dict(),
            "mfcq": None if self.mfcq is None else vars(self.mfcq),
            "multiplier_ranges": None if self.multiplier_ranges is None else [vars(r) for r in self.multiplier_ranges],
            "second_order": None if self.second_order is None else vars(self.second_order),
            "seconds": self.seconds,
        }

    def summary(self) -> str:
        p = self.problem
        lines = [f"{p.name}: {problem_shape(p)}, {p.formulation.value} formulation, tolerance {self.tolerance:g}"]
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
            if self.multipliers is not None:
                lines += multiplier_lines(p, self.multipliers)
            lines.append(
                f"  KKT residuals     stationarity {k.stationarity:.2e}, primal {k.primal_feasibility:.2e}, "
                f"dual {k.dual_feasibility:.2e}, complementarity {k.complementarity:.2e}"
                f" ({'a KKT point' if self.kkt_holds else 'NOT a KKT point'} at this tolerance)"
            )
        if self.licq is not None:
            lines += _licq_lines(self.licq, self.statics)
        if self.mfcq is not None:
            lines.append(f"  MFCQ              {'holds' if self.mfcq.holds else 'fails'}: {self.mfcq.reason}")
        stiffness_decides = self.statics is not None and self.statics.unique_with_stiffness
        if self.multiplier_ranges and not stiffness_decides:  # (the ranges of rigid links' forces)
            ranges = self.multiplier_ranges
            shown = ", ".join(f"{r.constraint} in [{r.min:.6g}, {r.max:.6g}]" for r in ranges[:RANGES_SHOWN])
            more = f" and {len(ranges) - RANGES_SHOWN} more" if len(ranges) > RANGES_SHOWN else ""
            lines.append(f"  force ranges      {shown}{more}; the other forces are determined")
        if self.second_order is not None:
            so = self.second_order
            lines.append(f"  second order      {so.verdict}: {so.reason}")
        lines.append(f"  checked in        {self.seconds:.3g} s")
        return "\n".join(lines)


def _licq_lines(licq: LICQ, statics: Statics | None) -> list[str]:
    """LICQ, its dependencies in words, and what it means for the structure's forces."""
    lines = [f"  LICQ              {licq.verdict}"]
    lines += [f"                    {d.text}" for d in licq.dependencies[:DEPENDENCIES_SHOWN]]
    meaning = licq.statics if statics is None or statics.verdict is None else statics.verdict
    if meaning is not None:
        lines.append(f"  statics           {meaning}")
    return lines


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
    """The ``licq`` block of the JSON documents (``check`` and a planar chain's ``solve --json``)."""
    return {
        "holds": licq.holds,
        "rank": licq.rank,
        "active_constraints": licq.active_constraints,
        "sigma_min": None if math.isnan(licq.sigma_min) else licq.sigma_min,
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
