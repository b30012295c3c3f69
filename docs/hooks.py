"""mkdocs hook: the command line reference, written at build time from the installed program.

Every page may hold the marker ``<!-- funicular-help -->``; the hook replaces it with the output
of ``funicular --help`` and of ``funicular COMMAND --help`` for every command (and every
subcommand of a command that has them, such as ``study refine``). The commands are discovered
from the help text itself, so the reference follows the program as it is installed: nothing
here lists them.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

MARKER = "<!-- funicular-help -->"
WIDTH = "100"  # argparse wraps at $COLUMNS


def program() -> list[str]:
    """The ``funicular`` program of the Python that runs mkdocs (the project's .venv), else PATH's."""
    beside = Path(sys.executable).with_name("funicular")
    if beside.is_file():
        return [str(beside)]
    found = shutil.which("funicular")
    if found is None:
        raise RuntimeError("the funicular program is not installed; run `make docs`, which installs it.")
    return [found]


def run_help(words: list[str]) -> str:
    """``funicular WORDS --help``, as a user's terminal would show it (COLUMNS fixed, no colour)."""
    env = {**os.environ, "COLUMNS": WIDTH, "NO_COLOR": "1", "PYTHON_COLORS": "0"}
    result = subprocess.run(
        [*program(), *words, "--help"], capture_output=True, text=True, env=env, timeout=120, check=False
    )
    if result.returncode != 0:
        raise RuntimeError(f"`funicular {' '.join(words)} --help` exited with {result.returncode}: {result.stderr}")
    return result.stdout.rstrip()


def subcommands(help_text: str, words: list[str]) -> list[str]:
    """The commands a help text offers: argparse lists them as ``{a,b,c}`` in the usage line or,
    with a metavar, one per line indented under the positional argument. Each candidate is kept
    only if ``funicular WORDS CANDIDATE --help`` answers with its own usage line."""
    candidates: list[str] = []
    usage = help_text.split("\n\n", 1)[0]
    for group in re.findall(r"\{([a-z][\w,-]*)\}", usage):
        candidates += group.split(",")
    section = re.search(r"^(?:positional arguments|commands):\n(.*?)(?:\n\n|\Z)", help_text, re.M | re.S)
    if section:
        lines = section.group(1).splitlines()
        indents = [len(line) - len(line.lstrip()) for line in lines if line.strip()]
        base = min(indents, default=0)
        for line in lines:
            indent = len(line) - len(line.lstrip())
            word = line.split()[0] if line.strip() else ""
            if indent > base and re.fullmatch(r"[a-z][\w-]*", word) and indent <= base + 4:
                candidates.append(word)
    found: list[str] = []
    for word in dict.fromkeys(candidates):
        try:
            text = run_help([*words, word])
        except RuntimeError:
            continue
        if text.startswith(f"usage: funicular {' '.join([*words, word])}"):
            found.append(word)
    return found


def reference() -> str:
    """Markdown: one section per command, each with its help text."""
    parts: list[str] = []

    def visit(words: list[str], level: int) -> None:
        text = run_help(words)
        title = " ".join(["funicular", *words])
        parts.append(f"{'#' * level} `{title}`\n\n```text\n$ {title} --help\n{text}\n```\n")
        for word in subcommands(text, words):
            visit([*words, word], level + 1 if words else 3)

    visit([], 2)
    return "\n".join(parts)


def on_page_markdown(markdown: str, **kwargs: object) -> str:
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, reference())
