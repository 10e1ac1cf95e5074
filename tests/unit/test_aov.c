/* --aov, --aov-origin, --time and --stats, through the exrfog binary.
 *
 * The input is a small synthetic frame whose camera is known by
 * construction: worldToCamera is a pure translation (camera at C, looking
 * down +Z, +Y up), CameraFov is the horizontal field of view, and Z is
 * planar depth. So pixel (x, y) looks along the camera-space ray
 *   d = (t (2u - 1), t (1 - 2v) H/W, 1),  t = tan(fov/2),
 *   u = (x + 0.5)/W, v = (y + 0.5)/H,
 * its surface is at C + Z d (distance Z |d|), and exp fog of density D
 * gives T = exp(-D Z |d|). Every expectation below is computed here from
 * that geometry (or, for the fog layer, from the output's own channels),
 * never by calling the code under test. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L
#endif

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "fog.h"
#include "tassert.h"
#include "testutil.h"

#define W 15                  /* odd: the middle column looks straight ahead (d.x = 0) */
#define H 40                  /* several 16-row units, so threads really split the work */
#define FOV 50.0
#define DENSITY 0.05

static const char *const AOV_CH[14] = {
    "fog.R", "fog.G", "fog.B", "fog.A", "fog_T.R", "fog_T.G", "fog_T.B",
    "fog_error.R", "fog_error.G", "fog_error.B", "fog_P.X", "fog_P.Y", "fog_P.Z",
    "fog_distance.Z",
};

/* The synthetic frame. */
typedef struct frame {
    double C[3];              /* camera position (exact in float) */
    float R[W * H], G[W * H], B[W * H], A[W * H], Z[W * H], NX[W * H];
    uint32_t id[W * H];
} frame;

enum { SKY_NONE = 0, SKY_INF, SKY_ZERO, SKY_FAR };

/* Which pixels are sky and how their depth says so. */
static int sky_kind(int x, int y)
{
    if (y == 3 && x % 3 == 0)
        return SKY_INF;
    if (y == 21 && x % 4 == 1)
        return SKY_ZERO;
    if (y == 37 || (y == 2 && x == W / 2))
        return SKY_FAR;
    return SKY_NONE;
}

static void frame_make(frame *f, double cx, double cy, double cz)
{
    f->C[0] = cx;
    f->C[1] = cy;
    f->C[2] = cz;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int i = y * W + x;
            f->R[i] = 0.1f + 0.8f * (float) x / W;
            f->G[i] = 0.2f + 0.5f * (float) y / H;
            f->B[i] = 0.3f + 0.01f * (float) ((x * 3 + y) % 7);
            f->A[i] = (x + y) % 5 == 0 ? 0.5f : (x * y) % 11 == 3 ? 0.0f : 1.0f;
            f->Z[i] = 2.0f + (float) ((x * 7 + y * 13) % 50) + 0.25f * (float) (x % 4);
            switch (sky_kind(x, y)) {
            case SKY_INF: f->Z[i] = INFINITY; break;
            case SKY_ZERO: f->Z[i] = 0.0f; break;
            case SKY_FAR: f->Z[i] = 1e10f; break;
            default: break;
            }
            f->NX[i] = (float) (x - y) * 0.125f;
            f->id[i] = 0xF0000000u + (uint32_t) i * 7919u;   /* above 2^24: exact only as uint */
        }
}

/* The camera-space ray of pixel (x, y), with z = 1. */
static void ray_of(int x, int y, double d[3])
{
    const double t = tan(FOV * 3.14159265358979323846 / 360.0);
    d[0] = t * (2.0 * (x + 0.5) / W - 1.0);
    d[1] = t * (1.0 - 2.0 * (y + 0.5) / H) * H / W;
    d[2] = 1.0;
}

static int is_sky(const frame *f, int i)
{
    return !(f->Z[i] > 0.0f) || !isfinite(f->Z[i]) || f->Z[i] >= 1e9f;
}

/* One part holding the frame: RGBA of rgba_type, float Z, and two
 * bystanders (N.X float, id uint) plus any extra channel. */
static void frame_part(tu_part *p, const frame *f, exr_pixel_type_t rgba_type, const char *extra)
{
    tu_part_init(p, W, H);
    tu_part_add(p, "R", rgba_type, f->R);
    tu_part_add(p, "G", rgba_type, f->G);
    tu_part_add(p, "B", rgba_type, f->B);
    tu_part_add(p, "A", rgba_type, f->A);
    tu_part_add(p, "Z", EXR_PIXEL_FLOAT, f->Z);
    tu_part_add(p, "N.X", EXR_PIXEL_FLOAT, f->NX);
    tu_part_add_uint(p, "id", f->id);
    if (extra)
        tu_part_add(p, extra, EXR_PIXEL_FLOAT, f->NX);
    static const float id16[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    p->m44[0].name = "worldToCamera";
    memcpy(p->m44[0].m, id16, sizeof id16);
    /* Row-vector layout: the translation -C is the last row. */
    p->m44[0].m[12] = (float) -f->C[0];
    p->m44[0].m[13] = (float) -f->C[1];
    p->m44[0].m[14] = (float) -f->C[2];
    p->f[0].name = "CameraFov";
    p->f[0].v = (float) FOV;
}

static char *write_frame(const char *name, const frame *f, exr_pixel_type_t rgba_type,
                         const char *extra)
{
    tu_part p;
    frame_part(&p, f, rgba_type, extra);
    char *path = tu_path(name);
    assert_int_equal(tu_write_exr(path, &p, 1), 0);
    return path;
}

/* How a run was asked to treat the frame. */
typedef struct expect {
    double density;
    int sky;                  /* 0 fog, 1 keep, 2 distance */
    double sky_d;
    double origin[3];
    int half;                 /* -d half: AOVs are HALF */
} expect;

/* Tolerances: float AOVs carry the double value rounded once; the
 * expectation here may differ from the program's double in the last bits. */
static double tol(const expect *e, double want)
{
    return e->half ? 1e-3 * fabs(want) + 1e-7 : 3e-7 * fabs(want) + 1e-12;
}

static long check_value(const char *what, int x, int y, double got, double want, double tl)
{
    if (isinf(want) ? got == want : fabs(got - want) <= tl)
        return 0;
    fprintf(stderr, "  %s at (%d,%d): got %.9g, want %.9g\n", what, x, y, got, want);
    return 1;
}

/* Checks every AOV channel of out (all five layers asked) against the
 * geometry, and the fog layer against the output's own colour. */
static void check_aovs(const frame *f, const char *in_path, const char *out_path, const expect *e)
{
    tu_image a, b;
    assert_int_equal(tu_read_image(in_path, 0, &a), 0);
    assert_int_equal(tu_read_image(out_path, 0, &b), 0);
    for (int c = 0; c < 14; ++c) {
        const int k = tu_image_find(&b, AOV_CH[c]);
        if (k < 0)
            fail_msg("no channel %s in %s", AOV_CH[c], out_path);
        /* -d half never demotes positions and distances (issue 9) */
        const int data = !strncmp(AOV_CH[c], "fog_P.", 6) || !strcmp(AOV_CH[c], "fog_distance.Z");
        assert_int_equal(b.type[k], e->half && !data ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT);
    }
    assert_int_equal(b.nch, a.nch + 14);
    const float *in[4] = { tu_image_f(&a, "R"), tu_image_f(&a, "G"), tu_image_f(&a, "B"),
                           tu_image_f(&a, "A") };
    const float *out[4] = { tu_image_f(&b, "R"), tu_image_f(&b, "G"), tu_image_f(&b, "B"),
                            tu_image_f(&b, "A") };
    const float *fog[4] = { tu_image_f(&b, "fog.R"), tu_image_f(&b, "fog.G"),
                            tu_image_f(&b, "fog.B"), tu_image_f(&b, "fog.A") };
    const float *T[3] = { tu_image_f(&b, "fog_T.R"), tu_image_f(&b, "fog_T.G"),
                          tu_image_f(&b, "fog_T.B") };
    const float *er[3] = { tu_image_f(&b, "fog_error.R"), tu_image_f(&b, "fog_error.G"),
                           tu_image_f(&b, "fog_error.B") };
    const float *P[3] = { tu_image_f(&b, "fog_P.X"), tu_image_f(&b, "fog_P.Y"),
                          tu_image_f(&b, "fog_P.Z") };
    const float *dist = tu_image_f(&b, "fog_distance.Z");
    long bad = 0, nsky = 0, nzero_dir = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int i = y * W + x;
            const int sky = is_sky(f, i);
            double d[3];
            ray_of(x, y, d);
            const double len = sqrt(d[0] * d[0] + d[1] * d[1] + 1.0);
            const double dd = sky ? INFINITY : (double) f->Z[i] * len;
            /* distance: the true one, inf for sky whatever --sky says */
            bad += check_value("fog_distance.Z", x, y, dist[i], dd, tol(e, dd));
            /* P: C + Z d - origin, or dir * inf (0 where dir is 0) */
            for (int k = 0; k < 3; ++k) {
                double want;
                if (sky) {
                    want = d[k] == 0.0 ? 0.0 : d[k] > 0 ? INFINITY : -INFINITY;
                    nzero_dir += d[k] == 0.0;
                } else {
                    want = (f->C[k] - e->origin[k]) + (double) f->Z[i] * d[k];
                }
                bad += check_value("fog_P", x, y, P[k][i], want, tol(e, want));
            }
            /* T: to the surface, to infinity (0 for exp) or to D for sky;
             * 1 for sky with --sky keep */
            double Tw;
            if (!sky)
                Tw = exp(-e->density * dd);
            else if (e->sky == 1)
                Tw = 1.0;
            else if (e->sky == 2)
                Tw = exp(-e->density * e->sky_d);
            else
                Tw = 0.0;
            nsky += sky;
            for (int k = 0; k < 3; ++k) {
                bad += check_value("fog_T", x, y, T[k][i], Tw, tol(e, Tw));
                /* exp has a closed form: no error */
                bad += check_value("fog_error", x, y, er[k][i], 0.0, 0.0);
                /* fog = out - T in, with the output's own values */
                const double fw = (double) out[k][i] - (double) T[k][i] * (double) in[k][i];
                bad += check_value("fog.RGB", x, y, fog[k][i], fw,
                                   e->half ? 2e-3 * (fabs(out[k][i]) + fabs(in[k][i])) + 1e-6
                                           : 1e-6 * (fabs(out[k][i]) + fabs(in[k][i])) + 1e-7);
                if (sky && e->sky == 1)
                    bad += check_value("fog.RGB (kept sky)", x, y, fog[k][i], 0.0, 0.0);
            }
            const double fa = (double) out[3][i] - (double) in[3][i];
            bad += check_value("fog.A", x, y, fog[3][i], fa, e->half ? 1e-3 : 1e-7);
        }
    assert_true(nsky > 10);
    assert_true(nzero_dir >= 1);   /* the sky pixel in the middle column */
    assert_int_equal(bad, 0);
    /* Every other channel bit for bit (uint ids above 2^24 included; -d
     * half rounds the float ones to half). */
    /* depth is never demoted by -d half: the sky's 1e10 would become inf */
    assert_int_equal(tu_compare_channel(&a, &b, "Z", 0.0, 0), 0);
    assert_int_equal(tu_compare_channel(&a, &b, "N.X", 0.0, e->half), 0);
    assert_int_equal(tu_compare_channel(&a, &b, "id", 0.0, 0), 0);
    tu_image_free(&a);
    tu_image_free(&b);
}

#define ALL "--aov fog,T --aov error,P,distance"

static void test_values_exp(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 10.5, -2.25, 100.0);
    char *in = write_frame("exp_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *out = tu_path("exp_out.exr");
    const expect e = { DENSITY, 0, 0, { 0, 0, 0 }, 0 };
    assert_run(0, "'%s' -o '%s' --fog exp:density=%g " ALL, in, out, DENSITY);
    check_aovs(&f, in, out, &e);
    /* The colour itself: the compositing formula with T and Tinf = 0. */
    tu_image b;
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    const float *R = tu_image_f(&b, "R"), *TR = tu_image_f(&b, "fog_T.R");
    const float *Aout = tu_image_f(&b, "A");
    for (int i = 0; i < W * H; ++i) {
        const double T = TR[i], a = f.A[i];
        const double want = (T > 0 ? T * f.R[i] : 0) + (1 - T) * a * 0.7 + (1 - a) * 0.7;
        assert_close(R[i], want, 1e-6);
        assert_close(Aout[i], 1.0, 1e-7);
    }
    tu_image_free(&b);
    free(in);
    free(out);
}

static void test_sky_policies(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, -3.0, 1.5, 0.0);
    char *in = write_frame("sky_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *out = tu_path("sky_out.exr");
    expect e = { 0.02, 1, 0, { 0, 0, 0 }, 0 };
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.02 --sky keep " ALL, in, out);
    check_aovs(&f, in, out, &e);
    e.sky = 2;
    e.sky_d = 300.0;
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.02 --sky distance=300 " ALL, in, out);
    check_aovs(&f, in, out, &e);
    free(in);
    free(out);
}

static void test_half_and_float_types(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.0, 2.0, -5.0);
    /* A half input: AOVs are FLOAT unless -d half. */
    char *in = write_frame("half_in.exr", &f, EXR_PIXEL_HALF, NULL);
    char *out = tu_path("half_out.exr");
    tu_image b;
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov T,distance", in, out);
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    assert_int_equal(b.type[tu_image_find(&b, "fog_T.G")], EXR_PIXEL_FLOAT);
    assert_int_equal(b.type[tu_image_find(&b, "fog_distance.Z")], EXR_PIXEL_FLOAT);
    assert_int_equal(b.type[tu_image_find(&b, "R")], EXR_PIXEL_HALF);
    assert_int_equal(tu_image_find(&b, "fog.R"), -1);
    assert_int_equal(tu_image_find(&b, "fog_P.X"), -1);
    tu_image_free(&b);
    /* -d half: every AOV channel HALF but P and distance, values to half precision. */
    char *in2 = write_frame("half_in2.exr", &f, EXR_PIXEL_FLOAT, NULL);
    const expect e = { 0.05, 0, 0, { 0, 0, 0 }, 1 };
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 -d half " ALL, in2, out);
    check_aovs(&f, in2, out, &e);
    /* -d half on a Blender multilayer input (issue 42): the passes are
     * named LAYER.FogP.X and LAYER.FogDistance.Z there, and stay float
     * all the same (the rule is what the channel holds, not its name);
     * LAYER.FogT is half. */
    {
        tu_part bp;
        tu_part_init(&bp, W, H);
        tu_part_add(&bp, "ViewLayer.Combined.R", EXR_PIXEL_FLOAT, f.R);
        tu_part_add(&bp, "ViewLayer.Combined.G", EXR_PIXEL_FLOAT, f.G);
        tu_part_add(&bp, "ViewLayer.Combined.B", EXR_PIXEL_FLOAT, f.B);
        tu_part_add(&bp, "ViewLayer.Combined.A", EXR_PIXEL_FLOAT, f.A);
        tu_part_add(&bp, "ViewLayer.Depth.Z", EXR_PIXEL_FLOAT, f.Z);
        tu_part ref;
        frame_part(&ref, &f, EXR_PIXEL_FLOAT, NULL);
        memcpy(bp.m44, ref.m44, sizeof bp.m44);
        memcpy(bp.f, ref.f, sizeof bp.f);
        char *bl = tu_path("half_blender.exr");
        assert_int_equal(tu_write_exr(bl, &bp, 1), 0);
        assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 -d half --aov T,P,distance --layer "
                      "ViewLayer.Combined --depth-channel ViewLayer.Depth.Z", bl, out);
        assert_int_equal(tu_read_image(out, 0, &b), 0);
        static const char *const kept[] = { "ViewLayer.FogP.X", "ViewLayer.FogP.Y",
                                            "ViewLayer.FogP.Z", "ViewLayer.FogDistance.Z" };
        for (size_t k = 0; k < sizeof kept / sizeof kept[0]; ++k) {
            const int at = tu_image_find(&b, kept[k]);
            assert_true(at >= 0);
            assert_int_equal(b.type[at], EXR_PIXEL_FLOAT);
        }
        assert_int_equal(b.type[tu_image_find(&b, "ViewLayer.FogT.R")], EXR_PIXEL_HALF);
        assert_int_equal(b.type[tu_image_find(&b, "ViewLayer.Combined.R")], EXR_PIXEL_HALF);
        tu_image_free(&b);
        free(bl);
    }
    /* -d float: FLOAT, as the default */
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 -d float --aov error", in, out);
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    assert_int_equal(b.type[tu_image_find(&b, "fog_error.B")], EXR_PIXEL_FLOAT);
    tu_image_free(&b);
    free(in);
    free(in2);
    free(out);
}

/* Reads the v3d attribute name of part 0; returns 0 when present. */
static int read_v3d(const char *path, const char *name, double v[3])
{
    exr_context_t c;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    if (exr_start_read(&c, path, &init))
        return -1;
    exr_attr_v3d_t a;
    const exr_result_t rv = exr_attr_get_v3d(c, 0, name, &a);
    exr_finish(&c);
    if (rv)
        return -1;
    v[0] = a.x;
    v[1] = a.y;
    v[2] = a.z;
    return 0;
}

static int read_string(const char *path, const char *name, char *buf, size_t len)
{
    exr_context_t c;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    if (exr_start_read(&c, path, &init))
        return -1;
    const char *s = NULL;
    int32_t n = 0;
    const exr_result_t rv = exr_attr_get_string(c, 0, name, &n, &s);
    if (!rv)
        snprintf(buf, len, "%.*s", (int) n, s);
    exr_finish(&c);
    return rv ? -1 : 0;
}

static void test_origin_far_from_zero(void **state)
{
    (void) state;
    static frame f;
    /* A camera a thousand kilometres out: float spacing there is 1/16. */
    frame_make(&f, 1000000.5, 3.0, -2000000.25);
    char *in = write_frame("far_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *out = tu_path("far_out.exr");
    const expect e = { DENSITY, 0, 0, { 1000000.0, 0.0, -2000000.0 }, 0 };
    assert_run(0, "'%s' -o '%s' --fog exp:density=%g --aov-origin 1000000,0,-2000000 " ALL, in,
               out, DENSITY);
    /* Relative to the origin the positions keep float precision (an
     * origin subtracted after the float cast would be off by ~1/16). */
    check_aovs(&f, in, out, &e);
    double v[3] = { 0, 0, 0 };
    assert_int_equal(read_v3d(out, "exrfog/aovOrigin", v), 0);
    assert_true(v[0] == 1000000.0 && v[1] == 0.0 && v[2] == -2000000.0);
    char params[2048];
    assert_int_equal(read_string(out, "exrfog/parameters", params, sizeof params), 0);
    assert_contains(params, "--aov-origin 1000000,0,-2000000");
    /* Without --aov-origin: absolute positions, and no attribute. */
    assert_run(0, "'%s' -o '%s' --fog exp:density=%g --aov P", in, out, DENSITY);
    assert_int_equal(read_v3d(out, "exrfog/aovOrigin", v), -1);
    tu_image b;
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    const float *PX = tu_image_f(&b, "fog_P.X");
    double d[3];
    ray_of(0, 0, d);
    assert_close(PX[0], f.C[0] + f.Z[0] * d[0], 0.0625);
    tu_image_free(&b);
    /* A bad origin is a usage error. */
    assert_run(2, "'%s' -o '%s' --fog exp:density=1 --aov P --aov-origin 1,2", in, out);
    assert_contains(tu_err, "--aov-origin '1,2'");
    assert_run(2, "'%s' -o '%s' --fog exp:density=1 --aov P --aov-origin 1,nan,2", in, out);
    /* one that would overflow fog_P to -inf (it wrote -inf with exit 0) */
    assert_run(2, "'%s' -o '%s' --fog exp:density=1 --aov P --aov-origin 1e308,0,0", in, out);
    assert_contains(tu_err, "more than 1e30 from the world's origin");
    assert_run(0, "'%s' -o '%s' --fog exp:density=1 --aov P --aov-origin 0,-1e30,0", in, out);
    free(in);
    free(out);
}

static void test_threads_and_tiles(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 1.0, 2.0, 3.0);
    char *in = write_frame("thr_in.exr", &f, EXR_PIXEL_HALF, NULL);
    char *o1 = tu_path("thr_1.exr"), *o2 = tu_path("thr_2.exr"), *o3 = tu_path("thr_3.exr");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.03 --threads 1 " ALL, in, o1);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.03 --threads 2 " ALL, in, o2);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.03 --threads 3 " ALL, in, o3);
    assert_int_equal(tu_compare_files(o1, o2, -1, NULL), 0);
    assert_int_equal(tu_compare_files(o1, o3, -1, NULL), 0);
    /* Tiled 8x8 (tiles cut the AOV planes too), against the scanline result. */
    tu_part p;
    frame_part(&p, &f, EXR_PIXEL_HALF, NULL);
    p.tile = 8;
    char *tin = tu_path("thr_tiled.exr"), *tout = tu_path("thr_tiled_out.exr");
    assert_int_equal(tu_write_exr(tin, &p, 1), 0);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.03 --threads 2 " ALL, tin, tout);
    tu_image a, b;
    assert_int_equal(tu_read_image(o1, 0, &a), 0);
    assert_int_equal(tu_read_image(tout, 0, &b), 0);
    assert_true(b.tiled);
    for (int c = 0; c < 14; ++c)
        assert_int_equal(tu_compare_channel(&a, &b, AOV_CH[c], 0.0, 0), 0);
    tu_image_free(&a);
    tu_image_free(&b);
    free(in);
    free(o1);
    free(o2);
    free(o3);
    free(tin);
    free(tout);
}

/* A two-part file: only the colour part gets the AOVs; the other part
 * streams through bit for bit. */
static void test_multipart(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.0, 0.0, 0.0);
    tu_part parts[2];
    tu_part_init(&parts[0], W, H);
    parts[0].name = "other";
    tu_part_add(&parts[0], "N.X", EXR_PIXEL_FLOAT, f.NX);
    tu_part_add_uint(&parts[0], "id", f.id);
    frame_part(&parts[1], &f, EXR_PIXEL_HALF, NULL);
    parts[1].name = "rgba";
    char *in = tu_path("mp_in.exr"), *out = tu_path("mp_out.exr");
    assert_int_equal(tu_write_exr(in, parts, 2), 0);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov T,distance --depth-channel rgba.Z",
               in, out);
    assert_int_equal(tu_nparts(out), 2);
    tu_image a, b;
    assert_int_equal(tu_read_image(in, 0, &a), 0);
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    assert_int_equal(tu_compare_layout(&a, &b, -1), 0);
    assert_int_equal(tu_compare_channel(&a, &b, "N.X", 0.0, 0), 0);
    assert_int_equal(tu_compare_channel(&a, &b, "id", 0.0, 0), 0);
    tu_image_free(&a);
    tu_image_free(&b);
    assert_int_equal(tu_read_image(out, 1, &b), 0);
    assert_int_equal(b.nch, 7 + 4);
    const float *dist = tu_image_f(&b, "fog_distance.Z");
    assert_non_null(dist);
    assert_non_null(tu_image_f(&b, "fog_T.B"));
    double d[3];
    ray_of(4, 5, d);
    assert_close(dist[5 * W + 4], f.Z[5 * W + 4] * sqrt(d[0] * d[0] + d[1] * d[1] + 1), 1e-4);
    tu_image_free(&b);
    free(in);
    free(out);
}

static void test_name_collision(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.0, 0.0, 0.0);
    char *in = write_frame("clash_in.exr", &f, EXR_PIXEL_FLOAT, "fog_T.G");
    char *out = tu_path("clash_out.exr");
    remove(out);
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --aov fog,T", in, out);
    assert_contains(tu_err, "'fog_T.G'");
    assert_false(tu_exists(out));
    /* No temporary file either: nothing was created. */
    char *dir = tu_path(".");
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "ls -a '%s' | grep -q '^\\.clash_out\\.exr\\.exrfog-'", dir);
    assert_int_not_equal(system(cmd), 0);
    free(dir);
    /* --explain refuses it too; the AOVs that do not clash are fine. */
    assert_run(2, "'%s' --explain --aov T", in);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov fog,P,error,distance", in, out);
    tu_image b;
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    assert_int_equal(tu_compare_channel(&b, &b, "fog_T.G", 0.0, 0), 0);
    tu_image a;
    assert_int_equal(tu_read_image(in, 0, &a), 0);
    assert_int_equal(tu_compare_channel(&a, &b, "fog_T.G", 0.0, 0), 0);
    tu_image_free(&a);
    tu_image_free(&b);
    free(in);
    free(out);
}

static void test_usage_errors(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.0, 0.0, 0.0);
    char *in = write_frame("usage_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *out = tu_path("usage_out.exr");
    remove(out);
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --aov fog,depth", in, out);
    assert_contains(tu_err, "'depth' is not an AOV");
    assert_contains(tu_err, "fog, T, error, P, distance");
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --aov t", in, out);   /* case matters */
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --aov fog,,T", in, out);
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --aov ''", in, out);
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --aov", in, out);
    static const char *const bad_time[] = { "nan", "abc", "", "inf", "-inf", "1e400", "1,2",
                                            "2s" };
    for (size_t k = 0; k < sizeof bad_time / sizeof bad_time[0]; ++k) {
        assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --time '%s'", in, out, bad_time[k]);
        assert_contains(tu_err, "--time");
    }
    assert_false(tu_exists(out));
    /* Good times parse, and do not change a model without velocity. */
    char *o2 = tu_path("usage_out2.exr");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --time -2.5e3", in, out);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05", in, o2);
    tu_image a, b;
    assert_int_equal(tu_read_image(out, 0, &a), 0);
    assert_int_equal(tu_read_image(o2, 0, &b), 0);
    assert_int_equal(tu_compare_channel(&a, &b, "R", 0.0, 0), 0);
    tu_image_free(&a);
    tu_image_free(&b);
    char params[2048];
    assert_int_equal(read_string(out, "exrfog/parameters", params, sizeof params), 0);
    assert_contains(params, "--time -2.5e3");
    /* --help and --explain mention them. */
    assert_run(0, "--help");
    assert_contains(tu_out, "--time T");
    assert_contains(tu_out, "--aov LIST");
    assert_contains(tu_out, "--aov-origin X,Y,Z");
    assert_run(0, "'%s' --explain --time 7 --aov distance,T", in);
    assert_contains(tu_out, "time: 7 s");
    assert_contains(tu_out, "fog_T.R fog_T.G fog_T.B fog_distance.Z");
    free(in);
    free(out);
    free(o2);
}

static char *write_text(const char *name, const char *text)
{
    char *p = tu_path(name);
    assert_int_equal(tu_write_bytes(p, text, strlen(text)), 0);
    return p;
}

static void test_scene_file(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.0, 1.0, 0.0);
    char *in = write_frame("scene_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *out = tu_path("scene_out.exr");
    char *s1 = write_text("s1.json", "{\"aov\": \"fog,T\", \"time\": 1.5, "
                                     "\"fog\": [\"exp:density=0.05\"]}");
    char *s2 = write_text("s2.json", "{\"aov\": [\"P\", \"distance\", \"P\"], "
                                     "\"fog\": [\"exp:density=0.05\"]}");
    assert_run(0, "'%s' -o '%s' --scene '%s'", in, out, s1);
    tu_image b;
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    assert_int_equal(b.nch, 7 + 7);
    assert_non_null(tu_image_f(&b, "fog.A"));
    assert_non_null(tu_image_f(&b, "fog_T.R"));
    tu_image_free(&b);
    assert_run(0, "'%s' --explain --scene '%s'", in, s1);
    assert_contains(tu_out, "time: 1.5 s");
    /* The flag wins over the file's time. */
    assert_run(0, "'%s' --explain --scene '%s' --time -4", in, s1);
    assert_contains(tu_out, "time: -4 s");
    /* An array, duplicates merged; --aov adds to the file's. */
    assert_run(0, "'%s' -o '%s' --scene '%s' --aov error,P", in, out, s2);
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    assert_int_equal(b.nch, 7 + 3 + 1 + 3);
    assert_non_null(tu_image_f(&b, "fog_P.Y"));
    assert_non_null(tu_image_f(&b, "fog_distance.Z"));
    assert_non_null(tu_image_f(&b, "fog_error.G"));
    tu_image_free(&b);
    /* Errors in the file name the key (a scene-file error: exit 1). */
    char *s3 = write_text("s3.json", "{\"aov\": [\"fog\", \"depth\"], \"fog\": [\"exp:density=1\"]}");
    assert_run(1, "'%s' -o '%s' --scene '%s'", in, out, s3);
    assert_contains(tu_err, "aov[1]:");
    assert_contains(tu_err, "'depth' is not an AOV");
    char *s4 = write_text("s4.json", "{\"time\": \"soon\", \"fog\": [\"exp:density=1\"]}");
    assert_run(1, "'%s' -o '%s' --scene '%s'", in, out, s4);
    assert_contains(tu_err, "time: expected a number");
    char *s5 = write_text("s5.json", "{\"aov\": 3, \"fog\": [\"exp:density=1\"]}");
    assert_run(1, "'%s' -o '%s' --scene '%s'", in, out, s5);
    assert_contains(tu_err, "aov: expected");
    free(in);
    free(out);
    free(s1);
    free(s2);
    free(s3);
    free(s4);
    free(s5);
}

/* --time moves a component with velocity=: at time 2 with velocity 1,0,0
 * the fog is the one offset by 2,0,0 at time 0, exactly. The scene file's
 * "time" sets it too, and the flag overrides the file. */
static void test_time_moves_noise(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.0, 1.0, 0.0);
    char *in = write_frame("time_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *a = tu_path("time_a.exr"), *b = tu_path("time_b.exr"), *c = tu_path("time_c.exr");
    const char *base = "noise:density=0.1:scale=3:octaves=2:method=steps:steps=8";
    assert_run(0, "'%s' -o '%s' --fog %s:velocity=1,0,0 --time 2 --aov T", in, a, base);
    assert_run(0, "'%s' -o '%s' --fog %s:offset=2,0,0 --aov T", in, b, base);
    assert_run(0, "'%s' -o '%s' --fog %s:velocity=1,0,0 --aov T", in, c, base);
    tu_image ia, ib, ic;
    assert_int_equal(tu_read_image(a, 0, &ia), 0);
    assert_int_equal(tu_read_image(b, 0, &ib), 0);
    assert_int_equal(tu_read_image(c, 0, &ic), 0);
    assert_int_equal(tu_compare_channel(&ia, &ib, "fog_T.R", 0.0, 0), 0);
    assert_int_equal(tu_compare_channel(&ia, &ib, "R", 0.0, 0), 0);
    const float *ta = tu_image_f(&ia, "fog_T.R"), *tc = tu_image_f(&ic, "fog_T.R");
    long differ = 0;
    for (int i = 0; i < W * H; ++i)
        differ += ta[i] != tc[i];
    assert_true(differ > W * H / 2);
    tu_image_free(&ia);
    tu_image_free(&ic);
    /* The scene file's time, and the flag over it. */
    char *s = write_text("time.json", "{\"time\": 2, \"fog\": [\"noise:density=0.1:scale=3:"
                                      "octaves=2:method=steps:steps=8:velocity=1,0,0\"]}");
    assert_run(0, "'%s' -o '%s' --scene '%s' --aov T", in, c, s);
    assert_int_equal(tu_read_image(c, 0, &ic), 0);
    assert_int_equal(tu_compare_channel(&ib, &ic, "fog_T.R", 0.0, 0), 0);
    tu_image_free(&ic);
    assert_run(0, "'%s' -o '%s' --scene '%s' --time 0 --aov T", in, c, s);
    assert_int_equal(tu_read_image(c, 0, &ic), 0);
    assert_int_not_equal(tu_compare_channel(&ib, &ic, "fog_T.R", 0.0, 0), 0);
    tu_image_free(&ic);
    tu_image_free(&ib);
    free(in);
    free(a);
    free(b);
    free(c);
    free(s);
}

/* The per-pixel error layer of a numerical component: the T layer and
 * the error layer follow the component's own tau and error bound on the
 * ray built here from the geometry, as T = exp(-tau) and
 * min(1, T expm1(err)); a closed-form component beside it adds nothing to
 * the error. */
static void test_error_layer_noise(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.5, 1.0, -1.0);
    char *in = write_frame("err_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *out = tu_path("err_out.exr");
    const char *spec = "noise:density=0.2:scale=4:octaves=3:tol=1e-3";
    assert_run(0, "'%s' -o '%s' --fog %s --fog exp:density=0.01 --aov T,error", in, out, spec);
    ef_fog_component c;
    ef_err err;
    assert_int_equal(ef_fog_parse(spec, NULL, &c, &err), 0);
    assert_non_null(c.model->tau_info);
    tu_image b;
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    const float *T = tu_image_f(&b, "fog_T.G"), *E = tu_image_f(&b, "fog_error.G");
    long bad = 0, positive = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int i = y * W + x;
            if (is_sky(&f, i))
                continue;
            double d[3];
            ray_of(x, y, d);
            const double len = sqrt(d[0] * d[0] + d[1] * d[1] + 1.0);
            ef_ray r;
            for (int k = 0; k < 3; ++k) {
                r.org[k] = f.C[k];
                r.dir[k] = d[k] / len;
            }
            r.dist = f.Z[i] * len;
            r.planar = f.Z[i];
            double tau[3];
            ef_tau_info info;
            c.model->tau_info(&c, &r, tau, &info);
            const double Tw = exp(-tau[1] - 0.01 * r.dist);
            const double Ew = fmin(1.0, Tw * expm1(info.err[1]));
            bad += check_value("fog_T.G", x, y, T[i], Tw, 1e-6 * Tw + 1e-9);
            bad += check_value("fog_error.G", x, y, E[i], Ew, 1e-6 * Ew + 1e-15);
            positive += E[i] > 0;
            bad += !(E[i] >= 0 && E[i] <= 1);
        }
    assert_int_equal(bad, 0);
    assert_true(positive > 0);
    tu_image_free(&b);
    ef_fog_free(&c);
    free(in);
    free(out);
}

/* --stats: one line per numerical component, counting the pixels whose
 * fog was evaluated (kept sky pixels are not), the same for any thread
 * count; none for closed forms. */
static void test_stats(void **state)
{
    (void) state;
    static frame f;
    frame_make(&f, 0.0, 1.0, 0.0);
    char *in = write_frame("stats_in.exr", &f, EXR_PIXEL_FLOAT, NULL);
    char *out = tu_path("stats_out.exr");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --stats", in, out);
    assert_contains(tu_err, "exrfog: stats: wall");
    assert_null(strstr(tu_err, "fog[0]"));
    long nsky = 0;
    for (int i = 0; i < W * H; ++i)
        nsky += is_sky(&f, i);
    const char *noise = "noise:density=0.1:scale=3:octaves=3";
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --fog %s --sky keep --stats --threads 1",
               in, out, noise);
    char want[256], line1[1024], line2[1024];
    snprintf(want, sizeof want, "fog[1] %s: %ld pixels; per pixel: noise evaluations mean ", noise,
             (long) (W * H - nsky));
    assert_contains(tu_err, want);
    assert_null(strstr(tu_err, "fog[0]"));
    assert_contains(tu_err, "cells walked mean");
    assert_contains(tu_err, "octaves dropped mean");
    assert_contains(tu_err, "error estimate (tau) max");
    snprintf(line1, sizeof line1, "%s", strstr(tu_err, "fog[1]"));
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --fog %s --sky keep --stats --threads 2",
               in, out, noise);
    snprintf(line2, sizeof line2, "%s", strstr(tu_err, "fog[1]"));
    assert_string_equal(line1, line2);
    /* With --sky fog every pixel counts. */
    assert_run(0, "'%s' -o '%s' --fog %s --stats", in, out, noise);
    snprintf(want, sizeof want, "fog[0] %s: %d pixels;", noise, W * H);
    assert_contains(tu_err, want);
    /* What the error output is, pixel by pixel (the man page's kinds): the
     * default method's node plans are estimates, and where it drops
     * octaves statistical ones, so only the sky's pixels have a bound
     * (with no falloff a sky ray is opaque: T = 0 exactly); method=steps
     * bounds every pixel; with the clamp able to bind (contrast 1.5) every
     * ground pixel's error involves the clamp's statistics. */
    {
        long b = -1, q = -1, st = -1;
        const char *at = strstr(tu_err, "the error output a bound on ");
        assert_true(at && sscanf(at, "the error output a bound on %ld pixels, a quadrature's "
                                     "estimate on %ld, a statistical estimate on %ld",
                                 &b, &q, &st) == 3);
        assert_int_equal(b, nsky);
        assert_int_equal(q + st, W * H - nsky);
    }
    assert_run(0, "'%s' -o '%s' --fog %s:method=steps --stats", in, out, noise);
    snprintf(want, sizeof want,
             "the error output a bound on %d pixels, a quadrature's estimate on 0, a statistical "
             "estimate on 0 ", W * H);
    assert_contains(tu_err, want);
    assert_run(0, "'%s' -o '%s' --fog %s:contrast=1.5 --stats", in, out, noise);
    snprintf(want, sizeof want,
             "the error output a bound on %ld pixels, a quadrature's estimate on 0, a statistical "
             "estimate on %ld ", nsky, (long) (W * H) - nsky);
    assert_contains(tu_err, want);
    /* The costliest pixel re-timed: measured, and no more than the
     * slowest single timing it was taken from allows (its least of three
     * is at most that one; the plain maximum caps a pixel by its span's
     * CPU time, so allow a factor for that cap). */
    const char *rt = strstr(tu_err, "costliest pixel re-timed ");
    assert_non_null(rt);
    const char *mx = strstr(tu_err, "us, max ");
    assert_non_null(mx);
    const double retimed = atof(rt + strlen("costliest pixel re-timed ")),
                 plain = atof(mx + strlen("us, max "));
    assert_true(retimed > 0 && retimed <= 2 * plain);
    free(in);
    free(out);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_values_exp),
        cmocka_unit_test(test_sky_policies),
        cmocka_unit_test(test_half_and_float_types),
        cmocka_unit_test(test_origin_far_from_zero),
        cmocka_unit_test(test_threads_and_tiles),
        cmocka_unit_test(test_multipart),
        cmocka_unit_test(test_name_collision),
        cmocka_unit_test(test_usage_errors),
        cmocka_unit_test(test_scene_file),
        cmocka_unit_test(test_time_moves_noise),
        cmocka_unit_test(test_error_layer_noise),
        cmocka_unit_test(test_stats),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
