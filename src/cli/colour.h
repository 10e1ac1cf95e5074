/* Colour management for the command line: the OpenColorIO config (opened
 * when first needed), the image's working space, and the colours the user
 * writes (R,G,B, #RRGGBB, SPACE:R,G,B) turned into working-space values. */
#ifndef EF_COLOUR_H
#define EF_COLOUR_H

#include <stddef.h>

#include "error.h"
#include "exr_io.h"
#include "ocio_shim.h"

/* The run's colour settings: --colorconfig (NULL: $OCIO, else exrfog's)
 * and --colorspace (NULL: from the header). Call once before parsing. */
void ef_colour_setup(const char *config, const char *colorspace);

/* The config, opened on first use; NULL with err set (naming the file)
 * when it cannot be opened. */
const ef_ocio *ef_colour_config(ef_err *err);

/* Where the config came from ("exrfog's config FILE", "$OCIO=FILE"...). */
const char *ef_colour_config_where(void);

/* A colour as the user wrote it, in the current working space: plain
 * numbers need no config; #RRGGBB and SPACE:R,G,B go through OCIO. The
 * signature is the core's ef_fog_context.parse_color (user unused). */
int ef_colour_parse(void *user, const char *text, double out[3], ef_err *err);

/* Whether a colour needed a conversion (so it depends on the working
 * space, and the scene is read again once the image's space is known). */
int ef_colour_converted(void);

/* Resolves the working space of part `part` of f: --colorspace, else the
 * header (colorSpace, oiio:ColorSpace, arnold/color_space, chromaticities
 * matched to a config space), else the config's scene_linear role. Opens
 * the config only when it is needed: with plain colours, no --colorspace
 * and no preview, nothing here can fail. Returns 0, or an exit status (1,
 * or 2 for a --colorspace the config lacks) with err set. need says
 * whether colour management is needed for this run at all. */
int ef_colour_working(const ef_exr_file *f, int part, int need, ef_err *err);

/* The working space and where it came from ("" before ef_colour_working
 * resolved it, or when it was not needed). */
const char *ef_colour_space(void);
const char *ef_colour_space_source(void);

/* Releases the config. */
void ef_colour_close(void);

#endif
