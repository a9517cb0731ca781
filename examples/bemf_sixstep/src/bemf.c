#include "bemf.h"

#include <math.h>
#include <string.h>

/* ---- commutation ---------------------------------------------------------- */

static const bemf_step step_table[6] = {
    {0u, 2u, 1u, 1u}, /* 1: a -> c, b rises */
    {1u, 2u, 0u, 0u}, /* 2: b -> c, a falls */
    {1u, 0u, 2u, 1u}, /* 3: b -> a, c rises */
    {2u, 0u, 1u, 0u}, /* 4: c -> a, b falls */
    {2u, 1u, 0u, 1u}, /* 5: c -> b, a rises */
    {0u, 1u, 2u, 0u}, /* 6: a -> b, c falls */
};

bemf_step bemf_commutation(uint8_t step)
{
    return step_table[(unsigned)(step + 5u) % 6u];
}

uint8_t bemf_next_step(uint8_t step)
{
    return (uint8_t)(step % 6u + 1u);
}

/* ---- zero-cross detection ------------------------------------------------- */

void bemf_zc_arm(bemf_zc_detector *zc, bemf_step step, uint32_t tick)
{
    zc->floating = step.floating;
    zc->rising = step.rising;
    zc->found = 0u;
    zc->armed_tick = tick;
    zc->run = 0u;
    zc->first_tick = tick;
    zc->quiet = 0u;
}

int bemf_zc_feed(const bemf_zc_config *cfg, bemf_zc_detector *zc, uint8_t comparators,
                 float floating_current_a, uint32_t tick, uint32_t *zc_tick)
{
    if (zc->found) {
        return 0;
    }
    if (tick - zc->armed_tick < cfg->blanking_periods) {
        zc->run = 0u;
        return 0;
    }
    /* demagnetisation: the comparator sees a period's average through the
     * terminal filter, so the current must have been out for a whole period
     * (two samples) before the comparator means the back-EMF. NaN counts as
     * current. */
    if (!(fabsf(floating_current_a) <= cfg->demag_current_a)) {
        zc->quiet = 0u;
        zc->run = 0u;
        return 0;
    }
    if (zc->quiet < 2u) {
        zc->quiet++;
        if (zc->quiet < 2u) {
            return 0;
        }
    }
    unsigned bit = (comparators >> zc->floating) & 1u;
    unsigned after = zc->rising ? 1u : 0u;
    if (bit != after) {
        zc->run = 0u;
        return 0;
    }
    if (zc->run == 0u) {
        zc->first_tick = tick;
    }
    zc->run++;
    if (zc->run < (cfg->confirm_samples > 0u ? cfg->confirm_samples : 1u)) {
        return 0;
    }
    zc->found = 1u;
    *zc_tick = zc->first_tick;
    return 1;
}

/* ---- zero-cross timing ---------------------------------------------------- */

void bemf_timing_seed(bemf_timing *t, float interval_ticks, uint32_t zc_tick)
{
    uint32_t slot = interval_ticks >= 1.0f ? (uint32_t)(interval_ticks + 0.5f) : 1u;
    for (unsigned k = 0u; k < BEMF_INTERVALS; ++k) {
        t->interval_ticks[k] = slot;
    }
    t->sum_ticks = slot * BEMF_INTERVALS;
    t->next = 0u;
    t->last_zc_tick = zc_tick;
}

uint32_t bemf_timing_zero_cross(bemf_timing *t, uint32_t zc_tick, float lag_ticks, uint32_t now_tick)
{
    uint32_t interval = zc_tick - t->last_zc_tick;
    if (interval == 0u) {
        interval = 1u;
    }
    t->sum_ticks = t->sum_ticks - t->interval_ticks[t->next] + interval;
    t->interval_ticks[t->next] = interval;
    t->next = (t->next + 1u) % BEMF_INTERVALS;
    t->last_zc_tick = zc_tick;
    /* 30 electrical degrees after the cross: half the 60-degree interval */
    float delay = 0.5f * (float)interval - lag_ticks;
    uint32_t due = zc_tick + (delay > 0.0f ? (uint32_t)(delay + 0.5f) : 0u);
    return (int32_t)(due - now_tick) < 0 ? now_tick : due;
}

float bemf_timing_speed_rad_s(const bemf_timing *t, uint32_t pole_pairs, float period_s)
{
    /* six 60-degree intervals are one electrical turn */
    return BEMF_TWO_PI / ((float)pole_pairs * (float)t->sum_ticks * period_s);
}

uint32_t bemf_timing_last_interval(const bemf_timing *t)
{
    return t->interval_ticks[(t->next + BEMF_INTERVALS - 1u) % BEMF_INTERVALS];
}

/* ---- open-loop start ------------------------------------------------------ */

void bemf_ramp_reset(bemf_ramp *r, const bemf_ramp_config *cfg)
{
    r->tick = 0u;
    r->speed_rad_s = cfg->ramp_start_rad_s;
    r->angle_rad = 0.0f;
}

int bemf_ramp_step(bemf_ramp *r, const bemf_ramp_config *cfg, uint32_t pole_pairs, float dt_s)
{
    float progress = cfg->ramp_periods > 0u && r->tick < cfg->ramp_periods
                         ? (float)r->tick / (float)cfg->ramp_periods
                         : 1.0f;
    r->speed_rad_s = cfg->ramp_start_rad_s + (cfg->ramp_end_rad_s - cfg->ramp_start_rad_s) * progress;
    if (r->tick < UINT32_MAX) {
        r->tick++;
    }
    r->angle_rad += r->speed_rad_s * (float)pole_pairs * dt_s;
    if (r->angle_rad >= BEMF_PI / 3.0f) {
        r->angle_rad -= BEMF_PI / 3.0f;
        return 1;
    }
    return 0;
}

/* ---- regulators ----------------------------------------------------------- */

static float clampf(float x, float lo, float hi)
{
    return x > hi ? hi : (x < lo ? lo : x);
}

bemf_speed_pi_gains bemf_speed_pi_design(float inertia_kgm2, float bandwidth_hz, float torque_limit_nm)
{
    float w = BEMF_TWO_PI * bandwidth_hz;
    bemf_speed_pi_gains g = {2.0f * inertia_kgm2 * w, inertia_kgm2 * w * w, torque_limit_nm};
    return g;
}

float bemf_speed_pi_step(const bemf_speed_pi_gains *g, bemf_speed_pi *pi, float error_rad_s, float dt_s)
{
    float lim = g->torque_limit_nm;
    float p = g->kp_nm_per_rad_s * error_rad_s;
    float candidate = pi->integral_nm + g->ki_nm_per_rad * dt_s * error_rad_s;
    float unsat = p + candidate;
    if ((unsat > lim && error_rad_s > 0.0f) || (unsat < -lim && error_rad_s < 0.0f)) {
        return unsat > lim ? lim : -lim; /* saturated, error pushing further: hold */
    }
    pi->integral_nm = clampf(candidate, -lim, lim);
    return clampf(p + pi->integral_nm, -lim, lim);
}

bemf_current_pi_gains bemf_current_pi_design(float resistance_ohm, float inductance_h, float bandwidth_hz)
{
    float wc = BEMF_TWO_PI * bandwidth_hz;
    bemf_current_pi_gains g = {resistance_ohm, 2.0f * inductance_h * wc, 2.0f * resistance_ohm * wc};
    return g;
}

float bemf_current_pi_step(const bemf_current_pi_gains *g, bemf_current_pi *pi, float current_ref_a,
                           float current_a, float line_emf_v, float vdc_v, float dt_s)
{
    float e = current_ref_a - current_a;
    float feed_forward = 2.0f * g->resistance_ohm * current_ref_a + line_emf_v;
    float candidate = pi->integral_v + g->ki_v_per_as * dt_s * e;
    float v = feed_forward + g->kp_v_per_a * e + candidate;
    if ((v > vdc_v && e > 0.0f) || (v < 0.0f && e < 0.0f)) {
        return clampf(v, 0.0f, vdc_v); /* at a rail, error pushing further: hold */
    }
    pi->integral_v = clampf(candidate, -vdc_v, vdc_v);
    return clampf(feed_forward + g->kp_v_per_a * e + pi->integral_v, 0.0f, vdc_v);
}

float bemf_torque_constant(uint32_t pole_pairs, float magnet_flux_wb)
{
    return 2.0f * (float)pole_pairs * magnet_flux_wb;
}

/* ---- the drive ------------------------------------------------------------ */

void bemf_drive_enable(bemf_drive *d, const bemf_config *cfg)
{
    memset(d, 0, sizeof *d);
    d->mode = BEMF_ALIGN;
    d->step = cfg->align_step;
}

void bemf_drive_disable(bemf_drive *d)
{
    d->mode = BEMF_OFF;
    d->step = 0u;
    d->duty = 0.0f;
}

static void trip(bemf_drive *d, uint8_t why, float value)
{
    d->mode = BEMF_TRIPPED;
    d->trip = why;
    d->trip_value = value;
    d->step = 0u;
    d->duty = 0.0f;
}

/* Commutates to the next step at `tick`; the detector is armed with a blanking
 * of a fraction of the last 60-degree interval. */
static void commutate(const bemf_config *cfg, bemf_drive *d, uint32_t interval_ticks)
{
    d->step = bemf_next_step(d->step);
    bemf_zc_arm(&d->zc, bemf_commutation(d->step), d->tick);
    uint32_t blank = (uint32_t)(cfg->blanking_fraction * (float)interval_ticks);
    d->blanking_periods = blank > cfg->min_blanking_periods ? blank : cfg->min_blanking_periods;
}

static float duty_of(float voltage_v, float vdc_v)
{
    /* a link below 1 V: nothing sensible to switch; 0 also catches NaN */
    return vdc_v > 1.0f ? clampf(voltage_v / vdc_v, 0.0f, 1.0f) : 0.0f;
}

static float pair_current(const bemf_drive *d, const float i_abc[3])
{
    bemf_step s = bemf_commutation(d->step);
    return 0.5f * (i_abc[s.high] - i_abc[s.low]);
}

static void run_align(const bemf_config *cfg, bemf_drive *d, const bemf_inputs *in)
{
    if (d->tick - d->mode_tick >= cfg->ramp.align_periods) {
        /* the rotor's d-axis sits on the align step's current vector, which is
         * the start of the step two on: start there */
        d->mode = BEMF_RAMP;
        d->mode_tick = d->tick;
        d->step = bemf_next_step(cfg->align_step);
        bemf_ramp_reset(&d->ramp, &cfg->ramp);
        d->valid_steps = 0u;
        commutate(cfg, d, 0u);
        return;
    }
    d->speed_rad_s = 0.0f;
    d->duty = duty_of(2.0f * cfg->resistance_ohm * cfg->align_current_a, in->vdc_v);
}

static float ramp_interval_ticks(const bemf_config *cfg, float speed_rad_s)
{
    return (BEMF_PI / 3.0f) / (speed_rad_s * (float)cfg->pole_pairs * cfg->control_period_s);
}

static void hand_over(const bemf_config *cfg, bemf_drive *d, uint32_t zc_tick)
{
    float interval = ramp_interval_ticks(cfg, d->ramp.speed_rad_s);
    bemf_timing_seed(&d->timing, interval, zc_tick);
    float delay = 0.5f * interval - cfg->zc_lag_periods;
    d->commutate_tick = zc_tick + (delay > 0.0f ? (uint32_t)(delay + 0.5f) : 0u);
    d->mode = BEMF_CLOSED;
    d->mode_tick = d->tick;
    d->last_zc_tick = zc_tick;
    /* bumpless: the speed loop starts from the open loop's current */
    float t0 = cfg->torque_constant_nm_per_a * cfg->ramp_current_a;
    d->speed_pi.integral_nm = clampf(t0, -cfg->speed_gains.torque_limit_nm, cfg->speed_gains.torque_limit_nm);
    d->current_pi.integral_v = 0.0f;
}

static void run_ramp(const bemf_config *cfg, bemf_drive *d, const bemf_inputs *in)
{
    bemf_zc_config zc_cfg = cfg->zc;
    zc_cfg.blanking_periods = d->blanking_periods;
    uint32_t zc_tick;
    int at_end_speed = d->ramp.tick >= cfg->ramp.ramp_periods;
    if (bemf_zc_feed(&zc_cfg, &d->zc, in->comparators, in->phase_current_a[d->zc.floating], d->tick, &zc_tick)) {
        d->last_zc_tick = zc_tick;
        if (at_end_speed && ++d->valid_steps >= cfg->handover_zero_crosses) {
            hand_over(cfg, d, zc_tick);
            return;
        }
    }
    if (at_end_speed && d->ramp.tick - cfg->ramp.ramp_periods > cfg->zc_timeout_periods) {
        /* the end speed held for the timeout without a run of zero crosses:
         * the rotor does not follow (locked, overloaded, or no back-EMF) */
        trip(d, BEMF_TRIP_DESYNC, (float)(d->ramp.tick - cfg->ramp.ramp_periods) * cfg->control_period_s);
        return;
    }
    if (bemf_ramp_step(&d->ramp, &cfg->ramp, cfg->pole_pairs, cfg->control_period_s)) {
        if (!d->zc.found) {
            d->valid_steps = 0u;
        }
        commutate(cfg, d, (uint32_t)ramp_interval_ticks(cfg, d->ramp.speed_rad_s));
    }
    d->speed_rad_s = d->ramp.speed_rad_s;
    /* voltage mode: the back-EMF damps the rotor's swing about the stepping field */
    float line_emf = cfg->torque_constant_nm_per_a * d->ramp.speed_rad_s;
    d->duty = duty_of(2.0f * cfg->resistance_ohm * cfg->ramp_current_a + line_emf, in->vdc_v);
}

static void run_closed(const bemf_config *cfg, bemf_drive *d, const bemf_inputs *in, float dt)
{
    bemf_zc_config zc_cfg = cfg->zc;
    zc_cfg.blanking_periods = d->blanking_periods;
    uint32_t zc_tick;
    if (bemf_zc_feed(&zc_cfg, &d->zc, in->comparators, in->phase_current_a[d->zc.floating], d->tick, &zc_tick)) {
        d->commutate_tick = bemf_timing_zero_cross(&d->timing, zc_tick, cfg->zc_lag_periods, d->tick);
        d->last_zc_tick = zc_tick;
    }
    if (d->tick - d->last_zc_tick > cfg->zc_timeout_periods) {
        trip(d, BEMF_TRIP_DESYNC, (float)(d->tick - d->last_zc_tick) * dt);
        return;
    }
    if (d->zc.found && (int32_t)(d->tick - d->commutate_tick) >= 0) {
        commutate(cfg, d, bemf_timing_last_interval(&d->timing));
    }
    d->speed_rad_s = bemf_timing_speed_rad_s(&d->timing, cfg->pole_pairs, dt);
    /* the drive runs forwards only, no slower than its hand-over speed */
    float speed_ref = fmaxf(in->speed_ref_rad_s, cfg->ramp.ramp_end_rad_s);
    float limit = cfg->speed_gains.torque_limit_nm;
    d->torque_ref_nm = in->torque_mode
                           ? clampf(in->torque_ref_nm, -limit, limit)
                           : bemf_speed_pi_step(&cfg->speed_gains, &d->speed_pi, speed_ref - d->speed_rad_s, dt);
    d->current_ref_a = d->torque_ref_nm / cfg->torque_constant_nm_per_a;
    float line_emf = cfg->torque_constant_nm_per_a * d->speed_rad_s;
    float v = bemf_current_pi_step(&cfg->current_gains, &d->current_pi, d->current_ref_a, d->pair_current_a,
                                   line_emf, in->vdc_v, dt);
    d->duty = duty_of(v, in->vdc_v);
}

bemf_output bemf_drive_step(const bemf_config *cfg, bemf_drive *d, const bemf_inputs *in)
{
    const float dt = cfg->control_period_s;
    int driving = d->mode == BEMF_ALIGN || d->mode == BEMF_RAMP || d->mode == BEMF_CLOSED;
    if (driving) {
        float i_peak = fmaxf(fabsf(in->phase_current_a[0]),
                             fmaxf(fabsf(in->phase_current_a[1]), fabsf(in->phase_current_a[2])));
        int finite = in->phase_current_a[0] == in->phase_current_a[0] &&
                     in->phase_current_a[1] == in->phase_current_a[1] &&
                     in->phase_current_a[2] == in->phase_current_a[2];
        if (in->overcurrent_flag || !finite || !(i_peak <= cfg->overcurrent_a)) {
            trip(d, BEMF_TRIP_OVERCURRENT, i_peak);
            driving = 0;
        }
    }
    if (driving) {
        d->pair_current_a = pair_current(d, in->phase_current_a);
        switch (d->mode) {
        case BEMF_ALIGN:
            run_align(cfg, d, in);
            if (d->mode == BEMF_RAMP) {
                run_ramp(cfg, d, in);
            }
            break;
        case BEMF_RAMP:
            run_ramp(cfg, d, in);
            if (d->mode == BEMF_CLOSED) {
                run_closed(cfg, d, in, dt);
            }
            break;
        default:
            run_closed(cfg, d, in, dt);
            break;
        }
    }
    if (d->tick < UINT32_MAX) {
        d->tick++;
    }
    bemf_output out = {0u, 0.0f};
    if (d->mode == BEMF_ALIGN || d->mode == BEMF_RAMP || d->mode == BEMF_CLOSED) {
        out.step = d->step;
        out.duty = d->duty;
    }
    return out;
}
