"""One vocabulary: every signal test_plans/README.md lists is accepted by `hil plans`, recorded
by a run, and found under the same name and unit by `hil log info`, `plot` and `export`.

The list is parsed from the README (section Signals): ``group.*`` bullets name their fields,
the other bullets full names; names written side by side share the unit after the last of
them, a name followed by no unit is a plain number. One short lockstep run on the in-process
stub (400 periods, simulated time) measures each signal in a check and writes the log the log
commands read.
"""
from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from hil.cli.main import main
from hil.logs.commands import (LogCommandError, field_unit, log_export, log_info, log_plot,
                               plot_series)
from hil.logs.recorder import log_source
from hil.plans.format import parse_plan
from hil.plans.outcome import Outcome
from hil.plans.signals import SIGNAL_CATALOG
from hil.plans.units import UnitError, canonical
from hil.run.runner import run_plan

README = Path(__file__).resolve().parents[1] / "test_plans" / "README.md"
_TICKED = re.compile(r"`([^`]*)`")
_NAME = re.compile(r"^[a-z][a-z0-9_]*(\.[a-z][a-z0-9_]*)?$")


def readme_signals(text: str) -> dict[str, str]:
    """name -> canonical unit of every signal the README's Signals section lists."""
    section = text.split("\n## Signals\n", 1)[1].split("\n## ", 1)[0]
    bullets = section.split("\n- ")[1:]
    out: dict[str, str] = {}
    for bullet in bullets:
        bullet = " ".join(bullet.split())
        head = re.match(r"`([a-z]+)\.\*`", bullet)
        group = head.group(1) if head else None
        body = bullet[head.end():] if head else bullet
        pending: list[str] = []           # names side by side, waiting for their unit
        for m in _TICKED.finditer(body):
            word = m.group(1)
            if not _NAME.match(word) or ("." in word) == (group is not None):
                continue                  # not a signal name (e.g. `wait_until`, a YAML snippet)
            name = f"{group}.{word}" if group else word
            after = body[m.end():]
            pending.append(name)
            if re.match(r"\s*`", after):  # the next name stands beside it: same unit
                continue
            unit = _unit_word(after)
            for n in pending:
                out.setdefault(n, unit)
            pending = []
    return out


def _unit_word(text: str) -> str:
    word = text.split(maxsplit=1)[0].rstrip(",.;:)") if text.strip() else ""
    if not word or word.startswith("("):
        return "1"
    try:
        return canonical(word)
    except UnitError:
        return "1"


def _plan_text(signals: dict[str, str]) -> str:
    checks = "\n".join(
        f"  - check: {{name: 'm{i}', kind: statistic, statistic: max, signal: {name}, role: finding}}"
        for i, name in enumerate(signals))
    return f"""
name: vocabulary
steps:
  - command: {{enable: true, speed_source: encoder, speed_ref_rpm: 300}}
  - wait_until: {{signal: plant.t_s, comparison: above, value: 0.005, timeout_s: 0.1}}
  - run: {{duration_s: 0.015}}
{checks}
"""


SIGNALS = readme_signals(README.read_text())


def test_readme_list_parses_and_matches_the_catalogue():
    """What the README lists is exactly what `hil plans` accepts, with the same units."""
    assert len(SIGNALS) >= 40 and SIGNALS["plant.i_a"] == "A" and SIGNALS["ctrl.gates"] == "1"
    assert sorted(set(SIGNALS) - set(SIGNAL_CATALOG)) == []
    assert sorted(set(SIGNAL_CATALOG) - set(SIGNALS)) == []
    assert {n: u for n, u in SIGNALS.items() if SIGNAL_CATALOG[n] != u} == {}


def test_parser_sees_a_name_the_catalogue_lacks():
    text = README.read_text().replace("`u_alpha` `u_beta` V.", "`u_alpha` `u_beta` V, `bogus_x` Nm.")
    assert readme_signals(text)["plant.bogus_x"] == "Nm"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("vocabulary")
    plan = parse_plan(_plan_text(SIGNALS), "vocabulary.yaml")
    result, signals = run_plan(plan, out_dir=out)
    logs = list(out.rglob("log.mcap"))
    assert len(logs) == 1
    return result, logs[0], signals


def test_a_run_records_every_listed_signal(run):
    """Every check on a listed signal is computed: none ends ERROR 'not recorded'."""
    result, _, _ = run
    assert result.outcome is not Outcome.ERROR, result.reason
    measured = {c.name: c for c in result.checks}
    assert len(measured) == len(SIGNALS)
    for i, name in enumerate(SIGNALS):
        check = measured[f"m{i}"]
        assert check.outcome is not Outcome.ERROR, (name, check)
        assert canonical(check.unit) == SIGNALS[name], name


def test_log_info_lists_each_field_with_its_unit_and_plan_name(run, capsys):
    _, log, _ = run
    info = log_info(log)
    named = {f["signal"]: (ch["topic"], f["unit"]) for ch in info["channels"]
             for f in ch["fields"] if f["signal"]}
    assert sorted(set(SIGNALS) - set(named)) == []
    for name, unit in SIGNALS.items():
        assert canonical(named[name][1] or "1") == unit, name
    assert main(["log", "info", str(log), "--json"]) == 0
    as_json = json.loads(capsys.readouterr().out)
    assert as_json["channels"] == json.loads(json.dumps(info["channels"], default=str))
    assert main(["log", "info", str(log)]) == 0
    text = capsys.readouterr().out
    for name in SIGNALS:       # one line per field: topic:field [unit] plan name
        topic, field = log_source(name)
        assert re.search(rf"^  {re.escape(topic)}:{field} +\[{re.escape(named[name][1])}\] +"
                         rf"{re.escape(name)}$", text, re.M), name


def test_plot_and_export_take_every_listed_name_with_its_unit(run, tmp_path):
    _, log, signals = run
    names = list(SIGNALS)
    exported = log_export(log, names, tmp_path / "all.csv")
    assert len(exported["units"]) == len(names)
    with open(tmp_path / "all.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for name in names:
        column = "{}:{}".format(*log_source(name))
        assert column in exported["units"], name
        assert canonical(exported["units"][column] or "1") == SIGNALS[name], name
        assert any(row[column] != "" for row in rows), f"{name}: no sample in the export"
    # what `hil log plot` draws (its data part: drawing 50 panels would only cost time) ...
    # the same samples the run's checks measured (held values at each logged change)
    series, _ = plot_series(log, names)
    for name, (spec, topic, field, t, values) in zip(names, series):
        assert spec == name and len(t) == len(values) > 0, name
        assert canonical(field_unit(topic, field) or "1") == SIGNALS[name], name
        last = np.r_[t[1:] != t[:-1], True]   # of two commands in one period, the one held
        in_run = np.array([signals[name].at(x) for x in t[last]])
        np.testing.assert_allclose(values[last], in_run, rtol=1e-6, atol=1e-6, err_msg=name)
    # ... and drawn, one signal of each kind of topic
    kinds = ["plant.speed_rpm", "sensor.adc_i1", "ctrl.speed_ekf_rad_s", "cmd.speed_ref_rpm",
             "board.state"]
    plotted = log_plot(log, kinds, tmp_path / "kinds.png")
    assert {n: s["unit"] or "1" for n, s in plotted["signals"].items()} == \
        {n: SIGNALS[n] for n in kinds}
    # the topic form keeps working, beside the plan's name, and means the same field
    both = log_plot(log, ["/cmd:speed_ref_rpm", "cmd.speed_ref_rpm"], tmp_path / "cmd.png")
    a, b = both["signals"].values()
    assert (a["topic"], a["field"], a["max"]) == (b["topic"], b["field"], b["max"]) == \
        ("/cmd", "speed_ref_rpm", 300.0)


def test_a_misspelt_name_says_what_there_is(run, tmp_path):
    _, log, _ = run
    with pytest.raises(LogCommandError, match="/plant/truth has no field 'speed_rmp'"):
        log_plot(log, ["plant.speed_rmp"], tmp_path / "x.png")
    with pytest.raises(LogCommandError, match="did you mean 'board.state'"):
        log_export(log, ["board.stat"], tmp_path / "x.csv")
