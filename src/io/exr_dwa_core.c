/* The Core side of the DWA support: which parts of a file are DWA. */
#include "exr_dwa.h"
#include "exr_io.h"

static int count_dwa(exr_context_t ctx, int nparts)
{
    int n = 0;
    for (int p = 0; p < nparts; ++p) {
        exr_compression_t c;
        if (exr_get_compression(ctx, p, &c) == EXR_ERR_SUCCESS &&
            (c == EXR_COMPRESSION_DWAA || c == EXR_COMPRESSION_DWAB))
            ++n;
    }
    return n;
}

int ef_exr_dwa_parts(const ef_exr_file *f)
{
    return f && f->ctx ? count_dwa(f->ctx, f->nparts) : 0;
}

int ef_exr_dwa_info(const char *path, ef_dwa_info *info, ef_err *err)
{
    exr_context_initializer_t init;
    ef_exr_init_context(&init);
    exr_context_t ctx = NULL;
    info->nparts = info->ndwa = info->mixed = 0;
    info->compression = -1;
    info->level = -1.0f;
    if (exr_start_read(&ctx, path, &init) != EXR_ERR_SUCCESS ||
        exr_get_count(ctx, &info->nparts) != EXR_ERR_SUCCESS) {
        ef_fail(err, "cannot read the EXR headers of %s: %s", path, ef_exr_last_core_message());
        exr_finish(&ctx);
        return -1;
    }
    for (int p = 0; p < info->nparts; ++p) {
        exr_compression_t c;
        if (exr_get_compression(ctx, p, &c) != EXR_ERR_SUCCESS ||
            (c != EXR_COMPRESSION_DWAA && c != EXR_COMPRESSION_DWAB))
            continue;
        /* the first DWA part's kind and level stand for the file's */
        if (info->ndwa++ == 0) {
            float l;
            info->compression = (int) c;
            if (exr_attr_get_float(ctx, p, "dwaCompressionLevel", &l) == EXR_ERR_SUCCESS && l > 0)
                info->level = l;
        } else if ((int) c != info->compression) {
            info->mixed = 1;
        }
    }
    exr_finish(&ctx);
    return 0;
}

int ef_exr_dwa_parts_path(const char *path, ef_err *err)
{
    exr_context_initializer_t init;
    ef_exr_init_context(&init);
    exr_context_t ctx = NULL;
    int nparts = 0;
    if (exr_start_read(&ctx, path, &init) != EXR_ERR_SUCCESS ||
        exr_get_count(ctx, &nparts) != EXR_ERR_SUCCESS) {
        ef_fail(err, "cannot read the EXR headers of %s: %s", path, ef_exr_last_core_message());
        exr_finish(&ctx);
        return -1;
    }
    int n = count_dwa(ctx, nparts);
    exr_finish(&ctx);
    return n;
}
