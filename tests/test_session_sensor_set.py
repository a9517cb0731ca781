"""Sensor-set boards (SPEC 6.13) through the real links, codec and session: after HELLO the bench
reads SENSOR_SET, checks it, and sends SAMPLE_SENSORS with exactly the board's set every period.

The reference for every value a board gets is a plant of the same profile and seed stepped
directly the way the session steps it (the fake boards answer GATES 0): its sensor_frame() of
period k, masked to the set by hand, must be what the board received for period k.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from configfile.source import ConfigError
from plant_rt import Plant, load_profile
from protocol.messages import (CAP_GATES, CAP_SENSOR_SET, SENSOR_SET_NAMES, Gates, ParamGet,
                               Sample, SampleSensors)

from hil.boards import load_board
from hil.boards.sensor_fields import ALL_SENSOR_FIELDS, SENSOR_FIELDS_OF
from hil.faults.injector import injector
from hil.links.wire import sample_sensors_can_dlc, sample_sensors_payload_bytes, serial_frame_bytes
from hil.plans.format import parse_plan
from hil.run.runner import check_plan_board
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from hil.session.policy import SessionPolicy
from tests.fake_board import FakeBoard
from tests.sensor_board import CanSensorBoard, exec_url, read_record

FAST = SessionPolicy(hello_wait_s=0.5, param_wait_s=0.5, answer_wait_min_s=0.5, watchdog_s=5.0)
PERIODS = 240
# coasting at 100 rad/s mechanical: the Hall word and the resolver move within the run
OVERRIDES = {"initial": {"speed_rad_s": 100.0}}
SENSOR_CAPS = CAP_GATES | CAP_SENSOR_SET
HALL_SET = ("current_a", "current_c", "hall", "bemf_comparators", "temperature")


def mask_of(names) -> int:
    return sum(SENSOR_SET_NAMES[n] for n in names)


ALL_SENSORS = mask_of(SENSOR_SET_NAMES)


def board_file(tmp_path: Path, sensors=None, name: str = "sensor board") -> Path:
    path = tmp_path / "board.yaml"
    text = f"name: {name}\ncapabilities: [GATES]\n"
    if sensors is not None:
        text += f"sensors: [{', '.join(sensors)}]\n"
    path.write_text(text)
    return path


def reference_frames(periods: int, mask: int) -> list[dict]:
    """Period k's SAMPLE_SENSORS fields as the set carries them: the reference plant's frame,
    the set's fields, every other field 0 (SPEC 6.13: absent fields decode as 0)."""
    plant = Plant(load_profile(overrides=OVERRIDES), seed=0)
    carried = {f for name, bit in SENSOR_SET_NAMES.items() if mask & bit
               for f in SENSOR_FIELDS_OF[name]}
    out = []
    for _ in range(periods):
        frame = plant.sensor_frame()
        row = {f: (getattr(frame, f) if f in carried else 0) for f in ALL_SENSOR_FIELDS}
        row.update(period=frame.period, sensor_set=mask, status=frame.status)
        out.append(row)
        plant.step(0)
    return out


def received_rows(messages) -> dict[int, dict]:
    """period -> the fields of the SAMPLE_SENSORS the board got for it (a resend must be the
    same message: asserted)."""
    rows: dict[int, dict] = {}
    for msg in messages:
        row = {f: getattr(msg, f) for f in (*ALL_SENSOR_FIELDS, "period", "sensor_set", "status")}
        if msg.period in rows:
            assert rows[msg.period] == row, "a resend differs from the first SAMPLE_SENSORS"
        rows[msg.period] = row
    return rows


def session(link: str, board=None, policy: SessionPolicy = FAST, **kw) -> BenchSession:
    config = SessionConfig(link=link, policy=policy, hold_cpu_latency=False,
                           board=load_board(board) if board is not None else None, **kw)
    return BenchSession(load_profile(overrides=OVERRIDES), config)


def assert_frames_match(rows: dict[int, dict], mask: int, periods: int) -> None:
    expected = reference_frames(periods, mask)
    assert sorted(rows) == list(range(periods))
    for k in range(periods):
        assert rows[k] == expected[k], f"period {k}"


# --------------------------------------------------------------------------- serial (pty)
def test_board_gets_sample_sensors_with_exactly_its_set_and_the_plants_values(tmp_path):
    mask = mask_of(HALL_SET)
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask) as board:
        with session(board.url, board_file(tmp_path, HALL_SET)) as s:
            s.run_periods(PERIODS)
            assert s.sensor_set == mask
            signals = s.recorder.arrays()
        got = [m for m in board.received if isinstance(m, (Sample, SampleSensors))]
    assert got and all(type(m) is SampleSensors for m in got)       # never a SAMPLE
    rows = received_rows(got)
    assert_frames_match(rows, mask, PERIODS)
    halls = {rows[k]["hall"] for k in rows}
    assert len(halls) >= 2                  # the rotor turned through Hall edges
    # logged per period under sample.<field>, only the set's fields
    assert sorted(n for n in signals if n.startswith("sample.")) == \
        sorted(f"sample.{f}" for n in HALL_SET for f in SENSOR_FIELDS_OF[n])
    assert list(signals["sample.hall"][1]) == [rows[k]["hall"] for k in range(PERIODS)]
    assert list(signals["sample.adc_ic"][1]) == [rows[k]["adc_ic"] for k in range(PERIODS)]
    assert "plant.winding_temperature_degc" in signals
    # SPEC 8.1: a sensor's scaling is not pushed unasked (it is the board file's settings)
    assert not {14, 15, 16, 17, 18} & set(board.params)


def test_a_resend_is_the_same_sample_sensors(tmp_path):
    """SPEC 2.8.1: the board leaves period 5's first SAMPLE_SENSORS unanswered; the bench
    resends that very message (not a SAMPLE, not a new frame)."""
    mask = mask_of(HALL_SET)
    ignored = []

    def answer(msg, encoder):
        if msg.period == 5 and not ignored:
            ignored.append(msg)
            return b""
        return encoder.encode(Gates(period=msg.period, gates=0))

    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask, on_sample=answer) as board:
        with session(board.url, board_file(tmp_path, HALL_SET)) as s:
            s.run_periods(10)
            assert s.resent_samples >= 1 and s.missed_answers == 0
        got = [m for m in board.received if isinstance(m, (Sample, SampleSensors))]
    fifth = [m for m in got if m.period == 5]
    assert len(fifth) >= 2 and all(m == fifth[0] and type(m) is SampleSensors for m in fifth)
    assert_frames_match(received_rows(got), mask, 10)


def test_board_without_the_capability_still_gets_todays_sample():
    """A GATES-only board: SAMPLE, equal field for field to the reference plant's sample(),
    no SENSOR_SET read, nothing logged under sample.*."""
    with FakeBoard(capabilities=CAP_GATES) as board:
        with session(board.url) as s:
            s.run_periods(PERIODS)
            assert s.sensor_set is None
            signals = s.recorder.arrays()
        got = [m for m in board.received if isinstance(m, (Sample, SampleSensors))]
        asked = [m for m in board.received if isinstance(m, ParamGet) and m.id == 8]
    assert not asked and got and all(type(m) is Sample for m in got)
    plant = Plant(load_profile(overrides=OVERRIDES), seed=0)
    expected = []
    for _ in range(PERIODS):
        smp = plant.sample()
        expected.append(Sample(smp.period, smp.adc_i1, smp.adc_i2, smp.adc_vdc, smp.encoder,
                               smp.status))
        plant.step(0)
    assert {m.period: m for m in got} == {m.period: m for m in expected}
    assert not [n for n in signals if n.startswith("sample.")]
    assert "plant.winding_temperature_degc" not in signals


THERMAL = {**OVERRIDES, "thermal": {"enabled": True, "thermal_capacitance_j_per_k": 0.5}}


def gates_for(k: int) -> int:
    """A then B low for 20 periods (the current rises through A-B), then all off."""
    return 0x09 if k < 20 else 0


def test_sample_board_on_a_thermal_profile_logs_the_winding_temperature():
    """A SAMPLE board on a profile whose thermal model is on: still SAMPLE, and the winding
    temperature is logged every period, equal to the reference plant's (heating while the
    current flows)."""
    def answer(msg, encoder):
        return encoder.encode(Gates(period=msg.period, gates=gates_for(msg.period)))

    with FakeBoard(capabilities=CAP_GATES, on_sample=answer) as board:
        config = SessionConfig(link=board.url, policy=FAST, hold_cpu_latency=False)
        with BenchSession(load_profile(overrides=THERMAL), config) as s:
            s.run_periods(60)
            signals = s.recorder.arrays()
        got = [m for m in board.received if isinstance(m, (Sample, SampleSensors))]
    assert got and all(type(m) is Sample for m in got)
    plant = Plant(load_profile(overrides=THERMAL), seed=0)
    expected = []
    for k in range(60):
        plant.sample()
        expected.append(plant.winding_temperature_degc)
        plant.step(gates_for(k))
    t, recorded, unit = signals["plant.winding_temperature_degc"]
    assert list(recorded) == expected and unit == "degC"
    assert recorded[-1] > recorded[0] + 1e-3            # it heated
    assert not [n for n in signals if n.startswith("sample.")]


def test_board_whose_set_differs_from_its_board_file_is_refused_naming_both(tmp_path):
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask_of(["current_a", "hall"])) as board:
        with pytest.raises(SessionError) as err:
            with session(board.url, board_file(tmp_path, ["current_a", "current_b", "hall"])):
                pass
    text = str(err.value)
    assert "[current_a, hall]" in text and "[current_a, current_b, hall]" in text
    assert "board.yaml" in text


@pytest.mark.parametrize("answer,words", [
    (math.nan, "non-finite"), (math.inf, "non-finite"), (3.5, "not a 16-bit integer"),
    (70000.0, "not a 16-bit integer"), (float(0x0400 | 0x0020), "reserved bits 0x0400")])
def test_a_bad_sensor_set_answer_is_refused_naming_the_parameter(answer, words):
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=answer) as board:
        with pytest.raises(SessionError) as err:
            with session(board.url):
                pass
        assert not [m for m in board.received if isinstance(m, (Sample, SampleSensors))]
    assert "parameter sensor_set" in str(err.value) and words in str(err.value)


def test_board_file_with_sensors_on_a_board_without_the_capability_is_refused(tmp_path):
    with FakeBoard(capabilities=CAP_GATES) as board:
        with pytest.raises(SessionError) as err:
            with session(board.url, board_file(tmp_path, ["hall"])):
                pass
    assert "SENSOR_SET capability" in str(err.value) and "[hall]" in str(err.value)


def test_hall_stuck_fault_shows_in_the_frame_the_board_gets(tmp_path):
    """hall_stuck b at 1 from period 100: bit 1 of every later Hall word is 1, the other bits
    as the reference plant's; before it, the words are the reference's (bit 1 low somewhere)."""
    names = ("hall",)
    mask = mask_of(names)
    fault_at = 100
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask) as board:
        with session(board.url, board_file(tmp_path, names)) as s:
            s.run_periods(fault_at)
            injector(s).inject("hall_stuck", sensor="b", level=1, source="plan")
            s.run_periods(PERIODS - fault_at)
            recorded = s.recorder.arrays()["sample.hall"][1]
        rows = received_rows([m for m in board.received if isinstance(m, SampleSensors)])
    expected = reference_frames(PERIODS, mask)
    hall = [rows[k]["hall"] for k in range(PERIODS)]
    assert hall[:fault_at] == [e["hall"] for e in expected[:fault_at]]
    assert any(not h & 0b010 for h in hall[:fault_at])
    assert hall[fault_at:] == [e["hall"] | 0b010 for e in expected[fault_at:]]
    assert any(not e["hall"] & 0b010 for e in expected[fault_at:])   # the fault changed words
    assert list(recorded) == hall


def test_bemf_comparator_stuck_shows_in_the_frame_the_board_gets(tmp_path):
    """bemf_comparator_stuck c at 1 from period 60, lifted at period 150 (duration_s): bit 2 of
    the comparator word is 1 in between, the reference's elsewhere; the other bits untouched."""
    names = ("terminal_voltages", "bemf_comparators")
    mask = mask_of(names)
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask) as board:
        with session(board.url, board_file(tmp_path, names)) as s:
            s.run_periods(60)
            injector(s).inject("bemf_comparator_stuck", phase="c", level=1,
                               duration_s=90 * s.period_s)
            s.run_periods(PERIODS - 60)
        rows = received_rows([m for m in board.received if isinstance(m, SampleSensors)])
    expected = [e["bemf_comparators"] for e in reference_frames(PERIODS, mask)]
    got = [rows[k]["bemf_comparators"] for k in range(PERIODS)]
    assert got[:60] == expected[:60] and got[150:] == expected[150:]
    assert got[60:150] == [e | 0b100 for e in expected[60:150]]
    assert any(not e & 0b100 for e in expected[60:150])       # the fault changed words


def test_hall_stuck_arguments_are_checked_at_the_boundary():
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask_of(["hall"])) as board:
        with session(board.url) as s:
            with pytest.raises(ValueError, match="fault 'hall_stuck', level"):
                injector(s).inject("hall_stuck", sensor="a", level=2)
            with pytest.raises(ValueError, match="fault 'bemf_comparator_stuck', phase"):
                injector(s).inject("bemf_comparator_stuck", phase="d", level=1)


# --------------------------------------------------------------------------- exec: and CAN
def test_exec_board_gets_every_sensor(tmp_path):
    """Every sensor of SPEC 6.13 to a board in its own process on the exec: link's pty."""
    record = tmp_path / "got.jsonl"
    # a Python process starting on a loaded machine: HELLO may take seconds
    with session(exec_url(tmp_path, ALL_SENSORS, record),
                 policy=SessionPolicy(hello_wait_s=10.0, param_wait_s=2.0,
                                      answer_wait_min_s=2.0, watchdog_s=20.0)) as s:
        s.run_periods(PERIODS)
        assert s.sensor_set == ALL_SENSORS
    got = read_record(record)
    assert got and {g["type"] for g in got} == {"SampleSensors"}
    rows = {}
    for g in got:
        row = {f: g[f] for f in (*ALL_SENSOR_FIELDS, "period", "sensor_set", "status")}
        assert rows.setdefault(g["period"], row) == row
    assert_frames_match(rows, ALL_SENSORS, PERIODS)


LIB_SOURCE = Path(__file__).resolve().parent / "data" / "sensor_board_lib.c"
PROTO_C = Path(__file__).resolve().parents[1] / "protocol" / "c"


def test_lib_board_gets_its_set_through_the_c_codec(tmp_path):
    """A firmware library in this process (lib:) decoding with the reference C codec: the
    session's Python loop sends SAMPLE_SENSORS through the link tap's C encoder."""
    import subprocess

    lib = tmp_path / "libsensorboard.so"
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-shared", "-fPIC",
                    f"-I{PROTO_C}", "-o", str(lib), str(LIB_SOURCE), str(PROTO_C / "hil_proto.c")],
                   check=True)
    names = ("current_b", "vdc", "hall", "terminal_voltages", "bemf_comparators", "resolver")
    mask = mask_of(names)
    record = tmp_path / "got.txt"
    with session(f"lib:{lib}?args=--sensor-set {mask} --record {record}") as s:
        s.run_periods(PERIODS)
        assert s.sensor_set == mask
    lines = [line.split() for line in record.read_text().splitlines()]
    assert lines and {line[0] for line in lines} == {"SampleSensors"}
    rows = {}
    for line in lines:
        row = dict(zip(("period", "sensor_set", "status", *ALL_SENSOR_FIELDS), map(int, line[1:])))
        assert rows.setdefault(row["period"], row) == row
    assert_frames_match(rows, mask, PERIODS)


def test_can_board_gets_its_set_segmented():
    """A set of 25 payload bytes, four CAN frames (SPEC 7.4), over python-can's virtual bus."""
    names = ("current_a", "current_b", "vdc", "encoder", "terminal_voltages", "resolver")
    mask = mask_of(names)
    assert sample_sensors_can_dlc(mask) == (8, 8, 8, 5)
    with CanSensorBoard(mask) as board:
        with session(board.url) as s:
            s.run_periods(PERIODS)
        got = list(board.samples)
    assert got and all(type(m) is SampleSensors for m in got)
    assert_frames_match(received_rows(got), mask, PERIODS)


def test_realtime_sends_sample_sensors_too(tmp_path):
    """The real-time loop: whatever the wall clock did, each SAMPLE_SENSORS the board got is
    the frame of its period (a late answer leaves the gates at 0, as the reference)."""
    mask = mask_of(HALL_SET)
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask) as board:
        # no verdict on the clock here (a loaded machine may lag): no watchdog, no miss budget
        with session(board.url, board_file(tmp_path, HALL_SET), mode="realtime",
                     realtime_period_s=2e-3, realtime_miss_budget=10_000,
                     watchdog_periods=1_000_000, watchdog_s=600.0) as s:
            s.run_periods(60)
        got = [m for m in board.received if isinstance(m, (Sample, SampleSensors))]
    assert got and all(type(m) is SampleSensors for m in got)
    rows = received_rows(got)
    expected = reference_frames(60, mask)
    assert all(rows[k] == expected[k] for k in rows)


# --------------------------------------------------------------------------- sizes
def test_sample_sensors_sizes_follow_the_spec_table():
    """7 + the set's bytes (SPEC 6.13, by hand from its table); CAN: 7 bytes a frame behind
    a header byte; a reserved bit has no size."""
    assert sample_sensors_payload_bytes(0) == 7
    assert sample_sensors_payload_bytes(mask_of(["current_a", "current_b", "vdc", "hall"])) == \
        7 + 2 + 2 + 2 + 1
    assert sample_sensors_payload_bytes(ALL_SENSORS) == 7 + 2 * 5 + 1 + 6 + 1 + 4 + 2 == 31
    assert serial_frame_bytes("SAMPLE_SENSORS", ALL_SENSORS) == 39
    assert sample_sensors_can_dlc(ALL_SENSORS) == (8, 8, 8, 8, 4)
    assert sample_sensors_can_dlc(mask_of(["hall"])) == (8, 2)
    with pytest.raises(ValueError, match="reserved"):
        sample_sensors_payload_bytes(0x0400)
    # a lockstep period through a wire of 250 us each way at 2 Mbaud (10 bits a byte): the
    # 39-byte SAMPLE_SENSORS out (195 us) and the 13-byte GATES back (65 us)
    from hil.links.wire import parse_wire

    wire = parse_wire("fixed-250us")
    assert wire.lockstep_period_s(sensor_set=ALL_SENSORS) == pytest.approx(760e-6)
    assert wire.lockstep_period_s() == pytest.approx(250e-6 + 95e-6 + 65e-6 + 250e-6)


def test_link_tap_carries_the_frame_the_wire_model_sizes(tmp_path):
    """The SAMPLE_SENSORS frames the session's link tap sent are serial_frame_bytes long."""
    mask = mask_of(HALL_SET)
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask) as board:
        with session(board.url, board_file(tmp_path, HALL_SET)) as s:
            s.run_periods(3)
            out, _count = s.tap.take_capture()["out"]
    from protocol.codec import StreamDecoder

    frames = [f + b"\0" for f in out.split(b"\0") if f]
    kinds = [type(StreamDecoder().feed(f)[0]) for f in frames]
    sizes = [len(f) for f, kind in zip(frames, kinds) if kind is SampleSensors]
    assert sizes and set(sizes) == {serial_frame_bytes("SAMPLE_SENSORS", mask)}


# --------------------------------------------------------------------------- board files, plans
def test_board_file_sensors_key(tmp_path):
    board = load_board(board_file(tmp_path, ["current_a", "hall", "terminal_voltages"]))
    assert board.sensors == ("current_a", "hall", "terminal_voltages")
    assert board.sensor_set == 0x0001 | 0x0020 | 0x0040
    assert "terminal_v_per_count" not in board.parameters  # listed under standard if taken
    assert load_board(board_file(tmp_path)).sensor_set == 0
    assert load_board(board_file(tmp_path, [])).sensor_set == 0


@pytest.mark.parametrize("names,words", [
    (["current_a", "hal"], "'hal' is not a sensor; did you mean 'hall'?"),
    (["hall", "hall"], "sensor 'hall' is listed twice")])
def test_board_file_bad_sensor_names_the_file_and_key(tmp_path, names, words):
    path = board_file(tmp_path, names)
    with pytest.raises(ConfigError) as err:
        load_board(path)
    text = str(err.value)
    assert words in text and "board.yaml" in text and "sensors" in text


PLAN = """name: hall plan
steps:
  - run: {duration_s: 0.001}
  - check: {name: hall moves, kind: statistic, statistic: max, signal: sample.hall,
             role: finding}
"""


def test_plan_naming_a_sensor_the_board_lacks_is_refused_before_the_run(tmp_path):
    plan = parse_plan(PLAN, str(tmp_path / "plan.yaml"))
    check_plan_board(plan, load_board(board_file(tmp_path, ["current_a", "hall"])))
    with pytest.raises(ConfigError) as err:
        check_plan_board(plan, load_board(board_file(tmp_path, ["current_a", "current_b"])))
    text = str(err.value)
    assert "sample.hall" in text and "'hall'" in text and ":4" in text and "plan.yaml" in text
    with pytest.raises(ConfigError, match="no sensors: list"):
        check_plan_board(plan, load_board(board_file(tmp_path)))
    # the winding temperature: on a sensor-set board, or a profile whose thermal model is on
    warm = parse_plan(PLAN.replace("sample.hall", "plant.winding_temperature_degc"),
                      str(tmp_path / "plan.yaml"))
    check_plan_board(warm, load_board(board_file(tmp_path, ["hall"])))
    check_plan_board(warm, load_board(board_file(tmp_path)), load_profile(overrides=THERMAL))
    with pytest.raises(ConfigError, match="thermal model"):
        check_plan_board(warm, load_board(board_file(tmp_path)), load_profile())


def test_readme_lists_the_sensor_set_signals():
    """test_plans/README.md's "Sensor-set signals" are exactly what plans accept beside the
    catalogue, with the same units (parsed as test_signal_vocabulary parses "Signals")."""
    from hil.plans.signals import SENSOR_SET_SIGNALS
    from tests.test_signal_vocabulary import README, readme_signals

    text = README.read_text().replace("\n## Signals\n", "\n## Catalogue\n")
    listed = readme_signals(text.replace("\n## Sensor-set signals\n", "\n## Signals\n"))
    assert listed == SENSOR_SET_SIGNALS
    assert set(SENSOR_SET_SIGNALS) - {"plant.winding_temperature_degc"} == \
        {f"sample.{f}" for f in ALL_SENSOR_FIELDS}


RUN_PLAN = """name: hall stuck run
overrides: {initial: {speed_rad_s: 100.0}}
steps:
  - wait_until: {signal: sample.hall, comparison: at_least, value: 2, timeout_s: 0.05}
  - mark: b_on
  - fault: {name: hall_stuck, sensor: b, level: 0}
  - run: {duration_s: 0.01}
  - check:
      name: Hall word while B is stuck low
      kind: bound
      signal: sample.hall
      window: {from: b_on, offset_s: 0.0001}
      limits: {low: 1, high: 5, unit: "1"}
  - check: {name: winding temperature, kind: statistic, statistic: max,
            signal: plant.winding_temperature_degc, role: finding}
"""


def test_a_plan_waits_on_checks_and_faults_a_sensor_set_signal(tmp_path):
    """A plan on a sensor-set board: wait_until on sample.hall (read live) ends on the first
    period Hall B is on; from the next period hall_stuck holds B low, which the reference
    rotor (no fault) has high there; the plan's checks on sample.* pass."""
    from hil.plans.outcome import Outcome
    from hil.run.runner import run_plan

    plan = parse_plan(RUN_PLAN, str(tmp_path / "plan.yaml"))
    mask = mask_of(HALL_SET)
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask) as board:
        result, signals = run_plan(plan, link=board.url, board=board_file(tmp_path, HALL_SET),
                                   out_dir=tmp_path / "out", reports=False)
    assert result.outcome is Outcome.PASS, result.reason
    t, hall = signals["sample.hall"].t_s, signals["sample.hall"].values.astype(int)
    period_s = load_profile().control_period_s
    k_on = int(np.argmax(hall >= 2))
    # the wait ends once period k_on is done: the mark and the fault at the next period
    assert k_on > 0 and result.marks["b_on"] == pytest.approx(t[k_on + 1])
    reference = [e["hall"] for e in reference_frames(len(hall), mask)]
    assert list(hall[:k_on + 1]) == reference[:k_on + 1]
    assert all(not h & 0b010 for h in hall[k_on + 1:])
    assert all(h == r & ~0b010 for h, r in zip(hall[k_on + 1:], reference[k_on + 1:]))
    assert reference[k_on + 1] & 0b010 and len(hall) * period_s > 0.01


def test_limit_formulas_read_the_thermal_model():
    """A stall plan's limits from the profile's thermal model: thermal.* with degC, K/W, J/K
    (the winding's steady rise R_th P and its time constant R_th C_th, by hand)."""
    from hil.plans.formula import FormulaError, evaluate
    from hil.plans.plan_formulas import profile_values

    values = profile_values(load_profile(overrides={"thermal": {
        "enabled": True, "thermal_resistance_k_per_w": 1.5, "thermal_capacitance_j_per_k": 40.0,
        "ambient_degc": 30.0}}))
    values["copper_loss"] = (12.0, "W")
    steady = evaluate("thermal.ambient_degc + thermal.thermal_resistance_k_per_w * copper_loss",
                      values, "degC")
    assert steady.value == pytest.approx(30.0 + 1.5 * 12.0) and steady.unit == "degC"
    tau = evaluate("thermal.thermal_resistance_k_per_w * thermal.thermal_capacitance_j_per_k",
                   values, "s")
    assert tau.value == pytest.approx(60.0)
    with pytest.raises(FormulaError, match="adds K and"):
        evaluate("thermal.ambient_degc + copper_loss", values, "degC")


def test_default_sample_log_has_no_sensor_set_channel(tmp_path):
    """A SAMPLE board's log keeps its channels: no /plant/sample_sensors topic."""
    from hil.logs.commands import log_info

    with FakeBoard(capabilities=CAP_GATES) as board:
        with session(board.url, log_path=tmp_path / "a.mcap") as s:
            s.run_periods(10)
    topics = {c["topic"] for c in log_info(tmp_path / "a.mcap")["channels"]}
    assert "/plant/sensors" in topics and "/plant/sample_sensors" not in topics


def test_sensor_set_log_names_the_signals(tmp_path):
    """`hil log info` names each sample_sensors field by the signal plans use."""
    from hil.logs.commands import log_info

    mask = mask_of(HALL_SET)
    with FakeBoard(capabilities=SENSOR_CAPS, sensor_set=mask) as board:
        with session(board.url, board_file(tmp_path, HALL_SET), log_path=tmp_path / "a.mcap") as s:
            s.run_periods(300)
            hall = s.recorder.arrays()["sample.hall"][1]
    channel = next(c for c in log_info(tmp_path / "a.mcap")["channels"]
                   if c["topic"] == "/plant/sample_sensors")
    signals = {f["signal"] for f in channel["fields"]}
    assert {"sample.hall", "sample.adc_ia", "plant.winding_temperature_degc"} <= signals
    assert channel["count"] == len(hall) == 300
