"""The documentation runs as shown: README.md and every page under docs/.

Conventions the pages follow (docs/development.md states them for writers):

* every fenced ``python`` block runs; a page's blocks run in order in one namespace, in a fresh
  temporary working directory;
* a fenced block with ``title="NAME"`` (a ``toml`` scenario, say) is written to the file NAME in
  that directory when the page reaches it, so later blocks and commands can use it;
* in any other fenced block, a line ``$ funicular ...`` is a command: it runs through the
  installed program and must exit with status 0. The lines after it, up to the next ``$`` line or
  the end of the block, are the output shown: each must match a line of the real output, in
  order (the output may have more lines; a line ``...`` marks an omission and ``...`` inside a
  line matches anything). Numbers match to the digits printed: a value shown as 0.3333333333 must
  be within 5e-11 of the real one. Residual-sized numbers (below 1e-8 in size) match any
  residual-sized number, and a number followed by ``s`` (a time in seconds) matches any number.
* ``$`` lines are only for funicular commands; ``make`` targets and the like are shown without
  ``$`` (in ``sh`` blocks) and are not run here.
"""

from __future__ import annotations

import math
import os
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

import funicular

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
GENERATED = {  # written by bench/
    "benchmark.md",
    "benchmark-1e6.md",
    "profile-1e6.md",
    "explorer-latency.md",
    "results-files-benchmark.md",
    "benchmark-chain-3d.md",
    "benchmark-elastic.md",
}
PAGES = [ROOT / "README.md", *sorted(p for p in DOCS.glob("*.md") if p.name not in GENERATED)]
RESIDUAL = 1e-8

FENCE = re.compile(r"^(?P<indent>\s*)(?P<fence>`{3,})(?P<lang>[\w+-]*)(?P<info>.*)$")
NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
NUMBER_TOKEN = re.compile(rf"(?<![\w.]){NUMBER}(?![\w])")


@dataclass(frozen=True)
class Block:
    lang: str
    info: str
    text: str
    line: int  # of the opening fence, 1-based


def blocks(path: Path) -> list[Block]:
    """The fenced code blocks of a Markdown file, in order."""
    found: list[Block] = []
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if not opening:
            i += 1
            continue
        indent, fence = opening["indent"], opening["fence"]
        body: list[str] = []
        j = i + 1
        while j < len(lines) and not (
            lines[j].strip().startswith(fence)
            and lines[j].strip().strip("`") == ""
            and len(lines[j].strip()) >= len(fence)
        ):
            body.append(lines[j][len(indent) :] if lines[j].startswith(indent) else lines[j].lstrip())
            j += 1
        assert j < len(lines), f"{path.name}:{i + 1}: code block never closed"
        found.append(Block(opening["lang"], opening["info"].strip(), "\n".join(body) + "\n", i + 1))
        i = j + 1
    return found


def program() -> str:
    """The installed funicular program of the Python that runs the tests."""
    beside = Path(sys.executable).with_name("funicular")
    return str(beside) if beside.is_file() else "funicular"


# ----------------------------------------------------------------- matching shown output
def _pattern(shown: str) -> tuple[re.Pattern[str], list[str | None]]:
    """A regex for a shown output line, and per captured number its text (None: any number)."""
    parts: list[str] = []
    numbers: list[str | None] = []
    for piece in re.split(r"\s*(\.\.\.)\s*", shown.strip()):
        if piece == "...":
            parts.append(".*?")
            continue
        position = 0
        for match in NUMBER_TOKEN.finditer(piece):
            parts.append(_text(piece[position : match.start()]))
            parts.append(rf"({NUMBER}|-?inf|nan)")
            timing = re.match(r"\s*s\b", piece[match.end() :]) is not None
            numbers.append(None if timing else match.group())
            position = match.end()
        parts.append(_text(piece[position:]))
    return re.compile("".join(parts)), numbers


def _text(piece: str) -> str:
    """Literal text, any run of whitespace matching any run."""
    return "".join(r"\s+" if word.isspace() else re.escape(word) for word in re.split(r"(\s+)", piece) if word)


def _same_number(shown: str, real: str) -> bool:
    expected, actual = float(shown), float(real)
    if abs(expected) < RESIDUAL and abs(actual) < RESIDUAL:
        return True
    mantissa, _, exponent = shown.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    unit = 10.0 ** (int(exponent or 0) - decimals)
    return math.isfinite(actual) and abs(actual - expected) <= 0.5 * unit * (1 + 1e-9) + 1e-15 * abs(expected)


def matches(shown: str, real: str) -> bool:
    pattern, numbers = _pattern(shown)
    found = pattern.fullmatch(real.strip())
    if not found:
        return False
    return all(want is None or _same_number(want, got) for want, got in zip(numbers, found.groups(), strict=True))


def check_output(shown: list[str], real: str, where: str) -> None:
    real_lines = real.splitlines()
    position = 0
    for line in shown:
        if line.strip() in ("", "..."):
            continue
        for k in range(position, len(real_lines)):
            if matches(line, real_lines[k]):
                position = k + 1
                break
        else:
            pytest.fail(
                f"{where}: the output shown\n    {line}\nis not in the real output (after line {position}):\n{real}"
            )


def test_matching_rules() -> None:
    assert matches("energy  -0.2967089491   (g m^T y)", "energy            -0.2967089491   (g m^T y)")
    assert not matches("energy  -0.2967089491", "energy  -0.2967089481")
    assert matches(
        "max tension  0.95 in link ... (19 of 19 links taut)", "max tension 0.95 in link 7 (19 of 19 links taut)"
    )
    assert matches("stationarity 3.80e-15, primal 0", "stationarity 2.05e-15, primal 7.1e-17")
    assert not matches("stationarity 3.80e-15", "stationarity 2.05e-6")
    assert matches("iterations 1 in 0.000696 s", "iterations 1 in 0.00101 s")
    assert not matches("iterations 1 in 0.000696 s", "iterations 2 in 0.000696 s")
    assert matches("Fx = 0   Fy =  1", "Fx = -0   Fy =  1")
    assert matches("a 0.333333", "a 0.3333334") and not matches("a 0.333333", "a 0.3333345")


# ----------------------------------------------------------------- running the pages
def _run_command(command: str, cwd: Path, where: str) -> str:
    words = shlex.split(command)
    assert words[0] == "funicular", f"{where}: a '$' line must run funicular, not {words[0]!r} (show it without '$')"
    env = {**os.environ, "COLUMNS": "100", "MPLBACKEND": "Agg"}
    result = subprocess.run(
        [program(), *words[1:]], cwd=cwd, capture_output=True, text=True, env=env, timeout=300, check=False
    )
    assert result.returncode == 0, f"{where}: `{command}` exited with {result.returncode}:\n{result.stderr}"
    return result.stdout


def _commands(block: Block) -> list[tuple[str, list[str], int]]:
    """The ``$`` commands of a block, each with the output lines shown after it."""
    found: list[tuple[str, list[str], int]] = []
    for offset, line in enumerate(block.text.splitlines(), start=1):
        if line.startswith("$ "):
            found.append((line[2:].strip(), [], block.line + offset))
        elif found:
            found[-1][1].append(line)
    return found


def _title(block: Block) -> str | None:
    titled = re.search(r'title="([^"]+)"', block.info)
    return titled.group(1) if titled else None


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_page_runs_as_shown(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for block in blocks(page):
        where = f"{page.name}:{block.line}"
        title = _title(block)
        if title is not None:
            (tmp_path / title).write_text(block.text, encoding="utf-8")
        if block.lang == "python":
            exec(compile(block.text, where, "exec"), namespace)
            continue
        for command, shown, line in _commands(block):
            check_output(shown, _run_command(command, tmp_path, f"{page.name}:{line}"), f"{page.name}:{line}")


def test_pages_show_something_to_run() -> None:
    """The tutorial and the README keep their runnable examples (a parser slip would skip them)."""
    for name in ("README.md", "tutorial.md"):
        page = ROOT / name if name == "README.md" else DOCS / name
        found = blocks(page)
        assert any(b.lang == "python" for b in found), name
        assert any(_commands(b) for b in found), name


def test_inline_code_stays_on_one_line() -> None:
    """The site's Markdown ends an inline code span at a line break (GitHub does not): keep each
    span on one line, so both render it the same."""
    for page in PAGES:
        inside = False
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), start=1):
            if FENCE.match(line):
                inside = not inside
            elif not inside:
                assert line.count("`") % 2 == 0, f"{page.name}:{number}: an inline code span crosses the line break"


def test_readme_is_short() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 160, f"README.md has {len(lines)} lines; move detail into docs/"


def test_nothing_points_outside_the_repository() -> None:
    needles = [b"shared" + b"/design", b"../" + b"shared"]
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "mkdocs.yml"]
    for folder in ("docs", "src", "tests"):
        files += [
            p for p in (ROOT / folder).rglob("*") if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".so"
        ]
    offending = [str(p.relative_to(ROOT)) for p in files if any(needle in p.read_bytes() for needle in needles)]
    assert not offending, f"these files point outside the repository: {offending}"


def test_version_matches_the_changelog() -> None:
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    releases = re.findall(r"^## \[(\d+\.\d+\.\d+)\] - \d{4}-\d{2}-\d{2}$", changelog, re.M)
    assert releases, "CHANGELOG.md names no released version (## [X.Y.Z] - YYYY-MM-DD)"
    assert changelog.index("## [Unreleased]") < changelog.index(f"## [{releases[0]}]")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["version"] == releases[0] == funicular.__version__


def _slug(heading: str) -> str:
    """A heading's anchor on the site (Python-Markdown's toc): word characters, spaces and hyphens
    kept, lower case, runs of spaces and hyphens one hyphen."""
    kept = re.sub(r"[^\w\s-]", "", heading).strip().lower()
    return re.sub(r"[-\s]+", "-", kept)


def test_site_pages_link_only_to_pages_and_headings_the_site_has() -> None:
    """A page of the site links to pages the site builds (not the benchmark tables mkdocs.yml
    excludes, which only other pages include) and to headings those pages have."""
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    excluded = set(re.search(r"exclude_docs: \|\n((?:  .*\n)+)", config)[1].split())  # type: ignore[index]
    site = {p.name: p for p in DOCS.glob("*.md") if p.name not in excluded}
    assert "benchmark-nets.md" in site and "benchmark.md" in excluded
    broken = []
    for page in site.values():
        text = page.read_text(encoding="utf-8")
        for target, anchor in re.findall(r"\]\(([\w.-]+\.md)(?:#([\w-]+))?\)", text):
            if target not in site:
                broken.append(f"{page.name} -> {target}")
            elif anchor:
                headings = re.findall(r"^#+ (.+)$", site[target].read_text(encoding="utf-8"), re.M)
                if anchor not in {_slug(heading) for heading in headings}:
                    broken.append(f"{page.name} -> {target}#{anchor}")
    assert not broken, f"links to what the site does not have: {broken}"
