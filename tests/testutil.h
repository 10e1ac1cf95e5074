/* Helpers shared by the test programs: writing and reading small EXRs
 * with OpenEXRCore, temp paths, and running the exrfog binary. */
#ifndef EF_TESTUTIL_H
#define EF_TESTUTIL_H

#include <openexr.h>
#include <stddef.h>
#include <stdint.h>

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
    const uint32_t *uplane[TU_MAX_CH]; /* set by tu_part_add_uint: written as uint, exactly */
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

/* Adds a UINT channel whose values are written exactly (no float detour,
 * so values above 2^24 survive). */
void tu_part_add_uint(tu_part *p, const char *name, const uint32_t *plane);

/* Writes parts to path. Returns 0 or a Core error code. */
int tu_write_exr(const char *path, const tu_part *parts, int nparts);

/* Reads channel `name` of part `part` into a new float array (data window,
 * row-major); sets *w, *h. NULL on failure. The caller frees. */
float *tu_read_channel(const char *path, int part, const char *name, int *w, int *h);

/* Like tu_read_channel, for a UINT channel read as uint32 (exact). NULL on
 * failure or when the channel is not UINT. */
uint32_t *tu_read_channel_uint(const char *path, int part, const char *name, int *w, int *h);

/* One part read back whole, in one decode pass: every channel as 32-bit
 * values (UINT channels as uint32_t, HALF and FLOAT as float, HALF widened
 * exactly), data-window rows, plus the header facts tests compare. */
typedef struct tu_image {
    char name[256];                   /* part name, "" when none */
    int dw[4], disp[4];
    int w, h;
    int tiled, tile_x, tile_y;
    exr_compression_t comp;
    int nch;
    char **ch;                        /* channel names, file order */
    exr_pixel_type_t *type;
    void **plane;                     /* w*h 32-bit values each */
} tu_image;

/* Reads part `part` of path. Returns 0, or -1 (img zeroed). */
int tu_read_image(const char *path, int part, tu_image *img);
void tu_image_free(tu_image *img);
/* Index of channel name, or -1. */
int tu_image_find(const tu_image *img, const char *name);
/* The plane of a HALF/FLOAT channel, or NULL (absent or UINT). */
const float *tu_image_f(const tu_image *img, const char *name);
/* The plane of a UINT channel, or NULL (absent or not UINT). */
const uint32_t *tu_image_u(const tu_image *img, const char *name);

/* Number of parts in path, or -1 when it cannot be read. */
int tu_nparts(const char *path);

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
