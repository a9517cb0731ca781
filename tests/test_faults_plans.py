"""The four fault plans of issue 7 pass from `hil run test_plans/faults/` against the stub.

Whether a measured value is inside its limits is the plan's verdict, not re-asserted here
(that would state each limit twice); tests/test_plans_can_fail.py shows the fault plans'
checks failing on broken inputs."""
from __future__ import annotations

import json
from pathlib import Path

from hil.cli.main import main as hil_main
from hil.logs.reader import read_log
from hil.plans.format import load_plan, plan_files

FAULT_PLANS = Path(__file__).resolve().parent.parent / "test_plans" / "faults"


def test_fault_plans_validate_and_state_their_limits():
    files = plan_files([FAULT_PLANS])
    assert len(files) == 4
    for f in files:
        plan = load_plan(f)
        assert "Limits" in plan.description and plan.checks and plan.plots
        assert any(step.kind == "fault" for step in plan.steps)
        assert plan.min_sim_duration_s() < 1.0


def test_fault_plans_pass(tmp_path, capsys):
    out = tmp_path / "out"
    assert hil_main(["run", str(FAULT_PLANS), "--out", str(out), "--no-progress"]) == 0
    results = {p.parent.name: json.loads(p.read_text()) for p in out.glob("*/result.json")}
    # The plans decide: each check's limits are the plan's, judged by the run. Here only what
    # the plans cannot say about themselves: every check was evaluated, and the run record
    # holds the structure a fault plan promises (injections, link counters, board faults).
    assert len(results) == 4 and all(r["outcome"] == "PASS" for r in results.values())
    for r in results.values():
        assert r["checks"] and all(c["outcome"] in ("PASS", "MARGINAL", "INFO") for c in r["checks"])

    drop = results["fault-sensorless-frame-drop-burst"]
    counters = drop["extra"]["link_counters"]
    assert counters["out_dropped"] > 0 and counters["in_dropped"] > 0
    # a dropped SAMPLE is resent (SPEC 2.8.1) or, past its resends, its period is missed
    assert counters["resent_samples"] + counters["missed_answers"] >= counters["out_dropped"]
    # the plan is about the board riding through missed periods: its resends are off, so the
    # burst reaches the board (with the default 3 resends it would miss none: bench faults)
    assert counters["missed_answers"] > 0 and counters["resent_samples"] == 0
    assert [f["action"] for f in drop["extra"]["faults_injected"]] == ["inject", "lift"]

    loss = results["fault-encoder-loss-detected"]
    assert [f["code"] for f in loss["extra"]["board_faults"]] == [2]
    for r in results.values():
        assert read_log(r["log_path"]).complete
