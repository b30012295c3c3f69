"""``funicular serve``: the explorer's domain layer (state -> problem -> solve -> JSON), its scenario
files, the command without its extra, and the page itself in a real browser (Debian's chromium driven
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

from funicular import Problem, ScenarioError, load_scenario, solve
from funicular.cli import main
from funicular.explorer._state import MAX_NODES, solve_state, state_of_scenario, toml_of_state


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


def test_serve_without_its_extra_names_the_install_command(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "uvicorn" else real(name, *a))
    assert main(["serve"]) == 2
    error = capsys.readouterr().err
    assert "pip install 'funicular[serve]'" in error and error.count("\n") == 1


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
        finally:
            browser.close()
