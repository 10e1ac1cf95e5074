/* Depth modes. The key property: for each mode, a depth image encoded in
 * that mode (with forward formulas written out here, not the library's)
 * rebuilds the same world positions to 1e-9 relative, in double. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "tassert.h"

#include "camera.h"
#include "depth.h"
#include "recon.h"

#define PI 3.14159265358979323846



static const double NEAR_ = 0.5, FAR_ = 200.0;
static const double HFOV = 62.5;
static const int X0 = 5, Y0 = -3, X1 = 84, Y1 = 46;
static const double PA = 1.1;
/* Lens shift and scales of the projection-matrix camera. */
static const double SHX = 0.1, SHY = -0.05, SCX = 1.6, SCY = 2.2;

/* The scene camera: rotated (with a handedness flip, as in real files) and
 * far from the origin. R rows are the camera axes in world space. */
typedef struct scene {
    double R[9], C[3], w2c[16];
    int projection; /* 0: fov camera; 1: screen matrix with lens shift */
} scene;

static void make_scene(scene *s, int projection)
{
    const double a = 30.0 * PI / 180.0, b = -20.0 * PI / 180.0;
    const double rx[9] = {1, 0, 0, 0, cos(b), sin(b), 0, -sin(b), cos(b)};
    const double ry[9] = {cos(a), 0, -sin(a), 0, 1, 0, sin(a), 0, cos(a)};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            s->R[3 * i + j] = rx[3 * i] * ry[j] + rx[3 * i + 1] * ry[3 + j]
                            + rx[3 * i + 2] * ry[6 + j];
    for (int j = 0; j < 3; ++j)
        s->R[6 + j] = -s->R[6 + j];
    s->C[0] = 120.5;
    s->C[1] = -40.25;
    s->C[2] = 1.0e4;
    /* w2c = [R^T ; -C R^T] for an orthonormal R. */
    memset(s->w2c, 0, sizeof s->w2c);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            s->w2c[4 * i + j] = s->R[3 * j + i];
    for (int j = 0; j < 3; ++j)
        s->w2c[12 + j] = -(s->C[0] * s->R[3 * j] + s->C[1] * s->R[3 * j + 1]
                           + s->C[2] * s->R[3 * j + 2]);
    s->w2c[15] = 1.0;
    s->projection = projection;
}

/* The camera the library resolves for the scene (near/far as flags). */
static void resolve(const scene *s, ef_camera *cam, int with_clip)
{
    ef_cam_meta m;
    ef_cam_flags fl;
    ef_err err = {0};
    memset(&fl, 0, sizeof fl);
    ef_cam_meta_init(&m, X0, Y0, X1, Y1);
    m.pixel_aspect = PA;
    m.w2c.set = 1;
    memcpy(m.w2c.v.m, s->w2c, sizeof s->w2c);
    if (s->projection) {
        /* camera->screen with shift, then world->screen = w2c . that. */
        const double P[16] = {SCX, 0, 0, 0, 0, SCY, 0, 0, SHX, SHY, 1.01, 1, 0, 0, -0.3, 0};
        m.w2screen.set = 1;
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) {
                double acc = 0;
                for (int k = 0; k < 4; ++k)
                    acc += s->w2c[4 * i + k] * P[4 * k + j];
                m.w2screen.v.m[4 * i + j] = acc;
            }
    } else {
        fl.fov.set = 1;
        fl.fov.v = HFOV;
    }
    if (with_clip) {
        fl.near_.set = fl.far_.set = 1;
        fl.near_.v = NEAR_;
        fl.far_.v = FAR_;
    }
    if (ef_camera_resolve(&m, &fl, cam, &err) != 0) {
        print_error("%s\n", err.msg);
        fail();
    }
}

/* Camera-space ray of pixel (x, y), from the reference-doc formulas. */
static void pixel_dir(const scene *s, int x, int y, double d[3])
{
    const double W = X1 - X0 + 1, H = Y1 - Y0 + 1;
    const double u = (x + 0.5 - X0) / W, v = (y + 0.5 - Y0) / H;
    if (s->projection) {
        d[0] = (2 * u - 1 - SHX) / SCX;
        d[1] = (1 - 2 * v - SHY) / SCY;
    } else {
        const double t = tan(HFOV * PI / 360.0);
        d[0] = t * (2 * u - 1);
        d[1] = t * (1 - 2 * v) * H / (W * PA);
    }
    d[2] = 1.0;
}

/* Stored value of a world point in mode m: projections written out. */
static double encode(const scene *s, ef_depth_mode mode, const double P[3])
{
    const double n = NEAR_, f = FAR_;
    /* Planar depth: z of (P, 1) . worldToCamera. */
    const double z = P[0] * s->w2c[2] + P[1] * s->w2c[6] + P[2] * s->w2c[10] + s->w2c[14];
    const double dx = P[0] - s->C[0], dy = P[1] - s->C[1], dz = P[2] - s->C[2];
    const double z_eye = -z; /* GL eye space looks down -Z */
    switch (mode) {
    case EF_DEPTH_PLANAR: return z;
    case EF_DEPTH_RADIAL: return sqrt(dx * dx + dy * dy + dz * dz);
    case EF_DEPTH_INVERSE: return 1.0 / z;
    case EF_DEPTH_NORMALIZED: return (z - n) / (f - n);
    case EF_DEPTH_GL_NDC:
    case EF_DEPTH_GL_WINDOW: {
        /* glFrustum row 3 and 4: clip z = -(f+n)/(f-n) z_eye - 2fn/(f-n), clip w = -z_eye */
        const double cz = -(f + n) / (f - n) * z_eye - 2 * f * n / (f - n);
        const double ndc = cz / -z_eye;
        return mode == EF_DEPTH_GL_NDC ? ndc : 0.5 * ndc + 0.5; /* glDepthRange(0,1) */
    }
    case EF_DEPTH_ZERO_ONE: /* D3D PerspectiveFovLH: _33 = f/(f-n), _43 = -nf/(f-n), w = z */
        return (f / (f - n) * z - n * f / (f - n)) / z;
    case EF_DEPTH_REVERSED: /* RH reversed: P33 = n/(f-n), P34 = nf/(f-n), w = -z_eye */
        return (n / (f - n) * z_eye + n * f / (f - n)) / -z_eye;
    case EF_DEPTH_REVERSED_INFINITE: /* P33 = 0, P34 = n */
        return n / -z_eye;
    default: return NAN;
    }
}

static void check_roundtrip(int projection)
{
    scene s;
    ef_camera cam;
    make_scene(&s, projection);
    resolve(&s, &cam, 1);
    const double ratio = 0.9 * FAR_ / (1.5 * NEAR_);
    for (int mode = 0; mode < EF_DEPTH_MODE_COUNT; ++mode) {
        ef_depth_conv conv;
        ef_err err = {0};
        assert_int_equal(ef_depth_conv_init(&conv, (ef_depth_mode)mode, &cam, &err), 0);
        int count = 0;
        for (int y = Y0; y <= Y1; y += 5)
            for (int x = X0; x <= X1; x += 7) {
                /* Planar depth from 1.5 near to 0.9 far, geometric, varied per pixel. */
                const double frac = ((x * 7 + y * 13 + 1000) % 17) / 16.0;
                const double d = 1.5 * NEAR_ * pow(ratio, frac);
                double dc[3], P[3];
                pixel_dir(&s, x, y, dc);
                for (int j = 0; j < 3; ++j)
                    P[j] = s.C[j] + d * (dc[0] * s.R[j] + dc[1] * s.R[3 + j] + dc[2] * s.R[6 + j]);
                const double v = encode(&s, (ef_depth_mode)mode, P);
                ef_ray r;
                if (ef_reconstruct(&cam, &conv, x, y, v, &r) != 0) {
                    print_error("mode %s: pixel %d,%d value %.17g read as sky\n",
                                ef_depth_mode_name((ef_depth_mode)mode), x, y, v);
                    fail();
                }
                double e2 = 0, l2 = 0;
                for (int j = 0; j < 3; ++j) {
                    const double q = cam.pos[j] + r.dir[j] * r.dist;
                    e2 += (q - P[j]) * (q - P[j]);
                    l2 += (P[j] - s.C[j]) * (P[j] - s.C[j]);
                }
                if (!(sqrt(e2) <= 1e-9 * sqrt(l2))) {
                    print_error("mode %s, camera %d: pixel %d,%d depth %g: error %g of %g\n",
                                ef_depth_mode_name((ef_depth_mode)mode), projection, x, y,
                                d, sqrt(e2), sqrt(l2));
                    fail();
                }
                assert_close(r.planar, d, 1e-9 * d);
                assert_close(r.dist, sqrt(l2), 1e-9 * sqrt(l2));
                ++count;
            }
        assert_int_equal(count, 12 * 10);
    }
}

static void test_roundtrip_fov_camera(void **state)
{
    (void)state;
    check_roundtrip(0);
}

static void test_roundtrip_projection_camera(void **state)
{
    (void)state;
    check_roundtrip(1);
}

static void conv_for(ef_depth_conv *conv, ef_depth_mode mode)
{
    scene s;
    ef_camera cam;
    ef_err err = {0};
    make_scene(&s, 0);
    resolve(&s, &cam, 1);
    assert_int_equal(ef_depth_conv_init(conv, mode, &cam, &err), 0);
}

static int sky(ef_depth_mode mode, double v)
{
    ef_depth_conv conv;
    double d;
    conv_for(&conv, mode);
    return ef_depth_linearize(&conv, v, &d);
}

static double lin(ef_depth_mode mode, double v)
{
    ef_depth_conv conv;
    double d = NAN;
    conv_for(&conv, mode);
    assert_int_equal(ef_depth_linearize(&conv, v, &d), 0);
    return d;
}

/* Clip-plane values by hand: near maps to n, the buffer midpoints to the
 * harmonic-mean-like 2fn/(f+n). */
static void test_known_values(void **state)
{
    (void)state;
    const double n = NEAR_, f = FAR_;
    assert_close(lin(EF_DEPTH_PLANAR, 3.25), 3.25, 0.0);
    assert_close(lin(EF_DEPTH_RADIAL, 3.25), 3.25, 0.0);
    assert_close(lin(EF_DEPTH_INVERSE, 0.25), 4.0, 0.0);
    assert_close(lin(EF_DEPTH_NORMALIZED, 0.0), n, 0.0);
    assert_close(lin(EF_DEPTH_NORMALIZED, 0.5), (n + f) / 2, 1e-13);
    assert_close(lin(EF_DEPTH_GL_NDC, -1.0), n, 1e-14);
    assert_close(lin(EF_DEPTH_GL_NDC, 0.0), 2 * f * n / (f + n), 1e-13);
    assert_close(lin(EF_DEPTH_GL_WINDOW, 0.0), n, 1e-14);
    assert_close(lin(EF_DEPTH_GL_WINDOW, 0.5), 2 * f * n / (f + n), 1e-13);
    assert_close(lin(EF_DEPTH_ZERO_ONE, 0.0), n, 1e-14);
    assert_close(lin(EF_DEPTH_REVERSED, 1.0), n, 1e-14);
    assert_close(lin(EF_DEPTH_REVERSED_INFINITE, 1.0), n, 0.0);
    assert_close(lin(EF_DEPTH_REVERSED_INFINITE, 0.25), 4 * n, 0.0);

    /* The seed paper's P33, P34. */
    ef_depth_conv conv;
    conv_for(&conv, EF_DEPTH_GL_NDC);
    assert_close(conv.p33, (f + n) / (n - f), 1e-15);
    assert_close(conv.p34, -2 * f * n / (f - n), 1e-15);
    assert_close(conv.near_, n, 0.0);
    assert_close(conv.far_, f, 0.0);
    assert_string_equal(conv.src_clip, "flags --near/--far");
}

static void test_sky_rules(void **state)
{
    (void)state;
    const double n = NEAR_, f = FAR_;
    for (int m = 0; m < EF_DEPTH_MODE_COUNT; ++m) {
        assert_int_equal(sky((ef_depth_mode)m, NAN), 1);
        assert_int_equal(sky((ef_depth_mode)m, INFINITY), 1);
        assert_int_equal(sky((ef_depth_mode)m, -INFINITY), 1);
    }
    const ef_depth_mode linear[] = {EF_DEPTH_PLANAR, EF_DEPTH_RADIAL};
    for (int i = 0; i < 2; ++i) {
        assert_int_equal(sky(linear[i], 0.0), 1);
        assert_int_equal(sky(linear[i], -0.0), 1);
        assert_int_equal(sky(linear[i], -5.0), 1);
        assert_int_equal(sky(linear[i], 1e9), 1);
        assert_int_equal(sky(linear[i], 1e10), 1);  /* Cycles background */
        assert_int_equal(sky(linear[i], 1e30), 1);  /* OIIO flattened deep */
        assert_int_equal(sky(linear[i], 9.99e8), 0);
        assert_int_equal(sky(linear[i], 1e-6), 0);
    }
    /* inverse: 0 is Nuke's background; 5e-10 is 2e9 away. */
    assert_int_equal(sky(EF_DEPTH_INVERSE, 0.0), 1);
    assert_int_equal(sky(EF_DEPTH_INVERSE, -0.5), 1);
    assert_int_equal(sky(EF_DEPTH_INVERSE, 5e-10), 1);
    assert_int_equal(sky(EF_DEPTH_INVERSE, 1e-8), 0);
    /* far plane of the buffer modes */
    assert_int_equal(sky(EF_DEPTH_NORMALIZED, 1.0), 1);
    assert_int_equal(sky(EF_DEPTH_NORMALIZED, 1.5), 1);
    assert_int_equal(sky(EF_DEPTH_NORMALIZED, 0.999), 0);
    /* below near, normalized goes to d <= 0 */
    assert_int_equal(sky(EF_DEPTH_NORMALIZED, -1.5 * n / (f - n)), 1);
    assert_int_equal(sky(EF_DEPTH_GL_NDC, 1.0), 1);
    assert_int_equal(sky(EF_DEPTH_GL_NDC, 2.0), 1);
    assert_int_equal(sky(EF_DEPTH_GL_NDC, 0.999), 0);
    assert_int_equal(sky(EF_DEPTH_GL_WINDOW, 1.0), 1);
    assert_int_equal(sky(EF_DEPTH_GL_WINDOW, 0.999), 0);
    assert_int_equal(sky(EF_DEPTH_ZERO_ONE, 1.0), 1);
    assert_int_equal(sky(EF_DEPTH_ZERO_ONE, 0.999), 0);
    assert_int_equal(sky(EF_DEPTH_REVERSED, 0.0), 1);
    assert_int_equal(sky(EF_DEPTH_REVERSED, -0.1), 1);
    assert_int_equal(sky(EF_DEPTH_REVERSED, 0.001), 0);
    assert_int_equal(sky(EF_DEPTH_REVERSED_INFINITE, 0.0), 1);
    assert_int_equal(sky(EF_DEPTH_REVERSED_INFINITE, -1.0), 1);
    /* n / v >= 1e9 once linearised */
    assert_int_equal(sky(EF_DEPTH_REVERSED_INFINITE, n / 2e9), 1);
    assert_int_equal(sky(EF_DEPTH_REVERSED_INFINITE, n / 5e8), 0);

    /* A sky pixel reconstructs to infinity along the unit pixel ray. */
    scene s;
    ef_camera cam;
    ef_depth_conv conv;
    ef_ray r;
    make_scene(&s, 0);
    resolve(&s, &cam, 1);
    conv_for(&conv, EF_DEPTH_PLANAR);
    assert_int_equal(ef_reconstruct(&cam, &conv, 30, 10, 0.0, &r), 1);
    assert_true(isinf(r.dist) && r.dist > 0 && isinf(r.planar) && r.planar > 0);
    double dc[3], w[3];
    pixel_dir(&s, 30, 10, dc);
    for (int j = 0; j < 3; ++j)
        w[j] = dc[0] * s.R[j] + dc[1] * s.R[3 + j] + dc[2] * s.R[6 + j];
    const double len = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    for (int j = 0; j < 3; ++j)
        assert_close(r.dir[j], w[j] / len, 1e-14);
}

static void test_conv_init_errors(void **state)
{
    (void)state;
    scene s;
    ef_camera cam;
    ef_depth_conv conv;
    ef_err err = {0};
    make_scene(&s, 0);
    resolve(&s, &cam, 0); /* fov camera: no clip planes anywhere */
    assert_false(cam.near_.set);

    /* Modes without clip planes are fine. */
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_PLANAR, &cam, &err), 0);
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_RADIAL, &cam, &err), 0);
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_INVERSE, &cam, &err), 0);
    /* Every other mode names the flags. */
    for (int m = EF_DEPTH_NORMALIZED; m < EF_DEPTH_MODE_COUNT; ++m) {
        err.msg[0] = '\0';
        assert_int_equal(ef_depth_conv_init(&conv, (ef_depth_mode)m, &cam, &err), -1);
        assert_contains(err.msg, "--near");
        assert_contains(err.msg, ef_depth_mode_name((ef_depth_mode)m));
        if (m != EF_DEPTH_REVERSED_INFINITE)
            assert_contains(err.msg, "--far");
    }
    /* Near only: enough for reversed-infinite, not for the others. */
    cam.near_.set = 1;
    cam.near_.v = 0.1;
    cam.src_near = "flag --near";
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_REVERSED_INFINITE, &cam, &err), 0);
    assert_close(conv.near_, 0.1, 0.0);
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_ZERO_ONE, &cam, &err), -1);
    assert_contains(err.msg, "--far");
    /* Not 0 < near < far. */
    cam.far_.set = 1;
    cam.far_.v = 0.05;
    cam.src_far = "flag --far";
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_GL_NDC, &cam, &err), -1);
    assert_contains(err.msg, "near < far");
    assert_contains(err.msg, "--near");
    cam.far_.v = 0.1;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_NORMALIZED, &cam, &err), -1);
    cam.far_.v = 10.0;
    cam.near_.v = 0.0;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_REVERSED, &cam, &err), -1);
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_REVERSED_INFINITE, &cam, &err), -1);
    cam.near_.v = -1.0;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_ZERO_ONE, &cam, &err), -1);
    cam.near_.v = NAN;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_ZERO_ONE, &cam, &err), -1);
    cam.near_.v = 1.0;
    cam.far_.v = INFINITY;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_ZERO_ONE, &cam, &err), -1);
    cam.far_.v = 10.0;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_ZERO_ONE, &cam, &err), 0);
}

static void test_mode_names(void **state)
{
    (void)state;
    const char *names[] = {"planar", "radial", "inverse", "normalized", "gl-ndc",
                           "gl-window", "zero-one", "reversed", "reversed-infinite"};
    assert_int_equal(sizeof names / sizeof names[0], EF_DEPTH_MODE_COUNT);
    for (int i = 0; i < EF_DEPTH_MODE_COUNT; ++i) {
        ef_depth_mode m = EF_DEPTH_MODE_COUNT;
        assert_int_equal(ef_depth_mode_parse(names[i], &m), 0);
        assert_int_equal(m, i);
        assert_string_equal(ef_depth_mode_name((ef_depth_mode)i), names[i]);
    }
    ef_depth_mode m;
    assert_int_equal(ef_depth_mode_parse("auto", &m), -1);
    assert_int_equal(ef_depth_mode_parse("Planar", &m), -1);
    assert_int_equal(ef_depth_mode_parse("", &m), -1);
    assert_non_null(ef_depth_mode_name(EF_DEPTH_MODE_COUNT));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_roundtrip_fov_camera),
        cmocka_unit_test(test_roundtrip_projection_camera),
        cmocka_unit_test(test_known_values),
        cmocka_unit_test(test_sky_rules),
        cmocka_unit_test(test_conv_init_errors),
        cmocka_unit_test(test_mode_names),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
