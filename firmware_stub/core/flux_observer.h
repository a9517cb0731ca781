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

/* eq. (5) */
float flux_magnitude(float psi_alpha_wb, float psi_beta_wb);
/* eq. (6): T = 3/2 p (psi_alpha i_beta - psi_beta i_alpha) */
float torque_estimate(float pole_pairs, float psi_alpha_wb, float psi_beta_wb, float i_alpha_a, float i_beta_a);

#endif
