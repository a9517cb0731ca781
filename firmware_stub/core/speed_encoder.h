/*
 * Speed and position from the incremental encoder (section 3).
 *
 * Speed is the count difference over a window of N periods (the derivative of
 * position averaged over N T): one count per period at 4096 counts/rev and
 * 50 us is 30.7 rad/s, so a one-period difference is useless for a speed loop;
 * over N = ENC_WINDOW_PERIODS = 64 periods the resolution is 0.48 rad/s for a mean delay of N T / 2.
 * The 16-bit counter may wrap; differences are taken modulo 2^16, valid while
 * fewer than 32768 counts pass in one window. The angle is kept as a count
 * within one revolution (any counts per revolution, not only powers of two)
 * and converted to radians only when asked for.
 */
#ifndef SPEED_ENCODER_H
#define SPEED_ENCODER_H

#include <stdint.h>

/* Speed window: a power of two, so the ring index wraps with a mask. */
#define ENC_WINDOW_PERIODS 64u

typedef struct {
    float counts_per_rev;
    float pole_pairs;
    float control_period_s;
    /* derived by enc_derive() */
    int32_t counts_per_rev_int;
    float rad_per_count;         /* mechanical */
    float speed_rad_s_per_count; /* mechanical speed of one count per window */
} enc_cfg;

typedef struct {
    uint16_t last_count;
    uint16_t head;
    int32_t position_counts; /* 0 .. counts_per_rev - 1; count 0 is theta_e = 0 */
    float speed_rad_s;       /* mechanical */
    uint16_t history[ENC_WINDOW_PERIODS];
} enc_state;

void enc_derive(enc_cfg *cfg);
/* Takes `count` as absolute (count 0 is theta_e = 0); speed history = standstill. */
void enc_reset(const enc_cfg *cfg, enc_state *st, uint16_t count);
void enc_step(const enc_cfg *cfg, enc_state *st, uint16_t count);
/* Electrical angle in [-pi, pi]. */
float enc_angle_e(const enc_cfg *cfg, const enc_state *st);

#endif
