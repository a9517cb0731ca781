"""hil sweep (issue 16): the sweep format and its errors, sampling and seeds, the summary
statistics against a hand-made table, reproducibility over 1 and 2 workers, resume, the CLI.

Short plans (tests/data/sweep/short_plan.yaml: 50 ms simulated) and a few runs each."""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
import textwrap
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from configfile.source import ConfigError
from hil.cli.main import main
from hil.plans.format import plan_files
from hil.sweep import load_sweep, parse_sweep
from hil.sweep.html import write_junit
from hil.sweep.run import run_sweep, tasks_for
from hil.sweep.sampling import expand, inverse_cdf, run_seed
from hil.sweep.summary import spearman, summarize, wilson

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data" / "sweep"
PLAN = DATA / "short_plan.yaml"


def sweep_text(runs=6, sampling="monte_carlo", extra="", seed=5):
    return textwrap.dedent(f"""\
        sweep:
          name: short
          plans: [{PLAN}]
          seed: {seed}
          sampling: {sampling}
          runs: {runs}
          parameters:
            plan.steps[2].check.limits.high: {{uniform: {{low: 1100.0, high: 1250.0}}}}
            profile.motor.inertia_kgm2: {{uniform: {{low: 6.0e-4, high: 1.0e-3}}}}
        {extra}""")


def write_sweep(tmp_path, **kw) -> Path:
    path = tmp_path / "short.sweep.yaml"
    path.write_text(sweep_text(**kw))
    return path


# --------------------------------------------------------------------------- format
def test_example_sweeps_load_and_are_not_plans():
    for f in sorted((REPO / "test_plans" / "sweeps").glob("*.yaml")):
        s = load_sweep(f)
        assert s.plan_paths and all(p.is_file() for p in s.plan_paths)
    found = plan_files([REPO / "test_plans"])
    assert not [p for p in found if "sweeps" in p.parts], "hil run would take sweep files for plans"


@pytest.mark.parametrize("body,line,key,words", [
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  sampling: sobol\n", 5, "sweep.sampling",
     "expected one of: monte_carlo, latin_hypercube"),
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  parameters:\n    profile.motor.resistance_ohm: {uniform: {low: 1, hihg: 2}}\n",
     6, "sweep.parameters.profile.motor.resistance_ohm.uniform.hihg", "did you mean 'high'"),
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  parameters:\n    motor.resistance_ohm: {uniform: {low: 1, high: 2}}\n",
     6, "sweep.parameters.motor.resistance_ohm", "not a parameter name"),
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  parameters:\n    profile.motor.resistance_ohm: {uniform: {low: 2, high: 1}}\n",
     6, "sweep.parameters.profile.motor.resistance_ohm.uniform", "must be below high"),
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  link: serial:/dev/ttyUSB0\n", 5, "sweep.link",
     "physical board"),
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  parameters:\n    plan.steps[9].run.duration_s: {grid: [0.1]}\n",
     6, "sweep.parameters.plan.steps[9].run.duration_s", "the plan has no 'steps[9]'"),
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  parameters:\n    profile.motor.resistance_ohm: {uniform: {low: -2, high: -1}}\n",
     6, "sweep.parameters.profile.motor.resistance_ohm", "makes plan short_plan.yaml invalid"),
    ("sweep:\n  name: x\n  plans: [P]\n  seed: 1\n  parameters:\n    profile.motor.resistnace_ohm: {grid: [1.0]}\n",
     6, "sweep.parameters.profile.motor.resistnace_ohm", "invalid"),
    ("name: x\nsteps: []\n", 1, None, "top-level key 'sweep'"),
])
def test_sweep_errors_name_file_line_and_key(tmp_path, body, line, key, words):
    path = tmp_path / "bad.yaml"
    path.write_text(body.replace("[P]", f"[{PLAN}]"))
    with pytest.raises(ConfigError) as err:
        load_sweep(path)
    e = err.value
    assert e.source == str(path) and e.line == line and e.key == key, str(e)
    assert words in str(e), str(e)


# --------------------------------------------------------------------------- sampling
def test_seeds_and_values_depend_on_sweep_seed_and_index_only(tmp_path):
    s = load_sweep(write_sweep(tmp_path, runs=8))
    runs = expand(s)
    assert [r.seed for r in runs] == [run_seed(5, i) for i in range(8)]
    assert len({r.seed for r in runs}) == 8
    # Monte Carlo: sample k is the same whatever the number of samples.
    more = expand(parse_sweep(sweep_text(runs=12), str(tmp_path / "m.yaml")))
    assert [r.values for r in more[:8]] == [r.values for r in runs]
    other = expand(parse_sweep(sweep_text(runs=8, seed=6), str(tmp_path / "o.yaml")))
    assert [r.values for r in other] != [r.values for r in runs]


def test_latin_hypercube_uses_every_stratum_once(tmp_path):
    s = load_sweep(write_sweep(tmp_path, runs=10, sampling="latin_hypercube"))
    for name, (lo, hi) in {"plan.steps[2].check.limits.high": (1100, 1250),
                           "profile.motor.inertia_kgm2": (6e-4, 1e-3)}.items():
        strata = sorted(int((r.values[name] - lo) / (hi - lo) * 10) for r in expand(s))
        assert strata == list(range(10)), (name, strata)


def test_truncated_normal_and_choice_inverse_cdf():
    from hil.sweep.format import Parameter

    n = Parameter("x", "normal", {"mean": 0.0, "sd": 1.0, "low": -1.0, "high": 2.0}, 1)
    assert inverse_cdf(n, 0.0) == pytest.approx(-1.0) and inverse_cdf(n, 1.0) == pytest.approx(2.0)
    # the median of N(0,1) truncated to [-1, 2]: Phi(-1) = 0.158655, Phi(2) = 0.977250 (table);
    # Phi^-1((0.158655 + 0.977250) / 2) = Phi^-1(0.567953) = 0.1712 (table)
    assert inverse_cdf(n, 0.5) == pytest.approx(0.1712, abs=1e-3)
    c = Parameter("y", "choice", {"values": ["a", "b", "c"], "weights": [1, 0, 3]}, 1)
    assert [inverse_cdf(c, u) for u in (0.0, 0.24, 0.26, 0.99)] == ["a", "a", "c", "c"]


# --------------------------------------------------------------------------- statistics
def _row(i, x, measured, outcome, check_outcome=None, lost=False):
    return {"index": i, "plan": "P", "params": {"x": x, "k": 3.0, "z": float((7 * i) % 10)},
            "outcome": outcome, "lost": lost,
            "checks": [] if lost else [{"name": "c", "measured": measured, "unit": "ms",
                                        "outcome": check_outcome or outcome}]}


def hand_table():
    # x = 1..10, the check measures x, fails from x = 9 on; one run lost; one check not evaluated.
    rows = [_row(i, float(i + 1), float(i + 1), "PASS" if i < 8 else "FAIL") for i in range(10)]
    rows.append(_row(10, 5.0, None, "ERROR", lost=True))
    rows.append(_row(11, 4.0, None, "ERROR", check_outcome="ERROR"))
    return rows


def test_wilson_against_tables():
    # Wilson score intervals, 95 %: 8/10 -> 0.4902 .. 0.9433; 0/5 -> 0 .. 0.4345; 10/10 -> 0.7225 .. 1
    assert wilson(8, 10) == pytest.approx((0.4902, 0.9433), abs=1e-4)
    assert wilson(0, 5) == pytest.approx((0.0, 0.4345), abs=1e-4)
    assert wilson(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)


def test_spearman_by_hand():
    # d = (-1, 1, -1, 1, 0): rho = 1 - 6 * 4 / (5 * 24) = 0.8
    assert spearman([1, 2, 3, 4, 5], [2, 1, 4, 3, 5]) == pytest.approx(0.8)
    # ties: x ranks (1, 2.5, 2.5, 4): rho = 4.5 / sqrt(4.5 * 5) = 0.948683
    assert spearman([1, 2, 2, 3], [1, 2, 3, 4]) == pytest.approx(0.948683, abs=1e-6)
    assert spearman([1, 1, 1], [1, 2, 3]) is None


def test_summary_against_hand_made_table():
    s = summarize(hand_table(), ["x", "k", "z"])
    (plan,) = s["plans"]
    # 11 judged runs (the lost one apart), 8 passed
    assert (plan["runs"], plan["judged"], plan["passed"], plan["lost"]) == (12, 11, 8, 1)
    assert (plan["ci_low"], plan["ci_high"]) == pytest.approx(wilson(8, 11))
    (c,) = s["checks"]
    assert (c["evaluated"], c["passed"], c["failed"]) == (10, 8, 2)
    assert c["not_evaluated"] == {"ERROR": 1}
    assert (c["ci_low"], c["ci_high"]) == pytest.approx((0.4902, 0.9433), abs=1e-4)
    assert c["failed_runs"] == [8, 9]
    assert (c["min"], c["median"], c["max"]) == (1.0, 5.5, 10.0)
    # x drives the failure: rho(x, value) = 1; rho(x, fail) = 40 / sqrt(82.5 * 40) = 0.696311;
    # k is constant (no rank correlation); z = 7i mod 10 ranks lower.
    d = c["drivers"]
    assert d[0]["parameter"] == "x"
    assert d[0]["rho_value"] == pytest.approx(1.0)
    assert d[0]["rho_fail"] == pytest.approx(0.696311, abs=1e-6)
    assert [x["parameter"] for x in d] == ["x", "z"]


def test_a_finding_is_summarised_by_its_values_not_counted_as_unevaluated(tmp_path):
    """A check with role finding (outcome INFO in every run) has no yield; its five values
    3, 1, 4, 1, 5 give min 1, median 3, max 5 and a Spearman rho against x of
    4 / sqrt(10 * 9.5) by hand (ranks of y 3, 1.5, 4, 1.5, 5 against 1..5: deviations
    products sum to 4, squares to 10 and 9.5), and no rho_fail."""
    rows = [{"index": i, "plan": "p", "outcome": "PASS", "params": {"x": float(i)},
             "checks": [{"name": "ratio", "outcome": "INFO", "measured": v, "unit": "1"}]}
            for i, v in enumerate([3.0, 1.0, 4.0, 1.0, 5.0])]
    (c,) = summarize(rows, ["x"])["checks"]
    assert c["finding"] and c["measured_runs"] == 5 and c["evaluated"] == 0
    assert c["not_evaluated"] == {}
    assert (c["min"], c["median"], c["max"]) == (1.0, 3.0, 5.0)
    (d,) = c["drivers"]
    assert d["rho_value"] == pytest.approx(4.0 / math.sqrt(10.0 * 9.5), abs=1e-9)
    assert d["rho_fail"] is None
    path = write_junit({"name": "s"}, summarize(rows, ["x"]), tmp_path)
    case = ET.parse(path).getroot().find(".//testcase")
    assert case.find("failure") is None and case.find("error") is None
    assert "finding, measured in 5 run(s): min / median / max 1 / 3 / 5" in case.find("system-out").text


def test_junit_one_case_per_check(tmp_path):
    s = summarize(hand_table(), ["x"])
    import xml.etree.ElementTree as ET

    root = ET.parse(write_junit({"name": "t"}, s, tmp_path)).getroot()
    cases = root.findall(".//testcase")
    assert [c.get("name") for c in cases] == ["c"]
    fail = cases[0].find("failure")
    assert fail is not None and "8/10" in fail.get("message") and "failed runs: 8, 9" in fail.text


# --------------------------------------------------------------------------- running
def _table(out: Path) -> list[dict]:
    rows = pq.read_table(out / "results.parquet").to_pylist()
    for r in rows:
        for k in ("wall_s", "run_wall_s", "worker", "log"):
            r.pop(k)
    return rows


def test_same_table_from_one_and_two_workers(tmp_path):
    path = write_sweep(tmp_path, runs=6)
    s = load_sweep(path)
    one = run_sweep(s, tmp_path / "one", workers=1, progress=False, stall_timeout_s=120)
    two = run_sweep(s, tmp_path / "two", workers=2, progress=False, stall_timeout_s=120)
    t1, t2 = _table(tmp_path / "one"), _table(tmp_path / "two")
    assert [r["index"] for r in t1] == list(range(6))
    assert t1 == t2
    outcomes = {r["check.speed reached.outcome"] for r in t1}
    assert outcomes == {"PASS", "FAIL"}, "the test sweep should have both outcomes"
    assert one["plans"] == two["plans"]
    # logs: every failed run keeps its MCAP log
    rows = json.loads((tmp_path / "two" / "results.json").read_text())
    for r in rows:
        if r["outcome"] == "FAIL":
            assert r["log"] and Path(r["log"]).is_file()


def test_resume_runs_only_what_is_missing(tmp_path):
    path = write_sweep(tmp_path, runs=5)
    s = load_sweep(path)
    full = tmp_path / "full"
    run_sweep(s, full, workers=1, progress=False, stall_timeout_s=120)
    # An interrupted sweep: three rows written, then a torn fourth line.
    part = tmp_path / "part"
    part.mkdir()
    (part / "sweep.json").write_text((full / "sweep.json").read_text())
    lines = (full / "results.jsonl").read_text().splitlines()
    (part / "results.jsonl").write_text("\n".join(lines[:3]) + "\n" + lines[3][:20])
    with pytest.raises(ConfigError, match="--resume"):
        run_sweep(s, part, workers=1, progress=False)
    summary = run_sweep(s, part, workers=1, resume=True, progress=False, stall_timeout_s=120)
    assert summary["ran"] == 2
    kept = [json.loads(l) for l in (part / "results.jsonl").read_text().splitlines()]
    assert sorted(r["index"] for r in kept) == list(range(5))
    # results.jsonl is a journal in the order runs finished (hil/sweep/results.py), and the
    # resume rewrites the rows it keeps by index: compare them as a set, not by position
    by_index = lambda rows: sorted(rows, key=lambda r: r["index"])   # noqa: E731
    assert by_index(kept[:3]) == by_index(json.loads(l) for l in lines[:3]), \
        "finished runs were repeated"
    assert _table(part) == _table(full)
    # a changed sweep is not resumed into old results
    path.write_text(sweep_text(runs=5, seed=9))
    with pytest.raises(ConfigError, match="changed"):
        run_sweep(load_sweep(path), part, workers=1, resume=True, progress=False)


def test_lost_worker_run_is_recorded_not_missing(tmp_path):
    """A local pool process that dies: the run is retried, then recorded lost (ERROR); the runs
    in flight beside it when the pool broke are run again and never charged for its crash
    (with 8 runs on 2 workers some always share the pool with the dying one)."""
    from hil.sweep.executors import LocalExecutor

    rows = []
    tasks = [{"index": i, "plan_path": "p", "point": 0, "sample": i, "seed": i, "values": {},
              "die": i == 1} for i in range(8)]
    LocalExecutor(2, retries=1, stall_timeout_s=60, fn=_dies_on_flag).run(tasks, rows.append)
    by = {r["index"]: r for r in rows}
    assert sorted(by) == list(range(8)) and len(rows) == 8
    assert by[1]["lost"] and by[1]["outcome"] == "ERROR" and "worker process died" in by[1]["reason"]
    assert "gave up after 2 attempts" in by[1]["reason"]
    assert [i for i, r in by.items() if r["lost"]] == [1]


def _dies_on_flag(task):
    """The flagged run kills its worker after 0.2 s; the others take 0.4 s, so some are always
    in flight in the same pool when it dies."""
    import os
    import time

    if task["die"]:
        time.sleep(0.2)
        os._exit(3)
    time.sleep(0.4)
    return {"index": task["index"], "outcome": "PASS", "lost": False}


def test_cli_runs_the_example_sweep_small(tmp_path, capsys):
    # The fault-timing example, cut down to 3 runs (the same file otherwise).
    text = (REPO / "test_plans" / "sweeps" / "encoder_loss_timing.yaml").read_text()
    small = tmp_path / "encoder_loss_timing.yaml"
    small.write_text(text.replace("runs: 40", "runs: 3").replace(
        "../faults/", str(REPO / "test_plans" / "faults") + "/"))
    code = main(["sweep", str(small), "--workers", "2", "--out", str(tmp_path / "o"), "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "yield 3/3" in out
    for f in ("results.parquet", "results.json", "summary.json", "index.html", "junit.xml"):
        assert (tmp_path / "o" / f).is_file()
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    det = next(c for c in summary["checks"] if c["check"] == "detection time")
    assert 10.0 <= det["min"] <= det["max"] <= 10.1
    assert main(["sweep", str(tmp_path / "nope.yaml")]) == 2


@pytest.mark.parametrize("link", ["exec:{marker_program}", "lib:{tmp}/libevil.so", "qemu:{tmp}/evil.elf"])
def test_a_sweep_naming_a_program_link_runs_only_with_allow_programs(tmp_path, capsys, link):
    """Running someone else's sweep file must not run their program unasked: a link that runs
    a program (exec:, lib:, qemu:) is refused by name (file, line, link) before anything runs,
    unless --allow-programs says so."""
    marker = tmp_path / "it-ran"
    program = tmp_path / "evil.sh"
    program.write_text(f"#!/bin/sh\ntouch {marker}\n")
    program.chmod(0o755)
    link = link.format(marker_program=program, tmp=tmp_path)
    path = tmp_path / "theirs.sweep.yaml"
    path.write_text(sweep_text(runs=1).replace("  seed: 5\n", f"  seed: 5\n  link: {link}\n"))
    assert path.read_text().splitlines()[4] == f"  link: {link}"          # line 5
    code = main(["sweep", str(path), "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and not marker.exists() and not (tmp_path / "o").exists()
    assert f"{path}:5: key 'sweep.link': link '{link}' runs the program it names" in err
    assert "--allow-programs" in err
    sweep = load_sweep(path)
    with pytest.raises(ConfigError, match="--allow-programs"):
        run_sweep(sweep, tmp_path / "o", progress=False)
    from hil.sweep.run import check_programs_allowed
    check_programs_allowed(sweep, allow_programs=True)        # the user's explicit yes
    ours = tmp_path / "ours"
    ours.mkdir()
    check_programs_allowed(load_sweep(write_sweep(ours)), allow_programs=False)   # link: stub


def test_a_sweeps_board_file_is_the_board_of_every_run(tmp_path):
    """`board:` (relative to the sweep file) applies to each run: a board file that promises a
    capability the stub lacks makes every run end ERROR naming it; a bad board file fails the
    sweep at load, naming its own file, line and key."""
    (tmp_path / "promise.yaml").write_text("name: promises DUTY_LEGS\ncapabilities: [DUTY_LEGS]\n")
    path = tmp_path / "short.sweep.yaml"
    path.write_text(sweep_text(runs=2).replace("  seed: 5\n", "  seed: 5\n  board: promise.yaml\n"))
    s = load_sweep(path)
    assert s.board_path == (tmp_path / "promise.yaml").resolve()
    run_sweep(s, tmp_path / "out", workers=1, progress=False, stall_timeout_s=120)
    rows = json.loads((tmp_path / "out" / "results.json").read_text())
    assert [r["outcome"] for r in rows] == ["ERROR", "ERROR"]
    assert all("lacks capability DUTY_LEGS, which its board file" in r["reason"] for r in rows)
    (tmp_path / "promise.yaml").write_text("name: bad\ncapabilities: [PWM]\n")
    with pytest.raises(ConfigError) as info:
        load_sweep(path)
    assert info.value.source == str(tmp_path / "promise.yaml") and info.value.line == 2
