"""The parameters a session pushes to the board with PARAM_SET before the first period.

A board must read its converters the way the bench's sensors write them, so SPEC 8.1's
required parameters (the control period, the sensor scaling, the pole pairs) come from the
bench profile (hil.boards.standard.required_values): what a test engineer would copy from the
transducer and ADC data sheets. Everything else is the board file's ``settings`` (and its
``profile_settings`` for the profile in use): the board's own tuning for its motor. The
plant's own motor parameters are deliberately not pushed: a plan that heats the winding must
not tell the board about it.
"""
from __future__ import annotations

from pathlib import Path

from hil.boards import BoardFile, Setting, load_board, spec_board
from hil.boards.standard import required_values

#: The reference stub's board file: its parameters and its tuning for the paper's motor.
STUB_BOARD_FILE = Path(__file__).resolve().parents[2] / "firmware_stub" / "board.yaml"
#: Links that run the reference stub (in-process, over a pty, over slcan, in QEMU).
STUB_LINKS = ("stub", "stub-pty", "stub-can", "qemu")


def default_board(link: str | None) -> BoardFile:
    """The board file a link gets when none is given: the stub's for the stub's links, else a
    board written from SPEC.md alone (only the required parameters are pushed)."""
    if (link or "stub").partition("?")[0] in STUB_LINKS:     # (stub-pty?wire=...: the stub)
        return load_board(STUB_BOARD_FILE)
    return spec_board()


def board_parameters(profile, board: BoardFile | None = None,
                     profile_label: str | None = None) -> list[Setting]:
    """What the session pushes, in order: the required parameters (values from the profile),
    then the board's settings. A setting of a required parameter replaces its value at its
    place (e.g. a board that assumes the nominal current zero and calibrates it itself). A
    sensor set's scaling (TERMINAL_V_PER_COUNT, ...) is not required (SPEC 8.1): a board that
    takes it lists it in its board file's settings."""
    pushed: dict[str, Setting] = {name: Setting(name, value)
                                  for name, value in required_values(profile).items()}
    for setting in (board or spec_board()).settings_for(profile_label):
        pushed[setting.name] = setting
    return list(pushed.values())


def load_bench_profile(path=None, overrides=None):
    """plant_rt.load_profile with the `session` section checked against SPEC 2.8's keys (file,
    line and key of a bad one)."""
    from plant_rt.profile import load_profile

    from hil.session.policy import SESSION_SCHEMA

    return load_profile(path, overrides, session_schema=SESSION_SCHEMA)
