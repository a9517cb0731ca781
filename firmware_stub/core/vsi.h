/*
 * Two-level voltage-source inverter: gate bits <-> the six active space
 * vectors V1..V6 of Fig. 2, and the stator voltage each one applies (Table 2).
 *
 * Vector k has switching state (S_a S_b S_c) with S = 1 meaning the phase's
 * high-side switch is on: V1 100, V2 110, V3 010, V4 011, V5 001, V6 101.
 */
#ifndef VSI_H
#define VSI_H

#include <stdint.h>

/* Gate bits as on the wire (protocol/c/hil_proto.h HIL_GATE_*). */
#define VSI_GATE_A_HIGH 0x01u
#define VSI_GATE_A_LOW 0x02u
#define VSI_GATE_B_HIGH 0x04u
#define VSI_GATE_B_LOW 0x08u
#define VSI_GATE_C_HIGH 0x10u
#define VSI_GATE_C_LOW 0x20u

/* Gate bits of active vector 1..6 (complementary legs, never both switches of a
 * leg on); 0 (all switches off) for anything else. */
uint8_t vsi_gates_of_vector(uint8_t vector);

/* Stator voltage in the stationary frame (Table 2) for the high-side states in
 * `gates` and DC-link voltage vdc_v: u_alpha = Vdc/3 (2Sa - Sb - Sc),
 * u_beta = Vdc/sqrt3 (Sb - Sc). All switches off counts as the zero vector;
 * the controller never sends that while running. */
void vsi_voltage(uint8_t gates, float vdc_v, float *u_alpha_v, float *u_beta_v);

/* The same from the vector number, which must be 0..6 (0: all off): one table
 * lookup, no check, for the control step. */
void vsi_voltage_of_vector(uint8_t vector, float vdc_v, float *u_alpha_v, float *u_beta_v);

#endif
