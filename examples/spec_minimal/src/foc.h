/*
 * Field-oriented control blocks for the minimal board: pure functions of their
 * arguments and of the state the caller passes, no globals, no I/O. Angles in
 * rad, currents in A, voltages in V, SI units throughout; float only (the
 * Cortex-M4F's FPU is single precision).
 */
#ifndef SPEC_MINIMAL_FOC_H
#define SPEC_MINIMAL_FOC_H

#include <stdint.h>

/* A PI controller's gains, its output limit and its integral state. */
typedef struct {
    float kp;
    float ki;
    float limit; /* |output| <= limit */
} foc_pi_gains;

/* Type-2 tracking loop (phase-locked loop) on the mechanical angle. */
typedef struct {
    float angle_rad; /* estimate, wrapped to [-pi, pi) */
    float speed_rad_s;
} foc_tracker;

/* Wraps an angle to [-pi, pi). */
float foc_wrap_pi(float angle_rad);

/* Amplitude-invariant Clarke transform (SPEC.md 1.1): alpha = a, beta = (a + 2 b)/sqrt3. */
void foc_clarke(float i_a, float i_b, float *alpha, float *beta);

/* Stationary (alpha, beta) to rotor (d, q) at the angle whose sine and cosine are given. */
void foc_park(float alpha, float beta, float sin_e, float cos_e, float *d, float *q);

/* Rotor (d, q) back to stationary (alpha, beta). */
void foc_inverse_park(float d, float q, float sin_e, float cos_e, float *alpha, float *beta);

/* One PI step with conditional integration: returns feedforward + kp e + integral,
 * clamped to +-limit; the integral moves only when that does not push the output
 * further into the limit. */
float foc_pi_step(const foc_pi_gains *g, float *integral, float error, float feedforward, float dt_s);

/* Scales (d, q) down to length limit when longer; returns 1 when it did. */
int foc_limit_vector(float *d, float *q, float limit);

/* Three centre-aligned duties (0..65535) for a stator voltage vector, min-max
 * zero-sequence injection (space-vector PWM): linear up to |v| = vdc/sqrt3. */
void foc_duties(float v_alpha, float v_beta, float vdc_v, uint16_t duty[3]);

/* One step of the critically damped type-2 tracking loop of natural frequency
 * w (rad/s): no angle or speed error at constant speed. */
void foc_tracker_step(foc_tracker *t, float measured_angle_rad, float w_rad_s, float dt_s);

#endif /* SPEC_MINIMAL_FOC_H */
