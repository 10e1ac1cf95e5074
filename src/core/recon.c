#include "recon.h"

#include "ddouble.h"

#include <math.h>

/* The world vector w = (dx, dy, 1) . rot of a camera-space direction, and
 * its length: the one formula every ray of this file is built from. */
static inline double world_vec(const ef_camera *cam, double dx, double dy, double w[3])
{
    const double dc[3] = { dx, dy, 1.0 };
    ef_camera_to_world_dir(cam, dc, w);
    return sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
}

/* Shared tail: the camera-space point is t * (dx, dy, 1); its world offset
 * is t * w with w = dir . rot, so distances stay relative to the camera. */
static void ray_from_cam(const ef_camera *cam, const double dc[3], double t, ef_ray *r)
{
    double w[3];
    const double len = world_vec(cam, dc[0], dc[1], w);
    r->dir[0] = w[0] / len;
    r->dir[1] = w[1] / len;
    r->dir[2] = w[2] / len;
    r->planar = t * cam->unit;
    r->dist = t * (len * cam->unit);
    r->org[0] = cam->pos[0];
    r->org[1] = cam->pos[1];
    r->org[2] = cam->pos[2];
}

/* Radial depth is measured along the ray: scale by 1/|dc| to reach dc.z = t. */
static inline double radial_to_planar(double d, double dx, double dy)
{
    return d / sqrt(dx * dx + dy * dy + 1.0);
}

int ef_reconstruct(const ef_camera *cam, const ef_depth_conv *conv,
                   int x, int y, double v, ef_ray *r)
{
    double dc[3], d;
    ef_camera_ray(cam, x, y, dc);
    if (ef_depth_linearize(conv, v, &d)) {
        ray_from_cam(cam, dc, INFINITY, r);
        return 1;
    }
    if (conv->mode == EF_DEPTH_RADIAL)
        d = radial_to_planar(d, dc[0], dc[1]);
    ray_from_cam(cam, dc, d, r);
    return 0;
}

/* The view geometry of n <= EF_RECON_SPAN pixels (x0 + i, y): ef_camera_ray's
 * sums in its order with the row's terms hoisted, h = (px ray[0..2] +
 * py ray[3..5]) + ray[6..8], then world_vec's w and its length. Branch-free
 * loops over arrays, so the compiler vectorises them. A pinhole's h.z is
 * exactly 1 (ray[2] = ray[5] = 0, ray[8] = 1): its divisions are then
 * skipped, the same bits. w may be NULL (then only len is kept). */
static inline void span_geometry(const ef_camera *cam, int x0, int y, int n, double *dx,
                                 double *dy, double w[3][EF_RECON_SPAN], double *len)
{
    const double *ray = cam->ray, *rot = cam->rot, py = y + 0.5;
    const double ry[3] = { py * ray[3], py * ray[4], py * ray[5] };
    const int unit_z = ray[2] == 0.0 && ray[5] == 0.0 && ray[8] == 1.0;
    for (int i = 0; i < n; ++i) {
        const double px = (double) (x0 + i) + 0.5;
        const double hx = (px * ray[0] + ry[0]) + ray[6];
        const double hy = (px * ray[1] + ry[1]) + ray[7];
        const double hz = unit_z ? 1.0 : (px * ray[2] + ry[2]) + ray[8];
        const double x = unit_z ? hx : hx / hz, yv = unit_z ? hy : hy / hz;
        dx[i] = x;
        dy[i] = yv;
        /* world_vec: (dx, dy, 1) . rot, the last product exactly rot[6..8] */
        const double w0 = (x * rot[0] + yv * rot[3]) + rot[6];
        const double w1 = (x * rot[1] + yv * rot[4]) + rot[7];
        const double w2 = (x * rot[2] + yv * rot[5]) + rot[8];
        if (w) {
            w[0][i] = w0;
            w[1][i] = w1;
            w[2][i] = w2;
        }
        len[i] = sqrt(w0 * w0 + w1 * w1 + w2 * w2);
    }
}

/* Planar depth t of each pixel (INFINITY on sky), radial depth turned planar. */
static inline void span_depth(const ef_depth_conv *conv, const float *depth, int n,
                              const double *dx, const double *dy, double *t, unsigned char *sky)
{
    ef_depth_linearize_span(conv, depth, n, t, sky);
    if (conv->mode == EF_DEPTH_RADIAL)
        for (int i = 0; i < n; ++i)
            t[i] = radial_to_planar(t[i], dx[i], dy[i]);
    for (int i = 0; i < n; ++i)
        t[i] = sky[i] ? INFINITY : t[i];
}

EF_MULTIVERSION void ef_reconstruct_span(const ef_camera *cam, const ef_depth_conv *conv, int x0, int y, int n,
                         const float *depth, int need_dir, ef_ray *r, unsigned char *sky)
{
    double dx[EF_RECON_SPAN], dy[EF_RECON_SPAN], len[EF_RECON_SPAN], d[EF_RECON_SPAN];
    double w[3][EF_RECON_SPAN];
    if (n > EF_RECON_SPAN)
        n = EF_RECON_SPAN;
    const double unit = cam->unit;
    span_geometry(cam, x0, y, n, dx, dy, w, len);
    span_depth(conv, depth, n, dx, dy, d, sky);
    for (int i = 0; i < n; ++i) {
        const double t = d[i];
        r[i].planar = t * unit;
        r[i].dist = t * (len[i] * unit);
        for (int k = 0; k < 3; ++k)
            r[i].org[k] = cam->pos[k];
    }
    if (need_dir)
        for (int i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k)
                r[i].dir[k] = w[k][i] / len[i];
    else
        for (int i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k)
                r[i].dir[k] = 0.0;
}

EF_MULTIVERSION void ef_reconstruct_dist(const ef_camera *cam, const ef_depth_conv *conv, int x0,
                                         int y, int n, const float *depth, int need_dist,
                                         double *planar, double *dist, unsigned char *sky)
{
    double dx[EF_RECON_SPAN], dy[EF_RECON_SPAN], len[EF_RECON_SPAN], d[EF_RECON_SPAN];
    if (n > EF_RECON_SPAN)
        n = EF_RECON_SPAN;
    const double unit = cam->unit;
    /* The geometry is needed for the distance, and for radial depth. */
    if (need_dist || conv->mode == EF_DEPTH_RADIAL)
        span_geometry(cam, x0, y, n, dx, dy, NULL, len);
    span_depth(conv, depth, n, dx, dy, d, sky);
    for (int i = 0; i < n; ++i)
        planar[i] = d[i] * unit;
    if (need_dist)
        for (int i = 0; i < n; ++i)
            dist[i] = d[i] * (len[i] * unit);
}

void ef_ray_at_distance(const ef_camera *cam, int x, int y, double dist, ef_ray *r)
{
    double dc[3];
    ef_camera_ray(cam, x, y, dc);
    ray_from_cam(cam, dc, 1.0, r);
    /* With t = 1, r->dist is the world length of one unit of planar depth. */
    r->planar = dist / r->dist;
    r->dist = dist;
}
