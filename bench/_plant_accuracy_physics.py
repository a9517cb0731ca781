"""The plant against analytic results and per-phase diode-circuit references: the figures
docs/plant.md quotes from tests/test_plant_accuracy.py (safe state, diode bridge, energy
returned to the link) and tests/test_plant_physics.py (locked rotor, six-step speed, energy
balance, regeneration, dead-time voltage error), computed here as those tests compute them
(the same runs, seeds and formulas; the tests assert limits, this returns the values).

The references are copies of the tests' (the bench does not import the tests package); scipy
and numpy's integration helpers are imported where they are used, as scipy is a test and
benchmark dependency, not a runtime one.
"""
from __future__ import annotations

import math

import numpy as np

from plant_rt import TRUTH_FIELDS, Plant, load_profile

F = {name: i for i, name in enumerate(TRUTH_FIELDS)}
RATED_RAD_S = 3000.0 * 2.0 * math.pi / 60.0
V1, V2, V3, V4, V5, V6 = 0x29, 0x25, 0x26, 0x16, 0x1A, 0x19
VECTORS = (V1, V2, V3, V4, V5, V6)
QUIET = {"sensors": {"current": {"noise_rms_counts": 0.0}, "dc_voltage": {"noise_rms_counts": 0.0}}}


def _g(x: float) -> float:
    """Two significant digits, as the other plant_accuracy figures."""
    return float(f"{x:.2g}")


def quiet_profile(**sections):
    """tests/test_plant_physics.py's profile(): no ADC noise, sections merged over it."""
    merged = {k: dict(v) for k, v in QUIET.items()}
    for key, value in sections.items():
        merged[key] = {**merged.get(key, {}), **value}
    return load_profile(overrides=merged)


def _clarke(va: float, vb: float, vc: float) -> tuple[float, float]:
    return (2 * va - vb - vc) / 3, (vb - vc) / math.sqrt(3)


# ------------------------------------------------------------- diode references
def phase_circuit_reference(motor, vdc: float, state: list[float], t_end: float):
    """All legs open (safe state), surface magnets: each phase L di/dt = V_x - V_n - R i - e_x
    with V_x = 0 (low diode, i_x > 0) or vdc (high diode, i_x < 0); three conducting phases
    give V_n = sum(V)/3, two a series circuit, none no current. Returns t -> (i_a, i_b, i_c, w)
    and the event times (tests/test_plant_accuracy.py's reference)."""
    from scipy.integrate import solve_ivp

    p, r, psim, L = motor.pole_pairs, motor.resistance_ohm, motor.flux_linkage_wb, \
        motor.inductance_d_h
    j, b = motor.inertia_kgm2, motor.damping_nm_per_rad_s

    def emf(th, w):
        return [-p * w * psim * math.sin(p * th - 2 * math.pi * k / 3) for k in range(3)]

    def rhs(conducting):
        def f(_t, x):
            ia, ib, w, th = x
            i = [ia, ib, -ia - ib]
            e = emf(th, w)
            v = [0.0 if i[k] > 0 else vdc for k in range(3)]
            d = [0.0, 0.0, 0.0]
            if len(conducting) == 3:
                vn = sum(v) / 3
                d = [(v[k] - vn - r * i[k] - e[k]) / L for k in range(3)]
            elif len(conducting) == 2:
                x_, y_ = conducting
                di = (v[x_] - v[y_] - 2 * r * i[x_] - (e[x_] - e[y_])) / (2 * L)
                d[x_], d[y_] = di, -di
            torque = sum(e[k] * i[k] for k in range(3)) / w
            return [d[0], d[1], (torque - b * w) / j, w]
        return f

    conducting = [0, 1, 2]
    t, x, pieces, events = 0.0, list(state), [], []
    while t < t_end:
        evs = []
        for k in conducting:
            def ev(_t, xx, k=k):
                return (xx[0], xx[1], -xx[0] - xx[1])[k]
            ev.terminal = True
            evs.append(ev)
        sol = solve_ivp(rhs(list(conducting)), (t, t_end), x, method="DOP853", rtol=1e-12,
                        atol=1e-13, events=evs or None, dense_output=True)
        pieces.append((t, sol.t[-1], sol.sol))
        x, t = list(sol.y[:, -1]), sol.t[-1]
        if sol.status == 1:
            events.append(t)
            hit = [k for n, k in enumerate(conducting) if len(sol.t_events[n])][0]
            conducting.remove(hit)
            if len(conducting) == 2:
                i = [x[0], x[1], -x[0] - x[1]]
                i[hit] = 0.0
                i[conducting[1]] = -i[conducting[0]]
                x[0], x[1] = i[0], i[1]
            else:
                x[0] = x[1] = 0.0
                conducting = []

    def at(tq):
        for a, b_, s in pieces:
            if a <= tq <= b_:
                y = s(tq)
                return y[0], y[1], -y[0] - y[1], y[2]
        raise ValueError(tq)
    return at, events


def diode_bridge_reference(motor, vdc: float, state: list[float], t_end: float):
    """All legs open, surface magnets, ideal link, in phase quantities: conducting phases sit
    on their diode's rail; a floating third phase joins when it reaches a rail; with none
    conducting, the largest line back-EMF turns a pair on once it exceeds vdc. Returns
    t -> (i_a, i_b, i_c, w) and the list of (time, what happened)
    (tests/test_plant_accuracy.py's reference)."""
    from scipy.integrate import solve_ivp

    p, r, psim, L = motor.pole_pairs, motor.resistance_ohm, motor.flux_linkage_wb, \
        motor.inductance_d_h
    j, b = motor.inertia_kgm2, motor.damping_nm_per_rad_s

    def emf(th, w):
        return [-p * w * psim * math.sin(p * th - 2 * math.pi * k / 3) for k in range(3)]

    def rail(side):
        return vdc if side == "H" else 0.0

    def float_voltage(sides, x):
        e = emf(x[3], x[2])
        a, c = sorted(sides)
        z = 3 - a - c
        return (rail(sides[a]) + rail(sides[c]) - e[a] - e[c]) / 2 + e[z]

    def rhs(sides):
        def f(_t, x):
            ia, ib, w, th = x
            i = [ia, ib, -ia - ib]
            e = emf(th, w)
            d = [0.0, 0.0, 0.0]
            if len(sides) == 3:
                v = [rail(sides[k]) for k in range(3)]
                d = [(v[k] - sum(v) / 3 - r * i[k] - e[k]) / L for k in range(3)]
            elif len(sides) == 2:
                a, c = sorted(sides)
                di = (rail(sides[a]) - rail(sides[c]) - 2 * r * i[a] - (e[a] - e[c])) / (2 * L)
                d[a], d[c] = di, -di
            torque = sum(e[k] * i[k] for k in range(3)) / w
            return [d[0], d[1], (torque - b * w) / j, w]
        return f

    def events_for(sides):
        evs = []
        for k, side in sides.items():
            def ev(_t, x, k=k):
                return (x[0], x[1], -x[0] - x[1])[k]
            ev.terminal, ev.direction = True, (1 if side == "H" else -1)
            evs.append((ev, ("stop", k)))
        if len(sides) == 2:
            def hi(_t, x, sides=dict(sides)):
                return float_voltage(sides, x) - vdc

            def lo(_t, x, sides=dict(sides)):
                return float_voltage(sides, x)
            hi.terminal, hi.direction = True, 1
            lo.terminal, lo.direction = True, -1
            z = 3 - sum(sides)
            evs += [(hi, ("on", z, "H")), (lo, ("on", z, "L"))]
        if not sides:
            def line(_t, x):
                e = emf(x[3], x[2])
                return max(e) - min(e) - vdc
            line.terminal, line.direction = True, 1
            evs.append((line, ("pair",)))
        return evs

    def pair_on(x, sides):
        e = emf(x[3], x[2])
        sides[e.index(max(e))] = "H"
        sides[e.index(min(e))] = "L"

    sides: dict[int, str] = {}
    t, x, pieces, log = 0.0, list(state), [], []
    e0 = emf(x[3], x[2])
    if max(e0) - min(e0) > vdc:
        pair_on(x, sides)
        log.append((0.0, "pair"))
    while t < t_end:
        evs = events_for(sides)
        sol = solve_ivp(rhs(dict(sides)), (t, t_end), x, method="DOP853", rtol=1e-12,
                        atol=1e-13, events=[e for e, _ in evs], dense_output=True)
        pieces.append((t, sol.t[-1], sol.sol))
        x, t = list(sol.y[:, -1]), sol.t[-1]
        if sol.status != 1:
            break
        what = [tag for n, (_, tag) in enumerate(evs) if len(sol.t_events[n])][0]
        log.append((t, what[0]))
        if what[0] == "stop":
            del sides[what[1]]
            i = [x[0], x[1], -x[0] - x[1]]
            i[what[1]] = 0.0
            if len(sides) == 2:
                a, c = sorted(sides)
                i[c] = -i[a]
            else:
                sides.clear()
                i = [0.0, 0.0, 0.0]
            x[0], x[1] = i[0], i[1]
        elif what[0] == "on":
            sides[what[1]] = what[2]
        else:
            pair_on(x, sides)

    def at(tq):
        for a, b_, sol in pieces:
            if a <= tq <= b_:
                y = sol(tq)
                return y[0], y[1], -y[0] - y[1], y[2]
        raise ValueError(tq)
    return at, log


# ------------------------------------------------------------------ the runs
def safe_state_rated() -> dict:
    """test_safe_state_at_rated_speed_decays_through_diodes_then_stays_zero."""
    profile = load_profile(overrides={"initial": {"speed_rad_s": RATED_RAD_S}})
    plant = Plant(profile)
    for _ in range(60):
        plant.step(gates=V2)
    for _ in range(3):
        plant.step(gates=V3)
    t = plant.truth()
    start = [t[F["i_a"]], t[F["i_b"]], t[F["speed_rad_s"]], t[F["theta_m_rad"]]]
    T = profile.control_period_s
    n = 400
    ref, events = phase_circuit_reference(profile.motor, 70.0, start, n * T)
    plant.safe_state()
    peak = max(abs(v) for v in start[:2])
    worst = worst_w = 0.0
    zero_after = True
    for k in range(1, n + 1):
        plant.step()
        t = plant.truth()
        ia, ib, ic, w = ref(k * T)
        worst = max(worst, abs(t[F["i_a"]] - ia), abs(t[F["i_b"]] - ib), abs(t[F["i_c"]] - ic))
        worst_w = max(worst_w, abs(t[F["speed_rad_s"]] - w) / abs(w))
        if k * T > events[-1] + T:
            zero_after &= (t[F["i_a"]], t[F["i_b"]], t[F["i_c"]], t[F["i_dc"]]) == (0.0,) * 4
    for _ in range(1000):           # the rotor coasts on for 50 ms
        plant.step()
        t = plant.truth()
        zero_after &= (t[F["i_a"]], t[F["i_b"]], t[F["i_c"]], t[F["torque_nm"]]) == (0.0,) * 4
    return {"current_error_of_peak": _g(worst / peak), "speed_error_relative": _g(worst_w),
            "conduction_changes": len(events), "peak_a": round(peak, 1),
            "currents_exactly_zero_after_decay_and_50_ms": bool(zero_after)}


def safe_state_energy(ld: float, lq: float) -> float:
    """test_safe_state_energy_returned_to_link: |link energy - released| / link energy."""
    T = 5e-6
    profile = load_profile(overrides={
        "timing": {"control_period_s": T, "max_step_s": T},
        "motor": {"inductance_d_h": ld, "inductance_q_h": lq},
        "initial": {"speed_rad_s": RATED_RAD_S}})
    m = profile.motor
    plant = Plant(profile)
    for _ in range(500):
        plant.step(gates=V2)
    rows = [plant.truth()]
    plant.safe_state()
    for _ in range(2000):
        plant.step()
        rows.append(plant.truth())
    a = np.array(rows)
    e_link = -np.sum(a[1:, F["v_dc"]] * a[1:, F["i_dc"]]) * T
    i_sq = a[:, F["i_alpha"]] ** 2 + a[:, F["i_beta"]] ** 2
    copper = np.trapezoid(1.5 * m.resistance_ohm * i_sq, dx=T)
    w = a[:, F["speed_rad_s"]]
    damping = np.trapezoid(m.damping_nm_per_rad_s * w ** 2, dx=T)
    kinetic = 0.5 * m.inertia_kgm2 * (w[0] ** 2 - w[-1] ** 2)
    th = a[0, F["theta_e_rad"]]
    i_d = math.cos(th) * a[0, F["i_alpha"]] + math.sin(th) * a[0, F["i_beta"]]
    i_q = -math.sin(th) * a[0, F["i_alpha"]] + math.cos(th) * a[0, F["i_beta"]]
    magnetic = 0.75 * (ld * i_d ** 2 + lq * i_q ** 2)
    released = magnetic + kinetic - copper - damping
    return _g(abs(e_link - released) / e_link)


def diode_bridge_twice_rated() -> dict:
    """test_diode_bridge_rectifying_at_twice_rated_speed_matches_reference."""
    w0 = 2 * RATED_RAD_S
    profile = load_profile(overrides={"initial": {"speed_rad_s": w0, "theta_m_rad": 0.2}})
    T = profile.control_period_s
    n = 400
    ref, log = diode_bridge_reference(profile.motor, 70.0, [0.0, 0.0, w0, 0.2], n * T)
    plant = Plant(profile)
    peak = worst = worst_w = 0.0
    for k in range(1, n + 1):
        plant.step()
        t = plant.truth()
        ia, ib, ic, w = ref(k * T)
        peak = max(peak, abs(ia), abs(ib), abs(ic))
        worst = max(worst, abs(t[F["i_a"]] - ia), abs(t[F["i_b"]] - ib), abs(t[F["i_c"]] - ic))
        worst_w = max(worst_w, abs(t[F["speed_rad_s"]] - w) / w)
    m = profile.motor
    return {"current_error_of_peak": _g(worst / peak), "speed_error_relative": _g(worst_w),
            "events": len(log), "peak_a": round(peak, 1),
            "line_back_emf_v": round(math.sqrt(3) * m.pole_pairs * m.flux_linkage_wb * w0, 1)}


def locked_rotor() -> dict:
    """test_locked_rotor_dc_current_is_v_over_r_with_l_over_r: worst |i - analytic| over 25
    time constants (all three phases) as a fraction of the final current, per case."""
    out = {}
    for name, (ld, lq, theta, axis) in {
            "ld_eq_lq": (4.8e-3, 4.8e-3, 0.0, "d"),
            "ld_ne_lq_along_d": (3.0e-3, 7.0e-3, 0.0, "d"),
            "ld_ne_lq_along_q": (3.0e-3, 7.0e-3, math.pi / 2, "q")}.items():
        p = quiet_profile(motor={"inductance_d_h": ld, "inductance_q_h": lq},
                          load={"locked": True}, initial={"theta_m_rad": theta})
        r = p.motor.resistance_ohm
        L = ld if axis == "d" else lq
        i_final = (2 * 70.0 / 3) / r
        plant = Plant(p)
        T = p.control_period_s
        worst = 0.0
        for k in range(1, round(25 * L / r / T) + 1):
            plant.step(gates=V1)
            t = plant.truth()
            expected = i_final * (1 - math.exp(-k * T * r / L))
            worst = max(worst, abs(t[F["i_a"]] - expected), abs(t[F["i_b"]] + expected / 2),
                        abs(t[F["i_c"]] + expected / 2))
        out[name] = _g(worst / i_final)
    return out


def six_step_speed(motor, vdc: float, period_s: float) -> float:
    """Steady no-load speed of rotor-position six-step drive from the back-EMF balance
    (tests/test_plant_physics.py's: mean q-axis voltage 2U/pi less half a period's
    commutation lag; R, w L i_d and the damping torque in the balance)."""
    from scipy.optimize import brentq

    L, R, psim = motor.inductance_d_h, motor.resistance_ohm, motor.flux_linkage_wb
    B, p = motor.damping_nm_per_rad_s, motor.pole_pairs
    V = 2 * vdc / math.pi

    def balance(we):
        phi = math.pi / 2 - we * period_s / 2
        iq = B * (we / p) / (1.5 * p * psim)
        i_d = (V * math.cos(phi) + we * L * iq) / R
        return V * math.sin(phi) - (R * iq + we * L * i_d + we * psim)
    return brentq(balance, 50.0, 5000.0) / p


def six_step() -> dict:
    """test_six_step_no_load_speed_matches_back_emf_balance: self-commutated six-step at 5 us,
    0.25 s to settle, mean speed over the next 0.15 s against the balance; and how far the
    balance is below the naive 2U/(pi psi_m)."""
    T = 5e-6
    base = {"control_period_s": T, "max_step_s": T}
    motor = quiet_profile(timing=base).motor
    w_pred = six_step_speed(motor, 70.0, T)
    naive = 2 * 70.0 / math.pi / motor.flux_linkage_wb
    p = quiet_profile(timing=base, motor={"inertia_kgm2": 8.0e-5},
                      initial={"speed_rad_s": w_pred})
    plant = Plant(p)
    speeds = []
    n_settle, n_avg = round(0.25 / T), round(0.15 / T)
    for k in range(n_settle + n_avg):
        t = plant.truth()
        j = round((t[F["theta_e_rad"]] + math.pi / 2) / (math.pi / 3)) % 6
        plant.step(gates=VECTORS[j])
        if k >= n_settle:
            speeds.append(t[F["speed_rad_s"]])
    w_sim = sum(speeds) / len(speeds)
    return {"speed_error_relative": _g(abs(w_sim - w_pred) / w_pred),
            "balance_below_naive": _g(1.0 - w_pred / naive),
            "speed_rad_s": round(w_sim, 2), "naive_rad_s": round(naive, 2)}


def _energy_terms(a: np.ndarray, motor, T: float) -> dict:
    e_dc = float(np.sum(a[1:, F["v_dc"]] * a[1:, F["i_dc"]]) * T)
    copper = float(np.trapezoid(1.5 * motor.resistance_ohm
                                * (a[:, F["i_alpha"]] ** 2 + a[:, F["i_beta"]] ** 2), dx=T))
    w = a[:, F["speed_rad_s"]]
    damping = float(np.trapezoid(motor.damping_nm_per_rad_s * w ** 2, dx=T))
    load = float(np.trapezoid(a[:, F["load_torque_nm"]] * w, dx=T))
    kinetic = 0.5 * motor.inertia_kgm2 * (w[-1] ** 2 - w[0] ** 2)

    def magnetic(row):
        th = row[F["theta_e_rad"]]
        c, s = math.cos(th), math.sin(th)
        i_d = c * row[F["i_alpha"]] + s * row[F["i_beta"]]
        i_q = -s * row[F["i_alpha"]] + c * row[F["i_beta"]]
        return 0.75 * (motor.inductance_d_h * i_d ** 2 + motor.inductance_q_h * i_q ** 2)
    return {"dc": e_dc, "copper": copper, "damping": damping, "load": load, "kinetic": kinetic,
            "magnetic": magnetic(a[-1]) - magnetic(a[0])}


def energy_balance() -> dict:
    """test_energy_balance: |DC-link energy - (copper + kinetic + damping + load + magnetic)|
    / DC-link energy over 0.15 s of sinusoidal duties at 10 us from rest, per case."""
    out = {}
    T = 10e-6
    for name, (ld, lq, dead_time) in {"ld_eq_lq": (4.8e-3, 4.8e-3, 0.0),
                                      "ld_ne_lq": (3.0e-3, 7.0e-3, 0.0),
                                      "dead_time_0.5us": (4.8e-3, 4.8e-3, 0.5e-6)}.items():
        p = quiet_profile(timing={"control_period_s": T, "max_step_s": T},
                          motor={"inductance_d_h": ld, "inductance_q_h": lq},
                          inverter={"dead_time_s": dead_time},
                          load={"torque_nm": 0.2, "speed_proportional_nm_per_rad_s": 5e-4})
        plant = Plant(p)
        rows = [plant.truth()]
        for _ in range(round(0.15 / T)):
            th = rows[-1][F["theta_e_rad"]]
            plant.step(duty=[0.5 + 0.45 * math.cos(th + 1.9 - 2 * math.pi * x / 3)
                             for x in range(3)])
            rows.append(plant.truth())
        e = _energy_terms(np.array(rows), p.motor, T)
        out_ = e["copper"] + e["kinetic"] + e["damping"] + e["load"] + e["magnetic"]
        out[name] = _g(abs(e["dc"] - out_) / e["dc"])
    return out


def regeneration() -> dict:
    """test_regeneration_through_diodes_raises_unidirectional_bus_voltage: 50 ms coasting at
    twice rated speed into a unidirectional link; the capacitor energy against the energy the
    inverter returned, and the largest fall of v_dc between samples."""
    T = 10e-6
    p = quiet_profile(timing={"control_period_s": T, "max_step_s": T},
                      dc_link={"source_resistance_ohm": 0.2, "capacitance_f": 2.0e-3,
                               "unidirectional": True},
                      initial={"speed_rad_s": 2 * 314.159})
    plant = Plant(p)
    rows = [plant.truth()]
    for _ in range(round(0.05 / T)):
        plant.step()
        rows.append(plant.truth())
    a = np.array(rows)
    v = a[:, F["v_dc"]]
    returned = -float(np.sum(0.5 * (v[1:] + v[:-1]) * a[1:, F["i_dc"]]) * T)
    stored = 0.5 * 2.0e-3 * (v[-1] ** 2 - v[0] ** 2)
    e = _energy_terms(a, p.motor, T)
    mech = (-e["kinetic"] - e["magnetic"]) - (returned + e["copper"] + e["damping"])
    return {"capacitor_energy_error": _g(abs(returned - stored) / stored),
            "mechanical_balance_error": _g(abs(mech) / returned),
            "largest_v_dc_fall_v": _g(max(0.0, -float(np.min(np.diff(v))))),
            "v_dc_end_v": round(float(v[-1]), 1)}


def dead_time_voltage_error() -> dict:
    """test_dead_time_voltage_error_follows_current_sign: on a locked rotor with 1 us dead
    time, the mean (u_alpha, u_beta) against d U - sign(i) U td/T per leg; the worst
    difference in volts over the three duty sets."""
    td, T = 1.0e-6, 50e-6
    worst = 0.0
    for duty in ((0.6, 0.45, 0.45), (0.4, 0.55, 0.55), (0.45, 0.6, 0.45)):
        plant = Plant(quiet_profile(inverter={"dead_time_s": td}, load={"locked": True}))
        for _ in range(3000):
            plant.step(duty=duty)
        t = plant.truth()
        signs = [1 if t[F[f"i_{x}"]] > 0 else -1 for x in "abc"]
        expected = _clarke(*(d * 70.0 - s * 70.0 * td / T for d, s in zip(duty, signs)))
        worst = max(worst, abs(t[F["u_alpha"]] - expected[0]), abs(t[F["u_beta"]] - expected[1]))
    return {"worst_v": _g(worst)}


def run(quick: bool = False) -> dict:
    """Every figure (about 4 s in all, the same with quick: the safe state's dense reference
    is the longest part)."""
    return {
        "safe_state_rated_speed": safe_state_rated(),
        "safe_state_energy_returned_error": {"ld_eq_lq": safe_state_energy(4.8e-3, 4.8e-3),
                                             "ld_ne_lq": safe_state_energy(3.0e-3, 7.0e-3)},
        "diode_bridge_twice_rated": diode_bridge_twice_rated(),
        "locked_rotor_current_error_of_final": locked_rotor(),
        "six_step_no_load": six_step(),
        "energy_balance_error": energy_balance(),
        "regeneration_unidirectional_link": regeneration(),
        "dead_time_voltage_error": dead_time_voltage_error(),
    }
