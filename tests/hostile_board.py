"""A hostile board: a seeded fake controller that answers the bench with random mixes of valid,
malformed, out-of-order and out-of-range frames, and a runner that plays one bench session
against it and says how the session ended.

Each session draws its board from its own seed (``session_seed(base, index)``): how it answers
HELLO and the parameters (some advertise SENSOR_SET and answer its PARAM_GET with a set, NaN,
reserved bits, a fraction, a huge value, a refusal or nothing, and then get SAMPLE_SENSORS),
and per SAMPLE a mix of valid answers, stale and future periods,
GATES with reserved bits or shoot-through, DUTY, TELEMETRY with NaN, infinities and huge
values, FAULT and STATUS with values no board should send, unknown types, frames of the
bench's own types, bursts of HEARTBEAT, damaged frames (serial: bad CRC, bad COBS, wrong
lengths, another version, oversize, partial frames, garbage; CAN: wrong dlc, over-long
frames, unknown, foreign and own-role identifiers, extended, remote and error frames,
segmented messages shuffled, cut, too long or of the wrong counter), silence, and an early
close. The same seed gives the same board; a failure names its seed.

Where the board sits (``transport``):

- ``pty``: a thread on the master side of a pseudo-terminal; the bench opens the slave as
  ``serial:/dev/pts/N`` (the real serial link, link tap and C period loop);
- ``can``: a thread on a python-can virtual bus; the bench opens ``can:virtual:CHANNEL``
  (the real CAN link and reassembler);
- ``exec``: this file run as a program on the pty the bench's ``exec:`` link makes
  (``exec:PYTHON?args=tests/hostile_board.py --seed N``), the board as its own process.

    python tests/hostile_board.py --seed 7                  # a board on stdin/stdout (exec:)
    python tests/hostile_board.py --seed 7 --session can    # one session against it (replay)
"""
from __future__ import annotations

import itertools
import math
import os
import random
import select
import struct
import sys
import threading
import time
import traceback
from binascii import crc_hqx
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):      # run as a program: the repository on the path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cobs.cobs import encode as cobs_encode  # noqa: E402

from protocol.can_mapping import DEFAULT_BASE_ID, ROLE_STRIDE, can_pack  # noqa: E402
from protocol.codec import FrameEncoder, StreamDecoder  # noqa: E402
from protocol.messages import (  # noqa: E402
    PROTOCOL_VERSION, Command, Duty, Fault, Gates, Heartbeat, Hello, MsgType, ParamGet, ParamSet,
    ParamValue, Role, Sample, SampleSensors, Shutdown, Status, Telemetry,
)

CAP_GATES, CAP_DUTY, CAP_TELEMETRY, CAP_CAN, CAP_SENSOR_SET = 0x1, 0x2, 0x4, 0x8, 0x20
SENSOR_SET_PARAM_ID = 8
HALL_SIX_STEP_SET = 0x002F      # currents a, b, c, DC link, Halls
TRANSPORTS = ("pty", "can", "exec")

# What a board may do for one SAMPLE; each session weighs them its own way.
ACTIONS = ("answer", "answer_twice", "answer_split", "shoot_through", "reserved_bits",
           "other_kind", "stale", "future", "telemetry", "telemetry_wild", "heartbeats", "fault",
           "status", "param_value", "hello", "bench_types", "damage", "silence")
# Floats a board should never send, and some it might.
WILD_FLOATS = (math.nan, -math.nan, math.inf, -math.inf, 3.4028234e38, -3.4028234e38, 1e-45,
               -0.0, 0.0, 1e30, -1e30)
# f32 bit patterns that are NaN with a payload, signalling NaN among them
WILD_BITS = (0x7F800001, 0xFFC00001, 0x7FFFFFFF, 0xFF800000)


def session_seed(base_seed: int, index: int) -> int:
    """Session ``index``'s seed under ``base_seed`` (stable across runs and platforms)."""
    return random.Random(f"hostile:{base_seed}:{index}").getrandbits(32)


def _wild_float(rng: random.Random) -> float:
    pick = rng.random()
    if pick < 0.4:
        return rng.choice(WILD_FLOATS)
    if pick < 0.6:
        return struct.unpack("<f", struct.pack("<I", rng.choice(WILD_BITS)))[0]
    return rng.uniform(-1e6, 1e6)


def _gates_ok(rng: random.Random) -> int:
    """A GATES word without shoot-through: each leg high, low or off."""
    word = 0
    for leg in range(3):
        word |= rng.choice((0, 1, 2)) << (2 * leg)
    return word


@dataclass
class BoardPlan:
    """What one session's board does, drawn from its seed."""

    seed: int
    hello: str                  # valid | silent | garbage_first | second_try | version | role
    #                             | no_caps | period | bad_name
    params: str                 # valid | clamp_nan | clamp_inf | unknown | out_of_range
    #                             | silent | readback
    param_victim: int           # index of the pushed parameter the `params` mode hits
    kind: type                  # Gates or Duty: its usual answer
    capabilities: int
    weights: dict[str, float]
    end_after: int | None       # SAMPLEs answered before the end below (None: never)
    end: str                    # close | silence | flood | stream (HEARTBEATs unasked, always)
    sensor_set: str             # none | valid | nan | reserved | fraction | huge | unknown | silent:
    #                             SENSOR_SET capability and the answer to PARAM_GET SENSOR_SET

    @classmethod
    def draw(cls, seed: int) -> "BoardPlan":
        rng = random.Random(seed)
        hello = rng.choices(("valid", "silent", "garbage_first", "second_try", "version", "role",
                             "no_caps", "period", "bad_name"),
                            (80, 3, 4, 4, 2, 2, 2, 2, 2))[0]
        params = rng.choices(("valid", "clamp_nan", "clamp_inf", "unknown", "out_of_range",
                              "silent", "readback"), (80, 4, 4, 2, 2, 2, 3))[0]
        kind = rng.choice((Gates, Duty))
        caps = (CAP_GATES if kind is Gates else CAP_DUTY) | rng.choice((0, CAP_TELEMETRY)) | CAP_CAN
        # Weights: a valid answer is the common case (or sessions would all end in the
        # watchdog at once); everything else in random proportions, some not at all.
        weights = {a: (rng.random() ** 3 if rng.random() < 0.7 else 0.0) for a in ACTIONS}
        weights["answer"] = 8.0 + rng.random() * 12.0
        weights["silence"] *= 0.3
        end_after = rng.randrange(0, 400) if rng.random() < 0.3 else None
        end = rng.choice(("close", "silence", "flood", "stream"))
        param_victim = rng.randrange(9)
        # Drawn last, so that every other choice of a seed is what it was before sensor sets.
        sensor_set = rng.choices(("none", "valid", "nan", "reserved", "fraction", "huge",
                                  "unknown", "silent"), (70, 18, 2, 2, 2, 2, 2, 2))[0]
        if sensor_set != "none":
            caps |= CAP_SENSOR_SET
        return cls(seed, hello, params, param_victim, kind, caps, weights, end_after, end,
                   sensor_set)


class HostileBoard:
    """The board's decisions, independent of the transport: ``react(msg)`` returns what to
    send, a list of items: a message (encoded by the transport), ("damage", None) for a
    transport-specific damaged frame, ("pause", s), or "close"."""

    def __init__(self, seed: int):
        self.plan = BoardPlan.draw(seed)
        self.rng = random.Random(seed ^ 0x5EED)
        self.hellos = 0
        self.params: dict[int, float] = {}
        self.param_sets = 0
        self.victim_id = -1
        self.samples = 0
        self.last_answer: dict[int, object] = {}
        self.ended = False
        self.streaming = False      # sends HEARTBEAT bursts unasked, as fast as it can
        self.heartbeat = 0
        self._actions = [a for a, w in self.plan.weights.items() if w > 0]
        self._weights = [self.plan.weights[a] for a in self._actions]

    # -- the handshake
    def _hello(self, msg: Hello) -> list:
        plan, rng = self.plan, self.rng
        self.hellos += 1
        mode = plan.hello
        if mode == "silent" or (mode == "second_try" and self.hellos < 2):
            return []
        name = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 41)))
        hello = Hello(PROTOCOL_VERSION, int(Role.CONTROLLER), plan.capabilities,
                      rng.choice((0, msg.control_period_ns)), len(name), name)
        out: list = []
        if mode == "garbage_first":
            out += [("damage", None) for _ in range(rng.randrange(1, 6))]
        elif mode == "version":
            hello = Hello(rng.choice((0, 2, 255)), *_fields(hello)[1:])
        elif mode == "role":
            hello = Hello(hello.proto_version, rng.choice((0, 2, 255)), *_fields(hello)[2:])
        elif mode == "no_caps":
            hello = Hello(hello.proto_version, hello.role, CAP_TELEMETRY, *_fields(hello)[3:])
        elif mode == "period":
            hello = Hello(*_fields(hello)[:3], msg.control_period_ns + rng.choice((1, -1, 10**6)),
                          *_fields(hello)[4:])
        elif mode == "bad_name":
            out.append(("bad_hello", None))
        out.append(hello)
        return out

    def _param(self, msg) -> list:
        plan, rng = self.plan, self.rng
        pid = msg.id
        if isinstance(msg, ParamSet):
            index = self.param_sets
            self.param_sets += 1
            victim = index == plan.param_victim
            if victim:
                self.victim_id = pid
            mode = plan.params if victim else "valid"
            if mode == "silent":
                return []
            if mode == "unknown":
                return [ParamValue(pid, 1, 0.0)]
            if mode == "out_of_range":
                return [ParamValue(pid, 2, _wild_float(rng))]
            value = msg.value
            if mode == "clamp_nan":
                value = math.nan
            elif mode == "clamp_inf":
                value = rng.choice((math.inf, -math.inf, 3.4028234e38))
            self.params[pid] = value
            return [ParamValue(pid, 0, value)]
        if pid == SENSOR_SET_PARAM_ID and plan.sensor_set != "none":
            return self._sensor_set_answer()
        value = self.params.get(pid, 0.0)
        if plan.params == "readback" and pid == self.victim_id:
            value = _wild_float(rng)
        return [ParamValue(pid, 0, value)]

    def _sensor_set_answer(self) -> list:
        """PARAM_VALUE of SENSOR_SET: the set, or a value no board should send."""
        mode = self.plan.sensor_set
        if mode == "silent":
            return []
        if mode == "unknown":
            return [ParamValue(SENSOR_SET_PARAM_ID, 1, 0.0)]
        value = {"valid": float(HALL_SIX_STEP_SET), "nan": math.nan,
                 "reserved": float(HALL_SIX_STEP_SET | 0x0400), "fraction": 47.5,
                 "huge": 3.4028234e38}[mode]
        return [ParamValue(SENSOR_SET_PARAM_ID, 0, value)]

    # -- the periods
    def _answer(self, k: int, kind: type | None = None) -> object:
        rng = self.rng
        kind = kind or self.plan.kind
        if kind is Gates:
            return Gates(k & 0xFFFFFFFF, _gates_ok(rng))
        return Duty(k & 0xFFFFFFFF, tuple(rng.randrange(65536) for _ in range(3)))

    def _telemetry(self, k: int, wild: bool) -> Telemetry:
        rng = self.rng
        if wild:
            floats = [_wild_float(rng) for _ in range(12)]
            return Telemetry(rng.choice((k, k + 1, k - 1, 0xFFFFFFFF, rng.getrandbits(32))) & 0xFFFFFFFF,
                             rng.randrange(256), rng.randrange(256), rng.randrange(256),
                             rng.randrange(256), *floats)
        return Telemetry(k, rng.randrange(7), 0, 1, _gates_ok(rng),
                         *[rng.uniform(-500, 500) for _ in range(12)])

    def _act(self, action: str, k: int) -> list:
        rng = self.rng
        if action == "answer":
            answer = self.last_answer.get(k) or self._answer(k)
            self.last_answer = {k: answer}
            return [answer]
        if action == "answer_twice":
            answer = self._answer(k)
            return [answer, self._answer(k)]
        if action == "answer_split":
            return [("split", self._answer(k))]
        if action == "shoot_through":
            leg = rng.randrange(3)
            return [Gates(k, _gates_ok(rng) | (3 << (2 * leg)))]
        if action == "reserved_bits":
            return [Gates(k, _gates_ok(rng) | rng.choice((0x40, 0x80, 0xC0)))]
        if action == "other_kind":
            return [self._answer(k, Duty if self.plan.kind is Gates else Gates)]
        if action == "stale":
            return [self._answer((k - rng.randrange(1, 300)) & 0xFFFFFFFF)]
        if action == "future":
            return [self._answer(rng.choice((k + rng.randrange(1, 300), 0xFFFFFFFF,
                                             rng.getrandbits(32))))]
        if action == "telemetry":
            return [self._telemetry(k, False)]
        if action == "telemetry_wild":
            return [self._telemetry(k, True)]
        if action == "heartbeats":
            n = rng.choice((1, 5, 50, 300))
            self.heartbeat += n
            return [Heartbeat((self.heartbeat + i) & 0xFFFFFFFF) for i in range(n)]
        if action == "fault":
            return [Fault(rng.getrandbits(32), rng.randrange(65536), _wild_float(rng))]
        if action == "status":
            return [Status(rng.getrandbits(32), rng.randrange(256), rng.randrange(65536))]
        if action == "param_value":
            return [ParamValue(rng.randrange(65536), rng.randrange(256), _wild_float(rng))]
        if action == "hello":
            return [Hello(rng.choice((1, 2)), rng.randrange(3), rng.randrange(65536),
                          rng.getrandbits(32), 0, b"")]
        if action == "bench_types":
            return [rng.choice((Sample(k, 1, 2, 3, 4, 5), Command(1, 0, 1.0, 0.0, 0.0),
                                ParamSet(1, 1.0), ParamGet(1), Shutdown(),
                                SampleSensors(k, 0x0021, 0, adc_ia=2048, hall=1)))]
        if action == "damage":
            return [("damage", None) for _ in range(rng.randrange(1, 4))]
        if action == "silence":
            return []
        raise AssertionError(action)

    def _sample(self, msg: Sample | SampleSensors) -> list:
        plan, rng = self.plan, self.rng
        self.samples += 1
        k = msg.period
        if plan.end_after is not None and self.samples > plan.end_after:
            if plan.end == "close":
                self.ended = True
                return ["close"]
            if plan.end == "stream":
                self.streaming = True
                return []
            if plan.end == "flood":
                self.heartbeat += 100
                return [Heartbeat((self.heartbeat + i) & 0xFFFFFFFF) for i in range(100)]
            return []
        out: list = []
        for action in rng.choices(self._actions, self._weights, k=rng.randrange(1, 4)):
            out += self._act(action, k)
        rng.shuffle(out)
        return out

    def next_heartbeat(self) -> int:
        self.heartbeat = (self.heartbeat + 1) & 0xFFFFFFFF
        return self.heartbeat

    def react(self, msg) -> list:
        if self.ended:
            return []
        if isinstance(msg, Hello):
            return self._hello(msg)
        if isinstance(msg, (ParamSet, ParamGet)):
            return self._param(msg)
        if isinstance(msg, (Sample, SampleSensors)):
            return self._sample(msg)
        if isinstance(msg, Command):
            return [Status(0, self.rng.randrange(3), 0)] if self.rng.random() < 0.3 else []
        return []


def _fields(hello: Hello) -> tuple:
    return (hello.proto_version, hello.role, hello.capabilities, hello.control_period_ns,
            hello.name_len, hello.name)


# ------------------------------------------------------------------ serial (pty, exec)

def _raw_frame(version: int, msg_type: int, seq: int, payload: bytes, length: int | None = None,
               crc_ok: bool = True) -> bytes:
    raw = bytes((version, msg_type, seq, len(payload) if length is None else length)) + payload
    crc = crc_hqx(raw, 0xFFFF) ^ (0 if crc_ok else 0x1234)
    return cobs_encode(raw + struct.pack("<H", crc)) + b"\x00"


SERIAL_DAMAGE_KINDS = 12


def serial_damage(rng: random.Random, encoder: FrameEncoder, k: int,
                  kind: int | None = None) -> bytes:
    """One damaged stretch of serial bytes (SPEC 3.4's every check failing in turn); kind
    0..SERIAL_DAMAGE_KINDS-1 picks one (default: drawn)."""
    seq = rng.randrange(256)
    kind = rng.randrange(SERIAL_DAMAGE_KINDS) if kind is None else kind
    if kind == 0:       # bad CRC
        return _raw_frame(1, 3, seq, struct.pack("<IB", k, 0), crc_ok=False)
    if kind == 1:       # bad COBS: a code byte whose run passes the delimiter
        return bytes((rng.randrange(10, 250),)) + bytes(rng.randrange(1, 256) for _ in range(4)) + b"\x00"
    if kind == 2:       # shorter than header + CRC
        return cobs_encode(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 6)))) + b"\x00"
    if kind == 3:       # payload_len disagrees with the frame
        return _raw_frame(1, 3, seq, struct.pack("<IB", k, 0), length=rng.choice((0, 4, 6, 255)))
    if kind == 4:       # wrong length for the type (TELEMETRY of 64 bytes, GATES of 4)
        t, n = rng.choice(((3, 4), (3, 6), (4, 9), (6, 64), (6, 55), (0x0C, 0), (1, 8)))
        return _raw_frame(1, t, seq, bytes(rng.randrange(256) for _ in range(n)))
    if kind == 5:       # unknown type
        return _raw_frame(1, rng.choice((0, 0x0E, 0x7F, 0xFF)), seq,
                          bytes(rng.randrange(256) for _ in range(rng.randrange(0, 65))))
    if kind == 6:       # another protocol version
        return _raw_frame(rng.choice((0, 2, 0xFF)), 3, seq, struct.pack("<IB", k, 0))
    if kind == 7:       # oversize candidate
        return bytes(rng.randrange(1, 256) for _ in range(rng.randrange(72, 600))) + b"\x00"
    if kind == 8:       # a partial frame: it joins (and costs) the next one
        frame = encoder.encode(Gates(k, 0))
        return frame[:rng.randrange(1, len(frame) - 1)]
    if kind == 9:       # garbage
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 100)))
    if kind == 10:      # delimiters only
        return b"\x00" * rng.randrange(1, 20)
    # payload longer than the protocol allows, valid CRC
    return _raw_frame(1, 6, seq, bytes(rng.randrange(256) for _ in range(rng.randrange(65, 200))),
                      length=rng.randrange(256))


def _bad_hello_serial(seq: int) -> bytes:
    payload = struct.pack("<BBHIB", 1, 1, CAP_GATES, 0, 41) + b"x" * 41
    return _raw_frame(1, 1, seq, payload)


def serve_serial(board: HostileBoard, fd_in: int, fd_out: int, stop: threading.Event) -> None:
    """Plays ``board`` on a byte stream until SHUTDOWN, its early close, or ``stop``."""
    enc, dec = FrameEncoder(), StreamDecoder()
    rng = board.rng

    def write(data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(fd_out, view)
            except BlockingIOError:
                if stop.is_set():
                    return
                select.select([], [fd_out], [], 0.05)
                continue
            view = view[n:]

    while not stop.is_set():
        if board.streaming:
            try:
                os.write(fd_out, b"".join(enc.encode(Heartbeat(board.next_heartbeat()))
                                          for _ in range(20)))
            except BlockingIOError:
                pass                    # the bench reads no more than it reads
            except OSError:
                return
        try:
            ready, _, _ = select.select([fd_in], [], [], 0.001 if board.streaming else 0.05)
        except (OSError, ValueError):
            return
        if not ready:
            continue
        try:
            data = os.read(fd_in, 4096)
        except OSError:
            return
        if not data:
            return
        for msg in dec.feed(data):
            if isinstance(msg, Shutdown):
                return
            out = bytearray()
            for item in board.react(msg):
                if item == "close":
                    if out:
                        write(bytes(out))
                    return
                if isinstance(item, tuple):
                    what, arg = item
                    if what == "damage":
                        out += serial_damage(rng, enc, getattr(msg, "period", 0))
                    elif what == "bad_hello":
                        out += _bad_hello_serial(enc.seq)
                    elif what == "split":
                        frame = enc.encode(arg)
                        cut = rng.randrange(1, len(frame))
                        write(bytes(out) + frame[:cut])
                        out = bytearray()
                        time.sleep(0.001)
                        out += frame[cut:]
                    continue
                out += enc.encode(item)
            if out:
                try:
                    write(bytes(out))
                except OSError:
                    return


class PtyBoard:
    """The hostile board on the master side of a pseudo-terminal, in a thread."""

    def __init__(self, seed: int):
        import termios
        import tty

        self.board = HostileBoard(seed)
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave, termios.TCSANOW)
        os.set_blocking(self.master, False)
        self.url = f"serial:{os.ttyname(self._slave)}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        try:
            serve_serial(self.board, self.master, self.master, self._stop)
        finally:
            os.close(self.master)       # an early close, or the end: the bench reads EIO
            self.master = -1

    def __enter__(self) -> "PtyBoard":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)
        os.close(self._slave)


# ------------------------------------------------------------------ CAN (python-can virtual bus)

def can_damage(rng: random.Random, k: int, base: int = DEFAULT_BASE_ID) -> list[dict]:
    """Damaged CAN traffic from the controller's identifiers (SPEC 7's every rule broken)."""
    me = base + ROLE_STRIDE * int(Role.CONTROLLER)
    kind = rng.randrange(11)
    if kind == 0:       # wrong dlc for a single-frame type
        t, n = rng.choice(((MsgType.GATES, 4), (MsgType.GATES, 8), (MsgType.DUTY, 7),
                           (MsgType.PARAM_VALUE, 3), (MsgType.STATUS, 0), (MsgType.HEARTBEAT, 8)))
        return [dict(arbitration_id=me + t, data=bytes(rng.randrange(256) for _ in range(n)))]
    if kind == 1:       # more than 8 data bytes on a classic frame
        return [dict(arbitration_id=me + rng.choice((3, 6, 4)),
                     data=bytes(rng.randrange(256) for _ in range(rng.randrange(9, 65))))]
    if kind == 2:       # undefined types within the span, both roles' halves
        return [dict(arbitration_id=base + rng.choice((0, 0x0E, 0x1F, 0x20, 0x2E, 0x3F)),
                     data=bytes(rng.randrange(256) for _ in range(rng.randrange(9))))]
    if kind == 3:       # outside the span, extended, remote, error frames
        pick = rng.randrange(4)
        if pick == 0:
            return [dict(arbitration_id=rng.choice((0, 0x7FF, base + 0x40, base - 1)), data=b"\x01")]
        if pick == 1:
            return [dict(arbitration_id=me + 3, data=struct.pack("<IB", k, 0), is_extended_id=True)]
        if pick == 2:
            return [dict(arbitration_id=me + 3, is_remote_frame=True, dlc=5, data=b"")]
        return [dict(arbitration_id=0, is_error_frame=True, data=b"")]
    if kind == 4:       # the bench's own role (a loop-back)
        return [dict(arbitration_id=base + MsgType.GATES, data=struct.pack("<IB", k, 0))]
    frames = can_pack(Telemetry(k, 1, 0, 1, 0, *([0.0] * 12)), Role.CONTROLLER, base,
                      rng.randrange(16))
    frames = [dict(arbitration_id=i, data=d) for i, d in frames]
    if kind == 5:       # shuffled
        rng.shuffle(frames)
        return frames
    if kind == 6:       # cut: frames missing
        return [f for f in frames if rng.random() < 0.6]
    if kind == 7:       # too long: more frames than the type holds (up to index 15)
        extra = [dict(arbitration_id=frames[0]["arbitration_id"],
                      data=bytes((frames[0]["data"][0] & 0xF0 | i,)) + bytes(7))
                 for i in range(len(frames), rng.randrange(len(frames) + 1, 17))]
        return frames[:-1] + [dict(arbitration_id=frames[-1]["arbitration_id"],
                                   data=frames[-1]["data"][:1] + bytes(7))] + extra
    if kind == 8:       # a counter changing midway, a repeated index
        cut = rng.randrange(1, len(frames))
        tail = [dict(arbitration_id=f["arbitration_id"],
                     data=bytes(((f["data"][0] + 0x10) & 0xFF,)) + f["data"][1:]) for f in frames[cut:]]
        return frames[:cut] + frames[cut - 1:cut] + tail
    if kind == 9:       # a segment of dlc 0, and one of a header only
        return [frames[0], dict(arbitration_id=frames[0]["arbitration_id"], data=b""),
                dict(arbitration_id=frames[0]["arbitration_id"], data=frames[1]["data"][:1])]
    # HELLO announcing a name over 40 bytes
    payload = struct.pack("<BBHIB", 1, 1, CAP_GATES, 0, rng.choice((41, 200, 255))) + bytes(40)
    return [dict(arbitration_id=me + MsgType.HELLO, data=bytes((i,)) + payload[s:s + 7])
            for i, s in enumerate(range(0, len(payload), 7))][:16]


class CanBoard:
    """The hostile board on a python-can virtual bus, in a thread; the bench opens ``url``."""

    _channels = itertools.count(1)

    def __init__(self, seed: int):
        import can

        from protocol.can_mapping import CanReassembler

        channel = f"hostile-{os.getpid()}-{next(CanBoard._channels)}-{seed}"
        self.url = f"can:virtual:{channel}"
        self.board = HostileBoard(seed)
        self._can = can
        self._bus = can.Bus(interface="virtual", channel=channel)
        self._rx = CanReassembler()
        self._seq = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _send(self, frames: list[dict]) -> None:
        for f in frames:
            self._bus.send(self._can.Message(is_extended_id=f.pop("is_extended_id", False), **f))

    def _message(self, msg) -> list[dict]:
        frames = can_pack(msg, Role.CONTROLLER, DEFAULT_BASE_ID, self._seq)
        if len(frames) > 1:
            self._seq = (self._seq + 1) & 0x0F
        return [dict(arbitration_id=i, data=d) for i, d in frames]

    def _run(self) -> None:
        board, rng = self.board, self.board.rng
        try:
            while not self._stop.is_set():
                if board.streaming:
                    self._send([f for _ in range(20) for f in
                                self._message(Heartbeat(board.next_heartbeat()))])
                frame = self._bus.recv(0.001 if board.streaming else 0.05)
                if frame is None:
                    continue
                got = self._rx.feed(frame.arbitration_id, frame.data)
                if got is None or got[1] != Role.BENCH:
                    continue
                msg = got[0]
                if isinstance(msg, Shutdown):
                    return
                for item in board.react(msg):
                    if item == "close":
                        return
                    if isinstance(item, tuple):
                        what, arg = item
                        if what == "damage":
                            self._send(can_damage(rng, getattr(msg, "period", 0)))
                        elif what == "bad_hello":
                            self._send(_bad_hello_can())
                        elif what == "split":
                            self._send(self._message(arg))
                        continue
                    self._send(self._message(item))
        finally:
            self._bus.shutdown()        # an early close: the bench hears nothing more

    def __enter__(self) -> "CanBoard":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)


def _bad_hello_can() -> list[dict]:
    payload = struct.pack("<BBHIB", 1, 1, CAP_GATES, 0, 41) + bytes(41)
    me = DEFAULT_BASE_ID + ROLE_STRIDE + MsgType.HELLO
    return [dict(arbitration_id=me, data=bytes((0x30 | i,)) + payload[s:s + 7])
            for i, s in enumerate(range(0, len(payload), 7))]


# ------------------------------------------------------------------ one bench session against it

def hostile_policy(transport: str = "pty"):
    """Short waits (the board is a thread on this machine): silence costs little. With them
    a busy machine may miss an answer now and then; the checks hold whatever the timing. A
    board process (exec) first starts Python: a longer HELLO wait."""
    from hil.session.policy import SessionPolicy

    return SessionPolicy(hello_wait_s=1.0 if transport == "exec" else 0.05, hello_tries=2,
                         param_wait_s=0.05, param_tries=2, answer_wait_min_s=0.008,
                         answer_resends=1, watchdog_periods=4, watchdog_s=0.2)

# What ends a session, by the words of its error (SPEC 2.9); anything else is unnamed.
OUTCOME_KINDS = (
    ("watchdog", "watchdog: "),
    ("link_failed", "link failed"),
    ("no_hello", "no HELLO from the board"),
    ("protocol_version", "protocol version"),
    ("role", "in its HELLO; a controller is role"),
    ("capability", "advertises none of GATES, DUTY and DUTY_LEGS"),
    ("capability", "lacks capability"),
    ("control_period", "was built for a control period"),
    ("parameter", "no PARAM_VALUE for"),
    ("parameter", "does not know parameter"),
    ("parameter", "refused parameter"),
    ("parameter", "PARAM_GET reads back"),
    ("parameter", "with a non-finite value in force"),
    ("sensor_set", "parameter sensor_set (id 8"),
)


def outcome_kind(error: str | None) -> str:
    """'ok', a named error's kind, or 'unnamed'."""
    if error is None:
        return "ok"
    for kind, words in OUTCOME_KINDS:
        if words in error:
            return kind
    return "unnamed"


@dataclass
class SessionResult:
    transport: str
    seed: int
    outcome: str                    # ok | a kind of OUTCOME_KINDS | unnamed | crash | hang
    error: str | None = None        # the session's error, or the crash's traceback
    periods_run: int = 0
    periods_asked: int = 0
    resent_samples: int = 0
    resends: int = 0                # the policy's answer_resends
    missed_answers: int = 0
    bound_s: float = 0.0            # the session's own bound on its length (policy_bound_s)
    elapsed_s: float = 0.0
    safe_state: bool = False
    log_readable: bool = False
    log_error: str | None = None
    plan: dict = field(default_factory=dict)

    @property
    def problem(self) -> str | None:
        """What is wrong with this session, or None."""
        if self.outcome in ("crash", "hang", "unnamed"):
            return self.outcome
        if not self.safe_state:
            return "not safe-stated"
        if not self.log_readable:
            return f"log unreadable: {self.log_error}"
        if self.periods_run > self.periods_asked:
            return f"ran {self.periods_run} of {self.periods_asked} periods"
        if self.resent_samples > (self.periods_run + 1) * self.resends:
            return (f"{self.resent_samples} SAMPLEs resent in {self.periods_run} periods, "
                    f"more than {self.resends} a period")
        return None

    def describe(self) -> str:
        return (f"{self.transport} session seed {self.seed} (replay: python "
                f"tests/hostile_board.py --seed {self.seed} --session {self.transport} "
                f"--periods {self.periods_asked}): {self.problem or self.outcome}; "
                f"error: {self.error}; plan: {self.plan}")


def policy_bound_s(policy, periods: int, parameters: int, answer_wait_s: float) -> float:
    """The longest a session may take by its own policy: every HELLO, PARAM_SET and PARAM_GET
    wait, and every SAMPLE's wait with its resends, each read for one more wait length
    (a flood, SPEC 2.8), plus teardown's drain (0.5 s) and a board process's exit (1 s)."""
    hello = policy.hello_tries * policy.hello_wait_s * 2
    params = parameters * 2 * policy.param_tries * policy.param_wait_s * 2
    period = (1 + policy.answer_resends) * answer_wait_s * 2
    return hello + params + periods * period + 0.55 + 1.0


def _exec_url(seed: int, directory: Path) -> str:
    """exec: on a launcher in ``directory`` that runs this file with this interpreter (the
    exec: link resolves symbolic links, which would take a virtual environment's python out
    of its environment)."""
    launcher = Path(directory) / "hostile_board.sh"
    if not launcher.exists():
        launcher.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{Path(__file__).resolve()}" "$@"\n')
        launcher.chmod(0o755)
    return f"exec:{launcher}?args=--seed {seed}"


def open_board(transport: str, seed: int, directory: Path):
    """A context manager with the board's link string (``url``) and its plan (``board``)."""
    if transport == "pty":
        return PtyBoard(seed)
    if transport == "can":
        return CanBoard(seed)
    if transport == "exec":
        return _ExecBoard(seed, directory)
    raise ValueError(f"transport {transport!r}; expected one of {', '.join(TRANSPORTS)}")


class _ExecBoard:
    def __init__(self, seed: int, directory: Path):
        self.url = _exec_url(seed, directory)
        self.board = HostileBoard(seed)     # (its plan, for the report; the process draws its own)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass


def run_session(transport: str, seed: int, log_path: Path, periods: int = 200,
                guard_s: float | None = None, policy=None,
                realtime_period_s: float | None = None) -> SessionResult:
    """One bench session against the hostile board of ``seed``: its outcome and the checks
    (safe state, readable log, bounded length). The session runs in a worker thread; if it
    outlives ``guard_s`` (default: twice its own bound, plus 10 s) it counts as a hang.
    realtime_period_s: a real-time session at that period instead of lockstep."""
    from hil.logs.commands import format_info, log_export, log_info
    from hil.logs.reader import read_log
    from hil.session.bench_session import BenchSession, SessionConfig
    from hil.session.board_params import board_parameters
    from hil.session.errors import SessionError
    from plant_rt import load_profile
    from plant_rt.inverter import GATE_COMMANDS

    policy = policy or hostile_policy(transport)
    profile = load_profile()
    answer_wait = policy.answer_wait_s(profile.control_period_s)
    bound = policy_bound_s(policy, periods, len(board_parameters(profile)), answer_wait)
    guard = 2 * bound + 10.0 if guard_s is None else guard_s
    result = SessionResult(transport, seed, "crash", periods_asked=periods, bound_s=bound,
                           resends=policy.answer_resends)
    box: dict = {}

    def play() -> None:
        session = None
        try:
            with open_board(transport, seed, Path(log_path).parent) as board:
                result.plan = _plan_summary(board.board.plan)
                session = BenchSession(profile, SessionConfig(
                    link=board.url, log_path=log_path, seed=seed, policy=policy,
                    hold_cpu_latency=False,
                    mode="lockstep" if realtime_period_s is None else "realtime",
                    realtime_period_s=realtime_period_s))
                box["session"] = session
                try:
                    with session:
                        session.send_command(enable=True, speed_source="encoder",
                                             speed_ref_rpm=1000)
                        session.run_periods(periods)
                except SessionError as exc:
                    box["error"] = str(exc)
                    box["named"] = True
        except BaseException:  # noqa: BLE001 - anything else escaping is what this looks for
            box["crash"] = traceback.format_exc()

    t0 = time.monotonic()
    worker = threading.Thread(target=play, daemon=True, name=f"hostile-{transport}-{seed}")
    worker.start()
    worker.join(guard)
    result.elapsed_s = time.monotonic() - t0
    if worker.is_alive():
        result.outcome = "hang"
        result.error = f"still running after {guard:.1f} s (its own bound {bound:.1f} s)"
        return result
    session = box.get("session")
    if "crash" in box:
        result.error = box["crash"]
    else:
        error = box.get("error")
        if session is not None and error is None:
            error = session.error          # (an error the session logged but did not raise)
        result.error = error
        result.outcome = outcome_kind(error)
    if session is not None:
        result.periods_run = session.plant.period
        result.resent_samples = session.resent_samples
        result.missed_answers = session.missed_answers
        result.safe_state = session.plant._cmd is GATE_COMMANDS[0]
    try:
        data = read_log(log_path)
        if not data.complete:
            raise ValueError(f"log not complete: {data.note}")
        # and what `hil log info` and `hil log export` make of it
        format_info(log_info(log_path))
        log_export(log_path, sorted(data), Path(log_path).with_suffix(".csv"))
        Path(log_path).with_suffix(".csv").unlink()
        result.log_readable = True
    except Exception as exc:  # noqa: BLE001 - any failure to read is the finding
        result.log_error = f"{type(exc).__name__}: {exc}"
    return result


def _plan_summary(plan: BoardPlan) -> dict:
    used = sorted(a for a, w in plan.weights.items() if w > 0)
    return {"hello": plan.hello, "params": plan.params, "kind": plan.kind.__name__,
            "end": f"{plan.end} after {plan.end_after}" if plan.end_after is not None else "none",
            "actions": used}


#: Session i's transport: pty and CAN in turn, every 25th a board process (exec).
TRANSPORT_CYCLE = ("pty", "can") * 12 + ("exec",)


def run_many(count: int, base_seed: int, directory: Path, transports=TRANSPORT_CYCLE,
             periods: int = 200, on_result=None, stop=None, workers: int = 3,
             realtime_period_s: float | None = None) -> tuple[dict, list[SessionResult]]:
    """``count`` sessions (fewer if ``stop()`` says so before one starts), session i on
    transports[i % len] seeded session_seed(base, i), ``workers`` at a time (a session spends
    most of its time waiting on its board: a few overlap on two cores); returns the figures
    and the sessions that went wrong, in session order. realtime_period_s: real-time
    sessions at that period instead of lockstep."""
    from concurrent.futures import ThreadPoolExecutor

    def one(i: int) -> SessionResult | None:
        if stop is not None and stop():
            return None
        transport = transports[i % len(transports)]
        seed = session_seed(base_seed, i)
        log = Path(directory) / f"{transport}-{i}-{seed}.mcap"
        r = run_session(transport, seed, log, periods, realtime_period_s=realtime_period_s)
        if r.outcome != "hang":
            log.unlink(missing_ok=True)
        if on_result is not None:
            on_result(i, r)
        return r

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="hostile") as pool:
        results = [r for r in pool.map(one, range(count)) if r is not None]
    return figures_of(results, base_seed, periods), [r for r in results if r.problem is not None]


def figures_of(results: list[SessionResult], base_seed: int, periods: int) -> dict:
    """The figures of a run of sessions: counts, and ends by kind (overall, per transport)."""
    ends: dict[str, int] = {}
    by_transport: dict[str, dict[str, int]] = {}
    for r in results:
        ends[r.outcome] = ends.get(r.outcome, 0) + 1
        per = by_transport.setdefault(r.transport, {})
        per[r.outcome] = per.get(r.outcome, 0) + 1
    return {
        "sessions": len(results), "base_seed": base_seed, "periods_asked": periods,
        "crashes": sum(r.outcome == "crash" for r in results),
        "hangs": sum(r.outcome == "hang" for r in results),
        "unnamed": sum(r.outcome == "unnamed" for r in results),
        "logs_readable": sum(r.log_readable for r in results),
        "not_safe": sum(not r.safe_state for r in results),
        "periods_run": sum(r.periods_run for r in results),
        "resent_samples": sum(r.resent_samples for r in results),
        "ends_by_kind": dict(sorted(ends.items())),
        "by_transport": {t: dict(sorted(e.items())) for t, e in sorted(by_transport.items())},
        "longest_s": round(max((r.elapsed_s for r in results), default=0.0), 3),
        "longest_of_bound": round(max((r.elapsed_s / r.bound_s for r in results), default=0.0), 4),
    }


def main(argv: list[str] | None = None) -> int:
    """The board as a program on stdin/stdout (a serial line), for the bench's exec: link;
    with --session, one bench session against it (a failure's replay)."""
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(description="a seeded hostile board on stdin/stdout")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--session", choices=TRANSPORTS,
                        help="play one bench session against the board on this transport")
    parser.add_argument("--periods", type=int, default=200)
    args = parser.parse_args(argv)
    if args.session:
        with tempfile.TemporaryDirectory() as directory:
            r = run_session(args.session, args.seed, Path(directory) / "session.mcap",
                            args.periods)
        print(r.describe())
        return 1 if r.problem else 0
    os.set_blocking(1, False)
    serve_serial(HostileBoard(args.seed), 0, 1, threading.Event())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
