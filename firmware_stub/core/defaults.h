/*
 * Default parameters. Sensing and motor values match the plant's defaults
 * (Table 1 motor); the controller's own values are derived from design inputs
 * in ctl_params_default() (control.c). Derivations: docs/stub.md.
 */
#ifndef DEFAULTS_H
#define DEFAULTS_H

/* sensing, shared with the plant */
#define CTL_DEFAULT_CONTROL_PERIOD_S 50e-6f
#define CTL_DEFAULT_CURRENT_A_PER_COUNT 0.01220703125f /* 25 A over 2048 counts */
#define CTL_DEFAULT_CURRENT_OFFSET_COUNTS 2048.0f
#define CTL_DEFAULT_VDC_V_PER_COUNT 0.0244140625f /* 100 V over 4096 counts */
#define CTL_DEFAULT_VDC_OFFSET_COUNTS 0.0f
#define CTL_DEFAULT_ENCODER_COUNTS_PER_REV 4096.0f
#define CTL_DEFAULT_CURRENT_PHASES 0u /* adc_i1 = phase a, adc_i2 = phase b */

/* motor, Table 1 */
#define CTL_DEFAULT_POLE_PAIRS 1.0f
#define CTL_DEFAULT_STATOR_RESISTANCE_OHM 0.466f
#define CTL_DEFAULT_STATOR_INDUCTANCE_H 4.8e-3f
#define CTL_DEFAULT_MAGNET_FLUX_WB 0.0928f

/* design inputs */
#define CTL_DESIGN_INERTIA_KG_M2 8.0e-4f     /* Table 1 rotor and load */
#define CTL_DESIGN_DC_LINK_V 70.0f           /* Table 1 */
#define CTL_DESIGN_SPEED_BANDWIDTH_HZ 5.0f   /* speed loop double pole */
#define CTL_DESIGN_LPF_OVER_SPEED_BANDWIDTH 4.0f /* conventional estimate's filter */
#define CTL_DEFAULT_TORQUE_LIMIT_NM 2.0f
#define CTL_DEFAULT_FLUX_DRIFT_CUTOFF_HZ 10.0f
#define CTL_DEFAULT_TELEMETRY_DIVIDER 10u
#define CTL_DEFAULT_OVERCURRENT_A 20.0f      /* 1.4 x the 14.4 A of the torque limit, inside the 25 A ADC range */
#define CTL_DEFAULT_ENCODER_LOSS_TIMEOUT_S 0.01f
#define CTL_DEFAULT_ENCODER_LOSS_MIN_SPEED_RAD_S 10.0f

/* FOC (docs/stub.md, FOC section) */
#define CTL_DEFAULT_CONTROL_LAW 0u           /* the paper's DTC */
#define CTL_DEFAULT_CURRENT_BANDWIDTH_HZ 1000.0f /* 1/20 of the 20 kHz sampling rate: 63 deg phase margin even with one period of computation delay */
#define CTL_DEFAULT_FOC_ANGLE_SOURCE 0u      /* encoder */
#define CTL_DEFAULT_DEAD_TIME_COMP_S 0.0f    /* the paper's plant has no dead time */
#define CTL_DEFAULT_DEVICE_DROP_COMP_V 0.0f  /* DTC observer; the paper's plant has no device drop */
#define CTL_DEFAULT_DELAY_COMP_PERIODS 0u    /* DTC; the paper's answer acts at once */
#define CTL_DEFAULT_CURRENT_ZERO_CAL_PERIODS 0u /* the paper's sensors have no offset */
/* Start-up stator-resistance identification (rs_id.h, docs/stub.md) */
#define CTL_DEFAULT_RS_ID_PERIODS 0u           /* off: the paper's board knows its R */
#define CTL_DESIGN_RS_ID_CURRENT_LOW_A 2.0f    /* the other two phases carry -1 A, 10x the devices' 0.1 A knee */
#define CTL_DESIGN_RS_ID_CURRENT_HIGH_A 4.0f   /* 28 % of the 14.4 A of the torque limit */
#define CTL_DESIGN_RS_ID_BANDWIDTH_HZ 500.0f /* its current PI: passes sigma_n sqrt(pi f / f_s) = 0.28 of the ADC noise to the true current */
#define CTL_DESIGN_RS_ID_OFF_S 1e-3f           /* bridge open after it: 4 A decays through the diodes in 0.4 ms */
#define CTL_DESIGN_RS_ID_MAX_SPEED_RAD_S 1.0f  /* runs only with the rotor at standstill (encoder speed) */
#define CTL_DESIGN_DEAD_TIME_COMP_BAND_A 0.1f /* linear zone of sign(i): 8 ADC counts, 16x the 0.5-count noise */

/* python -m hil.design.ekf (DLQE by the discrete Riccati equation) for the
 * documented noise model: sigma_v = 0.0136077 rad of flux-angle ripple,
 * sigma_w = 0.00625 rad/s per period of speed-increment change; estimator
 * poles at |s| = 568.5 rad/s. tests/test_stub_ekf_design.py checks these
 * against the design function. */
#define CTL_DEFAULT_EKF_K1 0.0568456203f
#define CTL_DEFAULT_EKF_K2_RAD_S 32.0846443f
#define CTL_DEFAULT_EKF_K3_RAD_S 0.446428746f

#endif
