/* Streaming transcoder: every part of the input is decoded unit by unit
 * (a band of scanline chunks or one tile), the colour part's units go
 * through the fog callback, and the result is compressed in parallel and
 * written in chunk order. Memory is a few units per thread, whatever the
 * image size. */
#include "exr_io.h"
#include "exr_parts.h"
#include "exr_deflate.h"
#include "exr_ring.h"
#include "half_conv.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>



/* Geometry of one part as the stream walks it. */
typedef struct part_geom {
    exr_attr_box2i_t dw;
    int width, height;
    int tiled, tw, th, ntx;
    /* tiled, walked a row of tiles per unit (the halo's: a unit then has
     * its left and right neighbours in it, and its rows above and below in
     * the units above and below, as scanline units do) */
    int tile_rows;
    int in_rows;              /* scanlines per input chunk */
    int unit_rows;            /* scanline: rows per unit (a multiple of both chunkings) */
    int nunits;
} part_geom;

static int geom_init(exr_const_context_t ctx, int p, int out_rows, part_geom *g)
{
    exr_storage_t st;
    memset(g, 0, sizeof *g);
    if (exr_get_data_window(ctx, p, &g->dw) || exr_get_storage(ctx, p, &st))
        return -1;
    g->width = g->dw.max.x - g->dw.min.x + 1;
    g->height = g->dw.max.y - g->dw.min.y + 1;
    g->tiled = st == EXR_STORAGE_TILED;
    if (g->tiled) {
        uint32_t tx, ty;
        if (exr_get_tile_descriptor(ctx, p, &tx, &ty, NULL, NULL))
            return -1;
        g->tw = (int) tx;
        g->th = (int) ty;
        g->ntx = (g->width + g->tw - 1) / g->tw;
        g->nunits = g->ntx * ((g->height + g->th - 1) / g->th);
        return 0;
    }
    if (exr_get_scanlines_per_chunk(ctx, p, &g->in_rows) || g->in_rows < 1)
        return -1;
    /* Chunk heights are 1, 16 or 32 (powers of two), so the larger is a
     * multiple of the smaller; at least 16 rows keep per-unit overhead low. */
    g->unit_rows = g->in_rows > out_rows ? g->in_rows : out_rows;
    if (g->unit_rows < 16)
        g->unit_rows = 16;
    g->nunits = (g->height + g->unit_rows - 1) / g->unit_rows;
    return 0;
}

/* Walks tiled part g a row of tiles per unit. */
static void geom_tile_rows(part_geom *g)
{
    g->tile_rows = 1;
    g->nunits = (g->height + g->th - 1) / g->th;
}

/* The rectangle of unit u, in absolute pixels. */
static void unit_rect(const part_geom *g, int u, int *x0, int *y0, int *w, int *h)
{
    if (g->tile_rows) {
        *x0 = g->dw.min.x;
        *y0 = g->dw.min.y + u * g->th;
        *w = g->width;
        *h = g->dw.max.y + 1 - *y0 < g->th ? g->dw.max.y + 1 - *y0 : g->th;
    } else if (g->tiled) {
        int tx = u % g->ntx, ty = u / g->ntx;
        *x0 = g->dw.min.x + tx * g->tw;
        *y0 = g->dw.min.y + ty * g->th;
        *w = g->dw.max.x + 1 - *x0 < g->tw ? g->dw.max.x + 1 - *x0 : g->tw;
        *h = g->dw.max.y + 1 - *y0 < g->th ? g->dw.max.y + 1 - *y0 : g->th;
    } else {
        *x0 = g->dw.min.x;
        *y0 = g->dw.min.y + u * g->unit_rows;
        *w = g->width;
        *h = g->dw.max.y + 1 - *y0 < g->unit_rows ? g->dw.max.y + 1 - *y0 : g->unit_rows;
    }
}

/* The most pixels a unit holds (a unit never exceeds the data window,
 * whatever the tile size claims). */
static size_t unit_pixels(const part_geom *g)
{
    const size_t th = (size_t) (g->th < g->height ? g->th : g->height);
    if (g->tile_rows)
        return (size_t) g->width * th;
    if (g->tiled)
        return (size_t) (g->tw < g->width ? g->tw : g->width) * th;
    return (size_t) g->width * (size_t) g->unit_rows;
}

/* Planes hold uint channels as uint32, so ids pass through exactly, unless
 * the fog reads or writes the channel (colour, alpha, depth): then float. */
static exr_pixel_type_t plane_type(exr_pixel_type_t file_type, uint8_t as_float)
{
    return file_type == EXR_PIXEL_UINT && !as_float ? EXR_PIXEL_UINT : EXR_PIXEL_FLOAT;
}

/* A worker's buffer for half channels on their way to or from float
 * planes (half_conv.h): a chunk's worth of each. */
#define EF_MAX_CHANNELS_SCRATCH 64   /* channels past it keep Core's conversion */

typedef struct half_scratch {
    uint16_t *buf;
    size_t cap;
    int fast;                 /* ef_half_fast(), once per worker */
} half_scratch;

static uint16_t *scratch_for(half_scratch *hs, size_t n)
{
    if (n > hs->cap) {
        uint16_t *b = realloc(hs->buf, n * sizeof *b);
        if (!b)
            return NULL;
        hs->buf = b;
        hs->cap = n;
    }
    return hs->buf;
}

/* Whether coding channel ch, half in the file and float in the planes,
 * goes through the scratch (full resolution only: sampled channels keep
 * Core's own unpack and pack). */
static int via_scratch(const half_scratch *hs, const exr_coding_channel_info_t *ch)
{
    return hs->fast && ch->data_type == EXR_PIXEL_HALF && ch->user_data_type == EXR_PIXEL_FLOAT &&
           ch->x_samples == 1 && ch->y_samples == 1;
}

/* Points coding channel ch at a half region of the scratch, `width`
 * pixels per row, for Core to unpack into or pack from. */
static void to_scratch(exr_coding_channel_info_t *ch, int width)
{
    ch->user_data_type = EXR_PIXEL_HALF;
    ch->user_bytes_per_element = 2;
    ch->user_pixel_stride = 2;
    ch->user_line_stride = 2 * width;
}

/* hs's buffer, sized for a chunk of `area` pixels in each of the first
 * channels of chs (up to EF_MAX_CHANNELS_SCRATCH) that go via_scratch;
 * *nh of them. NULL when none does, or when out of memory (*nh > 0). */
static uint16_t *scratch_chunk(half_scratch *hs, const exr_coding_channel_info_t *chs, int n,
                               size_t area, size_t *nh)
{
    *nh = 0;
    for (int c = 0; c < n && c < EF_MAX_CHANNELS_SCRATCH; ++c)
        *nh += via_scratch(hs, &chs[c]);
    return *nh ? scratch_for(hs, *nh * area) : NULL;
}

/* ---- planes straight from and to the chunk layout ----
 *
 * A chunk's uncompressed bytes are its rows in order, each row every
 * channel's samples in channel order, little-endian. When every channel is
 * full resolution and either half (as float planes) or 32-bit (as planes of
 * its own type), exrfog unpacks and packs that layout itself: each row
 * segment is converted (half_conv.h, the same bits as Core's) or copied
 * straight between the chunk and the planes. This replaces Core's generic
 * interleaving loops and the half scratch's extra pass, reads an
 * uncompressed chunk with one read instead of one per channel and row
 * (Core's "direct" read), and packs outside the output context's write
 * lock (Core 3.1.5 runs its own packing under it): Core is left the read,
 * the compression and nothing per pixel. Only with F16C (ef_half_fast), so
 * that EXRFOG_F16C=0 keeps Core's whole path to compare against. */

/* Whether coding channels chs can take the straight path (above). */
static int straight_ok(const half_scratch *hs, const exr_coding_channel_info_t *chs, int n)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    if (!hs->fast)
        return 0;
    for (int c = 0; c < n; ++c) {
        const exr_coding_channel_info_t *ch = &chs[c];
        const int same32 = ch->data_type != EXR_PIXEL_HALF && ch->user_data_type == ch->data_type;
        const int half = ch->data_type == EXR_PIXEL_HALF && ch->user_data_type == EXR_PIXEL_FLOAT;
        if (ch->x_samples != 1 || ch->y_samples != 1 || !(same32 || half) ||
            ch->user_bytes_per_element != 4 || ch->user_pixel_stride != 4)
            return 0;
    }
    return n > 0;
#else
    (void) hs;
    (void) chs;
    (void) n;
    return 0;
#endif
}

/* The bytes of one row of the chunk, every channel. */
static uint64_t row_bytes(const exr_coding_channel_info_t *chs, int n)
{
    uint64_t b = 0;
    for (int c = 0; c < n; ++c)
        b += (uint64_t) chs[c].width * (uint64_t) chs[c].bytes_per_element;
    return b;
}

/* read_fn for an uncompressed part: the whole chunk in one read. */
static exr_result_t read_whole(exr_decode_pipeline_t *d)
{
    if (d->unpacked_buffer == d->packed_buffer && d->unpacked_alloc_size == 0)
        d->unpacked_buffer = NULL;           /* was aliased to the packed buffer */
    exr_result_t rv = ef_pipeline_reserve(d->alloc_fn, d->free_fn, EXR_TRANSCODE_BUFFER_PACKED,
                                          &d->packed_buffer, &d->packed_alloc_size,
                                          d->chunk.packed_size);
    return rv ? rv : exr_read_chunk(d->context, d->part_index, &d->chunk, d->packed_buffer);
}

/* unpack_and_convert_fn: the chunk's rows into the channels' planes. A
 * size that does not match the channels' rows is a corrupt chunk (an
 * uncompressed chunk's stored size is checked before, by decode_chunk). */
static exr_result_t unpack_straight(exr_decode_pipeline_t *d)
{
    const uint64_t row = row_bytes(d->channels, d->channel_count);
    if (!d->unpacked_buffer || row * (uint64_t) d->chunk.height != d->chunk.unpacked_size)
        return EXR_ERR_CORRUPT_CHUNK;
    const uint8_t *s = d->unpacked_buffer;
    for (int y = 0; y < d->chunk.height; ++y)
        for (int c = 0; c < d->channel_count; ++c) {
            const exr_coding_channel_info_t *ch = &d->channels[c];
            uint8_t *dst = ch->decode_to_ptr + (size_t) y * (size_t) ch->user_line_stride;
            if (ch->data_type == EXR_PIXEL_HALF)
                ef_half_to_float((const uint16_t *) s, (float *) dst, (size_t) ch->width);
            else
                memcpy(dst, s, 4 * (size_t) ch->width);
            s += (size_t) ch->width * (size_t) ch->bytes_per_element;
        }
    return EXR_ERR_SUCCESS;
}

/* The packed size of enc's chunk. */
static uint64_t packed_size(const exr_encode_pipeline_t *e)
{
    return row_bytes(e->channels, e->channel_count) * (uint64_t) e->chunk.height;
}

/* Packs the planes of enc's channels into o (packed_size bytes). */
static void pack_straight(const exr_encode_pipeline_t *e, uint8_t *o)
{
    for (int y = 0; y < e->chunk.height; ++y)
        for (int c = 0; c < e->channel_count; ++c) {
            const exr_coding_channel_info_t *ch = &e->channels[c];
            const uint8_t *src = ch->encode_from_ptr + (size_t) y * (size_t) ch->user_line_stride;
            if (ch->data_type == EXR_PIXEL_HALF)
                ef_float_to_half((const float *) src, (uint16_t *) o, (size_t) ch->width);
            else
                memcpy(o, src, 4 * (size_t) ch->width);
            o += (size_t) ch->width * (size_t) ch->bytes_per_element;
        }
}

/* convert_and_pack_fn once pack_straight has filled the packed buffer (Core
 * allocated nothing: the buffer already had the size). */
static exr_result_t packed_already(exr_encode_pipeline_t *e)
{
    e->packed_bytes = packed_size(e);
    return EXR_ERR_SUCCESS;
}

/* Decodes one input chunk into planes (one 32-bit plane per channel,
 * row stride `stride` pixels, origin at absolute (ox, oy)). Every channel
 * gets a destination: Core 3.1.5 crashes on NULL ones. Half channels are
 * decoded as half into hs and converted here (via_scratch). */
static int decode_chunk(exr_const_context_t ctx, int p, const exr_chunk_info_t *ci, int cx,
                        int cy, exr_decode_pipeline_t *dec, int *ready, void **planes, int stride,
                        int ox, int oy, const uint8_t *as_float, int codec, half_scratch *hs)
{
    const int first = !*ready;
    /* An uncompressed chunk must store exactly its pixels: Core's own
     * per-channel reads go by the geometry and would take a neighbour's
     * bytes for pixels. */
    exr_compression_t comp;
    if (exr_get_compression(ctx, p, &comp) ||
        (comp == EXR_COMPRESSION_NONE && ci->packed_size != ci->unpacked_size))
        return -1;
    exr_result_t rv = first ? exr_decoding_initialize(ctx, p, ci, dec)
                            : exr_decoding_update(ctx, p, ci, dec);
    /* Even a failed initialisation may hold allocations: destroy it later. */
    *ready = 1;
    if (rv)
        return -1;
    const exr_attr_chlist_t *cl;
    exr_get_channels(ctx, p, &cl);
    for (int c = 0; c < dec->channel_count; ++c) {
        exr_coding_channel_info_t *ch = &dec->channels[c];
        int k = 0;
        while (k < cl->num_channels && strcmp(cl->entries[k].name.str, ch->channel_name))
            ++k;
        if (k == cl->num_channels)
            return -1;
        ch->decode_to_ptr = (uint8_t *) planes[k] +
                            4 * ((size_t) (cy - oy) * (size_t) stride + (size_t) (cx - ox));
        ch->user_data_type = plane_type(ch->data_type, as_float[k]);
        ch->user_bytes_per_element = 4;
        ch->user_pixel_stride = 4;
        ch->user_line_stride = 4 * stride;
    }
    if (straight_ok(hs, dec->channels, dec->channel_count)) {
        if (first && (exr_decoding_choose_default_routines(ctx, p, dec) ||
                      (codec == EF_CODEC_LIBDEFLATE && ef_deflate_decoding_setup(ctx, p, dec))))
            return -1;
        if (comp == EXR_COMPRESSION_NONE)
            dec->read_fn = read_whole;      /* not one read per channel and row */
        dec->unpack_and_convert_fn = unpack_straight;
        return exr_decoding_run(ctx, p, dec) ? -1 : 0;
    }
    /* The half channels' scratch, one chunk-sized region each. */
    const size_t area = (size_t) ci->width * (size_t) ci->height;
    size_t nh;
    uint16_t *sc = scratch_chunk(hs, dec->channels, dec->channel_count, area, &nh);
    if (nh && !sc)
        return -1;
    uint8_t *dest[EF_MAX_CHANNELS_SCRATCH];
    for (int c = 0, i = 0; c < dec->channel_count && c < EF_MAX_CHANNELS_SCRATCH; ++c) {
        exr_coding_channel_info_t *ch = &dec->channels[c];
        dest[c] = NULL;
        if (!via_scratch(hs, ch))
            continue;
        dest[c] = ch->decode_to_ptr;
        ch->decode_to_ptr = (uint8_t *) (sc + (size_t) i++ * area);
        to_scratch(ch, ci->width);
    }
    if (first && (exr_decoding_choose_default_routines(ctx, p, dec) ||
                  (codec == EF_CODEC_LIBDEFLATE && ef_deflate_decoding_setup(ctx, p, dec))))
        return -1;
    if (exr_decoding_run(ctx, p, dec))
        return -1;
    for (int c = 0; c < dec->channel_count && c < EF_MAX_CHANNELS_SCRATCH; ++c) {
        if (!dest[c])
            continue;
        const uint16_t *h = (const uint16_t *) dec->channels[c].decode_to_ptr;
        for (int r = 0; r < ci->height; ++r)
            ef_half_to_float(h + (size_t) r * (size_t) ci->width,
                             (float *) dest[c] + (size_t) r * (size_t) stride, (size_t) ci->width);
    }
    return 0;
}

/* Chunk info for the chunk that holds absolute pixel (x, y), and the
 * absolute pixel of its top-left corner (Core reports tile indices). */
static int chunk_at(exr_const_context_t ctx, int p, const part_geom *g, int x, int y,
                    exr_chunk_info_t *ci, int *cx, int *cy)
{
    if (g->tiled) {
        int tx = (x - g->dw.min.x) / g->tw, ty = (y - g->dw.min.y) / g->th;
        *cx = g->dw.min.x + tx * g->tw;
        *cy = g->dw.min.y + ty * g->th;
        return exr_read_tile_chunk_info(ctx, p, tx, ty, 0, 0, ci) ? -1 : 0;
    }
    if (exr_read_scanline_chunk_info(ctx, p, y, ci))
        return -1;
    *cx = g->dw.min.x;
    *cy = ci->start_y;
    return 0;
}

/* Reads depth for a rectangle from another part or file: decodes each
 * source chunk that overlaps it (whole, every channel) and copies the
 * overlap. The last chunk is cached because neighbouring units share it. */
typedef struct depth_reader {
    exr_const_context_t ctx;
    int part, chan, nch;
    int codec;                /* EF_CODEC_* */
    part_geom g;
    exr_decode_pipeline_t dec;
    int ready;
    void **planes;            /* nch planes of one source chunk */
    uint8_t *as_float;        /* only the depth channel */
    size_t plane_cap;
    int cached, cx, cy, cw, ch;
    half_scratch hs;
} depth_reader;

/* Copies channel r->chan of the rectangle into out (rows w long); with
 * more (nmore channels, their outputs), those too from the same chunks. */
static int depth_read_n(depth_reader *r, int x0, int y0, int w, int h, float *out,
                        const int *more, float *const *more_out, int nmore)
{
    for (int y = y0; y < y0 + h;) {
        int next_y = y0 + h;
        for (int x = x0; x < x0 + w;) {
            if (!(r->cached && x >= r->cx && x < r->cx + r->cw && y >= r->cy && y < r->cy + r->ch)) {
                exr_chunk_info_t ci;
                int cx, cy;
                if (chunk_at(r->ctx, r->part, &r->g, x, y, &ci, &cx, &cy))
                    return -1;
                size_t need = (size_t) ci.width * (size_t) ci.height;
                if (need > r->plane_cap) {
                    for (int k = 0; k < r->nch; ++k) {
                        free(r->planes[k]);
                        r->planes[k] = malloc(need * 4);
                        if (!r->planes[k])
                            return -1;
                    }
                    r->plane_cap = need;
                }
                r->cached = 0;
                if (decode_chunk(r->ctx, r->part, &ci, cx, cy, &r->dec, &r->ready, r->planes,
                                 ci.width, cx, cy, r->as_float, r->codec, &r->hs))
                    return -1;
                r->cached = 1;
                r->cx = cx;
                r->cy = cy;
                r->cw = ci.width;
                r->ch = ci.height;
            }
            int xe = r->cx + r->cw < x0 + w ? r->cx + r->cw : x0 + w;
            int ye = r->cy + r->ch < y0 + h ? r->cy + r->ch : y0 + h;
            for (int m = -1; m < nmore; ++m) {
                const float *src = r->planes[m < 0 ? r->chan : more[m]];
                float *dst = m < 0 ? out : more_out[m];
                for (int yy = y; yy < ye; ++yy)
                    memcpy(dst + (size_t) (yy - y0) * w + (x - x0),
                           src + (size_t) (yy - r->cy) * r->cw + (x - r->cx),
                           sizeof(float) * (size_t) (xe - x));
            }
            next_y = ye;
            x = xe;
        }
        y = next_y;
    }
    return 0;
}

static int depth_read(depth_reader *r, int x0, int y0, int w, int h, float *out)
{
    return depth_read_n(r, x0, y0, w, h, out, NULL, NULL, 0);
}

static void depth_reader_free(depth_reader *r)
{
    if (r->ready)
        ef_deflate_decoding_destroy(r->ctx, &r->dec);
    for (int k = 0; r->planes && k < r->nch; ++k)
        free(r->planes[k]);
    free(r->planes);
    free(r->as_float);
    free(r->hs.buf);
}

struct ef_exr_rows {
    depth_reader r;
    int chans[8], nchan;
};

ef_exr_rows *ef_exr_rows_open(const ef_exr_file *f, int part, const int *chans, int nchan,
                              int *width, int *height)
{
    const exr_attr_chlist_t *cl;
    if (nchan < 1 || nchan > 8 || exr_get_channels(f->ctx, part, &cl))
        return NULL;
    for (int c = 0; c < nchan; ++c)
        if (chans[c] < 0 || chans[c] >= cl->num_channels)
            return NULL;
    ef_exr_rows *R = calloc(1, sizeof *R);
    if (!R)
        return NULL;
    depth_reader *r = &R->r;
    r->ctx = f->ctx;
    r->part = part;
    r->chan = chans[0];
    r->nch = cl->num_channels;
    r->codec = EF_CODEC_LIBDEFLATE;
    r->hs.fast = ef_half_fast();
    memcpy(R->chans, chans, (size_t) nchan * sizeof *chans);
    R->nchan = nchan;
    if (geom_init(f->ctx, part, 1, &r->g) ||
        !(r->planes = calloc((size_t) r->nch, sizeof *r->planes)) ||
        !(r->as_float = calloc((size_t) r->nch, 1))) {
        ef_exr_rows_close(R);
        return NULL;
    }
    for (int c = 0; c < nchan; ++c)
        r->as_float[chans[c]] = 1;
    *width = r->g.width;
    *height = r->g.height;
    return R;
}

int ef_exr_rows_read(ef_exr_rows *R, int y, float *const *out)
{
    depth_reader *r = &R->r;
    if (y < 0 || y >= r->g.height)
        return -1;
    return depth_read_n(r, r->g.dw.min.x, r->g.dw.min.y + y, r->g.width, 1, out[0], R->chans + 1,
                        out + 1, R->nchan - 1);
}

void ef_exr_rows_close(ef_exr_rows *R)
{
    if (!R)
        return;
    depth_reader_free(&R->r);
    free(R);
}

int ef_exr_sample_rows(const ef_exr_file *f, int part, int chan, int nrows, float **out, int *width,
                       int *ys)
{
    *out = NULL;
    int w = 0, h = 0;
    ef_exr_rows *R = nrows >= 1 ? ef_exr_rows_open(f, part, &chan, 1, &w, &h) : NULL;
    if (!R)
        return -1;
    if (nrows > h)
        nrows = h;
    int ok = (*out = malloc((size_t) nrows * (size_t) w * sizeof **out)) != NULL;
    for (int i = 0; ok && i < nrows; ++i) {
        const int y = (int) (((long) (2 * i + 1) * h) / (2 * nrows));
        ys[i] = R->r.g.dw.min.y + y;
        float *row = *out + (size_t) i * (size_t) w;
        ok = ef_exr_rows_read(R, y, &row) == 0;
    }
    ef_exr_rows_close(R);
    if (!ok) {
        free(*out);
        *out = NULL;
        return -1;
    }
    *width = w;
    return nrows;
}

/* Shared state of one part's parallel pass. */
typedef struct part_job {
    exr_const_context_t in;
    exr_context_t out;
    const char *in_path, *depth_path, *out_path;
    int part;
    part_geom g;
    int out_rows;             /* scanlines per output chunk */
    int nch;
    const exr_attr_chlist_t *cl;
    int nextra;               /* colour part: channels added after the nch read */
    const char *const *extra; /* their names */
    uint8_t *as_float;        /* per channel: the callback sees it as float */
    /* The plans (views) whose colour is in this part: the callback edits
     * each in turn. Target t's extra channels are planes nch + t*nx ... */
    int ntarget, nx;
    struct {
        int plan;                 /* index in the plan array */
        const ef_channel_plan *pl;
        exr_const_context_t depth_ctx;
        int depth_part;           /* part in depth_ctx, when separate */
        int depth_local;          /* channel index of depth in this part, or -1 */
    } t[EF_MAX_VIEWS];
    ef_chunk_fn fn;
    void *user;
    const _Atomic int *cancel;    /* opts->cancel: stop at the next unit */
    int codec;                /* EF_CODEC_* */
    int halo;                 /* opts->halo (a tiled part: a row of tiles per unit) */
    /* The halo's shared rows: unit u, once decoded, leaves its first and
     * last EF_STREAM_HALO rows of every target (rgb, alpha, depth) in slot
     * u % nslot, so the units above and below it take them instead of
     * decoding its chunks again; a slot another unit has taken over is a
     * miss (the reader decodes). */
    int nslot;
    int halo_sync;                /* halo_mx and halo_cv made */
    pthread_mutex_t halo_mx;      /* with halo_cv: a slot was filled */
    pthread_cond_t halo_cv;
    struct halo_slot {
        pthread_mutex_t lock;
        int unit;                 /* -1: empty */
        float *rows;              /* [first, last][target][5][EF_STREAM_HALO][width]; the
                                   * last rows end at the block's end */
        int pre_unit;             /* -1, or the unit whose decoded planes pre holds */
        void **pre;               /* nch planes of a unit, as the worker decodes them, each
                                   * pre_plane bytes; or NULL. Handed over by swapping
                                   * pointers with buffers of the same size. */
    } *slot;
    size_t pre_plane;             /* bytes of one plane in pre */
    ef_ring ring;             /* pending encoded units, written in order */
    pthread_mutex_t lock;
    int failed;               /* guarded by lock */
    ef_err err;
    double t_decode, t_fog, t_encode;
    double t_write;           /* only the ring's writer touches it */
} part_job;

/* Records the first failure; file is the file it is about. */
static void job_fail(part_job *j, const char *file, const char *fmt, int a, const char *detail)
{
    pthread_mutex_lock(&j->lock);
    if (!j->failed) {
        char what[200];
        snprintf(what, sizeof what, fmt, a);
        ef_fail(&j->err, "%s%s%s", what, detail && detail[0] ? ": " : "", detail ? detail : "");
        j->err.file = file;
        j->failed = 1;
    }
    pthread_mutex_unlock(&j->lock);
    ef_ring_fail(&j->ring);
}

/* Packs and compresses one output chunk, copying the bytes into o. */
static int encode_chunk(part_job *j, exr_encode_pipeline_t *enc, int *ready,
                        const exr_chunk_info_t *ci, int cx, int cy, void **planes, int stride,
                        int ox, int oy, ef_unit_buf *o, int key_y, int key_ty, half_scratch *hs)
{
    exr_result_t rv = *ready ? exr_encoding_update(j->out, j->part, ci, enc)
                             : exr_encoding_initialize(j->out, j->part, ci, enc);
    *ready = 1;                               /* to destroy, even after a failure */
    if (rv)
        return -1;
    for (int c = 0; c < enc->channel_count; ++c) {
        exr_coding_channel_info_t *ch = &enc->channels[c];
        /* By name: the output list is sorted, the added channels among the
         * others. planes[nch + i] holds extra channel i, as float. */
        int k = 0;
        while (k < j->nch && strcmp(j->cl->entries[k].name.str, ch->channel_name))
            ++k;
        while (k >= j->nch && k < j->nch + j->nextra && strcmp(j->extra[k - j->nch], ch->channel_name))
            ++k;
        if (k == j->nch + j->nextra)
            return -1;
        ch->encode_from_ptr = (const uint8_t *) planes[k] +
                              4 * ((size_t) (cy - oy) * (size_t) stride + (size_t) (cx - ox));
        ch->user_data_type = k < j->nch ? plane_type(ch->data_type, j->as_float[k]) : EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = 4;
        ch->user_pixel_stride = 4;
        ch->user_line_stride = 4 * stride;
    }
    exr_compression_t comp;
    exr_get_compression(j->out, j->part, &comp);
    const int straight = straight_ok(hs, enc->channels, enc->channel_count);
    if (straight) {
        /* Uncompressed: the packed bytes are the chunk, packed in place. */
        const uint64_t n = packed_size(enc);
        uint8_t *at = comp == EXR_COMPRESSION_NONE ? ef_unit_reserve(o, n, key_y, key_ty) : NULL;
        if (at) {
            pack_straight(enc, at);
            return 0;
        }
        if (comp == EXR_COMPRESSION_NONE ||
            ef_pipeline_reserve(enc->alloc_fn, enc->free_fn, EXR_TRANSCODE_BUFFER_PACKED,
                                &enc->packed_buffer, &enc->packed_alloc_size, n))
            return -1;
        pack_straight(enc, enc->packed_buffer);
    }
    /* Otherwise half channels are converted here into hs, packed by Core. */
    const size_t area = (size_t) ci->width * (size_t) ci->height;
    size_t nh = 0;
    uint16_t *sc = straight ? NULL : scratch_chunk(hs, enc->channels, enc->channel_count, area, &nh);
    if (nh && !sc)
        return -1;
    for (int c = 0, i = 0; nh && c < enc->channel_count && c < EF_MAX_CHANNELS_SCRATCH; ++c) {
        exr_coding_channel_info_t *ch = &enc->channels[c];
        if (!via_scratch(hs, ch))
            continue;
        uint16_t *h = sc + (size_t) i++ * area;
        for (int r = 0; r < ci->height; ++r)
            ef_float_to_half((const float *) ch->encode_from_ptr + (size_t) r * (size_t) stride,
                             h + (size_t) r * (size_t) ci->width, (size_t) ci->width);
        ch->encode_from_ptr = (const uint8_t *) h;
        to_scratch(ch, ci->width);
    }
    if (!enc->convert_and_pack_fn) {          /* the first chunk Core encodes */
        if (exr_encoding_choose_default_routines(j->out, j->part, enc) ||
            (j->codec == EF_CODEC_LIBDEFLATE && ef_deflate_encoding_setup(j->out, j->part, enc)))
            return -1;
        /* Only pack and compress here; the ordered writer stores the bytes. */
        enc->write_fn = NULL;
        enc->yield_until_ready_fn = NULL;
    }
    if (straight)
        enc->convert_and_pack_fn = packed_already;
    if (exr_encoding_run(j->out, j->part, enc))
        return -1;
    if (comp == EXR_COMPRESSION_NONE || !enc->compressed_buffer ||
        enc->compressed_bytes >= enc->packed_bytes)
        return ef_unit_append(o, enc->packed_buffer, enc->packed_bytes, key_y, key_ty);
    return ef_unit_append(o, enc->compressed_buffer, enc->compressed_bytes, key_y, key_ty);
}

/* The ring's writer: stores unit u's chunks (in unit order). */
static int write_unit(void *arg, int u, const ef_unit_buf *b)
{
    part_job *j = arg;
    const double t0 = ef_now();
    if (ef_unit_write(j->out, j->part, j->g.tiled, b)) {
        int x0, y0, w, h;
        unit_rect(&j->g, u, &x0, &y0, &w, &h);
        job_fail(j, j->out_path, "cannot write the output chunk at scanline %d", y0,
                 ef_exr_last_core_message());
        return -1;
    }
    j->t_write += ef_now() - t0;
    return 0;
}

/* Planes of target t of a unit for the halo: rgb, alpha (NULL: none) and
 * depth, rows w long. */
typedef struct halo_src {
    const float *p[5];
} halo_src;

/* Leaves unit u's first and last rows (of its h rows of w: EF_STREAM_HALO
 * each, or h where fewer) in its slot. */
static void halo_publish(part_job *j, int u, int w, int h, const halo_src *src)
{
    struct halo_slot *sl = &j->slot[u % j->nslot];
    const int n = h < EF_STREAM_HALO ? h : EF_STREAM_HALO;
    pthread_mutex_lock(&sl->lock);
    for (int side = 0; side < 2; ++side)
        for (int t = 0; t < j->ntarget; ++t)
            for (int k = 0; k < 5; ++k) {
                float *d = sl->rows +
                           ((size_t) ((side * j->ntarget + t) * 5 + k) * EF_STREAM_HALO +
                            (size_t) (side ? EF_STREAM_HALO - n : 0)) * (size_t) w;
                if (src[t].p[k])
                    memcpy(d, src[t].p[k] + (size_t) (side ? h - n : 0) * (size_t) w,
                           (size_t) n * (size_t) w * sizeof *d);
            }
    sl->unit = u;
    pthread_mutex_unlock(&sl->lock);
    pthread_mutex_lock(&j->halo_mx);
    pthread_cond_broadcast(&j->halo_cv);
    pthread_mutex_unlock(&j->halo_mx);
}

/* A unit's decoded planes, left by the unit above it, which decoded its
 * chunk for its own halo (a ZIP chunk of 16 rows is the whole unit): the
 * unit then need not decode it again. The reader's planes (each
 * pre_plane bytes) go to the slot, and the slot's spare ones to the
 * reader, whose chunk cache is then empty. */
static void pre_publish(part_job *j, int u, depth_reader *r)
{
    struct halo_slot *sl = &j->slot[u % j->nslot];
    if (!sl->pre || r->plane_cap * 4 != j->pre_plane)
        return;
    pthread_mutex_lock(&sl->lock);
    for (int k = 0; k < j->nch; ++k) {
        void *t = sl->pre[k];
        sl->pre[k] = r->planes[k];
        r->planes[k] = t;
    }
    sl->pre_unit = u;
    pthread_mutex_unlock(&sl->lock);
    r->cached = 0;
}

/* Unit u's planes from its slot into planes (each pre_plane bytes, swapped
 * with the slot's): 1, else 0. */
static int pre_take(part_job *j, int u, void **planes)
{
    struct halo_slot *sl = &j->slot[u % j->nslot];
    if (!sl->pre)
        return 0;
    pthread_mutex_lock(&sl->lock);
    const int hit = sl->pre_unit == u;
    if (hit) {
        for (int k = 0; k < j->nch; ++k) {
            void *t = sl->pre[k];
            sl->pre[k] = planes[k];
            planes[k] = t;
        }
        sl->pre_unit = -1;
    }
    pthread_mutex_unlock(&sl->lock);
    return hit;
}

static int halo_take_now(part_job *j, int u, int side, int w, float *out);

/* Unit u's first (side 0) or last rows of every target into out ([target]
 * [5][EF_STREAM_HALO][w], the last rows ending at each block's end), when
 * its slot holds them: 1, else 0. A unit another thread has
 * claimed but not yet decoded is waited for (it publishes right after its
 * decode, before anything that could wait on this unit), up to 50 ms. */
static int halo_take(part_job *j, int u, int side, int w, float *out)
{
    for (int tries = 0; tries < 10; ++tries) {
        if (halo_take_now(j, u, side, w, out))
            return 1;
        pthread_mutex_lock(&j->ring.lock);
        const int claimed = j->ring.next > u && !j->ring.failed;
        pthread_mutex_unlock(&j->ring.lock);
        pthread_mutex_lock(&j->lock);
        const int failed = j->failed;
        pthread_mutex_unlock(&j->lock);
        if (!claimed || failed)
            return 0;
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_nsec += 5000000;
        if (ts.tv_nsec >= 1000000000) {
            ts.tv_sec += 1;
            ts.tv_nsec -= 1000000000;
        }
        pthread_mutex_lock(&j->halo_mx);
        if (!halo_take_now(j, u, side, w, out))
            pthread_cond_timedwait(&j->halo_cv, &j->halo_mx, &ts);
        else {
            pthread_mutex_unlock(&j->halo_mx);
            return 1;
        }
        pthread_mutex_unlock(&j->halo_mx);
    }
    return 0;
}

static int halo_take_now(part_job *j, int u, int side, int w, float *out)
{
    struct halo_slot *sl = &j->slot[u % j->nslot];
    pthread_mutex_lock(&sl->lock);
    const int hit = sl->unit == u;
    if (hit)
        memcpy(out, sl->rows + (size_t) (side * j->ntarget) * 5 * EF_STREAM_HALO * (size_t) w,
               (size_t) j->ntarget * 5 * EF_STREAM_HALO * (size_t) w * sizeof *out);
    pthread_mutex_unlock(&sl->lock);
    return hit;
}

static void *worker(void *arg)
{
    part_job *j = arg;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int dec_ready = 0, enc_ready = 0;
    depth_reader dr[EF_MAX_VIEWS];
    memset(dr, 0, sizeof dr);
    ef_unit_buf ob = { 0 };
    half_scratch hs = { NULL, 0, ef_half_fast() };
    float *depth[EF_MAX_VIEWS] = { NULL };
    /* A unit never exceeds the data window, whatever the tile size claims. */
    size_t cap = unit_pixels(&j->g);
    const int nplanes = j->nch + j->nextra;
    void **planes = calloc((size_t) nplanes, sizeof *planes);
    int ok = planes != NULL;
    for (int k = 0; ok && k < nplanes; ++k)
        ok = (planes[k] = malloc(cap * 4)) != NULL;
    for (int t = 0; ok && t < j->ntarget; ++t) {
        if (j->t[t].depth_local >= 0)
            continue;
        const exr_attr_chlist_t *dcl;
        depth_reader *r = &dr[t];
        r->ctx = j->t[t].depth_ctx;
        r->part = j->t[t].depth_part;
        r->chan = j->t[t].pl->depth.index;
        r->codec = j->codec;
        ok = !exr_get_channels(r->ctx, r->part, &dcl) && !geom_init(r->ctx, r->part, 1, &r->g);
        r->nch = ok ? dcl->num_channels : 0;
        ok = ok && (r->planes = calloc((size_t) r->nch, sizeof *r->planes)) != NULL &&
             (r->as_float = calloc((size_t) r->nch, 1)) != NULL &&
             (depth[t] = malloc(cap * sizeof *depth[t])) != NULL;
        if (ok)
            r->as_float[r->chan] = 1;
        r->hs.fast = ef_half_fast();
    }
    /* The halo (opts->halo): per side a reader of this part whose chunk
     * cache serves the units that share it, and per target its rows. */
    const int halo = j->halo && (!j->g.tiled || j->g.tile_rows);
    depth_reader hr[2];
    memset(hr, 0, sizeof hr);
    float *hbuf = NULL;
    for (int side = 0; ok && halo && side < 2; ++side) {
        depth_reader *r = &hr[side];
        r->ctx = j->in;
        r->part = j->part;
        r->codec = j->codec;
        r->nch = j->nch;
        r->hs.fast = ef_half_fast();
        ok = !geom_init(r->ctx, r->part, 1, &r->g) &&
             (r->planes = calloc((size_t) r->nch, sizeof *r->planes)) != NULL &&
             (r->as_float = malloc((size_t) r->nch)) != NULL;
        if (ok)
            memcpy(r->as_float, j->as_float, (size_t) r->nch);
        /* a unit's worth each (no chunk is larger), so that its planes and
         * a slot's can change hands (pre_publish) */
        for (int k = 0; ok && k < r->nch; ++k)
            ok = (r->planes[k] = malloc(cap * 4)) != NULL;
        if (ok)
            r->plane_cap = cap;
    }
    if (ok && halo)
        ok = (hbuf = malloc((size_t) 2 * (size_t) j->ntarget * 5 * EF_STREAM_HALO *
                            (size_t) j->g.width * sizeof *hbuf)) != NULL;
    if (!ok)
        job_fail(j, j->out_path, "out of memory for part %d", j->part, NULL);

    double td = 0, tf = 0, te = 0;
    for (;;) {
        const int u = ok ? ef_ring_claim(&j->ring) : -1;
        if (u < 0)
            break;
        if (j->cancel && atomic_load_explicit(j->cancel, memory_order_relaxed)) {
            job_fail(j, j->out_path, "cancelled at unit %d; nothing was written", u, NULL);
            break;
        }
        int x0, y0, w, h;
        unit_rect(&j->g, u, &x0, &y0, &w, &h);
        double t0 = ef_now();
        /* decode (unless the unit above left this unit's planes) */
        const int pre = halo && pre_take(j, u, planes);
        for (int y = y0; !pre && y < y0 + h; y += j->g.tiled ? h : j->g.in_rows)
            for (int x = x0; x < x0 + w; x += j->g.tiled ? j->g.tw : w) {
                exr_chunk_info_t ci;
                int cx, cy;
                if (chunk_at(j->in, j->part, &j->g, x, y, &ci, &cx, &cy) ||
                    decode_chunk(j->in, j->part, &ci, cx, cy, &dec, &dec_ready, planes, w, x0,
                                 y0, j->as_float, j->codec, &hs)) {
                    job_fail(j, j->in_path, "cannot decode the chunk at scanline %d, the file is "
                                "truncated or corrupt", y, ef_exr_last_core_message());
                    goto out;
                }
            }
        for (int t = 0; t < j->ntarget; ++t)
            if (j->t[t].depth_local < 0 && depth_read(&dr[t], x0, y0, w, h, depth[t])) {
                job_fail(j, j->depth_path,
                         j->depth_path == j->in_path
                             ? "cannot decode the depth part's chunk at scanline %d, the file is "
                               "truncated or corrupt"
                             : "cannot decode the depth chunk at scanline %d, the depth file is "
                               "truncated or corrupt",
                         y0, ef_exr_last_core_message());
                goto out;
            }
        /* the halo rows: colour, alpha and depth of each target, from the
         * neighbouring units' slots where they are there, else decoded */
        int have[2] = { 0, 0 };
        /* rows there above and below (the data window ends) */
        const int nside[2] = {
            y0 - j->g.dw.min.y < EF_STREAM_HALO ? y0 - j->g.dw.min.y : EF_STREAM_HALO,
            j->g.dw.max.y + 1 - (y0 + h) < EF_STREAM_HALO ? j->g.dw.max.y + 1 - (y0 + h)
                                                           : EF_STREAM_HALO };
        if (halo) {
            halo_src src[EF_MAX_VIEWS];
            for (int t = 0; t < j->ntarget; ++t) {
                const ef_channel_plan *pl = j->t[t].pl;
                for (int k = 0; k < 3; ++k)
                    src[t].p[k] = planes[pl->rgb[k].index];
                src[t].p[3] = pl->alpha.part >= 0 ? planes[pl->alpha.index] : NULL;
                src[t].p[4] = j->t[t].depth_local >= 0 ? planes[j->t[t].depth_local] : depth[t];
            }
            halo_publish(j, u, w, h, src);
        }
        /* one plane's block of rows in hbuf: EF_STREAM_HALO rows of w */
        const size_t blk = EF_STREAM_HALO * (size_t) w;
        for (int side = 0; halo && side < 2; ++side) {
            const int n = nside[side];
            if (n <= 0)
                continue;
            if (halo_take(j, side ? u + 1 : u - 1, !side, w,
                          hbuf + (size_t) (side * j->ntarget) * 5 * blk)) {
                have[side] = 1;
                continue;
            }
            /* the rows above end at a block's end, those below start it */
            const int y = side ? y0 + h : y0 - n;
            const size_t at = side ? 0 : (size_t) (EF_STREAM_HALO - n) * (size_t) w;
            for (int t = 0; t < j->ntarget; ++t) {
                const ef_channel_plan *pl = j->t[t].pl;
                float *b = hbuf + ((size_t) (side * j->ntarget + t) * 5) * blk + at;
                int more[4], nm = 0;
                float *mo[4];
                for (int k = 1; k < 3; ++k) {
                    more[nm] = pl->rgb[k].index;
                    mo[nm++] = b + (size_t) k * blk;
                }
                if (pl->alpha.part >= 0) {
                    more[nm] = pl->alpha.index;
                    mo[nm++] = b + 3 * blk;
                }
                if (j->t[t].depth_local >= 0) {
                    more[nm] = j->t[t].depth_local;
                    mo[nm++] = b + 4 * blk;
                }
                hr[side].chan = pl->rgb[0].index;
                if (depth_read_n(&hr[side], x0, y, w, n, b, more, mo, nm) ||
                    (j->t[t].depth_local < 0 && depth_read(&dr[t], x0, y, w, n, b + 4 * blk))) {
                    job_fail(j, j->in_path, "cannot decode the chunk at scanline %d, the file is "
                                "truncated or corrupt", y, ef_exr_last_core_message());
                    goto out;
                }
            }
            /* the chunk below is the whole next unit: leave it decoded */
            if (side && u + 1 < j->g.nunits) {
                int nx0, ny0, nw, nh;
                unit_rect(&j->g, u + 1, &nx0, &ny0, &nw, &nh);
                depth_reader *r = &hr[1];
                if (r->cached && r->cy == ny0 && r->ch == nh && r->cx == nx0 && r->cw == nw)
                    pre_publish(j, u + 1, r);
            }
            have[side] = 1;
        }
        double t1 = ef_now();
        td += t1 - t0;
        for (int t = 0; t < j->ntarget; ++t) {
            const ef_channel_plan *pl = j->t[t].pl;
            ef_chunk ck;
            memset(&ck, 0, sizeof ck);
            ck.view = j->t[t].plan;
            ck.x0 = x0;
            ck.y0 = y0;
            ck.w = w;
            ck.h = h;
            for (int k = 0; k < 3; ++k)
                ck.rgb[k] = planes[pl->rgb[k].index];
            ck.nextra = j->nx;
            for (int k = 0; k < j->nx; ++k) {
                ck.extra[k] = planes[j->nch + t * j->nx + k];
                memset(ck.extra[k], 0, (size_t) w * (size_t) h * sizeof(float));
            }
            ck.alpha = pl->alpha.part >= 0 ? planes[pl->alpha.index] : NULL;
            ck.depth = j->t[t].depth_local >= 0 ? planes[j->t[t].depth_local] : depth[t];
            for (int side = 0; side < 2; ++side) {
                if (!have[side])
                    continue;
                const float *b = hbuf + ((size_t) (side * j->ntarget + t) * 5) * blk +
                                 (side ? 0 : (size_t) (EF_STREAM_HALO - nside[0]) * (size_t) w);
                for (int k = 0; k < 3; ++k)
                    ck.halo_rgb[side][k] = b + (size_t) k * blk;
                ck.halo_alpha[side] = pl->alpha.part >= 0 ? b + 3 * blk : NULL;
                ck.halo_depth[side] = b + 4 * blk;
                ck.halo_rows[side] = nside[side];
            }
            j->fn(j->user, &ck);
        }
        double t2 = ef_now();
        tf += t2 - t1;
        /* encode */
        ob.n = 0;
        ob.len = 0;
        int step = j->g.tiled ? h : j->out_rows;
        for (int y = y0; y < y0 + h; y += step)
            for (int x = x0; x < x0 + w; x += j->g.tiled ? j->g.tw : w) {
                exr_chunk_info_t ci;
                exr_result_t rv;
                int tx = (x - j->g.dw.min.x) / (j->g.tiled ? j->g.tw : 1);
                int ty = (y0 - j->g.dw.min.y) / (j->g.tiled ? j->g.th : 1);
                if (j->g.tiled)
                    rv = exr_write_tile_chunk_info(j->out, j->part, tx, ty, 0, 0, &ci);
                else
                    rv = exr_write_scanline_chunk_info(j->out, j->part, y, &ci);
                if (rv || encode_chunk(j, &enc, &enc_ready, &ci, x, y, planes, w, x0, y0, &ob,
                                       j->g.tiled ? tx : y, ty, &hs)) {
                    job_fail(j, j->out_path, "cannot encode the output chunk at scanline %d", y,
                             ef_exr_last_core_message());
                    goto out;
                }
            }
        double t3 = ef_now();
        te += t3 - t2;
        /* park; the ring writes it in unit order */
        if (ef_ring_put(&j->ring, u, &ob))
            goto out;
    }
out:
    pthread_mutex_lock(&j->lock);
    j->t_decode += td;
    j->t_fog += tf;
    j->t_encode += te;
    pthread_mutex_unlock(&j->lock);
    if (dec_ready)
        ef_deflate_decoding_destroy(j->in, &dec);
    if (enc_ready)
        ef_deflate_encoding_destroy(j->out, &enc);
    for (int t = 0; t < j->ntarget; ++t) {
        depth_reader_free(&dr[t]);
        free(depth[t]);
    }
    depth_reader_free(&hr[0]);
    depth_reader_free(&hr[1]);
    free(hbuf);
    ef_unit_free(&ob);
    free(hs.buf);
    for (int k = 0; planes && k < nplanes; ++k)
        free(planes[k]);
    free(planes);
    return NULL;
}

/* Declares output part p like input part p: same name, storage, tile size
 * (one level), channels (types per opts), then every other attribute. The
 * colour part also gets opts' extra channels and origin attribute. */
/* Whether a channel holds data that half precision would destroy (depth,
 * positions, ids, Cryptomatte), which -d half leaves in float: a whole
 * name Z, ZBack, depth, Depth, distance, id or ID; a last segment ZBack; or
 * a layer segment P, Pw, Pworld, Pref, Pobj, position, Position,
 * (W|w)orldPosition, fog_P, fog_distance, id, ID, depth, Depth, Z, *Id,
 * *ID, *_id or crypto* (Cryptomatte). */
int ef_data_channel(const char *name)
{
    /* a whole name, or the last segment after a layer (N.Z is a normal) */
    static const char *const whole[] = { "Z", "ZBack", "depth", "Depth", "distance", "id", "ID" };
    static const char *const last[] = { "ZBack" };
    if (!strchr(name, '.'))
        for (size_t i = 0; i < sizeof whole / sizeof whole[0]; ++i)
            if (!strcmp(name, whole[i]))
                return 1;
    static const char *const layer[] = { "P",        "Pw",       "Pworld",   "Pref",
                                         "Pobj",     "position", "Position", "worldPosition",
                                         "WorldPosition", "fog_P", "fog_distance", "id",
                                         "ID",       "depth",    "Depth",    "Z" };
    const char *dot = strrchr(name, '.'), *tail = dot ? dot + 1 : name;
    for (size_t i = 0; i < sizeof last / sizeof last[0]; ++i)
        if (!strcmp(tail, last[i]))
            return 1;
    /* every segment before the last */
    for (const char *seg = name; dot && seg <= dot;) {
        const char *end = strchr(seg, '.');
        const size_t n = (size_t) (end - seg);
        for (size_t i = 0; i < sizeof layer / sizeof layer[0]; ++i)
            if (strlen(layer[i]) == n && !strncmp(seg, layer[i], n))
                return 1;
        if (n >= 2 && (!strncmp(end - 2, "Id", 2) || !strncmp(end - 2, "ID", 2) ||
                       (n >= 3 && !strncmp(end - 3, "_id", 3))))
            return 1;
        if (n >= 6 && !strncasecmp(seg, "crypto", 6))
            return 1;
        seg = end + 1;
    }
    return 0;
}

/* Whether the colour of one of the plans is in part p. */
static int plan_in_part(const ef_channel_plan *plans, int nplans, int p)
{
    for (int k = 0; k < nplans; ++k)
        if (plans[k].rgb[0].part == p)
            return 1;
    return 0;
}

int ef_exr_named_type(const char *const *names, const int *types, int n, const char *name, int t)
{
    if (t == EXR_PIXEL_UINT)
        return t;
    const size_t len = strlen(name);
    for (int k = 0; k < n; ++k) {
        const char *e = strrchr(names[k], '=');
        if (e && (size_t) (e - names[k]) == len && !strncmp(names[k], name, len))
            t = types[k];
    }
    return t;
}

/* -d NAME=TYPE: the last override naming this channel wins; uint stays. */
static exr_pixel_type_t named_type(const ef_stream_opts *o, const char *name, exr_pixel_type_t t)
{
    return (exr_pixel_type_t) ef_exr_named_type(o->chan_type_name, o->chan_type, o->nchan_type,
                                                 name, (int) t);
}

static int define_part(const ef_exr_file *in, exr_context_t out, int p,
                       const char *const *extra, int nextra, const ef_channel_plan *plans,
                       int nplans, const ef_exr_file *df, const ef_stream_opts *o, ef_err *err)
{
    const int colour = nextra > 0 || (nplans > 0 && plan_in_part(plans, nplans, p));
    const char *name = NULL;
    exr_storage_t st;
    exr_compression_t comp;
    const exr_attr_chlist_t *cl;
    int op;
    exr_get_name(in->ctx, p, &name);
    exr_get_storage(in->ctx, p, &st);
    exr_get_compression(in->ctx, p, &comp);
    exr_get_channels(in->ctx, p, &cl);
    if (o->compression >= 0)
        comp = (exr_compression_t) o->compression;
    if (exr_add_part(out, name, st, &op) || op != p)
        return ef_fail(err, "cannot add output part %d: %s", p, ef_exr_last_core_message());
    if (st == EXR_STORAGE_TILED) {
        uint32_t tx, ty;
        exr_get_tile_descriptor(in->ctx, p, &tx, &ty, NULL, NULL);
        if (exr_set_tile_descriptor(out, p, tx, ty, EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN))
            return ef_fail(err, "cannot set the tile size of part %d", p);
    }
    for (int c = 0; c < cl->num_channels; ++c) {
        const exr_attr_chlist_entry_t *e = &cl->entries[c];
        exr_pixel_type_t t = e->pixel_type;
        int read_depth = o->depth_name && p == o->depth_part && !strcmp(e->name.str, o->depth_name);
        for (int k = 0; k < nplans; ++k)
            read_depth |= df == in && plans[k].depth.part == p && plans[k].depth.index == c;
        const int keep = o->pixel_type == EXR_PIXEL_HALF && (ef_data_channel(e->name.str) || read_depth);
        if (o->pixel_type >= 0 && t != EXR_PIXEL_UINT && !keep)
            t = (exr_pixel_type_t) o->pixel_type;
        t = named_type(o, e->name.str, t);
        if (exr_add_channel(out, p, e->name.str, t, e->p_linear ? EXR_PERCEPTUALLY_LINEAR
                                                                : EXR_PERCEPTUALLY_LOGARITHMIC,
                            1, 1))
            return ef_fail(err, "cannot add channel '%s'", e->name.str);
    }
    for (int c = 0; c < nextra; ++c) {
        const int data = o->extra_data ? o->extra_data[c] : ef_data_channel(extra[c]);
        const exr_pixel_type_t t =
            named_type(o, extra[c], o->pixel_type == EXR_PIXEL_HALF && !data ? EXR_PIXEL_HALF
                                                                              : EXR_PIXEL_FLOAT);
        if (exr_add_channel(out, p, extra[c], t, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1))
            return ef_fail(err, "cannot add channel '%s': %s", extra[c], ef_exr_last_core_message());
    }
    if (colour && o->has_origin_attr) {
        const exr_attr_v3d_t v = { .x = o->origin_attr[0], .y = o->origin_attr[1], .z = o->origin_attr[2] };
        if (exr_attr_set_v3d(out, p, "exrfog/aovOrigin", &v))
            return ef_fail(err, "cannot record exrfog/aovOrigin: %s", ef_exr_last_core_message());
    }
    if (exr_set_compression(out, p, comp) || exr_set_lineorder(out, p, EXR_LINEORDER_INCREASING_Y))
        return ef_fail(err, "cannot set compression of part %d", p);
    if (o->zip_level > 0 && exr_set_zip_compression_level(out, p, o->zip_level))
        return ef_fail(err, "cannot set the zip level of part %d", p);
    return ef_exr_copy_attrs(in, p, out, p, o->param_attr, o->history, err);
}

/* The depth must hold every colour pixel (it may hold more). */
static int check_depth_window(const ef_exr_file *in, const ef_exr_file *df,
                              const ef_channel_plan *plan, ef_err *err)
{
    exr_attr_box2i_t cw, dw;
    if (exr_get_data_window(in->ctx, plan->rgb[0].part, &cw) ||
        exr_get_data_window(df->ctx, plan->depth.part, &dw))
        return ef_fail(err, "cannot read the data windows");
    /* A depth that covers the colour's pixels (say the full frame beside a
     * cropped render) is read where the colour is: the reader fetches any
     * rectangle by absolute coordinates. */
    if (dw.min.x <= cw.min.x && dw.min.y <= cw.min.y && dw.max.x >= cw.max.x &&
        dw.max.y >= cw.max.y)
        return 0;
    ef_fail(err, "the depth data window (%d,%d)-(%d,%d) [%dx%d] does not cover the colour data "
                 "window (%d,%d)-(%d,%d) [%dx%d] of %s; the depth must hold every colour pixel "
                 "(re-render it, or give the depth of the whole frame)",
            dw.min.x, dw.min.y, dw.max.x, dw.max.y, dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1,
            cw.min.x, cw.min.y, cw.max.x, cw.max.y, cw.max.x - cw.min.x + 1, cw.max.y - cw.min.y + 1,
            in->path);
    err->file = df->path;
    return -1;
}

/* The halo's slots, if any. */
static void halo_free(part_job *j)
{
    if (j->halo_sync) {
        pthread_mutex_destroy(&j->halo_mx);
        pthread_cond_destroy(&j->halo_cv);
        j->halo_sync = 0;
    }
    for (int i = 0; j->slot && i < j->nslot; ++i) {
        pthread_mutex_destroy(&j->slot[i].lock);
        free(j->slot[i].rows);
        for (int k = 0; j->slot[i].pre && k < j->nch; ++k)
            free(j->slot[i].pre[k]);
        free(j->slot[i].pre);
    }
    free(j->slot);
    j->slot = NULL;
    j->nslot = 0;
}

static int run_part(const ef_exr_file *in, const ef_exr_file *df, exr_context_t out,
                    const char *out_path, int p, const ef_channel_plan *plans, int nplans,
                    const char *const *extra, int nx, const ef_stream_opts *o, ef_chunk_fn fn,
                    void *user, ef_stream_stats *stats, ef_err *err)
{
    part_job j;
    memset(&j, 0, sizeof j);
    j.in = in->ctx;
    j.out = out;
    j.in_path = in->path;
    j.depth_path = df->path;
    j.out_path = out_path;
    j.part = p;
    j.fn = fn;
    j.user = user;
    j.cancel = o->cancel;
    j.codec = o->codec;
    j.halo = o->halo;
    for (int k = 0; k < nplans; ++k)
        if (plans[k].rgb[0].part == p) {
            j.t[j.ntarget].plan = k;
            j.t[j.ntarget].pl = &plans[k];
            j.ntarget++;
        }
    j.nx = j.ntarget ? nx : 0;
    j.nextra = j.nx * j.ntarget;
    j.extra = extra;
    if (exr_get_scanlines_per_chunk(out, p, &j.out_rows) || j.out_rows < 1)
        j.out_rows = 1;
    if (geom_init(in->ctx, p, j.out_rows, &j.g))
        return ef_fail(err, "part %d: cannot read its chunk layout", p);
    /* --edges on a tiled part: a row of tiles per unit, so pixels at a
     * tile's border see their neighbours (a row of tiles holds at most
     * EF_UNIT_MAX_CHUNKS tiles: one output chunk each) */
    if (j.halo && j.g.tiled) {
        if (j.g.ntx > EF_UNIT_MAX_CHUNKS) {
            ef_fail(err, "part %d: a row of its tiles holds %d tiles, more than the %d "
                    "--edges can read at once; rewrite it as scanlines (oiiotool IN "
                    "--scanline -o OUT) or with larger tiles", p, j.g.ntx, EF_UNIT_MAX_CHUNKS);
            err->file = in->path;
            return -1;
        }
        geom_tile_rows(&j.g);
    }
    exr_get_channels(in->ctx, p, &j.cl);
    j.nch = j.cl->num_channels;
    j.as_float = calloc((size_t) j.nch, 1);
    if (!j.as_float)
        return ef_fail(err, "out of memory");
    for (int t = 0; t < j.ntarget; ++t) {
        const ef_channel_plan *plan = j.t[t].pl;
        for (int k = 0; k < 3; ++k)
            j.as_float[plan->rgb[k].index] = 1;
        if (plan->alpha.part >= 0)
            j.as_float[plan->alpha.index] = 1;
        j.t[t].depth_local = -1;
        if (df == in && plan->depth.part == p) {
            j.t[t].depth_local = plan->depth.index;
            j.as_float[plan->depth.index] = 1;
        } else {
            j.t[t].depth_ctx = df->ctx;
            j.t[t].depth_part = plan->depth.part;
        }
    }
    pthread_mutex_init(&j.lock, NULL);
    int nt = o->threads < 1 ? 1 : o->threads;
    if (nt > j.g.nunits)
        nt = j.g.nunits;
    {
        /* Memory per worker: a unit of every plane, decoded and packed,
         * and its share of the ring: ef_ring_slots(1) + 1 encoded units,
         * each at most the unit's raw size. */
        const uint64_t px = unit_pixels(&j.g);
        const uint64_t per = px * ((uint64_t) j.nch + (uint64_t) j.nextra + 1) * 4 *
                             (2 + (uint64_t) ef_ring_slots(1) + 1);
        const uint64_t fit = per ? EF_STREAM_BYTES / per : (uint64_t) nt;
        if ((uint64_t) nt > fit)
            nt = fit < 1 ? 1 : (int) fit;
    }
    int halo_ok = 1;
    if (j.halo) {
        pthread_mutex_init(&j.halo_mx, NULL);
        pthread_cond_init(&j.halo_cv, NULL);
        j.halo_sync = 1;
        j.nslot = 4 * nt + 4;
        j.slot = calloc((size_t) j.nslot, sizeof *j.slot);
        for (int i = 0; j.slot && i < j.nslot; ++i) {
            pthread_mutex_init(&j.slot[i].lock, NULL);
            j.slot[i].unit = -1;
            j.slot[i].pre_unit = -1;
            j.slot[i].rows = malloc((size_t) 2 * (size_t) j.ntarget * 5 * EF_STREAM_HALO *
                                    (size_t) j.g.width * sizeof(float));
            /* the decoded planes of a unit too, within 64 MB for all slots
             * (without them, the halo decodes its chunks itself) */
            j.pre_plane = unit_pixels(&j.g) * 4;
            if ((uint64_t) j.pre_plane * (uint64_t) j.nch * (uint64_t) j.nslot <= (64u << 20) &&
                (j.slot[i].pre = calloc((size_t) j.nch, sizeof *j.slot[i].pre)) != NULL)
                for (int k = 0; k < j.nch; ++k)
                    halo_ok &= (j.slot[i].pre[k] = malloc(j.pre_plane)) != NULL;
            halo_ok &= j.slot[i].rows != NULL;
        }
        if (!j.slot || !halo_ok) {
            if (!j.slot)
                j.nslot = 0;
            halo_free(&j);
            pthread_mutex_destroy(&j.lock);
            free(j.as_float);
            return ef_fail(err, "out of memory for the edges' rows");
        }
    }
    if (ef_ring_init(&j.ring, ef_ring_slots(nt), j.g.nunits, write_unit, &j)) {
        halo_free(&j);
        pthread_mutex_destroy(&j.lock);
        free(j.as_float);
        return ef_fail(err, "out of memory");
    }
    pthread_t *th = calloc((size_t) nt, sizeof *th);
    int started = 0;
    for (; th && started < nt; ++started)
        if (pthread_create(&th[started], NULL, worker, &j))
            break;
    if (started == 0)
        worker(&j);
    for (int i = 0; i < started; ++i)
        pthread_join(th[i], NULL);
    free(th);
    stats->wait_s += j.ring.wait_s;
    ef_ring_destroy(&j.ring);
    halo_free(&j);
    pthread_mutex_destroy(&j.lock);
    free(j.as_float);
    stats->decode_s += j.t_decode;
    stats->fog_s += j.t_fog;
    stats->encode_s += j.t_encode;
    stats->write_s += j.t_write;
    stats->units += j.g.nunits;
    if (j.failed) {
        *err = j.err;
        return -1;
    }
    return 0;
}

/* 1 when a part, attribute, type or channel name is longer than 31 bytes. */
static int has_long_names(const ef_exr_file *in)
{
    for (int p = 0; p < in->nparts; ++p) {
        int32_t na = 0;
        const exr_attr_chlist_t *cl;
        exr_get_attribute_count(in->ctx, p, &na);
        for (int32_t i = 0; i < na; ++i) {
            const exr_attribute_t *a;
            if (exr_get_attribute_by_index(in->ctx, p, EXR_ATTR_LIST_FILE_ORDER, i, &a) == 0 &&
                (a->name_length > 31 || a->type_name_length > 31))
                return 1;
        }
        if (exr_get_channels(in->ctx, p, &cl) == 0)
            for (int c = 0; c < cl->num_channels; ++c)
                if (cl->entries[c].name.length > 31)
                    return 1;
    }
    return 0;
}

/* The extra channels of part p: those of every plan whose colour is
 * there, in plan order (run_part finds target t's at t * nextra).
 * Returns how many. */
static int part_extras(const ef_channel_plan *plan, int nplans, int p,
                       const char *(*xname)[EF_MAX_EXTRA_CHANNELS], int nextra,
                       const char **out)
{
    int n = 0;
    for (int k = 0; k < nplans; ++k)
        if (plan[k].rgb[0].part == p)
            for (int c = 0; c < nextra; ++c)
                out[n++] = xname[k][c];
    return n;
}

static int stream_named(const ef_exr_file *in, const ef_exr_file *df, const ef_channel_plan *plan,
                        int nplans, char (*names)[EF_MAX_EXTRA_CHANNELS][192],
                        const char *(*xname)[EF_MAX_EXTRA_CHANNELS], const char *out_path,
                        int out_fd, const ef_stream_opts *o, ef_chunk_fn fn, void *user,
                        ef_stream_stats *stats, double t0, ef_err *err);

int ef_exr_stream(const ef_exr_file *in, const ef_exr_file *df, const ef_channel_plan *plan,
                  const char *out_path, int out_fd, const ef_stream_opts *o, ef_chunk_fn fn, void *user,
                  ef_stream_stats *stats, ef_err *err)
{
    double t0 = ef_now();
    memset(stats, 0, sizeof *stats);
    const int nplans = o->nplans > 0 ? o->nplans : 1;
    if (nplans > EF_MAX_VIEWS)
        return ef_fail(err, "internal error: %d views (at most %d)", nplans, EF_MAX_VIEWS);
    if (o->nextra < 0 || o->nextra > EF_MAX_EXTRA_CHANNELS)
        return ef_fail(err, "internal error: %d extra channels (at most %d)", o->nextra,
                       EF_MAX_EXTRA_CHANNELS);
    /* Each plan's extra channels, named with its view where the file
     * names a view's channels that way (fog.R -> fog.left.R); on the heap
     * (a light's layers make many). */
    char(*names)[EF_MAX_EXTRA_CHANNELS][192] = calloc((size_t) nplans, sizeof *names);
    const char *(*xname)[EF_MAX_EXTRA_CHANNELS] = calloc((size_t) nplans, sizeof *xname);
    if (!names || !xname) {
        free(names);
        free(xname);
        return ef_fail(err, "out of memory");
    }
    int rc = stream_named(in, df, plan, nplans, names, xname, out_path, out_fd, o, fn, user, stats,
                          t0, err);
    free(names);
    free(xname);
    return rc;
}

/* ef_exr_stream with the extra channels' name tables allocated. */
static int stream_named(const ef_exr_file *in, const ef_exr_file *df, const ef_channel_plan *plan,
                        int nplans, char (*names)[EF_MAX_EXTRA_CHANNELS][192],
                        const char *(*xname)[EF_MAX_EXTRA_CHANNELS], const char *out_path,
                        int out_fd, const ef_stream_opts *o, ef_chunk_fn fn, void *user,
                        ef_stream_stats *stats, double t0, ef_err *err)
{
    exr_context_initializer_t init;
    exr_context_t out = NULL;
    for (int k = 0; k < nplans; ++k) {
        if (check_depth_window(in, df, &plan[k], err))
            return -1;
        for (int c = 0; c < o->nextra; ++c) {
            const char *e = o->extra[c], *dot = strrchr(e, '.');
            if (plan[k].chan_view[0] && dot)
                snprintf(names[k][c], sizeof names[k][c], "%.*s.%s%s", (int) (dot - e), e,
                         plan[k].chan_view, dot);
            else if (plan[k].chan_view[0])
                snprintf(names[k][c], sizeof names[k][c], "%s.%s", plan[k].chan_view, e);
            else
                snprintf(names[k][c], sizeof names[k][c], "%s", e);
            xname[k][c] = names[k][c];
        }
        const char *clash = ef_exr_part_has_any(in, plan[k].rgb[0].part, xname[k], o->nextra);
        if (clash)
            return ef_fail(err, "part %d already has a channel '%s'", plan[k].rgb[0].part, clash);
    }
    ef_exr_init_context(&init);
    ef_exr_sink sink = { out_fd, 0 };
    init.user_data = &sink;
    init.write_fn = ef_exr_sink_write;
    if (exr_start_write(&out, out_path, EXR_WRITE_FILE_DIRECTLY, &init)) {
        ef_fail(err, "cannot create the output: %s", ef_exr_last_core_message());
        err->file = out_path;
        return -1;
    }
    /* Names longer than 31 bytes (Blender view layers, renderer metadata,
     * an AOV of a light with a long name) are legal with the long-names
     * flag; the reader accepted them. */
    int longn = has_long_names(in);
    for (int k = 0; k < nplans && !longn; ++k)
        for (int c = 0; c < o->nextra; ++c)
            longn |= strlen(xname[k][c]) > 31;
    if (longn && exr_set_longname_support(out, 1)) {
        exr_finish(&out);
        ef_fail(err, "cannot enable long names: %s", ef_exr_last_core_message());
        err->file = out_path;
        return -1;
    }
    const char **part_extra = calloc((size_t) nplans * (size_t) (o->nextra + 1), sizeof *part_extra);
    if (!part_extra) {
        exr_finish(&out);
        return ef_fail(err, "out of memory");
    }
    int rc = 0;
    for (int p = 0; p < in->nparts && !rc; ++p) {
        const int n = part_extras(plan, nplans, p, xname, o->nextra, part_extra);
        /* a deep part beside the fogged ones goes through as it is */
        rc = ef_exr_part_is_deep(in, p)
                 ? ef_exr_define_part_copy(in, p, out, o->history, o->param_attr, err)
                 : define_part(in, out, p, part_extra, n, plan, nplans, df, o, err);
    }
    if (!rc && exr_write_header(out))
        rc = ef_fail(err, "cannot write the output header: %s", ef_exr_last_core_message());
    for (int p = 0; p < in->nparts && !rc; ++p) {
        part_extras(plan, nplans, p, xname, o->nextra, part_extra);
        rc = ef_exr_part_is_deep(in, p)
                 ? ef_exr_copy_part_chunks(in, p, out, err)
                 : run_part(in, df, out, out_path, p, plan, nplans, part_extra, o->nextra, o, fn,
                            user, stats, err);
    }
    free(part_extra);
    if (exr_finish(&out) && !rc)
        rc = ef_fail(err, "cannot finish the output: %s", ef_exr_last_core_message());
    if (rc && sink.errnum) {
        /* The system's reason beats Core's generic one. */
        ef_fail(err, "cannot write the output: %s%s", strerror(sink.errnum),
                sink.errnum == ENOSPC   ? " (free some space, or write elsewhere)"
                : sink.errnum == EFBIG  ? " (a file size limit: see ulimit -f)"
                : sink.errnum == EDQUOT ? " (over the disk quota)"
                                        : "");
    }
    if (rc && (sink.errnum || !err->file))
        err->file = out_path;
    stats->wall_s = ef_now() - t0;
    return rc;
}

int ef_exr_stream_file(const ef_exr_file *in, const ef_exr_file *df, const ef_channel_plan *plan,
                       const char *path, const ef_stream_opts *o, ef_chunk_fn fn, void *user,
                       ef_stream_stats *stats, ef_err *err)
{
    const int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (fd < 0) {
        ef_fail(err, "cannot create the output: %s", strerror(errno));
        err->file = path;
        return -1;
    }
    int rc = ef_exr_stream(in, df, plan, path, fd, o, fn, user, stats, err);
    if (close(fd) && !rc) {
        rc = ef_fail(err, "cannot write the output: %s", strerror(errno));
        err->file = path;
    }
    if (rc)
        unlink(path);
    return rc;
}

const char *ef_exr_part_has_any(const ef_exr_file *f, int part, const char *const *names, int n)
{
    const exr_attr_chlist_t *cl;
    if (exr_get_channels(f->ctx, part, &cl))
        return NULL;
    for (int i = 0; i < n; ++i)
        for (int c = 0; c < cl->num_channels; ++c)
            if (!strcmp(cl->entries[c].name.str, names[i]))
                return names[i];
    return NULL;
}

static const char *const comp_names[] = { "none", "rle", "zips", "zip", "piz",
                                          "pxr24", "b44", "b44a", "dwaa", "dwab" };

int ef_compression_parse(const char *text, int *compression, int *level, float *dwa_level,
                         ef_err *err)
{
    char name[16];
    const char *colon = strchr(text, ':');
    size_t len = colon ? (size_t) (colon - text) : strlen(text);
    *level = -1;
    *dwa_level = -1.0f;
    if (len >= sizeof name)
        len = sizeof name - 1;
    memcpy(name, text, len);
    name[len] = '\0';
    for (int i = 0; i < (int) (sizeof comp_names / sizeof comp_names[0]); ++i) {
        if (strcmp(name, comp_names[i]))
            continue;
        const int dwa = i == EXR_COMPRESSION_DWAA || i == EXR_COMPRESSION_DWAB;
        if (dwa)
            *dwa_level = 45.0f;   /* the library's default, as oiiotool */
        if (colon && dwa) {
            char *end;
            errno = 0;
            double l = strtod(colon + 1, &end);
            if (colon[1] == '\0' || *end || errno || !(l > 0) || l > 1e6)
                return ef_fail(err, "--compression '%s': the DWA level must be a positive "
                                    "number (45 by default; higher is smaller and lossier), "
                                    "e.g. %s:45", text, comp_names[i]);
            *dwa_level = (float) l;
        } else if (colon) {
            char *end;
            errno = 0;
            long l = strtol(colon + 1, &end, 10);
            if (i != EXR_COMPRESSION_ZIP && i != EXR_COMPRESSION_ZIPS)
                return ef_fail(err, "--compression '%s': only zip and zips (zlib level, from 1 "
                                    "(fastest) to 9 (smallest)) and dwaa and dwab (a positive "
                                    "quantisation level, 45 by default) take a level", text);
            if (colon[1] == '\0' || *end)
                return ef_fail(err, "--compression '%s': the zlib level is not a whole number "
                                    "(1 fastest to 9 smallest, e.g. %s:6)", text, comp_names[i]);
            if (errno || l < 1 || l > 9)
                return ef_fail(err, "--compression '%s': the zlib level %s is out of range "
                                    "(1 fastest to 9 smallest, e.g. %s:6)", text, colon + 1,
                               comp_names[i]);
            *level = (int) l;
        }
        *compression = i;
        return 0;
    }
    return ef_fail(err, "--compression '%s' is not one of none, rle, zips, zip, piz, pxr24, b44, "
                        "b44a, dwaa, dwab (zip and zips take :LEVEL, 1-9; dwaa and dwab take "
                        ":LEVEL, a positive number, 45 by default)", text);
}

