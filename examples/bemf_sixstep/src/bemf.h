/*
 * Sensorless six-step (120-degree block) drive from the back-EMF comparators:
 * the control law of the example ESC board. C99, float only, no allocation, no
 * I/O. Every block is a function of an explicit configuration, its state and
 * the control period; time is counted in control periods ("ticks") so that a
 * decision falls on the same sample on every machine.
 *
 * Conventions (protocol/SPEC.md 1.1): phases a, b, c in positive sequence,
 * theta_e = 0 with the magnet's d-axis on phase a; phase x's back-EMF is
 * -w_e psi sin(theta_e - x 120 deg) (trapezoidal: the same zero crossings), so
 * it crosses zero rising at theta_e = 180 + 120 x and falling at 120 x deg.
 * Comparator bit x is 1 while terminal x is above the virtual neutral, i.e.
 * while a floating phase's back-EMF is positive.
 */
#ifndef BEMF_H
#define BEMF_H

#include <stdint.h>

#define BEMF_PI 3.14159265358979f
#define BEMF_TWO_PI 6.28318530717959f

/* ---- commutation ---------------------------------------------------------- */

/* One of the six commutation steps (1..6), in the order of positive rotation.
 * Step s drives current in at `high` and out at `low` and floats the third
 * phase, whose back-EMF crosses zero in the middle of the step: rising for odd
 * steps, falling for even ones. Step s is right for theta_e in
 * [60 s - 150, 60 s - 90) deg (the current vector 90 deg ahead of the rotor in the
 * middle of the step; both driven phases on their EMF's flat tops).
 *   1: a -> c, b floats, rises at 300    2: b -> c, a floats, falls at 0
 *   3: b -> a, c floats, rises at 60     4: c -> a, b floats, falls at 120
 *   5: c -> b, a floats, rises at 180    6: a -> b, c floats, falls at 240 */
typedef struct {
    uint8_t high;     /* 0 = a, 1 = b, 2 = c */
    uint8_t low;
    uint8_t floating;
    uint8_t rising;   /* 1: the floating phase's comparator goes 0 -> 1 at its zero cross */
} bemf_step;
bemf_step bemf_commutation(uint8_t step);
/* The step after `step` for positive rotation (6 -> 1). */
uint8_t bemf_next_step(uint8_t step);

/* ---- zero-cross detection ------------------------------------------------- */

/* The floating phase's zero cross, from its comparator bit, once per period.
 * After a commutation the floating terminal is first clamped to a rail while
 * the current of the phase that just turned off decays through a diode
 * (demagnetisation); that clamp reads as the level *after* the zero cross.
 * So nothing is looked at until the blanking interval is over AND the floating
 * phase's current has been below the demagnetisation threshold for two
 * samples (the comparator sees a period's average), or it still flows at the
 * demagnetisation limit (then it is a rotor ahead of the step holding the
 * diode on, not demagnetisation); then the zero cross is the first of
 * `confirm_samples` consecutive samples at the level after the crossing for
 * this step's direction (as AM32 does: a rotor that is already past its
 * crossing shows it at once, which pulls the commutation forward and keeps the
 * drive in step).
 *
 * Its time within the period is found from the floating terminal's voltage to
 * the virtual neutral (the terminal ADCs), linear about the crossing: between
 * the samples either side of it; or, when one of them is clamped to a rail
 * (a floating terminal whose back-EMF pulls it below DC- conducts through its
 * diode during the PWM off-time), extrapolated from the two clean samples on
 * the other side; else the middle of the period. A cross whose level showed on
 * the first sample looked at is dated at that sample. */
typedef struct {
    uint32_t blanking_periods;   /* after a commutation: nothing is read */
    float demag_current_a;       /* the floating phase's |current| below which demagnetisation is over */
    uint32_t demag_limit_periods; /* after a commutation: a current still flowing is no longer demagnetisation */
    uint32_t confirm_samples;    /* >= 1; with 2 or more the sample after the cross helps date it */
} bemf_zc_config;

/* One sample of the floating terminal: its voltage less the virtual neutral
 * (V, any scale: only ratios are used) and whether it sits on a rail. */
typedef struct {
    float diff_v;
    uint8_t clamped;
} bemf_terminal;

typedef struct {
    uint8_t floating;
    uint8_t rising;
    uint8_t found;          /* this step's zero cross is found */
    uint8_t before_seen;    /* the previous sample was looked at and read the level before the cross */
    uint32_t armed_tick;    /* the commutation's tick */
    uint32_t run;           /* consecutive samples at the level after the crossing */
    uint32_t first_tick;    /* the first of them */
    uint32_t quiet;         /* consecutive samples with the floating current out (demagnetised) */
    float before_v[2];      /* the last two samples before the cross ([0] the newer), rising-signed */
    uint8_t before_ok[2];   /* each looked at, adjacent, not clamped */
    float after_v;          /* the first sample after the cross, rising-signed */
    uint8_t after_ok;
} bemf_zc_detector;

/* When a zero cross happened: `tick` + `frac` periods, frac in [0, 1]. */
typedef struct {
    uint32_t tick;
    float frac;
} bemf_instant;

/* Arms the detector for a new step, commutated at `tick`. */
void bemf_zc_arm(bemf_zc_detector *zc, bemf_step step, uint32_t tick);
/* Feeds one sample: the comparator bits, the floating phase's current and
 * terminal. Returns 1 on the sample that confirms the zero cross, with *at its
 * time; 0 otherwise (and after the cross is found). */
int bemf_zc_feed(const bemf_zc_config *cfg, bemf_zc_detector *zc, uint8_t comparators,
                 float floating_current_a, bemf_terminal terminal, uint32_t tick, bemf_instant *at);

/* ---- zero-cross timing: commutation 30 deg after the cross, speed ---------- */

/* The last two 60-degree intervals between zero crosses (a rising and a
 * falling one: 120 electrical degrees). The speed is their angle over their
 * sum: short enough a window to follow a start from a few hundred rpm, and
 * the interpolated crosses keep it smooth. */
#define BEMF_INTERVALS 2u
typedef struct {
    bemf_instant last_zc;
    float interval_periods[BEMF_INTERVALS];
    uint32_t next;          /* ring index */
} bemf_timing;

/* Starts the record with `interval_periods` (the open-loop ramp's 60-degree
 * time) in every slot, the last cross at `zc`. */
void bemf_timing_seed(bemf_timing *t, float interval_periods, bemf_instant zc);
/* Records a zero cross. Returns the tick to commutate on: the cross plus half
 * the interval just measured (30 electrical degrees), less the detection lag
 * (`lag_periods`: the comparator and ADCs see a period's average through the
 * terminal filter: half a period plus the filter's time constant), rounded to
 * the nearest period and never before `now_tick`. */
uint32_t bemf_timing_zero_cross(bemf_timing *t, bemf_instant zc, float lag_periods, uint32_t now_tick);
/* Mechanical speed (rad/s) from the last intervals. */
float bemf_timing_speed_rad_s(const bemf_timing *t, uint32_t pole_pairs, float period_s);
/* The last 60-degree interval, periods. */
float bemf_timing_last_interval(const bemf_timing *t);

/* ---- open-loop start: align, then a ramp of the commutation frequency ------ */

typedef struct {
    uint32_t align_periods;
    float ramp_start_rad_s;  /* mechanical */
    float ramp_end_rad_s;
    uint32_t ramp_periods;   /* from start to end, then held at the end speed */
} bemf_ramp_config;
typedef struct {
    uint32_t tick;           /* since the ramp began */
    float speed_rad_s;       /* the commutation frequency, as a mechanical speed */
    float angle_rad;         /* electrical angle into the present step, [0, pi/3) */
} bemf_ramp;
void bemf_ramp_reset(bemf_ramp *r, const bemf_ramp_config *cfg);
/* Advances one period; returns 1 when the commutation is due (60 degrees turned). */
int bemf_ramp_step(bemf_ramp *r, const bemf_ramp_config *cfg, uint32_t pole_pairs, float dt_s);

/* ---- regulators ----------------------------------------------------------- */

/* Speed PI: torque reference in [-limit, limit], conditional integration. */
typedef struct {
    float kp_nm_per_rad_s;
    float ki_nm_per_rad;
    float torque_limit_nm;
} bemf_speed_pi_gains;
typedef struct {
    float integral_nm;
} bemf_speed_pi;
/* kp = 2 J w, ki = J w^2: the closed speed loop's double pole at -w = -2 pi f. */
bemf_speed_pi_gains bemf_speed_pi_design(float inertia_kgm2, float bandwidth_hz, float torque_limit_nm);
float bemf_speed_pi_step(const bemf_speed_pi_gains *g, bemf_speed_pi *pi, float error_rad_s, float dt_s);

/* Pair-current PI with back-EMF feed-forward: the pair voltage
 * v = e_line + kp (i_ref - i) + integral, in [0, vdc]. The pair is 2 R, 2 L in
 * series with the line back-EMF, so kp = 2 L w_c and ki = 2 R w_c cancel its
 * pole and leave i / i_ref = w_c / (s + w_c): no overshoot. Conditional
 * integration at the rails. The back-EMF estimate moves in steps (the speed is
 * updated at each zero cross, late while the rotor accelerates) and the
 * integrator has meanwhile taken up what it missed: a step of the feed-forward
 * is taken off the integrator, so the voltage does not jump and the current
 * does not overshoot; the feed-forward sets the voltage where the loop starts. */
typedef struct {
    float resistance_ohm;     /* per phase */
    float kp_v_per_a;
    float ki_v_per_as;
} bemf_current_pi_gains;
typedef struct {
    float integral_v;
    float feed_forward_v;  /* the back-EMF fed forward last period */
    uint8_t primed;        /* feed_forward_v is valid */
} bemf_current_pi;
bemf_current_pi_gains bemf_current_pi_design(float resistance_ohm, float inductance_h, float bandwidth_hz);
/* Returns the pair voltage, V, in [0, vdc_v]. */
float bemf_current_pi_step(const bemf_current_pi_gains *g, bemf_current_pi *pi, float current_ref_a,
                           float current_a, float line_emf_v, float vdc_v, float dt_s);

/* The torque-making current of a step (A, positive into `high`, out of `low`):
 * the larger of the two driven phases' currents. Through a commutation the
 * phase the two steps share carries the outgoing phase's decaying current
 * too, and with both driven EMFs on their flat tops the torque is
 * 2 p psi times that shared current: regulating the mean of the two would let
 * it (and the torque) rise half as much again. */
float bemf_pair_current(uint8_t step, const float i_abc[3]);

/* Mean torque per ampere of pair current with a trapezoidal back-EMF (120-deg
 * flat tops, peak w_e psi) and 120-degree current blocks: both conducting
 * phases sit on their flat tops, T = 2 E I / w_m = 2 p psi I. */
float bemf_torque_constant(uint32_t pole_pairs, float magnet_flux_wb);

/* ---- the drive ------------------------------------------------------------ */

typedef enum {
    BEMF_OFF = 0,       /* bridge open */
    BEMF_ALIGN = 1,     /* fixed vector: the rotor turns to a known angle */
    BEMF_RAMP = 2,      /* open-loop commutation, zero crosses watched */
    BEMF_CLOSED = 3,    /* commutation from the zero crosses, speed PI */
    BEMF_TRIPPED = 4    /* a protection tripped: bridge open until disabled */
} bemf_mode;

typedef enum {
    BEMF_TRIP_NONE = 0,
    BEMF_TRIP_OVERCURRENT = 1,  /* phase current above the limit, or the plant's comparator */
    BEMF_TRIP_DESYNC = 2        /* no zero cross within the timeout (desync, stall, start failed) */
} bemf_trip;

typedef struct {
    float control_period_s;
    uint32_t pole_pairs;
    float resistance_ohm;
    float magnet_flux_wb;
    float overcurrent_a;
    uint32_t zc_timeout_periods;   /* closed loop: since the last cross; ramp: since the ramp's end */
    uint8_t align_step;
    float align_current_a;         /* align and ramp: voltage 2 R I (+ the ramp's line back-EMF) */
    float ramp_current_a;
    uint32_t handover_zero_crosses; /* consecutive steps with a cross, at the ramp's end speed */
    float zc_lag_periods;
    float blanking_fraction;       /* of the last 60-degree interval */
    uint32_t min_blanking_periods;
    bemf_ramp_config ramp;
    bemf_zc_config zc;
    bemf_speed_pi_gains speed_gains;
    bemf_current_pi_gains current_gains;
    float torque_constant_nm_per_a;
} bemf_config;

typedef struct {
    uint8_t mode;                  /* bemf_mode */
    uint8_t step;                  /* 1..6, 0 with the bridge open */
    uint32_t tick;                 /* periods since enable (wrapping) */
    uint32_t mode_tick;            /* tick the mode began */
    uint32_t commutate_tick;       /* closed loop: when the next commutation is due */
    uint32_t valid_steps;          /* ramp: consecutive steps with a zero cross */
    uint32_t last_zc_tick;         /* the tick of the last cross (desync timeout) */
    uint32_t blanking_periods;     /* of the present step */
    uint32_t demag_limit_periods;  /* of the present step: blanking + a quarter interval */
    uint8_t coasting;              /* closed loop: the cross is overdue, the bridge is open */
    uint8_t trip;                  /* bemf_trip */
    float trip_value;
    float speed_rad_s;             /* mechanical, from the zero crosses (ramp: its speed) */
    float torque_ref_nm;
    float current_ref_a;
    float pair_current_a;
    float duty;                    /* the high leg's duty, 0..1 */
    bemf_zc_detector zc;
    bemf_timing timing;
    bemf_ramp ramp;
    bemf_speed_pi speed_pi;
    bemf_current_pi current_pi;
} bemf_drive;

/* The inputs of one period, in SI units. */
typedef struct {
    float phase_current_a[3];
    float vdc_v;
    uint8_t comparators;       /* bit x: terminal x above the virtual neutral */
    float terminal_v[3];       /* the terminal voltages (V, any common scale) */
    uint8_t overcurrent_flag;  /* the plant's hardware comparator */
    uint8_t torque_mode;       /* closed loop: torque_ref_nm instead of the speed PI's */
    float speed_ref_rad_s;
    float torque_ref_nm;
} bemf_inputs;

/* The bridge command of one period: `step`'s high leg at `duty`, its low leg at
 * duty 0, its floating leg open; step 0 opens the whole bridge (off, tripped,
 * or coasting while a zero cross is overdue). */
typedef struct {
    uint8_t step;
    float duty;
} bemf_output;

void bemf_drive_enable(bemf_drive *d, const bemf_config *cfg);
void bemf_drive_disable(bemf_drive *d);
/* One control period. Protections first (a NaN input trips as overcurrent). */
bemf_output bemf_drive_step(const bemf_config *cfg, bemf_drive *d, const bemf_inputs *in);

#endif
