/* noise_lod.c - what lod=pixel does to a pixel (issue 41): against the
 * pixel's own mean over its footprint, and frame to frame on a pan.
 *
 *   noise_lod [--pixels P] [--sub N] [--frames F] [--threads T] [--only NAME]
 *
 * Shots (the sweep's pinhole over the ground plane y = 0, 1920 x 1080,
 * bench/noise_shots.h): the horizon shot; a fine noise seen far
 * (sweep-23); the cases where point sampling might sparkle: a high gain
 * (0.8, 8 octaves, so the fine octaves keep their amplitude), dense fine
 * fog ending on near ground (the camera 1.5 units up looking 30 degrees
 * down on scales of 0.05 and 0.2, the finest cells near a pixel's
 * footprint there; the second with gain 0.8), grazing rays (the camera 0.5 up, pitch 0, a
 * fine scale), and the pan (7 octaves against 4).
 *
 * Per shot, P pixels (default 200, drawn as the sweep draws them):
 *   - the footprint reference: the mean of T over an N x N grid (default
 *     8) of rays through the pixel's square (box filter), each ray with
 *     the default method on the unfiltered density (|dT| <= 2^-12 each);
 *   - lod=point (the default) and lod=pixel at the pixel's centre:
 *     |T - footprint mean|, mean, 99th percentile and max over pixels;
 *   - the sparkle: the camera pans right one pixel a frame for F frames
 *     (default 24); per pixel the mean over frames of |T(k+1) - 2 T(k) +
 *     T(k-1)| (the second difference in time), averaged over pixels, for
 *     lod=point, lod=pixel and the footprint mean (4 x 4 rays: the
 *     supersampled renderer's answer).
 * Densest channel (the specs are grey). Nothing asserts: bench/noise_lod.md
 * holds a run. */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fog.h"
#include "noise_shots.h"
#include "recon.h"

#define PROG "noise_lod"

typedef struct lshot {
    const char *name;
    double height, pitch, fov;
    const char *spec;
} lshot;

static const lshot SHOTS[] = {
    { "bench-horizon", 1.7, -4, 60, "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0" },
    { "sweep-23", 42.8721, -17.8971, 36.3033,
      "noise:density=0.01148:scale=1.389:octaves=6:contrast=0.333:falloff=0.002821:base=65.89" },
    { "high-gain", 10, -12, 60, "noise:density=0.05:scale=4:octaves=8:gain=0.8:contrast=0.9" },
    { "near-dense-fine", 1.5, -30, 60, "noise:density=0.3:scale=0.05:octaves=6:contrast=0.9" },
    { "near-high-gain", 1.5, -30, 60, "noise:density=0.3:scale=0.2:octaves=8:gain=0.8:contrast=0.9" },
    { "grazing-fine", 0.5, 0, 60, "noise:density=0.05:scale=1:octaves=7:contrast=0.9" },
    { "issue-pan-7oct", 1.7, -4, 60, "noise:density=0.05:scale=10:octaves=7:falloff=0.1:base=0" },
    { "issue-pan-4oct", 1.7, -4, 60, "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0" },
};
#define NSHOTS ((int) (sizeof SHOTS / sizeof SHOTS[0]))

typedef struct job {
    const lshot *s;
    ef_fog_component *point, *lod;   /* per thread */
    const double (*pix)[2];
    int n, sub, frames, next;
    double *fp_err_point, *fp_err_lod;          /* per pixel */
    double *sp_point, *sp_lod, *sp_fp;          /* per pixel */
    pthread_mutex_t mu;
} job;

static double T_of(const ef_fog_component *c, const ef_ray *r)
{
    double tau[3];
    ef_tau_info info;
    ef_fog_tau(c, r, tau, &info);
    return exp(-fmax(tau[0], fmax(tau[1], tau[2])));
}

/* The mean of T over an m x m grid of rays through pixel (px, py). */
static double footprint(const ef_fog_component *c, const view *v, double px, double py, int m)
{
    double sum = 0;
    for (int a = 0; a < m; ++a)
        for (int b = 0; b < m; ++b) {
            ef_ray r;
            view_ray(v, floor(px) + (a + 0.5) / m, floor(py) + (b + 0.5) / m, &r);
            sum += T_of(c, &r);
        }
    return sum / (m * m);
}

static void *worker(void *arg)
{
    job *J = arg;
    const lshot *s = J->s;
    shot sh = { "", s->height, s->pitch, s->fov, "" };
    ef_fog_component point, lod;
    ef_err err = { 0 };
    char spec[600];
    snprintf(spec, sizeof spec, "%s:lod=pixel", s->spec);
    if (ef_fog_parse(s->spec, NULL, &point, &err) || ef_fog_parse(spec, NULL, &lod, &err)) {
        fprintf(stderr, PROG ": %s: %s\n", s->name, err.msg);
        exit(1);
    }
    for (;;) {
        pthread_mutex_lock(&J->mu);
        const int j = J->next++;
        pthread_mutex_unlock(&J->mu);
        if (j >= J->n)
            break;
        const double px = J->pix[j][0], py = J->pix[j][1];
        double tp[64], tl[64], tf[64];
        for (int k = 0; k < J->frames; ++k) {
            view v;
            view_init_yaw(&v, &sh, 1920, 1080, YAW_DEG);
            /* one pixel a frame: the yaw step is the pixel's angle */
            const double step = atan(view_spread(&v)) * 180 / NS_PI;
            view_init_yaw(&v, &sh, 1920, 1080, YAW_DEG + k * step);
            lod.spread = view_spread(&v);
            ef_fog_bind(&point, v.eye);
            ef_fog_bind(&lod, v.eye);
            ef_ray r;
            view_ray(&v, floor(px) + 0.5, floor(py) + 0.5, &r);
            tp[k] = T_of(&point, &r);
            tl[k] = T_of(&lod, &r);
            tf[k] = footprint(&point, &v, px, py, 4);
            if (k == 0) {
                const double ref = footprint(&point, &v, px, py, J->sub);
                J->fp_err_point[j] = fabs(tp[0] - ref);
                J->fp_err_lod[j] = fabs(tl[0] - ref);
            }
        }
        double a = 0, b = 0, c = 0;
        for (int k = 1; k + 1 < J->frames; ++k) {
            a += fabs(tp[k + 1] - 2 * tp[k] + tp[k - 1]);
            b += fabs(tl[k + 1] - 2 * tl[k] + tl[k - 1]);
            c += fabs(tf[k + 1] - 2 * tf[k] + tf[k - 1]);
        }
        const int m = J->frames - 2;
        J->sp_point[j] = m > 0 ? a / m : 0;
        J->sp_lod[j] = m > 0 ? b / m : 0;
        J->sp_fp[j] = m > 0 ? c / m : 0;
    }
    ef_fog_free(&point);
    ef_fog_free(&lod);
    return NULL;
}

static int cmp_d(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return x < y ? -1 : x > y;
}

/* mean, 99th percentile and max of v[0..n) (sorts v). */
static void stats(double *v, int n, double *mean, double *p99, double *mx)
{
    double s = 0;
    for (int i = 0; i < n; ++i)
        s += v[i];
    qsort(v, (size_t) n, sizeof *v, cmp_d);
    *mean = s / n;
    *p99 = v[(int) floor(0.99 * (n - 1))];
    *mx = v[n - 1];
}

int main(int argc, char **argv)
{
    int pixels = 200, sub = 8, frames = 24, threads = 2;
    const char *only = NULL;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        if (i + 1 < argc && !strcmp(a, "--pixels"))
            pixels = atoi(argv[++i]);
        else if (i + 1 < argc && !strcmp(a, "--sub"))
            sub = atoi(argv[++i]);
        else if (i + 1 < argc && !strcmp(a, "--frames"))
            frames = atoi(argv[++i]);
        else if (i + 1 < argc && !strcmp(a, "--threads"))
            threads = atoi(argv[++i]);
        else if (i + 1 < argc && !strcmp(a, "--only"))
            only = argv[++i];
        else {
            fprintf(stderr, "usage: " PROG " [--pixels P] [--sub N] [--frames F] [--threads T] "
                            "[--only NAME]\n");
            return 2;
        }
    }
    if (pixels < 2 || sub < 1 || frames < 3 || frames > 64 || threads < 1 || threads > 64) {
        fprintf(stderr, PROG ": bad arguments\n");
        return 2;
    }
    printf("| shot | SPEC | \\|T − footprint mean\\| lod=point: mean / 99th / max | lod=pixel: mean / "
           "99th / max | sparkle lod=point | lod=pixel | footprint mean (4×4) |\n"
           "|---|---|---|---|---:|---:|---:|\n");
    for (int si = 0; si < NSHOTS; ++si) {
        const lshot *s = &SHOTS[si];
        if (only && strcmp(only, s->name))
            continue;
        shot sh = { "", s->height, s->pitch, s->fov, "" };
        view v;
        view_init(&v, &sh, 1920, 1080);
        double (*pix)[2] = malloc((size_t) pixels * sizeof *pix);
        double *buf = calloc((size_t) pixels * 5, sizeof *buf);
        if (!pix || !buf)
            return 1;
        shot_pixels(&v, 4100 + (uint64_t) si, pixels, pix);
        job J = { s, NULL, NULL, (const double (*)[2]) pix, pixels, sub, frames, 0,
                  buf, buf + pixels, buf + 2 * pixels, buf + 3 * pixels, buf + 4 * pixels,
                  PTHREAD_MUTEX_INITIALIZER };
        pthread_t th[64];
        for (int t = 0; t < threads; ++t)
            pthread_create(&th[t], NULL, worker, &J);
        for (int t = 0; t < threads; ++t)
            pthread_join(th[t], NULL);
        double m[5], p[5], x[5];
        for (int k = 0; k < 5; ++k)
            stats(buf + (size_t) k * pixels, pixels, &m[k], &p[k], &x[k]);
        printf("| %s | `%s` | %.2g / %.2g / %.2g | %.2g / %.2g / %.2g | %.2g | %.2g | %.2g |\n",
               s->name, s->spec, m[0], p[0], x[0], m[1], p[1], x[1], m[2], m[3], m[4]);
        fflush(stdout);
        free(pix);
        free(buf);
    }
    return 0;
}
