/* Orchestration: every message the user sees is printed here. */
#include "run.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "apply.h"
#include "exr_io.h"
#include "options.h"
#include "output.h"
#include "preview.h"
#include "recon.h"
#include "scene.h"
#include "version.h"
#include "frames.h"
#include "colour.h"
#include "exr_dwa.h"
#include "camera_file.h"

/* Where messages go: stderr for the command line; the library may point
 * it elsewhere (exrfog_run). The last error is kept for exrfog_error. */
static FILE *g_msg;
static char g_last_error[2048];

static FILE *msg_out(void)
{
    return g_msg ? g_msg : stderr;
}

/* Where --explain writes: stdout, or the library's buffer. */
static FILE *g_out;

static FILE *out_stream(void)
{
    return g_out ? g_out : stdout;
}

static void put_clean(const char *s);

/* Prints "exrfog: " and the formatted error, keeps it for exrfog_error,
 * and returns status. */
static int say_error(int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static int say_error(int status, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(g_last_error, sizeof g_last_error, fmt, ap);
    va_end(ap);
    fputs("exrfog: ", msg_out());
    put_clean(g_last_error);
    fputc('\n', msg_out());
    return status;
}

/* The length of the valid UTF-8 sequence at s (1..4), or 0 when the
 * bytes there are not one (overlong, surrogate, beyond U+10FFFF, cut). */
static int utf8_len(const unsigned char *s)
{
    const unsigned c = s[0];
    int n;
    unsigned min;
    if (c >= 0xc2 && c <= 0xdf)
        n = 2, min = 0x80;
    else if (c >= 0xe0 && c <= 0xef)
        n = 3, min = 0x800;
    else if (c >= 0xf0 && c <= 0xf4)
        n = 4, min = 0x10000;
    else
        return 0;
    unsigned v = c & (0x3fu >> (n - 1));
    for (int k = 1; k < n; ++k) {
        if ((s[k] & 0xc0) != 0x80)
            return 0;
        v = v << 6 | (s[k] & 0x3fu);
    }
    if (v < min || v > 0x10ffff || (v >= 0xd800 && v <= 0xdfff))
        return 0;
    return n;
}

/* Writes s with control bytes and bytes that are not valid UTF-8 as
 * \xNN: names in messages come from the file, and a hostile one must not
 * drive the terminal or garble its encoding. */
static void put_clean(const char *s)
{
    for (const unsigned char *c = (const unsigned char *) s; *c;) {
        if (*c < 0x20 || *c == 0x7f) {
            fprintf(msg_out(), "\\x%02x", *c++);
        } else if (*c < 0x80) {
            fputc(*c++, msg_out());
        } else {
            const int n = utf8_len(c);
            if (!n) {
                fprintf(msg_out(), "\\x%02x", *c++);
                continue;
            }
            fwrite(c, 1, (size_t) n, msg_out());
            c += n;
        }
    }
}

static struct progress *active_pg;
static void progress_clear(struct progress *pg);

/* Prints "exrfog: FILE: message"; the callee's idea of FILE wins. */
static int report(const char *file, const ef_err *err, int status)
{
    progress_clear(active_pg);
    snprintf(g_last_error, sizeof g_last_error, "%s: %s", err->file ? err->file : file, err->msg);
    fputs("exrfog: ", msg_out());
    put_clean(err->file ? err->file : file);
    fputs(": ", msg_out());
    put_clean(err->msg);
    fputc('\n', msg_out());
    return status;
}

/* The progress bar on a terminal: frames done, pixels, elapsed, ETA.
 * Workers add their pixels; whoever finds the last drawing 0.2 s old
 * draws, under a try-lock so no worker ever waits for the terminal. */
struct progress {
    int nframes, done;        /* frames in the run; finished so far */
    long frame;               /* the current frame's number */
    int has_frame;
    double t0, last;
    double frame_px;          /* pixels of the current frame */
    _Atomic long px;          /* pixels of the current frame fogged */
    double px_total;          /* pixels of the finished frames */
    pthread_mutex_t lock;
    int drawn;                /* a line is on the terminal */
    int draw;                 /* draw the bar (stderr is a terminal) */
    int (*hook)(void *user, double fraction);   /* the library's callback, or NULL */
    void *hook_user;
    volatile int cancel;      /* the hook asked to stop */
};
typedef struct progress progress;

static double wall_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double) ts.tv_sec + 1e-9 * (double) ts.tv_nsec;
}

static void hms(char *b, size_t n, double s)
{
    const long t = s > 0 && s < 1e7 ? (long) (s + 0.5) : 0;
    if (t >= 3600)
        snprintf(b, n, "%ld:%02ld:%02ld", t / 3600, t / 60 % 60, t % 60);
    else
        snprintf(b, n, "%ld:%02ld", t / 60, t % 60);
}

/* Draws the bar (pg->lock held). */
static double progress_fraction(const progress *pg);

static void progress_draw(progress *pg, double t)
{
    const double px = (double) pg->px;
    const double all = progress_fraction(pg);
    char bar[31], el[32], eta[32], fr[64] = "";
    const int fill = (int) (all * 30.0);
    for (int i = 0; i < 30; ++i)
        bar[i] = i < fill ? '#' : '.';
    bar[30] = '\0';
    hms(el, sizeof el, t - pg->t0);
    if (all > 0.001)
        hms(eta, sizeof eta, (t - pg->t0) * (1.0 - all) / all);
    else
        snprintf(eta, sizeof eta, "?");
    if (pg->has_frame)
        snprintf(fr, sizeof fr, "frame %ld (%d/%d) ", pg->frame, pg->done + 1, pg->nframes);
    fprintf(msg_out(), "\r\033[Kexrfog: %s[%s] %3.0f%%  %.1f Mpx  %s elapsed  ETA %s", fr, bar,
            100.0 * all, (pg->px_total + px) / 1e6, el, eta);
    fflush(msg_out());
    pg->drawn = 1;
    pg->last = t;
}

/* The share of the run done: finished frames plus the current one's. */
static double progress_fraction(const progress *pg)
{
    const double px = (double) pg->px;
    const double frac = pg->frame_px > 0 ? (px < pg->frame_px ? px / pg->frame_px : 1.0) : 0.0;
    return pg->nframes > 0 ? (pg->done + frac) / pg->nframes : frac;
}

static void progress_add(progress *pg, long px)
{
    pg->px += px;
    const double t = wall_now();
    if (t - pg->last < 0.2 || pthread_mutex_trylock(&pg->lock))
        return;
    if (t - pg->last >= 0.2) {
        if (pg->hook && pg->hook(pg->hook_user, progress_fraction(pg)))
            pg->cancel = 1;
        if (pg->draw)
            progress_draw(pg, t);
        pg->last = t;
    }
    pthread_mutex_unlock(&pg->lock);
}

/* Takes the bar off the terminal so a message can be printed. */
static void progress_clear(progress *pg)
{
    if (!pg || !pg->drawn)
        return;
    pthread_mutex_lock(&pg->lock);
    fputs("\r\033[K", msg_out());
    fflush(msg_out());
    pg->drawn = 0;
    pg->last = 0;
    pthread_mutex_unlock(&pg->lock);
}

/* Per-run state shared read-only by the worker threads, except the
 * statistics, which each unit adds under the lock. */
typedef struct fog_job {
    ef_fog_pass pass[EF_MAX_VIEWS];   /* per view (ef_chunk.view) */
    unsigned aov;             /* EF_AOV_* bits, in the stream's extra channels */
    double aov_origin[3];
    ef_tau_stats *stats;      /* per component, or NULL without --stats */
    pthread_mutex_t lock;
    progress *pg;             /* NULL without a progress bar */
    const ef_ocio_display *disp;  /* the preview's display transform */
    /* preview: every step-th pixel of the data window */
    unsigned char *preview;
    int pv_w, pv_h, pv_step, dw_x0, dw_y0;
} fog_job;

/* A display-referred value (0..1) to 8 bits. */
static unsigned char display8(float v)
{
    if (!(v > 0))
        return 0;
    if (v >= 1)
        return 255;
    return (unsigned char) lrintf(v * 255.0f);
}

/* A monotonic clock in ns, for --stats's time per pixel (the vDSO's: tens
 * of ns a call, so timing every pixel stays cheap). */
static double mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double) ts.tv_sec * 1e9 + (double) ts.tv_nsec;
}

/* This thread's CPU time in ns (read once per span of pixels). */
static double thread_cpu_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double) ts.tv_sec * 1e9 + (double) ts.tv_nsec;
}

static void fog_chunk(void *user, const ef_chunk *ck)
{
    fog_job *j = user;
    if (j->pg && j->pg->cancel)
        return;   /* the output is thrown away: no work for it */
    ef_aov_out aov;
    ef_aov_bind(&aov, j->aov, ck->extra);
    memcpy(aov.origin, j->aov_origin, sizeof aov.origin);
    /* Statistics per unit, merged once: no lock per pixel. */
    ef_tau_stats st[EF_FOG_MAX_COMPONENTS];
    const int ncomp = j->pass[0].scene->ncomp;
    if (j->stats) {
        memset(st, 0, sizeof st);
        st[0].clock_ns = mono_ns;
        st[0].cpu_ns = thread_cpu_ns;
    }
    ef_fog_block_aov(&j->pass[ck->view], ck->x0, ck->y0, ck->w, ck->h, ck->rgb, ck->alpha, ck->depth, &aov,
                     j->stats ? st : NULL);
    if (j->stats) {
        pthread_mutex_lock(&j->lock);
        for (int i = 0; i < ncomp; ++i)
            ef_tau_stats_merge(&j->stats[i], &st[i]);
        pthread_mutex_unlock(&j->lock);
    }
    if (j->pg)
        progress_add(j->pg, (long) ck->w * ck->h);
    if (!j->preview || ck->view != 0)
        return;
    /* The unit's preview pixels through the display transform, then 8 bits. */
    const int sx0 = ((ck->x0 - j->dw_x0) + j->pv_step - 1) / j->pv_step;
    const int sx1 = (ck->x0 + ck->w - 1 - j->dw_x0) / j->pv_step;
    if (sx1 < sx0)
        return;
    const int nx = sx1 - sx0 + 1;
    float *row = malloc(sizeof(float) * 3 * (size_t) nx);
    if (!row)
        return;   /* the preview stays black there; memory is gone anyway */
    for (int y = ck->y0; y < ck->y0 + ck->h; ++y) {
        if ((y - j->dw_y0) % j->pv_step)
            continue;
        for (int k = 0; k < nx; ++k) {
            const int x = j->dw_x0 + (sx0 + k) * j->pv_step;
            const size_t i = (size_t) (y - ck->y0) * (size_t) ck->w + (size_t) (x - ck->x0);
            for (int c = 0; c < 3; ++c)
                row[3 * k + c] = ck->rgb[c][i];
        }
        ef_ocio_display_apply(j->disp, row, nx);
        unsigned char *p = j->preview + 3 * ((size_t) ((y - j->dw_y0) / j->pv_step) * j->pv_w + (size_t) sx0);
        for (int k = 0; k < 3 * nx; ++k)
            p[k] = display8(row[k]);
    }
    free(row);
}

static void print_vec(FILE *out, const char *label, const double v[3], const char *src)
{
    fprintf(out, "  %-11s (%.9g, %.9g, %.9g)%s%s\n", label, v[0], v[1], v[2], src ? "  from " : "",
           src ? src : "");
}

/* The resolved camera, channels and conventions, as --explain and -v show them. */
static void explain_channels(FILE *out, const ef_options *o, const ef_channel_plan *plan,
                             const ef_depth_conv *conv, int conv_ok);
static void explain_scene(FILE *out, const ef_options *o, const ef_channel_plan *plan);

static void explain(FILE *out, const ef_options *o, const ef_exr_file *in, const ef_channel_plan *plan,
                    const ef_camera *cam, const ef_depth_conv *conv, int conv_ok)
{
    static const double fwd[3] = { 0, 0, 1 }, upc[3] = { 0, 1, 0 };
    double f[3], u[3];
    fprintf(out, "input: %s (%d part%s)\n", in->path, in->nparts, in->nparts > 1 ? "s" : "");
    if (!plan) {
        /* What was found before the first thing that was not. */
        fprintf(out, "colour, depth and views: not resolved (see the error)\n");
        explain_scene(out, o, NULL);
        return;
    }
    if (!cam) {
        fprintf(out, "camera: not resolved (see the error)\n");
        explain_channels(out, o, plan, NULL, 0);
        explain_scene(out, o, plan);
        return;
    }
    ef_camera_to_world_dir(cam, fwd, f);
    ef_camera_to_world_dir(cam, upc, u);
    fprintf(out, "camera:\n");
    print_vec(out, "position", cam->pos, cam->src_pose);
    print_vec(out, "forward", f, NULL);
    print_vec(out, "up", u, NULL);
    fprintf(out, "  %-11s %.6g deg horizontal  from %s\n", "fov", cam->hfov_deg, cam->src_fov);
    if (cam->proj != EF_PROJ_NONE)
        fprintf(out, "  %-11s %s\n", "projection", cam->src_proj);
    if (cam->near_.set)
        fprintf(out, "  %-11s %.9g  from %s\n", "near", cam->near_.v, cam->src_near);
    if (cam->far_.set)
        fprintf(out, "  %-11s %.9g  from %s\n", "far", cam->far_.v, cam->src_far);
    if (cam->warning[0])
        fprintf(out, "  warning:    %s\n", cam->warning);
    explain_channels(out, o, plan, conv, conv_ok);
    explain_scene(out, o, plan);
}

/* The colour and depth channels --explain found, and the depth mode. */
static void explain_channels(FILE *out, const ef_options *o, const ef_channel_plan *plan,
                             const ef_depth_conv *conv, int conv_ok)
{
    fprintf(out, "colour: %s, %s, %s%s%s (part %d)\n", plan->rgb[0].name, plan->rgb[1].name,
           plan->rgb[2].name, plan->alpha.part >= 0 ? ", alpha " : ", no alpha (alpha = 1)",
           plan->alpha.part >= 0 ? plan->alpha.name : "", plan->rgb[0].part);
    fprintf(out, "depth: %s (part %d%s%s), mode %s\n", plan->depth.name, plan->depth.part,
           o->depth_file ? " of " : "", o->depth_file ? o->depth_file : "",
           ef_depth_mode_name(o->depth_mode));
    if (conv && conv_ok && (conv->mode != EF_DEPTH_PLANAR && conv->mode != EF_DEPTH_RADIAL &&
                            conv->mode != EF_DEPTH_INVERSE))
        fprintf(out, "  clip planes near %.9g far %.9g  from %s\n", conv->near_, conv->far_, conv->src_clip);
}

/* What --explain says of the scene (none of it needs the file). */
static void explain_scene(FILE *out, const ef_options *o, const ef_channel_plan *plan)
{
    fprintf(out, "sky rule: depth non-finite, <= 0 (planar/radial/inverse), >= %g once linearised, or at "
           "the far plane (buffer modes)\n", EF_SKY_DISTANCE);
    if (o->scene.sky == EF_SKY_FOG)
        fprintf(out, "  sky pixels: fogged to infinity (--sky fog)\n");
    else if (o->scene.sky == EF_SKY_KEEP)
        fprintf(out, "  sky pixels: kept unchanged (--sky keep)\n");
    else
        fprintf(out, "  sky pixels: a background at distance %g (--sky distance=%g)\n",
               o->scene.sky_distance, o->scene.sky_distance);
    for (int i = 0; i < o->scene.ncomp; ++i)
        fprintf(out, "fog: %s\n", o->scene.comp[i].spec);
    fprintf(out, "fog colour: %g, %g, %g (working space)\n", o->scene.color[0], o->scene.color[1],
           o->scene.color[2]);
    fprintf(out, "up axis: %g, %g, %g; %g scene units per metre%s%s\n", o->scene.ctx.up[0],
            o->scene.ctx.up[1], o->scene.ctx.up[2], o->scene.ctx.units_per_meter,
            o->scene_file ? "; scene file " : "", o->scene_file ? o->scene_file : "");
    fprintf(out, "time: %.9g s\n", o->scene.ctx.time);
    if (ef_colour_space()[0])
        fprintf(out, "working colour space: %s  from %s; OpenColorIO config: %s\n",
                ef_colour_space(), ef_colour_space_source(), ef_colour_config_where());
    if (o->aov) {
        const char *names[EF_AOV_MAX_CHANNELS];
        const int n = ef_aov_channels(o->aov, names);
        fprintf(out, "aov channels (part %d):", plan ? plan->rgb[0].part : -1);
        for (int i = 0; i < n; ++i)
            fprintf(out, " %s", names[i]);
        if (o->aov & EF_AOV_P)
            fprintf(out, "; fog_P relative to %.9g, %.9g, %.9g", o->aov_origin[0],
                    o->aov_origin[1], o->aov_origin[2]);
        fputc('\n', out);
    }
}

/* A JSON string (NULL: null), escaped. */
static void json_str(FILE *out, const char *v)
{
    if (!v) {
        fputs("null", out);
        return;
    }
    fputc('"', out);
    for (const unsigned char *c = (const unsigned char *) v; *c; ++c) {
        if (*c == '"' || *c == '\\')
            fprintf(out, "\\%c", *c);
        else if (*c < 0x20)
            fprintf(out, "\\u%04x", *c);
        else
            fputc(*c, out);
    }
    fputc('"', out);
}

/* A JSON number (non-finite: null, which JSON has instead). */
static void json_num(FILE *out, double v)
{
    if (isfinite(v))
        fprintf(out, "%.17g", v);
    else
        fputs("null", out);
}

static void json_vec(FILE *out, const double *v, int n)
{
    fputc('[', out);
    for (int k = 0; k < n; ++k) {
        if (k)
            fputs(", ", out);
        json_num(out, v[k]);
    }
    fputc(']', out);
}

/* --explain --json: the facts of --explain as one JSON object, for scripts
 * (and exrfog.explain() in Python). */
static void explain_json(FILE *out, const ef_options *o, const ef_exr_file *in,
                         const ef_channel_plan *plans, const ef_camera *cams,
                         const ef_depth_conv *convs, const int *conv_ok, int nplans)
{
    static const double fwd[3] = { 0, 0, 1 }, upc[3] = { 0, 1, 0 };
    fputs("{\n  \"version\": ", out);
    json_str(out, EXRFOG_VERSION);
    fputs(",\n  \"input\": ", out);
    json_str(out, in->path);
    fprintf(out, ",\n  \"parts\": %d,\n  \"views\": [", in->nparts);
    for (int v = 0; v < nplans; ++v) {
        const ef_channel_plan *pl = &plans[v];
        const ef_camera *cam = &cams[v];
        double f[3], u[3];
        ef_camera_to_world_dir(cam, fwd, f);
        ef_camera_to_world_dir(cam, upc, u);
        fputs(v ? ",\n    {" : "\n    {", out);
        fputs("\"view\": ", out);
        json_str(out, pl->view[0] ? pl->view : NULL);
        fprintf(out, ", \"default_view\": %s,\n     \"camera\": {\"position\": ",
                pl->default_view ? "true" : "false");
        json_vec(out, cam->pos, 3);
        fputs(", \"forward\": ", out);
        json_vec(out, f, 3);
        fputs(", \"up\": ", out);
        json_vec(out, u, 3);
        fputs(", \"hfov_deg\": ", out);
        json_num(out, cam->hfov_deg);
        fputs(", \"near\": ", out);
        if (cam->near_.set)
            json_num(out, cam->near_.v);
        else
            fputs("null", out);
        fputs(", \"far\": ", out);
        if (cam->far_.set)
            json_num(out, cam->far_.v);
        else
            fputs("null", out);
        fputs(", \"pose_source\": ", out);
        json_str(out, cam->src_pose);
        fputs(", \"fov_source\": ", out);
        json_str(out, cam->src_fov);
        fputs(", \"projection\": ", out);
        json_str(out, cam->proj != EF_PROJ_NONE ? cam->src_proj : NULL);
        fputs(", \"warning\": ", out);
        json_str(out, cam->warning[0] ? cam->warning : NULL);
        fprintf(out, "},\n     \"colour\": {\"part\": %d, \"channels\": [", pl->rgb[0].part);
        for (int k = 0; k < 3; ++k) {
            json_str(out, pl->rgb[k].name);
            fputs(k < 2 ? ", " : "], \"alpha\": ", out);
        }
        json_str(out, pl->alpha.part >= 0 ? pl->alpha.name : NULL);
        fputs("},\n     \"depth\": {\"file\": ", out);
        json_str(out, o->depth_file ? o->depth_file : in->path);
        fprintf(out, ", \"part\": %d, \"channel\": ", pl->depth.part);
        json_str(out, pl->depth.name);
        fputs(", \"mode\": ", out);
        json_str(out, ef_depth_mode_name(o->depth_mode));
        fputs(", \"conversion_error\": ", out);
        json_str(out, conv_ok[v] ? NULL : "the depth mode needs clip planes or a projection");
        (void) convs;
        fputs("}}", out);
    }
    fputs("\n  ],\n  \"sky\": ", out);
    json_str(out, o->scene.sky == EF_SKY_FOG ? "fog" : o->scene.sky == EF_SKY_KEEP ? "keep" : "distance");
    fputs(", \"sky_distance\": ", out);
    json_num(out, o->scene.sky == EF_SKY_DISTANCE_MODE ? o->scene.sky_distance : NAN);
    fputs(",\n  \"fog\": [", out);
    for (int i = 0; i < o->scene.ncomp; ++i) {
        if (i)
            fputs(", ", out);
        json_str(out, o->scene.comp[i].spec);
    }
    fputs("],\n  \"fog_colour\": ", out);
    json_vec(out, o->scene.color, 3);
    fputs(", \"up\": ", out);
    json_vec(out, o->scene.ctx.up, 3);
    fputs(", \"units_per_meter\": ", out);
    json_num(out, o->scene.ctx.units_per_meter);
    fputs(", \"time\": ", out);
    json_num(out, o->scene.ctx.time);
    fputs(",\n  \"colour_space\": ", out);
    if (ef_colour_space()[0]) {
        fputs("{\"name\": ", out);
        json_str(out, ef_colour_space());
        fputs(", \"source\": ", out);
        json_str(out, ef_colour_space_source());
        fputs(", \"config\": ", out);
        json_str(out, ef_colour_config_where());
        fputc('}', out);
    } else {
        fputs("null", out);
    }
    const char *names[EF_AOV_MAX_CHANNELS];
    const int n = ef_aov_channels(o->aov, names);
    fputs(",\n  \"aov\": [", out);
    for (int i = 0; i < n; ++i) {
        if (i)
            fputs(", ", out);
        json_str(out, names[i]);
    }
    fputs("], \"aov_origin\": ", out);
    json_vec(out, o->aov_origin, 3);
    fputs("\n}\n", out);
}

/* --stats: one line per component whose optical depth is numerical. Only
 * the surface segment's evaluation of each fogged pixel is counted (not
 * the segment to infinity behind a partly transparent pixel). */
static void print_tau_stats(const ef_fog_scene *s, const ef_tau_stats *st)
{
    int any = 0;
    for (int i = 0; i < s->ncomp; ++i)
        any |= s->comp[i].model->tau_info != NULL;
    if (any && st[0].timed > 0)
        /* before the per-component lines: it varies from run to run */
        fprintf(msg_out(),
                "exrfog: stats: fog time per pixel (every component, one core): mean %.2f "
                "us, p99.9 %.3g us, max %.3g us (%.3g us where the thread was not "
                "descheduled)\n",
                st[0].time_sum / st[0].timed / 1e3,
                ef_stats_quantile(st[0].time_hist, st[0].timed, 0.999) / 1e3,
                st[0].time_max / 1e3, st[0].time_max_clean / 1e3);
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->tau_info)
            continue;
        const ef_tau_stats *t = &st[i];
        const double n = t->pixels > 0 ? t->pixels : 1.0;
        fprintf(msg_out(),
                "exrfog: stats: fog[%d] %.60s%s: %.0f pixels; per pixel: noise evaluations mean "
                "%.1f p99.9 %.3g max %.0f, cells walked mean %.1f, octaves dropped mean %.2f, "
                "over the work bound %.0f pixels; error estimate (tau) max %.3g mean %.3g, "
                "(|dT|, as --aov error) max %.3g\n",
                i, c->spec, strlen(c->spec) > 60 ? "..." : "", t->pixels, t->evals / n,
                ef_stats_quantile(t->evals_hist, t->pixels, 0.999), t->evals_max,
                t->cells / n, t->dropped / n, t->over, t->err_max,
                (t->err_sum + t->err_sum_lo) / n, t->dT_max);
    }
}

/* Appends s to the buffer b (growing it); returns -1 when out of memory. */
static int grow(char **b, size_t *len, size_t *cap, const char *s, size_t n)
{
    if (*len + n + 1 > *cap) {
        size_t c = *cap ? *cap : 256;
        while (*len + n + 1 > c)
            c *= 2;
        char *nb = realloc(*b, c);
        if (!nb)
            return -1;
        *b = nb;
        *cap = c;
    }
    memcpy(*b + *len, s, n);
    *len += n;
    (*b)[*len] = '\0';
    return 0;
}

/* Appends a, quoted for a POSIX shell when it needs it. */
static int grow_quoted(char **b, size_t *len, size_t *cap, const char *a)
{
    int plain = a[0] != '\0';
    for (const char *c = a; *c; ++c)
        plain &= (*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') || (*c >= '0' && *c <= '9') ||
                 strchr("_@%+=:,./-", *c) != NULL;
    if (plain)
        return grow(b, len, cap, a, strlen(a));
    if (grow(b, len, cap, "'", 1))
        return -1;
    for (const char *c = a; *c; ++c)
        if (*c == '\'' ? grow(b, len, cap, "'\\''", 4) : grow(b, len, cap, c, 1))
            return -1;
    return grow(b, len, cap, "'", 1);
}

/* Whether argv[i] is an option that cannot change the output file (and
 * the number of arguments it takes with it): left out of the history so
 * that equal outputs get equal headers whatever the threads, messages,
 * preview or output name. */
static int history_skip(char **argv, int argc, int i)
{
    const char *a = argv[i];
    static const char *const with_arg[] = { "--threads", "--preview", "--output", "-o", "--frames" };
    static const char *const alone[] = { "--stats", "--verbose", "--quiet", "--keep-going" };
    for (size_t k = 0; k < sizeof with_arg / sizeof with_arg[0]; ++k) {
        const size_t n = strlen(with_arg[k]);
        if (!strcmp(a, with_arg[k]))
            return i + 1 < argc ? 2 : 1;
        if (!strncmp(a, with_arg[k], n) && (a[n] == '=' || (n == 2 && a[n])))
            return 1;
    }
    for (size_t k = 0; k < sizeof alone / sizeof alone[0]; ++k)
        if (!strcmp(a, alone[k]))
            return 1;
    if (a[0] == '-' && a[1] && a[1] != '-' && strspn(a + 1, "vq") == strlen(a + 1))
        return 1;
    return 0;
}

/* The line this run adds to exrfog/history: the version, the command line
 * shell-quoted (less what cannot change the output) and the scene file's
 * contents as read, indented. NULL when out of memory. */
static char *history_line(int argc, char **argv, const char *scene_file, const char *scene_text)
{
    char *b = NULL;
    size_t len = 0, cap = 0;
    if (grow(&b, &len, &cap, "exrfog " EXRFOG_VERSION ":", strlen("exrfog " EXRFOG_VERSION ":")))
        return NULL;
    for (int i = 0; i < argc;) {
        const int skip = i ? history_skip(argv, argc, i) : 0;
        if (skip) {
            i += skip;
            continue;
        }
        if (grow(&b, &len, &cap, " ", 1) || grow_quoted(&b, &len, &cap, i ? argv[i] : "exrfog")) {
            free(b);
            return NULL;
        }
        ++i;
    }
    if (scene_file && scene_text) {
        int fail = grow(&b, &len, &cap, "\n  scene ", 9) ||
                   grow(&b, &len, &cap, scene_file, strlen(scene_file)) ||
                   grow(&b, &len, &cap, ":", 1);
        for (const char *l = scene_text; !fail && *l;) {
            const char *nl = strchr(l, '\n');
            const size_t n = nl ? (size_t) (nl - l) : strlen(l);
            fail = grow(&b, &len, &cap, "\n    ", 5) || grow(&b, &len, &cap, l, n);
            l += n + (nl != NULL);
        }
        if (fail) {
            free(b);
            return NULL;
        }
    }
    return b;
}

/* Whether the camera comes from a Z-up family: V-Ray's cameraTransform,
 * or a flag matrix pasted in Blender's convention. */
static int z_up_camera(const ef_cam_flags *flags, const ef_camera *cam)
{
    return strstr(cam->src_pose, "cameraTransform") != NULL ||
           ((flags->w2c.set || flags->c2w.set) && flags->convention == EF_CONV_BLENDER);
}

/* Reads every component again under a new up axis (NULL: keep) and time:
 * models fix their up and time when they are read. */
static int rebuild_scene(ef_fog_scene *s, const double *up, double time, ef_err *err)
{
    static ef_fog_scene ns;
    ns = *s;
    ns.ncomp = 0;
    if (up)
        memcpy(ns.ctx.up, up, sizeof ns.ctx.up);
    ns.ctx.time = time;
    for (int i = 0; i < s->ncomp; ++i)
        if (ef_scene_add(&ns, s->comp[i].spec, err)) {
            ef_scene_free(&ns);
            return -1;
        }
    ef_scene_free(s);
    *s = ns;
    return 0;
}

static void warn(const char *file, const char *msg)
{
    progress_clear(active_pg);
    fputs("exrfog: ", msg_out());
    put_clean(file);
    fputs(": warning: ", msg_out());
    fputs(msg, msg_out());
    fputc('\n', msg_out());
}

/* Silent traps of real renders, each with its fix: Nuke's depth.Z is 1/z;
 * V-Ray's world is Z-up while the height models default to y. */
static void warn_traps(const ef_options *o, const ef_exr_file *in, int part, const ef_camera *cam)
{
    if (!o->depth_mode_set && ef_exr_has_attr(in, part, "nuke/version"))
        warn(o->input, "a Nuke render (nuke/version): Nuke's ScanlineRender writes depth.Z as "
                       "1/z, read here as planar depth; pass --depth-mode inverse if the fog looks "
                       "wrong (--depth-mode planar keeps this reading and silences the warning)");
    int height = 0;
    for (int i = 0; i < o->scene.ncomp; ++i)
        height |= o->scene.comp[i].model->uses_up && !o->scene.comp[i].has_up;
    if (height && !o->up_set && strstr(cam->src_pose, "cameraTransform"))
        warn(o->input, "the camera is V-Ray's (cameraTransform), whose world is Z-up, and the "
                       "height fog uses y as up; pass --up-axis z (or --up-axis y to keep y and "
                       "silence this)");
}

static int cpu_count(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : n > 256 ? 256 : (int) n;
}

/* What one frame of a run needs besides the options. */
typedef struct frame_ctx {
    int argc;
    char **typed;             /* the command line as typed, for the history */
    progress *pg;             /* NULL: no progress bar */
    int has_frame;            /* a frame of a sequence: */
    long frame;               /* its number */
} frame_ctx;

/* Whether path is a regular file (opening a FIFO would block: the EXR
 * reader refuses those with a message). */
static int regular_file(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* Whether path starts with OpenEXR's magic number; anything but a
 * readable regular file counts as one, for the EXR reader to explain. */
static int is_exr_file(const char *path)
{
    unsigned char m[4] = { 0 };
    if (!regular_file(path))
        return 1;
    FILE *f = fopen(path, "rb");
    if (!f)
        return 1;   /* let the EXR reader say what is wrong */
    const size_t n = fread(m, 1, 4, f);
    fclose(f);
    return n == 4 && m[0] == 0x76 && m[1] == 0x2f && m[2] == 0x31 && m[3] == 0x01;
}

/* The camera file, read once per path (a pattern gives one per frame). */
static ef_camera_file *g_camfile;
static char g_camfile_path[4096];

/* The frame a single image stands for: the last group of digits of its
 * file name (shot.1042.exr -> 1042), or -1 when it has none. */
static int frame_of_name(const char *path, long *frame)
{
    const char *name = strrchr(path, '/');
    name = name ? name + 1 : path;
    const char *end = NULL, *beg = NULL;
    for (const char *c = name; *c; ++c)
        if (*c >= '0' && *c <= '9') {
            if (!end || c[-1] < '0' || c[-1] > '9')
                beg = c;
            end = c + 1;
        }
    if (!end || end - beg > 9)
        return -1;
    *frame = strtol(beg, NULL, 10);
    if (beg > name && beg[-1] == '-')
        *frame = -*frame;
    return 0;
}

/* The camera flags of this frame: the command line's, over the camera
 * file's camera for the frame when --camera-file is given (src then says
 * where it came from). Returns 0, or an exit status with err set. */
static int camera_flags(const ef_options *o, const frame_ctx *fr, ef_cam_flags *flags, char *src,
                        size_t srclen, ef_err *err)
{
    src[0] = '\0';
    if (!o->camera_file)
        return 0;
    char path[4096];
    ef_frame_pattern pat;
    ef_frame_pattern_find(o->camera_file, &pat);
    if (pat.has && !fr->has_frame) {
        ef_fail(err, "--camera-file has a frame pattern but INPUT is a single image; give INPUT "
                     "a pattern too (shot.#.exr --frames N)");
        return 2;
    }
    if (ef_frame_path(o->camera_file, &pat, fr->frame, path, sizeof path))
        return ef_fail(err, "the camera file's path is too long"), 1;
    if (!g_camfile || strcmp(path, g_camfile_path)) {
        ef_camera_file_free(g_camfile);
        g_camfile = NULL;
        if (ef_camera_file_read(path, o->cam.convention, &g_camfile, err)) {
            if (!err->file)
                ef_err_set_file(err, path);
            return 1;
        }
        snprintf(g_camfile_path, sizeof g_camfile_path, "%s", path);
    }
    long frame = fr->frame;
    double first = 0, last = 0;
    int count = 0;
    ef_camera_file_frames(g_camfile, &first, &last, &count);
    if (!fr->has_frame && frame_of_name(o->input, &frame)) {
        if (count != 1) {
            ef_fail(err, "INPUT's name holds no frame number and the camera file has %d frames; "
                         "name the frame with a pattern and --frames (shot.#.exr --frames N)",
                    count);
            ef_err_set_file(err, path);
            return 1;
        }
        frame = (long) first;
    }
    ef_cam_flags f = *flags;
    if (ef_camera_file_frame(g_camfile, (double) frame, &f, err)) {
        ef_err_set_file(err, path);
        return 1;
    }
    /* The command line's lens and clip planes win over the file's. */
    if (flags->fov.set) {
        f.fov = flags->fov;
        f.vfov.set = 0;
    }
    if (flags->near_.set)
        f.near_ = flags->near_;
    if (flags->far_.set)
        f.far_ = flags->far_;
    *flags = f;
    snprintf(src, srclen, "camera file %.300s, frame %ld (%.200s)", path, frame,
             ef_camera_file_describe(g_camfile));
    return 0;
}

/* Whether view v's camera can be resolved: a multi-part view's from its
 * part's header, a single-part file's only for the default view; flags
 * (one selected view) always. */
static int view_has_camera(const ef_options *o, const ef_exr_file *in, const ef_channel_plan *pl)
{
    if (o->camera_file || o->cam.w2c.set || o->cam.c2w.set)
        return 1;
    if (in->nparts == 1 && !pl->default_view)
        return 0;
    ef_cam_meta meta;
    static ef_camera cam;
    ef_err e = { 0 };
    return ef_exr_read_cam_meta(in, pl->rgb[0].part, &meta, &e) == 0 &&
           ef_camera_resolve(&meta, &o->cam, &cam, &e) == 0;
}

/* Chooses what to fog: the one colour of a file without views, or its
 * views (all, or those of --view), each found with its own channels.
 * Returns 0, or the exit status with err set. */
static int choose_views(const ef_options *o, const ef_exr_file *in, const ef_exr_file *df,
                        char views[][64], int nv, ef_channel_plan *plans, int *nplans, ef_err *err)
{
    char list[400] = "";
    for (int k = 0; k < nv; ++k)
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", k ? ", " : "", views[k]);
    if (nv == 0) {
        if (o->nviews)
            return ef_fail(err, "--view %s: INPUT has no views (no multiView attribute and no "
                                "part with a view)", o->views[0]), 2;
        *nplans = 1;
        return ef_find_channels(in, df, o->layer, o->depth_channel, &plans[0], err) ? 1 : 0;
    }
    const char *sel[EF_MAX_VIEWS];
    int ns = 0;
    /* --layer naming a view (left.R ...) chooses that view, as it did
     * before views were understood. */
    const char *layer = o->layer;
    const char *const *want = o->views;
    int nwant = o->nviews;
    for (int k = 0; layer && !nwant && k < nv; ++k)
        if (!strcmp(layer, views[k])) {
            want = &o->layer;
            nwant = 1;
            layer = NULL;
        }
    for (int i = 0; i < nwant; ++i) {
        int found = -1;
        for (int k = 0; k < nv; ++k)
            if (!strcmp(views[k], want[i]))
                found = k;
        if (found < 0)
            return ef_fail(err, "--view %s: INPUT has no such view (its views: %s)", want[i],
                           list), 2;
        int dup = 0;
        for (int k = 0; k < ns; ++k)
            dup |= !strcmp(sel[k], views[found]);
        if (!dup && ns < EF_MAX_VIEWS)
            sel[ns++] = views[found];
    }
    if (!nwant)
        for (int k = 0; k < nv; ++k)
            sel[ns++] = views[k];
    if (ns > 1 && (o->camera_file || o->cam.w2c.set || o->cam.c2w.set))
        return ef_fail(err, "INPUT has the views %s and the camera flags give one camera; choose "
                            "the view it belongs to with --view NAME (run once per view)", list), 2;
    char nocam[300] = "", withcam[300] = "";
    for (int k = 0; k < ns; ++k) {
        if (ef_find_view_channels(in, df, sel[k], layer, o->depth_channel, &plans[k], err))
            return 1;
        char *l = view_has_camera(o, in, &plans[k]) ? withcam : nocam;
        snprintf(l + strlen(l), 300 - strlen(l), "%s%s", l[0] ? ", " : "", sel[k]);
    }
    *nplans = ns;
    if (nocam[0] && !nwant) {
        if (withcam[0])
            return ef_fail(err, "the view%s %s %s no camera of its own, and exrfog fogs every "
                                "view unless told: fog the others with --view %s, or give %s "
                                "camera (--camera-file, or --camera-to-world with --fov) with "
                                "--view", strchr(nocam, ',') ? "s" : "", nocam,
                           strchr(nocam, ',') ? "have" : "has", withcam,
                           strchr(nocam, ',') ? "their" : "its"), 1;
        /* one view: the camera's own message says what is missing */
        if (ns == 1)
            return 0;
        return ef_fail(err, "no view has a camera (views: %s%s); give one with --camera-file, or "
                            "--world-to-camera M or --camera-to-world M and --fov DEG, and choose "
                            "its view with --view", list,
                       in->nparts == 1 ? "; a single-part file's header camera is the default "
                                         "view's" : ""), 1;
    }
    if (nwant && !o->quiet && !o->explain)
        for (int k = 0; k < nv; ++k) {
            int chosen = 0;
            for (int i = 0; i < ns; ++i)
                chosen |= !strcmp(sel[i], views[k]);
            if (!chosen) {
                char msg[200];
                snprintf(msg, sizeof msg, "view '%.64s' is not fogged (not chosen with --view); "
                                          "it is copied unchanged", views[k]);
                warn(o->input, msg);
            }
        }
    return 0;
}


/* Fogs one image: o->input, o->output, o->depth_file and o->preview name
 * this frame's files. Returns the exit status and prints every message. */
static int run_frame(ef_options *o, const frame_ctx *fr)
{
    ef_err err = {0};
    /* A frame's time is frame / fps unless --time or the scene file says. */
    if (fr->has_frame && !o->time_set &&
        rebuild_scene(&o->scene, NULL, (double) fr->frame / o->fps, &err)) {
        return report(o->input, &err, 1);
    }
    ef_exr_file in = { 0 }, dep = { 0 };
    const ef_exr_file *df = &in;
    static ef_channel_plan plans[EF_MAX_VIEWS];
    ef_cam_meta meta;
    static ef_camera cams[EF_MAX_VIEWS];
    static ef_depth_conv convs[EF_MAX_VIEWS];
    int convs_ok[EF_MAX_VIEWS] = { 0 };
    static ef_fog_scene view_scene[EF_MAX_VIEWS];
    static char camfile_src[600];
    ef_ocio_display *disp = NULL;
    int nview_scene = 0;
    camfile_src[0] = '\0';
    static fog_job job;
    memset(&job, 0, sizeof job);
    job.pv_step = 1;
    job.pg = fr->pg;
    pthread_mutex_init(&job.lock, NULL);
    const char *aov_names[EF_AOV_MAX_CHANNELS];
    const int naov = ef_aov_channels(o->aov, aov_names);
    int status = 1;
    ef_output out, pv, mid, dconv, din;
    char *history = NULL;
    out.fd = pv.fd = mid.fd = dconv.fd = din.fd = -1;
    out.tmp[0] = pv.tmp[0] = mid.tmp[0] = dconv.tmp[0] = din.tmp[0] = '\0';
    /* OUTPUT's extension chooses the format: .exr (or none) is written here,
     * anything else through OpenImageIO from an EXR beside it. */
    const char *ext = o->output ? strrchr(o->output, '.') : NULL;
    if (ext && strchr(ext, '/'))
        ext = NULL;
    const int foreign = ext && strcasecmp(ext, ".exr") != 0;
    if (!o->explain) {
        /* Everything about the destinations is checked, and their temporary
         * files made, before a pixel is read. */
        ef_output_signals();
        if (o->preview) {
            char msg[512];
            if (!strcmp(o->preview, o->output) || ef_output_same_file(o->preview, o->output) ||
                ef_output_same_file(o->preview, o->input) ||
                (o->depth_file && ef_output_same_file(o->preview, o->depth_file))) {
                ef_fail(&err, "--preview names the same file as INPUT, --depth or -o; give the "
                              "preview its own name");
                status = report(o->preview, &err, 2);
                goto done;
            }
            if (ef_preview_check(o->preview, msg, sizeof msg)) {
                ef_fail(&err, "--preview: %s", msg);
                status = report(o->preview, &err, 2);
                goto done;
            }
            /* the display and view exist (the working space comes later) */
            const ef_ocio *cfg = ef_colour_config(&err);
            if (!cfg) {
                report(o->preview, &err, 1);
                goto done;
            }
            char used[300], vmsg[1200];
            ef_ocio_display *d = ef_ocio_display_open(cfg, NULL, o->preview_view, used, sizeof used,
                                                      vmsg, sizeof vmsg);
            if (!d) {
                ef_fail(&err, "--preview-view: %s", vmsg);
                status = report(o->preview, &err, 2);
                goto done;
            }
            ef_ocio_display_close(d);
            const char *dot = strrchr(o->preview, '.'), *slash = strrchr(o->preview, '/');
            const int rc = ef_output_open(&pv, o->preview, dot && (!slash || dot > slash) ? dot : NULL,
                                          &err);
            if (rc) {
                status = report(o->preview, &err, rc);
                goto done;
            }
        }
        if (foreign) {
            char msg[512];
            if (naov) {
                ef_fail(&err, "--aov needs an EXR output: AOVs are extra channels, and %s holds "
                              "colour and alpha only", ext);
                status = report(o->output, &err, 2);
                goto done;
            }
            if (ef_preview_check(o->output, msg, sizeof msg)) {
                ef_fail(&err, "no writer for '%s' files (exrfog writes .exr itself, and through "
                              "OpenImageIO .tif, .png, .jpg, .dpx and the rest): %s", ext, msg);
                status = report(o->output, &err, 2);
                goto done;
            }
        }
        const int rc = ef_output_open(&out, o->output, foreign ? ext : NULL, &err);
        if (rc) {
            status = report(o->output, &err, rc);
            goto done;
        }
        if (foreign && (status = ef_output_open(&mid, o->output, ".exr", &err)) != 0) {
            status = report(o->output, &err, status);
            goto done;
        }
    }
    /* DWA parts (which OpenEXRCore 3.1.5 cannot decode) are decoded by the
     * OpenEXR C++ library into a temporary ZIP file first; the output is
     * encoded back to DWA after the pass unless --compression says
     * otherwise. */
    const char *ipath = o->input;
    ef_dwa_info dwa = { 0 };
    {
        ef_err derr = { 0 };
        if (!regular_file(o->input) || ef_exr_dwa_info(o->input, &dwa, &derr))
            dwa.ndwa = 0;   /* not an EXR: the reader below says what is wrong */
    }
    if (dwa.ndwa > 0) {
        char name[PATH_MAX], msg[800];
        const char *tmpdir = getenv("TMPDIR");
        snprintf(name, sizeof name, "%s/exrfog-dwa", tmpdir && tmpdir[0] ? tmpdir : "/tmp");
        if (ef_output_open(&din, name, ".exr", &err)) {
            report(o->input, &err, 1);
            goto done;
        }
        if (ef_dwa_transcode(o->input, din.fd, din.tmp, EXR_COMPRESSION_ZIP, -1, -1.0f,
                             o->threads ? o->threads : cpu_count(), msg, sizeof msg)) {
            ef_fail(&err, "%s", msg);
            report(o->input, &err, 1);
            goto done;
        }
        ipath = din.tmp;
    }
    if (ef_exr_open(ipath, &in, &err)) {
        report(o->input, &err, 1);
        goto done;
    }
    in.path = o->input;   /* messages name the user's file */
    if (o->depth_file) {
        /* A depth in another format (a 32-bit TIFF pass) is read through
         * OpenImageIO into a temporary float EXR. */
        const char *dpath = o->depth_file;
        if (!is_exr_file(o->depth_file)) {
            char name[PATH_MAX], msg[600];
            const char *tmpdir = getenv("TMPDIR");
            snprintf(name, sizeof name, "%s/exrfog-depth", tmpdir && tmpdir[0] ? tmpdir : "/tmp");
            if (ef_output_open(&dconv, name, ".exr", &err)) {
                report(o->depth_file, &err, 1);
                goto done;
            }
            if (ef_oiio_image_to_exr(o->depth_file, dconv.fd, msg, sizeof msg)) {
                ef_fail(&err, "%s", msg);
                report(o->depth_file, &err, 1);
                goto done;
            }
            dpath = dconv.tmp;
        }
        if (ef_exr_open(dpath, &dep, &err)) {
            report(o->depth_file, &err, 1);
            goto done;
        }
        dep.path = o->depth_file;   /* messages name the user's file */
        df = &dep;
    }
    /* The views to fog: every view of a multi-view file (or those of
     * --view), each with its channels and its own camera. */
    char views[EF_MAX_VIEWS][64];
    const int nfile_views = ef_exr_views(&in, views, EF_MAX_VIEWS);
    int nplans = 0;
    if ((status = choose_views(o, &in, df, views, nfile_views, plans, &nplans, &err)) != 0) {
        if (o->explain && status == 1)
            explain(out_stream(), o, &in, NULL, NULL, NULL, 0);
        report(o->input, &err, status);
        goto done;
    }
    /* The working space, when colours or the preview need it; colours
     * written as #RRGGBB or SPACE:R,G,B are then read again in it. */
    if ((status = ef_colour_working(&in, plans[0].rgb[0].part,
                                    ef_colour_converted() || o->preview || o->explain, &err)) != 0) {
        report(o->input, &err, status);
        goto done;
    }
    status = 1;
    if (ef_colour_converted()) {
        if (rebuild_scene(&o->scene, NULL, o->scene.ctx.time, &err) ||
            (o->fog_color && ef_colour_parse(NULL, o->fog_color, o->scene.color, &err))) {
            report(o->input, &err, 1);
            goto done;
        }
    }
    const char *clash = ef_exr_part_has_any(&in, plans[0].rgb[0].part, aov_names, naov);
    if (clash && !plans[0].chan_view[0]) {
        char list[64];
        ef_aov_list(o->aov, list, sizeof list);
        ef_fail(&err, "--aov %s: the colour part already has a channel '%s'; the AOV would "
                      "overwrite it (leave that AOV out, or rename the channel)", list, clash);
        status = report(o->input, &err, 2);
        goto done;
    }
    if (foreign && nplans > 1) {
        ef_fail(&err, "%s holds one image and INPUT has %d views (%s, ...); choose one with --view "
                      "NAME", strrchr(o->output, '.'), nplans, plans[0].view);
        status = report(o->output, &err, 2);
        goto done;
    }
    for (int v = 0; v < nplans; ++v) {
        const ef_channel_plan *const pl = &plans[v];
        ef_camera *const cam = &cams[v];
        ef_cam_flags flags = o->cam;
        if ((status = camera_flags(o, fr, &flags, camfile_src, sizeof camfile_src, &err)) != 0) {
            report(o->camera_file, &err, status);
            goto done;
        }
        status = 1;
        /* In a single-part multi-view file the header's camera is the
         * default view's: another view has no camera of its own. */
        if (pl->view[0] && in.nparts == 1 && !pl->default_view) {
            exr_attr_box2i_t disp;
            exr_get_display_window(in.ctx, 0, &disp);
            ef_cam_meta_init(&meta, disp.min.x, disp.min.y, disp.max.x, disp.max.y);
            float pa = 1;
            if (exr_get_pixel_aspect_ratio(in.ctx, 0, &pa) == EXR_ERR_SUCCESS && pa > 0)
                meta.pixel_aspect = pa;
        } else if (ef_exr_read_cam_meta(&in, pl->rgb[0].part, &meta, &err)) {
            report(o->input, &err, 1);
            goto done;
        }
        if (ef_camera_resolve(&meta, &flags, cam, &err)) {
            if (o->explain)
                explain(out_stream(), o, &in, pl, NULL, NULL, 0);
            if (pl->view[0]) {
                char msg[sizeof err.msg];
                snprintf(msg, sizeof msg, "%s", err.msg);
                ef_fail(&err, "view '%s': %s%s", pl->view, msg,
                        in.nparts == 1 && !pl->default_view
                            ? " (in a single-part multi-view file the header's camera is the "
                              "default view's)"
                            : "");
            }
            /* A bad --world-to-camera is a usage error; a bad header is not. */
            status = report(o->input, &err, cam->flag_error ? 2 : 1);
            goto done;
        }
        if (camfile_src[0])
            cam->src_pose = camfile_src;
        if (cam->warning[0] && !o->quiet && !o->explain) {
            progress_clear(active_pg);
            fputs("exrfog: ", msg_out());
            put_clean(o->input);
            fputs(": warning: ", msg_out());
            put_clean(cam->warning);
            fputc('\n', msg_out());
        }
        static const double z_up[3] = { 0, 0, 1 };
        if (v == 0 && o->up_auto && z_up_camera(&flags, cam) &&
            rebuild_scene(&o->scene, z_up, o->scene.ctx.time, &err)) {
            report(o->input, &err, 1);
            goto done;
        }
        if (v == 0 && !o->quiet && !o->explain)
            warn_traps(o, &in, pl->rgb[0].part, cam);
        int conv_ok = ef_depth_conv_init(&convs[v], o->depth_mode, cam, &err) == 0;
        convs_ok[v] = conv_ok;
        if (o->explain && o->json)
            continue;
        if (o->explain) {
            if (pl->view[0])
                fprintf(out_stream(), "%sview: %s%s\n", v ? "\n" : "", pl->view,
                       pl->default_view ? " (default view)" : "");
            explain(out_stream(), o, &in, pl, cam, &convs[v], conv_ok);
            if (!conv_ok)
                fprintf(out_stream(), "depth conversion: %s\n", err.msg);
            continue;
        }
        if (!conv_ok) {
            report(o->input, &err, 1);
            goto done;
        }
        /* Each view binds the scene to its own camera: a copy per view. */
        ef_fog_scene *sc = &o->scene;
        if (v > 0) {
            view_scene[v] = o->scene;
            view_scene[v].ncomp = 0;
            nview_scene = v + 1;
            for (int i = 0; i < o->scene.ncomp; ++i)
                if (ef_scene_add(&view_scene[v], o->scene.comp[i].spec, &err)) {
                    report(o->input, &err, 1);
                    goto done;
                }
            sc = &view_scene[v];
        }
        ef_scene_bind(sc, cam->pos);
        job.pass[v] = (ef_fog_pass){ cam, &convs[v], sc };
    }
    if (o->explain) {
        if (o->json)
            explain_json(out_stream(), o, &in, plans, cams, convs, convs_ok, nplans);
        status = 0;
        goto done;
    }
    job.aov = o->aov;
    memcpy(job.aov_origin, o->aov_origin, sizeof job.aov_origin);
    if (o->stats) {
        job.stats = calloc((size_t) o->scene.ncomp + 1, sizeof *job.stats);
        if (!job.stats) {
            ef_fail(&err, "out of memory for the statistics");
            report(o->output, &err, 1);
            goto done;
        }
    }
    exr_attr_box2i_t dw;
    exr_get_data_window(in.ctx, plans[0].rgb[0].part, &dw);
    if (fr->pg) {
        fr->pg->frame_px = (double) (dw.max.x - dw.min.x + 1) * (double) (dw.max.y - dw.min.y + 1);
        fr->pg->px = 0;
    }
    if (o->preview) {
        int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
        job.pv_step = (w > h ? w : h) / 2048 + 1;
        job.pv_w = (w + job.pv_step - 1) / job.pv_step;
        job.pv_h = (h + job.pv_step - 1) / job.pv_step;
        job.dw_x0 = dw.min.x;
        job.dw_y0 = dw.min.y;
        char used[300], msg[1200];
        const ef_ocio *cfg = ef_colour_config(&err);
        if (!cfg) {
            report(o->preview, &err, 1);
            goto done;
        }
        disp = ef_ocio_display_open(cfg, ef_colour_space(), o->preview_view, used, sizeof used, msg,
                                    sizeof msg);
        if (!disp) {
            ef_fail(&err, "--preview-view: %s", msg);
            report(o->preview, &err, 2);
            goto done;
        }
        job.disp = disp;
        job.preview = calloc((size_t) job.pv_w * (size_t) job.pv_h, 3);
        if (!job.preview) {
            ef_fail(&err, "out of memory for the preview");
            report(o->preview, &err, 1);
            goto done;
        }
    }
    for (int p = 0; p < in.nparts && !o->quiet; ++p)
        if (ef_exr_part_is_multilevel(&in, p))
            fprintf(msg_out(), "exrfog: %s: note: part %d is mip-mapped; level 0 is fogged and the "
                            "output part is single-level\n", o->input, p);

    history = history_line(fr->argc, fr->typed, o->scene_file, o->scene_text);
    if (!history) {
        ef_fail(&err, "out of memory for the history attribute");
        report(o->output, &err, 1);
        goto done;
    }
    /* More threads than CPUs cannot help a CPU-bound pass; they only cost memory. */
    const int cpus = cpu_count();
    if (o->threads > cpus && o->verbose)
        fprintf(msg_out(), "exrfog: note: --threads %d capped at the %d CPUs\n", o->threads, cpus);
    ef_stream_opts so = { .threads = o->threads && o->threads < cpus ? o->threads : cpus,
                          .compression = o->compression,
                          .zip_level = o->zip_level,
                          .codec = o->codec,
                          .pixel_type = o->pixel_type,
                          .chan_type_name = o->chan_type_name,
                          .chan_type = o->chan_type,
                          .nchan_type = o->nchan_type,
                          .depth_name = NULL,
                          .depth_part = -1,
                          .param_attr = o->params,
                          .history = history,
                          .extra = aov_names,
                          .nextra = naov,
                          .has_origin_attr = o->has_aov_origin,
                          .origin_attr = { o->aov_origin[0], o->aov_origin[1], o->aov_origin[2] } };
    ef_stream_stats st;
    if (o->verbose) {
        for (int v = 0; v < nplans; ++v)
            explain(msg_out(), o, &in, &plans[v], &cams[v], &convs[v], 1);
        fprintf(msg_out(), "exrfog: %s -> %s with %d thread%s\n", o->input, o->output, so.threads,
                so.threads > 1 ? "s" : "");
    }
    so.nplans = nplans;
    so.cancel = fr->pg ? &fr->pg->cancel : NULL;
    /* DWA output (asked for, or kept from a DWA input): the pass writes a
     * lossless temporary EXR that the C++ library encodes at the end. */
    int dwa_out = -1;
    float dwa_level = o->dwa_level;
    if (!foreign && (o->compression == EXR_COMPRESSION_DWAA || o->compression == EXR_COMPRESSION_DWAB)) {
        dwa_out = o->compression;
    } else if (!foreign && o->compression < 0 && dwa.ndwa > 0) {
        if (dwa.ndwa == dwa.nparts && !dwa.mixed) {
            dwa_out = dwa.compression;
            dwa_level = dwa.level > 0 ? dwa.level : EF_DWA_DEFAULT_LEVEL;
        } else if (!o->quiet) {
            warn(o->input, "some parts are DWA and others are not (or DWAA and DWAB are mixed); "
                           "the DWA parts are written ZIP-compressed (--compression dwaa or dwab "
                           "writes every part so)");
        }
    }
    if (dwa_out >= 0) {
        so.compression = EXR_COMPRESSION_ZIP;
        so.zip_level = 1;
        if ((status = ef_output_open(&mid, o->output, ".exr", &err)) != 0) {
            report(o->output, &err, status);
            status = 1;
            goto done;
        }
    }
    if (ef_exr_stream(&in, df, plans, o->output, foreign || dwa_out >= 0 ? mid.fd : out.fd, &so,
                      fog_chunk, &job, &st, &err)) {
        report(o->output, &err, fr->pg && fr->pg->cancel ? 3 : 1);
        status = fr->pg && fr->pg->cancel ? 3 : 1;
        goto done;
    }
    if (fr->pg && fr->pg->cancel) {
        ef_fail(&err, "cancelled; nothing was written");
        status = report(o->output, &err, 3);
        goto done;
    }
    if (dwa_out >= 0) {
        char msg[800];
        close(mid.fd);
        mid.fd = -1;
        if (ef_dwa_transcode(mid.tmp, out.fd, o->output, -1, dwa_out,
                             dwa_level > 0 ? dwa_level : EF_DWA_DEFAULT_LEVEL, so.threads, msg,
                             sizeof msg)) {
            ef_fail(&err, "%s", msg);
            report(o->output, &err, 1);
            goto done;
        }
        ef_output_abort(&mid);
    }
    if (foreign) {
        /* Colour and alpha of the fogged part, in OUTPUT's format. */
        const char *names[4] = { plans[0].rgb[0].name, plans[0].rgb[1].name, plans[0].rgb[2].name,
                                 plans[0].alpha.part >= 0 ? plans[0].alpha.name : NULL };
        char msg[512];
        close(mid.fd);
        mid.fd = -1;
        close(out.fd);
        out.fd = -1;
        if (ef_oiio_convert_exr(mid.tmp, plans[0].rgb[0].part, names, names[3] ? 4 : 3, out.tmp, msg,
                                sizeof msg)) {
            ef_fail(&err, "%s", msg);
            report(o->output, &err, 1);
            goto done;
        }
        ef_output_abort(&mid);
    }
    if (job.preview) {
        /* The preview goes in place first: when it fails, OUTPUT (which
         * may be the input) is left as it was and the run fails. */
        char msg[512];
        close(pv.fd);
        pv.fd = -1;
        if (ef_preview_write(pv.tmp, job.pv_w, job.pv_h, job.preview, msg, sizeof msg)) {
            ef_fail(&err, "%s; nothing was written", msg);
            report(o->preview, &err, 1);
            goto done;
        }
        if (ef_output_commit(&pv, &err)) {
            report(o->preview, &err, 1);
            goto done;
        }
    }
    if (ef_output_commit(&out, &err)) {
        report(o->output, &err, 1);
        goto done;
    }
    status = 0;
    if (o->stats) {
        struct rusage ru;
        getrusage(RUSAGE_SELF, &ru);
        fprintf(msg_out(),
                "exrfog: stats: wall %.3f s; thread time decode %.3f s, fog %.3f s, encode %.3f s, "
                "write %.3f s, wait %.3f s; %ld units on %d threads; peak memory %.1f MB\n",
                st.wall_s, st.decode_s, st.fog_s, st.encode_s, st.write_s, st.wait_s, st.units, so.threads,
                (double) ru.ru_maxrss / 1024.0);
        print_tau_stats(&o->scene, job.stats);
    }
done:
    free(history);
    ef_output_abort(&mid);
    ef_output_abort(&pv);
    ef_output_abort(&out);
    ef_output_abort(&dconv);
    ef_output_abort(&din);
    free(job.preview);
    free(job.stats);
    pthread_mutex_destroy(&job.lock);
    for (int v = 1; v < nview_scene; ++v)
        ef_scene_free(&view_scene[v]);
    ef_ocio_display_close(disp);
    ef_exr_close(&dep);
    ef_exr_close(&in);
    return status;
}

/* Appends frame f to a comma list in b (at most len), ending in "..."
 * once it is full. */
static void list_frame(char *b, size_t len, long f)
{
    const size_t at = strlen(b);
    if (at + 24 >= len) {
        if (at + 4 < len && strcmp(b + at - 3, "..."))
            snprintf(b + at, len - at, ", ...");
        return;
    }
    snprintf(b + at, len - at, "%s%ld", at ? ", " : "", f);
}

/* Runs every frame of a sequence in order: the frames of --frames, or
 * every frame on disk matching INPUT. Missing frames are found before any
 * work; a failed frame stops the run unless --keep-going, which fogs the
 * others and names every failure at the end. */
static int run_sequence(ef_options *o, frame_ctx *fr, const ef_frame_pattern *pin)
{
    const char *pattern = o->input, *out_pat = o->output, *dep_pat = o->depth_file,
               *pv_pat = o->preview;
    ef_frame_pattern pout = { 0 }, pdep = { 0 }, ppv = { 0 };
    ef_err err = { 0 };
    if (out_pat && !ef_frame_pattern_find(out_pat, &pout)) {
        return say_error(2, "INPUT is a sequence (%s) but -o %s has no frame pattern; every frame "
                            "would overwrite it (write e.g. -o fog.#.exr)", pattern, out_pat);
    }
    if (pv_pat && !ef_frame_pattern_find(pv_pat, &ppv)) {
        return say_error(2, "INPUT is a sequence (%s) but --preview %s has no frame pattern "
                            "(write e.g. --preview fog.#.png)", pattern, pv_pat);
    }
    if (dep_pat)
        ef_frame_pattern_find(dep_pat, &pdep);   /* one depth for every frame is allowed */
    long *frames = NULL;
    int n = 0;
    if (o->frames ? ef_frames_parse(o->frames, &frames, &n, &err)
                  : ef_frames_on_disk(pattern, pin, &frames, &n, &err)) {
        if (o->frames) {
            return say_error(2, "%s", err.msg);
        }
        return report(pattern, &err, 1);
    }
    if (n == 0) {
        if (pin->len > 1 && pattern[pin->at] == '#')
            ef_fail(&err, "no file on disk matches this frame pattern; as in oiiotool, each # "
                          "is four digits, so %d #s are %d digits (write shot.#.exr or "
                          "shot.%%04d.exr for shot.0001.exr)", (int) pin->len, pin->width);
        else
            ef_fail(&err, "no file on disk matches this frame pattern (check the name and the "
                          "padding: # is 4 digits, @ one digit, %%04d four)");
        return report(pattern, &err, 1);
    }
    static char in_path[4096], out_path[4096], dep_path[4096], pv_path[4096];
    char missing[400] = "";
    int nmissing = 0;
    unsigned char *skip = calloc((size_t) n, 1);
    if (!skip) {
        free(frames);
        fputs("exrfog: out of memory\n", msg_out());
        return 1;
    }
    for (int i = 0; i < n; ++i) {
        struct stat st;
        const int bad = ef_frame_path(pattern, pin, frames[i], in_path, sizeof in_path) ||
                        stat(in_path, &st) ||
                        (dep_pat && (ef_frame_path(dep_pat, &pdep, frames[i], dep_path,
                                                   sizeof dep_path) || stat(dep_path, &st)));
        if (bad) {
            skip[i] = 1;
            ++nmissing;
            list_frame(missing, sizeof missing, frames[i]);
        }
    }
    int status = 0;
    if (nmissing && !o->keep_going) {
        say_error(1, "%s: %d of %d frame%s missing on disk%s: %s; nothing was written (render "
                     "them, choose others with --frames, or pass --keep-going)", pattern,
                  nmissing, n, n > 1 ? "s" : "", dep_pat && pdep.has ? " (colour or depth)" : "",
                  missing);
        free(skip);
        free(frames);
        return 1;
    }
    if (o->explain && !o->json)
        fprintf(out_stream(), "sequence: %s, %d frame%s (%ld to %ld), time = frame / %g fps%s\n", pattern, n,
               n > 1 ? "s" : "", frames[0], frames[n - 1], o->fps,
               o->time_set ? " (overridden by --time or the scene file)" : "");
    char failed[400] = "";
    int nfailed = 0;
    if (fr->pg)
        fr->pg->nframes = n - nmissing;
    for (int i = 0; i < n; ++i) {
        if (skip[i]) {
            ++nfailed;
            list_frame(failed, sizeof failed, frames[i]);
            continue;
        }
        if (ef_frame_path(pattern, pin, frames[i], in_path, sizeof in_path) ||
            (out_pat && ef_frame_path(out_pat, &pout, frames[i], out_path, sizeof out_path)) ||
            (dep_pat && ef_frame_path(dep_pat, &pdep, frames[i], dep_path, sizeof dep_path)) ||
            (pv_pat && ef_frame_path(pv_pat, &ppv, frames[i], pv_path, sizeof pv_path))) {
            status = say_error(1, "%s: the path of frame %ld is too long", pattern, frames[i]);
            break;
        }
        o->input = in_path;
        o->output = out_pat ? out_path : NULL;
        o->depth_file = dep_pat ? dep_path : NULL;
        o->preview = pv_pat ? pv_path : NULL;
        fr->has_frame = 1;
        fr->frame = frames[i];
        if (fr->pg) {
            fr->pg->has_frame = 1;
            fr->pg->frame = frames[i];
        }
        const int rc = run_frame(o, fr);
        if (fr->pg) {
            fr->pg->done++;
            fr->pg->px_total += fr->pg->frame_px;
            fr->pg->frame_px = 0;
            fr->pg->px = 0;
        }
        if (o->explain)
            break;   /* the first frame tells what every frame is read as */
        if (rc == 0)
            continue;
        /* A usage error is the same for every frame; a cancel stops all. */
        if (rc == 2 || rc == 3 || !o->keep_going) {
            status = rc;
            if (rc == 1 && i + 1 < n)
                fprintf(msg_out(), "exrfog: %s: stopped at frame %ld; frames before it are written, "
                                "none after (--keep-going fogs the others)\n", pattern, frames[i]);
            break;
        }
        ++nfailed;
        list_frame(failed, sizeof failed, frames[i]);
    }
    if (status == 0 && nfailed) {
        progress_clear(fr->pg);
        status = say_error(1, "%s: %d of %d frames failed: %s", pattern, nfailed, n, failed);
    }
    o->input = pattern;
    o->output = out_pat;
    o->depth_file = dep_pat;
    o->preview = pv_pat;
    free(skip);
    free(frames);
    return status;
}

/* One run of the program with its messages going to msg_out(). */
static int run_main(int argc, char **argv, int (*hook)(void *, double), void *hook_user)
{
    static ef_options o;
    ef_err err = {0};
    /* The command line as typed, for the history: getopt permutes argv. */
    char **typed = malloc(((size_t) argc + 1) * sizeof *typed);
    if (!typed) {
        fputs("exrfog: out of memory\n", msg_out());
        return 1;
    }
    memcpy(typed, argv, ((size_t) argc + 1) * sizeof *typed);
    ef_parse_result pr = ef_options_parse(argc, argv, &o, &err);
    if (pr != EF_PARSE_RUN) {
        free(typed);
        ef_options_free(&o);
        if (pr == EF_PARSE_EXIT)
            return 0;
        if (pr == EF_PARSE_FAIL)
            return report(err.file, &err, 1);
        return say_error(2, "%s", err.msg);
    }

    frame_ctx fr = { .argc = argc, .typed = typed };
    static progress pg;
    memset(&pg, 0, sizeof pg);
    pthread_mutex_init(&pg.lock, NULL);
    pg.t0 = wall_now();
    pg.hook = hook;
    pg.hook_user = hook_user;
    pg.draw = !o.quiet && !o.explain && !g_msg && isatty(STDERR_FILENO);
    if (pg.draw || (hook && !o.explain)) {
        fr.pg = &pg;
        active_pg = &pg;
    }
    int status = 0;
    ef_frame_pattern pin;
    if (!ef_frame_pattern_find(o.input, &pin)) {
        if (o.frames) {
            status = say_error(2, "--frames needs a frame pattern in INPUT (shot.#.exr, "
                                  "shot.%%04d.exr or shot.@@@@.exr)");
        } else {
            pg.nframes = 1;
            status = run_frame(&o, &fr);
        }
    } else {
        status = run_sequence(&o, &fr, &pin);
    }
    progress_clear(active_pg);
    active_pg = NULL;
    ef_camera_file_free(g_camfile);
    g_camfile = NULL;
    ef_colour_close();
    pthread_mutex_destroy(&pg.lock);
    free(typed);
    ef_options_free(&o);
    return status;
}

int ef_main(int argc, char **argv)
{
    g_msg = NULL;
    return run_main(argc, argv, NULL, NULL);
}

int ef_run_lib(int argc, char **argv, FILE *msgs, FILE *out, int (*progress)(void *, double),
               void *user, char *err, size_t errlen)
{
    g_msg = msgs;
    g_out = out;
    g_last_error[0] = '\0';
    const int status = run_main(argc, argv, progress, user);
    g_msg = NULL;
    g_out = NULL;
    snprintf(err, errlen, "%s", status ? g_last_error : "");
    return status;
}
