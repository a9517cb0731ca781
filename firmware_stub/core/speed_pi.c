#include "speed_pi.h"

static float clampf(float v, float lim) { return v > lim ? lim : (v < -lim ? -lim : v); }

float spi_step(const spi_cfg *cfg, spi_state *st, float speed_ref_rad_s, float speed_meas_rad_s)
{
    float lim = cfg->torque_limit_nm;
    float e = speed_ref_rad_s - speed_meas_rad_s;
    float p = cfg->kp_nm_per_rad_s * e;
    float candidate = st->integral_nm + cfg->ki_nm_per_rad * cfg->control_period_s * e;
    float unsat = p + candidate;
    int winding_up = (unsat > lim && e > 0.0f) || (unsat < -lim && e < 0.0f);
    if (!winding_up) {
        st->integral_nm = clampf(candidate, lim);
    }
    return clampf(p + st->integral_nm, lim);
}
