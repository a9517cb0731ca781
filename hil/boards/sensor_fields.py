"""Which SAMPLE_SENSORS fields each sensor of a sensor set carries (SPEC 6.13), and the
signals plans name them by.

A board's sensor set (its board file's ``sensors:``, its SENSOR_SET parameter) is a bit mask of
protocol.messages.SENSOR_SET_NAMES; each set bit brings its fields, in bit order. The bench
logs what it sent under ``sample.<field>`` (hil/logs/recorder.py), so a plan can check only
what the board's set has (hil.run.runner.check_plan_board).
"""
from __future__ import annotations

from protocol.codec import SENSOR_FIELDS
from protocol.messages import SENSOR_SET_NAMES

_NAME_OF_BIT = {bit: name for name, bit in SENSOR_SET_NAMES.items()}
#: sensor name (SENSOR_SET_NAMES) -> its fields in SAMPLE_SENSORS, in wire order (the codec's
#: table, protocol.codec.SENSOR_FIELDS, by name).
SENSOR_FIELDS_OF: dict[str, tuple[str, ...]] = {
    _NAME_OF_BIT[bit]: names for bit, names, _codes, _limit in SENSOR_FIELDS}
#: Every SAMPLE_SENSORS sensor field, in wire order.
ALL_SENSOR_FIELDS: tuple[str, ...] = tuple(f for fields in SENSOR_FIELDS_OF.values()
                                           for f in fields)
#: field -> the sensor that carries it.
SENSOR_OF_FIELD: dict[str, str] = {f: name for name, fields in SENSOR_FIELDS_OF.items()
                                   for f in fields}
#: The signal group of what a sensor-set board was sent (``sample.hall``).
SAMPLE_GROUP = "sample"
#: The plant's winding temperature (its thermal model), logged beside the sensor set.
WINDING_TEMPERATURE_SIGNAL = "plant.winding_temperature_degc"


def fields_of_set(mask: int) -> tuple[str, ...]:
    """The fields a sensor set's mask carries, in wire order."""
    return tuple(f for name, fields in SENSOR_FIELDS_OF.items()
                 if mask & SENSOR_SET_NAMES[name] for f in fields)


def sensor_of_signal(name: str) -> str | None:
    """The sensor a ``sample.<field>`` signal needs, None for another signal."""
    group, _, field = name.partition(".")
    return SENSOR_OF_FIELD.get(field) if group == SAMPLE_GROUP else None
