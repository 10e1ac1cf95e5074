#include "fog.h"

#include "ddouble.h"

#include <errno.h>
#include <stdio.h>
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The registry: one line per model. */
static const ef_fog_model *const registry[] = {
    &ef_fog_linear,
    &ef_fog_exp,
    &ef_fog_exp2,
    &ef_fog_halfspace,
    &ef_fog_halfspace_linear,
    &ef_fog_halfspace_smooth,
    &ef_fog_height,
    &ef_fog_layered,
    &ef_fog_box,
    &ef_fog_convex,
    &ef_fog_noise,
    &ef_fog_noise_separable,
};

void ef_fog_context_init(ef_fog_context *ctx)
{
    ctx->up[0] = 0.0;
    ctx->up[1] = 1.0;
    ctx->up[2] = 0.0;
    ctx->units_per_meter = 1.0;
    ctx->read_file = NULL;
    ctx->parse_color = NULL;
    ctx->color_user = NULL;
    ctx->time = 0.0;
}

void ef_fog_tau(const ef_fog_component *c, const ef_ray *r, double tau[3], ef_tau_info *info)
{
    if (info && c->model->tau_info) {
        c->model->tau_info(c, r, tau, info);
        return;
    }
    c->model->tau(c, r, tau);
    if (info)
        memset(info, 0, sizeof *info);   /* exact: a bound of 0 */
}

void ef_fog_tau_add(const ef_fog_component *c, const ef_ray *r, int n, double (*acc)[3])
{
    if (c->model->tau_add) {
        c->model->tau_add(c, r, n, acc);
        return;
    }
    for (int j = 0; j < n; ++j) {
        double t[3];
        c->model->tau(c, &r[j], t);
        for (int k = 0; k < 3; ++k)
            acc[j][k] += t[k];
    }
}

double ef_fog_per_unit(const ef_fog_context *ctx, double per_meter)
{
    return per_meter / ctx->units_per_meter;
}

double ef_fog_per_unit2(const ef_fog_context *ctx, double per_meter2)
{
    return per_meter2 / ctx->units_per_meter / ctx->units_per_meter;
}

int ef_fog_model_count(void)
{
    return (int) (sizeof registry / sizeof registry[0]);
}

const ef_fog_model *ef_fog_model_at(int i)
{
    return i >= 0 && i < ef_fog_model_count() ? registry[i] : NULL;
}

const ef_fog_model *ef_fog_model_find(const char *name)
{
    for (size_t i = 0; i < sizeof registry / sizeof registry[0]; ++i)
        if (!strcmp(registry[i]->name, name))
            return registry[i];
    return NULL;
}

int ef_parse_real(const char *s, char **end, double *out, int wide)
{
    errno = 0;
    const double v = strtod(s, end);
    if (*end == s || isnan(v))
        return -1;
    /* ERANGE: overflow, or underflow to 0 or a subnormal (1e-400, 5e-324) */
    if (errno == ERANGE || isinf(v) || (v != 0 && fabs(v) < DBL_MIN) ||
        (!wide && fabs(v) > EF_NUM_MAX))
        return -2;
    *out = v;
    return 0;
}

int ef_out_of_range(const char *text, int wide)
{
    const char *s = text;
    while (*s) {
        if (strchr(",/: =", *s)) {
            ++s;
            continue;
        }
        char *end;
        double v;
        const int rc = ef_parse_real(s, &end, &v, wide);
        if (end == s) {
            ++s;
            continue;
        }
        if (rc == -2 && (*end == '\0' || strchr(",/: ", *end)))
            return 1;
        s = end;
    }
    return 0;
}

int ef_parse_numbers_ex(const char *text, double *out, int n, int wide)
{
    const char *s = text;
    for (int i = 0; i < n; ++i) {
        char *end;
        double v;
        const int rc = ef_parse_real(s, &end, &v, wide);
        if (rc)
            return rc;
        out[i] = v;
        s = end;
        while (*s == ' ')
            ++s;
        if (i + 1 < n) {
            if (*s != ',')
                return -1;
            ++s;
        }
    }
    return *s == '\0' ? 0 : -1;
}

int ef_parse_numbers(const char *text, double *out, int n)
{
    return ef_parse_numbers_ex(text, out, n, 0);
}

int ef_parse_list(const char *text, double *out, int cap)
{
    int n = 1;
    for (const char *q = text; *q; ++q)
        n += *q == ',';
    if (n > cap || ef_parse_numbers(text, out, n))
        return -1;
    return n;
}

int ef_parse_up(const char *text, double up[3])
{
    static const struct {
        const char *name;
        double v[3];
    } axes[] = { { "x", { 1, 0, 0 } },  { "y", { 0, 1, 0 } },  { "z", { 0, 0, 1 } },
                 { "-x", { -1, 0, 0 } }, { "-y", { 0, -1, 0 } }, { "-z", { 0, 0, -1 } },
                 { "+x", { 1, 0, 0 } },  { "+y", { 0, 1, 0 } },  { "+z", { 0, 0, 1 } } };
    for (size_t i = 0; i < sizeof axes / sizeof axes[0]; ++i)
        if (!strcmp(text, axes[i].name)) {
            memcpy(up, axes[i].v, sizeof axes[i].v);
            return 0;
        }
    double v[3];
    if (ef_parse_numbers(text, v, 3))
        return -1;
    const double len = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!(len > 0) || !isfinite(len))
        return -1;
    for (int i = 0; i < 3; ++i)
        up[i] = v[i] / len;
    return 0;
}

int ef_fog_set_density(ef_fog_component *c, const char *key, const char *val, double out[3],
                       ef_err *err)
{
    if (ef_parse_rgb(val, out))
        return ef_fail(err, "fog spec '%s': %s='%s' is not a number or R,G,B", c->spec, key, val);
    for (int i = 0; i < 3; ++i)
        if (out[i] < 0)
            return ef_fail(err, "fog spec '%s': %s='%s' is negative (it must be >= 0)", c->spec,
                           key, val);
    return 0;
}

int ef_fog_set_visibility(ef_fog_component *c, const char *key, const char *val, double out[3],
                          ef_err *err)
{
    double v[3];
    if (ef_parse_rgb(val, v))
        return ef_fail(err, "fog spec '%s': %s='%s' is not a distance or R,G,B", c->spec, key, val);
    for (int i = 0; i < 3; ++i) {
        if (!(v[i] > 0))
            return ef_fail(err, "fog spec '%s': %s='%s' must be > 0 (the distance at which "
                           "contrast falls to 2%%)", c->spec, key, val);
        out[i] = EF_VISIBILITY_K / v[i];
    }
    return 0;
}

int ef_fog_set_plane(ef_fog_component *c, const char *key, const char *val, double out[4],
                     ef_err *err)
{
    double v[4];
    if (ef_parse_numbers(val, v, 4))
        return ef_fail(err, "fog spec '%s': %s='%s' is not A,B,C,D (four numbers)", c->spec, key,
                       val);
    /* hypot's scaling: coefficients near 1e200 must not overflow to a "zero" normal. */
    const double len = hypot(hypot(v[0], v[1]), v[2]);
    if (!(len > 0) || !isfinite(len))
        return ef_fail(err, "fog spec '%s': %s='%s' has a zero normal (A,B,C must not all be 0)",
                       c->spec, key, val);
    for (int i = 0; i < 4; ++i)
        out[i] = v[i] / len;
    return 0;
}

int ef_parse_color(const char *text, double out[3])
{
    if (ef_parse_rgb(text, out))
        return -1;
    for (int i = 0; i < 3; ++i)
        if (!(out[i] >= 0 && out[i] <= EF_COLOR_MAX))
            return -1;
    return 0;
}

int ef_parse_rgb(const char *text, double out[3])
{
    if (strchr(text, ',') == NULL) {
        if (ef_parse_numbers(text, out, 1))
            return -1;
        out[1] = out[2] = out[0];
        return 0;
    }
    return ef_parse_numbers(text, out, 3);
}

static void list_models(char *buf, size_t len)
{
    buf[0] = '\0';
    for (size_t i = 0; i < sizeof registry / sizeof registry[0]; ++i) {
        if (i)
            strncat(buf, ", ", len - strlen(buf) - 1);
        strncat(buf, registry[i]->name, len - strlen(buf) - 1);
    }
}

static void list_keys(const ef_fog_model *m, char *buf, size_t len)
{
    buf[0] = '\0';
    for (int i = 0; m->keys[i]; ++i) {
        strncat(buf, m->keys[i], len - strlen(buf) - 1);
        strncat(buf, ", ", len - strlen(buf) - 1);
    }
    if (m->uses_distance)
        strncat(buf, "distance, ", len - strlen(buf) - 1);
    if (m->uses_up)
        strncat(buf, "up, ", len - strlen(buf) - 1);
    strncat(buf, "color, albedo, phase, g", len - strlen(buf) - 1);
}

static int parse_token_inner(ef_fog_component *c, char *tok, const char *spec,
                             const ef_fog_context *ctx, ef_err *err);

/* Applies one KEY=VALUE token (tok is modified in place); a number that
 * overflows or underflows is called out of range, whatever the key. */
static int parse_token(ef_fog_component *c, char *tok, const char *spec, const ef_fog_context *ctx,
                       ef_err *err)
{
    const char *eq = strchr(tok, '=');
    if (parse_token_inner(c, tok, spec, ctx, err) == 0)
        return 0;
    if (eq && ef_out_of_range(eq + 1, 0) && !strstr(err->msg, "out of range") &&
        !strstr(err->msg, "unknown key") && !strstr(err->msg, "twice"))
        return ef_fail(err, "fog spec '%s': %s='%s' is out of range (numbers in a SPEC are 0 or "
                       "between 2.2e-308 and 1.8e308 in magnitude)", spec, tok, eq + 1);
    return -1;
}

static int parse_token_inner(ef_fog_component *c, char *tok, const char *spec,
                             const ef_fog_context *ctx, ef_err *err)
{
    char *eq = strchr(tok, '=');
    char keys[256];
    list_keys(c->model, keys, sizeof keys);
    if (!eq)
        return ef_fail(err, "fog spec '%s': key '%s' has no value (write %s=VALUE)", spec, tok, tok);
    *eq = '\0';
    const char *key = tok, *val = eq + 1;
    if (*val == '\0')
        return ef_fail(err, "fog spec '%s': key '%s' has no value (write %s=VALUE)", spec, key, key);
    if (!strcmp(key, "color")) {
        if (c->has_color)
            return ef_fail(err, "fog spec '%s': key 'color' is given twice", spec);
        if (ctx->parse_color) {
            if (ctx->parse_color(ctx->color_user, val, c->color, err)) {
                char msg[sizeof err->msg];
                snprintf(msg, sizeof msg, "%s", err->msg);
                return ef_fail(err, "fog spec '%s': color='%s': %s", spec, val, msg);
            }
        } else if (ef_parse_color(val, c->color)) {
            return ef_fail(err, "fog spec '%s': color='%s' is not R,G,B (numbers from 0 to %g)",
                           spec, val, EF_COLOR_MAX);
        }
        c->has_color = 1;
        return 0;
    }
    if (!strcmp(key, "albedo")) {
        if (c->has_albedo)
            return ef_fail(err, "fog spec '%s': key 'albedo' is given twice", spec);
        if (ef_parse_rgb(val, c->albedo) || c->albedo[0] < 0 || c->albedo[1] < 0 ||
            c->albedo[2] < 0 || c->albedo[0] > 1 || c->albedo[1] > 1 || c->albedo[2] > 1)
            return ef_fail(err, "fog spec '%s': albedo='%s' is not A or R,G,B from 0 to 1 (the "
                           "scattered share of the extinction)", spec, val);
        c->has_albedo = 1;
        return 0;
    }
    if (!strcmp(key, "phase")) {
        static const char *const names[] = { "iso", "rayleigh", "hg", "cs" };
        for (int i = 0; i < 4; ++i)
            if (!strcmp(val, names[i])) {
                c->phase = i;
                return 0;
            }
        return ef_fail(err, "fog spec '%s': phase='%s' is not iso, rayleigh, hg or cs", spec, val);
    }
    if (!strcmp(key, "g")) {
        if (c->has_g)
            return ef_fail(err, "fog spec '%s': key 'g' is given twice", spec);
        if (ef_parse_numbers(val, &c->g, 1) || !(c->g > -1) || !(c->g < 1))
            return ef_fail(err, "fog spec '%s': g='%s' is not a number between -1 and 1 "
                           "(exclusive; > 0 scatters forward)", spec, val);
        c->has_g = 1;
        return 0;
    }
    if (!strcmp(key, "up") && c->model->uses_up) {
        if (c->has_up)
            return ef_fail(err, "fog spec '%s': key 'up' is given twice", spec);
        if (ef_parse_up(val, c->up))
            return ef_fail(err, "fog spec '%s': up='%s' is not y, z, -y, -z or X,Y,Z (non-zero)",
                           spec, val);
        c->has_up = 1;
        return 0;
    }
    if (!strcmp(key, "distance") && c->model->uses_distance) {
        if (!strcmp(val, "radial"))
            c->distance = EF_DIST_RADIAL;
        else if (!strcmp(val, "planar"))
            c->distance = EF_DIST_PLANAR;
        else
            return ef_fail(err, "fog spec '%s': distance='%s' is not radial or planar", spec, val);
        return 0;
    }
    for (int k = 0; c->model->keys[k]; ++k) {
        if (strcmp(c->model->keys[k], key))
            continue;
        if (c->seen & (1u << k))
            return ef_fail(err, "fog spec '%s': key '%s' is given twice", spec, key);
        c->seen |= 1u << k;
        return c->model->set(c, k, val, err);
    }
    return ef_fail(err, "fog spec '%s': unknown key '%s' for model '%s' (keys: %s)", spec, key,
                   c->model->name, keys);
}

int ef_fog_copy(ef_fog_component *dst, const ef_fog_component *src)
{
    *dst = *src;
    dst->arr = NULL;
    dst->path = NULL;
    dst->spec = (char *) ef_spec_none;
    if (src->spec != ef_spec_none && src->spec && !(dst->spec = strdup(src->spec))) {
        dst->spec = (char *) ef_spec_none;
        return -1;
    }
    if (src->path && !(dst->path = strdup(src->path)))
        return -1;
    if (src->narr > 0) {
        dst->arr = malloc((size_t) src->narr * sizeof *dst->arr);
        if (!dst->arr) {
            dst->narr = 0;
            return -1;
        }
        memcpy(dst->arr, src->arr, (size_t) src->narr * sizeof *dst->arr);
    }
    return 0;
}

void ef_fog_bind(ef_fog_component *c, const double org[3])
{
    ef_fog_functional f;
    c->bound = 0;
    if (c->model->bind)
        c->model->bind(c, org);
    if (!c->model->functionals || c->model->functionals(c, &f, 1) < 1)
        return;
    /* ef_dd_dot3 adds d last, so n.org + d later is the same bits as in one go. */
    const ef_dd d = ef_dd_add(ef_dd_add(ef_two_prod(f.n[0], org[0]), ef_two_prod(f.n[1], org[1])),
                              ef_two_prod(f.n[2], org[2]));
    memcpy(c->bound_org, org, sizeof c->bound_org);
    c->bound_dot[0] = d.hi;
    c->bound_dot[1] = d.lo;
    c->bound = 1;
}

const char ef_spec_none[] = "";

void ef_fog_free(ef_fog_component *c)
{
    free(c->arr);
    free(c->path);
    if (c->spec != ef_spec_none)
        free(c->spec);
    c->arr = NULL;
    c->path = NULL;
    c->spec = (char *) ef_spec_none;
    c->narr = 0;
}

char *ef_spec_next(const char *tok, char **save)
{
    char *next = strtok_r(NULL, ":", save);
    /* color=SPACE:R,G,B holds the SPEC separator: the part after it has no
     * '=' and belongs to the colour (strtok_r left the two tokens adjacent,
     * so the ':' is put back). */
    while (next && !strncmp(tok, "color=", 6) && !strchr(next, '=')) {
        next[-1] = ':';
        next = strtok_r(NULL, ":", save);
    }
    return next;
}

int ef_fog_parse(const char *spec, const ef_fog_context *ctx, ef_fog_component *c, ef_err *err)
{
    char buf[EF_SPEC_MAX + 1];
    ef_fog_context dflt;
    if (!ctx) {
        ef_fog_context_init(&dflt);
        ctx = &dflt;
    }
    memset(c, 0, sizeof *c);
    c->spec = (char *) ef_spec_none;
    if (strlen(spec) >= sizeof buf)
        return ef_fail(err, "fog spec '%.40s...' is too long", spec);
    snprintf(buf, sizeof buf, "%s", spec);

    if (strstr(spec, "::") || spec[0] == ':' || (spec[0] && spec[strlen(spec) - 1] == ':'))
        return ef_fail(err, "fog spec '%s' has an empty KEY=VALUE (write MODEL:KEY=VALUE:...)", spec);
    char *save = NULL;
    char *name = strtok_r(buf, ":", &save);
    char models[256];
    list_models(models, sizeof models);
    if (!name || !*name)
        return ef_fail(err, "fog spec '%s' is empty (write MODEL[:KEY=VALUE]..., models: %s)", spec, models);
    c->model = ef_fog_model_find(name);
    if (!c->model)
        return ef_fail(err, "fog spec '%s': unknown model '%s' (models: %s)", spec, name, models);
    if (!(c->spec = strdup(spec))) {
        c->spec = (char *) ef_spec_none;
        return ef_fail(err, "out of memory");
    }
    char *tok = strtok_r(NULL, ":", &save);
    while (tok) {
        char *next = ef_spec_next(tok, &save);
        if (parse_token(c, tok, c->spec, ctx, err)) {
            ef_fog_free(c);
            return -1;
        }
        tok = next;
    }
    if (!c->has_up)
        memcpy(c->up, ctx->up, sizeof c->up);
    if (c->has_g && c->phase != EF_PHASE_HG && c->phase != EF_PHASE_CS) {
        ef_fail(err, "fog spec '%s': g= applies to phase=hg or phase=cs only", c->spec);
        ef_fog_free(c);
        return -1;
    }
    if (c->model->finish(c, ctx, err)) {
        ef_fog_free(c);
        return -1;
    }
    return 0;
}
