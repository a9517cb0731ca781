/*
 * Callgrind driver for bench/stub.py: runs ctl_step on a fixed synthetic
 * sample sequence (a rotor turning at 150 rad/s with a rotating 8 A current
 * and its encoder) in one speed-source mode.
 *
 *   step_driver MODE STEPS [TELEMETRY_EVERY [baseline]]
 *     MODE 0 encoder, 1 conventional, 2 EKF (DTC); 3, 4, 5 the same sources
 *     with the FOC law (HIL_PARAM_CONTROL_LAW 1, encoder angle); telemetry filled every
 *     TELEMETRY_EVERY steps (default 1: every step; 0: never); "baseline"
 *     runs the same program without calling ctl_step.
 *
 * The samples are generated before the loop, so counting only inside
 * ctl_step (callgrind --toggle-collect=ctl_step) and subtracting the baseline
 * run's total from the full run's both give the instructions of the control
 * step; bench/stub.py reports both.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "control.h"

#define MAX_STEPS 100000

static hil_sample samples[MAX_STEPS];

/* stands in for ctl_step in the baseline run: one instruction, "return 0" */
static uint8_t skip_step(ctl *c, const hil_sample *s, hil_telemetry *tm)
{
    (void)c;
    (void)s;
    (void)tm;
    return 0u;
}

int main(int argc, char **argv)
{
    if (argc < 3 || argc > 5 || (argc == 5 && strcmp(argv[4], "baseline") != 0)) {
        fprintf(stderr, "usage: step_driver MODE STEPS [TELEMETRY_EVERY [baseline]]\n");
        return 2;
    }
    int mode = atoi(argv[1]);
    int steps = atoi(argv[2]);
    int telemetry_every = argc >= 4 ? atoi(argv[3]) : 1;
    int baseline = argc == 5;
    if (mode < 0 || mode > 5 || steps < 0 || steps > MAX_STEPS) {
        fprintf(stderr, "step_driver: MODE in 0..5, STEPS in 0..%d\n", MAX_STEPS);
        return 2;
    }
    const double w = 150.0, t = 50e-6, amps = 8.0, a_per_count = 0.01220703125;
    for (int k = 0; k < steps; ++k) {
        double th = w * t * k;
        double ia = amps * cos(th + 1.7), ib = amps * cos(th + 1.7 - 2.0943951023931953);
        samples[k].period = (uint32_t)k;
        samples[k].adc_i1 = (uint16_t)lround(2048.0 + ia / a_per_count);
        samples[k].adc_i2 = (uint16_t)lround(2048.0 + ib / a_per_count);
        samples[k].adc_vdc = 2867u;
        samples[k].encoder = (uint16_t)(long)floor(th / 6.283185307179586 * 4096.0);
        samples[k].status = 0u;
    }
    static ctl c;
    ctl_init(&c);
    c.params.overcurrent_a = 1e3f; /* the synthetic currents are not a motor's: keep it running */
    c.params.control_law = mode >= 3 ? CTL_LAW_FOC : CTL_LAW_DTC;
    ctl_derive(&c);
    hil_command cmd = {HIL_CMD_ENABLE, (uint8_t)(mode % 3), 150.0f, 0.0f, 0.0f};
    if (ctl_set_command(&c, &cmd) != 0) {
        return 1;
    }
    hil_telemetry tm;
    unsigned gates_or = 0;
    /* the function is called through a volatile pointer in both runs, so the
     * baseline keeps the loop, the call and the argument set-up */
    uint8_t (*volatile step)(ctl *, const hil_sample *, hil_telemetry *) = baseline ? skip_step : ctl_step;
    for (int k = 0; k < steps; ++k) {
        /* with telemetry every `telemetry_every` steps (0: never) */
        int with_tm = telemetry_every > 0 && k % telemetry_every == 0;
        gates_or |= step(&c, &samples[k], with_tm ? &tm : NULL);
    }
    /* keep the results live and check the drive kept switching */
    printf("state %u gates %02x\n", (unsigned)c.st.state, gates_or);
    return c.st.state == HIL_STATE_RUNNING || steps == 0 ? 0 : 1;
}
