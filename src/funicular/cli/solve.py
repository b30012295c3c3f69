"""``funicular solve``: solve a scenario, print its forces, write its result file and plot."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from funicular._text import force_table, summary
from funicular._uniqueness import multipliers_may_not_be_unique
from funicular.backends import SOLVERS, advice, check_size, solve_with
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_argument,
    announce_slow_start,
    check_outputs,
    check_result_output,
    escape_nodes,
    iteration_count,
    load_problem,
    log_stream,
    tolerance,
    write_result,
)
from funicular.errors import FunicularError, ScenarioError
from funicular.model import Problem
from funicular.plot import COLOURINGS, check_colouring, check_plot_path, save_solution_plot
from funicular.solution import Solution

CHECK_LICQ_UP_TO = 2000  # nodes: above, the checker's LICQ costs more than a note is worth; say "may"
MAY_NOT_BE_UNIQUE = (
    "  multipliers       may not be unique (the active constraints may be dependent): funicular check tells"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument("--tol", type=tolerance, default=1e-10, help="scaled KKT tolerance (default 1e-10)")
    parser.add_argument(
        "--max-iterations", type=iteration_count, metavar="N", help="Newton steps before giving up (default 200)"
    )
    parser.add_argument(
        "--table",
        action="store_true",
        help="print every link's multiplier, tension and length, and every contact force",
    )
    parser.add_argument(
        "--output",
        metavar="PATH",
        help="write the full result as .json, .npz or .parquet, by the extension ('-': JSON on standard output)",
    )
    parser.add_argument(
        "--json",
        metavar="PATH",
        help="write the full result as JSON, whatever the extension but .npz or .parquet ('-': standard output)",
    )
    parser.add_argument("--indent", action="store_true", help="indent the JSON for reading (default: compact)")
    parser.add_argument("--plot", metavar="PATH", help="draw the equilibrium (.png, .svg or .pdf)")
    parser.add_argument(
        "--colour",
        choices=COLOURINGS,
        help="what the plot colours the links by (default tension; strain where some link is elastic)",
    )
    parser.add_argument("--solver", choices=SOLVERS, default="funicular", help="which solver (default funicular)")
    parser.add_argument(
        "--escape-up-to",
        type=escape_nodes,
        metavar="N",
        help="the most nodes on which a result on an obstacle is checked for a saddle and moved off it "
        "(a chain solved coarse-to-fine: its coarsest level; default 20,000 for a chain, 5,000 for a net; "
        "a larger net's escape takes several times its solve)",
    )
    parser.add_argument(
        "--no-exact-start",
        dest="exact_start",
        action="store_false",
        help="start a chain that touches nothing from the general guess, not from its discrete catenary "
        "(to watch the interior-point method work)",
    )


def run(args: argparse.Namespace) -> int:
    problem = load_problem(args)
    if args.plot is not None:
        check_plot_path(args.plot)  # fail before solving, not after
    _check_colour(problem, args)
    check_outputs(args, "json", "plot")
    check_result_output(args, "output")
    check_size(problem, [args.solver])
    warning = advice(problem, args.solver)
    if warning:
        print(warning, file=sys.stderr)
    announce_slow_start([args.solver])
    solution = solve_with(
        problem,
        args.solver,
        tol=args.tol,
        max_iterations=args.max_iterations,
        exact_start=args.exact_start,
        escape_up_to=args.escape_up_to,
    )
    log = log_stream(args)
    print(summary(solution), file=log)
    document = None
    if args.json is not None or args.output is not None:
        from funicular.checks import solution_document  # (SciPy: loaded only for the file's licq block)

        document = solution_document(solution)
    note = uniqueness_note(solution, None if document is None else document["licq"])
    if note:
        print(note, file=log)
    if args.table:
        print(force_table(solution), file=log)
    if document is not None:
        if args.json is not None:
            write_result(args.json, document, "--json", args.indent, json=True, log=log)
        if args.output is not None:
            write_result(args.output, document, "--output", args.indent, log=log)
    if args.plot is not None:
        save_solution_plot(solution, args.plot, args.colour or "tension")
        print(f"  wrote {args.plot}", file=log)
    return EXIT_OK if solution.converged else EXIT_NOT_CONVERGED


def _check_colour(problem: Problem, args: argparse.Namespace) -> None:
    """--colour colours the plot, so it needs --plot, and strain needs an elastic link."""
    if args.colour is None:
        return
    if args.plot is None:
        raise ScenarioError(f"--colour {args.colour} colours the plot's links; give --plot PATH as well.")
    try:
        check_colouring(problem, args.colour)
    except FunicularError as error:
        raise error.renamed("--colour") from None


def uniqueness_note(solution: Solution, licq_block: dict[str, Any] | None = None) -> str | None:
    """A line saying the multipliers printed are one choice among many (LICQ fails), or None. The
    checker decides, for chains of up to CHECK_LICQ_UP_TO nodes whose geometry allows dependent
    constraints (:func:`multipliers_may_not_be_unique`): the common case pays nothing. A net's
    statics are read from ``licq_block``, a result file's, where it is given."""
    if not solution.converged or not multipliers_may_not_be_unique(solution):
        return None
    if not solution.problem.is_chain:
        return _statics_note(solution, licq_block)
    if solution.problem.n_nodes > CHECK_LICQ_UP_TO:
        return MAY_NOT_BE_UNIQUE
    from funicular.checks import licq_of  # (SciPy: loaded only where LICQ may fail)

    licq = licq_of(solution)
    if licq is None or licq.holds:
        return None
    return (
        f"  multipliers       NOT unique: LICQ fails (rank {licq.rank} of {licq.active_constraints} "
        "active constraints);\n"
        "                    the forces above are one choice among many (funicular check gives their ranges)"
    )


def _statics_note(solution: Solution, licq_block: dict[str, Any] | None) -> str | None:
    """A net's version of the note: its degree of static indeterminacy, where it is not zero. From
    a result file's statics where given; else the sparse proof of unique forces comes first (one
    factorization), and only where it fails, up to CHECK_LICQ_UP_TO nodes, the search for
    self-stress states (it can take longer than the solve)."""
    from funicular.checks import proven_determinate, statics_of

    if licq_block is not None:
        statics = licq_block
    elif proven_determinate(solution):
        return None
    elif solution.problem.n_nodes > CHECK_LICQ_UP_TO:
        return MAY_NOT_BE_UNIQUE
    else:
        statics = statics_of(solution).as_dict()
    degree = statics["degree_of_indeterminacy"]
    if degree == 0:
        return None
    if degree is None:
        return None if solution.problem.n_nodes <= CHECK_LICQ_UP_TO else MAY_NOT_BE_UNIQUE
    if statics.get("unique_with_stiffness"):
        return (
            f"  forces            unique: the {solution.problem.kind} is statically indeterminate to degree {degree} "
            f"({statics['active_constraints']} active constraints, rank {statics['rank']}),\n"
            "                    and its elastic links' stiffness decides the forces above"
        )
    return (
        f"  multipliers       NOT unique: the net is statically indeterminate to degree {degree} "
        f"({statics['active_constraints']} active constraints, rank {statics['rank']});\n"
        "                    the forces above are one choice among many (solve --json gives the self-stress "
        "states and each force's range)"
    )
