/* Shadow maps from files (shadow_file.h). */
#include "shadow_file.h"

#include "exr_io.h"
#include "exr_parts.h"
#include "shadow.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The depth channel of part p: Z, depth.Z, depth, Depth, then the first
 * *.Z; -1 when none. */
static int depth_channel(const ef_exr_file *f, int p)
{
    const exr_attr_chlist_t *cl;
    if (exr_get_channels(f->ctx, p, &cl))
        return -1;
    static const char *const names[] = { "Z", "depth.Z", "depth", "Depth" };
    for (int k = 0; k < 4; ++k)
        for (int i = 0; i < cl->num_channels; ++i)
            if (!strcmp(cl->entries[i].name.str, names[k]))
                return i;
    for (int i = 0; i < cl->num_channels; ++i) {
        const char *n = cl->entries[i].name.str;
        const size_t len = strlen(n);
        if (len > 2 && !strcmp(n + len - 2, ".Z"))
            return i;
    }
    return -1;
}

int ef_shadow_load(const char *path, const struct ef_shadow_opts *o, struct ef_shadow **out,
                   ef_err *err)
{
    ef_exr_file f;
    *out = NULL;
    if (ef_exr_open(path, &f, err)) {
        ef_err_set_file(err, path);
        return -1;
    }
    int part = -1, chan = -1;
    for (int p = 0; p < f.nparts && chan < 0; ++p)
        if ((chan = depth_channel(&f, p)) >= 0)
            part = p;
    ef_cam_meta meta;
    exr_attr_box2i_t dw;
    int rc = -1;
    float *depth = NULL;
    int *ys = NULL;
    if (chan >= 0 && ef_exr_part_is_deep(&f, part)) {
        ef_fail(err, "the shadow map is a deep image; a map is a flat depth render of the "
                "light's view (render it without deep output, or flatten it first)");
    } else if (chan < 0) {
        ef_fail(err, "no depth channel (Z, depth.Z, depth or *.Z) in the shadow map: render "
                "the light's view with its depth (Z) pass");
    } else if (ef_exr_read_cam_meta(&f, part, &meta, err) == 0 &&
               exr_get_data_window(f.ctx, part, &dw) == EXR_ERR_SUCCESS) {
        const int h = dw.max.y - dw.min.y + 1;
        int w = 0;
        const double texels = ((double) dw.max.x - dw.min.x + 1) * h * (1.0 + o->copies);
        if (!(texels <= EF_SHADOW_MAX_TEXELS)) {
            ef_fail(err, "the shadow map's %d x %d texels%s come to %.3g over the map%s, past "
                    "the limit of %.0f (12 to 26 bytes each; see LIMITS): render the map "
                    "smaller%s",
                    dw.max.x - dw.min.x + 1, h,
                    o->copies ? " times its penumbra's copies" : "", texels,
                    o->copies ? " and its copies" : "", EF_SHADOW_MAX_TEXELS,
                    o->copies ? " or lower penumbra=" : "");
        } else if (!(ys = malloc((size_t) h * sizeof *ys)) ||
            ef_exr_sample_rows(&f, part, chan, h, &depth, &w, ys) != h) {
            ef_fail(err, "cannot read the shadow map's depth channel (damaged or out of "
                    "memory)");
        } else {
            ef_shadow_src src;
            memset(&src, 0, sizeof src);
            src.path = path;
            src.width = w;
            src.height = h;
            src.dw[0] = dw.min.x;
            src.dw[1] = dw.min.y;
            memcpy(src.disp, meta.disp, sizeof src.disp);
            src.depth = depth;
            src.has_w2c = meta.w2c.set;
            src.w2c = meta.w2c.v;
            const int scr = meta.w2screen.set;
            src.has_proj = scr || meta.w2ndc.set;
            src.proj = scr ? meta.w2screen.v : meta.w2ndc.v;
            src.proj_name = scr ? "worldToScreen" : "worldToNDC";
            *out = ef_shadow_build(&src, o, err);
            rc = *out ? 0 : -1;
        }
    }
    free(depth);
    free(ys);
    ef_exr_close(&f);
    if (rc)
        ef_err_set_file(err, path);
    return rc;
}
