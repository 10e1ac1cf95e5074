/* Scene files (--scene FILE, JSON): the fog components, colour, sky, up
 * axis, units, time and AOVs of a scene, with the SPEC grammar's names. The
 * reader turns each component into a SPEC string; the core parses it as it
 * parses --fog. */
#ifndef EF_SCENE_FILE_H
#define EF_SCENE_FILE_H

#include "error.h"
#include "fog.h"
#include "light.h"

typedef struct ef_scene_file {
    char *specs[EF_FOG_MAX_COMPONENTS];      /* malloc'd SPEC strings */
    char where[EF_FOG_MAX_COMPONENTS][64];   /* each one's path in the file, e.g. "fog[2]" */
    int nspec;
    char *lights[EF_MAX_LIGHTS];             /* "lights": malloc'd --light SPECs */
    char lwhere[EF_MAX_LIGHTS][64];          /* e.g. "lights[0]" */
    int nlight;
    int has_color, has_up, has_units, has_sky, has_time;
    double color[3], up[3], units, time;
    unsigned aov;                            /* EF_AOV_* bits of "aov" (0: none) */
    char sky[64];                            /* as --sky takes it: fog, keep, distance=D */
    char *sky_light;                         /* "sky_light": a --sky-light SPEC (malloc'd), or NULL */
    char *text;                              /* the file as read, for provenance */
} ef_scene_file;

/* Reads and checks path. On error returns -1; the message names the
 * offending key and its path in the file (e.g. "fog[1].density: ..."). */
int ef_scene_file_read(const char *path, ef_scene_file *out, ef_err *err);

/* Releases the SPEC strings and the text. */
void ef_scene_file_free(ef_scene_file *f);

/* Reads a whole text file into a malloc'd NUL-terminated buffer (the fog
 * context's read_file). On error returns -1 with err->file set to path. */
int ef_read_text_file(const char *path, char **text, ef_err *err);

#endif
