#include "control.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "defaults.h"
#include "fastmath.h"

void ctl_params_default(ctl_params *p)
{
    p->control_period_s = CTL_DEFAULT_CONTROL_PERIOD_S;
    p->current_a_per_count = CTL_DEFAULT_CURRENT_A_PER_COUNT;
    p->current_offset_counts = CTL_DEFAULT_CURRENT_OFFSET_COUNTS;
    p->vdc_v_per_count = CTL_DEFAULT_VDC_V_PER_COUNT;
    p->vdc_offset_counts = CTL_DEFAULT_VDC_OFFSET_COUNTS;
    p->encoder_counts_per_rev = CTL_DEFAULT_ENCODER_COUNTS_PER_REV;
    p->current_phases = CTL_DEFAULT_CURRENT_PHASES;
    p->pole_pairs = CTL_DEFAULT_POLE_PAIRS;
    p->stator_resistance_ohm = CTL_DEFAULT_STATOR_RESISTANCE_OHM;
    p->stator_inductance_h = CTL_DEFAULT_STATOR_INDUCTANCE_H;
    p->magnet_flux_wb = CTL_DEFAULT_MAGNET_FLUX_WB;
    p->torque_limit_nm = CTL_DEFAULT_TORQUE_LIMIT_NM;

    float t = p->control_period_s;
    float psi_f = p->magnet_flux_wb;
    float ls = p->stator_inductance_h;
    /* Flux reference: the i_d = 0 stator flux at half the torque limit,
     * |psi| = sqrt(psi_f^2 + (Ls i_q)^2) with i_q = T / (3/2 p psi_f). */
    float iq_a = 0.5f * p->torque_limit_nm / (1.5f * p->pole_pairs * psi_f);
    p->flux_ref_wb = sqrtf(psi_f * psi_f + (ls * iq_a) * (ls * iq_a));
    /* Bands of one period's step: one active vector moves the flux by 2/3 Vdc T
     * and, at standstill, the torque by 3/2 p psi_f (Vdc/sqrt3) T / Ls. A
     * narrower band cannot be resolved at this period; a wider one adds ripple. */
    p->flux_band_wb = 2.0f / 3.0f * CTL_DESIGN_DC_LINK_V * t;
    p->torque_band_nm = 1.5f * p->pole_pairs * psi_f * CTL_DESIGN_DC_LINK_V * FM_INV_SQRT3 * t / ls;
    /* Speed PI: double closed-loop pole at the design bandwidth on 1/(J s). */
    float wb = FM_TWO_PI * CTL_DESIGN_SPEED_BANDWIDTH_HZ;
    p->speed_kp_nm_per_rad_s = 2.0f * CTL_DESIGN_INERTIA_KG_M2 * wb;
    p->speed_ki_nm_per_rad = CTL_DESIGN_INERTIA_KG_M2 * wb * wb;
    p->speed_lpf_cutoff_hz = CTL_DESIGN_LPF_OVER_SPEED_BANDWIDTH * CTL_DESIGN_SPEED_BANDWIDTH_HZ;
    p->ekf_k1 = CTL_DEFAULT_EKF_K1;
    p->ekf_k2_rad_s = CTL_DEFAULT_EKF_K2_RAD_S;
    p->ekf_k3_rad_s = CTL_DEFAULT_EKF_K3_RAD_S;
    p->flux_drift_cutoff_hz = CTL_DEFAULT_FLUX_DRIFT_CUTOFF_HZ;
    p->telemetry_divider = CTL_DEFAULT_TELEMETRY_DIVIDER;
    p->overcurrent_a = CTL_DEFAULT_OVERCURRENT_A;
    p->encoder_loss_timeout_s = CTL_DEFAULT_ENCODER_LOSS_TIMEOUT_S;
    p->encoder_loss_min_speed_rad_s = CTL_DEFAULT_ENCODER_LOSS_MIN_SPEED_RAD_S;
    p->control_law = CTL_DEFAULT_CONTROL_LAW;
    p->current_bandwidth_hz = CTL_DEFAULT_CURRENT_BANDWIDTH_HZ;
    p->foc_angle_source = CTL_DEFAULT_FOC_ANGLE_SOURCE;
    p->dead_time_comp_s = CTL_DEFAULT_DEAD_TIME_COMP_S;
    p->device_drop_comp_v = CTL_DEFAULT_DEVICE_DROP_COMP_V;
    p->delay_comp_periods = CTL_DEFAULT_DELAY_COMP_PERIODS;
    p->current_zero_cal_periods = CTL_DEFAULT_CURRENT_ZERO_CAL_PERIODS;
    p->rs_id_periods = CTL_DEFAULT_RS_ID_PERIODS;
}

void ctl_derive(ctl *c)
{
    const ctl_params *p = &c->params;
    ctl_cfg *k = &c->cfg;
    float t = p->control_period_s;

    k->clarke.current_a_per_count = p->current_a_per_count;
    k->clarke.current_offset_counts = p->current_offset_counts;
    k->clarke.phases = p->current_phases;
    clarke_derive(&k->clarke);

    k->flux.stator_resistance_ohm = p->stator_resistance_ohm;
    k->flux.stator_inductance_h = p->stator_inductance_h;
    k->flux.magnet_flux_wb = p->magnet_flux_wb;
    k->flux.control_period_s = t;
    k->flux.drift_cutoff_hz = p->flux_drift_cutoff_hz;
    fluxobs_derive(&k->flux);

    k->flux_hyst.band = p->flux_band_wb;
    hyst_derive(&k->flux_hyst);
    k->torque_hyst.band = p->torque_band_nm;
    hyst_derive(&k->torque_hyst);

    k->pi.kp_nm_per_rad_s = p->speed_kp_nm_per_rad_s;
    k->pi.ki_nm_per_rad = p->speed_ki_nm_per_rad;
    k->pi.torque_limit_nm = p->torque_limit_nm;
    k->pi.control_period_s = t;
    spi_derive(&k->pi);

    k->enc.counts_per_rev = p->encoder_counts_per_rev;
    k->enc.pole_pairs = p->pole_pairs;
    k->enc.control_period_s = t;
    enc_derive(&k->enc);

    k->conv.control_period_s = t;
    k->conv.lpf_cutoff_hz = p->speed_lpf_cutoff_hz;
    conv_derive(&k->conv);

    k->ekf.control_period_s = t;
    k->ekf.k1 = p->ekf_k1;
    k->ekf.k2_rad_s = p->ekf_k2_rad_s;
    k->ekf.k3_rad_s = p->ekf_k3_rad_s;

    k->rotor.stator_inductance_h = p->stator_inductance_h;
    k->rotor.magnet_flux_wb = p->magnet_flux_wb;
    k->rotor.pole_pairs = p->pole_pairs;
    rotor_derive(&k->rotor);

    k->prot.overcurrent_a = p->overcurrent_a;
    k->prot.encoder_loss_timeout_s = p->encoder_loss_timeout_s;
    k->prot.encoder_loss_min_speed_rad_s = p->encoder_loss_min_speed_rad_s;
    k->prot.control_period_s = t;
    prot_derive(&k->prot);

    /* FOC current-loop gains follow R, Ls and the bandwidth (current_pi.h) */
    k->foc.current.bandwidth_hz = p->current_bandwidth_hz;
    k->foc.current.stator_resistance_ohm = p->stator_resistance_ohm;
    k->foc.current.stator_inductance_h = p->stator_inductance_h;
    k->foc.current.magnet_flux_wb = p->magnet_flux_wb;
    k->foc.pwm.dead_time_comp_s = p->dead_time_comp_s;
    k->foc.pwm.comp_band_a = CTL_DESIGN_DEAD_TIME_COMP_BAND_A;
    k->foc.pole_pairs = p->pole_pairs;
    k->foc.control_period_s = t;
    foc_derive(&k->foc);
    k->control_law = p->control_law;
    /* DTC: the same dead time and a device drop, compensated in the observer */
    k->inv.dead_time_s = p->dead_time_comp_s;
    k->inv.device_drop_v = p->device_drop_comp_v;
    k->inv.control_period_s = t;
    k->inv.sign_band_a = CTL_DESIGN_DEAD_TIME_COMP_BAND_A;
    invcomp_derive(&k->inv);
    k->inv_comp_on = (p->dead_time_comp_s > 0.0f || p->device_drop_comp_v > 0.0f) ? 1u : 0u;
    k->delay_comp = p->delay_comp_periods;
    k->zero_cal_periods = p->current_zero_cal_periods;
    k->rs_id.periods_per_level = p->rs_id_periods;
    k->rs_id.off_periods = fm_trunc_sat_u32(CTL_DESIGN_RS_ID_OFF_S / t + 0.999f);
    k->rs_id.current_low_a = CTL_DESIGN_RS_ID_CURRENT_LOW_A;
    k->rs_id.current_high_a = CTL_DESIGN_RS_ID_CURRENT_HIGH_A;
    k->rs_id.stator_inductance_h = p->stator_inductance_h;
    k->rs_id.bandwidth_hz = CTL_DESIGN_RS_ID_BANDWIDTH_HZ;
    k->rs_id.control_period_s = t;
    rsid_derive(&k->rs_id);
    k->dtc_comp = (uint8_t)(k->inv_comp_on | k->delay_comp);
    k->foc_angle_source = p->foc_angle_source;

    k->vdc_v_per_count = p->vdc_v_per_count;
    k->vdc_offset_counts = p->vdc_offset_counts;
    k->pole_pairs = p->pole_pairs;
    k->inv_pole_pairs = 1.0f / p->pole_pairs;
    k->magnet_flux_wb = p->magnet_flux_wb;
    k->stator_inductance_h = p->stator_inductance_h;
    for (uint8_t col = 0; col < 4u; ++col) {
        k->vector_of[0][col] = 0u;
        for (uint8_t sector = 1; sector <= 6u; ++sector) {
            k->vector_of[sector][col] = swtab_vector(sector, col < 2u, (col & 1u) == 0u);
        }
    }
}

void ctl_init(ctl *c)
{
    memset(c, 0, sizeof *c);
    ctl_params_default(&c->params);
    ctl_derive(c);
    c->cmd.enable = 0u;
    c->cmd.torque_mode = 0u;
    c->cmd.speed_source = HIL_SPEED_ENCODER;
    c->cmd.speed_ref_rad_s = 0.0f;
    c->cmd.torque_ref_nm = 0.0f;
    c->cmd.flux_ref_wb = 0.0f;
    c->flux_ref_wb = c->params.flux_ref_wb;
    c->st.started = 0u;
    c->st.vector_prev = 0u;
    c->st.state = HIL_STATE_IDLE;
    c->st.fault_code = HIL_FAULT_NONE;
    c->st.fault_value = 0.0f;
    c->st.fault_period = 0u;
    c->st.step_cycles = 0u;
    c->st.pi.integral_nm = 0.0f;
    c->st.flux_hyst.out = 1u;
    c->st.torque_hyst.out = 1u;
    prot_reset(&c->st.prot, 0u);
}

int ctl_set_command(ctl *c, const hil_command *cmd)
{
    if (cmd->speed_source > HIL_SPEED_EKF) {
        return -1;
    }
    /* a NaN reference would reach the speed loop and the hysteresis comparators */
    if (!isfinite(cmd->speed_ref_rad_s) || !isfinite(cmd->torque_ref_nm) || !isfinite(cmd->flux_ref_wb)) {
        return -2;
    }
    c->cmd.enable = (cmd->flags & HIL_CMD_ENABLE) ? 1u : 0u;
    c->cmd.torque_mode = (cmd->flags & HIL_CMD_TORQUE_MODE) ? 1u : 0u;
    c->cmd.speed_source = cmd->speed_source;
    c->cmd.speed_ref_rad_s = cmd->speed_ref_rad_s;
    c->cmd.torque_ref_nm = cmd->torque_ref_nm;
    c->cmd.flux_ref_wb = cmd->flux_ref_wb;
    c->flux_ref_wb = cmd->flux_ref_wb > 0.0f ? cmd->flux_ref_wb : c->params.flux_ref_wb;
    ctl_state *st = &c->st;
    if (!c->cmd.enable) {
        st->state = HIL_STATE_IDLE;
        st->fault_code = HIL_FAULT_NONE;
        st->fault_value = 0.0f;
    } else if (st->state == HIL_STATE_IDLE) {
        st->state = HIL_STATE_RUNNING;
        /* the bridge has been off: measure the current ADCs' zero before driving it; its
         * length and nominal zero are latched here, so that a PARAM_SET during it (which may
         * write 0) acts at the next enable and cannot make the mean divide by zero */
        st->zero_cal_periods = c->cfg.zero_cal_periods;
        st->zero_cal_nominal_counts = c->params.current_offset_counts;
        st->zero_cal_left = st->zero_cal_periods;
        st->zero_cal_sum1 = 0.0f;
        st->zero_cal_sum2 = 0.0f;
        /* then, once, the stator resistance (rs_id.h): only with the rotor at standstill */
        if (c->cfg.rs_id.periods_per_level > 0u && st->rs_id.phase < RSID_DONE) {
            if (fabsf(st->enc.speed_rad_s) < CTL_DESIGN_RS_ID_MAX_SPEED_RAD_S) {
                rsid_start(&st->rs_id);
            } else {
                st->rs_id.phase = RSID_IDLE;
            }
        }
        st->startup = (uint8_t)(st->zero_cal_left > 0u || st->rs_id.phase == RSID_LOW);
        st->pi.integral_nm = 0.0f;
        st->flux_hyst.out = 1u;
        st->torque_hyst.out = 1u;
        prot_reset(&st->prot, st->enc.last_count);
    }
    return 0;
}

void ctl_trip(ctl *c, uint8_t fault_code, float value, uint32_t period)
{
    c->st.state = HIL_STATE_FAULT;
    c->st.fault_code = fault_code;
    c->st.fault_value = value;
    c->st.fault_period = period;
}

uint8_t ctl_reported_state(const ctl *c)
{
    /* st.state stays RUNNING through the start-up (the step tells the two apart by
     * st.startup); the wire tells the bench the drive is not controlling yet */
    return (c->st.state == HIL_STATE_RUNNING && c->st.startup) ? (uint8_t)HIL_STATE_STARTING : c->st.state;
}

/* Flux from the encoder angle for a surface-magnet motor, and every flux-based
 * estimator aligned with it. */
static void track_encoder(ctl *c, const clarke_out *i)
{
    const ctl_cfg *k = &c->cfg;
    ctl_state *st = &c->st;
    float s, co;
    fm_sincos(enc_angle_e(&k->enc, &st->enc), &s, &co);
    float pa = k->magnet_flux_wb * co + k->stator_inductance_h * i->i_alpha_a;
    float pb = k->magnet_flux_wb * s + k->stator_inductance_h * i->i_beta_a;
    fluxobs_reset(&st->flux, pa, pb, i->i_alpha_a, i->i_beta_a);
    float theta = fm_atan2(pb, pa);
    float speed_e = st->enc.speed_rad_s * k->pole_pairs;
    conv_reset(&st->conv, theta, speed_e);
    ekf_reset(&st->ekf, theta, speed_e);
}

/* FOC (foc.h) on the encoder angle, or sensorless on the EKF's flux angle
 * minus the eq. (25) load angle (eq. (26)); the speed loop's feedback, in
 * electrical rad/s, feeds the decoupling. Answers DUTY. */
static void foc_law(ctl *c, const clarke_out *i, float torque_est, float flux_mag, float vdc_v, float torque_ref,
                    float speed_mech)
{
    const ctl_cfg *k = &c->cfg;
    ctl_state *st = &c->st;
    float theta_e;
    if (k->foc_angle_source == CTL_FOC_ANGLE_EKF) {
        theta_e = st->ekf.theta_filtered_rad - rotor_load_angle(&k->rotor, torque_est, flux_mag);
    } else {
        theta_e = enc_angle_e(&k->enc, &st->enc);
    }
    float duty[3];
    foc_step(&k->foc, &st->foc, theta_e, speed_mech * k->pole_pairs, i->i_alpha_a, i->i_beta_a, torque_ref, vdc_v,
             duty);
    st->duty[0] = svpwm_duty_u16(duty[0]);
    st->duty[1] = svpwm_duty_u16(duty[1]);
    st->duty[2] = svpwm_duty_u16(duty[2]);
    st->answer_duty = 1u;
}

/* High-side states of vector 0..6 (bit 0 phase a, bit 1 b, bit 2 c; vsi.h),
 * INVCOMP_LEGS_OFF for 0, all switches off. */
static const uint8_t legs_of_vector[7] = {INVCOMP_LEGS_OFF, 1u, 3u, 2u, 6u, 4u, 5u};

/* The voltage the DTC observer integrates over [t_k-1, t_k] with the inverter
 * and delay compensation (flux_observer.h): with one period of delay the
 * answer to SAMPLE k-2 acted. Out of line for the same reason as below. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void observed_voltage(const ctl *c, const clarke_out *i, float vdc_v, float *ua, float *ub)
{
    const ctl_cfg *k = &c->cfg;
    const ctl_state *st = &c->st;
    uint8_t applied = k->delay_comp ? st->vector_prev2 : st->vector_prev;
    vsi_voltage_of_vector(applied, vdc_v, ua, ub); /* Table 2 */
    if (k->inv_comp_on) {
        /* the switching edge is at t_k-1 (the previous sample's current); the
         * drop follows the period's mean current (trapezoid, as the R i term) */
        uint8_t before = k->delay_comp ? st->vector_prev3 : st->vector_prev2;
        invcomp_correct(&k->inv, legs_of_vector[before], legs_of_vector[applied], vdc_v, st->flux.i_alpha_prev_a,
                        st->flux.i_beta_prev_a, 0.5f * (st->flux.i_alpha_prev_a + i->i_alpha_a),
                        0.5f * (st->flux.i_beta_prev_a + i->i_beta_a), ua, ub);
    }
}

/* One-period delay compensation (flux_observer.h fluxobs_predict): the vector
 * chosen now acts from t_k+1, so it is chosen from the state predicted there,
 * under the answer to SAMPLE k-1 that acts until then. Returns the predicted
 * sector, with |psi| eq. (5) and the torque eq. (6) there. Kept out of line:
 * inlined, it costs the step without delay compensation 15 instructions of
 * register pressure (callgrind, bench/stub.py). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static uint8_t predict_one_period(const ctl *c, const clarke_out *i, float vdc_v, float *mag, float *torque)
{
    const ctl_cfg *k = &c->cfg;
    const ctl_state *st = &c->st;
    float ua, ub, pa1, pb1, ia1, ib1;
    vsi_voltage_of_vector(st->vector_prev, vdc_v, &ua, &ub);
    if (k->inv_comp_on) {
        invcomp_correct(&k->inv, legs_of_vector[st->vector_prev2], legs_of_vector[st->vector_prev], vdc_v,
                        i->i_alpha_a, i->i_beta_a, i->i_alpha_a, i->i_beta_a, &ua, &ub);
    }
    fluxobs_predict(&k->flux, &st->flux, ua, ub, st->ekf.speed_rad_s, &pa1, &pb1, &ia1, &ib1);
    *mag = flux_magnitude(pa1, pb1);                                 /* eq. (5) */
    *torque = torque_estimate(k->pole_pairs, pa1, pb1, ia1, ib1);   /* eq. (6) */
    return swtab_sector_of_angle(fm_atan2(pb1, pa1));               /* eq. (10) */
}

static float clamp_abs(float v, float lim) { return v > lim ? lim : (v < -lim ? -lim : v); }

/* ---- non-finite quantities: FAULT NON_FINITE (SPEC.md 9.6) ----
 * A NaN compares false with everything, so a NaN current would pass every limit and a NaN
 * estimate would drive the switching table: any NaN or infinity in what the drive measures,
 * estimates or commands stops it. The step sums the quantities first (one test in the common
 * case: a NaN or an infinity in any term makes the sum NaN or infinite) and names the first
 * offending one, in signal-path order (a NaN current makes the flux NaN too: the current is
 * named), only when the sum is not finite. */

#if defined(__GNUC__)
#define CTL_COLD __attribute__((noinline, cold))
#else
#define CTL_COLD
#endif

/* The hil_nonfinite_quantity of the first non-finite of n values, 0 when none is (finite
 * values whose sum overflowed). */
static uint8_t first_nonfinite(const float *values, const uint8_t *quantities, size_t n)
{
    for (size_t k = 0; k < n; ++k) {
        if (!isfinite(values[k])) {
            return quantities[k];
        }
    }
    return 0u;
}

/* Everything the running drive acts on, in signal-path order: the measurements, the encoder
 * speed, the flux observer's flux, its magnitude and the torque, the conventional and the EKF
 * speed and the EKF angle, the speed loop's integrator (the torque reference is finite when
 * it, the speed fed back and the commanded speed, finite since ctl_set_command, are). FOC's
 * voltage is checked where it is made (ctl_step). Out of line: called only when state_sum()
 * is not finite. */
static CTL_COLD uint8_t nonfinite_state(const ctl *c, const clarke_out *i, float vdc_v, float flux_mag_wb,
                                        float torque_nm)
{
    const ctl_state *st = &c->st;
    const float values[12] = {i->i_alpha_a,
                              i->i_beta_a,
                              vdc_v,
                              st->enc.speed_rad_s,
                              st->flux.psi_alpha_wb,
                              st->flux.psi_beta_wb,
                              flux_mag_wb,
                              torque_nm,
                              st->conv.speed_lpf_rad_s,
                              st->ekf.speed_rad_s,
                              st->ekf.theta_filtered_rad,
                              st->pi.integral_nm};
    static const uint8_t quantities[12] = {
        HIL_NONFINITE_PHASE_CURRENT,  HIL_NONFINITE_PHASE_CURRENT,  HIL_NONFINITE_DC_LINK_VOLTAGE,
        HIL_NONFINITE_MEASURED_SPEED, HIL_NONFINITE_FLUX_ESTIMATE,  HIL_NONFINITE_FLUX_ESTIMATE,
        HIL_NONFINITE_FLUX_ESTIMATE,  HIL_NONFINITE_FLUX_ESTIMATE,  HIL_NONFINITE_SPEED_ESTIMATE,
        HIL_NONFINITE_SPEED_ESTIMATE, HIL_NONFINITE_SPEED_ESTIMATE, HIL_NONFINITE_TORQUE_REFERENCE};
    return first_nonfinite(values, quantities, 12u);
}

/* x - x is 0 for every finite x, NaN for NaN and the infinities: two instructions fewer than
 * isfinite() on x86-64 (the step is held to an instruction bound, tests/test_stub_bench.py). */
static inline int ctl_finite(float x) { return x - x == 0.0f; }

/* The sum nonfinite_state() looks behind. It leaves out the currents and the flux components:
 * the torque estimate 3/2 p (psi_a i_b - psi_b i_a) is not finite when any of them is not (a
 * NaN or an infinity times anything, zero included, is not finite), and the magnitude, which
 * overflows before its components do, is in; four adds fewer, again for the bound. */
static inline float state_sum(const ctl_state *st, float vdc_v, float flux_mag_wb, float torque_nm)
{
    return torque_nm + flux_mag_wb + vdc_v + st->enc.speed_rad_s + st->conv.speed_lpf_rad_s + st->ekf.speed_rad_s +
           st->ekf.theta_filtered_rad + st->pi.integral_nm;
}

enum { CTL_STARTUP_DONE = 0, CTL_STARTUP_ZERO_CAL = 1, CTL_STARTUP_RS_ID = 2 };

/* What the start-up does this period, after an enable, in this order:
 *  - zero calibration (CURRENT_ZERO_CAL_PERIODS): the bridge stays off (vector 0) for N
 *    periods; no current flows (a spinning rotor's line back-EMF is below the link), so the
 *    ADCs read their zero plus noise. Its mean replaces the nominal zero, per channel, as
 *    drive firmware does at start-up;
 *  - stator-resistance identification (RS_ID_PERIODS, rs_id.h), once: identify_resistance();
 *  - then the drive runs (st->startup cleared). Out of line: off the control step's path. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static uint8_t startup_phase(ctl *c, const hil_sample *s)
{
    ctl_state *st = &c->st;
    if (st->zero_cal_left > 0u) {
        float nominal = st->zero_cal_nominal_counts;
        st->zero_cal_sum1 += (float)s->adc_i1 - nominal;
        st->zero_cal_sum2 += (float)s->adc_i2 - nominal;
        if (--st->zero_cal_left == 0u) {
            /* zero_cal_left counted down from zero_cal_periods: n >= 1 */
            float n = (float)st->zero_cal_periods;
            c->cfg.clarke.offset1_counts = nominal + st->zero_cal_sum1 / n;
            c->cfg.clarke.offset2_counts = nominal + st->zero_cal_sum2 / n;
        }
        return CTL_STARTUP_ZERO_CAL;
    }
    if (st->rs_id.phase >= RSID_LOW && st->rs_id.phase <= RSID_OFF) {
        return CTL_STARTUP_RS_ID;
    }
    st->startup = 0u;
    return CTL_STARTUP_DONE;
}

/* One period of the start-up stator-resistance identification (rs_id.h): the current PI in
 * the encoder's rotor frame, answered with DUTY (SVPWM on the board's DC-link reading, no
 * dead-time compensation: the two-point method cancels the inverter's error); the hardware
 * protection stays armed. Its result replaces the board's R (params, flux observer, FOC PI),
 * so PARAM_GET STATOR_RESISTANCE_OHM reads the identified value. Out of line: it runs only
 * at start-up and must not cost the control step. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void identify_resistance(ctl *c, const clarke_out *i, float vdc_v, const hil_sample *s)
{
    ctl_state *st = &c->st;
    float value = 0.0f;
    uint8_t fault = prot_hardware(&c->cfg.prot, i->i_peak_a, vdc_v, s->status, &value);
    if (fault != PROT_FAULT_NONE) {
        ctl_trip(c, fault, value, s->period);
        return;
    }
    float sn, co;
    fm_sincos(enc_angle_e(&c->cfg.enc, &st->enc), &sn, &co);
    float i_d = co * i->i_alpha_a + sn * i->i_beta_a;
    float i_q = co * i->i_beta_a - sn * i->i_alpha_a;
    float vdc = vdc_v > 1.0f ? vdc_v : 1.0f;
    float u_d, u_q;
    if (rsid_step(&c->cfg.rs_id, &st->rs_id, i_d, i_q, vdc * FM_INV_SQRT3, &u_d, &u_q)) {
        if (!isfinite(u_d + u_q)) {
            ctl_trip(c, HIL_FAULT_NON_FINITE, (float)HIL_NONFINITE_VOLTAGE_REFERENCE, s->period);
            return;
        }
        float duty[3];
        svpwm_duties(co * u_d - sn * u_q, sn * u_d + co * u_q, vdc, duty);
        st->duty[0] = svpwm_duty_u16(duty[0]);
        st->duty[1] = svpwm_duty_u16(duty[1]);
        st->duty[2] = svpwm_duty_u16(duty[2]);
        st->answer_duty = 1u;
    } else if (st->rs_id.phase == RSID_DONE) {
        float r = st->rs_id.r_ohm;
        c->params.stator_resistance_ohm = r;
        c->cfg.flux.stator_resistance_ohm = r;
        fluxobs_derive(&c->cfg.flux);
        c->cfg.foc.current.stator_resistance_ohm = r;
        foc_derive(&c->cfg.foc);
    }
}

uint8_t ctl_step(ctl *c, const hil_sample *s, hil_telemetry *tm)
{
    const ctl_cfg *k = &c->cfg;
    ctl_state *st = &c->st;

    /* Start-up (zero calibration, resistance identification): the drive waits for it */
    uint8_t calibrating = 0u;
    if (st->startup && st->state == HIL_STATE_RUNNING) {
        calibrating = startup_phase(c, s);
    }
    clarke_out i;
    clarke_from_adc(&k->clarke, s->adc_i1, s->adc_i2, &i);
    float vdc_v = ((float)s->adc_vdc - k->vdc_offset_counts) * k->vdc_v_per_count;

    uint8_t running = st->state == HIL_STATE_RUNNING && !calibrating;
    if (st->started) {
        enc_step(&k->enc, &st->enc, s->encoder);
    } else {
        enc_reset(&k->enc, &st->enc, s->encoder);
        prot_reset(&st->prot, s->encoder);
        st->started = 1u;
        running = 0u; /* no previous sample to integrate from: initialise below */
    }
    if (running) {
        float ua, ub;
        if (k->control_law == CTL_LAW_FOC) {
            ua = st->foc.u_alpha_v; /* the average voltage the SVPWM applied */
            ub = st->foc.u_beta_v;
        } else {
            if (k->dtc_comp) {
                observed_voltage(c, &i, vdc_v, &ua, &ub);
            } else {
                vsi_voltage_of_vector(st->vector_prev, vdc_v, &ua, &ub); /* Table 2 */
            }
        }
        fluxobs_step(&k->flux, &st->flux, ua, ub, i.i_alpha_a, i.i_beta_a);
    } else {
        track_encoder(c, &i);
        foc_reset(&st->foc);
    }
    float pa = st->flux.psi_alpha_wb;
    float pb = st->flux.psi_beta_wb;
    float mag = flux_magnitude(pa, pb);                                               /* eq. (5) */
    float torque = torque_estimate(k->pole_pairs, pa, pb, i.i_alpha_a, i.i_beta_a); /* eq. (6) */
    float theta_s = fm_atan2(pb, pa);                                                 /* eq. (10) */
    conv_step(&k->conv, &st->conv, theta_s);                                          /* eq. (11) */
    ekf_step_angle(&k->ekf, &st->ekf, theta_s);                                       /* eq. (20)-(23) */

    float ip = k->inv_pole_pairs;
    float speed_ekf = st->ekf.speed_rad_s * ip;
    float speed_lpf = st->conv.speed_lpf_rad_s * ip;
    uint8_t source = c->cmd.speed_source;
    float feedback = source == HIL_SPEED_EKF ? speed_ekf : (source == HIL_SPEED_CONVENTIONAL ? speed_lpf : st->enc.speed_rad_s);

    uint8_t vector = 0u;
    uint8_t sector = 0u;
    float torque_ref = 0.0f;
    st->answer_duty = 0u;
    if (st->state == HIL_STATE_RUNNING && !ctl_finite(state_sum(st, vdc_v, mag, torque))) {
        /* never RUNNING with a NaN, the start-up included: checked before the limits a NaN fools */
        uint8_t quantity = nonfinite_state(c, &i, vdc_v, mag, torque);
        if (quantity != 0u) {
            ctl_trip(c, HIL_FAULT_NON_FINITE, (float)quantity, s->period);
        }
    }
    if (st->state == HIL_STATE_RUNNING && !calibrating) {
        float value = 0.0f;
        uint8_t fault = prot_hardware(&k->prot, i.i_peak_a, vdc_v, s->status, &value);
        if (fault == PROT_FAULT_NONE) {
            fault = prot_encoder_loss(&k->prot, &st->prot, s->encoder, speed_ekf, source == HIL_SPEED_ENCODER, &value);
        }
        if (fault != PROT_FAULT_NONE) {
            ctl_trip(c, fault, value, s->period);
        } else {
            if (c->cmd.torque_mode) {
                torque_ref = clamp_abs(c->cmd.torque_ref_nm, k->pi.torque_limit_nm);
                st->pi.integral_nm = torque_ref; /* bumpless return to speed mode */
            } else {
                torque_ref = spi_step(&k->pi, &st->pi, c->cmd.speed_ref_rad_s, feedback);
            }
            sector = swtab_sector_of_angle(theta_s);
            if (k->control_law == CTL_LAW_FOC) {
                foc_law(c, &i, torque, mag, vdc_v, torque_ref, feedback);
                if (!ctl_finite(st->foc.u_alpha_v + st->foc.u_beta_v)) {
                    /* the DUTY answer would be made of a NaN: every switch off instead */
                    ctl_trip(c, HIL_FAULT_NON_FINITE, (float)HIL_NONFINITE_VOLTAGE_REFERENCE, s->period);
                    st->answer_duty = 0u;
                }
            } else {
                float mag_c = mag, torque_c = torque;
                if (k->delay_comp) {
                    sector = predict_one_period(c, &i, vdc_v, &mag_c, &torque_c);
                }
                uint8_t flux_up = hyst_step(&k->flux_hyst, &st->flux_hyst, c->flux_ref_wb, mag_c);
                uint8_t torque_up = hyst_step(&k->torque_hyst, &st->torque_hyst, torque_ref, torque_c);
                vector = k->vector_of[sector][(flux_up ? 0u : 2u) + (torque_up ? 0u : 1u)]; /* Table 3 */
            }
        }
    } else if (calibrating == CTL_STARTUP_RS_ID && st->state == HIL_STATE_RUNNING) {
        identify_resistance(c, &i, vdc_v, s);
    }
    st->vector_prev3 = st->vector_prev2;
    st->vector_prev2 = st->vector_prev;
    st->vector_prev = vector;
    uint8_t gates = vsi_gates_of_vector(vector);
    if (tm == NULL) {
        return gates;
    }

    float delta = rotor_load_angle(&k->rotor, torque, mag); /* eq. (25) */
    float ekf_angle = fm_wrap_pi(st->ekf.theta_filtered_rad);
    tm->period = s->period;
    tm->sector = sector;
    tm->speed_source = source;
    tm->state = ctl_reported_state(c);
    tm->gates = st->answer_duty ? CTL_GATES_PWM : gates;
    tm->speed_feedback_rad_s = feedback;
    tm->speed_encoder_rad_s = st->enc.speed_rad_s;
    tm->speed_raw_rad_s = st->conv.speed_raw_rad_s * ip;
    tm->speed_lpf_rad_s = speed_lpf;
    tm->speed_ekf_rad_s = speed_ekf;
    tm->flux_angle_rad = theta_s;
    tm->ekf_angle_rad = ekf_angle;
    tm->flux_mag_wb = mag;
    tm->torque_est_nm = torque;
    tm->torque_ref_nm = torque_ref;
    tm->rotor_pos_conv_rad = fm_wrap_pi(theta_s - delta);      /* eq. (26) */
    tm->rotor_pos_ekf_rad = fm_wrap_pi(ekf_angle - delta);    /* eq. (26) */
    return gates;
}

/* ---- parameters by id ---- */

typedef enum { PT_F32, PT_U8, PT_U16, PT_U32 } param_type;

typedef struct {
    uint16_t id;
    uint8_t type;
    uint8_t integer; /* value must be a whole number */
    uint16_t offset; /* in ctl_params */
    float min;
    float max;
} param_desc;

#define P(id, field, type, integer, lo, hi) {(id), (type), (integer), (uint16_t)offsetof(ctl_params, field), (lo), (hi)}

static const param_desc param_table[] = {
    P(HIL_PARAM_CONTROL_PERIOD_S, control_period_s, PT_F32, 0, 1e-6f, 1e-2f),
    P(HIL_PARAM_CURRENT_A_PER_COUNT, current_a_per_count, PT_F32, 0, 1e-6f, 10.0f),
    P(HIL_PARAM_CURRENT_OFFSET_COUNTS, current_offset_counts, PT_F32, 0, 0.0f, 65535.0f),
    P(HIL_PARAM_VDC_V_PER_COUNT, vdc_v_per_count, PT_F32, 0, 1e-6f, 10.0f),
    P(HIL_PARAM_VDC_OFFSET_COUNTS, vdc_offset_counts, PT_F32, 0, -65535.0f, 65535.0f),
    P(HIL_PARAM_ENCODER_COUNTS_PER_REV, encoder_counts_per_rev, PT_F32, 1, 4.0f, 65536.0f),
    P(HIL_PARAM_CURRENT_PHASES, current_phases, PT_U8, 1, 0.0f, 2.0f),
    P(HIL_PARAM_POLE_PAIRS, pole_pairs, PT_F32, 1, 1.0f, 64.0f),
    P(HIL_PARAM_STATOR_RESISTANCE_OHM, stator_resistance_ohm, PT_F32, 0, 0.0f, 100.0f),
    P(HIL_PARAM_STATOR_INDUCTANCE_H, stator_inductance_h, PT_F32, 0, 1e-7f, 10.0f),
    P(HIL_PARAM_MAGNET_FLUX_WB, magnet_flux_wb, PT_F32, 0, 1e-6f, 10.0f),
    P(HIL_PARAM_FLUX_REF_WB, flux_ref_wb, PT_F32, 0, 1e-6f, 10.0f),
    P(HIL_PARAM_FLUX_BAND_WB, flux_band_wb, PT_F32, 0, 0.0f, 1.0f),
    P(HIL_PARAM_TORQUE_BAND_NM, torque_band_nm, PT_F32, 0, 0.0f, 1000.0f),
    P(HIL_PARAM_TORQUE_LIMIT_NM, torque_limit_nm, PT_F32, 0, 0.0f, 1000.0f),
    P(HIL_PARAM_SPEED_KP_NM_PER_RAD_S, speed_kp_nm_per_rad_s, PT_F32, 0, 0.0f, 1000.0f),
    P(HIL_PARAM_SPEED_KI_NM_PER_RAD, speed_ki_nm_per_rad, PT_F32, 0, 0.0f, 1e6f),
    P(HIL_PARAM_SPEED_LPF_CUTOFF_HZ, speed_lpf_cutoff_hz, PT_F32, 0, 1e-3f, 1e5f),
    P(HIL_PARAM_EKF_K1, ekf_k1, PT_F32, 0, 0.0f, 1.0f),
    P(HIL_PARAM_EKF_K2, ekf_k2_rad_s, PT_F32, 0, 0.0f, 1e5f),
    P(HIL_PARAM_EKF_K3, ekf_k3_rad_s, PT_F32, 0, 0.0f, 1e4f),
    P(HIL_PARAM_FLUX_DRIFT_CUTOFF_HZ, flux_drift_cutoff_hz, PT_F32, 0, 0.0f, 100.0f),
    P(HIL_PARAM_TELEMETRY_DIVIDER, telemetry_divider, PT_U32, 1, 0.0f, 1e6f),
    P(HIL_PARAM_OVERCURRENT_A, overcurrent_a, PT_F32, 0, 0.0f, 1e4f),
    P(HIL_PARAM_ENCODER_LOSS_TIMEOUT_S, encoder_loss_timeout_s, PT_F32, 0, 1e-4f, 100.0f),
    P(HIL_PARAM_CONTROL_LAW, control_law, PT_U8, 1, 0.0f, 1.0f),
    P(HIL_PARAM_CURRENT_BANDWIDTH_HZ, current_bandwidth_hz, PT_F32, 0, 1.0f, 1e5f),
    P(HIL_PARAM_FOC_ANGLE_SOURCE, foc_angle_source, PT_U8, 1, 0.0f, 1.0f),
    P(HIL_PARAM_DEAD_TIME_COMP_S, dead_time_comp_s, PT_F32, 0, 0.0f, 1e-5f),
    P(HIL_PARAM_DEVICE_DROP_COMP_V, device_drop_comp_v, PT_F32, 0, 0.0f, 10.0f),
    P(HIL_PARAM_DELAY_COMP_PERIODS, delay_comp_periods, PT_U8, 1, 0.0f, 1.0f),
    P(HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, current_zero_cal_periods, PT_U32, 1, 0.0f, 65535.0f),
    P(HIL_PARAM_RS_ID_PERIODS, rs_id_periods, PT_U32, 1, 0.0f, 65535.0f),
};

#undef P

static const param_desc *find_param(uint16_t id)
{
    for (size_t n = 0; n < sizeof param_table / sizeof param_table[0]; ++n) {
        if (param_table[n].id == id) {
            return &param_table[n];
        }
    }
    return NULL;
}

static float read_field(const ctl_params *p, const param_desc *d)
{
    const unsigned char *base = (const unsigned char *)p + d->offset;
    switch (d->type) {
    case PT_U8:
        return (float)*(const uint8_t *)base;
    case PT_U16:
        return (float)*(const uint16_t *)(const void *)base;
    case PT_U32:
        return (float)*(const uint32_t *)(const void *)base;
    default:
        return *(const float *)(const void *)base;
    }
}

static void write_field(ctl_params *p, const param_desc *d, float value)
{
    unsigned char *base = (unsigned char *)p + d->offset;
    switch (d->type) {
    /* value is in the table's range; saturated all the same, should a row's range exceed its type */
    case PT_U8: {
        uint32_t v = fm_trunc_sat_u32(value);
        *(uint8_t *)base = (uint8_t)(v < UINT8_MAX ? v : UINT8_MAX);
        break;
    }
    case PT_U16: {
        uint32_t v = fm_trunc_sat_u32(value);
        *(uint16_t *)(void *)base = (uint16_t)(v < UINT16_MAX ? v : UINT16_MAX);
        break;
    }
    case PT_U32:
        *(uint32_t *)(void *)base = fm_trunc_sat_u32(value);
        break;
    default:
        *(float *)(void *)base = value;
        break;
    }
}

uint8_t ctl_param_get(const ctl *c, uint16_t id, float *value)
{
    if (id == HIL_PARAM_CONTROL_STEP_CYCLES) {
        *value = (float)c->st.step_cycles;
        return HIL_PARAM_OK;
    }
    const param_desc *d = find_param(id);
    if (d == NULL) {
        *value = 0.0f;
        return HIL_PARAM_UNKNOWN;
    }
    *value = read_field(&c->params, d);
    return HIL_PARAM_OK;
}

uint8_t ctl_param_set(ctl *c, uint16_t id, float value, float *value_now)
{
    uint8_t status = ctl_param_get(c, id, value_now);
    if (status != HIL_PARAM_OK) {
        return status;
    }
    if (id == HIL_PARAM_CONTROL_STEP_CYCLES) {
        return HIL_PARAM_READ_ONLY;
    }
    const param_desc *d = find_param(id);
    /* written so that NaN fails every comparison and is refused */
    int in_range = value >= d->min && value <= d->max;
    if (in_range && d->integer) {
        in_range = truncf(value) == value; /* no conversion: value is finite and in range here */
    }
    if (!in_range) {
        return HIL_PARAM_OUT_OF_RANGE;
    }
    write_field(&c->params, d, value);
    if (id == HIL_PARAM_RS_ID_PERIODS) {
        c->st.rs_id.phase = RSID_IDLE; /* (re)armed: runs at the next enable */
    }
    /* ctl_derive sets the current zeros to the nominal one: what a zero calibration measured
     * stays, as on a drive, unless the nominal zero is what was written */
    float zero1 = c->cfg.clarke.offset1_counts, zero2 = c->cfg.clarke.offset2_counts;
    ctl_derive(c);
    if (id != HIL_PARAM_CURRENT_OFFSET_COUNTS) {
        c->cfg.clarke.offset1_counts = zero1;
        c->cfg.clarke.offset2_counts = zero2;
    }
    c->flux_ref_wb = c->cmd.flux_ref_wb > 0.0f ? c->cmd.flux_ref_wb : c->params.flux_ref_wb;
    *value_now = read_field(&c->params, d);
    return HIL_PARAM_OK;
}
