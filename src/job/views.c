/* Which views of a file to fog and where each one's camera comes from:
 * the header, a camera file (per frame) or the flags, and the traps of real
 * renders worth a warning. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "job_impl.h"

/* Whether the camera comes from a Z-up family: V-Ray's cameraTransform,
 * or a flag matrix pasted in Blender's convention. */
int ef_z_up_camera(const ef_cam_flags *flags, const ef_camera *cam)
{
    return strstr(cam->src_pose, "cameraTransform") != NULL ||
           ((flags->w2c.set || flags->c2w.set) && flags->convention == EF_CONV_BLENDER);
}

/* Silent traps of real renders, each with its fix: Nuke's depth.Z is 1/z;
 * V-Ray's and Blender's worlds are Z-up while the height models default
 * to y. */
void ef_warn_traps(ef_job *J, const ef_exr_file *in, int part, const ef_cam_flags *flags,
                   const ef_camera *cam)
{
    const ef_options *o = &J->o;
    if (!o->depth_mode_set && ef_exr_has_attr(in, part, "nuke/version"))
        ef_job_warn(J, o->input, "a Nuke render (nuke/version): Nuke's ScanlineRender writes depth.Z as "
                       "1/z, read here as planar depth; pass --depth-mode inverse if the fog looks "
                       "wrong (--depth-mode planar keeps this reading and silences the warning)");
    int height = 0;
    for (int i = 0; i < o->scene.ncomp; ++i)
        height |= o->scene.comp[i].model->uses_up && !o->scene.comp[i].has_up;
    if (height && !o->up_set && ef_z_up_camera(flags, cam)) {
        char msg[400];
        snprintf(msg, sizeof msg, "the camera is %s, whose world is Z-up, and the height fog uses "
                                  "y as up; pass --up-axis z or --up-axis auto (or --up-axis y to "
                                  "keep y and silence this)",
                 strstr(cam->src_pose, "cameraTransform") ? "V-Ray's (cameraTransform)"
                                                          : "in Blender's convention");
        ef_job_warn(J, o->input, msg);
    }
}

/* Whether path is a regular file (opening a FIFO would block: the EXR
 * reader refuses those with a message). */
int ef_regular_file(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* Whether path starts with OpenEXR's magic number; anything but a
 * readable regular file counts as one, for the EXR reader to explain. */
int ef_is_exr_file(const char *path)
{
    unsigned char m[4] = { 0 };
    if (!ef_regular_file(path))
        return 1;
    FILE *f = fopen(path, "rb");
    if (!f)
        return 1;   /* let the EXR reader say what is wrong */
    const size_t n = fread(m, 1, 4, f);
    fclose(f);
    return n == 4 && m[0] == 0x76 && m[1] == 0x2f && m[2] == 0x31 && m[3] == 0x01;
}

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
int ef_camera_flags(ef_job *J, ef_cam_flags *flags, char *src, size_t srclen, ef_err *err)
{
    const ef_options *o = &J->o;
    src[0] = '\0';
    if (!o->camera_file)
        return 0;
    char path[4096];
    ef_frame_pattern pat;
    ef_frame_pattern_find(o->camera_file, &pat);
    if (pat.has && !J->has_frame) {
        ef_fail(err, "--camera-file has a frame pattern but INPUT is a single image; give INPUT "
                     "a pattern too (shot.#.exr --frames N)");
        return 2;
    }
    if (ef_frame_path(o->camera_file, &pat, J->frame, path, sizeof path))
        return ef_fail(err, "the camera file's path is too long"), 1;
    if (!J->camfile || strcmp(path, J->camfile_path)) {
        ef_camera_file_free(J->camfile);
        J->camfile = NULL;
        if (ef_camera_file_read(path, o->cam.convention, &J->camfile, err)) {
            if (!err->file)
                ef_err_set_file(err, path);
            return 1;
        }
        snprintf(J->camfile_path, sizeof J->camfile_path, "%s", path);
    }
    long frame = J->frame;
    double first = 0, last = 0;
    int count = 0;
    ef_camera_file_frames(J->camfile, &first, &last, &count);
    if (!J->has_frame && frame_of_name(o->input, &frame)) {
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
    if (ef_camera_file_frame(J->camfile, (double) frame, &f, err)) {
        ef_err_set_file(err, path);
        return 1;
    }
    /* The command line's lens and clip planes win over the file's; a lens
     * from the file says so (src, written below, outlives the camera). */
    if (flags->fov.set) {
        f.fov = flags->fov;
        f.vfov.set = 0;
    } else if (f.fov.set || f.vfov.set) {
        f.fov_src = src;
    }
    if (!flags->w2c.set && !flags->c2w.set && (f.w2c.set || f.c2w.set))
        f.pose_src = src;
    if (flags->near_.set)
        f.near_ = flags->near_;
    else if (f.near_.set)
        f.near_src = src;
    if (flags->far_.set)
        f.far_ = flags->far_;
    else if (f.far_.set)
        f.far_src = src;
    *flags = f;
    snprintf(src, srclen, "camera file %.300s, frame %ld (%.200s)", path, frame,
             ef_camera_file_describe(J->camfile));
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
    ef_camera cam;
    ef_err e = { 0 };
    return ef_exr_read_cam_meta(in, pl->rgb[0].part, &meta, &e) == 0 &&
           ef_camera_resolve(&meta, &o->cam, &cam, &e) == 0;
}

/* Chooses what to fog: the one colour of a file without views, or its
 * views (all, or those of --view), each found with its own channels.
 * Returns 0, or the exit status with err set. */
int ef_choose_views(ef_job *J, const ef_exr_file *in, const ef_exr_file *df, char views[][64],
                    int nv, ef_channel_plan *plans, int *nplans, ef_err *err)
{
    const ef_options *o = &J->o;
    char list[400] = "";
    for (int k = 0; k < nv; ++k)
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", k ? ", " : "", views[k]);
    if (nv == 0) {
        /* a single part whose header names its one view (Weta's left-eye
         * elements): --view of that name is the whole file */
        const char *own = NULL;
        int32_t ol = 0;
        if (in->nparts == 1 && (exr_attr_get_string(in->ctx, 0, "view", &ol, &own) !=
                                    EXR_ERR_SUCCESS || !own || ol <= 0))
            own = NULL;
        for (int i = 0; own && i < o->nviews; ++i)
            if ((int) strlen(o->views[i]) != ol || strncmp(o->views[i], own, (size_t) ol))
                return ef_fail(err, "--view %s: INPUT holds the view '%.*s' alone (its view "
                                    "attribute)", o->views[i], (int) ol, own), 2;
        if (o->nviews && !own)
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
                ef_job_warn(J, o->input, msg);
            }
        }
    return 0;
}

