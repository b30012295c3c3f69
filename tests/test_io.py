"""Atomic file writes: the target is either fully replaced or left untouched."""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

import pytest

from funicular._io import atomic_write, atomic_write_text
from funicular.errors import OutputError


def _fail_halfway(stream: BinaryIO) -> None:
    stream.write(b"partial")
    raise RuntimeError("disk on fire")


def test_text_is_written_as_utf8_without_newline_translation(tmp_path: Path) -> None:
    target = tmp_path / "out.json"
    atomic_write_text(target, "α = 1\r\nβ = 2\n")
    assert target.read_bytes() == "α = 1\r\nβ = 2\n".encode()
    assert os.listdir(tmp_path) == ["out.json"]


def test_existing_file_is_replaced(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.write_text("old content that is longer than the new one")
    atomic_write_text(str(target), "new")
    assert target.read_text() == "new"


def test_failing_writer_keeps_the_previous_file_and_leaves_no_temp_file(tmp_path: Path) -> None:
    target = tmp_path / "out.bin"
    target.write_bytes(b"previous")
    with pytest.raises(RuntimeError, match="disk on fire"):
        atomic_write(target, _fail_halfway)
    assert target.read_bytes() == b"previous"
    assert os.listdir(tmp_path) == ["out.bin"]


def test_failing_writer_creates_nothing(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError):
        atomic_write(tmp_path / "new.bin", _fail_halfway)
    assert os.listdir(tmp_path) == []


def test_interrupt_also_cleans_up(tmp_path: Path) -> None:
    def interrupted(stream: BinaryIO) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(tmp_path / "new.bin", interrupted)
    assert os.listdir(tmp_path) == []


def test_missing_directory_is_an_error_naming_the_path_given(tmp_path: Path) -> None:
    target = tmp_path / "missing" / "out.txt"
    with pytest.raises(OutputError) as raised:
        atomic_write_text(target, "x")
    assert str(target) in str(raised.value) and ".tmp" not in str(raised.value)


@pytest.mark.skipif(os.name == "nt", reason="POSIX permissions")
def test_new_file_gets_the_usual_permissions_and_existing_keeps_its_own(tmp_path: Path) -> None:
    umask = os.umask(0o022)
    os.umask(umask)
    fresh = tmp_path / "fresh.txt"
    atomic_write_text(fresh, "x")
    assert fresh.stat().st_mode & 0o777 == 0o666 & ~umask

    kept = tmp_path / "kept.txt"
    kept.write_text("old")
    kept.chmod(0o640)
    atomic_write_text(kept, "new")
    assert kept.stat().st_mode & 0o777 == 0o640
