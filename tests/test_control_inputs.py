"""One validator for every control input (hil/control_inputs.py, docs/plans.md
"Control inputs"): the values that used to pass the checks and kill a run (1e308 rpm, a
1e308 N m load, fault bits -1 and 2^64 + 4, bits no fault defines) are refused by name on
every path (/cmd, Modbus, plan files, the Python API, the session's mailbox), counted, and
the run goes on; a plant state that still turns non-finite ends the run in ERROR naming the
quantity and the input before it."""
from __future__ import annotations

import math

import pytest

from configfile.source import ConfigError
from hil.faults.injector import MODBUS_BITS
from hil.plans.format import parse_plan
from hil.run.runner import Bench, run_plan
from hil.session.bench_session import SessionError
from hil.session.board_params import load_bench_profile
from hil.control_inputs import ControlInputError, ControlLimits

PAPER = load_bench_profile()
LIMITS = ControlLimits.from_profile(PAPER)
# The paper's motor (Table 1): 3000 rpm rated, one pole pair, 0.0928 Wb, surface magnets; the
# current sensor's full scale 25 A. Peak torque 1.5 p psi I = 3.48 N m, the bound 3x that.
SPEED_MAX_RPM = 2 * 3000.0
TORQUE_MAX_NM = 3 * 1.5 * 1 * 0.0928 * 25.0
HOSTILE = [({"speed_ref_rpm": 1e308}, "speed_ref_rpm"), ({"load_torque_nm": 1e308}, "load_torque_nm"),
           ({"fault_bits": -1}, "fault_bits"), ({"fault_bits": 2**64 + 4}, "fault_bits"),
           ({"fault_bits": 1 << 25}, "fault_bits"), ({"speed_ref_rpm": 2**1100}, "speed_ref_rpm")]


def test_the_ranges_follow_the_profile_by_the_documented_formulas():
    assert LIMITS.speed_ref_max_rpm == SPEED_MAX_RPM
    assert LIMITS.load_torque_max_nm == pytest.approx(TORQUE_MAX_NM, rel=1e-12)
    assert LIMITS.speed_ref_rpm(-SPEED_MAX_RPM) == -SPEED_MAX_RPM
    assert LIMITS.torque_nm(10.4) == 10.4
    with pytest.raises(ControlInputError, match=r"load_torque_nm = 10\.5 refused: outside "
                                                r"-10\.44 \.\. 10\.44 \(3 x the motor's peak torque"):
        LIMITS.torque_nm(10.5)
    with pytest.raises(ControlInputError, match=r"outside -6000 \.\. 6000 \(2 x the motor's rated 3000 rpm\)"):
        LIMITS.speed_ref_rpm(6000.5)
    mask = sum(1 << b for b in MODBUS_BITS)
    assert LIMITS.fault_bits(mask) == mask
    with pytest.raises(ControlInputError, match=r"bits 0x800000 name no fault"):
        LIMITS.fault_bits(1 << 23)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1e39, True, None, "1", 2**1100])
def test_a_wire_value_is_finite_float32_and_a_number(value):
    unbounded = ControlLimits()               # no profile: finite and float32 only
    with pytest.raises(ControlInputError, match=r"^speed_ref_rpm = .* refused: "):
        unbounded.speed_ref_rpm(value)


def test_cmd_values_that_killed_serve_are_refused_by_name_and_counted():
    from hil.live.stream import LiveStream
    from hil.ports.modbus import ControlMailbox

    stream = LiveStream("127.0.0.1", 0, period_s=50e-6)
    try:
        mailbox = ControlMailbox()
        stream.attach_mailbox(mailbox, LIMITS)
        for command, _ in HOSTILE:
            stream._command(repr(command).replace("'", '"').encode())
        errors = stream.take_errors()
        assert stream.commands_refused == len(HOSTILE) and stream.commands_taken == 0
        for error, (command, key) in zip(errors, HOSTILE):
            assert error.startswith(f"/cmd: '{key}': ") and error.endswith("not applied"), error
        assert "outside -6000 .. 6000" in errors[0] and "peak torque" in errors[1]
        assert "fault bits are >= 0" in errors[2] and "name no fault" in errors[3]
        assert "bits 0x2000000 name no fault" in errors[4] and "not a finite number" in errors[5]
        assert mailbox.take_requests() is None                      # nothing reached the session
        stream._command(b'{"speed_ref_rpm": 6000, "load_torque_nm": -10.4, "fault_bits": 4}')
        assert stream.take_errors() == [] and stream.commands_taken == 1
    finally:
        stream.close()


def test_modbus_writes_use_the_same_validator_and_are_counted():
    from pymodbus.constants import ExcCodes

    from hil.ports.modbus import ControlMailbox, _PortConfig, _PortServer

    mailbox = ControlMailbox()
    server = _PortServer(_PortConfig(None, 0, None, 19200, 1, None, None, 0xFFFFFFFF, None, LIMITS),
                         mailbox)
    for write in ({"speed_reference": 6000.01}, {"load_torque": 10.5},
                  {"fault_injection": 1 << 23}, {"dc_link_voltage_setpoint": 140.01},
                  {"speed_reference": 100.0, "load_torque": 11.0}):          # all or nothing
        assert server._apply(write) == ExcCodes.ILLEGAL_VALUE, write
    assert mailbox.writes_refused == 5 and mailbox.take_requests() is None
    assert server._apply({"speed_reference": -6000.0, "load_torque": 10.4}) is None
    taken = mailbox.take_requests()
    assert (taken.speed_ref_rpm, taken.load_torque_nm) == (-6000.0, 10.4)


@pytest.mark.parametrize("step,key", [
    ("command: {speed_ref_rpm: 1.0e+308}", "steps[0].command.speed_ref_rpm"),
    ("command: {torque_ref_nm: .inf}", "steps[0].command.torque_ref_nm"),
    ("load: {type: constant, torque_nm: .nan}", "steps[0].load.torque_nm"),
    ("load: {type: table, points: [[0, 1], [0.1, 1.0e+39]]}", "steps[0].load.points[1][1]"),
])
def test_a_plan_file_with_a_non_finite_or_non_float32_value_is_refused_at_load(step, key):
    text = f"name: hostile\nsteps:\n  - run: {{duration_s: 0.01}}\n  - {step}\n"
    text = text.replace("steps[0]", "steps[1]")
    with pytest.raises(ConfigError) as info:
        parse_plan(text, "hostile.yaml")
    err = info.value
    assert (err.source, err.line, err.key) == ("hostile.yaml", 4, key.replace("steps[0]", "steps[1]"))


def test_a_plan_outside_the_profile_ranges_ends_in_error_before_the_first_period():
    plan = parse_plan("name: too-fast\nsteps:\n  - command: {enable: true}\n  - run: {duration_s: 0.01}\n"
                      "  - command: {speed_ref_rpm: 9000}\n  - run: {duration_s: 0.01}\n", "fast.yaml")
    result, _ = run_plan(plan, reports=False)
    assert result.outcome.value == "ERROR" and result.sim_duration_s == 0.0
    assert result.reason.startswith("fast.yaml:5: key 'steps[2].command.speed_ref_rpm': 9000.0 "
                                    "refused: outside -6000 .. 6000"), result.reason


def test_the_python_api_refuses_by_name_and_the_session_goes_on():
    with Bench(link="stub") as bench:
        bench.command(enable=True, speed_ref_rpm=1000)
        with pytest.raises(ControlInputError, match=r"speed_ref_rpm = 1e\+308 refused"):
            bench.command(speed_ref_rpm=1e308)
        with pytest.raises(ControlInputError, match=r"enable = 2 refused"):
            bench.session.send_command(enable=2)
        assert bench.session.command_state.speed_ref_rpm == 1000.0      # unchanged
        bench.run(0.02)
        assert math.isfinite(bench.plant.state["speed_rad_s"])


def test_a_mailbox_written_past_the_port_is_checked_by_the_session():
    """The mailbox is shared memory: a value that did not come through the port's checks is
    refused between two periods, counted and named in an event; the run goes on."""
    from hil.faults.injector import apply_fault_bits
    from hil.ports.modbus import ControlMailbox

    with Bench(link="stub") as bench:
        session = bench.session
        mailbox = ControlMailbox()
        session.attach_mailbox(mailbox, on_fault_bits=lambda bits: apply_fault_bits(session, bits))
        bench.command(enable=True, speed_ref_rpm=1000)
        mailbox.request(load_torque_nm=1e308, speed_ref_rpm=500.0, fault_bits=2**64 - 1)
        bench.run(0.02)
        refused = [d for _, kind, d in session.events if kind == "input_refused"]
        assert [(d["input"], d["source"]) for d in refused] == [("load_torque_nm", "mailbox"),
                                                                ("fault_bits", "mailbox")]
        assert session.inputs_refused == 2 and session.fault_bits == 0
        assert session.command_state.speed_ref_rpm == 500.0                 # the good one applied
        assert math.isfinite(bench.plant.state["speed_rad_s"])


def test_a_plant_state_that_turns_non_finite_ends_the_run_naming_quantity_and_input():
    """Inertia drifted to 1e-300 (a plant parameter, not a control input): the speed turns
    NaN within a period. The run ends ERROR naming speed_rad_s, the period and the step,
    not 'cannot convert float NaN to integer'."""
    plan = parse_plan("name: nan\nsteps:\n  - command: {enable: true, speed_ref_rpm: 1000}\n"
                      "  - run: {duration_s: 0.01}\n  - plant_param: {inertia_kgm2: 1.0e-300}\n"
                      "  - run: {duration_s: 0.01}\n", "nan.yaml")
    result, _ = run_plan(plan, reports=False)
    assert result.outcome.value == "ERROR"
    assert "the plant's state is no longer finite at period 20" in result.reason, result.reason
    assert "speed_rad_s = nan" in result.reason
    assert "the last input before it: plant_param {'inertia_kgm2': 1e-300} at t = 0.01 s" in result.reason


def test_the_finite_check_runs_once_per_call_and_names_what_it_finds():
    """Between two run_periods calls the state can be made non-finite (Python may set it):
    the next call's check reports it even when the sensors would not have raised."""
    with Bench(link="stub") as bench:
        bench.run(0.001)
        bench.plant._vcap = math.inf
        with pytest.raises(SessionError, match=r"v_cap = inf; the last input before it: command"):
            bench.run(0.001)
