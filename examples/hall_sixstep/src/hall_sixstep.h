/*
 * Six-step (120-degree block) commutation of a BLDC motor on three Hall
 * sensors, with a PWM current regulator on the conducting pair (the current
 * chopper), a speed PI and the drive's protections: the control law of the
 * hall_sixstep example board. C99, float only, no allocation, no I/O. Every
 * block is a function of an explicit configuration, its state and the control
 * period.
 *
 * Conventions (protocol/SPEC.md 1.1): theta_e = 0 with the magnet's d-axis on
 * phase a; positive rotation turns a -> b -> c. Hall x (x = a, b, c: bits 0, 1,
 * 2 of the Hall word) reads 1 while cos(theta_e - x 120 deg) > 0, so for
 * positive rotation the word runs 1, 3, 2, 6, 4, 5 with edges at
 * theta_e = 30 + 60 n degrees. Words 0 and 7 cannot occur with three working
 * sensors 120 degrees apart.
 */
#ifndef HALL_SIXSTEP_H
#define HALL_SIXSTEP_H

#include <stdint.h>

#define HS_PI 3.14159265358979f
#define HS_TWO_PI 6.28318530717959f

/* ---- defaults: the BLDC of examples/hall_sixstep/profiles/bldc.yaml --------- */
#define HS_DEFAULT_PERIOD_S 50e-6f
#define HS_DEFAULT_POLE_PAIRS 4u
#define HS_DEFAULT_MAGNET_FLUX_WB 0.0060f
#define HS_DEFAULT_RESISTANCE_OHM 0.25f
#define HS_DEFAULT_INDUCTANCE_H 0.3e-3f
/* The design inertia of the speed loop (rotor and load). Not a protocol
 * parameter: a user sets it for their drive here, or pushes the PI gains. */
#define HS_DESIGN_INERTIA_KGM2 2.0e-5f
/* Speed loop: closed-loop double pole at this frequency (hs_speed_pi_design). */
#define HS_SPEED_BANDWIDTH_HZ 10.0f
/* Current loop: the PI cancels the pair's L/R pole, closed loop first order at this frequency. */
#define HS_CURRENT_BANDWIDTH_HZ 1000.0f
#define HS_DEFAULT_TORQUE_LIMIT_NM 0.1f
#define HS_DEFAULT_OVERCURRENT_A 15.0f
/* No Hall edge for this long while at least half the torque limit is asked
 * for: the rotor is stalled (or the sensors are blind). */
#define HS_DEFAULT_STALL_TIMEOUT_S 0.05f
/* An illegal Hall word (0 or 7) for this many samples in a row trips the
 * drive: a single sample is already suspicious, two rule out a sampling race
 * on a real board's GPIO read. */
#define HS_HALL_ILLEGAL_PERIODS 2u
/* The Hall speed estimate falls to 0 after this long without an edge. */
#define HS_SPEED_ZERO_AFTER_S 0.1f

/* ---- Hall sensors and commutation ------------------------------------------ */

/* Commutation sector 1..6 of a Hall word (bit0 A, bit1 B, bit2 C; bits 3-7
 * ignored), 0 for the illegal words 0 and 7. Sector s spans theta_e in
 * [60 s - 150, 60 s - 90) degrees: word 5 -> 1, 1 -> 2, 3 -> 3, 2 -> 4,
 * 6 -> 5, 4 -> 6, so sectors count up for positive rotation. */
uint8_t hs_sector_of_hall(uint8_t hall_word);

/* The pair of phases a sector drives: current flows in at `high` and out at
 * `low` (0 = a, 1 = b, 2 = c), the third phase floats. Over sector s the
 * trapezoidal back-EMFs of `high` and `low` are on their flat tops (+E and
 * -E), so positive pair current gives positive torque 2 p psi i in either
 * direction of rotation, and negative pair current brakes. */
typedef struct {
    uint8_t high;
    uint8_t low;
} hs_pair;
hs_pair hs_commutation(uint8_t sector);

/* Torque-producing current of the pair (A, positive into `high` and out of
 * `low`): the largest phase current, signed as the pair current. In a sector it
 * is the pair's current; while the outgoing phase's current decays after a
 * commutation it is the current of the phase common to both pairs, the one
 * whose back-EMF (+-E, with the outgoing phase still near its flat top) carries
 * the torque, T = 2 E i_common / w_m. Regulating it keeps the torque through the
 * commutation. */
float hs_pair_current(const float phase_current_a[3], hs_pair pair);

/* Torque per ampere of pair current with 120-degree flat-top trapezoidal
 * back-EMF (peak p psi w_m per phase): two phases at +-E carry I, T = 2 E I / w_m
 * = 2 p psi I. */
float hs_torque_constant(uint32_t pole_pairs, float magnet_flux_wb);

/* ---- Hall speed ----------------------------------------------------------- */

/* Speed from the time between Hall edges: each edge is 60 electrical degrees,
 * (pi / 3) / p mechanical radians. The estimate spans the last three edge
 * intervals (half an electrical turn), so its two ends are edges of the same
 * sensor: that sensor's placement error and its hysteresis (both edges h/2 late
 * in the direction of motion) cancel. Until three intervals are seen (after the
 * start or a reversal) it spans those there are. Times are counted in periods,
 * so every machine computes the same estimate. */
#define HS_SPEED_WINDOW_EDGES 3u
typedef struct {
    uint8_t sector;              /* last legal sector, 0 before the first */
    int8_t direction;            /* +1 / -1 of the last edge, 0 when none (or after a jump) */
    uint8_t intervals;           /* whole intervals in the window, 0 .. HS_SPEED_WINDOW_EDGES */
    uint32_t periods_since_edge; /* periods since the last edge (or since the first sample) */
    uint32_t interval_periods[HS_SPEED_WINDOW_EDGES]; /* newest first */
    float speed_rad_s;           /* mechanical, signed */
} hs_hall_speed;

void hs_hall_speed_reset(hs_hall_speed *s);
/* Feeds one sample's sector (0 = illegal word: ignored, the estimate holds).
 * Returns +1 or -1 on an edge in that direction, else 0. Between edges the
 * estimate is capped by one edge angle over the time since the last edge (the
 * rotor cannot be faster than that, or the edge would have come), and falls to
 * 0 after HS_SPEED_ZERO_AFTER_S. */
int hs_hall_speed_step(hs_hall_speed *s, uint8_t sector, uint32_t pole_pairs, float dt_s);

/* ---- current regulator (the chopper's duty) -------------------------------- */

/* PI on the pair current with back-EMF feed-forward. The pair is two phases in
 * series: 2 R, 2 L, line back-EMF 2 p psi w_m on the flat tops. */
typedef struct {
    float kp_v_per_a;          /* 2 L w_c */
    float ki_v_per_a_s;        /* 2 R w_c: the zero cancels the pair's pole */
    float back_emf_v_per_rad_s; /* 2 p psi: line EMF per mechanical rad/s */
} hs_current_gains;
typedef struct {
    float integral_v;
} hs_current_pi;

hs_current_gains hs_current_design(float resistance_ohm, float inductance_h, uint32_t pole_pairs,
                                   float magnet_flux_wb, float bandwidth_hz);
/* One step: the pair voltage (V) to apply over the period, in [-vdc, vdc].
 * Conditional integration: the integrator holds while the output is limited and
 * the error pushes further. */
float hs_current_step(const hs_current_gains *g, hs_current_pi *pi, float current_ref_a, float pair_current_a,
                      float speed_rad_s, float vdc_v, float dt_s);

/* The bridge's answer for one period: per-leg high-side duty 0..1 and which
 * legs switch (HIL_LEG_* bits; a leg whose bit is 0 is floated). */
typedef struct {
    float duty[3];
    uint8_t leg_enable;
} hs_legs;

/* Legs for a pair voltage: v >= 0 PWMs `high` at v / vdc with `low`'s low
 * switch on (current driven in at `high`); v < 0 the other way round. Off-time
 * of the PWM'd leg is its low switch: both low switches on, the pair shorted
 * (slow decay). The third leg floats. vdc <= 0 floats every leg. */
hs_legs hs_legs_for_pair_voltage(hs_pair pair, float pair_voltage_v, float vdc_v);
/* Every leg floated: switching stopped. */
hs_legs hs_legs_off(void);

/* ---- speed PI ------------------------------------------------------------- */

typedef struct {
    float kp_nm_per_rad_s;
    float ki_nm_per_rad;
    float torque_limit_nm;
} hs_speed_gains;
typedef struct {
    float integral_nm;
} hs_speed_pi;

/* Gains that put the closed speed loop's two poles at -2 pi f (torque follows
 * its reference; J s^2 + kp s + ki = J (s + w)^2): kp = 2 J w, ki = J w^2. */
hs_speed_gains hs_speed_pi_design(float inertia_kgm2, float bandwidth_hz, float torque_limit_nm);
/* One step: torque reference in [-limit, limit], conditional integration. */
float hs_speed_pi_step(const hs_speed_gains *g, hs_speed_pi *pi, float error_rad_s, float dt_s);

/* ---- protection ----------------------------------------------------------- */

/* Illegal Hall words: returns 1 when the word has been illegal for
 * HS_HALL_ILLEGAL_PERIODS samples in a row. */
typedef struct {
    uint32_t illegal_periods;
} hs_hall_watch;
int hs_hall_watch_step(hs_hall_watch *w, uint8_t sector);

/* Stall: no Hall edge for more than timeout_periods while the torque reference
 * has been at least half the limit all along: a locked rotor, a load beyond the
 * drive, or sensors frozen on a legal word (the speed estimate then decays, and
 * the speed PI asks for more and more torque). A rotor that stops because it was
 * asked to does so with little torque and never trips. Periods, not summed
 * seconds, so the trip comes on the same sample on every machine. */
typedef struct {
    uint32_t silent_periods; /* periods since the last Hall edge */
    uint32_t demand_periods; /* of those, the trailing run with |torque_ref| >= half the limit */
} hs_stall_watch;
/* timeout_periods 0 disables the check. Returns 1 on the trip. */
int hs_stall_watch_step(hs_stall_watch *w, int edge, float torque_ref_nm, float torque_limit_nm,
                        uint32_t timeout_periods);

#endif
