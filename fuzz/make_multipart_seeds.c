/* Writes the multi-part seeds oiiotool cannot make: colour and depth in
 * separate parts with different storage, chunk heights, tile sizes and
 * depth types, so the fuzzer starts inside exrfog's depth reader (depth
 * decoded from another part, chunk by chunk, with its cache).
 *
 *   make_multipart_seeds OUTDIR
 *
 * Built and run by fuzz/make_corpus.sh. */
#include <openexr.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct part_spec {
    const char *name;         /* part name */
    const char *view;         /* "view" attribute or NULL */
    int tiled, tw, th;
    exr_compression_t comp;
    const char *chans;        /* comma-separated; suffix ':h' half, ':u' uint, else float */
    int camera;               /* 1: worldToCamera + CameraFov */
} part_spec;

typedef struct seed {
    const char *file;
    int x0, y0, w, h;         /* data window (display window is 0,0 - 31,17) */
    int nparts;
    part_spec parts[3];
} seed;

static const seed seeds[] = {
    { "mp_piz_rgb__rle_depth.exr", 0, 0, 24, 40, 2,
      { { "rgba", NULL, 0, 0, 0, EXR_COMPRESSION_PIZ, "R:h,G:h,B:h", 1 },
        { "depth", NULL, 0, 0, 0, EXR_COMPRESSION_RLE, "Z", 0 } } },
    { "mp_tiled8_rgba__zip_depth.exr", 2, 1, 21, 19, 2,
      { { "rgba", NULL, 1, 8, 8, EXR_COMPRESSION_ZIP, "A:h,B:h,G:h,R:h", 0 },
        { "depth", NULL, 0, 0, 0, EXR_COMPRESSION_ZIP, "Z", 0 } } },
    { "mp_zips_rgb__tiled5x3_uintdepth.exr", -3, -2, 17, 11, 2,
      { { "rgba", NULL, 0, 0, 0, EXR_COMPRESSION_ZIPS, "R,G,B", 1 },
        { "depth", NULL, 1, 5, 3, EXR_COMPRESSION_NONE, "Z:u,id:u", 0 } } },
    { "mp_views_pxr24.exr", 0, 0, 16, 9, 3,
      { { "rgba.left", "left", 0, 0, 0, EXR_COMPRESSION_PXR24, "R:h,G:h,B:h,A:h", 1 },
        { "depth.left", "left", 1, 64, 64, EXR_COMPRESSION_B44, "Z:h", 0 },
        { "depth.right", "right", 0, 0, 0, EXR_COMPRESSION_RLE, "Z", 0 } } },
};

#define CHK(call)                                                                    \
    do {                                                                             \
        exr_result_t rv_ = (call);                                                   \
        if (rv_ != EXR_ERR_SUCCESS) {                                                \
            fprintf(stderr, "make_multipart_seeds: %s: %s failed: %s\n", s->file,    \
                    #call, exr_get_error_code_as_string(rv_));                       \
            goto fail;                                                               \
        }                                                                            \
    } while (0)

static int parse_chans(const char *spec, char names[8][32], exr_pixel_type_t types[8])
{
    int n = 0;
    const char *p = spec;
    while (*p && n < 8) {
        size_t len = strcspn(p, ",");
        char tok[40];
        snprintf(tok, sizeof tok, "%.*s", (int) len, p);
        types[n] = EXR_PIXEL_FLOAT;
        char *colon = strchr(tok, ':');
        if (colon) {
            types[n] = colon[1] == 'h' ? EXR_PIXEL_HALF : EXR_PIXEL_UINT;
            *colon = '\0';
        }
        snprintf(names[n], 32, "%s", tok);
        ++n;
        p += len + (p[len] == ',');
    }
    return n;
}

/* A value per channel and pixel: colour ramps, depth 1..50, sky at one corner. */
static void fill(uint8_t *buf, exr_pixel_type_t t, const char *name, int x, int y, int w, int h)
{
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i) {
            int px = x + i, py = y + j;
            float v;
            if (!strcmp(name, "Z"))
                v = (px < 0 && py < 0) ? 1e10f : 1.0f + (float) ((px * 7 + py * 13) & 31) * 1.5f;
            else if (!strcmp(name, "A"))
                v = ((px + py) & 3) ? 1.0f : 0.5f;
            else
                v = (float) ((px * 3 + py * 5 + name[0]) & 15) / 15.0f;
            size_t k = (size_t) j * (size_t) w + (size_t) i;
            if (t == EXR_PIXEL_UINT)
                ((uint32_t *) buf)[k] = (uint32_t) (v < 4e9f ? v : 0);
            else
                ((float *) buf)[k] = v;
        }
}

static int write_seed(const char *dir, const seed *s)
{
    char path[1024];
    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int started = 0;
    uint8_t *planes[8] = { 0 };
    snprintf(path, sizeof path, "%s/%s", dir, s->file);
    CHK(exr_start_write(&f, path, EXR_WRITE_FILE_DIRECTLY, &init));
    for (int p = 0; p < s->nparts; ++p) {
        const part_spec *ps = &s->parts[p];
        char names[8][32];
        exr_pixel_type_t types[8];
        int n = parse_chans(ps->chans, names, types), idx;
        exr_attr_box2i_t dw, disp;
        exr_attr_v2f_t swc;
        dw.min.x = s->x0;
        dw.min.y = s->y0;
        dw.max.x = s->x0 + s->w - 1;
        dw.max.y = s->y0 + s->h - 1;
        disp.min.x = disp.min.y = 0;
        disp.max.x = 31;
        disp.max.y = 17;
        swc.x = swc.y = 0.f;
        CHK(exr_add_part(f, ps->name, ps->tiled ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE, &idx));
        CHK(exr_initialize_required_attr(f, idx, &disp, &dw, 1.f, &swc, 1.f,
                                         EXR_LINEORDER_INCREASING_Y, ps->comp));
        if (ps->tiled)
            CHK(exr_set_tile_descriptor(f, idx, (uint32_t) ps->tw, (uint32_t) ps->th,
                                        EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN));
        for (int c = 0; c < n; ++c)
            CHK(exr_add_channel(f, idx, names[c], types[c], EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1));
        if (ps->view)
            CHK(exr_attr_set_string(f, idx, "view", ps->view));
        if (ps->camera) {
            exr_attr_m44f_t id = { { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 } };
            CHK(exr_attr_set_m44f(f, idx, "worldToCamera", &id));
            CHK(exr_attr_set_float(f, idx, "CameraFov", 45.f));
        }
    }
    CHK(exr_write_header(f));
    for (int p = 0; p < s->nparts; ++p) {
        const part_spec *ps = &s->parts[p];
        char names[8][32];
        exr_pixel_type_t types[8];
        int n = parse_chans(ps->chans, names, types);
        int cw = ps->tiled ? ps->tw : s->w, ch;
        if (ps->tiled)
            ch = ps->th;
        else
            CHK(exr_get_scanlines_per_chunk(f, p, &ch));
        int ntx = ps->tiled ? (s->w + cw - 1) / cw : 1, nty = (s->h + ch - 1) / ch;
        for (int c = 0; c < n; ++c)
            if (!(planes[c] = malloc((size_t) cw * (size_t) ch * 4)))
                goto fail;
        for (int ty = 0; ty < nty; ++ty)
            for (int tx = 0; tx < ntx; ++tx) {
                exr_chunk_info_t ci;
                if (ps->tiled)
                    CHK(exr_write_tile_chunk_info(f, p, tx, ty, 0, 0, &ci));
                else
                    CHK(exr_write_scanline_chunk_info(f, p, s->y0 + ty * ch, &ci));
                if (!started)
                    CHK(exr_encoding_initialize(f, p, &ci, &enc));
                else
                    CHK(exr_encoding_update(f, p, &ci, &enc));
                for (int c = 0; c < enc.channel_count; ++c) {
                    exr_coding_channel_info_t *cc = &enc.channels[c];
                    int k = 0;
                    while (k < n && strcmp(names[k], cc->channel_name))
                        ++k;
                    fill(planes[k], types[k] == EXR_PIXEL_UINT ? EXR_PIXEL_UINT : EXR_PIXEL_FLOAT,
                         names[k], s->x0 + tx * cw, ci.start_y, ci.width, ci.height);
                    cc->encode_from_ptr = planes[k];
                    cc->user_data_type =
                        types[k] == EXR_PIXEL_UINT ? EXR_PIXEL_UINT : EXR_PIXEL_FLOAT;
                    cc->user_bytes_per_element = 4;
                    cc->user_pixel_stride = 4;
                    cc->user_line_stride = 4 * ci.width;
                }
                if (!started)
                    CHK(exr_encoding_choose_default_routines(f, p, &enc));
                started = 1;
                CHK(exr_encoding_run(f, p, &enc));
            }
        CHK(exr_encoding_destroy(f, &enc));
        started = 0;
        for (int c = 0; c < n; ++c) {
            free(planes[c]);
            planes[c] = NULL;
        }
    }
    CHK(exr_finish(&f));
    return 0;
fail:
    if (started)
        exr_encoding_destroy(f, &enc);
    for (int c = 0; c < 8; ++c)
        free(planes[c]);
    if (f)
        exr_finish(&f);
    return 1;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: make_multipart_seeds OUTDIR\n");
        return 2;
    }
    int rc = 0;
    for (size_t i = 0; i < sizeof seeds / sizeof seeds[0]; ++i)
        rc |= write_seed(argv[1], &seeds[i]);
    return rc;
}
