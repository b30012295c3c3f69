"""Screenshots of the explorer for the docs: docs/explorer-two-supports.png (after dragging a support),
docs/explorer-disk-drape.png (contact forces), docs/explorer-seed-licq.png (LICQ failing) and
docs/explorer-net-over-sphere.png (a net in the 3-D view).

Run it as ``.venv/bin/python scripts/explorer_screenshots.py [OUTPUT_DIR]``: it starts
``funicular serve`` on a free loopback port and drives headless chromium with Playwright (the serve
and test extras; scripts/ensure_chromium.sh installs chromium). Each picture is the page at
1200 x 800 CSS pixels rendered at scale 0.75: 900 x 600 pixels.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # (bench/ is not part of the package)
from bench.explorer import server  # noqa: E402  # the explorer in its own process, as the benchmark runs it

DEFAULT_OUTPUT = ROOT / "docs"
# The newest state shown with its checks (``data-readout`` is "solving" from the moment a state is
# asked for, "checking" once it is drawn, "done" once LICQ and the second order are shown).
CHECKED = "document.body.dataset.readout === 'done' && document.body.dataset.idle === 'true'"


def settle(page: Any, solves: int) -> None:
    """Wait until the page has drawn a solve after the first ``solves`` and shows the newest state
    with its checks."""
    page.wait_for_function(f"Number(document.body.dataset.solves) > {solves} && {CHECKED}", timeout=120_000)
    page.wait_for_timeout(200)


def solves(page: Any) -> int:
    return int(page.evaluate("Number(document.body.dataset.solves || 0)"))


def preset(page: Any, name: str) -> None:
    before = solves(page)
    page.get_by_test_id(f"preset-{name}").click()
    settle(page, before)


def main(argv: list[str]) -> int:
    output = Path(argv[0]) if argv else DEFAULT_OUTPUT
    output.mkdir(parents=True, exist_ok=True)
    chromium = shutil.which("chromium")
    if chromium is None:
        print("explorer_screenshots.py: no chromium on PATH; scripts/ensure_chromium.sh installs it", file=sys.stderr)
        return 2
    from playwright.sync_api import sync_playwright  # (the test extra)

    with server("two-supports") as url, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium, headless=True, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 800}, device_scale_factor=0.75)
            page.goto(url)
            settle(page, 0)

            # two-supports: the right support dragged up and to the left, the chain slacker.
            box = page.get_by_test_id("support-1").bounding_box()
            x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
            before = solves(page)
            page.mouse.move(x, y)
            page.mouse.down()
            page.mouse.move(x - 110, y - 60, steps=12)
            page.mouse.up()
            settle(page, before)
            page.screenshot(path=output / "explorer-two-supports.png")

            preset(page, "disk-drape")
            page.screenshot(path=output / "explorer-disk-drape.png")

            preset(page, "seed-licq")
            licq = page.get_by_test_id("licq").inner_text()
            if "fails" not in licq:
                raise RuntimeError(f"seed-licq: LICQ was expected to fail, the page says {licq!r}")
            page.screenshot(path=output / "explorer-seed-licq.png")

            # net-over-sphere: the 3-D view, its statics as the LICQ readout.
            before = solves(page)
            page.select_option("#scenario-list", "net-over-sphere")
            page.click("#load")
            settle(page, before)
            page.screenshot(path=output / "explorer-net-over-sphere.png")
        finally:
            browser.close()
    for name in ("two-supports", "disk-drape", "seed-licq", "net-over-sphere"):
        path = output / f"explorer-{name}.png"
        print(f"{path} ({path.stat().st_size // 1024} KiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
