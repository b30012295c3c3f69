"""Type stubs of the compiled solver core (``rust/python``)."""

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

SMOOTH_RATIO: float
PROXIMAL: float
CURVATURE_PENALTY: float

class Network:
    def __init__(
        self,
        dim: int,
        squared: bool,
        positions: FloatArray,
        free: NDArray[np.int64],
        links: NDArray[np.int64],
        lengths: FloatArray,
        load: FloatArray,
        origin: FloatArray,
        quadratics: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None = None,
        field: Callable[[FloatArray], tuple[FloatArray, ...]] | None = None,
        n_obstacles: int = 0,
        links_contact: bool = False,
    ) -> None: ...
    def iterate(
        self, z: FloatArray, guess: FloatArray | None, tol: float, max_iterations: int
    ) -> tuple[str, FloatArray, FloatArray, int, tuple[int, int, bool] | None]: ...
    def escape(
        self, z: FloatArray, mu: FloatArray, tol: float, total_length: float
    ) -> tuple[str, float, FloatArray]: ...
    def evaluate(self, z: FloatArray, mu: FloatArray) -> tuple[FloatArray, FloatArray]: ...
    def jacobian_times(self, z: FloatArray, dz: FloatArray) -> FloatArray: ...
    def newton_matrix(self, z: FloatArray, mu: FloatArray, sigma: FloatArray) -> FloatArray: ...
    @property
    def statistics(self) -> dict[str, float]: ...
    @property
    def n_constraints(self) -> int: ...

def penalty_and_shift(
    stiffest: float, stiffness: float, degree: int, n_obstacles: int, threshold: float, penalty: float = ...
) -> tuple[float, float]: ...
def zero_curvature(tol: float, weight: float, n_nodes: int, total_length: float) -> float: ...

# positions (N d), movable nodes, fixed links' tensions, detached ends, the nodes they rest on, and
# the obstacles' gradients at the movable nodes (n_obstacles n_movable d) or None
Presolved = tuple[FloatArray, NDArray[np.int64], FloatArray, NDArray[np.int64], NDArray[np.int64], FloatArray | None]
Shapes = Callable[[int, FloatArray], tuple[FloatArray, FloatArray]]

class Chain:
    def __init__(
        self,
        dim: int,
        masses: FloatArray,
        lengths: FloatArray,
        gravity: float,
        supports: NDArray[np.int64],
        support_positions: FloatArray,
        quadratics: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None = None,
        shapes: Shapes | None = None,
        n_obstacles: int = 0,
    ) -> None: ...
    def presolve(self, guess: FloatArray | None = None, settled: bool = False) -> Presolved: ...
    def repositioned(
        self,
        positions: FloatArray,
        movable: NDArray[np.int64],
        fixed_tension: FloatArray,
        detached: NDArray[np.int64],
        attach: NDArray[np.int64],
        guess: FloatArray,
        settled: bool = False,
    ) -> Presolved: ...
    def exact_start(self) -> tuple[FloatArray, FloatArray] | None: ...

def hanging_span(
    interior_masses: FloatArray,
    lengths: FloatArray,
    gravity: float,
    left: FloatArray,
    right: FloatArray,
    shapes: Shapes | None = None,
    n_obstacles: int = 0,
) -> tuple[FloatArray, FloatArray] | None: ...
