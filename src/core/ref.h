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
#include "scene.h"

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
    /* Periodic seams (a noise lattice's planes): the segment is split where
     * lattice j's functional crosses lat[j].phase + k lat[j].period, for
     * every integer k, so no quadrature interval straddles a seam. */
    int nlat;
    const ef_fog_lattice *lat;
    /* Kinks inside the pieces (the noise's clamp), or NULL: a function of
     * the functional values whose sign changes are the kinks (fog.h's
     * kink; returns 0 where there are none). Each finite piece is sampled
     * at KINK_SAMPLES points and split at every sign change, located by
     * bisection to the last bit, so no quadrature interval straddles a
     * kink. */
    int (*kink)(const void *ctx, const long double *v, long double *g);
} ef_ref_density;

/* tau per channel along org + t dir, t in [0, len] (len may be INFINITY:
 * channels whose density stays positive at infinity get INFINITY). The
 * relative accuracy aimed at is 1e-15. On an infinite segment, lattice
 * seams are split at only up to where the infinite tail starts (the
 * farthest of the features' geometric steps; with no such step, nowhere):
 * the tail's substitution takes the rest. Returns 0, or -1 when memory runs
 * out, when the lattice seams inside the segment number more than
 * EF_REF_MAX_LATTICE_SPLITS in all, or when a lattice's period is not
 * finite and positive, its phase not finite, or its crossing index
 * (value - phase) / period reaches 2^53 in magnitude (its crossings could
 * not be placed). st may be NULL. */
#define EF_REF_MAX_LATTICE_SPLITS (1L << 22)

int ef_ref_integrate(const ef_ref_density *d, const double org[3], const double dir[3],
                     double len, long double tau[3], ef_ref_stats *st);

/* The same for a fog component along r, from its model's functionals,
 * features, lattices (when it has them) and density. Returns -1 for models without a density of position
 * (linear, exp2) or when memory runs out. */
int ef_ref_tau(const ef_fog_component *c, const ef_ray *r, long double tau[3], ef_ref_stats *st);

/* tau along r over [0, len] (len finite; r->dist is not used) for rays
 * too long for one call: in chunks of at most chunk units, each integrated
 * by ef_ref_integrate from its own start (org + t dir formed in long double
 * and rounded to double, about 1e-16 of the distance: far below what the
 * densities resolve), so memory stays that of one chunk. It stops after
 * the chunk where every channel with density has reached tau >= stop
 * (T < e^-stop: nothing after can show), and *reached (when not NULL)
 * tells how far it integrated. Returns 0, or -1 as ef_ref_tau. */
int ef_ref_tau_long(const ef_fog_component *c, const ef_ray *r, double len, double chunk,
                    double stop, long double tau[3], double *reached, ef_ref_stats *st);

/* Lit fog's in-scattered light of light l along r through s (lit.h's S),
 * from the definition alone: adaptive Gauss-Kronrod in t (long double, to
 * 1e-14 of the result by its Kronrod-Gauss differences), split where the
 * view ray crosses the densities' features and at geometric steps around a
 * lamp's closest approach; both transmittances (to the point, and from it
 * to the light) by ef_ref_tau at every node (nested quadrature), uniform
 * exp by hand (rho len). Infinite rays: t = a + lambda u / (1 - u) past
 * the last split. +inf where a lamp of radius 0 lies on the segment.
 * Returns 0, or -1 for a component without a density in space or when
 * memory runs out. Slow by design. */
int ef_ref_inscatter(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, long double S[3]);

#endif
