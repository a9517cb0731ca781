/* A surface-magnet motor in the stationary frame for the FOC tests (double):
 * d psi/dt = u - R i, psi = Ls i + psi_f e^(j theta), theta advancing at a
 * fixed electrical speed; the period's average voltage held for the period
 * (what the plant's centre-aligned PWM integrates to, ripple aside). */
#ifndef MOTOR_MODEL_H
#define MOTOR_MODEL_H

#include <math.h>

#define MM_R 0.466
#define MM_LS 4.8e-3
#define MM_PSI_F 0.0928
#define MM_T 50e-6

typedef struct {
    double i_alpha, i_beta, theta, speed_e;
} motor_model;

static inline void mm_period(motor_model *m, double u_alpha, double u_beta)
{
    const int sub = 50;
    double h = MM_T / sub;
    for (int n = 0; n < sub; ++n) {
        /* Ls di/dt = u - R i - d(psi_f e^(j theta))/dt */
        double ea = -m->speed_e * MM_PSI_F * sin(m->theta);
        double eb = m->speed_e * MM_PSI_F * cos(m->theta);
        m->i_alpha += h * (u_alpha - MM_R * m->i_alpha - ea) / MM_LS;
        m->i_beta += h * (u_beta - MM_R * m->i_beta - eb) / MM_LS;
        m->theta += h * m->speed_e;
    }
}

static inline void mm_dq(const motor_model *m, double *i_d, double *i_q)
{
    double c = cos(m->theta), s = sin(m->theta);
    *i_d = c * m->i_alpha + s * m->i_beta;
    *i_q = c * m->i_beta - s * m->i_alpha;
}

#endif
