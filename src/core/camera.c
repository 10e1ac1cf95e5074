#include "camera.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define EF_PI 3.14159265358979323846

/* Which header family supplied a part of the camera; clip planes are only
 * taken from the family that supplied the pose (or, for a flag pose, the lens). */
typedef enum fam { FAM_NONE = 0, FAM_EXR, FAM_VRAY, FAM_RS } fam;

void ef_cam_meta_init(ef_cam_meta *meta, int xmin, int ymin, int xmax, int ymax)
{
    memset(meta, 0, sizeof *meta);
    meta->disp[0] = xmin;
    meta->disp[1] = ymin;
    meta->disp[2] = xmax;
    meta->disp[3] = ymax;
    meta->pixel_aspect = 1.0;
}

/* Flag names start with "--"; only header attributes get the flag hint. */
static int check_mat(const ef_mat4 *m, const char *name, ef_err *err)
{
    if (!ef_mat4_finite(m))
        return ef_fail(err, "%s holds NaN/Inf%s", name, name[0] == '-' ? ""
                       : "; fix the header or pass --world-to-camera M and --fov DEG");
    return 0;
}

static int check_num(double v, const char *name, ef_err *err)
{
    if (!isfinite(v))
        return ef_fail(err, "%s holds NaN/Inf", name);
    return 0;
}

/* Pose matrices must be affine in the row-vector layout; a transposed
 * (column-vector) matrix shows up as a non-zero last column. */
static int check_affine(const ef_mat4 *m, const char *name, ef_err *err)
{
    const double *a = m->m;
    double mx = 0.0;
    for (int i = 0; i < 16; ++i)
        mx = fmax(mx, fabs(a[i]));
    const double tol = 1e-6 * mx;
    if (fabs(a[3]) > tol || fabs(a[7]) > tol || fabs(a[11]) > tol
        || fabs(a[15] - 1.0) > 1e-6)
        return ef_fail(err, "%s is not an affine row-vector matrix (its last "
                            "column should be 0 0 0 1; is it transposed?)", name);
    return 0;
}

/* The inverse of an affine row-vector pose whose entries may lie near
 * either end of the double range (a pose scaled by 1e300 or 1e-300): the
 * 3x3 and the translation are divided by the largest 3x3 entry k first, so
 * no cofactor overflows or underflows; [A/k; t/k]^-1 = [k A^-1; -t A^-1],
 * and dividing its 3x3 by k gives the true inverse. */
static int invert_pose(const ef_mat4 *m, ef_mat4 *out)
{
    double k = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            k = fmax(k, fabs(m->m[4 * i + j]));
    if (!(k > 0) || !isfinite(k))
        return -1;
    ef_mat4 a = *m;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 3; ++j)
            a.m[4 * i + j] /= k;
    if (ef_mat4_invert(&a, out) != 0)
        return -1;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            out->m[4 * i + j] /= k;
    return ef_mat4_finite(out) ? 0 : -1;
}

/* Inverse of a matrix the user or header named, with a message if singular. */
static int invert_named(const ef_mat4 *m, ef_mat4 *out, const char *name, ef_err *err)
{
    if (invert_pose(m, out) != 0)
        return ef_fail(err, "%s is singular (not invertible); fix it or pass "
                            "--world-to-camera M and --fov DEG", name);
    return 0;
}

/* Camera attributes the header carries, for the "no camera" message. */
static void list_attrs(const ef_cam_meta *meta, char *buf, size_t n)
{
    const struct { int set; const char *name; } a[] = {
        {meta->w2ndc.set, "worldToNDC"},      {meta->w2screen.set, "worldToScreen"},
        {meta->arnold_fov.set, "CameraFov"},  {meta->arnold_near.set, "arnold/camera/near_clip"},
        {meta->arnold_far.set, "arnold/camera/far_clip"}, {meta->vray_fov.set, "cameraFov"},
        {meta->vray_near.set, "cameraNearClip"}, {meta->vray_far.set, "cameraFarClip"},
        {meta->rs_fov.set, "rs/camera/fov"},  {meta->rs_near.set, "rs/camera/nearPlane"},
        {meta->rs_far.set, "rs/camera/farPlane"},
    };
    size_t len = 0;
    buf[0] = '\0';
    for (size_t i = 0; i < sizeof a / sizeof a[0]; ++i)
        if (a[i].set && len < n)
            len += (size_t)snprintf(buf + len, n - len, "%s%s", len ? ", " : "", a[i].name);
    if (!len)
        snprintf(buf, n, "none");
}

int ef_cam_convention_parse(const char *name, ef_cam_convention *out)
{
    static const char *const names[] = { "exr", "blender", "nuke", "maya", "houdini", "usd" };
    for (int i = 0; i < (int) (sizeof names / sizeof names[0]); ++i)
        if (!strcmp(name, names[i])) {
            *out = (ef_cam_convention) i;
            return 0;
        }
    return -1;
}

/* A flag matrix in exrfog's convention: column-vector layouts transposed,
 * a -Z-forward camera's Z axis flipped (as for V-Ray's cameraTransform):
 * row 2 of a camera-to-world, column 2 of a world-to-camera. */
static ef_mat4 from_convention(const ef_mat4 *m, ef_cam_convention c, int is_w2c)
{
    ef_mat4 r = *m;
    if (c == EF_CONV_BLENDER || c == EF_CONV_NUKE)
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                r.m[4 * i + j] = m->m[4 * j + i];
    if (c != EF_CONV_EXR)
        for (int k = 0; k < 4; ++k) {
            if (is_w2c)
                r.m[4 * k + 2] = -r.m[4 * k + 2];
            else
                r.m[8 + k] = -r.m[8 + k];
        }
    return r;
}

/* The pose, in precedence order: flags, worldToCamera, V-Ray, Redshift. */
static int resolve_pose(const ef_cam_meta *meta, const ef_cam_flags *flags,
                        ef_mat4 *c2w, fam *f, ef_camera *cam, ef_err *err)
{
    const ef_mat4 *m;
    const char *name;
    int is_w2c = 0, minus_z = 0;
    ef_mat4 conv;
    char fname[400];
    *f = FAM_NONE;
    if (flags->w2c.set || flags->c2w.set) {
        is_w2c = flags->w2c.set;
        conv = from_convention(is_w2c ? &flags->w2c.v : &flags->c2w.v, flags->convention, is_w2c);
        m = &conv;
        name = is_w2c ? "--world-to-camera" : "--camera-to-world";
        cam->src_pose = is_w2c ? "flag --world-to-camera" : "flag --camera-to-world";
        if (flags->pose_src) {
            /* A camera file's matrix: its errors name the file's key. */
            snprintf(fname, sizeof fname, "%s of %s",
                     is_w2c ? "world_to_camera" : "camera_to_world", flags->pose_src);
            name = fname;
            cam->src_pose = flags->pose_src;
        }
    } else if (meta->w2c.set) {
        m = &meta->w2c.v, name = "worldToCamera", is_w2c = 1, *f = FAM_EXR;
        cam->src_pose = "header worldToCamera";
    } else if (meta->vray_c2w.set) {
        m = &meta->vray_c2w.v, name = "cameraTransform", minus_z = 1, *f = FAM_VRAY;
        cam->src_pose = "header cameraTransform (camera-to-world, -Z forward)";
    } else if (meta->rs_c2w.set) {
        m = &meta->rs_c2w.v, name = "rs/camera/transform", minus_z = 1, *f = FAM_RS;
        cam->src_pose = "header rs/camera/transform (camera-to-world, -Z forward)";
    } else {
        char have[512];
        list_attrs(meta, have, sizeof have);
        return ef_fail(err, "no camera pose: the header has none of worldToCamera, "
                            "cameraTransform, rs/camera/transform (camera attributes "
                            "found: %s; other attributes: %s); pass --world-to-camera M or "
                            "--camera-to-world M (16 numbers, row-vector, as in the file) and "
                            "--fov DEG", have, meta->other_attrs[0] ? meta->other_attrs : "none");
    }
    if (check_mat(m, name, err) || check_affine(m, name, err))
        return -1;
    if (is_w2c)
        return invert_named(m, c2w, name, err);
    *c2w = *m;
    /* V-Ray and Redshift cameras look down their -Z (right-handed):
     * S = diag(1,1,-1,1) on the left flips the camera's own Z axis. */
    if (minus_z)
        for (int j = 0; j < 4; ++j)
            c2w->m[8 + j] = -c2w->m[8 + j];
    ef_mat4 w2c;
    return invert_named(c2w, &w2c, name, err);
}

/* Ray matrix of a centred pinhole with horizontal fov hfov_deg. */
static void fov_ray(ef_camera *cam, const ef_cam_meta *meta, double hfov_deg)
{
    const double W = meta->disp[2] - meta->disp[0] + 1.0;
    const double H = meta->disp[3] - meta->disp[1] + 1.0;
    const double t = tan(hfov_deg * (EF_PI / 360.0));
    const double k = t * H / (W * meta->pixel_aspect);
    memset(cam->ray, 0, sizeof cam->ray);
    cam->ray[0] = 2.0 * t / W;
    cam->ray[6] = -t * (1.0 + 2.0 * meta->disp[0] / W);
    cam->ray[4] = -2.0 * k / H;
    cam->ray[7] = k * (1.0 + 2.0 * meta->disp[1] / H);
    cam->ray[8] = 1.0;
    cam->hfov_deg = hfov_deg;
}

/* Angle between the rays through the left and right frame edges at mid height. */
static double ray_hfov(const ef_camera *cam, const ef_cam_meta *meta)
{
    const double ymid = 0.5 * (meta->disp[1] + meta->disp[3]);
    double a[3], b[3];
    ef_camera_ray(cam, meta->disp[0] - 0.5, ymid, a);
    ef_camera_ray(cam, meta->disp[2] + 0.5, ymid, b);
    const double c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                         a[0] * b[1] - a[1] * b[0]};
    const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    return atan2(sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]), dot) * (180.0 / EF_PI);
}

/* A projection made for another frame shape (the image was cropped or
 * reformatted after rendering) still gives rays, but they no longer match
 * the pixels: angle per pixel must be the same both ways, times the pixel
 * aspect. Worth a warning, not a refusal. */
static void check_aspect(ef_camera *cam, const ef_cam_meta *meta, const char *name)
{
    const double W = meta->disp[2] - meta->disp[0] + 1.0;
    const double H = meta->disp[3] - meta->disp[1] + 1.0;
    const double xm = 0.5 * (meta->disp[0] + meta->disp[2]);
    const double ym = 0.5 * (meta->disp[1] + meta->disp[3]);
    double l[3], r[3], t[3], b[3];
    ef_camera_ray(cam, meta->disp[0] - 0.5, ym, l);
    ef_camera_ray(cam, meta->disp[2] + 0.5, ym, r);
    ef_camera_ray(cam, xm, meta->disp[1] - 0.5, t);
    ef_camera_ray(cam, xm, meta->disp[3] + 0.5, b);
    const double per_px_x = (r[0] - l[0]) / W, per_px_y = (t[1] - b[1]) / H;
    const double ratio = per_px_x / (per_px_y * meta->pixel_aspect);
    if (isfinite(ratio) && fabs(ratio - 1.0) > 0.01)
        snprintf(cam->warning, sizeof cam->warning,
                 "%s implies a frame aspect of %.4g but the display window %gx%g (pixel aspect "
                 "%g) has %.4g; was the image cropped or reformatted after rendering? The rays "
                 "follow the matrix; pass --fov DEG to use the display window instead",
                 name, W / H * meta->pixel_aspect * ratio, W, H, meta->pixel_aspect,
                 W / H * meta->pixel_aspect);
}

/* Rays from a projection matrix, classified by where it sends the optical
 * axis (the attribute name is unreliable: Arnold writes screen space under
 * worldToNDC). c2w_hdr is the inverse of the header's own worldToCamera. */
/* The inverse of a 3x3 (row-major) by cofactors, with the rows scaled to
 * unit size first so no product overflows. Returns 0, or -1 if singular. */
static int invert3(const double a[9], double out[9])
{
    double s[3], m[9];
    for (int i = 0; i < 3; ++i) {
        s[i] = fmax(fmax(fabs(a[3 * i]), fabs(a[3 * i + 1])), fabs(a[3 * i + 2]));
        if (!(s[i] > 0) || !isfinite(s[i]))
            return -1;
        for (int j = 0; j < 3; ++j)
            m[3 * i + j] = a[3 * i + j] / s[i];
    }
    const double c00 = m[4] * m[8] - m[5] * m[7], c01 = m[5] * m[6] - m[3] * m[8],
                 c02 = m[3] * m[7] - m[4] * m[6];
    const double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
    if (!(fabs(det) > 1e-300) || !isfinite(det))
        return -1;
    const double inv[9] = { c00, m[2] * m[7] - m[1] * m[8], m[1] * m[5] - m[2] * m[4],
                            c01, m[0] * m[8] - m[2] * m[6], m[2] * m[3] - m[0] * m[5],
                            c02, m[1] * m[6] - m[0] * m[7], m[0] * m[4] - m[1] * m[3] };
    /* (S M)^-1 = M^-1 S^-1: column j of M^-1 divided by s[j] */
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            out[3 * i + j] = inv[3 * i + j] / det / s[j];
    return 0;
}

static int projection_ray(ef_camera *cam, const ef_cam_meta *meta,
                          const ef_mat4 *c2w_hdr, ef_err *err)
{
    const int scr = meta->w2screen.set;
    const ef_mat4 *M = scr ? &meta->w2screen.v : &meta->w2ndc.v;
    const char *name = scr ? "worldToScreen" : "worldToNDC";
    if (check_mat(M, name, err))
        return -1;
    ef_mat4 Pc, Q, absc, absm, Pabs;
    ef_mat4_mul(c2w_hdr, M, &Pc);
    /* |C2W|.|M| bounds the rounding in each entry of Pc: float32 headers
     * leave ~1e-7 of it where a perspective matrix has exact zeros. */
    for (int i = 0; i < 16; ++i) {
        absc.m[i] = fabs(c2w_hdr->m[i]);
        absm.m[i] = fabs(M->m[i]);
    }
    ef_mat4_mul(&absc, &absm, &Pabs);
    const double *p = Pc.m, *tol = Pabs.m;
    const double wz = p[11];
    const int w_const = fabs(wz) <= 1e-4 * tol[11];
    if (w_const && fabs(p[15]) > 1e-4 * tol[15])
        return ef_fail(err, "%s is an orthographic projection (its w column is 0 0 0 1); "
                            "exrfog needs a perspective camera", name);
    if (w_const || wz < 0.0 || fabs(p[3]) > 1e-4 * tol[3] || fabs(p[7]) > 1e-4 * tol[7]
        || fabs(p[15]) > 1e-4 * tol[15])
        return ef_fail(err, "%s is not a perspective projection looking down +Z of "
                            "worldToCamera; pass --fov DEG to ignore it", name);
    /* Where camera-space (0,0,1) lands. */
    const double cx = (p[8] + p[12]) / (p[11] + p[15]);
    const double cy = (p[9] + p[13]) / (p[11] + p[15]);
    int ndc;
    if (fabs(cx) < 0.25 && fabs(cy) < 0.25 && p[5] > 0.0)
        ndc = 0;
    else if (fabs(cx - 0.5) < 0.25 && fabs(cy - 0.5) < 0.25 && p[5] < 0.0)
        ndc = 1;
    else
        return ef_fail(err, "%s is neither a screen-space (centre 0,0, y up) nor an NDC "
                            "(centre 0.5,0.5, y down) projection (centre %g,%g); "
                            "pass --fov DEG to ignore it", name, cx, cy);
    if (ef_mat4_invert(&Pc, &Q) != 0)
        return ef_fail(err, "%s is singular (not invertible); pass --fov DEG to ignore it",
                       name);

    /* A: (px, py, 1) -> (sx, sy, 1), the display window onto screen or NDC. */
    const double W = meta->disp[2] - meta->disp[0] + 1.0;
    const double H = meta->disp[3] - meta->disp[1] + 1.0;
    double A[9] = {0};
    if (ndc) {
        A[0] = 1.0 / W;
        A[6] = -meta->disp[0] / W;
        A[4] = 1.0 / H;
        A[7] = -meta->disp[1] / H;
    } else {
        A[0] = 2.0 / W;
        A[6] = -1.0 - 2.0 * meta->disp[0] / W;
        A[4] = -2.0 / H;
        A[7] = 1.0 + 2.0 * meta->disp[1] / H;
    }
    A[8] = 1.0;
    /* B: (sx, sy, 1) -> the ray's direction, as the point at infinity
     * (d, 0) with (d, 0) . Pc = w (sx, sy, z, 1): only Pc's linear rows
     * 0..2 enter, in columns x, y and w, so the float32 noise of a far
     * camera's translation row (row 3) never tilts a ray. B is the inverse
     * of that 3x3. */
    double L3[9], B[9];
    static const int col[3] = { 0, 1, 3 };
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            L3[3 * i + j] = p[4 * i + col[j]];
    if (invert3(L3, B))
        return ef_fail(err, "%s is singular (not invertible); pass --fov DEG to ignore it",
                       name);
    (void) Q;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            cam->ray[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j]
                                + A[3 * i + 2] * B[6 + j];

    static const char *const srcs[2][2] = {
        {"header worldToNDC (classified as screen space)", "header worldToNDC (classified as NDC)"},
        {"header worldToScreen (classified as screen space)",
         "header worldToScreen (classified as NDC)"}};
    cam->src_fov = cam->src_proj = srcs[scr][ndc];
    cam->proj = ndc ? EF_PROJ_NDC : EF_PROJ_SCREEN;
    cam->proj_alpha = p[10] / wz;
    cam->proj_beta = p[14] / wz;
    cam->hfov_deg = ray_hfov(cam, meta);
    if (!isfinite(cam->hfov_deg) || !(cam->hfov_deg > 0.0 && cam->hfov_deg < 180.0))
        return ef_fail(err, "%s gives a field of view of %g degrees; pass --fov DEG",
                       name, cam->hfov_deg);
    check_aspect(cam, meta, name);
    return 0;
}

/* A field of view in degrees from a flag or attribute, checked. */
static int use_fov(ef_camera *cam, const ef_cam_meta *meta, double deg,
                   const char *name, const char *src, ef_err *err)
{
    if (check_num(deg, name, err))
        return -1;
    if (!(deg > 0.0 && deg < 180.0))
        return ef_fail(err, "%s gives a field of view of %g degrees; it must be "
                            "between 0 and 180: pass --fov DEG", name, deg);
    fov_ray(cam, meta, deg);
    cam->src_fov = src;
    return 0;
}

/* The lens, in precedence order: --fov, then the header family of the pose
 * (any family when the pose came from flags). Sets *lf to that family. */
static int resolve_lens(const ef_cam_meta *meta, const ef_cam_flags *flags, fam pf,
                        const ef_mat4 *c2w, fam *lf, ef_camera *cam, ef_err *err)
{
    *lf = FAM_NONE;
    if (flags->fov.set && flags->vfov.set) {
        cam->flag_error = 1;
        return ef_fail(err, "both a horizontal (--fov %g) and a vertical (vfov %g) field of "
                            "view are given; give only one", flags->fov.v, flags->vfov.v);
    }
    if (flags->fov.set)
        return use_fov(cam, meta, flags->fov.v, flags->fov_src ? "the camera file's fov" : "--fov",
                       flags->fov_src ? flags->fov_src : "flag --fov", err);
    if (flags->vfov.set) {
        /* tan(h/2) = tan(v/2) * W * pixelAspect / H over the display window. */
        const double v = flags->vfov.v;
        if (check_num(v, "the vertical fov (vfov)", err))
            return -1;
        if (!(v > 0.0 && v < 180.0))
            return ef_fail(err, "the vertical fov (vfov) is %g degrees; it must be between 0 "
                                "and 180", v);
        const double W = meta->disp[2] - meta->disp[0] + 1.0;
        const double H = meta->disp[3] - meta->disp[1] + 1.0;
        const double h = 2.0 * atan(tan(v * (EF_PI / 360.0)) * W * meta->pixel_aspect / H)
                         * (180.0 / EF_PI);
        return use_fov(cam, meta, h, "the vertical fov (vfov)",
                       flags->fov_src ? flags->fov_src
                                      : "vertical fov (vfov, via the display window's aspect)",
                       err);
    }
    const int exr = pf == FAM_EXR || pf == FAM_NONE;
    if (exr && meta->w2c.set && (meta->w2screen.set || meta->w2ndc.set)) {
        ef_mat4 hdr_c2w = *c2w;
        /* A flag pose replaces the header pose, but the lens is still the
         * header projection taken relative to the header's own camera. */
        if (pf == FAM_NONE && (check_mat(&meta->w2c.v, "worldToCamera", err)
                               || invert_named(&meta->w2c.v, &hdr_c2w, "worldToCamera", err)))
            return -1;
        *lf = FAM_EXR;
        return projection_ray(cam, meta, &hdr_c2w, err);
    }
    if (exr && meta->arnold_fov.set) {
        *lf = FAM_EXR;
        return use_fov(cam, meta, meta->arnold_fov.v, "CameraFov", "header CameraFov", err);
    }
    if ((pf == FAM_VRAY || pf == FAM_NONE) && meta->vray_fov.set) {
        *lf = FAM_VRAY;
        return use_fov(cam, meta, meta->vray_fov.v, "cameraFov", "header cameraFov", err);
    }
    if ((pf == FAM_RS || pf == FAM_NONE) && meta->rs_fov.set) {
        *lf = FAM_RS;
        double v = meta->rs_fov.v;
        if (check_num(v, "rs/camera/fov", err))
            return -1;
        /* Maxon documents radians; a value above pi can only be degrees. */
        const int deg = v > EF_PI;
        return use_fov(cam, meta, deg ? v : v * (180.0 / EF_PI), "rs/camera/fov",
                       deg ? "header rs/camera/fov (read as degrees)"
                           : "header rs/camera/fov (radians)", err);
    }
    static const char *const looked[] = {
        "worldToScreen, worldToNDC, CameraFov, cameraFov, rs/camera/fov",
        "worldToScreen, worldToNDC, CameraFov", "cameraFov", "rs/camera/fov"};
    return ef_fail(err, "no field of view for the camera from %s (looked for %s): "
                        "pass --fov DEG", cam->src_pose, looked[pf]);
}

/* One clip plane from a header attribute; "clipping off" values stay unset. */
static int meta_clip(ef_opt_num *out, const char **src, const ef_opt_num *a,
                     const char *name, const char *srcname, int is_far, ef_err *err)
{
    if (!a->set)
        return 0;
    if (check_num(a->v, name, err))
        return -1;
    /* V-Ray writes near 0 / far 1e30 when clipping is off. */
    if (a->v <= 0.0 || (is_far && a->v >= 1e29))
        return 0;
    out->set = 1;
    out->v = a->v;
    *src = srcname;
    return 0;
}

/* Clip planes, each on its own: flag, then the family's header attribute,
 * then the projection matrix. */
static int resolve_clip(const ef_cam_meta *meta, const ef_cam_flags *flags, fam cf,
                        ef_camera *cam, ef_err *err)
{
    if (flags->near_.set) {
        if (check_num(flags->near_.v, "--near", err))
            return -1;
        cam->near_ = flags->near_;
        cam->src_near = flags->near_src ? flags->near_src : "flag --near";
    }
    if (flags->far_.set) {
        if (check_num(flags->far_.v, "--far", err))
            return -1;
        cam->far_ = flags->far_;
        cam->src_far = flags->far_src ? flags->far_src : "flag --far";
    }
    const struct {
        const ef_opt_num *n, *f;
        const char *nn, *fn, *ns, *fs;
    } fams[] = {
        [FAM_NONE] = {0},
        [FAM_EXR] = {&meta->arnold_near, &meta->arnold_far,
                     "arnold/camera/near_clip", "arnold/camera/far_clip",
                     "header arnold/camera/near_clip", "header arnold/camera/far_clip"},
        [FAM_VRAY] = {&meta->vray_near, &meta->vray_far, "cameraNearClip", "cameraFarClip",
                      "header cameraNearClip", "header cameraFarClip"},
        [FAM_RS] = {&meta->rs_near, &meta->rs_far, "rs/camera/nearPlane", "rs/camera/farPlane",
                    "header rs/camera/nearPlane", "header rs/camera/farPlane"},
    };
    if (cf != FAM_NONE
        && ((!cam->near_.set && meta_clip(&cam->near_, &cam->src_near, fams[cf].n,
                                          fams[cf].nn, fams[cf].ns, 0, err))
            || (!cam->far_.set && meta_clip(&cam->far_, &cam->src_far, fams[cf].f,
                                            fams[cf].fn, fams[cf].fs, 1, err))))
        return -1;
    if (cam->proj != EF_PROJ_NONE) {
        /* z/w = alpha + beta/d read as a [0,1] depth range (D3D style, as
         * Arnold writes); a GL [-1,1] matrix would give near twice too small. */
        const double a = cam->proj_alpha, b = cam->proj_beta;
        const double n = -b / a, f = b / (1.0 - a);
        if (!cam->near_.set && isfinite(n) && n > 0.0) {
            cam->near_.set = 1;
            cam->near_.v = n;
            cam->src_near = "projection matrix";
        }
        if (!cam->far_.set && a != 1.0 && isfinite(f) && f > 0.0 && f < 1e29) {
            cam->far_.set = 1;
            cam->far_.v = f;
            cam->src_far = "projection matrix";
        }
    }
    return 0;
}

/* The length of row i of rot, without overflow or underflow. */
static double row_len(const double *r)
{
    return hypot(hypot(r[0], r[1]), r[2]);
}

/* Splits a uniform scale off the pose (cam->unit), so rot is orthonormal;
 * a pose with a shear or a non-uniform scale is kept as it is, with a
 * warning. Scales beyond 1e-30..1e30 are refused: distances would leave
 * the range of doubles. */
static int rigid_part(ef_camera *cam, ef_err *err)
{
    double n[3], lo = INFINITY, hi = 0;
    for (int i = 0; i < 3; ++i) {
        n[i] = row_len(cam->rot + 3 * i);
        lo = fmin(lo, n[i]);
        hi = fmax(hi, n[i]);
    }
    cam->unit = 1;
    if (!(lo >= 1e-30 && hi <= 1e30)) {
        cam->flag_error = !strncmp(cam->src_pose, "flag", 4);
        return ef_fail(err, "the camera pose (%s) scales camera space by %.3g to %.3g; exrfog "
                       "accepts a scale between 1e-30 and 1e30 (a rigid camera has 1): fix the "
                       "matrix or pass --world-to-camera M", cam->src_pose, lo, hi);
    }
    double cosmax = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = i + 1; j < 3; ++j) {
            const double *a = cam->rot + 3 * i, *b = cam->rot + 3 * j;
            const double d = (a[0] / n[i]) * (b[0] / n[j]) + (a[1] / n[i]) * (b[1] / n[j]) +
                             (a[2] / n[i]) * (b[2] / n[j]);
            cosmax = fmax(cosmax, fabs(d));
        }
    if (hi / lo - 1 <= 1e-6 && cosmax <= 1e-6) {
        const double u = (n[0] + n[1] + n[2]) / 3;
        if (fabs(u - 1) > 1e-6) {
            for (int k = 0; k < 9; ++k)
                cam->rot[k] /= u;
            cam->unit = u;
        }
        return 0;
    }
    const size_t at = strlen(cam->warning);
    snprintf(cam->warning + at, sizeof cam->warning - at,
             "%sthe camera pose (%s) is not rigid (axis lengths %.6g %.6g %.6g, largest cosine "
             "between axes %.2g): a shear or non-uniform scale; rays follow the matrix as given",
             at ? "; " : "", cam->src_pose, n[0], n[1], n[2], cosmax);
    return 0;
}

int ef_camera_resolve(const ef_cam_meta *meta, const ef_cam_flags *flags,
                      ef_camera *cam, ef_err *err)
{
    memset(cam, 0, sizeof *cam);
    cam->unit = 1;
    cam->src_pose = cam->src_fov = cam->src_near = cam->src_far = cam->src_proj = "none";
    if (flags->ortho_width.set)
        return ef_fail(err, "the camera file gives an orthographic camera (ortho_width %g): "
                            "an image exrfog fogs is seen through a perspective camera; "
                            "ortho_width is for a shadow map's camera (a light's "
                            "shadow-camera=FILE)", flags->ortho_width.v);
    if (meta->disp[2] < meta->disp[0] || meta->disp[3] < meta->disp[1])
        return ef_fail(err, "empty displayWindow (%d,%d)-(%d,%d)", meta->disp[0],
                       meta->disp[1], meta->disp[2], meta->disp[3]);
    if (!isfinite(meta->pixel_aspect) || !(meta->pixel_aspect > 0.0))
        return ef_fail(err, "pixelAspectRatio %g is not a positive number",
                       meta->pixel_aspect);
    ef_mat4 c2w;
    fam pf = FAM_NONE, lf = FAM_NONE;
    if (resolve_pose(meta, flags, &c2w, &pf, cam, err)) {
        cam->flag_error = (flags->w2c.set || flags->c2w.set) && !flags->pose_src;
        return -1;
    }
    if (resolve_lens(meta, flags, pf, &c2w, &lf, cam, err)
        || resolve_clip(meta, flags, pf != FAM_NONE ? pf : lf, cam, err))
        return -1;
    for (int i = 0; i < 3; ++i) {
        cam->pos[i] = c2w.m[12 + i];
        for (int j = 0; j < 3; ++j)
            cam->rot[3 * i + j] = c2w.m[4 * i + j];
    }
    return rigid_part(cam, err);
}

double ef_camera_pixel_spread(const ef_camera *c)
{
    /* h = (px, py, 1) . ray; the axis pixel is where hx = hy = 0, and there
     * d(dir)/d(px, py) is the 2x2 block over hz (dir = (0, 0, 1): planar
     * displacement is angle). */
    const double a = c->ray[0], b = c->ray[3], d = c->ray[1], e = c->ray[4];
    const double det = a * e - b * d;
    if (!(fabs(det) > 0) || !isfinite(det))
        return 0;
    const double px = (-c->ray[6] * e + b * c->ray[7]) / det;
    const double py = (-a * c->ray[7] + d * c->ray[6]) / det;
    const double hz = px * c->ray[2] + py * c->ray[5] + c->ray[8];
    const double s = sqrt(fabs(det)) / fabs(hz);
    return isfinite(s) ? s : 0;
}
