"""The real-time clock's statistics against hand-made lateness series."""
from __future__ import annotations

import numpy as np

from hil.session.realtime import held, lateness_summary


def test_thresholds_count_ticks_later_than_10_and_50_percent_and_a_whole_period():
    period = 1e-3
    # late by: 0, 0.05 T, 0.2 T, 0.6 T, 1.5 T  ->  over 10 %: 3, over 50 %: 2, over T: 1
    late = np.array([0.0, 0.05, 0.2, 0.6, 1.5]) * period
    s = lateness_summary(late, period)
    assert (s["late_over_10pct"], s["late_over_50pct"], s["deadline_misses"]) == (3, 2, 1)
    assert s["periods"] == 5 and s["lateness_us_max"] == 1500.0
    assert s["lateness_us_p50"] == 200.0


def test_held_needs_no_half_period_lateness_no_missing_answer_and_no_overrun():
    ok = {"periods": 100, "late_over_50pct": 0, "missing_answers": 0, "overruns": 0}
    assert held(ok)
    # the old criterion (no tick a whole period late) would have called each of these held
    assert not held({**ok, "late_over_50pct": 1})
    assert not held({**ok, "missing_answers": 1})
    assert not held({**ok, "overruns": 1})
    assert not held({**ok, "periods": 0})
