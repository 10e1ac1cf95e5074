/* Real renderer and compositor outputs from public projects
 * (../shared/real-exr, see its README.md): camera metadata, channel
 * finding and full fog runs. Expected values come from the files'
 * documented cameras (hand-derived below) and forward formulas; the code
 * under test only produces the values that are checked.
 *
 * Skipped (exit 77) when the folder is absent. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "tassert.h"

#include "camera.h"
#include "depth.h"
#include "exr_io.h"
#include "recon.h"
#include "testutil.h"



static const char *real_dir;

/* Identity pose (camera at the origin looking down +Z) and a 40 degree
 * lens, for files without a camera. */
#define NO_CAMERA_FLAGS "--camera-to-world 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 40"



/* The path of a real file; skips the test when that one file is missing. */
static char *real(const char *name)
{
    size_t n = strlen(real_dir) + strlen(name) + 2;
    char *p = malloc(n);
    assert_non_null(p);
    snprintf(p, n, "%s/%s", real_dir, name);
    if (!tu_exists(p)) {
        print_message("%s is absent: skipped\n", p);
        free(p);
        skip();
    }
    return p;
}

/* Camera of one part through the library, no flags. */
static void resolve(const char *path, int part, ef_cam_meta *meta, ef_camera *cam)
{
    ef_exr_file f;
    ef_err err = {0};
    ef_cam_flags flags;
    memset(&flags, 0, sizeof flags);
    if (ef_exr_open(path, &f, &err) || ef_exr_read_cam_meta(&f, part, meta, &err) ||
        ef_camera_resolve(meta, &flags, cam, &err)) {
        print_error("%s part %d: %s\n", path, part, err.msg);
        ef_exr_close(&f);
        fail();
    }
    ef_exr_close(&f);
}

/* A float attribute read straight from the header. */
static float header_float(const char *path, int part, const char *name)
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    const exr_attribute_t *a;
    assert_int_equal(exr_start_read(&f, path, &init), EXR_ERR_SUCCESS);
    assert_int_equal(exr_get_attribute_by_name(f, part, name, &a), EXR_ERR_SUCCESS);
    assert_int_equal(a->type, EXR_ATTR_FLOAT);
    const float v = a->f;
    exr_finish(&f);
    return v;
}

/* The m44f attribute name of a part, straight from the header. */
static void header_m44f(const char *path, int part, const char *name, float m[16])
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    const exr_attribute_t *a;
    assert_int_equal(exr_start_read(&f, path, &init), EXR_ERR_SUCCESS);
    assert_int_equal(exr_get_attribute_by_name(f, part, name, &a), EXR_ERR_SUCCESS);
    assert_int_equal(a->type, EXR_ATTR_M44F);
    memcpy(m, a->m44f->m, 16 * sizeof(float));
    exr_finish(&f);
}

static void check_files(const char *in, const char *out, int skip_part, const char *const *skip)
{
    assert_int_equal(tu_compare_files(in, out, skip_part, skip), 0);
}

static void check_fog(tu_fog_check *fc, int want_sky)
{
    assert_int_equal(tu_check_fog(fc), 0);
    assert_true(fc->fogged > 0);
    if (want_sky)
        assert_true(fc->sky > 0);
    print_message("  %ld fogged surface pixels, %ld sky pixels checked\n", fc->fogged, fc->sky);
}

static const char *const RGBA[] = { "R", "G", "B", "A", NULL };

/* Exit 1 with a message naming the camera flags. */
static void expect_no_camera(const char *in, const char *out)
{
    remove(out);
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.1", in, out);
    assert_contains(tu_err, "--world-to-camera");
    assert_contains(tu_err, "--camera-to-world");
    assert_contains(tu_err, "--fov");
    assert_false(tu_exists(out));
}

/* Exit 1 with a message saying there is no depth and how to give one. */
static void expect_no_depth(const char *in, const char *out)
{
    remove(out);
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.1", in, out);
    assert_contains(tu_err, "no depth channel");
    assert_contains(tu_err, "--depth-channel");
    assert_contains(tu_err, "--depth ");
    assert_false(tu_exists(out));
    assert_run(1, "--explain '%s'", in);
    assert_contains(tu_err, "no depth channel");
}

/* ------------------------------------------------------------------ */

/* OIIO's flattened Arnold 3.4 sphere: worldToCamera rows (1 0 0 0)(0 1 0 0)
 * (0 0 -1 0)(1.5 0 4 1), i.e. camera space (x + 1.5, y, 4 - z): the camera
 * sits at world (-1.5, 0, 4) looking down -Z. The matrix named worldToNDC is
 * Arnold's screen space, sx = 2.41421 X/Z (hfov 45), sy = 3.21895 Y/Z
 * (160/120 times sx). Planar Z puts the surface on a sphere of radius about
 * 1 around the origin. */
static void test_arnold_flat_sphere(void **state)
{
    (void) state;
    char *path = real("arnold-flat-sphere.exr");
    ef_cam_meta meta;
    ef_camera cam;
    resolve(path, 0, &meta, &cam);
    assert_true(meta.w2c.set);
    assert_true(meta.w2ndc.set);
    assert_false(meta.w2screen.set);
    assert_int_equal(cam.proj, EF_PROJ_SCREEN);   /* by its numbers, not its name */
    assert_close(cam.pos[0], -1.5, 1e-5);
    assert_close(cam.pos[1], 0.0, 1e-5);
    assert_close(cam.pos[2], 4.0, 1e-5);
    assert_close(cam.hfov_deg, 45.0, 1e-3);
    assert_true(cam.near_.set);
    assert_close(cam.near_.v, 0.1, 1e-3);

    float w2c[16], scr[16];
    header_m44f(path, 0, "worldToCamera", w2c);
    header_m44f(path, 0, "worldToNDC", scr);
    static const float expect_w2c[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 1.5f, 0, 4, 1 };
    assert_memory_equal(w2c, expect_w2c, sizeof w2c);
    const double sx = scr[0], sy = scr[5];
    assert_close(sx, 2.41421, 1e-5);
    assert_close(sy, 3.21895, 1e-5);

    int w, h, w2, h2;
    float *Z = tu_read_channel(path, 0, "Z", &w, &h);
    float *A = tu_read_channel(path, 0, "A", &w2, &h2);
    assert_non_null(Z);
    assert_non_null(A);
    assert_int_equal(w, 160);
    assert_int_equal(h, 120);
    assert_int_equal(w2, w);
    assert_int_equal(h2, h);
    ef_depth_conv conv;
    ef_err err = {0};
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_PLANAR, &cam, &err), 0);
    double sum = 0.0, worst = 0.0;
    long n = 0, sky = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const float z = Z[y * w + x], a = A[y * w + x];
            ef_ray r;
            const int is_sky = ef_reconstruct(&cam, &conv, x, y, z, &r);
            if (!(z < 1e9f && a > 0.0f)) {
                sky += z >= 1e9f;
                if (z >= 1e9f)
                    assert_int_equal(is_sky, 1);
                continue;
            }
            assert_int_equal(is_sky, 0);
            double P[3];
            for (int k = 0; k < 3; ++k)
                P[k] = cam.pos[k] + r.dir[k] * r.dist;
            sum += sqrt(P[0] * P[0] + P[1] * P[1] + P[2] * P[2]);
            ++n;
            /* By hand: screen (2u - 1, 1 - 2v) -> camera (sx' Z, sy' Z, Z)
             * -> world (X - 1.5, Y, 4 - Z). */
            const double u = (x + 0.5) / w, v = (y + 0.5) / h;
            const double Xc = (2.0 * u - 1.0) / sx * z, Yc = (1.0 - 2.0 * v) / sy * z;
            const double Q[3] = { Xc - 1.5, Yc, 4.0 - z };
            for (int k = 0; k < 3; ++k)
                worst = fmax(worst, fabs(P[k] - Q[k]));
        }
    const double mean = sum / (double) n;
    print_message("  %ld surface pixels, %ld sky, mean |P_world| %.5f, worst deviation from "
                  "the hand reconstruction %.3g\n", n, sky, mean, worst);
    assert_true(n > 1000);
    assert_true(sky > 1000);
    assert_close(mean, 1.0, 0.05);
    assert_true(worst < 1e-4);
    free(Z);
    free(A);
    free(path);
}

/* The flattened Arnold 5.4 render: camera at (0, 0, 7.2625) looking down
 * -Z, 50 degrees horizontally; then a full fog run checked against a 50
 * degree pinhole over its 150 x 100 frame. */
static void test_arnold_representative(void **state)
{
    (void) state;
    char *path = real("arnold-representative-flat.exr");
    ef_cam_meta meta;
    ef_camera cam;
    resolve(path, 0, &meta, &cam);
    assert_close(cam.pos[0], 0.0, 1e-4);
    assert_close(cam.pos[1], 0.0, 1e-4);
    assert_close(cam.pos[2], 7.2625, 1e-4);
    assert_close(cam.hfov_deg, 50.0, 1e-3);
    assert_int_equal(cam.proj, EF_PROJ_SCREEN);
    const double fwd[3] = { 0, 0, 1 };
    double f[3];
    ef_camera_to_world_dir(&cam, fwd, f);
    assert_close(f[0], 0.0, 1e-6);
    assert_close(f[1], 0.0, 1e-6);
    assert_close(f[2], -1.0, 1e-6);

    char *out = tu_path("real_representative.exr");
    assert_run(0, "--explain '%s'", path);
    assert_contains(tu_out, "depth: Z (part 0)");
    assert_contains(tu_out, "colour: R, G, B, alpha A (part 0)");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.1 --fog-color 0.25,0.5,0.75", path, out);
    check_files(path, out, 0, RGBA);
    const int disp[4] = { 0, 0, 149, 99 };
    tu_pinhole pin;
    tu_pinhole_fov(&pin, disp, 50.0);
    tu_fog_check fc;
    tu_fog_check_init(&fc, path, out, &pin, 0.1);
    check_fog(&fc, 1);
    free(out);
    free(path);
}

/* Nuke 13 single part: R,G,B,A, depth.Z and look-alikes (character.Z,
 * character.ZBack, other.ZBack). No camera: flags. */
static void test_nuke_singlepart(void **state)
{
    (void) state;
    char *path = real("nuke-singlepart.exr");
    char *out = tu_path("real_nuke_single.exr");
    expect_no_camera(path, out);
    assert_run(0, "--explain '%s' " NO_CAMERA_FLAGS, path);
    assert_contains(tu_out, "depth: depth.Z (part 0)");
    assert_contains(tu_out, "colour: R, G, B, alpha A (part 0)");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.5 --fog-color 0.25,0.5,0.75 " NO_CAMERA_FLAGS,
               path, out);
    check_files(path, out, 0, RGBA);
    /* depth.Z and character.Z differ in this file, so the result tells them apart. */
    int w, h;
    float *dz = tu_read_channel(path, 0, "depth.Z", &w, &h);
    float *cz = tu_read_channel(path, 0, "character.Z", &w, &h);
    assert_non_null(dz);
    assert_non_null(cz);
    assert_true(dz[0] != cz[0]);
    free(dz);
    free(cz);
    const int disp[4] = { 0, 0, 15, 15 };
    tu_pinhole pin;
    tu_pinhole_fov(&pin, disp, 40.0);
    tu_fog_check fc;
    tu_fog_check_init(&fc, path, out, &pin, 0.5);
    fc.z = "depth.Z";
    check_fog(&fc, 0);
    free(out);
    free(path);
}

/* Nuke 13, one part per layer: rgba.main, character.main, depth.main,
 * other.main (each with view "main"). Depth comes from part 2. */
static void test_nuke_part_per_layer(void **state)
{
    (void) state;
    char *path = real("nuke-part-per-layer.exr");
    char *out = tu_path("real_nuke_parts.exr");
    assert_int_equal(tu_nparts(path), 4);
    expect_no_camera(path, out);
    assert_run(0, "--explain '%s' " NO_CAMERA_FLAGS, path);
    assert_contains(tu_out, "depth: depth.Z (part 2)");
    assert_contains(tu_out, "colour: rgba.R, rgba.G, rgba.B, alpha rgba.A (part 0)");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.5 --fog-color 0.25,0.5,0.75 " NO_CAMERA_FLAGS,
               path, out);
    check_files(path, out, 0, RGBA);
    const int disp[4] = { 0, 0, 15, 15 };
    tu_pinhole pin;
    tu_pinhole_fov(&pin, disp, 40.0);
    tu_fog_check fc;
    tu_fog_check_init(&fc, path, out, &pin, 0.5);
    fc.depth = path;
    fc.depth_part = 2;
    check_fog(&fc, 0);
    free(out);
    free(path);
}

/* openexr-images Beachball, single part: 2048x1556 display, data window
 * (654,245)-(1564,1120), R,G,B,A,Z half plus the left view and AOVs, no
 * camera; Z = 0 where nothing was rendered (sky). */
static void test_beachball_singlepart(void **state)
{
    (void) state;
    char *path = real("beachball-singlepart.0001.exr");
    char *out = tu_path("real_beachball_single.exr");
    expect_no_camera(path, out);
    /* two views and one camera from the flags: the view must be named */
    assert_run(2, "--explain '%s' " NO_CAMERA_FLAGS, path);
    assert_contains(tu_err, "--view");
    assert_run(0, "--explain '%s' --view right " NO_CAMERA_FLAGS, path);
    assert_contains(tu_out, "depth: Z (part 0)");
    assert_contains(tu_out, "colour: R, G, B, alpha A (part 0)");
    /* The other view: its own depth, not the default view's Z. */
    assert_run(0, "--explain '%s' --layer left " NO_CAMERA_FLAGS, path);
    assert_contains(tu_out, "colour: left.R, left.G, left.B, alpha left.A (part 0)");
    assert_contains(tu_out, "depth: left.Z (part 0)");
    assert_run(0, "'%s' -o '%s' --view right --fog exp:density=0.1 --fog-color 0.25,0.5,0.75 "
                  NO_CAMERA_FLAGS, path, out);
    assert_contains(tu_err, "view 'left' is not fogged");
    check_files(path, out, 0, RGBA);
    const int disp[4] = { 0, 0, 2047, 1555 };
    tu_pinhole pin;
    tu_pinhole_fov(&pin, disp, 40.0);
    tu_fog_check fc;
    tu_fog_check_init(&fc, path, out, &pin, 0.1);
    check_fog(&fc, 1);
    free(out);
    free(path);
}

/* The same frame, one layer per part (rgba_right, depth_left, ...,
 * depth_right in part 5): the right view's colour with the right view's
 * depth. */
static void test_beachball_multipart(void **state)
{
    (void) state;
    char *path = real("beachball-multipart.0001.exr");
    char *out = tu_path("real_beachball_multi.exr");
    assert_int_equal(tu_nparts(path), 10);
    expect_no_camera(path, out);
    assert_run(0, "--explain '%s' --view right " NO_CAMERA_FLAGS, path);
    assert_contains(tu_out, "depth: depth.Z (part 5)");
    assert_contains(tu_out, "colour: rgba.R, rgba.G, rgba.B, alpha rgba.A (part 0)");
    assert_run(0, "'%s' -o '%s' --view right --fog exp:density=0.1 --fog-color 0.25,0.5,0.75 "
                  NO_CAMERA_FLAGS, path, out);
    check_files(path, out, 0, RGBA);
    const int disp[4] = { 0, 0, 2047, 1555 };
    tu_pinhole pin;
    tu_pinhole_fov(&pin, disp, 40.0);
    tu_fog_check fc;
    tu_fog_check_init(&fc, path, out, &pin, 0.1);
    fc.depth = path;
    fc.depth_part = 5;
    check_fog(&fc, 1);
    free(out);
    free(path);
}

/* V-Ray for Maya: cameraTransform rows (1 0 0 0)(0 0 1 0)(0 -1 0 0)(0 5 20 1)
 * is camera-to-world in a Z-up world, the camera looking down its own -Z:
 * position (0, 5, 20), forward -(0, -1, 0) = +Y, up +Z; cameraFov 54.43.
 * No depth in the file: refused; with a depth file made here, fogged. */
static void test_vray_cornellbox(void **state)
{
    (void) state;
    char *path = real("vray-cornellbox.0001.exr");
    ef_cam_meta meta;
    ef_camera cam;
    resolve(path, 0, &meta, &cam);
    assert_true(meta.vray_c2w.set);
    assert_close(cam.pos[0], 0.0, 1e-4);
    assert_close(cam.pos[1], 5.0, 1e-4);
    assert_close(cam.pos[2], 20.0, 1e-4);
    assert_close(cam.hfov_deg, 54.43, 1e-2);
    const double fwd[3] = { 0, 0, 1 }, up[3] = { 0, 1, 0 };
    double f[3], u[3];
    ef_camera_to_world_dir(&cam, fwd, f);
    ef_camera_to_world_dir(&cam, up, u);
    assert_close(f[0], 0.0, 1e-6);
    assert_close(f[1], 1.0, 1e-6);
    assert_close(f[2], 0.0, 1e-6);
    assert_close(u[0], 0.0, 1e-6);
    assert_close(u[1], 0.0, 1e-6);
    assert_close(u[2], 1.0, 1e-6);

    char *out = tu_path("real_vray.exr");
    expect_no_depth(path, out);   /* normals.Z is not a depth */

    /* A planar depth for the cropped data window (167,0)-(792,539). */
    const int dw[4] = { 167, 0, 792, 539 }, disp[4] = { 0, 0, 959, 539 };
    const int w = dw[2] - dw[0] + 1, h = dw[3] - dw[1] + 1;
    float *Z = malloc(sizeof(float) * (size_t) w * (size_t) h);
    assert_non_null(Z);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            Z[y * w + x] = (x + y) % 97 == 0 ? 0.0f : 5.0f + (float) ((x * 7 + y * 3) % 200) * 0.1f;
    tu_part dp;
    tu_part_init(&dp, 1, 1);
    memcpy(dp.dw, dw, sizeof dw);
    memcpy(dp.disp, disp, sizeof disp);
    tu_part_add(&dp, "Z", EXR_PIXEL_FLOAT, Z);
    char *dep = tu_path("real_vray_depth.exr");
    assert_int_equal(tu_write_exr(dep, &dp, 1), 0);
    free(Z);
    assert_run(0, "'%s' --depth '%s' -o '%s' --fog exp:density=0.05 --fog-color 0.25,0.5,0.75",
               path, dep, out);
    check_files(path, out, 0, RGBA);
    tu_pinhole pin;
    tu_pinhole_fov(&pin, disp, header_float(path, 0, "cameraFov"));
    tu_fog_check fc;
    tu_fog_check_init(&fc, path, out, &pin, 0.05);
    fc.depth = dep;
    check_fog(&fc, 1);
    free(dep);
    free(out);
    free(path);
}

/* Arnold 7.4, three tiled 16x16 parts (RGBA, id, instanceID), each with
 * worldToCamera (camera at (0, 0, 2.18629) looking down -Z) and a
 * worldToScreen of 50 degrees. No depth: refused; with a depth file,
 * fogged, every part back. */
static void test_arnold7_multipart(void **state)
{
    (void) state;
    char *path = real("arnold7-multipart.exr");
    assert_int_equal(tu_nparts(path), 3);
    for (int p = 0; p < 3; ++p) {
        ef_cam_meta meta;
        ef_camera cam;
        resolve(path, p, &meta, &cam);
        assert_true(meta.w2c.set);
        assert_true(meta.w2screen.set);
        assert_int_equal(cam.proj, EF_PROJ_SCREEN);
        assert_close(cam.pos[0], 0.0, 1e-4);
        assert_close(cam.pos[1], 0.0, 1e-4);
        assert_close(cam.pos[2], 2.18629, 1e-4);
        assert_close(cam.hfov_deg, 50.0, 1e-3);
        assert_true(cam.near_.set);
        assert_close(cam.near_.v, 0.01, 1e-6);    /* arnold/camera/near_clip */
    }
    char *out = tu_path("real_arnold7.exr");
    expect_no_depth(path, out);

    const int dw[4] = { 0, 0, 15, 15 };
    float Z[256];
    for (int i = 0; i < 256; ++i)
        Z[i] = i % 17 == 3 ? 1e30f : 0.5f + 0.05f * (float) i;
    tu_part dp;
    tu_part_init(&dp, 16, 16);
    memcpy(dp.dw, dw, sizeof dw);
    tu_part_add(&dp, "Z", EXR_PIXEL_FLOAT, Z);
    dp.tile = 5;
    char *dep = tu_path("real_arnold7_depth.exr");
    assert_int_equal(tu_write_exr(dep, &dp, 1), 0);
    assert_run(0, "--explain '%s' --depth '%s'", path, dep);
    assert_contains(tu_out, "depth: Z (part 0 of ");
    assert_contains(tu_out, "(part 0)");
    assert_run(0, "'%s' --depth '%s' -o '%s' --fog exp:density=0.3 --fog-color 0.25,0.5,0.75",
               path, dep, out);
    check_files(path, out, 0, RGBA);
    tu_image img;
    for (int p = 0; p < 3; ++p) {
        assert_int_equal(tu_read_image(out, p, &img), 0);
        assert_true(img.tiled);
        assert_int_equal(img.tile_x, 64);
        tu_image_free(&img);
    }
    tu_pinhole pin;
    tu_pinhole_fov(&pin, dw, 50.0);
    tu_fog_check fc;
    tu_fog_check_init(&fc, path, out, &pin, 0.3);
    fc.depth = dep;
    check_fog(&fc, 1);
    free(dep);
    free(out);
    free(path);
}

int main(void)
{
    real_dir = tu_real_exr_dir();
    if (!real_dir) {
        const char *shared = getenv("EXRFOG_SHARED_DIR");
        printf("test_realexr: %s/real-exr is absent; skipped (configure with "
               "-DEXRFOG_SHARED_DIR=PATH, or set EXRFOG_SHARED_DIR, to run it)\n",
               shared ? shared : "../shared");
        return 77;
    }
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_arnold_flat_sphere),
        cmocka_unit_test(test_arnold_representative),
        cmocka_unit_test(test_nuke_singlepart),
        cmocka_unit_test(test_nuke_part_per_layer),
        cmocka_unit_test(test_beachball_singlepart),
        cmocka_unit_test(test_beachball_multipart),
        cmocka_unit_test(test_vray_cornellbox),
        cmocka_unit_test(test_arnold7_multipart),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
