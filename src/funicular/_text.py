"""Plain-text summaries and JSON documents of results (the library never prints; the CLI does)."""

from __future__ import annotations

from typing import Any

import numpy as np

from funicular._constraints import norms
from funicular._diagnostics import estimated_depths
from funicular._results import json_bytes
from funicular._units import force_unit, label, length_unit, multiplier_unit, unit, with_unit
from funicular.model import Problem
from funicular.solution import Solution

TIE_RTOL = 1e-12  # tensions this close to the largest, relative to it, are equal to it


def largest_tension(tension: np.ndarray) -> int:
    """The link named as carrying the largest tension: the first of those equal to it to rounding
    (TIE_RTOL), so that a symmetric chain names its first end link, not whichever of its equal
    end links rounding happened to favour."""
    top = float(np.max(tension, initial=-np.inf))
    return int(np.argmax(tension >= top - TIE_RTOL * abs(top)))


def largest_strain(solution: Solution) -> int | None:
    """The elastic link with the largest strain (None where no link is elastic)."""
    problem = solution.problem
    if problem.axial_stiffness is None:
        return None
    return int(np.argmax(np.where(problem.elastic, solution.link_strain, -np.inf)))


def plural(count: int, noun: str) -> str:
    """``1 node``, ``2 nodes``."""
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"


def _components(force: np.ndarray, symbol: str, width: str = "", between: str = "   ") -> str:
    """``Fx = ...   Fy = ...`` (and ``Fz`` in 3-D), each printed with ``+ 0.0`` and followed by the
    unit ``symbol`` (none if "")."""
    return between.join(
        with_unit(f"F{axis} = {value + 0.0:{width}.10g}", symbol) for axis, value in zip("xyz", force, strict=False)
    )


def problem_shape(p: Problem) -> str:
    """A problem's size as a summary's first line gives it: ``51 nodes``, or ``400 nodes, 760 links,
    3-D`` with the point loads counted."""
    shape = f"{p.n_nodes} nodes" + ("" if p.is_chain else f", {p.n_links} links")
    shape += "" if p.dimension == 2 else ", 3-D"
    loaded = p.loaded_nodes.size
    return shape + ("" if not loaded else f", {loaded} point load" + ("s" if loaded > 1 else ""))


def summary(solution: Solution) -> str:
    """A short human-readable summary: status, energy, iterations, KKT residuals, forces, with their
    units where the problem declares them. (Forces print with ``+ 0.0``: a negative zero then
    prints as 0, not -0.)"""
    p = solution.problem
    force = force_unit(p)
    kkt = solution.kkt
    what = p.kind
    loaded = p.loaded_nodes.size
    height = "y" if p.dimension == 2 else "z"
    lines = [
        f"{p.name}: {problem_shape(p)}, {p.formulation.value} formulation, "
        f"g = {with_unit(f'{p.gravity:g}', unit(p, 'gravity'))}",
        f"  status            {solution.status.value} ({solution.status.message})",
        f"  energy            {with_unit(f'{solution.objective + 0.0:.10g}', unit(p, 'energy'))}   "
        f"(g m^T {height}{' - P . p' if loaded else ''}{' + strain energy' if p.axial_stiffness is not None else ''})",
        f"  iterations        {solution.iterations} in {solution.solve_seconds:.3g} s",
        f"  KKT residuals     stationarity {kkt.stationarity:.2e}, primal {kkt.primal_feasibility:.2e}, "
        f"dual {kkt.dual_feasibility:.2e}, complementarity {kkt.complementarity:.2e}",
    ]
    if solution.unsettled is not None:
        lines.append(f"  not settled       {solution.unsettled}")
    if p.n_links:
        k = largest_tension(solution.link_tension)
        taut = int(np.count_nonzero(solution.link_taut))
        between = "" if p.is_chain else f" (nodes {int(p.link_nodes[k, 0])}-{int(p.link_nodes[k, 1])})"
        lines.append(
            f"  max tension       {with_unit(f'{solution.link_tension[k]:.10g}', force)} in link {k}{between} "
            f"({taut} of {p.n_links} links taut)"
        )
    strained = largest_strain(solution)
    if strained is not None:
        k = strained
        between = "" if p.links is None else f" (nodes {int(p.link_nodes[k, 0])}-{int(p.link_nodes[k, 1])})"
        stretch = with_unit(f"{solution.link_stretch[k]:.4g}", length_unit(p))
        lines.append(
            f"  max strain        {solution.link_strain[k]:.4g} in link {k}{between}, stretched by {stretch} "
            f"({int(np.count_nonzero(p.elastic))} of {p.n_links} links elastic)"
        )
    if p.obstacles:
        contact = solution.contact_forces
        touching = int(np.count_nonzero(norms(contact) > 0))
        total = contact.sum(axis=0)
        lines.append(
            f"  contact forces    {plural(touching, 'node')} touch {plural(len(p.obstacles), 'obstacle')}; "
            f"total {_components(total, force, between=', ')}"
        )
        if solution.links_cross_obstacles:
            deepest = f"deepest {with_unit(f'{solution.link_penetration.max():.3g}', length_unit(p))}"
            estimated = estimated_depths(p)
            if estimated:  # (given by their phi: the depth to first order)
                names = ", ".join(repr(name) for name in estimated)
                which = "obstacle" if len(estimated) == 1 else "obstacles"
                deepest = f"{deepest}, estimated as phi / |grad phi| for {which} {names}"
            cut = f"with contact = '{p.contact}' some links cut into an obstacle"
            lines.append(f"  note              {cut} ({deepest})")
    lines.append(f"  support reactions (force each support exerts on the {what})")
    for node, reaction in zip(p.support_nodes, solution.support_reactions, strict=True):
        lines.append(f"    node {int(node):<8d} {_components(reaction, force, ' ')}")
    total = solution.support_reactions.sum(axis=0)
    lines.append(f"    total           {_components(total, force, ' ')}   ({balance(solution)})")
    return "\n".join(lines)


def _vector(force: np.ndarray) -> str:
    return f"({', '.join(f'{value + 0.0:.10g}' for value in force)})"


def balance(solution: Solution) -> str:
    """What the support reactions add up to, in parts that sum to their total component by
    component: the weight held up, minus the point loads' sum, minus the contact forces' sum
    (the supports balance all the other forces on the chain or net). Only the weight where there
    is nothing else. Each force with its unit where the problem declares one."""
    p = solution.problem
    force = force_unit(p)
    weight = with_unit(f"{p.weight:.10g}", force)
    parts = [f"weight {weight}" + (" held up" if p.loads is not None or p.obstacles else "")]
    if p.loads is not None:
        parts.append(f"minus point loads {with_unit(_vector(p.loads.sum(axis=0)), force)}")
    if p.obstacles:
        parts.append(f"minus contact forces {with_unit(_vector(solution.contact_forces.sum(axis=0)), force)}")
    return ", ".join(parts)


def to_json(document: dict[str, Any], indent: bool = True) -> str:
    """Strict JSON text, indented or compact: non-finite numbers (a failed solve's) as null, numpy
    arrays (strided ones too) and scalars as numbers. orjson writes it (a million-node result in
    about a second, where the standard library's indenting encoder took half a minute)."""
    return json_bytes(document, indent).decode()


def force_table(solution: Solution) -> str:
    """Every link's multiplier, tension, length and state (a net's: also its two nodes), and (with
    obstacles) every node's contact force; the headers carry the units the problem declares."""
    p = solution.problem
    force, length = force_unit(p), length_unit(p)
    multiplier = "mu_k = T_k" if p.formulation.value == "norm" else "mu_k = T_k/(2 d_k)"
    multiplier = label(multiplier, multiplier_unit(p, p.formulation.value))
    tension, distance, most = label("tension T_k", force), label("length d_k", length), label("max l_k", length)
    pairs = None if p.is_chain else p.link_nodes
    nodes = "" if pairs is None else f"  {'nodes':>15}"
    lines = [f"  {'link':>6}{nodes}  {multiplier:>18}  {tension:>18}  {distance:>16}  {most:>16}  state"]
    for k in range(p.n_links):
        between = "" if pairs is None else f"  {f'{int(pairs[k, 0])}-{int(pairs[k, 1])}':>15}"
        lines.append(
            f"  {k:>6}{between}  {solution.link_multipliers[k] + 0.0:>18.10g}  "
            f"{solution.link_tension[k] + 0.0:>18.10g}  "
            f"{solution.link_distance[k]:>16.10g}  {p.link_lengths[k]:>16.10g}  "
            f"{'taut' if solution.link_taut[k] else 'slack'}"
        )
    if p.obstacles:
        axes = "xyz"[: p.dimension]
        lines.append(f"  {'node':>6}" + "".join(f"  {label(f'contact F{axis}', force):>18}" for axis in axes))
        for i, force in enumerate(solution.contact_forces):
            lines.append(f"  {i:>6}" + "".join(f"  {value + 0.0:>18.10g}" for value in force))
    return "\n".join(lines)
