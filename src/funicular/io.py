"""Atomic file output: the target is replaced in one step, or left exactly as it was."""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO


def _new_file_mode(target: Path) -> int:
    """The permissions the target would get from a plain ``open(target, "w")``.

    Temp files are created with mode 0o600; without this, every output would end up private.
    """
    try:
        return os.stat(target).st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0o022)
        os.umask(umask)
        return 0o666 & ~umask


def atomic_write(path: str | os.PathLike[str], writer: Callable[[BinaryIO], None]) -> None:
    """Call ``writer`` on a temp file next to ``path``, then move it onto ``path``.

    If ``writer`` (or anything else, Ctrl-C included) fails, the temp file is removed and an
    existing file at ``path`` keeps its old content; a reader never sees a half-written file.
    The temp file's name is chosen before it is created, inside the ``try``: an interrupt that
    arrives just after the file appears still knows which file to remove (with ``mkstemp`` the
    name only exists once the call has returned).
    """
    target = Path(path)
    tmp_name: Path | None = None
    try:
        for _ in range(100):
            tmp_name = target.parent / f".{target.name}.{secrets.token_hex(8)}.tmp"
            try:
                fd = os.open(tmp_name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
                break
            except FileExistsError:  # someone else's file: never remove it, try another name
                tmp_name = None
        else:
            raise FileExistsError(f"could not create a temp file next to {target}")
        with os.fdopen(fd, "wb") as tmp:
            writer(tmp)
            tmp.flush()
            os.fsync(tmp.fileno())
        os.chmod(tmp_name, _new_file_mode(target))
        os.replace(tmp_name, target)
    except BaseException:
        if tmp_name is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` as UTF-8 to ``path`` atomically (no newline translation)."""
    data = text.encode("utf-8")

    def write(stream: BinaryIO) -> None:
        stream.write(data)

    atomic_write(path, write)
