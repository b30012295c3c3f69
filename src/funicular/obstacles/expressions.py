"""Obstacles written as text or code: :class:`Graph` (terrain below ``y = f(x)``),
:class:`Surface` (terrain below ``z = f(x, y)``) and :class:`Expression` (any ``phi``), parsed and
differentiated by sympy (the ``expr`` extra), and :class:`CallableObstacle`, a Python function.

The text is checked before sympy sees it (only numbers, the variables, known functions and
arithmetic; no huge constant exponent), and every evaluation is checked for its shapes.
"""

from __future__ import annotations

import ast
import io
import tokenize
from collections.abc import Callable
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from funicular._extras import install_command
from funicular._types import FloatArray
from funicular.errors import FunicularError, ScenarioError, shown
from funicular.obstacles.base import Bounds, Evaluation, _checked, _labeller, _string

# Names an expression may use besides its variables. Anything else is rejected before sympy sees
# the text, because parse_expr evaluates it as Python.
_FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "exp", "log", "sqrt")
_CONSTANTS = ("pi", "E")
_OPERATORS = frozenset({"+", "-", "*", "/", "**", "^", "(", ")", ","})
MAX_EXPONENT = 1000.0  # larger constant exponents only overflow, and sympy would compute them exactly
_TOKENS = frozenset({tokenize.NAME, tokenize.NUMBER, tokenize.OP, tokenize.NEWLINE, tokenize.NL, tokenize.ENDMARKER})


def _sympy() -> ModuleType:
    try:
        import sympy  # type: ignore[import-untyped]  # (an optional extra, and slow to import: only for expressions)
    except ImportError:
        raise FunicularError(f"expression obstacles need sympy: {install_command('expr')}") from None
    return sympy  # type: ignore[no-any-return]


def _check_tokens(text: str, names: frozenset[str], variables: tuple[str, ...], label: str) -> None:
    """Only numbers, the variables, known functions and arithmetic: nothing else reaches eval."""
    quoted = f"{label} = {shown(text)}"
    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (tokenize.TokenError, SyntaxError) as error:
        raise ScenarioError(f"{quoted} is not a valid expression ({error.args[0]}).", key=label) from None
    for token in tokens:
        if token.type == tokenize.NAME and token.string not in names:
            raise ScenarioError(
                f"{quoted} uses the unknown name {token.string!r}; use the variables {', '.join(variables)}, "
                f"the functions {', '.join((*_FUNCTIONS, 'Abs'))} and the constants {', '.join(_CONSTANTS)}.",
                key=label,
            )
        if token.type not in _TOKENS or (token.type == tokenize.OP and token.string not in _OPERATORS):
            raise ScenarioError(
                f"{quoted} uses {token.string!r}; use numbers, {', '.join(variables)}, functions and + - * / ** ( ).",
                key=label,
            )


def _constant(node: ast.expr) -> float | None:
    """The value of a subexpression made of numbers and arithmetic only, in floats (an overflow
    gives inf); None if it involves a variable or a function."""
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        value = _constant(node.operand)
        return None if value is None else (-value if isinstance(node.op, ast.USub) else value)
    if isinstance(node, ast.BinOp):
        left, right = _constant(node.left), _constant(node.right)
        if left is None or right is None:
            return None
        with np.errstate(all="ignore"):
            operations = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide}
            if isinstance(node.op, ast.Pow):
                return float(np.power(np.float64(left), right)) if left >= 0 or right == int(right) else float("nan")
            operation = operations.get(type(node.op))
            return None if operation is None else float(operation(np.float64(left), right))
    return None


def _check_exponents(text: str, label: str) -> None:
    """Refuse exponents like ``9**9**9`` before sympy computes them exactly (370 million digits)."""
    try:
        tree = ast.parse(text.replace("^", "**"), mode="eval")
        exponents = [
            _constant(node.right)
            for node in ast.walk(tree)
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow)
        ]
    except (SyntaxError, RecursionError, MemoryError):
        return  # sympy's parser gives the error message
    for exponent in exponents:
        if exponent is not None and not abs(exponent) <= MAX_EXPONENT:
            raise ScenarioError(
                f"{label} = {shown(text)} has the exponent {exponent:.3g}; exponents must be at most "
                f"{MAX_EXPONENT:g} in size.",
                key=label,
            )


def _parse_expression(text: object, variables: tuple[str, ...], label: str) -> tuple[Any, list[Any], Any]:
    """``(sympy, symbols, expression)`` for a real expression in the given variables."""
    text = _string(text, label).strip()
    sympy = _sympy()
    parser = sympy.parsing.sympy_parser
    symbols = {name: sympy.Symbol(name, real=True) for name in variables}
    namespace = {name: getattr(sympy, name) for name in (*_FUNCTIONS, *_CONSTANTS, "Abs")}
    namespace |= {"abs": sympy.Abs, **symbols}
    _check_tokens(text, frozenset(namespace), variables, label)
    _check_exponents(text, label)
    quoted = f"{label} = {shown(text)}"
    try:
        transformations = (*parser.standard_transformations, parser.convert_xor)
        expression = parser.parse_expr(text, local_dict=namespace, transformations=transformations, evaluate=True)
    except Exception as error:  # eval of a bad expression can raise almost any exception type
        raise ScenarioError(f"{quoted} is not a valid expression ({type(error).__name__}).", key=label) from None
    # Only evaluation can bring in I or an infinity (the names are checked): sqrt(-2), log(0).
    strange = (sympy.I, sympy.zoo, sympy.nan, sympy.oo, -sympy.oo)
    if not isinstance(expression, sympy.Expr) or expression.has(*strange) or expression.is_real is False:
        raise ScenarioError(f"{quoted} is not a real-valued expression in {', '.join(variables)}.", key=label)
    return sympy, list(symbols.values()), expression


def _derivative(sympy: Any, expression: Any, *symbols: Any) -> Any:
    # A kink (Abs) differentiates to a DiracDelta: zero away from the kink, all a Hessian can use.
    return sympy.diff(expression, *symbols).replace(sympy.DiracDelta, lambda *_: sympy.S.Zero)


def _arrays(values: list[Any], k: int) -> list[FloatArray]:
    """lambdify returns plain numbers for constant entries: broadcast every entry to (k,)."""
    return [np.broadcast_to(np.asarray(value, dtype=np.float64), (k,)).copy() for value in values]


@dataclass(frozen=True)
class Graph:
    """Terrain: the region below ``y = f(x)``, with ``phi = f(x) - y``.

    ``f`` is text in x (e.g. ``"-0.6 + 0.25*exp(-40*(x-0.5)**2)"``), differentiated by sympy.
    Whether the region is convex is not checked, so ``convex`` is False.
    """

    f: str
    name: str = "graph"
    _function: Callable[..., list[Any]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        label = _labeller(self.name)("f")
        sympy, (x,), f = _parse_expression(self.f, ("x",), label)
        derivatives = [f, _derivative(sympy, f, x), _derivative(sympy, f, x, 2)]
        object.__setattr__(self, "_function", sympy.lambdify(x, derivatives, modules="numpy"))

    def __reduce__(self) -> tuple[Any, ...]:
        # Lambdified functions do not pickle (process pools): rebuild from the text instead.
        return (type(self), (self.f, self.name))

    @property
    def convex(self) -> bool:
        return False

    def evaluate(self, points: FloatArray) -> Evaluation:
        points = np.asarray(points, dtype=np.float64)
        k = points.shape[0]
        with np.errstate(all="ignore"):  # a NaN (say log of a negative) is the solver's to report
            f, slope, curvature = _arrays(self._function(points[:, 0]), k)
        gradient = np.column_stack([slope, -np.ones(k)])
        hessian = np.zeros((k, 2, 2))
        hessian[:, 0, 0] = curvature
        return _checked(self.name, points, f - points[:, 1], gradient, hessian)

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        xmin, xmax, ymin, ymax = bounds
        x = np.linspace(xmin, xmax, samples)
        with np.errstate(all="ignore"):
            (f,) = _arrays(self._function(x)[:1], samples)
        # Where f is undefined draw no ground; the clip keeps the curve inside the plot.
        y = np.clip(np.nan_to_num(f, nan=ymin), ymin, ymax)
        return np.vstack([np.column_stack([x, y]), [[xmax, ymin], [xmin, ymin], [x[0], y[0]]]])


@dataclass(frozen=True)
class Surface:
    """Terrain in space: the region below ``z = f(x, y)``, with ``phi = f(x, y) - z``.

    ``height`` is text in x and y (e.g. ``"0.1*sin(3*x) - 0.5"``), differentiated by sympy, as
    :class:`Graph` is in the plane. Whether the region is convex is not checked, so ``convex`` is
    False.
    """

    height: str
    name: str = "surface"
    _function: Callable[..., list[Any]] = field(init=False, repr=False, compare=False)

    dimension = 3  # (a class attribute, not a field)

    def __post_init__(self) -> None:
        label = _labeller(self.name)("height")
        sympy, (x, y), f = _parse_expression(self.height, ("x", "y"), label)
        terms = [f, _derivative(sympy, f, x), _derivative(sympy, f, y)]
        terms += [_derivative(sympy, f, x, x), _derivative(sympy, f, x, y), _derivative(sympy, f, y, y)]
        object.__setattr__(self, "_function", sympy.lambdify((x, y), terms, modules="numpy"))

    def __reduce__(self) -> tuple[Any, ...]:
        # Lambdified functions do not pickle (process pools): rebuild from the text instead.
        return (type(self), (self.height, self.name))

    @property
    def convex(self) -> bool:
        return False

    def heights(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """``f(x, y)`` at points given by their coordinates (any matching shapes), for plots."""
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        with np.errstate(all="ignore"):
            (f,) = _arrays(self._function(x.ravel(), y.ravel())[:1], x.size)
        return f.reshape(x.shape)

    def evaluate(self, points: FloatArray) -> Evaluation:
        points = np.asarray(points, dtype=np.float64)
        k = points.shape[0]
        with np.errstate(all="ignore"):  # a NaN (say log of a negative) is the solver's to report
            f, fx, fy, fxx, fxy, fyy = _arrays(self._function(points[:, 0], points[:, 1]), k)
        gradient = np.column_stack([fx, fy, -np.ones(k)])
        hessian = np.zeros((k, 3, 3))
        hessian[:, 0, 0], hessian[:, 0, 1], hessian[:, 1, 0], hessian[:, 1, 1] = fxx, fxy, fxy, fyy
        return _checked(self.name, points, f - points[:, 2], gradient, hessian, 3)


_VARIABLES = ("x", "y", "z")


@dataclass(frozen=True)
class Expression:
    """Any obstacle ``{phi >= 0}`` with ``phi`` written as text: in x and y in the plane, in x, y
    and z in space (``dimension = 3``).

    Gradient and Hessian come from sympy. Convexity is not checked (``convex`` is False), and
    :meth:`outline` is empty: plot ``phi >= 0`` on a grid (e.g. ``contourf``) instead.
    """

    phi: str
    name: str = "expression"
    dimension: int = 2
    _function: Callable[..., list[Any]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        key = _labeller(self.name)
        if isinstance(self.dimension, bool) or self.dimension not in (2, 3):
            raise ScenarioError(
                f"{key('dimension')} = {shown(self.dimension)}; use 2 (phi in x, y) or 3 (phi in x, y, z).",
                key=key("dimension"),
            )
        d = int(self.dimension)
        object.__setattr__(self, "dimension", d)
        sympy, symbols, phi = _parse_expression(self.phi, _VARIABLES[:d], key("phi"))
        # phi, its d first derivatives, then the Hessian's upper triangle row by row.
        terms = [phi, *(_derivative(sympy, phi, s) for s in symbols)]
        terms += [_derivative(sympy, phi, symbols[i], symbols[j]) for i in range(d) for j in range(i, d)]
        object.__setattr__(self, "_function", sympy.lambdify(symbols, terms, modules="numpy"))

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.phi, self.name, self.dimension))

    @property
    def convex(self) -> bool:
        return False

    def evaluate(self, points: FloatArray) -> Evaluation:
        d = self.dimension
        points = np.asarray(points, dtype=np.float64)
        k = points.shape[0]
        with np.errstate(all="ignore"):
            values = _arrays(self._function(*points.T[:d]), k)
        gradient = np.column_stack(values[1 : 1 + d])
        hessian = np.empty((k, d, d))
        upper = iter(values[1 + d :])
        for i in range(d):
            for j in range(i, d):
                hessian[:, i, j] = hessian[:, j, i] = next(upper)
        return _checked(self.name, points, values[0], gradient, hessian, d)

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        return np.empty((0, 2))


@dataclass(frozen=True)
class CallableObstacle:
    """Any Python ``function(points) -> (phi, gradient, hessian)``, checked on every call.

    Wrong shapes or non-finite values raise :class:`ScenarioError` naming the obstacle.
    :meth:`outline` is empty (plot ``phi >= 0`` on a grid instead).
    """

    function: Callable[[FloatArray], Any]
    name: str = "callable"
    convex: bool = False

    def evaluate(self, points: FloatArray) -> Evaluation:
        points = np.asarray(points, dtype=np.float64)
        result = self.function(points)
        if not (isinstance(result, (tuple, list)) and len(result) == 3):
            what = (
                f"{len(result)} values"
                if isinstance(result, (tuple, list))
                else f"an object of type {type(result).__name__}"
            )
            raise ScenarioError(f"obstacle {self.name!r}: the function returned {what}, not (phi, gradient, hessian).")
        try:
            phi, gradient, hessian = (np.asarray(value, dtype=np.float64) for value in result)
        except (TypeError, ValueError):
            raise ScenarioError(f"obstacle {self.name!r}: the function returned non-numeric arrays.") from None
        return _checked(self.name, points, phi, gradient, hessian)

    def outline(self, bounds: Bounds, samples: int = 200) -> FloatArray:
        return np.empty((0, 2))
