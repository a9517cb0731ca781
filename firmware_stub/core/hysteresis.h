/*
 * Two-level hysteresis comparator (the flux and torque regulators of Fig. 3).
 * Output 1 asks for an increase, 0 for a decrease; it switches to 1 when the
 * value falls below ref - band/2, to 0 when it rises above ref + band/2, and
 * otherwise holds. band is the total width, in the unit of ref and value.
 */
#ifndef HYSTERESIS_H
#define HYSTERESIS_H

#include <stdint.h>

typedef struct {
    float band;      /* total width: flux_band_wb or torque_band_nm */
    float half_band; /* derived by hyst_derive() */
} hyst_cfg;

typedef struct {
    uint8_t out; /* last output, 1 = increase */
} hyst_state;

void hyst_derive(hyst_cfg *cfg);
uint8_t hyst_step(const hyst_cfg *cfg, hyst_state *st, float ref, float value);

#endif
