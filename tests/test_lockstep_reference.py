"""A lockstep run stays the same bit for bit across the bench's own rework (issue 18).

tests/data/lockstep_seed7_ekf_1500_3000.json holds the SHA-256 of every signal (float64 bytes)
of a 6,000-period run of the in-process stub (seed 7, EKF speed feedback, 1500 rpm then 3000 rpm) recorded with the bench as
it was before the per-period path was reworked (commit 52f9745: Python codec, per-message
recorder, per-frame link tap) by this very script, run in a checkout of that commit. The same
run today, with the C codec, the batched recorder and the fast tap, must give identical
arrays: no signal may differ in any bit. A legitimate change of the physics or the stub
replaces the file (and says why in its commit).
"""
from __future__ import annotations

from pathlib import Path

import hashlib
import json

import numpy as np

from hil.session import BenchSession, SessionConfig
from hil.session.board_params import load_bench_profile

REFERENCE = Path(__file__).resolve().parent / "data" / "lockstep_seed7_ekf_1500_3000.json"


def digest(values: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(values, dtype=np.float64).tobytes()).hexdigest()


def differing(reference: dict, run: dict[str, np.ndarray]) -> list[str]:
    return [name for name, want in reference.items()
            if name not in run or digest(run[name]) != want["sha256"]]


def record(seed: int = 7) -> dict[str, np.ndarray]:
    with BenchSession(load_bench_profile(), SessionConfig(link="stub", seed=seed)) as s:
        s.send_command(enable=True, speed_source="ekf", speed_ref_rpm=1500)
        s.run_periods(3000)
        s.send_command(speed_ref_rpm=3000)
        s.run_periods(3000)
        s.drain()
        return {name: values for name, (_, values, _) in s.recorder.arrays().items()}


def test_signals_identical_to_the_recorded_reference():
    reference = json.loads(REFERENCE.read_text())
    assert len(reference) > 30
    assert differing(reference, record()) == []


def test_the_comparison_sees_a_different_run():
    """Another seed changes the sensor noise: the same comparison reports the differences."""
    differ = differing(json.loads(REFERENCE.read_text()), record(seed=8))
    assert "sensor.adc_i1" in differ and "plant.speed_rad_s" in differ
