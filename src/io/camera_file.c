/* Camera files: JSON (jansson) and Nuke .chan, read and checked whole, then
 * looked up frame by frame. The format is described in camera_file.h and
 * docs/camera-file.md. */
#include "camera_file.h"

#include "json_util.h"
#include "scene_file.h"   /* ef_read_text_file */

#include <ctype.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#define EF_PI 3.14159265358979323846

typedef struct cf_frame {
    double frame;
    int is_w2c;
    ef_mat4 m;                     /* as written, row by row, in the file's convention */
    ef_opt_num fov, vfov, near_, far_;
    ef_opt_num ortho;              /* ortho_width: an orthographic (shadow map) camera */
    char where[100];               /* "frames.1001", "frames[3]", "line 12" */
    int seq;                       /* its place in the file */
} cf_frame;

struct ef_camera_file {
    int is_chan;
    ef_cam_convention conv;
    char rot_order[4];             /* .chan: "ZXY" */
    int has_vfov;                  /* .chan: an 8th column */
    cf_frame *frames;              /* sorted by frame */
    int n, cap;
    char desc[200];
    char path[4096];
};

static const char *const conv_names[] = { "exr", "blender", "nuke", "maya", "houdini", "usd" };

/* The shortest decimal that reads back as v (frame numbers in messages). */
static void fmt_num(double v, char out[32])
{
    for (int prec = 6; prec <= 17; ++prec) {
        snprintf(out, 32, "%.*g", prec, v);
        if (strtod(out, NULL) == v)
            return;
    }
}

static cf_frame *add_frame(ef_camera_file *cf, ef_err *err)
{
    if (cf->n == cf->cap) {
        const int ncap = cf->cap ? 2 * cf->cap : 64;
        cf_frame *nf = realloc(cf->frames, (size_t) ncap * sizeof *nf);
        if (!nf) {
            ef_fail(err, "out of memory reading the camera file");
            return NULL;
        }
        cf->frames = nf;
        cf->cap = ncap;
    }
    cf_frame *f = &cf->frames[cf->n];
    memset(f, 0, sizeof *f);
    f->seq = cf->n++;
    return f;
}

static int cmp_frame(const void *a, const void *b)
{
    const double x = ((const cf_frame *) a)->frame, y = ((const cf_frame *) b)->frame;
    return (x > y) - (x < y);
}

/* Sorts the frames and refuses an empty file or a frame given twice. */
static int finish(ef_camera_file *cf, ef_err *err)
{
    if (cf->n == 0)
        return ef_fail(err, "holds no frames; a camera file needs one camera per frame to "
                            "render");
    qsort(cf->frames, (size_t) cf->n, sizeof *cf->frames, cmp_frame);
    for (int i = 1; i < cf->n; ++i)
        if (cf->frames[i].frame == cf->frames[i - 1].frame) {
            char t[32];
            fmt_num(cf->frames[i].frame, t);
            const int a = cf->frames[i - 1].seq < cf->frames[i].seq;
            return ef_fail(err, "frame %s is given twice (%s and %s); keep one",
                           t, cf->frames[a ? i - 1 : i].where, cf->frames[a ? i : i - 1].where);
        }
    char a[32], b[32];
    fmt_num(cf->frames[0].frame, a);
    fmt_num(cf->frames[cf->n - 1].frame, b);
    if (cf->is_chan)
        snprintf(cf->desc, sizeof cf->desc, "Nuke .chan, rotation order %s, %d frame%s %s to %s%s",
                 cf->rot_order, cf->n, cf->n == 1 ? "" : "s", a, b,
                 cf->has_vfov ? ", vertical fov" : ", no fov");
    else
        snprintf(cf->desc, sizeof cf->desc, "JSON, convention %s, %d frame%s %s to %s",
                 conv_names[cf->conv], cf->n, cf->n == 1 ? "" : "s", a, b);
    return 0;
}

/* ------------------------------------------------------------ .chan */

/* Rotation about one axis, column vectors, right-handed, degrees. */
static void axis_rot(char axis, double deg, double r[9])
{
    const double a = deg * (EF_PI / 180.0);
    double c = cos(a), s = sin(a);
    /* Exact at the quarter turns, so 90 degrees gives 0, not 6e-17. */
    if (fmod(deg, 90.0) == 0.0) {
        c = round(c);
        s = round(s);
    }
    memset(r, 0, 9 * sizeof *r);
    const int i = axis - 'X', j = (i + 1) % 3, k = (i + 2) % 3;
    r[3 * i + i] = 1.0;
    r[3 * j + j] = c;
    r[3 * j + k] = -s;
    r[3 * k + j] = s;
    r[3 * k + k] = c;
}

static void mul3(const double a[9], const double b[9], double out[9])
{
    double t[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            t[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
    memcpy(out, t, sizeof t);
}

/* Nuke's camera-to-world (column vectors, translation in the last column),
 * written row by row: T . R_C . R_B . R_A for rotation order "ABC". */
static void chan_matrix(const char order[4], const double t[3], const double rdeg[3],
                        ef_mat4 *out)
{
    double r[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 }, a[9];
    for (int n = 0; n < 3; ++n) {
        const char ax = order[n];
        axis_rot(ax, rdeg[ax - 'X'], a);
        mul3(a, r, r);   /* later rotations go on the left */
    }
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j)
            out->m[4 * i + j] = r[3 * i + j];
        out->m[4 * i + 3] = t[i];
    }
    out->m[12] = out->m[13] = out->m[14] = 0.0;
    out->m[15] = 1.0;
}

static int valid_order(const char *s)
{
    static const char *const orders[] = { "XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX" };
    for (size_t i = 0; i < sizeof orders / sizeof orders[0]; ++i)
        if (!strcmp(s, orders[i]))
            return 1;
    return 0;
}

/* "# rotation_order: XYZ" (case-insensitive key and value). Returns 1 when
 * line (after the '#') is that directive, 0 when it is a plain comment,
 * -1 with a message when the order is not one of the six. */
static int order_directive(const char *c, int lineno, char order[4], ef_err *err)
{
    while (*c == ' ' || *c == '\t')
        ++c;
    static const char key[] = "rotation_order";
    if (strncasecmp(c, key, sizeof key - 1))
        return 0;
    c += sizeof key - 1;
    while (*c == ' ' || *c == '\t')
        ++c;
    if (*c != ':')
        return 0;
    ++c;
    while (*c == ' ' || *c == '\t')
        ++c;
    char v[8] = "";
    size_t n = 0;
    while (c[n] && !isspace((unsigned char) c[n]) && n < sizeof v - 1) {
        v[n] = (char) toupper((unsigned char) c[n]);
        ++n;
    }
    v[n] = '\0';
    const char *rest = c + n;
    while (*rest == ' ' || *rest == '\t' || *rest == '\r')
        ++rest;
    if (!valid_order(v) || (*rest && *rest != '\n'))
        return ef_fail(err, "line %d: rotation_order must be one of XYZ, XZY, YXZ, YZX, ZXY, "
                            "ZYX (the first letter is applied first; Nuke's default is ZXY)",
                       lineno);
    memcpy(order, v, 4);
    return 1;
}

static int read_chan(ef_camera_file *cf, char *text, ef_err *err)
{
    static const char *const colname[8] = { "frame", "tx", "ty", "tz", "rx", "ry", "rz",
                                             "vfov" };
    memcpy(cf->rot_order, "ZXY", 4);
    cf->conv = EF_CONV_NUKE;
    int lineno = 0, ncols = 0, first_line = 0, seen_order = 0;
    for (char *line = text, *next; line; line = next) {
        ++lineno;
        next = strchr(line, '\n');
        if (next)
            *next++ = '\0';
        char *hash = strchr(line, '#');
        if (hash) {
            *hash = '\0';
            char *p = line;
            while (isspace((unsigned char) *p))
                ++p;
            if (!*p) {   /* a whole-line comment: perhaps the rotation order */
                const int d = order_directive(hash + 1, lineno, cf->rot_order, err);
                if (d < 0)
                    return -1;
                if (d > 0) {
                    if (cf->n)
                        return ef_fail(err, "line %d: rotation_order must come before the "
                                            "first frame (line %d)", lineno, first_line);
                    if (seen_order)
                        return ef_fail(err, "line %d: a second rotation_order; give it once",
                                       lineno);
                    seen_order = 1;
                }
            }
        }
        double v[8];
        int n = 0;
        for (char *save = NULL, *tok = strtok_r(line, " \t\r\v\f", &save); tok;
             tok = strtok_r(NULL, " \t\r\v\f", &save)) {
            if (n == 8)
                return ef_fail(err, "line %d: more than 8 columns; a .chan line is frame tx ty "
                                    "tz rx ry rz [vfov]", lineno);
            char *end;
            v[n] = strtod(tok, &end);
            if (end == tok || *end)
                return ef_fail(err, "line %d: column %d (%s) '%s' is not a number; a .chan "
                                    "line is frame tx ty tz rx ry rz [vfov]",
                               lineno, n + 1, colname[n], tok);
            if (!isfinite(v[n]))
                return ef_fail(err, "line %d: column %d (%s) '%s' is not a finite number",
                               lineno, n + 1, colname[n], tok);
            ++n;
        }
        if (n == 0)
            continue;
        if (n < 7)
            return ef_fail(err, "line %d: has %d column%s; a .chan line is frame tx ty tz rx "
                                "ry rz [vfov] (7 or 8 columns)", lineno, n, n == 1 ? "" : "s");
        if (!ncols) {
            ncols = n;
            first_line = lineno;
            cf->has_vfov = n == 8;
        } else if (n != ncols) {
            return ef_fail(err, "line %d: has %d columns but line %d has %d; every line needs "
                                "the same columns (frame tx ty tz rx ry rz, and vfov on all "
                                "or none)", lineno, n, first_line, ncols);
        }
        if (n == 8 && !(v[7] > 0.0 && v[7] < 180.0))
            return ef_fail(err, "line %d: column 8 (vfov) is %g degrees; a vertical field of "
                                "view must be between 0 and 180", lineno, v[7]);
        cf_frame *f = add_frame(cf, err);
        if (!f)
            return -1;
        f->frame = v[0];
        snprintf(f->where, sizeof f->where, "line %d", lineno);
        chan_matrix(cf->rot_order, v + 1, v + 4, &f->m);
        if (n == 8) {
            f->vfov.set = 1;
            f->vfov.v = v[7];
        }
    }
    return 0;
}

/* ------------------------------------------------------------ JSON */

/* The lens and clip keys a frame or the file level may hold. */
typedef struct lens {
    ef_opt_num fov, vfov, focal, aperture, near_, far_, ortho;
} lens;

static const char frame_keys[] = "camera_to_world, world_to_camera, fov, vfov, focal_length, "
                                 "aperture, near, far, ortho_width";
static const char top_keys[] = "convention, frames, fov, vfov, focal_length, aperture, near, "
                               "far, ortho_width";

/* A positive finite number (fov and vfov also below 180). */
static int num_key(const json_t *v, const char *path, const char *key, ef_opt_num *out,
                   ef_err *err)
{
    const int angle = !strcmp(key, "fov") || !strcmp(key, "vfov");
    if (!json_is_number(v))
        return ef_json_expected(err, path, angle ? "a number (degrees)" : "a number", v);
    const double x = json_number_value(v);
    if (!isfinite(x))
        return ef_fail(err, "%s: is not a finite number", path);
    if (angle && !(x > 0.0 && x < 180.0))
        return ef_fail(err, "%s: %g degrees; a field of view must be between 0 and 180",
                       path, x);
    if (!angle && !(x > 0.0))
        return ef_fail(err, "%s: %g; it must be greater than 0", path, x);
    out->set = 1;
    out->v = x;
    return 0;
}

/* Reads key (one of the lens keys) into l; returns 1 when key is not one. */
static int lens_key(const char *key, const json_t *v, const char *path, lens *l, ef_err *err)
{
    ef_opt_num *o = !strcmp(key, "fov") ? &l->fov
                  : !strcmp(key, "vfov") ? &l->vfov
                  : !strcmp(key, "focal_length") ? &l->focal
                  : !strcmp(key, "aperture") ? &l->aperture
                  : !strcmp(key, "near") ? &l->near_
                  : !strcmp(key, "far") ? &l->far_
                  : !strcmp(key, "ortho_width") ? &l->ortho : NULL;
    if (!o)
        return 1;
    return num_key(v, path, key, o, err) ? -1 : 0;
}

static int lens_check(const lens *l, const char *path, ef_err *err)
{
    const int k = l->fov.set + l->vfov.set + l->focal.set;
    if (k > 0 && l->ortho.set)
        return ef_fail(err, "%s: gives ortho_width (an orthographic camera's width) and a "
                            "perspective lens (fov, vfov or focal_length); give one", path);
    if (k > 1)
        return ef_fail(err, "%s: gives %s%s%s%s%s; give one of fov (horizontal degrees), vfov "
                            "(vertical degrees) or focal_length with aperture", path,
                       l->fov.set ? "fov" : "", l->fov.set ? " and " : "",
                       l->vfov.set ? "vfov" : "", l->vfov.set && l->focal.set ? " and " : "",
                       l->focal.set ? "focal_length" : "");
    return 0;
}

/* A matrix: 16 numbers, or 4 rows of 4, read row by row. */
static int read_matrix(const json_t *v, const char *path, ef_mat4 *m, ef_err *err)
{
    static const char what[] = "a matrix: 16 numbers or 4 rows of 4 numbers";
    if (!json_is_array(v))
        return ef_json_expected(err, path, what, v);
    const size_t n = json_array_size(v);
    if (n == 16) {
        for (size_t i = 0; i < 16; ++i) {
            const json_t *e = json_array_get(v, i);
            if (!json_is_number(e))
                return ef_fail(err, "%s[%zu]: expected a number, got %s", path, i,
                               ef_json_type_name(e));
            m->m[i] = json_number_value(e);
        }
    } else if (n == 4) {
        for (size_t i = 0; i < 4; ++i) {
            const json_t *row = json_array_get(v, i);
            if (!json_is_array(row) || json_array_size(row) != 4) {
                char p[256];
                snprintf(p, sizeof p, "%s[%zu]", path, i);
                return ef_json_expected(err, p, "a row of 4 numbers", row);
            }
            for (size_t j = 0; j < 4; ++j) {
                const json_t *e = json_array_get(row, j);
                if (!json_is_number(e))
                    return ef_fail(err, "%s[%zu][%zu]: expected a number, got %s", path, i, j,
                                   ef_json_type_name(e));
                m->m[4 * i + j] = json_number_value(e);
            }
        }
    } else {
        return ef_json_expected(err, path, what, v);
    }
    for (int i = 0; i < 16; ++i)
        if (!isfinite(m->m[i]))
            return ef_fail(err, "%s: holds a non-finite number", path);
    return 0;
}

/* One frame object at path; frame_key says whether "frame" belongs in it
 * (list form). top is the file-level lens. */
static int read_frame(ef_camera_file *cf, const json_t *obj, const char *path, int frame_key,
                      double frame, const lens *top, int *used_aperture, ef_err *err)
{
    if (!json_is_object(obj))
        return ef_json_expected(err, path, "a frame object (keys: camera_to_world or "
                                   "world_to_camera, fov, vfov, focal_length, aperture, near, "
                                   "far)", obj);
    cf_frame *f = add_frame(cf, err);
    if (!f)
        return -1;
    snprintf(f->where, sizeof f->where, "%s", path);
    f->frame = frame;
    lens l = {0};
    int have_c2w = 0, have_w2c = 0, have_frame = 0;
    const char *key;
    json_t *v;
    json_object_foreach((json_t *) obj, key, v) {
        char p[200];
        snprintf(p, sizeof p, "%s.%s", path, key);
        if (!strcmp(key, "camera_to_world") || !strcmp(key, "world_to_camera")) {
            const int w2c = key[0] == 'w';
            if (read_matrix(v, p, &f->m, err))
                return -1;
            if (w2c)
                have_w2c = 1;
            else
                have_c2w = 1;
            f->is_w2c = w2c;
            continue;
        }
        if (frame_key && !strcmp(key, "frame")) {
            if (!json_is_number(v))
                return ef_json_expected(err, p, "the frame number", v);
            f->frame = json_number_value(v);
            if (!isfinite(f->frame))
                return ef_fail(err, "%s: is not a finite number", p);
            have_frame = 1;
            continue;
        }
        const int r = lens_key(key, v, p, &l, err);
        if (r < 0)
            return -1;
        if (r > 0)
            return ef_fail(err, "%s: unknown key '%s' (keys: %s%s)", path, key,
                           frame_key ? "frame, " : "", frame_keys);
    }
    if (frame_key && !have_frame)
        return ef_fail(err, "%s: has no \"frame\" (its frame number)", path);
    if (have_c2w && have_w2c)
        return ef_fail(err, "%s: gives both camera_to_world and world_to_camera; give one",
                       path);
    if (!have_c2w && !have_w2c)
        return ef_fail(err, "%s: has no camera_to_world or world_to_camera matrix", path);
    if (lens_check(&l, path, err))
        return -1;
    /* The frame's lens replaces the file-level one as a whole. */
    const int own = l.fov.set || l.vfov.set || l.focal.set || l.ortho.set;
    const lens *src = own ? &l : top;
    const ef_opt_num ap = l.aperture.set ? l.aperture : top->aperture;
    if (src->focal.set) {
        if (!ap.set)
            return ef_fail(err, "%s: focal_length %g needs an aperture (the horizontal film "
                                "width, in the focal length's unit) in the frame or at the "
                                "top level", path, src->focal.v);
        f->fov.set = 1;
        f->fov.v = 2.0 * atan(ap.v / (2.0 * src->focal.v)) * (180.0 / EF_PI);
        if (!l.aperture.set)
            *used_aperture = 1;
    } else {
        if (l.aperture.set)
            return ef_fail(err, "%s: aperture %g without a focal_length sets nothing; give "
                                "focal_length too, or drop it", path, l.aperture.v);
        f->fov = src->fov;
        f->vfov = src->vfov;
        f->ortho = src->ortho;
    }
    f->near_ = l.near_.set ? l.near_ : top->near_;
    f->far_ = l.far_.set ? l.far_ : top->far_;
    if (f->near_.set && f->far_.set && !(f->far_.v > f->near_.v))
        return ef_fail(err, "%s: far %g is not beyond near %g", path, f->far_.v, f->near_.v);
    return 0;
}

/* A frame number written as an object key: the whole string one number. */
static int key_frame(const char *key, const char *path, double *out, ef_err *err)
{
    char *end;
    const double v = strtod(key, &end);
    if (!*key || isspace((unsigned char) *key) || end == key || *end || !isfinite(v))
        return ef_fail(err, "%s: the key '%s' is not a frame number (write frames as "
                            "\"1001\" or \"1001.5\")", path, key);
    *out = v;
    return 0;
}

static int read_frames(ef_camera_file *cf, const json_t *v, const char *path, const lens *top,
                       int *used_aperture, ef_err *err)
{
    if (json_is_array(v)) {
        for (size_t i = 0; i < json_array_size(v); ++i) {
            char p[64];
            snprintf(p, sizeof p, "%s[%zu]", path, i);
            if (read_frame(cf, json_array_get(v, i), p, 1, 0.0, top, used_aperture, err))
                return -1;
        }
        return 0;
    }
    if (!json_is_object(v))
        return ef_json_expected(err, path, "an object of frames (\"1001\": {...}) or a list of "
                                   "frames ([{\"frame\": 1001, ...}])", v);
    const char *key;
    json_t *fv;
    json_object_foreach((json_t *) v, key, fv) {
        char p[96];
        snprintf(p, sizeof p, "%s.%.60s", path, key);
        double fr = 0.0;
        if (key_frame(key, path, &fr, err)
            || read_frame(cf, fv, p, 0, fr, top, used_aperture, err))
            return -1;
    }
    return 0;
}

static int read_json(ef_camera_file *cf, const char *text, ef_err *err)
{
    json_error_t jerr;
    json_t *root = json_loadb(text, strlen(text), JSON_REJECT_DUPLICATES | JSON_DECODE_ANY |
                              JSON_DECODE_INT_AS_REAL, &jerr);
    if (!root)
        return ef_fail(err, "line %d, column %d: %s%s", jerr.line, jerr.column, jerr.text,
                       strstr(jerr.text, "near '/") ? " (JSON has no comments)" : "");
    lens top = {0};
    int used_aperture = 0, rc = 0;
    if (json_is_array(root)) {
        rc = read_frames(cf, root, "", &top, &used_aperture, err);
    } else if (!json_is_object(root)) {
        rc = ef_fail(err, "expected a JSON object (keys: %s) or a list of frames at the top "
                          "level, got %s", top_keys, ef_json_type_name(root));
    } else {
        const char *key;
        json_t *v;
        const json_t *frames = NULL;
        json_object_foreach(root, key, v) {
            if (!strcmp(key, "frames")) {
                frames = v;
            } else if (!strcmp(key, "convention")) {
                if (!json_is_string(v) || ef_cam_convention_parse(json_string_value(v),
                                                                  &cf->conv)) {
                    rc = json_is_string(v)
                       ? ef_fail(err, "convention: '%s' is not one of exr, blender, nuke, "
                                      "maya, houdini, usd", json_string_value(v))
                       : ef_json_expected(err, "convention", "a convention name (exr, blender, "
                                                     "nuke, maya, houdini, usd)", v);
                    break;
                }
            } else {
                const int r = lens_key(key, v, key, &top, err);
                if (r) {
                    rc = r < 0 ? -1 : ef_fail(err, "unknown key '%s' (keys: %s)", key,
                                              top_keys);
                    break;
                }
            }
        }
        if (!rc && lens_check(&top, "the top level", err))
            rc = -1;
        if (!rc && !frames)
            rc = ef_fail(err, "has no \"frames\" (an object of frames, \"1001\": {...}, or "
                              "a list, [{\"frame\": 1001, ...}])");
        if (!rc)
            rc = read_frames(cf, frames, "frames", &top, &used_aperture, err);
        if (!rc && top.aperture.set && !used_aperture)
            rc = ef_fail(err, "aperture %g is given at the top level but no frame uses it (no "
                              "focal_length); drop it or give focal_length", top.aperture.v);
    }
    json_decref(root);
    return rc;
}

/* ------------------------------------------------------------ public */

static int ends_with_ci(const char *s, const char *suffix)
{
    const size_t n = strlen(s), m = strlen(suffix);
    return n >= m && !strcasecmp(s + n - m, suffix);
}

int ef_camera_file_read(const char *path, ef_cam_convention conv_default,
                        ef_camera_file **out, ef_err *err)
{
    *out = NULL;
    char *text;
    if (ef_read_text_file(path, &text, err))
        return -1;
    ef_camera_file *cf = calloc(1, sizeof *cf);
    if (!cf) {
        free(text);
        return ef_fail(err, "out of memory reading it");
    }
    snprintf(cf->path, sizeof cf->path, "%s", path);
    cf->conv = conv_default;
    /* A UTF-8 byte order mark is not JSON, but editors write one. */
    char *body = text + (!strncmp(text, "\xEF\xBB\xBF", 3) ? 3 : 0);
    const char *p = body;
    while (isspace((unsigned char) *p))
        ++p;
    int rc;
    if (ends_with_ci(path, ".chan")) {
        cf->is_chan = 1;
        rc = read_chan(cf, body, err);
    } else if (ends_with_ci(path, ".json") || *p == '{' || *p == '[') {
        rc = read_json(cf, body, err);
    } else {
        rc = ef_fail(err, "is neither a Nuke .chan file (name it *.chan) nor JSON (name it "
                          "*.json; JSON starts with '{' or '[')");
    }
    free(text);
    if (!rc)
        rc = finish(cf, err);
    if (rc) {
        ef_err_set_file(err, path);
        ef_camera_file_free(cf);
        return -1;
    }
    *out = cf;
    return 0;
}

void ef_camera_file_free(ef_camera_file *cf)
{
    if (!cf)
        return;
    free(cf->frames);
    free(cf);
}

int ef_camera_file_frame(const ef_camera_file *cf, double frame, ef_cam_flags *flags,
                         ef_err *err)
{
    int lo = 0, hi = cf->n;   /* first index with frames[i].frame >= frame */
    while (lo < hi) {
        const int mid = lo + (hi - lo) / 2;
        if (cf->frames[mid].frame < frame)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo == cf->n || cf->frames[lo].frame != frame) {
        char f[32], a[32], b[32];
        fmt_num(frame, f);
        fmt_num(cf->frames[0].frame, a);
        fmt_num(cf->frames[cf->n - 1].frame, b);
        ef_err_set_file(err, cf->path);
        if (lo > 0 && lo < cf->n) {
            char p[32], q[32];
            fmt_num(cf->frames[lo - 1].frame, p);
            fmt_num(cf->frames[lo].frame, q);
            return ef_fail(err, "frame %s is not in the camera file, which covers frames %s to "
                                "%s (%d frames) but has nothing between %s and %s; add the "
                                "frame's camera or render a frame it holds", f, a, b, cf->n,
                           p, q);
        }
        return ef_fail(err, "frame %s is not in the camera file, which covers frame%s %s%s%s "
                            "(%d frame%s); add the frame's camera or render a frame it holds",
                       f, cf->n == 1 ? "" : "s", a, cf->n == 1 ? "" : " to ",
                       cf->n == 1 ? "" : b, cf->n, cf->n == 1 ? "" : "s");
    }
    const cf_frame *fr = &cf->frames[lo];
    flags->convention = cf->conv;
    flags->c2w.set = !fr->is_w2c;
    flags->w2c.set = fr->is_w2c;
    if (fr->is_w2c)
        flags->w2c.v = fr->m;
    else
        flags->c2w.v = fr->m;
    flags->ortho_width = fr->ortho;
    if (fr->fov.set) {
        flags->fov = fr->fov;
        flags->vfov.set = 0;
    } else if (fr->vfov.set) {
        flags->vfov = fr->vfov;
        flags->fov.set = 0;
    }
    if (fr->near_.set)
        flags->near_ = fr->near_;
    if (fr->far_.set)
        flags->far_ = fr->far_;
    return 0;
}

int ef_camera_file_frames(const ef_camera_file *cf, double *first, double *last, int *count)
{
    *first = cf->frames[0].frame;
    *last = cf->frames[cf->n - 1].frame;
    *count = cf->n;
    return 0;
}

const char *ef_camera_file_describe(const ef_camera_file *cf)
{
    return cf->desc;
}

ef_cam_convention ef_camera_file_convention(const ef_camera_file *cf)
{
    return cf->conv;
}
