"""The plant against analytic results: locked rotor, six-step no-load speed, energy balance,
eq. (6) torque, dead-time voltage error, PWM and computation-delay timing, loads.

The runs of the locked rotor, six-step, energy-balance, regeneration and dead-time tests, the
six-step balance and the energy terms are bench/_plant_accuracy_physics.py's (`python -m bench
plant_accuracy` prints the values); the tests here assert the limits."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bench._plant_accuracy_physics import (ENERGY_BALANCE_CASES, LOCKED_ROTOR_CASES, V1, V2,
                                           VECTORS, F, clarke, dead_time_leg_voltages,
                                           dead_time_truth, energy_balance_terms,
                                           locked_rotor_run, regeneration_run, six_step_run)
from bench._plant_accuracy_physics import quiet_profile as profile
from plant_rt import Plant


# ------------------------------------------------------------------ locked rotor
@pytest.mark.parametrize("ld,lq,theta,axis_l", list(LOCKED_ROTOR_CASES.values()))
def test_locked_rotor_dc_current_is_v_over_r_with_l_over_r(ld, lq, theta, axis_l):
    """V1 held on a locked rotor: i_a(t) = (2U/3)/R (1 - exp(-t R/L)), i_b = i_c = -i_a/2.
    (Ld != Lq: at theta 0 V1 lies along the d-axis, L = Ld; turned 90 deg along -q, L = Lq.)"""
    run = locked_rotor_run(ld, lq, theta, axis_l)  # 25 time constants
    r, i_final = run["r"], run["i_final"]
    for t, expected in run["trace"]:
        assert abs(t[F["i_a"]] - expected) < 1e-9 * i_final
        assert abs(t[F["i_b"]] + expected / 2) < 1e-9 * i_final
        assert abs(t[F["i_c"]] + expected / 2) < 1e-9 * i_final
        assert t[F["speed_rad_s"]] == 0.0 and t[F["theta_m_rad"]] == theta
    assert abs(t[F["i_a"]] - 70.0 * 2 / 3 / r) < 1e-6
    # Power in = copper loss at steady state: U i_dc = 1.5 R |i|^2.
    assert abs(70.0 * t[F["i_dc"]] - 1.5 * r * t[F["i_a"]] ** 2) < 1e-6 * 70.0 * t[F["i_dc"]]


def test_locked_rotor_current_follows_resistance_and_source_changes():
    p = profile(load={"locked": True}, dc_link={"source_voltage_v": 7.0})
    plant = Plant(p)
    for _ in range(4000):
        plant.step(gates=V1)
    before = plant.truth()[F["i_a"]]
    assert before == pytest.approx(7.0 * 2 / 3 / 0.466, rel=1e-6)
    plant.set_motor_param("resistance_ohm", 0.466 * 1.2)        # a hotter winding
    assert plant.truth()[F["i_a"]] == pytest.approx(before, rel=1e-12)   # current continuous
    for _ in range(6000):
        plant.step()
    assert plant.truth()[F["i_a"]] == pytest.approx(7.0 * 2 / 3 / (0.466 * 1.2), rel=1e-6)
    plant.set_dc_voltage(5.0)                                      # a sag
    for _ in range(6000):
        plant.step()
    assert plant.truth()[F["i_a"]] == pytest.approx(5.0 * 2 / 3 / (0.466 * 1.2), rel=1e-6)
    assert plant.truth()[F["v_dc"]] == 5.0
    with pytest.raises(ValueError, match="resistance_ohm"):
        plant.set_motor_param("resistance_ohm", -1.0)
    with pytest.raises(ValueError, match="unknown motor parameter"):
        plant.set_motor_param("colour", 1.0)


# ---------------------------------------------------------- six-step no load
def test_six_step_no_load_speed_matches_back_emf_balance():
    """Self-commutated six-step (vector nearest 90 deg ahead of the rotor) at 5 us sampling.

    The inertia is cut tenfold so the speed settles within the test; it does not enter the
    steady state. The balance lands 8 % below the naive 2U/(pi psi_m) because of the R and
    w L i_d drops, so this checks the Table 2 voltages, R, L and psi_m together."""
    run = six_step_run()                      # the balance: six_step_speed
    w_pred, w_sim = run["w_pred"], run["w_sim"]
    assert 0.85 < w_pred / run["naive"] < 0.95   # naive: 2U/(pi psi_m)
    assert abs(w_sim - w_pred) < 1e-3 * w_pred


# --------------------------------------------------------------- energy balance
@pytest.mark.parametrize("ld,lq,dead_time", list(ENERGY_BALANCE_CASES.values()))
def test_energy_balance(ld, lq, dead_time):
    """DC-link energy = copper loss + kinetic energy change + damping + load work (+ the
    change of stored magnetic energy), from rest with a constant plus speed-proportional
    load. Sinusoidal PWM duties at 10 us (with dead time: diodes conduct every edge).

    Issue 2 asks for 0.5 %; the balance closes to about 1e-7 without dead time and 5e-5 with
    it (the trapezoid rule on the sampled truth is the limit), so 0.1 % is asserted."""
    e = energy_balance_terms(ld, lq, dead_time)
    assert e["dc"] > 1.0 and e["kinetic"] > 0.2 and e["load"] > 0.1
    out = e["copper"] + e["kinetic"] + e["damping"] + e["load"] + e["magnetic"]
    assert abs(e["dc"] - out) < 1e-3 * e["dc"]


def test_regeneration_through_diodes_raises_unidirectional_bus_voltage():
    """Coasting at twice rated speed with all switches off: the line back-EMF (about 100 V)
    exceeds the 70 V link, the diodes rectify it into the bus capacitor, which the rectifier
    source cannot discharge, so v_dc rises above 70 V. Capacitor energy gained equals the
    energy the inverter returned; the rotor's lost kinetic energy pays for it and the losses."""
    run = regeneration_run()                  # 50 ms at 10 us, 0.2 ohm source, 2 mF
    v = run["v"]
    assert v[-1] > 80.0
    assert np.all(np.diff(v) >= -1e-9)                 # never discharged into the source
    # Bus: the capacitor took exactly what the inverter returned (trapezoid on v).
    returned, stored = run["returned"], run["stored"]
    assert stored > 1.0
    assert abs(returned - stored) < 1e-6 * stored
    e = run["energy"]
    assert abs((-e["kinetic"] - e["magnetic"]) - (returned + e["copper"] + e["damping"])) \
        < 1e-5 * returned


# ----------------------------------------------------------------- eq. (6)
@pytest.mark.parametrize("ld,lq", [(4.8e-3, 4.8e-3), (3.0e-3, 7.0e-3)])
def test_torque_equals_eq6_from_flux_and_current(ld, lq):
    """The model's torque (rotor frame: 1.5 p (psi_m i_q + (Ld - Lq) i_d i_q)) equals the
    paper's eq. (6) 1.5 p (psi_alpha i_beta - psi_beta i_alpha) from the truth's flux linkage
    and currents, and the flux linkage is L i + psi_m on the rotor axes."""
    p = profile(motor={"inductance_d_h": ld, "inductance_q_h": lq, "pole_pairs": 2},
                initial={"speed_rad_s": 150.0})
    plant = Plant(p)
    rng = random.Random(11)
    checked = 0
    for _ in range(3000):
        plant.step(gates=rng.choice(VECTORS + (0x2A, 0x15)))
        t = plant.truth()
        eq6 = 1.5 * 2 * (t[F["psi_alpha"]] * t[F["i_beta"]] - t[F["psi_beta"]] * t[F["i_alpha"]])
        assert abs(eq6 - t[F["torque_nm"]]) < 1e-9 * max(1.0, abs(eq6))
        th = t[F["theta_e_rad"]]
        c, s = math.cos(th), math.sin(th)
        i_d = c * t[F["i_alpha"]] + s * t[F["i_beta"]]
        i_q = -s * t[F["i_alpha"]] + c * t[F["i_beta"]]
        assert abs(c * t[F["psi_alpha"]] + s * t[F["psi_beta"]] - (ld * i_d + 0.0928)) < 1e-12
        assert abs(-s * t[F["psi_alpha"]] + c * t[F["psi_beta"]] - lq * i_q) < 1e-12
        assert t[F["flux_mag_wb"]] == pytest.approx(math.hypot(t[F["psi_alpha"]],
                                                               t[F["psi_beta"]]))
        checked += abs(t[F["torque_nm"]]) > 0.5
    assert checked > 100


# ----------------------------------------------------------------- dead time
@pytest.mark.parametrize("duty,signs", [((0.6, 0.45, 0.45), (1, -1, -1)),
                                        ((0.4, 0.55, 0.55), (-1, 1, 1)),
                                        ((0.45, 0.6, 0.45), (-1, 1, -1))])
def test_dead_time_voltage_error_follows_current_sign(duty, signs):
    """Centre-aligned PWM with dead time td on a locked rotor (DC currents): each leg's mean
    voltage is d U - sign(i) U td / T (the dead interval takes the diode the current picks)."""
    t = dead_time_truth(duty)                 # td 1 us at T 50 us, 3000 periods
    currents = (t[F["i_a"]], t[F["i_b"]], t[F["i_c"]])
    assert tuple(1 if i > 0 else -1 for i in currents) == signs
    assert min(abs(i) for i in currents) > 1.0
    legs = dead_time_leg_voltages(duty, signs)   # d U - sign(i) U td / T
    ideal = clarke(*(d * 70.0 for d in duty))
    expected = clarke(*legs)
    assert abs(t[F["u_alpha"]] - expected[0]) < 1e-9 and abs(t[F["u_beta"]] - expected[1]) < 1e-9
    # The error is a vector opposite to the current: the dead time always costs voltage.
    err = (t[F["u_alpha"]] - ideal[0], t[F["u_beta"]] - ideal[1])
    assert err[0] * t[F["i_alpha"]] + err[1] * t[F["i_beta"]] < 0.0


def test_device_drop_opposes_current():
    p = profile(inverter={"device_drop_v": 1.0}, load={"locked": True})
    plant = Plant(p)
    for _ in range(4000):
        plant.step(duty=(0.6, 0.45, 0.45))
    t = plant.truth()
    # Each conducting device drops 1 V against its current, so the a-to-(b,c) loop loses 2 V:
    # mean u_alpha = 2/3 (U (da - db) - 2 * 1 V) = R i_a.
    assert t[F["u_alpha"]] == pytest.approx(2 / 3 * (70.0 * 0.15 - 2.0), rel=1e-9)
    assert t[F["i_a"]] == pytest.approx(2 / 3 * (70.0 * 0.15 - 2.0) / 0.466, rel=1e-6)


# ----------------------------------------------------------- timing equivalence
def run_pair(coarse: dict, fine: dict, n: int, commands, fine_sequence, steps_per: int):
    """The coarse plant takes commands[k] per period; the fine plant the gate words
    fine_sequence(k) (steps_per of them per coarse period). Returns the worst differences."""
    a, b = Plant(profile(**coarse)), Plant(profile(**fine))
    worst = {"i": 0.0, "w": 0.0, "th": 0.0, "u": 0.0}
    for k in range(n):
        a.step(**commands[k])
        u_fine = [0.0, 0.0]
        for word in fine_sequence(k):
            b.step(gates=word)
            tb = b.truth()
            u_fine[0] += tb[F["u_alpha"]] / steps_per
            u_fine[1] += tb[F["u_beta"]] / steps_per
        ta = a.truth()
        assert ta[F["t_s"]] == pytest.approx(tb[F["t_s"]], abs=1e-12)
        worst["i"] = max(worst["i"], abs(ta[F["i_a"]] - tb[F["i_a"]]),
                         abs(ta[F["i_b"]] - tb[F["i_b"]]))
        worst["w"] = max(worst["w"], abs(ta[F["speed_rad_s"]] - tb[F["speed_rad_s"]]))
        worst["th"] = max(worst["th"], abs(ta[F["theta_m_rad"]] - tb[F["theta_m_rad"]]))
        worst["u"] = max(worst["u"], abs(ta[F["u_alpha"]] - u_fine[0]),
                         abs(ta[F["u_beta"]] - u_fine[1]))
    return worst


def pwm_word(duty, t_rel: float) -> int:
    """Gate word of centre-aligned PWM at a time within the period (fraction 0..1)."""
    word = 0
    for x, d in enumerate(duty):
        high = abs(t_rel - 0.5) < d / 2
        word |= (1 << (2 * x)) if high else (2 << (2 * x))
    return word


def test_pwm_duty_matches_equivalent_gate_sequence():
    """Duties on a 2 % grid at 50 us against the same centre-aligned pattern built here as
    gate words at 1 us: same currents, speed, angle and mean voltage."""
    n_sub = 50
    rng = random.Random(4)
    duties = [tuple(rng.randrange(0, 26) * 2 / n_sub for _ in range(3)) for _ in range(200)]
    start = {"initial": {"speed_rad_s": 200.0, "theta_m_rad": 1.0}}
    worst = run_pair(
        {**start}, {**start, "timing": {"control_period_s": 1e-6, "max_step_s": 1e-6}},
        len(duties), [{"duty": d} for d in duties],
        lambda k: [pwm_word(duties[k], (j + 0.5) / n_sub) for j in range(n_sub)], n_sub)
    assert worst["i"] < 1e-9 and worst["w"] < 1e-9 and worst["th"] < 1e-12
    assert worst["u"] < 1e-9


def test_computation_delay_applies_new_gates_mid_period():
    """20 us delay at 50 us: each period runs 20 us of the previous word, then the new one;
    the same as a 10 us plant fed old, old, new, new, new."""
    rng = random.Random(8)
    words = [rng.choice(VECTORS) for _ in range(300)]
    start = {"initial": {"speed_rad_s": 100.0}}
    coarse = {**start, "timing": {"computation_delay_s": 20e-6}}
    fine = {**start, "timing": {"control_period_s": 10e-6, "max_step_s": 10e-6}}
    worst = run_pair(coarse, fine, len(words), [{"gates": w} for w in words],
                     lambda k: [words[k - 1] if k else 0] * 2 + [words[k]] * 3, 5)
    assert worst["i"] < 1e-9 and worst["w"] < 1e-9 and worst["u"] < 1e-9


def test_dead_time_and_delay_timeline_matches_explicit_switch_sequence():
    """Duties with 2 us dead time and a 10 us computation delay at 50 us, against a 1 us plant
    fed the switch states built here: command = previous duty before 10 us, new after;
    centre-aligned high-side window; a switch is on once its command has been on for 2 us
    (across period boundaries); otherwise the leg is open and its diodes conduct.
    The delay 10 * 1e-6 is 9.999999999999999e-06: new-duty edges at 10 us land on it up to
    rounding, which must not become a femtosecond glitch followed by a dead time."""
    n_sub, td_sub, delay_sub = 50, 2, 10
    rng = random.Random(9)
    duties = [tuple(rng.randrange(0, 26) * 2 / n_sub for _ in range(3)) for _ in range(150)]
    desired = []                                   # per 1 us slot: (high, low) per leg

    def slot_words(k):
        words = []
        for j in range(n_sub):
            d = duties[k] if j >= delay_sub else (duties[k - 1] if k else None)
            t_rel = (j + 0.5) / n_sub
            slot = []
            for x in range(3):
                if d is None:
                    slot.append((False, False))          # the initial all-open command
                else:
                    high = abs(t_rel - 0.5) < d[x] / 2
                    slot.append((high, not high))
            desired.append(slot)
            word = 0
            for x in range(3):
                for side in (0, 1):
                    if all(len(desired) - 1 - back >= 0 and desired[-1 - back][x][side]
                           for back in range(td_sub + 1)):
                        word |= 1 << (2 * x + side)
            words.append(word)
        return words
    start = {"initial": {"speed_rad_s": 150.0, "theta_m_rad": -0.4},
             "load": {"torque_nm": 0.1}}
    worst = run_pair(
        {**start, "inverter": {"dead_time_s": td_sub * 1e-6},
         "timing": {"computation_delay_s": delay_sub * 1e-6}},
        {**start, "timing": {"control_period_s": 1e-6, "max_step_s": 1e-6}},
        len(duties), [{"duty": d} for d in duties], slot_words, n_sub)
    assert worst["i"] < 1e-9 and worst["w"] < 1e-9 and worst["u"] < 1e-8


def test_full_period_delay_holds_previous_gates_for_the_whole_period():
    p = profile(timing={"computation_delay_s": 50e-6}, load={"locked": True})
    plant = Plant(p)
    plant.step(gates=V1)
    assert plant.truth()[F["i_a"]] == 0.0          # all-open initial command still held
    plant.step(gates=V1)
    assert plant.truth()[F["i_a"]] > 0.0


def test_shoot_through_sets_gate_fault_and_opens_the_leg():
    """Both switches of leg a on: the driver's desaturation trip turns the leg off, so its
    positive current falls through the low diode against B and C held high, reaches zero
    and stays there; SAMPLE reports GATE_FAULT for the period it happened in."""
    p = profile(load={"locked": True})
    plant = Plant(p)
    plant.step(gates=V1)
    assert plant.sample().status & 0x08 == 0
    assert plant.truth()[F["i_a"]] > 0.3
    for _ in range(3):
        plant.step(gates=0x03 | 0x04 | 0x10)          # A high and low, B high, C high
        assert plant.sample().status & 0x08
    t = plant.truth()
    assert (t[F["i_a"]], t[F["i_b"]], t[F["i_c"]]) == (0.0, 0.0, 0.0)
    plant.step(gates=V1)
    assert plant.sample().status & 0x08 == 0
    assert plant.truth()[F["i_a"]] > 0.3


# ------------------------------------------------------------------------ loads
def coast_profile(**extra):
    return profile(initial={"speed_rad_s": 100.0}, **extra)


def test_load_step_and_speed_proportional_term_match_analytic_coast():
    """Coasting (no current): J dw/dt = -B w - k w - T_L; a step set mid-period lands exactly."""
    p = coast_profile(load={"speed_proportional_nm_per_rad_s": 2e-4})
    J, B, k = 8.0e-4, 1.0e-4, 2e-4
    plant = Plant(p)
    T = p.control_period_s
    t_step, torque = 0.0123456, 0.3
    plant.load.set_step(t_step, torque)
    a = (B + k) / J
    w_at_step = 100.0 * math.exp(-a * t_step)
    for n in range(1, 600):
        plant.step()
        t = n * T
        if t <= t_step:
            w = 100.0 * math.exp(-a * t)
        else:
            w_inf = -torque / (B + k)
            w = w_inf + (w_at_step - w_inf) * math.exp(-a * (t - t_step))
        assert plant.truth()[F["speed_rad_s"]] == pytest.approx(w, rel=1e-11, abs=1e-11)
    assert plant.truth()[F["load_torque_nm"]] == pytest.approx(torque + k * w, rel=1e-12)


def test_load_ramp_and_table_match_reference_integration():
    """A ramp set while running, then a table (with a step in it) replacing it: the coasting
    rotor's speed follows a tight solve_ivp of J dw/dt = -B w - T_L(t)."""
    p = coast_profile()
    plant = Plant(p)
    T = p.control_period_s
    for _ in range(10):
        plant.step()
    t0, w0 = plant.t_s, plant.truth()[F["speed_rad_s"]]
    plant.load.set_ramp(0.4, 0.0031)                # from 0 to 0.4 Nm over 3.1 ms, then held
    table = [(0.006, 0.1), (0.0071, -0.2), (0.0071, 0.5), (0.009, 0.0)]
    times, speeds = [], []
    t_set = None
    for n in range(300):
        if n == 100:
            t_set = plant.t_s
            plant.load.set_table(table)             # replaces the ramp from now on
        plant.step()
        times.append(plant.t_s)
        speeds.append(plant.truth()[F["speed_rad_s"]])
    ramp_end = t0 + 0.0031

    def load(t):
        if t < t_set:
            return 0.4 * min(1.0, (t - t0) / 0.0031)
        if t < 0.006:
            return 0.1
        if t < 0.0071:
            return 0.1 + (-0.2 - 0.1) * (t - 0.006) / 0.0011
        if t < 0.009:
            return 0.5 * (0.009 - t) / 0.0019
        return 0.0

    def f(t, y):
        return [(-1e-4 * y[0] - load(t)) / 8e-4]
    breaks = [t0, ramp_end, t_set, 0.006, 0.0071, 0.009, times[-1]]
    y, start, ref = [w0], t0, {}
    for stop in breaks[1:]:
        sol = solve_ivp(f, (start, stop), y, method="DOP853", rtol=1e-12, atol=1e-12,
                        dense_output=True)
        for tq in times:
            if start <= tq <= stop:
                ref[tq] = float(sol.sol(tq)[0])
        y, start = [sol.y[0, -1]], stop
    assert min(speeds) < w0 - 1.0                   # the load really acted
    for tq, w in zip(times, speeds):
        assert w == pytest.approx(ref[tq], rel=1e-10)


def test_locked_rotor_holds_speed_and_reports_brake_reaction():
    p = profile(load={"locked": True})
    plant = Plant(p)
    for _ in range(100):
        plant.step(gates=V2)
    t = plant.truth()
    assert t[F["speed_rad_s"]] == 0.0 and t[F["torque_nm"]] > 0.1
    assert t[F["load_torque_nm"]] == t[F["torque_nm"]]
    plant.load.set_locked(False)
    for _ in range(100):
        plant.step()
    assert plant.truth()[F["speed_rad_s"]] > 0.0
