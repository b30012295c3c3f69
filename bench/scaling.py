"""Solve time and iteration count against N for the two-support chain (norm form, no obstacle).

Problem family (issue 6): supports 1 apart at equal height, chain length 1.5, total mass 1, g = 1;
"disk" adds a disk of radius 0.25 centred at (0.5, -0.55) under the chain.
Prints a Markdown table; each time is the median of several runs after one warm-up run.

    python bench/scaling.py [N ...]
"""

from __future__ import annotations

import platform
import statistics
import sys
import time

import numpy as np
import scipy

from funicular import Problem, solve
from funicular.obstacles import Disk


def family(nodes: int, formulation: str = "norm", disk: bool = False) -> Problem:
    return Problem.build(
        nodes=nodes, length=1.5, mass=1.0, gravity=1.0, formulation=formulation,
        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Disk((0.5, -0.55), 0.25)] if disk else [],
    )  # fmt: skip


def measure(nodes: int, formulation: str, disk: bool) -> tuple[float, int, float]:
    problem = family(nodes, formulation, disk)
    solve(problem)
    repeats = 5 if nodes <= 10_000 else 3
    times, iterations, error = [], 0, 0.0
    for _ in range(repeats):
        started = time.perf_counter()
        solution = solve(problem)
        times.append(time.perf_counter() - started)
        iterations, error = solution.iterations, solution.kkt_scaled.max()
        assert solution.converged, solution.status
    return statistics.median(times), iterations, error


def main() -> None:
    sizes = [int(a) for a in sys.argv[1:]] or [100, 1_000, 10_000, 100_000]
    print(
        f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, python {platform.python_version()}, "
        f"numpy {np.__version__}, scipy {scipy.__version__}"
    )
    print()
    print("| N | problem | formulation | median time [s] | Newton steps | max scaled KKT residual |")
    print("|---:|---|---|---:|---:|---:|")
    for disk, formulation in ((False, "norm"), (False, "squared"), (True, "norm")):
        for nodes in sizes:
            seconds, iterations, error = measure(nodes, formulation, disk)
            name = "disk" if disk else "no obstacle"
            print(f"| {nodes:,} | {name} | {formulation} | {seconds:.4f} | {iterations} | {error:.1e} |", flush=True)


if __name__ == "__main__":
    main()
