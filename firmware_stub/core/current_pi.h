/*
 * d-q current regulator of the field-oriented drive: two PI controllers in the
 * rotor frame with cross-coupling (decoupling) feed-forward, a voltage-vector
 * limit, and anti-windup by conditional integration.
 *
 * Surface-magnet motor in the rotor frame (Ld = Lq = Ls):
 *     u_d = R i_d + Ls di_d/dt - w Ls i_q
 *     u_q = R i_q + Ls di_q/dt + w (Ls i_d + psi_f)
 * The feed-forward adds -w Ls i_q and w (Ls i_d + psi_f) (measured currents),
 * leaving each axis the first-order plant 1/(Ls s + R). Gains from the
 * bandwidth wc (internal model control, pole-zero cancellation):
 *     Kp = Ls wc,  Ki = R wc   =>  closed loop i/i_ref = wc / (s + wc),
 * a first-order response with no overshoot (docs/stub.md, FOC section).
 *
 * The output is limited to a circle of radius u_max (the SVPWM linear range
 * Vdc/sqrt3), scaling both axes alike. While limited, each integrator moves
 * only when its error would pull its axis back toward the circle (e u < 0),
 * and both are clamped to +-u_max, so a saturated transient (a speed step at
 * the voltage limit) leaves no wound-up integral behind.
 */
#ifndef CURRENT_PI_H
#define CURRENT_PI_H

typedef struct {
    float bandwidth_hz;
    float stator_resistance_ohm;
    float stator_inductance_h;
    float magnet_flux_wb;
    float control_period_s;
    /* derived by cpi_derive() */
    float kp_v_per_a;        /* Ls wc */
    float ki_v_per_a_s;      /* R wc */
    float ki_per_step_v_per_a; /* Ki T */
} cpi_cfg;

typedef struct {
    float integral_d_v;
    float integral_q_v;
} cpi_state;

typedef struct {
    float u_d_v;
    float u_q_v;
    int limited; /* 1: the request was scaled onto the u_max circle */
} cpi_out;

void cpi_derive(cpi_cfg *cfg);
void cpi_reset(cpi_state *st);

/* One period: measured (i_d, i_q), references, electrical speed w (rad/s) for
 * the feed-forward, and the voltage limit u_max > 0. */
void cpi_step(const cpi_cfg *cfg, cpi_state *st, float i_d_a, float i_q_a, float i_d_ref_a, float i_q_ref_a,
              float speed_e_rad_s, float u_max_v, cpi_out *out);

#endif
