"""Property tests (hypothesis) of the Python decoders: garbage never raises, never grows the
buffers, and never costs a valid frame that it did not touch."""
from __future__ import annotations

from dataclasses import replace

from cobs.cobs import encode as cobs_encode
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.can_mapping import CanReassembler, can_pack
from protocol.codec import (
    MAX_ENCODED_SEGMENT, SENSOR_FIELDS, FrameEncoder, StreamDecoder, crc16, encode_frame, encode_payload,
)
from protocol.messages import (
    SENSOR_SET_ALL, Command, Duty, DutyLegs, Fault, Gates, Heartbeat, Hello, ParamGet, ParamSet, ParamValue,
    Sample, SampleSensors, Shutdown, Status, Telemetry,
)

# Deterministic (derandomize): the same examples on every run and machine.
SETTINGS = settings(max_examples=250, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

u8, u16, u32 = st.integers(0, 0xFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFFFFFF)
adc = st.integers(0, 0xFFF)
f32 = st.floats(width=32, allow_nan=False)  # NaN is covered bit-exactly in test_protocol_codec
f32s = st.lists(f32, min_size=12, max_size=12)


def sample_sensors(period: int, sensor_set: int, status: int, values: list[int]) -> SampleSensors:
    """A SAMPLE_SENSORS as a decoder returns it: the fields of clear bits 0, u8 words 3 bits."""
    kept, i = {}, 0
    for bit, names, _, limit in SENSOR_FIELDS:
        for name in names:
            kept[name] = values[i] & limit if sensor_set & bit else 0
            i += 1
    return SampleSensors(period, sensor_set, status, **kept)


SAMPLE_SENSORS = st.builds(sample_sensors, u32, st.integers(0, SENSOR_SET_ALL), st.integers(0, 15),
                           st.lists(u16, min_size=13, max_size=13))

MESSAGES = st.one_of(
    st.builds(Hello, u8, u8, u16, u32, name=st.binary(max_size=40)),
    st.builds(Sample, u32, adc, adc, adc, u16, st.integers(0, 15)),
    st.builds(Gates, u32, u8),
    st.builds(Duty, u32, st.tuples(u16, u16, u16)),
    st.builds(Command, u8, u8, f32, f32, f32),
    st.builds(lambda head, floats: Telemetry(*head, *floats), st.tuples(u32, u8, u8, u8, u8), f32s),
    st.builds(ParamSet, u16, f32),
    st.builds(ParamGet, u16),
    st.builds(ParamValue, u16, u8, f32),
    st.builds(Status, u32, u8, u16),
    st.builds(Fault, u32, u16, f32),
    st.builds(Heartbeat, u32),
    st.just(Shutdown()),
    st.builds(DutyLegs, u32, st.tuples(u16, u16, u16), st.integers(0, 7)),  # reserved bits 0 (CAN)
    SAMPLE_SENSORS,
)


def _chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    bounds = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    return [data[a:b] for a, b in zip(bounds, bounds[1:])]


def _subsequence(needles: list, haystack: list) -> bool:
    it = iter(haystack)
    return all(any(n == h for h in it) for n in needles)


@SETTINGS
@given(msg=MESSAGES, seq=u8)
def test_serial_round_trip(msg, seq):
    (got,) = StreamDecoder().feed(encode_frame(msg, seq))
    assert got == msg


@SETTINGS
@given(msg=MESSAGES, role=st.integers(0, 1), seq=st.integers(0, 15),
       base=st.integers(0, 0x7C0))
def test_can_round_trip(msg, role, seq, base):
    rx = CanReassembler(base)
    frames = can_pack(msg, role, base, seq)
    assert all(len(d) <= 8 and base <= i < base + 0x40 for i, d in frames)
    results = [rx.feed(i, d) for i, d in frames]
    assert results[:-1] == [None] * (len(frames) - 1)
    expected = msg
    if isinstance(msg, Sample):  # a fresh receiver has only the transmitted low bits
        expected = replace(msg, period=msg.period & 0xFF)
    elif isinstance(msg, Duty):
        expected = replace(msg, period=msg.period & 0xFFFF)
    elif isinstance(msg, DutyLegs):  # 13 bits: the leg enables share the word
        expected = replace(msg, period=msg.period & 0x1FFF)
    assert results[-1] == (expected, role)


@SETTINGS
@given(items=st.lists(st.tuples(st.binary(max_size=120), st.booleans(), MESSAGES), max_size=12),
       cuts=st.lists(st.integers(0, 10_000), max_size=10))
def test_garbage_between_frames_costs_no_untouched_frame(items, cuts):
    """A frame is untouched when its bytes are intact and a delimiter precedes it (garbage that
    does not end in 0x00 glues itself to the next frame, which is then rightly lost)."""
    enc = FrameEncoder()
    stream, untouched = b"", []
    for garbage, terminate, msg in items:
        stream += garbage + (b"\x00" if terminate else b"")
        if not stream or stream.endswith(b"\x00"):
            untouched.append(msg)
        stream += enc.encode(msg)
    dec = StreamDecoder()
    got = []
    for chunk in _chunks(stream, cuts):
        got += dec.feed(chunk)
        assert dec.buffered <= MAX_ENCODED_SEGMENT
    assert _subsequence(untouched, got)
    assert dec.frames_ok == len(got)


@SETTINGS
@given(data=st.binary(max_size=2000), cuts=st.lists(st.integers(0, 10_000), max_size=20))
def test_any_bytes_one_event_per_candidate_frame(data, cuts):
    """Never raises; every non-empty run of bytes closed by a delimiter is exactly one frame or
    one counted error, however the stream is chunked."""
    dec = StreamDecoder()
    for chunk in _chunks(data, cuts):
        dec.feed(chunk)
        assert dec.buffered <= MAX_ENCODED_SEGMENT
    c = dec.counters
    events = sum(v for k, v in c.items() if k != "seq_gaps")
    assert events == sum(1 for seg in data.split(b"\x00")[:-1] if seg)


@SETTINGS
@given(data=st.binary(max_size=400), flips=st.lists(st.tuples(st.integers(0, 10_000), st.integers(1, 255)),
                                                    min_size=1, max_size=4), msg=MESSAGES)
def test_corrupted_frame_is_counted_not_guessed(data, flips, msg):
    """A frame with bytes changed (but its delimiters intact) never yields a different message."""
    frame = bytearray(encode_frame(msg, 1))
    for pos, xor in flips:
        i = pos % (len(frame) - 1)
        if frame[i] ^ xor:  # keep delimiters where they are
            frame[i] ^= xor
    dec = StreamDecoder()
    got = dec.feed(b"\x00" + bytes(frame))
    assert got in ([], [msg])
    assert dec.frames_ok + dec.crc_errors + dec.framing_errors + dec.version_errors + dec.unknown_types \
        + dec.length_errors == 1


@SETTINGS
@given(frames=st.lists(st.tuples(st.integers(0x0C0, 0x160), st.binary(max_size=10)), max_size=60),
       valid=st.lists(st.tuples(MESSAGES, st.integers(0, 1)), max_size=5))
def test_can_reassembler_never_raises(frames, valid):
    rx = CanReassembler(0x100)
    for i, d in frames:
        got = rx.feed(i, d)
        assert got is None or got[1] in (0, 1)
    # after any garbage, whole messages still come through
    for msg, role in valid:
        results = [rx.feed(i, d) for i, d in can_pack(msg, role, 0x100, 3)]
        assert results[-1] is not None and type(results[-1][0]) is type(msg)


@SETTINGS
@given(msg=SAMPLE_SENSORS, absent=st.lists(u16, min_size=13, max_size=13), seq=u8)
def test_sample_sensors_fields_of_clear_bits_are_not_sent(msg, absent, seq):
    """Whatever the fields of clear bits hold, the frame is that of the message with them 0, and
    its length is 7 + the bytes of the set bits (SPEC 6.13)."""
    clear = [n for bit, names, _, _ in SENSOR_FIELDS if not msg.sensor_set & bit for n in names]
    noisy = replace(msg, **dict(zip(clear, absent)))
    frame = encode_frame(noisy, seq)
    assert frame == encode_frame(msg, seq)
    size = 7 + sum(len(codes) * (2 if codes[0] == "H" else 1) for bit, _, codes, _ in SENSOR_FIELDS
                   if msg.sensor_set & bit)
    assert StreamDecoder().feed(frame) == [msg]
    assert len(encode_payload(msg)) == size


@SETTINGS
@given(msg=SAMPLE_SENSORS, extra=st.integers(-3, 3), reserved=st.integers(1, 0x3F), seq=u8)
def test_sample_sensors_length_must_match_the_set(msg, extra, reserved, seq):
    """A payload one or more bytes off its set's length, or with a reserved set bit, is one
    length error and no message."""
    payload = encode_payload(msg)
    if extra:
        payload = (payload + bytes(extra))[:len(payload) + extra] if extra > 0 else payload[:extra]
    else:
        bad_set = msg.sensor_set | reserved << 10
        payload = payload[:4] + bad_set.to_bytes(2, "little") + payload[6:]
    raw = bytes((1, 0x10, seq, len(payload))) + payload
    frame = cobs_encode(raw + crc16(raw).to_bytes(2, "little")) + b"\x00"
    dec = StreamDecoder()
    assert dec.feed(frame) == []
    assert dec.counters == dict.fromkeys(dec.counters, 0) | {"length_errors": 1}
