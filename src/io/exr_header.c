/* Opening, validating and interpreting EXR headers. */
#include "exr_io.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

/* Core reports details through a callback; keep the last one per thread so
 * error messages can quote it instead of printing from inside the library. */
static _Thread_local char last_core_msg[512];

static void core_error_handler(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void) ctxt;
    snprintf(last_core_msg, sizeof last_core_msg, "%s (%s)", msg ? msg : "",
             exr_get_error_code_as_string(code));
}

const char *ef_exr_last_core_message(void)
{
    return last_core_msg;
}

void ef_exr_init_context(exr_context_initializer_t *init)
{
    exr_context_initializer_t def = EXR_DEFAULT_CONTEXT_INITIALIZER;
    *init = def;
    init->error_handler_fn = core_error_handler;
}

static int has_control_byte(const char *s)
{
    for (const unsigned char *c = (const unsigned char *) s; c && *c; ++c)
        if (*c < 0x20 || *c == 0x7f)
            return 1;
    return 0;
}

static int check_part(const ef_exr_file *f, int p, ef_err *err)
{
    exr_storage_t st;
    exr_attr_box2i_t dw, disp;
    const exr_attr_chlist_t *cl;
    if (exr_get_storage(f->ctx, p, &st) || exr_get_data_window(f->ctx, p, &dw) ||
        exr_get_display_window(f->ctx, p, &disp) || exr_get_channels(f->ctx, p, &cl))
        return ef_fail(err, "part %d has an incomplete header (%s)", p, last_core_msg);
    const int deep = st == EXR_STORAGE_DEEP_SCANLINE || st == EXR_STORAGE_DEEP_TILED;
    const exr_attr_box2i_t *win[2] = { &dw, &disp };
    const char *wname[2] = { "data", "display" };
    for (int i = 0; i < 2; ++i) {
        int64_t w = (int64_t) win[i]->max.x - win[i]->min.x + 1;
        int64_t h = (int64_t) win[i]->max.y - win[i]->min.y + 1;
        if (w < 1 || h < 1)
            return ef_fail(err, "part %d has an empty %s window (%d,%d)-(%d,%d)", p, wname[i],
                           win[i]->min.x, win[i]->min.y, win[i]->max.x, win[i]->max.y);
        if (w > EF_MAX_DIMENSION || h > EF_MAX_DIMENSION)
            return ef_fail(err, "part %d has an absurd %s window of %lld x %lld pixels "
                                "(exrfog caps each side at %d; the header is probably corrupt)",
                           p, wname[i], (long long) w, (long long) h, EF_MAX_DIMENSION);
    }
    if (cl->num_channels < 1)
        return ef_fail(err, "part %d has no channels", p);
    int32_t na = 0;
    exr_get_attribute_count(f->ctx, p, &na);
    for (int32_t i = 0; i < na; ++i) {
        const exr_attribute_t *a;
        if (exr_get_attribute_by_index(f->ctx, p, EXR_ATTR_LIST_FILE_ORDER, i, &a))
            continue;
        /* No writer puts control bytes in names; Core 3.1.5 also leaks when
         * asked to copy an empty user-typed attribute. Both mean damage. */
        if (has_control_byte(a->name) || has_control_byte(a->type_name))
            return ef_fail(err, "part %d has an attribute '%s' of type '%s' with control "
                                "characters in its name, so the header is corrupt",
                           p, a->name, a->type_name);
        if (a->type == EXR_ATTR_OPAQUE && (!a->opaque || a->opaque->size <= 0))
            return ef_fail(err, "part %d has an empty attribute '%s' of unknown type '%s', so "
                                "the header is corrupt", p, a->name, a->type_name);
    }
    exr_compression_t comp;
    if (exr_get_compression(f->ctx, p, &comp) == EXR_ERR_SUCCESS &&
        (comp == EXR_COMPRESSION_DWAA || comp == EXR_COMPRESSION_DWAB))
        return ef_fail(err, "part %d is %s-compressed, which OpenEXRCore 3.1.5 cannot decode "
                            "(convert it first, e.g. oiiotool IN --compression zip -o OUT)",
                       p, comp == EXR_COMPRESSION_DWAA ? "DWAA" : "DWAB");
    for (int c = 0; c < cl->num_channels; ++c)
        if (cl->entries[c].x_sampling != 1 || cl->entries[c].y_sampling != 1)
            return ef_fail(err, "channel '%s' is subsampled (%dx%d), which exrfog does not "
                                "support (OpenImageIO cannot read it either): convert the image "
                                "to full-resolution RGB with a reader of luminance/chroma EXRs "
                                "(OpenEXR's RgbaInputFile, Nuke), or render without subsampling",
                           cl->entries[c].name.str, cl->entries[c].x_sampling,
                           cl->entries[c].y_sampling);
    /* Deep parts size their buffers from their sample tables, checked
     * chunk by chunk as they are read (exr_deep.c). */
    if (deep)
        return 0;
    if (st == EXR_STORAGE_TILED) {
        uint32_t tx, ty;
        exr_tile_level_mode_t lm;
        exr_tile_round_mode_t rm;
        if (exr_get_tile_descriptor(f->ctx, p, &tx, &ty, &lm, &rm))
            return ef_fail(err, "part %d is tiled but has no valid tile description", p);
        if (tx < 1 || ty < 1 || tx > EF_MAX_DIMENSION || ty > EF_MAX_DIMENSION)
            return ef_fail(err, "part %d has an absurd tile size %u x %u", p, tx, ty);
    }
    /* One unit's buffers (every channel as 32 bits, decoded and packed,
     * plus room for depth and AOVs) must fit the per-worker limit before
     * anything is allocated. */
    const uint64_t W = (uint64_t) ((int64_t) dw.max.x - dw.min.x + 1),
                   H = (uint64_t) ((int64_t) dw.max.y - dw.min.y + 1);
    uint64_t uw = W, uh = 16;
    int32_t lines = 1;
    if (st == EXR_STORAGE_TILED) {
        uint32_t tx = 1, ty = 1;
        exr_get_tile_descriptor(f->ctx, p, &tx, &ty, NULL, NULL);
        uw = tx < W ? tx : W;
        uh = ty < H ? ty : H;
    } else if (exr_get_scanlines_per_chunk(f->ctx, p, &lines) == EXR_ERR_SUCCESS && lines > 16) {
        uh = (uint64_t) lines;
    }
    if (uh > H)
        uh = H;
    /* with the AOVs a run commonly adds (16): a header check, not a
     * budget of the run */
    const uint64_t bytes = uw * uh * ((uint64_t) cl->num_channels + 16 + 1) * 4 * 2;
    if (bytes > EF_WORKER_BYTES)
        return ef_fail(err, "part %d would need %.1f GiB per worker for one %s of %llu x %llu "
                            "pixels and %d channels, over exrfog's limit of %.0f GiB per worker "
                            "buffer: the header is probably corrupt (or re-chunk the file, e.g. "
                            "oiiotool IN --tile 64 64 -o OUT)",
                       p, (double) bytes / (1u << 30), st == EXR_STORAGE_TILED ? "tile" : "chunk",
                       (unsigned long long) uw, (unsigned long long) uh, cl->num_channels,
                       (double) EF_WORKER_BYTES / (1u << 30));
    return 0;
}

static int32_t le32(const unsigned char *b)
{
    return (int32_t) ((uint32_t) b[0] | (uint32_t) b[1] << 8 | (uint32_t) b[2] << 16 |
                      (uint32_t) b[3] << 24);
}

/* When Core refuses a header, look for window boxes it found absurd so the
 * message can say so (Core rejects coordinates near INT32_MAX itself). */
static int explain_bad_windows(const char *path, ef_err *err)
{
    static const char *const names[2] = { "dataWindow", "displayWindow" };
    unsigned char buf[65536];
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return 0;
    size_t n = fread(buf, 1, sizeof buf, fp);
    fclose(fp);
    for (int k = 0; k < 2; ++k) {
        char key[32];
        size_t klen = (size_t) snprintf(key, sizeof key, "%s%cbox2i", names[k], 0) + 1;
        for (size_t i = 0; i + klen + 20 <= n; ++i) {
            if (memcmp(buf + i, key, klen))
                continue;
            const unsigned char *b = buf + i + klen + 4;
            int64_t w = (int64_t) le32(b + 8) - le32(b) + 1, h = (int64_t) le32(b + 12) - le32(b + 4) + 1;
            if (w < 1 || h < 1 || w > EF_MAX_DIMENSION || h > EF_MAX_DIMENSION)
                return ef_fail(err, "absurd %s (%d,%d)-(%d,%d), %lld x %lld pixels (exrfog caps "
                                    "each side at %d; the header is probably corrupt)",
                               names[k], le32(b), le32(b + 4), le32(b + 8), le32(b + 12),
                               (long long) w, (long long) h, EF_MAX_DIMENSION);
        }
    }
    return 0;
}

/* The attributes every part of a multi-part file must share (OpenEXR's
 * "non-conforming shared attributes"): the C++ library refuses files where
 * they differ, so exrfog must neither read them as valid nor write them. */
static int check_shared(const ef_exr_file *f, ef_err *err)
{
    exr_attr_box2i_t d0, d;
    float a0 = 1, a = 1;
    if (f->nparts < 2 || exr_get_display_window(f->ctx, 0, &d0))
        return 0;
    exr_get_pixel_aspect_ratio(f->ctx, 0, &a0);
    for (int p = 1; p < f->nparts; ++p) {
        if (exr_get_display_window(f->ctx, p, &d) == EXR_ERR_SUCCESS &&
            (d.min.x != d0.min.x || d.min.y != d0.min.y || d.max.x != d0.max.x ||
             d.max.y != d0.max.y))
            return ef_fail(err, "parts 0 and %d have different display windows ((%d,%d)-(%d,%d) "
                                "and (%d,%d)-(%d,%d)); every part of a multi-part file must share "
                                "it (OpenEXR refuses such files: non-conforming shared "
                                "attributes); fix the file, e.g. split its parts with exrmultipart "
                                "-separate",
                           p, d0.min.x, d0.min.y, d0.max.x, d0.max.y, d.min.x, d.min.y, d.max.x,
                           d.max.y);
        if (exr_get_pixel_aspect_ratio(f->ctx, p, &a) == EXR_ERR_SUCCESS && a != a0)
            return ef_fail(err, "parts 0 and %d have different pixelAspectRatio (%g and %g); every "
                                "part of a multi-part file must share it (OpenEXR refuses such "
                                "files: non-conforming shared attributes); fix the file, e.g. split "
                                "its parts with exrmultipart -separate",
                           p, (double) a0, (double) a);
    }
    return 0;
}

int ef_exr_open(const char *path, ef_exr_file *f, ef_err *err)
{
    struct stat sb;
    memset(f, 0, sizeof *f);
    f->path = path;
    if (stat(path, &sb) != 0)
        return ef_fail(err, "cannot open: %s", strerror(errno));
    if (S_ISDIR(sb.st_mode))
        return ef_fail(err, "is a directory, not an EXR file");
    if (!S_ISREG(sb.st_mode))
        return ef_fail(err, "is %s, not a regular file: exrfog reads EXR files that it can seek "
                            "in (copy the stream to a file first)",
                       S_ISFIFO(sb.st_mode)  ? "a FIFO (named pipe)"
                       : S_ISCHR(sb.st_mode) ? "a character device"
                       : S_ISBLK(sb.st_mode) ? "a block device"
                       : S_ISSOCK(sb.st_mode) ? "a socket"
                                              : "not a regular file");
    if (sb.st_size == 0)
        return ef_fail(err, "the file is empty (0 bytes), not an EXR image");
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return ef_fail(err, "cannot open: %s", strerror(errno));
    unsigned char magic[4] = { 0 };
    size_t got = fread(magic, 1, 4, fp);
    fclose(fp);
    if (got < 4 || magic[0] != 0x76 || magic[1] != 0x2f || magic[2] != 0x31 || magic[3] != 0x01)
        return ef_fail(err, "not an OpenEXR file (wrong magic number)");

    exr_context_initializer_t init;
    ef_exr_init_context(&init);
    last_core_msg[0] = '\0';
    exr_result_t rv = exr_start_read(&f->ctx, path, &init);
    if (rv != EXR_ERR_SUCCESS) {
        f->ctx = NULL;
        if (explain_bad_windows(path, err))
            return -1;
        return ef_fail(err, "cannot read the EXR header, the file is truncated or corrupt: %s",
                       last_core_msg[0] ? last_core_msg : exr_get_error_code_as_string(rv));
    }
    if (last_core_msg[0]) {
        /* Core read the header but complained (e.g. a required attribute of
         * the wrong type): trusting such a header leads to silent damage. */
        ef_exr_close(f);
        return ef_fail(err, "the EXR header is corrupt: %s", last_core_msg);
    }
    if (exr_get_count(f->ctx, &f->nparts) || f->nparts < 1) {
        ef_exr_close(f);
        return ef_fail(err, "the EXR has no image parts");
    }
    for (int p = 0; p < f->nparts; ++p)
        if (check_part(f, p, err)) {
            ef_exr_close(f);
            return -1;
        }
    if (check_shared(f, err)) {
        ef_exr_close(f);
        return -1;
    }
    return 0;
}

void ef_exr_close(ef_exr_file *f)
{
    if (f && f->ctx)
        exr_finish(&f->ctx);
    if (f)
        f->ctx = NULL;
}

int ef_exr_part_is_multilevel(const ef_exr_file *f, int p)
{
    exr_storage_t st;
    exr_tile_level_mode_t lm;
    if (exr_get_storage(f->ctx, p, &st) || st != EXR_STORAGE_TILED)
        return 0;
    return exr_get_tile_descriptor(f->ctx, p, NULL, NULL, &lm, NULL) == EXR_ERR_SUCCESS &&
           lm != EXR_TILE_ONE_LEVEL;
}

/* Reads an m44f or m44d attribute; absent attributes leave out unset. */
static int get_mat(const ef_exr_file *f, int p, const char *name, ef_opt_mat *out, ef_err *err)
{
    const exr_attribute_t *a;
    if (exr_get_attribute_by_name(f->ctx, p, name, &a) != EXR_ERR_SUCCESS)
        return 0;
    if (a->type == EXR_ATTR_M44F)
        for (int i = 0; i < 16; ++i)
            out->v.m[i] = a->m44f->m[i];
    else if (a->type == EXR_ATTR_M44D)
        for (int i = 0; i < 16; ++i)
            out->v.m[i] = a->m44d->m[i];
    else
        return ef_fail(err, "attribute '%s' has type %s, expected m44f or m44d", name, a->type_name);
    out->set = 1;
    return 0;
}

/* Reads a float, double or int attribute as a number. */
static int get_num(const ef_exr_file *f, int p, const char *name, ef_opt_num *out, ef_err *err)
{
    const exr_attribute_t *a;
    if (exr_get_attribute_by_name(f->ctx, p, name, &a) != EXR_ERR_SUCCESS)
        return 0;
    if (a->type == EXR_ATTR_FLOAT)
        out->v = a->f;
    else if (a->type == EXR_ATTR_DOUBLE)
        out->v = a->d;
    else if (a->type == EXR_ATTR_INT)
        out->v = a->i;
    else
        return ef_fail(err, "attribute '%s' has type %s, expected a number", name, a->type_name);
    out->set = 1;
    return 0;
}

/* Names of the attributes beyond the required ones, for "no camera" messages. */
static void list_other_attrs(const ef_exr_file *f, int p, char *out, size_t len)
{
    static const char *const required[] = { "channels", "compression", "dataWindow", "displayWindow",
                                            "lineOrder", "pixelAspectRatio", "screenWindowCenter",
                                            "screenWindowWidth", "tiles", "type", "name", "version",
                                            "chunkCount", NULL };
    int32_t n = 0;
    out[0] = '\0';
    exr_get_attribute_count(f->ctx, p, &n);
    for (int32_t i = 0; i < n; ++i) {
        const exr_attribute_t *a;
        int skip = 0;
        if (exr_get_attribute_by_index(f->ctx, p, EXR_ATTR_LIST_SORTED_ORDER, i, &a))
            continue;
        for (int k = 0; required[k]; ++k)
            skip |= !strcmp(a->name, required[k]);
        size_t at = strlen(out);
        if (skip || at + strlen(a->name) + 8 >= len)
            continue;
        snprintf(out + at, len - at, "%s%s", at ? ", " : "", a->name);
    }
}

int ef_exr_read_cam_meta(const ef_exr_file *f, int p, ef_cam_meta *m, ef_err *err)
{
    exr_attr_box2i_t disp;
    float pa = 1.0f;
    if (exr_get_display_window(f->ctx, p, &disp))
        return ef_fail(err, "part %d has no display window", p);
    ef_cam_meta_init(m, disp.min.x, disp.min.y, disp.max.x, disp.max.y);
    if (exr_get_pixel_aspect_ratio(f->ctx, p, &pa) == EXR_ERR_SUCCESS && isfinite(pa) && pa > 0)
        m->pixel_aspect = pa;
    list_other_attrs(f, p, m->other_attrs, sizeof m->other_attrs);
    return get_mat(f, p, "worldToCamera", &m->w2c, err) ||
           get_mat(f, p, "worldToNDC", &m->w2ndc, err) ||
           get_mat(f, p, "worldToScreen", &m->w2screen, err) ||
           get_num(f, p, "CameraFov", &m->arnold_fov, err) ||
           get_num(f, p, "arnold/camera/near_clip", &m->arnold_near, err) ||
           get_num(f, p, "arnold/camera/far_clip", &m->arnold_far, err) ||
           get_mat(f, p, "cameraTransform", &m->vray_c2w, err) ||
           get_num(f, p, "cameraFov", &m->vray_fov, err) ||
           get_num(f, p, "cameraNearClip", &m->vray_near, err) ||
           get_num(f, p, "cameraFarClip", &m->vray_far, err) ||
           get_mat(f, p, "rs/camera/transform", &m->rs_c2w, err) ||
           get_num(f, p, "rs/camera/fov", &m->rs_fov, err) ||
           get_num(f, p, "rs/camera/nearPlane", &m->rs_near, err) ||
           get_num(f, p, "rs/camera/farPlane", &m->rs_far, err)
               ? -1
               : 0;
}

int ef_exr_has_attr(const ef_exr_file *f, int part, const char *name)
{
    const exr_attribute_t *a;
    return exr_get_attribute_by_name(f->ctx, part, name, &a) == EXR_ERR_SUCCESS;
}
