"""`hil probe` and the session's adapter check against boards on pseudo-terminals: the stub
(`stub-pty`), the stub through the wire model at 16 ms and 1 ms, and a fake board whose port
a fake sysfs tree describes as each driver. Timings are reported, never asserted: a round trip
is checked positive and finite, and every figure that is asserted comes from the model or the
tree. The modelled waits are held for real only in the probe (a few SAMPLEs, ~20 ms each) and
in one bounded real-time run; lockstep accounts them without sleeping."""
from __future__ import annotations

import json
import math

import pytest
from mcap.reader import make_reader

from plant_rt import load_profile

from hil.cli.main import main as hil_main
from hil.cli.probe import probe
from hil.links import adapters
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from tests.fake_board import FakeBoard
from tests.fake_sysfs import add_tty

SAMPLES = 6


def _check_structure(summary: dict, samples: int = SAMPLES) -> None:
    assert summary["samples_sent"] == samples and summary["answered"] == samples
    assert summary["missing"] == 0
    rtt = summary["round_trip_us"]
    assert set(rtt) == {"min", "p50", "p90", "p99", "max", "mean"}
    assert all(math.isfinite(v) and v > 0 for v in rtt.values())
    assert rtt["min"] <= rtt["p50"] <= rtt["p90"] <= rtt["p99"] <= rtt["max"]
    assert summary["lockstep_rate_hz"] == pytest.approx(1e6 / rtt["mean"])
    assert summary["shortest_realtime_period_us"] == rtt["p99"]


def test_probe_over_stub_pty_reports_the_ptys_own_round_trip(capsys):
    assert hil_main(["probe", "stub-pty", "--samples", str(SAMPLES), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    _check_structure(summary)
    assert summary["board"].startswith("hil-stub")
    assert summary["adapter"]["kind"] == "pty" and not summary["poor"] and not summary["fix"]
    assert summary["expected"] == {}            # no adapter: no model to expect


@pytest.mark.parametrize("wire, poor, cause, rate_hz", [
    ("ftdi-16ms", True, "latency timer 16 ms", 1000 / 17),
    ("ftdi-1ms", False, "latency timer 1 ms", 1000 / 2),
])
def test_probe_through_the_wire_model_names_cause_and_fix(wire, poor, cause, rate_hz):
    report = probe(f"stub-pty?wire={wire}", samples=SAMPLES)
    summary = report.summary()
    _check_structure(summary)
    assert summary["adapter"]["modelled.wire_model"] == wire
    assert summary["poor"] is poor and cause in summary["cause"]
    assert ("latency_timer" in summary["fix"]) is poor
    assert summary["expected"]["lockstep_rate_hz"] == pytest.approx(rate_hz)


@pytest.mark.parametrize("wire, held_us", [("ftdi-16ms", 16_000), ("ftdi-1ms", 1_000)])
def test_probe_holds_a_gates_only_answer_for_the_timer(wire, held_us):
    # a board answering GATES alone (13 B: no full packet) through the model: no answer can come
    # back before the timer has run (a bound the model guarantees whatever the load; nothing is
    # asserted on how much later it came). The stub's TELEMETRY may fill a packet: not here.
    with FakeBoard() as board:
        summary = probe(f"{board.url}?wire={wire}", samples=3).summary()
    _check_structure(summary, samples=3)
    assert summary["round_trip_us"]["min"] >= held_us


@pytest.fixture
def board_as(tmp_path, monkeypatch):
    """A fake board on a pty, reached through /dev-like link NAME that the fake sysfs tree
    describes as DRIVER."""
    boards = []

    def make(name: str, driver: str, **tty) -> str:
        board = FakeBoard().__enter__()
        boards.append(board)
        sysfs = tmp_path / "sys"
        add_tty(sysfs, name, driver, **tty)
        (tmp_path / "dev").mkdir(exist_ok=True)
        (tmp_path / "dev" / name).symlink_to(board.slave_path)
        monkeypatch.setattr(adapters, "SYSFS_ROOT", sysfs)
        return f"serial:{tmp_path / 'dev' / name}"

    yield make
    for board in boards:
        board.__exit__(None, None, None)


@pytest.mark.parametrize("name, driver, tty, poor, cause, fix", [
    ("ttyUSB0", "ftdi_sio", {"latency_timer_ms": 16}, True, "latency timer 16 ms",
     "/sys/bus/usb-serial/devices/ttyUSB0/latency_timer"),
    ("ttyUSB0", "ftdi_sio", {"latency_timer_ms": 1}, False, "latency timer 1 ms", ""),
    ("ttyACM0", "cdc_acm", {"speed": "480"}, False, "125 us high-speed microframes", ""),
    ("ttyUSB1", "cp210x", {}, False, "CP210x", "FTDI"),
    ("ttyUSB2", "ch341", {}, False, "CH340/CH341", "FTDI"),
])
def test_probe_names_each_drivers_cause_and_fix(board_as, name, driver, tty, poor, cause, fix):
    spec = board_as(name, driver, **tty)
    summary = probe(spec, samples=SAMPLES).summary()
    _check_structure(summary)
    assert summary["adapter"]["kind"] == driver
    assert summary["poor"] is poor and cause in summary["cause"]
    assert (fix in summary["fix"]) if fix else summary["fix"] == ""


def test_probe_sets_the_latency_timer_when_asked(board_as, tmp_path, capsys):
    spec = board_as("ttyUSB0", "ftdi_sio", latency_timer_ms=16)
    assert hil_main(["probe", spec, "--samples", "3", "--set-latency-timer", "1",
                     "--sysfs-root", str(tmp_path / "sys")]) == 0
    captured = capsys.readouterr()
    assert "latency timer now 1 ms" in captured.err and "latency timer 1 ms" in captured.out
    timer = next((tmp_path / "sys").rglob("latency_timer"))
    assert timer.read_text().strip() == "1"


def test_probe_of_a_silent_board_ends_with_its_error():
    from hil.cli.probe import ProbeError

    with FakeBoard(answer_hello=False) as board, pytest.raises(ProbeError, match="no HELLO"):
        probe(board.url, samples=2, hello_wait_s=0.05)


# ---------------------------------------------------------------- sessions

def _metadata(path) -> dict:
    with open(path, "rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


# By hand, per period: SAMPLE 19 B out; back GATES 13 B from the fake board, GATES +
# TELEMETRY 77 B from the stub, which fill a 62-byte FTDI packet that goes without the timer.
#   fake board, 16 ms: 19 + 13 B at 2 Mbaud = 160 us, + 16 ms = 16.16 ms -> next frame: 17 ms
#   fake board, 1 ms: 1.16 ms -> 2 ms
#   stub, 16 ms or 1 ms: 19 + 62 B at 2 Mbaud = 405 us -> 1 ms
#   stub at 115200 baud: (19 + 62) B * 10 / 115200 = 7.03 ms -> 8 ms
@pytest.mark.parametrize("board, wire, warns, period_s", [
    ("fake", "ftdi-16ms", True, 17e-3), ("fake", "ftdi-1ms", False, 2e-3),
    ("stub", "ftdi-16ms", True, 1e-3), ("stub", "ftdi-1ms", False, 1e-3),
    ("stub", "ftdi-16ms@115200", True, 8e-3)])
def test_session_through_the_model_warns_and_accounts_without_sleeping(tmp_path, capsys, board,
                                                                       wire, warns, period_s):
    log = tmp_path / "run.mcap"
    with FakeBoard() as fake:
        link = f"{fake.url}?wire={wire}" if board == "fake" else f"stub-pty?wire={wire}"
        _run_through(link, log, period_s, wire)
    err = capsys.readouterr().err
    assert err.count("hil: warning:") == (1 if warns else 0)
    if warns:
        assert "latency timer 16 ms" in err and "latency_timer" in err
    meta = _metadata(log)["adapter"]
    assert meta["modelled.wire_model"] == wire.partition("@")[0]
    assert meta["modelled.driver"] == "ftdi_sio"


def _run_through(link, log, period_s, wire):
    with BenchSession(load_profile(), SessionConfig(link=link, log_path=log)) as session:
        session.run_periods(40)
        counters = session.link_counters()
        assert session.tap._pump is None           # lockstep: nothing held for real
    assert counters["wire_model"] == wire.partition("@")[0]
    assert counters["wire_periods"] == 39
    assert counters["wire_modelled_s"] == pytest.approx(39 * period_s)
    assert 0 < counters["wire_projected_rate_hz"] < 1 / period_s


def test_session_on_a_serial_port_warns_from_sysfs(board_as, tmp_path, capsys):
    spec = board_as("ttyUSB0", "ftdi_sio", latency_timer_ms=16)
    log = tmp_path / "run.mcap"
    with BenchSession(load_profile(), SessionConfig(link=spec, log_path=log)) as session:
        session.run_periods(3)
    err = capsys.readouterr().err
    assert err.count("latency timer 16 ms") == 1 and "ttyUSB0/latency_timer" in err
    meta = _metadata(log)["adapter"]
    assert (meta["kind"], meta["driver"], meta["latency_timer_ms"]) == ("ftdi_sio", "ftdi_sio",
                                                                         "16")


def test_realtime_through_the_model_holds_frames_on_its_own_thread():
    # bounded (5 periods of 20 ms) and not asserted on timing: the frames go through the pump
    config = SessionConfig(link="stub-pty?wire=ftdi-1ms", mode="realtime",
                           realtime_period_s=0.02)
    with BenchSession(load_profile(), config) as session:
        assert session.run_periods(5) == 5
        assert session.tap._pump is not None and session.tap.wire_stats()["wire_mode"] == "held"
        assert session.rt_stats["periods"] == 5


def test_wire_model_on_a_can_link_is_refused():
    with pytest.raises(SessionError, match="wire=ftdi-1ms needs a byte link"):
        with BenchSession(load_profile(), SessionConfig(link="stub-can?wire=ftdi-1ms")):
            pass


# ---------------------------------------------------------------- the pump, alone

class _EchoLink:
    """A byte link in this process: each frame it is sent is answered by GATES of period 7;
    ``fail`` makes its next read raise as a broken line does."""

    url = "echo"

    def __init__(self):
        from protocol.codec import FrameEncoder
        from protocol.messages import Gates

        self.sent: list[bytes] = []
        self._answer = FrameEncoder().encode(Gates(7, 0x21))
        self._pending = b""
        self.fail = False
        self.counters = {}

    def send_bytes(self, data):
        self.sent.append(bytes(data))
        self._pending += self._answer

    def read_bytes(self, timeout_s=0.0):
        from protocol.links import LinkError

        if self.fail:
            raise LinkError("echo: the other end closed the line")
        data, self._pending = self._pending, b""
        return data

    def close(self):
        pass


def test_pump_holds_frames_and_hands_over_the_links_error():
    from protocol.links import LinkError
    from protocol.messages import Gates, Shutdown

    from hil.links.wire import parse_wire
    from hil.session.link_tap import LinkTap

    link = _EchoLink()
    tap = LinkTap(link, wire=parse_wire("fixed-2ms"), delay_frames=True)
    tap.send(Shutdown())                   # held 2 ms by the pump (the probe's test shows the
    answer = tap.recv(2.0)                 # holding); a bounded wait, its length not asserted
    assert answer == Gates(7, 0x21) and len(link.sent) == 1
    assert tap.counters["wire_mode"] == "held"
    link.fail = True
    tap.send(Shutdown())
    with pytest.raises(LinkError, match="other end closed"):
        for _ in range(100):               # the error arrives with the thread's next read
            tap.recv(0.05)
    tap.close()
