"""The trapezoidal back-EMF machine (motor.back_emf: trapezoidal) against closed forms and an
independent per-phase integration by scipy's solve_ivp.

The reference here is written from the physics, not from plant_rt's code: phase currents as
the state (the plant integrates the stationary-frame flux linkage), each phase's back-EMF the
trapezoid drawn through its corners, the floating star point by its voltage
v_n = (sum v_x - sum e_x)/3 (which keeps i_a + i_b + i_c = 0 and so drops the EMF's
zero-sequence part by itself).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from configfile.source import ConfigError
from plant_rt import TRUTH_FIELDS, Plant, load_profile
from plant_rt.motor import MotorModel

F = {name: i for i, name in enumerate(TRUTH_FIELDS)}
TWO_PI = 2.0 * math.pi
THIRD = TWO_PI / 3.0
QUIET = {"sensors": {"current": {"noise_rms_counts": 0.0}, "dc_voltage": {"noise_rms_counts": 0.0}}}
# GATES bits (protocol/SPEC.md): a_high 0x01, a_low 0x02, b_high 0x04, b_low 0x08, c_high 0x10,
# c_low 0x20. Table 2's V1 (100) .. V6 (101): every leg driven.
VECTOR_WORDS = (0x29, 0x25, 0x26, 0x16, 0x1A, 0x19)


def trapezoid_profile(flat_top_deg: float = 120.0, **sections):
    merged = {k: dict(v) for k, v in QUIET.items()}
    for key, value in sections.items():
        merged[key] = {**merged.get(key, {}), **value}
    merged["motor"] = {"back_emf": "trapezoidal", "back_emf_flat_top_deg": flat_top_deg,
                       **merged.get("motor", {})}
    return load_profile(overrides=merged)


def unit_emf(theta_e: float, flat_top_deg: float) -> float:
    """Phase a's back-EMF per (omega_e psi_r): the trapezoid through its corners, zero where
    -sin is, -1 on the flat top centred on 90 deg, +1 on the one centred on 270 deg."""
    ramp = 0.5 * (math.pi - math.radians(flat_top_deg))
    x = theta_e % TWO_PI
    return float(np.interp(x, [0.0, ramp, math.pi - ramp, math.pi + ramp, TWO_PI - ramp, TWO_PI],
                           [0.0, -1.0, -1.0, 1.0, 1.0, 0.0]))


def phase_emfs(theta_e: float, omega_e: float, psi_r: float, flat_top_deg: float) -> list[float]:
    return [omega_e * psi_r * unit_emf(theta_e - x * THIRD, flat_top_deg) for x in range(3)]


def terminal_voltages(word: int, vdc: float) -> list[float]:
    """Terminal voltages to DC- of a word with every leg driven (high switch: v_dc)."""
    return [vdc if word >> (2 * x) & 1 else 0.0 for x in range(3)]


# ------------------------------------------------------------------ the shape itself
@pytest.mark.parametrize("flat_top_deg", [30.0, 120.0, 150.0])
def test_phase_back_emf_is_the_trapezoid(flat_top_deg):
    """Peak omega_e psi_r, the zero crossings of -sin, a flat top of back_emf_flat_top_deg,
    phases 120 deg apart; the sinusoidal machine gives -omega_e psi_r sin."""
    profile = trapezoid_profile(flat_top_deg, motor={"pole_pairs": 2})
    motor = MotorModel(profile.motor)
    psi_r, w_m = profile.motor.flux_linkage_wb, 150.0
    peak = 2 * w_m * psi_r
    grid = np.linspace(-math.pi, 3 * math.pi, 7201)      # 1/1800 of a turn: 0.2 deg
    emf = np.array([motor.phase_back_emf_v(x, w_m) for x in grid])
    expected = np.array([phase_emfs(x, 2 * w_m, psi_r, flat_top_deg) for x in grid])
    assert np.abs(emf - expected).max() < 1e-12 * peak
    assert np.abs(emf).max() == pytest.approx(peak, rel=1e-15)
    # The flat top: the angles where |e_a| is the peak span flat_top_deg (to the grid step).
    step_deg = math.degrees(grid[1] - grid[0])
    one_turn = (grid >= 0.0) & (grid < TWO_PI)
    at_peak = one_turn & (np.abs(emf[:, 0]) >= peak * (1 - 1e-12))
    assert at_peak.sum() * step_deg == pytest.approx(2 * flat_top_deg, abs=2 * step_deg)
    # Zero crossings where -sin has them (0 and pi, phases b and c 120 deg later).
    for x in range(3):
        for zero in (x * THIRD, math.pi + x * THIRD):
            assert abs(motor.phase_back_emf_v(zero, w_m)[x]) < 1e-12 * peak
            before = motor.phase_back_emf_v(zero - 0.01, w_m)[x]
            after = motor.phase_back_emf_v(zero + 0.01, w_m)[x]
            assert before * after < 0.0
    sine = MotorModel(load_profile(overrides={"motor": {"pole_pairs": 2}}).motor)
    for x in grid[::37]:
        for n, e in enumerate(sine.phase_back_emf_v(x, w_m)):
            assert e == pytest.approx(-peak * math.sin(x - n * THIRD), abs=1e-12 * peak)


def test_trapezoid_needs_equal_inductances_and_a_flat_top_in_range():
    with pytest.raises(ConfigError, match="inductance_d_h.*inductance_q_h"):
        trapezoid_profile(motor={"inductance_d_h": 3e-3, "inductance_q_h": 7e-3})
    for bad in (0.0, 180.0, -5.0):
        with pytest.raises(ConfigError, match="back_emf_flat_top_deg"):
            trapezoid_profile(bad)
    with pytest.raises(ConfigError, match="back_emf"):
        load_profile(overrides={"motor": {"back_emf": "square"}})
    plant = Plant(trapezoid_profile())
    assert not plant.c_kernel
    with pytest.raises(ValueError, match="sinusoidal only"):
        plant.use_c_kernel(True)
    with pytest.raises(ValueError, match="inductance_d_h"):
        plant.set_motor_param("inductance_d_h", 3e-3)
    with pytest.raises(ValueError, match="back_emf"):
        plant.set_motor_param("back_emf", "sinusoidal")


# ------------------------------------------------------------------ open circuit
@pytest.mark.parametrize("flat_top_deg", [120.0, 90.0])
def test_free_spin_line_voltage_is_the_closed_form(flat_top_deg):
    """All switches off, no damping or load: the rotor keeps its speed and the plant's
    line-to-line voltage v_ab = 3/2 u_alpha - sqrt3/2 u_beta (its average over each period)
    is the line back-EMF e_a - e_b, averaged over the same period."""
    w_m = 80.0
    profile = trapezoid_profile(flat_top_deg, motor={"pole_pairs": 2, "damping_nm_per_rad_s": 0.0},
                                initial={"speed_rad_s": w_m, "theta_m_rad": 0.3})
    plant = Plant(profile)
    psi_r, T, p = profile.motor.flux_linkage_wb, plant.control_period_s, 2
    peak = 2 * p * w_m * psi_r                   # line peak: two flat tops of opposite sign
    assert peak < profile.dc_link.source_voltage_v       # no diode conducts
    theta0 = p * 0.3
    worst = 0.0
    seen = []
    for k in range(1, 1601):                     # 80 ms: 2 electrical turns
        plant.step(gates=0)
        t = plant.truth()
        assert (t[F["i_a"]], t[F["i_b"]], t[F["torque_nm"]]) == (0.0, 0.0, 0.0)
        assert t[F["speed_rad_s"]] == w_m
        v_ab = 1.5 * t[F["u_alpha"]] - 0.5 * math.sqrt(3) * t[F["u_beta"]]
        sub = np.linspace(theta0 + p * w_m * (k - 1) * T, theta0 + p * w_m * k * T, 401)
        line = [e[0] - e[1] for e in (phase_emfs(x, p * w_m, psi_r, flat_top_deg) for x in sub)]
        expected = np.trapezoid(line, sub) / (sub[-1] - sub[0])
        worst = max(worst, abs(v_ab - expected))
        seen.append(v_ab)
    # 401 points of a piecewise-linear curve: the trapezoid rule is exact but for a kink
    # inside a sub-interval, (slope jump) h^2 / 8 over the period; 1e-8 of the peak covers it.
    assert worst < 1e-8 * peak
    assert max(seen) > 0.98 * peak and min(seen) < -0.98 * peak


# ------------------------------------------------------------------ driven, vs solve_ivp
def phase_model(motor, flat_top_deg):
    """d/dt (i_a, i_b, w, theta_m) of the star-connected machine, written per phase."""
    p, r, psi_r = motor.pole_pairs, motor.resistance_ohm, motor.flux_linkage_wb
    ell, j, b = motor.inductance_d_h, motor.inertia_kgm2, motor.damping_nm_per_rad_s

    def f(_t, x, v):
        ia, ib, w, th = x
        cur = (ia, ib, -ia - ib)
        e = phase_emfs(p * th, p * w, psi_r, flat_top_deg)
        vn = (sum(v) - sum(e)) / 3.0                 # floating star point
        di = [(v[n] - vn - r * cur[n] - e[n]) / ell for n in range(2)]
        torque = p * psi_r * sum(unit_emf(p * th - n * THIRD, flat_top_deg) * cur[n]
                                 for n in range(3))
        return [di[0], di[1], (torque - b * w) / j, w]
    return f


def driven_run(profile, periods: int, choose) -> dict:
    """The plant and solve_ivp period by period from the same start, `choose(theta_e)` giving
    each period's gate word from the reference's angle at the period's start."""
    motor, T = profile.motor, profile.control_period_s
    flat = motor.back_emf_flat_top_deg
    vdc = profile.dc_link.source_voltage_v
    f = phase_model(motor, flat)
    plant = Plant(profile)
    x = [0.0, 0.0, profile.initial.speed_rad_s, profile.initial.theta_m_rad]
    p = motor.pole_pairs
    peak = err_i = err_w = err_th = err_te = 0.0
    speeds = []
    for _ in range(periods):
        word = choose(p * x[3])
        sol = solve_ivp(f, (0.0, T), x, method="DOP853", rtol=1e-11, atol=1e-12,
                        args=(terminal_voltages(word, vdc),))
        x = list(sol.y[:, -1])
        plant.step(gates=word)
        t = plant.truth()
        ia, ib = x[0], x[1]
        peak = max(peak, abs(ia), abs(ib), abs(ia + ib))
        err_i = max(err_i, abs(ia - t[F["i_a"]]), abs(ib - t[F["i_b"]]))
        err_w = max(err_w, abs(x[2] - t[F["speed_rad_s"]]))
        err_th = max(err_th, abs(math.remainder(x[3] - t[F["theta_m_rad"]], TWO_PI)))
        cur = (ia, ib, -ia - ib)
        te = p * motor.flux_linkage_wb * sum(unit_emf(p * x[3] - n * THIRD, flat) * cur[n]
                                             for n in range(3))
        err_te = max(err_te, abs(te - t[F["torque_nm"]]))
        speeds.append(x[2])
    return {"peak": peak, "err_i": err_i, "err_w": err_w, "err_th": err_th, "err_te": err_te,
            "w_max": max(np.abs(speeds)), "periods": periods}


def six_step_180(theta_e: float) -> int:
    """180-deg six-step: the Table 2 vector 90 deg (plus a little) ahead of the rotor."""
    return VECTOR_WORDS[round((theta_e + math.pi / 2 + 0.3) / (math.pi / 3)) % 6]


@pytest.mark.parametrize("case", ["six_step", "six_step_network", "fixed_vector"])
def test_driven_trapezoid_matches_solve_ivp(case):
    """Six-step words by angle (accelerating from 150 rad/s) and V1 held from standstill (the
    rotor swings through flat tops and ramps): phase currents, speed, angle and torque follow
    the per-phase reference. six_step_network runs the same through the general network
    (plant_rt.circuit, which a DC link with a source resistance takes: 1e-12 ohm here).

    The bound is the sinusoidal accuracy test's (tests/test_plant_accuracy.py: 1e-5 of the
    peak current, 1e-6 of the speed) tightened tenfold for the current: RK4 at 50 us with its
    steps cut at the trapezoid's corners reaches ~7e-9 of the peak here (the network, which
    ends its steps at the corners as events, ~1e-9); an RK4 step across a
    corner (where d e/dt jumps, so the step loses its order: a local error ~ jump h^3) leaves
    ~9e-6 of the peak after 1000 periods of six-step, which the limit refuses."""
    if case == "six_step":
        profile = trapezoid_profile(initial={"speed_rad_s": 150.0, "theta_m_rad": 0.2},
                                    motor={"pole_pairs": 2})
        run = driven_run(profile, 1000, six_step_180)
    elif case == "six_step_network":
        profile = trapezoid_profile(initial={"speed_rad_s": 150.0, "theta_m_rad": 0.2},
                                    motor={"pole_pairs": 2},
                                    dc_link={"source_resistance_ohm": 1e-12})
        run = driven_run(profile, 1000, six_step_180)
    else:
        profile = trapezoid_profile(100.0, initial={"theta_m_rad": 2.0})
        run = driven_run(profile, 1000, lambda _theta: VECTOR_WORDS[0])
    assert run["peak"] > 5.0 and run["w_max"] > 50.0     # currents and speed worth the name
    assert run["err_i"] < 1e-6 * run["peak"]
    kt = 2 * profile.motor.pole_pairs * profile.motor.flux_linkage_wb
    assert run["err_te"] < 1e-6 * kt * run["peak"]
    assert run["err_w"] < 1e-6 * run["w_max"]
    assert run["err_th"] < 1e-6


# ------------------------------------------------------------------ torque constant
SECTORS_120 = (  # theta_e sector start (deg) -> (high phase, low phase) of 120-deg six-step
    (210, 0, 1), (270, 0, 2), (330, 1, 2), (30, 1, 0), (90, 2, 0), (150, 2, 1))
SECTOR_START = {(hi, lo): start for start, hi, lo in SECTORS_120}
LEG_BITS = ((0x01, 0x02), (0x04, 0x08), (0x10, 0x20))


def six_step_120(theta_e: float) -> tuple[int, int, int]:
    """(gate word, high phase, low phase): two legs driven where their flat tops overlap, the
    third open."""
    deg = math.degrees(theta_e) % 360.0
    for start, hi, lo in SECTORS_120:
        if (deg - start) % 360.0 < 60.0:
            return LEG_BITS[hi][0] | LEG_BITS[lo][1], hi, lo
    raise AssertionError(deg)


def test_torque_constant_of_120_deg_six_step_is_2_p_psi():
    """Ideal 120-deg six-step on the 120-deg flat top: the driven pair carries +I and -I,
    each where its EMF is flat, the third phase nothing, so T = p psi_r (1 - (-1)) I =
    2 p psi_r I. Spinning at an (almost) constant speed with the pair switched by angle:
    in every period that starts and ends with the open phase's diode decay over (its current
    exactly zero) inside the sector's middle, T / I = 2 p psi_r; and the open phase's voltage
    to the star point is its back-EMF less the zero-sequence part, e_x - sum e / 3 (its
    current stays zero), averaged over the period as the plant's u is."""
    p = 2
    profile = trapezoid_profile(motor={"pole_pairs": p, "inertia_kgm2": 10.0},
                                initial={"speed_rad_s": 40.0})
    plant = Plant(profile)
    psi_r = profile.motor.flux_linkage_wb
    kt = 2 * p * psi_r
    names = ("i_a", "i_b", "i_c")
    axes = ((1.0, 0.0), (-0.5, 0.5 * math.sqrt(3)), (-0.5, -0.5 * math.sqrt(3)))
    checked = 0
    for _ in range(4000):
        before = plant.truth()
        theta0 = before[F["theta_e_rad"]]
        word, hi, lo = six_step_120(theta0)
        open_phase = 3 - hi - lo
        plant.step(gates=word)
        t = plant.truth()
        theta1 = theta0 + math.remainder(t[F["theta_e_rad"]] - theta0, TWO_PI)
        into = (math.degrees(theta1) - SECTOR_START[hi, lo]) % 360.0
        if not 5.0 < into < 55.0:               # still in the sector, away from its edges
            continue
        if (abs(before[F[names[open_phase]]]) > 1e-9 or abs(t[F[names[open_phase]]]) > 1e-9
                or abs(t[F[names[hi]]]) < 1.0):
            continue
        assert t[F[names[lo]]] == pytest.approx(-t[F[names[hi]]], rel=1e-9)
        assert t[F["torque_nm"]] == pytest.approx(kt * t[F[names[hi]]], rel=1e-9)
        w_e = p * t[F["speed_rad_s"]]
        sub = np.linspace(theta0, theta1, 401)
        star = [e[open_phase] - sum(e) / 3 for e in (phase_emfs(x, w_e, psi_r, 120.0)
                                                     for x in sub)]
        expected = np.trapezoid(star, sub) / (theta1 - theta0)
        ex = axes[open_phase]
        v_open = ex[0] * t[F["u_alpha"]] + ex[1] * t[F["u_beta"]]
        assert v_open == pytest.approx(expected, abs=1e-6 * w_e * psi_r)
        checked += 1
    assert checked > 1000
