"""Bench sessions end to end: the plant, the stub firmware on a link, the clock and the log."""
from __future__ import annotations

import json
import os
import signal
import socket

import jsonschema
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from plant_rt import load_profile
from protocol.messages import PROTOCOL_VERSION

from hil.cli.main import main as hil_main
from hil.logs.reader import read_log
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from tests.fake_board import FakeBoard


def _short_run(link: str, periods: int = 1000, log_path=None):
    with BenchSession(load_profile(), SessionConfig(link=link, log_path=log_path)) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(periods)
        return session.recorder.arrays(), session


@pytest.mark.parametrize("link", ["stub", "stub-pty"])
def test_lockstep_runs_are_identical_bit_for_bit(link):
    first, _ = _short_run(link)
    second, _ = _short_run(link)
    assert first.keys() == second.keys()
    speed = first["plant.speed_rpm"][1]
    assert speed[-1] > 200.0, "the stub must have accelerated the motor"
    for name in first:
        np.testing.assert_array_equal(first[name][1], second[name][1], err_msg=name)


@pytest.mark.parametrize("link", ["stub-pty", "stub-can"])
def test_process_links_match_the_in_process_stub(link):
    """The same firmware over a pseudo-terminal (serial framing, or SLCAN through python-can's
    slcan interface) and in-process gives the same run: both framings carry the same values."""
    in_process, _ = _short_run("stub", 200)
    over_link, session = _short_run(link, 200)
    np.testing.assert_array_equal(in_process["plant.i_a"][1], over_link["plant.i_a"][1])
    np.testing.assert_array_equal(in_process["ctrl.speed_ekf_rad_s"][1],
                                  over_link["ctrl.speed_ekf_rad_s"][1])
    assert session.board_name.startswith("hil-stub")


def test_hello_version_mismatch_names_both_versions():
    with FakeBoard(proto_version=PROTOCOL_VERSION + 1) as board:
        with pytest.raises(SessionError) as err:
            with BenchSession(load_profile(), SessionConfig(link=board.url)):
                pass
    text = str(err.value)
    assert f"protocol version {PROTOCOL_VERSION + 1}" in text
    assert f"bench speaks version {PROTOCOL_VERSION}" in text


def test_board_that_never_answers_hello(tmp_path):
    log = tmp_path / "silent.mcap"
    with FakeBoard(answer_hello=False) as board:
        with pytest.raises(SessionError, match="no HELLO"):
            with BenchSession(load_profile(), SessionConfig(link=board.url, log_path=log,
                                                            hello_timeout_s=0.3)):
                pass
    assert read_log(log) is not None  # the log is closed and readable


def test_watchdog_when_the_board_process_dies(tmp_path):
    log = tmp_path / "killed.mcap"
    session = BenchSession(load_profile(), SessionConfig(link="stub-pty", log_path=log,
                                                         watchdog_periods=5, answer_timeout_s=0.05))
    with pytest.raises(SessionError) as err:
        with session:
            session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=3000)
            session.run_periods(2000)
            assert session.plant.truth()[2] != 0.0  # current flows while switching
            os.kill(session.conn.process.pid, signal.SIGKILL)
            session.run_periods(2000)
    text = str(err.value)
    assert "watchdog" in text or "link failed" in text
    assert "exited with status -9" in text
    # Safe state: all switches off, the currents decay through the diodes to zero.
    session.plant.step(None)
    for _ in range(400):
        session.plant.step(None)
    i_a = session.plant.truth()[1]
    assert abs(i_a) < 1e-6
    data = read_log(log)
    events = data["/plan/events"]
    kinds = list(events["kind"])
    assert "watchdog" in kinds or "link_failed" in kinds
    assert len(data["/plant/truth"].t_s) >= 2000


def test_mcap_channels_carry_valid_schemas(tmp_path):
    log = tmp_path / "run.mcap"
    _short_run("stub", 300, log_path=log)
    seen = set()
    with open(log, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            if channel.topic in seen:
                continue
            seen.add(channel.topic)
            if schema.encoding == "protobuf":
                fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
                pool = descriptor_pool.DescriptorPool()
                for fd in fds.file:
                    pool.Add(fd)
                cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
                decoded = cls.FromString(message.data)
                assert decoded.ListFields(), channel.topic
            else:
                assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
                jsonschema.validate(json.loads(message.data), json.loads(schema.data))
    assert {"/plant/truth", "/plant/sensors", "/ctrl/telemetry", "/plan/events", "/cmd"} <= seen


def test_hil_log_commands_on_a_real_log(tmp_path, capsys):
    log = tmp_path / "run.mcap"
    _short_run("stub", 600, log_path=log)
    assert hil_main(["log", "info", str(log)]) == 0
    assert "/plant/truth" in capsys.readouterr().out
    png = tmp_path / "speed.png"
    assert hil_main(["log", "plot", str(log), "plant.speed_rpm", "ctrl.speed_ekf_rad_s",
                     "--out", str(png), "--from", "0.005", "--to", "0.03"]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    csv = tmp_path / "truth.csv"
    assert hil_main(["log", "export", str(log), "/plant/truth", "--out", str(csv)]) == 0
    lines = csv.read_text().splitlines()
    assert len(lines) == 601 and "speed_rpm" in lines[0]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_modbus_write_changes_the_plant_load_while_running():
    from pymodbus.client import ModbusTcpClient

    from hil.ports.modbus import HOLDING_REGISTERS, ControlMailbox, ModbusPort

    port_number = _free_port()
    mailbox = ControlMailbox()
    load_field = next(f for f in HOLDING_REGISTERS if f.name == "load_torque")
    with BenchSession(load_profile(), SessionConfig(link="stub")) as session:
        session.attach_mailbox(mailbox)
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        with ModbusPort(mailbox, host="127.0.0.1", port=port_number):
            session.run_periods(400)
            client = ModbusTcpClient("127.0.0.1", port=port_number)
            assert client.connect()
            try:
                reply = client.write_registers(load_field.address, load_field.encode(0.5))
                assert not reply.isError()
            finally:
                client.close()
            session.run_periods(400)
    load = session.recorder.arrays()["plant.load_torque_nm"][1]
    assert load[0] == 0.0
    assert load[-1] == pytest.approx(0.5, abs=1e-3)


def test_a_speed_reference_from_the_mailbox_reaches_the_board():
    """What Modbus holding registers 5-6 and a live viewer's /cmd write: a COMMAND."""
    from hil.ports.modbus import ControlMailbox

    mailbox = ControlMailbox(speed_ref_rpm=1500, run=True)
    with BenchSession(load_profile(), SessionConfig(link="stub")) as session:
        session.attach_mailbox(mailbox)
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(4000)
        assert mailbox.request(speed_ref_rpm=2000)
        session.run_periods(8000)
    arrays = session.recorder.arrays()
    ref = arrays["cmd.speed_ref_rpm"][1]
    speed = arrays["plant.speed_rpm"][1]
    assert ref[3999] == 1500 and ref[-1] == 2000
    assert abs(speed[3999] - 1500) < 30 and abs(speed[-1] - 2000) < 30


def test_realtime_board_that_closes_its_line_ends_the_session_named_and_safe(tmp_path):
    """A board that closes its line in a real-time run: the session ends with "link failed" at
    the period it happened, the plant safe-stated and the log readable (the lockstep loop's
    rule; the real-time loop let the LinkError through as it was). The watchdog and the miss
    budget are set out of reach, and the period is long, so only the closed line can end it."""
    log = tmp_path / "closed.mcap"
    with FakeBoard(die_after_samples=20) as board:
        session = BenchSession(load_profile(), SessionConfig(
            link=board.url, log_path=log, mode="realtime", realtime_period_s=2e-3,
            watchdog_periods=100_000, watchdog_s=60.0, realtime_miss_budget=100_000))
        with pytest.raises(SessionError) as err:
            with session:
                session.run_periods(2000)
    text = str(err.value)
    assert "link failed at period" in text and "closed the line" in text
    assert session.plant.period < 2000
    kinds = list(read_log(log)["/plan/events"]["kind"])
    assert "link_failed" in kinds
