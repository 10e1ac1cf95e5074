/* Reconstruction: pixel + stored depth -> the camera-to-surface segment,
 * in double, relative to the camera (so a camera far from the origin loses
 * nothing). */
#ifndef EF_RECON_H
#define EF_RECON_H

#include "camera.h"
#include "depth.h"

/* One pixel's view segment. The world point is cam->pos + dir * dist. */
typedef struct ef_ray {
    double dir[3];    /* unit direction in world axes */
    double dist;      /* distance along the ray; INFINITY for sky */
    double planar;    /* distance along the view axis; INFINITY for sky */
    double org[3];    /* world position of the segment's start (the camera) */
} ef_ray;

/* Builds the ray of absolute pixel (x, y) from stored depth value v.
 * Returns 1 for a sky pixel (dist = planar = INFINITY, dir still set), else 0. */
int ef_reconstruct(const ef_camera *cam, const ef_depth_conv *conv,
                   int x, int y, double v, ef_ray *r);

/* The most pixels ef_reconstruct_span builds in one call. */
#define EF_RECON_SPAN 64

/* ef_reconstruct for the n <= EF_RECON_SPAN pixels (x0 + i, y) of one row
 * with stored depths depth[i], into r[i] and sky[i] (1 for a sky pixel):
 * the same bits as n calls of ef_reconstruct, for a fraction of the cost.
 * With need_dir == 0, r[i].dir is left 0 (for users of dist/planar only). */
void ef_reconstruct_span(const ef_camera *cam, const ef_depth_conv *conv, int x0, int y, int n,
                         const float *depth, int need_dir, ef_ray *r, unsigned char *sky);

/* ef_reconstruct_span for users of the distances alone: planar[i] and,
 * when need_dist, dist[i] (else left as they were), the same bits as
 * r[i].planar and r[i].dist, without building rays. */
void ef_reconstruct_dist(const ef_camera *cam, const ef_depth_conv *conv, int x0, int y, int n,
                         const float *depth, int need_dist, double *planar, double *dist,
                         unsigned char *sky);

/* The ray of pixel (x, y) ending at radial distance dist (INFINITY allowed). */
void ef_ray_at_distance(const ef_camera *cam, int x, int y, double dist, ef_ray *r);

#endif
