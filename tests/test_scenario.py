"""Scenario files: the built-ins, the schema's mapping onto Problem, and every validation rule."""

from __future__ import annotations

import copy
import datetime
import math
import re
import tomllib
from collections.abc import Callable
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from funicular.errors import ScenarioError
from funicular.model import DEFAULT_GRAVITY, Formulation, Problem
from funicular.scenario import DEFAULT_SCENARIO, builtin_scenarios, load_scenario, parse_scenario

BUILTINS = [
    "box-edge",
    "chain-around-post",
    "dangling",
    "disk-drape",
    "ground",
    "hanging-model",
    "mooring",
    "net-over-sphere",
    "peg-two-ways",
    "pretensioned-saddle",
    "seed-licq",
    "seed-licq-elastic",
    "slope",
    "squared-dangling",
    "taut",
    "taut-mooring",
    "terrain",
    "three-supports",
    "two-pegs",
    "two-supports",
    "uneven-supports",
    "vanderbei",
]


def raw_builtin(name: str) -> dict[str, Any]:
    return tomllib.loads((files("funicular") / "scenarios" / f"{name}.toml").read_text("utf-8"))


def doc(chain: dict[str, Any] | None = None, supports: Any = None, **top: Any) -> dict[str, Any]:
    """A valid two-support document with the given overrides."""
    document: dict[str, Any] = {
        "chain": {"nodes": 5, "length": 2.0, "mass": 1.0} if chain is None else chain,
        "supports": [{"node": 0, "position": [0.0, 0.0]}, {"node": -1, "position": [1.0, 0.0]}]
        if supports is None
        else supports,
    }
    document.update(top)
    return document


# ----------------------------------------------------------------- built-ins
def test_builtin_names_and_descriptions() -> None:
    scenarios = builtin_scenarios()
    assert list(scenarios) == BUILTINS
    assert DEFAULT_SCENARIO in scenarios
    for description in scenarios.values():
        assert description and "\n" not in description


# name: (nodes, total length, total mass, gravity, formulation, support nodes, support positions)
EXPECTED = {
    "dangling": (20, 1.5, 1.0, 1.0, "norm", [0], [[0, 0]]),
    "squared-dangling": (20, 1.5, 1.0, 1.0, "squared", [0], [[0, 0]]),
    "two-supports": (51, 1.5, 1.0, 1.0, "norm", [0, 50], [[0, 0], [1, 0]]),
    "uneven-supports": (51, 1.6, 1.0, 1.0, "norm", [0, 50], [[0, 0], [1, 0.5]]),
    "three-supports": (61, 3.0, 1.0, 1.0, "norm", [0, 30, 60], [[0, 0], [1, -0.2], [2, 0.3]]),
    "taut": (11, 1.0, 1.1, 1.0, "norm", [0, 10], [[0, 0], [0, -1]]),
    "vanderbei": (101, 2.0, 101.0, 1.0, "norm", [0, 100], [[0, 0], [1, 0]]),
    "seed-licq": (3, 1.0, 1.0, 1.0, "norm", [0, 2], [[0, 0], [0, -1]]),
}


@pytest.mark.parametrize("name", sorted(EXPECTED))  # obstacle built-ins: tests/test_obstacles.py
def test_builtin_loads_with_stated_numbers(name: str) -> None:
    nodes, length, mass, gravity, formulation, support_nodes, positions = EXPECTED[name]
    problem = load_scenario(name)
    assert problem.name == name
    assert problem.n_nodes == nodes
    assert problem.total_length == pytest.approx(length, abs=1e-12)
    assert problem.total_mass == pytest.approx(mass, abs=1e-12)
    assert problem.gravity == gravity
    assert problem.formulation is Formulation(formulation)
    assert problem.support_nodes.tolist() == support_nodes
    np.testing.assert_allclose(problem.support_positions, positions, atol=0)
    # Equal links and equal masses in every built-in.
    np.testing.assert_allclose(problem.link_lengths, length / (nodes - 1), rtol=1e-12)
    np.testing.assert_allclose(problem.masses, mass / nodes, rtol=1e-12)


def test_taut_and_licq_supports_are_one_chain_length_apart() -> None:
    for name in ("taut", "seed-licq"):
        problem = load_scenario(name)
        gap = np.linalg.norm(problem.support_positions[1] - problem.support_positions[0])
        assert gap == pytest.approx(problem.total_length, abs=1e-12)


def test_file_beats_builtin_name_and_stem_is_default_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "dangling").write_text(
        "[chain]\nnodes = 4\nlink_length = 1.0\nmass = 2.0\n[[supports]]\nnode = 0\nposition = [0, 0]\n"
    )
    monkeypatch.chdir(tmp_path)
    problem = load_scenario("dangling")
    assert problem.n_nodes == 4
    assert load_scenario(tmp_path / "dangling").name == "dangling"


# ----------------------------------------------------------------- schema mapping
def test_link_length_every_link() -> None:
    problem = parse_scenario(doc(chain={"nodes": 4, "link_length": 0.5, "mass": 1.0}))
    np.testing.assert_array_equal(problem.link_lengths, [0.5, 0.5, 0.5])


def test_length_spread_equally() -> None:
    problem = parse_scenario(doc(chain={"nodes": 5, "length": 2.0, "mass": 1.0}))
    np.testing.assert_array_equal(problem.link_lengths, [0.5, 0.5, 0.5, 0.5])


def test_link_lengths_per_link() -> None:
    problem = parse_scenario(doc(chain={"nodes": 4, "link_lengths": [0.1, 0.2, 3], "mass": 1.0}))
    np.testing.assert_array_equal(problem.link_lengths, [0.1, 0.2, 3.0])


def test_masses_number_is_every_node() -> None:
    problem = parse_scenario(doc(chain={"nodes": 3, "length": 2.0, "masses": 2}))
    np.testing.assert_array_equal(problem.masses, [2.0, 2.0, 2.0])


def test_masses_list_per_node() -> None:
    problem = parse_scenario(doc(chain={"nodes": 3, "length": 2.0, "masses": [1, 0.0, 2.5]}))
    np.testing.assert_array_equal(problem.masses, [1.0, 0.0, 2.5])


def test_mass_total_spread_equally() -> None:
    problem = parse_scenario(doc(chain={"nodes": 4, "length": 2.0, "mass": 2.0}))
    np.testing.assert_array_equal(problem.masses, [0.5, 0.5, 0.5, 0.5])


def test_defaults_and_top_level_keys() -> None:
    problem = parse_scenario(doc())
    assert problem.gravity == DEFAULT_GRAVITY
    assert problem.formulation is Formulation.NORM
    assert problem.name == "chain"
    assert parse_scenario(doc(), source="demo/my-chain.toml").name == "my-chain"
    problem = parse_scenario(doc(name="x", description="d", formulation="squared", gravity=2))
    assert (problem.name, problem.formulation, problem.gravity) == ("x", Formulation.SQUARED, 2.0)


def test_negative_support_index_is_normalised() -> None:
    supports = [{"node": -5, "position": [0, 0]}, {"node": -1, "position": [1, 0]}, {"node": 2, "position": [0.5, 0]}]
    problem = parse_scenario(doc(supports=supports))
    assert problem.support_nodes.tolist() == [0, 2, 4]
    np.testing.assert_array_equal(problem.support_positions, [[0, 0], [0.5, 0], [1, 0]])


# ----------------------------------------------------------------- validation
ONE = [{"node": 0, "position": [0.0, 0.0]}]
BAD = [
    # (id, document, key path the message must name)
    ("unknown-top", doc(obstacels=[]), "obstacels"),
    ("unknown-top-typo", doc(gravty=1.0), "gravty"),
    ("unknown-chain", doc(chain={"nodes": 3, "length": 1.0, "mass": 1.0, "mases": 1}), "chain.mases"),
    ("unknown-support", doc(supports=[{"node": 0, "position": [0, 0], "pos": 1}]), "supports[0].pos"),
    ("missing-chain", {"supports": ONE}, "chain"),
    ("missing-nodes", doc(chain={"length": 1.0, "mass": 1.0}), "chain.nodes"),
    ("missing-supports", {"chain": {"nodes": 3, "length": 1.0, "mass": 1.0}}, "supports"),
    ("empty-supports", doc(supports=[]), "supports"),
    ("missing-node", doc(supports=[{"position": [0, 0]}]), "supports[0].node"),
    ("missing-position", doc(supports=[{"node": 0}]), "supports[0].position"),
    ("bool-nodes", doc(chain={"nodes": True, "length": 1.0, "mass": 1.0}), "chain.nodes"),
    ("float-nodes", doc(chain={"nodes": 10.0, "length": 1.0, "mass": 1.0}), "chain.nodes"),
    ("huge-nodes", doc(chain={"nodes": 2**40, "length": 1.0, "mass": 1.0}), "chain.nodes"),
    ("string-nodes", doc(chain={"nodes": "10", "length": 1.0, "mass": 1.0}), "chain.nodes"),
    ("bool-mass", doc(chain={"nodes": 3, "length": 1.0, "mass": True}), "chain.mass"),
    ("bool-gravity", doc(gravity=True), "gravity"),
    ("string-length", doc(chain={"nodes": 3, "length": "1.0", "mass": 1.0}), "chain.length"),
    ("string-in-masses", doc(chain={"nodes": 3, "length": 1.0, "masses": [1, "2", 3]}), "chain.masses[1]"),
    ("bool-in-link-lengths", doc(chain={"nodes": 3, "link_lengths": [1, True], "mass": 1}), "chain.link_lengths[1]"),
    ("table-masses", doc(chain={"nodes": 3, "length": 1.0, "masses": {"a": 1}}), "chain.masses"),
    ("number-link-lengths", doc(chain={"nodes": 3, "link_lengths": 1.0, "mass": 1}), "chain.link_lengths"),
    ("position-short", doc(supports=[{"node": 0, "position": [0.0]}]), "supports[0].position"),
    ("position-long", doc(supports=[{"node": 0, "position": [0, 0, 0]}]), "supports[0].position"),
    ("position-number", doc(supports=[{"node": 0, "position": 1.0}]), "supports[0].position"),
    ("position-string", doc(supports=[*ONE, {"node": 2, "position": [1, "0"]}]), "supports[1].position[1]"),
    ("position-bool", doc(supports=[{"node": 0, "position": [False, 0]}]), "supports[0].position[0]"),
    ("float-node", doc(supports=[{"node": 0.0, "position": [0, 0]}]), "supports[0].node"),
    ("supports-table", doc(supports={"node": 0, "position": [0, 0]}), "supports"),
    ("supports-not-tables", doc(supports=[1, 2]), "supports[0]"),
    ("chain-not-table", doc(chain=[5]), "chain"),
    ("inf-gravity", doc(gravity=math.inf), "gravity"),
    ("nan-length", doc(chain={"nodes": 3, "length": math.nan, "mass": 1.0}), "chain.length"),
    ("inf-link-length", doc(chain={"nodes": 3, "link_length": -math.inf, "mass": 1.0}), "chain.link_length"),
    ("nan-in-masses", doc(chain={"nodes": 3, "length": 1.0, "masses": [1, 1, math.nan]}), "chain.masses[2]"),
    ("inf-position", doc(supports=[{"node": 0, "position": [0, math.inf]}]), "supports[0].position[1]"),
    ("string-name", doc(name=3), "name"),
    ("string-description", doc(description=["a"]), "description"),
    ("bad-formulation", doc(formulation="cubic"), "formulation"),
    # Value checks that Problem.build owns: they must come through with their key.
    ("few-nodes", doc(chain={"nodes": 1, "length": 1.0, "mass": 1.0}, supports=ONE), "chain.nodes"),
    ("negative-mass", doc(chain={"nodes": 3, "length": 1.0, "masses": [1, -1, 1]}), "chain.masses"),
    ("zero-link", doc(chain={"nodes": 3, "link_lengths": [1, 0], "mass": 1}), "chain.link_lengths"),
    ("wrong-count", doc(chain={"nodes": 3, "length": 1.0, "masses": [1, 1]}), "chain.masses"),
    ("two-lengths", doc(chain={"nodes": 3, "length": 1.0, "link_length": 0.5, "mass": 1}), "link_length"),
    ("no-mass", doc(chain={"nodes": 3, "length": 1.0}), "mass"),
    ("node-range", doc(supports=[*ONE, {"node": 5, "position": [1, 0]}]), "supports[1].node"),
    ("node-twice", doc(supports=[*ONE, {"node": -5, "position": [1, 0]}]), "supports"),
    ("zero-gravity", doc(gravity=0), "gravity"),
]


@pytest.mark.parametrize(("document", "key"), [pytest.param(d, k, id=i) for i, d, k in BAD])
def test_bad_document_names_the_key(document: dict[str, Any], key: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(document, source="bad.toml")
    message = str(info.value)
    assert key in message
    assert message.startswith("bad.toml: ")
    assert "\n" not in message


def test_unknown_key_suggests_the_closest() -> None:
    with pytest.raises(ScenarioError, match="did you mean 'masses'"):
        parse_scenario(doc(chain={"nodes": 3, "length": 1.0, "mases": 1.0}))


def test_geometry_is_not_checked_here() -> None:
    # Supports 10 apart with a chain of length 2: infeasible, but that is the solver's call.
    far = [{"node": 0, "position": [0, 0]}, {"node": -1, "position": [10, 0]}]
    assert parse_scenario(doc(supports=far)).n_nodes == 5


# ----------------------------------------------------------------- loading
def test_toml_syntax_error(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("[chain]\nnodes = \n")
    with pytest.raises(ScenarioError, match=r"broken\.toml: invalid TOML: .*line 2, column 9") as info:
        load_scenario(path)
    assert "\n" not in str(info.value)


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin.toml"
    path.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(ScenarioError, match="UTF-8"):
        load_scenario(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(tmp_path / "nothing.toml")
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(str(tmp_path / "nothing.toml"))


def test_directory_is_not_a_scenario(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="not a file"):
        load_scenario(tmp_path)


def test_unknown_builtin_lists_the_names() -> None:
    with pytest.raises(ScenarioError) as info:
        load_scenario("two-support")
    assert all(name in str(info.value) for name in BUILTINS)


def test_file_error_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text("[chain]\nnodes = 3\nlength = 1.0\nmass = 1.0\n")
    with pytest.raises(ScenarioError, match=r"mine\.toml: supports is missing"):
        load_scenario(path)


# ----------------------------------------------------------------- fuzz
# Values TOML can hold. Floats are kept within ±1e100: a sum overflowing to inf inside
# Problem (e.g. 101 masses of 1e308) emits a numpy RuntimeWarning there, not a wrong type here.
toml_scalars = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.integers(min_value=-3, max_value=120),
    st.floats(min_value=-1e100, max_value=1e100),
    st.sampled_from([math.inf, -math.inf, math.nan, 0.0, -0.0]),
    st.text(max_size=8),
    st.sampled_from(["norm", "squared", "nodes", "mass", "position"]),
    st.datetimes(max_value=datetime.datetime(9999, 1, 1)),
    st.dates(),
    st.times(),
)
toml_values = st.recursive(
    toml_scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=8,
)


def paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path to a value inside a parsed TOML document."""
    found = []
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
    for key, value in items:
        found.append((*prefix, key))
        found.extend(paths(value, (*prefix, key)))
    return found


@st.composite
def mutated_documents(draw: st.DrawFn) -> dict[str, Any]:
    document = copy.deepcopy(draw(st.sampled_from(RAW_BUILTINS)))
    for _ in range(draw(st.integers(1, 3))):
        # The empty path stands for the document itself, so keys can be added at the top level.
        path = draw(st.sampled_from([(), *paths(document)]))
        parent: Any = document
        for key in path[:-1]:
            parent = parent[key]
        target = parent[path[-1]] if path else document
        action = draw(st.sampled_from(["delete", "replace", "add"]))
        if action == "add" and isinstance(target, dict):
            key = draw(st.sampled_from(["obstacles", "mass", "masses", "length", "node", "x"]) | st.text(max_size=6))
            target[key] = draw(toml_values)
        elif action == "delete" and path:
            del parent[path[-1]]
        elif path:
            parent[path[-1]] = draw(toml_values)
    return document


RAW_BUILTINS = [raw_builtin(name) for name in BUILTINS]


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_documents())
def test_fuzz_mutations_give_problem_or_scenario_error(document: dict[str, Any]) -> None:
    try:
        problem = parse_scenario(document)
    except ScenarioError as error:
        assert "\n" not in str(error)
    else:
        assert problem.n_nodes >= 2


@pytest.mark.parametrize(
    ("build", "words"),
    [
        (lambda: Problem.build(nodes=41, length=1e308, mass=1.0, supports=[(0, (0.0, 0.0))]), "chain is 1e+308 long"),
        (
            lambda: Problem.build(nodes=3, length=1.0, mass=1.0, supports=[(0, (1e200, 0.0))]),
            "supports[0].position = [1e+200, 0.0] is too large",
        ),
        (
            lambda: Problem.build(nodes=3, length=1.0, mass=1e308, supports=[(0, (0.0, 0.0))]),
            "the weight g * mass = inf is out of range",
        ),
        (
            lambda: Problem.build(nodes=3, length=1.0, mass=1.0, gravity=1e-320, supports=[(0, (0.0, 0.0))]),
            "the weight g * mass = 1e-320 is out of range",
        ),
    ],
    ids=["length", "coordinate", "weight", "tiny weight"],
)
def test_sizes_whose_squares_overflow_are_refused(build: Callable[[], Problem], words: str) -> None:
    """A disk's phi squares coordinates: 1e308 used to overflow with a numpy warning mid-solve."""
    with pytest.raises(ScenarioError, match=re.escape(words)):
        build()


def test_a_deeply_nested_value_is_quoted_short_in_the_model_messages_too() -> None:
    """Found by the long fuzz profile: ``formulation`` set to a table nested 64 deep was quoted whole
    (779 characters) by the model's check, which did not use the scenario parser's short quotes."""
    from funicular.model import Formulation

    value: object = "norm"
    for _ in range(64):
        value = {"chain": value}
    with pytest.raises(ScenarioError) as error:
        Formulation.parse(value)
    message = str(error.value)
    assert message.startswith("formulation = {'chain'") and message.endswith("use 'norm' or 'squared'.")
    assert len(message) <= 200
