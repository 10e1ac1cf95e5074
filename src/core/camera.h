/* Camera resolution: from what an EXR header offers (ef_cam_meta) and what
 * the user forced (ef_cam_flags) to one pinhole camera (ef_camera) that maps
 * every pixel to a ray. Pure computation; the I/O layer fills ef_cam_meta.
 *
 * Camera space is OpenEXR's: left-handed, +X right, +Y up, +Z forward.
 * Matrices use the Imath row-vector layout (see mat4.h). */
#ifndef EF_CAMERA_H
#define EF_CAMERA_H

#include "error.h"
#include "mat4.h"

/* One optional number or matrix, with the header attribute it came from. */
typedef struct ef_opt_num { int set; double v; } ef_opt_num;
typedef struct ef_opt_mat { int set; ef_mat4 v; } ef_opt_mat;

/* Everything camera-related a header may carry (unset fields: set == 0). */
typedef struct ef_cam_meta {
    int disp[4];              /* displayWindow xmin, ymin, xmax, ymax (inclusive) */
    double pixel_aspect;      /* pixelAspectRatio, 1 when absent */
    ef_opt_mat w2c;           /* worldToCamera (m44f or m44d) */
    ef_opt_mat w2ndc;         /* worldToNDC: true NDC or (Arnold) screen space */
    ef_opt_mat w2screen;      /* worldToScreen */
    ef_opt_num arnold_fov;    /* CameraFov, degrees, horizontal */
    ef_opt_num arnold_near;   /* arnold/camera/near_clip */
    ef_opt_num arnold_far;    /* arnold/camera/far_clip */
    ef_opt_mat vray_c2w;      /* cameraTransform: camera-to-world, RH, -Z forward */
    ef_opt_num vray_fov;      /* cameraFov, degrees, horizontal */
    ef_opt_num vray_near;     /* cameraNearClip */
    ef_opt_num vray_far;      /* cameraFarClip */
    ef_opt_mat rs_c2w;        /* rs/camera/transform: camera-to-world, RH, -Z forward */
    ef_opt_num rs_fov;        /* rs/camera/fov: radians (Maxon doc); > pi read as degrees */
    ef_opt_num rs_near;       /* rs/camera/nearPlane */
    ef_opt_num rs_far;        /* rs/camera/farPlane */
    char other_attrs[400];    /* the header's other attribute names, for messages */
} ef_cam_meta;

/* What the command line forces; each set field overrides the header. */
/* How a pasted matrix is laid out (--camera-convention): exrfog's own and
 * OpenEXR's is row vectors (translation in the last row) with the camera
 * looking down +Z; Blender and Nuke write column vectors (translation in
 * the last column); every DCC's camera looks down its -Z. */
typedef enum ef_cam_convention {
    EF_CONV_EXR = 0, EF_CONV_BLENDER, EF_CONV_NUKE, EF_CONV_MAYA, EF_CONV_HOUDINI, EF_CONV_USD
} ef_cam_convention;

/* Parses a convention name (exr, blender, nuke, maya, houdini, usd).
 * Returns 0 or -1. */
int ef_cam_convention_parse(const char *name, ef_cam_convention *out);

typedef struct ef_cam_flags {
    ef_opt_mat w2c;           /* --world-to-camera, in the convention below */
    ef_opt_mat c2w;           /* --camera-to-world, its inverse */
    ef_cam_convention convention;
    ef_opt_num fov;           /* --fov, degrees, horizontal */
    ef_opt_num vfov;          /* degrees, vertical (a camera file's, e.g. Nuke .chan);
                               * turned into a horizontal fov with the display
                               * window's aspect times the pixel aspect. Setting
                               * both fov and vfov is an error. */
    ef_opt_num ortho_width;   /* a camera file's ortho_width: an orthographic camera's
                               * width in scene units (shadow maps only) */
    ef_opt_num near_;         /* --near */
    ef_opt_num far_;          /* --far */
    const char *fov_src;      /* where fov came from when not --fov (a camera file), or
                               * NULL; kept as the camera's src_fov, so it must outlive it */
    const char *pose_src;     /* where w2c/c2w came from when not the flags (a camera
                               * file's frame), or NULL: its errors are then the file's */
    const char *near_src;     /* where near_ / far_ came from when not --near / --far (a */
    const char *far_src;      /* camera file), or NULL; kept as src_near / src_far */
} ef_cam_flags;

/* Depth-row of the camera->clip projection: z_clip/w = alpha + beta/d for
 * planar depth d.  kind says which clip range the matrix was classified as. */
typedef enum ef_proj_kind {
    EF_PROJ_NONE = 0,         /* no projection matrix (fov camera) */
    EF_PROJ_SCREEN,           /* x,y in [-1,1], y up (Arnold, worldToScreen) */
    EF_PROJ_NDC               /* x,y in [0,1], y down (OpenEXR/RenderMan NDC) */
} ef_proj_kind;

typedef struct ef_camera {
    double pos[3];            /* camera position, world */
    double rot[9];            /* camera->world 3x3, row vectors: world_dir = cam_dir . rot */
    /* Pixel -> camera-space ray: h = (x + 0.5, y + 0.5, 1) . ray (x, y absolute
     * pixel indices, same frame as the display window); dir = h / h[2] has dir.z = 1. */
    double ray[9];
    double hfov_deg;          /* horizontal field of view through the frame centre */
    ef_opt_num near_, far_;   /* clip planes when known (flags, metadata, or matrix) */
    ef_proj_kind proj;
    double proj_alpha, proj_beta; /* valid when proj != EF_PROJ_NONE */
    /* World units per camera-space unit: 1 for a rigid pose; a pose with a
     * uniform scale is stored rigid (rot orthonormal) with its scale here,
     * so that no product of the scale overflows. Depth (camera units)
     * times unit is world distance. */
    double unit;
    /* Non-fatal doubts about the header, "" when none (e.g. a projection
     * whose aspect no longer matches the display window after a crop). */
    char warning[320];
    /* Set with an error that comes from a flag (a usage error, exit 2). */
    int flag_error;
    /* Where each part came from, for --explain (static strings). */
    const char *src_pose, *src_fov, *src_near, *src_far, *src_proj;
} ef_camera;

/* Resolves the camera. Precedence: flags, then worldToCamera with
 * worldToScreen/worldToNDC (classified numerically, not by name) or an fov,
 * then V-Ray, then Redshift. Returns 0, or -1 with a message listing what
 * the header had and which flags would fix it (no camera, no fov, non-finite
 * or singular matrices, orthographic projections). */
int ef_camera_resolve(const ef_cam_meta *meta, const ef_cam_flags *flags,
                      ef_camera *cam, ef_err *err);

/* The angle one pixel subtends where the optical axis meets the image
 * (radians; the square root of the pixel's solid angle there, so
 * non-square pixels count by their area): a pixel at distance s from the
 * camera covers about s times this. 0 when the projection is degenerate. */
double ef_camera_pixel_spread(const ef_camera *c);

/* Camera-space ray through the centre of absolute pixel (x, y), with dir[2] == 1. */
static inline void ef_camera_ray(const ef_camera *c, double x, double y, double dir[3])
{
    const double px = x + 0.5, py = y + 0.5;
    const double hx = px * c->ray[0] + py * c->ray[3] + c->ray[6];
    const double hy = px * c->ray[1] + py * c->ray[4] + c->ray[7];
    const double hz = px * c->ray[2] + py * c->ray[5] + c->ray[8];
    dir[0] = hx / hz;
    dir[1] = hy / hz;
    dir[2] = 1.0;
}

/* world = cam . rot: a camera-space vector expressed in world axes (no translation). */
static inline void ef_camera_to_world_dir(const ef_camera *c, const double v[3], double out[3])
{
    for (int j = 0; j < 3; ++j)
        out[j] = v[0] * c->rot[j] + v[1] * c->rot[3 + j] + v[2] * c->rot[6 + j];
}

/* Fills meta with defaults: no attributes, pixel aspect 1, the given display window. */
void ef_cam_meta_init(ef_cam_meta *meta, int xmin, int ymin, int xmax, int ymax);

#endif
