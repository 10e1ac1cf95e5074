/* OpenColorIO behind a C interface.
 *
 * Every string output goes to a caller buffer (out, len) and is always
 * NUL-terminated when len > 0; a result that does not fit counts as a
 * failure. No C++ exception crosses this interface. A handle may be shared
 * between threads once opened (all queries are const); only
 * ef_ocio_display_apply is meant for hot loops. */
#ifndef EF_OCIO_SHIM_H
#define EF_OCIO_SHIM_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The linked OpenColorIO version string. */
const char *ef_ocio_version(void);

typedef struct ef_ocio ef_ocio;
typedef struct ef_ocio_display ef_ocio_display;

/* Opens and validates a config: path (from --colorconfig) if not NULL, else
 * $OCIO if set and non-empty, else exrfog's shipped config (the installed
 * share/exrfog/ocio/exrfog-config.ocio if it exists, else the source tree's
 * share/ocio/exrfog-config.ocio). where receives which one was used, e.g.
 * "--colorconfig FILE", "$OCIO=FILE" or "exrfog's config FILE". Returns NULL
 * on failure with msg saying what is wrong (missing file, not a config,
 * OCIO's own reason) and how to fix it. */
ef_ocio *ef_ocio_open(const char *path, char *where, size_t where_len, char *msg,
                      size_t msg_len);
/* Frees the handle (NULL is fine). Displays opened from it stay valid. */
void ef_ocio_close(ef_ocio *o);

/* 1 if name is a colour space of the config, one of its aliases or a role
 * (matched case-insensitively, as OCIO does), with the canonical space name
 * written to canonical (may be NULL); 0 otherwise. */
int ef_ocio_space_exists(const ef_ocio *o, const char *name, char *canonical, size_t len);

/* 0 and the canonical name of the space the role (scene_linear, data,
 * color_picking, ...) points to; -1 if the config lacks the role. */
int ef_ocio_role(const ef_ocio *o, const char *role, char *out, size_t len);

/* Finds the config's linear scene-referred colour space with the primaries
 * and white of chrom = {rx, ry, gx, gy, bx, by, wx, wy} (the EXR
 * chromaticities attribute). Each candidate's RGB -> ACES2065-1 matrix is
 * measured through OCIO (role aces_interchange), taken to XYZ with the AP0
 * primaries, adapted from the ACES white to chrom's white with Bradford, and
 * its primaries compared with chrom: 0 and the name of the closest space
 * within 1e-3 in x and y, -1 if none (or the config has no aces_interchange
 * role). */
int ef_ocio_space_from_chromaticities(const ef_ocio *o, const float chrom[8], char *out,
                                      size_t len);

/* Parses a colour into the working space (a space name, alias or role; NULL
 * means the scene_linear role): "R,G,B" is already in the working space and
 * returned as is; "#RRGGBB" is 8-bit sRGB texture (the config's "sRGB -
 * Texture"/srgb_texture space) converted to working; "SPACE:R,G,B" is
 * converted from any config space, split at the last ':' (names may hold ':'
 * and spaces). Returns 0, or -1 with msg naming the problem (malformed text,
 * unknown space with some valid names listed). */
int ef_ocio_parse_color(const ef_ocio *o, const char *text, const char *working,
                        double rgb[3], char *msg, size_t msg_len);

/* Opens a CPU processor from the working space (NULL: scene_linear) through
 * a display and view: display_view is "DISPLAY, VIEW" (split at the comma
 * where both halves name a display and one of its views, so names may hold
 * commas), "DISPLAY" alone for its default view, or NULL/"" for the config's
 * default display and view. used receives "DISPLAY, VIEW". Returns NULL with
 * msg (listing the displays and views) on failure. */
ef_ocio_display *ef_ocio_display_open(const ef_ocio *o, const char *working,
                                      const char *display_view, char *used, size_t used_len,
                                      char *msg, size_t msg_len);
/* Opens a CPU processor from the working space (NULL: scene_linear) to
 * the colour space target (a name, alias or role; NULL: the config's sRGB
 * texture space), for files written in that space. used receives the
 * target's canonical name. Returns NULL with msg on failure (an unknown
 * name: some of the config's spaces listed). Applied and freed as a
 * display. */
ef_ocio_display *ef_ocio_space_open(const ef_ocio *o, const char *working, const char *target,
                                    char *used, size_t used_len, char *msg, size_t msg_len);

/* Applies the display transform in place to npixels interleaved RGB floats.
 * Thread-safe (concurrent calls on one display are fine). 0, or -1 if OCIO
 * failed (the pixels are then unspecified). */
int ef_ocio_display_apply(const ef_ocio_display *d, float *rgb, long npixels);
/* Frees the display (NULL is fine). */
void ef_ocio_display_close(ef_ocio_display *d);

#ifdef __cplusplus
}
#endif

#endif
