#include "foc.h"

#include "fastmath.h"

void foc_derive(foc_cfg *cfg)
{
    cfg->current.control_period_s = cfg->control_period_s;
    cpi_derive(&cfg->current);
    cfg->pwm.control_period_s = cfg->control_period_s;
    svpwm_derive(&cfg->pwm);
    cfg->amp_per_nm = 1.0f / (1.5f * cfg->pole_pairs * cfg->current.magnet_flux_wb);
    cfg->half_period_s = 0.5f * cfg->control_period_s;
}

void foc_reset(foc_state *st)
{
    cpi_reset(&st->current);
    st->i_d_a = 0.0f;
    st->i_q_a = 0.0f;
    st->i_q_ref_a = 0.0f;
    st->u_alpha_v = 0.0f;
    st->u_beta_v = 0.0f;
    st->limited = 0u;
}

void foc_step(const foc_cfg *cfg, foc_state *st, float theta_e_rad, float speed_e_rad_s, float i_alpha_a,
              float i_beta_a, float torque_ref_nm, float vdc_v, float duty[3])
{
    float s, c;
    fm_sincos(theta_e_rad, &s, &c);
    /* Park */
    float i_d = c * i_alpha_a + s * i_beta_a;
    float i_q = c * i_beta_a - s * i_alpha_a;
    float vdc = vdc_v > 1.0f ? vdc_v : 1.0f;
    float i_q_ref = torque_ref_nm * cfg->amp_per_nm;
    cpi_out u;
    cpi_step(&cfg->current, &st->current, i_d, i_q, 0.0f, i_q_ref, speed_e_rad_s, vdc * FM_INV_SQRT3, &u);
    /* inverse Park at the mid-period angle: rotate (c, s) by w T/2 */
    float a = speed_e_rad_s * cfg->half_period_s;
    float ca = 1.0f - 0.5f * a * a;
    float cm = c * ca - s * a;
    float sm = s * ca + c * a;
    float u_alpha = cm * u.u_d_v - sm * u.u_q_v;
    float u_beta = sm * u.u_d_v + cm * u.u_q_v;
    /* |u| <= Vdc/sqrt3 already; the rotation's second-order error could
     * lengthen it by 1e-8 relative: limit again rather than trust rounding */
    (void)svpwm_limit(vdc, &u_alpha, &u_beta);
    svpwm_duties(u_alpha, u_beta, vdc, duty);
    if (cfg->pwm.dead_time_duty > 0.0f) {
        float half_alpha = 0.5f * i_alpha_a;
        float beta_part = 0.5f * FM_SQRT3 * i_beta_a;
        float i_abc[3] = {i_alpha_a, -half_alpha + beta_part, -half_alpha - beta_part};
        svpwm_dead_time_comp(&cfg->pwm, i_abc, duty);
    }
    st->i_d_a = i_d;
    st->i_q_a = i_q;
    st->i_q_ref_a = i_q_ref;
    st->u_alpha_v = u_alpha;
    st->u_beta_v = u_beta;
    st->limited = (uint8_t)u.limited;
}
