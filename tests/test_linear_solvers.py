"""The pluggable linear algebra: the compiled block Cholesky, LAPACK's banded Cholesky and the
dense reference solve the same block-tridiagonal systems, and give the same equilibria."""

from __future__ import annotations

import numpy as np
import pytest

from funicular import SolverOptions, solve
from funicular.scenario import builtin_scenarios, load_scenario
from funicular.solver import fused
from funicular.solver.banded import BlockTridiagonal, LinearSolver, banded_cholesky, dense_cholesky
from funicular.solver.compiled import HAVE_NUMBA, block_cholesky, default_linear_solver, jit

SOLVERS = pytest.mark.parametrize("linear_solver", [block_cholesky, banded_cholesky, dense_cholesky])


def random_spd(n: int, seed: int) -> BlockTridiagonal:
    """A random symmetric positive definite block-tridiagonal matrix (diagonally dominant)."""
    rng = np.random.default_rng(seed)
    diagonal = rng.normal(size=(n, 2, 2))
    diagonal = diagonal + diagonal.transpose(0, 2, 1)
    off_diagonal = rng.normal(size=(n - 1, 2, 2))
    diagonal[:, 0, 0] += 12.0
    diagonal[:, 1, 1] += 12.0
    return BlockTridiagonal(diagonal, off_diagonal)


def test_block_structure_matches_its_dense_and_band_forms() -> None:
    matrix = random_spd(7, 0)
    dense = matrix.to_dense()
    np.testing.assert_array_equal(dense, dense.T)
    x = np.random.default_rng(1).normal(size=matrix.size)
    np.testing.assert_allclose(matrix @ x, dense @ x, rtol=1e-14, atol=1e-13)
    band = matrix.to_banded()  # LAPACK upper storage: ab[3 + i - j, j] = A[i, j]
    for i, j in zip(*np.nonzero(np.triu(dense)), strict=True):
        assert band[3 + i - j, j] == dense[i, j]


@SOLVERS
@pytest.mark.parametrize("n", [1, 2, 50])
def test_linear_solvers_solve_the_system(linear_solver: LinearSolver, n: int) -> None:
    """Against numpy's dense LU solve of the same matrix."""
    matrix = random_spd(n, n)
    rhs = np.random.default_rng(n + 1).normal(size=matrix.size)
    expected = np.linalg.solve(matrix.to_dense(), rhs)
    np.testing.assert_allclose(linear_solver(matrix)(rhs), expected, rtol=1e-12, atol=1e-13)


@SOLVERS
def test_an_indefinite_matrix_is_refused(linear_solver: LinearSolver) -> None:
    """The driver's inertia correction relies on LinAlgError for a matrix that is not positive definite."""
    matrix = random_spd(6, 3)
    diagonal = matrix.diagonal.copy()
    diagonal[4, 1, 1] = -50.0
    with pytest.raises(np.linalg.LinAlgError):
        linear_solver(BlockTridiagonal(diagonal, matrix.off_diagonal))


def test_the_default_is_the_compiled_path_when_numba_is_installed() -> None:
    assert default_linear_solver() is (block_cholesky if HAVE_NUMBA else banded_cholesky)
    assert default_linear_solver(compiled=False) is banded_cholesky


# disk-drape leaves its symmetric saddle (see README, Saddles) in a direction that rounding decides.
AGREEMENT = {"disk-drape": 1e-10}


@pytest.mark.parametrize("name", list(builtin_scenarios()))
def test_compiled_and_lapack_paths_agree_on_every_builtin(name: str) -> None:
    """Positions, tensions and contact forces to 1e-12 (relative to the chain's size and weight)."""
    problem = load_scenario(name)
    compiled = solve(problem, SolverOptions(linear_solver=block_cholesky))
    lapack = solve(problem, SolverOptions(linear_solver=banded_cholesky))
    assert compiled.converged and lapack.converged
    tolerance = AGREEMENT.get(name, 1e-12)
    size, weight = problem.total_length, problem.weight
    np.testing.assert_allclose(compiled.positions, lapack.positions, rtol=0, atol=tolerance * size)
    np.testing.assert_allclose(compiled.link_tension, lapack.link_tension, rtol=0, atol=tolerance * weight)
    np.testing.assert_allclose(compiled.contact_forces, lapack.contact_forces, rtol=0, atol=tolerance * weight)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")
@pytest.mark.parametrize("formulation", ["norm", "squared"])
def test_compiled_and_numpy_link_terms_agree_at_every_distance(formulation: str) -> None:
    """``solver.fused`` against the vectorized ``constraints``: constraint values, gradients, the
    stationarity residual and the Newton matrix, with links longer and shorter than the smooth
    stand-in's radius (``SMOOTH_RATIO`` of the length), right at it, and of zero length."""
    from funicular import Problem
    from funicular.constraints import SMOOTH_RATIO
    from funicular.solver.chain import evaluate, newton_matrix
    from funicular.solver.initial import presolve
    from funicular.solver.ipm import _kkt_error, _scale

    lengths = np.array([1.0, 0.1, 1.0, 10.0, 0.1, 1.0, 1.0])
    problem = Problem.build(
        nodes=8, link_lengths=lengths, masses=1.0, gravity=1.0, formulation=formulation, supports=[(0, (0.0, 0.0))]
    )
    start = presolve(problem)
    chains = [_scale(problem, start, compiled) for compiled in (True, False)]
    ratios = np.array([0.9, 0.3, SMOOTH_RATIO, 1e-9, 0.0, 0.5 * SMOOTH_RATIO, 1.2])  # the last overstretched
    angles = np.random.default_rng(7).uniform(-np.pi, np.pi, size=lengths.size)
    steps = (ratios * lengths / lengths.max())[:, None] * np.column_stack((np.cos(angles), np.sin(angles)))
    z = np.cumsum(steps, axis=0).ravel()
    mu = np.random.default_rng(8).uniform(0.1, 1.0, size=chains[0].n_constraints)
    sigma = np.random.default_rng(9).uniform(0.1, 10.0, size=mu.size)
    points = [evaluate(chain, z, mu) for chain in chains]
    for name in ("c", "q", "dual_residual"):
        np.testing.assert_allclose(getattr(points[0], name), getattr(points[1], name), rtol=1e-14, atol=1e-14)
    errors = [_kkt_error(chain, point, mu) for chain, point in zip(chains, points, strict=True)]
    assert errors[0] == pytest.approx(errors[1], rel=1e-14)
    # Each part of the KKT error, against its formula: the last link is overstretched, and its
    # overstretch is a length, d - l, in either formulation.
    chain, point = chains[0], points[0]
    parts = jit(fused.kkt_parts)(chain.squared, point.dual_residual, point.c, -mu, chain.lengths, chain.links)
    distance = float(np.hypot(*(point.positions[-1] - point.positions[-2])))
    expected = (
        np.max(np.abs(point.dual_residual)),
        *np.sum(point.dual_residual, axis=0),
        distance - chain.lengths[-1],
        np.max(mu),
        np.max(np.abs(mu * point.c)),
    )
    np.testing.assert_allclose(parts, expected, rtol=1e-13)
    point.c[3] = np.nan  # kkt_parts must not skip a NaN as max() would
    assert np.isnan(_kkt_error(chain, point, mu))
    matrices = [newton_matrix(chain, point, mu, sigma) for chain, point in zip(chains, points, strict=True)]
    np.testing.assert_allclose(matrices[0].diagonal, matrices[1].diagonal, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(matrices[0].off_diagonal, matrices[1].off_diagonal, rtol=1e-14, atol=1e-12)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")
@pytest.mark.parametrize("name", ["three-supports", "two-pegs"])
def test_compiled_and_numpy_newton_directions_agree(name: str) -> None:
    """``fused.newton_rhs`` / ``newton_update`` / ``step_to_boundary`` / ``quadratic_contacts``
    against the numpy formulas of ``ipm`` and ``chain``, away from any solution: a support in the
    middle of the chain (links with one fixed end, free nodes not contiguous) and two disks
    (contact rows of both)."""
    from funicular.solver.banded import dense_cholesky
    from funicular.solver.chain import evaluate, newton_matrix
    from funicular.solver.initial import presolve
    from funicular.solver.ipm import _newton_direction, _scale, _step_to_boundary

    problem = load_scenario(name)
    start = presolve(problem)
    chains = [_scale(problem, start, compiled) for compiled in (True, False)]
    rng = np.random.default_rng(3)
    z = chains[0].positions[chains[0].free].ravel() + 0.01 * rng.standard_normal(2 * chains[0].free.size)
    m = chains[0].n_constraints
    s, mu, r_c = rng.uniform(0.1, 1.0, m), rng.uniform(0.1, 1.0, m), rng.uniform(-1.0, 1.0, m)
    directions, points = [], []
    for chain in chains:
        point = evaluate(chain, z, mu)
        points.append(point)
        matrix = newton_matrix(chain, point, mu, mu / s)  # shifted: the obstacles' curvature is negative
        solve_system = dense_cholesky(matrix.shifted(10.0 * matrix.max_diagonal()))
        directions.append(_newton_direction(chain, point, solve_system, s, mu, r_c))
    for compiled_part, numpy_part in zip(*directions, strict=True):
        np.testing.assert_allclose(compiled_part, numpy_part, rtol=1e-12, atol=1e-12)
    # Contact rows: the disks' phi written out by fused.quadratic_contacts against evaluate_obstacles.
    for name in ("c", "obstacle_gradient", "obstacle_hessian", "dual_residual"):
        np.testing.assert_allclose(getattr(points[0], name), getattr(points[1], name), rtol=1e-13, atol=1e-14)
    _, ds, dmu = directions[1]
    for values, steps in ((s, ds), (mu, dmu), (s, np.abs(ds))):
        assert _step_to_boundary(values, steps, compiled=True) == _step_to_boundary(values, steps)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")
@pytest.mark.parametrize("name", builtin_scenarios())
def test_compiled_and_numpy_link_terms_give_the_same_equilibrium(name: str) -> None:
    problem = load_scenario(name)
    compiled = solve(problem, SolverOptions(compiled=True))
    numpy_path = solve(problem, SolverOptions(compiled=False))
    assert compiled.converged and numpy_path.converged
    size, weight = float(problem.link_lengths.sum()), problem.weight
    np.testing.assert_allclose(compiled.positions, numpy_path.positions, rtol=0, atol=1e-12 * size)
    np.testing.assert_allclose(compiled.link_tension, numpy_path.link_tension, rtol=0, atol=1e-12 * weight)
    np.testing.assert_allclose(compiled.contact_forces, numpy_path.contact_forces, rtol=0, atol=1e-12 * weight)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")
def test_each_compiled_kernel_has_its_own_code_object() -> None:
    """cProfile keys functions by code object: one wrapper shared by every kernel merged their callers
    (``funicular bench --profile`` put the polish's elimination under evaluation)."""
    polish, links = jit(fused.polish_solve), jit(fused.link_terms)
    assert polish.__code__ is not links.__code__
    assert (polish.__code__.co_name, links.__code__.co_name) == ("polish_solve", "link_terms")
