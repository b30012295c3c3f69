"""The benchmark: funicular against other solvers on its benchmark family of chains.

Run from the repository (``make bench``)::

    .venv/bin/python -m bench.run --markdown docs/benchmark.md --plot docs/benchmark.png
    .venv/bin/python -m bench.run --nodes 1000000 --solvers funicular --repeats 1 --markdown docs/benchmark-1e6.md

The family: supports at (0, 0) and (1, 0) (nodes 0 and -1), chain length 1.5, total mass 1 spread
over N nodes, g = 1, norm formulation; ``disk`` adds ``Disk((0.5, -0.55), 0.25)`` under the chain.

Every solver gets the same instances and starts, where it takes a start, from funicular's initial
guess. Competitors, each run only if its package is installed (the ``bench`` extra):

* IPOPT through CasADi. The model is written here with whole-vector CasADi expressions and the
  disk as a formula, not through :mod:`funicular.backends.ipopt`, whose per-node Python callbacks
  for general obstacles would be what is measured (190 s instead of 5 s at N = 10^4 with the disk).
  Same scaling as the backend: energy / (W l), link constraints / l, ``bound_relax_factor = 0``.
* CVXPY + Clarabel: the second-order-cone program ``||p_k - p_(k+1)|| / l <= l_k / l``, energy / (W l)
  (l: the longest link). Scaling matters: unscaled, Clarabel's feasibility tolerance let links stretch
  by 1e-5 l at N = 10^4; with the positions divided by l too it needed 28 iterations at N = 10^5 and
  ended 0.03 above the minimum energy while reporting "optimal". No-disk problems only: staying
  outside a disk is not convex.
* SciPy SLSQP (:mod:`funicular.backends.slsqp`): dense, so only up to ``MAX_NODES["slsqp"]``.

Timing: for each instance every solver runs once as a warm-up (that answer is the one checked),
then ``repeats`` timed runs interleaved across the solvers, so that load on a shared machine
hits them alike; the table shows medians and ratios to funicular from the same run. A warm-up
slower than ``ONCE_ABOVE`` seconds is itself the measurement. Times are wall clock from the
``Problem`` to the positions, model building included; "in solver" is the part the competitor
reports for its own solve (the IPOPT call without CasADi's model building, Clarabel's ``solve_time``).

Checks: each answer goes through :func:`funicular.checks.check`, with the multipliers the solver
returns (funicular's, IPOPT's ``lam_g``, the Clarabel cones' duals, converted to funicular's
units; SLSQP has none, its backend recovers them from the positions with the same checker):
feasibility, the largest scaled KKT residual and the second-order verdict. Recovering multipliers
for every solver would judge IPOPT unfairly: at tol 1e-8 its barrier leaves the nodes on the disk
about 2e-6 link lengths off it (N = 1000), just outside the checker's contact tolerance of 1e-6 l,
so their contact forces would be missing from the recovered ones.
"dE" is the solver's energy ``g m^T y`` minus funicular's.

``--profile`` runs cProfile on one solve and sums each function's own time into phases by the
function's name (:data:`PHASE_PATTERNS`); a function without a phase of its own takes the phase
of the outermost phase function above it (so the evaluations a line search makes count as line
search), estimated from cProfile's caller edges, and anything else is "other". Renamed solver
functions therefore only move time to "other"; nothing breaks.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import importlib.metadata
import importlib.util
import math
import os
import platform
import pstats
import re
import statistics
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy

from funicular._diagnostics import scaled
from funicular._io import atomic_write_text
from funicular._progress import add_quiet_argument, progress_bar
from funicular._solver import solve
from funicular._text import to_json
from funicular.backends import starting_point
from funicular.checks import DEFAULT_TOL as CHECK_TOL
from funicular.checks import Multipliers, check
from funicular.errors import FunicularError, ScenarioError, SolverError, shown
from funicular.model import FloatArray, Problem
from funicular.obstacles import Disk
from funicular.plot import check_plot_path, save_figure
from funicular.solution import Solution

if TYPE_CHECKING:
    from matplotlib.figure import Figure

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT = 0, 1, 2
SOLVER_NAMES = ("funicular", "ipopt", "clarabel", "slsqp")
PROBLEMS = ("free", "disk")
DEFAULT_NODES = (50, 100, 1_000, 3_000, 10_000, 100_000)
PROFILE_NODES = 1_000_000
DEFAULT_REPEATS = 3
DEFAULT_TOL = 1e-10  # funicular's own default (scaled KKT residuals)
COMPETITOR_TOL = 1e-8  # IPOPT's tol, Clarabel's gap and feasibility tolerances, SLSQP's ftol
ONCE_ABOVE = 30.0  # seconds: a warm-up slower than this is the only timed run
# Larger N is skipped, measured on 2 cores: SLSQP is dense (2-8 s at N = 100). IPOPT (MUMPS) at tol 1e-8
# stops with Search_Direction_Becomes_Too_Small at N = 2e4, takes 76 iterations (29 s) at 4e4 and was
# still running after 20 minutes at 1e5. (Clarabel stays at 9 iterations: 16 s and 1.1 GB at N = 3e5.)
MAX_NODES = {"slsqp": 100, "ipopt": 10_000}
REQUIRES = {"ipopt": ("casadi",), "clarabel": ("cvxpy", "clarabel")}
# Searched in "module.py:function"; the first match names a function's own phase. "solve" alone is
# also funicular's entry point, so only the linear-algebra modules' "solve" closures count as factorization.
PHASE_PATTERNS = (
    ("polish", re.compile(r"polish")),
    ("line search", re.compile(r"line_search|linesearch|backtrack")),
    ("factorization", re.compile(r"factor|cholesky|cho_solve|solve_banded|solve_kernel|(banded|compiled)\.py:solve$")),
    ("assembly/evaluation", re.compile(r"evaluat|newton_matrix|jacobian|hessian|gradient|assembl|to_banded")),
)
PHASES = (*(name for name, _ in PHASE_PATTERNS), "other")
PROFILE_PASSES = 200  # fixed-point passes over the call graph (it converges in about its depth)
TOP_FUNCTIONS = 15
# A small solve before profiling: over ipm.COARSE_ABOVE, so the disk takes every path once and the
# profile counts no first-call costs (imports, the core's first allocations).
WARM_UP_NODES = 1000
BACK_TO_BACK = 200  # funicular's solves in a row on each small instance (``back_to_back``)
BACK_TO_BACK_UP_TO = 100  # nodes: the interactive sizes


# --------------------------------------------------------------------------- instances
def family(nodes: int, problem: str = "free") -> Problem:
    """The benchmark chain with ``nodes`` nodes; ``problem="disk"`` adds the disk."""
    return Problem.build(
        nodes=nodes,
        length=1.5,
        mass=1.0,
        gravity=1.0,
        formulation="norm",
        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Disk((0.5, -0.55), 0.25)] if problem == "disk" else [],
    )


# --------------------------------------------------------------------------- solvers
@dataclass(frozen=True)
class Outcome:
    """One solver's answer: positions (N, 2), multipliers if it gives them, its own status word, and
    its iteration count and solve time if it reports them."""

    positions: FloatArray
    multipliers: Multipliers | None
    status: str
    iterations: int | None
    solver_seconds: float | None


def _multipliers(solution: Solution) -> Multipliers:
    problem = solution.problem
    obstacle = solution.obstacle_multipliers.reshape(len(problem.obstacles), problem.n_nodes)
    return Multipliers(solution.link_multipliers, obstacle)


def run_funicular(problem: Problem, tol: float) -> Outcome:
    solution = solve(problem, tol=tol)
    return Outcome(solution.positions, _multipliers(solution), solution.status.value, solution.iterations, None)


def run_slsqp(problem: Problem, tol: float) -> Outcome:
    from funicular.backends import slsqp  # (scipy.optimize: loaded only when SLSQP runs)

    solution = slsqp.solve(problem, tol=tol)  # its multipliers are recovered from the positions by funicular.checks
    return Outcome(solution.positions, _multipliers(solution), solution.status.value, solution.iterations, None)


def run_ipopt(problem: Problem, tol: float) -> Outcome:
    import casadi as ca  # an optional competitor, loaded only when it runs

    start = starting_point(problem)
    free = problem.free_nodes
    longest = float(problem.link_lengths.max())
    z = ca.SX.sym("z", 2 * free.size)
    nodes = ca.reshape(z, 2, free.size)  # column c: free node c
    positions = ca.SX(ca.DM(start.T))
    positions[:, free.tolist()] = nodes
    delta = positions[:, 1:] - positions[:, :-1]
    constraints = [(ca.sqrt(ca.sum1(delta * delta)) - ca.DM(problem.link_lengths).T) / longest]
    for obstacle in problem.obstacles:
        if not isinstance(obstacle, Disk):
            raise SolverError(f"the benchmark's IPOPT model handles disks only, not {obstacle.name!r}.")
        offset = nodes - ca.repmat(ca.DM(obstacle.center), 1, free.size)
        constraints.append((obstacle.radius**2 - ca.sum1(offset * offset)) / (2.0 * obstacle.radius))  # Disk's phi
    weights = problem.gravity * problem.masses[free] / (problem.weight * longest)
    options: dict[str, Any] = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.bound_relax_factor": 0.0,  # else IPOPT may stretch every link by 1e-8
        "ipopt.max_iter": 500,
    }
    model = {"x": z, "f": ca.dot(ca.DM(weights), nodes[1, :].T), "g": ca.vertcat(*[ca.vec(c) for c in constraints])}
    nlp = ca.nlpsol("bench", "ipopt", model, options)
    started = time.perf_counter()
    result = nlp(x0=start[free].ravel(), lbg=-np.inf, ubg=0.0)
    seconds = time.perf_counter() - started
    stats = nlp.stats()
    answer = start.copy()
    answer[free] = np.asarray(result["x"], dtype=np.float64).reshape(-1, 2)
    # Lagrangian f + lam^T g with f = E / (W l), g = (c / l, phi): funicular's mu = lam W, nu = lam W l.
    lam = np.asarray(result["lam_g"], dtype=np.float64).ravel() * problem.weight
    contact = np.zeros((len(problem.obstacles), problem.n_nodes))
    contact[:, free] = lam[problem.n_links :].reshape(len(problem.obstacles), free.size) * longest
    status = "optimal" if stats.get("success") else str(stats.get("return_status", "failed"))
    multipliers = Multipliers(lam[: problem.n_links], contact)
    return Outcome(answer, multipliers, status, int(stats.get("iter_count", 0)), seconds)


def run_clarabel(problem: Problem, tol: float) -> Outcome:
    import cvxpy as cp  # an optional competitor, loaded only when it runs

    if problem.obstacles:
        raise SolverError("Clarabel solves the obstacle-free chain only (a disk makes the problem non-convex).")
    longest = float(problem.link_lengths.max())
    p = cp.Variable((problem.n_nodes, 2))
    links = cp.SOC(problem.link_lengths / longest, (p[1:] - p[:-1]) / longest, axis=1)
    objective = cp.Minimize((problem.gravity * problem.masses / (problem.weight * longest)) @ p[:, 1])
    program = cp.Problem(objective, [p[problem.support_nodes] == problem.support_positions, links])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "solution may be inaccurate" is in the status word too
        program.solve(  # type: ignore[no-untyped-call]
            solver=cp.CLARABEL, tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol
        )
    stats = program.solver_stats
    if p.value is None:
        return Outcome(np.full((problem.n_nodes, 2), np.nan), None, str(program.status), stats.num_iters, None)
    # The cone's dual on its "t" part multiplies (||dp|| - l_k) / l against the energy / (W l): it is the tension / W.
    multipliers = Multipliers(np.asarray(links.dual_value[0]) * problem.weight, np.zeros((0, problem.n_nodes)))
    return Outcome(np.asarray(p.value), multipliers, str(program.status), stats.num_iters, stats.solve_time)


RUNNERS: dict[str, Callable[[Problem, float], Outcome]] = {
    "funicular": run_funicular,
    "ipopt": run_ipopt,
    "clarabel": run_clarabel,
    "slsqp": run_slsqp,
}


def missing_packages(solver: str) -> list[str]:
    return [name for name in REQUIRES.get(solver, ()) if importlib.util.find_spec(name) is None]


def skip_reason(solver: str, nodes: int, problem: str) -> str | None:
    """Why ``solver`` does not run on this instance (None: it runs)."""
    if missing_packages(solver):
        return f"not installed ({', '.join(missing_packages(solver))}; pip install 'funicular[bench]')"
    if solver == "clarabel" and problem == "disk":
        return "disk problems skipped (non-convex: not a second-order-cone program)"
    if nodes > MAX_NODES.get(solver, nodes):
        return f"skipped above N = {MAX_NODES[solver]:,}"
    return None


# --------------------------------------------------------------------------- measuring
@dataclass(frozen=True)
class Result:
    nodes: int
    problem: str
    solver: str
    seconds: float  # median wall time
    runs: int
    ratio: float | None  # seconds / funicular's seconds on the same instance, from the same run
    solver_seconds: float | None
    iterations: int | None
    energy: float
    energy_difference: float | None  # minus funicular's energy
    kkt: float | None  # largest scaled KKT residual from funicular.checks (None: infeasible)
    verdict: str  # the checker's: second-order verdict, or why the point is not a KKT point
    status: str


@dataclass(frozen=True)
class BackToBack:
    """funicular's wall time per solve over ``solves`` solves of one instance in a row (its caches
    warm, as in interactive use), after one more as a warm-up: percentiles in seconds."""

    nodes: int
    problem: str
    solves: int
    p10: float
    median: float
    p90: float


def back_to_back(nodes: int, kind: str, solves: int, tol: float) -> BackToBack:
    """Time ``solves`` funicular solves of the same instance in a row (see :class:`BackToBack`)."""
    problem = family(nodes, kind)
    solve(problem, tol=tol)
    seconds = []
    for _ in range(solves):
        started = time.perf_counter()
        solve(problem, tol=tol)
        seconds.append(time.perf_counter() - started)
    p10, median, p90 = (float(q) for q in np.percentile(seconds, [10, 50, 90]))
    return BackToBack(nodes, kind, solves, p10, median, p90)


def back_to_back_text(runs: Sequence[BackToBack]) -> list[str]:
    """The back-to-back section of the report (empty without runs)."""
    if not runs:
        return []
    lines = [
        "",
        f"funicular alone, {runs[0].solves} solves in a row of each small instance after one more (in one process,"
        " its caches warm, as in interactive use; the table above interleaves every solver, so each of its"
        " runs starts with caches another solver used):",
        "",
        "| N | problem | p10 [ms] | median [ms] | p90 [ms] |",
        "|---:|---|---:|---:|---:|",
    ]
    lines += [
        f"| {r.nodes:,} | {r.problem} | {1e3 * r.p10:.3g} | {1e3 * r.median:.3g} | {1e3 * r.p90:.3g} |" for r in runs
    ]
    return lines


def _verdict(problem: Problem, outcome: Outcome) -> tuple[float | None, str]:
    """Largest scaled KKT residual and the checker's verdict (multipliers recovered if the solver gave none)."""
    if not np.all(np.isfinite(outcome.positions)):
        return None, "no finite answer"
    report = check(problem, outcome.positions, outcome.multipliers)
    if report.violation is not None:
        return None, f"infeasible: {report.violation.text}"
    assert report.kkt is not None and report.second_order is not None
    kkt = scaled(report.kkt, problem).max()
    return kkt, report.second_order.verdict if report.kkt_holds else "not a KKT point"


def _timed(solver: str, problem: Problem, tol: float) -> tuple[Outcome, float]:
    started = time.perf_counter()
    try:
        outcome = RUNNERS[solver](problem, tol)
    except Exception as error:  # a competitor's failure is a result to report, whatever it raises
        if solver == "funicular":
            raise
        message = f"error: {type(error).__name__}: {error}".splitlines()[0]
        outcome = Outcome(np.full((problem.n_nodes, 2), np.nan), None, message, None, None)
    return outcome, time.perf_counter() - started


def measure(
    nodes: int, kind: str, solvers: Sequence[str], repeats: int, tol: float, competitor_tol: float
) -> list[Result]:
    """Every solver on one instance: a warm-up each, then ``repeats`` interleaved timed runs."""
    problem = family(nodes, kind)
    tolerances = {solver: tol if solver == "funicular" else competitor_tol for solver in solvers}
    answers: dict[str, Outcome] = {}
    runs: dict[str, list[tuple[Outcome, float]]] = {}
    for solver in solvers:
        answers[solver], seconds = _timed(solver, problem, tolerances[solver])
        runs[solver] = [(answers[solver], seconds)]
    timed = [s for s in solvers if not answers[s].status.startswith("error") and runs[s][0][1] <= ONCE_ABOVE]
    for solver in timed:
        runs[solver] = []
    for _ in range(repeats):
        for solver in timed:  # interleaved, so that a burst of load on the shared machine slows every solver alike
            runs[solver].append(_timed(solver, problem, tolerances[solver]))
    times = {solver: [seconds for _, seconds in runs[solver]] for solver in solvers}
    inner = {solver: [o.solver_seconds for o, _ in runs[solver] if o.solver_seconds is not None] for solver in solvers}
    reference_energy = problem.energy(answers["funicular"].positions) if "funicular" in answers else None
    reference_seconds = statistics.median(times["funicular"]) if "funicular" in times else None
    results = []
    for solver in solvers:
        answer, seconds = answers[solver], statistics.median(times[solver])
        kkt, verdict = _verdict(problem, answer)
        e = problem.energy(answer.positions)
        result = Result(
            nodes=nodes,
            problem=kind,
            solver=solver,
            seconds=seconds,
            runs=len(runs[solver]),
            ratio=None if reference_seconds is None else seconds / reference_seconds,
            solver_seconds=statistics.median(inner[solver]) if inner[solver] else None,
            iterations=answer.iterations,
            energy=e,
            energy_difference=None if reference_energy is None else e - reference_energy,
            kkt=kkt,
            verdict=verdict,
            status=answer.status,
        )
        results.append(result)
    return results


# --------------------------------------------------------------------------- output
def _cpu_model() -> str:
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    models = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name") and ":" in line]
    return models[0] if models else platform.processor() or platform.machine()


def machine() -> dict[str, str]:
    """What the numbers were measured on: platform, CPU, cores, load and package versions."""
    versions = {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__}
    for package in ("casadi", "cvxpy", "clarabel"):
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            versions[package] = importlib.metadata.version(package)
    return {
        "platform": platform.platform(),
        "cpu": _cpu_model(),
        "cores": str(os.cpu_count()),
        "load_average": f"{os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else "unknown",
        "versions": ", ".join(f"{name} {version}" for name, version in versions.items()),
    }


def _cell(value: float | None, spec: str) -> str:
    return "-" if value is None or not math.isfinite(value) else format(value, spec)


TABLE_HEADER = (
    "| N | problem | solver | median time [s] | / funicular | in solver [s] | runs | iterations "
    "| dE vs funicular | max scaled KKT | checker | status |"
)
TABLE_RULE = "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---|---|"


def table_row(r: Result) -> str:
    cells = [
        f"{r.nodes:,}", r.problem, r.solver, _cell(r.seconds, ".4g"), _cell(r.ratio, ".3g"),
        _cell(r.solver_seconds, ".4g"), str(r.runs), "-" if r.iterations is None else str(r.iterations),
        _cell(r.energy_difference, ".1e"), _cell(r.kkt, ".1e"), r.verdict, r.status,
    ]  # fmt: skip
    return "| " + " | ".join(cell.replace("|", "/") for cell in cells) + " |"


def preamble(settings: dict[str, Any], about: dict[str, str]) -> list[str]:
    return [
        "# funicular bench",
        "",
        f"Machine: {about['platform']}, {about['cpu']}, {about['cores']} cores, load average "
        f"{about['load_average']} at the start; {about['versions']}.",
        "",
        "Problem family: supports at (0, 0) and (1, 0), chain length 1.5, total mass 1 on N nodes, "
        "g = 1, norm formulation; disk: a disk of radius 0.25 centred at (0.5, -0.55) under the chain.",
        "",
        f"Median wall time of {settings['repeats']} runs after one warm-up, solvers interleaved on each instance "
        f"(runs slower than {ONCE_ABOVE:g} s: the warm-up is the one run); from the problem to the answer, model "
        "building included ('in solver': the time the competitor reports for its own solve). Tolerances: "
        f"funicular {settings['tol']:g} (scaled KKT residuals), competitors {settings['competitor_tol']:g} "
        "(IPOPT tol, Clarabel gap and feasibility, SLSQP ftol). dE: energy minus funicular's. "
        "KKT and checker: funicular.checks.check of each answer with the solver's own multipliers (SLSQP: "
        f"recovered from its positions), the verdict at the checker's tolerance {CHECK_TOL:g}.",
        "",
        TABLE_HEADER,
        TABLE_RULE,
    ]


COLOURS = {"funicular": "tab:blue", "ipopt": "tab:orange", "clarabel": "tab:green", "slsqp": "tab:red"}


def draw_curves(
    figure: Figure, curves: dict[tuple[str, str], list[tuple[int, float]]], xlabel: str, title: str
) -> None:
    """Median time against size on log-log axes, one curve per (solver, problem): a colour per
    solver, solid for the first problem named ("free") and dashed for the other."""
    ax = figure.add_subplot()
    for (solver, kind), points in curves.items():
        if points:
            nodes, seconds = zip(*points, strict=True)
            style = "o-" if kind == "free" else "s--"
            ax.loglog(nodes, seconds, style, color=COLOURS[solver], label=f"{solver} ({kind})")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("median wall time [s]")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def write_plot(path: str | None, draw: Callable[[Figure], None]) -> None:
    """The picture ``draw`` makes, saved to ``path`` (nothing without one)."""
    if path is not None:
        save_figure(path, draw)
        print(f"wrote {path}")


def draw_times(results: Sequence[Result], figure: Figure, about: dict[str, str]) -> None:
    """Median time against N: one colour per solver, dashed with the disk."""
    curves = {
        (solver, kind): [(r.nodes, r.seconds) for r in results if r.solver == solver and r.problem == kind]
        for solver in SOLVER_NAMES
        for kind in PROBLEMS
    }
    title = f"chain between two supports (dashed: with the disk)\n{about['cpu']}, {about['cores']} cores"
    draw_curves(figure, curves, "N (nodes)", title)


# --------------------------------------------------------------------------- profiling
Function = tuple[str, int, str]  # pstats' key: file, line, name
ROOT: Function = ("", 0, "")  # stands for the code that enabled the profiler


def own_phase(function: Function) -> str | None:
    """The phase a function's name puts it in, or None."""
    key = f"{Path(function[0]).name}:{function[2]}"
    return next((phase for phase, pattern in PHASE_PATTERNS if pattern.search(key)), None)


def phase_seconds(stats: pstats.Stats) -> tuple[dict[str, float], dict[Function, dict[str, float]]]:
    """Own time summed into :data:`PHASES`, and each function's split of its own time between them.

    A function runs in the phase of the outermost phase function above it, else in its own phase,
    else in "other". cProfile keeps only caller -> callee edges with their times, so a function's
    share of each outer phase is its callers' shares weighted by the time spent on each edge.
    """
    table: dict[Function, Any] = stats.stats  # type: ignore[attr-defined]  # not in typeshed
    above: dict[Function, dict[str | None, float]] = {f: {None: 1.0} for f in table}  # outermost phase above

    def inside(function: Function) -> dict[str | None, float]:  # the phases the function's own code runs in
        shares = dict(above.get(function, {None: 1.0}))  # ROOT and callers the profile did not see
        own = own_phase(function)
        if own is not None and None in shares:
            shares[own] = shares.get(own, 0.0) + shares.pop(None)
        return shares

    for _ in range(PROFILE_PASSES):  # callers before callees would need a DAG; recursion makes cycles
        change = 0.0
        for function, (_, _, _, cumulative, callers) in table.items():
            edges = {caller: edge[3] for caller, edge in callers.items()}
            edges[ROOT] = max(cumulative - sum(edges.values()), 0.0)  # called from outside the profile
            total = sum(edges.values())
            shares: dict[str | None, float] = {}
            for caller, seconds in edges.items():
                weight = seconds / total if total > 0 else 1.0 / len(edges)
                for phase, share in inside(caller).items():
                    shares[phase] = shares.get(phase, 0.0) + weight * share
            change = max(change, *(abs(shares.get(p, 0.0) - above[function].get(p, 0.0)) for p in {*shares, None}))
            above[function] = shares
        if change < 1e-12:
            break
    seconds = dict.fromkeys(PHASES, 0.0)
    split: dict[Function, dict[str, float]] = {}
    for function, (_, _, own_time, _, _) in table.items():
        split[function] = {}
        for phase, share in inside(function).items():
            name = phase or "other"
            seconds[name] += share * own_time
            split[function][name] = split[function].get(name, 0.0) + share
    return seconds, split


@dataclass(frozen=True)
class Profile:
    nodes: int
    problem: str
    status: str
    iterations: int
    seconds: float  # the profiled solve, profiler overhead included
    phases: dict[str, float]
    top: list[dict[str, Any]]  # the functions with the most own time


def _split_the_core(phases: dict[str, float], statistics: Mapping[str, float]) -> None:
    """cProfile sees the solver core as one call: its own statistics split that time between the
    phases (evaluation, the Newton systems, the polish's KKT systems; the rest of the core, its line
    searches' arithmetic and tests, counts as line search)."""
    core = statistics.get("core_seconds", 0.0)
    if core <= 0.0:
        return
    evaluation, newton, polish = (
        statistics.get(key, 0.0) for key in ("evaluation_seconds", "newton_seconds", "polish_seconds")
    )
    phases["other"] = max(phases["other"] - core, 0.0)
    phases["assembly/evaluation"] += evaluation
    phases["factorization"] += newton
    phases["polish"] += polish
    phases["line search"] += max(core - evaluation - newton - polish, 0.0)


def profile(nodes: int, kind: str, tol: float) -> Profile:
    """cProfile one funicular solve and sum its time into phases."""
    problem = family(nodes, kind)
    solve(family(WARM_UP_NODES, kind), tol=tol)  # first-call costs (imports, compiled kernels) are not the solve's
    profiler = cProfile.Profile()
    started = time.perf_counter()
    profiler.enable()
    solution = solve(problem, tol=tol)
    profiler.disable()
    seconds = time.perf_counter() - started
    stats = pstats.Stats(profiler)
    phases, split = phase_seconds(stats)
    _split_the_core(phases, solution.statistics)
    table: dict[Function, Any] = stats.stats  # type: ignore[attr-defined]
    ranked = sorted(table.items(), key=lambda item: -item[1][2])[:TOP_FUNCTIONS]
    top = [
        {
            "function": f"{Path(f[0]).name}:{f[1]}({f[2]})" if f[0] != "~" else f[2],
            "phase": max(split[f], key=lambda phase: split[f][phase]),
            "calls": calls,
            "own_seconds": own,
            "cumulative_seconds": cumulative,
        }
        for f, (_, calls, own, cumulative, _) in ranked
    ]
    return Profile(nodes, kind, solution.status.value, solution.iterations, seconds, phases, top)


def profile_text(p: Profile) -> list[str]:
    total = sum(p.phases.values()) or 1.0
    lines = [
        f"## Profile: funicular, {p.problem}, N = {p.nodes:,}",
        "",
        f"One solve under cProfile: {p.seconds:.3g} s (profiler overhead included), status {p.status}, "
        f"{p.iterations} iterations. Own time of every function, grouped into phases by function name; "
        "a function called inside a phase function counts for that phase.",
        "",
        "| phase | seconds | share |",
        "|---|---:|---:|",
    ]
    lines += [f"| {phase} | {seconds:.3g} | {seconds / total:.0%} |" for phase, seconds in p.phases.items()]
    lines += ["", "| function | phase | calls | own [s] | cumulative [s] |", "|---|---|---:|---:|---:|"]
    lines += [
        f"| `{f['function']}` | {f['phase']} | {f['calls']} | {f['own_seconds']:.3g} | {f['cumulative_seconds']:.3g} |"
        for f in p.top
    ]
    return lines


# --------------------------------------------------------------------------- command line
def parse_solvers(text: str) -> list[str]:
    names = [item.strip() for item in text.split(",") if item.strip()]
    unknown = [name for name in names if name not in SOLVER_NAMES]
    if unknown or not names:
        raise ScenarioError(
            f"--solvers: {unknown[0] if unknown else text!r} is not a solver; "
            f"give a comma-separated list from {','.join(SOLVER_NAMES)}."
        )
    return list(dict.fromkeys(names))  # in the given order, duplicates dropped


def _check_output(path: str | None, option: str) -> None:
    if path is not None and not Path(path).parent.is_dir():
        raise ScenarioError(
            f"{option}: cannot write {path!r}: the directory {str(Path(path).parent)!r} does not exist."
        )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = ",".join(map(str, DEFAULT_NODES))
    parser.add_argument(
        "--nodes", help=f"comma-separated node counts (default {defaults}; with --profile {PROFILE_NODES})"
    )
    parser.add_argument(
        "--problem", choices=[*PROBLEMS, "both"], help="free chain, chain over the disk, or both (default both; "
        "with --profile disk)"
    )  # fmt: skip
    parser.add_argument(
        "--solvers", default=",".join(SOLVER_NAMES), help="comma-separated (default: all; missing ones are skipped)"
    )
    parser.add_argument("--repeats", type=int, default=DEFAULT_REPEATS, help="timed runs after the warm-up")
    parser.add_argument(
        "--back-to-back",
        type=int,
        default=BACK_TO_BACK,
        metavar="K",
        help=f"then K funicular solves in a row of each instance up to {BACK_TO_BACK_UP_TO} nodes (default "
        f"{BACK_TO_BACK}; 0: none)",
    )
    parser.add_argument(
        "--tol", type=float, default=DEFAULT_TOL, help=f"funicular's tolerance (default {DEFAULT_TOL:g})"
    )
    parser.add_argument(
        "--competitor-tol", type=float, default=COMPETITOR_TOL, help=f"the competitors' (default {COMPETITOR_TOL:g})"
    )
    parser.add_argument("--markdown", metavar="FILE", help="write the report (Markdown)")
    parser.add_argument("--plot", metavar="FILE", help="draw time against N (.png, .svg or .pdf)")
    parser.add_argument("--json", metavar="FILE", help="write every number as JSON")
    parser.add_argument("--profile", action="store_true", help="profile one funicular solve instead (phases)")
    add_quiet_argument(parser)


def _instances(args: argparse.Namespace) -> tuple[list[int], list[str]]:
    """Node counts and problems from the options; the defaults differ for --profile."""
    if args.nodes is not None:
        nodes = parse_nodes(args.nodes)
    else:
        nodes = [PROFILE_NODES] if args.profile else list(DEFAULT_NODES)
    problem = args.problem or ("disk" if args.profile else "both")
    return nodes, list(PROBLEMS) if problem == "both" else [problem]


def _check_options(args: argparse.Namespace) -> None:
    """Every option that could fail is checked here, before anything is measured."""
    if args.repeats < 1:
        raise ScenarioError(f"--repeats: {args.repeats} is too small; give at least 1.")
    if args.back_to_back < 0:
        raise ScenarioError(f"--back-to-back: {args.back_to_back} is negative; give 0 (none) or more solves.")
    for option, value in (("--tol", args.tol), ("--competitor-tol", args.competitor_tol)):
        if not 0 < value < 1:
            raise ScenarioError(f"{option}: {shown(value)} must be a number between 0 and 1.")
    for option in ("markdown", "json", "plot"):
        _check_output(getattr(args, option), f"--{option}")
    if args.plot is not None and args.profile:
        raise ScenarioError("--plot draws the timing table; --profile writes phases (use --markdown or --json).")
    if args.plot is not None:
        check_plot_path(args.plot)


def skip_notes(solvers: Sequence[str], nodes: Sequence[int], kinds: Sequence[str]) -> list[str]:
    """One note per reason a solver is left out somewhere."""
    reasons = [(s, skip_reason(s, n, kind)) for kind in kinds for n in nodes for s in solvers]
    return list(dict.fromkeys(f"{s}: {reason}" for s, reason in reasons if reason is not None))


def run(args: argparse.Namespace) -> int:
    nodes, kinds = _instances(args)
    solvers = parse_solvers(args.solvers)
    _check_options(args)
    about = machine()
    if args.profile:
        return _run_profile(args, nodes, kinds, about)
    settings = {"nodes": nodes, "problems": kinds, "solvers": solvers, "repeats": args.repeats}
    settings |= {"tol": args.tol, "competitor_tol": args.competitor_tol}
    lines = preamble(settings, about)
    print("\n".join(lines), flush=True)
    results: list[Result] = []
    runs: list[BackToBack] = []
    repeated = [(kind, n) for kind in kinds for n in nodes if n <= BACK_TO_BACK_UP_TO]
    if not args.back_to_back or "funicular" not in solvers:
        repeated = []
    # The bar redraws only when an instance is done: no drawing thread runs while solves are timed.
    total = len(kinds) * len(nodes) + len(repeated)
    with progress_bar(total, "benchmark", quiet=args.quiet, minimum=1, auto_refresh=False) as advance:
        for kind in kinds:
            for n in nodes:
                running = [s for s in solvers if skip_reason(s, n, kind) is None]
                for result in measure(n, kind, running, args.repeats, args.tol, args.competitor_tol):
                    results.append(result)
                    lines.append(table_row(result))
                    print(lines[-1], flush=True)
                advance(1)
        for kind, n in repeated:
            runs.append(back_to_back(n, kind, args.back_to_back, args.tol))
            advance(1)
    section = back_to_back_text(runs)
    print("\n".join(section), flush=True)
    lines += section
    notes = skip_notes(solvers, nodes, kinds)
    notes += [
        f"{r.solver} at N = {r.nodes:,} ({r.problem}): {r.status}" for r in results if r.status.startswith("error")
    ]
    tail = ["", *(f"- {note}" for note in notes)]
    print("\n".join(tail))
    lines += tail
    if args.markdown is not None:
        atomic_write_text(args.markdown, "\n".join(lines) + "\n")
        print(f"wrote {args.markdown}")
    if args.json is not None:
        document = {
            "machine": about,
            "settings": settings,
            "results": [asdict(r) for r in results],
            "back_to_back": [asdict(r) for r in runs],
            "notes": notes,
        }
        atomic_write_text(args.json, to_json(document))
        print(f"wrote {args.json}")
    write_plot(args.plot, lambda figure: draw_times(results, figure, about))
    converged = all(r.status == "optimal" for r in results if r.solver == "funicular")
    return EXIT_OK if converged else EXIT_NOT_CONVERGED


def _run_profile(args: argparse.Namespace, nodes: Sequence[int], kinds: list[str], about: dict[str, str]) -> int:
    lines = [f"Machine: {about['platform']}, {about['cpu']}, {about['cores']} cores; {about['versions']}."]
    profiles = []
    for kind in kinds:
        for n in nodes:
            profiles.append(profile(n, kind, args.tol))
            lines += ["", *profile_text(profiles[-1])]
    print("\n".join(lines))
    if args.markdown is not None:
        atomic_write_text(args.markdown, "\n".join(lines) + "\n")
        print(f"wrote {args.markdown}")
    if args.json is not None:
        atomic_write_text(args.json, to_json({"machine": about, "profiles": [asdict(p) for p in profiles]}))
        print(f"wrote {args.json}")
    return EXIT_OK if all(p.status == "optimal" for p in profiles) else EXIT_NOT_CONVERGED


def parse_nodes(text: str) -> list[int]:
    """``"2,3,5"`` -> [2, 3, 5]; a ScenarioError names the first bad entry."""
    counts = []
    for item in text.split(","):
        try:
            count = int(item.strip())
        except ValueError:
            raise ScenarioError(f"--nodes: {item.strip()!r} is not an integer; give a list like 50,100,1000.") from None
        if count < 2:
            raise ScenarioError(f"--nodes: {count} is too small; a chain needs at least 2 nodes.")
        counts.append(count)
    return counts


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.run", description="Time funicular and other solvers as N grows (docs/benchmark.md)."
    )
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except FunicularError as error:
        print(f"python -m bench.run: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
