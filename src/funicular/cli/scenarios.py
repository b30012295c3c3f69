"""``funicular scenarios``: the built-in scenarios with their descriptions."""

from __future__ import annotations

import argparse

from funicular.cli._common import EXIT_OK
from funicular.scenario import builtin_scenarios


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``scenarios`` takes none."""


def run(args: argparse.Namespace) -> int:
    scenarios = builtin_scenarios()
    width = max(map(len, scenarios))
    for name, description in scenarios.items():
        print(f"{name:<{width}}  {description}")
    return EXIT_OK
