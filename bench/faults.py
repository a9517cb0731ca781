"""Fault-plan figures that no check of the plans measures: the speed minimum and recovery of
test_plans/faults/01_sensorless_frame_drop_burst (as `hil run` runs it: its own override turns
the session's SAMPLE resends off, as the session was when the plan was written; and with the
session's default 3 resends, which recover every period of its burst), and the speed dip of
test_plans/faults/03_resistance_drift during and after its 50 ms resistance ramp. docs/faults.md
quotes them.

    python -m bench faults            # both plans; plan 01 also over link_drop seeds 1-6 (about 5 s)
    python -m bench faults --quick    # both plans, plan 01 on its own seed only

Each run is the plan as `hil run` gives it (lockstep, link `stub`, seed 0, no reports, no log;
`hil.run.runner.run_plan`), the figures computed from the run's signals (plant.speed_rpm, the
plan's marks) and, where a check measures the same thing, taken from the check. Plan 01's
variants change only the run: `session.answer_resends` 3 instead of the plan's 0, or the
link_drop fault's `seed`. Deterministic: every fault and noise
stream is seeded.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

FAULT_PLANS = Path(__file__).resolve().parent.parent / "test_plans" / "faults"
BURST = FAULT_PLANS / "01_sensorless_frame_drop_burst.yaml"
DRIFT = FAULT_PLANS / "03_resistance_drift.yaml"
REFERENCE_RPM = 1500.0          # both plans' speed reference
RAMP_S = 0.05                   # plan 03's ramp_s


def _r(x: float, digits: int = 1) -> float:
    return round(float(x), digits)


def _run(plan):
    from hil.run.runner import run_plan

    return run_plan(plan, reports=False)


def _burst_plan(resends: int | None = None, seed: int | None = None):
    """Plan 01, optionally with `session.answer_resends` overridden and the link_drop seed
    replaced (nothing else of the plan changes)."""
    from hil.plans.format import FaultStep, load_plan

    plan = load_plan(BURST)
    if resends is not None:
        plan = dataclasses.replace(plan, overrides={"session": {"answer_resends": resends}})
    if seed is not None:
        steps = tuple(dataclasses.replace(s, args={**s.args, "seed": seed})
                      if isinstance(s, FaultStep) and s.name == "link_drop" else s
                      for s in plan.steps)
        plan = dataclasses.replace(plan, steps=steps)
    return plan


def _burst(resends: int | None = None, seed: int | None = None) -> dict:
    import numpy as np

    result, signals = _run(_burst_plan(resends, seed))
    speed = signals["plant.speed_rpm"]
    after = speed.t_s >= result.marks["burst"]
    v = speed.values[after]
    i = int(np.argmin(v))
    checks = {c.name: c for c in result.checks}
    back = checks["back within 1 % after the burst"].measured
    link = result.extra.get("link_counters", {})
    return {"outcome": result.outcome.value,
            "speed_min_rpm": _r(v[i]),
            "speed_min_after_burst_ms": _r((speed.t_s[after][i] - result.marks["burst"]) * 1e3),
            "speed_max_rpm": _r(v.max()),
            "back_within_1pct_ms": None if back is None else _r(back),
            "samples_dropped": link.get("out_dropped"),
            "answers_dropped": link.get("in_dropped"),
            "samples_resent": link.get("resent_samples"),
            "periods_missed": link.get("missed_answers")}


def _drift() -> dict:
    import numpy as np

    from hil.plans.format import load_plan

    result, signals = _run(load_plan(DRIFT))
    m = result.marks
    speed = signals["plant.speed_rpm"]
    t, v = speed.t_s, speed.values
    window = (t >= m["drift"]) & (t <= m["hot"])
    i = int(np.argmin(v[window]))
    cold = (t >= m["drift"] - 0.1) & (t < m["drift"])
    ramp_end = int(np.argmin(np.abs(t - (m["drift"] + RAMP_S))))
    checks = {c.name: c for c in result.checks}
    return {"outcome": result.outcome.value,
            "speed_min_rpm": _r(v[window][i]),
            "dip_below_reference_rpm": _r(REFERENCE_RPM - v[window][i]),
            "dip_at_ms_after_drift_start": _r((t[window][i] - m["drift"]) * 1e3),
            "dip_below_cold_mean_rpm": _r(v[cold].mean() - v[window][i]),
            "cold_mean_rpm": _r(v[cold].mean(), 2),
            "below_reference_at_ramp_end_rpm": _r(REFERENCE_RPM - v[ramp_end]),
            "check_speed_dip_during_the_drift": _r(checks["speed dip during the drift"].measured)}


def run(quick: bool = False) -> dict:
    t0 = time.perf_counter()
    burst = {"as_run": _burst(),
             "with_3_resends": _burst(resends=3)}
    if not quick:
        burst["link_drop_seeds_1_6"] = {
            "as_run_speed_min_rpm": [_burst(seed=s)["speed_min_rpm"] for s in range(1, 7)],
            "with_3_resends_speed_min_rpm": [_burst(resends=3, seed=s)["speed_min_rpm"]
                                             for s in range(1, 7)]}
    out = {"01_sensorless_frame_drop_burst": burst,
           "03_resistance_drift": _drift(),
           "wall_s": _r(time.perf_counter() - t0),
           "run": "lockstep, link stub, seed 0, no reports; plan 01 as run (its override: "
                  "no SAMPLE resends) and with the session's default 3 resends"}
    return out
