"""Fault injection: the catalogue, and the three ways to switch a fault.

Every fault in hil/plans/format.py's FAULTS can be switched on (and lifted) from

* a plan step (``- fault: {name: open_phase, phase: a, duration_s: 0.02}``): ``apply_fault``;
* the Modbus control port (holding registers 3-4 ``fault_injection`` or coils 0-31, one bit
  per fault, level-triggered, with the arguments of MODBUS_BITS): ``apply_fault_bits``;
* Python: ``injector(session).inject("open_phase", phase="a", duration_s=0.02)``, ``.clear()``.

Whatever the source, a switch is logged as a ``fault`` event (``/plan/events`` in the MCAP log,
``session.events``) with its name, arguments, source and, on lifting, the reason; the active
set is published as ``fault_bits_active`` to Modbus and recorded as the step signal
``fault.active_bits``. A fault with ``duration_s`` is lifted at the period boundary
``round(duration_s / T)`` periods after it was switched on (counted in simulated periods, so
lockstep and real time lift it after the same number of periods).

A fault acts on the plant (plant_rt's hooks), on the sensors, or on the link (LinkTap). Only
the plant is told: the board must notice by itself, which is the point.
"""
from __future__ import annotations

from dataclasses import field
from types import MappingProxyType
from typing import Any, Callable, Mapping

from hil.session.link_tap import LinkFault
from hil.faults.catalog import FAULTS
from configfile.dataclass_methods import dataclass
from configfile.schema import schema_accepts

#: Modbus ``fault_injection`` bit -> (fault, arguments used when switched from Modbus).
#: A bit written 1 injects the fault (replacing an instance of it switched from elsewhere);
#: written 0 lifts every instance of it. ``fault_bits_active`` reads bit n as 1 while any
#: instance of fault n is active, whatever switched it on.
MODBUS_BITS: dict[int, tuple[str, Mapping[str, Any]]] = {
    0: ("open_phase", {"phase": "a"}),
    1: ("gate_stuck", {"switch": "a_high", "state": "off"}),
    2: ("encoder_lost", {}),
    3: ("encoder_missing_counts", {"fraction": 0.1}),
    4: ("encoder_noise", {"std_counts": 2.0}),
    5: ("encoder_index_missing", {}),
    6: ("sensor_offset", {"sensor": "adc_i1", "offset_counts": 82}),      # +1.0 A
    7: ("sensor_gain", {"sensor": "adc_i1", "gain": 1.1}),
    8: ("sensor_stuck", {"sensor": "adc_i1"}),                            # at its reading
    9: ("sensor_saturation", {"sensor": "adc_i1", "low_counts": 1229, "high_counts": 2867}),  # +-10 A
    10: ("sensor_noise", {"sensor": "adc_i1", "std_counts": 10.0}),
    11: ("dc_link_sag", {"fraction": 0.7}),
    12: ("dc_link_surge", {"fraction": 1.2}),
    13: ("dc_link_ripple", {"amplitude_v": 7.0, "frequency_hz": 300.0}),
    14: ("parameter_drift", {"parameter": "resistance_ohm", "factor": 1.5}),
    15: ("link_drop", {"rate": 0.1}),
    16: ("link_corrupt", {"rate": 0.01}),
    17: ("link_delay", {"periods": 1}),
    18: ("link_duplicate", {"rate": 0.01}),
    19: ("link_reorder", {"rate": 0.01}),
    20: ("link_unplug", {}),
    21: ("hall_stuck", {"sensor": "a", "level": 1}),
    22: ("bemf_comparator_stuck", {"phase": "a", "level": 1}),
}
BIT_OF = {name: bit for bit, (name, _) in MODBUS_BITS.items()}
MODBUS_BIT_MASK = sum(1 << bit for bit in MODBUS_BITS)

#: The argument that says what a fault acts on: two instances of a fault on different targets
#: coexist (an offset on adc_i1 and one on adc_vdc); on the same target the newer replaces.
TARGET_KEYS = {"gate_stuck": "switch", "sensor_offset": "sensor", "sensor_gain": "sensor",
               "sensor_stuck": "sensor", "sensor_saturation": "sensor", "sensor_noise": "sensor",
               "parameter_drift": "parameter", "hall_stuck": "sensor",
               "bemf_comparator_stuck": "phase"}
#: Faults of one kind that cannot coexist although their targets differ.
_EXCLUSIVE = {"dc_link_sag": "dc_level", "dc_link_surge": "dc_level"}

LINK_KINDS = {"link_drop": "drop", "link_corrupt": "corrupt", "link_delay": "delay",
              "link_duplicate": "duplicate", "link_reorder": "reorder", "link_unplug": "unplug"}

_SENSOR_CHANNELS = {"adc_i1": "i1", "adc_i2": "i2", "adc_vdc": "vdc"}

#: One line per fault for the docs and `hil plans`-style listings.
DESCRIPTIONS = {
    "open_phase": "phase disconnected from its leg: its current is zero, the other two opposite",
    "gate_stuck": "one switch stuck on or off whatever the board commands",
    "encoder_lost": "encoder counter frozen at its present count",
    "encoder_missing_counts": "each encoder edge lost with probability `fraction` (counts accumulate)",
    "encoder_noise": "encoder count jitters by Gaussian `std_counts` (does not accumulate)",
    "encoder_index_missing": "the index pulse (SAMPLE status bit 0x1) never reaches the board",
    "sensor_offset": "ADC zero moved by `offset_counts`",
    "sensor_gain": "transducer gain multiplied by `gain`",
    "sensor_stuck": "ADC returns `value_counts` (default: its last reading) whatever its input",
    "sensor_saturation": "ADC codes clamped to [`low_counts`, `high_counts`]",
    "sensor_noise": "extra Gaussian noise of `std_counts` rms (added in quadrature)",
    "dc_link_sag": "source voltage to `fraction` of nominal over `ramp_s`",
    "dc_link_surge": "source voltage to `fraction` (>= 1) of nominal over `ramp_s`",
    "dc_link_ripple": "source voltage + `amplitude_v` sin(2 pi `frequency_hz` t)",
    "parameter_drift": "motor constant (or load torque) times `factor`, linearly over `ramp_s`",
    "link_drop": "frames lost with probability `rate`",
    "link_corrupt": "frames with `bits` bits flipped with probability `rate`",
    "link_delay": "frames held back `periods` control periods",
    "link_duplicate": "frames sent twice with probability `rate`",
    "link_reorder": "a frame swapped with the next one with probability `rate`",
    "link_unplug": "every frame lost (the cable is out); use with `duration_s`",
    "hall_stuck": "Hall sensor `sensor` (a/b/c) reads `level` (0/1) whatever the rotor's angle",
    "bemf_comparator_stuck": "phase `phase`'s BEMF comparator reads `level` (0/1) whatever its inputs",
}

#: fault -> its arguments' jsonschema validator, made when a fault's arguments are first found
#: wrong (valid ones pass schema_accepts): hil.plans.format imports this module through the
#: catalogue, and jsonschema's import is ~0.1 s of a run that injects nothing.
_VALIDATORS: dict[str, Any] = {}


def _validator(name: str):
    validator = _VALIDATORS.get(name)
    if validator is None:
        from jsonschema import Draft202012Validator

        validator = _VALIDATORS[name] = Draft202012Validator(FAULTS[name])
    return validator


@dataclass
class ActiveFault:
    """One fault in effect."""

    name: str
    key: str
    args: Mapping[str, Any]
    source: str                      # plan | modbus | python
    start_period: int
    until_period: int | None         # lifted at this period boundary (None: until cleared)
    undo: Callable[[], None] = field(repr=False)


class FaultInjector:
    """The faults of one session: switch them on, lift them, lift them on time.

    >>> inj = injector(session)
    >>> inj.inject("sensor_offset", sensor="adc_i1", offset_counts=40, duration_s=0.01)
    'sensor_offset:adc_i1'
    >>> inj.clear("sensor_offset")         # or inj.clear() for every fault
    """

    def __init__(self, session):
        self.session = session
        self.active: dict[str, ActiveFault] = {}
        self.history: list[dict[str, Any]] = []
        self.modbus_bits = 0
        self._next_due: int | None = None
        self._ticking = False
        self._tap_ticking = False

    # ------------------------------------------------------------------ API
    @property
    def bits(self) -> int:
        """Modbus bit n set while any instance of fault MODBUS_BITS[n] is active."""
        out = 0
        for fault in self.active.values():
            out |= 1 << BIT_OF[fault.name]
        return out

    def inject(self, name: str, *, duration_s: float | None = None, source: str = "python",
               **args: Any) -> str:
        """Switches fault ``name`` on with its arguments (hil/plans/format.py FAULTS); returns its key."""
        args = validate(name, args, duration_s)
        session = self.session
        plant = session.plant
        key = _key(name, args)
        for other in [k for k, f in self.active.items()
                      if k == key or (_EXCLUSIVE.get(f.name) is not None
                                      and _EXCLUSIVE.get(f.name) == _EXCLUSIVE.get(name))]:
            self._lift(other, "replaced", source)
        undo = _APPLY[name](self, args)
        until = None
        if duration_s is not None:
            until = plant.period + max(1, round(duration_s / session.period_s))
        self.active[key] = ActiveFault(name, key, MappingProxyType(dict(args)), source,
                                       plant.period, until, undo)
        record = {"action": "inject", "name": name, "key": key, "source": source,
                  "period": plant.period, "duration_s": duration_s, **args}
        self.history.append(record)
        session.event("fault", **record)
        self._changed()
        return key

    def clear(self, name: str | None = None, *, source: str = "python") -> list[str]:
        """Lifts every active instance of ``name`` (every fault when None); returns the keys."""
        if name is not None and name not in FAULTS:
            raise ValueError(f"unknown fault '{name}' (known: {', '.join(FAULTS)})")
        keys = [k for k, f in self.active.items() if name is None or f.name == name]
        for key in keys:
            self._lift(key, "cleared", source)
        self._changed()
        return keys

    def detach(self) -> None:
        """The session is over: no more timed lifting (the plant keeps its faults)."""
        plant = self.session.plant
        if self._ticking:
            plant.remove_period_hook(self._tick)
            self._ticking = False
        if self._tap_ticking:
            plant.remove_period_hook(self.session.tap.tick)
            self._tap_ticking = False
        self._next_due = None

    # ------------------------------------------------------------ internals
    def _lift(self, key: str, reason: str, source: str) -> None:
        fault = self.active.pop(key)
        fault.undo()
        record = {"action": "lift", "name": fault.name, "key": key, "source": source,
                  "reason": reason, "period": self.session.plant.period}
        self.history.append(record)
        self.session.event("fault", **record)

    def _changed(self) -> None:
        session = self.session
        session.fault_bits = self.bits
        session.recorder.step_value("fault.active_bits", session.plant.period, session.fault_bits)
        dues = [f.until_period for f in self.active.values() if f.until_period is not None]
        self._next_due = min(dues) if dues else None
        plant = session.plant
        if self._next_due is not None and not self._ticking:
            plant.add_period_hook(self._tick, "after")
            self._ticking = True
        elif self._next_due is None and self._ticking:
            plant.remove_period_hook(self._tick)
            self._ticking = False
        # The real-time loop does not tick the tap (lockstep does, before each SAMPLE):
        # delayed frames must still come out and expired faults go.
        tap = session.tap
        wants_tap = (tap is not None and session.config.mode == "realtime"
                     and any(f.name in LINK_KINDS for f in self.active.values()))
        if wants_tap and not self._tap_ticking:
            plant.add_period_hook(tap.tick, "after")
            self._tap_ticking = True
        elif not wants_tap and self._tap_ticking:
            plant.remove_period_hook(tap.tick)
            self._tap_ticking = False

    def _tick(self, period: int) -> None:
        """After each plant step while a timed fault is active: lifts the ones due."""
        if self._next_due is None or period < self._next_due:
            return
        for key in [k for k, f in self.active.items()
                    if f.until_period is not None and f.until_period <= period]:
            self._lift(key, "duration", self.active[key].source)
        self._changed()


def injector(session) -> FaultInjector:
    """The session's fault injector (created on first use)."""
    inj = getattr(session, "fault_injector", None)
    if inj is None:
        inj = session.fault_injector = FaultInjector(session)
    return inj


def apply_fault(session, step) -> None:
    """A plan's ``fault`` step (hil.plans.format.FaultStep)."""
    inj = injector(session)
    if step.clear:
        inj.clear(step.name, source="plan")
    else:
        inj.inject(step.name, duration_s=step.duration_s, source="plan", **dict(step.args))


def apply_fault_bits(session, bits: int) -> None:
    """The Modbus ``fault_injection`` word as written (level-triggered, MODBUS_BITS)."""
    inj = injector(session)
    bits = int(bits)
    unknown = bits & ~MODBUS_BIT_MASK
    if unknown:
        session.event("fault_bits_refused", bits=bits, unknown_bits=unknown)
        bits &= MODBUS_BIT_MASK
    changed = bits ^ inj.modbus_bits
    inj.modbus_bits = bits
    for bit in sorted(MODBUS_BITS):
        if not changed & (1 << bit):
            continue
        name, args = MODBUS_BITS[bit]
        if bits & (1 << bit):
            inj.inject(name, source="modbus", **dict(args))
        else:
            inj.clear(name, source="modbus")


def validate(name: str, args: Mapping[str, Any], duration_s: float | None = None) -> dict:
    """The arguments checked against the plan schema; ValueError names the fault and the key."""
    if name not in FAULTS:
        raise ValueError(f"unknown fault '{name}' (known: {', '.join(FAULTS)})")
    args = dict(args)
    probe = dict(args)
    if duration_s is not None:
        probe["duration_s"] = duration_s
    if schema_accepts(FAULTS[name], probe):
        return args
    errors = sorted(_validator(name).iter_errors(probe), key=lambda e: list(e.path))
    if errors:
        err = errors[0]
        where = ".".join(str(p) for p in err.path) or "arguments"
        raise ValueError(f"fault '{name}', {where}: {err.message}")
    return args


def _key(name: str, args: Mapping[str, Any]) -> str:
    target = TARGET_KEYS.get(name)
    return f"{name}:{args[target]}" if target else name


# --------------------------------------------------------------------------- the faults
# Each takes (injector, args), switches the fault on and returns the function that lifts it.

def _open_phase(inj: FaultInjector, args) -> Callable[[], None]:
    plant = inj.session.plant
    before = plant.open_phase
    plant.set_open_phase(args["phase"])
    return lambda: plant.set_open_phase(before)


def _gate_stuck(inj: FaultInjector, args) -> Callable[[], None]:
    plant = inj.session.plant
    before = plant.gates_stuck.get(args["switch"])
    plant.set_gate_stuck(args["switch"], args["state"])
    return lambda: plant.set_gate_stuck(args["switch"], before)


def _encoder_lost(inj: FaultInjector, args) -> Callable[[], None]:
    plant = inj.session.plant
    enc = plant.sensors.encoder
    before = enc.stuck_counts
    enc.stuck_counts = plant.encoder_count()

    def undo() -> None:
        enc.stuck_counts = before
    return undo


def _encoder_missing(inj: FaultInjector, args) -> Callable[[], None]:
    enc = inj.session.plant.sensors.encoder
    enc.set_missing_counts(args["fraction"], args.get("seed", inj.session.config.seed))
    return lambda: enc.set_missing_counts(0.0)


def _encoder_noise(inj: FaultInjector, args) -> Callable[[], None]:
    enc = inj.session.plant.sensors.encoder
    enc.set_noise(args["std_counts"], args.get("seed", inj.session.config.seed))
    return lambda: enc.set_noise(0.0)


def _encoder_index(inj: FaultInjector, args) -> Callable[[], None]:
    enc = inj.session.plant.sensors.encoder
    enc.index_missing = True

    def undo() -> None:
        enc.index_missing = False
    return undo


def _channel(inj: FaultInjector, args):
    return getattr(inj.session.plant.sensors, _SENSOR_CHANNELS[args["sensor"]])


def _restore(channel, attr: str, value) -> Callable[[], None]:
    return lambda: setattr(channel, attr, value)


def _sensor_offset(inj: FaultInjector, args) -> Callable[[], None]:
    ch = _channel(inj, args)
    before = ch.offset_counts
    ch.offset_counts = before + float(args["offset_counts"])
    return _restore(ch, "offset_counts", before)


def _sensor_gain(inj: FaultInjector, args) -> Callable[[], None]:
    ch = _channel(inj, args)
    before = ch.gain
    ch.gain = before * float(args["gain"])
    return _restore(ch, "gain", before)


def _sensor_stuck(inj: FaultInjector, args) -> Callable[[], None]:
    ch = _channel(inj, args)
    before = ch.stuck_counts
    value = args.get("value_counts")
    if value is None:
        last = inj.session.plant.last_sample
        value = getattr(last, args["sensor"]) if last is not None else ch.convert(0.0)
    ch.stuck_counts = int(value)
    return _restore(ch, "stuck_counts", before)


def _sensor_saturation(inj: FaultInjector, args) -> Callable[[], None]:
    ch = _channel(inj, args)
    before = ch.saturation
    low = int(args.get("low_counts", 0))
    high = int(args.get("high_counts", ch.max_code))
    if low > high:
        raise ValueError(f"fault 'sensor_saturation': low_counts {low} > high_counts {high}")
    ch.saturation = (low, min(high, ch.max_code))
    return _restore(ch, "saturation", before)


def _sensor_noise(inj: FaultInjector, args) -> Callable[[], None]:
    ch = _channel(inj, args)
    ch.set_extra_noise(float(args["std_counts"]), args.get("seed"))
    return ch.clear_extra_noise


def _dc_level(inj: FaultInjector, args) -> Callable[[], None]:
    session = inj.session
    plant = session.plant
    before = plant.dc_source_voltage_v
    ramp_s = float(args.get("ramp_s", 0.0))
    plant.ramp_dc_voltage(args["fraction"] * session.profile.dc_link.source_voltage_v, ramp_s)
    return lambda: plant.ramp_dc_voltage(before, ramp_s)


def _dc_ripple(inj: FaultInjector, args) -> Callable[[], None]:
    plant = inj.session.plant
    plant.set_dc_ripple(args["amplitude_v"], args["frequency_hz"])
    return lambda: plant.set_dc_ripple(0.0, 0.0)


def _parameter_drift(inj: FaultInjector, args) -> Callable[[], None]:
    plant = inj.session.plant
    name, factor = args["parameter"], float(args["factor"])
    ramp_s = float(args.get("ramp_s", 0.0))
    if name == "load_torque_nm":
        # The load's time profile from now on (its speed-proportional part is not scaled).
        load = plant.load
        present = load.profile(plant.t_s)
        # a load stimulus like any other: within the profile's range (hil/control_inputs.py)
        inj.session.control_limits.torque_nm(present * factor, "parameter_drift load_torque_nm")
        load.set_ramp(present * factor, ramp_s)
        return lambda: load.set_ramp(present, ramp_s)
    # inductance_h drifts both axes, each from its own value.
    names = ("ld_h", "lq_h") if name == "inductance_h" else (name,)
    before = {n: plant.motor_param(n) for n in names}
    for n, value in before.items():
        plant.ramp_motor_param(n, value * factor, ramp_s)

    def undo() -> None:
        for n, value in before.items():
            plant.ramp_motor_param(n, value, ramp_s)
    return undo


_PHASE_INDEX = {"a": 0, "b": 1, "c": 2}


def _stuck_level(levels, index: int, level: int) -> Callable[[], None]:
    """levels[index] (None: working) held at `level`; the undo restores what it was."""
    before = levels[index]
    levels[index] = int(level)

    def undo() -> None:
        levels[index] = before
    return undo


def _hall_stuck(inj: FaultInjector, args) -> Callable[[], None]:
    hall = inj.session.plant.sensors.hall
    return _stuck_level(hall.stuck, _PHASE_INDEX[args["sensor"]], args["level"])


def _comparator_stuck(inj: FaultInjector, args) -> Callable[[], None]:
    terminal = inj.session.plant.sensors.terminal
    return _stuck_level(terminal.comparator_stuck, _PHASE_INDEX[args["phase"]], args["level"])


def _link(inj: FaultInjector, args, name: str) -> Callable[[], None]:
    session = inj.session
    tap = session.tap
    if tap is None:
        raise ValueError(f"fault '{name}' needs a link that carries bytes; '{session.config.link}' "
                         f"is not tapped (CAN links carry frames)")
    key = f"fault:{name}"
    tap.set_fault(key, LinkFault(LINK_KINDS[name], rate=float(args.get("rate", 1.0)),
                                 bits=int(args.get("bits", 1)), periods=int(args.get("periods", 1)),
                                 direction=args.get("direction", "both"), seed=args.get("seed")))
    return lambda: tap.clear_fault(key)


_APPLY: dict[str, Callable[[FaultInjector, Mapping[str, Any]], Callable[[], None]]] = {
    "open_phase": _open_phase,
    "gate_stuck": _gate_stuck,
    "encoder_lost": _encoder_lost,
    "encoder_missing_counts": _encoder_missing,
    "encoder_noise": _encoder_noise,
    "encoder_index_missing": _encoder_index,
    "sensor_offset": _sensor_offset,
    "sensor_gain": _sensor_gain,
    "sensor_stuck": _sensor_stuck,
    "sensor_saturation": _sensor_saturation,
    "sensor_noise": _sensor_noise,
    "dc_link_sag": _dc_level,
    "dc_link_surge": _dc_level,
    "dc_link_ripple": _dc_ripple,
    "parameter_drift": _parameter_drift,
    "hall_stuck": _hall_stuck,
    "bemf_comparator_stuck": _comparator_stuck,
    **{name: (lambda inj, args, name=name: _link(inj, args, name)) for name in LINK_KINDS},
}

__all__ = ["FaultInjector", "ActiveFault", "injector", "apply_fault", "apply_fault_bits",
           "validate", "MODBUS_BITS", "MODBUS_BIT_MASK", "BIT_OF", "DESCRIPTIONS", "LINK_KINDS"]
