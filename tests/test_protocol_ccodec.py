"""The C-extension codec (protocol/ccodec.py over protocol/c/build/_hilcodec*.so, the firmware's
hil_proto.c) held to what the Python codec is held to: frames built by hand from SPEC.md, the
shared vector file (protocol/vectors/, through protocol/vector_file.py), the Python decoder's
fuzz properties (tests/test_protocol_fuzz.py, run again with the C classes), and hypothesis
parity with the Python codec on random messages, out-of-range fields and random garbage streams,
chunk by chunk, counters included."""
from __future__ import annotations

import importlib
import os
import random
import struct
import subprocess
import threading
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

import protocol
from protocol import codec as py
from protocol.messages import (
    Command, Duty, Fault, Gates, Heartbeat, Hello, ParamGet, ParamSet, ParamValue, Sample, SampleSensors, Shutdown,
    Status, Telemetry,
)
from protocol import vector_file

try:  # tests/ as a package, or as a plain directory on sys.path
    from tests import test_protocol_fuzz as fuzz
except ImportError:
    import test_protocol_fuzz as fuzz

MESSAGES, SETTINGS = fuzz.MESSAGES, fuzz.SETTINGS
C_DIR = Path(__file__).resolve().parent.parent / "protocol" / "c"
# Every vector file in protocol/vectors/ (generated cases and the set built by hand from SPEC.md).
_PATHS = (vector_file.vector_paths() if hasattr(vector_file, "vector_paths") else [vector_file.VECTORS_PATH])
FILES = {path.stem: vector_file.load(path) for path in _PATHS}
VECTOR_MESSAGES = [(f, v) for f, vs in FILES.items() for v in vs.messages.values()]
REJECTS = [(f, r) for f, vs in FILES.items() for r in vs.rejects]
SERIAL = [(f, s) for f, vs in FILES.items() for s in vs.serial_streams]


def _ids(items):
    return [f"{f}:{x.name}" for f, x in items]
EXTRA = ("last_seq", "last_bad_version", "buffered")
_lock = threading.Lock()


@pytest.fixture(scope="module")
def cc():
    """protocol.ccodec, its extension built from the current sources (make ext), unless
    HIL_CCODEC_PATH names another build (make ext-san)."""
    if not os.environ.get("HIL_CCODEC_PATH"):
        with _lock:
            proc = subprocess.run(["make", "-s", "-C", str(C_DIR), "ext"], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stdout + proc.stderr
    from protocol import ccodec
    if not ccodec.AVAILABLE:  # imported before the build
        ccodec = importlib.reload(ccodec)
    assert ccodec.AVAILABLE, ccodec.UNAVAILABLE_REASON
    return ccodec


def state(dec) -> dict:
    return dec.counters | {k: getattr(dec, k) for k in EXTRA}


# ---------------------------------------------------------------- frames by hand (SPEC.md)

def crc_bitwise(data: bytes) -> int:
    """CRC-16/CCITT-FALSE bit by bit: poly 0x1021, init 0xFFFF, no reflection, no final xor."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
    return crc


def frame_by_hand(header: bytes, payload: bytes) -> bytes:
    body = header + payload
    body += struct.pack("<H", crc_bitwise(body))
    # COBS for bodies under 254 bytes: each zero-free run becomes (length + 1, run)
    return b"".join(bytes([len(run) + 1]) + run for run in body.split(b"\x00")) + b"\x00"


def test_crc_check_value(cc):
    assert cc.crc16(b"123456789") == 0x29B1
    assert cc.crc16(b"") == 0xFFFF
    assert cc.crc16(bytearray(b"\x01\x03\x08\x05")) == crc_bitwise(b"\x01\x03\x08\x05")


def test_crc_four_bytes_a_step_equals_bit_by_bit_for_every_length_and_table_entry(cc):
    """hil_crc16 takes four bytes a step through four tables, then the tail one at a time:
    every length 0-40 (each tail, several steps), and data that sends every byte value through
    each of the four table positions, against the bit-by-bit definition."""
    rng = random.Random(16)
    data = bytes(rng.randrange(256) for _ in range(40))
    for n in range(41):
        assert cc.crc16(data[:n]) == crc_bitwise(data[:n]), n
    for value in range(256):
        for at in range(4):
            block = bytearray(rng.randrange(256) for _ in range(9))
            block[at] = value
            assert cc.crc16(bytes(block)) == crc_bitwise(bytes(block)), (value, at)


def test_the_crc_tables_in_hil_proto_c_are_the_generators():
    import runpy

    gen = runpy.run_path(str(Path(__file__).resolve().parent.parent / "protocol" / "c" / "crc_tables.py"))
    source = (Path(__file__).resolve().parent.parent / "protocol" / "c" / "hil_proto.c").read_text()
    assert "\n".join(gen["c_lines"]()) in source


def test_gates_frame_by_hand(cc):
    expected = frame_by_hand(bytes([1, 3, 8, 5]), struct.pack("<I", 123_456) + bytes([0x29]))
    assert cc.encode_frame(Gates(123_456, 0x29), 8) == expected
    assert cc.encode_frame(Gates(123_456, 0x29), 8 + 256 * 3) == expected  # seq is taken mod 256
    dec = cc.StreamDecoder()
    assert dec.feed(expected) == [Gates(123_456, 0x29)]
    assert dec.last_seq == 8


def test_sample_frame_by_hand(cc):
    """adc_i1 bits 0-11, adc_i2 12-23, adc_vdc 24-35, status 36-39 of a 40-bit little-endian field;
    the period 0x00000100 puts zeros in the body, so COBS has work to do."""
    payload = bytes([0x00, 0x01, 0x00, 0x00, 0xBC, 0x3A, 0x12, 0x56, 0x94, 0xEF, 0xBE])
    expected = frame_by_hand(bytes([1, 2, 200, 11]), payload)
    msg = Sample(0x100, 0xABC, 0x123, 0x456, 0xBEEF, 0x9)
    assert cc.encode_frame(msg, 200) == expected
    (got,) = cc.StreamDecoder().feed(expected)
    assert got == msg and type(got) is Sample


def test_stream_by_hand(cc):
    """A bad CRC, a frame of version 2, a sequence jump of 3 and an overlong run, each counted."""
    good0 = frame_by_hand(bytes([1, 12, 0, 4]), struct.pack("<I", 7))       # HEARTBEAT seq 0
    good4 = frame_by_hand(bytes([1, 12, 4, 4]), struct.pack("<I", 8))       # seq 4: 3 missing
    bad_crc = bytearray(good0)
    bad_crc[5] ^= 0x01                                                     # a payload byte
    v2 = frame_by_hand(bytes([2, 12, 1, 4]), struct.pack("<I", 9))
    overlong = bytes([0xFF]) * 80 + b"\x00"
    stream = good0 + bytes(bad_crc) + v2 + overlong + good4
    dec = cc.StreamDecoder()
    assert dec.feed(stream) == [Heartbeat(7), Heartbeat(8)]
    assert dec.counters == {"frames_ok": 2, "crc_errors": 1, "framing_errors": 1, "seq_gaps": 3,
                            "unknown_types": 0, "version_errors": 1, "length_errors": 0}
    assert (dec.last_seq, dec.last_bad_version, dec.buffered) == (4, 2, 0)


# ---------------------------------------------------------------- the shared vectors

def test_vector_files_were_found():
    assert VECTOR_MESSAGES and SERIAL and REJECTS, _PATHS


@pytest.mark.parametrize("f, v", VECTOR_MESSAGES, ids=_ids(VECTOR_MESSAGES))
def test_vector_message(cc, f, v):
    assert cc.encode_frame(v.msg, v.seq) == v.serial
    enc = cc.FrameEncoder(v.seq)
    assert enc.encode(v.msg) == v.serial
    assert enc.seq == (v.seq + 1) & 0xFF
    dec = cc.StreamDecoder()
    assert dec.feed(v.serial[:-1]) == []
    assert dec.buffered == len(v.serial) - 1
    got = dec.feed(v.serial[-1:])
    assert got == [v.msg] and type(got[0]) is type(v.msg)
    assert dec.last_seq == v.seq
    assert dec.counters == dict.fromkeys(py.COUNTER_NAMES, 0) | {"frames_ok": 1}


@pytest.mark.parametrize("f, r", REJECTS, ids=_ids(REJECTS))
def test_vector_reject(cc, f, r):
    with pytest.raises(py.ProtocolError):
        cc.encode_frame(r.msg, 0)
    enc = cc.FrameEncoder(5)
    with pytest.raises(py.ProtocolError):
        enc.encode(r.msg)
    assert enc.seq == 5  # a message that failed to encode does not use a number


def _check_serial(cc, f, stream, chunks):
    dec = cc.StreamDecoder()
    got = []
    for chunk in chunks:
        got += dec.feed(chunk)
        assert dec.buffered <= py.MAX_ENCODED_SEGMENT
    assert got == [FILES[f].messages[n].msg for n in stream.yields]
    want = dict.fromkeys(py.COUNTER_NAMES + ("last_bad_version",), 0) | stream.counters
    assert dec.counters | {"last_bad_version": dec.last_bad_version} == want


@pytest.mark.parametrize("f, s", SERIAL, ids=_ids(SERIAL))
def test_vector_stream_whole(cc, f, s):
    _check_serial(cc, f, s, [s.data])


@pytest.mark.parametrize("f, s", SERIAL, ids=_ids(SERIAL))
def test_vector_stream_byte_by_byte(cc, f, s):
    _check_serial(cc, f, s, [s.data[i:i + 1] for i in range(len(s.data))])


@pytest.mark.parametrize("f, s", SERIAL, ids=_ids(SERIAL))
def test_vector_stream_random_chunks(cc, f, s):
    rng = random.Random(s.name)
    cuts = sorted(rng.sample(range(1, len(s.data)), min(len(s.data) - 1, 12)))
    bounds = [0, *cuts, len(s.data)]
    _check_serial(cc, f, s, [bytearray(s.data[a:b]) for a, b in zip(bounds, bounds[1:])])


# ---------------------------------------------------------------- the Python decoder's fuzzers, in C

@pytest.fixture
def fuzz_with_c(cc, monkeypatch):
    for name in ("StreamDecoder", "FrameEncoder", "encode_frame"):
        monkeypatch.setattr(fuzz, name, getattr(cc, name))
    return fuzz


@pytest.mark.parametrize("name", ["test_serial_round_trip", "test_garbage_between_frames_costs_no_untouched_frame",
                                  "test_any_bytes_one_event_per_candidate_frame",
                                  "test_corrupted_frame_is_counted_not_guessed"])
def test_python_fuzzer_on_c_codec(fuzz_with_c, name):
    getattr(fuzz_with_c, name)()


def test_fuzzers_really_use_the_c_codec(fuzz_with_c, cc):
    assert fuzz_with_c.StreamDecoder is cc.StreamDecoder is not py.StreamDecoder


# ---------------------------------------------------------------- parity with the Python codec

@SETTINGS
@given(msg=MESSAGES, seq=st.integers(-300, 600))
def test_same_frames(cc, msg, seq):
    frame = py.encode_frame(msg, seq)
    assert cc.encode_frame(msg, seq) == frame
    enc = cc.FrameEncoder(seq)
    assert enc.encode(msg) == frame
    (got,) = cc.StreamDecoder().feed(frame)
    assert got == msg and type(got) is type(msg) and hash(got) == hash(msg)


def _wide(n):
    return st.integers(-5, (1 << n) + 5)


FLOATISH = st.one_of(st.floats(allow_nan=False), st.integers(-(1 << 130), 1 << 130), st.just("x"))
ODD_MESSAGES = st.one_of(  # fields out of range or of the wrong type: the same bytes or the same error
    st.builds(Sample, _wide(32), _wide(12), _wide(12), _wide(12), _wide(16), _wide(4)),
    st.builds(Gates, _wide(32), st.one_of(_wide(8), st.just(1.0), st.booleans())),
    st.builds(Duty, _wide(32), st.one_of(st.tuples(_wide(16), _wide(16), _wide(16)),
                                         st.lists(_wide(16), min_size=3, max_size=3))),
    st.builds(Hello, _wide(8), _wide(8), _wide(16), _wide(32), st.integers(-1, 45), st.binary(max_size=45)),
    st.builds(Command, _wide(8), _wide(8), FLOATISH, FLOATISH, FLOATISH),
    st.builds(ParamSet, _wide(16), FLOATISH),
    st.builds(ParamValue, _wide(16), _wide(8), FLOATISH),
    st.builds(Status, _wide(32), _wide(8), _wide(16)),
    st.builds(Fault, _wide(32), _wide(16), FLOATISH),
    st.builds(Heartbeat, _wide(32)),
    st.builds(ParamGet, _wide(16)),
    st.builds(lambda head, values: SampleSensors(*head, *values),  # the fields of clear bits too
              st.tuples(_wide(32), st.integers(-2, 0x402), _wide(4)),
              st.lists(st.one_of(_wide(16), st.integers(-2, 9), st.just(1.0)), min_size=13, max_size=13)),
    st.just(3), st.just(None),
)


def _outcome(fn, *args):
    try:
        return fn(*args)
    except py.ProtocolError as exc:
        return ("ProtocolError", str(exc))


@SETTINGS
@given(msg=ODD_MESSAGES, seq=st.integers(0, 255))
def test_same_result_for_odd_fields(cc, msg, seq):
    assert _outcome(cc.encode_frame, msg, seq) == _outcome(py.encode_frame, msg, seq)
    enc = cc.FrameEncoder(seq)
    out = _outcome(enc.encode, msg)
    assert out == _outcome(py.FrameEncoder(seq).encode, msg)
    assert enc.seq == (seq + (not isinstance(out, tuple))) & 0xFF


def _piece(msg, kind, seq, noise, pos):
    frame = py.encode_frame(msg, seq)
    if kind == "frame":
        return frame
    if kind == "flip":  # a byte changed, the delimiter kept
        b = bytearray(frame)
        i = pos % (len(b) - 1)
        b[i] = (b[i] ^ noise[0]) or 1
        return bytes(b)
    if kind == "cut":
        return frame[: pos % len(frame)]
    if kind == "noise":
        return noise
    if kind == "long":
        return bytes((x or 1) for x in noise) * 2
    return b"\x00"


PIECES = st.lists(st.tuples(MESSAGES, st.sampled_from(["frame", "frame", "frame", "flip", "cut", "noise", "long",
                                                       "zero"]),
                            st.integers(0, 255), st.binary(min_size=1, max_size=80), st.integers(0, 1000)),
                  max_size=16)


@SETTINGS
@given(pieces=PIECES, cuts=st.lists(st.integers(0, 10_000), max_size=12),
       resets=st.lists(st.integers(0, 20), max_size=2), in_order=st.booleans())
def test_same_decoding_chunk_by_chunk(cc, pieces, cuts, resets, in_order):
    """Frames (numbered in order, or as drawn), damaged frames, cut frames, noise, overlong runs
    and delimiters, fed in random chunks with an occasional reset(): after every chunk the same
    messages, counters, last_seq, last_bad_version and buffered bytes."""
    if in_order:
        pieces = [(m, kind, k, noise, pos) for k, (m, kind, _, noise, pos) in enumerate(pieces)]
    data = b"".join(_piece(*p) for p in pieces)
    pd, cd = py.StreamDecoder(), cc.StreamDecoder()
    for i, chunk in enumerate(fuzz._chunks(data, cuts)):
        if i in resets:
            pd.reset()
            cd.reset()
        got = cd.feed(chunk)
        assert got == pd.feed(chunk)
        assert all(type(m) in (type(p) for p, *_ in pieces) for m in got)
        assert state(cd) == state(pd)


@SETTINGS
@given(data=st.binary(max_size=1500), cuts=st.lists(st.integers(0, 10_000), max_size=20))
def test_same_decoding_of_random_bytes(cc, data, cuts):
    pd, cd = py.StreamDecoder(), cc.StreamDecoder()
    for chunk in fuzz._chunks(data, cuts):
        assert cd.feed(memoryview(chunk)) == pd.feed(chunk)
        assert state(cd) == state(pd)


# ---------------------------------------------------------------- the decoder object

def test_counters_do_not_wrap_at_32_bits(cc):
    frame = py.encode_frame(Heartbeat(1), 0)
    pd, cd = py.StreamDecoder(), cc.StreamDecoder()
    for dec in (pd, cd):
        dec.frames_ok = (1 << 32) - 1
        dec.seq_gaps = 1 << 40
        dec.feed(frame)
        dec.feed(py.encode_frame(Heartbeat(2), 10))
    assert state(cd) == state(pd)
    assert cd.frames_ok == (1 << 32) + 1 and cd.seq_gaps == (1 << 40) + 9


def test_reset_forgets_partial_frame_and_sequence(cc):
    frame = py.encode_frame(Gates(1, 2), 9)
    for dec in (py.StreamDecoder(), cc.StreamDecoder()):
        dec.feed(py.encode_frame(Gates(0, 1), 3))
        dec.feed(frame[:4])
        assert dec.buffered == 4
        dec.reset()
        assert dec.buffered == 0 and dec.last_seq == 3
        assert dec.feed(frame) == [Gates(1, 2)]
        assert dec.seq_gaps == 0 and dec.frames_ok == 2  # no gap counted across the reset


def test_feed_refuses_what_is_not_bytes(cc):
    for dec in (py.StreamDecoder(), cc.StreamDecoder()):
        with pytest.raises(TypeError):
            dec.feed("not bytes")


def test_decoded_messages_are_frozen(cc):
    (msg,) = cc.StreamDecoder().feed(py.encode_frame(Sample(1, 2, 3, 4, 5, 6), 0))
    with pytest.raises(AttributeError):
        msg.period = 2


def test_messages_survive_the_decoder(cc):
    """Objects made by the extension are complete: they outlive the decoder and the input."""
    dec = cc.StreamDecoder()
    msgs = dec.feed(b"".join(py.encode_frame(Telemetry(k, 1, 2, 1, 5, *[k / 8] * 12), k) for k in range(50)))
    del dec
    import gc
    gc.collect()
    assert [m.period for m in msgs] == list(range(50)) and msgs[7].torque_ref_nm == 7 / 8


def test_shutdown_and_hello_round_trip(cc):
    for msg in (Shutdown(), Hello(1, 1, 7, 50_000, name="stub"), Hello(1, 0, 0, 0)):
        assert cc.StreamDecoder().feed(cc.encode_frame(msg, 1)) == [msg]


# ---------------------------------------------------------------- the selector

def test_codec_impl_selects(cc, monkeypatch):
    monkeypatch.delenv(protocol.CODEC_ENV, raising=False)
    assert protocol.codec_impl() is cc
    monkeypatch.setenv(protocol.CODEC_ENV, "python")
    assert protocol.codec_impl() is py
    monkeypatch.setenv(protocol.CODEC_ENV, "C")
    assert protocol.codec_impl() is cc
    monkeypatch.setenv(protocol.CODEC_ENV, "rust")
    with pytest.raises(ValueError, match="HIL_CODEC"):
        protocol.codec_impl()


def test_codec_impl_without_the_extension(cc, monkeypatch):
    monkeypatch.setattr(cc, "AVAILABLE", False)
    monkeypatch.setattr(cc, "UNAVAILABLE_REASON", "not built: run make -C protocol/c ext")
    monkeypatch.delenv(protocol.CODEC_ENV, raising=False)
    assert protocol.codec_impl() is py  # the fallback
    monkeypatch.setenv(protocol.CODEC_ENV, "c")
    with pytest.raises(ImportError, match="make -C protocol/c ext"):
        protocol.codec_impl()


def test_missing_extension_names_the_build(tmp_path):
    """Without the built file, protocol.ccodec still imports and says how to build it."""
    code = ("import protocol.ccodec as c; assert not c.AVAILABLE, c.UNAVAILABLE_REASON\n"
            "try:\n    from protocol.ccodec import StreamDecoder\nexcept ImportError as e:\n    print(e)\n")
    env = os.environ | {"HIL_CCODEC_PATH": str(tmp_path / "none.so")}
    proc = subprocess.run([os.sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          cwd=Path(__file__).resolve().parent.parent)
    assert proc.returncode == 0, proc.stderr
    assert "make -C protocol/c ext" in proc.stdout
