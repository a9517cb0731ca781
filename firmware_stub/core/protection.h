/*
 * Trips that switch every gate off and latch a fault:
 *  - overcurrent: the largest phase current (derived third phase included)
 *    above overcurrent_a, or the plant's hardware comparator bit;
 *  - DC link: the plant's overvoltage comparator bit;
 *  - encoder loss: with the encoder closing the speed loop, the counter has not
 *    moved while the flux-based (EKF) speed says the rotor turns faster than
 *    encoder_loss_min_speed_rad_s, for longer than encoder_loss_timeout_s.
 *    The minimum speed keeps the estimators' standstill noise from tripping it;
 *    at 10 rad/s a 4096-count encoder gives 6.5 counts per ms.
 */
#ifndef PROTECTION_H
#define PROTECTION_H

#include <stdint.h>

typedef struct {
    float overcurrent_a;
    float encoder_loss_timeout_s;
    float encoder_loss_min_speed_rad_s; /* mechanical */
    float control_period_s;
    uint32_t encoder_loss_timeout_periods; /* derived by prot_derive() */
} prot_cfg;

typedef struct {
    uint32_t frozen_periods; /* periods the counter has been still while the flux says it turns */
    uint16_t last_count;
} prot_state;

/* Plant status bits handled here (same values as HIL_STATUS_*). */
#define PROT_STATUS_OVERCURRENT 0x02u
#define PROT_STATUS_OVERVOLTAGE 0x04u
#define PROT_STATUS_GATE_FAULT 0x08u

/* Fault codes (same values as hil_fault_code). */
#define PROT_FAULT_NONE 0u
#define PROT_FAULT_OVERCURRENT 1u
#define PROT_FAULT_ENCODER_LOSS 2u
#define PROT_FAULT_DC_LINK 3u

void prot_derive(prot_cfg *cfg);
void prot_reset(prot_state *st, uint16_t count);
/* Returns a PROT_FAULT_* code (0 = none) and the tripping value in *value:
 * the peak phase current (A) or the DC-link voltage (V). */
uint8_t prot_hardware(const prot_cfg *cfg, float i_peak_a, float vdc_v, uint8_t status_bits, float *value);
/* Returns PROT_FAULT_ENCODER_LOSS or 0; *value is the time without an encoder
 * edge, s (SPEC.md 9.6). */
uint8_t prot_encoder_loss(const prot_cfg *cfg, prot_state *st, uint16_t count, float flux_speed_rad_s,
                          int encoder_selected, float *value);

#endif
