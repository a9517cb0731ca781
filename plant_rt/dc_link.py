"""DC link: a voltage source behind a resistance, an optional bus capacitor, optionally a
rectifier that cannot take energy back.

    ideal (default):            v_dc = U                      (the paper's 70 V)
    resistance, no capacitor:   v_dc = U - R_s i_dc           (i_dc drawn by the inverter)
    resistance and capacitor:   C dv_dc/dt = i_src - i_dc,  i_src = (U - v_dc)/R_s
    unidirectional source:      i_src = max(0, (U - v_dc)/R_s), so regenerated energy
                                charges the capacitor and raises v_dc above U

A unidirectional source needs both a capacitor (something must take the returned current) and
a source resistance (an ideal diode into an ideal source is a hybrid constraint, not an ODE).
"""
from __future__ import annotations

from configfile.dataclass_methods import dataclass

from configfile.fields import param


@dataclass(frozen=True)
class DcLinkParams:
    source_voltage_v: float = param(70.0, ge=0)
    source_resistance_ohm: float = param(0.0, ge=0)
    capacitance_f: float = param(0.0, ge=0)
    unidirectional: bool = param(False)

    def problems(self) -> list[tuple[str, str]]:
        """(key, message) for combinations that cannot be simulated."""
        out = []
        if self.unidirectional and self.capacitance_f <= 0.0:
            out.append(("capacitance_f", "a unidirectional source needs a bus capacitance > 0"))
        if self.unidirectional and self.source_resistance_ohm <= 0.0:
            out.append(("source_resistance_ohm",
                        "a unidirectional source needs a source resistance > 0"))
        return out


class DcLink:
    """Runtime DC link. `dynamic`: v_dc is a state; `resistive`: v_dc = U - R_s i_dc."""

    __slots__ = ("params", "source_v", "rs", "c", "ic", "unidirectional", "dynamic", "resistive")

    def __init__(self, params: DcLinkParams):
        self.params = params
        self.source_v = params.source_voltage_v
        self.rs = params.source_resistance_ohm
        self.c = params.capacitance_f
        self.ic = 1.0 / self.c if self.c > 0.0 else 0.0
        self.unidirectional = params.unidirectional
        self.dynamic = self.c > 0.0 and self.rs > 0.0
        self.resistive = self.rs > 0.0 and not self.dynamic

    @property
    def ideal(self) -> bool:
        return not self.dynamic and not self.resistive

    def voltage(self, state_v: float, i_dc: float) -> float:
        """Bus voltage given the capacitor state (used when dynamic) and the inverter current."""
        if self.dynamic:
            return state_v
        if self.resistive:
            return self.source_v - self.rs * i_dc
        return self.source_v

    def source_current(self, v: float) -> float:
        i = (self.source_v - v) / self.rs
        return 0.0 if self.unidirectional and i < 0.0 else i

    def dv_dt(self, v: float, i_dc: float) -> float:
        return (self.source_current(v) - i_dc) * self.ic if self.dynamic else 0.0

    def stiff_step_s(self) -> float:
        """Largest RK4 step that resolves the R_s C time constant (inf when none)."""
        return 0.5 * self.rs * self.c if self.dynamic else float("inf")
