"""Compile numba's kernels ahead of the first solve: ``python -m funicular.solver.warm_up``.

numba compiles a kernel the first time it runs and caches it on disk; on a fresh install that is
about a minute for every kernel a solve can use, which the first solve would otherwise spend
looking hung. ``make`` runs this while it installs. Each chain below takes another path through
the solver (the compiled loop with a disk, a free chain's exact start, the coarse-to-fine polish,
link contact, a box, whose phi is not quadratic, the squared formulation); a path that none of
them takes compiles on first use as before.
"""

from __future__ import annotations

import time

from funicular.model import Problem
from funicular.obstacles import Box, Disk
from funicular.solver.compiled import HAVE_NUMBA
from funicular.solver.ipm import SolverOptions, solve

SUPPORTS = [(0, (0.0, 0.0)), (-1, (1.0, 0.0))]


def chains() -> list[tuple[Problem, SolverOptions]]:
    """The chains whose solves compile the kernels, each with its options."""
    disk = Disk((0.5, -0.55), 0.25)
    build = Problem.build
    compiled = SolverOptions(compiled=True)
    general = SolverOptions(compiled=True, exact_start=False)
    return [
        (build(nodes=50, length=1.5, mass=1.0, gravity=1.0, supports=SUPPORTS, obstacles=[disk]), compiled),
        (build(nodes=50, length=1.5, mass=1.0, gravity=1.0, supports=SUPPORTS), compiled),
        (build(nodes=50, length=1.5, mass=1.0, gravity=1.0, supports=SUPPORTS), general),
        (build(nodes=50, length=1.5, mass=1.0, gravity=1.0, supports=SUPPORTS, formulation="squared"), general),
        (build(nodes=1000, length=1.5, mass=1.0, gravity=1.0, supports=SUPPORTS, obstacles=[disk]), compiled),
        (
            build(nodes=40, length=1.5, mass=1.0, gravity=1.0, supports=SUPPORTS, obstacles=[disk], contact="links"),
            compiled,
        ),
        (
            build(
                nodes=40,
                length=1.5,
                mass=1.0,
                gravity=1.0,
                supports=SUPPORTS,
                obstacles=[Box((0.5, -0.7), (0.2, 0.2), 0.05)],
            ),
            compiled,
        ),
    ]


def main() -> int:
    if not HAVE_NUMBA:
        print("funicular: numba is not installed; nothing to compile (the numpy paths need none).")
        return 0
    started = time.perf_counter()
    for problem, options in chains():
        solve(problem, options)
    print(f"funicular: numba's kernels compiled or loaded from its cache in {time.perf_counter() - started:.0f} s.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
