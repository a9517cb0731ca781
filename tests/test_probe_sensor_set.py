"""`hil probe` against sensor-set boards (SPEC 6.13): a board advertising SENSOR_SET has its set
read after HELLO, checked, reported, and gets SAMPLE_SENSORS with that set's fields (a motor at
rest: mid-scale currents, Hall word 001); a bad SENSOR_SET answer is refused naming the
parameter and its value before any sample goes; a SAMPLE board is probed as before (no
PARAM_GET, SAMPLEs only). The example Hall six-step board (a plain SAMPLE trips it FAULT 5
PROTOCOL once it runs) is probed over exec: with its own set; a FAULT in the train is reported.
Timings are never asserted."""
from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import pytest

from protocol.messages import (CAP_GATES, CAP_SENSOR_SET, SENSOR_CURRENT_A, SENSOR_CURRENT_B,
                               SENSOR_CURRENT_C, SENSOR_HALL, SENSOR_VDC, ParamGet, Sample,
                               SampleSensors)

from hil.cli.main import main as hil_main
from hil.cli.probe import ProbeError, format_report, probe
from tests.fake_board import FakeBoard

SAMPLES = 4
HALL_SET = SENSOR_CURRENT_A | SENSOR_CURRENT_B | SENSOR_CURRENT_C | SENSOR_VDC | SENSOR_HALL
HALL_SET_NAMES = ["current_a", "current_b", "current_c", "vdc", "hall"]
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "hall_sixstep"


def _stimuli(board: FakeBoard) -> list:
    return [m for m in board.received if isinstance(m, (Sample, SampleSensors))]


def test_probe_reads_the_set_and_sends_sample_sensors(capsys):
    with FakeBoard(capabilities=CAP_GATES | CAP_SENSOR_SET, sensor_set=float(HALL_SET)) as board:
        assert hil_main(["probe", board.url, "--samples", str(SAMPLES), "--json"]) == 0
        summary = json.loads(capsys.readouterr().out)
        stimuli = _stimuli(board)
        asked = [m for m in board.received if isinstance(m, ParamGet)]
    assert summary["sensor_set"] == {"mask": HALL_SET, "sensors": HALL_SET_NAMES}
    assert summary["answered"] == summary["samples_sent"] == SAMPLES and summary["faults"] == []
    assert [m.id for m in asked] == [8]
    # by hand from SPEC 6.13/9.8 and 1.1: the set's five fields, a motor at rest at theta_e = 0
    assert stimuli == [SampleSensors(k, HALL_SET, 0, adc_ia=2048, adc_ib=2048, adc_ic=2048,
                                     adc_vdc=2048, hall=0b001) for k in range(SAMPLES)]


def test_probe_text_names_the_sensor_set(capsys):
    with FakeBoard(capabilities=CAP_GATES | CAP_SENSOR_SET, sensor_set=float(HALL_SET)) as board:
        assert hil_main(["probe", board.url, "--samples", "2"]) == 0
    out = capsys.readouterr().out
    assert "2 of 2 SAMPLE_SENSORS answered" in out
    assert "sensors   current_a, current_b, current_c, vdc, hall (SENSOR_SET 0x002f" in out


@pytest.mark.parametrize("value, says", [
    (math.nan, "non-finite value (nan)"),
    (2.5, "with 2.5, not a 16-bit integer mask"),
    (-1.0, "with -1.0, not a 16-bit integer mask"),
    (float(HALL_SET | 0x0400), "= 0x042f, with reserved bits 0x0400"),
])
def test_probe_refuses_a_bad_sensor_set_before_sampling(value, says):
    with FakeBoard(capabilities=CAP_GATES | CAP_SENSOR_SET, sensor_set=value) as board:
        with pytest.raises(ProbeError, match=r"parameter sensor_set \(id 8\)") as refused:
            probe(board.url, samples=SAMPLES)
        stimuli = _stimuli(board)
    assert says in str(refused.value) and board.url.split(":", 1)[1] in str(refused.value)
    assert stimuli == []


def test_probe_refuses_a_board_that_refuses_the_param_get():
    # known=set(): every parameter id is answered status 1 UNKNOWN
    with FakeBoard(capabilities=CAP_GATES | CAP_SENSOR_SET, known=set()) as board:
        with pytest.raises(ProbeError, match=r"refused PARAM_GET of parameter sensor_set "
                                             r"\(id 8, status 1\)"):
            probe(board.url, samples=SAMPLES)
        assert _stimuli(board) == []


def test_probe_of_a_sample_board_is_as_before(capsys):
    # a SAMPLE board (no SENSOR_SET capability) is not asked, whatever it would answer
    with FakeBoard(capabilities=CAP_GATES, sensor_set=float(HALL_SET)) as board:
        assert hil_main(["probe", board.url, "--samples", str(SAMPLES)]) == 0
        out = capsys.readouterr().out
        stimuli = _stimuli(board)
        asked = [m for m in board.received if isinstance(m, ParamGet)]
    assert asked == []
    assert stimuli == [Sample(k, 2048, 2048, 2048, 0, 0) for k in range(SAMPLES)]
    assert f"{SAMPLES} of {SAMPLES} SAMPLEs answered" in out and "sensors" not in out
    summary = probe("stub-pty", samples=2).summary()
    assert summary["sensor_set"] is None and summary["answered"] == 2


def test_probe_of_the_hall_sixstep_example_over_exec(capsys):
    subprocess.run(["make", "-s", "-C", str(EXAMPLE), "host"], check=True, capture_output=True,
                   timeout=300)
    link = f"exec:{EXAMPLE / 'build' / 'hall_sixstep'}"
    assert hil_main(["probe", link, "--samples", str(SAMPLES), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["board"].startswith("hall_sixstep")
    # its board file's sensors: (examples/hall_sixstep/board.yaml)
    assert summary["sensor_set"] == {"mask": HALL_SET, "sensors": HALL_SET_NAMES}
    assert summary["answered"] == summary["samples_sent"] == SAMPLES and summary["faults"] == []


def test_probe_reports_a_fault_the_train_trips():
    # a board that trips FAULT 5 PROTOCOL on each SAMPLE and still answers it (as the example
    # Hall board does on a plain SAMPLE): the round trips alone would look healthy
    from protocol.messages import Fault, Gates

    def trip(sample, enc):
        return enc.encode(Fault(sample.period, 5, 0.0)) + enc.encode(Gates(sample.period, 0))

    with FakeBoard(capabilities=CAP_GATES, on_sample=trip) as board:
        summary = probe(board.url, samples=2).summary()
    assert summary["answered"] == 2
    assert summary["faults"] == [{"period": 0, "code": 5, "name": "PROTOCOL", "value": 0.0},
                                 {"period": 1, "code": 5, "name": "PROTOCOL", "value": 0.0}]
    assert "board     FAULT 5 PROTOCOL at period 1, value 0" in format_report(summary)
