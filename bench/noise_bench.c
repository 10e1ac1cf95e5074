/* noise_bench.c - the speed/accuracy trade of exrfog's noise fog methods.
 *
 *   noise_bench FRAME.exr [--tsv] [--runs N] [--budget S] [--sample K] [--step S] [--hstep H]
 *                         [--threads T] [--only NAME (exact, else a substring)]
 *   noise_bench --list
 *
 * For each entry in the list below (the noise model's methods and
 * tolerances, noise-separable's preintegrated pieces, exp as the baseline)
 * it
 *   - times the fog pass, ef_fog_block (src/core/apply.h), on one thread:
 *     the median and best of up to N runs (default 5) on fresh copies of the
 *     decoded planes, interleaved: one run of every entry per round. When N runs of the whole frame fit the budget (default
 *     10 s per entry, estimated from a probe on 1 in 64 pixels) the whole
 *     frame is one block; else 1 in K pixels (--sample K; default: the
 *     smallest power of two that fits): in every row one span of w/K
 *     pixels, span (7 j) mod K of row j, each its own block, so every row
 *     and every stretch of columns is represented (the cost varies a lot
 *     with the row: near the horizon the ground is kilometres away); and
 *     fewer runs when even that does not fit (at least one). Mpixel/s is pixels fogged over seconds; the per-frame
 *     time is the same rate over the whole frame;
 *   - on every S-th pixel each way (default 8), surface pixels only,
 *     evaluates the component's tau with ef_fog_tau and its info, and
 *     compares T = exp(-tau) with its yardstick's: for the noise model and
 *     for noise-separable method=exact the reference integrator
 *     (ef_ref_tau, src/core/ref.h) on the same density, for
 *     noise-separable preintegrated its method=exact tau. |dT| is
 *     |e^-tau - e^-tau_yard| in long double (the error tau causes, not the
 *     output's rounding), max over channels; reported: its max, its 99.9th
 *     percentile, and the share of pixels where the error output
 *     T expm1(info.err) (what --aov error writes) covers it. The mean noise
 *     evaluations per pixel (info.evals) are over every grid pixel, sky
 *     included (the fog pass does those too), as --stats counts them.
 *     The yardsticks are computed once, on --threads threads (default 2).
 * Sky pixels are left out of the comparison: for the noise model (no
 * falloff) every method and the reference give tau = inf there; for
 * noise-separable (falloff) the exact method walks a sky ray cell by cell
 * up to where the envelope's tail bound is negligible (or tau reaches its
 * opaque cut), which a few degrees above the horizon is kilometres: 2.5 s
 * for one pixel 0.05 rad up, over a minute 0.01 rad up, and the reference
 * needs gigabytes there. For that reason noise-separable exact is a
 * yardstick here, not a timed entry.
 *
 * The horizon entries (issue 21) fog the same frame with ground fog that
 * thins with height, unbounded (HORIZON below): its sky rays leave the fog
 * after hundreds to thousands of units, and its far ground is kilometres
 * away. Their yardstick is the reference run chunk by chunk along the whole
 * ray (ef_ref_tau_long), sky pixels included, on every H-th pixel each way
 * (--hstep, default 32: 2,040 pixels at 1080p), and their accuracy columns
 * count sky pixels too.
 *
 * FRAME is read the way the CLI reads it (ef_exr_open, ef_find_channels,
 * ef_exr_read_cam_meta, ef_camera_resolve, planar depth) and decoded once
 * through ef_exr_stream (bench/bench_frame.c; the encoded copy goes to /dev/null).
 *
 * Output: a Markdown table, or with --tsv one tab-separated line per entry:
 *   family name spec timed sample runs mpix_best mpix_median frame_s evals_px
 *   max_dT p999_dT covered surface_px sky_px
 * ("-" where a field does not apply). --list prints
 * "family<TAB>name<TAB>spec<TAB>timed" per entry (bench/noise.sh reads it, so
 * the list lives here only).
 * Nothing asserts on time. */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "apply.h"
#include "bench_frame.h"
#include "exr_io.h"
#include "ref.h"
#include "scene.h"

#define PROG "noise_bench"

/* The sample scene is y-up, ground y = 0, camera at y = 1.7 looking down -z,
 * objects from z = -5 to -180 (and the ground to the horizon). */
#define NOISE "noise:density=0.02:scale=10:octaves=4"
#define SEP "noise-separable:density=0.02:scale=10:octaves=4:axes=xz:falloff=0.05:contrast=0.9"
/* The horizon scene of issue 21: ground fog that thins with height, unbounded,
 * so sky rays leave it after hundreds to thousands of units. */
#define HORIZON "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0"
#define H_RHO 0.05
#define H_K 0.1
#define H_C 0.9

enum { Y_NONE, Y_REF, Y_SEP_REF, Y_SEP_EXACT, Y_HREF, NYARD };

typedef struct entry {
    const char *family; /* exact, adaptive, steps, preintegrated, separable-exact, baseline */
    const char *name;
    const char *spec;
    int yard;           /* what its tau is compared with */
    int timed;          /* 0: a yardstick only, its fog pass not timed */
} entry;

static const entry entries[] = {
    { "baseline", "exp (OpenGL baseline)", "exp:density=0.02", Y_NONE, 1 },
    { "exact", "noise exact", NOISE ":method=exact", Y_REF, 1 },
    { "adaptive", "noise adaptive tol=1e-2", NOISE ":method=adaptive:tol=1e-2", Y_REF, 1 },
    { "adaptive", "noise adaptive tol=1e-3", NOISE ":method=adaptive:tol=1e-3", Y_REF, 1 },
    { "adaptive", "noise adaptive (default, ttol=2^-12)", NOISE, Y_REF, 1 },
    { "adaptive", "noise adaptive tol=1e-4", NOISE ":method=adaptive:tol=1e-4", Y_REF, 1 },
    { "adaptive", "noise adaptive tol=1e-6", NOISE ":method=adaptive:tol=1e-6", Y_REF, 1 },
    { "adaptive-ttol", "noise adaptive ttol=1e-2", NOISE ":method=adaptive:ttol=1e-2", Y_REF, 1 },
    { "adaptive-ttol", "noise adaptive ttol=1e-3", NOISE ":method=adaptive:ttol=1e-3", Y_REF, 1 },
    { "adaptive-ttol", "noise adaptive ttol=1e-4", NOISE ":method=adaptive:ttol=1e-4", Y_REF, 1 },
    { "adaptive-ttol", "noise adaptive ttol=1e-6", NOISE ":method=adaptive:ttol=1e-6", Y_REF, 1 },
    { "steps", "noise steps=16", NOISE ":method=steps:steps=16", Y_REF, 1 },
    { "steps", "noise steps=64", NOISE ":method=steps:steps=64", Y_REF, 1 },
    { "steps", "noise steps=256", NOISE ":method=steps:steps=256", Y_REF, 1 },
    { "steps", "noise steps=1024", NOISE ":method=steps:steps=1024", Y_REF, 1 },
    { "separable-exact", "noise-separable exact", SEP ":method=exact", Y_SEP_REF, 0 },
    { "preintegrated", "noise-separable pieces=1", SEP ":method=preintegrated:pieces=1", Y_SEP_EXACT, 1 },
    { "preintegrated", "noise-separable pieces=2", SEP ":method=preintegrated:pieces=2", Y_SEP_EXACT, 1 },
    { "preintegrated", "noise-separable pieces=4", SEP ":method=preintegrated:pieces=4", Y_SEP_EXACT, 1 },
    { "preintegrated", "noise-separable pieces=8", SEP ":method=preintegrated:pieces=8", Y_SEP_EXACT, 1 },
    { "preintegrated", "noise-separable pieces=16", SEP ":method=preintegrated:pieces=16", Y_SEP_EXACT, 1 },
    { "preintegrated", "noise-separable pieces=32", SEP ":method=preintegrated:pieces=32", Y_SEP_EXACT, 1 },
    { "preintegrated", "noise-separable pieces=64", SEP ":method=preintegrated:pieces=64", Y_SEP_EXACT, 1 },
    { "horizon-baseline", "horizon: exp (baseline)", "exp:density=0.05", Y_NONE, 1 },
    { "horizon-adaptive", "horizon: adaptive (default, ttol=2^-12)", HORIZON, Y_HREF, 1 },
    { "horizon-ttol", "horizon: adaptive ttol=1e-3", HORIZON ":method=adaptive:ttol=1e-3", Y_HREF, 1 },
    { "horizon-ttol", "horizon: adaptive ttol=1e-2", HORIZON ":method=adaptive:ttol=1e-2", Y_HREF, 1 },
    { "horizon-tol", "horizon: adaptive tol=2^-12 (the old default)", HORIZON ":method=adaptive:tol=0.000244140625", Y_HREF, 1 },
    { "horizon-exact", "horizon: exact", HORIZON ":method=exact", Y_HREF, 1 },
    { "horizon-steps", "horizon: steps=64", HORIZON ":method=steps:steps=64", Y_HREF, 1 },
    { "horizon-steps", "horizon: steps=256", HORIZON ":method=steps:steps=256", Y_HREF, 1 },
};
#define NENTRIES ((int) (sizeof entries / sizeof entries[0]))

/* ------------------------------------------------------------ timing */

typedef struct planes {
    float *rgb[3], *alpha;
} planes;

/* Seconds of ef_fog_block over 1 in k pixels of the frame, fresh input
 * each call: with k = 1 the whole frame as one block, else one span of
 * w / k pixels per row, span (7 j) mod k of row j, one block each: every
 * row and every stretch of columns is represented (the cost varies a lot
 * with the row: near the horizon the ground is kilometres away), and the
 * spans are long enough that memory is read as a stream, not pixel by
 * pixel (which would add tens of ns per pixel). *npx: pixels fogged. */
static double pass_pixels(const frame *f, const ef_fog_pass *pass, planes *p, int k, long *npx)
{
    const size_t n = (size_t) f->w * (size_t) f->h;
    for (int c = 0; c < 3; ++c)
        memcpy(p->rgb[c], f->rgb[c], n * sizeof(float));
    if (p->alpha)
        memcpy(p->alpha, f->alpha, n * sizeof(float));
    long px = 0;
    const double a = bench_now();
    if (k == 1) {
        ef_fog_block(pass, f->x0, f->y0, f->w, f->h, p->rgb, p->alpha, f->depth);
        px = (long) n;
    } else {
        const int span = (f->w + k - 1) / k;
        for (int j = 0; j < f->h; ++j) {
            const int i = (int) ((7L * j) % k) * span;
            const int w = f->w - i < span ? f->w - i : span;
            if (w <= 0)
                continue;
            const size_t o = (size_t) j * (size_t) f->w + (size_t) i;
            float *rgb[3] = { p->rgb[0] + o, p->rgb[1] + o, p->rgb[2] + o };
            ef_fog_block(pass, f->x0 + i, f->y0 + j, w, 1, rgb, p->alpha ? p->alpha + o : NULL,
                         f->depth + o);
            px += w;
        }
    }
    const double t = bench_now() - a;
    *npx = px;
    return t;
}

typedef struct timing {
    int k, runs;
    long px;               /* pixels fogged per run */
    double best, median;   /* seconds per run */
} timing;

/* Chooses 1 in k pixels and the number of runs that fit about budget
 * seconds (see the header), from a probe on 1 in 64 pixels. */
static void plan_pass(const frame *f, const ef_fog_pass *pass, planes *p, int max_runs,
                      double budget, int force_k, timing *tm)
{
    const size_t n = (size_t) f->w * (size_t) f->h;
    long px;
    const double probe = pass_pixels(f, pass, p, 64, &px);
    const double frame_est = probe * (double) n / (double) px;
    int k = 1;
    if (frame_est * max_runs > budget) {
        if (force_k > 0)
            k = force_k;
        else
            while (k < 64 && frame_est / k * max_runs > budget)
                k *= 2;
    }
    int runs = max_runs;
    while (runs > 1 && frame_est / k * runs > budget)
        --runs;
    tm->k = k;
    tm->runs = runs;
}

/* Best and median of the n run times in t (sorted in place). */
static void summarise(double *t, int n, timing *tm)
{
    qsort(t, (size_t) n, sizeof *t, bench_cmp_double);
    tm->best = t[0];
    tm->median = n % 2 ? t[n / 2] : 0.5 * (t[n / 2 - 1] + t[n / 2]);
}

/* ------------------------------------------------------------ the pixel grid */

typedef struct grid {
    int n;                 /* grid pixels */
    ef_ray *ray;           /* the surface segment (sky: to infinity) */
    unsigned char *sky;
    /* Per yardstick: the reference tau of noise and of noise-separable,
     * and noise-separable's method=exact tau. */
    long double (*yard[NYARD])[3];
} grid;

static const char *const yard_spec[NYARD] = { NULL, NOISE, SEP, SEP ":method=exact", HORIZON };

static int make_grid(const frame *f, int step, grid *g)
{
    memset(g, 0, sizeof *g);
    const int nx = (f->w + step - 1) / step, ny = (f->h + step - 1) / step;
    g->n = nx * ny;
    g->ray = malloc((size_t) g->n * sizeof *g->ray);
    g->sky = malloc((size_t) g->n);
    if (!g->ray || !g->sky)
        return -1;
    int m = 0;
    for (int j = 0; j < f->h; j += step)
        for (int i = 0; i < f->w; i += step, ++m) {
            const size_t idx = (size_t) j * (size_t) f->w + (size_t) i;
            g->sky[m] = (unsigned char) ef_reconstruct(&f->cam, &f->conv, f->x0 + i, f->y0 + j,
                                                       f->depth[idx], &g->ray[m]);
        }
    return 0;
}

static void free_grid(grid *g)
{
    free(g->ray);
    free(g->sky);
    for (int y = 0; y < NYARD; ++y)
        free(g->yard[y]);
}

/* The yardsticks over the grid, split among threads by interleaved pixels. */
typedef struct yard_job {
    grid *g;
    const ef_fog_component *c;
    int which, t, nt, failed;
} yard_job;

static void *yard_run(void *arg)
{
    yard_job *J = arg;
    grid *g = J->g;
    long double (*out)[3] = g->yard[J->which];
    for (int m = J->t; m < g->n; m += J->nt) {
        if (J->which == Y_HREF) {
            /* Long rays, sky included: chunk by chunk, to the hit or, for
             * the sky, to where the fog ahead (rho B e^(-k h)/(k mu)) is
             * below 1e-12, stopping once tau >= 36 in every channel. */
            const ef_ray *r = &g->ray[m];
            double len = r->dist;
            if (!isfinite(len)) {
                const double mu = r->dir[1], B = 1 + H_C * 1.0363538;
                len = mu > 0 ? (log(H_RHO * B / (H_K * mu * 1e-12)) / H_K - r->org[1]) / mu : 1e5;
                if (!(len > 0))
                    len = 0;
            }
            if (ef_ref_tau_long(J->c, r, len, 100, 36, out[m], NULL, NULL))
                J->failed++;
        } else if (J->which != Y_REF && g->sky[m]) {
            /* noise-separable's sky rays (see the header): surface
             * segments only, as for the noise model. */
            out[m][0] = out[m][1] = out[m][2] = NAN;
        } else if (J->which != Y_SEP_EXACT) {
            if (ef_ref_tau(J->c, &g->ray[m], out[m], NULL))
                J->failed++;
        } else {
            double t[3];
            ef_fog_tau(J->c, &g->ray[m], t, NULL);
            for (int k = 0; k < 3; ++k)
                out[m][k] = t[k];
        }
    }
    return NULL;
}

static int compute_yard(const frame *f, grid *g, int which, int threads)
{
    ef_fog_scene s;
    ef_err err;
    ef_scene_init(&s);
    g->yard[which] = malloc((size_t) g->n * sizeof *g->yard[which]);
    if (!g->yard[which]) {
        fprintf(stderr, PROG ": out of memory\n");
        return -1;
    }
    if (ef_scene_add(&s, yard_spec[which], &err)) {
        fprintf(stderr, PROG ": %s\n", err.msg);
        return -1;
    }
    ef_scene_bind(&s, f->cam.pos);
    const double a = bench_now();
    yard_job job[16];
    pthread_t th[16];
    if (threads < 1)
        threads = 1;
    if (threads > 16)
        threads = 16;
    int failed = 0;
    for (int t = 0; t < threads; ++t) {
        job[t] = (yard_job) { g, &s.comp[0], which, t, threads, 0 };
        if (pthread_create(&th[t], NULL, yard_run, &job[t])) {
            yard_run(&job[t]);
            th[t] = 0;
        }
    }
    for (int t = 0; t < threads; ++t) {
        if (th[t])
            pthread_join(th[t], NULL);
        failed += job[t].failed;
    }
    ef_scene_free(&s);
    fprintf(stderr, PROG ": yardstick %s%s over %d grid pixels on %d threads in %.1f s\n",
            which == Y_SEP_EXACT ? "" : "ef_ref_tau of ", yard_spec[which], g->n, threads,
            bench_now() - a);
    if (failed) {
        fprintf(stderr, PROG ": the reference integrator failed on %d pixels\n", failed);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------ accuracy */

typedef struct accuracy {
    double evals_per_px, max_dT, p999_dT, covered;
    double max_dtau;                 /* max |tau - tau_ref| where tau_ref < 60 (tol= bounds it) */
    long surface, sky;
} accuracy;

/* Compares c's tau on the grid's surface pixels with yardstick which; the
 * mean evaluations are over every grid pixel (with sky_too; else over the
 * surface pixels). */
static int check_accuracy(const grid *g, const ef_fog_component *c, int which, int sky_too,
                          accuracy *acc)
{
    memset(acc, 0, sizeof *acc);
    double *dts = malloc((size_t) g->n * sizeof *dts);
    if (!dts)
        return -1;
    double evals = 0;
    long covered = 0, counted = 0;
    for (int m = 0; m < g->n; ++m) {
        if (g->sky[m] && !sky_too) {
            acc->sky++;
            continue;
        }
        double tau[3];
        ef_tau_info info;
        ef_fog_tau(c, &g->ray[m], tau, &info);
        evals += info.evals;
        counted++;
        if (g->sky[m] && which != Y_HREF) {
            acc->sky++;
            continue;
        }
        acc->sky += g->sky[m];
        double dT = 0;
        int cov = 1;
        for (int k = 0; k < 3; ++k) {
            const long double yard = g->yard[which][m][k];
            /* The error tau causes, in long double (e^-inf = 0 on both
             * sides: an opaque pair differs by 0). */
            const long double d = fabsl(expl(-(long double) tau[k]) - expl(-yard));
            const long double T = expl(-(long double) tau[k]);
            const double bound = (double) (T > 0 ? T * expm1l(info.err[k]) : 0);   /* as the error AOV */
            /* Where the reference T is below e^-60 the integrators stop
             * (nothing shows past it), so tau is compared short of that. */
            const long double dtau = yard < 60 ? fabsl(tau[k] - yard) : 0;
            if ((double) dtau > acc->max_dtau)
                acc->max_dtau = (double) dtau;
            cov &= !((double) d > bound);
            if ((double) d > dT)
                dT = (double) d;
        }
        dts[acc->surface++] = dT;
        covered += cov;
    }
    acc->evals_per_px = counted ? evals / counted : 0;
    if (acc->surface > 0) {
        qsort(dts, (size_t) acc->surface, sizeof *dts, bench_cmp_double);
        acc->max_dT = dts[acc->surface - 1];
        long q = (long) ceil(0.999 * (double) acc->surface) - 1;
        if (q < 0)
            q = 0;
        acc->p999_dT = dts[q];
        acc->covered = (double) covered / (double) acc->surface;
    }
    free(dts);
    return 0;
}

/* ------------------------------------------------------------ main */

static int usage(void)
{
    fprintf(stderr, "usage: " PROG " FRAME.exr [--tsv] [--runs N] [--budget SECONDS] "
                    "[--sample K] [--step S] [--hstep H] [--threads T] [--only NAME]\n"
                    "       " PROG " --list\n");
    return 2;
}

int main(int argc, char **argv)
{
    const char *path = NULL, *only = NULL;
    int tsv = 0, runs = 5, step = 8, hstep = 32, threads = 2, force_k = 0;
    double budget = 10;
    for (int i = 1; i < argc; ++i) {
        if (strcmp(argv[i], "--list") == 0) {
            for (int e = 0; e < NENTRIES; ++e)
                printf("%s\t%s\t%s\t%d\n", entries[e].family, entries[e].name, entries[e].spec,
                       entries[e].timed);
            return 0;
        } else if (strcmp(argv[i], "--tsv") == 0) {
            tsv = 1;
        } else if (strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
            runs = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--budget") == 0 && i + 1 < argc) {
            budget = atof(argv[++i]);
        } else if (strcmp(argv[i], "--sample") == 0 && i + 1 < argc) {
            force_k = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--step") == 0 && i + 1 < argc) {
            step = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--hstep") == 0 && i + 1 < argc) {
            hstep = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
            threads = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--only") == 0 && i + 1 < argc) {
            only = argv[++i];
        } else if (argv[i][0] == '-' || path) {
            return usage();
        } else {
            path = argv[i];
        }
    }
    if (!path || runs < 1 || step < 1 || hstep < 1 || !(budget > 0))
        return usage();

    frame f;
    if (bench_load_frame(PROG, path, &f))
        return 1;
    fprintf(stderr, PROG ": %s: %dx%d; fog pass up to %d runs within %.0f s per entry; "
                    "accuracy on every %d-th pixel each way\n",
            path, f.w, f.h, runs, budget, step);
    grid g, gh;
    if (make_grid(&f, step, &g) || make_grid(&f, hstep, &gh)) {
        fprintf(stderr, PROG ": out of memory\n");
        return 1;
    }
    /* --only NAME: that entry when a name is exactly NAME, else every
     * entry whose name contains it. */
    int exact = 0;
    for (int e = 0; only && e < NENTRIES; ++e)
        exact |= strcmp(entries[e].name, only) == 0;
    /* The yardsticks the selected entries need. */
    int need[NYARD] = { 0 };
    for (int e = 0; e < NENTRIES; ++e)
        if (!only || (exact ? !strcmp(entries[e].name, only) : strstr(entries[e].name, only) != NULL))
            need[entries[e].yard] = 1;
    for (int y = 1; y < NYARD; ++y)
        if (need[y] && compute_yard(&f, y == Y_HREF ? &gh : &g, y, threads))
            return 1;

    if (!tsv) {
        printf("| family | SPEC | fog pass Mpixel/s (1 thread, best / median) | s per frame "
               "| rows timed (runs) | evals/px | max \\|dT\\| | 99.9th \\|dT\\| "
               "| error output covers |\n");
        printf("|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    }
    /* Every selected entry's scene, sampling plan and accuracy first; then
     * the timed runs interleaved, one run of each entry per round (entries
     * with fewer runs drop out of the later rounds), so a change in the
     * machine's load falls on every entry alike. */
    int status = 0;
    const size_t npx = (size_t) f.w * (size_t) f.h;
    planes pl = { { malloc(npx * sizeof(float)), malloc(npx * sizeof(float)),
                    malloc(npx * sizeof(float)) }, f.alpha ? malloc(npx * sizeof(float)) : NULL };
    ef_fog_scene *scene = calloc(NENTRIES, sizeof *scene);
    timing *tmv = calloc(NENTRIES, sizeof *tmv);
    accuracy *accv = calloc(NENTRIES, sizeof *accv);
    double *times = calloc((size_t) NENTRIES * (size_t) runs, sizeof *times);
    int *sel = calloc(NENTRIES, sizeof *sel);
    double *acc_s = calloc(NENTRIES, sizeof *acc_s);
    if (!pl.rgb[0] || !pl.rgb[1] || !pl.rgb[2] || (f.alpha && !pl.alpha) || !scene || !tmv ||
        !accv || !times || !sel || !acc_s) {
        fprintf(stderr, PROG ": out of memory\n");
        return 1;
    }
    for (int e = 0; e < NENTRIES; ++e) {
        const entry *E = &entries[e];
        if (only && (exact ? strcmp(E->name, only) != 0 : !strstr(E->name, only)))
            continue;
        ef_err err;
        ef_scene_init(&scene[e]);
        if (ef_scene_add(&scene[e], E->spec, &err)) {
            fprintf(stderr, PROG ": %s\n", err.msg);
            ef_scene_free(&scene[e]);
            status = 1;
            continue;
        }
        ef_scene_bind(&scene[e], f.cam.pos);   /* as the CLI does, once per frame */
        sel[e] = 1;
        if (E->timed) {
            const ef_fog_pass pass = { &f.cam, &f.conv, &scene[e] };
            plan_pass(&f, &pass, &pl, runs, budget, force_k, &tmv[e]);
        }
        const double a = bench_now();
        if (E->yard != Y_NONE && check_accuracy(E->yard == Y_HREF ? &gh : &g, &scene[e].comp[0],
                                                E->yard, E->timed, &accv[e])) {
            fprintf(stderr, PROG ": out of memory\n");
            return 1;
        }
        acc_s[e] = bench_now() - a;
    }
    for (int r = 0; r < runs; ++r)
        for (int e = 0; e < NENTRIES; ++e) {
            if (!sel[e] || !entries[e].timed || r >= tmv[e].runs)
                continue;
            const ef_fog_pass pass = { &f.cam, &f.conv, &scene[e] };
            times[(size_t) e * (size_t) runs + (size_t) r] =
                pass_pixels(&f, &pass, &pl, tmv[e].k, &tmv[e].px);
        }
    for (int e = 0; e < NENTRIES; ++e) {
        if (!sel[e])
            continue;
        const entry *E = &entries[e];
        timing tm = tmv[e];
        double tsum = 0;
        if (E->timed) {
            double *t = times + (size_t) e * (size_t) runs;
            for (int r = 0; r < tm.runs; ++r)
                tsum += t[r];
            summarise(t, tm.runs, &tm);
        }
        const accuracy acc = accv[e];
        const int have = E->yard != Y_NONE;
        ef_scene_free(&scene[e]);
        const double px = (double) tm.px / 1e6;
        char pass[64] = "-", best[32] = "-", med[32] = "-", frame_s[32] = "-", evals[32] = "-";
        if (E->timed) {
            snprintf(best, sizeof best, "%.4g", px / tm.best);
            snprintf(med, sizeof med, "%.4g", px / tm.median);
            snprintf(frame_s, sizeof frame_s, "%.4g", tm.median * f.w * f.h / (double) tm.px);
            snprintf(pass, sizeof pass, "%d run%s, 1 in %d px", tm.runs,
                     tm.runs == 1 ? "" : "s", tm.k);
        }
        if (have && E->timed)
            snprintf(evals, sizeof evals, "%.4g", acc.evals_per_px);
        fprintf(stderr, PROG ": %-34s %s Mpixel/s median (%s; %.1f s), %s evals/px",
                E->name, med, pass, tsum, evals);
        if (have)
            fprintf(stderr, ", max |dT| %.3g, 99.9th %.3g, covered %.4f on %ld pixels (%.1f s)",
                    acc.max_dT, acc.p999_dT, acc.covered, acc.surface, acc_s[e]);
        fprintf(stderr, "\n");
        if (tsv) {
            printf("%s\t%s\t%s\t%d\t%d\t%d\t%s\t%s\t%s\t%s", E->family, E->name, E->spec,
                   E->timed, tm.k, tm.runs, best, med, frame_s, evals);
            if (have)
                printf("\t%.3e\t%.3e\t%.6f\t%ld\t%ld\t%.3e\n", acc.max_dT, acc.p999_dT,
                       acc.covered, acc.surface, acc.sky, acc.max_dtau);
            else
                printf("\t-\t-\t-\t-\t-\t-\n");
        } else {
            printf("| %s | `%s` | %s / %s | %s | %s | %s | ", E->family, E->spec, best, med,
                   frame_s, pass, evals);
            if (have)
                printf("%.2e | %.2e | %.2f %% |\n", acc.max_dT, acc.p999_dT, 100 * acc.covered);
            else
                printf("| | |\n");
        }
        fflush(stdout);
    }
    for (int c = 0; c < 3; ++c)
        free(pl.rgb[c]);
    free(pl.alpha);
    free(scene);
    free(tmv);
    free(accv);
    free(times);
    free(sel);
    free(acc_s);
    free_grid(&g);
    free_grid(&gh);
    bench_free_frame(&f);
    return status;
}
