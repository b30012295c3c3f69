"""The solver against exact answers: the dangling chain, the seed's hand computations, the discrete catenary.

Every expected number comes from ``tests/oracles.py``, which is derived independently of the
package (numpy/scipy only). Each test's docstring says where its expected numbers come from.
Tolerances are absolute errors relative to a natural scale: the chain length for positions,
M g (dangling) or the largest tension (catenary) for forces.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import pytest

from funicular._solver import solve
from funicular.model import Formulation, Problem
from funicular.solution import Solution

try:
    import oracles
except ModuleNotFoundError:  # tests/ imported as a package
    from tests import oracles

NORM = Formulation.NORM
SQUARED = Formulation.SQUARED
FORMULATIONS = [pytest.param(NORM, id="norm"), pytest.param(SQUARED, id="squared")]

# --------------------------------------------------------------------------- dangling chain

DANGLING_NODES = (2, 3, 5, 20, 101)
DANGLING_MASS = 2.5  # M
DANGLING_LENGTH = 3.0  # L
DANGLING_G = 9.81
DANGLING_TOP = (0.0, 0.0)


def dangling_problem(n: int, formulation: Formulation, *, mass: float, length: float, g: float) -> Problem:
    return Problem.build(
        nodes=n,
        supports=[(0, DANGLING_TOP)],
        length=length,
        mass=mass,
        gravity=g,
        formulation=formulation,
        name=f"dangling-{n}",
    )


@cache
def solved_dangling(n: int, formulation: Formulation) -> Solution:
    problem = dangling_problem(n, formulation, mass=DANGLING_MASS, length=DANGLING_LENGTH, g=DANGLING_G)
    return solve(problem)


DANGLING_N = [pytest.param(n, id=f"N{n}") for n in DANGLING_NODES]


@pytest.mark.parametrize("n", DANGLING_N)
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_dangling_tensions(n: int, formulation: Formulation) -> None:
    """Tension of link k is M g (N-1-k)/N, the weight hanging below it (oracles.dangling_tensions).

    Checked to 1e-9 of M g, in both formulations (squared: T_k = 2 d_k mu_k).
    """
    solution = solved_dangling(n, formulation)
    expected = oracles.dangling_tensions(n, DANGLING_MASS, DANGLING_G)
    scale = DANGLING_MASS * DANGLING_G
    np.testing.assert_allclose(solution.link_tension, expected, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("n", DANGLING_N)
def test_dangling_squared_multipliers(n: int) -> None:
    """Raw squared-form multipliers mu_k = T_k / (2 l), l = L/(N-1) (oracles.dangling_squared_multipliers).

    Checked to 1e-9 of the largest, M g (N-1)^2 / (2 N L), which grows with N.
    """
    solution = solved_dangling(n, SQUARED)
    expected = oracles.dangling_squared_multipliers(n, DANGLING_MASS, DANGLING_LENGTH, DANGLING_G)
    np.testing.assert_allclose(solution.link_multipliers, expected, rtol=0, atol=1e-9 * expected.max())


@pytest.mark.parametrize("n", DANGLING_N)
def test_dangling_norm_multipliers_are_tensions(n: int) -> None:
    """Norm-form multipliers are the tensions themselves (docs/model.md), M g (N-1-k)/N; 1e-9 of M g."""
    solution = solved_dangling(n, NORM)
    expected = oracles.dangling_tensions(n, DANGLING_MASS, DANGLING_G)
    np.testing.assert_allclose(solution.link_multipliers, expected, rtol=0, atol=1e-9 * DANGLING_MASS * DANGLING_G)


@pytest.mark.parametrize("n", DANGLING_N)
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_dangling_support_reaction(n: int, formulation: Formulation) -> None:
    """A single support carries the whole weight: R = (0, M g) (docs/model.md); 1e-9 of M g."""
    solution = solved_dangling(n, formulation)
    scale = DANGLING_MASS * DANGLING_G
    assert solution.support_reactions.shape == (1, 2)
    np.testing.assert_allclose(solution.support_reactions[0], [0.0, scale], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(solution.support_multipliers[0], [0.0, -scale], rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("n", DANGLING_N)
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_dangling_positions(n: int, formulation: Formulation) -> None:
    """Node k hangs at (0, -k l), l = L/(N-1): straight down, every link taut (oracles.dangling_positions).

    Checked to 1e-9 of the chain length L.
    """
    solution = solved_dangling(n, formulation)
    expected = oracles.dangling_positions(n, DANGLING_LENGTH, DANGLING_TOP)
    np.testing.assert_allclose(solution.positions, expected, rtol=0, atol=1e-9 * DANGLING_LENGTH)


# --------------------------------------------------------------------------- the seed's hand computations

SEED_CASES = [pytest.param(n, g, id=f"N{n}-g{g:g}") for n in (2, 3) for g in (1.0, 9.81)]


@cache
def solved_seed(n: int, g: float) -> Solution:
    problem = dangling_problem(n, SQUARED, mass=oracles.SEED_TOTAL_MASS, length=oracles.SEED_TOTAL_LENGTH, g=g)
    return solve(problem)


@pytest.mark.parametrize(("n", "g"), SEED_CASES)
def test_seed_squared_multipliers(n: int, g: float) -> None:
    """Seed 3.1 (iii), CHAIN-V1, M = 1, L = 1.5: N=2 gives mu_1 = g/(4 l) = g/6 (l = 1.5);
    N=3 gives mu_2 = g/(6 l) = 2g/9 and mu_1 = 2 mu_2 (l = 0.75). Literal values in
    oracles.SEED_SQUARED_MULTIPLIERS_PER_G; checked to 1e-9 of the largest.
    """
    solution = solved_seed(n, g)
    expected = oracles.seed_squared_multipliers(n, g)
    np.testing.assert_allclose(solution.link_multipliers, expected, rtol=0, atol=1e-9 * expected.max())


@pytest.mark.parametrize(("n", "g"), SEED_CASES)
def test_seed_support_reaction(n: int, g: float) -> None:
    """Seed 3.1 (iii): lambda_{1,2} = -2 mu_1 l - g/N = -g, so the reaction -lambda is (0, g) (M = 1); 1e-9 of g."""
    solution = solved_seed(n, g)
    expected = oracles.seed_support_reaction(g)
    np.testing.assert_allclose(solution.support_reactions[0], expected, rtol=0, atol=1e-9 * g)
    np.testing.assert_allclose(solution.support_multipliers[0], -expected, rtol=0, atol=1e-9 * g)


@pytest.mark.parametrize(("n", "g"), SEED_CASES)
def test_seed_converged(n: int, g: float) -> None:
    """The seed's cases converge with KKT residuals <= 1e-9 (physical units)."""
    solution = solved_seed(n, g)
    assert solution.converged, solution.status
    assert solution.kkt.max() <= 1e-9, solution.kkt


# --------------------------------------------------------------------------- discrete catenary

CATENARY_G = 9.81


@dataclass(frozen=True)
class CatenaryCase:
    """A chain between supports at node 0 (``left``) and node N-1 (``right``)."""

    name: str
    masses: tuple[float, ...]
    link_lengths: tuple[float, ...]
    left: tuple[float, float]
    right: tuple[float, float]

    @classmethod
    def equal(
        cls, name: str, n: int, length: float, left: tuple[float, float], right: tuple[float, float], mass: float = 1.0
    ) -> CatenaryCase:
        return cls(name, (mass / n,) * n, (length / (n - 1),) * (n - 1), left, right)

    @property
    def n(self) -> int:
        return len(self.masses)

    @property
    def length(self) -> float:
        return float(sum(self.link_lengths))

    def problem(self, formulation: Formulation) -> Problem:
        return Problem.build(
            nodes=self.n,
            supports=[(0, self.left), (self.n - 1, self.right)],
            link_lengths=np.array(self.link_lengths),
            masses=np.array(self.masses),
            gravity=CATENARY_G,
            formulation=formulation,
            name=self.name,
        )


def _random_masses_case() -> CatenaryCase:
    rng = np.random.default_rng(0)
    n = 31
    masses = rng.uniform(0.2, 2.0, n)
    masses /= masses.sum()  # total mass 1, like the equal-mass cases (KKT residuals are in physical units)
    return CatenaryCase("random-masses-seed0", tuple(masses), (1.5 / (n - 1),) * (n - 1), (0.0, 0.0), (1.0, 0.3))


def _random_links_case() -> CatenaryCase:
    rng = np.random.default_rng(1)
    n = 25
    masses = rng.uniform(0.2, 2.0, n)
    masses /= masses.sum()
    lengths = rng.uniform(0.5, 1.5, n - 1)
    lengths *= 1.8 / lengths.sum()
    return CatenaryCase("random-masses-and-links-seed1", tuple(masses), tuple(lengths), (-0.5, 0.2), (0.7, -0.4))


CATENARY_CASES = {
    case.name: case
    for case in (
        CatenaryCase.equal("level-L1.5-N51", 51, 1.5, (0.0, 0.0), (1.0, 0.0)),
        CatenaryCase.equal("uneven-L1.6-N31", 31, 1.6, (0.0, 0.0), (1.0, 0.5)),
        CatenaryCase.equal("nearly-taut-L1.02-N21", 21, 1.02, (0.0, 0.0), (1.0, 0.0)),
        CatenaryCase.equal("very-slack-L5-N41", 41, 5.0, (0.0, 0.0), (1.0, 0.0)),
        # Above ipm.COARSE_ABOVE_FREE: solved coarse to fine, the fine level by the polish alone.
        CatenaryCase.equal("uneven-L1.6-N6001", 6001, 1.6, (0.0, 0.0), (1.0, 0.5)),
        _random_masses_case(),
        _random_links_case(),
    )
}
CASES = [pytest.param(name, id=name) for name in CATENARY_CASES]


@cache
def catenary_oracle(name: str) -> oracles.CatenaryResult:
    case = CATENARY_CASES[name]
    return oracles.discrete_catenary(case.masses, case.link_lengths, CATENARY_G, case.left, case.right)


@cache
def solved_catenary(name: str, formulation: Formulation) -> Solution:
    return solve(CATENARY_CASES[name].problem(formulation))


# ----- the oracle checks itself: closure, link lengths, force balance (a KKT point of a convex problem)


@pytest.mark.parametrize("name", CASES)
def test_catenary_oracle_is_an_equilibrium(name: str) -> None:
    """The oracle's own answer, recomputed from its positions alone: every link exactly l_k long,
    the chain ends at the right support, every tension positive, gravity + link forces balance at
    every free node and the reactions balance the support nodes (1e-12 of the length / max tension),
    and the vertical reactions add up to the weight (1e-12 relative). Taut links with positive
    tensions in force balance are a KKT point of the convex problem, hence its minimum.
    """
    case = CATENARY_CASES[name]
    result = catenary_oracle(name)
    p = result.positions
    lengths = np.array(case.link_lengths)
    masses = np.array(case.masses)
    assert p.shape == (case.n, 2)
    np.testing.assert_array_equal(p[0], case.left)
    np.testing.assert_allclose(p[-1], case.right, rtol=0, atol=1e-12 * case.length)
    delta = np.diff(p, axis=0)
    d = np.hypot(delta[:, 0], delta[:, 1])
    np.testing.assert_allclose(d, lengths, rtol=0, atol=1e-12 * case.length)
    assert result.H > 0
    assert np.all(result.tension > 0)
    np.testing.assert_allclose(result.tension, np.hypot(result.H, result.V), rtol=1e-15)

    # force of link k on node k: T_k times the unit vector from node k to node k+1
    pull = result.tension[:, None] * delta / d[:, None]
    net = np.zeros_like(p)
    net[:-1] += pull
    net[1:] -= pull
    net[:, 1] -= CATENARY_G * masses
    scale = result.tension.max()
    np.testing.assert_allclose(net[1:-1], 0.0, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(net[0] + result.reaction_left, 0.0, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(net[-1] + result.reaction_right, 0.0, rtol=0, atol=1e-12 * scale)
    weight = CATENARY_G * masses.sum()
    total = result.reaction_left[1] + result.reaction_right[1]
    assert abs(total - weight) <= 1e-12 * weight
    assert abs(result.reaction_left[0] + result.reaction_right[0]) <= 1e-12 * scale


def test_catenary_oracle_symmetric_case() -> None:
    """Level supports and equal masses: the oracle's shape is mirror-symmetric and each support
    carries half the weight, V_0 = -(weight of the free nodes)/2 (symmetry, by hand)."""
    result = catenary_oracle("level-L1.5-N51")
    case = CATENARY_CASES["level-L1.5-N51"]
    p = result.positions
    np.testing.assert_allclose(p[:, 0] + p[::-1, 0], 1.0, rtol=0, atol=1e-13)
    np.testing.assert_allclose(p[:, 1], p[::-1, 1], rtol=0, atol=1e-13)
    weight = CATENARY_G * sum(case.masses)
    np.testing.assert_allclose(result.reaction_left[1], weight / 2, rtol=1e-13)
    np.testing.assert_allclose(result.V[0], -CATENARY_G * sum(case.masses[1:-1]) / 2, rtol=1e-13)


# ----- the solver against the oracle


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("name", CASES)
def test_catenary_positions(name: str, formulation: Formulation) -> None:
    """Positions equal oracles.discrete_catenary to 1e-8 of the chain length."""
    solution = solved_catenary(name, formulation)
    expected = catenary_oracle(name).positions
    np.testing.assert_allclose(solution.positions, expected, rtol=0, atol=1e-8 * CATENARY_CASES[name].length)


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("name", CASES)
def test_catenary_tensions(name: str, formulation: Formulation) -> None:
    """Link tensions equal oracles.discrete_catenary's hypot(H, V_k) to 1e-8 of the largest tension."""
    solution = solved_catenary(name, formulation)
    expected = catenary_oracle(name).tension
    np.testing.assert_allclose(solution.link_tension, expected, rtol=0, atol=1e-8 * expected.max())


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("name", CASES)
def test_catenary_support_reactions(name: str, formulation: Formulation) -> None:
    """Both reactions equal oracles.discrete_catenary's (from balance at nodes 0 and N-1: left
    (-H, g m_0 - V_0), right (H, g m_{N-1} + V_{N-2})) to 1e-8 of the largest tension."""
    solution = solved_catenary(name, formulation)
    oracle = catenary_oracle(name)
    atol = 1e-8 * oracle.tension.max()
    assert solution.problem.support_nodes.tolist() == [0, CATENARY_CASES[name].n - 1]
    np.testing.assert_allclose(solution.support_reactions[0], oracle.reaction_left, rtol=0, atol=atol)
    np.testing.assert_allclose(solution.support_reactions[1], oracle.reaction_right, rtol=0, atol=atol)
    np.testing.assert_allclose(solution.support_multipliers, -solution.support_reactions, rtol=0, atol=0)


@pytest.mark.parametrize("name", CASES)
def test_formulations_agree(name: str) -> None:
    """Norm and squared forms give the same chain (1e-8 of the length) and tensions (1e-8 of the
    largest oracle tension); the squared multipliers times 2 d_k are the norm tensions (docs/model.md)."""
    norm = solved_catenary(name, NORM)
    squared = solved_catenary(name, SQUARED)
    length = CATENARY_CASES[name].length
    force = catenary_oracle(name).tension.max()
    np.testing.assert_allclose(squared.positions, norm.positions, rtol=0, atol=1e-8 * length)
    np.testing.assert_allclose(squared.link_tension, norm.link_tension, rtol=0, atol=1e-8 * force)
    delta = np.diff(squared.positions, axis=0)
    d = np.hypot(delta[:, 0], delta[:, 1])
    np.testing.assert_allclose(2 * d * squared.link_multipliers, norm.link_multipliers, rtol=0, atol=1e-8 * force)


# --------------------------------------------------------------------------- every case


def _every_solution() -> list:
    params = []
    for n in DANGLING_NODES:
        for formulation in (NORM, SQUARED):
            params.append(pytest.param(("dangling", n, formulation), id=f"dangling-N{n}-{formulation.value}"))
    for n in (2, 3):
        for g in (1.0, 9.81):
            params.append(pytest.param(("seed", n, g), id=f"seed-N{n}-g{g:g}"))
    for name in CATENARY_CASES:
        for formulation in (NORM, SQUARED):
            params.append(pytest.param(("catenary", name, formulation), id=f"{name}-{formulation.value}"))
    return params


def _solution(key: tuple) -> Solution:
    kind, *args = key
    return {"dangling": solved_dangling, "seed": solved_seed, "catenary": solved_catenary}[kind](*args)


@pytest.mark.parametrize("key", _every_solution())
def test_converged_with_small_kkt_residuals(key: tuple) -> None:
    """Every exact case converges and its KKT residuals (physical units) are <= 1e-9."""
    solution = _solution(key)
    assert solution.converged, solution.status
    assert solution.kkt.max() <= 1e-9, solution.kkt


@pytest.mark.parametrize("key", _every_solution())
def test_vertical_reactions_carry_the_weight(key: tuple) -> None:
    """The supports carry the whole weight: sum of vertical reactions = g * sum(m), 1e-10 relative
    (global force balance; the horizontal reactions cancel to the same tolerance of the weight)."""
    solution = _solution(key)
    weight = solution.problem.weight
    reactions = solution.support_reactions
    assert abs(reactions[:, 1].sum() - weight) <= 1e-10 * weight
    assert abs(reactions[:, 0].sum()) <= 1e-10 * max(weight, float(np.max(np.abs(reactions))))
