"""The result files' benchmark: how long writing and reading ``.json``, ``.npz`` and ``.parquet`` takes,
and how much memory, next to the solve itself (docs/results-files-benchmark.md).

Run from the repository::

    nice -n 5 .venv/bin/python -m bench.results --markdown docs/results-files-benchmark.md

The instance: the benchmark family's chain with the disk (bench/run.py): supports at (0, 0) and
(1, 0), length 1.5, mass 1, g = 1, ``Disk((0.5, -0.55), 0.25)``, N nodes.

Every case runs in a process of its own, so that its peak resident memory (``ru_maxrss``) is its
own: "solve" solves and stops; "write" checks the path (as ``funicular solve --output`` does
before solving; for ``.parquet`` this imports pyarrow), solves, builds the document
(:func:`funicular.checks.solution_document`: ``to_dict``, the LICQ block, the problem table) and
writes it; "read" reads the file back with :func:`funicular.load_solution` (the document, its
validation and the :class:`Solution`) and nothing else. Times are wall clock; each case runs
``--repeats`` times, interleaved with the others, and the table shows medians.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from funicular._io import atomic_write_text
from funicular._results import FORMATS, check_output, write_document
from funicular.model import Problem
from funicular.obstacles import Disk

EXIT_OK, EXIT_BAD_INPUT = 0, 2
DEFAULT_NODES = (100_000, 1_000_000)
CASES = ("solve", "write", "read")


def family(nodes: int) -> Problem:
    """The benchmark family's chain with the disk (bench/run.py)."""
    return Problem.build(
        nodes=nodes,
        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        length=1.5,
        mass=1.0,
        gravity=1.0,
        obstacles=[Disk(center=(0.5, -0.55), radius=0.25)],
    )


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kilobytes on Linux


def run_case(case: str, nodes: int, path: str) -> dict[str, float]:
    """One case, in this process: its times [s] and peak memory [MiB]."""
    from funicular import load_solution, solve
    from funicular.checks import solution_document

    figures: dict[str, float] = {}
    if case == "read":
        started = time.perf_counter()
        solution = load_solution(path)
        figures["read"] = time.perf_counter() - started
        if solution.problem.n_nodes != nodes:
            raise SystemExit(f"{path} holds {solution.problem.n_nodes} nodes, not {nodes}")
    else:
        if case == "write":
            check_output(path)  # as the command line does before solving (this imports pyarrow for .parquet)
        started = time.perf_counter()
        solution = solve(family(nodes))
        figures["solve"] = time.perf_counter() - started
        if case == "write":
            started = time.perf_counter()
            document = solution_document(solution)
            figures["document"] = time.perf_counter() - started
            started = time.perf_counter()
            write_document(document, path)
            figures["write"] = time.perf_counter() - started
            figures["megabytes"] = os.path.getsize(path) / 1e6
    figures["peak_mib"] = _peak_mib()
    return figures


def _child(case: str, nodes: int, path: str) -> dict[str, float]:
    command = [sys.executable, __file__, "--case", case, "--nodes", str(nodes), "--path", path]
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise SystemExit(f"python -m bench.results: the {case} case at N = {nodes} failed:\n{result.stderr}")
    figures: dict[str, float] = json.loads(result.stdout.splitlines()[-1])
    return figures


@dataclass(frozen=True)
class Row:
    nodes: int
    format: str
    solve: float
    solve_peak: float
    document: float
    write: float
    write_peak: float
    read: float
    read_peak: float
    megabytes: float


def _median(runs: Sequence[dict[str, float]]) -> dict[str, float]:
    return {key: statistics.median(run[key] for run in runs) for key in runs[0]}


def measure(nodes: int, directory: Path, repeats: int) -> list[Row]:
    """Every format at ``nodes``: a solve alone, then for each format a write and a read; each
    ``repeats`` times, interleaved (load on a shared machine then hits every case alike), medians."""
    paths = {suffix: str(directory / f"result-{nodes}{suffix}") for suffix in FORMATS}
    runs: dict[tuple[str, str], list[dict[str, float]]] = {}
    for _ in range(repeats):
        runs.setdefault(("solve", ""), []).append(_child("solve", nodes, ""))
        for suffix, path in paths.items():
            runs.setdefault(("write", suffix), []).append(_child("write", nodes, path))
            runs.setdefault(("read", suffix), []).append(_child("read", nodes, path))
            os.unlink(path)
    alone = _median(runs["solve", ""])
    rows = []
    for suffix in FORMATS:
        written, read = _median(runs["write", suffix]), _median(runs["read", suffix])
        rows.append(
            Row(
                nodes,
                suffix,
                alone["solve"],
                alone["peak_mib"],
                written["document"],
                written["write"],
                written["peak_mib"],
                read["read"],
                read["peak_mib"],
                written["megabytes"],
            )
        )
    return rows


def machine() -> dict[str, str]:
    """What the figures were measured on: CPU, cores, load and package versions."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    models = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name") and ":" in line]
    versions = {"python": platform.python_version(), "numpy": np.__version__}
    for package in ("pyarrow", "orjson", "scipy"):
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return {
        "platform": platform.platform(),
        "cpu": models[0] if models else platform.processor() or platform.machine(),
        "cores": str(os.cpu_count()),
        "load_average": " / ".join(f"{load:.2f}" for load in os.getloadavg()),
        "versions": ", ".join(f"{name} {version}" for name, version in versions.items()),
    }


def markdown(rows: Sequence[Row], before: dict[str, str], after: dict[str, str], repeats: int) -> str:
    lines = [
        "# Result files: benchmark",
        "",
        "Generated by `python -m bench.results` (see [Result files](results-files.md)); do not edit by hand.",
        "",
        "The chain with the disk at N nodes. *solve*: the solve alone, in a process of its own. *document*:",
        "`solution_document` (`to_dict`, the LICQ block, the problem table); *write*: that document to the",
        "file; *added*: document + write, what an output adds to the solve. *read*: `load_solution`, the",
        "file back to a `Solution`. Peak memory is each process's resident maximum: *solve*'s is the solve",
        f"alone, *with output* solves and writes, *read* only reads. Medians of {repeats} runs per case.",
        "",
        "| N | format | size [MB] | solve [s] | document [s] | write [s] | added [s] | read [s] "
        "| peak solve [MiB] | peak with output [MiB] | ratio | peak read [MiB] |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.nodes:,} | {r.format} | {r.megabytes:.1f} | {r.solve:.2f} | {r.document:.2f} | {r.write:.2f} "
            f"| {r.document + r.write:.2f} | {r.read:.2f} | {r.solve_peak:.0f} | {r.write_peak:.0f} "
            f"| {r.write_peak / r.solve_peak:.2f} | {r.read_peak:.0f} |"
        )
    lines += [
        "",
        "Machine:",
        "",
        f"- CPU: {before['cpu']} ({before['cores']} cores, shared), {before['platform']}",
        f"- load average (1 / 5 / 15 min): {before['load_average']} before, {after['load_average']} after",
        f"- {before['versions']}",
        "",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.results",
        description="Time writing and reading result files (docs/results-files-benchmark.md).",
    )
    parser.add_argument("--nodes", default=",".join(map(str, DEFAULT_NODES)), help="node counts, comma-separated")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each case; the table shows medians")
    parser.add_argument("--markdown", metavar="PATH", help="write the table here")
    parser.add_argument("--case", choices=CASES, help=argparse.SUPPRESS)  # one case, in a process of its own
    parser.add_argument("--path", default="", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    try:
        counts = [int(item) for item in args.nodes.split(",")]
    except ValueError:
        message = f"--nodes {args.nodes!r} must be integers such as 100000,1000000"
        print(f"python -m bench.results: error: {message}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.case is not None:
        print(json.dumps(run_case(args.case, counts[0], args.path)))
        return EXIT_OK
    before = machine()
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="funicular-results-") as directory:
        for nodes in counts:
            rows += measure(nodes, Path(directory), max(args.repeats, 1))
            print(f"N = {nodes}: done", file=sys.stderr)
    text = markdown(rows, before, machine(), max(args.repeats, 1))
    print(text)
    if args.markdown:
        atomic_write_text(args.markdown, text)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
