"""The short acceptance plan against the Cortex-M4F firmware in QEMU, and against the host stub.

Tolerance between the two runs: none. Both builds compile the same core, app and codec
sources with -std=c99 (ISO C, not GNU C), under which GCC's default is -ffp-contract=off: the
Cortex-M4F's fused multiply-add is never used to merge a*b + c, so every float operation is
one IEEE-754 single-precision rounding on both targets, the fast sine/cosine are the same
table arithmetic, and no libm function whose implementation differs between glibc and newlib
is on the control path. The same bytes in must therefore give the same bytes out, and the
plant (the same Python on the bench side) the same truth. Should a target ever need
contraction, this test is where the tolerance would be introduced and argued.
"""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hil.plans.outcome import Outcome
from hil.plans.format import load_plan
from hil.run.runner import run_plan

PLAN = Path(__file__).resolve().parent.parent / "test_plans" / "targets" / "qemu_speed_step.yaml"

pytestmark = pytest.mark.skipif(
    shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None,
    reason="qemu-system-arm / gcc-arm-none-eabi not installed (scripts/bootstrap.sh installs them as root)")


def _qemu_processes() -> int:
    out = subprocess.run(["pgrep", "-c", "-f", "qemu-system-arm"], capture_output=True, text=True)
    return int(out.stdout.strip() or 0)


def test_plan_passes_on_the_target_and_matches_the_host_bit_for_bit(tmp_path):
    plan = load_plan(PLAN)
    before = _qemu_processes()
    target, target_signals = run_plan(plan, out_dir=tmp_path)
    assert _qemu_processes() == before, "QEMU must be stopped after the run"
    assert target.outcome is Outcome.PASS, target.reason
    assert target.link == "qemu" and "cm4f" in target.extra["board"]
    host, host_signals = run_plan(plan, link="stub")
    assert host.outcome is Outcome.PASS, host.reason
    for name in ("plant.speed_rpm", "plant.i_a", "plant.i_b", "plant.torque_nm", "ctrl.gates",
                 "ctrl.speed_ekf_rad_s", "ctrl.flux_mag_wb"):
        np.testing.assert_array_equal(target_signals[name].values, host_signals[name].values,
                                      err_msg=name)
    assert (tmp_path / "qemu-speed-step" / "log.mcap").stat().st_size > 0


def test_qemu_is_stopped_when_the_run_fails(tmp_path):
    """A plan that ends in TIMEOUT still stops QEMU and closes the log."""
    from hil.plans.format import parse_plan

    plan = parse_plan("""
name: qemu-timeout
link: qemu
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 300}
  - wait_until: {signal: plant.speed_rpm, comparison: above, value: 9000, unit: rpm, timeout_s: 0.005}
""", "inline.yaml")
    before = _qemu_processes()
    result, _ = run_plan(plan, out_dir=tmp_path)
    assert result.outcome is Outcome.TIMEOUT
    assert _qemu_processes() == before
