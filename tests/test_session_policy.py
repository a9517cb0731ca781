"""SPEC.md 2.8 and 2.9: what a foreign board can rely on, against a fake board on a real pty."""
from __future__ import annotations

import os
import struct
import subprocess
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import pytest

from plant_rt import load_profile
from protocol.codec import FrameEncoder
from protocol.messages import PROTOCOL_VERSION, Gates, Heartbeat, ParamId, Sample, Telemetry

from hil.logs.reader import read_log
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from hil.session.policy import SessionPolicy
from tests.fake_board import FakeBoard

FAST = SessionPolicy(hello_wait_s=0.2, param_wait_s=0.2, answer_wait_min_s=0.02, watchdog_s=0.5)

REPO = Path(__file__).resolve().parents[1]


def _session(board, tmp_path=None, **config) -> BenchSession:
    config.setdefault("policy", FAST)
    log = None if tmp_path is None else tmp_path / "run.mcap"
    return BenchSession(load_profile(), SessionConfig(link=board.url, log_path=log,
                                                      hold_cpu_latency=False, **config))


def _refused(board, **config) -> str:
    with pytest.raises(SessionError) as err:
        with _session(board, **config):
            pass
    return str(err.value)


def _frame_of_version(version: int) -> bytes:
    """A HELLO frame whose header says another protocol version (right CRC and COBS)."""
    frame = bytearray(FrameEncoder().encode(Heartbeat(counter=1)))
    from cobs.cobs import decode as cobs_decode, encode as cobs_encode  # noqa: PLC0415
    raw = bytearray(cobs_decode(bytes(frame[:-1])))
    raw[0] = version
    import binascii  # noqa: PLC0415
    crc = binascii.crc_hqx(bytes(raw[:-2]), 0xFFFF)
    raw[-2:] = struct.pack("<H", crc)
    return cobs_encode(bytes(raw)) + b"\x00"


def test_frame_header_of_another_version_names_both_versions():
    with FakeBoard(hello_raw=_frame_of_version(2)) as board:
        t0 = time.monotonic()
        text = _refused(board)
    assert "sends frames of protocol version 2, the bench speaks version 1" in text
    assert time.monotonic() - t0 < 1.0           # at once, not after the HELLO tries


def test_crc_errors_instead_of_hello_are_counted_in_the_message():
    enc = FrameEncoder()
    enc.encode(Heartbeat(counter=0))                      # seq 1 from now on: no zero byte there
    bad = bytearray(enc.encode(Heartbeat(counter=0x01020304)))
    assert 0 not in bad[:-1]
    bad[6] ^= 0x40                               # CRC fails, COBS still fine
    with FakeBoard(hello_raw=bytes(bad) * 10) as board:
        text = _refused(board)
    assert "no HELLO from the board on" in text and "after 3 tries of 0.2 s" in text
    assert "30 frames failed their CRC" in text and "noisy line" in text


def test_silent_board_gets_three_hellos():
    with FakeBoard(answer_hello=False) as board:
        text = _refused(board)
        assert board.hellos == 3
    assert text.endswith("after 3 tries of 0.2 s: nothing received")


def test_hello_answered_on_the_third_try():
    with FakeBoard(hello_after_tries=3) as board:
        with _session(board) as session:
            assert session.board_name == "fake-board"


@pytest.mark.parametrize("knobs, needle", [
    (dict(role=0), "says role 0 (bench) in its HELLO; a controller is role 1"),
    (dict(capabilities=0x4), "advertises none of GATES, DUTY and DUTY_LEGS (capabilities 0x0004)"),
    (dict(control_period_ns=100_000), "was built for a control period of 100000 ns, the bench runs 50000 ns"),
    (dict(clamp={int(ParamId.CONTROL_PERIOD_S): 1e-4}), "control period of 100000 ns"),
])
def test_refusals_name_the_reason(knobs, needle, tmp_path):
    with FakeBoard(**knobs) as board:
        text = _refused(board, tmp_path=tmp_path)
    assert needle in text
    events = read_log(tmp_path / "run.mcap")["/plan/events"]
    assert "refused" in list(events["kind"])


def test_required_capability_missing():
    with FakeBoard(capabilities=0x1) as board:
        text = _refused(board, policy=SessionPolicy(hello_wait_s=0.2, require_capabilities=("TELEMETRY",)))
    assert "lacks capability TELEMETRY, required by the profile (session.require_capabilities)" in text


def test_duty_only_board_is_accepted_and_telemetry_divider_not_pushed(tmp_path, capsys):
    with FakeBoard(capabilities=0x2, clamp={int(ParamId.POLE_PAIRS): 3.0}) as board:
        with _session(board, tmp_path) as session:
            session.run_periods(3)
        assert int(ParamId.TELEMETRY_DIVIDER) not in board.params
    assert session.board_params["pole_pairs"] == 3.0       # the clamped value is in force
    err = capsys.readouterr().err
    assert "parameter pole_pairs: requested 1, the board clamped it to 3 (in force)" in err
    kinds = list(read_log(tmp_path / "run.mcap")["/plan/events"]["kind"])
    assert "param_clamped" in kinds and "param_skipped" in kinds


def _stale(sample, enc):
    return enc.encode(Gates(period=(sample.period + 1000) & 0xFFFFFFFF, gates=0))


def _heartbeats(sample, enc):
    return b"".join(enc.encode(Heartbeat(counter=i)) for i in range(50))


def test_stale_answers_are_named_as_stale(tmp_path):
    with FakeBoard(on_sample=_stale) as board:
        session = _session(board, tmp_path)
        with pytest.raises(SessionError) as err:
            with session:
                session.run_periods(100)
    text = str(err.value)
    assert "no GATES/DUTY for period 0 in" in text and "stale answers" in text
    assert "(last: GATES for period 10" in text


def test_heartbeat_flood_does_not_extend_the_wait(tmp_path):
    with FakeBoard(on_sample=_heartbeats) as board:
        session = _session(board, tmp_path)
        t0 = time.monotonic()
        with pytest.raises(SessionError) as err:
            with session:
                session.run_periods(100)
        elapsed = time.monotonic() - t0
    assert "board sent only HEARTBEAT" in str(err.value)
    # watchdog_s 0.5 (raised to 4 waits of 0.02 s: no), HELLO + params well under 1 s
    assert elapsed < 3.0
    assert session.plant.gates_applied == 0 if hasattr(session.plant, "gates_applied") else True


def test_lost_answer_is_resent_and_the_run_is_unchanged():
    """A noisy line costs waits, not simulation: every 3rd answer lost, the same run."""
    def lossy(sample, enc):
        if sample.period % 3 == 1 and not lossy.dropped.get(sample.period):
            lossy.dropped[sample.period] = True
            return b""
        return enc.encode(Gates(period=sample.period, gates=0x29 if sample.period > 5 else 0))
    lossy.dropped = {}

    def clean(sample, enc):
        return enc.encode(Gates(period=sample.period, gates=0x29 if sample.period > 5 else 0))

    # The board is a thread of this process: on a loaded machine it may answer later than a
    # short wait, which costs a resend the test did not cause. So the waits are long enough
    # that a miss needs a stall of 6 x 0.25 s, and resends are counted against what the
    # board received rather than against a number that assumes a prompt board.
    patient = replace(FAST, answer_wait_min_s=0.25, answer_resends=5)
    runs = []
    for behaviour in (clean, lossy):
        with FakeBoard(on_sample=behaviour) as board:
            with _session(board, policy=patient) as session:
                session.run_periods(30)
                runs.append((session.recorder.arrays(), session.resent_samples,
                             session.missed_answers))
            sent = Counter(m.period for m in board.received if isinstance(m, Sample))
        runs[-1] += (sent,)
    (a, resent_a, missed_a, sent_a), (b, resent_b, missed_b, sent_b) = runs
    assert sorted(lossy.dropped) == list(range(1, 30, 3))          # 10 answers lost
    assert all(sent_b[k] >= 2 for k in lossy.dropped)               # each one's SAMPLE resent
    assert resent_a == sum(sent_a.values()) - 30 and resent_b == sum(sent_b.values()) - 30
    assert missed_a == missed_b == 0
    for name in a:
        assert (a[name][1] == b[name][1]).all(), name


def test_shoot_through_and_board_fault_printed_once(tmp_path, capsys):
    def shoot(sample, enc):
        return enc.encode(Gates(period=sample.period, gates=0x03))
    with FakeBoard(on_sample=shoot) as board:
        with _session(board, tmp_path) as session:
            session.run_periods(5)
    err = capsys.readouterr().err
    assert err.count("shoot-through") == 2     # the first one, then the count at the end
    assert "period 0 (t = 0 s): GATES 0x03 turns on A high and A low together (shoot-through)" in err


def write_heartbeat_board(tmp_path) -> Path:
    """An executable board that does HELLO and parameters, then answers every SAMPLE with
    HEARTBEAT and never with GATES."""
    script = tmp_path / "heartbeat_board.py"
    script.write_text(f"""
import os, sys
sys.path.insert(0, {str(os.getcwd())!r})
from protocol.codec import FrameEncoder, StreamDecoder
from protocol.messages import Hello, ParamSet, ParamGet, ParamValue, Heartbeat, Sample
enc, dec = FrameEncoder(), StreamDecoder()
params = {{}}
while True:
    data = os.read(0, 4096)
    if not data:
        break
    for m in dec.feed(data):
        out = []
        if isinstance(m, Hello):
            out.append(Hello(1, 1, 1, m.control_period_ns, 2, b"hb"))
        elif isinstance(m, ParamSet):
            params[m.id] = m.value
            out.append(ParamValue(m.id, 0, m.value))
        elif isinstance(m, ParamGet):
            out.append(ParamValue(m.id, 0, params.get(m.id, 0.0)))
        elif isinstance(m, Sample):
            out.append(Heartbeat(m.period))
        for o in out:
            os.write(1, enc.encode(o))
""")
    board = tmp_path / "heartbeat_board"
    board.write_text(f"#!/bin/sh\nexec {sys.executable} {script}\n")
    board.chmod(0o755)
    return board


def test_heartbeat_only_board_ends_hil_run_with_exit_2_within_15_s(tmp_path):
    """The issue's acceptance: a board process that answers HEARTBEAT but never GATES."""
    board = write_heartbeat_board(tmp_path)
    plan = tmp_path / "plan.yaml"
    plan.write_text("name: hb\nsteps:\n  - run: {duration_s: 1.0}\n")
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "run", str(plan), "--link",
                           f"exec:{board}", "--out", str(tmp_path / "out"), "--no-progress"],
                          capture_output=True, text=True, timeout=60)
    assert time.monotonic() - t0 < 15.0
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "board sent only HEARTBEAT" in proc.stdout + proc.stderr


def test_a_board_that_keeps_talking_cannot_hold_the_answer_wait(tmp_path):
    """A board that sends HEARTBEAT every 20 ms of its own accord, shorter than the 0.1 s
    answer wait, and never GATES: each wait still ends at its one deadline (SPEC 2.8), so the
    run ends by the watchdog within seconds. (A wait that restarted on every frame would never
    end: issue 13, item 1.)"""
    script = tmp_path / "chatty_board.py"
    script.write_text(f"""
import os, select, sys, time
sys.path.insert(0, {str(REPO)!r})
from protocol.codec import FrameEncoder, StreamDecoder
from protocol.messages import Hello, ParamSet, ParamGet, ParamValue, Heartbeat
enc, dec = FrameEncoder(), StreamDecoder()
params, beat, next_beat = {{}}, 0, time.monotonic()
while True:
    ready, _, _ = select.select([0], [], [], 0.005)
    if ready:
        data = os.read(0, 4096)
        if not data:
            break
        for m in dec.feed(data):
            if isinstance(m, Hello):
                os.write(1, enc.encode(Hello(1, 1, 1, m.control_period_ns, 2, b"hb")))
            elif isinstance(m, ParamSet):
                params[m.id] = m.value
                os.write(1, enc.encode(ParamValue(m.id, 0, m.value)))
            elif isinstance(m, ParamGet):
                os.write(1, enc.encode(ParamValue(m.id, 0, params.get(m.id, 0.0))))
    if time.monotonic() >= next_beat:
        beat += 1
        next_beat += 0.02
        os.write(1, enc.encode(Heartbeat(beat)))
""")
    board = tmp_path / "chatty_board"
    board.write_text(f"#!/bin/sh\nexec {sys.executable} {script}\n")
    board.chmod(0o755)
    plan = tmp_path / "plan.yaml"
    plan.write_text("name: chatty\nsteps:\n  - run: {duration_s: 1.0}\n")
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "hil.cli.main", "run", str(plan), "--link",
                           f"exec:{board}", "--out", str(tmp_path / "out"), "--no-progress"],
                          capture_output=True, text=True, timeout=60)
    assert time.monotonic() - t0 < 15.0
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "watchdog" in proc.stdout + proc.stderr
