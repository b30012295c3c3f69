"""Units on the outputs: a scenario that declares ``units = "SI"`` has every output label its forces,
lengths, masses, energies and gravity (N, m, kg, J, m/s^2); one that declares none has no output name
a unit, since its numbers are in whatever consistent units its author chose. The declaration changes
labels only: the same scenario with and without it gives the same numbers, which the tests check by
stripping the labels from the SI output and comparing it with the unlabelled one."""

from __future__ import annotations

import html
import json
import re
from collections.abc import Iterator
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from funicular import load_scenario, solve
from funicular._units import SYSTEMS, declared, force_unit, label, length_unit, multiplier_unit, unit, with_unit
from funicular.backends import Row, compare_table
from funicular.cli import main
from funicular.errors import ScenarioError
from funicular.explorer._state import solve_state, state_of_scenario
from funicular.model import UNIT_SYSTEMS, Problem

UNIT = r"(?:m/s\^2|N/m|kg|N|m|J)"  # every unit an SI output writes, longest first
BRACKETED = re.compile(rf"\[{UNIT}\]")  # a label's or a header's unit: "x [m]"
AFTER_NUMBER = re.compile(rf"(?<=[\d)]) {UNIT}(?![\w/^])")  # a number's unit: "0.5 N", "(0, -1) N"
# Node counts, which are not units: the refinement study's "last 3 N" (its fits use the last 3 N).
NODE_COUNTS = re.compile(r"last \d+ N\b")
WALL_TIME = re.compile(r"\b\d[\d.e+-]* s\b")  # seconds of wall time are labelled with or without units


def units_named(text: str) -> list[str]:
    """Every unit ``text`` names, bracketed or after a number ("Nodes" or "N = 5" are not units)."""
    text = NODE_COUNTS.sub("", text)
    return BRACKETED.findall(text) + AFTER_NUMBER.findall(text)


def unlabelled(text: str) -> str:
    """``text`` with its units taken out, its wall times blanked and its spacing and rules collapsed
    (a header with a unit widens its column): what the same output without declared units must read."""
    text = re.sub(rf" \[{UNIT}\]", "", text)
    text = AFTER_NUMBER.sub("", text)
    text = WALL_TIME.sub("TIME s", text)
    text = re.sub(r"-{2,}", "--", text)
    return " ".join(text.split())


def declaring_si(name: str, directory: Path) -> Path:
    """The built-in scenario ``name`` written to ``directory/name.toml`` (so it keeps its name) with
    ``units = "SI"`` put in front, and nothing else changed."""
    text = (files("funicular") / "scenarios" / f"{name}.toml").read_text(encoding="utf-8")
    path = directory / f"{name}.toml"
    path.write_text('units = "SI"\n' + text, encoding="utf-8")
    return path


@pytest.fixture
def si_dir(tmp_path: Path) -> Path:
    directory = tmp_path / "si"
    directory.mkdir()
    return directory


# ----------------------------------------------------------------- the rule
def test_the_rule_labels_what_is_declared_and_nothing_else() -> None:
    # Every system a scenario may declare has its units here, and no other.
    assert set(SYSTEMS) == {system for system in UNIT_SYSTEMS if system is not None}
    assert SYSTEMS["SI"] == {
        "force": "N",
        "length": "m",
        "mass": "kg",
        "gravity": "m/s^2",
        "energy": "J",
        "force_per_length": "N/m",
    }
    plain = Problem.build(nodes=3, length=2.0, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0))])
    si = Problem.build(nodes=3, length=2.0, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0))], units="SI")
    for quantity in SYSTEMS["SI"]:
        assert unit(plain, quantity) == unit(None, quantity) == ""
        assert unit(si, quantity) == unit("SI", quantity) == SYSTEMS["SI"][quantity]
    assert (force_unit(si), length_unit(si), force_unit(plain), length_unit(plain)) == ("N", "m", "", "")
    assert (multiplier_unit(si, "norm"), multiplier_unit(si, "squared"), multiplier_unit(plain, "squared")) == (
        "N",
        "N/m",
        "",
    )
    assert (with_unit("0.5", "N"), with_unit("0.5", ""), label("x", "m"), label("x", "")) == (
        "0.5 N",
        "0.5",
        "x [m]",
        "x",
    )
    assert (declared("SI"), declared(None), declared("imperial"), declared(3)) == ("SI", None, None, None)


def test_an_unknown_unit_system_is_one_sentence_naming_the_key(tmp_path: Path) -> None:
    path = tmp_path / "feet.toml"
    path.write_text('units = "imperial"\n[chain]\nnodes = 3\nlength = 1.0\nmass = 1.0\n[[supports]]\nnode = 0\n'
                    "position = [0.0, 0.0]\n", encoding="utf-8")  # fmt: skip
    with pytest.raises(ScenarioError, match="units = 'imperial' is not a unit system") as error:
        load_scenario(path)
    assert str(error.value).startswith(str(path)) and str(error.value).count(". ") == 0


def test_declaring_units_changes_no_number(si_dir: Path) -> None:
    plain, si = solve(load_scenario("disk-drape")), solve(load_scenario(declaring_si("disk-drape", si_dir)))
    assert si.problem.units == "SI" and plain.problem.units is None
    assert np.array_equal(plain.positions, si.positions)
    assert np.array_equal(plain.link_tension, si.link_tension)
    assert np.array_equal(plain.support_reactions, si.support_reactions)
    assert np.array_equal(plain.contact_forces, si.contact_forces)
    assert plain.objective == si.objective


# ----------------------------------------------------------------- the command line's text
@pytest.mark.parametrize("name", ["two-supports", "disk-drape"])
def test_the_summary_and_the_force_table(name: str, si_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solve", name, "--table"]) == 0
    plain = capsys.readouterr().out
    assert main(["solve", str(declaring_si(name, si_dir)), "--table"]) == 0
    si = capsys.readouterr().out
    assert units_named(plain) == []
    assert unlabelled(si) == unlabelled(plain)  # labels only
    solution = solve(load_scenario(name))
    top = float(solution.link_tension.max())
    assert re.search(rf"max tension +{top:.10g} N in link", si)
    assert "g = 1 m/s^2" in si and re.search(r"energy +-?[\d.]+ J ", si)
    assert re.search(r"node 0 +Fx = -?[\d.e-]+ N +Fy = +[\d.e-]+ N", si)
    assert "(weight 1 N" in si
    for header in ("mu_k = T_k [N]", "tension T_k [N]", "length d_k [m]", "max l_k [m]"):
        assert header in si
    if name == "disk-drape":  # contact forces and how deep links cut into the disk
        assert re.search(r"total Fx = [\d.e-]+ N, Fy = [\d.e-]+ N", si)
        assert re.search(r"deepest [\d.e-]+ m\)", si)
        assert "contact Fx [N]" in si


def test_a_squared_multiplier_is_a_force_per_length(si_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solve", str(declaring_si("two-supports", si_dir)), "--table", "--formulation", "squared"]) == 0
    assert "mu_k = T_k/(2 d_k) [N/m]" in capsys.readouterr().out


def test_the_studies_tables(si_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """study refine, sweep and explore print their tables with units only where they are declared."""
    si_path = str(declaring_si("two-supports", si_dir))
    commands = (
        ["study", "refine", "{}", "--nodes", "3,5,9", "--quiet"],
        ["sweep", "{}", "--set", "chain.length=1.2:1.5:3", "--quiet"],
        ["explore", "{}", "--starts", "2", "--quiet"],
    )
    expected = (
        ("M = 1 kg, L = 1.5 m, g = 1 m/s^2", "tension max [N]", "squared mu max [N/m]", "energy [J]", "R0 x [N]"),
        ("energy [J]", "max tension [N]", "contact force [N]"),
        ("energy [J]", "max tension [N]", "contact force [N]"),
    )
    for command, headers in zip(commands, expected, strict=True):
        assert main([word.format("two-supports") for word in command]) == 0
        plain = capsys.readouterr().out
        assert main([word.format(si_path) for word in command]) == 0
        si = capsys.readouterr().out
        assert units_named(plain) == [], command
        assert unlabelled(si) == unlabelled(plain), command
        for header in headers:
            assert header in si, (command, header)


def test_the_comparison_table(si_dir: Path) -> None:
    plain = solve(load_scenario("two-supports"))
    si = solve(load_scenario(declaring_si("two-supports", si_dir)))
    plain_table = compare_table([Row("funicular", plain, None, 0.5)])
    si_table = compare_table([Row("funicular", si, None, 0.5)])
    assert units_named(plain_table) == []
    assert unlabelled(si_table) == unlabelled(plain_table)
    assert {"energy [J]", "max |dp| [m]", "max |dT| [N]"} <= set(re.split(r"\s{2,}| (?=max)", si_table.splitlines()[0]))


# ----------------------------------------------------------------- the inverted form's files
def test_the_inverted_forms_files_and_lines(si_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plain_obj, si_obj = tmp_path / "plain.obj", tmp_path / "si.obj"
    assert main(["invert", "hanging-model", "--output", str(plain_obj)]) == 0
    plain_out = capsys.readouterr().out
    assert main(["invert", str(declaring_si("hanging-model", si_dir)), "--output", str(si_obj)]) == 0
    si_out = capsys.readouterr().out
    plain_text, si_text = plain_obj.read_text(), si_obj.read_text()
    plain_csv, si_csv = plain_obj.with_suffix(".csv").read_text(), si_obj.with_suffix(".csv").read_text()
    for text in (plain_out, plain_text, plain_csv):
        assert units_named(text) == [] and re.search(r"\bN\b|newton", text) is None

    # The same numbers: every vertex, link, face and force line, and every CSV row but the header.
    def data(obj: str) -> list[str]:
        return [line for line in obj.splitlines() if not line.startswith("# ") or line.startswith(("# axial", "# sup"))]

    assert data(si_text) == data(plain_text)
    assert si_csv.splitlines()[1:] == plain_csv.splitlines()[1:]
    assert si_csv.splitlines()[0] == "link,node_i,node_j,length [m],axial_force [N]"
    assert plain_csv.splitlines()[0] == "link,node_i,node_j,length,axial_force"
    comments = [line for line in si_text.splitlines() if line.startswith("# ") and line not in plain_text]
    assert "# coordinates (v lines) in m, forces in N" in comments
    assert any("carries the axial force VALUE in N" in line for line in comments)
    assert any(line.endswith("support NODE (0-based), in N") for line in comments)
    assert re.search(r"the largest [\d.e-]+ N\n", si_out) and re.search(r"pressed down with [\d.e-]+ N in all", si_out)
    assert unlabelled(si_out.replace(str(si_obj), "OUT").replace(str(si_obj.with_suffix(".csv")), "CSV")) == (
        unlabelled(plain_out.replace(str(plain_obj), "OUT").replace(str(plain_obj.with_suffix(".csv")), "CSV"))
    )


# ----------------------------------------------------------------- the pictures
pytest.importorskip("matplotlib")


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[Any]]:
    """Every figure the command line saves, kept to read its texts."""
    from matplotlib.figure import Figure

    figures: list[Any] = []
    save = Figure.savefig

    def keep(self: Any, *args: Any, **kwargs: Any) -> None:
        figures.append(self)
        save(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    yield figures


def texts(figure: Any) -> list[str]:
    """Every text on ``figure``: titles, axis labels, legends, annotations, colour-bar labels, ticks."""
    from matplotlib.text import Text

    return [text.get_text() for text in figure.findobj(Text) if text.get_text()]


def _plotted(command: list[str], drawn: list[Any]) -> list[str]:
    drawn.clear()
    assert main(command) == 0
    assert len(drawn) == 1
    return texts(drawn[0])


def si_plot_labels(solution: Any) -> set[str]:
    """What the plot of ``solution`` must say with SI units: its axes, colour bar and title, each
    support reaction's label (planar) or their legend (in space), and the contact forces' legend."""
    problem = solution.problem
    reactions = np.linalg.norm(solution.support_reactions, axis=1)
    contact = np.linalg.norm(solution.contact_forces, axis=1)
    labels = {f"{axis} [m]" for axis in "xyz"[: problem.dimension]} | {"link tension [N]"}
    labels.add(f"{problem.name}: optimal, max tension {solution.link_tension.max():.4g} N")
    if problem.dimension == 2:
        labels |= {f"R={reaction:.3g} N" for reaction in reactions}
    else:
        labels.add(f"support reactions (largest {reactions.max():.3g} N)")
    if contact.max() > 0:
        labels.add(f"contact forces (largest {contact.max():.3g} N, own scale)")
    return labels


@pytest.mark.parametrize("name", ["two-supports", "disk-drape", "hanging-model"])
def test_solve_plot(
    name: str, si_dir: Path, tmp_path: Path, drawn: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    plain = _plotted(["solve", name, "--plot", str(tmp_path / "plain.png")], drawn)
    si = _plotted(["solve", str(declaring_si(name, si_dir)), "--plot", str(tmp_path / "si.png")], drawn)
    capsys.readouterr()
    assert units_named("\n".join(plain)) == []
    assert [unlabelled(text) for text in si] == [unlabelled(text) for text in plain]
    expected = si_plot_labels(solve(load_scenario(name)))
    assert expected <= set(si), sorted(expected - set(si))


def test_the_inverted_form_and_several_equilibria(si_dir: Path) -> None:
    from matplotlib.figure import Figure

    from funicular.inversion import invert
    from funicular.plot import draw_equilibria, draw_hung_and_inverted

    plain, si = solve(load_scenario("hanging-model")), solve(load_scenario(declaring_si("hanging-model", si_dir)))
    figures = {}
    for key, solution in (("plain", plain), ("si", si)):
        figure = Figure()
        draw_hung_and_inverted(solution, invert(solution), figure)
        figures[key] = texts(figure)
    assert units_named("\n".join(figures["plain"])) == []
    assert "link compression [N]" in figures["si"] and "z [m]" in figures["si"]
    assert any(re.fullmatch(r"hanging-model inverted: max compression [\d.]+ N", text) for text in figures["si"])
    assert [unlabelled(text) for text in figures["si"]] == [unlabelled(text) for text in figures["plain"]]
    for key, name in (("plain", "peg-two-ways"), ("si", str(declaring_si("peg-two-ways", si_dir)))):
        figure = Figure()
        draw_equilibria([solve(load_scenario(name))], figure)
        figures[key] = texts(figure)
    assert units_named("\n".join(figures["plain"])) == []
    assert {"x [m]", "y [m]"} <= set(figures["si"]) and any(re.search(r"E = -?[\d.]+ J$", t) for t in figures["si"])


def test_the_studies_plots(si_dir: Path, tmp_path: Path, drawn: list[Any], capsys: pytest.CaptureFixture[str]) -> None:
    si_path = str(declaring_si("two-supports", si_dir))
    refine = ["study", "refine", "{}", "--nodes", "3,5,9", "--quiet", "--plot", str(tmp_path / "r.png")]
    sweep = ["sweep", "{}", "--set", "chain.length=1.2:1.5:3", "--quiet", "--plot", str(tmp_path / "s.png")]
    expected = (
        {"arclength s from node 0 [m]", "tension T [N] (norm form)"},
        {"energy g m^T y [J]", "max tension [N]", "total contact force [N]"},
    )
    for command, labels in zip((refine, sweep), expected, strict=True):
        plain = _plotted([word.format("two-supports") for word in command], drawn)
        si = _plotted([word.format(si_path) for word in command], drawn)
        assert units_named("\n".join(plain)) == [], command
        assert [unlabelled(text) for text in si] == [unlabelled(text) for text in plain]
        assert labels <= set(si), sorted(si)
        assert not labels & set(plain)
    capsys.readouterr()


# ----------------------------------------------------------------- the HTML report
def report_text(path: Path) -> str:
    """The report's words: its tags, scripts and embedded images left out."""
    page = path.read_text(encoding="utf-8")
    page = re.sub(r"<script.*?</script>", " ", page, flags=re.S)
    page = re.sub(r'src="data:[^"]*"', "", page)
    return html.unescape(re.sub(r"<[^>]+>", " ", page))


@pytest.mark.parametrize("name", ["disk-drape", "hanging-model"])
def test_the_report(name: str, si_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plain_path, si_path = tmp_path / "plain.html", tmp_path / "si.html"
    assert main(["report", name, "-o", str(plain_path)]) == 0
    assert main(["report", str(declaring_si(name, si_dir)), "-o", str(si_path)]) == 0
    capsys.readouterr()
    plain, si = report_text(plain_path), report_text(si_path)
    assert units_named(plain) == []
    assert unlabelled(si) == unlabelled(plain)
    headers = ["total length L [m]", "total mass M [kg]", "gravity g [m/s^2]", "weight M g [N]", "x [m]"]
    headers += ["length d_k [m]", "tension T_k [N]", "multiplier mu_k [N]", "link tensions [N]", "Fx [N]", "|R| [N]"]
    if name == "disk-drape":
        headers += ["|F| [N]", "squared mu max [N/m]", "R0 x [N]", "energy [J]"]
    for header in headers:
        assert f" {header} " in si, header
    assert re.search(r"Energy g m\^T [yz] = -?[\d.]+ J after", si)
    if name == "hanging-model":  # the 3-D view's data names its unit of force for the colour bar
        view = re.compile(r'id="view3d-data">(.*?)</script>', re.S)
        for path, unit_of_force in ((plain_path, ""), (si_path, "N")):
            found = view.search(path.read_text(encoding="utf-8"))
            assert found is not None and json.loads(found.group(1))["force_unit"] == unit_of_force


def test_the_3d_views_colour_bar_in_a_browser(si_dir: Path, tmp_path: Path) -> None:
    """The report's 3-D view writes "tension a to b N" under its colour bar with SI, no unit without."""
    from browser import chromium

    with chromium() as browser:
        for name, source, suffix in (("plain", "hanging-model", ""), ("si", None, " N")):
            path = tmp_path / f"{name}.html"
            scenario = source or str(declaring_si("hanging-model", si_dir))
            assert main(["report", scenario, "-o", str(path)]) == 0
            page = browser.new_page()
            # (every text the canvas draws, recorded as it is drawn)
            page.add_init_script(
                "window.drawnTexts = []; const fill = CanvasRenderingContext2D.prototype.fillText;"
                "CanvasRenderingContext2D.prototype.fillText = function (t, ...rest) {"
                " window.drawnTexts.push(String(t)); return fill.call(this, t, ...rest); };"
            )
            page.goto(path.resolve().as_uri())
            drawn_texts: list[str] = page.evaluate("() => window.drawnTexts")
            bars = [text for text in drawn_texts if text.startswith("tension ")]
            assert bars and all(re.fullmatch(rf"tension [\d.e+-]+ to [\d.e+-]+{suffix}", text) for text in bars)
            page.close()


# ----------------------------------------------------------------- the explorer
def test_the_explorers_answer_carries_the_units_for_its_labels() -> None:
    state = state_of_scenario("two-supports")
    plain = solve_state(state)
    si = solve_state({**state, "units": "SI"})
    squared = solve_state({**state, "units": "SI", "formulation": "squared"})
    assert plain["units"] == {
        "system": None, "force": "", "length": "", "mass": "", "gravity": "", "energy": "", "force_per_length": "",
        "multiplier": "",
    }  # fmt: skip
    assert si["units"] == {
        "system": "SI", "force": "N", "length": "m", "mass": "kg", "gravity": "m/s^2", "energy": "J",
        "force_per_length": "N/m", "multiplier": "N",
    }  # fmt: skip
    assert squared["units"]["multiplier"] == "N/m"
    # Labels only: the same numbers either way.
    assert {key: value for key, value in si.items() if key != "units"} == {
        key: value for key, value in plain.items() if key != "units"
    }
