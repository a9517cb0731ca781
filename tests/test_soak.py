"""Soak: 60 s of simulated time (1.2 million periods) in lockstep against the stub with 1 %
of the frames dropped and 1 % corrupted in both directions. The session must keep going,
every counter must reconcile with every other, and the log must be complete and readable.

Bounded: the in-process stub runs 20-40 thousand periods per second here, so this takes
30-60 s of wall time; the in-memory record is emptied every simulated second (the MCAP log
keeps everything) so memory stays flat.
"""
from __future__ import annotations

import time

import numpy as np

from plant_rt import load_profile

from hil.faults.injector import injector
from hil.logs.reader import log_summary
from hil.session.bench_session import BenchSession, SessionConfig
from tests.test_faults_link import reconcile, stub_counters

SOAK_S = 60.0
CHUNK_S = 1.0


def test_sixty_second_soak_with_drops_and_corruption(tmp_path):
    log = tmp_path / "soak.mcap"
    T = load_profile().control_period_s
    per_chunk = round(CHUNK_S / T)
    chunks = round(SOAK_S / CHUNK_S)
    telemetry = 0
    speed_min = np.inf
    speed_max = -np.inf
    wall0 = time.monotonic()
    with BenchSession(load_profile(), SessionConfig(link="stub", log_path=log, seed=11,
                                                         answer_resends=0)) as session:
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
            assert ran == per_chunk and session.error is None
            if chunk == chunks - 1:
                session.drain()
            telemetry += len(rec.telemetry_rows)
            speed = np.asarray(rec.truth_rows)[:, 11]           # speed_rpm
            speed_min, speed_max = min(speed_min, speed.min()), max(speed_max, speed.max())
            rec.clear()
        inj.clear()
        periods = chunks * per_chunk
        got = reconcile(session, periods, board0, bench0, telemetry,
                        session.missed_answers - missed0)
        assert not session.faults                    # the board never tripped
        counters = session.link_counters()
    wall = time.monotonic() - wall0
    # 1 % each way: out ~ 12,000 dropped and ~ 12,000 corrupted SAMPLEs, in twice as many.
    n = periods
    for key, expected in (("out_dropped", 0.01 * n), ("out_corrupted", 0.01 * 0.99 * n)):
        assert abs(counters[key] - expected) < 5 * np.sqrt(expected), key
    assert got["lost_out"] > 20000 and got["gates_lost"] > 20000
    assert counters["missed_answers"] - missed0 == got["lost_out"] + got["gates_lost"]
    assert 1350 < speed_min and speed_max < 1650      # the drive held its speed within 10 %
    summary = log_summary(log)
    assert summary["complete"]
    truth = next(c for c in summary["channels"] if c["topic"] == "/plant/truth")
    assert truth["count"] == 4000 + periods and summary["duration_s"] >= SOAK_S
    print(f"soak: {periods} periods in {wall:.1f} s wall ({periods / wall:.0f} periods/s), "
          f"log {log.stat().st_size / 1e6:.0f} MB, counters {counters}")
