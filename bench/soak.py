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


class _StubCounters(ctypes.Structure):       # hil_stub_get_counters' struct (as tests/test_faults_link.py)
    _fields_ = [("frames_in", ctypes.c_uint32), ("ignored", ctypes.c_uint32),
                ("tx_overflows", ctypes.c_uint32), ("decode_errors", ctypes.c_uint32)]


def _board(session) -> _StubCounters:
    link = session.tap.link
    out = _StubCounters()
    link._lib.hil_stub_get_counters.argtypes = [ctypes.c_void_p, ctypes.POINTER(_StubCounters)]
    link._lib.hil_stub_get_counters(link._instance, ctypes.byref(out))
    return out


def run(quick: bool = False) -> dict:
    import numpy as np

    from hil.faults.injector import injector
    from hil.session.bench_session import BenchSession, SessionConfig
    from plant_rt import load_profile

    soak_s = 5.0 if quick else 60.0
    T = load_profile().control_period_s
    per_chunk = round(CHUNK_S / T)
    chunks = round(soak_s / CHUNK_S)
    telemetry = 0
    speed_min, speed_max = np.inf, -np.inf
    wall0 = time.perf_counter()
    with BenchSession(load_profile(), SessionConfig(link="stub", seed=SEED, answer_resends=0)) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        session.run_periods(4000)
        session.drain()
        board0, bench0 = _board(session), dict(session.tap._decoder.counters)
        missed0 = session.missed_answers
        inj = injector(session)
        inj.inject("link_drop", rate=0.01, seed=1)
        inj.inject("link_corrupt", rate=0.01, seed=2)
        rec = session.recorder
        rec.clear()
        for chunk in range(chunks):
            session.run_periods(per_chunk)
            if chunk == chunks - 1:
                session.drain()
            telemetry += len(rec.telemetry_rows)
            speed = np.asarray(rec.truth_rows)[:, 11]           # speed_rpm
            speed_min, speed_max = min(speed_min, speed.min()), max(speed_max, speed.max())
            rec.clear()
        inj.clear()
        periods = chunks * per_chunk
        st = dict(session.tap.stats)
        board, bench = _board(session), session.tap._decoder.counters
        missed = session.missed_answers - missed0
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
        }
    wall = time.perf_counter() - wall0
    out["wall_s"] = round(wall, 1)
    out["periods_per_s"] = round((periods + 4000) / wall)
    return out
