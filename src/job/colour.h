/* Colour management for the command line: the OpenColorIO config (opened
 * when first needed), the image's working space, and the colours the user
 * writes (R,G,B, #RRGGBB, SPACE:R,G,B) turned into working-space values. */
#ifndef EF_COLOUR_H
#define EF_COLOUR_H

#include <stddef.h>

#include "error.h"
#include "exr_io.h"
#include "ocio_shim.h"

/* One run's colour state: the config (opened when first needed), where it
 * came from, and the working space once an image is read. */
typedef struct ef_colour {
    const char *config_path, *colorspace;
    ef_ocio *ocio;
    int open_failed;
    char where[600], open_msg[900];
    int converted;
    int resolved;             /* ef_colour_working has run: colours are final */
    char space[256], source[300];
} ef_colour;

/* The run's colour settings: --colorconfig (NULL: $OCIO, else exrfog's)
 * and --colorspace (NULL: from the header). Call once before parsing. */
void ef_colour_setup(ef_colour *g, const char *config, const char *colorspace);

/* The config, opened on first use; NULL with err set (naming the file)
 * when it cannot be opened. */
const ef_ocio *ef_colour_config(ef_colour *g, ef_err *err);

/* Where the config came from ("exrfog's config FILE", "$OCIO=FILE"...). */
const char *ef_colour_config_where(const ef_colour *g);

/* A colour as the user wrote it, in the current working space: plain
 * numbers need no config; #RRGGBB and SPACE:R,G,B go through OCIO. The
 * signature is the core's ef_fog_context.parse_color (user: the ef_colour). */
int ef_colour_parse(void *user, const char *text, double out[3], ef_err *err);

/* Whether a colour needed a conversion (so it depends on the working
 * space, and the scene is read again once the image's space is known). */
int ef_colour_converted(const ef_colour *g);

/* Resolves the working space of part `part` of f: --colorspace, else the
 * header (colorSpace, oiio:ColorSpace, arnold/color_space, chromaticities
 * matched to a config space), else the config's scene_linear role. Opens
 * the config only when it is needed: with plain colours, no --colorspace
 * and no preview, nothing here can fail. Returns 0, or an exit status (1,
 * or 2 for a --colorspace the config lacks) with err set. need says
 * whether colour management is needed for this run at all. */
int ef_colour_working(ef_colour *g, const ef_exr_file *f, int part, int need, ef_err *err);

/* The working space and where it came from ("" before ef_colour_working
 * resolved it, or when it was not needed). */
const char *ef_colour_space(const ef_colour *g);
const char *ef_colour_space_source(const ef_colour *g);

/* Releases the config. */
void ef_colour_close(ef_colour *g);

#endif
