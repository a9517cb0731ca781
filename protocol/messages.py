"""Message types of the hil-bench wire protocol (protocol/SPEC.md).

Every message is a frozen, slotted dataclass whose field names are the C
struct field names of protocol/c/hil_proto.h, so a field means the same thing
on both sides of the wire. Decoded messages carry plain ints (IntEnum members
compare equal to them), which keeps decoding cheap and lets a value this
version does not name (a future parameter id, say) pass through unguessed.
"""
from __future__ import annotations

from dataclasses import MISSING, fields
from enum import IntEnum
from typing import ClassVar

from configfile.dataclass_methods import dataclass

PROTOCOL_VERSION = 1
NAME_MAX = 40


class MsgType(IntEnum):
    HELLO = 0x01
    SAMPLE = 0x02
    GATES = 0x03
    DUTY = 0x04
    COMMAND = 0x05
    TELEMETRY = 0x06
    PARAM_SET = 0x07
    PARAM_GET = 0x08
    PARAM_VALUE = 0x09
    STATUS = 0x0A
    FAULT = 0x0B
    HEARTBEAT = 0x0C
    SHUTDOWN = 0x0D
    DUTY_LEGS = 0x0F  # 0x0E stays undefined: the vector files use it as the unknown type
    SAMPLE_SENSORS = 0x10  # SAMPLE with a board-declared sensor set, to a board with CAP_SENSOR_SET


class Role(IntEnum):
    BENCH = 0
    CONTROLLER = 1


class SpeedSource(IntEnum):
    ENCODER = 0
    CONVENTIONAL = 1  # eq. (10)-(11) with low-pass filter
    EKF = 2           # eq. (16)-(23)


class ControllerState(IntEnum):
    IDLE = 0
    RUNNING = 1      # enabled and controlling: ready (SPEC.md 2 item 5)
    FAULT = 2
    STARTING = 3     # enabled, start-up phase (alignment, calibration): not yet controlling


class FaultCode(IntEnum):
    NONE = 0
    OVERCURRENT = 1
    ENCODER_LOSS = 2
    DC_LINK = 3
    WATCHDOG = 4
    PROTOCOL = 5
    NON_FINITE = 6
    STALL = 7  # no commutation event under torque demand: locked rotor, lost synchronisation


class NonFiniteQuantity(IntEnum):
    """FAULT NON_FINITE's value: the quantity that was NaN or infinite (SPEC.md 9.6)."""
    OTHER = 0
    PHASE_CURRENT = 1
    DC_LINK_VOLTAGE = 2
    MEASURED_SPEED = 3
    FLUX_ESTIMATE = 4
    SPEED_ESTIMATE = 5
    TORQUE_REFERENCE = 6
    VOLTAGE_REFERENCE = 7
    COMMAND = 8


class ParamStatus(IntEnum):
    OK = 0
    UNKNOWN = 1
    OUT_OF_RANGE = 2
    READ_ONLY = 3


class ParamId(IntEnum):
    """PARAM_SET / PARAM_GET / PARAM_VALUE ids; every value is a float32 in the unit its name ends with."""

    CONTROL_PERIOD_S = 1
    CURRENT_A_PER_COUNT = 2
    CURRENT_OFFSET_COUNTS = 3
    VDC_V_PER_COUNT = 4
    VDC_OFFSET_COUNTS = 5
    ENCODER_COUNTS_PER_REV = 6
    CURRENT_PHASES = 7  # 0: a,b  1: a,c  2: b,c
    SENSOR_SET = 8  # read-only: the board's SAMPLE_SENSORS sensor set (SENSOR_* bits) as a float32
    POLE_PAIRS = 10
    STATOR_RESISTANCE_OHM = 11
    STATOR_INDUCTANCE_H = 12
    MAGNET_FLUX_WB = 13
    TERMINAL_V_PER_COUNT = 14  # phase terminal volts per count, divider included
    RESOLVER_POLE_PAIRS = 15  # resolver electrical turns per mechanical turn
    RESOLVER_OFFSET_COUNTS = 16  # resolver sin/cos count at zero signal
    TEMPERATURE_DEGC_PER_COUNT = 17
    TEMPERATURE_OFFSET_COUNTS = 18  # temperature count at 0 degC
    FLUX_REF_WB = 20
    FLUX_BAND_WB = 21
    TORQUE_BAND_NM = 22
    TORQUE_LIMIT_NM = 23
    SPEED_KP_NM_PER_RAD_S = 24
    SPEED_KI_NM_PER_RAD = 25
    SPEED_LPF_CUTOFF_HZ = 26
    EKF_K1 = 30
    EKF_K2 = 31
    EKF_K3 = 32
    FLUX_DRIFT_CUTOFF_HZ = 33
    TELEMETRY_DIVIDER = 40
    OVERCURRENT_A = 41
    ENCODER_LOSS_TIMEOUT_S = 42
    STALL_TIMEOUT_S = 43  # no commutation event under torque demand for this long trips FAULT STALL
    CONTROL_STEP_CYCLES = 50  # read-only: cycles of the last control step on target
    CONTROL_LAW = 60  # 0: DTC (answers GATES), 1: FOC (answers DUTY)
    CURRENT_BANDWIDTH_HZ = 61  # FOC d-q current loop bandwidth
    FOC_ANGLE_SOURCE = 62  # FOC rotor angle: 0 encoder, 1 EKF
    DEAD_TIME_COMP_S = 63  # dead-time compensation by current sign (FOC duties, DTC observer), 0 = off
    DEVICE_DROP_COMP_V = 64  # DTC: device drop compensated in the observer voltage, 0 = off
    DELAY_COMP_PERIODS = 65  # DTC: 1 = answers act one period late (integrate what acted, predict)
    CURRENT_ZERO_CAL_PERIODS = 66  # at each enable, periods with the bridge off to measure the current ADCs' zero, 0 = off
    RS_ID_PERIODS = 67  # start-up stator-resistance identification at standstill, periods per current level, 0 = off


# HELLO capability bits
CAP_GATES = 0x0001
CAP_DUTY = 0x0002
CAP_TELEMETRY = 0x0004
CAP_CAN = 0x0008
CAP_DUTY_LEGS = 0x0010
CAP_SENSOR_SET = 0x0020  # reads SAMPLE_SENSORS (instead of SAMPLE); its set is parameter SENSOR_SET

# SAMPLE_SENSORS sensor-set bits; each set bit's fields follow the fixed part in bit order
# (SPEC.md 6.13, 9.8); bits 10-15 reserved
SENSOR_CURRENT_A = 0x0001           # adc_ia u16
SENSOR_CURRENT_B = 0x0002           # adc_ib u16
SENSOR_CURRENT_C = 0x0004           # adc_ic u16
SENSOR_VDC = 0x0008                 # adc_vdc u16
SENSOR_ENCODER = 0x0010             # encoder u16
SENSOR_HALL = 0x0020                # hall u8: bit 0 A, 1 B, 2 C
SENSOR_TERMINAL_VOLTAGES = 0x0040   # adc_va, adc_vb, adc_vc u16
SENSOR_BEMF_COMPARATORS = 0x0080    # bemf_comparators u8: bit x = phase x above the virtual neutral
SENSOR_RESOLVER = 0x0100            # adc_resolver_sin, adc_resolver_cos u16
SENSOR_TEMPERATURE = 0x0200         # adc_temperature u16
SENSOR_SET_ALL = 0x03FF
# The names board files use (hil/boards: `sensors: [current_a, ...]`), in bit order.
SENSOR_SET_NAMES = {
    "current_a": SENSOR_CURRENT_A, "current_b": SENSOR_CURRENT_B, "current_c": SENSOR_CURRENT_C,
    "vdc": SENSOR_VDC, "encoder": SENSOR_ENCODER, "hall": SENSOR_HALL,
    "terminal_voltages": SENSOR_TERMINAL_VOLTAGES, "bemf_comparators": SENSOR_BEMF_COMPARATORS,
    "resolver": SENSOR_RESOLVER, "temperature": SENSOR_TEMPERATURE,
}

# DUTY_LEGS leg_enable bits: 1 = the leg switches (DUTY's complementary PWM), 0 = floated
# (both switches off, the phase current free-wheels through the diodes); bits 3-7 reserved
LEG_A = 0x01
LEG_B = 0x02
LEG_C = 0x04
LEGS_ALL = LEG_A | LEG_B | LEG_C

# GATES bits: 1 = switch on
GATE_A_HIGH = 0x01
GATE_A_LOW = 0x02
GATE_B_HIGH = 0x04
GATE_B_LOW = 0x08
GATE_C_HIGH = 0x10
GATE_C_LOW = 0x20

# SAMPLE status bits (4 bits on the wire)
STATUS_INDEX_PULSE = 0x01
STATUS_OVERCURRENT = 0x02
STATUS_OVERVOLTAGE = 0x04
STATUS_GATE_FAULT = 0x08

# COMMAND flags
CMD_ENABLE = 0x01
CMD_TORQUE_MODE = 0x02


def _fast_init(cls):
    """Gives a frozen, slotted dataclass declared with ``init=False`` an __init__ that stores
    through the slot descriptors.

    The generated frozen __init__ calls object.__setattr__ per field (0.76 us
    for SAMPLE); the slot descriptors halve that, and SAMPLE and GATES are
    built every 50 us. Instances stay frozen: __setattr__ still raises. (With
    ``init=False`` the dataclass does not compile an __init__ that this one would
    replace: one compile fewer per message class at import.)
    """
    names = [f.name for f in fields(cls)]
    if not names or hasattr(cls, "__post_init__") or "__init__" in cls.__dict__:
        raise TypeError(f"{cls.__name__}: _fast_init is for dataclasses with fields, declared "
                        f"with init=False and without __post_init__")
    namespace = {f"_set_{n}": cls.__dict__[n].__set__ for n in names}
    # a field with a default keeps it (SampleSensors: the fields of absent sensors are 0)
    params = [n if f.default is MISSING else f"{n}=_default_{n}" for n, f in zip(names, fields(cls))]
    namespace.update({f"_default_{f.name}": f.default for f in fields(cls) if f.default is not MISSING})
    body = "".join(f"    _set_{n}(self, {n})\n" for n in names)
    src = f"def __init__(self, {', '.join(params)}):\n{body}"
    exec(src, namespace)  # noqa: S102 - source built from the dataclass's own field names
    init = namespace["__init__"]
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__doc__ = None
    cls.__init__ = init
    return cls


@dataclass(frozen=True, slots=True)
class _Message:
    """A message of the protocol; TYPE is its type byte."""

    TYPE: ClassVar[MsgType]


@dataclass(frozen=True, slots=True)
class Hello(_Message):
    """Both ways at session start. ``name`` is bytes (a str is encoded as UTF-8);
    ``name_len`` may be left out and is then len(name)."""

    TYPE: ClassVar[MsgType] = MsgType.HELLO
    proto_version: int
    role: int
    capabilities: int
    control_period_ns: int
    name_len: int = -1
    name: bytes = b""

    def __post_init__(self) -> None:
        name = self.name
        if isinstance(name, str):
            name = name.encode("utf-8")
        elif not isinstance(name, bytes):
            name = bytes(name)
        name_len = self.name_len
        if name_len < 0:
            name_len = len(name)
        elif name_len < len(name):
            name = name[:name_len]  # the C struct's name is a buffer; name_len says what is valid
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "name_len", name_len)

    @property
    def name_str(self) -> str:
        return self.name.decode("utf-8", "replace")


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Sample(_Message):
    """Plant -> controller once per period: sensors sampled at t = period * T."""

    TYPE: ClassVar[MsgType] = MsgType.SAMPLE
    period: int
    adc_i1: int    # 12-bit ADC counts
    adc_i2: int    # 12-bit ADC counts
    adc_vdc: int   # 12-bit ADC counts
    encoder: int   # quadrature counter, wraps at 65536
    status: int    # STATUS_* (4 bits)


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Gates(_Message):
    """Controller -> plant: the six switch states answering SAMPLE ``period``."""

    TYPE: ClassVar[MsgType] = MsgType.GATES
    period: int
    gates: int     # GATE_*


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Duty(_Message):
    """Controller -> plant: three high-side duty cycles, 0..65535 = 0..1."""

    TYPE: ClassVar[MsgType] = MsgType.DUTY
    period: int
    duty: tuple[int, int, int]


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class DutyLegs(_Message):
    """Controller -> plant: DUTY with a per-leg enable, so a six-step or trapezoidal board can
    float a leg (both switches off) and still answer with one message."""

    TYPE: ClassVar[MsgType] = MsgType.DUTY_LEGS
    period: int
    duty: tuple[int, int, int]   # high-side on-time of each enabled leg, 0..65535 = 0..1
    leg_enable: int              # LEG_* bits; a leg whose bit is 0 is floated


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Command(_Message):
    """Bench -> controller: enable, speed source, speed, torque and flux references."""

    TYPE: ClassVar[MsgType] = MsgType.COMMAND
    flags: int             # CMD_*
    speed_source: int      # SpeedSource
    speed_ref_rad_s: float  # mechanical
    torque_ref_nm: float   # used in torque mode
    flux_ref_wb: float     # stator flux magnitude reference


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Telemetry(_Message):
    """Controller -> bench: the controller's estimates for logging and checks (paper equations)."""

    TYPE: ClassVar[MsgType] = MsgType.TELEMETRY
    period: int
    sector: int            # 1..6, 0 when not switching
    speed_source: int
    state: int             # ControllerState
    gates: int
    speed_feedback_rad_s: float
    speed_encoder_rad_s: float
    speed_raw_rad_s: float     # eq. (11), unfiltered
    speed_lpf_rad_s: float     # eq. (11) low-pass filtered
    speed_ekf_rad_s: float     # eq. (22)
    flux_angle_rad: float      # eq. (10)
    ekf_angle_rad: float       # eq. (21)
    flux_mag_wb: float         # eq. (5)
    torque_est_nm: float       # eq. (6)
    torque_ref_nm: float       # speed regulator output
    rotor_pos_conv_rad: float  # eq. (26) with the eq. (10) angle
    rotor_pos_ekf_rad: float   # eq. (26) with the eq. (21) angle


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class ParamSet(_Message):
    """Bench -> controller: set parameter ``id`` (ParamId) to ``value``."""

    TYPE: ClassVar[MsgType] = MsgType.PARAM_SET
    id: int
    value: float


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class ParamGet(_Message):
    """Bench -> controller: read parameter ``id`` (ParamId)."""

    TYPE: ClassVar[MsgType] = MsgType.PARAM_GET
    id: int


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class ParamValue(_Message):
    """Controller -> bench: parameter ``id``, the ParamStatus of the request and the value now held."""

    TYPE: ClassVar[MsgType] = MsgType.PARAM_VALUE
    id: int
    status: int    # ParamStatus
    value: float


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Status(_Message):
    """Controller -> bench on a change of state: the state and the latched fault at ``period``."""

    TYPE: ClassVar[MsgType] = MsgType.STATUS
    period: int
    state: int       # ControllerState
    fault_code: int  # FaultCode latched, 0 when none


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Fault(_Message):
    """Controller -> bench: fault ``code`` tripped at ``period`` by ``value``."""

    TYPE: ClassVar[MsgType] = MsgType.FAULT
    period: int
    code: int      # FaultCode
    value: float   # the measured value that tripped, SI units


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class Heartbeat(_Message):
    """Either way after 100 ms with nothing else sent (liveness); ``counter`` counts them."""

    TYPE: ClassVar[MsgType] = MsgType.HEARTBEAT
    counter: int


@_fast_init
@dataclass(frozen=True, slots=True, init=False)
class SampleSensors(_Message):
    """Plant -> a controller with CAP_SENSOR_SET once per period, instead of SAMPLE: the
    sensors of its ``sensor_set`` sampled at t = period * T. Only the fields of set bits travel;
    the others are 0 in a decoded message (and not sent, whatever they hold, when encoding)."""

    TYPE: ClassVar[MsgType] = MsgType.SAMPLE_SENSORS
    period: int
    sensor_set: int          # SENSOR_* bits; bits 10-15 reserved
    status: int              # STATUS_* (bits 0-3; 4-7 reserved)
    adc_ia: int = 0          # phase-a current, ADC counts (u16)
    adc_ib: int = 0
    adc_ic: int = 0
    adc_vdc: int = 0         # DC-link voltage, ADC counts
    encoder: int = 0         # quadrature counter, wraps at 65536
    hall: int = 0            # bit 0 Hall A, bit 1 B, bit 2 C
    adc_va: int = 0          # phase-a terminal voltage to DC-, ADC counts
    adc_vb: int = 0
    adc_vc: int = 0
    bemf_comparators: int = 0  # bit x: phase x terminal above the virtual neutral
    adc_resolver_sin: int = 0
    adc_resolver_cos: int = 0
    adc_temperature: int = 0   # winding temperature, ADC counts


@dataclass(frozen=True, slots=True)
class Shutdown(_Message):
    """Bench -> controller: stop switching and exit. No fields."""

    TYPE: ClassVar[MsgType] = MsgType.SHUTDOWN


MESSAGE_CLASSES: dict[MsgType, type] = {
    cls.TYPE: cls
    for cls in (Hello, Sample, Gates, Duty, Command, Telemetry, ParamSet, ParamGet, ParamValue,
                Status, Fault, Heartbeat, Shutdown, DutyLegs, SampleSensors)
}

Message = (Hello | Sample | Gates | Duty | Command | Telemetry | ParamSet | ParamGet | ParamValue
           | Status | Fault | Heartbeat | Shutdown | DutyLegs | SampleSensors)
