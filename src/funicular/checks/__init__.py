"""Diagnostics of any point: active set, multipliers, KKT residuals, LICQ, MFCQ and second order.

:func:`check` takes a problem, positions and (optionally) multipliers, from funicular's solver,
another solver or a file, and reports what holds there. Methods, in the problem's words:

* **Tolerance.** ``tol`` is relative; lengths compare with ``tol * l`` (``l`` the longest link),
  forces with ``tol * W`` (``W`` the total weight). A link is *taut* when ``d_k >= l_k - tol l``; a
  free node *touches* an obstacle when ``phi / |grad phi| >= -tol l``. A point that violates a
  constraint by more than ``tol l`` is *infeasible*: the report names the worst violation and
  stops there (no LICQ or second-order check of a point that is not in the feasible set).
  Contacts are node contacts (``contact = "nodes"``); supports carry no contact constraint (see
  :mod:`funicular._forces`). ``contact = "links"`` with obstacles is not checked here yet, nor
  are nets and 3-D chains by :func:`check`: it says so (``ScenarioError``), :func:`licq_of`
  returns None and :func:`second_order` "undecided". A net (or a 3-D chain) is checked by
  :func:`check_structure` (:class:`StructureCheck`): its multipliers (given, or recovered as
  below), the KKT residuals, its statics from :func:`statics` (:class:`Statics`: degree of
  indeterminacy, self-stress states, force ranges; the ``licq`` block of its result file) and the
  second order as below, on dense matrices up to 1500 free coordinates (above, a strict minimum
  by a sparse penalty test, ``H + rho A^T A - s I`` positive definite, and a saddle by the
  eigenvector of ``H + rho A^T A`` that curves down most, moved to keep the active constraints).
* **Jacobian.** Supports are eliminated: the support rows are unit rows, always independent,
  and only add their own columns, so LICQ of the full problem is equivalent to full row rank of
  the active link and contact rows restricted to the free coordinates. Each row is scaled so
  that its multiplier is a force: a link row holds the unit vectors ``+u_k`` at node k and
  ``-u_k`` at node k+1 (``u_k = (p_k - p_{k+1}) / d_k``), its multiplier is the tension ``T_k``; a
  contact row holds the unit normal ``grad phi / |grad phi|``, its multiplier is the contact
  force ``nu |grad phi|``. These rows are dimensionless and the same in both formulations.
* **LICQ.** The rows are dependent when a singular value of this matrix is ``<= RANK_TOL``. A
  chain of N taut links has ``sigma_min ~ 1 / N`` even where LICQ holds, so a fixed ``1e-8``
  separates "independent" from "dependent up to rounding" for N up to ~1e7. Small problems use a
  dense SVD; large ones the smallest eigenvalues of ``A A^T`` by shift-invert Lanczos (``eigsh``
  on a banded LU: sorted by their first node, the rows couple only neighbours), refined by an SVD
  of ``A^T W`` on the vectors found, so ``sigma_min`` is not limited to the square root of the
  rounding error. The left null vectors found are the dependent combinations: self-balanced sets
  of link and contact forces. Where only the verdict of independence is needed (the second-order
  check of a solver's result), a cheaper proof comes first: a Cholesky factorization of
  ``A A^T - (100 RANK_TOL)^2 I`` (banded for large problems), or ``1 / ||R^-1||_F`` of the QR
  ``A^T = Q R`` the second-order check needs anyway, shows every singular value above
  ``100 RANK_TOL``; only if that fails are the singular values computed.
* **Multipliers.** If none are given they are recovered from the positions: the least-squares
  solution of stationarity ``A^T t = -grad E`` over the active set (dense ``lstsq``, or sparse
  normal equations with one refinement step), moved along the null vectors to the smallest total
  force that keeps every force ``>= 0`` (a ``linprog``); if no exact nonnegative solution exists,
  a nonnegative least-squares fit (``nnls``, or ``lsq_linear`` for large problems).
* **MFCQ.** With supports eliminated every active constraint is an inequality, and by Gordan's
  theorem MFCQ fails iff a nonzero nonnegative combination of the active rows vanishes, i.e. iff
  the left null space holds a vector ``w >= 0``: a ``linprog`` in the null-space coordinates.
* **Multiplier ranges.** The multiplier set is ``{t0 + W c >= 0}`` (``t0`` the multipliers used,
  ``W`` the null vectors). Rows of W with the same direction are merged (a taut segment's links
  all share one), and each force's range comes from two ``linprog`` calls per direction. An
  unbounded range has ``max = inf`` (``null`` in JSON).
* **Second order.** ``H`` is the Hessian of the Lagrangian over the free coordinates. Strictly
  active constraints (force ``> tol W``) are equalities of the critical cone; weakly active
  ones make it a cone. If ``H`` is positive definite on the null space of the strictly active
  rows (a superset of the cone) the point is a strict local minimum (SOSC; valid for the
  multiplier used even when LICQ fails). If it has negative curvature on the null space of all
  active rows (a subset of the cone) and LICQ holds, the point is not a minimum (the necessary
  condition fails). Anything else is "undecided". The smallest eigenvalue of ``Z^T H Z`` comes
  from a dense null-space basis for small problems (one Householder QR of the rows, strictly
  active first, serves both null spaces); for large ones from shift-invert Lanczos on the
  bordered matrix ``[[H - s I, A^T], [A, 0]]`` (a banded LU, each row next to its first node;
  dependent rows dropped), whose inverse restricted to the positions is
  ``Z (Z^T H Z - s I)^{-1} Z^T``; the shift ``s`` lies below the spectrum because the link
  terms of ``H`` are positive semidefinite and the contact terms are 2x2 blocks whose
  eigenvalues bound the rest. An eigenvalue counts as zero below
  ``tol W / (N L)``: a curvature that changes the energy by less than ``tol W L`` when every
  node moves by the chain length ``L``.
* **A cheap proof of a strict minimum.** If ``H + rho A^T A - s I`` (A the strictly active rows,
  s the zero threshold plus rounding) is positive definite, H exceeds s on the null space of A:
  the sufficient condition without an eigenvalue. Links and contacts touch one or two
  neighbouring nodes, so the matrix is block tridiagonal like H and one O(N) Cholesky
  factorization decides; a failure only means "not proven". (The solver's saddle escape runs the
  same test, and looks for its direction, on its own Newton matrix: the core's ``curvature`` module.)
"""

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
    Violation,
)
from funicular.checks._statics import Statics, proven_determinate, statics, statics_of
from funicular.checks._structure import StructureCheck, check_structure
from funicular.checks._tolerances import DEFAULT_TOL, RANK_TOL

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
    "StructureCheck",
    "Violation",
    "check",
    "check_solution",
    "check_structure",
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
