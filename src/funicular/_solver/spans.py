"""The exact start of a chain that touches nothing: each span a discrete catenary, solved in the
solver core (``rust/core/src/catenary.rs``; the model is in docs/model.md, "The discrete
catenary"), for the tests and the studies that compare with it. The solve starts from it itself.
"""

from __future__ import annotations

import numpy as np

from funicular import _core
from funicular._solver.core_problem import core_chain, core_errors, node_field
from funicular.model import FloatArray, Problem
from funicular.obstacles import Obstacle


def exact_start(problem: Problem) -> tuple[FloatArray, FloatArray] | None:
    """Positions (N, 2) and link tensions (N-1,) of ``problem``'s equilibrium if every span is a
    discrete catenary with every link taut and no node touches an obstacle, else ``None`` (also
    where the construction does not apply: a span with no weight on its interior nodes, a nearly
    vertical span). An exactly taut span lies on its chord with zero tensions and massless free ends
    hang straight down: the presolve replaces both."""
    with core_errors(problem):
        exact = core_chain(problem).exact_start()
    if exact is None:
        return None
    return exact.positions.reshape(problem.n_nodes, 2), exact.tensions


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
        interior_masses=np.ascontiguousarray(interior_masses, dtype=np.float64),
        lengths=np.ascontiguousarray(lengths, dtype=np.float64),
        gravity=float(g),
        left=np.ascontiguousarray(left, dtype=np.float64),
        right=np.ascontiguousarray(right, dtype=np.float64),
        field=node_field(obstacles) if obstacles else None,
        n_obstacles=len(obstacles),
    )
    if span is None:
        return None
    return span.positions.reshape(-1, 2), span.tensions
