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
    zc->before_seen = 0u;
    zc->armed_tick = tick;
    zc->run = 0u;
    zc->first_tick = tick;
    zc->quiet = 0u;
    zc->before_v[0] = zc->before_v[1] = 0.0f;
    zc->before_ok[0] = zc->before_ok[1] = 0u;
    zc->after_v = 0.0f;
    zc->after_ok = 0u;
}

static float clamp01(float x)
{
    return x > 1.0f ? 1.0f : (x > 0.0f ? x : 0.0f); /* NaN -> 0 */
}

/* Where in the period before the first sample after the cross (0: at the last
 * sample before it, 1: at the first after) the terminal crossed the neutral.
 * Voltages are rising-signed (negative before, positive after). `next` is the
 * confirming sample after `after_v` (valid when next_ok). */
static float cross_fraction(const bemf_zc_detector *zc, float next_v, int next_ok)
{
    float b0 = zc->before_v[0], b1 = zc->before_v[1], a0 = zc->after_v;
    if (zc->before_ok[0] && zc->after_ok && b0 < 0.0f && a0 > 0.0f) {
        return b0 / (b0 - a0); /* both sides clean: interpolate */
    }
    if (zc->before_ok[0] && zc->before_ok[1] && b0 < 0.0f && b0 > b1) {
        return clamp01(-b0 / (b0 - b1)); /* the sample after is clamped: extrapolate forward */
    }
    if (zc->after_ok && next_ok && a0 > 0.0f && next_v > a0) {
        return clamp01(1.0f - a0 / (next_v - a0)); /* the sample before is clamped: backward */
    }
    return 0.5f;
}

int bemf_zc_feed(const bemf_zc_config *cfg, bemf_zc_detector *zc, uint8_t comparators,
                 float floating_current_a, bemf_terminal terminal, uint32_t tick, bemf_instant *at)
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
     * current. A floating phase that still conducts at demag_limit_periods is
     * not demagnetising: its diode is held on by a rotor far ahead of the step
     * (an open-loop start), and its rail is the level after the cross. */
    if (!(fabsf(floating_current_a) <= cfg->demag_current_a)) {
        if (tick - zc->armed_tick < cfg->demag_limit_periods) {
            zc->quiet = 0u;
            zc->run = 0u;
            zc->before_seen = 0u;
            zc->before_ok[0] = zc->before_ok[1] = 0u;
            return 0;
        }
    } else if (zc->quiet < 2u) {
        zc->quiet++;
        if (zc->quiet < 2u) {
            return 0;
        }
    }
    unsigned bit = (comparators >> zc->floating) & 1u;
    unsigned after = zc->rising ? 1u : 0u;
    float v = zc->rising ? terminal.diff_v : -terminal.diff_v;
    uint8_t ok = terminal.clamped ? 0u : 1u;
    if (bit != after) {
        /* before the cross; after a glitch the older sample is not adjacent */
        zc->before_v[1] = zc->before_v[0];
        zc->before_ok[1] = zc->run == 0u ? zc->before_ok[0] : 0u;
        zc->before_v[0] = v;
        zc->before_ok[0] = ok;
        zc->run = 0u;
        zc->before_seen = 1u;
        return 0;
    }
    if (zc->run == 0u) {
        zc->first_tick = tick;
        zc->after_v = v;
        zc->after_ok = ok;
    }
    zc->run++;
    if (zc->run < (cfg->confirm_samples > 0u ? cfg->confirm_samples : 1u)) {
        return 0;
    }
    zc->found = 1u;
    at->tick = zc->first_tick - 1u;
    at->frac = zc->before_seen ? cross_fraction(zc, v, zc->run >= 2u && ok) : 1.0f;
    return 1;
}

/* ---- zero-cross timing ---------------------------------------------------- */

void bemf_timing_seed(bemf_timing *t, float interval_periods, bemf_instant zc)
{
    for (unsigned k = 0u; k < BEMF_INTERVALS; ++k) {
        t->interval_periods[k] = interval_periods > 1.0f ? interval_periods : 1.0f;
    }
    t->next = 0u;
    t->last_zc = zc;
}

uint32_t bemf_timing_zero_cross(bemf_timing *t, bemf_instant zc, float lag_periods, uint32_t now_tick)
{
    float interval = (float)(zc.tick - t->last_zc.tick) + (zc.frac - t->last_zc.frac);
    if (!(interval >= 0.25f)) {
        interval = 0.25f; /* two crosses within a period: keep the speed finite */
    }
    t->interval_periods[t->next] = interval;
    t->next = (t->next + 1u) % BEMF_INTERVALS;
    t->last_zc = zc;
    /* 30 electrical degrees after the cross: half the 60-degree interval */
    float delay = zc.frac + 0.5f * interval - lag_periods;
    uint32_t due = zc.tick + (delay > 0.0f ? (uint32_t)(delay + 0.5f) : 0u);
    return (int32_t)(due - now_tick) < 0 ? now_tick : due;
}

float bemf_timing_speed_rad_s(const bemf_timing *t, uint32_t pole_pairs, float period_s)
{
    float sum = 0.0f;
    for (unsigned k = 0u; k < BEMF_INTERVALS; ++k) {
        sum += t->interval_periods[k];
    }
    return (float)BEMF_INTERVALS * (BEMF_PI / 3.0f) / ((float)pole_pairs * sum * period_s);
}

float bemf_timing_last_interval(const bemf_timing *t)
{
    return t->interval_periods[(t->next + BEMF_INTERVALS - 1u) % BEMF_INTERVALS];
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
    /* the back-EMF only: the integrator supplies 2 R i, and its zero (ki / kp =
     * R / L) then cancels the pair's pole, leaving i / i_ref = w_c / (s + w_c);
     * feeding 2 R i_ref forward as well would leave that zero uncancelled and the
     * current (the torque) overshooting its reference */
    float feed_forward = line_emf_v;
    if (pi->primed) {
        pi->integral_v -= feed_forward - pi->feed_forward_v;
    }
    pi->feed_forward_v = feed_forward;
    pi->primed = 1u;
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
static void commutate(const bemf_config *cfg, bemf_drive *d, float interval_periods)
{
    d->step = bemf_next_step(d->step);
    bemf_zc_arm(&d->zc, bemf_commutation(d->step), d->tick);
    uint32_t blank = (uint32_t)(cfg->blanking_fraction * interval_periods);
    d->blanking_periods = blank > cfg->min_blanking_periods ? blank : cfg->min_blanking_periods;
    d->demag_limit_periods = d->blanking_periods + 1u + (uint32_t)(0.25f * interval_periods);
}

static float duty_of(float voltage_v, float vdc_v)
{
    /* a link below 1 V: nothing sensible to switch; 0 also catches NaN */
    return vdc_v > 1.0f ? clampf(voltage_v / vdc_v, 0.0f, 1.0f) : 0.0f;
}

float bemf_pair_current(uint8_t step, const float i_abc[3])
{
    bemf_step s = bemf_commutation(step);
    float in = i_abc[s.high];
    float out = -i_abc[s.low];
    float magnitude = fmaxf(fabsf(in), fabsf(out));
    return in + out >= 0.0f ? magnitude : -magnitude;
}

static void run_align(const bemf_config *cfg, bemf_drive *d, const bemf_inputs *in)
{
    if (d->tick - d->mode_tick >= cfg->ramp.align_periods) {
        /* the rotor's d-axis sits on the align step's current vector, which is
         * the start of the step two on: start there (commutate() moves one on) */
        d->mode = BEMF_RAMP;
        d->mode_tick = d->tick;
        d->step = bemf_next_step(cfg->align_step);
        bemf_ramp_reset(&d->ramp, &cfg->ramp);
        d->valid_steps = 0u;
        commutate(cfg, d, 0.0f);
        return;
    }
    d->speed_rad_s = 0.0f;
    d->duty = duty_of(2.0f * cfg->resistance_ohm * cfg->align_current_a, in->vdc_v);
}

static float ramp_interval_periods(const bemf_config *cfg, float speed_rad_s)
{
    return (BEMF_PI / 3.0f) / (speed_rad_s * (float)cfg->pole_pairs * cfg->control_period_s);
}

static void hand_over(const bemf_config *cfg, bemf_drive *d, bemf_instant zc)
{
    float interval = ramp_interval_periods(cfg, d->ramp.speed_rad_s);
    bemf_timing_seed(&d->timing, interval, zc);
    float delay = zc.frac + 0.5f * interval - cfg->zc_lag_periods;
    d->commutate_tick = zc.tick + (delay > 0.0f ? (uint32_t)(delay + 0.5f) : 0u);
    d->mode = BEMF_CLOSED;
    d->mode_tick = d->tick;
    d->last_zc_tick = zc.tick;
    /* The speed PI starts from zero: the rotor needs next to no torque to hold
     * the ramp speed, and an integrator preloaded with the open loop's torque
     * would carry the first speed rise far past its reference. */
    d->speed_pi.integral_nm = 0.0f;
    memset(&d->current_pi, 0, sizeof d->current_pi);
}

/* The floating terminal less the virtual neutral (the mean of the three), and
 * whether it sits on a rail (within 2 % of the link of DC- or DC+: a diode
 * conducts, the voltage says nothing of the back-EMF). */
static bemf_terminal floating_terminal(const bemf_inputs *in, uint8_t floating)
{
    float neutral = (in->terminal_v[0] + in->terminal_v[1] + in->terminal_v[2]) * (1.0f / 3.0f);
    float v = in->terminal_v[floating];
    float margin = 0.02f * in->vdc_v;
    bemf_terminal t = {v - neutral, (uint8_t)(!(v > margin) || !(v < in->vdc_v - margin))};
    return t;
}

static void run_ramp(const bemf_config *cfg, bemf_drive *d, const bemf_inputs *in)
{
    bemf_zc_config zc_cfg = cfg->zc;
    zc_cfg.blanking_periods = d->blanking_periods;
    zc_cfg.demag_limit_periods = d->demag_limit_periods;
    bemf_instant zc;
    int at_end_speed = d->ramp.tick >= cfg->ramp.ramp_periods;
    if (bemf_zc_feed(&zc_cfg, &d->zc, in->comparators, in->phase_current_a[d->zc.floating],
                     floating_terminal(in, d->zc.floating), d->tick, &zc)) {
        d->last_zc_tick = zc.tick;
        if (at_end_speed && ++d->valid_steps >= cfg->handover_zero_crosses) {
            hand_over(cfg, d, zc);
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
        commutate(cfg, d, ramp_interval_periods(cfg, d->ramp.speed_rad_s));
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
    zc_cfg.demag_limit_periods = d->demag_limit_periods;
    bemf_instant zc;
    if (bemf_zc_feed(&zc_cfg, &d->zc, in->comparators, in->phase_current_a[d->zc.floating],
                     floating_terminal(in, d->zc.floating), d->tick, &zc)) {
        d->commutate_tick = bemf_timing_zero_cross(&d->timing, zc, cfg->zc_lag_periods, d->tick);
        d->last_zc_tick = zc.tick;
    }
    if (d->tick - d->last_zc_tick > cfg->zc_timeout_periods) {
        trip(d, BEMF_TRIP_DESYNC, (float)(d->tick - d->last_zc_tick) * dt);
        return;
    }
    if (d->zc.found && (int32_t)(d->tick - d->commutate_tick) >= 0) {
        commutate(cfg, d, bemf_timing_last_interval(&d->timing));
    }
    d->speed_rad_s = bemf_timing_speed_rad_s(&d->timing, cfg->pole_pairs, dt);
    /* A cross overdue (two intervals since the commutation and none): the rotor
     * is not where the step assumes, and holding the step against a turning
     * rotor shorts its back-EMF through the pair. Open the bridge and coast,
     * still watching the floating phase (with every leg open its comparator
     * still sees the back-EMF), until the cross comes or the timeout trips. */
    uint32_t overdue = 2u * (uint32_t)(bemf_timing_last_interval(&d->timing) + 0.5f) + d->blanking_periods;
    d->coasting = !d->zc.found && d->tick - d->zc.armed_tick > overdue;
    if (d->coasting) {
        d->duty = 0.0f;
        return; /* the regulators hold their state */
    }
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
        d->pair_current_a = bemf_pair_current(d->step, in->phase_current_a);
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
    d->tick++; /* wraps after 2.5 days at 50 us: every use is a difference */
    bemf_output out = {0u, 0.0f};
    if ((d->mode == BEMF_ALIGN || d->mode == BEMF_RAMP || d->mode == BEMF_CLOSED) && !d->coasting) {
        out.step = d->step;
        out.duty = d->duty;
    }
    return out;
}
