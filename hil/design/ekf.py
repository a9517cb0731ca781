"""Steady-state gains k1, k2, k3 of the simplified EKF, eq. (19)-(23).

The paper pre-computes the gains with Matlab's DLQE. For the model of
eq. (17)-(18), x = [theta_s, w, w'], F = [[1, T, 0], [0, 1, 1], [0, 0, 1]],
the innovation eq. (20) is sin(theta_s - theta^) ~ theta_s - theta^, so the
filter is a steady-state Kalman filter with H = [1, 0, 0] and a scalar angle
measurement. The discrete algebraic Riccati equation gives the a-priori error
covariance P; DLQE's innovation gain is M = P H^T / (H P H^T + R), and the
recursion (21)-(23) is the one-step predictor x^(k+1) = F x^(k) + K eps(k),
so the shipped gains are K = F M.

Noise model (docs/stub.md, "EKF gains"):
- process noise enters only w' (the speed change per period): its standard
  deviation is the per-period change of w' when the torque slews from zero to
  the limit in the DTC torque rise time, sigma_w = (p T_lim / J) T^2 / tau;
- measurement noise is the flux-angle ripple of hysteresis DTC: one period's
  flux step (2/3 Vdc T) seen from the flux circle, uniformly distributed,
  sigma_v = (2/3 Vdc T) / (psi_ref sqrt 3).

Run ``python -m hil.design.ekf`` to print the gains as the C defaults.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EkfNoiseModel:
    """Physical data the default covariances are derived from (Table 1 motor)."""

    control_period_s: float = 50e-6
    pole_pairs: int = 1
    torque_limit_nm: float = 2.0
    inertia_kg_m2: float = 8.0e-4
    torque_rise_time_s: float = 1.0e-3
    dc_link_v: float = 70.0
    magnet_flux_wb: float = 0.0928
    stator_inductance_h: float = 4.8e-3

    def flux_ref_wb(self) -> float:
        """The stub's default flux reference: the id = 0 stator flux at half the torque limit."""
        iq_a = 0.5 * self.torque_limit_nm / (1.5 * self.pole_pairs * self.magnet_flux_wb)
        return math.hypot(self.magnet_flux_wb, self.stator_inductance_h * iq_a)

    def speed_increment_std_rad_s(self) -> float:
        """sigma_w: per-period change of w' (electrical rad/s per period)."""
        accel_rad_s2 = self.pole_pairs * self.torque_limit_nm / self.inertia_kg_m2
        return accel_rad_s2 * self.control_period_s**2 / self.torque_rise_time_s

    def angle_std_rad(self) -> float:
        """sigma_v: flux-angle ripple of one active vector per period."""
        step_wb = 2.0 / 3.0 * self.dc_link_v * self.control_period_s
        return step_wb / (self.flux_ref_wb() * math.sqrt(3.0))


@dataclass(frozen=True)
class EkfGains:
    k1: float
    k2_rad_s: float
    k3_rad_s: float
    covariance: np.ndarray  # a-priori P from the Riccati equation
    poles_rad_s: tuple[float, ...]  # |s| of the closed-loop estimator poles


def transition_matrix(control_period_s: float) -> np.ndarray:
    """F of eq. (17)."""
    return np.array([[1.0, control_period_s, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])


def design_gains(control_period_s: float, angle_var_rad2: float, speed_increment_var: float) -> EkfGains:
    """DLQE by the discrete Riccati equation: K = F P H^T / (H P H^T + R)."""
    from scipy.linalg import solve_discrete_are

    if control_period_s <= 0.0 or angle_var_rad2 <= 0.0 or speed_increment_var <= 0.0:
        raise ValueError(
            f"period and variances must be positive, got T={control_period_s}, "
            f"R={angle_var_rad2}, Q={speed_increment_var}"
        )
    f = transition_matrix(control_period_s)
    h = np.array([[1.0, 0.0, 0.0]])
    q = np.diag([0.0, 0.0, speed_increment_var])
    r = np.array([[angle_var_rad2]])
    p = solve_discrete_are(f.T, h.T, q, r)
    m = p @ h.T / (h @ p @ h.T + r).item()
    k = (f @ m).ravel()
    poles = np.linalg.eigvals(f - np.outer(k, h))
    poles_rad_s = tuple(sorted(float(abs(np.log(z.astype(complex)))) / control_period_s for z in poles))
    return EkfGains(float(k[0]), float(k[1]), float(k[2]), p, poles_rad_s)


def default_gains(model: EkfNoiseModel = EkfNoiseModel()) -> EkfGains:
    """The gains the stub ships with (firmware_stub/core/defaults.h)."""
    return design_gains(
        model.control_period_s, model.angle_std_rad() ** 2, model.speed_increment_std_rad_s() ** 2
    )


def main() -> int:
    model = EkfNoiseModel()
    g = default_gains(model)
    print(f"/* hil/design/ekf.py: sigma_v = {model.angle_std_rad():.6g} rad, "
          f"sigma_w = {model.speed_increment_std_rad_s():.6g} rad/s per period; "
          f"estimator poles {', '.join(f'{w:.1f}' for w in g.poles_rad_s)} rad/s */")
    # 9 significant digits of the float32 value: the C literal parses back to exactly it
    for name, value in (("K1", g.k1), ("K2_RAD_S", g.k2_rad_s), ("K3_RAD_S", g.k3_rad_s)):
        print(f"#define CTL_DEFAULT_EKF_{name} {float(np.float32(value)):.9g}f")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
