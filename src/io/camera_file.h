/* Camera files (--camera-file FILE): per-frame cameras the EXR header does
 * not hold, as a JSON file or a Nuke .chan file. The reader checks the whole
 * file up front; ef_camera_file_frame then fills the ef_cam_flags of one
 * frame, which ef_camera_resolve interprets as it interprets the flags
 * (docs/camera-file.md is the user documentation).
 *
 * Format: a name ending in .chan (any case) is a .chan file; one ending in
 * .json, or whose content starts with '{' or '[' (after a UTF-8 BOM and
 * white space), is JSON; anything else is refused.
 *
 * JSON (strict: unknown keys, wrong types or counts, duplicate frames are
 * errors that name the key's path in the file, e.g. "frames.1001.fov"):
 *
 *   { "convention": "blender",          optional: exr blender nuke maya houdini
 *                                       usd; overrides the command line's
 *                                       --camera-convention (the default)
 *     "aperture": 36,                   optional file-level defaults for every
 *     "near": 0.1, "far": 1000,         frame: fov | vfov | focal_length,
 *                                       aperture, near, far
 *     "frames": {                       frame number (a JSON string holding a
 *       "1001": {                       number: "1001", "1001.5") -> camera
 *         "camera_to_world": [16 numbers] or [[4], [4], [4], [4]]
 *           (or "world_to_camera": ..., exactly one of the two)
 *         "fov": 40                     horizontal degrees, or
 *         "vfov": 24                    vertical degrees, or
 *         "focal_length": 35            mm, with "aperture" (horizontal film
 *                                       width, same unit) here or file-level
 *         "near": 0.1, "far": 1000 } } }
 *
 *   "frames" may also be a list of frame objects, each with its number in
 *   "frame": [{"frame": 1001, "camera_to_world": [...], ...}, ...]; and the
 *   whole file may be that list alone (no file-level keys).
 *
 *   Matrices are read row by row as printed (16 numbers, or 4 rows of 4),
 *   then interpreted in the convention: exr is row vectors with the
 *   translation in the last row and the camera looking down +Z; blender and
 *   nuke are column vectors (translation in the last column, as Blender
 *   prints matrix_world); maya, houdini, usd are row vectors; every DCC's
 *   camera looks down its -Z. A frame's own lens keys (fov, vfov,
 *   focal_length) replace the file-level ones; its aperture, near and far
 *   replace the file-level ones one by one. Errors: both matrices or
 *   neither; more than one of fov, vfov, focal_length in one object;
 *   focal_length without an aperture; an aperture where no focal_length
 *   uses it; fov or vfov outside (0, 180); focal_length, aperture, near or
 *   far not > 0; far not > near; a frame given twice (also as "1001" and
 *   "1001.0"); no frames.
 *
 * Nuke .chan: one frame per line, white-space separated
 *
 *   frame tx ty tz rx ry rz [vfov]
 *
 *   translation in scene units, rotations in degrees, vfov the vertical
 *   field of view in degrees (Nuke writes it for a Camera, not for an
 *   Axis); every line has the same number of columns (7 or 8). '#' starts a
 *   comment (to the end of the line); blank lines are ignored. The
 *   rotation order is Nuke's default ZXY unless a comment line before the
 *   first frame says otherwise: "# rotation_order: XYZ" (any of XYZ, XZY,
 *   YXZ, YZX, ZXY, ZYX). Order "ABC" applies the A rotation first: for
 *   column vectors R = R_C . R_B . R_A, so ZXY is R = Ry . Rx . Rz, and the
 *   camera-to-world is T . R (the camera looks down its -Z, +Y up). The
 *   command line's convention does not apply (Euler angles have no matrix
 *   layout). Source: Nuke's own nukescripts/snap3d.py builds a node's
 *   transform as T * R * S with R = rotateMatrixZXY(rotate), which starts
 *   from the identity and calls rotateY, rotateX, rotateZ in that order,
 *   each of which post-multiplies (Foundry's Python reference for
 *   nuke.math / CMatrix4: "Post-multiply this matrix by a rotation around
 *   the Y axis"), and it multiplies points as matrix * column vector
 *   (projectPoints). Column layout: the Blender manual's "Nuke Animation
 *   (chan)" add-on page ("frame location.x location.y location.z
 *   rotation_euler.x rotation_euler.y rotation_euler.z angle_y", angle_y
 *   the vertical field of view). */
#ifndef EF_CAMERA_FILE_H
#define EF_CAMERA_FILE_H

#include "camera.h"
#include "error.h"

typedef struct ef_camera_file ef_camera_file;

/* Reads and checks path. conv_default is the convention of JSON matrices
 * when the file names none (the command line's --camera-convention). On
 * error returns -1 with err->file set to path and the message naming the
 * key path (JSON) or line number (.chan). */
int ef_camera_file_read(const char *path, ef_cam_convention conv_default,
                        ef_camera_file **out, ef_err *err);

void ef_camera_file_free(ef_camera_file *cf);

/* Fills flags for one frame (exact match; 1001 and 1001.0 are the same
 * frame, 1001.5 only matches a 1001.5 in the file): the pose as c2w or w2c
 * in the file's convention (flags->convention is set to it; the other
 * matrix is cleared), and when the file gives them the lens (fov, or vfov
 * for a vertical one; the other of the two is cleared) and near/far. Fields
 * the file does not give are left as they were, so a caller that wants the
 * command line to win sets its values after this call. A frame not in the
 * file: -1 with a message naming it, the range the file covers and, inside
 * that range, the nearest frames it has. */
int ef_camera_file_frame(const ef_camera_file *cf, double frame, ef_cam_flags *flags,
                         ef_err *err);

/* The first and last frame and how many frames the file holds (at least one). */
int ef_camera_file_frames(const ef_camera_file *cf, double *first, double *last, int *count);

/* One line for --explain and messages, e.g. "Nuke .chan, rotation order ZXY,
 * 100 frames 1001 to 1100, vertical fov" or "JSON, convention blender,
 * 3 frames 1 to 3". Owned by cf. */
const char *ef_camera_file_describe(const ef_camera_file *cf);

/* The convention the poses are in (always nuke for .chan). */
ef_cam_convention ef_camera_file_convention(const ef_camera_file *cf);

#endif
