/* Helpers shared by the test programs: writing and reading small EXRs
 * with OpenEXRCore, temp paths, and running the exrfog binary. */
#ifndef EF_TESTUTIL_H
#define EF_TESTUTIL_H

#include <openexr.h>
#include <stddef.h>

#define TU_MAX_CH 16

typedef struct tu_attr_m44 { const char *name; float m[16]; } tu_attr_m44;
typedef struct tu_attr_float { const char *name; float v; } tu_attr_float;

/* One part to write. Planes are float, w*h of the data window, row-major. */
typedef struct tu_part {
    const char *name;                 /* NULL for an unnamed single part */
    int dw[4], disp[4];               /* xmin ymin xmax ymax */
    int nch;
    const char *ch[TU_MAX_CH];
    exr_pixel_type_t type[TU_MAX_CH];
    const float *plane[TU_MAX_CH];
    exr_compression_t comp;
    int tile;                         /* 0: scanline, else NxN tiles */
    tu_attr_m44 m44[4];               /* name NULL ends the list */
    tu_attr_float f[4];
    const char *str_name, *str_value; /* one optional string attribute */
} tu_part;

/* Fills p with a single unnamed scanline part of w x h at (0,0), ZIP. */
void tu_part_init(tu_part *p, int w, int h);
/* Adds a channel to p. */
void tu_part_add(tu_part *p, const char *name, exr_pixel_type_t type, const float *plane);

/* Writes parts to path. Returns 0 or a Core error code. */
int tu_write_exr(const char *path, const tu_part *parts, int nparts);

/* Reads channel `name` of part `part` into a new float array (data window,
 * row-major); sets *w, *h. NULL on failure. The caller frees. */
float *tu_read_channel(const char *path, int part, const char *name, int *w, int *h);

/* A path in this test program's scratch directory (created on demand).
 * Returns a new string; the caller frees. */
char *tu_path(const char *file);

/* Runs "$EXRFOG_BIN ARGS" through the shell; stdout and stderr go to the
 * given buffers (NULL to discard). Returns the exit status. */
int tu_run(const char *args, char *out, size_t outlen, char *err, size_t errlen);

/* 1 if the file exists. */
int tu_exists(const char *path);

/* Directory of ../shared/real-exr, or NULL when absent. */
const char *tu_real_exr_dir(void);

/* Copies a file; returns 0 on success. */
int tu_copy(const char *from, const char *to);

#endif
