"""A sensor-set board (SPEC 6.13): its set read and checked after HELLO, and every period's
SAMPLE_SENSORS made from the plant's sensor frame.

A board that advertises SENSOR_SET says which sensors it reads in its read-only parameter
SENSOR_SET (a u16 bit mask in a float32). The session reads it with PARAM_GET under SPEC 2.8.3's
waits and tries, refuses an answer that is not a finite integer mask without reserved bits, and
refuses a board whose set differs from its board file's ``sensors:`` (naming both sets). From
then on the board gets SAMPLE_SENSORS instead of SAMPLE: the plant's SensorFrame (every sensor
computed) with only the set's fields, the others 0 as a receiver decodes them. The same
sampler logs the plant's winding temperature for a SAMPLE board on a profile whose thermal
model is on.
"""
from __future__ import annotations

import math

from protocol.messages import CAP_SENSOR_SET, SENSOR_SET_NAMES, ParamGet, SampleSensors

from hil.boards.board_file import sensor_set_names
from hil.boards.sensor_fields import fields_of_set
from hil.boards.standard import STANDARD_PARAMS
from hil.session.errors import SessionError

#: SENSOR_SET's parameter id (SPEC 8).
SENSOR_SET_ID = STANDARD_PARAMS["sensor_set"].id
#: The bits SPEC 6.13 defines; the others (10-15) are reserved.
KNOWN_SENSOR_BITS = sum(SENSOR_SET_NAMES.values())


def names_text(mask: int) -> str:
    """A sensor set for a message: its names in brackets, e.g. [current_a, hall]."""
    return "[" + ", ".join(sensor_set_names(mask)) + "]"


def read_sensor_set(session) -> int | None:
    """The board's sensor set after HELLO: its SENSOR_SET parameter when it advertises the
    capability (checked), None when it does not (it gets today's SAMPLE). SessionError when the
    answer is refused, not a valid mask, or not the board file's `sensors:`; or when the board
    file names sensors and the board lacks the capability."""
    board, hello = session.board, session.board_hello
    where = session._where()
    wanted = board.sensor_set
    caps = hello.capabilities
    if not caps & CAP_SENSOR_SET:
        if wanted:
            raise SessionError(
                f"{where}: its board file {board.source} names sensors {names_text(wanted)}, but "
                f"the board does not advertise the SENSOR_SET capability (capabilities "
                f"0x{caps:04x}): it would get SAMPLE, not SAMPLE_SENSORS")
        return None
    answer = session._param_exchange(ParamGet(id=SENSOR_SET_ID), SENSOR_SET_ID,
                                     "parameter sensor_set (PARAM_GET)")
    if answer.status != 0:
        raise SessionError(f"{where} advertises SENSOR_SET but refused PARAM_GET of parameter "
                           f"sensor_set (id {SENSOR_SET_ID}, status {answer.status})")
    mask = sensor_set_of_answer(answer.value, where)
    if wanted and mask != wanted:
        raise SessionError(f"{where} reads sensors {names_text(mask)} (parameter sensor_set = "
                           f"0x{mask:04x}), its board file {board.source} says sensors: "
                           f"{names_text(wanted)} (0x{wanted:04x})")
    return mask


def sensor_set_of_answer(value: float, where: str) -> int:
    """SENSOR_SET's float32 as its u16 mask; SessionError naming the parameter otherwise (the
    session and `hil probe` both check it here)."""
    if not math.isfinite(value):
        raise SessionError(f"{where} answered parameter sensor_set (id {SENSOR_SET_ID}) with a "
                           f"non-finite value ({value!r})")
    if value != int(value) or not 0 <= value <= 0xFFFF:
        raise SessionError(f"{where} answered parameter sensor_set (id {SENSOR_SET_ID}) with "
                           f"{value!r}, not a 16-bit integer mask")
    mask = int(value)
    if mask & ~KNOWN_SENSOR_BITS:
        raise SessionError(f"{where} answered parameter sensor_set (id {SENSOR_SET_ID}) = "
                           f"0x{mask:04x}, with reserved bits 0x{mask & ~KNOWN_SENSOR_BITS:04x} set "
                           f"(SPEC 6.13: bits 10-15 are reserved)")
    return mask


class SensorSampler:
    """Every period's SAMPLE_SENSORS for a board whose sensor set is `mask`: the plant's
    SensorFrame with only the set's fields, and the period's rows for the recorder
    (sample.<field> of the set, the winding temperature). `mask` None: a SAMPLE board on a
    profile whose thermal model is on, for which only the winding temperature is recorded."""

    def __init__(self, plant, mask: int | None, recorder):
        self.plant = plant
        self.mask = mask
        self.fields = fields_of_set(mask) if mask is not None else ()
        self.recorder = recorder
        recorder.record_sample_sensors(self.fields, temperature=True)

    def __call__(self):
        """(the plant's sample of the period, its SAMPLE_SENSORS, None for a SAMPLE board):
        the sample (the frame's own, not drawn again: what a SAMPLE would have carried) is the
        recorder's sensor.* row; the period's sample_row (the set's fields, the winding
        temperature) is recorded."""
        plant = self.plant
        if self.mask is None:
            sample = plant.sample()
            self.recorder.sample_row(sample.period, (plant.winding_temperature_degc,))
            return sample, None
        frame = plant.sensor_frame()
        values = {f: getattr(frame, f) for f in self.fields}
        msg = SampleSensors(frame.period, self.mask, frame.status, **values)
        self.recorder.sample_row(frame.period, (*values.values(),
                                                plant.winding_temperature_degc))
        return plant.sample(), msg
