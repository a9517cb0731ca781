"""The in-process period exchange (one C call: SAMPLE encoded, the firmware's hil_fw_exchange,
the answers decoded, both directions captured and counted) against the tap's Python path for
the same run: same signals, same raw frames in the log, same link counters; and a closed
firmware instance is never reached."""
from __future__ import annotations

import numpy as np
import pytest

from hil.session import BenchSession, SessionConfig
from hil.session.board_params import load_bench_profile
from hil.session.link_tap import LinkTap
from protocol import ccodec

pytestmark = pytest.mark.skipif(not ccodec.AVAILABLE, reason=ccodec.UNAVAILABLE_REASON)


def _run(tmp_path, name: str, fast: bool, monkeypatch):
    if not fast:
        monkeypatch.setattr(LinkTap, "sample_exchanger", lambda self: None)
    from hil.logs.reader import read_log

    log = tmp_path / f"{name}.mcap"
    with BenchSession(load_bench_profile(), SessionConfig(link="stub", seed=3, log_path=log)) as s:
        s.send_command(enable=True, speed_source="ekf", speed_ref_rpm=2000)
        s.run_periods(700)
        s.send_command(speed_ref_rpm=1000)      # a COMMAND between periods: the Python path
        s.run_periods(700)
        s.drain()
        signals = {n: v for n, (_, v, _) in s.recorder.arrays().items()}
        counters = dict(s.tap.counters)
    monkeypatch.undo()
    frames = {t: read_log(log)[t] for t in ("/link/frames_out", "/link/frames_in")}
    return signals, counters, frames


def test_the_c_exchange_gives_what_the_python_path_gives(tmp_path, monkeypatch):
    fast = _run(tmp_path, "fast", True, monkeypatch)
    slow = _run(tmp_path, "slow", False, monkeypatch)
    assert fast[0].keys() == slow[0].keys()
    assert [n for n in fast[0] if not np.array_equal(fast[0][n], slow[0][n], equal_nan=True)] == []
    assert fast[1] == slow[1] and fast[1]["tx_frames"] >= 1400
    for topic in fast[2]:
        assert fast[2][topic].fields.keys() == slow[2][topic].fields.keys()
        for field, values in fast[2][topic].fields.items():
            assert list(values) == list(slow[2][topic].fields[field]), (topic, field)


def test_a_closed_firmware_is_not_called(tmp_path):
    with BenchSession(load_bench_profile(), SessionConfig(link="stub")) as s:
        s.run_periods(3)
        exchange = s.tap.sample_exchanger()
        assert exchange is not None and s.tap.fast_ready
        exchange(3, 2048, 2048, 3000, 0, 0)
        assert s.tap.link.exchange_counts[0] >= 1
        s.tap.link.close()
        assert not s.tap.fast_ready
        with pytest.raises(ValueError, match="firmware instance is closed"):
            exchange(4, 2048, 2048, 3000, 0, 0)
