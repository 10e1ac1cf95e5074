/* Helpers shared by the fog model tests (include after cmocka.h). */
#ifndef EF_TFOG_H
#define EF_TFOG_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "fog.h"

/* A seeded generator (splitmix64) for reproducible random rays. */
typedef struct trng {
    uint64_t s;
} trng;

static inline uint64_t trng_next(trng *g)
{
    uint64_t z = (g->s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/* Uniform in [a, b). */
static inline double trng_uni(trng *g, double a, double b)
{
    return a + (b - a) * ((double) (trng_next(g) >> 11) * 0x1.0p-53);
}

/* EXRFOG_NOISE_SEGMENTS scales a test's ray count n (quick local runs). */
static inline long trng_scaled(long n)
{
    const char *e = getenv("EXRFOG_NOISE_SEGMENTS");
    if (e && atof(e) > 0)
        return (long) (n * atof(e)) > 0 ? (long) (n * atof(e)) : 1;
    return n;
}

/* Optical depth of c from (ox,oy,oz) along (dx,dy,dz), made unit here, for length L. */
static inline void tau_of(const ef_fog_component *c, double ox, double oy, double oz, double dx,
                          double dy, double dz, double L, double tau[3])
{
    const double n = sqrt(dx * dx + dy * dy + dz * dz);
    ef_ray r = { { dx / n, dy / n, dz / n }, L, L, { ox, oy, oz } };
    c->model->tau(c, &r, tau);
}

/* The same for a grey component: the one tau all channels share. */
static inline double tau1(const ef_fog_component *c, double ox, double oy, double oz, double dx,
                          double dy, double dz, double L)
{
    double t[3];
    tau_of(c, ox, oy, oz, dx, dy, dz, L, t);
    assert_true(t[0] == t[1] && t[1] == t[2]);
    return t[0];
}

#endif
