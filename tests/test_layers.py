"""The package's layers: no import cycles among its modules, and no domain module imports the
command line. Module-level imports only (a function-local import is a lazy load on purpose)."""

from __future__ import annotations

import ast
from pathlib import Path

import funicular

PACKAGE = Path(funicular.__file__).parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _module_level_imports(path: Path, name: str, known: set[str]) -> set[str]:
    """The package's modules ``name`` imports at module level (``if TYPE_CHECKING:`` blocks excluded)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    body = ast.parse(path.read_text(encoding="utf-8")).body
    for node in body:
        if isinstance(node, ast.If):  # only `if TYPE_CHECKING:` appears at module level here
            continue
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the package, up level - 1 packages
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base)
    return {module for module in found if module in known and module != name}


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    known = set(modules)
    return {name: _module_level_imports(path, name, known) for name, path in modules.items()}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle, as the list of modules around it, or None (depth-first search)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = 1
        path.append(module)
        for imported in sorted(graph[module]):
            if state.get(imported) == 1:
                return [*path[path.index(imported) :], imported]
            if imported not in state and (found := visit(imported)):
                return found
        path.pop()
        state[module] = 2
        return None

    for module in sorted(graph):
        if module not in state and (found := visit(module)):
            return found
    return None


def test_the_graph_sees_the_imports_of_the_command_line() -> None:
    graph = _graph()
    assert "funicular.cli._common" in graph["funicular.cli.solve"]
    assert "funicular.model" in graph["funicular.scenario"]


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_no_module_imports_itself_back() -> None:
    assert _cycle(_graph()) is None


def test_only_the_command_line_imports_the_command_line() -> None:
    offenders = {
        module: sorted(m for m in imported if m.startswith("funicular.cli"))
        for module, imported in _graph().items()
        if not module.startswith("funicular.cli") and module != "funicular.__main__"  # (`python -m funicular`)
    }
    assert {module: found for module, found in offenders.items() if found} == {}
