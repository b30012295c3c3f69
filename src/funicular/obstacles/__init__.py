"""Rigid obstacles: each occupies ``{phi >= 0}``; every free node must satisfy ``phi(x, y) <= 0``.

An obstacle is anything with a ``name``, a ``convex`` flag and ``evaluate(points)`` returning
``phi`` (k,), its gradient (k, 2) and its Hessian (k, 2, 2) at the points (k, 2), vectorised.
The contact force obstacle j exerts on node i is ``-nu_ji grad phi_j(p_i)``: it points out of
the obstacle and does not change when phi is multiplied by a positive constant.

Shapes in the plane: :class:`HalfPlane`, :class:`Disk`, :class:`Ellipse`, :class:`Box` (rounded
corners), :class:`Graph` (terrain below ``y = f(x)``) and :class:`Expression` (any ``phi(x, y)``),
the last two written as text and differentiated by sympy (the ``expr`` extra);
:class:`CallableObstacle` wraps a Python function. In space (``dimension = 3``, points (k, 3)):
:class:`Sphere`, :class:`Ellipsoid`, :class:`HalfSpace`, :class:`Cuboid` (a rounded box),
:class:`Surface` (terrain below ``z = f(x, y)``) and :class:`Expression` with ``dimension = 3``
(any ``phi(x, y, z)``); an obstacle says which by its ``dimension`` attribute (2 when it has
none). Each shape's ``phi`` has a nonzero gradient on its boundary, so the contact constraint is
regular there. ``outline(bounds)`` gives a closed polygon for plotting.

For ``contact = "links"`` the convex built-ins (disk, ellipse, box, half-plane) also give phi's
largest value along a segment, its maximiser and derivatives (:func:`segment_max`), and the
link-contact constraint built on it (:func:`link_contact`): the one place these live. Every
built-in shape knows how deep a point lies inside it (``depth``, the distance to its boundary) and
how deep a segment reaches into it (:func:`segment_depth`).

Every name below is imported from here; each lives in one module, imported only by the ones after
it:

* ``base``: the :class:`Obstacle` protocol, the shared types (``Evaluation``, ``Bounds``,
  ``NodeFields``), :func:`obstacle_dimension`, :func:`outline`, :func:`depth`, and the checks of a
  shape's parameters and evaluations;
* ``native``: the built-in shapes as the solver core evaluates them (``NativeShape``,
  :func:`evaluate_native`, :class:`Quadratic`);
* ``_ellipsoid``: the exact distance to an ellipse's or ellipsoid's boundary;
* ``shapes``: the built-in shapes, their outlines and exact depths, and :func:`native_shape` /
  :func:`native_shapes`;
* ``expressions``: :class:`Graph`, :class:`Surface`, :class:`Expression` (sympy) and
  :class:`CallableObstacle`;
* ``contact``: phi's largest value along a segment (:func:`segment_max`), link contact
  (:func:`link_contact`, :func:`link_contact_ends`) and :func:`segment_depth`.
"""

from funicular.obstacles.base import Bounds, Evaluation, NodeFields, Obstacle, depth, obstacle_dimension, outline
from funicular.obstacles.contact import (
    DEPTH_SHAPES,
    SEGMENT_SHAPES,
    SegmentMax,
    has_segment_depth,
    has_segment_max,
    link_contact,
    link_contact_ends,
    segment_depth,
    segment_max,
)
from funicular.obstacles.expressions import CallableObstacle, Expression, Graph, Surface
from funicular.obstacles.native import NativeShape, Quadratic, evaluate_native
from funicular.obstacles.shapes import (
    Box,
    Cuboid,
    Disk,
    Ellipse,
    Ellipsoid,
    HalfPlane,
    HalfSpace,
    Sphere,
    native_shape,
    native_shapes,
)

__all__ = [
    "DEPTH_SHAPES",
    "SEGMENT_SHAPES",
    "Bounds",
    "Box",
    "CallableObstacle",
    "Cuboid",
    "Disk",
    "Ellipse",
    "Ellipsoid",
    "Evaluation",
    "Expression",
    "Graph",
    "HalfPlane",
    "HalfSpace",
    "NativeShape",
    "NodeFields",
    "Obstacle",
    "Quadratic",
    "SegmentMax",
    "Sphere",
    "Surface",
    "depth",
    "evaluate_native",
    "has_segment_depth",
    "has_segment_max",
    "link_contact",
    "link_contact_ends",
    "native_shape",
    "native_shapes",
    "obstacle_dimension",
    "outline",
    "segment_depth",
    "segment_max",
]
