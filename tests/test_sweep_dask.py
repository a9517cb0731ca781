"""hil sweep on a real Dask cluster: a scheduler and two workers started here as processes on
127.0.0.1, one worker killed (SIGKILL) mid-sweep; every run is accounted for exactly once."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from hil.sweep import load_sweep
from hil.sweep.run import run_sweep

REPO = Path(__file__).resolve().parents[1]
DASK = Path(sys.executable).parent / "dask"
PLAN = REPO / "tests" / "data" / "sweep" / "short_plan.yaml"
BOUND_S = 60.0


def _wait_for(pred, what, timeout=BOUND_S):
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.1)


@pytest.fixture
def cluster(tmp_path):
    if not DASK.exists():
        pytest.skip("no dask command in the venv")
    sched_file = tmp_path / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": str(REPO), "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "3"}
    procs = [subprocess.Popen([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(sched_file)],
                              cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        _wait_for(lambda: sched_file.exists() and sched_file.stat().st_size > 0, "the scheduler")
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        workers = [subprocess.Popen([str(DASK), "worker", address, "--host", "127.0.0.1",
                                     "--nthreads", "1", "--no-nanny", "--no-dashboard"],
                                    cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL) for _ in range(2)]
        procs += workers
        from distributed import Client

        with Client(address, timeout=20, set_as_default=False) as c:
            c.wait_for_workers(2, timeout=BOUND_S)
        yield address, workers
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=3)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=10)


def test_worker_killed_mid_sweep_every_run_once(tmp_path, cluster):
    address, workers = cluster
    runs = 16
    path = tmp_path / "s.yaml"
    path.write_text(f"""sweep:
  name: dask-kill
  plans: [{PLAN}]
  seed: 3
  runs: {runs}
  parameters:
    profile.motor.inertia_kgm2: {{uniform: {{low: 6.0e-4, high: 1.0e-3}}}}
""")
    sweep = load_sweep(path)
    out = tmp_path / "out"
    result: dict = {}

    def go():
        try:
            result["summary"] = run_sweep(sweep, out, cluster=address, progress=False,
                                          stall_timeout_s=BOUND_S)
        except BaseException as exc:  # noqa: BLE001 - reported by the test below
            result["error"] = exc

    t = threading.Thread(target=go, daemon=True)
    t.start()
    jsonl = out / "results.jsonl"
    _wait_for(lambda: "error" in result or (jsonl.exists() and len(jsonl.read_text().splitlines()) >= 3),
              "3 results")
    assert "error" not in result, result.get("error")
    done_at_kill = len(jsonl.read_text().splitlines())
    workers[0].send_signal(signal.SIGKILL)
    workers[0].wait(timeout=10)
    assert done_at_kill < runs, "the worker was killed after the sweep had finished"
    t.join(timeout=2 * BOUND_S)
    assert not t.is_alive(), "the sweep did not finish after a worker died"
    assert "error" not in result, result.get("error")
    lines = [json.loads(l) for l in jsonl.read_text().splitlines()]
    indices = [r["index"] for r in lines]
    assert sorted(indices) == list(range(runs)), "a run is missing or recorded twice"
    # every run has a verdict or, if Dask gave up on it, an ERROR row with the reason
    for r in lines:
        assert r["outcome"] in ("PASS", "FAIL") or (r["lost"] and r["reason"]), r
    workers_seen = {r["worker"] for r in lines if r["worker"]}
    assert len(workers_seen) >= 1
    # the same table as one local process gives
    local = run_sweep(sweep, tmp_path / "local", workers=1, progress=False, stall_timeout_s=BOUND_S)
    assert local["plans"] == result["summary"]["plans"] or any(r["lost"] for r in lines)
