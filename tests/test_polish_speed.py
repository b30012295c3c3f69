"""The compiled polish step (``fused.polish_solve``, which assembles the active-set KKT system as it
eliminates) against the banded LU, and its hand-over to the banded LU where the node-by-node
elimination must not be trusted."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from funicular import solve
from funicular.benchmark import family
from funicular.model import FloatArray, Problem
from funicular.scenario import load_scenario
from funicular.solver.chain import ScaledChain, evaluate
from funicular.solver.initial import presolve
from funicular.solver.ipm import _link_multiplier_unit, _scale
from funicular.solver.polish import _compiled_step, polish_step


def _near_solution(problem: Problem) -> tuple[ScaledChain, FloatArray, FloatArray]:
    """The compiled scaled chain at its solution, the free positions perturbed by 1e-6, and the
    solution's scaled multipliers."""
    solution = solve(problem)
    chain = _scale(problem, presolve(problem, solution.positions), True)
    links = solution.link_multipliers[chain.links] / _link_multiplier_unit(problem, chain.length_unit)
    contacts = solution.obstacle_multipliers[:, chain.free] * (chain.obstacle_scale[:, None] / problem.weight)
    z = chain.positions[chain.free].ravel() + 1e-6 * np.random.default_rng(0).normal(size=2 * chain.free.size)
    return chain, z, np.concatenate((links, contacts.ravel()))


def _assert_matches_banded(chain: ScaledChain, z: FloatArray, mu: FloatArray, active: np.ndarray) -> None:
    """The compiled step is taken (no hand-over) and agrees with the banded LU to rounding."""
    point = evaluate(chain, z, mu)
    compiled = _compiled_step(chain, point, mu, active)
    banded = polish_step(replace(chain, compiled=False), point, mu, active)
    assert compiled is not None and banded is not None
    for ours, theirs in zip(compiled, banded, strict=True):
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12 * max(1.0, float(np.max(np.abs(theirs)))))
    assert np.all(compiled[1][~active] == 0.0)


def _assert_steps_agree(
    chain: ScaledChain, z: FloatArray, mu: FloatArray, active: np.ndarray, atol_positions: float
) -> None:
    """polish_step on the compiled chain (whatever route it takes) and on the same chain without
    compiled loops (the banded LU) give the same step: positions to ``atol_positions``, multipliers
    to 1e-12."""
    lapack_chain = replace(chain, compiled=False)
    compiled = polish_step(chain, evaluate(chain, z, mu), mu, active)
    banded = polish_step(lapack_chain, evaluate(lapack_chain, z, mu), mu, active)
    assert compiled is not None and banded is not None
    np.testing.assert_allclose(compiled[0], banded[0], rtol=0, atol=atol_positions)
    np.testing.assert_allclose(compiled[1], banded[1], rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["three-supports", "squared-dangling", "two-pegs", "box-edge", "ground"])
def test_compiled_polish_step_matches_the_banded_lu_on_scenarios(name: str) -> None:
    """A fixed node between free ones (three-supports), the squared formulation, two obstacles, a
    corner: one step from a perturbed equilibrium agrees with the banded LU."""
    chain, z, mu = _near_solution(load_scenario(name))
    _assert_matches_banded(chain, z, mu, mu > 1e-12)


@pytest.mark.parametrize("kind", ["free", "disk"])
def test_compiled_polish_step_matches_the_banded_lu_on_a_long_chain(kind: str) -> None:
    """One step from a perturbed equilibrium of the benchmark chain, with the links and (disk) some
    200 contacts active: polish_step with and without the compiled elimination agree to rounding."""
    chain, z, mu = _near_solution(family(1000, kind))
    active = mu > 1e-12
    assert kind == "free" or active[chain.links.size :].sum() > 100
    _assert_steps_agree(chain, z, mu, active, atol_positions=1e-11)


def test_compiled_polish_step_with_both_contacts_of_a_node_active() -> None:
    """A node touching two obstacles has a 5x5 block, eliminated outside the registers' fast path;
    nodes with one contact have 4x4 blocks."""
    chain, z, mu = _near_solution(load_scenario("two-pegs"))
    n_links, n_free = chain.links.size, chain.free.size
    active = np.zeros(mu.size, dtype=bool)
    active[:n_links] = True
    both = np.arange(3, n_free - 3, 7)  # both contacts of every 7th node ...
    one = both[::2] + 2  # ... and the first contact of some others
    for obstacle, nodes in ((0, both), (1, both), (0, one)):
        active[n_links + obstacle * n_free + nodes] = True
    mu = np.where(active, np.maximum(mu, 1e-3), 0.0)
    _assert_matches_banded(chain, z, mu, active)


def test_compiled_polish_hands_over_after_a_slack_link_before_a_taut_one() -> None:
    """The unstable case of ``polish_solve``'s docstring: a Schur complement update above
    UPDATE_LIMIT makes the compiled step give up (eliminating node by node would cancel numbers
    1e10 apart: linear residuals of 1e-6), and polish_step still solves (banded LU), agreeing with
    the banded LU to rounding."""
    chain, _, _ = _near_solution(load_scenario("ground").with_nodes(40))
    mu = np.concatenate((np.full(chain.links.size, 0.5), np.zeros(len(chain.obstacles) * chain.free.size)))
    active = np.zeros(mu.size, dtype=bool)
    active[: chain.links.size] = True
    active[10] = False  # one slack link between taut ones
    mu[~active] = 0.0
    z = chain.positions[chain.free].ravel()
    point = evaluate(chain, z, mu)
    assert _compiled_step(chain, point, mu, active) is None
    assert polish_step(chain, point, mu, active) is not None
    _assert_steps_agree(chain, z, mu, active, atol_positions=1e-12)


def test_compiled_polish_hands_over_on_a_zero_pivot() -> None:
    """An active contact whose gradient vanishes makes its node's block singular."""
    chain, z, mu = _near_solution(load_scenario("disk-drape"))
    active = mu > 1e-12
    touching = np.flatnonzero(active[chain.links.size :])
    assert touching.size > 0
    point = evaluate(chain, z, mu)
    point.obstacle_gradient[0, touching[touching.size // 2]] = 0.0
    assert _compiled_step(chain, point, mu, active) is None


def test_compiled_polish_refuses_free_nodes_out_of_order() -> None:
    """``polish_solve`` walks ``free`` and ``links`` alongside the nodes, so they must ascend."""
    chain, z, mu = _near_solution(load_scenario("disk-drape"))
    active = mu > 1e-12
    point = evaluate(chain, z, mu)
    assert _compiled_step(chain, point, mu, active) is not None
    shuffled = replace(chain, free=chain.free[::-1].copy())
    assert _compiled_step(shuffled, point, mu, active) is None
