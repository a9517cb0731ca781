/*
 * Six-step (120-degree block) commutation from an incremental encoder, with a
 * speed PI and a per-period current chopper: the control law of the example
 * board. C99, float only, no allocation, no I/O. Every block is a function of
 * an explicit configuration, its state and the control period.
 *
 * Conventions (protocol/SPEC.md, docs/plant.md): the encoder counts up for
 * positive rotation with count 0 at theta_m = 0, where the magnet's d-axis lies
 * along phase a (theta_e = p theta_m = 0); positive rotation turns alpha towards
 * beta, i.e. phase order a, b, c.
 */
#ifndef SIXSTEP_H
#define SIXSTEP_H

#include <stdint.h>

#define SIXSTEP_PI 3.14159265358979f
#define SIXSTEP_TWO_PI 6.28318530717959f

/* ---- defaults: the Table 1 motor on the bench's 50 us period ---------------- */
#define SIXSTEP_DEFAULT_PERIOD_S 50e-6f
#define SIXSTEP_DEFAULT_POLE_PAIRS 1u
#define SIXSTEP_DEFAULT_MAGNET_FLUX_WB 0.0928f
#define SIXSTEP_DEFAULT_COUNTS_PER_REV 4096u
/* The design inertia of the speed loop (Table 1: rotor and load). It is not a
 * protocol parameter: a user sets it for their drive here. */
#define SIXSTEP_DESIGN_INERTIA_KGM2 8.0e-4f
/* Speed loop: closed-loop double pole at this frequency (see sixstep_speed_pi_design). */
#define SIXSTEP_SPEED_BANDWIDTH_HZ 10.0f
/* Encoder speed tracking loop: critically damped, 20x the speed loop so that
 * its lag hardly shifts the speed loop's poles. */
#define SIXSTEP_TRACKER_BANDWIDTH_HZ 200.0f
#define SIXSTEP_DEFAULT_TORQUE_LIMIT_NM 2.0f
#define SIXSTEP_DEFAULT_OVERCURRENT_A 20.0f
#define SIXSTEP_DEFAULT_ENCODER_LOSS_TIMEOUT_S 0.01f

/* ---- electrical angle and commutation ------------------------------------- */

/* Electrical angle in [0, 2 pi) of an encoder position in [0, counts_per_rev). */
float sixstep_electrical_angle(uint32_t position_counts, uint32_t counts_per_rev, uint32_t pole_pairs);

/* Commutation sector 1..6 of the electrical angle (any value, wrapped). Sector s
 * spans theta_e in [60 s - 150, 60 s - 90) degrees: its pair of phases puts the
 * current vector at 60 s - 30 degrees, the q-axis (theta_e + 90) never more than
 * 30 degrees away. The sector edges (30, 90, 150 ... degrees) are where a
 * BLDC's Hall sensors would switch. */
uint8_t sixstep_sector(float theta_e_rad);

/* The pair of phases a sector drives for positive torque: current flows in at
 * `high` and out at `low` (0 = a, 1 = b, 2 = c). Negative torque uses the pair
 * of the sector three steps on (the same two phases, reversed). */
typedef struct {
    uint8_t high;
    uint8_t low;
} sixstep_pair;
sixstep_pair sixstep_commutation(uint8_t sector, int torque_negative);

/* Chopper states for one period */
typedef enum {
    SIXSTEP_OFF = 0,        /* all six switches open: current decays into the DC link (fast) */
    SIXSTEP_DRIVE = 1,      /* high switch of `high`, low switch of `low`: +Vdc across the pair */
    SIXSTEP_FREEWHEEL = 2   /* low switch of `low` only: the pair shorted through a diode (slow decay) */
} sixstep_chop;

/* GATES bits (HIL_GATE_*) for a pair in a chopper state. Never both switches of a leg. */
uint8_t sixstep_gates(sixstep_pair pair, sixstep_chop chop);

/* Current chopper, decided once per period from the current sampled at its
 * start: drive while the pair current is below the reference magnitude, else
 * let it decay. Slow decay (freewheel) only while motoring: when braking the
 * back-EMF drives the pair current, a shorted pair would let it grow, so the
 * switches open and the DC link absorbs it. */
sixstep_chop sixstep_chopper(float pair_current_a, float current_ref_a, int motoring);

/* Pair current (A, positive into `high` and out of `low`): the mean of the two
 * phase currents so ADC noise averages. */
float sixstep_pair_current(const float phase_current_a[3], sixstep_pair pair);

/* Mean torque per ampere of pair current under 120-degree block commutation
 * with a sinusoidal back-EMF: the current vector of length 2 I / sqrt 3 sits
 * within +-30 degrees of the q-axis, T = 3/2 p psi (2/sqrt 3) I cos(delta),
 * averaged over delta: (3 sqrt 3 / pi) p psi (0.1535 N m/A for Table 1). */
float sixstep_torque_constant(uint32_t pole_pairs, float magnet_flux_wb);

/* ---- encoder position and speed ------------------------------------------- */

/* Tracks the mechanical position from a 16-bit wrapping counter (any counts
 * per revolution) and estimates the speed with a type-2 tracking loop: zero
 * steady-state error on constant speed and constant acceleration. */
typedef struct {
    float kp_per_s;    /* 2 w_n (critically damped) */
    float ki_per_s2;   /* w_n^2 */
} sixstep_tracker_gains;
typedef struct {
    uint8_t started;
    uint16_t last_count;
    uint32_t position_counts; /* 0 .. counts_per_rev - 1 */
    float angle_rad;          /* tracked mechanical angle, [0, 2 pi) */
    float speed_rad_s;        /* tracked mechanical speed */
} sixstep_tracker;

sixstep_tracker_gains sixstep_tracker_design(float bandwidth_hz);
void sixstep_tracker_reset(sixstep_tracker *tr);
/* Feeds one counter value; returns the counts moved since the last one. */
int32_t sixstep_tracker_step(const sixstep_tracker_gains *g, sixstep_tracker *tr, uint16_t count,
                             uint32_t counts_per_rev, float dt_s);

/* ---- speed PI ------------------------------------------------------------- */

typedef struct {
    float kp_nm_per_rad_s;
    float ki_nm_per_rad;
    float torque_limit_nm;
} sixstep_pi_gains;
typedef struct {
    float integral_nm;
} sixstep_pi;

/* Gains that put the closed speed loop's two poles at -2 pi f (torque follows
 * its reference; J ds^2 + kp s + ki = J (s + w)^2): kp = 2 J w, ki = J w^2. */
sixstep_pi_gains sixstep_speed_pi_design(float inertia_kgm2, float bandwidth_hz, float torque_limit_nm);
/* One step: torque reference in [-limit, limit]. Conditional integration: the
 * integrator holds while the output is saturated and the error pushes further. */
float sixstep_pi_step(const sixstep_pi_gains *g, sixstep_pi *pi, float error_rad_s, float dt_s);

/* ---- protection ----------------------------------------------------------- */

/* Encoder loss: the counter has not moved for longer than the timeout while
 * running, and either the last speed seen promised an edge within the timeout
 * (a turning rotor stopped counting) or the drive has asked for at least half
 * its torque limit all along (a stalled or blind drive). */
typedef struct {
    uint32_t silent_periods; /* periods since the counter last moved */
    uint32_t demand_periods; /* of those, periods the torque reference has been >= half the limit */
    float speed_at_edge_rad_s;
} sixstep_encoder_watch;
/* Returns 1 when the encoder is declared lost: silent for more than
 * timeout_periods (0 disables the check). Periods, not summed seconds, so the
 * trip comes on the same sample on every machine. */
int sixstep_encoder_watch_step(sixstep_encoder_watch *w, int32_t moved_counts, float speed_rad_s,
                               float torque_ref_nm, float torque_limit_nm, uint32_t counts_per_rev,
                               uint32_t timeout_periods, float dt_s);

#endif
