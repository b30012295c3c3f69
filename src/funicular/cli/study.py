"""``funicular study refine``: the same chain at growing N in both formulations, against exact answers."""

from __future__ import annotations

import argparse

from funicular._progress import add_quiet_argument, progress_bar
from funicular._text import to_json
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_name,
    check_outputs,
    node_list,
    tolerance,
    write_output,
)
from funicular.plot import check_plot_path
from funicular.scenario import load_scenario
from funicular.studies.refine import DEFAULT_NODES, refine, save_study_plot, study_text


def _add_refine_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_name(parser)
    parser.add_argument(
        "--nodes",
        default=",".join(map(str, DEFAULT_NODES)),
        help=f"comma-separated node counts (default: {','.join(map(str, DEFAULT_NODES))})",
    )
    parser.add_argument("--tol", type=tolerance, default=1e-10, help="scaled KKT tolerance (default 1e-10)")
    parser.add_argument("--json", metavar="PATH", help="write the table as JSON")
    parser.add_argument("--plot", metavar="PATH", help="draw multipliers against N and tension profiles")
    add_quiet_argument(parser)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``funicular study STUDY ...``: one subcommand per study (so far: refine)."""
    studies = parser.add_subparsers(dest="study", required=True, metavar="STUDY")
    _add_refine_arguments(
        studies.add_parser("refine", help="solve at growing N in both formulations, against exact answers")
    )


def run(args: argparse.Namespace) -> int:
    """``args.study == "refine"``, the only study."""
    nodes = node_list(args.nodes)
    problem = load_scenario(args.scenario)
    if args.plot is not None:
        check_plot_path(args.plot)  # fail before solving, not after
    check_outputs(args, "json", "plot")
    with progress_bar(2 * len(set(nodes)), "refine", quiet=args.quiet) as advance:
        study = refine(problem, nodes, tol=args.tol, on_solve=advance)
    print(study_text(study))
    if args.json is not None:
        write_output(args.json, to_json(study.as_dict()))
    if args.plot is not None:
        save_study_plot(study, args.plot)
        print(f"  wrote {args.plot}")
    return EXIT_OK if all(row.status == "optimal" for row in study.rows) else EXIT_NOT_CONVERGED
