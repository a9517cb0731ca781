"""Adapters (docs/adapters.md): the wire model's arithmetic against hand computations from
SPEC.md, the ports read from fake sysfs trees for each driver, the cause and fix named for
each, the latency timer written, and the page's tables held to the functions that make them.
No test here opens a port or measures time."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from protocol.can_mapping import can_pack
from protocol.codec import FrameEncoder
from protocol.links import LinkError
from protocol.messages import Duty, DutyLegs, Gates, Role, Sample, Telemetry

from hil.links import adapters
from hil.links.registry import split_wire
from hil.links.wire import (can_frame_bits, can_message_bits, lockstep_rate_table, parse_wire,
                            serial_frame_bytes, uart_time_s, wire_time_table)
from hil.session.adapter_check import check_adapter
from tests.fake_sysfs import add_can, add_tty

REPO = Path(__file__).resolve().parents[1]
MESSAGES = {"SAMPLE": Sample(123_456, 2048, 1000, 3000, 65_000, 5),
            "GATES": Gates(123_456, 0x29),
            "DUTY": Duty(123_456, (1, 2, 3)),
            "DUTY_LEGS": DutyLegs(123_456, (49152, 0, 0), 0x03),
            "TELEMETRY": Telemetry(7, 1, 0, 2, 0x29, *([1.5] * 12))}


# ---------------------------------------------------------------- wire arithmetic

@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_serial_frame_bytes_are_what_the_encoder_puts_on_the_wire(name):
    assert serial_frame_bytes(name) == len(FrameEncoder().encode(MESSAGES[name]))


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_can_frames_are_what_the_can_packer_sends(name):
    frames = can_pack(MESSAGES[name], Role.BENCH if name == "SAMPLE" else Role.CONTROLLER)
    expected = sum(47 + 8 * len(data) for _, data in frames)
    assert can_message_bits(name) == expected


def test_line_times_match_spec_section_11():
    # SPEC.md 11: at 2 Mbaud SAMPLE 19 bytes = 95 us, GATES 13 bytes = 65 us; on CAN SAMPLE
    # 111 bits and GATES 87 bits before stuffing
    assert uart_time_s(serial_frame_bytes("SAMPLE"), 2_000_000) == pytest.approx(95e-6)
    assert uart_time_s(serial_frame_bytes("GATES"), 2_000_000) == pytest.approx(65e-6)
    assert (can_message_bits("SAMPLE"), can_message_bits("GATES")) == (111, 87)
    # worst-case stuffing, by hand: dlc 8 -> (34 + 64 - 1) // 4 = 24 more bits, dlc 5 -> 18
    assert (can_frame_bits(8, stuffed=True), can_frame_bits(5, stuffed=True)) == (135, 105)
    with pytest.raises(ValueError, match="dlc 9"):
        can_frame_bits(9)


@pytest.mark.parametrize("name, baud, period_s", [
    # SAMPLE 19 B + GATES 13 B at 2 Mbaud = 160 us; + 16 ms timer = 16.16 ms -> next 1 ms frame
    ("ftdi-16ms", None, 17e-3),
    # at 115200 baud: 32 B * 10 / 115200 = 2.778 ms; + 16 ms = 18.78 ms -> 19 ms
    ("ftdi-16ms@115200", None, 19e-3),
    ("ftdi-1ms", None, 2e-3),                  # 1.16 ms -> 2 ms
    ("ftdi-1ms", 115_200, 4e-3),               # the link's baud: 3.78 ms -> 4 ms
    ("cdc-fs", None, 1e-3),                    # native USB: the next frame
    ("cdc-hs", None, 125e-6),                  # the next microframe
    ("cp210x", None, 1e-3),                    # 160 us -> 1 ms
    ("fixed-250us@115200", None, 0.5e-3 + 32 * 10 / 115_200),   # no grid: 3.278 ms
])
def test_lockstep_period_of_each_model_by_hand(name, baud, period_s):
    model = parse_wire(name, baud)
    assert model.lockstep_period_s() == pytest.approx(period_s, rel=1e-9)
    assert model.lockstep_rate_hz() == pytest.approx(1 / period_s, rel=1e-9)


def test_a_full_ftdi_packet_goes_without_the_latency_timer():
    model = parse_wire("ftdi-16ms")
    # 19 B out (95 us), then 61 B: under a packet, the timer: 95 + 305 us + 16 ms -> 17 ms
    assert model.exchange_s(0.0, 19, 61) == pytest.approx(17e-3)
    # 62 B fill the packet: 95 + 310 us -> the next 1 ms frame, timer or not; 77 B alike
    assert model.exchange_s(0.0, 19, 62) == pytest.approx(1e-3)
    assert model.exchange_s(0.0, 19, 77) == pytest.approx(1e-3)
    assert parse_wire("cdc-fs").flush_bytes is None


def test_shortest_realtime_period_is_the_worst_phase():
    # a SAMPLE sent just after a frame boundary: 16 ms + 160 us + almost a whole 1 ms frame
    assert parse_wire("ftdi-16ms").shortest_realtime_period_s() == pytest.approx(17.16e-3)
    assert parse_wire("cdc-hs").shortest_realtime_period_s() == pytest.approx(125e-6)


@pytest.mark.parametrize("text, why", [("ftdi-0ms", "1..255"), ("ftdi-256ms", "1..255"),
                                       ("usb-magic", "unknown wire model"),
                                       ("ftdi-16ms@fast", "not an integer"),
                                       ("fixed-3parsecs", "unknown wire model")])
def test_bad_wire_names_are_refused_naming_them(text, why):
    with pytest.raises(ValueError, match=why):
        parse_wire(text)


def test_wire_option_is_taken_off_any_link_string():
    spec, model = split_wire("stub-pty?wire=ftdi-16ms")
    assert (spec, model.name) == ("stub-pty", "ftdi-16ms")
    spec, model = split_wire("serial:/dev/ttyUSB0?baud=921600&wire=ftdi-1ms")
    assert (spec, model.baud) == ("serial:/dev/ttyUSB0?baud=921600", 921_600)
    assert split_wire("exec:/bin/board?args=a+b") == ("exec:/bin/board?args=a+b", None)
    with pytest.raises(LinkError, match="more than once"):
        split_wire("stub-pty?wire=cdc-fs&wire=cdc-hs")
    with pytest.raises(LinkError, match="stub-pty\\?wire=bogus.*unknown wire model"):
        split_wire("stub-pty?wire=bogus")


def test_docs_tables_are_the_functions_output():
    page = (REPO / "docs" / "adapters.md").read_text()
    assert wire_time_table() in page
    assert lockstep_rate_table() in page
    assert "docs/adapters.md" in (REPO / "docs" / "links.md").read_text()


# ---------------------------------------------------------------- sysfs, cause and fix

def _advice(root, spec):
    info = adapters.inspect_link(spec, root)
    return info, adapters.advice(info), adapters.warning(info)


def test_ftdi_at_16ms_names_the_timer_and_the_fix(tmp_path):
    device = add_tty(tmp_path, "ttyUSB0", "ftdi_sio", latency_timer_ms=16)
    info, found, warning = _advice(tmp_path, "serial:/dev/ttyUSB0?baud=2000000")
    assert (info.kind, info.driver, info.latency_timer_ms) == ("ftdi_sio", "ftdi_sio", 16)
    assert (info.usb_id, info.usb_speed_mbps, info.baud) == ("0403:6001", 12.0, 2_000_000)
    assert info.sysfs_path == str(device)
    assert found.poor and "latency timer 16 ms" in found.cause and "59 periods/s" in found.cause
    assert "/sys/bus/usb-serial/devices/ttyUSB0/latency_timer" in found.fix
    assert adapters.udev_rule() in found.fix
    assert warning.startswith("/dev/ttyUSB0: ") and "16 ms" in warning and "fix:" in warning


def test_ftdi_without_a_readable_timer_assumes_the_default(tmp_path):
    add_tty(tmp_path, "ttyUSB0", "ftdi_sio")           # no latency_timer attribute
    info, found, warning = _advice(tmp_path, "serial:/dev/ttyUSB0")
    assert info.latency_timer_ms is None and found.poor and "unreadable" in found.cause
    assert info.expected_wire().name == "ftdi-16ms" and "latency_timer" in found.fix


def test_ftdi_at_1ms_needs_no_fix(tmp_path):
    add_tty(tmp_path, "ttyUSB0", "ftdi_sio", latency_timer_ms=1)
    info, found, warning = _advice(tmp_path, "serial:/dev/ttyUSB0")
    assert info.latency_timer_ms == 1 and not found.poor and not found.fix and warning is None
    assert "latency timer 1 ms" in found.cause


@pytest.mark.parametrize("speed, frame, model", [("12", "1 ms full-speed frames", "cdc-fs"),
                                                 ("480", "125 us high-speed", "cdc-hs")])
def test_cdc_acm_names_its_usb_frame(tmp_path, speed, frame, model):
    add_tty(tmp_path, "ttyACM0", "cdc_acm", speed=speed)
    info, found, warning = _advice(tmp_path, "serial:/dev/ttyACM0")
    assert (info.kind, info.usb_id) == ("cdc_acm", "0483:5740")
    assert frame in found.cause and info.expected_wire().name == model and warning is None


@pytest.mark.parametrize("driver, name", [("cp210x", "CP210x"), ("ch341", "CH340/CH341")])
def test_bridges_without_a_timer_are_named_and_measured(tmp_path, driver, name):
    add_tty(tmp_path, "ttyUSB3", driver)
    info, found, _ = _advice(tmp_path, "serial:/dev/ttyUSB3")
    assert info.kind == driver and info.latency_timer_ms is None
    assert name in found.cause and "hil probe" in found.cause and "FTDI" in found.fix


def test_a_pseudo_terminal_is_no_adapter(tmp_path):
    info, found, warning = _advice(tmp_path, "serial:/dev/pts/3")
    assert info.kind == "pty" and "no adapter" in found.cause and warning is None
    # a port the tree does not know is said so, not guessed
    assert adapters.inspect_link("serial:/dev/ttyUSB9", tmp_path).kind == "unknown"


@pytest.mark.parametrize("bitrate, poor", [(125_000, True), (1_000_000, False)])
def test_can_interface_names_driver_and_bitrate(tmp_path, bitrate, poor):
    add_can(tmp_path, "can0", "gs_usb")
    info, found, warning = _advice(tmp_path, f"can:socketcan:can0?bitrate={bitrate}")
    assert (info.kind, info.driver, info.can_bitrate) == ("can", "gs_usb", bitrate)
    assert f"{bitrate} bit/s" in found.cause and found.poor == poor
    assert (warning is not None) == poor
    if poor:
        assert "bitrate=1000000" in found.fix


def test_slcan_on_an_ftdi_names_its_latency_timer(tmp_path):
    add_tty(tmp_path, "ttyUSB0", "ftdi_sio", latency_timer_ms=16)
    info, found, warning = _advice(tmp_path, "can:slcan:/dev/ttyUSB0?bitrate=1000000")
    assert (info.kind, info.driver, info.latency_timer_ms) == ("can", "slcan/ftdi_sio", 16)
    assert found.poor and "latency timer 16 ms" in found.cause
    assert "devices/ttyUSB0/latency_timer" in found.fix and "ttyUSB0" in warning


def test_can_bitrate_from_ip_details():
    out = '[{"ifname":"can0","linkinfo":{"info_data":{"bittiming":{"bitrate":500000}}}}]'
    assert adapters.can_bitrate_from_ip("can0", run=lambda argv: out) == 500_000
    assert adapters.can_bitrate_from_ip("vcan0", run=lambda argv: '[{"ifname":"vcan0"}]') is None


def test_set_latency_timer_writes_the_ports_file(tmp_path):
    device = add_tty(tmp_path, "ttyUSB0", "ftdi_sio", latency_timer_ms=16)
    info = adapters.inspect_link("serial:/dev/ttyUSB0", tmp_path)
    assert "now 1 ms" in adapters.set_latency_timer(info, 1, tmp_path)
    assert (device / "latency_timer").read_text().strip() == "1"
    assert adapters.inspect_link("serial:/dev/ttyUSB0", tmp_path).latency_timer_ms == 1
    with pytest.raises(ValueError, match="1..255"):
        adapters.set_latency_timer(info, 0, tmp_path)
    add_tty(tmp_path, "ttyACM0", "cdc_acm")
    with pytest.raises(ValueError, match="not an FTDI port"):
        adapters.set_latency_timer(adapters.inspect_link("serial:/dev/ttyACM0", tmp_path), 1)


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write a read-only file")
def test_set_latency_timer_without_permission_names_the_fix(tmp_path):
    device = add_tty(tmp_path, "ttyUSB0", "ftdi_sio", latency_timer_ms=16)
    (device / "latency_timer").chmod(0o444)
    info = adapters.inspect_link("serial:/dev/ttyUSB0", tmp_path)
    with pytest.raises(PermissionError, match="sudo tee .*latency_timer.*udev"):
        adapters.set_latency_timer(info, 1, tmp_path)


# ---------------------------------------------------------------- the start-up check

class _Conn:
    def __init__(self, wire=None):
        self.wire = wire
        self.link = self                    # a link without a descriptor

    def descriptor(self):
        return None


class _Log:
    def __init__(self):
        self.metadata = {}

    def add_metadata(self, name, data):
        self.metadata[name] = dict(data)


@pytest.mark.parametrize("driver, name, spec, warns, says", [
    ("ftdi_sio", "ttyUSB0", "serial:/dev/ttyUSB0", True, "latency timer 16 ms"),
    ("cdc_acm", "ttyACM0", "serial:/dev/ttyACM0", False, "1 ms full-speed"),
    ("cp210x", "ttyUSB1", "serial:/dev/ttyUSB1", False, "CP210x"),
    ("ch341", "ttyUSB2", "serial:/dev/ttyUSB2", False, "CH340"),
    ("can", "can0", "can:socketcan:can0?bitrate=125000", True, "125000 bit/s"),
    ("pty", "", "serial:/dev/pts/7", False, "pseudo-terminal"),
])
def test_startup_check_warns_once_and_records_the_adapter(tmp_path, monkeypatch, driver, name,
                                                          spec, warns, says):
    if driver == "can":
        add_can(tmp_path, name)
    elif driver != "pty":
        add_tty(tmp_path, name, driver, latency_timer_ms=16 if driver == "ftdi_sio" else None)
    monkeypatch.setattr(adapters, "SYSFS_ROOT", tmp_path)
    warnings, log = [], _Log()
    info = check_adapter(spec, _Conn(), log, warn=warnings.append)
    assert len(warnings) == (1 if warns else 0)
    if warns:
        assert says in warnings[0] and "fix:" in warnings[0]
    assert says in adapters.advice(info).cause
    recorded = log.metadata["adapter"]
    assert recorded["kind"] == driver and recorded["port"] in spec
    if driver == "ftdi_sio":
        assert recorded["latency_timer_ms"] == "16" and recorded["usb_id"] == "0403:6001"


def test_startup_check_leaves_local_links_alone():
    assert check_adapter("stub-pty", _Conn(), _Log(), warn=pytest.fail) is None
    assert check_adapter("stub", _Conn(), _Log(), warn=pytest.fail) is None
