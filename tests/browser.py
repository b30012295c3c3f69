"""What the browser tests read off a page, and the browser itself (headless chromium driven by
Playwright in the tests)."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest


@contextmanager
def chromium() -> Iterator[Any]:
    """Debian's chromium, headless, driven by Playwright; the test is skipped, saying why, when either
    is missing."""
    executable = shutil.which("chromium")
    if executable is None:
        pytest.skip("no chromium on PATH; scripts/ensure_chromium.sh installs it (apt-get, as root)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright (the test extra) is not installed")
    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=executable, headless=True, args=["--no-sandbox"])
        try:
            yield browser
        finally:
            browser.close()


def coloured_share(page: Any) -> float:
    """The share of the 3-D view's canvas (``#view3d``) that is not white: what has been drawn."""
    share: float = page.evaluate(
        """() => {
            const c = document.getElementById("view3d");
            const pixels = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
            let coloured = 0;
            for (let i = 0; i < pixels.length; i += 4) {
                if (pixels[i] < 250 || pixels[i + 1] < 250 || pixels[i + 2] < 250) coloured++;
            }
            return coloured / (pixels.length / 4);
        }"""
    )
    return share


# The explorer's readout: ``data-readout`` on the body is "solving" from the moment a state is asked
# for, "checking" once its solve is shown, then "done" (the checks shown), "error" or "not-converged".
SETTLED = (
    "['done', 'error', 'not-converged'].includes(document.body.dataset.readout) "
    "&& document.body.dataset.idle === 'true'"
)


def settle(page: Any, act: Any = None) -> None:
    """Do ``act`` (which asks for a new state) and wait until the explorer shows that state with its
    checks, or its error (a net's solve and checks may take a while on a loaded machine)."""
    if act is not None:
        act()
    page.wait_for_function(SETTLED, timeout=120_000)


def record_readout(page: Any) -> None:
    """From now on, note the explorer's readout every time the page changes it (a MutationObserver:
    every state the page renders is noted, not a sample); :func:`readout_log` returns the notes."""
    page.evaluate(
        """() => {
            const text = (id) => document.getElementById(id).textContent;
            const log = [];
            const note = () => log.push({
                readout: document.body.dataset.readout,
                solves: Number(document.body.dataset.solves),
                name: text("scenario-name"),
                status: text("status"),
                energy: text("energy"),
                max_tension: text("max-tension"),
                licq: text("licq"),
                second_order: text("second-order"),
                error: text("error"),
            });
            new MutationObserver(note).observe(document.body, {
                subtree: true, childList: true, characterData: true,
                attributes: true, attributeFilter: ["data-readout", "data-solves"],
            });
            note();
            window.__readout = log;
        }"""
    )


def readout_log(page: Any) -> list[dict[str, Any]]:
    log: list[dict[str, Any]] = page.evaluate("window.__readout")
    return log
