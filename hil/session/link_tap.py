"""A tap between the session and any byte link: records raw frames, injects link faults.

The tap frames the session's messages itself and hands whole frames to the
link's ``send_bytes``; it reads the link's raw bytes with ``read_bytes``,
splits them at the 0x00 delimiters and decodes them with its own stream
decoder. In between, each frame may be dropped, corrupted (bits flipped),
delayed by N periods, duplicated or swapped with the next one, or swallowed
by an unplugged cable — in either direction, at a rate, from a seeded random
generator per direction (the session's seed, or the fault's own ``seed``), so
the same seed and the same traffic give the same faults. Counters say what was
done to how many frames.

Corruption flips bits inside a frame and never creates or removes a 0x00
delimiter (a flip that would is drawn again): each corrupted frame is exactly
one bad candidate frame at the receiver (one CRC or framing error), so the
receivers' error counters reconcile exactly with ``*_corrupted``. Damage to a
delimiter (which merges or splits frames) is what the unplug and drop faults
and the decoders' own tests cover.

Links that carry frames rather than bytes (CAN) are not tapped.

A wire model (hil.links.wire.WireModel: ``wire=ftdi-16ms`` on the link) puts an adapter's
latency and line time between the two. In real time (``delay_frames``) each frame is really
held until its modelled arrival (the USB frame grid, the latency timer, the baud rate's
serialisation, one frame after another on each line) by a thread that owns the link
(hil/session/wire_pump.py).
In lockstep nothing is held: each period's traffic is accounted on a modelled clock
(``wire_stats``: the modelled wire time, and the lockstep rate projected from it and the
measured time), so a run "through an FTDI at 16 ms" costs no 16 ms sleeps.

Cost: the frames go through the bench's codec (protocol.codec_impl(): the firmware's C codec
as an extension module when built). While no link fault is active a frame out is encoded,
captured and sent, and the bytes in are captured and decoded as one chunk (their frames counted
by their delimiters), with no per-frame Python call.
"""
from __future__ import annotations

import os
import random
import time
from array import array
from collections import deque
from configfile.dataclass_methods import dataclass

from protocol import codec_impl

FAULT_KINDS = ("drop", "corrupt", "delay", "duplicate", "reorder", "unplug")
DIRECTIONS = ("out", "in")  # out: bench -> board; in: board -> bench


@dataclass
class LinkFault:
    kind: str                 # one of FAULT_KINDS
    rate: float = 1.0         # probability per frame (drop, corrupt, duplicate, reorder)
    bits: int = 1             # corrupt: bits flipped per damaged frame
    periods: int = 1          # delay: how long frames are held
    direction: str = "both"   # out | in | both
    until_period: int | None = None  # lifted at this period (None: until cleared)
    seed: int | None = None   # its own random streams (None: the tap's, seeded by the session)

    def __post_init__(self) -> None:
        if self.direction not in ("both", *DIRECTIONS):
            raise ValueError(f"link fault direction must be out, in or both, got {self.direction!r}")
        if not 0.0 <= self.rate <= 1.0:
            raise ValueError(f"link fault rate must be in [0, 1], got {self.rate!r}")
        if self.bits < 1 or self.periods < 1:
            raise ValueError("link fault bits and periods must be >= 1")
        self._rng = ({d: random.Random(f"{self.seed}:{d}:{self.kind}") for d in DIRECTIONS}
                     if self.seed is not None else None)

    def applies_to(self, direction: str) -> bool:
        return self.direction in ("both", direction)


def tappable(link) -> bool:
    return hasattr(link, "send_bytes") and hasattr(link, "read_bytes")


class LinkTap:
    """Same interface as a link (send, recv, close, counters), plus faults and capture."""

    def __init__(self, link, seed: int = 0, wire=None, delay_frames: bool = False):
        self.link = link
        self.url = getattr(link, "url", "")
        codec = codec_impl()
        self._encoder = codec.FrameEncoder()
        self._decoder = codec.StreamDecoder()
        # decoded messages not taken yet; the session's period loop pops it directly
        self.inbox: deque = deque()
        self._partial = bytearray()
        self._rng = {d: random.Random(f"{seed}:{d}") for d in DIRECTIONS}
        self._held: list[tuple[int, str, bytes]] = []
        self._reorder_slot: dict[str, bytes | None] = {d: None for d in DIRECTIONS}
        self.faults: dict[str, LinkFault] = {}
        self.period = 0
        self.stats = {f"{d}_{what}": 0 for d in DIRECTIONS
                      for what in ("frames", "dropped", "corrupted", "delayed", "duplicated",
                                   "reordered", "unplugged")}
        # Raw frames since the last take_capture(): the session batches them into the log.
        self.captured = {d: bytearray() for d in DIRECTIONS}
        self.captured_frames = {d: 0 for d in DIRECTIONS}
        # frames the C period exchange captured (the link's exchange_counts), and how many of
        # them the last take_capture() already counted
        self._exchange_counts = None
        self._exchange_taken = (0, 0)
        # the descriptor loop's own counts (descriptor_target), and how much of them the link's
        # counters already have
        self._direct_counts = None
        self._direct_settled = (0, 0, 0)
        # the wire model (None: none): frames held in real time, time accounted in lockstep
        self.wire = wire
        self._wire_delay = wire is not None and delay_frames
        self._pump = None
        if self._wire_delay:
            from hil.session.wire_pump import WirePump

            self._pump = WirePump(self, wire)
        self._wire_clock_s = 0.0          # the modelled clock of the lockstep accounting
        self._wire_marks = None           # captured lengths at the last tick
        self._wire_started = None         # monotonic time of the first accounted tick
        self._wire_periods = 0

    # ---------------------------------------------------------------- faults
    def set_fault(self, name: str, fault: LinkFault) -> None:
        if fault.kind not in FAULT_KINDS:
            raise ValueError(f"unknown link fault '{fault.kind}' (known: {', '.join(FAULT_KINDS)})")
        self.faults[name] = fault

    def clear_fault(self, name: str) -> None:
        self.faults.pop(name, None)
        if not self.faults:
            for direction, frame in self._flush_reorder():
                self._deliver(direction, frame)

    def tick(self, period: int) -> None:
        """Called once per period: lifts expired faults, releases delayed frames."""
        if self._pump is not None:
            with self._pump.lock:       # the pump thread decodes under the same lock
                self._tick(period)
        else:
            self._tick(period)

    def _tick(self, period: int) -> None:
        self.period = period
        if self.wire is not None and not self._wire_delay:
            self._wire_account()
        if self.faults:
            expired = [n for n, f in self.faults.items()
                       if f.until_period is not None and period >= f.until_period]
            for name in expired:
                self.clear_fault(name)
        if self._held:
            due = [h for h in self._held if h[0] <= period]
            if due:
                self._held = [h for h in self._held if h[0] > period]
                for _, direction, frame in due:
                    self._deliver(direction, frame)

    def _flush_reorder(self):
        out = []
        for direction in DIRECTIONS:
            frame = self._reorder_slot[direction]
            if frame is not None:
                out.append((direction, frame))
                self._reorder_slot[direction] = None
        return out

    def _apply(self, direction: str, frame: bytes) -> list[bytes]:
        stats = self.stats
        stats[f"{direction}_frames"] += 1
        frames = [frame]
        for fault in self.faults.values():
            if not fault.applies_to(direction):
                continue
            rng = fault._rng[direction] if fault._rng is not None else self._rng[direction]
            kind = fault.kind
            if kind == "unplug":
                stats[f"{direction}_unplugged"] += len(frames)
                return []
            if kind == "drop":
                kept = [f for f in frames if rng.random() >= fault.rate]
                stats[f"{direction}_dropped"] += len(frames) - len(kept)
                frames = kept
            elif kind == "corrupt":
                damaged = []
                for f in frames:
                    if rng.random() < fault.rate and len(f) > 1:
                        f = _flip_bits(f, fault.bits, rng)
                        stats[f"{direction}_corrupted"] += 1
                    damaged.append(f)
                frames = damaged
            elif kind == "duplicate":
                doubled = []
                for f in frames:
                    doubled.append(f)
                    if rng.random() < fault.rate:
                        doubled.append(f)
                        stats[f"{direction}_duplicated"] += 1
                frames = doubled
            elif kind == "delay":
                for f in frames:
                    self._held.append((self.period + fault.periods, direction, f))
                stats[f"{direction}_delayed"] += len(frames)
                return []
            elif kind == "reorder":
                swapped = []
                for f in frames:
                    held = self._reorder_slot[direction]
                    if held is not None:
                        swapped += [f, held]
                        self._reorder_slot[direction] = None
                    elif rng.random() < fault.rate:
                        self._reorder_slot[direction] = f
                        stats[f"{direction}_reordered"] += 1
                    else:
                        swapped.append(f)
                frames = swapped
        return frames

    # ------------------------------------------------------------ the wire model
    def _wire_account(self) -> None:
        """Lockstep: the traffic since the last tick as one modelled exchange (SAMPLE and
        whatever else went out, then the answers), on the model's own clock."""
        marks = (len(self.captured["out"]), len(self.captured["in"]))
        if self._wire_marks is not None:
            out_b, in_b = marks[0] - self._wire_marks[0], marks[1] - self._wire_marks[1]
            if out_b or in_b:
                self._wire_clock_s += self.wire.exchange_s(self._wire_clock_s, out_b, in_b)
                self._wire_periods += 1
        else:
            self._wire_started = time.monotonic()
        self._wire_marks = marks

    def wire_stats(self) -> dict:
        """The wire model's figures: in lockstep the modelled wire time of the periods run and
        the lockstep rate it projects (modelled wire time plus the time really measured)."""
        if self.wire is None:
            return {}
        stats = {"wire_model": self.wire.name, "wire_mode": "held" if self._wire_delay
                 else "accounted"}
        if not self._wire_delay and self._wire_periods:
            measured = time.monotonic() - self._wire_started
            periods = self._wire_periods
            stats.update(wire_periods=periods, wire_modelled_s=self._wire_clock_s,
                         wire_measured_s=measured,
                         wire_projected_rate_hz=periods / (self._wire_clock_s + measured))
        return stats

    def _send_out(self, frame: bytes) -> None:
        if self._pump is not None:
            self._pump.send(frame)
        else:
            self.link.send_bytes(frame)

    # ------------------------------------------------------------ data paths
    def _deliver(self, direction: str, frame: bytes) -> None:
        self.captured[direction] += frame
        self.captured_frames[direction] += 1
        if direction == "out":
            self._send_out(frame)
        else:
            self.inbox.extend(self._decoder.feed(frame))

    def _pass(self, direction: str, frame: bytes) -> None:
        if self.faults:
            for f in self._apply(direction, frame):
                self._deliver(direction, f)
        else:
            self._deliver(direction, frame)

    def send(self, msg) -> None:
        frame = self._encoder.encode(msg)
        if self._pump is not None:
            with self._pump.lock:       # the pump thread counts and decodes under it too
                self._pass("out", frame)
            return
        if self.faults:
            self._pass("out", frame)
            return
        self.captured["out"] += frame
        self.captured_frames["out"] += 1
        self.link.send_bytes(frame)

    def send_bytes(self, data: bytes) -> None:
        self._pass("out", data)

    def _c_codec(self) -> bool:
        """This tap frames and decodes with the C codec (what its C exchanges need)."""
        from protocol import ccodec

        return (ccodec.AVAILABLE and isinstance(self._encoder, ccodec.FrameEncoder)
                and isinstance(self._decoder, ccodec.StreamDecoder))

    def _count_with(self, counts) -> None:
        """The C exchange's counts (frames out, frames in, ...) from now on: take_capture()
        counts the captured frames from them."""
        if self._exchange_counts is not counts:
            self._exchange_counts = counts
            self._exchange_taken = (counts[0], counts[1])

    def sample_exchanger(self):
        """A function (k, adc_i1, adc_i2, adc_vdc, encoder, status) that sends SAMPLE(k) and
        queues the answers in one C call, for a firmware library in this process with the C
        codec; None where that does not apply (another link, the Python codec). It works only
        while no link fault is active and nothing is queued: the caller checks `fast_ready`.
        Its bound arguments (`.args`) are the in-process target of protocol.ccodec's period
        loop, exchange_periods."""
        from protocol import ccodec

        make = getattr(self.link, "sample_exchange", None)
        if (make is None or self.wire is not None or not self._c_codec()
                or self.link.exchange_target() is None):
            return None
        self._count_with(self.link.exchange_counts)
        return make(ccodec.exchange_sample, self._encoder, self._decoder, self.captured["out"],
                    self.captured["in"], self.inbox)

    def descriptor_target(self, answer_timeout_s: float):
        """protocol.ccodec.exchange_periods' target for a link with a file descriptor
        (SerialLink on a device or a pseudo-terminal), or None (another link, the Python
        codec): the descriptor, the answer wait, the write timeout, this tap's codec,
        captures, queue and partial-frame buffer, and counts of its own (frames out, frames in,
        bytes out, bytes in), which settle_direct() hands to the link's counters. It runs
        while `direct_ready`."""
        descriptor = getattr(self.link, "descriptor", None)
        fd = descriptor() if descriptor is not None else None
        if fd is None or not self._c_codec():
            return None
        if self._direct_counts is None:
            self._direct_counts = array("q", [0] * 5)
            self._direct_settled = (0, 0, 0)
        self._count_with(self._direct_counts)
        return (fd, float(answer_timeout_s), float(self.link.write_timeout_s), self._encoder,
                self._decoder, self.captured["out"], self.captured["in"], self._direct_counts,
                self.inbox, self._partial)

    @property
    def direct_ready(self) -> bool:
        """No link fault and nothing held: the C loop may read and write the link's descriptor
        itself (a half-read frame stays in the buffer it shares with this tap)."""
        return (not self.faults and not self._held and self.wire is None
                and self.link.descriptor() is not None)

    def settle_direct(self) -> None:
        """What the C loop wrote and read on the descriptor since the last call, added to the
        link's own counters (its tx_frames, tx_bytes, rx_bytes)."""
        counts = self._direct_counts
        frames, out, inb = self._direct_settled
        self.link.count_direct(counts[0] - frames, counts[2] - out, counts[3] - inb)
        self._direct_settled = (counts[0], counts[2], counts[3])

    def direct_failure(self, errno_value: int, what: str) -> ConnectionError:
        """The C loop's I/O failure worded as SerialLink words it."""
        detail = "" if what.startswith("the other end") or not errno_value else \
            f": [Errno {errno_value}] {os.strerror(errno_value)}"
        return ConnectionError(f"serial port '{self.url}': {what}{detail}")

    @property
    def fast_ready(self) -> bool:
        """No link fault, nothing held, no half-read frame, and the link has nothing of its own
        waiting: the C exchange may bypass the tap (messages already queued stay first: the
        exchange appends behind them)."""
        return (not self.faults and not self._held and not self._partial and self.wire is None
                and self._exchange_counts is not None and self.link.exchange_ready)

    def _take_in(self, data: bytes) -> None:
        buf = self._partial
        if buf or data[-1] != 0:
            buf += data
            end = buf.rfind(0)
            if end < 0:
                return
            complete = bytes(buf[: end + 1])
            del buf[: end + 1]
        else:
            # whole frames and nothing before them (a board's one write of its answers): taken
            # as they are, without the partial buffer's copies
            complete = data
        if not self.faults:
            # every complete frame of the chunk at once: captured, counted by its delimiter,
            # decoded in one call
            self.captured["in"] += complete
            self.captured_frames["in"] += complete.count(0)
            self.inbox.extend(self._decoder.feed(complete))
            return
        start = 0
        while start < len(complete):
            stop = complete.index(0, start) + 1
            self._pass("in", complete[start:stop])
            start = stop

    def recv(self, timeout_s: float | None = 0.0):
        inbox = self.inbox
        if inbox:
            return inbox.popleft()
        if self._pump is not None:
            return self._pump.recv(inbox, timeout_s)
        if timeout_s is None:
            deadline = remaining = None
        else:
            remaining = max(0.0, timeout_s)
            deadline = time.monotonic() + remaining
        while True:
            data = self.link.read_bytes(remaining)
            if data:
                self._take_in(data)
                if inbox:
                    return inbox.popleft()
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return None

    def take_capture(self) -> dict[str, tuple[bytes, int]]:
        if self._pump is not None:
            with self._pump.lock:
                return self._take_capture()
        return self._take_capture()

    def _take_capture(self) -> dict[str, tuple[bytes, int]]:
        counts = self._exchange_counts
        if counts is not None:          # what the C exchange captured since the last time
            out0, in0 = self._exchange_taken
            self.captured_frames["out"] += counts[0] - out0
            self.captured_frames["in"] += counts[1] - in0
            self._exchange_taken = (counts[0], counts[1])
        out = {}
        for d in DIRECTIONS:
            out[d] = (bytes(self.captured[d]), self.captured_frames[d])
            self.captured[d].clear()
            self.captured_frames[d] = 0
        if self._wire_marks is not None:
            self._wire_marks = (0, 0)
        return out

    @property
    def counters(self) -> dict[str, int]:
        counters = dict(self.link.counters)
        counters.update(self._decoder.counters)  # the tap decodes what the bench receives
        counters.update({k: v for k, v in self.stats.items() if v})
        counters.update(self.wire_stats())
        return counters

    def close(self) -> None:
        if self._pump is not None:
            self._pump.close()
        self.link.close()


def _flip_bits(frame: bytes, bits: int, rng: random.Random) -> bytes:
    """``bits`` distinct bit flips before the frame's delimiter, none leaving a 0x00 byte."""
    out = bytearray(frame)
    body_bits = (len(out) - 1) * 8          # the last byte is the 0x00 delimiter
    flipped: set[int] = set()
    attempts = 64 * bits                    # a frame always has far more valid bits than this
    while len(flipped) < min(bits, body_bits) and attempts:
        attempts -= 1
        bit = rng.randrange(body_bits)
        if bit in flipped or out[bit >> 3] ^ (1 << (bit & 7)) == 0:
            continue
        out[bit >> 3] ^= 1 << (bit & 7)
        flipped.add(bit)
    return bytes(out)
