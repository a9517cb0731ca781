"""The reference stub's tuning for any surface-magnet motor, from its nameplate.

The stub's defaults (firmware_stub/core/defaults.h, derived in docs/stub.md) are tuned for the
paper's Table 1 motor. This module applies the same derivations to another motor: what the
bench must emulate for the stub to have a chance (the control period, the sensor ranges, the
encoder resolution: a bench profile's `timing` and `sensors`) and what the bench pushes to the
stub (a board file's `settings`). Every value comes with the formula and the numbers that gave
it (`lines`), so a user can check it against the paper's.

Where docs/stub.md takes a design choice for the paper's motor (a 5 Hz speed loop, a 1 ms
torque rise time), the rule here is the one that gives that choice on Table 1 and scales with
the motor; on the Table 1 nameplate every value reproduces the stub's default to within a few
per cent (tests/test_init.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from hil.design.ekf import EkfNoiseModel, design_gains

#: Control periods a bench may pick, longest first: the paper's 50 us, then round values.
PERIOD_LADDER_S = (50e-6, 40e-6, 25e-6, 20e-6, 10e-6, 5e-6, 4e-6, 2.5e-6, 2e-6, 1e-6)
#: One period's current step Vdc T / Ls at most this share of the current limit (paper 5.1 %).
CURRENT_STEP_SHARE = 1.0 / 16.0
#: The flux turns at most this far in one period at rated speed (paper 0.9 deg).
MAX_ANGLE_PER_PERIOD_RAD = math.radians(1.0)
#: The stub's encoder speed is a count difference over this many periods (speed_encoder.c).
ENCODER_WINDOW_PERIODS = 64
#: Counts per period at rated speed the encoder should give (paper 10.2): below it one count's
#: step in the windowed speed moves the speed PI's torque by more than T_lim / 80.
MIN_COUNTS_PER_PERIOD = 10.0
#: Encoder resolution the bench offers: the paper's 1024 lines up to the stub's 65536 counts.
MIN_ENCODER_LINES, MAX_ENCODER_LINES = 1024, 16384
#: The stub's encoder-loss check runs above this mechanical speed (defaults.h).
ENCODER_LOSS_MIN_SPEED_RAD_S = 10.0
#: Pull-out torque over the torque limit at the flux reference: Table 1's 2.9 N m on 2 N m (the
#: load angle at the limit is then 44 deg, as in docs/stub.md).
PULLOUT_MARGIN = 1.43
#: Encoder loss must be reported within this time (the generated plan's requirement).
ENCODER_LOSS_DETECTION_S = 0.02


@dataclass(frozen=True)
class Motor:
    """What the stub's tuning needs of a motor and its drive (SI units, peak phase current)."""

    pole_pairs: int
    resistance_ohm: float
    inductance_h: float          # per phase, the q axis: the stub drives i_d = 0
    flux_linkage_wb: float
    inertia_kgm2: float
    rated_speed_rad_s: float     # mechanical
    dc_link_v: float
    current_limit_a: float


@dataclass
class StubTuning:
    """The bench's side (period, sensors) and the board file's settings, with their formulas."""

    control_period_s: float
    encoder_lines_per_rev: int
    current_full_scale_a: float
    dc_voltage_full_scale_v: float
    overvoltage_trip_v: float
    settings: dict[str, float] = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)   # setting -> its formula, one line
    lines: list[str] = field(default_factory=list)

    def set(self, name: str, value: float, note: str) -> None:
        self.settings[name] = value
        self.notes[name] = note
        self.lines.append(f"{name} = {note}")


def control_period_s(m: Motor, given: float | None = None) -> tuple[float, str]:
    """The longest period of the ladder whose current step and flux turn stay within the
    paper's shares (or the given one)."""
    if given is not None:
        return given, f"control period T = {given * 1e6:g} us (given)"
    w_e = m.pole_pairs * m.rated_speed_rad_s
    t_current = CURRENT_STEP_SHARE * m.inductance_h * m.current_limit_a / m.dc_link_v
    t_angle = MAX_ANGLE_PER_PERIOD_RAD / w_e
    bound = min(t_current, t_angle)
    period = next((t for t in PERIOD_LADDER_S if t <= bound * (1 + 1e-9)), PERIOD_LADDER_S[-1])
    short = ("" if period <= bound * (1 + 1e-9) else
             f"; WARNING: even {period * 1e6:g} us is longer than that: a larger current step or flux "
             "turn per period than the paper's")
    return period, (
        f"control period T = the longest of {', '.join(f'{t * 1e6:g}' for t in PERIOD_LADDER_S)} us "
        f"with one period's current step Vdc T / Ls <= I / 16 (T <= Ls I / (16 Vdc) = "
        f"{m.inductance_h:g} * {m.current_limit_a:g} / (16 * {m.dc_link_v:g}) = {t_current * 1e6:.3g} us) "
        f"and the flux turning <= 1 deg a period at rated speed (T <= {t_angle * 1e6:.3g} us): "
        f"{period * 1e6:g} us (Table 1: 50 us, a 5.1 % current step, 0.9 deg){short}")


def encoder_lines(m: Motor, period_s: float, given: int | None = None) -> tuple[int, str]:
    """Lines per revolution: a power of two from 1024 giving >= 10 counts per period at rated
    speed, at most the stub's 65536 counts (or the given number)."""
    if given is not None:
        return given, f"encoder {given} lines per revolution (given)"
    need_counts = MIN_COUNTS_PER_PERIOD * 2.0 * math.pi / (m.rated_speed_rad_s * period_s)
    lines = MIN_ENCODER_LINES
    while 4 * lines < need_counts and lines < MAX_ENCODER_LINES:
        lines *= 2
    per_period = 4 * lines * m.rated_speed_rad_s * period_s / (2.0 * math.pi)
    return lines, (
        f"encoder lines: a power of two from 1024 with >= 10 counts per period at rated speed "
        f"(10 x 2 pi / (w_r T) = {need_counts:.0f} counts per revolution; at most 16384 lines, "
        f"the stub's 65536 counts): {lines} lines, {per_period:.3g} counts per period (Table 1: "
        f"1024 lines, 10.2). One count in the stub's 64-period speed window moves the speed PI's "
        f"torque by T_lim / (8 counts per period)")


def tune_stub(m: Motor, period_given: float | None = None,
              lines_given: int | None = None) -> StubTuning:
    """The stub's tuning for motor `m`: docs/stub.md's derivations with m's values."""
    period, period_line = control_period_s(m, period_given)
    lines, lines_line = encoder_lines(m, period, lines_given)
    p, psi, ls, current = m.pole_pairs, m.flux_linkage_wb, m.inductance_h, m.current_limit_a
    vdc, j, w_r = m.dc_link_v, m.inertia_kgm2, m.rated_speed_rad_s
    torque = 1.5 * p * psi * current
    overcurrent = 1.4 * current
    t = StubTuning(control_period_s=period, encoder_lines_per_rev=lines,
                   current_full_scale_a=1.25 * overcurrent,
                   dc_voltage_full_scale_v=vdc * 10.0 / 7.0, overvoltage_trip_v=vdc * 9.0 / 7.0)
    t.lines += [period_line, lines_line,
                f"current sensor full scale +-1.25 overcurrent_a = +-{t.current_full_scale_a:.4g} A "
                f"on 12 bits (Table 1: +-25 A for the 20 A trip)",
                f"DC-voltage sensor full scale 10/7 Vdc = {t.dc_voltage_full_scale_v:.4g} V, overvoltage "
                f"trip 9/7 Vdc = {t.overvoltage_trip_v:.4g} V (Table 1: 100 V and 90 V on 70 V)"]
    t.set("stator_resistance_ohm", m.resistance_ohm, f"R = {m.resistance_ohm:g} ohm (nameplate)")
    t.set("stator_inductance_h", ls, f"Ls = Lq = {ls:g} H (nameplate; the stub drives i_d = 0)")
    t.set("magnet_flux_wb", psi, f"psi_f = {psi:.6g} Wb")
    t.set("torque_limit_nm", torque,
          f"3/2 p psi_f I = 1.5 * {p} * {psi:.5g} * {current:g} = {torque:.5g} N m (Table 1: 2 N m)")
    t.set("overcurrent_a", overcurrent,
          f"1.4 I = 1.4 * {current:g} = {overcurrent:.4g} A (Table 1: 20 A on 14.4 A)")
    iq_half = 0.5 * current
    flux_half = math.hypot(psi, ls * iq_half)
    flux_pullout = PULLOUT_MARGIN * ls * current
    flux_ref = max(flux_half, flux_pullout)
    t.set("flux_ref_wb", flux_ref,
          f"the larger of the i_d = 0 stator flux at half the torque limit, sqrt(psi_f^2 + "
          f"(Ls I/2)^2) = sqrt({psi:.5g}^2 + ({ls:g} * {iq_half:.4g})^2) = {flux_half:.5g} Wb, and "
          f"the flux whose pull-out torque 3/2 p psi_s psi_f / Ls is 1.43 T_lim (Table 1's margin: "
          f"2.9 N m on 2), 1.43 Ls I = {flux_pullout:.5g} Wb: {flux_ref:.5g} Wb (Table 1: 0.0990)")
    w_flux = vdc / (math.sqrt(3.0) * flux_ref * p)
    if w_flux < w_r:
        t.lines.append(f"WARNING: at this flux the DC link supports {w_flux * 30 / math.pi:.0f} rpm "
                       f"(Vdc / (sqrt3 psi_ref p)), below the rated speed")
    flux_band = 2.0 / 3.0 * vdc * period
    t.set("flux_band_wb", flux_band,
          f"one period's flux step 2/3 Vdc T = 2/3 * {vdc:g} * {period:g} = {flux_band:.4g} Wb "
          f"(Table 1: 2.33 mWb)")
    torque_band = 1.5 * p * psi * vdc / math.sqrt(3.0) * period / ls
    t.set("torque_band_nm", torque_band,
          f"one period's torque step at standstill 3/2 p psi_f (Vdc/sqrt3) T / Ls = 1.5 * {p} * "
          f"{psi:.5g} * {vdc / math.sqrt(3.0):.4g} * {period:g} / {ls:g} = {torque_band:.4g} N m "
          f"(Table 1: 0.0586)")
    # The paper's 5 Hz is, to 1.5 %, the bandwidth whose time constant 1/w_b is half the
    # torque-limited ramp from half to rated speed: the step response is then the paper's,
    # scaled in time by the ramp, whatever the motor.
    accel = torque / j
    w_b = 4.0 * torque / (j * w_r)
    f_b = w_b / (2.0 * math.pi)
    t.lines.append(
        f"speed-loop bandwidth w_b = 2 / ramp = 4 T_lim / (J w_r) = 4 * {torque:.4g} / ({j:g} * "
        f"{w_r:.4g}) = {w_b:.4g} rad/s = {f_b:.3g} Hz (1/w_b is half the torque-limited ramp from half "
        f"to rated speed, (w_r/2) / (T_lim/J) = {0.5 * w_r / accel * 1e3:.4g} ms; Table 1: 5.07 Hz "
        f"against the stub's 5 Hz)")
    t.set("speed_kp_nm_per_rad_s", 2.0 * j * w_b,
          f"2 J w_b = 2 * {j:g} * {w_b:.4g} = {2 * j * w_b:.4g} N m/(rad/s) (double pole at w_b on "
          f"1/(J s); Table 1: 0.0503)")
    t.set("speed_ki_nm_per_rad", j * w_b ** 2,
          f"J w_b^2 = {j:g} * {w_b:.4g}^2 = {j * w_b ** 2:.4g} N m/rad (Table 1: 0.790)")
    t.set("speed_lpf_cutoff_hz", 4.0 * f_b,
          f"4 f_b = 4 * {f_b:.3g} = {4 * f_b:.3g} Hz (the conventional estimate's filter; Table 1: 20 Hz)")
    rise_s = ls * current / vdc
    model = EkfNoiseModel(control_period_s=period, pole_pairs=p, torque_limit_nm=torque,
                          inertia_kg_m2=j, torque_rise_time_s=rise_s, dc_link_v=vdc,
                          magnet_flux_wb=psi, stator_inductance_h=ls)
    # the model's own flux reference is the i_d = 0 one: sigma_v with the one pushed
    angle_std = 2.0 / 3.0 * vdc * period / (flux_ref * math.sqrt(3.0))
    gains = design_gains(period, angle_std ** 2, model.speed_increment_std_rad_s() ** 2)
    t.lines.append(
        f"EKF noise model (hil/design/ekf.py): torque rise time tau = Ls I / Vdc = {ls:g} * {current:g} "
        f"/ {vdc:g} = {rise_s * 1e3:.4g} ms (Table 1: 0.985 ms, the stub's 1 ms); sigma_v = (2/3 Vdc T) "
        f"/ (psi_ref sqrt3) = {angle_std:.5g} rad; sigma_w = (p T_lim / J) T^2 / tau = "
        f"{model.speed_increment_std_rad_s():.5g} rad/s per period; DLQE poles |s| = "
        f"{max(gains.poles_rad_s):.4g} rad/s")
    t.set("ekf_k1", gains.k1, f"DLQE k1 = {gains.k1:.6g} (Table 1: 0.0568)")
    t.set("ekf_k2", gains.k2_rad_s, f"DLQE k2 = {gains.k2_rad_s:.6g} rad/s (Table 1: 32.1)")
    t.set("ekf_k3", gains.k3_rad_s, f"DLQE k3 = {gains.k3_rad_s:.6g} rad/s (Table 1: 0.446)")
    current_bw = 1.0 / (20.0 * period)
    t.set("current_bandwidth_hz", current_bw,
          f"FOC current loop at 1/20 of the sampling rate, 1 / (20 T) = {current_bw:.5g} Hz (63 deg "
          f"of phase margin with one period of delay; Table 1: 1000 Hz)")
    timeout = 0.5 * ENCODER_LOSS_DETECTION_S
    edge_s = 2.0 * math.pi / (ENCODER_LOSS_MIN_SPEED_RAD_S * 4 * lines)
    t.set("encoder_loss_timeout_s", timeout,
          f"half the 20 ms the encoder-loss plan allows = {timeout:g} s; at the stub's 10 rad/s "
          f"threshold an edge comes every 2 pi / (10 * {4 * lines}) = {edge_s * 1e3:.3g} ms, "
          f"{timeout / edge_s:.0f} edges within it (Table 1: 0.01 s)")
    return t
