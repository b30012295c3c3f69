"""The explorer's latency: from a pointer move while dragging a support to the redrawn picture.

Starts ``funicular serve two-supports`` on a free loopback port in its own process, opens the page
in headless chromium (Playwright), and for each N sets the number of nodes through the page's own
control, then drags the right support in many small steps, one pointer move per display frame
(about 60 per second, as a mouse sends them). Every solve's latency runs from its pointer event
(``performance.now()`` in a listener this script adds to the page) to the first animation frame
after the page has shown the answer (``document.body.dataset.solves`` incremented).

The page keeps one solve in flight and sends only the newest state, so moves made while a solve
runs are not solved on their own: the table gives the latency of the states that are drawn, the
number of moves that were dropped that way, and, for every move, the time until a picture of that
state or a newer one is drawn.

Run it as ``.venv/bin/python -m bench.explorer [--markdown docs/explorer-latency.md]`` (``make bench``
runs it after the solver benchmark).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.run import machine

# Added to the page before its own script runs; the product is not changed. The listener records
# each pointer move during a drag; the wrapped fetch notes, when a solve is sent, the newest move
# (the state sent is the state after that move); the observer waits for the page to show the answer
# and then for the next animation frame, the redrawn picture.
PROBE = """
(() => {
  const probe = { moves: [], drawn: [] };
  window.__latency = probe;
  let newest = null, pending = null;
  window.addEventListener("pointermove", (event) => {
    if (!event.buttons) return;
    newest = probe.moves.length;
    probe.moves.push(performance.now());
  }, true);
  const realFetch = window.fetch;
  window.fetch = function (input, init) {
    if (String(input).includes("/api/solve")) pending = { move: newest, sent: performance.now() };
    return realFetch.call(this, input, init);
  };
  const observe = () => new MutationObserver(() => {
    const solve = pending;
    pending = null;
    if (!solve) return;
    solve.shown = performance.now();
    requestAnimationFrame(() => { solve.frame = performance.now(); probe.drawn.push(solve); });
  }).observe(document.body, { attributes: true, attributeFilter: ["data-solves"] });
  if (document.body) observe(); else document.addEventListener("DOMContentLoaded", observe);
  probe.reset = () => { probe.moves.length = 0; probe.drawn.length = 0; newest = null; };
})();
"""

IDLE = "document.body.dataset.idle === 'true'"


@dataclass(frozen=True)
class Run:
    nodes: int
    moves: int
    drawn: list[float]  # ms from the move to the frame, per drawn state
    waited: list[float]  # ms from the move until its solve was sent (a solve in flight before it)
    round_trip: list[float]  # ms from sending the solve to the page showing the answer
    any_newer: list[float]  # ms, per move: until a picture of that state or a newer one is drawn


def quantiles(values: Sequence[float]) -> tuple[float, float, float]:
    """p10, median, p90."""
    if len(values) < 2:
        value = values[0] if values else float("nan")
        return value, value, value
    deciles = statistics.quantiles(values, n=10, method="inclusive")
    return deciles[0], statistics.median(values), deciles[-1]


@contextmanager
def server(scenario: str) -> Iterator[str]:
    """``funicular serve`` on a free loopback port in its own process; its URL."""
    command = [sys.executable, "-m", "funicular", "serve", scenario, "--port", "0"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            line = process.stdout.readline() if process.stdout else ""
            if "http://127.0.0.1:" not in line:
                error = process.stderr.read() if process.stderr else ""
                raise RuntimeError(f"the explorer did not start: {line}{error}")
            yield line.split()[3]
        finally:
            process.terminate()
            process.wait(timeout=30)


def drag(page: Any, testid: str, dx: float, dy: float, moves: int, interval: float) -> None:
    """Drag the element by (dx, dy) pixels in ``moves`` pointer moves, one each ``interval`` seconds."""
    box = page.get_by_test_id(testid).bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    start = time.perf_counter()
    for k in range(1, moves + 1):
        delay = start + k * interval - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        page.mouse.move(x + dx * k / moves, y + dy * k / moves)
    page.mouse.up()
    page.wait_for_function(IDLE)
    page.wait_for_timeout(100)  # the last frame


def measure(page: Any, url: str, nodes: int, moves: int, interval: float) -> Run:
    page.goto(url)
    page.wait_for_function(f"Number(document.body.dataset.solves) >= 1 && {IDLE}")
    solves = int(page.evaluate("document.body.dataset.solves"))
    page.fill("#nodes", str(nodes))
    page.dispatch_event("#nodes", "change")
    page.wait_for_function(f"Number(document.body.dataset.solves) > {solves} && {IDLE}")
    drag(page, "support-1", 20, 0, 10, interval)  # warm-up: the solves start from the last answer at this N
    page.evaluate("window.__latency.reset()")
    drag(page, "support-1", -90, -30, moves, interval)
    status = page.get_by_test_id("status").inner_text()
    if status != "optimal":
        raise RuntimeError(f"N = {nodes}: the last solve ended {status!r}")
    probe = page.evaluate("({moves: window.__latency.moves, drawn: window.__latency.drawn})")
    times: list[float] = probe["moves"]
    drawn = [d for d in probe["drawn"] if d["move"] is not None]
    any_newer = []
    for i, t in enumerate(times):
        frames = [d["frame"] for d in drawn if d["move"] >= i]
        if frames:
            any_newer.append(min(frames) - t)
    return Run(
        nodes=nodes,
        moves=len(times),
        drawn=[d["frame"] - times[d["move"]] for d in drawn],
        waited=[d["sent"] - times[d["move"]] for d in drawn],
        round_trip=[d["shown"] - d["sent"] for d in drawn],
        any_newer=any_newer,
    )


def versions() -> str:
    names = ["playwright", "starlette", "uvicorn"]
    found = [f"{name} {importlib.metadata.version(name)}" for name in names]
    return ", ".join(found)


def chromium_version(executable: str) -> str:
    output = subprocess.run([executable, "--version"], capture_output=True, text=True, check=False).stdout
    return output.strip() or "chromium (version unknown)"


def markdown(runs: Sequence[Run], about: dict[str, str], browser: str, interval: float) -> list[str]:
    lines = [
        "# funicular explorer latency",
        "",
        f"Machine: {about['platform']}, {about['cpu']}, {about['cores']} cores, load average "
        f"{about['load_average']} at the start; {about['versions']}, {versions()}; {browser} (headless).",
        "",
        f"`funicular serve two-supports` on a loopback port, N set through the page's nodes field, the right "
        f"support dragged by 90 x 30 pixels in {runs[0].moves if runs else 0} pointer moves, one each "
        f"{interval * 1000:.1f} ms, after a warm-up drag. Latency: from the pointer event (performance.now() "
        "in a listener on the page) to the first animation frame after the page shows the answer to that "
        "state. The page keeps one solve in flight and sends only the newest state, so moves made during a "
        "solve are dropped: the latency columns are of the states that are drawn; 'until a picture' is, for "
        "every move, the time until that state or a newer one is drawn.",
        "",
        "| N | moves | drawn | dropped | latency p10 [ms] | median [ms] | p90 [ms] | of which waiting for the "
        "previous solve (median) [ms] | request to answer shown (median) [ms] | until a picture, every move: "
        "median [ms] | p90 [ms] |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in runs:
        p10, median, p90 = quantiles(r.drawn)
        _, newer_median, newer_p90 = quantiles(r.any_newer)
        lines.append(
            f"| {r.nodes} | {r.moves} | {len(r.drawn)} | {r.moves - len(r.drawn)} | {p10:.1f} | {median:.1f} | "
            f"{p90:.1f} | {statistics.median(r.waited):.1f} | {statistics.median(r.round_trip):.1f} | "
            f"{newer_median:.1f} | {newer_p90:.1f} |"
        )
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--nodes", default="50,100,200", help="comma-separated numbers of nodes (default 50,100,200)")
    parser.add_argument("--moves", type=int, default=60, help="pointer moves per drag (default 60)")
    parser.add_argument("--interval", type=float, default=1 / 60, help="seconds between moves (default 1/60)")
    parser.add_argument("--markdown", metavar="PATH", help="write the table to this Markdown file")
    args = parser.parse_args(argv)
    chromium = shutil.which("chromium")
    if chromium is None:
        print("python -m bench.explorer: no chromium on PATH; scripts/ensure_chromium.sh installs it", file=sys.stderr)
        return 2
    from playwright.sync_api import sync_playwright  # (the test extra)

    about = machine()
    runs = []
    with server("two-supports") as url, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium, headless=True, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.add_init_script(PROBE)
            for nodes in (int(n) for n in args.nodes.split(",")):
                runs.append(measure(page, url, nodes, args.moves, args.interval))
                print(markdown(runs, about, "", args.interval)[-1], flush=True)
        finally:
            browser.close()
    lines = markdown(runs, about, chromium_version(chromium), args.interval)
    print("\n".join(lines))
    if args.markdown:
        Path(args.markdown).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
