/* Camera files (--camera-file): JSON in each convention and Nuke .chan,
 * read, looked up per frame and resolved into rays that are checked
 * against directions worked out by hand.
 *
 * Every case uses a 101x51 display window and a 90 degree horizontal fov
 * (tan 45 = 1), so in exrfog's camera space (+X right, +Y up, +Z forward)
 * the centre pixel (50, 25) looks along (0, 0, 1) and the top-left pixel
 * (0, 0) along (-100/101, 50/101, 1): x = 2 * 0.5/101 - 1, y = (1 - 2 * 0.5/51)
 * * 51/101. In world space that is fwd for the centre and
 * -100/101 right + 50/101 up + fwd for the corner, with right, up and fwd
 * the camera's axes in world space worked out by hand for each case.
 *
 * Scratch files live in $EXRFOG_TMP_DIR/camera_file. */
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
#include <sys/stat.h>
#include <sys/types.h>
#include <cmocka.h>

#include "tassert.h"
#include "testutil.h"

#include "camera.h"
#include "camera_file.h"

#define PI 3.14159265358979323846
#define TOL 1e-12

/* Writes text to $EXRFOG_TMP_DIR/camera_file/name; returns the path (static). */
static const char *put(const char *name, const char *text)
{
    static char root[512], path[1024];
    if (!root[0]) {
        char *p = tu_path("camera_file");
        snprintf(root, sizeof root, "%s", p);
        free(p);
        mkdir(root, 0777);
    }
    snprintf(path, sizeof path, "%s/%s", root, name);
    FILE *fp = fopen(path, "wb");
    assert_non_null(fp);
    fputs(text, fp);
    fclose(fp);
    return path;
}

/* Reads the file, expecting success. */
static ef_camera_file *load(const char *name, const char *text, ef_cam_convention def)
{
    ef_camera_file *cf = NULL;
    ef_err err = {0};
    const int rc = ef_camera_file_read(put(name, text), def, &cf, &err);
    if (rc)
        fail_msg("%s: %s", name, err.msg);
    assert_non_null(cf);
    return cf;
}

/* Reads the file, expecting failure with needle in the message and the
 * file named in err.file. */
static void load_fails(const char *name, const char *text, const char *needle)
{
    ef_camera_file *cf = NULL;
    ef_err err = {0};
    const char *path = put(name, text);
    if (ef_camera_file_read(path, EF_CONV_EXR, &cf, &err) == 0)
        fail_msg("%s: read without error, expected '%s'", name, needle);
    assert_null(cf);
    assert_contains(err.msg, needle);
    assert_non_null(err.file);
    assert_string_equal(err.file, path);
}

/* The camera of frame in cf over a 101x51 display window. */
static void resolve(const ef_camera_file *cf, double frame, ef_camera *cam)
{
    ef_cam_meta m;
    ef_cam_meta_init(&m, 0, 0, 100, 50);
    ef_cam_flags fl = {0};
    ef_err err = {0};
    if (ef_camera_file_frame(cf, frame, &fl, &err))
        fail_msg("frame %g: %s", frame, err.msg);
    if (ef_camera_resolve(&m, &fl, cam, &err))
        fail_msg("frame %g: resolve: %s", frame, err.msg);
}

static void assert_vec(const double got[3], const double want[3], double tol)
{
    assert_close(got[0], want[0], tol);
    assert_close(got[1], want[1], tol);
    assert_close(got[2], want[2], tol);
}

/* World-space rays through the centre and the top-left pixel, as unit
 * vectors, against the hand-computed axes. */
static void check_rays(const ef_camera *cam, const double pos[3], const double right[3],
                       const double up[3], const double fwd[3])
{
    assert_vec(cam->pos, pos, TOL);
    assert_close(cam->hfov_deg, 90.0, 1e-9);
    double d[3], w[3], want[3];
    ef_camera_ray(cam, 50, 25, d);
    assert_close(d[0], 0.0, TOL);
    assert_close(d[1], 0.0, TOL);
    ef_camera_to_world_dir(cam, d, w);
    assert_vec(w, fwd, TOL);
    ef_camera_ray(cam, 0, 0, d);
    assert_close(d[0], -100.0 / 101.0, TOL);
    assert_close(d[1], 50.0 / 101.0, TOL);
    ef_camera_to_world_dir(cam, d, w);
    for (int i = 0; i < 3; ++i)
        want[i] = -100.0 / 101.0 * right[i] + 50.0 / 101.0 * up[i] + fwd[i];
    assert_vec(w, want, TOL);
}

/* ------------------------------------------------------------ JSON */

/* One camera at (1, 2, 3) in each convention, looking along world -X.
 * Y-up DCCs (maya, houdini, usd, nuke): turned +90 degrees about Y,
 * Ry(90) = [[0,0,1],[0,1,0],[-1,0,0]] (column vectors): camera X axis
 * (first column) = (0,0,-1), Y = (0,1,0), Z = (1,0,0); the camera looks
 * down -Z = (-1,0,0). Column-vector layouts print those axes as columns
 * with the translation in the last column; row-vector layouts as rows with
 * the translation in the last row. */
static const double P[3] = { 1, 2, 3 };
static const double Y_RIGHT[3] = { 0, 0, -1 }, Y_UP[3] = { 0, 1, 0 }, FWD[3] = { -1, 0, 0 };

static void test_json_conventions(void **state)
{
    (void) state;
    static const struct {
        const char *conv, *mat;
    } yup[] = {
        { "maya", "[0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1]" },
        { "houdini", "[[0,0,-1,0], [0,1,0,0], [1,0,0,0], [1,2,3,1]]" },
        { "usd", "[0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1]" },
        { "nuke", "[[0,0,1,1], [0,1,0,2], [-1,0,0,3], [0,0,0,1]]" },
    };
    for (size_t i = 0; i < sizeof yup / sizeof yup[0]; ++i) {
        char text[512];
        snprintf(text, sizeof text, "{\"convention\": \"%s\", \"frames\": {\"1001\": "
                 "{\"camera_to_world\": %s, \"fov\": 90}}}", yup[i].conv, yup[i].mat);
        ef_camera_file *cf = load("conv.json", text, EF_CONV_EXR);
        ef_camera cam;
        resolve(cf, 1001, &cam);
        check_rays(&cam, P, Y_RIGHT, Y_UP, FWD);
        ef_camera_file_free(cf);
    }

    /* exr: row vectors, +Z forward. The rows are the camera's axes: X row
     * = right (0,0,-1), Y row = up (0,1,0), Z row = forward (-1,0,0). */
    ef_camera cam;
    ef_camera_file *cf = load("exr.json", "{\"frames\": {\"7\": {\"camera_to_world\": "
                              "[0,0,-1,0, 0,1,0,0, -1,0,0,0, 1,2,3,1], \"fov\": 90}}}",
                              EF_CONV_EXR);
    resolve(cf, 7, &cam);
    check_rays(&cam, P, Y_RIGHT, Y_UP, FWD);
    ef_camera_file_free(cf);

    /* blender (Z up): rotation_euler (90, 0, 90) XYZ, R = Rz(90) Rx(90) =
     * [[0,0,1],[1,0,0],[0,1,0]]: camera X = (0,1,0), Y = (0,0,1) (world
     * up), Z = (1,0,0), so it looks along -X; matrix_world printed row by
     * row as nested rows. */
    static const double B_RIGHT[3] = { 0, 1, 0 }, B_UP[3] = { 0, 0, 1 };
    cf = load("blender.json", "{\"convention\": \"blender\", \"frames\": {\"1\": "
              "{\"camera_to_world\": [[0,0,1,1],[1,0,0,2],[0,1,0,3],[0,0,0,1]], "
              "\"fov\": 90}}}", EF_CONV_EXR);
    resolve(cf, 1, &cam);
    check_rays(&cam, P, B_RIGHT, B_UP, FWD);
    ef_camera_file_free(cf);

    /* Its world_to_camera, [R^T | -R^T t] = [[0,1,0,-2],[0,0,1,-3],[1,0,0,-1]],
     * gives the same camera; the convention comes from the command line
     * (conv_default) because the file names none. */
    cf = load("blender_w2c.json", "{\"frames\": {\"1\": {\"world_to_camera\": "
              "[0,1,0,-2, 0,0,1,-3, 1,0,0,-1, 0,0,0,1], \"fov\": 90}}}", EF_CONV_BLENDER);
    assert_int_equal(ef_camera_file_convention(cf), EF_CONV_BLENDER);
    resolve(cf, 1, &cam);
    check_rays(&cam, P, B_RIGHT, B_UP, FWD);
    ef_camera_file_free(cf);

    /* A file's convention overrides the command line's. */
    cf = load("override.json", "{\"convention\": \"maya\", \"frames\": {\"1\": "
              "{\"camera_to_world\": [0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1], \"fov\": 90}}}",
              EF_CONV_BLENDER);
    resolve(cf, 1, &cam);
    check_rays(&cam, P, Y_RIGHT, Y_UP, FWD);
    assert_contains(ef_camera_file_describe(cf), "convention maya");
    ef_camera_file_free(cf);
}

/* Lens and clip keys: focal_length 18 mm on a 36 mm aperture is
 * 2 atan(36 / 36) = 90 degrees; file-level defaults and per-frame
 * overrides; the list forms. */
static void test_json_lens_and_forms(void **state)
{
    (void) state;
    ef_camera_file *cf = load("lens.json",
        "{\"convention\": \"maya\", \"aperture\": 36, \"focal_length\": 18,\n"
        " \"near\": 0.5, \"far\": 500,\n"
        " \"frames\": {\n"
        "  \"1\": {\"camera_to_world\": [0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1]},\n"
        "  \"2\": {\"camera_to_world\": [0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1],\n"
        "         \"fov\": 40, \"near\": 0.25},\n"
        "  \"2.5\": {\"camera_to_world\": [0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1],\n"
        "           \"focal_length\": 36, \"aperture\": 72, \"far\": 9}}}\n", EF_CONV_EXR);
    ef_camera cam;
    resolve(cf, 1, &cam);
    check_rays(&cam, P, Y_RIGHT, Y_UP, FWD);
    assert_close(cam.near_.v, 0.5, 0.0);
    assert_close(cam.far_.v, 500, 0.0);

    ef_cam_flags fl = {0};
    ef_err err = {0};
    assert_int_equal(ef_camera_file_frame(cf, 2, &fl, &err), 0);
    assert_true(fl.fov.set);
    assert_close(fl.fov.v, 40, 0.0);
    assert_close(fl.near_.v, 0.25, 0.0);
    assert_close(fl.far_.v, 500, 0.0);
    /* 2.5: 2 atan(72 / 72) = 90 degrees, its own far. */
    resolve(cf, 2.5, &cam);
    check_rays(&cam, P, Y_RIGHT, Y_UP, FWD);
    assert_close(cam.far_.v, 9, 0.0);
    assert_close(cam.near_.v, 0.5, 0.0);

    double first, last;
    int count;
    assert_int_equal(ef_camera_file_frames(cf, &first, &last, &count), 0);
    assert_close(first, 1, 0.0);
    assert_close(last, 2.5, 0.0);
    assert_int_equal(count, 3);
    assert_string_equal(ef_camera_file_describe(cf), "JSON, convention maya, 3 frames 1 to 2.5");
    /* Sub-frames match exactly: 2.25 is not there. */
    assert_int_equal(ef_camera_file_frame(cf, 2.25, &fl, &err), -1);
    assert_contains(err.msg, "frame 2.25 ");
    ef_camera_file_free(cf);

    /* "frames" as a list, and a bare list at the top level (vfov: the
     * vertical 2 atan(51/101) of a 90 degree horizontal fov on 101x51). */
    char text[512];
    snprintf(text, sizeof text, "{\"convention\": \"usd\", \"frames\": [{\"frame\": 12, "
             "\"camera_to_world\": [0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1], \"vfov\": %.17g}]}",
             2 * atan(51.0 / 101.0) * 180 / PI);
    cf = load("list.json", text, EF_CONV_EXR);
    resolve(cf, 12, &cam);
    check_rays(&cam, P, Y_RIGHT, Y_UP, FWD);
    ef_camera_file_free(cf);
    cf = load("bare.data", "  [{\"frame\": 3, \"camera_to_world\": "
              "[0,0,-1,0, 0,1,0,0, 1,0,0,0, 1,2,3,1], \"fov\": 90}]", EF_CONV_HOUDINI);
    resolve(cf, 3, &cam);
    check_rays(&cam, P, Y_RIGHT, Y_UP, FWD);
    ef_camera_file_free(cf);

    /* A frame without a lens leaves the caller's fov alone; a frame with
     * a vfov clears a caller's fov (and the other way round). */
    cf = load("nolens.json", "{\"frames\": {\"1\": {\"camera_to_world\": "
              "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}, \"2\": {\"camera_to_world\": "
              "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], \"vfov\": 30}}}", EF_CONV_EXR);
    memset(&fl, 0, sizeof fl);
    fl.fov.set = 1;
    fl.fov.v = 55;
    fl.w2c.set = 1;
    assert_int_equal(ef_camera_file_frame(cf, 1, &fl, &err), 0);
    assert_true(fl.fov.set && fl.fov.v == 55 && !fl.vfov.set);
    assert_true(fl.c2w.set && !fl.w2c.set);
    assert_int_equal(ef_camera_file_frame(cf, 2, &fl, &err), 0);
    assert_true(!fl.fov.set && fl.vfov.set && fl.vfov.v == 30);
    ef_camera_file_free(cf);
}

static void test_json_errors(void **state)
{
    (void) state;
#define M16 "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]"
    load_fails("e1.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 "}}, "
               "\"fovv\": 3}", "unknown key 'fovv'");
    load_fails("e2.json", "{\"frames\": {\"1\": {\"camera_to_wrld\": " M16 "}}}",
               "frames.1: unknown key 'camera_to_wrld'");
    load_fails("e3.json", "[{\"frame\": 1, \"camera_to_world\": " M16 ", \"fox\": 3}]",
               "[0]: unknown key 'fox'");
    /* Non-finite: JSON cannot spell NaN; an overflowing number is refused
     * by the parser with its line. */
    load_fails("e4.json", "{\"frames\": {\"1\": {\"camera_to_world\": "
               "[1e999,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}}}", "line 1");
    load_fails("e5.json", "{\"frames\": {\"1\": {\"camera_to_world\": NaN}}}", "line 1");
    /* Wrong counts. */
    load_fails("e6.json", "{\"frames\": {\"1\": {\"camera_to_world\": "
               "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0]}}}",
               "frames.1.camera_to_world: expected a matrix: 16 numbers or 4 rows of 4 "
               "numbers, got an array of 15");
    load_fails("e7.json", "{\"frames\": {\"1\": {\"camera_to_world\": "
               "[[1,0,0,0],[0,1,0,0],[0,0,1],[0,0,0,1]]}}}",
               "frames.1.camera_to_world[2]: expected a row of 4 numbers, got an array of 3");
    load_fails("e8.json", "{\"frames\": {\"1\": {\"camera_to_world\": "
               "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,\"0\",1]}}}",
               "frames.1.camera_to_world[14]: expected a number, got a string");
    /* Lens conflicts. */
    load_fails("e9.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 ", \"fov\": 40, "
               "\"focal_length\": 35, \"aperture\": 36}}}", "gives fov and focal_length");
    load_fails("e10.json", "{\"fov\": 40, \"vfov\": 30, \"frames\": {\"1\": "
               "{\"camera_to_world\": " M16 "}}}", "the top level: gives fov and vfov");
    load_fails("e11.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 ", "
               "\"focal_length\": 35}}}", "frames.1: focal_length 35 needs an aperture");
    load_fails("e12.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 ", "
               "\"fov\": 40, \"aperture\": 36}}}", "aperture 36 without a focal_length");
    load_fails("e13.json", "{\"aperture\": 36, \"frames\": {\"1\": {\"camera_to_world\": "
               M16 ", \"fov\": 40}}}", "no frame uses it");
    load_fails("e14.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 ", "
               "\"fov\": 180}}}", "frames.1.fov: 180 degrees");
    load_fails("e15.json", "{\"near\": -1, \"frames\": {}}", "near: -1; it must be greater");
    load_fails("e16.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 ", "
               "\"near\": 10, \"far\": 5}}}", "frames.1: far 5 is not beyond near 10");
    /* Duplicate frames: the same key, the same number spelled twice, a list. */
    load_fails("e17.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 "}, "
               "\"1\": {\"camera_to_world\": " M16 "}}}", "duplicate");
    load_fails("e18.json", "{\"frames\": {\"1001\": {\"camera_to_world\": " M16 "}, "
               "\"1001.0\": {\"camera_to_world\": " M16 "}}}",
               "frame 1001 is given twice (frames.1001 and frames.1001.0)");
    load_fails("e19.json", "[{\"frame\": 5, \"camera_to_world\": " M16 "}, "
               "{\"frame\": 6, \"camera_to_world\": " M16 "}, "
               "{\"frame\": 5, \"world_to_camera\": " M16 "}]",
               "frame 5 is given twice ([0] and [2])");
    /* Pose: both, neither. */
    load_fails("e20.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 ", "
               "\"world_to_camera\": " M16 "}}}", "both camera_to_world and world_to_camera");
    load_fails("e21.json", "{\"frames\": {\"1\": {\"fov\": 40}}}",
               "frames.1: has no camera_to_world or world_to_camera");
    /* Other shapes. */
    load_fails("e22.json", "{\"convention\": \"max\", \"frames\": {}}",
               "convention: 'max' is not one of");
    load_fails("e23.json", "{\"frames\": {\"one\": {\"camera_to_world\": " M16 "}}}",
               "the key 'one' is not a frame number");
    load_fails("e24.json", "[{\"camera_to_world\": " M16 "}]", "[0]: has no \"frame\"");
    load_fails("e25.json", "{\"frames\": {}}", "holds no frames");
    load_fails("e26.json", "{\"convention\": \"nuke\"}", "has no \"frames\"");
    load_fails("e27.json", "5", "expected a JSON object");
    load_fails("e28.json", "{\"frames\": 3}", "frames: expected an object of frames");
    load_fails("e29.json", "{\"frames\": {\"1\": {\"camera_to_world\": " M16 ", "
               "\"fov\": \"40\"}}}", "frames.1.fov: expected a number (degrees), got a string");
    load_fails("cam.txt", "1 0 0 0 0 0 0\n", "neither a Nuke .chan file");
#undef M16
}

/* ------------------------------------------------------------ .chan */

/* Nuke cameras look down -Z with +Y up; R = Ry . Rx . Rz (ZXY: Z first).
 * vfov 2 atan(51/101) is the vertical angle of a 90 degree horizontal fov
 * on the 101x51 window. Hand-computed:
 *   frame 1: rx = 90: Rx(90) = [[1,0,0],[0,0,-1],[0,1,0]]: right (1,0,0),
 *            up (0,0,1), fwd = -(0,-1,0) = (0,1,0): looks straight up.
 *   frame 2: rx = 30, ry = 90 (order matters): Rx(30) takes fwd (0,0,-1)
 *            to (0, 1/2, -sqrt3/2) and up to (0, sqrt3/2, 1/2); Ry(90)
 *            (x' = z, z' = -x) then gives fwd (-sqrt3/2, 1/2, 0), up
 *            (1/2, sqrt3/2, 0), right Ry(1,0,0) = (0,0,-1): panned to -X and
 *            tilted up 30 degrees. (Y applied first, Rx . Ry, would give fwd
 *            (-1, 0, 0) with no tilt.)
 *   frame 3: rx = 30, ry = 90, rz = 90: Rz(90) turns right into up and up
 *            into -right before the rest: right = Ry Rx (0,1,0) = (1/2,
 *            sqrt3/2, 0), up = Ry Rx (-1,0,0) = Ry (-1,0,0) = (0,0,1), fwd
 *            as frame 2. */
static void test_chan(void **state)
{
    (void) state;
    const double s3 = sqrt(3.0) / 2;
    char text[1024];
    const double vfov = 2 * atan(51.0 / 101.0) * 180 / PI;
    snprintf(text, sizeof text,
             "# exported from Nuke\r\n"
             "\n"
             "   # indented comment\n"
             "1\t1 2 3\t90 0 0\t%.17g\n"
             "2 1 2 3 30 90 0 %.17g   # trailing comment\r\n"
             "\n"
             "3 1 2 3 30 90 90 %.17g\n", vfov, vfov, vfov);
    ef_camera_file *cf = load("cam.CHAN", text, EF_CONV_BLENDER);
    assert_int_equal(ef_camera_file_convention(cf), EF_CONV_NUKE);
    assert_string_equal(ef_camera_file_describe(cf),
                        "Nuke .chan, rotation order ZXY, 3 frames 1 to 3, vertical fov");
    ef_camera cam;
    {
        const double r[3] = { 1, 0, 0 }, u[3] = { 0, 0, 1 }, f[3] = { 0, 1, 0 };
        resolve(cf, 1, &cam);
        check_rays(&cam, P, r, u, f);
    }
    {
        const double r[3] = { 0, 0, -1 }, u[3] = { 0.5, s3, 0 }, f[3] = { -s3, 0.5, 0 };
        resolve(cf, 2, &cam);
        check_rays(&cam, P, r, u, f);
    }
    {
        const double r[3] = { 0.5, s3, 0 }, u[3] = { 0, 0, 1 }, f[3] = { -s3, 0.5, 0 };
        resolve(cf, 3, &cam);
        check_rays(&cam, P, r, u, f);
    }
    ef_camera_file_free(cf);

    /* "# rotation_order: yxz" (Y first: R = Rz . Rx . Ry): frame 2's
     * angles now pan without tilting: Ry(90) takes fwd to (-1,0,0), Rx(30)
     * leaves it; up: Ry leaves (0,1,0), Rx(30) gives (0, sqrt3/2, 1/2);
     * right: Ry(90) (1,0,0) = (0,0,-1), Rx(30) gives (0, 1/2, -sqrt3/2). */
    snprintf(text, sizeof text, "#rotation_order: yxz\n2 1 2 3 30 90 0 %.17g\n", vfov);
    cf = load("yxz.chan", text, EF_CONV_EXR);
    assert_contains(ef_camera_file_describe(cf), "rotation order YXZ");
    {
        const double r[3] = { 0, 0.5, -s3 }, u[3] = { 0, s3, 0.5 }, f[3] = { -1, 0, 0 };
        resolve(cf, 2, &cam);
        check_rays(&cam, P, r, u, f);
    }
    ef_camera_file_free(cf);

    /* An Axis export has no vfov: the pose alone; the lens stays the caller's. */
    cf = load("axis.chan", "10 0 0 0 0 0 0\n11 0 0 5 0 0 0\n", EF_CONV_EXR);
    ef_cam_flags fl = {0};
    ef_err err = {0};
    fl.fov.set = 1;
    fl.fov.v = 33;
    assert_int_equal(ef_camera_file_frame(cf, 11, &fl, &err), 0);
    assert_true(fl.fov.set && fl.fov.v == 33 && !fl.vfov.set);
    assert_int_equal(fl.convention, EF_CONV_NUKE);
    assert_true(fl.c2w.set);
    assert_close(fl.c2w.v.m[11], 5, 0.0);   /* translation in the last column */
    assert_contains(ef_camera_file_describe(cf), "no fov");
    ef_camera_file_free(cf);
}

static void test_chan_errors(void **state)
{
    (void) state;
    load_fails("c1.chan", "# header\n1 0 0 0 0 0 0 40\n2 0 0 0 0\n",
               "line 3: has 5 columns");
    load_fails("c2.chan", "1 0 0 0 0 0 0 40\n\n2 0 0 0 abc 0 0 40\n",
               "line 3: column 5 (rx) 'abc' is not a number");
    load_fails("c3.chan", "1 0 0 0 0 0 0 40\n2 0 0 0 0 0 0\n",
               "line 2: has 7 columns but line 1 has 8");
    load_fails("c4.chan", "1 0 0 0 0 0 0 40 7\n", "line 1: more than 8 columns");
    load_fails("c5.chan", "1 0 0 0 nan 0 0 40\n", "line 1: column 5 (rx) 'nan' is not a finite");
    load_fails("c6.chan", "1 0 0 0 0 0 0 180\n", "line 1: column 8 (vfov) is 180 degrees");
    load_fails("c7.chan", "# rotation_order: XYY\n1 0 0 0 0 0 0\n",
               "line 1: rotation_order must be one of");
    load_fails("c8.chan", "1 0 0 0 0 0 0\n# rotation_order: XYZ\n2 0 0 0 0 0 0\n",
               "line 2: rotation_order must come before the first frame (line 1)");
    load_fails("c9.chan", "1 0 0 0 0 0 0\n1.0 0 0 0 0 0 0\n",
               "frame 1 is given twice (line 1 and line 2)");
    load_fails("c10.chan", "# nothing\n\n", "holds no frames");
}

/* A frame the file lacks: the message names it and what the file covers. */
static void test_missing_frame(void **state)
{
    (void) state;
    ef_camera_file *cf = load("gap.chan", "1001 0 0 0 0 0 0\n1002 0 0 0 0 0 0\n"
                              "1004 0 0 0 0 0 0\n", EF_CONV_EXR);
    ef_cam_flags fl = {0};
    ef_err err = {0};
    assert_int_equal(ef_camera_file_frame(cf, 1003, &fl, &err), -1);
    assert_contains(err.msg, "frame 1003 is not in the camera file");
    assert_contains(err.msg, "frames 1001 to 1004 (3 frames)");
    assert_contains(err.msg, "between 1002 and 1004");
    assert_non_null(err.file);
    assert_contains(err.file, "gap.chan");
    assert_false(fl.c2w.set);
    assert_int_equal(ef_camera_file_frame(cf, 1010, &fl, &err), -1);
    assert_contains(err.msg, "frame 1010 is not in the camera file, which covers frames 1001 "
                             "to 1004");
    assert_int_equal(ef_camera_file_frame(cf, 1001.5, &fl, &err), -1);
    assert_contains(err.msg, "frame 1001.5 ");
    assert_int_equal(ef_camera_file_frame(cf, 1004, &fl, &err), 0);
    ef_camera_file_free(cf);

    cf = load("one.json", "{\"frames\": {\"12.5\": {\"camera_to_world\": "
              "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}}}", EF_CONV_EXR);
    assert_int_equal(ef_camera_file_frame(cf, 12.5, &fl, &err), 0);
    assert_int_equal(ef_camera_file_frame(cf, 12, &fl, &err), -1);
    assert_contains(err.msg, "frame 12 is not in the camera file, which covers frame 12.5 "
                             "(1 frame)");
    ef_camera_file_free(cf);

    /* A file that cannot be opened. */
    ef_err e2 = {0};
    assert_int_equal(ef_camera_file_read("/nonexistent/cam.chan", EF_CONV_EXR, &cf, &e2), -1);
    assert_contains(e2.msg, "cannot open");
}

/* The examples in docs/camera-file.md read as documented. */
static char *doc_block(const char *doc, const char *fence)
{
    const char *a = strstr(doc, fence);
    assert_non_null(a);
    a = strchr(a, '\n') + 1;
    const char *b = strstr(a, "```");
    assert_non_null(b);
    char *out = malloc((size_t) (b - a) + 1);
    memcpy(out, a, (size_t) (b - a));
    out[b - a] = '\0';
    return out;
}

static void test_doc_examples(void **state)
{
    (void) state;
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    if (!src)
        skip();
    char path[1024];
    snprintf(path, sizeof path, "%s/docs/camera-file.md", src);
    FILE *fp = fopen(path, "rb");
    assert_non_null(fp);
    static char doc[1 << 16];
    const size_t n = fread(doc, 1, sizeof doc - 1, fp);
    fclose(fp);
    doc[n] = '\0';

    char *json = doc_block(doc, "```json");
    ef_camera_file *cf = load("doc.json", json, EF_CONV_EXR);
    free(json);
    assert_string_equal(ef_camera_file_describe(cf),
                        "JSON, convention blender, 2 frames 1001 to 1002");
    /* Blender's rotation (90, 0, 0) at (0, -10, 1.5): looks along +Y, up +Z;
     * 2 atan(36 / 70) horizontal fov. */
    ef_cam_meta m;
    ef_cam_meta_init(&m, 0, 0, 100, 50);
    ef_cam_flags fl = {0};
    ef_err err = {0};
    ef_camera cam;
    assert_int_equal(ef_camera_file_frame(cf, 1001, &fl, &err), 0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &cam, &err), 0);
    const double pos[3] = { 0, -10, 1.5 }, fwd[3] = { 0, 1, 0 }, z[3] = { 0, 0, 1 };
    assert_vec(cam.pos, pos, TOL);
    double w[3];
    ef_camera_to_world_dir(&cam, z, w);
    assert_vec(w, fwd, TOL);
    assert_close(cam.hfov_deg, 2 * atan(36.0 / 70.0) * 180 / PI, 1e-9);
    assert_close(cam.near_.v, 0.1, 0.0);
    assert_close(cam.far_.v, 1000, 0.0);
    ef_camera_file_free(cf);

    char *chan = doc_block(doc, "```\n# written by Nuke");
    cf = load("doc.chan", chan, EF_CONV_EXR);
    free(chan);
    assert_string_equal(ef_camera_file_describe(cf),
                        "Nuke .chan, rotation order ZXY, 2 frames 1001 to 1002, vertical fov");
    ef_camera_file_free(cf);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_json_conventions),
        cmocka_unit_test(test_json_lens_and_forms),
        cmocka_unit_test(test_json_errors),
        cmocka_unit_test(test_chan),
        cmocka_unit_test(test_chan_errors),
        cmocka_unit_test(test_missing_frame),
        cmocka_unit_test(test_doc_examples),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
