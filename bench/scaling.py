"""Superseded by ``funicular bench`` (``make bench``); kept so that ``python bench/scaling.py [N ...]`` still works.

It now runs ``funicular bench --solvers funicular [--nodes N,...]``: funicular alone on the benchmark
family of issue 6 (norm formulation, with and without the disk), timed and checked.
"""

from __future__ import annotations

import sys

from funicular.cli import main

if __name__ == "__main__":
    nodes = ["--nodes", ",".join(sys.argv[1:])] if sys.argv[1:] else []
    sys.exit(main(["bench", "--solvers", "funicular", *nodes]))
