/*
 * Space-vector PWM for a centre-aligned carrier: the stationary-frame voltage
 * the current regulator asks for -> three high-side duty cycles (DUTY).
 *
 * Phase references v_x = e_x . u (e_a = 0 deg, e_b = 120, e_c = 240 deg), plus
 * the min-max zero sequence v0 = -(max + min)/2, which is the same switching
 * pattern as the classical two-adjacent-vectors-plus-equal-zero-vectors SVPWM
 * (Holmes and Lipo, Pulse Width Modulation for Power Converters, sec. 6.6):
 *     d_x = 1/2 + (v_x + v0) / Vdc.
 * The linear range is the circle |u| <= Vdc/sqrt3 inscribed in the hexagon
 * (there max - min = sqrt3 |u| <= Vdc and every duty stays within 0..1);
 * svpwm_limit() scales a longer vector back onto it, so over-modulation never
 * happens and the applied average voltage equals the request.
 *
 * Dead-time compensation by current sign: a dead time Td delays each turn-on,
 * so while phase current flows out of the leg (i_x > 0) the lower diode
 * conducts during Td and the high side loses Td of on-time per PWM period
 * (both edges together), the opposite for i_x < 0. Adding Td/T sign(i_x) to
 * the duty gives it back; inside +-comp_band_a the sign is made linear so the
 * ADC noise around a zero crossing does not toggle a full Td/T.
 */
#ifndef SVPWM_H
#define SVPWM_H

#include <stdint.h>

typedef struct {
    float control_period_s;  /* = the PWM period (one carrier period per control period) */
    float dead_time_comp_s;  /* Td to compensate, 0 = off */
    float comp_band_a;       /* linear zone of the sign function, > 0 */
    /* derived by svpwm_derive() */
    float dead_time_duty;    /* Td / T */
    float dead_time_duty_per_a; /* Td / T / comp_band_a */
} svpwm_cfg;

void svpwm_derive(svpwm_cfg *cfg);

/* Scales (u_alpha, u_beta) onto the linear-range circle |u| <= vdc/sqrt3 when
 * it is longer, keeping its angle. Returns 1 when it scaled, else 0. */
int svpwm_limit(float vdc_v, float *u_alpha_v, float *u_beta_v);

/* Duties 0..1 of phases a, b, c for a request inside the linear range (call
 * svpwm_limit() first); vdc_v > 0. */
void svpwm_duties(float u_alpha_v, float u_beta_v, float vdc_v, float duty[3]);

/* Adds the dead-time compensation for phase currents i_abc (A, positive out
 * of the inverter) and clamps every duty to 0..1. */
void svpwm_dead_time_comp(const svpwm_cfg *cfg, const float i_abc_a[3], float duty[3]);

/* Duty 0..1 -> the DUTY message's 0..65535, rounded; out-of-range clamped. */
uint16_t svpwm_duty_u16(float duty);

#endif
