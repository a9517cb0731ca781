"""The fault catalogue: every fault a plan, the Modbus port or Python can switch on, with the
schema of its arguments (JSON Schema, configfile.schema). hil.faults.injector applies them;
the plan format only checks their shape. Every fault also takes duration_s (lifted after it)
and clear (lift it now); random ones take a seed.
"""
from __future__ import annotations

from configfile.schema import (BOOLEAN, FRACTION, NON_NEGATIVE, NUMBER, POSITIVE, POSITIVE_INT,
                               obj)

# Plant parameters a plan may change while running (a hotter winding, a warmer magnet).
PLANT_PARAMS: dict[str, str] = {
    "resistance_ohm": "stator phase resistance",
    "inductance_h": "synchronous inductance Ls (surface magnet)",
    "ld_h": "d-axis inductance (interior magnet)",
    "lq_h": "q-axis inductance (interior magnet)",
    "flux_linkage_wb": "magnet flux linkage",
    "inertia_kgm2": "rotor and load inertia",
    "damping_nm_per_rad_s": "viscous damping",
}

_SENSORS = {"enum": ["adc_i1", "adc_i2", "adc_vdc"]}
_COUNTS = {"type": "integer", "minimum": 0, "maximum": 4095}
_DIRECTION = {"enum": ["out", "in", "both"]}
_PHASE = {"enum": ["a", "b", "c"]}
_LEVEL = {"enum": [0, 1]}                      # a digital sensor's output: low or high   # link faults: bench -> board, board -> bench

_FAULT_COMMON = {"duration_s": POSITIVE, "clear": BOOLEAN}
FAULTS: dict[str, dict] = {
    "open_phase": obj({"phase": {"enum": ["a", "b", "c"]}}, ["phase"]),
    "gate_stuck": obj({"switch": {"enum": ["a_high", "a_low", "b_high", "b_low", "c_high", "c_low"]},
                        "state": {"enum": ["on", "off"]}}, ["switch", "state"]),
    "encoder_lost": obj({}),
    "encoder_missing_counts": obj({"fraction": {"type": "number", "exclusiveMinimum": 0, "maximum": 1},
                                    "seed": {"type": "integer"}}, ["fraction"]),
    "encoder_noise": obj({"std_counts": POSITIVE, "seed": {"type": "integer"}}, ["std_counts"]),
    "encoder_index_missing": obj({}),
    "sensor_offset": obj({"sensor": _SENSORS, "offset_counts": NUMBER}, ["sensor", "offset_counts"]),
    "sensor_gain": obj({"sensor": _SENSORS, "gain": POSITIVE}, ["sensor", "gain"]),
    "sensor_stuck": obj({"sensor": _SENSORS, "value_counts": _COUNTS}, ["sensor"]),
    "sensor_saturation": obj({"sensor": _SENSORS, "low_counts": _COUNTS, "high_counts": _COUNTS},
                              ["sensor"], 2),
    "sensor_noise": obj({"sensor": _SENSORS, "std_counts": POSITIVE, "seed": {"type": "integer"}},
                         ["sensor", "std_counts"]),
    "dc_link_sag": obj({"fraction": {"type": "number", "exclusiveMinimum": 0, "maximum": 1},
                         "ramp_s": NON_NEGATIVE}, ["fraction"]),
    "dc_link_surge": obj({"fraction": {"type": "number", "minimum": 1}, "ramp_s": NON_NEGATIVE},
                          ["fraction"]),
    "dc_link_ripple": obj({"amplitude_v": POSITIVE, "frequency_hz": POSITIVE},
                           ["amplitude_v", "frequency_hz"]),
    "parameter_drift": obj({"parameter": {"enum": [*PLANT_PARAMS, "load_torque_nm"]},
                             "factor": POSITIVE, "ramp_s": NON_NEGATIVE}, ["parameter", "factor"]),
    "link_drop": obj({"rate": FRACTION, "seed": {"type": "integer"}, "direction": _DIRECTION},
                      ["rate"]),
    "link_corrupt": obj({"rate": FRACTION, "bits": POSITIVE_INT, "seed": {"type": "integer"},
                          "direction": _DIRECTION}, ["rate"]),
    "link_delay": obj({"periods": POSITIVE_INT, "direction": _DIRECTION}, ["periods"]),
    "link_duplicate": obj({"rate": FRACTION, "seed": {"type": "integer"}, "direction": _DIRECTION},
                           ["rate"]),
    "link_reorder": obj({"rate": FRACTION, "seed": {"type": "integer"}, "direction": _DIRECTION},
                         ["rate"]),
    "link_unplug": obj({"direction": _DIRECTION}),
    # a sensor-set board's digital sensors (SPEC 6.13): a Hall sensor, a phase's BEMF comparator
    "hall_stuck": obj({"sensor": _PHASE, "level": _LEVEL}, ["sensor", "level"]),
    "bemf_comparator_stuck": obj({"phase": _PHASE, "level": _LEVEL}, ["phase", "level"]),
}
for _schema in FAULTS.values():
    _schema["properties"].update(_FAULT_COMMON)
del _schema


__all__ = ["FAULTS", "PLANT_PARAMS"]
