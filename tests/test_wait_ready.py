"""The `wait_ready` plan step and the board's start-up state (SPEC.md 2 item 5, 6.8, 9.4).

On the paper-hardware profile the stub calibrates at its first enable: its current zero
(CURRENT_ZERO_CAL_PERIODS), then the stator resistance (RS_ID_PERIODS per level, two levels,
then the bridge open for SPEC 8 row 67's 1 ms), reporting STARTING meanwhile and RUNNING from
the first period that controls. The expected ready period is computed from the parameters the
bench pushes (the stub's board file on that profile) and the period, not measured. Everything
runs in lockstep on the in-process stub: simulated time, nothing depends on the machine's load.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil.plans.format import parse_plan
from hil.plans.outcome import Outcome
from hil.run.runner import board_for, profile_for, profile_ref, run_plan
from hil.session.board_params import board_parameters
from hil.session.board_state import BoardState
from protocol.messages import ControllerState

STARTING, RUNNING, IDLE, FAULT = (int(ControllerState.STARTING), int(ControllerState.RUNNING),
                                  int(ControllerState.IDLE), int(ControllerState.FAULT))
RS_ID_OFF_S = 1e-3      # SPEC 8 row 67: the bridge is opened for 1 ms after the two levels


def _plan(text: str):
    return parse_plan(text, "inline.yaml")


def _start_up_periods(plan) -> int:
    """Periods from the enable to the first controlling period, from what the bench pushes."""
    profile = profile_for(plan)
    t = profile.control_period_s
    ref = profile_ref(plan)
    told = {s.name: s.value for s in board_parameters(profile, board_for(plan, "stub"), ref.label)}
    zero_cal = int(told["current_zero_cal_periods"])
    rs_id = int(told["rs_id_periods"])
    assert zero_cal > 0 and rs_id > 0        # the profile this test is about calibrates
    return zero_cal + 2 * rs_id + math.ceil(round(RS_ID_OFF_S / t, 9))


HARDWARE_READY = """
name: ready-on-hardware
profile: paper-hardware
steps:
  - run: {duration_s: 0.002}
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 500}
  - wait_ready: {timeout_s: 0.5}
  - run: {duration_s: 0.005}
  - check: {name: ready from its mark, kind: bound, signal: board.ready, window: {from: ready},
            limits: {low: 1, high: 1, unit: "1"}}
"""


def test_stub_starts_then_is_ready_at_the_end_of_its_calibrations(tmp_path):
    plan = _plan(HARDWARE_READY)
    t = profile_for(plan).control_period_s
    enabled_at = round(0.002 / t)
    ready_at = enabled_at + _start_up_periods(plan)
    result, signals = run_plan(plan, out_dir=tmp_path)
    assert result.outcome is Outcome.PASS, result.reason
    # the mark sits on the period the board's STATUS(RUNNING) names
    assert result.marks["ready"] == pytest.approx(ready_at * t, abs=1e-12)
    states = [(c["name"], c["period"], c["ready"]) for c in result.extra["board_states"]]
    assert states == [("STARTING", enabled_at, False), ("RUNNING", ready_at, True)]
    # the STATUS step signal and the TELEMETRY state agree, period by period
    k = np.rint(signals["board.state"].t_s / t).astype(int)
    expected = np.where(k < enabled_at, IDLE, np.where(k < ready_at, STARTING, RUNNING))
    assert np.array_equal(signals["board.state"].values, expected)
    assert np.array_equal(signals["board.ready"].values, (k >= ready_at).astype(float))
    tk = np.rint(signals["ctrl.state"].t_s / t).astype(int)
    telemetry_expected = np.where(tk < enabled_at, IDLE, np.where(tk < ready_at, STARTING, RUNNING))
    assert np.array_equal(signals["ctrl.state"].values, telemetry_expected)
    # result.json and the report carry the mark and the state changes
    record = json.loads((tmp_path / "ready-on-hardware" / "result.json").read_text())
    assert record["marks"]["ready"] == pytest.approx(ready_at * t, abs=1e-12)
    assert [c["name"] for c in record["extra"]["board_states"]] == ["STARTING", "RUNNING"]
    html = (tmp_path / "ready-on-hardware" / "report.html").read_text()
    assert "Board states" in html and "RUNNING (ready)" in html


def test_board_without_start_up_is_ready_at_its_enable():
    """The ideal profile pushes no calibration: IDLE -> RUNNING, ready from the enable on."""
    plan = _plan("""
name: ready-at-once
steps:
  - run: {duration_s: 0.001}
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 500}
  - wait_ready: {timeout_s: 0.1, mark: controlling}
  - run: {duration_s: 0.002}
""")
    t = profile_for(plan).control_period_s
    result, _ = run_plan(plan)
    assert result.outcome is Outcome.PASS, result.reason
    assert result.marks["controlling"] == pytest.approx(round(0.001 / t) * t, abs=1e-12)
    assert [c["name"] for c in result.extra["board_states"]] == ["RUNNING"]


def test_timeout_names_the_state_the_board_is_in():
    plan = _plan("""
name: too-short
profile: paper-hardware
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 500}
  - wait_ready: {timeout_s: 0.05}
  - run: {duration_s: 1.0}
""")
    assert _start_up_periods(plan) * profile_for(plan).control_period_s > 0.05
    result, _ = run_plan(plan)
    assert result.outcome is Outcome.TIMEOUT
    assert "not ready within 0.05 s" in result.reason and "STARTING since t = 0 s" in result.reason
    assert "line 6" in result.reason
    assert result.sim_duration_s == pytest.approx(0.05, abs=1e-4)
    assert [s.outcome for s in result.steps] == [Outcome.PASS, Outcome.TIMEOUT, Outcome.SKIPPED]


@pytest.mark.parametrize("steps, state", [
    ("  - wait_ready: {timeout_s: 0.01}\n", "no STATUS received"),
    ("  - command: {enable: true, speed_source: encoder}\n  - run: {duration_s: 0.001}\n"
     "  - command: {enable: false}\n  - wait_ready: {timeout_s: 0.01}\n", "IDLE since"),
])
def test_timeout_of_a_board_not_enabled(steps, state):
    result, _ = run_plan(_plan("name: idle\nsteps:\n" + steps))
    assert result.outcome is Outcome.TIMEOUT
    assert state in result.reason


def test_fault_while_starting_ends_the_wait_at_once():
    """An overcurrent trip level below the identification's 2 A: the stub trips while STARTING."""
    plan = _plan("""
name: trips-while-starting
profile: paper-hardware
steps:
  - param_set: {overcurrent_a: 1.0}
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 500}
  - wait_ready: {timeout_s: 1.0}
  - run: {duration_s: 0.1}
""")
    t = profile_for(plan).control_period_s
    result, _ = run_plan(plan)
    assert result.outcome is Outcome.FAIL       # a trip is a verdict on the board
    assert "FAULT 1 OVERCURRENT" in result.reason and "wait_ready, line 7" in result.reason
    fault_period = result.extra["board_faults"][0]["period"]
    # the FAULT follows the answer of the tripping period and is read with the next one
    assert result.sim_duration_s <= (fault_period + 2) * t + 1e-12
    assert [c["name"] for c in result.extra["board_states"]] == ["STARTING", "FAULT"]
    assert [s.outcome for s in result.steps][-2:] == [Outcome.FAIL, Outcome.SKIPPED]


def test_live_step_signals_feed_wait_until():
    """board.ready is a live signal: wait_until on it ends where wait_ready would."""
    plan = _plan(HARDWARE_READY.replace(
        "wait_ready: {timeout_s: 0.5}",
        "wait_until: {signal: board.ready, comparison: at_least, value: 1, timeout_s: 0.5}\n"
        "  - mark: ready").replace("name: ready-on-hardware", "name: ready-by-signal"))
    t = profile_for(plan).control_period_s
    result, _ = run_plan(plan)
    assert result.outcome is Outcome.PASS, result.reason
    ready_at = round(0.002 / t) + _start_up_periods(plan)
    # read with the period after the ready one (the STATUS follows that period's answer)
    assert result.marks["ready"] == pytest.approx((ready_at + 2) * t, abs=1e-12)


class _Rows:
    def __init__(self):
        self.rows: dict[str, list] = {}

    def step_value(self, name, k, value):
        self.rows.setdefault(name, []).append((k, value))


def test_status_period_from_the_board_is_checked():
    """A STATUS period the bench cannot have reached, or one before the last change, is not
    believed: the change is put at the period it arrived in, and said so."""
    rec = _Rows()
    board = BoardState(50e-6, rec)
    board.on_status(STARTING, 0, period=100, arrival_period=100)
    board.on_status(RUNNING, 0, period=10**9, arrival_period=250)     # from the future
    assert board.ready_period == 250
    assert board.changes[-1]["period_from_board"] is False and board.changes[-1]["board_period"] == 10**9
    board.on_status(IDLE, 0, period=5, arrival_period=300)            # before the last change
    assert board.since_period == 300 and not board.ready
    periods = [k for k, _ in rec.rows["board.state"]]
    assert periods == sorted(periods)                                 # the step signal holds
    board.on_status(RUNNING, 0, period=301, arrival_period=301)
    assert board.ready_period == 301
    board.enable_changed(400)                                         # enabled again
    assert not board.ready and "no state change reported" in board.describe()
    board.on_status(250, 0, period=401, arrival_period=401)           # a value SPEC 9.4 lacks
    assert not board.ready and "state 250 (unknown" in board.describe()
    board.on_status(FAULT, 1, period=402, arrival_period=402)
    assert board.faulted and "fault code 1 OVERCURRENT" in board.describe()


# ------------------------------------------------------------------ plan validation
READY_PLAN = """\
name: demo
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1500}
  - wait_ready: {timeout_s: 2}
  - run: {duration_s: 0.1}
  - check:
      name: speed after ready
      kind: final_value
      signal: plant.speed_rpm
      window: {from: ready, duration_s: 0.05}
      limits: {low: 0, unit: rpm}
"""


def _format_error(text: str):
    from configfile.source import ConfigError

    with pytest.raises(ConfigError) as info:
        parse_plan(text, "plan.yaml")
    assert info.value.source == "plan.yaml"
    return info.value


def test_wait_ready_step_loads_with_its_line_and_mark():
    from hil.plans.format import WaitReadyStep

    plan = parse_plan(READY_PLAN, "plan.yaml")
    step = plan.steps[1]
    assert isinstance(step, WaitReadyStep)
    assert (step.line, step.timeout_s, step.mark) == (4, 2.0, "ready")
    assert "ready" in plan.marks
    assert plan.max_sim_duration_s() == pytest.approx(2.1)
    named = parse_plan(READY_PLAN.replace("{timeout_s: 2}", "{timeout_s: 2, mark: calibrated}")
                       .replace("from: ready", "from: calibrated"), "plan.yaml")
    assert named.steps[1].mark == "calibrated"


@pytest.mark.parametrize("change, line, key, message", [
    ("{}", 4, "steps[1].wait_ready", "missing required key 'timeout_s'"),
    ("{timeout: 2}", 4, "steps[1].wait_ready.timeout",
     "unknown key 'timeout'; did you mean 'timeout_s'?"),
    ("{timeout_s: 0}", 4, "steps[1].wait_ready.timeout_s", "must be greater than 0"),
    ("{timeout_s: 2, mark: start}", 4, "steps[1].wait_ready.mark", "'start' is a reserved mark name"),
    ("{timeout_s: 2, mark: [a]}", 4, "steps[1].wait_ready.mark", "expected a string"),
])
def test_wait_ready_errors_name_line_and_key(change, line, key, message):
    err = _format_error(READY_PLAN.replace("{timeout_s: 2}", change))
    assert (err.line, err.key) == (line, key)
    assert message in err.message


def test_a_second_wait_ready_needs_its_own_mark():
    text = READY_PLAN.replace("  - run: {duration_s: 0.1}\n",
                              "  - run: {duration_s: 0.1}\n  - wait_ready: {timeout_s: 1}\n")
    err = _format_error(text)
    assert (err.line, err.key) == (6, "steps[3].wait_ready")
    assert "mark 'ready' is already set at line 4" in err.message and "its own 'mark: NAME'" in err.message
    parse_plan(text.replace("{timeout_s: 1}", "{timeout_s: 1, mark: ready_again}"), "plan.yaml")


def test_ready_mark_is_not_set_before_the_wait():
    text = READY_PLAN.replace("  - wait_ready: {timeout_s: 2}\n", "") + "  - wait_ready: {timeout_s: 2}\n"
    err = _format_error(text)
    assert err.key == "steps[2].check.window.from" and "mark 'ready' is not set before this step" in err.message
