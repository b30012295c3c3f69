"""IPOPT through CasADi (the ``ipopt`` extra): an independent interior-point solver for cross-checks.

The problem is written symbolically with the free coordinates as unknowns: energy divided by
``W l``, link constraints ``c_k / s <= 0`` (``s = l`` for norm, ``l^2`` for squared) from the same
formulas as :mod:`funicular._constraints`, and ``phi_j(p_i) <= 0`` at each free node through a
CasADi callback chain (phi, its gradient and its Hessian from ``Obstacle.evaluate``).
``bound_relax_factor = 0`` keeps IPOPT from stretching the links by its default 1e-8.

Multipliers: CasADi's Lagrangian is ``f + lam_g^T g`` with ``lam_g >= 0`` at an active upper
bound ``g <= 0``, funicular's is ``E + mu^T c``; with ``f = E / (W l)`` and ``g = c / s``,
``mu = lam_g W l / s`` and ``nu = lam_g W l``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any, cast

import casadi as ca
import numpy as np

from funicular.backends import link_scale, require_node_contact, solution, starting_point
from funicular.model import FloatArray, Formulation, Problem
from funicular.obstacles import Obstacle
from funicular.solution import Solution, Status

MAX_ITERATIONS = 500


class _Phi(ca.Callback):
    """An obstacle's phi at one point (order 0); its Jacobian is order 1 (the gradient), then 2 (Hessian).

    CasADi calls a Jacobian function with the inputs and the nominal outputs of the function it
    differentiates and expects one output per (output, input) pair.
    """

    def __init__(self, obstacle: Obstacle, order: int, name: str) -> None:
        ca.Callback.__init__(self)
        self.obstacle, self.order = obstacle, order
        self.children: list[_Phi] = []  # CasADi does not keep the Jacobian callbacks alive
        self.construct(name, {})

    def get_n_in(self) -> int:
        return self.order + 1

    def get_n_out(self) -> int:
        return 1 if self.order < 2 else 2

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return [ca.Sparsity.dense(2, 1), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(1, 2)][i]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        if self.order < 2:
            return ca.Sparsity.dense(1, 1) if self.order == 0 else ca.Sparsity.dense(1, 2)
        return ca.Sparsity.dense(2, 2) if i == 0 else ca.Sparsity(2, 1)  # d(gradient)/d(nominal phi) = 0

    def eval(self, arg: Sequence[ca.DM]) -> list[ca.DM]:
        phi, gradient, hessian = self.obstacle.evaluate(np.array(arg[0], dtype=np.float64).reshape(1, 2))
        if self.order == 0:
            return [ca.DM(phi[0])]
        if self.order == 1:
            return [ca.DM(gradient[0]).T]
        return [ca.DM(hessian[0]), ca.DM(2, 1)]

    def has_jacobian(self) -> bool:
        return self.order < 2

    def get_jacobian(
        self, name: str, inames: Sequence[str], onames: Sequence[str], opts: Mapping[str, Any]
    ) -> ca.Function:
        child = _Phi(self.obstacle, self.order + 1, name)
        self.children.append(child)
        return child


def solve(problem: Problem, *, tol: float | None = None) -> Solution:
    require_node_contact(problem, "ipopt")
    started = time.perf_counter()
    tol = 1e-10 if tol is None else tol
    start = starting_point(problem)
    free = problem.free_nodes
    longest = float(problem.link_lengths.max())
    energy_unit = problem.weight * longest
    scale = link_scale(problem)

    z = ca.MX.sym("z", 2 * free.size) if problem.obstacles else ca.SX.sym("z", 2 * free.size)
    nodes: list[Any] = [ca.DM(point) for point in start]
    for c, i in enumerate(free):
        nodes[i] = z[2 * c : 2 * c + 2]
    energy = sum(problem.gravity * problem.masses[i] * z[2 * c + 1] for c, i in enumerate(free)) / energy_unit
    constraints = []
    for k in range(problem.n_links):
        delta = nodes[k] - nodes[k + 1]
        if problem.formulation is Formulation.NORM:
            value = ca.norm_2(delta) - problem.link_lengths[k]
        else:
            value = ca.sumsqr(delta) - problem.link_lengths[k] ** 2
        constraints.append(value / scale)
    callbacks = [_Phi(obstacle, 0, f"phi_{j}") for j, obstacle in enumerate(problem.obstacles)]
    for phi in callbacks:
        constraints += [phi(nodes[i]) for i in free]
    options = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.bound_relax_factor": 0.0,
        "ipopt.max_iter": MAX_ITERATIONS,
    }
    problem_dict: Any = {"x": z, "f": energy, "g": ca.vertcat(*constraints)}
    nlp = ca.nlpsol("funicular", "ipopt", problem_dict, cast(Any, options))
    result = nlp(x0=start[free].ravel(), lbg=-np.inf, ubg=0.0)
    stats = nlp.stats()
    positions = start.copy()
    positions[free] = np.array(result["x"], dtype=np.float64).reshape(-1, 2)
    lam = np.array(result["lam_g"], dtype=np.float64).ravel()
    link_multipliers = lam[: problem.n_links] * energy_unit / scale
    obstacle_multipliers = np.zeros((len(problem.obstacles), problem.n_nodes))
    obstacle_multipliers[:, free] = lam[problem.n_links :].reshape(len(problem.obstacles), free.size) * energy_unit
    return solution(
        problem,
        positions,
        _status(stats, positions),
        link_multipliers,
        obstacle_multipliers,
        int(stats.get("iter_count", 0)),
        started,
    )


def _status(stats: dict[str, Any], positions: FloatArray) -> Status:
    if not np.all(np.isfinite(positions)):
        return Status.NONFINITE
    if stats.get("success"):
        return Status.OPTIMAL
    if stats.get("return_status") == "Maximum_Iterations_Exceeded":
        return Status.MAX_ITERATIONS
    return Status.STALLED
