/* libexrfog: the public API (include/exrfog.h), a thin ABI over the job
 * layer (whole runs) and the core (pixels). It keeps nothing per process:
 * every call's state is in its context, scene, camera or job. */
#include "exrfog.h"

#include <limits.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "apply.h"
#include "camera.h"
#include "depth.h"
#include "exr_io.h"
#include "job.h"
#include "scene.h"
#include "scene_build.h"

struct exrfog_context {
    char error[2048];
    exrfog_progress_fn progress;
    void *progress_user;
    exrfog_warning_fn warning;
    void *warning_user;
    int print;
    _Atomic int cancel;       /* exrfog_cancel: read by the run in progress */
    /* exrfog_fog_pixels's buffers, kept between calls (a context is one
     * thread's): the scene bound to the call's camera, small rectangles
     * gathered into contiguous planes, a row for unwanted AOV planes. */
    ef_fog_scene *bound;
    uint64_t bound_scene, bound_cam;   /* the tags it was made from (0: none) */
    float *gather, *scratch;
    size_t gather_cap, scratch_cap;
};

/* An object's identity for the context's cache: its address and the time
 * it was made, so a new object at a freed one's address differs. */
static uint64_t new_tag(const void *p)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    const uint64_t t = (uint64_t) ts.tv_sec * 1000000000u + (uint64_t) ts.tv_nsec;
    return (t * 0x9e3779b97f4a7c15u ^ (uint64_t) (uintptr_t) p) | 1u;
}

/* A built scene: immutable once made. The colour state is kept only
 * because the scene's context points at it (nothing re-reads colours). */
struct exrfog_scene {
    ef_fog_scene s;
    ef_colour colour;
    uint64_t tag;
};

struct exrfog_camera {
    ef_camera cam;
    uint64_t tag;
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
    if (!ctx)
        return;
    if (ctx->bound)
        ef_scene_free(ctx->bound);
    free(ctx->bound);
    free(ctx->gather);
    free(ctx->scratch);
    free(ctx);
}

const char *exrfog_error(const exrfog_context *ctx)
{
    return ctx ? ctx->error : "no context (exrfog_context_create returned NULL?)";
}

/* Records a usage error of the API itself (a NULL argument...) in ctx when
 * there is one, prints it when asked, and returns EXRFOG_USAGE. */
static exrfog_result misuse(exrfog_context *ctx, const char *what)
{
    if (ctx) {
        snprintf(ctx->error, sizeof ctx->error, "%s", what);
        if (ctx->print)
            fprintf(stderr, "exrfog: %s\n", ctx->error);
    }
    return EXRFOG_USAGE;
}

exrfog_result exrfog_set_progress(exrfog_context *ctx, exrfog_progress_fn fn, void *user)
{
    if (!ctx)
        return misuse(ctx, "exrfog_set_progress: ctx is NULL");
    ctx->progress = fn;
    ctx->progress_user = user;
    return EXRFOG_OK;
}

exrfog_result exrfog_set_warning(exrfog_context *ctx, exrfog_warning_fn fn, void *user)
{
    if (!ctx)
        return misuse(ctx, "exrfog_set_warning: ctx is NULL");
    ctx->warning = fn;
    ctx->warning_user = user;
    return EXRFOG_OK;
}

exrfog_result exrfog_set_print(exrfog_context *ctx, int print)
{
    if (!ctx)
        return misuse(ctx, "exrfog_set_print: ctx is NULL");
    ctx->print = print;
    return EXRFOG_OK;
}

void exrfog_cancel(exrfog_context *ctx)
{
    if (ctx)
        atomic_store(&ctx->cancel, 1);
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
    if (out)
        *out = NULL;
    if (!ctx || !out || nspecs < 0 || (nspecs > 0 && !specs))
        return misuse(ctx, "exrfog_scene_create: ctx and out must not be NULL, and specs must "
                           "hold nspecs (>= 0) SPECs");
    for (int i = 0; i < nspecs; ++i)
        if (!specs[i])
            return misuse(ctx, "exrfog_scene_create: a SPEC is NULL");
    if (nspecs > EF_FOG_MAX_COMPONENTS)
        return misuse(ctx, "exrfog_scene_create: too many SPECs (at most 32)");
    ctx->error[0] = '\0';
    ef_err err = { 0 };
    exrfog_scene *sc = calloc(1, sizeof *sc);
    if (!sc)
        return ef_fail(&err, "out of memory"), fail(ctx, &err, NULL, EXRFOG_ERROR);
    ef_scene_init(&sc->s);
    ef_colour_setup(&sc->colour, NULL, NULL);
    ef_scene_desc d;
    memset(&d, 0, sizeof d);
    d.scene_file = scene_file;
    for (int i = 0; i < nspecs; ++i)
        d.specs[d.nspec++] = specs[i];
    ef_scene_found found;
    const ef_parse_result r = ef_scene_build(&sc->s, &d, &sc->colour, &found, &err);
    free(found.scene_text);
    /* Colours are final: nothing reads them again, so the config goes. */
    ef_colour_close(&sc->colour);
    if (r != EF_PARSE_RUN) {
        exrfog_scene_destroy(sc);
        return fail(ctx, &err, NULL, r == EF_PARSE_USAGE ? EXRFOG_USAGE : EXRFOG_ERROR);
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
    sc->tag = new_tag(sc);
    *out = sc;
    return EXRFOG_OK;
}

void exrfog_scene_destroy(exrfog_scene *scene)
{
    if (!scene)
        return;
    ef_scene_free(&scene->s);
    ef_colour_close(&scene->colour);
    free(scene);
}

int exrfog_scene_light_count(const exrfog_scene *scene)
{
    return scene ? scene->s.nlight : 0;
}

int exrfog_scene_has_sky_light(const exrfog_scene *scene)
{
    return scene && scene->s.sky_light != NULL;
}

const char *exrfog_scene_light_name(const exrfog_scene *scene, int i, int *shadowed)
{
    if (shadowed)
        *shadowed = 0;
    if (!scene || i < 0 || i >= scene->s.nlight)
        return NULL;
    if (shadowed)
        *shadowed = scene->s.light[i].shadow != NULL;
    return scene->s.light[i].name;
}

/* Whether a display window is non-empty and its size fits an int. */
static int window_ok(const int w[4])
{
    const int64_t dx = (int64_t) w[2] - w[0], dy = (int64_t) w[3] - w[1];
    return dx >= 0 && dy >= 0 && dx < INT_MAX && dy < INT_MAX;
}

exrfog_result exrfog_camera_from_matrix(exrfog_context *ctx, const double camera_to_world[16],
                                        const char *convention, double hfov_deg,
                                        const int display_window[4], exrfog_camera **out)
{
    if (out)
        *out = NULL;
    if (!ctx || !camera_to_world || !display_window || !out)
        return misuse(ctx, "exrfog_camera_from_matrix: ctx, camera_to_world, display_window "
                           "and out must not be NULL");
    ef_err err = { 0 };
    ef_cam_meta meta;
    ef_cam_flags flags;
    ctx->error[0] = '\0';
    memset(&flags, 0, sizeof flags);
    if (ef_cam_convention_parse(convention ? convention : "exr", &flags.convention)) {
        ef_fail(&err, "camera convention '%s' is not one of exr, blender, nuke, maya, houdini, usd",
                convention);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    if (!window_ok(display_window)) {
        ef_fail(&err, "the display window (%d,%d)-(%d,%d) is empty or wider than %d pixels",
                display_window[0], display_window[1], display_window[2], display_window[3],
                INT_MAX);
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
    c->tag = new_tag(c);
    *out = c;
    return EXRFOG_OK;
}

exrfog_result exrfog_camera_from_file(exrfog_context *ctx, const char *path, exrfog_camera **out)
{
    if (out)
        *out = NULL;
    if (!ctx || !path || !out)
        return misuse(ctx, "exrfog_camera_from_file: ctx, path and out must not be NULL");
    ef_err err = { 0 };
    ef_exr_file f = { 0 };
    ef_channel_plan plan;
    ef_cam_meta meta;
    ef_cam_flags flags;
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
    c->tag = new_tag(c);
    *out = c;
    return EXRFOG_OK;
}

exrfog_result exrfog_camera_position(const exrfog_camera *cam, double pos[3])
{
    if (!cam || !pos)
        return EXRFOG_USAGE;
    memcpy(pos, cam->cam.pos, 3 * sizeof *pos);
    return EXRFOG_OK;
}

void exrfog_camera_destroy(exrfog_camera *cam)
{
    free(cam);
}

/* Checks img's shape: planes given, sizes that fit, absolute pixels whose
 * coordinates stay in an int. */
static exrfog_result check_image(exrfog_context *ctx, const exrfog_image *img)
{
    ef_err err;
    err.file = NULL;
    if (img->width < 0 || img->height < 0 || img->stride < img->width || !img->rgb[0] ||
        !img->rgb[1] || !img->rgb[2] || !img->depth) {
        ef_fail(&err, "the image needs width, height >= 0, stride >= width, and R, G, B and depth "
                      "planes");
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    if ((int64_t) img->x0 + img->width > INT_MAX || (int64_t) img->y0 + img->height > INT_MAX ||
        img->x0 < -INT_MAX / 2 || img->y0 < -INT_MAX / 2) {
        ef_fail(&err, "the rectangle at (%d,%d) of %dx%d pixels leaves the range of pixel "
                      "coordinates", img->x0, img->y0, img->width, img->height);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    return EXRFOG_OK;
}

/* The core's view of the caller's planes: AOV planes in the order
 * ef_aov_channels gives, a missing plane of a wanted group pointed at
 * scratch (as long as one call of the core, reused). */
typedef struct rect_planes {
    float *rgb[3], *alpha;
    const float *depth;
    float *aov[EF_AOV_MAX_CHANNELS];
    int naov;
} rect_planes;

static void copy_row(float *restrict dst, const float *restrict src, int n)
{
    for (int i = 0; i < n; ++i)
        dst[i] = src[i];
}

/* Fogs w x h contiguous pixels (rows w long) at (x0, y0). */
static void fog_rect(const ef_fog_pass *pass, int x0, int y0, int w, int h, rect_planes *p,
                     unsigned mask)
{
    ef_aov_out aov;
    memset(&aov, 0, sizeof aov);   /* fog_P relative to the world's origin */
    ef_aov_bind(&aov, mask, pass->scene, p->aov);
    ef_fog_block_aov(pass, x0, y0, w, h, p->rgb, p->alpha, p->depth, mask ? &aov : NULL, NULL);
}

/* The caller's rectangle has a stride: a small one is gathered into
 * contiguous planes (one call to the core instead of one per row, whose
 * set-up would cost more than a small rectangle's pixels), a big one goes
 * row by row. */
static exrfog_result fog_rows(exrfog_context *ctx, const ef_fog_pass *pass,
                              const exrfog_image *img, float *const *aov_in, const int *aov_given,
                              int naov, unsigned mask)
{
    const int w = img->width, h = img->height;
    const size_t n = (size_t) w * (size_t) h;
    if (n == 0)
        return EXRFOG_OK;   /* an empty rectangle (a band of 16384 / w rows needs w > 0) */
    if (h > 1 && img->stride != w && n <= 16384) {
        const int nplanes = 5 + naov;
        if (ctx->gather_cap < n * (size_t) nplanes) {
            float *g = realloc(ctx->gather, n * (size_t) nplanes * sizeof *g);
            if (!g)
                return EXRFOG_ERROR;
            ctx->gather = g;
            ctx->gather_cap = n * (size_t) nplanes;
        }
        float *const g = ctx->gather;
        rect_planes p = { { g, g + n, g + 2 * n }, img->alpha ? g + 3 * n : NULL, g + 4 * n,
                          { NULL }, naov };
        for (int k = 0; k < naov; ++k)
            p.aov[k] = g + (size_t) (5 + k) * n;
        /* short rows: plain loops, not a libc call per row */
        for (int y = 0; y < h; ++y) {
            const ptrdiff_t o = (ptrdiff_t) y * img->stride;
            const size_t r = (size_t) y * (size_t) w;
            for (int k = 0; k < 3; ++k)
                copy_row(p.rgb[k] + r, img->rgb[k] + o, w);
            if (img->alpha)
                copy_row(p.alpha + r, img->alpha + o, w);
            copy_row(g + 4 * n + r, img->depth + o, w);
        }
        fog_rect(pass, img->x0, img->y0, w, h, &p, mask);
        for (int y = 0; y < h; ++y) {
            const ptrdiff_t o = (ptrdiff_t) y * img->stride;
            const size_t r = (size_t) y * (size_t) w;
            for (int k = 0; k < 3; ++k)
                copy_row(img->rgb[k] + o, p.rgb[k] + r, w);
            if (img->alpha)
                copy_row(img->alpha + o, p.alpha + r, w);
            for (int k = 0; k < naov; ++k)
                if (aov_given[k])
                    copy_row(aov_in[k] + o, p.aov[k] + r, w);
        }
        return EXRFOG_OK;
    }
    /* contiguous: bands of about 16,384 pixels (one call each), else row
     * by row; exrfog_cancel is heard between them */
    const int band = img->stride == w ? (w >= 16384 ? 1 : 16384 / w) : 1;
    for (int y = 0; y < h; y += band) {
        if (atomic_load(&ctx->cancel))
            return EXRFOG_CANCELLED;
        const int n_rows = h - y < band ? h - y : band;
        const ptrdiff_t o = (ptrdiff_t) y * img->stride;
        rect_planes p = { { img->rgb[0] + o, img->rgb[1] + o, img->rgb[2] + o },
                          img->alpha ? img->alpha + o : NULL, img->depth + o, { NULL }, naov };
        for (int k = 0; k < naov; ++k)
            p.aov[k] = aov_in[k] + (aov_given[k] ? o : 0);
        fog_rect(pass, img->x0, img->y0 + y, w, n_rows, &p, mask);
    }
    return EXRFOG_OK;
}

exrfog_result exrfog_fog_pixels(exrfog_context *ctx, const exrfog_scene *scene,
                                const exrfog_camera *cam, exrfog_image *img)
{
    if (!ctx || !scene || !cam)
        return misuse(ctx, "exrfog_fog_pixels: ctx, scene and cam must not be NULL");
    /* not zeroed whole: 5 kB a call, more than a small call's pixels cost */
    ef_err err;
    err.file = NULL;
    err.msg[0] = '\0';
    ctx->error[0] = '\0';
    atomic_store(&ctx->cancel, 0);
    /* A caller built before the light layers passes the size up to P:
     * the members past its size read as NULL. */
    const size_t base = offsetof(exrfog_image, ambient);
    if (!img || img->size < base) {
        ef_fail(&err, "exrfog_image.size is %zu, not %zu: the caller was built against another "
                      "exrfog.h", img ? img->size : (size_t) 0, sizeof *img);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    exrfog_image im;
    if (img->size < sizeof im) {
        memset(&im, 0, sizeof im);
        memcpy(&im, img, img->size);
        img = &im;
    }
    exrfog_result r = check_image(ctx, img);
    if (r != EXRFOG_OK)
        return r;
    ef_depth_mode mode = EF_DEPTH_PLANAR;
    if (img->depth_mode && ef_depth_mode_parse(img->depth_mode, &mode)) {
        ef_fail(&err, "depth mode '%s' is not one of planar, radial, inverse, normalized, gl-ndc, "
                      "gl-window, zero-one, reversed, reversed-infinite", img->depth_mode);
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    ef_depth_conv conv;
    if (ef_depth_conv_init(&conv, mode, &cam->cam, &err))
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    /* The AOV groups in the core's order (T, error, P): a missing plane of
     * a wanted group writes to scratch (as long as one call of the core). */
    float *const *groups[3] = { img->T, img->error, img->P };
    static const unsigned bits[3] = { EF_AOV_T, EF_AOV_ERROR, EF_AOV_P };
    float *aov_in[EF_AOV_MAX_CHANNELS];
    int aov_given[EF_AOV_MAX_CHANNELS], naov = 0;
    unsigned mask = 0;
#define PUSH_PLANE(p) (aov_given[naov] = (p) != NULL, aov_in[naov++] = (p))
    for (int g = 0; g < 3; ++g) {
        if (!groups[g][0] && !groups[g][1] && !groups[g][2])
            continue;
        mask |= bits[g];
        for (int k = 0; k < 3; ++k)
            PUSH_PLANE(groups[g][k]);
    }
    /* the light layers, in ef_aov_channels' order: ambient, each light's,
     * the sky light's, then the shadowed lights' lit fractions */
    const ef_fog_scene *sc = &scene->s;
    int want_light = 0, want_lit = 0;
    for (int k = 0; k < 3; ++k)
        want_light |= img->ambient[k] != NULL || img->sky[k] != NULL;
    for (int j = 0; j < sc->nlight; ++j) {
        for (int k = 0; img->light && k < 3; ++k)
            want_light |= img->light[3 * j + k] != NULL;
        want_lit |= img->lit && img->lit[j] && sc->light[j].shadow;
    }
    if ((want_light || (img->lit && !want_lit)) && !ef_scene_lit(sc)) {
        ef_fail(&err, "the light layers need a scene with lights (a --light SPEC or a sky light)");
        return fail(ctx, &err, NULL, EXRFOG_USAGE);
    }
    if (want_light) {
        mask |= EF_AOV_LIGHT;
        for (int k = 0; k < 3; ++k)
            PUSH_PLANE(img->ambient[k]);
        for (int j = 0; j < sc->nlight; ++j)
            for (int k = 0; k < 3; ++k)
                PUSH_PLANE(img->light ? img->light[3 * j + k] : NULL);
        for (int k = 0; sc->sky_light && k < 3; ++k)
            PUSH_PLANE(img->sky[k]);
    }
    if (want_lit) {
        mask |= EF_AOV_LIT;
        for (int j = 0; j < sc->nlight; ++j)
            if (sc->light[j].shadow)
                PUSH_PLANE(img->lit[j]);
    }
#undef PUSH_PLANE
    int need_scratch = 0;
    for (int k = 0; k < naov; ++k)
        need_scratch |= !aov_given[k];
    /* The scratch takes what one call of the core writes to a plane: the
     * whole rectangle when it is contiguous (fog_rows makes one call),
     * else a row. */
    const size_t per_call =
        (img->stride == img->width ? (size_t) img->width * (size_t) img->height
                                   : (size_t) img->width) + 1;
    if (need_scratch && ctx->scratch_cap < per_call) {
        float *sc = realloc(ctx->scratch, per_call * sizeof *sc);
        if (!sc)
            return ef_fail(&err, "out of memory"), fail(ctx, &err, NULL, EXRFOG_ERROR);
        ctx->scratch = sc;
        ctx->scratch_cap = per_call;
    }
    for (int k = 0; k < naov; ++k)
        if (!aov_given[k])
            aov_in[k] = ctx->scratch;
    /* The scene is bound to this camera on a private copy, made without
     * parsing or reading anything, in the context's buffer (a context is
     * one thread's): the caller's stays read-only, so threads may share
     * it. */
    if (!ctx->bound && !(ctx->bound = calloc(1, sizeof *ctx->bound)))
        return ef_fail(&err, "out of memory"), fail(ctx, &err, NULL, EXRFOG_ERROR);
    /* The same scene and camera as the context's last call: its bound copy
     * serves again (a tile loop binds once). */
    if (ctx->bound_scene != scene->tag || ctx->bound_cam != cam->tag) {
        ef_scene_free(ctx->bound);
        ctx->bound_scene = ctx->bound_cam = 0;
        if (ef_scene_copy(ctx->bound, &scene->s, 0))
            return ef_fail(&err, "out of memory"), fail(ctx, &err, NULL, EXRFOG_ERROR);
        ef_scene_bind_camera(ctx->bound, &cam->cam);
        ctx->bound_scene = scene->tag;
        ctx->bound_cam = cam->tag;
    }
    const ef_fog_pass pass = { &cam->cam, &conv, ctx->bound };
    r = fog_rows(ctx, &pass, img, aov_in, aov_given, naov, mask);
    if (r == EXRFOG_CANCELLED)
        return ef_fail(&err, "cancelled: the rectangle is fogged in part"),
               fail(ctx, &err, NULL, EXRFOG_CANCELLED);
    if (r != EXRFOG_OK)
        return ef_fail(&err, "out of memory"), fail(ctx, &err, NULL, EXRFOG_ERROR);
    return EXRFOG_OK;
}

static int on_progress(void *user, double f)
{
    exrfog_context *ctx = user;
    return ctx->progress(ctx->progress_user, f);
}

static void on_warning(void *user, const char *file, const char *text)
{
    exrfog_context *ctx = user;
    ctx->warning(ctx->warning_user, file, text);
}

/* Runs the job with the context's hooks; out receives --explain. */
static exrfog_result run_job(exrfog_context *ctx, int argc, const char *const *argv, FILE *out)
{
    const ef_job_hooks hooks = { .msg = ctx->print ? stderr : NULL,
                                 .out = out ? out : ctx->print ? stdout : NULL,
                                 .progress = ctx->progress ? on_progress : NULL,
                                 .progress_user = ctx,
                                 .warning = ctx->warning ? on_warning : NULL,
                                 .warning_user = ctx,
                                 .cancel = &ctx->cancel };
    const int rc = ef_job_run(&hooks, argc, argv, ctx->error, sizeof ctx->error);
    return rc == 0 ? EXRFOG_OK : rc == 2 ? EXRFOG_USAGE : rc == 3 ? EXRFOG_CANCELLED : EXRFOG_ERROR;
}

/* Whether argv holds argc strings. */
static int argv_ok(int argc, const char *const *argv)
{
    if (argc < 1 || !argv)
        return 0;
    for (int i = 0; i < argc; ++i)
        if (!argv[i])
            return 0;
    return 1;
}

exrfog_result exrfog_run(exrfog_context *ctx, int argc, const char *const *argv)
{
    if (!ctx || !argv_ok(argc, argv))
        return misuse(ctx, "exrfog_run: ctx must not be NULL, and argv must hold argc >= 1 "
                           "strings (argv[0] is the program's name)");
    ctx->error[0] = '\0';
    atomic_store(&ctx->cancel, 0);
    return run_job(ctx, argc, argv, NULL);
}

exrfog_result exrfog_explain(exrfog_context *ctx, int argc, const char *const *argv, char **json)
{
    if (json)
        *json = NULL;
    if (!ctx || !json || !argv_ok(argc, argv))
        return misuse(ctx, "exrfog_explain: ctx and json must not be NULL, and argv must hold "
                           "argc >= 1 strings");
    ctx->error[0] = '\0';
    atomic_store(&ctx->cancel, 0);
    const char **args = calloc((size_t) argc + 3, sizeof *args);
    char *buf = NULL;
    size_t len = 0;
    FILE *mem = args ? open_memstream(&buf, &len) : NULL;
    if (!mem) {
        free(args);
        snprintf(ctx->error, sizeof ctx->error, "out of memory");
        return EXRFOG_ERROR;
    }
    /* right after the program's name: INPUT may follow a "--" */
    args[0] = argv[0];
    args[1] = "--explain";
    args[2] = "--json";
    for (int i = 1; i < argc; ++i)
        args[i + 2] = argv[i];
    const exrfog_result r = run_job(ctx, argc + 2, args, mem);
    const int bad = fclose(mem) != 0;
    free(args);
    if (r != EXRFOG_OK || bad) {
        free(buf);
        if (r == EXRFOG_OK)
            snprintf(ctx->error, sizeof ctx->error, "out of memory");
        return r != EXRFOG_OK ? r : EXRFOG_ERROR;
    }
    *json = buf;
    return EXRFOG_OK;
}

void exrfog_free(void *p)
{
    free(p);
}
