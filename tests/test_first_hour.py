"""A user's first hour: the cause of a failure said first, everything validated before the
first run, and the CLI's --version and `hil serve` summary.

Plans run in lockstep on the in-process stub (simulated time: nothing here depends on the
machine's load). The stub trips on a phase current above its `overcurrent_a`; a level of 1 A,
set by param_set, trips it within milliseconds of the enable at 1500 rpm.
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

from hil.cli.main import main
from hil.cli.serve import LOG_MEASURE_BYTES, LOG_WARN_BYTES_PER_S, LogRate
from hil.plans.format import ProfileRef, load_plan, parse_plan
from hil.plans.outcome import Outcome
from hil.run.runner import plan_dir_name, profile_for, run_plan

pytest_plugins = ["pytester"]

REPO = Path(__file__).resolve().parents[1]
PAPER_PROFILE = REPO / "plant_rt" / "profiles" / "paper.yaml"

TRIPPING = """
name: trips-on-overcurrent
steps:
  - param_set: {{overcurrent_a: 1.0, telemetry_divider: 1}}
  - command: {{enable: true, speed_source: encoder, speed_ref_rpm: 1500}}
  - {wait}
  - run: {{duration_s: 0.1}}
  - check: {{name: speed reached, kind: final_value, signal: plant.speed_rpm,
            limits: {{low: 1400, high: 1600, unit: rpm}}}}
"""
RUN_STEP = "run: {duration_s: 0.3}"
WAIT_STEP = ("wait_until: {signal: plant.speed_rpm, comparison: within, value: 1500, "
             "tolerance: 15, unit: rpm, timeout_s: 0.5}")


def _plan(text: str, name: str = "inline.yaml"):
    return parse_plan(text, name)


# --------------------------------------------------------------------------- 3. causes first
@pytest.mark.parametrize("wait, kind", [(RUN_STEP, "run"), (WAIT_STEP, "wait_until")])
def test_board_fault_ends_the_step_at_once_and_names_the_cause(tmp_path, wait, kind):
    """The user's case: a FAULT during a wait_until ended as TIMEOUT 0.5 s later; now the step
    ends at the FAULT and the plan FAILs naming it, in the result, result.json and report."""
    plan = _plan(TRIPPING.format(wait=wait))
    result, _ = run_plan(plan, out_dir=tmp_path)
    assert result.outcome is Outcome.FAIL, result.reason
    assert f"step 3 ({kind}, line 6)" in result.reason
    assert "board FAULT 1 OVERCURRENT" in result.reason
    faults = result.extra["board_faults"]
    assert faults and faults[0]["code"] == 1 and faults[0]["name"] == "OVERCURRENT"
    period = profile_for(plan).control_period_s
    # ended at the FAULT (read with the period after it), not at the step's end or timeout
    assert result.sim_duration_s <= (faults[0]["period"] + 2) * period + 1e-12
    steps = {s.index: s for s in result.steps}
    assert steps[2].outcome is Outcome.FAIL and "OVERCURRENT" in steps[2].message
    assert steps[3].outcome is Outcome.SKIPPED and steps[4].outcome is Outcome.SKIPPED
    assert result.checks[0].outcome is Outcome.SKIPPED

    out = tmp_path / "trips-on-overcurrent"
    record = json.loads((out / "result.json").read_text())
    assert record["outcome"] == "FAIL" and "OVERCURRENT" in record["reason"]
    assert record["extra"]["board_faults"][0]["name"] == "OVERCURRENT"
    html = (out / "report.html").read_text()
    head = html[:html.index("<h2>")]            # the cause comes before every section
    assert "Cause" in head and "OVERCURRENT" in head
    # the skipped check's signal is drawn as recorded up to the trip
    checks = html[html.index("Check windows"):]
    assert "data:image/svg+xml;base64," in checks[:checks.index("<h2>", 10)]


def test_pytest_plugin_fails_the_plan_item_of_a_tripped_plan(pytester, monkeypatch):
    """`pytest test_plans/`: the plan item says the board tripped (not only its skipped checks)."""
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")
    plans = pytester.mkdir("test_plans")
    (plans / "trip.yaml").write_text(TRIPPING.format(wait=RUN_STEP))
    result = pytester.runpytest("test_plans", "-p", "hil.run.pytest_plugin",
                                "-p", "no:cacheprovider")
    result.assert_outcomes(failed=2)                 # the plan item and its one check
    result.stdout.fnmatch_lines(["*plan 'trips-on-overcurrent' ended FAIL: step 3 (run, line 6): "
                                 "the board tripped*OVERCURRENT*"])


def test_expected_fault_lets_the_checks_judge_the_trip(tmp_path):
    """`expect_fault: true`: the same trip is the plan's subject, its checks judge it."""
    text = TRIPPING.format(wait=RUN_STEP).replace(
        "name: trips-on-overcurrent", "name: expects-overcurrent\nexpect_fault: true").replace(
        "name: speed reached, kind: final_value, signal: plant.speed_rpm,\n"
        "            limits: {low: 1400, high: 1600, unit: rpm}",
        "name: tripped on overcurrent, kind: final_value, signal: ctrl.fault_code,\n"
        "            limits: {low: 1, high: 1, unit: \"1\"}")
    plan = _plan(text)
    assert plan.expect_fault
    result, _ = run_plan(plan)
    assert result.outcome is Outcome.PASS, result.reason
    assert result.sim_duration_s == pytest.approx(0.4, abs=1e-6)    # ran to its end


def test_fault_after_an_injected_fault_is_the_plans_to_judge():
    """After a `fault` step the run goes on through the board's FAULT (faults/02's case)."""
    plan = _plan("""
name: encoder-loss
steps:
  - param_set: {telemetry_divider: 1, encoder_loss_timeout_s: 0.005}
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1500}
  - run: {duration_s: 0.15}
  - fault: {name: encoder_lost}
  - run: {duration_s: 0.03}
  - check: {name: ENCODER_LOSS, kind: final_value, signal: ctrl.fault_code,
            limits: {low: 2, high: 2, unit: "1"}}
""")
    result, _ = run_plan(plan)
    assert result.outcome is Outcome.PASS, result.reason
    assert [f["name"] for f in result.extra["board_faults"]] == ["ENCODER_LOSS"]


def test_console_names_the_plan_and_the_first_failing_check(tmp_path, capsys):
    """The FAIL line is followed by the first failing check's measured value and limits; the
    event lines on stderr name the plan and its profile."""
    plan = tmp_path / "fails.yaml"
    plan.write_text("""
name: fails-a-check
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1500}
  - fault: {name: encoder_noise, std_counts: 1, seed: 1}
  - run: {duration_s: 0.002}
  - check: {name: speed above 1000 rpm, kind: final_value, signal: plant.speed_rpm,
            limits: {low: 1000, unit: rpm}}
""")
    code = main(["run", str(plan), "--out", str(tmp_path / "out"), "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 1
    assert "FAIL     fails-a-check [paper]: 1 check(s) failed" in out
    line = next(line for line in out.splitlines() if "first failing check" in line)
    assert "'speed above 1000 rpm' (line 7) FAIL: measured " in line
    measured = float(line.split("measured ")[1].split(" rpm")[0])
    assert 0 < measured < 1000 and line.endswith(" rpm, limits >= 1000 rpm")
    assert "hil: fails-a-check [paper]: t = 0.000000 s: fault encoder_noise injected" in err


# --------------------------------------------------------------------------- 5. validate first
def _bad_profile(tmp_path: Path) -> Path:
    text = PAPER_PROFILE.read_text()
    assert "pole_pairs: 1" in text
    path = tmp_path / "profiles" / "bad.yaml"
    path.parent.mkdir()
    path.write_text(text.replace("pole_pairs: 1", "pole_pairs: seven"))
    return path


def test_a_bad_profile_value_is_named_before_any_run(tmp_path, capsys):
    bad = _bad_profile(tmp_path)
    plans = tmp_path / "plans"
    plans.mkdir()
    (plans / "a_good.yaml").write_text("name: good\nsteps:\n  - run: {duration_s: 0.001}\n")
    (plans / "b_bad.yaml").write_text("name: bad-profile\nprofile: ../profiles/bad.yaml\n"
                                      "steps:\n  - run: {duration_s: 0.001}\n")
    assert main(["plans", str(plans)]) == 2
    out = capsys.readouterr().out
    assert "INVALID" in out and "bad.yaml:" in out and "key 'motor.pole_pairs'" in out
    assert "b_bad.yaml" in out            # the plan that runs on it
    out_dir = tmp_path / "out"
    assert main(["run", str(plans), "--out", str(out_dir), "--no-progress"]) == 2
    out, err = capsys.readouterr()
    assert "pole_pairs" in err and "bad.yaml" in err
    assert not (out_dir / "good").exists()       # the good plan, first, did not run either


def test_an_unknown_link_is_one_error_with_a_did_you_mean(tmp_path, capsys):
    plans = tmp_path / "plans"
    plans.mkdir()
    for i in range(3):
        (plans / f"p{i}.yaml").write_text(f"name: p{i}\nsteps:\n  - run: {{duration_s: 0.001}}\n")
    code = main(["run", str(plans), "--link", "stubb", "--out", str(tmp_path / "out"),
                 "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 2
    assert err.count("unknown link 'stubb'") == 1 and "did you mean 'stub'?" in err
    assert "ERROR" not in out and not (tmp_path / "out" / "p0").exists()


@pytest.mark.parametrize("link, hint", [("seral:/dev/ttyUSB0", "serial:"), ("stub_pty", "stub-pty")])
def test_check_link_hints(link, hint):
    from hil.links.registry import LinkError, check_link

    with pytest.raises(LinkError, match=f"did you mean '{hint}'"):
        check_link(link)
    for good in ("stub", "stub-pty", "qemu", "serial:/dev/ttyUSB0", "can:socketcan:vcan0",
                 "/dev/ttyACM0", f"exec:{sys.executable}?args=-V"):
        check_link(good)


def test_check_link_names_a_missing_file_and_a_bad_option(tmp_path):
    from hil.links.registry import LinkError, check_link

    with pytest.raises(LinkError, match="file '.*nothing.so' does not exist"):
        check_link(f"lib:{tmp_path / 'nothing.so'}")
    with pytest.raises(LinkError, match="did you mean 'args'"):
        check_link(f"exec:{sys.executable}?arg=-V")


def test_output_folder_of_a_profile_path_is_its_stem(tmp_path):
    shutil.copy(PAPER_PROFILE, tmp_path / "x.yaml")
    plan_path = tmp_path / "plans" / "p.yaml"
    plan_path.parent.mkdir()
    plan_path.write_text("name: two-profiles\nprofiles: [paper, ../x.yaml]\n"
                         "steps:\n  - run: {duration_s: 0.001}\n")
    plan = load_plan(plan_path)
    assert [plan_dir_name(plan, ref) for ref in plan.profiles] == \
        ["two-profiles/paper", "two-profiles/x"]
    assert plan_dir_name(plan, ProfileRef("../profiles/.hidden.yaml", None)) == \
        "two-profiles/hidden"


# --------------------------------------------------------------------------- 8. CLI
def test_version(capsys):
    from hil import __version__

    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"hil {__version__}"


def test_serve_prints_its_summary_without_a_terminal(capsys):
    """capsys: stdout and stderr are not terminals. No --log: not a word about a log."""
    code = main(["serve", "--duration", "0.02", "--modbus", "off", "--enable",
                 "--speed-rpm", "600"])
    out, err = capsys.readouterr()
    assert code == 0
    summary = next(line for line in err.splitlines() if "periods" in line)
    assert "400 periods (0.020 s simulated)" in summary
    assert " rpm, torque " in summary and "board FAULTs: none" in summary
    assert "log" not in out + err


def test_serve_summary_names_the_log_it_wrote(tmp_path, capsys):
    log = tmp_path / "serve.mcap"
    assert main(["serve", "--duration", "0.01", "--modbus", "off", "--log", str(log)]) == 0
    err = capsys.readouterr().err
    assert f"hil serve: log {log} (" in err and log.stat().st_size > 0


def test_log_rate_warning(tmp_path):
    """Bytes a period from the file, times periods a wall second; once; fast pace only."""
    log = tmp_path / "log.mcap"
    log.write_bytes(bytes(LOG_MEASURE_BYTES * 4))            # 1 MiB
    periods = 4000                                            # 262 bytes a period
    rate = LogRate(log, 50e-6)
    assert rate.warning(periods, 1.0, "realtime") is None     # paced: 5 MB/s at most
    slow_wall = periods * (LOG_MEASURE_BYTES * 4 / periods) / (LOG_WARN_BYTES_PER_S * 0.9)
    assert rate.warning(periods, slow_wall, "fast") is None   # under the threshold
    text = rate.warning(periods, 0.05, "fast")               # 80000 periods/s: 21 MB/s
    assert text is not None and "writes 21 MB a second" in text and "262 bytes a period" in text
    assert "--pace realtime (5.2 MB a second)" in text and "--log-compression zstd" in text
    assert rate.warning(periods, 0.05, "fast") is None        # said once
    small = tmp_path / "small.mcap"
    small.write_bytes(bytes(LOG_MEASURE_BYTES - 1))
    assert LogRate(small, 50e-6).warning(10, 1e-6, "fast") is None   # too little to measure


def test_serve_stopped_by_ctrl_c_says_nothing_of_a_log_it_did_not_write(monkeypatch, capsys):
    """Ctrl-C (here: the second chunk interrupted) still prints the summary; no 'log closed'
    without --log."""
    from hil.session.bench_session import BenchSession

    run_periods = BenchSession.run_periods
    calls = []

    def interrupted(self, count, stop=None):
        calls.append(count)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return run_periods(self, count, stop)

    monkeypatch.setattr(BenchSession, "run_periods", interrupted)
    assert main(["serve", "--modbus", "off"]) == 0
    err = capsys.readouterr().err
    assert "stopping (Ctrl-C): plant safe-stated" in err and "log" not in err
    assert f"{calls[0]} periods (" in err and "board FAULTs: none" in err


class _FakeSession:
    """What TripWatch reads of a session: its FAULTs, shoot-throughs, events and injector."""

    def __init__(self):
        self.faults, self.shoot_throughs, self.events = [], 0, []
        self.period_s, self.fault_injector = 50e-6, None


def test_a_shoot_through_is_a_trip_named_by_its_gates():
    from hil.run.runner import BoardTripped, TripWatch

    session = _FakeSession()
    watch = TripWatch(session)
    assert not watch()
    session.shoot_throughs = 1
    session.events.append((0.001, "shoot_through", {"period": 20, "gates": 0x03, "legs": ["A"]}))
    assert watch()
    with pytest.raises(BoardTripped, match=r"step 2 \(run, line 5\): the board tripped: period 20 "
                                           r"\(t = 0\.001 s\): shoot-through, GATES 0x03 turns on "
                                           r"both switches of leg A"):
        watch.check("step 2 (run, line 5)")
    # an injected fault (any source) makes a trip the plan's to judge
    session.fault_injector = type("Injector", (), {"history": [{"action": "inject"}]})()
    assert not watch()
    expecting = _FakeSession()                  # expect_fault: true
    watch = TripWatch(expecting, expected=True)
    expecting.faults.append(object())
    assert not watch()


def test_a_trip_is_the_plans_reason_before_its_checks():
    from hil.plans.outcome import CheckResult, plan_outcome

    bad = CheckResult("b", "bound", Outcome.FAIL, 9.0, "A", None, "")
    err = CheckResult("c", "bound", Outcome.ERROR, None, "A", None, "no data")
    trip = "step 3 (run, line 6): the board tripped: board FAULT 1 OVERCURRENT"
    assert plan_outcome([], [bad, err], tripped=trip) == (Outcome.FAIL, trip)
    assert plan_outcome([], [bad], tripped=trip, error="link failed")[0] is Outcome.ERROR
