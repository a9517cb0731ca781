"""The interpreter's share of issue 18's figures: `hil run` start-up and the in-process lockstep
periods (`stub` + full log and the plant alone, bench.session.stub_log_plant_interleaved) on
this .venv's Python against another venv's, taken in turn so that the VM's drift falls on both.

scripts/bootstrap.sh makes .venv from the distribution's /usr/bin/python3 when it is 3.11 or
newer; this is the measurement behind that choice. Set HIL_BENCH_OTHER_VENV to a venv made
from the other interpreter, with the lock file and the package installed, e.g. for this
machine's pyenv build:

    python3 -m venv /tmp/other
    /tmp/other/bin/pip install -q --require-hashes -r requirements.lock
    /tmp/other/bin/pip install -q --no-deps --no-build-isolation -e .

Without it the benchmark says so and measures nothing (`hil bench` runs it that way). Both
interpreters load the same C extensions (same ABI tag), so only the interpreter differs.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.session import TWO_PERIOD_PLAN, timed_hil_run

ROOT = Path(__file__).resolve().parent.parent
# Whether the process maps a libpython shared object: Debian's /usr/bin/python3.11 links the
# interpreter in statically although its sysconfig says --enable-shared (for the library it
# also ships), so the build flags cannot tell.
_DESCRIBE = ("import os, sys; print(os.path.realpath(sys._base_executable), sys.version.split()[0], "
             "any('/libpython' in line for line in open('/proc/self/maps')))")
_LOCKSTEP = ("import json; from bench.session import stub_log_plant_interleaved as f; "
             "print(json.dumps(f(2000, {batches})))")


def _describe(python: Path) -> dict:
    out = subprocess.run([str(python), "-c", _DESCRIBE], capture_output=True, text=True,
                         timeout=60, check=True).stdout.split()
    return {"base_executable": out[0], "version": out[1], "libpython_shared_object": out[2] == "True"}


def _startup(venv: Path, plan: Path, out_dir: Path) -> float:
    took, error = timed_hil_run(venv / "bin" / "hil", plan, out_dir)
    if error is not None:
        raise RuntimeError(f"{venv}: hil run failed: {error}")
    return took


def _lockstep(venv: Path, batches: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([str(venv / "bin" / "python"), "-c", _LOCKSTEP.format(batches=batches)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT, env=env)
    if proc.returncode:
        raise RuntimeError(f"{venv}: lockstep exited {proc.returncode}: {proc.stderr[-500:]}")
    return json.loads(proc.stdout)


def compare(this: Path, other: Path, rounds: int, startups: int, batches: int) -> dict:
    """`rounds` rounds; in each, for each venv in turn, `startups` timed `hil run` of the
    two-period plan and one interleaved lockstep measurement of `batches` batches. Medians."""
    venvs = {"this": this, "other": other}
    start: dict[str, list[float]] = {k: [] for k in venvs}
    logged: dict[str, list[float]] = {k: [] for k in venvs}
    plant: dict[str, list[float]] = {k: [] for k in venvs}
    with tempfile.TemporaryDirectory() as tmp:
        plan = Path(tmp) / "two.yaml"
        plan.write_text(TWO_PERIOD_PLAN)
        for key, venv in venvs.items():             # warms the page cache, not counted
            _startup(venv, plan, Path(tmp) / f"warm-{key}")
        for r in range(rounds):
            for key, venv in venvs.items():
                start[key] += [_startup(venv, plan, Path(tmp) / f"{key}{r}-{i}") for i in range(startups)]
                got = _lockstep(venv, batches)
                logged[key].append(got["stub+log"]["us_per_period"])
                plant[key].append(got["plant_only"]["us_per_period"])
    out: dict = {"rounds": rounds, "startups_per_round": startups, "batches_per_lockstep": batches}
    for key, venv in venvs.items():
        out[key] = {"venv": str(venv), **_describe(venv / "bin" / "python"),
                    "hil_run_startup_median_s": round(statistics.median(start[key]), 3),
                    "stub+log_us_per_period": round(statistics.median(logged[key]), 2),
                    "plant_only_us_per_period": round(statistics.median(plant[key]), 2)}
    for ratio, figure in (("startup", "hil_run_startup_median_s"),
                          ("stub+log_period", "stub+log_us_per_period"),
                          ("plant_only_period", "plant_only_us_per_period")):
        out[f"{ratio}_other_over_this"] = round(out["other"][figure] / out["this"][figure], 3)
    return out


def run(quick: bool = False) -> dict:
    other = os.environ.get("HIL_BENCH_OTHER_VENV")
    if not other:
        return {"skipped": "HIL_BENCH_OTHER_VENV is not set (see python -m bench interpreter's docstring)"}
    this = Path(sys.prefix)
    other_venv = Path(other).resolve()
    if not (other_venv / "bin" / "hil").exists():
        return {"error": f"HIL_BENCH_OTHER_VENV={other}: no bin/hil there (install the package into it)"}
    return compare(this, other_venv, 3 if quick else 7, 3, 5 if quick else 9)
