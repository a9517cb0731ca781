/* Start-up stator-resistance identification (rs_id.c; control.c, RS_ID_PERIODS) against an
 * analytic RL load at standstill: a winding R, L behind an inverter that takes a constant
 * voltage c off every request (dead time and device drop at a fixed current sign), seen by a
 * board whose DC-link reading is (1 + e_v) high and whose current reading is g high.
 *
 * Expected values by hand. The load's DC state at a request U (board units) is
 * i = (U / (1 + e_v) - c) / R; the board reads g i. Two levels give
 *     R_id = (U2 - U1) / (g i2 - g i1) = (1 + e_v) R / g,
 * with c gone; one level would give U2 / (g i2) = R_id + (1 + e_v) c / (g i2). */
#include <string.h>

#include "check.h"
#include "control.h"
#include "rs_id.h"

static const double R = 0.5592, L = 4.8e-3, T = 50e-6;
static const double C_V = 5.733; /* (4/3)(Td/T Vdc + Ud) = (4/3)(2.8 + 1.5) V along d, a phase at +I */
static const double E_V = 0.016571, G = 1.005;

/* exact ZOH step of L di/dt = u - R i over one period */
static double rl_step(double i, double u)
{
    double a = exp(-R * T / L);
    return a * i + (1.0 - a) / R * u;
}

static rsid_cfg cfg_of(uint32_t n)
{
    rsid_cfg cfg;
    memset(&cfg, 0, sizeof cfg);
    cfg.periods_per_level = n;
    cfg.off_periods = 20u;
    cfg.current_low_a = 2.0f;
    cfg.current_high_a = 4.0f;
    cfg.stator_inductance_h = (float)L;
    cfg.bandwidth_hz = 500.0f;
    cfg.control_period_s = (float)T;
    rsid_derive(&cfg);
    return cfg;
}

/* The block alone on the d axis: the request acts one period late (a shadow register), the
 * inverter takes c off it, the board's voltage scale is 1 + e_v. Returns the periods driven. */
static int run_block(const rsid_cfg *cfg, rsid_state *st, double c_v)
{
    rsid_start(st);
    double i = 0.0, u_pending = 0.0;
    int driven = 0;
    for (int k = 0; k < 100000 && st->phase < RSID_DONE; ++k) {
        float u_d, u_q;
        uint8_t on = rsid_step(cfg, st, (float)(G * i), 0.0f, 40.0f, &u_d, &u_q);
        double u_true = u_pending / (1.0 + E_V) - (u_pending != 0.0 ? c_v : 0.0);
        i = rl_step(i, u_true);
        u_pending = on ? (double)u_d : 0.0;
        driven += on;
        assert_near(u_q, 0.0, 0.0);
    }
    return driven;
}

static void two_point_cancels_the_inverter_error(void **state)
{
    (void)state;
    rsid_cfg cfg = cfg_of(1000u);
    rsid_state st;
    int driven = run_block(&cfg, &st, C_V);
    assert_int_equal(st.phase, RSID_DONE);
    assert_int_equal(driven, 2000);
    double r_id = (1.0 + E_V) * R / G; /* 0.565628 ohm */
    assert_near(st.r_ohm, r_id, 2e-5 * r_id);
    /* the levels were reached: the measured means are the references */
    assert_near(st.i_low_a, 2.0, 1e-4);
    assert_near(st.i_high_a, 4.0, 1e-4);
    /* and the request carries the inverter's error: U = (1 + e_v)(R i / g + c) */
    assert_near(st.u_high_v, (1.0 + E_V) * (R * 4.0 / G + C_V), 1e-3);
    /* one point would have been off by (1 + e_v) c / I2 = 1.46 ohm */
    double one_point = st.u_high_v / st.i_high_a;
    assert_true(one_point - r_id > 1.4);
    /* without an inverter error the same R */
    rsid_state st0;
    run_block(&cfg, &st0, 0.0);
    assert_near(st0.r_ohm, r_id, 2e-5 * r_id);
}

static void voltage_limit_fails_the_identification(void **state)
{
    (void)state;
    rsid_cfg cfg = cfg_of(400u);
    rsid_state st;
    rsid_start(&st);
    double i = 0.0;
    /* u_max 3 V: the 8 V that 4 A needs cannot be applied */
    while (st.phase < RSID_DONE) {
        float u_d, u_q;
        uint8_t on = rsid_step(&cfg, &st, (float)i, 0.0f, 3.0f, &u_d, &u_q);
        assert_true(u_d <= 3.0f);
        i = rl_step(i, on ? u_d - 1.0 : 0.0);
    }
    assert_int_equal(st.phase, RSID_FAILED);
    assert_near(st.r_ohm, 0.0, 0.0);
}

/* ---- the control step: ADC samples in, DUTY answers out, R in force after ---- */

static const double A_PER_COUNT = 0.01220703125, V_PER_COUNT = 0.0244140625, VDC = 70.0;

typedef struct {
    double i_alpha, i_beta;
    uint32_t noise;
} load_ab;

static uint16_t counts(double amps, uint32_t *noise)
{
    /* +-1 count of uniform dither: the ADC's noise */
    double n = noise ? ((double)(check_rand(noise) % 2001u) / 1000.0 - 1.0) : 0.0;
    return (uint16_t)lround(2048.0 + G * amps / A_PER_COUNT + n);
}

static hil_sample sample_of(uint32_t k, load_ab *m)
{
    hil_sample s;
    memset(&s, 0, sizeof s);
    s.period = k;
    double ib = -0.5 * m->i_alpha + 0.8660254037844386 * m->i_beta;
    s.adc_i1 = counts(m->i_alpha, &m->noise);
    s.adc_i2 = counts(ib, &m->noise);
    s.adc_vdc = (uint16_t)lround((1.0 + E_V) * VDC / V_PER_COUNT);
    s.encoder = 0u; /* theta_e = 0: d along alpha */
    return s;
}

/* the load over one period under DUTY (duties on the true link, each leg's error -U0 sgn(i))
 * or under GATES 0 with no current (all that is asked of it here) */
static void load_period(load_ab *m, const ctl *c, int duty)
{
    if (!duty) {
        m->i_alpha = rl_step(m->i_alpha, 0.0);
        m->i_beta = rl_step(m->i_beta, 0.0);
        return;
    }
    const double u0 = 0.75 * C_V; /* per leg: (4/3) u0 = c along alpha at a positive i_alpha */
    double ia = m->i_alpha, ib = -0.5 * m->i_alpha + 0.8660254037844386 * m->i_beta, ic = -ia - ib;
    double cur[3] = {ia, ib, ic}, v[3];
    for (int x = 0; x < 3; ++x) {
        v[x] = ((double)c->st.duty[x] / 65535.0 - 0.5) * VDC - (cur[x] > 0.0 ? u0 : -u0);
    }
    double ua = (2.0 * v[0] - v[1] - v[2]) / 3.0, ub = (v[1] - v[2]) / 1.7320508075688772;
    m->i_alpha = rl_step(m->i_alpha, ua);
    m->i_beta = rl_step(m->i_beta, ub);
}

static void enable(ctl *c)
{
    hil_command cmd;
    memset(&cmd, 0, sizeof cmd);
    cmd.flags = HIL_CMD_ENABLE;
    cmd.speed_source = HIL_SPEED_ENCODER;
    cmd.speed_ref_rad_s = 0.0f;
    assert_int_equal(ctl_set_command(c, &cmd), 0);
}

static void control_step_identifies_then_drives(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    float v;
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_CURRENT_ZERO_CAL_PERIODS, 4.0f, &v), HIL_PARAM_OK);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_RS_ID_PERIODS, 1000.0f, &v), HIL_PARAM_OK);
    load_ab m = {0.0, 0.0, 12345u};
    uint32_t k = 0u;
    hil_sample s = sample_of(k++, &m);
    ctl_step(&c, &s, NULL); /* first SAMPLE: idle */
    enable(&c);
    /* the zero calibration first: GATES 0 */
    for (int n = 0; n < 4; ++n) {
        s = sample_of(k++, &m);
        assert_int_equal(ctl_step(&c, &s, NULL), 0u);
        assert_int_equal(c.st.answer_duty, 0u);
        load_period(&m, &c, 0);
    }
    /* then 2 x 1000 periods of DUTY, the delay of a shadow register in between */
    int pending = 0, duties = 0;
    ctl pend;
    for (int n = 0; n < 2000; ++n) {
        s = sample_of(k++, &m);
        hil_telemetry tm;
        ctl_step(&c, &s, &tm);
        assert_int_equal(c.st.answer_duty, 1u);
        assert_int_equal(tm.gates, CTL_GATES_PWM);
        assert_near(tm.torque_ref_nm, 0.0, 0.0);
        if (pending) {
            load_period(&m, &pend, 1);
        }
        pend = c;
        pending = 1;
        duties++;
    }
    assert_int_equal(duties, 2000);
    assert_true(fabs(m.i_alpha - 4.0 / G) < 0.05);
    assert_true(fabs(m.i_beta) < 0.05);
    /* then the bridge opens for 1 ms (20 periods); the load's current decays */
    load_period(&m, &pend, 1);
    for (int n = 0; n < 20; ++n) {
        s = sample_of(k++, &m);
        assert_int_equal(ctl_step(&c, &s, NULL), 0u);
        assert_int_equal(c.st.answer_duty, 0u);
        m.i_alpha = 0.0; /* through the diodes against the link: gone well within the period */
        m.i_beta = 0.0;
    }
    assert_int_equal(c.st.rs_id.phase, RSID_DONE);
    double r_id = (1.0 + E_V) * R / G;
    /* +-1 count of dither on 750 samples a level and the loop's noise through L: R to 1e-3 */
    assert_near(c.st.rs_id.r_ohm, r_id, 1e-3 * r_id);
    /* in force: the parameter reads it, the observer and the FOC loop use it */
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_STATOR_RESISTANCE_OHM, &v), HIL_PARAM_OK);
    assert_true(v == c.st.rs_id.r_ohm);
    assert_near(c.cfg.flux.stator_resistance_ohm, v, 0.0);
    assert_near(c.cfg.flux.half_r_t_ohm_s, 0.5 * v * T, 1e-12);
    assert_near(c.cfg.foc.current.stator_resistance_ohm, v, 0.0);
    /* and the drive runs: a vector (GATES) answers the next SAMPLE */
    s = sample_of(k++, &m);
    hil_telemetry tm;
    ctl_step(&c, &s, &tm);
    assert_int_equal(c.st.answer_duty, 0u);
    assert_int_equal(tm.state, HIL_STATE_RUNNING);
    /* once: a second enable calibrates the zero again but not R */
    hil_command off;
    memset(&off, 0, sizeof off);
    ctl_set_command(&c, &off);
    enable(&c);
    for (int n = 0; n < 5; ++n) {
        s = sample_of(k++, &m);
        ctl_step(&c, &s, NULL);
        assert_int_equal(c.st.answer_duty, 0u);
    }
    assert_int_equal(c.st.rs_id.phase, RSID_DONE);
}

static void off_by_default_bounded_and_only_at_standstill(void **state)
{
    (void)state;
    static ctl c;
    ctl_init(&c);
    float v;
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_RS_ID_PERIODS, &v), HIL_PARAM_OK);
    assert_near(v, 0.0, 0.0);
    load_ab m = {0.0, 0.0, 0u};
    hil_sample s = sample_of(0u, &m);
    ctl_step(&c, &s, NULL);
    enable(&c);
    s = sample_of(1u, &m);
    assert_true(ctl_step(&c, &s, NULL) != 0u); /* drives at once, GATES */
    assert_int_equal(c.st.answer_duty, 0u);
    assert_int_equal(c.st.rs_id.phase, RSID_IDLE);
    assert_int_equal(ctl_param_get(&c, HIL_PARAM_STATOR_RESISTANCE_OHM, &v), HIL_PARAM_OK);
    assert_near(v, 0.466, 1e-7);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_RS_ID_PERIODS, 70000.0f, &v), HIL_PARAM_OUT_OF_RANGE);
    assert_int_equal(ctl_param_set(&c, HIL_PARAM_RS_ID_PERIODS, 2.5f, &v), HIL_PARAM_OUT_OF_RANGE);
    /* a rotor that turns at the enable: no identification, R stays */
    static ctl d;
    ctl_init(&d);
    assert_int_equal(ctl_param_set(&d, HIL_PARAM_RS_ID_PERIODS, 400.0f, &v), HIL_PARAM_OK);
    s = sample_of(0u, &m);
    ctl_step(&d, &s, NULL);
    s = sample_of(1u, &m);
    s.encoder = 10u; /* 10 counts in 50 us: 307 rad/s */
    ctl_step(&d, &s, NULL);
    enable(&d);
    assert_int_equal(d.st.rs_id.phase, RSID_IDLE);
    s = sample_of(2u, &m);
    s.encoder = 20u;
    ctl_step(&d, &s, NULL);
    assert_int_equal(d.st.answer_duty, 0u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(two_point_cancels_the_inverter_error),
        cmocka_unit_test(voltage_limit_fails_the_identification),
        cmocka_unit_test(control_step_identifies_then_drives),
        cmocka_unit_test(off_by_default_bounded_and_only_at_standstill),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
