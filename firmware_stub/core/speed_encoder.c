#include "speed_encoder.h"

#include "fastmath.h"

void enc_derive(enc_cfg *cfg)
{
    int32_t cpr = (int32_t)(cfg->counts_per_rev + 0.5f);
    cfg->counts_per_rev_int = cpr > 0 ? cpr : 1;
    cfg->rad_per_count = FM_TWO_PI / (float)cfg->counts_per_rev_int;
    if (cfg->window_periods < 1u) {
        cfg->window_periods = 1u;
    }
    if (cfg->window_periods > ENC_WINDOW_MAX) {
        cfg->window_periods = ENC_WINDOW_MAX;
    }
    cfg->speed_rad_s_per_count = cfg->rad_per_count / ((float)cfg->window_periods * cfg->control_period_s);
}

static void set_angle(const enc_cfg *cfg, enc_state *st)
{
    st->theta_e_rad = fm_wrap_pi((float)st->position_counts * cfg->rad_per_count * cfg->pole_pairs);
}

void enc_reset(const enc_cfg *cfg, enc_state *st, uint16_t count)
{
    st->last_count = count;
    st->position_counts = (int32_t)count % cfg->counts_per_rev_int;
    for (unsigned k = 0; k < ENC_WINDOW_MAX; ++k) {
        st->history[k] = count;
    }
    st->head = 0u;
    st->speed_rad_s = 0.0f;
    set_angle(cfg, st);
}

void enc_step(const enc_cfg *cfg, enc_state *st, uint16_t count)
{
    int32_t delta = (int16_t)(uint16_t)(count - st->last_count);
    st->last_count = count;
    int32_t pos = st->position_counts + delta;
    int32_t cpr = cfg->counts_per_rev_int;
    if (pos >= cpr || pos < 0) {
        pos %= cpr;
        if (pos < 0) {
            pos += cpr;
        }
    }
    st->position_counts = pos;
    set_angle(cfg, st);

    uint16_t head = st->head < cfg->window_periods ? st->head : 0u;
    int32_t window_delta = (int16_t)(uint16_t)(count - st->history[head]);
    st->history[head] = count;
    head = (uint16_t)(head + 1u);
    st->head = head >= cfg->window_periods ? 0u : head;
    st->speed_rad_s = (float)window_delta * cfg->speed_rad_s_per_count;
}
