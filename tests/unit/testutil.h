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

/* One part to write. Planes are w*h of the data window, row-major: float
 * (converted by Core to the channel type), or uint32 via tu_part_add_uint. */
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
    int tile_h;                       /* tiled: tile height when not tile (0: square) */
    tu_attr_m44 m44[4];               /* name NULL ends the list */
    tu_attr_float f[4];
    const char *str_name, *str_value; /* one optional string attribute */
    const char *multiview[4];         /* a multiView attribute (NULL ends it) */
} tu_part;

/* Fills p with a single unnamed scanline part of w x h at (0,0), ZIP. */
void tu_part_init(tu_part *p, int w, int h);
/* Adds a channel to p. */
void tu_part_add(tu_part *p, const char *name, exr_pixel_type_t type, const float *plane);

/* Adds a UINT channel whose values are written exactly (no float detour,
 * so values above 2^24 survive). */
void tu_part_add_uint(tu_part *p, const char *name, const uint32_t *plane);

/* Writes parts to path (dw is the data window, disp the display window).
 * Returns 0 or a Core error code. */
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

/* When args (an exrfog command line) wrote an OUTPUT that exists, reads it
 * back whole with OpenImageIO (the OpenEXR C++ library): returns 0 when it
 * reads or oiiotool is absent, -1 with a message otherwise. tu_run and
 * test_cli's runs call it after every successful run (exit 98 when it
 * fails), so every output the suite writes is read back by a second
 * implementation. */
int tu_check_readback(const char *args, char *why, size_t cap);
/* The same for a file written without the CLI (ef_exr_stream_file). */
int tu_check_readback_path(const char *path, char *why, size_t cap);

/* Captured output of the last tu_runf. */
extern char tu_out[1 << 16], tu_err[1 << 16];

/* tu_run with printf-style arguments; output lands in tu_out/tu_err. */
int tu_runf(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;

/* Runs exrfog with printf-style arguments and fails the test unless it
 * exits with `expect` (include after cmocka.h). */
#define assert_run(expect, ...)                                                           \
    do {                                                                                  \
        int st_ = tu_runf(__VA_ARGS__);                                                   \
        if (st_ != (expect)) {                                                            \
            print_error("exrfog exited %d, expected %d\nstdout: %s\nstderr: %s\n", st_,    \
                        (expect), tu_out, tu_err);                                        \
            fail();                                                                       \
        }                                                                                 \
    } while (0)

/* Writes len bytes of data to path (replacing it). Returns 0, or -1 on any
 * failure. */
int tu_write_bytes(const char *path, const void *data, size_t len);

/* 1 if the file exists. */
int tu_exists(const char *path);

/* Directory of ../shared/real-exr, or NULL when absent. */
const char *tu_real_exr_dir(void);

/* Marsaglia's xorshift32 step on *state (never 0): the tests' seeded
 * random numbers, the same sequence on every machine. */
uint32_t tu_xorshift32(uint32_t *state);
/* A uniform double in [0, 1) with 24 random bits, from tu_xorshift32. */
double tu_rand01(uint32_t *state);

/* Copies a file; returns 0 on success. */
int tu_copy(const char *from, const char *to);

/* ---- Comparing outputs with inputs and with independent expectations.
 * These print what differs (first few values) to stderr and return a
 * count, so a test asserts the count is 0. */

/* A float rounded to the nearest half (ties to even), widened back. */
float tu_half_round(float f);

/* Same channel names in the same order, same windows; same types, except
 * that pixel_type >= 0 (EXR_PIXEL_HALF/FLOAT) replaces every non-UINT
 * type. Returns the number of differences. */
long tu_compare_layout(const tu_image *in, const tu_image *out, int pixel_type);

/* Channel name of out against in: bit-exact when rel == 0 (after rounding
 * to half when as_half), else within rel * (1 + |v|). UINT compares as
 * uint32. Returns the number of differing pixels (1 when absent). */
long tu_compare_channel(const tu_image *in, const tu_image *out, const char *name, double rel,
                        int as_half);

/* Every part of out_path against in_path: count, part names, layout, and
 * every channel bit-exact except, in part skip_part, the channels named in
 * the NULL-terminated list skip (NULL: the whole part). Returns the number
 * of differences. */
long tu_compare_files(const char *in_path, const char *out_path, int skip_part,
                      const char *const *skip);

/* A pinhole written the way the tests think of it: pixel (x, y) of the
 * display window W x H has u = (x + 0.5 - disp.xmin) / W, v = (y + 0.5 -
 * disp.ymin) / H, and the camera-space ray ((u - cu) / a, -(v - cv) / b, 1)
 * (the NDC projection u = a X/Z + cu, v = -b Y/Z + cv). */
typedef struct tu_pinhole {
    int disp[4];
    double a, b, cu, cv;
} tu_pinhole;

/* A centred pinhole of horizontal fov hfov_deg, square pixels. */
void tu_pinhole_fov(tu_pinhole *p, const int disp[4], double hfov_deg);
/* A screen-space projection sx = px X/Z, sy = py Y/Z over [-1,1] (Arnold). */
void tu_pinhole_screen(tu_pinhole *p, const int disp[4], double px, double py);
/* Length of the ray through absolute pixel (x, y) (its z is 1). */
double tu_pinhole_ray_len(const tu_pinhole *p, int x, int y);

/* Expected exp fog: for planar depth z (sky when non-finite, <= 0 or >=
 * 1e9), T = exp(-rho z |ray|), Tinf = 0 and
 *   rgb = T rgb + (1 - T) a F + (1 - a) F,  alpha = 1. */
typedef struct tu_fog_check {
    const char *in, *out, *depth;     /* depth NULL: in */
    int in_part, out_part, depth_part;
    const char *rgba[4];              /* channel names; rgba[3] NULL: no alpha */
    const char *z;                    /* depth channel name in its part (UINT: its value) */
    const tu_pinhole *cam;
    double rho, F[3];
    double extra_rel, extra_abs;      /* slack for lossy output compressions */
    /* results */
    long sky, fogged;                 /* sky pixels; surface pixels with T < 0.999 */
} tu_fog_check;

/* Sets up a check of in -> out with channels R,G,B,A,Z, density rho and the
 * fog colour the tests pass (--fog-color 0.25,0.5,0.75). */
void tu_fog_check_init(tu_fog_check *fc, const char *in, const char *out, const tu_pinhole *cam,
                       double rho);

/* Compares every pixel of the output colour with the expectation, computed
 * from the input file's colour and the depth file's depth as stored.
 * Tolerance: 6e-4 relative for half outputs, 1e-5 for float, plus the
 * slack. Returns the number of differing values, -1 if unreadable. */
long tu_check_fog(tu_fog_check *fc);

#endif
