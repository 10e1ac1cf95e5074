/* Copying a part of an EXR file into another as it is (exr_parts.h):
 * its header (attributes, storage, channels) and its chunks undecoded,
 * flat or deep, scanline or tiled, and the output file's writer. The home
 * of what the flat stream (exr_stream.c) and the deep pass (exr_deep.c)
 * both do to the parts beside the one they fog. */
#include "exr_parts.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Whether part p of f is deep (scanline or tiled). */
int ef_exr_part_is_deep(const ef_exr_file *f, int part)
{
    exr_storage_t st;
    return exr_get_storage(f->ctx, part, &st) == EXR_ERR_SUCCESS &&
           (st == EXR_STORAGE_DEEP_SCANLINE || st == EXR_STORAGE_DEEP_TILED);
}

/* Grows *p of *cap bytes to at least need (doubling); -1 when out of memory. */
int ef_deep_grow(void **p, size_t *cap, size_t need)
{
    if (need <= *cap)
        return 0;
    size_t n = *cap ? *cap : 4096;
    while (n < need)
        n *= 2;
    void *q = realloc(*p, n);
    if (!q)
        return -1;
    *p = q;
    *cap = n;
    return 0;
}

/* Attributes that describe a part's storage: set for the output by what
 * it is, never copied from a part stored otherwise. */
static int storage_attr(const char *name)
{
    static const char *const names[] = { "tiles", "chunkCount", "type", "version", "name",
                                         "channels", "compression", "lineOrder",
                                         "maxSamplesPerPixel" };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; ++i)
        if (!strcmp(name, names[i]))
            return 1;
    return 0;
}

/* One attribute onto out's part p by its type's setter (the windows by
 * theirs). Returns 0 or an exr_result_t. */
static exr_result_t set_attr(exr_context_t out, int p, const exr_attribute_t *a)
{
    const char *n = a->name;
    if (!strcmp(n, "dataWindow"))
        return exr_set_data_window(out, p, a->box2i);
    if (!strcmp(n, "displayWindow"))
        return exr_set_display_window(out, p, a->box2i);
    switch (a->type) {
    case EXR_ATTR_BOX2I: return exr_attr_set_box2i(out, p, n, a->box2i);
    case EXR_ATTR_BOX2F: return exr_attr_set_box2f(out, p, n, a->box2f);
    case EXR_ATTR_CHROMATICITIES: return exr_attr_set_chromaticities(out, p, n, a->chromaticities);
    case EXR_ATTR_COMPRESSION: return exr_attr_set_compression(out, p, n, (exr_compression_t) a->uc);
    case EXR_ATTR_DOUBLE: return exr_attr_set_double(out, p, n, a->d);
    case EXR_ATTR_ENVMAP: return exr_attr_set_envmap(out, p, n, (exr_envmap_t) a->uc);
    case EXR_ATTR_FLOAT: return exr_attr_set_float(out, p, n, a->f);
    case EXR_ATTR_FLOAT_VECTOR:
        return exr_attr_set_float_vector(out, p, n, a->floatvector->length, a->floatvector->arr);
    case EXR_ATTR_INT: return exr_attr_set_int(out, p, n, a->i);
    case EXR_ATTR_KEYCODE: return exr_attr_set_keycode(out, p, n, a->keycode);
    case EXR_ATTR_LINEORDER: return exr_attr_set_lineorder(out, p, n, (exr_lineorder_t) a->uc);
    case EXR_ATTR_M33F: return exr_attr_set_m33f(out, p, n, a->m33f);
    case EXR_ATTR_M33D: return exr_attr_set_m33d(out, p, n, a->m33d);
    case EXR_ATTR_M44F: return exr_attr_set_m44f(out, p, n, a->m44f);
    case EXR_ATTR_M44D: return exr_attr_set_m44d(out, p, n, a->m44d);
    case EXR_ATTR_PREVIEW: return exr_attr_set_preview(out, p, n, a->preview);
    case EXR_ATTR_RATIONAL: return exr_attr_set_rational(out, p, n, a->rational);
    case EXR_ATTR_STRING: return exr_attr_set_string(out, p, n, a->string->str);
    case EXR_ATTR_STRING_VECTOR: {
        const int32_t k = a->stringvector->n_strings;
        const char **v = calloc((size_t) (k > 0 ? k : 1), sizeof *v);
        if (!v)
            return EXR_ERR_OUT_OF_MEMORY;
        for (int32_t i = 0; i < k; ++i)
            v[i] = a->stringvector->strings[i].str;
        const exr_result_t rc = exr_attr_set_string_vector(out, p, n, k, v);
        free(v);
        return rc;
    }
    case EXR_ATTR_TIMECODE: return exr_attr_set_timecode(out, p, n, a->timecode);
    case EXR_ATTR_V2I: return exr_attr_set_v2i(out, p, n, a->v2i);
    case EXR_ATTR_V2F: return exr_attr_set_v2f(out, p, n, a->v2f);
    case EXR_ATTR_V2D: return exr_attr_set_v2d(out, p, n, a->v2d);
    case EXR_ATTR_V3I: return exr_attr_set_v3i(out, p, n, a->v3i);
    case EXR_ATTR_V3F: return exr_attr_set_v3f(out, p, n, a->v3f);
    case EXR_ATTR_V3D: return exr_attr_set_v3d(out, p, n, a->v3d);
    case EXR_ATTR_OPAQUE:
        return exr_attr_set_user(out, p, n, a->type_name, a->opaque->size, a->opaque->packed_data);
    default:
        return EXR_ERR_SUCCESS;   /* a storage description (tiles, channels): the output's own */
    }
}

/* Whether in's part pin and out's part pout store pixels alike (both
 * tiled or both not): Core's copy of every unset attribute is then right;
 * otherwise it would give a scanline part the tiles of a tiled one. */
static int same_layout(const ef_exr_file *in, int pin, exr_context_t out, int pout)
{
    exr_storage_t a, b;
    if (exr_get_storage(in->ctx, pin, &a) || exr_get_storage(out, pout, &b))
        return 1;
    const int ta = a == EXR_STORAGE_TILED || a == EXR_STORAGE_DEEP_TILED;
    const int tb = b == EXR_STORAGE_TILED || b == EXR_STORAGE_DEEP_TILED;
    return ta == tb;
}

int ef_exr_copy_attrs(const ef_exr_file *in, int pin, exr_context_t out, int pout,
                      const char *params, const char *history, ef_err *err)
{
    const int alike = same_layout(in, pin, out, pout);
    if (params && exr_attr_set_string(out, pout, "exrfog/parameters", params))
        return ef_fail(err, "cannot record exrfog/parameters");
    if (history) {
        /* Earlier passes' lines first, as oiiotool appends to ImageHistory. */
        const exr_attribute_t *h = NULL;
        const char *prev = NULL;
        if (exr_get_attribute_by_name(in->ctx, pin, "exrfog/history", &h) == EXR_ERR_SUCCESS &&
            h->type == EXR_ATTR_STRING && h->string && h->string->str && h->string->length > 0)
            prev = h->string->str;
        const size_t n = (prev ? strlen(prev) + 1 : 0) + strlen(history) + 1;
        char *v = malloc(n);
        if (!v)
            return ef_fail(err, "out of memory");
        snprintf(v, n, "%s%s%s", prev ? prev : "", prev ? "\n" : "", history);
        const int bad = exr_attr_set_string(out, pout, "exrfog/history", v) != EXR_ERR_SUCCESS;
        free(v);
        if (bad)
            return ef_fail(err, "cannot record exrfog/history: %s", ef_exr_last_core_message());
    }
    /* Core 3.1.5's copy cannot duplicate attributes of user-defined types
     * (EXR_ATTR_OPAQUE); declare those first so the copy skips them. */
    int32_t na = 0;
    exr_get_attribute_count(in->ctx, pin, &na);
    for (int32_t i = 0; i < na; ++i) {
        const exr_attribute_t *a;
        if (exr_get_attribute_by_index(in->ctx, pin, EXR_ATTR_LIST_FILE_ORDER, i, &a) ||
            a->type != EXR_ATTR_OPAQUE || !a->opaque)
            continue;
        if (exr_attr_set_user(out, pout, a->name, a->type_name, a->opaque->size,
                              a->opaque->packed_data))
            return ef_fail(err, "cannot copy attribute '%s' of part %d: %s", a->name, pin,
                           ef_exr_last_core_message());
    }
    if (alike && exr_copy_unset_attributes(out, pout, in->ctx, pin))
        return ef_fail(err, "cannot copy the header of part %d: %s", pin, ef_exr_last_core_message());
    for (int32_t i = 0; !alike && i < na; ++i) {
        const exr_attribute_t *a, *b;
        if (exr_get_attribute_by_index(in->ctx, pin, EXR_ATTR_LIST_FILE_ORDER, i, &a) ||
            storage_attr(a->name) || a->type == EXR_ATTR_OPAQUE ||
            exr_get_attribute_by_name(out, pout, a->name, &b) == EXR_ERR_SUCCESS)
            continue;
        if (set_attr(out, pout, a))
            return ef_fail(err, "cannot copy attribute '%s' of part %d: %s", a->name, pin,
                           ef_exr_last_core_message());
    }
    /* Core 3.1.5 can stop copying early yet report success; never drop
     * metadata silently. */
    for (int32_t i = 0; i < na; ++i) {
        const exr_attribute_t *a, *b;
        if (exr_get_attribute_by_index(in->ctx, pin, EXR_ATTR_LIST_FILE_ORDER, i, &a) == 0 &&
            (alike || !storage_attr(a->name)) &&
            exr_get_attribute_by_name(out, pout, a->name, &b) != EXR_ERR_SUCCESS)
            return ef_fail(err, "cannot copy attribute '%s' of part %d", a->name, pin);
    }
    return 0;
}

/* The output stream: Core writes through the caller's descriptor, so the
 * file is the one the caller created (exclusively, beside OUTPUT) and no
 * name is opened again. The first failure's errno is kept for the message. */
int64_t ef_exr_sink_write(exr_const_context_t ctx, void *user, const void *buf, uint64_t sz,
                          uint64_t off, exr_stream_error_func_ptr_t error_cb)
{
    ef_exr_sink *s = user;
    const unsigned char *p = buf;
    uint64_t done = 0;
    while (done < sz) {
        const ssize_t n = pwrite(s->fd, p + done, (size_t) (sz - done), (off_t) (off + done));
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0) {
            const int e = n < 0 ? errno : ENOSPC;
            if (!s->errnum)
                s->errnum = e;
            if (error_cb)
                error_cb(ctx, EXR_ERR_WRITE_IO, "%s", strerror(e));
            return -1;
        }
        done += (uint64_t) n;
    }
    return (int64_t) sz;
}

int ef_exr_define_part_copy(const ef_exr_file *in, int p, exr_context_t out,
                            const char *history, const char *params, ef_err *err)
{
    const char *name = NULL;
    exr_storage_t st;
    exr_compression_t comp;
    exr_lineorder_t lo;
    const exr_attr_chlist_t *cl;
    int op;
    exr_get_name(in->ctx, p, &name);
    if (exr_get_storage(in->ctx, p, &st) || exr_get_compression(in->ctx, p, &comp) ||
        exr_get_lineorder(in->ctx, p, &lo) || exr_get_channels(in->ctx, p, &cl))
        return ef_fail(err, "part %d: cannot read its header: %s", p, ef_exr_last_core_message());
    if (exr_add_part(out, name, st, &op) || op != p)
        return ef_fail(err, "cannot add output part %d: %s", p, ef_exr_last_core_message());
    if (st == EXR_STORAGE_TILED || st == EXR_STORAGE_DEEP_TILED) {
        uint32_t tx, ty;
        exr_tile_level_mode_t lm;
        exr_tile_round_mode_t rm;
        exr_get_tile_descriptor(in->ctx, p, &tx, &ty, &lm, &rm);
        if (lm != EXR_TILE_ONE_LEVEL)
            return ef_fail(err, "part %d is tiled with mipmap or ripmap levels: exrfog copies "
                                "one-level parts beside a deep one (split the parts first, e.g. "
                                "oiiotool IN --subimage NAME -o PART.exr)", p);
        if (exr_set_tile_descriptor(out, p, tx, ty, lm, rm))
            return ef_fail(err, "cannot set the tile size of part %d", p);
    }
    for (int c = 0; c < cl->num_channels; ++c) {
        const exr_attr_chlist_entry_t *e = &cl->entries[c];
        if (exr_add_channel(out, p, e->name.str, e->pixel_type,
                            e->p_linear ? EXR_PERCEPTUALLY_LINEAR : EXR_PERCEPTUALLY_LOGARITHMIC,
                            e->x_sampling, e->y_sampling))
            return ef_fail(err, "cannot add channel '%s' to part %d", e->name.str, p);
    }
    /* the chunks go in as they are: the same compression and line order */
    if (exr_set_compression(out, p, comp) || exr_set_lineorder(out, p, lo))
        return ef_fail(err, "cannot set the compression of part %d", p);
    return ef_exr_copy_attrs(in, p, out, p, params, history, err);
}

/* Copies one chunk of part p (ci read from in) into out. */
static int copy_chunk(const ef_exr_file *in, int p, exr_context_t out, int deep, int tiled,
                      int tx, int ty, int y, const exr_chunk_info_t *ci, uint8_t **buf,
                      size_t *cap, uint8_t **tab, size_t *tcap, ef_err *err)
{
    if (ci->packed_size > (1ull << 34) || ci->sample_count_table_size > (1ull << 34)) {
        ef_fail(err, "part %d has a chunk of %llu bytes: the file is corrupt", p,
                (unsigned long long) ci->packed_size);
        err->file = in->path;
        return -1;
    }
    if (ef_deep_grow((void **) buf, cap, (size_t) ci->packed_size + 1) ||
        (deep && ef_deep_grow((void **) tab, tcap, (size_t) ci->sample_count_table_size + 1)))
        return ef_fail(err, "out of memory");
    exr_result_t rc = deep ? exr_read_deep_chunk(in->ctx, p, ci, *buf, *tab)
                           : exr_read_chunk(in->ctx, p, ci, *buf);
    if (rc) {
        ef_fail(err, "part %d: cannot read a chunk (the file is truncated or corrupt): %s", p,
                ef_exr_last_core_message());
        err->file = in->path;
        return -1;
    }
    if (deep && tiled)
        rc = exr_write_deep_tile_chunk(out, p, tx, ty, 0, 0, *buf, ci->packed_size,
                                       ci->unpacked_size, *tab, ci->sample_count_table_size);
    else if (deep)
        rc = exr_write_deep_scanline_chunk(out, p, y, *buf, ci->packed_size, ci->unpacked_size,
                                           *tab, ci->sample_count_table_size);
    else if (tiled)
        rc = exr_write_tile_chunk(out, p, tx, ty, 0, 0, *buf, ci->packed_size);
    else
        rc = exr_write_scanline_chunk(out, p, y, *buf, ci->packed_size);
    if (rc)
        return ef_fail(err, "cannot write part %d: %s", p, ef_exr_last_core_message());
    return 0;
}

int ef_exr_copy_part_chunks(const ef_exr_file *in, int p, exr_context_t out, ef_err *err)
{
    exr_storage_t st;
    exr_attr_box2i_t dw;
    if (exr_get_storage(in->ctx, p, &st) || exr_get_data_window(in->ctx, p, &dw))
        return ef_fail(err, "part %d: cannot read its header", p);
    const int deep = st == EXR_STORAGE_DEEP_SCANLINE || st == EXR_STORAGE_DEEP_TILED;
    const int tiled = st == EXR_STORAGE_TILED || st == EXR_STORAGE_DEEP_TILED;
    uint8_t *buf = NULL, *tab = NULL;
    size_t cap = 0, tcap = 0;
    int rc = 0;
    exr_chunk_info_t ci;
    if (tiled) {
        uint32_t tw, th;
        exr_get_tile_descriptor(in->ctx, p, &tw, &th, NULL, NULL);
        const int64_t w = (int64_t) dw.max.x - dw.min.x + 1, h = (int64_t) dw.max.y - dw.min.y + 1;
        const int64_t nx = tw ? (w + tw - 1) / tw : 0, ny = th ? (h + th - 1) / th : 0;
        for (int64_t ty = 0; ty < ny && !rc; ++ty)
            for (int64_t tx = 0; tx < nx && !rc; ++tx) {
                if (exr_read_tile_chunk_info(in->ctx, p, (int) tx, (int) ty, 0, 0, &ci)) {
                    const char *m = ef_exr_last_core_message();
                    rc = ef_fail(err, "part %d: tile (%lld, %lld) is missing or damaged (the file "
                                      "is truncated or corrupt)%s%s", p, (long long) tx,
                                 (long long) ty, *m ? ": " : "", m);
                    err->file = in->path;
                } else
                    rc = copy_chunk(in, p, out, deep, 1, (int) tx, (int) ty, 0, &ci, &buf,
                                    &cap, &tab, &tcap, err);
            }
    } else {
        int32_t lines = 1;
        exr_get_scanlines_per_chunk(in->ctx, p, &lines);
        if (lines < 1)
            lines = 1;
        for (int64_t y = dw.min.y; y <= dw.max.y && !rc; y += lines) {
            if (exr_read_scanline_chunk_info(in->ctx, p, (int) y, &ci)) {
                /* (Core leaves no message for some offsets past the end) */
                const char *m = ef_exr_last_core_message();
                rc = ef_fail(err, "part %d: the chunk of line %lld is missing or damaged (the "
                                  "file is truncated or corrupt)%s%s", p, (long long) y,
                             *m ? ": " : "", m);
                err->file = in->path;
            } else
                rc = copy_chunk(in, p, out, deep, 0, 0, 0, (int) y, &ci, &buf, &cap, &tab,
                                &tcap, err);
        }
    }
    free(buf);
    free(tab);
    return rc;
}
