/*
 * Rotor position from the stator flux angle minus the load angle, eq. (24)-(26),
 * for telemetry only (DTC itself needs no rotor position):
 *   delta = asin(2 Ls T / (3 p psi_s psi_r)),   theta_r = theta_s - delta.
 * The asin argument is clamped to [-1, 1] (beyond it the estimate has no
 * solution: pull-out), and delta = 0 while |psi_s| is near zero.
 */
#ifndef ROTOR_POSITION_H
#define ROTOR_POSITION_H

typedef struct {
    float stator_inductance_h;
    float magnet_flux_wb;
    float pole_pairs;
    /* derived by rotor_derive() */
    float sin_delta_per_nm_wb; /* 2 Ls / (3 p psi_r) */
} rotor_cfg;

void rotor_derive(rotor_cfg *cfg);
/* eq. (25), electrical rad in [-pi/2, pi/2] */
float rotor_load_angle(const rotor_cfg *cfg, float torque_nm, float flux_mag_wb);

#endif
