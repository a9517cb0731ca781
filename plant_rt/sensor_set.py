"""Sensor sets (SPEC 1.1): what a board that declares SENSOR_SET reads besides today's SAMPLE.
three phase currents (inline or low-side shunts), Hall sensors, phase terminal voltages with
BEMF comparators, a resolver and the winding temperature, as ADC counts and bits.

Each model is a class with its state in plain attributes; the plant (Plant.sensor_frame) hands
them its state at t_k and assembles a SensorFrame. Every ADC channel is a
plant_rt.sensors.AdcChannel with a seeded noise stream of its own (stream ids below, apart from
SAMPLE's), so a plant that never builds a frame draws exactly the noise it drew before.

Angles: theta_e = p theta_m, theta_e = 0 with the magnet's d-axis on phase a; phase x's axis at
n_x 120 deg (n_a, n_b, n_c = 0, 1, 2). Currents in SPEC sign (positive into the motor).
"""
from __future__ import annotations

import math
from math import cos, sin
from typing import NamedTuple

from plant_rt.circuit import ZERO_CURRENT_A
from plant_rt.inverter import ALL_LEGS, H, L, LEG_BITS, Command, leg_states
from plant_rt.sensor_params import HallParams, ResolverParams, TemperatureSensorParams, TerminalParams
from plant_rt.sensors import (
    AdcChannel, CurrentSensorParams, GaussianNoise, SensorParams, SensorSample, _code,
)

TWO_PI_3 = 2.0 * math.pi / 3.0
_new_frame = tuple.__new__      # a NamedTuple from a tuple without its __new__'s argument parsing
_LEG_STATES = tuple(leg_states(g) for g in range(64))

#: Noise stream ids of the sensor-set channels (plant_rt.sensors uses 1 to 4 and 8).
STREAM_PHASE_CURRENTS = (16, 17, 18)
STREAM_TERMINAL_VOLTAGES = (19, 20, 21)
STREAM_RESOLVER = (22, 23)
STREAM_TEMPERATURE = 24


class SensorFrame(NamedTuple):
    """Every sensor at t_k = k T: the fields of protocol SampleSensors but sensor_set (the
    bench picks the set's fields). period, status, adc_vdc and encoder are Plant.sample()'s."""

    period: int
    status: int
    adc_ia: int
    adc_ib: int
    adc_ic: int
    adc_vdc: int
    encoder: int
    hall: int
    adc_va: int
    adc_vb: int
    adc_vc: int
    bemf_comparators: int
    adc_resolver_sin: int
    adc_resolver_cos: int
    adc_temperature: int


def _stuck_level(level) -> int | None:
    """A stuck fault's level checked: None (not stuck), or 0 / 1."""
    if level is None:
        return None
    if isinstance(level, float) or level not in (0, 1):
        raise ValueError(f"a stuck level is None, 0 or 1, got {level!r}")
    return int(level)


class StuckLevels(list):
    """Per phase (a, b, c) None or the level 0 / 1 a sensor is stuck at; a fault sets an
    element (levels[x] = 1, levels[:] = [...]) and anything else is refused there."""

    def __init__(self):
        super().__init__((None, None, None))

    def __setitem__(self, index, value):
        if isinstance(index, slice):
            value = [_stuck_level(v) for v in value]
            if len(range(*index.indices(3))) != len(value):
                raise ValueError("stuck levels are exactly three, one per phase")
        else:
            value = _stuck_level(value)
        super().__setitem__(index, value)

    def __delitem__(self, index):
        raise TypeError("stuck levels are exactly three, one per phase")

    def _fixed_length(self, *args, **kwargs):
        raise TypeError("stuck levels are exactly three, one per phase")

    append = extend = insert = pop = remove = clear = __iadd__ = __imul__ = _fixed_length


class HallSensors:
    """Three Hall sensors on the phase axes, one bit each (bit x: phase x).

    Sensor x sees c_x = cos(theta_e - n_x 120 deg - placement_error_x) (the magnet's flux
    linkage with its axis per psi_m, dimensionless). It turns on when c_x > sin(h/2) and off
    when c_x < -sin(h/2), else holds (h: hysteresis, electrical): for positive rotation the
    word (C B A) runs 1, 3, 2, 6, 4, 5 with edges at theta_e = 30 + 60 n deg + placement
    error, each h/2 late in either direction. First reading: on iff c_x > 0.

    State: ``state`` (three bits, None before the first reading). Faults: ``stuck[x]`` None, 0
    or 1 (the sensor's output held at that level; its state keeps following the magnet).
    """

    __slots__ = ("placement_error_rad", "hysteresis_rad", "_stuck", "state")

    def __init__(self, params: HallParams):
        self.placement_error_rad = [math.radians(e) for e in params.placement_error_deg]
        self.hysteresis_rad = math.radians(params.hysteresis_deg)
        self._stuck = StuckLevels()
        self.state: list[int] | None = None

    @property
    def stuck(self) -> StuckLevels:
        return self._stuck

    @stuck.setter
    def stuck(self, levels) -> None:
        self._stuck[:] = list(levels)

    def read(self, theta_e_rad: float) -> int:
        """The Hall word (bit0 A, bit1 B, bit2 C) at electrical angle theta_e_rad."""
        threshold = sin(0.5 * self.hysteresis_rad)
        state = self.state
        first = state is None
        if first:
            state = self.state = [0, 0, 0]
        word = 0
        for x in range(3):
            c = cos(theta_e_rad - x * TWO_PI_3 - self.placement_error_rad[x])
            if first:
                state[x] = 1 if c > 0.0 else 0
            elif c > threshold:
                state[x] = 1
            elif c < -threshold:
                state[x] = 0
            level = self._stuck[x]
            word |= (state[x] if level is None else level) << x
        return word


def driven_leg_voltages(command: Command, vdc: float, force_on: int = 0, force_off: int = 0
                        ) -> tuple[float | None, float | None, float | None]:
    """Per leg the terminal voltage (V, to DC-) that the command drives, averaged over its
    period: a gate word's leg v_dc (high) or 0 (low), a duty's d v_dc (dead time ignored);
    None for a leg with both switches off (floated, or a shoot-through the driver trips).
    force_on / force_off: stuck switches (gate bits), applied to a gate word."""
    if command.duty is None:
        a, b, c = _LEG_STATES[(command.gates | force_on) & ~force_off]
        return (vdc if a == H else 0.0 if a == L else None,
                vdc if b == H else 0.0 if b == L else None,
                vdc if c == H else 0.0 if c == L else None)
    duty, legs = command.duty, command.legs
    if legs == ALL_LEGS:
        return duty[0] * vdc, duty[1] * vdc, duty[2] * vdc
    return tuple(duty[x] * vdc if legs >> x & 1 else None for x in range(3))


def low_side_conducts(command: Command, currents: tuple[float, float, float],
                      force_on: int = 0, force_off: int = 0) -> tuple[bool, bool, bool]:
    """Per leg: its low switch or low diode conducts at t_k under the command of the period
    just ended (a duty's PWM is at its carrier valley: low side on unless d >= 1). An open leg
    conducts through its low diode while its current flows into the motor (i_x > 0)."""
    if command.duty is None:
        word = command.gates
    else:
        word = 0
        for x in range(3):
            if command.legs >> x & 1:
                word |= LEG_BITS[x][0] if command.duty[x] >= 1.0 else LEG_BITS[x][1]
    states = _LEG_STATES[(word | force_on) & ~force_off]
    return tuple(states[x] == L or (states[x] != H and currents[x] > ZERO_CURRENT_A)
                 for x in range(3))


def terminal_voltages_v(driven: tuple[float | None, float | None, float | None],
                        currents: tuple[float, float, float], emf: tuple[float, float, float],
                        vdc: float, diode_drop_v: float) -> tuple[float, float, float]:
    """Phase terminal voltages to DC- (V) from the legs' driven voltages (None: both switches
    off), the phase currents and back-EMFs (MotorModel.phase_back_emf_v).

    An open leg with current conducts through a diode: -U_d (i_x > 0, low diode) or
    v_dc + U_d (i_x < 0). One without floats at v_n + e_x, clamped to [-U_d, v_dc + U_d],
    with the star point v_n = mean over the conducting legs j of (v_j - e_j): with one leg
    floating (v_p + v_q - e_p - e_q)/2 (their currents are opposite, so with Ld = Lq their
    R i + L di/dt cancel), with two v_p - e_p (no current flows). With none conducting the
    sensing dividers pull the star point down until the lowest terminal's low diode conducts:
    v_n = -U_d - min e_x.
    """
    ud = diode_drop_v
    v = [0.0, 0.0, 0.0]
    floating = []
    star_sum = 0.0
    conducting = 0
    for x in range(3):
        vx = driven[x]
        if vx is None:
            i = currents[x]
            if i > ZERO_CURRENT_A:
                vx = -ud
            elif i < -ZERO_CURRENT_A:
                vx = vdc + ud
            else:
                floating.append(x)
                continue
        v[x] = vx
        star_sum += vx - emf[x]
        conducting += 1
    if floating:
        vn = star_sum / conducting if conducting else -ud - min(emf)
        top = vdc + ud
        for x in floating:
            vx = vn + emf[x]
            v[x] = -ud if vx < -ud else top if vx > top else vx
    return v[0], v[1], v[2]


class TerminalVoltages:
    """Phase terminal voltages through the board's divider, RC filter and ADC, and the BEMF
    comparators.

    State ``filtered_v`` (V, per phase; None until start()): the first-order RC filter,
    advanced once per period with the terminal voltage v averaged over the period just ended:
    y += (1 - exp(-T/tau)) (v - y), tau = filter_time_constant_s (0: y = v); n periods of the
    same v at once: y += (1 - exp(-n T/tau)) (v - y). So a step of v at t_0 reads
    1 - exp(-k T / tau) of it k periods later.
    ADC: count = round(y / v_per_count + noise), saturated to 0 .. 2^bits - 1.
    Comparator x (bit x): y_x > (y_a + y_b + y_c) / 3 + comparator_offset_v[x] (the virtual
    neutral of three equal resistors; offsets in V at the terminal scale).
    Faults: ``comparator_stuck[x]`` None, 0 or 1.
    """

    __slots__ = ("channels", "comparator_offset_v", "_comparator_stuck", "filtered_v",
                 "_filter_gain", "_filter_decay")

    def __init__(self, params: TerminalParams, seed: int, period_s: float):
        self.channels = tuple(
            AdcChannel(params.v_per_count, 0.0, params.bits, 1.0, params.noise_rms_counts,
                       GaussianNoise(seed, stream)) for stream in STREAM_TERMINAL_VOLTAGES)
        self.comparator_offset_v = list(params.comparator_offset_v)
        self._comparator_stuck = StuckLevels()
        self.filtered_v: list[float] | None = None
        tau = params.filter_time_constant_s
        self._filter_gain = 1.0 if tau == 0.0 else -math.expm1(-period_s / tau)
        self._filter_decay = 0.0 if tau == 0.0 else -period_s / tau     # log(1 - gain)

    @property
    def comparator_stuck(self) -> StuckLevels:
        return self._comparator_stuck

    @comparator_stuck.setter
    def comparator_stuck(self, levels) -> None:
        self._comparator_stuck[:] = list(levels)

    @property
    def filter_gain(self) -> float:
        """1 - exp(-T / tau): the share of a step the filter takes per period."""
        return self._filter_gain

    def start(self, v: tuple[float, float, float]) -> None:
        """The filters settled at v (V): the terminals have held it forever."""
        self.filtered_v = [v[0], v[1], v[2]]

    def advance(self, v: tuple[float, float, float], periods: int = 1) -> None:
        """`periods` periods (>= 1) with the average terminal voltages v (V)."""
        g = self._filter_gain
        if periods != 1 and g != 1.0:
            g = -math.expm1(periods * self._filter_decay)
        y = self.filtered_v
        for x in range(3):
            y[x] += g * (v[x] - y[x])

    def read(self) -> tuple[int, int, int, int]:
        """(adc_va, adc_vb, adc_vc, bemf_comparators) from the filters' state."""
        y = self.filtered_v
        neutral = (y[0] + y[1] + y[2]) / 3.0
        bits = 0
        for x in range(3):
            level = self._comparator_stuck[x]
            if level is None:
                level = 1 if y[x] > neutral + self.comparator_offset_v[x] else 0
            bits |= level << x
        ch = self.channels
        return _code(ch[0], y[0]), _code(ch[1], y[1]), _code(ch[2], y[2]), bits


class PhaseCurrents:
    """Three phase-current channels (the transducer and ADC of sensors.current, one noise
    stream each). ``placement`` inline: the phase current i_x (A, SPEC sign); low_side: i_x
    while phase x's low switch or low diode conducts at t_k (low_side_conducts), else 0 A
    (the zero-current code plus noise)."""

    __slots__ = ("channels", "placement")

    def __init__(self, params: CurrentSensorParams, seed: int):
        self.channels = tuple(
            AdcChannel(params.a_per_count, params.offset_counts, params.bits, params.gain,
                       params.noise_rms_counts, GaussianNoise(seed, stream))
            for stream in STREAM_PHASE_CURRENTS)
        self.placement = params.placement

    @property
    def low_side(self) -> bool:
        return self.placement == "low_side"

    def read(self, currents: tuple[float, float, float],
             conducts: tuple[bool, bool, bool] | None = None) -> tuple[int, int, int]:
        """Codes of (i_a, i_b, i_c); ``conducts`` (low_side only) per phase from
        low_side_conducts."""
        ch = self.channels
        if conducts is None:
            return _code(ch[0], currents[0]), _code(ch[1], currents[1]), _code(ch[2], currents[2])
        return tuple(_code(ch[x], currents[x] if conducts[x] else 0.0) for x in range(3))


class Resolver:
    """A resolver's demodulated sin and cos outputs, counts:

        theta_r = pole_pairs theta_m
        sin = offset + A (1 + m/2) sin(theta_r)
        cos = offset + A (1 - m/2) cos(theta_r - q)

    A = amplitude_counts, m = amplitude_imbalance, q = quadrature error (rad); each rounded
    with noise and saturated (AdcChannel, one count per unit). Stateless.
    """

    __slots__ = ("pole_pairs", "amplitude_counts", "amplitude_imbalance", "quadrature_error_rad",
                 "sin_channel", "cos_channel")

    def __init__(self, params: ResolverParams, seed: int):
        self.pole_pairs = params.pole_pairs
        self.amplitude_counts = params.amplitude_counts
        self.amplitude_imbalance = params.amplitude_imbalance
        self.quadrature_error_rad = math.radians(params.quadrature_error_deg)
        self.sin_channel, self.cos_channel = (
            AdcChannel(1.0, params.offset_counts, params.bits, 1.0, params.noise_rms_counts,
                       GaussianNoise(seed, stream)) for stream in STREAM_RESOLVER)

    def read(self, theta_m_rad: float) -> tuple[int, int]:
        """(sin count, cos count) at mechanical angle theta_m_rad."""
        th = self.pole_pairs * theta_m_rad
        a = self.amplitude_counts
        half = 0.5 * self.amplitude_imbalance
        return (_code(self.sin_channel, a * (1.0 + half) * sin(th)),
                _code(self.cos_channel, a * (1.0 - half) * cos(th - self.quadrature_error_rad)))


class TemperatureChannel:
    """The winding-temperature channel: count = offset_counts + T_w / degc_per_count (T_w in
    degC), rounded with noise and saturated (AdcChannel ``channel``). Stateless."""

    __slots__ = ("channel",)

    def __init__(self, params: TemperatureSensorParams, seed: int):
        self.channel = AdcChannel(params.degc_per_count, params.offset_counts, params.bits, 1.0,
                                  params.noise_rms_counts, GaussianNoise(seed, STREAM_TEMPERATURE))

    def read(self, winding_degc: float) -> int:
        return _code(self.channel, winding_degc)


class SensorSet:
    """The sensor-set models of one plant, built from the profile's sensors section."""

    __slots__ = ("phase_currents", "hall", "terminal", "resolver", "temperature")

    def __init__(self, params: SensorParams, seed: int, period_s: float):
        self.phase_currents = PhaseCurrents(params.current, seed)
        self.hall = HallSensors(params.hall)
        self.terminal = TerminalVoltages(params.terminal, seed, period_s)
        self.resolver = Resolver(params.resolver, seed)
        self.temperature = TemperatureChannel(params.temperature, seed)

    def attach(self, sensors) -> None:
        """Makes the models reachable as the plant's sensors.<name> (faults, tests)."""
        for name in self.__slots__:
            setattr(sensors, name, getattr(self, name))

    def frame(self, sample: SensorSample, theta_e_rad: float, theta_m_rad: float,
              currents: tuple[float, float, float], conducts: tuple[bool, bool, bool] | None,
              winding_degc: float) -> SensorFrame:
        """The frame at the sample's t_k; the terminal filters must have been start()ed."""
        ia, ib, ic = self.phase_currents.read(currents, conducts)
        va, vb, vc, comparators = self.terminal.read()
        rs, rc = self.resolver.read(theta_m_rad)
        return _new_frame(SensorFrame, (sample.period, sample.status, ia, ib, ic, sample.adc_vdc,
                                        sample.encoder, self.hall.read(theta_e_rad), va, vb, vc,
                                        comparators, rs, rc,
                                        self.temperature.read(winding_degc)))
