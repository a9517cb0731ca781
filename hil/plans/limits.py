"""Limits as structured data: bounds, a marginal band, a comparison and a unit.

A plan writes ``limits: {high: 150, marginal: 20, unit: ms}``, never a string
such as "< 150 ms" to be parsed. A measured value, with its own unit, is
converted into the limits' unit and judged:

- comparison ``inside`` (default): PASS when low <= value <= high (a missing
  bound is open). A value that passes but lies within ``marginal`` of a bound
  is MARGINAL: it passes today and warns that little margin is left.
- comparison ``outside``: PASS when value < low or value > high (both bounds
  required); MARGINAL when it passes within ``marginal`` of the bound it cleared.

A value that is NaN (not computable) is not judged here: the check reports ERROR.
"""
from __future__ import annotations

import math

from configfile.dataclass_methods import dataclass
from hil.plans.verdict import Outcome
from hil.plans.units import UnitError, canonical, convert

COMPARISONS = ("inside", "outside")


@dataclass(frozen=True)
class Limits:
    """A check's bounds in one unit, with an optional marginal band inside them."""

    unit: str
    low: float | None = None
    high: float | None = None
    marginal: float | None = None   # width of the warning band, in `unit`
    comparison: str = "inside"

    def __post_init__(self) -> None:
        object.__setattr__(self, "unit", canonical(self.unit))
        if self.comparison not in COMPARISONS:
            raise ValueError(f"comparison must be one of {', '.join(COMPARISONS)}, "
                             f"got {self.comparison!r}")
        if self.low is None and self.high is None:
            raise ValueError("limits need at least one of low, high")
        if self.comparison == "outside" and (self.low is None or self.high is None):
            raise ValueError("comparison 'outside' needs both low and high")
        for name in ("low", "high", "marginal"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if self.low is not None and self.high is not None and self.low > self.high:
            raise ValueError(f"low ({self.low:g}) is above high ({self.high:g})")
        if self.marginal is not None and self.marginal < 0:
            raise ValueError(f"marginal must not be negative, got {self.marginal:g}")

    def judge(self, value: float, value_unit: str | None = None) -> Outcome:
        """PASS / MARGINAL / FAIL for a finite value (converted from value_unit if given)."""
        v = self.to_limit_unit(value, value_unit)
        if math.isnan(v):
            raise ValueError("a NaN measurement cannot be judged; the check reports ERROR")
        m = self.marginal or 0.0
        if self.comparison == "inside":
            if (self.low is not None and v < self.low) or (self.high is not None and v > self.high):
                return Outcome.FAIL
            near_low = self.low is not None and v < self.low + m
            near_high = self.high is not None and v > self.high - m
            return Outcome.MARGINAL if (m > 0 and (near_low or near_high)) else Outcome.PASS
        assert self.low is not None and self.high is not None
        if self.low <= v <= self.high:
            return Outcome.FAIL
        near = (v < self.low and v > self.low - m) or (v > self.high and v < self.high + m)
        return Outcome.MARGINAL if (m > 0 and near) else Outcome.PASS

    def to_limit_unit(self, value: float, value_unit: str | None) -> float:
        if value_unit is None:
            return float(value)
        return float(convert(float(value), value_unit, self.unit))

    def in_unit(self, other_unit: str) -> "Limits":
        """The same limits expressed in another compatible unit (for plotting on a signal)."""
        def c(x: float | None) -> float | None:
            return None if x is None else float(convert(x, self.unit, other_unit))
        low, high = c(self.low), c(self.high)
        marginal = None if self.marginal is None else abs(float(convert(self.marginal, self.unit, other_unit)))
        return Limits(other_unit, low, high, marginal, self.comparison)

    def describe(self) -> str:
        """'<= 150 ms', '2940 .. 3060 rpm', 'outside -1 .. 1 A' (with the marginal band)."""
        u = "" if self.unit == "1" else f" {self.unit}"
        if self.comparison == "outside":
            text = f"outside {self.low:g} .. {self.high:g}{u}"
        elif self.low is not None and self.high is not None:
            text = f"{self.low:g} .. {self.high:g}{u}"
        elif self.high is not None:
            text = f"<= {self.high:g}{u}"
        else:
            text = f">= {self.low:g}{u}"
        if self.marginal:
            text += f" (marginal within {self.marginal:g}{u})"
        return text

    def to_json(self) -> dict:
        return {"low": self.low, "high": self.high, "marginal": self.marginal,
                "comparison": self.comparison, "unit": self.unit}

    @classmethod
    def from_json(cls, data: dict) -> "Limits":
        return cls(unit=data["unit"], low=data.get("low"), high=data.get("high"),
                   marginal=data.get("marginal"), comparison=data.get("comparison", "inside"))


__all__ = ["Limits", "COMPARISONS", "UnitError"]
