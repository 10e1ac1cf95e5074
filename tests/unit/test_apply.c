/* The per-block fog pass (ef_fog_block, ef_fog_block_aov) against the
 * per-pixel data flow it stands for: ef_reconstruct, the sky policy,
 * ef_scene_eval (the far segment only where the uncovered part needs it)
 * and ef_composite, one pixel at a time. The batched, span-wise pass must
 * give the same bits, float for float, for every model, sky policy, depth
 * mode, alpha (partial, zero, NaN, infinite, absent) and block shape. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "apply.h"
#include "scene.h"

#define W 150   /* more than two spans of EF_RECON_SPAN, and a ragged one */
#define H 7

static float to_float(double v)
{
    if (v > 3.4028234663852886e38)
        return INFINITY;
    if (v < -3.4028234663852886e38)
        return -INFINITY;
    return (float) v;
}

/* A pinhole camera looking down -z-ish, tilted and rolled, away from the
 * origin; proj != 0 gives a projective pixel map (hz varies per pixel). */
static void make_camera(ef_camera *cam, int proj)
{
    memset(cam, 0, sizeof *cam);
    const double a = 0.3, b = -0.2;   /* yaw, pitch */
    const double ca = cos(a), sa = sin(a), cb = cos(b), sb = sin(b);
    const double rot[9] = { ca, 0, -sa, sa * sb, cb, ca * sb, sa * cb, -sb, ca * cb };
    memcpy(cam->rot, rot, sizeof rot);
    cam->pos[0] = 1.25;
    cam->pos[1] = 1.7;
    cam->pos[2] = 3.5;
    const double f = 120.0;
    const double ray[9] = { 1 / f, 0, proj ? 1e-4 : 0, 0, -1 / f, proj ? -2e-4 : 0,
                            -W / 2.0 / f, H / 2.0 / f, 1 };
    memcpy(cam->ray, ray, sizeof ray);
    cam->unit = 1.0;
}

/* Depths: surfaces, sky (1e10), bad samples; alphas: opaque, partial,
 * zero, damaged. */
static void fill(float *rgb[3], float *alpha, float *depth, unsigned seed)
{
    srand(seed);
    for (int i = 0; i < W * H; ++i) {
        const int r = rand() % 16;
        depth[i] = r == 0 ? 1e10f : r == 1 ? NAN : r == 2 ? -1.0f : r == 3 ? 0.0f
                 : r == 4 ? INFINITY : (float) (0.05 + 80.0 * rand() / RAND_MAX);
        for (int k = 0; k < 3; ++k)
            rgb[k][i] = (float) (4.0 * rand() / RAND_MAX);
        if (i % 37 == 5)
            rgb[1][i] = INFINITY;
        if (i % 41 == 7)
            rgb[2][i] = NAN;
        const int q = rand() % 10;
        alpha[i] = q < 5 ? 1.0f : q == 5 ? 0.0f : q == 6 ? NAN : q == 7 ? INFINITY
                 : (float) rand() / RAND_MAX;
    }
}

/* The pass, one pixel at a time, from the documented parts. */
/* Returns how many composited values lie just above FLT_MAX, where a plain
 * conversion would round down to FLT_MAX and to_float gives infinity. */
static int reference(const ef_fog_pass *pass, float *rgb[3], float *alpha, const float *depth)
{
    int sliver = 0;
    const ef_fog_scene *s = pass->scene;
    const int fog_uncovered = s->sky != EF_SKY_KEEP;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int i = y * W + x;
            ef_ray r;
            const int sky = ef_reconstruct(pass->cam, pass->conv, x, y, depth[i], &r);
            if (sky && s->sky == EF_SKY_KEEP)
                continue;
            if (sky && s->sky == EF_SKY_DISTANCE_MODE)
                ef_ray_at_distance(pass->cam, x, y, s->sky_distance, &r);
            double a = alpha ? alpha[i] : 1.0;
            const int bad = !isfinite(a);
            if (bad)
                a = 1.0;
            const int need_inf = fog_uncovered && !(a == 1.0 && isfinite(r.dist));
            ef_fog_sample surf, inf;
            ef_scene_eval(s, &r, &surf, need_inf ? &inf : NULL);
            double c[3];
            for (int k = 0; k < 3; ++k)
                c[k] = rgb[k][i];
            ef_composite(&surf, need_inf ? &inf : &surf, fog_uncovered, c, alpha ? &a : NULL);
            for (int k = 0; k < 3; ++k) {
                sliver += fabs(c[k]) > 3.4028234663852886e38 && fabs(c[k]) < 0x1.ffffffp127;
                rgb[k][i] = to_float(c[k]);
            }
            if (alpha && !bad)
                alpha[i] = to_float(a);
        }
    return sliver;
}

static void check_scene(ef_fog_scene *s, const ef_camera *cam, ef_depth_mode mode)
{
    ef_depth_conv conv;
    ef_err err;
    assert_int_equal(ef_depth_conv_init(&conv, mode, cam, &err), 0);
    ef_scene_bind(s, cam->pos);
    const ef_fog_pass pass = { cam, &conv, s };
    static float buf[4][12][W * H];
    static float depth[W * H];
    float *in[3] = { buf[0][0], buf[0][1], buf[0][2] }, *in_a = buf[0][3];
    fill(in, in_a, depth, 7u + (unsigned) mode);
    for (int with_alpha = 0; with_alpha < 2; ++with_alpha)
        for (int way = 0; way < 3; ++way) {
            float *ref[3] = { buf[1][0], buf[1][1], buf[1][2] }, *ref_a = buf[1][3];
            float *got[3] = { buf[2][0], buf[2][1], buf[2][2] }, *got_a = buf[2][3];
            for (int k = 0; k < 3; ++k) {
                memcpy(ref[k], in[k], sizeof depth);
                memcpy(got[k], in[k], sizeof depth);
            }
            memcpy(ref_a, in_a, sizeof depth);
            memcpy(got_a, in_a, sizeof depth);
            reference(&pass, ref, with_alpha ? ref_a : NULL, depth);
            if (way == 0) {
                ef_fog_block(&pass, 0, 0, W, H, got, with_alpha ? got_a : NULL, depth);
            } else if (way == 1) {
                /* the general path: with AOVs */
                float *T[3] = { buf[3][0], buf[3][1], buf[3][2] };
                ef_aov_out aov;
                memset(&aov, 0, sizeof aov);
                aov.mask = EF_AOV_T;
                for (int k = 0; k < 3; ++k)
                    aov.T[k] = T[k];
                ef_fog_block_aov(&pass, 0, 0, W, H, got, with_alpha ? got_a : NULL, depth, &aov,
                                 NULL);
            } else {
                /* row by row, in ragged column blocks */
                for (int y = 0; y < H; ++y)
                    for (int x = 0; x < W;) {
                        const int w = 1 + (x * 7 + y) % 90 < W - x ? 1 + (x * 7 + y) % 90 : W - x;
                        float *g[3];
                        float a_row[W];
                        for (int k = 0; k < 3; ++k)
                            g[k] = buf[3][4 + k];
                        for (int k = 0; k < 3; ++k)
                            memcpy(g[k], got[k] + y * W + x, (size_t) w * sizeof(float));
                        memcpy(a_row, got_a + y * W + x, (size_t) w * sizeof(float));
                        ef_fog_block(&pass, x, y, w, 1, g, with_alpha ? a_row : NULL,
                                     depth + y * W + x);
                        for (int k = 0; k < 3; ++k)
                            memcpy(got[k] + y * W + x, g[k], (size_t) w * sizeof(float));
                        memcpy(got_a + y * W + x, a_row, (size_t) w * sizeof(float));
                        x += w;
                    }
            }
            for (int k = 0; k < 4; ++k) {
                const float *rp = k < 3 ? ref[k] : ref_a, *gp = k < 3 ? got[k] : got_a;
                if (memcmp(rp, gp, sizeof depth)) {
                    for (int i = 0; i < W * H; ++i)
                        if (memcmp(&rp[i], &gp[i], sizeof(float)))
                            fail_msg("%s (sky %d, mode %d, alpha %d, way %d): pixel %d channel "
                                     "%d: %.9g, expected %.9g", s->comp[0].spec, (int) s->sky,
                                     (int) mode, with_alpha, way, i, k, gp[i], rp[i]);
                }
            }
        }
}

static const char *const specs[][3] = {
    { "exp:density=0.02" },
    { "exp:density=0.01,0.02,0.03:distance=planar" },
    { "exp2:density=0.03" },
    /* the distance path with two components, a channel of no fog, both distances */
    { "exp:density=0.02,0,0.01", "exp2:density=0.01,0,0.03:distance=planar" },
    { "exp:density=0,0,0", "exp:density=1e300" },
    { "linear:start=2:end=60" },
    { "halfspace:plane=0,1,0,-1.2:density=0.15" },
    { "halfspace:plane=0.1,1,0.2,-1.7:density=0.15,0,0.3" },
    { "halfspace-linear:plane=0,1,0,-3:slope=0.05" },
    { "halfspace-linear:plane=0,-1,0,1.7:slope=0.05,0.1,0" },
    { "halfspace-smooth:plane=0,1,0,-2:density=0.2:sharpness=0.5" },
    { "halfspace-smooth:plane=0.3,1,0,-2:density=0.2,0.1,0:sharpness=0.5,1e-9,3" },
    { "height:density=0.08:falloff=0.3:base=0" },
    { "height:density=0.08,0,0.1:falloff=0:base=0" },
    { "height:density=0.08:falloff=0.3:base=1.7:up=0.1,1,0.2" },
    { "layered:heights=0,2,6:densities=0.2,0.05,0" },
    { "layered:heights=1.7:densities=0.1" },
    { "layered:heights=-1,1.7,2,6:densities=0,0.2,0.05,0.01" },
    { "box:min=-3,0,-12:max=3,2.5,-4:density=0.4" },
    { "box:min=-3,1.7,-12:max=1.25,2.5,3.5:density=0.4,0,1" },
    { "convex:planes=1,1,1,14,-1,1,1,24,1,-1,1,20,-1,-1,1,30,1,1,-1,-46,-1,1,-1,-36,1,-1,-1,"
      "-40,-1,-1,-1,-30:density=0.1" },
    { "convex:planes=0,0,1,-3.5,0.2,1,0,-2,0,-1,0,0:density=0.05" },
    { "halfspace:plane=0,1,0,-1:density=0.05", "height:density=0.02:falloff=0.1:base=0",
      "box:min=-3,0,-12:max=3,2.5,-4:density=0.2" },
    { "exp:density=0.01:color=1,0,0", "height:density=0.02:falloff=0.1" },
    { "box:min=-3,0,-12:max=3,2.5,-4:density=0.2:color=0,0,1", "exp:density=0.01" },
};

static void test_block_matches_pixels(void **state)
{
    (void) state;
    static const char *const sky[] = { "fog", "keep", "distance=40", "distance=0.5" };
    static const ef_depth_mode modes[] = { EF_DEPTH_PLANAR, EF_DEPTH_RADIAL, EF_DEPTH_INVERSE };
    for (size_t m = 0; m < sizeof specs / sizeof specs[0]; ++m)
        for (int proj = 0; proj < 2; ++proj)
            for (size_t k = 0; k < sizeof sky / sizeof sky[0]; ++k)
                for (size_t d = 0; d < sizeof modes / sizeof modes[0]; ++d) {
                    ef_fog_scene s;
                    ef_err err;
                    ef_scene_init(&s);
                    for (int c = 0; c < 3 && specs[m][c]; ++c)
                        assert_int_equal(ef_scene_add(&s, specs[m][c], &err), 0);
                    assert_int_equal(ef_scene_parse_sky(&s, sky[k], &err), 0);
                    ef_camera cam;
                    make_camera(&cam, proj);
                    check_scene(&s, &cam, modes[d]);
                    ef_scene_free(&s);
                }
}

/* Composited values just above FLT_MAX become infinities in the block pass
 * as per pixel (its conversion relies on IEC 60559 overflow): opaque-ish
 * huge alphas times the largest fog colour, seen through T > 0.5. */
static void test_float_overflow(void **state)
{
    (void) state;
    ef_fog_scene s;
    ef_err err;
    ef_scene_init(&s);
    assert_int_equal(ef_scene_add(&s, "exp:density=0.05", &err), 0);
    assert_int_equal(ef_scene_parse_sky(&s, "keep", &err), 0);
    for (int k = 0; k < 3; ++k)
        s.color[k] = 65504.0;
    ef_camera cam;
    make_camera(&cam, 0);
    ef_depth_conv conv;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_PLANAR, &cam, &err), 0);
    ef_scene_bind(&s, cam.pos);
    const ef_fog_pass pass = { &cam, &conv, &s };
    static float ref[4][W * H], got[4][W * H], depth[W * H];
    float a = (float) (3.4028234663852886e38 / 65504.0);
    while ((double) a * 65504.0 <= 3.4028234663852886e38)
        a = nextafterf(a, INFINITY);
    for (int i = 0; i < W * H; ++i) {
        depth[i] = 0.25f + 12.0f * (float) i / (W * H);
        for (int k = 0; k < 3; ++k)
            ref[k][i] = got[k][i] = k == 1 ? 3.4028234663852886e38f : 1e38f * (float) k;
        ref[3][i] = got[3][i] = i % 5 ? a : a * 0.999f;
    }
    float *r[3] = { ref[0], ref[1], ref[2] }, *g[3] = { got[0], got[1], got[2] };
    const int sliver = reference(&pass, r, ref[3], depth);
    ef_fog_block(&pass, 0, 0, W, H, g, got[3], depth);
    assert_true(sliver > 10);
    int infs = 0;
    for (int k = 0; k < 4; ++k)
        for (int i = 0; i < W * H; ++i) {
            assert_memory_equal(&got[k][i], &ref[k][i], sizeof(float));
            infs += isinf(got[k][i]);
        }
    assert_true(infs >= sliver);
    ef_scene_free(&s);
}

/* A random unit direction; every 4th one along or across an axis (the
 * planes' grazing and parallel cases), some with zero components. */
static void random_dir(double d[3], int i)
{
    for (int k = 0; k < 3; ++k)
        d[k] = 2.0 * rand() / RAND_MAX - 1.0;
    if (i % 4 == 1)
        d[rand() % 3] = 0.0;
    if (i % 8 == 3) {
        const int a = rand() % 3;
        d[a] = 0.0;
        d[(a + 1) % 3] = 0.0;
    }
    if (i % 16 == 5)
        d[rand() % 3] = 1e-17;
    const double n = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int k = 0; k < 3; ++k)
        d[k] = n > 0 ? d[k] / n : k == 2;
}

/* Every model's tau through a bound component (ef_fog_bind, its per-camera
 * cache) and through tau_add (ef_fog_tau_add) is the same bits as tau on
 * an unbound copy, for rays from the bound camera and from elsewhere:
 * cameras on a face's plane, inside a volume, on a layer's knot, far away. */
static void test_bound_tau_same_bits(void **state)
{
    (void) state;
    static const double cams[][3] = {
        { 1.25, 1.7, 3.5 }, { 0, 0, 0 },     { -3, 1, -8 },      { 3, 2.5, -4 },
        { 0, 2, 0 },        { 5, 3, -22 },   { 1e7, -3e6, 2e7 }, { -3, 0, -12 },
        { 0.5, 6, -11 },    { 0, -1, 0 },
    };
    for (size_t m = 0; m < sizeof specs / sizeof specs[0]; ++m)
        for (int c = 0; c < 3 && specs[m][c]; ++c)
            for (size_t q = 0; q < sizeof cams / sizeof cams[0]; ++q) {
                ef_fog_component bound, plain;
                ef_err err;
                assert_int_equal(ef_fog_parse(specs[m][c], NULL, &plain, &err), 0);
                assert_int_equal(ef_fog_copy(&bound, &plain), 0);
                ef_fog_bind(&bound, cams[q]);
                srand(11u + (unsigned) q);
                enum { N = 2000 };
                static ef_ray r[N];
                static double acc[N][3];
                for (int i = 0; i < N; ++i) {
                    const int own = i % 7 != 6;
                    for (int k = 0; k < 3; ++k)
                        r[i].org[k] = own ? cams[q][k] : cams[q][k] + (k == 1 ? 1e-9 : 0.0);
                    random_dir(r[i].dir, i);
                    const int kind = i % 5;
                    r[i].dist = kind == 0 ? INFINITY : kind == 1 ? 1e-3 * rand() / RAND_MAX
                              : kind == 2 ? 0.0 : 60.0 * rand() / RAND_MAX;
                    r[i].planar = r[i].dist * 0.75;
                    acc[i][0] = acc[i][1] = acc[i][2] = (double) (i % 3);
                }
                ef_fog_tau_add(&bound, r, N, acc);
                for (int i = 0; i < N; ++i) {
                    double want[3], got[3];
                    plain.model->tau(&plain, &r[i], want);
                    bound.model->tau(&bound, &r[i], got);
                    for (int k = 0; k < 3; ++k) {
                        const double sum = (double) (i % 3) + want[k];
                        if (memcmp(&got[k], &want[k], sizeof got[k]) ||
                            memcmp(&acc[i][k], &sum, sizeof sum))
                            fail_msg("%s, camera %zu, ray %d (dir %.17g,%.17g,%.17g dist %.17g) "
                                     "channel %d: bound %.17g, tau_add %.17g, expected %.17g",
                                     specs[m][c], q, i, r[i].dir[0], r[i].dir[1], r[i].dir[2],
                                     r[i].dist, k, got[k], acc[i][k] - (double) (i % 3),
                                     want[k]);
                    }
                }
                ef_fog_free(&bound);
                ef_fog_free(&plain);
            }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_block_matches_pixels),
        cmocka_unit_test(test_float_overflow),
        cmocka_unit_test(test_bound_tau_same_bits),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
