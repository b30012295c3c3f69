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
