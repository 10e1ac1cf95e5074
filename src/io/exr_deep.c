/* Deep scanline I/O from raw chunks: exr_read_deep_chunk gives the packed
 * table and data, decompressed here (NONE, RLE, ZIPS, ZIP) and checked;
 * output chunks are packed and compressed here and handed to
 * exr_write_deep_scanline_chunk / exr_write_scanline_chunk. */
#define _GNU_SOURCE 1
#include "exr_deep.h"
#include "exr_deflate.h"
#include "half_conv.h"

#include <errno.h>
#include <libdeflate.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int type_bytes(exr_pixel_type_t t)
{
    return t == EXR_PIXEL_HALF ? 2 : 4;
}

int ef_deep_in_open(const ef_exr_file *f, int part, ef_deep_in *d, ef_err *err)
{
    memset(d, 0, sizeof *d);
    d->f = f;
    d->part = part;
    exr_storage_t st;
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *cl;
    int32_t lines = 0;
    if (exr_get_storage(f->ctx, part, &st) || exr_get_data_window(f->ctx, part, &dw) ||
        exr_get_channels(f->ctx, part, &cl) || exr_get_compression(f->ctx, part, &d->comp))
        return ef_fail(err, "part %d has an incomplete header", part);
    if (st != EXR_STORAGE_DEEP_SCANLINE && st != EXR_STORAGE_DEEP_TILED)
        return ef_fail(err, "part %d is not deep", part);
    switch (d->comp) {
    case EXR_COMPRESSION_NONE:
    case EXR_COMPRESSION_RLE:
    case EXR_COMPRESSION_ZIPS:
    case EXR_COMPRESSION_ZIP:
        break;
    default:
        return ef_fail(err, "part %d is deep with a compression deep data cannot have (only "
                            "none, rle, zips and zip exist for deep parts): the file is corrupt",
                       part);
    }
    if (st == EXR_STORAGE_DEEP_TILED) {
        uint32_t tx, ty;
        if (exr_get_tile_descriptor(f->ctx, part, &tx, &ty, NULL, NULL) || tx < 1 || ty < 1)
            return ef_fail(err, "part %d is deep and tiled with an invalid tile size", part);
        /* legal in OpenEXR, but a tile is read whole: its rows are one band */
        if (tx > 4096 || ty > 4096)
            return ef_fail(err, "part %d is deep in tiles of %u x %u pixels; exrfog reads deep "
                                "tiles of at most 4096 on a side (re-tile it, e.g. oiiotool IN "
                                "--tile 64 64 -o OUT, or write it as scanlines)",
                           part, tx, ty);
        d->tiled = 1;
        d->tw = (int) tx;
        d->th = (int) ty;
        d->lines = (int) ty;
    } else {
        if (exr_get_scanlines_per_chunk(f->ctx, part, &lines) || lines < 1 || lines > 16)
            return ef_fail(err, "part %d has an invalid chunk height", part);
        d->lines = lines;
    }
    d->x0 = dw.min.x;
    d->y0 = dw.min.y;
    d->w = (int) ((int64_t) dw.max.x - dw.min.x + 1);
    d->h = (int) ((int64_t) dw.max.y - dw.min.y + 1);
    if (cl->num_channels > EF_DEEP_IO_MAX_CH)
        return ef_fail(err, "part %d has %d channels; exrfog handles at most %d in a deep part",
                       part, cl->num_channels, EF_DEEP_IO_MAX_CH);
    d->nch = cl->num_channels;
    for (int c = 0; c < d->nch; ++c) {
        d->name[c] = cl->entries[c].name.str;
        d->type[c] = cl->entries[c].pixel_type;
        if (d->type[c] != EXR_PIXEL_HALF && d->type[c] != EXR_PIXEL_FLOAT &&
            d->type[c] != EXR_PIXEL_UINT)
            return ef_fail(err, "channel '%s' has an unknown pixel type", d->name[c]);
    }
    return 0;
}

void ef_deep_rows_free(ef_deep_rows *r)
{
    free(r->count);
    free(r->start);
    free(r->v);
    free(r->raw);
    free(r->packed);
    free(r->tab);
    if (r->inflater)
        libdeflate_free_decompressor(r->inflater);
    memset(r, 0, sizeof *r);
}

/* OpenEXR's RLE: a negative count n is -n literal bytes, else n + 1
 * copies of the next byte. Returns the bytes written, or -1 when the
 * stream does not fit out exactly. */
static int64_t rle_decode(const uint8_t *in, uint64_t n, uint8_t *out, uint64_t cap)
{
    uint64_t i = 0, o = 0;
    while (i < n) {
        const int c = (int8_t) in[i++];
        if (c < 0) {
            const uint64_t k = (uint64_t) -c;
            if (i + k > n || o + k > cap)
                return -1;
            memcpy(out + o, in + i, k);
            i += k;
            o += k;
        } else {
            const uint64_t k = (uint64_t) c + 1;
            if (i >= n || o + k > cap)
                return -1;
            memset(out + o, in[i++], k);
            o += k;
        }
    }
    return (int64_t) o;
}

/* Unpacks src (n packed bytes) into dst (want bytes) per the compression;
 * scratch is a buffer of at least want bytes. Returns 0 or -1. */
static int unpack(ef_deep_rows *r, exr_compression_t comp, const uint8_t *src, uint64_t n,
                  uint8_t *dst, uint64_t want, uint8_t *scratch)
{
    if (n == want) {   /* stored raw (it did not shrink) */
        memcpy(dst, src, want);
        return 0;
    }
    if (comp == EXR_COMPRESSION_NONE)
        return -1;
    if (comp == EXR_COMPRESSION_RLE) {
        if (rle_decode(src, n, scratch, want) != (int64_t) want)
            return -1;
    } else {
        if (!r->inflater && !(r->inflater = libdeflate_alloc_decompressor()))
            return -1;
        size_t got = 0;
        if (libdeflate_zlib_decompress(r->inflater, src, n, scratch, want, &got) !=
                LIBDEFLATE_SUCCESS ||
            got != want)
            return -1;
    }
    ef_zip_reconstruct(dst, scratch, want);
    return 0;
}

static double read_value(const uint8_t *p, exr_pixel_type_t t)
{
    if (t == EXR_PIXEL_HALF) {
        const uint32_t b = ef_half_bits_to_float((uint16_t) (p[0] | p[1] << 8));
        float f;
        memcpy(&f, &b, 4);
        return (double) f;
    }
    uint32_t u = (uint32_t) p[0] | (uint32_t) p[1] << 8 | (uint32_t) p[2] << 16 |
                 (uint32_t) p[3] << 24;
    if (t == EXR_PIXEL_UINT)
        return (double) u;
    float f;
    memcpy(&f, &u, 4);
    return (double) f;
}

/* The values a read into r may decode into. */
static uint64_t rows_cap(const ef_deep_rows *r)
{
    return r->cap > 0 && r->cap < EF_DEEP_MAX_CHUNK_VALUES ? r->cap : EF_DEEP_MAX_CHUNK_VALUES;
}

/* The refusal of rows r->y.. whose samples (n so far) pass the cap: -2,
 * with the figure (the caller may read fewer rows under a soft cap). */
static int too_many(const ef_deep_in *d, const ef_deep_rows *r, uint64_t n, ef_err *err)
{
    char rows[48];
    if (r->n > 1)
        snprintf(rows, sizeof rows, "rows %d-%d", r->y, r->y + r->n - 1);
    else
        snprintf(rows, sizeof rows, "row %d", r->y);
    ef_fail(err, "%s hold%s %llu deep samples (%.2f GiB decoded), past the %.2f GiB "
                 "exrfog decodes at once per thread (a pixel may hold up to %d samples, one "
                 "%s at most %llu values: samples times channels); write the file with fewer "
                 "samples%s",
            rows, r->n > 1 ? "" : "s", (unsigned long long) n,
            (double) n * (double) d->nch * 8 / (1 << 30), (double) rows_cap(r) * 8 / (1 << 30),
            EF_DEEP_MAX_PIXEL_SAMPLES, d->tiled ? "row of tiles" : "chunk of rows",
            (unsigned long long) rows_cap(r),
            d->tiled ? " or in smaller tiles"
                     : d->lines > 1 ? " or one row per chunk (ZIPS or RLE)" : "");
    return -2;
}

/* Reads the chunk starting at row cy into r (rows from r->y). */
static int read_chunk(const ef_deep_in *d, int cy, ef_deep_rows *r, ef_err *err)
{
    exr_chunk_info_t ci;
    const exr_context_t ctx = d->f->ctx;
    if (exr_read_scanline_chunk_info(ctx, d->part, cy, &ci))
        return ef_fail(err, "the deep chunk at row %d cannot be located (%s): the file is "
                            "truncated or corrupt", cy, ef_exr_last_core_message());
    const int w = d->w, rows = ci.height;
    if (ci.start_y != cy || rows < 1 || rows > d->lines || ci.width != w)
        return ef_fail(err, "the deep chunk at row %d has an inconsistent size", cy);
    const uint64_t tab_raw = (uint64_t) rows * (uint64_t) w * 4;
    if (ci.sample_count_table_size > tab_raw || ci.packed_size > (1ull << 34) ||
        ci.sample_count_table_size == 0)
        return ef_fail(err, "the deep chunk at row %d has an impossible sample table size "
                            "(%llu bytes): the file is corrupt", cy,
                       (unsigned long long) ci.sample_count_table_size);
    if (ef_deep_grow((void **) &r->packed, &r->packcap, ci.packed_size + ci.sample_count_table_size + 8) ||
        ef_deep_grow((void **) &r->tab, &r->tabcap, tab_raw * 2 + 8))
        return ef_fail(err, "out of memory for a deep chunk");
    uint8_t *ptab = r->packed + ci.packed_size;
    if (exr_read_deep_chunk(ctx, d->part, &ci, r->packed, ptab))
        return ef_fail(err, "the deep chunk at row %d cannot be read (%s): the file is truncated "
                            "or corrupt", cy, ef_exr_last_core_message());
    uint8_t *tab = r->tab, *tscratch = r->tab + tab_raw;
    if (unpack(r, d->comp, ptab, ci.sample_count_table_size, tab, tab_raw, tscratch))
        return ef_fail(err, "the sample table of the deep chunk at row %d does not decompress: "
                            "the file is corrupt", cy);
    /* Cumulative per row; checked monotonic (OpenEXRCore 3.1.5 does not:
     * CVE-2023-5841) and capped before anything is sized from it. */
    const int r0 = cy - r->y;
    uint64_t total = 0;
    for (int j = 0; j < rows; ++j) {
        uint32_t prev = 0;
        for (int x = 0; x < w; ++x) {
            const uint8_t *p = tab + ((size_t) j * (size_t) w + (size_t) x) * 4;
            const uint32_t cum = (uint32_t) p[0] | (uint32_t) p[1] << 8 | (uint32_t) p[2] << 16 |
                                 (uint32_t) p[3] << 24;
            if (cum < prev || cum - prev > EF_DEEP_MAX_PIXEL_SAMPLES || cum > INT32_MAX)
                return ef_fail(err, "the deep chunk at row %d has a corrupt sample table "
                                    "(counts decreasing or above %d per pixel)",
                               cy, EF_DEEP_MAX_PIXEL_SAMPLES);
            r->count[(size_t) (r0 + j) * (size_t) w + (size_t) x] = cum - prev;
            prev = cum;
        }
        total += prev;
    }
    uint64_t bps = 0;
    for (int c = 0; c < d->nch; ++c)
        bps += (uint64_t) type_bytes(d->type[c]);
    if (total * bps != ci.unpacked_size)
        return ef_fail(err, "the deep chunk at row %d holds %llu bytes where its sample table "
                            "says %llu: the file is corrupt", cy,
                       (unsigned long long) ci.unpacked_size,
                       (unsigned long long) (total * bps));
    const uint64_t base = r->start[(size_t) r0 * (size_t) w];
    if ((base + total) * (uint64_t) d->nch > rows_cap(r))
        return too_many(d, r, base + total, err);
    for (int j = 0; j < rows; ++j)
        for (int x = 0; x < w; ++x) {
            const size_t i = (size_t) (r0 + j) * (size_t) w + (size_t) x;
            r->start[i + 1] = r->start[i] + r->count[i];
        }
    if (ef_deep_grow((void **) &r->v, &r->vcap, (size_t) (base + total) * (size_t) d->nch * sizeof(double)) ||
        ef_deep_grow((void **) &r->raw, &r->rawcap, 2 * ci.unpacked_size + 8))
        return ef_fail(err, "out of memory for a deep chunk");
    if (total > 0 &&
        unpack(r, d->comp, r->packed, ci.packed_size, r->raw, ci.unpacked_size,
               r->raw + ci.unpacked_size))
        return ef_fail(err, "the deep chunk at row %d does not decompress: the file is corrupt",
                       cy);
    /* per row, every channel in turn over the row's samples */
    const uint8_t *p = r->raw;
    for (int j = 0; j < rows; ++j) {
        const size_t i0 = (size_t) (r0 + j) * (size_t) w;
        const uint64_t s0 = r->start[i0], ns = r->start[i0 + (size_t) w] - s0;
        for (int c = 0; c < d->nch; ++c) {
            const int b = type_bytes(d->type[c]);
            double *v = r->v + (size_t) s0 * (size_t) d->nch + (size_t) c;
            for (uint64_t s = 0; s < ns; ++s, p += b)
                v[(size_t) s * (size_t) d->nch] = read_value(p, d->type[c]);
        }
    }
    r->total = base + total;
    return 0;
}

static uint32_t le32(const uint8_t *p)
{
    return (uint32_t) p[0] | (uint32_t) p[1] << 8 | (uint32_t) p[2] << 16 | (uint32_t) p[3] << 24;
}

/* The tile (tx, ty) of level 0: its chunk, and its sample table unpacked
 * into r->tab (tile rows x width, cumulative per row), checked. */
static int tile_table(const ef_deep_in *d, int tx, int ty, ef_deep_rows *r, exr_chunk_info_t *ci,
                      ef_err *err)
{
    const exr_context_t ctx = d->f->ctx;
    if (exr_read_tile_chunk_info(ctx, d->part, tx, ty, 0, 0, ci))
        return ef_fail(err, "the deep tile (%d, %d) cannot be located (%s): the file is "
                            "truncated or corrupt", tx, ty, ef_exr_last_core_message());
    if (ci->width < 1 || ci->height < 1 || ci->width > d->tw || ci->height > d->th)
        return ef_fail(err, "the deep tile (%d, %d) has an inconsistent size", tx, ty);
    const uint64_t tab_raw = (uint64_t) ci->width * (uint64_t) ci->height * 4;
    if (ci->sample_count_table_size > tab_raw || ci->sample_count_table_size == 0 ||
        ci->packed_size > (1ull << 34))
        return ef_fail(err, "the deep tile (%d, %d) has an impossible sample table: the file is "
                            "corrupt", tx, ty);
    if (ef_deep_grow((void **) &r->packed, &r->packcap, ci->packed_size + ci->sample_count_table_size + 8) ||
        ef_deep_grow((void **) &r->tab, &r->tabcap, tab_raw * 2 + 8))
        return ef_fail(err, "out of memory for a deep tile");
    uint8_t *ptab = r->packed + ci->packed_size;
    if (exr_read_deep_chunk(ctx, d->part, ci, NULL, ptab))
        return ef_fail(err, "the deep tile (%d, %d) cannot be read (%s): the file is truncated "
                            "or corrupt", tx, ty, ef_exr_last_core_message());
    if (unpack(r, d->comp, ptab, ci->sample_count_table_size, r->tab, tab_raw, r->tab + tab_raw))
        return ef_fail(err, "the sample table of the deep tile (%d, %d) does not decompress: the "
                            "file is corrupt", tx, ty);
    return 0;
}

/* Rows [y, y + n) of a deep tiled part: every tile they cross, tables
 * first (counts, then each pixel's first sample), then the samples
 * scattered to their pixels. */
static int read_tiles(const ef_deep_in *d, int y, int n, ef_deep_rows *r, ef_err *err)
{
    const int w = d->w;
    const int ty0 = (y - d->y0) / d->th, ty1 = (y + n - 1 - d->y0) / d->th;
    const int ntx = (w + d->tw - 1) / d->tw;
    exr_chunk_info_t ci;
    for (int pass = 0; pass < 2; ++pass) {
        for (int ty = ty0; ty <= ty1; ++ty)
            for (int tx = 0; tx < ntx; ++tx) {
                if (tile_table(d, tx, ty, r, &ci, err))
                    return -1;
                const int ty_abs = d->y0 + ty * d->th, tx_abs = tx * d->tw;
                uint64_t total = 0;
                for (int j = 0; j < ci.height; ++j) {
                    uint32_t prev = 0;
                    for (int x = 0; x < ci.width; ++x) {
                        const uint32_t cum = le32(r->tab + ((size_t) j * (size_t) ci.width + (size_t) x) * 4);
                        if (cum < prev || cum - prev > EF_DEEP_MAX_PIXEL_SAMPLES || cum > INT32_MAX)
                            return ef_fail(err, "the deep tile (%d, %d) has a corrupt sample "
                                                "table (counts decreasing or above %d per pixel)",
                                           tx, ty, EF_DEEP_MAX_PIXEL_SAMPLES);
                        const int row = ty_abs + j - y, col = tx_abs + x;
                        if (pass == 0 && row >= 0 && row < n && col < w)
                            r->count[(size_t) row * (size_t) w + (size_t) col] = cum - prev;
                        prev = cum;
                    }
                    total += prev;
                }
                if (pass == 0)
                    continue;
                uint64_t bps = 0;
                for (int c = 0; c < d->nch; ++c)
                    bps += (uint64_t) type_bytes(d->type[c]);
                if (total * bps != ci.unpacked_size)
                    return ef_fail(err, "the deep tile (%d, %d) holds %llu bytes where its sample "
                                        "table says %llu: the file is corrupt", tx, ty,
                                   (unsigned long long) ci.unpacked_size,
                                   (unsigned long long) (total * bps));
                if (total == 0)
                    continue;
                if (ef_deep_grow((void **) &r->raw, &r->rawcap, 2 * ci.unpacked_size + 8))
                    return ef_fail(err, "out of memory for a deep tile");
                if (exr_read_deep_chunk(d->f->ctx, d->part, &ci, r->packed, NULL) ||
                    unpack(r, d->comp, r->packed, ci.packed_size, r->raw, ci.unpacked_size,
                           r->raw + ci.unpacked_size))
                    return ef_fail(err, "the deep tile (%d, %d) does not decompress: the file "
                                        "is corrupt", tx, ty);
                const uint8_t *p = r->raw;
                for (int j = 0; j < ci.height; ++j) {
                    const int row = ty_abs + j - y;
                    const uint8_t *rowtab = r->tab + (size_t) j * (size_t) ci.width * 4;
                    const uint32_t row_total = le32(rowtab + ((size_t) ci.width - 1) * 4);
                    for (int c = 0; c < d->nch; ++c) {
                        const int b = type_bytes(d->type[c]);
                        uint32_t prev = 0;
                        for (int x = 0; x < ci.width; ++x) {
                            const uint32_t cum = le32(rowtab + (size_t) x * 4);
                            const int col = tx_abs + x;
                            if (row >= 0 && row < n && col < w) {
                                const size_t i = (size_t) row * (size_t) w + (size_t) col;
                                double *v = r->v + (size_t) r->start[i] * (size_t) d->nch + (size_t) c;
                                for (uint32_t s = 0; s < cum - prev; ++s)
                                    v[(size_t) s * (size_t) d->nch] = read_value(p + (size_t) (prev + s) * (size_t) b, d->type[c]);
                            }
                            prev = cum;
                        }
                        p += (size_t) row_total * (size_t) b;
                    }
                }
            }
        if (pass == 0) {
            r->start[0] = 0;
            for (size_t i = 0; i < (size_t) n * (size_t) w; ++i)
                r->start[i + 1] = r->start[i] + r->count[i];
            r->total = r->start[(size_t) n * (size_t) w];
            if (r->total * (uint64_t) d->nch > rows_cap(r))
                return too_many(d, r, r->total, err);
            if (ef_deep_grow((void **) &r->v, &r->vcap, (size_t) r->total * (size_t) d->nch * sizeof(double)))
                return ef_fail(err, "out of memory for deep samples");
        }
    }
    return 0;
}

int ef_deep_read_rows(const ef_deep_in *d, int y, int n, ef_deep_rows *r, ef_err *err)
{
    const size_t np = (size_t) n * (size_t) d->w;
    if (ef_deep_grow((void **) &r->count, &r->ccap, np * sizeof *r->count) ||
        ef_deep_grow((void **) &r->start, &r->pcap, (np + 1) * sizeof *r->start))
        return ef_fail(err, "out of memory for a deep chunk");
    r->y = y;
    r->n = n;
    r->w = d->w;
    r->start[0] = 0;
    r->total = 0;
    if (d->tiled) {
        memset(r->count, 0, np * sizeof *r->count);
        return read_tiles(d, y, n, r, err);
    }
    /* chunks start at the data window's top, every d->lines rows */
    for (int cy = y - (y - d->y0) % d->lines; cy < y + n; cy += d->lines) {
        if (cy < y)
            return ef_fail(err, "internal error: rows %d.. do not start a chunk", y);
        const int rc = read_chunk(d, cy, r, err);
        if (rc)
            return rc;
    }
    return 0;
}

/* ---- writing ---- */

void ef_deep_packed_free(ef_deep_packed *p)
{
    free(p->table);
    free(p->data);
    free(p->scratch);
    memset(p, 0, sizeof *p);
}

static void put_value(uint8_t *p, exr_pixel_type_t t, double v)
{
    if (t == EXR_PIXEL_HALF) {
        const float f = (float) v;
        uint32_t b;
        memcpy(&b, &f, 4);
        const uint16_t h = ef_float_bits_to_half(b);
        p[0] = (uint8_t) h;
        p[1] = (uint8_t) (h >> 8);
        return;
    }
    uint32_t u;
    if (t == EXR_PIXEL_UINT) {
        u = v > 0 ? (v < 4294967295.0 ? (uint32_t) v : UINT32_MAX) : 0;
    } else {
        const float f = (float) v;
        memcpy(&u, &f, 4);
    }
    p[0] = (uint8_t) u;
    p[1] = (uint8_t) (u >> 8);
    p[2] = (uint8_t) (u >> 16);
    p[3] = (uint8_t) (u >> 24);
}

/* ZIP-compresses raw (n bytes) into *dst (or stores it raw when that does
 * not shrink); returns the packed size, 0 when out of memory. */
static uint64_t zip_pack(const uint8_t *raw, uint64_t n, int level, uint8_t **dst, size_t *dcap,
                         uint8_t **scratch, size_t *scap)
{
    if (ef_deep_grow((void **) scratch, scap, n + 8) || ef_deep_grow((void **) dst, dcap, n + 64))
        return 0;
    if (n == 0)
        return 0;
    ef_zip_deconstruct(*scratch, raw, n);
    struct libdeflate_compressor *z = libdeflate_alloc_compressor(ef_deflate_level(level));
    if (!z)
        return 0;
    size_t got = libdeflate_zlib_compress(z, *scratch, n, *dst, n);
    libdeflate_free_compressor(z);
    if (got == 0 || got >= n) {
        memcpy(*dst, raw, n);
        return n;
    }
    return got;
}

int ef_deep_pack_row(int nch, const exr_pixel_type_t *type, int w, const uint32_t *counts,
                     const double *v, int zip_level, ef_deep_packed *out)
{
    uint64_t total = 0, bps = 0;
    out->max_count = 0;
    for (int x = 0; x < w; ++x) {
        total += counts[x];
        if (counts[x] > out->max_count)
            out->max_count = counts[x];
    }
    for (int c = 0; c < nch; ++c)
        bps += (uint64_t) type_bytes(type[c]);
    uint8_t *tab = malloc((size_t) w * 4 + 8), *raw = malloc((size_t) (total * bps) + 8);
    if (!tab || !raw) {
        free(tab);
        free(raw);
        return -1;
    }
    uint32_t cum = 0;
    for (int x = 0; x < w; ++x) {
        cum += counts[x];
        put_value(tab + (size_t) x * 4, EXR_PIXEL_UINT, (double) cum);
    }
    uint8_t *p = raw;
    for (int c = 0; c < nch; ++c) {
        const int b = type_bytes(type[c]);
        for (uint64_t s = 0; s < total; ++s, p += b)
            put_value(p, type[c], v[(size_t) s * (size_t) nch + (size_t) c]);
    }
    int rc = 0;
    out->table_size = zip_pack(tab, (uint64_t) w * 4, zip_level, &out->table, &out->tcap,
                               &out->scratch, &out->scap);
    if (out->table_size == 0)
        rc = -1;
    out->data_raw = total * bps;
    out->data_size = total ? zip_pack(raw, total * bps, zip_level, &out->data, &out->dcap,
                                      &out->scratch, &out->scap)
                           : 0;
    if (total && out->data_size == 0)
        rc = -1;
    if (!total && ef_deep_grow((void **) &out->data, &out->dcap, 8))
        rc = -1;
    free(tab);
    free(raw);
    /* the scratch is the row's raw size: not kept while the chunk waits */
    free(out->scratch);
    out->scratch = NULL;
    out->scap = 0;
    return rc;
}

int ef_flat_pack_rows(int nch, const exr_pixel_type_t *type, int w, int n, const double *v,
                      int zip_level, ef_deep_packed *out)
{
    uint64_t bps = 0;
    for (int c = 0; c < nch; ++c)
        bps += (uint64_t) type_bytes(type[c]);
    const uint64_t size = (uint64_t) w * (uint64_t) n * bps;
    uint8_t *raw = malloc((size_t) size + 8);
    if (!raw)
        return -1;
    uint8_t *p = raw;
    for (int j = 0; j < n; ++j)
        for (int c = 0; c < nch; ++c) {
            const int b = type_bytes(type[c]);
            for (int x = 0; x < w; ++x, p += b)
                put_value(p, type[c], v[((size_t) j * (size_t) w + (size_t) x) * (size_t) nch + (size_t) c]);
        }
    out->data_raw = size;
    out->data_size = zip_pack(raw, size, zip_level, &out->data, &out->dcap, &out->scratch,
                              &out->scap);
    out->table_size = 0;
    free(raw);
    free(out->scratch);
    out->scratch = NULL;
    out->scap = 0;
    return out->data_size ? 0 : -1;
}

static int cmp_name(const char *a, const char *b)
{
    return strcmp(a, b);
}

/* Adds the written part (index op = its place) to o->ctx. */
static int define_own(ef_deep_out *o, const ef_exr_file *in, int part, int multi, int nch,
                      const char *const *name, const exr_pixel_type_t *type, const char *history,
                      const char *params, const double *aov_origin, ef_err *err)
{
    const char *pname = NULL;
    exr_get_name(in->ctx, part, &pname);
    const int deep = o->deep;
    int op;
    if (exr_add_part(o->ctx, multi ? pname : NULL,
                     deep ? EXR_STORAGE_DEEP_SCANLINE : EXR_STORAGE_SCANLINE, &op) ||
        op != o->part)
        return ef_fail(err, "cannot add the output part: %s", ef_exr_last_core_message());
    for (int c = 0; c < nch; ++c)
        if (exr_add_channel(o->ctx, op, name[c], type[c], EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1))
            return ef_fail(err, "cannot add channel '%s': %s", name[c], ef_exr_last_core_message());
    if (exr_set_compression(o->ctx, op, deep ? EXR_COMPRESSION_ZIPS : EXR_COMPRESSION_ZIP) ||
        exr_set_lineorder(o->ctx, op, EXR_LINEORDER_INCREASING_Y))
        return ef_fail(err, "cannot set the output's compression");
    /* written as -1 ("unknown", which the spec allows) and set in place at
     * the end, once every pixel's count is known */
    if (deep && exr_attr_set_int(o->ctx, op, "maxSamplesPerPixel", -1))
        return ef_fail(err, "cannot set maxSamplesPerPixel: %s", ef_exr_last_core_message());
    if (aov_origin) {
        const exr_attr_v3d_t v = { .x = aov_origin[0], .y = aov_origin[1], .z = aov_origin[2] };
        if (exr_attr_set_v3d(o->ctx, op, "exrfog/aovOrigin", &v))
            return ef_fail(err, "cannot record exrfog/aovOrigin: %s", ef_exr_last_core_message());
    }
    return ef_exr_copy_attrs(in, part, o->ctx, op, params, history, err);
}

int ef_deep_out_begin(ef_deep_out *o, const char *path, int fd, const ef_exr_file *in, int part,
                      int deep, int nch, const char *const *name, const exr_pixel_type_t *type,
                      const char *history, const char *params, const double *aov_origin,
                      int others, ef_err *err)
{
    memset(o, 0, sizeof *o);
    o->fd = fd;
    o->deep = deep;
    o->nch = nch;
    o->path = path;
    if (nch < 1 || nch > EF_DEEP_IO_MAX_CH)
        return ef_fail(err, "internal error: %d output channels", nch);
    for (int c = 0; c < nch; ++c) {
        o->type[c] = type[c];
        if (c && cmp_name(name[c - 1], name[c]) >= 0)
            return ef_fail(err, "internal error: output channels not sorted");
    }
    ef_exr_sink *sink = calloc(1, sizeof *sink);
    if (!sink)
        return ef_fail(err, "out of memory");
    sink->fd = fd;
    o->sink = sink;
    exr_context_initializer_t init;
    ef_exr_init_context(&init);
    init.user_data = sink;
    init.write_fn = ef_exr_sink_write;
    if (exr_start_write(&o->ctx, path, EXR_WRITE_FILE_DIRECTLY, &init)) {
        free(sink);
        o->sink = NULL;
        return ef_fail(err, "cannot create the output: %s", ef_exr_last_core_message());
    }
    /* a channel name past 31 bytes (an AOV of a light with a long name)
     * needs the long-names flag */
    int longn = 0;
    for (int c = 0; c < nch; ++c)
        longn |= strlen(name[c]) > 31;
    if (longn && exr_set_longname_support(o->ctx, 1))
        return ef_fail(err, "cannot enable long names: %s", ef_exr_last_core_message());
    int32_t nparts = 0;
    exr_get_count(in->ctx, &nparts);
    const int multi = nparts > 1;
    if (!others || nparts < 2) {
        o->part = 0;
        if (define_own(o, in, part, multi, nch, name, type, history, params, aov_origin, err))
            return -1;
    } else {
        o->in = in;
        o->part = part;
        /* every part in its place: the copies before and after it */
        for (int p = 0; p < nparts; ++p)
            if (p == part ? define_own(o, in, part, 1, nch, name, type, history, params,
                                       aov_origin, err)
                          : ef_exr_define_part_copy(in, p, o->ctx, history, params, err))
                return -1;
    }
    for (int p = 0; p < o->part; ++p) {
        const exr_attribute_t *a;
        o->msp_skip +=
            exr_get_attribute_by_name(o->ctx, p, "maxSamplesPerPixel", &a) == EXR_ERR_SUCCESS;
    }
    if (exr_write_header(o->ctx))
        return ef_fail(err, "cannot write the output header: %s", ef_exr_last_core_message());
    /* Core takes the parts' chunks in part order */
    for (int p = 0; o->in && p < o->part; ++p)
        if (ef_exr_copy_part_chunks(in, p, o->ctx, err))
            return -1;
    return 0;
}

int ef_deep_out_write(ef_deep_out *o, const ef_deep_packed *p, ef_err *err)
{
    exr_result_t rc;
    if (o->deep) {
        if (p->max_count > o->max_count)
            o->max_count = p->max_count;
        rc = exr_write_deep_scanline_chunk(o->ctx, o->part, p->y, p->data, p->data_size,
                                           p->data_raw, p->table, p->table_size);
    } else {
        rc = exr_write_scanline_chunk(o->ctx, o->part, p->y, p->data, p->data_size);
    }
    if (rc) {
        const ef_exr_sink *s = o->sink;
        return ef_fail(err, "cannot write the output: %s",
                       s && s->errnum ? strerror(s->errnum) : ef_exr_last_core_message());
    }
    return 0;
}

/* Finds "maxSamplesPerPixel\0int\0" + size 4 in the header and writes the
 * count there. */
static int patch_max_samples(ef_deep_out *o, ef_err *err)
{
    static const char key[] = "maxSamplesPerPixel\0int\0\4\0\0\0";
    const size_t klen = sizeof key - 1;
    uint8_t buf[65536];
    const ssize_t n = pread(o->fd, buf, sizeof buf, 0);
    if (n <= 0)
        return ef_fail(err, "cannot read the output header back: %s", strerror(errno));
    /* the headers come in part order: skip the copied parts' own */
    int skip = o->msp_skip;
    const uint8_t *at = memmem(buf, (size_t) n, key, klen);
    for (; at && skip > 0; --skip) {
        const size_t off = (size_t) (at - buf) + klen;
        at = off < (size_t) n ? memmem(buf + off, (size_t) n - off, key, klen) : NULL;
    }
    if (!at || (size_t) (at - buf) + klen + 4 > (size_t) n)
        return ef_fail(err, "cannot find maxSamplesPerPixel in the output header");
    uint8_t v[4];
    put_value(v, EXR_PIXEL_UINT, (double) o->max_count);
    if (pwrite(o->fd, v, 4, (off_t) ((at - buf) + (ptrdiff_t) klen)) != 4)
        return ef_fail(err, "cannot write maxSamplesPerPixel: %s", strerror(errno));
    return 0;
}

int ef_deep_out_end(ef_deep_out *o, ef_err *err)
{
    const ef_exr_sink *s = o->sink;
    int32_t nparts = 0;
    if (o->in)
        exr_get_count(o->in->ctx, &nparts);
    for (int p = o->part + 1; p < nparts; ++p)
        if (ef_exr_copy_part_chunks(o->in, p, o->ctx, err)) {
            ef_deep_out_abort(o);
            return -1;
        }
    int rc = exr_finish(&o->ctx) ? -1 : 0;
    if (rc)
        ef_fail(err, "cannot finish the output: %s",
                s && s->errnum ? strerror(s->errnum) : ef_exr_last_core_message());
    if (!rc && o->deep)
        rc = patch_max_samples(o, err);
    free(o->sink);
    o->sink = NULL;
    return rc;
}

void ef_deep_out_abort(ef_deep_out *o)
{
    if (o->ctx)
        exr_finish(&o->ctx);
    free(o->sink);
    o->sink = NULL;
}
