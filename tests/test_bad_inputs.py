"""Bad input end to end through the `hil` command line: each case exits 2 with a message that
names what was wrong, and nothing is lost (a run that started leaves its result.json and a
readable MCAP log; a refused plan leaves no half-written output)."""
from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from protocol.links import open_link
from protocol.messages import PROTOCOL_VERSION

from hil.cli.main import main as hil_main
from hil.logs.reader import read_log
from tests.fake_board import FakeBoard

REPO = Path(__file__).resolve().parent.parent
HIL = [sys.executable, "-m", "hil.cli.main"]

TINY = """name: tiny
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 500}
  - run: {duration_s: %(run_s)s}
  - check: {name: spins, kind: final_value, signal: plant.speed_rpm, limits: {low: 1, unit: rpm}}
"""


def _plan(tmp_path: Path, run_s: float = 0.05, text: str | None = None, name: str = "plan.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text if text is not None else TINY % {"run_s": run_s})
    return path


def _run(tmp_path: Path, *args: str, plan: Path | None = None) -> tuple[int, Path]:
    out = tmp_path / "out"
    code = hil_main(["run", str(plan or _plan(tmp_path)), "--out", str(out), "--no-progress", *args])
    return code, out


def _errored(out: Path, capsys, *needles: str, plan: str = "tiny") -> dict:
    """The run ended ERROR with a reason holding every needle, its result.json says so, and
    its log is a readable MCAP file."""
    captured = capsys.readouterr()
    record = json.loads((out / plan / "result.json").read_text())
    assert record["outcome"] == "ERROR"
    for needle in needles:
        assert needle in record["reason"], record["reason"]
        assert needle in captured.out + captured.err
    log = read_log(out / plan / "log.mcap")
    assert log.complete
    return record


# --------------------------------------------------------------------------- plans
def test_malformed_plan(tmp_path, capsys):
    bad = _plan(tmp_path, text="name: bad\nsteps:\n  - run: {duration_s: 0.1\n")
    code, out = _run(tmp_path, plan=bad)
    assert code == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "YAML" in err
    assert not out.exists()                        # validated before anything was written


def test_unknown_key_in_a_plan(tmp_path, capsys):
    bad = _plan(tmp_path, text="name: bad\nsteps:\n  - run: {duration_s: 0.1}\n"
                               "  - fault: {name: open_phase, phase: a, durration_s: 0.1}\n")
    code, out = _run(tmp_path, plan=bad)
    assert code == 2
    err = capsys.readouterr().err
    assert f"{bad}:4" in err and "durration_s" in err
    assert not out.exists()


def test_plan_naming_a_missing_signal(tmp_path, capsys):
    bad = _plan(tmp_path, text=TINY.replace("plant.speed_rpm", "plant.sped_rpm") % {"run_s": 0.05})
    code, out = _run(tmp_path, plan=bad)
    assert code == 2
    err = capsys.readouterr().err
    assert f"{bad}:5" in err and "plant.sped_rpm" in err and "plant.speed_rpm" in err
    assert not out.exists()


def test_one_bad_plan_stops_the_whole_batch_before_it_runs(tmp_path, capsys):
    good = _plan(tmp_path, name="good.yaml")
    bad = _plan(tmp_path, text="name: x\nsteps: [{run: {}}]\n", name="bad.yaml")
    code = hil_main(["run", str(good), str(bad), "--out", str(tmp_path / "out"), "--no-progress"])
    assert code == 2 and "duration_s" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- links
def test_unknown_serial_port(tmp_path, capsys):
    code, out = _run(tmp_path, "--link", "serial:/dev/ttyHIL404")
    assert code == 2
    _errored(out, capsys, "serial port '/dev/ttyHIL404'", "no such port")


def test_busy_serial_port(tmp_path, capsys):
    master, slave = os.openpty()
    path = os.ttyname(slave)
    try:
        with open_link(f"serial:{path}"):            # someone else holds the port
            code, out = _run(tmp_path, "--link", f"serial:{path}")
    finally:
        os.close(master)
        os.close(slave)
    assert code == 2
    _errored(out, capsys, f"serial port '{path}'", "busy")


@pytest.mark.parametrize("link, needle", [
    ("can:frobcan:x", "CAN interface 'frobcan' channel 'x': interface not available"),
    ("can:pcan:PCAN_USBBUS1", "CAN interface 'pcan' channel 'PCAN_USBBUS1'"),   # no vendor driver
])
def test_can_interface_not_installed(tmp_path, capsys, link, needle):
    code, out = _run(tmp_path, "--link", link)
    assert code == 2
    _errored(out, capsys, needle)


def test_board_with_the_wrong_protocol_version(tmp_path, capsys):
    with FakeBoard(proto_version=PROTOCOL_VERSION + 1) as board:
        code, out = _run(tmp_path, "--link", board.url)
    assert code == 2
    _errored(out, capsys, f"protocol version {PROTOCOL_VERSION + 1}",
             f"bench speaks version {PROTOCOL_VERSION}")


def test_board_that_never_answers_hello(tmp_path, capsys):
    with FakeBoard(answer_hello=False) as board:
        code, out = _run(tmp_path, "--link", board.url)
    assert code == 2
    _errored(out, capsys, "no HELLO from the board", board.url)


def test_board_that_dies_mid_run(tmp_path, capsys):
    """The board answers 300 SAMPLEs and hangs up: ERROR at that period, the plant safe-stated,
    and the log holds every period up to the death."""
    with FakeBoard(die_after_samples=300) as board:
        code, out = _run(tmp_path, "--link", board.url)
    assert code == 2
    record = _errored(out, capsys, "link failed at period 300", "closed the line")
    truth = read_log(out / "tiny" / "log.mcap")["/plant/truth"]
    assert len(truth) == 301
    assert record["checks"][0]["outcome"] == "SKIPPED"


def test_cable_unplugged_past_the_watchdog(tmp_path, capsys):
    """A plan that unplugs the cable for 20 ms: the 20-period watchdog safe-states the plant."""
    plan = _plan(tmp_path, text="""name: unplug
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 500}
  - run: {duration_s: 0.02}
  - fault: {name: link_unplug, duration_s: 0.02}
  - run: {duration_s: 0.05}
""")
    code, out = _run(tmp_path, plan=plan)
    assert code == 2
    record = _errored(out, capsys, "watchdog: no GATES/DUTY for 20 consecutive periods (periods 400..419",
                     "at period 419",
                      plan="unplug")
    assert record["extra"]["faults_injected"][0]["name"] == "link_unplug"
    # 20 periods of 4 SAMPLEs (SPEC 2.8.1 resends), then the SHUTDOWN of the teardown: the cable is still out
    assert record["extra"]["link_counters"]["out_unplugged"] == 20 * 4 + 1


# --------------------------------------------------------------------------- output
def test_out_directory_that_cannot_be_created(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    for out in (blocker / "out", Path("/sys/hil-bench-out")):      # ENOTDIR; EPERM even for root
        code = hil_main(["run", str(_plan(tmp_path)), "--out", str(out), "--no-progress"])
        assert code == 2
        err = capsys.readouterr().err
        assert f"--out directory '{out}' is not writable" in err
    assert blocker.read_text() == "not a directory"


def test_log_on_a_full_disk_from_the_start(tmp_path, capsys):
    """log.mcap lands on a device with no space (/dev/full): the run stops before the board
    is driven, says so, and the reports beside it are still written."""
    out = tmp_path / "out"
    (out / "tiny").mkdir(parents=True)
    (out / "tiny" / "log.mcap").symlink_to("/dev/full")
    code = hil_main(["run", str(_plan(tmp_path)), "--out", str(out), "--no-progress"])
    assert code == 2
    captured = capsys.readouterr()
    assert "No space left on device" in captured.out
    record = json.loads((out / "tiny" / "result.json").read_text())
    assert record["outcome"] == "ERROR" and "log.mcap" in record["reason"]


def _file_size_limit(limit: int):
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # fail the write (EFBIG), do not kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def test_disk_filling_up_mid_run_keeps_the_log_readable(tmp_path):
    """The log cannot grow past 2 MB (a disk that fills up, by RLIMIT_FSIZE): the run stops with
    ERROR at that moment, and the log reads up to its last finished chunk."""
    out = tmp_path / "out"
    proc = subprocess.run([*HIL, "run", str(_plan(tmp_path, run_s=1.0)), "--out", str(out),
                           "--no-progress"], cwd=REPO, capture_output=True, text=True,
                          preexec_fn=_file_size_limit(2_000_000), timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "File too large" in proc.stdout and "log.mcap" in proc.stdout
    record = json.loads((out / "tiny" / "result.json").read_text())
    assert record["outcome"] == "ERROR" and "File too large" in record["reason"]
    log = read_log(out / "tiny" / "log.mcap")
    assert not log.complete and "did not finish" in log.note
    truth = log["/plant/truth"]
    assert len(truth) > 2000
    assert truth.log_time_ns[-1] / 1e9 < record["sim_duration_s"] <= 1.0


# --------------------------------------------------------------------------- hil log
@pytest.fixture(scope="module")
def run_log(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("log")
    code = hil_main(["run", str(_plan(tmp, run_s=0.2)), "--out", str(tmp / "out"), "--no-progress"])
    assert code == 0
    return tmp / "out" / "tiny" / "log.mcap"


def test_truncated_log_is_read_up_to_its_last_finished_chunk(run_log, tmp_path, capsys):
    data = run_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert hil_main(["log", "info", str(cut)]) == 0
    text = capsys.readouterr().out
    assert "UNFINISHED" in text and "last finished chunk" in text
    csv = tmp_path / "truth.csv"
    assert hil_main(["log", "export", str(cut), "/plant/truth", "--out", str(csv)]) == 0
    rows = csv.read_text().splitlines()
    full = len(read_log(run_log)["/plant/truth"])
    assert full // 4 < len(rows) - 1 < full


def test_foreign_file_given_to_hil_log(tmp_path, capsys):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(os.urandom(4096))
    for action in (["info"], ["export", "/plant/truth", "--out", str(tmp_path / "x.csv")]):
        assert hil_main(["log", action[0], str(junk), *action[1:]]) == 2
        err = capsys.readouterr().err
        assert str(junk) in err and "not an MCAP file" in err


def _records(data: bytes):
    """(offset, opcode, body offset, body length) of the top-level MCAP records."""
    pos = 8                                                # after the magic
    while pos + 9 <= len(data):
        op = data[pos]
        length = int.from_bytes(data[pos + 1:pos + 9], "little")
        yield pos, op, pos + 9, length
        pos += 9 + length


def test_bit_rot_in_a_chunk_given_to_hil_log(run_log, tmp_path, capsys):
    data = bytearray(run_log.read_bytes())
    chunk = next(body for _, op, body, _ in _records(data) if op == 0x06)
    data[chunk + 60] ^= 0x5A                               # inside the first chunk's data
    bad = tmp_path / "rotten.mcap"
    bad.write_bytes(bytes(data))
    assert hil_main(["log", "info", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "corrupted chunk at byte" in err


def test_damaged_channel_record_given_to_hil_log(run_log, tmp_path, capsys):
    data = bytearray(run_log.read_bytes())
    channel = next(body for _, op, body, _ in _records(data) if op == 0x04)
    data[channel + 4:channel + 8] = (0xFFFFFF00).to_bytes(4, "little")   # topic length: huge
    bad = tmp_path / "damaged.mcap"
    bad.write_bytes(bytes(data))
    assert hil_main(["log", "info", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err
