#include "fastmath.h"

#include <math.h>

/* Cody-Waite split of pi/2 (fdlibm's): HI has 17 significant bits, so q * HI
 * is exact for |q| < 128, and LO = pi/2 - HI carries the rest. */
#define FM_PIO2_HI 1.5707855225e+00f
#define FM_PIO2_LO 1.0804334124e-05f
#define FM_TWO_OVER_PI 0.636619772367581343076f

/* sin(r) = r + r^3 (S1 + r^2 (S2 + r^2 S3)) on [-pi/4, pi/4], error 1.8e-9 */
#define FM_S1 (-0.16666650772094727f)
#define FM_S2 0.00833197869360447f
#define FM_S3 (-0.00019495638844091445f)
/* cos(r) = 1 + r^2 (C1 + r^2 (C2 + r^2 C3)) on [-pi/4, pi/4], error 3.3e-8 */
#define FM_C1 (-0.49999895691871643f)
#define FM_C2 0.04165629670023918f
#define FM_C3 (-0.0013597827637568116f)
/* sin(r) = r + r^3 (W1 + r^2 (W2 + r^2 W3)) on [-pi/2, pi/2], error 8.8e-7 */
#define FM_W1 (-0.16665680706501007f)
#define FM_W2 0.008312366902828217f
#define FM_W3 (-0.00018492189701646566f)
/* asin(x) = pi/2 - sqrt(1 - x) (B0 + x (B1 + ... x B5)) on [0, 1], error 6.7e-7 */
#define FM_B0 1.5707956552505493f
#define FM_B1 (-0.21454279124736786f)
#define FM_B2 0.08817091584205627f
#define FM_B3 (-0.04592685401439667f)
#define FM_B4 0.02061963826417923f
#define FM_B5 (-0.004911002703011036f)

void fm_sincos(float theta_rad, float *sin_out, float *cos_out)
{
    float qf = theta_rad * FM_TWO_OVER_PI;
    /* saturated: a NaN or infinite angle gives a NaN sine and cosine, not undefined behaviour */
    int32_t q = fm_trunc_sat_i32(qf + (qf >= 0.0f ? 0.5f : -0.5f));
    float r = (theta_rad - (float)q * FM_PIO2_HI) - (float)q * FM_PIO2_LO;
    float r2 = r * r;
    float s = r + r * r2 * (FM_S1 + r2 * (FM_S2 + r2 * FM_S3));
    float c = 1.0f + r2 * (FM_C1 + r2 * (FM_C2 + r2 * FM_C3));
    switch ((uint32_t)q & 3u) {
    case 0u:
        *sin_out = s;
        *cos_out = c;
        break;
    case 1u:
        *sin_out = c;
        *cos_out = -s;
        break;
    case 2u:
        *sin_out = -s;
        *cos_out = -c;
        break;
    default:
        *sin_out = -c;
        *cos_out = s;
        break;
    }
}

float fm_sin(float theta_rad)
{
    float r = fm_wrap_pi(theta_rad);
    /* sin(pi - r) = sin(r) folds [pi/2, pi] onto [0, pi/2] */
    if (r > FM_HALF_PI) {
        r = FM_PI - r;
    } else if (r < -FM_HALF_PI) {
        r = -FM_PI - r;
    }
    float r2 = r * r;
    return r + r * r2 * (FM_W1 + r2 * (FM_W2 + r2 * FM_W3));
}

float fm_asin(float x)
{
    float ax = fabsf(x);
    ax = ax < 1.0f ? ax : 1.0f;
    float p = FM_B0 + ax * (FM_B1 + ax * (FM_B2 + ax * (FM_B3 + ax * (FM_B4 + ax * FM_B5))));
    float a = FM_HALF_PI - sqrtf(1.0f - ax) * p;
    return x < 0.0f ? -a : a;
}

float fm_wrap_pi_slow(float theta_rad)
{
    float turns = theta_rad * (1.0f / FM_TWO_PI);
    int32_t k = fm_trunc_sat_i32(turns + (turns >= 0.0f ? 0.5f : -0.5f));
    return theta_rad - (float)k * FM_TWO_PI;
}
