"""Instruction count of one control step under callgrind (repeatable, unlike time): a
regression bound, and the two counting methods of bench/stub.py agree."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from bench.stub import STUB, instructions_per_step

pytestmark = pytest.mark.skipif(shutil.which("valgrind") is None, reason="needs valgrind")

# measured 351 / 427 (EKF, gcc 12 -O2 with LTO); the bounds leave room for compiler
# versions, not for a new trigonometric call or a lost inlining
BOUND_WITHOUT_TELEMETRY = 390
BOUND_WITH_TELEMETRY = 470


@pytest.fixture(scope="module", autouse=True)
def built() -> None:
    subprocess.run(["make", "-s", "-C", str(STUB), "bench"], check=True, capture_output=True)


@pytest.mark.parametrize("mode", [0, 2])
def test_control_step_instruction_bound(mode):
    never = instructions_per_step(mode, 1000, 0)
    every = instructions_per_step(mode, 1000, 1)
    assert never["toggle"] < BOUND_WITHOUT_TELEMETRY
    assert every["toggle"] < BOUND_WITH_TELEMETRY
    # telemetry adds the rotor position and the record, not nothing
    assert every["toggle"] - never["toggle"] > 30
    # counting inside ctl_step and subtracting the baseline run agree: the
    # baseline's stand-in costs 2 instructions per call, and the printf of the
    # results differs by a few hundred instructions in all
    for r in (never, every):
        assert 0 <= r["toggle"] - r["difference"] < 4
