"""Superseded by ``bench/run.py`` (``make bench``); kept so that ``python bench/scaling.py [N ...]`` still works.

It runs ``bench/run.py --solvers funicular [--nodes N,...]``: funicular alone on the benchmark
family (norm formulation, with and without the disk), timed and checked.
"""

from __future__ import annotations

import sys

from bench.run import main

if __name__ == "__main__":
    nodes = ["--nodes", ",".join(sys.argv[1:])] if sys.argv[1:] else []
    sys.exit(main(["--solvers", "funicular", *nodes]))
