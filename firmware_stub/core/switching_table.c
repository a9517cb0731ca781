#include "switching_table.h"

#include "fastmath.h"

const uint8_t swtab_table3[6][4] = {
    {2u, 6u, 3u, 5u}, /* I   */
    {3u, 1u, 4u, 6u}, /* II  */
    {4u, 2u, 5u, 1u}, /* III */
    {5u, 3u, 6u, 2u}, /* IV  */
    {6u, 4u, 1u, 3u}, /* V   */
    {1u, 5u, 2u, 4u}, /* VI  */
};

/* Three lines through the origin at 30, 90 and 150 degrees split the plane into
 * the six sectors; their signs form a 3-bit code:
 *   b0: sqrt3 psi_beta - psi_alpha > 0   (angle in 30..210)
 *   b1: psi_alpha < 0                    (angle in 90..270)
 *   b2: -sqrt3 psi_beta - psi_alpha > 0  (angle in 150..330)
 * Codes 2 and 5 cannot occur. */
static const uint8_t sector_of_code[8] = {1u, 2u, 1u, 3u, 6u, 1u, 5u, 4u};

uint8_t swtab_sector(float psi_alpha, float psi_beta)
{
    float sb = FM_SQRT3 * psi_beta;
    unsigned code = (sb - psi_alpha > 0.0f ? 1u : 0u) | (psi_alpha < 0.0f ? 2u : 0u) |
                    (-sb - psi_alpha > 0.0f ? 4u : 0u);
    return sector_of_code[code];
}

/* n = floor((theta + pi/6) / (pi/3)) + 6 lies in 3..9 for theta in [-pi, pi]
 * (9 only at exactly pi: sector IV, as at -pi); sector = (n mod 6) + 1.
 * Angles out of range clamp to 0..9 and NaN to 0, so the read stays inside. */
static const uint8_t sector_of_sixth[10] = {1u, 2u, 3u, 4u, 5u, 6u, 1u, 2u, 3u, 4u};

uint8_t swtab_sector_of_angle(float theta_rad)
{
    float sixths = theta_rad * (3.0f / FM_PI) + 6.5f;
    sixths = sixths >= 0.0f ? sixths : 0.0f;
    sixths = sixths <= 9.0f ? sixths : 9.0f;
    return sector_of_sixth[(uint32_t)sixths];
}

uint8_t swtab_vector(uint8_t sector, uint8_t flux_up, uint8_t torque_up)
{
    unsigned column = (flux_up ? 0u : 2u) + (torque_up ? 0u : 1u);
    unsigned row = (sector >= 1u && sector <= 6u) ? sector - 1u : 0u;
    return swtab_table3[row][column];
}
