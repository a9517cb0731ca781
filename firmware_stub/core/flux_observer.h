/*
 * Stator flux observer, eq. (3)-(4), with the flux magnitude eq. (5) and the
 * torque estimate eq. (6).
 *
 * Drift compensation. A pure integrator (the paper) turns any DC error in
 * u - R i (ADC offset, resistance error, inverter asymmetry) into a flux error
 * e that grows without bound. Filtering the stator flux (leaky integrator,
 * high-pass on its centre) does not help under DTC: the controller holds the
 * estimate on a circle about the origin, so the error appears as the *true*
 * flux orbiting -e and the estimate itself looks perfect. What does reveal e is
 * the rotor flux eta = psi - Ls i: for surface magnets it is a vector of known
 * length psi_f whatever the controller does, and its estimate is off by e. The
 * option corrects the estimate along eta by the length error (the gradient
 * observer of Ortega et al., IEEE TCST 2011):
 *     dpsi/dt = u - R i + (gamma / 2) eta (psi_f^2 - |eta|^2),  eta = psi - Ls i
 * Linearised, the error obeys de/dt = e0 - gamma psi_f^2 n n^T e (n the rotor
 * flux direction): the radial part decays at 2 w0 and, once the rotor turns,
 * the whole error at w0 = gamma psi_f^2 / 2, set here as 2 pi drift_cutoff_hz.
 * Solved exactly in the rotor frame, a DC voltage error e0 leaves a bounded
 * flux offset e0 (1/w0 + j/(2 w)) at electrical speed w (j: 90 degrees ahead);
 * a current offset i0 gives e0 = -R i0 plus Ls i0, as it also shifts eta.
 * Unlike a
 * leaky integrator it adds no gain or phase error at any speed (the true rotor
 * flux has length psi_f exactly) and needs no speed estimate; at standstill it
 * corrects the radial component only. It relies on psi_f and Ls, which the
 * bench pushes; a length error in either biases the estimate by about that
 * much. drift_cutoff_hz = 0 gives the paper's pure integrator.
 */
#ifndef FLUX_OBSERVER_H
#define FLUX_OBSERVER_H

#include <stdint.h>

typedef struct {
    float stator_resistance_ohm;
    float stator_inductance_h;
    float magnet_flux_wb;
    float control_period_s;
    float drift_cutoff_hz; /* 0: pure integrator */
    /* derived by fluxobs_derive() */
    float magnet_flux_sq_wb2;    /* psi_f^2 */
    float drift_gain_per_step;   /* T gamma / 2 = T w0 / psi_f^2, 1/Wb^2 */
    float half_r_t_ohm_s;        /* T R / 2: the trapezoidal R i term, Ohm s */
} fluxobs_cfg;

typedef struct {
    float psi_alpha_wb;
    float psi_beta_wb;
    float i_alpha_prev_a; /* current at the previous sample: trapezoidal R i, and eta */
    float i_beta_prev_a;
} fluxobs_state;

void fluxobs_derive(fluxobs_cfg *cfg);
void fluxobs_reset(fluxobs_state *st, float psi_alpha_wb, float psi_beta_wb, float i_alpha_a, float i_beta_a);
/* Advances the flux from the previous sample to this one: u is the voltage
 * applied during the period just ended, i the current sampled now. */
void fluxobs_step(const fluxobs_cfg *cfg, fluxobs_state *st, float u_alpha_v, float u_beta_v, float i_alpha_a,
                  float i_beta_a);

/*
 * Inverter compensation of the voltage the observer integrates (docs/stub.md,
 * "Inverter and delay compensation"). Eq. (3)-(4) integrate the Table 2
 * voltage of the vector the controller asked for; a real inverter applies less.
 * Per leg x, over the period just ended (terminal voltage against DC-):
 *  - dead time Td: when the leg changed state at the period's start, for Td
 *    both switches are off and the leg sits on the rail of the diode its
 *    current picks (DC- for i_x > 0, DC+ for i_x < 0), so the period's mean
 *    is off by  e_x = (Td/T) Vdc (r_x - s_x),  r_x = (1 - sgn i_x)/2, with
 *    s_x the new state and i_x the current at the switching edge;
 *  - device drop Ud: every conducting switch or diode drops Ud against its
 *    current,  e_x = -Ud sgn i_x  with the period's mean current.
 * The star point floats, so only the Clarke transform of e (eq. (7), the
 * common mode cancels) reaches the stator:  e_alpha = (2 e_a - e_b - e_c)/3,
 * e_beta = (e_b - e_c)/sqrt3. sgn is linear within +-sign_band_a, like the
 * plant's device knee, so noise about a zero crossing does not chatter.
 */
typedef struct {
    float dead_time_s;   /* Td to compensate, 0 = off */
    float device_drop_v; /* Ud to compensate, 0 = off */
    float control_period_s;
    float sign_band_a;   /* > 0: linear zone of sgn(i) */
    /* derived by invcomp_derive() */
    float td_over_t;
    float inv_band_per_a;
} invcomp_cfg;

void invcomp_derive(invcomp_cfg *cfg);
/* Adds the inverter's error to (u_alpha, u_beta), the ideal voltage of the
 * leg states `legs_applied` (bit 0 phase a high, bit 1 b, bit 2 c) held over
 * the period that followed `legs_before`. i_edge: (alpha, beta) current at
 * the switching edge (the period's start); i_mean: the period's mean current.
 * Either state 0xFF (all switches off: the diodes set the voltage) skips the
 * dead-time term. */
void invcomp_correct(const invcomp_cfg *cfg, uint8_t legs_before, uint8_t legs_applied, float vdc_v,
                     float i_edge_alpha_a, float i_edge_beta_a, float i_mean_alpha_a, float i_mean_beta_a,
                     float *u_alpha_v, float *u_beta_v);
#define INVCOMP_LEGS_OFF 0xFFu

/*
 * One-period delay compensation. A board that writes its answer to a shadow
 * register applies the vector chosen from sample k only from t_k+1; during
 * [t_k, t_k+1] the previous answer acts, already known at t_k. Choosing the
 * vector from psi(t_k) then acts on a flux one period old. This predicts the
 * state at t_k+1, where the chosen vector starts to act:
 *   psi(k+1) = psi(k) + T (u - R i(k))                      eq. (3)-(4), Euler
 *   eta(k+1) = eta(k) e^{j w T},  eta = psi - Ls i          rotor flux turns at w
 *   i(k+1)   = (psi(k+1) - eta(k+1)) / Ls                   surface magnets
 * u: the (compensated) voltage of the vector that acts over [t_k, t_k+1],
 * w: the electrical speed estimate. Only the state struct is read.
 */
void fluxobs_predict(const fluxobs_cfg *cfg, const fluxobs_state *st, float u_alpha_v, float u_beta_v,
                     float speed_e_rad_s, float *psi_alpha_wb, float *psi_beta_wb, float *i_alpha_a,
                     float *i_beta_a);

/* eq. (5) */
float flux_magnitude(float psi_alpha_wb, float psi_beta_wb);
/* eq. (6): T = 3/2 p (psi_alpha i_beta - psi_beta i_alpha) */
float torque_estimate(float pole_pairs, float psi_alpha_wb, float psi_beta_wb, float i_alpha_a, float i_beta_a);

#endif
