"""The ``funicular`` command line: one module per command, loaded only when that command runs.

Exit status: 0 success, 1 a solve that did not converge, 2 bad input (one sentence on stderr).
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from funicular import __version__
from funicular.cli._common import EXIT_BAD_INPUT
from funicular.errors import FunicularError


@dataclass(frozen=True)
class Command:
    """A subcommand: its name, its one-line help, and its module (``funicular.cli.<module>``, with
    ``add_arguments(parser)`` and ``run(args) -> int``), imported only when the command is the one
    run, so that ``funicular solve`` does not load the checker's or the studies' dependencies."""

    name: str
    help: str
    module: str


COMMANDS = (
    Command("solve", "solve a scenario and print its forces", "solve"),
    Command("scenarios", "list the built-in scenarios", "scenarios"),
    Command("study", "studies of a scenario (refine: growing N)", "study"),
    Command("sweep", "solve a scenario over a range or grid of its values", "sweep"),
    Command("explore", "solve from many starts and list the distinct equilibria", "explore"),
    Command("invert", "mirror a hung net into its compression-only form (OBJ and CSV)", "invert"),
    Command("report", "write an HTML (or Markdown) report of a scenario", "report"),
    Command("check", "KKT, LICQ, MFCQ and second-order checks of a point", "check"),
    Command("compare", "solve with every available solver and compare them", "compare"),
    Command("serve", "an interactive explorer in the web browser (local)", "serve"),
)


def _module(command: Command) -> object:
    return importlib.import_module(f"funicular.cli.{command.module}")


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
    parser.add_argument("--version", action="version", version=f"funicular {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        subparser = subparsers.add_parser(command.name, help=command.help)
        if command.name == chosen:
            _module(command).add_arguments(subparser)  # type: ignore[attr-defined]
    return parser


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised so it unwinds like Ctrl-C: files being written are cleaned up, not left half-written."""


def _terminate(signum: int, frame: object) -> None:
    raise _Terminated


def _pipe_closed() -> int:
    """The reader of standard output went away (``funicular scenarios | head -1``): end quietly,
    with what is still buffered discarded rather than reported at exit."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 128 + signal.SIGPIPE


def main(argv: Sequence[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _terminate)
    try:
        words = sys.argv[1:] if argv is None else list(argv)
        args = _parser(_chosen(words)).parse_args(words)
        command = next(c for c in COMMANDS if c.name == args.command)
        run: Callable[[argparse.Namespace], int] = _module(command).run  # type: ignore[attr-defined]
        status = run(args)
        sys.stdout.flush()  # (a closed pipe shows here, not at exit)
        return status
    except BrokenPipeError:
        return _pipe_closed()
    except FunicularError as error:
        print(f"funicular: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:  # an output that failed while being written
        print(f"funicular: error: {error.strerror or error}: {error.filename}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ImportError as error:  # an extension module interrupted while loading reports the interrupt so
        interruption = error.__cause__ or error.__context__
        if not isinstance(interruption, KeyboardInterrupt):
            raise
        return _interrupted(interruption)
    except KeyboardInterrupt as interruption:
        return _interrupted(interruption)


def _interrupted(interruption: KeyboardInterrupt) -> int:
    terminated = isinstance(interruption, _Terminated)
    print("funicular: terminated" if terminated else "funicular: interrupted", file=sys.stderr)
    return 143 if terminated else 130
