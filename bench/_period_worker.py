"""The process bench.period_instructions runs under callgrind: a lockstep session of the
in-process stub (3000 rpm, EKF speed), warmed up, then `periods` more periods of one kind.

    python -m bench._period_worker {stub,stub+log,stub+log@lz4_level0,stub+log@numpy_packing,
                                    stub+log@python_loop,plant} PERIODS

Two runs that differ only in PERIODS differ by those periods' instructions: start-up, the
handshake and the warm-up cancel. `plant` replays, on a fresh plant, the switch words the
stub chose (sample, truth, step: the floor under any lockstep period, as in bench.session).
`stub+log@lz4_level0` writes the log's chunks at the lz4 library's default level instead of
the writer's LZ4_LEVEL; `stub+log@numpy_packing` packs the log's records with numpy instead of
the C codec's records_into; `stub+log@python_loop` runs every period in the session's Python
loop instead of the C period loop (protocol.ccodec.exchange_periods).
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from plant_rt import Plant, load_profile

from hil.session.bench_session import BenchSession, SessionConfig

WARM_UP_PERIODS = 2000


def main(kind: str, periods: int) -> None:
    if kind == "stub+log@lz4_level0":
        from hil.logs import mcap_writer

        mcap_writer.LZ4_LEVEL = 0
    elif kind == "stub+log@numpy_packing":
        from hil.logs import mcap_writer

        mcap_writer._RECORDS_INTO = None
    elif kind == "stub+log@python_loop":
        from protocol import ccodec

        ccodec.exchange_periods = None
    profile = load_profile()
    with tempfile.TemporaryDirectory() as tmp:
        log_path = Path(tmp) / "bench.mcap" if kind.startswith("stub+log") else None
        with BenchSession(profile, SessionConfig(link="stub", log_path=log_path)) as session:
            session.send_command(enable=True, speed_source="ekf", speed_ref_rpm=3000)
            session.run_periods(WARM_UP_PERIODS)
            if kind == "plant":
                session.run_periods(1000)
                gates = [int(row[4]) for row in session.recorder.telemetry_rows[-1000:]]
            else:
                session.run_periods(periods)
    if kind == "plant":
        plant = Plant(profile, seed=0)
        sample, truth, step = plant.sample, plant.truth, plant.step
        for i in range(periods):
            sample()
            truth()
            step(gates[i % len(gates)])


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
