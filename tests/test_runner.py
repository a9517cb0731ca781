"""Plan execution: stimuli act when their step runs, outcomes at plan level are right."""
from __future__ import annotations

import numpy as np
import pytest

from hil.plans.outcome import Outcome
from hil.plans.format import parse_plan
from hil.run.runner import run_plan


def _run(text: str, **kwargs):
    return run_plan(parse_plan(text, "inline.yaml"), **kwargs)


def test_stimuli_act_at_their_step_and_are_recorded():
    result, signals = _run("""
name: stimuli
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1000}
  - run: {duration_s: 0.02}
  - mark: load_on
  - load: {type: table, points: [[0, 0.0], [0.005, 0.2], [0.01, 0.0]], repeat: true}
  - run: {duration_s: 0.025}
  - load: {type: speed_proportional, nm_per_rad_s: 0.001, offset_nm: 0.05}
  - dc_link: {voltage_v: 60, ramp_s: 0.01}
  - plant_param: {resistance_ohm: 0.7}
  - run: {duration_s: 0.02}
""")
    assert result.outcome is Outcome.PASS, result.reason
    t = signals["plant.load_torque_nm"].t_s
    load = signals["plant.load_torque_nm"].values
    t_on = result.marks["load_on"]
    assert np.all(load[t < t_on] == 0.0)
    # Repeated triangle with a 10 ms period: peaks of 0.2 Nm at 5 ms and 15 ms after the step.
    for peak in (0.005, 0.015):
        i = int(np.argmin(np.abs(t - (t_on + peak))))
        assert load[i] == pytest.approx(0.2, abs=0.01)
    i = int(np.argmin(np.abs(t - (t_on + 0.010))))
    assert load[i] == pytest.approx(0.0, abs=0.01)
    # Speed-proportional with offset at the end: 0.05 + 0.001 * w.
    w = signals["plant.speed_rad_s"].values[-1]
    assert load[-1] == pytest.approx(0.05 + 0.001 * w, rel=1e-3)
    # DC link ramped to 60 V within 10 ms.
    assert signals["plant.v_dc"].values[-1] == pytest.approx(60.0, abs=0.5)


def test_wait_until_times_out_to_the_period_and_skips_the_rest():
    result, signals = _run("""
name: never
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 500}
  - wait_until: {signal: plant.speed_rpm, comparison: above, value: 5000, unit: rpm, timeout_s: 0.02}
  - run: {duration_s: 1.0}
  - check: {name: unreachable, kind: final_value, signal: plant.speed_rpm, limits: {low: 0, unit: rpm}}
""")
    assert result.outcome is Outcome.TIMEOUT
    assert "5000" in result.reason and "line" in result.reason
    assert result.sim_duration_s == pytest.approx(0.02, abs=1e-4)
    assert [c.outcome for c in result.checks] == [Outcome.SKIPPED]


def test_ctrl_c_aborts_with_a_safe_plant_and_a_readable_log(tmp_path):
    from hil.logs.reader import read_log

    calls = []

    def interrupt(done_s, total_s):
        calls.append(done_s)
        if len(calls) == 3:
            raise KeyboardInterrupt

    result, _ = _run("""
name: interrupted
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1500}
  - run: {duration_s: 0.5}
""", out_dir=tmp_path, progress=interrupt)
    assert result.outcome is Outcome.ABORTED
    assert result.sim_duration_s < 0.1
    log = read_log(tmp_path / "interrupted" / "log.mcap")
    assert log.complete
    assert "session_end" in list(log["/plan/events"]["kind"])
