"""``funicular compare``: solve with every available solver and compare the answers."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from funicular._extras import install_command
from funicular.backends import SOLVERS, Row, advice, available, check_size, compare, compare_table
from funicular.checks import licq_of
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_argument,
    announce_slow_start,
    load_problem,
    tolerance,
)

AGREE_RTOL = 1e-6  # tensions closer than this (relative to the weight) agree


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument("--tol", type=tolerance, default=None, help="tolerance passed to every solver")


def run(args: argparse.Namespace) -> int:
    problem = load_problem(args)
    check_size(problem, available())
    for name in available():
        warning = advice(problem, name)
        if warning:
            print(warning, file=sys.stderr)
    announce_slow_start(available())
    rows = compare(problem, args.tol)
    missing = [name for name in SOLVERS if name not in available()]
    print(f"{problem.name}: {problem.n_nodes} nodes, {problem.formulation.value} formulation")
    print(compare_table(rows))
    note = disagreement_note(rows)
    if note:
        print(note)
    if missing:
        print(f"  not installed: {', '.join(missing)} ({install_command('ipopt')})")
    converged = all(row.solution is not None and row.solution.converged for row in rows)
    return EXIT_OK if converged else EXIT_NOT_CONVERGED


def disagreement_note(rows: list[Row]) -> str | None:
    """Where the solvers' tensions differ and the multipliers are not unique (LICQ fails at
    funicular's answer), say so: the difference is a choice among valid multipliers, not an error."""
    reference = next((row.solution for row in rows if row.solver == "funicular"), None)
    if reference is None:
        return None
    tolerance = AGREE_RTOL * reference.problem.force_scale
    differing = [
        row.solver
        for row in rows
        if row.solution is not None
        and row.solver != "funicular"
        and float(np.abs(row.solution.link_tension - reference.link_tension).max(initial=0.0)) > tolerance
    ]
    if not differing:
        return None
    licq = licq_of(reference)
    if licq is None or licq.holds:
        return None
    return (
        f"  note: the multipliers are not unique here (LICQ fails: rank {licq.rank} of {licq.active_constraints} "
        f"active constraints), so {', '.join(differing)} may pick other tensions for the same equilibrium; "
        "max |dT| then measures that choice, not an error (funicular check gives each force's range)"
    )
