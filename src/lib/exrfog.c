/* libexrfog: the public API (include/exrfog.h) over the core, the I/O
 * adapters and the command line's run. */
#include "exrfog.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "apply.h"
#include "camera.h"
#include "depth.h"
#include "exr_io.h"
#include "run.h"
#include "scene.h"
#include "scene_file.h"

struct exrfog_context {
    char error[2048];
    exrfog_progress_fn progress;
    void *progress_user;
    int print;
};

struct exrfog_scene {
    ef_fog_scene s;
};

struct exrfog_camera {
    ef_camera cam;
};

const char *exrfog_version(void)
{
    return EXRFOG_VERSION;
}

exrfog_context *exrfog_context_create(void)
{
    return calloc(1, sizeof(exrfog_context));
}

void exrfog_context_destroy(exrfog_context *ctx)
{
    free(ctx);
}

const char *exrfog_error(const exrfog_context *ctx)
{
    return ctx ? ctx->error : "no context";
}

void exrfog_set_progress(exrfog_context *ctx, exrfog_progress_fn fn, void *user)
{
    ctx->progress = fn;
    ctx->progress_user = user;
}

void exrfog_set_print(exrfog_context *ctx, int print)
{
    ctx->print = print;
}

/* Records err as the context's failure ("FILE: message" when it names a
 * file) and returns result; prints it too when the context says so. */
static exrfog_result fail(exrfog_context *ctx, const ef_err *err, const char *file,
                          exrfog_result result)
{
    const char *f = err->file ? err->file : file;
    if (f)
        snprintf(ctx->error, sizeof ctx->error, "%s: %s", f, err->msg);
    else
        snprintf(ctx->error, sizeof ctx->error, "%s", err->msg);
    if (ctx->print)
        fprintf(stderr, "exrfog: %s\n", ctx->error);
    return result;
}

exrfog_result exrfog_scene_create(exrfog_context *ctx, const char *const *specs, int nspecs,
                                  const char *scene_file, const double *color, exrfog_scene **out)
{
    ef_err err = { 0 };
    *out = NULL;
    ctx->error[0] = '\0';
    exrfog_scene *sc = calloc(1, sizeof *sc);
    if (!sc)
        return ef_fail(&err, "out of memory"), fail(ctx, &err, NULL, EXRFOG_ERROR);
    ef_scene_init(&sc->s);
    sc->s.ctx.read_file = ef_read_text_file;
    if (scene_file) {
        ef_scene_file sf;
        memset(&sf, 0, sizeof sf);
        if (ef_scene_file_read(scene_file, &sf, &err)) {
            free(sc);
            return fail(ctx, &err, scene_file, EXRFOG_ERROR);
        }
        if (sf.has_color)
            memcpy(sc->s.color, sf.color, sizeof sc->s.color);
        if (sf.has_up)
            memcpy(sc->s.ctx.up, sf.up, sizeof sc->s.ctx.up);
        if (sf.has_units)
            sc->s.ctx.units_per_meter = sf.units;
        if (sf.has_time)
            sc->s.ctx.time = sf.time;
        int bad = sf.has_sky && ef_scene_parse_sky(&sc->s, sf.sky, &err);
        for (int i = 0; !bad && i < sf.nspec; ++i)
            bad = ef_scene_add(&sc->s, sf.specs[i], &err) != 0;
        ef_scene_file_free(&sf);
        if (bad) {
            exrfog_scene_destroy(sc);
            return fail(ctx, &err, scene_file, EXRFOG_ERROR);
        }
    }
    for (int i = 0; i < nspecs; ++i)
        if (ef_scene_add(&sc->s, specs[i], &err)) {
            exrfog_scene_destroy(sc);
            return fail(ctx, &err, NULL, err.file ? EXRFOG_ERROR : EXRFOG_USAGE);
        }
    if (sc->s.ncomp == 0) {
        exrfog_scene_destroy(sc);
        ef_fail(&err, "no fog given (a SPEC such as exp:density=0.02, or a scene file)");
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    if (color) {
        for (int k = 0; k < 3; ++k)
            if (!(color[k] >= 0 && color[k] <= EF_COLOR_MAX)) {
                exrfog_scene_destroy(sc);
                ef_fail(&err, "fog colour %g,%g,%g is not three numbers from 0 to %g", color[0],
                        color[1], color[2], EF_COLOR_MAX);
                return fail(ctx, &err, NULL, EXRFOG_USAGE);
            }
        memcpy(sc->s.color, color, sizeof sc->s.color);
    }
    *out = sc;
    return EXRFOG_OK;
}

void exrfog_scene_destroy(exrfog_scene *scene)
{
    if (!scene)
        return;
    ef_scene_free(&scene->s);
    free(scene);
}

exrfog_result exrfog_camera_from_matrix(exrfog_context *ctx, const double camera_to_world[16],
                                        const char *convention, double hfov_deg,
                                        const int display_window[4], exrfog_camera **out)
{
    ef_err err = { 0 };
    ef_cam_meta meta;
    ef_cam_flags flags;
    *out = NULL;
    ctx->error[0] = '\0';
    memset(&flags, 0, sizeof flags);
    if (ef_cam_convention_parse(convention ? convention : "exr", &flags.convention)) {
        ef_fail(&err, "camera convention '%s' is not one of exr, blender, nuke, maya, houdini, usd",
                convention);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    if (display_window[2] < display_window[0] || display_window[3] < display_window[1]) {
        ef_fail(&err, "the display window (%d,%d)-(%d,%d) is empty", display_window[0],
                display_window[1], display_window[2], display_window[3]);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    ef_cam_meta_init(&meta, display_window[0], display_window[1], display_window[2],
                     display_window[3]);
    flags.c2w.set = 1;
    memcpy(flags.c2w.v.m, camera_to_world, sizeof flags.c2w.v.m);
    flags.fov.set = 1;
    flags.fov.v = hfov_deg;
    exrfog_camera *c = calloc(1, sizeof *c);
    if (!c)
        return ef_fail(&err, "out of memory"), fail(ctx, &err, NULL, EXRFOG_ERROR);
    if (ef_camera_resolve(&meta, &flags, &c->cam, &err)) {
        free(c);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    *out = c;
    return EXRFOG_OK;
}

exrfog_result exrfog_camera_from_file(exrfog_context *ctx, const char *path, exrfog_camera **out)
{
    ef_err err = { 0 };
    ef_exr_file f = { 0 };
    ef_channel_plan plan;
    ef_cam_meta meta;
    ef_cam_flags flags;
    *out = NULL;
    ctx->error[0] = '\0';
    memset(&flags, 0, sizeof flags);
    exrfog_camera *c = calloc(1, sizeof *c);
    if (!c)
        return ef_fail(&err, "out of memory"), fail(ctx, &err, path, EXRFOG_ERROR);
    if (ef_exr_open(path, &f, &err) || ef_find_channels(&f, &f, NULL, NULL, &plan, &err) ||
        ef_exr_read_cam_meta(&f, plan.rgb[0].part, &meta, &err) ||
        ef_camera_resolve(&meta, &flags, &c->cam, &err)) {
        ef_exr_close(&f);
        free(c);
        return fail(ctx, &err, path, EXRFOG_ERROR);
    }
    ef_exr_close(&f);
    *out = c;
    return EXRFOG_OK;
}

void exrfog_camera_position(const exrfog_camera *cam, double pos[3])
{
    memcpy(pos, cam->cam.pos, 3 * sizeof *pos);
}

void exrfog_camera_destroy(exrfog_camera *cam)
{
    free(cam);
}

exrfog_result exrfog_fog_pixels(exrfog_context *ctx, const exrfog_scene *scene,
                                const exrfog_camera *cam, exrfog_image *img)
{
    ef_err err = { 0 };
    ctx->error[0] = '\0';
    if (!img || img->size < sizeof *img) {
        ef_fail(&err, "exrfog_image.size is %zu, not %zu: the caller was built against another "
                      "exrfog.h", img ? img->size : (size_t) 0, sizeof *img);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    if (img->width < 0 || img->height < 0 || img->stride < img->width || !img->rgb[0] ||
        !img->rgb[1] || !img->rgb[2] || !img->depth) {
        ef_fail(&err, "the image needs width, height >= 0, stride >= width, and R, G, B and depth "
                      "planes");
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    ef_depth_mode mode = EF_DEPTH_PLANAR;
    if (img->depth_mode && ef_depth_mode_parse(img->depth_mode, &mode)) {
        ef_fail(&err, "depth mode '%s' is not one of planar, radial, inverse, normalized, gl-ndc, "
                      "gl-window, zero-one, reversed, reversed-infinite", img->depth_mode);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    ef_depth_conv conv;
    if (ef_depth_conv_init(&conv, mode, &cam->cam, &err))
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    /* The scene is bound to this camera on a private copy: the caller's
     * stays read-only, so threads may share it. */
    ef_fog_scene bound = scene->s;
    bound.ncomp = 0;
    for (int i = 0; i < scene->s.ncomp; ++i)
        if (ef_scene_add(&bound, scene->s.comp[i].spec, &err)) {
            ef_scene_free(&bound);
            return fail(ctx, &err, NULL, EXRFOG_ERROR);
        }
    ef_scene_bind(&bound, cam->cam.pos);
    const ef_fog_pass pass = { &cam->cam, &conv, &bound };
    unsigned mask = 0;
    mask |= img->T[0] ? EF_AOV_T : 0;
    mask |= img->error[0] ? EF_AOV_ERROR : 0;
    mask |= img->P[0] ? EF_AOV_P : 0;
    /* Row by row: the core fogs contiguous rows; the caller's have a stride. */
    for (int y = 0; y < img->height; ++y) {
        const ptrdiff_t o = (ptrdiff_t) y * img->stride;
        float *const rgb[3] = { img->rgb[0] + o, img->rgb[1] + o, img->rgb[2] + o };
        float *planes[EF_AOV_MAX_CHANNELS] = { NULL };
        int n = 0;
        if (mask & EF_AOV_T)
            for (int k = 0; k < 3; ++k)
                planes[n++] = img->T[k] + o;
        if (mask & EF_AOV_ERROR)
            for (int k = 0; k < 3; ++k)
                planes[n++] = img->error[k] + o;
        if (mask & EF_AOV_P)
            for (int k = 0; k < 3; ++k)
                planes[n++] = img->P[k] + o;
        ef_aov_out aov;
        ef_aov_bind(&aov, mask, planes);
        ef_fog_block_aov(&pass, img->x0, img->y0 + y, img->width, 1, rgb,
                         img->alpha ? img->alpha + o : NULL, img->depth + o, mask ? &aov : NULL,
                         NULL);
    }
    ef_scene_free(&bound);
    return EXRFOG_OK;
}

exrfog_result exrfog_run(exrfog_context *ctx, int argc, const char *const *argv)
{
    ctx->error[0] = '\0';
    /* getopt permutes its argv: work on a copy the caller never sees. */
    char **args = calloc((size_t) argc + 1, sizeof *args);
    if (!args) {
        snprintf(ctx->error, sizeof ctx->error, "out of memory");
        return EXRFOG_ERROR;
    }
    for (int i = 0; i < argc; ++i)
        args[i] = (char *) argv[i];
    FILE *sink = ctx->print ? NULL : fopen("/dev/null", "w");
    const int rc = ef_run_lib(argc, args, ctx->print ? NULL : sink, NULL, ctx->progress,
                              ctx->progress_user, ctx->error, sizeof ctx->error);
    if (sink)
        fclose(sink);
    free(args);
    return rc == 0 ? EXRFOG_OK : rc == 2 ? EXRFOG_USAGE : rc == 3 ? EXRFOG_CANCELLED : EXRFOG_ERROR;
}

exrfog_result exrfog_explain(exrfog_context *ctx, int argc, const char *const *argv, char **json)
{
    *json = NULL;
    ctx->error[0] = '\0';
    char **args = calloc((size_t) argc + 3, sizeof *args);
    char *buf = NULL;
    size_t len = 0;
    FILE *mem = open_memstream(&buf, &len);
    FILE *sink = ctx->print ? NULL : fopen("/dev/null", "w");
    if (!args || !mem) {
        free(args);
        if (mem)
            fclose(mem);
        free(buf);
        if (sink)
            fclose(sink);
        snprintf(ctx->error, sizeof ctx->error, "out of memory");
        return EXRFOG_ERROR;
    }
    for (int i = 0; i < argc; ++i)
        args[i] = (char *) argv[i];
    args[argc] = (char *) "--explain";
    args[argc + 1] = (char *) "--json";
    const int rc = ef_run_lib(argc + 2, args, ctx->print ? NULL : sink, mem, NULL, NULL,
                              ctx->error, sizeof ctx->error);
    fclose(mem);
    if (sink)
        fclose(sink);
    free(args);
    if (rc) {
        free(buf);
        return rc == 2 ? EXRFOG_USAGE : EXRFOG_ERROR;
    }
    *json = buf;
    return EXRFOG_OK;
}

void exrfog_free(void *p)
{
    free(p);
}
