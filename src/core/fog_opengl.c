/* OpenGL's three fog modes (glFog, seed 001), expressed as optical depth so
 * they combine with other components: f = exp(-tau), f clamped to [0,1].
 * They depend on the distance from the camera, not on position, so they have
 * no density for the reference integrator; their tests use glFog's formulas. */
#include "fog.h"

#include "exact.h"

#include <math.h>
#include <string.h>

static const char *const density_keys[] = { "density", "visibility", NULL };
static const char *const linear_keys[] = { "start", "end", NULL };

/* Shared by exp and exp2: p[0..2] = per-channel density >= 0, per metre
 * until finish converts it. visibility=V is stored as its exp density. */
static int set_density(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    if (k == 0)
        return ef_fog_set_density(c, "density", val, c->p, err);
    return ef_fog_set_visibility(c, "visibility", val, c->p, err);
}

static int finish_density(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    const unsigned given = c->seen & 3u;
    if (!given)
        return ef_fail(err, "fog spec '%s': missing density (write %s:density=D or visibility=V)",
                       c->spec, c->model->name);
    if (given == 3u)
        return ef_fail(err, "fog spec '%s': give density or visibility, not both", c->spec);
    for (int i = 0; i < 3; ++i) {
        /* exp2 falls to 2% contrast where (rho V)^2 = 3.912, not rho V. */
        if (given == 2u && c->model == &ef_fog_exp2)
            c->p[i] *= sqrt(EF_VISIBILITY_K) / EF_VISIBILITY_K;
        c->p[i] = ef_fog_per_unit(ctx, c->p[i]);
    }
    return 0;
}

/* rho * z with the exact limit at infinity (0 * inf is 0: no fog stays no fog). */
static inline double scaled(double rho, double z)
{
    return rho == 0.0 ? 0.0 : rho * z;
}

static void tau_exp(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const double z = ef_fog_distance(c, r);
    for (int i = 0; i < 3; ++i)
        tau[i] = scaled(c->p[i], z);
}

/* tau_exp over n rays, added to acc: a loop the compiler vectorises. */
static void tau_add_exp(const ef_fog_component *c, const ef_ray *r, int n, double (*acc)[3])
{
    const int planar = c->distance == EF_DIST_PLANAR;
    for (int j = 0; j < n; ++j) {
        const double z = planar ? r[j].planar : r[j].dist;
        for (int i = 0; i < 3; ++i)
            acc[j][i] += scaled(c->p[i], z);
    }
}

/* tau_exp (square = 0) or tau_exp2 (square = 1) from the distances alone,
 * into planes: tau[k][j] += scaled(rho_k, z_j), squared for exp2 (from 0
 * when first). */
static inline void tau_dist_pow(const ef_fog_component *c, const double *planar,
                                const double *dist, int n, int first, double *const tau[3],
                                int square)
{
    const double *z = c->distance == EF_DIST_PLANAR ? planar : dist;
    for (int i = 0; i < 3; ++i) {
        const double rho = c->p[i];
        double *t = tau[i];
        for (int j = 0; j < n; ++j) {
            const double v = scaled(rho, z[j]);
            t[j] = (first ? 0.0 : t[j]) + (square ? v * v : v);
        }
    }
}

EF_MULTIVERSION static void tau_dist_exp(const ef_fog_component *c, const double *planar,
                                         const double *dist, int n, int first,
                                         double *const tau[3])
{
    tau_dist_pow(c, planar, dist, n, first, tau, 0);
}

static void tau_exp2(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const double z = ef_fog_distance(c, r);
    for (int i = 0; i < 3; ++i) {
        const double t = scaled(c->p[i], z);
        tau[i] = t * t;
    }
}

EF_MULTIVERSION static void tau_dist_exp2(const ef_fog_component *c, const double *planar,
                                          const double *dist, int n, int first,
                                          double *const tau[3])
{
    tau_dist_pow(c, planar, dist, n, first, tau, 1);
}

/* p[0] = start, p[1] = end, in scene units (they are distances in the scene). */
static int set_linear(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    if (ef_parse_numbers(val, &c->p[k], 1))
        return ef_fail(err, "fog spec '%s': %s='%s' is not a number", c->spec,
                       linear_keys[k], val);
    return 0;
}

static int finish_linear(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    (void) ctx;
    if (!(c->seen & 2u))
        return ef_fail(err, "fog spec '%s': missing end (write linear:start=S:end=E)", c->spec);
    if (c->p[1] < c->p[0])
        return ef_fail(err, "fog spec '%s': end (%g) is less than start (%g)", c->spec, c->p[1],
                       c->p[0]);
    return 0;
}

/* glFog: f = (end - z)/(end - start) clamped to [0,1]; tau = -ln f.
 * end == start is the limit: a hard wall at that distance. */
static void tau_linear(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const double z = ef_fog_distance(c, r), start = c->p[0], end = c->p[1];
    double t;
    if (z <= start)
        t = 0.0;
    else if (z >= end)
        t = INFINITY;
    else
        t = -log((end - z) / (end - start));
    tau[0] = tau[1] = tau[2] = t;
}

/* exp along the true distance is uniform fog of position: rho everywhere
 * (along the planar distance it is not: a function of the camera). */
static int uniform_exp(const ef_fog_component *c, double sigma[3])
{
    if (c->distance != EF_DIST_RADIAL)
        return 0;
    for (int k = 0; k < 3; ++k)
        sigma[k] = c->p[k];
    return 1;
}

const ef_fog_model ef_fog_linear = { .name = "linear", .keys = linear_keys, .set = set_linear,
                                     .finish = finish_linear, .tau = tau_linear,
                                     .depth_only = 1, .uses_distance = 1 };
const ef_fog_model ef_fog_exp = { .name = "exp", .keys = density_keys, .set = set_density,
                                  .finish = finish_density, .tau = tau_exp,
                                  .tau_add = tau_add_exp, .tau_dist = tau_dist_exp,
                                  .uniform = uniform_exp, .depth_only = 1, .uses_distance = 1 };
const ef_fog_model ef_fog_exp2 = { .name = "exp2", .keys = density_keys, .set = set_density,
                                   .finish = finish_density, .tau = tau_exp2,
                                   .tau_dist = tau_dist_exp2,
                                   .depth_only = 1, .uses_distance = 1 };
