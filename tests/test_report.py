"""Reports (JUnit, HTML, JSON), outcomes, and the pytest plugin.

Plans are run here against a model of the stub's speed loop (no board): the
speed PI of firmware_stub/core/speed_pi.c with its defaults (double pole at
2 pi 5 Hz, conditional integration, 2.0 Nm limit), a 64-period encoder
window, torque = reference, J and B of Table 1. It is enough to exercise the
plan steps the paper's speed-step plan uses and to produce real step
responses for the checks and plots; the lead's end-to-end test runs the
plans against the stub itself.
"""
from __future__ import annotations

import base64
import json
import math
import re
import sys
import types
import xml.etree.ElementTree as ET
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest
import xmlschema

from hil.plans.checks import evaluate_check
from hil.plans.outcome import CheckResult, Outcome, PlanResult, StepResult, plan_outcome
from hil.run.runner import skipped_remainder
from hil.plans.format import (CheckStep, CommandStep, DcLinkStep, LoadStep, MarkStep, ParamSetStep, Plan, RunStep,
                      WaitReadyStep, WaitUntilStep, load_plan, parse_plan)
from hil.reports.html import junit_xml, slug, write_reports, write_summary
from hil.reports.svg import polyline_points
from hil.plans.signals import Signal, SignalSet

pytest_plugins = ["pytester"]

REPO = Path(__file__).resolve().parents[1]
XSD = REPO / "tests" / "data" / "junit-10.xsd"
PERIOD_S = 50e-6
RAD_S_PER_RPM = math.pi / 30.0


class SpeedLoopModel:
    """The stub's speed loop on an ideal torque actuator (see the module docstring)."""

    J, B, T_MAX, WINDOW = 8.0e-4, 1.0e-4, 2.0, 64

    def __init__(self):
        wb = 2 * math.pi * 5.0
        self.kp, self.ki = 2 * self.J * wb, self.J * wb * wb
        self.w = 0.0
        self.integral = 0.0
        self.hist = [0.0] * self.WINDOW
        self.ref_rpm = 0.0
        self.enabled = False
        self.load_nm = 0.0
        self.k = 0
        self.rows: list[tuple] = []

    def step(self) -> tuple:
        meas = sum(self.hist) / self.WINDOW
        torque = 0.0
        if self.enabled:
            e = self.ref_rpm * RAD_S_PER_RPM - meas
            p = self.kp * e
            cand = self.integral + self.ki * PERIOD_S * e
            unsat = p + cand
            if not ((unsat > self.T_MAX and e > 0) or (unsat < -self.T_MAX and e < 0)):
                self.integral = max(-self.T_MAX, min(self.T_MAX, cand))
            torque = max(-self.T_MAX, min(self.T_MAX, p + self.integral))
        row = (self.k * PERIOD_S, self.w, torque, meas, self.ref_rpm, self.load_nm)
        self.rows.append(row)
        self.w += PERIOD_S * (torque - self.B * self.w - self.load_nm) / self.J
        self.hist.pop(0)
        self.hist.append(self.w)
        self.k += 1
        return row

    def signals(self) -> SignalSet:
        a = np.asarray(self.rows)
        t = a[:, 0]
        return SignalSet([
            Signal("plant.speed_rad_s", t, a[:, 1], "rad/s"),
            Signal("plant.speed_rpm", t, a[:, 1] / RAD_S_PER_RPM, "rpm"),
            Signal("plant.torque_nm", t, a[:, 2], "Nm"),
            Signal("plant.load_torque_nm", t, a[:, 5], "Nm"),
            Signal("ctrl.torque_ref_nm", t, a[:, 2], "Nm"),
            Signal("ctrl.torque_est_nm", t, a[:, 2], "Nm"),
            Signal("ctrl.speed_feedback_rad_s", t, a[:, 3], "rad/s"),
            Signal("cmd.speed_ref_rpm", t, a[:, 4], "rpm"),
        ])


def model_run(plan: Plan, link: str | None = None, mode: str | None = None,
              out_dir: Path | None = None) -> tuple[PlanResult, SignalSet]:
    """Runs a plan's command / load / run / wait_until / wait_ready / mark / check steps on the model."""
    m = SpeedLoopModel()
    marks: dict[str, float] = {"start": 0.0}
    steps: list[StepResult] = []
    checks: dict[str, CheckResult] = {}
    timeout = None
    for step in plan.steps:
        start = m.k * PERIOD_S
        outcome, message = Outcome.PASS, ""
        if isinstance(step, CommandStep):
            ch = step.changes()
            m.enabled = ch.get("enable", m.enabled)
            m.ref_rpm = ch.get("speed_ref_rpm", m.ref_rpm)
        elif isinstance(step, LoadStep):
            m.load_nm = step.torque_at(1.0, 0.0, m.load_nm)
        elif isinstance(step, RunStep):
            for _ in range(int(round(step.duration_s / PERIOD_S))):
                m.step()
        elif isinstance(step, WaitUntilStep):
            pred = step.predicate("rpm")
            held, met = 0, False
            for _ in range(int(round(step.timeout_s / PERIOD_S))):
                m.step()
                held = held + 1 if pred(m.w / RAD_S_PER_RPM) else 0
                if held * PERIOD_S >= step.hold_s and held:
                    met = True
                    break
            if not met:
                outcome, message = Outcome.TIMEOUT, f"not met within {step.timeout_s:g} s: {step.describe()}"
        elif isinstance(step, MarkStep):
            marks[step.name] = m.k * PERIOD_S
        elif isinstance(step, WaitReadyStep):
            marks[step.mark] = m.k * PERIOD_S   # the model has no start-up: ready at once
        elif isinstance(step, CheckStep):
            r = evaluate_check(step, m.signals(), marks, now_s=(m.k - 1) * PERIOD_S, results=checks)
            checks[r.name] = r
            outcome = Outcome.FAIL if r.outcome is Outcome.FAIL else (
                Outcome.ERROR if r.outcome is Outcome.ERROR else Outcome.PASS)
        elif not isinstance(step, (ParamSetStep, DcLinkStep)):   # the model has no voltage
            raise NotImplementedError(step.kind)
        steps.append(StepResult(step.index, step.kind, outcome, step.line, start, m.k * PERIOD_S, message))
        if outcome is Outcome.TIMEOUT:
            timeout = message
            break
    done_checks = list(checks.values())
    if timeout is not None:
        more_steps, more_checks = skipped_remainder(plan, steps, done_checks, "the plan ended TIMEOUT")
        steps += more_steps
        done_checks += more_checks
    outcome, reason = plan_outcome(steps, done_checks)
    now = datetime.now(timezone.utc).isoformat(timespec="seconds")
    result = PlanResult(plan.name, str(plan.source_path), outcome, reason, tuple(steps),
                        tuple(done_checks), now, now, m.k * PERIOD_S, 0.25, link or "model",
                        mode or "lockstep", None, plan.description, marks)
    return result, m.signals()


PAPER_STEP_PLAN = REPO / "test_plans" / "01_speed_step_sensored.yaml"


def step_plan_text() -> str:
    """Plan 01 on the paper profile alone: the plugin tests count one item per check (a plan
    on two profiles has two of each, named [profile]; test_plugin_runs_each_listed_profile...)."""
    text = re.sub(r"^profiles: .*\n", "", PAPER_STEP_PLAN.read_text(), flags=re.M)
    return re.sub(r"^      profile_limits:\n(        .*\n)+", "", text, flags=re.M)


@pytest.fixture(scope="module")
def paper_step_run():
    plan = load_plan(PAPER_STEP_PLAN)
    return plan, *model_run(plan)


def test_paper_speed_step_limits_hold_on_the_loop_model(paper_step_run):
    """The plan's derived limits accept the ideal-torque response of the stub's speed loop."""
    plan, result, _ = paper_step_run
    assert result.outcome is Outcome.PASS, [c.message for c in result.checks]
    by = {c.name: c for c in result.checks}
    assert len(by) == len(plan.checks)
    assert by["rise time 10-90 % (torque-limited)"].measured == pytest.approx(53.3, abs=1.0)
    assert by["overshoot"].measured == pytest.approx(3.2, abs=0.3)
    assert by["settling within 2 %"].measured == pytest.approx(147, abs=5)


def test_paper_load_step_limits_hold_on_the_loop_model():
    """Plan 06's load-step limits accept the model's response (dip 70 rpm = dT / (e J w_b), back in 121 ms);
    its flux and DC-link checks need signals the model does not record: ERROR, named."""
    plan = load_plan(REPO / "test_plans" / "06_load_step_dc_sag.yaml")
    result, _ = model_run(plan)
    by = {c.name: c for c in result.checks}
    assert by["speed dip after the load step"].outcome is Outcome.PASS
    assert by["speed dip after the load step"].measured == pytest.approx(3000 - 70, abs=3)
    assert by["recovery within 0.5 %"].measured == pytest.approx(121, abs=5)
    assert by["torque carries the load"].outcome is Outcome.PASS
    assert by["speed held through the sag"].outcome is Outcome.PASS
    missing = by["flux held through the sag"]
    assert missing.outcome is Outcome.ERROR
    assert f"06_load_step_dc_sag.yaml:{missing.line}: check 'flux held through the sag': signal " \
           "'plant.flux_mag_wb' was not recorded" in missing.message
    assert result.outcome is Outcome.ERROR and "could not be computed" in result.reason


def test_impossible_limit_makes_the_plan_fail_with_the_measured_value(tmp_path):
    text = step_plan_text().replace(
        'limits: {high: settling_limit, marginal: "0.15 * settling_limit", unit: ms}',
        "limits: {high: 20, unit: ms}")
    plan = parse_plan(text, "impossible.yaml", tmp_path)
    result, signals = model_run(plan)
    assert result.outcome is Outcome.FAIL
    assert "'settling within 2 %'" in result.reason
    failed = [c for c in result.checks if c.outcome is Outcome.FAIL]
    assert [c.name for c in failed] == ["settling within 2 %"]
    assert failed[0].measured == pytest.approx(147, abs=5) and "<= 20 ms" in failed[0].message
    paths = write_reports(result, signals, tmp_path / "out", plan=plan)
    root = ET.parse(paths["junit"]).getroot()
    suite = root.find("testsuite")
    assert suite.get("failures") == "1" and suite.get("errors") == "0"
    failure = root.find(".//testcase[@name='settling within 2 %']/failure")
    assert failure is not None and "measured 14" in failure.get("message")
    record = json.loads(paths["json"].read_text())
    assert record["outcome"] == "FAIL" and record["counts"]["FAIL"] == 1
    assert PlanResult.from_json(record).checks[2].measured == pytest.approx(failed[0].measured)


def test_timeout_plan_reports_error_testcase_and_skipped_checks(tmp_path):
    text = step_plan_text().replace('timeout_s: "8 * ramp_time"', "timeout_s: 0.05")
    plan = parse_plan(text, "short.yaml", tmp_path)
    result, signals = model_run(plan)
    assert result.outcome is Outcome.TIMEOUT and "not met within 0.05 s" in result.reason
    assert all(c.outcome is Outcome.SKIPPED for c in result.checks)
    assert len(result.checks) == len(plan.checks)
    paths = write_reports(result, signals, tmp_path / "out", plan=plan)
    xmlschema.XMLSchema(XSD).validate(paths["junit"])
    root = ET.parse(paths["junit"]).getroot()
    error = root.find(".//testcase[@name='plan timeout']/error")
    assert error is not None and error.get("type") == "TIMEOUT"
    assert root.find("testsuite").get("skipped") == str(len(plan.checks))


def test_junit_validates_against_the_jenkins_schema(paper_step_run, tmp_path):
    plan, result, signals = paper_step_run
    marginal = CheckResult("close", "bound", Outcome.MARGINAL, 1.0, "A", None, "within (marginal)")
    errored = CheckResult("broken", "bound", Outcome.ERROR, None, "A", None,
                          "plan.yaml:3: check 'broken': signal 'x.y' was not recorded \x07")
    extra = PlanResult("odd <name> & more", "plan.yaml", Outcome.ERROR, "board died: watchdog",
                       checks=(marginal, errored), wall_duration_s=1234.5)
    text = junit_xml([result, extra])
    schema = xmlschema.XMLSchema(XSD)
    schema.validate(text)
    root = ET.fromstring(text)
    assert root.get("tests") == str(len(plan.checks) + 3)
    assert root.get("errors") == "2"                         # the check ERROR and the plan ERROR
    suites = root.findall("testsuite")
    assert [s.get("name") for s in suites] == [plan.name, "odd <name> & more"]
    assert len(suites[0].findall("testcase")) == len(plan.checks)
    with pytest.raises(xmlschema.XMLSchemaValidationError):  # the schema really does validate
        schema.validate(text.replace('<testsuite name="speed-step-sensored"', '<testsuite'))


def test_html_report_is_self_contained_with_plots(paper_step_run, tmp_path):
    plan, result, signals = paper_step_run
    paths = write_reports(result, signals, tmp_path / "out", plan=plan)
    html = paths["html"].read_text()
    assert "<link" not in html and "<script" not in html and "http://" not in html.split("</style>")[0]
    images = html.count('src="data:image/svg+xml;base64,')
    assert images == len(plan.checks) + len(plan.plots)
    first = html.split('src="data:image/svg+xml;base64,', 1)[1].split('"', 1)[0]
    svg = ET.fromstring(base64.b64decode(first))                # a well-formed SVG document
    assert svg.tag == "{http://www.w3.org/2000/svg}svg"
    assert len(polyline_points(base64.b64decode(first).decode())[0]) > 100
    for c in plan.checks:
        assert c.name in html
    assert "Speed (Fig. 4a / 6a)" in html and "1500 to 3000 rpm" in html
    # the settling limit is a formula (the ramp plus 4.3 / w_b): its value and its formula
    assert "&lt;= 199.668 ms (marginal within 29.9502 ms)" in html
    assert "<code class=\"formula\">settling_limit</code>" in html
    assert "speed_loop_bw = 31.4245 rad/s" in html


def test_report_reloads_plots_from_the_source_and_summary_links(paper_step_run, tmp_path):
    plan, result, signals = paper_step_run
    paths = write_reports(result, signals, tmp_path / slug(plan.name))   # plan=None: reloads the plots
    assert paths["html"].read_text().count("data:image/svg+xml") == len(plan.checks) + len(plan.plots)
    other = PlanResult("second", "x.yaml", Outcome.ABORTED, "interrupted (Ctrl-C)")
    summary = write_summary([(result, paths), (other, {})], tmp_path)
    index = summary["html"].read_text()
    assert f'href="{slug(plan.name)}/report.html"' in index
    assert "ABORTED" in index and "interrupted (Ctrl-C)" in index
    xmlschema.XMLSchema(XSD).validate(summary["junit"])
    assert json.loads(summary["json"].read_text())["outcome"] == "ABORTED"


def test_plan_outcome_precedence():
    ok = CheckResult("a", "bound", Outcome.PASS, 1.0, "A", None, "")
    bad = CheckResult("b", "bound", Outcome.FAIL, 9.0, "A", None, "")
    err = CheckResult("c", "bound", Outcome.ERROR, None, "A", None, "no data")
    timed = StepResult(3, "wait_until", Outcome.TIMEOUT, 12, message="not met")
    assert plan_outcome([], [ok])[0] is Outcome.PASS
    assert plan_outcome([], [ok, bad]) == (Outcome.FAIL, "1 check(s) failed: 'b'")
    assert plan_outcome([timed], [bad])[0] is Outcome.TIMEOUT
    assert plan_outcome([timed], [err])[0] is Outcome.ERROR
    assert plan_outcome([], [ok], error="watchdog at period 9") == (Outcome.ERROR, "watchdog at period 9")
    assert plan_outcome([], [err], aborted="Ctrl-C")[0] is Outcome.ABORTED


# ------------------------------------------------------------------ pytest plugin

PLUGIN_ARGS = ("-p", "hil.run.pytest_plugin", "-p", "no:cacheprovider")


@pytest.fixture
def fake_runner(monkeypatch):
    """hil.run.runner replaced by the model (the real runner is the lead's)."""
    calls: list[str] = []

    def run_plan(plan, link=None, mode=None, out_dir=None, profile=None):
        calls.append(plan.name)
        result, signals = model_run(plan, link, mode, out_dir)
        if out_dir is not None:        # the runner's contract: reports in out_dir/<plan>/
            write_reports(result, signals, Path(out_dir) / slug(plan.name), plan=plan)
        return result, signals

    module = types.ModuleType("hil.run.runner")
    module.run_plan = run_plan
    monkeypatch.setitem(sys.modules, "hil.run.runner", module)
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")
    return calls


def test_plugin_collects_one_item_per_check(pytester, fake_runner):
    plans = pytester.mkdir("test_plans")
    (plans / "step.yaml").write_text(step_plan_text())
    (plans / "profile.yaml").write_text("motor: {resistance_ohm: 0.466}\n")   # not a plan
    result = pytester.runpytest("--collect-only", "-q", "test_plans", *PLUGIN_ARGS)
    plan = load_plan(PAPER_STEP_PLAN)
    lines = [l for l in result.outlines if "::" in l]
    assert lines == ["test_plans/step.yaml::run"] + [f"test_plans/step.yaml::{c.name}" for c in plan.checks]
    assert fake_runner == []                                 # collecting runs nothing


def test_plugin_runs_the_plan_once_and_reports_each_check(pytester, fake_runner):
    plans = pytester.mkdir("test_plans")
    text = step_plan_text().replace("limits: {high: \"overshoot_model + 1.5 / 100\", marginal: 1, unit: \"%\"}",
                                               "limits: {high: 1, unit: \"%\"}")
    (plans / "step.yaml").write_text(text)
    out = pytester.path / "out"
    result = pytester.runpytest("test_plans", f"--hil-out={out}", "-rf", *PLUGIN_ARGS)
    n = len(load_plan(PAPER_STEP_PLAN).checks)
    result.assert_outcomes(passed=n, failed=1)
    result.stdout.fnmatch_lines(["*step.yaml:*: check 'overshoot' FAIL: measured 3.* %, outside limits <= 1 %*"])
    assert fake_runner == ["speed-step-sensored"]
    assert (out / "speed-step-sensored" / "report.html").is_file()
    assert (out / "speed-step-sensored" / "junit.xml").is_file()


def test_plugin_shows_an_invalid_plan_as_a_collection_error(pytester, fake_runner):
    plans = pytester.mkdir("test_plans")
    (plans / "bad.yaml").write_text("name: bad\nsteps:\n  - run: {duration_s: -1}\n")
    result = pytester.runpytest("test_plans", *PLUGIN_ARGS)
    result.assert_outcomes(errors=1)
    assert "bad.yaml:3: key 'steps[0].run.duration_s': must be greater than 0, got -1" in result.stdout.str()
    assert "invalid plan: " in result.stdout.str()


def test_plugin_plan_item_fails_on_timeout(pytester, fake_runner):
    plans = pytester.mkdir("test_plans")
    text = step_plan_text().replace('timeout_s: "8 * ramp_time"', "timeout_s: 0.05")
    (plans / "short.yaml").write_text(text)
    result = pytester.runpytest("test_plans", *PLUGIN_ARGS)
    n = len(load_plan(PAPER_STEP_PLAN).checks)
    result.assert_outcomes(failed=n + 1)
    result.stdout.fnmatch_lines(["*plan 'speed-step-sensored' ended TIMEOUT: step 3 (wait_until, line *)*"])


def test_bench_fixture_opens_and_closes_a_bench(pytester, monkeypatch):
    events: list = []

    class FakeBench:
        def __init__(self, **kwargs):
            events.append(("init", kwargs))

        def __enter__(self):
            events.append("enter")
            return self

        def __exit__(self, *exc):
            events.append("exit")

    module = types.ModuleType("hil.run.runner")
    module.Bench = FakeBench
    monkeypatch.setitem(sys.modules, "hil.run.runner", module)
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")
    from plant_rt.profile import default_profile_path

    pytester.makepyfile(test_accept=f"""
        import pytest

        @pytest.mark.hil_profile({str(default_profile_path())!r})
        def test_uses_bench(bench):
            assert type(bench).__name__ == "FakeBench"

        @pytest.mark.hil_profile("paper")
        def test_named_profile(bench):
            pass
    """)
    result = pytester.runpytest("--hil-link=stub-pty", *PLUGIN_ARGS)
    result.assert_outcomes(passed=2)
    (kind, kwargs), enter, leave, (_, named), _, _ = events
    assert (kind, enter, leave) == ("init", "enter", "exit")
    assert kwargs["link"] == "stub-pty" and "mode" not in kwargs
    assert type(kwargs["profile"]).__name__ == "BenchProfile"
    assert kwargs["log_path"].name == "bench.mcap" and kwargs["log_path"].parent.is_dir()
    assert "profile" not in named


def test_plugin_marginal_passes_with_a_warning(pytester, fake_runner):
    plans = pytester.mkdir("test_plans")
    text = step_plan_text().replace("limits: {high: \"overshoot_model + 1.5 / 100\", marginal: 1, unit: \"%\"}",
                                               "limits: {high: 3.5, marginal: 1, unit: \"%\"}")
    (plans / "step.yaml").write_text(text)
    # Run from the pytest console script, the outer process has already imported the plugin
    # (entry point), so the inner run adds a PytestAssertRewriteWarning about it: not ours.
    result = pytester.runpytest("test_plans", "-k", "overshoot", "-W",
                                "ignore::pytest.PytestAssertRewriteWarning", *PLUGIN_ARGS)
    result.assert_outcomes(passed=1, deselected=len(load_plan(PAPER_STEP_PLAN).checks), warnings=1)
    result.stdout.fnmatch_lines(["*HilMarginalWarning: overshoot: measured 3.* %, within (marginal)*"])


def test_plugin_reports_a_runner_failure_on_every_item(pytester, monkeypatch):
    calls = []

    def run_plan(plan, link=None, mode=None, out_dir=None, profile=None):
        calls.append(plan.name)
        raise RuntimeError("board on 'stub' exited with status -11 while waiting for HELLO")

    module = types.ModuleType("hil.run.runner")
    module.run_plan = run_plan
    monkeypatch.setitem(sys.modules, "hil.run.runner", module)
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")
    plans = pytester.mkdir("test_plans")
    (plans / "step.yaml").write_text(step_plan_text())
    result = pytester.runpytest("test_plans", *PLUGIN_ARGS)
    n_items = len(load_plan(PAPER_STEP_PLAN).checks) + 1
    result.assert_outcomes(failed=n_items)
    assert result.stdout.str().count("the plan could not run: RuntimeError: board on 'stub' exited") >= n_items
    assert calls == ["speed-step-sensored"]                  # run once, reported on every item


def test_plugin_runs_each_listed_profile_and_findings_pass(pytester, monkeypatch):
    """A plan listing two profiles gives one set of items per profile, each run on its own
    profile; a finding (INFO) is recorded, never failed."""
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")
    plans = pytester.mkdir("test_plans")
    (plans / "two.yaml").write_text(
        "name: two-profiles\n"
        "profiles: [paper, paper-hardware]\n"
        "steps:\n"
        "  - run: {duration_s: 0.002}\n"
        "  - check: {name: dc link, kind: final_value, signal: plant.v_dc,\n"
        "            limits: {low: 60, high: 80, unit: V}}\n"
        "  - check: {name: a claim that does not hold, kind: final_value, signal: plant.v_dc,\n"
        "            role: finding, limits: {low: 100, unit: V}}\n")
    result = pytester.runpytest("test_plans", *PLUGIN_ARGS, "-v")
    result.assert_outcomes(passed=6)
    result.stdout.fnmatch_lines(["*run?paper?*", "*run?paper-hardware?*",
                                 "*a claim that does not hold?paper-hardware?*PASSED*"])
