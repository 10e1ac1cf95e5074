/* Lit fog over a scene: the in-scattered light of every light along a view
 * segment (light.h gives the model and the methods). */
#ifndef EF_LIT_H
#define EF_LIT_H

#include "scene.h"

/* Whether every component of s has a density in space, so that light can
 * be carried through it: not linear or exp2, nor exp with
 * distance=planar (functions of the camera's distance); a planet sun takes
 * one exponential height fog. Returns 0, or -1 with a message naming the
 * component. */
int ef_lights_check(const ef_fog_scene *s, ef_err *err);

/* Whether light l of s cannot light the fog at all: a sun (without
 * planet=) over a component that fills all space uniformly with density in
 * every channel (exp): its light crosses infinite fog on the way in, so S
 * is 0 everywhere. */
int ef_light_dark(const ef_fog_scene *s, const ef_light *l);

/* S per channel along r (its org is the camera; r->dist may be INFINITY)
 * from light l of s, and into *err (may be NULL) an estimate of its
 * absolute error per channel (the quadrature's Kronrod-Gauss differences,
 * with noise fog the steps' Richardson differences and the noise calls'
 * estimates; 0 for closed forms). +inf where a lamp of radius 0 lies on the
 * segment itself. err NULL skips what serves the estimate alone (a lamp's
 * multiple scattering's second reads); S is the same bits. */
void ef_light_inscatter(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3],
                        double err[3]);
/* ef_light_inscatter with its quadrature aiming at relative accuracy rel
 * (0: its own, 1e-10 or 1e-13): deep samples, whose light a composite
 * needs to a share of --deep-tol, not to the flat path's digits. */
void ef_light_inscatter_rel(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double rel,
                            double S[3], double err[3]);

/* ef_light_inscatter for each of the n rays r[j]: S[k][j] and, where E is
 * not NULL, the estimate E[k][j], the same bits. A point lamp in uniform
 * isotropic fog takes its closed form four rays at a time (on vectors). */
void ef_light_rays(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, int n,
                   double *const S[3], double *const E[3]);

/* Where along r (org the camera, dir unit), strictly inside (a, b), light
 * l's in-scatter per unit optical depth jumps or turns fast: a lamp's
 * closest approach and points 4^j times its distance from the line either
 * side of it, a spot's cone crossings, a shadow map's lit-interval ends (the
 * first 64 intervals). Sorted and distinct into cut (at most cap); returns
 * how many. Deep fog samples are cut there, so that the split rule's
 * colour error can be estimated from one midpoint per sample. */
int ef_light_cuts(const ef_light *l, const ef_ray *r, double a, double b, double *cut, int cap);
/* A light's in-scatter along one whole view ray as a dense output of the
 * general quadrature: its final Gauss-Kronrod intervals, each with the
 * Legendre series of its integrand (from the 15 Kronrod values), so that
 * J(t) = integral over [0, t] of T(0, u) sigma_s p E du is at hand for any
 * t. A view segment's light seen from its front a is then
 * (J(b) - J(a)) / T(0, a): one quadrature per pixel for all its deep fog
 * samples instead of one or more per sample. Owned by the caller (one per
 * thread, reused: ef_lit_dense_free releases it). */
#define EF_LIT_DENSE_NC 15
/* The antiderivative's monomial coefficients per leaf (degree 15). */
#define EF_LIT_DENSE_NA (EF_LIT_DENSE_NC + 1)
typedef struct ef_lit_leaf {
    double t0, t1;            /* its stretch of the ray, in t */
    double u0, u1;            /* in the quadrature's variable */
    int mode;                 /* how u maps to t (lit_quad.c's equi; 3: u = t) */
    double ts, hq, ua, lam;   /* the mapping's constants */
    /* the integrand's series integrated from u0, as a polynomial in y (y
     * from -1 at u0 to 1 at u1; times half the width in u): monomial
     * coefficients, so a lookup is one short polynomial */
    double c[3][EF_LIT_DENSE_NA];
    int grey;                 /* the three channels' coefficients are the same */
    double J0[3], E0[3];      /* J and the summed error estimates at t0 */
    double r[3], e[3];        /* the leaf's integral and its estimate */
} ef_lit_leaf;
typedef struct ef_lit_dense {
    ef_lit_leaf *leaf;
    int n, cap;
    int failed;               /* 1: not usable (a lamp on the ray itself), 2: out of memory */
    double total[3];          /* J to the ray's end */
    /* the estimate of a lamp's multiple scattering in fog that is not
     * uniform over the whole ray (ms.h's local mode; not in the leaves'
     * estimates, which steer the quadrature) */
    double aux[3];
    double *fv;               /* scratch: 45 values per interval of one adaptive run */
    int fvcap;
    /* a leaf's c from its 15 Kronrod values: c[n] = w sum_i fv_i q[i][n],
     * w the leaves' visibility (constants, made at the first build; qready
     * says they are there) */
    double q[15][EF_LIT_DENSE_NA];
    int qready;
    /* ef_lit_dense_at's last answers (a deep pixel's samples share ends):
     * t, then J, E and Elo */
    double memo[4][10];
    int nmemo, next;
} ef_lit_dense;

/* Builds d for light l of s along the whole of r (org the camera, r->dist
 * possibly INFINITY), its quadrature aiming at relative accuracy rel (0:
 * the flat path's own, 1e-10 or 1e-13): 0, or 1 where the per-segment
 * methods serve l better or alone can (a sun, whose closed forms are cheap
 * per segment; noise fog, which has its own integrator), or -1 (out of
 * memory). */
int ef_lit_dense_build(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double rel,
                       ef_lit_dense *d);
/* J(t) per channel, the summed error estimates of the leaves up to t's
 * leaf included (E) and excluded (Elo), so that J(b) - J(a) is within
 * E(b) - Elo(a) (a leaf's estimate covers its partial integrals); t may
 * be INFINITY. */
void ef_lit_dense_at(ef_lit_dense *d, double t, double J[3], double E[3], double Elo[3]);
void ef_lit_dense_free(ef_lit_dense *d);

/* Whether l's light in scene s is the closed form of the sun in one
 * exponential height fog, without a shadow map: what the span path of
 * apply.c computes from the optical depths it already has. */
int ef_light_sun_span(const ef_fog_scene *s, const ef_light *l);
/* That light along r (ef_light_inscatter's S for such a sun), given the
 * segment's optical depth tv per channel as the model computes it. */
void ef_light_sun_span_eval(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                            const double tv[3], double S[3]);

#endif
