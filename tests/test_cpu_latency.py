"""The CPU-latency hold: what it writes, that it lets go, and how a session uses it."""
from __future__ import annotations

import os
import struct

from plant_rt import load_profile

from hil.session.cpu_latency import CpuLatencyHold
from hil.session.bench_session import BenchSession, SessionConfig


def test_hold_writes_the_latency_and_releases_it(tmp_path, monkeypatch):
    device = tmp_path / "cpu_dma_latency"   # a regular file stands in for the device
    device.write_bytes(b"")
    monkeypatch.setattr(CpuLatencyHold, "PATH", str(device))
    with CpuLatencyHold(latency_us=7) as hold:
        assert hold.status == "held at 7 us"
        fd = hold.fd
        assert fd is not None and os.fstat(fd).st_ino == device.stat().st_ino
        assert struct.unpack("<i", device.read_bytes()) == (7,)
    assert hold.fd is None
    try:
        os.fstat(fd)
        raise AssertionError("the descriptor (the kernel's request) must be closed")
    except OSError:
        pass


def test_hold_where_the_os_refuses_is_recorded_not_fatal(tmp_path, monkeypatch):
    monkeypatch.setattr(CpuLatencyHold, "PATH", str(tmp_path / "missing" / "cpu_dma_latency"))
    with CpuLatencyHold() as hold:
        assert hold.fd is None
        assert hold.status.startswith("not available (")
        assert "missing/cpu_dma_latency" in hold.status


def test_sessions_over_a_process_link_hold_it_and_let_go(tmp_path, monkeypatch):
    device = tmp_path / "cpu_dma_latency"
    device.write_bytes(b"")
    monkeypatch.setattr(CpuLatencyHold, "PATH", str(device))
    with BenchSession(load_profile(), SessionConfig(link="stub")) as in_process:
        assert in_process.cpu_latency.fd is None       # never waits: no hold
    with BenchSession(load_profile(), SessionConfig(link="stub-pty")) as session:
        assert session.cpu_latency.status == "held at 0 us"
        assert session._metadata()["bench"]["cpu_dma_latency"] == "held at 0 us"
        session.run_periods(10)
    assert session.cpu_latency.fd is None
    with BenchSession(load_profile(), SessionConfig(link="stub-pty", hold_cpu_latency=False)) as off:
        assert off.cpu_latency.fd is None and off.cpu_latency.status == "not requested"
