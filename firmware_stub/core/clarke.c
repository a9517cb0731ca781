#include "clarke.h"

#include "fastmath.h"

static float absf(float v) { return v < 0.0f ? -v : v; }

void clarke_from_adc(const clarke_cfg *cfg, uint16_t adc_i1, uint16_t adc_i2, clarke_out *out)
{
    float i1 = ((float)adc_i1 - cfg->current_offset_counts) * cfg->current_a_per_count;
    float i2 = ((float)adc_i2 - cfg->current_offset_counts) * cfg->current_a_per_count;
    float ia, ib;
    switch (cfg->phases) {
    case CLARKE_PHASES_AC:
        ia = i1;
        ib = -i1 - i2;
        break;
    case CLARKE_PHASES_BC:
        ia = -i1 - i2;
        ib = i1;
        break;
    default:
        ia = i1;
        ib = i2;
        break;
    }
    float ic = -ia - ib;
    out->i_alpha_a = ia;                              /* eq. (8) */
    out->i_beta_a = (ia + 2.0f * ib) * FM_INV_SQRT3; /* eq. (9) */
    float peak = absf(ia);
    float m = absf(ib);
    peak = m > peak ? m : peak;
    m = absf(ic);
    out->i_peak_a = m > peak ? m : peak;
}
