"""Result files (.json, .npz, .parquet): each round-trips a solution to the same one, holds the same
document, and bad files or paths are one sentence (exit 2) with nothing half-written or clobbered."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import orjson
import pytest

from funicular import ScenarioError, load_solution, solve
from funicular._extras import install_command
from funicular._results import read_document, split_arrays, write_document
from funicular.checks import Multipliers, check, licq_of, read_solution
from funicular.checks._files import SCHEMA_VERSION, licq_block, solution_document, write_solution
from funicular.checks._report import licq_dict
from funicular.cli import main
from funicular.errors import OutputError
from funicular.model import Problem
from funicular.scenario import load_scenario
from funicular.solution import Solution

NO_PYARROW = importlib.util.find_spec("pyarrow") is None
PARQUET = pytest.param(".parquet", marks=pytest.mark.skipif(NO_PYARROW, reason="pyarrow (the parquet extra)"))
FORMATS = (".json", ".npz", PARQUET)


def _problem(kind: str) -> Any:
    if kind == "free":
        return load_scenario("two-supports").with_nodes(21)
    drape = load_scenario("disk-drape").with_nodes(31)
    return drape if kind == "disk" else dataclasses.replace(drape, contact="links")


@pytest.fixture(scope="module", params=["free", "disk", "links"])
def solution(request: pytest.FixtureRequest) -> Solution:
    result = solve(_problem(request.param))
    assert result.converged
    return result


def _plain(value: Any) -> Any:
    """A document with its arrays as lists: what the JSON file holds."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def one_sentence(stderr: str) -> str:
    lines = [line for line in stderr.strip().splitlines() if not line.startswith(("usage:", " "))]
    assert "Traceback" not in stderr and len(lines) == 1, stderr
    return lines[0]


# ----------------------------------------------------------------- round trips
@pytest.mark.parametrize("suffix", FORMATS)
def test_a_solution_reads_back_the_same(solution: Solution, suffix: str, tmp_path: Path) -> None:
    path = tmp_path / f"result{suffix}"
    write_solution(solution, path)
    back = load_solution(path)
    np.testing.assert_array_equal(back.positions, solution.positions)
    np.testing.assert_array_equal(back.link_multipliers, solution.link_multipliers)
    np.testing.assert_array_equal(back.obstacle_multipliers, solution.obstacle_multipliers)
    assert (back.status, back.iterations, back.solve_seconds) == (
        solution.status,
        solution.iterations,
        solution.solve_seconds,
    )
    np.testing.assert_array_equal(back.problem.masses, solution.problem.masses)
    np.testing.assert_array_equal(back.problem.link_lengths, solution.problem.link_lengths)
    assert back.problem.obstacles == solution.problem.obstacles and back.problem.contact == solution.problem.contact
    # The residuals are recomputed from what was read: they match the solver's own.
    assert back.kkt == solution.kkt
    assert os.listdir(tmp_path) == [path.name]


@pytest.mark.parametrize("suffix", [".npz", PARQUET])
def test_every_format_holds_the_json_document(solution: Solution, suffix: str, tmp_path: Path) -> None:
    write_solution(solution, tmp_path / "result.json")
    write_solution(solution, tmp_path / f"result{suffix}")
    reference = read_document(tmp_path / "result.json")
    document = read_document(tmp_path / f"result{suffix}")
    assert _plain(document) == _plain(reference)
    assert list(document) == list(reference) and document["schema_version"] == SCHEMA_VERSION


@pytest.mark.parametrize("suffix", FORMATS)
def test_keys_a_document_gains_flow_through_every_format(suffix: str, tmp_path: Path) -> None:
    """3-D chains and nets add positions (N x 3), links (L x 2 node pairs) and z: no format knows them."""
    rng = np.random.default_rng(7)
    n, links = 9, 14
    document: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "dimension": 3,
        "positions": rng.normal(size=(n, 3)),
        "z": rng.normal(size=n),
        "links": rng.integers(0, n, size=(links, 2)),
        "link_taut": rng.random(links) > 0.5,
        "multipliers": {"link": rng.random(links).tolist(), "obstacle": {"a.b": [0.5] * n}},
        "support_reactions": [{"node": 0, "force": [0.0, 1.0, 0.0]}],
        "licq": None,
    }
    path = tmp_path / f"net{suffix}"
    write_document(document, path)
    back = read_document(path)
    assert _plain(back) == _plain(document)
    if suffix != ".json":
        _, arrays = split_arrays(back)
        kinds = {name: array.dtype.kind for name, array in arrays.items()}
        assert kinds.items() >= {"positions": "f", "links": "i", "link_taut": "b"}.items()


def test_json_reads_as_any_json_reader_reads_it_with_its_number_lists_as_arrays(tmp_path: Path) -> None:
    text = (
        '{"x": [1, 2.5, -0.0, 1e-300], "n": [3, -4], "nested": {"rows": [[1, 2], [3, 4.5]], "flags": [true]},'
        ' "s": "caf\\u00e9 \\ud83d\\ude00 \\"q\\"", "tables": [{"force": [0.5, 1]}], "ragged": [[1], [2, 3]],'
        ' "mixed": [1, "a"], "empty": [], "none": null, "n2": [9223372036854775807]}'
    )
    path = tmp_path / "d.json"
    path.write_text(text)
    document = read_document(path)
    assert _plain(document) == json.loads(text)
    arrays = {key: (value.dtype.kind, value.shape) for key, value in split_arrays(document)[1].items()}
    assert {key: value for key, value in document.items() if isinstance(value, np.ndarray)}.keys() == {"x", "n", "n2"}
    assert arrays["x"] == ("f", (4,)) and arrays["n"] == ("i", (2,)) and arrays["nested.rows"] == ("f", (2, 2))
    # Inside lists (a list of tables) nothing is an array, as in the binary formats; nor are booleans.
    assert document["tables"] == [{"force": [0.5, 1]}] and document["nested"]["flags"] == [True]
    assert isinstance(document["ragged"], list) and isinstance(document["mixed"], list)


@pytest.mark.parametrize(
    "value",
    [
        [[1, 2], [3]],
        [1, [2, 3]],
        [[2, 3], 1],
        [[2, 3], [1, "x"], [4, 5]],
        [[1, "x"], [2, 3]],
        [[], []],
        [[[1, 2], [3, 4]], [[5, 6]]],
        [[1, 18446744073709551615]],
        [1, 2.5, "s", None, True, [1], {"k": [[1, 2]]}],
        [{"rows": [[1, 2], [3, 4]]}, {"rows": [[1.5], [2.5]]}],
    ],
)
def test_json_lists_that_are_not_tables_read_as_pythons_reader_reads_them(value: Any, tmp_path: Path) -> None:
    path = tmp_path / "d.json"
    path.write_text(json.dumps({"value": value, "table": [[1, 2], [3, 4]]}))
    document = read_document(path)
    assert json.dumps(document["value"]) == json.dumps(value)  # integers stay integers, nothing is an array
    np.testing.assert_array_equal(document["table"], np.array([[1, 2], [3, 4]]))
    assert document["table"].dtype == np.int64


@pytest.mark.parametrize(
    "text",
    ['{"x": [1, NaN]}', '{"x": [1, 1e999]}', '{"x": "\\ud800"}', '{"x": [1,]}'],
)
def test_json_that_is_not_plain_is_read_as_before(text: str, tmp_path: Path) -> None:
    path = tmp_path / "d.json"
    path.write_text(text)
    try:  # the readers of lists: orjson, then Python's for what orjson refuses
        expected: Any = orjson.loads(text)
    except orjson.JSONDecodeError:
        try:
            expected = json.loads(text)
        except json.JSONDecodeError:
            with pytest.raises(ScenarioError, match="is not valid JSON"):
                read_document(path)
            return
    assert json.dumps(read_document(path)) == json.dumps(expected)  # lists, as those readers give them (NaN too)


def test_npz_and_parquet_are_plain_tables_outside_funicular(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    result = solve(_problem("disk"))
    write_solution(result, tmp_path / "r.npz")
    write_solution(result, tmp_path / "r.parquet")
    with np.load(tmp_path / "r.npz") as archive:
        np.testing.assert_array_equal(archive["x"], result.x)
        np.testing.assert_array_equal(archive["multipliers.obstacle.disk"], result.obstacle_multipliers[0])
        assert json.loads(str(archive["metadata"]))["status"] == "optimal"
    table = pq.read_table(tmp_path / "r.parquet")
    assert table.num_rows == result.problem.n_nodes
    np.testing.assert_array_equal(table.column("y").to_numpy(), result.y)
    np.testing.assert_array_equal(table.column("contact_forces[1]").to_numpy(), result.contact_forces[:, 1])
    tension = table.column("link_tension")
    assert tension.null_count == 1 and tension[result.problem.n_links].as_py() is None  # the last row: no link
    assert json.loads(table.schema.metadata[b"funicular"])["schema_version"] == SCHEMA_VERSION


@pytest.mark.parametrize("name", ["disk", "free"])
def test_compact_json_is_written_as_orjson_writes_the_whole_document(name: str, tmp_path: Path) -> None:
    result = solve(_problem(name))
    document = solution_document(result)
    document["extra"] = {"1": [1.5, math.nan], "": {}, "strided": np.arange(12.0).reshape(6, 2)[:, 1]}
    write_document(document, tmp_path / "r.json")
    whole = orjson.dumps(
        json.loads(json.dumps(document, default=lambda a: a.tolist())),  # plain Python values
        option=orjson.OPT_APPEND_NEWLINE,
    )
    assert (tmp_path / "r.json").read_bytes() == whole


def test_parquet_writes_each_column_once(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    result = solve(_problem("disk"))  # norm formulation: each link's multiplier is its tension
    path = tmp_path / "r.parquet"
    write_solution(result, path)
    table = pq.read_table(path)
    metadata = json.loads(table.schema.metadata[b"funicular"])
    assert "positions[0]" not in table.column_names and "multipliers.link" not in table.column_names
    assert metadata["positions"]["columns"] == ["x", "y"]
    assert metadata["multipliers"]["link"]["columns"] == ["link_tension"]
    back = load_solution(path)
    np.testing.assert_array_equal(back.positions, result.positions)
    np.testing.assert_array_equal(back.link_multipliers, result.link_multipliers)


def test_a_version_3_parquet_file_with_every_column_reads_back(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    result = solve(_problem("disk"))
    path = tmp_path / "r.parquet"
    write_solution(result, path)
    table = pq.read_table(path)
    metadata = json.loads(table.schema.metadata[b"funicular"])
    metadata["schema_version"] = 3  # the layout before: each array its own columns, no "columns" key
    for name, place in [("positions", metadata["positions"]), ("multipliers.link", metadata["multipliers"]["link"])]:
        for c, column in enumerate(place.pop("columns")):
            own = name if len(place["shape"]) == 1 else f"{name}[{c}]"
            table = table.append_column(own, table.column(column))
    old = table.replace_schema_metadata({b"funicular": json.dumps(metadata).encode()})
    pq.write_table(old, path)
    assert "positions[1]" in old.column_names
    back = load_solution(path)
    np.testing.assert_array_equal(back.positions, result.positions)
    np.testing.assert_array_equal(back.link_multipliers, result.link_multipliers)


def test_parquet_metadata_naming_columns_wrongly_is_one_sentence(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    path = tmp_path / "r.parquet"
    write_solution(solve(_problem("disk")), path)
    table = pq.read_table(path)
    metadata = json.loads(table.schema.metadata[b"funicular"])
    metadata["positions"]["columns"] = ["x"]  # one column for an (N, 2) array
    spoiled = table.replace_schema_metadata({b"funicular": json.dumps(metadata).encode()})
    pq.write_table(spoiled, path)
    with pytest.raises(ScenarioError, match=r"names the columns of 'positions' wrongly"):
        load_solution(path)


# ----------------------------------------------------------------- the LICQ block of large chains
def test_the_licq_proof_agrees_with_the_singular_values(monkeypatch: pytest.MonkeyPatch) -> None:
    result = solve(_problem("disk"))
    licq = licq_of(result)
    assert licq is not None and licq.holds
    exact = licq_dict(licq)
    monkeypatch.setattr("funicular.checks._files.EXACT_LICQ_UP_TO", 0)
    proven = licq_block(result)
    assert proven is not None and proven["sigma_min"] is None
    assert 0 < proven["sigma_min_above"] <= exact["sigma_min"]
    for key in ("holds", "rank", "active_constraints", "dependencies", "jacobian"):
        assert proven[key] == exact[key]


def test_without_a_proof_the_licq_block_is_computed(monkeypatch: pytest.MonkeyPatch) -> None:
    result = solve(load_scenario("seed-licq"))  # LICQ fails: no proof of independence exists
    monkeypatch.setattr("funicular.checks._files.EXACT_LICQ_UP_TO", 0)
    block, licq = licq_block(result), licq_of(result)
    assert licq is not None and block == licq_dict(licq)
    assert block is not None and not block["holds"]


def _dense_licq(solution: Solution) -> tuple[int, int, float]:
    """Count, rank and smallest singular value of the active rows (force units, over the free
    coordinates), assembled here from the positions and factored by a dense SVD."""
    problem, positions = solution.problem, solution.positions
    tol = 1e-6 * float(problem.link_lengths.max())
    free = problem.free_nodes
    column = {int(node): c for c, node in enumerate(free)}
    rows = []
    for k in range(problem.n_links):
        delta = positions[k] - positions[k + 1]
        if np.linalg.norm(delta) >= problem.link_lengths[k] - tol:
            row = np.zeros((free.size, 2))
            for node, sign in ((k, 1.0), (k + 1, -1.0)):
                if node in column:
                    row[column[node]] = sign * delta / np.linalg.norm(delta)
            rows.append(row.ravel())
    for obstacle in problem.obstacles:
        phi, gradient, _ = obstacle.evaluate(positions[free])
        for c in np.flatnonzero(phi / np.linalg.norm(gradient, axis=1) >= -tol):
            row = np.zeros((free.size, 2))
            row[c] = gradient[c] / np.linalg.norm(gradient[c])
            rows.append(row.ravel())
    singular = np.linalg.svd(np.array(rows), compute_uv=False)
    singular = np.concatenate([singular, np.zeros(max(len(rows) - singular.size, 0))])
    return len(rows), int(np.sum(singular > 1e-8)), float(singular.min())


def test_above_the_exact_limit_the_licq_proof_agrees_with_a_dense_svd(monkeypatch: pytest.MonkeyPatch) -> None:
    result = solve(load_scenario("disk-drape").with_nodes(120))  # 236 free coordinates: the banded proof
    count, rank, sigma_min = _dense_licq(result)
    assert count > result.problem.n_links  # links and contacts
    monkeypatch.setattr("funicular.checks._files.EXACT_LICQ_UP_TO", 0)
    block = licq_block(result)
    assert block is not None and block["sigma_min"] is None
    assert sigma_min > block["sigma_min_above"]
    assert (block["holds"], block["rank"], block["active_constraints"]) == (True, rank, count)


def test_a_dependent_active_set_above_the_exact_limit_is_found_dependent(monkeypatch: pytest.MonkeyPatch) -> None:
    result = solve(load_scenario("taut").with_nodes(80))  # straight and taut: one pre-tension is free
    count, rank, sigma_min = _dense_licq(result)
    assert rank == count - 1 and sigma_min < 1e-12
    monkeypatch.setattr("funicular.checks._files.EXACT_LICQ_UP_TO", 0)
    block = licq_block(result)
    assert block is not None and "sigma_min_above" not in block
    assert (block["holds"], block["rank"], block["active_constraints"]) == (False, rank, count)
    assert block["sigma_min"] == pytest.approx(sigma_min, abs=1e-10)
    assert len(block["dependencies"]) == 1


# ----------------------------------------------------------------- the command line
@pytest.mark.parametrize("suffix", [".npz", PARQUET])
def test_check_reads_what_solve_wrote(suffix: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / f"r{suffix}"
    assert main(["solve", "disk-drape", "--nodes", "31", "--output", str(path)]) == 0
    assert f"wrote {path}" in capsys.readouterr().out
    assert main(["check", "disk-drape", "--nodes", "31", "--solution", str(path)]) == 0
    assert f"checking {path} (with multipliers)" in capsys.readouterr().out


def test_json_stays_json_whatever_the_extension_but_a_binary_formats(tmp_path: Path) -> None:
    """--json writes JSON into any name but one ending in .npz or .parquet (which the reader would
    then refuse: those are refused before the solve)."""
    path = tmp_path / "r.txt"
    assert main(["solve", "dangling", "--json", str(path)]) == 0
    assert json.loads(path.read_text())["schema_version"] == SCHEMA_VERSION
    assert main(["solve", "dangling", "--json", str(tmp_path / "r.npz")]) == 2
    assert not (tmp_path / "r.npz").exists()


@pytest.mark.parametrize(
    ("name", "needle"),
    [("r.txt", "extension '.txt'"), ("r", "no extension"), ("adir.npz", "is a directory"), ("no/r.npz", "not exist")],
)
def test_a_bad_output_path_is_refused_before_solving(
    name: str, needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "adir.npz").mkdir()
    path = tmp_path / name
    assert main(["solve", "two-supports", "--output", str(path)]) == 2
    captured = capsys.readouterr()
    line = one_sentence(captured.err)
    assert "--output" in line and str(path) in line and needle in line
    assert captured.out == ""  # the summary comes after the solve: nothing was solved
    assert sorted(os.listdir(tmp_path)) == ["adir.npz"]


@pytest.mark.skipif(os.name == "nt" or os.geteuid() == 0, reason="POSIX permissions, not root")
def test_a_read_only_directory_is_refused_before_solving(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    tmp_path.chmod(0o500)
    try:
        assert main(["solve", "two-supports", "--output", str(tmp_path / "r.parquet")]) == 2
    finally:
        tmp_path.chmod(0o700)
    assert "not writable" in one_sentence(capsys.readouterr().err)


def test_parquet_without_pyarrow_names_the_extra(tmp_path: Path) -> None:
    prelude = "sys.modules['pyarrow'] = None\nsys.modules['pyarrow.parquet'] = None"
    code = f"import sys\n{prelude}\nfrom funicular.cli import main\nsys.exit(main(sys.argv[1:]))"
    path = tmp_path / "r.parquet"
    result = subprocess.run(
        [sys.executable, "-c", code, "solve", "two-supports", "--output", str(path)],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert result.returncode == 2 and result.stdout == ""
    assert install_command("parquet") in one_sentence(result.stderr)
    assert not path.exists()


@pytest.mark.parametrize("suffix", FORMATS)
def test_a_failing_write_keeps_the_existing_file(
    suffix: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / f"r{suffix}"
    path.write_bytes(b"the previous result")

    def full(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    target = {
        ".json": "funicular._results._write_json",
        ".npz": "numpy.savez",
        ".parquet": "pyarrow.parquet.write_table",
    }
    if suffix == ".parquet":
        pytest.importorskip("pyarrow.parquet")
    monkeypatch.setattr(target[suffix], full)
    assert main(["solve", "dangling", "--output", str(path)]) == 2
    assert "No space left" in one_sentence(capsys.readouterr().err)
    assert path.read_bytes() == b"the previous result" and os.listdir(tmp_path) == [path.name]


# ----------------------------------------------------------------- bad files
def _truncated(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _newer(path: Path) -> None:
    document = read_document(path)
    document["schema_version"] = SCHEMA_VERSION + 1
    write_document(document, path)


def _foreign(path: Path) -> None:
    if path.suffix == ".npz":
        np.savez(path, x=np.zeros(3))
    elif path.suffix == ".parquet":
        pa = pytest.importorskip("pyarrow")
        pytest.importorskip("pyarrow.parquet").write_table(pa.table({"x": [0.0, 1.0]}), path)
    else:
        path.write_text('{"schema_version": "two", "x": []}')


@pytest.mark.parametrize("suffix", FORMATS)
@pytest.mark.parametrize(
    ("spoil", "needle"),
    [
        (_truncated, "solution file"),
        (_newer, f"schema_version {SCHEMA_VERSION + 1} is newer"),
        (_foreign, ""),
    ],
)
def test_a_bad_file_is_one_sentence(
    suffix: str, spoil: Any, needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / f"r{suffix}"
    write_solution(solve(_problem("free")), path)
    spoil(path)
    with pytest.raises(ScenarioError, match=str(path)):
        load_solution(path)
    assert main(["check", "two-supports", "--nodes", "21", "--solution", str(path)]) == 2
    line = one_sentence(capsys.readouterr().err)
    assert line.startswith("funicular: error:") and str(path) in line and needle in line


@pytest.mark.parametrize("suffix", FORMATS)
def test_another_scenarios_file_is_named_as_such(
    suffix: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / f"dangling{suffix}"
    write_solution(solve(load_scenario("dangling")), path)
    assert main(["check", "two-supports", "--solution", str(path)]) == 2
    assert "is it a solution of this scenario?" in one_sentence(capsys.readouterr().err)


def test_content_and_extension_must_agree(tmp_path: Path) -> None:
    path = tmp_path / "r.parquet"
    write_solution(solve(_problem("free")), tmp_path / "r.npz")
    (tmp_path / "r.npz").rename(path)
    with pytest.raises(ScenarioError, match=r"ends in \.parquet but holds an \.npz archive; rename it to end in \.npz"):
        load_solution(path)


def test_an_unknown_extension_is_refused_by_the_api_too(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match=r"\.json, \.npz or \.parquet"):
        write_solution(solve(_problem("free")), tmp_path / "r.csv")
    assert os.listdir(tmp_path) == []


def test_non_finite_numbers_survive_the_binary_formats(tmp_path: Path) -> None:
    document = {"schema_version": SCHEMA_VERSION, "x": np.array([0.0, math.nan, math.inf]), "nodes": 3}
    for suffix in (".npz",) if NO_PYARROW else (".npz", ".parquet"):
        write_document(document, tmp_path / f"d{suffix}")
        back = read_document(tmp_path / f"d{suffix}")
        np.testing.assert_array_equal(back["x"], document["x"])


# ----------------------------------------------------------------- nets and 3-D chains
@pytest.fixture(scope="module", params=["net-over-sphere", "chain-around-post"])
def spatial(request: pytest.FixtureRequest) -> Solution:
    result = solve(load_scenario(request.param))
    assert result.converged and result.problem.dimension == 3
    return result


@pytest.mark.parametrize("suffix", FORMATS)
def test_a_net_or_3d_chain_reads_back_the_same(spatial: Solution, suffix: str, tmp_path: Path) -> None:
    path = tmp_path / f"result{suffix}"
    write_solution(spatial, path)
    back = load_solution(path)
    assert back.problem.dimension == 3 and back.problem.is_chain == spatial.problem.is_chain
    np.testing.assert_array_equal(back.problem.link_nodes, spatial.problem.link_nodes)
    np.testing.assert_array_equal(back.positions, spatial.positions)
    np.testing.assert_array_equal(back.link_multipliers, spatial.link_multipliers)
    np.testing.assert_array_equal(back.obstacle_multipliers, spatial.obstacle_multipliers)
    assert back.status == spatial.status
    assert back.kkt == spatial.kkt  # recomputed from what was read


def test_the_licq_block_of_a_net_is_its_statics(spatial: Solution) -> None:
    block = licq_block(spatial)
    assert block is not None
    assert set(block) == {
        "holds",
        "rank",
        "active_constraints",
        "degree_of_indeterminacy",
        "mfcq",
        "unique_with_stiffness",
        "self_stress",
        "force_ranges",
    }
    # Every taut link is active (and every contact): at least as many as the taut links.
    assert block["active_constraints"] >= int(spatial.link_taut.sum())
    assert block["degree_of_indeterminacy"] == block["active_constraints"] - block["rank"]


def test_the_licq_block_of_three_strings_is_indeterminate_to_degree_one() -> None:
    """A unit weight on three taut strings of length 1 from (-0.6, 0.8), (0, 1), (0.6, 0.8): the
    middle string's tension T1 and the outer ones' T satisfy 2 (0.8) T + T1 = 1, one free parameter."""
    problem = Problem.build(
        nodes=4,
        links=[[0, 3, 1.0], [1, 3, 1.0], [2, 3, 1.0]],
        supports=[(0, (-0.6, 0.8)), (1, (0.0, 1.0)), (2, (0.6, 0.8))],
        masses=[0.0, 0.0, 0.0, 1.0],
        gravity=1.0,
    )
    block = licq_block(solve(problem))
    assert block is not None and block["holds"] is False and block["degree_of_indeterminacy"] == 1
    np.testing.assert_allclose(block["force_ranges"]["link 1"], [0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(block["force_ranges"]["link 0"], [0.0, 1 / 1.6], atol=1e-9)


def test_a_point_given_as_positions_rows_is_read(tmp_path: Path) -> None:
    """A point written by another program may hold ``positions`` (N rows of 3) instead of x, y, z."""
    problem = load_scenario("chain-around-post")
    result = solve(problem)
    path = tmp_path / "point.json"
    path.write_text(json.dumps({"positions": result.positions.tolist()}))
    positions, multipliers = read_solution(problem, path)
    np.testing.assert_array_equal(positions, result.positions)
    assert multipliers is None
    rows = result.positions.tolist()
    rows[5][2] = "high"
    path.write_text(json.dumps({"positions": rows}))
    with pytest.raises(ScenarioError, match=r"positions\[5\]\[2\] = 'high' is not a finite number"):
        read_solution(problem, path)


def test_a_3d_support_moved_is_named_with_three_coordinates(tmp_path: Path) -> None:
    problem = load_scenario("chain-around-post")
    result = solve(problem)
    path = tmp_path / "r.json"
    write_solution(result, path)
    document = read_document(path)
    document["z"][0] = 0.25  # node 0 is the support at (0, 0, 0)
    write_document(document, path)
    moved = r"node 0 is a support at \(0, 0, 0\).*0\.25 away \(offset \(0, 0, 0\.25\)\)"
    with pytest.raises(ScenarioError, match=moved):
        read_solution(problem, path)


def test_a_3d_chains_saved_result_is_checked_with_its_statics(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    problem = load_scenario("chain-around-post")
    result = solve(problem)
    path = tmp_path / "r.npz"
    write_solution(result, path)
    assert main(["check", "chain-around-post", "--solution", str(path)]) == 0
    out = capsys.readouterr().out
    assert "a KKT point" in out and "LICQ              holds" in out and "statically determinate" in out
    # The file's point read back is the one checked: the same report from the positions in memory.
    direct = check(problem, result.positions, Multipliers(result.link_multipliers, result.obstacle_multipliers))
    assert direct.licq is not None and direct.second_order is not None
    assert f"rank {direct.licq.rank} of {direct.licq.active_constraints}" in out
    assert f"second order      {direct.second_order.verdict}" in out
