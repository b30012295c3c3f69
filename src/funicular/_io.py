"""File output: a regular file is replaced in one step, or left exactly as it was.

A symlink is followed (its target is written, atomically there), and a character device or a
FIFO (``/dev/stdout``, a named pipe) is written directly: only a regular file, or a new one,
is replaced by a rename.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from funicular.errors import OutputError


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


def _is_stream(target: Path) -> bool:
    """Whether ``target`` is a character device or a FIFO: written in place, never replaced."""
    try:
        mode = os.stat(target).st_mode
    except OSError:
        return False
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)


def _cannot(path: str | os.PathLike[str], option: str, why: str) -> OutputError:
    where = f"{option} {str(path)!r}" if option else repr(str(path))
    return OutputError(f"cannot write {where}: {why}.")


def check_writable(path: str | os.PathLike[str], option: str = "") -> None:
    """Raise :class:`OutputError` naming ``path`` (and the ``option`` that gave it) if it cannot be
    written: a directory, a missing or read-only directory, a read-only file. Checked before work."""
    target = Path(os.path.realpath(path))
    if target.is_dir():
        raise _cannot(path, option, "it is a directory; give a file name")
    if target.exists():
        if not os.access(target, os.W_OK):
            raise _cannot(path, option, "permission denied")
        if _is_stream(target):
            return
    parent = target.parent
    if not parent.is_dir():
        raise _cannot(path, option, f"the directory {str(Path(path).parent)!r} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise _cannot(path, option, f"the directory {str(Path(path).parent)!r} is not writable")


def atomic_write(path: str | os.PathLike[str], writer: Callable[[BinaryIO], None]) -> None:
    """Call ``writer`` on a temp file next to ``path`` (next to its target if it is a symlink),
    then move it onto that target; a character device or a FIFO is written directly.

    If ``writer`` (or anything else, Ctrl-C included) fails, the temp file is removed and an
    existing file at ``path`` keeps its old content; a reader never sees a half-written file.
    The temp file's name is chosen before it is created, inside the ``try``: an interrupt that
    arrives just after the file appears still knows which file to remove (with ``mkstemp`` the
    name only exists once the call has returned). Errors name ``path``, never the temp file.
    """
    target = Path(os.path.realpath(path))
    if _is_stream(target):
        try:
            with open(target, "wb") as stream:
                writer(stream)
        except OSError as error:
            raise _cannot(path, "", error.strerror or str(error)) from None
        return
    tmp_name: Path | None = None
    try:
        for _ in range(100):
            # (os.urandom, as secrets.token_hex: importing secrets loads hashlib and random as well)
            tmp_name = target.parent / f".{target.name}.{os.urandom(8).hex()}.tmp"
            try:
                fd = os.open(tmp_name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
                break
            except FileExistsError:  # someone else's file: never remove it, try another name
                tmp_name = None
            except OSError as error:  # (a missing or read-only directory: named as the caller gave it)
                tmp_name = None
                raise _cannot(path, "", error.strerror or str(error)) from None
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
