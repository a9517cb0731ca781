"""Link faults: the tap's statistics follow its seed, its counters reconcile with both
decoders, and a session survives every link fault (lockstep and real time) or, past the
watchdog, safe-states and ends with ERROR with its log readable."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from plant_rt import load_profile

from bench.soak import stub_counters
from hil.faults.injector import LINK_KINDS, injector
from hil.session.link_tap import LinkFault, LinkTap, _flip_bits
from hil.logs.reader import read_log
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from protocol.codec import FrameEncoder, StreamDecoder
from protocol.messages import Sample


class _Sink:
    """A byte link that keeps what it is sent (the tap's far end, without a board)."""

    url = "sink"

    def __init__(self):
        self.sent: list[bytes] = []
        self.counters: dict[str, int] = {}

    def send_bytes(self, data: bytes) -> None:
        self.sent.append(bytes(data))

    def read_bytes(self, timeout_s=None) -> bytes:
        return b""

    def close(self) -> None:
        pass


def _traffic(tap: LinkTap, periods: int) -> None:
    for k in range(periods):
        tap.tick(k)
        tap.send(Sample(k, 2048, 2048, 2867, k & 0xFFFF, 0))


# --------------------------------------------------------------------------- seeds and rates
@pytest.mark.parametrize("kind", ["drop", "corrupt", "duplicate", "reorder"])
def test_same_seed_same_faults_and_counts_near_rate_times_frames(kind):
    runs = []
    for seed in (7, 7, 8):
        sink = _Sink()
        tap = LinkTap(sink, seed=0)
        tap.set_fault("f", LinkFault(kind, rate=0.05, direction="out", seed=seed))
        _traffic(tap, 20000)
        runs.append((dict(tap.stats), sink.sent))
    (stats_a, sent_a), (stats_b, sent_b), (stats_c, sent_c) = runs
    assert stats_a == stats_b and sent_a == sent_b          # same seed: the same frames hit
    assert sent_a != sent_c                                 # another seed: other frames
    done = {"drop": "dropped", "corrupt": "corrupted", "duplicate": "duplicated",
            "reorder": "reordered"}[kind]
    n = stats_a["out_frames"]
    assert n == 20000
    sigma = math.sqrt(n * 0.05 * 0.95)
    assert abs(stats_a[f"out_{done}"] - 0.05 * n) < 4 * sigma
    assert stats_a["in_frames"] == 0                          # direction: out only


def test_the_session_seed_drives_faults_without_their_own():
    def counts(seed):
        tap = LinkTap(_Sink(), seed=seed)
        tap.set_fault("f", LinkFault("drop", rate=0.1))
        _traffic(tap, 2000)
        return tap.stats["out_dropped"]

    assert counts(1) == counts(1) != counts(2)


def test_corruption_damages_exactly_one_frame_each():
    """A corrupted frame never gains or loses a 0x00 delimiter: the receiver counts exactly one
    error per corrupted frame (CRC or framing) and decodes every other frame."""
    rng = random.Random(3)
    encoder = FrameEncoder()
    decoder = StreamDecoder()
    stream = bytearray()
    damaged = 0
    for k in range(20000):
        frame = encoder.encode(Sample(k, 2048, k & 0xFFF, 2867, k & 0xFFFF, 0))
        if rng.random() < 0.2:
            frame = _flip_bits(frame, rng.choice((1, 2, 3)), rng)
            damaged += 1
        stream += frame
    msgs = decoder.feed(bytes(stream))
    c = decoder.counters
    assert c["crc_errors"] + c["framing_errors"] == damaged
    assert c["frames_ok"] == len(msgs) == 20000 - damaged


def test_bad_link_fault_arguments_are_refused():
    with pytest.raises(ValueError, match="direction must be out, in or both"):
        LinkFault("drop", direction="sideways")
    with pytest.raises(ValueError, match="rate must be in"):
        LinkFault("drop", rate=1.5)
    tap = LinkTap(_Sink())
    with pytest.raises(ValueError, match="unknown link fault 'melt'"):
        tap.set_fault("x", LinkFault("melt"))


# --------------------------------------------------------------------------- the stub's counters
def reconcile(session, periods: int, before_board, before_bench: dict, telemetry_rows: int,
              missed: int) -> dict:
    """Checks every counter against every other over a stretch of ``periods`` periods under
    drop and corrupt faults (SAMPLE out; GATES and TELEMETRY back each answered period):
    - the board decoded exactly the SAMPLEs that were neither dropped nor corrupted, and
      counted exactly one decode error per corrupted SAMPLE;
    - the bench's decoder counted exactly one CRC or framing error per corrupted frame in,
      and decoded every frame in that was neither dropped nor corrupted;
    - the periods without GATES are exactly the SAMPLEs lost plus the GATES lost, where the
      GATES lost are the frames lost in minus the TELEMETRY lost."""
    st = session.tap.stats
    board = stub_counters(session)
    bench = session.tap._decoder.counters
    lost_out = st["out_dropped"] + st["out_corrupted"]
    lost_in = st["in_dropped"] + st["in_corrupted"]
    assert st["out_frames"] == periods
    assert board.decode_errors - before_board.decode_errors == st["out_corrupted"]
    assert board.frames_in - before_board.frames_in == periods - lost_out
    assert st["in_frames"] == 2 * (periods - lost_out)
    assert (bench["crc_errors"] + bench["framing_errors"]
            - before_bench["crc_errors"] - before_bench["framing_errors"]) == st["in_corrupted"]
    assert bench["frames_ok"] - before_bench["frames_ok"] == st["in_frames"] - lost_in
    telemetry_lost = (periods - lost_out) - telemetry_rows
    gates_lost = lost_in - telemetry_lost
    assert missed == lost_out + gates_lost
    assert 0 <= lost_in - (bench["seq_gaps"] - before_bench["seq_gaps"]) <= 2   # trailing losses
    assert session.stale_answers == 0
    return {"lost_out": lost_out, "lost_in": lost_in, "gates_lost": gates_lost}


def test_counters_reconcile_under_drop_and_corruption(tmp_path):
    log = tmp_path / "run.mcap"
    with BenchSession(load_profile(), SessionConfig(link="stub", log_path=log, seed=5,
                                                    answer_resends=0)) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1000)
        session.run_periods(200)
        session.drain()                      # period 199's TELEMETRY: not the window's
        board0, bench0 = stub_counters(session), dict(session.tap._decoder.counters)
        missed0, tel0 = session.missed_answers, len(session.recorder.telemetry_rows)
        inj = injector(session)
        inj.inject("link_drop", rate=0.05)
        inj.inject("link_corrupt", rate=0.05, bits=2)
        session.run_periods(20000)
        session.drain()                      # the last TELEMETRY, already counted in
        inj.clear()
        got = reconcile(session, 20000, board0, bench0,
                        len(session.recorder.telemetry_rows) - tel0, session.missed_answers - missed0)
        assert got["lost_out"] > 1500 and got["gates_lost"] > 700
        assert not session.faults            # the board rode through: no FAULT, no STATUS
        counters = session.link_counters()
    assert counters["out_corrupted"] > 800 and counters["missed_answers"] >= 2000
    data = read_log(log)
    assert data.complete and len(data["/plant/truth"]) == 20200


# --------------------------------------------------------------------------- survival
BURSTS = {  # fault -> (arguments, periods it lasts): all shorter than the 20-period watchdog
    "link_drop": ({"rate": 0.3, "seed": 1}, 400),
    "link_corrupt": ({"rate": 0.3, "bits": 3, "seed": 1}, 400),
    "link_delay": ({"periods": 3}, 15),
    "link_duplicate": ({"rate": 0.3, "seed": 1}, 400),
    "link_reorder": ({"rate": 0.3, "seed": 1}, 400),
    "link_unplug": ({}, 15),
}


def _survives(link: str, mode: str, name: str, tmp_path, **config):
    args, periods = BURSTS[name]
    log = tmp_path / f"{name}.mcap"
    with BenchSession(load_profile(), SessionConfig(link=link, mode=mode, log_path=log,
                                                    **config)) as session:
        session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=600)
        session.run_periods(400)
        missed0 = session.missed_answers + session.rt_stats.get("missing_answers", 0)
        injector(session).inject(name, duration_s=periods * session.period_s, **args)
        session.run_periods(periods + 300)
        missed = session.missed_answers + session.rt_stats.get("missing_answers", 0) - missed0
        counters = session.link_counters()
        speed = session.recorder.arrays()["plant.speed_rpm"][1]
    assert session.error is None and not injector(session).active
    kind = LINK_KINDS[name]
    done = {"drop": "dropped", "corrupt": "corrupted", "delay": "delayed", "duplicate": "duplicated",
            "reorder": "reordered", "unplug": "unplugged"}[kind]
    assert counters.get(f"out_{done}", 0) + counters.get(f"in_{done}", 0) > 0
    if kind in ("drop", "corrupt", "unplug", "delay"):
        assert missed > 0
    assert speed[-1] > 300                                   # the drive is still under control
    data = read_log(log)
    assert data.complete
    events = data["/plan/events"]
    actions = [a for k, a in zip(events["kind"], events["action"]) if k == "fault"]
    assert actions == ["inject", "lift"]
    return counters, missed


@pytest.mark.parametrize("name", sorted(BURSTS))
def test_lockstep_survives_each_link_fault(name, tmp_path):
    counters, missed = _survives("stub", "lockstep", name, tmp_path)
    if name in ("link_duplicate", "link_reorder"):
        assert counters["stale_answers"] > 0 or counters["seq_gaps"] > 0


@pytest.mark.parametrize("name", sorted(BURSTS))
def test_realtime_survives_each_link_fault(name, tmp_path):
    _survives("stub", "realtime", name, tmp_path, realtime_period_s=2e-4,
              realtime_miss_budget=10 ** 6)


@pytest.mark.parametrize("name", ["link_drop", "link_corrupt", "link_unplug"])
def test_lockstep_over_a_pseudo_terminal_survives(name, tmp_path):
    """The same through the hil-stub process on a pty: a lost frame costs answer_timeout_s."""
    _survives("stub-pty", "lockstep", name, tmp_path, answer_timeout_s=0.02)


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_a_20ms_unplug_trips_the_watchdog_and_the_log_survives(mode, tmp_path):
    """The cable out for 20 ms (400 periods) with a 20-period watchdog: the session safe-states
    the plant and ends with an error that says when and why; the log is readable to the end."""
    log = tmp_path / "unplug.mcap"
    config = dict(link="stub", mode=mode, log_path=log)
    if mode == "realtime":
        config.update(realtime_period_s=2e-4, realtime_miss_budget=10 ** 6)
    session = BenchSession(load_profile(), SessionConfig(**config))
    with pytest.raises(SessionError, match=r"watchdog: no GATES/DUTY for 20 consecutive.* at period \d+ "):
        with session:
            session.send_command(enable=True, speed_source="encoder", speed_ref_rpm=1500)
            session.run_periods(2000)
            injector(session).inject("link_unplug", duration_s=0.02)
            session.run_periods(1000)
    k_fault = next(d["period"] for _, kind, d in session.events if kind == "fault")
    k_dog = next(d["period"] for _, kind, d in session.events if kind == "watchdog")
    assert k_dog - k_fault in (19, 20)          # periods k_fault .. k_dog: 20 without GATES
    # safe state: all switches off from the watchdog on; the motor coasts, currents die out
    for _ in range(400):
        session.plant.step(None)
    assert abs(session.plant.truth()[1]) < 1e-6
    data = read_log(log)
    assert data.complete
    kinds = list(data["/plan/events"]["kind"])
    assert "fault" in kinds and "watchdog" in kinds and kinds[-1] == "session_end"
    periods = np.asarray(data["/plant/sensors"]["period"])
    assert periods[-1] >= k_dog - 1
