#include "hysteresis.h"

void hyst_derive(hyst_cfg *cfg) { cfg->half_band = 0.5f * cfg->band; }

uint8_t hyst_step(const hyst_cfg *cfg, hyst_state *st, float ref, float value)
{
    float half = cfg->half_band;
    if (value < ref - half) {
        st->out = 1u;
    } else if (value > ref + half) {
        st->out = 0u;
    }
    return st->out;
}
