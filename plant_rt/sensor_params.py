"""Profile parameters of the sensor sets a board may read besides today's SAMPLE (SPEC 1.1):
Hall sensors, phase terminal voltages with BEMF comparators, resolver and winding temperature.

Plain data only (configfile `param` fields: finite, bounded, lists of three per phase), so the
profile loader and plant_rt.sensors can nest them without importing the models
(plant_rt.sensor_set). Every key has a default: a profile without them loads unchanged.
"""
from __future__ import annotations

from configfile.dataclass_methods import dataclass
from configfile.fields import param

#: Where the three phase-current shunts sit (sensors.current.placement).
CURRENT_PLACEMENTS = ("inline", "low_side")


@dataclass(frozen=True)
class HallParams:
    """Three Hall sensors on the phase axes. placement_error_deg: each sensor's angle from its
    phase axis (electrical deg); hysteresis_deg: h, each edge h/2 late in either direction."""

    placement_error_deg: tuple[float, float, float] = param([0.0, 0.0, 0.0], ge=-60.0, le=60.0,
                                                           kind="triple")
    hysteresis_deg: float = param(0.0, ge=0.0, lt=180.0)


@dataclass(frozen=True)
class TerminalParams:
    """Phase terminal voltages (divider, RC filter, ADC) and the BEMF comparators."""

    v_per_count: float = param(0.0244140625, gt=0)      # 100 V / 4096, divider included
    bits: int = param(12, ge=1, le=16)
    filter_time_constant_s: float = param(0.0, ge=0)    # 0: no filter
    comparator_offset_v: tuple[float, float, float] = param([0.0, 0.0, 0.0], ge=-1000.0,
                                                           le=1000.0, kind="triple")
    noise_rms_counts: float = param(0.5, ge=0)


@dataclass(frozen=True)
class ResolverParams:
    """A resolver's sin and cos outputs as ADC counts (SPEC 1.1)."""

    pole_pairs: int = param(1, ge=1, le=64)
    amplitude_counts: float = param(1800.0, gt=0, le=65535.0)
    offset_counts: float = param(2048.0, ge=0, le=65535.0)
    amplitude_imbalance: float = param(0.0, gt=-2.0, lt=2.0)   # (A_sin - A_cos) / A
    quadrature_error_deg: float = param(0.0, gt=-90.0, lt=90.0)
    bits: int = param(12, ge=1, le=16)
    noise_rms_counts: float = param(0.5, ge=0)


@dataclass(frozen=True)
class TemperatureSensorParams:
    """The winding-temperature channel: count = offset_counts + T_w / degc_per_count."""

    degc_per_count: float = param(0.1, gt=0)
    offset_counts: float = param(0.0, ge=-65535.0, le=65535.0)
    bits: int = param(12, ge=1, le=16)
    noise_rms_counts: float = param(0.5, ge=0)
