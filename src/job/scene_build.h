/* The one scene builder: what --scene, --fog, --fog-color, --sky,
 * --up-axis, --units-per-meter and --time say, or the same through the
 * library's exrfog_scene_create, turned into an ef_fog_scene. */
#ifndef EF_SCENE_BUILD_H
#define EF_SCENE_BUILD_H

#include "colour.h"
#include "parse_result.h"
#include "scene.h"

/* What a description of a scene says, applied in this order: a scene file
 * first, then the flags over it, then the SPECs. */
typedef struct ef_scene_desc {
    const char *scene_file;   /* or NULL */
    const char *specs[EF_FOG_MAX_COMPONENTS];
    int nspec;
    const char *lights[EF_MAX_LIGHTS];   /* --light SPECs */
    int nlight;
    const char *sky_light;    /* --sky-light SPEC, or NULL */
    int has_color, has_sky, has_up, has_units, has_time;
    double up[3], units, time;
    const char *color_text;   /* the fog colour as written: R,G,B, #RRGGBB, SPACE:R,G,B */
    const char *sky;
} ef_scene_desc;

/* What the builder found besides the scene. */
typedef struct ef_scene_found {
    int up_set, time_set;     /* the flags or the scene file gave them */
    unsigned aov;             /* the scene file's "aov" */
    char *scene_text;         /* the scene file as read (owned), or NULL */
} ef_scene_found;

/* Builds s (initialised by the caller) from d, with colours read through
 * colour (which the scene keeps as its parse_color user: it must outlive
 * s). Returns EF_PARSE_RUN; EF_PARSE_USAGE with err set for a bad value;
 * EF_PARSE_FAIL when a file (the scene file, a profile, the colour config)
 * is missing or wrong, err->file naming it. found->scene_text is owned by
 * the caller whatever the result. */
ef_parse_result ef_scene_build(ef_fog_scene *s, const ef_scene_desc *d, ef_colour *colour,
                               ef_scene_found *found, ef_err *err);

/* Reads every component again under a new up axis (NULL: keep) and time:
 * models fix their up and time when they are read. Returns 0 or -1. */
int ef_scene_rebuild(ef_fog_scene *s, const double *up, double time, ef_err *err);

#endif
