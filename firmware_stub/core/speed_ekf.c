#include "speed_ekf.h"

#include "fastmath.h"

void ekf_reset(ekf_state *st, float theta_rad, float speed_rad_s)
{
    st->theta_rad = fm_wrap_pi(theta_rad);
    st->speed_rad_s = speed_rad_s;
    st->speed_increment_rad_s = 0.0f;
    st->theta_filtered_rad = st->theta_rad;
}

/* eq. (21)-(23) for an innovation eps */
static void update(const ekf_cfg *cfg, ekf_state *st, float eps)
{
    float w = st->speed_rad_s;
    float filtered = st->theta_rad + cfg->k1 * eps;
    st->theta_filtered_rad = filtered;
    st->theta_rad = fm_wrap_pi(filtered + cfg->control_period_s * w);     /* eq. (21) */
    st->speed_rad_s = w + st->speed_increment_rad_s + cfg->k2_rad_s * eps; /* eq. (22) */
    st->speed_increment_rad_s += cfg->k3_rad_s * eps;                       /* eq. (23) */
}

void ekf_step(const ekf_cfg *cfg, ekf_state *st, float y1_cos, float y2_sin)
{
    float s, c;
    fm_sincos(st->theta_rad, &s, &c);
    update(cfg, st, y2_sin * c - y1_cos * s); /* eq. (20) */
}

void ekf_step_angle(const ekf_cfg *cfg, ekf_state *st, float theta_s_rad)
{
    update(cfg, st, fm_sin(theta_s_rad - st->theta_rad)); /* eq. (20) */
}
