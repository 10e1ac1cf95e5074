/* Shadow maps from files (shadow_file.h). */
#include "shadow_file.h"

#include "camera_file.h"
#include "exr_io.h"
#include "exr_parts.h"
#include "shadow.h"

#include <math.h>
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

/* The map's camera from a camera file (shadow-camera=) in place of its
 * header's: its one frame's pose, and ortho_width (a sun's orthographic
 * map, that many scene units across the display window) or a perspective
 * lens (a spot's), into meta as worldToCamera and worldToScreen (centre
 * 0,0, y up, +-1 over the display window), the header's own matrices
 * dropped. Read before the texels. Returns 0, or -1 with a message naming
 * the file. */
static int map_camera(const char *file, ef_cam_meta *meta, ef_err *err)
{
    ef_camera_file *cf;
    if (ef_camera_file_read(file, EF_CONV_EXR, &cf, err))
        return -1;
    double first, last;
    int n;
    ef_camera_file_frames(cf, &first, &last, &n);
    ef_cam_flags fl;
    memset(&fl, 0, sizeof fl);
    int rc = 0;
    if (n != 1)
        rc = ef_fail(err, "the shadow map's camera file holds %d frames; a map is rendered once, "
                     "from one camera: give that one frame", n);
    else
        rc = ef_camera_file_frame(cf, first, &fl, err);
    ef_camera_file_free(cf);
    const int ortho = fl.ortho_width.set;
    const double width = fl.ortho_width.v;
    if (!rc && ortho) {
        fl.ortho_width.set = 0;   /* the pose resolves as a perspective one's */
        fl.vfov.set = 0;
        fl.fov.set = 1;
        fl.fov.v = 90;
    } else if (!rc && !fl.fov.set && !fl.vfov.set) {
        rc = ef_fail(err, "the shadow map's camera file gives no lens: ortho_width (scene units "
                     "across the map) for a sun's orthographic map, or fov, vfov or "
                     "focal_length for a spot's perspective one");
    }
    ef_camera cam;
    if (!rc && ef_camera_resolve(meta, &fl, &cam, err))
        rc = -1;
    if (rc) {
        ef_err_set_file(err, file);
        return -1;
    }
    ef_mat4 c2w, P, w2c;
    memset(&c2w, 0, sizeof c2w);
    memset(&P, 0, sizeof P);
    for (int r = 0; r < 3; ++r) {
        for (int j = 0; j < 3; ++j)
            c2w.m[4 * r + j] = cam.rot[3 * r + j] * cam.unit;
        c2w.m[12 + r] = cam.pos[r];
    }
    c2w.m[15] = 1;
    if (ef_mat4_invert(&c2w, &w2c)) {
        ef_fail(err, "the shadow map's camera pose is singular");
        ef_err_set_file(err, file);
        return -1;
    }
    /* half the view across and up: the display window's shape with its
     * pixel aspect */
    const double Wd = meta->disp[2] - meta->disp[0] + 1.0, Hd = meta->disp[3] - meta->disp[1] + 1.0;
    const double hx = ortho ? width / 2 : tan(cam.hfov_deg * (3.14159265358979323846 / 360));
    const double hy = hx * Hd / (Wd * meta->pixel_aspect);
    P.m[0] = 1 / hx;
    P.m[5] = 1 / hy;
    P.m[10] = 1;
    if (ortho)
        P.m[15] = 1;
    else
        P.m[11] = 1;
    meta->w2c.set = meta->w2screen.set = 1;
    meta->w2ndc.set = 0;
    meta->w2c.v = w2c;
    ef_mat4_mul(&w2c, &P, &meta->w2screen.v);
    return 0;
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
    int rc = -1, named = 0;   /* named: the message names the camera file */
    float *depth = NULL;
    int *ys = NULL;
    if (chan >= 0 && ef_exr_part_is_deep(&f, part)) {
        ef_fail(err, "the shadow map is a deep image; a map is a flat depth render of the "
                "light's view (render it without deep output, or flatten it first)");
    } else if (chan < 0) {
        ef_fail(err, "no depth channel (Z, depth.Z, depth or *.Z) in the shadow map: render "
                "the light's view with its depth (Z) pass");
    } else if (ef_exr_read_cam_meta(&f, part, &meta, err) == 0 &&
               exr_get_data_window(f.ctx, part, &dw) == EXR_ERR_SUCCESS &&
               !(o->camera && (named = map_camera(o->camera, &meta, err) != 0))) {
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
    if (rc && !named)
        ef_err_set_file(err, path);
    return rc;
}
