/* Depth conventions: a stored depth sample -> distance from the camera, and
 * the sky rule. Pure computation. */
#ifndef EF_DEPTH_H
#define EF_DEPTH_H

#include "camera.h"
#include "error.h"

typedef enum ef_depth_mode {
    EF_DEPTH_PLANAR = 0,      /* distance along the view axis */
    EF_DEPTH_RADIAL,          /* distance along the ray */
    EF_DEPTH_INVERSE,         /* 1/z (Nuke ScanlineRender) */
    EF_DEPTH_NORMALIZED,      /* near + v (far - near) */
    EF_DEPTH_GL_NDC,          /* OpenGL NDC z in [-1,1]: z = -P34 / (v + P33) */
    EF_DEPTH_GL_WINDOW,       /* [0,1] window depth of the GL projection */
    EF_DEPTH_ZERO_ONE,        /* D3D/Vulkan [0,1] */
    EF_DEPTH_REVERSED,        /* reversed-Z [0,1], finite far */
    EF_DEPTH_REVERSED_INFINITE, /* reversed-Z, infinite far: d = n / v */
    EF_DEPTH_MODE_COUNT
} ef_depth_mode;

/* Parses a --depth-mode name; returns 0 or -1. */
int ef_depth_mode_parse(const char *name, ef_depth_mode *mode);
/* The --depth-mode name of a mode. */
const char *ef_depth_mode_name(ef_depth_mode mode);

/* A prepared conversion: mode plus the near/far it needs. */
typedef struct ef_depth_conv {
    ef_depth_mode mode;
    double near_, far_;
    double p33, p34;          /* GL modes: the seed paper's P33 = (f+n)/(n-f), P34 = -2fn/(f-n) */
    const char *src_clip;     /* where near/far came from, for --explain */
} ef_depth_conv;

/* Prepares a conversion. near/far come from the camera (flags, metadata, or
 * the projection matrix, already in that order). Fails, naming the flags to
 * pass, when the mode needs a clip plane the camera does not have, or when
 * the planes are not 0 < near < far (reversed-infinite needs only near). */
int ef_depth_conv_init(ef_depth_conv *conv, ef_depth_mode mode,
                       const ef_camera *cam, ef_err *err);

/* Distance for one stored value: planar depth for every mode but RADIAL,
 * where it is the distance along the ray. Returns 1 when the value means sky
 * (non-finite, <= 0 for planar/radial/inverse, >= 1e9 once linearised, or at
 * the far plane for the buffer modes), 0 otherwise. */
int ef_depth_linearize(const ef_depth_conv *conv, double v, double *dist);

/* ef_depth_linearize on n stored values: dist[i] and sky[i] (1 for sky). */
void ef_depth_linearize_span(const ef_depth_conv *conv, const float *v, int n, double *dist,
                             unsigned char *sky);

/* The sky threshold on linear distance. */
#define EF_SKY_DISTANCE 1e9

#endif
