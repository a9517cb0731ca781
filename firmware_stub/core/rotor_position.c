#include "rotor_position.h"

#include "fastmath.h"

#define ROTOR_MIN_FLUX_WB 1e-6f

void rotor_derive(rotor_cfg *cfg)
{
    float den = 3.0f * cfg->pole_pairs * cfg->magnet_flux_wb;
    cfg->sin_delta_per_nm_wb = den > 0.0f ? 2.0f * cfg->stator_inductance_h / den : 0.0f;
}

float rotor_load_angle(const rotor_cfg *cfg, float torque_nm, float flux_mag_wb)
{
    if (flux_mag_wb < ROTOR_MIN_FLUX_WB) {
        return 0.0f;
    }
    return fm_asin(cfg->sin_delta_per_nm_wb * torque_nm / flux_mag_wb);
}
