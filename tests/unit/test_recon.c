/* ef_reconstruct / ef_ray_at_distance against reconstructions done by hand
 * on a 90-degree camera 1e7 units from the origin. */
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


/* Camera axes in world: x -> (0,0,1), y -> (0,1,0), z (forward) -> (-1,0,0),
 * at (1e7, -3e7, 2e7); hfov 90 (tan 45 = 1) on a 2x2 display, so pixel
 * (0,0) has camera ray (-0.5, 0.5, 1) and world ray (-1, 0.5, -0.5). */
static const double CPOS[3] = {1e7, -3e7, 2e7};

static void make_camera(ef_camera *cam)
{
    const double c2w[16] = {0, 0, 1, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1e7, -3e7, 2e7, 1};
    ef_cam_meta m;
    ef_cam_flags fl;
    ef_err err = {0};
    memset(&fl, 0, sizeof fl);
    ef_cam_meta_init(&m, 0, 0, 1, 1);
    fl.c2w.set = 1;
    memcpy(fl.c2w.v.m, c2w, sizeof c2w);
    fl.fov.set = 1;
    fl.fov.v = 90.0;
    assert_int_equal(ef_camera_resolve(&m, &fl, cam, &err), 0);
}

static void make_conv(const ef_camera *cam, ef_depth_conv *conv, ef_depth_mode mode)
{
    ef_err err = {0};
    assert_int_equal(ef_depth_conv_init(conv, mode, cam, &err), 0);
}

/* r->dir * r->dist equals the expected camera-relative offset to 1e-12. */
static void assert_offset(const ef_ray *r, double x, double y, double z)
{
    const double len = sqrt(x * x + y * y + z * z);
    assert_close(r->dist, len, 1e-12 * len);
    assert_close(r->dir[0] * r->dist, x, 1e-12 * len);
    assert_close(r->dir[1] * r->dist, y, 1e-12 * len);
    assert_close(r->dir[2] * r->dist, z, 1e-12 * len);
    assert_close(r->dir[0] * r->dir[0] + r->dir[1] * r->dir[1] + r->dir[2] * r->dir[2],
                 1.0, 1e-15);
}

static void test_planar(void **state)
{
    (void)state;
    ef_camera cam;
    ef_depth_conv conv;
    ef_ray r;
    make_camera(&cam);
    assert_true(cam.pos[0] == CPOS[0] && cam.pos[1] == CPOS[1] && cam.pos[2] == CPOS[2]);
    make_conv(&cam, &conv, EF_DEPTH_PLANAR);

    /* Pixel (0,0), planar 4: camera (-2, 2, 4) = world offset (-4, 2, -2). */
    assert_int_equal(ef_reconstruct(&cam, &conv, 0, 0, 4.0, &r), 0);
    assert_offset(&r, -4, 2, -2);
    assert_close(r.planar, 4.0, 1e-15);
    /* Pixel (1,1), planar 10: camera (5, -5, 10) = world (-10, -5, 5). */
    assert_int_equal(ef_reconstruct(&cam, &conv, 1, 1, 10.0, &r), 0);
    assert_offset(&r, -10, -5, 5);
    assert_close(r.planar, 10.0, 1e-14);
    /* Pixel (1,0), planar 1: camera (0.5, 0.5, 1) = world (-1, 0.5, 0.5). */
    assert_int_equal(ef_reconstruct(&cam, &conv, 1, 0, 1.0, &r), 0);
    assert_offset(&r, -1, 0.5, 0.5);

    /* The world point stays exact next to a 1e7 camera position. */
    assert_int_equal(ef_reconstruct(&cam, &conv, 0, 0, 4.0, &r), 0);
    assert_close(cam.pos[0] + r.dir[0] * r.dist, 1e7 - 4, 1e-8);
    assert_close(cam.pos[1] + r.dir[1] * r.dist, -3e7 + 2, 1e-8);
    assert_close(cam.pos[2] + r.dir[2] * r.dist, 2e7 - 2, 1e-8);
}

static void test_radial(void **state)
{
    (void)state;
    ef_camera cam;
    ef_depth_conv conv;
    ef_ray r;
    make_camera(&cam);
    make_conv(&cam, &conv, EF_DEPTH_RADIAL);

    /* Pixel (0,0), radial 3: |(-0.5,0.5,1)| = sqrt(1.5), so planar
     * 3 / sqrt(1.5) = sqrt(6) and world offset sqrt(6) (-1, 0.5, -0.5). */
    const double s6 = sqrt(6.0);
    assert_int_equal(ef_reconstruct(&cam, &conv, 0, 0, 3.0, &r), 0);
    assert_offset(&r, -s6, 0.5 * s6, -0.5 * s6);
    assert_close(r.dist, 3.0, 1e-15);
    assert_close(r.planar, s6, 1e-14);

    /* Planar 2 and radial sqrt(6) are the same point: camera (-1, 1, 2). */
    ef_depth_conv planar;
    ef_ray rp;
    make_conv(&cam, &planar, EF_DEPTH_PLANAR);
    assert_int_equal(ef_reconstruct(&cam, &planar, 0, 0, 2.0, &rp), 0);
    assert_int_equal(ef_reconstruct(&cam, &conv, 0, 0, s6, &r), 0);
    assert_offset(&rp, -2, 1, -1);
    assert_offset(&r, -2, 1, -1);
    assert_close(r.planar, 2.0, 1e-14);
}

static void test_buffer_mode(void **state)
{
    (void)state;
    ef_camera cam;
    ef_depth_conv conv;
    ef_ray r;
    make_camera(&cam);
    /* 1/z = 0.25 is planar 4. */
    make_conv(&cam, &conv, EF_DEPTH_INVERSE);
    assert_int_equal(ef_reconstruct(&cam, &conv, 0, 0, 0.25, &r), 0);
    assert_offset(&r, -4, 2, -2);
    /* reversed-infinite with near 2: v = 0.5 is planar 4. */
    cam.near_.set = 1;
    cam.near_.v = 2.0;
    make_conv(&cam, &conv, EF_DEPTH_REVERSED_INFINITE);
    assert_int_equal(ef_reconstruct(&cam, &conv, 0, 0, 0.5, &r), 0);
    assert_offset(&r, -4, 2, -2);
}

static void test_sky(void **state)
{
    (void)state;
    ef_camera cam;
    ef_depth_conv conv;
    ef_ray r;
    make_camera(&cam);
    const double l = sqrt(1.5);
    const ef_depth_mode modes[] = {EF_DEPTH_PLANAR, EF_DEPTH_RADIAL};
    const double skies[] = {0.0, -1.0, NAN, INFINITY, 1e10};
    for (int m = 0; m < 2; ++m)
        for (int i = 0; i < 5; ++i) {
            make_conv(&cam, &conv, modes[m]);
            assert_int_equal(ef_reconstruct(&cam, &conv, 0, 0, skies[i], &r), 1);
            assert_true(r.dist == INFINITY && r.planar == INFINITY);
            assert_close(r.dir[0], -1 / l, 1e-15);
            assert_close(r.dir[1], 0.5 / l, 1e-15);
            assert_close(r.dir[2], -0.5 / l, 1e-15);
        }
}

static void test_ray_at_distance(void **state)
{
    (void)state;
    ef_camera cam;
    ef_ray r;
    make_camera(&cam);
    const double l = sqrt(1.5);
    /* Radial 6 on pixel (0,0): planar 6 / sqrt(1.5) = sqrt(24). */
    ef_ray_at_distance(&cam, 0, 0, 6.0, &r);
    assert_close(r.dist, 6.0, 0.0);
    assert_close(r.planar, sqrt(24.0), 1e-14);
    assert_close(r.dir[0], -1 / l, 1e-15);
    assert_close(r.dir[1], 0.5 / l, 1e-15);
    assert_close(r.dir[2], -0.5 / l, 1e-15);
    ef_ray_at_distance(&cam, 0, 0, INFINITY, &r);
    assert_true(r.dist == INFINITY && r.planar == INFINITY);
    assert_close(r.dir[0], -1 / l, 1e-15);
    ef_ray_at_distance(&cam, 1, 1, 0.0, &r);
    assert_true(r.dist == 0.0 && r.planar == 0.0);
    assert_close(r.dir[1], -0.5 / l, 1e-15);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_planar),
        cmocka_unit_test(test_radial),
        cmocka_unit_test(test_buffer_mode),
        cmocka_unit_test(test_sky),
        cmocka_unit_test(test_ray_at_distance),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
