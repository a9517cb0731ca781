"""The plans `hil init` writes into a project: hil-bench's standard plans that run on any
motor, copied so they name the project's profile and board file, and the starter plans that
cover what no motor-portable standard plan covers.

Every limit of both is a formula of the profile and the board file (test_plans/README.md,
"Formulas"), or a tolerance named `*_requirement` (a requirement of the drive, not physics):
one plan text serves every motor, and `hil init` writes no number of the nameplate into a
plan. Which standard plans are portable, and why the others are not, is in docs/init.md.
"""
from __future__ import annotations

import re
from pathlib import Path

from hil import __version__

# The standard plans (paths under test_plans/) a project gets: their stimuli and limits are
# formulas of the profile and the board file, and they pass on the stub on every motor of
# tests/test_init.py. test_plans/foc/01_speed_step.yaml is portable too but selects the
# stub's FOC law through its vendor parameter control_law, which a user's firmware does not
# take (docs/init.md).
STANDARD_PLANS = ("01_speed_step_sensored.yaml",)

# Where the plans point, relative to the project's plans/ folder.
PROFILE_REF = "../profile.yaml"
BOARD_REF = "../boards/stub.yaml"

_TOP_PROFILE = re.compile(r"^(profile|profiles):[^\n]*\n", re.MULTILINE)
_TOP_BOARD = re.compile(r"^board:[^\n]*\n", re.MULTILINE)


def standard_plans_dir() -> Path:
    """test_plans/: beside the hil package in a checkout, and in site-packages where hil-bench
    is pip-installed (pyproject.toml installs test_plans/*.yaml as package data)."""
    return Path(__file__).resolve().parents[2] / "test_plans"


def standard_plan_copy(rel: str) -> str:
    """The standard plan test_plans/REL as the project runs it: a header naming the source,
    then the plan's text with its top-level `profile(s):` and `board:` replaced by the
    project's profile and the stub's board file. Nothing else changes."""
    source = standard_plans_dir() / rel
    try:
        text = source.read_text()
    except OSError as exc:
        raise RuntimeError(f"the standard plan {source} is missing from this "
                           f"hil-bench installation ({exc.strerror})") from None
    if len(_TOP_PROFILE.findall(text)) != 1:
        raise RuntimeError(f"{source} has no single top-level profile(s) line to replace")
    text = _TOP_BOARD.sub("", text)
    text = _TOP_PROFILE.sub(f"profile: {PROFILE_REF}\nboard: {BOARD_REF}\n", text)
    header = (f"# hil-bench's standard plan test_plans/{rel} (hil-bench {__version__}), copied by\n"
              f"# `hil init`: unchanged but for `profile:` and `board:`, which name this project's\n"
              f"# profile and the stub's board file for this motor. Its stimuli and limits are\n"
              f"# formulas of the profile and the board file, evaluated before each run (hil-bench\n"
              f"# test_plans/README.md, \"Formulas\"): edit profile.yaml and they follow.\n")
    return header + text


_STARTER_HEADER = f"""# Written by `hil init` (hil-bench {__version__}): no standard plan of hil-bench covers this on
# any motor (docs/init.md). Its stimuli and limits are formulas of the project's profile and
# board file; a tolerance named *_requirement is a requirement, not physics: set it to yours.
profile: {PROFILE_REF}
board: {BOARD_REF}
"""

# The torque the plant reaches at most, as test_plans/01_speed_step_sensored.yaml derives it:
# the torque limit, half the torque band and one period's torque rise at standstill.
_TORQUE_PEAK = """  # one period's torque rise at standstill, (2/3 Vdc) T / Ls * 3/2 p psi_f
  torque_step: {value: "2/3 * dc_link.source_voltage_v * timing.control_period_s / motor.inductance_q_h * 1.5 * motor.pole_pairs * motor.flux_linkage_wb", unit: Nm}
  # the highest torque the plant reaches: T_max + half the torque band + one period's rise
  torque_peak: {value: "board.torque_limit_nm + board.torque_band_nm / 2 + torque_step", unit: Nm}
"""

STEADY_STATE = _STARTER_HEADER + """name: steady-state
description: |
  Rated speed, no load, encoder feedback: the speed loop holds the speed and the torque
  stays inside the drive's limit. The standard plans' steady state
  (test_plans/02_steady_state_3000rpm.yaml) runs at a fixed 3000 rpm under a fixed 0.5 Nm
  load, so this plan takes its place on any motor.

  Limits (formulas of profile.yaml and the board file; the report shows each with its
  inputs):
  - Mean speed within speed_tolerance_requirement (0.5 %) of the reference: a requirement,
    not physics (a speed loop with integral action has no steady error; the tolerance
    covers the encoder's quantisation and the torque band's ripple).
  - The torque never exceeds 5 % over torque_peak, test_plans/01's bound: the torque
    limit, half the torque band and one period's torque rise at standstill,
    (2/3 Vdc) T / Ls * 3/2 p psi_f.
constants:
  second: {value: 1, unit: s}
  speed: {value: "motor.rated_speed_rpm", unit: rpm}
  speed_tolerance_requirement: {value: 0.005, unit: "1"}
  # the torque-limited ramp from standstill to the speed, J w / T_max
  ramp_time: {value: "motor.inertia_kgm2 * speed / board.torque_limit_nm", unit: ms}
""" + _TORQUE_PEAK + """steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: speed}
  - wait_until: {signal: plant.speed_rpm, comparison: within, value: speed, tolerance: "0.01 * speed",
                 unit: rpm, hold_s: 0.05, timeout_s: "4 * ramp_time + second"}
  - mark: steady
  - run: {duration_s: 0.1}
  - check:
      name: mean speed
      kind: statistic
      statistic: mean
      signal: plant.speed_rpm
      window: {from: steady}
      limits: {low: "(1 - speed_tolerance_requirement) * speed",
               high: "(1 + speed_tolerance_requirement) * speed", unit: rpm}
  - check:
      name: torque inside the limit
      kind: statistic
      statistic: max_abs
      signal: plant.torque_nm
      window: {from: steady}
      limits: {high: "1.05 * torque_peak", unit: Nm}
"""

ENCODER_LOSS = _STARTER_HEADER + """name: encoder-loss
description: |
  The encoder's counter freezes at half the rated speed: the firmware reports FAULT
  ENCODER_LOSS (code 2, protocol/SPEC.md 9.6) and stops switching. The standard plans'
  encoder-loss plans (test_plans/faults/02_encoder_loss_detected.yaml, foc/05) run at a
  fixed 1500 rpm, so this plan takes their place on any motor.

  Limits (formulas of profile.yaml and the board file):
  - Detection within detection_time_requirement (20 ms) of the fault: a requirement, not
    physics (the stub's board file sets encoder_loss_timeout_s to half of it).
  - Then the phase currents die out through the diodes: from at most the overcurrent trip
    I_trip, against the link less the line back-EMF across a phase pair (2 Ls),
    t = 2 Ls I_trip / (Vdc - sqrt3 psi_f p w) (decay_time). From the detection limit plus
    that, every phase current is below one count of the current sensor
    (board.current_a_per_count): gone as far as the board can tell.
constants:
  second: {value: 1, unit: s}
  speed: {value: "0.5 * motor.rated_speed_rpm", unit: rpm}
  detection_time_requirement: {value: 20, unit: ms}
  # the torque-limited ramp from standstill to the speed, J w / T_max
  ramp_time: {value: "motor.inertia_kgm2 * speed / board.torque_limit_nm", unit: ms}
  # the currents through the diodes: from I_trip against Vdc less the line back-EMF
  decay_time: {value: "2 * motor.inductance_q_h * board.overcurrent_a / (dc_link.source_voltage_v - sqrt(3) * motor.flux_linkage_wb * motor.pole_pairs * speed)", unit: ms}
  currents_gone_after: {value: "detection_time_requirement + decay_time", unit: s}
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: speed}
  - wait_until: {signal: plant.speed_rpm, comparison: within, value: speed, tolerance: "0.01 * speed",
                 unit: rpm, hold_s: 0.02, timeout_s: "8 * ramp_time + second"}
  - mark: lost
  - fault: {name: encoder_lost}
  - run: {duration_s: "2 * currents_gone_after"}
  - check:
      name: FAULT code is ENCODER_LOSS
      kind: final_value
      signal: ctrl.fault_code
      limits: {low: 2, high: 2, unit: "1"}
  - check:
      name: detection time
      kind: settling_time
      signal: ctrl.fault_code
      initial: {value: 0, unit: "1"}
      target: {value: 2, unit: "1"}
      band: {value: 0.5, unit: "1"}
      window: {from: lost}
      limits: {high: detection_time_requirement, unit: ms}
  - check:
      name: phase a current gone
      kind: statistic
      statistic: max_abs
      signal: plant.i_a
      window: {from: lost, offset_s: currents_gone_after}
      limits: {high: board.current_a_per_count, unit: A}
  - check:
      name: phase b current gone
      kind: statistic
      statistic: max_abs
      signal: plant.i_b
      window: {from: lost, offset_s: currents_gone_after}
      limits: {high: board.current_a_per_count, unit: A}
"""

DC_SAG = _STARTER_HEADER + """name: dc-sag
description: |
  The DC link sags at half the rated speed to twice the back-EMF's share of the bus,
  2 sqrt3 psi_f p (w_r / 2) / Vdc, kept within 0.6 .. 0.9 of the link (sag_fraction). The
  standard plans' sags (test_plans/06_load_step_dc_sag.yaml,
  faults/04_dc_link_sag_full_speed.yaml) run at a fixed 3000 rpm, so this plan takes their
  place on any motor.

  Limits (formulas of profile.yaml): the bus still holds twice the back-EMF's share, so the
  speed stays within speed_tolerance_requirement (2 %) of the reference through the sag (a
  requirement, not physics), and the drive keeps running (no FAULT).
constants:
  second: {value: 1, unit: s}
  speed: {value: "0.5 * motor.rated_speed_rpm", unit: rpm}
  speed_tolerance_requirement: {value: 0.02, unit: "1"}
  # the torque-limited ramp from standstill to the speed, J w / T_max
  ramp_time: {value: "motor.inertia_kgm2 * speed / board.torque_limit_nm", unit: ms}
  sag_fraction: {value: "min(0.9, max(0.6, 2 * sqrt(3) * motor.flux_linkage_wb * motor.pole_pairs * speed / dc_link.source_voltage_v))", unit: "1"}
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: speed}
  - wait_until: {signal: plant.speed_rpm, comparison: within, value: speed, tolerance: "0.01 * speed",
                 unit: rpm, hold_s: 0.02, timeout_s: "8 * ramp_time + second"}
  - mark: sag
  - dc_link: {voltage_v: "sag_fraction * dc_link.source_voltage_v", ramp_s: 0.005}
  - run: {duration_s: 0.1}
  - check:
      name: speed held through the sag
      kind: bound
      signal: plant.speed_rpm
      window: {from: sag}
      limits: {low: "(1 - speed_tolerance_requirement) * speed",
               high: "(1 + speed_tolerance_requirement) * speed", unit: rpm}
  - check:
      name: no board fault
      kind: final_value
      signal: ctrl.fault_code
      limits: {low: 0, high: 0, unit: "1"}
"""

STARTER_PLANS = {
    "02_steady_state.yaml": STEADY_STATE,
    "03_encoder_loss.yaml": ENCODER_LOSS,
    "04_dc_sag.yaml": DC_SAG,
}


def project_plans() -> dict[str, str]:
    """File name under plans/ -> text: the standard plans, then the starter plans."""
    plans = {Path(rel).name: standard_plan_copy(rel) for rel in STANDARD_PLANS}
    plans.update(STARTER_PLANS)
    return plans
