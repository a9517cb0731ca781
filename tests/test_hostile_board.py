"""A hostile board (a seeded generator playing the board on a real pty): random valid and invalid
frames, floods, heartbeats only, partial frames, wrong periods, silence. Whatever it does, the
session ends within its stated bound, with a named error when it fails, the plant safe-stated
and the log readable: never a hang."""
from __future__ import annotations

import random
import time

import pytest

from plant_rt import load_profile
from plant_rt.plant import GATE_COMMANDS
from protocol.messages import Duty, Fault, Gates, Heartbeat, Status

from hil.logs.reader import read_log
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from hil.session.policy import SessionPolicy
from tests.fake_board import FakeBoard

POLICY = SessionPolicy(hello_wait_s=0.2, param_wait_s=0.2, answer_wait_min_s=0.01, watchdog_s=0.3)
PERIODS = 60
# HELLO + 9 parameters + per period at most 4 waits of 0.01 s, a flood read for one more wait,
# and the watchdog at 0.3 s: a generous bound that a hang would still break
BOUND_S = 10.0
NAMED = ("watchdog: no GATES/DUTY", "link failed", "no HELLO", "stale answers")


def _hostile(seed: int):
    rng = random.Random(seed)
    style = rng.choice(["mixed", "flood", "heartbeats", "partial", "wrong_periods", "silence"])

    def frame(enc, k):
        kind = rng.randrange(9)
        if kind == 0:
            return enc.encode(Gates(period=k, gates=rng.randrange(64)))
        if kind == 1:
            return enc.encode(Duty(period=k, duty=(rng.randrange(65536),) * 3))
        if kind == 2:
            return enc.encode(Heartbeat(counter=rng.randrange(2 ** 32)))
        if kind == 3:
            return enc.encode(Heartbeat(counter=k)) * rng.randrange(1, 40)          # burst
        if kind == 4:
            return enc.encode(Fault(code=rng.randrange(6), period=k, value=rng.random()))
        if kind == 5:
            return enc.encode(Status(state=rng.randrange(3), fault_code=0, period=k))
        if kind == 6:
            return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 80)))   # garbage
        if kind == 7:
            return enc.encode(Gates(period=k, gates=0))[: rng.randrange(1, 12)]     # partial
        return enc.encode(Gates(period=(k + rng.randrange(1, 500)) & 0xFFFFFFFF, gates=0))

    def on_sample(sample, enc):
        k = sample.period
        if style == "silence":
            return b""
        if style == "heartbeats":
            return enc.encode(Heartbeat(counter=k))
        if style == "flood":
            return b"".join(enc.encode(Heartbeat(counter=i)) for i in range(200))
        if style == "partial":
            return enc.encode(Gates(period=k, gates=0))[:-3]
        if style == "wrong_periods":
            return enc.encode(Gates(period=k + 7, gates=0))
        return b"".join(frame(enc, k) for _ in range(rng.randrange(0, 6)))

    return style, on_sample


@pytest.mark.parametrize("seed", range(12))
def test_hostile_board_never_hangs_the_session(seed, tmp_path):
    style, on_sample = _hostile(seed)
    log = tmp_path / "hostile.mcap"
    t0 = time.monotonic()
    error = None
    with FakeBoard(on_sample=on_sample) as board:
        session = BenchSession(load_profile(), SessionConfig(link=board.url, log_path=log, seed=seed,
                                                             policy=POLICY, hold_cpu_latency=False))
        try:
            with session:
                session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1000)
                session.run_periods(PERIODS)
        except SessionError as exc:
            error = str(exc)
    elapsed = time.monotonic() - t0
    assert elapsed < BOUND_S, (style, elapsed)
    if style in ("silence", "heartbeats", "flood", "partial", "wrong_periods"):
        assert error is not None, style
    if error is not None:
        assert any(n in error for n in NAMED), (style, error)
        assert session.error == error
    # safe state: all six switches off after the session, whatever happened
    assert session.plant._cmd is GATE_COMMANDS[0]
    data = read_log(log)                        # readable, with the periods that ran
    assert "/plant/truth" in data
