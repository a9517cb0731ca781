#include "hysteresis.h"

uint8_t hyst_step(const hyst_cfg *cfg, hyst_state *st, float ref, float value)
{
    float half = 0.5f * cfg->band;
    if (value < ref - half) {
        st->out = 1u;
    } else if (value > ref + half) {
        st->out = 0u;
    }
    return st->out;
}
