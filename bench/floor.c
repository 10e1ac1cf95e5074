/* floor: the physical floor of exrfog's job, a transcode through
 * OpenEXRCore alone. Every chunk of every part of IN is read, decompressed,
 * unpacked into planes of its own pixel types, packed, compressed again
 * (the input's compression, or --compression) and written to OUT in chunk
 * order, on N threads, with no per-pixel work. The pixels of OUT are those
 * of IN. ZIP/ZIPS go through stock zlib (OpenEXRCore's) or libdeflate
 * (--codec, as exrfog's), and the write order uses exrfog's ring, so the
 * floor and exrfog differ only in the fog pass and their planes.
 *
 * usage: floor [--threads N] [--compression NAME[:LEVEL]] [--codec zlib|libdeflate]
 *              [--stats] IN OUT
 *
 * Flat single-level images only (scanline or one-level tiles), as exrfog. */
#include "exr_deflate.h"
#include "exr_ring.h"

#include <openexr.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct floor_part {
    exr_const_context_t in;
    exr_context_t out;
    int part, tiled, codec;
    exr_attr_box2i_t dw;
    int lines, tw, th, ntx;
    int nchunks;
    ef_ring ring;
    pthread_mutex_t lock;
    int failed;
    char msg[256];
} floor_part;

static void part_fail(floor_part *j, const char *what, int chunk)
{
    pthread_mutex_lock(&j->lock);
    if (!j->failed)
        snprintf(j->msg, sizeof j->msg, "part %d, chunk %d: %s", j->part, chunk, what);
    j->failed = 1;
    pthread_mutex_unlock(&j->lock);
    ef_ring_fail(&j->ring);
}

/* Chunk c of the part: its read and write infos, and its write key. */
static int chunk_infos(floor_part *j, int c, exr_chunk_info_t *ri, exr_chunk_info_t *wi, int *ky,
                       int *kty)
{
    if (j->tiled) {
        const int tx = c % j->ntx, ty = c / j->ntx;
        *ky = tx;
        *kty = ty;
        return exr_read_tile_chunk_info(j->in, j->part, tx, ty, 0, 0, ri) ||
               exr_write_tile_chunk_info(j->out, j->part, tx, ty, 0, 0, wi);
    }
    const int y = j->dw.min.y + c * j->lines;
    *ky = y;
    *kty = 0;
    return exr_read_scanline_chunk_info(j->in, j->part, y, ri) ||
           exr_write_scanline_chunk_info(j->out, j->part, y, wi);
}

/* Points every channel of a pipeline at its plane of buf (planar, rows of
 * width elements of the channel's own type). */
static void bind_planes(exr_coding_channel_info_t *chs, int n, uint8_t *buf, int decode)
{
    size_t off = 0;
    for (int c = 0; c < n; ++c) {
        exr_coding_channel_info_t *ch = &chs[c];
        if (decode)
            ch->decode_to_ptr = buf + off;
        else
            ch->encode_from_ptr = buf + off;
        ch->user_data_type = ch->data_type;
        ch->user_bytes_per_element = ch->bytes_per_element;
        ch->user_pixel_stride = ch->bytes_per_element;
        ch->user_line_stride = ch->width * ch->bytes_per_element;
        off += (size_t) ch->width * (size_t) ch->height * (size_t) ch->bytes_per_element;
    }
}

static int write_chunk(void *arg, int u, const ef_unit_buf *b)
{
    floor_part *j = arg;
    if (ef_unit_write(j->out, j->part, j->tiled, b)) {
        part_fail(j, "cannot write", u);
        return -1;
    }
    return 0;
}

static void *worker(void *arg)
{
    floor_part *j = arg;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int dready = 0, eready = 0;
    uint8_t *planes = NULL;
    size_t cap = 0;
    ef_unit_buf ob = { 0 };
    for (;;) {
        const int c = ef_ring_claim(&j->ring);
        if (c < 0)
            break;
        exr_chunk_info_t ri, wi;
        int ky, kty;
        if (chunk_infos(j, c, &ri, &wi, &ky, &kty)) {
            part_fail(j, "bad chunk table", c);
            break;
        }
        if (ri.unpacked_size > cap) {
            free(planes);
            cap = (size_t) ri.unpacked_size;
            if (!(planes = malloc(cap))) {
                part_fail(j, "out of memory", c);
                break;
            }
        }
        exr_result_t rv = dready ? exr_decoding_update(j->in, j->part, &ri, &dec)
                                 : exr_decoding_initialize(j->in, j->part, &ri, &dec);
        const int dfirst = !dready;
        dready = 1;
        if (!rv) {
            bind_planes(dec.channels, dec.channel_count, planes, 1);
            if (dfirst)
                rv = exr_decoding_choose_default_routines(j->in, j->part, &dec) ||
                     (j->codec == EF_CODEC_LIBDEFLATE &&
                      ef_deflate_decoding_setup(j->in, j->part, &dec));
        }
        if (rv || exr_decoding_run(j->in, j->part, &dec)) {
            part_fail(j, "cannot decode", c);
            break;
        }
        rv = eready ? exr_encoding_update(j->out, j->part, &wi, &enc)
                    : exr_encoding_initialize(j->out, j->part, &wi, &enc);
        if (!rv) {
            bind_planes(enc.channels, enc.channel_count, planes, 0);
            if (!eready) {
                eready = 1;
                rv = exr_encoding_choose_default_routines(j->out, j->part, &enc) ||
                     (j->codec == EF_CODEC_LIBDEFLATE &&
                      ef_deflate_encoding_setup(j->out, j->part, &enc));
                enc.write_fn = NULL;
                enc.yield_until_ready_fn = NULL;
            }
        }
        if (rv || exr_encoding_run(j->out, j->part, &enc)) {
            part_fail(j, "cannot encode", c);
            break;
        }
        const int raw = !enc.compressed_buffer || enc.compressed_bytes >= enc.packed_bytes;
        if (ef_unit_append(&ob, raw ? enc.packed_buffer : enc.compressed_buffer,
                           raw ? enc.packed_bytes : enc.compressed_bytes, ky, kty)) {
            part_fail(j, "out of memory", c);
            break;
        }
        if (ef_ring_put(&j->ring, c, &ob))
            break;
    }
    if (dready)
        ef_deflate_decoding_destroy(j->in, &dec);
    if (eready)
        ef_deflate_encoding_destroy(j->out, &enc);
    ef_unit_free(&ob);
    free(planes);
    return NULL;
}

static const char *const comp_names[] = { "none", "rle", "zips", "zip", "piz",
                                          "pxr24", "b44", "b44a", "dwaa", "dwab" };

static int parse_compression(const char *s, int *comp, int *level)
{
    const char *colon = strchr(s, ':');
    const size_t n = colon ? (size_t) (colon - s) : strlen(s);
    for (int i = 0; i < (int) (sizeof comp_names / sizeof comp_names[0]); ++i)
        if (strlen(comp_names[i]) == n && !strncmp(s, comp_names[i], n)) {
            *comp = i;
            *level = colon ? atoi(colon + 1) : -1;
            return colon && (*level < 1 || *level > 9) ? -1 : 0;
        }
    return -1;
}

/* Declares output part p like input part p (compression comp unless < 0). */
static int define_part(exr_const_context_t in, exr_context_t out, int p, int comp, int level)
{
    const char *name = NULL;
    exr_storage_t st;
    exr_compression_t c;
    const exr_attr_chlist_t *cl;
    int op;
    exr_get_name(in, p, &name);
    if (exr_get_storage(in, p, &st) || exr_get_compression(in, p, &c) ||
        exr_get_channels(in, p, &cl) || exr_add_part(out, name, st, &op))
        return -1;
    if (st != EXR_STORAGE_SCANLINE && st != EXR_STORAGE_TILED)
        return -1;
    if (st == EXR_STORAGE_TILED) {
        uint32_t tx, ty;
        exr_tile_level_mode_t lm;
        if (exr_get_tile_descriptor(in, p, &tx, &ty, &lm, NULL) || lm != EXR_TILE_ONE_LEVEL ||
            exr_set_tile_descriptor(out, op, tx, ty, EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN))
            return -1;
    }
    for (int k = 0; k < cl->num_channels; ++k) {
        const exr_attr_chlist_entry_t *e = &cl->entries[k];
        if (exr_add_channel(out, op, e->name.str, e->pixel_type, e->p_linear, e->x_sampling,
                            e->y_sampling))
            return -1;
    }
    if (exr_set_compression(out, op, comp >= 0 ? (exr_compression_t) comp : c) ||
        exr_set_lineorder(out, op, EXR_LINEORDER_INCREASING_Y) ||
        (level > 0 && exr_set_zip_compression_level(out, op, level)) ||
        exr_copy_unset_attributes(out, op, in, p))
        return -1;
    /* Chunk for chunk: the output must chunk scanlines as the input does. */
    static const int lines[] = { 1, 1, 1, 16, 32, 16, 32, 32, 32, 256 };
    const int oc = comp >= 0 ? comp : (int) c;
    int32_t li = 1;
    if (st == EXR_STORAGE_SCANLINE &&
        (exr_get_scanlines_per_chunk(in, p, &li) || oc < 0 || oc > 9 || li != lines[oc])) {
        fprintf(stderr, "floor: part %d: --compression must keep the input's %d scanlines per "
                        "chunk\n", p, li);
        return -1;
    }
    return 0;
}

static int run_part(exr_const_context_t in, exr_context_t out, int p, int threads, int codec,
                    double *wait)
{
    floor_part j;
    memset(&j, 0, sizeof j);
    j.in = in;
    j.out = out;
    j.part = p;
    j.codec = codec;
    exr_storage_t st;
    if (exr_get_storage(in, p, &st) || exr_get_data_window(in, p, &j.dw))
        return -1;
    j.tiled = st == EXR_STORAGE_TILED;
    if (j.tiled) {
        uint32_t tx, ty;
        exr_get_tile_descriptor(in, p, &tx, &ty, NULL, NULL);
        j.tw = (int) tx;
        j.th = (int) ty;
        j.ntx = (j.dw.max.x - j.dw.min.x + j.tw) / j.tw;
        j.nchunks = j.ntx * ((j.dw.max.y - j.dw.min.y + j.th) / j.th);
    } else {
        if (exr_get_scanlines_per_chunk(in, p, &j.lines))
            return -1;
        j.nchunks = (j.dw.max.y - j.dw.min.y + j.lines) / j.lines;
    }
    if (threads > j.nchunks)
        threads = j.nchunks;
    if (ef_ring_init(&j.ring, ef_ring_slots(threads), j.nchunks, write_chunk, &j))
        return -1;
    pthread_mutex_init(&j.lock, NULL);
    pthread_t th[64];
    int started = 0;
    for (; started < threads && started < 64; ++started)
        if (pthread_create(&th[started], NULL, worker, &j))
            break;
    if (started == 0)
        worker(&j);
    for (int i = 0; i < started; ++i)
        pthread_join(th[i], NULL);
    *wait += j.ring.wait_s;
    ef_ring_destroy(&j.ring);
    pthread_mutex_destroy(&j.lock);
    if (j.failed)
        fprintf(stderr, "floor: %s\n", j.msg);
    return j.failed ? -1 : 0;
}

static void usage(FILE *f)
{
    fprintf(f, "usage: floor [--threads N] [--compression NAME[:LEVEL]] [--codec zlib|libdeflate] "
               "[--stats] IN OUT\n");
}

int main(int argc, char **argv)
{
    int threads = (int) sysconf(_SC_NPROCESSORS_ONLN), comp = -1, level = -1;
    int codec = EF_CODEC_LIBDEFLATE, stats = 0, a = 1;
    for (; a < argc && !strncmp(argv[a], "--", 2); ++a) {
        const char *o = argv[a], *v = a + 1 < argc ? argv[a + 1] : NULL;
        if (!strcmp(o, "--stats")) {
            stats = 1;
        } else if (!strcmp(o, "--threads") && v) {
            threads = atoi(v);
            ++a;
        } else if (!strcmp(o, "--compression") && v && !parse_compression(v, &comp, &level)) {
            ++a;
        } else if (!strcmp(o, "--codec") && v && (!strcmp(v, "zlib") || !strcmp(v, "libdeflate"))) {
            codec = !strcmp(v, "zlib") ? EF_CODEC_ZLIB : EF_CODEC_LIBDEFLATE;
            ++a;
        } else {
            usage(stderr);
            return 2;
        }
    }
    if (argc - a != 2 || threads < 1) {
        usage(stderr);
        return 2;
    }
    const double t0 = ef_now();
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_context_t in = NULL, out = NULL;
    int nparts = 0, rc = 0;
    double wait = 0;
    if (exr_start_read(&in, argv[a], &init) || exr_get_count(in, &nparts)) {
        fprintf(stderr, "floor: cannot read %s\n", argv[a]);
        return 1;
    }
    if (exr_start_write(&out, argv[a + 1], EXR_WRITE_FILE_DIRECTLY, &init)) {
        fprintf(stderr, "floor: cannot create %s\n", argv[a + 1]);
        exr_finish(&in);
        return 1;
    }
    for (int p = 0; p < nparts && !rc; ++p)
        if (define_part(in, out, p, comp, level)) {
            fprintf(stderr, "floor: cannot declare part %d (flat, single-level parts only)\n", p);
            rc = 1;
        }
    if (!rc && exr_write_header(out)) {
        fprintf(stderr, "floor: cannot write the header\n");
        rc = 1;
    }
    for (int p = 0; p < nparts && !rc; ++p)
        rc = run_part(in, out, p, threads, codec, &wait) ? 1 : 0;
    if (exr_finish(&out) && !rc) {
        fprintf(stderr, "floor: cannot finish %s\n", argv[a + 1]);
        rc = 1;
    }
    exr_finish(&in);
    if (rc)
        unlink(argv[a + 1]);
    else if (stats)
        fprintf(stderr, "floor: wall %.3f s, %d threads, ring wait %.3f s\n", ef_now() - t0, threads,
                wait);
    return rc;
}
