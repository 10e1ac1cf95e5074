/* The run: one ef_job per ef_job_run call, on the heap, holding every piece
 * of state the run needs; a single image is one frame, a pattern a
 * sequence of frames, each an ef_frame of its own (frame.c). */
#include <errno.h>
#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "job_impl.h"
#include "output.h"

int ef_cpu_count(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : n > 256 ? 256 : (int) n;
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

/* A frame and where it stood in --frames, for finding repeats. */
typedef struct frame_at {
    long frame;
    int at;
} frame_at;

static int cmp_frame_at(const void *a, const void *b)
{
    const frame_at *x = a, *y = b;
    return x->frame != y->frame ? (x->frame < y->frame ? -1 : 1) : (x->at > y->at) - (x->at < y->at);
}

/* Drops the frames --frames lists again (1,1 or 1-10,5-15), keeping the
 * first of each, with a note: fogging an in-place frame twice would fog
 * it twice. Returns 0, or -1 when out of memory. */
static int drop_repeats(ef_job *J, const char *pattern, long *frames, int *n)
{
    frame_at *s = malloc((size_t) *n * sizeof *s + 1);
    unsigned char *again = calloc((size_t) *n + 1, 1);
    if (!s || !again) {
        free(s);
        free(again);
        return -1;
    }
    for (int i = 0; i < *n; ++i)
        s[i] = (frame_at){ frames[i], i };
    qsort(s, (size_t) *n, sizeof *s, cmp_frame_at);
    char list[400] = "";
    int repeats = 0;
    for (int i = 1; i < *n; ++i)
        if (s[i].frame == s[i - 1].frame) {
            again[s[i].at] = 1;
            ++repeats;
            if (i < 2 || s[i - 2].frame != s[i].frame)   /* named once however often */
                list_frame(list, sizeof list, s[i].frame);
        }
    int k = 0;
    for (int i = 0; i < *n; ++i)
        if (!again[i])
            frames[k++] = frames[i];
    free(s);
    free(again);
    if (repeats)
        ef_job_note(J, "exrfog: %s: note: --frames lists frame%s %s more than once; each frame is "
                       "fogged once\n", pattern, strchr(list, ',') ? "s" : "", list);
    *n = k;
    return 0;
}

/* Refuses a sequence whose output (or preview) pattern names another
 * frame's input, or any frame's --depth or --camera-file (s.%d.exr -o
 * s.%d0.exr: frame 1's output is frame 10's input, which would be
 * overwritten before it is read); the same name, or the same file through
 * a link. The files every frame shares are checked per frame (frame.c).
 * Every name is known up front. Returns 0, or 2 with the message printed. */
static int check_overwrites(ef_job *J, const char *pattern, const long *frames, int n,
                            const char *const outs[2], const ef_frame_pattern pouts[2])
{
    enum { PER_FRAME = 3 };   /* at most: INPUT, --depth, --camera-file */
    struct id {
        dev_t dev;
        ino_t ino;
        int set;
    } *in = calloc((size_t) n * PER_FRAME + 1, sizeof *in);
    ef_read_list *r = malloc(sizeof *r);
    if (!in || !r) {
        free(in);
        free(r);
        return ef_job_say(J, 1, "out of memory");
    }
    for (int j = 0; j < n; ++j) {
        ef_job_reads(J, 1, frames[j], 1, r);
        for (int k = 0; k < r->n && k < PER_FRAME && r->f[k].per_frame; ++k) {
            struct stat st;
            if (stat(r->f[k].path, &st) == 0)
                in[j * PER_FRAME + k] = (struct id) { st.st_dev, st.st_ino, 1 };
        }
    }
    int status = 0;
    char b[4096];
    for (int w = 0; w < 2 && !status; ++w) {
        if (!outs[w])
            continue;
        for (int i = 0; i < n && !status; ++i) {
            struct stat st;
            if (ef_frame_path(outs[w], &pouts[w], frames[i], b, sizeof b) || stat(b, &st) != 0)
                continue;
            for (int x = 0; x < n * PER_FRAME && !status; ++x) {
                const int j = x / PER_FRAME, k = x % PER_FRAME;
                /* -o over the frame's own INPUT replaces it in place, as asked */
                if ((w == 0 && j == i && k == 0) || !in[x].set || in[x].ino != st.st_ino ||
                    in[x].dev != st.st_dev)
                    continue;
                ef_job_reads(J, 1, frames[j], 1, r);
                const ef_read_file *f = &r->f[k];
                status = ef_job_say(J, 2, "%s: %s %s names frame %ld's %s (%s) as frame %ld's "
                                          "%s: it would be overwritten%s; nothing was written "
                                          "(choose a pattern that names no file the run reads)",
                                    pattern, w ? "--preview" : "-o", outs[w], frames[j],
                                    k == 0 ? "input" : f->role, f->path, frames[i],
                                    w ? "preview" : "output", j > i ? " before it is read" : "");
            }
        }
    }
    free(in);
    free(r);
    return status;
}

/* --failed-list names a file of its own (issue 47): a regular file or
 * none (a FIFO would block the write for ever, a device or directory
 * lose it), and no file the run reads (any frame's INPUT, depth, camera
 * file, the scene, profiles, maps, the environment, the config) or
 * writes (any frame's output or preview): the list is rewritten at the
 * end, which would leave such a file empty. Returns 0, or 2 with the
 * message printed, before any work. */
static int check_failed_list(ef_job *J, const long *frames, int n, const char *const outs[2],
                             const ef_frame_pattern pouts[2])
{
    const char *fl = J->o.failed_list;
    if (!fl)
        return 0;
    struct stat st;
    if (stat(fl, &st) == 0 && !S_ISREG(st.st_mode))
        return ef_job_say(J, 2, "--failed-list %s: is not a regular file (a FIFO would block the "
                                "list's write, a device or directory lose it); give a file name",
                          fl);
    ef_read_list *r = malloc(sizeof *r);
    if (!r)
        return ef_job_say(J, 1, "out of memory");
    int status = 0;
    char b[4096];
    for (int i = 0; i < n && !status; ++i) {
        ef_job_reads(J, 1, frames[i], 1, r);
        const ef_read_file *f = ef_output_clash(r, fl);
        if (f) {
            status = ef_job_say(J, 2, "--failed-list %s names %s%s (%s, frame %ld): the list is "
                                      "written at the end of the run and would replace it; give "
                                      "the list its own name",
                                fl, ef_read_article(f), f->role, f->path, frames[i]);
            break;
        }
        for (int w = 0; w < 2 && !status; ++w)
            if (outs[w] && !ef_frame_path(outs[w], &pouts[w], frames[i], b, sizeof b) &&
                (!strcmp(fl, b) || ef_output_same_file(fl, b)))
                status = ef_job_say(J, 2, "--failed-list %s names frame %ld's %s (%s): give the "
                                          "list its own name",
                                    fl, frames[i], w == 0 ? "output" : "preview", b);
    }
    free(r);
    return status;
}

/* Writes --failed-list: every frame of frames[0..n) not marked written,
 * one per line (an empty file when all were). Returns status, or 1 with
 * the message printed when the list cannot be written. */
static int write_failed_list(ef_job *J, int status, const long *frames, int n,
                             const unsigned char *written)
{
    const char *path = J->o.failed_list;
    if (!path)
        return status;
    FILE *f = fopen(path, "w");
    int bad = !f;
    for (int i = 0; f && i < n; ++i)
        if (!(written && written[i]))
            bad |= fprintf(f, "%ld\n", frames[i]) < 0;
    if (f)
        bad |= fclose(f) != 0;
    if (bad) {
        const int e = errno;
        return ef_job_say(J, status ? status : 1, "--failed-list %s: cannot write it (%s)", path,
                          strerror(e ? e : EIO));
    }
    return status;
}

/* When a padded pattern (####, %08d...) finds nothing, whether the same
 * frames exist with four digits, the padding Nuke, Houdini and Blender
 * users mean by ####: writes a hint naming such a file (and the file
 * looked for, for frame, or the pattern's digits when frame is absent) to
 * hint. Returns 1 with the hint, 0 when there is none. */
static int padding_hint(const char *pattern, const ef_frame_pattern *pin, const long *frame,
                        char *hint, size_t len)
{
    if (!pin->has || pin->width == 4)
        return 0;
    ef_frame_pattern four = *pin;
    four.width = 4;
    long *fr = NULL;
    int n = 0;
    ef_err e = { 0 };
    char seen[4096], want[4096];
    int found = 0;
    if (frame) {
        struct stat st;
        found = !ef_frame_path(pattern, &four, *frame, seen, sizeof seen) && stat(seen, &st) == 0;
    } else if (!ef_frames_on_disk(pattern, &four, &fr, &n, &e) && n > 0) {
        found = !ef_frame_path(pattern, &four, fr[0], seen, sizeof seen);
    }
    free(fr);
    if (!found)
        return 0;
    if (frame)
        ef_frame_path(pattern, pin, *frame, want, sizeof want);
    else
        snprintf(want, sizeof want, "names with %d digits", pin->width);
    snprintf(hint, len, "; it looked for %s, but %s exists: %s (write %.*s#%s or %.*s%%04d%s)",
             want, seen,
             pattern[pin->at] == '#' ? "under oiiotool's rule each # is four digits, so #### "
                                       "is sixteen"
                                     : "the pattern's width is not four",
             (int) pin->at, pattern, pattern + pin->at + pin->len, (int) pin->at, pattern,
             pattern + pin->at + pin->len);
    return 1;
}

/* Runs every frame of a sequence in order: the frames of --frames, or
 * every frame on disk matching INPUT. Missing frames are found before any
 * work; a failed frame stops the run unless --keep-going, which fogs the
 * others and names every failure at the end. */
static int run_sequence(ef_job *J, const ef_frame_pattern *pin)
{
    ef_options *o = &J->o;
    const char *pattern = o->input, *out_pat = o->output, *dep_pat = o->depth_file,
               *pv_pat = o->preview;
    ef_frame_pattern pout = { 0 }, pdep = { 0 }, ppv = { 0 };
    ef_err err = { 0 };
    if (out_pat && !ef_frame_pattern_find(out_pat, &pout)) {
        return ef_job_say(J, 2, "INPUT is a sequence (%s) but -o %s has no frame pattern; every frame "
                            "would overwrite it (write e.g. -o fog.#.exr)", pattern, out_pat);
    }
    if (pv_pat && !ef_frame_pattern_find(pv_pat, &ppv)) {
        return ef_job_say(J, 2, "INPUT is a sequence (%s) but --preview %s has no frame pattern "
                            "(write e.g. --preview fog.#.png)", pattern, pv_pat);
    }
    if (dep_pat)
        ef_frame_pattern_find(dep_pat, &pdep);   /* one depth for every frame is allowed */
    const struct {
        const char *path;
        const ef_frame_pattern *p;
    } pats[] = { { pattern, pin }, { out_pat, &pout }, { dep_pat, &pdep }, { pv_pat, &ppv } };
    for (size_t k = 0; k < sizeof pats / sizeof pats[0]; ++k)
        if (pats[k].path && pats[k].p->has && pats[k].p->width > 100)
            return ef_job_say(J, 2, "%s: the frame pattern asks for %d digits; at most 100 "
                                    "(write e.g. %%04d)", pats[k].path, pats[k].p->width);
    long *frames = NULL;
    int n = 0;
    if (o->frames ? ef_frames_parse(o->frames, &frames, &n, &err)
                  : ef_frames_on_disk(pattern, pin, &frames, &n, &err)) {
        if (o->frames) {
            return ef_job_say(J, 2, "%s", err.msg);
        }
        return ef_job_report(J, pattern, &err, 1);
    }
    char hint[20000];
    if (n == 0 && padding_hint(pattern, pin, NULL, hint, sizeof hint)) {
        ef_fail(&err, "no file on disk matches this frame pattern%s", hint);
        return ef_job_report(J, pattern, &err, 1);
    }
    if (n == 0) {
        if (pin->len > 1 && pattern[pin->at] == '#')
            ef_fail(&err, "no file on disk matches this frame pattern; as in oiiotool, each # "
                          "is four digits, so %d #s are %d digits (write shot.#.exr or "
                          "shot.%%04d.exr for shot.0001.exr)", (int) pin->len, pin->width);
        else
            ef_fail(&err, "no file on disk matches this frame pattern (check the name and the "
                          "padding: # is 4 digits, @ one digit, %%04d four)");
        return ef_job_report(J, pattern, &err, 1);
    }
    if (o->frames && drop_repeats(J, pattern, frames, &n)) {
        free(frames);
        return ef_job_say(J, 1, "out of memory");
    }
    int ow;
    const char *const outs[2] = { out_pat, pv_pat };
    const ef_frame_pattern pouts[2] = { pout, ppv };
    if (!o->explain && (ow = check_failed_list(J, frames, n, outs, pouts)) != 0) {
        free(frames);
        return ow;
    }
    if (!o->explain && (ow = check_overwrites(J, pattern, frames, n, outs, pouts)) != 0) {
        ow = write_failed_list(J, ow, frames, n, NULL);
        free(frames);
        return ow;
    }
    char *paths = malloc(4 * 4096);
    if (!paths) {
        free(frames);
        return ef_job_say(J, 1, "out of memory");
    }
    char *in_path = paths, *out_path = paths + 4096, *dep_path = paths + 2 * 4096,
         *pv_path = paths + 3 * 4096;
    char missing[400] = "";
    int nmissing = 0;
    unsigned char *skip = calloc(2 * (size_t) n, 1), *written = skip + n;
    if (!skip) {
        free(paths);
        free(frames);
        return ef_job_say(J, 1, "out of memory");
    }
    for (int i = 0; i < n; ++i) {
        struct stat st;
        const int bad = ef_frame_path(pattern, pin, frames[i], in_path, 4096) ||
                        stat(in_path, &st) ||
                        (dep_pat && (ef_frame_path(dep_pat, &pdep, frames[i], dep_path,
                                                   4096) || stat(dep_path, &st)));
        if (bad) {
            skip[i] = 1;
            ++nmissing;
            list_frame(missing, sizeof missing, frames[i]);
        }
    }
    int status = 0;
    long first_missing = 0;
    for (int i = 0; i < n; ++i)
        if (skip[i]) {
            first_missing = frames[i];
            break;
        }
    if (nmissing && !o->keep_going) {
        if (nmissing == n && padding_hint(pattern, pin, &first_missing, hint, sizeof hint))
            ef_job_say(J, 1, "%s: %d of %d frame%s missing on disk%s; nothing was written", pattern,
                       nmissing, n, n > 1 ? "s" : "", hint);
        else
            ef_job_say(J, 1, "%s: %d of %d frame%s missing on disk%s: %s; nothing was written "
                             "(render them, choose others with --frames, or pass --keep-going)",
                       pattern, nmissing, n, n > 1 ? "s" : "",
                       dep_pat && pdep.has ? " (colour or depth)" : "", missing);
        const int rc = write_failed_list(J, 1, frames, n, NULL);
        free(paths);
        free(skip);
        free(frames);
        return rc;
    }
    if (nmissing && !o->explain)
        ef_job_note(J, "exrfog: %s: %d of %d frame%s missing on disk%s: %s; fogging the others "
                       "(--keep-going)\n", pattern, nmissing, n, n > 1 ? "s" : "",
                    dep_pat && pdep.has ? " (colour or depth)" : "", missing);
    if (o->explain && !o->json)
        fprintf(J->out, "sequence: %s, %d frame%s (%ld to %ld), time = frame / %g fps%s\n", pattern, n,
               n > 1 ? "s" : "", frames[0], frames[n - 1], o->fps,
               o->time_set ? " (overridden by --time or the scene file)" : "");
    char failed[400] = "";
    int nfailed = 0;
    J->pg.nframes = n - nmissing;
    for (int i = 0; i < n; ++i) {
        if (skip[i]) {
            ++nfailed;
            list_frame(failed, sizeof failed, frames[i]);
            continue;
        }
        if (ef_frame_path(pattern, pin, frames[i], in_path, 4096) ||
            (out_pat && ef_frame_path(out_pat, &pout, frames[i], out_path, 4096)) ||
            (dep_pat && ef_frame_path(dep_pat, &pdep, frames[i], dep_path, 4096)) ||
            (pv_pat && ef_frame_path(pv_pat, &ppv, frames[i], pv_path, 4096))) {
            status = ef_job_say(J, 1, "%s: the path of frame %ld is too long", pattern, frames[i]);
            break;
        }
        o->input = in_path;
        o->output = out_pat ? out_path : NULL;
        o->depth_file = dep_pat ? dep_path : NULL;
        o->preview = pv_pat ? pv_path : NULL;
        J->has_frame = 1;
        J->frame = frames[i];
        pthread_mutex_lock(&J->pg.lock);
        J->pg.has_frame = 1;
        J->pg.frame = frames[i];
        pthread_mutex_unlock(&J->pg.lock);
        const int rc = ef_run_frame(J);
        ef_progress_frame_done(J);
        if (o->explain)
            break;   /* the first frame tells what every frame is read as */
        if (rc == 0) {
            written[i] = 1;
            continue;
        }
        /* A usage error is the same for every frame; a cancel stops all. */
        if (rc == 2 || rc == 3 || !o->keep_going) {
            status = rc;
            if (rc == 1 && i + 1 < n)
                ef_job_note(J, "exrfog: %s: stopped at frame %ld; frames before it are written, "
                                "none after (--keep-going fogs the others)\n", pattern, frames[i]);
            break;
        }
        ++nfailed;
        list_frame(failed, sizeof failed, frames[i]);
    }
    if (status == 0 && nfailed) {
        status = ef_job_say(J, 1, "%s: %d of %d frames failed: %s%s", pattern, nfailed, n, failed,
                            strstr(failed, "...") ? (o->failed_list ? " (every one in --failed-list)"
                                                                    : " (--failed-list FILE "
                                                                      "writes every one)")
                                                  : "");
    }
    if (!o->explain)
        status = write_failed_list(J, status, frames, n, written);
    o->input = pattern;
    o->output = out_pat;
    o->depth_file = dep_pat;
    o->preview = pv_pat;
    free(paths);
    free(skip);
    free(frames);
    return status;
}


/* The run once its options are read: one image, or a sequence. */
static int run_parsed(ef_job *J)
{
    ef_options *o = &J->o;
    ef_progress_init(&J->pg, J->msg);
    J->pg.hook = J->h.progress;
    J->pg.hook_user = J->h.progress_user;
    J->pg.draw = J->h.bar && !o->quiet && !o->explain && J->msg == stderr &&
                 isatty(STDERR_FILENO);
    if (J->pg.draw || (J->h.progress && !o->explain))
        J->active_pg = &J->pg;
    int status = 0;
    ef_frame_pattern pin;
    if (!ef_frame_pattern_find(o->input, &pin)) {
        if (o->frames || o->failed_list) {
            status = ef_job_say(J, 2, "%s needs a frame pattern in INPUT (shot.#.exr, "
                                      "shot.%%04d.exr or shot.@@@@.exr)",
                                o->frames ? "--frames" : "--failed-list");
        } else {
            ef_frame_pattern pp;
            const char *pat = o->output && ef_frame_pattern_find(o->output, &pp) ? o->output
                              : o->preview && ef_frame_pattern_find(o->preview, &pp) ? o->preview
                                                                                   : NULL;
            if (pat) {
                status = ef_job_say(J, 2, "%s has a frame pattern but INPUT %s is one file, so "
                                          "nothing would fill it in (give INPUT the pattern, e.g. "
                                          "shot.#.exr, or name one file)", pat, o->input);
            } else {
                J->pg.nframes = 1;
                status = ef_run_frame(J);
            }
        }
    } else {
        status = run_sequence(J, &pin);
    }
    if (status == 0)
        ef_progress_finish(J);
    ef_progress_clear(J->active_pg);
    J->active_pg = NULL;
    pthread_mutex_destroy(&J->pg.lock);
    return status;
}

/* The job's message and output streams: the host's, or /dev/null. */
static int open_streams(ef_job *J)
{
    J->msg = J->h.msg;
    J->out = J->h.out;
    if (!J->msg && !(J->msg = J->own_msg = fopen("/dev/null", "w")))
        return -1;
    if (!J->out && !(J->out = J->own_out = fopen("/dev/null", "w")))
        return -1;
    return 0;
}

static int job_run(ef_job *J, int argc, const char *const *argv)
{
    ef_err err = { 0 };
    /* The parser permutes its argv as getopt does: it works on a copy, and
     * the history keeps the command line as typed. */
    char **args = malloc(((size_t) argc + 1) * sizeof *args);
    J->typed = malloc(((size_t) argc + 1) * sizeof *J->typed);
    if (!args || !J->typed) {
        free(args);
        return ef_job_say(J, 1, "out of memory");
    }
    for (int i = 0; i < argc; ++i)
        args[i] = J->typed[i] = (char *) argv[i];
    args[argc] = J->typed[argc] = NULL;
    J->argc = argc;
    const ef_parse_result pr = ef_options_parse(argc, args, &J->o, &J->colour, J->out, &err);
    int status;
    if (pr == EF_PARSE_EXIT)
        status = 0;
    else if (pr == EF_PARSE_FAIL)
        status = ef_job_report(J, err.file, &err, 1);
    else if (pr != EF_PARSE_RUN)
        status = ef_job_say(J, 2, "%s", err.msg);
    else
        status = run_parsed(J);
    free(args);
    return status;
}

int ef_job_run(const ef_job_hooks *hooks, int argc, const char *const *argv, char *err,
               size_t errlen)
{
    static const ef_job_hooks none;
    if (errlen)
        err[0] = '\0';
    ef_job *J = calloc(1, sizeof *J);
    if (!J) {
        snprintf(err, errlen, "out of memory");
        return 1;
    }
    J->h = hooks ? *hooks : none;
    J->stop = J->h.cancel ? J->h.cancel : &J->own_stop;
    int status;
    if (open_streams(J)) {
        snprintf(J->last_error, sizeof J->last_error, "cannot open /dev/null: %s",
                 strerror(errno));
        status = 1;
    } else {
        status = job_run(J, argc, argv);
    }
    if (status && errlen)
        snprintf(err, errlen, "%s", J->last_error);
    ef_camera_file_free(J->camfile);
    ef_colour_close(&J->colour);
    ef_options_free(&J->o);
    free(J->typed);
    if (J->own_msg)
        fclose(J->own_msg);
    if (J->own_out)
        fclose(J->own_out);
    else if (J->out)
        fflush(J->out);
    free(J);
    return status;
}
