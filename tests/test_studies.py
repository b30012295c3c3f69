"""Studies: the continuous and discrete catenary, the refinement study, parameter sweeps.

Expected numbers come from ``tests/oracles.py`` (derived without the package) or from closed
forms written out in each test; each docstring says which, and why the tolerance is what it is.
"""

from __future__ import annotations

import itertools
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from funicular.cli import main
from funicular.errors import ScenarioError
from funicular.model import FloatArray
from funicular.scenario import load_document, load_scenario
from funicular.studies import loglog_slope
from funicular.studies.catenary import ContinuousCatenary, discrete_catenary, log_sinhc, sinh_minus_identity
from funicular.studies.refine import refine
from funicular.studies.sweep import COLD_RESTART, Sweep, SweepStep, flag_jumps, sweep, sweep_text

try:
    import oracles
except ModuleNotFoundError:  # tests/ imported as a package
    from tests import oracles


# --------------------------------------------------------------------------- stable scalar functions
@pytest.mark.parametrize("u", [1e-12, 1e-6, 1e-3, 0.3, 0.999, 1.0, 2.0, 30.0, 700.0, 1e6])
def test_log_sinhc_is_finite_and_accurate(u: float) -> None:
    """log(sinh(u)/u) against its two textbook forms, each where it is exact in floating point.

    Small u: the series u^2/6 - u^4/180 + u^6/2835 (relative 1e-12 while u < 1e-2). Large u: from
    sinh(u) = e^u (1 - e^-2u)/2 (no cancellation for u > 1). Between: math.sinh directly.
    """
    value = log_sinhc(u)
    assert math.isfinite(value)
    if u < 1e-2:
        expected = u**2 / 6 - u**4 / 180 + u**6 / 2835
    elif u < 700:
        expected = math.log(math.sinh(u) / u)
    else:
        expected = u - math.log(2 * u)
    assert value == pytest.approx(expected, rel=1e-12)


def test_sinh_minus_identity_has_no_cancellation() -> None:
    """sinh(z) - z = z^3/6 (1 + z^2/20 + ...) for small z, continuous at the switch to math.sinh at z = 1."""
    assert sinh_minus_identity(1e-5) == pytest.approx(1e-15 / 6, rel=1e-9)
    below, above = sinh_minus_identity(1 - 1e-15), sinh_minus_identity(1.0)
    assert below == pytest.approx(math.sinh(1.0) - 1.0, rel=1e-14) and above == pytest.approx(below, rel=1e-14)


# --------------------------------------------------------------------------- continuous catenary
EXTREMES = [
    pytest.param(1.0000001, 0.0, id="taut-level"),
    pytest.param(1.0000001, 0.4, id="taut-uneven"),
    pytest.param(50.0, 0.0, id="slack-level"),
    pytest.param(50.0, -0.7, id="slack-uneven"),
]


@pytest.mark.parametrize(("factor", "rise"), EXTREMES)
def test_continuous_catenary_extremes(factor: float, rise: float) -> None:
    """Very taut (L = 1.0000001 x span) and very slack (L = 50 x span) ropes: no overflow, and to 1e-10

    * both ends: y(x_left), y(x_right) and position_at_arclength(0), (L) are the supports;
    * length: a polyline through 200,001 points of y(x) is L long (its chord error is below 1e-11 here);
    * shape: the stable y(x) equals the textbook a cosh((x - x0)/a) + c, and every point at arclength s lies on it;
    * balance: the two reactions carry the weight w L and cancel horizontally.
    """
    span, w = 1.0, 2.0
    length = factor * math.hypot(span, rise)
    rope = ContinuousCatenary.between((0.0, 0.0), (span, rise), length, w)
    assert all(math.isfinite(v) for v in (rope.a, rope.x0, rope.c, rope.u, rope.arc_left))
    ends = rope.position_at_arclength(np.array([0.0, length]))
    np.testing.assert_allclose(ends, [[0.0, 0.0], [span, rise]], rtol=0, atol=1e-10 * length)
    np.testing.assert_allclose(rope.y(np.array([0.0, span])), [0.0, rise], rtol=0, atol=1e-10 * length)
    x = np.linspace(0.0, span, 200_001)
    y = rope.y(x)
    assert np.hypot(np.diff(x), np.diff(y)).sum() == pytest.approx(length, rel=1e-10)
    np.testing.assert_allclose(rope.a * np.cosh((x - rope.x0) / rope.a) + rope.c, y, rtol=0, atol=1e-10 * length)
    points = rope.position_at_arclength(np.linspace(0.0, length, 101))
    np.testing.assert_allclose(rope.y(points[:, 0]), points[:, 1], rtol=0, atol=1e-10 * length)
    reactions = rope.reactions
    np.testing.assert_allclose(reactions.sum(axis=0), [0.0, w * length], rtol=1e-12, atol=1e-12 * w * length)


@pytest.mark.parametrize(("factor", "rise"), EXTREMES)
def test_discrete_catenary_tends_to_the_continuous_one(factor: float, rise: float) -> None:
    """At N = 4097 the discrete catenary (masses M/(N-1), halved at the ends) lies on the continuous one.

    Both converge at order 2 (measured: positions 1.6e-6 L, tensions 3e-8 T_max at this N for the
    slack rope), so the bounds are 1e-5 L for the positions and 1e-6 relative for H and the energy.
    """
    n, mass, g = 4097, 1.0, 1.0
    length = factor * math.hypot(1.0, rise)
    rope = ContinuousCatenary.between((0.0, 0.0), (1.0, rise), length, g * mass / length)
    masses = np.full(n, mass / (n - 1))
    masses[[0, -1]] /= 2
    chain = discrete_catenary(masses, np.full(n - 1, length / (n - 1)), g, (0.0, 0.0), (1.0, rise))
    arclength = np.linspace(0.0, length, n)
    np.testing.assert_allclose(chain.positions, rope.position_at_arclength(arclength), rtol=0, atol=1e-5 * length)
    assert chain.horizontal_force == pytest.approx(rope.horizontal_force, rel=1e-6)
    assert chain.energy == pytest.approx(rope.energy(mass, g), rel=1e-6, abs=1e-6 * mass * g * length)


def test_height_integral_matches_quadrature() -> None:
    """The closed form of the integral of y ds against scipy's quad over the arclength (rel 1e-12)."""
    from scipy.integrate import quad

    for length, rise in ((1.5, 0.0), (1.5, 0.3), (3.0, -0.9), (1.01, 0.1)):
        rope = ContinuousCatenary.between((0.2, 0.1), (1.2, 0.1 + rise), length)
        height = rope.position_at_arclength
        expected, _ = quad(lambda s, at=height: float(at(s)[1]), 0.0, length, epsabs=1e-14, epsrel=1e-13)
        assert rope.height_integral() == pytest.approx(expected, rel=1e-12, abs=1e-14)


@pytest.mark.parametrize(
    ("length", "rise"), [(1.5, 0.0), (1.5, 0.3), (1.5, 1.0), (3.0, -0.9), (1.01, 0.1), (2.0, -1.5)]
)
def test_lowest_point_is_the_lowest_of_dense_samples(length: float, rise: float) -> None:
    """Against a bounded scalar minimisation of y over the arclength (the vertex where it lies on
    the rope, the lower support where it does not: rise 1.0 and -1.5 put it beyond a support)."""
    from scipy.optimize import minimize_scalar

    rope = ContinuousCatenary.between((0.2, 0.1), (1.2, 0.1 + rise), length)
    height = rope.position_at_arclength
    found = minimize_scalar(
        lambda s: float(height(s)[1]), bounds=(0.0, length), method="bounded", options={"xatol": 1e-12}
    )
    np.testing.assert_allclose(rope.lowest_point, height(found.x), rtol=0.0, atol=1e-6)
    assert rope.lowest_point[1] <= float(height(np.linspace(0.0, length, 1001))[:, 1].min()) + 1e-15


def test_vertical_supports_are_a_clear_error() -> None:
    with pytest.raises(ScenarioError, match="different x"):
        ContinuousCatenary.between((0.0, 0.0), (0.0, -1.0), 2.0)
    with pytest.raises(ScenarioError, match="longer than their distance"):
        ContinuousCatenary.between((0.0, 0.0), (1.0, 0.0), 1.0)


# --------------------------------------------------------------------------- discrete catenary
@pytest.mark.parametrize("n", [3, 5, 51, 1001])
@pytest.mark.parametrize("right", [(1.0, 0.0), (1.0, 0.5), (1.4999, 0.0), (0.2, -1.3)])
def test_discrete_catenary_matches_the_oracle(n: int, right: tuple[float, float]) -> None:
    """The package's discrete catenary against tests/oracles.py (written separately): positions to
    1e-12 L, tensions and reactions to 1e-9 of the largest tension (the nearly taut chain's tension
    is ~40 W and ill-conditioned in H). A steep chord with few nodes has a slack link: both say so."""
    masses, lengths = np.full(n, 1.0 / n), np.full(n - 1, 1.5 / (n - 1))
    try:
        expected = oracles.discrete_catenary(masses, lengths, 1.0, (0.0, 0.0), right)
    except ValueError:
        expected = None
    if n <= 5 and right == (0.2, -1.3):
        with pytest.raises(ScenarioError, match="slack"):
            discrete_catenary(masses, lengths, 1.0, (0.0, 0.0), right)
        return
    assert expected is not None
    chain = discrete_catenary(masses, lengths, 1.0, (0.0, 0.0), right)
    scale = float(expected.tension.max())
    np.testing.assert_allclose(chain.positions, expected.positions, rtol=0, atol=1e-12 * 1.5)
    np.testing.assert_allclose(chain.tension, expected.tension, rtol=0, atol=1e-9 * scale)
    reactions = np.array([expected.reaction_left, expected.reaction_right])
    np.testing.assert_allclose(chain.reactions, reactions, rtol=0, atol=1e-9 * scale)


def test_discrete_to_continuous_convergence_orders() -> None:
    """Errors of the discrete catenary against the continuous one, N = 9..257, slope over all six N.

    Expected (tolerance 0.1): positions order 2 (the shape depends only on the ratios of the
    inner masses, equal in both lumpings); energy order 2 with trapezoidal masses (M/(N-1) inside,
    half at the ends) but order 1 with with_nodes' equal masses M/N, whose support nodes hold 2M/N
    that never hangs (the (N-1)/N factor again).
    """
    rise, length = 0.3, 1.5
    rope = ContinuousCatenary.between((0.0, 0.0), (1.0, rise), length, 1.0 / length)
    nodes = [9, 17, 33, 65, 129, 257]
    errors: dict[str, list[float]] = {"position": [], "energy equal": [], "energy trapezoid": []}
    for n in nodes:
        lengths = np.full(n - 1, length / (n - 1))
        trapezoid = np.full(n, 1.0 / (n - 1))
        trapezoid[[0, -1]] /= 2
        equal = discrete_catenary(np.full(n, 1.0 / n), lengths, 1.0, (0.0, 0.0), (1.0, rise))
        lumped = discrete_catenary(trapezoid, lengths, 1.0, (0.0, 0.0), (1.0, rise))
        exact = rope.position_at_arclength(np.linspace(0.0, length, n))
        errors["position"].append(float(np.abs(equal.positions - exact).max()))
        errors["energy equal"].append(abs(equal.energy - rope.energy(1.0, 1.0)))
        errors["energy trapezoid"].append(abs(lumped.energy - rope.energy(1.0, 1.0)))
    links = [n - 1 for n in nodes]
    orders = {name: -(loglog_slope(links, values, len(nodes)) or 0.0) for name, values in errors.items()}
    assert orders["position"] == pytest.approx(2.0, abs=0.1)
    assert orders["energy trapezoid"] == pytest.approx(2.0, abs=0.1)
    assert orders["energy equal"] == pytest.approx(1.0, abs=0.1)


# --------------------------------------------------------------------------- refinement study
DANGLING_NODES = [2, 3, 4, 8, 16, 32, 64]


def test_refine_reproduces_the_dangling_chain(tmp_path: Path) -> None:
    """`study refine dangling` (M = 1, L = 1.5, g = 1): every multiplier of both forms equals the exact
    M g (N-1-k)/N and M g (N-1-k)(N-1)/(2 N L) (oracles.py) to 1e-10 relative, N = 2..64; the largest
    squared multiplier M g (N-1)^2/(2 N L) grows with slope 1 +- 0.05 (fit against N-1 over N = 16, 32, 64:
    the exact local slope there is about 1.03), while the largest tension tends to M g."""
    out = tmp_path / "refine.json"
    assert main(["study", "refine", "dangling", "--nodes", ",".join(map(str, DANGLING_NODES)), "--json", str(out)]) == 0
    study = json.loads(out.read_text())
    assert [row["nodes"] for row in study["rows"]] == DANGLING_NODES
    for row in study["rows"]:
        n = row["nodes"]
        assert row["status"] == "optimal"
        assert row["exact_relative_error"] < 1e-10
        squared = oracles.dangling_squared_multipliers(n, 1.0, 1.5, 1.0)
        assert row["squared_multiplier_max"] == pytest.approx(squared.max(), rel=1e-10)
        assert row["squared_multiplier_min"] == pytest.approx(squared.min(), rel=1e-10)
        assert row["tension_max"] == pytest.approx(oracles.dangling_tensions(n, 1.0, 1.0).max(), rel=1e-10)
        assert row["exact_squared_multiplier_max"] == pytest.approx((n - 1) ** 2 / (2 * n * 1.5), rel=1e-14)
        assert row["support_reactions"] == [pytest.approx([0.0, 1.0], abs=1e-12)]
    assert study["orders"]["squared_multiplier_max_growth"] == pytest.approx(1.0, abs=0.05)
    assert abs(study["orders"]["tension_max_growth"]) < 0.05
    assert any("(N-1)/N" in note for note in study["notes"])


def test_refine_two_supports_against_both_catenaries(tmp_path: Path) -> None:
    """uneven-supports through the solver, N = 9..129: the solver matches the discrete catenary to
    1e-8 relative (its KKT tolerance is 1e-10 of the weight); against the continuous catenary the
    positions converge at order 2 and energy and tensions at order 1 (with_nodes' M/N lumping), +- 0.15."""
    plot = tmp_path / "refine.png"
    study = refine(load_scenario("uneven-supports"), [9, 17, 33, 65, 129])
    assert study.reference.startswith("discrete catenary")
    for row in study.rows:
        assert row.status == "optimal" and row.exact_error is not None and row.exact_error < 1e-8
    orders = study.orders
    assert orders["continuous_position_error_order"] == pytest.approx(2.0, abs=0.15)
    assert orders["continuous_energy_error_order"] == pytest.approx(1.0, abs=0.15)
    assert orders["continuous_tension_error_order"] == pytest.approx(1.0, abs=0.15)
    assert main(["study", "refine", "uneven-supports", "--nodes", "5,9", "--plot", str(plot)]) == 0
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_refine_prints_each_error_divided_by_the_scale_its_header_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """two-supports (M = 1, L = 1.5, g = 1, supports (0, 0) and (1, 0)): the printed energy error is
    |E_N - E| over the M g L its header names (at N = 257, 0.00118 / 1.5 = 0.000786), E the
    continuous catenary's energy g (M / L) integral of y ds, here from sinh(u)/u = L/D (brentq) and
    the trapezoidal rule on 200,001 points (1e-10); E_N from the JSON. The caption names every scale."""
    from scipy.optimize import brentq

    out = tmp_path / "refine.json"
    assert main(["study", "refine", "two-supports", "--nodes", "9,33,257", "--json", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    mass, length, g, span = 1.0, 1.5, 1.0, 1.0
    u = brentq(lambda u: math.sinh(u) / u - length / span, 1e-6, 10.0, xtol=1e-15)
    a = span / (2 * u)
    x = np.linspace(-span / 2, span / 2, 200_001)
    y = a * np.cosh(x / a) - a * np.cosh(u)
    limit = g * mass / length * np.trapezoid(y * np.cosh(x / a), x)
    lines = text.splitlines()
    header = next(line for line in lines if line.lstrip().startswith("N ") and "energy err" in line)
    headers = re.split(r"\s{2,}", header.strip())
    column = headers.index("energy err / (M g L)")
    assert {"tension err / (M g)", "position err / L"} <= set(headers)
    rows = {int(line.split()[0]): re.split(r"\s{2,}", line.strip()) for line in lines[lines.index(header) + 2 :][:3]}
    for row in json.loads(out.read_text())["rows"]:
        printed = float(rows[row["nodes"]][column])
        assert printed == pytest.approx(abs(row["energy"] - limit) / (mass * g * length), rel=1e-5)
    assert float(rows[257][column]) == pytest.approx(0.000786, rel=1e-3)
    assert "|E_N - E| / (M g L), max |T_k - T(s_k)| / (M g), max |p_i - p(s_i)| / L" in text


def test_refine_rejects_bad_node_lists(capsys: pytest.CaptureFixture[str]) -> None:
    for nodes in ("1,3", "3,x", "", "2.5"):
        assert main(["study", "refine", "dangling", "--nodes", nodes]) == 2
        err = capsys.readouterr().err
        assert err.startswith("funicular: error: --nodes") and err.count("\n") == 1


# --------------------------------------------------------------------------- sweeps
BAD_SETTINGS = [
    pytest.param(["chain.lenght=1:2:3"], "chain.lenght", id="unknown-key"),
    pytest.param(["chian.length=1:2:3"], "chian", id="unknown-table"),
    pytest.param(["supports[2].position[0]=1:2:3"], "supports[2]", id="index-out-of-range"),
    pytest.param(["supports.1.position[0]=1:2:3"], "as in supports[0]", id="index-after-a-dot"),
    pytest.param(["chain.length=1:2:0"], "COUNT = 0", id="count-zero"),
    pytest.param(["chain.length=1:2:-3"], "COUNT = -3", id="count-negative"),
    pytest.param(["chain.length=1:2"], "KEY=START:STOP:COUNT", id="two-fields"),
    pytest.param(["chain.length=a:2:3"], "KEY=START:STOP:COUNT", id="not-a-number"),
    pytest.param(["chain.length=1:2:2.5"], "KEY=START:STOP:COUNT", id="fractional-count"),
    pytest.param(["chain.length=1:inf:3"], "finite", id="infinite"),
    pytest.param(["=1:2:3"], "KEY=START:STOP:COUNT", id="no-key"),
    pytest.param(["chain.nodes=3:10:3"], "integers", id="fractional-nodes"),
    pytest.param(["description=1:2:3"], "not a number", id="not-numeric"),
    pytest.param([], "one or two --set", id="none"),
    pytest.param(["gravity=1:2:2"] * 3, "one or two --set", id="three"),
]


@pytest.mark.parametrize(("settings", "message"), BAD_SETTINGS)
def test_sweep_bad_settings_exit_2(settings: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Each mistake is one sentence on stderr and exit status 2, before anything is solved."""
    args = [item for text in settings for item in ("--set", text)]
    assert main(["sweep", "two-supports", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("funicular: error: ") and message in err and err.count("\n") == 1
    with pytest.raises(ScenarioError):
        sweep(load_document("two-supports"), settings)


def _capped(*args: str) -> subprocess.CompletedProcess[str]:
    """``funicular ARGS`` with its address space capped at 2 GiB: a count that were allocated
    before it is checked fails fast here instead of filling the machine's memory."""
    import resource

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))

    return subprocess.run(
        [sys.executable, "-m", "funicular.cli", *args], capture_output=True, text=True, check=False, timeout=120,
        preexec_fn=cap,
    )  # fmt: skip


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        (["chain.length=1:2:1000000000"], "1,000,000,000 steps"),
        (["chain.length=1:2:100001"], "100,001 steps"),
        (["chain.length=1:2:1000", "gravity=1:2:1000"], "1,000,000 steps (1,000 x 1,000)"),
    ],
    ids=["billion", "just-over", "grid"],
)
def test_a_sweep_of_more_steps_than_it_takes_is_refused_before_anything_is_made(
    tmp_path: Path, settings: list[str], words: str
) -> None:
    """`funicular sweep --set chain.length=1:2:1000000000` was killed for memory: the steps are
    counted from the COUNTs (a grid's multiplied) and more than 100,000 are refused in one
    sentence, exit 2, nothing written."""
    out = tmp_path / "sweep.json"
    result = _capped("sweep", *(item for text in settings for item in ("--set", text)), "--json", str(out))
    assert result.returncode == 2 and "Traceback" not in result.stderr and result.stderr.count("\n") == 1
    assert words in result.stderr and "at most 100,000 steps" in result.stderr and "--set" in result.stderr
    assert not out.exists()


def test_sweep_chain_length_gives_monotone_energy(tmp_path: Path) -> None:
    """A longer chain between the same supports hangs lower: energy strictly decreasing, no jumps."""
    out, plot = tmp_path / "sweep.json", tmp_path / "sweep.png"
    status = main(
        ["sweep", "two-supports", "--set", "chain.length=1.1:2.0:10", "--json", str(out), "--plot", str(plot)]
    )
    assert status == 0
    steps = json.loads(out.read_text())["steps"]
    energies = [step["energy"] for step in steps]
    assert [step["values"]["chain.length"] for step in steps] == pytest.approx(np.linspace(1.1, 2.0, 10))
    assert all(step["status"] == "optimal" and not step["jump"] for step in steps)
    assert all(later < earlier for earlier, later in itertools.pairwise(energies))
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sweep_grid_and_failed_steps(capsys: pytest.CaptureFixture[str]) -> None:
    """Two keys make a grid (rows: the first key); an infeasible step is marked, the sweep goes on, exit 1."""
    result = sweep(load_document("two-supports"), ["chain.nodes=3:11:3", "chain.length=0.5:1.5:2"])
    assert [[step.values for step in row] for row in result.rows] == [
        [(3, 0.5), (3, 1.5)],
        [(7, 0.5), (7, 1.5)],
        [(11, 0.5), (11, 1.5)],
    ]
    assert [step.status for step in result.steps] == ["infeasible", "optimal"] * 3
    assert [step.taut_links for row in result.rows for step in row[1:]] == [2, 6, 10]
    assert main(["sweep", "two-supports", "--set", "chain.length=0.5:1.5:3"]) == 1
    out = capsys.readouterr().out
    assert "not solved at chain.length = 0.5: infeasible" in out


def test_jump_rule() -> None:
    """A step whose largest node move exceeds both neighbouring moves, 4x the median of the moves up to
    two steps either side and 1 % of L is a jump; failed steps are skipped; a row with one move flags
    nothing."""

    def row(offsets: list[float | None]) -> list[SweepStep]:
        steps = []
        for i, offset in enumerate(offsets):
            positions = None if offset is None else np.array([[0.0, 0.0], [offset, -1.0]])
            status = "optimal" if offset is not None else "max_iterations"
            steps.append(SweepStep(values=(float(i),), status=status, positions=positions, length=1.0))
        return steps

    def moved(moves: list[float]) -> list[SweepStep]:
        """A row whose successive moves are ``moves`` (the second node slides sideways)."""
        return row([0.0, *itertools.accumulate(moves)])

    smooth_then_jump = row([0.0, 0.02, 0.04, 0.5, 0.52, 0.54])
    flag_jumps(smooth_then_jump)
    assert [step.jump for step in smooth_then_jump] == [False, False, False, True, False, False]
    assert smooth_then_jump[3].move == pytest.approx(0.46)
    across_failure = row([0.0, 0.02, None, 0.5, 0.52])
    flag_jumps(across_failure)
    assert [step.jump for step in across_failure] == [False, False, False, True, False]
    tiny = row([0.0, 0.001, 0.002, 0.009, 0.01])  # 7x the neighbours, but only 0.7 % of L
    flag_jumps(tiny)
    assert not any(step.jump for step in tiny)
    alone = row([0.0, 0.5])
    flag_jumps(alone)
    assert not any(step.jump for step in alone)
    # disk-drape's disk moved sideways across the middle in steps of 0.01 (the moves measured there): the
    # chain switches to the mirror-image drape (0.127) and the new branch still moves fast (0.038), which
    # "more than 4x both neighbours" missed; against the median (0.018) it is a jump.
    masked = moved([0.0147, 0.0182, 0.127, 0.0377, 0.0182, 0.0147])
    flag_jumps(masked)
    assert [step.jump for step in masked] == [False, False, False, True, False, False, False]
    # approaching a fold the branch steepens (0.02, 5x the median around it) right before the jump: only
    # the jump, the local maximum, is flagged
    fold = moved([0.003, 0.003, 0.004, 0.02, 0.27, 0.003, 0.003])
    flag_jumps(fold)
    assert [step.jump for step in fold] == [False] * 5 + [True, False, False]
    # a jump and a jump back two steps later are both flagged
    there_and_back = moved([0.01, 0.01, 0.3, 0.01, 0.3, 0.01, 0.01])
    flag_jumps(there_and_back)
    assert [step.jump for step in there_and_back] == [False, False, False, True, False, True, False, False]


# A chain hanging from one support whose end rests on a disk below it. The disk's top is 0.3 below the
# support and the chain 0.4 long, so its last 0.1 or so lies on the disk, off to one side of the top.
FLIP_LENGTH, FLIP_RADIUS, FLIP_DEPTH = 0.4, 0.3, 0.6
DISK_FLIP = f"""
description = "A 31-node chain of length 0.4 hanging from one support, its end resting on a disk below."
gravity = 1.0

[chain]
nodes = 31
length = {FLIP_LENGTH}
mass = 1.0

[[supports]]
node = 0
position = [0.0, 0.0]

[[obstacles]]
shape = "disk"
name = "disk"
center = [-0.1, -{FLIP_DEPTH}]
radius = {FLIP_RADIUS}
"""
FLIP_STEP = 0.005  # the disk moves this far per step


def sweep_disk_flip(tmp_path: Path, start: float, stop: float) -> Sweep:
    """Sweep the disk's centre x of DISK_FLIP from ``start`` to ``stop`` in steps of FLIP_STEP."""
    path = tmp_path / "disk-flip.toml"
    path.write_text(DISK_FLIP)
    count = round((stop - start) / FLIP_STEP) + 1
    return sweep(load_document(path), [f"obstacles[0].center[0]={start}:{stop}:{count}"])


def positions(step: SweepStep) -> FloatArray:
    assert step.positions is not None
    return step.positions


def end_offset(step: SweepStep) -> float:
    """How far right of the disk's centre (the swept value) the chain's end is, after checking it lies on the disk."""
    centre = np.array([step.values[0], -FLIP_DEPTH])
    assert math.hypot(*(positions(step)[-1] - centre)) == pytest.approx(FLIP_RADIUS, abs=1e-6)
    return float(positions(step)[-1, 0] - centre[0])


def node_moves(steps: list[SweepStep]) -> list[float]:
    """The largest node displacement between consecutive steps, recomputed from their positions."""
    return [float(np.max(np.hypot(*(positions(b) - positions(a)).T))) for a, b in itertools.pairwise(steps)]


def test_sweep_disk_moving_sideways_flips_the_chain_over_it(tmp_path: Path) -> None:
    """The disk moves from 0.1 left of the support to 0.1 right of it in steps of 0.005. At the start the
    chain comes down right of the disk's top and its end rests on the disk's right shoulder; by mirror
    symmetry the equilibria at c are the mirror images of those at -c, so near c = 0 both sides are
    equilibria. Warm-started, the chain stays on the right past c = 0, until it slides over the top onto
    the left shoulder: one jump, and exactly one is flagged. The right-side branch ends in a fold at
    c = 0.0595 (continued with scipy's SLSQP on the same chain in steps of 0.00005, the largest node move
    per step grows 0.0002, 0.0003, 0.0005, 0.0007, 0.0016, then the chain slides over: 0.25), so by
    c = 0.06 the jump is forced; funicular's solver may leave the branch a little earlier, for the
    mirror-image minimum that coexists with it, which is a jump as well.

    Checked from the positions alone: the end lies on the disk at every converged step (to 1e-6); its side
    of the centre changes exactly once, from right to left, at the flagged step, at 0 < c <= 0.06 (the
    hysteresis); that step moves a node by more than L/2 and lowers g m^T y by more than 10x any other
    step's change, while every other step moves the nodes by less than 2x the disk's step. After the jump
    the chain is the mirror image of itself at -c (to 1e-6 L); before it, at 0 <= c, it is not (it is on
    the other branch). The solver may fail to converge while the chain slides (it did with 29 or 33
    nodes): such steps may only lie inside the jump, and the jump is then flagged at the next converged
    step."""
    result = sweep_disk_flip(tmp_path, -0.1, 0.1)
    steps = result.steps
    assert len(steps) == 41 and steps[0].converged and steps[-1].converged
    converged = [step for step in steps if step.converged]
    sides = [math.copysign(1.0, end_offset(step)) for step in converged]
    flips = [i for i in range(1, len(sides)) if sides[i] != sides[i - 1]]
    assert sides[0] == 1.0 and len(flips) == 1
    before, after = converged[flips[0] - 1], converged[flips[0]]
    assert [step for step in steps if step.jump] == [after]
    assert 0 < after.values[0] <= 0.06 + 1e-12
    assert all(before.values[0] < step.values[0] < after.values[0] for step in steps if not step.converged)
    assert sum(line.rstrip().endswith("JUMP") for line in sweep_text(result).splitlines()) == 1

    moves = node_moves(converged)
    energies = [float(np.mean(positions(step)[:, 1])) for step in converged]  # g m^T y: g = 1, masses 1/N
    changes = [abs(b - a) for a, b in itertools.pairwise(energies)]
    jump = flips[0] - 1  # index of the move from before to after
    assert moves[jump] > 0.5 * FLIP_LENGTH
    assert after.move == pytest.approx(moves[jump])
    assert max(moves[:jump] + moves[jump + 1 :]) < 2 * FLIP_STEP
    assert energies[jump] - energies[jump + 1] > 10 * max(changes[:jump] + changes[jump + 1 :])

    def mirror_distance(step: SweepStep) -> float:
        partner = min(steps, key=lambda other: abs(other.values[0] + step.values[0]))
        assert partner.values[0] == pytest.approx(-step.values[0], abs=1e-12) and partner.converged
        mirrored = positions(step) * np.array([-1.0, 1.0])
        return float(np.max(np.hypot(*(mirrored - positions(partner)).T)))

    assert all(mirror_distance(step) < 1e-6 * FLIP_LENGTH for step in converged if step.values[0] >= after.values[0])
    assert all(mirror_distance(step) > 0.1 for step in converged if 0 <= step.values[0] <= before.values[0])


def test_sweep_disk_moving_smoothly_flags_no_jump(tmp_path: Path) -> None:
    """Negative control: the same disk moving from 0.1 left of the support up to below it, where the chain
    stays on the right shoulder (one branch, no fold): every step converges, the end stays on the disk
    right of its centre, no node moves more than 2x the disk's step, and nothing is flagged."""
    result = sweep_disk_flip(tmp_path, -0.1, 0.0)
    steps = result.steps
    assert len(steps) == 21 and all(step.converged for step in steps)
    assert all(end_offset(step) > 0 for step in steps)
    assert max(node_moves(steps)) < 2 * FLIP_STEP
    assert not any(step.jump for step in steps)


def test_a_warm_start_that_fails_is_retried_from_the_default_guess(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A warm-started solve that does not converge (at a fold it can wander off) is repeated from the
    default initial guess, and the step's message says so. The solver now converges from every warm
    start of this sweep, so the failure is injected: the 12th warm-started solve gets one Newton step."""
    import funicular.studies.sweep as sweep_module

    real_solve = sweep_module.solve
    warm_calls = itertools.count(1)

    def solve_failing_once(problem: object, **options: object) -> object:
        if options.get("initial_positions") is not None and next(warm_calls) == 12:
            return real_solve(problem, **{**options, "max_iterations": 1})  # type: ignore[arg-type]
        return real_solve(problem, **options)  # type: ignore[arg-type]

    monkeypatch.setattr(sweep_module, "solve", solve_failing_once)
    path = tmp_path / "disk-flip.toml"
    path.write_text(DISK_FLIP)
    result = sweep(load_document(path), ["obstacles[0].center[0]=-0.1:0.1:41"])
    steps = [step for row in result.rows for step in row]
    assert all(step.converged for step in steps)
    assert [i for i, step in enumerate(steps) if step.message == COLD_RESTART] == [12]
    assert sum(step.jump for step in steps) == 1
    sides = [end_offset(step) > 0 for step in steps]
    assert sides[0] and not sides[-1]
    assert sum(a != b for a, b in itertools.pairwise(sides)) == 1
