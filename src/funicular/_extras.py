"""How to install an optional extra's packages: the ``pip install`` command every message gives.

The requirements come from the installed distribution's metadata (``Requires-Dist: pyarrow>=15 ;
extra == 'parquet'``), so a message names the packages and versions that pyproject.toml lists, in
a command that works wherever funicular was installed from (a clone, a wheel): ``pip install
'pyarrow>=15'``. Reading the metadata costs a few milliseconds, so it happens only when a message
is shown.
"""

from __future__ import annotations

import functools
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

DISTRIBUTION = "funicular"
_EXTRA_MARKER = re.compile(r"""\bextra\s*==\s*["']([^"']+)["']""")
_PYPROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"  # a source checkout run without installing


def _normalized(extra: str) -> str:
    """Extra names compare as PEP 685 has it: case and runs of ``-_.`` do not matter."""
    return re.sub(r"[-_.]+", "-", extra).lower()


def _from_metadata(extra: str) -> tuple[str, ...]:
    from importlib import metadata  # (only when a message is shown: its import alone takes milliseconds)

    try:
        listed = metadata.requires(DISTRIBUTION) or []
    except metadata.PackageNotFoundError:
        return ()
    found = []
    for line in listed:
        requirement, _, marker = line.partition(";")
        match = _EXTRA_MARKER.search(marker)
        if match and _normalized(match[1]) == _normalized(extra):
            found.append(requirement.strip())
    return tuple(found)


def _from_pyproject(extra: str) -> tuple[str, ...]:
    import tomllib

    try:
        project = tomllib.loads(_PYPROJECT.read_text(encoding="utf-8")).get("project", {})
    except (OSError, tomllib.TOMLDecodeError):
        return ()
    if project.get("name") != DISTRIBUTION:
        return ()
    extras = {_normalized(name): found for name, found in project.get("optional-dependencies", {}).items()}
    return tuple(extras.get(_normalized(extra), ()))


@functools.cache
def requirements(extra: str) -> tuple[str, ...]:
    """The requirements of one of funicular's extras, as pyproject.toml lists them (``'pyarrow>=15'``)."""
    return _from_metadata(extra) or _from_pyproject(extra)


def install_command(extra: str) -> str:
    """The shell command that installs an extra's packages: ``pip install 'pyarrow>=15'``."""
    found = requirements(extra)
    if not found:  # neither installed nor in a checkout: name the extra at least
        return f"install the packages of funicular's {extra} extra (pyproject.toml lists them)"
    return "pip install " + " ".join(shlex.quote(requirement) for requirement in found)


@dataclass(frozen=True)
class InstallHint:
    """``install_command(extra)`` for a module constant: formatted into a message (``f"{HINT}"``) it
    reads the metadata then, not when the module is imported."""

    extra: str

    def __str__(self) -> str:
        return install_command(self.extra)
