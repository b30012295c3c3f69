"""The cores a large net's factorization uses: one thread or two give the same bits, and a thread
count that is not a whole number is refused before any work."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from funicular import ParameterError, solve
from funicular.nets import grid
from funicular.obstacles import Sphere
from test_nets import assert_equilibrium


@pytest.mark.parametrize(
    ("side", "obstacles"),
    [(80, []), (72, [Sphere(center=(0.5, 0.5, -0.45), radius=0.3)])],
    ids=["free", "over-a-sphere"],
)
def test_a_large_net_gives_the_same_bits_on_one_thread_or_two(
    monkeypatch: pytest.MonkeyPatch, side: int, obstacles: list[Sphere]
) -> None:
    """An 80 x 80 net (6,396 free nodes), and a 72 x 72 one draped over a sphere (whose polish
    steps factor the condensed system by L D L^T), are factored in nested-dissection order, split
    in two halves below their top separators, which two threads factor at once: the answer is the
    same to the last bit as on one thread, and it is an equilibrium (checked from positions and
    forces alone)."""
    problem = grid(side, side, slack=1.2, obstacles=obstacles)
    solutions = []
    for threads in ("1", "2"):
        monkeypatch.setenv("FUNICULAR_THREADS", threads)
        solutions.append(solve(problem))
    one, two = solutions
    assert one.status.value == "optimal" and one.iterations == two.iterations
    if obstacles:
        assert one.statistics["polish_steps"] > 0
    assert one.positions.tobytes() == two.positions.tobytes()
    assert one.link_tension.tobytes() == two.link_tension.tobytes()
    assert one.support_reactions.tobytes() == two.support_reactions.tobytes()
    assert one.contact_forces.tobytes() == two.contact_forces.tobytes()
    assert_equilibrium(problem, one, tol=1e-7)


@pytest.mark.parametrize("value", ["0", "two", "-1", "1.5", ""])
def test_a_thread_count_that_is_not_a_whole_number_is_refused(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    monkeypatch.setenv("FUNICULAR_THREADS", value)
    sentence = rf"^FUNICULAR_THREADS must be a whole number .* not {re.escape(repr(value))}\.$"
    with pytest.raises(ParameterError, match=sentence):
        solve(grid(3, 3, slack=1.2))
    code = "import sys\nfrom funicular.cli import main\nsys.exit(main(sys.argv[1:]))"
    result = subprocess.run(
        [sys.executable, "-c", code, "solve", "two-supports"],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
        env={**os.environ, "FUNICULAR_THREADS": value},
    )
    assert result.returncode == 2 and result.stdout == ""
    assert "Traceback" not in result.stderr and result.stderr.startswith("funicular: error: FUNICULAR_THREADS must be")
    assert len(result.stderr.strip().splitlines()) == 1
