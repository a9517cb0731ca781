#include "rs_id.h"

#include "fastmath.h"

void rsid_derive(rsid_cfg *cfg)
{
    float wc = FM_TWO_PI * cfg->bandwidth_hz;
    cfg->kp_v_per_a = cfg->stator_inductance_h * wc;
    cfg->ki_per_step_v_per_a = cfg->kp_v_per_a * (0.2f * wc) * cfg->control_period_s;
    cfg->settle_periods = cfg->periods_per_level / 4u;
}

void rsid_start(rsid_state *st)
{
    st->phase = RSID_LOW;
    st->limited = 0u;
    st->count = 0u;
    st->integral_d_v = 0.0f;
    st->integral_q_v = 0.0f;
    st->sum_u_v = 0.0f;
    st->sum_i_a = 0.0f;
    st->u_start_v = 0.0f;
    st->u_low_v = 0.0f;
    st->i_low_a = 0.0f;
    st->u_high_v = 0.0f;
    st->i_high_a = 0.0f;
    st->r_ohm = 0.0f;
}

static float clamp_abs(float v, float lim) { return v > lim ? lim : (v < -lim ? -lim : v); }

/* R from the two levels' means, or RSID_FAILED: a request at the limit (the mean is not what
 * was applied) or a current that did not reach three quarters of the step. */
static void finish(const rsid_cfg *cfg, rsid_state *st)
{
    float di = st->i_high_a - st->i_low_a;
    float r = di > 0.0f ? (st->u_high_v - st->u_low_v) / di : -1.0f;
    int ok = !st->limited && di > 0.75f * (cfg->current_high_a - cfg->current_low_a) && r > 0.0f && r < 100.0f;
    st->r_ohm = ok ? r : 0.0f;
    st->phase = ok ? RSID_DONE : RSID_FAILED;
}

uint8_t rsid_step(const rsid_cfg *cfg, rsid_state *st, float i_d_a, float i_q_a, float u_max_v, float *u_d_v,
                  float *u_q_v)
{
    *u_d_v = 0.0f;
    *u_q_v = 0.0f;
    if (st->phase == RSID_OFF) {
        if (++st->count >= cfg->off_periods) {
            finish(cfg, st);
        }
        return 0u;
    }
    if (st->phase != RSID_LOW && st->phase != RSID_HIGH) {
        return 0u;
    }
    float ref = st->phase == RSID_LOW ? cfg->current_low_a : cfg->current_high_a;
    float e_d = ref - i_d_a;
    float e_q = -i_q_a;
    st->integral_d_v = clamp_abs(st->integral_d_v + cfg->ki_per_step_v_per_a * e_d, u_max_v);
    st->integral_q_v = clamp_abs(st->integral_q_v + cfg->ki_per_step_v_per_a * e_q, u_max_v);
    float u_d = cfg->kp_v_per_a * e_d + st->integral_d_v;
    float u_q = cfg->kp_v_per_a * e_q + st->integral_q_v;
    /* the rotor stands still: the d axis carries the whole request; a clamp keeps it inside
     * the linear range (and marks the window invalid) */
    u_max_v *= 0.99f;
    int limited = 0;
    if (u_d > u_max_v || u_d < -u_max_v) {
        u_d = clamp_abs(u_d, u_max_v);
        limited = 1;
    }
    float q_room = u_max_v - (u_d < 0.0f ? -u_d : u_d);
    if (u_q > q_room || u_q < -q_room) {
        u_q = clamp_abs(u_q, q_room);
        limited = 1;
    }
    if (st->count >= cfg->settle_periods) {
        /* the measuring window: the request made now acts over the period that follows
         * (or the one after, with a shadow register); in the steady state that is the same.
         * Sums of the deviations from the window's first request and from the reference, so
         * that float rounding does not add up (750 sums of 8 V would lose 3e-4 of R) */
        if (st->count == cfg->settle_periods) {
            st->u_start_v = u_d;
        }
        st->sum_u_v += u_d - st->u_start_v;
        st->sum_i_a += i_d_a - ref;
        st->limited = (uint8_t)(st->limited | (uint8_t)limited);
    }
    if (++st->count >= cfg->periods_per_level) {
        float n = (float)(cfg->periods_per_level - cfg->settle_periods);
        if (st->phase == RSID_LOW) {
            st->u_low_v = st->u_start_v + st->sum_u_v / n;
            st->i_low_a = ref + st->sum_i_a / n;
            st->phase = RSID_HIGH;
        } else {
            st->u_high_v = st->u_start_v + st->sum_u_v / n;
            st->i_high_a = ref + st->sum_i_a / n;
            st->phase = RSID_OFF;
        }
        st->count = 0u;
        st->sum_u_v = 0.0f;
        st->sum_i_a = 0.0f;
    }
    *u_d_v = u_d;
    *u_q_v = u_q;
    return 1u;
}
