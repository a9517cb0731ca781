/*
 * PI speed regulator producing the torque reference (Fig. 3), with a torque
 * limit and anti-windup by conditional integration: the integrator is frozen
 * while the output is saturated and the error would push it further into
 * saturation, and it is itself clamped to the torque limit.
 *
 * Gains from a bandwidth: with the DTC torque loop much faster than the speed
 * loop the plant is 1/(J s), and Kp = 2 J wb, Ki = J wb^2 place a double
 * closed-loop pole at -wb (see docs/stub.md).
 */
#ifndef SPEED_PI_H
#define SPEED_PI_H

typedef struct {
    float kp_nm_per_rad_s;
    float ki_nm_per_rad;
    float torque_limit_nm;
    float control_period_s;
    float ki_per_step_nm_per_rad_s; /* Ki T, derived by spi_derive() */
} spi_cfg;

typedef struct {
    float integral_nm;
} spi_state;

void spi_derive(spi_cfg *cfg);
/* Speeds in mechanical rad/s; returns the torque reference in Nm. While the
 * output is saturated and the error pushes further, it returns the limit and
 * leaves the integrator alone. */
float spi_step(const spi_cfg *cfg, spi_state *st, float speed_ref_rad_s, float speed_meas_rad_s);

#endif
