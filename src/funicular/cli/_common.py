"""What the commands share: exit statuses, the scenario arguments, option types and output files."""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TextIO

from funicular._io import atomic_write_text, check_writable
from funicular._results import FORMATS, check_output, json_bytes, write_document
from funicular.errors import FunicularError, OutputError, ScenarioError, shown
from funicular.model import MAX_NODES, Formulation, Problem
from funicular.scenario import DEFAULT_SCENARIO, load_scenario

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT = 0, 1, 2
STDOUT = "-"  # an output PATH of "-" is standard output


def integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not an integer") from None


def node_count(text: str) -> int:
    """``--nodes N``: from 2 to the scenario files' limit, checked before anything is allocated."""
    value = integer(text)
    if value < 2:
        raise argparse.ArgumentTypeError(f"{value} is too small; a chain needs at least 2 nodes")
    if value > MAX_NODES:
        raise argparse.ArgumentTypeError(f"{value} is too large; use at most {MAX_NODES} nodes")
    return value


def iteration_count(text: str) -> int:
    """``--max-iterations N``: at least one Newton step."""
    value = integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is too small; give a number of Newton steps >= 1")
    return value


def escape_nodes(text: str) -> int:
    """``--escape-up-to N``: a number of nodes >= 0."""
    value = integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; give a number of nodes >= 0")
    return value


def positive_number(example: str) -> Callable[[str], float]:
    """An option's type: a finite positive number (the message gives ``example``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{shown(text)} is not a number") from None
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"{shown(text)} must be a finite positive number, such as {example}")
        return value

    return parse


tolerance = positive_number("1e-10")  # --tol


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
    parser.add_argument("--nodes", type=node_count, help="re-discretise with N nodes (total mass and length kept)")


def overridden(problem: Problem, args: argparse.Namespace) -> Problem:
    """``problem`` with the --nodes and --formulation of the command line applied."""
    if args.nodes is not None:
        try:
            problem = problem.with_nodes(args.nodes)
        except FunicularError as error:
            raise error.renamed("--nodes") from None
    if args.formulation is not None:
        problem = problem.with_formulation(args.formulation)
    return problem


def load_problem(args: argparse.Namespace) -> Problem:
    """The scenario named on the command line, with its overrides applied."""
    return overridden(load_scenario(args.scenario), args)


def check_outputs(args: argparse.Namespace, *options: str) -> None:
    """Every output PATH given in ``options`` (attribute names: "json", "output", ...) can be
    written: checked before any long work, naming the path as given. A ``--json`` file may not
    end in .npz or .parquet: a result file's reader goes by its content and its extension, which
    would disagree."""
    for option in options:
        path = getattr(args, option)
        if path is not None and path != STDOUT:
            suffix = Path(path).suffix.lower()
            if option == "json" and suffix in FORMATS and suffix != ".json":
                raise OutputError(
                    f"--json {path!r} ends in {suffix}, but --json writes JSON; give a name ending in .json "
                    f"(funicular solve --output writes {suffix} files)."
                )
            check_writable(path, f"--{option}")


def check_result_output(args: argparse.Namespace, option: str) -> None:
    """The result file ``option`` names (an attribute name, such as "output") can be written, in a
    format its extension names (.json, .npz, .parquet; .parquet needs pyarrow): checked before solving."""
    path = getattr(args, option)
    if path is not None and path != STDOUT:
        check_output(path, f"--{option}")


def write_output(path: str, text: str, log: TextIO | None = None) -> None:
    """Write ``text`` to ``path`` (standard output for "-"); say so on ``log`` (standard output by
    default) for a file."""
    if path == STDOUT:
        sys.stdout.write(text)
        sys.stdout.flush()
        return
    atomic_write_text(path, text)
    print(f"  wrote {path}", file=log or sys.stdout)


def write_result(
    path: str,
    document: dict[str, Any],
    option: str,
    indent: bool = False,
    json: bool = False,
    log: TextIO | None = None,
) -> None:
    """Write a result ``document`` to ``path``: as JSON if ``json`` or ``path`` is "-" (standard
    output), else in the format of its extension (checked by :func:`check_result_output`). Says so on
    ``log`` (standard output by default) for a file."""
    if path == STDOUT:
        sys.stdout.write(json_bytes(document, indent).decode())
        sys.stdout.flush()
        return
    write_document(document, path, indent, option, ".json" if json else None)
    print(f"  wrote {path}", file=log or sys.stdout)


def log_stream(args: argparse.Namespace) -> TextIO:
    """Where the human-readable text goes: standard error when --json or --output writes to standard output."""
    to_stdout = STDOUT in (getattr(args, "json", None), getattr(args, "output", None))
    return sys.stderr if to_stdout else sys.stdout


def node_list(text: str) -> list[int]:
    """``--nodes 2,3,5`` -> [2, 3, 5]; the error names the first bad entry."""
    counts = []
    for item in text.split(","):
        try:
            counts.append(node_count(item.strip()))
        except argparse.ArgumentTypeError as error:
            raise ScenarioError(f"--nodes: {error}; give a list like 3,5,9,17.") from None
    return counts


SLOW_FIRST = {"ipopt": "casadi"}  # solvers whose package takes seconds to load the first time


def announce_slow_start(solvers: Iterable[str]) -> None:
    """One line on standard error before a step that takes more than a second the first time."""
    for solver in solvers:
        package = SLOW_FIRST.get(solver)
        if package is not None and package not in sys.modules and importlib.util.find_spec(package) is not None:
            print(f"funicular: loading {package} for {solver} (a few seconds the first time)", file=sys.stderr)
