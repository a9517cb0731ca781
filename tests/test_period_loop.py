"""The C period loop (protocol.ccodec.exchange_periods) that runs the plain lockstep periods of
an in-process firmware, against what the bench's Python loop does.

Two kinds of evidence:
- whole sessions with the stub, run once with the C loop and once with the Python loop only
  (exchange_periods set to None): the same signals bit for bit, the same raw frames and link
  counters, the same period count returned, for GATES (DTC) and DUTY (FOC) answers, a stop
  condition, a COMMAND between runs and a per-period stimulus that is idle or not, in process
  and over a pseudo-terminal (stub-pty);
- the loop alone, driven by a scripted board (a ctypes callback in hil_fw_exchange's place, or
  the far end of a socket pair) and a stand-in plant: every answer it must not take (stale,
  shoot-through, another kind, a STATUS, none at all) is handed back at the right period with
  the rest of the answers queued, as the Python loop would find them; over a descriptor, the
  answers read ahead are carried over, a frame split across reads waits in the partial
  buffer, the answer wait is the SAMPLE's one deadline, and a closed line is a link error.
"""
from __future__ import annotations

import ctypes
from array import array
from collections import deque

import numpy as np
import pytest

from protocol import ccodec, codec
from protocol.messages import Duty, Gates, Sample, Status, Telemetry

pytestmark = pytest.mark.skipif(not ccodec.AVAILABLE or ccodec.exchange_periods is None,
                                reason=ccodec.UNAVAILABLE_REASON or "an old _hilcodec build")


# ------------------------------------------------------------------ whole sessions

def _session_run(tmp_path, name, c_loop, monkeypatch, scenario):
    from hil.logs.reader import read_log
    from hil.session import BenchSession, SessionConfig
    from hil.session.board_params import load_bench_profile

    calls = []
    if c_loop:
        real = ccodec.exchange_periods

        def counting(*args):
            calls.append(1)
            return real(*args)
        monkeypatch.setattr(ccodec, "exchange_periods", counting)
    else:
        monkeypatch.setattr(ccodec, "exchange_periods", None)
    log = tmp_path / f"{name}.mcap"
    with BenchSession(load_bench_profile(), SessionConfig(link="stub", seed=11, log_path=log)) as s:
        returned = scenario(s)
        s.drain()
        signals = {n: v for n, (_, v, _) in s.recorder.arrays().items()}
        counters = dict(s.tap.counters)
        stats = (s.missed_answers, s.stale_answers, s.resent_samples, s.plant.period,
                 s._answer_kind)
    monkeypatch.undo()
    frames = {t: read_log(log)[t] for t in ("/link/frames_out", "/link/frames_in")}
    return signals, counters, stats, returned, frames, len(calls)


def _same(tmp_path, monkeypatch, scenario, c_loop_used=True):
    fast = _session_run(tmp_path, "c", True, monkeypatch, scenario)
    slow = _session_run(tmp_path, "py", False, monkeypatch, scenario)
    assert fast[0].keys() == slow[0].keys()
    assert [n for n in fast[0] if not np.array_equal(fast[0][n], slow[0][n], equal_nan=True)] == []
    assert fast[1:4] == slow[1:4]
    for topic in fast[4]:
        for field, values in fast[4][topic].fields.items():
            assert list(values) == list(slow[4][topic].fields[field]), (topic, field)
    assert (fast[5] > 0) == c_loop_used
    return fast


def _dtc_with_stop(s):
    s.send_command(enable=True, speed_source="ekf", speed_ref_rpm=2000)
    first = s.run_periods(1500)
    s.send_command(speed_ref_rpm=1000)
    stop_at = s.plant.period + 537
    second = s.run_periods(5000, stop=lambda: s.plant.period >= stop_at)
    return first, second


def test_dtc_gates_and_a_stop_condition_as_the_python_loop(tmp_path, monkeypatch):
    fast = _same(tmp_path, monkeypatch, _dtc_with_stop)
    assert fast[3] == (1500, 537)
    assert fast[1]["tx_frames"] >= 2000


def test_foc_duty_answers_as_the_python_loop(tmp_path, monkeypatch):
    def foc(s):
        s.param_set("control_law", 1)
        s.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
        return s.run_periods(1800)
    fast = _same(tmp_path, monkeypatch, foc)
    assert fast[2][4] is Duty


class _Stimulus:
    """A per-period hook that is idle until armed: the loop may skip it only while idle."""

    def __init__(self, session):
        self.session, self.armed, self.calls = session, False, 0

    @property
    def idle(self):
        return not self.armed

    def __call__(self, k):
        self.calls += 1
        if self.armed:
            self.session.plant.set_dc_voltage(70.0 - 0.01 * (k % 100))


def test_a_per_period_hook_runs_every_period_unless_idle(tmp_path, monkeypatch):
    idle_calls = []

    def hooked(s):
        hook = _Stimulus(s)
        s.on_period = hook
        s.send_command(enable=True, speed_source="ekf", speed_ref_rpm=1500)
        s.run_periods(600)                 # idle: the C loop may skip it
        idle_calls.append(hook.calls)
        hook.armed = True
        s.run_periods(400)                 # armed: called every period, in Python
        return hook.calls - idle_calls[-1]
    fast = _same(tmp_path, monkeypatch, hooked)
    assert fast[3] == 400
    assert idle_calls[0] < 600 and idle_calls[1] == 600     # C loop first, then the Python one


class _Live:
    """What a live stream takes from the recorder (hil.live.LiveStream's period/telemetry_row)."""

    def __init__(self, every):
        self.every, self.periods, self.rows = every, [], []

    def period(self, k, truth, sample):
        self.periods.append((k, tuple(truth), tuple(sample)))

    def telemetry_row(self, row):
        self.rows.append(tuple(row))


def test_a_live_viewer_gets_the_same_rows_from_either_loop(tmp_path, monkeypatch):
    lives = []

    def watched(s):
        live = _Live(every=7)
        lives.append(live)
        s.recorder.live = live
        s.send_command(enable=True, speed_source="ekf", speed_ref_rpm=1500)
        return s.run_periods(1500)
    _same(tmp_path, monkeypatch, watched)
    fast, slow = lives
    assert fast.periods == slow.periods and len(fast.periods) >= 1500 // 7
    assert fast.rows == slow.rows and len(fast.rows) >= 1500 // 7 - 1
    assert all(k % 7 == 0 for k, _, _ in fast.periods) and all(r[0] % 7 == 0 for r in fast.rows)


# ------------------------------------------------------------------ the loop alone

_EXCHANGE = ctypes.CFUNCTYPE(ctypes.c_size_t, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint8),
                             ctypes.c_size_t, ctypes.POINTER(ctypes.c_uint8), ctypes.c_size_t)


def _telemetry(k):
    return Telemetry(k, 1, 0, 1, 0b100001, *([0.5] * 12))


class _Rig:
    """A scripted board (answers[k]: the messages it sends for SAMPLE(k)) and a stand-in plant
    (sample/truth/step on a period counter) around one exchange_periods call."""

    def __init__(self, answers, publish_every=1000, batch=1000, telemetry_rows=None):
        self.answers = answers
        self.k = 1
        self.steps = []
        self.board_encoder = codec.FrameEncoder()
        self.board_decoder = codec.StreamDecoder()
        self.exchange = _EXCHANGE(self._board)
        self.counts = array("q", [0] * 5)
        self.inbox = deque()
        # the recorder's stage (Recorder.batch_stage) and what seal() took out of it
        self.stage = (np.full((batch, 6), np.nan), np.full((batch, 2), np.nan),
                      np.full((telemetry_rows or 2 * batch, 17), np.nan), np.zeros(2, np.int64))
        self.sealed_rows = ([], [], [])
        self.sealed = 0
        self.publish_every = publish_every
        self.target = (ctypes.cast(self.exchange, ctypes.c_void_p).value, 1, ccodec.FrameEncoder(),
                       ccodec.StreamDecoder(), bytearray(), bytearray(), self.counts, self.inbox)

    def _rows(self, i):
        fill = self.stage[3][0 if i < 2 else 1]
        return self.sealed_rows[i] + [tuple(r) for r in self.stage[i][:fill].tolist()]

    @property
    def periods(self):
        return [int(r[0]) for r in self._rows(0)]

    @property
    def sensors(self):
        return [tuple(int(v) for v in r[1:]) for r in self._rows(0)]

    @property
    def truths(self):
        return self._rows(1)

    @property
    def telemetry(self):
        return self._rows(2)

    def _board(self, _fw, rx, rx_len, tx, tx_cap):
        if rx_len == 0:
            return 0
        (sample,) = self.board_decoder.feed(bytes(rx[:rx_len]))
        out = b"".join(self.board_encoder.encode(m) for m in self.answers.get(sample.period, ()))
        assert len(out) <= tx_cap
        ctypes.memmove(tx, out, len(out))
        return len(out)

    def sample(self):
        return (self.k, 2048, 2050, 3000, self.k & 0xFFFF, 0)

    def truth(self):
        return (self.k * 1e-4, float(self.k))

    def step(self, gates=None, duty=None):
        self.steps.append((self.k, gates, duty))
        self.k += 1

    def seal(self):
        self.sealed += 1
        for i in range(3):
            self.sealed_rows[i].extend(self._rows(i)[len(self.sealed_rows[i]):])
        self.stage[3][:] = 0

    def run(self, count, answer=0, stop=None, live_every=0):
        return ccodec.exchange_periods(self.target, self.sample, self.truth, self.step, self.stage,
                                       self.seal, self.publish_every, count, stop, answer, live_every)


def test_plain_periods_are_taken_and_the_answers_after_gates_stay_queued():
    rig = _Rig({k: [Gates(k, 0b100001), _telemetry(k)] for k in range(1, 6)})
    assert rig.run(5) == (5, 0, None)
    assert rig.steps == [(k, 0b100001, None) for k in range(1, 6)]
    assert rig.periods == [1, 2, 3, 4, 5] and rig.truths[2] == (3 * 1e-4, 3.0)
    assert rig.sensors[0] == (2048, 2050, 3000, 1, 0)
    # TELEMETRY(k) comes after GATES(k): taken at period k + 1, as the Python loop pops it
    assert [r[0] for r in rig.telemetry] == [1, 2, 3, 4]
    assert rig.telemetry[0] == (1.0, 1.0, 0.0, 1.0, 33.0) + (0.5,) * 12
    assert list(rig.inbox) == [_telemetry(5)]
    assert list(rig.counts) == [5, 10, sum(len(codec.FrameEncoder().encode(Sample(k, 2048, 2050, 3000, k, 0)))
                                           for k in range(1, 6)), rig.counts[3], 0]
    # what inbox held at entry is taken first
    rig.answers[6] = [Gates(6, 0)]
    assert rig.run(1) == (1, 0, None)
    assert rig.telemetry[-1][0] == 5 and not rig.inbox


@pytest.mark.parametrize("why, answers", [
    ("stale", [Gates(2, 0b100001), _telemetry(2)]),
    ("shoot-through", [Gates(3, 0b000011)]),
    ("another kind", [Duty(3, (1000, 2000, 3000))]),
    ("a STATUS first", [Status(3, 1, 0), Gates(3, 0b100001)]),
    ("no answer", []),
])
def test_an_answer_it_must_not_take_is_handed_back_at_its_period(why, answers):
    script = {1: [Gates(1, 0b100001)], 2: [Gates(2, 0b100001), _telemetry(2)], 3: answers}
    rig = _Rig(script)
    done, state, extra = rig.run(10)
    assert (done, state, extra) == (2, 2, None), why
    assert [s[0] for s in rig.steps] == [1, 2]
    # period 3 sampled, recorded and sent; its answers (TELEMETRY(2) first) wait in inbox
    assert rig.periods == [1, 2, 3] and rig.counts[0] == 3
    # the TELEMETRY(2) queued behind GATES(2) was taken; from the first answer not taken on,
    # everything is left for the caller, in order
    assert [r[0] for r in rig.telemetry] == [2]
    assert list(rig.inbox) == answers


def test_duty_and_the_publish_boundary_and_stop():
    rig = _Rig({k: [Duty(k, (0, 32768, 65535))] for k in range(1, 20)}, publish_every=7)
    assert rig.run(20, answer=1) == (6, 1, None)         # period 7 is the caller's (raw frames)
    assert rig.steps[0] == (1, None, (0.0, 32768 / 65535.0, 1.0))
    rig.k = 8
    assert rig.run(20, answer=1, stop=lambda: rig.k >= 10) == (2, 3, None)
    assert rig.run(20, answer=0) == (0, 2, None)         # DUTY where GATES is the board's kind


def test_a_telemetry_flood_seals_the_batch_early():
    rig = _Rig({k: [_telemetry(k), _telemetry(k), Gates(k, 0)] for k in range(1, 6)},
               telemetry_rows=3)
    assert rig.run(5) == (5, 0, None)
    assert rig.sealed == 3 and rig.periods == [1, 2, 3, 4, 5]
    assert [r[0] for r in rig.telemetry] == [1, 1, 2, 2, 3, 3, 4, 4, 5, 5]


def test_the_rows_a_live_view_takes_are_handed_back():
    # a period that is a multiple of live_every is not begun
    rig = _Rig({k: [Gates(k, 0)] for k in range(1, 11)})
    assert rig.run(10, live_every=4) == (3, 1, None)
    assert rig.periods == [1, 2, 3] and rig.counts[0] == 3
    # a TELEMETRY of such a period is not taken: its period goes back with it at the front
    rig = _Rig({1: [Gates(1, 0b100001)], 2: [_telemetry(9), Gates(2, 0b100001)]})
    assert rig.run(10, live_every=3) == (1, 2, None)
    assert list(rig.inbox) == [_telemetry(9), Gates(2, 0b100001)] and rig.telemetry == []


def test_batches_are_sealed_and_a_closed_instance_is_not_called():
    rig = _Rig({k: [Gates(k, 0)] for k in range(1, 12)}, batch=4)
    assert rig.run(10) == (10, 0, None)
    assert rig.sealed == 2 and rig.periods == list(range(1, 11))
    assert rig.stage[3].tolist() == [2, 0]
    rig.counts[4] = 1
    assert rig.run(1) == (0, 1, None)
    assert rig.counts[0] == 10


# ------------------------------------------------------------------ over a file descriptor

def test_stub_pty_as_the_python_loop(tmp_path, monkeypatch):
    """The descriptor kind: the stub in its own process behind a pseudo-terminal."""
    def pty_run(s):
        s.send_command(enable=True, speed_source="ekf", speed_ref_rpm=1500)
        return s.run_periods(1200)

    def on_pty(tmp, name, c_loop, mp, scenario):
        from hil.session import BenchSession, SessionConfig
        from hil.session.board_params import load_bench_profile

        mp.setattr(ccodec, "exchange_periods", ccodec.exchange_periods if c_loop else None)
        with BenchSession(load_bench_profile(), SessionConfig(link="stub-pty", seed=11)) as s:
            returned = scenario(s)
            s.drain()
            signals = {n: v for n, (_, v, _) in s.recorder.arrays().items()}
            counters = dict(s.tap.counters)
            used = s.tap._direct_counts is not None and s.tap._direct_counts[0] > 0
        mp.undo()
        return signals, counters, returned, used
    fast = on_pty(tmp_path, "c", True, monkeypatch, pty_run)
    slow = on_pty(tmp_path, "py", False, monkeypatch, pty_run)
    assert fast[3] and not slow[3]
    assert [n for n in fast[0] if not np.array_equal(fast[0][n], slow[0][n], equal_nan=True)] == []
    assert fast[1] == slow[1] and fast[2] == slow[2] == 1200


class _FdRig(_Rig):
    """The loop over one end of a socket pair; the test is the board at the other end."""

    def __init__(self, answer_timeout_s=0.5, **kw):
        import socket
        super().__init__({}, **kw)
        self.bench_end, self.board_end = socket.socketpair()
        self.bench_end.setblocking(False)
        self.partial = bytearray()
        self.target = (self.bench_end.fileno(), answer_timeout_s, 0.5, ccodec.FrameEncoder(),
                       ccodec.StreamDecoder(), bytearray(), bytearray(), self.counts, self.inbox,
                       self.partial)

    def answer(self, *msgs) -> bytes:
        data = b"".join(self.board_encoder.encode(m) for m in msgs)
        self.board_end.sendall(data)
        return data

    def samples(self):
        self.board_end.setblocking(False)
        try:
            return [m.period for m in self.board_decoder.feed(self.board_end.recv(65536))]
        except BlockingIOError:
            return []

    def close(self):
        self.bench_end.close()
        self.board_end.close()


def test_answers_already_on_the_line_are_read_and_carried_over():
    rig = _FdRig()
    sent = b"".join(rig.answer(Gates(k, 0b100001), _telemetry(k)) for k in range(1, 6))
    assert rig.run(5) == (5, 0, None)
    assert rig.samples() == [1, 2, 3, 4, 5]
    assert [s[0] for s in rig.steps] == [1, 2, 3, 4, 5]
    assert [r[0] for r in rig.telemetry] == [1, 2, 3, 4]
    # everything was read at once: what followed GATES(5) went back to inbox, in order
    assert list(rig.inbox) == [_telemetry(5)]
    assert (rig.counts[0], rig.counts[1], rig.counts[3]) == (5, 10, len(sent))
    assert bytes(rig.target[6]) == sent and rig.partial == bytearray()
    rig.close()


def test_a_frame_split_across_reads_waits_in_the_partial_buffer():
    rig = _FdRig(answer_timeout_s=0.05)
    frame = rig.board_encoder.encode(Gates(1, 0b100001))
    rig.board_end.sendall(frame[:5])
    done, state, sent_at = rig.run(3)
    assert (done, state) == (0, 2) and isinstance(sent_at, float)
    assert rig.partial == frame[:5] and rig.periods == [1] and not rig.target[6]
    import time
    assert time.monotonic() - sent_at >= 0.05          # it waited the whole answer time
    rig.board_end.sendall(frame[5:])
    assert rig.run(1) == (1, 0, None)                  # (SAMPLE(1) again, as a resend)
    assert rig.steps == [(1, 0b100001, None)] and rig.partial == bytearray()
    assert bytes(rig.target[6]) == frame
    rig.close()


def test_a_line_closed_by_the_board_is_a_link_error_after_the_record():
    import errno
    import socket
    rig = _FdRig()
    rig.board_end.shutdown(socket.SHUT_WR)
    assert rig.run(3) == (0, 4, (0, "the other end closed the line"))
    assert rig.periods == [1] and not rig.steps
    rig.board_end.close()
    done, state, (code, what) = rig.run(3)
    assert (done, state, what) == (0, 4, "write failed") and code == errno.EPIPE
    rig.bench_end.close()
