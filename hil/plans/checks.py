"""Checks: small functions over recorded signals, and the registry plans name them by.

Two layers:

1. Pure measurement functions over numpy arrays (`settling_time`, `thd_percent`,
   `lag_s`, ...). They know nothing of plans and are tested against analytic
   answers on synthetic signals (a first-order step settles to 2 % in
   tau*ln(50); a sine with 10 % third and 5 % fifth harmonic has a THD of
   11.18 %; a delayed copy lags by its delay).
2. `CHECK_KINDS`: the plan's ``kind`` string -> the signals it needs, the
   arguments it accepts (validated when the plan is loaded), the unit of what
   it measures, and an adapter that windows the signals and calls layer 1.

`evaluate_check(spec, signals, marks)` turns a plan's check step into a
CheckResult: measured value converted to the limits' unit, PASS / MARGINAL /
FAIL from the limits, or ERROR (with the plan file, line and reason) when the
value cannot be computed.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import field
from typing import Any

import numpy as np

from configfile.dataclass_methods import dataclass
from hil.plans.limits import Limits
from hil.plans.outcome import CheckResult
from hil.plans.verdict import Outcome
from hil.plans.signals import MissingSignalError, Signal, SignalSet
from hil.plans.units import Quantity, UnitError, compatible, convert, is_angle, wrap_angle

# A check step (hil.plans.format.CheckStep) is read by duck typing: the plan format
# imports this module for the check kinds, so this one does not import it back.


class CheckError(ValueError):
    """A check that cannot be computed on the data it was given."""


# --------------------------------------------------------------------------- #
# Layer 1: measurement functions (arrays in, numbers out)                     #
# --------------------------------------------------------------------------- #

def _crossing_time(t: np.ndarray, y: np.ndarray, i: int, level: float) -> float:
    """Time between samples i-1 and i where y crosses level (linear interpolation)."""
    if i <= 0:
        return float(t[0])
    y0, y1 = y[i - 1], y[i]
    if y1 == y0:
        return float(t[i])
    frac = (level - y0) / (y1 - y0)
    return float(t[i - 1] + min(max(frac, 0.0), 1.0) * (t[i] - t[i - 1]))


def final_value(t: np.ndarray, y: np.ndarray, average_s: float = 0.0) -> float:
    """Mean of the samples in the last average_s of the record (the last sample if 0)."""
    if len(y) == 0:
        raise CheckError("no samples")
    if average_s <= 0:
        return float(y[-1])
    return float(np.mean(y[t >= t[-1] - average_s]))


def settling_time(t: np.ndarray, y: np.ndarray, target: float, band: float) -> float:
    """Time from t[0] until y enters |y - target| <= band for good.

    Returns 0 when y never leaves the band and +inf when the last sample is
    outside it. The entry instant is interpolated between samples.
    """
    if band <= 0:
        raise CheckError(f"settling band must be positive, got {band:g}")
    err = np.abs(y - target)
    outside = np.flatnonzero(err > band)
    if len(outside) == 0:
        return 0.0
    last = int(outside[-1])
    if last == len(y) - 1:
        return math.inf
    # y crosses the band edge between samples last and last+1, on the side it left from.
    edge = target + band if y[last] > target else target - band
    return _crossing_time(t, y, last + 1, edge) - float(t[0])


def rise_crossings(t: np.ndarray, y: np.ndarray, initial: float, target: float,
                   from_pct: float = 10.0, to_pct: float = 90.0) -> tuple[float, float]:
    """Times of the first crossings of from_pct and to_pct of the step (inf if never)."""
    step = target - initial
    if step == 0:
        raise CheckError("rise time of a zero step (initial equals target)")
    progress = (y - initial) / step          # 0 at initial, 1 at target, either direction
    lo, hi = from_pct / 100.0, to_pct / 100.0
    above_lo = np.flatnonzero(progress >= lo)
    above_hi = np.flatnonzero(progress >= hi)
    t_lo = _crossing_time(t, progress, int(above_lo[0]), lo) if len(above_lo) else math.inf
    t_hi = _crossing_time(t, progress, int(above_hi[0]), hi) if len(above_hi) else math.inf
    return t_lo, t_hi


def rise_time(t: np.ndarray, y: np.ndarray, initial: float, target: float,
              from_pct: float = 10.0, to_pct: float = 90.0) -> float:
    """Time for y to go from from_pct to to_pct of the step initial -> target (first crossings)."""
    t_lo, t_hi = rise_crossings(t, y, initial, target, from_pct, to_pct)
    if math.isinf(t_lo) or math.isinf(t_hi):
        return math.inf
    return t_hi - t_lo


def overshoot_percent(y: np.ndarray, initial: float, target: float) -> float:
    """Peak excursion beyond target as a percentage of the step (0 when none)."""
    step = target - initial
    if step == 0:
        raise CheckError("overshoot of a zero step (initial equals target)")
    peak = float(np.max(y)) if step > 0 else float(np.min(y))
    return max(0.0, (peak - target) / step * 100.0)


def statistic(y: np.ndarray, name: str) -> float:
    if len(y) == 0:
        raise CheckError("no samples")
    if name == "mean":
        return float(np.mean(y))
    if name == "rms":
        return float(np.sqrt(np.mean(np.square(y))))
    if name == "std":
        return float(np.std(y))
    if name == "min":
        return float(np.min(y))
    if name == "max":
        return float(np.max(y))
    if name == "max_abs":
        return float(np.max(np.abs(y)))
    if name == "peak_to_peak":
        return float(np.ptp(y))
    raise CheckError(f"unknown statistic '{name}'")


STATISTICS = ("mean", "rms", "std", "min", "max", "max_abs", "peak_to_peak")


def _running_extreme(x: np.ndarray, half_width: int, fn: Callable) -> np.ndarray:
    """Running min or max over [i - half_width, i + half_width] (van Herk / Gil-Werman, O(n))."""
    if half_width <= 0:
        return x.copy()
    w = 2 * half_width + 1
    padded = np.concatenate([np.full(half_width, x[0]), x, np.full(half_width, x[-1])])
    n = len(padded)
    blocks = -(-n // w)
    fill = x[-1]
    full = np.concatenate([padded, np.full(blocks * w - n, fill)]).reshape(blocks, w)
    prefix = fn.accumulate(full, axis=1).ravel()
    suffix = fn.accumulate(full[:, ::-1], axis=1)[:, ::-1].ravel()
    starts = np.arange(len(x))
    return fn(suffix[starts], prefix[starts + w - 1])


def envelope_excursion(t: np.ndarray, y: np.ndarray, ref_t: np.ndarray, ref: np.ndarray,
                       tolerance: float, time_tolerance_s: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Largest distance of y outside the tube around ref (0 when always inside).

    The tube at time t is [min(ref over t +- time_tolerance) - tolerance,
    max(ref over t +- time_tolerance) + tolerance]: the signal may be late or
    early by the time tolerance and off by the value tolerance, the way
    commercial HIL test libraries define an envelope. Returns (excursion,
    tube_low, tube_high) on y's sample times.
    """
    if len(t) < 2:
        raise CheckError("an envelope needs at least two samples")
    dt = float(np.median(np.diff(t)))
    m = int(round(time_tolerance_s / dt)) if dt > 0 else 0
    grid = t[0] + dt * np.arange(-m, len(t) + m)
    r = np.interp(grid, ref_t, ref)
    lo = _running_extreme(r, m, np.minimum)[m:m + len(t)] - tolerance
    hi = _running_extreme(r, m, np.maximum)[m:m + len(t)] + tolerance
    excursion = np.maximum(np.maximum(lo - y, y - hi), 0.0)
    return float(np.max(excursion)), lo, hi


def error_between(y: np.ndarray, ref: np.ndarray, angle_unit: str | None = None) -> np.ndarray:
    """y - ref, wrapped into a half turn either way when angle_unit is given."""
    diff = y - ref
    return wrap_angle(diff, angle_unit) if angle_unit is not None else diff


def lag_s(t: np.ndarray, y: np.ndarray, ref: np.ndarray, max_lag_s: float) -> tuple[float, float]:
    """Delay of y behind ref (y(t) ~ ref(t - lag)) by normalised cross-correlation.

    For each lag in +-max_lag_s the Pearson correlation of the overlapping
    parts is computed; the peak is refined by a parabola through its
    neighbours. Normalising each lag by its own overlap keeps the estimate
    unbiased for step responses, where a plain correlation sum favours zero
    lag. Returns (lag in s, peak correlation). Raises CheckError when either
    signal is constant or the peak sits at the edge of the search range (the
    true lag may be larger).
    """
    n = len(y)
    if n < 4:
        raise CheckError("a lag needs at least four samples")
    dt = float(np.median(np.diff(t)))
    max_k = min(int(round(max_lag_s / dt)), n // 2)
    if max_k < 1:
        raise CheckError(f"max_lag_s {max_lag_s:g} s is shorter than one sample ({dt:g} s)")
    if np.ptp(y) == 0 or np.ptp(ref) == 0:
        raise CheckError("a signal is constant in the window: its lag is undefined")
    lags = np.arange(-max_k, max_k + 1)
    corr = np.empty(len(lags))
    for j, k in enumerate(lags):
        a, b = (y[k:], ref[:n - k]) if k >= 0 else (y[:n + k], ref[-k:])
        a = a - a.mean()
        b = b - b.mean()
        denom = math.sqrt(float(np.dot(a, a)) * float(np.dot(b, b)))
        corr[j] = float(np.dot(a, b)) / denom if denom > 0 else 0.0
    j = int(np.argmax(corr))
    if j == 0 or j == len(lags) - 1:
        raise CheckError(f"the correlation peaks at the edge of the search range "
                         f"(+-{max_k * dt * 1e3:g} ms): increase max_lag_s")
    c0, c1, c2 = corr[j - 1], corr[j], corr[j + 1]
    denom = c0 - 2 * c1 + c2
    frac = 0.5 * (c0 - c2) / denom if denom != 0 else 0.0
    return float((lags[j] + frac) * dt), float(c1)


def ramp_lag_s(t: np.ndarray, y: np.ndarray, ref: np.ndarray,
               min_r2: float = 0.98) -> tuple[float, dict[str, float]]:
    """Delay of y behind a ramping reference: -mean(y - ref) / slope of ref.

    The velocity-error definition: a first-order filter with time constant
    tau, fed a ramp, settles to lag tau behind it; an estimator that models
    acceleration (the EKF's w' state) settles to zero lag. Cross-correlation
    cannot measure this (every shift of a straight line correlates perfectly),
    so the window must hold a ramp: a straight-line fit of ref must explain at
    least min_r2 of its variance, or this raises CheckError.
    """
    if len(t) < 3:
        raise CheckError("a ramp lag needs at least three samples")
    x = t - t[0]
    slope, intercept = np.polyfit(x, ref, 1)
    ss_tot = float(np.sum((ref - np.mean(ref)) ** 2))
    if ss_tot == 0 or slope == 0:
        raise CheckError("the reference is constant in the window: no ramp to lag behind")
    r2 = 1.0 - float(np.sum((ref - (slope * x + intercept)) ** 2)) / ss_tot
    if r2 < min_r2:
        raise CheckError(f"the reference is not a ramp in this window (straight-line fit "
                         f"R^2 = {r2:.3f} < {min_r2}); choose a window of constant acceleration")
    mean_error = float(np.mean(y - ref))
    return -mean_error / float(slope), {"slope_per_s": float(slope), "mean_error": mean_error,
                                        "r2": r2}


def ripple(t: np.ndarray, y: np.ndarray, measure: str = "peak_to_peak",
           detrend: str = "mean") -> float:
    """Peak-to-peak or RMS of y about its mean (or about a fitted line, for a drifting signal)."""
    if len(y) < 2:
        raise CheckError("ripple needs at least two samples")
    if detrend == "linear":
        coeffs = np.polyfit(t - t[0], y, 1)
        dev = y - np.polyval(coeffs, t - t[0])
    else:
        dev = y - np.mean(y)
    if measure == "rms":
        return float(np.sqrt(np.mean(dev * dev)))
    return float(np.ptp(dev))


def estimate_fundamental_hz(t: np.ndarray, y: np.ndarray) -> float:
    """Frequency of the strongest spectral line (Hann window, zero-padded FFT, parabolic peak)."""
    n = len(y)
    dt = float(np.median(np.diff(t)))
    x = (y - np.mean(y)) * np.hanning(n)
    nfft = 1 << int(math.ceil(math.log2(n * 8)))
    spec = np.abs(np.fft.rfft(x, nfft))
    spec[0] = 0.0
    k = int(np.argmax(spec))
    if 0 < k < len(spec) - 1:
        a, b, c = np.log(spec[k - 1] + 1e-300), np.log(spec[k] + 1e-300), np.log(spec[k + 1] + 1e-300)
        den = a - 2 * b + c
        k = k + (0.5 * (a - c) / den if den != 0 else 0.0)
    return float(k / (nfft * dt))


def thd_percent(t: np.ndarray, y: np.ndarray, fundamental_hz: float | None = None,
                harmonics: int = 40, method: str = "harmonics") -> tuple[float, dict[str, float]]:
    """Total harmonic distortion relative to the fundamental, in percent.

    The record is cut to a whole number of fundamental cycles (its last
    ones) so that harmonics are orthogonal to it, and each harmonic's
    amplitude is the projection on exp(-j 2 pi h f0 t). ``method``:
    ``harmonics`` = sqrt(sum of h = 2..H amplitudes^2) / fundamental;
    ``total`` (THD+N) = RMS of everything except DC and the fundamental,
    over the fundamental's RMS: the honest figure for a hysteresis drive
    whose switching ripple is not at harmonics of the fundamental.
    """
    if len(y) < 8:
        raise CheckError("THD needs at least eight samples")
    dt = float(np.median(np.diff(t)))
    f0 = fundamental_hz if fundamental_hz is not None else estimate_fundamental_hz(t, y)
    if not f0 or f0 <= 0:
        raise CheckError("no fundamental found")
    span = len(y) * dt
    cycles = math.floor(span * f0 + 1e-9)
    if cycles < 2:
        raise CheckError(f"the window holds {span * f0:.2f} cycles of {f0:g} Hz; THD needs at least 2")
    n = int(round(cycles / f0 / dt))
    tt, yy = t[-n:] - t[-n], y[-n:]
    max_h = min(harmonics, int((0.5 / dt) / f0 - 1e-9))
    amps = []
    for h in range(1, max_h + 1):
        c = 2.0 / n * np.dot(yy, np.exp(-2j * math.pi * h * f0 * tt))
        amps.append(abs(c))
    a1 = amps[0]
    if a1 <= 0:
        raise CheckError("zero fundamental amplitude")
    if method == "total":
        ac = yy - np.mean(yy)
        rest = max(float(np.mean(ac * ac)) - a1 * a1 / 2.0, 0.0)
        value = math.sqrt(rest) / (a1 / math.sqrt(2.0)) * 100.0
    else:
        value = math.sqrt(sum(a * a for a in amps[1:])) / a1 * 100.0
    return value, {"fundamental_hz": f0, "fundamental_amplitude": a1, "cycles": cycles,
                   "harmonics_used": max_h, "harmonic_amplitudes": [float(a) for a in amps]}


def circularity_percent(x: np.ndarray, y: np.ndarray, centre: str = "origin",
                        measure: str = "peak_to_peak") -> tuple[float, dict[str, float]]:
    """How far a locus is from a circle: radius spread over mean radius, in percent.

    ``centre: origin`` measures radii from (0, 0), so an offset locus (a
    drifting flux integrator) counts against it; ``fit`` uses the
    least-squares circle centre (Kasa fit) and reports the offset separately.
    ``measure``: peak_to_peak = (r_max - r_min) / r_mean; rms = std(r) / r_mean.
    """
    if len(x) < 3:
        raise CheckError("a locus needs at least three samples")
    if centre == "fit":
        a = np.column_stack([2 * x, 2 * y, np.ones_like(x)])
        sol, *_ = np.linalg.lstsq(a, x * x + y * y, rcond=None)
        cx, cy = float(sol[0]), float(sol[1])
    else:
        cx = cy = 0.0
    r = np.hypot(x - cx, y - cy)
    r_mean = float(np.mean(r))
    if r_mean <= 0:
        raise CheckError("zero mean radius")
    spread = float(np.ptp(r)) if measure == "peak_to_peak" else float(np.std(r))
    return spread / r_mean * 100.0, {"r_mean": r_mean, "r_min": float(np.min(r)),
                                     "r_max": float(np.max(r)), "centre_x": cx, "centre_y": cy,
                                     "centre_offset": math.hypot(float(np.mean(x)), float(np.mean(y)))}


# --------------------------------------------------------------------------- #
# Layer 2: the registry                                                        #
# --------------------------------------------------------------------------- #

@dataclass(frozen=True)
class ArgSpec:
    """One kind-specific argument of a check, as the plan writes it.

    type: number (finite), positive (> 0), nonneg (>= 0), integer (>= 1),
    bool, choice (one of `choices`), quantity ({value, unit}), check (the name
    of an earlier check).
    """

    type: str
    required: bool = False
    default: Any = None
    choices: tuple[str, ...] = ()
    doc: str = ""


@dataclass(frozen=True)
class Role:
    """A signal a check reads. With allow_quantity, a constant {value, unit} may stand in."""

    key: str
    required: bool = True
    allow_quantity: bool = False
    doc: str = ""


@dataclass
class Measurement:
    """What a check measured: the value in its unit, a message and details for the report."""

    value: float
    unit: str
    message: str = ""
    details: dict[str, Any] = field(default_factory=dict)


@dataclass
class CheckContext:
    """What a kind's adapter receives: windowed signals by role, parsed arguments."""

    spec: "CheckStep"
    window: tuple[float, float]
    sig: dict[str, Signal]              # role -> signal, cut to the window
    full: dict[str, Signal]             # role -> whole recorded signal
    const: dict[str, Quantity]          # role -> constant standing in for a signal
    args: dict[str, Any]
    results: Mapping[str, CheckResult]

    def arg(self, key: str) -> Any:
        return self.args.get(key)

    @property
    def main(self) -> Signal:
        return self.sig["signal"]

    def reference_values(self, role: str = "reference") -> np.ndarray:
        """The reference on the main signal's samples, in the main signal's unit."""
        main = self.main
        if role in self.const:
            return np.full(len(main), self.const[role].to(main.unit))
        return self.full[role].to_unit(main.unit).resampled(main.t_s)

    def in_main_unit(self, key: str) -> float | None:
        q = self.args.get(key)
        return None if q is None else q.to(self.main.unit)


@dataclass(frozen=True)
class CheckKind:
    """A check `kind`: the signals it reads (roles), its arguments, how it measures and in which unit."""

    name: str
    roles: tuple[Role, ...]
    args: Mapping[str, ArgSpec]
    measure: Callable[[CheckContext], Measurement]
    result_unit: str              # a unit symbol, or "signal" for the main signal's unit
    doc: str
    limits_required: bool = True
    min_samples: int = 1


def _initial_and_target(ctx: CheckContext) -> tuple[float, float]:
    s = ctx.main
    initial = ctx.in_main_unit("initial")
    target = ctx.in_main_unit("target")
    if initial is None:
        initial = float(s.values[0])
    if target is None:
        target = final_value(s.t_s, s.values, 0.1 * (s.t_s[-1] - s.t_s[0]))
    return initial, target


def _m_final_value(ctx: CheckContext) -> Measurement:
    s = ctx.main
    v = final_value(s.t_s, s.values, ctx.arg("average_s") or 0.0)
    return Measurement(v, s.unit, details={"final_value": v})


def _m_settling(ctx: CheckContext) -> Measurement:
    s = ctx.main
    initial, target = _initial_and_target(ctx)
    if ctx.arg("band") is not None:
        band = ctx.in_main_unit("band")
    else:
        pct = ctx.arg("band_pct")
        if target == initial:
            raise CheckError("band_pct of a zero step (initial equals target): give an absolute band")
        band = abs(target - initial) * pct / 100.0
    ts = settling_time(s.t_s, s.values, target, band)
    msg = "" if math.isfinite(ts) else "never settled inside the band before the window ended"
    return Measurement(ts, "s", msg, {"target": target, "initial": initial, "band": band,
                                      "signal_unit": s.unit})


def _m_rise(ctx: CheckContext) -> Measurement:
    s = ctx.main
    initial, target = _initial_and_target(ctx)
    lo_pct, hi_pct = ctx.arg("from_pct"), ctx.arg("to_pct")
    t_lo, t_hi = rise_crossings(s.t_s, s.values, initial, target, lo_pct, hi_pct)
    tr = t_hi - t_lo if math.isfinite(t_lo) and math.isfinite(t_hi) else math.inf
    msg = "" if math.isfinite(tr) else f"never reached {hi_pct:g} % of the step"
    return Measurement(tr, "s", msg, {"target": target, "initial": initial, "signal_unit": s.unit,
                                      "from_pct": lo_pct, "to_pct": hi_pct,
                                      "t_from_s": t_lo, "t_to_s": t_hi})


def _m_overshoot(ctx: CheckContext) -> Measurement:
    s = ctx.main
    initial, target = _initial_and_target(ctx)
    ov = overshoot_percent(s.values, initial, target)
    peak = float(np.max(s.values) if target >= initial else np.min(s.values))
    return Measurement(ov, "%", details={"target": target, "initial": initial, "peak": peak,
                                         "signal_unit": s.unit})


def _m_steady_state_error(ctx: CheckContext) -> Measurement:
    s = ctx.main
    err = error_between(s.values, ctx.reference_values(), s.unit if is_angle(s.unit) else None)
    mean = float(np.mean(err))
    return Measurement(mean, s.unit, details={"mean_error": mean,
                                              "max_abs_error": float(np.max(np.abs(err)))})


def _m_bound(ctx: CheckContext) -> Measurement:
    s = ctx.main
    lo, hi = float(np.min(s.values)), float(np.max(s.values))
    lim = ctx.spec.limits
    details = {"min": lo, "max": hi}
    if lim is None or not compatible(lim.unit, s.unit):
        return Measurement(hi, s.unit, details=details)
    limits = lim.in_unit(s.unit)
    if limits.high is None:
        return Measurement(lo, s.unit, "minimum over the window", details)
    if limits.low is None:
        return Measurement(hi, s.unit, "maximum over the window", details)
    # Both bounds: report the extreme with the least room left (or the most overshoot).
    u = "" if s.unit == "1" else f" {s.unit}"
    if (hi - limits.high) >= (limits.low - lo):
        return Measurement(hi, s.unit, f"maximum over the window (minimum {lo:.6g}{u})", details)
    return Measurement(lo, s.unit, f"minimum over the window (maximum {hi:.6g}{u})", details)


def _m_statistic(ctx: CheckContext) -> Measurement:
    s = ctx.main
    name = ctx.arg("statistic")
    return Measurement(statistic(s.values, name), s.unit, details={"statistic": name})


def _m_envelope(ctx: CheckContext) -> Measurement:
    s = ctx.main
    if "reference" in ctx.const:
        ref_t = s.t_s
        ref = np.full(len(s), ctx.const["reference"].to(s.unit))
    else:
        full_ref = ctx.full["reference"].to_unit(s.unit)
        ref_t, ref = full_ref.t_s, full_ref.values
    tol = ctx.in_main_unit("tolerance")
    exc, lo, hi = envelope_excursion(s.t_s, s.values, ref_t, ref, tol, ctx.arg("time_tolerance_s"))
    outside = int(np.count_nonzero((s.values < lo) | (s.values > hi)))
    return Measurement(exc, s.unit, f"{outside} of {len(s)} samples outside the envelope",
                       {"samples_outside": outside, "_tube": (s.t_s, lo, hi)})


def _error_signal(ctx: CheckContext) -> np.ndarray:
    s = ctx.main
    wrap = ctx.arg("wrap")
    if wrap is None:
        wrap = is_angle(s.unit)
    if wrap and not is_angle(s.unit):
        raise CheckError(f"wrap needs an angle signal; '{s.name}' is in {s.unit}")
    return error_between(s.values, ctx.reference_values(), s.unit if wrap else None)


def _m_rms_error(ctx: CheckContext) -> Measurement:
    err = _error_signal(ctx)
    return Measurement(float(np.sqrt(np.mean(err * err))), ctx.main.unit,
                       details={"mean_error": float(np.mean(err)),
                                "max_abs_error": float(np.max(np.abs(err)))})


def _m_peak_error(ctx: CheckContext) -> Measurement:
    err = _error_signal(ctx)
    i = int(np.argmax(np.abs(err)))
    return Measurement(float(abs(err[i])), ctx.main.unit,
                       f"at t = {ctx.main.t_s[i]:.6f} s",
                       {"at_s": float(ctx.main.t_s[i]), "rms_error": float(np.sqrt(np.mean(err * err)))})


def _m_lag(ctx: CheckContext) -> Measurement:
    s = ctx.main
    ref = ctx.reference_values()
    y = s.values
    if is_angle(s.unit):
        y, ref = np.unwrap(y, period=2 * convert(math.pi, "rad", s.unit)), \
            np.unwrap(ref, period=2 * convert(math.pi, "rad", s.unit))
    lag, peak = lag_s(s.t_s, y, ref, ctx.arg("max_lag_s"))
    return Measurement(lag, "s", f"correlation peak {peak:.3f}", {"correlation": peak})


def _m_ramp_lag(ctx: CheckContext) -> Measurement:
    s = ctx.main
    ref = ctx.reference_values()
    y = s.values
    if is_angle(s.unit):
        ref = np.unwrap(ref, period=2 * convert(math.pi, "rad", s.unit))
        y = ref + error_between(y, ref, s.unit)
    lag, d = ramp_lag_s(s.t_s, y, ref)
    return Measurement(lag, "s", f"mean error {d['mean_error']:.4g} {s.unit} on a ramp of "
                       f"{d['slope_per_s']:.4g} {s.unit}/s", d)


def _m_ripple(ctx: CheckContext) -> Measurement:
    s = ctx.main
    v = ripple(s.t_s, s.values, ctx.arg("measure"), ctx.arg("detrend"))
    return Measurement(v, s.unit, details={"mean": float(np.mean(s.values)), "min": float(np.min(s.values)),
                                           "max": float(np.max(s.values)),
                                           "measure": ctx.arg("measure"), "detrend": ctx.arg("detrend")})


def _m_thd(ctx: CheckContext) -> Measurement:
    s = ctx.main
    v, details = thd_percent(s.t_s, s.values, ctx.arg("fundamental_hz"), ctx.arg("harmonics"),
                             ctx.arg("method"))
    return Measurement(v, "%", f"fundamental {details['fundamental_hz']:.4g} Hz, amplitude "
                       f"{details['fundamental_amplitude']:.4g} {s.unit}", details)


def _m_circularity(ctx: CheckContext) -> Measurement:
    a, b = ctx.sig["alpha"], ctx.sig["beta"].to_unit(ctx.sig["alpha"].unit)
    v, details = circularity_percent(a.values, b.resampled(a.t_s), ctx.arg("centre"), ctx.arg("measure"))
    details["signal_unit"] = a.unit
    details["measure"] = ctx.arg("measure")
    return Measurement(v, "%", f"mean radius {details['r_mean']:.4g} {a.unit}, "
                       f"{details['r_min']:.4g} .. {details['r_max']:.4g}", details)


def _m_compare(ctx: CheckContext) -> Measurement:
    a_name, b_name = ctx.arg("a"), ctx.arg("b")
    for name in (a_name, b_name):
        r = ctx.results.get(name)
        if r is None:
            raise CheckError(f"check '{name}' has no result yet")
        if (r.measured is None or not math.isfinite(r.measured)) and r.outcome is Outcome.FAIL:
            raise DependencyFailed(f"check '{name}' failed without a measured value: {r.message}")
        if r.measured is None or not math.isfinite(r.measured):
            raise CheckError(f"check '{name}' has no finite measured value ({r.outcome.value})")
    a, b = ctx.results[a_name], ctx.results[b_name]
    if not compatible(a.unit, b.unit):
        raise CheckError(f"cannot compare '{a_name}' in {a.unit} with '{b_name}' in {b.unit}")
    b_value = float(convert(b.measured, b.unit, a.unit))
    if ctx.arg("operation") == "ratio":
        if b_value == 0:
            raise CheckError(f"check '{b_name}' measured 0: the ratio is undefined")
        return Measurement(a.measured / b_value, "1",
                           f"{a.measured:.4g} {a.unit} / {b_value:.4g} {a.unit}")
    return Measurement(a.measured - b_value, a.unit,
                       f"{a.measured:.4g} {a.unit} - {b_value:.4g} {a.unit}")


_TARGET = ArgSpec("quantity", doc="the value the signal steps to; default the mean of the "
                                  "window's last 10 %")
_INITIAL = ArgSpec("quantity", doc="the value the signal steps from; default its first sample "
                                   "in the window")
_MAIN = Role("signal", doc="the signal measured")
_REF_SIGNAL = Role("reference", doc="the signal it is compared with (truth)")
_REF_EITHER = Role("reference", allow_quantity=True,
                   doc="a signal, or a constant {value, unit}")

CHECK_KINDS: dict[str, CheckKind] = {k.name: k for k in (
    CheckKind("final_value", (_MAIN,), {
        "average_s": ArgSpec("nonneg", default=0.0, doc="average over the window's last seconds; "
                                                         "0 = the last sample"),
    }, _m_final_value, "signal", "The signal's final value (optionally averaged) within limits."),
    CheckKind("settling_time", (_MAIN,), {
        "target": _TARGET, "initial": _INITIAL,
        "band_pct": ArgSpec("positive", default=2.0, doc="band half-width in % of |target - initial|"),
        "band": ArgSpec("quantity", doc="absolute band half-width instead of band_pct"),
    }, _m_settling, "s", "Time from the window start until the signal stays within the band "
                          "around target (inf if never).", min_samples=2),
    CheckKind("rise_time", (_MAIN,), {
        "target": _TARGET, "initial": _INITIAL,
        "from_pct": ArgSpec("nonneg", default=10.0), "to_pct": ArgSpec("positive", default=90.0),
    }, _m_rise, "s", "Time to go from from_pct to to_pct of the step (first crossings).",
        min_samples=2),
    CheckKind("overshoot", (_MAIN,), {"target": _TARGET, "initial": _INITIAL},
              _m_overshoot, "%", "Peak beyond target in % of the step (0 if none)."),
    CheckKind("steady_state_error", (_MAIN, _REF_EITHER), {},
              _m_steady_state_error, "signal", "Mean of signal - reference over the window "
                                                "(angles wrapped)."),
    CheckKind("bound", (_MAIN,), {}, _m_bound, "signal",
              "Every sample within limits: the minimum and maximum over the window are judged."),
    CheckKind("statistic", (_MAIN,), {
        "statistic": ArgSpec("choice", required=True, choices=STATISTICS),
    }, _m_statistic, "signal", "A statistic of the signal over the window."),
    CheckKind("envelope", (_MAIN, _REF_EITHER), {
        "tolerance": ArgSpec("quantity", required=True, doc="value tolerance either side"),
        "time_tolerance_s": ArgSpec("nonneg", default=0.0, doc="time tolerance either side"),
    }, _m_envelope, "signal", "Largest excursion outside the reference's tube (value and time "
                              "tolerance); limits default to 0 in the signal's unit.",
        limits_required=False, min_samples=2),
    CheckKind("rms_error", (_MAIN, _REF_SIGNAL), {
        "wrap": ArgSpec("bool", doc="wrap the difference to a half turn; default: if an angle"),
    }, _m_rms_error, "signal", "RMS of signal - reference (angles wrapped)."),
    CheckKind("peak_error", (_MAIN, _REF_SIGNAL), {
        "wrap": ArgSpec("bool", doc="wrap the difference to a half turn; default: if an angle"),
    }, _m_peak_error, "signal", "Largest |signal - reference| (angles wrapped)."),
    CheckKind("lag", (_MAIN, _REF_SIGNAL), {
        "max_lag_s": ArgSpec("positive", default=0.02, doc="search range either side"),
    }, _m_lag, "s", "Delay of the signal behind the reference by normalised cross-correlation "
                     "(positive = later).", min_samples=4),
    CheckKind("ramp_lag", (_MAIN, _REF_SIGNAL), {}, _m_ramp_lag, "s",
              "Delay behind a ramping reference, -mean(signal - reference) / its slope "
              "(positive = later).", min_samples=3),
    CheckKind("ripple", (_MAIN,), {
        "measure": ArgSpec("choice", default="peak_to_peak", choices=("peak_to_peak", "rms")),
        "detrend": ArgSpec("choice", default="mean", choices=("mean", "linear")),
    }, _m_ripple, "signal", "Peak-to-peak or RMS ripple about the mean (or a fitted line).",
        min_samples=2),
    CheckKind("thd", (_MAIN,), {
        "fundamental_hz": ArgSpec("positive", doc="default: the strongest spectral line"),
        "harmonics": ArgSpec("integer", default=40, doc="highest harmonic counted"),
        "method": ArgSpec("choice", default="harmonics", choices=("harmonics", "total")),
    }, _m_thd, "%", "Total harmonic distortion relative to the fundamental, whole cycles.",
        min_samples=8),
    CheckKind("circularity", (Role("alpha", doc="x of the locus"), Role("beta", doc="y of the locus")), {
        "centre": ArgSpec("choice", default="origin", choices=("origin", "fit")),
        "measure": ArgSpec("choice", default="peak_to_peak", choices=("peak_to_peak", "rms")),
    }, _m_circularity, "%", "Radius spread of a locus over its mean radius.", min_samples=3),
    CheckKind("compare", (), {
        "a": ArgSpec("check", required=True, doc="an earlier check"),
        "b": ArgSpec("check", required=True, doc="another earlier check"),
        "operation": ArgSpec("choice", default="ratio", choices=("ratio", "difference")),
    }, _m_compare, "compare", "a / b or a - b of two earlier checks' measured values, for claims "
                              "such as 'the EKF lags less than the filter'."),
)}


def result_unit(kind: CheckKind, role_units: Mapping[str, str]) -> str | None:
    """The unit a kind measures in, given its roles' units (None: known only at run time)."""
    if kind.result_unit == "signal":
        return role_units.get("signal")
    if kind.result_unit == "compare":
        return None
    return kind.result_unit


# --------------------------------------------------------------------------- #
# Evaluation                                                                   #
# --------------------------------------------------------------------------- #

class DependencyFailed(CheckError):
    """A check built on another check's value, which failed on the board's account."""


def _unreported(windows: dict) -> str:
    """The board's signals (ctrl.*) with NaN in their window (SPEC 6.5: not computed), named;
    '' if none."""
    names = []
    for w in windows.values():
        name = getattr(w, "name", "")
        values = getattr(w, "values", None)
        if str(name).startswith("ctrl.") and values is not None and len(values) \
                and bool(np.isnan(values).any()):
            names.append(str(name))
    return ", ".join(names)


def evaluate_check(spec: "CheckStep", signals: SignalSet, marks: Mapping[str, float],
                   now_s: float | None = None,
                   results: Mapping[str, CheckResult] | None = None,
                   profile: str | None = None) -> CheckResult:
    """Measures one check over the recorded signals and judges it.

    marks: named times the runner recorded (``start`` is 0). now_s: the
    simulated time the check step was reached, the default end of its window
    (default: the end of the recording). results: earlier checks by name, for
    ``compare``. profile: the label of the profile the plan ran on, which
    picks the check's ``profile_limits`` entry if it has one. A ``role:
    finding`` check is measured and recorded with outcome INFO, never judged
    (its limits, if any, are a claim reported as holding or not). Never
    raises for bad data: a check that cannot be computed is an ERROR result
    whose message names the plan file, line and cause.
    """
    kind = CHECK_KINDS[spec.check_kind]
    where = f"{spec.source}:{spec.line}: check '{spec.name}'"
    check_role = getattr(spec, "role", "acceptance")
    note = getattr(spec, "note", "")
    if hasattr(spec, "role_for"):
        check_role, note = spec.role_for(profile)
    spec_limits = spec.limits_for(profile) if hasattr(spec, "limits_for") else spec.limits
    formulas = ({k: d.to_json() for k, d in spec.derivations_for(profile).items()}
                if hasattr(spec, "derivations_for") else {})
    unit = spec_limits.unit if spec_limits is not None else (kind.result_unit
                                                             if kind.result_unit not in ("signal", "compare") else "1")
    window: tuple[float, float] | None = None

    def error(message: str) -> CheckResult:
        return CheckResult(spec.name, spec.check_kind, Outcome.ERROR, None, unit, spec_limits,
                           f"{where}: {message}", window, spec.signals, spec.line, plot=spec.plot,
                           role=check_role, note=note, formulas=formulas)

    def board_verdict(message: str) -> CheckResult:
        """The board did not give what the check needs: FAIL (INFO for a finding)."""
        outcome = Outcome.INFO if check_role == "finding" else Outcome.FAIL
        return CheckResult(spec.name, spec.check_kind, outcome, None, unit, spec_limits,
                           f"{where}: {message}", window, spec.signals, spec.line, plot=spec.plot,
                           role=check_role, note=note, formulas=formulas)

    now = signals.end_s if now_s is None else float(now_s)
    try:
        window = spec.window.resolve(marks, now) if spec.window is not None else (0.0, now)
    except KeyError as exc:
        return error(f"mark {exc} was not recorded before this check")
    t0, t1 = window
    if not t1 > t0:
        return error(f"empty window [{t0:.6f}, {t1:.6f}] s")

    sig: dict[str, Signal] = {}
    full: dict[str, Signal] = {}
    const: dict[str, Quantity] = {}
    for role in kind.roles:
        ref = spec.roles.get(role.key)
        if ref is None:
            continue
        if isinstance(ref, Quantity):
            const[role.key] = ref
            continue
        try:
            s = signals[ref]
        except MissingSignalError as exc:
            return error(str(exc))
        if len(s) >= 2:
            dt = float(s.t_s[-1] - s.t_s[-2])
            if t1 > s.t_s[-1] + 1.5 * dt:
                return error(f"window [{t0:.6f}, {t1:.6f}] s ends after the recording of '{ref}' "
                             f"(last sample {s.t_s[-1]:.6f} s): put the check after the steps "
                             f"that produce its data")
        w = s.window(t0, t1)
        if len(w) < kind.min_samples:
            return error(f"window [{t0:.6f}, {t1:.6f}] s holds {len(w)} sample(s) of '{ref}'; "
                         f"{kind.name} needs at least {kind.min_samples}")
        full[role.key] = s
        sig[role.key] = w

    ctx = CheckContext(spec, window, sig, full, const, dict(spec.args), results or {})
    try:
        m = kind.measure(ctx)
    except DependencyFailed as exc:
        return board_verdict(str(exc))
    except (CheckError, UnitError, ValueError, ArithmeticError) as exc:
        if _unreported(sig):        # garbage in from the board: its verdict, not a plan error
            return board_verdict(f"the board reports no value for {_unreported(sig)} in the "
                                 f"window (NaN: not computed by this board): {exc}")
        return error(str(exc))

    limits = spec_limits
    if limits is None and check_role == "finding":
        details = dict(m.details)
        details["measured_native"] = m.value
        details["native_unit"] = m.unit
        if math.isnan(m.value) and _unreported(sig):
            return CheckResult(spec.name, spec.check_kind, Outcome.INFO, None, m.unit, None,
                               f"finding: the board reports no value for {_unreported(sig)} "
                               f"in the window (NaN: not computed by this board)", window,
                               spec.signals, spec.line, details, plot=spec.plot,
                               role=check_role, note=note, formulas=formulas)
        if math.isnan(m.value):
            return error(m.message or "the measurement is not a number")
        shown = "inf" if math.isinf(m.value) else f"{m.value:.6g}"
        u = "" if m.unit == "1" else f" {m.unit}"
        message = f"finding: measured {shown}{u}" + (f"; {m.message}" if m.message else "")
        return CheckResult(spec.name, spec.check_kind, Outcome.INFO, m.value, m.unit, None, message,
                           window, spec.signals, spec.line, details, plot=spec.plot,
                           role=check_role, note=note, formulas=formulas)
    if limits is None:
        # Only kinds whose limits are optional get here (envelope: nothing outside the tube).
        limits = Limits(m.unit, high=0.0)
    unit = limits.unit
    details = dict(m.details)
    details["measured_native"] = m.value
    details["native_unit"] = m.unit
    if math.isnan(m.value):
        unreported = _unreported(sig)
        if unreported:
            # What the board sent is NaN (SPEC 6.5: a value it does not compute): the board
            # does not meet the check; the plan and the bench did their part.
            return CheckResult(spec.name, spec.check_kind, Outcome.FAIL, None, unit, limits,
                               f"{where}: the board reports no value for {unreported} in the "
                               f"window (NaN: not computed by this board)", window,
                               spec.signals, spec.line, details, plot=spec.plot,
                               role=check_role, note=note, formulas=formulas)
        return error(m.message or "the measurement is not a number")
    try:
        measured = limits.to_limit_unit(m.value, m.unit)
    except UnitError as exc:
        return error(f"limits in {limits.unit} do not fit a measurement in {m.unit}: {exc}")
    outcome = limits.judge(measured)
    shown = "inf" if math.isinf(measured) else f"{measured:.6g}"
    u = "" if unit == "1" else f" {unit}"
    if check_role == "finding":
        holds = outcome is not Outcome.FAIL
        details["claim_holds"] = holds
        message = (f"finding: measured {shown}{u}; the claim {limits.describe()} "
                   f"{'holds' if holds else 'does not hold'}")
        outcome = Outcome.INFO
    else:
        verdict = {Outcome.PASS: "within", Outcome.MARGINAL: "within (marginal)",
                   Outcome.FAIL: "outside"}[outcome]
        message = f"measured {shown}{u}, {verdict} limits {limits.describe()}"
        if check_role == "regression":
            message += " (regression bound)"
    if m.message:
        message += f"; {m.message}"
    return CheckResult(spec.name, spec.check_kind, outcome, measured, unit, limits, message,
                       window, spec.signals, spec.line, details, plot=spec.plot,
                       role=check_role, note=note, formulas=formulas)


__all__ = ["CheckError", "CheckKind", "ArgSpec", "Role", "Measurement", "CheckContext",
           "CHECK_KINDS", "STATISTICS", "evaluate_check", "result_unit",
           "final_value", "settling_time", "rise_time", "rise_crossings", "overshoot_percent", "statistic",
           "envelope_excursion", "error_between", "lag_s", "ramp_lag_s", "ripple", "estimate_fundamental_hz",
           "thd_percent", "circularity_percent"]
