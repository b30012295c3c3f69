"""The exact start of a chain that touches nothing: each span a discrete catenary, solved in the
solver core (``rust/core/src/catenary.rs``; the model is in docs/model.md, "The discrete
catenary").

When every span between consecutive supports is solved this way and every free node is outside
every obstacle (with ``contact = "links"``: every link), this is the equilibrium, and the solver
starts from it with its tensions: the polish confirms it in one Newton step.
"""

from __future__ import annotations

import numpy as np

from funicular import _core
from funicular.model import FloatArray, IntArray, Problem
from funicular.obstacles import Obstacle, has_segment_max, link_contact, link_contact_ends
from funicular.solver.initial import core_chain, obstacle_shapes


def exact_start(problem: Problem, chain: _core.Chain | None = None) -> tuple[FloatArray, FloatArray] | None:
    """Positions (N, 2) and link tensions (N-1,) of ``problem``'s equilibrium if no node touches an
    obstacle, else ``None``. Also ``None`` where this construction does not apply and the solver
    must work: a span with no weight on its interior nodes (its links may hang slack), a nearly
    vertical span (it folds). ``chain``: ``initial.core_chain(problem)``, if already made.

    Two parts are left to the presolve, which replaces them: an exactly taut span gets its chord
    and zero tensions here (the presolve fixes it with its own tensions), and massless free ends
    hang straight down (the presolve rests them on the node they hang from; they are not checked
    against the obstacles)."""
    links = problem.contact == "links" and bool(problem.obstacles)
    if links and not all(map(has_segment_max, problem.obstacles)):
        return None  # (the solver refuses these itself, with a sentence)
    exact = (chain or core_chain(problem)).exact_start()
    if exact is None:
        return None
    positions, tension = exact[0].reshape(problem.n_nodes, 2), exact[1]
    if links and not _links_clear(problem, positions):
        return None
    return positions, tension


def _links_clear(problem: Problem, positions: FloatArray) -> bool:
    """With ``contact = "links"``: every link the solver keeps out of the obstacles (one with a
    movable end and no detached massless end, as in ``ipm._scale``) has its contact row ``psi``
    (``link_contact``: phi's largest value along it, or at its free end) below zero."""
    end, pinned = link_contact_ends(problem.is_support)
    movable, left_out = ~problem.is_support, np.zeros(problem.n_nodes, dtype=bool)
    left_out[_massless_ends(problem)] = True
    rows = np.flatnonzero((movable[:-1] | movable[1:]) & ~left_out[:-1] & ~left_out[1:])
    for obstacle in problem.obstacles:
        psi = link_contact(obstacle, positions[rows], positions[rows + 1], end[rows], pinned[rows]).psi
        if not np.all(psi < 0.0):
            return False
    return True


def _massless_ends(problem: Problem) -> IntArray:
    """The free end nodes the presolve detaches (nothing pulls them)."""
    anchored = problem.is_support | (problem.masses > 0)
    first, last = int(anchored.argmax()), int(problem.n_nodes - 1 - anchored[::-1].argmax())
    return np.concatenate((np.arange(first), np.arange(last + 1, problem.n_nodes)))


def hanging_span(
    interior_masses: FloatArray,
    lengths: FloatArray,
    g: float,
    left: FloatArray,
    right: FloatArray,
    obstacles: tuple[Obstacle, ...] = (),
) -> tuple[FloatArray, FloatArray] | None:
    """Interior node positions (n-1, 2) and link tensions (n,) of n links hanging between ``left``
    and ``right`` with every link taut (the core's), or ``None``: no weight between them, a nearly
    vertical span, no convergence, or a starting rope deep in one of ``obstacles``."""
    span = _core.hanging_span(
        np.ascontiguousarray(interior_masses, dtype=np.float64),
        np.ascontiguousarray(lengths, dtype=np.float64),
        float(g),
        np.ascontiguousarray(left, dtype=np.float64),
        np.ascontiguousarray(right, dtype=np.float64),
        obstacle_shapes(obstacles) if obstacles else None,
        len(obstacles),
    )
    if span is None:
        return None
    return span[0].reshape(-1, 2), span[1]
