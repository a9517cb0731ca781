"""The lockstep rate through a USB adapter: `python -m bench adapters [--quick]`.

For an FTDI adapter with its latency timer at 16 ms (Linux's default) and at 1 ms, and a
board's native CDC-ACM port at full speed (1 ms frames) and high speed (125 us microframes),
the wire model's own figures (hil/links/wire.py: periods/s, modelled period, shortest
real-time period) and a lockstep session of the stub over a pseudo-terminal through that
model (``stub-pty?wire=NAME``): the modelled wire time is accounted, not slept, and the
projected rate is periods / (modelled wire time + the time measured). The stub over the same
pseudo-terminal without a model is the reference: what the bench alone allows.
"""
from __future__ import annotations

import time

from plant_rt import load_profile

from hil.links.wire import parse_wire, serial_frame_bytes
from hil.session.bench_session import BenchSession, SessionConfig

WIRES = ("ftdi-16ms", "ftdi-1ms", "cdc-fs", "cdc-hs")


def model_figures(name: str) -> dict:
    model = parse_wire(name)
    period_s = model.lockstep_period_s()
    return {"model": model.describe(), "lockstep_rate_hz": 1.0 / period_s,
            "lockstep_period_us": period_s * 1e6,
            "lockstep_rate_with_telemetry_hz": model.lockstep_rate_hz_with(
                serial_frame_bytes("GATES") + serial_frame_bytes("TELEMETRY")),
            "shortest_realtime_period_us": model.shortest_realtime_period_s() * 1e6,
            "seconds_for_1s_at_20kHz": 20_000 * period_s}


def session_figures(link: str, periods: int) -> dict:
    with BenchSession(load_profile(), SessionConfig(link=link)) as session:
        session.run_periods(10)                  # past the first periods' set-up
        started = time.monotonic()
        session.run_periods(periods)
        measured = time.monotonic() - started
        wire = session.tap.wire_stats() if session.tap is not None else {}
    out = {"periods": periods, "measured_rate_hz": periods / measured}
    if wire:
        out.update(modelled_wire_s=wire.get("wire_modelled_s"),
                   projected_rate_hz=wire.get("wire_projected_rate_hz"))
    return out


def run(quick: bool = False) -> dict:
    periods = 300 if quick else 3000
    out = {"reference_stub_pty": session_figures("stub-pty", periods)}
    for name in WIRES:
        out[name] = {**model_figures(name),
                     "session": session_figures(f"stub-pty?wire={name}", periods)}
    return out
