/*
 * Field-oriented control law (the stub's second control law beside the
 * paper's DTC, selected by HIL_PARAM_CONTROL_LAW): torque reference and rotor
 * angle in, three PWM duties out (the DUTY message).
 *
 *   i_q_ref = T_ref / (3/2 p psi_f), i_d_ref = 0   (surface magnets: maximum torque per ampere)
 *   (i_d, i_q) = Park(theta_e) (i_alpha, i_beta)   (Clarke is clarke.c's, shared with DTC)
 *   (u_d, u_q) = current_pi.c (PI + decoupling, limited to Vdc/sqrt3)
 *   (u_alpha, u_beta) = Park^-1(theta_e + w T/2) (u_d, u_q)
 *   duties = svpwm.c, then dead-time compensation by current sign
 *
 * The inverse Park uses the angle at the middle of the period the voltage acts
 * in ([t_k, t_k + T) when the plant applies it at once): with the sample's
 * angle the voltage would lag the rotor by w T/2 on average (0.45 deg at
 * 3000 rpm), a d-axis voltage error w T/2 |u| the PI must absorb.
 * (cos, sin) are rotated by w T/2 to second order (error (wT/2)^3/6 = 2e-7 rad
 * at 3000 rpm) instead of a second sincos.
 *
 * The voltage request is kept (u_alpha_v, u_beta_v) for the flux observer:
 * with the linear-range limit the inverter applies it on average, and the
 * dead-time compensation exists to make that true with a dead time too.
 */
#ifndef FOC_H
#define FOC_H

#include <stdint.h>

#include "current_pi.h"
#include "svpwm.h"

typedef struct {
    cpi_cfg current;
    svpwm_cfg pwm;
    float pole_pairs;
    float control_period_s;
    /* derived by foc_derive() */
    float amp_per_nm; /* 1 / (3/2 p psi_f) */
    float half_period_s;
} foc_cfg;

typedef struct {
    cpi_state current;
    float i_d_a;     /* last measured, rotor frame */
    float i_q_a;
    float i_q_ref_a;
    float u_alpha_v; /* request of the last step (applied during the period after it) */
    float u_beta_v;
    uint8_t limited; /* last step hit the linear-range limit */
} foc_state;

void foc_derive(foc_cfg *cfg);
void foc_reset(foc_state *st);

/* One period. theta_e: rotor (magnet) electrical angle at the sample, rad;
 * speed_e: electrical rad/s; vdc_v: measured DC link (values below 1 V count
 * as 1 V). Writes duty[3] in 0..1. */
void foc_step(const foc_cfg *cfg, foc_state *st, float theta_e_rad, float speed_e_rad_s, float i_alpha_a,
              float i_beta_a, float torque_ref_nm, float vdc_v, float duty[3]);

#endif
