"""``funicular serve``: the explorer's domain layer (state -> problem -> solve -> JSON, then the
checks of that answer) for planar chains, nets, chains in space and chains with point loads, its
scenario files, the command without its extra, the 3-D view's one script, the server's answers over
HTTP, and the page itself in a real browser (Debian's chromium driven by Playwright; skipped, with
the reason, when either is missing)."""

from __future__ import annotations

import copy
import importlib.util
import json
import re
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from browser import chromium, coloured_share, readout_log, record_readout, settle
from funicular import Problem, ScenarioError, load_scenario, solve
from funicular._extras import install_command
from funicular._static import VIEW3D, view3d_script
from funicular.checks import check_solution
from funicular.cli import main
from funicular.explorer._state import (
    MAX_NODES,
    check_state,
    scenarios,
    served_entry,
    solve_state,
    state_of_scenario,
    toml_of_state,
)
from funicular.scenario import builtin_scenarios, load_document, parse_scenario


def _point(answer: dict[str, Any]) -> dict[str, Any]:
    """The point the page sends back for the checks of ``answer``: its positions and multipliers, as
    JSON carries them."""
    point = {
        "positions": answer["positions"],
        "multipliers": {"link": answer["multiplier"], "obstacle": answer["obstacle_multiplier"]},
    }
    loaded: dict[str, Any] = json.loads(json.dumps(point))
    return loaded


def _checked(state: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """What the page shows of ``state``: the solve's answer, then the checks of the point it found."""
    answer = solve_state(state)
    return answer, check_state(state, _point(answer))


def test_a_moved_support_solves_as_the_same_problem_built_independently() -> None:
    state = state_of_scenario("two-supports")
    state["supports"][1]["position"] = [1.2, 0.1]
    answer = solve_state(state)
    problem = Problem.build(nodes=51, length=1.5, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.2, 0.1))])
    expected = solve(problem)
    assert answer["status"] == "optimal"
    assert answer["energy"] == pytest.approx(expected.objective, rel=1e-12)
    assert answer["max_tension"] == pytest.approx(expected.link_tension.max(), rel=1e-10)
    warm = solve_state(state, start=answer["positions"])
    assert warm["energy"] == pytest.approx(expected.objective, rel=1e-9)
    json.dumps(answer, allow_nan=False)  # what the page receives is plain JSON


def test_licq_fails_in_words_and_the_squared_multipliers_differ_while_the_tensions_agree() -> None:
    licq = _checked(state_of_scenario("seed-licq"))[1]["licq"]
    assert licq["holds"] is False and "fails" in licq["text"] and "not unique" in licq["text"]
    state = state_of_scenario("two-supports")
    norm, checks = _checked(state)
    squared, squared_checks = _checked({**state, "formulation": "squared"})
    assert checks["licq"]["holds"] is True and checks["second_order"]["verdict"] == "strict local minimum"
    assert squared_checks["second_order"]["verdict"] == "strict local minimum"  # (its multipliers, taken back)
    np.testing.assert_allclose(squared["tension"], norm["tension"], rtol=1e-7)
    assert not np.allclose(squared["multiplier"], norm["multiplier"], rtol=1e-3)


def test_a_long_chains_second_order_is_proven_by_the_cheap_test() -> None:
    state = state_of_scenario("two-supports")
    state["chain"] = {"nodes": 2000, "length": 1.5, "mass": 1.0}
    second = _checked(state)[1]["second_order"]
    assert second["verdict"] == "strict local minimum" and "penalty" in second["reason"]


def test_the_answer_is_the_picture_and_the_checks_are_of_the_point_sent_back() -> None:
    state = state_of_scenario("net-over-sphere")
    answer = solve_state(state)
    assert {"positions", "energy", "tension", "reactions", "contacts", "kkt"} <= set(answer)
    assert "licq" not in answer and "second_order" not in answer  # (the picture does not wait for them)
    assert set(answer["obstacle_multiplier"]) == {o["name"] for o in state["obstacles"]}
    assert set(check_state(state, _point(answer))) == {"licq", "second_order"}
    # The checks are of the point sent, not of a solve of their own: the same positions with every
    # multiplier halved no longer balance the weight (not a KKT point).
    point = _point(answer)
    point["multipliers"]["link"] = [0.5 * m for m in point["multipliers"]["link"]]
    assert check_state(state, point)["second_order"]["verdict"] == "undecided"


def test_a_nets_verdict_is_the_cheap_tests_and_agrees_with_the_checks_curvature() -> None:
    # net-over-sphere: 396 free nodes in space; the penalty test proves the minimum, and funicular
    # check computes the curvature, positive.
    state = state_of_scenario("net-over-sphere")
    _, checks = _checked(state)
    assert checks["second_order"]["verdict"] == "strict local minimum"
    assert "penalty" in checks["second_order"]["reason"]  # (the cheap test decided it)
    report = check_solution(solve(load_scenario("net-over-sphere")))
    assert report.second_order is not None and report.second_order.verdict == "strict local minimum"
    assert report.second_order.min_eigenvalue > 0


@pytest.mark.parametrize(
    ("point", "needle"),
    [
        ([1, 2], "must be a JSON object"),
        ({"positions": [[0.0, 0.0, 0.0]] * 3, "multipliers": {"link": []}}, "positions has 3 rows"),
        ("two-supports", "positions must be a list of 400 [x, y, z] rows"),
        ("no multipliers", "multipliers is missing"),
        ("short links", "link has 1 entries, but the scenario has 760 links"),
        ("bad obstacle", "no entry for obstacle 'sphere'"),
    ],
)
def test_a_point_of_another_shape_is_one_sentence(point: object, needle: str) -> None:
    state = state_of_scenario("net-over-sphere")
    if isinstance(point, str):
        answer = _point(solve_state(state))
        point = {
            "two-supports": _point(solve_state(state_of_scenario("two-supports"))),
            "no multipliers": {"positions": answer["positions"]},
            "short links": {**answer, "multipliers": {"link": [1.0], "obstacle": {}}},
            "bad obstacle": {**answer, "multipliers": {**answer["multipliers"], "obstacle": {}}},
        }[point]
    with pytest.raises(ScenarioError) as error:
        check_state(state, point)
    message = str(error.value)
    assert needle in message and "\n" not in message and message.endswith((".", "?")), message


def test_a_served_file_is_named_by_its_file_name_even_where_a_built_in_shares_its_name(tmp_path: Path) -> None:
    assert served_entry("box-edge") == {"builtin": "box-edge", "file": None}
    path = tmp_path / "two-supports"  # (a file wins over the built-in of the same name)
    path.write_text("[chain]\nnodes = 5\nlength = 1.5\nmass = 1.0\n", encoding="utf-8")
    assert served_entry(str(path)) == {"builtin": None, "file": "two-supports"}
    assert served_entry(str(tmp_path / "two-supports")) != served_entry("two-supports")


@pytest.mark.parametrize(
    ("state", "start", "needle"),
    [
        (None, None, "must be a JSON object"),
        ([1, 2], None, "must be a JSON object"),
        ({"supports": []}, None, "supports is empty"),
        ({"chain": {"nodes": MAX_NODES + 1, "length": 1, "mass": 1}}, None, "too large"),
        ({"chain": {"nodes": "many"}}, None, "chain.nodes must be"),
        ({"formulation": "cubic"}, None, "formulation"),
        ({"colour": "red"}, None, "colour is not a known key"),
        ({}, [[0, "a"]], "start must be"),
        ({}, [1, 2, 3], "start must be"),
    ],
)
def test_malformed_states_are_one_sentence_scenario_errors(state: object, start: object, needle: str) -> None:
    if isinstance(state, dict):
        state = {**state_of_scenario("two-supports"), **state}
    with pytest.raises(ScenarioError) as error:
        solve_state(state, start)
    message = str(error.value)
    assert needle in message and "\n" not in message and message.endswith(".")


@pytest.mark.parametrize("name", ["disk-drape", "box-edge", "uneven-supports", "three-supports"])
def test_a_saved_scenario_reads_back_to_the_same_energy(name: str, tmp_path: Path) -> None:
    state = state_of_scenario(name)
    state["supports"][0]["position"] = [state["supports"][0]["position"][0] - 0.05, 0.02]
    state["formulation"] = "squared"
    path = tmp_path / "saved.toml"
    path.write_text(toml_of_state(state), encoding="utf-8")
    again = solve(load_scenario(path))
    assert again.problem.formulation.value == "squared"
    assert again.objective == pytest.approx(solve_state(state)["energy"], rel=1e-12)


# ----------------------------------------------------------------- nets, chains in space, point loads
def test_every_built_in_can_be_loaded_including_nets_and_chains_in_space() -> None:
    assert set(scenarios()) == set(builtin_scenarios())
    for name in ("net-over-sphere", "hanging-model", "chain-around-post"):
        assert state_of_scenario(name)["name"] == name


def test_a_symmetric_net_carries_its_weight_in_four_equal_reactions_and_the_contacts() -> None:
    state = state_of_scenario("net-over-sphere")  # a square grid hung from its corners over a centred sphere
    state["gravity"], state["net"]["mass"] = 2.5, 0.8
    answer = solve_state(state)
    assert answer["status"] == "optimal" and answer["dimension"] == 3
    weight = state["net"]["mass"] * state["gravity"]
    reactions = np.array([r["force"] for r in answer["reactions"]])
    contacts = np.array([c["force"] for c in answer["contacts"]])
    assert len(reactions) == 4 and len(contacts) > 0
    np.testing.assert_allclose(reactions.sum(axis=0) + contacts.sum(axis=0), [0.0, 0.0, weight], atol=1e-8 * weight)
    # The corners of the unit square: the same lift, and the same horizontal pull away from the middle
    # (a support holds the sagging net back), along the diagonal.
    np.testing.assert_allclose(reactions[:, 2], reactions[0, 2], rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(reactions[:, :2], axis=1), np.linalg.norm(reactions[0, :2]), rtol=1e-6)
    corners = np.array([answer["positions"][r["node"]][:2] for r in answer["reactions"]])
    inward = np.array([0.5, 0.5]) - corners
    across = reactions[:, 0] * inward[:, 1] - reactions[:, 1] * inward[:, 0]
    np.testing.assert_allclose(across, 0.0, atol=1e-8 * weight)
    assert np.all(np.einsum("ij,ij->i", reactions[:, :2], inward) < 0)
    checks = check_state(state, _point(answer))
    assert checks["licq"]["holds"] is True and "statically determinate" in checks["licq"]["text"]
    assert checks["second_order"]["verdict"] == "strict local minimum"
    assert len(answer["links"]) == len(answer["tension"]) == 2 * 20 * 19
    json.dumps(answer, allow_nan=False)


def test_a_chain_in_a_vertical_plane_has_the_planar_chains_energy() -> None:
    # Supports 1 apart horizontally along the direction (0.6, 0.8), the second 0.25 lower.
    state = {
        "dimension": 3,
        "gravity": 1.0,
        "chain": {"nodes": 31, "length": 1.4, "mass": 1.0},
        "supports": [{"node": 0, "position": [0.1, 0.2, 0.0]}, {"node": -1, "position": [0.7, 1.0, -0.25]}],
    }
    answer = solve_state(state)
    planar = solve(
        Problem.build(nodes=31, length=1.4, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0)), (-1, (1.0, -0.25))])
    )
    assert answer["status"] == "optimal"
    assert answer["energy"] == pytest.approx(planar.objective, rel=1e-9)
    assert answer["max_tension"] == pytest.approx(planar.link_tension.max(), rel=1e-7)
    # Every node stays in the supports' vertical plane: (x - 0.1, y - 0.2) is along (0.6, 0.8).
    positions = np.array(answer["positions"])
    np.testing.assert_allclose(0.8 * (positions[:, 0] - 0.1) - 0.6 * (positions[:, 1] - 0.2), 0.0, atol=1e-9)
    warm = solve_state(state, start=answer["positions"])
    assert warm["energy"] == pytest.approx(planar.objective, rel=1e-9)
    other = solve_state(state, start=[[0.0, 0.0]] * 31)  # a planar start: another shape, ignored
    assert other["energy"] == pytest.approx(planar.objective, rel=1e-9)


def test_a_point_load_is_carried_by_the_supports_of_a_planar_chain() -> None:
    state = state_of_scenario("two-supports")  # 51 nodes, mass 1, gravity 1, supports (0, 0) and (1, 0)
    state["loads"] = [{"node": 25, "force": [0.0, -0.5]}]
    answer, checks = _checked(state)
    reactions = np.array([r["force"] for r in answer["reactions"]])
    # By symmetry each support lifts half of the weight and the load.
    np.testing.assert_allclose(reactions[:, 1], [0.75, 0.75], rtol=1e-8)
    np.testing.assert_allclose(reactions[0, 0], -reactions[1, 0], rtol=1e-8)
    assert answer["loads"] == [{"node": 25, "force": [0.0, -0.5]}]
    assert checks["licq"]["holds"] is True and "statically determinate" in checks["licq"]["text"]
    assert checks["second_order"]["verdict"] == "strict local minimum"


def test_a_taut_chain_in_space_between_aligned_supports_is_statically_indeterminate() -> None:
    # Two links of 1 between supports 2 apart vertically: a straight taut line, so one tension can be
    # added to both links and carried by the supports alone (degree of indeterminacy 1).
    state = {
        "dimension": 3,
        "chain": {"nodes": 3, "length": 2.0, "mass": 1.0},
        "supports": [{"node": 0, "position": [0.0, 0.0, 0.0]}, {"node": -1, "position": [0.0, 0.0, -2.0]}],
    }
    licq = _checked(state)[1]["licq"]
    assert licq["holds"] is False and "indeterminate to degree 1" in licq["text"] and licq["text"].endswith(".")


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        (lambda s: s["net"].update(grid=[50, 50]), "net.grid = [50, 50] makes 2500 nodes"),
        (lambda s: s["net"].update(grid=[1, 5]), "net.grid = [1, 5] has fewer than 2 rows or columns"),
        (lambda s: s["obstacles"][0].update(radius=-0.3), "obstacles[0].radius"),
        (lambda s: s["net"].update(mesh="net.obj"), "net.mesh"),
        (lambda s: s["net"].update(slack="loose"), "net.slack"),
        (lambda s: s.update(net={"radial": {"rings": 100, "spokes": 30}, "slack": 1.2}), "1 + rings x spokes"),
        (lambda s: s.update(supports=[{"node": 0, "position": [0.0, 0.0, 0.0]}]), "supports"),
    ],
)
def test_malformed_net_states_are_one_sentence_scenario_errors(change: Any, needle: str) -> None:
    state = state_of_scenario("net-over-sphere")
    change(state)
    with pytest.raises(ScenarioError) as error:
        solve_state(state)
    message = str(error.value)
    assert needle in message and "\n" not in message and message.endswith("."), message


def test_a_chain_in_space_with_a_planar_support_position_is_one_sentence() -> None:
    state = state_of_scenario("chain-around-post")
    state["supports"][1]["position"] = [1.0, 0.0]
    with pytest.raises(ScenarioError) as error:
        solve_state(state)
    message = str(error.value)
    assert "supports[1].position" in message and "3 numbers" in message and "\n" not in message


def test_a_saved_net_reads_back_to_the_same_energy(tmp_path: Path) -> None:
    state = state_of_scenario("net-over-sphere")
    state["net"]["grid"], state["net"]["slack"] = [8, 9], 1.25
    state["obstacles"][0]["radius"] = 0.25
    path = tmp_path / "net.toml"
    path.write_text(toml_of_state(state), encoding="utf-8")
    again = load_scenario(path)
    assert again.n_nodes == 72 and again.dimension == 3
    assert solve(again).objective == pytest.approx(solve_state(state)["energy"], rel=1e-9)


def test_the_report_and_the_page_draw_with_one_script() -> None:
    from funicular._htmlreport import View3D, render_view

    script = view3d_script()
    assert "function funicularView3D(canvas, data)" in script
    assert script in render_view(View3D({"positions": []}))
    page = (Path(__file__).parents[1] / "src/funicular/explorer/static/index.html").read_text(encoding="utf-8")
    assert '<script src="/view3d.js">' in page
    assert VIEW3D.read_text(encoding="utf-8") == script


def test_serve_refuses_a_net_too_large_for_it_in_one_sentence(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("uvicorn", reason="the serve extra is not installed")
    path = tmp_path / "big.toml"
    path.write_text("dimension = 3\n\n[net]\ngrid = [50, 50]\nslack = 1.2\nmass = 1.0\n", encoding="utf-8")
    assert main(["serve", str(path), "--port", "0"]) == 2
    error = capsys.readouterr().err
    assert "net.grid = [50, 50] makes 2500 nodes" in error and error.count("\n") == 1


def test_serve_without_its_extra_names_the_install_command(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "uvicorn" else real(name, *a))
    assert main(["serve"]) == 2
    error = capsys.readouterr().err
    assert install_command("serve") in error and error.count("\n") == 1


# ----------------------------------------------------------------- elastic links
TWO_SUPPORTS = [(0, (0.0, 0.0)), (-1, (1.0, 0.0))]  # (the built-in two-supports: 51 nodes, length 1.5, mass 1, g = 1)


def _strain(answer: dict[str, Any], rest: np.ndarray) -> np.ndarray:
    """Each link's strain recomputed from the answer's positions and the links' lengths ``rest``:
    (d - L0) / L0, 0 where slack."""
    positions, links = np.array(answer["positions"]), np.array(answer["links"])
    drawn = np.linalg.norm(positions[links[:, 0]] - positions[links[:, 1]], axis=1)
    strain: np.ndarray = np.maximum(drawn - rest, 0.0) / rest
    return strain


def _assert_largest_strain(answer: dict[str, Any], strain: np.ndarray, rest: np.ndarray) -> None:
    """The answer's ``max_strain`` is the largest of ``strain``, in a link that has it (a symmetric
    chain's end links tie), stretched by its strain times its length."""
    shown = answer["max_strain"]
    k = shown["link"]
    assert shown["strain"] == pytest.approx(strain.max(), rel=1e-9)
    assert strain[k] == pytest.approx(strain.max(), rel=1e-9)
    assert shown["stretch"] == pytest.approx(strain[k] * rest[k], rel=1e-9)
    assert shown["nodes"] == answer["links"][k]


def test_the_ea_field_solves_as_the_same_problem_built_with_its_axial_stiffness() -> None:
    state = state_of_scenario("two-supports")
    assert solve_state(state)["strain"] is None and solve_state(state)["max_strain"] is None  # (no elastic link)
    state["chain"]["axial_stiffness"] = 100.0  # what the page's EA field sets
    answer = solve_state(state)
    expected = solve(
        Problem.build(nodes=51, length=1.5, mass=1.0, gravity=1.0, supports=TWO_SUPPORTS, axial_stiffness=100)
    )
    assert answer["status"] == "optimal"
    assert answer["energy"] == pytest.approx(expected.objective, rel=1e-12)
    np.testing.assert_allclose(answer["tension"], expected.link_tension, rtol=1e-10)
    # Stretched links let the chain hang lower than the inextensible one, whose shape it could keep
    # at no strain energy.
    rigid = solve(Problem.build(nodes=51, length=1.5, mass=1.0, gravity=1.0, supports=TWO_SUPPORTS))
    assert answer["energy"] < rigid.objective - 1e-6
    # The strains the page colours by: the solution's, each link's (d - L0) / L0 recomputed from the
    # positions, and Hooke's law gives each tension as EA times it.
    rest = np.full(50, 1.5 / 50)
    strain = _strain(answer, rest)
    np.testing.assert_allclose(answer["strain"], expected.link_strain, rtol=1e-10)
    np.testing.assert_allclose(answer["strain"], strain, rtol=1e-9)
    np.testing.assert_allclose(answer["tension"], 100.0 * strain, rtol=1e-6)
    _assert_largest_strain(answer, strain, rest)
    assert answer["max_strain"]["elastic"] == 50
    json.dumps(answer, allow_nan=False)


@pytest.mark.parametrize(("ea", "got"), [(0, "EA = 0.0"), (-5.0, "EA = -5.0"), ("stiff", "a string 'stiff'")])
@pytest.mark.parametrize("name", ["two-supports", "pretensioned-saddle"])
def test_a_bad_ea_is_one_sentence_naming_its_key(name: str, ea: object, got: str) -> None:
    state = state_of_scenario(name)
    table = state.get("chain") or state["net"]
    if "links" in table:  # (the page's EA field: one number for every link, instead of the rows' own)
        table["links"] = [row[:3] for row in table["links"]]
    table["axial_stiffness"] = ea
    with pytest.raises(ScenarioError) as error:
        solve_state(state)
    message = str(error.value)
    key = "chain" if name == "two-supports" else "net"
    assert f"{key}.axial_stiffness" in message and got in message, message
    assert "\n" not in message and message.endswith(".")


@pytest.mark.parametrize("name", ["mooring", "taut-mooring", "pretensioned-saddle", "seed-licq-elastic"])
def test_every_elastic_built_in_loads_solves_and_shows_its_largest_strain(name: str) -> None:
    state = state_of_scenario(name)
    answer = solve_state(state)
    problem = load_scenario(name)
    assert answer["status"] == "optimal"
    assert answer["energy"] == pytest.approx(solve(problem).objective, rel=1e-12)
    _assert_largest_strain(answer, _strain(answer, problem.link_lengths), problem.link_lengths)
    assert answer["max_strain"]["elastic"] == problem.n_links
    assert answer["units"]["force"] == ("N" if name.endswith("mooring") else "")  # (the moorings are SI)
    assert answer["units"]["length"] == ("m" if name.endswith("mooring") else "")


def test_elastic_links_that_make_indeterminate_forces_unique_are_said_so() -> None:
    # seed-licq-elastic: supports 1.002 apart vertically, two links of 0.5 (EA 1000) in line, the
    # middle node weighing 1/3. The two links are dependent constraints (LICQ fails, degree 1), but
    # compatibility decides: T1 - T2 = 1/3 and (T1 + T2) 0.5 / 1000 = 0.002, so T1 = 13/6, T2 = 11/6.
    answer, checks = _checked(state_of_scenario("seed-licq-elastic"))
    np.testing.assert_allclose(answer["tension"], [13 / 6, 11 / 6], rtol=1e-8)
    licq = checks["licq"]
    assert licq["holds"] is False and licq["text"].startswith("fails: rank 1 of 2 active constraints")
    assert "statically indeterminate to degree 1; with the links' axial stiffness the forces are unique" in licq["text"]
    assert checks["second_order"]["verdict"] == "strict local minimum"


def test_one_ea_for_a_nets_links_solves_as_each_link_row_carrying_it(tmp_path: Path) -> None:
    state = state_of_scenario("pretensioned-saddle")
    rows = state["net"]["links"]
    page = copy.deepcopy(state)  # the page's EA field: the rows' own EA dropped, one for every link
    page["net"]["links"] = [row[:3] for row in rows]
    page["net"]["axial_stiffness"] = 2.0e4
    each = copy.deepcopy(state)
    each["net"]["links"] = [[*row[:3], 2.0e4] for row in rows]
    answer = solve_state(page)
    assert answer["energy"] == pytest.approx(solve(parse_scenario(each, "each row")).objective, rel=1e-12)
    rest = np.array([row[2] for row in rows])
    np.testing.assert_allclose(answer["tension"], 2.0e4 * _strain(answer, rest), rtol=1e-6)  # Hooke's law
    path = tmp_path / "saddle.toml"
    path.write_text(toml_of_state(page), encoding="utf-8")
    assert solve(load_scenario(path)).objective == pytest.approx(answer["energy"], rel=1e-12)


# ----------------------------------------------------------------- over HTTP
@contextmanager
def _serving(scenario: str) -> Iterator[str]:
    """``funicular serve scenario`` on a free loopback port, in its own process; its URL."""
    pytest.importorskip("uvicorn", reason="the serve extra is not installed")
    command = [sys.executable, "-m", "funicular", "serve", scenario, "--port", "0"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            line = process.stdout.readline() if process.stdout else ""
            assert "http://127.0.0.1:" in line, line + (process.stderr.read() if process.stderr else "")
            yield line.split()[3]
        finally:
            process.terminate()
            process.wait(timeout=30)
        assert process.returncode in (0, 143), process.stderr.read() if process.stderr else ""  # 143: terminated


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    """The explorer on the built-in two-supports."""
    with _serving("two-supports") as url:
        yield url


# A chain of 21 nodes and length 1.5 between supports 1 apart, with no name of its own: the page
# names it by its file.
SERVED_FILE = """[chain]
nodes = 21
length = 1.5
mass = 2.0

[[supports]]
node = 0
position = [0.0, 0.0]

[[supports]]
node = -1
position = [1.0, 0.0]
"""


@pytest.fixture(scope="module")
def served_file(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    """The explorer on a scenario file; its URL and the file."""
    path = tmp_path_factory.mktemp("served") / "my-chain.toml"
    path.write_text(SERVED_FILE, encoding="utf-8")
    with _serving(str(path)) as url:
        yield url, path


def _post(url: str, body: bytes) -> tuple[int, dict[str, Any]]:
    request = urllib.request.Request(url, data=body, headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=120) as response:
            return response.status, json.load(response)
    except urllib.error.HTTPError as error:
        with error:
            return error.code, json.load(error)


def _get(url: str) -> dict[str, Any]:
    with urllib.request.urlopen(url, timeout=30) as response:
        answer: dict[str, Any] = json.load(response)
        return answer


def test_the_server_answers_the_picture_then_the_checks_and_an_error_carries_no_numbers(server: str) -> None:
    start = _get(server + "api/start")
    assert start["served"] == {"builtin": "two-supports", "file": None}
    state = start["state"]
    status, answer = _post(server + "api/solve", json.dumps({"state": state}).encode())
    assert status == 200 and answer["status"] == "optimal" and "licq" not in answer
    assert answer["energy"] == pytest.approx(solve(load_scenario("two-supports")).objective, rel=1e-9)
    status, checks = _post(server + "api/check", json.dumps({"state": state, "point": _point(answer)}).encode())
    assert status == 200 and set(checks) == {"licq", "second_order"}
    assert checks["second_order"]["verdict"] == "strict local minimum"

    # Malformed requests, an impossible scenario and a point of another scenario: one sentence, and
    # nothing else (no number of any state); the server goes on answering.
    apart = {**state, "supports": [{"node": 0, "position": [0.0, 0.0]}, {"node": -1, "position": [2.0, 0.0]}]}
    net = state_of_scenario("net-over-sphere")
    for path, body, code in (
        ("api/solve", b"not json", 400),
        ("api/solve", b"[]", 400),
        ("api/solve", b'{"state": {"chain": 3}}', 400),
        ("api/solve", b'{"state": {}, "start": "x"}', 400),
        (
            "api/solve",
            json.dumps({"state": {**state, "chain": {"nodes": 51, "length": 1.5, "mass": -1}}}).encode(),
            400,
        ),
        ("api/solve", json.dumps({"state": apart}).encode(), 422),
        ("api/check", json.dumps({"state": net, "point": _point(answer)}).encode(), 400),
        ("api/check", json.dumps({"state": state}).encode(), 400),
        ("api/load", b'{"name": "no-such-scenario"}', 400),
    ):
        status, error = _post(server + path, body)
        assert status == code and set(error) == {"error"}, (path, body[:60], error)
        assert error["error"].endswith((".", "?")) and "\n" not in error["error"]
    status, loaded = _post(server + "api/load", b'{"name": "two-supports"}')
    assert status == 200 and loaded["state"]["name"] == "two-supports"
    with urllib.request.urlopen(server + "view3d.js", timeout=30) as response:
        assert response.read() == VIEW3D.read_bytes()  # the report's script, served as it is


def test_a_served_file_is_what_the_menu_names(served_file: tuple[str, Path]) -> None:
    start = _get(served_file[0] + "api/start")
    assert start["served"] == {"builtin": None, "file": "my-chain.toml"}
    assert start["state"]["name"] == "my-chain" and start["state"]["chain"]["nodes"] == 21


def test_the_server_solves_an_elastic_chain_and_answers_a_bad_ea_with_one_sentence(server: str) -> None:
    state = _get(server + "api/start")["state"]
    elastic = {**state, "chain": {**state["chain"], "axial_stiffness": 100.0}}
    status, answer = _post(server + "api/solve", json.dumps({"state": elastic}).encode())
    assert status == 200 and answer["max_strain"]["elastic"] == 50 and len(answer["strain"]) == 50
    for ea in (0, -5.0, "stiff"):
        bad = {**state, "chain": {**state["chain"], "axial_stiffness": ea}}
        status, error = _post(server + "api/solve", json.dumps({"state": bad}).encode())
        assert status == 400 and set(error) == {"error"}, error  # (no number of any state)
        assert "chain.axial_stiffness" in error["error"] and error["error"].endswith(".")


# ----------------------------------------------------------------- in the browser
@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with chromium() as launched:
        yield launched


def _number(page: Any, testid: str) -> float:
    return float(page.get_by_test_id(testid).inner_text())


def _open(browser: Any, url: str) -> tuple[Any, list[str]]:
    """A new page on the explorer at ``url``, once it shows its first state with its checks; and the
    list its script errors go to."""
    page = browser.new_page(viewport={"width": 1400, "height": 900}, accept_downloads=True)
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(url)
    settle(page)
    return page, errors


def _labels(page: Any) -> dict[str, Any]:
    """What the page shows with a unit, or without: the readout's energy and largest tension, the
    link table's headers and the labels of the planar picture's arrows."""
    shown: dict[str, Any] = page.evaluate(
        """() => ({
            energy: document.getElementById("energy").textContent,
            tension: document.getElementById("max-tension").textContent,
            headers: [...document.querySelectorAll("#link-table thead th")].map((th) => th.textContent),
            arrows: [...document.querySelectorAll("#arrows text")].map((text) => text.textContent),
        })"""
    )
    return shown


def test_the_page_labels_units_only_where_the_scenario_declares_them(browser: Any, tmp_path: Path) -> None:
    """A chain that declares SI units shows its energy in J, its forces in N and its table's headers
    with units; the built-in two-supports, which declares none, loaded after it shows numbers alone."""
    path = tmp_path / "si-chain.toml"
    path.write_text('units = "SI"\n' + SERVED_FILE, encoding="utf-8")
    number = r"-?[\d.]+(?:e[+-]\d+)?"
    with _serving(str(path)) as url:
        page, errors = _open(browser, url)
        si = _labels(page)
        assert re.fullmatch(rf"{number} J", si["energy"]) and re.fullmatch(rf"{number} N", si["tension"])
        top = solve(load_scenario(path)).link_tension.max()
        assert float(si["tension"].removesuffix(" N")) == pytest.approx(top, rel=1e-9)
        assert si["headers"] == ["link", "multiplier [N]", "tension [N]", "taut"]
        assert len(si["arrows"]) == 2 and all(re.fullmatch(rf"{number} N", text) for text in si["arrows"])

        page.select_option("#scenario-list", "two-supports")
        settle(page, lambda: page.click("#load"))
        plain = _labels(page)
        assert re.fullmatch(number, plain["energy"]) and re.fullmatch(number, plain["tension"])
        assert plain["headers"] == ["link", "multiplier", "tension", "taut"]
        assert len(plain["arrows"]) == 2 and all(re.fullmatch(number, text) for text in plain["arrows"])
        assert errors == []


def _change(page: Any, selector: str, value: str) -> Any:
    """An act: type ``value`` into the field and commit it (its change event)."""
    return lambda: (page.fill(selector, value), page.dispatch_event(selector, "change"))


def test_the_page_in_a_real_browser(server: str, browser: Any, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    page, errors = _open(browser, server)
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    before = _number(page, "max-tension")

    # Drag the right support to the right: the chain is pulled tighter.
    box = page.get_by_test_id("support-1").bounding_box()
    assert box is not None
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2

    def drag() -> None:
        page.mouse.move(x, y)
        page.mouse.down()
        page.mouse.move(x + 60, y, steps=6)
        page.mouse.up()

    settle(page, drag)
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    assert _number(page, "max-tension") > before

    # Save it: funicular solve reads the file back to the energy shown.
    shown = _number(page, "energy")
    with page.expect_download() as download:
        page.get_by_test_id("save").click()
    saved = tmp_path / "saved.toml"
    download.value.save_as(saved)
    result = tmp_path / "result.json"
    assert main(["solve", str(saved), "--json", str(result)]) == 0
    assert json.loads(result.read_text())["objective"] == pytest.approx(shown, rel=1e-8)

    # The seed's LICQ failure.
    page.select_option("#scenario-list", "seed-licq")
    settle(page, lambda: page.click("#load"))
    expect(page.get_by_test_id("licq")).to_contain_text("fails")
    expect(page.get_by_test_id("status")).to_have_text("optimal")

    _the_3d_view(page, expect)
    assert errors == []


def _the_3d_view(page: Any, expect: Any) -> None:
    """net-over-sphere in the 3-D view: drawn, and re-solved when gravity or the sphere changes."""
    page.select_option("#scenario-list", "net-over-sphere")
    settle(page, lambda: page.click("#load"))
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    expect(page.get_by_test_id("view3d")).to_be_visible()
    expect(page.locator("#scene")).to_be_hidden()
    expect(page.get_by_test_id("licq")).to_contain_text("statically determinate")
    expect(page.get_by_test_id("second-order")).to_contain_text("strict local minimum")
    drawn = coloured_share(page)
    assert 0.01 < drawn < 0.9  # the net on a white background
    energy = _number(page, "energy")

    # The equilibrium does not depend on g, so the energy g m^T z doubles with it.
    settle(page, _change(page, "#gravity", "2"))
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    assert _number(page, "energy") == pytest.approx(2 * energy, rel=1e-6)

    # A larger sphere about the same centre leaves the net fewer places to go: the energy rises.
    settle(page, _change(page, "[data-testid=obstacle-0-radius]", "0.35"))
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    assert _number(page, "energy") > 2 * energy + 1e-3

    # A grid too large for the explorer: its sentence (a request answered, but no solve).
    settle(page, _change(page, "#grid-rows", "150"))
    expect(page.get_by_test_id("status")).to_have_text("error")
    expect(page.locator("#error")).to_contain_text("net.grid = [150, 20] makes 3000 nodes")


class _Gate:
    """Requests to a URL pattern held back while the gate is closed (Playwright's routes), and let go
    when it opens; an open gate lets them pass."""

    def __init__(self, page: Any, pattern: str) -> None:
        self.page, self.held, self.room = page, [], 0
        page.route(pattern, self._route)

    def _route(self, route: Any) -> None:
        if self.room > 0:
            self.room -= 1
            self.held.append(route)
        else:
            route.continue_()

    def close(self, count: int = 1_000_000) -> None:
        """Hold the next ``count`` requests (the later ones pass)."""
        self.room = count

    def open(self) -> None:
        self.room = 0
        held, self.held = self.held, []
        for route in held:
            route.continue_()

    def wait_held(self, count: int) -> None:
        """Wait until ``count`` requests are held (the routes reach the test while it waits on the page)."""
        for _ in range(6000):
            if len(self.held) >= count:
                return
            self.page.wait_for_timeout(20)
        raise AssertionError(f"{len(self.held)} requests held, {count} expected")


def _set(page: Any, selector: str, value: str) -> None:
    """Type ``value`` into the field and commit it, in the page (a user's quick edit: nothing waited for)."""
    page.eval_on_selector(selector, "(f, v) => { f.value = v; f.dispatchEvent(new Event('change')); }", value)


def _energies(log: list[dict[str, Any]]) -> list[float]:
    """The energies a readout log shows (its placeholders left out)."""
    return [float(entry["energy"]) for entry in log if entry["energy"] not in ("…", "")]


def test_a_scenario_loaded_from_the_menu_never_shows_the_old_numbers(server: str, browser: Any) -> None:
    page, errors = _open(browser, server)
    old = page.get_by_test_id("energy").inner_text()
    solves = _Gate(page, "**/api/solve")
    solves.close(1)  # the old scenario's next solve: answered only once the new one is shown
    record_readout(page)
    page.select_option("#scenario-list", "net-over-sphere")
    # In one go, as a user's two quick actions: a new gravity (a solve of the old scenario, held) and
    # the load.
    page.evaluate(
        """() => {
            const gravity = document.getElementById("gravity");
            gravity.value = "3";
            gravity.dispatchEvent(new Event("change"));
            document.getElementById("load").click();
        }"""
    )
    settle(page)
    assert len(solves.held) == 1  # (the new scenario's solve was not held back behind the old one)
    new = page.get_by_test_id("energy").inner_text()
    assert page.locator("#scenario-name").inner_text() == "net-over-sphere"
    expected = solve(load_scenario("net-over-sphere")).objective
    assert float(new) == pytest.approx(expected, rel=1e-6) and new != old

    # The old scenario's answer comes last: it is dropped, picture and numbers.
    answers, drawn = int(page.evaluate("document.body.dataset.answers")), coloured_share(page)
    solves.open()
    page.wait_for_function(f"Number(document.body.dataset.answers) > {answers}", timeout=120_000)
    assert page.get_by_test_id("energy").inner_text() == new
    assert page.locator("#scenario-name").inner_text() == "net-over-sphere"
    assert page.locator("#scene").is_hidden() and coloured_share(page) == drawn > 0.01  # (the net's picture)

    # Every state the page rendered since the click: solving, or the net's numbers, never another's.
    log = readout_log(page)
    assert {entry["energy"] for entry in log[1:]} <= {"…", new}, [entry["energy"] for entry in log]
    assert all(entry["name"] == "net-over-sphere" for entry in log if entry["energy"] == new)
    # The numbers came before the verdict: first shown while the checks were still coming.
    first = next(entry for entry in log if entry["energy"] == new)
    assert first["readout"] == "checking" and first["second_order"] == "checking…"
    assert log[-1]["readout"] == "done" and log[-1]["second_order"].startswith("strict local minimum")
    assert errors == []


def test_an_answer_or_a_check_of_a_state_changed_since_is_not_shown(server: str, browser: Any) -> None:
    page, errors = _open(browser, server)  # two-supports: the shape does not depend on g, the energy is g m^T y
    energy = _number(page, "energy")
    solves, checks = _Gate(page, "**/api/solve"), _Gate(page, "**/api/check")
    record_readout(page)
    # g = 2, held; g = 3 meanwhile: g = 2's answer comes after g = 3 was asked for.
    solves.close()
    _set(page, "#gravity", "2")
    solves.wait_held(1)
    _set(page, "#gravity", "3")
    checks.close()
    solves.open()
    page.wait_for_function("document.body.dataset.readout === 'checking'", timeout=120_000)
    assert _number(page, "energy") == pytest.approx(3 * energy, rel=1e-6)
    # g = 3's check comes after g = 4 was asked for.
    solves.close()
    _set(page, "#gravity", "4")
    checked = int(page.evaluate("document.body.dataset.checks"))
    checks.open()
    page.wait_for_function(f"Number(document.body.dataset.checks) > {checked}", timeout=120_000)
    assert [page.get_by_test_id(t).inner_text() for t in ("status", "energy", "licq", "second-order")] == [
        "solving…",
        "…",
        "…",
        "…",
    ]
    settle(page, solves.open)
    assert _number(page, "energy") == pytest.approx(4 * energy, rel=1e-6)
    assert page.get_by_test_id("second-order").inner_text().startswith("strict local minimum")

    log = readout_log(page)
    shown = _energies(log[1:])  # (the first note: the state before)
    assert all(
        value == pytest.approx(3 * energy, rel=1e-6) or value == pytest.approx(4 * energy, rel=1e-6) for value in shown
    ), shown
    assert all(entry["licq"] == entry["second_order"] == "…" for entry in log if entry["readout"] == "solving")
    assert errors == []


def test_the_picture_and_the_forces_come_before_the_verdict(server: str, browser: Any) -> None:
    page, errors = _open(browser, server)
    checks = _Gate(page, "**/api/check")
    checks.close()
    page.select_option("#scenario-list", "net-over-sphere")
    # The old scenario's numbers are gone the moment the load is asked for.
    shown = page.evaluate(
        """() => {
            document.getElementById("load").click();
            return ["status", "energy", "max-tension", "licq"].map((id) => document.getElementById(id).textContent);
        }"""
    )
    assert shown == ["solving…", "…", "…", "…"]
    # While the checks are held back, the net is drawn and its numbers shown.
    checks.wait_held(1)
    assert page.evaluate("document.body.dataset.readout") == "checking"
    assert coloured_share(page) > 0.01
    assert _number(page, "energy") == pytest.approx(solve(load_scenario("net-over-sphere")).objective, rel=1e-6)
    assert page.get_by_test_id("licq").inner_text() == "checking…"
    assert page.get_by_test_id("second-order").inner_text() == "checking…"
    settle(page, checks.open)
    assert page.get_by_test_id("second-order").inner_text().startswith("strict local minimum")
    assert "statically determinate" in page.get_by_test_id("licq").inner_text()
    assert errors == []


def test_a_bad_field_value_shows_its_sentence_and_no_numbers(server: str, browser: Any) -> None:
    page, errors = _open(browser, server)
    energy = page.get_by_test_id("energy").inner_text()
    record_readout(page)
    settle(page, _change(page, "#mass", "-1"))
    assert page.get_by_test_id("status").inner_text() == "error"
    assert "chain.mass" in page.locator("#error").inner_text()
    for testid in ("energy", "max-tension", "licq", "second-order"):
        assert page.get_by_test_id(testid).inner_text() == ""
    assert page.locator("#link-table tbody tr").count() == 0
    log = readout_log(page)
    assert all(entry["energy"] in ("…", "") for entry in log[1:]), [entry["energy"] for entry in log]
    # A good value again: the numbers of that state.
    settle(page, _change(page, "#mass", "1"))
    assert page.get_by_test_id("energy").inner_text() == energy
    assert errors == []


def test_a_served_file_is_the_menus_entry_and_can_be_loaded_again(served_file: tuple[str, Path], browser: Any) -> None:
    url, path = served_file
    page, errors = _open(browser, url)
    selected = "s => s.options[s.selectedIndex].text"
    assert page.eval_on_selector("#scenario-list", selected) == "file: my-chain.toml"
    assert page.locator("#scenario-name").inner_text() == "my-chain"
    expected = solve(load_scenario(path)).objective
    assert _number(page, "energy") == pytest.approx(expected, rel=1e-8)
    page.select_option("#scenario-list", "seed-licq")
    settle(page, lambda: page.click("#load"))
    assert page.eval_on_selector("#scenario-list", selected) == "seed-licq"
    page.select_option("#scenario-list", label="file: my-chain.toml")
    settle(page, lambda: page.click("#load"))
    assert page.locator("#scenario-name").inner_text() == "my-chain"
    assert _number(page, "energy") == pytest.approx(expected, rel=1e-8)
    assert errors == []


def _text(page: Any, testid: str) -> str:
    """The text of an element of the page, an SVG one too (which has no inner text)."""
    text: str = page.get_by_test_id(testid).text_content()
    return text


def _strain_offered(page: Any) -> bool:
    return not page.eval_on_selector("#colour-by option[value=strain]", "option => option.disabled")


def test_the_ea_field_solves_the_elastic_chain_and_a_bad_one_shows_its_sentence(server: str, browser: Any) -> None:
    page, errors = _open(browser, server)  # two-supports
    rigid = page.get_by_test_id("energy").inner_text()
    assert not _strain_offered(page) and page.locator("#strain-row").is_hidden()
    assert _text(page, "colour-bar-label").startswith("tension 0 to ")

    settle(page, _change(page, "#axial-stiffness", "100"))
    expected = solve(
        Problem.build(nodes=51, length=1.5, mass=1.0, gravity=1.0, supports=TWO_SUPPORTS, axial_stiffness=100)
    )
    assert _number(page, "energy") == pytest.approx(expected.objective, rel=1e-9)
    assert _number(page, "energy") < float(rigid)  # (stretched, it hangs lower)
    largest = page.get_by_test_id("max-strain").inner_text()
    assert float(largest.split()[0]) == pytest.approx(expected.link_strain.max(), rel=1e-3)  # (4 digits shown)
    assert largest.endswith("(50 of 50 links elastic)") and _strain_offered(page)
    assert "+ strain energy" in page.locator("#energy-terms").inner_text()

    # A new number of nodes keeps the links' EA.
    settle(page, _change(page, "#nodes", "21"))
    fewer = solve(
        Problem.build(nodes=21, length=1.5, mass=1.0, gravity=1.0, supports=TWO_SUPPORTS, axial_stiffness=100)
    )
    assert _number(page, "energy") == pytest.approx(fewer.objective, rel=1e-9)

    # A bad EA: the model's sentence naming the key, and no numbers.
    for bad, got in (("0", "EA = 0.0"), ("-3", "EA = -3.0"), ("stiff", "a string 'stiff'")):
        settle(page, _change(page, "#axial-stiffness", bad))
        assert page.get_by_test_id("status").inner_text() == "error"
        message = page.locator("#error").inner_text()
        assert "chain.axial_stiffness" in message and got in message, message
        assert all(page.get_by_test_id(t).inner_text() == "" for t in ("energy", "max-tension", "max-strain"))
    # Empty (or inf): inextensible again.
    settle(page, _change(page, "#axial-stiffness", "inf"))
    rigid21 = solve(Problem.build(nodes=21, length=1.5, mass=1.0, gravity=1.0, supports=TWO_SUPPORTS))
    assert _number(page, "energy") == pytest.approx(rigid21.objective, rel=1e-9)
    assert page.locator("#strain-row").is_hidden() and not _strain_offered(page)
    assert errors == []


def test_mooring_from_the_menu_shows_its_units_and_colours_its_links_by_strain(server: str, browser: Any) -> None:
    page, errors = _open(browser, server)
    page.select_option("#scenario-list", "mooring")
    settle(page, lambda: page.click("#load"))
    expected = solve(load_scenario("mooring"))
    energy, tension = page.get_by_test_id("energy").inner_text(), page.get_by_test_id("max-tension").inner_text()
    assert energy.endswith(" J") and float(energy.removesuffix(" J")) == pytest.approx(expected.objective, rel=1e-9)
    assert tension.endswith(" N") and float(tension.removesuffix(" N")) == pytest.approx(
        expected.link_tension.max(), rel=1e-9
    )
    assert re.search(
        r"stretched by [\d.e+-]+ m \(100 of 100 links elastic\)$", page.get_by_test_id("max-strain").inner_text()
    )
    assert page.eval_on_selector("#axial-stiffness", "field => Number(field.value)") == 5.0e8

    by_tension = _text(page, "colour-bar-label")
    assert re.fullmatch(r"tension 0 to [\d.e+-]+ N", by_tension), by_tension
    assert _strain_offered(page)
    page.select_option("#colour-by", "strain")
    by_strain = _text(page, "colour-bar-label")
    top = re.fullmatch(r"strain 0 to ([\d.e+-]+)", by_strain)  # (a strain has no unit)
    assert top is not None, by_strain
    assert float(top.group(1)) == pytest.approx(expected.link_strain.max(), rel=5e-3)  # (3 digits shown)

    # In space: the saddle's links by strain, then by tension again (the 3-D view's colour bar).
    page.select_option("#scenario-list", "pretensioned-saddle")
    settle(page, lambda: page.click("#load"))
    assert page.eval_on_selector("#axial-stiffness", "field => Number(field.value)") == 1.0e4
    bar = page.eval_on_selector("#view3d", "canvas => canvas.dataset.colourBar")
    saddle = solve(load_scenario("pretensioned-saddle")).link_strain
    shown = re.fullmatch(r"strain (\S+) to (\S+)", bar)
    assert shown is not None, bar
    low, high = (float(x) for x in shown.groups())
    assert (low, high) == (pytest.approx(saddle.min(), rel=5e-3), pytest.approx(saddle.max(), rel=5e-3))
    page.select_option("#colour-by", "tension")
    assert page.eval_on_selector("#view3d", "canvas => canvas.dataset.colourBar").startswith("tension ")

    # One EA for every cable: the page solves the net each of whose rows carries it.
    settle(page, _change(page, "#axial-stiffness", "2e4"))
    document = load_document("pretensioned-saddle").document
    document["net"]["links"] = [[*row[:3], 2.0e4] for row in document["net"]["links"]]
    stiffer = solve(parse_scenario(document, "each row"))
    assert _number(page, "energy") == pytest.approx(stiffer.objective, rel=1e-9)
    assert errors == []
