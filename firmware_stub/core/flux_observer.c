#include "flux_observer.h"

#include <math.h>

#include "fastmath.h"

void fluxobs_derive(fluxobs_cfg *cfg)
{
    float psi_f2 = cfg->magnet_flux_wb * cfg->magnet_flux_wb;
    cfg->magnet_flux_sq_wb2 = psi_f2;
    float w0 = FM_TWO_PI * cfg->drift_cutoff_hz;
    cfg->half_r_t_ohm_s = 0.5f * cfg->stator_resistance_ohm * cfg->control_period_s;
    cfg->drift_gain_per_step = psi_f2 > 0.0f ? cfg->control_period_s * w0 / psi_f2 : 0.0f;
}

void fluxobs_reset(fluxobs_state *st, float psi_alpha_wb, float psi_beta_wb, float i_alpha_a, float i_beta_a)
{
    st->psi_alpha_wb = psi_alpha_wb;
    st->psi_beta_wb = psi_beta_wb;
    st->i_alpha_prev_a = i_alpha_a;
    st->i_beta_prev_a = i_beta_a;
}

void fluxobs_step(const fluxobs_cfg *cfg, fluxobs_state *st, float u_alpha_v, float u_beta_v, float i_alpha_a,
                  float i_beta_a)
{
    float half_r_t = cfg->half_r_t_ohm_s;
    float t = cfg->control_period_s;
    float pa = st->psi_alpha_wb;
    float pb = st->psi_beta_wb;
    /* rotor flux at the previous sample and its length error */
    float eta_a = pa - cfg->stator_inductance_h * st->i_alpha_prev_a;
    float eta_b = pb - cfg->stator_inductance_h * st->i_beta_prev_a;
    float k = cfg->drift_gain_per_step * (cfg->magnet_flux_sq_wb2 - (eta_a * eta_a + eta_b * eta_b));
    st->psi_alpha_wb = pa + t * u_alpha_v - half_r_t * (i_alpha_a + st->i_alpha_prev_a) + k * eta_a; /* eq. (3) */
    st->psi_beta_wb = pb + t * u_beta_v - half_r_t * (i_beta_a + st->i_beta_prev_a) + k * eta_b;    /* eq. (4) */
    st->i_alpha_prev_a = i_alpha_a;
    st->i_beta_prev_a = i_beta_a;
}

float flux_magnitude(float psi_alpha_wb, float psi_beta_wb)
{
    return sqrtf(psi_alpha_wb * psi_alpha_wb + psi_beta_wb * psi_beta_wb);
}

float torque_estimate(float pole_pairs, float psi_alpha_wb, float psi_beta_wb, float i_alpha_a, float i_beta_a)
{
    return 1.5f * pole_pairs * (psi_alpha_wb * i_beta_a - psi_beta_wb * i_alpha_a);
}
