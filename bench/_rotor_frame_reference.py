"""An independent rotor-frame reference for the plant's gate-word path: the dq current and
mechanical equations written here from the physics (not from the plant's code), Table 2's
voltages, integrated by scipy's solve_ivp (DOP853, rtol 1e-10) period by period from the same
state as the plant (which integrates the stationary-frame flux linkage with RK4).

`run_against_reference` drives both through random gate words; `CASES` are the runs that
tests/test_plant_accuracy.py asserts limits on and `python -m bench plant_accuracy` prints.
"""
from __future__ import annotations

import math
import random

from plant_rt import TRUTH_FIELDS, Plant, load_profile

F = {name: i for i, name in enumerate(TRUTH_FIELDS)}
RATED_RAD_S = 3000.0 * 2.0 * math.pi / 60.0
VECTOR_WORDS = (0x29, 0x25, 0x26, 0x16, 0x1A, 0x19)   # V1..V6 as HIL_GATE_* words
ZERO_WORDS = (0x2A, 0x15)                              # V0 (all low), V7 (all high)


def table2(word: int, vdc: float) -> tuple[float, float]:
    """Paper's Table 2: V1(100) = (2U/3, 0), V2(110) = (U/3, U/sqrt3), ... V0, V7 = 0."""
    if word in ZERO_WORDS:
        return 0.0, 0.0
    k = VECTOR_WORDS.index(word)
    return {0: (2 * vdc / 3, 0.0), 1: (vdc / 3, vdc / math.sqrt(3)),
            2: (-vdc / 3, vdc / math.sqrt(3)), 3: (-2 * vdc / 3, 0.0),
            4: (-vdc / 3, -vdc / math.sqrt(3)), 5: (vdc / 3, -vdc / math.sqrt(3))}[k]


def dq_model(motor):
    p, r, psim = motor.pole_pairs, motor.resistance_ohm, motor.flux_linkage_wb
    ld, lq, j, b = motor.inductance_d_h, motor.inductance_q_h, motor.inertia_kgm2, \
        motor.damping_nm_per_rad_s

    def f(_t, x, ua, ub):
        i_d, i_q, w, th = x
        c, s = math.cos(p * th), math.sin(p * th)
        ud, uq = c * ua + s * ub, -s * ua + c * ub
        we = p * w
        torque = 1.5 * p * (psim * i_q + (ld - lq) * i_d * i_q)
        return [(ud - r * i_d + we * lq * i_q) / ld,
                (uq - r * i_q - we * (ld * i_d + psim)) / lq,
                (torque - b * w) / j, w]
    return f


def run_against_reference(overrides: dict, duration_s: float, w_start: float, w_end: float,
                          seed: int, random_share: float = 0.5) -> dict:
    """Random gate words (half uniformly random, half steering the speed along a ramp from
    w_start to w_end); the plant and solve_ivp period by period from the same state."""
    # scipy is a test and benchmark dependency, not a runtime one (requirements-runtime.lock)
    from scipy.integrate import solve_ivp

    overrides = {**overrides, "initial": {**overrides.get("initial", {}), "speed_rad_s": w_start}}
    profile = load_profile(overrides=overrides)
    motor, T = profile.motor, profile.control_period_s
    vdc = profile.dc_link.source_voltage_v
    p = motor.pole_pairs
    f = dq_model(motor)
    plant = Plant(profile)
    rng = random.Random(seed)
    x = [0.0, 0.0, w_start, profile.initial.theta_m_rad]
    n = round(duration_s / T)
    peak = err_i = err_w = err_th = 0.0
    w_seen = []
    for k in range(n):
        target = w_start + (w_end - w_start) * k / n
        if rng.random() < random_share:
            word = (VECTOR_WORDS + ZERO_WORDS)[rng.randrange(8)]
        else:
            # Motoring vector ahead of the q-axis (into field weakening above base speed) or
            # a braking one behind it.
            lead = math.pi / 2 + 0.6 if x[2] < target else -math.pi / 2
            word = VECTOR_WORDS[round((p * x[3] + lead) / (math.pi / 3)) % 6]
        sol = solve_ivp(f, (0.0, T), x, method="DOP853", rtol=1e-10, atol=1e-12,
                        args=table2(word, vdc))
        x = list(sol.y[:, -1])
        plant.step(gates=word)
        truth = plant.truth()
        c, s = math.cos(p * x[3]), math.sin(p * x[3])
        ia, ib = c * x[0] - s * x[1], s * x[0] + c * x[1]
        peak = max(peak, abs(ia), abs(ib))
        err_i = max(err_i, abs(ia - truth[F["i_alpha"]]), abs(ib - truth[F["i_beta"]]))
        err_w = max(err_w, abs(x[2] - truth[F["speed_rad_s"]]) / abs(x[2]))
        w_seen.append(x[2])
        # Angles agree modulo a turn (the plant wraps its own).
        err_th = max(err_th, abs(math.remainder(x[3] - truth[F["theta_m_rad"]], 2 * math.pi)))
    return {"peak_a": peak, "current_rel": err_i / peak, "speed_rel": err_w, "angle_rad": err_th,
            "w_min": min(w_seen), "w_max": max(w_seen)}


#: name -> run_against_reference's arguments (overrides, duration_s, w_start, w_end, seed,
#: random_share)
CASES = {
    "random_gates_1s_0.3x_to_2x_rated": ({}, 1.0, 0.3 * RATED_RAD_S, 2.05 * RATED_RAD_S, 3, 0.4),
    "ld_ne_lq_twice_rated": ({"motor": {"inductance_d_h": 3.0e-3, "inductance_q_h": 7.0e-3},
                              "initial": {"theta_m_rad": 0.3}}, 0.15, 2.0 * RATED_RAD_S,
                             2.0 * RATED_RAD_S, 5, 0.5),
    "four_pole_pairs": ({"motor": {"pole_pairs": 4}}, 0.1, 0.4 * RATED_RAD_S, 0.5 * RATED_RAD_S, 7, 0.5),
}
