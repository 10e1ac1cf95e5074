#include "recon.h"

#include <math.h>

/* Shared tail: the camera-space point is t * (dx, dy, 1); its world offset
 * is t * w with w = dir . rot, so distances stay relative to the camera. */
static void ray_from_cam(const ef_camera *cam, const double dc[3], double t, ef_ray *r)
{
    double w[3];
    ef_camera_to_world_dir(cam, dc, w);
    const double len = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    r->dir[0] = w[0] / len;
    r->dir[1] = w[1] / len;
    r->dir[2] = w[2] / len;
    r->planar = t * cam->unit;
    r->dist = t * (len * cam->unit);
    r->org[0] = cam->pos[0];
    r->org[1] = cam->pos[1];
    r->org[2] = cam->pos[2];
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
    /* Radial depth is measured along the ray: scale by 1/|dc| to reach dc.z = t. */
    if (conv->mode == EF_DEPTH_RADIAL)
        d /= sqrt(dc[0] * dc[0] + dc[1] * dc[1] + 1.0);
    ray_from_cam(cam, dc, d, r);
    return 0;
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
