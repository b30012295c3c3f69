"""``funicular check``: KKT, LICQ and the statics, MFCQ and second-order checks of funicular's
solution or of a point read from a file (JSON, or the .npz or .parquet that ``solve --output``
writes), for any problem: one checker, one report. funicular's solution is checked as any other
point, from its positions and multipliers (the checker does not repeat the solver's own tests)."""

from __future__ import annotations

import argparse

from funicular._solver import solve
from funicular._text import to_json
from funicular.checks import DEFAULT_TOL, check, check_solution, read_solution
from funicular.checks._check import refuse_unchecked
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_argument,
    check_outputs,
    load_problem,
    log_stream,
    write_output,
)
from funicular.errors import shown


def _relative_tolerance(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not a number") from None
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"{shown(text)} must be a number between 0 and 1")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument(
        "--solution",
        metavar="FILE",
        help="check this point instead of funicular's solution: JSON with x and y (and z in 3-D), or the "
        ".json, .npz or .parquet that solve --output writes",
    )
    parser.add_argument("--json", metavar="PATH", help="write the report as JSON ('-': standard output)")
    parser.add_argument(
        "--tol",
        type=_relative_tolerance,
        default=DEFAULT_TOL,
        help=f"relative tolerance of every test (default {DEFAULT_TOL:g})",
    )


def run(args: argparse.Namespace) -> int:
    """Exit 0 at a feasible KKT point, 1 at an infeasible point or one whose residuals exceed tol."""
    problem = load_problem(args)
    check_outputs(args, "json")
    refuse_unchecked(problem)  # (before the solve)
    log = log_stream(args)
    if args.solution is None:
        solution = solve(problem)
        print(f"checking funicular's solution ({solution.status.value})", file=log)
        report = check_solution(solution, args.tol)
    else:
        positions, multipliers = read_solution(problem, args.solution, args.tol)
        print(f"checking {args.solution} ({'with' if multipliers else 'without'} multipliers)", file=log)
        report = check(problem, positions, multipliers, args.tol)
    print(report.summary(), file=log)
    if args.json is not None:
        write_output(args.json, to_json(report.to_dict()), log)
    return EXIT_OK if report.feasible and report.kkt_holds else EXIT_NOT_CONVERGED
