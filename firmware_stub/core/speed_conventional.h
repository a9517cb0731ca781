/*
 * Conventional speed estimate from the stator flux angle: eq. (10) gives the
 * angle, eq. (11) differentiates it over one period (angle difference wrapped
 * to [-pi, pi]), and a first-order low-pass filter, pole matched at
 * lpf_cutoff_hz, makes it usable for speed feedback at the cost of phase lag
 * (section 5, Fig. 9(b)). Speeds here are electrical rad/s.
 */
#ifndef SPEED_CONVENTIONAL_H
#define SPEED_CONVENTIONAL_H

typedef struct {
    float control_period_s;
    float lpf_cutoff_hz;
    /* derived by conv_derive() */
    float lpf_alpha;       /* 1 - exp(-2 pi fc T) */
    float inv_period_hz;   /* 1 / T */
} conv_cfg;

typedef struct {
    float theta_prev_rad;
    float speed_raw_rad_s; /* eq. (11) */
    float speed_lpf_rad_s;
} conv_state;

void conv_derive(conv_cfg *cfg);
void conv_reset(conv_state *st, float theta_rad, float speed_rad_s);
void conv_step(const conv_cfg *cfg, conv_state *st, float theta_s_rad);

#endif
