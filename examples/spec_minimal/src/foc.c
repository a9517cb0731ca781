/* Field-oriented control blocks of the minimal board (foc.h). */
#include "foc.h"

#include <math.h>

#define FOC_PI 3.14159265358979f
#define FOC_SQRT3 1.73205080756888f

float foc_wrap_pi(float angle_rad)
{
    const float two_pi = 2.0f * FOC_PI;
    return angle_rad - two_pi * floorf((angle_rad + FOC_PI) / two_pi);
}

void foc_clarke(float i_a, float i_b, float *alpha, float *beta)
{
    *alpha = i_a;
    *beta = (i_a + 2.0f * i_b) / FOC_SQRT3;
}

void foc_park(float alpha, float beta, float sin_e, float cos_e, float *d, float *q)
{
    *d = alpha * cos_e + beta * sin_e;
    *q = -alpha * sin_e + beta * cos_e;
}

void foc_inverse_park(float d, float q, float sin_e, float cos_e, float *alpha, float *beta)
{
    *alpha = d * cos_e - q * sin_e;
    *beta = d * sin_e + q * cos_e;
}

static float clamp(float v, float limit) { return fminf(fmaxf(v, -limit), limit); }

float foc_pi_step(const foc_pi_gains *g, float *integral, float error, float feedforward, float dt_s)
{
    float candidate = *integral + g->ki * error * dt_s;
    float out = feedforward + g->kp * error + candidate;
    /* integrate only while the output is inside the limit or the error pulls it back */
    if (fabsf(out) <= g->limit || out * error < 0.0f) {
        *integral = clamp(candidate, g->limit);
    }
    return clamp(feedforward + g->kp * error + *integral, g->limit);
}

int foc_limit_vector(float *d, float *q, float limit)
{
    float length = sqrtf(*d * *d + *q * *q);
    if (length <= limit) {
        return 0;
    }
    float scale = limit / length;
    *d *= scale;
    *q *= scale;
    return 1;
}

void foc_duties(float v_alpha, float v_beta, float vdc_v, uint16_t duty[3])
{
    /* phase voltages (inverse amplitude-invariant Clarke), then the min-max
     * common mode that centres them in the DC link */
    float v[3];
    v[0] = v_alpha;
    v[1] = -0.5f * v_alpha + 0.5f * FOC_SQRT3 * v_beta;
    v[2] = -0.5f * v_alpha - 0.5f * FOC_SQRT3 * v_beta;
    float common = -0.5f * (fmaxf(v[0], fmaxf(v[1], v[2])) + fminf(v[0], fminf(v[1], v[2])));
    for (int k = 0; k < 3; ++k) {
        /* d = 1/2 + v/vdc: the leg's mean voltage over the period, from the DC- rail, is d vdc */
        float d = 0.5f + (v[k] + common) / vdc_v;
        d = fminf(fmaxf(d, 0.0f), 1.0f);
        duty[k] = (uint16_t)(d * 65535.0f + 0.5f);
    }
}

void foc_tracker_step(foc_tracker *t, float measured_angle_rad, float w_rad_s, float dt_s)
{
    /* angle'' driven by the wrapped error: kp = 2 w (zeta 1), ki = w^2 */
    float error = foc_wrap_pi(measured_angle_rad - t->angle_rad);
    t->speed_rad_s += w_rad_s * w_rad_s * error * dt_s;
    t->angle_rad = foc_wrap_pi(t->angle_rad + (t->speed_rad_s + 2.0f * w_rad_s * error) * dt_s);
}
