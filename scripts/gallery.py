"""Render every built-in scenario into docs/gallery/<name>.png and print a Markdown snippet for the README.

Run it as ``make gallery`` (or ``.venv/bin/python scripts/gallery.py [OUTPUT_DIR]``). A scenario that
cannot be solved is reported and skipped; the exit status is 1 if any was skipped.
"""

from __future__ import annotations

import sys
from pathlib import Path

from funicular._solver import solve
from funicular.errors import FunicularError
from funicular.plot import save_solution_plot
from funicular.scenario import builtin_scenarios, load_scenario

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_OUTPUT = ROOT / "docs" / "gallery"


def main(argv: list[str]) -> int:
    output = Path(argv[0]) if argv else DEFAULT_OUTPUT
    output.mkdir(parents=True, exist_ok=True)
    snippet = ["| scenario | equilibrium |", "|---|---|"]
    skipped = 0
    for name, description in builtin_scenarios().items():
        try:
            solution = solve(load_scenario(name))
        except FunicularError as error:
            print(f"skipped {name}: {error}", file=sys.stderr)
            skipped += 1
            continue
        path = output / f"{name}.png"
        save_solution_plot(solution, path)
        print(f"wrote {path} ({solution.status.value})", file=sys.stderr)
        link = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        snippet.append(f"| `{name}`: {description} | ![{name}]({link.as_posix()}) |")
    print("\n".join(snippet))
    return 1 if skipped else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
