/* The reference integrator: optical depth of any density by adaptive
 * Gauss-Kronrod (7/15) quadrature in long double, independent of the closed
 * forms. It splits the segment where the density's functionals cross their
 * critical values, and at geometric steps (scale * 2^j) around each one, so
 * features far narrower than the segment are never stepped over. Values of
 * the functionals are carried from the nearer end of every piece, so pieces
 * next to a crossing keep their full relative precision. Slow by design: it
 * is the yardstick for tests and benchmarks, not a renderer. */
#ifndef EF_REF_H
#define EF_REF_H

#include "fog.h"

typedef struct ef_ref_stats {
    long pieces;      /* pieces after splitting, before adaptive bisection */
    long intervals;   /* Gauss-Kronrod intervals evaluated */
    long evals;       /* density evaluations */
    int unconverged;  /* intervals that hit the depth limit */
} ef_ref_stats;

/* A density of position described through linear functionals. */
typedef struct ef_ref_density {
    int nf;
    const ef_fog_functional *f;
    int nfeat;
    const ef_fog_feature *feat;
    void (*density)(const void *ctx, const long double *v, long double out[3]);
    const void *ctx;
} ef_ref_density;

/* tau per channel along org + t dir, t in [0, len] (len may be INFINITY:
 * channels whose density stays positive at infinity get INFINITY). The
 * relative accuracy aimed at is 1e-15. Returns 0, or -1 when memory runs
 * out. st may be NULL. */
int ef_ref_integrate(const ef_ref_density *d, const double org[3], const double dir[3],
                     double len, long double tau[3], ef_ref_stats *st);

/* The same for a fog component along r, from its model's functionals,
 * features and density. Returns -1 for models without a density of position
 * (linear, exp2) or when memory runs out. */
int ef_ref_tau(const ef_fog_component *c, const ef_ray *r, long double tau[3], ef_ref_stats *st);

#endif
