"""``funicular serve``: the explorer's domain layer (state -> problem -> solve -> JSON) for planar
chains, nets, chains in space and chains with point loads, its scenario files, the command without
its extra, the 3-D view's one script, and the page itself in a real browser (Debian's chromium driven
by Playwright; skipped, with the reason, when either is missing)."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from browser import coloured_share
from funicular import Problem, ScenarioError, load_scenario, solve
from funicular._extras import install_command
from funicular._static import VIEW3D, view3d_script
from funicular.cli import main
from funicular.explorer._state import MAX_NODES, scenarios, solve_state, state_of_scenario, toml_of_state
from funicular.scenario import builtin_scenarios


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
    licq = solve_state(state_of_scenario("seed-licq"))["licq"]
    assert licq["holds"] is False and "fails" in licq["text"] and "not unique" in licq["text"]
    state = state_of_scenario("two-supports")
    norm = solve_state(state)
    squared = solve_state({**state, "formulation": "squared"})
    assert norm["licq"]["holds"] is True and norm["second_order"]["verdict"] == "strict local minimum"
    np.testing.assert_allclose(squared["tension"], norm["tension"], rtol=1e-7)
    assert not np.allclose(squared["multiplier"], norm["multiplier"], rtol=1e-3)


def test_second_order_is_left_out_for_long_chains() -> None:
    state = state_of_scenario("two-supports")
    state["chain"] = {"nodes": 401, "length": 1.5, "mass": 1.0}
    assert solve_state(state)["second_order"]["verdict"] == "not checked"


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
    assert answer["licq"]["holds"] is True and "statically determinate" in answer["licq"]["text"]
    assert answer["second_order"]["verdict"] == "strict local minimum"
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
    answer = solve_state(state)
    reactions = np.array([r["force"] for r in answer["reactions"]])
    # By symmetry each support lifts half of the weight and the load.
    np.testing.assert_allclose(reactions[:, 1], [0.75, 0.75], rtol=1e-8)
    np.testing.assert_allclose(reactions[0, 0], -reactions[1, 0], rtol=1e-8)
    assert answer["loads"] == [{"node": 25, "force": [0.0, -0.5]}]
    assert answer["licq"]["holds"] is True and "statically determinate" in answer["licq"]["text"]
    assert answer["second_order"]["verdict"] == "strict local minimum"


def test_a_taut_chain_in_space_between_aligned_supports_is_statically_indeterminate() -> None:
    # Two links of 1 between supports 2 apart vertically: a straight taut line, so one tension can be
    # added to both links and carried by the supports alone (degree of indeterminacy 1).
    state = {
        "dimension": 3,
        "chain": {"nodes": 3, "length": 2.0, "mass": 1.0},
        "supports": [{"node": 0, "position": [0.0, 0.0, 0.0]}, {"node": -1, "position": [0.0, 0.0, -2.0]}],
    }
    licq = solve_state(state)["licq"]
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


# ----------------------------------------------------------------- in the browser
@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    """The explorer on a free loopback port, in its own process; its URL."""
    pytest.importorskip("uvicorn", reason="the serve extra is not installed")
    command = [sys.executable, "-m", "funicular", "serve", "two-supports", "--port", "0"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            line = process.stdout.readline() if process.stdout else ""
            assert "http://127.0.0.1:" in line, line + (process.stderr.read() if process.stderr else "")
            yield line.split()[3]
        finally:
            process.terminate()
            process.wait(timeout=30)
        assert process.returncode in (0, 143), process.stderr.read() if process.stderr else ""  # 143: terminated


def _post(url: str, body: bytes) -> tuple[int, dict[str, Any]]:
    request = urllib.request.Request(url, data=body, headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, json.load(response)
    except urllib.error.HTTPError as error:
        with error:
            return error.code, json.load(error)


def _number(page: Any, testid: str) -> float:
    return float(page.get_by_test_id(testid).inner_text())


def test_the_page_in_a_real_browser(server: str, tmp_path: Path) -> None:
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.skip("no chromium on PATH; scripts/ensure_chromium.sh installs it (apt-get, as root)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright (the test extra) is not installed")
    expect = sync_api.expect
    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium, headless=True, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900}, accept_downloads=True)
            page.goto(server)
            page.wait_for_function("Number(document.body.dataset.solves) >= 1 && document.body.dataset.idle === 'true'")
            expect(page.get_by_test_id("status")).to_have_text("optimal")
            before, solves = _number(page, "max-tension"), int(page.evaluate("document.body.dataset.solves"))

            # Drag the right support to the right: the chain is pulled tighter.
            box = page.get_by_test_id("support-1").bounding_box()
            assert box is not None
            x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
            page.mouse.move(x, y)
            page.mouse.down()
            page.mouse.move(x + 60, y, steps=6)
            page.mouse.up()
            page.wait_for_function(
                f"Number(document.body.dataset.solves) > {solves} && document.body.dataset.idle === 'true'"
            )
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
            page.click("#load")
            expect(page.get_by_test_id("licq")).to_contain_text("fails")
            expect(page.get_by_test_id("status")).to_have_text("optimal")

            # Malformed requests get an error, and the server goes on answering.
            for body in (b"not json", b"[]", b'{"state": {"chain": 3}}', b'{"state": {}, "start": "x"}'):
                status, answer = _post(server + "api/solve", body)
                assert status == 400 and answer["error"].endswith("."), answer
            status, answer = _post(server + "api/load", b'{"name": "two-supports"}')
            assert status == 200 and answer["state"]["name"] == "two-supports"
            status, answer = _post(server + "api/solve", json.dumps({"state": answer["state"]}).encode())
            assert status == 200 and answer["status"] == "optimal"

            _the_3d_view(page, sync_api.expect)
            with urllib.request.urlopen(server + "view3d.js", timeout=30) as response:
                assert response.read() == VIEW3D.read_bytes()  # the report's script, served as it is
        finally:
            browser.close()


SOLVED = "Number(document.body.dataset.solves) > {} && document.body.dataset.idle === 'true'"


def _after_a_solve(page: Any, act: Any) -> None:
    """Do ``act`` and wait until the page shows the solve it caused (a net's checks take a while)."""
    solves = int(page.evaluate("document.body.dataset.solves"))
    act()
    page.wait_for_function(SOLVED.format(solves), timeout=120_000)


def _the_3d_view(page: Any, expect: Any) -> None:
    """net-over-sphere in the 3-D view: drawn, and re-solved when gravity or the sphere changes."""
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.select_option("#scenario-list", "net-over-sphere")
    _after_a_solve(page, lambda: page.click("#load"))
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    expect(page.get_by_test_id("view3d")).to_be_visible()
    expect(page.locator("#scene")).to_be_hidden()
    expect(page.get_by_test_id("licq")).to_contain_text("statically determinate")
    drawn = coloured_share(page)
    assert 0.01 < drawn < 0.9  # the net on a white background
    energy = _number(page, "energy")

    # The equilibrium does not depend on g, so the energy g m^T z doubles with it.
    _after_a_solve(page, lambda: (page.fill("#gravity", "2"), page.dispatch_event("#gravity", "change")))
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    assert _number(page, "energy") == pytest.approx(2 * energy, rel=1e-6)

    # A larger sphere about the same centre leaves the net fewer places to go: the energy rises.
    radius = page.get_by_test_id("obstacle-0-radius")
    _after_a_solve(page, lambda: (radius.fill("0.35"), radius.dispatch_event("change")))
    expect(page.get_by_test_id("status")).to_have_text("optimal")
    assert _number(page, "energy") > 2 * energy + 1e-3

    # A grid too large for the explorer: its sentence (a request answered, but no solve).
    page.fill("#grid-rows", "150")
    page.dispatch_event("#grid-rows", "change")
    page.wait_for_function("document.body.dataset.idle === 'true'", timeout=120_000)
    expect(page.get_by_test_id("status")).to_have_text("error")
    expect(page.locator("#error")).to_contain_text("net.grid = [150, 20] makes 3000 nodes")
    assert errors == []
