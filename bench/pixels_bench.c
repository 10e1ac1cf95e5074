/* bench/pixels_bench: what a small exrfog_fog_pixels call costs beside a big
 * one, per model, through the public API (libexrfog.a) as a host calls it.
 *
 * For every model: a 1024 x 1024 image (a ground plane to 60 units under a
 * camera 1.7 up, sky above the horizon) fogged in one call, and the same
 * image fogged in 16,384 calls of 64 pixels: rows of 64 x 1, and tiles of
 * 8 x 8. The small calls' total over the big call's time is what a
 * 64-pixel call costs over 64 times the per-pixel cost of a 1-Mpixel call
 * (the per-call work: the scene's lean copy, its binding to the camera,
 * the depth conversion; for a tile also its gathering into contiguous
 * planes and the core's eight row spans of 8 instead of one of 64). One
 * thread; medians of RUNS rounds, the three interleaved (one round for a
 * model slower than 2 s a frame). Prints a Markdown table. Nothing asserts
 * on time.
 *
 * usage: pixels_bench [RUNS [MODEL]]   (default 5 runs; MODEL: only the
 * models whose name starts so) */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "exrfog.h"

#define N 1024
#define B 8

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double) ts.tv_sec + 1e-9 * (double) ts.tv_nsec;
}

static int cmp(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return x < y ? -1 : x > y;
}

static float *plane(void)
{
    float *p = malloc(sizeof(float) * N * N);
    if (!p) {
        fprintf(stderr, "pixels_bench: out of memory\n");
        exit(1);
    }
    return p;
}

/* The depth of a ground plane y = 0 under a camera at height 1.7 with a
 * 60-degree horizontal fov looking slightly down; sky (infinite) above the
 * horizon, and depth capped at 60 as a far wall. */
static void ground_depth(float *z)
{
    const double t = tan(30.0 * 3.14159265358979323846 / 180.0), tilt = 0.1;
    for (int y = 0; y < N; ++y)
        for (int x = 0; x < N; ++x) {
            const double v = (1.0 - 2.0 * (y + 0.5) / N) * t;
            /* the ray (u, v, -1) pitched down by tilt: its y component */
            const double dy = v * cos(tilt) - sin(tilt);
            double d = dy < 0 ? 1.7 / -dy : INFINITY;   /* planar depth, near enough */
            if (d > 60)
                d = 60;
            z[y * N + x] = (float) d;
        }
}

typedef struct img_set {
    float *r, *g, *b, *z, *r0;
} img_set;

/* One pass: the whole image in calls of w x h. Returns the seconds. */
static double pass(exrfog_context *ctx, exrfog_scene *sc, exrfog_camera *cam, img_set *s, int w,
                   int h)
{
    for (int i = 0; i < N * N; ++i)
        s->r[i] = s->g[i] = s->b[i] = s->r0[i];
    const double t0 = now();
    for (int y = 0; y < N; y += h)
        for (int x = 0; x < N; x += w) {
            const size_t o = (size_t) y * N + (size_t) x;
            exrfog_image img = { .size = sizeof img, .x0 = x, .y0 = y, .width = w, .height = h,
                                 .stride = N, .rgb = { s->r + o, s->g + o, s->b + o },
                                 .depth = s->z + o };
            if (exrfog_fog_pixels(ctx, sc, cam, &img) != EXRFOG_OK) {
                fprintf(stderr, "pixels_bench: %s\n", exrfog_error(ctx));
                exit(1);
            }
        }
    return now() - t0;
}

int main(int argc, char **argv)
{
    const int runs = argc > 1 ? atoi(argv[1]) : 5;
    if (runs < 1 || runs > 99) {
        fprintf(stderr, "usage: pixels_bench [RUNS]\n");
        return 2;
    }
    static const char *const models[][2] = {
        { "exp", "exp:density=0.02" },
        { "exp2", "exp2:density=0.02" },
        { "linear", "linear:start=5:end=80" },
        { "exp per channel", "exp:density=0.02,0.03,0.04" },
        { "exp radial", "exp:density=0.02:distance=radial" },
        { "halfspace", "halfspace:plane=0,1,0,-2:density=0.05" },
        { "halfspace-linear", "halfspace-linear:plane=0,1,0,-2:slope=0.01" },
        { "halfspace-smooth", "halfspace-smooth:plane=0,1,0,-2:density=0.05:sharpness=1" },
        { "height", "height:density=0.1:falloff=0.2:base=0" },
        { "layered", "layered:heights=0,5,20:densities=0.2,0.05,0" },
        { "box", "box:min=-5,0,-30:max=5,3,-5:density=0.3" },
        { "convex", "convex:planes=0,1,0,-2,0,-1,0,0:density=0.1" },
        { "exp with color=", "exp:density=0.02:color=1,0.9,0.8" },
        { "noise (default)", "noise:density=0.05:scale=10:octaves=4" },
        { "noise-separable preintegrated", "noise-separable:density=0.05:scale=10:method=preintegrated:pieces=1" },
    };
    const int nm = (int) (sizeof models / sizeof models[0]);
    img_set s = { plane(), plane(), plane(), plane(), plane() };
    ground_depth(s.z);
    for (int i = 0; i < N * N; ++i)
        s.r0[i] = 0.25f + 0.5f * (float) (i % 97) / 97.0f;
    exrfog_context *ctx = exrfog_context_create();
    const double m[16] = { 1, 0, 0, 0, 0, cos(0.1), -sin(0.1), 0, 0, sin(0.1), cos(0.1), 0,
                           0, 1.7, 0, 1 };
    const int win[4] = { 0, 0, N - 1, N - 1 };
    exrfog_camera *cam = NULL;
    if (exrfog_camera_from_matrix(ctx, m, "exr", 60.0, win, &cam) != EXRFOG_OK) {
        fprintf(stderr, "pixels_bench: %s\n", exrfog_error(ctx));
        return 1;
    }
    printf("| model | 1-Mpixel call, ns/pixel | 64x1 call, us | ratio | 8x8 call, us | ratio |\n"
           "|---|---:|---:|---:|---:|---:|\n");
    for (int k = 0; k < nm; ++k) {
        if (argc > 2 && strncmp(models[k][0], argv[2], strlen(argv[2])))
            continue;
        exrfog_scene *sc = NULL;
        const char *spec = models[k][1];
        if (exrfog_scene_create(ctx, &spec, 1, NULL, NULL, &sc) != EXRFOG_OK) {
            fprintf(stderr, "pixels_bench: %s: %s\n", spec, exrfog_error(ctx));
            return 1;
        }
        double big[99], row[99], tile[99];
        /* a warm-up; a model slower than 2 s a frame gets one round only
         * (its calls' fixed cost is lost in its pixels' anyway) */
        const int nr = pass(ctx, sc, cam, &s, N, N) > 2.0 ? 1 : runs;
        for (int r = 0; r < nr; ++r) {
            big[r] = pass(ctx, sc, cam, &s, N, N);
            row[r] = pass(ctx, sc, cam, &s, B * B, 1);
            tile[r] = pass(ctx, sc, cam, &s, B, B);
        }
        qsort(big, (size_t) nr, sizeof big[0], cmp);
        qsort(row, (size_t) nr, sizeof row[0], cmp);
        qsort(tile, (size_t) nr, sizeof tile[0], cmp);
        const double tb = big[nr / 2], tr = row[nr / 2], tt = tile[nr / 2];
        const double calls = (double) N * N / (B * B);
        printf("| %s (`%s`) | %.1f | %.2f | %.2f | %.2f | %.2f |\n", models[k][0], spec,
               tb / (N * N) * 1e9, tr / calls * 1e6, tr / tb, tt / calls * 1e6, tt / tb);
        fflush(stdout);
        exrfog_scene_destroy(sc);
    }
    exrfog_camera_destroy(cam);
    exrfog_context_destroy(ctx);
    free(s.r);
    free(s.g);
    free(s.b);
    free(s.z);
    free(s.r0);
    return 0;
}
