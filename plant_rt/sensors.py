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
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from plant_rt.spec import param

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
    phases: str = param("ab", choices=tuple(PHASE_PAIRS))
    bits: int = param(12, ge=1, le=16)
    a_per_count: float = param(0.01220703125, gt=0)   # 25 A / 2048
    offset_counts: float = param(2048.0)
    gain: float = param(1.0)
    noise_rms_counts: float = param(0.5, ge=0)


@dataclass(frozen=True)
class VoltageSensorParams:
    bits: int = param(12, ge=1, le=16)
    v_per_count: float = param(0.0244140625, gt=0)    # 100 V / 4096
    offset_counts: float = param(0.0)
    gain: float = param(1.0)
    noise_rms_counts: float = param(0.5, ge=0)


@dataclass(frozen=True)
class EncoderParams:
    lines_per_rev: int = param(1024, ge=1)
    counter_bits: int = param(16, ge=2, le=32)
    offset_counts: int = param(0)


@dataclass(frozen=True)
class SensorParams:
    current: CurrentSensorParams = field(default_factory=CurrentSensorParams)
    dc_voltage: VoltageSensorParams = field(default_factory=VoltageSensorParams)
    encoder: EncoderParams = field(default_factory=EncoderParams)
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
                 "noise_rms_counts", "stuck_counts", "_noise", "_buf", "_i", "_base", "_scale",
                 "_top")

    def __init__(self, units_per_count: float, offset_counts: float, bits: int, gain: float,
                 noise_rms_counts: float, noise: GaussianNoise):
        self._units_per_count = units_per_count
        self._offset_counts = offset_counts
        self._bits = bits
        self._gain = gain
        self._offset = 0.0
        self.noise_rms_counts = noise_rms_counts
        self.stuck_counts: int | None = None
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
    if ch.stuck_counts is not None:
        return ch.stuck_counts
    # int() truncates towards zero; negative codes are clamped to 0 anyway.
    code = int(x + 0.5)
    top = ch._top
    return 0 if code < 0 else top if code > top else code


class Encoder:
    """Incremental encoder counter. `stuck_counts` freezes it, `invert` reverses the direction."""

    __slots__ = ("counts_per_rev", "counter_bits", "offset_counts", "stuck_counts", "invert")

    def __init__(self, params: EncoderParams):
        self.counts_per_rev = 4 * params.lines_per_rev
        self.counter_bits = params.counter_bits
        self.offset_counts = params.offset_counts
        self.stuck_counts: int | None = None
        self.invert = False

    def position(self, revs: int, theta_m: float) -> int:
        """Unwrapped count of the angle revs * 2 pi + theta_m."""
        cpr = self.counts_per_rev
        return revs * cpr + math.floor(theta_m * cpr * _INV_2PI)

    def read(self, position: int) -> int:
        if self.stuck_counts is not None:
            return self.stuck_counts
        value = (-position if self.invert else position) + self.offset_counts
        return value & ((1 << self.counter_bits) - 1)


class Sensors:
    """The board's view: i1, i2 (two phase currents), vdc and the encoder."""

    __slots__ = ("params", "i1", "i2", "vdc", "encoder", "overcurrent_trip_a",
                 "overvoltage_trip_v", "_pair")

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
        if enc.stuck_counts is not None:
            count = enc.stuck_counts
        else:
            cpr = enc.counts_per_rev
            position = revs * cpr + _floor(theta_m * cpr * _INV_2PI)
            if enc.invert:
                position = -position
            count = (position + enc.offset_counts) & ((1 << enc.counter_bits) - 1)
        return _new_sample(SensorSample, (period, c1, c2, c3, count, status))
