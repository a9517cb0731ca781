"""Plan loading and validation: every error names the file, the line and the key."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from hil.plans.checks import CHECK_KINDS
from hil.plans.format import (BOARD_PARAMS, FAULTS, PLANT_PARAMS, STEP_SCHEMAS, CheckStep, CommandStep,
                      FaultStep, LoadStep, MarkStep, RunStep, WaitUntilStep, load_plan,
                      looks_like_plan, parse_plan, plan_files)
from configfile.source import ConfigError

REPO = Path(__file__).resolve().parents[1]
PLANS = REPO / "test_plans"

GOOD = """\
name: demo
description: a demo plan
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1500}
  - wait_until: {signal: plant.speed_rpm, comparison: within, value: 1500, tolerance: 15,
                 unit: rpm, hold_s: 0.02, timeout_s: 0.5}
  - mark: step
  - command: {speed_ref_rpm: 3000}
  - run: {duration_s: 0.3}
  - check:
      name: settles
      kind: settling_time
      signal: plant.speed_rpm
      window: {from: step, duration_s: 0.3}
      target: {value: 3000, unit: rpm}
      limits: {high: 150, unit: ms}
"""


def _write(tmp_path: Path, text: str, name: str = "plan.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _error(tmp_path: Path, text: str) -> ConfigError:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_plan(path)
    assert info.value.source == str(path)
    return info.value


def test_good_plan_loads_into_frozen_steps_with_lines(tmp_path):
    plan = load_plan(_write(tmp_path, GOOD))
    assert plan.name == "demo" and plan.source_path == tmp_path / "plan.yaml"
    kinds = [type(s) for s in plan.steps]
    assert kinds == [CommandStep, WaitUntilStep, MarkStep, CommandStep, RunStep, CheckStep]
    assert [s.line for s in plan.steps] == [4, 5, 7, 8, 9, 10]
    assert plan.steps[0].changes() == {"enable": True, "speed_source": "encoder", "speed_ref_rpm": 1500.0}
    check = plan.checks[0]
    assert check.limits.unit == "ms" and check.limits.high == 150
    assert check.window.resolve({"step": 1.0}, now_s=9.0) == (1.0, 1.3)
    with pytest.raises(AttributeError):
        check.name = "other"                                   # frozen


def test_malformed_yaml(tmp_path):
    err = _error(tmp_path, "name: x\nsteps:\n  - run: {duration_s: 1\n")
    assert err.line == 4 and "not valid YAML" in err.message


def test_unknown_key_names_line_key_and_suggestion(tmp_path):
    err = _error(tmp_path, GOOD.replace("speed_ref_rpm: 3000", "speed_ref_rmp: 3000"))
    assert err.line == 8
    assert err.key == "steps[3].command.speed_ref_rmp"
    assert "unknown key 'speed_ref_rmp'; did you mean 'speed_ref_rpm'?" in err.message


def test_unknown_top_level_key(tmp_path):
    err = _error(tmp_path, "name: x\nstepz: []\nsteps:\n  - run: {duration_s: 1}\n")
    assert (err.line, err.key) == (2, "stepz")
    assert "unknown key 'stepz'; did you mean 'steps'?" in err.message
    err = _error(tmp_path, "name: x\nowner: me\nsteps:\n  - run: {duration_s: 1}\n")
    assert "unknown key 'owner'; expected one of: name, description, profile" in err.message


def test_wrong_type(tmp_path):
    err = _error(tmp_path, GOOD.replace("duration_s: 0.3}\n  - check", "duration_s: soon}\n  - check"))
    assert (err.line, err.key) == (9, "steps[4].run.duration_s")
    # a string where a number goes is a formula (hil.plans.formula): 'soon' names nothing
    assert err.message.startswith("expected a number, got a string ('soon')")
    assert "unknown name 'soon'" in err.message


def test_yaml_exponent_pitfall_gets_a_hint(tmp_path):
    err = _error(tmp_path, "name: x\nsteps:\n  - plant_param: {inertia_kgm2: 8e-4}\n")
    assert err.key == "steps[0].plant_param.inertia_kgm2"
    assert "write 8.0e-4" in err.message


def test_non_positive_duration(tmp_path):
    err = _error(tmp_path, "name: x\nsteps:\n  - run: {duration_s: 0}\n")
    assert err.key == "steps[0].run.duration_s" and "must be greater than 0" in err.message


def test_missing_signal(tmp_path):
    err = _error(tmp_path, GOOD.replace("signal: plant.speed_rpm\n      window",
                                        "signal: plant.speed_rmp\n      window"))
    assert (err.line, err.key) == (13, "steps[5].check.signal")
    assert "unknown signal 'plant.speed_rmp'; did you mean 'plant.speed_rpm'?" in err.message


def test_undefined_mark(tmp_path):
    err = _error(tmp_path, GOOD.replace("{from: step,", "{from: stpe,"))
    assert (err.line, err.key) == (14, "steps[5].check.window.from")
    assert "mark 'stpe' is not set before this step (marks so far: start, now, step)" in err.message


def test_mark_used_before_it_is_set(tmp_path):
    text = GOOD.replace("  - mark: step\n", "") + "  - mark: step\n"
    err = _error(tmp_path, text)
    assert err.key == "steps[4].check.window.from" and "not set before this step" in err.message


def test_bad_unit_and_incompatible_unit(tmp_path):
    err = _error(tmp_path, GOOD.replace("unit: ms}", "unit: fortnight}"))
    assert (err.line, err.key) == (16, "steps[5].check.limits.unit")
    assert "unknown unit 'fortnight'" in err.message
    err = _error(tmp_path, GOOD.replace("unit: ms}", "unit: rpm}"))
    assert "unit rpm does not fit what settling_time measures (in s; time)" in err.message
    err = _error(tmp_path, GOOD.replace("target: {value: 3000, unit: rpm}", "target: {value: 3, unit: A}"))
    assert err.key == "steps[5].check.target.unit" and "does not fit the signal" in err.message


def test_step_shape_errors(tmp_path):
    err = _error(tmp_path, "name: x\nsteps:\n  - sleep: {duration_s: 1}\n")
    assert err.key == "steps[0].sleep" and "unknown step kind 'sleep'" in err.message
    err = _error(tmp_path, "name: x\nsteps:\n  - run: {duration_s: 1}\n    mark: a\n")
    assert err.key == "steps[0]" and "exactly one key" in err.message
    err = _error(tmp_path, "name: x\nsteps: []\n")
    assert err.key == "steps" and "at least 1 item" in err.message
    err = _error(tmp_path, "steps:\n  - run: {duration_s: 1}\n")
    assert err.line == 1 and err.message == "missing required key 'name'"


def test_check_errors(tmp_path):
    base = "name: x\nsteps:\n  - run: {duration_s: 1}\n  - check: "
    err = _error(tmp_path, base + "{name: a, kind: median, signal: plant.i_a, limits: {high: 1, unit: A}}\n")
    assert err.key == "steps[1].check.kind" and "expected one of: final_value" in err.message
    err = _error(tmp_path, base + "{name: a, kind: bound, signal: plant.i_a}\n")
    assert err.message.startswith("'bound' needs 'limits'")
    err = _error(tmp_path, base + "{name: a, kind: bound, signal: plant.i_a, band_pct: 2, limits: {high: 1, unit: A}}\n")
    assert err.key == "steps[1].check.band_pct" and "unknown key 'band_pct'" in err.message
    err = _error(tmp_path, base + "{name: a, kind: rms_error, signal: plant.i_a, reference: plant.speed_rpm, "
                                  "limits: {high: 1, unit: A}}\n")
    assert err.key == "steps[1].check.reference" and "does not compare with the signal's A" in err.message
    err = _error(tmp_path, base + "{name: a, kind: bound, signal: plant.i_a, limits: {low: 2, high: 1, unit: A}}\n")
    assert err.key == "steps[1].check.limits" and "is above high" in err.message
    err = _error(tmp_path, base + "{name: a, kind: compare, a: b, b: c, limits: {high: 1, unit: '1'}}\n")
    assert err.key == "steps[1].check.a" and "check 'b' is not defined before this one" in err.message
    twice = base + "{name: a, kind: bound, signal: plant.i_a, limits: {high: 1, unit: A}}\n"
    err = _error(tmp_path, twice + twice.split("\n", 3)[3])
    assert err.key == "steps[2].check.name" and "already used at line 4" in err.message


def test_wait_until_rules(tmp_path):
    base = "name: x\nsteps:\n  - wait_until: "
    err = _error(tmp_path, base + "{signal: plant.speed_rpm, comparison: within, value: 1, timeout_s: 1}\n")
    assert "needs a tolerance" in err.message
    err = _error(tmp_path, base + "{signal: plant.speed_rpm, comparison: above, value: 1, unit: A, timeout_s: 1}\n")
    assert err.key == "steps[0].wait_until.unit" and "does not fit signal 'plant.speed_rpm'" in err.message
    err = _error(tmp_path, base + "{signal: plant.speed_rpm, comparison: '>', value: 1, timeout_s: 1}\n")
    assert "expected one of: above, below, at_least, at_most, within" in err.message


def test_wait_until_predicate_converts_units_once():
    plan = parse_plan("name: w\nsteps:\n  - wait_until: {signal: plant.speed_rad_s, comparison: within, "
                      "value: 3000, tolerance: 30, unit: rpm, timeout_s: 1}\n")
    wait = plan.steps[0]
    assert wait.unit == "rpm"
    pred = wait.predicate("rad/s")
    assert pred(3000 * 3.14159265 / 30) and not pred(3040 * 3.14159265 / 30)


def test_param_set_names_follow_the_protocol_header():
    header = (REPO / "protocol" / "c" / "hil_proto.h").read_text()
    block = re.search(r"typedef enum \{([^}]*)\} hil_param_id;", header).group(1)
    ids = re.findall(r"HIL_PARAM_([A-Z0-9_]+)\s*=\s*(\d+)", block)
    # SPEC 8: ids 1-59 are standard, 60 and up a board's own (the stub's are in its board file)
    standard = {name.lower() for name, pid in ids if int(pid) < 60}
    assert {"control_step_cycles", "sensor_set"} <= standard
    assert set(BOARD_PARAMS) == standard - {"control_step_cycles", "sensor_set"}  # the read-only ones


def test_param_set_errors(tmp_path):
    err = _error(tmp_path, "name: x\nsteps:\n  - param_set: {Speed-Kp: 0.1}\n")
    assert err.key == "steps[0].param_set.Speed-Kp" and "not a parameter name" in err.message
    err = _error(tmp_path, "name: x\nsteps:\n  - param_set: {control_step_cycles: 1}\n")
    assert "read-only" in err.message


def test_fault_step_shape_for_issue_7(tmp_path):
    plan = parse_plan("name: f\nsteps:\n  - fault: {name: link_drop, rate: 0.1, duration_s: 0.02, seed: 3}\n"
                      "  - fault: {name: encoder_lost, clear: true}\n")
    drop, lift = plan.steps
    assert isinstance(drop, FaultStep) and drop.args == {"rate": 0.1, "seed": 3} and drop.duration_s == 0.02
    assert lift.clear and lift.args == {}
    err = _error(tmp_path, "name: x\nsteps:\n  - fault: {name: open_phase, phase: d}\n")
    assert err.key == "steps[0].fault.phase" and "expected one of: a, b, c" in err.message
    err = _error(tmp_path, "name: x\nsteps:\n  - fault: {name: link_drop}\n")
    assert err.message == "missing required key 'rate'"
    err = _error(tmp_path, "name: x\nsteps:\n  - fault: {name: meteor}\n")
    assert "open_phase" in err.message


def test_load_profiles():
    plan = parse_plan("""name: l
steps:
  - load: {type: ramp, torque_nm: 1.0, duration_s: 0.1}
  - load: {type: table, points: [[0, 0], [0.1, 1.0], [0.2, 1.0]], repeat: true}
  - load: {type: speed_proportional, nm_per_rad_s: 0.001, offset_nm: 0.1}
  - load: {type: step, torque_nm: 0.5, delay_s: 0.01}
""")
    ramp, table, prop, step = plan.steps
    assert isinstance(ramp, LoadStep)
    assert ramp.torque_at(0.05, 0.0, previous_nm=0.2) == pytest.approx(0.6)
    assert table.torque_at(0.05, 0.0, 0.0) == pytest.approx(0.5)
    assert table.torque_at(0.25, 0.0, 0.0) == pytest.approx(0.5)          # repeats every 0.2 s
    assert prop.torque_at(1.0, 300.0, 0.0) == pytest.approx(0.4)
    assert step.torque_at(0.005, 0.0, 0.2) == 0.2 and step.torque_at(0.02, 0.0, 0.2) == 0.5
    with pytest.raises(ConfigError, match="missing required key 'duration_s'"):
        parse_plan("name: l\nsteps:\n  - load: {type: ramp, torque_nm: 1.0}\n")
    with pytest.raises(ConfigError, match="table times must not decrease"):
        parse_plan("name: l\nsteps:\n  - load: {type: table, points: [[0.1, 0], [0.0, 1]]}\n")


def test_profile_path_is_relative_to_the_plan(tmp_path):
    (tmp_path / "profiles").mkdir()
    (tmp_path / "profiles" / "hot.yaml").write_text("motor: {}\n")
    plan = load_plan(_write(tmp_path, "name: p\nprofile: profiles/hot.yaml\nsteps:\n  - run: {duration_s: 1}\n"))
    assert plan.profile_path == (tmp_path / "profiles" / "hot.yaml").resolve()
    assert load_plan(_write(tmp_path, "name: p\nprofile: paper\nsteps:\n  - run: {duration_s: 1}\n")).profile_path is None
    err = _error(tmp_path, "name: p\nprofile: profiles/cold.yaml\nsteps:\n  - run: {duration_s: 1}\n")
    assert err.key == "profile" and "profile file not found" in err.message
    err = _error(tmp_path, "name: p\nprofile: hot\nsteps:\n  - run: {duration_s: 1}\n")
    assert err.line == 2 and "unknown profile 'hot': expected one of paper, default" in err.message


def test_link_and_mode(tmp_path):
    plan = load_plan(_write(tmp_path, "name: p\nlink: serial:/dev/ttyUSB0?baud=2000000\nmode: realtime\n"
                                      "steps:\n  - run: {duration_s: 1}\n"))
    assert plan.link.startswith("serial:") and plan.mode == "realtime"
    err = _error(tmp_path, "name: p\nlink: usb\nsteps:\n  - run: {duration_s: 1}\n")
    assert err.key == "link" and "serial:PORT" in err.message


def test_plots_section(tmp_path):
    err = _error(tmp_path, GOOD + "plots:\n  - {title: locus, type: xy, x: plant.psi_alpha}\n")
    assert "an xy plot needs 'y'" in err.message
    err = _error(tmp_path, GOOD + "plots:\n  - {title: s, signals: [plant.speed_rpm, plant.i_a], unit: rpm}\n")
    assert "signal 'plant.i_a' is in A, not convertible to rpm" in err.message
    plan = load_plan(_write(tmp_path, GOOD + "plots:\n  - {title: s, signals: [plant.speed_rpm], "
                                             "window: {from: step}}\n"))
    assert plan.plots[0].window.from_mark == "step"


def test_paper_plans_validate_and_stay_short():
    files = sorted(PLANS.glob("*.yaml"))  # the paper's plans; faults/ and targets/ are their own
    assert len(files) == 6
    total_min = 0.0
    for f in files:
        plan = load_plan(f)
        assert plan.description and plan.checks and plan.plots
        total_min += plan.min_sim_duration_s()
    # The runs between waits; the waits add about 0.2 s per plan (the startup ramps).
    assert total_min + 6 * 0.25 < 4.0


def test_plan_files_skip_non_plans(tmp_path):
    _write(tmp_path, GOOD, "a.yaml")
    _write(tmp_path, "motor: {resistance_ohm: 0.466}\n", "profile.yaml")
    _write(tmp_path, "name: [unclosed\n", "broken.yml")
    assert not looks_like_plan(tmp_path / "profile.yaml")
    assert [p.name for p in plan_files([tmp_path])] == ["a.yaml", "broken.yml"]


def test_readme_documents_every_key():
    readme = (PLANS / "README.md").read_text(encoding="utf-8")
    names = set(STEP_SCHEMAS) | set(CHECK_KINDS) | set(FAULTS) | set(PLANT_PARAMS)
    for kind in CHECK_KINDS.values():
        names.update(r.key for r in kind.roles)
        names.update(kind.args)
    names.update(["name", "description", "profile", "overrides", "link", "mode", "timeout_s",
                  "steps", "plots", "window", "offset_s", "duration_s", "to_offset_s", "limits",
                  "low", "high", "marginal", "comparison", "unit", "hold_s", "tolerance",
                  "ramp_s", "voltage_v", "points", "repeat", "nm_per_rad_s", "offset_nm", "delay_s"])
    missing = sorted(n for n in names if f"`{n}`" not in readme)
    assert not missing, f"test_plans/README.md does not document: {missing}"
