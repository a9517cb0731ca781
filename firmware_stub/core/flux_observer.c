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

void invcomp_derive(invcomp_cfg *cfg)
{
    cfg->td_over_t = cfg->control_period_s > 0.0f ? cfg->dead_time_s / cfg->control_period_s : 0.0f;
    cfg->inv_band_per_a = cfg->sign_band_a > 0.0f ? 1.0f / cfg->sign_band_a : 0.0f;
}

/* sgn(i), linear within +-band (band 0: a hard sign) */
static float soft_sign(float i_a, float inv_band)
{
    if (inv_band > 0.0f) {
        float s = i_a * inv_band;
        return s > 1.0f ? 1.0f : (s < -1.0f ? -1.0f : s);
    }
    return i_a > 0.0f ? 1.0f : (i_a < 0.0f ? -1.0f : 0.0f);
}

void invcomp_correct(const invcomp_cfg *cfg, uint8_t legs_before, uint8_t legs_applied, float vdc_v,
                     float i_edge_alpha_a, float i_edge_beta_a, float i_mean_alpha_a, float i_mean_beta_a,
                     float *u_alpha_v, float *u_beta_v)
{
    /* phase currents from (alpha, beta): inverse of eq. (7)-(9) */
    const float half_sqrt3 = 0.866025404f;
    float edge[3], mean[3];
    edge[0] = i_edge_alpha_a;
    edge[1] = -0.5f * i_edge_alpha_a + half_sqrt3 * i_edge_beta_a;
    edge[2] = -edge[0] - edge[1];
    mean[0] = i_mean_alpha_a;
    mean[1] = -0.5f * i_mean_alpha_a + half_sqrt3 * i_mean_beta_a;
    mean[2] = -mean[0] - mean[1];
    int dead = cfg->td_over_t > 0.0f && legs_before != INVCOMP_LEGS_OFF && legs_applied != INVCOMP_LEGS_OFF;
    float e[3];
    for (unsigned x = 0; x < 3u; ++x) {
        e[x] = -cfg->device_drop_v * soft_sign(mean[x], cfg->inv_band_per_a);
        unsigned s_new = (legs_applied >> x) & 1u;
        if (dead && s_new != ((legs_before >> x) & 1u)) {
            float rail = 0.5f * (1.0f - soft_sign(edge[x], cfg->inv_band_per_a)); /* 1: DC+ diode */
            e[x] += cfg->td_over_t * vdc_v * (rail - (float)s_new);
        }
    }
    *u_alpha_v += (2.0f * e[0] - e[1] - e[2]) * (1.0f / 3.0f);
    *u_beta_v += (e[1] - e[2]) * 0.577350269f;
}

void fluxobs_predict(const fluxobs_cfg *cfg, const fluxobs_state *st, float u_alpha_v, float u_beta_v,
                     float speed_e_rad_s, float *psi_alpha_wb, float *psi_beta_wb, float *i_alpha_a,
                     float *i_beta_a)
{
    float t = cfg->control_period_s;
    float ls = cfg->stator_inductance_h;
    float ia = st->i_alpha_prev_a; /* after fluxobs_step: the current sampled now */
    float ib = st->i_beta_prev_a;
    float pa = st->psi_alpha_wb + t * (u_alpha_v - cfg->stator_resistance_ohm * ia);
    float pb = st->psi_beta_wb + t * (u_beta_v - cfg->stator_resistance_ohm * ib);
    float eta_a = st->psi_alpha_wb - ls * ia;
    float eta_b = st->psi_beta_wb - ls * ib;
    /* e^{j x} to second order, x = w T (0.016 rad at 3000 rpm: error x^3/6 = 7e-7) */
    float x = speed_e_rad_s * t;
    float co = 1.0f - 0.5f * x * x;
    float si = x;
    float ra = co * eta_a - si * eta_b;
    float rb = si * eta_a + co * eta_b;
    *psi_alpha_wb = pa;
    *psi_beta_wb = pb;
    *i_alpha_a = (pa - ra) / ls;
    *i_beta_a = (pb - rb) / ls;
}
