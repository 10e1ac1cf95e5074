/* OpenEXRCore adapter: opening and validating inputs, reading camera
 * metadata, finding the colour and depth channels, and streaming a file
 * chunk by chunk into a new one while a callback edits the colour. */
#ifndef EF_EXR_IO_H
#define EF_EXR_IO_H

#include <openexr.h>
#include <stdatomic.h>
#include <stdint.h>

#include "camera.h"
#include "error.h"

/* Widths and heights above this are refused as absurd (corrupt headers). */
#define EF_MAX_DIMENSION 262144
/* The most one worker's unit buffers may take: a part whose tile or chunk
 * needs more is refused as corrupt before anything is allocated. */
#define EF_WORKER_BYTES (1ull << 30)
/* The most all workers' unit buffers may take together: fewer threads run
 * when the chunks are large (documented with --threads). */
#define EF_STREAM_BYTES (2ull << 30)

typedef struct ef_exr_file {
    const char *path;
    exr_context_t ctx;
    int nparts;
} ef_exr_file;

/* Opens and validates path: an EXR whose parts are flat (not deep), not
 * subsampled, with sane windows. Returns 0, or -1 with a message. */
int ef_exr_open(const char *path, ef_exr_file *f, ef_err *err);
/* Releases what ef_exr_open took; safe on a zeroed struct. */
void ef_exr_close(ef_exr_file *f);

/* 1 when part p is a tiled mip- or rip-map (exrfog writes level 0 only). */
int ef_exr_part_is_multilevel(const ef_exr_file *f, int part);

/* Reads the camera attributes of a part into meta. Fails only on
 * attributes of an unexpected type. */
int ef_exr_read_cam_meta(const ef_exr_file *f, int part, ef_cam_meta *meta, ef_err *err);

/* A channel located in a file: part, index in its channel list, and the
 * qualified name (layer.channel, the layer coming from the part name for
 * multi-part files). */
typedef struct ef_chan_ref {
    int part;                 /* -1: absent */
    int index;
    char name[256];
} ef_chan_ref;

typedef struct ef_channel_plan {
    ef_chan_ref rgb[3];
    ef_chan_ref alpha;        /* part == -1 when the colour has no alpha */
    ef_chan_ref depth;        /* in depth_file */
    char view[64];            /* the view these channels show, "" in a file without views */
    /* The view inserted in the names of channels exrfog adds (AOVs), as
     * OpenEXR names a non-default view's channels in a single-part
     * multi-view file (fog.R -> fog.left.R); "" otherwise. */
    char chan_view[64];
    int default_view;         /* 1: the default (first) view of a multiView part */
} ef_channel_plan;

/* Views a file or a selection can hold. */
#define EF_MAX_VIEWS 8

/* Finds colour in f (layer NULL: automatic) and depth in depth_file (which
 * may be f; depth_channel NULL: automatic). Never picks look-alikes such as
 * normals.Z, N.Z, P.Z, *.ZBack or another layer's Z. Fails with the list of
 * what the file has and the flag that chooses explicitly. */
int ef_find_channels(const ef_exr_file *f, const ef_exr_file *depth_file, const char *layer,
                     const char *depth_channel, ef_channel_plan *plan, ef_err *err);

/* The views of f: the multiView attribute of a single-part file (the
 * first is the default view), or the distinct "view" attributes of a
 * multi-part file's parts, in part order. Returns the count (0: no views),
 * or max + 1 when the file has more than max (the first max are in
 * names). */
int ef_exr_views(const ef_exr_file *f, char names[][64], int max);

/* Finds the colour and depth of view `view` of f, as ef_find_channels does
 * within the view's channels only: in a multiView part, the default view's
 * unprefixed channels or another view's (left.R, layer.left.R); in a
 * multi-part file, the parts whose "view" is this view (and parts without
 * a view for depth). A depth file with views is searched the same way;
 * one without views gives its depth to every view. */
int ef_find_view_channels(const ef_exr_file *f, const ef_exr_file *depth_file, const char *view,
                          const char *layer, const char *depth_channel, ef_channel_plan *plan,
                          ef_err *err);

/* A channel's output type under -d NAME=TYPE overrides names[0..n) ("R=half"
 * with types[k] its EXR_PIXEL_ type): the last one naming it wins; uint
 * stays uint. */
int ef_exr_named_type(const char *const *names, const int *types, int n, const char *name, int t);

/* Channels the stream can add to the colour part (ef_stream_opts.extra). */
/* Channels a run adds per part (the AOVs: every light's layers included,
 * aov.h's EF_AOV_MAX_CHANNELS) */
#define EF_MAX_EXTRA_CHANNELS 160

/* One work unit of the colour part, decoded to float: a rectangle of
 * absolute pixels, rows of w floats. alpha is NULL without alpha. extra[i]
 * is the plane of opts->extra[i] (zeroed before the callback), which the
 * callback fills. */
typedef struct ef_chunk {
    int view;                 /* index of the plan (view) these channels belong to */
    int x0, y0, w, h;
    float *rgb[3];
    float *alpha;
    const float *depth;
    float *extra[EF_MAX_EXTRA_CHANNELS];
    int nextra;
    /* With ef_stream_opts.halo, the rows just outside the unit as read:
     * halo_rows[0] rows above (rows y0 - n .. y0 - 1, top first) and
     * halo_rows[1] below (from row y0 + h), w values each: EF_STREAM_HALO
     * of each, fewer where the data window ends (0: NULL); read-only. A
     * tiled part is then walked a row of tiles per unit (x0 and w the
     * data window's). */
    const float *halo_rgb[2][3], *halo_alpha[2], *halo_depth[2];
    int halo_rows[2];
} ef_chunk;

/* The rows on each side of a unit that ef_stream_opts.halo reads. */
#define EF_STREAM_HALO 3

/* Edits the colour of one unit in place; called from worker threads, so it
 * must only touch the unit and read-only shared state. */
typedef void (*ef_chunk_fn)(void *user, const ef_chunk *chunk);

typedef struct ef_stream_stats {
    double decode_s, fog_s, encode_s, write_s;  /* summed over threads */
    double wait_s;            /* summed over threads: blocked on a full write ring (exr_ring.h) */
    double wall_s;
    long units;
} ef_stream_stats;

typedef struct ef_stream_opts {
    int threads;              /* >= 1 */
    /* When not NULL and *cancel becomes non-zero, the stream stops at the
     * next unit and fails ("cancelled"). */
    const _Atomic int *cancel;
    int nplans;               /* plans (views) in the plan array; 0 means 1 */
    int compression;          /* exr_compression_t, or -1 to keep each part's */
    int zip_level;            /* zlib level 1..9 for zip/zips output, or -1 for Core's default */
    int codec;                /* ZIP/ZIPS through EF_CODEC_LIBDEFLATE (0, the default) or
                                 EF_CODEC_ZLIB (1, OpenEXRCore's own); exr_deflate.h */
    int pixel_type;           /* EXR_PIXEL_HALF / _FLOAT for half/float channels, or -1 to keep;
                                 HALF never demotes ef_data_channel()s nor the depth read */
    const char *depth_name;   /* the depth channel exrfog reads in INPUT, or NULL */
    const char *const *chan_type_name;   /* "NAME=TYPE" overrides (-d NAME=TYPE), */
    const int *chan_type;                /* their types, */
    int nchan_type;                      /* and how many */
    int depth_part;           /* and its part */
    const char *param_attr;   /* value of the exrfog/parameters string attribute */
    const char *history;      /* this run's line of exrfog/history, appended to the input's */
    /* New channels of the colour part, FLOAT (HALF when pixel_type is
     * HALF), filled by the callback; names must not be in the part yet. */
    const char *const *extra;
    int nextra;               /* 0..EF_MAX_EXTRA_CHANNELS */
    /* per extra channel: data (positions, distances) that a half output
     * keeps in float; NULL: judged by name (ef_data_channel) */
    const unsigned char *extra_data;
    /* A v3d attribute of the colour part (exrfog/aovOrigin), when
     * has_origin_attr. */
    int has_origin_attr;
    double origin_attr[3];
    /* Scanline colour parts: give each unit the rows just outside it
     * (ef_chunk's halo), for --edges. */
    int halo;
} ef_stream_opts;

/* Writes every part of in to out_fd (a new, empty file the caller opened
 * for writing; it picks the temporary name, renames or removes it), calling
 * fn on each unit of the colour of each of opts->nplans plans (views; the
 * chunk says which) with its depth; every plan gets the extra channels,
 * named with its chan_view. out_path names the
 * output in messages. Every channel is written back; header attributes are
 * copied. Returns 0, or -1 with a message about out_path or an input. */
int ef_exr_stream(const ef_exr_file *in, const ef_exr_file *depth_file,
                  const ef_channel_plan *plan, const char *out_path, int out_fd,
                  const ef_stream_opts *opts, ef_chunk_fn fn, void *user,
                  ef_stream_stats *stats, ef_err *err);

/* ef_exr_stream to a path created (or truncated) here and removed on
 * failure: for tools and tests; the CLI creates its temporary file itself. */
int ef_exr_stream_file(const ef_exr_file *in, const ef_exr_file *depth_file,
                       const ef_channel_plan *plan, const char *path,
                       const ef_stream_opts *opts, ef_chunk_fn fn, void *user,
                       ef_stream_stats *stats, ef_err *err);

/* Whether part p of f has an attribute of this name. */
int ef_exr_has_attr(const ef_exr_file *f, int part, const char *name);

/* Channel chan (an index in part's channel list) of nrows rows spread
 * evenly over part's data window, as float: *out (malloc'd, nrows rows of
 * *width values), the rows' y in ys[0..nrows). For estimates before a
 * pass (a sample of the depth). Returns the rows read, or -1. */
int ef_exr_sample_rows(const ef_exr_file *f, int part, int chan, int nrows, float **out, int *width,
                       int *ys);

/* Whole rows of channels chans (1 to 8) of part as float, one at a time,
 * each chunk decoded once for all of them (the last one kept: read rows in
 * order). NULL when the part or a channel is not there, or out of memory;
 * *width, *height: the data window's size. */
typedef struct ef_exr_rows ef_exr_rows;
ef_exr_rows *ef_exr_rows_open(const ef_exr_file *f, int part, const int *chans, int nchan,
                              int *width, int *height);
/* Row y (0: the data window's top) into out[c][0..width) for chans[c].
 * Returns 0, or -1 (damaged, out of memory, y out of range). */
int ef_exr_rows_read(ef_exr_rows *r, int y, float *const *out);
void ef_exr_rows_close(ef_exr_rows *r);

/* Whether -d half must leave channel name in float: depth (Z, *.Z,
 * *.ZBack, depth...), positions (P.*, position.*, fog_P.*), ids (id.*,
 * *Id.*, Cryptomatte). */
int ef_data_channel(const char *name);

/* The name of the first of the n channel names that part p of f already
 * has, or NULL when it has none of them. */
const char *ef_exr_part_has_any(const ef_exr_file *f, int part, const char *const *names, int n);

/* Parses a --compression value: NAME, zip:LEVEL / zips:LEVEL (zlib, 1..9)
 * or dwaa:LEVEL / dwab:LEVEL (a positive dwaCompressionLevel, as oiiotool).
 * *level is the zlib level or -1 without one; *dwa_level is the DWA level
 * (45 when DWA is named without one) or -1 for other compressions.
 * DWAA/DWAB are accepted: they need the C++ transcoder (exr_dwa.h).
 * Returns 0 or -1. */
int ef_compression_parse(const char *name, int *compression, int *level, float *dwa_level,
                         ef_err *err);


/* Shared inside the adapter: a context initializer whose error handler
 * keeps Core's last message (per thread) instead of printing it. */
void ef_exr_init_context(exr_context_initializer_t *init);
const char *ef_exr_last_core_message(void);

#endif
