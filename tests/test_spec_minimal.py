"""The minimal board of examples/spec_minimal, written from SPEC.md alone with its state in
globals (Arduino-style): its speed step passes over `lib:`, one `hil run` of two profiles over
one `lib:` library works for both sessions (each gets fresh globals), the link string's args
reach the firmware (lib: and exec: alike), and the protocol duties SPEC.md 2 puts on a board
hold: UNKNOWN for what is not pushed, NaN TELEMETRY for what it does not compute, the same
answer to a resent SAMPLE without a second control step."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from protocol.links import LinkError
from protocol.messages import (Command, ControllerState, Duty, FaultCode, Gates, Hello, ParamGet,
                               ParamId, ParamSet, ParamStatus, ParamValue, Sample, Status, Telemetry)

from hil.links.firmware_library import FirmwareLibraryLink
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from hil.session.board_params import default_board, load_bench_profile
from hil.plans.format import load_plan
from hil.plans.outcome import Outcome
from hil.run.runner import run_plan

REPO = Path(__file__).resolve().parents[1]
BOARD = REPO / "examples" / "spec_minimal"
PLAN = BOARD / "plans" / "01_speed_step.yaml"
LIB = BOARD / "build" / "libspec_minimal.so"
EXE = BOARD / "build" / "spec_minimal"
RAD_S_PER_RPM = 2 * math.pi / 60


@pytest.fixture(scope="module", autouse=True)
def built() -> None:
    subprocess.run(["make", "-s", "-C", str(BOARD), "host", "lib"], check=True,
                   capture_output=True, timeout=300)


def hil_run(out: Path, *extra: str, link: str = f"lib:{LIB}"):
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "run", str(PLAN), "--link", link,
                           "--out", str(out), "--no-progress", *extra],
                          capture_output=True, text=True, timeout=300, cwd=REPO)
    results = [json.loads(p.read_text()) for p in sorted(out.glob("**/result.json"))]
    return proc, results


def test_speed_step_on_the_paper_profile_over_lib(tmp_path):
    proc, results = hil_run(tmp_path / "out", "--profile", "paper")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    [result] = results
    assert result["outcome"] == "PASS", result["reason"]
    assert [c["outcome"] for c in result["checks"]] == ["PASS"] * 4
    assert result["extra"]["board"].startswith("spec-minimal")


def test_one_hil_run_of_two_profiles_over_one_lib_gets_fresh_globals_for_each(tmp_path):
    """The second session reloads the library: with one load per process the board (which
    boots once per load, as a microcontroller does) refused it: hil_fw_create returned NULL."""
    proc, results = hil_run(tmp_path / "out")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(results) == 2
    assert [r["outcome"] for r in results] == ["PASS", "PASS"], [r["reason"] for r in results]
    assert "hil_fw_create returned NULL" not in proc.stdout + proc.stderr


PAPER_PLANS = sorted((REPO / "test_plans").glob("0[1-6]_*.yaml"))


@pytest.mark.parametrize("plan_path", PAPER_PLANS, ids=lambda p: p.stem)
def test_every_paper_plan_on_both_profiles_ends_in_a_verdict_on_a_spec_only_board(plan_path, tmp_path):
    """A board that knows only SPEC's required parameters, no board file: the bench pushes it
    nothing else (no stub tuning), and each plan ends PASS or FAIL on the board's account, never
    ERROR: what it does not compute (EKF, flux) it reports as NaN, and the checks say so."""
    plan = load_plan(plan_path)
    assert [r.label for r in plan.profiles] == ["paper", "paper-hardware"]
    for ref in plan.profiles:
        result, _ = run_plan(plan, link=f"lib:{LIB}", profile=ref, out_dir=tmp_path)
        assert result.outcome in (Outcome.PASS, Outcome.FAIL), (ref.label, result.reason)
        assert result.extra["board_file"]["source"] == "<no board file>"


def _profile():
    # lib: is not a stub link: without a board file only SPEC 8.1's parameters are pushed
    return load_bench_profile(None)


def _speed_step(link: str, periods: int = 1500):
    with BenchSession(_profile(), SessionConfig(link=link, hold_cpu_latency=False)) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(periods)
        return session.recorder.arrays(), list(session.faults)


@pytest.mark.parametrize("link", [f"lib:{LIB}?args=--overcurrent-a%205", f"exec:{EXE}?args=--overcurrent-a+5"])
def test_args_reach_the_firmware_over_lib_and_exec(link):
    """The 12 A q-current limit of the speed step trips a 5 A overcurrent level given as args."""
    _, faults = _speed_step(link, 200)
    assert [f.code for f in faults] == [FaultCode.OVERCURRENT]
    assert 5.0 < faults[0].value < 6.0


def test_without_args_the_same_step_does_not_trip():
    _, faults = _speed_step(f"lib:{LIB}", 200)
    assert faults == []


def test_exec_and_lib_are_the_same_board_bit_for_bit():
    a, _ = _speed_step(f"exec:{EXE}", 400)
    b, _ = _speed_step(f"lib:{LIB}", 400)
    np.testing.assert_array_equal(a["plant.i_a"][1], b["plant.i_a"][1])
    assert np.ptp(a["plant.i_a"][1]) > 2.0         # it did drive current


def test_arguments_it_does_not_know_are_refused_naming_them():
    with pytest.raises((LinkError, SessionError)) as err:
        _speed_step(f"lib:{LIB}?args=--overcurrent 5", 1)
    text = str(err.value)
    assert f"firmware library '{LIB}'" in text and "unknown argument" in text and "--overcurrent" in text
    with pytest.raises(SessionError) as err:
        _speed_step(f"exec:{EXE}?args=--overcurrent-a+lots", 1)
    assert "status 2" in str(err.value) and "--overcurrent-a wants a current in A" in str(err.value)


def test_a_parameter_that_is_not_pushed_ends_the_session_unknown():
    # a board file that pushes torque_limit_nm, which this board does not know
    board = default_board(f"lib:{LIB}").with_settings({"torque_limit_nm": 2.0})
    with pytest.raises(SessionError, match=r"does not know parameter torque_limit_nm \(id 23, status 1"):
        with BenchSession(load_bench_profile(), SessionConfig(link=f"lib:{LIB}", hold_cpu_latency=False,
                                                              board=board)):
            pass


# ---- the protocol, frame by frame, on the library ------------------------------------------

def _exchange(link: FirmwareLibraryLink, msg) -> list:
    link.send(msg)
    got = []
    while (m := link.recv(0.0)) is not None:
        got.append(m)
    return got


def _started(speed_ref_rad_s: float = 100.0) -> FirmwareLibraryLink:
    link = FirmwareLibraryLink(LIB)
    [hello] = _exchange(link, Hello(1, 0, 0, 50_000, name="bench"))
    assert (hello.role, hello.capabilities, hello.control_period_ns) == (1, 0x0002 | 0x0004, 0)
    assert _exchange(link, ParamSet(ParamId.TELEMETRY_DIVIDER, 1.0)) == [
        ParamValue(ParamId.TELEMETRY_DIVIDER, ParamStatus.OK, 1.0)]
    [status] = _exchange(link, Command(1, 0, speed_ref_rad_s, 0.0, 0.0))
    assert isinstance(status, Status) and status.state == ControllerState.RUNNING
    return link


def _sample(k: int) -> Sample:
    # 3 A on phase a, -1 A on b; 70 V; the rotor turning forwards a count a period
    return Sample(k, 2048 + 246, 2048 - 82, 2867, 10 + k, 0)


def test_only_the_pushed_parameters_are_known():
    link = FirmwareLibraryLink(LIB)
    try:
        pushed = [ParamId.CONTROL_PERIOD_S, ParamId.CURRENT_A_PER_COUNT, ParamId.CURRENT_OFFSET_COUNTS,
                  ParamId.CURRENT_PHASES, ParamId.VDC_V_PER_COUNT, ParamId.VDC_OFFSET_COUNTS,
                  ParamId.ENCODER_COUNTS_PER_REV, ParamId.POLE_PAIRS, ParamId.TELEMETRY_DIVIDER]
        for pid in ParamId:
            [answer] = _exchange(link, ParamGet(pid))
            want = ParamStatus.OK if pid in pushed else ParamStatus.UNKNOWN
            assert (answer.id, answer.status) == (pid, want), pid.name
            if pid not in pushed:
                assert answer.value == 0.0
                [answer] = _exchange(link, ParamSet(pid, 1.0))
                assert (answer.status, answer.value) == (ParamStatus.UNKNOWN, 0.0), pid.name
        [answer] = _exchange(link, ParamSet(ParamId.POLE_PAIRS, float("nan")))
        assert (answer.status, answer.value) == (ParamStatus.OUT_OF_RANGE, 1.0)
    finally:
        link.close()


def test_a_resent_sample_gets_the_same_answer_and_no_second_control_step():
    once, twice = _started(), _started()
    try:
        first = _exchange(once, _sample(0))
        assert isinstance(first[0], Duty) and first[0].period == 0
        assert _exchange(twice, _sample(0))[0] == first[0]
        assert _exchange(twice, _sample(0)) == [first[0]]          # the resend: the same DUTY
        after_once, after_twice = _exchange(once, _sample(1)), _exchange(twice, _sample(1))
        assert after_once[0] == after_twice[0]                     # its integrators moved once
    finally:
        once.close()
        twice.close()


def test_telemetry_is_nan_where_the_board_computes_nothing():
    link = _started()
    try:
        answer, telemetry = _exchange(link, _sample(0))
        assert isinstance(telemetry, Telemetry) and telemetry.period == 0
        for name in ("speed_raw_rad_s", "speed_lpf_rad_s", "speed_ekf_rad_s", "flux_angle_rad",
                     "ekf_angle_rad", "flux_mag_wb", "rotor_pos_conv_rad", "rotor_pos_ekf_rad"):
            assert math.isnan(getattr(telemetry, name)), name
        for name in ("speed_feedback_rad_s", "speed_encoder_rad_s", "torque_est_nm", "torque_ref_nm"):
            assert math.isfinite(getattr(telemetry, name)), name
        assert (telemetry.sector, telemetry.gates, telemetry.state) == (0, 0, ControllerState.RUNNING)
        # disabled, the bridge is open: GATES 0 (DUTY cannot open a leg)
        [status] = _exchange(link, Command(0, 0, 0.0, 0.0, 0.0))
        assert status.state == ControllerState.IDLE
        assert _exchange(link, _sample(1))[0] == Gates(1, 0)
    finally:
        link.close()


def test_a_session_on_the_board_built_with_asan_and_ubsan():
    """The executable built with -fsanitize=address,undefined (no recovery: any report ends
    it, and the bench names its exit status and stderr) runs a speed step and a trip."""
    subprocess.run(["make", "-s", "-C", str(BOARD), "build/spec_minimal.san"], check=True,
                   capture_output=True, timeout=300)
    arrays, faults = _speed_step(f"exec:{BOARD / 'build' / 'spec_minimal.san'}?args=--overcurrent-a+5", 300)
    assert [f.code for f in faults] == [FaultCode.OVERCURRENT]
    assert len(arrays["plant.i_a"][1]) == 300


def test_torque_mode_is_followed_clamped_and_other_speed_sources_refused():
    link = _started()
    try:
        _exchange(link, Command(1 | 2, 0, 0.0, 0.5, 0.0))           # torque mode, 0.5 Nm
        _, telemetry = _exchange(link, _sample(0))
        assert telemetry.torque_ref_nm == pytest.approx(0.5)
        _exchange(link, Command(1 | 2, 0, 0.0, 9.0, 0.0))           # clamped to 12 A x 0.1392 Nm/A
        _, telemetry = _exchange(link, _sample(1))
        assert telemetry.torque_ref_nm == pytest.approx(1.5 * 0.0928 * 12.0, rel=1e-6)
        fault, status = _exchange(link, Command(1, 2, 100.0, 0.0, 0.0))  # EKF: no estimator
        assert (fault.code, fault.value) == (FaultCode.PROTOCOL, 2.0)
        assert (status.state, status.fault_code) == (ControllerState.FAULT, FaultCode.PROTOCOL)
        assert _exchange(link, _sample(2))[0] == Gates(2, 0)
    finally:
        link.close()
