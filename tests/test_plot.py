"""The solution plot: links by tension, supports, reaction arrows, and atomic file output."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.image import imread
from matplotlib.quiver import Quiver

import funicular.plot
from funicular._extras import install_command
from funicular.errors import FunicularError, ScenarioError
from funicular.model import Problem
from funicular.plot import draw_solution, save_solution_plot
from funicular.solution import Solution, Status


def _solution(
    positions: Any,
    multipliers: Any,
    supports: Any = ((0, (0, 0)),),
    name: str = "dangling",
    units: str | None = None,
) -> Solution:
    """A hand-made solution: total length 2, total mass 1, g = 1, so the weight is 1."""
    positions = np.array(positions, dtype=float)
    n = len(positions)
    problem = Problem.build(nodes=n, length=2.0, mass=1.0, gravity=1.0, supports=list(supports), name=name, units=units)
    return Solution(
        problem=problem,
        status=Status.OPTIMAL,
        positions=positions,
        link_multipliers=np.array(multipliers, dtype=float),
        iterations=0,
        solve_seconds=0.0,
    )


def dangling(units: str | None = None) -> Solution:
    """Three nodes hanging straight down from node 0: tensions 2/3 and 1/3, reaction (0, 1)."""
    return _solution([[0, 0], [0, -1], [0, -2]], [2 / 3, 1 / 3], units=units)


def with_slack_link() -> Solution:
    """The last link is shorter than its length 1, so it is slack and carries nothing."""
    return _solution([[0, 0], [0, -1], [0, -1.5]], [2 / 3, 0.0])


def _links(ax: Any) -> LineCollection:
    (links,) = [c for c in ax.collections if isinstance(c, LineCollection)]
    return links


def _quiver(ax: Any) -> Quiver:
    (quiver,) = [c for c in ax.collections if isinstance(c, Quiver)]
    return quiver


def test_links_are_one_collection_with_a_segment_per_link() -> None:
    solution = dangling()
    links = _links(draw_solution(solution))
    segments = links.get_segments()
    assert len(segments) == 2
    np.testing.assert_allclose(segments[0], solution.positions[:2])
    np.testing.assert_allclose(segments[1], solution.positions[1:])
    np.testing.assert_allclose(links.get_array(), [2 / 3, 1 / 3])
    assert all(dashes is None for _, dashes in links.get_linestyles())  # all taut: solid


def test_taut_links_are_solid_and_slack_links_dashed() -> None:
    solution = with_slack_link()
    assert solution.link_taut.tolist() == [True, False]
    styles = _links(draw_solution(solution)).get_linestyles()
    assert len(styles) == 2
    assert styles[0][1] is None
    assert styles[1][1] is not None


def test_colorbar_is_labelled_and_optional() -> None:
    colorbar = _links(draw_solution(dangling())).colorbar
    assert colorbar is not None
    assert colorbar.ax.get_ylabel() == "link tension"  # (no units declared: none named)
    si = _links(draw_solution(dangling("SI"))).colorbar
    assert si is not None and si.ax.get_ylabel() == "link tension [N]"
    assert colorbar.cmap.name == "viridis"
    assert _links(draw_solution(dangling(), colorbar=False)).colorbar is None


@pytest.mark.parametrize("multipliers", [[0.5, 0.5], [0.0, 0.0]])
def test_equal_tensions_still_give_a_usable_colour_scale(multipliers: list[float]) -> None:
    links = _links(draw_solution(_solution([[0, 0], [0, -1], [0, -2]], multipliers)))
    assert links.norm.vmin < links.norm.vmax
    assert np.isfinite(links.norm(links.get_array())).all()


def test_single_support_reaction_points_up_with_a_quarter_of_the_extent() -> None:
    ax = draw_solution(dangling())
    quiver = _quiver(ax)
    np.testing.assert_allclose(quiver.X, [0.0])
    np.testing.assert_allclose(quiver.Y, [0.0])
    np.testing.assert_allclose(quiver.U, [0.0], atol=1e-12)
    np.testing.assert_allclose(quiver.V, [0.25 * 2.0])  # reaction (0, 1); the chain spans 2
    assert [t.get_text() for t in ax.texts] == ["R=1"]
    assert [t.get_text() for t in draw_solution(dangling("SI")).texts] == ["R=1 N"]
    assert ax.get_ylim()[1] > 0.5  # the whole arrow is in view


def test_explicit_force_scale_sets_the_arrow_length() -> None:
    quiver = _quiver(draw_solution(dangling(), force_scale=0.3))
    np.testing.assert_allclose(quiver.V, [0.3])


@pytest.mark.parametrize("force_scale", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_force_scale_is_rejected(force_scale: float) -> None:
    with pytest.raises(ScenarioError, match="force_scale"):
        draw_solution(dangling(), force_scale=force_scale)


def test_arrows_of_several_supports_share_one_scale() -> None:
    solution = _solution([[0, 0], [1, -1], [3, 0]], [2.0, 1.0], supports=[(0, (0, 0)), (2, (3, 0))])
    quiver = _quiver(draw_solution(solution))
    arrows = np.column_stack([quiver.U, quiver.V])
    np.testing.assert_allclose(arrows, solution.support_reactions * (arrows[0, 0] / solution.support_reactions[0, 0]))
    lengths = np.hypot(*arrows.T)
    np.testing.assert_allclose(lengths.max(), 0.25 * 3.0)  # bounding box 3 x 1


def test_axes_title_labels_and_aspect() -> None:
    figure = Figure()
    ax = figure.add_subplot()
    assert draw_solution(dangling(), ax) is ax
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x", "y")
    si = draw_solution(dangling("SI"))
    assert (si.get_xlabel(), si.get_ylabel()) == ("x [m]", "y [m]")
    assert si.get_title().endswith("max tension 0.6667 N")
    assert ax.get_aspect() == 1.0
    title = ax.get_title()
    assert "dangling" in title
    assert "optimal" in title
    assert "0.6667" in title  # the max tension


def test_supports_are_marked_distinctly() -> None:
    ax = draw_solution(dangling())
    markers = {line.get_marker(): line for line in ax.lines}
    assert set(markers) == {".", "^"}
    np.testing.assert_allclose(markers["^"].get_xydata(), [[0.0, 0.0]])


@pytest.mark.parametrize("suffix", [".png", ".svg", ".pdf"])
def test_saved_plot_is_a_non_empty_file_of_the_format(tmp_path: Path, suffix: str) -> None:
    target = tmp_path / f"plot{suffix}"
    save_solution_plot(with_slack_link(), target)
    data = target.read_bytes()
    magic = {".png": b"\x89PNG", ".svg": b"<?xml", ".pdf": b"%PDF"}[suffix]
    assert data.startswith(magic)
    assert os.listdir(tmp_path) == [target.name]


def test_saved_png_decodes_to_a_non_blank_image(tmp_path: Path) -> None:
    target = tmp_path / "plot.PNG"  # the suffix is not case-sensitive
    save_solution_plot(dangling(), str(target))
    image = imread(target)
    assert image.ndim == 3
    assert image.shape[0] > 100
    assert image.shape[1] > 100
    assert image[..., :3].std() > 0.01


def test_two_node_chain() -> None:
    solution = _solution([[0, 0], [2, 0]], [0.5], supports=[(0, (0, 0)), (1, (2, 0))])
    ax = draw_solution(solution)
    assert len(_links(ax).get_segments()) == 1
    assert len(_quiver(ax).U) == 2


def test_a_non_finite_iterate_still_draws(tmp_path: Path) -> None:
    solution = _solution([[0, 0], [np.nan, -1], [0, -2]], [np.nan, 1 / 3])
    save_solution_plot(solution, tmp_path / "nan.png")
    assert (tmp_path / "nan.png").stat().st_size > 0


@pytest.mark.slow
def test_a_hundred_thousand_nodes() -> None:
    n = 100_000
    positions = np.column_stack([np.zeros(n), np.linspace(0.0, -2.0, n)])
    ax = draw_solution(_solution(positions, np.linspace(1.0, 0.0, n - 1)))
    assert len(_links(ax).get_paths()) == n - 1
    assert [line.get_marker() for line in ax.lines] == ["^"]  # no node dots: they would hide the links


@pytest.mark.parametrize("name", ["plot.jpg", "plot", "plot.png.txt"])
def test_unsupported_suffix_is_rejected_before_drawing(tmp_path: Path, name: str) -> None:
    with pytest.raises(ScenarioError, match=r"\.png, \.svg or \.pdf") as error:
        save_solution_plot(dangling(), tmp_path / name)
    assert name in str(error.value)
    assert os.listdir(tmp_path) == []


def test_failed_drawing_keeps_the_existing_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("drawing failed")

    target = tmp_path / "plot.png"
    target.write_bytes(b"previous plot")
    monkeypatch.setattr(funicular.plot, "draw_solution", broken)
    with pytest.raises(RuntimeError, match="drawing failed"):
        save_solution_plot(dangling(), target)
    assert target.read_bytes() == b"previous plot"
    assert os.listdir(tmp_path) == ["plot.png"]


def test_failed_rendering_halfway_keeps_the_existing_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def half_written(self: Figure, stream: Any, **kwargs: object) -> None:
        stream.write(b"\x89PNG truncated")
        raise OSError("renderer crashed")

    target = tmp_path / "plot.png"
    target.write_bytes(b"previous plot")
    monkeypatch.setattr(Figure, "savefig", half_written)
    with pytest.raises(OSError, match="renderer crashed"):
        save_solution_plot(dangling(), target)
    assert target.read_bytes() == b"previous plot"
    assert os.listdir(tmp_path) == ["plot.png"]


def test_missing_matplotlib_gives_an_install_hint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # makes `import matplotlib` fail
    with pytest.raises(FunicularError, match=re.escape(install_command("plot"))):
        draw_solution(dangling())
    with pytest.raises(FunicularError, match="matplotlib"):
        save_solution_plot(dangling(), tmp_path / "plot.png")
    assert os.listdir(tmp_path) == []


def test_a_3d_drawing_shows_its_obstacles_its_contact_forces_and_equal_scales() -> None:
    from funicular import load_scenario, solve
    from funicular.plot import draw_solution_3d

    solution = solve(load_scenario("net-over-sphere"))
    figure = Figure()
    ax: Any = draw_solution_3d(solution, figure)
    labels = ax.get_legend_handles_labels()[1]
    assert "sphere" in labels and any(label.startswith("contact forces") for label in labels)
    spans = [np.ptp(getattr(ax, f"get_{axis}lim")()) for axis in "xyz"]
    assert spans == pytest.approx([spans[0]] * 3)
    # The sphere (centre z = -0.7, radius 0.3) is shown whole: its bottom is inside the view.
    assert ax.get_zlim()[0] <= -1.0


def test_a_half_space_is_drawn_as_a_patch_of_its_plane() -> None:
    from funicular import solve
    from funicular.nets import grid
    from funicular.obstacles import HalfSpace
    from funicular.plot import draw_solution_3d

    floor = HalfSpace(point=(0.0, 0.0, -0.2), normal=(0.0, 0.0, 1.0), name="floor")
    solution = solve(grid(6, 6, slack=1.3, supports="corners", obstacles=[floor]))
    ax: Any = draw_solution_3d(solution, Figure())
    assert "floor" in ax.get_legend_handles_labels()[1]
    patches = [c for c in ax.collections if type(c).__name__ == "Poly3DCollection"]
    assert patches and patches[0].get_alpha() < 1


@pytest.mark.parametrize(
    "command",
    [
        ["explore", "terrain", "--quiet", "--plot", "{out}.png"],
        ["report", "disk-drape", "-o", "{out}.html"],
        ["solve", "disk-drape", "--plot", "{out}.png"],
        ["solve", "box-edge", "--plot", "{out}.svg"],
        ["explore", "peg-two-ways", "--quiet", "--plot", "{out}.png"],
    ],
    ids=["explore-terrain", "report-disk-drape", "solve-disk-drape", "solve-box-edge", "explore-peg"],
)
def test_drawing_obstacles_writes_nothing_to_stderr(tmp_path: Path, command: list[str]) -> None:
    """The obstacles' fills fixed the view and the layout then resized the axes: matplotlib logged
    "Ignoring fixed x limits to fulfill fixed data aspect with adjustable data limits." on stderr
    from these commands. They draw and write their file with stderr empty."""
    import subprocess

    out = str(tmp_path / "out")
    words = [word.format(out=out) for word in command]
    result = subprocess.run(
        [sys.executable, "-m", "funicular.cli", *words], capture_output=True, text=True, check=False, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    assert Path(words[-1]).stat().st_size > 0


# ----------------------------------------------------------------- colouring by strain
def _elastic_hanging(ea: float = 10.0) -> Solution:
    """Three nodes hanging from node 0 by links of 1 with EA = ``ea``, drawn 1.1 and 1.05 long: strains
    0.1 and 0.05 (tensions EA times those)."""
    problem = Problem.build(
        nodes=3, length=2.0, mass=1.0, gravity=1.0, supports=[(0, (0.0, 0.0))], axial_stiffness=ea, name="elastic"
    )
    return Solution(
        problem=problem,
        status=Status.OPTIMAL,
        positions=np.array([[0.0, 0.0], [0.0, -1.1], [0.0, -2.15]]),
        link_multipliers=np.array([0.1 * ea, 0.05 * ea]),
        iterations=0,
        solve_seconds=0.0,
    )


def test_links_coloured_by_strain_carry_each_links_strain_and_the_bar_says_so() -> None:
    links = _links(draw_solution(_elastic_hanging(), colour="strain"))
    np.testing.assert_allclose(links.get_array(), [0.1, 0.05], rtol=1e-12)  # (1.1 - 1) / 1, (1.05 - 1) / 1
    assert links.colorbar is not None and links.colorbar.ax.get_ylabel() == "link strain"
    tension = _links(draw_solution(_elastic_hanging()))  # the default stays tension
    np.testing.assert_allclose(tension.get_array(), [1.0, 0.5], rtol=1e-12)
    assert tension.colorbar is not None and tension.colorbar.ax.get_ylabel() == "link tension"


def test_a_nets_links_in_space_coloured_by_strain_carry_the_strain_of_their_drawn_lengths() -> None:
    from funicular import load_scenario, solve
    from funicular.plot import draw_solution_3d

    solution = solve(load_scenario("pretensioned-saddle"))
    ax: Any = draw_solution_3d(solution, Figure(), colour="strain")
    # (the arrows are line collections too; the links are the one coloured by values)
    (links,) = [c for c in ax.collections if type(c).__name__ == "Line3DCollection" and c.get_array() is not None]
    ends = solution.positions[solution.problem.link_nodes]
    rest = solution.problem.link_lengths
    strain = (np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1) - rest) / rest
    np.testing.assert_allclose(links.get_array(), strain, rtol=1e-9)
    assert strain.min() > 0.01  # (every cable is stretched: pretensioned by 2 % and more)
    assert links.colorbar is not None and links.colorbar.ax.get_ylabel() == "link strain"


@pytest.mark.parametrize(
    ("solution", "colour", "needle"),
    [(dangling, "strain", "no link of 'dangling' is elastic"), (_elastic_hanging, "stress", "'tension' or 'strain'")],
)
def test_a_colouring_that_cannot_be_drawn_is_one_sentence_before_any_file(
    tmp_path: Path, solution: Any, colour: str, needle: str
) -> None:
    with pytest.raises(ScenarioError, match=needle) as error:
        save_solution_plot(solution(), tmp_path / "plot.png", colour=colour)
    assert str(error.value).startswith("colour") and "\n" not in str(error.value)
    assert os.listdir(tmp_path) == []


def test_solve_colours_the_plot_by_strain_on_request_and_refuses_it_without_elastic_links(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from funicular.cli import main

    plot = tmp_path / "mooring.png"
    assert main(["solve", "mooring", "--plot", str(plot), "--colour", "strain"]) == 0
    assert imread(plot)[..., :3].std() > 0.01
    capsys.readouterr()
    for words in (
        ["two-supports", "--plot", str(tmp_path / "chain.png"), "--colour", "strain"],
        ["mooring", "--colour", "strain"],
    ):
        assert main(["solve", *words]) == 2
        error = capsys.readouterr().err
        assert error.startswith("funicular: error: --colour strain") and error.count("\n") == 1, error
    assert os.listdir(tmp_path) == ["mooring.png"]
