"""SPEC.md section 8's standard parameters: ids 1-59, the same name, id and unit on every board.

Ids 60-65535 are a board's own (vendor) parameters: their names, units and ranges come from
the board's file (hil.boards.board_file), never from this table.

The *required* ones are what SPEC 8.1 marks as pushed: the control period, the sensor scaling
and the pole pairs, which a board must know to read the bench's converters at all. Their
values come from the bench profile (``required_values``); every other parameter is sent only
when a board file's ``settings`` or a plan's ``param_set`` names it.
"""
from __future__ import annotations

from configfile.dataclass_methods import dataclass

#: HELLO capability bits (SPEC 9.1), bit i = 1 << i.
CAPABILITY_NAMES = ("GATES", "DUTY", "TELEMETRY", "CAN", "DUTY_LEGS", "SENSOR_SET")

#: Lowest vendor id: SPEC 8 reserves 60-65535 for a board's own parameters.
VENDOR_ID_MIN = 60
VENDOR_ID_MAX = 0xFFFF


@dataclass(frozen=True)
class ParamSpec:
    """One parameter a board takes: SPEC's (standard) or the board's own (vendor)."""

    name: str
    id: int
    unit: str
    description: str = ""
    minimum: float | None = None
    maximum: float | None = None
    default: float | None = None
    read_only: bool = False
    vendor: bool = False

    def problem(self, value: float) -> str | None:
        """Why `value` is outside this parameter's range, or None."""
        if self.minimum is not None and value < self.minimum:
            return f"below its minimum {self.minimum:g} {self.unit}"
        if self.maximum is not None and value > self.maximum:
            return f"above its maximum {self.maximum:g} {self.unit}"
        return None


#: SPEC 8.1's defaults: what a board starts with (the reference system's values).
SPEC_DEFAULTS: dict[str, float] = {
    "control_period_s": 5e-05,
    "current_a_per_count": 0.01220703125,
    "current_offset_counts": 2048,
    "vdc_v_per_count": 0.0244140625,
    "vdc_offset_counts": 0,
    "encoder_counts_per_rev": 4096,
    "current_phases": 0,
    "pole_pairs": 1,
    "stator_resistance_ohm": 0.466,
    "stator_inductance_h": 0.0048,
    "magnet_flux_wb": 0.0928,
    "terminal_v_per_count": 0.0244140625,
    "resolver_pole_pairs": 1,
    "resolver_offset_counts": 2048,
    "temperature_degc_per_count": 0.1,
    "temperature_offset_counts": 0,
    "flux_ref_wb": 0.099,
    "flux_band_wb": 0.00233,
    "torque_band_nm": 0.0586,
    "torque_limit_nm": 2.0,
    "speed_kp_nm_per_rad_s": 0.0503,
    "speed_ki_nm_per_rad": 0.79,
    "speed_lpf_cutoff_hz": 20,
    "ekf_k1": 0.0568456,
    "ekf_k2": 32.0846,
    "ekf_k3": 0.446429,
    "flux_drift_cutoff_hz": 10,
    "telemetry_divider": 10,
    "overcurrent_a": 20,
    "encoder_loss_timeout_s": 0.01,
    "stall_timeout_s": 0.05,
    "control_step_cycles": 0,
}

def _std(name: str, pid: int, unit: str, description: str, **kw) -> ParamSpec:
    return ParamSpec(name=name, id=pid, unit=unit, description=description,
                     default=SPEC_DEFAULTS[name], **kw)


#: SPEC 8's table, ids 1-59, in id order.
STANDARD_PARAMS: dict[str, ParamSpec] = {p.name: p for p in (
    _std("control_period_s", 1, "s", "control period T (also in HELLO)", minimum=1e-7),
    _std("current_a_per_count", 2, "A/count", "phase-current scaling"),
    _std("current_offset_counts", 3, "count", "ADC count at zero current"),
    _std("vdc_v_per_count", 4, "V/count", "DC-link scaling"),
    _std("vdc_offset_counts", 5, "count", "ADC count at 0 V"),
    _std("encoder_counts_per_rev", 6, "count", "quadrature counts per mechanical revolution",
         minimum=1),
    _std("current_phases", 7, "1", "phases in adc_i1, adc_i2: 0 = a,b; 1 = a,c; 2 = b,c",
         minimum=0, maximum=2),
    # read-only, no default: the board's own sensor set (SPEC 9.8), read after HELLO
    ParamSpec(name="sensor_set", id=8, unit="1", description="the board's SAMPLE_SENSORS sensor set "
              "(bit mask, read-only)", minimum=0, maximum=0x3FF, read_only=True),
    _std("pole_pairs", 10, "1", "pole pairs p", minimum=1),
    _std("stator_resistance_ohm", 11, "ohm", "stator resistance R_s", minimum=0),
    _std("stator_inductance_h", 12, "H", "synchronous inductance L_s", minimum=0),
    _std("magnet_flux_wb", 13, "Wb", "magnet flux linkage psi_r", minimum=0),
    _std("terminal_v_per_count", 14, "V/count", "phase terminal voltage scaling, divider included",
         minimum=0),
    _std("resolver_pole_pairs", 15, "1", "resolver electrical turns per mechanical turn", minimum=1),
    _std("resolver_offset_counts", 16, "count", "resolver sin and cos count at zero signal",
         minimum=0, maximum=0xFFFF),
    _std("temperature_degc_per_count", 17, "degC/count", "winding temperature scaling"),
    _std("temperature_offset_counts", 18, "count", "temperature count at 0 degC"),
    _std("flux_ref_wb", 20, "Wb", "default stator flux reference", minimum=0),
    _std("flux_band_wb", 21, "Wb", "flux hysteresis band (full width)", minimum=0),
    _std("torque_band_nm", 22, "N m", "torque hysteresis band (full width)", minimum=0),
    _std("torque_limit_nm", 23, "N m", "speed regulator output limit", minimum=0),
    _std("speed_kp_nm_per_rad_s", 24, "N m/(rad/s)", "speed PI proportional gain", minimum=0),
    _std("speed_ki_nm_per_rad", 25, "N m/rad", "speed PI integral gain", minimum=0),
    _std("speed_lpf_cutoff_hz", 26, "Hz", "low-pass filter on the eq. (11) speed", minimum=0),
    _std("ekf_k1", 30, "rad", "EKF gain k1, eq. (19), (21)"),
    _std("ekf_k2", 31, "rad/s", "EKF gain k2, eq. (19), (22)"),
    _std("ekf_k3", 32, "rad/s", "EKF gain k3, eq. (19), (23)"),
    _std("flux_drift_cutoff_hz", 33, "Hz", "corner of the flux integrator's drift compensation",
         minimum=0),
    _std("telemetry_divider", 40, "period", "TELEMETRY every N periods; 0 = none", minimum=0),
    _std("overcurrent_a", 41, "A", "phase-current trip level (FAULT 1)", minimum=0),
    _std("encoder_loss_timeout_s", 42, "s", "encoder silence while running that trips FAULT 2",
         minimum=0),
    # > 0: a zero timeout would trip on the first period without a commutation event
    _std("stall_timeout_s", 43, "s", "no commutation event under torque demand that trips FAULT 7",
         minimum=1e-6),
    _std("control_step_cycles", 50, "cycle", "CPU cycles of the last control step (read-only)",
         read_only=True),
)}

#: SPEC 8.1's pushed parameters, in the order the bench sends them (telemetry_divider only to a
#: board that advertises TELEMETRY).
REQUIRED_PARAMS: tuple[str, ...] = (
    "control_period_s", "current_a_per_count", "current_offset_counts", "current_phases",
    "vdc_v_per_count", "vdc_offset_counts", "encoder_counts_per_rev", "pole_pairs",
    "telemetry_divider")

PHASE_PAIRS = {"ab": 0, "ac": 1, "bc": 2}


def required_values(profile) -> dict[str, float]:
    """SPEC 8.1's pushed parameters from a bench profile, in push order (SI units)."""
    sensors = profile.sensors
    return {
        "control_period_s": profile.control_period_s,
        "current_a_per_count": sensors.current.a_per_count,
        "current_offset_counts": sensors.current.offset_counts,
        "current_phases": float(PHASE_PAIRS[sensors.current.phases]),
        "vdc_v_per_count": sensors.dc_voltage.v_per_count,
        "vdc_offset_counts": sensors.dc_voltage.offset_counts,
        "encoder_counts_per_rev": float(4 * sensors.encoder.lines_per_rev),
        "pole_pairs": float(profile.motor.pole_pairs),
        # Checks compare estimates with the truth period by period; a board file for a board
        # on a slow UART may lower the rate in its settings.
        "telemetry_divider": 1.0,
    }
