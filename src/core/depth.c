#include "depth.h"

#include "ddouble.h"

#include <math.h>
#include <string.h>

static const char *const mode_names[EF_DEPTH_MODE_COUNT] = {
    [EF_DEPTH_PLANAR] = "planar",
    [EF_DEPTH_RADIAL] = "radial",
    [EF_DEPTH_INVERSE] = "inverse",
    [EF_DEPTH_NORMALIZED] = "normalized",
    [EF_DEPTH_GL_NDC] = "gl-ndc",
    [EF_DEPTH_GL_WINDOW] = "gl-window",
    [EF_DEPTH_ZERO_ONE] = "zero-one",
    [EF_DEPTH_REVERSED] = "reversed",
    [EF_DEPTH_REVERSED_INFINITE] = "reversed-infinite",
};

int ef_depth_mode_parse(const char *name, ef_depth_mode *mode)
{
    for (int i = 0; name && i < EF_DEPTH_MODE_COUNT; ++i)
        if (strcmp(name, mode_names[i]) == 0) {
            *mode = (ef_depth_mode)i;
            return 0;
        }
    return -1;
}

/* Never NULL, so messages can print any value. */
const char *ef_depth_mode_name(ef_depth_mode mode)
{
    return ((unsigned)mode < EF_DEPTH_MODE_COUNT) ? mode_names[mode] : "unknown";
}

/* One static string naming where both planes came from. */
static const char *clip_source(const char *n, const char *f)
{
    static const char *const pairs[][3] = {
        {"flag --near", "flag --far", "flags --near/--far"},
        {"header arnold/camera/near_clip", "header arnold/camera/far_clip",
         "header arnold/camera/near_clip, far_clip"},
        {"header cameraNearClip", "header cameraFarClip", "header cameraNearClip, cameraFarClip"},
        {"header rs/camera/nearPlane", "header rs/camera/farPlane",
         "header rs/camera/nearPlane, farPlane"},
    };
    if (!n || !f)
        return "unknown";
    if (strcmp(n, f) == 0)
        return n;
    for (size_t i = 0; i < sizeof pairs / sizeof pairs[0]; ++i)
        if (strcmp(n, pairs[i][0]) == 0 && strcmp(f, pairs[i][1]) == 0)
            return pairs[i][2];
    return "near and far from different sources";
}

int ef_depth_conv_init(ef_depth_conv *conv, ef_depth_mode mode,
                       const ef_camera *cam, ef_err *err)
{
    memset(conv, 0, sizeof *conv);
    if ((unsigned)mode >= EF_DEPTH_MODE_COUNT)
        return ef_fail(err, "unknown depth mode %d", (int)mode);
    conv->mode = mode;
    conv->src_clip = "not needed";
    if (mode == EF_DEPTH_PLANAR || mode == EF_DEPTH_RADIAL || mode == EF_DEPTH_INVERSE)
        return 0;

    const char *name = mode_names[mode];
    const int need_far = mode != EF_DEPTH_REVERSED_INFINITE;
    if (!cam->near_.set || (need_far && !cam->far_.set))
        return ef_fail(err, "depth mode %s needs the %s clip plane%s, which the header "
                            "does not give: pass %s", name,
                       need_far ? "near and far" : "near", need_far ? "s" : "",
                       need_far ? "--near N --far F" : "--near N");
    const double n = cam->near_.v, f = need_far ? cam->far_.v : INFINITY;
    if (!isfinite(n) || !(n > 0.0) || (need_far && !(isfinite(f) && f > n))) {
        if (need_far)
            return ef_fail(err, "depth mode %s needs 0 < near < far, but near is %g (%s) "
                                "and far is %g (%s): pass --near N --far F", name, n,
                           cam->src_near ? cam->src_near : "?", f,
                           cam->src_far ? cam->src_far : "?");
        return ef_fail(err, "depth mode %s needs near > 0, but near is %g (%s): pass --near N",
                       name, n, cam->src_near ? cam->src_near : "?");
    }
    conv->near_ = n;
    conv->far_ = need_far ? f : 0.0;
    conv->p33 = (f + n) / (n - f);
    conv->p34 = -2.0 * f * n / (f - n);
    conv->src_clip = need_far ? clip_source(cam->src_near, cam->src_far) : cam->src_near;
    if (!need_far)
        conv->p33 = conv->p34 = 0.0;
    return 0;
}

/* The branch per sample is cheap next to the fog integral; the far-plane
 * tests are on the stored value, before rounding can move it. */
static inline int linearize(const ef_depth_conv *conv, double v, double *dist)
{
    const double n = conv->near_, f = conv->far_;
    double d;
    *dist = INFINITY;
    if (!isfinite(v))
        return 1;
    switch (conv->mode) {
    case EF_DEPTH_PLANAR:
    case EF_DEPTH_RADIAL:
        if (v <= 0.0)
            return 1;
        d = v;
        break;
    case EF_DEPTH_INVERSE:
        if (v <= 0.0)
            return 1;
        d = 1.0 / v;
        break;
    case EF_DEPTH_NORMALIZED:
        if (v >= 1.0)
            return 1;
        d = n + v * (f - n);
        break;
    case EF_DEPTH_GL_WINDOW:
        if (v >= 1.0)
            return 1;
        v = 2.0 * v - 1.0;
        /* the seed paper's eq. 1 on the NDC value */
        d = conv->p34 / (v + conv->p33);
        break;
    case EF_DEPTH_GL_NDC:
        if (v >= 1.0)
            return 1;
        /* eq. 1: z_eye = -P34 / (v + P33), and d = -z_eye */
        d = conv->p34 / (v + conv->p33);
        break;
    case EF_DEPTH_ZERO_ONE:
        if (v >= 1.0)
            return 1;
        d = f * n / (f - v * (f - n));
        break;
    case EF_DEPTH_REVERSED:
        if (v <= 0.0)
            return 1;
        d = f * n / (n + v * (f - n));
        break;
    case EF_DEPTH_REVERSED_INFINITE:
        if (v <= 0.0)
            return 1;
        d = n / v;
        break;
    default:
        return 1;
    }
    if (!isfinite(d) || d <= 0.0 || d >= EF_SKY_DISTANCE)
        return 1;
    *dist = d;
    return 0;
}

int ef_depth_linearize(const ef_depth_conv *conv, double v, double *dist)
{
    return linearize(conv, v, dist);
}

EF_MULTIVERSION void ef_depth_linearize_span(const ef_depth_conv *conv, const float *v, int n, double *dist,
                             unsigned char *sky)
{
    if (conv->mode == EF_DEPTH_PLANAR || conv->mode == EF_DEPTH_RADIAL) {
        /* linearize()'s planar case as selects, so the loop vectorises. */
        for (int i = 0; i < n; ++i) {
            const double d = v[i];
            const int s = !(isfinite(d) && d > 0.0 && d < EF_SKY_DISTANCE);
            dist[i] = s ? INFINITY : d;
            sky[i] = (unsigned char) s;
        }
        return;
    }
    for (int i = 0; i < n; ++i)
        sky[i] = (unsigned char) linearize(conv, v[i], &dist[i]);
}
