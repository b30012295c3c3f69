"""Diagnostics of any point: active set, multipliers, KKT residuals, LICQ and the statics, MFCQ and
second order.

:func:`check` takes a problem (a chain or a net, in the plane or in space, with or without point
loads), positions and (optionally) multipliers, from funicular's solver, another solver or a file,
and reports what holds there (:class:`CheckReport`). It judges the point it is given: it never
solves. Methods, in the problem's words:

* **Tolerance.** ``tol`` is relative; lengths compare with ``tol * l`` (``l`` the longest link),
  forces with ``tol * W`` (``W`` the total weight). A link is *taut* when ``d_k >= l_k - tol l``; a
  free node *touches* an obstacle when ``phi / |grad phi| >= -tol l``. A point that violates a
  constraint by more than ``tol l`` is *infeasible*: the report names the worst violation and
  stops there (no LICQ or second-order check of a point that is not in the feasible set).
  Contacts are node contacts (``contact = "nodes"``); supports carry no contact constraint (see
  :mod:`funicular._forces`). ``contact = "links"`` with obstacles is not checked here yet: it says
  so (``ScenarioError``), :func:`licq_of` returns None and :func:`second_order` "undecided".
* **Jacobian.** Supports are eliminated: the support rows are unit rows, always independent,
  and only add their own columns, so LICQ of the full problem is equivalent to full row rank of
  the active link and contact rows restricted to the free coordinates. Each row is scaled so
  that its multiplier is a force: a link row holds the unit vectors ``+u_k`` at its first node a
  and ``-u_k`` at its second node b (``u_k = (p_a - p_b) / d_k``; a chain's link k joins k and
  k+1), its multiplier is the tension ``T_k``; a contact row holds the unit normal
  ``grad phi / |grad phi|``, its multiplier is the contact force ``nu |grad phi|``. These rows are
  dimensionless and the same in both formulations.
* **Factorizations.** The matrices built from the rows and the Hessian (``A A^T``, the bordered
  matrix below) are factored with their unknowns ordered by node, each row next to its first
  node: a chain's then couple only neighbours, a band a few unknowns wide, factored by LAPACK's
  banded LU in O(N); a net's, whose band would be wide, by SuperLU's sparse LU.
* **LICQ and the statics.** The rows are dependent when a singular value of this matrix is
  ``<= RANK_TOL``. A chain of N taut links has ``sigma_min ~ 1 / N`` even where LICQ holds, so a
  fixed ``1e-8`` separates "independent" from "dependent up to rounding" for N up to ~1e7. Small
  problems (up to DENSE_LIMIT free coordinates) use a dense SVD; larger ones the smallest
  eigenvalues of ``A A^T`` by shift-invert Lanczos (``eigsh``), NULL_BLOCK at a time and twice as
  many while all found are dependent, refined by an SVD of ``A^T W`` on the vectors found, so
  ``sigma_min`` is not limited to the square root of the rounding error; beyond
  SELF_STRESS_SOUGHT dependencies the dense SVD up to DENSE_ENTRIES entries, and past that LICQ is
  not decided (``holds`` and ``rank`` None). The left null vectors found are the dependent
  combinations, in a basis with one pivot constraint each: self-balanced sets of link and contact
  forces, a structure's *self-stress states*, described in words with how the supports' reactions
  change. Their number is the *degree of static indeterminacy* (0: the forces are unique, the
  structure statically determinate). Where only the verdict of independence is needed (the
  second-order check of a solver's result, a result file's statics, the note of ``funicular
  solve``), a cheaper proof comes first: a Cholesky factorization of ``A A^T - (100 RANK_TOL)^2 I``
  (in the solver core: banded for a chain's rows, sparse for a net's), or ``1 / ||R^-1||_F`` of
  the QR ``A^T = Q R`` the second-order check needs anyway, shows every singular value above
  ``100 RANK_TOL``; only if that fails are the singular values computed. :func:`statics` gives
  the same findings as a :class:`Statics` (the ``licq`` block of a net's result file).
* **Multipliers.** If none are given they are recovered from the positions: the least-squares
  solution of stationarity ``A^T t = -grad E`` over the active set (dense ``lstsq``, or sparse
  normal equations with one refinement step), moved along the null vectors to the smallest total
  force that keeps every force ``>= 0`` (a ``linprog``); if no exact nonnegative solution exists
  (or the dependencies are not decided), a nonnegative least-squares fit (``nnls``, or
  ``lsq_linear`` for large problems).
* **MFCQ.** With supports eliminated every active constraint is an inequality, and by Gordan's
  theorem MFCQ fails iff a nonzero nonnegative combination of the active rows vanishes, i.e. iff
  the left null space holds a vector ``w >= 0`` (a pure tension self-stress: the forces are then
  unbounded): a ``linprog`` in the null-space coordinates.
* **Force ranges.** The multiplier set is ``{t0 + W c >= 0}`` (``t0`` the forces used, ``W`` the
  null vectors, their entries at rounding level zero). Rows of W with the same direction are
  merged (a taut segment's links all share one), and each force's range comes from two
  ``linprog`` calls per direction (at most MAX_RANGE_LPS directions and LP_SECONDS in all); a
  bound within rounding of 0 is 0. An unbounded range has ``max = inf`` (``null`` in JSON). The
  report lists the forces that are not determined; the statics every force's range, up to
  RANGES_UP_TO active constraints.
* **Second order.** One test decides every problem's verdict (``_second_order`` in
  ``funicular.checks._second_order``). ``H`` is the Hessian of the Lagrangian over
  the free coordinates, by d x d node blocks (the energy is linear: the link terms, blocks on each
  link's two nodes, and the contact terms, one block per touching node). Strictly active
  constraints (force ``> tol W``) are equalities of the critical cone; weakly active ones make it
  a cone. If ``H`` is positive definite on the null space of the strictly active rows (a
  superset of the cone) the point is a strict local minimum (SOSC; valid for the multiplier used
  even when LICQ fails). If it has negative curvature on the null space of all active rows (a
  subset of the cone) and LICQ holds, the point is not a minimum (the necessary condition fails),
  and the eigenvector is a direction that keeps every active constraint active. Anything else is
  "undecided". The smallest eigenvalue of ``Z^T H Z`` comes from a dense null-space basis up to
  DENSE_LIMIT free coordinates (one Householder QR of the rows, strictly active first, serves
  both null spaces); above, from shift-invert Lanczos on the bordered matrix
  ``[[H - s I, A^T], [A, 0]]`` (dependent rows dropped), whose inverse restricted to the
  positions is ``Z (Z^T H Z - s I)^{-1} Z^T``; the shift ``s`` lies below the spectrum because
  the link terms of ``H`` are positive semidefinite and the contact terms' node blocks bound the
  rest from below. An eigenvalue counts as zero below ``tol W / (N L)``: a curvature that changes
  the energy by less than ``tol W L`` when every node moves by the chain length ``L``.
* **A cheap proof of a strict minimum.** If ``H + rho A^T A - s I`` (A the strictly active rows,
  s the zero threshold plus rounding) is positive definite, H exceeds s on the null space of A:
  the sufficient condition without an eigenvalue. ``A^T A`` has H's node blocks, so one sparse
  Cholesky factorization in the solver core decides (O(N) for a chain's block tridiagonal
  matrix); a failure only means "not proven". :func:`proves_strict_minimum` runs it alone;
  :func:`second_order` with ``proof=True`` runs it before the eigenvalue problem (the explorer
  does). (The solver's saddle escape runs the same test, and looks for its direction, on its own
  Newton matrix: the core's ``curvature`` module; the checker does not use it.)
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from funicular.checks._check import (
        check,
        check_solution,
        licq_of,
        proves_strict_minimum,
        recover_multipliers,
        second_order,
    )
    from funicular.checks._files import load_solution, read_solution, solution_document
    from funicular.checks._report import (
        LICQ,
        MFCQ,
        ActiveSet,
        CheckReport,
        Dependency,
        MultiplierRange,
        Multipliers,
        SecondOrder,
        Statics,
        Violation,
    )
    from funicular.checks._statics import proven_determinate, statics, statics_of
    from funicular.checks._tolerances import DEFAULT_TOL, RANK_TOL

# Each name and the module it comes from, loaded on first use: the proof of unique forces
# (proven_determinate) then runs without the SciPy parts the rest of the checker needs.
_LAZY = {
    **dict.fromkeys(
        ("check", "check_solution", "licq_of", "proves_strict_minimum", "recover_multipliers", "second_order"),
        "funicular.checks._check",
    ),
    **dict.fromkeys(("load_solution", "read_solution", "solution_document"), "funicular.checks._files"),
    **dict.fromkeys(
        (
            *("LICQ", "MFCQ", "ActiveSet", "CheckReport", "Dependency", "MultiplierRange", "Multipliers"),
            *("SecondOrder", "Statics", "Violation"),
        ),
        "funicular.checks._report",
    ),
    **dict.fromkeys(("proven_determinate", "statics", "statics_of"), "funicular.checks._statics"),
    **dict.fromkeys(("DEFAULT_TOL", "RANK_TOL"), "funicular.checks._tolerances"),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # (looked up once)
        return value
    if name.startswith("_") and not name.startswith("__"):  # a submodule, as `checks._tolerances`
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as error:
            if error.name != f"{__name__}.{name}":
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "DEFAULT_TOL",
    "LICQ",
    "MFCQ",
    "RANK_TOL",
    "ActiveSet",
    "CheckReport",
    "Dependency",
    "MultiplierRange",
    "Multipliers",
    "SecondOrder",
    "Statics",
    "Violation",
    "check",
    "check_solution",
    "licq_of",
    "load_solution",
    "proven_determinate",
    "proves_strict_minimum",
    "read_solution",
    "recover_multipliers",
    "second_order",
    "solution_document",
    "statics",
    "statics_of",
]
