"""The sensorless six-step example (examples/bemf_sixstep), written only against the public
headers and SPEC.md, reads SAMPLE_SENSORS (currents, DC link, terminal voltages, BEMF
comparators) and runs its own plans through `hil run` with its board file and motor profile:
over an executable on a pseudo-terminal (exec:) and as a Cortex-M4F image under QEMU (qemu:),
each plan PASS. And the plans can fail: comparators whose offsets exceed the back-EMF at the
hand-over speed never show the crosses, so the start-up plan does not pass."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "bemf_sixstep"
PLANS = EXAMPLE / "plans"
BUILD = EXAMPLE / "build"


@pytest.fixture(scope="module", autouse=True)
def built() -> None:
    targets = ["host", "lib"] + (["arm"] if shutil.which("arm-none-eabi-gcc") else [])
    subprocess.run(["make", "-s", "-C", str(EXAMPLE), *targets], check=True, capture_output=True,
                   timeout=300)


def hil_run(plans: Path, link: str, out: Path, *extra: str
            ) -> tuple[subprocess.CompletedProcess, list[dict]]:
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "run", str(plans), "--link", link,
                           "--out", str(out), "--no-progress", *extra], capture_output=True,
                          text=True, timeout=600, cwd=REPO)
    results = [json.loads(p.read_text()) for p in sorted(out.glob("**/result.json"))]
    return proc, results


def test_example_passes_its_plans_over_exec(tmp_path):
    link = f"exec:{BUILD / 'bemf_sixstep'}"
    proc, results = hil_run(PLANS, link, tmp_path / "out")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(results) == len(list(PLANS.glob("*.yaml"))) == 5
    assert all(r["outcome"] == "PASS" for r in results), [(r["plan"], r["reason"]) for r in results]
    assert {r["link"] for r in results} == {link}
    assert all(r["extra"]["board"].startswith("bemf-sixstep") for r in results)


@pytest.mark.skipif(shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None,
                    reason="needs qemu-system-arm and arm-none-eabi-gcc")
def test_example_image_passes_its_plans_under_qemu(tmp_path):
    link = f"qemu:{BUILD / 'bemf_sixstep.elf'}"
    proc, results = hil_run(PLANS, link, tmp_path / "out")           # about 100 s of QEMU
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [r["outcome"] for r in results] == ["PASS"] * 5
    assert all(r["extra"]["board"].endswith("cm4f") for r in results)


def test_the_start_fails_when_the_comparators_cannot_see_the_back_emf(tmp_path):
    """Offsets of 1.5 V, above the 1.2 V phase back-EMF at the ramp's end speed (50 rad/s x
    4 pole pairs x 6 mWb): phases a and b never cross, no hand-over, the board trips (FAULT 7
    STALL: the rotor does not follow the drive) and the plan does not pass."""
    profile = tmp_path / "offsets.yaml"
    text = (EXAMPLE / "profiles" / "bldc.yaml").read_text()
    assert "comparator_offset_v: [0.02, -0.015, 0.01]" in text
    profile.write_text(text.replace("comparator_offset_v: [0.02, -0.015, 0.01]",
                                    "comparator_offset_v: [1.5, -1.5, 0.01]"))
    proc, results = hil_run(PLANS / "01_startup.yaml", f"lib:{BUILD / 'libbemf_sixstep.so'}",
                            tmp_path / "out", "--profile", str(profile))
    assert proc.returncode != 0, proc.stdout + proc.stderr
    assert [r["outcome"] for r in results] == ["FAIL"]
    assert "STALL" in results[0]["reason"]
