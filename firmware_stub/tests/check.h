/* Shared includes and a tolerance assertion for the cmocka block tests. */
#ifndef CHECK_H
#define CHECK_H

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#define assert_near(a, b, tol)                                                                         \
    do {                                                                                               \
        double a_ = (double)(a), b_ = (double)(b), t_ = (double)(tol);                                 \
        if (!(fabs(a_ - b_) <= t_)) {                                                                  \
            fail_msg("%s = %.9g, expected %.9g +- %.3g", #a, a_, b_, t_);                              \
        }                                                                                              \
    } while (0)

#define PI_D 3.14159265358979323846

/* Deterministic xorshift32 for reproducible pseudo-random inputs. */
static inline uint32_t check_rand(uint32_t *s)
{
    uint32_t x = *s;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    *s = x;
    return x;
}
static inline double check_uniform(uint32_t *s, double lo, double hi)
{
    return lo + (hi - lo) * (double)check_rand(s) / 4294967296.0;
}

#endif
