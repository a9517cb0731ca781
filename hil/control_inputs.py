"""One gate for every control input, whoever sends it: a viewer's /cmd, a Modbus write, a plan
step, the Python API (``Bench.command``, ``BenchSession.send_command``) and the load and
fault-bit stimuli. Each value is checked here before it reaches the board or the plant:

* a number is a real number (not a bool, not None), finite, and within float32 where it goes
  on the wire (COMMAND carries float32: protocol/SPEC.md);
* it lies within the range the bench profile gives (:class:`ControlLimits`):

  - speed reference: ``|speed_ref_rpm| <= SPEED_REF_LIMIT_FACTOR * motor.rated_speed_rpm``
    (2x rated: room for field weakening and overspeed tests, nowhere near an overflow);
  - load torque and torque reference: ``|T| <= LOAD_TORQUE_LIMIT_FACTOR * T_peak`` with the
    motor's peak torque at the current sensor's full scale I_fs,
    ``T_peak = 1.5 p I_fs (psi_m + |L_d - L_q| I_fs)``, I_fs = a_per_count 2^(bits-1)
    (3x: a load may stall the motor; it may not accelerate the rotor past any float). The
    profile's own load (torque_nm and table) is always within the bound;
  - speed-proportional load: ``0 <= k <= motor.inertia_kgm2 / timing.control_period_s``
    (its time constant J/k at least one control period: a stiffer one the integrator cannot
    follow, and a negative one is a source that runs away);
  - DC-link voltage: ``0 < v <= DC_LINK_LIMIT_FACTOR * dc_link.source_voltage_v``;
  - flux reference: ``0 <= psi <= FLUX_REF_LIMIT_FACTOR * motor.flux_linkage_wb`` (0 = the
    board's own PARAM; the bound is 1 Wb for a magnet-free motor);
  - fault bits: a whole number with only the bits hil.faults.injector.MODBUS_BITS defines.

A refusal is a :class:`ControlInputError` (a ValueError) naming the input, the value, the
range and why; the caller counts it and goes on (``hil serve``) or stops (a plan file at load).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

FLOAT32_MAX = 3.4028234663852886e38
SPEED_REF_LIMIT_FACTOR = 2.0
LOAD_TORQUE_LIMIT_FACTOR = 3.0
DC_LINK_LIMIT_FACTOR = 2.0
FLUX_REF_LIMIT_FACTOR = 3.0
SPEED_SOURCES = ("encoder", "conventional", "ekf")
#: COMMAND fields that go on the wire as float32
WIRE_FLOATS = ("speed_ref_rpm", "torque_ref_nm", "flux_ref_wb")


class ControlInputError(ValueError):
    """A control input refused: `name`, `value` and the reason (with the range) in the text."""

    def __init__(self, name: str, value: Any, why: str):
        self.name, self.value, self.why = name, value, why
        super().__init__(f"{name} = {value!r} refused: {why}")


def _number(name: str, value: Any) -> float:
    """A finite real number as float (a bool is not a number here: JSON true is not 1 rpm)."""
    if type(value) is bool or not isinstance(value, (int, float)):
        raise ControlInputError(name, value, "expected a number")
    try:
        x = float(value)
    except OverflowError:                       # an int beyond any float
        raise ControlInputError(name, value, "not a finite number") from None
    if not math.isfinite(x):
        raise ControlInputError(name, value, "not a finite number")
    return x


def finite_float32(name: str, value: Any) -> float:
    """A number that is finite and fits a float32 (what goes on the wire)."""
    x = _number(name, value)
    if abs(x) > FLOAT32_MAX:
        raise ControlInputError(name, value, f"does not fit a float32 (|x| <= {FLOAT32_MAX:.4g})")
    return x


def _within(name: str, value: Any, low: float, high: float, why: str) -> float:
    """The range first (it says more than float32's), then float32 for an unbounded one."""
    x = _number(name, value)
    if not low <= x <= high:
        raise ControlInputError(name, value, f"outside {low:g} .. {high:g} ({why})")
    return finite_float32(name, x)


def _flag(name: str, value: Any) -> bool:
    if type(value) is bool or (type(value) is int and value in (0, 1)):
        return bool(value)
    raise ControlInputError(name, value, "expected true or false (or 1, 0)")


@dataclass(frozen=True)
class ControlLimits:
    """The ranges of the control inputs (module docstring: the formulas); None = no range
    beyond finite and float32. Picklable: the Modbus port's process gets a copy."""

    speed_ref_max_rpm: float | None = None
    load_torque_max_nm: float | None = None
    dc_link_max_v: float | None = None
    flux_ref_max_wb: float | None = None
    load_damping_max_nm_per_rad_s: float | None = None
    fault_bits_mask: int | None = None
    speed_why: str = ""
    torque_why: str = ""
    dc_why: str = ""
    flux_why: str = ""

    @classmethod
    def from_profile(cls, profile) -> "ControlLimits":
        from hil.faults.injector import MODBUS_BIT_MASK

        m, cur = profile.motor, profile.sensors.current
        i_fs = cur.a_per_count * 2.0 ** (cur.bits - 1)
        t_peak = 1.5 * m.pole_pairs * i_fs * (m.flux_linkage_wb
                                              + abs(m.inductance_d_h - m.inductance_q_h) * i_fs)
        own = [abs(profile.load.torque_nm)] + [abs(v) for _, v in profile.load.table]
        torque = max(LOAD_TORQUE_LIMIT_FACTOR * t_peak, *own)
        flux = FLUX_REF_LIMIT_FACTOR * m.flux_linkage_wb or 1.0
        return cls(
            speed_ref_max_rpm=SPEED_REF_LIMIT_FACTOR * m.rated_speed_rpm,
            load_torque_max_nm=torque,
            dc_link_max_v=DC_LINK_LIMIT_FACTOR * profile.dc_link.source_voltage_v,
            flux_ref_max_wb=flux,
            load_damping_max_nm_per_rad_s=m.inertia_kgm2 / profile.timing.control_period_s,
            fault_bits_mask=MODBUS_BIT_MASK,
            speed_why=f"{SPEED_REF_LIMIT_FACTOR:g} x the motor's rated "
                      f"{m.rated_speed_rpm:g} rpm",
            torque_why=f"{LOAD_TORQUE_LIMIT_FACTOR:g} x the motor's peak torque "
                       f"{t_peak:.3g} N m at the current sensor's {i_fs:g} A full scale",
            dc_why=f"{DC_LINK_LIMIT_FACTOR:g} x the profile's "
                   f"{profile.dc_link.source_voltage_v:g} V source",
            flux_why=(f"{FLUX_REF_LIMIT_FACTOR:g} x the motor's {m.flux_linkage_wb:g} Wb"
                      if m.flux_linkage_wb else "a motor without magnet flux"))

    # ------------------------------------------------------------------ single inputs
    def speed_ref_rpm(self, value: Any, name: str = "speed_ref_rpm") -> float:
        top = self.speed_ref_max_rpm
        if top is None:
            return finite_float32(name, value)
        return _within(name, value, -top, top, self.speed_why)

    def torque_nm(self, value: Any, name: str = "load_torque_nm") -> float:
        top = self.load_torque_max_nm
        if top is None:
            return finite_float32(name, value)
        return _within(name, value, -top, top, self.torque_why)

    def dc_link_voltage_v(self, value: Any, name: str = "dc_link_voltage_v") -> float:
        x = finite_float32(name, value)
        if x <= 0.0:
            raise ControlInputError(name, value, "a DC-link voltage is above 0 V")
        top = self.dc_link_max_v
        if top is not None and x > top:
            raise ControlInputError(name, value, f"outside 0 .. {top:g} ({self.dc_why})")
        return x

    def flux_ref_wb(self, value: Any, name: str = "flux_ref_wb") -> float:
        top = self.flux_ref_max_wb
        return _within(name, value, 0.0, FLOAT32_MAX if top is None else top,
                       self.flux_why or "0 means the board's own")

    def load_damping(self, value: Any, name: str = "nm_per_rad_s") -> float:
        """A speed-proportional load's N m per rad/s (module docstring)."""
        top = self.load_damping_max_nm_per_rad_s
        return _within(name, value, 0.0, FLOAT32_MAX if top is None else top,
                       "time constant J/k at least one control period" if top is not None
                       else "a load proportional to speed brakes: k >= 0")

    def fault_bits(self, value: Any, name: str = "fault_bits") -> int:
        """A whole number >= 0 with only defined bits: -1 or 2^64 + 4 never wrap into faults."""
        if type(value) is bool:
            raise ControlInputError(name, value, "expected a whole number of fault bits")
        if isinstance(value, float):
            if not (math.isfinite(value) and value == int(value)):
                raise ControlInputError(name, value, "expected a whole number of fault bits")
            value = int(value)
        if not isinstance(value, int):
            raise ControlInputError(name, value, "expected a whole number of fault bits")
        if value < 0:
            raise ControlInputError(name, value, "fault bits are >= 0 (one bit per fault)")
        mask = self.fault_bits_mask
        if mask is not None and value & ~mask:
            raise ControlInputError(name, value, f"bits 0x{value & ~mask:x} name no fault "
                                                 f"(defined: 0x{mask:x}, hil/faults/injector.py)")
        return value

    # ------------------------------------------------------------------ a COMMAND's changes
    def command(self, changes: Mapping[str, Any], where: str = "") -> dict[str, Any]:
        """send_command's changes, checked field by field; the normalised values."""
        out: dict[str, Any] = {}
        for key, value in changes.items():
            name = f"{where}{key}"
            if key in ("enable", "torque_mode"):
                out[key] = _flag(name, value)
            elif key == "speed_source":
                if value not in SPEED_SOURCES:
                    raise ControlInputError(name, value, f"expected one of {', '.join(SPEED_SOURCES)}")
                out[key] = value
            elif key == "speed_ref_rpm":
                out[key] = self.speed_ref_rpm(value, name)
            elif key == "torque_ref_nm":
                out[key] = self.torque_nm(value, name)
            elif key == "flux_ref_wb":
                out[key] = self.flux_ref_wb(value, name)
            else:
                out[key] = value          # send_command names unknown fields itself
        return out

    def request(self, name: str, value: Any) -> Any:
        """One mailbox field (hil.ports.modbus.ControlRequests) checked."""
        if name == "run":
            return _flag(name, value)
        if name == "speed_ref_rpm":
            return self.speed_ref_rpm(value)
        if name == "load_torque_nm":
            return self.torque_nm(value)
        if name == "dc_link_voltage_v":
            return self.dc_link_voltage_v(value)
        if name == "fault_bits":
            return self.fault_bits(value)
        raise ControlInputError(name, value, "not a control input")


#: Finite and float32 only: what a plan file can be refused for before a profile is chosen.
UNBOUNDED = ControlLimits()


__all__ = ["ControlInputError", "ControlLimits", "UNBOUNDED", "finite_float32", "FLOAT32_MAX",
           "SPEED_REF_LIMIT_FACTOR", "LOAD_TORQUE_LIMIT_FACTOR", "DC_LINK_LIMIT_FACTOR",
           "FLUX_REF_LIMIT_FACTOR"]
