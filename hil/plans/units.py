"""Engineering units for plans, checks and reports.

A unit is a dimension and a scale to the SI unit of that dimension, so that a
limit written in rpm can be compared with a signal logged in rad/s. Only
multiplicative units exist here (no temperatures with offsets). Frequency (Hz)
and angular velocity (rad/s, rpm) are kept apart on purpose: converting one to
the other needs a 2*pi and a choice of electrical or mechanical, which a plan
should state, not the unit table.
"""
from __future__ import annotations

import math
from typing import TypeVar

import numpy as np

from configfile.dataclass_methods import dataclass

ArrayOrFloat = TypeVar("ArrayOrFloat", float, np.ndarray)


class UnitError(ValueError):
    """An unknown unit, or a conversion between units of different dimensions."""


@dataclass(frozen=True)
class Unit:
    """A unit symbol, its physical dimension and its factor to SI."""

    symbol: str        # canonical spelling, as reports print it
    dimension: str     # e.g. "angular_velocity"; equal dimensions convert
    scale_to_si: float  # value_in_si = value * scale_to_si


_RPM = 2.0 * math.pi / 60.0

_UNITS: tuple[Unit, ...] = (
    Unit("1", "dimensionless", 1.0),
    Unit("%", "dimensionless", 0.01),
    Unit("count", "dimensionless", 1.0),
    Unit("s", "time", 1.0),
    Unit("ms", "time", 1e-3),
    Unit("us", "time", 1e-6),
    Unit("rad/s", "angular_velocity", 1.0),
    Unit("rpm", "angular_velocity", _RPM),
    Unit("deg/s", "angular_velocity", math.pi / 180.0),
    Unit("Hz", "frequency", 1.0),
    Unit("kHz", "frequency", 1e3),
    Unit("rad", "angle", 1.0),
    Unit("deg", "angle", math.pi / 180.0),
    Unit("A", "current", 1.0),
    Unit("mA", "current", 1e-3),
    Unit("V", "voltage", 1.0),
    Unit("mV", "voltage", 1e-3),
    Unit("Nm", "torque", 1.0),
    Unit("mNm", "torque", 1e-3),
    Unit("Wb", "flux_linkage", 1.0),
    Unit("mWb", "flux_linkage", 1e-3),
    Unit("ohm", "resistance", 1.0),
    Unit("mohm", "resistance", 1e-3),
    Unit("H", "inductance", 1.0),
    Unit("mH", "inductance", 1e-3),
    Unit("uH", "inductance", 1e-6),
    Unit("W", "power", 1.0),
    Unit("kgm^2", "inertia", 1.0),
    # a temperature only in degC: no kelvin, whose offset this multiplicative table cannot hold
    Unit("degC", "temperature", 1.0),
)

# Other spellings people write; each maps to a canonical symbol above.
_ALIASES = {
    "": "1", "dimensionless": "1", "counts": "count",
    "sec": "s", "µs": "us", "μs": "us",
    "rad_s": "rad/s", "r/min": "rpm", "RPM": "rpm",
    "°": "deg", "degree": "deg", "degrees": "deg",
    "N*m": "Nm", "N·m": "Nm", "N.m": "Nm", "mN*m": "mNm",
    "Ω": "ohm", "Ohm": "ohm", "mΩ": "mohm", "µH": "uH", "μH": "uH",
    "kg*m^2": "kgm^2", "kgm2": "kgm^2",
    "°C": "degC", "degc": "degC",
}

UNITS: dict[str, Unit] = {u.symbol: u for u in _UNITS}
KNOWN_UNITS: tuple[str, ...] = tuple(UNITS)


def unit(symbol: str) -> Unit:
    """The Unit for a symbol or alias; UnitError naming the known units otherwise."""
    if not isinstance(symbol, str):
        raise UnitError(f"a unit must be a string, got {type(symbol).__name__} {symbol!r}")
    text = symbol.strip()
    found = UNITS.get(_ALIASES.get(text, text))
    if found is None:
        raise UnitError(f"unknown unit '{symbol}'; known units: {', '.join(KNOWN_UNITS)}")
    return found


def canonical(symbol: str) -> str:
    """'r/min' -> 'rpm', '' -> '1'."""
    return unit(symbol).symbol


def is_known(symbol: str) -> bool:
    try:
        unit(symbol)
    except UnitError:
        return False
    return True


def compatible(a: str, b: str) -> bool:
    """True when values in unit a convert to unit b."""
    return unit(a).dimension == unit(b).dimension


def dimension(symbol: str) -> str:
    return unit(symbol).dimension


def convert(value: ArrayOrFloat, from_unit: str, to_unit: str) -> ArrayOrFloat:
    """value in from_unit expressed in to_unit; UnitError if the dimensions differ."""
    src, dst = unit(from_unit), unit(to_unit)
    if src.dimension != dst.dimension:
        raise UnitError(f"cannot convert {src.symbol} ({src.dimension.replace('_', ' ')}) "
                        f"to {dst.symbol} ({dst.dimension.replace('_', ' ')})")
    if src.scale_to_si == dst.scale_to_si:
        return value
    return value * (src.scale_to_si / dst.scale_to_si)


def is_angle(symbol: str) -> bool:
    return unit(symbol).dimension == "angle"


def wrap_angle(values: ArrayOrFloat, unit_symbol: str = "rad") -> ArrayOrFloat:
    """Wraps an angle (or angle difference) in the given unit into (-half turn, half turn]."""
    half_turn = convert(math.pi, "rad", unit_symbol)
    full = 2.0 * half_turn
    wrapped = half_turn - np.mod(half_turn - np.asarray(values, dtype=float), full)
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


__all__ = ["Unit", "UnitError", "UNITS", "KNOWN_UNITS", "unit", "canonical", "is_known",
           "compatible", "dimension", "convert", "is_angle", "wrap_angle"]


@dataclass(frozen=True)
class Quantity:
    """A value with its unit, as plans write it: ``{value: 3000, unit: rpm}``."""

    value: float
    unit: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "unit", canonical(self.unit))
        object.__setattr__(self, "value", float(self.value))

    def to(self, unit_symbol: str) -> float:
        return float(convert(self.value, self.unit, unit_symbol))

    def __str__(self) -> str:
        return f"{self.value:g}" if self.unit == "1" else f"{self.value:g} {self.unit}"

    def to_json(self) -> dict:
        return {"value": self.value, "unit": self.unit}


__all__ += ["Quantity"]
