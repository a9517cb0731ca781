"""One run of a sweep, in whichever process runs it (a local pool process or a Dask worker).

`run_one(task)` takes and returns plain data (picklable, no project objects), so the same
function runs under concurrent.futures and Dask. It never raises for what a plan or board
does (the row says PASS/FAIL/ERROR with the reason); an exception here is a failure of the
worker itself, which the executor retries.
"""
from __future__ import annotations

import contextlib
import math
import os
import shutil
import socket
import time
from pathlib import Path
from typing import Any

_PLAN_DOCS: dict[str, Any] = {}     # per process: each plan file is read once


def _num(x):
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


def run_one(task: dict) -> dict:
    t0 = time.monotonic()
    from configfile.source import ConfigError, load_yaml
    from hil.run.runner import run_plan
    from hil.sweep.format import build_plan

    plan_path = Path(task["plan_path"])
    doc = _PLAN_DOCS.get(str(plan_path))
    if doc is None:
        doc = _PLAN_DOCS[str(plan_path)] = load_yaml(plan_path)
    row: dict[str, Any] = {
        "index": task["index"], "plan_file": str(plan_path), "point": task["point"],
        "sample": task["sample"], "seed": task["seed"], "params": dict(task["values"]),
        "worker": f"{socket.gethostname()}:{os.getpid()}", "lost": False,
    }
    try:
        plan = build_plan(doc, plan_path, {**task["fixed"], **task["values"]})
    except (ConfigError, KeyError, IndexError, TypeError) as exc:
        row.update(plan=plan_path.stem, outcome="ERROR", reason=f"parameters rejected: {exc}",
                   checks=[], sim_s=0.0, run_wall_s=0.0, log=None,
                   wall_s=time.monotonic() - t0)
        return row
    run_dir = Path(task["out_dir"]) / f"{task['index']:06d}" if task.get("out_dir") else None
    # The session's warnings (board FAULTs) go to stderr; in a sweep the row carries them.
    with open(os.devnull, "w") as quiet, contextlib.redirect_stderr(quiet):
        result, _signals = run_plan(plan, link=task["link"], out_dir=run_dir, seed=task["seed"],
                                    reports=False, board=task.get("board"))
    passed = result.outcome.passed
    log = result.log_path
    keep = (task["keep_failed"] if not passed else task["keep_passing"])
    if run_dir is not None and not keep:
        shutil.rmtree(run_dir, ignore_errors=True)
        log = None
    row.update(
        plan=result.plan_name, outcome=result.outcome.value, reason=result.reason,
        # each run's limits: formulas evaluated with this run's sampled profile
        checks=[{"name": c.name, "measured": _num(c.measured), "unit": c.unit,
                 "outcome": c.outcome.value,
                 "limits": None if c.limits is None else c.limits.to_json()}
                for c in result.checks],
        sim_s=float(result.sim_duration_s), run_wall_s=float(result.wall_duration_s), log=log,
        wall_s=time.monotonic() - t0)
    return row
