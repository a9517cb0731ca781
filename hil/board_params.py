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
