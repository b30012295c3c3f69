"""``funicular invert``: solve a net (or chain), mirror it into its compression-only form, write it as OBJ and CSV."""

from __future__ import annotations

import argparse

import numpy as np

from funicular._solver import solve
from funicular._units import force_unit, with_unit
from funicular.cli._common import (
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    add_scenario_argument,
    iteration_count,
    load_problem,
    positive_number,
    tolerance,
)
from funicular.inversion import check_obj_path, invert, write_obj

DEFAULT_OUTPUT = "shell.obj"
CARRYING_RTOL = 1e-9


scale_factor = positive_number("100")  # --scale


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_argument(parser)
    parser.add_argument(
        "-o",
        "--output",
        default=DEFAULT_OUTPUT,
        metavar="PATH",
        help=f"the OBJ file to write (default {DEFAULT_OUTPUT}); the link forces also go to a .csv beside it",
    )
    parser.add_argument(
        "--scale",
        type=scale_factor,
        default=1.0,
        metavar="S",
        help="multiply every coordinate written by S (model to building; the forces are unchanged)",
    )
    parser.add_argument("--tol", type=tolerance, default=1e-10, help="scaled KKT tolerance (default 1e-10)")
    parser.add_argument(
        "--max-iterations", type=iteration_count, metavar="N", help="Newton steps before giving up (default 200)"
    )


def run(args: argparse.Namespace) -> int:
    problem = load_problem(args)
    csv_path = check_obj_path(args.output, "--output")  # before solving, not after
    solution = solve(problem, tol=args.tol, max_iterations=args.max_iterations)
    if not solution.converged:
        print(f"{problem.name}: {solution.status.value} ({solution.status.message}); nothing written")
        return EXIT_NOT_CONVERGED
    inverted = invert(solution).scaled(args.scale)
    write_obj(inverted, args.output)
    axis = "z" if inverted.dimension == 3 else "y"
    compression = -inverted.axial_force
    largest = float(compression.max(initial=0.0))
    # (links between two supports carry nothing; below this fraction a force is the solver's zero)
    carrying = int(np.count_nonzero(compression > CARRYING_RTOL * largest))
    down = float(-inverted.support_forces[:, -1].sum())
    print(f"{problem.name}: {solution.status.value}; mirrored in {axis} = {inverted.mirror_height:.6g}")
    force = force_unit(problem)
    print(f"  {carrying} of {problem.n_links} links in compression, the largest {with_unit(f'{largest:.6g}', force)}")
    print(f"  {inverted.support_nodes.size} supports pressed down with {with_unit(f'{down:.6g}', force)} in all")
    print(f"  wrote {args.output}")
    print(f"  wrote {csv_path}")
    return EXIT_OK
