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
    ) -> None: ...
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
# status, positions (N d), link multipliers, obstacle multipliers, Newton steps, statistics, and the
# second-order test at the result if asked for: (verdict, curvature, moves (N d))
Solved = tuple[str, FloatArray, FloatArray, FloatArray, int, dict[str, float], tuple[str, float, FloatArray] | None]

class Chain:
    def __init__(
        self,
        dim: int,
        masses: FloatArray,
        lengths: FloatArray,
        gravity: float,
        supports: NDArray[np.int64],
        support_positions: FloatArray,
        squared: bool = False,
        shapes: list[tuple[str, list[float]]] | None = None,
        field: Callable[[FloatArray], tuple[FloatArray, ...]] | None = None,
        links: Callable[[FloatArray, NDArray[np.int64]], tuple[FloatArray, ...]] | None = None,
        n_obstacles: int = 0,
    ) -> None: ...
    def presolve(self, guess: FloatArray | None = None, settled: bool = False) -> Presolved: ...
    def exact_start(self) -> tuple[FloatArray, FloatArray] | None: ...
    def solve(
        self,
        tol: float,
        max_iterations: int,
        escape_saddles: bool = True,
        exact_start: bool = True,
        guess: FloatArray | None = None,
        link_multipliers: FloatArray | None = None,
        obstacle_multipliers: FloatArray | None = None,
        settled: bool = False,
        judge: bool = False,
    ) -> Solved: ...
    def network(self, guess: FloatArray) -> tuple[Network, FloatArray]: ...

class Net:
    def __init__(
        self,
        dim: int,
        masses: FloatArray,
        links: NDArray[np.int64],
        lengths: FloatArray,
        gravity: float,
        supports: NDArray[np.int64],
        support_positions: FloatArray,
        squared: bool = False,
        shapes: list[tuple[str, list[float]]] | None = None,
        field: Callable[[FloatArray], tuple[FloatArray, ...]] | None = None,
        n_obstacles: int = 0,
        loads: FloatArray | None = None,
        stiffness: FloatArray | None = None,
    ) -> None: ...
    def hanging_start(self) -> FloatArray | None: ...
    def solve(
        self,
        tol: float,
        max_iterations: int,
        escape_saddles: bool = True,
        guess: FloatArray | None = None,
        judge: bool = False,
    ) -> Solved: ...

def hanging_span(
    interior_masses: FloatArray,
    lengths: FloatArray,
    gravity: float,
    left: FloatArray,
    right: FloatArray,
    field: Callable[[FloatArray], tuple[FloatArray, ...]] | None = None,
    n_obstacles: int = 0,
) -> tuple[FloatArray, FloatArray] | None: ...
def evaluate_shapes(
    shapes: list[tuple[str, list[float]]], points: FloatArray, dim: int = 2
) -> tuple[FloatArray, FloatArray, FloatArray]: ...
def read_json(text: bytes) -> object | None: ...
def blocks_positive_definite(
    node_blocks: FloatArray, pairs: NDArray[np.int64], pair_blocks: FloatArray, shift: float
) -> bool: ...
def gram_positive_definite(nodes: NDArray[np.int64], vectors: FloatArray, shift: float, max_band: int) -> bool: ...
