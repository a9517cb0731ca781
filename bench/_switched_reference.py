"""An independent switched-circuit reference for the plant's PWM paths (issue 14): the circuit
written from its equations, not from the plant's code, integrated by scipy's solve_ivp.

Per phase L di_x/dt = V_x - V_n - R i_x - e_x (surface magnets, star point floating), with the
leg's terminal V_x set by which switch is on (its rail minus U_d clamp(i/knee)), or, with both
off, by the diode the current picks (-U_d for i > 0, v_dc + U_d for i < 0); a phase whose
current reaches zero with both switches off floats (its terminal at V_n + e_x) until a switch
turns on or its terminal reaches a rail. solve_ivp (DOP853, rtol 1e-10) integrates each
constant-switch interval with these events located; the switch timing is built here too:
centre-aligned PWM with the carrier valley at the sampling instant, every turn-on edge delayed
by the dead time.

A phase whose current reaches zero while both its switches are off floats only if its
terminal stays between the rails; at twice rated speed the line back-EMF exceeds the link and
the opposite diode takes over at once. Until 2026-11-24 this reference left such a phase
floating (its rail events fire on a crossing, and the terminal was already beyond the rail),
which was the 1.8e-4 "unexplained" error at twice rated speed: the plant was right.

`run()` drives a plant and the reference side by side through random duties that follow the
rotor; tests/test_plant_pwm_reference.py asserts its limits, `python -m bench plant_accuracy`
prints its figures.
"""
from __future__ import annotations

import math
import random

from plant_rt import TRUTH_FIELDS, Plant, load_profile

F = {name: i for i, name in enumerate(TRUTH_FIELDS)}
RATED_RAD_S = 3000.0 * 2.0 * math.pi / 60.0


class SwitchedCircuit:
    """The three-phase bridge and the motor in phase quantities; state (i_a, i_b, w, theta_m,
    e_dc) with i_c = -i_a - i_b and e_dc = int v_dc i_dc dt."""

    def __init__(self, motor, vdc: float, drop: float, knee: float):
        self.p, self.r, self.psim = motor.pole_pairs, motor.resistance_ohm, motor.flux_linkage_wb
        self.L, self.j, self.b = motor.inductance_d_h, motor.inertia_kgm2, \
            motor.damping_nm_per_rad_s
        self.vdc, self.drop, self.knee = vdc, drop, knee

    def emf_shape(self, th):
        """e_x = w * shape_x: the phase back-EMF per mechanical rad/s."""
        p = self.p
        return [-p * self.psim * math.sin(p * th - 2.0 * math.pi * x / 3.0) for x in range(3)]

    def terminal(self, x, sw, i):
        """Terminal voltage of a conducting leg x (sw: 'H', 'L' switch on, or 'P'/'N' diode)."""
        if sw == "H" or sw == "L":
            z = max(-1.0, min(1.0, i / self.knee))
            return (self.vdc if sw == "H" else 0.0) - self.drop * z
        return -self.drop if sw == "P" else self.vdc + self.drop

    def rhs(self, modes):
        """modes[x]: 'H', 'L', 'P', 'N' (conducting) or 'F' (floating, i_x = 0)."""
        def f(_t, s):
            ia, ib, w, th, _ = s
            i = [ia, ib, -ia - ib]
            k = self.emf_shape(th)
            e = [w * kx for kx in k]
            on = [x for x in range(3) if modes[x] != "F"]
            v = {x: self.terminal(x, modes[x], i[x]) for x in on}
            di = [0.0, 0.0, 0.0]
            if len(on) == 3:
                vn = sum(v.values()) / 3.0          # sum e = 0, sum di = 0
                di = [(v[x] - vn - self.r * i[x] - e[x]) / self.L for x in range(3)]
            elif len(on) == 2:
                y, z = on
                d = (v[y] - v[z] - self.r * (i[y] - i[z]) - (e[y] - e[z])) / (2.0 * self.L)
                di[y], di[z] = d, -d
            torque = sum(kx * ix for kx, ix in zip(k, i))
            high = [x for x in on if modes[x] == "H" or modes[x] == "N"]
            p_dc = self.vdc * sum(i[x] for x in high)
            return [di[0], di[1], (torque - self.b * w) / self.j, w, p_dc]
        return f

    def float_voltage(self, modes, s):
        """Terminal voltage of the floating phase (the other two conduct)."""
        ia, ib, w, th, _ = s
        i = [ia, ib, -ia - ib]
        e = [w * kx for kx in self.emf_shape(th)]
        x = modes.index("F")
        y, z = [k for k in range(3) if k != x]
        vn = (self.terminal(y, modes[y], i[y]) + self.terminal(z, modes[z], i[z])
              - e[y] - e[z]) / 2.0
        return vn + e[x]


def leg_switches(duty: float, T: float, td: float):
    """[(t_start, t_end, high_on, low_on)] over one period (duty within (2 td/T, 1 - 2 td/T):
    the low switch is on at the period's start, turned on td after the last period's edge)."""
    t_on, t_off = 0.5 * T * (1.0 - duty), 0.5 * T * (1.0 + duty)
    return [(0.0, t_on, False, True), (t_on, t_on + td, False, False),
            (t_on + td, t_off, True, False), (t_off, t_off + td, False, False),
            (t_off + td, T, False, True)]


def reference_period(circ: SwitchedCircuit, s, duty, T: float, td: float, modes):
    """One period from state s; modes carries diode / floating states across intervals."""
    # scipy is a test and benchmark dependency, not a runtime one (requirements-runtime.lock):
    # imported where it is used, so the module imports with the runtime set
    from scipy.integrate import solve_ivp

    legs = [leg_switches(d, T, td) for d in duty]
    times = sorted({t for leg in legs for seg in leg for t in seg[:2]})
    for t0, t1 in zip(times, times[1:]):
        if t1 - t0 <= 1e-15:
            continue
        sw = []
        for leg in legs:
            for a, b, hi, lo in leg:
                if a <= t0 < b:
                    sw.append("H" if hi else "L" if lo else None)
        t = t0
        while t1 - t > 1e-15:
            i = [s[0], s[1], -s[0] - s[1]]
            cur = []
            for x in range(3):
                if sw[x] is not None:
                    cur.append(sw[x])
                elif modes[x] in ("P", "N", "F"):
                    cur.append(modes[x])
                else:
                    cur.append("P" if i[x] > 0.0 else "N" if i[x] < 0.0 else "F")
            if cur.count("F") >= 2:
                raise AssertionError("two floating phases: not met in these runs")
            if "F" in cur:
                # A phase can only float while its terminal stays between the rails: one that
                # would float beyond a rail (its current just reached zero with the line
                # back-EMF above the link, as at twice rated speed) has that rail's diode on at
                # once. The float events below only see the terminal cross a rail later.
                x = cur.index("F")
                v = circ.float_voltage(cur, s)
                if v > circ.vdc + circ.drop:
                    cur[x] = "N"
                elif v < -circ.drop:
                    cur[x] = "P"
            events, tags = [], []
            for x in range(3):
                if cur[x] in ("P", "N"):
                    def ev(_t, y, x=x):
                        return (y[0], y[1], -y[0] - y[1])[x]
                    ev.terminal, ev.direction = True, (-1 if cur[x] == "P" else 1)
                    events.append(ev)
                    tags.append(("zero", x))
            if "F" in cur:
                def hi(_t, y, m=tuple(cur)):
                    return circ.float_voltage(list(m), y) - (circ.vdc + circ.drop)

                def lo(_t, y, m=tuple(cur)):
                    return circ.float_voltage(list(m), y) + circ.drop
                hi.terminal, hi.direction = True, 1
                lo.terminal, lo.direction = True, -1
                events += [hi, lo]
                tags += [("hi", cur.index("F")), ("lo", cur.index("F"))]
            sol = solve_ivp(circ.rhs(cur), (t, t1), s, method="DOP853", rtol=1e-10,
                            atol=1e-12, events=events or None)
            s = list(sol.y[:, -1])
            t = sol.t[-1]
            for x in range(3):
                modes[x] = cur[x] if sw[x] is None else sw[x]
            if sol.status == 1:
                what = [tag for n, tag in enumerate(tags) if len(sol.t_events[n])][0]
                x = what[1]
                if what[0] == "zero":
                    modes[x] = "F"
                    i = [s[0], s[1], -s[0] - s[1]]
                    i[x] = 0.0
                    y, z = [k for k in range(3) if k != x]
                    d = 0.5 * (i[y] - i[z])
                    i[y], i[z] = d, -d
                    s[0], s[1] = i[0], i[1]
                else:
                    modes[x] = "N" if what[0] == "hi" else "P"
    return s


def start_after_first_period(plant, duty):
    """The plant starts from the all-open command (its low switches turn on td into the
    first period, from rest currents or through the diodes); the reference takes over from
    the end of that first period, where every low switch is on."""
    plant.step(duty=duty)
    t = plant.truth()
    return [t[F["i_a"]], t[F["i_b"]], t[F["speed_rad_s"]], t[F["theta_m_rad"]], 0.0], \
        ["L", "L", "L"]


def run(speed: float, n: int, seed: int, td: float, drop: float, knee: float = 0.1):
    T = 50e-6
    profile = load_profile(overrides={
        "initial": {"speed_rad_s": speed},
        "inverter": {"dead_time_s": td, "device_drop_v": drop, "device_knee_a": knee}})
    circ = SwitchedCircuit(profile.motor, 70.0, drop, knee)
    plant = Plant(profile)
    rng = random.Random(seed)
    lo_d, hi_d = 2.5 * td / T, 1.0 - 2.5 * td / T
    s, modes = start_after_first_period(plant, (0.5, 0.5, 0.5))
    peak = err = 0.0
    e_plant = e_abs = 0.0
    crossings = 0
    prev = None
    p = profile.motor.pole_pairs
    for k in range(n):
        # Random duties around a sinusoidal set that follows the rotor (currents swing
        # through zero every electrical half turn).
        th = p * s[3] + 1.8
        duty = tuple(min(hi_d, max(lo_d, 0.5 + 0.35 * math.cos(th - 2 * math.pi * x / 3)
                                   + 0.1 * (rng.random() - 0.5))) for x in range(3))
        e_before = s[4]
        s = reference_period(circ, s, duty, T, td, modes)
        plant.step(duty=duty)
        t = plant.truth()
        ref = (s[0], s[1], -s[0] - s[1])
        if prev is not None:
            crossings += sum(1 for a, b in zip(prev, ref) if a * b < 0.0)
        prev = ref
        peak = max(peak, *(abs(v) for v in ref))
        err = max(err, abs(t[F["i_a"]] - ref[0]), abs(t[F["i_b"]] - ref[1]),
                  abs(t[F["i_c"]] - ref[2]))
        e_plant += t[F["v_dc"]] * t[F["i_dc"]] * T
        e_abs += abs(s[4] - e_before)
    return {"peak": peak, "current_rel": err / peak, "crossings": crossings,
            "energy_rel": abs(e_plant - s[4]) / e_abs, "e_abs": e_abs}
