"""The paper plans' limits on the hardware-like profile, derived (issue 15): what the errors
no compensation in the stub removes do to its flux observer, at each plan's operating point.
Prints the values written into test_plans/0[1-6]*.yaml's descriptions and `profile_limits`.

The errors (plant_rt/profiles/paper-hardware.yaml against the board's controller section):
the winding is warm (R = 0.5592 ohm) where the board keeps 0.466, and the current reading is
0.5 % high, so the observer's R i is short by dR = 0.5592 - 1.005 x 0.466; the DC-link reading
is high by e_v = (1.008 v + 0.6 V) / v - 1. The current offsets are calibrated at start-up
(CURRENT_ZERO_CAL_PERIODS) and the inverter and delay are compensated, so they are left out.

Rotor frame, d along the magnet, surface magnets (L_d = L_q = L). The observer integrates
v_hat - R_board i_hat; its error grows at dR i and turns with the frame at w_e, while the
drift compensation (flux_observer.c) pulls the rotor-flux estimate's length back to psi_f at
2 w0 per unit of relative error (w0 = 2 pi x FLUX_DRIFT_CUTOFF_HZ). In steady state the error
(x along d, y along q) solves j w_e (x + j y) + 2 w0 x = dR (i_d + j i_q):

    x = dR i_q / w_e,    y = (2 w0 x - dR i_d) / w_e

and the estimate is psi_hat = (1 + e_v) psi + (x, y). The board holds |psi_hat| at its flux
reference and its eq. (6) torque 1.5 p (psi_hat x i_hat) at its torque reference (or the load
sets i_q). A fixed-point iteration on i_d gives the true flux, the true torque, and the
rotor-position error of eq. (24)-(26) (flux angle of psi_hat minus the eq. (25) load angle of
the estimated torque and flux). Nothing here runs the bench.
"""
from __future__ import annotations

import math

R_WARM_OHM = 0.5592
R_BOARD_OHM = 0.466
CURRENT_GAIN = 1.005
VDC_GAIN, VDC_OFFSET_V = 1.008, 0.6
L_H = 4.8e-3
PSI_F_WB = 0.0928
DAMPING = 1e-4
DRIFT_W0 = 2 * math.pi * 10.0
POLE_PAIRS = 1


def operating_point(rpm: float, vdc_v: float, flux_ref_wb: float, *, load_nm: float | None = None,
                    torque_estimate_nm: float | None = None) -> dict:
    """The steady state at `rpm`: with the load setting the true torque, or with the board
    holding its torque estimate (at its limit)."""
    w_e = rpm / 60 * 2 * math.pi * POLE_PAIRS
    e_v = (VDC_GAIN * vdc_v + VDC_OFFSET_V) / vdc_v - 1
    d_r = R_WARM_OHM - CURRENT_GAIN * R_BOARD_OHM

    def state(i_q: float) -> dict:
        i_d = 0.0
        for _ in range(60):
            x = d_r * i_q / w_e
            y = (2 * DRIFT_W0 * x - d_r * i_d) / w_e
            psi_q_hat = (1 + e_v) * L_H * i_q + y
            psi_d_hat = math.sqrt(flux_ref_wb ** 2 - psi_q_hat ** 2)
            psi_d = (psi_d_hat - x) / (1 + e_v)
            i_d = (psi_d - PSI_F_WB) / L_H
        torque_hat = 1.5 * POLE_PAIRS * CURRENT_GAIN * (psi_d_hat * i_q - psi_q_hat * i_d)
        load_angle_hat = math.asin(2 * L_H * torque_hat / (3 * POLE_PAIRS * flux_ref_wb * PSI_F_WB))
        return {"i_q_a": i_q, "i_d_a": i_d, "x_mwb": x * 1e3, "y_mwb": y * 1e3, "e_v": e_v,
                "true_flux_mwb": math.hypot(psi_d, L_H * i_q) * 1e3,
                "true_torque_nm": 1.5 * POLE_PAIRS * PSI_F_WB * i_q, "torque_estimate_nm": torque_hat,
                "flux_angle_hat_rad": math.atan2(psi_q_hat, psi_d_hat),
                "rotor_position_error_deg": math.degrees(math.atan2(psi_q_hat, psi_d_hat) - load_angle_hat)}

    if load_nm is not None:
        return state((load_nm + DAMPING * w_e / POLE_PAIRS) / (1.5 * POLE_PAIRS * PSI_F_WB))
    lo, hi = 0.1, 30.0
    for _ in range(80):
        mid = (lo + hi) / 2
        if state(mid)["torque_estimate_nm"] > torque_estimate_nm:
            hi = mid
        else:
            lo = mid
    return state(lo)


def ramp_drift(rpm_a: float, rpm_b: float, torque_limit_nm: float = 2.0) -> dict:
    """On the torque-limited ramp: how fast the estimated flux angle drifts against the rotor,
    d(theta_hat - theta_r)/dw, and the speed-estimate bias and extra lag it gives."""
    a = operating_point(rpm_a, 70.0, 0.099, torque_estimate_nm=torque_limit_nm)
    b = operating_point(rpm_b, 70.0, 0.099, torque_estimate_nm=torque_limit_nm)
    dw = (rpm_b - rpm_a) / 60 * 2 * math.pi
    slope = (b["flux_angle_hat_rad"] - a["flux_angle_hat_rad"]) / dw
    accel = (a["true_torque_nm"] - DAMPING * rpm_a / 60 * 2 * math.pi) / 8.0e-4
    bias = slope * accel
    return {"dtheta_dw_s": slope, "accel_rad_s2": accel, "speed_bias_rad_s": bias,
            "speed_bias_rpm": bias * 60 / (2 * math.pi), "extra_lag_ms": -bias / accel * 1e3}


def run(quick: bool = False) -> dict:
    return {
        "plan01_torque_limit_at_1500rpm": operating_point(1500, 70.0, 0.099, torque_estimate_nm=2.0),
        "plan02_3000rpm_1Nm": operating_point(3000, 70.0, 0.099, load_nm=1.0),
        "plan03_ramp_1700_1900rpm": ramp_drift(1700, 1900),
        "plan05_1500rpm_1Nm": operating_point(1500, 70.0, 0.099, load_nm=1.0),
        "plan06_sag_3000rpm_0.5Nm_56V": operating_point(3000, 56.0, 0.0928, load_nm=0.5),
    }


if __name__ == "__main__":
    import json

    print(json.dumps({k: {a: round(v, 4) for a, v in d.items()} for k, d in run().items()}, indent=1))
