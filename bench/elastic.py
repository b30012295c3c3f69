"""Elastic cables: what elasticity costs, side by side with inextensible links and with CVXPY +
Clarabel on the same convex program, and how a mooring line converges to MoorPy's catenary.

Run from the repository::

    .venv/bin/python -m bench.elastic --markdown docs/benchmark-elastic.md

Three tables:

* a catenary mooring line (800 m out and 200 m up from a seabed anchor, 950 m of line, 1000 N/m,
  EA 5e8 N, the seabed a half-plane without friction) with N nodes, elastic and inextensible, median
  wall time of ``funicular.solve``;
* an n x n grid hung from its corners (links 1.05 times the spacing, mass 1, g = 9.81), inextensible
  and with EA = 1e4 on every link, and the elastic one as the conic program CVXPY + Clarabel solves
  (second-order cones ``||p_a - p_b|| <= L0 + e``, ``e >= 0``, energy plus ``sum EA / (2 L0) e^2``);
* the mooring line's fairlead and anchor forces and grounded length against MoorPy's
  ``Catenary.catenary`` (CB = 0), as N grows.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np

from bench.run import machine, parse_nodes
from funicular._io import atomic_write_text
from funicular._solver import solve
from funicular.errors import FunicularError, ScenarioError
from funicular.model import Problem
from funicular.nets import grid
from funicular.obstacles import HalfPlane

EXIT_OK, EXIT_BAD_INPUT = 0, 2
DEFAULT_LINES = (10_001, 100_001, 1_000_001)
DEFAULT_GRIDS = (50, 100)
ACCURACY_NODES = (26, 51, 101, 201, 401, 801, 1601)
DEFAULT_REPEATS = 3
NET_STIFFNESS = 1e4
CLARABEL_UP_TO = 100  # grid sizes Clarabel is timed at (one solve: it takes tens of seconds at 100 x 100)


def mooring(nodes: int, elastic: bool) -> Problem:
    """The catenary mooring line of the ``mooring`` built-in, with ``nodes`` nodes."""
    return Problem.build(
        nodes=nodes,
        length=950.0,
        linear_density=1000.0 / 9.81,
        gravity=9.81,
        supports=[(0, (0.0, 0.0)), (nodes - 1, (800.0, 200.0))],
        axial_stiffness=5e8 if elastic else None,
        obstacles=[HalfPlane(point=(0.0, 0.0), normal=(0.0, 1.0), name="seabed")],
        units="SI",
    )


def net(n: int, elastic: bool) -> Problem:
    return grid(n, n, slack=1.05, mass=1.0, gravity=9.81, axial_stiffness=NET_STIFFNESS if elastic else None)


def median_times(makes: Sequence[Callable[[], Problem]], repeats: int) -> list[tuple[float, str, int]]:
    """Median wall time of ``funicular.solve`` over ``repeats`` solves of each problem, with its
    status and step count; the solves interleaved, so that load on a shared machine hits each alike."""
    problems = [make() for make in makes]
    times: list[list[float]] = [[] for _ in problems]
    outcomes = [("", 0) for _ in problems]
    for _ in range(repeats):
        for i, problem in enumerate(problems):
            started = time.perf_counter()
            solution = solve(problem)
            times[i].append(time.perf_counter() - started)
            outcomes[i] = (solution.status.value, solution.iterations)
    return [(statistics.median(t), status, steps) for t, (status, steps) in zip(times, outcomes, strict=True)]


def clarabel_seconds(problem: Problem) -> tuple[float, float]:
    """Wall time of CVXPY + Clarabel on the elastic net's conic program (building included) and
    its energy."""
    import cvxpy as cp

    started = time.perf_counter()
    positions = cp.Variable((problem.n_nodes, problem.dimension))
    a, b = problem.link_nodes.T
    stretch = cp.Variable(problem.n_links, nonneg=True)
    lengths = problem.link_lengths
    assert problem.axial_stiffness is not None
    constraints = [
        positions[problem.support_nodes] == problem.support_positions,
        cp.SOC(lengths + stretch, positions[a] - positions[b], axis=1),
    ]
    energy = problem.gravity * problem.masses @ positions[:, -1]
    energy += 0.5 * (problem.axial_stiffness / lengths) @ cp.square(stretch)  # type: ignore[attr-defined]
    program = cp.Problem(cp.Minimize(energy), constraints)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        program.solve(  # type: ignore[no-untyped-call]
            solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10
        )
    return time.perf_counter() - started, float(program.value)


def lines_table(sizes: Sequence[int], repeats: int) -> list[str]:
    rows = []
    for n in sizes:
        (rigid, rigid_status, rigid_steps), (elastic, status, steps) = median_times(
            [partial(mooring, n, False), partial(mooring, n, True)], repeats
        )
        print(f"  mooring N = {n:,}: {rigid:.3g} s rigid, {elastic:.3g} s elastic", file=sys.stderr, flush=True)
        rows.append(
            f"| {n:,} | {rigid:.3g} | {elastic:.3g} | {elastic / rigid:.2f} | {rigid_steps} / {steps} | "
            f"{rigid_status} / {status} |"
        )
    return rows


def nets_table(sizes: Sequence[int], repeats: int) -> list[str]:
    rows = []
    for n in sizes:
        (rigid, _, rigid_steps), (elastic, status, steps) = median_times(
            [partial(net, n, False), partial(net, n, True)], repeats
        )
        competitor, agreement = "-", "-"
        if n <= CLARABEL_UP_TO:
            seconds, energy = clarabel_seconds(net(n, True))
            ours = solve(net(n, True)).objective
            competitor = f"{seconds:.3g} ({seconds / elastic:.0f}x)"
            agreement = f"{abs(ours - energy) / abs(energy):.1e}"
        print(f"  net {n} x {n}: {rigid:.3g} s rigid, {elastic:.3g} s elastic, Clarabel {competitor}", file=sys.stderr)
        rows.append(
            f"| {n} x {n} | {rigid:.3g} | {elastic:.3g} | {elastic / rigid:.2f} | {rigid_steps} / {steps} | "
            f"{competitor} | {agreement} | {status} |"
        )
    return rows


def accuracy_table() -> list[str]:
    from moorpy.Catenary import catenary

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        anchor_h, _, fairlead_h, fairlead_v, info = catenary(800.0, 200.0, 950.0, 5e8, 1000.0, CB=0)
    rows = [
        f"| MoorPy | {-fairlead_h:.7g} | {-fairlead_v:.7g} | {anchor_h:.7g} | {info['LBot']:.5g} | | |",
    ]
    for n in ACCURACY_NODES:
        problem = mooring(n, True)
        solution = solve(problem)
        (anchor_x, _), (fairlead_x, fairlead_y) = solution.support_reactions
        touching = np.flatnonzero(np.linalg.norm(solution.contact_forces, axis=1) > 0)
        grounded = float(problem.link_lengths[: touching.max()].sum())
        error = max(abs(fairlead_x / -fairlead_h - 1), abs(fairlead_y / -fairlead_v - 1), abs(-anchor_x / anchor_h - 1))
        rows.append(
            f"| {n} | {fairlead_x:.7g} | {fairlead_y:.7g} | {-anchor_x:.7g} | {grounded:.5g} | {error:.1e} | "
            f"{problem.link_lengths[0]:.3g} |"
        )
    return rows


def report(
    lines: Sequence[str], nets: Sequence[str], accuracy: Sequence[str], repeats: int, about: dict[str, Any]
) -> str:
    text = [
        "# Benchmark: elastic cables",
        "",
        "Generated by `python -m bench.elastic` (see [Elastic cables](elastic.md)); do not edit by hand. Median wall "
        f"time of `funicular.solve` over {repeats} solves, the inextensible and the elastic one taking turns (load "
        "on the machine hits both alike); *steps*: interior-point and polish steps, inextensible / elastic.",
        "",
        "## A mooring line on the seabed",
        "",
        "The `mooring` built-in's line (800 m out and 200 m up, 950 m of line, 1000 N/m, EA 5e8 N) with N nodes, "
        "inextensible and elastic.",
        "",
        "| N | inextensible [s] | elastic [s] | elastic / inextensible | steps | status |",
        "|---:|---:|---:|---:|---|---|",
        *lines,
        "",
        "## Nets",
        "",
        f"An n x n grid hung from its corners (links 1.05 times the spacing, mass 1, g = 9.81), inextensible and "
        f"with EA = {NET_STIFFNESS:g} on every link; CVXPY + Clarabel on the elastic net's conic program "
        "(one solve, building the program included), and how far its energy is from funicular's.",
        "",
        "| net | inextensible [s] | elastic [s] | elastic / inextensible | steps | Clarabel [s] | energies apart "
        "| status |",
        "|---|---:|---:|---:|---|---:|---:|---|",
        *nets,
        "",
        "## Against MoorPy",
        "",
        "The same line against MoorPy's catenary with seabed contact and no friction: the fairlead's horizontal "
        "and vertical reactions, the anchor's horizontal one (N), the length lying on the seabed (m), the largest "
        "relative difference of the three forces, and the length of a link. The touchdown point falls between two "
        "nodes, so the error does not fall smoothly with N.",
        "",
        "| N | fairlead H | fairlead V | anchor H | grounded | force error | link |",
        "|---|---:|---:|---:|---:|---:|---:|",
        *accuracy,
        "",
        "## Machine",
        "",
        f"{about['platform']}, {about['cpu']}, {about['cores']} cores, load average {about['load_average']} at the "
        f"start; {about['versions']}.",
    ]
    return "\n".join(text) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.elastic", description="Elastic cables (docs/benchmark-elastic.md)."
    )
    parser.add_argument("--lines", default=",".join(map(str, DEFAULT_LINES)), help="mooring line sizes N")
    parser.add_argument("--grids", default=",".join(map(str, DEFAULT_GRIDS)), help="grid sizes n (n x n nodes)")
    parser.add_argument("--repeats", type=int, default=DEFAULT_REPEATS, help="solves per case")
    parser.add_argument("--markdown", metavar="FILE", help="write the report (Markdown)")
    args = parser.parse_args(argv)
    try:
        lines, grids = parse_nodes(args.lines), parse_nodes(args.grids)
        if args.repeats < 1:
            raise ScenarioError(f"--repeats: {args.repeats} is too small; give at least 1.")
        about = machine()
        solve(mooring(1001, True))  # (warm-up: first-call costs are not measured)
        text = report(
            lines_table(lines, args.repeats), nets_table(grids, args.repeats), accuracy_table(), args.repeats, about
        )
    except FunicularError as error:
        print(f"python -m bench.elastic: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.markdown is not None:
        atomic_write_text(args.markdown, text)
        print(f"wrote {args.markdown}")
    print(text)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
