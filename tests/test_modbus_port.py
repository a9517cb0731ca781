"""Modbus control port over loopback with a pymodbus client: writes reach the session's
mailbox with the documented scaling, published snapshots read back with it, bad writes
are refused, the server thread stops cleanly; RTU over a socat pseudo-terminal pair."""
from __future__ import annotations

import os
import shutil
import sys
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ModbusException

from hil.ports.modbus import (HOLDING_REGISTERS, INPUT_REGISTERS, REGISTER_MAP_VERSION, ControlMailbox,
                             ControlRequests, ModbusPort, PlantSnapshot, StateBit, register_map_markdown)

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module", params=["thread", "process"])
def running_port(request):
    mailbox = ControlMailbox(load_torque_nm=0.0, dc_link_voltage_v=70.0)
    p = ModbusPort(mailbox, port=0, load_torque_limit_nm=5.0, dc_link_voltage_limit_v=100.0,
                   fault_bits_mask=0x0001_FFFF, speed_ref_limit_rpm=6000.0,
                   isolation=request.param).start()
    yield p
    p.stop()
    assert not p.running


@pytest.fixture
def port(running_port):
    """The module's port with its commanded state back to the initial one, nothing pending."""
    mailbox = running_port.mailbox
    assert mailbox.request(load_torque_nm=0.0, dc_link_voltage_v=70.0, run=False, fault_bits=0,
                           speed_ref_rpm=0.0)
    mailbox.take_requests()
    assert not mailbox.pending
    return running_port


@pytest.fixture
def client(port):
    host, number = port.tcp_address
    c = ModbusTcpClient(host, port=number, timeout=3)
    assert c.connect()
    yield c
    c.close()


def _s16(value: int) -> int:
    return value & 0xFFFF


def test_binds_to_loopback_by_default(port):
    assert port.tcp_address[0] == "127.0.0.1"


def test_nothing_pending_means_none(port):
    assert port.mailbox.pending is False and port.mailbox.take_requests() is None


def test_load_torque_write_reaches_take_requests_scaled(port, client):
    assert not client.write_register(0, _s16(-1234)).isError()
    assert port.mailbox.pending
    assert port.mailbox.take_requests() == ControlRequests(load_torque_nm=-1.234)
    assert port.mailbox.take_requests() is None  # taken once
    assert client.read_holding_registers(0, count=1).registers == [_s16(-1234)]


def test_block_write_of_all_holding_registers(port, client):
    # 0.5 N·m, 71.00 V, run, fault bits 0x0001_0003 (high word first)
    assert not client.write_registers(0, [500, 7100, 1, 0x0001, 0x0003]).isError()
    assert port.mailbox.take_requests() == ControlRequests(0.5, 71.0, True, 0x0001_0003)
    assert client.read_holding_registers(0, count=5).registers == [500, 7100, 1, 1, 3]


def test_speed_reference_is_an_int32_in_hundredths_of_an_rpm(port, client):
    # -2500.5 rpm = -250050 = 0xFFFC_2F3E, high word first (built by hand from the map)
    assert not client.write_registers(5, [0xFFFC, 0x2F3E]).isError()
    assert port.mailbox.take_requests() == ControlRequests(speed_ref_rpm=-2500.5)
    assert client.read_holding_registers(5, count=2).registers == [0xFFFC, 0x2F3E]
    # 6000.01 rpm is over the port's limit: refused, nothing posted
    response = client.write_registers(5, [0x0009, 0x27C1])
    assert response.isError() and response.exception_code == 3
    assert port.mailbox.take_requests() is None


def test_writing_the_current_value_still_counts(port, client):
    """A plan may have changed the load since; writing 0 again must reach the session."""
    assert not client.write_register(0, 0).isError()
    assert port.mailbox.take_requests() == ControlRequests(load_torque_nm=0.0)


def test_latest_write_wins_between_periods(port, client):
    for value in (100, 200, 300):
        client.write_register(0, value)
    client.write_register(2, 1)
    assert port.mailbox.take_requests() == ControlRequests(load_torque_nm=0.3, run=True)


def test_bad_writes_are_refused_with_illegal_value_and_change_nothing(port, client):
    for address, value in ((2, 2), (0, 5001), (0, _s16(-5001)), (1, 10001)):
        response = client.write_register(address, value)
        assert response.isError() and response.exception_code == 3, (address, value)
    response = client.write_registers(3, [0x0002, 0x0000])  # bit 17: outside the mask
    assert response.isError() and response.exception_code == 3
    response = client.write_register(9, 1)  # no such holding register
    assert response.isError() and response.exception_code == 2
    assert port.mailbox.take_requests() is None
    assert client.read_holding_registers(0, count=7).registers == [0, 7000, 0, 0, 0, 0, 0]


def test_coils_are_the_fault_bits(port, client):
    assert not client.write_coil(3, True).isError()
    assert port.mailbox.take_requests() == ControlRequests(fault_bits=0b1000)
    assert not client.write_coils(15, [True, True]).isError()  # bits 15 and 16 span both words
    assert port.mailbox.take_requests() == ControlRequests(fault_bits=0b1000 | 1 << 15 | 1 << 16)
    assert client.read_holding_registers(3, count=2).registers == [0x0001, 0x8008]
    assert client.read_coils(0, count=17).bits[:17] == [i in (3, 15, 16) for i in range(17)]
    assert not client.write_registers(3, [0, 0b1]).isError()
    assert client.read_coils(0, count=8).bits == [True] + [False] * 7
    response = client.write_coil(20, True)  # outside the fault-bit mask
    assert response.isError() and response.exception_code == 3


def test_published_snapshot_reads_back_with_documented_scaling(port, client):
    state = StateBit.RUNNING | StateBit.REAL_TIME | StateBit.FAULT_INJECTED
    port.mailbox.publish(PlantSnapshot(speed_rpm=-1500.25, i_a_a=1.5, i_b_a=-0.75, i_c_a=-0.755, torque_nm=0.1234,
                                       dc_link_voltage_v=69.99, period=0x0001_0002, deadline_misses=70_000,
                                       state=state, load_torque_nm=-0.3, fault_bits=0x0001_0005))
    regs = client.read_input_registers(0, count=16).registers
    assert client.convert_from_registers(regs[0:2], client.DATATYPE.INT32) == -150025  # 0.01 rpm, high word first
    assert regs[0:2] == [0xFFFD, 0xB5F7]
    assert regs[2:5] == [150, _s16(-75), _s16(-76)]  # 0.01 A, rounded to nearest (-75.5 -> -76)
    assert regs[5] == 123 and regs[6] == 6999  # 0.001 N·m, 0.01 V
    assert regs[7:9] == [0x0001, 0x0002]
    assert regs[9:11] == [70_000 >> 16, 70_000 & 0xFFFF]
    assert regs[11] == int(state)
    assert regs[12] == _s16(-300)
    assert regs[13:15] == [0x0001, 0x0005]
    assert regs[15] == REGISTER_MAP_VERSION
    bits = client.read_discrete_inputs(0, count=8).bits
    assert bits[:6] == [True, False, False, True, False, True]
    port.mailbox.publish(PlantSnapshot(0, 0, 0, 0, 0, 70.0, period=5))  # the latest snapshot is served
    assert client.read_input_registers(7, count=2).registers == [0, 5]


def test_out_of_range_values_saturate():
    speed = INPUT_REGISTERS[0]
    current = INPUT_REGISTERS[1]
    assert current.encode(400.0) == [32767] and current.encode(-400.0) == [_s16(-32768)]
    assert speed.decode(speed.encode(-1e12)) == pytest.approx(-(2**31) * 0.01)
    assert current.encode(float("nan")) == [0]
    assert HOLDING_REGISTERS[1].encode(-5.0) == [0]  # unsigned


def test_before_any_publish_inputs_read_zero_and_the_map_version():
    with ModbusPort(ControlMailbox(), port=0) as fresh:
        c = ModbusTcpClient(fresh.tcp_address[0], port=fresh.tcp_address[1], timeout=3)
        assert c.connect()
        try:
            regs = c.read_input_registers(0, count=16).registers
        finally:
            c.close()
    assert regs[:15] == [0] * 15 and regs[15] == REGISTER_MAP_VERSION


def test_mailbox_never_waits_for_a_busy_port():
    """While the port holds the lock, the session's calls return at once and lose nothing."""
    mailbox = ControlMailbox()
    mailbox.request(load_torque_nm=1.5)
    assert mailbox.pending
    snapshot = PlantSnapshot(1.0, 0, 0, 0, 0, 70.0, period=1)
    with mailbox._lock:  # the port mid-write
        assert mailbox.take_requests() is None
        mailbox.publish(snapshot)
    assert mailbox.publishes_skipped == 1 and mailbox.snapshot() is None
    assert mailbox.take_requests() == ControlRequests(load_torque_nm=1.5)
    mailbox.publish(snapshot)
    assert mailbox.snapshot() == snapshot
    assert isinstance(mailbox.snapshot().period, int)
    with pytest.raises(TypeError, match="unknown request field.*speed"):
        mailbox.request(speed=3)


def test_session_thread_and_client_writes_interleave_safely(port, client):
    """A session thread polls once per 'period' while a client writes increasing values:
    it sees an increasing sequence ending with the last value, never a torn one."""
    seen = []
    stop = threading.Event()

    def session():
        while not stop.is_set():
            requests = port.mailbox.take_requests()
            if requests is not None and requests.load_torque_nm is not None:
                seen.append(requests.load_torque_nm)
            port.mailbox.publish(PlantSnapshot(0, 0, 0, 0, 0, 70.0, period=len(seen)))

    thread = threading.Thread(target=session)
    thread.start()
    try:
        for value in range(1, 201):
            assert not client.write_register(0, value).isError()
    finally:
        time.sleep(0.05)
        stop.set()
        thread.join(5)
    assert seen[-1] == pytest.approx(0.2)
    assert all(b > a for a, b in zip(seen, seen[1:]))
    assert {round(v * 1000) for v in seen} <= set(range(1, 201))
    assert all(v == round(v, 3) for v in seen)


@pytest.mark.parametrize("isolation", ["thread", "process"])
def test_stop_is_clean_and_frees_the_port(isolation):
    mailbox = ControlMailbox()
    p = ModbusPort(mailbox, port=0, isolation=isolation).start()
    host, number = p.tcp_address
    worker = p._thread or p._process
    p.stop()
    assert not worker.is_alive() and not p.running
    if isolation == "process":
        assert worker.exitcode == 0  # it stopped by itself, not killed
    p.stop()  # idempotent
    with socket.socket() as s:  # the listening socket is closed
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((host, number))
    with ModbusPort(mailbox, port=number) as again:
        assert again.tcp_address == (host, number)


@pytest.mark.parametrize("isolation", ["thread", "process"])
def test_busy_port_is_a_clear_error(isolation):
    mailbox = ControlMailbox()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        busy = s.getsockname()[1]
        port = ModbusPort(mailbox, port=busy, isolation=isolation)
        with pytest.raises(OSError, match=f"Modbus TCP: cannot listen on 127.0.0.1:{busy}: Address already in use"):
            port.start()
        assert not port.running


def test_rtu_device_id_out_of_range_is_refused():
    for bad in (0, 248, 1.5):
        with pytest.raises(ValueError, match="rtu_device_id .*1..247"):
            ModbusPort(ControlMailbox(), host=None, rtu_port="/dev/null", rtu_device_id=bad)


def test_missing_serial_port_is_a_clear_error():
    with pytest.raises(OSError, match="Modbus RTU: cannot open serial port '/dev/hil-no-such-tty'"):
        ModbusPort(ControlMailbox(), host=None, rtu_port="/dev/hil-no-such-tty").start()


@pytest.mark.skipif(shutil.which("socat") is None, reason="socat makes the pseudo-terminal pair")
def test_rtu_over_a_pseudo_terminal_pair(tmp_path):
    a, b = tmp_path / "bench", tmp_path / "plc"
    socat = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                             stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 5
        while not (a.exists() and b.exists()):
            assert time.monotonic() < deadline, "socat did not create the pty pair"
            time.sleep(0.01)
        mailbox = ControlMailbox()
        with ModbusPort(mailbox, host=None, rtu_port=str(a), rtu_baudrate=115200):
            client = ModbusSerialClient(str(b), baudrate=115200, timeout=2)
            assert client.connect()
            try:
                assert not client.write_register(0, 250, device_id=1).isError()
                assert mailbox.take_requests() == ControlRequests(load_torque_nm=0.25)
                mailbox.publish(PlantSnapshot(1000.0, 1.0, 2.0, 3.0, 0.1, 70.0, period=42))
                regs = client.read_input_registers(0, count=8, device_id=1).registers
                assert regs == [100_000 >> 16, 100_000 & 0xFFFF, 100, 200, 300, 100, 7000, 0]
                client.close()
                # another device's address on the shared line: the bench keeps quiet
                other = ModbusSerialClient(str(b), baudrate=115200, timeout=0.3, retries=0)
                assert other.connect()
                try:
                    try:
                        answered = not other.read_input_registers(0, count=1, device_id=2).isError()
                    except ModbusException:
                        answered = False
                    assert not answered
                    assert not other.read_input_registers(0, count=1, device_id=1).isError()
                finally:
                    other.close()
            finally:
                client.close()
    finally:
        socat.terminate()
        socat.wait(5)


def test_docs_carry_the_register_map_from_the_code():
    assert register_map_markdown() in (REPO / "docs" / "modbus.md").read_text()


_PARENT = """
import os, sys, time
from hil.ports.modbus import ControlMailbox, ModbusPort
if __name__ == "__main__":
    port = ModbusPort(ControlMailbox(), port=0, isolation="process").start()
    print(port._process.pid, port.tcp_address[1], flush=True)
    time.sleep(60)
"""


def test_port_process_exits_when_its_parent_is_killed(tmp_path):
    """No orphan server keeps the port after the bench process dies (SIGKILL included)."""
    script = tmp_path / "parent.py"
    script.write_text(_PARENT)
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        pid, number = map(int, parent.stdout.readline().split())
        parent.kill()
        parent.wait(5)
        deadline = time.monotonic() + 10
        while _alive(pid):
            assert time.monotonic() < deadline, "the port process outlived its parent"
            time.sleep(0.05)
    finally:
        parent.kill()
        parent.wait(5)
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", number))


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except FileNotFoundError:
        return False
