"""Limits as formulas in plans (hil.plans.plan_formulas): checked before anything runs,
evaluated for each run's profile and board, shown with their inputs; and the rule that every
acceptance limit of test_plans/ is a formula or a regression bound with a note."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from configfile.source import ConfigError
from hil.cli.main import main as hil_main
from hil.plans.format import load_plan
from hil.plans.outcome import Outcome
from hil.run.runner import run_plan

REPO = Path(__file__).resolve().parents[1]
PLANS = REPO / "test_plans"
PLAN01 = PLANS / "01_speed_step_sensored.yaml"

SMALL = """\
name: formula-demo
constants:
  speed_target: {value: "motor.rated_speed_rpm", unit: rpm}
  ramp_time: {value: "motor.inertia_kgm2 * speed_target / board.torque_limit_nm", unit: ms}
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: speed_target}
  - mark: step
  - run: {duration_s: 0.02}
  - check:
      name: speed
      kind: final_value
      signal: plant.speed_rpm
      limits: {low: 0, high: "HIGH", unit: rpm}
"""


def _plan(tmp_path: Path, high: str, extra: str = "") -> Path:
    path = tmp_path / "plan.yaml"
    path.write_text(extra + SMALL.replace("HIGH", high))
    return path


def test_a_formula_limit_is_evaluated_with_its_inputs(tmp_path):
    plan = load_plan(_plan(tmp_path, "2 * speed_target"))
    [check] = plan.checks
    assert check.limits.high == pytest.approx(6000.0)
    d = check.derivations["high"]
    assert d.formula == "2 * speed_target" and d.unit == "rpm"
    inputs = {i.name: (i.value, i.unit) for i in d.inputs}
    assert inputs == {"speed_target": (3000.0, "rpm"), "motor.rated_speed_rpm": (3000.0, "rpm")}
    # the stimulus from a formula too
    assert plan.steps[0].speed_ref_rpm == pytest.approx(3000.0)
    assert plan.constants["ramp_time"].value == pytest.approx(8e-4 * 3000 * 2 * 3.14159265 / 60 / 2 * 1e3)


@pytest.mark.parametrize("high, message", [
    ("2 * speed_targte", "unknown name 'speed_targte'; did you mean 'speed_target'?"),
    ("2 * motor.inertia_kgm", "did you mean 'motor.inertia_kgm2'?"),
    ("ramp_time", "gives s, which is not rpm"),
    ("speed_target + ramp_time", "adds"),
    ("speed_target / load.torque_nm", "division by zero: 'load.torque_nm' is 0"),
    ("__import__('os').getcwd()", "is not allowed"),
    ("speed_target if 1 else 0", "is not allowed"),
])
def test_formula_errors_name_the_file_line_and_key(tmp_path, high, message):
    path = _plan(tmp_path, high.replace('"', "'"))
    with pytest.raises(ConfigError) as info:
        load_plan(path)
    err = info.value
    assert err.source == str(path)
    assert err.line == 13
    assert err.key == "steps[3].check.limits.high"
    assert message in err.message


def test_a_formula_that_fails_on_another_listed_profile_fails_the_plan(tmp_path):
    """Every profile a plan lists is evaluated when it loads: a zero that only one of them
    has is found by `hil plans`, before anything runs."""
    other = tmp_path / "no_damping.yaml"
    other.write_text("motor: {damping_nm_per_rad_s: 0.0}\n")
    path = _plan(tmp_path, "speed_target * motor.damping_nm_per_rad_s / motor.damping_nm_per_rad_s",
                 extra=f"profiles: [paper, {other}]\n")
    with pytest.raises(ConfigError, match="division by zero") as info:
        load_plan(path)
    assert info.value.line == 14     # one line more: the profiles line on top
    assert hil_main(["plans", str(path)]) == 2


def test_a_value_a_formula_gives_is_checked_on_every_listed_profile(tmp_path):
    """A formula that evaluates on each profile but gives a value the format refuses on one
    (a negative duration on a slow motor) fails the plan when it loads, naming the key."""
    slow = tmp_path / "slow.yaml"
    slow.write_text("motor: {rated_speed_rpm: 500.0}\n")
    path = tmp_path / "plan.yaml"
    path.write_text(f"profiles: [paper, {slow}]\n" + SMALL.replace("HIGH", "1").replace(
        "  - run: {duration_s: 0.02}",
        '  - run: {duration_s: "(speed_target - 1000 * ramp_time / ramp_time * rpm) / speed_target * second"}'
    ).replace("constants:\n", "constants:\n  rpm: {value: 1, unit: rpm}\n  second: {value: 1, unit: s}\n"))
    with pytest.raises(ConfigError) as info:
        load_plan(path)
    assert info.value.key == "steps[2].run.duration_s" and "greater than 0" in info.value.message


def test_a_bad_constant_names_its_key(tmp_path):
    path = tmp_path / "plan.yaml"
    path.write_text(SMALL.replace("HIGH", "1").replace(
        'value: "motor.rated_speed_rpm", unit: rpm', 'value: "motor.rated_speed_rpm", unit: ms'))
    with pytest.raises(ConfigError) as info:
        load_plan(path)
    assert info.value.key == "constants.speed_target.value" and info.value.line == 3


def test_a_profile_value_moves_the_limit(tmp_path):
    """The same plan with the profile's inertia doubled (overrides): ramp_time doubles."""
    base = load_plan(_plan(tmp_path, "10 * ramp_time / ramp_time * speed_target"))
    data = yaml.safe_load((tmp_path / "plan.yaml").read_text())
    data["overrides"] = {"motor": {"inertia_kgm2": 1.6e-3, "rated_speed_rpm": 1500.0}}
    (tmp_path / "plan.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    moved = load_plan(tmp_path / "plan.yaml")
    assert moved.constants["ramp_time"].value == pytest.approx(base.constants["ramp_time"].value)
    assert moved.checks[0].limits.high == pytest.approx(base.checks[0].limits.high / 2)


def test_the_report_shows_each_limits_formula_and_inputs(tmp_path):
    """result.json and the HTML report of plan 01: the rise time's bounds with their formulas,
    the value of each input and its unit, and the plan's constants."""
    plan = load_plan(PLAN01)
    result, _ = run_plan(plan, out_dir=tmp_path, profile="paper")
    assert result.outcome is Outcome.PASS, result.reason
    [record_path] = tmp_path.glob("**/result.json")
    record = json.loads(record_path.read_text())
    rise = next(c for c in record["checks"] if c["name"].startswith("rise time"))
    low = rise["limit_formulas"]["low"]
    assert low["value"] == pytest.approx(rise["limits"]["low"])
    inputs = {i["name"]: (i["value"], i["unit"]) for i in low["inputs"]}
    assert inputs["motor.inertia_kgm2"] == (8e-4, "kgm^2")
    assert inputs["board.torque_limit_nm"] == (2.0, "Nm")
    assert record["extra"]["constants"]["ramp_time"]["unit"] == "ms"
    html = (record_path.parent / "report.html").read_text()
    assert "0.8 * motor.inertia_kgm2 * (speed_target - speed_start) / torque_peak" in html
    assert "board.torque_band_nm = 0.0586 N m" not in html     # units as the formulas read them
    assert "board.torque_band_nm = 0.0586 Nm" in html
    assert "<h2>Constants</h2>" in html


# ------------------------------------------------------------------ plan 01 on other motors
INIT_MOTORS = {
    # tests/test_init.py's gimbal and multirotor motors
    "gimbal": ["--pole-pairs", "7", "--dc-link-v", "24", "--resistance-ohm", "2.5",
               "--inductance-h", "1.2e-3", "--back-emf-v-per-krpm", "6", "--inertia-kgm2", "1e-4",
               "--rated-speed-rpm", "1000", "--current-limit-a", "2.5"],
    "drone": ["--pole-pairs", "14", "--dc-link-v", "16", "--resistance-ohm", "0.1",
              "--inductance-h", "60e-6", "--back-emf-v-per-krpm", "4.16", "--inertia-kgm2", "4e-4",
              "--rated-speed-rpm", "2000", "--current-limit-a", "25"],
}


FOC01 = PLANS / "foc" / "01_speed_step.yaml"


@pytest.mark.parametrize("plan", [PLAN01, FOC01], ids=["01", "foc01"])
@pytest.mark.parametrize("motor", sorted(INIT_MOTORS))
def test_speed_step_plan_passes_on_a_hil_init_motor(tmp_path, motor, plan):
    """The paper's plan 01 file and its FOC counterpart, unchanged, on a `hil init` motor's
    profile and stub board file: their limits (the overshoot's e^-2 T_max / (Kp dw) among
    them) and stimuli are evaluated for that motor, and the stub passes them."""
    project = tmp_path / motor
    assert hil_main(["init", str(project), "--name", motor, *INIT_MOTORS[motor]]) == 0
    out = tmp_path / "out"
    code = hil_main(["run", str(plan), "--profile", str(project / "profile.yaml"),
                     "--board", str(project / "boards" / "stub.yaml"), "--out", str(out),
                     "--no-progress"])
    [path] = out.glob("**/result.json")
    record = json.loads(path.read_text())
    assert code == 0 and record["outcome"] == "PASS", [
        (c["name"], c["outcome"], c["measured"], c["limits"]) for c in record["checks"]]
    rated = yaml.safe_load((project / "profile.yaml").read_text())["motor"]["rated_speed_rpm"]
    final = next(c for c in record["checks"] if c["name"] == "final speed")
    assert final["limits"]["low"] == pytest.approx(rated - 0.005 * rated)
    rise = next(c for c in record["checks"] if c["name"].startswith("rise time"))
    assert rise["limits"]["high"] < 60.0       # the paper's is 69.8 ms: this motor's is its own


def test_a_sweep_run_sees_its_sampled_profile_in_its_limits(tmp_path):
    """hil sweep's worker on plan 01 with the inertia sampled: the row's rise-time limits are
    the formula's for that inertia (twice the paper's inertia: twice the limits)."""
    from hil.sweep.worker import run_one

    def row(inertia: float) -> dict:
        task = {"plan_path": str(PLAN01), "index": 0, "point": 0, "sample": 0, "seed": 1,
                "values": {"profile.motor.inertia_kgm2": inertia}, "fixed": {}, "out_dir": None,
                "link": "stub", "keep_failed": False, "keep_passing": False}
        return run_one(task)

    paper, heavy = row(8e-4), row(16e-4)
    def rise(r):
        return next(c for c in r["checks"] if c["name"].startswith("rise time"))["limits"]
    assert rise(heavy)["high"] == pytest.approx(2 * rise(paper)["high"])
    assert rise(heavy)["low"] == pytest.approx(2 * rise(paper)["low"])


# ------------------------------------------------------------------ every acceptance limit
# Acceptance limits of test_plans/ still written as numbers (plan file, check, profile of a
# `profile_limits` entry or None for `limits`). Empty: every acceptance limit is a formula of
# the profile, the board and the plan, or a regression bound whose note names the
# measurement. It stays empty: a new literal acceptance limit fails the test below. Limits
# that state an identity (low == high in "1": a state or fault code, a switch pattern) are
# definitions, not tolerances, and are not listed.
LITERAL_ACCEPTANCE_LIMITS: set[tuple[str, str, str | None]] = set()


def literal_acceptance_limits(paths, root: Path | None = None) -> set[tuple[str, str, str | None]]:
    """(plan file relative to root, default test_plans/; check; profile) of every acceptance
    bound (low/high) that is a number."""
    from hil.run.runner import expand_plan_paths

    found = set()
    for path in expand_plan_paths(paths):
        plan = load_plan(path)
        rel = str(Path(path).resolve().relative_to(root or PLANS))
        for check in plan.checks:
            entries = [(None, check.limits, check.role, check.derivations)]
            for label, limits in check.profile_limits.items():
                entries.append((label, limits, check.role_for(label)[0],
                                check.profile_derivations.get(label, {})))
            for label, limits, role, derived in entries:
                if role != "acceptance" or limits is None:
                    continue
                if limits.low is not None and limits.low == limits.high and limits.unit == "1":
                    continue
                bounds = [b for b in ("low", "high") if getattr(limits, b) is not None]
                if any(b not in derived for b in bounds):
                    found.add((rel, check.name, label))
    return found


def test_every_acceptance_limit_is_a_formula_or_a_known_literal():
    """Every acceptance check of test_plans/ has formulas for its bounds, or is a regression
    bound (whose note says what was measured), or is on the shrinking list above."""
    found = literal_acceptance_limits([PLANS])
    new = found - LITERAL_ACCEPTANCE_LIMITS
    assert not new, f"acceptance limits written as numbers, not formulas: {sorted(new)}"
    converted = LITERAL_ACCEPTANCE_LIMITS - found
    assert not converted, f"no longer literal: remove from LITERAL_ACCEPTANCE_LIMITS: {sorted(converted)}"


def test_regression_bounds_say_what_was_measured():
    """A regression bound (a check's role or a profile's) has a note that names a measurement."""
    from hil.run.runner import expand_plan_paths

    for path in expand_plan_paths([PLANS]):
        for check in load_plan(path).checks:
            for label in [None, *check.profile_limits]:
                role, note = check.role_for(label)
                if role == "regression":
                    assert "measured" in note.lower(), (path, check.name, label, note)


EXAMPLE_PLANS = sorted((REPO / "examples").glob("*/plans"))


@pytest.mark.parametrize("plans", EXAMPLE_PLANS, ids=lambda p: p.parent.name)
def test_example_boards_plans_follow_the_same_rule(plans):
    """The example boards' plans (issue 36: "limits by formula from the profile") hold to the
    rule of test_plans/: no literal acceptance bound, and every regression bound's note names
    its measurement."""
    from hil.run.runner import expand_plan_paths

    assert not literal_acceptance_limits([plans], root=plans)
    for path in expand_plan_paths([plans]):
        for check in load_plan(path).checks:
            for label in [None, *check.profile_limits]:
                role, note = check.role_for(label)
                if role == "regression":
                    assert "measured" in note.lower(), (path, check.name, label, note)


def test_the_walker_finds_a_literal_acceptance_limit(tmp_path):
    """The walk above can fail: plan 01 with its rise time's formulas replaced by numbers is
    reported, and the same check relabelled regression with a note is not."""
    text = PLAN01.read_text()
    start = text.index('limits: {low: "0.8 * motor.inertia_kgm2')
    end = text.index("unit: ms}", start) + len("unit: ms}")
    literal = text[:start] + "limits: {low: 48, high: 70, marginal: 3, unit: ms}" + text[end:]
    plans = tmp_path / "test_plans"
    plans.mkdir()
    (plans / "01.yaml").write_text(literal)
    global PLANS
    saved, PLANS = PLANS, plans
    try:
        assert ("01.yaml", "rise time 10-90 % (torque-limited)", None) in literal_acceptance_limits([plans])
        relabelled = literal.replace("      name: rise time 10-90 % (torque-limited)\n",
                                     "      name: rise time 10-90 % (torque-limited)\n"
                                     "      role: regression\n      note: measured 50.3 ms\n")
        (plans / "01.yaml").write_text(relabelled)
        assert ("01.yaml", "rise time 10-90 % (torque-limited)", None) not in literal_acceptance_limits([plans])
    finally:
        PLANS = saved


# ------------------------------------------------------------------ bench/hardware_limits.py
def test_hardware_limits_reads_the_profile_and_agrees_with_the_plans_formulas(tmp_path):
    """bench/hardware_limits.py models what it reads (issue 34 item 5): a hardware-like profile
    whose DC-link reading is 2 % high instead of 0.8 % moves its prediction of plan 02's true
    flux, and the plans' first-order formulas (their constants, bound to the same profile)
    stay within 0.3 mWb and 0.03 Nm of its fuller second model, on both profiles."""
    from bench import hardware_limits as hl

    profile = yaml.safe_load((REPO / "plant_rt" / "profiles" / "paper-hardware.yaml").read_text())
    profile["sensors"]["dc_voltage"]["gain"] = 1.02
    high_gain = tmp_path / "high-gain.yaml"
    high_gain.write_text(yaml.safe_dump(profile))
    try:
        hl.load(None)
        nominal = hl.formulas_against_model()
        hl.load(high_gain)
        moved = hl.formulas_against_model()
    finally:
        hl.load(None)
    for result in (nominal, moved):
        assert result["plan02_true_flux_mwb"]["formula"] == pytest.approx(
            result["plan02_true_flux_mwb"]["second_model"], abs=0.3)
        assert result["plan06_true_flux_mwb"]["formula"] == pytest.approx(
            result["plan06_true_flux_mwb"]["second_model"], abs=0.3)
        assert result["plan01_true_torque_at_the_limit_nm"]["formula"] == pytest.approx(
            result["plan01_true_torque_at_the_limit_nm"]["second_model"], abs=0.03)
    # e_v 1.66 % -> 2.86 %: the true flux under the board's 99 mWb falls by about 1.1 mWb
    for key in ("formula", "second_model"):
        drop = nominal["plan02_true_flux_mwb"][key] - moved["plan02_true_flux_mwb"][key]
        assert 0.8 < drop < 1.5, (key, drop)
