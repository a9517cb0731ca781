/*
 * On-target check of the control core's fast trigonometry (core/fastmath.c,
 * the same source the host tests): the worst absolute error of fm_sincos and
 * fm_atan2 over a dense grid, against newlib's double-precision sin, cos and
 * atan2 evaluated on the same float inputs. Prints one line and exits QEMU:
 *   FASTMATH n=<points> sincos=<float bits, hex> atan2=<float bits, hex>
 * tests/test_qemu_board.py compares the figures with FM_SINCOS_MAX_ERR and
 * FM_ATAN2_MAX_ERR.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "fastmath.h"
#include "uart.h"

#define SINCOS_POINTS 20001u /* over |theta| <= 4 pi, the range fastmath.h states */
#define ATAN2_ANGLES 4001u   /* per radius */
#define PI_D 3.14159265358979323846 /* PI_D is not in strict C99 */

static void put(const char *text) { uart0_write((const uint8_t *)text, strlen(text)); }

static void put_hex32(uint32_t v)
{
    char out[9];
    for (int i = 0; i < 8; i++) {
        out[i] = "0123456789abcdef"[(v >> (28 - 4 * i)) & 0xFu];
    }
    out[8] = '\0';
    put(out);
}

static void put_dec(uint32_t v)
{
    char out[11];
    int i = 10;
    out[i] = '\0';
    do {
        out[--i] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v != 0u);
    put(&out[i]);
}

static uint32_t float_bits(float f)
{
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    return bits;
}

int main(void)
{
    uart0_init(921600u);
    board_irq_enable();

    double sincos_err = 0.0;
    for (uint32_t i = 0; i < SINCOS_POINTS; i++) {
        float theta = (float)(-4.0 * PI_D + 8.0 * PI_D * (double)i / (double)(SINCOS_POINTS - 1u));
        float s, c;
        fm_sincos(theta, &s, &c);
        double es = fabs((double)s - sin((double)theta));
        double ec = fabs((double)c - cos((double)theta));
        sincos_err = fmax(sincos_err, fmax(es, ec));
    }

    static const float radii[] = {1e-3f, 1.0f, 1e3f};
    double atan2_err = 0.0;
    for (uint32_t r = 0; r < sizeof radii / sizeof radii[0]; r++) {
        for (uint32_t i = 0; i < ATAN2_ANGLES; i++) {
            double a = -PI_D + 2.0 * PI_D * (double)i / (double)(ATAN2_ANGLES - 1u);
            float y = (float)((double)radii[r] * sin(a));
            float x = (float)((double)radii[r] * cos(a));
            double ref = atan2((double)y, (double)x);
            double err = fabs((double)fm_atan2(y, x) - ref);
            /* -pi and pi are the same angle */
            err = fmin(err, fabs(err - 2.0 * PI_D));
            atan2_err = fmax(atan2_err, err);
        }
    }

    put("FASTMATH n=");
    put_dec(SINCOS_POINTS + ATAN2_ANGLES * (uint32_t)(sizeof radii / sizeof radii[0]));
    put(" sincos=");
    put_hex32(float_bits((float)sincos_err));
    put(" atan2=");
    put_hex32(float_bits((float)atan2_err));
    put("\n");
    while (!uart0_tx_idle()) {
    }
    board_halt(0);
}
