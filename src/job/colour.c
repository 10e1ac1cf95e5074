#include "colour.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fog.h"


void ef_colour_setup(ef_colour *g, const char *config, const char *colorspace)
{
    ef_colour_close(g);
    memset(g, 0, sizeof *g);
    g->config_path = config;
    g->colorspace = colorspace;
}

const ef_ocio *ef_colour_config(ef_colour *g, ef_err *err)
{
    if (!g->ocio && !g->open_failed) {
        g->ocio = ef_ocio_open(g->config_path, g->where, sizeof g->where, g->open_msg, sizeof g->open_msg);
        g->open_failed = g->ocio == NULL;
    }
    if (!g->ocio) {
        ef_fail(err, "colour management: %s", g->open_msg);
        const char *env = getenv("OCIO");
        ef_err_set_file(err, g->config_path ? g->config_path
                             : env && env[0] ? env
                                             : "exrfog's OpenColorIO config");
    }
    return g->ocio;
}

const char *ef_colour_config_where(const ef_colour *g)
{
    return g->where;
}

/* Plain numbers: R,G,B or one grey. */
static int plain(const char *text)
{
    return text[0] != '#' && strchr(text, ':') == NULL;
}

int ef_colour_parse(void *user, const char *text, double out[3], ef_err *err)
{
    ef_colour *g = user;
    if (plain(text)) {
        if (ef_parse_color(text, out))
            return ef_fail(err, "not a colour: write R,G,B (numbers from 0 to %g, in the working "
                                "space), #RRGGBB (sRGB) or SPACE:R,G,B", EF_COLOR_MAX);
        return 0;
    }
    const ef_ocio *o = ef_colour_config(g, err);
    if (!o)
        return -1;
    char msg[800];
    if (ef_ocio_parse_color(o, text, g->space[0] ? g->space : NULL, out, msg, sizeof msg))
        return ef_fail(err, "%s", msg);
    /* Before the image's working space is known the value is provisional
     * (it is read again per image): only the final one is checked. */
    if (g->resolved) {
        int neg = 0, big = 0;
        for (int k = 0; k < 3; ++k) {
            /* A saturated colour of a wide space may leave a small one. */
            if (out[k] < 0 && out[k] > -1e-6)
                out[k] = 0;
            neg |= !(out[k] >= 0);
            big |= out[k] > EF_COLOR_MAX;
        }
        const char *ws = g->space[0] ? g->space : "scene_linear";
        if (neg)
            return ef_fail(err, "'%s' is %.6g, %.6g, %.6g in the working space %s: outside "
                                "its gamut (a fog colour is R,G,B >= 0)", text, out[0], out[1],
                           out[2], ws);
        if (big)
            return ef_fail(err, "'%s' is %.6g, %.6g, %.6g in the working space %s: above %d, "
                                "the largest value a half-float output holds (give a dimmer "
                                "colour)", text, out[0], out[1], out[2], ws, (int) EF_COLOR_MAX);
    }
    g->converted = 1;
    return 0;
}

int ef_colour_converted(const ef_colour *g)
{
    return g->converted;
}

/* A string attribute of the part, or NULL. */
static const char *str_attr(const ef_exr_file *f, int part, const char *name, char *buf, size_t len)
{
    const char *v = NULL;
    int32_t n = 0;
    if (exr_attr_get_string(f->ctx, part, name, &n, &v) != EXR_ERR_SUCCESS || !v || n <= 0)
        return NULL;
    snprintf(buf, len, "%.*s", (int) n, v);
    return buf;
}

int ef_colour_working(ef_colour *g, const ef_exr_file *f, int part, int need, ef_err *err)
{
    g->space[0] = g->source[0] = '\0';
    g->resolved = 1;
    if (!need && !g->colorspace)
        return 0;
    const ef_ocio *o = ef_colour_config(g, err);
    if (!o)
        return 1;
    char canon[256], buf[256];
    if (g->colorspace) {
        if (!ef_ocio_space_exists(o, g->colorspace, canon, sizeof canon))
            return ef_fail(err, "--colorspace '%s' is not a colour space of %s (see its spaces "
                                "with ociocheck, or give the config with --colorconfig)",
                           g->colorspace, g->where), 2;
        snprintf(g->space, sizeof g->space, "%s", canon);
        snprintf(g->source, sizeof g->source, "--colorspace %s", g->colorspace);
        return 0;
    }
    static const char *const attrs[] = { "colorSpace", "oiio:ColorSpace", "arnold/color_space" };
    for (size_t k = 0; k < sizeof attrs / sizeof attrs[0]; ++k) {
        const char *v = str_attr(f, part, attrs[k], buf, sizeof buf);
        if (!v)
            continue;
        if (!ef_ocio_space_exists(o, v, canon, sizeof canon))
            return ef_fail(err, "the header's %s '%s' is not a colour space of %s; pass "
                                "--colorspace NAME (or a config that has it with --colorconfig)",
                           attrs[k], v, g->where), 1;
        snprintf(g->space, sizeof g->space, "%s", canon);
        snprintf(g->source, sizeof g->source, "header %s '%s'", attrs[k], v);
        return 0;
    }
    exr_attr_chromaticities_t ch;
    if (exr_attr_get_chromaticities(f->ctx, part, "chromaticities", &ch) == EXR_ERR_SUCCESS) {
        const float c[8] = { ch.red_x, ch.red_y, ch.green_x, ch.green_y,
                             ch.blue_x, ch.blue_y, ch.white_x, ch.white_y };
        if (ef_ocio_space_from_chromaticities(o, c, canon, sizeof canon))
            return ef_fail(err, "the header's chromaticities (red %g,%g green %g,%g blue %g,%g "
                                "white %g,%g) match no linear space of %s; pass --colorspace NAME",
                           c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], g->where), 1;
        snprintf(g->space, sizeof g->space, "%s", canon);
        snprintf(g->source, sizeof g->source, "header chromaticities");
        return 0;
    }
    if (ef_ocio_role(o, "scene_linear", canon, sizeof canon))
        return ef_fail(err, "%s has no scene_linear role and the header names no colour space; "
                            "pass --colorspace NAME", g->where), 1;
    snprintf(g->space, sizeof g->space, "%s", canon);
    snprintf(g->source, sizeof g->source, "the config's scene_linear role (the header names none)");
    return 0;
}

const char *ef_colour_space(const ef_colour *g)
{
    return g->space;
}

const char *ef_colour_space_source(const ef_colour *g)
{
    return g->source;
}

void ef_colour_close(ef_colour *g)
{
    ef_ocio_close(g->ocio);
    g->ocio = NULL;
    g->open_failed = 0;
}
