"""The solver core's networks beyond chains, through its test hook (``_core.Network``): a net's
Newton matrix is the derivative of the residual of stationarity it evaluates (finite differences),
in 2-D and in 3-D. (The core's own tests solve nets and check force balance, ``rust/core/tests``.)"""

from __future__ import annotations

import numpy as np
import pytest

from funicular import _core


def _net(dim: int) -> tuple[_core.Network, np.ndarray]:
    """A square of four nodes with both diagonals, node 0 fixed at the origin, the others free; in
    3-D lifted out of the plane."""
    square = np.array([[0.0, 0.0], [1.0, 0.1], [1.1, 1.0], [0.1, 0.9]])
    positions = square if dim == 2 else np.column_stack((square, [0.0, 0.2, -0.1, 0.3]))
    links = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [0, 2], [1, 3]], dtype=np.int64)
    lengths = 1.3 * np.linalg.norm(positions[links[:, 0]] - positions[links[:, 1]], axis=1)
    free = np.array([1, 2, 3], dtype=np.int64)
    network = _core.Network(
        dim=dim,
        squared=False,
        positions=positions.ravel(),
        free=free,
        links=links,
        lengths=lengths,
        load=np.full(4, 0.25),
        origin=np.zeros(dim),
        quadratics=None,
    )
    return network, positions[free].ravel()


@pytest.mark.parametrize("dim", [2, 3])
def test_a_nets_newton_matrix_is_the_derivative_of_its_stationarity_residual(dim: int) -> None:
    network, z = _net(dim)
    mu = np.random.default_rng(dim).uniform(0.5, 1.5, network.n_constraints)
    dense = network.newton_matrix(z=z, mu=mu, sigma=np.zeros_like(mu)).reshape(z.size, z.size)
    np.testing.assert_allclose(dense, dense.T, atol=1e-14)
    h = 1e-6
    for i in range(z.size):
        step = np.zeros_like(z)
        step[i] = h
        plus, minus = network.evaluate(z=z + step, mu=mu).dual, network.evaluate(z=z - step, mu=mu).dual
        np.testing.assert_allclose(dense[:, i], (plus - minus) / (2 * h), atol=1e-6)
