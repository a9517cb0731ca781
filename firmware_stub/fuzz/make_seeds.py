"""Writes the seed corpus of fuzz/fuzz_stub.c (its program format is described there):
a few sessions that reach each part of the drive, for the fuzzer to mutate.

    python3 firmware_stub/fuzz/make_seeds.py     (from the repository root, or anywhere)
"""
from __future__ import annotations

import struct
from pathlib import Path

SEEDS = Path(__file__).resolve().parent / "seeds"

# operation numbers (op % 6 in fuzz_stub.c)
SAMPLE, REPEAT, COMMAND, PARAM_SET, PARAM_GET, HELLO_OR_HEARTBEAT = range(6)
ENABLE = 0x01
TORQUE_MODE = 0x02
# protocol/SPEC.md 8, minus the fuzzer's offset of 10
CONTROL_LAW = 60 - 10
CURRENT_ZERO_CAL_PERIODS = 66 - 10
RS_ID_PERIODS = 67 - 10
OVERCURRENT_A = 41 - 10


def sample(i1: int = 2048, i2: int = 2048, vdc: int = 2867, step: int = 0, status: int = 0) -> bytes:
    return struct.pack("<BHHHbB", SAMPLE, i1, i2, vdc, step, status)


def repeat(n: int) -> bytes:
    return struct.pack("<BB", REPEAT, n)


def command(flags: int, source: int, speed: float, torque: float = 0.0, flux: float = 0.0) -> bytes:
    return struct.pack("<BBBfff", COMMAND, flags, source, speed, torque, flux)


def param_integer(pid: int, value: int) -> bytes:
    return struct.pack("<BBBI", PARAM_SET, pid, 1, value)


def param_raw(pid: int, value: float) -> bytes:
    return struct.pack("<BBBf", PARAM_SET, pid, 0, value)


SESSIONS = {
    "dtc_encoder": sample() + command(ENABLE, 0, 100.0) + sample(2060, 2040, step=3) + repeat(200),
    "dtc_ekf_torque": sample() + command(ENABLE | TORQUE_MODE, 2, 0.0, 1.0) + sample(2070, 2030, step=5)
    + repeat(150),
    "foc": param_integer(CONTROL_LAW, 1) + sample() + command(ENABLE, 0, 50.0) + sample(2050, 2046, step=2)
    + repeat(150),
    "zero_cal_rewritten": param_integer(CURRENT_ZERO_CAL_PERIODS, 8) + sample() + command(ENABLE, 0, 100.0)
    + sample(2052, 2045) + repeat(3) + param_integer(CURRENT_ZERO_CAL_PERIODS, 0) + repeat(40),
    "rs_id": param_integer(RS_ID_PERIODS, 40) + sample() + command(ENABLE, 0, 0.0) + sample(2100, 2020)
    + repeat(120),
    "nan_command_then_clear": sample() + command(ENABLE, 0, float("nan")) + repeat(3) + command(0, 0, 0.0)
    + repeat(2) + command(ENABLE, 0, 10.0) + repeat(20),
    "nan_param_and_trip": param_raw(OVERCURRENT_A, float("inf")) + sample() + command(ENABLE, 0, 100.0)
    + sample(4000, 100, step=1, status=0x02) + repeat(5) + struct.pack("<BB", PARAM_GET, OVERCURRENT_A)
    + struct.pack("<BB", HELLO_OR_HEARTBEAT, 1) + struct.pack("<BB", HELLO_OR_HEARTBEAT, 2),
}


def main() -> None:
    SEEDS.mkdir(exist_ok=True)
    for name, program in SESSIONS.items():
        (SEEDS / name).write_bytes(program)


if __name__ == "__main__":
    main()
