/* Deliverables other than EXR (-o shot.png, .tif, .dpx, .jpg...): the
 * sample type, the channels, the colour encoding and the geometry, all
 * decided and checked against the format's writer before a pixel is read. */
#ifndef EF_DELIVER_H
#define EF_DELIVER_H

#include "job_impl.h"
#include "foreign.h"

typedef struct ef_deliver {
    ef_oiio_deliver d;        /* what the writer is given */
    char ext[32];             /* ".png", lower case */
    char fmt[32];             /* "PNG", for messages */
    int alpha;                /* the format holds alpha and it is written */
    int integer;              /* an integer type: display-referred, encoded */
    int noted;                /* the note on a dropped alpha was given */
    char space[256];          /* the colour space of the file's values */
    ef_ocio_display *proc;    /* working space -> space, or NULL */
} ef_deliver;

/* Plans output (whose extension ext is not .exr) from -d, --crop and the
 * format: the type (DPX uint10 RGB, TIFF uint16, PNG and JPEG uint8 unless
 * -d says; others the writer's choice from float), whether alpha is
 * written, all checked by opening a 1x1 probe with the writer. Returns 0,
 * or 2 (a usage error: a type or channel count the format cannot hold, a
 * discard format) with err set. */
int ef_deliver_plan(ef_job *J, const char *ext, ef_deliver *dv, ef_err *err);

/* Opens the colour encoding once the working space is known: integer
 * outputs (and any with --output-colorspace) go from the working space to
 * --output-colorspace or the config's sRGB texture space, and are labelled
 * with it (oiio:ColorSpace; DPX's transfer and colorimetric codes).
 * Returns 0, or an exit status (2 for an unknown space) with err set. */
int ef_deliver_colour(ef_job *J, ef_deliver *dv, ef_err *err);

/* Whether the working space must be resolved for this output. */
int ef_deliver_needs_colour(const ef_job *J, const ef_deliver *dv);

/* Releases the encoding. */
void ef_deliver_free(ef_deliver *dv);

#endif
