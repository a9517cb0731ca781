#include "fastmath.h"

#include <stdint.h>

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
/* atan(z) = z (A0 + z^2 (A1 + ... z^2 A6)) on [0, 1], error 2.5e-7 */
#define FM_A0 0.9999961256980896f
#define FM_A1 (-0.3331736922264099f)
#define FM_A2 0.19807815551757812f
#define FM_A3 (-0.13233338296413422f)
#define FM_A4 0.07962360978126526f
#define FM_A5 (-0.03360416740179062f)
#define FM_A6 0.006811774335801601f

void fm_sincos(float theta_rad, float *sin_out, float *cos_out)
{
    float qf = theta_rad * FM_TWO_OVER_PI;
    int32_t q = (int32_t)(qf + (qf >= 0.0f ? 0.5f : -0.5f));
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

float fm_atan2(float y, float x)
{
    float ax = x < 0.0f ? -x : x;
    float ay = y < 0.0f ? -y : y;
    float hi = ax > ay ? ax : ay;
    float lo = ax > ay ? ay : ax;
    if (hi == 0.0f) {
        return 0.0f;
    }
    float z = lo / hi;
    float z2 = z * z;
    float a = z * (FM_A0 + z2 * (FM_A1 + z2 * (FM_A2 + z2 * (FM_A3 + z2 * (FM_A4 + z2 * (FM_A5 + z2 * FM_A6))))));
    if (ay > ax) {
        a = FM_HALF_PI - a;
    }
    if (x < 0.0f) {
        a = FM_PI - a;
    }
    return y < 0.0f ? -a : a;
}

float fm_wrap_pi(float theta_rad)
{
    if (theta_rad >= -FM_PI && theta_rad <= FM_PI) {
        return theta_rad;
    }
    float turns = theta_rad * (1.0f / FM_TWO_PI);
    int32_t k = (int32_t)(turns + (turns >= 0.0f ? 0.5f : -0.5f));
    return theta_rad - (float)k * FM_TWO_PI;
}
