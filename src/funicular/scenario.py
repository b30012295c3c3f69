"""Scenario files: TOML descriptions of a hanging chain or a cable net, validated into a :class:`Problem`.

A ``[chain]`` table describes a chain; a ``[net]`` table a net, either by its ``links`` or by a
generator (``grid``, ``radial``, ``disk`` or ``mesh``, see :mod:`funicular.nets`).

This module checks the *shape* of a document (known keys, types, finite numbers) and leaves the
value checks (masses >= 0, lengths > 0, support indices in range, ...) to :meth:`Problem.build`,
so each rule lives in one place. Geometric feasibility is the solver's business.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from funicular import nets
from funicular._types import finite_numbers
from funicular.errors import ScenarioError, shown
from funicular.model import DEFAULT_GRAVITY, MAX_NODES, FloatArray, Problem
from funicular.obstacles import (
    Box,
    Cuboid,
    Disk,
    Ellipse,
    Ellipsoid,
    Expression,
    Graph,
    HalfPlane,
    HalfSpace,
    Obstacle,
    Sphere,
    Surface,
    obstacle_dimension,
)

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable

DEFAULT_SCENARIO = "two-supports"

# Allowed keys per table. Sets, so later features (obstacles, contact) only add a name here.
TOP_LEVEL_KEYS = frozenset(
    {
        "name",
        "description",
        "formulation",
        "gravity",
        "dimension",
        "chain",
        "net",
        "supports",
        "loads",
        "obstacles",
        "contact",
        "units",
    }
)
# A link's stiffness and the cable's weight per unstretched length (elastic cables).
CABLE_KEYS = frozenset({"axial_stiffness", "linear_density"})
CHAIN_KEYS = (
    frozenset({"nodes", "link_length", "length", "link_lengths", "masses", "mass", "axial_stiffnesses"}) | CABLE_KEYS
)
# A net: nodes and links listed, or one generator (grid, radial, disk, mesh) with its options.
GENERATORS = ("grid", "radial", "disk", "mesh")
NET_KEYS = (
    frozenset(
        {"nodes", "links", "link_length", "link_lengths", "masses", "mass", "size", "slack", "supports", *GENERATORS}
    )
    | CABLE_KEYS
)
RADIAL_KEYS = frozenset({"rings", "spokes", "radius"})
SUPPORT_KEYS = frozenset({"node", "position"})
LOAD_KEYS = frozenset({"node", "force"})
# Problem.build's arguments as a scenario file names them (the chain's keys live in [chain]).
FILE_KEYS = {key: f"chain.{key}" for key in CHAIN_KEYS} | {"Problem.build": "chain"}


def _type_name(value: object) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a float", str: "a string", list: "a list", dict: "a table"}
    return names.get(type(value), type(value).__name__)


# ----------------------------------------------------------------- value checks
def _key_path(where: str, key: str) -> str:
    # Quote odd keys as TOML would, so a key holding a newline cannot break the message.
    quoted = key if re.fullmatch(r"[A-Za-z0-9_-]{1,40}", key) else shown(key)
    return f"{where}.{quoted}" if where else quoted


def _check_keys(table: Mapping[str, Any], allowed: frozenset[str], where: str) -> None:
    for key in table:
        if key in allowed:
            continue
        path = _key_path(where, key)
        close = difflib.get_close_matches(str(key), sorted(allowed), n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        valid = ", ".join(sorted(allowed))
        raise ScenarioError(f"{path} is not a known key ({hint}valid keys here: {valid}).")


def _number(value: object, key: str) -> float:
    # bool is a subclass of int, but TOML `true` is not a number.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f"{key} must be a number, got {_type_name(value)} {shown(value)}.")
    try:
        number = float(value)
    except OverflowError:  # a Python int beyond float range
        number = math.inf
    if not math.isfinite(number):
        raise ScenarioError(f"{key} = {shown(value)} is not a finite number.")
    return number


def _number_list(value: object, key: str) -> FloatArray:
    if not isinstance(value, (list, tuple, np.ndarray)):
        raise ScenarioError(f"{key} must be a list of numbers, got {_type_name(value)} {shown(value)}.")
    array = finite_numbers(value)
    if array is not None:
        return array
    return np.array([_number(item, f"{key}[{i}]") for i, item in enumerate(value)], dtype=np.float64)


def _integer(value: object, key: str, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ScenarioError(f"{key} must be {what}, got {_type_name(value)} {shown(value)}.")
    return value


def _string(value: object, key: str) -> str:
    if not isinstance(value, str):
        raise ScenarioError(f"{key} must be a string, got {_type_name(value)} {shown(value)}.")
    return value


def _table(value: object, key: str, how: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise ScenarioError(f"{key} must be a table ({how}), got {_type_name(value)} {shown(value)}.")
    return value


# ----------------------------------------------------------------- parsing
def _chain_arguments(chain: Mapping[str, Any]) -> dict[str, Any]:
    """The chain's keyword arguments for Problem.build, type-checked; values are checked there."""
    _check_keys(chain, CHAIN_KEYS, "chain")
    if "nodes" not in chain:
        raise ScenarioError("chain.nodes is missing; give the number of nodes, an integer >= 2.")
    nodes = _integer(chain["nodes"], "chain.nodes", "an integer >= 2")
    if nodes > MAX_NODES:
        raise ScenarioError(f"chain.nodes = {nodes} is too large; use at most {MAX_NODES} nodes.")
    arguments: dict[str, Any] = {"nodes": nodes}
    for key in ("link_length", "length"):
        if key in chain:
            arguments[key] = _number(chain[key], f"chain.{key}")
    if "link_lengths" in chain:
        arguments["link_lengths"] = _number_list(chain["link_lengths"], "chain.link_lengths")
    return arguments | _masses(chain, "chain")


def _node_vectors(
    value: object, dimension: int, table: str, keys: frozenset[str], each: str
) -> list[tuple[int, tuple[float, ...]]]:
    """An array of ``[[table]]`` tables, each with ``node`` and a d-vector (the other of ``keys``),
    as (node, vector) pairs; ``each`` names one table in the messages (a support, a point load)."""
    (vector,) = keys - {"node"}
    if not isinstance(value, (list, tuple)):
        got = f"{_type_name(value)} {shown(value)}"
        raise ScenarioError(f"{table} must be an array of tables ([[{table}]]), got {got}.")
    axes = "[x, y]" if dimension == 2 else "[x, y, z]"
    pairs = []
    for j, item in enumerate(value):
        where = f"{table}[{j}]"
        entry = _table(item, where, f"[[{table}]] with node and {vector}")
        _check_keys(entry, keys, where)
        for key in ("node", vector):
            if key not in entry:
                raise ScenarioError(f"{where}.{key} is missing; each {each} needs node and {vector} = {axes}.")
        node = _integer(entry["node"], f"{where}.node", "an integer node index")
        numbers = entry[vector]
        if not isinstance(numbers, (list, tuple)) or len(numbers) != dimension:
            raise ScenarioError(
                f"{where}.{vector} must be a list of {dimension} numbers {axes}"
                + (" (dimension = 3)" if dimension == 3 else "")
                + f", got {shown(numbers)}."
            )
        pairs.append((node, tuple(_number(c, f"{where}.{vector}[{i}]") for i, c in enumerate(numbers))))
    return pairs


def _supports(value: object, dimension: int = 2) -> list[tuple[int, tuple[float, ...]]]:
    if isinstance(value, (list, tuple)) and not value:
        raise ScenarioError("supports is empty; give at least one [[supports]] table, or the chain falls forever.")
    return _node_vectors(value, dimension, "supports", SUPPORT_KEYS, "support")


def _loads(value: object, dimension: int) -> list[tuple[int, tuple[float, ...]]]:
    """``[[loads]]`` tables (node, force) as (node, force) pairs."""
    return _node_vectors(value, dimension, "loads", LOAD_KEYS, "point load")


# ----------------------------------------------------------------- obstacles
class _Shape(NamedTuple):
    """How a file's ``shape`` is built: the class, its required and optional keys, and fixed
    arguments (an expression's dimension). _VECTORS and _NUMBERS say how each key is read."""

    build: Callable[..., Obstacle]  # (a class: the reverse lookup of obstacle_table keys on it)
    required: tuple[str, ...]
    optional: tuple[str, ...] = ()
    fixed: tuple[tuple[str, int], ...] = ()


# Per dimension: "box" and "expression" are shapes of both, with their own keys.
_SHAPES: dict[int, dict[str, _Shape]] = {
    2: {
        "halfplane": _Shape(HalfPlane, ("point", "normal")),
        "disk": _Shape(Disk, ("center", "radius")),
        "ellipse": _Shape(Ellipse, ("center", "semi_axes"), ("angle",)),
        "box": _Shape(Box, ("center", "half_size", "corner_radius"), ("angle",)),
        "graph": _Shape(Graph, ("f",)),
        "expression": _Shape(Expression, ("phi",)),
    },
    3: {
        "sphere": _Shape(Sphere, ("center", "radius")),
        "ellipsoid": _Shape(Ellipsoid, ("center", "semi_axes")),
        "halfspace": _Shape(HalfSpace, ("point", "normal")),
        "box": _Shape(Cuboid, ("center", "half_sizes"), ("radius", "angle")),
        "surface": _Shape(Surface, ("height",)),
        "expression": _Shape(Expression, ("phi",), (), (("dimension", 3),)),
    },
}
_VECTORS = frozenset({"point", "normal", "center", "semi_axes", "half_size", "half_sizes"})
_NUMBERS = frozenset({"radius", "corner_radius", "angle"})
# A planar box's keys in a 3-D file, and the other way round: said outright, not only guessed.
_OTHER_BOX_KEYS = {3: frozenset({"half_size", "corner_radius"}), 2: frozenset({"half_sizes"})}


def _toml_vector(value: object, key: str, length: int) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise ScenarioError(f"{key} must be a list of {length} numbers, got {shown(value)}.")
    return tuple(_number(item, f"{key}[{i}]") for i, item in enumerate(value))


def _toml_pair(value: object, key: str) -> tuple[float, float]:
    x, y = _toml_vector(value, key, 2)
    return x, y


def parse_obstacle(table: Mapping[str, Any], index: int, dimension: int = 2) -> Obstacle:
    """Build obstacle ``index`` of a ``dimension``-D scenario from its ``[[obstacles]]`` table;
    errors name ``obstacles[index].key``."""
    where = f"obstacles[{index}]"
    table = _table(table, where, "[[obstacles]] with a shape and its keys")
    valid = _SHAPES[dimension]
    shapes = ", ".join(valid)
    if "shape" not in table:
        raise ScenarioError(f"{where}.shape is missing; use one of {shapes}.")
    shape = _string(table["shape"], f"{where}.shape")
    if shape not in valid:
        if shape not in _SHAPES[5 - dimension]:
            raise ScenarioError(f"{where}.shape = {shown(shape)} is not a shape; use one of {shapes}.")
        raise ScenarioError(
            f"{where}.shape = {shown(shape)} is a {5 - dimension}-D shape, but the scenario is {dimension}-D "
            f"(dimension = {dimension}); use one of {shapes}."
        )
    build, required, optional, fixed = valid[shape]
    other = next((key for key in table if key in _OTHER_BOX_KEYS[dimension]), None) if shape == "box" else None
    if other is not None:
        raise ScenarioError(
            f"{where}.{other} is a key of a box in {'the plane' if dimension == 3 else 'space'}; a box in a "
            f"{dimension}-D scenario takes {', '.join(required[:-1])} and {required[-1]}, and optionally "
            f"{' and '.join(optional)}."
        )
    _check_keys(table, frozenset({"shape", "name", *required, *optional}), where)
    for key in required:
        if key not in table:
            raise ScenarioError(f"{where}.{key} is missing; a {shape} needs {', '.join(required)}.")
    arguments: dict[str, Any] = dict(fixed)
    for key in (*required, *optional):
        if key not in table:
            continue
        value, path = table[key], f"{where}.{key}"
        if key in _VECTORS:
            arguments[key] = _toml_vector(value, path, dimension)
        elif key in _NUMBERS:
            arguments[key] = _number(value, path)
        else:
            arguments[key] = _string(value, path)
    name = _string(table.get("name", f"{shape} {index}"), f"{where}.name")
    try:
        return build(**arguments, name=name)
    except ScenarioError as error:  # the shape names its field; the file's key is obstacles[index].field
        prefix = f"obstacle {name!r}: "
        if error.key is None or not error.key.startswith(prefix):
            raise
        raise error.renamed(f"{where}.{error.key.removeprefix(prefix)}") from None


def _obstacles(value: object, dimension: int = 2) -> list[Obstacle]:
    if not isinstance(value, (list, tuple)):
        raise ScenarioError(
            f"obstacles must be an array of tables ([[obstacles]]), got {_type_name(value)} {shown(value)}."
        )
    obstacles = [parse_obstacle(item, j, dimension) for j, item in enumerate(value)]
    names = [obstacle.name for obstacle in obstacles]
    for j, name in enumerate(names):
        if name in names[:j]:
            raise ScenarioError(
                f"obstacles[{j}].name = {shown(name)} is already used by obstacles[{names.index(name)}]; "
                "give each obstacle its own name."
            )
    return obstacles


def _dimension(document: Mapping[str, Any], generated: bool) -> int:
    """The file's dimension: 2 unless given, 3 for a generated net (which lies in space)."""
    if "dimension" not in document:
        return 3 if generated else 2
    dimension = _integer(document["dimension"], "dimension", "2 (a plane) or 3 (space)")
    if dimension not in (2, 3):
        raise ScenarioError(f"dimension = {dimension}; use 2 (a plane) or 3 (space).")
    if generated and dimension != 3:
        raise ScenarioError(
            "dimension = 2, but a generated net (grid, radial, disk, mesh) hangs in space; "
            "set dimension = 3 or leave it out."
        )
    return dimension


def _generator(net: Mapping[str, Any]) -> str | None:
    given = [key for key in GENERATORS if key in net]
    if len(given) > 1:
        raise ScenarioError(
            f"net.{given[1]}: give one generator of {', '.join(GENERATORS)}, not {' and '.join(given)}."
        )
    return given[0] if given else None


def _number_or_list(value: object, key: str) -> float | FloatArray:
    """A number for every entry, or a list of them."""
    if isinstance(value, (list, tuple)):
        return _number_list(value, key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f"{key} must be a number or a list of numbers, got {_type_name(value)} {shown(value)}.")
    return float(value)  # (Problem.build checks the value: inf is an inextensible link)


def _masses(table: Mapping[str, Any], name: str) -> dict[str, Any]:
    """A chain's or a net's ``mass`` (total), ``masses`` (a number for every node, or a list) or
    ``linear_density`` (mass per unstretched length), and its links' ``axial_stiffness`` (a
    chain's list of them: ``axial_stiffnesses``)."""
    arguments: dict[str, Any] = {}
    if "linear_density" in table:
        arguments["linear_density"] = _number_or_list(table["linear_density"], f"{name}.linear_density")
    if "axial_stiffness" in table and "axial_stiffnesses" in table:
        raise ScenarioError(
            f"{name}.axial_stiffnesses: give axial_stiffness (every link) or axial_stiffnesses (one per link), "
            "not both."
        )
    if "axial_stiffness" in table:
        value = table["axial_stiffness"]
        if isinstance(value, (list, tuple)):
            raise ScenarioError(
                f"{name}.axial_stiffness is one number for every link; give one per link as "
                + ("axial_stiffnesses = [...]." if name == "chain" else "a fourth number in each link row.")
            )
        arguments["axial_stiffness"] = _number_or_list(value, f"{name}.axial_stiffness")
    if "axial_stiffnesses" in table:
        arguments["axial_stiffness"] = _number_list(table["axial_stiffnesses"], f"{name}.axial_stiffnesses")
    if "mass" in table:
        arguments["mass"] = _number(table["mass"], f"{name}.mass")
    if "masses" in table:
        masses = table["masses"]
        if isinstance(masses, (list, tuple)):
            arguments["masses"] = _number_list(masses, f"{name}.masses")
        elif isinstance(masses, bool) or not isinstance(masses, (int, float)):
            raise ScenarioError(
                f"{name}.masses must be a number or a list of numbers, got {_type_name(masses)} {shown(masses)}."
            )
        else:
            arguments["masses"] = _number(masses, f"{name}.masses")
    return arguments


def _net_links(value: object) -> list[list[float]]:
    """``net.links`` type-checked: [i, j, length] or [i, j] entries (Problem.build checks the values)."""
    if not isinstance(value, (list, tuple)) or not value:
        raise ScenarioError(f"net.links must be a non-empty list of [i, j, length] entries, got {shown(value)}.")
    links: list[list[float]] = []
    width = None
    for k, entry in enumerate(value):
        key = f"net.links[{k}]"
        if not isinstance(entry, (list, tuple)) or len(entry) not in (2, 3, 4):
            raise ScenarioError(
                f"{key} must be [i, j, length], [i, j, length, EA] (an elastic link) or [i, j] with "
                f"net.link_length, got {shown(entry)}."
            )
        if width is not None and min(len(entry), 3) != width:
            raise ScenarioError(f"{key} = {shown(entry)}: give every link as [i, j, length], or every one as [i, j].")
        width = min(len(entry), 3)
        i, j = (_integer(entry[m], f"{key}[{m}]", "an integer node index") for m in (0, 1))
        if not (-MAX_NODES <= i < MAX_NODES and -MAX_NODES <= j < MAX_NODES):
            raise ScenarioError(f"{key} = {shown(entry)} names a node far out of range.")
        links.append(
            [
                i,
                j,
                *(
                    _number(entry[m], f"{key}[{m}]") if m == 2 else _stiffness(entry[m], f"{key}[{m}]")
                    for m in range(2, len(entry))
                ),
            ]
        )
    return links


def _stiffness(value: object, key: str) -> float:
    """A link row's EA: a number (inf: inextensible)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(
            f"{key} must be a number (the link's axial stiffness EA), got {_type_name(value)} {shown(value)}."
        )
    return float(value)


def _net_supports(value: object) -> str | list[int]:
    if isinstance(value, str):
        return value
    if isinstance(value, (list, tuple)):
        return [_integer(item, f"net.supports[{i}]", "an integer node index") for i, item in enumerate(value)]
    raise ScenarioError(
        f"net.supports must be a name (corners, edges, outer, boundary) or a list of node indices, got {shown(value)}."
    )


# The generators' argument names as a scenario file names them.
_GENERATOR_KEYS = {
    "rows": "net.grid",
    "columns": "net.grid",
    "size": "net.size",
    "slack": "net.slack",
    "link_length": "net.link_length",
    "supports": "net.supports",
    "mass": "net.mass",
    "masses": "net.masses",
    "linear_density": "net.linear_density",
    "axial_stiffness": "net.axial_stiffness",
    "nodes": "net",
    "links": "net",
    "link_lengths": "net.slack",
    "Problem.build": "net",
    "mesh": "net.mesh",
}


def _generated_net(net: Mapping[str, Any], generator: str, common: dict[str, Any], base: Path) -> Problem:
    for key in ("nodes", "links", "link_lengths"):
        if key in net:
            raise ScenarioError(
                f"net.{key} does not go with net.{generator}, which makes the nodes and links; remove one of them."
            )
    arguments: dict[str, Any] = {**common, **_masses(net, "net")}
    for key in ("slack", "link_length"):
        if key in net:
            arguments[key] = _number(net[key], f"net.{key}")
    if "supports" in net:
        arguments["supports"] = _net_supports(net["supports"])
    if "size" in net and generator != "grid":
        raise ScenarioError(f"net.size applies to a grid; a {generator} net takes its size from its own keys.")
    value = net[generator]
    renames = dict(_GENERATOR_KEYS)
    if generator == "grid":
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            raise ScenarioError(f"net.grid must be [rows, columns], two integers >= 2, got {shown(value)}.")
        rows, columns = (_integer(item, f"net.grid[{i}]", "an integer >= 2") for i, item in enumerate(value))
        if "size" in net:
            arguments["size"] = _toml_pair(net["size"], "net.size")
        make: Callable[..., Problem] = nets.grid
        positional: tuple[Any, ...] = (rows, columns)
    elif generator in ("radial", "disk"):
        where = f"net.{generator}"
        table = _table(value, where, "{rings = ..., spokes = ..., radius = ...}")
        _check_keys(table, RADIAL_KEYS, where)
        for key in ("rings", "spokes"):
            if key not in table:
                raise ScenarioError(f"{where}.{key} is missing; a {generator} net needs rings and spokes (and radius).")
        positional = tuple(_integer(table[key], f"{where}.{key}", "an integer") for key in ("rings", "spokes"))
        if "radius" in table:
            arguments["radius"] = _number(table["radius"], f"{where}.radius")
        renames |= {key: f"{where}.{key}" for key in RADIAL_KEYS}
        make = nets.radial
        arguments["triangulated"] = generator == "disk"
    else:
        path = Path(_string(value, "net.mesh"))
        make, positional = nets.mesh, (path if path.is_absolute() else base / path,)
    try:
        return make(*positional, **arguments)
    except ScenarioError as error:  # the generator names its arguments; the file has them in [net]
        raise error.renamed(renames.get(error.key or "", error.key or "")) from None


def _listed_net(net: Mapping[str, Any], document: Mapping[str, Any], common: dict[str, Any], dimension: int) -> Problem:
    for key in ("size", "slack", "supports"):
        if key in net:
            raise ScenarioError(
                f"net.{key} applies to a generated net (grid, radial, disk, mesh); a net with listed links "
                "has [[supports]] tables and each link's length."
            )
    for key in ("nodes", "links"):
        if key not in net:
            raise ScenarioError(
                f"net.{key} is missing; a net needs nodes and links = [[i, j, length], ...], or a generator "
                f"({', '.join(GENERATORS)})."
            )
    nodes = _integer(net["nodes"], "net.nodes", "an integer >= 2")
    if nodes > MAX_NODES:
        raise ScenarioError(f"net.nodes = {nodes} is too large; use at most {MAX_NODES} nodes.")
    arguments: dict[str, Any] = {"nodes": nodes, "links": _net_links(net["links"]), **_masses(net, "net")}
    if "link_length" in net:
        arguments["link_length"] = _number(net["link_length"], "net.link_length")
    if "link_lengths" in net:
        arguments["link_lengths"] = _number_list(net["link_lengths"], "net.link_lengths")
    if "supports" not in document:
        raise ScenarioError("supports is missing; add at least one [[supports]] table with node and position.")
    supports = _supports(document["supports"], dimension)
    try:
        return Problem.build(**arguments, supports=supports, dimension=dimension, **common)
    except ScenarioError as error:  # Problem.build names its arguments; the file has them in [net]
        keys = {key: f"net.{key}" for key in NET_KEYS} | {"Problem.build": "net"}
        # the lengths as the file gives them: a list, one for all, or each link's [i, j, length]
        given = next((key for key in ("link_lengths", "link_length") if key in net), "links")
        keys["link_lengths"] = f"net.{given}"
        raise error.renamed(keys.get(error.key or "", error.key or "")) from None


def _parse(document: Mapping[str, Any], default_name: str, base: Path | None = None) -> Problem:
    problem = _parse_structure(document, default_name, base)
    if "loads" not in document:
        return problem
    return problem.with_loads(_loads(document["loads"], problem.dimension))


def _parse_structure(document: Mapping[str, Any], default_name: str, base: Path | None = None) -> Problem:
    _check_keys(document, TOP_LEVEL_KEYS, "")
    name = _string(document.get("name", default_name), "name")
    if "description" in document:
        _string(document["description"], "description")
    if "chain" in document and "net" in document:
        raise ScenarioError("net: give either a [chain] table or a [net] table, not both.")
    if "chain" not in document and "net" not in document:
        raise ScenarioError(
            "chain is missing; add a [chain] table with nodes, a length and a mass (or a [net] table for a net)."
        )
    if "net" in document:
        net = _table(document["net"], "net", "[net] with nodes and links, or a generator such as grid")
        _check_keys(net, NET_KEYS, "net")
        generator = _generator(net)
        dimension = _dimension(document, generator is not None)
        common: dict[str, Any] = {
            "gravity": _number(document.get("gravity", DEFAULT_GRAVITY), "gravity"),
            "formulation": document.get("formulation", "norm"),  # Formulation.parse names the key on error
            "name": name,
            "obstacles": _obstacles(document.get("obstacles", []), dimension),
            "units": document.get("units"),  # Problem checks the value and names the key
        }
        if "contact" in document and document["contact"] != "nodes":
            raise ScenarioError(
                f"contact = {shown(document['contact'])}; a net keeps its nodes out of the obstacles: "
                "use contact = 'nodes' (or leave it out)."
            )
        if generator is None:
            return _listed_net(net, document, common, dimension)
        if "supports" in document:
            raise ScenarioError(
                f"supports: a generated net is held by net.supports (e.g. 'corners'); "
                f"remove the [[supports]] tables or list the links in [net] instead of net.{generator}."
            )
        return _generated_net(net, generator, common, base or Path.cwd())
    chain = _table(document["chain"], "chain", "[chain] with nodes, a length and a mass")
    chain_arguments = _chain_arguments(chain)  # (first: a key misplaced into [chain] is named as such)
    dimension = _dimension(document, False)
    if "supports" not in document:
        raise ScenarioError("supports is missing; add at least one [[supports]] table with node and position.")
    try:
        return Problem.build(
            **chain_arguments,
            supports=_supports(document["supports"], dimension),
            gravity=_number(document.get("gravity", DEFAULT_GRAVITY), "gravity"),
            formulation=document.get("formulation", "norm"),  # Formulation.parse names the key on error
            name=name,
            obstacles=_obstacles(document.get("obstacles", []), dimension),
            contact=document.get("contact", "nodes"),  # Problem checks the value and names the key
            dimension=dimension,
            units=document.get("units"),
        )
    except ScenarioError as error:  # Problem.build names its arguments; the file has them in [chain]
        raise error.renamed(FILE_KEYS.get(error.key or "", error.key or "")) from None


def parse_scenario(document: Mapping[str, Any], source: str = "<scenario>") -> Problem:
    """Validate a parsed TOML document and build its Problem.

    ``source`` names the document in error messages; its stem is the default ``name``.
    Every invalid document raises :class:`ScenarioError` with a one-line message.
    """
    default_name = "chain" if source.startswith("<") else Path(source).stem
    return _parse_from(document, source, default_name)


def _parse_from(document: Mapping[str, Any], source: str, default_name: str) -> Problem:
    where = Path(source)
    base = where.parent if not source.startswith("<") and where.is_file() else None  # (a mesh is read from there)
    try:
        return _parse(document, default_name, base)
    except ScenarioError as error:
        raise ScenarioError(f"{source}: {error}") from None


# ----------------------------------------------------------------- a problem as a table (solution files)
PROBLEM_KEYS = frozenset(
    {
        "name",
        "formulation",
        "gravity",
        "contact",
        "masses",
        "link_lengths",
        "supports",
        "obstacles",
        "links",
        "dimension",
        "loads",
        "axial_stiffness",
        "units",
    }
)
_SHAPE_NAMES = {
    (dimension, entry.build): shape for dimension, shapes in _SHAPES.items() for shape, entry in shapes.items()
}


def obstacle_table(obstacle: Obstacle) -> dict[str, Any] | None:
    """The ``[[obstacles]]`` table of a built-in shape (None for any other obstacle)."""
    dimension = obstacle_dimension(obstacle)
    shape = _SHAPE_NAMES.get((dimension, type(obstacle)))
    if shape is None:
        return None
    _, required, optional, _ = _SHAPES[dimension][shape]
    table: dict[str, Any] = {"shape": shape, "name": obstacle.name}
    for key in (*required, *optional):
        value = getattr(obstacle, key)
        table[key] = list(value) if isinstance(value, tuple) else value
    return table


def problem_table(problem: Problem, arrays: bool = False) -> dict[str, Any] | None:
    """Every value of ``problem`` as a JSON-ready table (per-node masses and per-link lengths);
    None if an obstacle is not a built-in shape (a Python function cannot be written down). A net
    adds its ``links`` (node pairs) and a 3-D problem its ``dimension``. ``arrays``: the masses and
    lengths as the problem's own arrays, not lists (the result files' writers take them as they are)."""
    obstacles = [obstacle_table(obstacle) for obstacle in problem.obstacles]
    if any(table is None for table in obstacles):
        return None
    extra: dict[str, Any] = {} if problem.dimension == 2 else {"dimension": problem.dimension}
    if problem.links is not None:
        extra["links"] = problem.links.tolist()
    if problem.loads is not None:
        extra["loads"] = [{"node": int(node), "force": problem.loads[node].tolist()} for node in problem.loaded_nodes]
    if problem.axial_stiffness is not None:  # (an inextensible link's EA, infinite, as null)
        extra["axial_stiffness"] = [float(ea) if math.isfinite(ea) else None for ea in problem.axial_stiffness]
    if problem.units is not None:
        extra["units"] = problem.units
    return extra | {
        "name": problem.name,
        "formulation": problem.formulation.value,
        "gravity": problem.gravity,
        "contact": problem.contact,
        "masses": problem.masses if arrays else problem.masses.tolist(),
        "link_lengths": problem.link_lengths if arrays else problem.link_lengths.tolist(),
        "supports": [
            {"node": int(node), "position": position.tolist()}
            for node, position in zip(problem.support_nodes, problem.support_positions, strict=True)
        ],
        "obstacles": obstacles,
    }


def problem_from_table(table: Mapping[str, Any], source: str) -> Problem:
    """The :class:`Problem` of a :func:`problem_table`; errors start with ``source`` and name the key."""
    try:
        _check_keys(table, PROBLEM_KEYS, "")
        for key in ("masses", "link_lengths", "supports"):
            if key not in table:
                raise ScenarioError(f"{key} is missing.")
        dimension = _dimension(table, False)
        links = None
        if "links" in table:
            links = [pair[:2] for pair in _net_links(table["links"])]
        supports = _supports(table["supports"], dimension)
        problem = Problem(
            masses=_number_list(table["masses"], "masses"),
            link_lengths=_number_list(table["link_lengths"], "link_lengths"),
            support_nodes=[node for node, _ in supports],  # type: ignore[arg-type]
            support_positions=[position for _, position in supports],  # type: ignore[arg-type]
            gravity=_number(table.get("gravity", DEFAULT_GRAVITY), "gravity"),
            formulation=table.get("formulation", "norm"),
            name=_string(table.get("name", "chain"), "name"),
            obstacles=tuple(_obstacles(table.get("obstacles", []), dimension)),
            contact=table.get("contact", "nodes"),
            links=None if links is None else np.asarray(links, dtype=np.intp).reshape(-1, 2),
            dimension=dimension,
            axial_stiffness=None if "axial_stiffness" not in table else _stiffness_list(table["axial_stiffness"]),
            units=table.get("units"),
        )
        return problem.with_loads(_loads(table["loads"], dimension)) if "loads" in table else problem
    except ScenarioError as error:
        raise ScenarioError(f"{source}: {error}") from None


def _stiffness_list(value: object) -> FloatArray:
    """A result file's ``axial_stiffness``: one EA per link, null (None) for an inextensible one."""
    if isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind == "f":
        return np.where(np.isnan(value), math.inf, value)  # (a binary file's column: null read as NaN)
    if not isinstance(value, (list, tuple)):
        raise ScenarioError(f"axial_stiffness must be a list of numbers (null: inextensible), got {shown(value)}.")
    return np.array([math.inf if ea is None else _number(ea, f"axial_stiffness[{k}]") for k, ea in enumerate(value)])


def _toml_value(value: object) -> str:
    if isinstance(value, str):  # a TOML basic string: JSON's escapes, plus DEL, which TOML forbids raw
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return repr(float(value)) if isinstance(value, float) else str(value)  # repr: the float read back exactly


def scenario_toml(problem: Problem) -> str | None:
    """``problem`` as a scenario file that :func:`load_scenario` reads back to the same problem: one
    ``masses`` and ``link_length`` when every node and link share them, per-node and per-link lists
    otherwise. None if an obstacle is not a built-in shape (a Python function cannot be written down)."""
    table = problem_table(problem)
    if table is None:
        return None
    masses, lengths = table["masses"], table["link_lengths"]
    stiffness = None if problem.axial_stiffness is None else problem.axial_stiffness.tolist()
    chain: dict[str, object] = {"nodes": problem.n_nodes}
    if problem.links is not None:
        ea = stiffness or [math.inf] * len(lengths)
        chain["links"] = [
            [i, j, length, *([k] if math.isfinite(k) else [])]
            for (i, j), length, k in zip(table["links"], lengths, ea, strict=True)
        ]
    else:
        chain |= {"link_length": lengths[0]} if len(set(lengths)) == 1 else {"link_lengths": lengths}
        if stiffness is not None:
            chain |= {"axial_stiffness": stiffness[0]} if len(set(stiffness)) == 1 else {"axial_stiffnesses": stiffness}
    chain |= {"masses": masses[0]} if len(set(masses)) == 1 else {"masses": masses}
    optional = (*(("dimension",) if "dimension" in table else ()), *(("units",) if "units" in table else ()))
    keys = ("name", "formulation", "gravity", "contact", *optional)
    lines = [f"{key} = {_toml_value(table[key])}" for key in keys]
    lines += ["", "[chain]" if problem.links is None else "[net]"]
    lines += [f"{key} = {_toml_value(value)}" for key, value in chain.items()]
    for name in ("supports", "loads", "obstacles"):
        for item in table.get(name, []):
            lines += ["", f"[[{name}]]", *(f"{key} = {_toml_value(value)}" for key, value in item.items())]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------- loading
def _builtin_files() -> dict[str, Traversable]:
    from importlib.resources import files  # (here: a scenario given as a file needs none of it)

    folder = files("funicular") / "scenarios"
    found = {entry.name.removesuffix(".toml"): entry for entry in folder.iterdir() if entry.name.endswith(".toml")}
    return dict(sorted(found.items()))


def _read_toml(text: bytes, source: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError as error:
        raise ScenarioError(f"{source}: not valid UTF-8 text ({error.reason} at byte {error.start}).") from None
    except tomllib.TOMLDecodeError as error:
        raise ScenarioError(f"{source}: invalid TOML: {error}.") from None


def builtin_scenarios() -> dict[str, str]:
    """Built-in scenario names mapped to their one-line descriptions, sorted by name."""
    descriptions = {}
    for name, entry in _builtin_files().items():
        description = _read_toml(entry.read_bytes(), f"built-in scenario {name!r}").get("description", "")
        descriptions[name] = str(description)
    return descriptions


@dataclass(frozen=True)
class ScenarioDocument:
    """A scenario's parsed TOML, before validation: what sweeps edit and re-parse."""

    document: dict[str, Any]
    source: str  # for error messages
    default_name: str

    def problem(self) -> Problem:
        return _parse_from(self.document, self.source, self.default_name)


def load_document(source: str | os.PathLike[str]) -> ScenarioDocument:
    """Read a scenario (file path or built-in name) without validating it."""
    path = Path(source)
    if path.is_file():
        try:
            text = path.read_bytes()
        except OSError as error:
            raise ScenarioError(f"cannot read scenario file {str(path)!r}: {error.strerror}.") from None
        return ScenarioDocument(_read_toml(text, str(path)), str(path), path.stem)
    builtins = _builtin_files()
    if isinstance(source, str) and source in builtins:
        label = f"built-in scenario {source!r}"
        return ScenarioDocument(_read_toml(builtins[source].read_bytes(), label), label, source)
    names = ", ".join(builtins)
    if path.exists():
        raise ScenarioError(f"scenario {str(path)!r} is not a file; give a .toml file or a built-in name ({names}).")
    if path.suffix == ".toml" or len(path.parts) > 1:
        raise ScenarioError(f"scenario file {str(path)!r} does not exist.")
    raise ScenarioError(f"{str(source)!r} is neither a scenario file nor a built-in scenario; built-ins: {names}.")


def load_scenario(source: str | os.PathLike[str]) -> Problem:
    """Load a scenario from a ``.toml`` file path or by the name of a built-in scenario.

    An existing file wins over a built-in of the same name.
    """
    return load_document(source).problem()
