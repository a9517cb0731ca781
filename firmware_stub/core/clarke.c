#include "clarke.h"

#include <math.h>

#include "fastmath.h"

void clarke_derive(clarke_cfg *cfg)
{
    float k = cfg->current_a_per_count;
    cfg->offset1_counts = cfg->current_offset_counts;
    cfg->offset2_counts = cfg->current_offset_counts;
    switch (cfg->phases) {
    case CLARKE_PHASES_AC: /* i1 = i_a, i2 = i_c: i_b = -i_a - i_c */
        cfg->a1 = k;
        cfg->a2 = 0.0f;
        cfg->b1 = -k;
        cfg->b2 = -k;
        break;
    case CLARKE_PHASES_BC: /* i1 = i_b, i2 = i_c: i_a = -i_b - i_c */
        cfg->a1 = -k;
        cfg->a2 = -k;
        cfg->b1 = k;
        cfg->b2 = 0.0f;
        break;
    default: /* i1 = i_a, i2 = i_b */
        cfg->a1 = k;
        cfg->a2 = 0.0f;
        cfg->b1 = 0.0f;
        cfg->b2 = k;
        break;
    }
}

void clarke_from_adc(const clarke_cfg *cfg, uint16_t adc_i1, uint16_t adc_i2, clarke_out *out)
{
    float c1 = (float)adc_i1 - cfg->offset1_counts;
    float c2 = (float)adc_i2 - cfg->offset2_counts;
    float ia = cfg->a1 * c1 + cfg->a2 * c2;
    float ib = cfg->b1 * c1 + cfg->b2 * c2;
    float ic = -ia - ib;
    out->i_alpha_a = ia;                              /* eq. (8) */
    out->i_beta_a = (ia + 2.0f * ib) * FM_INV_SQRT3; /* eq. (9) */
    float pa = fabsf(ia), pb = fabsf(ib), pc = fabsf(ic);
    float peak = pa > pb ? pa : pb;
    out->i_peak_a = pc > peak ? pc : peak;
}
