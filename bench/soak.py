"""Soak counters: the run of tests/test_soak.py (lockstep, in-process stub, seed 11, 1 % of the
frames dropped and 1 % corrupted each way, after 4000 periods at 1500 rpm), printing its
counters; docs/faults.md quotes them. The test asserts that they reconcile; this prints them.

    python -m bench soak            # 60 s simulated, as the test (about 30-60 s of wall time)
    python -m bench soak --quick    # 5 s simulated (other counts; a quick look only)

No MCAP log is written (the test writes one and checks it): the counters do not depend on it.
Deterministic: the same counts on every run of the same tree.
"""
from __future__ import annotations

import ctypes
import time

SEED = 11
CHUNK_S = 1.0


class _StubCounters(ctypes.Structure):       # hil_stub_get_counters' struct
    _fields_ = [("frames_in", ctypes.c_uint32), ("ignored", ctypes.c_uint32),
                ("tx_overflows", ctypes.c_uint32), ("decode_errors", ctypes.c_uint32)]


def stub_counters(session) -> _StubCounters:
    """The board side's decoder counters (the in-process stub's hil_stub_get_counters)."""
    link = session.tap.link
    out = _StubCounters()
    link._lib.hil_stub_get_counters.argtypes = [ctypes.c_void_p, ctypes.POINTER(_StubCounters)]
    link._lib.hil_stub_get_counters(link._instance, ctypes.byref(out))
    return out


def soak(soak_s: float, log_path=None, check=None) -> dict:
    """The soak: 4000 periods at 1500 rpm, then ``soak_s`` simulated seconds with the faults,
    the in-memory record emptied every CHUNK_S (the log, if any, keeps everything). ``check``
    (session, periods, board counters before, bench decoder counters before, TELEMETRY rows,
    periods without GATES) runs before the session closes: tests/test_soak.py's reconciliation.
    Returns the counters."""
    import numpy as np

    from hil.faults.injector import injector
    from hil.session.bench_session import BenchSession, SessionConfig
    from plant_rt import load_profile

    T = load_profile().control_period_s
    per_chunk = round(CHUNK_S / T)
    chunks = round(soak_s / CHUNK_S)
    telemetry = 0
    speed_min, speed_max = np.inf, -np.inf
    wall0 = time.perf_counter()
    config = SessionConfig(link="stub", log_path=log_path, seed=SEED, answer_resends=0)
    with BenchSession(load_profile(), config) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(4000)                    # at speed before the faults
        session.drain()
        board0, bench0 = stub_counters(session), dict(session.tap._decoder.counters)
        missed0 = session.missed_answers
        inj = injector(session)
        inj.inject("link_drop", rate=0.01, seed=1)
        inj.inject("link_corrupt", rate=0.01, seed=2)
        rec = session.recorder
        rec.clear()                                  # memory stays bounded; the log keeps all
        for chunk in range(chunks):
            ran = session.run_periods(per_chunk)
            if ran != per_chunk or session.error is not None:
                raise RuntimeError(f"soak: chunk {chunk} ran {ran} of {per_chunk} periods "
                                   f"({session.error})")
            if chunk == chunks - 1:
                session.drain()
            telemetry += len(rec.telemetry_rows)
            speed = np.asarray(rec.truth_rows)[:, 11]           # speed_rpm
            speed_min, speed_max = min(speed_min, speed.min()), max(speed_max, speed.max())
            rec.clear()
        inj.clear()
        periods = chunks * per_chunk
        missed = session.missed_answers - missed0
        if check is not None:
            check(session, periods, board0, bench0, telemetry, missed)
        st = dict(session.tap.stats)
        board, bench = stub_counters(session), session.tap._decoder.counters
        lost_out = st["out_dropped"] + st["out_corrupted"]
        lost_in = st["in_dropped"] + st["in_corrupted"]
        gates_lost = lost_in - ((periods - lost_out) - telemetry)
        out = {
            "simulated_s": soak_s, "periods": periods, "seed": SEED,
            "out_samples": st["out_frames"], "out_dropped": st["out_dropped"],
            "out_corrupted": st["out_corrupted"],
            "in_frames": st["in_frames"], "in_dropped": st["in_dropped"],
            "in_corrupted": st["in_corrupted"],
            "periods_without_gates": missed, "samples_lost_plus_gates_lost": lost_out + gates_lost,
            "board_decode_errors": board.decode_errors - board0.decode_errors,
            "board_frames_decoded": board.frames_in - board0.frames_in,
            "bench_crc_errors": bench["crc_errors"] - bench0["crc_errors"],
            "bench_framing_errors": bench["framing_errors"] - bench0["framing_errors"],
            "bench_frames_ok": bench["frames_ok"] - bench0["frames_ok"],
            "stale_answers": session.stale_answers, "board_faults": len(session.faults),
            "speed_min_rpm": round(float(speed_min), 1), "speed_max_rpm": round(float(speed_max), 1),
            "link_counters": session.link_counters(), "missed_answers_before": missed0,
        }
    wall = time.perf_counter() - wall0
    out["wall_s"] = round(wall, 1)
    out["periods_per_s"] = round((periods + 4000) / wall)
    return out


def run(quick: bool = False) -> dict:
    out = soak(5.0 if quick else 60.0)
    del out["link_counters"], out["missed_answers_before"]   # (the test's cross-checks)
    return out
