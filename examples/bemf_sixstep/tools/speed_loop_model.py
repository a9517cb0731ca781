"""Design model of the bemf_sixstep speed loop, for the plans' limits (run before any plan).

    python examples/bemf_sixstep/tools/speed_loop_model.py

The loop as designed, not the firmware: a rigid rotor J dw/dt = k_t i - B w - T_load; the
pair current follows its reference through the current PI's first-order pole (w_c); the
speed is measured as the firmware does it, 120 electrical degrees over the sum of the last two
60-degree intervals between zero crosses, each cross interpolated to a quarter period and the
estimate updated at each cross; the hand-over starts the integrator at zero; the speed PI (kp = 2 J w, ki = J w^2, conditional
integration, output limited to T_max) runs every period on the latest estimate. It prints
the figures the plans' descriptions quote: rise time, overshoot and settling of the start
(from the hand-over speed) and of the speed step, the dip and recovery of the load step.
"""
from __future__ import annotations

import math

P = 4                 # pole pairs
PSI = 0.0060          # Wb
J = 2.0e-5            # kg m2
B = 2.0e-6            # Nm/(rad/s)
T_PERIOD = 50e-6
T_MAX = 0.15          # board torque limit
KP = 2.5133e-3        # board speed PI
KI = 0.078957
WC = 2 * math.pi * 500.0
KT = 2 * P * PSI      # 0.048 Nm/A
RPM = 2 * math.pi / 60
N_INTERVALS = 2       # 60-degree intervals per speed estimate (src/bemf.h BEMF_INTERVALS)
RESOLUTION = 0.25     # of a cross's time, periods (interpolated from the terminal voltages)


def simulate(w0: float, w_ref: float, t_end: float, integral0: float, load_at: float | None = None,
             load_nm: float = 0.0, n: int = N_INTERVALS, resolution: float = RESOLUTION):
    w = w0
    i = integral0 / KT
    integral = integral0
    theta = 0.0                   # electrical angle since the last cross
    intervals = [(math.pi / 3) / (P * w0 * T_PERIOD)] * n
    last_cross = 0.0
    w_est = n * (math.pi / 3) / (P * sum(intervals) * T_PERIOD)
    out = []
    for k in range(int(t_end / T_PERIOD)):
        t = k * T_PERIOD
        e = w_ref - w_est
        p = KP * e
        cand = integral + KI * T_PERIOD * e
        u = p + cand
        if (u > T_MAX and e > 0) or (u < -T_MAX and e < 0):
            tref = math.copysign(T_MAX, u)
        else:
            integral = max(-T_MAX, min(T_MAX, cand))
            tref = max(-T_MAX, min(T_MAX, p + integral))
        load = load_nm if load_at is not None and t >= load_at else 0.0
        sub = 20
        for _ in range(sub):
            i += (tref / KT - i) * WC * T_PERIOD / sub
            w += (KT * i - B * w - load) / J * T_PERIOD / sub
        step = P * w * T_PERIOD
        theta += step
        if theta >= math.pi / 3:
            theta -= math.pi / 3
            # the cross, in periods, to the firmware's resolution (interpolated between samples)
            cross = k + 1 - theta / step
            cross = round(cross / resolution) * resolution
            intervals = intervals[1:] + [cross - last_cross] if k > 0 else intervals
            last_cross = cross
            w_est = n * (math.pi / 3) / (P * sum(intervals) * T_PERIOD)
        out.append((t + T_PERIOD, w, KT * i))
    return out


def step_figures(rows, w0, w1):
    ts = [r[0] for r in rows]
    ws = [r[1] for r in rows]
    step = w1 - w0

    def first(frac):
        for t, w in zip(ts, ws):
            if (w - w0) / step >= frac:
                return t
        return math.inf
    rise = first(0.9) - first(0.1)
    over = max(0.0, (max(ws) - w1) / step * 100)
    band = 0.02 * abs(step)
    settle = 0.0
    for t, w in zip(ts, ws):
        if abs(w - w1) > band:
            settle = t
    return rise, over, settle, ws[-1]


def main() -> None:
    hand_over = 50.0              # the board's ramp_end_rad_s
    start = 0.5 * 4000 * RPM      # plan 01's target, plan 02's start
    target = 0.75 * 4000 * RPM    # plan 02's target, plan 03's speed
    rows = simulate(hand_over, start, 0.4, 0.0)   # the hand-over zeroes the integrator
    r, o, s, f = step_figures(rows, hand_over, start)
    print(f"start {hand_over/RPM:.0f} -> {start/RPM:.0f} rpm: rise {r*1e3:.1f} ms, overshoot {o:.2f} %, "
          f"settle 2 % {s*1e3:.1f} ms, final {f/RPM:.1f} rpm (ramp J dw / T_max "
          f"{J*(start-hand_over)/T_MAX*1e3:.1f} ms)")
    rows = simulate(start, target, 0.4, B * start)
    r, o, s, f = step_figures(rows, start, target)
    print(f"step {start/RPM:.0f} -> {target/RPM:.0f} rpm: rise {r*1e3:.1f} ms, overshoot {o:.2f} %, "
          f"settle 2 % {s*1e3:.1f} ms, final {f/RPM:.1f} rpm (ramp {J*(target-start)/T_MAX*1e3:.1f} ms)")
    load = 0.5 * T_MAX
    rows = simulate(target, target, 0.5, B * target, load_at=0.1, load_nm=load)
    after = [r for r in rows if r[0] >= 0.1]
    dip = min(r[1] for r in after)
    t_dip = [r[0] for r in after if r[1] == dip][0] - 0.1
    rec = 0.0
    for t, w, _ in after:
        if abs(w - target) > 0.01 * target:
            rec = t - 0.1
    tmax = max(r[2] for r in after)
    wb = math.sqrt(KI / J)
    print(f"load step {load} Nm at {target/RPM:.0f} rpm: dip {(target-dip)/RPM:.1f} rpm at {t_dip*1e3:.1f} ms "
          f"(ideal double pole dT/(J w_b e) = {load/(J*wb*math.e)/RPM:.1f} rpm at 1/w_b = "
          f"{1e3/wb:.1f} ms), back within 1 % after {rec*1e3:.1f} ms, "
          f"peak torque {tmax:.4f} Nm, final {after[-1][1]/RPM:.1f} rpm")


if __name__ == "__main__":
    main()
