"""Wire-protocol costs: `python -m bench protocol [--quick]`.

- Python codec: microseconds to encode and to decode one SAMPLE and one GATES frame.
- C codec: nanoseconds per frame (protocol/c/build/hil_codec_bench, clock_gettime), and
  instructions per frame under valgrind callgrind (repeatable).
- Codecs on a realistic stream ("codec_stream"): SAMPLE, GATES and TELEMETRY frames with incrementing
  periods and sequence numbers (no gaps), encoded with FrameEncoder and decoded one frame per
  feed (as the session does every period) and as one chunk of 1024 frames (one feed), in
  nanoseconds per frame: the Python codec, the C codec as an extension module (protocol.ccodec),
  the same C decoder reached through cffi in ABI mode with the message built in Python (the
  alternative the extension was chosen over; SAMPLE and GATES), and the pure C figures from
  hil_codec_bench.
- Round trips per second between Python and the C echo (protocol/c/build/hil_echo) over a
  pseudo-terminal: SAMPLE frames through SerialLink and the C decoder/encoder, against the same
  loop with the echo in raw byte mode and the Python side writing and reading the same bytes
  without the codec. The difference is what the protocol costs on top of the line.

Every figure is the median of several batches (raw and protocol batches alternate, so both
see the same load); on a shared, noisy machine the batch ranges and the best batch of each kind
are reported too.
"""
from __future__ import annotations

import importlib
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
from protocol.messages import Gates, Sample, Telemetry

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


STREAM_FRAMES = 1024  # a multiple of 256: the stream repeats without a sequence gap


def _stream_messages(kind: str) -> list:
    if kind == "sample":
        return [Sample(100_000 + k, 2048 + k % 7, 1000 + k % 5, 3000, (17 * k) & 0xFFFF, k & 1)
                for k in range(STREAM_FRAMES)]
    if kind == "gates":
        return [Gates(100_000 + k, (0x29, 0x25, 0x16, 0x1A)[k % 4]) for k in range(STREAM_FRAMES)]
    return [Telemetry(100_000 + k, 1 + k % 6, 2, 1, 0x29, *(0.25 * (k % 9) + i for i in range(12)))
            for k in range(STREAM_FRAMES)]


def _per_frame_ns(fn, batches: int) -> float:
    """Median over batches of ns per frame; fn() handles STREAM_FRAMES frames."""
    fn()  # warm-up
    per = []
    for _ in range(batches):
        t0 = time.perf_counter()
        fn()
        per.append((time.perf_counter() - t0) / STREAM_FRAMES * 1e9)
    return round(statistics.median(per), 1)


def _codec_figures(codec, msgs: list, frames: list[bytes], batches: int) -> dict:
    enc = codec.FrameEncoder()
    dec_frame, dec_chunk = codec.StreamDecoder(), codec.StreamDecoder()
    chunk = b"".join(frames)

    def encode(e=enc.encode, msgs=msgs):
        for m in msgs:
            e(m)

    def decode_each(f=dec_frame.feed, frames=frames):
        for fr in frames:
            f(fr)

    def decode_chunk(f=dec_chunk.feed, chunk=chunk):
        f(chunk)

    out = {"encode_ns": _per_frame_ns(encode, batches),
           "decode_one_frame_per_feed_ns": _per_frame_ns(decode_each, batches),
           "decode_chunk_of_1024_ns": _per_frame_ns(decode_chunk, batches)}
    for dec in (dec_frame, dec_chunk):
        c = dec.counters
        if c["frames_ok"] != (batches + 1) * STREAM_FRAMES or sum(c.values()) != c["frames_ok"]:
            raise RuntimeError(f"{codec.__name__}: a clean stream was not decoded cleanly: {c}")
    if dec_chunk.feed(chunk) != msgs:
        raise RuntimeError(f"{codec.__name__}: decoded messages differ from those encoded")
    return out


def _cffi_decoder():
    """hil_decoder_feed_buf from build/libhilproto.so through cffi (ABI mode, no compiler), the
    message built in Python from the cdata fields: what a cffi front end has to do per frame."""
    import re

    import cffi

    header = (C_DIR / "hil_proto.h").read_text()
    header = re.sub(r"/\*.*?\*/", "", header, flags=re.S)
    structs = re.findall(r"typedef struct \{.*?\} hil_\w+;", header, flags=re.S)
    wanted = ("hil_hello", "hil_sample", "hil_gates", "hil_duty", "hil_command", "hil_telemetry",
              "hil_param_set", "hil_param_get", "hil_param_value", "hil_status", "hil_fault", "hil_heartbeat",
              "hil_msg", "hil_decoder")
    cdef = "\n".join(s for s in structs if s.rsplit("}", 1)[1].strip(" ;") in wanted)
    cdef = cdef.replace("HIL_NAME_MAX", "40").replace("HIL_MAX_RAW_FRAME", "70")
    ffi = cffi.FFI()
    ffi.cdef(cdef + """
        void hil_decoder_init(hil_decoder *dec);
        size_t hil_decoder_feed_buf(hil_decoder *dec, const uint8_t *data, size_t len, hil_msg *out, int *got);
    """)
    lib = ffi.dlopen(str(C_DIR / "build" / "libhilproto.so"))
    dec = ffi.new("hil_decoder *")
    lib.hil_decoder_init(dec)
    out, got = ffi.new("hil_msg *"), ffi.new("int *")
    feed_buf, from_buffer = lib.hil_decoder_feed_buf, ffi.from_buffer

    def feed(data: bytes) -> list:
        msgs, buf, n = [], from_buffer(data), len(data)
        off = 0
        while off < n:
            off += feed_buf(dec, buf + off, n - off, out, got)
            if got[0]:
                if out.type == 2:
                    s = out.u.sample
                    msgs.append(Sample(s.period, s.adc_i1, s.adc_i2, s.adc_vdc, s.encoder, s.status))
                elif out.type == 3:
                    g = out.u.gates
                    msgs.append(Gates(g.period, g.gates))
        return msgs
    return feed, dec


def cffi_decode(kind: str, frames: list[bytes], batches: int) -> dict:
    try:
        feed, dec = _cffi_decoder()
    except Exception as exc:  # noqa: BLE001 - a comparison figure, not a product path
        return {"error": f"cffi comparison unavailable: {exc}"}

    def decode_each(frames=frames):
        for fr in frames:
            feed(fr)

    chunk = b"".join(frames)
    out = {"decode_one_frame_per_feed_ns": _per_frame_ns(decode_each, batches),
           "decode_chunk_of_1024_ns": _per_frame_ns(lambda: feed(chunk), batches)}
    if dec.seq_gaps or dec.crc_errors or dec.framing_errors:
        raise RuntimeError("cffi decoder: a clean stream was not decoded cleanly")
    return out


def codec_stream(quick: bool) -> dict:
    """ns per frame on a realistic stream: Python codec, C extension, cffi (ABI) and pure C."""
    from protocol import ccodec
    from protocol import codec as pycodec

    _make("ext", "build/libhilproto.so")
    if not ccodec.AVAILABLE:
        ccodec = importlib.reload(ccodec)
    batches = 5 if quick else 15
    out: dict = {"frames_per_batch": STREAM_FRAMES, "batches": batches}
    for kind in ("sample", "gates", "telemetry"):
        msgs = _stream_messages(kind)
        enc = pycodec.FrameEncoder()
        frames = [enc.encode(m) for m in msgs]
        fig = {"frame_bytes": len(frames[0]), "python": _codec_figures(pycodec, msgs, frames, batches)}
        if ccodec.AVAILABLE:
            fig["c_extension"] = _codec_figures(ccodec, msgs, frames, batches)
            fig["speedup_one_frame_per_feed"] = round(
                fig["python"]["decode_one_frame_per_feed_ns"] / fig["c_extension"]["decode_one_frame_per_feed_ns"], 1)
        else:
            fig["c_extension"] = {"error": ccodec.UNAVAILABLE_REASON}
        if kind != "telemetry":
            fig["cffi_abi"] = cffi_decode(kind, frames, batches)
        out[kind] = fig
    pure = c_codec(quick)
    out["c_pure_ns"] = {k: v for k, v in pure.items() if k.startswith(("sample_", "gates_", "telemetry_"))}
    return out


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


def c_instructions(quick: bool) -> dict:
    """Instructions per frame of the C codec on x86-64 (valgrind callgrind, difference of two
    run lengths so start-up cancels): repeatable, unlike the timings."""
    _make("build/hil_codec_bench")
    n = 500 if quick else 2000
    out = {}
    for op in ("sample_encode", "sample_decode", "sample_decode_bytewise", "gates_encode", "gates_decode",
               "gates_decode_bytewise"):
        counts = []
        for iterations in (n, 2 * n):
            proc = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                                   str(C_DIR / "build" / "hil_codec_bench"), "--only", op, str(iterations)],
                                  capture_output=True, text=True)
            found = [line for line in proc.stderr.splitlines() if "Collected :" in line]
            if proc.returncode != 0 or not found:
                return {"error": f"valgrind callgrind failed: {proc.stderr.strip()[-300:]}"}
            counts.append(int(found[0].split(":")[-1]))
        out[f"{op}_instructions"] = round((counts[1] - counts[0]) / n, 1)
    return out


def _spawn_echo(raw: bool) -> tuple[subprocess.Popen, SerialLink]:
    master, slave = os.openpty()
    tty.setraw(slave, termios.TCSANOW)
    path = os.ttyname(slave)
    args = [str(C_DIR / "build" / "hil_echo"), "--fd", str(master)] + (["--raw"] if raw else [])
    proc = subprocess.Popen(args, pass_fds=(master,), stderr=subprocess.DEVNULL)
    os.close(master)
    link = SerialLink(path, baudrate=2_000_000)
    os.close(slave)  # the link holds the slave now; the echo reads EIO until then
    return proc, link


def _protocol_batch(link: SerialLink, round_trips: int, k0: int) -> float:
    t0 = time.perf_counter()
    for k in range(k0, k0 + round_trips):
        link.send(Sample(k, 2048, 1000, 3000, k & 0xFFFF, 0))
        got = link.recv(1.0)
        if got is None or got.period != k:
            raise RuntimeError(f"the C echo answered {got!r} to period {k}")
    return (time.perf_counter() - t0) / round_trips * 1e6


def _raw_batch(link: SerialLink, round_trips: int, frame: bytes) -> float:
    n = len(frame)
    t0 = time.perf_counter()
    for _ in range(round_trips):
        link.send_bytes(frame)
        got = 0
        while got < n:
            chunk = link.read_bytes(1.0)
            if not chunk:
                raise RuntimeError("the raw echo did not answer")
            got += len(chunk)
    return (time.perf_counter() - t0) / round_trips * 1e6


def pty_round_trips(round_trips: int, batches: int) -> dict:
    """Raw and protocol batches alternate, so both see the same machine load; the protocol's
    cost is the median of the per-pair differences."""
    _make("build/hil_echo")
    frame = FrameEncoder().encode(SAMPLE)
    raw_proc, raw_link = _spawn_echo(raw=True)
    proto_proc, proto_link = _spawn_echo(raw=False)
    raw_us, proto_us = [], []
    try:
        _raw_batch(raw_link, round_trips // 4 + 1, frame)  # warm-up
        _protocol_batch(proto_link, round_trips // 4 + 1, 0)
        k = round_trips
        for b in range(batches):
            if b % 2:
                raw_us.append(_raw_batch(raw_link, round_trips, frame))
                proto_us.append(_protocol_batch(proto_link, round_trips, k))
            else:
                proto_us.append(_protocol_batch(proto_link, round_trips, k))
                raw_us.append(_raw_batch(raw_link, round_trips, frame))
            k += round_trips
        counters = proto_link.counters
        if counters["crc_errors"] or counters["framing_errors"] or counters["seq_gaps"]:
            raise RuntimeError(f"errors on a clean pseudo-terminal: {counters}")
    finally:
        for link, proc in ((raw_link, raw_proc), (proto_link, proto_proc)):
            link.close()
            proc.wait(5)
    raw = statistics.median(raw_us)
    proto = statistics.median(proto_us)
    cost = statistics.median(p - r for p, r in zip(proto_us, raw_us))
    return {
        "frame": "SAMPLE", "frame_bytes": len(frame), "round_trips_per_batch": round_trips, "batches": batches,
        "raw_round_trips_per_s": round(1e6 / raw), "protocol_round_trips_per_s": round(1e6 / proto),
        "raw_us_per_round_trip": round(raw, 2), "protocol_us_per_round_trip": round(proto, 2),
        "raw_batch_range_us": [round(min(raw_us), 2), round(max(raw_us), 2)],
        "protocol_batch_range_us": [round(min(proto_us), 2), round(max(proto_us), 2)],
        "protocol_cost_us_per_round_trip": round(cost, 2),
        "protocol_cost_percent": round(100.0 * cost / raw, 1),
        # the least-disturbed batch of each kind: on a loaded machine closest to the bare cost
        "best_raw_us_per_round_trip": round(min(raw_us), 2),
        "best_protocol_us_per_round_trip": round(min(proto_us), 2),
        "best_protocol_cost_us_per_round_trip": round(min(proto_us) - min(raw_us), 2),
    }


def run(quick: bool = False) -> dict:
    return {
        "command": "python -m bench protocol" + (" --quick" if quick else ""),
        "python_codec": python_codec(*((5_000, 3) if quick else (50_000, 7))),
        "c_codec_ns": c_codec(quick),
        "codec_stream": codec_stream(quick),
        "c_codec_instructions": c_instructions(quick),
        "pty_round_trip": pty_round_trips(*((300, 4) if quick else (1_000, 21))),
    }


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
