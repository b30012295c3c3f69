"""``funicular explore``: solve from many starting shapes and list the distinct equilibria."""

from __future__ import annotations

import argparse

from funicular._progress import add_quiet_argument, progress_bar
from funicular._text import to_json
from funicular.checks import second_order
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_argument,
    check_outputs,
    load_problem,
    write_output,
)
from funicular.errors import ScenarioError
from funicular.plot import check_plot_path, save_equilibria_plot
from funicular.solution import Solution
from funicular.studies._parallel import add_parallel_arguments, pool_for
from funicular.studies.explore import explore, table, to_dict

# The most starting shapes: each is a solve and a second-order check (a millisecond or more on a
# small chain, seconds on a net), and the distinct equilibria of 10,000 starts are all there are
# to find in any scenario we know; 10^8 starts run for days.
MAX_STARTS = 10_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument(
        "--starts", type=int, default=20, help=f"number of starting shapes, 1 to {MAX_STARTS:,} (default 20)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed of the starting shapes (default 0)")
    parser.add_argument("--json", metavar="PATH", help="write every equilibrium as JSON")
    parser.add_argument("--plot", metavar="PATH", help="draw all equilibria in one figure")
    add_parallel_arguments(parser)
    add_quiet_argument(parser)


def _second_order_verdict(solution: Solution) -> str:
    return second_order(solution.problem, solution).verdict


def run(args: argparse.Namespace) -> int:
    if not 1 <= args.starts <= MAX_STARTS:
        raise ScenarioError(f"--starts = {args.starts:,}; give from 1 to {MAX_STARTS:,} starting shapes.")
    problem = load_problem(args)
    if args.plot is not None:
        check_plot_path(args.plot)
    check_outputs(args, "json", "plot")
    with pool_for(args) as pool, progress_bar(args.starts, "explore", quiet=args.quiet) as advance:
        exploration = explore(
            problem, args.starts, args.seed, classify=_second_order_verdict, on_start=advance, pool=pool
        )
    print(table(exploration))
    if args.json is not None:
        write_output(args.json, to_json(to_dict(exploration)))
    if args.plot is not None:
        save_equilibria_plot([eq.solution for eq in exploration.equilibria], args.plot)
        print(f"  wrote {args.plot}")
    return EXIT_OK if exploration.equilibria else EXIT_NOT_CONVERGED
