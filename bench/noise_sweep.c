/* noise_sweep.c - the noise fog's default method on a sweep of shots, not
 * one (issue 41): accuracy against the reference integrator, the error
 * output's coverage, and the work per pixel.
 *
 *   noise_sweep --list [--count N]
 *   noise_sweep [--count N] [--only NAME] [--pixels P] [--threads T]
 *               [--width W --height H] [--tsv] [--ref-stop S]
 *               [--shot NAME,HEIGHT,PITCH,FOV,SPEC]   (that shot alone)
 *               [--lod]   (every shot with lod=pixel: against its own reference)
 *
 * The shots: the bench's two (noise_bench's noise and horizon), the three
 * the issue measured, two worst corners (the highest camera with the
 * gentlest falloff; contrast 4 with 8 octaves), and N (default 24) drawn
 * from a fixed SplitMix64 seed over what users set: camera height 1.5-300
 * units (log-uniform), pitch -30 to +10 degrees, horizontal field of view
 * 30-90 degrees, contrast 0-4 (every third shot above 1, every sixth
 * negative), octaves 1-8, scale 1-100 (log-uniform), falloff 0 (every
 * fifth) or 0.002-1 (log-uniform) with base above or below the camera,
 * a box (every fourth), and noise-separable (every sixth, axes xz). The
 * scene is the ground plane y = 0 to the horizon and the sky, seen by a
 * pinhole at (0, height, 0) turned 6 degrees right (as make_sample --view
 * renders it, so bench/noise_sweep.sh times the same shots end to end).
 *
 * Per shot, P pixels (default 1000) of a W x H frame (default 1920 x
 * 1080): 60 % uniform over the frame, 20 % in the rows within 2 % of the
 * frame's height of the horizon (long ground and sky rays), 20 % in the
 * sky or, when none is in frame, the farthest fifth of the ground. For
 * each: tau and its info from ef_fog_tau (the default method: no method,
 * tol, ttol or lod key), timed on the thread's CPU clock; the reference
 * from ef_ref_tau_long, chunk by chunk up to where tau >= S (default 20)
 * in every channel (T < 2e-9: nothing after can show) or the envelope's
 * tail is below REF_TAIL = 1e-10 (an error output within 2e-10 of |dT|
 * counts as covering it: that much is the reference's own; where it
 * stopped at S, the true T lies in [0, e^-tau_ref] and |dT| is how far the
 * method's T lies above that); |dT| = |e^-tau - e^-tau_ref| in long double, max
 * over channels. Reported per shot: |dT| max and 99.9th percentile, the
 * share of pixels within the man page's promise (|dT| <= 2^-12), the
 * share where the error output T expm1(err) covers |dT|, noise
 * evaluations per pixel (mean, max) and the fog's time per pixel (mean,
 * max, microseconds of one core). Nothing asserts on time.
 *
 * --lod adds lod=pixel to every shot (the shots where it is refused, the
 * separable and the patchy ones, are listed as such) with the pinhole's
 * pixel footprint, 2 tan(fov / 2) / W, bound as the CLI binds the camera's:
 * the reference then integrates the same filtered density (the fade is
 * in the model's density). */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fog.h"
#include "noise_shots.h"
#include "recon.h"
#include "ref.h"
#include "splitmix.h"

#define PROG "noise_sweep"
#define PROMISE 0x1p-12
/* The reference stops where the envelope's tail (the most tau it can still
 * add) is below this: |dT| up to it is the reference's own, and an error
 * output within it of |dT| counts as covering. */
#define REF_TAIL 1e-10

typedef struct px_result {
    double dT, cover, evals, us;
    int sky, ref_ok;
} px_result;

typedef struct work {
    const ef_fog_component *c;
    const view *v;
    const double (*pix)[2];
    int n, next;
    double ref_stop;
    const char *spec;
    px_result *out;
    pthread_mutex_t lock;
} work;

static double cpu_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec * 1e6 + ts.tv_nsec * 1e-3;
}

static void *worker(void *arg)
{
    work *W = arg;
    for (;;) {
        pthread_mutex_lock(&W->lock);
        const int j = W->next++;
        pthread_mutex_unlock(&W->lock);
        if (j >= W->n)
            return NULL;
        ef_ray r;
        view_ray(W->v, W->pix[j][0], W->pix[j][1], &r);
        px_result *o = &W->out[j];
        double tau[3];
        ef_tau_info info;
        const double t0 = cpu_us();
        ef_fog_tau(W->c, &r, tau, &info);
        o->us = cpu_us() - t0;
        o->evals = info.evals;
        o->sky = !isfinite(r.dist);
        long double tr[3] = { 0, 0, 0 };
        const double len = shot_ref_len(W->spec, &r, REF_TAIL);
        o->ref_ok = 1;
        int stopped = 0;   /* the reference stopped at tau >= ref_stop: T_ref is an upper value */
        if (isinf(len)) {
            for (int k = 0; k < 3; ++k)
                tr[k] = INFINITY;   /* the fog never thins: T = 0 (the model's own answer) */
        } else {
            double reached = len;
            o->ref_ok = ef_ref_tau_long(W->c, &r, len, 4096, W->ref_stop, tr, &reached, NULL) == 0;
            stopped = reached < len;
        }
        o->dT = 0;
        o->cover = 1;
        for (int k = 0; k < 3; ++k) {
            const long double T = expl(-(long double) tau[k]), Tr = expl(-tr[k]);
            /* where the reference stopped, the true T lies in [0, Tr] */
            const double d = (double) (stopped ? (T > Tr ? T - Tr : 0) : fabsl(T - Tr));
            const double bound = (double) (T > 0 ? T * expm1l(info.err[k]) : 0);
            if (d > o->dT)
                o->dT = d;
            if (!(bound + 2 * REF_TAIL >= d)) {
                o->cover = 0;
                if (getenv("SWEEP_DEBUG"))
                    fprintf(stderr, "uncovered: dir %.17g,%.17g,%.17g dist %g len %g tau %.12g ref %.12Lg err %.3g\n",
                            r.dir[0], r.dir[1], r.dir[2], r.dist, len, tau[k], tr[k], info.err[k]);
            }
        }
    }
}

static int cmp_d(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return x < y ? -1 : x > y;
}

int main(int argc, char **argv)
{
    int count = 24, pixels = 1000, threads = 2, W = 1920, H = 1080, list = 0, tsv = 0, lod = 0;
    const char *only = NULL, *extra = NULL;
    double ref_stop = 20;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--list"))
            list = 1;
        else if (!strcmp(a, "--tsv"))
            tsv = 1;
        else if (!strcmp(a, "--lod"))
            lod = 1;
        else if (v && !strcmp(a, "--count"))
            count = atoi(argv[++i]);
        else if (v && !strcmp(a, "--pixels"))
            pixels = atoi(argv[++i]);
        else if (v && !strcmp(a, "--threads"))
            threads = atoi(argv[++i]);
        else if (v && !strcmp(a, "--width"))
            W = atoi(argv[++i]);
        else if (v && !strcmp(a, "--height"))
            H = atoi(argv[++i]);
        else if (v && !strcmp(a, "--only"))
            only = argv[++i];
        else if (v && !strcmp(a, "--ref-stop"))
            ref_stop = atof(argv[++i]);
        else if (v && !strcmp(a, "--shot"))
            extra = argv[++i];
        else {
            fprintf(stderr, "usage: " PROG " [--list] [--count N] [--only NAME] [--pixels P] "
                            "[--threads T] [--width W --height H] [--tsv] [--ref-stop S] "
                            "[--shot NAME,HEIGHT,PITCH,FOV,SPEC] [--lod]\n");
            return 2;
        }
    }
    if (count < 0 || count > MAX_SHOTS - 8 || pixels < 1 || threads < 1 || W < 2 || H < 2) {
        fprintf(stderr, PROG ": bad arguments\n");
        return 2;
    }
    shot shots[MAX_SHOTS];
    int n = make_shots(shots, count);
    if (extra) {
        /* --shot NAME,HEIGHT,PITCH,FOV,SPEC: one more shot (and only it) */
        shot *t = &shots[n];
        char name[48];
        int used = 0;
        if (sscanf(extra, "%47[^,],%lf,%lf,%lf,%n", name, &t->height, &t->pitch, &t->fov, &used) < 4 ||
            !used) {
            fprintf(stderr, PROG ": --shot NAME,HEIGHT,PITCH,FOV,SPEC\n");
            return 2;
        }
        snprintf(t->name, sizeof t->name, "%s", name);
        snprintf(t->spec, sizeof t->spec, "%s", extra + used);
        only = t->name;
        ++n;
    }
    if (list) {
        for (int i = 0; i < n; ++i)
            printf("%s\t%.6g\t%.6g\t%.6g\t%s\n", shots[i].name, shots[i].height, shots[i].pitch,
                   shots[i].fov, shots[i].spec);
        return 0;
    }
    if (tsv)
        printf("shot\tpixels\tsky\tref_failed\tmax_dT\tp999_dT\twithin\tcovered\tevals_mean"
               "\tevals_max\tus_mean\tus_max\n");
    else
        printf("| shot | pixels (sky) | max \\|ΔT\\| | 99.9th \\|ΔT\\| | within 2^-12 | error output "
               "covers | evals/px mean | max | µs/px mean | max |\n|---|---:|---:|---:|---:|---:|"
               "---:|---:|---:|---:|\n");
    int bad = 0;
    for (int s = 0; s < n; ++s) {
        if (only && strcmp(only, shots[s].name))
            continue;
        ef_fog_component c;
        ef_err err = { 0 };
        char spec[sizeof shots[s].spec + 16];
        snprintf(spec, sizeof spec, "%s%s", shots[s].spec, lod ? ":lod=pixel" : "");
        if (ef_fog_parse(spec, NULL, &c, &err)) {
            if (lod && strstr(err.msg, "lod=pixel")) {
                if (!tsv)
                    printf("| %s | lod=pixel refused (%s) |\n", shots[s].name,
                           strstr(shots[s].spec, "separable") ? "noise-separable" : "the clamp binds");
                continue;
            }
            fprintf(stderr, PROG ": %s: %s\n", shots[s].name, err.msg);
            bad = 1;
            continue;
        }
        view v;
        view_init(&v, &shots[s], W, H);
        c.spread = 2 * v.tx / W;   /* the pinhole's footprint per unit distance on its axis */
        ef_fog_bind(&c, v.eye);
        double (*pix)[2] = malloc((size_t) pixels * sizeof *pix);
        px_result *out = calloc((size_t) pixels, sizeof *out);
        shot_pixels(&v, 1000 + (uint64_t) s, pixels, pix);
        work Wk = { &c, &v, (const double (*)[2]) pix, pixels, 0, ref_stop, shots[s].spec, out,
                    PTHREAD_MUTEX_INITIALIZER };
        pthread_t th[64];
        const int nt = threads < 64 ? threads : 64;
        for (int t = 0; t < nt; ++t)
            pthread_create(&th[t], NULL, worker, &Wk);
        for (int t = 0; t < nt; ++t)
            pthread_join(th[t], NULL);
        double *dts = malloc((size_t) pixels * sizeof *dts);
        int nsky = 0, nfail = 0, within = 0, covered = 0, m = 0;
        double ev = 0, evmax = 0, us = 0, usmax = 0, dmax = 0;
        for (int j = 0; j < pixels; ++j) {
            nsky += out[j].sky;
            ev += out[j].evals;
            evmax = fmax(evmax, out[j].evals);
            us += out[j].us;
            usmax = fmax(usmax, out[j].us);
            if (!out[j].ref_ok) {
                ++nfail;
                continue;
            }
            dts[m++] = out[j].dT;
            dmax = fmax(dmax, out[j].dT);
            within += out[j].dT <= PROMISE;
            covered += out[j].cover;
        }
        qsort(dts, (size_t) m, sizeof *dts, cmp_d);
        const double p999 = m ? dts[(int) floor(0.999 * (m - 1))] : 0;
        if (tsv)
            printf("%s\t%d\t%d\t%d\t%.3g\t%.3g\t%.4f\t%.4f\t%.0f\t%.0f\t%.2f\t%.1f\n",
                   shots[s].name, pixels, nsky, nfail, dmax, p999, m ? (double) within / m : 0,
                   m ? (double) covered / m : 0, ev / pixels, evmax, us / pixels, usmax);
        else
            printf("| %s | %d (%d)%s | %.2g | %.2g | %.2f %% | %.2f %% | %.0f | %.0f | %.2f | %.0f "
                   "|\n",
                   shots[s].name, pixels, nsky, nfail ? " ref failed on some" : "", dmax, p999,
                   m ? 100.0 * within / m : 0, m ? 100.0 * covered / m : 0, ev / pixels, evmax,
                   us / pixels, usmax);
        fflush(stdout);
        free(dts);
        free(pix);
        free(out);
        ef_fog_free(&c);
    }
    return bad;
}
