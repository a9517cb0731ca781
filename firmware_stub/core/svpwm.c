#include "svpwm.h"

#include <math.h>

#include "fastmath.h"

void svpwm_derive(svpwm_cfg *cfg)
{
    cfg->dead_time_duty = cfg->dead_time_comp_s / cfg->control_period_s;
    cfg->dead_time_duty_per_a = cfg->dead_time_duty / cfg->comp_band_a;
}

int svpwm_limit(float vdc_v, float *u_alpha_v, float *u_beta_v)
{
    float umax = vdc_v * FM_INV_SQRT3;
    float mag2 = *u_alpha_v * *u_alpha_v + *u_beta_v * *u_beta_v;
    if (mag2 <= umax * umax) {
        return 0;
    }
    float scale = umax / sqrtf(mag2);
    *u_alpha_v *= scale;
    *u_beta_v *= scale;
    return 1;
}

void svpwm_duties(float u_alpha_v, float u_beta_v, float vdc_v, float duty[3])
{
    /* phase references: v_x = e_x . u */
    float half_alpha = 0.5f * u_alpha_v;
    float beta_part = 0.5f * FM_SQRT3 * u_beta_v;
    float va = u_alpha_v;
    float vb = -half_alpha + beta_part;
    float vc = -half_alpha - beta_part;
    float vmax = va > vb ? va : vb;
    vmax = vmax > vc ? vmax : vc;
    float vmin = va < vb ? va : vb;
    vmin = vmin < vc ? vmin : vc;
    float v0 = -0.5f * (vmax + vmin); /* min-max zero sequence: centres the pulses */
    float inv_vdc = 1.0f / vdc_v;
    duty[0] = 0.5f + (va + v0) * inv_vdc;
    duty[1] = 0.5f + (vb + v0) * inv_vdc;
    duty[2] = 0.5f + (vc + v0) * inv_vdc;
}

static float clamp01(float d) { return d > 1.0f ? 1.0f : (d < 0.0f ? 0.0f : d); }

void svpwm_dead_time_comp(const svpwm_cfg *cfg, const float i_abc_a[3], float duty[3])
{
    float full = cfg->dead_time_duty;
    for (int x = 0; x < 3; ++x) {
        float comp = i_abc_a[x] * cfg->dead_time_duty_per_a; /* linear inside the band */
        comp = comp > full ? full : (comp < -full ? -full : comp);
        duty[x] = clamp01(duty[x] + comp);
    }
}

uint16_t svpwm_duty_u16(float duty)
{
    /* written so that NaN gives 0 */
    if (!(duty > 0.0f)) {
        return 0u;
    }
    if (duty >= 1.0f) {
        return 65535u;
    }
    return (uint16_t)(duty * 65535.0f + 0.5f);
}
