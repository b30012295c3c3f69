"""``funicular report``: one self-contained HTML page (or Markdown with its images) about a scenario.

The report holds the scenario's parameters, the equilibrium picture with its forces, force tables
(link tensions, support reactions, contact forces), the KKT residuals, the LICQ / second-order
section (from :mod:`funicular.checks`) and a small refinement study. It is built as
a list of sections of paragraphs, tables and images, then rendered: HTML embeds the images as
base64 PNG and its style inline (no external file); Markdown writes the images next to it as
``<stem>-<name>.png``. Every file is written atomically.

A 3-D problem's HTML report also holds an interactive view (:class:`View3D`): a ``<canvas>`` drawn
by an inline script from the equilibrium embedded as JSON (orthographic projection, drag to
rotate, wheel to zoom), with no library and no request to any server. The script is
:mod:`funicular._static`'s ``view3d.js``, which the explorer (``funicular serve``) draws with too.
A planar report has no script.
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from funicular import __version__
from funicular._io import atomic_write, atomic_write_text
from funicular._static import view3d_script
from funicular._text import balance, largest_tension
from funicular._units import force_unit, label, length_unit, multiplier_unit, unit, with_unit
from funicular.checks import check_solution
from funicular.errors import FunicularError, ScenarioError
from funicular.model import Problem
from funicular.plot import draw_solution, draw_solution_3d
from funicular.scenario import obstacle_table
from funicular.solution import Solution
from funicular.studies import format_number
from funicular.studies import refine as refine_study

REFINE_NODES = [5, 9, 17, 33]  # small, so the report stays fast
EDGE_LINKS = 5  # the link table shows the first and last EDGE_LINKS links
MAX_CONTACT_ROWS = 30
CONTACT_RTOL = 1e-8  # contact forces below this fraction of the weight are not listed
DIGITS = 8
FORMATS = ("html", "md")


@dataclass(frozen=True)
class Table:
    headers: list[str]
    rows: list[list[str]]


@dataclass(frozen=True)
class Image:
    name: str  # file-name part for Markdown: <stem>-<name>.png
    png: bytes
    alt: str


@dataclass(frozen=True)
class View3D:
    """The interactive 3-D view of an equilibrium (HTML only): the data its script draws."""

    data: dict[str, Any]


Block = str | Table | Image | View3D  # a str is a paragraph


@dataclass(frozen=True)
class Section:
    title: str
    blocks: list[Block]


def _cells(*values: object) -> list[str]:
    return [format_number(value, DIGITS) for value in values]


def _png(draw: Any, size: tuple[float, float]) -> bytes:
    """Render ``draw(figure)`` to PNG bytes (pyplot-free)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # (an optional extra: loaded to draw)
    from matplotlib.figure import Figure

    figure = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(figure)
    draw(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()


# --------------------------------------------------------------------------- sections
def scenario_section(problem: Problem, description: str) -> Section:
    lengths, masses = problem.link_lengths, problem.masses
    length, mass = length_unit(problem), unit(problem, "mass")
    rows = [
        ["name", problem.name],
        ["description", description or "-"],
        ["nodes", str(problem.n_nodes)],
        [label("total length L", length), format_number(problem.total_length, DIGITS)],
        [label("link lengths", length), _range(lengths)],
        [label("total mass M", mass), format_number(problem.total_mass, DIGITS)],
        [label("node masses", mass), _range(masses)],
        [label("gravity g", unit(problem, "gravity")), format_number(problem.gravity, DIGITS)],
        [label("weight M g", force_unit(problem)), format_number(problem.weight, DIGITS)],
        ["formulation", problem.formulation.value],
        ["contact", problem.contact],
    ]
    if problem.dimension == 3 or not problem.is_chain:
        rows[2:2] = [["dimension", str(problem.dimension)], ["links", str(problem.n_links)]]
    if problem.loads is not None:
        loaded = problem.loaded_nodes.size
        largest = format_number(np.linalg.norm(problem.loads[problem.loaded_nodes], axis=1).max(), DIGITS)
        largest = with_unit(largest, force_unit(problem))
        rows.append(["point loads", f"{loaded} node{'s' if loaded > 1 else ''}, largest {largest}"])
    supports = Table(
        ["support node", *_labelled(_axes(problem), length)],
        [[str(node), *_cells(*xy)] for node, xy in zip(problem.support_nodes, problem.support_positions, strict=True)],
    )
    blocks: list[Block] = [Table(["parameter", "value"], rows), supports]
    if problem.obstacles:
        blocks.append(Table(["obstacle", "shape"], [[o.name, repr(o)] for o in problem.obstacles]))
    return Section("Scenario", blocks)


def _axes(problem: Problem) -> list[str]:
    return list("xyz"[: problem.dimension])


def _labelled(names: list[str], symbol: str) -> list[str]:
    """Column headers with the unit ``symbol`` (none if "")."""
    return [label(name, symbol) for name in names]


def _forces(problem: Problem, *names: str) -> list[str]:
    """Force columns' headers, with the problem's unit of force."""
    return _labelled(list(names), force_unit(problem))


def _energy(solution: Solution) -> str:
    return with_unit(format_number(solution.objective, 10), unit(solution.problem, "energy"))


def _norm(vector: np.ndarray) -> float:
    return float(np.linalg.norm(vector))


def _range(values: np.ndarray) -> str:
    lo, hi = float(values.min()), float(values.max())
    return format_number(lo, DIGITS) if lo == hi else f"{format_number(lo, DIGITS)} to {format_number(hi, DIGITS)}"


def equilibrium_section(solution: Solution) -> Section:
    height = "z" if solution.problem.dimension == 3 else "y"
    text = (
        f"Status: {solution.status.value} ({solution.status.message}). Energy g m^T {height} = "
        f"{_energy(solution)} after {solution.iterations} Newton steps "
        f"in {solution.solve_seconds:.3g} s."
    )
    if solution.problem.dimension == 3:
        picture = Image(
            "equilibrium",
            _png(lambda figure: draw_solution_3d(solution, figure), (8, 6)),
            "the equilibrium in perspective: links coloured by tension (dashed when slack), support reactions as "
            "arrows, obstacles as wireframes",
        )
        return Section("Equilibrium", [text, *view_3d(solution), picture])
    picture = Image(
        "equilibrium",
        _png(lambda figure: draw_solution(solution, figure.add_subplot()), (8, 5.5)),
        "the equilibrium: links coloured by tension (dashed when slack), support reactions as arrows",
    )
    return Section("Equilibrium", [text, picture])


MAX_VIEW_LINKS = 50_000  # above, the embedded data would weigh more than the page is worth
VIEW_DIGITS = 7  # significant digits of the view's coordinates and forces: far below a pixel


def _rounded(values: np.ndarray) -> Any:
    """``values`` as nested lists of numbers with VIEW_DIGITS significant digits (a short JSON)."""
    flat = [float(format(value, f".{VIEW_DIGITS}g")) for value in values.ravel().tolist()]
    return np.array(flat).reshape(values.shape).tolist()


def view_3d(solution: Solution) -> list[Block]:
    """The interactive view of a 3-D equilibrium, or a sentence saying why there is none."""
    problem = solution.problem
    if problem.n_links > MAX_VIEW_LINKS:
        return [f"The interactive view is left out: {problem.n_links} links are more than {MAX_VIEW_LINKS}."]
    arrays = (solution.positions, solution.link_tension, solution.support_reactions, solution.contact_forces)
    if not all(np.isfinite(array).all() for array in arrays):
        return ["The interactive view is left out: the returned point is not finite."]
    contact = solution.contact_forces
    touching = np.flatnonzero(np.linalg.norm(contact, axis=1) > CONTACT_RTOL * problem.force_scale)
    data = {
        "positions": _rounded(solution.positions),
        "links": problem.link_nodes.tolist(),
        "tension": _rounded(solution.link_tension),
        "taut": solution.link_taut.tolist(),
        "supports": problem.support_nodes.tolist(),
        "reactions": _rounded(solution.support_reactions),
        "contact_nodes": touching.tolist(),
        "contact_forces": _rounded(contact[touching]) if touching.size else [],
        # (the shapes the script draws: the built-in ones, as their scenario tables)
        "obstacles": [table for table in map(obstacle_table, problem.obstacles) if table is not None],
        "force_unit": force_unit(problem),  # (the script's colour-bar label; "" where none is declared)
    }
    loaded = problem.loaded_nodes
    if problem.loads is not None and loaded.size:
        data["load_nodes"], data["load_forces"] = loaded.tolist(), _rounded(problem.loads[loaded])
    return [View3D(data)]


def link_table(solution: Solution) -> Table:
    """The first and last EDGE_LINKS links (all of them when there are few)."""
    n = solution.problem.n_links
    links = list(range(n)) if n <= 2 * EDGE_LINKS + 2 else [*range(EDGE_LINKS), *range(n - EDGE_LINKS, n)]
    rows: list[list[str]] = []
    for k in links:
        if rows and k != links[links.index(k) - 1] + 1:
            rows.append(["…"] * 6)
        distance, length = solution.link_distance[k], solution.problem.link_lengths[k]
        taut = "taut" if solution.link_taut[k] else "slack"
        rows.append([str(k), *_cells(distance, length, solution.link_tension[k], solution.link_multipliers[k]), taut])
    p = solution.problem
    length = length_unit(p)
    multiplier = label("multiplier mu_k", multiplier_unit(p, p.formulation.value))
    headers = ["link k", label("length d_k", length), label("max length l_k", length), *_forces(p, "tension T_k")]
    return Table([*headers, multiplier, "state"], rows)


def forces_section(solution: Solution) -> Section:
    p = solution.problem
    tension = solution.link_tension
    k = largest_tension(tension)
    taut = int(np.count_nonzero(solution.link_taut))
    summary = Table(
        [*_forces(p, "link tensions"), "value"],
        [
            ["largest", f"{format_number(tension[k], DIGITS)} (link {k})"],
            ["smallest", format_number(float(tension.min()), DIGITS)],
            ["mean", format_number(float(tension.mean()), DIGITS)],
            ["taut links", f"{taut} of {p.n_links}"],
        ],
    )
    reactions = solution.support_reactions
    rows = [[str(node), *_cells(*force, _norm(force))] for node, force in zip(p.support_nodes, reactions, strict=True)]
    total = reactions.sum(axis=0)
    rows.append(["total", *_cells(*total, _norm(total))])
    components = [f"F{axis}" for axis in _axes(p)]
    blocks: list[Block] = [
        "Sign conventions: a tension T_k >= 0 pulls the two nodes of link k together; a reaction is the force a "
        f"support exerts on the chain. The norm-form multiplier is T_k; the squared-form one is T_k / (2 d_k). "
        f"Formulation used here: {p.formulation.value}.",
        summary,
        link_table(solution),
        Table(["support node", *_forces(p, *components, "|R|")], rows),
        f"The support reactions add up to the {balance(solution)}.",
    ]
    if p.obstacles:
        blocks.append(contact_table(solution))
    return Section("Forces", blocks)


def contact_table(solution: Solution) -> Table | str:
    forces = solution.contact_forces
    magnitude = np.linalg.norm(forces, axis=1)
    touching = np.flatnonzero(magnitude > CONTACT_RTOL * solution.problem.force_scale)
    if touching.size == 0:
        return "No node touches an obstacle."
    axes = _axes(solution.problem)
    rows = [[str(i), *_cells(*solution.positions[i], *forces[i], magnitude[i])] for i in touching[:MAX_CONTACT_ROWS]]
    total = forces[touching].sum(axis=0)
    rows.append(["total", *[""] * len(axes), *_cells(*total, float(magnitude.sum()))])
    if touching.size > MAX_CONTACT_ROWS:
        rows.insert(-1, [f"… {touching.size - MAX_CONTACT_ROWS} more", *[""] * (2 * len(axes) + 1)])
    p = solution.problem
    headers = ["contact node", *_labelled(axes, length_unit(p)), *_forces(p, *(f"F{axis}" for axis in axes), "|F|")]
    return Table(headers, rows)


def kkt_section(solution: Solution) -> Section:
    raw, scaled = solution.kkt.as_dict(), solution.kkt_scaled.as_dict()
    rows = [[name.replace("_", " "), f"{raw[name]:.3e}", f"{scaled[name]:.3e}"] for name in raw]
    return Section(
        "KKT residuals",
        [
            "Recomputed from the returned positions and multipliers alone (max-norms). Scaled: divided by the total "
            "weight and the longest link; the solver stops when every scaled residual is below its tolerance.",
            Table(["residual", "value", "scaled"], rows),
        ],
    )


def second_order_section(solution: Solution) -> Section:
    """What the checker (:func:`funicular.checks.check_solution`) finds at the solution, a chain's or a
    net's: LICQ and the statics, MFCQ, the multipliers' ranges where they are not unique, and the
    second-order verdict."""
    title = "LICQ and second-order conditions"
    try:
        report = check_solution(solution)
    except FunicularError as error:
        return Section(title, [f"Not checked: {error}"])
    if report.violation is not None:
        return Section(title, [f"The point is not feasible: {report.violation.text}."])
    rows: list[list[str]] = []
    licq = report.licq
    if licq is not None:
        rows.append(["LICQ", licq.verdict])
        if licq.statics is not None:
            rows.append(["statics", licq.statics])
    if report.mfcq is not None:
        rows.append(["MFCQ", f"{'holds' if report.mfcq.holds else 'fails'}: {report.mfcq.reason}"])
    if report.second_order is not None:
        rows.append(["second order", f"{report.second_order.verdict}: {report.second_order.reason}"])
    blocks: list[Block] = [
        "Checked at the returned point with the solver's multipliers (relative tolerance "
        f"{report.tolerance:g}): constraint qualifications on the active set, and the curvature of the "
        "Lagrangian on the critical cone.",
        Table(["condition", "result"], rows),
    ]
    if licq is not None and licq.dependencies:
        blocks.append(
            "The multipliers are not unique: these forces balance each other, so any amount of them can be added."
        )
        blocks += [dependency.text for dependency in licq.dependencies[:5]]
    if report.multiplier_ranges:
        blocks.append(
            Table(
                ["force", "smallest", "largest"],
                [[r.constraint, *_cells(r.min, r.max)] for r in report.multiplier_ranges[:MAX_CONTACT_ROWS]],
            )
        )
    return Section(title, blocks)


def refine_section(problem: Problem) -> Section:
    title = f"Refinement study (N = {', '.join(map(str, REFINE_NODES))})"
    try:
        study = refine_study.refine(problem, REFINE_NODES)
    except FunicularError as error:
        return Section(title, [f"Not available for this scenario: {error}"])
    orders = ", ".join(f"{name.replace('_', ' ')} {format_number(value, 3)}" for name, value in study.orders.items())
    return Section(
        title,
        [
            "The same chain (total mass and length fixed) at growing N, solved in both formulations: the squared-form "
            "multipliers grow like N, the norm-form ones (the tensions) converge. "
            f"Exact answers: {study.reference}.",
            _table(*refine_study.multiplier_columns(study)),
            _table(*refine_study.convergence_columns(study)),
            f"{refine_study.ERRORS_CAPTION[0].upper()}{refine_study.ERRORS_CAPTION[1:]}.",
            f"Observed slopes (log-log against N-1, last {refine_study.FIT_POINTS} N): {orders}.",
            *study.notes,
            Image(
                "refine",
                _png(lambda figure: refine_study.draw_study(study, figure), (11, 4.5)),
                "largest multipliers against N, and tension profiles",
            ),
        ],
    )


def _table(headers: list[str], rows: list[list[object]]) -> Table:
    return Table(headers, [[format_number(cell, DIGITS) for cell in row] for row in rows])


def build_sections(solution: Solution, description: str) -> list[Section]:
    return [
        scenario_section(solution.problem, description),
        equilibrium_section(solution),
        forces_section(solution),
        kkt_section(solution),
        second_order_section(solution),
        refine_section(solution.problem),
    ]


# --------------------------------------------------------------------------- rendering
STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; color: #222; }
h1 { border-bottom: 2px solid #444; }
h2 { margin-top: 1.6em; border-bottom: 1px solid #bbb; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #eee; }
td:first-child, th:first-child { text-align: left; }
img { max-width: 100%; border: 1px solid #ddd; }
canvas { border: 1px solid #ddd; cursor: grab; touch-action: none; max-width: 100%; }
"""

# The 3-D view's script, shared with the explorer (one file, shipped in the package): inlined, as
# the report must open offline, and started on the canvas and the JSON block before it.
VIEW_SCRIPT = view3d_script()
VIEW_START = (
    'funicularView3D(document.getElementById("view3d"), '
    'JSON.parse(document.getElementById("view3d-data").textContent));'
)


VIEW_CAPTION = (
    "Drag the picture to turn it, use the wheel to zoom (orthographic projection; links coloured by tension, "
    "dashed when slack; supports black, support reactions red, contact forces blue on their own scale)."
)


def _json_in_script(data: dict[str, Any]) -> str:
    """``data`` as JSON safe inside a <script> element: no "</" can end it early."""
    return json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def render_view(view: View3D) -> str:
    """The canvas, its data and its script (the report's only script)."""
    return (
        f"<p>{html.escape(VIEW_CAPTION)}</p>\n"
        '<p><canvas id="view3d" width="900" height="600" '
        'aria-label="interactive 3-D view of the equilibrium: drag to turn, wheel to zoom"></canvas></p>\n'
        f'<script type="application/json" id="view3d-data">{_json_in_script(view.data)}</script>\n'
        f"<script>{VIEW_SCRIPT}{VIEW_START}</script>"
    )


def render_html(title: str, sections: list[Section]) -> str:
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
    ]
    for section in sections:
        parts.append(f"<h2>{html.escape(section.title)}</h2>")
        for block in section.blocks:
            if isinstance(block, Table):
                head = "".join(f"<th>{html.escape(h)}</th>" for h in block.headers)
                body = "".join(
                    "<tr>" + "".join(f"<td>{html.escape(cell)}</td>" for cell in row) + "</tr>" for row in block.rows
                )
                parts.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
            elif isinstance(block, View3D):
                parts.append(render_view(block))
            elif isinstance(block, Image):
                data = base64.b64encode(block.png).decode("ascii")
                parts.append(f'<p><img alt="{html.escape(block.alt)}" src="data:image/png;base64,{data}"></p>')
            else:
                parts.append(f"<p>{html.escape(block)}</p>")
    parts.append(f"<p><small>funicular {__version__}</small></p></body></html>")
    return "\n".join(parts) + "\n"


def _markdown_cell(text: str) -> str:
    return text.replace("|", "\\|")


def render_markdown(title: str, sections: list[Section], stem: str) -> str:
    """Markdown; images are referenced as ``<stem>-<name>.png`` (written by :func:`write_report`)."""
    parts = [f"# {title}"]
    for section in sections:
        parts.append(f"## {section.title}")
        for block in section.blocks:
            if isinstance(block, Table):
                lines = ["| " + " | ".join(map(_markdown_cell, block.headers)) + " |"]
                lines.append("|" + "---|" * len(block.headers))
                lines += ["| " + " | ".join(map(_markdown_cell, row)) + " |" for row in block.rows]
                parts.append("\n".join(lines))
            elif isinstance(block, Image):
                parts.append(f"![{block.alt}]({stem}-{block.name}.png)")
            elif isinstance(block, View3D):
                continue  # (a script: the HTML report's only)
            else:
                parts.append(block)
    parts.append(f"<small>funicular {__version__}</small>")
    return "\n\n".join(parts) + "\n"


def write_report(solution: Solution, path: str | os.PathLike[str], report_format: str, description: str = "") -> None:
    """Build the report of ``solution`` and write it to ``path`` (and, for Markdown, its images beside it)."""
    if report_format not in FORMATS:
        raise ScenarioError(f"--format {report_format!r}: use html or md.")
    target = Path(path)
    title = f"funicular report: {solution.problem.name}"
    sections = build_sections(solution, description)
    if report_format == "html":
        atomic_write_text(target, render_html(title, sections))
        return
    for section in sections:
        for block in section.blocks:
            if isinstance(block, Image):
                _write_png(target.with_name(f"{target.stem}-{block.name}.png"), block.png)
    atomic_write_text(target, render_markdown(title, sections, target.stem))


def _write_png(path: Path, png: bytes) -> None:
    def write(stream: BinaryIO) -> None:
        stream.write(png)

    atomic_write(path, write)
