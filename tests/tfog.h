/* Helpers shared by the fog model tests (include after cmocka.h). */
#ifndef EF_TFOG_H
#define EF_TFOG_H

#include <math.h>

#include "fog.h"

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
