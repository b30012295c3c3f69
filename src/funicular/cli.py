"""The ``funicular`` command line.

Exit status: 0 success, 1 a solve that did not converge, 2 bad input (one sentence on stderr).
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from funicular.backends import SOLVERS, solve_for_cli
from funicular.errors import FunicularError, shown
from funicular.io import atomic_write_text
from funicular.model import Formulation, Problem
from funicular.report import summary, to_json
from funicular.scenario import DEFAULT_SCENARIO, builtin_scenarios, load_scenario

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT = 0, 1, 2


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not an integer") from None


def _positive_int(text: str) -> int:
    value = _integer(text)
    if value < 2:
        raise argparse.ArgumentTypeError(f"{value} is too small; a chain needs at least 2 nodes")
    return value


def _iteration_count(text: str) -> int:
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; give a number of Newton steps >= 0")
    return value


def _add_solve_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument("--tol", type=float, default=1e-10, help="scaled KKT tolerance (default 1e-10)")
    parser.add_argument(
        "--max-iterations", type=_iteration_count, metavar="N", help="Newton steps before giving up (default 200)"
    )
    parser.add_argument("--json", metavar="PATH", help="write the full result as JSON")
    parser.add_argument("--plot", metavar="PATH", help="draw the equilibrium (.png, .svg or .pdf)")
    parser.add_argument("--solver", choices=SOLVERS, default="funicular", help="which solver (default funicular)")
    parser.add_argument(
        "--no-exact-start",
        dest="exact_start",
        action="store_false",
        help="start a chain that touches nothing from the general guess, not from its discrete catenary "
        "(to watch the interior-point method work)",
    )


def add_scenario_name(parser: argparse.ArgumentParser) -> None:
    """The SCENARIO positional argument: a TOML file or a built-in name."""
    parser.add_argument(
        "scenario",
        nargs="?",
        default=DEFAULT_SCENARIO,
        help=f"a TOML file or the name of a built-in scenario (default: {DEFAULT_SCENARIO})",
    )


def add_scenario_argument(parser: argparse.ArgumentParser) -> None:
    """SCENARIO plus the overrides every command that loads a scenario accepts."""
    add_scenario_name(parser)
    parser.add_argument(
        "--formulation", choices=[f.value for f in Formulation], help="override the scenario's link formulation"
    )
    parser.add_argument("--nodes", type=_positive_int, help="re-discretise with N nodes (total mass and length kept)")


def load_problem(args: argparse.Namespace) -> Problem:
    """The scenario named on the command line, with its overrides applied."""
    problem = load_scenario(args.scenario)
    if args.nodes is not None:
        problem = problem.with_nodes(args.nodes)
    if args.formulation is not None:
        problem = problem.with_formulation(args.formulation)
    return problem


@dataclass(frozen=True)
class Command:
    """A subcommand: its name, its one-line help, and where its ``add_arguments`` and ``run`` are
    (``module:function``; imported only when the command is the one run, so that ``funicular solve``
    does not load the benchmark's, the checker's or the studies' dependencies)."""

    name: str
    help: str
    add_arguments: str
    run: str


def _load(where: str) -> Callable[..., Any]:
    module, _, name = where.partition(":")
    function: Callable[..., Any] = getattr(importlib.import_module(module), name)
    return function


def _solve(args: argparse.Namespace) -> int:
    problem = load_problem(args)
    if args.plot is not None:
        from funicular.plot import check_plot_path

        check_plot_path(args.plot)  # fail before solving, not after
    solution = solve_for_cli(problem, args.solver, args.tol, args.max_iterations, args.exact_start)
    print(summary(solution))
    if args.json is not None:
        from funicular.checks import solution_document

        atomic_write_text(args.json, to_json(solution_document(solution)))
        print(f"  wrote {args.json}")
    if args.plot is not None:
        from funicular.plot import save_solution_plot

        save_solution_plot(solution, args.plot)
        print(f"  wrote {args.plot}")
    return EXIT_OK if solution.converged else EXIT_NOT_CONVERGED


def _scenarios(args: argparse.Namespace) -> int:
    scenarios = builtin_scenarios()
    width = max(map(len, scenarios))
    for name, description in scenarios.items():
        print(f"{name:<{width}}  {description}")
    return EXIT_OK


COMMANDS = (
    Command(
        "solve", "solve a scenario and print its forces", "funicular.cli:_add_solve_arguments", "funicular.cli:_solve"
    ),
    Command("scenarios", "list the built-in scenarios", "funicular.cli:_no_arguments", "funicular.cli:_scenarios"),
    Command(
        "study",
        "studies of a scenario (refine: growing N)",
        "funicular.studies.refine:add_study_arguments",
        "funicular.studies.refine:run_study",
    ),
    Command(
        "sweep",
        "solve a scenario over a range or grid of its values",
        "funicular.studies.sweep:add_arguments",
        "funicular.studies.sweep:run",
    ),
    Command(
        "explore",
        "solve from many starts and list the distinct equilibria",
        "funicular.studies.explore:add_arguments",
        "funicular.studies.explore:run",
    ),
    Command(
        "report",
        "write an HTML (or Markdown) report of a scenario",
        "funicular.htmlreport:add_arguments",
        "funicular.htmlreport:run",
    ),
    Command(
        "check",
        "KKT, LICQ, MFCQ and second-order checks of a point",
        "funicular.checks:add_arguments",
        "funicular.checks:run",
    ),
    Command(
        "compare",
        "solve with every available solver and compare them",
        "funicular.backends:add_arguments",
        "funicular.backends:run",
    ),
    Command(
        "bench",
        "time funicular and other solvers as N grows",
        "funicular.benchmark:add_arguments",
        "funicular.benchmark:run",
    ),
)


def _no_arguments(parser: argparse.ArgumentParser) -> None:
    """``scenarios`` takes none."""


def _chosen(argv: Sequence[str]) -> str | None:
    """The command named on the command line (its first word that is not an option), if any."""
    return next((word for word in argv if not word.startswith("-")), None)


def _parser(chosen: str | None) -> argparse.ArgumentParser:
    """Every command is listed; only the ``chosen`` one's arguments are loaded (the others' parsers
    are never used: argparse parses one subcommand)."""
    parser = argparse.ArgumentParser(
        prog="funicular",
        description="Equilibria of hanging chains by energy minimization, with the forces read off the multipliers.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        subparser = subparsers.add_parser(command.name, help=command.help)
        if command.name == chosen:
            _load(command.add_arguments)(subparser)
    return parser


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised so it unwinds like Ctrl-C: files being written are cleaned up, not left half-written."""


def _terminate(signum: int, frame: object) -> None:
    raise _Terminated


def main(argv: Sequence[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _terminate)
    try:
        words = sys.argv[1:] if argv is None else list(argv)
        args = _parser(_chosen(words)).parse_args(words)
        run: Callable[[argparse.Namespace], int] = _load(next(c.run for c in COMMANDS if c.name == args.command))
        return run(args)
    except FunicularError as error:
        print(f"funicular: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:  # an output path that cannot be written
        print(f"funicular: error: {error.strerror or error}: {error.filename}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt as interruption:
        terminated = isinstance(interruption, _Terminated)
        print("funicular: terminated" if terminated else "funicular: interrupted", file=sys.stderr)
        return 143 if terminated else 130


if __name__ == "__main__":
    sys.exit(main())
