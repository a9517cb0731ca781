"""The hil-stub executable over its three transports: a pseudo-terminal (pyserial,
through protocol.links), SLCAN driven by python-can's own `slcan` interface, and
stdin/stdout. Each run checks the handshake (HELLO), a PARAM round trip and GATES
answers to SAMPLEs, and that the process exits cleanly."""
from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from hil.links.stub_library import EXECUTABLE_PATH, STUB_DIR
from protocol.codec import FrameEncoder, StreamDecoder
from protocol.links import open_link
from protocol.messages import (Command, Gates, Hello, ParamGet, ParamId, ParamSet, ParamValue, Role,
                               Sample, Shutdown, Status, Telemetry)

pytestmark = pytest.mark.skipif(shutil.which("socat") is None, reason="socat makes the pty pairs")


@pytest.fixture(scope="module", autouse=True)
def built() -> None:
    subprocess.run(["make", "-s", "-C", str(STUB_DIR)], check=True, capture_output=True)


class PtyPair:
    """Two linked pseudo-terminals (socat): the stub opens one path, the bench the other."""

    def __init__(self, tmp: Path) -> None:
        self.stub_path = str(tmp / "stub")
        self.bench_path = str(tmp / "bench")
        self.proc = subprocess.Popen(
            ["socat", f"PTY,raw,echo=0,link={self.stub_path}", f"PTY,raw,echo=0,link={self.bench_path}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 10.0
        while not (os.path.exists(self.stub_path) and os.path.exists(self.bench_path)):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"socat did not create the ptys: {self.proc.stderr.read().decode()}")
            time.sleep(0.01)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait(timeout=10)


@pytest.fixture
def ptys(tmp_path):
    pair = PtyPair(tmp_path)
    yield pair
    pair.close()


def spawn(*args: str) -> subprocess.Popen:
    return subprocess.Popen([str(EXECUTABLE_PATH), *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def reap(proc: subprocess.Popen, timeout: float = 10.0) -> int:
    try:
        return proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def expect(link, kind, timeout_s: float = 5.0, where=lambda m: True):
    """The next message of a type (others skipped), or a failure naming what came instead."""
    deadline = time.monotonic() + timeout_s
    seen = []
    while time.monotonic() < deadline:
        msg = link.recv(max(0.0, deadline - time.monotonic()))
        if msg is None:
            break
        if isinstance(msg, kind) and where(msg):
            return msg
        seen.append(type(msg).__name__)
    pytest.fail(f"no {kind.__name__} within {timeout_s} s; got {seen}")


def session(link, samples: int = 12) -> dict:
    """HELLO, a PARAM round trip, COMMAND, SAMPLEs: returns what came back."""
    link.send(Hello(1, int(Role.BENCH), 0, 50_000, 9, b"hil-bench"))
    hello = expect(link, Hello)
    link.send(ParamSet(int(ParamId.TORQUE_LIMIT_NM), 1.25))
    set_answer = expect(link, ParamValue)
    link.send(ParamGet(int(ParamId.TORQUE_LIMIT_NM)))
    get_answer = expect(link, ParamValue)
    link.send(Command(1, 2, 100.0, 0.0, 0.0))
    status = expect(link, Status)
    gates = []
    telemetry = []
    for k in range(samples):
        link.send(Sample(k, 2048, 2048, 2867, 0, 0))
        gates.append(expect(link, Gates))
        if k % 10 == 0:
            telemetry.append(expect(link, Telemetry))
    return dict(hello=hello, set=set_answer, get=get_answer, status=status, gates=gates, telemetry=telemetry)


def check_session(r: dict) -> None:
    hello = r["hello"]
    assert hello.proto_version == 1 and hello.role == int(Role.CONTROLLER)
    assert hello.name_str.startswith("hil-stub 0.1 ") and hello.name_len <= 40
    assert hello.control_period_ns == 50_000
    assert (r["set"].id, r["set"].status, r["set"].value) == (int(ParamId.TORQUE_LIMIT_NM), 0, 1.25)
    assert (r["get"].status, r["get"].value) == (0, 1.25)
    assert r["status"].state == 1
    assert [g.period for g in r["gates"]] == list(range(len(r["gates"])))
    assert all(g.gates in (0x25, 0x15, 0x19, 0x1A, 0x2A, 0x26) for g in r["gates"])  # active vectors
    assert [t.period for t in r["telemetry"]] == list(range(0, len(r["gates"]), 10))
    assert all(t.torque_ref_nm == 1.25 for t in r["telemetry"])  # the new limit is in force


def test_serial_pty_session_and_shutdown(ptys):
    stub = spawn("--serial", ptys.stub_path)
    try:
        link = open_link(f"serial:{ptys.bench_path}")
        try:
            check_session(session(link))
            # idle: blocked in poll, not spinning
            time.sleep(0.5)
            assert cpu_seconds(stub.pid) < 0.2
            link.send(Shutdown())
            assert expect(link, Status).state == 0
        finally:
            link.close()
        assert reap(stub) == 0
    finally:
        reap(stub, 0)


def test_serial_pty_exits_on_hangup(ptys):
    stub = spawn("--serial", ptys.stub_path)
    link = open_link(f"serial:{ptys.bench_path}")
    link.send(Hello(1, 0, 0, 50_000, 0, b""))
    expect(link, Hello)
    link.close()
    ptys.close()  # the far end goes away: the stub sees the hang-up
    assert reap(stub) == 0


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_slcan_python_can_session(ptys):
    stub = spawn("--slcan", ptys.stub_path)
    try:
        link = open_link(f"can:slcan:{ptys.bench_path}?bitrate=1000000", sleep_after_open=0)
        try:
            r = session(link)
            check_session(r)
            # GATES came on the controller's identifier for GATES, one 5-byte frame each
            assert link.counters["sequence_errors"] == 0
            link.send(Shutdown())
            assert expect(link, Status).state == 0
        finally:
            link.close()
        assert reap(stub) == 0
    finally:
        reap(stub, 0)


def test_slcan_other_base_id(ptys):
    stub = spawn("--slcan", ptys.stub_path, "--can-base", "0x200")
    try:
        link = open_link(f"can:slcan:{ptys.bench_path}?base_id=0x200", sleep_after_open=0)
        try:
            link.send(Hello(1, 0, 0, 50_000, 0, b""))
            assert expect(link, Hello).role == 1
        finally:
            link.close()
    finally:
        stub.terminate()
        reap(stub)


def test_slcan_adapter_commands(ptys):
    """The Lawicel commands a USB-CAN tool sends, answered as an adapter would."""
    import serial

    stub = spawn("--slcan", ptys.stub_path)
    try:
        port = serial.Serial(ptys.bench_path, timeout=2.0)
        try:
            def ask(cmd: bytes) -> bytes:
                port.write(cmd + b"\r")
                out = b""
                while not out.endswith((b"\r", b"\a")):
                    c = port.read(1)
                    assert c, f"no answer to {cmd!r} (got {out!r})"
                    out += c
                return out

            assert ask(b"V") == b"V1013\r"
            assert ask(b"N") == b"NHIL1\r"
            assert ask(b"S8") == b"\r"
            assert ask(b"t1010") == b"\a"          # not open yet
            assert ask(b"O") == b"\r"
            assert ask(b"F") == b"F00\r"
            assert ask(b"S6") == b"\a"             # bit rate only while closed
            assert ask(b"Q") == b"\a"              # unknown command
            assert ask(b"T123456780") == b"Z\r"   # extended frame: acknowledged, not ours
            # HEARTBEAT (single frame, id 0x10C) -> ack, then the stub's HEARTBEAT on 0x12C
            assert ask(b"t10C40A000000") == b"z\r"
            line = b""
            while not line.endswith(b"\r"):
                line += port.read(1)
            assert line == b"t12C400000000\r"
            assert ask(b"C") == b"\r"
        finally:
            port.close()
    finally:
        stub.terminate()
        reap(stub)


def test_stdio_session_and_eof():
    stub = subprocess.Popen([str(EXECUTABLE_PATH), "--stdio"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    enc = FrameEncoder()
    msgs = [Hello(1, 0, 0, 50_000, 0, b""), ParamGet(int(ParamId.OVERCURRENT_A))]
    msgs += [Sample(k, 2048, 2048, 2867, 0, 0) for k in range(3)]
    out, err = stub.communicate(b"".join(enc.encode(m) for m in msgs), timeout=10)
    assert stub.returncode == 0, err.decode()
    got = StreamDecoder().feed(out)
    kinds = [type(m).__name__ for m in got]
    assert kinds == ["Hello", "ParamValue", "Gates", "Telemetry", "Gates", "Gates"]
    assert got[1].value == 20.0
    assert [m.gates for m in got if isinstance(m, Gates)] == [0, 0, 0]  # not enabled


def test_stdio_non_blocking_input_waits_for_frames():
    """The stub blocks in read() between frames; handed a non-blocking stdin (read() gives
    EAGAIN) it waits in poll() instead, neither exiting nor losing the frames that come later."""
    r, w = os.pipe()
    os.set_blocking(r, False)
    stub = subprocess.Popen([str(EXECUTABLE_PATH), "--stdio"], stdin=r, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    os.close(r)
    try:
        time.sleep(0.2)                     # the stub finds nothing to read yet
        assert stub.poll() is None
        enc = FrameEncoder()
        os.write(w, enc.encode(Hello(1, 0, 0, 50_000, 0, b"")))
        time.sleep(0.1)
        os.write(w, b"".join(enc.encode(Sample(k, 2048, 2048, 2867, 0, 0)) for k in range(3)))
    finally:
        os.close(w)                         # end of file: the stub exits 0
    out, err = stub.communicate(timeout=10)
    assert stub.returncode == 0, err.decode()
    got = StreamDecoder().feed(out)
    assert [type(m).__name__ for m in got] == ["Hello", "Gates", "Telemetry", "Gates", "Gates"]


def test_usage_errors_name_the_argument():
    r = subprocess.run([str(EXECUTABLE_PATH), "--can-base", "0x7F0", "--stdio"], capture_output=True, text=True)
    assert r.returncode == 2 and "--can-base 0x7F0" in r.stderr
    r = subprocess.run([str(EXECUTABLE_PATH), "--serial", "/nonexistent/tty"], capture_output=True, text=True)
    assert r.returncode == 1 and "/nonexistent/tty" in r.stderr
    r = subprocess.run([str(EXECUTABLE_PATH)], capture_output=True, text=True)
    assert r.returncode == 2 and "exactly one of" in r.stderr
    r = subprocess.run([str(EXECUTABLE_PATH), "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.startswith("hil-stub 0.1 ")
