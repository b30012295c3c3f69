"""The units an output labels its numbers with: those the scenario declares, or none.

A scenario without ``units`` is in whatever consistent units its author chose (lengths in feet and
forces in pounds-force, or the built-ins' weight of 1), so nothing printed, drawn or written for it
names a unit: a number stands alone, a label has no ``[N]``. With ``units = "SI"`` every force,
length, mass, energy and gravity is labelled. Every output asks here; none decides for itself.
"""

from __future__ import annotations

from typing import Literal, Protocol, get_args

Quantity = Literal["force", "length", "mass", "gravity", "energy", "force_per_length"]

QUANTITIES: tuple[Quantity, ...] = get_args(Quantity)
# Each unit system a scenario may declare (model.UNIT_SYSTEMS), with the unit of every quantity an
# output shows (a squared-form multiplier is a tension per length).
SYSTEMS: dict[str, dict[Quantity, str]] = {
    "SI": {
        "force": "N",
        "length": "m",
        "mass": "kg",
        "gravity": "m/s^2",
        "energy": "J",
        "force_per_length": "N/m",
    },
}


class Declares(Protocol):
    """Anything that carries the scenario's declaration: a Problem, an inverted form, a study."""

    @property
    def units(self) -> str | None: ...


Units = Declares | str | None  # a declaration, or what carries one


def declared(value: object) -> str | None:
    """``value`` if it names a unit system, else None (a scenario document's ``units``, not yet
    checked: a misspelt one is refused where the document is built, not here)."""
    return value if isinstance(value, str) and value in SYSTEMS else None


def system_of(units: Units) -> str | None:
    """The unit system declared ("SI"), or None."""
    return units if units is None or isinstance(units, str) else units.units


def unit(units: Units, quantity: Quantity) -> str:
    """The unit of ``quantity`` under ``units`` ("N", "m", ...), or "" where none is declared."""
    system = system_of(units)
    return "" if system is None else SYSTEMS[system][quantity]


def force_unit(units: Units) -> str:
    return unit(units, "force")


def length_unit(units: Units) -> str:
    return unit(units, "length")


def multiplier_unit(units: Units, formulation: str) -> str:
    """The unit of a link's multiplier: a tension in the norm form, a tension per length in the
    squared form (``T_k / (2 d_k)``)."""
    return unit(units, "force" if formulation == "norm" else "force_per_length")


def with_unit(number: str, symbol: str) -> str:
    """A number followed by its unit (``0.5 N``), or the number alone without one."""
    return f"{number} {symbol}" if symbol else number


def in_unit(symbol: str) -> str:
    """`` in N`` to end a phrase with its unit, or nothing without one."""
    return f" in {symbol}" if symbol else ""


def label(name: str, symbol: str) -> str:
    """An axis label or a column header with its unit in brackets (``tension [N]``), or the name alone."""
    return f"{name} [{symbol}]" if symbol else name


def unit_labels(units: Units) -> dict[str, str | None]:
    """The declaration and every quantity's unit ("" for none), as a page or a file carries them:
    ``{"system": "SI", "force": "N", ...}`` or ``{"system": None, "force": "", ...}``."""
    system = system_of(units)
    return {"system": system, **{quantity: unit(system, quantity) for quantity in QUANTITIES}}
