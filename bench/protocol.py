"""Wire-protocol costs: `python -m bench protocol [--quick]`.

- Python codec: microseconds to encode and to decode one SAMPLE and one GATES frame.
- C codec: nanoseconds per frame (protocol/c/build/hil_codec_bench, clock_gettime).
- Round trips per second between Python and the C echo (protocol/c/build/hil_echo) over a
  pseudo-terminal: SAMPLE frames through SerialLink and the C decoder/encoder, against the same
  loop with the echo in raw byte mode and the Python side writing and reading the same bytes
  without the codec. The difference is what the protocol costs on top of the line.

Every figure is the median of several batches; the machine is shared and noisy, so batch
spreads are reported too.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import termios
import time
import tty
from pathlib import Path

from protocol.can_mapping import CanReassembler, can_pack
from protocol.codec import FrameEncoder, StreamDecoder
from protocol.links import SerialLink
from protocol.messages import Gates, Sample

C_DIR = Path(__file__).resolve().parent.parent / "protocol" / "c"
SAMPLE = Sample(123_456, 2048, 1000, 3000, 65_000, 5)
GATES = Gates(123_456, 0x29)


def _median_us(fn, iterations: int, batches: int) -> tuple[float, float]:
    """(median, spread) of per-call microseconds over batches."""
    fn(iterations // 10 + 1)  # warm-up
    per = []
    for _ in range(batches):
        t0 = time.perf_counter()
        fn(iterations)
        per.append((time.perf_counter() - t0) / iterations * 1e6)
    return statistics.median(per), max(per) - min(per)


def python_codec(iterations: int, batches: int) -> dict:
    out: dict[str, float] = {}
    for name, msg in (("sample", SAMPLE), ("gates", GATES)):
        enc, dec = FrameEncoder(), StreamDecoder()
        frame = enc.encode(msg)

        def encode(n, enc=enc, msg=msg):
            e = enc.encode
            for _ in range(n):
                e(msg)

        def decode(n, dec=dec, frame=frame):
            f = dec.feed
            for _ in range(n):
                f(frame)

        def both(n, enc=enc, dec=dec, msg=msg):
            e, f = enc.encode, dec.feed
            for _ in range(n):
                f(e(msg))

        def can(n, msg=msg):
            rx = CanReassembler()
            feed = rx.feed
            for _ in range(n):
                for i, d in can_pack(msg, 0):
                    feed(i, d)

        out[f"{name}_frame_bytes"] = len(frame)
        out[f"{name}_encode_us"], _ = _median_us(encode, iterations, batches)
        out[f"{name}_decode_us"], _ = _median_us(decode, iterations, batches)
        out[f"{name}_encode_decode_us"], out[f"{name}_encode_decode_spread_us"] = \
            _median_us(both, iterations, batches)
        out[f"{name}_can_pack_reassemble_us"], _ = _median_us(can, iterations, batches)
        assert dec.frames_ok > 0 and dec.crc_errors == 0
    return {k: round(v, 3) for k, v in out.items()}


def _make(*targets: str) -> None:
    proc = subprocess.run(["make", "-s", "-C", str(C_DIR), *targets], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"make -C {C_DIR} {' '.join(targets)} failed:\n{proc.stdout}{proc.stderr}")


def c_codec(quick: bool) -> dict:
    _make("build/hil_codec_bench")
    args = ["20000", "3"] if quick else ["200000", "7"]
    proc = subprocess.run([str(C_DIR / "build" / "hil_codec_bench"), *args], capture_output=True, text=True,
                          check=True)
    return json.loads(proc.stdout)


def _spawn_echo(raw: bool) -> tuple[subprocess.Popen, SerialLink, int]:
    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    path = os.ttyname(slave)
    args = [str(C_DIR / "build" / "hil_echo"), "--fd", str(master)] + (["--raw"] if raw else [])
    proc = subprocess.Popen(args, pass_fds=(master,), stderr=subprocess.DEVNULL)
    os.close(master)
    link = SerialLink(path, baudrate=2_000_000)
    os.close(slave)  # the link holds the slave now
    return proc, link, 0


def pty_round_trips(round_trips: int, batches: int) -> dict:
    _make("build/hil_echo")
    frame = FrameEncoder().encode(SAMPLE)
    results = {}
    for mode in ("raw", "protocol"):
        proc, link, _ = _spawn_echo(raw=mode == "raw")
        try:
            per_s = []
            k = 0
            for b in range(batches + 1):  # the first batch warms up
                t0 = time.perf_counter()
                if mode == "protocol":
                    for _ in range(round_trips):
                        k += 1
                        link.send(Sample(k & 0xFFFFFFFF, 2048, 1000, 3000, k & 0xFFFF, 0))
                        got = link.recv(1.0)
                        if got is None or got.period != k:
                            raise RuntimeError(f"echo answered {got!r} to period {k}")
                else:
                    n = len(frame)
                    for _ in range(round_trips):
                        link.send_bytes(frame)
                        got = b""
                        while len(got) < n:
                            chunk = link.read_bytes(1.0)
                            if not chunk:
                                raise RuntimeError("raw echo did not answer")
                            got += chunk
                elapsed = time.perf_counter() - t0
                if b:
                    per_s.append(round_trips / elapsed)
            results[mode] = (statistics.median(per_s), max(per_s) - min(per_s))
            if mode == "protocol":
                counters = link.counters
                if counters["crc_errors"] or counters["framing_errors"] or counters["seq_gaps"]:
                    raise RuntimeError(f"errors on a clean pty: {counters}")
        finally:
            link.close()
            proc.wait(5)
    raw_rt, raw_spread = results["raw"]
    proto_rt, proto_spread = results["protocol"]
    return {
        "frame": "SAMPLE", "frame_bytes": len(frame), "round_trips_per_batch": round_trips, "batches": batches,
        "raw_round_trips_per_s": round(raw_rt), "raw_spread_per_s": round(raw_spread),
        "protocol_round_trips_per_s": round(proto_rt), "protocol_spread_per_s": round(proto_spread),
        "raw_us_per_round_trip": round(1e6 / raw_rt, 2),
        "protocol_us_per_round_trip": round(1e6 / proto_rt, 2),
        "protocol_cost_us_per_round_trip": round(1e6 / proto_rt - 1e6 / raw_rt, 2),
        "protocol_cost_percent": round(100.0 * (raw_rt / proto_rt - 1.0), 1),
    }


def run(quick: bool = False) -> dict:
    return {
        "command": "python -m bench protocol" + (" --quick" if quick else ""),
        "python_codec": python_codec(*((5_000, 3) if quick else (50_000, 7))),
        "c_codec_ns": c_codec(quick),
        "pty_round_trip": pty_round_trips(*((500, 3) if quick else (4_000, 7))),
    }


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
