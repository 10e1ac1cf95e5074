/* Lit fog's private header (light.c's lights lit through the models):
 * what the family's files share and offer each other. Not an interface
 * outside src/core/lit*.c.
 *
 *   light.c      the lights themselves: parsing, kinds, phases, binding (light.h)
 *   lit.c        which method serves each light and segment; the public
 *                entry points (lit.h), the sun's closed forms, the cuts
 *   lit_quad.c   the general quadrature: adaptive Gauss-Kronrod over the
 *                pieces between the features, in t or in a lamp's angle
 *   lit_lamp.c   a point lamp in uniform isotropic fog: its closed form,
 *                four rays at a time (lit.c holds a lamp's geometry along a
 *                ray and the uniform medium it sees)
 *   lit_noise.c  lit fog through a rough (noise) component
 *   lit_ms.c     multiple scattering of a sun or a sky light (ms.h)
 *   lit_lamp_ms.c  multiple scattering of a point lamp in uniform fog (ms.h)
 */
#ifndef EF_LIT_INT_H
#define EF_LIT_INT_H

#include <time.h>

#include "light.h"
#include "lit.h"
#include "scene.h"

#define PI 3.14159265358979323846

/* Cut points a segment takes, at most. */
#define MAX_CUTS 512

/* Whether c is uniform fog of position (the model's uniform hook: exp
 * along the true distance), with its extinction per channel into sigma
 * (0 where it is not). */
static inline int uniform_sigma(const ef_fog_component *c, double sigma[3])
{
    sigma[0] = sigma[1] = sigma[2] = 0;
    return c->model->uniform && c->model->uniform(c, sigma);
}

/* Whether c is uniform fog of position. */
static inline int is_uniform(const ef_fog_component *c)
{
    double sigma[3];
    return uniform_sigma(c, sigma);
}

/* A component's albedo in channel k (1 unless albedo= was given). */
static inline double albedo(const ef_fog_component *c, int k)
{
    return c->has_albedo ? c->albedo[k] : 1.0;
}

/* Monotonic seconds since t0 (the solves' times for --explain). */
static inline double ef_lit_seconds_since(const struct timespec *t0)
{
    struct timespec t1;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    return (double) (t1.tv_sec - t0->tv_sec) + 1e-9 * (double) (t1.tv_nsec - t0->tv_nsec);
}

/* qsort's order of doubles. */
static inline int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return (x > y) - (x < y);
}

/* ---- lit.c ---- */

/* Total optical depth per channel from p along unit d over len (may be
 * INFINITY), from the models' closed forms. */
void ef_lit_tau_from(const ef_fog_scene *s, const double p[3], const double d[3], double len,
                     double tau[3]);
/* A planet sun's optical depth from x (the scene's one height fog). */
void ef_lit_sun_planet_tau(const ef_fog_scene *s, const ef_light *l, const double x[3],
                           double tau[3]);

/* ---- lit_quad.c ---- */

/* Where r's segment (a, D) crosses the components' features, appended to cut. */
int ef_lit_feature_cuts(const ef_fog_scene *s, const ef_ray *r, double a, double D, double *cut,
                        int n);
/* Cuts at ts +- st 4^j inside (a, D), appended to cut. */
int ef_lit_steps_around(double *cut, int n, double ts, double a, double D, double st);
/* Where r crosses spot l's cones, appended to cut. */
int ef_lit_cone_cuts(const ef_light *l, const ef_ray *r, double a, double D, double *cut, int n);
/* Legendre's recurrence P_{m+1} = A_m y P_m - B_m P_{m-1} (A_m = (2m + 1) /
 * (m + 1), B_m = m / (m + 1)), and 1 / (2m + 1) for the integrals:
 * constants, so a lookup divides nothing. */
static const double lg_A[EF_LIT_DENSE_NC] = {
    1.0, 1.5, 5.0 / 3, 7.0 / 4, 9.0 / 5, 11.0 / 6, 13.0 / 7, 15.0 / 8,
    17.0 / 9, 19.0 / 10, 21.0 / 11, 23.0 / 12, 25.0 / 13, 27.0 / 14, 29.0 / 15,
};
static const double lg_B[EF_LIT_DENSE_NC] = {
    0.0, 0.5, 2.0 / 3, 3.0 / 4, 4.0 / 5, 5.0 / 6, 6.0 / 7, 7.0 / 8,
    8.0 / 9, 9.0 / 10, 10.0 / 11, 11.0 / 12, 12.0 / 13, 13.0 / 14, 14.0 / 15,
};
static const double lg_I[EF_LIT_DENSE_NC] = {
    1.0, 1.0 / 3, 1.0 / 5, 1.0 / 7, 1.0 / 9, 1.0 / 11, 1.0 / 13, 1.0 / 15,
    1.0 / 17, 1.0 / 19, 1.0 / 21, 1.0 / 23, 1.0 / 25, 1.0 / 27, 1.0 / 29,
};

/* ef_lit_quad_range recording its final intervals into d (weighted by w,
 * a shadow map's visibility) to relative accuracy rel (0: its own),
 * without the closed forms. */
void ef_lit_quad_range_dense(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                             double D, double w, double rel, ef_lit_dense *d);
/* The general quadrature of l's light over [a, D] of r, added to S and E,
 * to relative accuracy rel (0: its own). E NULL: no estimate wanted (a
 * lamp's multiple scattering then skips its estimate's reads; S is the
 * same bits). */
void ef_lit_quad_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                       double D, double rel, double S[3], double E[3]);
/* The scene's extinction per channel at x (its components' densities). */
void ef_lit_sigma_at(const ef_fog_scene *s, const double x[3], double out[3]);

/* ---- lit.c: a lamp's geometry, the uniform medium ---- */

/* sqrt(x^2 + y^2), with hypot's care only where the squares need it. */
double ef_lit_len2(double x, double y);
/* Lamp l's closest approach along r: w = lamp - origin, ts along r, h off it. */
void ef_lit_lamp_line(const ef_light *l, const ef_ray *r, double w[3], double *ts, double *h);
/* The uniform fog's extinction and isotropic scattering per channel. */
void ef_lit_lamp_medium(const ef_fog_scene *s, double sig[3], double scat[3]);

/* ---- lit_lamp.c ---- */

/* E_2(x) = int_1^inf e^-(x t) / t^2 dt for x >= 0, from the closed form's
 * exponential integral (to about 1e-15; e^-x, its bound, where that does
 * not converge). */
double ef_lit_e2(double x);
/* A point lamp's closed form over [a, D], added to S and E; -1 when it does not hold. */
int ef_lit_lamp_closed(const double sig[3], const double scat[3], const double e[3], double ts,
                       double h, double a, double D, double S[3], double E[3]);
/* A span of rays beside point lamp l by the closed form; the others' indices into left. */
int ef_lit_lamp_span(const ef_light *l, const double sig[3], const double scat[3],
                     const ef_ray *r, int n, double *const S[3], double *const E[3], int *left);

/* ---- lit_noise.c ---- */

/* l's light over [a, D] of r through a rough component, added to S and E. */
void ef_lit_noise_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                        double D, double S[3], double E[3]);

#endif
