"""Output files and bad input as a first-time user meets them: symlinks, pipes and devices are
written through, a closed pipe ends quietly, every mistake is one sentence (exit 2) found before
the long work, and nothing prints a traceback or a numpy warning."""

from __future__ import annotations

import json
import math
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from funicular import InfeasibleError, Problem, ScenarioError, SolverOptions, solve
from funicular._extras import install_command
from funicular._htmlreport import write_report
from funicular._text import summary
from funicular.cli import main
from funicular.errors import ParameterError
from funicular.obstacles import Disk, Expression, depth
from funicular.scenario import load_scenario, parse_scenario


def run(*args: str, prelude: str = "") -> subprocess.CompletedProcess[str]:
    """The command line in a fresh process; ``prelude`` runs first (e.g. to hide matplotlib)."""
    code = f"import sys\n{prelude}\nfrom funicular.cli import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, check=False, timeout=120)


def one_sentence(stderr: str) -> str:
    """The error line of a run that failed on bad input (argparse adds its usage line before it)."""
    lines = [line for line in stderr.strip().splitlines() if not line.startswith(("usage:", " ", "TIMING"))]
    assert "Traceback" not in stderr and len(lines) == 1, stderr
    return lines[0]


# ----------------------------------------------------------------- where output goes
def test_json_through_a_symlink_writes_its_target_and_keeps_the_link(tmp_path: Path) -> None:
    target, link = tmp_path / "target.json", tmp_path / "link.json"
    target.write_text("old")
    link.symlink_to(target)
    assert main(["solve", "dangling", "--json", str(link)]) == 0
    assert link.is_symlink() and link.resolve() == target.resolve()
    assert len(json.loads(target.read_text())["x"]) == load_scenario("dangling").n_nodes


def test_json_into_a_fifo_writes_into_the_pipe_and_keeps_it(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()))
    reader.start()
    try:
        assert main(["solve", "dangling", "--json", str(fifo)]) == 0
    finally:
        reader.join(timeout=60)
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    assert json.loads(received[0])["status"] == "optimal"


def test_json_dash_is_standard_output_and_the_summary_goes_to_stderr() -> None:
    result = run("solve", "dangling", "--json", "-")
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert document["schema_version"] >= 2 and "support reactions" in result.stderr


def test_a_closed_pipe_ends_quietly() -> None:
    code = "import sys\nfrom funicular.cli import main\nsys.exit(main(sys.argv[1:]))"
    process = subprocess.Popen(
        [sys.executable, "-c", code, "scenarios"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert process.stdout is not None and process.stderr is not None
    process.stdout.close()  # like `| head -0`: the reader is gone before anything is written
    error = process.stderr.read()
    process.stderr.close()
    assert process.wait(timeout=120) in (0, 141)
    assert error == ""


@pytest.mark.parametrize("make", ["directory", "missing-directory"])
def test_an_unwritable_output_is_found_before_solving_and_named_as_given(tmp_path: Path, make: str) -> None:
    path = tmp_path / "adir" if make == "directory" else tmp_path / "nonexistent" / "x.json"
    if make == "directory":
        path.mkdir()
    result = run("solve", "two-supports", "--json", str(path))
    assert result.returncode == 2
    line = one_sentence(result.stderr)
    assert str(path) in line and ".tmp" not in line
    assert result.stdout == ""  # the summary comes after the solve: nothing was solved


# ----------------------------------------------------------------- the report
def test_report_without_matplotlib_names_the_extra(tmp_path: Path) -> None:
    out = tmp_path / "r.html"
    result = run("report", "two-supports", "-o", str(out), prelude="sys.modules['matplotlib'] = None")
    assert result.returncode == 2
    assert install_command("plot") in one_sentence(result.stderr)
    assert not out.exists()


def test_report_refuses_a_file_name_that_is_not_html_or_markdown(tmp_path: Path) -> None:
    out = tmp_path / "r.pdf"
    result = run("report", "two-supports", "-o", str(out))
    assert result.returncode == 2
    assert ".html" in one_sentence(result.stderr)
    assert not out.exists()


def test_report_holds_the_checkers_licq_and_second_order_verdict(tmp_path: Path) -> None:
    # seed-licq: three nodes, both links taut along one line, so their two rows are parallel (rank 1 of 2).
    out = tmp_path / "r.html"
    write_report(solve(load_scenario("seed-licq")), out, "html")
    text = out.read_text()
    assert "has no report_section" not in text
    assert "fails: rank 1 of 2 active constraints" in text and "strict local minimum" in text


# ----------------------------------------------------------------- values out of range
@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--tol", "nan"),
        ("--tol", "-1"),
        ("--tol", "inf"),
        ("--max-iterations", "0"),
        ("--nodes", "100000000"),
        ("--escape-up-to", "-1"),
        ("--escape-up-to", "5e3"),
    ],
)
def test_out_of_range_options_are_refused_at_once(option: str, value: str) -> None:
    result = run("solve", "two-supports", option, value)
    assert result.returncode == 2
    assert option in one_sentence(result.stderr) and result.stdout == ""


@pytest.mark.parametrize("value", [-1, 2.5, True, "5000"])
def test_an_escape_cap_that_is_not_a_number_of_nodes_is_refused_before_solving(value: object) -> None:
    options = SolverOptions(escape_up_to=value)  # type: ignore[arg-type]
    with pytest.raises(
        ParameterError, match=rf"^escape_up_to must be a whole number of nodes >= 0 or None, not {value!r}\.$"
    ):
        solve(load_scenario("disk-drape"), options)


def test_an_escape_cap_may_be_a_numpy_integer_or_larger_than_any_structure() -> None:
    """disk-drape (61 nodes) escapes its saddle by default; a cap of a million as numpy's integer, or
    of 10^30 (more nodes than any structure may have), runs the same escape."""
    problem = load_scenario("disk-drape")
    default = solve(problem)
    for cap in (np.int64(1_000_000), 10**30):
        np.testing.assert_array_equal(solve(problem, SolverOptions(escape_up_to=cap)).positions, default.positions)
    result = run("solve", "disk-drape", "--escape-up-to", "99999999999999999999999")
    assert result.returncode == 0 and result.stderr == "", result.stderr


def test_more_nodes_than_a_scenario_file_may_have_are_refused_by_the_api_too() -> None:
    with pytest.raises(ScenarioError, match=r"^n_nodes = 100000000 is too large"):
        load_scenario("two-supports").with_nodes(100_000_000)


@pytest.mark.parametrize("suffix", [".npz", ".parquet", ".NPZ"])
def test_json_into_a_binary_result_name_is_refused_before_solving_and_keeps_the_file(
    tmp_path: Path, suffix: str
) -> None:
    """`funicular solve ok.toml --json x.npz` wrote JSON into x.npz, which the reader then refused:
    --json names .json files (or any name but the binary formats'), checked before the solve, and
    a file already there keeps its content."""
    target = tmp_path / f"x{suffix}"
    target.write_bytes(b"previous")
    result = run("solve", "two-supports", "--json", str(target))
    assert result.returncode == 2 and result.stdout == ""
    sentence = one_sentence(result.stderr)
    assert f"--json {str(target)!r} ends in {suffix.lower()}, but --json writes JSON" in sentence
    assert "give a name ending in .json" in sentence and sentence.endswith(".")
    assert target.read_bytes() == b"previous"


def test_a_result_file_whose_content_is_not_its_extension_is_named_in_plain_words(tmp_path: Path) -> None:
    """A JSON result saved as x.npz: the checker says the name ends in .npz but the file holds JSON,
    and to rename it; a file of neither format is named as not being what its extension says."""
    written = tmp_path / "x.json"
    assert run("solve", "two-supports", "--json", str(written)).returncode == 0
    renamed = tmp_path / "x.npz"
    written.rename(renamed)
    result = run("check", "two-supports", "--solution", str(renamed))
    assert result.returncode == 2
    assert one_sentence(result.stderr) == (
        f"funicular: error: solution file {str(renamed)!r} ends in .npz but holds JSON; rename it to end in "
        ".json, or write it again with funicular solve --output."
    )
    garbage = tmp_path / "y.parquet"
    garbage.write_text("not a result")
    result = run("check", "two-supports", "--solution", str(garbage))
    assert result.returncode == 2
    assert f"{str(garbage)!r} ends in .parquet but is not a Parquet file;" in one_sentence(result.stderr)


HUGE = 10**400  # a Python int beyond any float


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"supports": []}, "supports is empty: a chain or net needs at least one support"),
        ({"supports": None}, "supports must be a list of (node, position) pairs, got None."),
        ({"supports": 5}, "supports must be a list of (node, position) pairs, got 5."),
        ({"supports": {0: (0.0, 0.0)}}, "supports must be a list of (node, position) pairs"),
        ({"obstacles": None}, "obstacles must be a list of obstacles, got None."),
        ({"obstacles": 5}, "obstacles must be a list of obstacles, got 5."),
        ({"loads": 5}, "loads must be a list of (node, force) pairs, got 5."),
        ({"mass": None, "masses": [[1.0], [2.0], [3.0]]}, "masses must have 3 entries, got an array of shape (3, 1)."),
        ({"mass": None, "masses": [HUGE, 1, 1]}, "masses must be a number or a list of 3 numbers"),
        ({"length": None, "link_lengths": [HUGE, 1]}, "link_lengths must be a number or a list of 2 numbers"),
        ({"length": None, "link_length": HUGE}, "link_length = "),
        ({"length": HUGE}, "length = "),
        ({"mass": HUGE}, "mass = "),
        ({"gravity": HUGE}, "gravity = "),
        ({"length": None, "links": [[0, HUGE, 1.0]]}, "links must be a list of [i, j, length] entries"),
    ],
    ids=lambda value: "" if isinstance(value, str) else ",".join(f"{k}" for k in value),
)
def test_problem_build_names_the_argument_numpy_would_have_choked_on(change: dict[str, object], words: str) -> None:
    """Problem.build(nodes=3, length=1, mass=1, supports=[]) raised numpy's "cannot reshape array of
    size 0"; an empty, non-list or ragged argument, or a number too large for a float, is one
    sentence naming the argument."""
    arguments: dict[str, object] = {"nodes": 3, "length": 1.0, "mass": 1.0, "supports": [(0, (0.0, 0.0))]}
    arguments.update(change)
    arguments = {key: value for key, value in arguments.items() if value is not None or key in change}
    for key in ("mass", "length"):
        if key in change and change[key] is None:
            del arguments[key]
    with pytest.raises(ScenarioError) as raised:
        Problem.build(**arguments)  # type: ignore[arg-type]
    message = str(raised.value)
    assert words in message and "\n" not in message and message.endswith(".")


TINY = """
[chain]
nodes = 5
length = 1e-200
mass = 1.0
[[supports]]
node = 0
position = [0.0, 0.0]
[[supports]]
node = -1
position = [1e-201, 0.0]
"""


def test_a_chain_too_short_for_floating_point_is_a_range_error() -> None:
    with pytest.raises(ScenarioError, match=r"chain\.length: .* between 1e-150 and 1e\+150"):
        parse_scenario(__import__("tomllib").loads(TINY))


def test_a_support_written_inside_chain_is_an_unknown_key() -> None:
    document = {"chain": {"nodes": 3, "length": 1.0, "mass": 1.0, "supports": []}}
    with pytest.raises(ScenarioError, match=r"chain\.supports is not a known key"):
        parse_scenario(document)


# ----------------------------------------------------------------- a support inside an obstacle
@pytest.mark.parametrize(("support", "deep"), [((0.01, 0.0), 0.19), ((0.0, 0.0), 0.2)])
def test_a_support_inside_a_disk_reports_how_deep_it_really_is(support: tuple[float, float], deep: float) -> None:
    problem = Problem.build(
        nodes=5, length=2.0, mass=1.0, supports=[(0, support), (-1, (1.5, 0.0))], obstacles=[Disk((0.0, 0.0), 0.2)]
    )
    with pytest.raises(InfeasibleError, match=rf"about {deep:g} deep"):
        solve(problem)


def test_depth_is_infinite_where_phi_is_positive_and_flat() -> None:
    pytest.importorskip("sympy")
    assert depth(Expression("1"), np.array([[0.3, 0.4]]))[0] == math.inf


def test_a_support_inside_a_flat_obstacle_is_named_without_a_depth() -> None:
    pytest.importorskip("sympy")
    problem = Problem.build(
        nodes=5, length=2.0, mass=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.5, 0.0))], obstacles=[Expression("1")]
    )
    with pytest.raises(InfeasibleError, match=r"is inside obstacle '[^']+'; move") as raised:
        solve(problem)
    assert "deep" not in str(raised.value)


def test_link_contact_with_a_shape_it_cannot_follow_names_the_shape_type() -> None:
    pytest.importorskip("sympy")
    problem = Problem.build(
        nodes=5,
        length=2.0,
        mass=1.0,
        supports=[(0, (0.0, 0.0)), (-1, (1.5, 0.0))],
        obstacles=[Expression("-(x**2 + (y + 3)**2) + 1")],
        contact="links",
    )
    with pytest.raises(ScenarioError, match="is of type Expression; use contact = 'nodes'"):
        solve(problem)


def test_an_undefined_graph_is_an_error_without_a_numpy_warning(recwarn: pytest.WarningsRecorder) -> None:
    pytest.importorskip("sympy")
    text = TINY.replace("1e-200", "1.5").replace("1e-201", "1.0")
    document = __import__("tomllib").loads(text + '[[obstacles]]\nshape = "graph"\nf = "-0.9 + 0.1*sqrt(x - 0.3)"\n')
    with pytest.raises(ScenarioError, match="not finite"):
        solve(parse_scenario(document))
    assert not recwarn.list


# ----------------------------------------------------------------- wording
def test_the_summary_prints_no_negative_zero_and_counts_in_the_singular() -> None:
    # One node on flat ground under a symmetric chain: no sideways contact force at all.
    text = summary(solve(load_scenario("ground")))
    assert "-0 " not in text.replace("e-0", "") and "= -0\n" not in text
    problem = Problem.build(
        nodes=3,
        length=2.2,
        mass=1.0,
        supports=[(0, (0.0, 0.0)), (-1, (2.0, 0.0))],
        obstacles=[Disk((1.0, -1.25), 1.0)],
    )
    assert "1 node touch 1 obstacle;" in summary(solve(problem))


# ----------------------------------------------------------------- JSON text
def test_json_is_compact_by_default_indented_on_request_and_strict(tmp_path: Path) -> None:
    compact, indented = tmp_path / "compact.json", tmp_path / "indented.json"
    assert main(["solve", "two-supports", "--json", str(compact)]) == 0
    assert main(["solve", "two-supports", "--json", str(indented), "--indent"]) == 0
    text = compact.read_text()
    assert text.count("\n") == 1 and indented.read_text().count("\n") > 100
    document, again = json.loads(text), json.loads(indented.read_text())
    del document["solve_seconds"], again["solve_seconds"]  # (two solves: their times differ)
    assert document == again
    # (the tensions and reactions as the solution has them, and read back by the standard library)
    solution = solve(load_scenario("two-supports"))
    np.testing.assert_array_equal(document["link_tension"], solution.link_tension)


def test_non_finite_numbers_are_written_as_null() -> None:
    from funicular._text import to_json

    text = to_json({"a": [1.0, math.nan, -math.inf], "b": np.array([math.inf, 2.0]), 3: math.nan}, indent=False)
    assert json.loads(text) == {"a": [1.0, None, None], "b": [None, 2.0], "3": None}
