#include "speed_conventional.h"

#include <math.h>

#include "fastmath.h"

void conv_derive(conv_cfg *cfg)
{
    cfg->lpf_alpha = 1.0f - expf(-FM_TWO_PI * cfg->lpf_cutoff_hz * cfg->control_period_s);
    cfg->inv_period_hz = 1.0f / cfg->control_period_s;
}

void conv_reset(conv_state *st, float theta_rad, float speed_rad_s)
{
    st->theta_prev_rad = theta_rad;
    st->speed_raw_rad_s = speed_rad_s;
    st->speed_lpf_rad_s = speed_rad_s;
}

void conv_step(const conv_cfg *cfg, conv_state *st, float theta_s_rad)
{
    float d = theta_s_rad - st->theta_prev_rad;
    d = d > FM_PI ? d - FM_TWO_PI : (d < -FM_PI ? d + FM_TWO_PI : d);
    st->theta_prev_rad = theta_s_rad;
    st->speed_raw_rad_s = d * cfg->inv_period_hz;
    st->speed_lpf_rad_s += cfg->lpf_alpha * (st->speed_raw_rad_s - st->speed_lpf_rad_s);
}
