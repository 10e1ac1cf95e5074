/* Fog at the edges of flat renders (--edges unmix).
 *
 * An anti-aliased edge pixel mixes the colours of a near surface and of
 * what lies behind it, but its depth is one number, so one fog for the
 * whole pixel is wrong for part of its colour (the outline around thin
 * things). Here each edge pixel is taken as a mix of two surfaces its
 * neighbourhood shows. The layers are the depths its 8 neighbours show;
 * a layer's colour comes from its nearest pixels in the 5x5 window that
 * are not edges themselves. Where the pixel's own depth is a layer (a Z
 * that is one surface's depth), its share s solves C = s A + (1 - s) B
 * (RGB and alpha, least squares) with A its own layer's colour nearest
 * C and B the other layer's colour that fits best; no mix where C lies
 * within its own layer's texture or no mix explains it. Where its depth
 * lies between two layers (a filtered Z), the depth gives the share. The
 * fit's residual goes to both parts by their shares. Each part is
 * fogged at its own depth along the pixel's own ray, by the pass itself
 * (lights, sky light and AOVs included), and the two are summed. Pixels
 * that are not edges are left to the pass as they are.
 *
 * An edge is a pixel where the inverse depth 1/z of its 3x3 window bends:
 * |1/z_q - 2/z_p + 1/z_q'| over a pair of opposite neighbours above
 * EF_EDGE_REL of the window's largest 1/z (a step of 5 % in depth). A
 * plane has 1/z linear on the screen, so ground seen at a grazing angle
 * is no edge, however fast its depth grows.
 *
 * Pure C, no I/O, no globals. */
#ifndef EF_EDGES_H
#define EF_EDGES_H

#include "apply.h"
#include "aov.h"

#include <stddef.h>

#define EF_EDGE_REL 0.05

/* The rows outside a unit an edge pixel's result depends on: its 5x5
 * window's (2), and their own edge test's 3x3 window (1 more). */
#define EF_EDGE_HALO 3

/* One unit of rows and the rows just outside it: nup rows above (rows
 * y0 - nup .. y0 - 1, top first) and ndn below (y0 + h .. y0 + h + ndn -
 * 1), each w long, 0 to EF_EDGE_HALO of each where the frame or the
 * stream has fewer (the pointers then NULL). alpha and the rows' alphas
 * may be NULL (1). Whether an edge pixel is unmixed depends only on its
 * own rows and these, and on the 16-row band of the unit it lies in (a
 * band whose edge pixels mostly lie between layers has a filtered Z):
 * units that start on the same 16-row grid give the same pixels. */
typedef struct ef_edge_rows {
    int x0, y0, w, h;
    const float *rgb[3], *alpha, *depth;
    const float *up_rgb[3], *up_alpha, *up_depth;
    const float *dn_rgb[3], *dn_alpha, *dn_depth;
    int nup, ndn;
} ef_edge_rows;

/* An edge pixel's two parts: part 0 near, part 1 far. */
typedef struct ef_edge_px {
    int i;                   /* index in the unit (row-major, w wide) */
    float v[2];              /* each part's stored depth value */
    double w;                /* the near part's share of the pixel */
    double c[2][4];          /* each part's premultiplied RGB and alpha (they sum to the pixel's) */
    double pure[2][4];       /* each layer's colour as its pure pixel shows it */
    double du;               /* the uncertainty of w (the error output's unmixing share) */
    int between;             /* its depth lies between the layers (a filtered Z) */
    int keep;                /* the pass's pixel stands; only its error output gains du */
} ef_edge_px;

/* Scratch kept between units by one thread. */
typedef struct ef_edge_work {
    double *iz;              /* 1 / planar depth of the unit and its outer rows */
    unsigned char *edge;
    unsigned char *outl;     /* depth outliers (edges.c is_outlier) */
    size_t cap;
    int *band;               /* per 16-row band: edge pixels seen, then those between layers */
    size_t bandcap;
    ef_edge_px *px;
    size_t pxcap;
} ef_edge_work;

void ef_edge_work_free(ef_edge_work *wk);

/* The edge pixels of unit u (its input, before the fog) into wk->px;
 * with want_err (the error output is written), also those the pass's
 * result stands for, for their error term. Returns their count, or -1
 * when out of memory. */
int ef_edge_find(const ef_fog_pass *pass, const ef_edge_rows *u, int want_err, ef_edge_work *wk);

/* Replaces the pass's result at each of the n edge pixels e (unit at x0,
 * y0, w wide; rgb, alpha and aov as the pass wrote them) by the sum of its
 * two parts, each fogged by the pass at its own depth; fog_P and
 * fog_distance stay the pixel's own, and the error output gains du times
 * the difference of the two parts' fogged colours. */
void ef_edge_apply(const ef_fog_pass *pass, int x0, int y0, int w, const ef_edge_px *e, int n,
                   float *const rgb[3], float *alpha, const ef_aov_out *aov);

#endif
