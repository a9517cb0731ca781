/*
 * Clarke transform from two measured phase currents, eq. (8)-(9), starting
 * from raw ADC counts through the scaling the bench pushes with PARAM_SET.
 * With an isolated star point i_a + i_b + i_c = 0, so any two phases suffice:
 * clarke_derive() folds the phase pair and the A/count scale into one 2x2
 * matrix from offset-corrected counts to (i_a, i_b), and the step applies it.
 */
#ifndef CLARKE_H
#define CLARKE_H

#include <stdint.h>

typedef enum { CLARKE_PHASES_AB = 0, CLARKE_PHASES_AC = 1, CLARKE_PHASES_BC = 2 } clarke_phases;

typedef struct {
    float current_a_per_count;   /* ADC scale, A per count */
    float current_offset_counts; /* ADC count at zero current */
    uint8_t phases;              /* clarke_phases: which phases adc_i1, adc_i2 measure */
    /* per-channel zero, counts: current_offset_counts from clarke_derive(), or what the
     * start-up calibration measured (control.c, CURRENT_ZERO_CAL_PERIODS) */
    float offset1_counts;
    float offset2_counts;
    /* derived by clarke_derive(): i_a = a1 c1 + a2 c2, i_b = b1 c1 + b2 c2 */
    float a1, a2, b1, b2;
} clarke_cfg;

typedef struct {
    float i_alpha_a;
    float i_beta_a;
    float i_peak_a; /* max(|i_a|, |i_b|, |i_c|), for the overcurrent trip */
} clarke_out;

void clarke_derive(clarke_cfg *cfg);
void clarke_from_adc(const clarke_cfg *cfg, uint16_t adc_i1, uint16_t adc_i2, clarke_out *out);

#endif
