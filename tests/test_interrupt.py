"""Kill test (robustness): a signal never leaves a truncated or half-written --json output.

``funicular solve two-supports --nodes N --json OUT`` is interrupted at three moments:

* half a second after the CLI has printed a readiness line (see ``CLI`` below), so the signal
  never lands in the imports: mid-solve of a 300,000-node chain on a slow machine, in the
  document or the write on a fast one (the solve alone takes a few tenths of a second there);
* right after the summary is printed, while the result is being serialised (before any file exists);
* the moment the temp file ``.OUT.*.tmp`` appears next to OUT (between its creation and the
  atomic rename), with a smaller chain so the solve is quick.

OUT is pre-created with known content. Afterwards it must hold either that content or a complete
JSON result (if the run won the race). After SIGINT and SIGTERM no temp file may remain. After
SIGKILL the process cannot clean up: a ``.OUT.*.tmp`` file may be left behind, but OUT itself is
still either untouched or complete (the rename is atomic).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

PREVIOUS = '{"previous": "complete result"}\n'
SOLVE_NODES = 300_000  # solve, document and write: tenths of a second to seconds, by machine
WRITE_NODES = 30_000  # quick to solve; the signal lands while the output is written
TIMEOUT = 600.0  # seconds for any one run (a 300,000-node solve on a loaded 2-core machine: ~40 s)

# The CLI's own main(), behind a line that says the imports are done; otherwise the same process as
# `python -m funicular.cli solve ...` (an interrupt during the imports is Python's business, not ours).
CLI = "import sys; from funicular.cli import main; print('ready', flush=True); sys.exit(main(sys.argv[1:]))"


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str
    signalled: bool  # False: the run finished before the moment to signal came


def _temp_files(folder: Path, target: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(f".{target.name}.") and p.name.endswith(".tmp"))


def run_and_signal(folder: Path, sig: int, moment: str, nodes: int) -> tuple[Run, Path]:
    """Start the CLI writing ``folder/out.json`` (pre-created with PREVIOUS), send ``sig`` at ``moment``:
    "solve" (0.5 s after the imports), "serialise" (right after the summary) or "write" (when the temp
    file appears)."""
    out = folder / "out.json"
    out.write_text(PREVIOUS, encoding="utf-8")
    args = ["solve", "two-supports", "--nodes", str(nodes), "--json", str(out)]
    process = subprocess.Popen(
        [sys.executable, "-u", "-c", CLI, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # our own signals only reach this process
    )
    signalled = False
    try:
        assert process.stdout is not None
        assert process.stdout.readline() == "ready\n"
        deadline = time.monotonic() + TIMEOUT
        if moment == "solve":
            time.sleep(0.5)
        elif moment == "serialise":
            # The summary's first line is printed after the solve, before the JSON is built.
            line = process.stdout.readline()
            assert line.startswith("two-supports:") or not line, line
        else:
            while process.poll() is None and not _temp_files(folder, out):
                if time.monotonic() > deadline:
                    pytest.fail(f"no temp file within {TIMEOUT} s")
                time.sleep(0.0005)
        if process.poll() is None:
            process.send_signal(sig)
            signalled = True
        stdout, stderr = process.communicate(timeout=TIMEOUT)
    finally:
        if process.poll() is None:  # only if something above failed
            process.kill()
            process.communicate()
    return Run(process.returncode, stdout, stderr, signalled), out


def assert_previous_or_complete(out: Path) -> None:
    """OUT is untouched or a complete JSON result, never anything in between."""
    text = out.read_text(encoding="utf-8")
    if text == PREVIOUS:
        return
    result = json.loads(text)  # a truncated file would fail here
    assert result["nodes"] == len(result["x"]) == len(result["y"])
    assert len(result["link_tension"]) == result["nodes"] - 1
    assert result["status"] in ("optimal", "max_iterations", "stalled", "nonfinite")


def assert_clean_exit(run: Run, sig: int) -> None:
    if not run.signalled:
        assert run.returncode in (0, 1), run
        return
    assert "Traceback" not in run.stderr, run.stderr
    if sig == signal.SIGINT:
        # KeyboardInterrupt is caught: one line, status 130 (unless the run was already past it).
        # A SIGINT landing after main() has returned, while Python shuts down with its default
        # handler back in place, ends the process by that signal: allowed once the output is written.
        finished = "wrote " in run.stdout
        assert run.returncode in ((130, 0, 1, -signal.SIGINT) if finished else (130, 0, 1)), run
        if run.returncode == 130:
            assert run.stderr.strip().splitlines() == ["funicular: interrupted"], run.stderr
    else:
        assert run.returncode in (-sig, 128 + sig, 0, 1), run


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["SIGINT", "SIGTERM", "SIGKILL"])
def test_signal_half_a_second_in_leaves_the_previous_output_or_a_complete_one(tmp_path: Path, sig: int) -> None:
    """Mid-solve on a slow machine; on a fast one the solve is over and the signal lands in the
    document or the write. Either way OUT is whole; only SIGKILL, which cannot be handled, may
    leave the temp file of a write it cut short."""
    run, out = run_and_signal(tmp_path, sig, "solve", SOLVE_NODES)
    assert_clean_exit(run, sig)
    assert_previous_or_complete(out)
    assert len(_temp_files(tmp_path, out)) <= (1 if sig == signal.SIGKILL else 0)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_while_serialising_leaves_the_previous_output(tmp_path: Path, sig: int) -> None:
    run, out = run_and_signal(tmp_path, sig, "serialise", WRITE_NODES)
    assert_clean_exit(run, sig)
    assert_previous_or_complete(out)
    assert _temp_files(tmp_path, out) == []


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_while_writing_leaves_no_temp_file(tmp_path: Path, sig: int) -> None:
    """SIGINT and SIGTERM between the temp file's creation and the rename: the temp file is removed."""
    run, out = run_and_signal(tmp_path, sig, "write", WRITE_NODES)
    assert_clean_exit(run, sig)
    assert_previous_or_complete(out)
    assert _temp_files(tmp_path, out) == []


@pytest.mark.slow
def test_sigkill_while_writing_keeps_the_target_whole(tmp_path: Path) -> None:
    """SIGKILL cannot be handled: a temp file may remain (documented), but the target is never partial."""
    run, out = run_and_signal(tmp_path, signal.SIGKILL, "write", WRITE_NODES)
    assert_clean_exit(run, signal.SIGKILL)
    assert_previous_or_complete(out)
    left = _temp_files(tmp_path, out)
    assert len(left) <= 1, left


def test_uninterrupted_run_writes_complete_json(tmp_path: Path) -> None:
    """The reference: without a signal OUT is replaced by the complete result, and nothing else is left."""
    out = tmp_path / "out.json"
    out.write_text(PREVIOUS, encoding="utf-8")
    result = subprocess.run(
        [sys.executable, "-m", "funicular.cli", "solve", "two-supports", "--nodes", "2000", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )
    assert result.returncode == 0, result
    assert out.read_text(encoding="utf-8") != PREVIOUS
    assert_previous_or_complete(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]
