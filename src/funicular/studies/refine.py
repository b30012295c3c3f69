"""``funicular study refine``: one chain at growing N in both formulations, against exact answers.

Every N keeps the scenario's total mass and length (``Problem.with_nodes``: N equal masses M/N,
N-1 equal links L/(N-1)). Each N is solved in the ``norm`` form (multiplier = tension, a force)
and the ``squared`` form (multiplier = tension / (2 d_k), a force per length). Exact answers:

* **dangling chain** (one support, at node 0, no obstacle): tension ``M g (N-1-k)/N`` and squared
  multiplier ``M g (N-1-k)(N-1) / (2 N L)`` in link k (the seed's 1-based ``M g (N-k)/N`` and
  ``M g (N-k)(N-1)/(2 N L)``); the continuous limit is the rope tension ``M g (L - s)/L``.
* **catenary** (supports at node 0 and node N-1, the first on the left, no obstacle): the discrete
  catenary (:func:`funicular.studies.catenary.discrete_catenary`) for each N, and the continuous
  catenary of weight ``M g / L`` per length as N -> infinity.

Errors against the continuous limit: energy ``|E_N - E| / (M g L)``; tension
``max_k |T_k - T(s_k)| / (M g)`` at the link midpoints ``s_k``; position ``max_i |p_i - p(s_i)| / L``
at the nodes' arclengths. Observed orders are least-squares slopes of log(error) against
log(N - 1) (the mesh size is L/(N-1)) over the last ``FIT_POINTS`` N.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from funicular._progress import Advance, no_progress
from funicular._solver import solve
from funicular._units import force_unit, label, length_unit, unit, with_unit
from funicular.errors import ScenarioError
from funicular.model import FloatArray, Problem
from funicular.plot import save_figure
from funicular.solution import Solution
from funicular.studies import TINY_ERROR, format_number, format_table, loglog_slope
from funicular.studies.catenary import ContinuousCatenary, dangling_chain, dangling_rope_tension, discrete_catenary

DEFAULT_NODES = (3, 5, 9, 17, 33, 65, 129)
# What each error against the continuous limit is divided by (see the module docstring), as the
# table's headers, its caption and the JSON name it: a number without units, the same in any.
ERROR_SCALES = {"energy": "M g L", "tension": "M g", "position": "L"}
ERRORS_CAPTION = (
    "errors against the continuous limit, divided by a scale so that they have no units: "
    "|E_N - E| / (M g L), max |T_k - T(s_k)| / (M g), max |p_i - p(s_i)| / L"
)
FIT_POINTS = 3  # observed orders: slope over the last three N
PROFILE_CURVES = 4  # tension profiles drawn in the plot
SEED_NOTE = (
    "The seed's closed forms drop the factor (N-1)/N: it gives M g (N-1)/(2L) for the top squared multiplier "
    "and M g for the top tension; the exact values are M g (N-1)^2/(2 N L) and M g (N-1)/N."
)
LUMPING_NOTE = (
    "with_nodes puts mass M/N on every node, the support nodes too, so only M (N-2)/N hangs between them: "
    "tensions and energy converge at order 1, positions (which depend only on the mass ratios) at order 2; "
    "end masses M/(2(N-1)) and inner masses M/(N-1) would make the energy converge at order 2."
)


@dataclass(frozen=True)
class Exact:
    """Exact discrete multipliers for one N: norm-form tensions and squared-form multipliers."""

    tension: FloatArray
    squared_multipliers: FloatArray


@dataclass(frozen=True)
class Limit:
    """The continuous rope (N -> infinity), as functions of the arclength s from node 0."""

    description: str
    tension: Callable[[FloatArray], FloatArray]
    position: Callable[[FloatArray], FloatArray]
    energy: float


@dataclass(frozen=True)
class RefineRow:
    """The results for one N (forces from the norm solve unless named ``squared``)."""

    nodes: int
    status: str
    squared_max: float
    squared_min: float
    tension_max: float
    tension_min: float
    energy: float
    reactions: FloatArray  # (S, 2)
    exact_tension_max: float | None = None
    exact_squared_max: float | None = None
    exact_error: float | None = None  # largest relative error of any multiplier, both forms
    energy_error: float | None = None  # against the continuous limit, see the module docstring
    tension_error: float | None = None
    position_error: float | None = None
    link_midpoints: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)
    tension: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def exact_columns(self) -> tuple[float | None, float | None, float | None]:
        return self.exact_tension_max, self.exact_squared_max, self.exact_error

    def as_dict(self) -> dict[str, Any]:
        return {
            "nodes": self.nodes,
            "status": self.status,
            "squared_multiplier_max": self.squared_max,
            "squared_multiplier_min": self.squared_min,
            "tension_max": self.tension_max,
            "tension_min": self.tension_min,
            "energy": self.energy,
            "support_reactions": self.reactions.tolist(),
            "exact_tension_max": self.exact_tension_max,
            "exact_squared_multiplier_max": self.exact_squared_max,
            "exact_relative_error": self.exact_error,
            "continuous_energy_error": self.energy_error,
            "continuous_tension_error": self.tension_error,
            "continuous_position_error": self.position_error,
        }


@dataclass(frozen=True)
class RefineStudy:
    problem: Problem
    reference: str  # which exact answers apply, or why none does
    rows: list[RefineRow]
    limit: Limit | None
    notes: list[str]

    @property
    def orders(self) -> dict[str, float | None]:
        """Observed slopes: growth of the largest multipliers, order of the errors (see module docstring)."""
        links = [row.nodes - 1 for row in self.rows]

        def order(values: list[float | None]) -> float | None:
            slope = loglog_slope(links, values, FIT_POINTS, floor=TINY_ERROR)
            return None if slope is None else -slope

        return {
            "squared_multiplier_max_growth": loglog_slope(links, [r.squared_max for r in self.rows], FIT_POINTS),
            "tension_max_growth": loglog_slope(links, [r.tension_max for r in self.rows], FIT_POINTS),
            "continuous_energy_error_order": order([r.energy_error for r in self.rows]),
            "continuous_tension_error_order": order([r.tension_error for r in self.rows]),
            "continuous_position_error_order": order([r.position_error for r in self.rows]),
        }

    def as_dict(self) -> dict[str, Any]:
        return {
            "scenario": self.problem.name,
            "total_mass": self.problem.total_mass,
            "total_length": self.problem.total_length,
            "gravity": self.problem.gravity,
            "reference": self.reference,
            "continuous_limit": None if self.limit is None else self.limit.description,
            "fit": f"least-squares slope of log(value) against log(N - 1) over the last {FIT_POINTS} N",
            "continuous_error_scales": ERROR_SCALES,
            "rows": [row.as_dict() for row in self.rows],
            "orders": self.orders,
            "notes": self.notes,
        }


# --------------------------------------------------------------------------- exact answers
def reference_kind(problem: Problem) -> tuple[str, str]:
    """``("dangling" | "catenary" | "", description)`` of the exact answers this problem has."""
    if problem.obstacles:
        return "", "none (obstacles: no closed form)"
    nodes = problem.support_nodes.tolist()
    last = problem.n_nodes - 1
    if nodes == [0]:
        return "dangling", "dangling chain: exact M g (N-1-k)/N; continuous rope M g (L - s)/L"
    if nodes == [0, last]:
        (xl, yl), (xr, yr) = problem.support_positions
        if not xr > xl:
            return "", "none (the catenary needs the node-0 support strictly left of the last one)"
        if not math.hypot(xr - xl, yr - yl) < problem.total_length:
            return "", "none (the chain is not longer than the distance between its supports)"
        return "catenary", "discrete catenary (exact, per N); continuous catenary as N -> infinity"
    return "", "none (exact answers exist for one support at node 0, or supports at both ends)"


def continuous_limit(problem: Problem) -> Limit | None:
    """The continuous rope the chain tends to, or None."""
    kind, _ = reference_kind(problem)
    mass, length, g = problem.total_mass, problem.total_length, problem.gravity
    length_symbol = length_unit(problem)
    if kind == "dangling":
        top = problem.support_positions[0]

        def hanging(s: FloatArray) -> FloatArray:
            return np.column_stack([np.full_like(s, top[0]), top[1] - s])

        return Limit(
            description=f"uniform rope hanging from {with_unit(f'({top[0]:g}, {top[1]:g})', length_symbol)}: "
            "T(s) = M g (L - s)/L",
            tension=lambda s: dangling_rope_tension(s, mass, length, g),
            position=hanging,
            energy=g * mass * (float(top[1]) - 0.5 * length),
        )
    if kind == "catenary":
        left, right = problem.support_positions
        rope = ContinuousCatenary.between(left, right, length, g * mass / length)
        return Limit(
            description=f"continuous catenary, a = {with_unit(f'{rope.a:.6g}', length_symbol)}, "
            f"H = {with_unit(f'{rope.horizontal_force:.6g}', force_unit(problem))}",
            tension=rope.tension_at_arclength,
            position=rope.position_at_arclength,
            energy=rope.energy(mass, g),
        )
    return None


def exact_answer(problem: Problem) -> Exact | None:
    """The exact discrete answer for this N, or None (no closed form, or a link hangs slack)."""
    kind, _ = reference_kind(problem)
    n, g = problem.n_nodes, problem.gravity
    if kind == "dangling":
        chain = dangling_chain(n, problem.total_mass, problem.total_length, g)
        return Exact(chain.tension, chain.squared_multipliers)
    if kind == "catenary" and n >= 3:
        left, right = problem.support_positions
        try:
            catenary = discrete_catenary(problem.masses, problem.link_lengths, g, left, right)
        except ScenarioError:  # too few nodes: a link hangs slack
            return None
        return Exact(catenary.tension, catenary.tension / (2.0 * problem.link_lengths))
    return None


# --------------------------------------------------------------------------- the study
def _relative_error(values: FloatArray, exact: FloatArray) -> float:
    return float(np.max(np.abs(values - exact) / np.abs(exact), initial=0.0))


def _status(norm: Solution, squared: Solution) -> str:
    if norm.converged and squared.converged:
        return "optimal"
    return f"norm {norm.status.value}, squared {squared.status.value}"


def refine_row(problem: Problem, nodes: int, limit: Limit | None, tol: float) -> RefineRow:
    """Solve ``problem.with_nodes(nodes)`` in both formulations and compare with the exact answers."""
    chain = problem.with_nodes(nodes)
    norm = solve(chain.with_formulation("norm"), tol=tol)
    squared = solve(chain.with_formulation("squared"), tol=tol)
    arclength = np.concatenate(([0.0], np.cumsum(chain.link_lengths)))
    midpoints = arclength[:-1] + 0.5 * chain.link_lengths
    row: dict[str, Any] = {}
    exact = exact_answer(chain)
    if exact is not None:
        row["exact_tension_max"] = float(exact.tension.max())
        row["exact_squared_max"] = float(exact.squared_multipliers.max())
        row["exact_error"] = max(
            _relative_error(norm.link_multipliers, exact.tension),
            _relative_error(squared.link_multipliers, exact.squared_multipliers),
        )
    if limit is not None:
        weight, length = chain.weight, chain.total_length
        row["energy_error"] = abs(norm.objective - limit.energy) / (weight * length)
        row["tension_error"] = float(np.max(np.abs(norm.link_tension - limit.tension(midpoints)))) / weight
        offsets = np.linalg.norm(norm.positions - limit.position(arclength), axis=1)
        row["position_error"] = float(offsets.max()) / length
    return RefineRow(
        nodes=nodes,
        status=_status(norm, squared),
        squared_max=float(squared.link_multipliers.max()),
        squared_min=float(squared.link_multipliers.min()),
        tension_max=float(norm.link_tension.max()),
        tension_min=float(norm.link_tension.min()),
        energy=norm.objective,
        reactions=norm.support_reactions,
        link_midpoints=midpoints,
        tension=norm.link_tension,
        **row,
    )


def refine(problem: Problem, nodes: list[int], tol: float = 1e-10, *, on_solve: Advance = no_progress) -> RefineStudy:
    """The refinement study of ``problem`` at each N in ``nodes`` (sorted, duplicates dropped).

    ``on_solve(2)`` is called after each N, solved in both formulations (a progress bar).
    """
    if not problem.is_chain:
        why = (
            "an elastic chain's continuous limit is not computed"
            if problem.links is None and problem.axial_stiffness is not None
            else "a net has no N to refine"
        )
        raise ScenarioError(
            f"{problem.name}: study refine refines an inextensible chain (N -> infinity, its length and mass "
            f"kept); {why}."
        )
    counts = sorted(set(nodes))
    kind, reference = reference_kind(problem)
    limit = continuous_limit(problem)
    notes = []
    if kind == "dangling":
        notes.append(SEED_NOTE)
    if kind == "catenary":
        notes.append(LUMPING_NOTE)
    rows = []
    for n in counts:
        rows.append(refine_row(problem, n, limit, tol))
        on_solve(2)
    return RefineStudy(problem=problem, reference=reference, rows=rows, limit=limit, notes=notes)


# --------------------------------------------------------------------------- output
def multiplier_columns(study: RefineStudy) -> tuple[list[str], list[list[object]]]:
    """Headers and rows of the multiplier table: both forms' extremes against the exact values (with
    their units where the scenario declares them)."""
    force, per_length = force_unit(study.problem), unit(study.problem, "force_per_length")
    headers = ["N", "status", label("squared mu max", per_length), label("squared mu min", per_length)]
    headers += [label("tension max", force), label("tension min", force)]
    headers += [label("exact T max", force), label("exact mu max", per_length), "rel. error"]
    rows: list[list[object]] = [
        [r.nodes, r.status, r.squared_max, r.squared_min, r.tension_max, r.tension_min, *r.exact_columns]
        for r in study.rows
    ]
    return headers, rows


def convergence_columns(study: RefineStudy) -> tuple[list[str], list[list[object]]]:
    """Headers and rows of the convergence table: energy, reactions, errors against the continuous limit."""
    supports = range(study.problem.support_nodes.size)
    axes = "xyz"[: study.problem.dimension]
    force = force_unit(study.problem)
    headers = ["N", label("energy", unit(study.problem, "energy"))]
    headers += [label(f"R{j} {axis}", force) for j in supports for axis in axes]
    headers += [f"{name} err / {scale if ' ' not in scale else f'({scale})'}" for name, scale in ERROR_SCALES.items()]
    rows: list[list[object]] = [
        [r.nodes, r.energy, *r.reactions.ravel().tolist(), r.energy_error, r.tension_error, r.position_error]
        for r in study.rows
    ]
    return headers, rows


def study_text(study: RefineStudy) -> str:
    """The whole study as printed by the command line."""
    p = study.problem
    mass = with_unit(f"{p.total_mass:g}", unit(p, "mass"))
    length = with_unit(f"{p.total_length:g}", length_unit(p))
    gravity = with_unit(f"{p.gravity:g}", unit(p, "gravity"))
    lines = [
        f"{p.name}: refinement at M = {mass}, L = {length}, g = {gravity} "
        "(both formulations; forces, energy and reactions from the norm form)",
        f"  exact answers: {study.reference}",
        "",
        format_table(*multiplier_columns(study)),
        "",
        format_table(*convergence_columns(study)),
        "",
        "  R{j}: reaction of the j-th support (in node order) on the chain",
        f"  {ERRORS_CAPTION}",
        f"  observed slopes (log-log against N-1, last {FIT_POINTS} N):",
    ]
    lines += [f"    {name:<34} {format_number(value, 4)}" for name, value in study.orders.items()]
    lines += [f"  note: {note}" for note in study.notes]
    return "\n".join(lines)


def draw_study(study: RefineStudy, figure: Any) -> None:
    """Two panels on ``figure``: largest multipliers against N (log-log), tension profiles along the chain."""
    rows = study.rows
    nodes = np.array([r.nodes for r in rows], dtype=np.float64)
    growth, profiles = figure.subplots(1, 2)
    orders = study.orders
    squared_slope = format_number(orders["squared_multiplier_max_growth"], 3)
    tension_slope = format_number(orders["tension_max_growth"], 3)
    # (the two multipliers differ in units, so each curve's label carries its own)
    squared = label("squared: max mu", unit(study.problem, "force_per_length"))
    norm = label("norm: max T", force_unit(study.problem))
    growth.loglog(nodes, [r.squared_max for r in rows], "o-", label=f"{squared} (slope {squared_slope})")
    growth.loglog(nodes, [r.tension_max for r in rows], "s-", label=f"{norm} (slope {tension_slope})")
    exact_mu = [r.exact_squared_max for r in rows]
    if all(value is not None for value in exact_mu):
        growth.loglog(nodes, exact_mu, "k:", label="exact")
        growth.loglog(nodes, [r.exact_tension_max for r in rows], "k:")
    growth.set_xlabel("N (nodes)")
    growth.set_ylabel("largest multiplier")
    growth.set_title("multipliers as N grows (M, L fixed)")
    growth.legend(fontsize=8)
    picks = sorted({int(i) for i in np.linspace(0, len(rows) - 1, min(PROFILE_CURVES, len(rows)))})
    for i in picks:
        profiles.plot(rows[i].link_midpoints, rows[i].tension, ".-", markersize=3, label=f"N = {rows[i].nodes}")
    if study.limit is not None:
        s = np.linspace(0.0, study.problem.total_length, 400)
        profiles.plot(s, study.limit.tension(s), "k-", linewidth=1, label="continuous")
    profiles.set_xlabel(label("arclength s from node 0", length_unit(study.problem)))
    profiles.set_ylabel(f"{label('tension T', force_unit(study.problem))} (norm form)")
    profiles.set_title("tension along the chain")
    profiles.legend(fontsize=8)


def save_study_plot(study: RefineStudy, path: str) -> None:
    save_figure(path, lambda figure: draw_study(study, figure), size=(11, 4.5))
