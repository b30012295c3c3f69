"""SciPy's SLSQP on the chain, as the exercise suggests: dense, and it returns no multipliers.

Unknowns are the free nodes' coordinates. The energy is divided by ``W l`` (total weight times
the longest link) and the link constraints by ``l`` (norm) or ``l^2`` (squared), so ``tol`` means
roughly what it means for funicular. The multipliers are recovered from the positions by
:func:`funicular.checks.recover_multipliers` (nonnegative least squares over the active set).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import minimize

from funicular._constraints import link_deltas, link_distances, link_gradients, link_values
from funicular.backends import link_scale, require_node_contact, solution, starting_point
from funicular.checks import recover_multipliers
from funicular.model import FloatArray, Problem
from funicular.solution import Solution, Status

MAX_ITERATIONS = 1000
ITERATION_LIMIT = 9  # SLSQP's status for "iteration limit reached"


def solve(problem: Problem, *, tol: float | None = None) -> Solution:
    require_node_contact(problem, "slsqp")
    started = time.perf_counter()
    tol = 1e-10 if tol is None else tol
    start = starting_point(problem)
    free = problem.free_nodes
    n = 2 * free.size
    column = np.full(problem.n_nodes, -1, dtype=np.intp)
    column[free] = np.arange(free.size)
    energy_unit = problem.weight * float(problem.link_lengths.max())
    scale = link_scale(problem)

    def positions(z: FloatArray) -> FloatArray:
        p = start.copy()
        p[free] = z.reshape(-1, 2)
        return p

    gradient = np.zeros(n)
    gradient[1::2] = problem.gravity * problem.masses[free] / energy_unit

    def energy(z: FloatArray) -> tuple[float, FloatArray]:
        return float(gradient @ z), gradient

    def links(z: FloatArray) -> FloatArray:  # >= 0 when feasible
        p = positions(z)
        return -link_values(problem.formulation, link_distances(p), problem.link_lengths) / scale

    def links_jacobian(z: FloatArray) -> FloatArray:
        p = positions(z)
        q = link_gradients(problem.formulation, link_deltas(p), link_distances(p)) / scale
        jacobian = np.zeros((problem.n_links, n))
        for k in range(problem.n_links):
            for node, sign in ((k, -1.0), (k + 1, 1.0)):
                if column[node] >= 0:
                    jacobian[k, 2 * column[node] : 2 * column[node] + 2] = sign * q[k]
        return jacobian

    def contacts(z: FloatArray) -> FloatArray:
        p = positions(z)[free]
        return -np.concatenate([obstacle.evaluate(p)[0] for obstacle in problem.obstacles])

    def contacts_jacobian(z: FloatArray) -> FloatArray:
        p = positions(z)[free]
        blocks = []
        for obstacle in problem.obstacles:
            gradient_phi = obstacle.evaluate(p)[1]
            block = np.zeros((free.size, n))
            block[np.arange(free.size), 2 * np.arange(free.size)] = -gradient_phi[:, 0]
            block[np.arange(free.size), 2 * np.arange(free.size) + 1] = -gradient_phi[:, 1]
            blocks.append(block)
        return np.vstack(blocks)

    constraints = [{"type": "ineq", "fun": links, "jac": links_jacobian}]
    if problem.obstacles:
        constraints.append({"type": "ineq", "fun": contacts, "jac": contacts_jacobian})
    result = minimize(  # type: ignore[call-overload]
        energy,
        start[free].ravel(),
        jac=True,
        method="SLSQP",
        constraints=constraints,
        options={"ftol": tol, "maxiter": MAX_ITERATIONS},
    )
    final = positions(np.asarray(result.x))
    if result.success:
        status = Status.OPTIMAL
    elif result.status == ITERATION_LIMIT:
        status = Status.MAX_ITERATIONS
    elif np.all(np.isfinite(final)):
        status = Status.STALLED
    else:
        status = Status.NONFINITE
    multipliers = recover_multipliers(problem, final) if np.all(np.isfinite(final)) else None
    link = np.zeros(problem.n_links) if multipliers is None else multipliers.link
    obstacle = np.zeros((len(problem.obstacles), problem.n_nodes)) if multipliers is None else multipliers.obstacle
    return solution(problem, final, status, link, obstacle, int(result.nit), started)
