"""Render every built-in scenario into docs/gallery/<name>.png and print a Markdown snippet for the README.

The 3-D scenarios are drawn in perspective (obstacles as wireframes, contact forces as arrows), and
the hanging model also beside its inverted, compression-only form (``hanging-model-inverted.png``).

Run it as ``make gallery`` (or ``.venv/bin/python scripts/gallery.py [OUTPUT_DIR]``). A scenario that
cannot be solved is reported and skipped; the exit status is 1 if any was skipped.
"""

from __future__ import annotations

import sys
from pathlib import Path

from funicular._solver import solve
from funicular.errors import FunicularError
from funicular.inversion import invert
from funicular.plot import draw_hung_and_inverted, save_figure, save_solution_plot
from funicular.scenario import builtin_scenarios, load_scenario
from funicular.solution import Solution

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_OUTPUT = ROOT / "docs" / "gallery"
INVERTED = "hanging-model"  # drawn again beside its inverted form
PALETTE = 256  # colours of a 3-D picture's PNG


def compact(path: Path) -> None:
    """Rewrite a 3-D picture as a palette PNG: its hundreds of anti-aliased links make a full-colour
    PNG several times larger, for no difference seen at this size."""
    from PIL import Image  # (matplotlib's own dependency)

    with Image.open(path) as image:
        quantized = image.convert("RGB").quantize(colors=PALETTE, method=Image.Quantize.MEDIANCUT)
    quantized.save(path, optimize=True)


def save_inverted(solution: Solution, path: Path) -> None:
    inverted = invert(solution)
    save_figure(path, lambda figure: draw_hung_and_inverted(solution, inverted, figure), size=(13, 5.5))


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
        pictures = [path]
        if name == INVERTED:
            pictures.append(output / f"{name}-inverted.png")
            save_inverted(solution, pictures[-1])
        for picture in pictures:
            if solution.problem.dimension == 3:
                compact(picture)
            print(f"wrote {picture} ({solution.status.value})", file=sys.stderr)
            link = picture.relative_to(ROOT) if picture.is_relative_to(ROOT) else picture
            snippet.append(f"| `{name}`: {description} | ![{picture.stem}]({link.as_posix()}) |")
    print("\n".join(snippet))
    return 1 if skipped else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
