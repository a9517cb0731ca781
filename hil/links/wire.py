"""The wire between the bench and a real board: frame sizes, line time, and the USB latency
of the adapter, as a model the link tap can apply (docs/adapters.md).

Frame sizes come from protocol/SPEC.md: a serial frame is its payload + 8 bytes (4 header,
2 CRC, 1 COBS code byte, 1 delimiter; section 3.2), a UART byte is 10 bit times (8N1;
section 11), a classic CAN data frame is 47 + 8 * dlc bits before bit stuffing, and stuffing
adds at most one bit per 4 after the first of the 34 + 8 * dlc stuffed bits (section 11).

A WireModel is one adapter between the host and the board, per direction:

* out (bench -> board): the host's bulk OUT transfer goes within the current USB frame (no
  wait modelled), then the adapter's UART sends the bytes at the line's baud rate (none for a
  board with a native USB port, CDC-ACM);
* in (board -> bench): the board's UART sends the bytes, the adapter holds them for
  ``latency_s`` (an FTDI chip's latency timer) and the host takes them at the next USB frame
  (``grid_s``: 1 ms at full speed, 125 us microframes at high speed), so a round trip is a
  whole number of frames: at most 1,000 a second at full speed.

The time of one lockstep period is then the SAMPLE's way out plus the answer's way back, on a
clock that starts on a USB frame boundary (so the grid's phase is the model's own, not the
machine's). ``wire=NAME`` on any byte link (``stub-pty?wire=ftdi-16ms``,
``serial:/dev/ttyACM0?wire=cdc-fs``) puts the model in the session's link tap.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

#: Payload bytes of each message that crosses every period (SPEC.md section 6).
PAYLOAD_BYTES = {"SAMPLE": 11, "GATES": 5, "DUTY": 10, "DUTY_LEGS": 11, "TELEMETRY": 56,
                 "COMMAND": 14, "HELLO_BENCH": 18}
#: Data bytes of each message in one classic CAN frame, or its frames (SPEC.md 7.2, 7.4).
CAN_DLC = {"SAMPLE": (8,), "GATES": (5,), "DUTY": (8,), "DUTY_LEGS": (8,),
           "TELEMETRY": (8,) * 8}
#: SAMPLE_SENSORS (SPEC 6.13): a fixed head (period u32, sensor_set u16, status u8), then the
#: bytes of each sensor in the set; bit -> its bytes.
SAMPLE_SENSORS_HEAD_BYTES = 7
SENSOR_BYTES = {0x0001: 2, 0x0002: 2, 0x0004: 2, 0x0008: 2, 0x0010: 2, 0x0020: 1, 0x0040: 6,
                0x0080: 1, 0x0100: 4, 0x0200: 2}
CAN_SEGMENT_BYTES = 7               # SPEC 7.4: a segmented message's chunk per frame
SERIAL_OVERHEAD_BYTES = 8           # 4 header + 2 CRC + 1 COBS code byte + 1 delimiter
UART_BITS_PER_BYTE = 10             # 8N1: start bit, 8 data bits, stop bit
USB_FULL_SPEED_FRAME_S = 1e-3       # USB 2.0: a frame every 1 ms at full speed
USB_HIGH_SPEED_MICROFRAME_S = 125e-6    # ... and a microframe every 125 us at high speed
FTDI_DEFAULT_LATENCY_TIMER_S = 16e-3    # FTDI AN232B-04; Linux ftdi_sio default
FTDI_PACKET_DATA_BYTES = 62            # a full-speed packet's 64 bytes less 2 status bytes
DEFAULT_BAUD = 2_000_000            # what the bench opens a pseudo-terminal's line at


def serial_frame_bytes(message: str, sensor_set: int = 0) -> int:
    """Bytes on a serial line for one message (SPEC.md 3.2: payload + 8); SAMPLE_SENSORS' by
    its `sensor_set`."""
    if message == "SAMPLE_SENSORS":
        return sample_sensors_payload_bytes(sensor_set) + SERIAL_OVERHEAD_BYTES
    return PAYLOAD_BYTES[message] + SERIAL_OVERHEAD_BYTES


def sample_sensors_payload_bytes(sensor_set: int) -> int:
    """SAMPLE_SENSORS' payload for a sensor set (SPEC 6.13: 7 + the set's sensors' bytes);
    ValueError for a reserved bit, whose layout nobody knows."""
    unknown = sensor_set & ~sum(SENSOR_BYTES)
    if unknown or sensor_set < 0:
        raise ValueError(f"sensor set 0x{sensor_set:04x} has reserved bits 0x{unknown:04x}")
    return SAMPLE_SENSORS_HEAD_BYTES + sum(n for bit, n in SENSOR_BYTES.items() if sensor_set & bit)


def sample_sensors_can_dlc(sensor_set: int) -> tuple[int, ...]:
    """The CAN frames' dlc of one SAMPLE_SENSORS (segmented, SPEC 7.4: 7 payload bytes behind
    a one-byte header per frame, the last frame shorter)."""
    n = sample_sensors_payload_bytes(sensor_set)
    full, rest = divmod(n, CAN_SEGMENT_BYTES)
    return (8,) * full + ((1 + rest,) if rest else ())


def uart_time_s(nbytes: float, baud: int) -> float:
    """Seconds a UART at ``baud`` (8N1) takes to send ``nbytes``."""
    return nbytes * UART_BITS_PER_BYTE / baud


def can_frame_bits(dlc: int, stuffed: bool = False) -> int:
    """Bits of one classic CAN data frame with an 11-bit identifier: 47 + 8 * dlc, and with
    stuffing at its worst one more bit per 4 of the 34 + 8 * dlc bits that are stuffed."""
    if not 0 <= dlc <= 8:
        raise ValueError(f"CAN dlc {dlc} is not 0..8")
    bits = 47 + 8 * dlc
    if stuffed:
        bits += (34 + 8 * dlc - 1) // 4
    return bits


def can_message_bits(message: str, stuffed: bool = False, sensor_set: int = 0) -> int:
    dlcs = sample_sensors_can_dlc(sensor_set) if message == "SAMPLE_SENSORS" else CAN_DLC[message]
    return sum(can_frame_bits(dlc, stuffed) for dlc in dlcs)


def wire_time_table(bauds=(115_200, 921_600, 2_000_000, 3_000_000),
                    bitrates=(500_000, 1_000_000),
                    messages=("SAMPLE", "GATES", "DUTY", "DUTY_LEGS", "TELEMETRY")) -> str:
    """docs/adapters.md's table of line time per message (a test holds the doc to it)."""
    head = ["message", "bytes"] + [f"{b} baud" for b in bauds] + ["CAN bits"] + \
        [f"CAN {r / 1e6:g} Mbit/s" if r >= 1_000_000 else f"CAN {r // 1000} kbit/s"
         for r in bitrates]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name in messages:
        n = serial_frame_bytes(name)
        cells = [name, str(n)] + [_us(uart_time_s(n, b)) for b in bauds]
        lo, hi = can_message_bits(name), can_message_bits(name, stuffed=True)
        cells.append(f"{lo} - {hi}")
        cells += [f"{_us(lo / r)} - {_us(hi / r)}" for r in bitrates]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def lockstep_rate_table(names=("ftdi-16ms", "ftdi-4ms", "ftdi-1ms", "cp210x", "ch340",
                               "cdc-fs", "cdc-hs")) -> str:
    """docs/adapters.md's table of what each modelled adapter allows (GATES answers at
    2 Mbaud, the board's own computation not counted; a test holds the doc to it)."""
    chatty = serial_frame_bytes("GATES") + serial_frame_bytes("TELEMETRY")
    rows = ["| wire model | driver | one lockstep period | periods/s | 1 s at 20 kHz takes | "
            "periods/s with TELEMETRY every period | shortest real-time period |",
            "|---|---|---|---|---|---|---|"]
    for name in names:
        model = parse_wire(name)
        period = model.lockstep_period_s()
        rows.append(f"| `{name}` | {model.driver} | {_us(period)} | {1 / period:.0f} | "
                    f"{20_000 * period:.1f} s | {model.lockstep_rate_hz_with(chatty):.0f} | "
                    f"{_us(model.shortest_realtime_period_s())} |")
    return "\n".join(rows)


def _us(seconds: float) -> str:
    us = seconds * 1e6
    if us < 1000:
        return f"{us:.0f} µs"
    return f"{us / 1000:.2f} ms" if us < 10_000 else f"{us / 1000:.1f} ms"


@dataclass(frozen=True)
class Direction:
    """One direction of the wire: a fixed latency, then the USB frame grid it waits for."""

    latency_s: float = 0.0
    grid_s: float = 0.0

    def arrival(self, t_s: float, held: bool = True) -> float:
        """When something handed over at t_s reaches the far side (grid-aligned); ``held``
        False: without the latency (an FTDI packet that filled up goes at once)."""
        t = t_s + (self.latency_s if held else 0.0)
        if self.grid_s > 0.0:
            # the host takes it at the next (micro)frame after it is ready: strictly later,
            # also from a boundary (rounded to a millionth of a frame against float noise)
            t = (math.floor(round(t / self.grid_s, 6)) + 1) * self.grid_s
        return t


@dataclass(frozen=True)
class WireModel:
    name: str
    driver: str                   # the Linux driver such an adapter uses
    out: Direction = Direction()
    back: Direction = Direction()           # board -> bench
    baud: int | None = DEFAULT_BAUD   # None: a native USB port (no UART in the path)
    note: str = ""
    # an adapter that sends a full USB packet at once, whatever its latency: the data bytes
    # of one packet (FTDI full speed: 64-byte packets less 2 status bytes = 62)
    flush_bytes: int | None = None

    def sample_arrival_s(self, t_s: float, out_bytes: float) -> float:
        """SAMPLE sent at t_s reaches the board (USB out, then the adapter's UART)."""
        return self.out.arrival(t_s) + self._line(out_bytes)

    def answer_arrival_s(self, t_s: float, in_bytes: float) -> float:
        """An answer the board starts sending at t_s reaches the bench (UART, then USB in).
        What the board sends with it counts: ``flush_bytes`` or more (GATES + TELEMETRY, 77
        bytes) fill a packet, which goes without the latency, the answer at its head."""
        if self.flush_bytes is not None and in_bytes >= self.flush_bytes:
            return self.back.arrival(t_s + self._line(self.flush_bytes), held=False)
        return self.back.arrival(t_s + self._line(in_bytes))

    def _line(self, nbytes: float) -> float:
        return 0.0 if self.baud is None else uart_time_s(nbytes, self.baud)

    def exchange_s(self, t_s: float, out_bytes: float, in_bytes: float,
                   compute_s: float = 0.0) -> float:
        """Modelled seconds from sending out_bytes at t_s to the answer's arrival."""
        at_board = self.sample_arrival_s(t_s, out_bytes)
        return self.answer_arrival_s(at_board + compute_s, in_bytes) - t_s

    def lockstep_period_s(self, answer: str = "GATES", compute_s: float = 0.0,
                          periods: int = 64, in_bytes: int | None = None,
                          sensor_set: int | None = None) -> float:
        """Mean modelled wall time of one lockstep period (SAMPLE, or a sensor-set board's
        SAMPLE_SENSORS for `sensor_set`, then the answer: ``in_bytes`` if given, e.g. GATES +
        TELEMETRY), over ``periods`` periods from a USB frame boundary (the grid's phase may
        change from period to period)."""
        out_b = serial_frame_bytes("SAMPLE") if sensor_set is None else \
            serial_frame_bytes("SAMPLE_SENSORS", sensor_set)
        in_b = serial_frame_bytes(answer) if in_bytes is None else in_bytes
        t = 0.0
        for _ in range(periods):
            t += self.exchange_s(t, out_b, in_b, compute_s)
        return t / periods

    def lockstep_rate_hz(self, answer: str = "GATES", compute_s: float = 0.0) -> float:
        return 1.0 / self.lockstep_period_s(answer, compute_s)

    def lockstep_rate_hz_with(self, in_bytes: int, compute_s: float = 0.0) -> float:
        """The lockstep rate when the board sends ``in_bytes`` a period."""
        return 1.0 / self.lockstep_period_s(compute_s=compute_s, in_bytes=in_bytes)

    def shortest_realtime_period_s(self, answer: str = "GATES", compute_s: float = 0.0) -> float:
        """The shortest real-time period whose answer is back before the next tick: the
        round trip's worst case over the grid's phase (a SAMPLE sent just after a frame
        boundary waits almost a whole frame at each grid), and at least each line's bytes."""
        out_b, in_b = serial_frame_bytes("SAMPLE"), serial_frame_bytes(answer)
        worst = (self.out.latency_s + self.out.grid_s + self._line(out_b) + compute_s
                 + self._line(in_b) + self.back.latency_s + self.back.grid_s)
        return max(worst, self._line(out_b), self._line(in_b))

    def describe(self) -> str:
        parts = [f"out {_us(self.out.latency_s)} + {_grid(self.out.grid_s)}",
                 f"in {_us(self.back.latency_s)} + {_grid(self.back.grid_s)}",
                 "native USB" if self.baud is None else f"{self.baud} baud"]
        return f"{self.name} ({', '.join(parts)})"

    def settings(self) -> dict[str, str]:
        """For a log's metadata."""
        return {"wire_model": self.name, "driver": self.driver,
                "out_latency_s": f"{self.out.latency_s:g}", "out_grid_s": f"{self.out.grid_s:g}",
                "in_latency_s": f"{self.back.latency_s:g}", "in_grid_s": f"{self.back.grid_s:g}",
                "baud": "native USB" if self.baud is None else str(self.baud)}


def _grid(grid_s: float) -> str:
    return "no USB grid" if grid_s <= 0 else f"{_us(grid_s)} USB frames"


def ftdi(latency_timer_ms: int, baud: int = DEFAULT_BAUD) -> WireModel:
    """An FTDI full-speed adapter (FT232R, FT231X, ...): the chip holds what the board sends
    until its latency timer expires or 62 bytes fill a USB packet (FTDI AN232B-04), then the
    host takes it at the next 1 ms frame."""
    if not 1 <= latency_timer_ms <= 255:
        raise ValueError(f"FTDI latency timer {latency_timer_ms} ms is not 1..255 ms")
    return WireModel(f"ftdi-{latency_timer_ms}ms", "ftdi_sio",
                     out=Direction(),
                     back=Direction(latency_timer_ms * 1e-3, USB_FULL_SPEED_FRAME_S), baud=baud,
                     flush_bytes=FTDI_PACKET_DATA_BYTES)


def _fixed(text: str) -> float:
    m = re.fullmatch(r"(\d+(?:\.\d+)?)(us|ms)", text)
    if m is None:
        raise ValueError(text)
    return float(m.group(1)) * (1e-6 if m.group(2) == "us" else 1e-3)


PRESETS = {
    "cdc-fs": lambda baud: WireModel("cdc-fs", "cdc_acm", out=Direction(),
                                     back=Direction(0.0, USB_FULL_SPEED_FRAME_S), baud=None,
                                     note="a native full-speed USB port"),
    "cdc-hs": lambda baud: WireModel("cdc-hs", "cdc_acm", out=Direction(),
                                     back=Direction(0.0, USB_HIGH_SPEED_MICROFRAME_S), baud=None,
                                     note="a native high-speed USB port"),
    # CP210x and CH340: full-speed bridges without a latency timer the host can set; the
    # model is their USB frame (their own buffering is not documented: measure with hil probe)
    "cp210x": lambda baud: WireModel("cp210x", "cp210x", out=Direction(),
                                     back=Direction(0.0, USB_FULL_SPEED_FRAME_S), baud=baud),
    "ch340": lambda baud: WireModel("ch340", "ch341", out=Direction(),
                                    back=Direction(0.0, USB_FULL_SPEED_FRAME_S), baud=baud),
}
WIRE_NAMES = ("ftdi-<1..255>ms", *PRESETS, "fixed-<N>us|ms")


def parse_wire(text: str, baud: int | None = None) -> WireModel:
    """A wire model by name: ftdi-16ms, ftdi-1ms, cdc-fs, cdc-hs, cp210x, ch340, fixed-250us
    (that latency each way, no grid); ``@BAUD`` after a name sets the UART's baud rate
    (default ``baud``, else 2 Mbaud)."""
    name, _, at = text.partition("@")
    try:
        line = int(at) if at else (baud or DEFAULT_BAUD)
    except ValueError:
        raise ValueError(f"wire model '{text}': baud '{at}' is not an integer") from None
    if line <= 0:
        raise ValueError(f"wire model '{text}': baud {line} must be positive")
    m = re.fullmatch(r"ftdi-(\d+)ms", name)
    if m is not None:
        return ftdi(int(m.group(1)), line)
    if name in PRESETS:
        return PRESETS[name](line)
    if name.startswith("fixed-"):
        try:
            each = _fixed(name[len("fixed-"):])
        except ValueError:
            each = None
        if each is not None:
            return WireModel(name, "", out=Direction(each, 0.0), back=Direction(each, 0.0),
                             baud=line)
    raise ValueError(f"unknown wire model '{text}'; expected one of: {', '.join(WIRE_NAMES)} "
                     f"(optionally @BAUD)")


def with_baud(model: WireModel, baud: int | None) -> WireModel:
    return model if baud is None or model.baud is None else replace(model, baud=baud)
