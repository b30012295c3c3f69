"""The progress bar of the long-running commands (sweep, explore, study refine, the benchmark).

A rich bar with the time left, on standard error, when standard error is a terminal and the work
is long enough to be worth one; nothing otherwise (``--quiet``, output to a file or a pipe, or
rich, the ``progress`` extra, not installed).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator

PROGRESS_FROM = 10  # units of work (solves, steps) below which no bar is shown: it would only flash

Advance = Callable[[int], None]  # called with the number of units just finished


def no_progress(done: int) -> None:
    """An ``advance`` that shows nothing (the studies' default)."""


def add_quiet_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--quiet", action="store_true", help="no progress bar or other messages on standard error (errors still)"
    )


@contextlib.contextmanager
def progress_bar(
    total: int, label: str, *, quiet: bool = False, minimum: int = PROGRESS_FROM, auto_refresh: bool = True
) -> Iterator[Advance]:
    """Yield ``advance(units)``, which moves a bar of ``total`` units labelled ``label``.

    ``minimum``: the smallest total that gets a bar. ``auto_refresh=False`` redraws only when
    ``advance`` is called (no drawing thread: for timings that must not be disturbed).
    """
    if quiet or total < minimum or not sys.stderr.isatty():
        yield no_progress
        return
    try:  # rich is an optional extra, loaded only when a bar is shown
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
    except ImportError:
        yield no_progress
        return
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("time left"))
    with Progress(
        *columns,
        TimeRemainingColumn(),
        console=Console(file=sys.stderr),
        transient=True,
        auto_refresh=auto_refresh,
        # Lines printed while the bar is shown go above it; only when standard output is the same
        # terminal: otherwise they belong in the file or pipe, not on standard error.
        redirect_stdout=sys.stdout.isatty(),
        redirect_stderr=False,
    ) as progress:
        task = progress.add_task(label, total=total)

        def advance(done: int) -> None:
            progress.advance(task, done)
            if not auto_refresh:
                progress.refresh()

        yield advance
