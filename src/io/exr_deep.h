/* Deep scanline parts through OpenEXRCore's raw chunk calls: reading
 * (NONE, RLE, ZIPS, ZIP; the sample tables checked before any allocation
 * that depends on them) and writing deep scanline ZIPS or a flat ZIP part.
 * Nothing here relies on Core 3.1.5's deep unpacker or packer (the first
 * mishandles zero-sample chunks and individual counts, the second refuses
 * every call). */
#ifndef EF_EXR_DEEP_H
#define EF_EXR_DEEP_H

#include "exr_io.h"
#include "exr_parts.h"

#include <stddef.h>
#include <stdint.h>

#define EF_DEEP_IO_MAX_CH 64
/* Samples one pixel may have; more is taken for corruption. */
#define EF_DEEP_MAX_PIXEL_SAMPLES (1 << 20)
/* Values (samples times channels) one read may decode into, at most
 * (memory: 8 bytes each, 1 GiB): a single chunk past it is refused. */
#define EF_DEEP_MAX_CHUNK_VALUES (1ull << 27)

typedef struct ef_deep_in {
    const ef_exr_file *f;
    int part;
    int x0, y0, w, h;
    int nch;
    const char *name[EF_DEEP_IO_MAX_CH];
    exr_pixel_type_t type[EF_DEEP_IO_MAX_CH];
    exr_compression_t comp;
    int lines;                /* scanlines per chunk (tiled: the tile height) */
    int tiled, tw, th;        /* deep tiled: level 0's tiles of tw x th */
} ef_deep_in;


/* Describes deep part p of f (scanline, or tiled: level 0 is read).
 * Refuses compressions a deep part cannot have and channel lists exrfog
 * cannot hold. */
int ef_deep_in_open(const ef_exr_file *f, int part, ef_deep_in *d, ef_err *err);

/* Rows [y, y + n) decoded: per pixel its sample count and first sample,
 * and every sample's channel values as doubles, sample-major. */
typedef struct ef_deep_rows {
    int y, n, w;
    uint32_t *count;          /* n * w */
    uint64_t *start;          /* n * w + 1 */
    double *v;                /* start[n * w] * nch */
    uint64_t total;
    uint64_t cap;             /* values a read may decode into (0: EF_DEEP_MAX_CHUNK_VALUES) */
    size_t vcap, pcap, ccap;
    uint8_t *raw, *packed, *tab;  /* scratch */
    size_t rawcap, packcap, tabcap;
    void *inflater;
} ef_deep_rows;

void ef_deep_rows_free(ef_deep_rows *r);


/* Reads rows [y, y + n) (inside the data window) of d into r, chunk by
 * chunk. Thread-safe for distinct r. Returns 0; -2 with a message when
 * the rows hold more than r->cap values (samples times channels), found
 * from the sample tables before the samples are decoded (a caller may
 * then read fewer rows); or -1 with a message (corrupt chunk, absurd
 * sample counts, out of memory). */
int ef_deep_read_rows(const ef_deep_in *d, int y, int n, ef_deep_rows *r, ef_err *err);

/* One packed output chunk (what a worker makes and the writer puts out). */
typedef struct ef_deep_packed {
    int y;
    uint8_t *table, *data;
    uint64_t table_size, data_size, data_raw;
    size_t tcap, dcap;
    uint8_t *scratch;
    size_t scap;
    uint32_t max_count;
} ef_deep_packed;

void ef_deep_packed_free(ef_deep_packed *p);

/* Packs one deep row: counts[w] per pixel, values sample-major (nch
 * doubles each) converted to the channel types, table and data ZIPS
 * compressed with the EXR predictor (stored raw where that does not
 * shrink). */
int ef_deep_pack_row(int nch, const exr_pixel_type_t *type, int w, const uint32_t *counts,
                     const double *v, int zip_level, ef_deep_packed *out);

/* Packs n flat rows of w pixels, values pixel-major (nch doubles each per
 * pixel, rows after one another), as one ZIP chunk. */
int ef_flat_pack_rows(int nch, const exr_pixel_type_t *type, int w, int n, const double *v,
                      int zip_level, ef_deep_packed *out);

typedef struct ef_deep_out {
    exr_context_t ctx;
    void *sink;
    int fd, deep, nch;
    int part;                 /* the written part's index */
    const ef_exr_file *in;    /* parts copied beside it, or NULL */
    int msp_skip;             /* copied parts before it with their own maxSamplesPerPixel */
    exr_pixel_type_t type[EF_DEEP_IO_MAX_CH];
    const char *path;
    uint32_t max_count;
} ef_deep_out;

/* Starts OUTPUT (fd: a new empty file) with one part: deep scanline ZIPS
 * when deep, else flat scanline ZIP, holding channels name/type (sorted
 * by name here), with every attribute of in's part p (plus history and
 * parameters, and exrfog/aovOrigin when aov_origin is not NULL) and, when
 * deep, maxSamplesPerPixel (set at the end). With others, every other part
 * of in is kept beside it, in its place: the same header (plus history and
 * parameters) and its chunks copied as they are, flat or deep, scanline or
 * tiled (one level); the parts before p are written here, those after by
 * ef_deep_out_end. */
int ef_deep_out_begin(ef_deep_out *o, const char *path, int fd, const ef_exr_file *in, int part,
                      int deep, int nch, const char *const *name, const exr_pixel_type_t *type,
                      const char *history, const char *params, const double *aov_origin,
                      int others, ef_err *err);

/* Writes one packed chunk (in increasing y). */
int ef_deep_out_write(ef_deep_out *o, const ef_deep_packed *p, ef_err *err);
/* Finishes the file (maxSamplesPerPixel in place). Returns 0 or -1. */
int ef_deep_out_end(ef_deep_out *o, ef_err *err);
/* Releases an unfinished output (after a failure). */
void ef_deep_out_abort(ef_deep_out *o);

#endif
