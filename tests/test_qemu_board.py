"""The Cortex-M4F port under QEMU (firmware_stub/boards/mps2_an386, hil/links/qemu.py).

Each test boots QEMU once and stays within a few seconds; QEMU must be gone
after every test, whatever the test body did.
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import time

import pytest
import serial

from hil.links import qemu as qemu_board
from hil.links.qemu import BOARD_DIR, ECHO_ELF, FIRMWARE_ELF, QemuBoard, QemuBoardError, rotating_samples
from protocol.links import open_link
from protocol.messages import (CMD_ENABLE, PROTOCOL_VERSION, Command, ControllerState, Gates, Hello, ParamGet,
                               ParamId, ParamSet, ParamStatus, ParamValue, Role, Sample, Shutdown,
                               SpeedSource, Status, Telemetry)

pytestmark = pytest.mark.skipif(
    shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None,
    reason="needs qemu-system-arm and arm-none-eabi-gcc (Debian: sudo apt-get install -y "
           "qemu-system-arm gcc-arm-none-eabi libnewlib-arm-none-eabi; scripts/bootstrap.sh does it)")

FASTMATH_ELF = BOARD_DIR / "build" / "fastmath_check.elf"
FPU_OFF_ELF = BOARD_DIR / "build" / "fpu_off_check.elf"


def _gone(pid: int) -> bool:
    """True when neither the process nor anything in its process group is left."""
    try:
        os.kill(pid, 0)
        return False
    except ProcessLookupError:
        pass
    try:
        os.killpg(pid, 0)
        return False
    except ProcessLookupError:
        return True


def _read_exactly(port: serial.SerialBase, count: int, timeout_s: float = 5.0) -> bytes:
    data = b""
    deadline = time.monotonic() + timeout_s
    while len(data) < count and time.monotonic() < deadline:
        data += port.read(count - len(data))
    return data


def _run_to_exit(elf, timeout_s: float = 20.0) -> tuple[int | None, bytes]:
    """Runs a check firmware that prints its result and exits QEMU itself; returns
    QEMU's exit status and everything printed. A plain socket, read to EOF:
    pyserial drops the bytes of a read() that ends in a disconnect."""
    with QemuBoard(elf) as board:
        with socket.create_connection(("127.0.0.1", board.port), timeout=timeout_s) as sock:
            out = b""
            while chunk := sock.recv(4096):
                out += chunk
        code = board.wait_exit(timeout_s=5.0)
    return code, out


# -- the chain: startup, FPU, vector table, interrupt-driven UART, QEMU chardev, socket ------
def test_echo_firmware_returns_every_byte_value_unchanged():
    with QemuBoard(ECHO_ELF) as board:
        assert re.fullmatch(r"socket://127\.0\.0\.1:\d+", board.serial_url)
        assert board.link_url == "serial:" + board.serial_url
        port = serial.serial_for_url(board.serial_url, timeout=0.5)
        try:
            # nothing the firmware printed at boot is lost: QEMU waited for us (wait=on)
            assert _read_exactly(port, 11) == b"echo ready\n"
            # 0x00 is the frame delimiter and 0x01 the byte -nographic's monitor mux eats
            payload = bytes(range(256)) * 2
            port.write(payload)
            assert _read_exactly(port, len(payload)) == payload
        finally:
            port.close()
        board.check_alive()


def test_float_code_without_fpu_enable_faults_and_qemu_reports_it():
    """Proves the CPACR write in startup.S is what keeps the echo firmware alive,
    and that a firmware fault ends QEMU with status 3, which QemuBoard names."""
    code, _ = _run_to_exit(FPU_OFF_ELF, timeout_s=2.0)
    assert code == 3


def test_fast_trig_meets_its_stated_bounds_on_target():
    header = (BOARD_DIR.parent.parent / "core" / "fastmath.h").read_text()
    bounds = {name: float(value.rstrip("f")) for name, value in
              re.findall(r"#define FM_(SINCOS|ATAN2)_MAX_ERR\s+(\S+)", header)}
    code, out = _run_to_exit(FASTMATH_ELF)
    assert code == 0, out
    m = re.search(rb"FASTMATH n=(\d+) sincos=([0-9a-f]{8}) atan2=([0-9a-f]{8})", out)
    assert m, out
    sincos_err, atan2_err = (struct.unpack(">f", bytes.fromhex(m.group(i).decode()))[0] for i in (2, 3))
    assert int(m.group(1)) > 30000
    # non-zero: the polynomials are approximations, a zero would mean nothing was compared
    assert 0.0 < sincos_err <= bounds["SINCOS"], (sincos_err, bounds)
    assert 0.0 < atan2_err <= bounds["ATAN2"], (atan2_err, bounds)


# -- the controller firmware over the protocol -------------------------------------------------
REPLY_TIMEOUT_S = 5.0


def _exchange(link, msg, answer_type):
    """Sends msg; returns every message received up to and including the first answer_type."""
    link.send(msg)
    got = []
    while True:
        reply = link.recv(REPLY_TIMEOUT_S)
        assert reply is not None, f"no {answer_type.__name__} within {REPLY_TIMEOUT_S} s after {msg}"
        got.append(reply)
        if isinstance(reply, answer_type):
            return got


def _hello():
    return Hello(PROTOCOL_VERSION, Role.BENCH, 0, 50_000, name=b"pytest")


def _gates_legal(gates: int) -> bool:
    """No leg with both switches on (shoot-through)."""
    return all((gates >> (2 * leg)) & 0b11 != 0b11 for leg in range(3))


def test_firmware_answers_hello_with_its_build():
    with QemuBoard() as board:
        with open_link(board.link_url) as link:
            hello = _exchange(link, _hello(), Hello)[-1]
    assert hello.role == Role.CONTROLLER
    assert hello.proto_version == PROTOCOL_VERSION
    words = hello.name_str.split()
    gcc_major = subprocess.run(["arm-none-eabi-gcc", "-dumpversion"], capture_output=True, text=True,
                               check=True).stdout.split(".")[0]
    # target (Cortex-M4F on mps2-an386), the compiler that built it, the flags that shape the code
    for part in ("cm4f", "an386", f"gcc{gcc_major}", "-O2", "hard"):
        assert part in words, (part, words)


def test_param_round_trip_and_read_only_step_cycles():
    with QemuBoard() as board, open_link(board.link_url) as link:
        _exchange(link, _hello(), Hello)
        set_answer = _exchange(link, ParamSet(ParamId.SPEED_KP_NM_PER_RAD_S, 0.125), ParamValue)[-1]
        get_answer = _exchange(link, ParamGet(ParamId.SPEED_KP_NM_PER_RAD_S), ParamValue)[-1]
        cycles_set = _exchange(link, ParamSet(ParamId.CONTROL_STEP_CYCLES, 1.0), ParamValue)[-1]
        unknown = _exchange(link, ParamGet(999), ParamValue)[-1]
    assert set_answer == ParamValue(ParamId.SPEED_KP_NM_PER_RAD_S, ParamStatus.OK, 0.125)
    assert get_answer == ParamValue(ParamId.SPEED_KP_NM_PER_RAD_S, ParamStatus.OK, 0.125)
    assert cycles_set.status == ParamStatus.READ_ONLY
    assert unknown.status == ParamStatus.UNKNOWN


def test_every_sample_answered_by_gates_and_shutdown_stops_switching():
    with QemuBoard() as board, open_link(board.link_url) as link:
        _exchange(link, _hello(), Hello)
        _exchange(link, Command(CMD_ENABLE, SpeedSource.EKF, 100.0, 0.0, 0.0), Status)
        answers = [_exchange(link, sample, Gates)[-1] for sample in rotating_samples(200)]
        (status,) = [m for m in _exchange(link, Shutdown(), Status) if isinstance(m, Status)]
        after = _exchange(link, Sample(200, 2048, 2048, 2900, 0, 0), Gates)[-1]
        board.check_alive()
    assert [g.period for g in answers] == list(range(200))
    assert all(_gates_legal(g.gates) for g in answers)
    assert len({g.gates for g in answers}) > 2  # it switches between vectors
    assert status.state == ControllerState.IDLE
    assert after.gates == 0


def test_target_answers_bit_identical_to_the_host_build():
    """The same byte stream into the host library (x86-64) and into the Cortex-M4F
    under QEMU gives the same GATES and TELEMETRY, float for float. Expected: both
    build the same C with -std=c99 (no fused multiply-add contraction), IEEE-754
    single precision on both FPUs, no libm call in the step. A difference here
    means the targets round differently, and plan-level comparisons of host and
    target runs then need a tolerance instead of equality."""
    from hil.links.stub_library import StubLibraryLink

    def script():
        yield ParamSet(ParamId.TELEMETRY_DIVIDER, 1.0), ParamValue
        yield Command(CMD_ENABLE, SpeedSource.EKF, 50.0, 0.0, 0.0), Status
        for sample in rotating_samples(300):
            yield sample, Gates

    def run(link):
        return [_exchange(link, msg, answer) for msg, answer in script()]

    with StubLibraryLink() as host_link:
        host = run(host_link)
    with QemuBoard() as board, open_link(board.link_url) as link:
        target = run(link)
    assert sum(isinstance(m, Telemetry) for step in target for m in step) >= 299
    mismatches = [(k, h, t) for k, (h, t) in enumerate(zip(host, target)) if h != t]
    assert not mismatches, mismatches[:3]


def _return_addresses_of_calls(elf, callee: str) -> set[int]:
    """Addresses after each `bl <callee>` in the firmware: where the step returns to
    (the compiler may emit more than one call site)."""
    dump = subprocess.run(["arm-none-eabi-objdump", "-d", str(elf)], capture_output=True, text=True,
                          check=True).stdout
    calls = re.findall(rf"^\s*([0-9a-f]+):\s+[0-9a-f]{{4}} [0-9a-f]{{4}}\s+bl\s+[0-9a-f]+ <{callee}>", dump, re.M)
    assert calls, f"no call to {callee} in {elf}"
    return {int(address, 16) + 4 for address in calls}


def test_step_cycles_equal_the_instructions_qemu_executes(tmp_path):
    """HIL_PARAM_CONTROL_STEP_CYCLES (SysTick, calibrated against icount) against an
    independent count: QEMU's own trace of every executed instruction (-singlestep
    -d exec) from the entry of ctl_step to its return. The measured window also
    holds the call's argument set-up and the counter's return path: a few
    instructions more, the same on every step."""
    log = tmp_path / "exec.log"
    with QemuBoard(extra_args=["-singlestep", "-d", "exec,nochain", "-D", str(log)]) as board, \
            open_link(board.link_url) as link:
        _exchange(link, _hello(), Hello)
        _exchange(link, Command(CMD_ENABLE, SpeedSource.EKF, 100.0, 0.0, 0.0), Status)
        reported = []
        for sample in rotating_samples(6):
            _exchange(link, sample, Gates)
            value = _exchange(link, ParamGet(ParamId.CONTROL_STEP_CYCLES), ParamValue)[-1]
            assert value.status == ParamStatus.OK
            reported.append(int(value.value))
    entry = int(subprocess.run(["arm-none-eabi-nm", str(FIRMWARE_ELF)], capture_output=True, text=True,
                               check=True).stdout.split(" T ctl_step")[0].split()[-1], 16)
    back = _return_addresses_of_calls(FIRMWARE_ELF, "ctl_step")
    pcs = [int(m, 16) for m in re.findall(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/", log.read_text(), re.M)]
    traced = []
    i = 0
    while i < len(pcs):
        if pcs[i] == entry:
            j = next(k for k in range(i, len(pcs)) if pcs[k] in back)
            traced.append(j - i)
            i = j
        i += 1
    assert len(traced) == len(reported)
    overheads = {r - t for r, t in zip(reported, traced)}
    # A few instructions of set-up and return path, within one or two of each other: since
    # the compensation paths went out of line (issue 15), ctl_step has more than one
    # epilogue, and the first step (start-up tracking) leaves by another one.
    assert max(overheads) - min(overheads) <= 2 and 0 <= min(overheads) <= 16, \
        (reported, traced, overheads)
    assert min(reported) > 200


# -- QEMU is always stopped --------------------------------------------------------------------
def test_qemu_stopped_when_the_body_raises():
    with pytest.raises(RuntimeError, match="body failed"):
        with QemuBoard(ECHO_ELF) as board:
            pid = board.pid
            port = serial.serial_for_url(board.serial_url, timeout=0.5)
            assert _read_exactly(port, 11) == b"echo ready\n"
            raise RuntimeError("body failed")
    port.close()
    assert _gone(pid)


def test_qemu_stopped_while_still_waiting_for_its_first_client():
    with QemuBoard(ECHO_ELF) as board:
        pid = board.pid
        assert board.returncode is None
    assert _gone(pid)


def test_qemu_stopped_when_the_board_object_is_dropped_without_exit():
    board = QemuBoard(ECHO_ELF)
    board.start()
    pid = board.pid
    del board  # the weakref finalizer kills the process group
    deadline = time.monotonic() + 5.0
    while not _gone(pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert _gone(pid)


def test_qemu_killed_with_the_python_process():
    """A Python process SIGKILLed mid-run cannot reach __exit__: QEMU must die with it."""
    script = ("import sys, time\n"
              "from hil.links.qemu import QemuBoard, ECHO_ELF\n"
              "b = QemuBoard(ECHO_ELF, build=False); b.start()\n"
              "print(b.pid, flush=True); time.sleep(60)\n")
    child = subprocess.Popen([os.sys.executable, "-c", script], stdout=subprocess.PIPE,
                             cwd=BOARD_DIR.parent.parent.parent, text=True)
    try:
        qemu_pid = int(child.stdout.readline())
        assert not _gone(qemu_pid)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    deadline = time.monotonic() + 5.0
    while not _gone(qemu_pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    survived = not _gone(qemu_pid)
    if survived:  # do not leave it behind for the next tests
        os.killpg(qemu_pid, signal.SIGKILL)
    assert not survived


# -- errors name the Debian package ------------------------------------------------------------
def test_missing_qemu_names_the_debian_package(monkeypatch):
    real_which = shutil.which
    monkeypatch.setattr(qemu_board.shutil, "which",
                        lambda name: None if name == "qemu-system-arm" else real_which(name))
    with pytest.raises(QemuBoardError, match=r"apt-get install -y qemu-system-arm"):
        QemuBoard(ECHO_ELF).start()


def test_missing_cross_compiler_names_the_debian_packages(monkeypatch):
    real_which = shutil.which
    monkeypatch.setattr(qemu_board.shutil, "which",
                        lambda name: None if name == "arm-none-eabi-gcc" else real_which(name))
    with pytest.raises(QemuBoardError,
                       match=r"apt-get install -y gcc-arm-none-eabi libnewlib-arm-none-eabi"):
        QemuBoard(ECHO_ELF, build=True).start()


def test_firmware_not_built_by_the_board_makefile_is_refused(tmp_path):
    with pytest.raises(QemuBoardError, match="not built by"):
        QemuBoard(tmp_path / "other.elf", build=True).start()
