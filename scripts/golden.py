"""Write tests/data/golden.json: every built-in scenario's status, Newton steps, energy and largest
link tension, as the solver core computes them on this machine.

``tests/test_golden.py`` checks them on every machine the suite runs on (to 1e-12 relative): the
core is built for the baseline x86-64 target without fast-math, so its arithmetic, and with it the
answers, do not depend on the CPU. Regenerate only on purpose (a change to the method), with
``.venv/bin/python scripts/golden.py``, and say why in the commit.
"""

from __future__ import annotations

import json
from pathlib import Path

from funicular._solver import solve
from funicular.scenario import builtin_scenarios, load_scenario

GOLDEN = Path(__file__).resolve().parent.parent / "tests" / "data" / "golden.json"


def main() -> None:
    results = {}
    for name in sorted(builtin_scenarios()):
        solution = solve(load_scenario(name))
        results[name] = {
            "status": solution.status.value,
            "iterations": solution.iterations,
            "objective": solution.objective,
            "max_tension": float(solution.link_tension.max()),
        }
    GOLDEN.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {GOLDEN} ({len(results)} scenarios)")


if __name__ == "__main__":
    main()
