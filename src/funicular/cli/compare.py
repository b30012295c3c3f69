"""``funicular compare``: solve with every available solver and compare the answers."""

from __future__ import annotations

import argparse
import sys

from funicular.backends import SOLVERS, advice, available, compare, compare_table
from funicular.cli._common import EXIT_NOT_CONVERGED, EXIT_OK, add_scenario_argument, load_problem, tolerance


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument("--tol", type=tolerance, default=None, help="tolerance passed to every solver")


def run(args: argparse.Namespace) -> int:
    problem = load_problem(args)
    for name in available():
        warning = advice(problem, name)
        if warning:
            print(warning, file=sys.stderr)
    rows = compare(problem, args.tol)
    missing = [name for name in SOLVERS if name not in available()]
    print(f"{problem.name}: {problem.n_nodes} nodes, {problem.formulation.value} formulation")
    print(compare_table(rows))
    if missing:
        print(f"  not installed: {', '.join(missing)} (pip install 'funicular[ipopt]')")
    converged = all(row.solution is not None and row.solution.converged for row in rows)
    return EXIT_OK if converged else EXIT_NOT_CONVERGED
