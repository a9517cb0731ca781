#include "speed_pi.h"

void spi_derive(spi_cfg *cfg) { cfg->ki_per_step_nm_per_rad_s = cfg->ki_nm_per_rad * cfg->control_period_s; }

float spi_step(const spi_cfg *cfg, spi_state *st, float speed_ref_rad_s, float speed_meas_rad_s)
{
    float lim = cfg->torque_limit_nm;
    float e = speed_ref_rad_s - speed_meas_rad_s;
    float p = cfg->kp_nm_per_rad_s * e;
    float candidate = st->integral_nm + cfg->ki_per_step_nm_per_rad_s * e;
    float unsat = p + candidate;
    /* saturated and the error pushing further: hold the integrator */
    if (unsat > lim && e > 0.0f) {
        return lim;
    }
    if (unsat < -lim && e < 0.0f) {
        return -lim;
    }
    candidate = candidate > lim ? lim : candidate;
    candidate = candidate < -lim ? -lim : candidate;
    st->integral_nm = candidate;
    float out = p + candidate;
    out = out > lim ? lim : out;
    return out < -lim ? -lim : out;
}
