"""Bench profile loading: the paper's defaults, and errors that name file, line and key."""
from __future__ import annotations

import re
import textwrap
from pathlib import Path

import pytest

from configfile.source import ConfigError
from plant_rt import BenchProfile, Plant, default_profile_path, load_profile
from hil.session.board_params import load_bench_profile


def write(tmp_path, text: str):
    path = tmp_path / "bench.yaml"
    path.write_text(textwrap.dedent(text).lstrip("\n"))
    return path


def test_default_profile_is_the_papers_bench():
    p = load_profile()
    assert isinstance(p, BenchProfile)
    assert p.source == str(default_profile_path())
    assert p.control_period_s == 50e-6 and p.timing.computation_delay_s == 0.0
    m = p.motor
    assert (m.pole_pairs, m.resistance_ohm, m.flux_linkage_wb, m.inductance_d_h,
            m.inductance_q_h, m.inertia_kgm2, m.damping_nm_per_rad_s, m.rated_speed_rpm) == \
        (1, 0.466, 0.0928, 4.8e-3, 4.8e-3, 8.0e-4, 1.0e-4, 3000.0)
    assert p.dc_link.source_voltage_v == 70.0 and not p.dc_link.unidirectional
    assert (p.inverter.dead_time_s, p.inverter.device_drop_v) == (0.0, 0.0)
    c = p.sensors.current
    assert (c.phases, c.bits, c.a_per_count, c.offset_counts) == ("ab", 12, 0.01220703125, 2048.0)
    assert (p.sensors.dc_voltage.v_per_count, p.sensors.dc_voltage.offset_counts) == \
        (0.0244140625, 0.0)
    assert (p.sensors.encoder.lines_per_rev, p.sensors.encoder.counter_bits) == (1024, 16)
    # The file lists every key, so it equals the dataclass defaults.
    assert p.as_dict() == {**BenchProfile().as_dict(), "source": p.source}


def test_missing_keys_take_the_papers_values(tmp_path):
    p = load_profile(write(tmp_path, """
        motor:
          resistance_ohm: 0.6
        timing:
          control_period_s: 50e-6   # YAML 1.1 reads this as a string; a number is meant
    """))
    assert p.motor.resistance_ohm == 0.6 and p.motor.flux_linkage_wb == 0.0928
    assert p.control_period_s == 50e-6
    assert p.sensors.current.bits == 12
    Plant(p).step(gates=0x29)


def expect_error(path, message: str, line: int, key: str) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        load_bench_profile(path)     # the plant's checks and the bench's controller names
    err = info.value
    assert err.source == str(path) and err.line == line and err.key == key
    assert message in str(err)
    assert f"{path}:{line}: key '{key}'" in str(err)
    return err


def test_negative_inductance_names_file_line_and_key(tmp_path):
    path = write(tmp_path, """
        motor:
          resistance_ohm: 0.466
          inductance_q_h: -4.8e-3
    """)
    expect_error(path, "must be > 0", 3, "motor.inductance_q_h")


def test_zero_period_is_rejected(tmp_path):
    path = write(tmp_path, """
        timing:
          control_period_s: 0
    """)
    expect_error(path, "must be > 0", 2, "timing.control_period_s")


def test_unknown_keys_and_sections_are_rejected(tmp_path):
    err = expect_error(write(tmp_path, """
        motor:
          pole_pairs: 1
          colour: red
    """), "unknown key", 3, "motor.colour")
    assert "resistance_ohm" in str(err)          # lists what is known
    expect_error(write(tmp_path, """
        sensors:
          current:
            bits: 12
            phase: ab
    """), "unknown key", 4, "sensors.current.phase")
    expect_error(write(tmp_path, """
        motr:
          pole_pairs: 1
    """), "unknown key 'motr'; did you mean 'motor'?", 1, "motr")


@pytest.mark.parametrize("text,message,line,key", [
    ("motor:\n  pole_pairs: 1.5\n", "whole number", 2, "motor.pole_pairs"),
    ("motor:\n  resistance_ohm: low\n", "expected a number", 2, "motor.resistance_ohm"),
    ("dc_link:\n  unidirectional: 1\n", "true or false", 2, "dc_link.unidirectional"),
    ("sensors:\n  current:\n    phases: ca\n", "must be one of", 3, "sensors.current.phases"),
    ("timing:\n  control_period_s: 50.0e-6\n  computation_delay_s: 60.0e-6\n",
     "between 0 and one control period", 3, "timing.computation_delay_s"),
    ("inverter:\n  dead_time_s: 30.0e-6\n", "shorter than half", 2, "inverter.dead_time_s"),
    ("dc_link:\n  unidirectional: true\n  source_resistance_ohm: 0.1\n",
     "needs a bus capacitance", 1, "dc_link.capacitance_f"),
    ("load:\n  table: [[0.0, 1.0], [0.5, 2.0], [0.2, 0.0]]\n", "must not decrease", 2,
     "load.table"),
    ("motor:\n  pole_pairs: 1\ncontroller:\n  torque_limit_nm: 2.0\n",
     "board file", 3, "controller"),
    ("motor: [1, 2]\n", "expected a mapping", 1, "motor"),
    ("sensors:\n  encoder:\n    lines_per_rev: 0\n", "must be >= 1", 3,
     "sensors.encoder.lines_per_rev"),
])
def test_bad_values_name_line_and_key(tmp_path, text, message, line, key):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    expect_error(path, message, line, key)


def test_overrides_merge_and_are_validated_the_same_way(tmp_path):
    path = write(tmp_path, """
        motor:
          resistance_ohm: 0.5
          pole_pairs: 2
    """)
    p = load_profile(path, overrides={"motor": {"resistance_ohm": 0.7}})
    assert (p.motor.resistance_ohm, p.motor.pole_pairs) == (0.7, 2)
    with pytest.raises(ConfigError) as info:
        load_profile(path, overrides={"motor": {"inductance_d_h": -1.0}})
    assert info.value.key == "motor.inductance_d_h" and "(overrides)" in str(info.value)
    assert "must be > 0" in str(info.value)
    with pytest.raises(ConfigError, match="unknown key"):
        load_profile(path, overrides={"motor": {"mass_kg": 3.0}})
    # A file error is still located in the file when overrides are given.
    with pytest.raises(ConfigError) as info:
        load_profile(write(tmp_path, "motor:\n  flux_linkage_wb: -1.0\n"),
                     overrides={"motor": {"resistance_ohm": 0.7}})
    assert info.value.line == 2 and "(overrides)" not in str(info.value)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ConfigError, match="cannot read file"):
        load_profile(tmp_path / "nope.yaml")
    path = tmp_path / "broken.yaml"
    path.write_text("motor:\n  pole_pairs: [1\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_profile(path)


def test_a_profile_carries_no_board_settings(tmp_path):
    """What the board is told lives in its board file: a profile's `controller` section is
    refused with the file, line and key, and says where it went."""
    bad = tmp_path / "old.yaml"
    bad.write_text("controller:\n  torque_limit_nm: 2.0\n")
    with pytest.raises(ConfigError, match="board file") as info:
        load_profile(bad)
    assert info.value.line == 1 and info.value.key == "controller"


def test_session_section_is_checked_against_the_spec_keys(tmp_path):
    """SPEC 2.8's session settings live in the profile; the bench checks their names and
    values with file, line and key, and fills the rest with the spec's defaults."""
    from hil.session.policy import SessionPolicy

    ok = write(tmp_path, """
        session:
          answer_resends: 1
          require_capabilities: [TELEMETRY]
    """)
    policy = SessionPolicy.from_profile(load_bench_profile(ok))
    assert policy.answer_resends == 1 and policy.require_capabilities == ("TELEMETRY",)
    assert policy.watchdog_periods == 20 and policy.answer_wait_s(50e-6) == 0.1
    expect_error(write(tmp_path, "session:\n  answer_resend: 1\n"),
                 "did you mean 'answer_resends'", 2, "session.answer_resend")
    expect_error(write(tmp_path, "session:\n  watchdog_s: -1\n"),
                 "must be greater than 0", 2, "session.watchdog_s")
    expect_error(write(tmp_path, "session:\n  require_capabilities: [PWM]\n"),
                 "expected one of", 2, "session.require_capabilities[0]")
