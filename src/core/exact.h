/* Error-free transformations (fma-based) for the few sums that cancel:
 * a plane's value at a camera far from the origin, and a ray's slope
 * against a plane it nearly parallels. With them, a functional's value at
 * both ends of a segment is correct to the last bit of a double. */
#ifndef EF_EXACT_H
#define EF_EXACT_H

#include <math.h>

#include "fog.h"

/* Marks a per-pixel function for runtime dispatch: GCC on x86-64 Linux
 * builds it twice, for the baseline ISA and for x86-64-v3 (AVX2, FMA), and
 * the loader picks one per CPU. The results are the same bits: fma() is
 * correctly rounded in libm and in hardware, and strict C11 contracts no
 * other a*b+c (no -ffp-contract=fast). What buys is fma() without a libm
 * call and wider vectors. */
/* (Not under ThreadSanitizer: its instrumented ifunc resolvers would run
 * before its runtime is up.) */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && \
    !defined(__SANITIZE_THREAD__)
#define EF_MULTIVERSION __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define EF_MULTIVERSION
#endif

/* A helper of a per-pixel function, inlined into it (and so compiled for
 * each of its targets): a call from one multiversioned function to another
 * goes through the dispatcher and is never inlined. */
#if defined(__GNUC__)
#define EF_INLINE static inline __attribute__((always_inline))
#else
#define EF_INLINE static inline
#endif

/* fmax and fmin as glibc computes them on x86-64 (the first argument on a
 * tie, so -0 against +0 too; the other one where one is NaN), inline: the
 * library calls cost more than the per-pixel work around them. */
EF_INLINE double ef_fmax(double a, double b)
{
    return (a >= b || b != b) ? a : b;
}

EF_INLINE double ef_fmin(double a, double b)
{
    return (a <= b || b != b) ? a : b;
}

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

/* An unevaluated sum hi + lo, |lo| <= ulp(hi)/2. */
typedef struct ef_dd {
    double hi, lo;
} ef_dd;

static inline ef_dd ef_two_sum(double a, double b)
{
    const double s = a + b, bb = s - a;
    return (ef_dd) { s, (a - (s - bb)) + (b - bb) };
}

static inline ef_dd ef_two_prod(double a, double b)
{
    const double p = a * b;
    return (ef_dd) { p, fma(a, b, -p) };
}

static inline ef_dd ef_dd_add(ef_dd a, ef_dd b)
{
    ef_dd s = ef_two_sum(a.hi, b.hi);
    s.lo += a.lo + b.lo;
    return ef_two_sum(s.hi, s.lo);
}

/* a.b + d, accurate to about 2^-104 relative to the largest term. */
static inline ef_dd ef_dd_dot3(const double a[3], const double b[3], double d)
{
    ef_dd s = ef_dd_add(ef_two_prod(a[0], b[0]), ef_two_prod(a[1], b[1]));
    s = ef_dd_add(s, ef_two_prod(a[2], b[2]));
    return ef_dd_add(s, (ef_dd) { d, 0.0 });
}

/* h + s * t for a double-double h and s. */
static inline ef_dd ef_dd_affine(ef_dd h, ef_dd s, double t)
{
    ef_dd p = ef_two_prod(s.hi, t);
    p.lo += s.lo * t;
    return ef_dd_add(h, p);
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
