"""Type stubs of the compiled solver core (``rust/python``); ``tests/test_core_stub.py`` keeps them
true to the module (mypy's stubtest)."""

from collections.abc import Callable, Iterator
from typing import Self, final

import numpy as np
from numpy.typing import NDArray

_Floats = NDArray[np.float64]
_Ints = NDArray[np.int64]

__all__ = [
    "CURVATURE_PENALTY",
    "PROXIMAL",
    "SMOOTH_RATIO",
    "Chain",
    "CoreError",
    "Curvature",
    "Evaluated",
    "Hanging",
    "InternalError",
    "Net",
    "Network",
    "NodeFields",
    "NotFactored",
    "ObstacleNotFinite",
    "Obstacles",
    "Presolved",
    "Quadratics",
    "SecondOrderBound",
    "SegmentFields",
    "Settings",
    "Shape",
    "Solved",
    "Start",
    "SupportsTooFar",
    "TautNotVertical",
    "blocks_positive_definite",
    "evaluate_shapes",
    "gram_positive_definite",
    "hanging_span",
    "penalty_and_shift",
    "read_json",
    "zero_curvature",
]

SMOOTH_RATIO: float
PROXIMAL: float
CURVATURE_PENALTY: float

class CoreError(Exception): ...

class SupportsTooFar(CoreError):
    a: int
    b: int
    distance: float
    length: float

class TautNotVertical(CoreError):
    a: int
    b: int

class NotFactored(CoreError): ...

class ObstacleNotFinite(CoreError):
    obstacle: int
    index: int
    at_start: bool

class InternalError(CoreError):
    message: str

@final
class Settings:
    def __new__(
        cls,
        *,
        tol: float,
        max_iterations: int,
        escape_saddles: bool,
        exact_start: bool,
        escape_up_to: int | None = None,
    ) -> Self: ...
    @property
    def tol(self) -> float: ...
    @property
    def max_iterations(self) -> int: ...
    @property
    def escape_saddles(self) -> bool: ...
    @property
    def escape_up_to(self) -> int | None: ...
    @property
    def exact_start(self) -> bool: ...

@final
class Start:
    def __new__(
        cls,
        *,
        positions: _Floats,
        link_multipliers: _Floats | None,
        obstacle_multipliers: _Floats | None,
        settled: bool,
    ) -> Self: ...

@final
class Shape:
    def __new__(cls, *, kind: str, parameters: list[float]) -> Self: ...
    @property
    def kind(self) -> str: ...
    @property
    def parameters(self) -> list[float]: ...

@final
class NodeFields:
    def __new__(cls, *, phi: _Floats, gradient: _Floats, hessian: _Floats) -> Self: ...
    @property
    def phi(self) -> _Floats: ...
    @property
    def gradient(self) -> _Floats: ...
    @property
    def hessian(self) -> _Floats: ...

@final
class SegmentFields:
    def __new__(cls, *, psi: _Floats, t: _Floats, gradient: _Floats, hessian: _Floats) -> Self: ...
    @property
    def psi(self) -> _Floats: ...
    @property
    def t(self) -> _Floats: ...
    @property
    def gradient(self) -> _Floats: ...
    @property
    def hessian(self) -> _Floats: ...

@final
class Obstacles:
    def __new__(
        cls,
        *,
        count: int,
        shapes: list[Shape] | None,
        field: Callable[[_Floats], NodeFields] | None,
        links: Callable[[_Floats, _Ints], SegmentFields] | None,
    ) -> Self: ...

@final
class Quadratics:
    def __new__(cls, *, centres: _Floats, values: _Floats, gradients: _Floats, hessians: _Floats) -> Self: ...

@final
class Presolved:
    @property
    def positions(self) -> _Floats: ...
    @property
    def movable(self) -> _Ints: ...
    @property
    def fixed_tension(self) -> _Floats: ...
    @property
    def detached(self) -> _Ints: ...
    @property
    def attach(self) -> _Ints: ...
    @property
    def obstacle_gradients(self) -> _Floats | None: ...

@final
class Hanging:
    @property
    def positions(self) -> _Floats: ...
    @property
    def tensions(self) -> _Floats: ...

@final
class Curvature:
    @property
    def verdict(self) -> str: ...
    @property
    def value(self) -> float: ...
    @property
    def direction(self) -> _Floats | None: ...

@final
class Solved:
    @property
    def status(self) -> str: ...
    @property
    def positions(self) -> _Floats: ...
    @property
    def link_multipliers(self) -> _Floats: ...
    @property
    def obstacle_multipliers(self) -> _Floats: ...
    @property
    def iterations(self) -> int: ...
    @property
    def statistics(self) -> dict[str, float]: ...
    @property
    def curvature(self) -> Curvature | None: ...

@final
class Evaluated:
    @property
    def c(self) -> _Floats: ...
    @property
    def dual(self) -> _Floats: ...

@final
class SecondOrderBound:
    @property
    def rho(self) -> float: ...
    @property
    def shift(self) -> float: ...
    def __iter__(self) -> Iterator[float]: ...

@final
class Network:
    def __new__(
        cls,
        *,
        dim: int,
        squared: bool,
        positions: _Floats,
        free: _Ints,
        links: _Ints,
        lengths: _Floats,
        load: _Floats,
        origin: _Floats,
        quadratics: Quadratics | None,
    ) -> Self: ...
    def free_coordinates(self) -> _Floats: ...
    def evaluate(self, *, z: _Floats, mu: _Floats) -> Evaluated: ...
    def jacobian_times(self, *, z: _Floats, dz: _Floats) -> _Floats: ...
    def newton_matrix(self, *, z: _Floats, mu: _Floats, sigma: _Floats) -> _Floats: ...
    @property
    def statistics(self) -> dict[str, float]: ...
    @property
    def n_constraints(self) -> int: ...

@final
class Chain:
    def __new__(
        cls,
        *,
        dim: int,
        masses: _Floats,
        lengths: _Floats,
        gravity: float,
        supports: _Ints,
        support_positions: _Floats,
        squared: bool,
        obstacles: Obstacles,
        stiffness: _Floats | None,
    ) -> Self: ...
    def presolve(self, *, guess: _Floats | None, settled: bool) -> Presolved: ...
    def exact_start(self) -> Hanging | None: ...
    def solve(self, *, settings: Settings, start: Start | None, judge: bool) -> Solved: ...
    def network(self, *, guess: _Floats) -> Network: ...

@final
class Net:
    def __new__(
        cls,
        *,
        dim: int,
        masses: _Floats,
        links: _Ints,
        lengths: _Floats,
        gravity: float,
        supports: _Ints,
        support_positions: _Floats,
        squared: bool,
        obstacles: Obstacles,
        loads: _Floats | None,
        stiffness: _Floats | None,
    ) -> Self: ...
    def hanging_start(self) -> _Floats | None: ...
    def solve(self, *, settings: Settings, start: Start | None, judge: bool) -> Solved: ...

def hanging_span(
    *,
    interior_masses: _Floats,
    lengths: _Floats,
    gravity: float,
    left: _Floats,
    right: _Floats,
    field: Callable[[_Floats], NodeFields] | None,
    n_obstacles: int,
) -> Hanging | None: ...
def evaluate_shapes(*, shapes: list[Shape], points: _Floats, dim: int) -> NodeFields: ...
def penalty_and_shift(
    stiffest: float, stiffness: float, degree: int, n_obstacles: int, threshold: float, penalty: float = ...
) -> SecondOrderBound: ...
def zero_curvature(tol: float, weight: float, n_nodes: int, total_length: float) -> float: ...
def read_json(text: bytes) -> object | None: ...
def blocks_positive_definite(node_blocks: _Floats, pairs: _Ints, pair_blocks: _Floats, shift: float) -> bool: ...
def gram_positive_definite(nodes: _Ints, vectors: _Floats, shift: float, max_band: int) -> bool: ...
