"""Hostile-board soak: many bench sessions against seeded hostile boards (tests/hostile_board.py:
valid, malformed, out-of-order and out-of-range frames, floods, silence, early close) on a
pseudo-terminal, a python-can virtual bus and as a board process (exec:), each with an MCAP
log; prints how they ended: sessions, crashes, hangs, unnamed errors, readable logs, plants
not safe-stated, ends by kind, and the seeds of the sessions that went wrong.

    python -m bench hostile_board           # up to 2000 sessions of 400 periods, at most 15 min
    python -m bench hostile_board --quick   # up to 200 sessions, at most 2 min

A tenth as many sessions again run in real time (a 2 ms period, 200 periods), their figures
under ``realtime``.

The session count and the wall time are both bounded: sessions stop starting when the time is
up (``sessions`` says how many ran). The seeds are fixed (BASE_SEED): a listed failure replays
with tests.hostile_board.run_session(transport, seed, log_path, periods).
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

BASE_SEED = 4_2026_1128         # another base than the test's: other boards
PERIODS = 400
REALTIME_PERIOD_S = 0.002


def soak(sessions: int, time_budget_s: float, base_seed: int = BASE_SEED,
         periods: int = PERIODS, realtime_period_s: float | None = None) -> dict:
    from tests.hostile_board import TRANSPORT_CYCLE, run_many

    wall0 = time.monotonic()

    def out_of_time() -> bool:
        return time.monotonic() - wall0 > time_budget_s

    with tempfile.TemporaryDirectory(prefix="hostile-board-") as directory:
        figures, bad = run_many(sessions, base_seed, Path(directory), TRANSPORT_CYCLE, periods,
                                stop=out_of_time, realtime_period_s=realtime_period_s)
    figures["wall_s"] = round(time.monotonic() - wall0, 1)
    figures["sessions_planned"] = sessions
    figures["time_budget_s"] = time_budget_s
    figures["problems"] = [{"transport": r.transport, "seed": r.seed, "problem": r.problem,
                            "error": (r.error or "")[-2000:], "plan": r.plan} for r in bad[:20]]
    return figures


def run(quick: bool = False) -> dict:
    sessions, budget_s = (200, 120.0) if quick else (2000, 900.0)
    figures = soak(sessions, budget_s)
    figures["realtime"] = soak(sessions // 10, budget_s / 10, BASE_SEED + 1, 200, REALTIME_PERIOD_S)
    return figures
