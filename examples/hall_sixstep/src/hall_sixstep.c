#include "hall_sixstep.h"

#include <math.h>

#include "hil_proto.h"

static float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }

/* Hall word (C B A) -> sector; 0 and 7 illegal. Word 1 ((-30, 30) degrees) is
 * sector 2, as in the encoder example's numbering (examples/sixstep). */
static const uint8_t sector_of_word[8] = {0u, 2u, 4u, 3u, 6u, 1u, 5u, 0u};

uint8_t hs_sector_of_hall(uint8_t hall_word) { return sector_of_word[hall_word & 0x07u]; }

/* Pair per sector: the phase on its positive flat top in, the one on its
 * negative flat top out. Sector 2 (theta_e in (-30, 30)): e_b = +E, e_c = -E. */
static const hs_pair commutation_table[6] = {
    {0u, 2u}, {1u, 2u}, {1u, 0u}, {2u, 0u}, {2u, 1u}, {0u, 1u},
};

hs_pair hs_commutation(uint8_t sector) { return commutation_table[(unsigned)(sector - 1u) % 6u]; }

float hs_pair_current(const float phase_current_a[3], hs_pair pair)
{
    /* three currents summing to 0: the largest magnitude is half the sum of magnitudes */
    float largest = 0.5f * (fabsf(phase_current_a[0]) + fabsf(phase_current_a[1]) + fabsf(phase_current_a[2]));
    return phase_current_a[pair.high] - phase_current_a[pair.low] < 0.0f ? -largest : largest;
}

float hs_torque_constant(uint32_t pole_pairs, float magnet_flux_wb) { return 2.0f * (float)pole_pairs * magnet_flux_wb; }

/* ---- Hall speed ----------------------------------------------------------- */

void hs_hall_speed_reset(hs_hall_speed *s)
{
    s->sector = 0u;
    s->direction = 0;
    s->intervals = 0u;
    s->periods_since_edge = 0u;
    for (unsigned i = 0u; i < HS_SPEED_WINDOW_EDGES; i++) {
        s->interval_periods[i] = 0u;
    }
    s->speed_rad_s = 0.0f;
}

/* One edge in `edge` direction: a whole interval when the previous edge was one
 * in the same direction, else the window starts again. */
static void hall_speed_edge(hs_hall_speed *s, int edge, float edge_angle, float dt_s)
{
    if (edge != 0 && edge == s->direction) {
        for (unsigned i = HS_SPEED_WINDOW_EDGES - 1u; i > 0u; i--) {
            s->interval_periods[i] = s->interval_periods[i - 1u];
        }
        s->interval_periods[0] = s->periods_since_edge;
        if (s->intervals < HS_SPEED_WINDOW_EDGES) {
            s->intervals++;
        }
        uint32_t window = 0u;
        for (unsigned i = 0u; i < s->intervals; i++) {
            window += s->interval_periods[i];
        }
        s->speed_rad_s = (float)edge * (float)s->intervals * edge_angle / ((float)window * dt_s);
    } else {
        /* the first edge, a reversal inside a sector, or a jumped sector: the time
         * since the previous edge is not one sector's crossing */
        s->intervals = 0u;
        s->speed_rad_s = 0.0f;
    }
    s->direction = (int8_t)edge;
    s->periods_since_edge = 0u;
}

static uint32_t longest_interval(const hs_hall_speed *s)
{
    uint32_t longest = 0u;
    for (unsigned i = 0u; i < s->intervals; i++) {
        longest = s->interval_periods[i] > longest ? s->interval_periods[i] : longest;
    }
    return longest;
}

int hs_hall_speed_step(hs_hall_speed *s, uint8_t sector, uint32_t pole_pairs, float dt_s)
{
    const float edge_angle = (HS_PI / 3.0f) / (float)pole_pairs;
    if (s->periods_since_edge < UINT32_MAX) {
        s->periods_since_edge++;
    }
    int edge = 0;
    if (sector != 0u && s->sector != 0u && sector != s->sector) {
        unsigned step = (unsigned)(sector + 6u - s->sector) % 6u;
        edge = step == 1u ? 1 : (step == 5u ? -1 : 0);
        hall_speed_edge(s, edge, edge_angle, dt_s);
    }
    if (sector != 0u) {
        s->sector = sector;
    }
    if (s->periods_since_edge > 0u) {
        float elapsed = (float)s->periods_since_edge * dt_s;
        if (elapsed > HS_SPEED_ZERO_AFTER_S) {
            s->speed_rad_s = 0.0f;
        } else if (s->intervals > 0u && s->periods_since_edge > longest_interval(s)) {
            /* overdue (later than any interval in the window): no faster than one edge
             * angle over the time since the last edge */
            float cap = edge_angle / elapsed;
            s->speed_rad_s = clampf(s->speed_rad_s, -cap, cap);
        }
    }
    return edge;
}

/* ---- current regulator ----------------------------------------------------- */

hs_current_gains hs_current_design(float resistance_ohm, float inductance_h, uint32_t pole_pairs,
                                   float magnet_flux_wb, float bandwidth_hz)
{
    float wc = HS_TWO_PI * bandwidth_hz;
    hs_current_gains g = {2.0f * inductance_h * wc, 2.0f * resistance_ohm * wc,
                          2.0f * (float)pole_pairs * magnet_flux_wb};
    return g;
}

float hs_current_step(const hs_current_gains *g, hs_current_pi *pi, float current_ref_a, float pair_current_a,
                      float speed_rad_s, float vdc_v, float dt_s)
{
    float lim = vdc_v > 0.0f ? vdc_v : 0.0f;
    float error = current_ref_a - pair_current_a;
    float feed_forward = g->back_emf_v_per_rad_s * speed_rad_s;
    float candidate = pi->integral_v + g->ki_v_per_a_s * dt_s * error;
    float unlimited = feed_forward + g->kp_v_per_a * error + candidate;
    if ((unlimited > lim && error > 0.0f) || (unlimited < -lim && error < 0.0f)) {
        return clampf(unlimited, -lim, lim); /* limited, error pushing further: hold */
    }
    pi->integral_v = clampf(candidate, -2.0f * lim, 2.0f * lim);
    return clampf(feed_forward + g->kp_v_per_a * error + pi->integral_v, -lim, lim);
}

hs_legs hs_legs_off(void)
{
    hs_legs legs = {{0.0f, 0.0f, 0.0f}, 0u};
    return legs;
}

hs_legs hs_legs_for_pair_voltage(hs_pair pair, float pair_voltage_v, float vdc_v)
{
    hs_legs legs = hs_legs_off();
    if (!(vdc_v > 0.0f) || !(fabsf(pair_voltage_v) <= vdc_v)) {
        return legs; /* no link to switch, or a request it cannot give (NaN included) */
    }
    float duty = fabsf(pair_voltage_v) / vdc_v;
    uint8_t pwm_leg = pair_voltage_v >= 0.0f ? pair.high : pair.low;
    legs.duty[pwm_leg] = duty; /* the other enabled leg stays at 0: its low switch on */
    legs.leg_enable = (uint8_t)((1u << pair.high) | (1u << pair.low));
    return legs;
}

/* ---- speed PI ------------------------------------------------------------- */

hs_speed_gains hs_speed_pi_design(float inertia_kgm2, float bandwidth_hz, float torque_limit_nm)
{
    float w = HS_TWO_PI * bandwidth_hz;
    hs_speed_gains g = {2.0f * inertia_kgm2 * w, inertia_kgm2 * w * w, torque_limit_nm};
    return g;
}

float hs_speed_pi_step(const hs_speed_gains *g, hs_speed_pi *pi, float error_rad_s, float dt_s)
{
    float lim = g->torque_limit_nm;
    float p = g->kp_nm_per_rad_s * error_rad_s;
    float candidate = pi->integral_nm + g->ki_nm_per_rad * dt_s * error_rad_s;
    float unlimited = p + candidate;
    if ((unlimited > lim && error_rad_s > 0.0f) || (unlimited < -lim && error_rad_s < 0.0f)) {
        return clampf(unlimited, -lim, lim); /* saturated, error pushing further: hold */
    }
    pi->integral_nm = clampf(candidate, -lim, lim);
    return clampf(p + pi->integral_nm, -lim, lim);
}

/* ---- protection ----------------------------------------------------------- */

int hs_hall_watch_step(hs_hall_watch *w, uint8_t sector)
{
    if (sector != 0u) {
        w->illegal_periods = 0u;
        return 0;
    }
    if (w->illegal_periods < UINT32_MAX) {
        w->illegal_periods++;
    }
    return w->illegal_periods >= HS_HALL_ILLEGAL_PERIODS;
}

int hs_stall_watch_step(hs_stall_watch *w, int edge, float torque_ref_nm, float torque_limit_nm,
                        uint32_t timeout_periods)
{
    if (edge != 0) {
        w->silent_periods = 0u;
        w->demand_periods = 0u;
        return 0;
    }
    if (w->silent_periods < UINT32_MAX) {
        w->silent_periods++;
    }
    /* NaN fails the comparison (no demand counted); the firmware's torque
     * reference is finite: a non-finite COMMAND is refused with FAULT 6, and PARAM_SET
     * refuses non-finite gains */
    if (fabsf(torque_ref_nm) >= 0.5f * torque_limit_nm) {
        if (w->demand_periods < UINT32_MAX) {
            w->demand_periods++;
        }
    } else {
        w->demand_periods = 0u;
    }
    return timeout_periods != 0u && w->demand_periods > timeout_periods;
}
