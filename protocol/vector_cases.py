"""The cases behind protocol/vectors/vectors.txt, the regression set.

`python -m protocol.vector_cases --write` regenerates the file (and the
libFuzzer seeds); `--check` fails when the file differs from what the cases
produce. The message bytes in vectors.txt are the Python encoder's output,
pinned so that both codecs keep producing them; every stream's messages and
counters are written by hand here and checked against the Python codec when
generating. The conformance set built by hand from SPEC.md, bytes included,
is protocol/vectors/handbuilt.txt (not generated).
"""
from __future__ import annotations

import argparse
import random
import struct
import sys
from binascii import crc_hqx

from cobs.cobs import encode as cobs_encode

from protocol.can_mapping import CanReassembler, can_pack
from protocol.codec import COUNTER_NAMES, StreamDecoder, encode_frame, encode_payload
from protocol.can_mapping import COUNTER_NAMES as CAN_COUNTER_NAMES
from protocol.messages import (
    CAP_CAN, CAP_GATES, CAP_TELEMETRY, GATE_A_HIGH, GATE_B_LOW, GATE_C_LOW, LEG_A, LEG_B, LEGS_ALL,
    SENSOR_BEMF_COMPARATORS, SENSOR_CURRENT_A, SENSOR_CURRENT_B, SENSOR_CURRENT_C, SENSOR_ENCODER, SENSOR_HALL,
    SENSOR_RESOLVER, SENSOR_SET_ALL, SENSOR_TEMPERATURE, SENSOR_TERMINAL_VOLTAGES, SENSOR_VDC, STATUS_INDEX_PULSE,
    STATUS_OVERVOLTAGE, Command, ControllerState, Duty, DutyLegs, Fault, FaultCode, Gates, Heartbeat, Hello,
    ParamGet, ParamId, ParamSet, ParamStatus, ParamValue, Role, Sample, SampleSensors, Shutdown, SpeedSource,
    Status, Telemetry,
)
from protocol.vector_file import (
    HANDBUILT_PATH, VECTORS_PATH, CanStream, MessageVector, RejectVector, SerialStream, VectorSet, dump,
    load,
)

BENCH, CONTROLLER = int(Role.BENCH), int(Role.CONTROLLER)
BASE = 0x100


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _telemetry(period: int, rng: random.Random) -> Telemetry:
    floats = [f32(rng.uniform(-400.0, 400.0)) for _ in range(12)]
    return Telemetry(period, 3, int(SpeedSource.EKF), int(ControllerState.RUNNING), GATE_A_HIGH | GATE_B_LOW | GATE_C_LOW,
                     *floats)


def messages() -> list[tuple[str, object, int, int, int]]:
    """(name, message, seq, sender role, CAN base id): at least one per type, edges included."""
    rng = random.Random(3)
    return [
        ("hello_bench", Hello(1, BENCH, 0, 50_000, name=b"hil-bench"), 0, BENCH, BASE),
        ("hello_controller", Hello(1, CONTROLLER, CAP_GATES | CAP_TELEMETRY | CAP_CAN, 50_000,
                                   name=b"hil-stub 0.1"), 0, CONTROLLER, BASE),
        ("hello_empty_name", Hello(1, CONTROLLER, 0, 0, name=b""), 200, CONTROLLER, BASE),
        ("hello_max_name", Hello(1, BENCH, 0xFFFF, 0xFFFFFFFF, name=bytes(range(0x30, 0x58))), 1,
         BENCH, 0x7C0),
        ("hello_newer", Hello(2, CONTROLLER, 0x0F00, 100_000, name="vers\u00e9 2".encode()), 17,
         CONTROLLER, BASE),
        ("sample_zero", Sample(0, 0, 0, 0, 0, 0), 0, BENCH, BASE),
        ("sample_mid", Sample(123_456, 2048, 1000, 3000, 65_000, STATUS_INDEX_PULSE | STATUS_OVERVOLTAGE),
         7, BENCH, BASE),
        ("sample_max", Sample(0xFFFFFFFF, 4095, 4095, 4095, 65_535, 15), 255, BENCH, BASE),
        ("sample_zeros_in_fields", Sample(0x01000000, 0x100, 0x010, 0x001, 0x0100, 0), 3, BENCH, BASE),
        ("gates_off", Gates(0, 0), 0, CONTROLLER, BASE),
        ("gates_mid", Gates(123_456, GATE_A_HIGH | GATE_B_LOW | GATE_C_LOW), 8, CONTROLLER, BASE),
        ("gates_max", Gates(0xFFFFFFFF, 0x3F), 255, CONTROLLER, 0x7C0),
        ("duty_mid", Duty(70_000, (0, 32_768, 65_535)), 9, CONTROLLER, BASE),
        ("duty_zero", Duty(0, (0, 0, 0)), 0, CONTROLLER, BASE),
        ("command_ekf", Command(1, int(SpeedSource.EKF), f32(104.71975511965977), 0.0, f32(0.3)), 4,
         BENCH, BASE),
        ("command_torque", Command(3, int(SpeedSource.ENCODER), float("-inf"), -0.0, float("inf")), 5,
         BENCH, BASE),
        ("telemetry_run", _telemetry(123_457, rng), 10, CONTROLLER, BASE),
        ("telemetry_idle", Telemetry(0, 0, 0, 0, 0, *([0.0] * 12)), 11, CONTROLLER, BASE),
        ("param_set_period", ParamSet(int(ParamId.CONTROL_PERIOD_S), f32(50e-6)), 12, BENCH, BASE),
        ("param_set_rs", ParamSet(int(ParamId.STATOR_RESISTANCE_OHM), f32(0.466)), 13, BENCH, BASE),
        ("param_get_cycles", ParamGet(int(ParamId.CONTROL_STEP_CYCLES)), 14, BENCH, BASE),
        ("param_value_flux", ParamValue(int(ParamId.MAGNET_FLUX_WB), int(ParamStatus.OK), f32(0.0928)), 15,
         CONTROLLER, BASE),
        ("param_value_unknown", ParamValue(999, int(ParamStatus.UNKNOWN), 0.0), 16, CONTROLLER, BASE),
        ("status_running", Status(5_000, int(ControllerState.RUNNING), 0), 17, CONTROLLER, BASE),
        ("status_fault", Status(5_001, int(ControllerState.FAULT), int(FaultCode.OVERCURRENT)), 18,
         CONTROLLER, BASE),
        ("fault_overcurrent", Fault(5_001, int(FaultCode.OVERCURRENT), f32(12.5)), 19, CONTROLLER, BASE),
        ("heartbeat_zero", Heartbeat(0), 20, BENCH, BASE),
        ("heartbeat_max", Heartbeat(0xFFFFFFFF), 21, CONTROLLER, BASE),
        ("shutdown", Shutdown(), 22, BENCH, BASE),
        ("duty_legs_six_step", DutyLegs(70_000, (40_000, 0, 0), LEG_A | LEG_B), 23, CONTROLLER, BASE),
        ("duty_legs_all", DutyLegs(0xFFFFFFFF, (1, 2, 3), LEGS_ALL), 24, CONTROLLER, 0x7C0),
        *sample_sensors_messages(),
    ]


CURRENTS_VDC = SENSOR_CURRENT_A | SENSOR_CURRENT_B | SENSOR_CURRENT_C | SENSOR_VDC


def sample_sensors_messages() -> list[tuple[str, object, int, int, int]]:
    """SAMPLE_SENSORS with the sets of the example drives, the empty and the full set, and fields
    whose bytes hold zeros (COBS)."""
    return [
        ("sample_sensors_encoder", SampleSensors(123_456, SENSOR_CURRENT_A | SENSOR_CURRENT_B | SENSOR_VDC
                                                 | SENSOR_ENCODER, STATUS_INDEX_PULSE, adc_ia=2048, adc_ib=1000,
                                                 adc_vdc=3000, encoder=65_000), 30, BENCH, BASE),
        ("sample_sensors_hall", SampleSensors(70_000, CURRENTS_VDC | SENSOR_HALL, 0, adc_ia=2100, adc_ib=1990,
                                              adc_ic=1958, adc_vdc=983, hall=0b011), 31, BENCH, BASE),
        ("sample_sensors_sensorless", SampleSensors(5, CURRENTS_VDC | SENSOR_TERMINAL_VOLTAGES
                                                    | SENSOR_BEMF_COMPARATORS, 0, adc_ia=2048, adc_ib=2048,
                                                    adc_ic=2048, adc_vdc=983, adc_va=983, adc_vb=0, adc_vc=500,
                                                    bemf_comparators=0b001), 32, BENCH, BASE),
        ("sample_sensors_resolver", SampleSensors(1 << 24, SENSOR_RESOLVER | SENSOR_TEMPERATURE, 8,
                                                  adc_resolver_sin=3848, adc_resolver_cos=248,
                                                  adc_temperature=250), 33, BENCH, BASE),
        ("sample_sensors_empty", SampleSensors(0, 0, 0), 0, BENCH, BASE),
        ("sample_sensors_all_max", SampleSensors(0xFFFFFFFF, SENSOR_SET_ALL, 15, *([0xFFFF] * 5), 7,
                                                 *([0xFFFF] * 3), 7, *([0xFFFF] * 3)), 255, BENCH, 0x7C0),
        ("sample_sensors_zero_bytes", SampleSensors(0x100, SENSOR_SET_ALL, 0, 0x100, 0x001, 0, 0x8000, 0x0080,
                                                    0, 1, 0x100, 0, 0, 0x0100, 0x0001, 0x0200), 34, BENCH, BASE),
    ]


def rejects() -> list[RejectVector]:
    return [
        RejectVector("sample_adc_13bit", Sample(1, 4096, 0, 0, 0, 0)),
        RejectVector("sample_vdc_13bit", Sample(1, 0, 0, 0x1000, 0, 0)),
        RejectVector("sample_status_5bit", Sample(1, 0, 0, 0, 0, 16)),
        RejectVector("hello_name_41", Hello(1, 0, 0, 0, 41, b"x" * 41)),
        RejectVector("sample_sensors_reserved_set_bit", SampleSensors(1, 0x0400, 0)),
        RejectVector("sample_sensors_status_5bit", SampleSensors(1, SENSOR_CURRENT_A, 16)),
        RejectVector("sample_sensors_hall_reserved_bit", SampleSensors(1, SENSOR_HALL, 0, hall=8)),
        RejectVector("sample_sensors_comparator_reserved_bit",
                     SampleSensors(1, SENSOR_BEMF_COMPARATORS, 0, bemf_comparators=0x80)),
    ]


def raw_frame(version: int, msg_type: int, seq: int, payload: bytes, length: int | None = None,
              crc_xor: int = 0) -> bytes:
    """A frame built field by field, to make well-formed frames with one thing wrong."""
    raw = bytes((version, msg_type, seq, len(payload) if length is None else length)) + payload
    crc = crc_hqx(raw, 0xFFFF) ^ crc_xor
    return cobs_encode(raw + struct.pack("<H", crc)) + b"\x00"


def corrupt_payload_bit(frame_msg, seq: int, byte: int, bit: int) -> bytes:
    """The frame of frame_msg with one payload bit flipped after the CRC was computed."""
    good = encode_frame(frame_msg, seq)
    from cobs.cobs import decode as cobs_decode

    raw = bytearray(cobs_decode(good[:-1]))
    raw[4 + byte] ^= 1 << bit
    return cobs_encode(bytes(raw)) + b"\x00"


def serial_streams(m: dict[str, object]) -> list[tuple[SerialStream, bool]]:
    """(stream, exact): every stream here has hand-written counters (exact). The garbage stream
    whose counters are derived from SPEC 3.4 rule by rule is in handbuilt.txt; random garbage is
    left to the fuzzers and the parity tests, which compare the two decoders."""
    F = encode_frame
    s, g, t = m["sample_mid"], m["gates_mid"], m["telemetry_run"]
    cases = [
        (SerialStream("clean", b"\x00" + F(s, 0) + F(g, 1) + F(t, 2), ["sample_mid", "gates_mid", "telemetry_run"],
                      {"frames_ok": 3}), True),
        (SerialStream("no_leading_delimiter", F(s, 0) + F(g, 1), ["sample_mid", "gates_mid"], {"frames_ok": 2}),
         True),
        (SerialStream("idle_delimiters", b"\x00\x00" + F(s, 0) + b"\x00\x00\x00" + F(g, 1) + b"\x00",
                      ["sample_mid", "gates_mid"], {"frames_ok": 2}), True),
        # code 0x05 promises four data bytes, only one follows before the delimiter
        (SerialStream("cobs_overrun", F(s, 0) + bytes.fromhex("050100") + F(g, 1), ["sample_mid", "gates_mid"],
                      {"frames_ok": 2, "framing_errors": 1}), True),
        # decode to 1 and 0 bytes: shorter than header + CRC
        (SerialStream("too_short", bytes.fromhex("02010001 00") + F(g, 0), ["gates_mid"],
                      {"frames_ok": 1, "framing_errors": 2}), True),
        # one flipped payload bit: CRC error, and the lost seq 1 is a gap of one
        (SerialStream("crc_flip", F(s, 0) + corrupt_payload_bit(g, 1, 0, 3) + F(t, 2),
                      ["sample_mid", "telemetry_run"], {"frames_ok": 2, "crc_errors": 1, "seq_gaps": 1}), True),
        (SerialStream("crc_bytes_wrong", raw_frame(1, 3, 0, bytes(5), crc_xor=0x8000) + F(g, 1), ["gates_mid"],
                      {"frames_ok": 1, "crc_errors": 1}), True),
        # the first candidate frame is garbage + a valid frame: 0xde promises 221 bytes
        (SerialStream("garbage_glued_to_frame", bytes.fromhex("deadbeef") + F(s, 0) + F(g, 1), ["gates_mid"],
                      {"frames_ok": 1, "framing_errors": 1}), True),
        # 71 bytes between delimiters is the longest candidate: decoded and failing its CRC;
        # 72 and 300 bytes are dropped unread as one framing error each
        (SerialStream("segment_limits", bytes([71]) + bytes([0x47]) * 70 + b"\x00" + b"\x55" * 72 + b"\x00"
                      + b"\x55" * 300 + b"\x00" + F(g, 0), ["gates_mid"],
                      {"frames_ok": 1, "crc_errors": 1, "framing_errors": 2}), True),
        (SerialStream("newer_version", raw_frame(2, 3, 0, bytes(5)) + F(g, 1), ["gates_mid"],
                      {"frames_ok": 1, "version_errors": 1, "last_bad_version": 2}), True),
        # CRC is right but the length field says 4 for a 5-byte payload
        (SerialStream("length_field_mismatch", raw_frame(1, 3, 0, bytes(5), length=4) + F(g, 1), ["gates_mid"],
                      {"frames_ok": 1, "framing_errors": 1}), True),
        # unknown types are counted and still advance the sequence: no gap before seq 3
        (SerialStream("unknown_types", raw_frame(1, 0x0E, 0, b"") + raw_frame(1, 0x00, 1, b"\x01")
                      + raw_frame(1, 0xFF, 2, bytes(64)) + F(g, 3), ["gates_mid"],
                      {"frames_ok": 1, "unknown_types": 3}), True),
        (SerialStream("wrong_payload_lengths",
                      raw_frame(1, 3, 0, bytes(6)) + raw_frame(1, 0x0D, 1, b"\x00")
                      + raw_frame(1, 1, 2, bytes(8) + b"\x29" + b"n" * 41)
                      + raw_frame(1, 1, 3, bytes(8) + b"\x03" + b"abcd") + raw_frame(1, 1, 4, bytes(8))
                      + F(g, 5), ["gates_mid"], {"frames_ok": 1, "length_errors": 5}), True),
        # gaps: 11-10-1 = 0, 15-11-1 = 3, 15-15-1 = 255 (a repeat), 0-15-1 = 240 (mod 256)
        (SerialStream("seq_gaps", F(g, 10) + F(g, 11) + F(g, 15) + F(g, 15) + F(g, 0), ["gates_mid"] * 5,
                      {"frames_ok": 5, "seq_gaps": 498}), True),
        (SerialStream("seq_wraps", F(g, 254) + F(g, 255) + F(g, 0) + F(g, 1), ["gates_mid"] * 4,
                      {"frames_ok": 4}), True),
        # a frame cut short by a lost delimiter-less tail merges with the next one
        (SerialStream("truncated_frame", F(s, 0)[:9] + F(g, 1) + F(t, 2), ["telemetry_run"],
                      {"frames_ok": 1, "crc_errors": 1}), True),
        (SerialStream("overflow_then_frame", bytes(range(1, 201)) + b"\x00" + F(g, 0), ["gates_mid"],
                      {"frames_ok": 1, "framing_errors": 1}), True),
        *_sample_sensors_streams(m),
    ]
    return cases


def _sample_sensors_streams(m: dict[str, object]) -> list[tuple[SerialStream, bool]]:
    """SAMPLE_SENSORS payloads whose length disagrees with their sensor set: length errors."""
    F = encode_frame
    enc = m["sample_sensors_encoder"]
    good = encode_payload(enc)                       # 15 bytes: 7 + 4 fields of 2
    fixed = struct.pack("<IHB", 9, 0x0400, 0)         # reserved bit 10: layout unknown
    return [
        (SerialStream("sample_sensors_wrong_lengths",
                      raw_frame(1, 0x10, 0, good[:-1]) + raw_frame(1, 0x10, 1, good + b"\x00")
                      + raw_frame(1, 0x10, 2, good[:6]) + raw_frame(1, 0x10, 3, fixed)
                      + raw_frame(1, 0x10, 4, fixed + bytes(2)) + raw_frame(1, 0x10, 5, struct.pack("<IHB", 9, 0xFFFF, 0)
                                                                             + bytes(31))
                      + F(enc, 6), ["sample_sensors_encoder"], {"frames_ok": 1, "length_errors": 6}), True),
        (SerialStream("sample_sensors_between_samples",
                      F(m["sample_mid"], 0) + F(enc, 1) + F(m["sample_sensors_all_max"], 2) + F(m["gates_mid"], 3),
                      ["sample_mid", "sample_sensors_encoder", "sample_sensors_all_max", "gates_mid"],
                      {"frames_ok": 4}), True),
    ]


def _frames(msg, role: int, seq: int = 0, base: int = BASE) -> list[tuple[int, bytes]]:
    return can_pack(msg, role, base, seq)


def can_streams(m: dict[str, object]) -> tuple[list[CanStream], dict[str, tuple[object, int, int]]]:
    """Hand-written CAN streams and the extra messages they yield (name -> (msg, role, seq))."""
    extra: dict[str, tuple[object, int, int]] = {}
    streams: list[CanStream] = []

    def sample(period: int) -> str:
        name = f"sample_p{period}"
        extra[name] = (Sample(period, 100, 200, 300, 1234, 0), BENCH, 0)
        return name

    # SAMPLE carries period & 0xFF; the receiver takes the period nearest the last one it saw.
    # 429 is 130 ahead of 299, beyond the +-127 window: it aliases to 173 (SPEC.md).
    periods = [254, 255, 256, 257, 300, 299, 429]
    names = [sample(p) for p in periods]
    streams.append(CanStream("sample_period_extension", BASE,
                             [f for n in names for f in _frames(extra[n][0], BENCH)],
                             [(n, BENCH) for n in names[:-1]] + [(sample(173), BENCH)], {"messages_ok": 7}))
    # a full 32-bit period (GATES) sets the reference: the next SAMPLE extends from it
    extra["gates_p70000"] = (Gates(70_000, 0x21), CONTROLLER, 0)
    s70001 = sample(70_001)
    streams.append(CanStream("gates_sets_reference", BASE,
                             _frames(extra["gates_p70000"][0], CONTROLLER) + _frames(extra[s70001][0], BENCH),
                             [("gates_p70000", CONTROLLER), (s70001, BENCH)], {"messages_ok": 2}))
    # DUTY carries period & 0xFFFF: 70001 reads as 4465 until a full period (STATUS) is seen
    extra["duty_p70001"] = (Duty(70_001, (1, 2, 3)), CONTROLLER, 0)
    extra["duty_p4465"] = (Duty(4465, (1, 2, 3)), CONTROLLER, 0)
    extra["status_p70000"] = (Status(70_000, int(ControllerState.RUNNING), 0), CONTROLLER, 0)
    streams.append(CanStream("duty_period_extension", BASE,
                             _frames(extra["duty_p70001"][0], CONTROLLER)
                             + _frames(extra["status_p70000"][0], CONTROLLER)
                             + _frames(extra["duty_p70001"][0], CONTROLLER),
                             [("duty_p4465", CONTROLLER), ("status_p70000", CONTROLLER),
                              ("duty_p70001", CONTROLLER)], {"messages_ok": 3}))
    tele = _frames(m["telemetry_run"], CONTROLLER, seq=5)
    assert len(tele) == 8
    streams.append(CanStream("telemetry_in_order", BASE, tele, [("telemetry_run", CONTROLLER)],
                             {"messages_ok": 1}))
    # frame 3 lost: one sequence error; frames 4..7 of the same message are dropped uncounted
    streams.append(CanStream("telemetry_missing_frame", BASE,
                             tele[:3] + tele[4:] + _frames(m["telemetry_run"], CONTROLLER, seq=6),
                             [("telemetry_run", CONTROLLER)], {"messages_ok": 1, "sequence_errors": 1}))
    # frame 0 lost: the orphans count once
    streams.append(CanStream("telemetry_missing_first", BASE, tele[1:] + _frames(m["gates_mid"], CONTROLLER),
                             [("gates_mid", CONTROLLER)], {"messages_ok": 1, "sequence_errors": 1}))
    # a new message (index 0) while one is incomplete
    streams.append(CanStream("restart", BASE, tele[:3] + _frames(m["telemetry_run"], CONTROLLER, seq=6),
                             [("telemetry_run", CONTROLLER)], {"messages_ok": 1, "sequence_errors": 1}))
    # the first half of counter 5 and the second half of counter 6 must not be glued together
    tele6 = _frames(m["telemetry_run"], CONTROLLER, seq=6)
    streams.append(CanStream("counter_mismatch", BASE, tele[:4] + tele6[4:], [], {"sequence_errors": 1}))
    # single-frame messages may come between the frames of a multi-frame one
    streams.append(CanStream("single_frames_interleaved", BASE,
                             tele[:4] + _frames(m["gates_mid"], CONTROLLER) + tele[4:],
                             [("gates_mid", CONTROLLER), ("telemetry_run", CONTROLLER)], {"messages_ok": 2}))
    # the two roles' multi-frame messages interleave frame by frame
    cmd = _frames(m["command_ekf"], BENCH, seq=1)
    mixed = [cmd[0], tele[0], tele[1], cmd[1]] + tele[2:]
    streams.append(CanStream("roles_interleaved", BASE, mixed,
                             [("command_ekf", BENCH), ("telemetry_run", CONTROLLER)], {"messages_ok": 2}))
    streams.append(CanStream("unknown_and_foreign_ids", BASE,
                             [(BASE + 0x0E, b""), (BASE + 0x00, b"\x01"), (BASE + 0x3F, bytes(8)),
                              (BASE - 1, bytes(8)), (BASE + 0x40, b""), (0x7FF, b"\x00")]
                             + _frames(m["gates_mid"], CONTROLLER),
                             [("gates_mid", CONTROLLER)],
                             {"messages_ok": 1, "unknown_types": 3, "ignored_frames": 3}), )
    streams.append(CanStream("wrong_dlc", BASE,
                             [(BASE + 0x20 + 3, bytes(4)), (BASE + 2, bytes(7)), (BASE + 8, bytes(3)),
                              (BASE + 0x20 + 4, bytes(6)), (BASE + 0x0D, b"\x00")],
                             [], {"length_errors": 5}))
    # a 3-byte middle frame: length error; the rest of that message is dropped uncounted
    short = tele[:1] + [(tele[1][0], tele[1][1][:4])] + tele[2:]
    streams.append(CanStream("short_middle_frame", BASE, short, [], {"length_errors": 1}))
    # FAULT is 10 bytes: a second frame of 7 makes 14
    fault = _frames(m["fault_overcurrent"], CONTROLLER, seq=2)
    long_fault = [fault[0], (fault[1][0], fault[1][1] + bytes(7 - len(fault[1][1]) + 1))]
    streams.append(CanStream("message_too_long", BASE, long_fault + fault, [("fault_overcurrent", CONTROLLER)],
                             {"messages_ok": 1, "length_errors": 1}))
    hello = _frames(m["hello_bench"], BENCH, seq=3)
    bad_hello = [hello[0], (hello[1][0], hello[1][1][:2] + b"\x29" + hello[1][1][3:])]  # name_len 41
    streams.append(CanStream("hello_name_len_41", BASE, bad_hello + hello[2:], [], {"length_errors": 1}))
    streams.append(CanStream("empty_segment_frame", BASE, [(BASE + 5, b"")] + cmd, [("command_ekf", BENCH)],
                             {"messages_ok": 1, "length_errors": 1}))
    streams.append(CanStream("other_base_id", 0x7C0, _frames(m["gates_max"], CONTROLLER, base=0x7C0)
                             + _frames(m["gates_mid"], CONTROLLER),
                             [("gates_max", CONTROLLER)], {"messages_ok": 1, "ignored_frames": 1}))
    streams += _sample_sensors_can_streams(m, extra)
    return streams, extra


def _sample_sensors_can_streams(m: dict[str, object], extra: dict) -> list[CanStream]:
    """SAMPLE_SENSORS on CAN: segmented (SPEC 7.4), its length known from sensor_set in frame 0."""
    streams = []
    full = _frames(m["sample_sensors_zero_bytes"], BENCH, seq=7)
    assert len(full) == 5                            # 31 bytes: 4 frames of 7 and one of 3
    streams.append(CanStream("sample_sensors_in_order", BASE, full, [("sample_sensors_zero_bytes", BENCH)],
                             {"messages_ok": 1}))
    # frame 2 lost: one sequence error, frames 3 and 4 dropped uncounted; the next copy arrives whole
    streams.append(CanStream("sample_sensors_missing_frame", BASE,
                             full[:2] + full[3:] + _frames(m["sample_sensors_zero_bytes"], BENCH, seq=8),
                             [("sample_sensors_zero_bytes", BENCH)], {"messages_ok": 1, "sequence_errors": 1}))
    # a reserved sensor-set bit in frame 0: the length is unknown, one length error; the rest of
    # that message is dropped uncounted
    bad = [(full[0][0], full[0][1][:5] + bytes((full[0][1][5], full[0][1][6] | 0x04)) + full[0][1][7:])] + full[1:]
    streams.append(CanStream("sample_sensors_reserved_set_bit", BASE, bad, [], {"length_errors": 1}))
    # the encoder set's 15 bytes in three frames; a last frame of 2 bytes makes 16: too long
    enc = _frames(m["sample_sensors_encoder"], BENCH, seq=1)
    assert [len(d) for _, d in enc] == [8, 8, 2]
    too_long = enc[:2] + [(enc[2][0], enc[2][1] + b"\x00")]
    streams.append(CanStream("sample_sensors_too_long", BASE, too_long + enc, [("sample_sensors_encoder", BENCH)],
                             {"messages_ok": 1, "length_errors": 1}))
    # the empty set: 7 bytes, one frame
    streams.append(CanStream("sample_sensors_empty_set", BASE, _frames(m["sample_sensors_empty"], BENCH),
                             [("sample_sensors_empty", BENCH)], {"messages_ok": 1}))
    # its full 32-bit period sets the reference (SPEC 7.3): a following DUTY_LEGS extends from it
    extra["duty_legs_p123457"] = (DutyLegs(123_457, (1, 2, 3), LEGS_ALL), CONTROLLER, 0)
    streams.append(CanStream("sample_sensors_sets_reference", BASE,
                             enc + _frames(extra["duty_legs_p123457"][0], CONTROLLER),
                             [("sample_sensors_encoder", BENCH), ("duty_legs_p123457", CONTROLLER)],
                             {"messages_ok": 2}))
    return streams


# ---------------------------------------------------------------- building and checking

def _full(counters: dict[str, int], names: tuple[str, ...]) -> dict[str, int]:
    return {n: counters.get(n, 0) for n in names}


def build() -> VectorSet:
    vs = VectorSet()
    for name, msg, seq, role, base in messages():
        vs.messages[name] = _message_vector(name, msg, seq, role, base)
    vs.rejects = rejects()
    plain = {name: v.msg for name, v in vs.messages.items()}
    for stream, exact in serial_streams(plain):
        dec = StreamDecoder()
        got = dec.feed(stream.data)
        expected_msgs = [plain[n] for n in stream.yields]
        counters = dict(dec.counters, last_bad_version=dec.last_bad_version)
        if exact:
            want = _full(stream.counters, COUNTER_NAMES + ("last_bad_version",))
            _require(counters == want, f"serial stream {stream.name}: counters {counters}, expected {want}")
            _require(got == expected_msgs, f"serial stream {stream.name}: got {got}")
        else:
            _require(_subsequence(expected_msgs, got), f"serial stream {stream.name}: a valid frame was lost")
            stream.yields = [_name_of(plain, msg, stream.name) for msg in got]
            stream.counters = counters
        vs.serial_streams.append(stream)
    streams, extra = can_streams(plain)
    for name, (msg, role, seq) in extra.items():
        vs.messages[name] = _message_vector(name, msg, seq, role, BASE)
        plain[name] = msg
    for stream in streams:
        rx = CanReassembler(stream.base_id)
        got = [r for r in (rx.feed(i, d) for i, d in stream.frames) if r is not None]
        want = [(plain[n], role) for n, role in stream.yields]
        _require(got == want, f"CAN stream {stream.name}: got {got}, expected {want}")
        full = _full(stream.counters, CAN_COUNTER_NAMES)
        _require(rx.counters == full, f"CAN stream {stream.name}: counters {rx.counters}, expected {full}")
        vs.can_streams.append(stream)
    return vs


def _message_vector(name: str, msg, seq: int, role: int, base: int) -> MessageVector:
    v = MessageVector(name, msg, seq, role, base, serial=encode_frame(msg, seq), can=can_pack(msg, role, base, seq))
    rx = CanReassembler(base)
    got = [r for r in (rx.feed(i, d) for i, d in v.can) if r is not None]
    _require(len(got) == 1 and got[0][1] == role, f"{name}: CAN frames do not reassemble")
    for attr in ("period",):
        if hasattr(msg, attr) and getattr(got[0][0], attr) != getattr(msg, attr):
            v.can_fields[attr] = getattr(got[0][0], attr)
    return v


def _subsequence(needles: list, haystack: list) -> bool:
    it = iter(haystack)
    return all(any(n == h for h in it) for n in needles)


def _name_of(plain: dict[str, object], msg, where: str) -> str:
    for name, m in plain.items():
        if m == msg:
            return name
    raise AssertionError(f"serial stream {where}: garbage decoded into a message {msg}")


def _require(ok: bool, what: str) -> None:
    if not ok:
        raise AssertionError(what)


SEEDS_DIR = VECTORS_PATH.parent.parent / "c" / "fuzz" / "seeds"


def fuzz_seeds(vs: VectorSet) -> dict[str, bytes]:
    """libFuzzer seed inputs (relative path -> bytes): every serial stream and message frame for
    fuzz_stream; every CAN stream as id u16 LE, dlc, data records for fuzz_can; the streams of
    handbuilt.txt too."""
    hb = load(HANDBUILT_PATH)
    seeds = {f"stream/{s.name}": s.data for s in vs.serial_streams + hb.serial_streams}
    for c in hb.can_streams:
        seeds[f"can/{c.name}"] = b"".join(struct.pack("<HB", i, len(d)) + d for i, d in c.frames)
    seeds["stream/all_messages"] = b"".join(v.serial for v in vs.messages.values())
    for c in vs.can_streams:
        seeds[f"can/{c.name}"] = b"".join(struct.pack("<HB", i, len(d)) + d for i, d in c.frames)
    seeds["can/all_messages"] = b"".join(struct.pack("<HB", i, len(d)) + d
                                         for v in vs.messages.values() if v.base_id == BASE for i, d in v.can)
    return seeds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m protocol.vector_cases", description=__doc__)
    parser.add_argument("--write", action="store_true", help=f"rewrite {VECTORS_PATH}")
    parser.add_argument("--check", action="store_true", help="fail if the file is out of date")
    args = parser.parse_args(argv)
    vs = build()
    text = dump(vs)
    seeds = fuzz_seeds(vs)
    if args.write:
        VECTORS_PATH.parent.mkdir(parents=True, exist_ok=True)
        VECTORS_PATH.write_text(text)
        for rel, data in seeds.items():
            path = SEEDS_DIR / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        print(f"wrote {VECTORS_PATH} and {len(seeds)} fuzz seeds under {SEEDS_DIR}")
    elif args.check:
        stale = [str(VECTORS_PATH)] if not VECTORS_PATH.exists() or VECTORS_PATH.read_text() != text else []
        stale += [str(SEEDS_DIR / rel) for rel, data in seeds.items()
                  if not (SEEDS_DIR / rel).exists() or (SEEDS_DIR / rel).read_bytes() != data]
        if stale:
            print(f"out of date: {', '.join(stale)}; run python -m protocol.vector_cases --write", file=sys.stderr)
            return 1
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
