/* The public API (include/exrfog.h) as an embedding host uses it: jobs at
 * once on threads, each giving the bytes it gives alone; the process left
 * alone (signal handlers, umask, cwd, stdio); cancellation; progress and
 * warnings; one scene builder for the library and the command line;
 * immutable scenes; hostile arguments; and every allocation failed in
 * turn (the test is linked with --wrap=malloc,calloc,realloc). */
#define _GNU_SOURCE 1
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <cmocka.h>

#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
#include <dirent.h>
#include <execinfo.h>

#include "exrfog.h"
#include "testutil.h"

/* ------------------------------------------------ allocation failures */

/* 0: no failure; N: the N-th allocation from now fails (and only it). */
static _Atomic long fail_countdown;
static _Atomic long alloc_count;

void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t m);
void *__real_realloc(void *p, size_t n);

static int should_fail(void)
{
    atomic_fetch_add(&alloc_count, 1);
    long c = atomic_load(&fail_countdown);
    while (c > 0) {
        if (atomic_compare_exchange_weak(&fail_countdown, &c, c - 1)) {
            if (c == 1 && getenv("EF_FAULT_TRACE")) {
                /* where the failed allocation was: for a failing case */
                void *bt[16];
                backtrace_symbols_fd(bt, backtrace(bt, 16), 2);
            }
            return c == 1;
        }
    }
    return 0;
}

void *__wrap_malloc(size_t n)
{
    return should_fail() ? NULL : __real_malloc(n);
}

void *__wrap_calloc(size_t n, size_t m)
{
    return should_fail() ? NULL : __real_calloc(n, m);
}

void *__wrap_realloc(void *p, size_t n)
{
    return should_fail() ? NULL : __real_realloc(p, n);
}

/* ------------------------------------------------------------ helpers */

static char g_dir[900];

static char *path_in(const char *name)
{
    static _Thread_local char buf[4][1200];
    static _Thread_local int k;
    char *b = buf[k++ % 4];
    snprintf(b, 1200, "%s/%s", g_dir, name);
    return b;
}

/* samples/sample.exr, found once by setup before any thread starts. */
static char g_sample[1200];

static const char *sample(void)
{
    return g_sample;
}

/* The whole of a file, or NULL (len 0) when it cannot be read. */
static unsigned char *slurp(const char *path, size_t *len)
{
    *len = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    const long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = __real_malloc(n > 0 ? (size_t) n : 1);
    if (b && fread(b, 1, (size_t) n, f) != (size_t) n) {
        free(b);
        b = NULL;
    }
    fclose(f);
    if (b)
        *len = (size_t) n;
    return b;
}

static int same_bytes(const char *a, const char *b)
{
    size_t na, nb;
    unsigned char *x = slurp(a, &na), *y = slurp(b, &nb);
    const int same = x && y && na == nb && memcmp(x, y, na) == 0;
    free(x);
    free(y);
    return same;
}

/* Files in g_dir whose name holds ".exrfog-" (a temporary file). */
static int temporaries(void)
{
    DIR *d = opendir(g_dir);
    int n = 0;
    for (struct dirent *e; d && (e = readdir(d));)
        n += strstr(e->d_name, ".exrfog-") != NULL;
    if (d)
        closedir(d);
    return n;
}

static void copy_file(const char *from, const char *to)
{
    size_t n;
    unsigned char *b = slurp(from, &n);
    assert_non_null(b);
    FILE *f = fopen(to, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(b, 1, n, f), n);
    fclose(f);
    free(b);
}

/* A 32 x 16 single-part stereo file (multiView right, left): the default
 * view (right) has the header's camera at x = 1; left.* has none. */
#define SW 32
#define SH 16
static float s_c[SW * SH], s_c2[SW * SH], s_a[SW * SH], s_z[SW * SH];

static void write_stereo(const char *path)
{
    for (int i = 0; i < SW * SH; ++i) {
        s_c[i] = 0.5f;
        s_c2[i] = 0.25f;
        s_a[i] = 1.0f;
        s_z[i] = 2.0f + (float) (i % 7);
    }
    tu_part p;
    tu_part_init(&p, SW, SH);
    static const char *const names[2][5] = { { "R", "G", "B", "A", "Z" },
                                             { "left.R", "left.G", "left.B", "left.A", "left.Z" } };
    for (int v = 0; v < 2; ++v)
        for (int k = 0; k < 5; ++k)
            tu_part_add(&p, names[v][k], EXR_PIXEL_FLOAT,
                        k < 3 ? (v ? s_c2 : s_c) : k == 3 ? s_a : s_z);
    p.multiview[0] = "right";
    p.multiview[1] = "left";
    static const float id[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1 };
    p.m44[0].name = "worldToCamera";
    memcpy(p.m44[0].m, id, sizeof id);
    p.f[0].name = "CameraFov";
    p.f[0].v = 90.0f;
    assert_int_equal(tu_write_exr(path, &p, 1), 0);
}

static int setup(void **state)
{
    (void) state;
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    snprintf(g_sample, sizeof g_sample, "%s/samples/sample.exr", src ? src : ".");
    char *d = tu_path("api");
    snprintf(g_dir, sizeof g_dir, "%s", d);
    free(d);
    char cmd[2200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s' && mkdir -p '%s'", g_dir, g_dir);
    assert_int_equal(system(cmd), 0);
    for (int f = 1; f <= 3; ++f) {
        char n[64];
        snprintf(n, sizeof n, "seq.%04d.exr", f);
        copy_file(sample(), path_in(n));
    }
    write_stereo(path_in("stereo.exr"));
    FILE *prof = fopen(path_in("valley.txt"), "w");
    assert_non_null(prof);
    fputs("# height  density\n0 0.2\n5 0.05\n20 0\n", prof);
    fclose(prof);
    return 0;
}

/* ------------------------------------------------------- the jobs */

/* A job of the mix: its arguments after argv[0], with OUT for the output. */
typedef struct job_spec {
    const char *args[16];
    const char *out_name;     /* "%s" takes the job's tag */
    int frames;               /* a sequence: outputs out.0001.. */
} job_spec;

static const job_spec mix[] = {
    { { "IN:sample", "--fog", "exp:density=0.05", "--aov", "T,error", NULL }, "exp_%s.exr", 0 },
    { { "IN:sample", "--fog", "noise:density=0.3:scale=2:octaves=2:falloff=0.2:base=0", "--fog",
        "layered:file=DIR/valley.txt", NULL }, "noise_%s.exr", 0 },
    { { "IN:seq.#.exr", "--frames", "1-3", "--fog", "height:density=0.1:falloff=0.2:base=0",
        "--fog-color", "#ff8000", NULL }, "seq_%s.#.exr", 3 },
    { { "IN:stereo.exr", "--view", "right", "--aov", "P", "--fog",
        "halfspace:plane=0,1,0,-2:density=0.05", NULL }, "view_%s.exr", 0 },
};
#define NMIX ((int) (sizeof mix / sizeof mix[0]))

/* The argv of job j writing to outputs tagged tag. */
static int job_argv(int j, const char *tag, const char **argv, char store[][1200])
{
    int n = 0, s = 0;
    argv[n++] = "exrfog";
    for (int i = 0; mix[j].args[i]; ++i) {
        const char *a = mix[j].args[i];
        if (!strncmp(a, "IN:", 3)) {
            if (!strcmp(a + 3, "sample"))
                snprintf(store[s], 1200, "%s", sample());
            else
                snprintf(store[s], 1200, "%s/%s", g_dir, a + 3);
            argv[n++] = store[s++];
        } else if (strstr(a, "DIR/")) {
            const char *at = strstr(a, "DIR/");
            snprintf(store[s], 1200, "%.*s%s/%s", (int) (at - a), a, g_dir, at + 4);
            argv[n++] = store[s++];
        } else {
            argv[n++] = a;
        }
    }
    char name[200];
    snprintf(name, sizeof name, mix[j].out_name, tag);
    snprintf(store[s], 1200, "%s/%.200s", g_dir, name);
    argv[n++] = "-o";
    argv[n++] = store[s++];
    argv[n] = NULL;
    return n;
}

/* Output path k (frame k + 1 of a sequence) of job j with tag. */
static void job_output(int j, const char *tag, int k, char *out, size_t len)
{
    char name[200], frame[16];
    snprintf(name, sizeof name, mix[j].out_name, tag);
    char *hash = strchr(name, '#');
    if (hash) {
        snprintf(frame, sizeof frame, "%04d", k + 1);
        char tmp[200];
        snprintf(tmp, sizeof tmp, "%.*s%s%s", (int) (hash - name), name, frame, hash + 1);
        snprintf(name, sizeof name, "%s", tmp);
    }
    snprintf(out, len, "%s/%s", g_dir, name);
}

static exrfog_result run_job(int j, const char *tag, exrfog_context *ctx)
{
    const char *argv[24];
    char store[8][1200];
    const int n = job_argv(j, tag, argv, store);
    return exrfog_run(ctx, n, argv);
}

typedef struct worker {
    int kind;                 /* 0: run job j; 1: explain; 2: fog_pixels */
    int j;
    char tag[32];
    exrfog_result r;
    char *json;
    float px[64 * 3];
} worker;

static void fog_pixels_once(float *rgb_out, exrfog_result *r)
{
    exrfog_context *ctx = exrfog_context_create();
    const char *specs[] = { "noise:density=0.3:scale=2:octaves=2:falloff=0.2:base=0",
                            "exp:density=0.02" };
    exrfog_scene *sc = NULL;
    exrfog_camera *cam = NULL;
    *r = exrfog_scene_create(ctx, specs, 2, NULL, NULL, &sc);
    if (*r == EXRFOG_OK)
        *r = exrfog_camera_from_file(ctx, sample(), &cam);
    float R[64], G[64], B[64], Z[64];
    for (int i = 0; i < 64; ++i) {
        R[i] = 0.2f;
        G[i] = 0.3f;
        B[i] = 0.4f;
        Z[i] = i == 5 ? INFINITY : 1.0f + 0.5f * (float) i;
    }
    exrfog_image img = { .size = sizeof img, .x0 = 100, .y0 = 40, .width = 16, .height = 4,
                         .stride = 16, .rgb = { R, G, B }, .depth = Z };
    if (*r == EXRFOG_OK)
        *r = exrfog_fog_pixels(ctx, sc, cam, &img);
    for (int i = 0; i < 64; ++i) {
        rgb_out[3 * i] = R[i];
        rgb_out[3 * i + 1] = G[i];
        rgb_out[3 * i + 2] = B[i];
    }
    exrfog_camera_destroy(cam);
    exrfog_scene_destroy(sc);
    exrfog_context_destroy(ctx);
}

static char *explain_once(exrfog_result *r)
{
    exrfog_context *ctx = exrfog_context_create();
    const char *argv[] = { "exrfog", path_in("stereo.exr"), "--view", "right", "--fog",
                           "exp:density=0.1" };
    char *json = NULL;
    *r = exrfog_explain(ctx, 6, argv, &json);
    exrfog_context_destroy(ctx);
    return json;
}

static void *worker_main(void *arg)
{
    worker *w = arg;
    if (w->kind == 0) {
        exrfog_context *ctx = exrfog_context_create();
        w->r = run_job(w->j, w->tag, ctx);
        exrfog_context_destroy(ctx);
    } else if (w->kind == 1) {
        w->json = explain_once(&w->r);
    } else {
        fog_pixels_once(w->px, &w->r);
    }
    return NULL;
}

/* Two rounds of the four jobs at once on eight threads, with explains and
 * pixel calls beside them: every output is byte for byte the output of
 * the same job run alone. */
static void test_reentrant(void **state)
{
    (void) state;
    for (int j = 0; j < NMIX; ++j) {
        exrfog_context *ctx = exrfog_context_create();
        const exrfog_result r = run_job(j, "alone", ctx);
        if (r != EXRFOG_OK)
            fprintf(stderr, "job %d: %s\n", j, exrfog_error(ctx));
        assert_int_equal(r, EXRFOG_OK);
        exrfog_context_destroy(ctx);
    }
    exrfog_result r1;
    char *json_alone = explain_once(&r1);
    assert_int_equal(r1, EXRFOG_OK);
    float px_alone[64 * 3];
    fog_pixels_once(px_alone, &r1);
    assert_int_equal(r1, EXRFOG_OK);
    enum { NW = 2 * NMIX + 4 };
    worker w[NW];
    pthread_t t[NW];
    memset(w, 0, sizeof w);
    for (int i = 0; i < NW; ++i) {
        w[i].kind = i < 2 * NMIX ? 0 : i < 2 * NMIX + 2 ? 1 : 2;
        w[i].j = i % NMIX;
        snprintf(w[i].tag, sizeof w[i].tag, "t%d", i);
        assert_int_equal(pthread_create(&t[i], NULL, worker_main, &w[i]), 0);
    }
    for (int i = 0; i < NW; ++i)
        pthread_join(t[i], NULL);
    for (int i = 0; i < NW; ++i) {
        assert_int_equal(w[i].r, EXRFOG_OK);
        if (w[i].kind == 1) {
            assert_string_equal(w[i].json, json_alone);
            exrfog_free(w[i].json);
            continue;
        }
        if (w[i].kind == 2) {
            assert_memory_equal(w[i].px, px_alone, sizeof px_alone);
            continue;
        }
        const int nout = mix[w[i].j].frames ? mix[w[i].j].frames : 1;
        for (int k = 0; k < nout; ++k) {
            char a[1300], b[1300];
            job_output(w[i].j, "alone", k, a, sizeof a);
            job_output(w[i].j, w[i].tag, k, b, sizeof b);
            if (!same_bytes(a, b))
                fail_msg("job %d (thread %d) output %s differs from %s", w[i].j, i, b, a);
        }
    }
    exrfog_free(json_alone);
    assert_int_equal(temporaries(), 0);
}

/* ------------------------------------------------ the process alone */

static void host_handler(int sig)
{
    (void) sig;
}

static void host_handler2(int sig)
{
    (void) sig;
}

/* A host's SIGINT and SIGTERM handlers, umask, cwd and stdio are as they
 * were after runs that succeed, fail and warn; nothing reaches stdout or
 * stderr when the context does not print. */
static void test_process_alone(void **state)
{
    (void) state;
    struct sigaction sa, before[2], after[2];
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = host_handler;
    sigaction(SIGINT, &sa, NULL);
    sa.sa_handler = host_handler2;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, NULL, &before[0]);
    sigaction(SIGTERM, NULL, &before[1]);
    const mode_t mask = umask(027);
    char cwd[PATH_MAX], cwd2[PATH_MAX];
    assert_non_null(getcwd(cwd, sizeof cwd));
    /* stdout and stderr into a file for the duration */
    fflush(stdout);
    fflush(stderr);
    const int o1 = dup(1), o2 = dup(2);
    const int cap = open(path_in("captured.txt"), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    assert_true(cap >= 0);
    dup2(cap, 1);
    dup2(cap, 2);
    exrfog_context *ctx = exrfog_context_create();
    assert_int_equal(run_job(0, "alone2", ctx), EXRFOG_OK);
    const char *bad[] = { "exrfog", path_in("missing.exr"), "-o", path_in("x.exr"), "--fog",
                          "exp:density=0.1" };
    assert_int_equal(exrfog_run(ctx, 6, bad), EXRFOG_ERROR);
    const char *help[] = { "exrfog", "--help" };
    assert_int_equal(exrfog_run(ctx, 2, help), EXRFOG_OK);
    /* a warning: view left is not fogged */
    assert_int_equal(run_job(3, "alone2", ctx), EXRFOG_OK);
    exrfog_context_destroy(ctx);
    fflush(stdout);
    fflush(stderr);
    dup2(o1, 1);
    dup2(o2, 2);
    close(o1);
    close(o2);
    close(cap);
    struct stat st;
    assert_int_equal(stat(path_in("captured.txt"), &st), 0);
    assert_int_equal(st.st_size, 0);
    sigaction(SIGINT, NULL, &after[0]);
    sigaction(SIGTERM, NULL, &after[1]);
    assert_ptr_equal(after[0].sa_handler, before[0].sa_handler);
    assert_ptr_equal(after[1].sa_handler, before[1].sa_handler);
    assert_ptr_equal(after[0].sa_handler, host_handler);
    assert_ptr_equal(after[1].sa_handler, host_handler2);
    assert_int_equal(umask(mask), 027);
    assert_non_null(getcwd(cwd2, sizeof cwd2));
    assert_string_equal(cwd, cwd2);
    signal(SIGINT, SIG_DFL);
    signal(SIGTERM, SIG_DFL);
}

/* ------------------------------------------------ progress, warnings */

typedef struct progress_log {
    double f[4096];
    int n;
    int decreasing;
} progress_log;

static int on_progress(void *user, double f)
{
    progress_log *p = user;
    if (p->n > 0 && f < p->f[p->n - 1])
        p->decreasing = 1;
    if (p->n < 4096)
        p->f[p->n++] = f;
    return 0;
}

/* Progress is heard per chunk and per frame, never goes back and ends at
 * exactly 1.0, once; on a failed run it never reaches 1. */
static void test_progress(void **state)
{
    (void) state;
    for (int j = 0; j < 3; j += 2) {
        progress_log log = { .n = 0 };
        exrfog_context *ctx = exrfog_context_create();
        assert_int_equal(exrfog_set_progress(ctx, on_progress, &log), EXRFOG_OK);
        assert_int_equal(run_job(j, "progress", ctx), EXRFOG_OK);
        exrfog_context_destroy(ctx);
        assert_true(log.n >= (j == 2 ? 6 : 3));   /* chunks of every frame */
        assert_false(log.decreasing);
        assert_true(log.f[log.n - 1] == 1.0);
        for (int i = 0; i + 1 < log.n; ++i)
            assert_true(log.f[i] < 1.0);
    }
}

typedef struct warn_log {
    char text[8][512];
    char file[8][1200];
    int n;
} warn_log;

static void on_warning(void *user, const char *file, const char *text)
{
    warn_log *w = user;
    if (w->n < 8) {
        snprintf(w->file[w->n], sizeof w->file[0], "%s", file);
        snprintf(w->text[w->n], sizeof w->text[0], "%s", text);
        w->n++;
    }
}

/* The warning the command line prints for a view left unfogged reaches
 * the callback with the same text and file. */
static void test_warnings(void **state)
{
    (void) state;
    warn_log w = { .n = 0 };
    exrfog_context *ctx = exrfog_context_create();
    assert_int_equal(exrfog_set_warning(ctx, on_warning, &w), EXRFOG_OK);
    assert_int_equal(run_job(3, "warn", ctx), EXRFOG_OK);
    exrfog_context_destroy(ctx);
    assert_int_equal(w.n, 1);
    assert_string_equal(w.file[0], path_in("stereo.exr"));
    /* as the command line prints it (test_pipeline checks the CLI's) */
    assert_string_equal(w.text[0], "view 'left' is not fogged (not chosen with --view); it is "
                                   "copied unchanged");
}

/* ------------------------------------------------ cancellation */

typedef struct canceller {
    exrfog_context *ctx;
    double delay;
} canceller;

static void *cancel_later(void *arg)
{
    canceller *c = arg;
    struct timespec ts = { 0, (long) (c->delay * 1e9) };
    nanosleep(&ts, NULL);
    exrfog_cancel(c->ctx);
    return NULL;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double) ts.tv_sec + 1e-9 * (double) ts.tv_nsec;
}

/* exrfog_cancel from another thread stops a slow noise run within a
 * second: EXRFOG_CANCELLED, no output, no temporary file; the context then
 * runs afresh. */
static void test_cancel(void **state)
{
    (void) state;
    exrfog_context *ctx = exrfog_context_create();
    const char *out = path_in("cancelled.exr");
    const char *argv[] = { "exrfog", sample(), "-o", out, "--fog",
                           "noise:density=0.05:scale=10:octaves=4:falloff=0.01:base=0:method=exact",
                           "--threads", "2" };
    canceller c = { ctx, 0.3 };
    pthread_t t;
    pthread_create(&t, NULL, cancel_later, &c);
    const double t0 = now_s();
    const exrfog_result r = exrfog_run(ctx, 8, argv);
    const double took = now_s() - t0;
    pthread_join(t, NULL);
    assert_int_equal(r, EXRFOG_CANCELLED);
    assert_true(took < 0.3 + 1.0);
    assert_false(tu_exists(out));
    assert_int_equal(temporaries(), 0);
    assert_non_null(strstr(exrfog_error(ctx), "cancelled"));
    assert_int_equal(run_job(0, "aftercancel", ctx), EXRFOG_OK);
    exrfog_context_destroy(ctx);
}

static int stop_at_once(void *user, double f)
{
    (void) f;
    ++*(int *) user;
    return 1;
}

/* Cancelling through the progress hook stops decode and encode, not only
 * the fog work: a 12-frame sequence whose hook says stop at the first
 * unit writes no frame, leaves no temporary file, and the hook is not
 * called again once it said so. */
static void test_cancel_stops_stream(void **state)
{
    (void) state;
    for (int f = 1; f <= 12; ++f) {
        char n[64];
        snprintf(n, sizeof n, "long.%04d.exr", f);
        copy_file(sample(), path_in(n));
    }
    char in[1300], out[1300];
    snprintf(in, sizeof in, "%s/long.#.exr", g_dir);
    snprintf(out, sizeof out, "%s/long_out.#.exr", g_dir);
    const char *argv[] = { "exrfog", in, "-o", out, "--fog", "exp:density=0.05", "--threads", "2" };
    exrfog_context *ctx = exrfog_context_create();
    int calls = 0;
    exrfog_set_progress(ctx, stop_at_once, &calls);
    assert_int_equal(exrfog_run(ctx, 8, argv), EXRFOG_CANCELLED);
    exrfog_context_destroy(ctx);
    assert_int_equal(calls, 1);
    for (int f = 1; f <= 12; ++f) {
        char n[64];
        snprintf(n, sizeof n, "long_out.%04d.exr", f);
        assert_false(tu_exists(path_in(n)));
    }
    assert_int_equal(temporaries(), 0);
}

/* ------------------------------------------------ one scene builder */

/* Every SPEC form of the man page's examples and the colour forms of
 * --fog-color and color=: exrfog_scene_create accepts exactly what the
 * command line does (the same status through exrfog_explain). */
static void test_one_builder(void **state)
{
    (void) state;
    char prof[1300];
    snprintf(prof, sizeof prof, "layered:file=%s/valley.txt:up=z", g_dir);
    const char *specs[] = {
        "exp:density=0.02:distance=planar", "linear:start=10:end=200", "exp:density=0.02",
        "exp2:visibility=150", "halfspace:plane=0,1,0,-2:density=0.05",
        "halfspace-linear:plane=0,1,0,-2:slope=0.01", "height:density=0.1:falloff=0.2:base=0",
        "layered:heights=0,5,20:densities=0.2,0.05,0", prof,
        "box:min=-5,0,-5:max=5,3,5:density=0.3", "convex:planes=0,1,0,-2,0,-1,0,0:density=0.1",
        "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0", "exp:visibility=2000",
        "halfspace:plane=0,0,1,-200:density=0.15:color=1,0.9,0.8",
        "layered:heights=0,1000,5000:densities=0.02/0.025/0.03,0.005,0",
        "exp:density=0.05,0.04,0.03", "noise:density=0.05:scale=20:velocity=1.5,0,0",
        "exp:density=0.1:color=#ff8000", "exp:density=0.1:color=ACEScg:0.2,0.3,0.4",
        "exp:density=0.1:color=#808080", "exp:density=0.1:color=Linear Rec.709 (sRGB):1,0,0",
        "noise-separable:density=0.1:scale=4:method=preintegrated:pieces=1",
        /* refused by both */
        "exp:density=-1", "exp:density=0.1:color=#ff80", "exp:density=0.1:color=NoSuch:1,2,3",
        "layered:file=/nonexistent/profile.txt", "fog:density=1", "exp",
    };
    const int nspec = (int) (sizeof specs / sizeof specs[0]);
    exrfog_context *ctx = exrfog_context_create();
    for (int i = 0; i < nspec; ++i) {
        exrfog_scene *sc = NULL;
        const exrfog_result a = exrfog_scene_create(ctx, &specs[i], 1, NULL, NULL, &sc);
        char lib_err[2048];
        snprintf(lib_err, sizeof lib_err, "%s", exrfog_error(ctx));
        exrfog_scene_destroy(sc);
        const char *argv[] = { "exrfog", sample(), "--fog", specs[i] };
        char *json = NULL;
        const exrfog_result b = exrfog_explain(ctx, 4, argv, &json);
        if (a != b)
            fail_msg("'%s': exrfog_scene_create %d (%s), the command line %d (%s)", specs[i], a,
                     lib_err, b, exrfog_error(ctx));
        if (i < 22 && a != EXRFOG_OK)
            fail_msg("'%s' is refused: %s", specs[i], lib_err);
        exrfog_free(json);
    }
    /* --fog-color's forms through a scene file's "color" and the library's */
    const char *colours[] = { "#ff8000", "ACEScg:0.2,0.3,0.4", "#808080", "0.5,0.5,0.5" };
    for (int i = 0; i < 4; ++i) {
        const char *argv[] = { "exrfog", sample(), "--fog", "exp:density=0.1", "--fog-color",
                               colours[i] };
        char *json = NULL;
        assert_int_equal(exrfog_explain(ctx, 6, argv, &json), EXRFOG_OK);
        exrfog_free(json);
    }
    exrfog_context_destroy(ctx);
}

/* A made scene reads no file again: its layered profile deleted, the next
 * exrfog_fog_pixels still works and gives the same pixels. */
static void test_scene_immutable(void **state)
{
    (void) state;
    copy_file(path_in("valley.txt"), path_in("gone.txt"));
    char spec[1300];
    snprintf(spec, sizeof spec, "layered:file=%s", path_in("gone.txt"));
    const char *specs[] = { spec };
    exrfog_context *ctx = exrfog_context_create();
    exrfog_scene *sc = NULL;
    exrfog_camera *cam = NULL;
    assert_int_equal(exrfog_scene_create(ctx, specs, 1, NULL, NULL, &sc), EXRFOG_OK);
    assert_int_equal(exrfog_camera_from_file(ctx, sample(), &cam), EXRFOG_OK);
    float out[2][3][8];
    for (int pass = 0; pass < 2; ++pass) {
        float R[8], G[8], B[8], Z[8];
        for (int i = 0; i < 8; ++i) {
            R[i] = G[i] = B[i] = 0.5f;
            Z[i] = 3.0f * (float) (i + 1);
        }
        exrfog_image img = { .size = sizeof img, .x0 = 10, .y0 = 200, .width = 8, .height = 1,
                             .stride = 8, .rgb = { R, G, B }, .depth = Z };
        assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &img), EXRFOG_OK);
        memcpy(out[pass][0], R, sizeof R);
        memcpy(out[pass][1], G, sizeof G);
        memcpy(out[pass][2], B, sizeof B);
        if (pass == 0)
            assert_int_equal(unlink(path_in("gone.txt")), 0);
    }
    assert_memory_equal(out[0], out[1], sizeof out[0]);
    assert_true(out[0][0][7] != 0.5f);   /* fogged */
    exrfog_camera_destroy(cam);
    exrfog_scene_destroy(sc);
    exrfog_context_destroy(ctx);
}

/* fog_pixels on 8 pixels with scene sc and camera cam through ctx. */
static void fog8(exrfog_context *ctx, exrfog_scene *sc, exrfog_camera *cam, float out[8])
{
    float R[8], G[8], B[8], Z[8];
    for (int i = 0; i < 8; ++i) {
        R[i] = G[i] = B[i] = 0.5f;
        Z[i] = 2.0f * (float) (i + 1);
    }
    exrfog_image img = { .size = sizeof img, .x0 = 40, .y0 = 100, .width = 8, .height = 1,
                         .stride = 8, .rgb = { R, G, B }, .depth = Z };
    assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &img), EXRFOG_OK);
    memcpy(out, R, sizeof R);
}

/* A context keeps the last call's bound scene: switching scenes and
 * cameras on one context, or a scene made where a destroyed one was,
 * gives what a fresh context gives. */
static void test_context_cache(void **state)
{
    (void) state;
    exrfog_context *ctx = exrfog_context_create();
    const char *a = "exp:density=0.05", *b = "height:density=0.3:falloff=0.5:base=0";
    const double m1[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 1, 0, 1 };
    const double m2[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 3, 0, 1 };
    const int win[4] = { 0, 0, 255, 255 };
    exrfog_scene *sa, *sb;
    exrfog_camera *c1, *c2;
    assert_int_equal(exrfog_scene_create(ctx, &a, 1, NULL, NULL, &sa), EXRFOG_OK);
    assert_int_equal(exrfog_scene_create(ctx, &b, 1, NULL, NULL, &sb), EXRFOG_OK);
    assert_int_equal(exrfog_camera_from_matrix(ctx, m1, "exr", 60, win, &c1), EXRFOG_OK);
    assert_int_equal(exrfog_camera_from_matrix(ctx, m2, "exr", 60, win, &c2), EXRFOG_OK);
    float want[2][2][8], got[8];
    exrfog_scene *sc[2] = { sa, sb };
    exrfog_camera *cm[2] = { c1, c2 };
    for (int i = 0; i < 2; ++i)
        for (int k = 0; k < 2; ++k) {
            exrfog_context *fresh = exrfog_context_create();
            fog8(fresh, sc[i], cm[k], want[i][k]);
            exrfog_context_destroy(fresh);
        }
    assert_memory_not_equal(want[1][0], want[1][1], sizeof want[1][0]);
    static const int order[][2] = { { 0, 0 }, { 1, 0 }, { 1, 1 }, { 0, 1 }, { 0, 0 }, { 1, 1 } };
    for (size_t t = 0; t < sizeof order / sizeof order[0]; ++t) {
        fog8(ctx, sc[order[t][0]], cm[order[t][1]], got);
        assert_memory_equal(got, want[order[t][0]][order[t][1]], sizeof got);
    }
    /* a new scene where the old one was */
    exrfog_scene_destroy(sb);
    assert_int_equal(exrfog_scene_create(ctx, &a, 1, NULL, NULL, &sb), EXRFOG_OK);
    fog8(ctx, sb, c2, got);
    assert_memory_equal(got, want[0][1], sizeof got);
    exrfog_scene_destroy(sa);
    exrfog_scene_destroy(sb);
    exrfog_camera_destroy(c1);
    exrfog_camera_destroy(c2);
    exrfog_context_destroy(ctx);
}

/* ------------------------------------------------ hostile arguments */

/* Every NULL the header does not allow is EXRFOG_USAGE with a message
 * (when there is a context), never a crash. */
static void test_null_arguments(void **state)
{
    (void) state;
    exrfog_context *ctx = exrfog_context_create();
    const char *spec = "exp:density=0.1";
    const char *specs_null[] = { NULL };
    exrfog_scene *sc = NULL;
    exrfog_camera *cam = NULL;
    assert_int_equal(exrfog_set_progress(NULL, on_progress, NULL), EXRFOG_USAGE);
    assert_int_equal(exrfog_set_print(NULL, 1), EXRFOG_USAGE);
    assert_int_equal(exrfog_set_warning(NULL, NULL, NULL), EXRFOG_USAGE);
    assert_int_equal(exrfog_scene_create(NULL, &spec, 1, NULL, NULL, &sc), EXRFOG_USAGE);
    assert_int_equal(exrfog_scene_create(ctx, NULL, 1, NULL, NULL, &sc), EXRFOG_USAGE);
    assert_non_null(strstr(exrfog_error(ctx), "exrfog_scene_create"));
    assert_int_equal(exrfog_scene_create(ctx, specs_null, 1, NULL, NULL, &sc), EXRFOG_USAGE);
    assert_int_equal(exrfog_scene_create(ctx, &spec, 1, NULL, NULL, NULL), EXRFOG_USAGE);
    assert_int_equal(exrfog_scene_create(ctx, &spec, -1, NULL, NULL, &sc), EXRFOG_USAGE);
    const double m[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    const int win[4] = { 0, 0, 63, 31 };
    assert_int_equal(exrfog_camera_from_matrix(ctx, NULL, "exr", 60, win, &cam), EXRFOG_USAGE);
    assert_int_equal(exrfog_camera_from_matrix(ctx, m, "exr", 60, NULL, &cam), EXRFOG_USAGE);
    assert_int_equal(exrfog_camera_from_matrix(ctx, m, "exr", 60, win, NULL), EXRFOG_USAGE);
    assert_int_equal(exrfog_camera_from_matrix(NULL, m, "exr", 60, win, &cam), EXRFOG_USAGE);
    assert_int_equal(exrfog_camera_from_file(ctx, NULL, &cam), EXRFOG_USAGE);
    assert_int_equal(exrfog_camera_from_file(NULL, sample(), &cam), EXRFOG_USAGE);
    double pos[3];
    assert_int_equal(exrfog_camera_position(NULL, pos), EXRFOG_USAGE);
    assert_int_equal(exrfog_scene_create(ctx, &spec, 1, NULL, NULL, &sc), EXRFOG_OK);
    assert_int_equal(exrfog_camera_from_matrix(ctx, m, "exr", 60, win, &cam), EXRFOG_OK);
    assert_int_equal(exrfog_camera_position(cam, NULL), EXRFOG_USAGE);
    float R[4] = { 0 }, Z[4] = { 1, 1, 1, 1 };
    exrfog_image img = { .size = sizeof img, .width = 4, .height = 1, .stride = 4,
                         .rgb = { R, R, R }, .depth = Z };
    assert_int_equal(exrfog_fog_pixels(NULL, sc, cam, &img), EXRFOG_USAGE);
    assert_int_equal(exrfog_fog_pixels(ctx, NULL, cam, &img), EXRFOG_USAGE);
    assert_int_equal(exrfog_fog_pixels(ctx, sc, NULL, &img), EXRFOG_USAGE);
    assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, NULL), EXRFOG_USAGE);
    const char *argv[] = { "exrfog", "--version" };
    assert_int_equal(exrfog_run(NULL, 2, argv), EXRFOG_USAGE);
    assert_int_equal(exrfog_run(ctx, 2, NULL), EXRFOG_USAGE);
    assert_int_equal(exrfog_run(ctx, 0, argv), EXRFOG_USAGE);
    const char *argv_null[] = { "exrfog", NULL };
    assert_int_equal(exrfog_run(ctx, 2, argv_null), EXRFOG_USAGE);
    char *json = NULL;
    assert_int_equal(exrfog_explain(NULL, 2, argv, &json), EXRFOG_USAGE);
    assert_int_equal(exrfog_explain(ctx, 2, argv, NULL), EXRFOG_USAGE);
    exrfog_cancel(NULL);
    assert_non_null(exrfog_error(NULL));
    exrfog_camera_destroy(cam);
    exrfog_scene_destroy(sc);
    exrfog_context_destroy(ctx);
}

/* Windows and rectangles whose pixel coordinates overflow an int are
 * refused; an AOV group may leave planes out (T[1] NULL), and the planes it
 * gives hold what a full group gets. */
static void test_bounds_and_partial_aovs(void **state)
{
    (void) state;
    exrfog_context *ctx = exrfog_context_create();
    const double m[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    const int huge[4] = { INT32_MIN, INT32_MIN, INT32_MAX, INT32_MAX };
    exrfog_camera *cam = NULL;
    assert_int_equal(exrfog_camera_from_matrix(ctx, m, "exr", 60, huge, &cam), EXRFOG_USAGE);
    assert_null(cam);
    assert_non_null(strstr(exrfog_error(ctx), "display window"));
    const int win[4] = { 0, 0, 63, 31 };
    assert_int_equal(exrfog_camera_from_matrix(ctx, m, "exr", 60, win, &cam), EXRFOG_OK);
    const char *spec = "exp:density=0.1";
    exrfog_scene *sc = NULL;
    assert_int_equal(exrfog_scene_create(ctx, &spec, 1, NULL, NULL, &sc), EXRFOG_OK);
    float R[4], G[4], B[4], Z[4] = { 1, 2, 3, 4 }, T0[4], T2[4], F[3][4];
    for (int i = 0; i < 4; ++i)
        R[i] = G[i] = B[i] = 0.5f;
    exrfog_image img = { .size = sizeof img, .x0 = INT32_MAX - 2, .width = 4, .height = 1,
                         .stride = 4, .rgb = { R, G, B }, .depth = Z };
    assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &img), EXRFOG_USAGE);
    img.x0 = 2;
    img.T[0] = T0;
    img.T[2] = T2;
    assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &img), EXRFOG_OK);
    for (int i = 0; i < 4; ++i)
        R[i] = G[i] = B[i] = 0.5f;
    exrfog_image full = img;
    full.T[0] = F[0];
    full.T[1] = F[1];
    full.T[2] = F[2];
    assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &full), EXRFOG_OK);
    assert_memory_equal(T0, F[0], sizeof T0);
    assert_memory_equal(T2, F[2], sizeof T2);
    /* exp's T along the ray to planar depth z at x: exp(-0.1 d) */
    assert_true(F[0][0] > 0.8f && F[0][0] < 0.95f);
    /* Partial groups on rectangles of several rows (issue 42: the missing
     * planes' scratch was one row long, and a contiguous rectangle is one
     * call of the core): T[0] and T[2] without T[1], P[1] alone, error[2]
     * alone, on 16 x 16 contiguous, 16 x 16 with a stride (gathered) and
     * 200 x 100 with a stride (row by row): each plane given holds what a
     * full group gets (ASan would see a write past the scratch). */
    static const int shapes[3][3] = { { 16, 16, 16 }, { 16, 16, 20 }, { 200, 100, 203 } };
    for (int sh = 0; sh < 3; ++sh) {
        const int w = shapes[sh][0], h = shapes[sh][1], st = shapes[sh][2];
        const size_t n = (size_t) st * (size_t) h;
        float *buf = calloc(n * 17, sizeof *buf);
        assert_non_null(buf);
        float *pl[17];
        for (int k = 0; k < 17; ++k)
            pl[k] = buf + (size_t) k * n;
        for (size_t i = 0; i < n; ++i) {
            pl[3][i] = 1.0f + (float) (i % 37);   /* depth */
            pl[0][i] = pl[1][i] = pl[2][i] = pl[8][i] = pl[9][i] = pl[10][i] = 0.5f;
        }
        exrfog_image part = { .size = sizeof part, .x0 = 1, .y0 = 2, .width = w, .height = h,
                              .stride = st, .rgb = { pl[0], pl[1], pl[2] }, .depth = pl[3] };
        part.T[0] = pl[4];
        part.T[2] = pl[5];
        part.P[1] = pl[6];
        part.error[2] = pl[7];
        assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &part), EXRFOG_OK);
        exrfog_image all = part;
        all.rgb[0] = pl[8];
        all.rgb[1] = pl[9];
        all.rgb[2] = pl[10];
        for (int k = 0; k < 3; ++k) {
            all.T[k] = pl[11 + k];
            all.P[k] = pl[14 + k];
        }
        float *E[3];
        for (int k = 0; k < 3; ++k)
            E[k] = calloc(n, sizeof *E[k]);
        all.error[0] = E[0];
        all.error[1] = E[1];
        all.error[2] = E[2];
        assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &all), EXRFOG_OK);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const size_t i = (size_t) y * (size_t) st + (size_t) x;
                assert_true(pl[4][i] == pl[11][i] && pl[5][i] == pl[13][i]);
                assert_true(pl[6][i] == pl[15][i] && pl[7][i] == E[2][i]);
                assert_true(pl[0][i] == pl[8][i]);
            }
        for (int k = 0; k < 3; ++k)
            free(E[k]);
        free(buf);
    }
    exrfog_scene_destroy(sc);
    exrfog_camera_destroy(cam);
    exrfog_context_destroy(ctx);
}

/* The light layers through exrfog_fog_pixels (issue 25): a 40 x 8
 * rectangle of the sample frame in height fog lit by a sun with a shadow
 * map (make_sample --sun-view: the frame's own depth from the sun) and a
 * point lamp. Their values are the core's, checked against the reference
 * integrator in test_light and test_shadow; here the library's plumbing
 * is: the layers equal those exrfog_run writes for the same pixels (--aov
 * light,lit, float), the layers sum to the fog the call adds to a black
 * input, a caller built before the light members (size up to P) gets the
 * same pixels and no layers, and an unlit scene refuses them. */
static void test_light_layers(void **state)
{
    (void) state;
    const char *mk = getenv("EXRFOG_MAKE_SAMPLE");
    if (!mk)
        skip();
    char cmd[3000], map[1200], scene_path[1200], out[1200];
    snprintf(map, sizeof map, "%s", path_in("sunmap.exr"));
    snprintf(scene_path, sizeof scene_path, "%s", path_in("lights.json"));
    snprintf(out, sizeof out, "%s", path_in("lit_layers.exr"));
    snprintf(cmd, sizeof cmd, "'%s' '%s' --sun-view 0.2,0.3,-1 --size 256x256 >/dev/null 2>&1", mk,
             map);
    assert_int_equal(system(cmd), 0);
    FILE *f = fopen(scene_path, "w");
    assert_non_null(f);
    fprintf(f, "{\"lights\": [\"sun:towards=0.2,0.3,-1:intensity=3:name=key:shadow=%s\",\n"
               "            \"point:position=1,2,-8:intensity=40:name=lamp\"]}\n", map);
    fclose(f);
    const char *fog = "height:density=0.3:falloff=0.5:base=0:phase=hg:g=0.5";
    exrfog_context *ctx = exrfog_context_create();
    const char *argv[] = { "exrfog", sample(), "--fog", fog, "--scene", scene_path, "--aov",
                           "light,lit", "-d", "float", "-o", out };
    assert_int_equal(exrfog_run(ctx, 12, argv), EXRFOG_OK);
    exrfog_scene *sc = NULL;
    exrfog_camera *cam = NULL;
    assert_int_equal(exrfog_scene_create(ctx, &fog, 1, scene_path, NULL, &sc), EXRFOG_OK);
    assert_int_equal(exrfog_camera_from_file(ctx, sample(), &cam), EXRFOG_OK);
    assert_int_equal(exrfog_scene_light_count(sc), 2);
    int sh = -1;
    assert_string_equal(exrfog_scene_light_name(sc, 0, &sh), "key");
    assert_int_equal(sh, 1);
    assert_string_equal(exrfog_scene_light_name(sc, 1, &sh), "lamp");
    assert_int_equal(sh, 0);
    assert_null(exrfog_scene_light_name(sc, 2, &sh));
    /* the input's pixels, and the file's layers */
    enum { X0 = 360, Y0 = 240, W = 40, H = 8, N = W * H };
    static const char *const in_names[5] = { "R", "G", "B", "A", "Z" };
    static const char *const layer[12] = {
        "fog_ambient.R", "fog_ambient.G", "fog_ambient.B", "fog_light.key.R", "fog_light.key.G",
        "fog_light.key.B", "fog_light.lamp.R", "fog_light.lamp.G", "fog_light.lamp.B",
        "fog_lit.key", "R", "G"
    };
    float in[5][N], want[12][N];
    int w = 0, h = 0;
    for (int c = 0; c < 17; ++c) {
        float *v = tu_read_channel(c < 5 ? sample() : out, 0, c < 5 ? in_names[c] : layer[c - 5],
                                   &w, &h);
        assert_non_null(v);
        for (int j = 0; j < H; ++j)
            for (int i = 0; i < W; ++i)
                (c < 5 ? in[c] : want[c - 5])[j * W + i] = v[(Y0 + j) * w + X0 + i];
        free(v);
    }
    float R[N], G[N], B[N], A[N], L[10][N];
    for (int pass = 0; pass < 2; ++pass) {
        /* pass 0: the input as it is; 1: black (the layers' sum is the fog) */
        for (int i = 0; i < N; ++i) {
            R[i] = pass ? 0 : in[0][i];
            G[i] = pass ? 0 : in[1][i];
            B[i] = pass ? 0 : in[2][i];
            A[i] = in[3][i];
        }
        float *const lp[6] = { L[3], L[4], L[5], L[6], L[7], L[8] };
        float *const litp[2] = { L[9], NULL };
        exrfog_image img = { .size = sizeof img, .x0 = X0, .y0 = Y0, .width = W, .height = H,
                             .stride = W, .rgb = { R, G, B }, .alpha = A, .depth = in[4],
                             .ambient = { L[0], L[1], L[2] }, .light = lp, .lit = litp };
        assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &img), EXRFOG_OK);
        double worst = 0, wsum = 0;
        for (int i = 0; i < N; ++i) {
            for (int c = 0; c < 10; ++c)
                worst = fmax(worst, fabs(L[c][i] - want[c][i]) / (1e-6 + fabs(want[c][i])));
            if (pass == 0)
                continue;
            const float *chan[3] = { R, G, B };
            for (int k = 0; k < 3; ++k) {
                const double sum = (double) L[k][i] + L[3 + k][i] + L[6 + k][i];
                wsum = fmax(wsum, fabs(chan[k][i] - sum) / (1e-6 + fabs(sum)));
            }
        }
        /* float layers: the same core on the same pixels, to float rounding */
        assert_true(worst <= 1e-6);
        if (pass == 1)
            assert_true(wsum <= 1e-6);
        if (pass == 0)
            for (int i = 0; i < N; ++i) {
                assert_true(fabs(R[i] - want[10][i]) <= 1e-6 * (1e-6 + fabs(want[10][i])));
                assert_true(fabs(G[i] - want[11][i]) <= 1e-6 * (1e-6 + fabs(want[11][i])));
            }
    }
    /* the lamp and the sun both show in the rectangle, the map shades some */
    double lamp = 0, key = 0, litmin = 1;
    for (int i = 0; i < N; ++i) {
        lamp = fmax(lamp, want[6][i]);
        key = fmax(key, want[3][i]);
        litmin = fmin(litmin, want[9][i]);
    }
    assert_true(lamp > 0 && key > 0 && litmin < 0.9);
    /* a caller built before the light members: the same pixels, no layers */
    float R2[N], G2[N], B2[N];
    for (int i = 0; i < N; ++i) {
        R2[i] = in[0][i];
        G2[i] = in[1][i];
        B2[i] = in[2][i];
    }
    exrfog_image old = { .size = offsetof(exrfog_image, ambient), .x0 = X0, .y0 = Y0,
                         .width = W, .height = H, .stride = W, .rgb = { R2, G2, B2 },
                         .alpha = A, .depth = in[4] };
    assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &old), EXRFOG_OK);
    for (int i = 0; i < N; ++i)
        assert_true(fabs(R2[i] - want[10][i]) <= 1e-6 * (1e-6 + fabs(want[10][i])));
    old.size = offsetof(exrfog_image, P);
    assert_int_equal(exrfog_fog_pixels(ctx, sc, cam, &old), EXRFOG_USAGE);
    /* an unlit scene has no layers to give */
    exrfog_scene *bare = NULL;
    assert_int_equal(exrfog_scene_create(ctx, &fog, 1, NULL, NULL, &bare), EXRFOG_OK);
    assert_int_equal(exrfog_scene_light_count(bare), 0);
    exrfog_image img = { .size = sizeof img, .x0 = X0, .y0 = Y0, .width = W, .height = H,
                         .stride = W, .rgb = { R2, G2, B2 }, .depth = in[4],
                         .ambient = { L[0], NULL, NULL } };
    assert_int_equal(exrfog_fog_pixels(ctx, bare, cam, &img), EXRFOG_USAGE);
    assert_non_null(strstr(exrfog_error(ctx), "lights"));
    printf("light layers: 40x8 pixels as exrfog_run writes them; lamp up to %.3g, sun %.3g, "
           "lit fraction down to %.2f\n", lamp, key, litmin);
    exrfog_scene_destroy(bare);
    exrfog_scene_destroy(sc);
    exrfog_camera_destroy(cam);
    exrfog_context_destroy(ctx);
}

/* ------------------------------------------------ fault injection */

/* Fails allocation N of fn for every N up to the count of a clean call:
 * each failure returns an error with a message (or, where an allocation
 * is not needed for the result, success with the clean call's result). */
static void faults(const char *what, exrfog_result (*fn)(exrfog_context *, void *), void *arg,
                   int (*clean)(void *, exrfog_result), long *tried)
{
    atomic_store(&alloc_count, 0);
    exrfog_context *ctx = exrfog_context_create();
    assert_int_equal(fn(ctx, arg), EXRFOG_OK);
    exrfog_context_destroy(ctx);
    const long total = atomic_load(&alloc_count);
    if (clean)
        copy_file(path_in("fault.exr"), path_in("fault_clean.exr"));
    assert_true(total > 0);
    for (long n = 1; n <= total + 2; ++n) {
        ctx = exrfog_context_create();
        atomic_store(&fail_countdown, n);
        const exrfog_result r = fn(ctx, arg);
        const int failed = atomic_load(&fail_countdown) == 0;
        atomic_store(&fail_countdown, 0);
        /* Success after a failed allocation only where the work went on
         * without it to the same result (one thread instead of many). */
        if (failed && r == EXRFOG_OK &&
            !(clean && same_bytes(path_in("fault.exr"), path_in("fault_clean.exr"))))
            fail_msg("%s: allocation %ld of %ld failed and the call succeeded", what, n, total);
        if (r != EXRFOG_OK && !exrfog_error(ctx)[0])
            fail_msg("%s: allocation %ld failed with no message", what, n);
        if (clean && !clean(arg, r))
            fail_msg("%s: allocation %ld left output or temporary files", what, n);
        exrfog_context_destroy(ctx);
    }
    *tried += total;
}

static exrfog_result fault_scene(exrfog_context *ctx, void *arg)
{
    (void) arg;
    char prof[1300];
    snprintf(prof, sizeof prof, "layered:file=%s", path_in("valley.txt"));
    const char *specs[] = { "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0", prof,
                            "exp:density=0.1:color=#ff8000",
                            "noise-separable:density=0.1:scale=4:method=preintegrated:pieces=1" };
    exrfog_scene *sc = NULL;
    const exrfog_result r = exrfog_scene_create(ctx, specs, 4, NULL, NULL, &sc);
    exrfog_scene_destroy(sc);
    return r;
}

typedef struct pixels_arg {
    exrfog_scene *sc;
    exrfog_camera *cam;
} pixels_arg;

static exrfog_result fault_pixels(exrfog_context *ctx, void *arg)
{
    pixels_arg *p = arg;
    float R[16], G[16], B[16], Z[16], T[16];
    for (int i = 0; i < 16; ++i) {
        R[i] = G[i] = B[i] = 0.5f;
        Z[i] = 1.0f + (float) i;
    }
    exrfog_image img = { .size = sizeof img, .x0 = 4, .y0 = 4, .width = 16, .height = 1,
                         .stride = 16, .rgb = { R, G, B }, .depth = Z, .T = { T, NULL, NULL } };
    return exrfog_fog_pixels(ctx, p->sc, p->cam, &img);
}

static exrfog_result fault_run(exrfog_context *ctx, void *arg)
{
    (void) arg;
    const char *argv[] = { "exrfog", path_in("stereo.exr"), "-o", path_in("fault.exr"),
                           "--view", "right", "--aov", "T,error", "--fog",
                           "noise:density=0.3:scale=2:octaves=2", "--fog", "exp:density=0.1",
                           "--threads", "2" };
    unlink(path_in("fault.exr"));
    return exrfog_run(ctx, 14, argv);
}

static int no_leftovers(void *arg, exrfog_result r)
{
    (void) arg;
    return temporaries() == 0 && (r == EXRFOG_OK || !tu_exists(path_in("fault.exr")));
}

static void test_fault_injection(void **state)
{
    (void) state;
    long tried = 0;
    faults("exrfog_scene_create", fault_scene, NULL, NULL, &tried);
    exrfog_context *ctx = exrfog_context_create();
    pixels_arg p = { NULL, NULL };
    const char *specs[] = { "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0",
                            "exp:density=0.1" };
    assert_int_equal(exrfog_scene_create(ctx, specs, 2, NULL, NULL, &p.sc), EXRFOG_OK);
    assert_int_equal(exrfog_camera_from_file(ctx, sample(), &p.cam), EXRFOG_OK);
    faults("exrfog_fog_pixels", fault_pixels, &p, NULL, &tried);
    exrfog_camera_destroy(p.cam);
    exrfog_scene_destroy(p.sc);
    exrfog_context_destroy(ctx);
    faults("exrfog_run", fault_run, NULL, no_leftovers, &tried);
    fprintf(stderr, "test_api: %ld allocations failed one at a time\n", tried);
}

/* ---- every field of exrfog_image, at random (issue 42 item 11) ---- */

/* SplitMix64: the same cases on every machine. */
static uint64_t fz_next(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static int fz_int(uint64_t *s, int lo, int hi)
{
    return lo + (int) (fz_next(s) % (uint64_t) (hi - lo + 1));
}

/* A plane the harness owns: exactly the floats the image's rectangle
 * reaches (stride (h - 1) + w, at least one), so ASan sees any access past
 * it; the gaps between rows hold a sentinel the call must leave alone. */
typedef struct fz_plane {
    float *p;
    size_t n;
} fz_plane;

#define FZ_SENTINEL (-1234.5f)

static float *fz_alloc(fz_plane *pl, int w, int h, ptrdiff_t stride, uint64_t *s, int values)
{
    const size_t n = w > 0 && h > 0 && stride >= w ? (size_t) stride * (size_t) (h - 1) + (size_t) w : 1;
    pl->p = malloc(n * sizeof *pl->p);
    pl->n = n;
    assert_non_null(pl->p);
    for (size_t i = 0; i < n; ++i) {
        const int inside = w > 0 && stride > 0 && (ptrdiff_t) (i % (size_t) stride) < w;
        static const float odd[] = { 0.0f, -1.0f, INFINITY, NAN, 1e30f, 1e-30f, 3.0f, 40.0f };
        pl->p[i] = !inside ? FZ_SENTINEL
                   : values ? odd[fz_next(s) % 8] : (float) (fz_next(s) % 1000) * 0.01f;
    }
    return pl->p;
}

/* The row gaps still hold the sentinel. */
static int fz_gaps_kept(const fz_plane *pl, int w, ptrdiff_t stride)
{
    for (size_t i = 0; i < pl->n; ++i)
        if (!(w > 0 && stride > 0 && (ptrdiff_t) (i % (size_t) stride) < w) &&
            pl->p[i] != FZ_SENTINEL)
            return 0;
    return 1;
}

/* exrfog_fog_pixels with every field of exrfog_image drawn at random, on
 * an unlit scene and on one with a lamp and a sun with a shadow map: the
 * rectangle (inside, across and outside the display window, empty and
 * negative sizes), the stride (below, at and past the width), each plane of
 * every group (colour, alpha, depth, T, error, P, ambient, sky) present or
 * NULL, the light and lit arrays (NULL, NULL entries, entries aliasing one
 * buffer), the ABI size (today's, the one before the light members, wrong
 * ones), the depth mode (valid, unknown) and depth values (0, negative,
 * inf, NaN, huge). Every plane is allocated to exactly what the rectangle
 * reaches, so under ASan (the sanitized suite) any access past it fails;
 * every call returns EXRFOG_OK or EXRFOG_USAGE with a message, and the
 * memory between rows is left as it was. The hostile campaign's overflow
 * (T[0] and T[2] without T[1], P[1] alone, aliased light planes, a sky
 * plane without a sky light) is among the draws. */
static void test_image_fuzz(void **state)
{
    (void) state;
    const char *mk = getenv("EXRFOG_MAKE_SAMPLE");
    char map[1200], cmd[3000];
    snprintf(map, sizeof map, "%s", path_in("fuzzmap.exr"));
    int lit_ok = 0;
    if (mk) {
        snprintf(cmd, sizeof cmd, "'%s' '%s' --sun-view 0.2,0.3,-1 --size 64x64 >/dev/null 2>&1",
                 mk, map);
        lit_ok = system(cmd) == 0;
    }
    exrfog_context *ctx = exrfog_context_create();
    assert_non_null(ctx);
    exrfog_scene *scenes[2] = { NULL, NULL };
    const char *unlit = "height:density=0.2:falloff=0.3";
    assert_int_equal(exrfog_scene_create(ctx, &unlit, 1, NULL, NULL, &scenes[0]), EXRFOG_OK);
    if (lit_ok) {
        char lights[1400];
        snprintf(lights, sizeof lights, "%s", path_in("fuzzlights.json"));
        FILE *f = fopen(lights, "w");
        assert_non_null(f);
        fprintf(f, "{\"lights\": [\"sun:towards=0.2,0.3,-1:intensity=3:shadow=%s\", "
                   "\"point:position=1,2,-8:intensity=40\"]}\n", map);
        fclose(f);
        assert_int_equal(exrfog_scene_create(ctx, &unlit, 1, lights, NULL, &scenes[1]), EXRFOG_OK);
    }
    const double c2w[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 1.7, 0, 1 };
    const int win[4] = { 0, 0, 63, 35 };
    exrfog_camera *cam = NULL;
    assert_int_equal(exrfog_camera_from_matrix(ctx, c2w, "exr", 60, win, &cam), EXRFOG_OK);
    uint64_t seed = 0x66757a7aull;
    const int runs = 4000;
    int ok = 0, usage = 0;
    for (int it = 0; it < runs; ++it) {
        exrfog_scene *sc = scenes[lit_ok ? it & 1 : 0];
        const int nl = exrfog_scene_light_count(sc);
        exrfog_image img;
        memset(&img, 0, sizeof img);
        const int sz = fz_int(&seed, 0, 15);
        img.size = sz < 13 ? sizeof img : sz == 13 ? offsetof(exrfog_image, ambient)
                                    : sz == 14 ? sizeof img + 8 : 3;
        img.x0 = fz_int(&seed, -10, 70);
        img.y0 = fz_int(&seed, -10, 40);
        img.width = fz_int(&seed, -1, 9);
        img.height = fz_int(&seed, -1, 5);
        img.stride = img.width + fz_int(&seed, -1, 5);
        const int w = img.width, h = img.height;
        const ptrdiff_t st = img.stride;
        fz_plane pl[32];
        int np = 0;
#define FZ_PLANE(values) fz_alloc(&pl[np++], w, h, st, &seed, values)
        for (int k = 0; k < 3; ++k)
            img.rgb[k] = fz_int(&seed, 0, 15) ? FZ_PLANE(0) : NULL;
        img.alpha = fz_int(&seed, 0, 1) ? FZ_PLANE(0) : NULL;
        img.depth = fz_int(&seed, 0, 15) ? FZ_PLANE(1) : NULL;
        static const char *const modes[] = { NULL, "planar", "radial", NULL, "planar",
                                             "radial", "bogus", "" };
        img.depth_mode = modes[fz_int(&seed, 0, 7)];
        float **groups[5] = { img.T, img.error, img.P, img.ambient, img.sky };
        for (int g = 0; g < 5; ++g) {
            const int want = fz_int(&seed, 0, 2);   /* 0: none, 1: some, 2: all */
            for (int k = 0; k < 3; ++k)
                groups[g][k] = want == 2 || (want == 1 && fz_int(&seed, 0, 1)) ? FZ_PLANE(0) : NULL;
        }
        float **light = NULL, **lit = NULL;
        if (nl > 0 && fz_int(&seed, 0, 2)) {
            light = malloc((size_t) (3 * nl) * sizeof *light);
            assert_non_null(light);
            const int alias = fz_int(&seed, 0, 1);
            float *one = alias ? FZ_PLANE(0) : NULL;
            for (int k = 0; k < 3 * nl; ++k)
                light[k] = alias ? (fz_int(&seed, 0, 3) ? one : NULL)
                                 : (fz_int(&seed, 0, 3) ? FZ_PLANE(0) : NULL);
            img.light = light;
        }
        if (nl > 0 && fz_int(&seed, 0, 2)) {
            lit = malloc((size_t) nl * sizeof *lit);
            assert_non_null(lit);
            for (int k = 0; k < nl; ++k)
                lit[k] = fz_int(&seed, 0, 2) ? FZ_PLANE(0) : NULL;
            img.lit = lit;
        }
#undef FZ_PLANE
        const exrfog_result r = exrfog_fog_pixels(ctx, sc, cam, &img);
        if (r != EXRFOG_OK && r != EXRFOG_USAGE)
            print_error("case %d: result %d: %s\n", it, (int) r, exrfog_error(ctx));
        assert_true(r == EXRFOG_OK || r == EXRFOG_USAGE);
        if (r == EXRFOG_USAGE) {
            assert_non_null(exrfog_error(ctx));
            assert_true(exrfog_error(ctx)[0] != '\0');
            ++usage;
        } else {
            ++ok;
        }
        for (int k = 0; k < np; ++k) {
            assert_true(fz_gaps_kept(&pl[k], w, st));
            free(pl[k].p);
        }
        free(light);
        free(lit);
    }
    printf("exrfog_image fuzz: %d calls (%s), %d fogged, %d refused as usage errors\n", runs,
           lit_ok ? "unlit and lit scenes" : "unlit scene only", ok, usage);
    assert_true(ok > runs / 10 && usage > runs / 10);
    exrfog_camera_destroy(cam);
    exrfog_scene_destroy(scenes[0]);
    exrfog_scene_destroy(scenes[1]);
    exrfog_context_destroy(ctx);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_reentrant),
        cmocka_unit_test(test_process_alone),
        cmocka_unit_test(test_progress),
        cmocka_unit_test(test_warnings),
        cmocka_unit_test(test_cancel),
        cmocka_unit_test(test_cancel_stops_stream),
        cmocka_unit_test(test_one_builder),
        cmocka_unit_test(test_scene_immutable),
        cmocka_unit_test(test_context_cache),
        cmocka_unit_test(test_null_arguments),
        cmocka_unit_test(test_bounds_and_partial_aovs),
        cmocka_unit_test(test_light_layers),
        cmocka_unit_test(test_image_fuzz),
        cmocka_unit_test(test_fault_injection),
    };
    /* EF_API_TESTS=a,b: only those (the ThreadSanitizer build runs the
     * reentrancy tests) */
    const char *only = getenv("EF_API_TESTS");
    if (only && only[0]) {
        struct CMUnitTest some[sizeof tests / sizeof tests[0]];
        size_t n = 0;
        char list[512];
        snprintf(list, sizeof list, ",%s,", only);
        for (size_t i = 0; i < sizeof tests / sizeof tests[0]; ++i) {
            char name[128];
            snprintf(name, sizeof name, ",%s,", tests[i].name);
            if (strstr(list, name))
                some[n++] = tests[i];
        }
        return _cmocka_run_group_tests("test_api", some, n, setup, NULL);
    }
    return cmocka_run_group_tests(tests, setup, NULL);
}
