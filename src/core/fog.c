#include "fog.h"

#include <errno.h>
#include <stdio.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The registry: one line per model. */
static const ef_fog_model *const registry[] = {
    &ef_fog_linear,
    &ef_fog_exp,
    &ef_fog_exp2,
};

const ef_fog_model *ef_fog_model_find(const char *name)
{
    for (size_t i = 0; i < sizeof registry / sizeof registry[0]; ++i)
        if (!strcmp(registry[i]->name, name))
            return registry[i];
    return NULL;
}

int ef_parse_numbers(const char *text, double *out, int n)
{
    const char *s = text;
    for (int i = 0; i < n; ++i) {
        char *end;
        errno = 0;
        double v = strtod(s, &end);
        if (end == s || errno == ERANGE || !isfinite(v))
            return -1;
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
    snprintf(buf, len, "distance");
    for (int i = 0; m->keys[i]; ++i) {
        strncat(buf, ", ", len - strlen(buf) - 1);
        strncat(buf, m->keys[i], len - strlen(buf) - 1);
    }
}

/* Applies one KEY=VALUE token (tok is modified in place). */
static int parse_token(ef_fog_component *c, char *tok, const char *spec, ef_err *err)
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
    if (!strcmp(key, "distance")) {
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

int ef_fog_parse(const char *spec, ef_fog_component *c, ef_err *err)
{
    char buf[sizeof c->spec];
    memset(c, 0, sizeof *c);
    if (strlen(spec) >= sizeof buf)
        return ef_fail(err, "fog spec '%.40s...' is too long", spec);
    snprintf(c->spec, sizeof c->spec, "%s", spec);
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
    for (char *tok = strtok_r(NULL, ":", &save); tok; tok = strtok_r(NULL, ":", &save))
        if (parse_token(c, tok, c->spec, err))
            return -1;
    return c->model->finish(c, err);
}
