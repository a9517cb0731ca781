/*
 * Fast float trigonometry for the control step, polynomial (no tables, no
 * libm calls), so every step costs about the same and the Cortex-M4F FPU runs
 * it inline: one fused sincos, a sine, atan2 and asin.
 *
 * Coefficients are near-minimax fits (Lawson's iteration) made by
 * firmware_stub/tools/fit_fastmath.py; the error bounds below are asserted by
 * tests/test_fastmath.c over dense grids against libm in double precision.
 */
#ifndef FASTMATH_H
#define FASTMATH_H

#include <math.h>
#include <stdint.h>

#define FM_PI 3.14159265358979323846f
#define FM_TWO_PI 6.28318530717958647692f
#define FM_HALF_PI 1.57079632679489661923f
#define FM_SQRT3 1.73205080756887729353f
#define FM_INV_SQRT3 0.57735026918962576451f

/* Absolute error bounds in float arithmetic. The polynomials alone are 3.3e-8
 * (sincos), 8.8e-7 (sin), 1.7e-6 (atan2) and 6.7e-7 (asin); the rest is float
 * rounding (half an ulp of pi is 1.2e-7). */
#define FM_SINCOS_MAX_ERR 1.5e-7f /* |theta| <= 4 pi */
#define FM_SIN_MAX_ERR 1.5e-6f    /* |theta| <= 4 pi (wrapping 4 pi costs 1e-6) */
#define FM_ATAN2_MAX_ERR 2.0e-6f  /* any finite (y, x) */
#define FM_ASIN_MAX_ERR 1.0e-6f   /* |x| <= 1 */

/* sin and cos of theta in one range reduction. */
void fm_sincos(float theta_rad, float *sin_out, float *cos_out);
/* sin alone, cheaper: one reduction to [-pi/2, pi/2] for |theta| <= pi. */
float fm_sin(float theta_rad);
/* arcsine of x clamped to [-1, 1]. */
float fm_asin(float x);

float fm_wrap_pi_slow(float theta_rad);

/* atan(z) = z (A0 + z^2 (A1 + ... z^2 A5)) on [0, 1], error 1.7e-6 */
#define FM_A0 0.9999772310256958f
#define FM_A1 (-0.33262282609939575f)
#define FM_A2 0.19354042410850525f
#define FM_A3 (-0.11642659455537796f)
#define FM_A4 0.05264747887849808f
#define FM_A5 (-0.01171918585896492f)

/* Four-quadrant arctangent in [-pi, pi]; 0 for (0, 0). Inline: the control
 * step's one heavy function. */
static inline float fm_atan2(float y, float x)
{
    float ax = fabsf(x);
    float ay = fabsf(y);
    float hi = ax > ay ? ax : ay;
    float lo = ax > ay ? ay : ax;
    if (hi == 0.0f) {
        return 0.0f;
    }
    float z = lo / hi;
    float z2 = z * z;
    float a = z * (FM_A0 + z2 * (FM_A1 + z2 * (FM_A2 + z2 * (FM_A3 + z2 * (FM_A4 + z2 * FM_A5)))));
    if (ay > ax) {
        a = FM_HALF_PI - a;
    }
    if (x < 0.0f) {
        a = FM_PI - a;
    }
    return y < 0.0f ? -a : a;
}

/* Float to integer as a C cast (truncation towards zero) where the cast is defined, saturated
 * where it is not (C99 6.3.1.4: undefined out of range): +-inf and values beyond the type's
 * range give its limits, NaN gives 0. The callers' NaN becomes a NaN result or a fault
 * downstream (control.c); only the conversion itself must never be undefined. */
static inline int32_t fm_trunc_sat_i32(float x)
{
    if (x >= 2147483648.0f) {
        return INT32_MAX;
    }
    if (x >= -2147483648.0f) {
        return (int32_t)x;
    }
    return x < 0.0f ? INT32_MIN : 0; /* below the range, or NaN */
}

static inline uint32_t fm_trunc_sat_u32(float x)
{
    if (x >= 4294967296.0f) {
        return UINT32_MAX;
    }
    if (x >= 0.0f) {
        return (uint32_t)x;
    }
    return 0u; /* negative, or NaN */
}

/* theta wrapped to [-pi, pi]; exact for |theta| < 2^20 rad. Inline: most
 * calls are already in range or one turn out. */
static inline float fm_wrap_pi(float theta_rad)
{
    if (theta_rad > FM_PI) {
        theta_rad -= FM_TWO_PI;
        if (theta_rad > FM_PI) {
            theta_rad = fm_wrap_pi_slow(theta_rad);
        }
    } else if (theta_rad < -FM_PI) {
        theta_rad += FM_TWO_PI;
        if (theta_rad < -FM_PI) {
            theta_rad = fm_wrap_pi_slow(theta_rad);
        }
    }
    return theta_rad;
}

#endif
