#include "vsi.h"

#include "fastmath.h"

static const uint8_t vector_gates[7] = {
    0u,
    VSI_GATE_A_HIGH | VSI_GATE_B_LOW | VSI_GATE_C_LOW,   /* V1 100 */
    VSI_GATE_A_HIGH | VSI_GATE_B_HIGH | VSI_GATE_C_LOW,  /* V2 110 */
    VSI_GATE_A_LOW | VSI_GATE_B_HIGH | VSI_GATE_C_LOW,   /* V3 010 */
    VSI_GATE_A_LOW | VSI_GATE_B_HIGH | VSI_GATE_C_HIGH,  /* V4 011 */
    VSI_GATE_A_LOW | VSI_GATE_B_LOW | VSI_GATE_C_HIGH,   /* V5 001 */
    VSI_GATE_A_HIGH | VSI_GATE_B_LOW | VSI_GATE_C_HIGH,  /* V6 101 */
};

/* Table 2 divided by Vdc, indexed by Sa | Sb << 1 | Sc << 2. */
static const float unit_alpha[8] = {0.0f, 2.0f / 3.0f, -1.0f / 3.0f, 1.0f / 3.0f,
                                    -1.0f / 3.0f, 1.0f / 3.0f, -2.0f / 3.0f, 0.0f};
static const float unit_beta[8] = {0.0f, 0.0f, FM_INV_SQRT3, FM_INV_SQRT3,
                                   -FM_INV_SQRT3, -FM_INV_SQRT3, 0.0f, 0.0f};

uint8_t vsi_gates_of_vector(uint8_t vector)
{
    return vector <= 6u ? vector_gates[vector] : 0u;
}

void vsi_voltage(uint8_t gates, float vdc_v, float *u_alpha_v, float *u_beta_v)
{
    unsigned idx = (gates & VSI_GATE_A_HIGH ? 1u : 0u) | (gates & VSI_GATE_B_HIGH ? 2u : 0u) |
                   (gates & VSI_GATE_C_HIGH ? 4u : 0u);
    *u_alpha_v = unit_alpha[idx] * vdc_v;
    *u_beta_v = unit_beta[idx] * vdc_v;
}

/* Table 2 divided by Vdc, by vector number (0: all off). */
static const float vector_alpha[7] = {0.0f, 2.0f / 3.0f, 1.0f / 3.0f, -1.0f / 3.0f, -2.0f / 3.0f, -1.0f / 3.0f, 1.0f / 3.0f};
static const float vector_beta[7] = {0.0f, 0.0f, FM_INV_SQRT3, FM_INV_SQRT3, 0.0f, -FM_INV_SQRT3, -FM_INV_SQRT3};

void vsi_voltage_of_vector(uint8_t vector, float vdc_v, float *u_alpha_v, float *u_beta_v)
{
    *u_alpha_v = vector_alpha[vector] * vdc_v;
    *u_beta_v = vector_beta[vector] * vdc_v;
}
