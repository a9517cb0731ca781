/*
 * Start-up stator-resistance identification (HIL_PARAM_RS_ID_PERIODS), what drive firmware
 * does about a winding whose temperature it does not know (ODrive's measure_phase_resistance,
 * a commercial drive's "motor ID"): with the rotor at standstill, a current PI on the measured
 * current drives a DC current along the rotor's d axis (the magnet: no torque), and R comes
 * from the voltage the board applies for it.
 *
 * Two-point method. The inverter does not apply what the board asks: dead time and device
 * drop take a voltage c off the request that depends on the sign of each phase current but
 * not on its size (once every phase current is clear of the devices' knee). At a DC current
 * I along d, in the board's own units,
 *     U = R I + c,
 * so two levels I1 < I2 of the same sign give R = (U2 - U1) / (I2 - I1), with c gone; one
 * level would give R + c / I (c = 5.7 V on the paper's inverter against R I = 2.2 V at 4 A).
 *
 * Each level lasts periods_per_level periods: the first quarter lets the loop settle, the mean
 * request U and the mean measured current I over the other three quarters (the window W) are
 * taken. The winding's L di/dt term averages to L (i_end - i_start) / W: once the loop has
 * settled, what is left of it is the true current's noise (the loop feeds the ADC noise
 * back), whose two ends give R an error of about 2 L sigma_i / (W (I2 - I1)): W must be long
 * against L / R and the loop slow enough to pass little noise (docs/stub.md). Then
 * the bridge is opened for off_periods so the current decays through the diodes before the
 * drive starts (its observer then starts from a zero current, as after the zero calibration).
 *
 * What R it finds: the board computes its duties from its own DC-link reading v_hat =
 * (1 + e_v) v and reads its current as g i, so U = (1 + e_v) (R i + c) and
 * R_id = (1 + e_v) R / g: the resistance as seen through the board's own voltage and current
 * scales, which is the one its flux observer needs (docs/stub.md).
 *
 * PI: u = Kp e + integral, Kp = Ls wc, Ki = Kp wc / 5 (integral zero a fifth of the crossover,
 * so the step of c is rejected by a closed-loop pole, not by the slow L/R = 8.6 ms pole that
 * the pole-zero cancelling FOC design Ki = R wc leaves when R is wrong). At wc = 2 pi 500 Hz
 * on the Table 1 winding, with one period of delay, the slowest closed-loop pole is at 1.3 ms.
 * The request is limited to u_max with the integrators clamped to it. Functions of the state
 * struct and the period only.
 */
#ifndef RS_ID_H
#define RS_ID_H

#include <stdint.h>

typedef struct {
    uint32_t periods_per_level; /* N per current level, 0 = off */
    uint32_t off_periods;       /* bridge open after the two levels */
    float current_low_a;        /* I1 */
    float current_high_a;       /* I2 > I1 */
    float stator_inductance_h;  /* the PI gains */
    float bandwidth_hz;
    float control_period_s;
    /* derived by rsid_derive() */
    float kp_v_per_a;
    float ki_per_step_v_per_a;
    uint32_t settle_periods; /* N / 4 */
} rsid_cfg;

typedef enum {
    RSID_IDLE = 0, /* not run (yet) */
    RSID_LOW,      /* driving I1 */
    RSID_HIGH,     /* driving I2 */
    RSID_OFF,      /* bridge open, current decaying */
    RSID_DONE,     /* r_ohm identified */
    RSID_FAILED    /* no valid result (voltage limit, current not reached) */
} rsid_phase;

typedef struct {
    uint8_t phase;    /* rsid_phase */
    uint8_t limited;  /* the request hit u_max during a measuring window */
    uint32_t count;   /* periods spent in this phase */
    float integral_d_v;
    float integral_q_v;
    float u_start_v;  /* the request at the start of the measuring window */
    float sum_u_v;    /* over the measuring window of the level: sum of u - u_start */
    float sum_i_a;    /* sum of i - the level's reference */
    float u_low_v;    /* level means */
    float i_low_a;
    float u_high_v;
    float i_high_a;
    float r_ohm;      /* the result once phase is RSID_DONE */
} rsid_state;

void rsid_derive(rsid_cfg *cfg);
/* Arms the identification: the next rsid_step drives I1. */
void rsid_start(rsid_state *st);
/* One period. i_d, i_q: the measured current in the rotor frame (the encoder's angle); u_max:
 * the voltage limit (Vdc/sqrt3 of the board's reading). Writes the rotor-frame request
 * (u_d, u_q) for the next period and returns 1 while the bridge is driven; returns 0 when it
 * must be open (RSID_OFF) or the identification has ended (RSID_DONE, RSID_FAILED). */
uint8_t rsid_step(const rsid_cfg *cfg, rsid_state *st, float i_d_a, float i_q_a, float u_max_v, float *u_d_v,
                  float *u_q_v);

#endif
