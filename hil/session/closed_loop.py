"""A plant and a board in closed loop, for tests and benchmarks that drive the loop from
Python rather than from a plan: the same BenchSession that runs every plan (handshake,
parameters, the period loop, the recorder), with the period's truth and telemetry handed back
as arrays.

    with ClosedLoop(settings={"flux_drift_cutoff_hz": 10.0}) as loop:
        loop.command("ekf", speed_rad_s=157.08)
        r = loop.run(0.5)          # r["speed_rad_s"], r["tm_speed_ekf_rad_s"], ...
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from plant_rt import TRUTH_FIELDS

from hil.logs.recorder import TELEMETRY_FIELDS
from hil.session.bench_session import BenchSession, SessionConfig
from hil.session.board_params import default_board, load_bench_profile

SPEED_SOURCES = ("encoder", "conventional", "ekf")   # SPEC 9.7, by number


class ClosedLoop:
    """BenchSession on `link` (default the in-process stub) with the paper's profile updated
    by `overrides`, and the link's board file with `settings` pushed on top of its own."""

    def __init__(self, settings: dict[str, float] | None = None,
                 overrides: dict[str, Any] | None = None, link: str = "stub", seed: int = 0):
        profile = load_bench_profile(overrides=overrides or None)
        self.period_s = profile.control_period_s
        board = default_board(link).with_settings(settings)
        self.session = BenchSession(profile, SessionConfig(link=link, seed=seed, board=board,
                                                          hold_cpu_latency=False))

    def __enter__(self) -> "ClosedLoop":
        self.session.__enter__()
        return self

    def __exit__(self, *exc_info) -> None:
        self.session.__exit__(*exc_info)

    @property
    def plant(self):
        return self.session.plant

    @property
    def faults(self) -> list:
        return self.session.faults

    @property
    def states(self) -> list[int]:
        """The board's STATUS states, in order."""
        return [data["state"] for _, kind, data in self.session.events if kind == "board_status"]

    def command(self, source: int | str, speed_rad_s: float, enable: bool = True) -> None:
        name = SPEED_SOURCES[source] if isinstance(source, int) else source
        self.session.send_command(enable=enable, speed_source=name,
                                  speed_ref_rpm=speed_rad_s * 60.0 / (2.0 * math.pi))

    def run(self, seconds: float) -> dict[str, np.ndarray]:
        """Runs round(seconds / T) periods; the plant's truth of each (TRUTH_FIELDS names) and
        the board's telemetry of each (tm_<field>), one value per period."""
        rec = self.session.recorder
        periods = rec.periods
        first = len(periods)
        k0 = int(periods[-1]) + 1 if first else self.plant.period
        n = int(round(seconds / self.period_s))
        self.session.run_periods(n)
        self.session.drain()                 # the last period's TELEMETRY
        truth = rec.truth_rows[first:]
        out = {name: truth[:, i] for i, name in enumerate(TRUTH_FIELDS)}
        tel = rec.telemetry_rows
        tel = tel[(tel[:, 0] >= k0) & (tel[:, 0] < k0 + n)]
        for i, name in enumerate(TELEMETRY_FIELDS):
            out["tm_" + name] = tel[:, i + 1]
        return out
