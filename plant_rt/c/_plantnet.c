/*
 * _plantnet: the plant's hot numerics in C, as a CPython extension (plant_rt/ckernel.py is its
 * front end; plant_rt/circuit.py and plant_rt/plant.py stay the reference and the fallback).
 *
 *   integrate   Network.integrate: the general network (inverter legs driven or through their
 *               diodes, DC link, stator, rotor) over one constant-switch interval by RK4 with
 *               event location (a diode current reaching zero, a floating terminal reaching a
 *               rail, a line back-EMF overcoming the rails with no current, a driven current
 *               crossing the device-drop knee), the state transitions they cause, the coast
 *               with no current at all.
 *   settle      Network._settle after Network.begin: the turn-on conditions that hold now.
 *   period      Plant._general's loop over a period's intervals when all go to the network
 *               (Network.begin and Network.integrate for each).
 *   leg_period  Plant._leg_period: a PWM period as constant-vector pieces from the legs'
 *               switch windows, integrated piece by piece (MotorModel.advance_pieces), with
 *               the sign check of Plant._signs_hold.
 *   advance     MotorModel.advance (the driven and diode intervals of the general path).
 *   duty_windows  SwitchTimeline._duty_windows (the switches' on-intervals of a duty command).
 *   duty_period  Plant.step's DUTY period on the leg-window path in one call: Command.parse,
 *               switch_windows (the dead-time memory included), leg_period, _finish.
 *   sample      Plant.sample with Sensors.read (the ADC codes with their noise draws, the
 *               encoder count, the status bits) in the plain case: no sensor fault, no open
 *               phase, no noise buffer to refill (None otherwise: the Python code runs).
 *   truth       Plant.truth's record in the plain case (no open phase, load not locked).
 *
 * Why hand-written C: with PWM, dead time and device drop the plant spends its time in the
 * Python interpreter's per-call overhead (about 50 RHS evaluations per 50 us period, each a few
 * microseconds), not in arithmetic; and no maintained library integrates this switched network
 * with these events in a way that keeps the Python reference's step sequence. Every function
 * here mirrors its Python original operation by operation (same order of operations, compiled
 * with -ffp-contract=off, the same libm cos/sin), so the two agree to rounding and a run is
 * deterministic.
 *
 * Plain C99 and the CPython API; no state between calls (everything comes in as arguments)
 * but the class layouts sample and truth read slots at (see there).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <string.h>

/* Leg / phase states (plant_rt/inverter.py). */
enum { K_H = 0, K_L = 1, K_P = 2, K_N = 3, K_O = 4 };
/* Event tags (plant_rt/circuit.py event_values). */
enum { T_I = 0, T_HI = 1, T_LO = 2, T_REL = 3, T_K = 4 };

#define ZERO_CURRENT_A 1e-9
#define MAX_EVENTS_PER_INTERVAL 64
#define MAX_G 10

static double SQRT3, S32, INV_SQRT3;
static const double TWO_THIRDS = 2.0 / 3.0;
static double AX[3][2];

/* What the kernel knows of the plant besides its state: the Python objects' constants, in
 * the order of MotorModel._k and Network._cfg (plant_rt/motor.py, plant_rt/circuit.py). */
typedef struct {
    /* motor (MotorModel._k) */
    double pole_pairs;
    double resistance_ohm;        /* stator phase resistance */
    double flux_linkage_wb;       /* permanent-magnet flux linkage (peak, per phase) */
    double inv_ld_per_h;          /* 1 / L_d */
    double inv_lq_per_h;          /* 1 / L_q */
    double inv_inertia_per_kgm2;  /* 1 / J */
    double damping_nm_per_rad_s;  /* viscous friction */
    double torque_coeff;          /* 1.5 pole_pairs: T_e = torque_coeff (psi_d i_q - psi_q i_d) */
    /* DC link: mode 0 ideal, 1 resistive, 2 dynamic */
    int dc_link_mode, dc_source_unidirectional; /* (unidirectional: the source takes no current) */
    double dc_source_v;
    double dc_source_resistance_ohm;
    double inv_dc_capacitance_per_f; /* 1 / C (0 without a capacitor) */
    /* inverter */
    double device_drop_v;         /* a conducting device's forward drop */
    double device_knee_a;         /* below this current the drop is proportional to it */
    /* load: torque = load_torque0_nm + load_slope_nm_per_s (t - load_t0_s)
     *               + load_nm_per_rad_s w over the interval */
    int load_locked;
    double load_nm_per_rad_s, load_t0_s, load_torque0_nm, load_slope_nm_per_s;
    int open_phase; /* -1: none */
} cfg_t;

typedef struct {
    double g;
    int tag, x;
} ev_t;

/* The general network over one interval (Network in plant_rt/circuit.py): the constants, the
 * legs' states, and what the last RHS evaluation found (the event functions read it). */
typedef struct {
    cfg_t cfg;
    int kinds[3];                /* per phase: K_H, K_L (driven), K_P, K_N (a diode), K_O (open) */
    int zero[3];                 /* the phases held at zero current (K_O) ... */
    int nzero;                   /* ... and their number */
    int all_zero;                /* no current anywhere: the coast */
    double phase_current_a[3];
    double floating_terminal_v;  /* the one open phase's terminal voltage (nzero == 1) */
    double dc_link_v;
    double release_margin_v;     /* > 0: a line back-EMF overcomes the rails (release) ... */
    double back_emf_alpha_v, back_emf_beta_v; /* (the coast's stator voltage) */
    double torque_nm;            /* the electromagnetic torque */
    int release_out_phase, release_into_phase; /* ... between these two phases */
    int knee_side[3];
    long events, overflows;
} net_t;

/* ------------------------------------------------------------------ DC link */

static double dc_voltage(const cfg_t *c, double v, double idc)
{
    if (c->dc_link_mode == 2) {
        return v;
    }
    if (c->dc_link_mode == 1) {
        return c->dc_source_v - c->dc_source_resistance_ohm * idc;
    }
    return c->dc_source_v;
}

static double dc_dv_dt(const cfg_t *c, double v, double idc)
{
    if (c->dc_link_mode != 2) {
        return 0.0;
    }
    double i = (c->dc_source_v - v) / c->dc_source_resistance_ohm;
    if (c->dc_source_unidirectional && i < 0.0) {
        i = 0.0;
    }
    return (i - idc) * c->inv_dc_capacitance_per_f;
}

/* ------------------------------------------------------------------ leg states */

static void configure(net_t *n, const int kinds[3])
{
    int k[3] = {kinds[0], kinds[1], kinds[2]};
    int nz = 0;
    for (int x = 0; x < 3; x++) {
        if (k[x] == K_O) {
            nz++;
        }
    }
    if (nz >= 2) {
        for (int x = 0; x < 3; x++) {
            if (k[x] == K_P || k[x] == K_N) {
                k[x] = K_O;
            }
        }
    }
    n->nzero = 0;
    for (int x = 0; x < 3; x++) {
        n->kinds[x] = k[x];
        if (k[x] == K_O) {
            n->zero[n->nzero++] = x;
        }
    }
    n->all_zero = n->nzero >= 2;
}

static void project_phase(const net_t *n, int x, double *y)
{
    const cfg_t *m = &n->cfg;
    double e = m->pole_pairs * y[3];
    double c = cos(e), s = sin(e);
    double ex0 = AX[x][0], ex1 = AX[x][1];
    double i_d = (c * y[0] + s * y[1] - m->flux_linkage_wb) * m->inv_ld_per_h;
    double i_q = (c * y[1] - s * y[0]) * m->inv_lq_per_h;
    double ia = c * i_d - s * i_q;
    double ib = s * i_d + c * i_q;
    double ix = ex0 * ia + ex1 * ib;
    double rd = c * ex0 + s * ex1;
    double rq = c * ex1 - s * ex0;
    double delta = -ix / (rd * rd * m->inv_ld_per_h + rq * rq * m->inv_lq_per_h);
    y[0] += delta * ex0;
    y[1] += delta * ex1;
}

static void project(const net_t *n, double *y)
{
    if (n->nzero == 0) {
        return;
    }
    double e = n->cfg.pole_pairs * y[3];
    double c = cos(e), s = sin(e);
    if (n->all_zero) {
        y[0] = n->cfg.flux_linkage_wb * c;
        y[1] = n->cfg.flux_linkage_wb * s;
        return;
    }
    project_phase(n, n->zero[0], y);
}

/* ------------------------------------------------------------------ RHS */

/* out: dpsi_a, dpsi_b, dw, dtheta, dv_dc, u_alpha, u_beta, i_dc */
static void rhs(net_t *n, double t, const double *y, double *out)
{
    const cfg_t *m = &n->cfg;
    double pa = y[0], pb = y[1], w = y[2], th = y[3], v = y[4];
    double e = m->pole_pairs * th;
    double c = cos(e);
    double s = sin(e);
    double we = m->pole_pairs * w;
    double dpa, dpb, te, idc, vdc, va, vb;
    if (n->all_zero) {
        va = -we * m->flux_linkage_wb * s;
        vb = we * m->flux_linkage_wb * c;
        dpa = va;
        dpb = vb;
        te = 0.0;
        idc = 0.0;
        vdc = dc_voltage(m, v, 0.0);
        n->phase_current_a[0] = n->phase_current_a[1] = n->phase_current_a[2] = 0.0;
        n->back_emf_alpha_v = va;
        n->back_emf_beta_v = vb;
    } else {
        double pd = c * pa + s * pb;
        double pq = c * pb - s * pa;
        double i_d = (pd - m->flux_linkage_wb) * m->inv_ld_per_h;
        double i_q = pq * m->inv_lq_per_h;
        double ia = c * i_d - s * i_q;
        double ib = s * i_d + c * i_q;
        double cur[3] = {ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib};
        idc = 0.0;
        for (int x = 0; x < 3; x++) {
            if (n->kinds[x] == K_H || n->kinds[x] == K_N) {
                idc += cur[x];
            }
        }
        vdc = dc_voltage(m, v, idc);
        double ud = m->device_drop_v;
        double vt[3] = {0.0, 0.0, 0.0};
        for (int x = 0; x < 3; x++) {
            int k = n->kinds[x];
            if (k == K_H || k == K_L) {
                double drop = 0.0;
                if (ud != 0.0) {
                    double z = cur[x] / m->device_knee_a;
                    drop = ud * (z > 1.0 ? 1.0 : z < -1.0 ? -1.0 : z);
                }
                vt[x] = (k == K_H ? vdc : 0.0) - drop;
            } else if (k == K_P) {
                vt[x] = -ud;
            } else if (k == K_N) {
                vt[x] = vdc + ud;
            }
        }
        va = (2.0 * vt[0] - vt[1] - vt[2]) / 3.0;
        vb = (vt[1] - vt[2]) * INV_SQRT3;
        if (n->nzero) {
            double ex0 = AX[n->zero[0]][0], ex1 = AX[n->zero[0]][1];
            double did = (c * va + s * vb - m->resistance_ohm * i_d + we * pq) * m->inv_ld_per_h;
            double diq = (c * vb - s * va - m->resistance_ohm * i_q - we * pd) * m->inv_lq_per_h;
            double rd = c * ex0 + s * ex1;
            double rq = c * ex1 - s * ex0;
            double g0 = rd * did + rq * diq + we * (ex1 * ia - ex0 * ib);
            double vx = -g0 / (TWO_THIRDS * (rd * rd * m->inv_ld_per_h + rq * rq * m->inv_lq_per_h));
            va += TWO_THIRDS * ex0 * vx;
            vb += TWO_THIRDS * ex1 * vx;
            n->floating_terminal_v = vx;
        }
        dpa = va - m->resistance_ohm * ia;
        dpb = vb - m->resistance_ohm * ib;
        te = m->torque_coeff * (pd * i_q - pq * i_d);
        n->phase_current_a[0] = cur[0];
        n->phase_current_a[1] = cur[1];
        n->phase_current_a[2] = cur[2];
    }
    n->dc_link_v = vdc;
    n->torque_nm = te;
    double dw;
    if (m->load_locked) {
        dw = 0.0;
    } else {
        dw = (te - m->damping_nm_per_rad_s * w - ((m->load_torque0_nm + m->load_slope_nm_per_s * (t - m->load_t0_s)) + m->load_nm_per_rad_s * w)) * m->inv_inertia_per_kgm2;
    }
    out[0] = dpa;
    out[1] = dpb;
    out[2] = dw;
    out[3] = w;
    out[4] = dc_dv_dt(m, v, idc);
    out[5] = va;
    out[6] = vb;
    out[7] = idc;
}

static void release(net_t *n, double va, double vb, double vdc)
{
    double ud = n->cfg.device_drop_v;
    double up[3], lo[3];
    for (int x = 0; x < 3; x++) {
        double ex = AX[x][0] * va + AX[x][1] * vb;
        int k = n->kinds[x];
        if (k == K_O) {
            up[x] = ex - vdc - ud;
            lo[x] = ex + ud;
        } else {
            double rail = k == K_H ? vdc : 0.0;
            up[x] = ex - rail;
            lo[x] = ex - rail;
        }
    }
    static const int pairs[6][2] = {{0, 1}, {0, 2}, {1, 0}, {1, 2}, {2, 0}, {2, 1}};
    double best = -INFINITY;
    int bo = 0, bi = 1;
    int cut = n->cfg.open_phase;
    for (int j = 0; j < 6; j++) {
        int x = pairs[j][0], yy = pairs[j][1];
        if (x == cut || yy == cut) {
            continue;
        }
        double g = up[x] - lo[yy];
        if (g > best) {
            best = g;
            bo = x;
            bi = yy;
        }
    }
    n->release_margin_v = best;
    n->release_out_phase = bo;
    n->release_into_phase = bi;
}

static int event_values(net_t *n, ev_t *out)
{
    int k = 0;
    if (n->all_zero) {
        release(n, n->back_emf_alpha_v, n->back_emf_beta_v, n->dc_link_v);
        out[0].g = n->release_margin_v;
        out[0].tag = T_REL;
        out[0].x = 0;
        return 1;
    }
    for (int x = 0; x < 3; x++) {
        if (n->kinds[x] == K_P) {
            out[k].g = -n->phase_current_a[x];
            out[k].tag = T_I;
            out[k++].x = x;
        } else if (n->kinds[x] == K_N) {
            out[k].g = n->phase_current_a[x];
            out[k].tag = T_I;
            out[k++].x = x;
        }
    }
    if (n->nzero && n->zero[0] != n->cfg.open_phase) {
        int x = n->zero[0];
        out[k].g = n->floating_terminal_v - n->dc_link_v - n->cfg.device_drop_v;
        out[k].tag = T_HI;
        out[k++].x = x;
        out[k].g = -n->cfg.device_drop_v - n->floating_terminal_v;
        out[k].tag = T_LO;
        out[k++].x = x;
    }
    if (n->cfg.device_drop_v != 0.0) {
        for (int x = 0; x < 3; x++) {
            if ((n->kinds[x] == K_H || n->kinds[x] == K_L) && n->knee_side[x]) {
                out[k].g = n->knee_side[x] * (n->cfg.device_knee_a - fabs(n->phase_current_a[x]));
                out[k].tag = T_K;
                out[k++].x = x;
            }
        }
    }
    return k;
}

static void note_knee_sides(net_t *n)
{
    if (n->cfg.device_drop_v != 0.0) {
        for (int x = 0; x < 3; x++) {
            n->knee_side[x] = fabs(n->phase_current_a[x]) > n->cfg.device_knee_a ? 1 : -1;
        }
    }
}

/* ------------------------------------------------------------------ integration */

static void rk4(net_t *n, double t, const double *y, double h, const double *k1, double *out,
                double *quad)
{
    double k2[8], k3[8], k4[8], z[5];
    double h2 = 0.5 * h;
    for (int i = 0; i < 5; i++) {
        z[i] = y[i] + h2 * k1[i];
    }
    rhs(n, t + h2, z, k2);
    for (int i = 0; i < 5; i++) {
        z[i] = y[i] + h2 * k2[i];
    }
    rhs(n, t + h2, z, k3);
    for (int i = 0; i < 5; i++) {
        z[i] = y[i] + h * k3[i];
    }
    rhs(n, t + h, z, k4);
    double h6 = h / 6.0;
    for (int i = 0; i < 5; i++) {
        out[i] = y[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
    for (int i = 0; i < 3; i++) {
        quad[i] = h6 * (k1[5 + i] + 2.0 * (k2[5 + i] + k3[5 + i]) + k4[5 + i]);
    }
    if (n->cfg.load_locked) {
        out[2] = 0.0;
    }
}

static int state_after(net_t *n, double t, const double *y, double h, const double *k1,
                       double *y1, double *quad, ev_t *g)
{
    double scratch[8];
    rk4(n, t, y, h, k1, y1, quad);
    rhs(n, t + h, y1, scratch);
    return event_values(n, g);
}

static void transition(net_t *n, double t, int tag, int x, double *y)
{
    if (tag == T_K) {
        n->events++;
        return;
    }
    int kinds[3] = {n->kinds[0], n->kinds[1], n->kinds[2]};
    if (tag == T_I) {
        kinds[x] = K_O;
    } else if (tag == T_HI) {
        kinds[x] = K_N;
    } else if (tag == T_LO) {
        kinds[x] = K_P;
    } else {
        double scratch[8];
        ev_t g[MAX_G];
        rhs(n, t, y, scratch);
        event_values(n, g);
        if (kinds[n->release_out_phase] == K_O) {
            kinds[n->release_out_phase] = K_N;
        }
        if (kinds[n->release_into_phase] == K_O) {
            kinds[n->release_into_phase] = K_P;
        }
    }
    configure(n, kinds);
    project(n, y);
    n->events++;
}

static void settle(net_t *n, double t, double *y)
{
    for (int it = 0; it < 6; it++) {
        double scratch[8];
        ev_t g[MAX_G];
        rhs(n, t, y, scratch);
        note_knee_sides(n);
        int ng = event_values(n, g);
        int best = -1;
        for (int j = 0; j < ng; j++) {
            if (g[j].tag != T_I && g[j].tag != T_K && g[j].g > 0.0 &&
                (best < 0 || g[j].g > g[best].g)) {
                best = j;
            }
        }
        if (best < 0) {
            return;
        }
        transition(n, t, g[best].tag, g[best].x, y);
    }
}

static double locate(net_t *n, double t, const double *y, double h, const double *k1, int j,
                     double ga, double gb)
{
    if (ga > 0.0) {
        return 0.0;
    }
    double a = 0.0, b = h;
    double fa = ga, fb = gb;
    int side = 0;
    double tol = 1e-15 + 1e-11 * h;
    for (int it = 0; it < 80; it++) {
        if (b - a <= tol) {
            break;
        }
        double x = fb != fa ? b - fb * (b - a) / (fb - fa) : 0.5 * (a + b);
        if (!(a < x && x < b)) {
            x = 0.5 * (a + b);
        }
        double y1[5], quad[3];
        ev_t g[MAX_G];
        state_after(n, t, y, x, k1, y1, quad, g);
        double fx = g[j].g;
        if (fx > 0.0) {
            b = x;
            fb = fx;
            if (side == 1) {
                fa *= 0.5;
            }
            side = 1;
        } else {
            a = x;
            fa = fx;
            if (side == -1) {
                fb *= 0.5;
            }
            side = -1;
        }
    }
    return b;
}

/* The RK4 step count of an interval, max(1, ceil(...)) as the Python reference computes it from
 * cn = ceil(length / h_max - 1e-9): 0, or -1 with ValueError when cn is NaN, infinite or above
 * MAX_RK4_STEPS (the conversion to long would be undefined there, and Python's int would make
 * a loop that never ends). Identical to the cast for every count that can run. */
#define MAX_RK4_STEPS 2147483647.0
static int rk4_steps(double cn, long *steps)
{
    if (cn < 1.0) {
        *steps = 1;
        return 0;
    }
    if (!(cn <= MAX_RK4_STEPS)) {
        PyErr_SetString(PyExc_ValueError, "plant kernel: an interval's RK4 step count (its length / h_max) is "
                                          "NaN, infinite or above 2^31 - 1");
        return -1;
    }
    *steps = (long)cn;
    return 0;
}

/* Network._coast: 1 and out filled when no conducting path opens, else 0. */
static int coast(net_t *n, double t0, double t1, const double *y, long steps, double *acc,
                 double *out)
{
    const cfg_t *m = &n->cfg;
    double pa0 = y[0], pb0 = y[1], w = y[2], th = y[3], v = y[4];
    double h = (t1 - t0) / (double)steps;
    /* load.segment(t0): the interval's segment starts at tl_t */
    double v0 = m->load_torque0_nm + m->load_slope_nm_per_s * (t0 - m->load_t0_s);
    double slope = m->load_slope_nm_per_s;
    double kw = m->load_nm_per_rad_s, b = m->damping_nm_per_rad_s, ij = m->inv_inertia_per_kgm2;
    for (long i = 0; i < steps; i++) {
        double t = (double)i * h;
        double k1w, k2w, k3w, k4w;
        if (m->load_locked) {
            k1w = k2w = k3w = k4w = 0.0;
            w = 0.0;
        } else {
            k1w = -(b * w + v0 + slope * t + kw * w) * ij;
            double w2 = w + 0.5 * h * k1w;
            k2w = -(b * w2 + v0 + slope * (t + 0.5 * h) + kw * w2) * ij;
            double w3 = w + 0.5 * h * k2w;
            k3w = -(b * w3 + v0 + slope * (t + 0.5 * h) + kw * w3) * ij;
            double w4 = w + h * k3w;
            k4w = -(b * w4 + v0 + slope * (t + h) + kw * w4) * ij;
        }
        th += h / 6.0 * (w + 2.0 * (w + 0.5 * h * k1w) + 2.0 * (w + 0.5 * h * k2w) + w + h * k3w);
        w += h / 6.0 * (k1w + 2.0 * (k2w + k3w) + k4w);
        if (m->dc_link_mode == 2) {
            double q1 = dc_dv_dt(m, v, 0.0);
            double q2 = dc_dv_dt(m, v + 0.5 * h * q1, 0.0);
            double q3 = dc_dv_dt(m, v + 0.5 * h * q2, 0.0);
            double q4 = dc_dv_dt(m, v + h * q3, 0.0);
            v += h / 6.0 * (q1 + 2.0 * (q2 + q3) + q4);
        }
    }
    double e = m->pole_pairs * th;
    out[0] = m->flux_linkage_wb * cos(e);
    out[1] = m->flux_linkage_wb * sin(e);
    out[2] = w;
    out[3] = th;
    out[4] = v;
    double scratch[8];
    rhs(n, t1, out, scratch);
    release(n, n->back_emf_alpha_v, n->back_emf_beta_v, n->dc_link_v);
    if (n->release_margin_v > 0.0) {
        return 0;
    }
    acc[0] += out[0] - pa0;
    acc[1] += out[1] - pb0;
    return 1;
}

/* 0, or -1 with an exception (rk4_steps). */
static int net_integrate(net_t *n, double t0, double t1, double *y, double h_max, double *acc)
{
    double ratio = (t1 - t0) / h_max - 1e-9;
    double cn = ceil(ratio);
    long steps;
    if (rk4_steps(cn, &steps) < 0) {
        return -1;
    }
    if (n->all_zero) {
        double out[5];
        if (coast(n, t0, t1, y, steps, acc, out)) {
            memcpy(y, out, sizeof out);
            return 0;
        }
    }
    double h_nom = (t1 - t0) / (double)steps;
    double t = t0;
    int budget = MAX_EVENTS_PER_INTERVAL;
    double k1[8];
    ev_t g0[MAX_G], g1[MAX_G];
    rhs(n, t, y, k1);
    note_knee_sides(n);
    int n0 = event_values(n, g0);
    while (t1 - t > 1e-12 * h_nom) {
        double h = h_nom < t1 - t ? h_nom : t1 - t;
        if (t + h > t1 - 1e-9 * h_nom) {
            h = t1 - t;
        }
        double y1[5], quad[3];
        int n1 = state_after(n, t, y, h, k1, y1, quad, g1);
        int fired[MAX_G];
        int nf = 0;
        if (budget > 0 && n1 == n0) {
            for (int j = 0; j < n0; j++) {
                double a = g0[j].g, b = g1[j].g;
                if (b > 0.0 && (a <= 0.0 || b > a)) {
                    fired[nf++] = j;
                }
            }
        }
        if (nf) {
            budget--;
            if (budget == 0) {
                n->overflows++;
            }
            double tau = 0.0;
            int jbest = -1;
            for (int f = 0; f < nf; f++) {
                int j = fired[f];
                double tj = locate(n, t, y, h, k1, j, g0[j].g, g1[j].g);
                if (jbest < 0 || tj < tau) { /* fired is ascending: ties keep the smaller j */
                    tau = tj;
                    jbest = j;
                }
            }
            double yn[5];
            rk4(n, t, y, tau, k1, yn, quad);
            memcpy(y, yn, sizeof yn);
            for (int i = 0; i < 3; i++) {
                acc[i] += quad[i];
            }
            t += tau;
            transition(n, t, g0[jbest].tag, g0[jbest].x, y);
            settle(n, t, y);
        } else {
            memcpy(y, y1, sizeof y1);
            for (int i = 0; i < 3; i++) {
                acc[i] += quad[i];
            }
            t += h;
            if (n->nzero) {
                project(n, y);
            }
        }
        rhs(n, t, y, k1);
        note_knee_sides(n);
        n0 = event_values(n, g0);
    }
    return 0;
}

/* ------------------------------------------------------------------ leg period */

#define MAX_WIN 16
#define MAX_TOG 96

typedef struct {
    double len, va, vb, ga, gb;
} piece_t;

/* MotorModel.advance: n RK4 steps of length h at constant (va, vb), Ld != Lq form. */
static void advance_general(const cfg_t *m, double *st, double va, double vb, double h, long n,
                            double tl0, double tl_slope, double bw)
{
    double p = m->pole_pairs, r = m->resistance_ohm, psim = m->flux_linkage_wb, ild = m->inv_ld_per_h, ilq = m->inv_lq_per_h, ij = m->inv_inertia_per_kgm2, kt = m->torque_coeff;
    double pa = st[0], pb = st[1], w = st[2], th = st[3];
    double h2 = 0.5 * h;
    double h6 = h / 6.0;
    double t = 0.0;
    for (long i = 0; i < n; i++) {
        double tl1 = tl0 + tl_slope * t;
        double tl2 = tl1 + tl_slope * h2;
        double tl4 = tl1 + tl_slope * h;
        double e = p * th;
        double c = cos(e);
        double s = sin(e);
        double pd = c * pa + s * pb;
        double pq = c * pb - s * pa;
        double i_d = (pd - psim) * ild;
        double i_q = pq * ilq;
        double d1a = va - r * (c * i_d - s * i_q);
        double d1b = vb - r * (s * i_d + c * i_q);
        double d1w = (kt * (pd * i_q - pq * i_d) - bw * w - tl1) * ij;
        double w2 = w + h2 * d1w;
        e = p * (th + h2 * w);
        c = cos(e);
        s = sin(e);
        double xa = pa + h2 * d1a;
        double xb = pb + h2 * d1b;
        pd = c * xa + s * xb;
        pq = c * xb - s * xa;
        i_d = (pd - psim) * ild;
        i_q = pq * ilq;
        double d2a = va - r * (c * i_d - s * i_q);
        double d2b = vb - r * (s * i_d + c * i_q);
        double d2w = (kt * (pd * i_q - pq * i_d) - bw * w2 - tl2) * ij;
        double w3 = w + h2 * d2w;
        e = p * (th + h2 * w2);
        c = cos(e);
        s = sin(e);
        xa = pa + h2 * d2a;
        xb = pb + h2 * d2b;
        pd = c * xa + s * xb;
        pq = c * xb - s * xa;
        i_d = (pd - psim) * ild;
        i_q = pq * ilq;
        double d3a = va - r * (c * i_d - s * i_q);
        double d3b = vb - r * (s * i_d + c * i_q);
        double d3w = (kt * (pd * i_q - pq * i_d) - bw * w3 - tl2) * ij;
        double w4 = w + h * d3w;
        e = p * (th + h * w3);
        c = cos(e);
        s = sin(e);
        xa = pa + h * d3a;
        xb = pb + h * d3b;
        pd = c * xa + s * xb;
        pq = c * xb - s * xa;
        i_d = (pd - psim) * ild;
        i_q = pq * ilq;
        double d4a = va - r * (c * i_d - s * i_q);
        double d4b = vb - r * (s * i_d + c * i_q);
        double d4w = (kt * (pd * i_q - pq * i_d) - bw * w4 - tl4) * ij;
        pa += h6 * (d1a + 2.0 * (d2a + d3a) + d4a);
        pb += h6 * (d1b + 2.0 * (d2b + d3b) + d4b);
        th += h6 * (w + 2.0 * (w2 + w3) + w4);
        w += h6 * (d1w + 2.0 * (d2w + d3w) + d4w);
        t += h;
    }
    st[0] = pa;
    st[1] = pb;
    st[2] = w;
    st[3] = th;
}

/* One RK4 step of MotorModel's Ld = Lq form at constant (va, vb) with the load torque at the
 * step's start, middle and end (tl1, tl2, tl4); ril = R/L, rk = R psim/L, kti = kt psim/L.
 * advance_spm and advance_pieces both take it: each keeps its own load-time bookkeeping,
 * as the Python they mirror does. */
static inline void rk4_spm_step(double p, double ril, double rk, double kti, double ij, double bw,
                                double va, double vb, double h, double tl1, double tl2, double tl4,
                                double *pa_io, double *pb_io, double *w_io, double *th_io)
{
    double pa = *pa_io, pb = *pb_io, w = *w_io, th = *th_io;
    double h2 = 0.5 * h;
    double h6 = h / 6.0;
    double e = p * th;
    double c = cos(e);
    double s = sin(e);
    double d1a = va - ril * pa + rk * c;
    double d1b = vb - ril * pb + rk * s;
    double d1w = (kti * (c * pb - s * pa) - bw * w - tl1) * ij;
    double xa = pa + h2 * d1a;
    double xb = pb + h2 * d1b;
    double w2 = w + h2 * d1w;
    e = p * (th + h2 * w);
    c = cos(e);
    s = sin(e);
    double d2a = va - ril * xa + rk * c;
    double d2b = vb - ril * xb + rk * s;
    double d2w = (kti * (c * xb - s * xa) - bw * w2 - tl2) * ij;
    xa = pa + h2 * d2a;
    xb = pb + h2 * d2b;
    double w3 = w + h2 * d2w;
    e = p * (th + h2 * w2);
    c = cos(e);
    s = sin(e);
    double d3a = va - ril * xa + rk * c;
    double d3b = vb - ril * xb + rk * s;
    double d3w = (kti * (c * xb - s * xa) - bw * w3 - tl2) * ij;
    xa = pa + h * d3a;
    xb = pb + h * d3b;
    double w4 = w + h * d3w;
    e = p * (th + h * w3);
    c = cos(e);
    s = sin(e);
    double d4a = va - ril * xa + rk * c;
    double d4b = vb - ril * xb + rk * s;
    double d4w = (kti * (c * xb - s * xa) - bw * w4 - tl4) * ij;
    pa += h6 * (d1a + 2.0 * (d2a + d3a) + d4a);
    pb += h6 * (d1b + 2.0 * (d2b + d3b) + d4b);
    th += h6 * (w + 2.0 * (w2 + w3) + w4);
    w += h6 * (d1w + 2.0 * (d2w + d3w) + d4w);
    *pa_io = pa;
    *pb_io = pb;
    *w_io = w;
    *th_io = th;
}

/* MotorModel.advance's Ld = Lq form (its own time bookkeeping: t accumulates h). */
static void advance_spm(const cfg_t *m, double *st, double va, double vb, double h, long n,
                        double tl0, double tl_slope, double bw)
{
    double p = m->pole_pairs, r = m->resistance_ohm, psim = m->flux_linkage_wb, ild = m->inv_ld_per_h, ij = m->inv_inertia_per_kgm2, kt = m->torque_coeff;
    double pa = st[0], pb = st[1], w = st[2], th = st[3];
    double h2 = 0.5 * h;
    double t = 0.0;
    double ril = r * ild;
    double rk = r * psim * ild;
    double kti = kt * psim * ild;
    for (long i = 0; i < n; i++) {
        double tl1 = tl0 + tl_slope * t;
        double tl2 = tl1 + tl_slope * h2;
        double tl4 = tl1 + tl_slope * h;
        rk4_spm_step(p, ril, rk, kti, ij, bw, va, vb, h, tl1, tl2, tl4, &pa, &pb, &w, &th);
        t += h;
    }
    st[0] = pa;
    st[1] = pb;
    st[2] = w;
    st[3] = th;
}

/* MotorModel.advance_pieces; st = (pa, pb, w, th) in and out, *q_out = int g . i dt. 0, or -1
 * with an exception (rk4_steps; st is then partly advanced). */
static int advance_pieces(const cfg_t *m, int spm, double *st, const piece_t *pieces,
                          int npieces, double h_max, double tl0, double tl_slope, double bw,
                          double *q_out)
{
    double p = m->pole_pairs, r = m->resistance_ohm, psim = m->flux_linkage_wb, ild = m->inv_ld_per_h, ij = m->inv_inertia_per_kgm2, kt = m->torque_coeff;
    double pa = st[0], pb = st[1], w = st[2], th = st[3];
    double t = 0.0, q = 0.0;
    double ril = r * ild;
    double rk = r * psim * ild;
    double kti = kt * psim * ild;
    for (int k = 0; k < npieces; k++) {
        double length = pieces[k].len, va = pieces[k].va, vb = pieces[k].vb;
        long n = 1;
        if (!(length <= h_max) && rk4_steps(ceil(length / h_max - 1e-9), &n) < 0) {
            return -1;
        }
        double pa0 = pa, pb0 = pb;
        if (!spm) {
            double s4[4] = {pa, pb, w, th};
            advance_general(m, s4, va, vb, length / (double)n, n, tl0 + tl_slope * t, tl_slope,
                            bw);
            pa = s4[0];
            pb = s4[1];
            w = s4[2];
            th = s4[3];
        } else {
            double h = length / (double)n;
            double h2 = 0.5 * h;
            for (long i = 0; i < n; i++) {
                double tl1 = tl0 + tl_slope * (t + (double)i * h);
                double tl2 = tl1 + tl_slope * h2;
                double tl4 = tl1 + tl_slope * h;
                rk4_spm_step(p, ril, rk, kti, ij, bw, va, vb, h, tl1, tl2, tl4, &pa, &pb, &w, &th);
            }
        }
        double ga = pieces[k].ga, gb = pieces[k].gb;
        if (ga != 0.0 || gb != 0.0) {
            q += ga * (va * length - pa + pa0) + gb * (vb * length - pb + pb0);
        }
        t += length;
    }
    st[0] = pa;
    st[1] = pb;
    st[2] = w;
    st[3] = th;
    *q_out = q / r;
    return 0;
}

/* MotorModel.currents: i_alpha, i_beta, i_d, i_q (out[0..3]) of the flux linkage (pa, pb) at
 * the electrical angle e = p theta_m. */
static void currents_at(double e, double psim, double ild, double ilq, double pa, double pb,
                        double out[4])
{
    double c = cos(e), s = sin(e);
    double i_d = (c * pa + s * pb - psim) * ild;
    double i_q = (c * pb - s * pa) * ilq;
    out[0] = c * i_d - s * i_q;
    out[1] = s * i_d + c * i_q;
    out[2] = i_d;
    out[3] = i_q;
}

static void currents(const cfg_t *m, double pa, double pb, double th, double *ia, double *ib)
{
    double i[4];
    currents_at(m->pole_pairs * th, m->flux_linkage_wb, m->inv_ld_per_h, m->inv_lq_per_h, pa, pb, i);
    *ia = i[0];
    *ib = i[1];
}

/* ------------------------------------------------------------------ argument helpers */

/* The motor constants MotorModel._k passes, in its order (plant_rt/motor.py), into a cfg_t. */
static void motor_constants(cfg_t *m, const double k[8])
{
    m->pole_pairs = k[0];
    m->resistance_ohm = k[1];
    m->flux_linkage_wb = k[2];
    m->inv_ld_per_h = k[3];
    m->inv_lq_per_h = k[4];
    m->inv_inertia_per_kgm2 = k[5];
    m->damping_nm_per_rad_s = k[6];
    m->torque_coeff = k[7];
}

static int get_doubles(PyObject *seq, double *out, Py_ssize_t n, const char *what)
{
    if (!PyTuple_Check(seq) && !PyList_Check(seq)) {
        PyErr_Format(PyExc_TypeError, "%s must be a tuple or list", what);
        return -1;
    }
    if (PySequence_Fast_GET_SIZE(seq) != n) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd items", what, n);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(seq);
    for (Py_ssize_t i = 0; i < n; i++) {
        double v = PyFloat_AsDouble(items[i]);
        if (v == -1.0 && PyErr_Occurred()) {
            return -1;
        }
        out[i] = v;
    }
    return 0;
}

static int get_double(PyObject *o, double *out)
{
    double v = PyFloat_AsDouble(o);
    if (v == -1.0 && PyErr_Occurred()) {
        return -1;
    }
    *out = v;
    return 0;
}

/* cfg: (dc_mode, src_v, rs, ic, unidirectional, ud, knee, locked, kw, tl_t, tl_v0, tl_slope,
 *       open_phase); motor: MotorModel._k = (p, r, psim, ild, ilq, ij, b, kt). */
#define NCFG 13
static int get_cfg(PyObject *motor, PyObject *cfg, cfg_t *c)
{
    double k[8], f[NCFG];
    if (get_doubles(motor, k, 8, "motor constants") < 0 || get_doubles(cfg, f, NCFG, "cfg") < 0) {
        return -1;
    }
    c->pole_pairs = k[0];
    c->resistance_ohm = k[1];
    c->flux_linkage_wb = k[2];
    c->inv_ld_per_h = k[3];
    c->inv_lq_per_h = k[4];
    c->inv_inertia_per_kgm2 = k[5];
    c->damping_nm_per_rad_s = k[6];
    c->torque_coeff = k[7];
    /* the ranges below before the conversions to int (undefined for NaN or out of int's range);
     * accepted are the values whose truncation is in range, as before */
    if (!(f[0] > -1.0 && f[0] < 3.0) || !(f[12] > -2.0 && f[12] < 3.0)) {
        PyErr_SetString(PyExc_ValueError, "cfg: dc_mode or open_phase out of range");
        return -1;
    }
    c->dc_link_mode = (int)f[0];
    c->dc_source_v = f[1];
    c->dc_source_resistance_ohm = f[2];
    c->inv_dc_capacitance_per_f = f[3];
    c->dc_source_unidirectional = f[4] != 0.0;
    c->device_drop_v = f[5];
    c->device_knee_a = f[6];
    c->load_locked = f[7] != 0.0;
    c->load_nm_per_rad_s = f[8];
    c->load_t0_s = f[9];
    c->load_torque0_nm = f[10];
    c->load_slope_nm_per_s = f[11];
    c->open_phase = (int)f[12];
    if (c->dc_link_mode < 0 || c->dc_link_mode > 2 || c->open_phase < -1 || c->open_phase > 2) {
        PyErr_SetString(PyExc_ValueError, "cfg: dc_mode or open_phase out of range");
        return -1;
    }
    return 0;
}

static int get_kinds(PyObject *seq, int *kinds)
{
    double k[3];
    if (get_doubles(seq, k, 3, "kinds") < 0) {
        return -1;
    }
    for (int x = 0; x < 3; x++) {
        if (!(k[x] >= 0.0 && k[x] <= 4.0)) {
            PyErr_SetString(PyExc_ValueError, "kinds: a leg state must be 0..4");
            return -1;
        }
        kinds[x] = (int)k[x];
    }
    return 0;
}

/* ------------------------------------------------------------------ Python functions */

PyDoc_STRVAR(integrate_doc,
"integrate(motor_k, cfg, kinds, t0, t1, y, h_max, acc) -> (y, kinds, events, overflows, vdc)\n\n"
"Network.integrate over [t0, t1] from y (5 floats) with the phase states kinds (3 ints,\n"
"already configured); adds int u_alpha, u_beta, i_dc dt to the list acc (3 floats).\n"
"Returns the end state (a new list), the phase states at the end, the events and event-budget\n"
"overflows counted, and v_dc at the last evaluation.");

static PyObject *mod_integrate(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError, "integrate takes 8 arguments");
        return NULL;
    }
    net_t n;
    memset(&n, 0, sizeof n);
    double t0, t1, h_max, y[5], acc[3];
    int kinds[3];
    if (get_cfg(args[0], args[1], &n.cfg) < 0 || get_kinds(args[2], kinds) < 0 ||
        get_double(args[3], &t0) < 0 || get_double(args[4], &t1) < 0 ||
        get_doubles(args[5], y, 5, "y") < 0 || get_double(args[6], &h_max) < 0) {
        return NULL;
    }
    PyObject *acc_list = args[7];
    if (!PyList_Check(acc_list) || get_doubles(acc_list, acc, 3, "acc") < 0) {
        if (!PyErr_Occurred()) {
            PyErr_SetString(PyExc_TypeError, "acc must be a list of 3 floats");
        }
        return NULL;
    }
    if (!(h_max > 0.0) || !isfinite(t0) || !isfinite(t1) || !(t1 >= t0)) {
        PyErr_SetString(PyExc_ValueError, "integrate: need t0 <= t1 finite and h_max > 0");
        return NULL;
    }
    configure(&n, kinds);
    if (net_integrate(&n, t0, t1, y, h_max, acc) < 0) {
        return NULL;
    }
    for (int i = 0; i < 3; i++) {
        PyObject *f = PyFloat_FromDouble(acc[i]);
        if (f == NULL) {
            return NULL;
        }
        PyList_SetItem(acc_list, i, f); /* steals f */
    }
    return Py_BuildValue("[ddddd](iii)lld", y[0], y[1], y[2], y[3], y[4], n.kinds[0], n.kinds[1],
                         n.kinds[2], n.events, n.overflows, n.dc_link_v);
}

/* Network.begin: the phase states for an interval with the given leg states (H, L or O).
 * *last is the legs of the last begin (-1: none, i.e. Network._legs is None). */
static void begin(net_t *n, double t, double *y, const int legs[3], int *last)
{
    int code = legs[0] + 5 * legs[1] + 25 * legs[2];
    if (code == *last) {
        return;
    }
    *last = code;
    double ia, ib;
    double e = n->cfg.pole_pairs * y[3];
    double c = cos(e), s = sin(e);
    double i_d = (c * y[0] + s * y[1] - n->cfg.flux_linkage_wb) * n->cfg.inv_ld_per_h;
    double i_q = (c * y[1] - s * y[0]) * n->cfg.inv_lq_per_h;
    ia = c * i_d - s * i_q;
    ib = s * i_d + c * i_q;
    double cur[3] = {ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib};
    int kinds[3];
    for (int x = 0; x < 3; x++) {
        if (x == n->cfg.open_phase) {
            kinds[x] = K_O;
        } else if (legs[x] != K_O) {
            kinds[x] = legs[x];
        } else if (n->kinds[x] == K_P || n->kinds[x] == K_N || n->kinds[x] == K_O) {
            kinds[x] = n->kinds[x];
        } else if (cur[x] > ZERO_CURRENT_A) {
            kinds[x] = K_P;
        } else if (cur[x] < -ZERO_CURRENT_A) {
            kinds[x] = K_N;
        } else {
            kinds[x] = K_O;
        }
    }
    configure(n, kinds);
    if (n->nzero) {
        project(n, y);
        settle(n, t, y);
    }
}

static const int LEG_BITS[3][2] = {{0x01, 0x02}, {0x04, 0x08}, {0x10, 0x20}};

/* What period() and fast_period() take first, in this order: (motor_k, cfg, kinds, last_legs,
 * intervals, t0, T, y, h_max, acc, seg_t, seg_v0, slope, vdc); the network is configured. */
typedef struct {
    net_t n;
    double t0, T, y[5], acc[3], h_max, seg_t, seg_v0, slope;
    int last;
    PyObject *intervals, *acc_list;
} period_args_t;

static int period_args(PyObject *const *args, const char *name, period_args_t *pa)
{
    memset(&pa->n, 0, sizeof pa->n);
    int kinds[3];
    long last_l = PyLong_AsLong(args[3]);
    if (last_l == -1 && PyErr_Occurred()) {
        return -1;
    }
    if (get_cfg(args[0], args[1], &pa->n.cfg) < 0 || get_kinds(args[2], kinds) < 0 ||
        get_double(args[5], &pa->t0) < 0 || get_double(args[6], &pa->T) < 0 ||
        get_doubles(args[7], pa->y, 5, "y") < 0 || get_double(args[8], &pa->h_max) < 0 ||
        get_double(args[10], &pa->seg_t) < 0 || get_double(args[11], &pa->seg_v0) < 0 ||
        get_double(args[12], &pa->slope) < 0 || get_double(args[13], &pa->n.dc_link_v) < 0) {
        return -1;
    }
    pa->intervals = args[4];
    pa->acc_list = args[9];
    if (!PyList_Check(pa->intervals)) {
        PyErr_SetString(PyExc_TypeError, "intervals must be a list of (a, b, word)");
        return -1;
    }
    if (!PyList_Check(pa->acc_list) || get_doubles(pa->acc_list, pa->acc, 3, "acc") < 0) {
        if (!PyErr_Occurred()) {
            PyErr_SetString(PyExc_TypeError, "acc must be a list of 3 floats");
        }
        return -1;
    }
    if (!(pa->h_max > 0.0) || !(pa->T > 0.0) || !isfinite(pa->t0)) {
        PyErr_Format(PyExc_ValueError, "%s: need h_max > 0, T > 0, t0 finite", name);
        return -1;
    }
    pa->last = (int)last_l;
    configure(&pa->n, kinds);
    return 0;
}

/* Interval i of the list: 1 with a, b, the word (0..63) and its legs (H, L or O each); 0 when
 * it is too short to integrate (b - a <= 1e-15 T); -1 with an exception. */
static int period_interval(const period_args_t *pa, Py_ssize_t i, double *a, double *b, long *word,
                           int legs[3])
{
    PyObject *iv = PyList_GET_ITEM(pa->intervals, i);
    if (!PyTuple_Check(iv) || PyTuple_GET_SIZE(iv) != 3) {
        PyErr_SetString(PyExc_TypeError, "intervals must be a list of (a, b, word)");
        return -1;
    }
    if (get_double(PyTuple_GET_ITEM(iv, 0), a) < 0 || get_double(PyTuple_GET_ITEM(iv, 1), b) < 0) {
        return -1;
    }
    *word = PyLong_AsLong(PyTuple_GET_ITEM(iv, 2));
    if (*word == -1 && PyErr_Occurred()) {
        return -1;
    }
    if (*word < 0 || *word > 63) {
        PyErr_SetString(PyExc_ValueError, "intervals: a word is 0..63");
        return -1;
    }
    if (!(*b - *a > 1e-15 * pa->T)) {
        return 0;
    }
    for (int x = 0; x < 3; x++) {
        int on_h = (*word & LEG_BITS[x][0]) != 0, on_l = (*word & LEG_BITS[x][1]) != 0;
        legs[x] = on_h && !on_l ? K_H : on_l && !on_h ? K_L : K_O;
    }
    return 1;
}

/* Network.set_load_segment, begin and integrate over [t0 + a, t0 + b]: one interval through the
 * network, the load v0 + slope (t - (t0 + a)) over it. 0, or -1 with an exception. */
static int network_interval(period_args_t *pa, double a, double b, double v0, const int legs[3])
{
    net_t *n = &pa->n;
    double ta = pa->t0 + a;
    n->cfg.load_t0_s = ta;
    n->cfg.load_torque0_nm = v0;
    n->cfg.load_slope_nm_per_s = pa->slope;
    begin(n, ta, pa->y, legs, &pa->last);
    return net_integrate(n, ta, pa->t0 + b, pa->y, pa->h_max, pa->acc);
}

/* Writes acc back into the caller's list; 0, or -1 with an exception. */
static int period_acc_back(period_args_t *pa)
{
    for (int i = 0; i < 3; i++) {
        PyObject *f = PyFloat_FromDouble(pa->acc[i]);
        if (f == NULL) {
            return -1;
        }
        PyList_SetItem(pa->acc_list, i, f); /* steals f */
    }
    return 0;
}

PyDoc_STRVAR(period_doc,
"period(motor_k, cfg, kinds, last_legs, intervals, t0, T, y, h_max, acc, seg_t, seg_v0, slope,\n"
"       vdc) -> (y, kinds, last_legs, events, overflows, vdc, intervals_run)\n\n"
"Plant._general's loop when every interval goes to the network and no load knot falls in the\n"
"period: for each (a, b, word) of intervals, Network.begin with the word's leg states and\n"
"Network.integrate over [t0 + a, t0 + b], the load profile seg_v0 + slope (t - seg_t).\n"
"last_legs: the legs of the network's last begin coded l0 + 5 l1 + 25 l2, -1 for none;\n"
"vdc: the network's last v_dc (returned as it is when no interval runs).");

struct fast_path;
static int run_intervals(period_args_t *pa, const struct fast_path *f, int *net_dirty, int *ran);

static PyObject *mod_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 14) {
        PyErr_SetString(PyExc_TypeError, "period takes 14 arguments");
        return NULL;
    }
    period_args_t pa;
    if (period_args(args, "period", &pa) < 0) {
        return NULL;
    }
    int ran = 0, net_dirty = 0;
    if (run_intervals(&pa, NULL, &net_dirty, &ran) < 0) {
        return NULL;
    }
    const net_t *n = &pa.n;
    return Py_BuildValue("[ddddd](iii)illdi", pa.y[0], pa.y[1], pa.y[2], pa.y[3], pa.y[4], n->kinds[0],
                         n->kinds[1], n->kinds[2], pa.last, n->events, n->overflows, n->dc_link_v, ran);
}

/* A driven word's vector as Plant._vectors holds it: (va, vb, ga, gb, legs); 0 none (None), 1 read,
 * -1 with an exception. */
static int driven_vector(PyObject *vectors, long word, double v[4], int legs[3])
{
    PyObject *vec = PyList_GET_ITEM(vectors, word);
    if (vec == Py_None) {
        return 0;
    }
    if (!PyTuple_Check(vec) || PyTuple_GET_SIZE(vec) != 5) {
        PyErr_SetString(PyExc_TypeError, "vectors: (va, vb, ga, gb, legs) or None per word");
        return -1;
    }
    for (int i = 0; i < 4; i++) {
        if (get_double(PyTuple_GET_ITEM(vec, i), &v[i]) < 0) {
            return -1;
        }
    }
    return get_kinds(PyTuple_GET_ITEM(vec, 4), legs) < 0 ? -1 : 1;
}

/* Plant._advance: the fast RK4 over one driven interval of `length`, y and acc updated. 0, or -1
 * with an exception (rk4_steps). */
static int fast_advance(const cfg_t *m, int spm, double *y, const double v[4], double length,
                        double h_max, double v0, double slope, double bw, double *acc)
{
    long n;
    if (rk4_steps(ceil(length / h_max - 1e-9), &n) < 0) {
        return -1;
    }
    double pa0 = y[0], pb0 = y[1];
    double st[4] = {y[0], y[1], y[2], y[3]};
    if (spm) {
        advance_spm(m, st, v[0], v[1], length / (double)n, n, v0, slope, bw);
    } else {
        advance_general(m, st, v[0], v[1], length / (double)n, n, v0, slope, bw);
    }
    y[0] = st[0];
    y[1] = st[1];
    y[2] = st[2];
    y[3] = st[3];
    acc[0] += v[0] * length;
    acc[1] += v[1] * length;
    acc[2] += (v[2] * (v[0] * length - (y[0] - pa0)) + v[3] * (v[1] * length - (y[1] - pb0))) / m->resistance_ohm;
    return 0;
}

/* A switch toggling at `when` (word bit `bit`): the sweep's events, in (when, bit) order. */
typedef struct {
    double when;
    int bit;
} toggle_t;

static int toggle_cmp(const void *pa, const void *pb)
{
    const toggle_t *a = pa, *b = pb;
    if (a->when != b->when) {
        return a->when < b->when ? -1 : 1;
    }
    return (a->bit > b->bit) - (a->bit < b->bit);
}

#define MAX_TOGGLES (6 * MAX_WIN * 2)

PyDoc_STRVAR(word_intervals_doc,
"word_intervals(T, windows) -> [(start, end, word), ...] or None\n\n"
"Timeline._word_intervals: the six switches' on-windows [(a, b), ...] swept into the\n"
"constant-word intervals covering [0, T), neighbours with the same word joined (stuck bits\n"
"not applied). None when there are more toggles than it holds (Python's turn).");

static PyObject *mod_word_intervals(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "word_intervals takes 2 arguments");
        return NULL;
    }
    double T;
    if (get_double(args[0], &T) < 0) {
        return NULL;
    }
    PyObject *windows = args[1];
    if (!PyList_Check(windows) || PyList_GET_SIZE(windows) != 6) {
        PyErr_SetString(PyExc_TypeError, "windows must be a list of 6 lists of (a, b)");
        return NULL;
    }
    toggle_t toggles[MAX_TOGGLES];
    int nt = 0;
    long word = 0;
    for (int j = 0; j < 6; j++) {
        PyObject *sw = PyList_GET_ITEM(windows, j);
        if (!PyList_Check(sw)) {
            PyErr_SetString(PyExc_TypeError, "windows must be a list of 6 lists of (a, b)");
            return NULL;
        }
        int bit = 1 << j;
        for (Py_ssize_t i = 0; i < PyList_GET_SIZE(sw); i++) {
            PyObject *w = PyList_GET_ITEM(sw, i);
            double a, b;
            if (!PyTuple_Check(w) || PyTuple_GET_SIZE(w) != 2) {
                PyErr_SetString(PyExc_TypeError, "a window is (a, b)");
                return NULL;
            }
            if (get_double(PyTuple_GET_ITEM(w, 0), &a) < 0 || get_double(PyTuple_GET_ITEM(w, 1), &b) < 0) {
                return NULL;
            }
            if (nt > MAX_TOGGLES - 2) {
                Py_RETURN_NONE;
            }
            if (a <= 0.0) {
                word |= bit;
            } else {
                toggles[nt].when = a;
                toggles[nt++].bit = bit;
            }
            if (b < T) {
                toggles[nt].when = b;
                toggles[nt++].bit = bit;
            }
        }
    }
    qsort(toggles, (size_t)nt, sizeof toggles[0], toggle_cmp);
    /* the sweep, joining a new interval to the last one when the word is the same */
    double start[MAX_TOGGLES + 1], end[MAX_TOGGLES + 1];
    long words[MAX_TOGGLES + 1];
    int n = 0;
    double t = 0.0;
    for (int i = 0; i < nt; i++) {
        double when = toggles[i].when;
        if (when > t) {
            if (n > 0 && words[n - 1] == word) {
                end[n - 1] = when;
            } else {
                start[n] = t;
                end[n] = when;
                words[n++] = word;
            }
            t = when;
        }
        word ^= toggles[i].bit;
    }
    if (n > 0 && words[n - 1] == word) {
        end[n - 1] = T;
    } else {
        start[n] = t;
        end[n] = T;
        words[n++] = word;
    }
    PyObject *out = PyList_New(n);
    if (out == NULL) {
        return NULL;
    }
    for (int i = 0; i < n; i++) {
        PyObject *iv = Py_BuildValue("(ddl)", start[i], end[i], words[i]);
        if (iv == NULL) {
            Py_DECREF(out);
            return NULL;
        }
        PyList_SET_ITEM(out, i, iv);
    }
    return out;
}

/* After a fast interval: Network.set_driven(legs) if an interval went through the network since
 * the last one (no open phase on this path, so the legs are the phases' states). */
static void took_driven(period_args_t *pa, const int legs[3], int *net_dirty)
{
    if (*net_dirty) {
        configure(&pa->n, legs);
        pa->last = -1;
        *net_dirty = 0;
    }
}

PyDoc_STRVAR(fast_period_doc,
"fast_period(motor_k, cfg, kinds, last_legs, intervals, t0, T, y, h_max, acc, seg_t, seg_v0,\n"
"            slope, vdc, spm, vectors, bw, net_dirty) -> (y, kinds, last_legs, events, overflows,\n"
"            vdc, net_dirty)\n\n"
"Plant._intervals' loop on the fast path (an ideal link, no device drop, no open phase) when no\n"
"load knot falls in the period, operation by operation: a driven word's interval by the fast\n"
"RK4 (Plant._advance), an interval with an open leg whose diode conducts throughout as the\n"
"equivalent driven word (Plant._diode_interval), any other through the network (Network.begin\n"
"and integrate, as period() does); after a fast interval the network takes the driven legs\n"
"(Network.set_driven) if an interval through it came since the last time (net_dirty).\n"
"vectors: Plant._vectors, 64 entries; bw: the motor's and the load's damping.");

/* The fast path's extra inputs (fast_period's last arguments): the motor's surface-magnet flag,
 * Plant._vectors and the motor's and the load's damping. */
struct fast_path {
    int spm;
    PyObject *vectors;
    double bw;
};

/* The intervals of pa, one after the other: on the fast path (f not NULL) a driven word's
 * interval by the fast RK4 and an open leg whose diode conducts throughout as the equivalent
 * driven word, every other interval through the network (all of them when f is NULL). *ran
 * counts the network's intervals, *net_dirty says whether one came since the network last took
 * driven legs. 0, or -1 with an exception. */
static int run_intervals(period_args_t *pa, const struct fast_path *f, int *net_dirty, int *ran)
{
    net_t *n = &pa->n;
    double *y = pa->y;
    Py_ssize_t count = PyList_GET_SIZE(pa->intervals);
    for (Py_ssize_t i = 0; i < count; i++) {
        double a, b;
        long word;
        int legs[3];
        int got = period_interval(pa, i, &a, &b, &word, legs);
        if (got < 0) {
            return -1;
        }
        if (!got) {
            continue;
        }
        double ta = pa->t0 + a;
        double length = b - a;
        /* _load_segment(t0 + a) inside the segment that holds the whole period */
        double v0 = pa->seg_v0 + pa->slope * (ta - pa->seg_t);
        if (f != NULL) {
            double v[4];
            int driven[3];
            got = driven_vector(f->vectors, word, v, driven);
            if (got < 0) {
                return -1;
            }
            if (got) {
                if (fast_advance(&n->cfg, f->spm, y, v, length, pa->h_max, v0, pa->slope, f->bw, pa->acc) < 0) {
                    return -1;
                }
                took_driven(pa, driven, net_dirty);
                continue;
            }
            /* _diode_interval: every open leg's diode by its current's sign, tried as that word */
            double ia, ib;
            currents(&n->cfg, y[0], y[1], y[3], &ia, &ib);
            double cur[3] = {ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib};
            long equivalent = 0;
            int diode = 1;
            for (int x = 0; x < 3 && diode; x++) {
                int side = legs[x];
                if (side == K_O) {
                    if (cur[x] > ZERO_CURRENT_A) {
                        side = K_L;         /* current into the motor: low diode */
                    } else if (cur[x] < -ZERO_CURRENT_A) {
                        side = K_H;
                    } else {
                        diode = 0;          /* at zero: the network decides what follows */
                    }
                }
                equivalent |= side == K_H ? LEG_BITS[x][0] : LEG_BITS[x][1];
            }
            if (diode) {
                got = driven_vector(f->vectors, equivalent, v, driven);
                if (got < 0) {
                    return -1;
                }
                if (!got) {
                    PyErr_SetString(PyExc_ValueError, "fast_period: no vector for a driven word");
                    return -1;
                }
                double trial[5] = {y[0], y[1], y[2], y[3], y[4]};
                double part[3] = {0.0, 0.0, 0.0};
                if (fast_advance(&n->cfg, f->spm, trial, v, length, pa->h_max, v0, pa->slope, f->bw, part) < 0) {
                    return -1;
                }
                currents(&n->cfg, trial[0], trial[1], trial[3], &ia, &ib);
                double after[3] = {ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib};
                for (int x = 0; x < 3; x++) {
                    if (legs[x] == K_O && (after[x] > 0.0) != (cur[x] > 0.0)) {
                        diode = 0;
                    }
                }
                if (diode) {
                    memcpy(y, trial, sizeof trial);
                    for (int j = 0; j < 3; j++) {
                        pa->acc[j] += part[j];
                    }
                    took_driven(pa, driven, net_dirty);
                    continue;
                }
            }
        }
        if (network_interval(pa, a, b, v0, legs) < 0) {
            return -1;
        }
        *net_dirty = 1;
        (*ran)++;
    }
    return period_acc_back(pa);
}

static PyObject *mod_fast_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 18) {
        PyErr_SetString(PyExc_TypeError, "fast_period takes 18 arguments");
        return NULL;
    }
    period_args_t pa;
    if (period_args(args, "fast_period", &pa) < 0) {
        return NULL;
    }
    struct fast_path f;
    f.spm = PyObject_IsTrue(args[14]);
    f.vectors = args[15];
    int net_dirty = PyObject_IsTrue(args[17]);
    if (f.spm < 0 || net_dirty < 0 || get_double(args[16], &f.bw) < 0) {
        return NULL;
    }
    if (!PyList_Check(f.vectors) || PyList_GET_SIZE(f.vectors) != 64) {
        PyErr_SetString(PyExc_TypeError, "vectors must be a list of 64 entries");
        return NULL;
    }
    int ran = 0;
    if (run_intervals(&pa, &f, &net_dirty, &ran) < 0) {
        return NULL;
    }
    const net_t *n = &pa.n;
    return Py_BuildValue("[ddddd](iii)illdO", pa.y[0], pa.y[1], pa.y[2], pa.y[3], pa.y[4],
                         n->kinds[0], n->kinds[1], n->kinds[2], pa.last, n->events, n->overflows,
                         n->dc_link_v, net_dirty ? Py_True : Py_False);
}

PyDoc_STRVAR(settle_doc,
"settle(motor_k, cfg, kinds, t, y) -> (y, kinds, events)\n\n"
"Network.begin's projection and _settle: puts y on the constraint of the floating phases and\n"
"applies every turn-on condition that holds at t.");

static PyObject *mod_settle(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "settle takes 5 arguments");
        return NULL;
    }
    net_t n;
    memset(&n, 0, sizeof n);
    double t, y[5];
    int kinds[3];
    if (get_cfg(args[0], args[1], &n.cfg) < 0 || get_kinds(args[2], kinds) < 0 ||
        get_double(args[3], &t) < 0 || get_doubles(args[4], y, 5, "y") < 0) {
        return NULL;
    }
    configure(&n, kinds);
    if (n.nzero) {
        project(&n, y);
        settle(&n, t, y);
    }
    return Py_BuildValue("[ddddd](iii)l", y[0], y[1], y[2], y[3], y[4], n.kinds[0], n.kinds[1],
                         n.kinds[2], n.events);
}

/* The working state of one leg_period call, handed by pointer from step to step. */
typedef struct {
    int need[3];            /* legs whose current must keep its sign over the period */
    int nneed;
    double signs[3];        /* that sign (+1, -1; 0 for a leg that needs none) */
    double cur0[3];         /* phase currents at the period's start (A), once needed */
    int have_cur0;
    int h0;                 /* legs high at t = 0 (bit x: leg x) */
    double tog_t[MAX_TOG];  /* the legs' toggles: time (s) ... */
    int tog_b[MAX_TOG];     /* ... and the leg's bit */
    int ntog;
    piece_t pieces[MAX_TOG + 1];
    double edges[MAX_TOG + 2]; /* the pieces' start times (s), then T */
    int np;
    double ua_int, ub_int;  /* the period's integral of the stator voltage (V s) */
    int h_end;              /* the leg-high pattern at the period's end */
} leg_work_t;

/* The on-time (s) of a leg's high and low windows in *on; 0 when they overlap (a shoot-through
 * the constant-vector form does not model), else 1. */
static int leg_on_time(const double (*hi)[2], int nhi, const double (*lo)[2], int nlo,
                       double *on)
{
    double sum = 0.0;
    for (int i = 0; i < nhi; i++) {
        double a = hi[i][0], b = hi[i][1];
        sum += b - a;
        for (int k = 0; k < nlo; k++) {
            if (a < lo[k][1] && lo[k][0] < b) {
                return 0;
            }
        }
    }
    for (int k = 0; k < nlo; k++) {
        sum += lo[k][1] - lo[k][0];
    }
    *on = sum;
    return 1;
}

/* The gaps between a leg's low windows over [0, T] in high[]: where a leg with negative current
 * sits at the high rail through its upper diode. Returns their number. */
static int low_window_gaps(const double (*lo)[2], int nlo, double T, double high[][2])
{
    int nh = 0;
    double t = 0.0;
    for (int k = 0; k < nlo; k++) {
        if (lo[k][0] > t) {
            high[nh][0] = t;
            high[nh][1] = lo[k][0];
            nh++;
        }
        t = lo[k][1];
    }
    if (t < T) {
        high[nh][0] = t;
        high[nh][1] = T;
        nh++;
    }
    return nh;
}

/* Leg x conducts through a diode part of the period: notes the sign its current (at the
 * period's start) must keep. 0 when the form may not take it (a general motor, a current
 * within the knee), else 1. */
static int note_leg_sign(leg_work_t *w, const cfg_t *m, int spm, const double *st, int x,
                         double ud, double knee)
{
    if (!spm) {
        return 0;
    }
    if (!w->have_cur0) {
        double ia, ib;
        currents(m, st[0], st[1], st[3], &ia, &ib);
        w->cur0[0] = ia;
        w->cur0[1] = -0.5 * ia + S32 * ib;
        w->cur0[2] = -0.5 * ia - S32 * ib;
        w->have_cur0 = 1;
    }
    double ix = w->cur0[x];
    double thr = ud > 0.0 ? knee : 0.0;
    if (fabs(ix) <= thr + ZERO_CURRENT_A) {
        return 0;
    }
    w->signs[x] = ix > 0.0 ? 1.0 : -1.0;
    w->need[w->nneed++] = x;
    return 1;
}

/* The high windows' edges of one leg as toggles (an edge at 0 sets the leg high from the
 * start, one at T is no toggle). -1 when they do not fit, else 0. */
static int add_leg_toggles(leg_work_t *w, const double (*hi)[2], int nhi, double T, int bit)
{
    for (int i = 0; i < nhi; i++) {
        double a = hi[i][0], b = hi[i][1];
        if (w->ntog + 2 > MAX_TOG) {
            return -1;
        }
        if (a <= 0.0) {
            w->h0 |= bit;
        } else {
            w->tog_t[w->ntog] = a;
            w->tog_b[w->ntog++] = bit;
        }
        if (b < T) {
            w->tog_t[w->ntog] = b;
            w->tog_b[w->ntog++] = bit;
        }
    }
    return 0;
}

/* Every leg's toggles from its switch windows, with the signs the diode-conducting legs need.
 * 1, or 0 (not a constant-vector period), or -1 (too many edges). */
static int leg_toggles(leg_work_t *w, const cfg_t *m, int spm, double T,
                       double wins[6][MAX_WIN][2], const int nwin[6], double ud, double knee,
                       const double *st)
{
    for (int x = 0; x < 3; x++) {
        const double (*hi)[2] = (const double (*)[2])wins[2 * x];
        const double (*lo)[2] = (const double (*)[2])wins[2 * x + 1];
        int nhi = nwin[2 * x], nlo = nwin[2 * x + 1];
        double high[MAX_WIN + 1][2];
        double on;
        if (!leg_on_time(hi, nhi, lo, nlo, &on)) {
            return 0;
        }
        if (ud > 0.0 || on < T * (1.0 - 1e-12)) {
            if (!note_leg_sign(w, m, spm, st, x, ud, knee)) {
                return 0;
            }
            if (w->cur0[x] < 0.0) {
                nhi = low_window_gaps(lo, nlo, T, high);
                hi = (const double (*)[2])high;
            }
        }
        if (add_leg_toggles(w, hi, nhi, T, 1 << x) < 0) {
            return -1;
        }
    }
    return 1;
}

/* Sorts the toggles by (time, bit) as Python sorts the tuples (insertion sort: few, nearly
 * in order). */
static void sort_toggles(leg_work_t *w)
{
    for (int i = 1; i < w->ntog; i++) {
        double tt = w->tog_t[i];
        int bb = w->tog_b[i];
        int j = i - 1;
        while (j >= 0 && (w->tog_t[j] > tt || (w->tog_t[j] == tt && w->tog_b[j] > bb))) {
            w->tog_t[j + 1] = w->tog_t[j];
            w->tog_b[j + 1] = w->tog_b[j];
            j--;
        }
        w->tog_t[j + 1] = tt;
        w->tog_b[j + 1] = bb;
    }
}

/* The constant-vector pieces between the toggles: each one's length, stator voltage (the
 * leg pattern's vector at vdc plus the diode legs' drop) and DC-link current gain; the
 * voltage's integral over the period and the final leg pattern. */
static void build_pieces(leg_work_t *w, double T, double vdc, double ud)
{
    double off_a = -ud * (2.0 * w->signs[0] - w->signs[1] - w->signs[2]) / 3.0;
    double off_b = -ud * (w->signs[1] - w->signs[2]) / SQRT3;
    int np = 0, ne = 0;
    w->edges[ne++] = 0.0;
    double t = 0.0;
    int h = w->h0;
    double ua_int = 0.0, ub_int = 0.0;
    for (int i = 0; i <= w->ntog; i++) {
        double when = i < w->ntog ? w->tog_t[i] : T;
        if (i == w->ntog && !(t < T)) {
            break;
        }
        if (when > t || i == w->ntog) {
            /* _LEG_UNITS[h] */
            double ua = ((double)(2 * (h & 1)) - (double)(h >> 1 & 1) - (double)(h >> 2 & 1)) / 3.0;
            double ub = ((double)(h >> 1 & 1) - (double)(h >> 2 & 1)) / SQRT3;
            double ga = 0.0, gb = 0.0;
            for (int x = 0; x < 3; x++) {
                if (h >> x & 1) {
                    ga += AX[x][0];
                    gb += AX[x][1];
                }
            }
            double va = ua * vdc + off_a;
            double vb = ub * vdc + off_b;
            w->pieces[np].len = when - t;
            w->pieces[np].va = va;
            w->pieces[np].vb = vb;
            w->pieces[np].ga = ga;
            w->pieces[np].gb = gb;
            np++;
            ua_int += va * (when - t);
            ub_int += vb * (when - t);
            w->edges[ne++] = when;
            t = when;
        }
        if (i < w->ntog) {
            h ^= w->tog_b[i];
        }
    }
    w->np = np;
    w->ua_int = ua_int;
    w->ub_int = ub_int;
    w->h_end = h;
}

/* Plant._signs_hold: every diode leg's current kept its sign over the period, with the
 * bound on the straight line's error between the pieces' edges. 1 if so, else 0. */
static int signs_hold(const leg_work_t *w, const cfg_t *m, double lind, double T, double ud,
                      double knee, double vdc, const double y0[4], const double *st, double v0,
                      double slope, double bw)
{
    double ia, ib;
    currents(m, st[0], st[1], st[3], &ia, &ib);
    double cur1[3] = {ia, -0.5 * ia + S32 * ib, -0.5 * ia - S32 * ib};
    double u_max = 2.0 / 3.0 * (vdc + 2.0 * ud);
    double w_max = fabs(y0[2]) > fabs(st[2]) ? fabs(y0[2]) : fabs(st[2]);
    double ia0, ib0;
    currents(m, y0[0], y0[1], y0[3], &ia0, &ib0);
    double i0 = hypot(ia0, ib0), i1 = hypot(ia, ib);
    double i_max = i0 > i1 ? i0 : i1;
    i_max += T * (u_max + m->pole_pairs * w_max * m->flux_linkage_wb) / lind + 1e-3;
    double load_max = fabs(v0) + fabs(slope) * T;
    double alpha_e = m->pole_pairs * (m->torque_coeff * m->flux_linkage_wb * i_max + bw * w_max + load_max) * m->inv_inertia_per_kgm2;
    double we = m->pole_pairs * w_max + alpha_e * T;
    double bound = (m->resistance_ohm / lind * (u_max + m->resistance_ohm * i_max + we * m->flux_linkage_wb) +
                    (we * we + alpha_e) * m->flux_linkage_wb) * T * T / 8.0;
    double thr = lind * (ud > 0.0 ? knee : 0.0) + bound;
    const piece_t *pieces = w->pieces;
    for (int k = 0; k < w->nneed; k++) {
        int x = w->need[k];
        double ex0 = AX[x][0], ex1 = AX[x][1];
        double s = w->signs[x];
        double vx = 0.0, vx_end = 0.0;
        for (int i = 0; i < w->np; i++) {
            vx_end += (ex0 * pieces[i].va + ex1 * pieces[i].vb) * pieces[i].len;
        }
        double yy0 = lind * w->cur0[x];
        double dy = lind * cur1[x] - vx_end - yy0;
        for (int i = 0; i < w->np; i++) {
            if (s * (vx + yy0 + dy * w->edges[i] / T) <= thr) {
                return 0;
            }
            vx += (ex0 * pieces[i].va + ex1 * pieces[i].vb) * pieces[i].len;
        }
        if (s * lind * cur1[x] <= thr) {
            return 0;
        }
    }
    return 1;
}

/* Plant._leg_period's numerics from the windows on. Returns 0 (the period is not one the
 * constant-vector form may take: the caller uses the general network), 1 (done: st, out),
 * -1 (more edges than this code holds: the caller uses the Python version), -2 with an
 * exception (rk4_steps; st unchanged). */
static int leg_period(const cfg_t *m, double lind, int spm, double T, double wins[6][MAX_WIN][2],
                      const int nwin[6], double ud, double knee, double vdc, double *st,
                      double h_max, double v0, double slope, double bw, double *out, int *h_end)
{
    leg_work_t w;
    w.nneed = 0;
    w.signs[0] = w.signs[1] = w.signs[2] = 0.0;
    w.cur0[0] = w.cur0[1] = w.cur0[2] = 0.0;
    w.have_cur0 = 0;
    w.h0 = 0;
    w.ntog = 0;
    int r = leg_toggles(&w, m, spm, T, wins, nwin, ud, knee, st);
    if (r <= 0) {
        return r;
    }
    sort_toggles(&w);
    build_pieces(&w, T, vdc, ud);
    double y0[4] = {st[0], st[1], st[2], st[3]};
    double q;
    if (advance_pieces(m, spm, st, w.pieces, w.np, h_max, v0, slope, bw, &q) < 0) {
        memcpy(st, y0, sizeof y0);
        return -2;
    }
    if (w.nneed && !signs_hold(&w, m, lind, T, ud, knee, vdc, y0, st, v0, slope, bw)) {
        memcpy(st, y0, sizeof y0);
        return 0;
    }
    out[0] = w.ua_int;
    out[1] = w.ub_int;
    out[2] = q;
    *h_end = w.h_end;
    return 1;
}

PyDoc_STRVAR(leg_period_doc,
"leg_period(motor_k, ld, spm, T, windows, ud, knee, vdc, state, h_max, v0, slope, bw)\n"
"    -> None | False | (pa, pb, w, th, u_alpha_int, u_beta_int, idc_int, h)\n\n"
"Plant._leg_period from the switch windows (6 lists of (on, off) pairs) on: False when the\n"
"period cannot be taken as constant-vector pieces (the general network takes it), None when\n"
"it has more edges than the C code holds (the Python version takes it), else the end state\n"
"(state: pa, pb, w, th), the period's integrals and the final leg-high pattern.");

static PyObject *mod_leg_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 13) {
        PyErr_SetString(PyExc_TypeError, "leg_period takes 13 arguments");
        return NULL;
    }
    double k[8];
    cfg_t m;
    memset(&m, 0, sizeof m);
    if (get_doubles(args[0], k, 8, "motor constants") < 0) {
        return NULL;
    }
    motor_constants(&m, k);
    double ld;
    if (get_double(args[1], &ld) < 0) {
        return NULL;
    }
    int spm = PyObject_IsTrue(args[2]);
    if (spm < 0) {
        return NULL;
    }
    double T, ud, knee, vdc, st[4], h_max, v0, slope, bw;
    if (get_double(args[3], &T) < 0 || get_double(args[5], &ud) < 0 ||
        get_double(args[6], &knee) < 0 || get_double(args[7], &vdc) < 0 ||
        get_doubles(args[8], st, 4, "state") < 0 || get_double(args[9], &h_max) < 0 ||
        get_double(args[10], &v0) < 0 || get_double(args[11], &slope) < 0 ||
        get_double(args[12], &bw) < 0) {
        return NULL;
    }
    PyObject *windows = args[4];
    if (!PyList_Check(windows) || PyList_GET_SIZE(windows) != 6) {
        PyErr_SetString(PyExc_TypeError, "windows must be a list of 6 lists");
        return NULL;
    }
    double wins[6][MAX_WIN][2];
    int nwin[6];
    for (int j = 0; j < 6; j++) {
        PyObject *lst = PyList_GET_ITEM(windows, j);
        if (!PyList_Check(lst)) {
            PyErr_SetString(PyExc_TypeError, "windows must be a list of 6 lists");
            return NULL;
        }
        Py_ssize_t nw = PyList_GET_SIZE(lst);
        if (nw > MAX_WIN) {
            Py_RETURN_NONE;
        }
        nwin[j] = (int)nw;
        for (Py_ssize_t i = 0; i < nw; i++) {
            if (get_doubles(PyList_GET_ITEM(lst, i), wins[j][i], 2, "a switch window") < 0) {
                return NULL;
            }
        }
    }
    double out[3];
    int h_end = 0;
    int r = leg_period(&m, ld, spm, T, wins, nwin, ud, knee, vdc, st, h_max, v0, slope, bw, out,
                       &h_end);
    if (r == -2) {
        return NULL;
    }
    if (r < 0) {
        Py_RETURN_NONE;
    }
    if (r == 0) {
        Py_RETURN_FALSE;
    }
    return Py_BuildValue("(ddddddd i)", st[0], st[1], st[2], st[3], out[0], out[1], out[2], h_end);
}

PyDoc_STRVAR(advance_doc,
"advance(motor_k, spm, pa, pb, w, th, va, vb, h, n, tl0, tl_slope, bw) -> (pa, pb, w, th)\n\n"
"MotorModel.advance: n RK4 steps of length h at the constant stator voltage (va, vb), load\n"
"torque tl0 + tl_slope t + bw w.");

static PyObject *mod_advance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 13) {
        PyErr_SetString(PyExc_TypeError, "advance takes 13 arguments");
        return NULL;
    }
    double k[8], f[11];
    cfg_t m;
    memset(&m, 0, sizeof m);
    if (get_doubles(args[0], k, 8, "motor constants") < 0) {
        return NULL;
    }
    int spm = PyObject_IsTrue(args[1]);
    if (spm < 0) {
        return NULL;
    }
    for (int i = 0; i < 11; i++) {
        if (i == 7) { /* n */
            continue;
        }
        if (get_double(args[2 + i], &f[i]) < 0) {
            return NULL;
        }
    }
    long n = PyLong_AsLong(args[9]);
    if (n == -1 && PyErr_Occurred()) {
        return NULL;
    }
    motor_constants(&m, k);
    double st[4] = {f[0], f[1], f[2], f[3]};
    if (spm) {
        advance_spm(&m, st, f[4], f[5], f[6], n, f[8], f[9], f[10]);
    } else {
        advance_general(&m, st, f[4], f[5], f[6], n, f[8], f[9], f[10]);
    }
    return Py_BuildValue("(dddd)", st[0], st[1], st[2], st[3]);
}

/* rise[j] as Python keeps it: None (commanded off) or the time of the last rising edge. */
static int rise_get(PyObject *rise, int j, int *has, double *r)
{
    PyObject *o = PyList_GET_ITEM(rise, j);
    if (o == Py_None) {
        *has = 0;
        *r = 0.0;
        return 0;
    }
    *has = 1;
    return get_double(o, r);
}

static int rise_set(PyObject *rise, int j, int has, double r)
{
    PyObject *o;
    if (has) {
        o = PyFloat_FromDouble(r);
        if (o == NULL) {
            return -1;
        }
    } else {
        o = Py_None;
        Py_INCREF(o);
    }
    return PyList_SetItem(rise, j, o); /* steals o */
}

static int int_in(PyObject *o, long long lo, long long hi, long long *out);

/* SwitchTimeline._duty_windows on arrays: per switch j its on-intervals wins[j][0..nwin[j]-1]
 * for the duties `duty` with the leg enables `legs` (no delay in play); the dead-time memory
 * rise (has[j]: not None, r[j]: its value) is read and updated as the Python code does. A
 * floated leg has no window and forgets its rises. */
static void duty_windows_c(double T, double td, const double duty[3], long legs, int has[6], double r[6],
                           double wins[6][MAX_WIN][2], int nwin[6])
{
    for (int x = 0; x < 3; x++) {
        double d = duty[x];
        int jh = 2 * x, jl = 2 * x + 1;
        double a;
        nwin[jh] = 0;
        nwin[jl] = 0;
        if (!(legs >> x & 1)) {
            has[jh] = 0;
            r[jh] = 0.0;
            has[jl] = 0;
            r[jl] = 0.0;
            continue;
        }
        if (d >= 1.0 || d <= 0.0) {
            int jon = d >= 1.0 ? jh : jl, joff = d >= 1.0 ? jl : jh;
            double rr = r[jon];
            int hh = has[jon];
            if (!hh) {
                a = td;
            } else {
                double z = rr + td;
                a = 0.0 > z ? 0.0 : z;
            }
            if (a < T) {
                wins[jon][0][0] = a;
                wins[jon][0][1] = T;
                nwin[jon] = 1;
            }
            has[jon] = 1;
            r[jon] = (hh ? rr : 0.0) - T;
            has[joff] = 0;
            r[joff] = 0.0;
            continue;
        }
        double t_on = 0.5 * T * (1.0 - d);
        double t_off = 0.5 * T * (1.0 + d);
        a = t_on + td;
        if (a < t_off) {
            wins[jh][0][0] = a;
            wins[jh][0][1] = t_off;
            nwin[jh] = 1;
        }
        has[jh] = 0;
        r[jh] = 0.0;
        if (!has[jl]) {
            a = td;
        } else {
            double z = r[jl] + td;
            a = 0.0 > z ? 0.0 : z;
        }
        if (a < t_on) {
            wins[jl][nwin[jl]][0] = a;
            wins[jl][nwin[jl]][1] = t_on;
            nwin[jl]++;
        }
        a = t_off + td;
        if (a < T) {
            wins[jl][nwin[jl]][0] = a;
            wins[jl][nwin[jl]][1] = T;
            nwin[jl]++;
        }
        has[jl] = 1;
        r[jl] = t_off - T;
    }
}

/* The six windows as Python builds them: a list of 6 lists of (on, off) tuples. */
static PyObject *windows_list(double wins[6][MAX_WIN][2], const int nwin[6])
{
    PyObject *out = PyList_New(6);
    if (out == NULL) {
        return NULL;
    }
    for (int j = 0; j < 6; j++) {
        PyObject *lst = PyList_New(nwin[j]);
        if (lst == NULL) {
            Py_DECREF(out);
            return NULL;
        }
        PyList_SET_ITEM(out, j, lst);
        for (int i = 0; i < nwin[j]; i++) {
            PyObject *w = Py_BuildValue("(dd)", wins[j][i][0], wins[j][i][1]);
            if (w == NULL) {
                Py_DECREF(out);
                return NULL;
            }
            PyList_SET_ITEM(lst, i, w);
        }
    }
    return out;
}

/* Writes the dead-time memory back into the list rise (None or a float per switch). */
static int rise_store(PyObject *rise, const int has[6], const double r[6])
{
    for (int j = 0; j < 6; j++) {
        if (!has[j] && PyList_GET_ITEM(rise, j) == Py_None) {
            continue;
        }
        if (rise_set(rise, j, has[j], r[j]) < 0) {
            return -1;
        }
    }
    return 0;
}

PyDoc_STRVAR(duty_windows_doc,
"duty_windows(T, dead_time, duty, rise[, legs]) -> [[(on, off), ...] x 6]\n\n"
"SwitchTimeline._duty_windows: per switch its on-intervals in [0, T) for a duty command with\n"
"no delay in play, turn-on edges delayed by the dead time; updates the list rise (6 items,\n"
"None or the time of the command's last rising edge) in place. legs: the leg enables (bit x\n"
"= leg x, default 7); a floated leg has no window.");

static PyObject *mod_duty_windows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 4 && nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "duty_windows takes 4 or 5 arguments");
        return NULL;
    }
    double T, td, duty[3];
    if (get_double(args[0], &T) < 0 || get_double(args[1], &td) < 0 ||
        get_doubles(args[2], duty, 3, "duty") < 0) {
        return NULL;
    }
    long long legs = 7;
    if (nargs == 5 && !int_in(args[4], 0, 7, &legs)) {
        PyErr_SetString(PyExc_ValueError, "duty_windows: legs must be an int 0..7");
        return NULL;
    }
    PyObject *rise = args[3];
    if (!PyList_Check(rise) || PyList_GET_SIZE(rise) != 6) {
        PyErr_SetString(PyExc_TypeError, "rise must be a list of 6 items");
        return NULL;
    }
    int has[6], nwin[6];
    double r[6], wins[6][MAX_WIN][2];
    for (int j = 0; j < 6; j++) {
        if (rise_get(rise, j, &has[j], &r[j]) < 0) {
            return NULL;
        }
    }
    duty_windows_c(T, td, duty, (long)legs, has, r, wins, nwin);
    PyObject *out = windows_list(wins, nwin);
    if (out == NULL || rise_store(rise, has, r) < 0) {
        Py_XDECREF(out);
        return NULL;
    }
    return out;
}

/* ------------------------------------------------------------------ sample and truth
 *
 * Plant.sample() (with Sensors.read and sensors._code) and Plant.truth() for the plain case:
 * no open phase, some current flowing (not _zero_current), every ADC channel and the encoder
 * on their plain path (_plain), the load not locked, no noise buffer exhausted. Anything else,
 * and any value the Python code would raise on (a non-finite angle or code), makes the
 * function return None without changing anything: the caller then runs the Python code, the
 * reference (and the noise buffers' refill, GaussianNoise.block, stays there).
 *
 * The sensors, the motor and the load are __slots__ objects; their slots are read at the
 * offsets of the classes' member descriptors, looked up once per class (a module-level cache
 * holding the class: the one state kept between calls) and used only for an object of
 * exactly that class, which must define the slots itself (a subclass runs the Python code).
 * math.hypot is called as it is (its algorithm is CPython's own, not libm's hypot). */

#include <structmember.h>

#ifndef Py_T_OBJECT_EX
#define Py_T_OBJECT_EX T_OBJECT_EX
#endif

#define MAX_SLOTS 8

typedef struct {
    PyTypeObject *type;     /* the class bound (a strong reference), or NULL */
    int ok;                 /* 1: every name is a plain slot of it, at off[] */
    const char *names[MAX_SLOTS];
    Py_ssize_t off[MAX_SLOTS];
} layout_t;

enum { SE_I1, SE_I2, SE_VDC, SE_ENC, SE_OC, SE_OV, SE_PAIR };
static layout_t L_SENSORS = {NULL, 0, {"i1", "i2", "vdc", "encoder", "overcurrent_trip_a",
                                       "overvoltage_trip_v", "_pair", NULL}, {0}};
enum { CH_BASE, CH_SCALE, CH_SD, CH_I, CH_BUF, CH_PLAIN, CH_TOP };
static layout_t L_ADC = {NULL, 0, {"_base", "_scale", "noise_rms_counts", "_i", "_buf", "_plain",
                                   "_top", NULL}, {0}};
enum { EN_PLAIN, EN_CPR, EN_OFFSET, EN_BITS };
static layout_t L_ENC = {NULL, 0, {"_plain", "counts_per_rev", "_offset", "counter_bits", NULL,
                                   NULL, NULL, NULL}, {0}};
enum { MO_P, MO_PSIM, MO_ILD, MO_ILQ, MO_KT, MO_LD, MO_LQ };
static layout_t L_MOTOR = {NULL, 0, {"p", "psim", "ild", "ilq", "kt", "ld", "lq", NULL}, {0}};
enum { LO_LOCKED, LO_T, LO_V, LO_KW };
static layout_t L_LOAD = {NULL, 0, {"locked", "_t", "_v", "kw", NULL, NULL, NULL, NULL}, {0}};

/* 1 when obj's class is bound (binding it now if it is new), 0 when its attributes are not
 * all plain slots (no error set), -1 on an error. */
static int bind_type(layout_t *lay, PyTypeObject *tp)
{
    if (lay->type == tp) {
        return lay->ok;
    }
    Py_ssize_t off[MAX_SLOTS];
    int ok = 1;
    for (int i = 0; i < MAX_SLOTS && lay->names[i] != NULL && ok; i++) {
        PyObject *d = PyObject_GetAttrString((PyObject *)tp, lay->names[i]);
        if (d == NULL) {
            if (!PyErr_ExceptionMatches(PyExc_AttributeError)) {
                return -1;
            }
            PyErr_Clear();
            ok = 0;
            break;
        }
        if (Py_IS_TYPE(d, &PyMemberDescr_Type)) {
            PyMemberDescrObject *md = (PyMemberDescrObject *)d;
            /* the class's own slot: a subclass (which might override a method the Python
             * code calls, MotorModel.currents, Load.torque...) runs the Python code */
            ok = md->d_member->type == Py_T_OBJECT_EX && PyDescr_TYPE(md) == tp;
            off[i] = md->d_member->offset;
        } else {
            ok = 0;
        }
        Py_DECREF(d);
    }
    Py_INCREF(tp);
    Py_XSETREF(lay->type, tp);
    lay->ok = ok;
    if (ok) {
        memcpy(lay->off, off, sizeof off);
    }
    return ok;
}

static int bind(layout_t *lay, PyObject *obj)
{
    return bind_type(lay, Py_TYPE(obj));
}

/* A bound slot's value (borrowed; NULL when unset). */
static inline PyObject *slot(const layout_t *lay, PyObject *obj, int i)
{
    return *(PyObject **)((char *)obj + lay->off[i]);
}

#define EXACT_INT_LIMIT 4503599627370496.0 /* 2^52 */

/* A float, or an int small enough that Python's mixed int/float operations on it give what
 * the same operations on its double give: 1 with *out set, else 0 (no error set). */
static inline int num(PyObject *o, double *out)
{
    if (o == NULL) {
        return 0;
    }
    if (PyFloat_CheckExact(o)) {
        *out = PyFloat_AS_DOUBLE(o);
        return 1;
    }
    if (PyLong_CheckExact(o)) {
        int overflow;
        long long v = PyLong_AsLongLongAndOverflow(o, &overflow);
        if (overflow || v > (long long)EXACT_INT_LIMIT || v < -(long long)EXACT_INT_LIMIT) {
            return 0;
        }
        *out = (double)v;
        return 1;
    }
    if (PyFloat_Check(o)) {     /* a subclass (numpy.float64): the same IEEE operations */
        *out = PyFloat_AS_DOUBLE(o);
        return 1;
    }
    return 0;
}

/* An int in [lo, hi]: 1 with *out set, else 0 (no error set). */
static int int_in(PyObject *o, long long lo, long long hi, long long *out)
{
    if (o == NULL || !PyLong_CheckExact(o)) {
        return 0;
    }
    int overflow;
    long long v = PyLong_AsLongLongAndOverflow(o, &overflow);
    if (overflow || v < lo || v > hi) {
        return 0;
    }
    *out = v;
    return 1;
}

/* sensors._code on the plain path: 1 with the code (and the noise index to store, or -1 when
 * no draw was taken), 0 when the Python code must run. */
static int adc_code(PyObject *ch, double value, long long *code, Py_ssize_t *i_next)
{
    const layout_t *a = &L_ADC;
    double base, scale, sd;
    long long top;
    if (slot(a, ch, CH_PLAIN) != Py_True || !num(slot(a, ch, CH_BASE), &base)
        || !num(slot(a, ch, CH_SCALE), &scale) || !num(slot(a, ch, CH_SD), &sd)
        || !int_in(slot(a, ch, CH_TOP), 0, (long long)EXACT_INT_LIMIT, &top)) {
        return 0;
    }
    double x = base + scale * value;
    *i_next = -1;
    if (sd != 0.0) {    /* Python's "if sd:" (NaN is true) */
        long long i;
        PyObject *buf = slot(a, ch, CH_BUF);
        if (!int_in(slot(a, ch, CH_I), 0, PY_SSIZE_T_MAX - 1, &i) || buf == NULL
            || !PyList_CheckExact(buf) || i >= PyList_GET_SIZE(buf)) {
            return 0;   /* also the refill (GaussianNoise.block), left to Python */
        }
        PyObject *draw = PyList_GET_ITEM(buf, (Py_ssize_t)i);
        if (!PyFloat_CheckExact(draw)) {
            return 0;
        }
        x += sd * PyFloat_AS_DOUBLE(draw);
        *i_next = (Py_ssize_t)i + 1;
    }
    double y = x + 0.5;
    if (!isfinite(y)) {
        return 0;       /* int() raises */
    }
    double t = trunc(y);    /* int() truncates towards zero */
    *code = t < 0.0 ? 0 : t > (double)top ? top : (long long)t;
    return 1;
}

/* Stores an advanced noise index (a new reference to index is taken over). */
static void put_index(PyObject *ch, PyObject *index)
{
    PyObject **p = (PyObject **)((char *)ch + L_ADC.off[CH_I]);
    Py_XSETREF(*p, index);
}

#define STATUS_OVERCURRENT 0x02
#define STATUS_OVERVOLTAGE 0x04
static double INV_2PI, TWO_PI, PI_, RPM_PER_RAD_S;
static PyObject *MATH_HYPOT;

PyDoc_STRVAR(sample_doc,
"sample(sensors, motor, sample_type, period, pa, pb, th, revs, vdc, flags) -> sample or None\n\n"
"Plant.sample's reading (Sensors.read) when no open phase and current flows, for plain\n"
"sensors and noise buffers that need no refill; None (nothing changed) otherwise: then run\n"
"the Python code. Advances the channels' noise indices as Python does.");

static PyObject *mod_sample(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 10) {
        PyErr_SetString(PyExc_TypeError, "sample takes 10 arguments");
        return NULL;
    }
    PyObject *sensors = args[0], *motor = args[1], *period = args[3];
    PyTypeObject *stype = (PyTypeObject *)args[2];
    if (!PyType_Check(args[2]) || !PyType_IsSubtype(stype, &PyTuple_Type)) {
        PyErr_SetString(PyExc_TypeError, "sample_type must be a tuple type");
        return NULL;
    }
    int r;
    if ((r = bind(&L_SENSORS, sensors)) <= 0 || (r = bind(&L_MOTOR, motor)) <= 0) {
        goto python;
    }
    PyObject *ch[3] = {slot(&L_SENSORS, sensors, SE_I1), slot(&L_SENSORS, sensors, SE_I2),
                       slot(&L_SENSORS, sensors, SE_VDC)};
    PyObject *enc = slot(&L_SENSORS, sensors, SE_ENC);
    PyObject *pair = slot(&L_SENSORS, sensors, SE_PAIR);
    for (int j = 0; j < 3; j++) {
        if (ch[j] == NULL || (r = bind(&L_ADC, ch[j])) <= 0) {
            goto python;
        }
    }
    if (enc == NULL || (r = bind(&L_ENC, enc)) <= 0) {
        goto python;
    }
    double p, psim, ild, ilq, pa, pb, th, vdc, oc, ov;
    long long revs, flags, x, y, cpr, offset, bits;
    if (!num(slot(&L_MOTOR, motor, MO_P), &p) || !num(slot(&L_MOTOR, motor, MO_PSIM), &psim)
        || !num(slot(&L_MOTOR, motor, MO_ILD), &ild) || !num(slot(&L_MOTOR, motor, MO_ILQ), &ilq)
        || !num(slot(&L_SENSORS, sensors, SE_OC), &oc)
        || !num(slot(&L_SENSORS, sensors, SE_OV), &ov)
        || !num(args[4], &pa) || !num(args[5], &pb) || !PyFloat_Check(args[6])
        || !num(args[8], &vdc)
        || !int_in(args[7], -(1LL << 31), 1LL << 31, &revs)
        || !int_in(args[9], LONG_MIN, LONG_MAX, &flags)
        || pair == NULL || !PyTuple_CheckExact(pair) || PyTuple_GET_SIZE(pair) != 2
        || !int_in(PyTuple_GET_ITEM(pair, 0), LLONG_MIN, LLONG_MAX, &x)
        || !int_in(PyTuple_GET_ITEM(pair, 1), LLONG_MIN, LLONG_MAX, &y)
        || slot(&L_ENC, enc, EN_PLAIN) != Py_True
        || !int_in(slot(&L_ENC, enc, EN_CPR), -(1LL << 31), 1LL << 31, &cpr)
        || !int_in(slot(&L_ENC, enc, EN_OFFSET), -(1LL << 60), 1LL << 60, &offset)
        || !int_in(slot(&L_ENC, enc, EN_BITS), 0, 62, &bits)) {
        goto python;
    }
    th = PyFloat_AS_DOUBLE(args[6]);
    /* Plant.sample: the currents */
    double e = p * th;
    if (!isfinite(e)) {
        goto python;    /* math.cos raises on an infinity (and a NaN makes int() raise) */
    }
    double i[4];
    currents_at(e, psim, ild, ilq, pa, pb, i);
    double ia = i[0], ib = i[1];
    /* Sensors.read */
    double i_a = ia;
    double i_b = -0.5 * ia + S32 * ib;
    double i_c = -0.5 * ia - S32 * ib;
    long status = (long)flags;
    if (!(-oc <= i_a && i_a <= oc && -oc <= i_b && i_b <= oc && -oc <= i_c && i_c <= oc)) {
        status |= STATUS_OVERCURRENT;
    }
    if (vdc > ov) {
        status |= STATUS_OVERVOLTAGE;
    }
    long long code[3];
    Py_ssize_t next[3];
    if (!adc_code(ch[0], x == 0 ? i_a : i_b, &code[0], &next[0])
        || !adc_code(ch[1], y == 1 ? i_b : i_c, &code[1], &next[1])
        || !adc_code(ch[2], vdc, &code[2], &next[2])) {
        goto python;
    }
    /* the encoder: position = revs cpr + floor(theta_m cpr / 2 pi) */
    double fl = floor(th * (double)cpr * INV_2PI);
    if (!(fabs(fl) <= EXACT_INT_LIMIT)) {
        goto python;    /* floor raises on an infinity or NaN */
    }
    long long position = revs * cpr + (long long)fl;
    unsigned long long mask = (1ULL << bits) - 1ULL;
    long long count = (long long)((unsigned long long)(position + offset) & mask);
    /* the new objects first, then the channels' indices (nothing changes on an error) */
    PyObject *out = stype->tp_alloc(stype, 6);
    PyObject *idx[3] = {NULL, NULL, NULL};
    if (out == NULL) {
        return NULL;
    }
    Py_INCREF(period);
    PyTuple_SET_ITEM(out, 0, period);
    PyObject *items[5] = {PyLong_FromLongLong(code[0]), PyLong_FromLongLong(code[1]),
                          PyLong_FromLongLong(code[2]), PyLong_FromLongLong(count),
                          PyLong_FromLong(status)};
    int failed = 0;
    for (int j = 0; j < 5; j++) {
        failed |= items[j] == NULL;
        PyTuple_SET_ITEM(out, 1 + j, items[j]);     /* a NULL item is fine for the DECREF */
    }
    for (int j = 0; j < 3; j++) {
        if (next[j] >= 0) {
            idx[j] = PyLong_FromSsize_t(next[j]);
            failed |= idx[j] == NULL;
        }
    }
    if (failed) {
        Py_DECREF(out);
        for (int j = 0; j < 3; j++) {
            Py_XDECREF(idx[j]);
        }
        return NULL;
    }
    for (int j = 0; j < 3; j++) {
        if (idx[j] != NULL) {
            put_index(ch[j], idx[j]);
        }
    }
    return out;
python:
    if (r < 0) {
        return NULL;
    }
    Py_RETURN_NONE;
}

/* Load.profile(t): 1 with *out set, else 0 (not two float lists of the same length, or a
 * division by zero). */
static int load_profile_at(PyObject *ts, PyObject *vs, double t, double *out)
{
    if (ts == NULL || vs == NULL || !PyList_CheckExact(ts) || !PyList_CheckExact(vs)) {
        return 0;
    }
    Py_ssize_t n = PyList_GET_SIZE(ts);
    if (n == 0 || PyList_GET_SIZE(vs) != n) {
        return 0;
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        if (!PyFloat_Check(PyList_GET_ITEM(ts, j)) || !PyFloat_Check(PyList_GET_ITEM(vs, j))) {
            return 0;
        }
    }
#define AT(lst, j) PyFloat_AS_DOUBLE(PyList_GET_ITEM((lst), (j)))
    /* bisect.bisect_right(ts, t) */
    Py_ssize_t lo = 0, hi = n;
    while (lo < hi) {
        Py_ssize_t mid = (Py_ssize_t)(((size_t)lo + (size_t)hi) / 2);
        if (t < AT(ts, mid)) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    if (lo == 0) {
        *out = AT(vs, 0);
        return 1;
    }
    if (lo == n) {
        *out = AT(vs, n - 1);
        return 1;
    }
    double t0 = AT(ts, lo - 1), t1 = AT(ts, lo);
    double dt = t1 - t0;
    if (dt == 0.0) {
        return 0;
    }
    *out = AT(vs, lo - 1) + (AT(vs, lo) - AT(vs, lo - 1)) * (t - t0) / dt;
#undef AT
    return 1;
}

PyDoc_STRVAR(truth_doc,
"truth(motor, load, period, T, pa, pb, th, w, vdc, idc_int, u_int) -> tuple or None\n\n"
"Plant.truth's record (TRUTH_FIELDS) when no open phase and current flows and the load is\n"
"not locked; None otherwise: then run the Python code.");

static PyObject *mod_truth(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 11) {
        PyErr_SetString(PyExc_TypeError, "truth takes 11 arguments");
        return NULL;
    }
    PyObject *motor = args[0], *load = args[1], *u_int = args[10];
    int r;
    if ((r = bind(&L_MOTOR, motor)) <= 0 || (r = bind(&L_LOAD, load)) <= 0) {
        goto python;
    }
    double p, psim, ild, ilq, kt, ld, lq, kw, T, pa, pb, th, w, vdc, idc, u0, u1;
    long long period;
    if (!num(slot(&L_MOTOR, motor, MO_P), &p) || !num(slot(&L_MOTOR, motor, MO_PSIM), &psim)
        || !num(slot(&L_MOTOR, motor, MO_ILD), &ild) || !num(slot(&L_MOTOR, motor, MO_ILQ), &ilq)
        || !num(slot(&L_MOTOR, motor, MO_KT), &kt) || !num(slot(&L_MOTOR, motor, MO_LD), &ld)
        || !num(slot(&L_MOTOR, motor, MO_LQ), &lq)
        || slot(&L_LOAD, load, LO_LOCKED) != Py_False || !num(slot(&L_LOAD, load, LO_KW), &kw)
        || !int_in(args[2], -(long long)EXACT_INT_LIMIT, (long long)EXACT_INT_LIMIT, &period)
        || !PyFloat_Check(args[3]) || !num(args[4], &pa) || !num(args[5], &pb)
        || !num(args[6], &th) || !num(args[7], &w) || !num(args[8], &vdc) || !num(args[9], &idc)
        || !PyTuple_CheckExact(u_int) || PyTuple_GET_SIZE(u_int) != 2
        || !num(PyTuple_GET_ITEM(u_int, 0), &u0) || !num(PyTuple_GET_ITEM(u_int, 1), &u1)) {
        goto python;
    }
    T = PyFloat_AS_DOUBLE(args[3]);
    double e = p * th;
    if (!isfinite(e) || T == 0.0) {
        goto python;    /* math.cos and math.remainder raise on an infinity, x / 0 raises */
    }
    double i[4];
    currents_at(e, psim, ild, ilq, pa, pb, i);
    double ia = i[0], ib = i[1], i_d = i[2], i_q = i[3];
    double t = (double)period * T;
    /* MotorModel.torque */
    double te = kt * (psim * i_q + (ld - lq) * i_d * i_q);
    /* Load.torque */
    double prof;
    if (!load_profile_at(slot(&L_LOAD, load, LO_T), slot(&L_LOAD, load, LO_V), t, &prof)) {
        goto python;
    }
    double tl = prof + kw * w;
    /* wrap_angle(p th): math.remainder is exact, as C's remainder */
    double wr = remainder(e, TWO_PI);
    if (wr == -PI_) {
        wr = PI_;
    }
    PyObject *hyp_args[2] = {args[4], args[5]};
    PyObject *hyp = PyObject_Vectorcall(MATH_HYPOT, hyp_args, 2, NULL);
    if (hyp == NULL) {
        return NULL;
    }
    PyObject *out = PyTuple_New(19);
    if (out == NULL) {
        Py_DECREF(hyp);
        return NULL;
    }
    PyObject *ia_o = PyFloat_FromDouble(ia);
    Py_XINCREF(ia_o);
    PyObject *items[19] = {
        PyFloat_FromDouble(t), ia_o, PyFloat_FromDouble(-0.5 * ia + S32 * ib),
        PyFloat_FromDouble(-0.5 * ia - S32 * ib), ia_o, PyFloat_FromDouble(ib),
        Py_NewRef(args[4]), Py_NewRef(args[5]), hyp, PyFloat_FromDouble(te), Py_NewRef(args[7]),
        PyFloat_FromDouble(w * RPM_PER_RAD_S), PyFloat_FromDouble(wr), Py_NewRef(args[6]),
        Py_NewRef(args[8]), PyFloat_FromDouble(idc / T), PyFloat_FromDouble(tl),
        PyFloat_FromDouble(u0 / T), PyFloat_FromDouble(u1 / T)};
    int failed = 0;
    for (int j = 0; j < 19; j++) {
        failed |= items[j] == NULL;
        PyTuple_SET_ITEM(out, j, items[j]);
    }
    if (failed) {
        Py_DECREF(out);
        return NULL;
    }
    return out;
python:
    if (r < 0) {
        return NULL;
    }
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------ a duty period in one call
 *
 * Plant.step's DUTY period on the leg-window path: SwitchTimeline.switch_windows (the dead-time
 * memory included) and Plant._leg_period in one call, so that Python only stores the result.
 * Every operation is the Python code's (and the kernel's duty_windows and leg_period), in the
 * same order. */

/* Command.edges(j, T) of a command given as its gate word (duty NULL) or its duties and leg
 * enables: the switch's state at 0+ in *state0, the number of toggle times (0 or 2) put in e. */
static int cmd_edges(long gates, const double *duty, long legs, int j, double T, int *state0, double e[2])
{
    int leg = j / 2, low = j % 2;
    if (duty == NULL) {
        *state0 = (gates & LEG_BITS[leg][low]) != 0;
        return 0;
    }
    if (!(legs >> leg & 1)) {
        *state0 = 0; /* a floated leg: both switches off all period */
        return 0;
    }
    double d = duty[leg];
    if (d <= 0.0) {
        *state0 = low;
        return 0;
    }
    if (d >= 1.0) {
        *state0 = !low;
        return 0;
    }
    *state0 = low;
    e[0] = 0.5 * T * (1.0 - d);
    e[1] = 0.5 * T * (1.0 + d);
    return 2;
}

/* SwitchTimeline.switch_windows' general loop (a computation delay splits the period between
 * the old command and the new duty command). At most 5 toggles per switch, so at most 3
 * windows. */
static void switch_windows_c(double T, double delay_s, double td, long old_gates,
                             const double *old_duty, long old_legs, const double duty[3], long legs,
                             int has[6], double r[6], double wins[6][MAX_WIN][2], int nwin[6])
{
    double delay = T < delay_s ? T : delay_s;
    for (int j = 0; j < 6; j++) {
        double oe[2], ne[2], tog[8];
        int s0, ns0, nt = 0, start;
        int no = cmd_edges(old_gates, old_duty, old_legs, j, T, &s0, oe);
        int nn = cmd_edges(0, duty, legs, j, T, &ns0, ne);
        if (delay > 0.0) {
            start = s0;
            for (int i = 0; i < no; i++) {
                if (oe[i] < delay) {
                    tog[nt++] = oe[i];
                }
            }
            int at_delay = s0 ^ (nt % 2 == 1);
            int count = 0;
            for (int i = 0; i < nn; i++) {
                count += ne[i] <= delay;
            }
            int new_at_delay = ns0 ^ (count % 2 == 1);
            if (delay < T && at_delay != new_at_delay) {
                tog[nt++] = delay;
            }
            for (int i = 0; i < nn; i++) {
                if (delay < ne[i] && ne[i] < T) {
                    tog[nt++] = ne[i];
                }
            }
        } else {
            start = ns0;
            for (int i = 0; i < nn; i++) {
                tog[nt++] = ne[i];
            }
        }
        /* _drop_glitches */
        double min_width = 1e-9 * T, kept[8];
        int nk = 0;
        for (int i = 0; i < nt; i++) {
            if (nk && tog[i] - kept[nk - 1] < min_width) {
                nk--;
            } else {
                kept[nk++] = tog[i];
            }
        }
        double iv[8][2], rise = 0.0;
        int ni = 0, on = start;
        if (start) {
            rise = has[j] ? r[j] : 0.0;
        }
        for (int i = 0; i < nk; i++) {
            if (on) {
                iv[ni][0] = rise;
                iv[ni][1] = kept[i];
                ni++;
            } else {
                rise = kept[i];
            }
            on = !on;
        }
        if (on) {
            iv[ni][0] = rise;
            iv[ni][1] = T;
            ni++;
            has[j] = 1;
            r[j] = rise - T;
        } else {
            has[j] = 0;
            r[j] = 0.0;
        }
        nwin[j] = 0;
        for (int i = 0; i < ni; i++) {
            double a = iv[i][0] + td;
            a = 0.0 > a ? 0.0 : a;
            if (a < iv[i][1]) {
                wins[j][nwin[j]][0] = a;
                wins[j][nwin[j]][1] = iv[i][1];
                nwin[j]++;
            }
        }
    }
}

/* An exact float's value: 1 with *out set, else 0 (no error set). */
static inline int exact_float(PyObject *o, double *out)
{
    if (!PyFloat_CheckExact(o)) {
        return 0;
    }
    *out = PyFloat_AS_DOUBLE(o);
    return 1;
}

/* n exact floats of a tuple: 1 with out set, else 0 (no error set). */
static int exact_floats(PyObject *tup, double *out, Py_ssize_t n)
{
    if (!PyTuple_CheckExact(tup) || PyTuple_GET_SIZE(tup) != n) {
        return 0;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        if (!exact_float(PyTuple_GET_ITEM(tup, i), &out[i])) {
            return 0;
        }
    }
    return 1;
}

/* The duties and leg enables of a new command: a Command (of the class bound in L_COMMAND) as
 * it is, or a tuple or list of three exact floats in [0, 1] (Command.parse's check; all three
 * legs enabled). 1 with duty and *legs set and *tup the tuple to keep (a new reference), 0 when
 * Python must parse it (no error set), -1 on an error. */
enum { CM_GATES, CM_DUTY, CM_LEGS };
static layout_t L_COMMAND = {NULL, 0, {"gates", "duty", "legs", NULL, NULL, NULL, NULL, NULL}, {0}};

static int new_duties(PyObject *arg, PyObject **tup, double duty[3], long *legs)
{
    PyObject *seq = arg;
    *legs = 7;
    if (Py_TYPE(arg) == L_COMMAND.type) {
        seq = slot(&L_COMMAND, arg, CM_DUTY);
        long long mask;
        PyObject *lg = slot(&L_COMMAND, arg, CM_LEGS);
        if (seq == NULL || !PyTuple_CheckExact(seq) || lg == NULL || !int_in(lg, 0, 7, &mask)) {
            return 0;
        }
        *legs = (long)mask;
    } else if (!PyTuple_CheckExact(seq) && !PyList_CheckExact(seq)) {
        return 0;
    }
    if (PySequence_Fast_GET_SIZE(seq) != 3) {
        return 0;
    }
    PyObject **items = PySequence_Fast_ITEMS(seq);
    for (int x = 0; x < 3; x++) {
        if (!exact_float(items[x], &duty[x]) || !(0.0 <= duty[x] && duty[x] <= 1.0)) {
            return 0;
        }
    }
    if (PyTuple_CheckExact(seq)) {
        Py_INCREF(seq);
        *tup = seq;
        return 1;
    }
    *tup = PyList_AsTuple(seq);
    return *tup == NULL ? -1 : 1;
}

/* A Command(duty=tup) of the bound class, all legs enabled (its __init__ only sets the three
 * slots), or `given` when the new command was one already. New reference. */
static PyObject *duty_command(PyObject *given, PyObject *tup)
{
    if (Py_TYPE(given) == L_COMMAND.type) {
        Py_INCREF(given);
        return given;
    }
    PyTypeObject *tp = L_COMMAND.type;
    PyObject *cmd = tp->tp_alloc(tp, 0);
    if (cmd == NULL) {
        return NULL;
    }
    PyObject **gates = (PyObject **)((char *)cmd + L_COMMAND.off[CM_GATES]);
    PyObject **duty = (PyObject **)((char *)cmd + L_COMMAND.off[CM_DUTY]);
    PyObject **legs = (PyObject **)((char *)cmd + L_COMMAND.off[CM_LEGS]);
    PyObject *all_legs = PyLong_FromLong(7);
    if (all_legs == NULL) {
        Py_DECREF(cmd);
        return NULL;
    }
    Py_INCREF(Py_None);
    *gates = Py_None;
    Py_INCREF(tup);
    *duty = tup;
    *legs = all_legs;
    return cmd;
}

#define NDUTY_CFG 17

PyDoc_STRVAR(duty_period_doc,
"duty_period(cfg, command_type, old_gates, old_duty, new, rise, vdc, pa, pb, w, th, revs,\n"
"            period, load_seg, bw, old_legs)\n"
"    -> None | (command, windows)\n"
"       | (command, pa, pb, w, th, (u_alpha_int, u_beta_int), idc_int, flags, revs, period, h)\n\n"
"Plant.step's period for a duty command on the leg-window path in one call: Command.parse\n"
"(new: the duties, or a duty Command with its leg enables), SwitchTimeline.switch_windows (old\n"
"command: gate word old_gates, or duties old_duty with leg enables old_legs) with the dead-time\n"
"memory rise (updated in place),\n"
"Plant._leg_period (the kernel's leg_period) and Plant._finish (index pulse, angle wrap,\n"
"revolutions, period count). cfg: motor constants (MotorModel._k, 8), ld, spm (0 or 1), T,\n"
"computation delay, dead time, device drop, knee, h_max, the index pulse's status bit.\n"
"load_seg: Plant._load_seg (t, v0, slope, next knot). command_type: the Command class.\n"
"Returns None with nothing changed when the call does not take the period (duties Python\n"
"must parse or refuse, the load cache not covering the period start, a load knot in the\n"
"period, an argument that is not an exact float, more edges than held): the Python code\n"
"then runs. (command, windows), rise updated, when _leg_period refuses the period (the\n"
"general network takes those windows). Else the new command and the period's end state.");

static PyObject *mod_duty_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 16) {
        PyErr_SetString(PyExc_TypeError, "duty_period takes 16 arguments");
        return NULL;
    }
    double c[NDUTY_CFG], duty[3], old_duty[3], seg[4], vdc, st[4], bw;
    long old_gates = 0;
    const double *od = NULL;
    PyObject *rise = args[5];
    if (!PyType_Check(args[1])) {
        PyErr_SetString(PyExc_TypeError, "duty_period: command_type must be a class");
        return NULL;
    }
    int bound = bind_type(&L_COMMAND, (PyTypeObject *)args[1]);
    if (bound <= 0) {
        return bound < 0 ? NULL : Py_NewRef(Py_None);
    }
    if (!exact_floats(args[0], c, NDUTY_CFG) || !exact_floats(args[13], seg, 4) ||
        !exact_float(args[6], &vdc) || !exact_float(args[7], &st[0]) ||
        !exact_float(args[8], &st[1]) || !exact_float(args[9], &st[2]) ||
        !exact_float(args[10], &st[3]) || !exact_float(args[14], &bw) ||
        !PyList_CheckExact(rise) || PyList_GET_SIZE(rise) != 6) {
        Py_RETURN_NONE;
    }
    long long revs, period, old_legs;
    if (!int_in(args[11], -(long long)EXACT_INT_LIMIT, (long long)EXACT_INT_LIMIT, &revs) ||
        !int_in(args[12], 0, (long long)EXACT_INT_LIMIT, &period) || !int_in(args[15], 0, 7, &old_legs)) {
        Py_RETURN_NONE;
    }
    if (args[3] != Py_None) {
        if (!exact_floats(args[3], old_duty, 3)) {
            Py_RETURN_NONE;
        }
        od = old_duty;
    } else {
        long long g;
        if (!int_in(args[2], 0, 0x3F, &g)) {
            Py_RETURN_NONE;
        }
        old_gates = (long)g;
    }
    int has[6];
    double r[6];
    for (int j = 0; j < 6; j++) {
        PyObject *o = PyList_GET_ITEM(rise, j);
        has[j] = o != Py_None;
        r[j] = 0.0;
        if (has[j] && !exact_float(o, &r[j])) {
            Py_RETURN_NONE;
        }
    }
    cfg_t m;
    memset(&m, 0, sizeof m);
    m.pole_pairs = c[0];
    m.resistance_ohm = c[1];
    m.flux_linkage_wb = c[2];
    m.inv_ld_per_h = c[3];
    m.inv_lq_per_h = c[4];
    m.inv_inertia_per_kgm2 = c[5];
    m.damping_nm_per_rad_s = c[6];
    m.torque_coeff = c[7];
    double ld = c[8], T = c[10], delay_s = c[11], td = c[12], ud = c[13], knee = c[14];
    double h_max = c[15];
    int spm = c[9] != 0.0;
    if (!(c[16] >= 0.0 && c[16] <= 2147483647.0)) {
        PyErr_SetString(PyExc_ValueError, "duty_period: cfg's pulse bit must be 0 .. 2^31 - 1");
        return NULL;
    }
    long pulse_bit = (long)c[16];
    /* Plant.step: t0 = period * T (the int converted exactly: period < 2^52) */
    double t0 = (double)period * T;
    /* Plant._load_segment(t0) from its cache (a miss: None, Python refreshes it), then
     * _leg_period's refusal of a load knot inside the period (None: Python refuses it). */
    double seg_t = seg[0], t_next = seg[3];
    if (!(seg_t <= t0 && t0 < t_next)) {
        Py_RETURN_NONE;
    }
    double v0 = seg[1] + seg[2] * (t0 - seg_t);
    double slope = seg[2];
    if (t_next < t0 + T) {
        Py_RETURN_NONE;
    }
    PyObject *tup = NULL;
    long legs;
    int parsed = new_duties(args[4], &tup, duty, &legs);
    if (parsed <= 0) {
        return parsed < 0 ? NULL : Py_NewRef(Py_None);
    }
    /* SwitchTimeline.switch_windows (Command.__eq__ of the old and the new duty command) */
    int same = od != NULL && od[0] == duty[0] && od[1] == duty[1] && od[2] == duty[2] && old_legs == legs;
    double wins[6][MAX_WIN][2];
    int nwin[6];
    if (delay_s == 0.0 || same) {
        duty_windows_c(T, td, duty, legs, has, r, wins, nwin);
    } else {
        switch_windows_c(T, delay_s, td, old_gates, od, (long)old_legs, duty, legs, has, r, wins, nwin);
    }
    double th0 = st[3], out[3];
    int h_end = 0;
    int done = leg_period(&m, ld, spm, T, wins, nwin, ud, knee, vdc, st, h_max, v0, slope, bw,
                          out, &h_end);
    if (done == -2) {
        Py_DECREF(tup);
        return NULL;
    }
    if (done < 0) {
        Py_DECREF(tup);
        Py_RETURN_NONE;     /* the rise memory is untouched: Python does it all again */
    }
    PyObject *cmd = duty_command(args[4], tup);
    Py_DECREF(tup);
    if (cmd == NULL || rise_store(rise, has, r) < 0) {
        Py_XDECREF(cmd);
        return NULL;
    }
    if (done == 0) {
        PyObject *w = windows_list(wins, nwin);
        if (w == NULL) {
            Py_DECREF(cmd);
            return NULL;
        }
        return Py_BuildValue("(NN)", cmd, w);
    }
    /* Plant._finish */
    double th = st[3];
    long flags = 0;
    if ((th0 >= 0.0) != (th >= 0.0)) {
        flags |= pulse_bit;
    }
    if (th > PI_) {
        th -= TWO_PI;
        revs += 1;
    } else if (th <= -PI_) {
        th += TWO_PI;
        revs -= 1;
    }
    /* (command, pa, pb, w, th, (u_alpha_int, u_beta_int), idc_int, flags, revs, period, h),
     * built item by item (Py_BuildValue's format parsing costs as much as the rest) */
    PyObject *res = PyTuple_New(11), *u = PyTuple_New(2);
    if (res == NULL || u == NULL) {
        Py_XDECREF(res);
        Py_XDECREF(u);
        Py_DECREF(cmd);
        return NULL;
    }
    PyTuple_SET_ITEM(res, 0, cmd);
    PyTuple_SET_ITEM(u, 0, PyFloat_FromDouble(out[0]));
    PyTuple_SET_ITEM(u, 1, PyFloat_FromDouble(out[1]));
    PyTuple_SET_ITEM(res, 5, u);
    PyTuple_SET_ITEM(res, 1, PyFloat_FromDouble(st[0]));
    PyTuple_SET_ITEM(res, 2, PyFloat_FromDouble(st[1]));
    PyTuple_SET_ITEM(res, 3, PyFloat_FromDouble(st[2]));
    PyTuple_SET_ITEM(res, 4, PyFloat_FromDouble(th));
    PyTuple_SET_ITEM(res, 6, PyFloat_FromDouble(out[2]));
    PyTuple_SET_ITEM(res, 7, PyLong_FromLong(flags));
    PyTuple_SET_ITEM(res, 8, PyLong_FromLongLong(revs));
    PyTuple_SET_ITEM(res, 9, PyLong_FromLongLong(period + 1));
    PyTuple_SET_ITEM(res, 10, PyLong_FromLong(h_end));
    for (int i = 1; i < 11; i++) {
        if (PyTuple_GET_ITEM(res, i) == NULL || (i == 5 && (PyTuple_GET_ITEM(u, 0) == NULL ||
                                                            PyTuple_GET_ITEM(u, 1) == NULL))) {
            Py_DECREF(res);     /* tuples with NULL items are freed safely */
            return NULL;
        }
    }
    return res;
}

static PyMethodDef methods[] = {
    {"integrate", (PyCFunction)(void (*)(void))mod_integrate, METH_FASTCALL, integrate_doc},
    {"settle", (PyCFunction)(void (*)(void))mod_settle, METH_FASTCALL, settle_doc},
    {"leg_period", (PyCFunction)(void (*)(void))mod_leg_period, METH_FASTCALL, leg_period_doc},
    {"advance", (PyCFunction)(void (*)(void))mod_advance, METH_FASTCALL, advance_doc},
    {"period", (PyCFunction)(void (*)(void))mod_period, METH_FASTCALL, period_doc},
    {"fast_period", (PyCFunction)(void (*)(void))mod_fast_period, METH_FASTCALL, fast_period_doc},
    {"word_intervals", (PyCFunction)(void (*)(void))mod_word_intervals, METH_FASTCALL, word_intervals_doc},
    {"duty_windows", (PyCFunction)(void (*)(void))mod_duty_windows, METH_FASTCALL, duty_windows_doc},
    {"duty_period", (PyCFunction)(void (*)(void))mod_duty_period, METH_FASTCALL, duty_period_doc},
    {"sample", (PyCFunction)(void (*)(void))mod_sample, METH_FASTCALL, sample_doc},
    {"truth", (PyCFunction)(void (*)(void))mod_truth, METH_FASTCALL, truth_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT,
    "_plantnet",
    "The plant's network integration and PWM period in C (plant_rt/ckernel.py).",
    -1,
    methods,
    NULL,
    NULL,
    NULL,
    NULL,
};

PyMODINIT_FUNC PyInit__plantnet(void);

PyMODINIT_FUNC PyInit__plantnet(void)
{
    SQRT3 = sqrt(3.0);
    S32 = 0.5 * SQRT3;
    INV_SQRT3 = 1.0 / SQRT3;
    AX[0][0] = 1.0;
    AX[0][1] = 0.0;
    AX[1][0] = -0.5;
    AX[1][1] = 0.5 * SQRT3;
    AX[2][0] = -0.5;
    AX[2][1] = -0.5 * SQRT3;
    PI_ = 3.141592653589793;                /* math.pi */
    TWO_PI = 2.0 * PI_;
    INV_2PI = 1.0 / TWO_PI;
    RPM_PER_RAD_S = 60.0 / TWO_PI;
    if (MATH_HYPOT == NULL) {
        PyObject *math = PyImport_ImportModule("math");
        if (math == NULL) {
            return NULL;
        }
        MATH_HYPOT = PyObject_GetAttrString(math, "hypot");
        Py_DECREF(math);
        if (MATH_HYPOT == NULL) {
            return NULL;
        }
    }
    PyObject *mod = PyModule_Create(&module_def);
    if (mod == NULL) {
        return NULL;
    }
    /* The kernel's interface version: plant_rt/ckernel.py refuses a build of another one. */
    if (PyModule_AddIntConstant(mod, "ABI", 6) < 0) {
        Py_DECREF(mod);
        return NULL;
    }
    return mod;
}
