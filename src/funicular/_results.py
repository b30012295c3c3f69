"""Result files in three formats, one document: ``.json``, ``.npz`` and ``.parquet``.

A *document* is what :func:`funicular.checks.solution_document` builds: keys to values, nested
tables as dicts, where every long numeric list may be a numpy array. Each format stores the
same document and reads it back; what the keys mean, and their validation, is the business of
:mod:`funicular.checks._files`, never of a format.

* ``.json``: the document itself (orjson; compact, or indented), arrays written as lists,
  non-finite numbers as null. Read back with serde_json (:func:`_core.read_json`), each list of
  numbers in the dicts is an array again, as the binary formats give it (a list of booleans stays
  a list); a file serde_json does not read is read by orjson (or named as invalid).
* ``.npz``: every array of the document (:func:`split_arrays`) is an entry of its own, named by
  its key path joined with dots (``x``, ``multipliers.link``, ``problem.masses``); the rest is
  one JSON string, the entry ``metadata``, where each array's place holds ``{"$array": name}``.
* ``.parquet``: one table (snappy-compressed) with as many rows as the longest array. Each
  array at least half as long is a column (a 2-D array (n, d) gives d columns ``name[0]`` ...
  ``name[d-1]``), null from its own length on: for a chain, row i holds node i and link i (from
  node i to node i + 1), and the link columns are null in the last row. Shorter arrays stay in
  the metadata, a JSON string under the key ``funicular`` of the Arrow schema's metadata, where
  each column's place holds ``{"$array": name, "shape": [n, ...]}``. A column is written once:
  an array whose values another column holds already, bit for bit (``x`` is ``positions[0]``),
  names the columns that hold it: ``{"$array": name, "shape": [n, ...], "columns": [...]}``.

An array is a numpy array, or a non-empty list of numbers (all booleans, all integers, or
integers and floats) or of equal-length non-empty lists of numbers: a key the document gains
(``positions``, ``links``, ``z``) becomes an array or metadata by this rule, in every format.
Only dicts are searched for arrays (a list of tables, such as ``support_reactions``, is metadata).
"""

from __future__ import annotations

import importlib
import itertools
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import orjson

from funicular import _core
from funicular._extras import InstallHint
from funicular._io import atomic_write, check_writable
from funicular.errors import OutputError, ScenarioError, shown

FORMATS = (".json", ".npz", ".parquet")
METADATA = "metadata"  # the npz entry holding the document without its arrays
PARQUET_METADATA = b"funicular"  # the Arrow schema metadata key holding it in a parquet file
PLACEHOLDER = "$array"
WRITE_BATCH = 1 << 20  # rows handed to the parquet encoder at a time
INSTALL_PARQUET = InstallHint("parquet")
_MAGIC = {b"PK\x03\x04": ".npz", b"PAR1": ".parquet"}  # how each binary format starts; else JSON
_HELD = {".json": "JSON", ".npz": "an .npz archive", ".parquet": "a Parquet file"}  # (in the reader's sentences)
_KINDS = {bool: np.bool_, int: np.int64, float: np.float64}


# ----------------------------------------------------------------- choosing a format
def format_of(path: str | os.PathLike[str], option: str = "") -> str:
    """The format (".json", ".npz" or ".parquet") that ``path``'s extension names; an
    :class:`OutputError` naming ``option`` and ``path`` for any other extension."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        where = f"{option} {str(path)!r}" if option else repr(str(path))
        extension = f"extension {suffix!r}" if suffix else "no extension"
        raise OutputError(f"{where} has {extension}; give a file name ending in .json, .npz or .parquet.")
    return suffix


def check_output(path: str | os.PathLike[str], option: str = "") -> str:
    """Everything that can be checked before a solve: the extension, pyarrow for ``.parquet``, and
    that ``path`` can be written. Returns the format."""
    suffix = format_of(path, option)
    if suffix == ".parquet" and not _have_pyarrow():
        where = f"{option} {str(path)!r}" if option else repr(str(path))
        raise OutputError(f"{where}: writing .parquet needs pyarrow; install it with {INSTALL_PARQUET}.")
    check_writable(path, option)
    return suffix


def _pyarrow() -> tuple[Any, Any]:
    """pyarrow and pyarrow.parquet (an optional extra, imported only for a .parquet file)."""
    import pyarrow as pa  # type: ignore[import-untyped]
    import pyarrow.parquet as pq  # type: ignore[import-untyped]

    return pa, pq


def _have_pyarrow() -> bool:
    try:
        importlib.import_module("pyarrow.parquet")
    except ImportError:
        return False
    return True


# ----------------------------------------------------------------- arrays and metadata
def _as_array(value: object) -> np.ndarray | None:
    """``value`` as a numpy array if it is one by the module's rule, else None."""
    if isinstance(value, np.ndarray):
        return value if value.ndim >= 1 and value.dtype.kind in "biuf" else None
    if not isinstance(value, list) or not value:
        return None
    items: list[Any] = value
    if type(value[0]) is list:
        if {type(row) for row in value} != {list} or len({len(row) for row in value}) != 1 or not value[0]:
            return None
        items = list(itertools.chain.from_iterable(value))
    kinds = set(map(type, items))
    if not kinds <= _KINDS.keys() or (bool in kinds and len(kinds) > 1):
        return None
    dtype = _KINDS[float] if float in kinds else _KINDS[next(iter(kinds))]
    try:
        return np.array(value, dtype=dtype)
    except OverflowError:  # an integer beyond 64 bits: leave it to the JSON text
        return None


def split_arrays(document: dict[str, Any]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The document without its arrays (each replaced by ``{"$array": name}``), and the arrays by
    name: their key paths joined with dots, made unique if two paths join to the same name."""
    arrays: dict[str, np.ndarray] = {}

    def strip(table: dict[str, Any], prefix: str) -> dict[str, Any]:
        result: dict[str, Any] = {}
        for key, value in table.items():
            path = f"{prefix}{key}"
            if isinstance(value, dict):
                result[key] = strip(value, path + ".")
                continue
            array = _as_array(value)
            if array is None:
                result[key] = value
                continue
            name = path
            for n in itertools.count(2):
                if name != METADATA and name not in arrays:
                    break
                name = f"{path}~{n}"
            arrays[name] = array
            result[key] = {PLACEHOLDER: name}
        return result

    return strip(document, ""), arrays


def join_arrays(metadata: Any, arrays: dict[str, Any], source: str) -> Any:
    """The document whose metadata is ``metadata``: each placeholder replaced by its array (by
    the value ``arrays`` holds under its name)."""
    if isinstance(metadata, dict):
        if PLACEHOLDER in metadata:
            name = metadata[PLACEHOLDER]
            if not isinstance(name, str) or name not in arrays:
                raise ScenarioError(f"{source}: the array {shown(name)} its metadata names is not in the file.")
            return arrays[name]
        return {key: join_arrays(value, arrays, source) for key, value in metadata.items()}
    return metadata


def _placeholders(metadata: Any) -> Iterator[dict[str, Any]]:
    if isinstance(metadata, dict):
        if PLACEHOLDER in metadata:
            yield metadata
        else:
            for value in metadata.values():
                yield from _placeholders(value)


# ----------------------------------------------------------------- writing
JSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS


def _json_default(value: object) -> object:
    if isinstance(value, np.ndarray):  # one orjson does not take as it is (its dtype)
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


def _contiguous(value: Any) -> Any:
    """``value`` with every array that is a strided view (a column) copied into a contiguous one,
    which orjson takes as it is. Done before orjson runs, not in its ``default``: an exception in
    ``default`` (an interrupt's, say) comes out of orjson as a TypeError."""
    if isinstance(value, dict):
        return {key: _contiguous(item) for key, item in value.items()}
    if isinstance(value, list) and value and isinstance(value[0], (dict, list, np.ndarray)):
        return [_contiguous(item) for item in value]
    if isinstance(value, np.ndarray) and not value.flags.c_contiguous:
        return np.ascontiguousarray(value)
    return value


def _dumps(value: Any, option: int = 0) -> bytes:
    """Strict JSON: non-finite numbers as null, numpy arrays as lists (``option``: orjson's, added)."""
    return orjson.dumps(_contiguous(value), default=_json_default, option=JSON_OPTIONS | option)


def json_bytes(document: dict[str, Any], indent: bool = False) -> bytes:
    """:func:`_dumps` of ``document``, with a final newline."""
    return _dumps(document, orjson.OPT_APPEND_NEWLINE | (orjson.OPT_INDENT_2 if indent else 0))


def _write_json(stream: BinaryIO, value: Any) -> None:
    """``_dumps(value)``, the same bytes, written piece by piece: a dict with string keys key by
    key, so that at most one entry's text is in memory at a time (a million-node document's text
    is about 200 MB, and orjson builds it whole)."""
    if not (isinstance(value, dict) and value and all(type(key) is str for key in value)):
        stream.write(_dumps(value))
        return
    separator = b"{"
    for key, item in value.items():
        stream.write(separator + orjson.dumps(key) + b":")
        _write_json(stream, item)
        separator = b","
    stream.write(b"}")


def write_document(
    document: dict[str, Any],
    path: str | os.PathLike[str],
    indent: bool = False,
    option: str = "",
    suffix: str | None = None,
) -> None:
    """Write ``document`` to ``path`` in the format its extension names, or ``suffix`` (".json",
    ".npz", ".parquet") if given; ``indent``: JSON only. Atomic: an existing file keeps its
    content unless the whole new one is written."""
    suffix = suffix or format_of(path, option)
    if suffix == ".json":

        def write(stream: BinaryIO) -> None:
            if indent:
                stream.write(json_bytes(document, indent=True))
            else:  # (piece by piece)
                _write_json(stream, document)
                stream.write(b"\n")

        atomic_write(path, write)
    elif suffix == ".npz":
        metadata, arrays = split_arrays(document)
        text = np.array(json_bytes(metadata).decode())

        def savez(stream: BinaryIO) -> None:
            np.savez(stream, **{METADATA: text}, **arrays)  # type: ignore[arg-type]

        atomic_write(path, savez)
    else:
        _write_parquet(document, path, option)


class _Columns:
    """The parquet table's columns, each written once: a column whose values are already in the
    table, bit for bit (``x`` and ``positions[0]``; a norm chain's tensions and link multipliers),
    is not added again, and its array's placeholder names the column that holds it."""

    def __init__(self, pa: Any, rows: int) -> None:
        self.pa, self.rows = pa, rows
        self.table: dict[str, Any] = {}
        self._views: dict[tuple[int, int, int, str], str] = {}  # (address, stride, length, dtype): name
        self._values: dict[tuple[str, int, bytes], list[tuple[str, np.ndarray]]] = {}

    def add(self, name: str, values: np.ndarray) -> str:
        """The name of the column holding ``values`` (1-D): ``name``, added now, or an earlier one."""
        view = (values.__array_interface__["data"][0], values.strides[0], len(values), values.dtype.str)
        if view in self._views:  # the same memory (x is a view of the positions)
            return self._views[view]
        values = np.ascontiguousarray(values)
        ends = values[[0, len(values) // 2, -1]].tobytes() if len(values) else b""
        key = (values.dtype.str, len(values), ends)
        for held, earlier in self._values.get(key, []):
            if np.array_equal(earlier.view(np.uint8), values.view(np.uint8)):
                self._views[view] = held
                return held
        self._values.setdefault(key, []).append((name, values))
        self._views[view] = name
        column = self.pa.array(values)
        nulls = self.rows - len(values)
        chunks = [column] if nulls == 0 else [column, self.pa.nulls(nulls, column.type)]
        self.table[name] = self.pa.chunked_array(chunks)
        return name


def _write_parquet(document: dict[str, Any], path: str | os.PathLike[str], option: str) -> None:
    if not _have_pyarrow():
        where = f"{option} {str(path)!r}" if option else repr(str(path))
        raise OutputError(f"{where}: writing .parquet needs pyarrow; install it with {INSTALL_PARQUET}.")
    pa, pq = _pyarrow()

    metadata, arrays = split_arrays(document)
    rows = max((len(array) for array in arrays.values()), default=0)
    columns = _Columns(pa, rows)
    places: dict[str, Any] = {}
    for name, array in arrays.items():
        if 2 * len(array) <= rows:  # a short array (the supports'): JSON, not a column of nulls
            places[name] = array.tolist()
            continue
        flat = array.reshape(len(array), -1)
        names = [name] if array.ndim == 1 else [f"{name}[{c}]" for c in range(flat.shape[1])]
        held = [columns.add(column, flat[:, c]) for c, column in enumerate(names)]
        places[name] = {PLACEHOLDER: name, "shape": list(array.shape)}
        if held != names:
            places[name]["columns"] = held
    text = json_bytes(join_arrays(metadata, places, str(path)))
    table = pa.table(columns.table).replace_schema_metadata({PARQUET_METADATA: text})

    def write(stream: BinaryIO) -> None:
        # Plain encoding: solver output rarely repeats a float, so dictionaries only cost time; snappy
        # halves the file (constant masses and lengths, zero multipliers off the obstacles) for little.
        # The values reach the encoder in batches of up to WRITE_BATCH rows (pyarrow's default, 1024,
        # costs a call per batch; the pages, and the file, are the same).
        pq.write_table(table, stream, use_dictionary=False, compression="snappy", write_batch_size=WRITE_BATCH)

    atomic_write(path, write)


# ----------------------------------------------------------------- reading
def read_document(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The document a result file holds, whatever its format (told by its first bytes; a
    ``.json``, ``.npz`` or ``.parquet`` extension must agree with them). Raises
    :class:`ScenarioError` naming the file for one that cannot be read, is truncated, or holds no
    funicular document."""
    source = str(path)
    try:
        with open(path, "rb") as stream:
            head = stream.read(64)
    except OSError as error:
        raise ScenarioError(f"cannot read solution file {source!r}: {error.strerror or error}.") from None
    found = _MAGIC.get(head[:4], ".json")
    claimed = Path(path).suffix.lower()
    if claimed in FORMATS and claimed != found:
        held = _HELD.get(found) if found != ".json" or head.lstrip()[:1] in (b"{", b"[") else None
        if held is None:
            raise ScenarioError(
                f"solution file {source!r} ends in {claimed} but is not {_HELD[claimed]}; "
                "give a file funicular solve --output wrote, ending in .json, .npz or .parquet."
            )
        raise ScenarioError(
            f"solution file {source!r} ends in {claimed} but holds {held}; rename it to end in {found}, "
            "or write it again with funicular solve --output."
        )
    if found == ".npz":
        document = _read_npz(path, source)
    elif found == ".parquet":
        document = _read_parquet(path, source)
    else:
        document = _read_json(path, source)
    if not isinstance(document, dict):
        raise ScenarioError(f"{source}: a solution file must be a JSON object with x and y lists.")
    return document


def _read_json(path: str | os.PathLike[str], source: str) -> Any:
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise ScenarioError(f"cannot read solution file {source!r}: {error.strerror or error}.") from None
    document = _core.read_json(data)  # lists of numbers as arrays, as the binary formats hold them
    if document is not None:
        return document
    try:  # what serde_json does not read (NaN, say): read as lists, or named as invalid
        return orjson.loads(data)
    except orjson.JSONDecodeError:
        pass
    try:  # what orjson refuses but Python's reader takes (NaN, Infinity: then named as not finite)
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ScenarioError(f"solution file {source!r} is not valid JSON: {error}.") from None


def _not_ours(source: str, kind: str, why: str) -> ScenarioError:
    return ScenarioError(
        f"solution file {source!r} is not a {kind} file funicular wrote ({why}); "
        "write one with funicular solve --output."
    )


def _metadata(text: bytes | str, source: str, kind: str) -> dict[str, Any]:
    try:
        metadata = orjson.loads(text)
    except orjson.JSONDecodeError:
        raise _not_ours(source, kind, "its metadata is not valid JSON") from None
    if not isinstance(metadata, dict):
        raise _not_ours(source, kind, "its metadata is not a JSON object")
    if "schema_version" not in metadata:
        raise _not_ours(source, kind, "its metadata has no schema_version")
    return metadata


def _read_npz(path: str | os.PathLike[str], source: str) -> Any:
    import zipfile

    try:
        with open(path, "rb") as stream, np.load(stream, allow_pickle=False) as archive:
            if METADATA not in archive.files:
                raise _not_ours(source, ".npz", f"it has no {METADATA!r} entry")
            entry = archive[METADATA]
            if entry.dtype.kind != "U" or entry.ndim != 0:
                raise _not_ours(source, ".npz", f"its {METADATA!r} entry is not a string")
            metadata = _metadata(str(entry), source, ".npz")
            names = [p[PLACEHOLDER] for p in _placeholders(metadata)]
            arrays = {name: archive[name] for name in names if isinstance(name, str) and name in archive.files}
    except ScenarioError:
        raise
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as error:
        raise ScenarioError(
            f"cannot read solution file {source!r}: it is truncated or not an .npz ({error})."
        ) from None
    return join_arrays(metadata, arrays, source)


def _read_parquet(path: str | os.PathLike[str], source: str) -> Any:
    if not _have_pyarrow():
        raise ScenarioError(f"reading {source!r} (.parquet) needs pyarrow; install it with {INSTALL_PARQUET}.")
    pa, pq = _pyarrow()

    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as error:
        raise ScenarioError(
            f"cannot read solution file {source!r}: it is truncated or not a .parquet ({error})."
        ) from None
    text = (table.schema.metadata or {}).get(PARQUET_METADATA)
    if text is None:
        raise _not_ours(source, ".parquet", f"its schema has no {PARQUET_METADATA.decode()!r} metadata")
    metadata = _metadata(text, source, ".parquet")
    arrays: dict[str, np.ndarray] = {}
    for placeholder in _placeholders(metadata):
        name, shape = placeholder[PLACEHOLDER], placeholder.get("shape")
        if not (isinstance(name, str) and isinstance(shape, list) and shape and all(type(s) is int for s in shape)):
            raise _not_ours(source, ".parquet", f"its metadata describes the array {shown(name)} wrongly")
        rows = shape[0]
        names = [name] if len(shape) == 1 else [f"{name}[{c}]" for c in range(int(np.prod(shape[1:])))]
        held = placeholder.get("columns", names)  # (a column written once for two arrays)
        if not (isinstance(held, list) and len(held) == len(names) and all(isinstance(c, str) for c in held)):
            raise _not_ours(source, ".parquet", f"its metadata names the columns of {name!r} wrongly")
        names = held
        parts = []
        for column in names:
            if column not in table.column_names or not 0 <= rows <= table.num_rows:
                raise _not_ours(source, ".parquet", f"it has no column {column!r} of {rows} rows")
            values = table.column(column).slice(0, rows)
            if values.null_count:
                raise _not_ours(source, ".parquet", f"its column {column!r} has missing values")
            parts.append(values.to_numpy())
        arrays[name] = parts[0] if len(shape) == 1 else np.column_stack(parts).reshape(shape)
    return join_arrays(metadata, arrays, source)
