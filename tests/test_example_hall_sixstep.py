"""The hall_sixstep example board (examples/hall_sixstep): a BLDC six-step drive on three Hall
sensors, written only against protocol/SPEC.md and the public C headers, reads SAMPLE_SENSORS
with its declared sensor set and answers DUTY_LEGS. Its own plans (start-up, speed step, load
step, a stuck Hall sensor, a locked rotor), which name their profile and board file, pass
through `hil run` over an executable (exec:) and the Cortex-M4F image under QEMU (qemu:); and
they fail a drive whose Hall sensors are mounted 60 electrical degrees off."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "hall_sixstep"
PLANS = EXAMPLE / "plans"
BUILD = EXAMPLE / "build"
HAVE_ARM = shutil.which("arm-none-eabi-gcc") is not None
HAVE_QEMU = HAVE_ARM and shutil.which("qemu-system-arm") is not None


@pytest.fixture(scope="module", autouse=True)
def built() -> None:
    targets = ["host", "lib"] + (["arm"] if HAVE_ARM else [])
    subprocess.run(["make", "-s", "-C", str(EXAMPLE), *targets], check=True, capture_output=True,
                   timeout=300)


def hil_run(plans: Path, link: str, out: Path, *extra: str) -> tuple[subprocess.CompletedProcess, list[dict]]:
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "run", str(plans), "--link", link,
                           "--out", str(out), "--no-progress", *extra], capture_output=True, text=True,
                          timeout=600, cwd=REPO)
    results = [json.loads(p.read_text()) for p in sorted(out.glob("**/result.json"))]
    return proc, results


def test_example_passes_its_plans_over_exec(tmp_path):
    link = f"exec:{BUILD / 'hall_sixstep'}"
    proc, results = hil_run(PLANS, link, tmp_path / "out")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(results) == len(list(PLANS.glob("*.yaml"))) == 5
    assert all(r["outcome"] == "PASS" for r in results), [(r["plan"], r["reason"]) for r in results]
    assert {r["link"] for r in results} == {link}
    # the two fault plans saw the board's two faults: FAULT 2 for the illegal Hall word (the
    # position sensor lost), FAULT 7 for the locked rotor (the rotor does not follow the drive)
    assert "board FAULT 2 ENCODER_LOSS" in proc.stdout + proc.stderr
    assert "board FAULT 7 STALL" in proc.stdout + proc.stderr


@pytest.mark.skipif(not HAVE_QEMU, reason="qemu-system-arm / gcc-arm-none-eabi not installed "
                                          "(scripts/bootstrap.sh installs them as root)")
def test_example_image_passes_its_plans_under_qemu(tmp_path):
    link = f"qemu:{BUILD / 'hall_sixstep.elf'}"
    proc, results = hil_run(PLANS, link, tmp_path / "out")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [r["outcome"] for r in results] == ["PASS"] * 5
    assert all(r["extra"]["board"].startswith("hall_sixstep") for r in results)


def test_the_plans_fail_hall_sensors_mounted_off_their_axes(tmp_path):
    """The plans can fail: Hall sensors mounted 60 electrical degrees off their phase axes
    (a board not told) make the drive commutate a whole sector late, and the start-up misses."""
    profile = tmp_path / "bldc_halls_off.yaml"
    text = (EXAMPLE / "profiles" / "bldc.yaml").read_text()
    assert "placement_error_deg: [0.0, 1.5, -1.0]" in text
    profile.write_text(text.replace("placement_error_deg: [0.0, 1.5, -1.0]",
                                    "placement_error_deg: [60.0, 60.0, 60.0]"))
    proc, results = hil_run(PLANS / "01_startup.yaml", f"exec:{BUILD / 'hall_sixstep'}",
                            tmp_path / "out", "--profile", str(profile))
    assert proc.returncode != 0, proc.stdout + proc.stderr
    assert [r["outcome"] for r in results] in (["FAIL"], ["TIMEOUT"], ["ERROR"])
