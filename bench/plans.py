"""Plan results: every check's measured value for the paper's six plans (test_plans/0[1-6]_*)
on the `paper` profile and the four fault plans (test_plans/faults/), as `hil run` gives them
(lockstep, link `stub`, seed 0). docs/plans.md and docs/faults.md quote these.

    python -m bench plans            # the ten plans (about 5 s on 2 shared cores)
    python -m bench plans --quick    # plans 01 and 06 and fault plan 02 only

No reports or logs are written (`run_plan(..., reports=False)`, no out_dir), so `wall_s` is the
runs alone. The plans' limits and outcomes are printed beside the measured values; this module
sets none of them.
"""
from __future__ import annotations

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


def run(quick: bool = False) -> dict:
    return {"paper_plans_on_paper": _group(sorted(PLANS.glob("0[1-6]_*.yaml")), "paper", quick),
            "fault_plans": _group(sorted((PLANS / "faults").glob("0[1-4]_*.yaml")), None, quick),
            "run": "lockstep, link stub, seed 0, no reports"}
