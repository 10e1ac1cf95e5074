/* model_bench.c - per-model throughput and accuracy of exrfog's fog pass.
 *
 *   model_bench FRAME.exr [--tsv] [--runs N] [--step S] [--only NAME]
 *   model_bench --list
 *
 * For each model in the list below (one SPEC per model, plus exp as the
 * OpenGL baseline and a three-component combination) it
 *   - times ef_fog_block (src/core/apply.h) over the whole frame on one
 *     thread, N runs (default 5) on fresh copies of the decoded planes, and
 *     reports the best and the median as Mpixel/s of the fog pass alone;
 *   - compares the closed-form optical depth (c->model->tau, summed over the
 *     components) with the reference integrator (ef_ref_tau, src/core/ref.h)
 *     on every S-th pixel each way (default 8), on the surface segment and on
 *     the ray to infinity: max |T_closed - T_ref| over channels with
 *     T = exp(-tau), and max |tau_closed - tau_ref| / tau_ref.
 * exp has no density for ef_ref_tau (glFog models carry none); its reference
 * is the same integrator run on a constant density through ef_ref_integrate.
 *
 * FRAME is read the way the CLI reads it: ef_exr_open, ef_find_channels,
 * ef_exr_read_cam_meta, ef_camera_resolve, planar depth, and the frame is
 * decoded through ef_exr_stream (bench/bench_frame.c; the encoded copy goes to /dev/null).
 *
 * Output: a Markdown table, or with --tsv one tab-separated line per model:
 *   name  specs(space-separated)  mpix_best  mpix_median  max_dT  max_rel_tau  samples
 * --list prints "name<TAB>specs" per model (bench/models.sh reads it, so the
 * list lives here only). Nothing asserts on time. */
#include <errno.h>
#include <math.h>
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

#define PROG "model_bench"
#define MAX_SPECS 4

typedef struct bench_model {
    const char *name;
    const char *spec[MAX_SPECS]; /* NULL-terminated */
} bench_model;

/* The sample scene is y-up, ground y = 0, camera at y = 1.7 looking down -z,
 * objects from z = -5 to -180. Every SPEC fogs it visibly. */
static const bench_model models[] = {
    { "exp (OpenGL baseline)", { "exp:density=0.02" } },
    { "halfspace", { "halfspace:plane=0,1,0,-1.2:density=0.15" } },
    { "halfspace-linear", { "halfspace-linear:plane=0,1,0,-3:slope=0.05" } },
    { "halfspace-smooth", { "halfspace-smooth:plane=0,1,0,-2:density=0.2:sharpness=0.5" } },
    { "height", { "height:density=0.08:falloff=0.3:base=0" } },
    { "layered (inline)", { "layered:heights=0,2,6:densities=0.2,0.05,0" } },
    { "box", { "box:min=-3,0,-12:max=3,2.5,-4:density=0.4" } },
    /* An octahedron |x-5| + |y-3| + |z+30| < 8: fog where every plane is < 0. */
    { "convex (octahedron)",
      { "convex:planes=1,1,1,14,-1,1,1,24,1,-1,1,20,-1,-1,1,30,1,1,-1,-46,-1,1,-1,-36,"
        "1,-1,-1,-40,-1,-1,-1,-30:density=0.1" } },
    { "combination (3 components)",
      { "halfspace:plane=0,1,0,-1:density=0.05", "height:density=0.02:falloff=0.1:base=0",
        "box:min=-3,0,-12:max=3,2.5,-4:density=0.2" } },
};
#define NMODELS ((int) (sizeof models / sizeof models[0]))


/* ------------------------------------------------------------ timing */

/* Best and median seconds of ef_fog_block over the whole frame. */
static int time_pass(const frame *f, const ef_fog_scene *s, int runs, double *best,
                     double *median)
{
    const size_t n = (size_t) f->w * (size_t) f->h;
    float *rgb[3], *alpha = NULL;
    for (int k = 0; k < 3; ++k)
        rgb[k] = malloc(n * sizeof(float));
    if (f->alpha)
        alpha = malloc(n * sizeof(float));
    double *t = malloc((size_t) runs * sizeof *t);
    if (!rgb[0] || !rgb[1] || !rgb[2] || (f->alpha && !alpha) || !t) {
        for (int k = 0; k < 3; ++k)
            free(rgb[k]);
        free(alpha);
        free(t);
        return -1;
    }
    const ef_fog_pass pass = { &f->cam, &f->conv, s };
    volatile float sink = 0;
    for (int r = 0; r < runs; ++r) {
        for (int k = 0; k < 3; ++k)
            memcpy(rgb[k], f->rgb[k], n * sizeof(float));
        if (alpha)
            memcpy(alpha, f->alpha, n * sizeof(float));
        const double a = bench_now();
        ef_fog_block(&pass, f->x0, f->y0, f->w, f->h, rgb, alpha, f->depth);
        t[r] = bench_now() - a;
        sink += rgb[0][n / 2];
    }
    (void) sink;
    qsort(t, (size_t) runs, sizeof *t, bench_cmp_double);
    *best = t[0];
    *median = runs % 2 ? t[runs / 2] : 0.5 * (t[runs / 2 - 1] + t[runs / 2]);
    for (int k = 0; k < 3; ++k)
        free(rgb[k]);
    free(alpha);
    free(t);
    return 0;
}

/* ------------------------------------------------------------ accuracy */

static void const_density(const void *ctx, const long double *v, long double out[3])
{
    const double *rho = ctx;
    (void) v;
    for (int k = 0; k < 3; ++k)
        out[k] = rho[k];
}

/* The reference tau of one component; exp (no density of position in its
 * model) integrates its constant density along the radial segment. */
static int ref_tau(const ef_fog_component *c, const ef_ray *r, long double tau[3])
{
    if (!c->model->density && strcmp(c->model->name, "exp") == 0 &&
        c->distance == EF_DIST_RADIAL) {
        const ef_ref_density d = { .density = const_density, .ctx = c->p };
        return ef_ref_integrate(&d, r->org, r->dir, r->dist, tau, NULL);
    }
    return ef_ref_tau(c, r, tau, NULL);
}

typedef struct accuracy {
    double max_dT, max_rel;
    long samples, fogged, mismatched_inf;
} accuracy;

/* One ray: the scene's summed closed and reference taus. */
static int check_ray(const ef_fog_scene *s, const ef_ray *r, accuracy *acc)
{
    double closed[3] = { 0, 0, 0 };
    long double ref[3] = { 0, 0, 0 };
    for (int i = 0; i < s->ncomp; ++i) {
        double t[3];
        long double u[3];
        s->comp[i].model->tau(&s->comp[i], r, t);
        if (ref_tau(&s->comp[i], r, u))
            return -1;
        for (int k = 0; k < 3; ++k) {
            closed[k] += t[k];
            ref[k] += u[k];
        }
    }
    for (int k = 0; k < 3; ++k) {
        const double Tc = exp(-closed[k]), Tr = (double) expl(-ref[k]);
        const double dT = fabs(Tc - Tr);
        if (dT > acc->max_dT)
            acc->max_dT = dT;
        double rel;
        if (isinf(ref[k]) || isinf(closed[k])) {
            rel = isinf(ref[k]) && isinf(closed[k]) ? 0.0 : INFINITY;
            acc->mismatched_inf += rel != 0.0;
        } else if (ref[k] > 0) {
            rel = (double) (fabsl((long double) closed[k] - ref[k]) / ref[k]);
        } else {
            rel = closed[k] == 0 ? 0.0 : INFINITY;
        }
        if (rel > acc->max_rel)
            acc->max_rel = rel;
        acc->fogged += k == 0 && Tr < 0.99;
    }
    acc->samples++;
    return 0;
}

static int check_accuracy(const frame *f, const ef_fog_scene *s, int step, accuracy *acc)
{
    memset(acc, 0, sizeof *acc);
    for (int j = 0; j < f->h; j += step)
        for (int i = 0; i < f->w; i += step) {
            const size_t idx = (size_t) j * (size_t) f->w + (size_t) i;
            ef_ray r;
            const int sky = ef_reconstruct(&f->cam, &f->conv, f->x0 + i, f->y0 + j,
                                           f->depth[idx], &r);
            if (check_ray(s, &r, acc))
                return -1;
            if (!sky) {
                ef_ray rinf = r;
                rinf.dist = rinf.planar = INFINITY;
                if (check_ray(s, &rinf, acc))
                    return -1;
            }
        }
    return 0;
}

/* ------------------------------------------------------------ main */

static void join_specs(const bench_model *m, char *out, size_t cap, const char *sep)
{
    out[0] = '\0';
    for (int i = 0; i < MAX_SPECS && m->spec[i]; ++i) {
        if (i)
            strncat(out, sep, cap - strlen(out) - 1);
        strncat(out, m->spec[i], cap - strlen(out) - 1);
    }
}

static int usage(void)
{
    fprintf(stderr, "usage: " PROG " FRAME.exr [--tsv] [--runs N] [--step S] [--only NAME]\n"
                    "       " PROG " --list\n");
    return 2;
}

int main(int argc, char **argv)
{
    const char *path = NULL, *only = NULL;
    int tsv = 0, runs = 5, step = 8;
    for (int i = 1; i < argc; ++i) {
        if (strcmp(argv[i], "--list") == 0) {
            char specs[4096];
            for (int m = 0; m < NMODELS; ++m) {
                join_specs(&models[m], specs, sizeof specs, " ");
                printf("%s\t%s\n", models[m].name, specs);
            }
            return 0;
        } else if (strcmp(argv[i], "--tsv") == 0) {
            tsv = 1;
        } else if (strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
            runs = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--step") == 0 && i + 1 < argc) {
            step = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--only") == 0 && i + 1 < argc) {
            only = argv[++i];
        } else if (argv[i][0] == '-' || path) {
            return usage();
        } else {
            path = argv[i];
        }
    }
    if (!path || runs < 1 || step < 1)
        return usage();

    frame f;
    if (bench_load_frame(PROG, path, &f))
        return 1;
    const double mpix = (double) f.w * (double) f.h / 1e6;
    fprintf(stderr, PROG ": %s: %dx%d, %d timed runs per model, accuracy on every %d-th pixel\n",
            path, f.w, f.h, runs, step);
    if (!tsv) {
        printf("| model | SPEC | fog pass Mpixel/s (1 thread, best / median) | max \\|dT\\| "
               "| max rel tau error | rays checked |\n");
        printf("|---|---|---:|---:|---:|---:|\n");
    }
    int status = 0;
    for (int m = 0; m < NMODELS; ++m) {
        if (only && !strstr(models[m].name, only))
            continue;
        ef_fog_scene s;
        ef_err err;
        ef_scene_init(&s);
        int bad = 0;
        for (int i = 0; i < MAX_SPECS && models[m].spec[i] && !bad; ++i)
            if (ef_scene_add(&s, models[m].spec[i], &err)) {
                fprintf(stderr, PROG ": %s\n", err.msg);
                bad = 1;
            }
        ef_scene_bind(&s, f.cam.pos);   /* as the CLI does, once per frame */
        double best = 0, med = 0;
        accuracy acc;
        if (!bad && time_pass(&f, &s, runs, &best, &med)) {
            fprintf(stderr, PROG ": out of memory\n");
            bad = 1;
        }
        const double a = bench_now();
        if (!bad && check_accuracy(&f, &s, step, &acc)) {
            fprintf(stderr, PROG ": %s: the reference integrator failed\n", models[m].name);
            bad = 1;
        }
        ef_scene_free(&s);
        if (bad) {
            status = 1;
            continue;
        }
        fprintf(stderr, PROG ": %-28s %7.2f Mpixel/s best, %7.2f median; %ld rays (%ld fogged) "
                        "checked in %.1f s\n",
                models[m].name, mpix / best, mpix / med, acc.samples, acc.fogged, bench_now() - a);
        if (acc.mismatched_inf)
            fprintf(stderr, PROG ": %s: %ld rays where only one of closed/reference is infinite\n",
                    models[m].name, acc.mismatched_inf);
        char specs[4096];
        if (tsv) {
            join_specs(&models[m], specs, sizeof specs, " ");
            printf("%s\t%s\t%.3f\t%.3f\t%.3g\t%.3g\t%ld\n", models[m].name, specs, mpix / best,
                   mpix / med, acc.max_dT, acc.max_rel, acc.samples);
        } else {
            join_specs(&models[m], specs, sizeof specs, "` `");
            printf("| %s | `%s` | %.1f / %.1f | %.2g | %.2g | %ld |\n", models[m].name, specs,
                   mpix / best, mpix / med, acc.max_dT, acc.max_rel, acc.samples);
        }
        fflush(stdout);
    }
    bench_free_frame(&f);
    return status;
}
