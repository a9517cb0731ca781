"""The `hil` command line: exit codes, reports, errors that name what was wrong."""
from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from hil.cli.main import main as hil_main

REPO = Path(__file__).resolve().parent.parent
SPEED_STEP = REPO / "test_plans" / "01_speed_step_sensored.yaml"

SHORT_PLAN = """
name: short-spin
description: spin up briefly and check the speed rose
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1000}
  - run: {duration_s: 0.05}
  - check:
      name: speed rose
      kind: final_value
      signal: plant.speed_rpm
      limits: {low: %(low)s, unit: rpm}
"""


def _plan(tmp_path: Path, low: float, name: str = "plan.yaml") -> Path:
    path = tmp_path / name
    path.write_text(SHORT_PLAN % {"low": low})
    return path


def test_run_passing_plan_writes_reports_and_exits_0(tmp_path, capsys):
    out = tmp_path / "out"
    assert hil_main(["run", str(_plan(tmp_path, 100)), "--out", str(out), "--no-progress"]) == 0
    assert "PASS" in capsys.readouterr().out
    plan_dir = out / "short-spin"
    record = json.loads((plan_dir / "result.json").read_text())
    assert record["outcome"] == "PASS" and record["checks"][0]["measured"] > 100
    ET.parse(out / "junit.xml")
    assert (plan_dir / "log.mcap").stat().st_size > 0
    assert "<img" in (plan_dir / "report.html").read_text()


def test_impossible_limit_fails_with_exit_1_and_the_measured_value(tmp_path, capsys):
    out = tmp_path / "out"
    assert hil_main(["run", str(_plan(tmp_path, 100000)), "--out", str(out), "--no-progress"]) == 1
    record = json.loads((out / "short-spin" / "result.json").read_text())
    check = record["checks"][0]
    assert check["outcome"] == "FAIL" and 100 < check["measured"] < 100000


def test_unknown_link_is_an_error_naming_it(tmp_path, capsys):
    code = hil_main(["run", str(_plan(tmp_path, 1)), "--link", "bogus-link", "--out",
                     str(tmp_path / "out"), "--no-progress"])
    assert code == 2
    # said once, before any plan runs (hil.links.registry.check_link): no run, no result
    assert "unknown link 'bogus-link'" in capsys.readouterr().err
    assert not (tmp_path / "out" / "short-spin").exists()


def test_unwritable_out_directory_is_refused_before_running(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    code = hil_main(["run", str(_plan(tmp_path, 1)), "--out", str(blocker / "out"), "--no-progress"])
    assert code == 2
    assert str(blocker / "out") in capsys.readouterr().err


def test_invalid_plan_is_refused_with_file_line_and_key(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nsteps:\n  - run: {duration_s: -1}\n")
    assert hil_main(["run", str(bad), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:3" in err and "duration_s" in err
    assert not (tmp_path / "out" / "bad").exists()


def test_plans_lists_and_validates(tmp_path, capsys):
    assert hil_main(["plans", str(REPO / "test_plans")]) == 0
    assert "speed-step-sensored" in capsys.readouterr().out
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nsteps:\n  - run: {duration_s: 1, typo: 2}\n")
    assert hil_main(["plans", str(bad)]) == 2
    assert "typo" in capsys.readouterr().out


def test_serve_runs_the_plant_against_the_stub_for_a_duration(tmp_path):
    log = tmp_path / "serve.mcap"
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "serve", "--link", "stub", "--duration",
                           "0.02", "--modbus", "off", "--log", str(log), "--enable",
                           "--speed-rpm", "1000", "--log-compression", "zstd"],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    assert "400 periods" in proc.stderr
    from mcap.reader import make_reader

    from hil.logs.reader import read_log

    truth = read_log(log)["/plant/truth"]
    assert len(truth) == 400 and truth["speed_rpm"][-1] > 50.0  # the board drove the motor
    with open(log, "rb") as f:
        assert {c.compression for c in make_reader(f).get_summary().chunk_indexes} == {"zstd"}


@pytest.mark.parametrize("choice", ["lz4", "zstd", "none"])
def test_log_compression_option_sets_the_chunks_compression(tmp_path, choice):
    """--log-compression reaches the MCAP writer: every chunk of the run's log says so in its
    chunk index, as the mcap package reads it, and the log reads back whole."""
    from mcap.reader import make_reader

    from hil.logs.mcap_writer import COMPRESSIONS
    from hil.logs.reader import read_log

    out = tmp_path / "out"
    assert hil_main(["run", str(_plan(tmp_path, 100)), "--out", str(out), "--no-progress",
                     "--log-compression", choice]) == 0
    log = out / "short-spin" / "log.mcap"
    with open(log, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert chunks and {c.compression for c in chunks} == {"" if choice == "none" else choice}
    assert len(read_log(log)["/plant/truth"]) == 1000      # 0.05 s at 50 us
    assert choice in COMPRESSIONS


def test_log_compression_choices_are_the_writers():
    from hil.cli.main import LOG_COMPRESSIONS
    from hil.logs.mcap_writer import COMPRESSIONS

    assert LOG_COMPRESSIONS == COMPRESSIONS


def test_unknown_log_compression_is_refused_naming_the_choices(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        hil_main(["run", str(_plan(tmp_path, 100)), "--out", str(tmp_path / "out"),
                  "--no-progress", "--log-compression", "gzip"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--log-compression" in err and "gzip" in err and "lz4" in err


def test_help_for_every_command():
    for command in ([], ["run"], ["serve"], ["log"], ["bench"], ["plans"]):
        proc = subprocess.run([sys.executable, "-m", "hil.cli.main", *command, "--help"],
                              capture_output=True, text=True, timeout=60, cwd=REPO)
        assert proc.returncode == 0 and "usage: hil" in proc.stdout


def _subparsers(parser):
    import argparse

    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_a_command_line_builds_only_its_command_s_parser_with_the_same_arguments():
    """`hil run ...` builds the run subparser alone (the argparse set-up of the other commands
    is start-up time); its help, hence its arguments, are those of the parser of every command."""
    import sys as _sys

    hil_cli = _sys.modules["hil.cli.main"]
    full = _subparsers(hil_cli._parser(["--help", "init"]))     # every command, init's options too
    assert list(full) == list(hil_cli.COMMANDS)
    for command in hil_cli.COMMANDS:
        alone = _subparsers(hil_cli._parser([command, "p.yaml"] if command != "init" else ["init"]))
        assert list(alone) == [command]
        assert alone[command].format_help() == full[command].format_help()
    args = hil_cli._parser(["run", "p.yaml", "--seed", "3"]).parse_args(["run", "p.yaml", "--seed", "3"])
    assert args.command == "run" and args.seed == 3 and args.plans == [Path("p.yaml")]


@pytest.mark.parametrize("columns", [None, "57", "200", "0", "wide"])
def test_the_help_is_as_wide_as_argparse_makes_it_and_reads_the_same(columns, monkeypatch):
    """hil's help formatter finds the width as shutil.get_terminal_size does ($COLUMNS, else the
    terminal, else 80) without importing shutil; every command's help is the standard
    formatter's, word for word, at each width."""
    import argparse
    import shutil
    import sys as _sys

    hil_cli = _sys.modules["hil.cli.main"]
    if columns is None:
        monkeypatch.delenv("COLUMNS", raising=False)
    else:
        monkeypatch.setenv("COLUMNS", columns)
    assert hil_cli._terminal_columns() == shutil.get_terminal_size().columns
    ours, lean = hil_cli._parser(["--help", "init"]), hil_cli._ArgumentParser
    monkeypatch.setattr(hil_cli, "_ArgumentParser", argparse.ArgumentParser)
    standard = hil_cli._parser(["--help", "init"])
    assert ours.format_help() == standard.format_help()
    for (name, parser), (_, twin) in zip(_subparsers(ours).items(), _subparsers(standard).items()):
        assert type(parser) is lean and type(twin) is argparse.ArgumentParser
        assert parser.format_help() == twin.format_help(), name
