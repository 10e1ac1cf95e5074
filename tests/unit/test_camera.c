/* ef_camera_resolve: each metadata family and the flags, against poses and
 * rays worked out by hand or from the pinhole formula written out here. */
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



static ef_mat4 mk(const double v[16])
{
    ef_mat4 m;
    for (int i = 0; i < 16; ++i)
        m.m[i] = v[i];
    return m;
}

/* Row-vector product written out, independent of ef_mat4_mul. */
static ef_mat4 mul(const ef_mat4 a, const ef_mat4 b)
{
    ef_mat4 r;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            r.m[4 * i + j] = a.m[4 * i] * b.m[j] + a.m[4 * i + 1] * b.m[4 + j]
                           + a.m[4 * i + 2] * b.m[8 + j] + a.m[4 * i + 3] * b.m[12 + j];
    return r;
}

static void set_mat(ef_opt_mat *o, ef_mat4 m)
{
    o->set = 1;
    o->v = m;
}

static void set_num(ef_opt_num *o, double v)
{
    o->set = 1;
    o->v = v;
}

/* The expected camera-space ray of absolute pixel (x, y) for a centred
 * pinhole (reference doc section 5.3). */
static void pinhole(const ef_cam_meta *m, double hfov_deg, int x, int y, double d[3])
{
    const double W = m->disp[2] - m->disp[0] + 1, H = m->disp[3] - m->disp[1] + 1;
    const double u = (x + 0.5 - m->disp[0]) / W, v = (y + 0.5 - m->disp[1]) / H;
    const double t = tan(hfov_deg * PI / 360.0);
    d[0] = t * (2 * u - 1);
    d[1] = t * (1 - 2 * v) * H / (W * m->pixel_aspect);
    d[2] = 1.0;
}

static void assert_rays_match(const ef_camera *cam, const ef_cam_meta *m, double hfov,
                              double tol)
{
    for (int y = m->disp[1]; y <= m->disp[3]; y += 3)
        for (int x = m->disp[0]; x <= m->disp[2]; x += 5) {
            double got[3], want[3];
            ef_camera_ray(cam, x, y, got);
            pinhole(m, hfov, x, y, want);
            assert_close(got[0], want[0], tol);
            assert_close(got[1], want[1], tol);
            assert_close(got[2], 1.0, 0.0);
        }
}

/* Camera-space vector to world with the resolved rotation. */
static void to_world(const ef_camera *c, double x, double y, double z, double out[3])
{
    const double v[3] = {x, y, z};
    ef_camera_to_world_dir(c, v, out);
}

static void assert_vec(const double got[3], double x, double y, double z, double tol)
{
    assert_close(got[0], x, tol);
    assert_close(got[1], y, tol);
    assert_close(got[2], z, tol);
}

/* Angle in degrees between two vectors. */
static double angle_deg(const double a[3], const double b[3])
{
    const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const double la = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    const double lb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    return acos(dot / (la * lb)) * 180.0 / PI;
}

/* D3D-LH camera->screen matrix: x,y in [-1,1] over the frame, y up,
 * w = z_cam, z in [0,1] from near to far. */
static ef_mat4 screen_proj(double hfov, double W, double H, double pa, double n, double f)
{
    const double sx = 1.0 / tan(hfov * PI / 360.0), sy = sx * W * pa / H;
    const double A = f / (f - n), B = -n * f / (f - n);
    const double m[16] = {sx, 0, 0, 0, 0, sy, 0, 0, 0, 0, A, 1, 0, 0, B, 0};
    return mk(m);
}

/* RenderMan-style camera->NDC: x,y in [0,1], y down, (0,0) top-left. */
static ef_mat4 ndc_proj(double hfov, double W, double H, double pa, double n, double f)
{
    const double sx = 1.0 / tan(hfov * PI / 360.0), sy = sx * W * pa / H;
    const double A = f / (f - n), B = -n * f / (f - n);
    const double m[16] = {0.5 * sx, 0, 0, 0, 0, -0.5 * sy, 0, 0, 0.5, 0.5, A, 1, 0, 0, B, 0};
    return mk(m);
}

/* Arnold-like: camera at (0,0,7.2625) looking down world -Z, Z flip baked
 * into worldToCamera, screen matrix stored under the name worldToNDC. */
static const double arnold_w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 7.2625, 1};

static void arnold_meta(ef_cam_meta *m)
{
    ef_cam_meta_init(m, 0, 0, 149, 99);
    set_mat(&m->w2c, mk(arnold_w2c));
    set_mat(&m->w2ndc, mul(mk(arnold_w2c), screen_proj(50, 150, 100, 1, 0.01, 1e5)));
}

static void test_arnold_screen(void **state)
{
    (void)state;
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    arnold_meta(&m);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_vec(c.pos, 0, 0, 7.2625, 1e-12);
    double fwd[3], up[3], right[3];
    to_world(&c, 0, 0, 1, fwd);
    to_world(&c, 0, 1, 0, up);
    to_world(&c, 1, 0, 0, right);
    assert_vec(fwd, 0, 0, -1, 1e-15);
    assert_vec(up, 0, 1, 0, 1e-15);
    assert_vec(right, 1, 0, 0, 1e-15);
    assert_int_equal(c.proj, EF_PROJ_SCREEN);
    assert_contains(c.src_proj, "worldToNDC");
    assert_contains(c.src_proj, "screen");
    assert_close(c.hfov_deg, 50.0, 1e-6);
    assert_rays_match(&c, &m, 50.0, 1e-12);
    /* The pixel footprint lod=pixel reads: 2 tan(hfov / 2) / W on the axis. */
    assert_close(ef_camera_pixel_spread(&c), 2 * tan(25 * PI / 180) / 150, 1e-15);
    /* [0,1] hypothesis: n = -beta/alpha, f = beta/(1-alpha). */
    assert_true(c.near_.set && c.far_.set);
    assert_close(c.near_.v, 0.01, 1e-12);
    assert_close(c.far_.v, 1e5, 1e-2);
    assert_string_equal(c.src_near, "projection matrix");
    assert_close(c.proj_alpha, 1e5 / (1e5 - 0.01), 1e-12);
    assert_close(c.proj_beta, -0.01 * 1e5 / (1e5 - 0.01), 1e-15);

    /* Clip metadata wins over the matrix. */
    set_num(&m.arnold_near, 0.02);
    set_num(&m.arnold_far, 5e4);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_close(c.near_.v, 0.02, 0.0);
    assert_close(c.far_.v, 5e4, 0.0);
    assert_string_equal(c.src_near, "header arnold/camera/near_clip");
    assert_string_equal(c.src_far, "header arnold/camera/far_clip");
}

/* A screen matrix made for 16:9 on a square display window (a crop after
 * rendering, as OIIO's cryptoasset.exr): still resolves, with a warning
 * that names both aspects; a matching one gives no warning. */
static void test_aspect_warning(void **state)
{
    (void)state;
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    arnold_meta(&m);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_string_equal(c.warning, "");
    ef_cam_meta_init(&m, 0, 0, 31, 31);
    set_mat(&m.w2c, mk(arnold_w2c));
    set_mat(&m.w2ndc, mul(mk(arnold_w2c), screen_proj(50, 1920, 1080, 1, 0.1, 1e4)));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_contains(c.warning, "1.778");
    assert_contains(c.warning, "32x32");
    /* Anamorphic pixels that match the matrix are fine. */
    ef_cam_meta_init(&m, 0, 0, 99, 99);
    m.pixel_aspect = 2.0;
    set_mat(&m.w2c, mk(arnold_w2c));
    set_mat(&m.w2ndc, mul(mk(arnold_w2c), screen_proj(50, 100, 100, 2.0, 0.1, 1e4)));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_string_equal(c.warning, "");
}

/* Float32 matrices (as Arnold writes M44f) and a camera far from the origin:
 * still recognised as a perspective screen matrix. */
static void test_arnold_float32(void **state)
{
    (void)state;
    /* Camera at C looking down world -Z: w2c translation = -C . R^T, R = diag(1,1,-1). */
    const double C[3] = {1250.0, -340.0, 5300.0};
    const double w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, -C[0], -C[1], C[2], 1};
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    ef_cam_meta_init(&m, 0, 0, 149, 99);
    ef_mat4 M = mul(mk(w2c), screen_proj(50, 150, 100, 1, 0.01, 1e5));
    for (int i = 0; i < 16; ++i)
        M.m[i] = (float)M.m[i];
    set_mat(&m.w2c, mk(w2c));
    set_mat(&m.w2screen, M);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_int_equal(c.proj, EF_PROJ_SCREEN);
    assert_contains(c.src_proj, "worldToScreen");
    assert_close(c.hfov_deg, 50.0, 1e-2);
    assert_vec(c.pos, C[0], C[1], C[2], 1e-9);
}

/* True NDC (RenderMan): y down, centre at 0.5; same rays as the fov camera.
 * Rotated camera, offset display window, non-square pixels. */
static void test_true_ndc(void **state)
{
    (void)state;
    /* c2w rows: camera x -> world (0,0,1), y -> (0,1,0), z -> (1,0,0),
     * at (2,3,4). w2c = [R^T; -C R^T]; R is symmetric here, so R^T = R. */
    const double w2c[16] = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0, -4, -3, -2, 1};
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    ef_cam_meta_init(&m, 10, 20, 49, 39);
    m.pixel_aspect = 2.0;
    set_mat(&m.w2c, mk(w2c));
    set_mat(&m.w2ndc, mul(mk(w2c), ndc_proj(40, 40, 20, 2.0, 0.1, 100)));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_int_equal(c.proj, EF_PROJ_NDC);
    assert_contains(c.src_proj, "NDC");
    assert_vec(c.pos, 2, 3, 4, 1e-15);
    double fwd[3];
    to_world(&c, 0, 0, 1, fwd);
    assert_vec(fwd, 1, 0, 0, 1e-15);
    assert_rays_match(&c, &m, 40.0, 1e-12);
    assert_close(c.hfov_deg, 40.0, 1e-9);
    assert_close(c.near_.v, 0.1, 1e-12);
    assert_close(c.far_.v, 100, 1e-8);

    /* The name does not matter: the same NDC matrix under worldToScreen. */
    m.w2screen = m.w2ndc;
    m.w2ndc.set = 0;
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_int_equal(c.proj, EF_PROJ_NDC);
    assert_string_equal(c.src_proj, "header worldToScreen (classified as NDC)");
    assert_rays_match(&c, &m, 40.0, 1e-12);
}

/* The Arnold fov attribute with worldToCamera and no projection matrix. */
static void test_arnold_fov(void **state)
{
    (void)state;
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    ef_cam_meta_init(&m, 0, 0, 99, 49);
    set_mat(&m.w2c, mk(arnold_w2c));
    set_num(&m.arnold_fov, 65.0);
    set_num(&m.arnold_near, 0.5);
    set_num(&m.vray_near, 7.0); /* another family: ignored */
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_int_equal(c.proj, EF_PROJ_NONE);
    assert_string_equal(c.src_fov, "header CameraFov");
    assert_close(c.hfov_deg, 65.0, 0.0);
    assert_rays_match(&c, &m, 65.0, 1e-14);
    assert_close(c.near_.v, 0.5, 0.0);
    assert_false(c.far_.set);
}

/* V-Ray: cameraTransform is camera-to-world for a camera looking down its
 * own -Z. Rows: x -> (1,0,0), y -> (0,0,1), z -> (0,-1,0), at (0,5,20).
 * It looks along -(0,-1,0) = +Y world, with +Z world up (V-Ray is Z-up),
 * and right = forward x up = (0,1,0) x (0,0,1) = (1,0,0). */
static void test_vray(void **state)
{
    (void)state;
    const double c2w[16] = {1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 5, 20, 1};
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    ef_cam_meta_init(&m, 0, 0, 959, 539);
    set_mat(&m.vray_c2w, mk(c2w));
    set_num(&m.vray_fov, 54.43);
    set_num(&m.vray_near, 0.0);  /* clipping off */
    set_num(&m.vray_far, 1e30);  /* clipping off */
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_contains(c.src_pose, "cameraTransform");
    assert_string_equal(c.src_fov, "header cameraFov");
    assert_vec(c.pos, 0, 5, 20, 0.0);
    /* Principal ray: through the frame centre (pixel coordinate 480, 270). */
    double d[3], w[3];
    ef_camera_ray(&c, 479.5, 269.5, d);
    assert_vec(d, 0, 0, 1, 1e-15);
    ef_camera_to_world_dir(&c, d, w);
    assert_vec(w, 0, 1, 0, 1e-15);
    double up[3], right[3];
    to_world(&c, 0, 1, 0, up);
    to_world(&c, 1, 0, 0, right);
    assert_vec(up, 0, 0, 1, 0.0);
    assert_vec(right, 1, 0, 0, 0.0);
    /* Left and right frame edges at mid height span the fov, and the left
     * edge leans toward -X world. */
    double l[3], r[3], lw[3], rw[3];
    ef_camera_ray(&c, -0.5, 269.5, l);
    ef_camera_ray(&c, 959.5, 269.5, r);
    ef_camera_to_world_dir(&c, l, lw);
    ef_camera_to_world_dir(&c, r, rw);
    assert_close(angle_deg(lw, rw), 54.43, 1e-9);
    assert_close(lw[0], -tan(54.43 * PI / 360.0), 1e-14);
    assert_close(lw[1], 1.0, 1e-15);
    assert_close(c.hfov_deg, 54.43, 0.0);
    /* Top edge leans toward +Z world (up), by the vertical half-angle. */
    double t[3], tw[3];
    ef_camera_ray(&c, 479.5, -0.5, t);
    ef_camera_to_world_dir(&c, t, tw);
    assert_close(tw[2], tan(54.43 * PI / 360.0) * 540.0 / 960.0, 1e-14);
    assert_false(c.near_.set);
    assert_false(c.far_.set);

    /* Real clip values are taken. */
    set_num(&m.vray_near, 0.25);
    set_num(&m.vray_far, 800.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_close(c.near_.v, 0.25, 0.0);
    assert_close(c.far_.v, 800.0, 0.0);
    assert_string_equal(c.src_far, "header cameraFarClip");
}

/* Redshift: camera-to-world, -Z forward, fov in radians (or degrees if > pi). */
static void test_redshift(void **state)
{
    (void)state;
    /* Identity rotation at (1,2,3): looks down world -Z, Y up, X right. */
    const double c2w[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 2, 3, 1};
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    ef_cam_meta_init(&m, 0, 0, 63, 47);
    set_mat(&m.rs_c2w, mk(c2w));
    set_num(&m.rs_fov, 0.8);
    set_num(&m.rs_near, 0.1);
    set_num(&m.rs_far, 500.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_vec(c.pos, 1, 2, 3, 0.0);
    double fwd[3], up[3], right[3];
    to_world(&c, 0, 0, 1, fwd);
    to_world(&c, 0, 1, 0, up);
    to_world(&c, 1, 0, 0, right);
    assert_vec(fwd, 0, 0, -1, 0.0);
    assert_vec(up, 0, 1, 0, 0.0);
    assert_vec(right, 1, 0, 0, 0.0);
    const double deg = 0.8 * 180.0 / PI; /* 45.836... */
    assert_close(c.hfov_deg, deg, 1e-12);
    assert_rays_match(&c, &m, deg, 1e-14);
    assert_close(c.near_.v, 0.1, 0.0);
    assert_close(c.far_.v, 500.0, 0.0);
    assert_string_equal(c.src_near, "header rs/camera/nearPlane");

    /* 60 cannot be radians (> pi): read as degrees. */
    set_num(&m.rs_fov, 60.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_close(c.hfov_deg, 60.0, 0.0);
    assert_contains(c.src_fov, "degrees");
}

/* Pose precedence: worldToCamera beats V-Ray beats Redshift. */
static void test_precedence(void **state)
{
    (void)state;
    const double vray[16] = {1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 5, 20, 1};
    const double rs[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 2, 3, 1};
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    ef_cam_meta_init(&m, 0, 0, 9, 9);
    set_mat(&m.vray_c2w, mk(vray));
    set_num(&m.vray_fov, 30);
    set_mat(&m.rs_c2w, mk(rs));
    set_num(&m.rs_fov, 1.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_vec(c.pos, 0, 5, 20, 0.0);
    assert_close(c.hfov_deg, 30, 0.0);
    set_mat(&m.w2c, mk(arnold_w2c));
    set_num(&m.arnold_fov, 20);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_vec(c.pos, 0, 0, 7.2625, 0.0);
    assert_close(c.hfov_deg, 20, 0.0);
}

/* Flags override the header: pose, fov, clip planes. */
static void test_flags(void **state)
{
    (void)state;
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    arnold_meta(&m);
    set_num(&m.arnold_near, 0.02);

    /* --world-to-camera: camera at (10,0,0), camera axes = world axes. */
    const double w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -10, 0, 0, 1};
    set_mat(&fl.w2c, mk(w2c));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_string_equal(c.src_pose, "flag --world-to-camera");
    assert_vec(c.pos, 10, 0, 0, 0.0);
    double fwd[3];
    to_world(&c, 0, 0, 1, fwd);
    assert_vec(fwd, 0, 0, 1, 0.0);
    /* The header lens still applies (taken relative to the header camera). */
    assert_close(c.hfov_deg, 50.0, 1e-6);
    assert_rays_match(&c, &m, 50.0, 1e-12);

    /* --camera-to-world: the matrix itself; it wins over nothing but --world-to-camera. */
    fl.w2c.set = 0;
    const double c2w[16] = {0, 0, -1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 7, 8, 9, 1};
    set_mat(&fl.c2w, mk(c2w));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_string_equal(c.src_pose, "flag --camera-to-world");
    assert_vec(c.pos, 7, 8, 9, 1e-15);
    to_world(&c, 0, 0, 1, fwd);
    assert_vec(fwd, 1, 0, 0, 1e-15);

    /* --fov replaces the projection matrix. */
    set_num(&fl.fov, 70.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_int_equal(c.proj, EF_PROJ_NONE);
    assert_string_equal(c.src_fov, "flag --fov");
    assert_close(c.hfov_deg, 70.0, 0.0);
    assert_rays_match(&c, &m, 70.0, 1e-14);
    /* A flag pose with a flag lens takes no clip plane from the header. */
    assert_false(c.near_.set);

    /* --fov with the header pose: header clip metadata still applies. */
    fl.c2w.set = 0;
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_string_equal(c.src_pose, "header worldToCamera");
    assert_close(c.near_.v, 0.02, 0.0);

    /* --near / --far override the header and the matrix. */
    fl.fov.set = 0;
    set_num(&fl.near_, 0.3);
    set_num(&fl.far_, 3000.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_close(c.near_.v, 0.3, 0.0);
    assert_close(c.far_.v, 3000.0, 0.0);
    assert_string_equal(c.src_near, "flag --near");
    assert_string_equal(c.src_far, "flag --far");
    assert_int_equal(c.proj, EF_PROJ_SCREEN);
}

static void test_errors(void **state)
{
    (void)state;
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};

    /* Nothing at all. */
    ef_cam_meta_init(&m, 0, 0, 9, 9);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "--world-to-camera");
    assert_contains(err.msg, "--camera-to-world");
    assert_contains(err.msg, "--fov");
    assert_contains(err.msg, "worldToCamera");
    assert_contains(err.msg, "cameraTransform");
    assert_contains(err.msg, "rs/camera/transform");

    /* A projection and an fov but no pose: the message lists them. */
    set_mat(&m.w2ndc, screen_proj(50, 10, 10, 1, 0.1, 10));
    set_num(&m.arnold_fov, 50);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "worldToNDC");
    assert_contains(err.msg, "CameraFov");

    /* NaN in worldToCamera. */
    ef_mat4 bad = mk(arnold_w2c);
    bad.m[5] = NAN;
    set_mat(&m.w2c, bad);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "worldToCamera holds NaN/Inf");

    /* Inf in the projection matrix that is used. */
    set_mat(&m.w2c, mk(arnold_w2c));
    m.w2ndc.v.m[0] = INFINITY;
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "worldToNDC holds NaN/Inf");

    /* Pose without any fov. */
    ef_cam_meta_init(&m, 0, 0, 9, 9);
    set_mat(&m.w2c, mk(arnold_w2c));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "no field of view");
    assert_contains(err.msg, "--fov DEG");
    /* V-Ray pose, and only another family's fov. */
    ef_cam_meta_init(&m, 0, 0, 9, 9);
    const double vray[16] = {1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 5, 20, 1};
    set_mat(&m.vray_c2w, mk(vray));
    set_num(&m.rs_fov, 0.5);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "--fov DEG");
    /* Non-finite fov. */
    set_num(&m.vray_fov, NAN);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "cameraFov holds NaN/Inf");
    /* fov outside (0, 180). */
    set_num(&m.vray_fov, 180.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "cameraFov");
    set_num(&fl.fov, 0.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "--fov");
    set_num(&fl.fov, -10.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    fl.fov.set = 0;
    /* Non-finite clip metadata of the family in use. */
    set_num(&m.vray_fov, 40.0);
    set_num(&m.vray_near, INFINITY);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "cameraNearClip");

    /* Singular pose. */
    ef_cam_meta_init(&m, 0, 0, 9, 9);
    const double sing[16] = {1, 0, 0, 0, 2, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    set_mat(&m.w2c, mk(sing));
    set_num(&m.arnold_fov, 50);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "singular");
    /* A transposed (column-vector) pose. */
    const double tr[16] = {1, 0, 0, 5, 0, 1, 0, 6, 0, 0, 1, 7, 0, 0, 0, 1};
    set_mat(&m.w2c, mk(tr));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "transposed");
    /* Non-finite flag matrix. */
    ef_mat4 nanflag = mk(arnold_w2c);
    nanflag.m[12] = NAN;
    set_mat(&fl.w2c, nanflag);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_string_equal(err.msg, "--world-to-camera holds NaN/Inf");
    fl.w2c.set = 0;
    /* Singular flag matrix. */
    set_mat(&fl.c2w, mk(sing));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "--camera-to-world");
    fl.c2w.set = 0;

    /* Orthographic projection matrix: w column (0,0,0,1). */
    ef_cam_meta_init(&m, 0, 0, 9, 9);
    set_mat(&m.w2c, mk(arnold_w2c));
    const double ortho[16] = {0.1, 0, 0, 0, 0, 0.1, 0, 0, 0, 0, 0.01, 0, 0, 0, 0, 1};
    set_mat(&m.w2screen, mul(mk(arnold_w2c), mk(ortho)));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "orthographic");
    /* Screen content but y down: neither class. */
    ef_mat4 flip = screen_proj(50, 10, 10, 1, 0.1, 10);
    flip.m[5] = -flip.m[5];
    set_mat(&m.w2screen, mul(mk(arnold_w2c), flip));
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "--fov");

    /* Bad display window and pixel aspect. */
    ef_cam_meta_init(&m, 0, 0, -1, 9);
    set_mat(&m.w2c, mk(arnold_w2c));
    set_num(&m.arnold_fov, 50);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    ef_cam_meta_init(&m, 0, 0, 9, 9);
    set_mat(&m.w2c, mk(arnold_w2c));
    set_num(&m.arnold_fov, 50);
    m.pixel_aspect = 0.0;
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "pixelAspectRatio");
}

/* Pixel centres by hand: hfov 90 => tan(45) = 1. */
static void test_pixel_centres(void **state)
{
    (void)state;
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    const double id[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    set_mat(&fl.w2c, mk(id));
    set_num(&fl.fov, 90.0);
    double d[3];

    /* 2x1 display: u = 0.25 and 0.75, v = 0.5. */
    ef_cam_meta_init(&m, 0, 0, 1, 0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    ef_camera_ray(&c, 0, 0, d);
    assert_vec(d, -0.5, 0.0, 1.0, 1e-15);
    ef_camera_ray(&c, 1, 0, d);
    assert_vec(d, 0.5, 0.0, 1.0, 1e-15);

    /* 4x2 display: half-height tan = 2/4; pixel (0,0): u = 1/8, v = 1/4. */
    ef_cam_meta_init(&m, 0, 0, 3, 1);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    ef_camera_ray(&c, 0, 0, d);
    assert_vec(d, -0.75, 0.25, 1.0, 1e-15);
    ef_camera_ray(&c, 3, 1, d);
    assert_vec(d, 0.75, -0.25, 1.0, 1e-15);

    /* Same frame shifted to (100,-50): absolute coordinates follow it. */
    ef_cam_meta_init(&m, 100, -50, 103, -49);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    ef_camera_ray(&c, 100, -50, d);
    assert_vec(d, -0.75, 0.25, 1.0, 1e-14);
    ef_camera_ray(&c, 102, -49, d);
    assert_vec(d, 0.25, -0.25, 1.0, 1e-14);

    /* Pixel aspect 2 (wide pixels): a 2x2 image is 4:2 on screen. */
    ef_cam_meta_init(&m, 0, 0, 1, 1);
    m.pixel_aspect = 2.0;
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    ef_camera_ray(&c, 0, 0, d);
    assert_vec(d, -0.5, 0.25, 1.0, 1e-15);
}

/* Arnold's worldToCamera with its 3x3 and translation scaled by s, and
 * --fov 50, on a 150 x 100 frame. */
static int resolve_scaled(double s, ef_camera *c, ef_err *err)
{
    double w[16];
    memcpy(w, arnold_w2c, sizeof w);
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 3; ++j)
            w[4 * i + j] *= s;
    ef_cam_meta m;
    ef_cam_meta_init(&m, 0, 0, 149, 99);
    set_mat(&m.w2c, mk(w));
    ef_cam_flags fl = {0};
    fl.fov.set = 1;
    fl.fov.v = 50;
    return ef_camera_resolve(&m, &fl, c, err);
}

/* A pose with a uniform scale s (worldToCamera = s * rigid in its 3x3 and
 * translation) is the rigid camera with camera units of 1/s world units.
 * By hand: the camera sits at (0, 0, 7.2625) looking down world -Z; pixel
 * (px, 60) of the 150-wide, 50-degree frame has the camera-space direction
 * (dx, dy, 1) with dx = (px + 0.5 - 75) t, |dy| = 10.5 t, t = 2 tan(25 deg)
 * / 150, so a planar depth of 10 s camera units is 10 |(dx, dy, 1)| world
 * units away. Checked for s near both ends of the accepted range; 1e300 is
 * refused with a message; a shear warns. */
static void test_scaled_pose(void **state)
{
    (void)state;
    static const double scales[] = { 1e-25, 3.7e-9, 0.5, 1e7 };   /* depth 10 s stays below EF_SKY_DISTANCE */
    const double t = 2 * tan(25 * PI / 180) / 150;
    ef_camera c;
    ef_err err = {0};
    for (size_t k = 0; k < sizeof scales / sizeof scales[0]; ++k) {
        const double s = scales[k];
        assert_int_equal(resolve_scaled(s, &c, &err), 0);
        ef_depth_conv conv;
        assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_PLANAR, &c, &err), 0);
        assert_true(fabs(c.unit * s - 1) < 1e-12);
        assert_vec(c.pos, 0, 0, 7.2625, 1e-12);
        assert_true(c.warning[0] == '\0');
        for (int px = 0; px < 150; px += 37) {
            const double dx = (px + 0.5 - 75) * t, dy = 10.5 * t, n = sqrt(dx * dx + dy * dy + 1);
            ef_ray r;
            ef_reconstruct(&c, &conv, px, 60, 10.0 * s, &r);
            if (!(fabs(r.dist - 10 * n) < 1e-12 * 10 * n))
                fail_msg("s %g px %d: dist %.17g, by hand %.17g", s, px, r.dist, 10 * n);
            assert_true(fabs(r.dir[0] - dx / n) < 1e-14);
            assert_true(fabs(fabs(r.dir[1]) - dy / n) < 1e-14);
            assert_true(fabs(r.dir[2] + 1 / n) < 1e-14);
        }
    }
    /* Beyond 1e30 either way: refused, saying why. */
    assert_int_equal(resolve_scaled(1e300, &c, &err), -1);
    assert_non_null(strstr(err.msg, "between 1e-30 and 1e30"));
    assert_int_equal(c.flag_error, 0);
    assert_int_equal(resolve_scaled(1e-300, &c, &err), -1);
    assert_non_null(strstr(err.msg, "between 1e-30 and 1e30"));
    /* A shear: accepted with a warning. */
    double w[16];
    memcpy(w, arnold_w2c, sizeof w);
    w[4] = 0.5;
    ef_cam_meta m;
    ef_cam_meta_init(&m, 0, 0, 149, 99);
    set_mat(&m.w2c, mk(w));
    ef_cam_flags fl = {0};
    fl.fov.set = 1;
    fl.fov.v = 50;
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_non_null(strstr(c.warning, "not rigid"));
}

/* A vertical fov (a camera file's, e.g. Nuke .chan) becomes the horizontal
 * one through the display window's aspect and the pixel aspect. By hand:
 * 200x100 pixels, vfov 90 => tan(v/2) = 1, tan(h/2) = 1 * 200/100 = 2,
 * h = 2 atan 2 = 126.86989764584402 degrees; the top-left pixel's centre
 * (0.5, 0.5) is at u = 0.0025, v = 0.005: dir = (-2 * 0.995, 1 * 0.99, 1). */
static void test_vfov(void **state)
{
    (void)state;
    ef_cam_meta m;
    ef_cam_flags fl = {0};
    ef_camera c;
    ef_err err = {0};
    const double id[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    ef_cam_meta_init(&m, 0, 0, 199, 99);
    set_mat(&fl.w2c, mk(id));
    set_num(&fl.vfov, 90.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_close(c.hfov_deg, 126.86989764584402, 1e-12);
    assert_contains(c.src_fov, "vertical");
    double d[3];
    ef_camera_ray(&c, 0, 0, d);
    assert_vec(d, -1.99, 0.99, 1.0, 1e-14);
    /* The bottom-right pixel: the mirror image. */
    ef_camera_ray(&c, 199, 99, d);
    assert_vec(d, 1.99, -0.99, 1.0, 1e-14);

    /* Square pixels of aspect 2 on a 100x100 window: tan(h/2) = 1 * 100 * 2 / 100
     * = 2 again; the vertical half-angle stays 45 degrees (top edge at y = 1). */
    ef_cam_meta_init(&m, 0, 0, 99, 99);
    m.pixel_aspect = 2.0;
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), 0);
    assert_close(c.hfov_deg, 126.86989764584402, 1e-12);
    ef_camera_ray(&c, 0, 0, d);
    assert_vec(d, -1.98, 0.99, 1.0, 1e-14);

    /* A vfov outside (0, 180) and a NaN one. */
    set_num(&fl.vfov, 180.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "vfov");
    set_num(&fl.vfov, NAN);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "NaN");

    /* Both a horizontal and a vertical fov: a usage error. */
    set_num(&fl.vfov, 40.0);
    set_num(&fl.fov, 50.0);
    assert_int_equal(ef_camera_resolve(&m, &fl, &c, &err), -1);
    assert_contains(err.msg, "only one");
    assert_true(c.flag_error);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_arnold_screen),
        cmocka_unit_test(test_arnold_float32),
        cmocka_unit_test(test_true_ndc),
        cmocka_unit_test(test_arnold_fov),
        cmocka_unit_test(test_vray),
        cmocka_unit_test(test_redshift),
        cmocka_unit_test(test_precedence),
        cmocka_unit_test(test_flags),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_pixel_centres),
        cmocka_unit_test(test_aspect_warning),
        cmocka_unit_test(test_scaled_pose),
        cmocka_unit_test(test_vfov),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
