"""The parameters a session pushes to the board with PARAM_SET before the first period.

A board must read its converters the way the bench's sensors write them, so
the sensor scaling comes from the bench profile's sensor section (what a test
engineer would copy from the transducer and ADC data sheets). Everything else
is the profile's ``controller`` section, verbatim: gains, limits, and whatever
motor model the board should assume. The plant's own motor parameters are
deliberately not pushed: a plan that heats the winding must not tell the
board about it.
"""
from __future__ import annotations

from plant_rt.profile import ControllerNames
from protocol.messages import ParamId

#: Board parameters, as a profile's `controller` section and a plan's `param_set` name them:
#: protocol/c/hil_proto.h's hil_param_id names, lower case, without the HIL_PARAM_ prefix.
READ_ONLY_PARAMS: tuple[str, ...] = (ParamId.CONTROL_STEP_CYCLES.name.lower(),)
SETTABLE_PARAMS: tuple[str, ...] = tuple(p.name.lower() for p in ParamId
                                         if p.name.lower() not in READ_ONLY_PARAMS)
CONTROLLER_NAMES = ControllerNames(settable=SETTABLE_PARAMS, read_only=READ_ONLY_PARAMS)

PHASE_PAIRS = {"ab": 0, "ac": 1, "bc": 2}


def board_parameters(profile) -> dict[str, float]:
    """Ordered name -> value (SI units), sensor scaling first."""
    sensors = profile.sensors
    params: dict[str, float] = {
        "control_period_s": profile.control_period_s,
        "current_a_per_count": sensors.current.a_per_count,
        "current_offset_counts": sensors.current.offset_counts,
        "current_phases": float(PHASE_PAIRS[sensors.current.phases]),
        "vdc_v_per_count": sensors.dc_voltage.v_per_count,
        "vdc_offset_counts": sensors.dc_voltage.offset_counts,
        "encoder_counts_per_rev": float(4 * sensors.encoder.lines_per_rev),
        "pole_pairs": float(profile.motor.pole_pairs),
        # Checks compare estimates with the truth period by period; a profile for a
        # board on a slow UART may lower the rate in its controller section.
        "telemetry_divider": 1.0,
    }
    params.update(profile.controller)
    return params


def load_bench_profile(path=None, overrides=None):
    """plant_rt.load_profile with the `controller` section checked against the board's
    parameter names and the `session` section against SPEC 2.8's keys (file, line and key
    of a bad one)."""
    from plant_rt.profile import load_profile

    from hil.session.policy import SESSION_SCHEMA

    return load_profile(path, overrides, controller_names=CONTROLLER_NAMES,
                        session_schema=SESSION_SCHEMA)
