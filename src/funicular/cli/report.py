"""``funicular report``: one self-contained HTML page (or Markdown with its images) about a scenario."""

from __future__ import annotations

import argparse
from pathlib import Path

from funicular._htmlreport import FORMATS, write_report
from funicular._solver import solve
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_argument,
    check_outputs,
    load_problem,
    tolerance,
)
from funicular.errors import ScenarioError
from funicular.plot import require_matplotlib
from funicular.scenario import load_document

SUFFIXES = {".html": "html", ".htm": "html", ".md": "md"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument("-o", "--output", required=True, metavar="PATH", help="the report file to write")
    parser.add_argument(
        "--format", choices=FORMATS, help="html (one self-contained file) or md (images beside it); default: from PATH"
    )
    parser.add_argument("--tol", type=tolerance, default=1e-10, help="scaled KKT tolerance (default 1e-10)")


def report_format(output: str, chosen: str | None) -> str:
    """The format of the report file ``output``: its suffix says it (.html or .md), and --format must agree."""
    suffix = Path(output).suffix.lower()
    if suffix not in SUFFIXES:
        raise ScenarioError(
            f"--output {output!r}: a report is written as HTML or Markdown; use a file name ending in .html or .md."
        )
    if chosen is not None and chosen != SUFFIXES[suffix]:
        raise ScenarioError(
            f"--format {chosen} does not match --output {output!r}; use a file name ending in .{chosen}."
        )
    return SUFFIXES[suffix]


def run(args: argparse.Namespace) -> int:
    chosen = report_format(args.output, args.format)
    check_outputs(args, "output")
    require_matplotlib()  # the report's pictures: fail before solving, not after
    problem = load_problem(args)
    description = str(load_document(args.scenario).document.get("description", ""))
    solution = solve(problem, tol=args.tol)
    write_report(solution, args.output, chosen, description)
    print(f"{problem.name}: {solution.status.value}; wrote {args.output}")
    return EXIT_OK if solution.converged else EXIT_NOT_CONVERGED
