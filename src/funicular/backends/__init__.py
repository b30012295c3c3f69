"""Other solvers, for cross-checks: SciPy's SLSQP and IPOPT (through CasADi, the ``ipopt`` extra).

Each backend solves the same problem (supports eliminated, the problem's link formulation,
node contacts) from funicular's initial guess and returns a :class:`funicular.Solution`, so the
same KKT, LICQ and second-order checks apply to every answer. :func:`compare` runs them all.
"""

from __future__ import annotations

import importlib.util
import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from funicular._extras import install_command
from funicular._solver import SolverOptions
from funicular._solver import solve as funicular_solve
from funicular._solver.initial import presolve
from funicular._units import force_unit, label, length_unit, unit
from funicular.errors import ParameterError, SolverError
from funicular.model import FloatArray, Problem
from funicular.solution import Solution, Status

SOLVERS = ("funicular", "slsqp", "ipopt")
SLSQP_DENSE_ABOVE = 200  # nodes; SLSQP works with dense matrices and gets slow beyond this
# The most nodes each other solver is given, so that what it allocates stays within about 2 GB.
# SLSQP's matrices are dense: SciPy's workspace holds about 8.5 n^2 + 3 m n numbers and the
# constraints' Jacobian m n more (n = 2 x the free nodes, m >= N constraints), 1.3 GB at 2,000
# nodes and 2.9 TiB at 100,000. IPOPT's symbolic problem (CasADi) takes about 12 kB a node, 40 kB
# with an obstacle (measured): 0.6 to 2 GB at 50,000 nodes.
MAX_NODES = {"slsqp": 2_000, "ipopt": 50_000}


def available() -> list[str]:
    """The solvers that can run here: IPOPT needs CasADi (the ``ipopt`` extra)."""
    return [name for name in SOLVERS if name != "ipopt" or importlib.util.find_spec("casadi") is not None]


def solve_with(
    problem: Problem,
    solver: str = "funicular",
    *,
    tol: float | None = None,
    max_iterations: int | None = None,
    exact_start: bool = True,
    escape_up_to: int | None = None,
) -> Solution:
    """Solve ``problem`` with the named solver; raises :class:`SolverError` if it is not available.
    ``max_iterations``, ``exact_start`` and ``escape_up_to`` (see :class:`funicular.SolverOptions`)
    apply to funicular's own solver (the others keep their own limits and start from its general
    guess)."""
    if solver == "funicular":
        options = SolverOptions(exact_start=exact_start, escape_up_to=escape_up_to)
        return funicular_solve(problem, options, tol=tol, max_iterations=max_iterations)
    check_size(problem, [solver])
    if solver in SOLVERS and not problem.is_planar_chain:
        raise SolverError(
            f"--solver {solver} solves planar chains of inextensible links without point loads; solve a net, a "
            "chain in space, a chain with point loads or with elastic links with funicular's own solver."
        )
    if solver == "slsqp":
        from funicular.backends import slsqp  # (scipy.optimize: loaded only when SLSQP runs)

        return slsqp.solve(problem, tol=tol)
    if solver == "ipopt":
        if "ipopt" not in available():
            raise SolverError(f"--solver ipopt needs CasADi; install it with {install_command('ipopt')}.")
        from funicular.backends import ipopt  # (CasADi, an optional extra: loaded only when IPOPT runs)

        return ipopt.solve(problem, tol=tol)
    raise SolverError(f"solver {solver!r} is not known; use one of {', '.join(SOLVERS)}.")


def check_size(problem: Problem, solvers: Iterable[str]) -> None:
    """A :class:`ParameterError` before anything is allocated where ``problem`` has more nodes than
    one of ``solvers`` takes (MAX_NODES); the sentence names every limit."""
    over = [solver for solver in solvers if problem.n_nodes > MAX_NODES.get(solver, problem.n_nodes)]
    if over:
        raise ParameterError(
            f"solver {over[0]!r} cannot take the {problem.n_nodes:,} nodes of {problem.name!r}: slsqp takes at "
            f"most {MAX_NODES['slsqp']:,} nodes (its matrices are dense) and ipopt at most {MAX_NODES['ipopt']:,}; "
            "use fewer nodes (--nodes) or funicular's own solver.",
            key="solver",
        )


def advice(problem: Problem, solver: str) -> str | None:
    """A warning worth printing before a solve, or None."""
    if solver == "slsqp" and problem.n_nodes > SLSQP_DENSE_ABOVE:
        return (
            f"funicular: warning: SLSQP uses dense matrices; with {problem.n_nodes} nodes it is slow "
            "(funicular's own solver is O(N))."
        )
    return None


# ----------------------------------------------------------------- shared by the backends
def require_node_contact(problem: Problem, solver: str) -> None:
    """The other solvers keep only the nodes out of obstacles: refuse ``contact = "links"``."""
    if problem.contact == "links" and problem.obstacles:
        raise SolverError(
            f"--solver {solver} supports contact = 'nodes' only; solve contact = 'links' with funicular's own solver."
        )


def starting_point(problem: Problem) -> FloatArray:
    """funicular's initial guess (N, 2): supports in place, every link shorter than allowed."""
    return presolve(problem).positions


def link_scale(problem: Problem) -> float:
    """Unit of the link constraint values: the longest link (norm) or its square (squared)."""
    longest = float(problem.link_lengths.max())
    return longest if problem.formulation.value == "norm" else longest * longest


def solution(
    problem: Problem,
    positions: FloatArray,
    status: Status,
    link_multipliers: FloatArray,
    obstacle_multipliers: FloatArray,
    iterations: int,
    started: float,
) -> Solution:
    return Solution(
        problem=problem,
        status=status,
        positions=positions,
        link_multipliers=link_multipliers,
        obstacle_multipliers=obstacle_multipliers,
        iterations=iterations,
        solve_seconds=time.perf_counter() - started,
    )


# ----------------------------------------------------------------- funicular compare
@dataclass(frozen=True)
class Row:
    solver: str
    solution: Solution | None
    error: str | None
    seconds: float


def compare(problem: Problem, tol: float | None = None) -> list[Row]:
    """Run every available solver; a solver that fails to run gives a row with its error. A
    problem larger than one of them takes (MAX_NODES) is refused before any runs."""
    check_size(problem, available())
    rows = []
    for name in available():
        started = time.perf_counter()
        try:
            result: Solution | None = solve_with(problem, name, tol=tol)
            error = None
        except SolverError as failure:
            result, error = None, str(failure)
        rows.append(Row(name, result, error, time.perf_counter() - started))
    return rows


def compare_table(rows: list[Row]) -> str:
    """The comparison as text: differences are measured against funicular's answer (energy and
    differences with their units where the scenario declares them)."""
    reference = next((row.solution for row in rows if row.solver == "funicular"), None)
    problem = next((row.solution.problem for row in rows if row.solution is not None), None)
    names = (
        label("energy", unit(problem, "energy")),
        label("max |dp|", length_unit(problem)),
        label("max |dT|", force_unit(problem)),
        "max KKT",
        "time [s]",
    )
    columns = tuple((name, max(width, len(name))) for name, width in zip(names, (16, 10, 10, 10, 9), strict=True))
    energy_width, dp_width, dt_width, kkt_width, time_width = (width for _, width in columns)
    lines = [f"{'solver':<10} {'status':<15} " + " ".join(f"{name:>{width}}" for name, width in columns)]
    for row in rows:
        s = row.solution
        if s is None:
            lines.append(f"{row.solver:<10} {'error':<15} {row.error}")
            continue
        dp = dt = "-"
        if reference is not None and row.solver != "funicular":
            dp = f"{np.abs(s.positions - reference.positions).max():.2e}"
            dt = f"{np.abs(s.link_tension - reference.link_tension).max():.2e}"
        lines.append(
            f"{row.solver:<10} {s.status.value:<15} {s.objective:>{energy_width}.10g} {dp:>{dp_width}} "
            f"{dt:>{dt_width}} {s.kkt.max():>{kkt_width}.2e} {row.seconds:>{time_width}.3g}"
        )
    return "\n".join(lines)
