#include "protection.h"

#include <math.h>

#include "fastmath.h"

void prot_derive(prot_cfg *cfg)
{
    float n = cfg->encoder_loss_timeout_s / cfg->control_period_s;
    /* a NaN timeout gives 0 periods: the shortest, so that it trips rather than never */
    cfg->encoder_loss_timeout_periods = n >= 4e9f ? 4000000000u : fm_trunc_sat_u32(n + 0.5f);
}

void prot_reset(prot_state *st, uint16_t count)
{
    st->frozen_periods = 0u;
    st->last_count = count;
}

uint8_t prot_hardware(const prot_cfg *cfg, float i_peak_a, float vdc_v, uint8_t status_bits, float *value)
{
    /* written so that a NaN current trips it */
    if (!(i_peak_a <= cfg->overcurrent_a) || (status_bits & (PROT_STATUS_OVERCURRENT | PROT_STATUS_GATE_FAULT))) {
        *value = i_peak_a;
        return PROT_FAULT_OVERCURRENT;
    }
    if (status_bits & PROT_STATUS_OVERVOLTAGE) {
        *value = vdc_v;
        return PROT_FAULT_DC_LINK;
    }
    return PROT_FAULT_NONE;
}

uint8_t prot_encoder_loss(const prot_cfg *cfg, prot_state *st, uint16_t count, float flux_speed_rad_s,
                          int encoder_selected, float *value)
{
    float speed = fabsf(flux_speed_rad_s);
    /* a NaN speed fails "speed < min": counted as turning, so the timer runs (fails safe) */
    if (!encoder_selected || count != st->last_count || speed < cfg->encoder_loss_min_speed_rad_s) {
        st->frozen_periods = 0u;
        st->last_count = count;
        return PROT_FAULT_NONE;
    }
    if (++st->frozen_periods > cfg->encoder_loss_timeout_periods) {
        *value = (float)st->frozen_periods * cfg->control_period_s;
        return PROT_FAULT_ENCODER_LOSS;
    }
    return PROT_FAULT_NONE;
}
