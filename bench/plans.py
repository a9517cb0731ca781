"""Plan results: every check's measured value for the paper's six plans (test_plans/0[1-6]_*)
on the `paper` profile and the four fault plans (test_plans/faults/), as `hil run` gives them
(lockstep, link `stub`, seed 0). docs/plans.md and docs/faults.md quote these.

`exploratory`: the figures docs/plans.md's findings quote that no check measures, each from a
run of a paper plan (on `paper`) or of a variant of one made in memory (the YAML files are not
touched; a variant's own checks and outcome are not the plan's and are not printed):
- `load_angle` (plan 03): the true load angle, the plant's stator-flux angle
  atan2(psi_beta, psi_alpha) minus its rotor angle theta_e, mean over the 20 ms before each
  speed step and over the torque-limited ramp after it (25 .. 45 ms, the plan's ramp window),
  and the time after the step it first reaches 90 % of the ramp's mean;
- `estimate_spikes` (plan 03): in the 20 ms after each step, the peak error against the rotor
  speed (plant.speed_rad_s) of the EKF's and the filtered estimate, their width at half that
  peak, and of the raw estimate and of the true stator-flux speed, both averaged over 1 ms
  (20 periods; the raw estimate's own per-period noise is 3300 rpm RMS);
- `sensorless_overshoot` (plan 04): the step-up overshoot as run (loop on the EKF) and with the
  plan's `command: {speed_source: ekf}` step left out (loop on the encoder throughout);
- `rotor_position_with_imperfections` (plan 05): its rotor position errors with the profile
  overrides current noise 4 counts RMS, dead time 2 us and device drops 1 V, together (and, not
  in --quick, each alone): RMS and mean (the bias), arctan and EKF angle, and EKF / arctan RMS.

    python -m bench plans            # the ten plans and the exploratory runs (about 8 s)
    python -m bench plans --quick    # plans 01 and 06 and fault plan 02, the exploratory runs
                                     # (plan 05's overrides together only)

No reports or logs are written (`run_plan(..., reports=False)`, no out_dir), so `wall_s` is the
runs alone. The plans' limits and outcomes are printed beside the measured values; this module
sets none of them.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

PLANS = Path(__file__).resolve().parent.parent / "test_plans"
QUICK = {"01_speed_step_sensored", "06_load_step_dc_sag", "02_encoder_loss_detected"}


def _one(path: Path, profile: str | None) -> dict:
    from hil.plans.format import load_plan
    from hil.run.runner import run_plan

    result, _ = run_plan(load_plan(path), reports=False, profile=profile)
    checks = {}
    for c in result.checks:
        measured = None if c.measured is None else float(f"{c.measured:.5g}")
        checks[c.name] = {"measured": measured, "unit": c.unit, "outcome": c.outcome.value,
                          "limits": c.limits.describe() if c.limits is not None else ""}
    return {"profile": result.profile, "outcome": result.outcome.value,
            "simulated_s": round(result.sim_duration_s, 3), "checks": checks}


def _group(paths: list[Path], profile: str | None, quick: bool) -> dict:
    paths = [p for p in paths if not quick or p.stem in QUICK]
    t0 = time.perf_counter()
    plans = {p.stem: _one(p, profile) for p in paths}
    return {"plans": plans,
            "checks": sum(len(p["checks"]) for p in plans.values()),
            "simulated_s": round(sum(p["simulated_s"] for p in plans.values()), 3),
            "wall_s": round(time.perf_counter() - t0, 1)}


RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
T_S = 50e-6                     # the paper profile's control period
IMPERFECTIONS = {                # plan 05's profile overrides, each alone (all_three: together)
    "current_noise_4_counts": {"sensors": {"current": {"noise_rms_counts": 4.0}}},
    "dead_time_2_us": {"inverter": {"dead_time_s": 2e-6}},
    "device_drop_1_v": {"inverter": {"device_drop_v": 1.0}}}


def _r(x: float, digits: int = 1) -> float:
    return round(float(x), digits)


def _paper_run(plan):
    from hil.run.runner import run_plan

    return run_plan(plan, reports=False, profile="paper")


def _mean_1ms(x):
    import numpy as np

    n = round(1e-3 / T_S)
    c = np.cumsum(np.insert(np.asarray(x, dtype=float), 0, 0.0))
    out = np.full(len(x), np.nan)
    out[n - 1:] = (c[n:] - c[:-n]) / n
    return out


def _plan03() -> tuple[dict, dict]:
    """Plan 03 on paper: the load angle and the flux-based estimates' spikes at the steps."""
    import numpy as np

    from hil.plans.format import load_plan

    result, sig = _paper_run(load_plan(PLANS / "03_speed_estimation.yaml"))
    m = result.marks
    t = sig["plant.theta_e_rad"].t_s
    psi_angle = np.arctan2(sig["plant.psi_beta"].values, sig["plant.psi_alpha"].values)
    delta = np.degrees(np.angle(np.exp(1j * (psi_angle - sig["plant.theta_e_rad"].values))))
    rotor = sig["plant.speed_rad_s"].values
    # the true stator-flux speed over 1 ms: its angle's change over 20 periods
    unwrapped = np.unwrap(psi_angle)
    n = round(1e-3 / T_S)
    flux_speed = np.full(len(t), np.nan)
    flux_speed[n:] = (unwrapped[n:] - unwrapped[:-n]) / (t[n:] - t[:-n])
    series = {"ekf": sig["ctrl.speed_ekf_rad_s"].values, "filtered": sig["ctrl.speed_lpf_rad_s"].values,
              "raw_1ms_mean": _mean_1ms(sig["ctrl.speed_raw_rad_s"].values),
              "true_stator_flux_speed_1ms": flux_speed}
    angle, spikes = {}, {}
    for step, label in (("step_up", "1500_to_3000"), ("step_down", "3000_to_1500")):
        k = m[step]
        before = delta[(t >= k - 0.02) & (t < k)].mean()
        ramp = delta[(t >= k + 0.025) & (t < k + 0.045)].mean()
        after = t >= k
        reached = np.nonzero(after & (np.abs(delta - before) >= 0.9 * abs(ramp - before)))[0]
        angle[label] = {"before_deg": _r(before), "torque_limited_ramp_deg": _r(ramp),
                        "jump_deg": _r(ramp - before),
                        "90pct_reached_ms": _r((t[reached[0]] - k) * 1e3, 2) if len(reached) else None}
        w = (t >= k) & (t < k + 0.02)
        spikes[label] = {}
        for name, x in series.items():
            err = (x[w] - rotor[w]) * RPM_PER_RAD_S
            i = int(np.nanargmax(np.abs(err)))
            entry = {"peak_error_rpm": _r(err[i], 0), "at_ms": _r((t[w][i] - k) * 1e3, 2)}
            if name in ("ekf", "filtered"):
                entry["half_peak_width_ms"] = _r(np.count_nonzero(np.abs(err) >= abs(err[i]) / 2)
                                                 * T_S * 1e3, 2)
            spikes[label][name] = entry
    return angle, spikes


def _plan04() -> dict:
    """Plan 04's step-up overshoot on the EKF, and the same run with the loop left on the encoder."""
    import dataclasses

    from hil.plans.format import CommandStep, load_plan

    plan = load_plan(PLANS / "04_sensorless_ekf.yaml")
    on_encoder = dataclasses.replace(plan, steps=tuple(
        s for s in plan.steps
        if not (isinstance(s, CommandStep) and s.changes() == {"speed_source": "ekf"})))

    def overshoot(p) -> float:
        result, _ = _paper_run(p)
        return next(c.measured for c in result.checks if c.name == "overshoot on the step up")

    ekf, encoder = overshoot(plan), overshoot(on_encoder)
    return {"overshoot_on_the_ekf_pct": _r(ekf, 2), "overshoot_on_the_encoder_pct": _r(encoder, 2),
            "added_by_the_ekf_pct_points": _r(ekf - encoder, 2)}


def _plan05(quick: bool) -> dict:
    """Plan 05 on paper with imperfections as profile overrides: rotor position errors."""
    import dataclasses

    import numpy as np

    from hil.plans.format import load_plan

    plan = load_plan(PLANS / "05_rotor_position.yaml")
    variants = {"all_three": {"sensors": {"current": {"noise_rms_counts": 4.0}},
                              "inverter": {"dead_time_s": 2e-6, "device_drop_v": 1.0}}}
    if not quick:
        variants.update(IMPERFECTIONS)
    out = {}
    for label, overrides in variants.items():
        result, sig = _paper_run(dataclasses.replace(plan, overrides=overrides))
        truth = sig["plant.theta_e_rad"]
        w = truth.t_s >= result.marks["steady"]
        row = {}
        for name, key in (("arctan", "ctrl.rotor_pos_conv_rad"), ("ekf", "ctrl.rotor_pos_ekf_rad")):
            err = np.degrees(np.angle(np.exp(1j * (sig[key].values[w] - truth.values[w]))))
            row[f"{name}_rms_deg"] = _r(np.sqrt(np.mean(err ** 2)), 2)
            row[f"{name}_mean_deg"] = _r(err.mean(), 2)
        row["ekf_over_arctan_rms"] = _r(row["ekf_rms_deg"] / row["arctan_rms_deg"], 3)
        out[label] = row
    return out


def exploratory(quick: bool = False) -> dict:
    t0 = time.perf_counter()
    angle, spikes = _plan03()
    out = {"load_angle": angle, "estimate_spikes": spikes, "sensorless_overshoot": _plan04(),
           "rotor_position_with_imperfections": _plan05(quick)}
    out["wall_s"] = _r(time.perf_counter() - t0)
    return out


def run(quick: bool = False) -> dict:
    return {"paper_plans_on_paper": _group(sorted(PLANS.glob("0[1-6]_*.yaml")), "paper", quick),
            "fault_plans": _group(sorted((PLANS / "faults").glob("0[1-4]_*.yaml")), None, quick),
            "exploratory": exploratory(quick),
            "run": "lockstep, link stub, seed 0, no reports"}
