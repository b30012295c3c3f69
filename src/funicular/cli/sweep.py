"""``funicular sweep``: solve a scenario over a range or grid of its values."""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections.abc import Callable, Iterator

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
from funicular.model import Problem
from funicular.plot import check_plot_path
from funicular.scenario import load_document
from funicular.studies.sweep import parse_key, parse_range, save_sweep_plot, sweep, sweep_text

PROGRESS_FROM = 10  # show a progress bar (rich, on a terminal) for sweeps of at least this many steps


@contextlib.contextmanager
def progress_bar(total: int) -> Iterator[Callable[[], None]]:
    """A rich progress bar on stderr for long sweeps on a terminal; a no-op otherwise (or without rich)."""
    if total < PROGRESS_FROM or not sys.stderr.isatty():
        yield lambda: None
        return
    try:  # rich is an optional extra, loaded only for a long sweep on a terminal
        from rich.console import Console
        from rich.progress import Progress
    except ImportError:
        yield lambda: None
        return
    with Progress(console=Console(stderr=True), transient=True) as progress:
        task = progress.add_task("sweep", total=total)
        yield lambda: progress.advance(task)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument(
        "--set",
        dest="settings",
        metavar="KEY=START:STOP:COUNT",
        action="append",
        default=[],
        help="a scenario value to sweep, e.g. chain.length=1.2:2:9 or supports[1].position[0]=0.5:1.2:8; "
        "give two for a grid",
    )
    parser.add_argument("--tol", type=tolerance, default=1e-10, help="scaled KKT tolerance (default 1e-10)")
    parser.add_argument("--json", metavar="PATH", help="write the table as JSON")
    parser.add_argument("--plot", metavar="PATH", help="draw the quantities against the parameter")


def run(args: argparse.Namespace) -> int:
    scenario = load_document(args.scenario)
    if any(parse_key(parse_range(text)[0]) == ("chain", "nodes") for text in args.settings) and args.nodes:
        raise ScenarioError("--nodes and --set chain.nodes contradict each other; give one of them.")

    def adjust(problem: Problem) -> Problem:
        return overridden(problem, args)

    if args.plot is not None:
        check_plot_path(args.plot)  # fail before solving, not after
    check_outputs(args, "json", "plot")
    total = math.prod(parse_range(text)[3] for text in args.settings) if args.settings else 0
    with progress_bar(total) as advance:
        result = sweep(scenario, args.settings, adjust=adjust, tol=args.tol, on_step=advance)
    print(sweep_text(result))
    if args.json is not None:
        write_output(args.json, to_json(result.as_dict()))
    if args.plot is not None:
        save_sweep_plot(result, args.plot)
        print(f"  wrote {args.plot}")
    return EXIT_OK if all(step.converged for step in result.steps) else EXIT_NOT_CONVERGED
