"""Cost of logging a run to MCAP (docs/logging.md), on the channels the recorder writes.

Data: a lockstep session over the in-process stub (Table 1 motor, encoder speed loop,
1500 rpm, TELEMETRY every period as in the default profile) is run once without a log and
its recorder's rows are kept: the plant truth (/plant/truth: t_s double + 18 floats), the
sensor values (/plant/sensors: period + 5 fixed32), the board's TELEMETRY
(/ctrl/telemetry: period, 4 fixed32, 12 floats) and the raw frames the link tap captured
every 10 ms (/link/frames_out, /link/frames_in). The channels are made by
`Recorder.attach_log` itself, so their layouts are the recorder's.

Timed, each on a fresh log over the same rows, variants interleaved `repeats` times:

- ``recorder_path``: what a session does, `Recorder.period` / `telemetry` / `frames` for
  every period, so the full-rate channels go to the log in batches of
  `LOG_BATCH_PERIODS` through `FixedChannel.write_many`; with lz4 64 KiB chunks (the
  default, at the writer's `LZ4_LEVEL`), lz4 1 MiB, lz4 64 KiB at the lz4 library's own
  default level 0 (``lz4_level0_64KiB``) and at -2 (``lz4_level-2_64KiB``, the writer's level
  before 2026-11-26), zstd 64 KiB and no compression. The in-memory lists the recorder
  keeps for the checks are part of the cost (they are there with or without a log).
- ``numpy_packing_lz4_64KiB``: the default variant with the records packed by numpy column by
  column (`FixedChannel.write_many` without the C codec's `records_into`), as before it.
- ``records_into_in_session``: two logged in-process sessions, one packing with the C codec
  and one with numpy, batches alternating (the variant above goes through Recorder's Python
  path and drifts with the VM; this one is the period loop as a run has it).
- ``per_message_path``: the same rows and the same in-memory lists, but one
  `FixedChannel.write` per message (the path before batching), lz4 64 KiB.
- ``no_log``: the recorder without a log (its lists only); ``log_us_per_period`` of a
  variant is its median minus this median: what the log itself costs a period.
- ``chunk_finish_ms``: each chunk finish (compress, CRC, one write()) timed in the
  default variant.
- ``one_truth_message_us``: one /plant/truth message through `FixedChannel.write`,
  through `mcap.writer.Writer.add_message` (the same bytes, packed beforehand) and as
  JSON through `McapLog.write_json`.
- ``read_s``: `log_summary` (what `hil log info` reads) and `read_log` of every channel on
  the default variant's file.
- ``foxglove_sdk_writer``: the same full-rate rows (truth, sensors, telemetry; not the frame
  captures) through foxglove-sdk's own MCAP writer (`foxglove.open_mcap`, lz4, 64 KiB chunks,
  CRCs on, as ours), one `Channel.log` per message with the log's protobuf schemas and the
  payloads packed as the live stream packs them, beside the recorder's lists; its
  ``log_us_per_period`` against the same no-log median (issue 17 asks which writer is faster).

Every time is the median over the repeats (min and max given beside it). Sizes and chunk
counts are the same in every repeat.
"""
from __future__ import annotations

import io
import os
import statistics
import struct
import tempfile
import time
from types import SimpleNamespace

import numpy as np

from hil.logs.recorder import telemetry_row as _fields
from protocol.messages import Telemetry

#: (compression, chunk size, lz4 level or None: the writer's default, LZ4_LEVEL)
VARIANTS = (("lz4", 64 * 1024, None), ("lz4", 1024 * 1024, None), ("lz4", 64 * 1024, 0),
            ("lz4", 64 * 1024, -2), ("zstd", 64 * 1024, None), ("none", 64 * 1024, None))


def _variant_name(compression: str, chunk_size: int, lz4_level: int | None) -> str:
    level = "" if lz4_level is None else f"_level{lz4_level}"
    return f"{compression}{level}_{chunk_size // 1024}KiB"


def _session_rows(periods: int) -> dict:
    """Rows of a real run: recorder lists and the tap's frame captures (no log written)."""
    from hil.session.bench_session import BenchSession, SessionConfig
    from plant_rt import load_profile

    captures: list[tuple[int, dict]] = []
    with BenchSession(load_profile(), SessionConfig(link="stub")) as s:
        rec = s.recorder
        original = rec.frames

        def keep(k, capture):
            captures.append((k, capture))
            original(k, capture)

        rec.frames = keep
        s.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        s.run_periods(periods)
        # the messages as the session has them (the codec's Telemetry, which the recorder
        # takes in C) and the truth as the plant gives it (tuples of floats)
        telemetry = [Telemetry(*[int(v) for v in row[:5]], *row[5:].tolist()) for row in rec.telemetry_rows]
        # as a session hands them to the recorder: truth tuples of floats, sensor integers
        return {"periods": rec.periods.tolist(), "truth": [tuple(r) for r in rec.truth_rows.tolist()],
                "sensors": [SimpleNamespace(adc_i1=a, adc_i2=b, adc_vdc=c, encoder=d, status=e)
                            for a, b, c, d, e in rec.sensor_rows.astype(np.int64).tolist()],
                "telemetry": {int(m.period): m for m in telemetry}, "frames": dict(captures),
                "period_s": s.period_s}


def _recorder_run(path: str | None, rows: dict, compression: str = "lz4", chunk_size: int = 64 * 1024,
                  per_message: bool = False, finishes: list | None = None,
                  lz4_level: int | None = None, numpy_packing: bool = False) -> float:
    """Feeds a run's rows through a Recorder as the session does; path None: no log (the
    recorder's in-memory lists only); per_message: the lists, plus one write() per message
    instead of the batched write_many."""
    from hil.logs import mcap_writer
    from hil.logs.mcap_writer import McapLog
    from hil.logs.recorder import Recorder

    packer = mcap_writer._RECORDS_INTO
    if numpy_packing:
        mcap_writer._RECORDS_INTO = None
    try:
        return _timed_feed(McapLog, Recorder, path, rows, compression, chunk_size, per_message,
                           finishes, lz4_level)
    finally:
        mcap_writer._RECORDS_INTO = packer


def _timed_feed(McapLog, Recorder, path, rows, compression, chunk_size, per_message, finishes,
                lz4_level) -> float:
    rec = Recorder(rows["period_s"])
    log = None
    if path is not None:
        levels = {} if lz4_level is None else {"lz4_level": lz4_level}
        log = McapLog(path, metadata={"bench": {"what": "mcap_logging"}}, chunk_size=chunk_size,
                      compression=compression, **levels)
        if finishes is not None:
            finish = log._finish_chunk

            def timed_finish():
                t0 = time.perf_counter_ns()
                finish()
                finishes.append((time.perf_counter_ns() - t0) / 1e6)

            log._finish_chunk = timed_finish
        rec.attach_log(log)
    periods, truth, sensors, telemetry, frames = (rows["periods"], rows["truth"], rows["sensors"],
                                                   rows["telemetry"], rows["frames"])
    period, tele, frm = rec.period, rec.telemetry, rec.frames
    t_start = time.perf_counter()
    if per_message:
        tr, se, te = rec._truth_ch.write, rec._sensor_ch.write, rec._telemetry_ch.write
        rec._log = None                 # the lists only; the messages are written here
        period_s = rows["period_s"]
        for i, k in enumerate(periods):
            t = round(k * period_s * 1e9)
            if k in frames:
                rec._log = log
                frm(k, frames[k])
                rec._log = None
            period(k, truth[i], sensors[i])
            tr(t, *truth[i])
            s = sensors[i]
            se(t, k, s.adc_i1, s.adc_i2, s.adc_vdc, s.encoder, s.status)
            m = telemetry.get(k)
            if m is not None:
                tele(m)
                te(t, *_fields(m))
    else:
        for i, k in enumerate(periods):
            if k in frames:
                frm(k, frames[k])
            period(k, truth[i], sensors[i])
            m = telemetry.get(k)
            if m is not None:
                tele(m)
        rec.seal()
    if log is not None:
        log.close()
    return time.perf_counter() - t_start


def _one_message(n: int, rows: list[tuple]) -> dict[str, float]:
    """One /plant/truth message: our writer, mcap's Writer (same bytes), JSON."""
    from mcap.writer import CompressionType, Writer

    from hil.logs.mcap_writer import McapLog
    from hil.logs.recorder import Recorder
    from plant_rt import TRUTH_FIELDS

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        log = McapLog(os.path.join(tmp, "a.mcap"))
        rec = Recorder(50e-6)
        rec.attach_log(log)
        ch = rec._truth_ch
        t0 = time.perf_counter()
        for i in range(n):
            ch.write(i, *rows[i])
        out["fixed_channel_write"] = (time.perf_counter() - t0) / n * 1e6
        dicts = [dict(zip(TRUTH_FIELDS, r)) for r in rows[:n]]
        t0 = time.perf_counter()
        for i in range(n):
            log.write_json("/plant/truth_json", i, dicts[i])
        out["json"] = (time.perf_counter() - t0) / n * 1e6
        log.close()
    fmt = "<" + "Bd" + "Bf" * (len(TRUTH_FIELDS) - 1)
    pack = struct.Struct(fmt).pack
    tags = [((1 << 3) | 1)] + [(((k + 1) << 3) | 5) for k in range(1, len(TRUTH_FIELDS))]
    payloads = []
    args = [0] * (2 * len(TRUTH_FIELDS))
    args[0::2] = tags
    for i in range(n):
        args[1::2] = rows[i]
        payloads.append(pack(*args))
    writer = Writer(io.BytesIO(), chunk_size=64 * 1024, compression=CompressionType.LZ4)
    writer.start()
    cid = writer.register_channel("/plant/truth", "protobuf", writer.register_schema("x", "protobuf", b""))
    t0 = time.perf_counter()
    for i in range(n):
        writer.add_message(cid, i, payloads[i], i)
    out["mcap_writer_add_message"] = (time.perf_counter() - t0) / n * 1e6
    writer.finish()
    return out


def _stats(values: list[float], digits: int = 2) -> dict:
    return {"median": round(statistics.median(values), digits), "min": round(min(values), digits),
            "max": round(max(values), digits), "runs": len(values)}


def _sdk_writer_run(path: str, rows: dict) -> float:
    """The recorder's lists as in no_log, plus every full-rate message through foxglove-sdk's
    MCAP writer (the live stream's channel definitions, on a context of their own)."""
    import foxglove
    from foxglove.mcap import MCAPCompression, MCAPWriteOptions

    from hil.live.stream import _FixedTopic
    from hil.logs.recorder import SENSOR_FIELDS, TELEMETRY_FIELDS, Recorder
    from plant_rt import TRUTH_FIELDS

    context = foxglove.Context()
    truth_ch = _FixedTopic(context, "/plant/truth", "hil.PlantTruth",
                           [(f, "double" if f == "t_s" else "float") for f in TRUTH_FIELDS], {})
    sensor_ch = _FixedTopic(context, "/plant/sensors", "hil.SensorSample",
                            [("period", "fixed32")] + [(f, "fixed32") for f in SENSOR_FIELDS], {})
    tele_ch = _FixedTopic(context, "/ctrl/telemetry", "hil.Telemetry",
                          [("period", "fixed32")] + [(f, "fixed32" if i < 4 else "float")
                                                     for i, f in enumerate(TELEMETRY_FIELDS)], {})
    options = MCAPWriteOptions(compression=MCAPCompression.Lz4, chunk_size=64 * 1024)
    rec = Recorder(rows["period_s"])
    periods, truth, sensors, telemetry = rows["periods"], rows["truth"], rows["sensors"], rows["telemetry"]
    period, tele = rec.period, rec.telemetry
    period_s = rows["period_s"]
    t_start = time.perf_counter()
    writer = foxglove.open_mcap(path, allow_overwrite=True, context=context, writer_options=options)
    for i, k in enumerate(periods):
        t = round(k * period_s * 1e9)
        s = sensors[i]
        period(k, truth[i], s)
        truth_ch.log(t, truth[i])
        sensor_ch.log(t, (k, s.adc_i1, s.adc_i2, s.adc_vdc, s.encoder, s.status))
        m = telemetry.get(k)
        if m is not None:
            tele(m)
            tele_ch.log(t, _fields(m))
    writer.close()
    return time.perf_counter() - t_start


def run(quick: bool = False) -> dict:
    from hil.logs.reader import log_summary, read_log
    from hil.logs.recorder import LOG_BATCH_PERIODS

    n = 20_000 if quick else 100_000
    repeats = 3 if quick else 7
    rows = _session_rows(n)
    n = len(rows["periods"])
    sim_s = n * rows["period_s"]
    frame_messages = sum(1 for c in rows["frames"].values() for _, count in c.values() if count)
    messages = 2 * n + len(rows["telemetry"]) + frame_messages
    result: dict = {
        "periods": n, "simulated_s": round(sim_s, 4), "repeats": repeats,
        "log_batch_periods": LOG_BATCH_PERIODS,
        "messages": messages, "messages_per_period": round(messages / n, 3),
        "data": "lockstep session, --link stub, encoder speed loop at 1500 rpm, TELEMETRY every period",
    }
    times: dict = {v: [] for v in VARIANTS}
    times["per_message"] = []
    times["numpy_packing"] = []
    times["no_log"] = []
    times["sdk"] = []
    finishes: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(repeats):
            for variant in VARIANTS:
                compression, chunk_size, lz4_level = variant
                path = os.path.join(tmp, _variant_name(*variant) + ".mcap")
                default = variant == VARIANTS[0]
                times[variant].append(_recorder_run(
                    path, rows, compression, chunk_size, False, finishes if default else None,
                    lz4_level))
            times["per_message"].append(_recorder_run(os.path.join(tmp, "per_message.mcap"), rows,
                                                      per_message=True))
            times["numpy_packing"].append(_recorder_run(os.path.join(tmp, "numpy_packing.mcap"), rows,
                                                        numpy_packing=True))
            times["no_log"].append(_recorder_run(None, rows))
            times["sdk"].append(_sdk_writer_run(os.path.join(tmp, "sdk.mcap"), rows))
        no_log = statistics.median(times["no_log"])
        result["no_log_us_per_period"] = _stats([t / n * 1e6 for t in times["no_log"]])
        recorder_path = {}
        for variant in VARIANTS:
            path = os.path.join(tmp, _variant_name(*variant) + ".mcap")
            summary = log_summary(path)
            chunks = max(summary["chunk_count"], 1)
            recorder_path[_variant_name(*variant)] = {
                "us_per_period": _stats([t / n * 1e6 for t in times[variant]]),
                "log_us_per_period": round((statistics.median(times[variant]) - no_log) / n * 1e6, 2),
                "file_bytes_per_simulated_s": round(os.path.getsize(path) / sim_s),
                "chunks": summary["chunk_count"],
                "simulated_ms_per_chunk": round(n / chunks * rows["period_s"] * 1e3, 2),
                "messages_per_chunk": round(summary["message_count"] / chunks),
            }
        result["recorder_path"] = recorder_path
        result["numpy_packing_lz4_64KiB"] = {
            "us_per_period": _stats([t / n * 1e6 for t in times["numpy_packing"]]),
            "log_us_per_period": round((statistics.median(times["numpy_packing"]) - no_log) / n * 1e6, 2)}
        result["per_message_path_lz4_64KiB"] = {
            "us_per_period": _stats([t / n * 1e6 for t in times["per_message"]]),
            "log_us_per_period": round((statistics.median(times["per_message"]) - no_log) / n * 1e6, 2)}
        result["log_cost_per_message_over_batched_ratio"] = round(
            (statistics.median(times["per_message"]) - no_log) / (statistics.median(times[VARIANTS[0]]) - no_log), 2)
        result["chunk_finish_ms_lz4_64KiB"] = _stats(finishes, 3)
        sdk_path = os.path.join(tmp, "sdk.mcap")
        sdk_summary = log_summary(sdk_path)
        result["foxglove_sdk_writer_lz4_64KiB"] = {
            "us_per_period": _stats([t / n * 1e6 for t in times["sdk"]]),
            "log_us_per_period": round((statistics.median(times["sdk"]) - no_log) / n * 1e6, 2),
            "over_recorder_path_ratio": round((statistics.median(times["sdk"]) - no_log)
                                              / (statistics.median(times[VARIANTS[0]]) - no_log), 2),
            "messages": sdk_summary["message_count"], "chunks": sdk_summary["chunk_count"]}
        default_path = os.path.join(tmp, _variant_name(*VARIANTS[0]) + ".mcap")
        reads, summaries = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            log_summary(default_path)
            summaries.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            read_log(default_path)
            reads.append(time.perf_counter() - t0)
        result["read_s_lz4_64KiB_file"] = {"log_summary": _stats(summaries, 3), "read_log_all": _stats(reads, 3),
                                           "messages": log_summary(default_path)["message_count"]}
    m = min(n, 20_000)
    runs = [_one_message(m, rows["truth"]) for _ in range(repeats)]
    result["one_truth_message_us"] = {k: _stats([r[k] for r in runs]) for k in runs[0]}
    result["records_into_in_session"] = _packing_in_session(5 if quick else 15, 5000)
    return result


def _packing_in_session(batches: int, periods: int) -> dict:
    """Two logged in-process sessions side by side, one packing the log's records with the C
    codec's records_into and one with numpy, batches alternating: us a period of each (median)
    and the median of numpy over C batch by batch."""
    import contextlib

    from hil.logs import mcap_writer
    from hil.session.bench_session import BenchSession, SessionConfig
    from plant_rt import load_profile

    packer = mcap_writer._RECORDS_INTO
    if packer is None:
        return {"error": "the C codec extension is not built"}
    us: dict[str, list[float]] = {"c": [], "numpy": []}
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        sessions = {}
        try:
            for kind in us:
                mcap_writer._RECORDS_INTO = packer if kind == "c" else None
                s = stack.enter_context(BenchSession(load_profile(), SessionConfig(
                    link="stub", log_path=os.path.join(tmp, f"{kind}.mcap"))))
                s.send_command(enable=True, speed_source="ekf", speed_ref_rpm=3000)
                s.run_periods(periods)                      # to speed, warmed up
                sessions[kind] = s
            for _ in range(batches):
                for kind, s in sessions.items():
                    mcap_writer._RECORDS_INTO = packer if kind == "c" else None
                    t0 = time.perf_counter()
                    s.run_periods(periods)
                    us[kind].append((time.perf_counter() - t0) / periods * 1e6)
        finally:
            mcap_writer._RECORDS_INTO = packer
    return {"c_us_per_period": round(statistics.median(us["c"]), 2),
            "numpy_us_per_period": round(statistics.median(us["numpy"]), 2),
            "numpy_over_c": round(statistics.median(n / c for n, c in zip(us["numpy"], us["c"])), 3),
            "batches": batches, "periods_per_batch": periods}


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick=True), indent=2))
