"""DUTY_LEGS (SPEC 6.12, 7.2): the reserved leg bits and the 13-bit CAN period, in both codecs.

The byte-exact conformance is in protocol/vectors/handbuilt.txt (hb_duty_legs*), checked by
tests/test_protocol_vectors.py and protocol/c/tests; here what the vectors cannot hold: a message
with reserved bits set (serial carries it as is, CAN has no room and refuses it) and a long run of
periods through the 13-bit extension.
"""
from __future__ import annotations

import pytest

from protocol import ccodec
from protocol.can_mapping import CanReassembler, can_pack
from protocol.codec import ProtocolError, StreamDecoder, encode_frame, encode_payload
from protocol.messages import LEG_A, LEG_C, LEGS_ALL, MsgType, DutyLegs, Gates, Role

try:  # tests/ as a package, or as a plain directory on sys.path
    from tests.test_protocol_c_parity import c_can, c_can_stream, lib  # noqa: F401 - lib is a fixture
except ImportError:
    from test_protocol_c_parity import c_can, c_can_stream, lib  # noqa: F401

CONTROLLER = int(Role.CONTROLLER)


def test_serial_carries_the_whole_leg_byte_in_both_codecs():
    """Reserved bits 3-7 pass the serial codecs unchanged (as GATES bits 6-7 do): a frame stays its
    own canonical encoding, and the receiver ignores the bits (the plant reads bits 0-2)."""
    msg = DutyLegs(7, (1, 2, 3), 0xF8 | LEG_A)
    frame = encode_frame(msg, 3)
    assert StreamDecoder().feed(frame) == [msg]
    if ccodec.AVAILABLE:
        assert ccodec.encode_frame(msg, 3) == frame
        assert ccodec.StreamDecoder().feed(frame) == [msg]


def test_serial_refuses_a_leg_byte_that_is_not_a_byte():
    with pytest.raises(ProtocolError, match="DUTY_LEGS.leg_enable = 256"):
        encode_payload(DutyLegs(7, (1, 2, 3), 256))


def test_can_refuses_reserved_leg_bits_in_both_codecs(lib):
    """The CAN word has room for bits 0-2 only: a sender with a reserved bit set is refused,
    never silently cut."""
    msg = DutyLegs(7, (1, 2, 3), 0x08 | LEG_A)
    with pytest.raises(ProtocolError, match="reserved bits 3-7 must be 0"):
        can_pack(msg, CONTROLLER)
    with pytest.raises(AssertionError, match="C refused"):
        c_can(lib, msg, CONTROLLER, 0x100, 0)
    good = DutyLegs(7, (1, 2, 3), LEGS_ALL)
    assert c_can(lib, good, CONTROLLER, 0x100, 0) == can_pack(good, CONTROLLER)


def test_can_period_extension_over_13_bits_in_both_codecs(lib):
    """A board answering every 1000 periods for 100 000 periods: each DUTY_LEGS carries only
    period & 0x1FFF, and both receivers give back the full period (SPEC 7.3, n = 13), as long as
    one full period (GATES) started the count."""
    sent = [Gates(0, 0)] + [DutyLegs(p, (p & 0xFFFF, 0, 65535), p // 1000 % 8)
                            for p in range(1000, 100_001, 1000)]
    frames = [f for m in sent for f in can_pack(m, CONTROLLER)]
    rx = CanReassembler()
    got = [rx.feed(i, d) for i, d in frames]
    assert [g[0] for g in got] == sent
    c_got, c_counters = c_can_stream(lib, 0x100, [(i, d, len(d)) for i, d in frames])
    assert [m for m, _ in c_got] == sent and c_counters["messages_ok"] == len(sent)


def test_duty_legs_is_type_0x0f_and_0x0e_stays_unknown():
    """0x0E is the unknown type of the vector files (SPEC 5): it must stay undefined."""
    assert MsgType.DUTY_LEGS == 0x0F and 0x0E not in {int(t) for t in MsgType}
    assert LEG_C == 0x04


def test_spec_example_is_the_handbuilt_vector():
    """SPEC 10's DUTY_LEGS example, as printed, is hb_duty_legs of handbuilt.txt byte for byte."""
    import re
    from pathlib import Path

    from protocol.vector_file import HANDBUILT_PATH, load

    spec = (Path(__file__).resolve().parents[1] / "protocol" / "SPEC.md").read_text()
    example = spec[spec.index("DUTY_LEGS, period 123456"):spec.index("(These bytes are in the vector")]
    wire = re.search(r"^wire  ([0-9A-F ]+)$", example, re.M).group(1)
    can = re.search(r"identifier 0x12F, data\s+`([0-9A-F ]+)`", example).group(1)
    vector = load(HANDBUILT_PATH).messages["hb_duty_legs"]
    assert bytes.fromhex(wire) == vector.serial
    assert [(0x12F, bytes.fromhex(can))] == vector.can
