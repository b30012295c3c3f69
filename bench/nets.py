"""The nets benchmark: funicular against CVXPY + Clarabel and IPOPT (CasADi) on square cable nets.

Run from the repository::

    .venv/bin/python -m bench.nets --markdown docs/benchmark-nets.md --plot docs/benchmark-nets.png

The family: an n x n grid of nodes over the unit square, each node linked to its 4 neighbours by
a link 1.2 grid spacings long, the corners fixed at (0, 0, 0), (1, 0, 0), (0, 1, 0) and (1, 1, 0),
total mass 1 spread evenly, g = 1, norm formulation, 3-D; ``sphere`` adds a sphere of radius 0.3
centred at (0.5, 0.5, -0.45) that the nodes stay out of.

Competitors (each run only if its package is installed, the ``bench`` extra):

* CVXPY + Clarabel: the second-order-cone program ``||p_a - p_b|| / l <= l_k / l`` (l: the longest
  link), energy ``g m^T z / (W l)``, supports as equality constraints; tolerances gap (absolute and
  relative) and feasibility 1e-8. Without the sphere only: staying outside a ball is not convex.
  Scaled as in ``bench/run.py``, which says why scaling matters.
* IPOPT through CasADi, with and without the sphere: the free nodes as variables, energy / (W l),
  the links as ``(||p_a - p_b||^2 - l_k^2) / (2 l_k l) <= 0`` (``--ipopt-links squared``, the
  default) or ``(||p_a - p_b|| - l_k) / l <= 0`` (``norm``), the sphere as
  ``(r^2 - |p - c|^2) / (2 r) <= 0`` for every free node; exact Hessians from CasADi's SX graphs;
  tol 1e-8, ``max_iter`` 3000, ``max_wall_time`` 300 s, ``bound_relax_factor = 0`` (as ``bench/run.py``:
  otherwise IPOPT may stretch every link), MUMPS; started from the flat grid (z = 0), as a user would.
* funicular at its default tolerance (scaled KKT residuals below 1e-10).

Timing: one small net per solver first (imports and first-call costs are not measured), then for
each instance rounds of every solver in turn (interleaved, so that load on the shared machine
hits them alike) until each has ``repeats`` runs; a first run slower than ``ONCE_ABOVE`` seconds
is that solver's only run there. The table shows medians, from the ``Problem`` to the positions
with model building included, and "in solver": the time the competitor reports for its own solve
(Clarabel's ``solve_time``, the IPOPT call without CasADi's model building). A competitor that
failed or took longer than ``GIVE_UP_AFTER`` seconds is not run on larger nets of that kind; a
size in ``--extra-nodes`` runs only for funicular and Clarabel, and only where the time predicted
from the two smaller sizes stays under ``EXTRA_BUDGET`` seconds.

Checks: every answer's KKT residuals are recomputed by funicular
(:func:`funicular._diagnostics.kkt_residuals`, scaled by the weight and the longest link) from
its positions and the solver's own duals in funicular's conventions: link multiplier = tension
(Clarabel: the cone dual's scalar part times W; IPOPT: ``lam_g`` times W, times ``d_k / l_k`` for
the squared form), sphere multiplier of ``phi = (r^2 - |p - c|^2) / (2 r)`` (IPOPT: ``lam_g W l``).
"dE" is the solver's energy ``g m^T z`` minus funicular's.

Set OPENBLAS_NUM_THREADS=1 (this script does so when it is unset, before numpy is loaded): every
solver runs with single-threaded BLAS, as in ``bench/run.py`` (docs/performance.md says why).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported

import argparse
import json
import math
import statistics
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from bench.run import draw_curves, machine, missing_packages, write_plot
from funicular._diagnostics import kkt_residuals, scaled
from funicular._io import atomic_write_text
from funicular._solver import solve
from funicular._text import to_json
from funicular.errors import FunicularError, ScenarioError
from funicular.model import FloatArray, IntArray, Problem
from funicular.obstacles import Sphere
from funicular.plot import check_plot_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT = 0, 1, 2
SOLVERS = ("funicular", "clarabel", "ipopt")
KINDS = ("free", "sphere")
DEFAULT_NODES = (20, 50, 70)  # n: n x n nodes
DEFAULT_EXTRA_NODES = (100,)
EXTRA_SOLVERS = ("funicular", "clarabel")  # the only ones tried at the extra sizes
DEFAULT_REPEATS = 3
COMPETITOR_TOL = 1e-8
IPOPT_MAX_ITER = 3000
IPOPT_MAX_SECONDS = 300.0  # its max_wall_time: a run that long tells enough (the give-up rule is 120 s)
ONCE_ABOVE = 30.0  # seconds: a first run slower than this is the only run
GIVE_UP_AFTER = 120.0  # seconds: slower (or failed) here, a competitor skips the larger nets
EXTRA_BUDGET = 90.0  # seconds: an extra size runs only if its predicted time stays below this
SLACK = 1.2  # link length / grid spacing
SPHERE = Sphere(center=(0.5, 0.5, -0.45), radius=0.3)
WARM_UP_N = 5


# --------------------------------------------------------------------------- instances
def grid_links(n: int) -> IntArray:
    """The 4-neighbourhood of an n x n grid, node ``i * n + j`` at (x, y) = (i, j) / (n - 1)."""
    index = np.arange(n * n).reshape(n, n)
    along_y = np.column_stack((index[:, :-1].ravel(), index[:, 1:].ravel()))
    along_x = np.column_stack((index[:-1, :].ravel(), index[1:, :].ravel()))
    return np.vstack((along_y, along_x))


def flat_grid(n: int) -> FloatArray:
    """Every node at its grid point, z = 0 (N, 3): the competitors' start."""
    x, y = np.meshgrid(np.linspace(0.0, 1.0, n), np.linspace(0.0, 1.0, n), indexing="ij")
    return np.column_stack((x.ravel(), y.ravel(), np.zeros(n * n)))


def net(n: int, kind: str = "free") -> Problem:
    """The benchmark net with n x n nodes; ``kind="sphere"`` adds the sphere."""
    pairs = grid_links(n)
    length = SLACK / (n - 1)
    corners = [(0, (0.0, 0.0, 0.0)), ((n - 1) * n, (1.0, 0.0, 0.0)), (n - 1, (0.0, 1.0, 0.0))]
    corners.append((n * n - 1, (1.0, 1.0, 0.0)))
    return Problem.build(
        nodes=n * n,
        links=[[int(a), int(b), length] for a, b in pairs],
        supports=corners,
        mass=1.0,
        gravity=1.0,
        dimension=3,
        obstacles=[SPHERE] if kind == "sphere" else [],
    )


def incidence(problem: Problem) -> sp.csr_matrix:
    """(L, N): row k is +1 at link k's first node and -1 at its second, so ``D @ P`` are the deltas."""
    pairs = problem.link_nodes
    rows = np.repeat(np.arange(problem.n_links), 2)
    values = np.tile([1.0, -1.0], problem.n_links)
    return sp.csr_matrix((values, (rows, pairs.ravel())), shape=(problem.n_links, problem.n_nodes))


# --------------------------------------------------------------------------- solvers
@dataclass(frozen=True)
class Outcome:
    """One answer: positions (N, 3), tensions and sphere multipliers (funicular's conventions) if the
    solver gives duals, its own status word, iterations and solve time if it reports them."""

    positions: FloatArray
    tensions: FloatArray | None
    contact: FloatArray | None  # (n_obstacles, N)
    status: str
    iterations: int | None
    solver_seconds: float | None
    statistics: dict[str, float] = field(default_factory=dict)


def run_funicular(problem: Problem, _: float) -> Outcome:
    solution = solve(problem)  # the default tolerance, 1e-10
    contact = solution.obstacle_multipliers if problem.obstacles else None
    return Outcome(
        solution.positions,
        solution.link_multipliers,  # norm formulation: the tensions
        contact,
        solution.status.value,
        solution.iterations,
        solution.solve_seconds,
        {**solution.statistics, "solve_seconds": solution.solve_seconds},
    )


def run_clarabel(problem: Problem, tol: float) -> Outcome:
    import cvxpy as cp  # an optional competitor, loaded only when it runs

    if problem.obstacles:
        raise ValueError("Clarabel solves the net without the sphere only (a ball to stay out of is not convex)")
    longest = float(problem.link_lengths.max())
    p = cp.Variable((problem.n_nodes, 3))
    links = cp.SOC(problem.link_lengths / longest, (incidence(problem) / longest) @ p, axis=1)
    weights = problem.gravity * problem.masses / (problem.weight * longest)
    program = cp.Problem(cp.Minimize(weights @ p[:, 2]), [p[problem.support_nodes] == problem.support_positions, links])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "solution may be inaccurate" is in the status word too
        program.solve(  # type: ignore[no-untyped-call]
            solver=cp.CLARABEL, tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol
        )
    stats = program.solver_stats
    if p.value is None:
        nan = np.full((problem.n_nodes, 3), np.nan)
        return Outcome(nan, None, None, str(program.status), stats.num_iters, stats.solve_time)
    # The cone dual's scalar part multiplies (||dp|| - l_k) / l against energy / (W l): tension / W.
    tensions = np.asarray(links.dual_value[0], dtype=np.float64) * problem.weight
    return Outcome(np.asarray(p.value), tensions, None, str(program.status), stats.num_iters, stats.solve_time)


def run_ipopt(problem: Problem, tol: float, links_form: str) -> Outcome:
    import casadi as ca  # an optional competitor, loaded only when it runs

    n = math.isqrt(problem.n_nodes)
    start = flat_grid(n)
    free = problem.free_nodes
    longest = float(problem.link_lengths.max())
    lengths = problem.link_lengths
    z = ca.SX.sym("z", 3 * free.size)
    nodes = ca.reshape(z, 3, free.size)  # column c: free node c
    # All positions (3, N) = free nodes placed by a sparse selection + the supports' constant columns.
    place = sp.csr_matrix((np.ones(free.size), (np.arange(free.size), free)), shape=(free.size, problem.n_nodes))
    fixed = np.zeros((3, problem.n_nodes))
    fixed[:, problem.support_nodes] = problem.support_positions.T
    positions = ca.mtimes(nodes, _casadi_sparse(ca, place)) + ca.DM(fixed)
    delta = ca.mtimes(positions, _casadi_sparse(ca, incidence(problem).T.tocsr()))  # (3, L)
    squares = ca.sum1(delta * delta)
    if links_form == "squared":
        link_constraint = (squares - ca.DM(lengths**2).T) / ca.DM(2.0 * lengths * longest).T
    else:
        link_constraint = (ca.sqrt(squares) - ca.DM(lengths).T) / longest
    constraints = [ca.vec(link_constraint)]
    for obstacle in problem.obstacles:
        assert isinstance(obstacle, Sphere)
        offset = nodes - ca.repmat(ca.DM(obstacle.center), 1, free.size)
        constraints.append(ca.vec((obstacle.radius**2 - ca.sum1(offset * offset)) / (2.0 * obstacle.radius)))
    weights = problem.gravity * problem.masses[free] / (problem.weight * longest)
    options: dict[str, Any] = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.bound_relax_factor": 0.0,
        "ipopt.max_iter": IPOPT_MAX_ITER,
        "ipopt.max_wall_time": IPOPT_MAX_SECONDS,
    }
    model = {"x": z, "f": ca.dot(ca.DM(weights), nodes[2, :].T), "g": ca.vertcat(*constraints)}
    solver = ca.nlpsol("nets", "ipopt", model, options)
    started = time.perf_counter()
    result = solver(x0=start[free].ravel(), lbg=-np.inf, ubg=0.0)
    seconds = time.perf_counter() - started
    stats = solver.stats()
    answer = start.copy()
    answer[free] = np.asarray(result["x"], dtype=np.float64).reshape(-1, 3)
    lam = np.asarray(result["lam_g"], dtype=np.float64).ravel()
    # Lagrangian f + lam^T g, f = E / (W l): norm g = (d - l_k) / l gives T = lam W; squared
    # g = (d^2 - l_k^2) / (2 l_k l), gradient delta / (l_k l), gives T = lam W d / l_k.
    tensions = lam[: problem.n_links] * problem.weight
    if links_form == "squared":
        distances = np.linalg.norm(answer[problem.link_nodes[:, 0]] - answer[problem.link_nodes[:, 1]], axis=1)
        tensions = tensions * distances / lengths
    contact = None
    if problem.obstacles:
        contact = np.zeros((len(problem.obstacles), problem.n_nodes))
        contact[:, free] = lam[problem.n_links :].reshape(len(problem.obstacles), free.size) * problem.weight * longest
    status = str(stats.get("return_status", "unknown"))
    return Outcome(answer, tensions, contact, status, int(stats.get("iter_count", 0)), seconds)


def _casadi_sparse(ca: Any, matrix: sp.csr_matrix) -> Any:
    """A scipy CSR matrix as a sparse CasADi DM."""
    csc = matrix.tocsc()
    pattern = ca.Sparsity(csc.shape[0], csc.shape[1], csc.indptr.tolist(), csc.indices.tolist())
    return ca.DM(pattern, csc.data.tolist())


Runner = Callable[[Problem, float], Outcome]


def runners(ipopt_links: str) -> dict[str, Runner]:
    return {
        "funicular": run_funicular,
        "clarabel": run_clarabel,
        "ipopt": lambda problem, tol: run_ipopt(problem, tol, ipopt_links),
    }


def succeeded(solver: str, status: str) -> bool:
    return status in {"funicular": ("optimal",), "clarabel": ("optimal",), "ipopt": ("Solve_Succeeded",)}[solver]


# --------------------------------------------------------------------------- measuring
@dataclass(frozen=True)
class Result:
    n: int
    kind: str
    solver: str
    seconds: float  # median wall time
    runs: int
    ratio: float | None  # seconds / funicular's seconds on the same instance
    solver_seconds: float | None
    iterations: int | None
    energy: float
    energy_difference: float | None  # minus funicular's energy
    kkt: float | None  # largest scaled KKT residual recomputed by funicular (None: no duals or no answer)
    status: str
    statistics: dict[str, float]
    cpu_seconds: float | None = None  # median CPU time of the process, every thread's


def _timed(run: Runner, solver: str, problem: Problem) -> tuple[Outcome, float, float]:
    """The outcome, its wall time and the process's CPU time (every thread's) over the run."""
    started, cpu = time.perf_counter(), time.process_time()
    try:
        outcome = run(problem, COMPETITOR_TOL)
    except (KeyboardInterrupt, SystemExit):
        raise
    # A failure is a result to report, whatever it raises (a panic of a compiled core is a BaseException).
    except BaseException as error:
        text = next((line.strip() for line in str(error).splitlines() if line.strip()), "")
        message = f"error: {type(error).__name__}: {text}"
        outcome = Outcome(np.full((problem.n_nodes, 3), np.nan), None, None, message, None, None)
    return outcome, time.perf_counter() - started, time.process_time() - cpu


def kkt_of(problem: Problem, outcome: Outcome) -> float | None:
    """Largest scaled KKT residual of an answer with its duals, as funicular computes it."""
    if outcome.tensions is None or not np.all(np.isfinite(outcome.positions)):
        return None
    residuals = kkt_residuals(problem, outcome.positions, outcome.tensions, outcome.contact)
    return float(scaled(residuals, problem).max())


def measure(n: int, kind: str, solvers: Sequence[str], repeats: int, run: dict[str, Runner]) -> list[Result]:
    """Every solver on one instance, interleaved: rounds of one run each until ``repeats`` runs
    (a first run slower than ONCE_ABOVE is the only one)."""
    problem = net(n, kind)
    runs: dict[str, list[tuple[Outcome, float, float]]] = {solver: [] for solver in solvers}
    for round_ in range(repeats):
        for solver in solvers:
            if round_ > 0 and (runs[solver][0][1] > ONCE_ABOVE or runs[solver][0][0].status.startswith("error")):
                continue
            runs[solver].append(_timed(run[solver], solver, problem))
            print(f"  n = {n} {kind} {solver}: {runs[solver][-1][1]:.3g} s", file=sys.stderr, flush=True)
    reference = runs["funicular"][0][0] if "funicular" in runs else None
    answered = reference is not None and bool(np.all(np.isfinite(reference.positions)))
    reference_energy = problem.energy(reference.positions) if answered and reference is not None else None
    reference_seconds = statistics.median(s for _, s, _ in runs["funicular"]) if answered else None
    results = []
    for solver in solvers:
        answer = runs[solver][0][0]  # the answer checked: the first run's (every run gives the same)
        seconds = statistics.median(s for _, s, _ in runs[solver])
        inner = [o.solver_seconds for o, _, _ in runs[solver] if o.solver_seconds is not None]
        energy = problem.energy(answer.positions)
        results.append(
            Result(
                n=n,
                kind=kind,
                solver=solver,
                seconds=seconds,
                runs=len(runs[solver]),
                ratio=None if reference_seconds is None else seconds / reference_seconds,
                solver_seconds=statistics.median(inner) if inner else None,
                iterations=answer.iterations,
                energy=energy,
                energy_difference=None if reference_energy is None else energy - reference_energy,
                kkt=kkt_of(problem, answer),
                status=answer.status,
                statistics=answer.statistics,
                cpu_seconds=statistics.median(c for _, _, c in runs[solver]),
            )
        )
    return results


def warm_up(solvers: Sequence[str], run: dict[str, Runner]) -> None:
    """One small net per solver and kind: imports and first-call costs are not measured."""
    for kind in KINDS:
        problem = net(WARM_UP_N, kind)
        for solver in solvers:
            _timed(run[solver], solver, problem)


def funicular_build() -> str:
    """Which funicular was measured: the commit, and whether the core's sources differ from it."""
    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "rust"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "funicular from an unknown commit"
    return f"funicular at commit {commit}" + (" (its core built from uncommitted changes to rust/)" if dirty else "")


def predicted_seconds(history: Sequence[tuple[int, float]], n: int) -> float | None:
    """Time at grid size n extrapolated from the last two sizes: a power of n fitted to them, between
    n^2 and n^8 (the node count to the power 1 to 4); n^6 from a single size."""
    if not history:
        return None
    (n1, t1), (n2, t2) = history[-2] if len(history) > 1 else history[-1], history[-1]
    exponent = 6.0 if n1 == n2 else min(max(math.log(t2 / t1) / math.log(n2 / n1), 2.0), 8.0)
    return float(t2 * (n / n2) ** exponent)


# --------------------------------------------------------------------------- output
# Why the squared link constraint for IPOPT: both forms tried once with this script (--ipopt-links)
# on the same machine, while choosing.
IPOPT_CHOICE = [
    "",
    "  IPOPT's link constraint is the squared form, the one it does best on these nets: tried once each with "
    "`--ipopt-links`, the squared form took 20 iterations (0.14 s) at n = 20 without the sphere and 25 (1.5 s) at "
    "n = 50, the norm form 26 (0.22 s) at n = 20 and had not finished n = 50 after ten minutes. With the sphere at "
    "n = 20 the norm form took 223 iterations (1.3 s) against 33 (0.26 s), though it ended at funicular's "
    "equilibrium and the squared form at a higher one (see dE).",
]


def _cell(value: float | None, spec: str) -> str:
    return "-" if value is None or not math.isfinite(value) else format(value, spec)


TABLE_HEADER = (
    "| n | nodes | problem | solver | median time [s] | CPU [s] | / funicular | in solver [s] | runs | iterations "
    "| dE vs funicular | max scaled KKT | status |"
)
TABLE_RULE = "|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"
STATISTICS_HEADER = (
    "| n | problem | iterations | interior-point steps | polish steps | factorizations | Newton [s] | polish [s] "
    "| core [s] | solve [s] |"
)
STATISTICS_RULE = "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"


def table_row(r: Result) -> str:
    cells = [
        str(r.n), f"{r.n * r.n:,}", r.kind, r.solver, _cell(r.seconds, ".4g"), _cell(r.cpu_seconds, ".4g"),
        _cell(r.ratio, ".3g"),
        _cell(r.solver_seconds, ".4g"), str(r.runs), "-" if r.iterations is None else str(r.iterations),
        _cell(r.energy_difference, ".1e"), _cell(r.kkt, ".1e"), r.status,
    ]  # fmt: skip
    return "| " + " | ".join(cell.replace("|", "/") for cell in cells) + " |"


def statistics_row(r: Result) -> str:
    s = r.statistics
    cells = [
        str(r.n), r.kind, str(r.iterations), _cell(s.get("interior_point_steps"), ".0f"),
        _cell(s.get("polish_steps"), ".0f"), _cell(s.get("factorizations"), ".0f"),
        _cell(s.get("newton_seconds"), ".3g"), _cell(s.get("polish_seconds"), ".3g"),
        _cell(s.get("core_seconds"), ".3g"), _cell(s.get("solve_seconds"), ".3g"),
    ]  # fmt: skip
    return "| " + " | ".join(cells) + " |"


def preamble(about: dict[str, str], settings: dict[str, Any]) -> list[str]:
    load = float(about["load_average"]) if about["load_average"] != "unknown" else math.nan
    busy = (
        f" The load average was {about['load_average']} on {about['cores']} cores: other jobs shared the "
        "machine, so the times are slower and noisier than on an idle one (the interleaving spreads that "
        "over every solver alike)."
        if load > 0.5 * int(about["cores"])
        else ""
    )
    ipopt_links = (
        "`(|p_a - p_b|^2 - l_k^2) / (2 l_k l) <= 0` (squared)"
        if settings["ipopt_links"] == "squared"
        else "`(|p_a - p_b| - l_k) / l <= 0` (norm)"
    )
    return [
        "# Benchmark: nets",
        "",
        "funicular against CVXPY + Clarabel and IPOPT (through CasADi) on hanging cable nets, side by side in "
        "one run. Generated by `python -m bench.nets` (`make bench-nets`: `.venv/bin/python -m bench.nets --markdown "
        "docs/benchmark-nets.md --plot docs/benchmark-nets.png`); the chain benchmark is in "
        "[Performance](performance.md#n-50-to-100000).",
        "",
        "![Median time against the number of nodes, each solver; dashed: over the sphere](benchmark-nets.png)",
        "",
        "## Machine",
        "",
        f"{about['platform']}, {about['cpu']}, {about['cores']} cores, load average {about['load_average']} at "
        f"the start; {about['versions']}; {about.get('funicular', 'funicular')}. BLAS single-threaded "
        f"(`OPENBLAS_NUM_THREADS=1`).{busy}",
        "",
        "## Problem family",
        "",
        "An n x n grid of nodes over the unit square, each node linked to its 4 neighbours by a link 1.2 grid "
        "spacings long (`1.2 / (n - 1)`), the corners fixed at (0, 0, 0), (1, 0, 0), (0, 1, 0) and (1, 1, 0), total "
        "mass 1 spread evenly over the n^2 nodes, g = 1, norm formulation, in 3-D. *sphere*: the same net over a "
        "sphere of radius 0.3 centred at (0.5, 0.5, -0.45), the nodes kept out of it. In Python:",
        "",
        "```python",
        "import funicular",
        "from funicular.obstacles import Sphere",
        "",
        "n = 20",
        "node = [[i * n + j for j in range(n)] for i in range(n)]  # at (x, y) = (i, j) / (n - 1)",
        "links = [[node[i][j], node[i][j + 1], 1.2 / (n - 1)] for i in range(n) for j in range(n - 1)]",
        "links += [[node[i][j], node[i + 1][j], 1.2 / (n - 1)] for i in range(n - 1) for j in range(n)]",
        "corners = [(node[0][0], (0, 0, 0)), (node[-1][0], (1, 0, 0)), (node[0][-1], (0, 1, 0)), "
        "(node[-1][-1], (1, 1, 0))]",
        "problem = funicular.Problem.build(",
        "    nodes=n * n, links=links, supports=corners, mass=1.0, gravity=1.0, dimension=3,",
        "    obstacles=[Sphere(center=(0.5, 0.5, -0.45), radius=0.3)],  # without it: the free net",
        ")",
        "assert problem.n_links == 2 * n * (n - 1)",
        "```",
        "",
        "## Method",
        "",
        "* **funicular**: `funicular.solve(problem)` at its default tolerance (scaled KKT residuals below 1e-10), "
        "from its own start.",
        "* **Clarabel** through CVXPY: the second-order-cone program `||p_a - p_b|| / l <= l_k / l` (l: the longest "
        "link), minimize `g m^T z / (W l)` (W: the weight), supports as equality constraints; tolerances "
        f"{settings['competitor_tol']:g} (gap absolute and relative, feasibility). Without the sphere only: "
        "staying out of a ball is not convex.",
        "* **IPOPT** through CasADi, with and without the sphere: the free nodes as variables, links as "
        f"{ipopt_links}, the sphere as `(r^2 - |p - c|^2) / (2 r) <= 0` for every free node "
        "(that is `|p - c|^2 >= r^2`), "
        f"energy / (W l), exact Hessians, tol {settings['competitor_tol']:g}, max_iter {IPOPT_MAX_ITER}, "
        f"wall time capped at {IPOPT_MAX_SECONDS:g} s (`max_wall_time`, checked between iterations; an uncapped run "
        "of n = 70 with the sphere had not ended after 25 minutes), "
        "`bound_relax_factor = 0`, MUMPS; started from the flat grid (every node at its grid point, z = 0), "
        "as a user would.",
        *(IPOPT_CHOICE if settings["ipopt_links"] == "squared" else []),
        "",
        f"Times are the median of {settings['repeats']} runs (one run where the first took more than "
        f"{ONCE_ABOVE:g} s), the solvers interleaved on each instance after one small warm-up net each, from the "
        "problem to the answer with model building included; *in solver* is what the competitor reports for its "
        "own solve (Clarabel's `solve_time`, the IPOPT call without CasADi's model building; for funicular its "
        "`solve_seconds`). *CPU*: the median CPU time of the process over the same runs, every thread counted: "
        "funicular factors a net of 5,000 nodes and more on two threads (`FUNICULAR_THREADS`), the competitors' "
        "BLAS runs on one. *dE*: energy `g m^T z` minus funicular's. *max scaled KKT*: the largest of the four "
        "KKT residuals (stationarity, feasibility, dual feasibility, complementarity) of the answer, recomputed by "
        "funicular from its positions and the solver's own duals converted to funicular's conventions (link "
        "multiplier = tension; IPOPT's squared form: tension = `lam W d_k / l_k`), divided by the weight and the "
        "longest link. *status*: the solver's own word. A competitor that failed or took longer than "
        f"{GIVE_UP_AFTER:g} s is not run on larger nets"
        + (
            f"; n = {', '.join(str(n) for n in settings['extra_nodes'])} runs for funicular and Clarabel only, "
            f"where the time predicted from the two smaller sizes stays under {EXTRA_BUDGET:g} s."
            if settings["extra_nodes"]
            else "."
        ),
        "",
        "## Results",
        "",
        TABLE_HEADER,
        TABLE_RULE,
    ]


def funicular_section(results: Sequence[Result]) -> list[str]:
    rows = [statistics_row(r) for r in results if r.solver == "funicular"]
    if not rows:
        return []
    return [
        "",
        "funicular's own statistics on each instance (one solve: the checked one): iterations, interior-point "
        "steps, polish steps (Newton steps on the active set's KKT system), factorizations of the sparse Newton "
        "matrix, and seconds spent in the Newton systems, in the polish, in the compiled core altogether, and in "
        "the whole solve:",
        "",
        STATISTICS_HEADER,
        STATISTICS_RULE,
        *rows,
    ]


# funicular's saddle escape on nets (NET_ESCAPE_UP_TO in rust/core/src/net.rs; docs/nets.md, Limits).
NET_ESCAPE_UP_TO = 1000
ENERGY_GAP = 1e-6  # |dE| above this (the weight is 1): a different local minimum, not a tolerance


def findings(results: Sequence[Result]) -> list[str]:
    """What the numbers state, sentence by sentence: who is faster where, where funicular's time
    goes against the competitors' iterations, and which answers differ."""
    lines = ["", "## What it shows", ""]
    lines.append(
        "Generated from the numbers above. Speed (median wall time, model building included, against funicular's "
        "on the same instance):"
    )
    lines.append("")
    for solver in SOLVERS[1:]:
        for kind in KINDS:
            mine = [r for r in results if r.solver == solver and r.kind == kind and r.ratio is not None]
            if mine:
                lines.append(f"* {solver}, {kind}: " + "; ".join(f"n = {r.n}: {_speed(r)}" for r in mine) + ".")
    lines += ["", *_summary(results)]
    lines += ["", "Where the time goes (funicular's statistics against the competitors' iteration counts):", ""]
    by_instance = {(r.n, r.kind, r.solver): r for r in results}
    for r in results:
        if r.solver != "funicular" or not r.statistics:
            continue
        s = r.statistics
        newton, polish, whole = (s.get(key, 0.0) for key in ("newton_seconds", "polish_seconds", "solve_seconds"))
        factorizations = s.get("factorizations", 0.0)
        sentence = (
            f"* {r.kind}, n = {r.n}: funicular {s.get('interior_point_steps', 0):.0f} interior-point steps "
            f"({factorizations:.0f} factorizations, {_per(newton, factorizations)} each) and "
            f"{s.get('polish_steps', 0):.0f} polish steps; of its {whole:.3g} s, {_share(newton, whole)} in the "
            f"Newton systems and {_share(polish, whole)} in the polish"
        )
        for solver in SOLVERS[1:]:
            other = by_instance.get((r.n, r.kind, solver))
            if other is not None and other.iterations and other.solver_seconds is not None:
                sentence += (
                    f"; {solver} {other.iterations} iterations, {_per(other.solver_seconds, other.iterations)} "
                    "each in its solver"
                )
        lines.append(sentence + ".")
    lines += ["", "Answers:", ""]
    lines += _answers(results)
    return lines


def _summary(results: Sequence[Result]) -> list[str]:
    """Failures, and for every instance where funicular is slower than a competitor that succeeded:
    whether it takes more steps (interior-point plus polish, against the competitor's iterations)
    or dearer ones (seconds per factorization against seconds per iteration in the solver)."""
    sentences = []
    for r in results:
        if not (succeeded(r.solver, r.status) or r.status.startswith("optimal")):
            sentences.append(
                f"* {r.solver} did not converge on {r.kind}, n = {r.n}: {r.status} after {r.seconds:.3g} s."
            )
    mine = {(r.n, r.kind): r for r in results if r.solver == "funicular" and succeeded("funicular", r.status)}
    for r in results:
        reference = mine.get((r.n, r.kind))
        if r.solver == "funicular" or reference is None or r.ratio is None or r.ratio >= 1:
            continue
        if not succeeded(r.solver, r.status) or not r.iterations or r.solver_seconds is None:
            continue
        s = reference.statistics
        steps = s.get("interior_point_steps", 0.0) + s.get("polish_steps", 0.0)
        per_step = s.get("newton_seconds", 0.0) / max(s.get("factorizations", 0.0), 1.0)
        per_iteration = r.solver_seconds / r.iterations
        reasons = []
        if steps > r.iterations:
            reasons.append(f"more steps ({steps:.0f} against {r.iterations} iterations)")
        if per_step > per_iteration:
            reasons.append(f"dearer ones ({_per(per_step, 1)} per factorization against {_per(per_iteration, 1)})")
        else:
            reasons.append(
                f"not dearer ones ({_per(per_step, 1)} per factorization against {_per(per_iteration, 1)} per "
                "iteration)"
            )
        sentences.append(
            f"* {r.solver} is {1 / r.ratio:.3g}x faster than funicular on {r.kind}, n = {r.n}: funicular takes "
            + " but ".join(reasons)
            + "."
        )
    if sentences:
        sentences.insert(0, "Failures, and where funicular is slower, why as far as its statistics show:")
        sentences.insert(1, "")
    return sentences


def _answers(results: Sequence[Result]) -> list[str]:
    """Energy differences beyond a tolerance, and the KKT residuals' range per solver."""
    sentences = []
    for r in results:
        if r.solver == "funicular" or r.energy_difference is None or abs(r.energy_difference) <= ENERGY_GAP:
            continue
        if not succeeded(r.solver, r.status):
            continue  # a failed answer's energy says nothing about the equilibria (the status says it failed)
        lower = "funicular's" if r.energy_difference > 0 else f"{r.solver}'s"
        higher = f"{r.solver}'s" if r.energy_difference > 0 else "funicular's"
        sentence = (
            f"* {r.kind}, n = {r.n}: {r.solver}'s energy differs from funicular's by {r.energy_difference:+.2g} "
            "(the weight is 1)"
        )
        if r.kind == "free":
            sentence += f": the problem is convex, so the higher one, {higher}, is short of the minimum."
        else:
            sentence += (
                f": the two stopped at different equilibria, {lower} the lower. With the sphere the problem is not "
                "convex, and a small KKT residual shows a stationary point, not the lowest one."
            )
            if r.energy_difference < 0 and r.n * r.n > NET_ESCAPE_UP_TO:
                sentence += (
                    f" funicular's escape from saddles runs on nets of up to {NET_ESCAPE_UP_TO} nodes "
                    "([Nets and 3-D](nets.md#limits)), and this one has "
                    f"{r.n * r.n:,}."
                )
        sentences.append(sentence)
    if not sentences:
        sentences.append(f"* Every answer's energy is within {ENERGY_GAP:g} of funicular's.")
    for solver in SOLVERS:
        values = [r.kkt for r in results if r.solver == solver and r.kkt is not None]
        if values:
            sentences.append(
                f"* {solver}: max scaled KKT residual from {min(values):.1e} to {max(values):.1e} over its answers."
            )
    return sentences


def _per(seconds: float, count: float) -> str:
    return f"{1e3 * seconds / count:.3g} ms" if count > 0 else "-"


def _speed(r: Result) -> str:
    assert r.ratio is not None
    if not (succeeded(r.solver, r.status) or r.status.startswith("optimal")):
        return f"{r.status} after {r.seconds:.3g} s"
    if r.ratio >= 1:
        return f"funicular {r.ratio:.3g}x faster"
    return f"funicular {1 / r.ratio:.3g}x slower"


def _share(part: float, whole: float) -> str:
    return f"{part / whole:.0%}" if whole > 0 else "-"


# --------------------------------------------------------------------------- command line
def parse_sizes(text: str, option: str) -> list[int]:
    sizes = []
    for item in (item.strip() for item in text.split(",")):
        if not item:
            continue
        if not item.isdigit() or int(item) < 2:
            raise ScenarioError(f"{option}: {item!r} is not a grid size; give integers >= 2, like 20,50,70.")
        sizes.append(int(item))
    return sizes


def run(args: argparse.Namespace) -> int:
    if args.plot is not None:
        check_plot_path(args.plot)
    if args.render is not None:
        return render(args)
    nodes = parse_sizes(args.nodes, "--nodes")
    extra = parse_sizes(args.extra_nodes, "--extra-nodes")
    if args.repeats < 1:
        raise ScenarioError(f"--repeats: {args.repeats} is too small; give at least 1.")
    for option in ("markdown", "json"):
        path = getattr(args, option)
        if path is not None and not Path(path).parent.is_dir():
            raise ScenarioError(f"--{option}: the directory of {path!r} does not exist.")
    about = machine() | {"funicular": funicular_build()}
    settings: dict[str, Any] = {
        "repeats": args.repeats,
        "competitor_tol": COMPETITOR_TOL,
        "ipopt_links": args.ipopt_links,
        "nodes": nodes,
        "extra_nodes": extra,
    }
    print(f"{about['cpu']}, {about['cores']} cores, load average {about['load_average']}", flush=True)
    notes: list[str] = []
    solvers = []
    for solver in SOLVERS:
        missing = missing_packages(solver)
        if missing:
            notes.append(f"{solver}: not installed ({', '.join(missing)}; pip install 'funicular[bench]')")
        else:
            solvers.append(solver)
    if "funicular" not in solvers:
        raise ScenarioError("funicular is the reference: it must run.")
    notes.append("clarabel: sphere problems not run (not convex: not a second-order-cone program)")
    if extra:
        notes.append(f"ipopt: not run at n = {', '.join(map(str, extra))} (those sizes are for funicular and Clarabel)")
    table = runners(args.ipopt_links)
    warm_up(solvers, table)
    results: list[Result] = []
    given_up: dict[tuple[str, str], str] = {}  # (solver, kind) -> why it stopped
    history: dict[tuple[str, str], list[tuple[int, float]]] = {}
    for n in sorted({*nodes, *extra}):
        for kind in KINDS:
            running = []
            for solver in solvers:
                if (solver, kind) in given_up or (solver == "clarabel" and kind == "sphere"):
                    continue
                if n in extra and n not in nodes:
                    if solver not in EXTRA_SOLVERS:
                        continue
                    guess = predicted_seconds(history.get((solver, kind), []), n)
                    if guess is None or guess > EXTRA_BUDGET:
                        notes.append(
                            f"{solver}, {kind}: not run at n = {n} (predicted {_cell(guess, '.3g')} s, over the "
                            f"{EXTRA_BUDGET:g} s budget)"
                        )
                        continue
                running.append(solver)
            if "funicular" not in running:
                continue
            if results:  # what is measured so far, in case a later instance never ends
                save(args, about, settings, results, [*notes, *given_up.values()], quiet=True)
            for result in measure(n, kind, running, args.repeats, table):
                results.append(result)
                print(table_row(result), flush=True)
                history.setdefault((result.solver, kind), []).append((n, result.seconds))
                failed = not (succeeded(result.solver, result.status) or result.status == "optimal")
                if result.solver != "funicular" and (failed or result.seconds > GIVE_UP_AFTER):
                    why = result.status if failed else f"took {result.seconds:.3g} s"
                    given_up[(result.solver, kind)] = f"{result.solver}, {kind}: not run above n = {n} ({why})"
    notes += list(given_up.values())
    save(args, about, settings, results, notes)
    write_plot(args.plot, lambda figure: draw_times(results, figure, about))
    return EXIT_OK if all(r.status == "optimal" for r in results if r.solver == "funicular") else EXIT_NOT_CONVERGED


def save(
    args: argparse.Namespace,
    about: dict[str, str],
    settings: dict[str, Any],
    results: Sequence[Result],
    notes: Sequence[str],
    quiet: bool = False,
) -> None:
    """The JSON (``--json``) and the report (``--markdown``) of the results so far."""
    if args.json is not None:
        document = {"machine": about, "settings": settings, "results": [asdict(r) for r in results], "notes": notes}
        atomic_write_text(args.json, to_json(document))
    write_report(args.markdown, about, settings, results, notes, quiet)


def draw_times(results: Sequence[Result], figure: Figure, about: dict[str, str]) -> None:
    """Median time against the number of nodes: one colour per solver, dashed over the sphere
    (solves that did not succeed left out)."""
    curves = {
        (solver, kind): [
            (r.n * r.n, r.seconds)
            for r in results
            if r.solver == solver and r.kind == kind and succeeded(solver, r.status)
        ]
        for solver in SOLVERS
        for kind in KINDS
    }
    title = f"cable net hung from its corners (dashed: over the sphere)\n{about['cpu']}, {about['cores']} cores"
    draw_curves(figure, curves, "nodes (n x n grid)", title)


def render(args: argparse.Namespace) -> int:
    """The report again from a run's JSON (``--json``), without solving anything."""
    try:
        document = json.loads(Path(args.render).read_text())
        results = [Result(**entry) for entry in document["results"]]
        about, settings, notes = document["machine"], document["settings"], document["notes"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ScenarioError(f"--render: cannot read {args.render!r}: {error}") from None
    write_report(args.markdown, about, settings, results, notes)
    write_plot(args.plot, lambda figure: draw_times(results, figure, about))
    return EXIT_OK


def write_report(
    path: str | None,
    about: dict[str, str],
    settings: dict[str, Any],
    results: Sequence[Result],
    notes: Sequence[str],
    quiet: bool = False,
) -> None:
    lines = preamble(about, settings)
    lines += [table_row(r) for r in results]
    lines += funicular_section(results)
    lines += findings(results)
    lines += ["", "## Notes", "", *(f"- {note}" for note in notes)]
    if path is not None:
        atomic_write_text(path, "\n".join(lines) + "\n")
    if not quiet:
        print("\n".join(lines), flush=True)
        if path is not None:
            print(f"wrote {path}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.nets",
        description="funicular, Clarabel and IPOPT on hanging nets (docs/benchmark-nets.md).",
    )
    parser.add_argument("--nodes", default=",".join(map(str, DEFAULT_NODES)), help="grid sizes n (n x n nodes)")
    parser.add_argument(
        "--extra-nodes",
        default=",".join(map(str, DEFAULT_EXTRA_NODES)),
        help=f"sizes for funicular and Clarabel only, each if predicted under {EXTRA_BUDGET:g} s ('' for none)",
    )
    parser.add_argument("--repeats", type=int, default=DEFAULT_REPEATS, help="runs per solver and instance")
    parser.add_argument("--ipopt-links", choices=("squared", "norm"), default="squared", help="IPOPT's link constraint")
    parser.add_argument("--markdown", metavar="FILE", help="write the report (Markdown)")
    parser.add_argument("--json", metavar="FILE", help="write every number as JSON")
    parser.add_argument("--render", metavar="JSON", help="write the report from a run's --json instead of running")
    parser.add_argument("--plot", metavar="FILE", help="draw time against the number of nodes (.png, .svg or .pdf)")
    args = parser.parse_args(argv)
    try:
        return run(args)
    except FunicularError as error:
        print(f"python -m bench.nets: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
