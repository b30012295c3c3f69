"""Every install hint is a command that works: the messages' ``pip install`` commands name what
pyproject.toml lists for the extra, and every ``pip install`` in the README and the docs installs a
wheel, the clone, or requirements that pyproject.toml lists (no ``funicular[extra]``: the package is
installed from a clone or a wheel, not from a package index)."""

from __future__ import annotations

import importlib.metadata
import re
import shlex
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

import funicular._extras as extras
import funicular.cli.compare as compare_cli
from funicular import backends
from funicular._extras import InstallHint, install_command, requirements
from funicular.cli import main

ROOT = Path(__file__).resolve().parent.parent
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
EXTRAS: dict[str, list[str]] = PROJECT["optional-dependencies"]
# every requirement pyproject.toml lists, each written exactly as there
LISTED = set(PROJECT["dependencies"]).union(*EXTRAS.values())
USER_EXTRAS = ("plot", "parquet", "serve", "expr", "progress", "cluster", "ipopt")  # the README's list
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^\s*(`{3,}|~{3,})")
CODE_SPAN = re.compile(r"`([^`]+)`")
WHEEL = re.compile(r"dist/funicular-[^/\s]*\.whl")


@pytest.fixture(autouse=True)
def fresh_requirements() -> Iterator[None]:
    """The requirements are cached per process: each test reads them anew."""
    requirements.cache_clear()
    yield
    requirements.cache_clear()


def no_metadata(name: str) -> list[str]:
    raise importlib.metadata.PackageNotFoundError(name)


@pytest.mark.parametrize("extra", sorted(EXTRAS))
def test_each_extra_hint_installs_what_pyproject_lists(extra: str) -> None:
    assert shlex.split(install_command(extra)) == ["pip", "install", *EXTRAS[extra]]


def test_the_readme_extras_are_pyproject_extras() -> None:
    assert set(USER_EXTRAS) <= set(EXTRAS)


def test_a_checkout_that_is_not_installed_reads_pyproject(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(importlib.metadata, "requires", no_metadata)
    for extra in USER_EXTRAS:
        assert shlex.split(install_command(extra)) == ["pip", "install", *EXTRAS[extra]]


def test_without_metadata_or_pyproject_the_hint_names_the_extra(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(importlib.metadata, "requires", no_metadata)
    monkeypatch.setattr(extras, "_PYPROJECT", tmp_path / "pyproject.toml")
    hint = install_command("parquet")
    assert "parquet extra" in hint and not hint.startswith("pip install")


def test_metadata_markers_in_either_quoting_and_any_spelling_of_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    listed = [
        "numpy>=1.26",  # a dependency of every install, not of an extra
        "pyarrow>=15 ; extra == 'parquet'",
        'fastparquet>=2024; extra == "Parquet"',
        "polars ; python_version >= '3.12' and extra == 'parquet'",
        "rich>=13 ; extra == 'progress'",
    ]
    monkeypatch.setattr(importlib.metadata, "requires", lambda name: listed)
    assert requirements("parquet") == ("pyarrow>=15", "fastparquet>=2024", "polars")
    assert install_command("parquet") == "pip install 'pyarrow>=15' 'fastparquet>=2024' polars"


def test_a_hint_constant_reads_the_metadata_only_when_shown(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[str] = []

    def requires(name: str) -> list[str]:
        calls.append(name)
        return ["pyarrow>=15 ; extra == 'parquet'"]

    monkeypatch.setattr(importlib.metadata, "requires", requires)
    hint = InstallHint("parquet")
    assert calls == []
    assert f"install it with {hint}." == "install it with pip install 'pyarrow>=15'."
    assert calls == ["funicular"]


def test_compare_without_casadi_says_what_to_install(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(backends, "available", lambda: ["funicular", "slsqp"])
    monkeypatch.setattr(compare_cli, "available", lambda: ["funicular", "slsqp"])
    assert main(["compare", "two-supports"]) == 0
    assert f"not installed: ipopt ({install_command('ipopt')})" in capsys.readouterr().out


def test_nothing_names_a_funicular_extra_to_install_from_an_index() -> None:
    files = [*PAGES, *(ROOT / "src" / "funicular").rglob("*.py")]
    offending = [str(p.relative_to(ROOT)) for p in files if "funicular[" in p.read_text(encoding="utf-8")]
    assert not offending, f"these files name funicular[...], which no package index serves: {offending}"


def pip_commands(page: Path) -> list[tuple[str, str]]:
    """Each ``pip install`` command of a page, with where it is: a line of a fenced block, or an
    inline code span. One anywhere else (in prose, where a reader cannot copy it whole) fails."""
    found = []
    inside = False
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), start=1):
        if FENCE.match(line):
            inside = not inside
            continue
        where = f"{page.relative_to(ROOT)}:{number}"
        spans = [span for span in ([line] if inside else CODE_SPAN.findall(line)) if "pip install" in span]
        assert sum(span.count("pip install") for span in spans) == line.count("pip install"), (
            f"{where}: a pip install outside code"
        )
        found += [(where, span[span.index("pip install") :]) for span in spans]
    return found


def installs_something_that_exists(command: str) -> bool:
    words = shlex.split(command, comments=True)
    assert words[:2] == ["pip", "install"], command
    arguments = words[2:]
    if arguments == ["-e", "."] or (len(arguments) == 1 and WHEEL.fullmatch(arguments[0])):
        return True
    return bool(arguments) and all(arg in LISTED and not arg.startswith("funicular") for arg in arguments)


def test_every_pip_install_in_the_docs_installs_something_that_exists() -> None:
    commands = [found for page in PAGES for found in pip_commands(page)]
    assert len(commands) >= len(USER_EXTRAS) + 1  # the README alone has the wheel and every extra
    wrong = [f"{where}: {command}" for where, command in commands if not installs_something_that_exists(command)]
    assert not wrong, "these commands install nothing that pyproject.toml lists:\n" + "\n".join(wrong)


def test_the_readme_installs_the_wheel_and_every_extra() -> None:
    commands = [shlex.split(command, comments=True)[2:] for _, command in pip_commands(ROOT / "README.md")]
    assert any(len(arguments) == 1 and WHEEL.fullmatch(arguments[0]) for arguments in commands)
    for extra in USER_EXTRAS:
        assert EXTRAS[extra] in commands, f"the README has no pip install for the {extra} extra"
