#include "current_pi.h"

#include <math.h>

#include "fastmath.h"

void cpi_derive(cpi_cfg *cfg)
{
    float wc = FM_TWO_PI * cfg->bandwidth_hz;
    cfg->kp_v_per_a = cfg->stator_inductance_h * wc;
    cfg->ki_v_per_a_s = cfg->stator_resistance_ohm * wc;
    cfg->ki_per_step_v_per_a = cfg->ki_v_per_a_s * cfg->control_period_s;
}

void cpi_reset(cpi_state *st)
{
    st->integral_d_v = 0.0f;
    st->integral_q_v = 0.0f;
}

static float clamp_abs(float v, float lim) { return v > lim ? lim : (v < -lim ? -lim : v); }

void cpi_step(const cpi_cfg *cfg, cpi_state *st, float i_d_a, float i_q_a, float i_d_ref_a, float i_q_ref_a,
              float speed_e_rad_s, float u_max_v, cpi_out *out)
{
    float e_d = i_d_ref_a - i_d_a;
    float e_q = i_q_ref_a - i_q_a;
    float cand_d = clamp_abs(st->integral_d_v + cfg->ki_per_step_v_per_a * e_d, u_max_v);
    float cand_q = clamp_abs(st->integral_q_v + cfg->ki_per_step_v_per_a * e_q, u_max_v);
    /* decoupling feed-forward: the rotor-frame cross terms and the back-EMF */
    float ff_d = -speed_e_rad_s * cfg->stator_inductance_h * i_q_a;
    float ff_q = speed_e_rad_s * (cfg->stator_inductance_h * i_d_a + cfg->magnet_flux_wb);
    float u_d = cfg->kp_v_per_a * e_d + cand_d + ff_d;
    float u_q = cfg->kp_v_per_a * e_q + cand_q + ff_q;
    float mag2 = u_d * u_d + u_q * u_q;
    out->limited = mag2 > u_max_v * u_max_v;
    if (out->limited) {
        float scale = u_max_v / sqrtf(mag2);
        u_d *= scale;
        u_q *= scale;
        /* conditional integration: only toward the inside of the circle */
        if (e_d * u_d < 0.0f) {
            st->integral_d_v = cand_d;
        }
        if (e_q * u_q < 0.0f) {
            st->integral_q_v = cand_q;
        }
    } else {
        st->integral_d_v = cand_d;
        st->integral_q_v = cand_q;
    }
    out->u_d_v = u_d;
    out->u_q_v = u_q;
}
