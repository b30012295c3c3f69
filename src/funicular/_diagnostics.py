"""KKT residuals of any point, computed from positions and multipliers alone."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from funicular._constraints import link_distances, link_values, norms
from funicular._forces import applied_forces, contact_forces
from funicular.model import FloatArray, Formulation, IntArray, Problem
from funicular.obstacles.base import NodeFields, depth
from funicular.obstacles.contact import has_segment_depth, link_contact, link_contact_ends, segment_depth


@dataclass(frozen=True)
class KKTResiduals:
    """The four KKT residuals, each a max-norm.

    stationarity: largest force component left unbalanced at a free node (gravity + links + contacts).
    primal_feasibility: largest constraint violation (link overstretch ``max(d_k - l_k, 0)``, a length
        in either formulation, so a short link may not stretch more than a long one; for an elastic
        link the stretch beyond what its tension gives, ``d_k - l_k - T_k l_k / EA_k``; support offset).
    dual_feasibility: largest negative multiplier ``max(-mu_k, 0)``.
    complementarity: largest ``|mu_k c_k|``.
    """

    stationarity: float
    primal_feasibility: float
    dual_feasibility: float
    complementarity: float

    def max(self) -> float:
        return max(self.stationarity, self.primal_feasibility, self.dual_feasibility, self.complementarity)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def residual_scales(problem: Problem) -> KKTResiduals:
    """Units of each residual, so that ``residual / scale`` is dimensionless.

    Force scale: the total weight W (:attr:`Problem.force_scale`: without any weight, the point
    loads, or the stiffness of a pretensioned net). Length scale: the longest link l. The link violation is a
    length (``d_k - l_k``) in either formulation; the multiplier has units of W (norm) or W/l (squared).
    """
    force = problem.force_scale
    length = float(problem.link_lengths.max())
    squared = problem.formulation is Formulation.SQUARED
    return KKTResiduals(
        stationarity=force,
        primal_feasibility=length,
        dual_feasibility=force / length if squared else force,
        complementarity=force * length,
    )


@np.errstate(over="ignore")  # a solve gone far astray (|mu| ~ 1e200) reports inf, not a warning
def kkt_residuals(
    problem: Problem,
    positions: FloatArray,
    link_multipliers: FloatArray,
    obstacle_multipliers: FloatArray | None = None,
    *,
    applied: FloatArray | None = None,
    distances: FloatArray | None = None,
    fields: NodeFields | None = None,
) -> KKTResiduals:
    """KKT residuals of a point and its multipliers; support multipliers follow from force balance.

    Obstacle terms are measured in units that do not depend on how phi is scaled: the violation
    ``phi / |grad phi|`` (a distance), the sign of ``nu |grad phi|`` (a force) and the
    complementarity ``|nu phi|`` (force times distance), over the free nodes; with
    ``contact = "links"`` over the links with a free end, phi and its gradient taken where phi is
    largest along the link (``obstacle_multipliers`` then has shape (n_obstacles, N-1)).
    ``applied`` (this point's :func:`funicular._forces.applied_forces`, contacts included) and
    ``distances`` (its links' lengths) are computed unless given (a :class:`Solution` has them), and
    so are the obstacles at every node (``fields``).
    """
    positions = np.asarray(positions, dtype=np.float64)
    mu = np.asarray(link_multipliers, dtype=np.float64)
    free = problem.free_rows  # (a view where the free nodes are consecutive)
    if applied is None:
        contact = contact_forces(problem, positions, obstacle_multipliers, fields)
        applied = applied_forces(problem, positions, mu, contact)
    net = applied[free]
    if distances is None:
        distances = link_distances(positions, problem.links)
    c = link_values(problem.formulation, distances, problem.link_lengths)
    stretch = distances - problem.link_lengths  # (beyond what an elastic link's tension stretches it)
    if problem.axial_stiffness is not None:  # (the norm formulation: mu is the tension)
        stretch = stretch - problem.link_compliance * mu
        c = stretch
    support_offset = positions[problem.support_nodes] - problem.support_positions

    def largest(values: FloatArray) -> float:
        return float(np.max(np.abs(values))) if values.size else 0.0

    primal = max(largest(np.maximum(stretch, 0.0)), largest(support_offset))
    dual = largest(np.maximum(-mu, 0.0))
    complementarity = largest(mu * c)
    # Contact rows: per free node, or per link with a free end (contact = "links", psi at p*).
    links = _contact_links(problem) if problem.contact == "links" else None
    rows = free if links is None else links
    for j, obstacle in enumerate(problem.obstacles):
        if links is not None:
            end, pinned = link_contact_ends(problem.is_support)
            segment = link_contact(obstacle, positions[links], positions[links + 1], end[links], pinned[links])
            phi, gradient = segment.psi, segment.gradient
        elif fields is None:
            phi, gradient, _ = obstacle.evaluate(positions[free])
        else:
            phi, gradient = fields[j][0][free], fields[j][1][free]
        norm = norms(gradient)
        nu = np.zeros(phi.size) if obstacle_multipliers is None else np.asarray(obstacle_multipliers)[j, rows]
        primal = max(primal, largest(np.maximum(phi, 0.0) / np.maximum(norm, 1e-300)))
        dual = max(dual, largest(np.maximum(-nu, 0.0) * norm))
        complementarity = max(complementarity, largest(nu * phi))
    return KKTResiduals(
        stationarity=largest(net),
        primal_feasibility=primal,
        dual_feasibility=dual,
        complementarity=complementarity,
    )


def _contact_links(problem: Problem) -> IntArray:
    """Links with at least one free end: the ones that carry a contact row in ``contact = "links"``."""
    free = ~problem.is_support
    return np.flatnonzero(free[:-1] | free[1:])


def scaled(residuals: KKTResiduals, problem: Problem) -> KKTResiduals:
    """Residuals divided by :func:`residual_scales`."""
    s = residual_scales(problem)
    return KKTResiduals(
        stationarity=residuals.stationarity / s.stationarity,
        primal_feasibility=residuals.primal_feasibility / s.primal_feasibility,
        dual_feasibility=residuals.dual_feasibility / s.dual_feasibility,
        complementarity=residuals.complementarity / s.complementarity,
    )


def link_penetration(
    problem: Problem, positions: FloatArray, samples: int = 15, fields: NodeFields | None = None
) -> FloatArray:
    """How deep each link segment reaches into the obstacles (L,): the largest distance from a
    point of the link to an obstacle's boundary, over the link's points inside it; 0 for a link
    that stays out. Exact for the built-in shapes (:func:`funicular.obstacles.segment_depth`); for
    an obstacle given by its phi (an expression, a graph, a surface, a callable) an estimate
    (:func:`estimated_depths`): the depth to first order, ``phi / |grad phi|``, largest at
    ``samples`` points strictly inside the link. With ``contact = "nodes"`` the nodes stay out but
    a link may cut a corner; ``contact = "links"`` keeps it out."""
    deepest = np.zeros(problem.n_links)
    if not problem.obstacles:
        return deepest
    starts: slice | IntArray = slice(0, -1) if problem.links is None else problem.link_nodes[:, 0]
    first = positions[starts]  # (a view for a chain)
    second = positions[1:] if problem.links is None else positions[problem.link_nodes[:, 1]]
    # The sample points (L x samples x d) only where some obstacle needs them.
    flat: FloatArray | None = None
    for j, obstacle in enumerate(problem.obstacles):
        if has_segment_depth(obstacle):
            # A built-in shape's phi is concave: along a link it stays below its tangent at the first
            # end, phi(a) + t grad phi(a).(b - a), so only links whose tangent rises above 0 can reach in.
            if fields is None:
                phi, gradient, _ = obstacle.evaluate(first)
            else:
                phi, gradient = fields[j][0][starts], fields[j][1][starts]
            rise = phi + np.maximum(np.einsum("ij,ij->i", gradient, second - first), 0.0)
            near = np.flatnonzero(rise > 0.0)
            deepest[near] = np.maximum(deepest[near], segment_depth(obstacle, first[near], second[near]))
            continue
        if flat is None:
            t = np.linspace(0.0, 1.0, samples + 2)[1:-1]
            points = first[:, None, :] * (1.0 - t[None, :, None]) + second[:, None, :] * t[None, :, None]
            flat = points.reshape(-1, problem.dimension)
        # (fmax: a NaN, where phi is undefined, is not deeper than anything)
        estimate = np.fmax.reduce(depth(obstacle, flat).reshape(problem.n_links, samples), axis=1)
        deepest = np.fmax(deepest, estimate)
    return deepest


def estimated_depths(problem: Problem) -> list[str]:
    """The obstacles whose links' depth :func:`link_penetration` estimates (given by their phi):
    the names a report of the depth says it is an estimate for."""
    return [obstacle.name for obstacle in problem.obstacles if not has_segment_depth(obstacle)]
