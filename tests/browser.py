"""What the browser tests read off a page (the pages are driven by Playwright in the tests)."""

from __future__ import annotations

from typing import Any


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
