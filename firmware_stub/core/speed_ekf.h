/*
 * Simplified EKF of the stator flux angle and speed, eq. (16)-(23).
 *
 * State x = [theta_s, w, w']: flux angle (electrical rad), its speed
 * (electrical rad/s) and the speed increment per period w' (rad/s), with
 * F = [[1 T 0] [0 1 1] [0 0 1]]. The measurement is the normalised flux
 * (y1, y2) = (cos theta_s, sin theta_s), eq. (16); the innovation eq. (20)
 *   eps = y2 cos(theta^) - y1 sin(theta^) = sin(theta_s - theta^)
 * is the angle error for small errors, so the steady-state Kalman gain reduces
 * to the three numbers k1, k2, k3 of eq. (19), designed by hil/design/ekf.py.
 *
 * ekf_step() takes the normalised flux as in the paper (one sincos);
 * ekf_step_angle() takes theta_s itself and forms the same eps as
 * sin(theta_s - theta^), for a caller that has the eq. (10) angle anyway (the
 * control step: one sine instead of a sincos and a normalisation).
 */
#ifndef SPEED_EKF_H
#define SPEED_EKF_H

typedef struct {
    float control_period_s;
    float k1;       /* rad per rad of innovation */
    float k2_rad_s; /* rad/s per rad */
    float k3_rad_s; /* (rad/s per period) per rad */
} ekf_cfg;

typedef struct {
    float theta_rad;             /* theta^(k), predicted for this sample, [-pi, pi] */
    float speed_rad_s;           /* w^(k) */
    float speed_increment_rad_s; /* w'(k) */
    float theta_filtered_rad;    /* theta^(k) + k1 eps(k): the angle at sample k (may pass +-pi by k1 eps) */
} ekf_state;

void ekf_reset(ekf_state *st, float theta_rad, float speed_rad_s);
/* One update with y1 = cos theta_s, y2 = sin theta_s (normalised flux). */
void ekf_step(const ekf_cfg *cfg, ekf_state *st, float y1_cos, float y2_sin);
/* The same update from the flux angle theta_s. */
void ekf_step_angle(const ekf_cfg *cfg, ekf_state *st, float theta_s_rad);

#endif
