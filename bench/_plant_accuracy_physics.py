"""The plant against analytic results and per-phase diode-circuit references: the figures
docs/plant.md quotes from tests/test_plant_accuracy.py (safe state, diode bridge, energy
returned to the link) and tests/test_plant_physics.py (locked rotor, six-step speed, energy
balance, regeneration, dead-time voltage error).

The references (the diode circuits, the six-step balance, the energy terms) and the runs are
written once, here: the tests import them and assert their limits on what the runs return,
`run` prints the values. scipy is imported where it is used, as it is a test and benchmark
dependency, not a runtime one (requirements-runtime.lock).
"""
from __future__ import annotations

import math

import numpy as np

from bench._rotor_frame_reference import F, RATED_RAD_S, VECTOR_WORDS
from plant_rt import Plant, load_profile

VECTORS = VECTOR_WORDS
V1, V2, V3, V4, V5, V6 = VECTORS
QUIET = {"sensors": {"current": {"noise_rms_counts": 0.0}, "dc_voltage": {"noise_rms_counts": 0.0}}}


def _g(x: float) -> float:
    """Two significant digits, as the other plant_accuracy figures."""
    return float(f"{x:.2g}")


def quiet_profile(**sections):
    """The default profile without ADC noise, `sections` merged over it (section -> keys)."""
    merged = {k: dict(v) for k, v in QUIET.items()}
    for key, value in sections.items():
        merged[key] = {**merged.get(key, {}), **value}
    return load_profile(overrides=merged)


def clarke(va: float, vb: float, vc: float) -> tuple[float, float]:
    """Amplitude-invariant Clarke transform: (alpha, beta) = ((2a - b - c)/3, (b - c)/sqrt3)."""
    return (2 * va - vb - vc) / 3, (vb - vc) / math.sqrt(3)


# ------------------------------------------------------------- diode references
def _back_emf(motor):
    """emf(theta_m, w_m) -> the phase back-EMFs e_x = -p w_m psi_m sin(p theta_m - 2 pi x/3)
    (V; theta_m in rad, w_m in rad/s), x = a, b, c."""
    p, psim = motor.pole_pairs, motor.flux_linkage_wb

    def emf(th, w):
        return [-p * w * psim * math.sin(p * th - 2 * math.pi * k / 3) for k in range(3)]
    return emf


def _open_leg_equations(motor, emf, conducting: list[int], voltages):
    """f(t, x) for solve_ivp with all legs open, surface magnets (L = Ld), x = (i_a, i_b (A),
    w_m (rad/s), theta_m (rad)), i_c = -i_a - i_b. `conducting`: the phases whose diode
    conducts, in ascending order; voltages(i) -> their terminal voltages (V, a list of three;
    only the conducting ones are read). Three conducting: L di_x/dt = V_x - V_n - R i_x - e_x
    with V_n = sum(V)/3; two (x, y): the series circuit 2L di/dt = V_x - V_y - 2 R i - (e_x -
    e_y); none: no current. J dw/dt = (sum e i)/w - B w (electrical power / speed)."""
    r, L = motor.resistance_ohm, motor.inductance_d_h
    j, b = motor.inertia_kgm2, motor.damping_nm_per_rad_s

    def f(_t, x):
        ia, ib, w, th = x
        i = [ia, ib, -ia - ib]
        e = emf(th, w)
        d = [0.0, 0.0, 0.0]
        if len(conducting) == 3:
            v = voltages(i)
            vn = sum(v) / 3
            d = [(v[k] - vn - r * i[k] - e[k]) / L for k in range(3)]
        elif len(conducting) == 2:
            x_, y_ = conducting
            v = voltages(i)
            di = (v[x_] - v[y_] - 2 * r * i[x_] - (e[x_] - e[y_])) / (2 * L)
            d[x_], d[y_] = di, -di
        torque = sum(e[k] * i[k] for k in range(3)) / w   # electrical power / speed
        return [d[0], d[1], (torque - b * w) / j, w]
    return f


def _current_zero(k: int, direction: int = 0):
    """A terminal solve_ivp event: phase k's current (A) reaches zero (direction as solve_ivp's)."""
    def ev(_t, x):
        return (x[0], x[1], -x[0] - x[1])[k]
    ev.terminal, ev.direction = True, direction
    return ev


def _solve(f, t: float, t_end: float, x: list[float], events):
    """One piece: DOP853 at rtol 1e-12, atol 1e-13, dense, stopping at the first event."""
    from scipy.integrate import solve_ivp

    return solve_ivp(f, (t, t_end), x, method="DOP853", rtol=1e-12, atol=1e-13, events=events,
                     dense_output=True)


def _piecewise(pieces):
    """at(t) -> (i_a, i_b, i_c (A), w_m (rad/s)) from the pieces (t0, t1, dense solution)."""
    def at(tq):
        for a, b_, s in pieces:
            if a <= tq <= b_:
                y = s(tq)
                return y[0], y[1], -y[0] - y[1], y[2]
        raise ValueError(tq)
    return at


def phase_circuit_reference(motor, vdc: float, state: list[float], t_end: float):
    """All legs open (safe state), surface magnets: each phase L di/dt = V_x - V_n - R i - e_x
    with V_x = 0 (low diode, i_x > 0) or vdc (high diode, i_x < 0). Three conducting phases
    give V_n = sum(V)/3; when one current reaches zero the other two form a series circuit
    2L di/dt = V_x - V_y - 2 R i - (e_x - e_y); with two at zero nothing flows. state =
    (i_a, i_b (A), w_m (rad/s), theta_m (rad)), vdc in V, t_end in s. Returns a function
    t -> (i_a, i_b, i_c, w) and the event times (s)."""
    emf = _back_emf(motor)

    def voltages(i):
        return [0.0 if i[k] > 0 else vdc for k in range(3)]

    conducting = [k for k in range(3)]
    t, x, pieces, events = 0.0, list(state), [], []
    while t < t_end:
        evs = [_current_zero(k) for k in conducting]
        sol = _solve(_open_leg_equations(motor, emf, list(conducting), voltages), t, t_end, x,
                     evs or None)
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
                # The open phase's floating terminal must stay between the rails.
                e = emf(x[3], x[2])
                xx, yy = conducting
                vx = 0.0 if i[xx] > 0 else vdc
                vy = 0.0 if i[yy] > 0 else vdc
                vn = (vx - e[xx] + vy - e[yy]) / 2
                assert 0.0 < vn + e[hit] < vdc
            else:
                x[0] = x[1] = 0.0
                conducting = []
    return _piecewise(pieces), events


def diode_bridge_reference(motor, vdc: float, state: list[float], t_end: float):
    """All legs open, surface magnets, ideal link, in phase quantities: every conducting phase
    sits on the rail of its diode (high: vdc, low: 0). Three conducting: V_n = sum(V)/3;
    two (x, y): 2L di/dt = V_x - V_y - 2 R i - (e_x - e_y) and the third floats at
    V_z = (V_x + V_y - e_x - e_y)/2 + e_z until it reaches a rail, where that diode turns
    on; none: the largest line back-EMF turns a pair on once it exceeds vdc. A conducting
    phase stops when its current returns to zero. state = (i_a, i_b (A), w_m (rad/s),
    theta_m (rad)), vdc in V, t_end in s. Returns t -> (i_a, i_b, i_c, w) and the list of
    (time, what happened)."""
    emf = _back_emf(motor)

    def rail(side):
        return vdc if side == "H" else 0.0

    def float_voltage(sides, x):
        ia, ib, w, th = x
        e = emf(th, w)
        a, c = sorted(sides)
        z = 3 - a - c
        return (rail(sides[a]) + rail(sides[c]) - e[a] - e[c]) / 2 + e[z]

    def rhs(sides):
        def voltages(_i):
            return [rail(sides.get(k)) for k in range(3)]
        return _open_leg_equations(motor, emf, sorted(sides), voltages)

    def events_for(sides):
        evs = [(_current_zero(k, 1 if side == "H" else -1), ("stop", k))
               for k, side in sides.items()]
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
        sides[e.index(max(e))] = "H"      # current leaves the motor through the high diode
        sides[e.index(min(e))] = "L"

    sides: dict[int, str] = {}
    t, x, pieces, log = 0.0, list(state), [], []
    e0 = emf(x[3], x[2])
    if max(e0) - min(e0) > vdc:
        pair_on(x, sides)
        log.append((0.0, "pair"))
    while t < t_end:
        evs = events_for(sides)
        sol = _solve(rhs(dict(sides)), t, t_end, x, [e for e, _ in evs])
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
    return _piecewise(pieces), log


def _worst_current(t, ref) -> float:
    """max |plant - reference| over the three phase currents (A); ref = (i_a, i_b, i_c, w)."""
    ia, ib, ic, _w = ref
    return max(abs(t[F["i_a"]] - ia), abs(t[F["i_b"]] - ib), abs(t[F["i_c"]] - ic))


# ------------------------------------------------------------------ the runs
def safe_state_decay(n: int = 400, coast: int = 1000) -> dict:
    """Motoring at rated speed (60 periods of V2, 3 of V3), then the safe state for n periods
    beside phase_circuit_reference (70 V link), then `coast` periods more. Returns "truth0"
    (the truth at the switch-off), "start" (its (i_a, i_b, w_m, theta_m)), "events" (the
    reference's conduction changes, s), "T" (s), "trace" ([(truth, reference (i_a, i_b, i_c,
    w)] at the end of each period), "worst" (the largest phase-current difference, A), "peak"
    (max |i_a|, |i_b| at the switch-off, A), "coast" (the truths after) and the plant."""
    profile = load_profile(overrides={"initial": {"speed_rad_s": RATED_RAD_S}})
    plant = Plant(profile)
    for _ in range(60):
        plant.step(gates=V2)              # build up current
    for _ in range(3):
        plant.step(gates=V3)
    truth0 = plant.truth()
    start = [truth0[F["i_a"]], truth0[F["i_b"]], truth0[F["speed_rad_s"]], truth0[F["theta_m_rad"]]]
    T = profile.control_period_s
    ref, events = phase_circuit_reference(profile.motor, 70.0, start, n * T)
    plant.safe_state()
    trace = []
    for k in range(1, n + 1):
        plant.step()
        trace.append((plant.truth(), ref(k * T)))
    after = []
    for _ in range(coast):
        plant.step()
        after.append(plant.truth())
    return {"truth0": truth0, "start": start, "events": events, "T": T, "trace": trace,
            "worst": max(_worst_current(t, r) for t, r in trace),
            "peak": max(abs(v) for v in start[:2]), "coast": after, "plant": plant}


def safe_state_rated() -> dict:
    """test_safe_state_at_rated_speed_decays_through_diodes_then_stays_zero's figures."""
    run = safe_state_decay()
    T, events = run["T"], run["events"]
    worst_w = max(abs(t[F["speed_rad_s"]] - r[3]) / abs(r[3]) for t, r in run["trace"])
    zero_after = all((t[F["i_a"]], t[F["i_b"]], t[F["i_c"]], t[F["i_dc"]]) == (0.0,) * 4
                     for k, (t, _r) in enumerate(run["trace"], start=1)
                     if k * T > events[-1] + T)
    zero_after &= all((t[F["i_a"]], t[F["i_b"]], t[F["i_c"]], t[F["torque_nm"]]) == (0.0,) * 4
                      for t in run["coast"])
    return {"current_error_of_peak": _g(run["worst"] / run["peak"]),
            "speed_error_relative": _g(worst_w), "conduction_changes": len(events),
            "peak_a": round(run["peak"], 1),
            "currents_exactly_zero_after_decay_and_50_ms": bool(zero_after)}


def safe_state_energy_run(ld: float, lq: float) -> dict:
    """500 periods of V2 at 5 us from rated speed, then 2000 in the safe state.
    Returns "rows" (the truths as an array), "link" (the energy the link received,
    -sum(v_dc i_dc) T, J) and "released" (the magnetic energy 0.75 (Ld i_d^2 + Lq i_q^2) at the
    switch-off plus the kinetic energy 0.5 J (w0^2 - w1^2), less the copper loss
    1.5 R |i|^2 and the damping B w^2 integrated by the trapezoid rule, J)."""
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
    return {"rows": a, "link": e_link, "released": magnetic + kinetic - copper - damping}


def safe_state_energy(ld: float, lq: float) -> float:
    """test_safe_state_energy_returned_to_link: |link energy - released| / link energy."""
    run = safe_state_energy_run(ld, lq)
    return _g(abs(run["link"] - run["released"]) / run["link"])


def diode_bridge_run(n: int = 400) -> dict:
    """All switches off at twice rated speed (theta_m 0.2 rad), n periods beside
    diode_bridge_reference (70 V link). Returns "log" (the reference's events), "w0" (rad/s),
    "trace" ([(truth, reference (i_a, i_b, i_c, w))] at the end of each period), "peak" (the
    reference's largest |phase current|, A), "worst" (the largest phase-current difference,
    A) and the motor."""
    w0 = 2 * RATED_RAD_S
    profile = load_profile(overrides={"initial": {"speed_rad_s": w0, "theta_m_rad": 0.2}})
    T = profile.control_period_s
    ref, log = diode_bridge_reference(profile.motor, 70.0, [0.0, 0.0, w0, 0.2], n * T)
    plant = Plant(profile)
    trace = []
    for k in range(1, n + 1):
        plant.step()
        trace.append((plant.truth(), ref(k * T)))
    return {"log": log, "w0": w0, "trace": trace,
            "peak": max(max(abs(ia), abs(ib), abs(ic)) for _t, (ia, ib, ic, _w) in trace),
            "worst": max(_worst_current(t, r) for t, r in trace), "motor": profile.motor}


def diode_bridge_twice_rated() -> dict:
    """test_diode_bridge_rectifying_at_twice_rated_speed_matches_reference's figures."""
    run = diode_bridge_run()
    w0, m = run["w0"], run["motor"]
    worst_w = max(abs(t[F["speed_rad_s"]] - r[3]) / r[3] for t, r in run["trace"])
    return {"current_error_of_peak": _g(run["worst"] / run["peak"]),
            "speed_error_relative": _g(worst_w), "events": len(run["log"]),
            "peak_a": round(run["peak"], 1),
            "line_back_emf_v": round(math.sqrt(3) * m.pole_pairs * m.flux_linkage_wb * w0, 1)}


#: name -> locked_rotor_run's arguments (Ld (H), Lq (H), theta_m (rad), the axis whose
#: inductance sets the time constant)
LOCKED_ROTOR_CASES = {
    "ld_eq_lq": (4.8e-3, 4.8e-3, 0.0, "d"),
    "ld_ne_lq_along_d": (3.0e-3, 7.0e-3, 0.0, "d"),            # V1 along the d-axis: Ld / R
    "ld_ne_lq_along_q": (3.0e-3, 7.0e-3, math.pi / 2, "q"),    # rotor turned 90 deg: V1 along -q
}


def locked_rotor_run(ld: float, lq: float, theta: float, axis: str) -> dict:
    """V1 held on a locked rotor (70 V, no ADC noise) for 25 time constants L/R, L = Ld or Lq
    by `axis`: i_a(t) = (2U/3)/R (1 - exp(-t R/L)), i_b = i_c = -i_a/2. Returns "r" (ohm),
    "i_final" ((2U/3)/R, A) and "trace" ([(truth, the analytic i_a (A))] after each period)."""
    p = quiet_profile(motor={"inductance_d_h": ld, "inductance_q_h": lq},
                      load={"locked": True}, initial={"theta_m_rad": theta})
    r = p.motor.resistance_ohm
    L = ld if axis == "d" else lq
    i_final = (2 * 70.0 / 3) / r
    plant = Plant(p)
    T = p.control_period_s
    trace = []
    for k in range(1, round(25 * L / r / T) + 1):  # 25 time constants
        plant.step(gates=V1)
        trace.append((plant.truth(), i_final * (1 - math.exp(-k * T * r / L))))
    return {"r": r, "i_final": i_final, "trace": trace}


def locked_rotor() -> dict:
    """test_locked_rotor_dc_current_is_v_over_r_with_l_over_r: worst |i - analytic| over 25
    time constants (all three phases) as a fraction of the final current, per case."""
    out = {}
    for name, case in LOCKED_ROTOR_CASES.items():
        run = locked_rotor_run(*case)
        worst = max(max(abs(t[F["i_a"]] - expected), abs(t[F["i_b"]] + expected / 2),
                        abs(t[F["i_c"]] + expected / 2)) for t, expected in run["trace"])
        out[name] = _g(worst / run["i_final"])
    return out


def six_step_speed(motor, vdc: float, period_s: float) -> float:
    """Steady no-load speed (rad/s, mechanical) of rotor-position six-step drive from the
    back-EMF balance; vdc in V, period_s the sampling period in s.

    Over each 60 deg sector the applied vector sweeps 60..120 deg ahead of the d-axis, so the
    mean voltage is 2U/pi on the q-axis, less the mean commutation lag of half a sampling
    period. With the speed constant the rotor-frame equations are linear, so the mean
    currents obey them exactly:  u_d = R i_d - w L i_q,  u_q = R i_q + w L i_d + w psi_m,
    and the mean torque 1.5 p psi_m i_q balances the damping B w_m."""
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


def six_step_run() -> dict:
    """Self-commutated six-step (vector nearest 90 deg ahead of the rotor) at 5 us sampling,
    inertia cut tenfold (8e-5 kg m^2) so the speed settles, starting at the predicted speed;
    0.25 s to settle, the mean speed over the next 0.15 s. Returns "w_pred" (six_step_speed,
    rad/s), "naive" (2U/(pi psi_m), rad/s) and "w_sim" (the plant's mean speed, rad/s)."""
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
    return {"w_pred": w_pred, "naive": naive, "w_sim": sum(speeds) / len(speeds)}


def six_step() -> dict:
    """test_six_step_no_load_speed_matches_back_emf_balance: the simulated mean speed against
    the balance; and how far the balance is below the naive 2U/(pi psi_m)."""
    run = six_step_run()
    w_sim, w_pred, naive = run["w_sim"], run["w_pred"], run["naive"]
    return {"speed_error_relative": _g(abs(w_sim - w_pred) / w_pred),
            "balance_below_naive": _g(1.0 - w_pred / naive),
            "speed_rad_s": round(w_sim, 2), "naive_rad_s": round(naive, 2)}


def energy_terms(rows: np.ndarray, motor, T: float) -> dict:
    """The energies (J) over truth rows sampled every T s (the first row the start): "dc" =
    sum(v_dc i_dc) T over the rows after the first (what the link gave); by the trapezoid
    rule "copper" = 1.5 R |i_alphabeta|^2, "damping" = B w_m^2, "load" = T_L w_m; "kinetic" =
    0.5 J (w_end^2 - w_0^2); "magnetic" = the change of 0.75 (Ld i_d^2 + Lq i_q^2)."""
    a = rows
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


#: name -> energy_balance_terms' arguments (Ld (H), Lq (H), dead time (s))
ENERGY_BALANCE_CASES = {"ld_eq_lq": (4.8e-3, 4.8e-3, 0.0), "ld_ne_lq": (3.0e-3, 7.0e-3, 0.0),
                        "dead_time_0.5us": (4.8e-3, 4.8e-3, 0.5e-6)}


def energy_balance_terms(ld: float, lq: float, dead_time: float) -> dict:
    """0.15 s of sinusoidal PWM duties at 10 us from rest against a constant (0.2 Nm) plus
    speed-proportional (5e-4 Nm s/rad) load: energy_terms of the run."""
    T = 10e-6
    p = quiet_profile(timing={"control_period_s": T, "max_step_s": T},
                      motor={"inductance_d_h": ld, "inductance_q_h": lq},
                      inverter={"dead_time_s": dead_time},
                      load={"torque_nm": 0.2, "speed_proportional_nm_per_rad_s": 5e-4})
    plant = Plant(p)
    rows = [plant.truth()]
    for _ in range(round(0.15 / T)):
        th = rows[-1][F["theta_e_rad"]]
        duty = [0.5 + 0.45 * math.cos(th + 1.9 - 2 * math.pi * x / 3) for x in range(3)]
        plant.step(duty=duty)
        rows.append(plant.truth())
    return energy_terms(np.array(rows), p.motor, T)


def energy_balance() -> dict:
    """test_energy_balance: |DC-link energy - (copper + kinetic + damping + load + magnetic)|
    / DC-link energy, per case."""
    out = {}
    for name, case in ENERGY_BALANCE_CASES.items():
        e = energy_balance_terms(*case)
        out_ = e["copper"] + e["kinetic"] + e["damping"] + e["load"] + e["magnetic"]
        out[name] = _g(abs(e["dc"] - out_) / e["dc"])
    return out


def regeneration_run() -> dict:
    """50 ms coasting at twice rated speed, all switches off, into a unidirectional link
    (0.2 ohm source, 2 mF) at 10 us. Returns "v" (v_dc per row, V), "returned" (the energy
    the inverter returned, -sum((v_k + v_k-1)/2 i_dc,k) T, J), "stored" (the capacitor's gain
    0.5 C (v_end^2 - v_0^2), J) and "energy" (energy_terms of the run)."""
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
    return {"v": v, "returned": returned, "stored": stored, "energy": energy_terms(a, p.motor, T)}


def regeneration() -> dict:
    """test_regeneration_through_diodes_raises_unidirectional_bus_voltage: the capacitor
    energy against the energy the inverter returned, the mechanical balance, and the largest
    fall of v_dc between samples."""
    run = regeneration_run()
    v, returned, stored, e = run["v"], run["returned"], run["stored"], run["energy"]
    mech = (-e["kinetic"] - e["magnetic"]) - (returned + e["copper"] + e["damping"])
    return {"capacitor_energy_error": _g(abs(returned - stored) / stored),
            "mechanical_balance_error": _g(abs(mech) / returned),
            "largest_v_dc_fall_v": _g(max(0.0, -float(np.min(np.diff(v))))),
            "v_dc_end_v": round(float(v[-1]), 1)}


DEAD_TIME_S, DEAD_TIME_PERIOD_S = 1.0e-6, 50e-6


def dead_time_truth(duty) -> tuple:
    """The truth after 3000 periods of `duty` on a locked rotor with 1 us dead time (50 us)."""
    plant = Plant(quiet_profile(inverter={"dead_time_s": DEAD_TIME_S}, load={"locked": True}))
    for _ in range(3000):
        plant.step(duty=duty)
    return plant.truth()


def dead_time_leg_voltages(duty, signs) -> list[float]:
    """Each leg's mean voltage (V) with dead time td at period T on the 70 V link:
    d U - sign(i) U td / T (the dead interval takes the diode the current picks)."""
    td, T = DEAD_TIME_S, DEAD_TIME_PERIOD_S
    return [d * 70.0 - s * 70.0 * td / T for d, s in zip(duty, signs)]


def dead_time_voltage_error() -> dict:
    """test_dead_time_voltage_error_follows_current_sign: the mean (u_alpha, u_beta) against
    Clarke of dead_time_leg_voltages; the worst difference in volts over the three duty sets."""
    worst = 0.0
    for duty in ((0.6, 0.45, 0.45), (0.4, 0.55, 0.55), (0.45, 0.6, 0.45)):
        t = dead_time_truth(duty)
        signs = [1 if t[F[f"i_{x}"]] > 0 else -1 for x in "abc"]
        expected = clarke(*dead_time_leg_voltages(duty, signs))
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
