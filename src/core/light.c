/* Lights and phase functions (light.h): parsing every kind, their names,
 * a planet sun's Chapman table, a spot's cone share. What lights do to
 * fog is lit.c's (lit_int.h lists the family). */
#include "light.h"
#include "chapman.h"

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

/* The kinds: name, keys, geometry. */
const ef_light_kind_info ef_light_kinds[EF_LIGHT_NKIND] = {
    [EF_LIGHT_SUN] = { "sun",
                       "towards, color, intensity, angle, planet, name, shadow, shadow-camera, "
                       "bias, slope, outside, penumbra, scattering, ground",
                       0, 0, 1 },
    [EF_LIGHT_POINT] = { "point", "position, color, intensity, radius, name, scattering", 1, 0, 0 },
    [EF_LIGHT_SPOT] = { "spot",
                        "position, aim, cone, blend, cosine, color, intensity, radius, name, "
                        "shadow, shadow-camera, bias, slope, outside, scattering",
                        1, 1, 1 },
};

const char *ef_light_kind_name(ef_light_kind k)
{
    return (int) k >= 0 && k < EF_LIGHT_NKIND ? ef_light_kinds[k].name : "?";
}

/* Reads l's shadow map through the context and checks it fits the light:
 * a sun's map is orthographic and looks along the sunlight, a spot's is a
 * perspective from the spot. Returns 0 or -1. */
static int light_shadow(const ef_fog_context *ctx, const char *spec, ef_light *l, ef_err *err)
{
    if (!ctx->load_shadow)
        return ef_fail(err, "--light '%s': shadow maps cannot be read here", spec);
    ef_shadow_opts o = l->shadow_opts;
    o.camera = l->shadow_camera[0] ? l->shadow_camera : NULL;   /* read while loading only */
    if (ctx->load_shadow(l->shadow_path, &o, &l->shadow, err))
        return -1;
    const ef_shadow *m = l->shadow;
    const char *why = NULL;
    char detail[200] = "";
    if (!ef_light_at_position(l)) {
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
    const ef_light_kind_info *K = NULL;
    for (int k = 0; kind && k < EF_LIGHT_NKIND; ++k)
        if (!strcmp(kind, ef_light_kinds[k].name)) {
            l->kind = (ef_light_kind) k;
            K = &ef_light_kinds[k];
            keys = K->keys;
        }
    if (!keys) {
        return ef_fail(err, "--light '%s': the kind is not sun, point or spot (write "
                       "sun:towards=X,Y,Z:intensity=E or point:position=X,Y,Z:intensity=I)", spec);
    }
    double color[3] = { 1, 1, 1 }, intensity = 1, cone = 0, blend = 0;
    l->shadow_opts = (ef_shadow_opts) { 0, 1, 1, 0, NULL };   /* bias 0, slope 1, outside lit */
    unsigned seen = 0;
    enum { S_DIR = 1, S_POS = 2, S_AIM = 4, S_CONE = 8, S_COLOR = 16, S_INT = 32, S_ANGLE = 64,
           S_RADIUS = 128, S_BLEND = 256, S_NAME = 512, S_SHADOW = 1024, S_BIAS = 2048,
           S_OUTSIDE = 4096, S_SLOPE = 8192, S_COSINE = 16384, S_PLANET = 32768,
           S_PENUMBRA = 65536, S_SHADOWCAM = 131072, S_SCATTER = 262144, S_GROUND = 524288 };
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
        /* a number that overflows or underflows is out of range, whatever
         * the key's own rule (names and paths hold no numbers to read) */
        static const char *const words[] = { "name", "shadow", "shadow-camera", "outside",
                                             "cosine", NULL };
        int wordy = 0;
        for (int w = 0; words[w]; ++w)
            wordy |= !strcmp(key, words[w]);
        if (!wordy && strstr(keys, key) && ef_out_of_range(val, 0))
            return ef_fail(err, "--light '%s': %s='%s' is out of range (numbers are 0 or between "
                           "2.2e-308 and 1.8e308 in magnitude)", spec, key, val);
        int ok = strstr(keys, key) != NULL;
        if (!strcmp(key, "ground") && K->at_position)
            return ef_fail(err, "--light '%s': ground= is the sun's: a point lamp's multiple "
                           "scattering is solved in unbounded uniform fog", spec);
        if (!strcmp(key, "shadow") && !K->shadow)
            return ef_fail(err, "--light '%s': a point lamp takes no shadow= map (it shines "
                           "every way; a spot's or the sun's map covers one view)", spec);
        if (!ok) {
            bit = 0;
        } else if (!strcmp(key, "towards") && !K->at_position) {
            bit = S_DIR;
            if (unit3(val, l->dir))
                return ef_fail(err, "--light '%s': towards='%s' is not X,Y,Z (a non-zero "
                               "direction from the scene to the sun, world axes)", spec, val);
        } else if (!strcmp(key, "position") && K->at_position) {
            bit = S_POS;
            if (ef_parse_numbers(val, l->pos, 3))
                return ef_fail(err, "--light '%s': position='%s' is not X,Y,Z (world, scene "
                               "units)", spec, val);
        } else if (!strcmp(key, "aim") && K->cone) {
            bit = S_AIM;
            if (unit3(val, l->dir))
                return ef_fail(err, "--light '%s': aim='%s' is not X,Y,Z (the non-zero direction "
                               "the spot points in, world axes)", spec, val);
        } else if (!strcmp(key, "cone") && K->cone) {
            bit = S_CONE;
            if (ef_parse_numbers(val, &cone, 1) || !(cone > 0) || !(cone <= 180))
                return ef_fail(err, "--light '%s': cone='%s' is not a full cone angle in "
                               "degrees, above 0 and at most 180", spec, val);
        } else if (!strcmp(key, "blend") && K->cone) {
            bit = S_BLEND;
            if (ef_parse_numbers(val, &blend, 1) || !(blend >= 0) || !(blend <= 1))
                return ef_fail(err, "--light '%s': blend='%s' is not a number from 0 to 1", spec,
                               val);
        } else if (!strcmp(key, "cosine") && K->cone) {
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
                               spec, val, !K->at_position
                                              ? "the irradiance on a surface facing the sun"
                                              : "the radiant intensity, per steradian");
        } else if (!strcmp(key, "angle") && !K->at_position) {
            bit = S_ANGLE;
            if (ef_parse_numbers(val, &l->angle, 1) || !(l->angle >= 0) || !(l->angle < 180))
                return ef_fail(err, "--light '%s': angle='%s' is not the sun's angular diameter "
                               "in degrees, from 0 to below 180", spec, val);
            l->angle *= PI / 180;
        } else if (!strcmp(key, "scattering")) {
            bit = S_SCATTER;
            if (!strcmp(val, "single") || !strcmp(val, "multiple"))
                l->multiple = val[0] == 'm';
            else
                return ef_fail(err, "--light '%s': scattering='%s' is not single or multiple "
                               "(multiple adds the light scattered twice and more)", spec, val);
        } else if (!strcmp(key, "ground") && !K->at_position) {
            bit = S_GROUND;
            if (ef_parse_numbers(val, &l->ground, 1))
                return ef_fail(err, "--light '%s': ground='%s' is not a height (scene units "
                               "along the fog's up axis: the black ground multiple scattering "
                               "stops at)", spec, val);
            l->has_ground = 1;
        } else if (!strcmp(key, "penumbra") && !K->at_position) {
            bit = S_PENUMBRA;
            if (ef_parse_numbers(val, &penumbra, 1) || !(penumbra >= 0) ||
                !(penumbra <= EF_PENUMBRA_MAX) || penumbra != floor(penumbra))
                return ef_fail(err, "--light '%s': penumbra='%s' is not a whole number of "
                               "directions over the sun's disc from 0 (hard shadows) to %d",
                               spec, val, EF_PENUMBRA_MAX);
        } else if (!strcmp(key, "planet") && !K->at_position) {
            bit = S_PLANET;
            /* earth: 6371 km, in scene units */
            if (!strcmp(val, "earth"))
                l->planet = 6371000.0 * ctx->units_per_meter;
            else if (ef_parse_numbers(val, &l->planet, 1) || !(l->planet > 0) ||
                     !(l->planet < 1e300))
                return ef_fail(err, "--light '%s': planet='%s' is not a radius > 0 in scene "
                               "units, or earth", spec, val);
        } else if (!strcmp(key, "radius") && K->at_position) {
            bit = S_RADIUS;
            if (ef_parse_numbers(val, &l->radius, 1) || !(l->radius >= 0))
                return ef_fail(err, "--light '%s': radius='%s' is not a number >= 0 (scene "
                               "units)", spec, val);
        } else if (!strcmp(key, "shadow-camera")) {
            bit = S_SHADOWCAM;
            if (strlen(val) >= sizeof l->shadow_camera)
                return ef_fail(err, "--light '%s': shadow-camera= path is too long", spec);
            snprintf(l->shadow_camera, sizeof l->shadow_camera, "%s", val);
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
    if (!K->at_position && !(seen & S_DIR))
        return ef_fail(err, "--light '%s': missing towards=X,Y,Z (from the scene to the sun)", spec);
    if (K->at_position && !(seen & S_POS))
        return ef_fail(err, "--light '%s': missing position=X,Y,Z", spec);
    if (K->cone && (seen & (S_AIM | S_CONE)) != (S_AIM | S_CONE))
        return ef_fail(err, "--light '%s': a spot needs aim=X,Y,Z and cone=DEG", spec);
    /* point and spot: E = I / d_m^2 with d_m = d / U metres */
    const double U = ctx->units_per_meter, scale = K->at_position ? U * U : 1;
    for (int k = 0; k < 3; ++k) {
        l->e[k] = color[k] * intensity * scale;
        if (!isfinite(l->e[k]))
            return ef_fail(err, "--light '%s': color times intensity overflows", spec);
    }
    if (K->cone) {
        l->cos_outer = cos(cone * (PI / 360));
        l->smooth = blend * (1 - l->cos_outer);
    }
    if ((seen & (S_BIAS | S_OUTSIDE | S_SLOPE | S_SHADOWCAM)) && !(seen & S_SHADOW))
        return ef_fail(err, "--light '%s': bias=, slope=, outside= and shadow-camera= need "
                       "shadow=FILE.exr", spec);
    if ((seen & S_GROUND) && !l->multiple)
        return ef_fail(err, "--light '%s': ground= is where multiple scattering stops: it needs "
                       "scattering=multiple", spec);
    if (l->multiple && ef_light_kinds[l->kind].at_position && l->radius > 0)
        return ef_fail(err, "--light '%s': scattering=multiple is solved for a lamp of radius 0 "
                       "(a point); drop radius= or scattering=multiple", spec);
    if (l->multiple && (seen & S_PLANET))
        return ef_fail(err, "--light '%s': scattering=multiple is solved over flat ground; "
                       "drop planet= or scattering=multiple", spec);
    if ((seen & S_PENUMBRA) && (!(seen & S_SHADOW) || !(l->angle > 0)))
        return ef_fail(err, "--light '%s': penumbra= needs shadow=FILE.exr and the sun's "
                       "angle=DEG (its angular diameter, e.g. 0.53)", spec);
    /* the map's memory grows with the penumbra's copies: the loader bounds
     * both before it reads a texel */
    l->shadow_opts.copies = l->angle > 0 && penumbra > 0 ? (int) penumbra : 0;
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
/* Ch of a planet sun at height y: from the light's table where it holds
 * y, else ef_chapman (mu clamped to [-1, 1]). */
double ef_light_planet_ch(const ef_light *l, double k, double mu, double y)
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
    double rho[3], k, base;
    if (!(!ef_light_at_position(l) && l->planet > 0) || !c->model->strata ||
        !c->model->strata(c, rho, &k, &base))
        return;
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
        const double want = ef_chapman(k * (l->planet + y), mu), got = ef_light_planet_ch(l, k, mu, y);
        if (!(fabs(got - want) <= 1e-14 * want)) {
            l->ch_ok = 0;
            return;
        }
    }
}


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
