"""CAN mapping of the hil-bench protocol (classic CAN, 11-bit identifiers; protocol/SPEC.md).

identifier = base_id + 0x20 * sender_role + type. SAMPLE, GATES, DUTY and
every payload of at most 8 bytes travel in one frame; HELLO, COMMAND,
TELEMETRY, FAULT and SAMPLE_SENSORS are split over numbered frames whose first data byte is
(counter << 4) | index. The CAN CRC replaces the serial CRC, and there is no
sequence number: SAMPLE carries the low 8 bits of its period, DUTY the low 16
and DUTY_LEGS the low 13 (its leg enables take the word's top 3 bits), which
the receiver extends from the last period it saw.
"""
from __future__ import annotations

import struct

from protocol.codec import (
    HELLO_FIXED_SIZE, MAX_PAYLOAD, PAYLOAD_SIZES, SAMPLE_SENSORS_FIXED_SIZE, ProtocolError, decode_payload,
    encode_payload, pack_adc40, sample_sensors_size,
)
from protocol.messages import LEGS_ALL, NAME_MAX, SENSOR_SET_ALL, Duty, DutyLegs, MsgType, Role, Sample

DEFAULT_BASE_ID = 0x100
ROLE_STRIDE = 0x20
ID_SPAN = 0x40          # base_id .. base_id + 0x3F
CAN_ID_MAX = 0x7FF
SEGMENT_DATA = 7        # payload bytes per segmented frame
MAX_FRAMES = 16

SEGMENTED_TYPES = frozenset({MsgType.HELLO, MsgType.COMMAND, MsgType.TELEMETRY, MsgType.FAULT,
                             MsgType.SAMPLE_SENSORS})
_FULL_PERIOD_TYPES = frozenset({MsgType.GATES, MsgType.TELEMETRY, MsgType.STATUS, MsgType.FAULT,
                                MsgType.SAMPLE_SENSORS})
_KNOWN_TYPES = frozenset(int(t) for t in MsgType)

_SAMPLE_CAN = struct.Struct("<BIBH")   # period low 8, adc40 low 32, adc40 high 8, encoder
_DUTY_CAN = struct.Struct("<4H")       # period low 16, duty x3
_DUTY_LEGS_CAN = _DUTY_CAN             # period low 13 | leg_enable << 13, duty x3
DUTY_LEGS_PERIOD_BITS = 13
_DUTY_LEGS_PERIOD_MASK = (1 << DUTY_LEGS_PERIOD_BITS) - 1

COUNTER_NAMES = ("messages_ok", "sequence_errors", "unknown_types", "length_errors", "ignored_frames")


def check_base_id(base_id: int) -> int:
    if not 0 <= base_id <= CAN_ID_MAX - (ID_SPAN - 1):
        raise ProtocolError(f"CAN base_id 0x{base_id:x}: the protocol uses base_id .. base_id + 0x3F, "
                            f"which must stay within the 11-bit range (base_id <= 0x{CAN_ID_MAX - ID_SPAN + 1:x})")
    return base_id


def can_pack(msg, sender_role: int, base_id: int = DEFAULT_BASE_ID, seq: int = 0) -> list[tuple[int, bytes]]:
    """The CAN frames of ``msg`` as (arbitration_id, data); ``seq & 0x0F`` numbers a multi-frame message."""
    if sender_role not in (Role.BENCH, Role.CONTROLLER):
        raise ProtocolError(f"sender_role {sender_role!r}: expected 0 (bench) or 1 (controller)")
    check_base_id(base_id)
    msg_type = getattr(msg, "TYPE", None)
    if msg_type is None:
        raise ProtocolError(f"not a protocol message: {msg!r}")
    can_id = base_id + ROLE_STRIDE * int(sender_role) + int(msg_type)
    if msg_type == MsgType.SAMPLE or msg_type == MsgType.DUTY:
        period = msg.period
        try:
            if not 0 <= period <= 0xFFFFFFFF:
                raise ValueError("period")
            if msg_type == MsgType.SAMPLE:
                low, high = pack_adc40(msg.adc_i1, msg.adc_i2, msg.adc_vdc, msg.status)
                return [(can_id, _SAMPLE_CAN.pack(period & 0xFF, low, high, msg.encoder))]
            return [(can_id, _DUTY_CAN.pack(period & 0xFFFF, *msg.duty))]
        except (struct.error, TypeError, ValueError):
            encode_payload(msg)  # raises the ProtocolError naming the field
            raise
    if msg_type == MsgType.DUTY_LEGS:
        return [(can_id, _pack_duty_legs(msg))]
    payload = encode_payload(msg)
    if msg_type not in SEGMENTED_TYPES:
        return [(can_id, payload)]
    counter = (seq & 0x0F) << 4
    return [(can_id, bytes((counter | i,)) + payload[start:start + SEGMENT_DATA])
            for i, start in enumerate(range(0, len(payload), SEGMENT_DATA))]


def _pack_duty_legs(msg: DutyLegs) -> bytes:
    """Period low 13 bits and the three leg enables in one u16, then the duties (SPEC 7.2)."""
    encode_payload(msg)  # checks every field's range, naming the one that does not fit
    if msg.leg_enable & ~LEGS_ALL:
        raise ProtocolError(f"DUTY_LEGS.leg_enable = 0x{msg.leg_enable:02x}: reserved bits 3-7 must be 0 "
                            f"(the CAN frame carries bits 0-2 only)")
    word = (msg.period & _DUTY_LEGS_PERIOD_MASK) | msg.leg_enable << DUTY_LEGS_PERIOD_BITS
    return _DUTY_LEGS_CAN.pack(word, *msg.duty)


class _Slot:
    """A multi-frame message being reassembled from one sender role."""

    __slots__ = ("type", "counter", "next_index", "buf", "skip_type", "skip_counter")

    def __init__(self) -> None:
        self.type = 0
        self.counter = 0
        self.next_index = 0
        self.buf = bytearray()
        self.skip_type = 0
        self.skip_counter = 0

    def abandon(self, msg_type: int, counter: int) -> None:
        """Drops the message in progress; its remaining frames are then dropped uncounted,
        so one broken message costs one error."""
        self.type = 0
        self.skip_type = msg_type
        self.skip_counter = counter


class CanReassembler:
    """Turns CAN frames back into messages; never raises on bad input.

    ``feed(arbitration_id, data)`` returns (message, sender_role) when the
    frame completes a message, else None. Frames outside base_id .. base_id +
    0x3F are counted in ignored_frames; the rules and counters are those of
    hil_can_rx_feed in protocol/c/hil_proto.c.
    """

    def __init__(self, base_id: int = DEFAULT_BASE_ID) -> None:
        self.base_id = check_base_id(base_id)
        self._slots = (_Slot(), _Slot())
        self.last_period = 0
        self.have_period = False
        self.messages_ok = 0
        self.sequence_errors = 0
        self.unknown_types = 0
        self.length_errors = 0
        self.ignored_frames = 0

    @property
    def counters(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in COUNTER_NAMES}

    def feed(self, arbitration_id: int, data: bytes):
        offset = arbitration_id - self.base_id
        if not 0 <= offset < ID_SPAN:
            self.ignored_frames += 1
            return None
        role, msg_type = divmod(offset, ROLE_STRIDE)
        if msg_type not in _KNOWN_TYPES:
            self.unknown_types += 1
            return None
        if len(data) > 8:
            self.length_errors += 1
            return None
        if msg_type in SEGMENTED_TYPES:
            msg = self._segment(self._slots[role], msg_type, bytes(data))
        else:
            msg = self._single(msg_type, bytes(data))
        if msg is None:
            return None
        self.messages_ok += 1
        return msg, role

    def _extend(self, low: int, bits: int) -> int:
        if not self.have_period:
            period = low
        else:
            mask = (1 << bits) - 1
            ahead = (low - self.last_period) & mask
            period = (self.last_period + ahead if ahead < 1 << (bits - 1)
                      else self.last_period - (mask + 1 - ahead)) & 0xFFFFFFFF
        self.last_period = period
        self.have_period = True
        return period

    def _note_period(self, msg) -> None:
        if msg.TYPE in _FULL_PERIOD_TYPES:
            self.last_period = msg.period
            self.have_period = True

    def _single(self, msg_type: int, data: bytes):
        if msg_type == MsgType.SAMPLE or msg_type == MsgType.DUTY:
            if len(data) != 8:
                self.length_errors += 1
                return None
            if msg_type == MsgType.SAMPLE:
                low8, low, high, encoder = _SAMPLE_CAN.unpack(data)
                return Sample(self._extend(low8, 8), low & 0xFFF, (low >> 12) & 0xFFF,
                              low >> 24 | (high & 0x0F) << 8, encoder, high >> 4)
            low16, d0, d1, d2 = _DUTY_CAN.unpack(data)
            return Duty(self._extend(low16, 16), (d0, d1, d2))
        if msg_type == MsgType.DUTY_LEGS:
            if len(data) != 8:
                self.length_errors += 1
                return None
            word, d0, d1, d2 = _DUTY_LEGS_CAN.unpack(data)
            period = self._extend(word & _DUTY_LEGS_PERIOD_MASK, DUTY_LEGS_PERIOD_BITS)
            return DutyLegs(period, (d0, d1, d2), word >> DUTY_LEGS_PERIOD_BITS)
        try:
            msg = decode_payload(msg_type, data)
        except ProtocolError:
            self.length_errors += 1
            return None
        self._note_period(msg)
        return msg

    def _segment(self, slot: _Slot, msg_type: int, data: bytes):
        if not data:
            self.length_errors += 1
            if slot.type:
                slot.abandon(slot.type, slot.counter)
            return None
        index, counter = data[0] & 0x0F, data[0] >> 4
        if index == 0:
            if slot.type:
                self.sequence_errors += 1  # the previous message never completed
            slot.type, slot.counter, slot.next_index, slot.skip_type = msg_type, counter, 0, 0
            slot.buf = bytearray()
        elif slot.type != msg_type or slot.counter != counter or slot.next_index != index:
            if not slot.type and slot.skip_type == msg_type and slot.skip_counter == counter:
                return None  # the rest of a message already counted
            self.sequence_errors += 1
            slot.abandon(msg_type, counter)
            return None
        chunk = data[1:]
        if not chunk or len(slot.buf) + len(chunk) > MAX_PAYLOAD:
            self.length_errors += 1
            slot.abandon(msg_type, counter)
            return None
        slot.buf += chunk
        slot.next_index += 1
        expected = _expected_len(msg_type, slot.buf)
        if expected < 0 or 0 < expected < len(slot.buf):
            self.length_errors += 1
            slot.abandon(msg_type, counter)
            return None
        if expected == len(slot.buf):
            slot.type = 0
            msg = decode_payload(msg_type, bytes(slot.buf))  # cannot fail: the length was checked
            self._note_period(msg)
            return msg
        if len(chunk) < SEGMENT_DATA:
            self.length_errors += 1  # a short frame that does not end the message
            slot.abandon(msg_type, counter)
        return None


def _expected_len(msg_type: int, buf: bytearray) -> int:
    """Payload length of a segmented message: 0 while not yet known, -1 when invalid."""
    if msg_type == MsgType.SAMPLE_SENSORS:
        if len(buf) < SAMPLE_SENSORS_FIXED_SIZE - 1:  # sensor_set is payload bytes 4-5
            return 0
        sensor_set = buf[4] | buf[5] << 8
        return -1 if sensor_set & ~SENSOR_SET_ALL else sample_sensors_size(sensor_set)
    if msg_type != MsgType.HELLO:
        return PAYLOAD_SIZES[msg_type]
    if len(buf) < HELLO_FIXED_SIZE:
        return 0
    if buf[8] > NAME_MAX:
        return -1
    return HELLO_FIXED_SIZE + buf[8]
