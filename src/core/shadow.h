/* Shadow maps for lit fog: a depth render from the light (shadow=FILE.exr),
 * read as a piecewise-constant depth per texel, and the lit intervals of a
 * view segment against it, exactly with respect to that map.
 *
 * The map's camera is its header's worldToCamera (the light's position and
 * its +Z axis, OpenEXR's convention) and worldToNDC or worldToScreen (the
 * projection: perspective for a spot, orthographic for the sun, told apart
 * by the projection's w column). Each texel holds the planar depth (along
 * the light's axis, scene units) of what the light sees first; a point x is
 * lit when its own planar depth is at most the texel's plus the biases.
 * Along a view ray both the texel coordinates (a projective map of t) and
 * the planar depth (affine in t) are known in closed form, so the texels
 * the segment crosses are walked exactly (a 2-D DDA in t), each texel's
 * lit part is one interval, and a min-max mip skips runs that are wholly
 * lit or wholly shadowed. Pure C, no I/O: the I/O layer fills
 * ef_shadow_src.
 *
 * A texel holds one depth where the surface it saw spans a range of them:
 * lit by the sun at a low angle, a ground texel's depth varies by the
 * texel's width over the tangent of the angle, and fog just above the
 * ground would be shadowed in stripes (acne). The slope bias adds, per
 * texel, slope times half the sum over x and y of the smaller one-sided
 * depth difference to its neighbours: a plane's variation across the
 * texel, and nothing where one side is flat (so silhouettes keep their
 * shadow). */
#ifndef EF_SHADOW_H
#define EF_SHADOW_H

#include "error.h"
#include "mat4.h"

#include <stdatomic.h>

/* What a light-view depth render holds, as read from its file. */
typedef struct ef_shadow_src {
    const char *path;         /* for messages */
    int width, height;        /* data window */
    int dw[2];                /* data window origin */
    int disp[4];              /* display window xmin, ymin, xmax, ymax (inclusive) */
    const float *depth;       /* width x height, rows top-down */
    int has_w2c, has_proj;
    ef_mat4 w2c;              /* worldToCamera (row vectors, +Z forward) */
    ef_mat4 proj;             /* worldToNDC or worldToScreen */
    const char *proj_name;    /* which of the two */
} ef_shadow_src;

/* How a map is read: the constant bias (scene units, >= 0), the slope
 * bias's factor (>= 0; 0: none) and what lies outside the map. */
typedef struct ef_shadow_opts {
    double bias, slope;
    int outside_lit;
    int copies;          /* the penumbra's tilted copies to be made of the map (0: none) */
    const char *camera;  /* the map's camera from this camera file instead of its header
                          * (NULL: the header's); read by the loader only */
} ef_shadow_opts;

/* The most texels a shadow map may hold over itself and its penumbra
 * copies (2^27: a 11585^2 map alone, a 2048^2 one with 31 copies): a
 * texel costs about 12 bytes in the map and up to 26 in each copy (the
 * hostile campaign's 16384^2 map took 3 GB, a penumbra of 64 on a 2048^2
 * one 7.1 GB), so this bounds a map's memory between 1.6 and 3.5 GB. Past
 * it a map is refused before it is read (LIMITS). */
#define EF_SHADOW_MAX_TEXELS 134217728.0

/* A shadow map, immutable once built and shared (by reference count)
 * between the copies of a scene. */
typedef struct ef_shadow {
    _Atomic int refs;
    int w, h;                 /* texels */
    int ortho;                /* 1: orthographic (a sun's map) */
    /* (X, Y, W) = [x y z 1] . T (columns): the texel coordinates of world x
     * are X / W, Y / W (0..w, 0..h over the data window, y down) */
    double T[4][3];
    double org[3], axis[3];   /* the light camera's position and unit +Z */
    ef_shadow_opts opts;      /* as built (the biases are in zmin and zmax) */
    int outside_lit;          /* what lies outside the map (and behind a spot's map) */
    int nlev;                 /* mip levels, 0 = the texels */
    int lw[24], lh[24];       /* their sizes */
    /* per level; level 0's zmin is the map's depth plus its biases, the
     * greatest depth still lit (inf: nothing there) */
    float *zmin[24], *zmax[24];
    char path[256];
    /* a penumbra (ef_shadow_soften): ntilt orthographic maps of the same
     * occluders seen along directions spread over the sun's disc, owned
     * by this one; 0: hard shadows */
    int ntilt;
    struct ef_shadow **tilt;
    double angle;             /* the disc's angular diameter, radians */
    /* where no copy can differ from the map (ef_shadow_soften): a point
     * whose depth is below env's at its texel is in no penumbra */
    struct ef_shadow *env;
} ef_shadow;

/* Builds a map from src read as o says. Returns it (one reference), or
 * NULL with a message naming what is missing or wrong in the file and how
 * to fix it. */
ef_shadow *ef_shadow_build(const ef_shadow_src *src, const ef_shadow_opts *o, ef_err *err);

/* Takes one more reference (for a copy of the scene holding it). */
void ef_shadow_ref(ef_shadow *m);

/* Drops one reference; the last frees the map. NULL is a no-op. */
void ef_shadow_unref(ef_shadow *m);

/* The lit parts of the view segment org + t dir, t in [a, b] (b may be
 * INFINITY): sorted, disjoint, adjacent runs merged, written as pairs
 * into iv (at most cap pairs; a segment lit in more pieces than that gets
 * its remainder as one last piece, flagged by a return of -1 - n).
 * Returns the number of pairs n. */
int ef_shadow_lit(const ef_shadow *m, const double org[3], const double dir[3], double a,
                  double b, double (*iv)[2], int cap);

/* Whether world point x is lit by the map (the same rule, at one point). */
int ef_shadow_point_lit(const ef_shadow *m, const double x[3]);

/* Penumbrae from a sun of angular diameter angle (radians, > 0) for an
 * orthographic map: n tilted copies of the map (1 <= n <= EF_PENUMBRA_MAX),
 * one per direction of a golden-angle spiral that covers the sun's disc
 * evenly. Each copy re-projects the map's texels, taken as thin plates at
 * their depths, along its direction (a plate covers the texel centres its
 * shifted square holds; the sub-texel gaps that opening a continuous
 * surface would leave, between neighbours less than 16 texel widths apart
 * in depth, are closed). A point's visibility is the fraction of the
 * copies that see it lit: a filtered penumbra (exact with respect to the
 * copies, not to the scene: what the map does not hold cannot be seen
 * round). Costs n times the map's memory. Returns 0, or -1 with a message
 * (m unchanged). */
#define EF_PENUMBRA_MAX 64
int ef_shadow_soften(ef_shadow *m, double angle, int n, ef_err *err);

/* The lit parts of [a, b] along org + t dir with their visibility (the
 * fraction of the sun's disc that lights them, 1 for a hard map): sorted,
 * disjoint triples (t0, t1, v > 0), adjacent runs of one visibility merged,
 * at most cap of them (more: the rest joins the last, flagged by a return
 * of -1 - n). Returns the number n. */
int ef_shadow_pieces(const ef_shadow *m, const double org[3], const double dir[3], double a,
                     double b, double (*iv)[3], int cap);

/* The visibility of world point x: ef_shadow_point_lit's for a hard map,
 * the fraction of its tilted copies that light x for a soft one. */
double ef_shadow_point_vis(const ef_shadow *m, const double x[3]);

#endif
