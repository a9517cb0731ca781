#include "sixstep.h"

#include <math.h>

#include "hil_proto.h"

static float wrap_two_pi(float x)
{
    /* angles here stay within a few turns of [0, 2 pi): loops, not fmodf */
    while (x >= SIXSTEP_TWO_PI) {
        x -= SIXSTEP_TWO_PI;
    }
    while (x < 0.0f) {
        x += SIXSTEP_TWO_PI;
    }
    return x;
}

static float wrap_pi(float x)
{
    x = wrap_two_pi(x);
    return x > SIXSTEP_PI ? x - SIXSTEP_TWO_PI : x;
}

float sixstep_electrical_angle(uint32_t position_counts, uint32_t counts_per_rev, uint32_t pole_pairs)
{
    /* p theta_m modulo one electrical turn, in integers so that no precision is
     * lost at many pole pairs */
    uint32_t e_counts = (uint32_t)(((uint64_t)position_counts * pole_pairs) % counts_per_rev);
    return SIXSTEP_TWO_PI * (float)e_counts / (float)counts_per_rev;
}

uint8_t sixstep_sector(float theta_e_rad)
{
    /* sector s covers theta_e + 90 deg in [60 (s - 1), 60 s) */
    float phi = wrap_two_pi(theta_e_rad + 0.5f * SIXSTEP_PI);
    int k = (int)(phi * (3.0f / SIXSTEP_PI));
    if (k > 5) {
        k = 5; /* phi just below 2 pi rounding up */
    }
    return (uint8_t)(k + 1);
}

/* Pair for positive torque per sector, current vector at 60 s - 30 degrees:
 * a->c at 30, b->c at 90, b->a at 150, c->a at 210, c->b at 270, a->b at 330
 * (with i_c = 0, i_a = -i_b = I the vector is (I, -I/sqrt 3): -30 degrees). */
static const sixstep_pair commutation_table[6] = {
    {0u, 2u}, {1u, 2u}, {1u, 0u}, {2u, 0u}, {2u, 1u}, {0u, 1u},
};

sixstep_pair sixstep_commutation(uint8_t sector, int torque_negative)
{
    unsigned k = (unsigned)(sector - 1u) % 6u;
    if (torque_negative) {
        k = (k + 3u) % 6u;
    }
    return commutation_table[k];
}

uint8_t sixstep_gates(sixstep_pair pair, sixstep_chop chop)
{
    /* leg x: high switch bit 2x, low switch bit 2x + 1 (GATES bits, SPEC.md 9.2) */
    switch (chop) {
    case SIXSTEP_DRIVE:
        return (uint8_t)((HIL_GATE_A_HIGH << (2u * pair.high)) | (HIL_GATE_A_LOW << (2u * pair.low)));
    case SIXSTEP_FREEWHEEL:
        return (uint8_t)(HIL_GATE_A_LOW << (2u * pair.low));
    case SIXSTEP_OFF:
    default:
        return 0u;
    }
}

sixstep_chop sixstep_chopper(float pair_current_a, float current_ref_a, int motoring)
{
    if (pair_current_a < fabsf(current_ref_a)) {
        return SIXSTEP_DRIVE;
    }
    return motoring ? SIXSTEP_FREEWHEEL : SIXSTEP_OFF;
}

float sixstep_pair_current(const float phase_current_a[3], sixstep_pair pair)
{
    return 0.5f * (phase_current_a[pair.high] - phase_current_a[pair.low]);
}

float sixstep_torque_constant(uint32_t pole_pairs, float magnet_flux_wb)
{
    return 1.65399040f * (float)pole_pairs * magnet_flux_wb; /* 3 sqrt(3) / pi */
}

sixstep_tracker_gains sixstep_tracker_design(float bandwidth_hz)
{
    float wn = SIXSTEP_TWO_PI * bandwidth_hz;
    sixstep_tracker_gains g = {2.0f * wn, wn * wn};
    return g;
}

void sixstep_tracker_reset(sixstep_tracker *tr)
{
    tr->started = 0u;
    tr->last_count = 0u;
    tr->position_counts = 0u;
    tr->angle_rad = 0.0f;
    tr->speed_rad_s = 0.0f;
}

int32_t sixstep_tracker_step(const sixstep_tracker_gains *g, sixstep_tracker *tr, uint16_t count,
                             uint32_t counts_per_rev, float dt_s)
{
    int32_t moved = 0;
    if (!tr->started) {
        /* count 0 is theta_m = 0 (SPEC.md, docs/plant.md); the counter has not
         * wrapped yet at the first sample of a session */
        tr->started = 1u;
        tr->position_counts = (uint32_t)count % counts_per_rev;
        tr->angle_rad = SIXSTEP_TWO_PI * (float)tr->position_counts / (float)counts_per_rev;
    } else {
        /* signed 16-bit difference: right across the counter's wrap as long as
         * the rotor moves less than 32768 counts per period */
        moved = (int16_t)(uint16_t)(count - tr->last_count);
        int32_t pos = (int32_t)(tr->position_counts % counts_per_rev) + moved % (int32_t)counts_per_rev;
        if (pos < 0) {
            pos += (int32_t)counts_per_rev;
        }
        tr->position_counts = (uint32_t)pos % counts_per_rev;
    }
    tr->last_count = count;
    float measured = SIXSTEP_TWO_PI * (float)tr->position_counts / (float)counts_per_rev;
    float e = wrap_pi(measured - tr->angle_rad);
    tr->speed_rad_s += g->ki_per_s2 * dt_s * e;
    tr->angle_rad = wrap_two_pi(tr->angle_rad + dt_s * (tr->speed_rad_s + g->kp_per_s * e));
    return moved;
}

sixstep_pi_gains sixstep_speed_pi_design(float inertia_kgm2, float bandwidth_hz, float torque_limit_nm)
{
    float w = SIXSTEP_TWO_PI * bandwidth_hz;
    sixstep_pi_gains g = {2.0f * inertia_kgm2 * w, inertia_kgm2 * w * w, torque_limit_nm};
    return g;
}

float sixstep_pi_step(const sixstep_pi_gains *g, sixstep_pi *pi, float error_rad_s, float dt_s)
{
    float lim = g->torque_limit_nm;
    float p = g->kp_nm_per_rad_s * error_rad_s;
    float candidate = pi->integral_nm + g->ki_nm_per_rad * dt_s * error_rad_s;
    float unsat = p + candidate;
    if ((unsat > lim && error_rad_s > 0.0f) || (unsat < -lim && error_rad_s < 0.0f)) {
        return unsat > lim ? lim : -lim; /* saturated, error pushing further: hold */
    }
    candidate = candidate > lim ? lim : (candidate < -lim ? -lim : candidate);
    pi->integral_nm = candidate;
    float out = p + candidate;
    return out > lim ? lim : (out < -lim ? -lim : out);
}

int sixstep_encoder_watch_step(sixstep_encoder_watch *w, int32_t moved_counts, float speed_rad_s,
                               float torque_ref_nm, float torque_limit_nm, uint32_t counts_per_rev,
                               uint32_t timeout_periods, float dt_s)
{
    if (moved_counts != 0) {
        w->silent_periods = 0u;
        w->demand_periods = 0u;
        w->speed_at_edge_rad_s = speed_rad_s;
        return 0;
    }
    if (w->silent_periods < UINT32_MAX) {
        w->silent_periods++;
    }
    if (fabsf(torque_ref_nm) >= 0.5f * torque_limit_nm) {
        if (w->demand_periods < UINT32_MAX) {
            w->demand_periods++;
        }
    } else {
        w->demand_periods = 0u;
    }
    if (timeout_periods == 0u || w->silent_periods <= timeout_periods) {
        return 0;
    }
    /* at the last speed seen, one count takes 2 pi / (cpr |w|) seconds */
    float timeout_s = (float)timeout_periods * dt_s;
    int edge_overdue = fabsf(w->speed_at_edge_rad_s) * timeout_s * (float)counts_per_rev > SIXSTEP_TWO_PI;
    return edge_overdue || w->demand_periods > timeout_periods;
}
