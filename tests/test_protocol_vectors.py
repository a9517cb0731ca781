"""The Python codec against the shared vectors (protocol/vectors/vectors.txt).

The C codec is held to the same file by protocol/c/tests/test_vectors.c, and
the two are compared directly in test_protocol_c_parity.py.
"""
from __future__ import annotations

import random
import struct

import pytest

from protocol.can_mapping import CanReassembler, can_pack
from protocol.codec import (
    COUNTER_NAMES, ProtocolError, StreamDecoder, crc16, encode_frame, encode_payload,
)
from protocol.can_mapping import COUNTER_NAMES as CAN_COUNTER_NAMES
from protocol.messages import Gates, Sample
from protocol.vector_cases import build, fuzz_seeds, SEEDS_DIR
from protocol.vector_file import VECTORS_PATH, dump, load

VECTORS = load()
MESSAGES = list(VECTORS.messages.values())
SERIAL = VECTORS.serial_streams
CAN = VECTORS.can_streams


def test_vector_file_is_current():
    """The committed file (and the fuzz seeds) are what the hand-written cases produce."""
    vs = build()
    assert VECTORS_PATH.read_text() == dump(vs), "run: python -m protocol.vector_cases --write"
    for rel, data in fuzz_seeds(vs).items():
        assert (SEEDS_DIR / rel).read_bytes() == data, rel


def test_every_message_type_has_a_vector():
    from protocol.messages import MsgType

    assert {v.msg.TYPE for v in MESSAGES} == set(MsgType)


def test_crc_check_value():
    assert crc16(b"123456789") == 0x29B1
    assert crc16(b"") == 0xFFFF


def test_gates_frame_by_hand():
    """One frame assembled from SPEC.md alone, independent of the codec's own tables."""
    raw = bytes([1, 3, 8, 5]) + struct.pack("<I", 123_456) + bytes([0x29])
    crc = 0xFFFF
    for byte in raw:  # bitwise CRC-16/CCITT-FALSE
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
    body = raw + struct.pack("<H", crc)
    # COBS: each zero-free run becomes (length + 1, run); the zeros themselves are implied
    expected = b"".join(bytes([len(run) + 1]) + run for run in body.split(b"\x00")) + b"\x00"
    assert encode_frame(Gates(123_456, 0x29), 8) == expected
    assert VECTORS.messages["gates_mid"].serial == expected


def test_sample_packing_by_hand():
    """adc_i1 bits 0-11, adc_i2 12-23, adc_vdc 24-35, status 36-39 of a 40-bit LE field."""
    payload = encode_payload(Sample(0x01020304, 0xABC, 0x123, 0x456, 0xBEEF, 0x9))
    assert payload == bytes([0x04, 0x03, 0x02, 0x01, 0xBC, 0x3A, 0x12, 0x56, 0x94, 0xEF, 0xBE])


@pytest.mark.parametrize("v", MESSAGES, ids=[v.name for v in MESSAGES])
def test_message_serial(v):
    assert encode_frame(v.msg, v.seq) == v.serial
    dec = StreamDecoder()
    assert dec.feed(v.serial[:-1]) == []
    assert dec.feed(v.serial[-1:]) == [v.msg]
    assert dec.last_seq == v.seq
    assert dec.counters == dict.fromkeys(COUNTER_NAMES, 0) | {"frames_ok": 1}


@pytest.mark.parametrize("v", MESSAGES, ids=[v.name for v in MESSAGES])
def test_message_can(v):
    assert can_pack(v.msg, v.role, v.base_id, v.seq) == v.can
    rx = CanReassembler(v.base_id)
    results = [rx.feed(i, d) for i, d in v.can]
    assert results[:-1] == [None] * (len(results) - 1)
    expected = v.msg
    if v.can_fields:
        from dataclasses import replace

        expected = replace(v.msg, **v.can_fields)
    assert results[-1] == (expected, v.role)


@pytest.mark.parametrize("r", VECTORS.rejects, ids=[r.name for r in VECTORS.rejects])
def test_reject(r):
    with pytest.raises(ProtocolError):
        encode_payload(r.msg)
    with pytest.raises(ProtocolError):
        encode_frame(r.msg, 0)
    with pytest.raises(ProtocolError):
        can_pack(r.msg, 0)


def _check_serial(stream, chunks):
    dec = StreamDecoder()
    got = []
    for chunk in chunks:
        got += dec.feed(chunk)
        assert dec.buffered <= 71
    assert got == [VECTORS.messages[n].msg for n in stream.yields]
    want = dict.fromkeys(COUNTER_NAMES + ("last_bad_version",), 0) | stream.counters
    assert dec.counters | {"last_bad_version": dec.last_bad_version} == want


@pytest.mark.parametrize("s", SERIAL, ids=[s.name for s in SERIAL])
def test_serial_stream_whole(s):
    _check_serial(s, [s.data])


@pytest.mark.parametrize("s", SERIAL, ids=[s.name for s in SERIAL])
def test_serial_stream_byte_by_byte(s):
    _check_serial(s, [s.data[i:i + 1] for i in range(len(s.data))])


@pytest.mark.parametrize("s", SERIAL, ids=[s.name for s in SERIAL])
def test_serial_stream_random_chunks(s):
    rng = random.Random(s.name)
    cuts = sorted(rng.sample(range(1, len(s.data)), min(len(s.data) - 1, 12)))
    bounds = [0, *cuts, len(s.data)]
    _check_serial(s, [s.data[a:b] for a, b in zip(bounds, bounds[1:])])


@pytest.mark.parametrize("s", CAN, ids=[s.name for s in CAN])
def test_can_stream(s):
    rx = CanReassembler(s.base_id)
    got = [r for r in (rx.feed(i, d) for i, d in s.frames) if r is not None]
    assert got == [(VECTORS.messages[n].msg, role) for n, role in s.yields]
    assert rx.counters == dict.fromkeys(CAN_COUNTER_NAMES, 0) | s.counters
