"""The hanging model, inverted: a hung equilibrium turned upside down is a form in pure compression.

A net (or chain) hanging under its own weight carries it in tension only. Mirror it in a
horizontal plane, the plane of its supports' mean height ``z0`` (``z -> 2 z0 - z``; ``y`` for a
planar chain), and every link force keeps its magnitude but changes sign: the hung form's
tensions become the inverted form's compressions. This is the form-finding of Gaudí's hanging
models, Isler's shells and Frei Otto's nets.

Sign convention (the inverted form read as a vault carrying its own weight):

* ``axial_force[k] = N_k = -T_k <= 0``: the force in link k, positive in tension, so negative
  here. On node i the link exerts ``N_k u_ij``, ``u_ij`` the unit vector from i towards the
  link's other node j: a compression pushes its two nodes apart.
* ``loads[i]``: the loads on node i, its weight ``-g m_i`` along the last axis (still acting down)
  plus any point load and contact force of the hung form, mirrored and reversed (``-M P_i`` and
  ``-M C_i``, ``M`` the mirror).
* ``support_reactions[s]``: the force support s exerts on the inverted form, ``-M R_s`` (``R_s``
  the hung reaction): upwards, and inwards where the hung reaction pulled outwards.
* ``support_forces = -support_reactions = M R_s``: the hung reactions mirrored, the force the
  form exerts on its supports; its vertical component points down into them, its horizontal
  component is the thrust.

Under this convention each node is in balance,
``sum_k N_k u_ij + loads[i] (+ support_reactions at a support) = 0``: it is the hung balance
multiplied by ``-M``. Read the other way, the same numbers say the mirrored form with tensions
``T_k`` is in balance under the reversed loads (weights acting upwards), held by
``support_forces``.

:func:`write_obj` writes the form as a Wavefront OBJ (``v``, ``l`` and, for a grid net, ``f``
lines; each link's axial force as a ``# axial_force <link> <value>`` comment) and a CSV beside it.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from funicular._io import atomic_write_text, check_writable
from funicular._units import force_unit, in_unit, label, length_unit
from funicular.errors import ScenarioError
from funicular.model import FloatArray, IntArray, Problem
from funicular.solution import Solution

__all__ = ["Inverted", "check_obj_path", "companion_csv", "grid_faces", "invert", "write_obj"]

OBJ_SUFFIX = ".obj"
DIGITS = 17  # significant digits written: a float64 reads back exactly


@dataclass(frozen=True, eq=False)
class Inverted:
    """A hung equilibrium mirrored into its compression-only form (see the module's sign convention).

    Attributes:
        name: the problem's name.
        status: how the hung solve ended (``"optimal"`` when it converged).
        positions: the mirrored node positions (N, d).
        links: each link's node pair (L, 2).
        axial_force: each link's axial force (L,), ``-T_k``: negative, a compression.
        loads: the loads on each node (N, d): weight downwards plus reversed, mirrored contact forces.
        support_nodes: the support nodes (S,).
        support_reactions: the force each support exerts on the inverted form (S, d), ``-M R``.
        mirror_height: ``z0`` (``y0`` for a planar chain), the supports' mean height: ``h' = 2 h0 - h``.
        faces: the quadrilateral cells (F, 4) of a grid net, counter-clockwise in plan; (0, 4) otherwise.
        units: the unit system the scenario declares (``"SI"``), or None: the files label their
            numbers with its units only where it is declared.
    """

    name: str
    status: str
    positions: FloatArray
    links: IntArray
    axial_force: FloatArray
    loads: FloatArray
    support_nodes: IntArray
    support_reactions: FloatArray
    mirror_height: float
    faces: IntArray
    units: str | None = None

    @property
    def dimension(self) -> int:
        return int(self.positions.shape[1])

    @property
    def support_forces(self) -> FloatArray:
        """The force the form exerts on each support (S, d): the hung reactions mirrored, pointing
        down into the supports (and outwards: the thrust)."""
        return -self.support_reactions

    @property
    def link_lengths(self) -> FloatArray:
        """The current length of every link (L,)."""
        ends = self.positions[self.links]
        return np.asarray(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1), dtype=np.float64)

    def scaled(self, scale: float) -> Inverted:
        """The same form with every coordinate multiplied by ``scale`` (about the origin), as from
        a model to a building. The forces are unchanged: the balance of a node involves only the
        directions of its links, which scaling keeps."""
        if isinstance(scale, bool) or not (isinstance(scale, int | float) and math.isfinite(scale) and scale > 0):
            raise ScenarioError(f"scale = {scale!r}; it must be a finite number > 0.", key="scale")
        return replace(self, positions=self.positions * scale, mirror_height=self.mirror_height * scale)


def _mirror(dimension: int) -> FloatArray:
    """The diagonal of ``M``: the last (vertical) axis reversed."""
    diagonal = np.ones(dimension)
    diagonal[-1] = -1.0
    return diagonal


def invert(solution: Solution) -> Inverted:
    """The compression-only form of a hung equilibrium: ``solution`` mirrored in the horizontal
    plane of its supports' mean height, its tensions turned into compressions of the same magnitude.

    A non-converged solution is inverted as it is (``status`` says so); its mirror is only as
    balanced as the hung point was.
    """
    problem: Problem = solution.problem
    mirror = _mirror(problem.dimension)
    height = float(np.mean(problem.support_positions[:, -1]))
    positions = solution.positions * mirror
    positions[:, -1] += 2.0 * height
    weight = np.zeros_like(positions)
    weight[:, -1] = -problem.gravity * problem.masses
    if problem.loads is not None:
        weight -= problem.loads * mirror
    return Inverted(
        name=problem.name,
        status=solution.status.value,
        positions=_frozen(positions),
        links=_frozen(np.array(problem.link_nodes, dtype=np.intp)),
        axial_force=_frozen(-np.asarray(solution.link_tension, dtype=np.float64)),
        loads=_frozen(weight - solution.contact_forces * mirror),
        support_nodes=_frozen(np.array(problem.support_nodes, dtype=np.intp)),
        support_reactions=_frozen(-solution.support_reactions * mirror),
        mirror_height=height,
        faces=_frozen(grid_faces(problem)),
        units=problem.units,
    )


def _frozen(array: NDArray[Any]) -> NDArray[Any]:
    array.setflags(write=False)
    return array


def grid_faces(problem: Problem) -> IntArray:
    """The cells (F, 4) of a net whose links are exactly those :func:`funicular.nets.grid` makes
    (for some rows x columns), each ``(i, i+1, i+1+c, i+c)``; an empty (0, 4) array for any other net
    or a chain, whose faces are not known from its links alone."""
    none = np.zeros((0, 4), dtype=np.intp)
    if problem.links is None:
        return none
    n, links = problem.n_nodes, problem.links
    for rows in range(2, n // 2 + 1):
        columns, left = divmod(n, rows)
        if left or columns < 2 or links.shape[0] != 2 * rows * columns - rows - columns:
            continue
        index = np.arange(n).reshape(rows, columns)
        across = np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()])
        up = np.column_stack([index[:-1, :].ravel(), index[1:, :].ravel()])
        if np.array_equal(links, np.vstack([across, up])):
            corner = index[:-1, :-1].ravel()
            return np.column_stack([corner, corner + 1, corner + 1 + columns, corner + columns])
    return none


def check_obj_path(path: str | os.PathLike[str], option: str = "") -> Path:
    """The companion CSV of the OBJ file ``path``, after checking that both can be written and that
    ``path`` ends in .obj: an :class:`~funicular.errors.OutputError` (or ``ScenarioError`` for the
    suffix) naming ``option`` before any work is done."""
    target = Path(path)
    where = f"{option} {str(path)!r}" if option else repr(str(path))
    if target.suffix.lower() != OBJ_SUFFIX:
        raise ScenarioError(
            f"{where}: the inverted form is written as Wavefront OBJ; use a file name ending in .obj.", key=option
        )
    csv_path = companion_csv(target)
    check_writable(target, option)
    check_writable(csv_path, f"the CSV beside {option}".rstrip())
    return csv_path


def companion_csv(path: str | os.PathLike[str]) -> Path:
    """The CSV written beside the OBJ file ``path``: the same name ending in .csv."""
    return Path(path).with_suffix(".csv")


def _number(value: float) -> str:
    return format(float(value) + 0.0, f".{DIGITS}g")  # (+ 0.0: no "-0" for a mirrored zero)


def _xyz(inverted: Inverted) -> FloatArray:
    """The coordinates written: a planar chain is put in the plane y = 0 with its height as z, so
    that every file is z-up like a 3-D one."""
    if inverted.dimension == 3:
        return inverted.positions
    x, h = inverted.positions.T
    return np.column_stack([x, np.zeros_like(x), h])


def obj_text(inverted: Inverted) -> str:
    """The OBJ file's text (see :func:`write_obj`)."""
    length, force = length_unit(inverted), force_unit(inverted)
    lines = [
        f"# {inverted.name}: the hung equilibrium mirrored in z = {_number(inverted.mirror_height)} (compression only)",
        f"# status {inverted.status}",
        *([f"# coordinates (v lines) in {length}, forces in {force}"] if length else []),
        "# each l line follows a comment 'axial_force LINK VALUE': link LINK (0-based, in the order of the "
        f"l lines) carries the axial force VALUE{in_unit(force)}, negative in compression",
        "# each 'support_force NODE FX FY FZ' comment: the force the form exerts on support NODE (0-based)"
        + ("," + in_unit(force) if force else ""),
        f"o {inverted.name}",
    ]
    lines += [f"v {_number(x)} {_number(y)} {_number(z)}" for x, y, z in _xyz(inverted)]
    for k, ((i, j), force) in enumerate(zip(inverted.links, inverted.axial_force, strict=True)):
        lines.append(f"# axial_force {k} {_number(force)}")
        lines.append(f"l {i + 1} {j + 1}")
    lines += ["f " + " ".join(str(int(i) + 1) for i in face) for face in inverted.faces]
    for node, force in zip(inverted.support_nodes, inverted.support_forces, strict=True):
        lines.append(f"# support_force {int(node)} " + " ".join(_number(f) for f in force))
    return "\n".join(lines) + "\n"


def csv_text(inverted: Inverted) -> str:
    """The CSV's text: one row per link (link, node i, node j, length, axial force); the last two
    columns' headers carry their units where the scenario declares them (``length [m]``)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(
        ["link", "node_i", "node_j", label("length", length_unit(inverted)), label("axial_force", force_unit(inverted))]
    )
    for k, ((i, j), length, force) in enumerate(
        zip(inverted.links, inverted.link_lengths, inverted.axial_force, strict=True)
    ):
        writer.writerow([k, int(i), int(j), _number(length), _number(force)])
    return buffer.getvalue()


def write_obj(inverted: Inverted, path: str | os.PathLike[str]) -> Path:
    """Write ``inverted`` to the OBJ file ``path`` and its links to a CSV beside it (returned).

    The OBJ holds a ``v x y z`` line per node (1-based in the ``l`` and ``f`` lines; a planar chain
    lies in the plane y = 0), an ``l i j`` line per link preceded by its
    ``# axial_force <link> <value>`` comment (OBJ has no per-element attributes a CAD program
    reads), an ``f`` line per cell of a grid net, and a ``# support_force <node> <fx> <fy> <fz>``
    comment per support (the force the form exerts on it). The CSV has one row per link:
    ``link, node_i, node_j, length, axial_force`` (nodes 0-based; ``length [m]`` and
    ``axial_force [N]`` where the scenario declares SI units). Both are written atomically.
    """
    csv_path = check_obj_path(path)
    atomic_write_text(path, obj_text(inverted))
    atomic_write_text(csv_path, csv_text(inverted))
    return csv_path
