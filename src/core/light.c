/* Lights, phase functions and the in-scattered light of lit fog (light.h,
 * lit.h). */
#include "light.h"
#include "chapman.h"
#include "lit.h"
#include "gk15.h"
#include "shadow.h"
#include "vmath.h"

#include <complex.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

/* ------------------------------------------------------------- parsing */

/* Reads an R,G,B (or SPACE:R,G,B through the context) colour. */
static int light_color(const ef_fog_context *ctx, const char *spec, const char *val,
                       double out[3], ef_err *err)
{
    if (ctx->parse_color) {
        if (ctx->parse_color(ctx->color_user, val, out, err)) {
            char msg[sizeof err->msg];
            snprintf(msg, sizeof msg, "%s", err->msg);
            return ef_fail(err, "--light '%s': color='%s': %s", spec, val, msg);
        }
        return 0;
    }
    if (ef_parse_color(val, out))
        return ef_fail(err, "--light '%s': color='%s' is not R,G,B (numbers from 0 to %g)", spec,
                       val, EF_COLOR_MAX);
    return 0;
}

/* A non-zero vector made unit. */
static int unit3(const char *val, double v[3])
{
    if (ef_parse_numbers(val, v, 3))
        return -1;
    const double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!(n > 0) || !isfinite(n))
        return -1;
    for (int a = 0; a < 3; ++a)
        v[a] /= n;
    return 0;
}

/* The keys every kind accepts, and the ones it must have. */
static const char *const sun_keys =
    "towards, color, intensity, angle, planet, name, shadow, bias, slope, outside, penumbra";
static const char *const point_keys = "position, color, intensity, radius, name";

const char *ef_light_kind_name(ef_light_kind k)
{
    static const char *const names[] = { [EF_LIGHT_SUN] = "sun", [EF_LIGHT_POINT] = "point",
                                         [EF_LIGHT_SPOT] = "spot" };
    return k >= EF_LIGHT_SUN && k <= EF_LIGHT_SPOT ? names[k] : "?";
}
static const char *const spot_keys =
    "position, aim, cone, blend, cosine, color, intensity, radius, name, shadow, bias, slope, "
    "outside";

/* Reads l's shadow map through the context and checks it fits the light:
 * a sun's map is orthographic and looks along the sunlight, a spot's is a
 * perspective from the spot. Returns 0 or -1. */
static int light_shadow(const ef_fog_context *ctx, const char *spec, ef_light *l, ef_err *err)
{
    if (!ctx->load_shadow)
        return ef_fail(err, "--light '%s': shadow maps cannot be read here", spec);
    if (ctx->load_shadow(l->shadow_path, &l->shadow_opts, &l->shadow, err))
        return -1;
    const ef_shadow *m = l->shadow;
    const char *why = NULL;
    char detail[200] = "";
    if (l->kind == EF_LIGHT_SUN) {
        const double c = -(m->axis[0] * l->dir[0] + m->axis[1] * l->dir[1] +
                           m->axis[2] * l->dir[2]);
        if (!m->ortho)
            why = "is a perspective render; a sun's map is orthographic (render it with an "
                  "orthographic camera looking along the sunlight)";
        else if (!(c >= cos(0.25 * PI / 180))) {
            why = "looks along another direction than the sunlight (its camera's +Z must be "
                  "-towards, within 0.25 degrees)";
            snprintf(detail, sizeof detail, ": the map's axis is %g,%g,%g", m->axis[0],
                     m->axis[1], m->axis[2]);
        }
    } else {
        const double dx = m->org[0] - l->pos[0], dy = m->org[1] - l->pos[1],
                     dz = m->org[2] - l->pos[2];
        const double off = sqrt(dx * dx + dy * dy + dz * dz);
        const double size = 1 + sqrt(l->pos[0] * l->pos[0] + l->pos[1] * l->pos[1] +
                                     l->pos[2] * l->pos[2]);
        if (m->ortho)
            why = "is an orthographic render; a spot's map is a perspective render from the "
                  "spot";
        else if (!(off <= 1e-4 * size)) {
            why = "was rendered from elsewhere than the spot's position";
            snprintf(detail, sizeof detail, ": its camera is at %g,%g,%g", m->org[0], m->org[1],
                     m->org[2]);
        }
    }
    if (why) {
        ef_fail(err, "the shadow map of --light '%s' %s%s", spec, why, detail);
        ef_err_set_file(err, l->shadow_path);
        ef_shadow_unref(l->shadow);
        l->shadow = NULL;
        return -1;
    }
    return 0;
}

int ef_light_parse(const char *spec, const ef_fog_context *ctx, ef_light *l, ef_err *err)
{
    ef_fog_context dflt;
    if (!ctx) {
        ef_fog_context_init(&dflt);
        ctx = &dflt;
    }
    memset(l, 0, sizeof *l);
    if (strlen(spec) >= sizeof l->spec)
        return ef_fail(err, "--light '%.40s...' is too long", spec);
    snprintf(l->spec, sizeof l->spec, "%s", spec);
    char buf[sizeof l->spec];
    snprintf(buf, sizeof buf, "%s", spec);
    char *save = NULL, *kind = strtok_r(buf, ":", &save);
    const char *keys = NULL;
    const char *const kind_keys[] = { [EF_LIGHT_SUN] = sun_keys, [EF_LIGHT_POINT] = point_keys,
                                      [EF_LIGHT_SPOT] = spot_keys };
    for (int k = EF_LIGHT_SUN; kind && k <= EF_LIGHT_SPOT; ++k)
        if (!strcmp(kind, ef_light_kind_name((ef_light_kind) k))) {
            l->kind = (ef_light_kind) k;
            keys = kind_keys[k];
        }
    if (!keys) {
        return ef_fail(err, "--light '%s': the kind is not sun, point or spot (write "
                       "sun:towards=X,Y,Z:intensity=E or point:position=X,Y,Z:intensity=I)", spec);
    }
    double color[3] = { 1, 1, 1 }, intensity = 1, cone = 0, blend = 0;
    l->shadow_opts = (ef_shadow_opts) { 0, 1, 1 };   /* bias 0, slope 1, outside lit */
    unsigned seen = 0;
    enum { S_DIR = 1, S_POS = 2, S_AIM = 4, S_CONE = 8, S_COLOR = 16, S_INT = 32, S_ANGLE = 64,
           S_RADIUS = 128, S_BLEND = 256, S_NAME = 512, S_SHADOW = 1024, S_BIAS = 2048,
           S_OUTSIDE = 4096, S_SLOPE = 8192, S_COSINE = 16384, S_PLANET = 32768,
           S_PENUMBRA = 65536 };
    double penumbra = 16;   /* directions over the sun's disc, with angle= and shadow= */
    char *tok = strtok_r(NULL, ":", &save);
    while (tok) {
        char *next = ef_spec_next(tok, &save);
        char *eq = strchr(tok, '=');
        if (!eq || !eq[1])
            return ef_fail(err, "--light '%s': '%s' is not KEY=VALUE (keys: %s)", spec, tok, keys);
        *eq = '\0';
        const char *key = tok, *val = eq + 1;
        unsigned bit = 0;
        int ok = strstr(keys, key) != NULL;
        if (!strcmp(key, "shadow") && l->kind == EF_LIGHT_POINT)
            return ef_fail(err, "--light '%s': a point lamp takes no shadow= map (it shines "
                           "every way; a spot's or the sun's map covers one view)", spec);
        if (!ok) {
            bit = 0;
        } else if (!strcmp(key, "towards") && l->kind == EF_LIGHT_SUN) {
            bit = S_DIR;
            if (unit3(val, l->dir))
                return ef_fail(err, "--light '%s': towards='%s' is not X,Y,Z (a non-zero "
                               "direction from the scene to the sun, world axes)", spec, val);
        } else if (!strcmp(key, "position") && l->kind != EF_LIGHT_SUN) {
            bit = S_POS;
            if (ef_parse_numbers(val, l->pos, 3))
                return ef_fail(err, "--light '%s': position='%s' is not X,Y,Z (world, scene "
                               "units)", spec, val);
        } else if (!strcmp(key, "aim") && l->kind == EF_LIGHT_SPOT) {
            bit = S_AIM;
            if (unit3(val, l->dir))
                return ef_fail(err, "--light '%s': aim='%s' is not X,Y,Z (the non-zero direction "
                               "the spot points in, world axes)", spec, val);
        } else if (!strcmp(key, "cone") && l->kind == EF_LIGHT_SPOT) {
            bit = S_CONE;
            if (ef_parse_numbers(val, &cone, 1) || !(cone > 0) || !(cone <= 180))
                return ef_fail(err, "--light '%s': cone='%s' is not a full cone angle in "
                               "degrees, above 0 and at most 180", spec, val);
        } else if (!strcmp(key, "blend") && l->kind == EF_LIGHT_SPOT) {
            bit = S_BLEND;
            if (ef_parse_numbers(val, &blend, 1) || !(blend >= 0) || !(blend <= 1))
                return ef_fail(err, "--light '%s': blend='%s' is not a number from 0 to 1", spec,
                               val);
        } else if (!strcmp(key, "cosine") && l->kind == EF_LIGHT_SPOT) {
            bit = S_COSINE;
            if (!strcmp(val, "0") || !strcmp(val, "1"))
                l->cosine = val[0] == '1';
            else
                return ef_fail(err, "--light '%s': cosine='%s' is not 0 or 1 (1: the spot's "
                               "intensity also falls as cos alpha inside the cone, as Cycles' "
                               "spots do)", spec, val);
        } else if (!strcmp(key, "color")) {
            bit = S_COLOR;
            if (light_color(ctx, spec, val, color, err))
                return -1;
        } else if (!strcmp(key, "intensity")) {
            bit = S_INT;
            if (ef_parse_numbers(val, &intensity, 1) || !(intensity >= 0))
                return ef_fail(err, "--light '%s': intensity='%s' is not a number >= 0 (%s)",
                               spec, val, l->kind == EF_LIGHT_SUN
                                              ? "the irradiance on a surface facing the sun"
                                              : "the radiant intensity, per steradian");
        } else if (!strcmp(key, "angle") && l->kind == EF_LIGHT_SUN) {
            bit = S_ANGLE;
            if (ef_parse_numbers(val, &l->angle, 1) || !(l->angle >= 0) || !(l->angle < 180))
                return ef_fail(err, "--light '%s': angle='%s' is not the sun's angular diameter "
                               "in degrees, from 0 to below 180", spec, val);
            l->angle *= PI / 180;
        } else if (!strcmp(key, "penumbra") && l->kind == EF_LIGHT_SUN) {
            bit = S_PENUMBRA;
            if (ef_parse_numbers(val, &penumbra, 1) || !(penumbra >= 0) ||
                !(penumbra <= EF_PENUMBRA_MAX) || penumbra != floor(penumbra))
                return ef_fail(err, "--light '%s': penumbra='%s' is not a whole number of "
                               "directions over the sun's disc from 0 (hard shadows) to %d",
                               spec, val, EF_PENUMBRA_MAX);
        } else if (!strcmp(key, "planet") && l->kind == EF_LIGHT_SUN) {
            bit = S_PLANET;
            /* earth: 6371 km, in scene units */
            if (!strcmp(val, "earth"))
                l->planet = 6371000.0 * ctx->units_per_meter;
            else if (ef_parse_numbers(val, &l->planet, 1) || !(l->planet > 0) ||
                     !(l->planet < 1e300))
                return ef_fail(err, "--light '%s': planet='%s' is not a radius > 0 in scene "
                               "units, or earth", spec, val);
        } else if (!strcmp(key, "radius") && l->kind != EF_LIGHT_SUN) {
            bit = S_RADIUS;
            if (ef_parse_numbers(val, &l->radius, 1) || !(l->radius >= 0))
                return ef_fail(err, "--light '%s': radius='%s' is not a number >= 0 (scene "
                               "units)", spec, val);
        } else if (!strcmp(key, "shadow")) {
            bit = S_SHADOW;
            if (strlen(val) >= sizeof l->shadow_path)
                return ef_fail(err, "--light '%s': shadow= path is too long", spec);
            snprintf(l->shadow_path, sizeof l->shadow_path, "%s", val);
        } else if (!strcmp(key, "bias")) {
            bit = S_BIAS;
            double *b = &l->shadow_opts.bias;
            if (ef_parse_numbers(val, b, 1) || !(*b >= 0) || !isfinite(*b))
                return ef_fail(err, "--light '%s': bias='%s' is not a depth >= 0 (scene units "
                               "added to the shadow map's depth)", spec, val);
        } else if (!strcmp(key, "slope")) {
            bit = S_SLOPE;
            double *b = &l->shadow_opts.slope;
            if (ef_parse_numbers(val, b, 1) || !(*b >= 0) || !(*b <= 100))
                return ef_fail(err, "--light '%s': slope='%s' is not a factor from 0 to 100 (of "
                               "the shadow map's own depth slope added as a bias; 0: none)",
                               spec, val);
        } else if (!strcmp(key, "outside")) {
            bit = S_OUTSIDE;
            if (!strcmp(val, "lit"))
                l->shadow_opts.outside_lit = 1;
            else if (!strcmp(val, "shadow"))
                l->shadow_opts.outside_lit = 0;
            else
                return ef_fail(err, "--light '%s': outside='%s' is not lit or shadow (what "
                               "lies outside the shadow map)", spec, val);
        } else if (!strcmp(key, "name")) {
            bit = S_NAME;
            size_t n = strlen(val);
            int good = n > 0 && n < sizeof l->name;
            for (size_t i = 0; good && i < n; ++i)
                good = (val[i] >= 'a' && val[i] <= 'z') || (val[i] >= 'A' && val[i] <= 'Z') ||
                       (val[i] >= '0' && val[i] <= '9') || val[i] == '_' || val[i] == '-';
            if (!good)
                return ef_fail(err, "--light '%s': name='%s' is not 1 to %d letters, digits, _ "
                               "or - (it names the light's AOV channels)", spec, val,
                               (int) sizeof l->name - 1);
            snprintf(l->name, sizeof l->name, "%s", val);
        }
        if (!bit)
            return ef_fail(err, "--light '%s': unknown key '%s' for a %s light (keys: %s)", spec,
                           key, kind, keys);
        if (seen & bit)
            return ef_fail(err, "--light '%s': key '%s' is given twice", spec, key);
        seen |= bit;
        tok = next;
    }
    if (l->kind == EF_LIGHT_SUN && !(seen & S_DIR))
        return ef_fail(err, "--light '%s': missing towards=X,Y,Z (from the scene to the sun)", spec);
    if (l->kind != EF_LIGHT_SUN && !(seen & S_POS))
        return ef_fail(err, "--light '%s': missing position=X,Y,Z", spec);
    if (l->kind == EF_LIGHT_SPOT && (seen & (S_AIM | S_CONE)) != (S_AIM | S_CONE))
        return ef_fail(err, "--light '%s': a spot needs aim=X,Y,Z and cone=DEG", spec);
    /* point and spot: E = I / d_m^2 with d_m = d / U metres */
    const double U = ctx->units_per_meter, scale = l->kind == EF_LIGHT_SUN ? 1 : U * U;
    for (int k = 0; k < 3; ++k) {
        l->e[k] = color[k] * intensity * scale;
        if (!isfinite(l->e[k]))
            return ef_fail(err, "--light '%s': color times intensity overflows", spec);
    }
    if (l->kind == EF_LIGHT_SPOT) {
        l->cos_outer = cos(cone * (PI / 360));
        l->smooth = blend * (1 - l->cos_outer);
    }
    if ((seen & (S_BIAS | S_OUTSIDE | S_SLOPE)) && !(seen & S_SHADOW))
        return ef_fail(err, "--light '%s': bias=, slope= and outside= need shadow=FILE.exr", spec);
    if ((seen & S_PENUMBRA) && (!(seen & S_SHADOW) || !(l->angle > 0)))
        return ef_fail(err, "--light '%s': penumbra= needs shadow=FILE.exr and the sun's "
                       "angle=DEG (its angular diameter, e.g. 0.53)", spec);
    if ((seen & S_SHADOW) && light_shadow(ctx, spec, l, err))
        return -1;
    if (l->shadow && l->angle > 0 && penumbra > 0 &&
        ef_shadow_soften(l->shadow, l->angle, (int) penumbra, err)) {
        ef_err_set_file(err, l->shadow_path);
        ef_shadow_unref(l->shadow);
        l->shadow = NULL;
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------- phase */

double ef_phase_eval(int phase, double g, double c)
{
    switch (phase) {
    case EF_PHASE_RAYLEIGH:
        return 3 / (16 * PI) * (1 + c * c);
    case EF_PHASE_HG:
    case EF_PHASE_CS: {
        /* 1 + g^2 - 2 g c without losing it where g c is near 1 */
        const double q = g * c >= 0 ? (1 - fabs(g)) * (1 - fabs(g)) + 2 * fabs(g) * (1 - fabs(c))
                                    : 1 + g * g - 2 * g * c;
        const double d = q * sqrt(q);
        if (phase == EF_PHASE_HG)
            return (1 - g * g) / (4 * PI * d);
        return 3 / (8 * PI) * (1 - g * g) * (1 + c * c) / ((2 + g * g) * d);
    }
    default:
        return 1 / (4 * PI);
    }
}

/* ------------------------------------------------------ the densities */

/* Uniform fog of position: exp with the true (radial) distance. */
static int is_uniform(const ef_fog_component *c)
{
    return c->model == &ef_fog_exp && c->distance == EF_DIST_RADIAL;
}

int ef_lights_check(const ef_fog_scene *s, ef_err *err)
{
    if (s->nlight == 0)
        return 0;
    const int one_height = s->ncomp == 1 && s->comp[0].model == &ef_fog_height &&
                           s->comp[0].p[3] > 0;
    for (int j = 0; j < s->nlight; ++j)
        if (s->light[j].planet > 0 && !one_height)
            return ef_fail(err, "--light '%s': planet= takes one exponential height fog "
                           "(height with falloff > 0: the fog a planet's atmosphere "
                           "stratifies)", s->light[j].spec);
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (is_uniform(c))
            continue;
        if (!c->model->functionals || !c->model->density)
            return ef_fail(err, "fog spec '%s': %s fog is a function of the distance from the "
                           "camera, with no density in space for light to cross (use exp, "
                           "height, the half-spaces, layered or the volumes with --light)",
                           c->spec, c->model->name);
    }
    return 0;
}

int ef_light_dark(const ef_fog_scene *s, const ef_light *l)
{
    if (l->kind != EF_LIGHT_SUN || l->planet > 0)
        return 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (is_uniform(c) && c->p[0] > 0 && c->p[1] > 0 && c->p[2] > 0)
            return 1;
    }
    return 0;
}

/* Extinction of component c at x per channel, from its functionals. */
static void sigma_at(const ef_fog_component *c, const double x[3], double out[3])
{
    if (is_uniform(c)) {
        for (int k = 0; k < 3; ++k)
            out[k] = c->p[k];
        return;
    }
    ef_fog_functional fs[64], *f = fs;
    long double vs[64], *v = vs;
    const int n = c->model->functionals(c, NULL, 0);
    if (n > 64) {
        f = malloc((size_t) n * sizeof *f);
        v = malloc((size_t) n * sizeof *v);
        if (!f || !v) {   /* no memory: no light from here (the caller's estimate) */
            free(f);
            free(v);
            out[0] = out[1] = out[2] = 0;
            return;
        }
    }
    c->model->functionals(c, f, n);
    for (int i = 0; i < n; ++i)
        v[i] = (long double) f[i].n[0] * x[0] + (long double) f[i].n[1] * x[1] +
               (long double) f[i].n[2] * x[2] + f[i].d;
    long double o[3];
    c->model->density(c, v, o);
    for (int k = 0; k < 3; ++k)
        out[k] = (double) o[k];
    if (f != fs) {
        free(f);
        free(v);
    }
}

/* Total optical depth per channel from p along unit d over len (may be
 * INFINITY), from the models' closed forms. */
static void tau_from(const ef_fog_scene *s, const double p[3], const double d[3], double len,
                     double tau[3])
{
    ef_ray r = { { d[0], d[1], d[2] }, len, len, { p[0], p[1], p[2] } };
    tau[0] = tau[1] = tau[2] = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        double t[3];
        s->comp[i].model->tau(&s->comp[i], &r, t);
        for (int k = 0; k < 3; ++k)
            tau[k] += t[k];
    }
}

/* Ch of a planet sun at height y: from the light's table where it holds
 * y, else ef_chapman (mu clamped to [-1, 1]). */
static double planet_ch(const ef_light *l, double k, double mu, double y)
{
    if (l->ch_ok && y >= l->ch_y0 && y <= l->ch_y1) {
        /* Clenshaw on u in [-1, 1] */
        const double u = (2 * y - l->ch_y0 - l->ch_y1) / (l->ch_y1 - l->ch_y0);
        double b1 = 0, b2 = 0;
        for (int j = EF_CH_TERMS - 1; j >= 1; --j) {
            const double b0 = 2 * u * b1 - b2 + l->ch_c[j];
            b2 = b1;
            b1 = b0;
        }
        return u * b1 - b2 + l->ch_c[0];
    }
    return ef_chapman(k * (l->planet + y), mu > 1 ? 1 : mu < -1 ? -1 : mu);
}

void ef_light_bind(ef_light *l, const ef_fog_component *c, double cam_y)
{
    l->ch_ok = 0;
    if (!(l->kind == EF_LIGHT_SUN && l->planet > 0) || c->model != &ef_fog_height ||
        !(c->p[3] > 0))
        return;
    const double k = c->p[3], base = c->p[4];
    const double mu = l->dir[0] * c->up[0] + l->dir[1] * c->up[1] + l->dir[2] * c->up[2];
    const double y0 = fmin(cam_y, base) - 200 / k, y1 = fmax(cam_y, base) + 60 / k;
    if (!(l->planet + y0 > 0) || !isfinite(y1))
        return;
    enum { N = EF_CH_TERMS };
    double f[N];
    l->ch_y0 = y0;
    l->ch_y1 = y1;
    for (int i = 0; i < N; ++i) {
        const double u = cos(PI * (i + 0.5) / N);
        f[i] = ef_chapman(k * (l->planet + 0.5 * (y0 + y1) + 0.5 * (y1 - y0) * u), mu);
        if (!isfinite(f[i]))
            return;
    }
    for (int j = 0; j < N; ++j) {
        double sum = 0;
        for (int i = 0; i < N; ++i)
            sum += f[i] * cos(PI * j * (i + 0.5) / N);
        l->ch_c[j] = (j == 0 ? 1.0 : 2.0) * sum / N;
    }
    l->ch_ok = 1;
    for (int i = 0; i < 40; ++i) {
        const double y = y0 + (y1 - y0) * (i + 0.37) / 40;
        const double want = ef_chapman(k * (l->planet + y), mu), got = planet_ch(l, k, mu, y);
        if (!(fabs(got - want) <= 1e-14 * want)) {
            l->ch_ok = 0;
            return;
        }
    }
}

/* The sun's optical depth from x over a planet of radius l->planet (the
 * scene's one height fog stratified over a sphere whose surface lies at
 * height 0 below x, its centre on x's vertical): sigma(x) H Ch(X, mu), H =
 * 1/k, X = (R + height) / H, mu = l . up; +inf where the planet itself
 * stands between x and the sun (its tangent point below the surface). */
static void sun_planet_tau(const ef_fog_scene *s, const ef_light *l, const double x[3],
                           double tau[3])
{
    const ef_fog_component *c = &s->comp[0];
    const double k = c->p[3], R = l->planet;
    const double y = c->up[0] * x[0] + c->up[1] * x[1] + c->up[2] * x[2];
    const double mu = l->dir[0] * c->up[0] + l->dir[1] * c->up[1] + l->dir[2] * c->up[2];
    const double r0 = R + y;
    tau[0] = tau[1] = tau[2] = INFINITY;
    if (!(r0 > 0) || (mu < 0 && r0 * sqrt((1 - mu) * (1 + mu)) < R))
        return;
    const double ch = planet_ch(l, k, mu, y);
    const double e = exp(-k * (y - c->p[4]));
    for (int ch3 = 0; ch3 < 3; ++ch3)
        tau[ch3] = c->p[ch3] == 0 ? 0 : c->p[ch3] * e / k * ch;
}

static double albedo(const ef_fog_component *c, int k)
{
    return c->has_albedo ? c->albedo[k] : 1.0;
}

/* ----------------------------------------------------- the quadrature */

typedef void (*lit_fn)(const void *q, double u, double out[3]);

typedef struct gk_iv {
    double a, b, r[3], e[3];
} gk_iv;

/* One Kronrod rule over [a, b]; e: |Kronrod - Gauss| per channel. */
static void gk15(lit_fn f, const void *q, gk_iv *iv)
{
    const double c = 0.5 * (iv->a + iv->b), h = 0.5 * (iv->b - iv->a);
    double fv[15][3], rk[3], rg[3];
    f(q, c, fv[7]);
    for (int k = 0; k < 3; ++k) {
        rk[k] = (double) ef_gk15_wk[7] * fv[7][k];
        rg[k] = (double) ef_gk15_wg[3] * fv[7][k];
    }
    for (int j = 0; j < 7; ++j) {
        const double dx = h * (double) ef_gk15_x[j];
        f(q, c - dx, fv[j]);
        f(q, c + dx, fv[14 - j]);
        for (int k = 0; k < 3; ++k) {
            rk[k] += (double) ef_gk15_wk[j] * (fv[j][k] + fv[14 - j][k]);
            if (j & 1)
                rg[k] += (double) ef_gk15_wg[j / 2] * (fv[j][k] + fv[14 - j][k]);
        }
    }
    /* QUADPACK's qk15 estimate: |K - G| scaled by (200 |K - G| / resasc)^1.5
     * (resasc: the integral of |f - its mean|), which on a smooth piece
     * tracks the Kronrod rule's own error rather than the Gauss rule's */
    for (int k = 0; k < 3; ++k) {
        const double mean = rk[k] * 0.5;
        double asc = (double) ef_gk15_wk[7] * fabs(fv[7][k] - mean);
        for (int j = 0; j < 7; ++j)
            asc += (double) ef_gk15_wk[j] * (fabs(fv[j][k] - mean) + fabs(fv[14 - j][k] - mean));
        asc *= fabs(h);
        double e = fabs((rk[k] - rg[k]) * h);
        if (asc != 0 && e != 0)
            e = asc * fmin(1, pow(200 * e / asc, 1.5));
        iv->r[k] = rk[k] * h;
        iv->e[k] = fmax(e, 50 * 0x1p-52 * fabs(iv->r[k]));
    }
}

#define GK_MAX 512

/* Global adaptive Gauss-Kronrod over the pieces [cut[i], cut[i+1]] until
 * the summed error estimate is at most rel of the result plus S in every
 * channel (or GK_MAX intervals): adds the result to S and its estimate to
 * E. */
static void gk_adapt(lit_fn f, const void *q, const double *cut, int ncut, double rel,
                     double S[3], double E[3])
{
    gk_iv iv[GK_MAX];
    int n = 0;
    for (int i = 0; i + 1 < ncut && n < GK_MAX; ++i) {
        if (!(cut[i + 1] > cut[i]))
            continue;
        iv[n].a = cut[i];
        iv[n].b = cut[i + 1];
        gk15(f, q, &iv[n++]);
    }
    for (;;) {
        double R[3] = { 0, 0, 0 }, Er[3] = { 0, 0, 0 };
        for (int i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k) {
                R[k] += iv[i].r[k];
                Er[k] += iv[i].e[k];
            }
        int done = 1;
        /* relative to what S already holds too: a far piece of a ray
         * whose light was collected before need not resolve its own
         * near-zero to 1e-13 of itself */
        for (int k = 0; k < 3; ++k)
            done &= Er[k] <= rel * fabs(R[k] + S[k]) || !isfinite(R[k]);
        /* the interval of the largest error relative to its channel's total */
        int worst = -1;
        double we = -1;
        for (int i = 0; i < n; ++i) {
            const double m = 0x1p-20 * (iv[i].b - iv[i].a) < 0x1p-52 * fmax(fabs(iv[i].a),
                                                                            fabs(iv[i].b))
                                 ? 0 : 1;   /* too narrow to split further */
            for (int k = 0; k < 3; ++k) {
                const double w = m * iv[i].e[k] / (fabs(R[k] + S[k]) + 1e-300);
                if (w > we) {
                    we = w;
                    worst = i;
                }
            }
        }
        if (done || n + 1 >= GK_MAX || worst < 0 || !(we > 0)) {
            for (int k = 0; k < 3; ++k) {
                S[k] += R[k];
                E[k] += Er[k];
            }
            return;
        }
        const double a = iv[worst].a, b = iv[worst].b, m = 0.5 * (a + b);
        iv[worst].b = m;
        gk15(f, q, &iv[worst]);
        iv[n].a = m;
        iv[n].b = b;
        gk15(f, q, &iv[n++]);
    }
}

/* ------------------------------------------------------ the integrands */

typedef struct lit_q {
    const ef_fog_scene *s;
    const ef_light *l;
    const ef_ray *r;
    int equi;                 /* 1: u = xi, t = ts + hq tan(xi), E dt = e / hq dxi; 2: the tail v; 0: t (sun) or t - ts (lamp) */
    double ts, hq, h;         /* the lamp's closest approach along the ray, its distances */
    double w[3], wa, va;      /* lamp - camera; w . aim and dir . aim (spots) */
    double W;                 /* xi within W of the closest approach, t beyond */
    double ua, lam;           /* an infinite ray's tail: u = ua + lam v / (1 - v) */
    int uniform;              /* every component uniform: sig per channel */
    double sig[3];
} lit_q;

double ef_spot_share(const ef_light *l, double cos_alpha)
{
    const double t = cos_alpha - l->cos_outer;
    if (!(t > 0))
        return 0;
    const double c = l->cosine ? cos_alpha : 1;
    if (l->smooth > 0 && t < l->smooth) {
        const double x = t / l->smooth;
        return c * x * x * (3 - 2 * x);
    }
    return c;
}

/* sum_c sigma_c albedo_c p_c(cos) per channel at x. */
static void scatter_at(const ef_fog_scene *s, const double x[3], double cos_theta, double acc[3])
{
    acc[0] = acc[1] = acc[2] = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double sg[3];
        sigma_at(c, x, sg);
        if (sg[0] == 0 && sg[1] == 0 && sg[2] == 0)
            continue;
        const double p = ef_phase_eval(c->phase, c->g, cos_theta);
        for (int k = 0; k < 3; ++k)
            acc[k] += sg[k] == 0 ? 0 : sg[k] * albedo(c, k) * p;
    }
}

/* The integrand at u (t or xi), light included. For a lamp, its distance
 * and the phase's angle come from u - ts and the line's distance h (both
 * exact at the closest approach), not from a world point rounded to
 * double, whose rounding (an ulp of the ray's length) would be a large
 * share of d where the lamp is near the ray. */
static void lit_integrand(const void *qv, double u, double out[3])
{
    const lit_q *q = qv;
    const ef_light *l = q->l;
    const ef_ray *r = q->r;
    double t = u, ur = 0, wgt = 1;
    out[0] = out[1] = out[2] = 0;
    if (q->equi == 1) {
        ur = q->hq * tan(u);
        t = q->ts + ur;
        wgt = 1 / q->hq;
    } else if (q->equi == 2) {
        if (!(u < 1))
            return;
        ur = q->ua + q->lam * u / (1 - u);
        t = q->ts + ur;
        wgt = q->lam / ((1 - u) * (1 - u)) / (ur * ur + q->hq * q->hq);
    } else if (l->kind != EF_LIGHT_SUN) {
        /* a lamp's pieces in t are in u = t - ts: nodes near the lamp
         * keep their full precision */
        ur = u;
        t = q->ts + u;
        wgt = 1 / (ur * ur + q->hq * q->hq);
    }
    if (!(t >= 0))
        t = 0;
    double ld[3], dl = INFINITY, cth;
    if (l->kind == EF_LIGHT_SUN) {
        memcpy(ld, l->dir, sizeof ld);
        cth = ld[0] * r->dir[0] + ld[1] * r->dir[1] + ld[2] * r->dir[2];
    } else {
        dl = sqrt(ur * ur + q->h * q->h);
        if (!(dl > 0))
            return;
        cth = -ur / dl;
        double y[3], yn = 0;
        for (int a = 0; a < 3; ++a) {
            y[a] = q->w[a] - t * r->dir[a];
            yn += y[a] * y[a];
        }
        yn = sqrt(yn);
        for (int a = 0; a < 3; ++a)
            ld[a] = yn > 0 ? y[a] / yn : 0;
        if (l->kind == EF_LIGHT_SPOT) {
            wgt *= ef_spot_share(l, -(q->wa - t * q->va) / dl);
            if (wgt == 0)
                return;
        }
    }
    if (q->uniform) {
        /* T(0,t) T_l = e^-(sig (t + d)); one phase per component, one
         * exponential per distinct density */
        double a[3] = { 0, 0, 0 };
        for (int i = 0; i < q->s->ncomp; ++i) {
            const ef_fog_component *c = &q->s->comp[i];
            const double p = ef_phase_eval(c->phase, c->g, cth);
            for (int k = 0; k < 3; ++k)
                if (c->p[k] > 0)
                    a[k] += c->p[k] * albedo(c, k) * p;
        }
        double e[3];
        e[0] = exp(-q->sig[0] * (t + dl));
        e[1] = q->sig[1] == q->sig[0] ? e[0] : exp(-q->sig[1] * (t + dl));
        e[2] = q->sig[2] == q->sig[0] ? e[0] : exp(-q->sig[2] * (t + dl));
        /* the transmittance first: where it is 0 a dense fog's sigma times
         * a near lamp's weight may overflow, and inf * 0 is no answer */
        for (int k = 0; k < 3; ++k)
            out[k] = q->sig[k] == 0 || e[k] == 0 ? 0 : a[k] * e[k] * wgt * l->e[k];
        return;
    }
    double x[3], acc[3];
    for (int a = 0; a < 3; ++a)
        x[a] = r->org[a] + t * r->dir[a];
    scatter_at(q->s, x, cth, acc);
    if (acc[0] == 0 && acc[1] == 0 && acc[2] == 0)
        return;
    double tv[3], tl[3];
    tau_from(q->s, r->org, r->dir, t, tv);
    if (l->kind == EF_LIGHT_SUN && l->planet > 0)
        sun_planet_tau(q->s, l, x, tl);
    else
        tau_from(q->s, x, ld, dl, tl);
    /* where either leg is opaque the density may have overflowed too:
     * no light, not inf * 0 */
    for (int k = 0; k < 3; ++k) {
        const double e = exp(-(tv[k] + tl[k]));
        out[k] = acc[k] == 0 || e == 0 ? 0 : acc[k] * e * wgt * l->e[k];
    }
}

/* ------------------------------------------------------- the closed forms */

/* tau phi(tau q), phi(x) = -expm1(-x) / x: the integral of e^(linear) over
 * a segment of optical depth tau whose exponent changes by tau q, relative
 * to its larger end. tau phi(x) while x <= 1 (x -> 0 tends to tau exactly),
 * -expm1(-x) / q beyond (tau = inf gives 1 / q). */
static double tau_phi(double tau, double q)
{
    const double x = tau * q;
    if (x == 0)
        return tau;
    if (x <= 1)
        return tau * (-expm1(-x) / x);
    return -expm1(-x) / q;
}

/* The sun in one exponential height fog (k > 0), with its own extinction
 * in the fog: T_sun(x) = e^-(sigma(x) / (k l_up)), and along the view ray
 *   S = albedo p E tau_v e^-min(A, B) phi(|B - A|),
 *   A = sigma(C) / (k l_up), B = tau_v + sigma(P) / (k l_up),
 * phi(x) = -expm1(-x) / x and B - A = tau_v (1 - mu / l_up) exactly (mu the
 * view ray's up component), so no difference of large terms is formed. */
static void sun_height_tau(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                           const double tv[3], double S[3])
{
    const ef_fog_component *c = &s->comp[0];
    const double k = c->p[3];
    const double lu = l->dir[0] * c->up[0] + l->dir[1] * c->up[1] + l->dir[2] * c->up[2];
    const double mu = r->dir[0] * c->up[0] + r->dir[1] * c->up[1] + r->dir[2] * c->up[2];
    S[0] = S[1] = S[2] = 0;
    if (!(lu > 0))
        return;   /* at or below the horizon, the sun crosses unbounded fog */
    double sc[3], sp[3] = { 0, 0, 0 };
    /* the densities at the ends, rho e^-(k (height - base)), in double
     * (one exponential each: the model's own density works in long double
     * for the reference) */
    const double hc = c->up[0] * r->org[0] + c->up[1] * r->org[1] + c->up[2] * r->org[2] - c->p[4];
    const double ec = exp(-k * hc);
    double ep = 0;
    if (isfinite(r->dist))
        ep = exp(-k * (hc + r->dist * mu));
    else if (!(mu > 0))
        ep = INFINITY;
    for (int ch = 0; ch < 3; ++ch) {
        sc[ch] = c->p[ch] == 0 ? 0 : c->p[ch] * ec;
        sp[ch] = c->p[ch] == 0 ? 0 : c->p[ch] * ep;
    }
    const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    const double p = ef_phase_eval(c->phase, c->g, cth), q = fabs(1 - mu / lu);
    double me = 0;   /* m e^-min(A, B) of channel last (-1: none yet) */
    int last = -1;
    for (int ch = 0; ch < 3; ++ch) {
        if (!(tv[ch] > 0) || l->e[ch] == 0 || albedo(c, ch) == 0)
            continue;
        /* grey fog: the same densities, the same factor */
        if (!(last >= 0 && c->p[ch] == c->p[last] && tv[ch] == tv[last])) {
            last = ch;
            const double A = sc[ch] / (k * lu), B = tv[ch] + sp[ch] / (k * lu);
            const double e = exp(-(A < B ? A : B));
            me = e == 0 ? 0 : tau_phi(tv[ch], q) * e;
        }
        S[ch] = me == 0 ? 0 : albedo(c, ch) * p * l->e[ch] * me;
    }
}

/* sun_height with the view segment's optical depth from the model. */
static void sun_height(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3])
{
    double tv[3];
    s->comp[0].model->tau(&s->comp[0], r, tv);
    sun_height_tau(s, l, r, tv, S);
}

int ef_light_sun_span(const ef_fog_scene *s, const ef_light *l)
{
    return l->kind == EF_LIGHT_SUN && !l->shadow && !(l->planet > 0) && s->ncomp == 1 &&
           s->comp[0].model == &ef_fog_height && s->comp[0].p[3] > 0;
}

void ef_light_sun_span_eval(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                            const double tv[3], double S[3])
{
    S[0] = S[1] = S[2] = 0;
    /* as ef_light_inscatter: no segment, no light */
    if (!(r->dist > 0) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return;
    sun_height_tau(s, l, r, tv, S);
}

/* The sun in one half-space fog of any of the three densities sigma(X) of
 * the depth X = -h below the plane (h = n.x + d, n unit, fog where h < 0:
 * constant, linear, Walker's smooth): from x the sun's path in the fog has
 * optical depth tau_sun(x) = Sigma(X) / (n.l), Sigma the density's
 * integral from the plane down, so along the view ray the exponent
 * E(t) = -(tau_v(0, t) + tau_sun(x(t))) has dE/dt = -sigma (1 - s / (n.l))
 * (s = n.u) wherever there is fog, and 0 where there is none:
 *   S = albedo p E int sigma e^E dt = albedo p E (e^E(0) - e^E(D)) / q,
 * q = 1 - s / (n.l), written as tau_v e^max(E(0), E(D)) phi(tau_v |q|)
 * (no difference of large terms; q -> 0 tends to tau_v e^E). Both ends'
 * E come from the model's own closed-form optical depths (the view
 * segment, and the sun's ray from each end). With n.l <= 0 the sun never
 * leaves the fog: no light. */
static void sun_halfspace(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3])
{
    const ef_fog_component *c = &s->comp[0];
    const double *n = c->p;
    const double nl = n[0] * l->dir[0] + n[1] * l->dir[1] + n[2] * l->dir[2];
    const double sv = n[0] * r->dir[0] + n[1] * r->dir[1] + n[2] * r->dir[2];
    S[0] = S[1] = S[2] = 0;
    if (!(nl > 0))
        return;
    double tv[3], ta[3], tb[3] = { 0, 0, 0 };
    c->model->tau(c, r, tv);
    if (c->model == &ef_fog_halfspace) {
        /* constant: Sigma(X) = rho X, from the plane values at the ends */
        const double h0 = n[0] * r->org[0] + n[1] * r->org[1] + n[2] * r->org[2] + n[3];
        const double hb = isfinite(r->dist) ? h0 + sv * r->dist : 0;
        for (int ch = 0; ch < 3; ++ch) {
            ta[ch] = h0 < 0 ? c->p[4 + ch] * -h0 / nl : 0;
            tb[ch] = hb < 0 ? c->p[4 + ch] * -hb / nl : 0;
        }
    } else {
        ef_ray sun = { { l->dir[0], l->dir[1], l->dir[2] }, INFINITY, INFINITY,
                       { r->org[0], r->org[1], r->org[2] } };
        c->model->tau(c, &sun, ta);
        if (isfinite(r->dist)) {
            for (int k = 0; k < 3; ++k)
                sun.org[k] = r->org[k] + r->dist * r->dir[k];
            c->model->tau(c, &sun, tb);
        }
    }
    const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    const double p = ef_phase_eval(c->phase, c->g, cth), q = fabs(1 - sv / nl);
    for (int ch = 0; ch < 3; ++ch) {
        if (!(tv[ch] > 0) || l->e[ch] == 0 || albedo(c, ch) == 0)
            continue;
        const double ya = -ta[ch], yb = -tv[ch] - tb[ch];
        const double e = exp(ya > yb ? ya : yb);
        S[ch] = e == 0 ? 0 : albedo(c, ch) * p * l->e[ch] * tau_phi(tv[ch], q) * e;
    }
}

/* The sun in one constant-density convex volume (box or convex: planes
 * n.x + d < 0, n unit, in c->arr): inside, the sun's path out of the
 * volume is e(t) = min over the planes the sunlight leaves through
 * (n.l > 0) of -(n.x(t) + d) / (n.l), a lower envelope of lines in t, and
 * the fog is only there, so along the view segment's part inside,
 * [t_in, t_out], the exponent -rho (t - t_in + e(t)) is piecewise linear:
 * per piece rho L e^max(ends) phi(|difference|). With no plane facing the
 * sun the sun's path never leaves: no light. */
static void sun_convex(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3])
{
    const ef_fog_component *c = &s->comp[0];
    const int np = (int) c->p[9];
    S[0] = S[1] = S[2] = 0;
    if (np <= 0 || np > 64)
        return;
    double h0[64], sv[64], m[64];
    double tin = 0, tout = r->dist;
    for (int i = 0; i < np; ++i) {
        const double *P = c->arr + 4 * i;
        h0[i] = P[0] * r->org[0] + P[1] * r->org[1] + P[2] * r->org[2] + P[3];
        sv[i] = P[0] * r->dir[0] + P[1] * r->dir[1] + P[2] * r->dir[2];
        m[i] = P[0] * l->dir[0] + P[1] * l->dir[1] + P[2] * l->dir[2];
        if (sv[i] == 0) {
            if (!(h0[i] < 0))
                return;   /* along the plane, outside it */
        } else if (sv[i] < 0) {
            tin = fmax(tin, -h0[i] / sv[i]);
        } else {
            tout = fmin(tout, -h0[i] / sv[i]);
        }
    }
    if (!(tin < tout))
        return;
    /* the length inside from the model's own optical depth, which clips in
     * double-double: a sliver's ends, subtracted in double, would lose it */
    double tv[3], len = tout - tin;
    c->model->tau(c, r, tv);
    for (int ch = 0; ch < 3; ++ch)
        if (c->p[ch] > 0 && isfinite(tv[ch])) {
            len = tv[ch] / c->p[ch];
            break;
        }
    /* e(t) = min_i alpha_i + beta_i t over the planes the sun leaves by */
    int cur = -1;
    double ecur = INFINITY;
    for (int i = 0; i < np; ++i)
        if (m[i] > 0) {
            const double e = -(h0[i] + tin * sv[i]) / m[i];
            if (cur < 0 || e < ecur || (e == ecur && -sv[i] / m[i] < -sv[cur] / m[cur])) {
                cur = i;
                ecur = e;
            }
        }
    if (cur < 0)
        return;   /* no plane faces the sun: its light never gets in */
    const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    const double p = ef_phase_eval(c->phase, c->g, cth);
    /* pieces by their offset from tin (u): the kinks' t only place them,
     * so the lengths add up to len exactly */
    double t = tin, u = 0;
    while (u < len) {
        const double bc = -sv[cur] / m[cur];
        /* the next line to dip below the current one */
        double tn = INFINITY;
        int next = -1;
        for (int i = 0; i < np; ++i) {
            if (!(m[i] > 0) || i == cur)
                continue;
            const double bi = -sv[i] / m[i];
            if (!(bi < bc))
                continue;
            /* alpha_i + bi t = alpha_c + bc t, alpha = -h0 / m */
            const double tx = (-h0[i] / m[i] + h0[cur] / m[cur]) / (bc - bi);
            if (tx > t && tx < tn && tx - tin < len) {
                tn = tx;
                next = i;
            }
        }
        const double e0 = fmax(-(h0[cur] + t * sv[cur]) / m[cur], 0);
        const double un = next < 0 ? len : fmin(fmax(tn - tin, u), len);
        const double L = un - u, q = fabs(1 + bc);
        for (int ch = 0; ch < 3; ++ch) {
            const double rho = c->p[ch];
            if (!(rho > 0) || l->e[ch] == 0 || albedo(c, ch) == 0)
                continue;
            const double y0 = -rho * (u + e0);
            const double y1 = y0 - rho * (1 + bc) * L;
            const double e = isfinite(L) ? exp(y0 > y1 ? y0 : y1) : exp(y0);
            if (e == 0)
                continue;
            S[ch] += albedo(c, ch) * p * l->e[ch] * tau_phi(rho * L, q) * e;
        }
        if (next < 0)
            break;
        cur = next;
        t = tn;
        u = un;
    }
}

/* ------------------------------------------ a point lamp in uniform fog */

/* sqrt(x^2 + y^2): hypot's care only where the squares could overflow
 * or underflow (hypot costs several times more). */
static double len2(double x, double y)
{
    const double ax = fabs(x), ay = fabs(y), m = ax > ay ? ax : ay;   /* (NaN: NaN below) */
    if (m < 1e150 && m > 1e-150)
        return sqrt(x * x + y * y);
    return m == 0 ? 0 : hypot(x, y);
}

/* |(x, y, z)| with one square root where the largest magnitude lies
 * within 1e-150 .. 1e150 (its square then neither overflows nor loses
 * digits that matter), else by len2 twice. lamp_span computes the same
 * plain form on vectors. */
static double len3(double x, double y, double z)
{
    const double ax = fabs(x), ay = fabs(y), az = fabs(z), mxy = ax > ay ? ax : ay,
                 m = mxy > az ? mxy : az;
    if (m < 1e150 && m > 1e-150)
        return sqrt(x * x + y * y + z * z);
    return len2(len2(x, y), z);
}

/* Where lamp l comes closest to the line of r: its parameter *ts along
 * r->dir, and its distance *h from the line by the cross product (no
 * cancellation near the line); w gets lamp - origin. */
static void lamp_line(const ef_light *l, const ef_ray *r, double w[3], double *ts, double *h)
{
    for (int k = 0; k < 3; ++k)
        w[k] = l->pos[k] - r->org[k];
    *ts = w[0] * r->dir[0] + w[1] * r->dir[1] + w[2] * r->dir[2];
    const double cx = w[1] * r->dir[2] - w[2] * r->dir[1],
                 cy = w[2] * r->dir[0] - w[0] * r->dir[2],
                 cz = w[0] * r->dir[1] - w[1] * r->dir[0];
    *h = len3(cx, cy, cz);
}

/* |z|^2, without hypot's care for overflow (the arguments here are far
 * from it) */
static double norm2(double complex z)
{
    return creal(z) * creal(z) + cimag(z) * cimag(z);
}

/* w_k = (-1)^k / (k k!), k = 0..21 (w_0 = 0): sum_k w_k z^k is the sum
 * (-z)^k / (k k!) in E1(z) = -gamma - ln z - sum. */
static const double lamp_w[22] = {
    0, -1, 0.25, -0.055555555555555552, 0.010416666666666666, -0.0016666666666666668,
    0.00023148148148148149, -2.834467120181406e-05, 3.1001984126984127e-06,
    -3.0619243582206544e-07, 2.7557319223985891e-08, -2.27746439867652e-09,
    1.7397297489890083e-10, -1.2353110643708935e-11, 8.1933897126640886e-13,
    -5.0981091545465446e-14, 2.9871733327421158e-15, -1.6537983849091297e-16,
    8.6773372047701253e-18, -4.326650129802279e-19, 2.0551588116560825e-20,
    -9.3204481254244102e-22,
};

/* The terms of lamp_w that reach 1e-17 of the series for |z|^2 <= r2
 * <= 2.25: r^n / (n + 1)! below it. */
static int lamp_terms(double r2)
{
    return r2 <= 0.0625 ? 12 : r2 <= 0.25 ? 15 : r2 <= 0.5625 ? 17 : r2 <= 1 ? 18
           : r2 <= 1.5625 ? 20 : 21;
}

/* g_e1's continued fraction for the lanes of live (|z| >= 1.5), each
 * lane stopping at its own convergence (its value is the same whatever
 * its neighbours): G into (Gr, Gi), and in conv whether it converged
 * within 2000 terms. F = b_0 + a_1 / (b_1 + a_2 / (b_2 + ...)), b_j =
 * z + 2j + 1, a_j = -j^2, G = 1 / F, by the forward recurrences of F's
 * numerators and denominators (Wallis): no division per term, so one
 * term is a few multiplications deep rather than the modified Lentz
 * method's three divisions. Both grow; every fourth term they are scaled
 * back by a power of two of the lane's own (exact: no rounding), and the
 * test for convergence uses |F_j - F_(j-1)| = (j!)^2 / |B_j B_(j-1)| (the
 * product of the a's, not a difference that would cancel), tracked in
 * the same scale as q2 = (j!)^4. */
EF_INLINE void lamp_cf4(const v4d *zr, const v4d *zi, const v4di *live_in, v4d *Gr, v4d *Gi,
                        v4di *conv)
{
    const v4d zero = { 0, 0, 0, 0 };
    /* A_(j-1), A_j, B_(j-1), B_j; j = 0 */
    v4d pAr = zero + 1.0, pAi = zero, Ar = *zr + 1.0, Ai = *zi, pBr = zero, pBi = zero,
        Br = zero + 1.0, Bi = zero, q2 = zero + 1.0;
    v4d fAr = Ar, fAi = Ai, fBr = Br, fBi = Bi;   /* each lane's at its convergence */
    v4di live = *live_in;
    *conv = live & 0;
    for (int j = 1; j < 2000 && v_any(&live); ++j) {
        const v4d br = *zr + (2.0 * j + 1);
        const double a = -(double) j * j;
        const v4d nAr = (br * Ar - *zi * Ai) + a * pAr, nAi = (br * Ai + *zi * Ar) + a * pAi;
        const v4d nBr = (br * Br - *zi * Bi) + a * pBr, nBi = (br * Bi + *zi * Br) + a * pBi;
        pAr = Ar;
        pAi = Ai;
        pBr = Br;
        pBi = Bi;
        Ar = nAr;
        Ai = nAi;
        Br = nBr;
        Bi = nBi;
        q2 = q2 * (a * a);
        /* |F_j - F_(j-1)| < 1e-16 |F_j|: (j!)^2 < 1e-16 |A_j| |B_(j-1)| */
        const v4di done =
            live & (q2 < 1e-32 * ((Ar * Ar + Ai * Ai) * (pBr * pBr + pBi * pBi)));
        v_sel(&fAr, &done, &Ar, &fAr);
        v_sel(&fAi, &done, &Ai, &fAi);
        v_sel(&fBr, &done, &Br, &fBr);
        v_sel(&fBi, &done, &Bi, &fBi);
        *conv |= done;
        live &= ~done;
        if (j % 4 == 0) {
            /* by 2^-e, 2^e <= |Br| + |Bi| < 2^(e+1) (lanes not live may
             * hold anything: their scale is never used) */
            v4d m, t;
            v_abs(&Br, &m);
            v_abs(&Bi, &t);
            m = m + t;
            const v4u eb = ((v4u) m >> 52) & 2047;
            const v4d sc = (v4d) ((2046 - eb) << 52), sc2 = sc * sc;
            pAr = pAr * sc;
            pAi = pAi * sc;
            Ar = Ar * sc;
            Ai = Ai * sc;
            pBr = pBr * sc;
            pBi = pBi * sc;
            Br = Br * sc;
            Bi = Bi * sc;
            q2 = q2 * (sc2 * sc2);
        }
    }
    /* G = B / A */
    const v4d an = fAr * fAr + fAi * fAi;
    *Gr = (fBr * fAr + fBi * fAi) / an;
    *Gi = (fBi * fAr - fBr * fAi) / an;
}

/* G(z) = e^z E1(z) for Re z >= 0, z != 0, to about 1e-16 of |G|: the
 * series -gamma - ln z - sum (-z)^k / (k k!) (times e^z) for |z| < 1.5,
 * else the continued fraction 1/(z + 1 - 1/(z + 3 - 4/(z + 5 - ...)))
 * by the modified Lentz method. Returns 0, or -1 when it did not converge
 * (the caller integrates instead). */
static int g_e1(double complex z, double complex *out)
{
    const double zr = creal(z), zi = cimag(z), r2 = zr * zr + zi * zi;
    if (r2 < 1.5 * 1.5) {
        /* Horner: sum_k w_k z^k = z (w_1 + z (w_2 + ...)) */
        const int n = lamp_terms(r2);
        double sr = lamp_w[n], si = 0;
        for (int k = n - 1; k >= 1; --k) {
            const double tr = lamp_w[k] + zr * sr - zi * si;
            si = zr * si + zi * sr;
            sr = tr;
        }
        const double complex sum = (zr * sr - zi * si) + I * (zr * si + zi * sr);
        *out = cexp(z) * (-0.57721566490153286061 - clog(z) - sum);
        return 0;
    }
    /* the continued fraction: lamp_cf4's, one lane used */
    const v4d vr = { zr, zr, zr, zr }, vi = { zi, zi, zi, zi };
    const v4di live = { -1, -1, -1, -1 };
    v4d Gr, Gi;
    v4di conv;
    lamp_cf4(&vr, &vi, &live, &Gr, &Gi, &conv);
    if (!conv[0])
        return -1;
    *out = Gr[0] + I * Gi[0];
    return 0;
}

/* Sun, Ramamoorthi, Narasimhan and Nayar's closed form for a point lamp
 * of radius 0 in uniform fog with the isotropic phase, over [a, D]:
 *   int e^-(sigma (t + d)) / d^2 dt = (2 / h) Im[F(w_a) - F(w_D)],
 *   F(w) = e^-(sigma (t + d)) G(sigma (t - ts + d) - i sigma h),
 * with w = tan(xi) + sec(xi) = (t - ts + d) / h (the equiangular xi in
 * the half angle: 2 int e^-(A w) / (1 + w^2) dw, A = sigma h) and the
 * exponential integral of the complex argument in place of their table.
 * t - ts + d is formed as h^2 / (d - (t - ts)) behind the lamp (no
 * cancellation). Adds to S per channel scat[k] e[k] times it, and to E
 * the rounding of the two ends (2e-15 of their magnitudes); returns 0,
 * or -1 (nothing added) where G does not converge or the two ends cancel
 * to more than a tenth of the result's digits at 1e-13 (short segments,
 * a lamp far off the segment's end): the caller integrates then. */
/* (2 / h) Im[F(w_a) - F(w_D)] for two finite ends whose z = sig (p - i h)
 * (p = t - ts + d) both lie inside the series' circle |z| < 1.5, into *r,
 * and its rounding into *err; returns 0, or -1 when they do not. There
 * x e^z = e^-(sig ts) at both ends, so
 *   F(w_a) - F(w_D) = e^-(sig ts) e^-(i sig h) (log(z_D / z_a) + sum_k
 *                     (-1)^k (z_D^k - z_a^k) / (k k!)),
 * with no cexp or clog per end, and no difference of the ends' values:
 * z_D - z_a = sig dp is real (dp = p_D - p_a as the caller forms it),
 * |z_D|^2 - |z_a|^2 = sig dp (Re z_a + Re z_D), arg(z_D / z_a) from
 * z_D conj(z_a), and z_D^k - z_a^k = z_D P_(k-1) + (z_D - z_a) z_a^(k-1).
 * Near ends (a short segment far from the lamp) keep their digits. */
static int lamp_series_pair(double sg, double ts, double h, double pa, double pD, double dp,
                            double *r, double *err)
{
    const double ar = sg * pa, dr = sg * pD, zi = -sg * h, dz = sg * dp;
    const double na = ar * ar + zi * zi, nd = dr * dr + zi * zi;
    if (!(na < 2.25 && nd < 2.25) || !(na > 0) || !(sg * ts > -700))
        return -1;
    const double lr = 0.5 * log1p(dz * (ar + dr) / na);
    const double li = atan2(-zi * dz, ar * dr + zi * zi);
    /* Horner at z_D with the divided difference (p(z_D) - p(z_a)) / dz
     * alongside: q <- b + z_a q, b <- w_k + z_D b */
    const int n = lamp_terms(na > nd ? na : nd);
    double br = lamp_w[n], bi = 0, qr = 0, qi = 0;
    for (int k = n - 1; k >= 0; --k) {
        const double nqr = br + ar * qr - zi * qi, nqi = bi + ar * qi + zi * qr;
        const double nbr = lamp_w[k] + dr * br - zi * bi, nbi = dr * bi + zi * br;
        qr = nqr;
        qi = nqi;
        br = nbr;
        bi = nbi;
    }
    const double complex V = (lr + dz * qr) + I * (li + dz * qi);
    const double c = cos(sg * h), sn = sin(sg * h), f = 2 / h * exp(-sg * ts);
    *r = f * (c * cimag(V) - sn * creal(V));
    *err = f * sqrt(norm2(V)) * 1e-15;
    return isfinite(*r) ? 0 : -1;
}

/* One channel of lamp_closed for one segment: the integral per unit of
 * scat e over [a, D] into *r and its rounding into *re, by the series pair
 * where both ends lie in its circle and its rounding allows, else from
 * the two ends' G (series or continued fraction). Returns 0, or -1 where
 * G does not converge or the ends cancel (the caller integrates). The
 * scalar form, for the segments lamp_kernel leaves. */
static int lamp_unit1(double sg, double ts, double h, double a, double D, double *r, double *re)
{
    if (isfinite(D)) {
        /* both ends near the lamp's scale: the series pair */
        const double ua = a - ts, uD = D - ts, da = len2(ua, h), dD = len2(uD, h);
        const double pa = ua >= 0 ? ua + da : h * h / (da - ua);
        const double pD = uD >= 0 ? uD + dD : h * h / (dD - uD);
        if (lamp_series_pair(sg, ts, h, pa, pD, (D - a) * (pa + pD) / (da + dD), r, re) == 0 &&
            *re <= 1e-13 * fabs(*r))
            return 0;
    }
    double v[2] = { 0, 0 }, mag = 0;
    const double ends[2] = { a, D };
    for (int i = 0; i < 2; ++i) {
        const double t = ends[i];
        if (!isfinite(t))
            continue;   /* F(inf) = 0 */
        const double u = t - ts, d = len2(u, h);
        const double w = u >= 0 ? u + d : h * h / (d - u);   /* h w, really */
        double complex G;
        if (g_e1(sg * w - I * (sg * h), &G))
            return -1;
        const double x = exp(-sg * (t + d));
        v[i] = x == 0 ? 0 : x * cimag(G);
        mag += x == 0 ? 0 : x * sqrt(norm2(G));
    }
    *r = 2 / h * (v[0] - v[1]);
    *re = 2 / h * mag * 2e-15;   /* the ends' rounding */
    return *re <= 1e-13 * fabs(*r) && isfinite(*r) ? 0 : -1;
}

/* Four segments of one lamp at once: their ts, h (> 0) and ends a < D
 * (D may be infinite), one sigma. */
typedef struct lamp4 {
    double ts[4], h[4], a[4], D[4];
} lamp4;

/* (or, oi) = (ar, ai) (br, bi), complex, per lane */
EF_INLINE void cmul4(const v4d *ar, const v4d *ai, const v4d *br, const v4d *bi, v4d *or,
                     v4d *oi)
{
    const v4d r = *ar * *br - *ai * *bi, i = *ar * *bi + *ai * *br;
    *or = r;
    *oi = i;
}

/* One of lamp_poly4's chains: X(v) = sum_n lamp_w[i0 + 4 n] v^n, n =
 * 0..top, by Horner at v into b, and with pair its divided difference
 * [X](v, va) into q (q <- b + va q beside b <- w + v b). */
EF_INLINE void lamp_chain4(int i0, int top, const v4d *vr, const v4d *vi, const v4d *var,
                           const v4d *vai, int pair, v4d b[2], v4d q[2])
{
    const v4d zero = { 0, 0, 0, 0 };
    v4d br = zero + lamp_w[i0 + 4 * top], bi = zero, qr = zero, qi = zero;
    for (int n = top - 1; n >= 0; --n) {
        if (pair) {
            const v4d nqr = br + (*var * qr - *vai * qi), nqi = bi + (*var * qi + *vai * qr);
            qr = nqr;
            qi = nqi;
        }
        const v4d nbr = lamp_w[i0 + 4 * n] + (*vr * br - *vi * bi), nbi = *vr * bi + *vi * br;
        br = nbr;
        bi = nbi;
    }
    b[0] = br;
    b[1] = bi;
    q[0] = qr;
    q[1] = qi;
}

/* o = (a + u b) t + c, complex (index 0 real, 1 imaginary), per lane:
 * one step of [A(u) + u B(u)](u, ua) = ([A] + ua [B]) (u + ua) + B(u) */
EF_INLINE void lamp_dd4(const v4d u[2], const v4d a[2], const v4d b[2], const v4d t[2],
                        const v4d c[2], v4d o[2])
{
    v4d x0, x1, y0, y1;
    cmul4(&u[0], &u[1], &b[0], &b[1], &x0, &x1);
    x0 = a[0] + x0;
    x1 = a[1] + x1;
    cmul4(&x0, &x1, &t[0], &t[1], &y0, &y1);
    o[0] = y0 + c[0];
    o[1] = y1 + c[1];
}

/* P(z) = sum_k w_k z^k over all of lamp_w (21 terms: 1e-17 at |z| = 1.5,
 * more than needed nearer 0, but the same steps for every lane, so that a
 * lane's value never depends on its neighbours; per-lane counts measured
 * no faster) into P, or with pair the divided difference [P](z, za) =
 * (P(z) - P(za)) / (z - za) without that difference's cancellation. The
 * weights split four ways, P(z) = EE(v) + u EO(v) + z (OE(v) + u OO(v)),
 * u = z^2, v = u^2: four independent chains of five steps (rather than
 * one Horner's twenty dependent ones), and [P] from the
 * chains' divided differences by [A(u) + u B(u)](uD, ua) = [A] (uD + ua)
 * ... applied twice: [E](u, ua) = [EE](v, va) t + EO(v) + ua [EO](v, va) t,
 * t = u + ua, and [P] = [E] s + O(u) + za [O] s, s = z + za. */
EF_INLINE void lamp_poly4(const v4d *zr, const v4d *zi, const v4d *zar, const v4d *zai,
                          int pair, v4d *Pr, v4d *Pi)
{
    v4d ur, ui, vr, vi, uar = *zr, uai = *zi, var = *zr, vai = *zi;
    cmul4(zr, zi, zr, zi, &ur, &ui);
    cmul4(&ur, &ui, &ur, &ui, &vr, &vi);
    if (pair) {
        cmul4(zar, zai, zar, zai, &uar, &uai);
        cmul4(&uar, &uai, &uar, &uai, &var, &vai);
    }
    v4d ee[2], eo[2], oe[2], oo[2], qee[2], qeo[2], qoe[2], qoo[2];
    lamp_chain4(0, 5, &vr, &vi, &var, &vai, pair, ee, qee);
    lamp_chain4(2, 4, &vr, &vi, &var, &vai, pair, eo, qeo);
    lamp_chain4(1, 5, &vr, &vi, &var, &vai, pair, oe, qoe);
    lamp_chain4(3, 4, &vr, &vi, &var, &vai, pair, oo, qoo);
    v4d t0, t1;
    cmul4(&ur, &ui, &oo[0], &oo[1], &t0, &t1);
    const v4d Or = oe[0] + t0, Oi = oe[1] + t1;   /* O(u) */
    if (!pair) {
        v4d x0, x1;
        cmul4(&ur, &ui, &eo[0], &eo[1], &t0, &t1);
        cmul4(zr, zi, &Or, &Oi, &x0, &x1);
        *Pr = (ee[0] + t0) + x0;
        *Pi = (ee[1] + t1) + x1;
        return;
    }
    const v4d t[2] = { ur + uar, ui + uai }, sz[2] = { *zr + *zar, *zi + *zai },
              ua[2] = { uar, uai }, za[2] = { *zar, *zai }, O[2] = { Or, Oi };
    /* [E] and [O] over (u, ua), then [P] = ([E] + za [O]) s + O(u) */
    v4d dE[2], dO[2], P[2];
    lamp_dd4(ua, qee, qeo, t, eo, dE);
    lamp_dd4(ua, qoe, qoo, t, oo, dO);
    lamp_dd4(za, dE, dO, sz, O, P);
    *Pr = P[0];
    *Pi = P[1];
}

/* sqrt(x^2 + y^2) per lane, and in ok whether len2 takes that form (its
 * magnitudes within 1e-150 .. 1e150), so that the value is len2's. */
EF_INLINE void len2_4(const v4d *x, const v4d *y, v4d *o, v4di *ok)
{
    v4d ax, ay;
    v_abs(x, &ax);
    v_abs(y, &ay);
    const v4di xbig = ax > ay;
    v4d m;
    v_sel(&m, &xbig, &ax, &ay);   /* NaN: ay, which fails below as len2's does */
    const v4d s = *x * *x + *y * *y;
    v_sqrt(&s, o);
    *ok = (m < 1e150) & (m > 1e-150);
}

/* lamp_unit1 for four lanes on vectors: the series pair as
 * lamp_series_pair computes it; where that is not taken, the two ends'
 * F = e^-(sg ts) e^-(i sg h) E1(z) (x e^z = e^-(sg ts) at every end: one
 * exp and one sincos per segment, E1 = -gamma - log z - series), each end
 * inside the series' circle. st[i]: 1 done (r, re), -1 the ends cancel
 * (the caller integrates), 0 left to lamp_unit1 (an end outside the
 * circle, or a value beyond vmath.h's ranges). */
EF_INLINE void lamp_kernel(double sg, const lamp4 *in, v4d *r, v4d *re, v4di *st)
{
    v4d ts, h, a, D;
    memcpy(&ts, in->ts, sizeof ts);
    memcpy(&h, in->h, sizeof h);
    memcpy(&a, in->a, sizeof a);
    memcpy(&D, in->D, sizeof D);
    const v4di finD = D < INFINITY;
    const v4d zero = { 0, 0, 0, 0 }, ua = a - ts, uD0 = D - ts;
    v4d uD;
    v_sel(&uD, &finD, &uD0, &zero);   /* no inf - inf below */
    v4d da, dD;
    v4di okA, okD;
    len2_4(&ua, &h, &da, &okA);
    len2_4(&uD, &h, &dD, &okD);
    const v4d h2 = h * h, paf = ua + da, pab = h2 / (da - ua), pDf = uD + dD,
              pDb = h2 / (dD - uD);
    v4d pa, pD;
    const v4di fa = ua >= 0.0, fD = uD >= 0.0;
    v_sel(&pa, &fa, &paf, &pab);
    v_sel(&pD, &fD, &pDf, &pDb);
    const v4d dp = (D - a) * (pa + pD) / (da + dD);
    const v4d ar = sg * pa, dr = sg * pD, zi = -sg * h, dz = sg * dp;
    const v4d na = ar * ar + zi * zi, nd = dr * dr + zi * zi, sts = sg * ts;
    /* the vector functions' ranges: exp's argument, log's normal inputs;
     * each end by the series inside its circle, else by the continued
     * fraction with e^-(sg (t + d)) */
    const v4di sts_ok = (sts > -700.0) & (sts < 700.0);
    const v4di ser_a = (na > 1e-200) & (na < 2.25), ser_D = (nd > 1e-200) & (nd < 2.25);
    const v4d xa_arg = sg * (a + da), xD_arg = sg * (D + dD);
    const v4di cf_a = (na >= 2.25) & (na < 1e300) & (xa_arg < 700.0);
    const v4di cf_D = (nd >= 2.25) & (nd < 1e300) & (xD_arg < 700.0);
    const v4di pair = okA & okD & finD & sts_ok & ser_a & ser_D;
    const v4di ends = okA & ((ser_a & sts_ok) | cf_a) &
                      (~finD | (okD & ((ser_D & sts_ok) | cf_D)));
    const v4d msts = -sts, sgh = sg * h;
    v4d E, sn, cs;
    v_exp(&msts, &E);
    v_sincos(&sgh, &sn, &cs);
    const v4d h2h = 2.0 / h, f = h2h * E;
    v4d rp = zero, rpe = zero;
    v4di done = { 0, 0, 0, 0 };
    if (v_any(&pair)) {
        const v4d x1 = dz * (ar + dr) / na, y = -zi * dz, x = ar * dr + zi * zi;
        v4d lr, li;
        v_log1p(&x1, &lr);
        lr = lr * 0.5;
        v_atan2(&y, &x, &li);
        v4d qr, qi;   /* [P](z_D, z_a) */
        lamp_poly4(&dr, &zi, &ar, &zi, 1, &qr, &qi);
        const v4d Vr = lr + dz * qr, Vi = li + dz * qi;
        rp = f * (cs * Vi - sn * Vr);
        v4d m2 = Vr * Vr + Vi * Vi;
        v_sqrt(&m2, &m2);
        rpe = f * m2 * 1e-15;
        v4d arp;
        v_abs(&rp, &arp);
        done = pair & (arp < INFINITY) & (rpe <= 1e-13 * arp);
    }
    v4d re2 = zero, ree = zero;
    const v4di need = ends & ~done;
    v4di bad = { 0, 0, 0, 0 };   /* a continued fraction that did not converge */
    if (v_any(&need)) {
        /* Im F and |F| at each end (D's where finite), then their
         * difference and sum */
        v4d V = zero, mag = zero;
        for (int e = 0; e < 2; ++e) {
            const v4d zr = e ? dr : ar, r2 = e ? nd : na, xarg = e ? xD_arg : xa_arg;
            /* (the far end only where it is finite) */
            const v4di ser = (e ? ser_D & finD : ser_a) & need,
                       cf = (e ? cf_D & finD : cf_a) & need;
            v4d vi = zero, m = zero;
            if (v_any(&ser)) {
                v4d lg, th;
                v_log(&r2, &lg);
                v_atan2(&zi, &zr, &th);
                v4d sumr, sumi;
                lamp_poly4(&zr, &zi, &zr, &zi, 0, &sumr, &sumi);
                const v4d Er = (-0.57721566490153286061 - 0.5 * lg) - sumr, Ei = -th - sumi;
                v4d m2 = Er * Er + Ei * Ei;
                v_sqrt(&m2, &m2);
                const v4d svi = E * (cs * Ei - sn * Er), sm = E * m2;
                v_sel(&vi, &ser, &svi, &vi);
                v_sel(&m, &ser, &sm, &m);
            }
            if (v_any(&cf)) {
                v4d Gr, Gi, x;
                v4di conv;
                lamp_cf4(&zr, &zi, &cf, &Gr, &Gi, &conv);
                bad |= cf & ~conv;
                const v4d mx = -xarg;
                v_exp(&mx, &x);
                v4d m2 = Gr * Gr + Gi * Gi;
                v_sqrt(&m2, &m2);
                const v4d cvi = x * Gi, cm = x * m2;
                v_sel(&vi, &cf, &cvi, &vi);
                v_sel(&m, &cf, &cm, &m);
            }
            if (e == 0) {
                V = vi;
                mag = m;
            } else {
                const v4d dV = V - vi, dm = mag + m;
                v_sel(&V, &finD, &dV, &V);
                v_sel(&mag, &finD, &dm, &mag);
            }
        }
        re2 = h2h * V;
        ree = h2h * mag * 2e-15;
    }
    /* as vectors: their lanes are read as vectors next */
    v4d are2;
    v_abs(&re2, &are2);
    const v4di one = { 1, 1, 1, 1 }, ok = ~bad & (ree <= 1e-13 * are2) & (are2 < INFINITY);
    v_sel(r, &done, &rp, &re2);
    v_sel(re, &done, &rpe, &ree);
    *st = (done & one) | (need & ~done & ((ok & one) | (~ok & -one)));
}

/* lamp_closed for four segments of one medium (sig, scat) and lamp (e),
 * lamp_kernel's lanes with lamp_unit1 for those it leaves: for each lane
 * i < m whose every channel holds (st[i] 0), S[k][idx[i]] and (E not
 * NULL) E[k][idx[i]] set to the sums from 0 that ef_light_inscatter forms;
 * st[i] -1 and nothing written where a channel's closed form does not
 * hold (the caller integrates). */
EF_INLINE void lamp_rays4_in(const double sig[3], const double scat[3], const double e[3],
                             const lamp4 *in, int m, const int *idx, double *const S[3],
                             double *const E[3], int st[4])
{
    const v4d zero = { 0, 0, 0, 0 };
    v4d out[3], err[3];
    /* the integral per unit of scat e, and its rounding, at sig[have]:
     * channels of the same sigma take it (grey fog, coloured lamps) */
    v4d unit = zero, unit_e = zero;
    v4di stv = { 0, 0, 0, 0 };
    int have = -1;
    for (int k = 0; k < 3; ++k) {
        if (!(sig[k] > 0) || scat[k] == 0 || e[k] == 0) {
            out[k] = err[k] = zero;
            continue;
        }
        if (have < 0 || sig[k] != sig[have]) {
            v4di ust;
            lamp_kernel(sig[k], in, &unit, &unit_e, &ust);
            stv |= ust == -1;
            const v4di left = ust == 0;
            if (v_any(&left)) {   /* rare: lamp_unit1 for those lanes */
                double u[4], ue[4];
                memcpy(u, &unit, sizeof u);
                memcpy(ue, &unit_e, sizeof ue);
                for (int i = 0; i < 4; ++i)
                    if (left[i] && lamp_unit1(sig[k], in->ts[i], in->h[i], in->a[i], in->D[i],
                                              &u[i], &ue[i]))
                        stv[i] = -1;
                memcpy(&unit, u, sizeof u);
                memcpy(&unit_e, ue, sizeof ue);
            }
            have = k;
        }
        out[k] = unit * scat[k] * e[k];
        err[k] = E ? unit_e * scat[k] * e[k] : zero;
    }
    for (int i = 0; i < 4; ++i)
        st[i] = (int) stv[i];
    /* 0.0 + x: a -0 sum from 0, as ef_light_inscatter's */
    if (m == 4 && idx[3] == idx[0] + 3 && !v_any(&stv)) {
        for (int k = 0; k < 3; ++k) {
            const v4d o = 0.0 + out[k];
            memcpy(S[k] + idx[0], &o, sizeof o);
            if (E) {
                const v4d oe = 0.0 + err[k];
                memcpy(E[k] + idx[0], &oe, sizeof oe);
            }
        }
        return;
    }
    for (int i = 0; i < m; ++i)
        if (st[i] == 0)
            for (int k = 0; k < 3; ++k) {
                S[k][idx[i]] = 0.0 + out[k][i];
                if (E)
                    E[k][idx[i]] = 0.0 + err[k][i];
            }
}

/* lamp_rays4_in, dispatched (one segment at a time: lamp_closed) */
EF_MULTIVERSION static void lamp_rays4(const double sig[3], const double scat[3],
                                       const double e[3], const lamp4 *in, int m,
                                       const int *idx, double *const S[3], double *const E[3],
                                       int st[4])
{
    lamp_rays4_in(sig, scat, e, in, m, idx, S, E, st);
}

/* The uniform fog's extinction sig (its components' sum, in their order)
 * and isotropic scattering scat per channel, as inscatter_range gives
 * them to lamp_closed. */
static void lamp_medium(const ef_fog_scene *s, double sig[3], double scat[3])
{
    for (int k = 0; k < 3; ++k)
        sig[k] = scat[k] = 0;
    for (int i = 0; i < s->ncomp; ++i)
        for (int k = 0; k < 3; ++k) {
            sig[k] += s->comp[i].p[k];
            if (s->comp[i].p[k] > 0)
                scat[k] += s->comp[i].p[k] * albedo(&s->comp[i], k) / (4 * PI);
        }
}

/* lamp_rays4 for one segment (its lanes all alike): the same bits as the
 * segment in any lane of a span's batch, added to S and E (0 here: a
 * point lamp's one lit range). Returns 0, or -1 with nothing added. */
static int lamp_closed(const double sig[3], const double scat[3], const double e[3], double ts,
                       double h, double a, double D, double S[3], double E[3])
{
    const lamp4 in = { { ts, ts, ts, ts }, { h, h, h, h }, { a, a, a, a }, { D, D, D, D } };
    double Sv[3], Ev[3];
    double *const Sk[3] = { &Sv[0], &Sv[1], &Sv[2] }, *const Ek[3] = { &Ev[0], &Ev[1], &Ev[2] };
    const int idx = 0;
    int st[4];
    lamp_rays4(sig, scat, e, &in, 1, &idx, Sk, Ek, st);
    if (st[0])
        return -1;
    for (int k = 0; k < 3; ++k) {
        S[k] += Sv[k];
        E[k] += Ev[k];
    }
    return 0;
}

/* --------------------------------------------------------------- driver */

#define MAX_CUTS 512

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return (x > y) - (x < y);
}

/* Where the view segment [0, D) crosses the components' features (the
 * density's jumps, kinks and fronts), appended to cut. */
static int feature_cuts(const ef_fog_scene *s, const ef_ray *r, double a, double D, double *cut,
                        int n)
{
    for (int i = 0; i < s->ncomp && n < MAX_CUTS - 8; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->features || !c->model->functionals)
            continue;
        const int nf = c->model->functionals(c, NULL, 0), nt = c->model->features(c, NULL, 0);
        if (nf <= 0 || nt <= 0 || nf > 256 || nt > 256)
            continue;
        ef_fog_functional f[256];
        ef_fog_feature ft[256];
        c->model->functionals(c, f, nf);
        c->model->features(c, ft, nt);
        for (int j = 0; j < nt && n < MAX_CUTS - 8; ++j) {
            const ef_fog_functional *F = &f[ft[j].f];
            const double v0 = F->n[0] * r->org[0] + F->n[1] * r->org[1] + F->n[2] * r->org[2] + F->d;
            const double rate = F->n[0] * r->dir[0] + F->n[1] * r->dir[1] + F->n[2] * r->dir[2];
            const double t = (ft[j].value - v0) / rate;
            if (t > a && t < D)
                cut[n++] = t;
        }
    }
    return n;
}

/* Cuts at ts +- st 4^j inside (a, D), from st until past the segment. */
static int steps_around(double *cut, int n, double ts, double a, double D, double st)
{
    for (; n < MAX_CUTS - 4; st *= 4) {
        if (ts + st > a && ts + st < D)
            cut[n++] = ts + st;
        if (ts - st > a && ts - st < D)
            cut[n++] = ts - st;
        if (!(st < 1e300) || st > fabs(ts) + (isfinite(D) ? D : 0))
            break;
    }
    return n;
}

/* Where the ray crosses the spot's cones cos alpha = c (c = its edge, and
 * its blend band's inner edge), appended to cut. */
static int cone_cuts(const ef_light *l, const ef_ray *r, double a, double D, double *cut, int n)
{
    double w[3];
    for (int a = 0; a < 3; ++a)
        w[a] = r->org[a] - l->pos[a];   /* y(t) = w + t v, from the lamp */
    const double a0 = w[0] * l->dir[0] + w[1] * l->dir[1] + w[2] * l->dir[2];
    const double a1 = r->dir[0] * l->dir[0] + r->dir[1] * l->dir[1] + r->dir[2] * l->dir[2];
    const double ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    const double wv = w[0] * r->dir[0] + w[1] * r->dir[1] + w[2] * r->dir[2];
    const double cs[2] = { l->cos_outer, l->cos_outer + l->smooth };
    for (int i = 0; i < 2; ++i) {
        const double c = cs[i], c2 = c * c;
        /* (a0 + a1 t)^2 = c^2 |w + t v|^2 */
        const double A = a1 * a1 - c2, B = 2 * (a0 * a1 - c2 * wv), C = a0 * a0 - c2 * ww;
        double roots[2];
        int nr = 0;
        if (fabs(A) > 1e-300) {
            const double disc = B * B - 4 * A * C;
            if (disc >= 0) {
                const double sq = sqrt(disc), qq = -0.5 * (B + (B >= 0 ? sq : -sq));
                roots[nr++] = qq / A;
                if (qq != 0)
                    roots[nr++] = C / qq;
            }
        } else if (B != 0) {
            roots[nr++] = -C / B;
        }
        for (int j = 0; j < nr; ++j)
            if (roots[j] > a && roots[j] < D && (a0 + a1 * roots[j]) * c >= 0 && n < MAX_CUTS)
                cut[n++] = roots[j];
    }
    return n;
}

/* Relative accuracy aimed at: the uniform fog's integrand costs a few
 * exponentials, the general one optical depths along two rays per node. */
#define REL_UNIFORM 1e-13
#define REL_GENERAL 1e-10

/* ------------------------------------------------------- lit noise fog
 *
 * Where a component's optical depth is not a closed form (noise), the
 * integrand sigma T is as rough as the noise, but what light adds to it is
 * not: S = sum_c int h_c dmu_c, with mu_c the component's own share of the
 * view ray's extinction (dmu_c = sigma_c T_c(0,t) dt, its pieces from the
 * model's optical depths, so within the noise method's tolerance) and h_c
 * = albedo_c p_c(theta) E T_light V T_rest(0,t), smooth between the cuts
 * (T_rest: the other components' transmittance). Steps forward along the
 * ray: each step's quarters give h at five points placed at their own
 * coordinates s = mu(t) (known), the quadratic through three of them
 * integrated in s over each half and over the whole, and Richardson's
 * difference of the two levels the step's estimate; a step whose estimate
 * passes tol of its own light (plus 2^-6 of what came before) is halved,
 * the next grows with the fifth root of the margin. The noise calls'
 * estimates (4 sigma each, independent) add in quadrature. */

#define NZ_STEPS 4096

typedef struct nz_pt {
    double t, cth, G[3], gerr;   /* E T_light (spot share) per channel, T_light's tau error */
} nz_pt;

/* The point at t of r for light l: its light before scattering. */
static void nz_point(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double t,
                     nz_pt *p)
{
    p->t = t;
    p->gerr = 0;
    p->G[0] = p->G[1] = p->G[2] = 0;
    p->cth = 0;
    double x[3], ld[3], dl = INFINITY, f = 1;
    for (int a = 0; a < 3; ++a)
        x[a] = r->org[a] + t * r->dir[a];
    if (l->kind == EF_LIGHT_SUN) {
        memcpy(ld, l->dir, sizeof ld);
        p->cth = ld[0] * r->dir[0] + ld[1] * r->dir[1] + ld[2] * r->dir[2];
    } else {
        double y[3], d2 = 0;
        for (int a = 0; a < 3; ++a) {
            y[a] = (l->pos[a] - r->org[a]) - t * r->dir[a];
            d2 += y[a] * y[a];
        }
        dl = sqrt(d2);
        if (!(dl > 0))
            return;
        for (int a = 0; a < 3; ++a)
            ld[a] = y[a] / dl;
        p->cth = ld[0] * r->dir[0] + ld[1] * r->dir[1] + ld[2] * r->dir[2];
        f = 1 / (d2 + l->radius * l->radius);
        if (l->kind == EF_LIGHT_SPOT)
            f *= ef_spot_share(l, -(ld[0] * l->dir[0] + ld[1] * l->dir[1] + ld[2] * l->dir[2]));
        if (f == 0)
            return;
    }
    double tl[3] = { 0, 0, 0 };
    ef_ray lr = { { ld[0], ld[1], ld[2] }, dl, dl, { x[0], x[1], x[2] } };
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double v[3];
        if (c->model->tau_info) {
            ef_tau_info in;
            c->model->tau_info(c, &lr, v, &in);
            p->gerr += fmax(in.err[0], fmax(in.err[1], in.err[2]));
        } else {
            c->model->tau(c, &lr, v);
        }
        for (int k = 0; k < 3; ++k)
            tl[k] += v[k];
    }
    for (int k = 0; k < 3; ++k) {
        const double e = exp(-tl[k]);
        p->G[k] = e == 0 || l->e[k] == 0 ? 0 : l->e[k] * f * e;
    }
}

/* Optical depth of each component over [t0, t1] of r into tau (ncomp x
 * 3), the noise methods' error estimates summed into *err. The view ray's
 * pieces go at 1/16 of each model's tolerance: their errors add up along
 * the ray in T(0, t) (over ~100 steps, to ~10 tol at the model's own),
 * where the light paths' errors are independent and average out. */
static void nz_taus(const ef_fog_scene *s, const ef_ray *r, double t0, double t1,
                    double (*tau)[3], double *err)
{
    ef_ray sub = *r;
    for (int a = 0; a < 3; ++a)
        sub.org[a] = r->org[a] + t0 * r->dir[a];
    sub.dist = sub.planar = t1 - t0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (c->model->tau_tol && c->model->lit_tol) {
            ef_tau_info in;
            c->model->tau_tol(c, &sub, c->model->lit_tol(c) / 16, tau[i], &in);
            *err += fmax(in.err[0], fmax(in.err[1], in.err[2]));
        } else if (c->model->tau_info) {
            ef_tau_info in;
            c->model->tau_info(c, &sub, tau[i], &in);
            *err += fmax(in.err[0], fmax(in.err[1], in.err[2]));
        } else {
            c->model->tau(c, &sub, tau[i]);
        }
    }
}

/* int h ds over [0, S] from h0, h1, h2 at s = 0, p, S: the quadratic's
 * integral, or the two trapezoids where p leaves one side too thin for it
 * (and *low set). */
static double nz_rule(double h0, double h1, double h2, double p, double S, int *low)
{
    if (!(p > 0.05 * S && p < 0.95 * S)) {
        *low = 1;
        return 0.5 * (h0 + h1) * p + 0.5 * (h1 + h2) * (S - p);
    }
    const double x = p / S;   /* in (0.05, 0.95): no overflow, no underflow */
    return S * ((3 * x - 1) / (6 * x) * h0 + h1 / (6 * x * (1 - x)) +
                (2 - 3 * x) / (6 * (1 - x)) * h2);
}

/* The relative accuracy lit fog aims at through s's rough components:
 * the finest their models promise (each model's lit_tol). */
static double nz_tol(const ef_fog_scene *s)
{
    double rel = INFINITY;
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->lit_tol)
            rel = fmin(rel, s->comp[i].model->lit_tol(&s->comp[i]));
    return isfinite(rel) ? fmax(rel, 1e-12) : EF_NOISE_DEFAULT_TOL;
}

/* Adds to S light l's in-scatter over [a, D] of r (T counted from r's
 * origin; D may be INFINITY) with a rough component in s, and its error
 * estimate to E. */
static void noise_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                        double D, double S[3], double E[3])
{
    const int nc = s->ncomp;
    double cum[EF_FOG_MAX_COMPONENTS][3], tq[4][EF_FOG_MAX_COMPONENTS][3];
    double cum_var = 0, hb = 0;   /* the running tau error's square, a bound on h / T */
    double rss[3] = { 0, 0, 0 };  /* the independent errors' squares */
    const double rel = nz_tol(s);
    if (a > 0) {
        nz_taus(s, r, 0, a, cum, &cum_var);   /* one call: its estimate, squared */
        cum_var *= cum_var;
    } else {
        for (int i = 0; i < nc; ++i)
            cum[i][0] = cum[i][1] = cum[i][2] = 0;
    }
    /* the cuts: the densities' features, and a lamp's closest approach
     * with geometric steps around it (and a spot's cone); hb bounds h / T */
    double cut[MAX_CUTS];
    int n = 0;
    cut[n++] = a;
    n = feature_cuts(s, r, a, D, cut, n);
    double pmax = 0, amax = 0;
    for (int i = 0; i < nc; ++i) {
        pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, 1));
        pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, -1));
        pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, 0));
        for (int k = 0; k < 3; ++k)
            amax = fmax(amax, albedo(&s->comp[i], k));
    }
    double emax = fmax(l->e[0], fmax(l->e[1], l->e[2]));
    if (l->kind != EF_LIGHT_SUN) {
        double w[3], ts, h;
        lamp_line(l, r, w, &ts, &h);
        const double hq = len2(h, l->radius);
        if (!isfinite(ts) || !(hq <= DBL_MAX / 64))
            return;
        if (hq == 0 && ts >= a && ts <= D) {
            for (int k = 0; k < 3; ++k)
                if (l->e[k] > 0)
                    S[k] = INFINITY;
            return;
        }
        if (ts > a && ts < D)
            cut[n++] = ts;
        n = steps_around(cut, n, ts, a, D, hq > 0 ? hq : 1e-9 * fmax(fabs(ts), 1));
        if (l->kind == EF_LIGHT_SPOT)
            n = cone_cuts(l, r, a, D, cut, n);
        emax /= hq * hq;
    }
    hb = amax * pmax * emax;
    if (isfinite(D))
        cut[n++] = D;
    qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
    /* Steps of at most a quarter of the rough components' coarsest
     * lattice cell at the default tol (the whole cell from 16 times it,
     * a sixteenth from 1/16 of it): the light's transmittance varies over
     * the noise's own scales (the light's path crosses other features as
     * the point moves), and Richardson's estimate only sees what a step's
     * five points resolve. Measured against the reference and tight-tol
     * runs (tests/test_lit_noise.c; a quarter cell: within 5e-5 on a
     * 10-unit ray at the ground where the whole cell was 0.4 % off). */
    double cap = INFINITY;
    for (int i = 0; i < nc; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->tau_info || !c->model->lattices)
            continue;
        ef_fog_lattice lt[64];
        const int nl = c->model->lattices(c, lt, 64);
        double big = 0;
        for (int j = 0; j < nl && j < 64; ++j)
            big = fmax(big, lt[j].period);
        if (big > 0)
            cap = fmin(cap, big * fmin(1, fmax(0.0625, 0.25 * sqrt(rel / EF_NOISE_DEFAULT_TOL))));
    }
    double Sum[3] = { 0, 0, 0 }, rest[3] = { 0, 0, 0 };
    double last_mass = INFINITY;   /* the last step's share of extinction */
    nz_pt pa;
    nz_point(s, l, r, a, &pa);
    double dt = 0;
    int steps = 0;
    for (int ci = 0; ci < n && steps < NZ_STEPS; ++ci) {
        if (ci + 1 == n && isfinite(D))
            break;
        const double c0 = cut[ci], c1 = ci + 1 < n ? cut[ci + 1] : INFINITY;
        if (!(c1 > c0))
            continue;
        double t = c0;
        dt = dt > 0 ? fmin(dt, c1 - c0) : isfinite(c1) ? c1 - c0 : fmax(c0, 1);
        last_mass = INFINITY;   /* past a cut (a box's face) the cap holds again */
        while (t < c1 && steps < NZ_STEPS) {
            /* what is left cannot show: T(0, t) times the bound on h */
            double T0max = 0;
            for (int k = 0; k < 3; ++k) {
                double tt = 0;
                for (int i = 0; i < nc; ++i)
                    tt += cum[i][k];
                T0max = fmax(T0max, exp(-tt));
            }
            double left = hb * T0max;
            if (isinf(c1)) {
                /* the infinite tail: what is left of the ray's own
                 * extinction from t on, per channel */
                ef_ray tail = *r;
                for (int q = 0; q < 3; ++q)
                    tail.org[q] = r->org[q] + t * r->dir[q];
                tail.dist = tail.planar = INFINITY;
                rest[0] = rest[1] = rest[2] = 0;
                for (int i = 0; i < nc; ++i) {
                    double v[3];
                    s->comp[i].model->tau(&s->comp[i], &tail, v);
                    for (int k = 0; k < 3; ++k)
                        rest[k] += v[k];
                }
                left = 0;
                for (int k = 0; k < 3; ++k) {
                    double tt = 0;
                    for (int i = 0; i < nc; ++i)
                        tt += cum[i][k];
                    left = fmax(left, hb * exp(-tt) * -expm1(-fmax(rest[k], 0)));
                }
            }
            double smax = fmax(Sum[0], fmax(Sum[1], Sum[2]));
            if (!(left > 0.25 * rel * smax) || left < 1e-300) {
                for (int k = 0; k < 3; ++k)
                    E[k] += left;
                t = INFINITY;
                ci = n;
                break;
            }
            /* where a step can no longer matter, the cap is lifted */
            const double smax_ = fmax(Sum[0], fmax(Sum[1], Sum[2]));
            double b = t + (hb * last_mass <= 0x1p-6 * rel * smax_ ? dt : fmin(dt, cap));
            if (!(b < c1) || c1 - b < 1e-3 * dt)
                b = c1;
            ++steps;
            /* the step's quarters: each component's optical depth over
             * each, the light at their ends */
            double terr = 0;
            nz_pt pq[5];
            pq[0] = pa;
            for (int j = 1; j <= 4; ++j) {
                const double tj = j == 4 ? b : t + 0.25 * j * (b - t);
                nz_taus(s, r, j == 1 ? t : t + 0.25 * (j - 1) * (b - t), tj, tq[j - 1], &terr);
                nz_point(s, l, r, tj, &pq[j]);
            }
            double Q[3] = { 0, 0, 0 }, Qe[3] = { 0, 0, 0 }, hm[3] = { 0, 0, 0 };
            for (int i = 0; i < nc; ++i) {
                const ef_fog_component *c = &s->comp[i];
                double ph[5];
                for (int j = 0; j < 5; ++j)
                    ph[j] = ef_phase_eval(c->phase, c->g, pq[j].cth);
                for (int k = 0; k < 3; ++k) {
                    double other = 0, own = cum[i][k], h[5], mu[4];
                    for (int q = 0; q < nc; ++q)
                        other += q == i ? 0 : cum[q][k];
                    const double al = albedo(c, k), Ta = exp(-cum[i][k]);
                    double hmax = 0;
                    for (int j = 0; j < 5; ++j) {
                        if (j > 0) {
                            /* its share of the quarter's extinction */
                            mu[j - 1] = exp(-own) * -expm1(-tq[j - 1][i][k]);
                            for (int q = 0; q < nc; ++q)
                                other += q == i ? 0 : tq[j - 1][q][k];
                            own += tq[j - 1][i][k];
                        }
                        /* the other components' transmittance there (0
                         * light where they or the light's path are opaque:
                         * no inf * 0) */
                        const double tr = exp(-other);
                        h[j] = tr == 0 || pq[j].G[k] == 0 ? 0 : al * ph[j] * pq[j].G[k] * tr;
                        hmax = fmax(hmax, h[j]);
                    }
                    const double S2 = mu[0] + mu[1], S4 = S2 + mu[2] + mu[3];
                    if (!(S4 > 0))
                        continue;
                    int low = 0;
                    const double coarse = nz_rule(h[0], h[2], h[4], S2, S4, &low);
                    const double fine = nz_rule(h[0], h[1], h[2], mu[0], S2, &low) +
                                        nz_rule(h[2], h[3], h[4], mu[2], mu[2] + mu[3], &low);
                    Q[k] += fine;
                    /* Richardson: the order-4 rules' difference over 15;
                     * where a side was too thin for the quadratic, the
                     * trapezoids' (order 2) over 3 */
                    Qe[k] += fabs(fine - coarse) / (low ? 3 : 15);
                    hm[k] = fmax(hm[k], hmax * Ta);
                }
            }
            int ok = 1;
            for (int k = 0; k < 3; ++k)
                ok &= Qe[k] <= rel * (fabs(Q[k]) + 0x1p-6 * fabs(Sum[k])) + 1e-300 ||
                      !isfinite(Qe[k]);
            if (!ok && (b - t) > 1e-9 * fmax(fabs(t), 1) && steps < NZ_STEPS) {
                dt = 0.5 * (b - t);
                continue;
            }
            /* accepted: the step's light, its estimates, the next step.
             * The noise methods' estimates are 4 sigma of independent
             * errors: over many calls they add in quadrature. */
            double gerr = 0;
            for (int j = 0; j < 5; ++j)
                gerr = fmax(gerr, pq[j].gerr);
            for (int k = 0; k < 3; ++k) {
                Sum[k] += Q[k];
                E[k] += Qe[k] + fabs(Q[k]) * expm1(sqrt(cum_var));
                rss[k] += Q[k] * Q[k] * gerr * gerr + hm[k] * hm[k] * terr * terr;
            }
            cum_var += terr * terr;
            last_mass = 0;
            for (int k = 0; k < 3; ++k) {
                double before = 0, d = 0;
                for (int i = 0; i < nc; ++i) {
                    before += cum[i][k];
                    d += tq[0][i][k] + tq[1][i][k] + tq[2][i][k] + tq[3][i][k];
                }
                last_mass = fmax(last_mass, exp(-before) * -expm1(-d));
            }
            for (int i = 0; i < nc; ++i)
                for (int k = 0; k < 3; ++k) {
                    cum[i][k] += tq[0][i][k] + tq[1][i][k] + tq[2][i][k] + tq[3][i][k];
                }
            double worst = 0;
            for (int k = 0; k < 3; ++k) {
                const double room = rel * (fabs(Q[k]) + 0x1p-6 * fabs(Sum[k])) + 1e-300;
                worst = fmax(worst, Qe[k] / room);
            }
            const double grow = worst > 0 ? 0.8 * pow(worst, -0.2) : 4;
            dt = (b - t) * fmin(4, fmax(0.5, grow));
            t = b;
            pa = pq[4];
        }
    }
    for (int k = 0; k < 3; ++k) {
        S[k] += Sum[k];
        E[k] += sqrt(rss[k]);
    }
    if (steps >= NZ_STEPS)
        for (int k = 0; k < 3; ++k)
            E[k] += hb;   /* the step budget ran out: say so */
}

/* A closed form f (over a whole ray from its origin) over [a, b] of r:
 * T(0, a) times f along the ray from x(a). */
static void closed_range(void (*f)(const ef_fog_scene *, const ef_light *, const ef_ray *,
                                   double *),
                         const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                         double b, double S[3])
{
    if (a == 0 && b == r->dist) {
        f(s, l, r, S);
        return;
    }
    ef_ray sub = *r;
    for (int k = 0; k < 3; ++k)
        sub.org[k] = r->org[k] + a * r->dir[k];
    sub.dist = sub.planar = b - a;
    double tv[3];
    tau_from(s, r->org, r->dir, a, tv);
    f(s, l, &sub, S);
    for (int k = 0; k < 3; ++k)
        S[k] = S[k] == 0 ? 0 : S[k] * exp(-tv[k]);
}

/* Adds to S the light l scatters in over [a, b] of r (0 <= a < b, b may
 * be INFINITY), T(0, t) counted from the camera, and its error estimate
 * to E. */
static void inscatter_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                            double D, double S[3], double E[3])
{
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->tau_info) {
            noise_range(s, l, r, a, D, S, E);
            return;
        }
    lit_q q = { s, l, r, 0, 0, 0, 0, { 0, 0, 0 }, 0, 0, 0, 0, 0, 1, { 0, 0, 0 } };
    for (int i = 0; i < s->ncomp; ++i) {
        q.uniform &= is_uniform(&s->comp[i]);
        for (int k = 0; k < 3 && is_uniform(&s->comp[i]); ++k)
            q.sig[k] += s->comp[i].p[k];
    }
    if (l->kind == EF_LIGHT_SUN) {
        if (q.uniform)
            return;   /* the sun's light never crosses unbounded uniform fog */
        void (*f)(const ef_fog_scene *, const ef_light *, const ef_ray *, double *) = NULL;
        if (s->ncomp == 1 && s->comp[0].model == &ef_fog_height && s->comp[0].p[3] > 0 &&
            !(l->planet > 0))
            f = sun_height;
        if (s->ncomp == 1 && (s->comp[0].model == &ef_fog_halfspace ||
                              s->comp[0].model == &ef_fog_halfspace_linear ||
                              s->comp[0].model == &ef_fog_halfspace_smooth))
            f = sun_halfspace;
        if (s->ncomp == 1 && (s->comp[0].model == &ef_fog_box ||
                              s->comp[0].model == &ef_fog_convex) && s->comp[0].p[9] <= 64)
            f = sun_convex;
        if (f) {
            double v[3];
            closed_range(f, s, l, r, a, D, v);
            for (int k = 0; k < 3; ++k)
                S[k] += v[k];
            return;
        }
    }
    double cut[MAX_CUTS];
    int n = 0;
    cut[n++] = a;
    if (!q.uniform)
        n = feature_cuts(s, r, a, D, cut, n);
    if (l->kind == EF_LIGHT_SPOT)
        n = cone_cuts(l, r, a, D, cut, n);
    if (l->kind != EF_LIGHT_SUN) {
        /* the lamp's closest approach along the line, and its distance
         * there from the cross product (no cancellation near the line) */
        double *w = q.w;
        lamp_line(l, r, w, &q.ts, &q.h);
        q.wa = w[0] * l->dir[0] + w[1] * l->dir[1] + w[2] * l->dir[2];
        q.va = r->dir[0] * l->dir[0] + r->dir[1] * l->dir[1] + r->dir[2] * l->dir[2];
        q.hq = len2(q.h, l->radius);
        if (!(q.hq <= DBL_MAX / 64) || !isfinite(q.ts))
            return;   /* a lamp beyond 1e306 units: e / d^2 is no light at all */
        if (q.hq == 0) {
            if (q.ts >= a && q.ts <= D) {
                /* a lamp of radius 0 on the segment: its 1/d^2 does not
                 * integrate */
                for (int k = 0; k < 3; ++k)
                    if (l->e[k] > 0 && (q.uniform ? q.sig[k] > 0 : 1))
                        S[k] = INFINITY;
                return;
            }
            /* on the line beyond an end: the substitution's hq from a
             * billionth of its least distance, which changes 1/d^2 by
             * (hq / d)^2 <= 1e-18 */
            q.hq = 1e-9 * (q.ts < a ? a - q.ts : q.ts - D);
        }
        int iso = 1;
        for (int i = 0; i < s->ncomp; ++i)
            iso &= s->comp[i].phase == EF_PHASE_ISO;
        if (l->kind == EF_LIGHT_POINT && q.uniform && iso && l->radius == 0 && q.h > 0) {
            double sig[3], scat[3];
            lamp_medium(s, sig, scat);
            if (lamp_closed(sig, scat, l->e, q.ts, q.h, a, D, S, E) == 0)
                return;
            /* The two ends cancelled: a segment short beside its distance
             * from the lamp, where the integrand is smooth in t. One
             * Kronrod rule in u = t - ts, kept where its estimate meets
             * the closed form's 1e-13 (else the pieces below). */
            if (isfinite(D)) {
                gk_iv iv = { .a = a - q.ts, .b = D - q.ts };
                gk15(lit_integrand, &q, &iv);
                int ok = 1;
                for (int k = 0; k < 3; ++k)
                    ok &= iv.e[k] <= REL_UNIFORM * fabs(iv.r[k]) && isfinite(iv.r[k]);
                if (ok) {
                    for (int k = 0; k < 3; ++k) {
                        S[k] += iv.r[k];
                        E[k] += iv.e[k];
                    }
                    return;
                }
            }
        }
        q.equi = 1;
        /* Within W of the closest approach the substitution makes 1/d^2
         * flat; past it, t - ts itself, in pieces of geometric length (a
         * xi crowded against +-pi/2 would lose the pieces to rounding).
         * The closest approach itself is a cut (where h is 0 the phase
         * jumps there); where the radius is far wider than the line's
         * distance h, the phase still turns from forward to back over ~h:
         * geometric steps from h inside W too. */
        const double W = 64 * q.hq;
        if (q.ts > a && q.ts < D)
            cut[n++] = q.ts;
        const double h0 = q.h < q.hq / 16 ? fmax(q.h, 1e-6 * q.hq) : W;
        n = steps_around(cut, n, q.ts, a, D, h0);
        if (h0 < W)
            n = steps_around(cut, n, q.ts, a, D, W);
        q.W = W;
    }
    if (isfinite(D))
        cut[n++] = D;
    const double rel = q.uniform ? REL_UNIFORM : REL_GENERAL;
    if (q.equi) {
        /* pieces within W of the lamp in xi = atan((t - ts) / hq), the
         * others in u = t - ts; an infinite ray's last piece in v, u =
         * ua + lam v / (1 - v), lam its start's distance from the lamp */
        qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
        const double W = q.W;
        double run[MAX_CUTS];
        for (int i = 0; i + 1 < n;) {
            const int in = cut[i] >= q.ts - W && cut[i + 1] <= q.ts + W;
            int m = 0, j = i;
            run[m++] = in ? atan((cut[i] - q.ts) / q.hq) : cut[i] - q.ts;
            for (; j + 1 < n; ++j) {
                if ((cut[j] >= q.ts - W && cut[j + 1] <= q.ts + W) != in)
                    break;
                run[m++] = in ? atan((cut[j + 1] - q.ts) / q.hq) : cut[j + 1] - q.ts;
            }
            q.equi = in;
            gk_adapt(lit_integrand, &q, run, m, rel, S, E);
            i = j;
        }
        if (!isfinite(D)) {
            q.equi = 2;
            q.ua = cut[n - 1] - q.ts;
            q.lam = fmax(fabs(q.ua), q.hq);
            const double v[2] = { 0, 1 };
            gk_adapt(lit_integrand, &q, v, 2, rel, S, E);
        }
    } else if (isfinite(D)) {
        qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
        gk_adapt(lit_integrand, &q, cut, n, rel, S, E);
    } else {
        /* The sun on an infinite ray: pieces doubling in length past the
         * last cut until what is left is below the tolerance: its integral
         * is at most max(albedo p) E T(0,t) (1 - T(t,inf)) per channel,
         * which joins the error estimate. */
        qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
        gk_adapt(lit_integrand, &q, cut, n, REL_GENERAL, S, E);
        const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
        double pmax = 0;
        for (int i = 0; i < s->ncomp; ++i)
            pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, cth));
        double ta = cut[n - 1], len = fmax(ta, 1.0);
        for (int it = 0; it < 2100; ++it) {
            double x[3], tv[3], tr[3], tail[3];
            for (int k = 0; k < 3; ++k)
                x[k] = r->org[k] + ta * r->dir[k];
            tau_from(s, r->org, r->dir, ta, tv);
            tau_from(s, x, r->dir, INFINITY, tr);
            int done = 1;
            for (int k = 0; k < 3; ++k) {
                tail[k] = pmax * l->e[k] * exp(-tv[k]) * -expm1(-tr[k]);
                done &= !(tail[k] > REL_GENERAL * fabs(S[k])) || tail[k] < 1e-300;
            }
            if (done || !(ta + len < 1e300)) {
                for (int k = 0; k < 3; ++k)
                    E[k] += tail[k] > 0 ? tail[k] : 0;
                break;
            }
            const double piece[2] = { ta, ta + len };
            gk_adapt(lit_integrand, &q, piece, 2, REL_GENERAL, S, E);
            ta += len;
            len *= 2;
        }
    }
}

int ef_light_cuts(const ef_light *l, const ef_ray *r, double a, double b, double *cut, int cap)
{
    double c[MAX_CUTS];
    int n = 0;
    if (l->kind != EF_LIGHT_SUN) {
        double w[3], ts, h;
        lamp_line(l, r, w, &ts, &h);
        const double hq = len2(h, l->radius);
        if (isfinite(ts) && isfinite(hq)) {
            if (ts > a && ts < b)
                c[n++] = ts;
            /* 1 / d^2 halves its slope each doubling of the distance from
             * the closest approach: geometric cuts from there */
            n = steps_around(c, n, ts, a, b, hq > 0 ? hq : 1e-9 * fmax(fabs(ts), 1));
        }
        if (l->kind == EF_LIGHT_SPOT)
            n = cone_cuts(l, r, a, b, c, n);
    }
    if (l->shadow && n < MAX_CUTS - 2) {
        double iv[64][3];
        int m = ef_shadow_pieces(l->shadow, r->org, r->dir, a, b, iv, 64);
        if (m < 0)
            m = -1 - m;
        for (int i = 0; i < m && n < MAX_CUTS - 2; ++i)
            for (int e = 0; e < 2; ++e)
                if (iv[i][e] > a && iv[i][e] < b)
                    c[n++] = iv[i][e];
    }
    qsort(c, (size_t) n, sizeof c[0], cmp_double);
    int m = 0;
    for (int i = 0; i < n && m < cap; ++i)
        if (m == 0 || c[i] > cut[m - 1])
            cut[m++] = c[i];
    return m;
}

/* Lit intervals a view segment holds on the stack; more (foliage, a
 * fence) go to the heap, up to MAX_LIT, beyond which the rest joins the
 * last (shadow.h). */
#define LIT_STACK 256
#define MAX_LIT 65536

/* Whether lamp_span's batches take a ray of length D whose closest
 * approach to the lamp is h at ts (h as lamp_line gives it): a segment,
 * beside the lamp, in magnitudes the kernel handles. No short circuit, so
 * a loop over a span vectorises. */
EF_INLINE int lamp_takes(double D, double h, double ts)
{
    return (D > 0) & (h > 0) & (h <= DBL_MAX / 64) & (fabs(ts) < INFINITY);
}

/* The n <= EF_SPAN rays r[j] of one span beside point lamp l (radius 0)
 * in the medium (sig, scat), four at a time by lamp_rays4_in: S[k][j]
 * and (E not NULL) E[k][j] set, except for the rays whose indices go to
 * left (their count returned), which the caller evaluates one by one (at
 * or through the lamp, a length of 0, magnitudes out of range, a closed
 * form that does not hold). ts and h as lamp_line forms them, in a loop
 * the compiler vectorises (len3's plain form; lamp_line where a ray
 * leaves it): the same bits. */
EF_MULTIVERSION static int lamp_span(const ef_light *l, const double sig[3],
                                     const double scat[3], const ef_ray *r, int n,
                                     double *const S[3], double *const E[3], int *left)
{
    double F[8][EF_SPAN], tsv[EF_SPAN], hv[EF_SPAN];
    rays_soa(r, n, F);
    const double px = l->pos[0], py = l->pos[1], pz = l->pos[2];
    for (int j = 0; j < n; ++j) {
        const double dx = F[EF_F_DIR][j], dy = F[EF_F_DIR + 1][j], dz = F[EF_F_DIR + 2][j];
        const double wx = px - F[EF_F_ORG][j], wy = py - F[EF_F_ORG + 1][j],
                     wz = pz - F[EF_F_ORG + 2][j];
        tsv[j] = wx * dx + wy * dy + wz * dz;
        const double cx = wy * dz - wz * dy, cy = wz * dx - wx * dz, cz = wx * dy - wy * dx;
        const double ax = fabs(cx), ay = fabs(cy), az = fabs(cz);
        const double mxy = ax > ay ? ax : ay, m = mxy > az ? mxy : az;
        const double v = sqrt(cx * cx + cy * cy + cz * cz);
        hv[j] = m < 1e150 && m > 1e-150 ? v : -1.0;
    }
    /* the common span: every ray beside the lamp in plain magnitudes, its
     * batches the arrays' slices (copied as vectors) */
    int all = n % 4 == 0;
    for (int j = 0; j < n; ++j)
        all &= lamp_takes(F[EF_F_DIST][j], hv[j], tsv[j]);
    lamp4 in[EF_SPAN / 4];
    int idx[EF_SPAN], m = 0, nl = 0;
    if (all) {
        const double zero[4] = { 0, 0, 0, 0 };
        for (int b = 0; b < n / 4; ++b) {
            memcpy(in[b].ts, tsv + 4 * b, sizeof in[b].ts);
            memcpy(in[b].h, hv + 4 * b, sizeof in[b].h);
            memcpy(in[b].a, zero, sizeof in[b].a);
            memcpy(in[b].D, F[EF_F_DIST] + 4 * b, sizeof in[b].D);
        }
        for (int j = 0; j < n; ++j)
            idx[j] = j;
        m = n;
    }
    /* else every ray's batch first, then the batches: a batch's four lanes
     * are read as vectors long after their scalar stores (not through a
     * stalled store-to-load forward) */
    for (int j = 0; !all && j < n; ++j) {
        double w[3], ts = tsv[j], h = hv[j];
        const int beside = r[j].dist > 0;
        if (beside && !(h >= 0))
            lamp_line(l, &r[j], w, &ts, &h);
        if (!lamp_takes(r[j].dist, h, ts)) {
            left[nl++] = j;
            continue;
        }
        lamp4 *const b = &in[m / 4];
        b->ts[m % 4] = ts;
        b->h[m % 4] = h;
        b->a[m % 4] = 0;
        b->D[m % 4] = r[j].dist;
        idx[m++] = j;
    }
    for (int i = m; i % 4; ++i) {   /* the last batch: its last ray again */
        lamp4 *const b = &in[i / 4];
        const lamp4 *const lb = &in[(m - 1) / 4];
        b->ts[i % 4] = lb->ts[(m - 1) % 4];
        b->h[i % 4] = lb->h[(m - 1) % 4];
        b->a[i % 4] = lb->a[(m - 1) % 4];
        b->D[i % 4] = lb->D[(m - 1) % 4];
    }
    for (int i0 = 0; i0 < m; i0 += 4) {
        int st[4];
        const int mb = m - i0 < 4 ? m - i0 : 4;
        lamp_rays4_in(sig, scat, l->e, &in[i0 / 4], mb, idx + i0, S, E, st);
        for (int i = 0; i < mb; ++i)
            if (st[i])   /* the ends cancel: ef_light_inscatter integrates */
                left[nl++] = idx[i0 + i];
    }
    return nl;
}

/* Whether ef_light_inscatter takes l's light in s from lamp_closed
 * wherever a ray passes beside the lamp: a point lamp of radius 0, no
 * shadow, in fog that is uniform and isotropic throughout. */
static int lamp_batch(const ef_fog_scene *s, const ef_light *l)
{
    if (l->kind != EF_LIGHT_POINT || l->radius != 0 || l->shadow || s->ncomp == 0)
        return 0;
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->tau_info || !is_uniform(&s->comp[i]) ||
            s->comp[i].phase != EF_PHASE_ISO)
            return 0;
    return 1;
}

/* ef_light_inscatter for ray j into S[k][j] and (E not NULL) E[k][j]. */
static void one_ray(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, int j,
                    double *const S[3], double *const E[3])
{
    double v[3], ve[3];
    ef_light_inscatter(s, l, &r[j], v, ve);
    for (int k = 0; k < 3; ++k) {
        S[k][j] = v[k];
        if (E)
            E[k][j] = ve[k];
    }
}

void ef_light_rays(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, int n,
                   double *const S[3], double *const E[3])
{
    if (!lamp_batch(s, l) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0)) {
        for (int j = 0; j < n; ++j)
            one_ray(s, l, r, j, S, E);
        return;
    }
    double sig[3], scat[3];
    lamp_medium(s, sig, scat);
    for (int j0 = 0; j0 < n; j0 += EF_SPAN) {
        const int m = n - j0 < EF_SPAN ? n - j0 : EF_SPAN;
        double *const Sj[3] = { S[0] + j0, S[1] + j0, S[2] + j0 };
        double *const Ej[3] = { E ? E[0] + j0 : NULL, E ? E[1] + j0 : NULL,
                                E ? E[2] + j0 : NULL };
        int left[EF_SPAN];
        const int nl = lamp_span(l, sig, scat, r + j0, m, Sj, E ? Ej : NULL, left);
        for (int i = 0; i < nl; ++i)
            one_ray(s, l, r + j0, left[i], Sj, E ? Ej : NULL);
    }
}

void ef_light_inscatter(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3],
                        double err[3])
{
    double E[3] = { 0, 0, 0 };
    S[0] = S[1] = S[2] = 0;
    if (err)
        err[0] = err[1] = err[2] = 0;
    const double D = r->dist;
    if (s->ncomp == 0 || !(D > 0) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return;
    if (!l->shadow) {
        inscatter_range(s, l, r, 0, D, S, E);
    } else {
        /* each lit piece at its visibility (1: hard shadows) */
        double stack[LIT_STACK][3], (*iv)[3] = stack;
        int n = ef_shadow_pieces(l->shadow, r->org, r->dir, 0, D, iv, LIT_STACK);
        if (n < 0) {
            double (*heap)[3] = malloc(MAX_LIT * sizeof *heap);
            if (heap) {
                iv = heap;
                n = ef_shadow_pieces(l->shadow, r->org, r->dir, 0, D, iv, MAX_LIT);
            } else {   /* no memory: what fitted, and the estimate says so */
                for (int k = 0; k < 3; ++k)
                    E[k] = INFINITY;
            }
        }
        if (n < 0)
            n = -1 - n;
        for (int i = 0; i < n; ++i) {
            if (iv[i][2] == 1) {
                inscatter_range(s, l, r, iv[i][0], iv[i][1], S, E);
                continue;
            }
            double Sp[3] = { 0, 0, 0 }, Ep[3] = { 0, 0, 0 };
            inscatter_range(s, l, r, iv[i][0], iv[i][1], Sp, Ep);
            for (int k = 0; k < 3; ++k) {
                S[k] += iv[i][2] * Sp[k];
                E[k] += iv[i][2] * Ep[k];
            }
        }
        if (iv != stack)
            free(iv);
    }
    if (err)
        for (int k = 0; k < 3; ++k)
            err[k] = E[k];
}
