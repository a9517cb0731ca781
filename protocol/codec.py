"""Serial framing of the hil-bench protocol: payload codecs, frame encoder, stream decoder.

Frame on the wire (protocol/SPEC.md):  COBS( header | payload | crc16 ) 0x00
    header = version u8, type u8, seq u8, payload_len u8
    crc16  = CRC-16/CCITT-FALSE over header and payload, little-endian

The work that costs is done in C: COBS by the ``cobs`` package's extension,
the CRC by binascii.crc_hqx, packing by one precompiled struct.Struct per
message type, and the decoder splits the stream on 0x00 with bytes.split
rather than walking it byte by byte. The counters and the resynchronisation
rules are the C decoder's (protocol/c/hil_proto.c), byte for byte.
"""
from __future__ import annotations

import math
import struct
from binascii import crc_hqx
from operator import attrgetter, index

from cobs.cobs import DecodeError as _CobsError
from cobs.cobs import decode as _cobs_decode
from cobs.cobs import encode as _cobs_encode

from protocol.messages import (
    NAME_MAX, PROTOCOL_VERSION, SENSOR_SET_ALL, Command, Duty, DutyLegs, Fault, Gates, Heartbeat, Hello,
    MsgType, ParamGet, ParamSet, ParamValue, Sample, SampleSensors, Shutdown, Status, Telemetry,
)

HEADER_SIZE = 4
CRC_SIZE = 2
MAX_PAYLOAD = 64
MAX_RAW_FRAME = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE
# Longest run of bytes between two delimiters that can be a frame: COBS adds one byte per 254.
MAX_ENCODED_SEGMENT = MAX_RAW_FRAME + (MAX_RAW_FRAME + 253) // 254
MAX_ENCODED_FRAME = MAX_ENCODED_SEGMENT + 1  # with the 0x00 delimiter
CRC_INIT = 0xFFFF

COUNTER_NAMES = ("frames_ok", "crc_errors", "framing_errors", "seq_gaps", "unknown_types",
                 "version_errors", "length_errors")


class ProtocolError(ValueError):
    """A message that cannot be encoded, or a payload that is not a valid message."""


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor."""
    return crc_hqx(data, CRC_INIT)


# ---------------------------------------------------------------- payload layouts
_HELLO = struct.Struct("<BBHIB")        # + name bytes
_SAMPLE = struct.Struct("<IIBH")        # period, adc40 low 32 bits, adc40 high 8 bits, encoder
_GATES = struct.Struct("<IB")
_DUTY = struct.Struct("<I3H")
_DUTY_LEGS = struct.Struct("<I3HB")    # period, duty x3, leg_enable
_COMMAND = struct.Struct("<BBfff")
_TELEMETRY = struct.Struct("<IBBBB12f")
_PARAM_SET = struct.Struct("<Hf")
_PARAM_GET = struct.Struct("<H")
_PARAM_VALUE = struct.Struct("<HBf")
_STATUS = struct.Struct("<IBH")
_FAULT = struct.Struct("<IHf")
_HEARTBEAT = struct.Struct("<I")

# SAMPLE_SENSORS: a fixed part, then the fields of each set sensor-set bit in bit order (SPEC 6.13).
_SAMPLE_SENSORS_FIXED = struct.Struct("<IHB")   # period, sensor_set, status
SAMPLE_SENSORS_FIXED_SIZE = _SAMPLE_SENSORS_FIXED.size
# (bit, fields, struct codes, largest value of each field: u8 fields with reserved bits are 0..7)
SENSOR_FIELDS = (
    (0x0001, ("adc_ia",), "H", 0xFFFF),
    (0x0002, ("adc_ib",), "H", 0xFFFF),
    (0x0004, ("adc_ic",), "H", 0xFFFF),
    (0x0008, ("adc_vdc",), "H", 0xFFFF),
    (0x0010, ("encoder",), "H", 0xFFFF),
    (0x0020, ("hall",), "B", 0x07),
    (0x0040, ("adc_va", "adc_vb", "adc_vc"), "HHH", 0xFFFF),
    (0x0080, ("bemf_comparators",), "B", 0x07),
    (0x0100, ("adc_resolver_sin", "adc_resolver_cos"), "HH", 0xFFFF),
    (0x0200, ("adc_temperature",), "H", 0xFFFF),
)
_SENSOR_FIELD_NAMES = tuple(name for _, names, _, _ in SENSOR_FIELDS for name in names)
SAMPLE_SENSORS_STATUS_MAX = 0x0F  # status bits 4-7 reserved
_HALL_INDEX = _SENSOR_FIELD_NAMES.index("hall")
_COMPARATORS_INDEX = _SENSOR_FIELD_NAMES.index("bemf_comparators")


def sample_sensors_size(sensor_set: int) -> int:
    """Payload length of SAMPLE_SENSORS with ``sensor_set``: 7 + the bytes of each set bit's fields."""
    return _sensor_layout(sensor_set)[0].size + SAMPLE_SENSORS_FIXED_SIZE


_SENSOR_LAYOUTS: dict[int, tuple] = {}


def _sensor_layout(sensor_set: int) -> tuple:
    """(struct of the set bits' fields, their names, their indices among the 13 sensor fields,
    their largest values) for a sensor set without reserved bits; built once per set."""
    layout = _SENSOR_LAYOUTS.get(sensor_set)
    if layout is None:
        fmt, names, limits = "<", [], []
        for bit, bit_names, codes, limit in SENSOR_FIELDS:
            if sensor_set & bit:
                fmt += codes
                names += bit_names
                limits += [limit] * len(bit_names)
        layout = (struct.Struct(fmt), tuple(names), tuple(_SENSOR_FIELD_NAMES.index(n) for n in names),
                  tuple(limits), attrgetter(*names) if names else (lambda m: ()))
        _SENSOR_LAYOUTS[sensor_set] = layout
    return layout


# Payload length of every fixed-size type; HELLO is 9 + name_len, SAMPLE_SENSORS 7 + its set's fields.
HELLO_FIXED_SIZE = _HELLO.size
PAYLOAD_SIZES: dict[int, int] = {
    MsgType.SAMPLE: _SAMPLE.size, MsgType.GATES: _GATES.size, MsgType.DUTY: _DUTY.size,
    MsgType.COMMAND: _COMMAND.size, MsgType.TELEMETRY: _TELEMETRY.size,
    MsgType.PARAM_SET: _PARAM_SET.size, MsgType.PARAM_GET: _PARAM_GET.size,
    MsgType.PARAM_VALUE: _PARAM_VALUE.size, MsgType.STATUS: _STATUS.size,
    MsgType.FAULT: _FAULT.size, MsgType.HEARTBEAT: _HEARTBEAT.size, MsgType.SHUTDOWN: 0,
    MsgType.DUTY_LEGS: _DUTY_LEGS.size,
}


def pack_adc40(adc_i1: int, adc_i2: int, adc_vdc: int, status: int) -> tuple[int, int]:
    """Three 12-bit ADC counts and 4 status bits as a 40-bit little-endian field (low u32, high u8)."""
    if (adc_i1 | adc_i2 | adc_vdc) >> 12 or status >> 4:
        raise ProtocolError(
            f"SAMPLE: ADC counts must be 0..4095 and status 0..15, got adc_i1={adc_i1} "
            f"adc_i2={adc_i2} adc_vdc={adc_vdc} status={status}")
    return adc_i1 | adc_i2 << 12 | (adc_vdc & 0xFF) << 24, adc_vdc >> 8 | status << 4


def _enc_hello(m: Hello) -> bytes:
    name = m.name
    if m.name_len != len(name) or m.name_len > NAME_MAX:
        raise ProtocolError(f"HELLO: name_len {m.name_len} with a {len(name)}-byte name; "
                            f"the name must be 0..{NAME_MAX} bytes and name_len its length")
    return _HELLO.pack(m.proto_version, m.role, m.capabilities, m.control_period_ns, m.name_len) + name


def _enc_sample(m: Sample) -> bytes:
    low, high = pack_adc40(m.adc_i1, m.adc_i2, m.adc_vdc, m.status)
    return _SAMPLE.pack(m.period, low, high, m.encoder)


def _enc_duty(m: Duty) -> bytes:
    d0, d1, d2 = m.duty
    return _DUTY.pack(m.period, d0, d1, d2)


def _enc_duty_legs(m: DutyLegs) -> bytes:
    d0, d1, d2 = m.duty
    return _DUTY_LEGS.pack(m.period, d0, d1, d2, m.leg_enable)


def _wire_int(value, limit: int):
    """``value`` as an int (numpy integers too) when it is one in 0..limit, else None."""
    try:
        v = index(value)
    except TypeError:
        return None
    return v if 0 <= v <= limit else None


def _enc_sample_sensors(m: SampleSensors) -> bytes:
    sensor_set = _wire_int(m.sensor_set, SENSOR_SET_ALL)
    if sensor_set is None:
        raise ProtocolError(f"SAMPLE_SENSORS.sensor_set = {m.sensor_set!r} is not an integer in "
                            f"0..0x{SENSOR_SET_ALL:03x} (bits 10-15 are reserved)")
    status = _wire_int(m.status, SAMPLE_SENSORS_STATUS_MAX)
    if status is None:
        raise ProtocolError(f"SAMPLE_SENSORS.status = {m.status!r} is not an integer in "
                            f"0..{SAMPLE_SENSORS_STATUS_MAX} (bits 4-7 are reserved)")
    st, names, _, limits, get = _sensor_layout(sensor_set)
    values = get(m)
    if len(names) == 1:
        values = (values,)
    checked = []
    for name, value, limit in zip(names, values, limits):
        v = _wire_int(value, limit)
        if v is None:
            raise ProtocolError(f"SAMPLE_SENSORS.{name} = {value!r} is not an integer in 0..{limit}"
                                + (" (bits 3-7 are reserved)" if limit == 0x07 else ""))
        checked.append(v)
    return _SAMPLE_SENSORS_FIXED.pack(m.period, sensor_set, status) + st.pack(*checked)


def _generic_encoder(st: struct.Struct, *names: str):
    get = attrgetter(*names)
    if len(names) == 1:
        return lambda m: st.pack(get(m))
    return lambda m: st.pack(*get(m))


_TELEMETRY_FIELDS = ("period", "sector", "speed_source", "state", "gates", "speed_feedback_rad_s",
                     "speed_encoder_rad_s", "speed_raw_rad_s", "speed_lpf_rad_s", "speed_ekf_rad_s",
                     "flux_angle_rad", "ekf_angle_rad", "flux_mag_wb", "torque_est_nm",
                     "torque_ref_nm", "rotor_pos_conv_rad", "rotor_pos_ekf_rad")

_PAYLOAD_ENCODERS = {
    Hello: _enc_hello,
    Sample: _enc_sample,
    Gates: _generic_encoder(_GATES, "period", "gates"),
    Duty: _enc_duty,
    Command: _generic_encoder(_COMMAND, "flags", "speed_source", "speed_ref_rad_s", "torque_ref_nm",
                              "flux_ref_wb"),
    Telemetry: _generic_encoder(_TELEMETRY, *_TELEMETRY_FIELDS),
    ParamSet: _generic_encoder(_PARAM_SET, "id", "value"),
    ParamGet: _generic_encoder(_PARAM_GET, "id"),
    ParamValue: _generic_encoder(_PARAM_VALUE, "id", "status", "value"),
    Status: _generic_encoder(_STATUS, "period", "state", "fault_code"),
    Fault: _generic_encoder(_FAULT, "period", "code", "value"),
    Heartbeat: _generic_encoder(_HEARTBEAT, "counter"),
    Shutdown: lambda m: b"",
    DutyLegs: _enc_duty_legs,
    SampleSensors: _enc_sample_sensors,
}

# Wire width of each field, to name the offending field when packing fails.
_FIELD_LIMITS = {"B": (0, 0xFF), "H": (0, 0xFFFF), "I": (0, 0xFFFFFFFF), "adc": (0, 0xFFF), "nibble": (0, 0xF)}


def encode_payload(msg) -> bytes:
    """The payload of ``msg`` (no header, no CRC); raises ProtocolError when a field does not fit."""
    try:
        enc = _PAYLOAD_ENCODERS[type(msg)]
    except KeyError:
        raise ProtocolError(f"not a protocol message: {msg!r}") from None
    try:
        return enc(msg)
    except ProtocolError:
        raise
    except (struct.error, OverflowError, TypeError, ValueError) as exc:
        raise _range_error(msg, exc) from exc


def _range_error(msg, exc: Exception) -> ProtocolError:
    """Names the field that does not fit (only runs when packing failed)."""
    from dataclasses import fields

    fmt = _FIELD_FORMATS.get(type(msg), {})
    for f in fields(msg):
        code = fmt.get(f.name)
        value = getattr(msg, f.name)
        for v in (value if isinstance(value, (tuple, list)) else (value,)):
            if code in _FIELD_LIMITS:
                lo, hi = _FIELD_LIMITS[code]
                if not isinstance(v, int) or not lo <= v <= hi:
                    return ProtocolError(f"{msg.TYPE.name}.{f.name} = {v!r} is not an integer "
                                         f"in {lo}..{hi}")
            elif code == "f":
                if not isinstance(v, (int, float)):
                    return ProtocolError(f"{msg.TYPE.name}.{f.name} = {v!r} is not a number")
                if math.isfinite(v) and abs(v) > 3.4028235677973366e38:
                    return ProtocolError(f"{msg.TYPE.name}.{f.name} = {v!r} does not fit a float32")
    return ProtocolError(f"{msg.TYPE.name}: cannot encode {msg!r}: {exc}")


_FIELD_FORMATS: dict[type, dict[str, str]] = {
    Hello: {"proto_version": "B", "role": "B", "capabilities": "H", "control_period_ns": "I",
            "name_len": "B"},
    Sample: {"period": "I", "adc_i1": "adc", "adc_i2": "adc", "adc_vdc": "adc", "encoder": "H",
             "status": "nibble"},
    Gates: {"period": "I", "gates": "B"},
    Duty: {"period": "I", "duty": "H"},
    Command: {"flags": "B", "speed_source": "B", "speed_ref_rad_s": "f", "torque_ref_nm": "f",
              "flux_ref_wb": "f"},
    Telemetry: dict(zip(_TELEMETRY_FIELDS, "IBBBB" + "f" * 12)),
    ParamSet: {"id": "H", "value": "f"},
    ParamGet: {"id": "H"},
    ParamValue: {"id": "H", "status": "B", "value": "f"},
    Status: {"period": "I", "state": "B", "fault_code": "H"},
    Fault: {"period": "I", "code": "H", "value": "f"},
    Heartbeat: {"counter": "I"},
    DutyLegs: {"period": "I", "duty": "H", "leg_enable": "B"},
    SampleSensors: {"period": "I"},  # the other fields are checked by _enc_sample_sensors
}


# ---------------------------------------------------------------- payload decoders
# Each takes (buffer, offset, length) and returns the message, or None when the
# length (or HELLO's name_len) is wrong for the type.

def _dec_hello(buf, off: int, n: int):
    if n < HELLO_FIXED_SIZE:
        return None
    version, role, caps, period_ns, name_len = _HELLO.unpack_from(buf, off)
    if name_len > NAME_MAX or n != HELLO_FIXED_SIZE + name_len:
        return None
    start = off + HELLO_FIXED_SIZE
    return Hello(version, role, caps, period_ns, name_len, bytes(buf[start:start + name_len]))


def _dec_sample(buf, off: int, n: int):
    if n != 11:
        return None
    period, low, high, encoder = _SAMPLE.unpack_from(buf, off)
    return Sample(period, low & 0xFFF, (low >> 12) & 0xFFF, low >> 24 | (high & 0x0F) << 8, encoder,
                  high >> 4)


def _dec_gates(buf, off: int, n: int):
    if n != 5:
        return None
    period, gates = _GATES.unpack_from(buf, off)
    return Gates(period, gates)


def _dec_duty(buf, off: int, n: int):
    if n != 10:
        return None
    period, d0, d1, d2 = _DUTY.unpack_from(buf, off)
    return Duty(period, (d0, d1, d2))


def _dec_duty_legs(buf, off: int, n: int):
    if n != 11:
        return None
    period, d0, d1, d2, leg_enable = _DUTY_LEGS.unpack_from(buf, off)
    return DutyLegs(period, (d0, d1, d2), leg_enable)


def _dec_sample_sensors(buf, off: int, n: int):
    if n < SAMPLE_SENSORS_FIXED_SIZE:
        return None
    period, sensor_set, status = _SAMPLE_SENSORS_FIXED.unpack_from(buf, off)
    if sensor_set & ~SENSOR_SET_ALL:
        return None  # a reserved bit: the layout is unknown, counted as a length error
    st, _, indices, _, _ = _sensor_layout(sensor_set)
    if n != SAMPLE_SENSORS_FIXED_SIZE + st.size:
        return None
    values = [0] * len(_SENSOR_FIELD_NAMES)
    for i, v in zip(indices, st.unpack_from(buf, off + SAMPLE_SENSORS_FIXED_SIZE)):
        values[i] = v
    # reserved bits are ignored on receipt (SPEC 6.13): dropped here, so that every decoded
    # message encodes again
    values[_HALL_INDEX] &= 0x07
    values[_COMPARATORS_INDEX] &= 0x07
    return SampleSensors(period, sensor_set, status & SAMPLE_SENSORS_STATUS_MAX, *values)


def _generic_decoder(st: struct.Struct, cls):
    size = st.size
    unpack_from = st.unpack_from

    def dec(buf, off: int, n: int):
        if n != size:
            return None
        return cls(*unpack_from(buf, off))
    return dec


_PAYLOAD_DECODERS = {
    MsgType.HELLO: _dec_hello,
    MsgType.SAMPLE: _dec_sample,
    MsgType.GATES: _dec_gates,
    MsgType.DUTY: _dec_duty,
    MsgType.COMMAND: _generic_decoder(_COMMAND, Command),
    MsgType.TELEMETRY: _generic_decoder(_TELEMETRY, Telemetry),
    MsgType.PARAM_SET: _generic_decoder(_PARAM_SET, ParamSet),
    MsgType.PARAM_GET: _generic_decoder(_PARAM_GET, ParamGet),
    MsgType.PARAM_VALUE: _generic_decoder(_PARAM_VALUE, ParamValue),
    MsgType.STATUS: _generic_decoder(_STATUS, Status),
    MsgType.FAULT: _generic_decoder(_FAULT, Fault),
    MsgType.HEARTBEAT: _generic_decoder(_HEARTBEAT, Heartbeat),
    MsgType.SHUTDOWN: lambda buf, off, n: Shutdown() if n == 0 else None,
    MsgType.DUTY_LEGS: _dec_duty_legs,
    MsgType.SAMPLE_SENSORS: _dec_sample_sensors,
}
# Plain int keys: a dict lookup with an int hashes the same but skips the enum's __hash__.
_PAYLOAD_DECODERS = {int(k): v for k, v in _PAYLOAD_DECODERS.items()}


def decode_payload(msg_type: int, payload: bytes):
    """The message of type ``msg_type`` in ``payload``; raises ProtocolError naming what is wrong."""
    dec = _PAYLOAD_DECODERS.get(msg_type)
    if dec is None:
        raise ProtocolError(f"unknown message type 0x{msg_type:02x} in protocol version {PROTOCOL_VERSION}")
    msg = dec(payload, 0, len(payload))
    if msg is None:
        name = MsgType(msg_type).name
        if msg_type == MsgType.HELLO:
            expected = f"{HELLO_FIXED_SIZE} + name_len (name_len <= {NAME_MAX})"
        elif msg_type == MsgType.SAMPLE_SENSORS:
            expected = _sample_sensors_expected(payload)
        else:
            expected = str(PAYLOAD_SIZES[msg_type])
        raise ProtocolError(f"{name} payload of {len(payload)} bytes; expected {expected}")
    return msg


def _sample_sensors_expected(payload: bytes) -> str:
    """What a SAMPLE_SENSORS payload of the wrong length should have been, for the error."""
    if len(payload) < SAMPLE_SENSORS_FIXED_SIZE:
        return f"at least {SAMPLE_SENSORS_FIXED_SIZE}"
    sensor_set = payload[4] | payload[5] << 8
    if sensor_set & ~SENSOR_SET_ALL:
        return f"a sensor_set without reserved bits 10-15 (got 0x{sensor_set:04x})"
    return f"{sample_sensors_size(sensor_set)} for sensor_set 0x{sensor_set:04x}"


# ---------------------------------------------------------------- frames
_HEADER = struct.Struct("<BBBB")
_CRC = struct.Struct("<H")
_SAMPLE_RAW = struct.Struct("<BBBB" + _SAMPLE.format[1:])
_GATES_RAW = struct.Struct("<BBBB" + _GATES.format[1:])
_DUTY_RAW = struct.Struct("<BBBB" + _DUTY.format[1:])


def _frame_sample(m: Sample, seq: int) -> bytes:
    a, b, c, status = m.adc_i1, m.adc_i2, m.adc_vdc, m.status
    if (a | b | c) >> 12 or status >> 4:
        pack_adc40(a, b, c, status)  # raises, naming the values
    raw = _SAMPLE_RAW.pack(1, 2, seq, 11, m.period, a | b << 12 | (c & 0xFF) << 24, c >> 8 | status << 4,
                           m.encoder)
    return _cobs_encode(raw + _CRC.pack(crc_hqx(raw, CRC_INIT))) + b"\x00"


def _frame_gates(m: Gates, seq: int) -> bytes:
    raw = _GATES_RAW.pack(1, 3, seq, 5, m.period, m.gates)
    return _cobs_encode(raw + _CRC.pack(crc_hqx(raw, CRC_INIT))) + b"\x00"


def _frame_duty(m: Duty, seq: int) -> bytes:
    d0, d1, d2 = m.duty
    raw = _DUTY_RAW.pack(1, 4, seq, 10, m.period, d0, d1, d2)
    return _cobs_encode(raw + _CRC.pack(crc_hqx(raw, CRC_INIT))) + b"\x00"


def _frame_generic(msg, seq: int) -> bytes:
    payload = encode_payload(msg)
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"{msg.TYPE.name}: payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    raw = _HEADER.pack(PROTOCOL_VERSION, int(msg.TYPE), seq, len(payload)) + payload
    return _cobs_encode(raw + _CRC.pack(crc_hqx(raw, CRC_INIT))) + b"\x00"


# The hot paths spell version, type and size as literals: an IntEnum argument costs struct an
# __index__ call. The assertion keeps them honest.
assert (PROTOCOL_VERSION, MsgType.SAMPLE, MsgType.GATES, MsgType.DUTY) == (1, 2, 3, 4)
assert (_SAMPLE.size, _GATES.size, _DUTY.size) == (11, 5, 10)

_FRAME_ENCODERS = {cls: _frame_generic for cls in _PAYLOAD_ENCODERS}
_FRAME_ENCODERS.update({Sample: _frame_sample, Gates: _frame_gates, Duty: _frame_duty})


def encode_frame(msg, seq: int) -> bytes:
    """One serial frame: COBS(header | payload | crc16) followed by the 0x00 delimiter."""
    try:
        frame = _FRAME_ENCODERS[type(msg)]
    except KeyError:
        raise ProtocolError(f"not a protocol message: {msg!r}") from None
    try:
        return frame(msg, seq & 0xFF)
    except ProtocolError:
        raise
    except (struct.error, OverflowError, TypeError, ValueError) as exc:
        raise _range_error(msg, exc) from exc


class FrameEncoder:
    """Encodes messages into serial frames, numbering them with its own u8 sequence counter."""

    __slots__ = ("seq",)

    def __init__(self, first_seq: int = 0) -> None:
        self.seq = first_seq & 0xFF

    def encode(self, msg) -> bytes:
        try:
            frame = _FRAME_ENCODERS[type(msg)]
        except KeyError:
            raise ProtocolError(f"not a protocol message: {msg!r}") from None
        seq = self.seq
        try:
            data = frame(msg, seq)
        except ProtocolError:
            raise
        except (struct.error, OverflowError, TypeError, ValueError) as exc:
            raise _range_error(msg, exc) from exc
        self.seq = (seq + 1) & 0xFF  # a message that failed to encode does not use a number
        return data


class StreamDecoder:
    """Turns a byte stream into messages; never raises on bad input.

    Bytes between two 0x00 delimiters form one candidate frame. A candidate
    longer than MAX_ENCODED_SEGMENT, with bad COBS, shorter than header + CRC,
    or whose length field disagrees with its size counts one framing error; a
    bad CRC counts a CRC error; then the header version, sequence number, type
    and payload length are checked in that order (SPEC.md, "Receiving").
    At most MAX_ENCODED_SEGMENT bytes are ever held between calls.
    """

    __slots__ = ("_pending", "_overflow", "_have_seq", "last_seq", "last_bad_version", *COUNTER_NAMES)

    def __init__(self) -> None:
        self._pending = b""
        self._overflow = False
        self._have_seq = False
        self.last_seq = 0
        self.last_bad_version = 0  # header version of the last frame rejected for its version
        self.frames_ok = 0
        self.crc_errors = 0
        self.framing_errors = 0
        self.seq_gaps = 0
        self.unknown_types = 0
        self.version_errors = 0
        self.length_errors = 0

    @property
    def counters(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in COUNTER_NAMES}

    @property
    def buffered(self) -> int:
        """Bytes held waiting for a delimiter (at most MAX_ENCODED_SEGMENT)."""
        return len(self._pending)

    def reset(self) -> None:
        """Forgets a partial frame and the sequence history (counters are kept)."""
        self._pending = b""
        self._overflow = False
        self._have_seq = False

    def feed(self, data: bytes) -> list:
        """Messages completed by ``data``, in order; bad frames are counted, never raised."""
        if type(data) is not bytes:
            data = bytes(data)
        parts = data.split(b"\x00")
        tail = parts.pop()
        if self._overflow or self._pending:
            if not parts:  # still inside the same candidate frame
                if not self._overflow:
                    tail = self._pending + tail
                    if len(tail) > MAX_ENCODED_SEGMENT:
                        self._overflow = True
                        tail = b""
                    self._pending = tail
                return []
            if self._overflow:
                self._overflow = False
                self.framing_errors += 1
                parts[0] = b""
            else:
                parts[0] = self._pending + parts[0]
        if len(tail) > MAX_ENCODED_SEGMENT:
            self._overflow = True
            tail = b""
        self._pending = tail
        out = []
        frame = self._frame
        for seg in parts:
            if seg:
                msg = frame(seg)
                if msg is not None:
                    out.append(msg)
        return out

    def _frame(self, seg: bytes):
        if len(seg) > MAX_ENCODED_SEGMENT:
            self.framing_errors += 1
            return None
        try:
            raw = _cobs_decode(seg)
        except _CobsError:
            self.framing_errors += 1
            return None
        n = len(raw)
        if n < HEADER_SIZE + CRC_SIZE:
            self.framing_errors += 1
            return None
        if crc_hqx(raw[:-2], CRC_INIT) != raw[-2] | raw[-1] << 8:
            self.crc_errors += 1
            return None
        version = raw[0]
        if version != PROTOCOL_VERSION:
            self.version_errors += 1
            self.last_bad_version = version
            return None
        plen = raw[3]
        if plen != n - (HEADER_SIZE + CRC_SIZE):
            self.framing_errors += 1
            return None
        seq = raw[2]
        if self._have_seq:
            gap = (seq - self.last_seq - 1) & 0xFF
            if gap:
                self.seq_gaps += gap
        else:
            self._have_seq = True
        self.last_seq = seq
        dec = _PAYLOAD_DECODERS.get(raw[1])
        if dec is None:
            self.unknown_types += 1
            return None
        msg = dec(raw, HEADER_SIZE, plen)
        if msg is None:
            self.length_errors += 1
            return None
        self.frames_ok += 1
        return msg
