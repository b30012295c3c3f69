"""Plot an equilibrium: links coloured by tension (or by strain), supports, and support reactions as arrows.

matplotlib is an optional extra (see :func:`require_matplotlib`) and is imported only when
a plot is drawn. Nothing here touches pyplot, so there is no global state and no GUI.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import NDArray

from funicular._extras import install_command
from funicular._io import atomic_write
from funicular._units import Units, force_unit, label, length_unit, unit, with_unit
from funicular.errors import FunicularError, ScenarioError, shown
from funicular.inversion import Inverted
from funicular.model import FloatArray, IntArray, Problem
from funicular.obstacles import (
    Box,
    Cuboid,
    Disk,
    Ellipse,
    Ellipsoid,
    HalfSpace,
    Obstacle,
    Sphere,
    Surface,
    outline,
)
from funicular.solution import Solution

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

PLOT_SUFFIXES = (".png", ".svg", ".pdf")
ARROW_FRACTION = 0.25  # the largest reaction arrow is this fraction of the chain's bounding box
CONTACT_FRACTION = 0.12  # and the largest contact-force arrow this fraction (contact forces have their own scale)
LOAD_COLOUR = "darkgreen"  # point loads: arrows at their nodes, on their own scale like the contact forces
BOUNDED_UP_TO = 3.0  # a disk, ellipse or box up to this many times the drawing's size is shown whole
COLORMAP = "viridis"
OBSTACLE_COLOUR = "0.82"
MAX_NODE_DOTS = 500  # more nodes than this would hide the links under their dots
RASTERIZE_LINKS = 10_000  # more links than this are embedded as an image in .svg/.pdf output
COLOURINGS = ("tension", "strain")  # what the links may be coloured by; strain where some link is elastic


def require_matplotlib() -> None:
    try:
        import matplotlib  # noqa: F401  # (an optional extra: only whether it is installed)
    except ImportError:
        raise FunicularError(f"plotting needs matplotlib: {install_command('plot')}") from None


def _finite_range(values: FloatArray, empty: tuple[float, float]) -> tuple[float, float]:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return empty
    return float(finite.min()), float(finite.max())


def check_colouring(problem: Problem, colour: str) -> None:
    """``colour``, what the links are coloured by: one of COLOURINGS, strain only where some link is
    elastic (every strain is 0 otherwise); a ScenarioError naming ``colour`` before anything is drawn."""
    if colour not in COLOURINGS:
        raise ScenarioError(
            f"colour = {shown(colour)} is not a colouring; colour the links by 'tension' or 'strain'.", key="colour"
        )
    if colour == "strain" and problem.axial_stiffness is None:
        raise ScenarioError(
            f"colour strain: no link of {problem.name!r} is elastic, so every strain is 0; colour the links by "
            "tension, or give them an axial_stiffness.",
            key="colour",
        )


def _link_colours(solution: Solution, colour: str) -> tuple[FloatArray, str]:
    """The values the links are coloured by (``colour``: tension or strain) and the colour bar's label."""
    check_colouring(solution.problem, colour)
    if colour == "strain":
        return solution.link_strain, "link strain"
    return solution.link_tension, label("link tension", force_unit(solution.problem))


def _colour_limits(values: FloatArray) -> tuple[float, float]:
    """Colour-scale limits; a constant value V gets the scale [0, V] (or [0, 1] if V = 0)."""
    lo, hi = _finite_range(values, (0.0, 1.0))
    if hi > lo:
        return lo, hi
    return (0.0, hi) if hi > 0 else (hi, hi + 1.0)


def _bounding_size(solution: Solution) -> float:
    """The larger side of the chain's bounding box (the chain length if it is a point)."""
    x0, x1 = _finite_range(solution.x, (0.0, 0.0))
    y0, y1 = _finite_range(solution.y, (0.0, 0.0))
    size = max(x1 - x0, y1 - y0)
    return size if size > 0 else solution.problem.total_length


def default_force_scale(solution: Solution) -> float:
    """Arrow length per unit of force that makes the largest reaction arrow 25% of the chain's extent."""
    magnitudes = np.hypot(*solution.support_reactions.T)
    _, largest = _finite_range(magnitudes, (0.0, 0.0))
    if largest <= 0:
        return 1.0
    return ARROW_FRACTION * _bounding_size(solution) / largest


def _max_tension(solution: Solution) -> float:
    return _finite_range(solution.link_tension, (math.nan, math.nan))[1]


def draw_solution(
    solution: Solution,
    ax: Axes | None = None,
    *,
    force_scale: float | None = None,
    colorbar: bool = True,
    colour: str = "tension",
) -> Axes:
    """Draw the chain on ``ax`` (or on a new, pyplot-free figure) and return the axes.

    Links are coloured by tension, or by strain with ``colour="strain"`` where some link is elastic
    (solid when taut, dashed when slack), nodes are dots,
    supports black triangles, and each support reaction is an arrow from its node of length
    ``force * force_scale`` (lengths per unit of force), labelled with its magnitude. Contact forces
    (blue) and point loads (green) are arrows on scales of their own. Forces and lengths are
    labelled with their units where the problem declares them (:mod:`funicular._units`).
    """
    require_matplotlib()
    from matplotlib.collections import LineCollection  # (matplotlib, an optional extra: loaded to draw)
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    if force_scale is None:
        force_scale = default_force_scale(solution)
    if not (math.isfinite(force_scale) and force_scale > 0):
        raise ScenarioError(f"force_scale = {force_scale!r}; it must be a finite number > 0.")
    values, colour_label = _link_colours(solution, colour)
    if ax is None:
        ax = Figure(layout="constrained").add_subplot()
    problem: Problem = solution.problem
    positions = solution.positions
    force_symbol = force_unit(problem)

    segments = positions[problem.link_nodes]  # (L, 2, 2): each link's two ends
    taut = solution.link_taut
    links = LineCollection(
        segments,  # type: ignore[arg-type]  # an (N-1, 2, 2) array is accepted; the stubs say Sequence
        cmap=COLORMAP,
        norm=Normalize(*_colour_limits(values)),
        linestyles="solid" if taut.all() else np.where(taut, "solid", "dashed").tolist(),
        linewidths=2.0,
        capstyle="round",
        zorder=1,
        rasterized=problem.n_links > RASTERIZE_LINKS,
    )
    links.set_array(values)
    ax.add_collection(links, autolim=False)  # autolim walks 100k paths one by one; the points are enough
    if problem.n_nodes <= MAX_NODE_DOTS:
        ax.plot(solution.x, solution.y, ".", color="0.3", markersize=3, zorder=2)
    supports = positions[problem.support_nodes]
    ax.plot(supports[:, 0], supports[:, 1], "^", color="black", markersize=9, zorder=3)

    arrows = solution.support_reactions * force_scale
    ax.quiver(
        supports[:, 0],
        supports[:, 1],
        arrows[:, 0],
        arrows[:, 1],
        angles="xy",
        scale_units="xy",
        scale=1.0,
        color="crimson",
        zorder=4,
        label="support reactions",
    )
    tips = supports + arrows
    for tip, (fx, fy) in zip(tips, solution.support_reactions, strict=True):
        ax.annotate(
            with_unit(f"R={math.hypot(fx, fy):.3g}", force_symbol),
            tip,
            xytext=(0, 4 if fy >= 0 else -4),
            textcoords="offset points",
            ha="right" if fx > 0 else "left" if fx < 0 else "center",  # inwards, so it stays in the axes
            va="bottom" if fy >= 0 else "top",
            color="crimson",
            fontsize=9,
        )
    contact = solution.contact_forces
    magnitude = np.hypot(contact[:, 0], contact[:, 1])
    touching = np.flatnonzero(magnitude > 0)
    reach = [positions, supports + 1.2 * arrows]  # room for the labels past the tips
    if touching.size:
        # Contact forces get their own scale: a node's share of the weight is far smaller than a
        # support's reaction, and at the reactions' scale the arrows would vanish on flat ground.
        largest = int(touching[np.argmax(magnitude[touching])])
        contact_scale = CONTACT_FRACTION * _bounding_size(solution) / magnitude[largest]
        pushes = contact[touching] * contact_scale
        ax.quiver(
            positions[touching, 0],
            positions[touching, 1],
            pushes[:, 0],
            pushes[:, 1],
            angles="xy",
            scale_units="xy",
            scale=1.0,
            color="royalblue",
            width=0.004,
            zorder=5,
            label=f"contact forces (largest {with_unit(f'{magnitude[largest]:.3g}', force_symbol)}, own scale)",
        )
        ax.annotate(
            with_unit(f"F={magnitude[largest]:.3g}", force_symbol),
            positions[largest] + contact[largest] * contact_scale,
            xytext=(0, 4),
            textcoords="offset points",
            ha="center",
            color="royalblue",
            fontsize=9,
        )
        reach.append(positions[touching] + 1.2 * pushes)
    loaded, shown, load_label = _point_load_arrows(solution.problem, _bounding_size(solution))
    if loaded.size:
        ax.quiver(
            *positions[loaded].T,
            *shown.T,
            angles="xy",
            scale_units="xy",
            scale=1.0,
            color=LOAD_COLOUR,
            width=0.004,
            zorder=5,
            label=load_label,
        )
        reach.append(positions[loaded] + 1.2 * shown)
    ax.update_datalim(np.vstack(reach))
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.1)
    ax.autoscale_view()
    _draw_obstacles(ax, problem, *reach)
    ax.legend(loc="best", fontsize=8)
    _label_axes(ax, problem, "xy")
    ax.set_title(_solution_title(solution))
    if colorbar:
        ax.figure.colorbar(links, ax=ax, label=colour_label)
    return ax


def _label_axes(ax: Any, units: Units, axes: str) -> None:
    """Name each coordinate axis, with the unit of length where one is declared."""
    length = length_unit(units)
    for axis in axes:
        getattr(ax, f"set_{axis}label")(label(axis, length))


def _solution_title(solution: Solution) -> str:
    largest = with_unit(f"{_max_tension(solution):.4g}", force_unit(solution.problem))
    return f"{solution.problem.name}: {solution.status.value}, max tension {largest}"


def _point_load_arrows(problem: Problem, size: float) -> tuple[IntArray, FloatArray, str]:
    """The loaded nodes, their point loads as arrows on their own scale (the largest
    CONTACT_FRACTION of ``size``, like the contact forces) and the arrows' label."""
    loaded = problem.loaded_nodes
    if problem.loads is None:
        return loaded, np.zeros((0, problem.dimension)), ""
    forces = problem.loads[loaded]
    largest = float(np.linalg.norm(forces, axis=1).max())
    shown = with_unit(f"{largest:.3g}", force_unit(problem))
    return loaded, forces * (CONTACT_FRACTION * size / largest), f"point loads (largest {shown}, own scale)"


def _draw_obstacles(ax: Axes, problem: Problem, *point_sets: FloatArray) -> None:
    """Fill every obstacle out to the edges of the axes (its outline, or phi >= 0 on a grid).

    A bounded shape (disk, ellipse, box) not much larger than the drawing is shown whole; the view
    is then fixed and each fill reaches past every edge, so the axes clip it, never the fill's own
    extent (a disk is not cut into a half-disk, the ground reaches the sides)."""
    if not problem.obstacles:
        return
    points = np.vstack(point_sets)
    low, high = np.nanmin(points, axis=0), np.nanmax(points, axis=0)
    size = max(float(np.max(high - low)), 1e-12)
    for obstacle in problem.obstacles:
        far = (low[0] - 10 * size, high[0] + 10 * size, low[1] - 10 * size, high[1] + 10 * size)
        whole = outline(obstacle, far)
        bounded = isinstance(obstacle, Disk | Ellipse | Box)
        if bounded and whole.size and float(np.ptp(whole, axis=0).max()) <= BOUNDED_UP_TO * size:
            ax.update_datalim(whole)
    ax.autoscale_view()
    ax.apply_aspect()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    span = max(x1 - x0, y1 - y0)
    bounds = (x0 - span, x1 + span, y0 - span, y1 + span)  # past any edge the aspect may still move
    # The fills reach far past the view and must not widen it: the data limits are put back after
    # them. The view stays autoscaled (not fixed), so that when the layout resizes the axes (a colour
    # bar, the legend) the equal scales move the limits quietly; fixed limits made matplotlib warn
    # "Ignoring fixed x limits to fulfill fixed data aspect".
    view = ax.dataLim.frozen()
    for obstacle in problem.obstacles:
        polygon = outline(obstacle, bounds)
        if polygon.size:
            ax.fill(polygon[:, 0], polygon[:, 1], color=OBSTACLE_COLOUR, zorder=0)
            continue
        xs, ys = np.linspace(bounds[0], bounds[1], 400), np.linspace(bounds[2], bounds[3], 400)
        grid_x, grid_y = np.meshgrid(xs, ys)
        with np.errstate(all="ignore"):  # (phi may be undefined on part of the grid: not drawn there)
            phi = obstacle.evaluate(np.column_stack((grid_x.ravel(), grid_y.ravel())))[0].reshape(grid_x.shape)
        if np.nanmax(phi) >= 0:
            ax.contourf(grid_x, grid_y, phi, levels=[0.0, np.inf], colors=[OBSTACLE_COLOUR], zorder=0)
    ax.dataLim.set(view)


def draw_equilibria(solutions: list[Solution], figure: Figure) -> None:
    """Every equilibrium in one axes (one colour each, lowest energy first), obstacles filled."""
    from matplotlib import colormaps  # (an optional extra: loaded to draw)

    ax = figure.add_subplot()
    colours = colormaps["tab10"]
    for index, solution in enumerate(solutions):
        colour = colours(index % 10)
        energy = with_unit(f"{solution.objective:.6g}", unit(solution.problem, "energy"))
        ax.plot(solution.x, solution.y, "-", color=colour, linewidth=2, label=f"#{index}: E = {energy}")
    if solutions:
        problem = solutions[0].problem
        supports = problem.support_positions
        ax.plot(supports[:, 0], supports[:, 1], "^", color="black", markersize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.margins(0.1)
        _draw_obstacles(ax, problem, *(solution.positions for solution in solutions))
        ax.set_title(f"{problem.name}: {len(solutions)} equilibria")
        ax.legend(loc="best", fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.1)
    _label_axes(ax, solutions[0].problem if solutions else None, "xy")


def save_equilibria_plot(solutions: list[Solution], path: str | os.PathLike[str]) -> None:
    save_figure(path, lambda figure: draw_equilibria(solutions, figure))


def save_figure(
    path: str | os.PathLike[str], draw: Callable[[Figure], object], size: tuple[float, float] = (8, 6)
) -> None:
    """Check ``path``, let ``draw`` fill a pyplot-free figure, and write it atomically (format from the suffix)."""
    image_format = check_plot_path(path)
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # (an optional extra: loaded to draw)
    from matplotlib.figure import Figure

    figure = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(figure)
    draw(figure)
    atomic_write(Path(path), lambda stream: figure.savefig(stream, format=image_format, dpi=150))


def check_plot_path(path: str | os.PathLike[str]) -> str:
    """The image format of ``path`` (from its suffix); a ``ScenarioError`` before any work is done."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in PLOT_SUFFIXES:
        raise ScenarioError(f"cannot write the plot to {str(target)!r}: the file name must end in .png, .svg or .pdf.")
    require_matplotlib()
    return suffix[1:]


def save_solution_plot(solution: Solution, path: str | os.PathLike[str], colour: str = "tension") -> None:
    """Render the plot to ``path`` (.png, .svg or .pdf, from the suffix), replacing it atomically:
    a 3-D problem in perspective (:func:`draw_solution_3d`), a planar one in the plane; the links
    coloured by ``colour`` (tension, or strain where some link is elastic)."""
    check_colouring(solution.problem, colour)
    if solution.problem.dimension == 3:
        save_figure(path, lambda figure: draw_solution_3d(solution, figure, colour=colour))
    else:
        save_figure(path, lambda figure: draw_solution(solution, figure.add_subplot(), colour=colour))


def draw_solution_3d(solution: Solution, figure: Figure, ax: Any = None, colour: str = "tension") -> Axes:
    """Draw a 3-D equilibrium on ``ax`` (a new 3-D axes of ``figure`` if None): links coloured by
    tension, or by strain with ``colour="strain"`` (dashed when slack), supports as black triangles,
    reactions as red arrows (the largest a quarter of the drawing's size), contact forces as blue and
    point loads as green arrows on scales of their own, spheres and ellipsoids as wireframes and
    half-spaces as translucent patches; equal scales on all three axes."""
    require_matplotlib()
    problem = solution.problem
    values, colour_label = _link_colours(solution, colour)
    return _draw_form_3d(
        figure,
        ax,
        positions=solution.positions,
        links=problem.link_nodes,
        values=values,
        taut=solution.link_taut,
        support_nodes=problem.support_nodes,
        arrows=solution.support_reactions,
        arrows_label="support reactions",
        contact=solution.contact_forces,
        obstacles=problem.obstacles,
        problem=problem,
        units=problem.units,
        colour_label=colour_label,
        title=_solution_title(solution),
    )


def draw_inverted_3d(inverted: Inverted, figure: Figure, ax: Any = None) -> Axes:
    """Draw the compression-only form of :func:`funicular.inversion.invert` like a hung one: links
    coloured by their compression ``-N_k``, supports, and the forces the form exerts on its supports
    (the hung reactions mirrored: down into them, and outwards). Obstacles are not drawn (the form
    stands on its supports; an obstacle's push is one of its loads)."""
    require_matplotlib()
    positions = inverted.positions
    if inverted.dimension == 2:  # a planar chain: drawn upright in the plane y = 0
        positions = np.column_stack([positions[:, 0], np.zeros(len(positions)), positions[:, 1]])
    forces = inverted.support_forces
    if inverted.dimension == 2:
        forces = np.column_stack([forces[:, 0], np.zeros(len(forces)), forces[:, 1]])
    compression = -inverted.axial_force
    largest = _finite_range(compression, (math.nan, math.nan))[1]
    return _draw_form_3d(
        figure,
        ax,
        positions=positions,
        links=inverted.links,
        values=compression,
        taut=compression > 0,
        support_nodes=inverted.support_nodes,
        arrows=forces,
        arrows_label="forces on the supports",
        contact=None,
        obstacles=(),
        units=inverted.units,
        colour_label=label("link compression", force_unit(inverted)),
        title=f"{inverted.name} inverted: max compression {with_unit(f'{largest:.4g}', force_unit(inverted))}",
    )


def draw_hung_and_inverted(solution: Solution, inverted: Inverted, figure: Figure) -> None:
    """The hung form and its inverted form side by side, on the same scale of lengths."""
    left = figure.add_subplot(1, 2, 1, projection="3d")
    right = figure.add_subplot(1, 2, 2, projection="3d")
    draw_solution_3d(solution, figure, left)
    draw_inverted_3d(inverted, figure, right)
    span = max(float(np.diff(getattr(axes, f"get_{axis}lim")())[0]) for axes in (left, right) for axis in "xyz")
    for axes in (left, right):  # (the larger cube for both, each about its own middle)
        for axis in "xyz":
            low, high = getattr(axes, f"get_{axis}lim")()
            middle = (low + high) / 2
            getattr(axes, f"set_{axis}lim")(middle - span / 2, middle + span / 2)


def _draw_form_3d(
    figure: Figure,
    ax: Any,
    *,
    positions: FloatArray,
    links: IntArray,
    values: FloatArray,
    taut: NDArray[np.bool_],
    support_nodes: IntArray,
    arrows: FloatArray,
    arrows_label: str,
    contact: FloatArray | None,
    obstacles: tuple[Obstacle, ...],
    units: str | None,
    colour_label: str,
    title: str,
    problem: Problem | None = None,
) -> Axes:
    from matplotlib.colors import Normalize
    from mpl_toolkits.mplot3d.art3d import Line3DCollection  # type: ignore[import-untyped]  # (no stubs)

    if ax is None:
        ax = figure.add_subplot(projection="3d")  # an Axes3D, which has no stubs
    collection = Line3DCollection(
        positions[links],
        cmap=COLORMAP,
        norm=Normalize(*_colour_limits(values)),
        linestyles="solid" if taut.all() else np.where(taut, "solid", "dashed").tolist(),
        linewidths=1.5,
        rasterized=links.shape[0] > RASTERIZE_LINKS,
    )
    collection.set_array(values)
    ax.add_collection3d(collection)
    supports = positions[support_nodes]
    ax.scatter(*supports.T, marker="^", color="black", s=40, depthshade=False, label="supports")
    low, high = np.nanmin(positions, axis=0), np.nanmax(positions, axis=0)
    size = float((high - low).max()) or 1.0
    largest = _finite_range(np.linalg.norm(arrows, axis=1), (0.0, 0.0))[1]
    if largest > 0:
        shown = arrows * (ARROW_FRACTION * size / largest)
        largest_force = with_unit(f"{largest:.3g}", force_unit(units))
        ax.quiver(*supports.T, *shown.T, color="crimson", label=f"{arrows_label} (largest {largest_force})")
        low, high = np.minimum(low, (supports + shown).min(axis=0)), np.maximum(high, (supports + shown).max(axis=0))
    if contact is not None:
        magnitude = np.linalg.norm(contact, axis=1)
        touching = np.flatnonzero(magnitude > 0)
        if touching.size:
            # Their own scale, as in the plane: a node's share of the weight is far below a reaction.
            strongest = float(magnitude[touching].max())
            pushes = contact[touching] * (CONTACT_FRACTION * size / strongest)
            ax.quiver(
                *positions[touching].T,
                *pushes.T,
                color="royalblue",
                linewidth=0.8,
                label=f"contact forces (largest {with_unit(f'{strongest:.3g}', force_unit(units))}, own scale)",
            )
    if problem is not None:  # (the hung form's point loads; the inverted form draws none)
        loaded, shown_loads, load_label = _point_load_arrows(problem, size)
        if loaded.size:
            ax.quiver(*positions[loaded].T, *shown_loads.T, color=LOAD_COLOUR, linewidth=0.8, label=load_label)
    for obstacle in obstacles:
        extent = _obstacle_extent(obstacle)
        if extent is not None and float((extent[1] - extent[0]).max()) <= BOUNDED_UP_TO * size:
            low, high = np.minimum(low, extent[0]), np.maximum(high, extent[1])
    middle, half = (low + high) / 2, max(float((high - low).max()), 1e-12) / 2
    box = np.array([middle - half, middle + half])
    for obstacle in obstacles:
        _draw_obstacle_3d(ax, obstacle, box)
    ax.set_xlim(box[0, 0], box[1, 0])
    ax.set_ylim(box[0, 1], box[1, 1])
    ax.set_zlim(box[0, 2], box[1, 2])
    ax.set_box_aspect((1.0, 1.0, 1.0))  # equal scales, so a sphere's drape looks round
    _label_axes(ax, units, "xyz")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title)
    figure.colorbar(collection, ax=ax, label=colour_label, shrink=0.7)
    return cast("Axes", ax)


WIREFRAME_STEPS = 24  # meridians and parallels of a sphere or ellipsoid
SURFACE_STEPS = 24  # a terrain surface is drawn on this many cells a side: coarse, so the net shows through


def _obstacle_extent(obstacle: Obstacle) -> FloatArray | None:
    """The bounding box (2, 3) of a sphere, an ellipsoid or a cuboid; None for an unbounded shape."""
    if isinstance(obstacle, Sphere):
        centre, axes = np.asarray(obstacle.center), np.full(3, obstacle.radius)
    elif isinstance(obstacle, Ellipsoid):
        centre, axes = np.asarray(obstacle.center), np.asarray(obstacle.semi_axes)
    elif isinstance(obstacle, Cuboid):
        # A box turned about z reaches |R| h from its centre along each axis.
        centre = np.asarray(obstacle.center)
        axes = np.abs(obstacle.rotation()) @ np.asarray(obstacle.half_sizes)
    else:
        return None
    return np.array([centre - axes, centre + axes])


def _draw_cuboid(ax: Any, cuboid: Cuboid, box: FloatArray) -> None:
    """A translucent prism: the cuboid's footprint (rounded corners) between its bottom and top,
    all clipped to the drawing's cube ``box``, with the outlines of its top and bottom."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    plan = cuboid.footprint((box[0, 0], box[1, 0], box[0, 1], box[1, 1]), samples=48)
    low = max(cuboid.center[2] - cuboid.half_sizes[2], box[0, 2])
    high = min(cuboid.center[2] + cuboid.half_sizes[2], box[1, 2])
    if len(plan) < 4 or low >= high:  # (outside the drawing)
        return
    bottom = np.column_stack([plan, np.full(len(plan), low)])
    top = np.column_stack([plan, np.full(len(plan), high)])
    sides = [[bottom[i], bottom[i + 1], top[i + 1], top[i]] for i in range(len(plan) - 1)]
    faces = Poly3DCollection(
        [bottom[:-1], top[:-1], *sides], facecolor=OBSTACLE_COLOUR, alpha=0.35, linewidth=0, label=cuboid.name
    )
    ax.add_collection3d(faces)
    for ring in (bottom, top):
        ax.plot(*ring.T, color="0.55", linewidth=0.6)


def _draw_surface(ax: Any, surface: Surface, box: FloatArray) -> None:
    """The terrain's height over the drawing's x-y square, a coarse translucent sheet, its heights
    clipped to the cube ``box`` (where f is undefined, at the cube's floor)."""
    x, y = np.meshgrid(*(np.linspace(box[0, axis], box[1, axis], SURFACE_STEPS + 1) for axis in (0, 1)))
    z = np.clip(np.nan_to_num(surface.heights(x, y), nan=box[0, 2]), box[0, 2], box[1, 2])
    ax.plot_surface(x, y, z, color=OBSTACLE_COLOUR, alpha=0.35, linewidth=0, label=surface.name)


def _draw_obstacle_3d(ax: Any, obstacle: Obstacle, box: FloatArray) -> None:
    """A sphere or ellipsoid as a grey wireframe; a half-space as a translucent patch of its plane
    and a terrain surface as a translucent sheet across the drawing's cube ``box`` (2, 3); a cuboid
    as a translucent box. Expressions and Python obstacles are not drawn (their region is not
    known in closed form)."""
    if isinstance(obstacle, Cuboid):
        _draw_cuboid(ax, obstacle, box)
    elif isinstance(obstacle, Surface):
        _draw_surface(ax, obstacle, box)
    elif isinstance(obstacle, Sphere | Ellipsoid):
        extent = _obstacle_extent(obstacle)
        assert extent is not None  # (a sphere or an ellipsoid)
        centre, axes = (extent[0] + extent[1]) / 2, (extent[1] - extent[0]) / 2
        u, v = np.meshgrid(
            np.linspace(0, 2 * np.pi, WIREFRAME_STEPS + 1), np.linspace(0, np.pi, WIREFRAME_STEPS // 2 + 1)
        )
        ax.plot_wireframe(
            centre[0] + axes[0] * np.cos(u) * np.sin(v),
            centre[1] + axes[1] * np.sin(u) * np.sin(v),
            centre[2] + axes[2] * np.cos(v),
            color="0.55",
            linewidth=0.5,
            label=obstacle.name,
        )
    elif isinstance(obstacle, HalfSpace):
        normal = np.asarray(obstacle.normal, dtype=np.float64)
        point = np.asarray(obstacle.point, dtype=np.float64)
        # The plane as a graph over the two axes its normal is least along, clipped to the cube.
        k = int(np.argmax(np.abs(normal)))
        i, j = (axis for axis in range(3) if axis != k)
        a, b = np.meshgrid(np.linspace(box[0, i], box[1, i], 2), np.linspace(box[0, j], box[1, j], 2))
        c = point[k] - (normal[i] * (a - point[i]) + normal[j] * (b - point[j])) / normal[k]
        coordinates: list[FloatArray] = [a, a, a]
        coordinates[i], coordinates[j], coordinates[k] = a, b, np.clip(c, box[0, k], box[1, k])
        ax.plot_surface(*coordinates, color=OBSTACLE_COLOUR, alpha=0.35, linewidth=0, label=obstacle.name)
