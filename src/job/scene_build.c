/* The one scene builder (see scene_build.h): the command line, the scene
 * file and the library all build scenes here, so they accept exactly the
 * same things. */
#include "scene_build.h"
#include "env_file.h"
#include "shadow_file.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lit.h"
#include "scene_file.h"

/* The scene file's settings under the flags: colour, up, units, time, aov
 * and sky. */
static ef_parse_result apply_file(ef_fog_scene *s, const ef_scene_desc *d, const ef_scene_file *sf,
                                  ef_scene_found *found, ef_err *err)
{
    if (sf->has_color)
        memcpy(s->color, sf->color, sizeof s->color);
    if (sf->has_up)
        memcpy(s->ctx.up, sf->up, sizeof s->ctx.up);
    found->up_set |= sf->has_up;
    if (sf->has_units)
        s->ctx.units_per_meter = sf->units;
    if (sf->has_time)
        s->ctx.time = sf->time;
    found->time_set |= sf->has_time;
    found->aov |= sf->aov;
    if (sf->has_sky && ef_scene_parse_sky(s, sf->sky, err)) {
        char msg[sizeof err->msg];
        snprintf(msg, sizeof msg, "%s", err->msg);
        ef_fail(err, "sky: %s", msg);
        err->file = d->scene_file;
        return EF_PARSE_FAIL;
    }
    return EF_PARSE_RUN;
}

/* The fog colour as written, in the working space. */
static ef_parse_result apply_color(ef_fog_scene *s, const char *t, ef_colour *colour, ef_err *err)
{
    if (!ef_colour_parse(colour, t, s->color, err))
        return EF_PARSE_RUN;
    char msg[sizeof err->msg];
    snprintf(msg, sizeof msg, "%s", err->msg);
    if (ef_out_of_range(t, 0))
        ef_fail(err, "--fog-color '%s' is out of range (numbers are 0 or between 2.2e-308 "
                     "and 1.8e308 in magnitude; colours at most 65504)", t);
    else if (t[0] != '#' && !strchr(t, ':'))
        ef_fail(err, "--fog-color '%s' is not R,G,B (three numbers from 0 to %g), #RRGGBB "
                     "or SPACE:R,G,B", t, EF_COLOR_MAX);
    else
        ef_fail(err, "--fog-color '%s': %s", t, msg);
    /* a config that cannot be opened is a runtime error */
    return strstr(msg, "colour management:") ? EF_PARSE_FAIL : EF_PARSE_USAGE;
}

/* The scene file's components: a profile the component names keeps its
 * own name in the message. */
static ef_parse_result add_file_specs(ef_fog_scene *s, const ef_scene_desc *d,
                                      const ef_scene_file *sf, ef_err *err)
{
    for (int i = 0; i < sf->nspec; ++i)
        if (ef_scene_add(s, sf->specs[i], err)) {
            char msg[sizeof err->msg];
            snprintf(msg, sizeof msg, "%s", err->msg);
            if (err->file)
                ef_fail(err, "%s: %s: %s", sf->where[i], err->file, msg);
            else
                ef_fail(err, "%s: %s", sf->where[i], msg);
            err->file = d->scene_file;
            return EF_PARSE_FAIL;
        }
    return EF_PARSE_RUN;
}

ef_parse_result ef_scene_build(ef_fog_scene *s, const ef_scene_desc *d, ef_colour *colour,
                               ef_scene_found *found, ef_err *err)
{
    ef_scene_file sf;
    memset(&sf, 0, sizeof sf);
    memset(found, 0, sizeof *found);
    ef_parse_result r = EF_PARSE_RUN;
    if (d->scene_file) {
        if (ef_scene_file_read(d->scene_file, &sf, err)) {
            err->file = d->scene_file;
            return EF_PARSE_FAIL;
        }
        if ((r = apply_file(s, d, &sf, found, err)) != EF_PARSE_RUN)
            goto out;
    }
    if (d->has_color && (r = apply_color(s, d->color_text, colour, err)) != EF_PARSE_RUN)
        goto out;
    if (d->has_up)
        memcpy(s->ctx.up, d->up, sizeof s->ctx.up);
    found->up_set |= d->has_up;
    if (d->has_units)
        s->ctx.units_per_meter = d->units;
    if (d->has_time)
        s->ctx.time = d->time;
    found->time_set |= d->has_time;
    if (d->has_sky && ef_scene_parse_sky(s, d->sky, err)) {
        r = EF_PARSE_USAGE;
        goto out;
    }
    s->ctx.read_file = ef_read_text_file;
    s->ctx.parse_color = ef_colour_parse;
    s->ctx.color_user = colour;
    s->ctx.load_shadow = ef_shadow_load;
    s->ctx.load_sky = ef_sky_load;
    if ((r = add_file_specs(s, d, &sf, err)) != EF_PARSE_RUN)
        goto out;
    found->scene_text = sf.text;   /* kept for exrfog/history: the file is read once */
    sf.text = NULL;
    for (int i = 0; i < d->nspec; ++i)
        if (ef_scene_add(s, d->specs[i], err)) {
            /* A profile file that is missing or wrong is a runtime error. */
            r = err->file ? EF_PARSE_FAIL : EF_PARSE_USAGE;
            break;
        }
    for (int i = 0; r == EF_PARSE_RUN && i < sf.nlight; ++i)
        if (ef_scene_add_light(s, sf.lights[i], err)) {
            char msg[sizeof err->msg];
            snprintf(msg, sizeof msg, "%s", err->msg);
            ef_fail(err, "%s: %s", sf.lwhere[i], msg);
            if (!err->file)   /* else the shadow map it names is at fault */
                err->file = d->scene_file;
            r = EF_PARSE_FAIL;
        }
    for (int i = 0; r == EF_PARSE_RUN && i < d->nlight; ++i)
        if (ef_scene_add_light(s, d->lights[i], err))
            r = err->file ? EF_PARSE_FAIL : EF_PARSE_USAGE;   /* a shadow map's fault: 1 */
    /* A light brighter than a half can hold lights pixels past it, which a
     * half output writes as +inf: refused as a fog colour past it is. */
    for (int i = 0; r == EF_PARSE_RUN && i < s->nlight; ++i) {
        const ef_light *l = &s->light[i];
        const double U = s->ctx.units_per_meter, scale = ef_light_at_position(l) ? U * U : 1;
        const double e = fmax(l->e[0], fmax(l->e[1], l->e[2])) / scale;
        if (e > EF_COLOR_MAX) {
            ef_fail(err, "light '%s': color times intensity is %g, past %g (the largest half, "
                         "as fog colours are held to); give the scene's light in the units "
                         "its image is in", l->name, e, EF_COLOR_MAX);
            r = EF_PARSE_USAGE;
        }
    }
    if (r == EF_PARSE_RUN && ef_lights_check(s, err))
        r = EF_PARSE_USAGE;
    /* after the components: the sky light is convolved with their phases */
    const char *sky_light = d->sky_light ? d->sky_light : sf.sky_light;
    if (r == EF_PARSE_RUN && sky_light && ef_scene_set_sky_light(s, sky_light, err)) {
        r = err->file ? EF_PARSE_FAIL : EF_PARSE_USAGE;
        if (!d->sky_light && !err->file) {
            char msg[sizeof err->msg];
            snprintf(msg, sizeof msg, "%s", err->msg);
            ef_fail(err, "sky_light: %s", msg);
            err->file = d->scene_file;
            r = EF_PARSE_FAIL;
        }
    }
    /* the solves the lights need from the final scene (ms.h), the sky's
     * included */
    if (r == EF_PARSE_RUN && ef_scene_prepare_lights(s, err))
        r = EF_PARSE_USAGE;
out:
    ef_scene_file_free(&sf);
    return r;
}

int ef_scene_rebuild(ef_fog_scene *s, const double *up, double time, ef_err *err)
{
    ef_fog_scene *ns = malloc(sizeof *ns);
    if (!ns)
        return ef_fail(err, "out of memory for the scene");
    *ns = *s;
    ns->ncomp = 0;
    if (up)
        memcpy(ns->ctx.up, up, sizeof ns->ctx.up);
    ns->ctx.time = time;
    for (int i = 0; i < s->ncomp; ++i)
        if (ef_scene_add(ns, s->comp[i].spec, err)) {
            ns->nlight = 0;   /* the lights are still s's */
            ns->sky_light = NULL;
            ef_scene_free(ns);
            free(ns);
            return -1;
        }
    s->nlight = 0;   /* the lights moved to ns */
    s->sky_light = NULL;
    ef_scene_free(s);
    *s = *ns;
    free(ns);
    return ef_scene_prepare_lights(s, err);
}
