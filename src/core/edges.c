/* Fog at the edges of flat renders: the unmixing (edges.h). */
#include "edges.h"

#include "ddouble.h"
#include "recon.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Below this contrast between the two layers' colours (relative to the
 * larger), the colours cannot tell the shares apart: the pixel's own
 * depth does instead. */
#define CONTRAST_MIN 0.02
/* The share's uncertainty beyond what the residual shows (edges.h's du):
 * calibrated on bench/edges_blender.py's calib scene, not a test scene. */
#define DU_FLOOR 0.1
/* The share of another layer a pixel left as it is may still hold (the
 * error output's term there): calibrated on bench/edges_blender.py's
 * calib scene, not a test scene (bench/edges.md). */
#define DU_KEEP 0.2
/* The share of a thin thing (no pixel of it pure) in its most distinct
 * pixel, as the pixel filter leaves it: calibrated on the calib scene. */
#define W_THIN 0.85
/* The same for the other layer where it is the thin one and the pixel's
 * own surface shows pure pixels: calibrated on the calib scene (0.85 to
 * 1.0 tried; 0.95 gave its least edge RMS error and fewest pixels off by
 * 2 %, bench/edges.md). */
#define W_THIN_OTHER 0.95
/* A mix of the two colours leaving a residual above this fraction of
 * their difference explains nothing (texture, or a third surface). */
#define RES_MAX 0.35
/* A pixel whose depth is none of its neighbours' has their colour when it
 * lies within their range per channel widened by this much of the
 * largest (the render's noise and a blurred thing's faint share). */
#define OUTLIER_TOL 0.02

void ef_edge_work_free(ef_edge_work *wk)
{
    free(wk->iz);
    free(wk->edge);
    free(wk->outl);
    free(wk->band);
    free(wk->px);
    memset(wk, 0, sizeof *wk);
}

#define HR EF_EDGE_HALO

/* Whether row r of u (-nup .. h + ndn - 1) is there. */
static int row_there(const ef_edge_rows *u, int r)
{
    return r < 0 ? r >= -u->nup && u->up_rgb[0] && u->up_depth
                 : r < u->h || (r < u->h + u->ndn && u->dn_rgb[0] && u->dn_depth);
}

/* Offset of row r's first pixel in its plane (the unit's, or the halo's
 * above or below). */
EF_INLINE size_t row_off(const ef_edge_rows *u, int r)
{
    const int i = r < 0 ? r + u->nup : r >= u->h ? r - u->h : r;
    return (size_t) i * (size_t) u->w;
}

/* The rows of u, r = -nup (above) .. h + ndn - 1 (below): depth. */
EF_INLINE const float *row_depth(const ef_edge_rows *u, int r)
{
    const float *d = r < 0 ? u->up_depth : r >= u->h ? u->dn_depth : u->depth;
    return d ? d + row_off(u, r) : NULL;
}

/* The larger and the smaller of two finite values, without libm's call
 * (fmax and fmin take care of NaN, which these never see). */
EF_INLINE double max2(double a, double b)
{
    return a > b ? a : b;
}

EF_INLINE double min2(double a, double b)
{
    return a < b ? a : b;
}

/* Pixel (x, r)'s premultiplied RGB and alpha (1 without alpha; a value
 * that is not finite counts as 0). */
EF_INLINE void pixel_colour(const ef_edge_rows *u, int r, int x, double c[4])
{
    const float *const *rgb = r < 0 ? u->up_rgb : r >= u->h ? u->dn_rgb : u->rgb;
    const float *a = r < 0 ? u->up_alpha : r >= u->h ? u->dn_alpha : u->alpha;
    const size_t off = row_off(u, r) + (size_t) x;
    for (int k = 0; k < 3; ++k)
        c[k] = rgb[k] ? rgb[k][off] : 0;
    c[3] = a ? a[off] : 1.0;
    for (int k = 0; k < 4; ++k)
        if (!isfinite(c[k]))
            c[k] = 0;
}

/* out[j] = 1 / planar[j] (0 for sky, NaN where the depth is not positive
 * and finite), without branches, so the loop vectorises. */
EF_MULTIVERSION static void inverse_span(const double *planar, const unsigned char *sky, int n,
                                         double *out)
{
    for (int j = 0; j < n; ++j) {
        const double p = planar[j];
        const double inv = 1.0 / p;
        const double v = p > 0 && p < INFINITY ? inv : NAN;
        out[j] = sky[j] ? 0.0 : v;
    }
}

/* 1 / planar depth of every pixel of rows -HR..h + HR - 1 (0 for sky, NaN
 * where the row is missing or the depth unusable) into wk->iz, (h + 2 HR)
 * rows of w. */
static void inverse_depths(const ef_fog_pass *pass, const ef_edge_rows *u, double *iz)
{
    double planar[EF_RECON_SPAN];
    unsigned char sky[EF_RECON_SPAN];
    for (int r = -HR; r < u->h + HR; ++r) {
        double *out = iz + (size_t) (r + HR) * (size_t) u->w;
        const float *d = row_there(u, r) ? row_depth(u, r) : NULL;
        if (!d) {
            for (int x = 0; x < u->w; ++x)
                out[x] = NAN;
            continue;
        }
        for (int xs = 0; xs < u->w; xs += EF_RECON_SPAN) {
            const int n = u->w - xs < EF_RECON_SPAN ? u->w - xs : EF_RECON_SPAN;
            ef_reconstruct_dist(pass->cam, pass->conv, u->x0 + xs, u->y0 + r, n, d + xs, 0, planar,
                                NULL, sky);
            inverse_span(planar, sky, n, out + xs);
        }
    }
}

/* Whether 1/z bends from A through c to B: by more than EF_EDGE_REL of
 * the largest (false where any is NaN: a missing row or depth). */
EF_INLINE int bends3(double A, double c, double B)
{
    double m = c > A ? c : A;
    m = m > B ? m : B;
    return fabs(A - 2 * c + B) > EF_EDGE_REL * m;
}

/* The edge flags of a row: whether 1/z bends at each x over a pair of
 * opposite neighbours (the rows up, mid and dn of 1/z; a missing row is
 * NaN). Without branches, so the loop vectorises. */
EF_MULTIVERSION static void bends_row(const double *up, const double *mid, const double *dn,
                                      int w, unsigned char *e)
{
    if (w < 3) {
        for (int x = 0; x < w; ++x)
            e[x] = (unsigned char) bends3(up[x], mid[x], dn[x]);
        return;
    }
    e[0] = (unsigned char) bends3(up[0], mid[0], dn[0]);
    for (int x = 1; x < w - 1; ++x) {
        const double c = mid[x];
        e[x] = (unsigned char) (bends3(mid[x - 1], c, mid[x + 1]) | bends3(up[x - 1], c, dn[x + 1]) |
                                bends3(dn[x - 1], c, up[x + 1]) | bends3(up[x], c, dn[x]));
    }
    e[w - 1] = (unsigned char) bends3(up[w - 1], mid[w - 1], dn[w - 1]);
}

/* Whether 1/z value q belongs to the layer of 1/z value l. */
static int same_layer(double q, double l)
{
    return l == 0 ? q == 0 : fabs(q - l) <= EF_EDGE_REL * l;
}

/* The layers of a window and the colours their pure pixels show. */
#define MAXL 4      /* layers per 3x3 window */
#define MAXC 12     /* colours per layer */
typedef struct layer {
    double iz;      /* 1 / planar depth (0: sky) */
    float v;        /* a stored depth value of it in the 3x3 window */
    int n;
    int npure;      /* colours of pixels that are no edges (a surface's own); the rest mixed */
    double c[MAXC][4];
} layer;

/* The 5x5 window's cells around its centre, nearest first (Chebyshev
 * ring, then Manhattan distance). */
static const signed char ring_cells[24][2] = {
    { 0, -1 }, { -1, 0 }, { 1, 0 }, { 0, 1 }, { -1, -1 }, { 1, -1 }, { -1, 1 }, { 1, 1 },
    { 0, -2 }, { -2, 0 }, { 2, 0 }, { 0, 2 }, { -1, -2 }, { 1, -2 }, { -2, -1 }, { 2, -1 },
    { -2, 1 }, { 2, 1 }, { -1, 2 }, { 1, 2 }, { -2, -2 }, { 2, -2 }, { -2, 2 }, { 2, 2 },
};

/* Up to MAXC colours of each of the nl layers Ls in one pass over the 5x5
 * window of (x, r): a layer's pixels that are not edges themselves,
 * nearest first; where it has none, its other pixels of the 3x3 window
 * (the edge pixel itself excepted); never an outlier's. */
static void layer_colours(const ef_edge_rows *u, const double *iz, const unsigned char *edge,
                          const unsigned char *outl, int x, int r, layer *Ls, int nl)
{
    const int w = u->w;
    int nmix[MAXL] = { 0 };
    double mix[MAXL][8][4];
    for (int m = 0; m < nl; ++m)
        Ls[m].n = 0;
    for (int q = 0; q < 24; ++q) {
        const int xx = x + ring_cells[q][0], rr = r + ring_cells[q][1];
        if (xx < 0 || xx >= w)
            continue;
        const size_t k = (size_t) (rr + HR) * (size_t) w + (size_t) xx;
        const double v = iz[k];
        if (isnan(v) || outl[k])
            continue;
        int m = 0;
        while (m < nl && !same_layer(v, Ls[m].iz))
            ++m;
        if (m == nl)
            continue;
        if (!edge[k]) {
            if (Ls[m].n < MAXC)
                pixel_colour(u, rr, xx, Ls[m].c[Ls[m].n++]);
        } else if (q < 8 && nmix[m] < 8) {
            pixel_colour(u, rr, xx, mix[m][nmix[m]++]);
        }
    }
    for (int m = 0; m < nl && m < MAXL; ++m) {
        Ls[m].npure = Ls[m].n;
        if (!Ls[m].npure) {
            for (int q = 0; q < nmix[m] && q < 8; ++q)
                memcpy(Ls[m].c[q], mix[m][q], sizeof mix[m][q]);
            Ls[m].n = nmix[m];
        }
    }
}

/* The share s of colour a in C = s a + (1 - s) b (RGB and alpha, least
 * squares, s in [0, 1]) and the squared residual; 0 where the two are
 * too alike to tell (their RGB within CONTRAST_MIN of the larger and
 * their alphas equal). */
static int unmix(const double C[4], const double a[4], const double b[4], double *s, double *res2,
                 double *dd_out)
{
    double dd = 0, dot = 0, mag = 0;
    for (int c = 0; c < 4; ++c) {
        const double d = a[c] - b[c];
        dd += d * d;
        dot += (C[c] - b[c]) * d;
        if (c < 3)
            mag = max2(mag, max2(fabs(a[c]), fabs(b[c])));
    }
    const double rgb2 = dd - (a[3] - b[3]) * (a[3] - b[3]);
    if (!(rgb2 > CONTRAST_MIN * CONTRAST_MIN * mag * mag) && !(fabs(a[3] - b[3]) > CONTRAST_MIN))
        return 0;
    double sm = dot / dd;
    sm = sm < 0 ? 0 : sm > 1 ? 1 : sm;
    double r2 = 0;
    for (int c = 0; c < 4; ++c) {
        const double e = C[c] - (sm * a[c] + (1 - sm) * b[c]);
        r2 += e * e;
    }
    *s = sm;
    *res2 = r2;
    *dd_out = dd;
    return 1;
}

/* The layers the 8 neighbours of (x, r) show (1/z clusters; the pixel's
 * own depth may be none of them; outliers' depths are none), each with
 * one stored depth value: their count. */
static int window_layers(const ef_edge_rows *u, const double *iz, const unsigned char *outl,
                         int x, int r, layer *Ls)
{
    const int w = u->w;
    int nl = 0;
    for (int dr = -1; dr <= 1; ++dr)
        for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, rr = r + dr;
            if (xx < 0 || xx >= w || (dx == 0 && dr == 0))
                continue;
            const size_t kq = (size_t) (rr + HR) * (size_t) w + (size_t) xx;
            const double q = iz[kq];
            if (isnan(q) || outl[kq])
                continue;
            int m = 0;
            while (m < nl && !same_layer(q, Ls[m].iz) && !same_layer(Ls[m].iz, q))
                ++m;
            if (m == nl && nl < MAXL) {
                Ls[nl].iz = q;
                Ls[nl].v = row_depth(u, rr)[xx];
                ++nl;
            }
        }
    return nl;
}

/* How an edge pixel splits: layer a's part (share s, colour pa) and layer
 * b's (colour pb), the share's uncertainty du. */
typedef struct split {
    int a, b;
    double s, du;
    double pa[4], pb[4];
} split;

/* sp as the pixel's own depth's part (share s, colour pa: the pixel's
 * own) and layer b's (colour pb), du the share's uncertainty; returns 1. */
static int set_split(split *sp, int b, double s, double du, const double pa[4],
                     const double pb[4])
{
    sp->a = -1;
    sp->b = b;
    sp->s = s;
    sp->du = du;
    memcpy(sp->pa, pa, sizeof sp->pa);
    memcpy(sp->pb, pb, sizeof sp->pb);
    return 1;
}

/* The index of the colour of c[0 .. n) nearest ref (far: farthest), in
 * RGB and alpha; its squared distance into *d2 (may be NULL). n >= 1. */
static int pick(const double (*c)[4], int n, const double ref[4], int far, double *d2)
{
    int best = 0;
    double bd = far ? -1 : INFINITY;
    for (int q = 0; q < n; ++q) {
        double d = 0;
        for (int k = 0; k < 4; ++k)
            d += (c[q][k] - ref[k]) * (c[q][k] - ref[k]);
        if (far ? d > bd : d < bd) {
            bd = d;
            best = q;
        }
    }
    if (d2)
        *d2 = bd;
    return best;
}

/* The colour a thing thinner than the filter has, from its most distinct
 * pixel `through`, a mix with `from` in which it holds a share w: taken
 * beyond itself to out, its alpha kept in [0, 1]. */
static void beyond(const double from[4], const double through[4], double w, double out[4])
{
    for (int k = 0; k < 4; ++k)
        out[k] = from[k] + (through[k] - from[k]) / w;
    out[3] = out[3] > 1 ? 1 : out[3] < 0 ? 0 : out[3];
}

/* C as a mix of colour a (the pixel's own layer) and b (layer mb): kept
 * in sp where its residual is the least so far (*best, and *bdd the two
 * colours' squared difference). */
static void try_mix(const double C[4], const double a[4], const double b[4], int mb, split *sp,
                    double *best, double *bdd)
{
    double sm, r2, dd;
    if (!unmix(C, a, b, &sm, &r2, &dd) || !(r2 < *best))
        return;
    *best = r2;
    *bdd = dd;
    sp->s = sm;
    sp->b = mb;
    memcpy(sp->pa, a, sizeof sp->pa);
    memcpy(sp->pb, b, sizeof sp->pb);
}

/* The pixel's own depth is layer own (a closest-sample or one-sample Z):
 * the share from the colours. A colour within the range its own layer's
 * pure pixels span is that surface's texture, not a mix. Else the own
 * colour nearest to it (where the layer shows no pure pixel, a thing
 * thinner than the filter, the most distinct one taken beyond itself at
 * W_THIN of the way) and the other layer's colour that explains it best:
 * the least share that can be given away. 0 where no mix explains C. */
static int split_by_colour(const double C[4], const layer *Ls, int nl, int own, split *sp)
{
    const layer *O = &Ls[own];
    if (O->n == 0)
        return 0;
    int inside = O->npure > 0;
    for (int c = 0; c < 4 && inside; ++c) {
        double lo = O->c[0][c], hi = lo;
        for (int ia = 1; ia < O->npure; ++ia) {
            lo = min2(lo, O->c[ia][c]);
            hi = max2(hi, O->c[ia][c]);
        }
        const double tol = 0.01 * max2(fabs(lo), fabs(hi)) + 1e-6;
        inside = C[c] >= lo - tol && C[c] <= hi + tol;
    }
    if (inside)
        return 0;
    const int near = pick(O->c, O->n, C, 0, NULL);
    double best = INFINITY, bdd = 1;
    sp->a = own;
    sp->b = -1;
    for (int mb = 0; mb < nl; ++mb) {
        if (mb == own)
            continue;
        if (O->npure && !Ls[mb].npure) {
            /* the other layer thinner than the filter (no pure pixel of
             * it: a gap, a sliver): its most distinct pixel taken beyond
             * itself at W_THIN_OTHER, as the own layer's is at W_THIN
             * when it is the thin one */
            const double *a = O->c[near];
            double bx[4];
            beyond(a, Ls[mb].c[pick(Ls[mb].c, Ls[mb].n, a, 1, NULL)], W_THIN_OTHER, bx);
            try_mix(C, a, bx, mb, sp, &best, &bdd);
            continue;
        }
        for (int ib = 0; ib < Ls[mb].n; ++ib) {
            const double *bc = Ls[mb].c[ib];
            double a[4];
            if (O->npure)
                memcpy(a, O->c[near], sizeof a);
            else
                beyond(bc, O->c[pick(O->c, O->n, bc, 1, NULL)], W_THIN, a);
            try_mix(C, a, bc, mb, sp, &best, &bdd);
        }
    }
    if (sp->b < 0 || sqrt(best / bdd) > RES_MAX)
        return 0;
    sp->du = fmin(1, sqrt(best / bdd) + DU_FLOOR + (O->npure && Ls[sp->b].npure ? 0 : 0.25));
    return 1;
}

/* The pixel's depth lies between the layers (a filtered Z, the mean of
 * the surfaces' depths): the share from it, Z = s z_a + (1 - s) z_b with
 * the layers just in front and behind. 0 where there are not both. */
static int split_by_depth(double izp, const layer *Ls, int nl, split *sp)
{
    int a = -1, b = -1;
    for (int m = 0; m < nl; ++m) {
        if (Ls[m].iz > izp && (a < 0 || Ls[m].iz < Ls[a].iz))
            a = m;
        if (Ls[m].iz < izp && (b < 0 || Ls[m].iz > Ls[b].iz))
            b = m;
    }
    if (a < 0 || b < 0 || Ls[a].n == 0 || Ls[b].n == 0)
        return 0;
    const double za = 1 / Ls[a].iz, zp = 1 / izp;
    double s = Ls[b].iz > 0 ? (1 / Ls[b].iz - zp) / (1 / Ls[b].iz - za) : 1;
    sp->a = a;
    sp->b = b;
    sp->s = !(s > 0) ? 0 : s > 1 ? 1 : s;
    sp->du = 0.5;
    memcpy(sp->pa, Ls[a].c[0], sizeof sp->pa);
    memcpy(sp->pb, Ls[b].c[0], sizeof sp->pb);
    return 1;
}

/* Whether (x, r)'s depth is an outlier: at most one neighbour's depth is
 * its layer (a pair of such pixels), it lies in front of all the others
 * or behind them all, and its colour is theirs (within OUTLIER_TOL of
 * their range per channel). A depth sample that struck something the
 * pixel hardly shows (a fast thing's motion blur, a hair, a grain of
 * foliage), or missed the surface it shows; not a thing of its own as
 * small as a pixel or two, nor the end of a line, whose colour stands
 * out. Reads rows r - 1 .. r + 1. */
static int is_outlier(const ef_edge_rows *u, const double *iz, int x, int r)
{
    const int w = u->w;
    const double izp = iz[(size_t) (r + HR) * (size_t) w + (size_t) x];
    if (isnan(izp))
        return 0;
    double lo[4] = { 0, 0, 0, 0 }, hi[4] = { 0, 0, 0, 0 };
    int nn = 0, front = 0, behind = 0, shared = 0;
    for (int dr = -1; dr <= 1; ++dr)
        for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, rr = r + dr;
            if (xx < 0 || xx >= w || (dx == 0 && dr == 0))
                continue;
            const double q = iz[(size_t) (rr + HR) * (size_t) w + (size_t) xx];
            if (isnan(q))
                continue;
            if (same_layer(q, izp) || same_layer(izp, q)) {
                if (++shared > 1)
                    return 0;
                continue;
            }
            front += izp > q;
            behind += izp < q;
            double c[4];
            pixel_colour(u, rr, xx, c);
            for (int k = 0; k < 4; ++k) {
                lo[k] = nn ? min2(lo[k], c[k]) : c[k];
                hi[k] = nn ? max2(hi[k], c[k]) : c[k];
            }
            ++nn;
        }
    if (nn < 3 || (front && behind))
        return 0;
    double C[4], mag = 0;
    pixel_colour(u, r, x, C);
    for (int k = 0; k < 3; ++k)
        mag = max2(mag, max2(fabs(lo[k]), fabs(hi[k])));
    for (int k = 0; k < 4; ++k) {
        const double tol = OUTLIER_TOL * (k < 3 ? mag : 1) + 1e-6;
        if (!(C[k] >= lo[k] - tol && C[k] <= hi[k] + tol))
            return 0;
    }
    return 1;
}

/* An outlier's split (is_outlier): its own depth's share 0, its colour
 * all the layer's whose colours lie nearest it, DU_FLOOR the share's
 * uncertainty. 0 where no layer shows a colour. */
static int split_outlier(const double C[4], const layer *Ls, int nl, split *sp)
{
    int b = -1;
    double dmin = INFINITY;
    for (int m = 0; m < nl; ++m) {
        if (Ls[m].n == 0)
            continue;
        double d2;
        pick(Ls[m].c, Ls[m].n, C, 0, &d2);
        if (d2 < dmin) {
            dmin = d2;
            b = m;
        }
    }
    if (b < 0)
        return 0;
    return set_split(sp, b, 0, DU_FLOOR, C, C);
}

/* The pass's result stands (all of it the pixel's own surface, as far as
 * the colours tell); for the error output, what a share DU_KEEP of the
 * layer farthest from its own would move it by. 0 where that layer shows
 * no colour. */
static int split_keep(const double C[4], double izp, const layer *Ls, int nl, split *sp)
{
    int b = 0;
    for (int m = 1; m < nl; ++m)
        if (fabs(Ls[m].iz - izp) > fabs(Ls[b].iz - izp))
            b = m;
    if (Ls[b].n == 0)
        return 0;
    return set_split(sp, b, 1, DU_KEEP, C, Ls[b].c[0]);
}

int ef_edge_find(const ef_fog_pass *pass, const ef_edge_rows *u, int want_err, ef_edge_work *wk)
{
    const int w = u->w, h = u->h;
    const size_t n = (size_t) (h + 2 * HR) * (size_t) w;
    if (n > wk->cap) {
        double *iz = realloc(wk->iz, n * sizeof *iz);
        if (!iz)
            return -1;
        wk->iz = iz;
        unsigned char *e = realloc(wk->edge, n);
        if (!e)
            return -1;
        wk->edge = e;
        unsigned char *o = realloc(wk->outl, n);
        if (!o)
            return -1;
        wk->outl = o;
        wk->cap = n;
    }
    double *iz = wk->iz;
    unsigned char *edge = wk->edge, *outl = wk->outl;
    inverse_depths(pass, u, iz);
    /* edges on the rows the 5x5 windows reach (missing rows are NaN,
     * which fails every bends3; the outermost rows have no test) */
    memset(edge, 0, (size_t) w);
    memset(edge + (size_t) (h + 2 * HR - 1) * (size_t) w, 0, (size_t) w);
    for (int r = 1 - HR; r < h + HR - 1; ++r) {
        const double *mid = iz + (size_t) (r + HR) * (size_t) w;
        bends_row(mid - w, mid, mid + w, w, edge + (size_t) (r + HR) * (size_t) w);
    }
    /* outliers on the rows the 5x5 windows reach (each is an edge: its
     * 1/z bends against every neighbour) */
    memset(outl, 0, n);
    for (int r = 1 - HR; r < h + HR - 1; ++r)
        for (int x = 0; x < w; ++x) {
            const size_t k = (size_t) (r + HR) * (size_t) w + (size_t) x;
            outl[k] = edge[k] && is_outlier(u, iz, x, r);
        }
    /* per 16-row band of the unit: edge pixels seen, and those whose
     * depth lies between layers */
    const size_t nband = (size_t) (h + 15) / 16;
    if (2 * nband > wk->bandcap) {
        int *b = realloc(wk->band, 2 * nband * sizeof *b);
        if (!b)
            return -1;
        wk->band = b;
        wk->bandcap = 2 * nband;
    }
    int *const seen_b = wk->band, *const between_b = wk->band + nband;
    memset(wk->band, 0, 2 * nband * sizeof *wk->band);
    int count = 0;
    for (int r = 0; r < h; ++r)
        for (int x = 0; x < w; ++x) {
            const size_t k = (size_t) (r + HR) * (size_t) w + (size_t) x;
            /* most pixels are no edge: eight flags at a time */
            if (!(x & 7) && x + 8 <= w) {
                uint64_t eight;
                memcpy(&eight, edge + k, sizeof eight);
                if (!eight) {
                    x += 7;
                    continue;
                }
            }
            if (!edge[k])
                continue;
            layer Ls[MAXL];
            const int nl = window_layers(u, iz, outl, x, r, Ls);
            const double izp = iz[k];
            if (nl < 1 || (nl == 1 && same_layer(izp, Ls[0].iz)))
                continue;   /* curvature, not two layers (one: the pixel's own depth another) */
            const float vp = u->depth[(size_t) r * (size_t) w + (size_t) x];
            layer_colours(u, iz, edge, outl, x, r, Ls, nl);
            int own = -1;
            for (int m = 0; m < nl; ++m)
                if (same_layer(izp, Ls[m].iz) && (own < 0 || (Ls[m].npure && !Ls[own].npure)))
                    own = m;
            double C[4];
            pixel_colour(u, r, x, C);
            seen_b[r / 16]++;
            split sp;
            int found, outlier = 0;
            if (own >= 0) {
                found = split_by_colour(C, Ls, nl, own, &sp);
            } else {
                outlier = outl[k];
                found = outlier ? split_outlier(C, Ls, nl, &sp) : split_by_depth(izp, Ls, nl, &sp);
                between_b[r / 16] += !outlier && found;
            }
            int kept = 0;
            if (!found || (sp.a == own && sp.s >= 1)) {
                if (!want_err || !split_keep(C, izp, Ls, nl, &sp))
                    continue;
                kept = 1;
            }
            if ((size_t) count >= wk->pxcap) {
                const size_t cap = wk->pxcap ? 2 * wk->pxcap : 256;
                ef_edge_px *p = realloc(wk->px, cap * sizeof *p);
                if (!p)
                    return -1;
                wk->px = p;
                wk->pxcap = cap;
            }
            ef_edge_px *e = &wk->px[count++];
            e->i = r * w + x;
            e->v[0] = kept || sp.a == own ? vp : Ls[sp.a].v;
            e->v[1] = sp.b == own ? vp : Ls[sp.b].v;
            e->w = sp.s;
            e->du = sp.du;
            e->between = own < 0 && !kept && !outlier;
            e->keep = kept;
            for (int c = 0; c < 4; ++c) {
                const double res = C[c] - (sp.s * sp.pa[c] + (1 - sp.s) * sp.pb[c]);
                e->c[0][c] = sp.s * (sp.pa[c] + res);
                e->c[1][c] = C[c] - e->c[0][c];
                e->pure[0][c] = sp.pa[c];
                e->pure[1][c] = sp.pb[c];
            }
        }
    /* A band whose edge pixels mostly lie between layers has a filtered
     * Z: there a pixel whose depth is a layer is that surface's (nearly)
     * alone, and its colour's likeness to a mix is the texture's. */
    int k = 0;
    for (int m = 0; m < count; ++m) {
        const int b = wk->px[m].i / w / 16;
        const int texture = between_b[b] > seen_b[b] / 5 && !wk->px[m].between;
        if (texture && !want_err)
            continue;
        wk->px[k] = wk->px[m];
        wk->px[k++].keep |= texture;
    }
    return k;
}

/* The mixable planes of an AOV binding (not fog_P, not fog_distance), in a
 * fixed order; returns their count. */
static int mixable(const ef_aov_out *a, float **out)
{
    int n = 0;
    for (int k = 0; k < 4; ++k)
        out[n++] = a->fog[k];
    for (int k = 0; k < 3; ++k)
        out[n++] = a->T[k];
    for (int k = 0; k < 3; ++k)
        out[n++] = a->err[k];
    for (int k = 0; k < 3; ++k)
        out[n++] = a->ambient[k];
    for (int l = 0; l < EF_MAX_LIGHTS; ++l)
        for (int k = 0; k < 3; ++k)
            out[n++] = a->light[l][k];
    for (int l = 0; l < EF_MAX_LIGHTS; ++l)
        out[n++] = a->lit[l];
    for (int k = 0; k < 3; ++k)
        out[n++] = a->sky[k];
    return n;
}

#define NMIX (4 + 3 + 3 + 3 + 4 * EF_MAX_LIGHTS + 3)

/* Edge pixels fogged together when they are neighbours in a row. */
#define RUN 64

void ef_edge_apply(const ef_fog_pass *pass, int x0, int y0, int w, const ef_edge_px *e, int n,
                   float *const rgb[3], float *alpha, const ef_aov_out *aov)
{
    const ef_fog_scene *s = pass->scene;
    const unsigned mask = aov ? aov->mask : 0;
    float vals[2][EF_AOV_MAX_CHANNELS][RUN];
    float *planes[2][EF_AOV_MAX_CHANNELS];
    ef_aov_out loc[2];
    float *unit_mix[NMIX], *loc_mix[2][NMIX];
    int nmix = 0;
    if (mask) {
        for (int p = 0; p < 2; ++p) {
            for (int c = 0; c < EF_AOV_MAX_CHANNELS; ++c)
                planes[p][c] = vals[p][c];
            memset(&loc[p], 0, sizeof loc[p]);
            ef_aov_bind(&loc[p], mask, s, planes[p]);
            memcpy(loc[p].origin, aov->origin, sizeof loc[p].origin);
            mixable(&loc[p], loc_mix[p]);
        }
        nmix = mixable(aov, unit_mix);
    }
    for (int m = 0; m < n;) {
        /* a run of edge pixels next to each other in one row */
        int len = 1;
        while (m + len < n && len < RUN && e[m + len].i == e[m].i + len &&
               e[m + len].i / w == e[m].i / w)
            ++len;
        const int x = x0 + e[m].i % w, y = y0 + e[m].i / w;
        float c[2][3][RUN], a[2][RUN], v[2][RUN];
        for (int p = 0; p < 2; ++p) {
            for (int j = 0; j < len; ++j) {
                const ef_edge_px *E = &e[m + j];
                const double wp = p ? 1 - E->w : E->w;
                for (int k = 0; k < 3; ++k)
                    c[p][k][j] = (float) (wp > 1e-9 ? E->c[p][k] / wp : E->pure[p][k]);
                a[p][j] = (float) (wp > 1e-9 ? E->c[p][3] / wp : E->pure[p][3]);
                v[p][j] = E->v[p];
            }
            float *cp[3] = { c[p][0], c[p][1], c[p][2] };
            ef_fog_block_aov(pass, x, y, len, 1, cp, alpha ? a[p] : NULL, v[p],
                             mask ? &loc[p] : NULL, NULL);
        }
        for (int j = 0; j < len; ++j) {
            const ef_edge_px *E = &e[m + j];
            if (E->keep) {
                /* the pass's pixel stands; only the error output learns more */
                for (int k = 0; mask & EF_AOV_ERROR && k < 3; ++k)
                    aov->err[k][E->i] += (float) (E->du * fabs(c[0][k][j] - c[1][k][j]));
                continue;
            }
            const double sh = E->w;
            for (int k = 0; k < 3; ++k)
                rgb[k][E->i] = (float) (sh * c[0][k][j] + (1 - sh) * c[1][k][j]);
            if (alpha && isfinite(alpha[E->i]))
                alpha[E->i] = (float) (sh * a[0][j] + (1 - sh) * a[1][j]);
            for (int q = 0; q < nmix; ++q)
                if (unit_mix[q] && loc_mix[0][q] && loc_mix[1][q])
                    unit_mix[q][E->i] =
                        (float) (sh * loc_mix[0][q][j] + (1 - sh) * loc_mix[1][q][j]);
            if (mask & EF_AOV_ERROR)
                for (int k = 0; k < 3; ++k)
                    aov->err[k][E->i] += (float) (E->du * fabs(c[0][k][j] - c[1][k][j]));
        }
        m += len;
    }
}
