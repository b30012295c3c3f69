"""`funicular report` of a 3-D problem: its tables in three components, the embedded interactive view
(its data, self-contained, no request made) and the view itself in a real browser (Debian's chromium
driven by Playwright; skipped, with the reason, when either is missing)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from browser import coloured_share
from funicular import load_scenario
from funicular._htmlreport import _json_in_script
from funicular.cli import main
from test_report import parse_tables

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def report_3d(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("report3d") / "net-over-sphere.html"
    assert main(["report", "net-over-sphere", "-o", str(path)]) == 0
    return path


def view_data(text: str) -> dict[str, Any]:
    found = re.search(r'<script type="application/json" id="view3d-data">(.*?)</script>', text, re.S)
    assert found is not None
    data: dict[str, Any] = json.loads(found.group(1))
    return data


def test_the_view_holds_the_net_and_its_forces(report_3d: Path) -> None:
    text = report_3d.read_text(encoding="utf-8")
    assert text.count("<canvas") == 1
    data = view_data(text)
    problem = load_scenario("net-over-sphere")  # a 20 x 20 grid hung from its 4 corners, weight 1
    assert len(data["positions"]) == 400 and all(len(p) == 3 for p in data["positions"])
    assert len(data["links"]) == len(data["tension"]) == len(data["taut"]) == 2 * 20 * 19
    assert data["supports"] == [0, 19, 380, 399]
    np.testing.assert_allclose(np.array(data["positions"])[data["supports"]], problem.support_positions, atol=1e-12)
    # The supports and the sphere carry the weight together: their vertical forces add up to it.
    lifted = sum(r[2] for r in data["reactions"]) + sum(f[2] for f in data["contact_forces"])
    assert lifted == pytest.approx(problem.weight, rel=1e-5)
    assert len(data["contact_nodes"]) == len(data["contact_forces"]) > 0
    # By symmetry about both mid-planes, the four corners hold equal shares.
    vertical = [r[2] for r in data["reactions"]]
    assert vertical == pytest.approx([vertical[0]] * 4, rel=1e-5)
    # The sphere is drawn from the scenario's own table; the net carries no point load.
    assert data["obstacles"] == [{"shape": "sphere", "name": "sphere", "center": [0.5, 0.5, -0.7], "radius": 0.3}]
    assert "load_nodes" not in data


def test_the_view_shows_point_loads(tmp_path: Path) -> None:
    scenario = tmp_path / "loaded.toml"
    scenario.write_text(
        'dimension = 3\n[net]\ngrid = [4, 4]\nslack = 1.2\nmass = 1.0\nsupports = "corners"\n'
        "[[loads]]\nnode = 5\nforce = [0.25, 0.0, -0.5]\n",
        encoding="utf-8",
    )
    path = tmp_path / "loaded.html"
    assert main(["report", str(scenario), "-o", str(path)]) == 0
    data = view_data(path.read_text(encoding="utf-8"))
    assert data["load_nodes"] == [5] and data["load_forces"] == [[0.25, 0.0, -0.5]] and data["obstacles"] == []


def test_the_tables_have_three_components(report_3d: Path) -> None:
    tables = {tuple(table["headers"][0]): table["rows"] for table in parse_tables(report_3d.read_text("utf-8"))}
    assert ("support node", "x", "y", "z") in tables
    reactions = tables[("support node", "Fx", "Fy", "Fz", "|R|")]
    assert [row[0] for row in reactions] == ["0", "19", "380", "399", "total"]
    fx, fy, fz, size = (float(cell) for cell in reactions[0][1:])
    assert size == pytest.approx(float(np.linalg.norm([fx, fy, fz])), rel=1e-7)
    assert ("contact node", "x", "y", "z", "Fx", "Fy", "Fz", "|F|") in tables


def test_the_page_is_self_contained(report_3d: Path) -> None:
    """Inline scripts only: no src or href but the embedded PNG, no URL anywhere in the script."""
    text = report_3d.read_text(encoding="utf-8")
    sources = re.findall(r'(?:src|href)="([^"]*)"', text)
    assert sources and all(source.startswith("data:image/png;base64,") for source in sources)
    assert "<link" not in text and "url(" not in text
    scripts = re.findall(r"<script[^>]*>(.*?)</script>", text, re.S)
    assert len(scripts) == 2 and not any(re.search(r"https?:|//[a-z]|import|fetch|XMLHttpRequest", s) for s in scripts)


def test_markdown_of_a_3d_problem_has_no_script(tmp_path: Path) -> None:
    path = tmp_path / "post.md"
    assert main(["report", "chain-around-post", "-o", str(path)]) == 0
    text = path.read_text(encoding="utf-8")
    assert "<script" not in text and "<canvas" not in text and "](post-equilibrium.png)" in text


def test_the_data_cannot_end_its_script_early() -> None:
    data = {"name": "</script><script>alert(1)</script>"}
    text = _json_in_script(data)
    assert "</" not in text and json.loads(text) == data


def test_the_view_in_a_real_browser(report_3d: Path) -> None:
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.skip("no chromium on PATH; scripts/ensure_chromium.sh installs it (apt-get, as root)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright (the test extra) is not installed")
    url = report_3d.resolve().as_uri()
    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium, headless=True, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1100, "height": 900})
            requests: list[str] = []
            errors: list[str] = []
            page.on("request", lambda request: requests.append(request.url))
            page.on("pageerror", lambda error: errors.append(str(error)))
            page.goto(url)
            canvas = page.locator("#view3d")
            canvas.scroll_into_view_if_needed()
            drawn = coloured_share(page)
            assert 0.01 < drawn < 0.9  # the net is drawn on a white background, which shows around it
            before = page.evaluate("() => document.getElementById('view3d').toDataURL()")
            box = canvas.bounding_box()
            assert box is not None
            x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
            page.mouse.move(x, y)
            page.mouse.down()
            page.mouse.move(x + 120, y + 40, steps=6)
            page.mouse.up()
            turned = page.evaluate("() => document.getElementById('view3d').toDataURL()")
            assert turned != before
            page.mouse.wheel(0, -400)
            zoomed = page.evaluate("() => document.getElementById('view3d').toDataURL()")
            assert zoomed != turned
            assert errors == []
            assert requests == [url]  # the page itself, and nothing else
        finally:
            browser.close()
