"""Load torque on the shaft: a time profile plus a speed-proportional term, or a locked rotor.

    T_load(t, w) = profile(t) + k w

profile(t) is piecewise linear in absolute plant time (constant, step, ramp and table are all
knot lists), held constant before the first knot and after the last; a positive value opposes
positive rotation (an active load such as a hoist: it does not reverse with the speed). k w
opposes the motion in either direction. Every setter may be called while the plant runs; the
knots are breakpoints at which the plant splits its integration, so a step lands exactly.

A locked rotor (a brake) holds the speed at zero whatever the torque.
"""
from __future__ import annotations

import bisect
import math
from configfile.dataclass_methods import dataclass
from typing import Callable, Iterable

from configfile.fields import param


@dataclass(frozen=True)
class LoadParams:
    torque_nm: float = param(0.0)
    speed_proportional_nm_per_rad_s: float = param(0.0, ge=0)
    table: tuple[tuple[float, float], ...] = param((), kind="table")  # ((t_s, torque_nm), ...)
    locked: bool = param(False)


class Load:
    """Runtime load; `clock()` returns the plant's time (s) for setters relative to now."""

    __slots__ = ("_clock", "_t", "_v", "kw", "locked", "version")

    def __init__(self, params: LoadParams, clock: Callable[[], float]):
        self._clock = clock
        self._t: list[float] = []
        self._v: list[float] = []
        self.kw = params.speed_proportional_nm_per_rad_s
        self.locked = params.locked
        self.version = 0
        if params.table:
            self.set_table(params.table)
        else:
            self.set_constant(params.torque_nm)

    # ------------------------------------------------------------------ setters
    def set_constant(self, torque_nm: float) -> None:
        self._set([0.0], [_finite(torque_nm, "torque_nm")])

    def set_step(self, at_s: float, torque_nm: float) -> None:
        """The current profile up to at_s (absolute plant time), then torque_nm."""
        at_s = _finite(at_s, "at_s")
        before = self.profile(at_s)
        keep = [(t, v) for t, v in zip(self._t, self._v) if t < at_s]
        knots = keep + [(at_s, before), (at_s, _finite(torque_nm, "torque_nm"))]
        self._set([t for t, _ in knots], [v for _, v in knots])

    def set_ramp(self, to_nm: float, duration_s: float) -> None:
        """Linear from the present value to to_nm over duration_s from now, then held."""
        duration_s = _finite(duration_s, "duration_s")
        if duration_s < 0.0:
            raise ValueError(f"duration_s must be >= 0, got {duration_s}")
        now = self._clock()
        self._set([now, now + duration_s], [self.profile(now), _finite(to_nm, "to_nm")])

    def set_table(self, rows: Iterable[tuple[float, float]]) -> None:
        """[(t_s, torque_nm), ...] in absolute plant time, linear in between; times must not
        decrease (two rows at the same time make a step)."""
        rows = [(_finite(t, "t_s"), _finite(v, "torque_nm")) for t, v in rows]
        if not rows:
            raise ValueError("a load table needs at least one (t_s, torque_nm) row")
        for (t0, _), (t1, _) in zip(rows, rows[1:]):
            if t1 < t0:
                raise ValueError(f"load table times must not decrease ({t1} after {t0})")
        self._set([t for t, _ in rows], [v for _, v in rows])

    def set_speed_proportional(self, nm_per_rad_s: float) -> None:
        value = _finite(nm_per_rad_s, "nm_per_rad_s")
        if value < 0.0:
            raise ValueError(f"nm_per_rad_s must be >= 0, got {value}")
        self.kw = value
        self.version += 1

    def set_locked(self, locked: bool) -> None:
        self.locked = bool(locked)
        self.version += 1

    def _set(self, t: list[float], v: list[float]) -> None:
        self._t, self._v = t, v
        self.version += 1

    # ------------------------------------------------------------------ queries
    def profile(self, t: float) -> float:
        """The time profile at t (without the speed term)."""
        ts, vs = self._t, self._v
        i = bisect.bisect_right(ts, t)
        if i == 0:
            return vs[0]
        if i == len(ts):
            return vs[-1]
        t0, t1 = ts[i - 1], ts[i]
        return vs[i - 1] + (vs[i] - vs[i - 1]) * (t - t0) / (t1 - t0)

    def torque(self, t: float, w: float) -> float:
        return self.profile(t) + self.kw * w

    def segment(self, t: float) -> tuple[float, float, float]:
        """(value at t, slope, next knot > t or inf): profile(t + x) = value + slope x
        until that knot."""
        ts, vs = self._t, self._v
        i = bisect.bisect_right(ts, t)
        if i == 0:
            return vs[0], 0.0, ts[0]
        if i == len(ts):
            return vs[-1], 0.0, math.inf
        t0, t1 = ts[i - 1], ts[i]
        slope = (vs[i] - vs[i - 1]) / (t1 - t0)
        return vs[i - 1] + slope * (t - t0), slope, t1


def _finite(value: float, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(number):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return number
