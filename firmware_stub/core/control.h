/*
 * The control step of the DTC drive of Fig. 3: one SAMPLE in, gates and
 * telemetry out. All three speed sources (encoder, conventional eq. (10)-(11)
 * with low-pass filter, simplified EKF eq. (16)-(23)) run every step side by
 * side; the COMMAND picks the one that closes the speed loop.
 *
 * No I/O, no allocation: the caller owns the ctl struct. Start-up: while not
 * running, the flux observer is re-initialised every step from the encoder
 * angle, psi = psi_f (cos theta_e, sin theta_e) + Ls i (exact for a
 * surface-magnet motor), and the EKF tracks it, so all estimators are warm when
 * the drive is enabled. The paper does not describe start-up; a sensorless
 * board would use an alignment or injection method instead.
 */
#ifndef CONTROL_H
#define CONTROL_H

#include <stdint.h>

#include "hil_proto.h"
#include "clarke.h"
#include "flux_observer.h"
#include "foc.h"
#include "hysteresis.h"
#include "protection.h"
#include "rotor_position.h"
#include "rs_id.h"
#include "speed_conventional.h"
#include "speed_ekf.h"
#include "speed_encoder.h"
#include "speed_pi.h"
#include "switching_table.h"
#include "vsi.h"

/* Everything the bench can set with PARAM_SET (SI units), plus one value that
 * is not on the wire (the last). */
typedef struct {
    float control_period_s;
    float current_a_per_count;
    float current_offset_counts;
    float vdc_v_per_count;
    float vdc_offset_counts;
    float encoder_counts_per_rev;
    uint8_t current_phases; /* clarke_phases */
    float pole_pairs;
    float stator_resistance_ohm;
    float stator_inductance_h;
    float magnet_flux_wb;
    float flux_ref_wb;
    float flux_band_wb;
    float torque_band_nm;
    float torque_limit_nm;
    float speed_kp_nm_per_rad_s;
    float speed_ki_nm_per_rad;
    float speed_lpf_cutoff_hz;
    float ekf_k1;
    float ekf_k2_rad_s;
    float ekf_k3_rad_s;
    float flux_drift_cutoff_hz;
    uint32_t telemetry_divider; /* TELEMETRY every N SAMPLEs, 0 = never */
    float overcurrent_a;
    float encoder_loss_timeout_s;
    float encoder_loss_min_speed_rad_s;
    uint8_t control_law;      /* ctl_law */
    float current_bandwidth_hz; /* FOC current loop */
    uint8_t foc_angle_source; /* ctl_foc_angle */
    float dead_time_comp_s;   /* FOC duties and DTC observer voltage, 0 = off */
    float device_drop_comp_v; /* DTC observer voltage, 0 = off */
    uint8_t delay_comp_periods; /* DTC: 1 = answers act one period late: integrate the vector that acted, predict */
    uint32_t current_zero_cal_periods; /* at each enable, this many periods with the bridge off to measure the current ADCs' zero, 0 = off */
    uint32_t rs_id_periods; /* start-up stator-resistance identification, periods per current level (rs_id.h), 0 = off */
} ctl_params;

/* HIL_PARAM_CONTROL_LAW: the paper's DTC answers GATES, FOC answers DUTY */
typedef enum { CTL_LAW_DTC = 0, CTL_LAW_FOC = 1 } ctl_law;
/* TELEMETRY gates while FOC modulates: every switch is pulse-width modulated */
#define CTL_GATES_PWM 0x3Fu
/* HIL_PARAM_FOC_ANGLE_SOURCE: the rotor angle of the Park transforms */
typedef enum { CTL_FOC_ANGLE_ENCODER = 0, CTL_FOC_ANGLE_EKF = 1 } ctl_foc_angle;

/* Block configurations derived from ctl_params by ctl_derive(). */
typedef struct {
    clarke_cfg clarke;
    fluxobs_cfg flux;
    hyst_cfg flux_hyst;
    hyst_cfg torque_hyst;
    spi_cfg pi;
    enc_cfg enc;
    conv_cfg conv;
    ekf_cfg ekf;
    rotor_cfg rotor;
    prot_cfg prot;
    foc_cfg foc;
    invcomp_cfg inv;     /* DTC: the observer's inverter compensation */
    uint8_t inv_comp_on; /* dead time or device drop compensated */
    uint8_t delay_comp;  /* delay_comp_periods */
    uint32_t zero_cal_periods; /* current_zero_cal_periods */
    rsid_cfg rs_id;            /* rs_id_periods and the design values of defaults.h */
    uint8_t dtc_comp;    /* either of the two: the observer takes the compensated path */
    uint8_t control_law;
    uint8_t foc_angle_source;
    float vdc_v_per_count;
    float vdc_offset_counts;
    float pole_pairs;
    float inv_pole_pairs;
    float magnet_flux_wb;
    float stator_inductance_h;
    /* Table 3 composed with the gate bits: [sector 0..6][column], where the
     * column is (flux_up ? 0 : 2) + (torque_up ? 0 : 1) as in Table 3 and
     * sector 0 (not switching) gives 0 */
    uint8_t vector_of[7][4];
} ctl_cfg;

typedef struct {
    uint8_t enable;
    uint8_t torque_mode;
    uint8_t speed_source; /* hil_speed_source */
    float speed_ref_rad_s; /* mechanical */
    float torque_ref_nm;
    float flux_ref_wb; /* <= 0: use params.flux_ref_wb */
} ctl_command;

typedef struct {
    fluxobs_state flux;
    hyst_state flux_hyst;
    hyst_state torque_hyst;
    spi_state pi;
    enc_state enc;
    conv_state conv;
    ekf_state ekf;
    prot_state prot;
    foc_state foc;
    uint16_t duty[3];   /* FOC: the DUTY answer when answer_duty */
    uint8_t answer_duty; /* 1: answer this SAMPLE with DUTY (duty[]), 0: with GATES */
    uint8_t started;    /* first SAMPLE seen */
    uint8_t vector_prev; /* answer to the previous SAMPLE: vector 0..6 applied during the period that just ended (no delay) */
    uint8_t vector_prev2; /* the answer before it (the vector that acted, with one period of delay) */
    uint8_t vector_prev3; /* and before that (the dead-time edge, with one period of delay) */
    uint8_t state;      /* hil_state */
    uint8_t startup;        /* 1 after an enable until the zero calibration and the R identification are done */
    uint32_t zero_cal_left; /* periods of the start-up zero calibration still to run */
    uint32_t zero_cal_periods; /* its length, latched at the enable: a PARAM_SET during it acts at the next enable */
    float zero_cal_nominal_counts; /* the nominal zero the sums are taken from, latched with it */
    float zero_cal_sum1;    /* sums of adc_i1, adc_i2 minus the nominal zero over them */
    float zero_cal_sum2;
    rsid_state rs_id; /* the stator-resistance identification: runs once, after the zero calibration of the first enable */
    uint8_t fault_code; /* hil_fault_code latched */
    float fault_value;
    uint32_t fault_period;
    uint32_t step_cycles; /* set by the board layer (SysTick), read by PARAM_GET */
} ctl_state;

typedef struct {
    ctl_params params;
    ctl_cfg cfg;
    ctl_command cmd;
    float flux_ref_wb; /* in force: the command's, or params.flux_ref_wb when it gives none */
    ctl_state st;
} ctl;

void ctl_params_default(ctl_params *p);
/* Defaults, derived configuration, IDLE state. */
void ctl_init(ctl *c);
/* Recomputes every block configuration from c->params; call after changing them. */
void ctl_derive(ctl *c);

/* Applies a COMMAND. Enabling from IDLE starts switching at the next step;
 * clearing ENABLE stops switching and clears a latched fault. Returns 0, or -1
 * (command ignored) for an unknown speed source, or -2 (command ignored) for a
 * NaN or infinite reference (the caller trips NON_FINITE, HIL_NONFINITE_COMMAND). */
int ctl_set_command(ctl *c, const hil_command *cmd);

/* Latches a fault: switches off from now on, state FAULT until disabled. */
void ctl_trip(ctl *c, uint8_t fault_code, float value, uint32_t period);

/* The state the board reports in STATUS and TELEMETRY (SPEC.md 9.4): STARTING while the
 * start-up after an enable (zero calibration, resistance identification) runs, RUNNING once
 * the drive controls (ready), else st.state. */
uint8_t ctl_reported_state(const ctl *c);

/* One control period. While running, any current, voltage, speed, estimate or
 * reference that is NaN or infinite trips FAULT NON_FINITE (value: the
 * hil_nonfinite_quantity) and the gates go off in this same answer.
 * Returns the gates to apply until the next SAMPLE, or,
 * when it leaves c->st.answer_duty at 1 (FOC while running), the duties in
 * c->st.duty are the answer instead (the return value is then 0). With
 * tm not NULL, also fills every telemetry field, including the telemetry-only
 * rotor position of eq. (24)-(26); the estimators run every step either way. */
uint8_t ctl_step(ctl *c, const hil_sample *s, hil_telemetry *tm);

/* PARAM_SET / PARAM_GET by hil_param_id. Return a hil_param_status; *value is
 * the value now in force (the old one when the set is refused). */
uint8_t ctl_param_set(ctl *c, uint16_t id, float value, float *value_now);
uint8_t ctl_param_get(const ctl *c, uint16_t id, float *value);

#endif
