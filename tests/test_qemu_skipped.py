"""The QEMU plan (test_plans/targets/qemu_speed_step.yaml) on a machine without QEMU or the
Arm toolchain: SKIPPED with the reason naming the missing program and its Debian package,
not ERROR; `hil run` exits 0 for a run whose plans all passed or were SKIPPED."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest_plugins = ["pytester"]

from hil.links import qemu as qemu_module
from hil.plans.format import load_plan
from hil.plans.outcome import Outcome
from hil.run.runner import run_plan

REPO = Path(__file__).resolve().parents[1]
QEMU_PLAN = REPO / "test_plans" / "targets" / "qemu_speed_step.yaml"
HIL = Path(sys.executable).parent / "hil"


def _without(monkeypatch, *programs: str) -> None:
    real_which = qemu_module.shutil.which
    monkeypatch.setattr(qemu_module.shutil, "which",
                        lambda name, *a, **k: None if name in programs else real_which(name, *a, **k))


@pytest.mark.parametrize("missing, package", [
    ("qemu-system-arm", "qemu-system-arm"),
    ("arm-none-eabi-gcc", "gcc-arm-none-eabi"),
])
def test_the_qemu_plan_is_skipped_naming_the_missing_program(monkeypatch, tmp_path, missing, package):
    _without(monkeypatch, missing)
    result, _signals = run_plan(load_plan(QEMU_PLAN), out_dir=tmp_path)
    assert result.outcome is Outcome.SKIPPED, result.reason
    assert missing in result.reason and package in result.reason
    assert result.checks and all(c.outcome is Outcome.SKIPPED for c in result.checks)
    record = json.loads((tmp_path / "qemu-speed-step" / "result.json").read_text())
    assert record["outcome"] == "SKIPPED"


def test_hil_run_exits_0_for_a_skipped_plan(tmp_path):
    """A PATH without qemu-system-arm (the directory of hil's interpreter only)."""
    env = {**os.environ, "PATH": str(tmp_path / "empty")}
    got = subprocess.run([str(HIL), "run", str(QEMU_PLAN), "--out", str(tmp_path / "out"),
                          "--no-progress"], env=env, capture_output=True, text=True, timeout=120)
    assert got.returncode == 0, got.stdout + got.stderr
    assert got.stdout.startswith("SKIPPED  qemu-speed-step")
    assert "qemu-system-arm not found on PATH" in got.stdout


def test_the_pytest_plugin_skips_the_plan_and_its_checks(pytester, monkeypatch):
    _without(monkeypatch, "qemu-system-arm")
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")
    plans = pytester.mkdir("test_plans")
    (plans / QEMU_PLAN.name).write_text(QEMU_PLAN.read_text())
    result = pytester.runpytest("test_plans", "-rs", "-p", "hil.run.pytest_plugin",
                                "-p", "no:cacheprovider")
    result.assert_outcomes(skipped=1 + len(load_plan(QEMU_PLAN).checks))
    result.stdout.fnmatch_lines(["*qemu-system-arm not found on PATH*"])
