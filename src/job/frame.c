/* One frame of a run, as stages over an ef_frame on the heap: the
 * destinations are checked and their temporary files made before a pixel
 * is read; then the inputs, the views and their cameras, the pass, and the
 * results put in place. Every stage returns 0 to go on, or the frame's
 * exit status with its message printed (FRAME_DONE: finished early, 0). */
#define _GNU_SOURCE 1
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <strings.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "apply.h"
#include "edges.h"
#include "deep_pass.h"
#include "exr_deep.h"
#include "exr_dwa.h"
#include "deliver.h"
#include "job_impl.h"
#include "lit.h"
#include "output.h"
#include "foreign.h"
#include "scene_build.h"

_Static_assert(EF_AOV_MAX_CHANNELS <= EF_MAX_EXTRA_CHANNELS,
               "the writer takes every AOV channel a scene can ask for");

#define FRAME_DONE (-1)

/* What the workers share read-only during the pass, except the statistics,
 * which each unit adds under the lock. */
typedef struct fog_job {
    ef_job *J;
    ef_fog_pass pass[EF_MAX_VIEWS];   /* per view (ef_chunk.view) */
    unsigned aov;             /* EF_AOV_* bits, in the stream's extra channels */
    double aov_origin[3];
    ef_tau_stats *stats;      /* per component, or NULL without --stats */
    pthread_mutex_t lock;
    const ef_ocio_display *disp;  /* the preview's display transform */
    /* preview: every step-th pixel of the data window */
    unsigned char *preview;
    int pv_w, pv_h, pv_step, dw_x0, dw_y0;
    int edges;                /* --edges unmix */
    _Atomic int edge_oom;     /* a unit could not get the edges' memory */
} fog_job;

typedef struct ef_frame {
    ef_job *J;
    ef_options *o;
    ef_err err;
    ef_exr_file in, dep;
    const ef_exr_file *df;
    const char *ipath;        /* INPUT, or its DWA-decoded temporary copy */
    ef_dwa_info dwa;
    ef_channel_plan plans[EF_MAX_VIEWS];
    ef_camera cams[EF_MAX_VIEWS];
    ef_depth_conv convs[EF_MAX_VIEWS];
    int convs_ok[EF_MAX_VIEWS];
    ef_fog_scene *view_scene[EF_MAX_VIEWS];   /* views after the first: copies */
    int nplans;
    char camfile_src[600];
    ef_ocio_display *disp;
    fog_job job;
    const char *aov_names[EF_AOV_MAX_CHANNELS];
    int naov;
    char blender_aov[EF_AOV_MAX_CHANNELS][256];   /* Blender's pass names, when used */
    unsigned char aov_data[EF_AOV_MAX_CHANNELS];  /* per AOV channel: a position or distance */
    ef_output out, pv, mid, dconv, din;
    const char *ext;          /* OUTPUT's extension when it is not .exr */
    int foreign;
    ef_deliver dv;            /* foreign: its type, channels, colour, geometry */
    char *history;
    exr_attr_box2i_t dw;
    ef_stream_opts so;
    ef_stream_stats st;
    int dwa_out;
    float dwa_level;
    int deep;                 /* the colour part is deep (deep.c's pass) */
    char din_path[PATH_MAX], dconv_path[PATH_MAX];   /* fd_path of din and dconv */
    ef_deep_result deep_res;
    double pred_fog_s;        /* probe_cost: the frame's fog predicted, in thread seconds */
    int pred_n;               /* the pixels it timed (0: not probed) */
} ef_frame;

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

/* The unit's preview pixels through the display transform, then 8 bits. */
static void preview_unit(fog_job *j, const ef_chunk *ck)
{
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

/* The stream's work on one unit: fog, statistics, progress, preview. */
static void fog_chunk(void *user, const ef_chunk *ck)
{
    fog_job *j = user;
    if (ef_job_cancelled(j->J))
        return;   /* the output is thrown away: no work for it */
    ef_aov_out aov;
    ef_aov_bind(&aov, j->aov, j->pass[0].scene, ck->extra);
    memcpy(aov.origin, j->aov_origin, sizeof aov.origin);
    /* Statistics per unit, merged once: no lock per pixel. */
    ef_tau_stats st[EF_FOG_MAX_COMPONENTS];
    const int ncomp = j->pass[0].scene->ncomp;
    if (j->stats) {
        memset(st, 0, sizeof st);
        st[0].clock_ns = mono_ns;
        st[0].cpu_ns = thread_cpu_ns;
    }
    /* --edges: the edge pixels are found on the input as read (the pass
     * then writes over it) and replaced after it */
    ef_edge_work wk = { 0 };
    int nedge = 0;
    if (j->edges) {
        _Static_assert(EF_STREAM_HALO >= EF_EDGE_HALO, "the stream reads the rows edges need");
        const ef_edge_rows u = { ck->x0, ck->y0, ck->w, ck->h,
                                 { ck->rgb[0], ck->rgb[1], ck->rgb[2] }, ck->alpha, ck->depth,
                                 { ck->halo_rgb[0][0], ck->halo_rgb[0][1], ck->halo_rgb[0][2] },
                                 ck->halo_alpha[0], ck->halo_depth[0],
                                 { ck->halo_rgb[1][0], ck->halo_rgb[1][1], ck->halo_rgb[1][2] },
                                 ck->halo_alpha[1], ck->halo_depth[1],
                                 ck->halo_rows[0], ck->halo_rows[1] };
        nedge = ef_edge_find(&j->pass[ck->view], &u, (j->aov & EF_AOV_ERROR) != 0, &wk);
        if (nedge < 0) {
            atomic_store(&j->edge_oom, 1);
            nedge = 0;
        }
    }
    ef_fog_block_aov(&j->pass[ck->view], ck->x0, ck->y0, ck->w, ck->h, ck->rgb, ck->alpha, ck->depth, &aov,
                     j->stats ? st : NULL);
    if (nedge)
        ef_edge_apply(&j->pass[ck->view], ck->x0, ck->y0, ck->w, wk.px, nedge, ck->rgb, ck->alpha,
                      &aov);
    ef_edge_work_free(&wk);
    if (j->stats) {
        pthread_mutex_lock(&j->lock);
        for (int i = 0; i < ncomp; ++i)
            ef_tau_stats_merge(&j->stats[i], &st[i]);
        pthread_mutex_unlock(&j->lock);
    }
    ef_progress_add(j->J, (long) ck->w * ck->h);
    if (j->preview && ck->view == 0)
        preview_unit(j, ck);
}

/* The name other libraries open one of our temporary files by: its
 * descriptor's /proc/self/fd/N, which reaches the file this run created
 * even if its directory entry was replaced meanwhile (by a symlink to a
 * file of someone else's, say); the plain name only where /proc is
 * missing. */
static void fd_path(char *buf, size_t len, int fd, const char *name)
{
    if (fd >= 0 && access("/proc/self/fd", X_OK) == 0)
        snprintf(buf, len, "/proc/self/fd/%d", fd);
    else
        snprintf(buf, len, "%s", name);
}

/* Where temporary copies of inputs go: $TMPDIR, else /tmp. */
static void temp_name(char *name, size_t len, const char *what)
{
    const char *tmpdir = getenv("TMPDIR");
    snprintf(name, len, "%s/%s", tmpdir && tmpdir[0] ? tmpdir : "/tmp", what);
}

/* Refuses to write out (as flag says) over a file the frame reads: the
 * same name, or the same file through a link. INPUT counts only when
 * with_input: -o INPUT replaces the image in place, as asked. Returns 0,
 * or 2 with the message printed. */
static int refuse_clash(ef_frame *F, const char *out, const char *flag, int with_input)
{
    ef_job *J = F->J;
    ef_read_list *r = malloc(sizeof *r);
    if (!r) {
        ef_fail(&F->err, "out of memory");
        return ef_job_report(J, out, &F->err, 1);
    }
    ef_job_reads(J, J->has_frame, J->frame, with_input, r);
    const ef_read_file *f = ef_output_clash(r, out);
    int rc = 0;
    if (f) {
        const int same_name = !strcmp(out, f->path);
        ef_fail(&F->err, "%s names %s%s%s%s%s: writing it would replace a file this run reads; "
                         "nothing was written (give the output its own name)",
                flag, ef_read_article(f), f->role, same_name ? "" : " (",
                same_name ? "" : f->path, same_name ? "" : ", the same file)");
        rc = ef_job_report(J, out, &F->err, 2);
    }
    free(r);
    return rc;
}

/* --preview: checked and its temporary file made before any work. */
static int open_preview(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    char msg[512];
    if (o->output && (!strcmp(o->preview, o->output) || ef_output_same_file(o->preview, o->output))) {
        ef_fail(&F->err, "--preview names the same file as -o; give the preview its own name");
        return ef_job_report(J, o->preview, &F->err, 2);
    }
    int rc = refuse_clash(F, o->preview, "--preview", 1);
    if (rc)
        return rc;
    if (ef_preview_check(o->preview, msg, sizeof msg)) {
        ef_fail(&F->err, "--preview: %s", msg);
        return ef_job_report(J, o->preview, &F->err, 2);
    }
    /* the display and view exist (the working space comes later) */
    const ef_ocio *cfg = ef_colour_config(&J->colour, &F->err);
    if (!cfg)
        return ef_job_report(J, o->preview, &F->err, 1);
    char used[300], vmsg[1200];
    ef_ocio_display *d = ef_ocio_display_open(cfg, NULL, o->preview_view, used, sizeof used,
                                              vmsg, sizeof vmsg);
    if (!d) {
        ef_fail(&F->err, "--preview-view: %s", vmsg);
        return ef_job_report(J, o->preview, &F->err, 2);
    }
    ef_ocio_display_close(d);
    const char *dot = strrchr(o->preview, '.'), *slash = strrchr(o->preview, '/');
    rc = ef_output_open(&F->pv, o->preview, dot && (!slash || dot > slash) ? dot : NULL,
                                  J->h.temps, &F->err);
    return rc ? ef_job_report(J, o->preview, &F->err, rc) : 0;
}

/* Everything about the destinations is checked, and their temporary files
 * made, before a pixel is read. OUTPUT's extension chooses the format:
 * .exr (or none) is written here, anything else through OpenImageIO from
 * an EXR beside it. */
static int open_destinations(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    F->ext = o->output ? strrchr(o->output, '.') : NULL;
    if (F->ext && strchr(F->ext, '/'))
        F->ext = NULL;
    F->foreign = F->ext && strcasecmp(F->ext, ".exr") != 0;
    if (o->explain)
        return 0;
    int rc;
    if (o->output && (rc = refuse_clash(F, o->output, "-o", 0)) != 0)
        return rc;
    if (o->preview && (rc = open_preview(F)) != 0)
        return rc;
    struct stat ost;
    if (o->output && stat(o->output, &ost) == 0 && S_ISDIR(ost.st_mode)) {
        ef_fail(&F->err, "is a directory; give a file name (e.g. %s/fog.exr)", o->output);
        return ef_job_report(J, o->output, &F->err, 2);
    }
    if (!F->foreign && o->output && o->out_dt >= EF_DT_UINT8 && o->out_dt <= EF_DT_UINT16) {
        ef_fail(&F->err, "-d uint%s is for non-EXR outputs (.png, .tif, .dpx, .jpg); EXR colour "
                         "is half or float (-d half|float)",
                o->out_dt == EF_DT_UINT8 ? "8" : o->out_dt == EF_DT_UINT10 ? "10"
                : o->out_dt == EF_DT_UINT12 ? "12" : "16");
        return ef_job_report(J, o->output, &F->err, 2);
    }
    if (o->output_display && o->output && !F->foreign) {
        ef_fail(&F->err, "--output-display is for non-EXR outputs (.png, .tif, .dpx, .jpg): an "
                         "EXR stays scene-referred (use --preview for a display view of it)");
        return ef_job_report(J, o->output, &F->err, 2);
    }
    if (F->foreign) {
        if (F->naov) {
            ef_fail(&F->err, "--aov needs an EXR output: AOVs are extra channels, and %s holds "
                             "colour and alpha only", F->ext);
            return ef_job_report(J, o->output, &F->err, 2);
        }
        if ((rc = ef_deliver_plan(J, F->ext, &F->dv, &F->err)) != 0)
            return ef_job_report(J, o->output, &F->err, rc);
    }
    if ((rc = ef_output_open(&F->out, o->output, F->foreign ? F->ext : NULL, J->h.temps,
                             &F->err)) != 0)
        return ef_job_report(J, o->output, &F->err, rc);
    if (F->foreign &&
        (rc = ef_output_open(&F->mid, o->output, ".exr", J->h.temps, &F->err)) != 0)
        return ef_job_report(J, o->output, &F->err, rc);
    return 0;
}

/* Standard error taken over while a third-party reader runs, when the
 * host owns it (the program): libpng prints "libpng error: ..." on
 * descriptor 2 beside the error it returns. */
typedef struct err_capture {
    int saved, fd;
} err_capture;

static void capture_begin(const ef_job *J, err_capture *c)
{
    c->saved = c->fd = -1;
    if (!J->h.own_stderr)
        return;
    fflush(stderr);
    c->fd = memfd_create("exrfog-stderr", MFD_CLOEXEC);
    if (c->fd >= 0 && (c->saved = dup(2)) >= 0 && dup2(c->fd, 2) >= 0)
        return;
    if (c->saved >= 0)
        close(c->saved);
    if (c->fd >= 0)
        close(c->fd);
    c->saved = c->fd = -1;
}

/* Gives descriptor 2 back; what was printed meanwhile, one line joined by
 * "; ", goes to text (empty when nothing was). */
static void capture_end(err_capture *c, char *text, size_t len)
{
    text[0] = '\0';
    if (c->fd < 0)
        return;
    fflush(stderr);
    dup2(c->saved, 2);
    close(c->saved);
    char buf[1024];
    const ssize_t n = pread(c->fd, buf, sizeof buf - 1, 0);
    close(c->fd);
    size_t at = 0;
    for (ssize_t i = 0; n > 0 && i < n && at + 3 < len; ++i) {
        const char ch = buf[i];
        if (ch == '\n') {
            if (i + 1 < n && at)
                at += (size_t) snprintf(text + at, len - at, "; ");
        } else if (ch >= 0x20 && ch < 0x7f) {
            text[at++] = ch;
        }
    }
    text[at < len ? at : len - 1] = '\0';
}

/* The inputs: DWA parts (which OpenEXRCore 3.1.5 cannot decode) decoded by
 * the OpenEXR C++ library into a temporary ZIP file first; a depth in
 * another format (a 32-bit TIFF pass) read through OpenImageIO into a
 * temporary float EXR. */
static int open_inputs(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    F->ipath = o->input;
    {
        ef_err derr = { 0 };
        if (!ef_regular_file(o->input) || ef_exr_dwa_info(o->input, &F->dwa, &derr))
            F->dwa.ndwa = 0;   /* not an EXR: the reader below says what is wrong */
    }
    if (F->dwa.ndwa > 0) {
        char name[PATH_MAX], msg[800];
        temp_name(name, sizeof name, "exrfog-dwa");
        if (ef_output_open(&F->din, name, ".exr", J->h.temps, &F->err))
            return ef_job_report(J, o->input, &F->err, 1);
        if (ef_dwa_transcode(o->input, F->din.fd, F->din.tmp, EXR_COMPRESSION_ZIP, -1, -1.0f,
                             o->threads ? o->threads : ef_cpu_count(), msg, sizeof msg)) {
            ef_fail(&F->err, "%s", msg);
            return ef_job_report(J, o->input, &F->err, 1);
        }
        fd_path(F->din_path, sizeof F->din_path, F->din.fd, F->din.tmp);
        F->ipath = F->din_path;
    }
    if (ef_exr_open(F->ipath, &F->in, &F->err))
        return ef_job_report(J, o->input, &F->err, 1);
    F->in.path = o->input;   /* messages name the user's file */
    F->df = &F->in;
    if (!o->depth_file)
        return 0;
    const char *dpath = o->depth_file;
    if (!ef_is_exr_file(o->depth_file)) {
        char name[PATH_MAX], msg[600];
        temp_name(name, sizeof name, "exrfog-depth");
        if (ef_output_open(&F->dconv, name, ".exr", J->h.temps, &F->err))
            return ef_job_report(J, o->depth_file, &F->err, 1);
        err_capture cap;
        char raw[600];
        capture_begin(J, &cap);
        /* A depth pass covers its render's windows (overscan: a little
         * more): four times the larger is the most that can be one. */
        exr_attr_box2i_t dw, disp;
        double most = 0;
        if (!exr_get_data_window(F->in.ctx, 0, &dw) && !exr_get_display_window(F->in.ctx, 0, &disp))
            most = 4 * fmax(((double) dw.max.x - dw.min.x + 1) * ((double) dw.max.y - dw.min.y + 1),
                            ((double) disp.max.x - disp.min.x + 1) *
                                ((double) disp.max.y - disp.min.y + 1));
        const int bad = ef_oiio_image_to_exr(o->depth_file, F->dconv.fd, most, msg, sizeof msg);
        capture_end(&cap, raw, sizeof raw);
        if (bad) {
            ef_fail(&F->err, "%s%s%s%s", msg, raw[0] ? " (the reader said: " : "", raw,
                    raw[0] ? ")" : "");
            return ef_job_report(J, o->depth_file, &F->err, 1);
        }
        if (raw[0])
            ef_job_warn(J, o->depth_file, raw);
        fd_path(F->dconv_path, sizeof F->dconv_path, F->dconv.fd, F->dconv.tmp);
        dpath = F->dconv_path;
    }
    if (ef_exr_open(dpath, &F->dep, &F->err))
        return ef_job_report(J, o->depth_file, &F->err, 1);
    F->dep.path = o->depth_file;   /* messages name the user's file */
    F->df = &F->dep;
    return 0;
}

/* A deep colour part: what its pass can do, refused clearly otherwise. */
static int check_deep(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    F->deep = ef_exr_part_is_deep(&F->in, F->plans[0].rgb[0].part);
    if (F->df != &F->in && ef_exr_part_is_deep(F->df, F->plans[0].depth.part)) {
        ef_fail(&F->err, "the depth file is deep; deep samples carry their own Z (give the deep "
                         "image as INPUT alone)");
        return ef_job_report(J, o->depth_file, &F->err, 1);
    }
    if (!F->deep) {
        if ((o->deep_set || o->deep_grey) && !o->explain) {
            /* in a sequence it is this frame's file that differs from the
             * rest: a failed frame (--keep-going goes on), not a usage error */
            ef_fail(&F->err, J->has_frame
                                 ? "%s applies to deep input, and this frame is flat (the "
                                   "sequence mixes flat and deep frames)"
                                 : "%s applies to deep input, and INPUT is flat (leave it out)",
                    o->deep_set ? "--deep" : "--deep-grey-alpha");
            return ef_job_report(J, o->input, &F->err, J->has_frame ? 1 : 2);
        }
        return 0;
    }
    const char *why = NULL;
    int status = 2;
    if (F->nplans > 1)
        why = "deep input with several views is not supported (choose one with --view NAME)";
    else if (o->edges)
        why = "--edges applies to flat input: deep samples carry each surface's own depth, so "
              "deep fog is exact at edges already (leave --edges out)";
    else if (o->deep_grey && o->deep_mode == EF_DEEP_MODE_FLATTEN)
        why = "--deep-grey-alpha applies to deep output (--deep samples or fog): a flattened "
              "image is exact per channel already";
    else if (F->naov && o->deep_mode != EF_DEEP_MODE_FLATTEN)
        why = "--aov with deep input needs --deep flatten (a deep output carries no AOVs: "
              "its fog samples are the fog)";
    else if (F->foreign && o->deep_mode != EF_DEEP_MODE_FLATTEN)
        why = "a deep output is EXR (--deep flatten writes other formats)";
    else if (o->preview)
        why = "--preview does not apply to deep input";
    else if (o->depth_file)
        why = "--depth does not apply to deep input: its samples carry their own Z (leave "
              "--depth out)";
    if (why) {
        ef_fail(&F->err, "%s", why);
        return ef_job_report(J, o->input, &F->err, status);
    }
    /* A fine --deep-tol, once per run: the split rule's bound falls with
     * the square of a fog sample's length, so the samples, and the deep
     * pass's time, grow as sqrt(1e-3 / tol). */
    if (o->deep_tol < EF_DEEP_TOL_COSTLY && !J->noted_deep_tol && !o->quiet && !o->explain) {
        J->noted_deep_tol = 1;
        char msg[400];
        snprintf(msg, sizeof msg, "--deep-tol %g asks for about %.0f times the fog samples of "
                                  "the default %g where a fog sample is split by its bound, and "
                                  "the deep pass takes about that much longer there; a float "
                                  "channel stores 6e-8, a half one 5e-4",
                 o->deep_tol, sqrt(EF_DEEP_DEFAULT_TOL / o->deep_tol), EF_DEEP_DEFAULT_TOL);
        ef_job_warn(J, o->input, msg);
    }
    return 0;
}

/* On a Blender multilayer input (colour LAYER.Combined.R), the AOVs are
 * passes of that view layer, as Blender's compositor lists them:
 * LAYER.Fog.R, LAYER.FogT.R, LAYER.FogError.R, LAYER.FogP.X and
 * LAYER.FogDistance.Z (Blender 3.4 reads LAYER.PASS.CHANNEL). Other inputs
 * keep the Nuke-style names (fog.R, fog_T.R...). */
static void blender_aov_names(ef_frame *F)
{
    const char *r = F->plans[0].rgb[0].name, *at = strstr(r, ".Combined.");
    if (!F->naov || !at || at == r || strstr(at + 1, ".Combined."))
        return;
    static const struct {
        const char *from, *to;
    } pass[] = { { "fog_distance.", "FogDistance." }, { "fog_error.", "FogError." },
                 { "fog_T.", "FogT." }, { "fog_P.", "FogP." }, { "fog.", "Fog." },
                 { "fog_ambient.", "FogAmbient." }, { "fog_light.", "FogLight_" },
                 { "fog_lit.", "FogLit." } };
    for (int i = 0; i < F->naov; ++i) {
        const char *n = F->aov_names[i];
        for (size_t k = 0; k < sizeof pass / sizeof pass[0]; ++k) {
            const size_t len = strlen(pass[k].from);
            if (!strncmp(n, pass[k].from, len)) {
                snprintf(F->blender_aov[i], sizeof F->blender_aov[i], "%.*s.%s%s",
                         (int) (at - r), r, pass[k].to, n + len);
                F->aov_names[i] = F->blender_aov[i];
                break;
            }
        }
    }
}

/* The views to fog (every view of a multi-view file, or those of --view),
 * each with its channels; the working space, when colours or the preview
 * need it (colours written as #RRGGBB or SPACE:R,G,B are then read again
 * in it); and what the output format and the AOVs allow. */
static int find_views(ef_frame *F)
{
    ef_job *J = F->J;
    ef_options *o = F->o;
    char views[EF_MAX_VIEWS][64];
    const int nfile_views = ef_exr_views(&F->in, views, EF_MAX_VIEWS);
    if (nfile_views > EF_MAX_VIEWS) {
        /* fogging the first eight and copying the rest was silent */
        ef_fail(&F->err, "INPUT has more than %d views (%s, %s, ...); exrfog fogs at most %d "
                         "views of a file in one run and copies none unfogged without saying so "
                         "(split the views into files of at most %d, e.g. with oiiotool)",
                EF_MAX_VIEWS, views[0], views[1], EF_MAX_VIEWS, EF_MAX_VIEWS);
        return ef_job_report(J, o->input, &F->err, 1);
    }
    int status = ef_choose_views(J, &F->in, F->df, views, nfile_views, F->plans, &F->nplans,
                                 &F->err);
    if (status) {
        if (o->explain && status == 1) {
            /* Everything found, then the error: the header's camera too. */
            ef_cam_flags flags = o->cam;
            ef_cam_meta meta;
            ef_err e2 = { 0 };
            const int have = ef_camera_flags(J, &flags, F->camfile_src, sizeof F->camfile_src,
                                             &e2) == 0 &&
                             ef_exr_read_cam_meta(&F->in, 0, &meta, &e2) == 0 &&
                             ef_camera_resolve(&meta, &flags, &F->cams[0], &e2) == 0;
            ef_explain(J, J->out, &F->in, NULL, have ? &F->cams[0] : NULL, NULL, 0);
        }
        return ef_job_report(J, o->input, &F->err, status);
    }
    if ((status = ef_colour_working(&J->colour, &F->in, F->plans[0].rgb[0].part,
                                    ef_colour_converted(&J->colour) || o->preview || o->explain ||
                                        (F->foreign && ef_deliver_needs_colour(J, &F->dv)),
                                    &F->err)) != 0)
        return ef_job_report(J, o->input, &F->err, status);
    if (F->foreign && !o->explain && (status = ef_deliver_colour(J, &F->dv, &F->err)) != 0)
        return ef_job_report(J, o->output, &F->err, status);
    if (ef_colour_converted(&J->colour)) {
        if (ef_scene_rebuild(&o->scene, NULL, o->scene.ctx.time, &F->err) ||
            (o->fog_color && ef_colour_parse(&J->colour, o->fog_color, o->scene.color, &F->err)))
            return ef_job_report(J, o->input, &F->err, 1);
    }
    blender_aov_names(F);
    const char *clash = ef_exr_part_has_any(&F->in, F->plans[0].rgb[0].part, F->aov_names, F->naov);
    if (clash && !F->plans[0].chan_view[0]) {
        char list[64];
        ef_aov_list(o->aov, list, sizeof list);
        ef_fail(&F->err, "--aov %s: the colour part already has a channel '%s'; the AOV would "
                         "overwrite it (leave that AOV out, or rename the channel)", list, clash);
        return ef_job_report(J, o->input, &F->err, 2);
    }
    if ((status = check_deep(F)) != 0)
        return status;
    if (F->foreign && F->nplans > 1) {
        ef_fail(&F->err, "%s holds one image and INPUT has %d views (%s, ...); choose one with "
                         "--view NAME", strrchr(o->output, '.'), F->nplans, F->plans[0].view);
        return ef_job_report(J, o->output, &F->err, 2);
    }
    return 0;
}

/* The camera metadata of view v: in a single-part multi-view file the
 * header's camera is the default view's, and another view has none. */
static int view_meta(ef_frame *F, const ef_channel_plan *pl, ef_cam_meta *meta)
{
    if (pl->view[0] && F->in.nparts == 1 && !pl->default_view) {
        exr_attr_box2i_t disp;
        exr_get_display_window(F->in.ctx, 0, &disp);
        ef_cam_meta_init(meta, disp.min.x, disp.min.y, disp.max.x, disp.max.y);
        float pa = 1;
        if (exr_get_pixel_aspect_ratio(F->in.ctx, 0, &pa) == EXR_ERR_SUCCESS && pa > 0)
            meta->pixel_aspect = pa;
        return 0;
    }
    if (ef_exr_read_cam_meta(&F->in, pl->rgb[0].part, meta, &F->err))
        return ef_job_report(F->J, F->o->input, &F->err, 1);
    return 0;
}

/* A failed camera: --explain shows what was found, the message names the
 * view. A bad --world-to-camera is a usage error; a bad header is not. */
static int camera_failed(ef_frame *F, const ef_channel_plan *pl, const ef_camera *cam)
{
    ef_job *J = F->J;
    if (F->o->explain)
        ef_explain(J, J->out, &F->in, pl, NULL, NULL, 0);
    if (pl->view[0]) {
        char msg[sizeof F->err.msg];
        snprintf(msg, sizeof msg, "%s", F->err.msg);
        ef_fail(&F->err, "view '%s': %s%s", pl->view, msg,
                F->in.nparts == 1 && !pl->default_view
                    ? " (in a single-part multi-view file the header's camera is the "
                      "default view's)"
                    : "");
    }
    return ef_job_report(J, F->o->input, &F->err, cam->flag_error ? 2 : 1);
}

/* Each view binds the scene to its own camera: a copy per view after the
 * first. */
static int bind_view(ef_frame *F, int v)
{
    ef_options *o = F->o;
    ef_fog_scene *sc = &o->scene;
    if (v > 0) {
        F->view_scene[v] = malloc(sizeof *F->view_scene[v]);
        if (!F->view_scene[v] || ef_scene_copy(F->view_scene[v], &o->scene, 1)) {
            free(F->view_scene[v]);
            F->view_scene[v] = NULL;
            ef_fail(&F->err, "out of memory for the scene of view %d", v);
            return ef_job_report(F->J, o->input, &F->err, 1);
        }
        sc = F->view_scene[v];
    }
    ef_scene_bind_camera(sc, &F->cams[v]);
    ef_scene_set_cancel(sc, F->J->stop);
    F->job.pass[v] = (ef_fog_pass){ &F->cams[v], &F->convs[v], sc };
    return 0;
}

/* The warning before a frame predicted to take more than two minutes on
 * the run's threads (secs of wall time): what is predicted, from what,
 * and the advice (from "; "). */
static void warn_predicted(ef_job *J, const char *file, const char *what, double secs,
                           double ms_px, int sampled, int threads, const char *advice)
{
    char msg[600], when[64];
    if (secs < 2 * 3600)
        snprintf(when, sizeof when, "%.0f minutes", secs / 60);
    else
        snprintf(when, sizeof when, "%.1f hours", secs / 3600);
    snprintf(msg, sizeof msg, "this %s is predicted to take about %s (%.3g ms of fog a pixel on "
                              "%d sampled pixels, %d thread%s)%s; Ctrl-C stops it and writes "
                              "nothing",
             what, when, ms_px, sampled, threads, threads > 1 ? "s" : "", advice);
    ef_job_warn(J, file, msg);
}

/* Up to 64 columns of a row, in bit-reversed order: a probe stopped early
 * has still seen the whole width. */
static int probe_column(int k)
{
    int r = 0;
    for (int b = 0; b < 6; ++b)
        r |= (k >> b & 1) << (5 - b);
    return r;
}

/* Before a costly run: the fog of a sample of this frame's pixels (16 rows
 * of the depth, up to 64 pixels each, the whole per-pixel pass with its
 * lights), timed on this thread and projected over the frame on the run's
 * threads; a warning past two minutes, and the prediction for --stats.
 * Timing, not a count: the clamp's pieces, separable factors and lit
 * noise cost what no evaluation count foresees. The probe stops after
 * half a second (whole pixels: a cancel stops the pixel), so it costs a
 * cheap frame nothing and a costly one a fraction of a per cent. Only
 * where some component's cost varies by the pixel (noise) or lights
 * integrate: closed forms cost tens of ns a pixel. Once per run, on its
 * first frame: the first frame speaks for the sequence. */
static void probe_cost(ef_frame *F, const ef_channel_plan *pl)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    const ef_fog_scene *sc = F->job.pass[0].scene;
    if (J->cost_checked || o->explain || (o->quiet && !o->stats))
        return;
    J->cost_checked = 1;
    int costly = ef_scene_lit(sc), exact = 0;
    ef_ray probe = { { 0, 0, 1 }, 1, 1, { F->cams[0].pos[0], F->cams[0].pos[1], F->cams[0].pos[2] } };
    for (int i = 0; i < sc->ncomp; ++i) {
        costly |= sc->comp[i].model->tau_info != NULL;
        exact |= sc->comp[i].model->work && sc->comp[i].model->work(&sc->comp[i], &probe) > 0;
    }
    if (!costly)
        return;
    float *d;
    int w, ys[16];
    const int n = ef_exr_sample_rows(F->df, pl->depth.part, pl->depth.index, 16, &d, &w, ys);
    exr_attr_box2i_t dw, cw;
    if (n < 1 || exr_get_data_window(F->df->ctx, pl->depth.part, &dw) ||
        exr_get_data_window(F->in.ctx, pl->rgb[0].part, &cw)) {
        if (n >= 1)
            free(d);
        return;
    }
    const int cols = w < 64 ? w : 64;
    const double t0 = thread_cpu_ns(), w0 = mono_ns();
    int done = 0;
    for (int k = 0; k < 64; ++k) {
        const int c = probe_column(k);
        if (c >= cols)
            continue;
        const int x = (int) ((long) c * w / cols);
        for (int i = 0; i < n; ++i) {
            if (mono_ns() - w0 > 0.5e9)
                goto timed;   /* (checked between pixels) */
            float r = 0, g = 0, b = 0, *rgb[3] = { &r, &g, &b };
            ef_fog_block(&F->job.pass[0], dw.min.x + x, ys[i], 1, 1, rgb, NULL,
                         &d[(size_t) i * (size_t) w + (size_t) x]);
            ++done;
        }
    }
timed:;
    const double per_px = done > 0 ? (thread_cpu_ns() - t0) * 1e-9 / done : 0;
    free(d);
    const double px = ((double) cw.max.x - cw.min.x + 1) * ((double) cw.max.y - cw.min.y + 1);
    const int threads = o->threads > 0 ? o->threads : ef_cpu_count();
    F->pred_fog_s = per_px * px * F->nplans;
    F->pred_n = done;
    const double secs = F->pred_fog_s / threads;
    if (!(secs > 120) || o->quiet || ef_job_cancelled(J))
        return;
    warn_predicted(J, o->input, "frame", secs, per_px * 1e3, done, threads,
                   exact ? "; method=exact has no bound on a pixel's work, the default method "
                           "bounds it (drop method=exact)"
                   : ef_scene_lit(sc) ? "; lit fog integrates every light along every ray: "
                                        "fewer lights, a coarser noise scale or fewer octaves "
                                        "cost less"
                                      : "; a coarser noise scale or fewer octaves cost less");
}

/* View v's camera, resolved and explained (or warned about), its depth
 * conversion, and its pass. */
static int resolve_view(ef_frame *F, int v)
{
    ef_job *J = F->J;
    ef_options *o = F->o;
    const ef_channel_plan *const pl = &F->plans[v];
    ef_camera *const cam = &F->cams[v];
    ef_cam_flags flags = o->cam;
    ef_cam_meta meta;
    int status;
    if ((status = ef_camera_flags(J, &flags, F->camfile_src, sizeof F->camfile_src, &F->err)) != 0)
        return ef_job_report(J, o->camera_file, &F->err, status);
    if ((status = view_meta(F, pl, &meta)) != 0)
        return status;
    if (ef_camera_resolve(&meta, &flags, cam, &F->err))
        return camera_failed(F, pl, cam);
    if (F->camfile_src[0])
        cam->src_pose = F->camfile_src;
    if (cam->warning[0] && !o->quiet && !o->explain)
        ef_job_warn(J, o->input, cam->warning);
    static const double z_up[3] = { 0, 0, 1 };
    if (v == 0 && o->up_auto && ef_z_up_camera(&flags, cam)) {
        if (ef_scene_rebuild(&o->scene, z_up, o->scene.ctx.time, &F->err))
            return ef_job_report(J, o->input, &F->err, 1);
        if (!J->noted_up && !o->quiet && !o->explain) {
            J->noted_up = 1;
            ef_job_note(J, "exrfog: %s: note: --up-axis auto: z, since the camera is %s\n",
                        o->input, strstr(cam->src_pose, "cameraTransform")
                                      ? "V-Ray's (cameraTransform)"
                                      : "in Blender's convention");
        }
    }
    if (v == 0 && !o->quiet && !o->explain)
        ef_warn_traps(J, &F->in, pl->rgb[0].part, &flags, cam);
    const int conv_ok = ef_depth_conv_init(&F->convs[v], o->depth_mode, cam, &F->err) == 0;
    F->convs_ok[v] = conv_ok;
    if (o->explain && o->json)
        return 0;
    if (o->explain) {
        if (pl->view[0])
            fprintf(J->out, "%sview: %s%s\n", v ? "\n" : "", pl->view,
                    pl->default_view ? " (default view)" : "");
        ef_explain(J, J->out, &F->in, pl, cam, &F->convs[v], conv_ok);
        if (!conv_ok)
            fprintf(J->out, "depth conversion: %s\n", F->err.msg);
        if (F->deep) {
            double px, ns, mx;
            ef_err derr = { 0 };
            const int mode = o->deep_mode;
            exr_storage_t st = EXR_STORAGE_DEEP_SCANLINE;
            exr_get_storage(F->in.ctx, pl->rgb[0].part, &st);
            const char *kind = st == EXR_STORAGE_DEEP_TILED ? "tiled" : "scanline";
            if (ef_deep_census(&F->in, pl->rgb[0].part, &px, &ns, &mx, &derr))
                fprintf(J->out, "deep: part %d is deep %s, but %s\n", pl->rgb[0].part, kind,
                        derr.msg);
            else
                fprintf(J->out,
                        "deep: part %d is deep %s: %.0f samples over %.0f pixels (mean "
                        "%.2f, at most %.0f per pixel); --deep %s, --deep-tol %g\n",
                        pl->rgb[0].part, kind, ns, px, px > 0 ? ns / px : 0, mx,
                        mode == EF_DEEP_MODE_FOG       ? "fog (a fog-only deep element)"
                        : mode == EF_DEEP_MODE_FLATTEN ? "flatten (a flat image)"
                                                       : "samples (the input's samples and the "
                                                         "fog as volume samples)",
                        o->deep_tol);
        }
        return 0;
    }
    if (!conv_ok)
        return ef_job_report(J, o->input, &F->err, 1);
    if ((status = bind_view(F, v)) == 0 && v == 0 && !F->deep)
        probe_cost(F, pl);
    return status;
}

static int resolve_views(ef_frame *F)
{
    for (int v = 0; v < F->nplans; ++v) {
        const int status = resolve_view(F, v);
        if (status)
            return status;
    }
    if (F->o->explain) {
        if (F->o->json)
            ef_explain_json(F->J, F->J->out, &F->in, F->plans, F->cams, F->convs_ok, F->nplans);
        return FRAME_DONE;
    }
    return 0;
}

/* --preview: every step-th pixel through the display transform. */
static int setup_preview(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    fog_job *j = &F->job;
    const int w = F->dw.max.x - F->dw.min.x + 1, h = F->dw.max.y - F->dw.min.y + 1;
    j->pv_step = (w > h ? w : h) / 2048 + 1;
    j->pv_w = (w + j->pv_step - 1) / j->pv_step;
    j->pv_h = (h + j->pv_step - 1) / j->pv_step;
    j->dw_x0 = F->dw.min.x;
    j->dw_y0 = F->dw.min.y;
    char used[300], msg[1200];
    const ef_ocio *cfg = ef_colour_config(&J->colour, &F->err);
    if (!cfg)
        return ef_job_report(J, o->preview, &F->err, 1);
    F->disp = ef_ocio_display_open(cfg, ef_colour_space(&J->colour), o->preview_view, used,
                                   sizeof used, msg, sizeof msg);
    if (!F->disp) {
        ef_fail(&F->err, "--preview-view: %s", msg);
        return ef_job_report(J, o->preview, &F->err, 2);
    }
    j->disp = F->disp;
    j->preview = calloc((size_t) j->pv_w * (size_t) j->pv_h, 3);
    if (!j->preview) {
        ef_fail(&F->err, "out of memory for the preview");
        return ef_job_report(J, o->preview, &F->err, 1);
    }
    return 0;
}

/* Names, once per run, each light that cannot add anything: a sun over
 * fog that fills all space (exp), whose light never gets in. As linear
 * and exp2 with lights are refused, this would otherwise be silent. */
static void warn_dark_lights(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    if (J->noted_dark || o->quiet)
        return;
    J->noted_dark = 1;
    for (int j = 0; j < o->scene.nlight; ++j)
        if (ef_light_dark(&o->scene, &o->scene.light[j])) {
            char msg[1024];
            snprintf(msg, sizeof msg, "--light '%s' adds nothing: sunlight crosses infinite "
                                      "uniform fog (exp fills all space) before it reaches any "
                                      "point, so none arrives; bound the fog (height, a box, a "
                                      "half-space) or light it with a point or spot lamp",
                     o->scene.light[j].spec);
            ef_job_warn(J, o->input, msg);
        }
}

/* The pass's settings: statistics, progress, preview, history, threads. */
static int prepare_pass(ef_frame *F)
{
    ef_job *J = F->J;
    ef_options *o = F->o;
    int status;
    warn_dark_lights(F);
    F->job.aov = o->aov;
    memcpy(F->job.aov_origin, o->aov_origin, sizeof F->job.aov_origin);
    if (o->stats) {
        F->job.stats = calloc((size_t) o->scene.ncomp + 1, sizeof *F->job.stats);
        if (!F->job.stats) {
            ef_fail(&F->err, "out of memory for the statistics");
            return ef_job_report(J, o->output, &F->err, 1);
        }
    }
    exr_get_data_window(F->in.ctx, F->plans[0].rgb[0].part, &F->dw);
    if (J->active_pg) {
        pthread_mutex_lock(&J->pg.lock);
        J->pg.frame_px = (double) (F->dw.max.x - F->dw.min.x + 1) *
                         (double) (F->dw.max.y - F->dw.min.y + 1);
        J->pg.px = 0;
        pthread_mutex_unlock(&J->pg.lock);
    }
    if (o->preview && (status = setup_preview(F)) != 0)
        return status;
    for (int p = 0; p < F->in.nparts && !o->quiet; ++p)
        if (ef_exr_part_is_multilevel(&F->in, p))
            ef_job_note(J, "exrfog: %s: note: part %d is mip-mapped; level 0 is fogged and the "
                           "output part is single-level\n", o->input, p);
    F->history = ef_history_line(J->argc, J->typed, o->scene_file, o->scene_text);
    if (!F->history) {
        ef_fail(&F->err, "out of memory for the history attribute");
        return ef_job_report(J, o->output, &F->err, 1);
    }
    /* More threads than CPUs cannot help a CPU-bound pass; they only cost memory. */
    const int cpus = ef_cpu_count();
    if (o->threads > cpus && o->verbose)
        ef_job_note(J, "exrfog: note: --threads %d capped at the %d CPUs\n", o->threads, cpus);
    F->so = (ef_stream_opts){ .threads = o->threads && o->threads < cpus ? o->threads : cpus,
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
                              .history = F->history,
                              .extra = F->aov_names,
                              .nextra = F->naov,
                              .extra_data = F->aov_data,
                              .has_origin_attr = o->has_aov_origin,
                              .origin_attr = { o->aov_origin[0], o->aov_origin[1],
                                               o->aov_origin[2] } };
    if (o->verbose) {
        ef_progress_clear(J->active_pg);
        for (int v = 0; v < F->nplans; ++v)
            ef_explain(J, J->msg, &F->in, &F->plans[v], &F->cams[v], &F->convs[v], 1);
        fprintf(J->msg, "exrfog: %s -> %s with %d thread%s\n", o->input, o->output,
                F->so.threads, F->so.threads > 1 ? "s" : "");
    }
    F->so.nplans = F->nplans;
    F->so.cancel = J->stop;
    F->so.halo = o->edges;
    F->job.edges = o->edges;
    return 0;
}

/* DWA output (asked for, or kept from a DWA input): the pass writes a
 * lossless temporary EXR that the C++ library encodes at the end. */
static int choose_dwa_output(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    F->dwa_out = -1;
    F->dwa_level = o->dwa_level;
    if (F->deep)
        return 0;
    if (!F->foreign &&
        (o->compression == EXR_COMPRESSION_DWAA || o->compression == EXR_COMPRESSION_DWAB)) {
        F->dwa_out = o->compression;
    } else if (!F->foreign && o->compression < 0 && F->dwa.ndwa > 0) {
        if (F->dwa.ndwa == F->dwa.nparts && !F->dwa.mixed) {
            F->dwa_out = F->dwa.compression;
            F->dwa_level = F->dwa.level > 0 ? F->dwa.level : EF_DWA_DEFAULT_LEVEL;
        } else if (!o->quiet) {
            ef_job_warn(J, o->input, "some parts are DWA and others are not (or DWAA and DWAB "
                                     "are mixed); the DWA parts are written ZIP-compressed "
                                     "(--compression dwaa or dwab writes every part so)");
        }
    }
    if (F->dwa_out < 0)
        return 0;
    F->so.compression = EXR_COMPRESSION_ZIP;
    F->so.zip_level = 1;
    const int rc = ef_output_open(&F->mid, o->output, ".exr", J->h.temps, &F->err);
    if (rc) {
        ef_job_report(J, o->output, &F->err, rc);
        return 1;
    }
    return 0;
}

static void deep_progress(void *user, long px)
{
    ef_progress_add(((ef_frame *) user)->J, px);
}

/* The deep pass's prediction (deep.c's timed probe): kept for --stats,
 * and past two minutes on the run's threads a warning before the work, as
 * probe_cost gives a flat frame. */
static void deep_predicted(void *user, double thread_s, int sampled)
{
    ef_frame *F = user;
    ef_job *J = F->J;
    const ef_options *o = F->o;
    F->pred_fog_s = thread_s;
    F->pred_n = sampled;
    const int threads = F->so.threads > 0 ? F->so.threads : 1;
    const double secs = thread_s / threads;
    if (!(secs > 120) || o->quiet || J->cost_checked || ef_job_cancelled(J))
        return;
    J->cost_checked = 1;
    warn_predicted(J, o->input, "deep frame", secs,
                   thread_s / ((double) F->dw.max.x - F->dw.min.x + 1) /
                       ((double) F->dw.max.y - F->dw.min.y + 1) * 1e3,
                   sampled, threads,
                   o->deep_tol < EF_DEEP_TOL_COSTLY ? "; a coarser --deep-tol makes fewer fog samples"
                   : ef_scene_lit(F->job.pass[0].scene) ? "; lit fog integrates every light along "
                                                          "every fog sample"
                                                        : "");
}

/* A deep part's pass (deep.c), with its own statistics line. */
static int run_deep_pass(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    char params[sizeof o->params + 160];
    snprintf(params, sizeof params, "%s%s--deep %s --deep-tol %g", o->params,
             o->params[0] ? " " : "",
             o->deep_mode == EF_DEEP_MODE_FOG       ? "fog"
             : o->deep_mode == EF_DEEP_MODE_FLATTEN ? "flatten"
                                                    : "samples",
             o->deep_tol);
    /* the history line says which mode ran, and with what tolerance, also
     * when they were the defaults */
    const size_t hn = strlen(F->history) + 200;
    char *hist = malloc(hn);
    if (!hist) {
        ef_fail(&F->err, "out of memory");
        return ef_job_report(J, o->output, &F->err, 1);
    }
    snprintf(hist, hn, "%s (deep: --deep %s --deep-tol %g%s)", F->history,
             o->deep_mode == EF_DEEP_MODE_FOG       ? "fog"
             : o->deep_mode == EF_DEEP_MODE_FLATTEN ? "flatten"
                                                    : "samples",
             o->deep_tol, o->deep_grey ? " --deep-grey-alpha" : "");
    const ef_deep_req q = { .in = &F->in,
                            .part = F->plans[0].rgb[0].part,
                            .cplan = &F->plans[0],
                            .cam = &F->cams[0],
                            .conv = &F->convs[0],
                            .scene = F->job.pass[0].scene,
                            .mode = o->deep_mode,
                            .tol = o->deep_tol,
                            .out_path = o->output,
                            /* a flattened foreign output goes through its EXR */
                            .out_fd = F->foreign ? F->mid.fd : F->out.fd,
                            .history = hist,
                            .params = params,
                            .threads = F->so.threads,
                            .zip_level = o->zip_level,
                            .pixel_type = o->pixel_type,
                            .chan_type_name = o->chan_type_name,
                            .chan_type = o->chan_type,
                            .nchan_type = o->nchan_type,
                            .aov = o->aov,
                            .aov_names = F->aov_names,
                            .naov = F->naov,
                            .aov_origin = { o->aov_origin[0], o->aov_origin[1],
                                            o->aov_origin[2] },
                            .has_aov_origin = o->has_aov_origin,
                            .grey = o->deep_grey,
                            .keep_parts = !F->foreign,
                            .cancel = J->stop,
                            .progress = J->active_pg ? deep_progress : NULL,
                            .predicted = o->explain || (o->quiet && !o->stats) ? NULL
                                                                              : deep_predicted,
                            .progress_user = F };
    const int drc = ef_deep_run(&q, &F->deep_res, &F->err);
    free(hist);
    if (drc)
        return ef_job_report(J, ef_job_cancelled(J) ? o->output : o->input, &F->err,
                             ef_job_cancelled(J) ? 3 : 1);
    if (ef_job_cancelled(J)) {
        ef_fail(&F->err, "cancelled; nothing was written");
        return ef_job_report(J, o->output, &F->err, 3);
    }
    const ef_deep_result *r = &F->deep_res;
    if (o->stats || o->verbose)
        ef_job_note(J,
                    "exrfog: deep: %.0f pixels, %.0f input samples (mean %.2f, max %.0f per "
                    "pixel); fog samples mean %.2f per pixel (tau at most %g each%s; inf: "
                    "flatten splits nothing); largest "
                    "split-error estimate %.3g (--deep-tol %g)%s; output at most %u samples "
                    "per pixel\n",
                    r->pixels, r->samples_in, r->pixels > 0 ? r->samples_in / r->pixels : 0,
                    r->max_in, r->pixels > 0 ? r->fog_samples / r->pixels : 0, r->tau_cap,
                    r->chromatic ? ", per channel: AR/AG/AB" : "", r->max_split_est, o->deep_tol,
                    r->capped > 0 ? "; some pixels reached 4096 fog samples" : "", r->max_out);
    return 0;
}

/* The pass itself: decode, fog, encode, into OUTPUT's temporary file (or
 * the intermediate EXR of a DWA or foreign output). */
static int run_pass(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    const int fd = F->foreign || F->dwa_out >= 0 ? F->mid.fd : F->out.fd;
    if (F->deep)
        return run_deep_pass(F);
    if (ef_exr_stream(&F->in, F->df, F->plans, o->output, fd, &F->so, fog_chunk, &F->job, &F->st,
                      &F->err))
        return ef_job_report(J, o->output, &F->err, ef_job_cancelled(J) ? 3 : 1);
    if (atomic_load(&F->job.edge_oom)) {
        ef_fail(&F->err, "out of memory for the edge pixels (--edges); nothing was written");
        return ef_job_report(J, o->output, &F->err, 1);
    }
    if (ef_job_cancelled(J)) {
        ef_fail(&F->err, "cancelled; nothing was written");
        return ef_job_report(J, o->output, &F->err, 3);
    }
    return 0;
}

/* The intermediate EXR into its final form: DWA through the C++ library,
 * or a foreign format (colour and alpha of the fogged part) through
 * OpenImageIO. */
static int convert_output(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    char mid[sizeof F->mid.tmp];
    fd_path(mid, sizeof mid, F->mid.fd, F->mid.tmp);
    if (F->dwa_out >= 0) {
        char msg[800];
        if (ef_dwa_transcode(mid, F->out.fd, o->output, -1, F->dwa_out,
                             F->dwa_level > 0 ? F->dwa_level : EF_DWA_DEFAULT_LEVEL,
                             F->so.threads, msg, sizeof msg)) {
            ef_fail(&F->err, "%s", msg);
            return ef_job_report(J, o->output, &F->err, 1);
        }
        ef_output_abort(&F->mid);
    }
    if (F->foreign) {
        const ef_channel_plan *pl = &F->plans[0];
        const char *names[4] = { pl->rgb[0].name, pl->rgb[1].name, pl->rgb[2].name,
                                 pl->alpha.part >= 0 ? pl->alpha.name : NULL };
        char msg[512], out[sizeof F->out.tmp];
        fd_path(out, sizeof out, F->out.fd, F->out.tmp);
        if (names[3] && !F->dv.alpha && !J->noted_alpha) {
            J->noted_alpha = 1;
            ef_job_note(J, "exrfog: %s: note: alpha is not written (%s)\n", o->output,
                        !strcmp(F->dv.ext, ".dpx") ? "DPX deliveries are RGB"
                                                   : "the format cannot hold it");
        }
        /* a deep flatten's intermediate holds the fogged part alone, its
         * channels without the part's name as their layer */
        const int part = F->deep ? 0 : pl->rgb[0].part;
        const char *pn = NULL;
        if (F->deep && exr_get_name(F->in.ctx, pl->rgb[0].part, &pn) == EXR_ERR_SUCCESS && pn) {
            const size_t pl_len = strlen(pn);
            for (int k = 0; k < 4; ++k)
                if (names[k] && !strncmp(names[k], pn, pl_len) && names[k][pl_len] == '.')
                    names[k] += pl_len + 1;
        }
        if (ef_oiio_convert_exr(mid, part, names, names[3] && F->dv.alpha ? 4 : 3,
                                out, F->out.tmp, &F->dv.d, msg, sizeof msg)) {
            ef_fail(&F->err, "%s", msg);
            return ef_job_report(J, o->output, &F->err, 1);
        }
        ef_output_abort(&F->mid);
    }
    return 0;
}

/* The results in place: the preview first, so that when it fails OUTPUT
 * (which may be the input) is left as it was and the run fails. */
static int commit(ef_frame *F)
{
    ef_job *J = F->J;
    const ef_options *o = F->o;
    if (F->job.preview) {
        char msg[512], pv[sizeof F->pv.tmp];
        fd_path(pv, sizeof pv, F->pv.fd, F->pv.tmp);
        if (ef_preview_write(pv, F->pv.tmp, F->job.pv_w, F->job.pv_h, F->job.preview, msg,
                             sizeof msg)) {
            ef_fail(&F->err, "%s; nothing was written", msg);
            return ef_job_report(J, o->preview, &F->err, 1);
        }
        if (ef_output_commit(&F->pv, &F->err))
            return ef_job_report(J, o->preview, &F->err, 1);
    }
    if (ef_output_commit(&F->out, &F->err))
        return ef_job_report(J, o->output, &F->err, 1);
    if (o->stats) {
        struct rusage ru;
        getrusage(RUSAGE_SELF, &ru);
        const ef_stream_stats *st = &F->st;
        if (F->deep) {
            ef_job_note(J, "exrfog: stats: peak memory %.1f MB\n", (double) ru.ru_maxrss / 1024.0);
        } else {
            ef_job_note(J,
                        "exrfog: stats: wall %.3f s; thread time decode %.3f s, fog %.3f s, "
                        "encode %.3f s, write %.3f s, wait %.3f s; %ld units on %d threads; peak "
                        "memory %.1f MB\n",
                        st->wall_s, st->decode_s, st->fog_s, st->encode_s, st->write_s,
                        st->wait_s, st->units, F->so.threads, (double) ru.ru_maxrss / 1024.0);
        }
        if (F->pred_n > 0)
            ef_job_note(J, "exrfog: stats: fog predicted before the pass at %.3f s of thread "
                           "time (%d sampled pixels timed)\n",
                        F->pred_fog_s, F->pred_n);
        ef_print_tau_stats(J, &o->scene, F->job.stats);
    }
    return 0;
}

static void frame_free(ef_frame *F)
{
    free(F->history);
    ef_output_abort(&F->mid);
    ef_output_abort(&F->pv);
    ef_output_abort(&F->out);
    ef_output_abort(&F->dconv);
    ef_output_abort(&F->din);
    free(F->job.preview);
    free(F->job.stats);
    pthread_mutex_destroy(&F->job.lock);
    for (int v = 1; v < EF_MAX_VIEWS; ++v)
        if (F->view_scene[v]) {
            ef_scene_free(F->view_scene[v]);
            free(F->view_scene[v]);
        }
    ef_ocio_display_close(F->disp);
    ef_deliver_free(&F->dv);
    ef_exr_close(&F->dep);
    ef_exr_close(&F->in);
    free(F);
}

int ef_run_frame(ef_job *J)
{
    ef_options *o = &J->o;
    ef_err err = { 0 };
    /* A frame's time is frame / fps unless --time or the scene file says. */
    if (J->has_frame && !o->time_set &&
        ef_scene_rebuild(&o->scene, NULL, (double) J->frame / o->fps, &err))
        return ef_job_report(J, o->input, &err, 1);
    ef_frame *F = calloc(1, sizeof *F);
    if (!F) {
        ef_fail(&err, "out of memory");
        return ef_job_report(J, o->input, &err, 1);
    }
    F->J = J;
    F->o = o;
    F->job.J = J;
    F->job.pv_step = 1;
    pthread_mutex_init(&F->job.lock, NULL);
    F->naov = ef_aov_channels(o->aov, &o->scene, F->aov_names);
    for (int i = 0; i < F->naov; ++i)
        F->aov_data[i] = (unsigned char) ef_aov_channel_data(o->aov, i);
    F->out.fd = F->pv.fd = F->mid.fd = F->dconv.fd = F->din.fd = -1;
    F->dwa_out = -1;
    int (*const stages[])(ef_frame *) = { open_destinations, open_inputs, find_views,
                                          resolve_views, prepare_pass, choose_dwa_output,
                                          run_pass, convert_output, commit };
    int status = 0;
    for (size_t i = 0; i < sizeof stages / sizeof stages[0] && !status; ++i)
        status = stages[i](F);
    frame_free(F);
    return status == FRAME_DONE ? 0 : status;
}
