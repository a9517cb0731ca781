"""The path a user takes (issue 13): the example board of examples/sixstep, written only
against the public headers and SPEC.md, runs its own plans through `hil run` over each link a
user's firmware can take: an executable on a pseudo-terminal (exec:), a shared library with
the firmware ABI (lib:) and a Cortex-M4F image under QEMU (qemu:). And a board that answers
HEARTBEAT but never GATES ends `hil serve` with exit 2 and the cause within 15 s."""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.test_session_policy import write_heartbeat_board

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "sixstep"
PLANS = EXAMPLE / "plans"
BUILD = EXAMPLE / "build"


@pytest.fixture(scope="module", autouse=True)
def built() -> None:
    subprocess.run(["make", "-s", "-C", str(EXAMPLE), "host", "lib", "arm"], check=True,
                   capture_output=True, timeout=300)


def hil_run(plans: Path, link: str, out: Path) -> tuple[subprocess.CompletedProcess, list[dict]]:
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "run", str(plans), "--link", link,
                           "--out", str(out), "--no-progress"], capture_output=True, text=True,
                          timeout=300, cwd=REPO)
    results = [json.loads(p.read_text()) for p in sorted(out.glob("**/result.json"))]
    return proc, results


@pytest.mark.parametrize("link", [f"exec:{BUILD / 'sixstep'}", f"lib:{BUILD / 'libsixstep.so'}"])
def test_example_board_passes_its_plans_over_exec_and_lib(link, tmp_path):
    proc, results = hil_run(PLANS, link, tmp_path / "out")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(results) == len(list(PLANS.glob("*.yaml"))) == 3
    assert all(r["outcome"] == "PASS" for r in results), [(r["plan"], r["reason"]) for r in results]
    assert {r["link"] for r in results} == {link}


def test_example_board_image_passes_its_plans_under_qemu(tmp_path):
    link = f"qemu:{BUILD / 'sixstep.elf'}"
    proc, results = hil_run(PLANS, link, tmp_path / "out")          # about 15 s of QEMU
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [r["outcome"] for r in results] == ["PASS"] * 3
    assert all(r["extra"]["board"].startswith("sixstep") for r in results)


def test_the_example_plans_fail_a_misaligned_encoder(tmp_path):
    """The plans can fail: an encoder mounted a quarter turn off (offset the board is not
    told) makes the board commutate 90 electrical degrees late, and the speed step misses."""
    profile = tmp_path / "misaligned.yaml"
    profile.write_text("sensors:\n  encoder:\n    offset_counts: 1024\n")
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "run", str(PLANS / "01_speed_step.yaml"),
                           "--link", f"exec:{BUILD / 'sixstep'}", "--profile", str(profile),
                           "--out", str(tmp_path / "out"), "--no-progress"],
                          capture_output=True, text=True, timeout=300, cwd=REPO)
    results = [json.loads(p.read_text()) for p in (tmp_path / "out").glob("**/result.json")]
    assert proc.returncode != 0, proc.stdout + proc.stderr
    assert [r["outcome"] for r in results] in (["FAIL"], ["TIMEOUT"])


def test_heartbeat_only_board_ends_hil_serve_with_exit_2_within_15_s(tmp_path):
    board = write_heartbeat_board(tmp_path)
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "serve", "--link", f"exec:{board}",
                           "--enable", "--speed-rpm", "1500", "--modbus", "off", "--duration", "30"],
                          capture_output=True, text=True, timeout=60, cwd=REPO)
    assert time.monotonic() - t0 < 15.0
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "board sent only HEARTBEAT" in proc.stdout + proc.stderr


def _sixstep_step_faults(link: str, periods: int = 400) -> list:
    from hil.session.bench_session import BenchSession, SessionConfig
    from hil.session.board_params import load_bench_profile

    with BenchSession(load_bench_profile(None), SessionConfig(link=link, hold_cpu_latency=False)) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(periods)
        return list(session.faults)


@pytest.mark.parametrize("link", [f"exec:{BUILD / 'sixstep'}?args=--overcurrent-a+1",
                                  f"lib:{BUILD / 'libsixstep.so'}?args=--overcurrent-a%201"])
def test_the_template_takes_args_over_exec_and_lib_alike(link):
    """host/main.c hands its argv to the firmware's hil_fw_configure, as lib: hands args=:
    a 1 A trip level trips the speed step's current; without args the step does not trip."""
    from protocol.messages import FaultCode

    faults = _sixstep_step_faults(link)
    assert [f.code for f in faults][:1] == [FaultCode.OVERCURRENT]
    assert faults[0].value > 1.0
    assert _sixstep_step_faults(link.partition("?")[0]) == []


def test_the_template_refuses_an_argument_it_does_not_know_naming_it():
    from hil.session.bench_session import SessionError

    with pytest.raises(SessionError) as err:
        _sixstep_step_faults(f"exec:{BUILD / 'sixstep'}?args=--overcurrent+5", 1)
    assert "status 2" in str(err.value) and "unknown argument" in str(err.value)
    assert "--overcurrent" in str(err.value)
