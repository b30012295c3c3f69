"""Parser fuzzing (robustness): any document is a Problem or a FunicularError, never a crash.

Three sources of documents: arbitrary TOML-able values (nested tables, lists, every scalar type,
non-finite and huge numbers), documents shaped like scenarios (known keys, random values), and
random mutations of the built-in scenarios (delete, retype, add, negate, huge, NaN, empty,
deeply nested). Each goes through ``parse_scenario``, and some through TOML text and the file
loader; small Problems are also solved (only crashes count there: the solver may refuse or fail).
A few invalid files go through the CLI: exit status 2, one line on stderr, no traceback.
"""

from __future__ import annotations

import contextlib
import copy
import datetime
import math
import subprocess
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import tomli_w
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument

from funicular import FunicularError, Problem, Solution, solve
from funicular.scenario import (
    CHAIN_KEYS,
    SUPPORT_KEYS,
    TOP_LEVEL_KEYS,
    builtin_scenarios,
    load_document,
    load_scenario,
    parse_scenario,
)

MAX_MESSAGE = 600  # characters: "one sentence", even when a value or key is huge
SOLVE_UP_TO = 400  # nodes: larger parsed problems are not solved (time)
OBSTACLE_KEYS = ("shape", "name", "point", "normal", "center", "radius", "semi_axes", "angle", "half_size")
OBSTACLE_KEYS += ("corner_radius", "f", "phi")
SHAPES = ("halfplane", "disk", "ellipse", "box", "graph", "expression")
BUILTINS = sorted(builtin_scenarios())


def examples(factor: float) -> int:
    return max(3, round(factor * settings().max_examples))


fuzz = settings(
    max_examples=examples(5),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)


# ----------------------------------------------------------------- the property
def _note(text: str) -> None:
    """hypothesis.note inside a hypothesis test, nothing elsewhere (the parametrized tests share the helpers)."""
    with contextlib.suppress(InvalidArgument):
        note(text)


def check_message(error: FunicularError) -> None:
    message = str(error)
    assert message.strip(), f"{type(error).__name__} without a message"
    assert "\n" not in message, f"a multi-line message: {message!r}"
    assert len(message) <= MAX_MESSAGE, f"a {len(message)}-character message: {message[:200]!r}..."


def parse_or_error(document: Any, source: str = "<fuzz>") -> Problem | None:
    """parse_scenario's answer: a Problem, or None after a well-formed FunicularError."""
    try:
        problem = parse_scenario(document, source)
    except FunicularError as error:
        _note(f"{type(error).__name__}: {error}")
        check_message(error)
        return None
    assert isinstance(problem, Problem)
    return problem


def solve_or_error(problem: Problem) -> Solution | None:
    """Small problems are solved too: a Solution (any status) or a FunicularError, never a crash."""
    if problem.n_nodes > SOLVE_UP_TO:
        return None
    try:
        solution = solve(problem, max_iterations=40)
    except FunicularError as error:
        check_message(error)
        return None
    assert isinstance(solution, Solution)
    solution.to_dict()  # the JSON document of any result can be built
    return solution


def check_document(document: Any) -> None:
    problem = parse_or_error(document)
    if problem is not None:
        solve_or_error(problem)


# ----------------------------------------------------------------- strategies
finite = st.floats(allow_nan=False, allow_infinity=False)
weird_numbers = st.sampled_from(
    [
        *(0, -0.0, 1, -1, 2, 0.5, 1e12, 10_000_001, 2**63, -(2**63) - 1, 2**64, 10**400),
        *(1e308, -1e308, 1.7976931348623157e308, 1e-300, 5e-324, math.nan, math.inf, -math.inf),
    ]
)
scalars = st.one_of(
    st.booleans(),
    st.integers(),
    st.floats(),
    weird_numbers,
    st.text(max_size=20),
    st.sampled_from(["norm", "squared", "nodes", "links", *SHAPES, "x", "-y", "x**2 + y**2 - 1", ""]),
    st.datetimes(),
    st.dates(),
    st.times(),
)
keys = st.one_of(
    st.sampled_from(sorted(TOP_LEVEL_KEYS | CHAIN_KEYS | SUPPORT_KEYS | set(OBSTACLE_KEYS))), st.text(max_size=12)
)
toml_values = st.recursive(
    scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=5),
        st.dictionaries(keys, children, max_size=5),
    ),
    max_leaves=30,
)
documents = st.dictionaries(keys, toml_values, max_size=8)


def _pair(value: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    return st.one_of(st.lists(value, min_size=2, max_size=2), st.lists(value, max_size=4), value)


numbers = st.one_of(finite, st.integers(-5, 200), weird_numbers)
plausible = st.one_of(numbers, numbers, toml_values)


@st.composite
def obstacle_tables(draw: st.DrawFn) -> dict[str, Any]:
    table: dict[str, Any] = {"shape": draw(st.one_of(st.sampled_from(SHAPES), scalars))}
    for key in draw(st.lists(st.sampled_from(OBSTACLE_KEYS[1:]), max_size=5, unique=True)):
        if key in ("point", "normal", "center", "semi_axes", "half_size"):
            table[key] = draw(_pair(numbers))
        elif key in ("f", "phi"):
            table[key] = draw(expressions)
        elif key == "name":
            table[key] = draw(st.one_of(st.text(max_size=10), scalars))
        else:
            table[key] = draw(plausible)
    return table


# Short expressions from the tokens the obstacle parser sees, plus some it must refuse.
TOKENS = ["x", "y", "1", "0", "2.5", "1e308", "-", "+", "*", "/", "**", "^", "(", ")", ",", "sin", "exp", "log"]
TOKENS += ["sqrt", "atan2", "Abs", "pi", "E", " ", "__import__", "[", "]", ".", "'", ";", "lambda", "I", "oo", "\n"]
expressions = st.one_of(
    st.lists(st.sampled_from(TOKENS), max_size=8).map("".join),
    st.sampled_from(["x**2 + y**2 - 1", "-0.6 + 0.25*exp(-40*(x-0.5)**2)", "log(x)", "1/x", "sqrt(x)", "0"]),
    st.text(max_size=10),
)


@st.composite
def scenario_like(draw: st.DrawFn) -> dict[str, Any]:
    """Known keys with plausible or random values: reaches the value checks behind the type checks."""
    document: dict[str, Any] = {}
    chain: dict[str, Any] = {}
    for key in draw(st.lists(st.sampled_from(sorted(CHAIN_KEYS)), max_size=4, unique=True)):
        if key == "nodes":
            chain[key] = draw(st.one_of(st.integers(-3, 300), plausible))
        elif key in ("masses", "link_lengths"):
            chain[key] = draw(st.one_of(numbers, st.lists(numbers, max_size=12), plausible))
        else:
            chain[key] = draw(plausible)
    document["chain"] = chain if draw(st.integers(0, 9)) else draw(toml_values)
    supports = []
    for _ in range(draw(st.integers(0, 4))):
        support: dict[str, Any] = {}
        if draw(st.integers(0, 9)):
            support["node"] = draw(st.one_of(st.integers(-12, 12), plausible))
        if draw(st.integers(0, 9)):
            support["position"] = draw(_pair(numbers))
        if not draw(st.integers(0, 9)):
            support[draw(keys)] = draw(plausible)
        supports.append(support)
    if draw(st.integers(0, 9)):
        document["supports"] = supports
    if draw(st.booleans()):
        document["obstacles"] = draw(st.lists(obstacle_tables(), max_size=3))
    for key in draw(st.lists(st.sampled_from(["name", "description", "formulation", "gravity", "contact"]))):
        document[key] = draw(plausible)
    return document


# ----------------------------------------------------------------- mutations of the built-ins
Path_ = tuple[Any, ...]


def _paths(value: Any, prefix: Path_ = ()) -> list[Path_]:
    """Every path to a value inside a document (dict keys and list indices)."""
    found = [prefix] if prefix else []
    if isinstance(value, dict):
        for key, item in value.items():
            found += _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            found += _paths(item, (*prefix, index))
    return found


def _parent(document: Any, path: Path_) -> Any:
    for step in path[:-1]:
        document = document[step]
    return document


def _deep(depth: int, leaf: Any, as_list: bool) -> Any:
    for _ in range(depth):
        leaf = [leaf] if as_list else {"chain": leaf}
    return leaf


def _negated(value: Any) -> Any:
    if isinstance(value, bool):
        return not value
    if isinstance(value, (int, float)):
        return -value
    if isinstance(value, list):
        return [_negated(item) for item in value]
    if isinstance(value, dict):
        return {key: _negated(item) for key, item in value.items()}
    return value


MUTATIONS = ("delete", "retype", "add", "negate", "huge", "nonfinite", "empty", "deep", "duplicate")


@st.composite
def mutated_builtins(draw: st.DrawFn) -> dict[str, Any]:
    name = draw(st.sampled_from(BUILTINS))
    document = copy.deepcopy(load_document(name).document)
    note(f"built-in {name!r}")
    for _ in range(draw(st.integers(1, 4))):
        paths = _paths(document)
        mutation = draw(st.sampled_from(MUTATIONS))
        if not paths:
            document[draw(keys)] = draw(toml_values)
            continue
        path = draw(st.sampled_from(paths))
        parent, last = _parent(document, path), path[-1]
        note(f"{mutation} at {path!r}")
        if mutation == "delete":
            del parent[last]
        elif mutation == "retype":
            parent[last] = draw(toml_values)
        elif mutation == "add":
            target = parent[last] if isinstance(parent[last], (dict, list)) else parent
            if isinstance(target, dict):
                target[draw(keys)] = draw(plausible)
            else:
                target.append(draw(plausible))
        elif mutation == "negate":
            parent[last] = _negated(parent[last])
        elif mutation == "huge":
            parent[last] = draw(st.sampled_from([1e308, -1e308, 10**400, 2**64, 10_000_001, 1e-320]))
        elif mutation == "nonfinite":
            parent[last] = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
        elif mutation == "empty":
            parent[last] = draw(st.sampled_from([[], {}, ""]))
        elif mutation == "deep":
            parent[last] = _deep(draw(st.integers(10, 120)), parent[last], draw(st.booleans()))
        elif mutation == "duplicate" and isinstance(parent, list):
            parent.append(copy.deepcopy(parent[last]))
    return document


# ----------------------------------------------------------------- tests
@fuzz
@given(documents)
def test_random_documents_are_problems_or_package_errors(document: dict[str, Any]) -> None:
    check_document(document)


@fuzz
@given(scenario_like())
def test_scenario_shaped_documents_are_problems_or_package_errors(document: dict[str, Any]) -> None:
    check_document(document)


@settings(
    max_examples=examples(10),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)
@given(mutated_builtins())
def test_mutated_builtins_are_problems_or_package_errors(document: dict[str, Any]) -> None:
    check_document(document)


def _toml_text(document: dict[str, Any]) -> str | None:
    """The document as TOML text, if tomli_w can write it (it refuses e.g. mixed-type tables in arrays)."""
    try:
        return tomli_w.dumps(document)
    except (TypeError, ValueError, RecursionError):
        return None


@fuzz
@given(st.one_of(mutated_builtins(), scenario_like(), documents))
def test_documents_through_toml_files(tmp_path_factory: pytest.TempPathFactory, document: dict[str, Any]) -> None:
    """The same documents written as TOML and read back by load_scenario (the CLI's path)."""
    text = _toml_text(document)
    assume(text is not None)
    assert text is not None
    path = tmp_path_factory.mktemp("fuzz") / "scenario.toml"
    path.write_text(text, encoding="utf-8")
    try:
        problem = load_scenario(path)
    except FunicularError as error:
        check_message(error)
        return
    assert isinstance(problem, Problem)
    # What the loader built equals what the parser builds from the parsed text.
    again = parse_scenario(tomllib.loads(text), str(path))
    assert again.n_nodes == problem.n_nodes


@fuzz
@given(st.binary(max_size=200) | st.text(max_size=200).map(lambda text: text.encode("utf-8")))
def test_arbitrary_bytes_are_refused_cleanly(tmp_path_factory: pytest.TempPathFactory, data: bytes) -> None:
    path = tmp_path_factory.mktemp("fuzz") / "bytes.toml"
    path.write_bytes(data)
    try:
        load_scenario(path)
    except FunicularError as error:
        check_message(error)


# ----------------------------------------------------------------- specific hostile inputs
def _terrain(f: str) -> dict[str, Any]:
    document = copy.deepcopy(load_document("terrain").document)
    document["obstacles"][0]["f"] = f
    return document


HOSTILE: dict[str, Callable[[], Any]] = {
    "nested tables 500 deep": lambda: {"chain": _deep(500, {}, as_list=False)},
    "nested lists 500 deep": lambda: {"chain": {"nodes": 3, "masses": _deep(500, 1.0, as_list=True)}},
    "a 10,000-character key": lambda: {"k" * 10_000: 1},
    "a 10,000-character value": lambda: {"name": "n" * 10_000, "chain": {"nodes": "x" * 10_000}},
    "masses of 1e308 overflow": lambda: {
        "chain": {"nodes": 3, "length": 1.0, "masses": [1e308, 1e308, 1e308]},
        "supports": [{"node": 0, "position": [0, 0]}],
    },
    "a link length of 1e308": lambda: {
        "chain": {"nodes": 3, "link_lengths": [1e308, 1e308], "mass": 1.0},
        "supports": [{"node": 0, "position": [0, 0]}, {"node": 2, "position": [1e308, 0]}],
    },
    "a subnormal link length": lambda: {
        "chain": {"nodes": 3, "link_length": 5e-324, "mass": 1.0},
        "supports": [{"node": 0, "position": [0, 0]}],
    },
    "an integer beyond float range": lambda: {"chain": {"nodes": 3, "length": 10**400, "mass": 1.0}},
    "a datetime for a number": lambda: {"gravity": datetime.datetime(2020, 1, 1)},
    "a node index of 2**64": lambda: {
        "chain": {"nodes": 3, "length": 1.0, "mass": 1.0},
        "supports": [{"node": 2**64, "position": [0, 0]}],
    },
    "an expression that recurses": lambda: _terrain("x" + "+x" * 5000),
    "too many nodes": lambda: {"chain": {"nodes": 10**11, "length": 1.0, "mass": 1.0}},
    "a key with a newline": lambda: {"chain\nnodes": 1},
    "an unknown shape": lambda: {
        "chain": {"nodes": 3, "length": 1.0, "mass": 1.0},
        "supports": [{"node": 0, "position": [0.0, 0.0]}],
        "obstacles": [{"shape": "triangle"}],
    },
}


@pytest.mark.parametrize("make", HOSTILE.values(), ids=HOSTILE.keys())
def test_hostile_documents(make: Callable[[], Any]) -> None:
    check_document(make())


def _run_cli(args: list[str], timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "funicular.cli", *args], capture_output=True, text=True, timeout=timeout, check=False
    )


def test_exponent_towers_in_expressions_do_not_hang_the_parser(tmp_path: Path) -> None:
    """`f = "9**9**9"` makes sympy compute a 370-million-digit integer while parsing (minutes, GBs).
    A scenario file must not be able to do that: the parser should refuse it (or evaluate it as a
    float, 9**9**9 = inf -> not finite) within a moment."""
    path = tmp_path / "tower.toml"
    path.write_text(tomli_w.dumps(_terrain("9**9**9")), encoding="utf-8")
    try:
        result = _run_cli(["solve", str(path)], timeout=20.0)
    except subprocess.TimeoutExpired:
        pytest.fail("parsing f = '9**9**9' took more than 20 s")
    assert result.returncode == 2, result


# ----------------------------------------------------------------- through the CLI
CLI_DOCUMENTS: dict[str, bytes] = {
    "invalid TOML": b"[chain\nnodes = 3\n",
    "not UTF-8": b'name = "\xff\xfe"\n',
    "NaN mass": tomli_w.dumps(
        {"chain": {"nodes": 3, "length": 1.0, "mass": math.nan}, "supports": [{"node": 0, "position": [0.0, 0.0]}]}
    ).encode(),
    "deeply nested": tomli_w.dumps({"chain": _deep(200, {"x": 1}, as_list=False)}).encode(),
    "expression with a dunder": tomli_w.dumps(_terrain("__import__('os')")).encode(),
}


@pytest.mark.parametrize("content", CLI_DOCUMENTS.values(), ids=CLI_DOCUMENTS.keys())
def test_cli_reports_bad_scenarios_in_one_line(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "bad.toml"
    path.write_bytes(content)
    result = _run_cli(["solve", str(path), "--json", str(tmp_path / "out.json")])
    assert result.returncode == 2, result
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("funicular: error: ")
    assert result.stdout == ""
    assert not (tmp_path / "out.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


@settings(max_examples=2, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_builtins())
def test_cli_on_mutated_builtins(tmp_path_factory: pytest.TempPathFactory, document: dict[str, Any]) -> None:
    """A mutated built-in through the CLI: 0 or 1 with a summary, or 2 with one line on stderr."""
    text = _toml_text(document)
    assume(text is not None)
    assert text is not None
    problem = parse_or_error(document)
    assume(problem is None or problem.n_nodes <= 2000)  # keep the subprocess short
    folder = tmp_path_factory.mktemp("cli")
    path = folder / "mutated.toml"
    path.write_text(text, encoding="utf-8")
    result = _run_cli(["solve", str(path)])
    assert "Traceback" not in result.stderr
    if result.returncode == 2:
        assert len(result.stderr.splitlines()) == 1, result.stderr
    else:
        assert result.returncode in (0, 1), result
        assert result.stdout
