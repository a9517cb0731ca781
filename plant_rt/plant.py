"""The plant: motor, inverter, DC link, load and sensors advanced one control period at a time.

Per period k (T = control_period_s):

    s = plant.sample()        # what the board's converters read at t_k = k T
    plant.step(gates=...)     # integrate [t_k, t_k+1] with the board's answer

(plant.sensor_frame() instead of sample() for a board with a sensor set: plant_rt.sensor_set.)

The answer takes effect computation_delay_s after t_k; before that the previous command holds.
The period is cut into intervals of constant switch state (computation delay, PWM edges, dead
time, load-profile knots) and each interval is integrated exactly as it is, never averaged:
with all legs driven, an ideal DC link and no device drop, by the motor's plain-float RK4
(the fast path: one RK4 step per 50 us); otherwise by the general network with diode events
(plant_rt.circuit).

Fault hooks (hil/faults/injector.py drives them; each costs nothing while it is off):

    set_open_phase('a')            one motor phase disconnected: its current is exactly zero
    set_gate_stuck('b_high', 'on') a switch stuck on or off whatever the board commands
    set_dc_ripple(5.0, 300.0)      source voltage + A sin(2 pi f t)
    ramp_dc_voltage(49.0, 0.01)    a sag or surge reached linearly
    ramp_motor_param('resistance_ohm', 0.699, 0.1)   drift (winding or magnet temperature)
    add_period_hook(fn, 'before' | 'after')          fn(k) around every step()

Slowly varying quantities (ripple, ramps) are held constant over a period at their value at
the period's midpoint: a zero-order hold at 20 kHz, exact for the integration of that period.

The slow paths (the PWM period as constant-vector pieces, the general network) and the plain
case of sample() and truth() (no sensor fault, no open phase...) run in the C kernel
plant_rt/c/_plantnet.c when it is built (plant_rt.ckernel; HIL_PLANT_PURE_PYTHON=1 or
use_c_kernel(False) keeps this Python code, the reference).
"""
from __future__ import annotations

import dataclasses
import math
from math import cos, pi, sin

from plant_rt import ckernel
from plant_rt.circuit import S32, ZERO_CURRENT_A, Network
from plant_rt.dc_link import DcLink
from plant_rt.inverter import (
    GATE_COMMANDS, LEG_BITS, PHASE_AXES, SQRT3, H, L, O, Command, InverterParams, SwitchTimeline,
    driven_vector, leg_states, shoot_through,
)
from plant_rt.load import Load
from plant_rt.motor import MotorModel
from plant_rt.profile import BenchProfile
from plant_rt.sensor_set import (
    SensorFrame, SensorSet, driven_leg_voltages, low_side_conducts, terminal_voltages_v,
)
from plant_rt.sensors import STATUS_GATE_FAULT, STATUS_INDEX_PULSE, SensorSample, Sensors
from plant_rt.thermal import ThermalModel
from configfile.fields import coerce

TWO_PI = 2.0 * pi
RPM_PER_RAD_S = 60.0 / TWO_PI

#: Fields of Plant.truth(), in order. Speed is mechanical; angles wrapped to (-pi, pi];
#: psi is the stator flux linkage; u_* and i_dc are averages over the last period.
TRUTH_FIELDS = ("t_s", "i_a", "i_b", "i_c", "i_alpha", "i_beta", "psi_alpha", "psi_beta",
                "flux_mag_wb", "torque_nm", "speed_rad_s", "speed_rpm", "theta_e_rad",
                "theta_m_rad", "v_dc", "i_dc", "load_torque_nm", "u_alpha", "u_beta")
_SHOOT_THROUGH = tuple(shoot_through(g) for g in range(64))
_LEG_STATES = tuple(leg_states(g) for g in range(64))
#: (u_alpha, u_beta per volt of link, g_alpha, g_beta, leg states) per word, None if not driven.
_UNIT_VECTORS = tuple(None if driven_vector(g, 1.0) is None
                      else driven_vector(g, 1.0) + (leg_states(g),) for g in range(64))
_DRIVEN_WORDS = tuple((g, unit) for g, unit in enumerate(_UNIT_VECTORS) if unit is not None)
#: Per 3-bit leg-high pattern h (bit x: leg x at DC+): (u_alpha, u_beta per volt of link, g_alpha,
#: g_beta), u = 2/3 sum_x V_x e_x (Table 2) and i_dc = g . i_alphabeta.
_LEG_UNITS = tuple(
    (((2 * (h & 1)) - (h >> 1 & 1) - (h >> 2 & 1)) / 3.0, ((h >> 1 & 1) - (h >> 2 & 1)) / SQRT3,
     sum(PHASE_AXES[x][0] for x in range(3) if h >> x & 1),
     sum(PHASE_AXES[x][1] for x in range(3) if h >> x & 1))
    for h in range(8))
#: Gate word of a leg-high pattern (every leg driven: high or low switch).
_LEG_WORDS = tuple(sum(LEG_BITS[x][0] if h >> x & 1 else LEG_BITS[x][1] for x in range(3))
                   for h in range(8))
PHASES = ("a", "b", "c")
SWITCHES = ("a_high", "a_low", "b_high", "b_low", "c_high", "c_low")
#: Names a test plan uses for motor constants (hil/faults/catalog.py PLANT_PARAMS) -> MotorParams fields.
PARAM_ALIASES = {"inductance_h": ("inductance_d_h", "inductance_q_h"),
                 "ld_h": ("inductance_d_h",), "lq_h": ("inductance_q_h",)}
#: Drift ramps update the motor every this many seconds (a parameter change re-derives the
#: plant's tables, about 16 us; thermal drifts take seconds).
PARAM_RAMP_UPDATE_S = 1e-3


def wrap_angle(x: float) -> float:
    """x wrapped to (-pi, pi]."""
    r = math.remainder(x, TWO_PI)
    return pi if r == -pi else r


class Plant:
    """See the module docstring. Attributes: period (k), t_s, load, sensors, motor, dc_link."""

    def __init__(self, profile: BenchProfile, seed: int = 0):
        self.profile = profile
        self.seed = seed
        timing = profile.timing
        self._T = timing.control_period_s
        self.motor = MotorModel(profile.motor)
        self.inverter = profile.inverter
        self.dc_link = DcLink(profile.dc_link)
        self.load = Load(profile.load, clock=lambda: self.t_s)
        self.sensors = Sensors(profile.sensors, seed)
        self.network = Network(self.motor, profile.inverter, self.dc_link, self.load)
        self._timeline = SwitchTimeline(self._T, timing.computation_delay_s,
                                        profile.inverter.dead_time_s)
        self.period = 0
        th = wrap_angle(profile.initial.theta_m_rad)
        self._th = th
        self._revs = 0
        self._w = 0.0 if profile.load.locked else profile.initial.speed_rad_s
        self._pa, self._pb = self.motor.flux_from_currents(0.0, 0.0, th)
        self._vcap = self.dc_link.source_v
        self._vdc = self.dc_link.source_v
        self._cmd = GATE_COMMANDS[0]
        self._timeline.reset(self._cmd)
        self._flags = 0
        self._u_int = (0.0, 0.0)
        self._idc_int = 0.0
        self._net_dirty = True
        self._zero_current = False
        self._sample_k = -1
        self._sample: SensorSample | None = None
        self._load_seg = (0.0, 0.0, 0.0, math.inf)
        self._seg_key = None
        self._open_phase: int | None = None
        self._hooks: dict[str, list] = {"before": [], "after": []}
        self._dc_base_v = self.dc_link.source_v
        self._dc_ramp: tuple[float, float, float, float] | None = None   # t0, t1, v0, v1
        self._ripple: tuple[float, float] | None = None                   # amplitude, Hz
        self._param_ramps: dict[str, tuple[float, float, float, float, int]] = {}
        self._vectors: list = [None] * 64
        # the C kernel is sinusoidal only: the trapezoidal machine runs the Python paths
        self._ckernel = None if self.motor.trapezoidal else ckernel.KERNEL
        self.network.ckernel = self._ckernel
        self._timeline.kernel = self._ckernel
        self._bind_readout(self._ckernel)
        self._rebuild()
        # Sensor sets: computed by sensor_frame() only, so a plant never asked for a frame
        # does nothing more per period. The thermal model, when the profile enables it, runs
        # after every period (_thermal_period).
        self._sensor_set = SensorSet(profile.sensors, seed, self._T)
        self._sensor_set.attach(self.sensors)
        self._frame: SensorFrame | None = None
        self._frame_sample: SensorSample | None = None
        self._terminal_k: int | None = None       # the period the terminal filters are at
        self._emf_then: tuple[float, float, float] = (0.0, 0.0, 0.0)   # back-EMFs then
        self._thermal = ThermalModel(profile.thermal, profile.motor.resistance_ohm, self._T)
        self._thermal_on = profile.thermal.enabled
        if self._thermal_on:
            self._apply_winding_resistance()
            self.add_period_hook(self._thermal_period, "after")

    @property
    def c_kernel(self) -> bool:
        """True when the slow paths run in the C kernel (plant_rt.ckernel)."""
        return self._ckernel is not None

    def use_c_kernel(self, on) -> None:
        """Runs the slow paths in the C kernel (True: ImportError when it is not built) or in
        Python (False: the reference); an object with the extension's functions is used as
        the kernel (tests wrap the extension so)."""
        kernel = None
        if on is not False and on is not None and self.motor.trapezoidal:
            raise ValueError("the C kernel is sinusoidal only: motor back_emf trapezoidal "
                             "runs in Python")
        if on is True:
            kernel = ckernel.EXTENSION
            if kernel is None:
                raise ImportError(ckernel.UNAVAILABLE_REASON)
        elif on is not False and on is not None:
            kernel = on
        self._ckernel = kernel
        self.network.ckernel = kernel
        self._timeline.kernel = kernel
        self._bind_readout(kernel)
        self._bind_duty_period()

    def _bind_readout(self, kernel) -> None:
        """sample() and truth() in the kernel when it has them (a kernel without, such as a
        test's wrapper of the extension, leaves them in Python)."""
        self._c_sample = getattr(kernel, "sample", None)
        self._c_truth = getattr(kernel, "truth", None)

    # --------------------------------------------------------------- helpers
    def _rebuild(self) -> None:
        """Derived tables after a parameter change: fast-path vectors and the step limit."""
        m = self.motor
        h = self.profile.timing.max_step_s
        h = min(h, self.dc_link.stiff_step_s())
        lmin = min(m.ld, m.lq)
        h = min(h, 0.5 * lmin / m.r)
        if self.dc_link.dynamic:
            h = min(h, 0.2 * math.sqrt(lmin * self.dc_link.c))
        if self.inverter.device_drop_v > 0.0:
            h = min(h, 0.5 * lmin * self.inverter.device_knee_a / self.inverter.device_drop_v)
        self._h_max = h
        self._n_fast = max(1, math.ceil(self._T / h - 1e-9))
        self._scale_vectors()
        self._ir = 1.0 / m.r
        self._load_key = None           # re-read the load (and the damping) at the next step
        self._load_until = -math.inf
        self._fast_ok = (self.dc_link.ideal and self.inverter.device_drop_v == 0.0
                         and self._open_phase is None)
        # Leg-window path (PWM, dead time, device drop): every interval a constant vector as
        # long as no current that matters changes sign (checked after the period).
        self._pwm_ok = (self.dc_link.ideal and self._open_phase is None
                        and not (self._timeline.force_on or self._timeline.force_off))
        # The whole period as one Table 2 vector needs the commanded word to be the real one.
        self._direct = self._fast_ok and not (self._timeline.force_on or self._timeline.force_off)
        self._timeline.dead_time_s = self.inverter.dead_time_s
        # Every gate command is one interval: no dead time, and no delay that could split it.
        self._one_interval = (self.inverter.dead_time_s == 0.0
                              and self.profile.timing.computation_delay_s == 0.0)
        self._bind_duty_period()

    def _bind_duty_period(self) -> None:
        """The DUTY fast path (the kernel's duty_period, None when there is none or the
        leg-window path may not run) and its constants, after a change of either."""
        kernel = self._ckernel
        fn = getattr(kernel, "duty_period", None) if self._pwm_ok else None
        self._duty_period = fn
        if fn is not None:
            m, inv, tl = self.motor, self.inverter, self._timeline
            self._duty_cfg = tuple(float(v) for v in m._k + (
                m.ld, 1.0 if m.spm else 0.0, tl.period_s, tl.delay_s, tl.dead_time_s,
                inv.device_drop_v, inv.device_knee_a, self._h_max, STATUS_INDEX_PULSE))

    def _scale_vectors(self) -> None:
        """Table 2 voltages of every driven gate word at the present source voltage."""
        vdc = self.dc_link.source_v
        vectors = self._vectors
        for g, unit in _DRIVEN_WORDS:
            vectors[g] = (unit[0] * vdc, unit[1] * vdc, unit[2], unit[3], unit[4])
        self.network.invalidate()

    def _load_segment(self, t: float) -> tuple[float, float, float]:
        """(profile value at t, slope, next knot) with a cache for the constant case."""
        key = self.load.version
        seg_t, v0, slope, t_next = self._load_seg
        if key != self._seg_key or not seg_t <= t < t_next:
            v0, slope, t_next = self.load.segment(t)
            self._load_seg = (t, v0, slope, t_next)
            self._seg_key = key
            return v0, slope, t_next
        return v0 + slope * (t - seg_t), slope, t_next

    # ------------------------------------------------------------------ API
    @property
    def t_s(self) -> float:
        return self.period * self._T

    @property
    def control_period_s(self) -> float:
        return self._T

    def step(self, gates: int | None = None, duty=None, legs: int | None = None) -> None:
        """Integrates one control period with the new command (None keeps the previous one).
        ``legs`` goes with ``duty``: the leg enables (bit x = leg x; a leg whose bit is 0 is
        floated, both switches off all period), None for all three legs switching."""
        old = self._cmd
        if legs is not None:
            duty = Command.parse(gates, duty, legs)  # the duty Command (or the ValueError)
        if (gates is None and self._duty_period is not None
                and (duty is not None or old.duty is not None)
                and self._duty_step(old, old if duty is None else duty)):
            return
        if duty is None and gates is None:
            new = old
        elif duty is None and type(gates) is int and 0 <= gates < 64:
            new = GATE_COMMANDS[gates]
        elif type(duty) is Command:
            new = duty
        else:
            new = Command.parse(gates, duty)
        self._cmd = new
        T = self._T
        t0 = self.period * T
        th = self._th
        self._flags = 0
        # Fast path: the whole period is one driven Table 2 vector (the paper's case).
        vec = self._vectors[new.gates] if new.duty is None else None
        if vec is not None and self._direct and (old is new or self._one_interval):
            if self.load.version != self._load_key or t0 + T > self._load_until:
                self._refresh_load(t0)
            if t0 + T <= self._load_until:
                va, vb, ga, gb, legs = vec
                pa0, pb0 = self._pa, self._pb
                n = self._n_fast
                kernel = self._ckernel
                motor = self.motor
                tl0 = self._load_v0 + self._load_slope * (t0 - self._load_t)
                if kernel is not None:       # the same RK4 in C (MotorModel.advance's mirror)
                    pa, pb, self._w, th_end = kernel.advance(
                        motor._k, motor.spm, pa0, pb0, self._w, th, va, vb, T / n, n, tl0,
                        self._load_slope, self._bw)
                else:
                    pa, pb, self._w, th_end = motor.advance(
                        pa0, pb0, self._w, th, va, vb, T / n, n, tl0, self._load_slope, self._bw)
                self._pa = pa
                self._pb = pb
                self._u_int = (va * T, vb * T)
                # int i dt follows from eq. (1) exactly as RK4 integrated it: (u T - dpsi)/R.
                self._idc_int = (ga * (va * T - pa + pa0) + gb * (vb * T - pb + pb0)) * self._ir
                if self._net_dirty:
                    self.network.set_driven(legs)
                    self._net_dirty = False
                    self._zero_current = False
                self._finish(th, th_end)
                return
        self._general(t0, old, new)
        self._finish(th, self._th)

    def _duty_step(self, old: Command, new) -> bool:
        """The DUTY fast path: step() for duties `new` (or the duty Command held) in one call
        of the kernel's duty_period, which parses the duties, builds the switch windows (with
        the dead-time memory) and runs _leg_period and _finish as the code below step() would;
        False (nothing changed) when it does not take the period: step() then runs that code.
        A period _leg_period refuses goes to the general network with the windows built."""
        load = self.load
        if load.locked or load.version != self._seg_key or self._seg_key != self._load_key:
            return False
        vdc = self.dc_link.source_v
        done = self._duty_period(self._duty_cfg, Command, old.gates, old.duty, new,
                                 self._timeline._rise, vdc, self._pa, self._pb, self._w, self._th,
                                 self._revs, self.period, self._load_seg, self._bw, old.legs)
        if done is None:
            return False
        if len(done) == 2:
            self._cmd, windows = done
            self._flags = 0
            th = self._th
            self._intervals(self.period * self._T, self._timeline.words(windows))
            self._finish(th, self._th)
            return True
        (self._cmd, self._pa, self._pb, self._w, self._th, self._u_int, self._idc_int,
         self._flags, self._revs, self.period, h) = done
        self._zero_current = False
        self._vdc = vdc
        if self._net_dirty:
            self.network.set_driven(_LEG_STATES[_LEG_WORDS[h]])
            self._net_dirty = False
        return True

    def _refresh_load(self, t0: float) -> None:
        """Caches the load's linear piece at t0 for the fast path (none while locked)."""
        load = self.load
        v0, slope, t_next = load.segment(t0)
        self._load_key = load.version
        self._load_t, self._load_v0, self._load_slope = t0, v0, slope
        self._load_until = -math.inf if load.locked else t_next
        self._bw = self.motor.b + load.kw

    def _finish(self, th_start: float, th: float) -> None:
        """Index pulse, angle wrap, period count."""
        if (th_start >= 0.0) != (th >= 0.0):
            self._flags |= STATUS_INDEX_PULSE
        if th > pi:
            th -= TWO_PI
            self._revs += 1
        elif th <= -pi:
            th += TWO_PI
            self._revs -= 1
        self._th = th
        self.period += 1

    def _general(self, t0: float, old: Command, new: Command) -> None:
        """A period that is not one ideal driven interval: split it and integrate each part."""
        T = self._T
        tl = self._timeline
        if self._pwm_ok and not self.load.locked and (
                new.duty is not None or old.duty is not None or self.inverter.dead_time_s > 0.0
                or self.inverter.device_drop_v > 0.0):
            windows = tl.switch_windows(old, new)
            if self._leg_period(t0, windows):
                return
            intervals = tl.words(windows)
        else:
            intervals = tl.build(old, new)
        self._intervals(t0, intervals)

    def _intervals(self, t0: float, intervals: list[tuple[float, float, int]]) -> None:
        """_general's integration of the period's constant-word intervals, one after the other."""
        T = self._T
        net = self.network
        y = [self._pa, self._pb, self._w, self._th, self._vcap]
        acc = [0.0, 0.0, 0.0]
        fast = self._fast_ok and not self.load.locked
        kernel = self._ckernel
        for _, _, word in intervals:        # whichever path integrates the period
            if _SHOOT_THROUGH[word]:
                self._flags |= STATUS_GATE_FAULT
        # With no load knot in the period the kernel runs the loop below in one call: period()
        # when every interval goes to the network (begin + integrate per interval), fast_period()
        # on the fast path (the fast RK4, the diode-equivalent trial and the network per
        # interval, as it does them: with dead time near current zeros a period has a dozen
        # intervals, each a few Python calls; ~80 us a period at 20 rad/s against ~5 us,
        # bench.plant's low-speed figure).
        fast_period = getattr(kernel, "fast_period", None) if fast else None
        if (kernel is not None and not fast) or fast_period is not None:
            v0, slope, t_next = self._load_segment(t0)
            if t_next - t0 >= T:
                seg_t, seg_v0, seg_slope, _ = self._load_seg
                args = (self.motor._k, net._cfg(), net.kinds, net.legs_code(), intervals, t0, T, y,
                        self._h_max, acc, seg_t, seg_v0, seg_slope, net.vdc)
                if fast_period is None:
                    y, kinds, last, events, overflows, net.vdc, ran = kernel.period(*args)
                    if ran:
                        self._net_dirty = True
                else:
                    y, kinds, last, events, overflows, net.vdc, self._net_dirty = fast_period(
                        *args, self.motor.spm, self._vectors, self.motor.b + self.load.kw,
                        self._net_dirty)
                net.set_state(kinds, last, events, overflows)
                intervals = ()
        for a, b, word in intervals:
            while b - a > 1e-15 * T:
                v0, slope, t_next = self._load_segment(t0 + a)
                end = min(b, t_next - t0) if t_next - t0 > a else b
                vec = self._vectors[word] if fast else None
                if vec is not None:
                    self._advance(y, vec, end - a, v0, slope, acc)
                    if self._net_dirty:
                        net.set_driven(vec[4])
                        self._net_dirty = False
                elif not (fast and self._diode_interval(y, word, end - a, v0, slope, acc)):
                    net.set_load_segment(t0 + a, v0, slope)
                    net.begin(t0 + a, y, _LEG_STATES[word])
                    y = net.integrate(t0 + a, t0 + end, y, self._h_max, acc)
                    self._net_dirty = True
                a = end
        if self.load.locked:
            y[2] = 0.0
        self._pa, self._pb, self._w, self._th, self._vcap = y
        self._u_int = (acc[0], acc[1])
        self._idc_int = acc[2]
        self._zero_current = net.all_zero and self._net_dirty
        if self.dc_link.dynamic:
            self._vdc = self._vcap
        elif self.dc_link.resistive:
            self._vdc = net.vdc     # the network's last evaluation is at the period's end
        else:
            self._vdc = self.dc_link.source_v

    def _leg_period(self, t0: float, windows: list[list[tuple[float, float]]]) -> bool:
        """The period as constant-vector pieces from each leg's switch windows; False (nothing
        changed) when it cannot be: a shoot-through, a load knot inside the period, or a
        phase current that matters (a leg with a dead interval, every leg with a device drop)
        at or crossing zero (or the knee) in the period. The general network then takes it.

        With the sign s_x of every such current fixed, leg x sits at DC+ while its high switch
        is on (s_x > 0: otherwise the low switch or diode conducts) or while its low switch is
        off (s_x < 0), and its terminal is that rail minus U_d s_x: a constant voltage vector
        between the legs' edges, integrated piece by piece with the motor's RK4. The sign is
        checked from the end state: L i_x(t) = V_x(t) + Y_x(t) with V_x = int u_x dt known
        (piecewise linear) and Y_x = L i_x - V_x C^1 with |Y''| <= M (bound below), so
        L i_x(t) >= V_x(t) + chord of Y_x - M T^2/8: checked at every edge, where the
        piecewise-linear part takes its extreme values."""
        T = self._T
        v0, slope, t_next = self._load_segment(t0)
        if t_next < t0 + T:
            return False
        m = self.motor
        inv = self.inverter
        ud = inv.device_drop_v
        kernel = self._ckernel
        if kernel is not None:
            if self.load.version != self._load_key:
                self._refresh_load(t0)
            vdc = self.dc_link.source_v
            done = kernel.leg_period(m._k, m.ld, m.spm, T, windows, ud, inv.device_knee_a, vdc,
                                     (self._pa, self._pb, self._w, self._th), self._h_max, v0,
                                     slope, self._bw)
            if done is False:
                return False
            if done is not None:        # None: more edges than the kernel holds (Python's turn)
                pa, pb, w, th, ua_int, ub_int, q, h = done
                self._end_leg_period(pa, pb, w, th, ua_int, ub_int, q, h, vdc)
                return True
        y_pa, y_pb, y_w, y_th = self._pa, self._pb, self._w, self._th
        need = []                       # legs whose current sign matters
        signs = [0.0, 0.0, 0.0]
        cur0 = None
        h0 = 0
        toggles = []
        for x in range(3):
            hi = windows[2 * x]
            lo = windows[2 * x + 1]
            on = 0.0
            for a, b in hi:
                on += b - a
                for c, d in lo:
                    if a < d and c < b:
                        return False    # shoot-through: the general path trips the leg
            for c, d in lo:
                on += d - c
            if ud > 0.0 or on < T * (1.0 - 1e-12):
                if not m.spm or m.trapezoidal:
                    return False        # the sign check below is written for sinusoidal Ld = Lq
                if cur0 is None:
                    ia, ib, _, _ = m.currents(y_pa, y_pb, y_th)
                    cur0 = (ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib)
                ix = cur0[x]
                thr = inv.device_knee_a if ud > 0.0 else 0.0
                if abs(ix) <= thr + ZERO_CURRENT_A:
                    return False
                signs[x] = 1.0 if ix > 0.0 else -1.0
                need.append(x)
                if ix < 0.0:            # at DC+ except while the low switch conducts
                    high, t = [], 0.0
                    for c, d in lo:
                        if c > t:
                            high.append((t, c))
                        t = d
                    if t < T:
                        high.append((t, T))
                    hi = high
            bit = 1 << x
            for a, b in hi:
                if a <= 0.0:
                    h0 |= bit
                else:
                    toggles.append((a, bit))
                if b < T:
                    toggles.append((b, bit))
        toggles.sort()
        vdc = self.dc_link.source_v
        # Device drop: leg x's terminal is its rail - U_d s_x, a constant offset vector.
        off_a = -ud * (2.0 * signs[0] - signs[1] - signs[2]) / 3.0
        off_b = -ud * (signs[1] - signs[2]) / SQRT3
        pieces = []
        edges = [0.0]
        t = 0.0
        h = h0
        ua_int = ub_int = 0.0
        for when, bit in toggles:
            if when > t:
                unit = _LEG_UNITS[h]
                va = unit[0] * vdc + off_a
                vb = unit[1] * vdc + off_b
                pieces.append((when - t, va, vb, unit[2], unit[3]))
                ua_int += va * (when - t)
                ub_int += vb * (when - t)
                edges.append(when)
                t = when
            h ^= bit
        if t < T:
            unit = _LEG_UNITS[h]
            va = unit[0] * vdc + off_a
            vb = unit[1] * vdc + off_b
            pieces.append((T - t, va, vb, unit[2], unit[3]))
            ua_int += va * (T - t)
            ub_int += vb * (T - t)
            edges.append(T)
        if self.load.version != self._load_key:
            self._refresh_load(t0)
        pa, pb, w, th, q = m.advance_pieces(y_pa, y_pb, y_w, y_th, pieces, self._h_max, v0,
                                            slope, self._bw)
        if need and not self._signs_hold(need, signs, cur0, pieces, edges, pa, pb, w, th,
                                         y_w, ud, vdc, abs(v0) + abs(slope) * T):
            return False
        self._end_leg_period(pa, pb, w, th, ua_int, ub_int, q, h, vdc)
        return True

    def _end_leg_period(self, pa: float, pb: float, w: float, th: float, ua_int: float,
                        ub_int: float, q: float, h: int, vdc: float) -> None:
        """A PWM period done by _leg_period (in C or in Python): its end state, the volt-seconds
        and DC-link charge it integrated, and the network's legs as the last word `h` left them."""
        self._pa, self._pb, self._w, self._th = pa, pb, w, th
        self._u_int = (ua_int, ub_int)
        self._idc_int = q
        self._zero_current = False
        self._vdc = vdc
        if self._net_dirty:
            self.network.set_driven(_LEG_STATES[_LEG_WORDS[h]])
            self._net_dirty = False

    def _signs_hold(self, need, signs, cur0, pieces, edges, pa, pb, w, th, w0, ud, vdc,
                    load_max) -> bool:
        """No current in `need` reached zero (or the knee) within the period (see _leg_period)."""
        m = self.motor
        T = self._T
        ia, ib, _, _ = m.currents(pa, pb, th)
        cur1 = (ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib)
        lind = m.ld
        # |Y''| <= (R/L)(|u| + R i_max + w_e psi_m) + (w_e^2 + |alpha_e|) psi_m over the period.
        u_max = 2.0 / 3.0 * (vdc + 2.0 * ud)
        w_max = max(abs(w0), abs(w))
        i_max = max(math.hypot(*m.currents(self._pa, self._pb, self._th)[:2]), math.hypot(ia, ib))
        i_max += T * (u_max + m.p * w_max * m.psim) / lind + 1e-3
        alpha_e = m.p * (m.kt * m.psim * i_max + self._bw * w_max + load_max) * m.ij
        we = m.p * w_max + alpha_e * T
        bound = (m.r / lind * (u_max + m.r * i_max + we * m.psim)
                 + (we * we + alpha_e) * m.psim) * T * T / 8.0
        thr = lind * (self.inverter.device_knee_a if ud > 0.0 else 0.0) + bound
        for x in need:
            ex0, ex1 = PHASE_AXES[x]
            s = signs[x]
            vx = 0.0
            vx_end = 0.0
            for length, va, vb, _, _ in pieces:
                vx_end += (ex0 * va + ex1 * vb) * length
            y0 = lind * cur0[x]
            dy = lind * cur1[x] - vx_end - y0
            k = 0
            for length, va, vb, _, _ in pieces:
                if s * (vx + y0 + dy * edges[k] / T) <= thr:
                    return False
                vx += (ex0 * va + ex1 * vb) * length
                k += 1
            if s * lind * cur1[x] <= thr:
                return False
        return True

    def _advance(self, y: list[float], vec: tuple, length: float, v0: float, slope: float,
                 acc: list[float]) -> None:
        """The fast RK4 over one driven interval; updates y and the period's integrals."""
        motor = self.motor
        va, vb, ga, gb, _ = vec
        n = max(1, math.ceil(length / self._h_max - 1e-9))
        pa0, pb0 = y[0], y[1]
        kernel = self._ckernel
        if kernel is not None:
            y[0], y[1], y[2], y[3] = kernel.advance(motor._k, motor.spm, pa0, pb0, y[2], y[3], va,
                                                    vb, length / n, n, v0, slope,
                                                    motor.b + self.load.kw)
        else:
            y[0], y[1], y[2], y[3] = motor.advance(pa0, pb0, y[2], y[3], va, vb, length / n, n,
                                                   v0, slope, motor.b + self.load.kw)
        acc[0] += va * length
        acc[1] += vb * length
        acc[2] += (ga * (va * length - (y[0] - pa0)) + gb * (vb * length - (y[1] - pb0))) / motor.r

    def _diode_interval(self, y: list[float], word: int, length: float, v0: float,
                        slope: float, acc: list[float]) -> bool:
        """An open leg whose diode conducts throughout is, with no device drop and an ideal
        link, the same as its switch on (low diode: 0 V, high diode: v_dc). Tries the fast RK4
        with that word and keeps it if no diode current reached zero; False leaves y as it
        was for the general network (dead time costs little away from current zeros)."""
        m = self.motor
        if m.trapezoidal:
            ia, ib, _, _ = m.currents(y[0], y[1], y[3])
        else:
            e = m.p * y[3]
            c, s = cos(e), sin(e)
            i_d = (c * y[0] + s * y[1] - m.psim) * m.ild
            i_q = (c * y[1] - s * y[0]) * m.ilq
            ia, ib = c * i_d - s * i_q, s * i_d + c * i_q
        cur = (ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib)
        legs = _LEG_STATES[word]
        equivalent = 0
        for x in range(3):
            side = legs[x]
            if side == O:
                if cur[x] > ZERO_CURRENT_A:
                    side = L                    # current into the motor: low diode
                elif cur[x] < -ZERO_CURRENT_A:
                    side = H
                else:
                    return False                # at zero: the network decides what follows
            equivalent |= LEG_BITS[x][0] if side == H else LEG_BITS[x][1]
        vec = self._vectors[equivalent]
        trial = list(y)
        part = [0.0, 0.0, 0.0]
        self._advance(trial, vec, length, v0, slope, part)
        ia, ib, _, _ = m.currents(trial[0], trial[1], trial[3])
        after = (ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib)
        for x in range(3):
            if legs[x] == O and (after[x] > 0.0) != (cur[x] > 0.0):
                return False
        y[:] = trial
        for i in range(3):
            acc[i] += part[i]
        if self._net_dirty:
            self.network.set_driven(vec[4])     # the diode legs behaved as driven ones
            self._net_dirty = False
        return True

    def safe_state(self) -> None:
        """All six switches off from now on: the motor coasts through the diodes until the next
        step() with gates or duty (the bench's hardware disable, no computation delay)."""
        self._cmd = GATE_COMMANDS[0]
        self._timeline.reset(self._cmd)
        self.network.invalidate()

    def sample(self) -> SensorSample:
        """The board's reading at t_k (the same object if called again in the same period)."""
        k = self.period
        if self._sample_k == k:
            return self._sample
        c_sample = self._c_sample
        if c_sample is not None and not self._zero_current and self._open_phase is None:
            # The plain case in C (None: a fault, a noise refill... the code below, the
            # reference, does it).
            s = c_sample(self.sensors, self.motor, SensorSample, k, self._pa, self._pb,
                         self._th, self._revs, self._vdc, self._flags)
            if s is not None:
                self._sample = s
                self._sample_k = k
                return s
        th = self._th
        if self._zero_current:
            ia = ib = 0.0
        elif self.motor.trapezoidal:
            ia, ib = self._currents_ab()
        else:
            m = self.motor
            e = m.p * th
            c, s = cos(e), sin(e)
            i_d = (c * self._pa + s * self._pb - m.psim) * m.ild
            i_q = (c * self._pb - s * self._pa) * m.ilq
            ia, ib = c * i_d - s * i_q, s * i_d + c * i_q
            if self._open_phase is not None:
                ia, ib = _cut_phase(self._open_phase, ia, ib)[3:]
        self._sample = self.sensors.read(k, ia, ib, self._vdc, self._revs, th, self._flags)
        self._sample_k = k
        return self._sample

    def sensor_frame(self) -> SensorFrame:
        """Every sensor of the sensor sets at t_k (the same object if called again in the same
        period), with sample()'s period, status, adc_vdc and encoder.

        The terminal filters start at the first call, settled at the terminal voltages of that
        instant; each later call advances them by the periods since the one before, with the
        terminal voltages averaged over the period just ended (under the command in force,
        the back-EMF as the mean of its values then and now): exact when a frame is asked for
        every period, as a session does; after a gap the last period's average stands for the
        whole gap."""
        sample = self.sample()
        if self._frame_sample is sample:
            return self._frame
        sset = self._sensor_set
        currents = self._phase_currents()
        k = self.period
        emf_now = self._back_emf()
        if self._terminal_k is None:
            sset.terminal.start(self._terminal_voltages(currents, emf_now))
        elif k > self._terminal_k:
            then = self._emf_then
            emf = (0.5 * (then[0] + emf_now[0]), 0.5 * (then[1] + emf_now[1]),
                   0.5 * (then[2] + emf_now[2]))
            sset.terminal.advance(self._terminal_voltages(currents, emf), k - self._terminal_k)
        self._terminal_k = k
        self._emf_then = emf_now
        conducts = None
        if sset.phase_currents.low_side:
            tl = self._timeline
            conducts = low_side_conducts(self._cmd, currents, tl.force_on, tl.force_off)
        th = self._th
        frame = sset.frame(sample, self.motor.p * th, th, currents, conducts,
                           self._thermal.temperature_degc)
        self._frame = frame
        self._frame_sample = sample
        return frame

    @property
    def winding_temperature_degc(self) -> float:
        """The winding temperature (degC) of the thermal model (profile `thermal:`); without
        it the winding stays at thermal.initial_degc."""
        return self._thermal.temperature_degc

    def _thermal_period(self, k: int) -> None:
        """After every period (an 'after' hook, installed when the profile enables the thermal
        model): the winding temperature advances with the copper loss at the period's end held
        over the period, and the motor's resistance follows."""
        thermal = self._thermal
        thermal.advance(thermal.copper_loss_w(*self._currents_ab()))
        self._apply_winding_resistance()

    def _apply_winding_resistance(self) -> None:
        """The motor's resistance to the thermal model's R(T), when it moved by more than 1e-6
        relative (a change rebuilds the plant's tables)."""
        r = self._thermal.resistance_ohm()
        if abs(r - self.motor.r) > 1e-6 * self.motor.r:
            self.set_motor_param("resistance_ohm", r)

    def _currents_ab(self) -> tuple[float, float]:
        """(i_alpha, i_beta) at t_k through the motor's own currents(), either back-EMF shape:
        zero once the currents have died, an open phase cut."""
        if self._zero_current:
            return 0.0, 0.0
        ia, ib, _, _ = self.motor.currents(self._pa, self._pb, self._th)
        if self._open_phase is not None:
            ia, ib = _cut_phase(self._open_phase, ia, ib)[3:]
        return ia, ib

    def _back_emf(self) -> tuple[float, float, float]:
        return self.motor.phase_back_emf_v(self.motor.p * self._th, self._w)

    def _phase_currents(self) -> tuple[float, float, float]:
        """(i_a, i_b, i_c) at t_k, as truth() gives them."""
        if self._zero_current:
            return 0.0, 0.0, 0.0
        ia, ib, _, _ = self.motor.currents(self._pa, self._pb, self._th)
        if self._open_phase is not None:
            return _cut_phase(self._open_phase, ia, ib)[:3]
        return ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib

    def _terminal_voltages(self, currents: tuple[float, float, float],
                           emf: tuple[float, float, float]) -> tuple[float, float, float]:
        """The terminal voltages over the period just ended (sensor_set.terminal_voltages_v)
        under the command in force (stuck switches applied to a gate word)."""
        tl = self._timeline
        vdc = self._vdc
        driven = driven_leg_voltages(self._cmd, vdc, tl.force_on, tl.force_off)
        return terminal_voltages_v(driven, currents, emf, vdc, self.inverter.device_drop_v)

    @property
    def last_sample(self) -> SensorSample | None:
        """The most recent sample() (None before the first)."""
        return self._sample

    def encoder_count(self) -> int:
        """The encoder counter now, as the next sample would read it (no noise drawn)."""
        enc = self.sensors.encoder
        return enc.read(enc.position(self._revs, self._th))

    def truth(self) -> tuple[float, ...]:
        """The plant's true state at t_k, in the order of TRUTH_FIELDS."""
        c_truth = self._c_truth
        if c_truth is not None and not self._zero_current and self._open_phase is None:
            # The plain case in C (None: a locked load... the code below, the reference).
            record = c_truth(self.motor, self.load, self.period, self._T, self._pa, self._pb,
                             self._th, self._w, self._vdc, self._idc_int, self._u_int)
            if record is not None:
                return record
        m = self.motor
        pa, pb, th, w = self._pa, self._pb, self._th, self._w
        if self._zero_current:
            ia = ib = i_d = i_q = 0.0     # every leg open and no current: exactly none
        else:
            ia, ib, i_d, i_q = m.currents(pa, pb, th)
        t = self.period * self._T
        te = m.torque_ab(ia, ib, th) if m.trapezoidal else m.torque(i_d, i_q)
        tl = te if self.load.locked else self.load.torque(t, w)
        T = self._T
        if self._open_phase is not None and not self._zero_current:
            i_ph_a, i_ph_b, i_ph_c, ia, ib = _cut_phase(self._open_phase, ia, ib)
            return (t, i_ph_a, i_ph_b, i_ph_c, ia, ib, pa, pb,
                    math.hypot(pa, pb), te, w, w * RPM_PER_RAD_S, wrap_angle(m.p * th), th,
                    self._vdc, self._idc_int / T, tl, self._u_int[0] / T, self._u_int[1] / T)
        return (t, ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib, ia, ib, pa, pb,
                math.hypot(pa, pb), te, w, w * RPM_PER_RAD_S, wrap_angle(m.p * th), th,
                self._vdc, self._idc_int / T, tl, self._u_int[0] / T, self._u_int[1] / T)

    # ------------------------------------------------------- runtime changes
    @property
    def dc_source_voltage_v(self) -> float:
        """The source voltage set by set_dc_voltage or a ramp (without ripple)."""
        return self._dc_base_v

    def set_dc_voltage(self, v: float) -> None:
        """Source voltage (a sag or surge) from now on; ends a ramp in progress."""
        v = _finite_nonneg(v, "DC source voltage")
        self._dc_ramp = None
        self._dc_base_v = v
        self._apply_source(v + self._ripple_at((self.period + 0.5) * self._T))
        self._update_dc_hook()

    def _apply_source(self, v: float) -> None:
        v = max(v, 0.0)
        self.dc_link.source_v = v
        if self.dc_link.ideal:
            self._vdc = v
        self._scale_vectors()

    def _ripple_at(self, t: float) -> float:
        if self._ripple is None:
            return 0.0
        amplitude, hz = self._ripple
        return amplitude * sin(TWO_PI * hz * t)

    def ramp_dc_voltage(self, v: float, ramp_s: float) -> None:
        """Source voltage reaches v linearly over ramp_s from now (0: at once), then holds."""
        v = _finite_nonneg(v, "DC source voltage")
        ramp_s = _finite_nonneg(ramp_s, "ramp_s")
        if ramp_s < self._T:
            self.set_dc_voltage(v)
            return
        t0 = self.period * self._T
        self._dc_ramp = (t0, t0 + ramp_s, self._dc_base_v, v)
        self._update_dc_hook()

    def set_dc_ripple(self, amplitude_v: float, frequency_hz: float) -> None:
        """Adds amplitude_v sin(2 pi f t) to the source voltage (amplitude 0 removes it); the
        bus is clamped at 0 V."""
        amplitude_v = _finite_nonneg(amplitude_v, "ripple amplitude_v")
        frequency_hz = _finite_nonneg(frequency_hz, "ripple frequency_hz")
        if amplitude_v and not frequency_hz < 0.5 / self._T:
            raise ValueError(f"ripple frequency {frequency_hz:g} Hz is not below the Nyquist "
                             f"frequency of the {self._T * 1e6:g} us period")
        self._ripple = (amplitude_v, frequency_hz) if amplitude_v else None
        if self._ripple is None:
            self._apply_source(self._dc_base_v)
        self._update_dc_hook()

    def _update_dc_hook(self) -> None:
        active = self._ripple is not None or self._dc_ramp is not None
        if active and self._dc_hook not in self._hooks["before"]:
            self.add_period_hook(self._dc_hook, "before")
        elif not active and self._dc_hook in self._hooks["before"]:
            self.remove_period_hook(self._dc_hook)

    def _dc_hook(self, k: int) -> None:
        t = (k + 0.5) * self._T
        ramp = self._dc_ramp
        if ramp is not None:
            t0, t1, v0, v1 = ramp
            if t >= t1:
                self._dc_base_v = v1
                self._dc_ramp = None
                if self._ripple is None:
                    self._apply_source(v1)
                    self.remove_period_hook(self._dc_hook)
                    return
            else:
                self._dc_base_v = v0 + (v1 - v0) * (t - t0) / (t1 - t0)
        self._apply_source(self._dc_base_v + self._ripple_at(t))

    def motor_param(self, name: str) -> float:
        """A motor constant by MotorParams name or PARAM_ALIASES name."""
        fields = PARAM_ALIASES.get(name, (name,))
        try:
            return float(getattr(self.motor.params, fields[0]))
        except AttributeError:
            raise ValueError(f"unknown motor parameter {name!r}") from None

    def set_motor_param(self, name: str, value: float) -> None:
        """Changes a motor constant while running (a hotter winding, a weaker magnet...).

        ``name`` is a MotorParams field or a test plan's name (PARAM_ALIASES: inductance_h sets
        both axes). The phase currents are continuous across the change (the flux linkage is
        recomputed).
        """
        if name in ("pole_pairs", "back_emf"):
            raise ValueError(f"{name} cannot change while the plant runs")
        changes = {}
        for field_name in PARAM_ALIASES.get(name, (name,)):
            try:
                changes[field_name] = coerce(type(self.motor.params), field_name, value)
            except KeyError:
                names = [f.name for f in dataclasses.fields(self.motor.params)
                         if f.name != "pole_pairs"] + list(PARAM_ALIASES)
                raise ValueError(f"unknown motor parameter {name!r} "
                                 f"(known: {', '.join(names)})") from None
            except ValueError as exc:
                raise ValueError(f"motor parameter {name}: {exc}") from None
        _, _, i_d, i_q = self.motor.currents(self._pa, self._pb, self._th)
        self.motor.set_params(dataclasses.replace(self.motor.params, **changes))
        self._pa, self._pb = self.motor.flux_from_currents(i_d, i_q, self._th)
        self._rebuild()

    def ramp_motor_param(self, name: str, value: float, ramp_s: float) -> None:
        """A motor constant drifts linearly to ``value`` over ramp_s from now (0: at once),
        updated every PARAM_RAMP_UPDATE_S and exactly at the end. A new ramp of the same
        parameter replaces the old one; set_motor_param does not end a ramp."""
        start = self.motor_param(name)
        ramp_s = _finite_nonneg(ramp_s, "ramp_s")
        self._param_ramps.pop(name, None)
        if ramp_s < self._T:
            self.set_motor_param(name, value)
        else:
            self.set_motor_param(name, start)       # validates the name before the ramp runs
            _finite_nonneg(value, name)
            t0 = self.period * self._T
            self._param_ramps[name] = (t0, t0 + ramp_s, start, float(value), self.period)
        active = bool(self._param_ramps)
        if active and self._param_hook not in self._hooks["before"]:
            self.add_period_hook(self._param_hook, "before")
        elif not active and self._param_hook in self._hooks["before"]:
            self.remove_period_hook(self._param_hook)

    def _param_hook(self, k: int) -> None:
        t = (k + 0.5) * self._T
        every = max(1, round(PARAM_RAMP_UPDATE_S / self._T))
        for name, (t0, t1, v0, v1, due) in list(self._param_ramps.items()):
            if t >= t1:
                self.set_motor_param(name, v1)
                del self._param_ramps[name]
            elif k >= due:
                self.set_motor_param(name, v0 + (v1 - v0) * (t - t0) / (t1 - t0))
                self._param_ramps[name] = (t0, t1, v0, v1, k + every)
        if not self._param_ramps:
            self.remove_period_hook(self._param_hook)

    @property
    def open_phase(self) -> str | None:
        return None if self._open_phase is None else PHASES[self._open_phase]

    def set_open_phase(self, phase: str | None) -> None:
        """Disconnects phase 'a', 'b' or 'c' from its inverter leg (None reconnects): its
        current is forced to zero at once (the flux jumps to the constraint, as an arc that
        quenches within a period would leave it)."""
        if phase is not None and phase not in PHASES:
            raise ValueError(f"phase must be one of a, b, c (or None), got {phase!r}")
        self._open_phase = None if phase is None else PHASES.index(phase)
        self.network.set_open_phase(self._open_phase)
        if self._open_phase is not None and not self._zero_current:
            # Onto i_x = 0 now, so that the next sample already reads it.
            y = [self._pa, self._pb, self._w, self._th, self._vcap]
            self.network.project_phase(self._open_phase, y)
            self._pa, self._pb = y[0], y[1]
        self._net_dirty = True
        self._sample_k = -1
        self._rebuild()

    @property
    def gates_stuck(self) -> dict[str, str]:
        """Switch name -> 'on' | 'off' for every stuck switch."""
        tl = self._timeline
        out = {}
        for j, name in enumerate(SWITCHES):
            if tl.force_on & (1 << j):
                out[name] = "on"
            elif tl.force_off & (1 << j):
                out[name] = "off"
        return out

    def set_gate_stuck(self, switch: str, state: str | None) -> None:
        """Switch 'a_high' ... 'c_low' stuck 'on' or 'off' (None frees it), from now on."""
        if switch not in SWITCHES:
            raise ValueError(f"switch must be one of {', '.join(SWITCHES)}, got {switch!r}")
        if state not in ("on", "off", None):
            raise ValueError(f"state must be 'on', 'off' or None, got {state!r}")
        bit = 1 << SWITCHES.index(switch)
        tl = self._timeline
        tl.force_on &= ~bit
        tl.force_off &= ~bit
        if state == "on":
            tl.force_on |= bit
        elif state == "off":
            tl.force_off |= bit
        self.network.invalidate()
        self._rebuild()

    # ------------------------------------------------------------- hooks
    def add_period_hook(self, fn, when: str = "after") -> None:
        """fn(k) is called at the start of every step() that integrates period k ('before'),
        or after it with the new period k + 1 ('after'). Without hooks step() is the plain
        method: an installed hook costs a call per period, none costs nothing."""
        if when not in self._hooks:
            raise ValueError(f"when must be 'before' or 'after', got {when!r}")
        self._hooks[when].append(fn)
        self.step = self._hooked_step       # the instance attribute shadows the method

    def remove_period_hook(self, fn) -> None:
        for hooks in self._hooks.values():
            if fn in hooks:
                hooks.remove(fn)
        if not (self._hooks["before"] or self._hooks["after"]):
            self.__dict__.pop("step", None)

    def _hooked_step(self, gates: int | None = None, duty=None, legs: int | None = None) -> None:
        k = self.period
        for fn in tuple(self._hooks["before"]):
            fn(k)
        Plant.step(self, gates, duty, legs)
        for fn in tuple(self._hooks["after"]):
            fn(k + 1)

    def set_inverter_param(self, name: str, value: float) -> None:
        """Changes dead_time_s, device_drop_v or device_knee_a while running."""
        try:
            value = coerce(InverterParams, name, value)
        except KeyError:
            raise ValueError(f"unknown inverter parameter {name!r}") from None
        except ValueError as exc:
            raise ValueError(f"inverter parameter {name}: {exc}") from None
        if name == "dead_time_s" and value >= 0.5 * self._T:
            raise ValueError(f"dead_time_s must be shorter than half a period, got {value}")
        self.inverter = dataclasses.replace(self.inverter, **{name: value})
        self.network.set_inverter(self.inverter)
        self._rebuild()
        self._timeline.reset(self._cmd)

    def non_finite_state(self) -> tuple[str, float] | None:
        """(name, value) of the first integrator state that is not finite, or None: one
        expression while all are (x - x is 0.0 for a finite x, NaN for an infinity or NaN)."""
        pa, pb, w, th, vcap, vdc = self._pa, self._pb, self._w, self._th, self._vcap, self._vdc
        if (pa - pa) + (pb - pb) + (w - w) + (th - th) + (vcap - vcap) + (vdc - vdc) == 0.0:
            return None
        for name, value in (("speed_rad_s", w), ("theta_m_rad", th), ("psi_alpha", pa),
                            ("psi_beta", pb), ("v_cap", vcap), ("v_dc", vdc)):
            if not math.isfinite(value):
                return name, value
        return None

    @property
    def state(self) -> dict[str, float]:
        """Integrator state (for diagnostics and reference comparisons)."""
        return {"psi_alpha": self._pa, "psi_beta": self._pb, "speed_rad_s": self._w,
                "theta_m_rad": self._th, "revolutions": self._revs, "v_cap": self._vcap}



def _cut_phase(x: int, i_alpha: float, i_beta: float) -> tuple[float, float, float, float, float]:
    """Phase currents (a, b, c) and (alpha, beta) with phase x exactly zero and the other two
    exactly opposite (the state satisfies this to rounding; the record states it exactly)."""
    cur = [i_alpha, -0.5 * i_alpha + S32 * i_beta, -0.5 * i_alpha - S32 * i_beta]
    y, z = (x + 1) % 3, (x + 2) % 3
    d = 0.5 * (cur[y] - cur[z])
    cur[x], cur[y], cur[z] = 0.0, d, -d
    return cur[0], cur[1], cur[2], cur[0], (cur[0] + 2.0 * cur[1]) / SQRT3


def _finite_nonneg(value: float, name: str) -> float:
    v = float(value)
    if not math.isfinite(v) or v < 0.0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return v
