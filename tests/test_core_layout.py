"""The solver core's layout keeps its design visible (``rust/core/src``): its modules use one another
in layers, without a cycle; the iteration, the polish and the second-order test never ask what kind
of network they run on (a policy and the linear algebra's types say it); no function is longer than
a screenful. Read from the sources, with a brace counter that skips comments and strings."""

from __future__ import annotations

import re
from pathlib import Path

SOURCES = Path(__file__).resolve().parents[1] / "rust" / "core" / "src"
LONGEST = 100  # lines, from a function's `fn` to its closing brace
FUNCTION = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(unsafe\s+)?fn\s+(\w+)")


def _code(line: str) -> str:
    """A line without its comment, character literals and strings (for counting braces)."""
    line = re.sub(r"'(\\.|[^'\\])'", "", line)
    line = re.sub(r'"(\\.|[^"\\])*"', '""', line)
    return line.split("//")[0]


def _functions(path: Path) -> list[tuple[str, int, int]]:
    """Every function of a file with a body: name, first line, length in lines."""
    lines = path.read_text(encoding="utf-8").splitlines()
    found = []
    for start, line in enumerate(lines):
        match = FUNCTION.match(line)
        if not match:
            continue
        depth, opened = 0, False
        for end in range(start, len(lines)):
            code = _code(lines[end])
            if not opened and ";" in code and "{" not in code:
                break  # a declaration in a trait
            depth += code.count("{") - code.count("}")
            opened |= "{" in code
            if opened and depth <= 0:
                found.append((match.group(5), start + 1, end - start + 1))
                break
    return found


def _module_graph() -> dict[str, set[str]]:
    """Each top-level module (a directory is one) and the crate's modules it names."""
    graph: dict[str, set[str]] = {}
    for path in sorted(SOURCES.rglob("*.rs")):
        module = path.relative_to(SOURCES).parts[0].removesuffix(".rs")
        if module in ("lib", "test_support"):
            continue
        code = "\n".join(_code(line) for line in path.read_text(encoding="utf-8").splitlines())
        named = set(re.findall(r"crate::(\w+)", code))
        for group in re.findall(r"crate::\{([^}]*)\}", code):
            named |= {item.strip().split("::")[0] for item in group.split(",") if item.strip()}
        graph.setdefault(module, set()).update(named - {module, "test_support"})
    return graph


def test_the_core_is_read_whole() -> None:
    graph = _module_graph()
    assert {"problem", "driver", "chain", "net", "ipm", "polish", "policy", "linalg"} <= set(graph)
    assert sum(len(_functions(path)) for path in SOURCES.rglob("*.rs")) > 300


def test_no_module_cycle() -> None:
    graph = _module_graph()
    done: set[str] = set()

    def visit(module: str, path: list[str]) -> None:
        for used in sorted(graph.get(module, ())):
            assert used not in path, " -> ".join([*path, used])
            if used not in done:
                visit(used, [*path, used])
        done.add(module)

    for module in sorted(graph):
        visit(module, [module])
    assert graph["linalg"] == set()  # (the linear algebra knows no problem)


def test_the_iteration_does_not_ask_what_it_runs_on() -> None:
    for path in [SOURCES / "ipm.rs", SOURCES / "curvature.rs", *sorted((SOURCES / "polish").glob("*.rs"))]:
        code = "\n".join(_code(line) for line in path.read_text(encoding="utf-8").splitlines())
        assert not re.search(r"\.path\b", code), path.name


def test_no_function_in_the_core_is_over_a_hundred_lines() -> None:
    long = [
        f"{path.relative_to(SOURCES)}:{line} {name} ({length} lines)"
        for path in sorted(SOURCES.rglob("*.rs"))
        for name, line, length in _functions(path)
        if length > LONGEST
    ]
    assert not long, long
