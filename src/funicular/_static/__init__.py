"""Files shipped for the browser, in one place: ``view3d.js``, the interactive 3-D view of an
equilibrium that the HTML report inlines and the explorer (``funicular serve``) loads."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

VIEW3D = Path(str(files(__name__) / "view3d.js"))


def view3d_script() -> str:
    """The 3-D view's script: it defines ``funicularView3D(canvas, data)``."""
    return VIEW3D.read_text(encoding="utf-8")
