/* Error-free transformations (fma-based) for the few sums that cancel:
 * a plane's value at a camera far from the origin, and a ray's slope
 * against a plane it nearly parallels. With them, a functional's value at
 * both ends of a segment is correct to the last bit of a double. */
#ifndef EF_EXACT_H
#define EF_EXACT_H

#include <math.h>

#include "ddouble.h"
#include "fog.h"

/* A model's tau_add over its inlined one-ray body tau##_one: one call per
 * batch into a multiversioned loop, the same sums as tau per ray. */
#define EF_TAU_ADD(name, tau)                                                               \
    EF_MULTIVERSION static void name(const ef_fog_component *c, const ef_ray *r, int n,     \
                                     double (*acc)[3])                                      \
    {                                                                                       \
        for (int j = 0; j < n; ++j) {                                                       \
            double t[3];                                                                    \
            tau##_one(c, &r[j], t);                                                         \
            for (int k = 0; k < 3; ++k)                                                     \
                acc[j][k] += t[k];                                                          \
        }                                                                                   \
    }

/* A functional along a segment org + t dir, t in [0, len]: its value at the
 * start (h0), its rate (s, per unit t) and its value at the end (h1; for
 * len = INFINITY, +-INFINITY by the sign of s, or h0 when s == 0). Each is
 * the correctly rounded value of the exact one, to within an ulp. */
typedef struct ef_line {
    double h0, s, h1;
} ef_line;

/* n.org + d where n is the normal of c's first functional: from the
 * camera bound by ef_fog_bind when org is that camera (bit-identical). */
static inline ef_dd ef_fog_dot_org(const ef_fog_component *c, const double n[3],
                                   const double org[3], double d)
{
    if (c->bound && org[0] == c->bound_org[0] && org[1] == c->bound_org[1] &&
        org[2] == c->bound_org[2])
        return ef_dd_add((ef_dd) { c->bound_dot[0], c->bound_dot[1] }, (ef_dd) { d, 0.0 });
    return ef_dd_dot3(n, org, d);
}

/* A per-camera cache of one functional n.x + d, for models with a bind
 * hook, in c->p[EF_CAM_SLOT ..]: a flag, the camera, n.org + d as
 * ef_dd_dot3 gives it (the same bits as ef_fog_dot_org) and n's axis when n
 * is a signed unit axis (else -1). */
#define EF_CAM_SLOT 24
enum { EF_CAM_FLAG = EF_CAM_SLOT, EF_CAM_ORG, EF_CAM_HI = EF_CAM_ORG + 3, EF_CAM_LO, EF_CAM_AXIS };

/* The axis a normal lies on (its other two components are 0), or -1. */
static inline int ef_normal_axis(const double n[3])
{
    if (n[1] == 0.0 && n[2] == 0.0)
        return 0;
    if (n[0] == 0.0 && n[2] == 0.0)
        return 1;
    if (n[0] == 0.0 && n[1] == 0.0)
        return 2;
    return -1;
}

/* ef_normal_axis when n is a signed unit axis (n.x then needs no sums), else -1. */
static inline int ef_unit_axis(const double n[3])
{
    const int a = ef_normal_axis(n);
    return a >= 0 && fabs(n[a]) == 1.0 ? a : -1;
}

static inline void ef_cam_bind(ef_fog_component *c, const double n[3], double d,
                               const double org[3])
{
    const ef_dd h = ef_dd_dot3(n, org, d);
    const int a = ef_unit_axis(n);
    for (int k = 0; k < 3; ++k)
        c->p[EF_CAM_ORG + k] = org[k];
    c->p[EF_CAM_HI] = h.hi;
    c->p[EF_CAM_LO] = h.lo;
    c->p[EF_CAM_AXIS] = a;
    c->p[EF_CAM_FLAG] = 1.0;
}

/* n.org + d: from the cache when org is the bound camera. */
static inline ef_dd ef_cam_h0(const ef_fog_component *c, const double n[3], double d,
                              const double org[3])
{
    if (c->p[EF_CAM_FLAG] != 0.0 && org[0] == c->p[EF_CAM_ORG] &&
        org[1] == c->p[EF_CAM_ORG + 1] && org[2] == c->p[EF_CAM_ORG + 2])
        return (ef_dd) { c->p[EF_CAM_HI], c->p[EF_CAM_LO] };
    return ef_fog_dot_org(c, n, org, d);
}

/* n.dir as ef_dd_dot3(n, dir, 0) gives it: for a unit axis n and a finite
 * dir with dir[axis] != 0 that is (n[axis] dir[axis], +0) exactly (the
 * zero products and their fma residues sum to +0), found without the sums. */
static inline ef_dd ef_cam_rate(const ef_fog_component *c, const double n[3],
                                const double dir[3])
{
    const int a = (int) c->p[EF_CAM_AXIS];
    if (c->p[EF_CAM_FLAG] != 0.0 && a >= 0 && dir[a] != 0.0 && isfinite(dir[0]) &&
        isfinite(dir[1]) && isfinite(dir[2]))
        return (ef_dd) { n[a] * dir[a], 0.0 };
    return ef_dd_dot3(n, dir, 0.0);
}

/* ef_line_of with the start value h0 = f.org + d already known. */
static inline void ef_line_from_rate(ef_dd h0, ef_dd s, double len, ef_line *l)
{
    l->h0 = h0.hi + h0.lo;
    l->s = s.hi + s.lo;
    if (isinf(len))
        l->h1 = l->s == 0.0 ? l->h0 : copysign(INFINITY, l->s);
    else {
        const ef_dd h1 = ef_dd_affine(h0, s, len);
        l->h1 = h1.hi + h1.lo;
    }
}

static inline void ef_line_from(const ef_fog_functional *f, ef_dd h0, const double dir[3],
                                double len, ef_line *l)
{
    ef_line_from_rate(h0, ef_dd_dot3(f->n, dir, 0.0), len, l);
}

static inline void ef_line_of(const ef_fog_functional *f, const double org[3],
                              const double dir[3], double len, ef_line *l)
{
    ef_line_from(f, ef_dd_dot3(f->n, org, f->d), dir, len, l);
}

/* The same in long double, for the reference integrator. */
typedef struct ef_line_ld {
    long double h0, s, h1;
} ef_line_ld;

static inline void ef_line_of_ld(const ef_fog_functional *f, const double org[3],
                                 const double dir[3], double len, ef_line_ld *l)
{
    const ef_dd h0 = ef_dd_dot3(f->n, org, f->d), s = ef_dd_dot3(f->n, dir, 0.0);
    l->h0 = (long double) h0.hi + h0.lo;
    l->s = (long double) s.hi + s.lo;
    if (isinf(len))
        l->h1 = l->s == 0.0L ? l->h0 : copysignl(INFINITY, l->s);
    else {
        const ef_dd h1 = ef_dd_affine(h0, s, len);
        l->h1 = (long double) h1.hi + h1.lo;
    }
}

#endif
