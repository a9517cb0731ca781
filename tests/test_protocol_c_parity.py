"""The C codec (protocol/c, through build/libhilproto.so) against the Python codec on inputs
hypothesis makes up: the same bytes out, the same messages and counters in."""
from __future__ import annotations

import ctypes
import subprocess
import threading
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.can_mapping import CanReassembler, can_pack
from protocol.codec import (
    ProtocolError, StreamDecoder, decode_payload, encode_frame, encode_payload, sample_sensors_size,
)
from protocol.can_mapping import COUNTER_NAMES as CAN_COUNTER_NAMES
from protocol.codec import COUNTER_NAMES
try:  # tests/ as a package, or as a plain directory on sys.path
    from tests.test_protocol_fuzz import MESSAGES, SETTINGS
except ImportError:
    from test_protocol_fuzz import MESSAGES, SETTINGS

C_DIR = Path(__file__).resolve().parent.parent / "protocol" / "c"
LIBRARY = C_DIR / "build" / "libhilproto.so"
_lock = threading.Lock()


@pytest.fixture(scope="module")
def lib():
    with _lock:
        proc = subprocess.run(["make", "-s", "-C", str(C_DIR), "build/libhilproto.so"], capture_output=True,
                              text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lib = ctypes.CDLL(str(LIBRARY))
    c_u8, c_sz, buf = ctypes.c_uint8, ctypes.c_size_t, ctypes.c_char_p
    lib.hil_shim_frame_from_payload.argtypes = [c_u8, c_u8, buf, c_sz, buf, c_sz]
    lib.hil_shim_can_from_payload.argtypes = [c_u8, c_u8, c_u8, ctypes.c_uint16, buf, c_sz, buf, c_sz]
    lib.hil_shim_decode_stream.argtypes = [buf, c_sz, buf, c_sz, ctypes.POINTER(ctypes.c_uint32)]
    lib.hil_shim_decode_stream.restype = ctypes.c_long
    lib.hil_shim_can_stream.argtypes = [ctypes.c_uint16, buf, c_sz, buf, c_sz, ctypes.POINTER(ctypes.c_uint32)]
    lib.hil_shim_can_stream.restype = ctypes.c_long
    lib.hil_crc16.argtypes = [buf, c_sz]
    lib.hil_crc16.restype = ctypes.c_uint16
    return lib


def c_frame(lib, msg, seq: int) -> bytes:
    payload = encode_payload(msg)
    out = ctypes.create_string_buffer(128)
    n = lib.hil_shim_frame_from_payload(int(msg.TYPE), seq, payload, len(payload), out, 128)
    assert n > 0, f"C refused {msg}: {n}"
    return out.raw[:n]


def c_can(lib, msg, role: int, base: int, seq: int) -> list[tuple[int, bytes]]:
    payload = encode_payload(msg)
    out = ctypes.create_string_buffer(11 * 16)
    n = lib.hil_shim_can_from_payload(int(msg.TYPE), seq, role, base, payload, len(payload), out, 11 * 16)
    assert n > 0, f"C refused {msg}: {n}"
    recs = [out.raw[11 * i:11 * i + 11] for i in range(n)]
    return [(r[0] | r[1] << 8, r[3:3 + r[2]]) for r in recs]


def c_decode(lib, data: bytes):
    out = ctypes.create_string_buffer(80 * (len(data) // 6 + 1))
    counters = (ctypes.c_uint32 * 8)()
    n = lib.hil_shim_decode_stream(data, len(data), out, len(out), counters)
    assert n >= 0
    msgs = StreamDecoder().feed(out.raw[:n])
    return msgs, dict(zip(COUNTER_NAMES + ("last_bad_version",), counters))


def c_can_stream(lib, base: int, frames: list[tuple[int, bytes, int]]):
    records = b"".join(bytes((i & 0xFF, i >> 8, dlc)) + d[:8].ljust(8, b"\x00") for i, d, dlc in frames)
    out = ctypes.create_string_buffer(80 * (len(frames) + 1))
    counters = (ctypes.c_uint32 * 5)()
    n = lib.hil_shim_can_stream(base, records, len(frames), out, len(out), counters)
    assert n >= 0
    raw, got = out.raw[:n], []
    while raw:  # role byte, then one serial frame
        end = raw.index(b"\x00", 1) + 1
        (msg,) = StreamDecoder().feed(raw[1:end])
        got.append((msg, raw[0]))
        raw = raw[end:]
    return got, dict(zip(CAN_COUNTER_NAMES, counters))


def test_crc_check_value(lib):
    assert lib.hil_crc16(b"123456789", 9) == 0x29B1


@SETTINGS
@given(msg=MESSAGES, seq=st.integers(0, 255))
def test_same_serial_bytes(lib, msg, seq):
    assert c_frame(lib, msg, seq) == encode_frame(msg, seq)


@SETTINGS
@given(msg=MESSAGES, role=st.integers(0, 1), base=st.integers(0, 0x7C0), seq=st.integers(0, 255))
def test_same_can_frames(lib, msg, role, base, seq):
    assert c_can(lib, msg, role, base, seq) == can_pack(msg, role, base, seq)


# Streams built from pieces: valid frames, frames with a byte changed, frames cut short,
# random bytes, delimiters.
def _piece(draw_msg, kind, seq, noise, pos):
    frame = encode_frame(draw_msg, seq)
    if kind == "frame":
        return frame
    if kind == "flip":
        b = bytearray(frame)
        i = pos % (len(b) - 1)
        b[i] = (b[i] ^ noise[0]) or 1 if noise else b[i]
        return bytes(b)
    if kind == "cut":
        return frame[: pos % len(frame)]
    if kind == "noise":
        return noise
    return b"\x00"


PIECES = st.lists(st.tuples(MESSAGES, st.sampled_from(["frame", "frame", "flip", "cut", "noise", "zero"]),
                            st.integers(0, 255), st.binary(min_size=1, max_size=80), st.integers(0, 1000)),
                  max_size=14)


@SETTINGS
@given(pieces=PIECES)
def test_same_stream_decoding(lib, pieces):
    data = b"".join(_piece(*p) for p in pieces)
    py = StreamDecoder()
    py_msgs = py.feed(data)
    c_msgs, c_counters = c_decode(lib, data)
    assert c_msgs == py_msgs
    assert c_counters == py.counters | {"last_bad_version": py.last_bad_version}


@SETTINGS
@given(data=st.binary(max_size=600))
def test_same_counters_on_random_bytes(lib, data):
    py = StreamDecoder()
    py_msgs = py.feed(data)
    c_msgs, c_counters = c_decode(lib, data)
    assert c_msgs == py_msgs
    assert c_counters == py.counters | {"last_bad_version": py.last_bad_version}


CAN_ITEMS = st.lists(st.one_of(
    st.tuples(st.integers(0x0F0, 0x150), st.binary(max_size=8), st.none()),
    st.tuples(MESSAGES, st.integers(0, 1), st.integers(0, 15)),
), max_size=12)


@SETTINGS
@given(items=CAN_ITEMS, drop=st.lists(st.integers(0, 200), max_size=3))
def test_same_can_reassembly(lib, items, drop):
    frames = []
    for a, b, c in items:
        if c is None:
            frames.append((a, b))
        else:
            frames += can_pack(a, b, 0x100, c)
    frames = [f for k, f in enumerate(frames) if k not in drop]  # lost frames
    rx = CanReassembler(0x100)
    py = [r for r in (rx.feed(i, d) for i, d in frames) if r is not None]
    got, counters = c_can_stream(lib, 0x100, [(i, d, len(d)) for i, d in frames])
    assert got == py
    assert counters == rx.counters


# SAMPLE_SENSORS payloads of any set (reserved bits too), mostly of the set's length, else a byte
# off: the same refusal, or the same message (reserved field bits dropped alike).
def _sample_sensors_payload(period, sensor_set, status, body, off):
    known = sensor_set & 0x3FF
    length = sample_sensors_size(known) - 7 + off
    return (period.to_bytes(4, "little") + sensor_set.to_bytes(2, "little") + bytes((status,))
            + body[:max(length, 0)])


SAMPLE_SENSORS_PAYLOADS = st.builds(
    _sample_sensors_payload, st.integers(0, 0xFFFFFFFF),
    st.one_of(st.integers(0, 0x3FF), st.integers(0, 0x3FF), st.integers(0, 0xFFFF)), st.integers(0, 0xFF),
    st.binary(min_size=32, max_size=32), st.sampled_from([0, 0, 0, -1, 1]))


@SETTINGS
@given(payload=st.one_of(SAMPLE_SENSORS_PAYLOADS, st.binary(max_size=8)), seq=st.integers(0, 255))
def test_same_sample_sensors_payload_decoding(lib, payload, seq):
    out = ctypes.create_string_buffer(128)
    n = lib.hil_shim_frame_from_payload(0x10, seq, payload, len(payload), out, 128)
    try:
        py = encode_frame(decode_payload(0x10, payload), seq)
    except ProtocolError:
        assert n == -1  # HIL_ERR_LENGTH
    else:
        assert n > 0 and out.raw[:n] == py


def test_dlc_above_8_handled_alike(lib):
    rx = CanReassembler(0x100)
    assert rx.feed(0x126, bytes(12)) is None
    got, counters = c_can_stream(lib, 0x100, [(0x126, bytes(8), 12)])
    assert got == [] and counters == rx.counters and counters["length_errors"] == 1
