"""The winding's temperature: a first-order thermal network heated by the copper loss.

    C_th dT/dt = P_cu - (T - T_amb) / R_th              T in degC, P in W
    P_cu = 3/2 R(T) |i_alphabeta|^2                     amplitude-invariant Clarke (eq. (7))
    R(T) = R_ref (1 + alpha (T - T_ref))                R_ref: the profile's resistance_ohm

Advanced once per control period exactly for the loss held over the period:
T_{k+1} = T_inf + (T_k - T_inf) exp(-T / (R_th C_th)), T_inf = T_amb + P R_th.
Off by default (the profile's `thermal:` section); the plant then never calls it.
"""
from __future__ import annotations

import math

from configfile.dataclass_methods import dataclass
from configfile.fields import param


@dataclass(frozen=True)
class ThermalParams:
    """The profile's thermal section."""

    enabled: bool = param(False)
    thermal_resistance_k_per_w: float = param(2.0, gt=0)
    thermal_capacitance_j_per_k: float = param(50.0, gt=0)
    ambient_degc: float = param(25.0, ge=-273.15, le=1000.0)
    initial_degc: float = param(25.0, ge=-273.15, le=1000.0)
    reference_degc: float = param(20.0, ge=-273.15, le=1000.0)
    copper_alpha_per_k: float = param(0.00393, ge=0, le=0.1)


class ThermalModel:
    """State: the winding temperature temperature_degc. resistance_ohm() is R(T) for the
    reference resistance it was built with."""

    __slots__ = ("params", "temperature_degc", "reference_resistance_ohm", "_decay", "_period_s")

    def __init__(self, params: ThermalParams, reference_resistance_ohm: float, period_s: float):
        self.params = params
        self.temperature_degc = params.initial_degc
        self.reference_resistance_ohm = reference_resistance_ohm
        self._period_s = period_s
        self._decay = math.exp(-period_s / (params.thermal_resistance_k_per_w
                                            * params.thermal_capacitance_j_per_k))

    def resistance_ohm(self) -> float:
        """R(T) = R_ref (1 + alpha (T - T_ref)), ohm, at the present temperature."""
        p = self.params
        return self.reference_resistance_ohm * (
            1.0 + p.copper_alpha_per_k * (self.temperature_degc - p.reference_degc))

    def copper_loss_w(self, i_alpha: float, i_beta: float) -> float:
        """P_cu = 3/2 R(T) (i_alpha^2 + i_beta^2), W."""
        return 1.5 * self.resistance_ohm() * (i_alpha * i_alpha + i_beta * i_beta)

    def advance(self, loss_w: float) -> float:
        """One control period with loss_w held; returns the new temperature (degC)."""
        p = self.params
        settled = p.ambient_degc + loss_w * p.thermal_resistance_k_per_w
        self.temperature_degc = settled + (self.temperature_degc - settled) * self._decay
        return self.temperature_degc
