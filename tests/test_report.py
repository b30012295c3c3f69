"""`funicular report`: the HTML page's content, that it is self-contained, the Markdown variant, and a
real render of the page in headless Chromium (skipped, with the reason, when no Chromium is found;
``scripts/ensure_chromium.sh`` installs it)."""

from __future__ import annotations

import base64
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from funicular._htmlreport import write_report
from funicular._solver import solve
from funicular.cli import main
from funicular.model import Problem
from funicular.obstacles import Disk

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
BROWSERS = ("chromium", "chromium-browser", "google-chrome")


class Tables(HTMLParser):
    """Collects each table's header cells and body rows as text."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[dict[str, list[list[str]]]] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == "table":
            self.tables.append({"headers": [[]], "rows": []})
        elif tag == "tr" and self.tables:
            self.tables[-1]["rows"].append([])
        elif tag in ("th", "td"):
            self._cell = []

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)

    def handle_endtag(self, tag: str) -> None:
        if tag in ("th", "td") and self._cell is not None:
            text = "".join(self._cell)
            table = self.tables[-1]
            (table["headers"][0] if tag == "th" else table["rows"][-1]).append(text)
            self._cell = None


def parse_tables(text: str) -> list[dict[str, list[list[str]]]]:
    parser = Tables()
    parser.feed(text)
    for table in parser.tables:
        table["rows"] = [row for row in table["rows"] if row]
    return parser.tables


@pytest.fixture(scope="module")
def html_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("report") / "two-supports.html"
    assert main(["report", "two-supports", "-o", str(path)]) == 0
    return path


def test_html_report_has_the_sections_tables_and_images(html_report: Path) -> None:
    """Every section, the force and KKT tables with the right numbers, and embedded PNG figures.

    two-supports is symmetric with weight 1, so each support carries Fy = 0.5 (README's demo output).
    """
    text = html_report.read_text(encoding="utf-8")
    for heading in ("Scenario", "Equilibrium", "Forces", "KKT residuals", "LICQ and second-order", "Refinement"):
        assert re.search(f"<h2>{heading}", text), heading
    tables = {tuple(table["headers"][0]): table["rows"] for table in parse_tables(text)}
    reactions = tables[("support node", "Fx", "Fy", "|R|")]
    assert [row[0] for row in reactions] == ["0", "50", "total"]
    assert [float(row[2]) for row in reactions] == pytest.approx([0.5, 0.5, 1.0], abs=1e-9)
    links = tables[("link k", "length d_k", "max length l_k", "tension T_k", "multiplier mu_k", "state")]
    assert links[0][0] == "0" and links[-1][0] == "49" and any(row[0] == "…" for row in links)
    kkt = tables[("residual", "value", "scaled")]
    assert [row[0] for row in kkt] == ["stationarity", "primal feasibility", "dual feasibility", "complementarity"]
    assert all(float(row[2]) <= 1e-10 for row in kkt)
    refinement = next(rows for headers, rows in tables.items() if headers[:3] == ("N", "status", "squared mu max"))
    assert [row[0] for row in refinement] == ["5", "9", "17", "33"]
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert len(images) == 2 and all(base64.b64decode(data)[:8] == PNG_SIGNATURE for data in images)


def test_html_report_is_self_contained(html_report: Path) -> None:
    """No script, no stylesheet link, no URL other than the embedded data: images."""
    text = html_report.read_text(encoding="utf-8")
    assert "<script" not in text and "<link" not in text and "url(" not in text
    sources = re.findall(r'(?:src|href)="([^"]*)"', text)
    assert sources and all(source.startswith("data:image/png;base64,") for source in sources)


def test_markdown_report_writes_its_images_beside_it(tmp_path: Path) -> None:
    path = tmp_path / "notes.md"
    assert main(["report", "dangling", "-o", str(path), "--nodes", "8"]) == 0
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# funicular report: dangling")
    assert "| support node | Fx | Fy | \\|R\\| |" in text
    for name in ("notes-equilibrium.png", "notes-refine.png"):
        assert f"]({name})" in text
        assert (tmp_path / name).read_bytes()[:8] == PNG_SIGNATURE
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes-equilibrium.png", "notes-refine.png", "notes.md"]


def test_report_lists_contact_forces(tmp_path: Path) -> None:
    """With an obstacle, the forces section lists the nodes it pushes and their total."""
    problem = Problem.build(
        nodes=31,
        length=1.5,
        mass=1.0,
        gravity=1.0,
        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
        obstacles=[Disk((0.5, -0.55), 0.25)],
        name="drape",
    )
    solution = solve(problem)
    path = tmp_path / "drape.html"
    write_report(solution, path, "html")
    tables = {tuple(table["headers"][0]): table["rows"] for table in parse_tables(path.read_text(encoding="utf-8"))}
    contacts = tables[("contact node", "x", "y", "Fx", "Fy", "|F|")]
    magnitude = np.hypot(*solution.contact_forces.T)
    assert len(contacts) - 1 == np.count_nonzero(magnitude > 1e-8 * problem.weight) > 0
    assert contacts[-1][0] == "total" and float(contacts[-1][-1]) == pytest.approx(magnitude.sum(), rel=1e-7)
    assert [row[0] for row in tables[("obstacle", "shape")]] == ["disk"]


def test_report_renders_in_headless_chromium(html_report: Path, tmp_path: Path) -> None:
    """Chromium draws the page: the screenshot exists and is not blank (its pixels vary)."""
    browser = next((found for name in BROWSERS if (found := shutil.which(name))), None)
    if browser is None:
        pytest.skip("no chromium on PATH; scripts/ensure_chromium.sh installs it (apt-get, as root)")
    from matplotlib.image import imread

    screenshot = tmp_path / "page.png"
    command = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={screenshot}",
        "--window-size=1200,2000",
        html_report.resolve().as_uri(),
    ]
    done = subprocess.run(command, capture_output=True, text=True, timeout=180, check=False)
    assert done.returncode == 0 and screenshot.exists(), done.stderr[-2000:]
    pixels = imread(screenshot)
    assert pixels.shape[:2] == (2000, 1200)
    gray = pixels[..., :3].mean(axis=2)
    assert gray.std() > 0.05  # a blank page has no variance
    assert np.mean(gray < 0.5) > 0.01  # some dark text and drawing, not just a white page
