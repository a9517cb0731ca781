"""Sweep throughput: runs per second with 1 and 2 local workers, and the per-run overhead.

A run's own time is run_plan's wall time (the simulated periods, the session start, the MCAP
log); everything else a sweep spends per run (worker dispatch, plan build with the overrides,
result row and its write) is overhead, measured two ways: in the worker (wall_s - run_wall_s)
and end to end at one worker (wall time / runs - mean run_wall_s, which also includes the
pool's process start and stub library load, spread over the runs).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _sweep(tmp: Path, runs: int):
    from hil.sweep import load_sweep

    path = tmp / "bench.yaml"
    path.write_text(f"""sweep:
  name: bench
  plans: [{REPO / 'test_plans' / 'faults' / '02_encoder_loss_detected.yaml'}]
  seed: 1
  runs: {runs}
  parameters:
    plan.steps[2].wait_until.hold_s: {{uniform: {{low: 0.02, high: 0.08}}}}
  logs: {{failed: true, passing: 0.0}}
""")
    return load_sweep(path)


def run(quick: bool = False) -> dict:
    from hil.sweep.run import run_sweep
    import json

    runs = 12 if quick else 40
    out: dict = {"plan": "faults/02_encoder_loss_detected (0.25 s simulated)", "runs": runs}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        sweep = _sweep(tmp, runs)
        for n in (1, 2):
            t0 = time.monotonic()
            run_sweep(sweep, tmp / f"w{n}", workers=n, progress=False)
            wall = time.monotonic() - t0
            rows = [json.loads(l) for l in (tmp / f"w{n}" / "results.jsonl").read_text().splitlines()]
            run_wall = statistics.mean(r["run_wall_s"] for r in rows)
            in_worker = statistics.mean(r["wall_s"] - r["run_wall_s"] for r in rows)
            out[f"workers_{n}"] = {"wall_s": round(wall, 3), "runs_per_s": round(runs / wall, 2),
                                   "mean_run_s": round(run_wall, 4),
                                   "overhead_in_worker_s": round(in_worker, 5)}
            if n == 1:
                out["overhead_fraction_in_worker"] = round(in_worker / run_wall, 4)
                out["overhead_fraction_end_to_end"] = round((wall / runs - run_wall) / run_wall, 4)
        out["speedup_2_over_1"] = round(out["workers_2"]["runs_per_s"] / out["workers_1"]["runs_per_s"], 2)
    return out
