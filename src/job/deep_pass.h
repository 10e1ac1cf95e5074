/* The pass of a deep input (--deep samples | fog | flatten), inside the
 * job layer. */
#ifndef EF_DEEP_PASS_H
#define EF_DEEP_PASS_H

#include <stdatomic.h>

#include "args.h"
#include "exr_io.h"
#include "scene.h"

typedef struct ef_deep_req {
    const ef_exr_file *in;
    int part;                 /* the deep part holding the colour */
    const ef_channel_plan *cplan;
    const ef_camera *cam;
    const ef_depth_conv *conv;
    const ef_fog_scene *scene;  /* bound to the camera */
    int mode;                 /* EF_DEEP_MODE_* */
    double tol;               /* --deep-tol */
    const char *out_path;
    int out_fd;
    const char *history, *params;
    int threads, zip_level;
    /* -d: half/float for the output's half and float channels (-1: keep;
     * half never demotes depth), and NAME=TYPE overrides */
    int pixel_type;
    const char *const *chan_type_name;
    const int *chan_type;
    int nchan_type;
    /* --deep flatten: the AOVs (ef_aov_channels order of aov), under
     * these channel names (Blender's where the input is a multilayer) */
    unsigned aov;
    const char *const *aov_names;
    int naov;
    double aov_origin[3];
    int has_aov_origin;       /* record it (exrfog/aovOrigin), as the flat path does */
    int keep_parts;           /* EXR output: the input's other parts go beside the fogged one */
    int grey;                 /* --deep-grey-alpha */
    const _Atomic int *cancel;
    void (*progress)(void *user, long pixels);
    /* Optional: told before the pass the fog's thread time predicted for
     * the part (a timed sample of its pixels, see probe_deep) */
    void (*predicted)(void *user, double thread_s, int sampled);
    void *progress_user;      /* progress's and predicted's */
} ef_deep_req;

typedef struct ef_deep_result {
    double pixels, samples_in, max_in, fog_samples, capped, max_split_est;
    double tau_cap;
    unsigned max_out;
    int chromatic;
} ef_deep_result;

/* Fogs the deep part q->part of q->in into q->out_fd. Returns 0, or -1
 * with a message (the output is then unfinished: the caller removes it). */
int ef_deep_run(const ef_deep_req *q, ef_deep_result *res, ef_err *err);

/* For --explain: the pixels, samples and most samples of one pixel of
 * deep part `part` (every chunk read and checked). Returns 0 or -1. */
int ef_deep_census(const ef_exr_file *f, int part, double *pixels, double *samples,
                   double *max_px, ef_err *err);

#endif
