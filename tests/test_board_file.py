"""Board files (hil/boards): what a board takes and what the bench pushes to it, checked at the
boundary with file, line and key, and used by the session and the plan runner."""
from __future__ import annotations

import pytest

from configfile.source import ConfigError
from hil.boards import STANDARD_PARAMS, load_board, spec_board
from hil.boards.standard import REQUIRED_PARAMS
from hil.logs.reader import read_log
from hil.plans.format import load_plan
from hil.run.runner import board_for, check_plan_board
from hil.session.bench_session import BenchSession, SessionConfig, SessionError
from hil.session.board_params import STUB_BOARD_FILE, board_parameters, default_board
from hil.session.board_params import load_bench_profile
from hil.session.policy import SessionPolicy
from plant_rt.profile import load_profile

from tests.fake_board import FakeBoard

FAST = SessionPolicy(hello_wait_s=0.3, param_wait_s=0.3, param_tries=1, answer_wait_min_s=0.05)
REQUIRED_IDS = {STANDARD_PARAMS[n].id for n in REQUIRED_PARAMS}
HARDWARE = STUB_BOARD_FILE.parents[1] / "plant_rt" / "profiles" / "paper-hardware.yaml"


def _write(tmp_path, text: str, name: str = "board.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_the_stubs_board_file_declares_its_own_parameters_and_its_tuning():
    stub = load_board(STUB_BOARD_FILE)
    assert stub.param("dead_time_comp_s").id == 63 and stub.param("dead_time_comp_s").vendor
    assert stub.param("torque_limit_nm").id == 23 and not stub.param("torque_limit_nm").vendor
    paper = {s.name: s.value for s in stub.settings_for("paper")}
    hardware = {s.name: s.value for s in stub.settings_for("paper-hardware")}
    assert paper == {"torque_limit_nm": 2.0}
    assert hardware["rs_id_periods"] == 1000 and hardware["torque_limit_nm"] == 2.0
    # a profile file is keyed by its stem
    assert stub.settings_for("../somewhere/paper-hardware.yaml") == stub.settings_for("paper-hardware")


def test_no_shipped_profile_pushes_anything_but_the_required_parameters_to_a_spec_board():
    for path in (None, HARDWARE):
        pushed = [s.name for s in board_parameters(load_bench_profile(path), spec_board(),
                                                    "paper-hardware")]
        assert pushed == list(REQUIRED_PARAMS)


def test_a_board_file_may_take_the_sensor_set_parameters(tmp_path):
    """SPEC 8's parameters 8 and 14-18 are standard and optional: listed, set, never pushed unasked."""
    path = _write(tmp_path, "name: b\ncapabilities: [DUTY_LEGS, SENSOR_SET]\nparameters:\n  standard: "
                            "[sensor_set, terminal_v_per_count, resolver_pole_pairs, resolver_offset_counts,"
                            " temperature_degc_per_count, temperature_offset_counts]\n"
                            "settings:\n  terminal_v_per_count: 0.0146484375\n  resolver_pole_pairs: 2\n")
    board = load_board(path)
    assert [board.param(n).id for n in ("sensor_set", "terminal_v_per_count", "resolver_pole_pairs",
                                        "resolver_offset_counts", "temperature_degc_per_count",
                                        "temperature_offset_counts")] == [8, 14, 15, 16, 17, 18]
    assert board.param("sensor_set").read_only and board.param("terminal_v_per_count").default == 100 / 4096
    assert {s.name: s.value for s in board.settings_for(None)} == {
        "terminal_v_per_count": 0.0146484375, "resolver_pole_pairs": 2}
    assert not set(REQUIRED_PARAMS) & {"sensor_set", "terminal_v_per_count", "resolver_pole_pairs"}


@pytest.mark.parametrize("text, line, key, needle", [
    ("name: b\nparameters:\n  standard: [torque_limt_nm]\n", 3, "parameters.standard[0]",
     "did you mean 'torque_limit_nm'"),
    ("name: b\nparameters:\n  vendor:\n    gain_x: {id: 12, unit: '1'}\n", 4,
     "parameters.vendor.gain_x.id", "at least 60"),
    ("name: b\nparameters:\n  vendor:\n    a_hz: {id: 300, unit: Hz}\n    b_hz: {id: 300, unit: Hz}\n",
     5, "parameters.vendor.b_hz.id", "already 'a_hz'"),
    ("name: b\nparameters:\n  vendor:\n    pole_pairs: {id: 300, unit: '1'}\n", 4,
     "parameters.vendor.pole_pairs", "list it under parameters.standard"),
    ("name: b\nparameters:\n  vendor:\n    a_hz: {id: 300, unit: Hz, min: 1, max: 10, default: 20}\n",
     4, "parameters.vendor.a_hz.default", "above its maximum 10"),
    ("name: b\nsettings:\n  torque_limit_nm: 2.0\n", 3, "settings.torque_limit_nm",
     "does not take the standard parameter"),
    ("name: b\nparameters:\n  vendor:\n    a_hz: {id: 300, unit: Hz, max: 10}\nsettings:\n  a_hz: 11\n",
     6, "settings.a_hz", "above its maximum 10 Hz"),
    ("name: b\nsettings:\n  control_step_cycles: 1\n", 3, "settings.control_step_cycles",
     "read-only"),
    ("name: b\nprofile_settings:\n  paper:\n    magic_x: 1\n", 4,
     "profile_settings.paper.magic_x", "unknown board parameter 'magic_x'"),
    ("name: b\ncapabilities: [GATES, PWM]\n", 2, "capabilities[1]", "expected one of"),
    ("name: b\nparameters:\n  standard: [resolver_pole_pairs]\nsettings:\n  resolver_pole_pairs: 0\n", 5,
     "settings.resolver_pole_pairs", "below its minimum 1"),
    # STALL_TIMEOUT_S (SPEC 8, id 43) must be > 0: a zero timeout would trip at once
    ("name: b\nparameters:\n  standard: [stall_timeout_s]\nsettings:\n  stall_timeout_s: 0\n", 5,
     "settings.stall_timeout_s", "below its minimum"),
    ("name: b\nparameters:\n  standard: [sensor_set]\nsettings:\n  sensor_set: 3\n", 5,
     "settings.sensor_set", "read-only"),
    ("parameters: {}\n", 1, None, "missing required key 'name'"),
])
def test_bad_board_files_name_file_line_and_key(tmp_path, text, line, key, needle):
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_board(path)
    err = info.value
    assert (err.source, err.line, err.key) == (str(path), line, key), str(err)
    assert needle in str(err)


def _session(board, board_file, tmp_path=None, profile=None, label=None) -> BenchSession:
    log = None if tmp_path is None else tmp_path / "run.mcap"
    return BenchSession(profile or load_profile(),
                        SessionConfig(link=board.url, log_path=log, hold_cpu_latency=False,
                                      policy=FAST, board=board_file, profile_label=label))


def test_a_board_that_knows_only_the_required_parameters_runs_on_the_hardware_profile():
    profile = load_bench_profile(HARDWARE)
    with FakeBoard(capabilities=0x1, known=REQUIRED_IDS) as board:
        with _session(board, default_board(board.url), profile=profile) as session:
            session.run_periods(5)
        assert set(board.params) == REQUIRED_IDS - {STANDARD_PARAMS["telemetry_divider"].id}


def test_the_stubs_settings_to_a_board_without_them_end_the_session_naming_one(tmp_path):
    stub = load_board(STUB_BOARD_FILE)
    with FakeBoard(capabilities=0x7, known=REQUIRED_IDS) as board:
        with pytest.raises(SessionError, match=r"does not know parameter torque_limit_nm "
                                               r"\(id 23, status 1 UNKNOWN; board file"):
            with _session(board, stub, tmp_path):
                pass
    kinds = list(read_log(tmp_path / "run.mcap")["/plan/events"]["kind"])
    assert "refused" in kinds


def test_an_optional_setting_the_board_does_not_know_is_logged_and_the_run_goes_on(tmp_path, capsys):
    path = _write(tmp_path, "name: b\nparameters:\n  vendor:\n    filter_hz: {id: 400, unit: Hz}\n"
                            "settings:\n  filter_hz: {value: 250, optional: true}\n")
    with FakeBoard(capabilities=0x1, known=REQUIRED_IDS) as board:
        with _session(board, load_board(path), tmp_path) as session:
            session.run_periods(3)
    assert "does not know optional parameter filter_hz (id 400): not set" in capsys.readouterr().err
    events = read_log(tmp_path / "run.mcap")["/plan/events"]
    assert "param_unknown" in list(events["kind"])


def test_vendor_parameters_travel_with_the_board_files_id(tmp_path):
    path = _write(tmp_path, "name: b\nparameters:\n  vendor:\n    filter_hz: {id: 400, unit: Hz}\n"
                            "settings:\n  filter_hz: 250\n")
    with FakeBoard(capabilities=0x1) as board:
        with _session(board, load_board(path)) as session:
            assert session.param_set("filter_hz", 125.0) == 125.0
            with pytest.raises(SessionError, match="unknown board parameter 'fliter_hz'.*did you "
                                                   "mean 'filter_hz'"):
                session.param_set("fliter_hz", 1.0)
        assert board.params[400] == 125.0


def test_a_capability_the_board_file_promises_is_checked_against_the_hello(tmp_path):
    path = _write(tmp_path, "name: b\ncapabilities: [DUTY, TELEMETRY]\n")
    with FakeBoard(capabilities=0x1) as board:
        with pytest.raises(SessionError, match="lacks capability DUTY, which its board file"):
            with _session(board, load_board(path)):
                pass


def test_plans_are_checked_against_the_board_before_anything_runs(tmp_path):
    plan_path = _write(tmp_path, "name: p\nsteps:\n  - command: {enable: true}\n"
                                 "  - param_set: {control_law: 1}\n  - run: {duration_s: 0.01}\n",
                       "plan.yaml")
    plan = load_plan(plan_path)
    check_plan_board(plan, board_for(plan, "stub"))           # the stub takes its own parameter
    with pytest.raises(ConfigError) as info:
        check_plan_board(plan, board_for(plan, "exec:./my-board"))
    err = info.value
    assert (err.source, err.line, err.key) == (str(plan_path), 4, "steps[1].param_set.control_law")
    assert "not a SPEC parameter" in err.message
    out_of_range = _write(tmp_path, "name: p\nsteps:\n  - param_set: {control_law: 7}\n", "p2.yaml")
    with pytest.raises(ConfigError, match="above its maximum 1"):
        check_plan_board(load_plan(out_of_range), board_for(load_plan(out_of_range), "stub"))


def test_a_plans_board_key_names_a_file_relative_to_the_plan(tmp_path):
    _write(tmp_path, "name: my board\nparameters:\n  vendor:\n    x_hz: {id: 500, unit: Hz}\n",
           "my-board.yaml")
    plan = load_plan(_write(tmp_path, "name: p\nboard: my-board.yaml\nsteps:\n"
                                      "  - param_set: {x_hz: 3}\n", "plan.yaml"))
    assert board_for(plan, "stub").name == "my board"        # the plan's board wins over the link's
    check_plan_board(plan, board_for(plan, "stub"))
    with pytest.raises(ConfigError, match="board file not found"):
        load_plan(_write(tmp_path, "name: p\nboard: nope.yaml\nsteps:\n  - run: {duration_s: 1}\n",
                         "p3.yaml"))


@pytest.mark.parametrize("answered", [float("nan"), float("inf"), float("-inf")])
def test_a_non_finite_value_in_force_is_refused_by_name(answered):
    """A board that answers a PARAM_SET with status OK and a NaN or infinite value is refused,
    naming the parameter, not accepted as a clamp."""
    with FakeBoard(capabilities=0x1, clamp={STANDARD_PARAMS["pole_pairs"].id: answered}) as board:
        with pytest.raises(SessionError, match="answered parameter pole_pairs = 1 with a "
                                               "non-finite value in force"):
            with _session(board, spec_board()):
                pass
