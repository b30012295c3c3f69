"""``funicular sweep``: solve a scenario over a range or grid of its values."""

from __future__ import annotations

import argparse
import functools
import math

from funicular._progress import add_quiet_argument, progress_bar
from funicular._text import to_json
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_argument,
    check_outputs,
    overridden,
    tolerance,
    write_output,
)
from funicular.errors import ScenarioError
from funicular.plot import check_plot_path
from funicular.scenario import load_document
from funicular.studies._parallel import add_parallel_arguments, pool_for
from funicular.studies.sweep import parameters_of, parse_range, save_sweep_plot, sweep, sweep_text

# The most steps a sweep takes (a grid's: both counts multiplied). Each step is a solve, a row of
# the table and a point of the JSON and the plot: 100,000 already take minutes on a small chain
# and make a table nobody reads, and a COUNT of 10^9 fills the memory with its values before the
# first solve.
MAX_STEPS = 100_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument(
        "--set",
        dest="settings",
        metavar="KEY=START:STOP:COUNT",
        action="append",
        default=[],
        help="a scenario value to sweep, e.g. chain.length=1.2:2:9 or supports[1].position[0]=0.5:1.2:8; "
        "give two for a grid (its rows, one per value of the first, are solved in parallel); "
        f"at most {MAX_STEPS:,} steps in all",
    )
    parser.add_argument("--tol", type=tolerance, default=1e-10, help="scaled KKT tolerance (default 1e-10)")
    parser.add_argument("--json", metavar="PATH", help="write the table as JSON")
    parser.add_argument("--plot", metavar="PATH", help="draw the quantities against the parameter")
    add_parallel_arguments(parser)
    add_quiet_argument(parser)


def run(args: argparse.Namespace) -> int:
    check_steps(args.settings)
    scenario = load_document(args.scenario)
    parameters = parameters_of(scenario.document, args.settings)
    if any(p.path == ("chain", "nodes") for p in parameters) and args.nodes:
        raise ScenarioError("--nodes and --set chain.nodes contradict each other; give one of them.")
    # A partial of a top-level function, not a closure: worker processes receive it pickled.
    adjust = functools.partial(overridden, args=argparse.Namespace(nodes=args.nodes, formulation=args.formulation))
    if args.plot is not None:
        check_plot_path(args.plot)  # fail before solving, not after
    check_outputs(args, "json", "plot")
    total = math.prod(len(p.values) for p in parameters)
    with pool_for(args) as pool, progress_bar(total, "sweep", quiet=args.quiet) as advance:
        result = sweep(scenario, args.settings, adjust=adjust, tol=args.tol, on_step=advance, pool=pool)
    print(sweep_text(result))
    if args.json is not None:
        write_output(args.json, to_json(result.as_dict()))
    if args.plot is not None:
        save_sweep_plot(result, args.plot)
        print(f"  wrote {args.plot}")
    return EXIT_OK if all(step.converged for step in result.steps) else EXIT_NOT_CONVERGED


def check_steps(settings: list[str]) -> None:
    """At most MAX_STEPS steps, checked from the COUNTs before any value is made."""
    counts = [parse_range(text)[3] for text in settings]
    steps = math.prod(counts)
    if steps > MAX_STEPS:
        grid = f" ({' x '.join(f'{count:,}' for count in counts)})" if len(counts) > 1 else ""
        raise ScenarioError(
            f"--set {' --set '.join(settings)}: {steps:,} steps{grid} are more than a sweep takes; "
            f"give COUNTs that make at most {MAX_STEPS:,} steps in all."
        )
