"""Python codec API: the message classes mirror hil_proto.h, and bad input gets a clear error."""
from __future__ import annotations

import math
import re
import struct
from dataclasses import FrozenInstanceError, fields
from pathlib import Path

import pytest

import protocol.messages as messages
from protocol.codec import (
    MAX_ENCODED_FRAME, MAX_PAYLOAD, FrameEncoder, ProtocolError, StreamDecoder, decode_payload,
    encode_frame, encode_payload,
)
from protocol.messages import (
    MESSAGE_CLASSES, NAME_MAX, PROTOCOL_VERSION, Command, ControllerState, FaultCode, Gates, Hello,
    MsgType, NonFiniteQuantity, ParamId, ParamStatus, Role, Sample, SpeedSource, Telemetry,
)

HEADER = (Path(__file__).resolve().parent.parent / "protocol" / "c" / "hil_proto.h").read_text()


def _c_enum(c_name: str) -> dict[str, int]:
    body = re.search(r"typedef enum \{([^{}]*)\}\s*" + c_name + ";", HEADER).group(1)
    return {m.group(1): int(m.group(2), 0) for m in re.finditer(r"HIL_(\w+)\s*=\s*(0x[0-9A-Fa-f]+|\d+)", body)}


@pytest.mark.parametrize("c_name, prefix, py_enum", [
    ("hil_msg_type", "MSG_", MsgType), ("hil_role", "ROLE_", Role),
    ("hil_speed_source", "SPEED_", SpeedSource), ("hil_state", "STATE_", ControllerState),
    ("hil_fault_code", "FAULT_", FaultCode), ("hil_param_status", "PARAM_", ParamStatus),
    ("hil_param_id", "PARAM_", ParamId), ("hil_nonfinite_quantity", "NONFINITE_", NonFiniteQuantity),
])
def test_enums_match_the_c_header(c_name, prefix, py_enum):
    c = {k.removeprefix(prefix): v for k, v in _c_enum(c_name).items()}
    assert c == {m.name: m.value for m in py_enum}


def test_bit_constants_and_limits_match_the_c_header():
    defines = {m.group(1): int(m.group(2), 0)
               for m in re.finditer(r"#define HIL_((?:CAP|GATE|STATUS|CMD|LEGS?|SENSOR)_\w+)\s+(0x[0-9A-Fa-f]+|\d+)u",
                                    HEADER)}
    assert len(defines) == 33
    for name, value in defines.items():
        assert getattr(messages, name) == value, name
    assert re.search(r"#define HIL_PROTO_VERSION (\d+)u", HEADER).group(1) == str(PROTOCOL_VERSION)
    assert re.search(r"#define HIL_NAME_MAX (\d+)u", HEADER).group(1) == str(NAME_MAX)
    assert re.search(r"#define HIL_MAX_PAYLOAD (\d+)u", HEADER).group(1) == str(MAX_PAYLOAD)
    assert MAX_ENCODED_FRAME == 72  # the C test asserts HIL_MAX_ENCODED_FRAME == 72


@pytest.mark.parametrize("msg_type", [t for t in MsgType if t != MsgType.SHUTDOWN])
def test_field_names_are_the_c_struct_field_names(msg_type):
    struct_name = "hil_" + msg_type.name.lower()
    body = re.search(r"typedef struct \{([^{}]*)\}\s*" + struct_name + ";", HEADER).group(1)
    c_fields = re.findall(r"^\s*\w+\s+(\w+)(?:\[\w+\])?;", body, re.M)
    assert [f.name for f in fields(MESSAGE_CLASSES[msg_type])] == c_fields


def test_messages_are_frozen_and_hashable():
    s = Sample(1, 2, 3, 4, 5, 6)
    with pytest.raises(FrozenInstanceError):
        s.period = 2
    assert {s, Sample(1, 2, 3, 4, 5, 6)} == {s}


def test_hello_name_forms():
    assert Hello(1, 0, 0, 50_000, name="hil").name == b"hil"
    assert Hello(1, 0, 0, 50_000, name="hil").name_len == 3
    assert Hello(1, 0, 0, 50_000, 3, b"hil-bench") == Hello(1, 0, 0, 50_000, name=b"hil")
    with pytest.raises(ProtocolError, match="name_len 5 with a 3-byte name"):
        encode_payload(Hello(1, 0, 0, 0, 5, b"abc"))


@pytest.mark.parametrize("msg, pattern", [
    (Gates(2**32, 0), r"GATES\.period = 4294967296 is not an integer in 0\.\.4294967295"),
    (Gates(-1, 0), r"GATES\.period = -1"),
    (Gates(1, 256), r"GATES\.gates = 256"),
    (Sample(1, 4096, 0, 0, 0, 0), r"adc_i1=4096"),
    (Sample(1, 0, 0, 0, 0x10000, 0), r"SAMPLE\.encoder = 65536"),
    (Command(1, 0, 1e39, 0.0, 0.0), r"COMMAND\.speed_ref_rad_s = 1e\+39 does not fit a float32"),
    (Command(1, 0, "fast", 0.0, 0.0), r"COMMAND\.speed_ref_rad_s = 'fast' is not a number"),
    (Hello(1, 0, 0, 0, name=b"x" * 41), r"must be 0\.\.40 bytes"),
])
def test_encode_errors_name_the_field(msg, pattern):
    with pytest.raises(ProtocolError, match=pattern):
        encode_payload(msg)
    with pytest.raises(ProtocolError, match=pattern):
        FrameEncoder().encode(msg)


def test_encode_rejects_non_messages():
    with pytest.raises(ProtocolError, match="not a protocol message"):
        encode_frame(object(), 0)


def test_decode_payload_errors():
    with pytest.raises(ProtocolError, match="unknown message type 0x0e"):
        decode_payload(0x0E, b"")
    with pytest.raises(ProtocolError, match="GATES payload of 4 bytes; expected 5"):
        decode_payload(MsgType.GATES, bytes(4))
    with pytest.raises(ProtocolError, match="HELLO payload of 10 bytes"):
        decode_payload(MsgType.HELLO, bytes(8) + b"\x02x")


def test_encoder_sequence_wraps_and_failures_do_not_use_a_number():
    enc = FrameEncoder(first_seq=254)
    dec = StreamDecoder()
    for _ in range(3):
        dec.feed(enc.encode(Gates(0, 0)))
        with pytest.raises(ProtocolError):
            enc.encode(Gates(-1, 0))
    assert dec.last_seq == 0 and dec.seq_gaps == 0 and dec.frames_ok == 3


def test_floats_travel_as_float32_bit_patterns():
    nan_bits = 0x7FC01234  # a NaN with a payload survives bit for bit
    nan = struct.unpack("<f", struct.pack("<I", nan_bits))[0]
    t = Telemetry(1, 2, 3, 4, 5, nan, math.inf, -0.0, 0.1, *[1.5] * 8)
    (got,) = StreamDecoder().feed(encode_frame(t, 0))
    assert struct.pack("<f", got.speed_feedback_rad_s) == struct.pack("<I", nan_bits)
    assert got.speed_encoder_rad_s == math.inf
    assert math.copysign(1.0, got.speed_raw_rad_s) == -1.0
    assert got.speed_lpf_rad_s == struct.unpack("<f", struct.pack("<f", 0.1))[0] != 0.1
    assert encode_frame(got, 0) == encode_frame(t, 0)


def test_decoder_accepts_any_bytes_like():
    frame = encode_frame(Gates(5, 1), 0)
    assert StreamDecoder().feed(bytearray(frame)) == [Gates(5, 1)]
    assert StreamDecoder().feed(memoryview(frame)) == [Gates(5, 1)]


def test_decoder_reset_forgets_partial_frame_and_sequence():
    dec = StreamDecoder()
    frame = encode_frame(Gates(5, 1), 7)
    dec.feed(encode_frame(Gates(5, 1), 3))
    dec.feed(frame[:5])
    dec.reset()
    assert dec.feed(frame) == [Gates(5, 1)]
    assert dec.seq_gaps == 0 and dec.buffered == 0


def test_decoder_holds_at_most_one_frame_of_bytes():
    dec = StreamDecoder()
    for _ in range(100):
        dec.feed(b"\x55" * 1000)
        assert dec.buffered <= 71
    assert dec.feed(b"\x00" + encode_frame(Gates(1, 1), 0)) == [Gates(1, 1)]
    assert dec.framing_errors == 1
