/*
 * Sector of the stator flux vector and the voltage-vector switching table of
 * Table 3.
 *
 * Sectors (Fig. 2): sector k (1..6) spans 60 degrees centred on voltage vector
 * Vk, i.e. sector I is -30..30 degrees around the alpha axis (phase a).
 *
 * Table 3 column convention: "Flux 1" = increase |psi| (comparator output 1,
 * flux below its band), "Flux 0" = decrease; "Torque 1" = increase torque
 * (counter-clockwise, positive rotation), "Torque 0" = decrease. With the flux
 * in sector k the table picks V(k+1) for (1,1), V(k-1) for (1,0), V(k+2) for
 * (0,1) and V(k-2) for (0,0): the vector's component along the flux moves |psi|
 * and its component across the flux moves the flux angle, hence the torque.
 * The paper's table uses active vectors only (no zero vectors).
 */
#ifndef SWITCHING_TABLE_H
#define SWITCHING_TABLE_H

#include <stdint.h>

/* Table 3 as printed: [sector-1][column], columns (flux,torque) = (1,1) (1,0) (0,1) (0,0). */
extern const uint8_t swtab_table3[6][4];

/* Sector 1..6 of the vector (psi_alpha, psi_beta). */
uint8_t swtab_sector(float psi_alpha, float psi_beta);

/* Sector 1..6 of a flux angle in [-pi, pi] (the paper's definition: sector k
 * spans (2k - 3) pi/6 .. (2k - 1) pi/6). The control step has the angle anyway
 * (eq. (10)), so this costs a multiply, an add and a table read; it agrees with
 * swtab_sector() except within the angle's error of a sector boundary. */
uint8_t swtab_sector_of_angle(float theta_rad);
/* Voltage vector 1..6 for a sector 1..6 and the comparator outputs (0 or 1). */
uint8_t swtab_vector(uint8_t sector, uint8_t flux_up, uint8_t torque_up);

#endif
