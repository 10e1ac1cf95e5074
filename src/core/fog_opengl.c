/* OpenGL's three fog modes (glFog, seed 001), expressed as optical depth so
 * they combine with other components: f = exp(-tau), f clamped to [0,1]. */
#include "fog.h"

#include <math.h>
#include <string.h>

static const char *const density_keys[] = { "density", NULL };
static const char *const linear_keys[] = { "start", "end", NULL };

/* Shared by exp and exp2: p[0..2] = per-channel density >= 0. */
static int set_density(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    (void) k;
    if (ef_parse_rgb(val, c->p))
        return ef_fail(err, "fog spec '%s': density='%s' is not a number or R,G,B", c->spec, val);
    for (int i = 0; i < 3; ++i)
        if (c->p[i] < 0)
            return ef_fail(err, "fog spec '%s': density='%s' is negative (densities must be >= 0)",
                           c->spec, val);
    return 0;
}

static int finish_density(ef_fog_component *c, ef_err *err)
{
    if (!(c->seen & 1u))
        return ef_fail(err, "fog spec '%s': missing density (write %s:density=D)", c->spec,
                       c->model->name);
    return 0;
}

/* rho * z with the exact limit at infinity (0 * inf is 0: no fog stays no fog). */
static double scaled(double rho, double z)
{
    return rho == 0.0 ? 0.0 : rho * z;
}

static void tau_exp(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const double z = ef_fog_distance(c, r);
    for (int i = 0; i < 3; ++i)
        tau[i] = scaled(c->p[i], z);
}

static void tau_exp2(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const double z = ef_fog_distance(c, r);
    for (int i = 0; i < 3; ++i) {
        const double t = scaled(c->p[i], z);
        tau[i] = t * t;
    }
}

/* p[0] = start, p[1] = end. */
static int set_linear(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    if (ef_parse_numbers(val, &c->p[k], 1))
        return ef_fail(err, "fog spec '%s': %s='%s' is not a number", c->spec,
                       linear_keys[k], val);
    return 0;
}

static int finish_linear(ef_fog_component *c, ef_err *err)
{
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

const ef_fog_model ef_fog_linear = { "linear", linear_keys, set_linear, finish_linear, tau_linear };
const ef_fog_model ef_fog_exp = { "exp", density_keys, set_density, finish_density, tau_exp };
const ef_fog_model ef_fog_exp2 = { "exp2", density_keys, set_density, finish_density, tau_exp2 };
