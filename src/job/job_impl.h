/* Inside the job layer: the run (ef_job, one per ef_job_run call) and the
 * stages' shared helpers. Nothing here is static: every piece of state a
 * run needs hangs off its ef_job. */
#ifndef EF_JOB_IMPL_H
#define EF_JOB_IMPL_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>

#include "aov.h"
#include "args.h"
#include "camera_file.h"
#include "colour.h"
#include "exr_io.h"
#include "frames.h"
#include "job.h"

/* The progress of a run: frames done, pixels, elapsed, ETA. Workers add
 * their pixels; the host's hook hears every unit, the bar is drawn at most
 * every 0.2 s under a try-lock so no worker ever waits for the terminal. */
typedef struct ef_progress {
    int nframes, done;        /* frames in the run; finished so far */
    long frame;               /* the current frame's number */
    int has_frame;
    double t0, last;
    double frame_px;          /* pixels of the current frame */
    long px;                  /* pixels of the current frame fogged (under lock) */
    double px_total;          /* pixels of the finished frames */
    double reported;          /* the last fraction the hook heard */
    pthread_mutex_t lock;
    int drawn;                /* a line is on the terminal */
    int draw;                 /* draw the bar (stderr is a terminal) */
    FILE *msg;
    int (*hook)(void *user, double fraction);   /* the host's callback, or NULL */
    void *hook_user;
} ef_progress;

typedef struct ef_job {
    ef_job_hooks h;
    FILE *msg, *out;          /* never NULL: the hooks', or /dev/null */
    FILE *own_msg, *own_out;  /* opened here (/dev/null), closed at the end */
    char last_error[2048];
    _Atomic int own_stop;    /* the stop flag when the host gives none */
    _Atomic int *stop;        /* the host's (hooks.cancel) or own_stop: the progress
                               * hook's answer, the host's request */
    ef_options o;
    ef_colour colour;
    ef_progress pg;
    ef_progress *active_pg;   /* NULL: no bar and no hook */
    ef_camera_file *camfile;  /* read once per path (a pattern gives one per frame) */
    char camfile_path[4096];
    int argc;
    char **typed;             /* the command line as typed, for the history */
    int has_frame;            /* a frame of a sequence: */
    long frame;               /* its number */
    int noted_alpha;          /* the note on a deliverable without alpha was given */
    int cost_checked;         /* the fog's cost was probed (on the first frame) */
    /* A non-EXR output's writer, probed once per run (deliver.c) */
    int dl_ok, dl_type, dl_alpha;
    char dl_ext[32];
    int noted_up;             /* --up-axis auto's choice was told */
    int noted_dark;           /* the lights that add nothing were named */
    int noted_deep_tol;       /* a costly --deep-tol was warned about */
} ef_job;

/* Whether the run is to stop: the host's flag or the progress hook's. */
static inline int ef_job_cancelled(const ef_job *J)
{
    return atomic_load_explicit(J->stop, memory_order_relaxed) != 0;
}

/* messages.c: every line the user sees passes here. */
int ef_job_say(ef_job *J, int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
int ef_job_report(ef_job *J, const char *file, const ef_err *err, int status);
void ef_job_warn(ef_job *J, const char *file, const char *msg);
void ef_job_put_clean(ef_job *J, const char *s);
void ef_job_note(ef_job *J, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* progress.c */
void ef_progress_init(ef_progress *pg, FILE *msg);
void ef_progress_add(ef_job *J, long px);
void ef_progress_frame_done(ef_job *J);
void ef_progress_finish(ef_job *J);
void ef_progress_clear(ef_progress *pg);

/* explain.c: --explain, --explain --json, -v and --stats. */
void ef_explain(ef_job *J, FILE *out, const ef_exr_file *in, const ef_channel_plan *plan,
                const ef_camera *cam, const ef_depth_conv *conv, int conv_ok);
void ef_explain_json(ef_job *J, FILE *out, const ef_exr_file *in, const ef_channel_plan *plans,
                     const ef_camera *cams, const int *conv_ok, int nplans);
void ef_print_tau_stats(ef_job *J, const ef_fog_scene *s, const ef_tau_stats *st);

/* history.c: the line this run adds to exrfog/history (NULL: out of memory). */
char *ef_history_line(int argc, char **argv, const char *scene_file, const char *scene_text);

/* views.c: which views to fog and with which cameras. */
int ef_choose_views(ef_job *J, const ef_exr_file *in, const ef_exr_file *df, char views[][64],
                    int nv, ef_channel_plan *plans, int *nplans, ef_err *err);
int ef_camera_flags(ef_job *J, ef_cam_flags *flags, char *src, size_t srclen, ef_err *err);
int ef_z_up_camera(const ef_cam_flags *flags, const ef_camera *cam);
void ef_warn_traps(ef_job *J, const ef_exr_file *in, int part, const ef_cam_flags *flags,
                   const ef_camera *cam);
int ef_regular_file(const char *path);
int ef_is_exr_file(const char *path);

/* reads.c: the files a frame reads (INPUT too when with_input), each with
 * the role it plays in a message ("--depth file"), patterns resolved for
 * frame when has_frame; per_frame marks those a pattern names per frame
 * (INPUT, --depth, --camera-file), which come first. The list is large
 * (put it on the heap). */
#define EF_MAX_READS (8 + EF_FOG_MAX_COMPONENTS + EF_MAX_LIGHTS)
typedef struct ef_read_file {
    char role[128];
    char path[4096];
    int per_frame;
} ef_read_file;
typedef struct ef_read_list {
    int n;
    ef_read_file f[EF_MAX_READS];
} ef_read_list;
void ef_job_reads(const ef_job *J, int has_frame, long frame, int with_input, ef_read_list *r);

/* "the " before a role in a message, or "" (INPUT). */
const char *ef_read_article(const ef_read_file *f);

/* The file of r that writing out would replace (the same name, or the
 * same file through a symbolic or hard link), or NULL. */
const ef_read_file *ef_output_clash(const ef_read_list *r, const char *out);

/* frame.c: fogs one image (o->input to o->output); returns the status. */
int ef_run_frame(ef_job *J);

int ef_cpu_count(void);

#endif
