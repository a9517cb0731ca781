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

from bench.soak import soak
from hil.logs.reader import log_summary
from tests.test_faults_link import reconcile

SOAK_S = 60.0    # bench/soak.py's scenario, which `python -m bench soak` prints


def test_sixty_second_soak_with_drops_and_corruption(tmp_path):
    log = tmp_path / "soak.mcap"
    wall0 = time.monotonic()
    got = {}

    def check(session, periods, board0, bench0, telemetry, missed):
        got.update(reconcile(session, periods, board0, bench0, telemetry, missed))
        assert not session.faults                    # the board never tripped

    out = soak(SOAK_S, log, check)
    wall = time.monotonic() - wall0
    periods, counters, speed_min, speed_max = (out["periods"], out["link_counters"],
                                               out["speed_min_rpm"], out["speed_max_rpm"])
    missed0 = out["missed_answers_before"]
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
