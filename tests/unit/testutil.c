#include "testutil.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

void tu_part_init(tu_part *p, int w, int h)
{
    memset(p, 0, sizeof *p);
    p->dw[2] = p->disp[2] = w - 1;
    p->dw[3] = p->disp[3] = h - 1;
    p->comp = EXR_COMPRESSION_ZIP;
}

void tu_part_add(tu_part *p, const char *name, exr_pixel_type_t type, const float *plane)
{
    p->ch[p->nch] = name;
    p->type[p->nch] = type;
    p->plane[p->nch] = plane;
    p->uplane[p->nch] = NULL;
    p->nch++;
}

void tu_part_add_uint(tu_part *p, const char *name, const uint32_t *plane)
{
    p->ch[p->nch] = name;
    p->type[p->nch] = EXR_PIXEL_UINT;
    p->plane[p->nch] = NULL;
    p->uplane[p->nch] = plane;
    p->nch++;
}

static int write_part_pixels(exr_context_t f, int pi, const tu_part *p)
{
    int w = p->dw[2] - p->dw[0] + 1, h = p->dw[3] - p->dw[1] + 1;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int first = 1, rv = 0;
    int32_t lpc = 1;
    int tw = p->tile ? p->tile : w;
    if (!p->tile)
        exr_get_scanlines_per_chunk(f, pi, &lpc);
    int th = p->tile ? (p->tile_h ? p->tile_h : p->tile) : lpc;
    for (int ty = 0; ty * th < h && !rv; ++ty)
        for (int tx = 0; tx * tw < w && !rv; ++tx) {
            exr_chunk_info_t ci;
            rv = p->tile ? exr_write_tile_chunk_info(f, pi, tx, ty, 0, 0, &ci)
                         : exr_write_scanline_chunk_info(f, pi, p->dw[1] + ty * th, &ci);
            if (rv)
                break;
            rv = first ? exr_encoding_initialize(f, pi, &ci, &enc) : exr_encoding_update(f, pi, &ci, &enc);
            if (rv)
                break;
            for (int c = 0; c < enc.channel_count; ++c) {
                int k = 0;
                while (k < p->nch && strcmp(p->ch[k], enc.channels[c].channel_name))
                    ++k;
                const size_t at = (size_t) ty * th * w + (size_t) tx * tw;
                if (p->uplane[k]) {
                    enc.channels[c].encode_from_ptr = (const uint8_t *) (p->uplane[k] + at);
                    enc.channels[c].user_data_type = EXR_PIXEL_UINT;
                } else {
                    enc.channels[c].encode_from_ptr = (const uint8_t *) (p->plane[k] + at);
                    enc.channels[c].user_data_type = EXR_PIXEL_FLOAT;
                }
                enc.channels[c].user_bytes_per_element = 4;
                enc.channels[c].user_pixel_stride = 4;
                enc.channels[c].user_line_stride = 4 * w;
            }
            if (first && (rv = exr_encoding_choose_default_routines(f, pi, &enc)))
                break;
            first = 0;
            rv = exr_encoding_run(f, pi, &enc);
        }
    if (!first)
        exr_encoding_destroy(f, &enc);
    return rv;
}

int tu_write_exr(const char *path, const tu_part *parts, int nparts)
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    int rv = exr_start_write(&f, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv)
        return rv;
    for (int i = 0; i < nparts && !rv; ++i) {
        const tu_part *p = &parts[i];
        int pi;
        exr_attr_box2i_t dw, disp;
        exr_attr_v2f_t swc;
        dw.min.x = p->dw[0]; dw.min.y = p->dw[1]; dw.max.x = p->dw[2]; dw.max.y = p->dw[3];
        disp.min.x = p->disp[0]; disp.min.y = p->disp[1];
        disp.max.x = p->disp[2]; disp.max.y = p->disp[3];
        swc.x = swc.y = 0.0f;
        rv = exr_add_part(f, p->name, p->tile ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE, &pi);
        if (!rv)
            /* Core's order is displayWindow, then dataWindow. */
            rv = exr_initialize_required_attr(f, pi, &disp, &dw, 1.0f, &swc, 1.0f,
                                              EXR_LINEORDER_INCREASING_Y, p->comp);
        if (!rv && p->tile)
            rv = exr_set_tile_descriptor(f, pi, (uint32_t) p->tile,
                                         (uint32_t) (p->tile_h ? p->tile_h : p->tile),
                                         EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN);
        for (int c = 0; c < p->nch && !rv; ++c)
            rv = exr_add_channel(f, pi, p->ch[c], p->type[c], EXR_PERCEPTUALLY_LINEAR, 1, 1);
        for (int a = 0; a < 4 && p->m44[a].name && !rv; ++a) {
            exr_attr_m44f_t m;
            memcpy(m.m, p->m44[a].m, sizeof m.m);
            rv = exr_attr_set_m44f(f, pi, p->m44[a].name, &m);
        }
        for (int a = 0; a < 4 && p->f[a].name && !rv; ++a)
            rv = exr_attr_set_float(f, pi, p->f[a].name, p->f[a].v);
        if (!rv && p->str_name)
            rv = exr_attr_set_string(f, pi, p->str_name, p->str_value);
        int nmv = 0;
        while (nmv < 4 && p->multiview[nmv])
            ++nmv;
        if (!rv && nmv)
            rv = exr_attr_set_string_vector(f, pi, "multiView", nmv, (const char **) p->multiview);
    }
    if (!rv)
        rv = exr_write_header(f);
    for (int i = 0; i < nparts && !rv; ++i)
        rv = write_part_pixels(f, i, &parts[i]);
    int rv2 = exr_finish(&f);
    return rv ? rv : rv2;
}

float *tu_read_channel(const char *path, int part, const char *name, int *pw, int *ph)
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    if (exr_start_read(&f, path, &init))
        return NULL;
    exr_attr_box2i_t dw;
    exr_storage_t st;
    const exr_attr_chlist_t *cl;
    exr_get_data_window(f, part, &dw);
    exr_get_storage(f, part, &st);
    exr_get_channels(f, part, &cl);
    int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    int nch = cl->num_channels, want = -1;
    for (int c = 0; c < nch; ++c)
        if (!strcmp(cl->entries[c].name.str, name))
            want = c;
    if (want < 0 || nch < 1 || nch > 4096) {
        exr_finish(&f);
        return NULL;
    }
    float **planes = calloc((size_t) nch, sizeof *planes);
    float *result = NULL;
    int ok = planes != NULL;
    for (int c = 0; c < nch && ok; ++c)
        ok = (planes[c] = malloc(sizeof(float) * (size_t) w * (size_t) h)) != NULL;
    int32_t cw = w, chh = 1;
    if (ok && st == EXR_STORAGE_TILED) {
        uint32_t tx, ty;
        exr_get_tile_descriptor(f, part, &tx, &ty, NULL, NULL);
        cw = (int32_t) tx;
        chh = (int32_t) ty;
    } else if (ok) {
        exr_get_scanlines_per_chunk(f, part, &chh);
    }
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int first = 1;
    for (int ty = 0; ok && ty * chh < h; ++ty)
        for (int tx = 0; ok && tx * cw < w; ++tx) {
            exr_chunk_info_t ci;
            ok = !(st == EXR_STORAGE_TILED ? exr_read_tile_chunk_info(f, part, tx, ty, 0, 0, &ci)
                                           : exr_read_scanline_chunk_info(f, part, dw.min.y + ty * chh, &ci));
            ok = ok && !(first ? exr_decoding_initialize(f, part, &ci, &dec)
                               : exr_decoding_update(f, part, &ci, &dec));
            for (int c = 0; ok && c < dec.channel_count; ++c) {
                int k = 0;
                while (strcmp(cl->entries[k].name.str, dec.channels[c].channel_name))
                    ++k;
                dec.channels[c].decode_to_ptr =
                    (uint8_t *) (planes[k] + (size_t) ty * chh * w + (size_t) tx * cw);
                dec.channels[c].user_data_type = EXR_PIXEL_FLOAT;
                dec.channels[c].user_bytes_per_element = 4;
                dec.channels[c].user_pixel_stride = 4;
                dec.channels[c].user_line_stride = 4 * w;
            }
            if (ok && first)
                ok = !exr_decoding_choose_default_routines(f, part, &dec);
            first = 0;
            ok = ok && !exr_decoding_run(f, part, &dec);
        }
    if (!first)
        exr_decoding_destroy(f, &dec);
    if (ok) {
        result = planes[want];
        planes[want] = NULL;
        *pw = w;
        *ph = h;
    }
    for (int c = 0; planes && c < nch; ++c)
        free(planes[c]);
    free(planes);
    exr_finish(&f);
    return result;
}

void tu_image_free(tu_image *img)
{
    for (int c = 0; c < img->nch; ++c) {
        if (img->ch)
            free(img->ch[c]);
        if (img->plane)
            free(img->plane[c]);
    }
    free(img->ch);
    free(img->type);
    free(img->plane);
    memset(img, 0, sizeof *img);
}

int tu_read_image(const char *path, int part, tu_image *img)
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    memset(img, 0, sizeof *img);
    if (exr_start_read(&f, path, &init))
        return -1;
    exr_attr_box2i_t dw, disp;
    exr_storage_t st;
    const exr_attr_chlist_t *cl;
    const char *pname = NULL;
    int ok = !exr_get_data_window(f, part, &dw) && !exr_get_display_window(f, part, &disp) &&
             !exr_get_storage(f, part, &st) && !exr_get_channels(f, part, &cl) &&
             !exr_get_compression(f, part, &img->comp) && cl->num_channels > 0 &&
             (st == EXR_STORAGE_SCANLINE || st == EXR_STORAGE_TILED);
    if (!ok) {
        exr_finish(&f);
        return -1;
    }
    if (exr_get_name(f, part, &pname) == EXR_ERR_SUCCESS && pname)
        snprintf(img->name, sizeof img->name, "%s", pname);
    img->dw[0] = dw.min.x; img->dw[1] = dw.min.y; img->dw[2] = dw.max.x; img->dw[3] = dw.max.y;
    img->disp[0] = disp.min.x; img->disp[1] = disp.min.y;
    img->disp[2] = disp.max.x; img->disp[3] = disp.max.y;
    const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    img->w = w;
    img->h = h;
    img->nch = cl->num_channels;
    img->ch = calloc((size_t) img->nch, sizeof *img->ch);
    img->type = calloc((size_t) img->nch, sizeof *img->type);
    img->plane = calloc((size_t) img->nch, sizeof *img->plane);
    ok = img->ch && img->type && img->plane;
    for (int c = 0; ok && c < img->nch; ++c) {
        img->ch[c] = strdup(cl->entries[c].name.str);
        img->type[c] = cl->entries[c].pixel_type;
        img->plane[c] = malloc(4 * (size_t) w * (size_t) h);
        ok = img->ch[c] && img->plane[c];
    }
    int32_t cw = w, chh = 1;
    img->tiled = st == EXR_STORAGE_TILED;
    if (ok && img->tiled) {
        uint32_t tx, ty;
        ok = !exr_get_tile_descriptor(f, part, &tx, &ty, NULL, NULL);
        img->tile_x = (int) tx;
        img->tile_y = (int) ty;
        cw = (int32_t) tx;
        chh = (int32_t) ty;
    } else if (ok) {
        ok = !exr_get_scanlines_per_chunk(f, part, &chh);
    }
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int first = 1, chosen = 0;
    for (int ty = 0; ok && ty * chh < h; ++ty)
        for (int tx = 0; ok && tx * cw < w; ++tx) {
            exr_chunk_info_t ci;
            ok = !(img->tiled ? exr_read_tile_chunk_info(f, part, tx, ty, 0, 0, &ci)
                              : exr_read_scanline_chunk_info(f, part, dw.min.y + ty * chh, &ci));
            ok = ok && !(first ? exr_decoding_initialize(f, part, &ci, &dec)
                               : exr_decoding_update(f, part, &ci, &dec));
            if (ok)
                first = 0;
            for (int c = 0; ok && c < dec.channel_count; ++c) {
                exr_coding_channel_info_t *e = &dec.channels[c];
                int k = tu_image_find(img, e->channel_name);
                if (k < 0) {
                    ok = 0;
                    break;
                }
                e->decode_to_ptr = (uint8_t *) img->plane[k] +
                                   4 * ((size_t) ty * chh * w + (size_t) tx * cw);
                e->user_data_type = e->data_type == EXR_PIXEL_UINT ? EXR_PIXEL_UINT : EXR_PIXEL_FLOAT;
                e->user_bytes_per_element = 4;
                e->user_pixel_stride = 4;
                e->user_line_stride = 4 * w;
            }
            if (ok && !chosen)
                ok = !exr_decoding_choose_default_routines(f, part, &dec);
            chosen = 1;
            ok = ok && !exr_decoding_run(f, part, &dec);
        }
    if (!first)
        exr_decoding_destroy(f, &dec);
    exr_finish(&f);
    if (!ok) {
        tu_image_free(img);
        return -1;
    }
    return 0;
}

int tu_image_find(const tu_image *img, const char *name)
{
    for (int c = 0; c < img->nch; ++c)
        if (!strcmp(img->ch[c], name))
            return c;
    return -1;
}

const float *tu_image_f(const tu_image *img, const char *name)
{
    int k = tu_image_find(img, name);
    return k >= 0 && img->type[k] != EXR_PIXEL_UINT ? img->plane[k] : NULL;
}

const uint32_t *tu_image_u(const tu_image *img, const char *name)
{
    int k = tu_image_find(img, name);
    return k >= 0 && img->type[k] == EXR_PIXEL_UINT ? img->plane[k] : NULL;
}

uint32_t *tu_read_channel_uint(const char *path, int part, const char *name, int *w, int *h)
{
    tu_image img;
    if (tu_read_image(path, part, &img))
        return NULL;
    uint32_t *out = NULL;
    int k = tu_image_find(&img, name);
    if (k >= 0 && img.type[k] == EXR_PIXEL_UINT) {
        out = img.plane[k];
        img.plane[k] = NULL;
        *w = img.w;
        *h = img.h;
    }
    tu_image_free(&img);
    return out;
}

int tu_nparts(const char *path)
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    int n = -1;
    if (exr_start_read(&f, path, &init))
        return -1;
    if (exr_get_count(f, &n))
        n = -1;
    exr_finish(&f);
    return n;
}

char *tu_path(const char *file)
{
    const char *base = getenv("EXRFOG_TMP_DIR");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", base ? base : "/tmp/exrfog-tests");
    mkdir(dir, 0777);
    size_t n = strlen(dir) + strlen(file) + 2;
    char *p = malloc(n);
    snprintf(p, n, "%s/%s", dir, file);
    return p;
}

static void slurp(const char *path, char *buf, size_t len)
{
    if (!buf || !len)
        return;
    buf[0] = '\0';
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return;
    size_t n = fread(buf, 1, len - 1, fp);
    buf[n] = '\0';
    fclose(fp);
    remove(path);
}

/* The OUTPUT of an exrfog command line: the argument after "-o", quoted
 * with '...' or bare. Returns 0 and the path, or -1. */
static int output_of(const char *args, char *path, size_t cap)
{
    for (const char *a = strstr(args, "-o "); a; a = strstr(a + 1, "-o ")) {
        if (a != args && a[-1] != ' ')
            continue;
        const char *p = a + 3;
        while (*p == ' ')
            ++p;
        const char *e;
        if (*p == '\'') {
            e = strchr(++p, '\'');
            if (!e)
                return -1;
        } else {
            e = p + strcspn(p, " ");
        }
        if (e == p || (size_t) (e - p) >= cap)
            return -1;
        memcpy(path, p, (size_t) (e - p));
        path[e - p] = '\0';
        return 0;
    }
    return -1;
}

int tu_check_readback(const char *args, char *why, size_t cap)
{
    char path[4096];
    if (output_of(args, path, sizeof path))
        return 0;
    return tu_check_readback_path(path, why, cap);
}

int tu_check_readback_path(const char *path, char *why, size_t cap)
{
    static int have = -1;
    if (have < 0)
        have = system("command -v oiiotool >/dev/null 2>&1") == 0;
    if (!have || !tu_exists(path))
        return 0;
    /* The C++ OpenEXR library, through OpenImageIO: every part, every pixel. */
    size_t n = strlen(path) + 128;
    char *cmd = malloc(n);
    snprintf(cmd, n, "oiiotool -a --stats '%s' >/dev/null 2>&1", path);
    const int st = system(cmd);
    free(cmd);
    if (st == 0)
        return 0;
    snprintf(why, cap, "OpenImageIO (the OpenEXR C++ library) cannot read the output %s back",
             path);
    return -1;
}

int tu_run(const char *args, char *out, size_t outlen, char *err, size_t errlen)
{
    const char *bin = getenv("EXRFOG_BIN");
    /* Per-process names: test programs share the scratch directory and
     * ctest may run them in parallel. */
    char on[64], en[64];
    snprintf(on, sizeof on, "run.%ld.stdout", (long) getpid());
    snprintf(en, sizeof en, "run.%ld.stderr", (long) getpid());
    char *o = tu_path(on), *e = tu_path(en);
    size_t n = strlen(args) + strlen(o) + strlen(e) + 1024;
    char *cmd = malloc(n);
    snprintf(cmd, n, "%s %s >'%s' 2>'%s'", bin ? bin : "exrfog", args, o, e);
    int st = system(cmd);
    slurp(o, out, outlen);
    slurp(e, err, errlen);
    free(cmd);
    free(o);
    free(e);
    const int rc = WIFEXITED(st) ? WEXITSTATUS(st) : 128;
    char why[4200];
    if (rc == 0 && tu_check_readback(args, why, sizeof why)) {
        /* A run that wrote what other readers refuse has not succeeded. */
        if (err && errlen)
            snprintf(err, errlen, "%s", why);
        return 98;
    }
    return rc;
}

int tu_write_bytes(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    if (!f)
        return -1;
    const int ok = (len == 0 || fwrite(data, 1, len, f) == len);
    return fclose(f) == 0 && ok ? 0 : -1;
}

int tu_exists(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0;
}

const char *tu_real_exr_dir(void)
{
    static char dir[1024];
    const char *shared = getenv("EXRFOG_SHARED_DIR");
    snprintf(dir, sizeof dir, "%s/real-exr", shared ? shared : "../shared");
    return tu_exists(dir) ? dir : NULL;
}

int tu_copy(const char *from, const char *to)
{
    FILE *a = fopen(from, "rb"), *b = fopen(to, "wb");
    char buf[65536];
    size_t n;
    int rc = a && b ? 0 : -1;
    while (!rc && (n = fread(buf, 1, sizeof buf, a)) > 0)
        if (fwrite(buf, 1, n, b) != n)
            rc = -1;
    if (a)
        fclose(a);
    if (b)
        fclose(b);
    return rc;
}

/* ---- comparisons ---- */

float tu_half_round(float f)
{
    if (!isfinite(f) || f == 0.0f)
        return f;
    const double a = fabs((double) f);
    if (a >= 65520.0)
        return f > 0 ? INFINITY : -INFINITY;
    int e;
    frexp(a, &e);
    int lead = e - 1;          /* a in [2^lead, 2^(lead+1)) */
    if (lead < -14)
        lead = -14;            /* subnormal halves share the 2^-24 step */
    const double q = ldexp(1.0, lead - 10);
    return (float) copysign(rint(a / q) * q, (double) f);
}

static const char *tu_type_name(exr_pixel_type_t t)
{
    return t == EXR_PIXEL_UINT ? "uint" : t == EXR_PIXEL_HALF ? "half" : "float";
}

long tu_compare_layout(const tu_image *in, const tu_image *out, int pixel_type)
{
    long bad = 0;
    if (in->nch != out->nch) {
        fprintf(stderr, "  %d channels in, %d out\n", in->nch, out->nch);
        return 1;
    }
    for (int c = 0; c < in->nch; ++c) {
        if (strcmp(in->ch[c], out->ch[c])) {
            fprintf(stderr, "  channel %d is %s, expected %s\n", c, out->ch[c], in->ch[c]);
            ++bad;
            continue;
        }
        exr_pixel_type_t want = in->type[c];
        if (pixel_type >= 0 && want != EXR_PIXEL_UINT)
            want = (exr_pixel_type_t) pixel_type;
        if (out->type[c] != want) {
            fprintf(stderr, "  channel %s is %s, expected %s\n", out->ch[c],
                    tu_type_name(out->type[c]), tu_type_name(want));
            ++bad;
        }
    }
    if (memcmp(in->dw, out->dw, sizeof in->dw)) {
        fprintf(stderr, "  data window (%d,%d)-(%d,%d), expected (%d,%d)-(%d,%d)\n", out->dw[0],
                out->dw[1], out->dw[2], out->dw[3], in->dw[0], in->dw[1], in->dw[2], in->dw[3]);
        ++bad;
    }
    if (memcmp(in->disp, out->disp, sizeof in->disp)) {
        fprintf(stderr, "  display window differs\n");
        ++bad;
    }
    return bad;
}

long tu_compare_channel(const tu_image *in, const tu_image *out, const char *name, double rel,
                        int as_half)
{
    const int ki = tu_image_find(in, name), ko = tu_image_find(out, name);
    if (ki < 0 || ko < 0 || in->w != out->w || in->h != out->h) {
        fprintf(stderr, "  channel %s missing or resized (in %d, out %d)\n", name, ki, ko);
        return 1;
    }
    const size_t n = (size_t) in->w * (size_t) in->h;
    long bad = 0;
    if (in->type[ki] == EXR_PIXEL_UINT || out->type[ko] == EXR_PIXEL_UINT) {
        if (in->type[ki] != out->type[ko]) {
            fprintf(stderr, "  channel %s: uint changed type\n", name);
            return 1;
        }
        const uint32_t *a = in->plane[ki], *b = out->plane[ko];
        for (size_t i = 0; i < n; ++i)
            if (a[i] != b[i] && bad++ < 5)
                fprintf(stderr, "  %s[%zu]: %u, expected %u\n", name, i, b[i], a[i]);
    } else {
        const float *a = in->plane[ki], *b = out->plane[ko];
        for (size_t i = 0; i < n; ++i) {
            const float want = as_half ? tu_half_round(a[i]) : a[i];
            int ok;
            if (rel == 0.0 || !isfinite(want))
                ok = memcmp(&want, &b[i], sizeof want) == 0;
            else
                ok = fabs((double) b[i] - want) <= rel * (1.0 + fabs(want));
            if (!ok && bad++ < 5)
                fprintf(stderr, "  %s[%zu]: %.9g, expected %.9g\n", name, i, (double) b[i],
                        (double) want);
        }
    }
    if (bad)
        fprintf(stderr, "  %ld pixels of %s differ\n", bad, name);
    return bad;
}

long tu_compare_files(const char *in_path, const char *out_path, int skip_part,
                      const char *const *skip)
{
    const int n = tu_nparts(in_path), m = tu_nparts(out_path);
    if (n < 1 || n != m) {
        fprintf(stderr, "  %d parts in %s, %d in %s\n", n, in_path, m, out_path);
        return 1;
    }
    long bad = 0;
    for (int p = 0; p < n; ++p) {
        tu_image a, b;
        if (tu_read_image(in_path, p, &a))
            return fprintf(stderr, "  cannot read part %d of %s\n", p, in_path), bad + 1;
        if (tu_read_image(out_path, p, &b)) {
            tu_image_free(&a);
            return fprintf(stderr, "  cannot read part %d of %s\n", p, out_path), bad + 1;
        }
        if (strcmp(a.name, b.name)) {
            fprintf(stderr, "  part %d is named '%s', expected '%s'\n", p, b.name, a.name);
            ++bad;
        }
        long lb = tu_compare_layout(&a, &b, -1);
        if (lb)
            fprintf(stderr, "  part %d ('%s'): channel layout differs\n", p, a.name);
        bad += lb;
        for (int c = 0; !lb && c < a.nch; ++c) {
            int skipped = 0;
            if (p == skip_part) {
                skipped = skip == NULL;
                for (int k = 0; skip && skip[k]; ++k)
                    skipped |= !strcmp(skip[k], a.ch[c]);
            }
            if (!skipped)
                bad += tu_compare_channel(&a, &b, a.ch[c], 0.0, 0);
        }
        tu_image_free(&a);
        tu_image_free(&b);
    }
    return bad;
}

void tu_pinhole_fov(tu_pinhole *p, const int disp[4], double hfov_deg)
{
    const double W = disp[2] - disp[0] + 1.0, H = disp[3] - disp[1] + 1.0;
    const double t = tan(hfov_deg * 3.14159265358979323846 / 360.0);
    memcpy(p->disp, disp, sizeof p->disp);
    p->a = 0.5 / t;
    p->b = p->a * W / H;
    p->cu = p->cv = 0.5;
}

void tu_pinhole_screen(tu_pinhole *p, const int disp[4], double px, double py)
{
    /* sx = 2u - 1 = px X/Z  <=>  u = (px / 2) X/Z + 1/2; sy = 1 - 2v likewise. */
    memcpy(p->disp, disp, sizeof p->disp);
    p->a = 0.5 * px;
    p->b = 0.5 * py;
    p->cu = p->cv = 0.5;
}

double tu_pinhole_ray_len(const tu_pinhole *p, int x, int y)
{
    const double W = p->disp[2] - p->disp[0] + 1.0, H = p->disp[3] - p->disp[1] + 1.0;
    const double u = (x + 0.5 - p->disp[0]) / W, v = (y + 0.5 - p->disp[1]) / H;
    const double dx = (u - p->cu) / p->a, dy = -(v - p->cv) / p->b;
    return sqrt(dx * dx + dy * dy + 1.0);
}

long tu_check_fog(tu_fog_check *fc)
{
    tu_image in, out, dimg;
    fc->sky = fc->fogged = 0;
    if (tu_read_image(fc->in, fc->in_part, &in))
        return fprintf(stderr, "  cannot read %s\n", fc->in), -1;
    if (tu_read_image(fc->out, fc->out_part, &out)) {
        tu_image_free(&in);
        return fprintf(stderr, "  cannot read %s\n", fc->out), -1;
    }
    if (tu_read_image(fc->depth ? fc->depth : fc->in, fc->depth ? fc->depth_part : fc->in_part,
                      &dimg)) {
        tu_image_free(&in);
        tu_image_free(&out);
        return fprintf(stderr, "  cannot read the depth\n"), -1;
    }
    long bad = 0;
    /* A UINT depth counts by its numeric value. */
    const float *Z = tu_image_f(&dimg, fc->z);
    float *zconv = NULL;
    const uint32_t *zu = tu_image_u(&dimg, fc->z);
    if (!Z && zu && (zconv = malloc(sizeof(float) * (size_t) dimg.w * (size_t) dimg.h))) {
        for (size_t i = 0; i < (size_t) dimg.w * (size_t) dimg.h; ++i)
            zconv[i] = (float) zu[i];
        Z = zconv;
    }
    const float *cin[4] = { NULL }, *cout[4] = { NULL };
    int half[4] = { 0 };
    if (!Z || memcmp(in.dw, out.dw, sizeof in.dw) || memcmp(in.dw, dimg.dw, sizeof in.dw)) {
        fprintf(stderr, "  no depth %s, or the windows differ\n", fc->z);
        bad = -1;
    }
    for (int k = 0; bad == 0 && k < 4; ++k) {
        if (!fc->rgba[k])
            continue;
        cin[k] = tu_image_f(&in, fc->rgba[k]);
        cout[k] = tu_image_f(&out, fc->rgba[k]);
        if (!cin[k] || !cout[k]) {
            fprintf(stderr, "  no channel %s\n", fc->rgba[k]);
            bad = -1;
            break;
        }
        half[k] = out.type[tu_image_find(&out, fc->rgba[k])] == EXR_PIXEL_HALF;
    }
    for (int j = 0; bad >= 0 && j < in.h; ++j)
        for (int i = 0; i < in.w; ++i) {
            const size_t idx = (size_t) j * (size_t) in.w + (size_t) i;
            const int x = in.dw[0] + i, y = in.dw[1] + j;
            const double z = Z[idx];
            const int sky = !isfinite(z) || z <= 0.0 || z >= 1e9;
            const double T = sky ? 0.0 : exp(-fc->rho * z * tu_pinhole_ray_len(fc->cam, x, y));
            const double a = cin[3] ? cin[3][idx] : 1.0;
            fc->sky += sky;
            fc->fogged += !sky && T < 0.999;
            for (int k = 0; k < 4; ++k) {
                if (!cin[k])
                    continue;
                const double want = k < 3 ? T * cin[k][idx] + (1.0 - T) * a * fc->F[k] +
                                                (1.0 - a) * fc->F[k]
                                          : a + (1.0 - a);
                const double got = cout[k][idx];
                const double tol = (half[k] ? 6e-4 : 1e-5) * (fabs(want) + 1e-3) +
                                   fc->extra_rel * fabs(want) + fc->extra_abs;
                if (!(fabs(got - want) <= tol) && bad++ < 8)
                    fprintf(stderr, "  %s at (%d,%d) z %g: %.9g, expected %.9g (T %.6g, a %g)\n",
                            fc->rgba[k], x, y, z, got, want, T, a);
            }
        }
    if (bad > 0)
        fprintf(stderr, "  %ld fogged values differ from the expectation\n", bad);
    free(zconv);
    tu_image_free(&in);
    tu_image_free(&out);
    tu_image_free(&dimg);
    return bad;
}

char tu_out[1 << 16], tu_err[1 << 16];

int tu_runf(const char *fmt, ...)
{
    char args[8192];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(args, sizeof args, fmt, ap);
    va_end(ap);
    return tu_run(args, tu_out, sizeof tu_out, tu_err, sizeof tu_err);
}

void tu_fog_check_init(tu_fog_check *fc, const char *in, const char *out, const tu_pinhole *cam,
                       double rho)
{
    static const char *const rgba[4] = { "R", "G", "B", "A" };
    memset(fc, 0, sizeof *fc);
    fc->in = in;
    fc->out = out;
    for (int k = 0; k < 4; ++k)
        fc->rgba[k] = rgba[k];
    fc->z = "Z";
    fc->cam = cam;
    fc->rho = rho;
    fc->F[0] = 0.25;
    fc->F[1] = 0.5;
    fc->F[2] = 0.75;
}

uint32_t tu_xorshift32(uint32_t *state)
{
    uint32_t x = *state;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    return *state = x;
}

double tu_rand01(uint32_t *state)
{
    return (double) (tu_xorshift32(state) >> 8) * (1.0 / 16777216.0);
}
