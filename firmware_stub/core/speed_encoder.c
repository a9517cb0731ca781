#include "speed_encoder.h"

#include "fastmath.h"

void enc_derive(enc_cfg *cfg)
{
    int32_t cpr = fm_trunc_sat_i32(cfg->counts_per_rev + 0.5f);
    cfg->counts_per_rev_int = cpr > 0 ? cpr : 1;
    cfg->rad_per_count = FM_TWO_PI / (float)cfg->counts_per_rev_int;
    cfg->speed_rad_s_per_count = cfg->rad_per_count / ((float)ENC_WINDOW_PERIODS * cfg->control_period_s);
}

void enc_reset(const enc_cfg *cfg, enc_state *st, uint16_t count)
{
    st->last_count = count;
    st->position_counts = (int32_t)count % cfg->counts_per_rev_int;
    for (unsigned k = 0; k < ENC_WINDOW_PERIODS; ++k) {
        st->history[k] = count;
    }
    st->head = 0u;
    st->speed_rad_s = 0.0f;
}

void enc_step(const enc_cfg *cfg, enc_state *st, uint16_t count)
{
    int32_t delta = (int16_t)(uint16_t)(count - st->last_count);
    st->last_count = count;
    int32_t pos = st->position_counts + delta;
    int32_t cpr = cfg->counts_per_rev_int;
    if (pos >= cpr || pos < 0) {
        pos %= cpr;
        pos += pos < 0 ? cpr : 0;
    }
    st->position_counts = pos;

    uint16_t head = st->head;
    int32_t window_delta = (int16_t)(uint16_t)(count - st->history[head]);
    st->history[head] = count;
    st->head = (uint16_t)((head + 1u) & (ENC_WINDOW_PERIODS - 1u));
    st->speed_rad_s = (float)window_delta * cfg->speed_rad_s_per_count;
}

float enc_angle_e(const enc_cfg *cfg, const enc_state *st)
{
    float mech = (float)st->position_counts * cfg->rad_per_count; /* [0, 2 pi) */
    return fm_wrap_pi(mech * cfg->pole_pairs);
}
