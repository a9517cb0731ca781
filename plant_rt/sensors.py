"""Sensors as the controller board's converters read them: ADC counts and an encoder counter.

Current and DC-link channels: transducer (gain, bias) -> ADC: counts = offset_counts +
(gain * x + bias) / units_per_count + noise, rounded to the nearest code and saturated to
0 .. 2^bits - 1; a stuck channel returns its stuck code. The paper measures two phase currents
(eq. (8)-(9)); which two is configurable (ab, ac, bc as HIL_PARAM_CURRENT_PHASES 0, 1, 2).

Encoder: incremental quadrature, 4 counts per line, counter = floor(theta_m * counts_per_rev /
2 pi) + offset, wrapping at 2^counter_bits, increasing for positive rotation (alpha towards
beta); count 0 and the index pulse at theta_m = 0.

Noise is Gaussian in counts, one seeded stream per channel (numpy PCG64 drawn in blocks, so the
per-sample cost is a list lookup and changing one channel's noise never shifts another's).
Every channel attribute may be changed while the plant runs (fault injection).

Faults (hil/faults/injector.py switches them): an ADC channel may be stuck at a code or saturate inside a
window [low, high] of codes narrower than the converter's; an encoder may be frozen, lose a
fraction of its edges (the lost counts accumulate, as a real counter's would), jitter by a
Gaussian number of counts (spurious edges that a quadrature decoder counts forward and back,
so they do not accumulate), or lose its index pulse. A channel without any of these takes the
plain path: one flag test, the same cost as before faults existed.
"""
from __future__ import annotations

import math
import random
from dataclasses import field
from typing import NamedTuple

import numpy as np

from configfile.dataclass_methods import dataclass
from configfile.fields import param
from plant_rt.sensor_params import (
    CURRENT_PLACEMENTS, HallParams, ResolverParams, TemperatureSensorParams, TerminalParams,
)

STATUS_INDEX_PULSE = 0x01
STATUS_OVERCURRENT = 0x02
STATUS_OVERVOLTAGE = 0x04
STATUS_GATE_FAULT = 0x08

PHASE_PAIRS = {"ab": (0, 1), "ac": (0, 2), "bc": (1, 2)}
_S32 = 0.5 * math.sqrt(3.0)
_INV_2PI = 1.0 / (2.0 * math.pi)
_new_sample = tuple.__new__
_floor = math.floor


class SensorSample(NamedTuple):
    """One SAMPLE: what the board reads at t_k = k T (protocol hil_sample)."""

    period: int
    adc_i1: int
    adc_i2: int
    adc_vdc: int
    encoder: int
    status: int


@dataclass(frozen=True)
class CurrentSensorParams:
    """The phase-current channels (SAMPLE's two, a sensor set's three): transducer and ADC;
    placement of the three shunts, inline (always the phase current) or low_side."""

    phases: str = param("ab", choices=tuple(PHASE_PAIRS))
    placement: str = param("inline", choices=CURRENT_PLACEMENTS)
    bits: int = param(12, ge=1, le=16)
    a_per_count: float = param(0.01220703125, gt=0)   # 25 A / 2048
    offset_counts: float = param(2048.0)
    gain: float = param(1.0)
    noise_rms_counts: float = param(0.5, ge=0)


@dataclass(frozen=True)
class VoltageSensorParams:
    """The DC-link voltage channel: transducer and ADC."""

    bits: int = param(12, ge=1, le=16)
    v_per_count: float = param(0.0244140625, gt=0)    # 100 V / 4096
    offset_counts: float = param(0.0)
    gain: float = param(1.0)
    noise_rms_counts: float = param(0.5, ge=0)


@dataclass(frozen=True)
class EncoderParams:
    """The incremental encoder and its counter."""

    lines_per_rev: int = param(1024, ge=1)
    counter_bits: int = param(16, ge=2, le=32)
    offset_counts: int = param(0)


@dataclass(frozen=True)
class SensorParams:
    """The profile's sensors section."""

    current: CurrentSensorParams = field(default_factory=CurrentSensorParams)
    dc_voltage: VoltageSensorParams = field(default_factory=VoltageSensorParams)
    encoder: EncoderParams = field(default_factory=EncoderParams)
    hall: HallParams = field(default_factory=HallParams)
    terminal: TerminalParams = field(default_factory=TerminalParams)
    resolver: ResolverParams = field(default_factory=ResolverParams)
    temperature: TemperatureSensorParams = field(default_factory=TemperatureSensorParams)
    overcurrent_trip_a: float = param(20.0, gt=0)
    overvoltage_trip_v: float = param(90.0, gt=0)


class GaussianNoise:
    """Standard normal draws from a seeded stream, generated in blocks."""

    __slots__ = ("_rng",)
    BLOCK = 4096

    def __init__(self, seed: int, stream: int):
        self._rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, stream])))

    def block(self) -> list[float]:
        return self._rng.standard_normal(self.BLOCK).tolist()


class AdcChannel:
    """Transducer plus ADC. `offset` (units) and `gain` model transducer errors; `stuck_counts`
    (None or a code) a frozen converter. Every attribute may be set while running."""

    __slots__ = ("_units_per_count", "_offset_counts", "_bits", "_gain", "_offset",
                 "noise_rms_counts", "_stuck", "_window", "_plain", "_noise", "_buf", "_i",
                 "_base", "_scale", "_top", "_extra")

    def __init__(self, units_per_count: float, offset_counts: float, bits: int, gain: float,
                 noise_rms_counts: float, noise: GaussianNoise):
        self._units_per_count = units_per_count
        self._offset_counts = offset_counts
        self._bits = bits
        self._gain = gain
        self._offset = 0.0
        self.noise_rms_counts = noise_rms_counts
        self._stuck: int | None = None
        self._window: tuple[int, int] | None = None   # saturation codes (low, high)
        self._plain = True
        self._extra: tuple | None = None    # what set_extra_noise replaced
        self._noise = noise
        self._buf: list[float] = []
        self._i = 0
        self._derive()

    def _derive(self) -> None:
        # counts = base + scale * value: two operations per sample instead of five.
        self._scale = self._gain / self._units_per_count
        self._base = self._offset_counts + self._offset / self._units_per_count
        self._top = (1 << self._bits) - 1

    def _setter(name: str):  # noqa: N805 - builds properties below
        def get(self):
            return getattr(self, name)

        def put(self, value):
            setattr(self, name, value)
            self._derive()
        return property(get, put)

    units_per_count = _setter("_units_per_count")
    offset_counts = _setter("_offset_counts")
    bits = _setter("_bits")
    gain = _setter("_gain")
    offset = _setter("_offset")
    del _setter

    @property
    def max_code(self) -> int:
        return self._top

    @property
    def stuck_counts(self) -> int | None:
        """None, or the code a frozen converter returns whatever its input."""
        return self._stuck

    @stuck_counts.setter
    def stuck_counts(self, code: int | None) -> None:
        self._stuck = None if code is None else int(code)
        self._plain = self._stuck is None and self._window is None

    @property
    def saturation(self) -> tuple[int, int] | None:
        """None, or (low, high): codes clamped to this window (a transducer or amplifier that
        saturates before the converter does)."""
        return self._window

    @saturation.setter
    def saturation(self, window: tuple[int, int] | None) -> None:
        if window is not None:
            low, high = int(window[0]), int(window[1])
            if not 0 <= low <= high <= self._top:
                raise ValueError(f"saturation window must satisfy 0 <= low <= high <= "
                                 f"{self._top}, got ({low}, {high})")
            window = (low, high)
        self._window = window
        self._plain = self._stuck is None and self._window is None

    def set_extra_noise(self, std_counts: float, seed: int | None = None) -> None:
        """Adds Gaussian noise of std_counts rms (in quadrature with the channel's own). With a
        seed it comes from a stream of its own; the channel's stream resumes where it was once
        clear_extra_noise() lifts it."""
        std_counts = float(std_counts)
        if not std_counts >= 0.0 or not math.isfinite(std_counts):
            raise ValueError(f"extra noise must be a finite number >= 0, got {std_counts!r}")
        if self._extra is None:
            self._extra = (self.noise_rms_counts, self._noise, self._buf, self._i, seed is not None)
        base = self._extra[0]
        self.noise_rms_counts = math.hypot(base, std_counts)
        if seed is not None:
            self._extra = self._extra[:4] + (True,)
            self._noise = GaussianNoise(seed, 8)
            self._buf, self._i = [], 0

    def clear_extra_noise(self) -> None:
        if self._extra is None:
            return
        rms, noise, buf, i, swapped = self._extra
        self.noise_rms_counts = rms
        if swapped:
            self._noise, self._buf, self._i = noise, buf, i
        self._extra = None

    def _faulty(self, x: float) -> int:
        if self._stuck is not None:
            return self._stuck
        code = int(x + 0.5)
        low, high = self._window
        return low if code < low else high if code > high else code

    def convert(self, value: float) -> int:
        """The code for a physical value (consumes one noise draw when noise is on)."""
        return _code(self, value)

    def to_units(self, code: float) -> float:
        """Inverse of the nominal scaling (what a board computes from a code)."""
        return (code - self._offset_counts) * self._units_per_count


def _code(ch: AdcChannel, value: float) -> int:
    x = ch._base + ch._scale * value
    sd = ch.noise_rms_counts
    if sd:
        i = ch._i
        buf = ch._buf
        if i >= len(buf):
            buf = ch._buf = ch._noise.block()
            i = 0
        x += sd * buf[i]
        ch._i = i + 1
    if not ch._plain:
        return ch._faulty(x)
    # int() truncates towards zero; negative codes are clamped to 0 anyway.
    code = int(x + 0.5)
    top = ch._top
    return 0 if code < 0 else top if code > top else code


class Encoder:
    """Incremental encoder counter. `stuck_counts` freezes it, `invert` reverses the direction;
    `set_missing_counts`, `set_noise` and `index_missing` are faults (module docstring)."""

    __slots__ = ("counts_per_rev", "counter_bits", "_offset", "_stuck", "_invert", "_plain",
                 "_missing_fraction", "_missing_rng", "_lost", "_last_position", "_noise_sd",
                 "_noise", "_noise_buf", "_noise_i", "_index_missing")

    def __init__(self, params: EncoderParams):
        self.counts_per_rev = 4 * params.lines_per_rev
        self.counter_bits = params.counter_bits
        self._offset = params.offset_counts
        self._stuck: int | None = None
        self._invert = False
        self._missing_fraction = 0.0
        self._missing_rng: random.Random | None = None
        self._lost = 0
        self._last_position: int | None = None
        self._noise_sd = 0.0
        self._noise: GaussianNoise | None = None
        self._noise_buf: list[float] = []
        self._noise_i = 0
        self._index_missing = False
        self._plain = True

    def _update(self) -> None:
        self._plain = (self._stuck is None and not self._invert and not self._missing_fraction
                       and not self._lost and not self._noise_sd and not self._index_missing)

    @property
    def offset_counts(self) -> int:
        return self._offset

    @offset_counts.setter
    def offset_counts(self, value: int) -> None:
        self._offset = int(value)

    @property
    def stuck_counts(self) -> int | None:
        return self._stuck

    @stuck_counts.setter
    def stuck_counts(self, value: int | None) -> None:
        self._stuck = None if value is None else int(value)
        self._update()

    @property
    def invert(self) -> bool:
        return self._invert

    @invert.setter
    def invert(self, value: bool) -> None:
        self._invert = bool(value)
        self._update()

    @property
    def index_missing(self) -> bool:
        """True: the index pulse never reaches the board (SAMPLE status bit INDEX_PULSE)."""
        return self._index_missing

    @index_missing.setter
    def index_missing(self, value: bool) -> None:
        self._index_missing = bool(value)
        self._update()

    @property
    def lost_counts(self) -> int:
        """Edges lost so far by the missing-counts fault (signed: in the direction of motion)."""
        return self._lost

    def set_missing_counts(self, fraction: float, seed: int = 0) -> None:
        """Each edge is lost with probability ``fraction`` (0 lifts it; the counts already lost
        stay lost, as in a real counter, until `reset_lost_counts`)."""
        fraction = float(fraction)
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"missing-counts fraction must be in [0, 1], got {fraction}")
        self._missing_fraction = fraction
        self._missing_rng = random.Random(f"encoder-missing:{seed}") if fraction else None
        self._last_position = None
        self._update()

    def reset_lost_counts(self) -> None:
        self._lost = 0
        self._update()

    def set_noise(self, std_counts: float, seed: int = 0) -> None:
        """Gaussian jitter of ``std_counts`` rms, rounded to whole counts (0 lifts it)."""
        std_counts = float(std_counts)
        if not std_counts >= 0.0:
            raise ValueError(f"encoder noise must be >= 0 counts rms, got {std_counts}")
        self._noise_sd = std_counts
        self._noise = GaussianNoise(seed, 4) if std_counts else None
        self._noise_buf, self._noise_i = [], 0
        self._update()

    def position(self, revs: int, theta_m: float) -> int:
        """Unwrapped count of the angle revs * 2 pi + theta_m."""
        cpr = self.counts_per_rev
        return revs * cpr + math.floor(theta_m * cpr * _INV_2PI)

    def read(self, position: int) -> int:
        if self._plain:
            return (position + self._offset) & ((1 << self.counter_bits) - 1)
        return self._faulty(position)

    def _faulty(self, position: int) -> int:
        """The counter with the active faults (one call per sample)."""
        if self._stuck is not None:
            return self._stuck
        f = self._missing_fraction
        if f:
            last = self._last_position
            if last is not None and position != last:
                edges = position - last
                rnd = self._missing_rng.random
                lost = sum(1 for _ in range(abs(edges)) if rnd() < f)
                self._lost += lost if edges > 0 else -lost
            self._last_position = position
        position -= self._lost
        if self._noise_sd:
            i = self._noise_i
            if i >= len(self._noise_buf):
                self._noise_buf, i = self._noise.block(), 0
            position += int(round(self._noise_sd * self._noise_buf[i]))
            self._noise_i = i + 1
        if self._invert:
            position = -position
        return (position + self._offset) & ((1 << self.counter_bits) - 1)


class Sensors:
    """The board's view: i1, i2 (two phase currents), vdc and the encoder. The sensor-set
    models (plant_rt.sensor_set: phase_currents, hall, terminal, resolver, temperature) are
    attached by the plant, so their faults sit beside these (sensors.hall.stuck[x])."""

    __slots__ = ("params", "i1", "i2", "vdc", "encoder", "overcurrent_trip_a",
                 "overvoltage_trip_v", "_pair", "phase_currents", "hall", "terminal", "resolver",
                 "temperature")

    def __init__(self, params: SensorParams, seed: int):
        cur, vol = params.current, params.dc_voltage
        self.params = params
        self.i1 = AdcChannel(cur.a_per_count, cur.offset_counts, cur.bits, cur.gain,
                             cur.noise_rms_counts, GaussianNoise(seed, 1))
        self.i2 = AdcChannel(cur.a_per_count, cur.offset_counts, cur.bits, cur.gain,
                             cur.noise_rms_counts, GaussianNoise(seed, 2))
        self.vdc = AdcChannel(vol.v_per_count, vol.offset_counts, vol.bits, vol.gain,
                              vol.noise_rms_counts, GaussianNoise(seed, 3))
        self.encoder = Encoder(params.encoder)
        self.overcurrent_trip_a = params.overcurrent_trip_a
        self.overvoltage_trip_v = params.overvoltage_trip_v
        self._pair = PHASE_PAIRS[cur.phases]
        self.phase_currents = self.hall = self.terminal = self.resolver = None
        self.temperature = None

    @property
    def phases(self) -> str:
        return next(k for k, v in PHASE_PAIRS.items() if v == self._pair)

    @phases.setter
    def phases(self, value: str) -> None:
        if value not in PHASE_PAIRS:
            raise ValueError(f"phases must be one of {', '.join(PHASE_PAIRS)}, got {value!r}")
        self._pair = PHASE_PAIRS[value]

    def read(self, period: int, ia: float, ib: float, v_dc: float, revs: int, theta_m: float,
             status: int) -> SensorSample:
        """The sample for currents (i_alpha, i_beta), bus voltage and angle revs*2pi + theta_m."""
        i_a = ia
        i_b = -0.5 * ia + _S32 * ib
        i_c = -0.5 * ia - _S32 * ib
        trip = self.overcurrent_trip_a
        if not (-trip <= i_a <= trip and -trip <= i_b <= trip and -trip <= i_c <= trip):
            status |= STATUS_OVERCURRENT
        if v_dc > self.overvoltage_trip_v:
            status |= STATUS_OVERVOLTAGE
        x, y = self._pair
        c1 = _code(self.i1, i_a if x == 0 else i_b)
        c2 = _code(self.i2, i_b if y == 1 else i_c)
        c3 = _code(self.vdc, v_dc)
        enc = self.encoder
        cpr = enc.counts_per_rev
        position = revs * cpr + _floor(theta_m * cpr * _INV_2PI)
        if enc._plain:
            count = (position + enc._offset) & ((1 << enc.counter_bits) - 1)
        else:
            count = enc._faulty(position)
            if enc._index_missing:
                status &= ~STATUS_INDEX_PULSE
        return _new_sample(SensorSample, (period, c1, c2, c3, count, status))
