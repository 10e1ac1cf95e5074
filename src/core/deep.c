/* Deep pixels: the OpenEXR rules (split, merge, tidy, flatten) and the fog
 * as volume samples whose alpha and colour are exact integrals. */
#include "deep.h"
#include "ms.h"

#include "lit.h"
#include "sky_light.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

void ef_deep_buf_init(ef_deep_buf *b, int nch)
{
    memset(b, 0, sizeof *b);
    b->stride = EF_DEEP_STRIDE(nch);
}

void ef_deep_buf_free(ef_deep_buf *b)
{
    free(b->v);
    free(b->bnd);
    free(b->ord);
    free(b->sv);
    free(b->ft);
    free(b->cut);
    free(b->lv);
    for (int i = 0; i < b->ndense; ++i)
        ef_lit_dense_free(&b->dense[i]);
    free(b->dense);
    const int stride = b->stride;
    memset(b, 0, sizeof *b);
    b->stride = stride;
}

/* Grows *p to hold n elements of size sz (capacity in elements in *cap). */
static int reserve(void **p, int *cap, int n, size_t sz)
{
    if (n <= *cap)
        return 0;
    int c = *cap ? *cap : 64;
    while (c < n)
        c *= 2;
    void *q = realloc(*p, (size_t) c * sz);
    if (!q)
        return -1;
    *p = q;
    *cap = c;
    return 0;
}

double *ef_deep_buf_push_raw(ef_deep_buf *b)
{
    if (b->n == b->cap) {
        const int cap = b->cap ? 2 * b->cap : 16;
        double *v = realloc(b->v, (size_t) cap * (size_t) b->stride * sizeof *v);
        if (!v)
            return NULL;
        b->v = v;
        b->cap = cap;
    }
    return b->v + (size_t) b->n++ * (size_t) b->stride;
}

double *ef_deep_buf_push(ef_deep_buf *b)
{
    double *s = ef_deep_buf_push_raw(b);
    if (s)
        memset(s, 0, (size_t) b->stride * sizeof *s);
    return s;
}

double ef_deep_split_alpha(double a, double x)
{
    if (!(a < 1))
        return 1;
    if (a <= FLT_MIN)
        return a * x;
    return -expm1(x * log1p(-a));
}

/* Scales one sample's values to the fraction x of its slab (the split
 * rule for every channel of s; COPY channels stay). Each alpha's split is
 * computed once and shared by the colours that use it. */
static void split_values(const ef_deep_layout *L, const double *s, double x, double *d)
{
    for (int c = 0; c < L->nch; ++c)
        if (L->role[c] == EF_DEEP_ALPHA)
            d[c] = ef_deep_split_alpha(s[c], x);
    for (int c = 0; c < L->nch; ++c) {
        if (L->role[c] == EF_DEEP_ALPHA)
            continue;
        if (L->role[c] != EF_DEEP_COLOR) {
            d[c] = s[c];
            continue;
        }
        const int ai = L->alpha[c];
        const double a = ai >= 0 ? s[ai] : 0;
        if (ai >= 0 && !(a < 1))
            d[c] = s[c];
        else if (ai >= 0 && a > FLT_MIN)
            d[c] = s[c] * (d[ai] / a);
        else
            d[c] = s[c] * x;
    }
}

/* Merges coincident q into p: alphas 1 - (1 - a)(1 - b); colours by the
 * optical-depth weighting of the spec (u = -log1p(-a), v = u / a), each
 * alpha's weights computed once. */
static void merge_into(const ef_deep_layout *L, double *p, const double *q)
{
    double v1[EF_DEEP_MAX_CH], v2[EF_DEEP_MAX_CH], w[EF_DEEP_MAX_CH];
    for (int c = 0; c < L->nch; ++c) {
        if (L->role[c] != EF_DEEP_ALPHA)
            continue;
        const double a1 = p[c], a2 = q[c];
        if (a1 < 1 && a2 < 1) {
            const double u1 = -log1p(-a1), u2 = -log1p(-a2);
            v1[c] = a1 > 0 ? u1 / a1 : 1;
            v2[c] = a2 > 0 ? u2 / a2 : 1;
            const double a = a1 + a2 - a1 * a2;
            w[c] = u1 + u2 > 0 ? a / (u1 + u2) : 1;
        }
    }
    for (int c = 0; c < L->nch; ++c) {
        if (L->role[c] == EF_DEEP_COPY) {
            if (p[c] == 0)
                p[c] = q[c];
            continue;
        }
        if (L->role[c] != EF_DEEP_COLOR)
            continue;
        const int ai = L->alpha[c];
        if (ai < 0) {
            p[c] += q[c];
            continue;
        }
        const double a1 = p[ai], a2 = q[ai];
        if (!(a1 < 1) && !(a2 < 1))
            p[c] = 0.5 * (p[c] + q[c]);
        else if (!(a2 < 1))
            p[c] = q[c];
        else if (a1 < 1)
            p[c] = w[ai] * (p[c] * v1[ai] + q[c] * v2[ai]);
        /* else p is opaque: its colour stands */
    }
    for (int c = 0; c < L->nch; ++c)
        if (L->role[c] == EF_DEEP_ALPHA)
            p[c] = p[c] + q[c] - p[c] * q[c];
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return x < y ? -1 : x > y;
}

typedef struct order {
    double z, zb;
    int i;
} order;

static int cmp_order(const void *a, const void *b)
{
    const order *x = a, *y = b;
    if (x->z != y->z)
        return x->z < y->z ? -1 : 1;
    if (x->zb != y->zb)
        return x->zb < y->zb ? -1 : 1;
    return (x->i > y->i) - (x->i < y->i);
}

/* Sorts m elements of sz <= 32 bytes: insertion while the input is nearly
 * in order (samples from renderers, and tidy samples with fog merged in by
 * depth, are), a full sort once it proves not to be. */
static void sort_nearly(void *base, int m, size_t sz, int (*cmp)(const void *, const void *))
{
    unsigned char *e = base, v[32];
    long moves = 0;
    for (int i = 1; i < m; ++i) {
        memcpy(v, e + (size_t) i * sz, sz);
        int j = i;
        while (j > 0 && cmp(e + (size_t) (j - 1) * sz, v) > 0) {
            memcpy(e + (size_t) j * sz, e + (size_t) (j - 1) * sz, sz);
            --j;
            if (++moves > 8L * m + 64) {
                memcpy(e + (size_t) j * sz, v, sz);
                qsort(base, (size_t) m, sz, cmp);
                return;
            }
        }
        memcpy(e + (size_t) j * sz, v, sz);
    }
}

/* The sorted distinct fronts and backs of b's samples, into own->bnd.
 * Returns the count, or -1 when out of memory. */
static int bounds_of(const ef_deep_buf *b, int nch, ef_deep_buf *own)
{
    if (reserve((void **) &own->bnd, &own->bcap, 2 * b->n + 1, sizeof *own->bnd))
        return -1;
    double *B = own->bnd;
    int m = 0;
    for (int i = 0; i < b->n; ++i) {
        const double *s = b->v + (size_t) i * (size_t) b->stride;
        B[m++] = s[nch];
        if (s[nch + 1] > s[nch])
            B[m++] = s[nch + 1];
    }
    sort_nearly(B, m, sizeof *B, cmp_double);
    int u = 0;
    for (int i = 0; i < m; ++i)
        if (u == 0 || B[i] != B[u - 1])
            B[u++] = B[i];
    return u;
}

/* Whether b is tidy already (renderers mostly write it so): sorted, no
 * two samples alike, none starting inside an earlier volume. */
static int is_tidy(const ef_deep_buf *b, int nch)
{
    double back = -INFINITY, pz = -INFINITY, pzb = -INFINITY;
    for (int i = 0; i < b->n; ++i) {
        const double *s = b->v + (size_t) i * (size_t) b->stride;
        const double z = s[nch], zb = s[nch + 1] > z ? s[nch + 1] : z;
        if (z < back || !(z > pz || (z == pz && zb > pzb)))
            return 0;
        back = zb;
        pz = z;
        pzb = zb;
    }
    return 1;
}

long long ef_deep_tidy_cap(int stride)
{
    return EF_DEEP_TIDY_BYTES / ((long long) stride * (long long) sizeof(double) +
                                 (long long) sizeof(order));
}

/* The first index of B[0..nb) not below z (B sorted). */
static int lower_bound(const double *B, int nb, double z)
{
    int lo = 0, hi = nb;
    while (lo < hi) {
        const int mid = lo + (hi - lo) / 2;
        if (B[mid] < z)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* A running sum with Neumaier's compensation: samples' densities are
 * added at their fronts and taken away at their backs, and what is left
 * where few remain must not be the rounding of what passed. */
typedef struct nsum {
    double s, c;
} nsum;

static void nadd(nsum *a, double x)
{
    const double t = a->s + x;
    a->c += fabs(a->s) >= fabs(x) ? (a->s - t) + x : (x - t) + a->s;
    a->s = t;
}

/* Whether tidy_sweep serves in: no id channel (their first-non-zero rule
 * follows the merge's order), every volume's alphas in [0, 1) and every
 * value finite. */
static int sweep_ok(const ef_deep_layout *L, const ef_deep_buf *in)
{
    const int nch = L->nch;
    for (int c = 0; c < nch; ++c)
        if (L->role[c] == EF_DEEP_COPY)
            return 0;
    for (int i = 0; i < in->n; ++i) {
        const double *s = in->v + (size_t) i * (size_t) in->stride;
        if (!(s[nch + 1] > s[nch]))
            continue;
        for (int c = 0; c < nch; ++c)
            if (!isfinite(s[c]) || (L->role[c] == EF_DEEP_ALPHA && !(s[c] >= 0 && s[c] < 1)))
                return 0;
    }
    return 1;
}

/* The tidy list of in by one sweep over its sorted distinct boundaries B
 * (nb of them), in O(n log n + nb nch) time and O(nb nch) memory where
 * the split makes O(n^2) pieces. Over an interval of length l inside a
 * volume of length V, the split rule gives the volume optical depth
 * u l / V per alpha channel (u = -log1p(-a)) and keeps each colour per
 * unit optical depth, c v (v = u / a; 1 where a = 0); the merge of
 * coincident pieces adds the optical depths and the colours weighted by
 * theirs (merge_into keeps sum u and sum c v). So per interval
 * U = l sum(u / V) and K = l sum(c v / V) over the volumes that span it,
 * running sums of densities added at fronts and taken at backs, and the
 * merged piece is alpha = -expm1(-U), colour = K alpha / U (K where U is
 * 0); colours without an alpha add (K = l sum(c / V)). Points are merged
 * among themselves as ef_deep_tidy does, before the interval starting at
 * their depth. Returns 0 or -1 (out of memory). */
static int tidy_sweep(const ef_deep_layout *L, const ef_deep_buf *in, ef_deep_buf *out,
                      const double *B, int nb)
{
    const int nch = L->nch, S = in->stride;
    double *dens = calloc((size_t) nb * (size_t) nch, sizeof *dens);
    int *cnt = calloc((size_t) nb, sizeof *cnt), np = 0;
    nsum *run = calloc((size_t) nch, sizeof *run);
    if (!dens || !cnt || !run || reserve(&out->ord, &out->ocap, in->n, sizeof(order))) {
        free(dens);
        free(cnt);
        free(run);
        return -1;
    }
    order *pts = out->ord;
    for (int i = 0; i < in->n; ++i) {
        const double *s = in->v + (size_t) i * (size_t) S;
        const double z = s[nch], zb = s[nch + 1];
        if (!(zb > z)) {
            pts[np++] = (order){ z, z, i };
            continue;
        }
        const int lo = lower_bound(B, nb, z), hi = lower_bound(B, nb, zb);
        const double V = zb - z;
        double v[EF_DEEP_MAX_CH];
        for (int c = 0; c < nch; ++c)
            if (L->role[c] == EF_DEEP_ALPHA) {
                const double u = -log1p(-s[c]);
                v[c] = s[c] > 0 ? u / s[c] : 1;
                dens[(size_t) lo * nch + c] += u / V;
                dens[(size_t) hi * nch + c] -= u / V;
            }
        for (int c = 0; c < nch; ++c)
            if (L->role[c] == EF_DEEP_COLOR) {
                const int ai = L->alpha[c];
                const double d = s[c] * (ai >= 0 ? v[ai] : 1) / V;
                dens[(size_t) lo * nch + c] += d;
                dens[(size_t) hi * nch + c] -= d;
            }
        ++cnt[lo];
        --cnt[hi];
    }
    sort_nearly(pts, np, sizeof *pts, cmp_order);
    int ip = 0, active = 0, rc = 0;
    for (int j = 0; j < nb && !rc; ++j) {
        /* the points at B[j], merged in input order */
        double *prev = NULL;
        for (; ip < np && pts[ip].z <= B[j]; ++ip) {
            const double *s = in->v + (size_t) pts[ip].i * (size_t) S;
            if (prev) {
                merge_into(L, prev, s);
                continue;
            }
            if (!(prev = ef_deep_buf_push_raw(out))) {
                rc = -1;
                break;
            }
            memcpy(prev, s, (size_t) S * sizeof *prev);
            prev[nch + 1] = prev[nch];
        }
        active += cnt[j];
        for (int c = 0; c < nch; ++c)
            nadd(&run[c], dens[(size_t) j * nch + c]);
        if (active <= 0 || j + 1 >= nb || rc)
            continue;
        double *d = ef_deep_buf_push_raw(out);
        if (!d) {
            rc = -1;
            break;
        }
        const double l = B[j + 1] - B[j];
        double U[EF_DEEP_MAX_CH];
        for (int c = 0; c < nch; ++c)
            if (L->role[c] == EF_DEEP_ALPHA) {
                U[c] = fmax(0.0, l * (run[c].s + run[c].c));
                d[c] = -expm1(-U[c]);
            }
        for (int c = 0; c < nch; ++c) {
            const double K = l * (run[c].s + run[c].c);
            const int ai = L->alpha[c];
            if (L->role[c] == EF_DEEP_COLOR)
                d[c] = ai >= 0 && U[ai] > 0 ? K * (d[ai] / U[ai]) : K;
            else if (L->role[c] == EF_DEEP_Z)
                d[c] = B[j];
            else if (L->role[c] == EF_DEEP_ZBACK)
                d[c] = B[j + 1];
        }
        d[nch] = B[j];
        d[nch + 1] = B[j + 1];
    }
    free(dens);
    free(cnt);
    free(run);
    return rc;
}

int ef_deep_tidy(const ef_deep_layout *L, const ef_deep_buf *in, ef_deep_buf *out)
{
    const int nch = L->nch, S = in->stride;
    out->n = 0;
    if (in->n == 0)
        return 0;
    if (is_tidy(in, nch)) {
        for (int i = 0; i < in->n; ++i) {
            const double *s = in->v + (size_t) i * (size_t) S;
            double *d = ef_deep_buf_push_raw(out);
            if (!d)
                return -1;
            memcpy(d, s, (size_t) S * sizeof *d);
            if (!(d[nch + 1] > d[nch]))
                d[nch + 1] = d[nch];
        }
        return 0;
    }
    const int nb = bounds_of(in, nch, out);
    if (nb < 0)
        return -1;
    const double *B = out->bnd;
    /* how many pieces first: a volume makes one per boundary interval it
     * spans (B holds its front and back exactly), a point one */
    long long total = 0;
    for (int i = 0; i < in->n; ++i) {
        const double *s = in->v + (size_t) i * (size_t) S;
        const double z = s[nch], zb = s[nch + 1];
        total += zb > z ? lower_bound(B, nb, zb) - lower_bound(B, nb, z) : 1;
    }
    out->pieces = total;
    /* where the samples overlap heavily, the sweep (linear in them);
     * elsewhere the pieces, as renders' files keep them */
    if (total > 4LL * in->n + 64 && sweep_ok(L, in))
        return tidy_sweep(L, in, out, B, nb);
    if (total > ef_deep_tidy_cap(S))
        return -2;
    /* the pieces: every point, every volume cut at every depth inside it */
    int np = 0;
    for (int i = 0; i < in->n; ++i) {
        const double *s = in->v + (size_t) i * (size_t) S;
        const double z = s[nch], zb = s[nch + 1];
        const int lo = zb > z ? lower_bound(B, nb, z) : 0;
        for (int j = lo; zb > z ? j + 1 < nb && B[j + 1] <= zb : j == lo; ++j) {
            if (reserve((void **) &out->sv, &out->scap, (np + 1) * S, sizeof *out->sv))
                return -1;
            double *d = out->sv + (size_t) np++ * (size_t) S;
            if (!(zb > z)) {
                memcpy(d, s, (size_t) S * sizeof *d);
                d[nch + 1] = z;
                continue;
            }
            if (B[j] == z && B[j + 1] == zb)
                memcpy(d, s, (size_t) S * sizeof *d);
            else
                split_values(L, s, (B[j + 1] - B[j]) / (zb - z), d);
            d[nch] = B[j];
            d[nch + 1] = B[j + 1];
        }
    }
    if (reserve(&out->ord, &out->ocap, np, sizeof(order)))
        return -1;
    order *ord = out->ord;
    for (int i = 0; i < np; ++i) {
        const double *s = out->sv + (size_t) i * (size_t) S;
        ord[i] = (order){ s[nch], s[nch + 1], i };
    }
    sort_nearly(ord, np, sizeof *ord, cmp_order);
    double *prev = NULL;
    for (int i = 0; i < np; ++i) {
        const double *s = out->sv + (size_t) ord[i].i * (size_t) S;
        if (prev && prev[nch] == s[nch] && prev[nch + 1] == s[nch + 1]) {
            merge_into(L, prev, s);
            continue;
        }
        double *d = ef_deep_buf_push_raw(out);
        if (!d)
            return -1;
        memcpy(d, s, (size_t) S * sizeof *d);
        prev = d;
    }
    return 0;
}

/* ---- the fog over one interval ---- */

/* The optical depth per channel of the scene over [a, b) of the ray whose
 * unit-distance form is r1 (b may be INFINITY), and the colour it scatters
 * in (the scene's, or the tau-weighted mean of the components' own); with
 * err, the models' error estimates summed. *linear: every component's
 * density is constant along the ray (a split of this interval is then
 * exact). */
/* The segment [a, b) of the ray whose unit-distance form is r1 as a ray of
 * its own: from the point at a, of length b - a (b may be INFINITY). */
static ef_ray seg_ray(const ef_ray *r1, double a, double b)
{
    ef_ray seg = *r1;
    for (int k = 0; k < 3; ++k)
        seg.org[k] = r1->org[k] + r1->dir[k] * a;
    seg.dist = b - a;
    seg.planar = isinf(b) ? INFINITY : (b - a) * r1->planar;
    return seg;
}

/* One component's optical depth per channel over [a, b) of the ray whose
 * unit-distance form is r1 (b may be INFINITY), into t; with ip, its error
 * estimate added to err. Depth-only models are defined from the camera, so
 * theirs is the difference of the two distances' optical depths; the
 * others integrate a density along a segment ray that starts at a. */
static void comp_tau(const ef_fog_component *c, const ef_ray *r1, double a, double b, double t[3],
                     double err[3])
{
    ef_tau_info info, *ip = err ? &info : NULL;
    if (c->model->depth_only) {
        ef_ray ra = *r1, rb = *r1;
        ra.dist = a;
        ra.planar = a * r1->planar;
        rb.dist = b;
        rb.planar = isinf(b) ? INFINITY : b * r1->planar;
        double ta[3] = { 0, 0, 0 }, tb[3];
        if (a > 0) {
            ef_fog_tau(c, &ra, ta, ip);
            for (int k = 0; err && k < 3; ++k)
                err[k] += info.err[k];
        }
        ef_fog_tau(c, &rb, tb, ip);
        for (int k = 0; k < 3; ++k)
            t[k] = isinf(ta[k]) ? INFINITY : tb[k] - ta[k];
    } else {
        const ef_ray seg = seg_ray(r1, a, b);
        ef_fog_tau(c, &seg, t, ip);
    }
    for (int k = 0; err && k < 3; ++k)
        err[k] += info.err[k];
    for (int k = 0; k < 3; ++k)
        if (!(t[k] > 0))
            t[k] = 0;
}

/* A pixel's light sources for its fog samples' colours. */
typedef struct px_lit {
    int lights;                                 /* --light: each sample's in-scatter */
    int sky;                                    /* --sky-light: sky_c joins the colours */
    double sky_c[EF_FOG_MAX_COMPONENTS][3];     /* albedo_c C_c(u), u the pixel's direction */
    double scale;   /* the lights' in-scatter along the pixel's visible ray: the colour unit */
    /* lights whose in-scatter along the whole ray (to dend) is in dense[j]
     * (bit j): a segment's is then a difference of it, not a quadrature */
    unsigned dmask;
    double dend;
    ef_lit_dense *dense;       /* the thread's (ef_deep_buf.dense): its memo changes */
    double rel;                /* the lights' quadratures' accuracy (dense_rel) */
} px_lit;

static void seg_tau(const ef_fog_scene *s, const px_lit *lt, const ef_ray *r1, double a, double b,
                    double tau[3], double F[3], double Fsky[3], int *linear, double err[3])
{
    const int sky = lt && lt->sky;
    double wc[3] = { 0, 0, 0 }, winf[3] = { 0, 0, 0 }, ws[3] = { 0, 0, 0 }, wsi[3] = { 0, 0, 0 };
    int ninf[3] = { 0, 0, 0 };
    tau[0] = tau[1] = tau[2] = 0;
    if (err)
        err[0] = err[1] = err[2] = 0;
    if (linear)
        *linear = 1;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double t[3];
        comp_tau(c, r1, a, b, t, err);
        if (linear && c->model != &ef_fog_exp)
            *linear = 0;
        for (int k = 0; k < 3; ++k) {
            tau[k] += t[k];
            const double col =
                (c->has_color ? c->color[k] : s->color[k]) + (sky ? lt->sky_c[i][k] : 0.0);
            const double sc = sky ? lt->sky_c[i][k] : 0.0;
            if (isinf(t[k])) {
                ninf[k]++;
                winf[k] += col;
                wsi[k] += sc;
            } else {
                wc[k] += t[k] * col;
                ws[k] += t[k] * sc;
            }
        }
    }
    for (int k = 0; k < 3; ++k) {
        const int first = (!s->any_color && !sky) || tau[k] == 0;
        if (first)
            F[k] = s->color[k] + (sky ? lt->sky_c[0][k] : 0.0);
        else
            F[k] = ninf[k] ? winf[k] / ninf[k] : wc[k] / tau[k];
        /* the sky light's share of it, weighted alike */
        if (Fsky)
            Fsky[k] = !sky ? 0.0
                      : first ? lt->sky_c[0][k]
                      : ninf[k] ? wsi[k] / ninf[k] : ws[k] / tau[k];
    }
}

/* Appends one fog sample over [a, b) with optical depths tau: colour col
 * per unit alpha (the ambient and the sky light) plus the lights' own
 * in-scatter S over it. */
static int emit(const ef_deep_layout *L, const ef_deep_fog *F, ef_deep_buf *fog, double a, double b,
                const double tau[3], const double col[3], const double csky[3],
                const double S[3], const double (*Sl)[3])
{
    double *d = ef_deep_buf_push(fog);
    if (!d)
        return -1;
    double al[3], mean = 0;
    for (int k = 0; k < 3; ++k) {
        al[k] = k && tau[k] == tau[k - 1] ? al[k - 1] : isinf(tau[k]) ? 1.0 : -expm1(-tau[k]);
        mean += al[k] / 3;
    }
    if (F->per_light) {
        const int nl = F->scene->nlight, nv = EF_DEEP_LV(F->scene), at = (fog->n - 1) * nv;
        if (reserve((void **) &fog->lv, &fog->lvcap, at + nv, sizeof *fog->lv))
            return -1;
        for (int j = 0; j < nl; ++j)
            for (int k = 0; k < 3; ++k)
                fog->lv[at + 3 * j + k] = Sl ? Sl[j][k] : 0;
        for (int k = 0; k < 3 && F->scene->sky_light; ++k)
            fog->lv[at + 3 * nl + k] = !F->scene->sky_multiple ? csky[k] * al[k]
                                       : Sl ? Sl[nl][k] : 0;
    }
    /* colour per channel always (exact); alpha per channel where the
     * layout has AR/AG/AB, else A alone, the mean */
    for (int k = 0; k < 3; ++k) {
        if (L->rgb[k] >= 0)
            d[L->rgb[k]] = col[k] * al[k] + S[k];
        if (L->argb[k] >= 0 && L->argb[k] != L->a)
            d[L->argb[k]] = F->chromatic ? al[k] : mean;
    }
    if (L->a >= 0)
        d[L->a] = mean;
    d[L->nch] = a;
    d[L->nch + 1] = b;
    return 0;
}

static double max3(const double v[3])
{
    return fmax(v[0], fmax(v[1], v[2]));
}

/* An interval of the fog waiting to be emitted or split: its optical
 * depths, colour per unit alpha and their error estimates, and the
 * lights' in-scatter over it (from its front) with theirs. */
typedef struct piece {
    double a, b, tau[3], col[3], csky[3], err[3], S[3], Se[3];
    double Ta[3];             /* T(0, a) per channel, Ta[0] < 0 when not known */
    int depth;
} piece;

/* Light j's in-scatter over [a, b) seen from a from its dense output d,
 * built to relative accuracy rel: (J(b) - J(a)) / T(0, a), Ta = T(0, a),
 * with the leaves' estimates from a's to b's as its error. 0 (the caller
 * integrates the segment itself) where that error passes 1e-6 of the
 * segment's light plus 10 rel of the whole ray's (1e-6 at the default
 * --deep-tol, dense_rel; a segment beyond which T has underflowed, or one
 * whose difference the whole ray's rounding would swamp): what a
 * composite sees of a sample is T(0, a) times its light, so the second
 * term bounds the composite's error at 1e-3 of --deep-tol (1e-9 at least)
 * relative to the pixel's light. */
static int dense_light(ef_lit_dense *d, double a, double b, double rel, const double Ta[3],
                       double v[3], double e[3])
{
    double Ja[3], Ea[3], La[3], Jb[3], Eb[3], Lb[3];
    const double *Jt = d->total;
    ef_lit_dense_at(d, a, Ja, Ea, La);
    ef_lit_dense_at(d, b, Jb, Eb, Lb);
    for (int k = 0; k < 3; ++k) {
        const double dj = Jb[k] - Ja[k];
        /* the leaves from a's to b's, and the rounding of J's sums */
        const double de = (Eb[k] - La[k]) + 1e-15 * fabs(Jb[k]);
        if (!(Ta[k] > 1e-300) || !(de <= 1e-6 * fabs(dj) + 10 * rel * fabs(Jt[k])))
            return 0;
        v[k] = dj > 0 ? dj / Ta[k] : 0;
        e[k] = de / Ta[k];
    }
    return 1;
}

/* The relative accuracy a pixel's dense output is built to for
 * --deep-tol tol: 1e-4 of it, between 1e-10 (the flat path's) and 1e-7.
 * The output's samples need their light to a small share of what a split
 * may change, not to the flat path's 1e-10 or 1e-13, and a Kronrod rule's
 * pieces grow as the accuracy loosens (Balls, a lamp in height fog: the
 * --deep fog run 10.1 -> 8.5 s). */
static double dense_rel(double tol)
{
    return fmin(1e-7, fmax(1e-10, 1e-4 * tol));
}

/* T(0, a) along r1 per channel into Ta, unless Ta[0] >= 0 says it is there. */
static void seg_ta(const ef_fog_scene *s, const ef_ray *r1, double a, double Ta[3])
{
    if (Ta[0] >= 0)
        return;
    double tau[3] = { 0, 0, 0 };
    for (int i = 0; i < s->ncomp; ++i) {
        double t[3];
        comp_tau(&s->comp[i], r1, 0, a, t, NULL);
        for (int k = 0; k < 3; ++k)
            tau[k] += t[k];
    }
    for (int k = 0; k < 3; ++k)
        Ta[k] = exp(-tau[k]);
}

/* A point lamp's multiple scattering over [a, b) of r1 seen from a, with
 * its estimate: where r1 starts at the camera the lamp is bound to, from
 * the camera's table, G(b) - G(a) over T(0, a) (G the gather from the
 * camera, which the table holds; the two estimates, over T(0, a), in the
 * estimate), else integrated along the segment seg. A deep pixel's many
 * samples then cost two lookups each, not a quadrature each. Where T(0,
 * a) is below 1e-6 the difference would lose its digits: integrated. */
static void lms_segment(const ef_light *l, const ef_ray *r1, const ef_ray *seg, double a, double b,
                        const double Ta[3], double vm[3], double em[3])
{
    if (a == 0) {   /* from the camera: the table itself (or integrated off it) */
        ef_lms_gather_view(l->lms, l->lms_view, r1, 0, b, vm, em);
        return;
    }
    if (!l->lms_view || !(Ta[0] >= 1e-6 && Ta[1] >= 1e-6 && Ta[2] >= 1e-6)) {
        ef_lms_gather(l->lms, seg, 0, seg->dist, vm, em);
        return;
    }
    double Gb[3], Eb[3], Ga[3], Ea[3];
    ef_lms_gather_view(l->lms, l->lms_view, r1, 0, b, Gb, Eb);
    ef_lms_gather_view(l->lms, l->lms_view, r1, 0, a, Ga, Ea);
    for (int k = 0; k < 3; ++k) {
        vm[k] = (Gb[k] - Ga[k]) / Ta[k];
        em[k] = (Eb[k] + Ea[k]) / Ta[k];
    }
}

/* The lights' in-scatter over [a, b) of r1 (b may be INFINITY), seen from
 * a (T counted from there), summed over the scene's lights, into S, and
 * their error estimates into E. Ta: T(0, a) per channel when known (the
 * dense lights need it), else Ta[0] < 0 and it is computed there when
 * needed and left in Ta. */
static void seg_light(const ef_fog_scene *s, const px_lit *lt, const ef_ray *r1, double a,
                      double b, double S[3], double E[3], double (*per)[3], double Ta[3])
{
    S[0] = S[1] = S[2] = E[0] = E[1] = E[2] = 0;
    const ef_ray seg = seg_ray(r1, a, b);
    for (int j = 0; j < s->nlight; ++j) {
        double v[3], e[3];
        int done = 0;
        const ef_light *l = &s->light[j];
        /* a lamp's multiple scattering in fog that is not uniform is part
         * of its quadrature's integrand (ms.h), as its single scattering */
        const int gather = l->lms && !ef_lms_is_local(l->lms);
        if (lt && (lt->dmask >> j & 1) && b <= lt->dend) {
            seg_ta(s, r1, a, Ta);
            done = dense_light(&lt->dense[j], a, b, lt->rel, Ta, v, e);
        }
        if (!done && gather) {
            /* the single scattering here, the multiple below */
            ef_light single = *l;
            single.lms = NULL;
            ef_light_inscatter_rel(s, &single, &seg, lt ? lt->rel : 0, v, e);
        } else if (!done) {
            ef_light_inscatter_rel(s, l, &seg, lt ? lt->rel : 0, v, e);
        }
        if (gather) {
            /* the dense output or the segment's inscatter is the single
             * scattering: a point lamp's multiple scattering beside it */
            double vm[3], em[3];
            seg_ta(s, r1, a, Ta);
            lms_segment(l, r1, &seg, a, b, Ta, vm, em);
            for (int k = 0; k < 3; ++k) {
                v[k] += vm[k];
                e[k] += em[k];
            }
        }
        for (int k = 0; k < 3; ++k) {
            S[k] += v[k];
            E[k] += e[k];
            if (per)
                per[j][k] = v[k];
        }
    }
    if (s->sky_light && s->sky_multiple) {   /* the sky's, after the lights */
        double v[3], e[3];
        ef_ms_gather_view(s->sky_ms, &s->sky_ms_view, s, &seg, NULL, v, e);
        for (int k = 0; k < 3; ++k) {
            S[k] += v[k];
            E[k] += e[k];
            if (per)
                per[s->nlight][k] = v[k];
        }
    }
}

/* The piece [a, b) of r1 with every value computed; Ta: T(0, a) when
 * known (NULL: not). */
static piece make_piece(const ef_deep_fog *F, const px_lit *lt, const ef_ray *r1, double a,
                        double b, int depth, int *linear, double (*per)[3], const double *Ta)
{
    piece p = { .a = a, .b = b, .depth = depth, .Ta = { -1, -1, -1 } };
    if (Ta)
        memcpy(p.Ta, Ta, sizeof p.Ta);
    seg_tau(F->scene, lt, r1, a, b, p.tau, p.col, p.csky, linear, F->want_err ? p.err : NULL);
    if (lt->lights)
        seg_light(F->scene, lt, r1, a, b, p.S, p.Se, per, p.Ta);
    return p;
}

/* split_bound's term for one monotone component from its optical depths
 * over the slab (tb) and its front half (tm). */
static double split_dev(const double tb[3], const double tm[3])
{
    double dev = 0;
    for (int k = 0; k < 3; ++k) {
        if (isinf(tb[k]))
            return INFINITY;
        dev = fmax(dev, fabs(tm[k] - 0.5 * tb[k]));
    }
    return 2 * dev;
}

/* A bound on what a later split of the slab [a, b) can change: the
 * largest |tau(a, a + x h) - x tau(a, b)| over x in [0, 1] and the
 * channels, summed over the components (h = b - a). For a density monotone
 * along the slab that difference is convex or concave in x and zero at
 * both ends, so it is at most twice its value at x = 1/2 (certified, from
 * two exact optical depths); models that are not monotone (noise) bound
 * their rate instead, |d sigma/dt| <= D on the slab giving h^2 D / 8.
 * Models without dsigma_max are monotone between the crossings of their
 * jump and kink features (fog.h), which fog_interval splits at first. */
static double split_bound(const ef_fog_scene *s, const ef_ray *r1, double a, double b)
{
    const double m = 0.5 * (a + b), h = b - a;
    double sum = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (c->model == &ef_fog_exp)
            continue;
        if (c->model->dsigma_max) {
            const ef_ray seg = seg_ray(r1, a, b);
            sum += h * h / 8 * c->model->dsigma_max(c, &seg);
            continue;
        }
        double tb[3], tm[3];
        comp_tau(c, r1, a, b, tb, NULL);
        comp_tau(c, r1, a, m, tm, NULL);
        sum += split_dev(tb, tm);
    }
    return sum;
}

/* Where along r1 (unit-distance form), strictly inside (a, b), a
 * component's density jumps or kinks (its features of scale 0): into
 * fog->cut, sorted (every one of them: a layered profile may have thousands
 * of knots, and a missed one would break the monotone promise); returns
 * how many, or -1 when out of memory. */
#define FUNCTIONAL_CAP 64
static int feature_cuts(const ef_fog_scene *s, const ef_ray *r1, double a, double b,
                        ef_deep_buf *fog)
{
    int n = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->functionals || !c->model->features)
            continue;
        ef_fog_functional fn[FUNCTIONAL_CAP];
        const int nf = c->model->functionals(c, fn, FUNCTIONAL_CAP);
        const int nt = c->model->features(c, NULL, 0);
        if (reserve(&fog->ft, &fog->ftcap, nt, sizeof(ef_fog_feature)) ||
            reserve((void **) &fog->cut, &fog->ccap, n + nt, sizeof *fog->cut))
            return -1;
        ef_fog_feature *ft = fog->ft;
        c->model->features(c, ft, nt);
        for (int j = 0; j < nt; ++j) {
            if (ft[j].scale != 0 || ft[j].f < 0 || ft[j].f >= nf || ft[j].f >= FUNCTIONAL_CAP)
                continue;
            const ef_fog_functional *f = &fn[ft[j].f];
            const double v0 =
                f->n[0] * r1->org[0] + f->n[1] * r1->org[1] + f->n[2] * r1->org[2] + f->d;
            const double rate = f->n[0] * r1->dir[0] + f->n[1] * r1->dir[1] + f->n[2] * r1->dir[2];
            if (rate == 0)
                continue;
            const double tc = (ft[j].value - v0) / rate;
            if (tc > a && tc < b)
                fog->cut[n++] = tc;
        }
    }
    sort_nearly(fog->cut, n, sizeof *fog->cut, cmp_double);
    return n;
}

/* The split rule's colour error at the piece's middle, relative to the
 * pixel's light: |S(a, m) - S(a, b) alpha(a, m) / alpha(a, b)| per
 * channel, the lights' in-scatter over the front half against what the
 * rule gives it, twice (as split_bound's midpoint, for a deviation that
 * is zero at both ends and turns once: light cuts keep the source
 * monotone within a piece), times T(0, a). */
static double color_est(const piece *p, const piece *front, double Tf, double scale)
{
    double dev = 0;
    for (int k = 0; k < 3; ++k) {
        const double al = isinf(p->tau[k]) ? 1.0 : -expm1(-p->tau[k]);
        const double af = isinf(front->tau[k]) ? 1.0 : -expm1(-front->tau[k]);
        const double pred = al > 0 ? p->S[k] * (af / al) : 0.0;
        dev = fmax(dev, fabs(front->S[k] - pred));
    }
    return Tf * 2 * dev / scale;
}

/* The fog over [a, b) (b finite) in samples, front to back, splitting
 * where tau passes the cap or a later split's error estimate (of T, or of
 * the lit colour relative to the pixel's light) passes tol; *Tf: the
 * largest channel's transmittance from the camera to a, advanced to b. */
static int fog_piece(const ef_deep_layout *L, const ef_deep_fog *F, const px_lit *lt,
                     const ef_ray *r1, double a, double b, double *Tf, ef_deep_buf *fog,
                     ef_deep_stats *st)
{
    enum { DEPTH = 48, PARTS = 8, STACK = DEPTH + 2 + 2 * PARTS };
    piece stack[STACK];
    /* with F->per_light, stack entry i's light per light, kept beside the
     * stack (not in each piece, which is copied as it moves) */
    double sl[STACK][EF_MAX_LIGHTS + 1][3];
#define PER(i) (F->per_light ? sl[(i)] : NULL)
    int linear;
    const ef_fog_scene *sc = F->scene;
    const int one = sc->ncomp == 1 && !sc->comp[0].model->dsigma_max;
    stack[0] = make_piece(F, lt, r1, a, b, 0, &linear, PER(0), NULL);
    int sp = 1;
    while (sp > 0) {
        const piece p = stack[--sp];
        const double sa = p.a, sb = p.b, m = 0.5 * (sa + sb);
        /* Behind T < tol nothing a later split or alpha's rounding does
         * can show: one sample takes the rest. */
        const int can = p.depth < DEPTH && m > sa && m < sb && fog->n < F->max_samples &&
                        *Tf > F->tol;
        int split = can && max3(p.tau) > F->tau_cap;
        double est = 0;
        piece front;
        int have_front = 0;
        if (!split && !linear && *Tf > F->tol && isfinite(max3(p.tau))) {
            /* |dT| of any later split <= T(0, a) times the slab's bound;
             * with one monotone component, from the slab's optical depths
             * and its front half's, which a split or the colour's estimate
             * needs anyway (split_bound would compute both again) */
            if (can && one) {
                front = make_piece(F, lt, r1, sa, m, p.depth + 1, NULL, PER(sp + 1),
                                   p.Ta[0] >= 0 ? p.Ta : NULL);
                have_front = 1;
                est = *Tf * split_dev(p.tau, front.tau);
            } else {
                est = *Tf * split_bound(F->scene, r1, sa, sb);
            }
            split = can && est > F->tol;
        }
        if (!split && can && lt->lights && lt->scale > 0 && isfinite(max3(p.S))) {
            if (!have_front)
                front = make_piece(F, lt, r1, sa, m, p.depth + 1, NULL, PER(sp + 1),
                                   p.Ta[0] >= 0 ? p.Ta : NULL);
            have_front = 1;
            const double ec = color_est(&p, &front, *Tf, lt->scale);
            est = fmax(est, ec);
            split = ec > F->tol;
        }
        /* how many equal parts: the estimate falls with the square of a
         * piece's length, so sqrt(est / tol) parts would each pass; a
         * part that does not splits again, so this only saves the tests
         * of the levels a bisection would pass through */
        int parts = 2;
        if (split) {
            const double want = fmax(max3(p.tau) / F->tau_cap, sqrt(est / F->tol));
            parts = want < PARTS ? (int) ceil(want) : PARTS;
            /* room for the top part's bisections down to DEPTH */
            if (parts < 2 || sp + parts + DEPTH - p.depth - 1 > STACK)
                parts = 2;
        }
        if (split && parts > 2) {
            /* front to back, so that each part's T(0, a) follows from
             * the one before; the first on top of the stack */
            const double h = (sb - sa) / parts;
            double Ta[3];
            memcpy(Ta, p.Ta, sizeof Ta);
            for (int i = 0; i < parts; ++i) {
                const double x0 = i ? sa + i * h : sa, x1 = i + 1 < parts ? sa + (i + 1) * h : sb;
                const int slot = sp + parts - 1 - i;
                stack[slot] = make_piece(F, lt, r1, x0, x1, p.depth + 1, NULL, PER(slot),
                                         Ta[0] >= 0 ? Ta : NULL);
                for (int k = 0; k < 3; ++k)
                    Ta[k] = stack[slot].Ta[k] >= 0 ? stack[slot].Ta[k] * exp(-stack[slot].tau[k])
                                                   : -1;
            }
            sp += parts;
            continue;
        }
        if (split) {
            /* the back half after: in p's slot, the front above it */
            if (!have_front)
                front = make_piece(F, lt, r1, sa, m, p.depth + 1, NULL, PER(sp + 1),
                                   p.Ta[0] >= 0 ? p.Ta : NULL);
            /* T(0, m) = T(0, a) T(a, m) */
            double Tm[3];
            for (int k = 0; k < 3; ++k)
                Tm[k] = front.Ta[k] >= 0 ? front.Ta[k] * exp(-front.tau[k]) : -1;
            stack[sp] = make_piece(F, lt, r1, m, sb, p.depth + 1, NULL, PER(sp),
                                   Tm[0] >= 0 ? Tm : NULL);
            ++sp;
            stack[sp++] = front;
            continue;
        }
        if (st) {
            if (est > st->max_split_est)
                st->max_split_est = est;
            if (fog->n >= F->max_samples)
                st->capped = 1;
        }
        if (emit(L, F, fog, sa, sb, p.tau, p.col, p.csky, p.S, PER(sp)))
            return -1;
        for (int k = 0; st && k < 3; ++k) {
            st->pix_err[k] += p.err[k];
            st->pix_light_err[k] += *Tf * p.Se[k];
        }
        /* the clearest channel's transmittance: exp of the smallest tau */
        const double tmin = fmin(p.tau[0], fmin(p.tau[1], p.tau[2]));
        *Tf *= isinf(tmin) ? 0 : exp(-tmin);
    }
    return 0;
}
#undef PER

/* The fog over [a, b) (b finite) in samples, front to back: split first
 * where a component's density jumps or kinks (so that each piece is
 * monotone where a model says so) and where a light's source does
 * (ef_light_cuts), then by fog_piece. */
static int fog_interval(const ef_deep_layout *L, const ef_deep_fog *F, const px_lit *lt,
                        const ef_ray *r1, double a, double b, double *Tf, ef_deep_buf *fog,
                        ef_deep_stats *st)
{
    int n = F->tau_cap < INFINITY ? feature_cuts(F->scene, r1, a, b, fog) : 0;
    if (n < 0)
        return -1;
    if (lt->lights && F->tau_cap < INFINITY) {   /* (a flatten splits nothing) */
        enum { LIGHT_CUTS = 256 };
        const ef_fog_scene *s = F->scene;
        if (reserve((void **) &fog->cut, &fog->ccap, n + s->nlight * LIGHT_CUTS, sizeof *fog->cut))
            return -1;
        for (int j = 0; j < s->nlight; ++j)
            n += ef_light_cuts(&s->light[j], r1, a, b, fog->cut + n, LIGHT_CUTS);
        sort_nearly(fog->cut, n, sizeof *fog->cut, cmp_double);
    }
    double prev = a;
    for (int i = 0; i <= n; ++i) {
        const double e = i < n ? fog->cut[i] : b;
        if (e > prev && fog_piece(L, F, lt, r1, prev, e, Tf, fog, st))
            return -1;
        prev = e > prev ? e : prev;
    }
    return 0;
}

/* Behind the last boundary a to infinity: samples out to where what is
 * left of the fog changes T by at most tol, the last one carrying the
 * optical depth (and the light) to infinity, so the flatten is exact. */
static int fog_tail(const ef_deep_layout *L, const ef_deep_fog *F, const px_lit *lt,
                    const ef_ray *r1, double a, double *Tf, ef_deep_buf *fog, ef_deep_stats *st)
{
    double tinf[3], cinf[3];
    seg_tau(F->scene, lt, r1, a, INFINITY, tinf, cinf, NULL, NULL, NULL);
    if (!(max3(tinf) > 0))
        return 0;
    double Tinf = 0;
    for (int k = 0; k < 3; ++k)
        Tinf = fmax(Tinf, isinf(tinf[k]) ? 0 : exp(-tinf[k]));
    double h = a > 1 ? a : 1, end = a + h;
    for (int i = 0; i < 400; ++i) {
        double t[3], c[3], T = 0;
        end = a + h;
        seg_tau(F->scene, lt, r1, a, end, t, c, NULL, NULL, NULL);
        for (int k = 0; k < 3; ++k)
            T = fmax(T, isinf(t[k]) ? 0 : exp(-t[k]));
        if (*Tf * (T - Tinf) <= F->tol || !isfinite(a + 2 * h))
            break;
        h *= 2;
    }
    const int first = fog->n;
    const double T0 = *Tf;
    if (!(F->tau_cap < INFINITY)) {
        /* a flatten splits nothing: one sample from a takes it all (what
         * the pieces below would come to, without computing them first) */
        double *d = ef_deep_buf_push(fog);
        if (!d)
            return -1;
        d[L->nch] = a;
        d[L->nch + 1] = end;
    } else if (fog_interval(L, F, lt, r1, a, end, Tf, fog, st)) {
        return -1;
    }
    if (fog->n > first) {
        /* the last sample takes everything behind its front */
        double *d = fog->v + (size_t) (fog->n - 1) * (size_t) fog->stride;
        const double za = d[L->nch], zb = d[L->nch + 1];
        double t[3], c[3], cs[3], e[3], S[3] = { 0, 0, 0 }, Se[3] = { 0, 0, 0 };
        double Sl[EF_MAX_LIGHTS + 1][3] = { { 0 } };
        /* (its error replaces nothing: the piece it extends stays counted,
         * an over-estimate) */
        seg_tau(F->scene, lt, r1, za, INFINITY, t, c, cs, NULL, F->want_err ? e : NULL);
        double Ta[3] = { -1, -1, -1 };
        if (lt->lights)
            seg_light(F->scene, lt, r1, za, INFINITY, S, Se, F->per_light ? Sl : NULL, Ta);
        for (int k = 0; st && k < 3; ++k) {
            if (F->want_err)
                st->pix_err[k] += e[k];
            st->pix_light_err[k] += T0 * Se[k];
        }
        fog->n--;
        if (emit(L, F, fog, za, zb, t, c, cs, S, Sl))
            return -1;
    }
    return 0;
}

/* Whether a tidy sample hides everything behind its front in every fog
 * channel. */
static int opaque(const ef_deep_layout *L, const double *s)
{
    int any = 0;
    for (int k = 0; k < 3; ++k) {
        const int ai = L->argb[k] >= 0 ? L->argb[k] : L->a;
        if (ai < 0)
            continue;
        any = 1;
        if (s[ai] < 1)
            return 0;
    }
    return any;
}

int ef_deep_fog_samples(const ef_deep_layout *L, const ef_deep_fog *F, const ef_ray *r,
                        const ef_deep_buf *tidy, int stop_at_opaque, ef_deep_buf *fog,
                        ef_deep_stats *st)
{
    const int nch = L->nch;
    fog->n = 0;
    if (st)
        for (int k = 0; k < 3; ++k)
            st->pix_err[k] = st->pix_light_err[k] = 0;
    ef_ray r1 = *r;
    r1.dist = 1;
    if (!(r->planar > 0) || !isfinite(r->planar) || !isfinite(r->dist) || !(r->dist > 0))
        r1.planar = 1;
    else
        r1.planar = r->planar / r->dist;
    double cut = INFINITY;
    if (stop_at_opaque)
        for (int i = 0; i < tidy->n; ++i) {
            const double *s = tidy->v + (size_t) i * (size_t) tidy->stride;
            if (opaque(L, s)) {
                cut = s[nch];
                break;
            }
        }
    const int nb = bounds_of(tidy, nch, fog);
    if (nb < 0)
        return -1;
    const double *B = fog->bnd;
    const ef_fog_scene *s = F->scene;
    /* a sky carried through the fog (scattering=multiple) is lit like a
     * light, per sample; else its unattenuated light joins the colours */
    px_lit lt = { .lights = s->nlight > 0 || (s->sky_light && s->sky_multiple),
                  .sky = s->sky_light != NULL && !s->sky_multiple,
                  .rel = dense_rel(F->tol) };
    for (int i = 0; lt.sky && i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        ef_sky_light_eval(s->sky_light, c->phase, c->g, s->ctx.up, r1.dir, lt.sky_c[i]);
        for (int k = 0; k < 3; ++k)
            lt.sky_c[i][k] *= c->has_albedo ? c->albedo[k] : 1.0;
    }
    if (lt.lights && F->tau_cap < INFINITY) {
        /* the colour contract's unit: the lights' in-scatter along what
         * the pixel shows of its ray (a flatten splits nothing: none) */
        const double last = nb > 0 ? B[nb - 1] : 0;
        const double end = isfinite(cut) ? cut
                           : s->sky == EF_SKY_FOG ? INFINITY
                           : s->sky == EF_SKY_DISTANCE_MODE ? fmax(last, s->sky_distance) : last;
        double S[3], E[3];
        if (end > 0) {
            /* one quadrature along the whole ray per light (its dense
             * output), from which every fog sample's light is a
             * difference */
            if (fog->ndense < s->nlight) {
                ef_lit_dense *nd = realloc(fog->dense, (size_t) s->nlight * sizeof *nd);
                if (!nd)
                    return -1;
                memset(nd + fog->ndense, 0, (size_t) (s->nlight - fog->ndense) * sizeof *nd);
                fog->dense = nd;
                fog->ndense = s->nlight;
            }
            const ef_ray whole = seg_ray(&r1, 0, end);
            for (int j = 0; j < s->nlight; ++j) {
                const int rc =
                    ef_lit_dense_build(s, &s->light[j], &whole, lt.rel, &fog->dense[j]);
                if (rc < 0)
                    return -1;
                if (rc == 0)
                    lt.dmask |= 1u << j;
                /* a lamp's multiple scattering's estimate in fog that is
                 * not uniform, over the whole visible ray (lit.h) */
                for (int k = 0; rc == 0 && st && k < 3; ++k)
                    st->pix_light_err[k] += fog->dense[j].aux[k];
            }
            lt.dense = fog->dense;
            lt.dend = end;
            double T0[3] = { 1, 1, 1 };
            seg_light(s, &lt, &r1, 0, end, S, E, NULL, T0);
            lt.scale = max3(S);
        }
    }
    double Tf = 1, prev = 0;
    int rc = 0;
    for (int j = 0; j < nb && !rc; ++j) {
        const double b = B[j] < cut ? B[j] : cut;
        if (b > prev)
            rc = fog_interval(L, F, &lt, &r1, prev, b, &Tf, fog, st);
        if (b > prev)
            prev = b;
        if (B[j] >= cut)
            break;
    }
    if (!rc && isinf(cut)) {
        if (s->sky == EF_SKY_FOG)
            rc = fog_tail(L, F, &lt, &r1, prev, &Tf, fog, st);
        else if (s->sky == EF_SKY_DISTANCE_MODE && s->sky_distance > prev)
            rc = fog_interval(L, F, &lt, &r1, prev, s->sky_distance, &Tf, fog, st);
    }
    if (st) {
        st->fog_samples += fog->n;
        st->pixels += 1;
    }
    return rc;
}

/* "Over" of one sample onto the running flat values. */
static void over(const ef_deep_layout *L, const double *s, double *out, int first)
{
    for (int c = 0; c < L->nch; ++c) {
        if (L->role[c] == EF_DEEP_COLOR) {
            const int ai = L->alpha[c];
            out[c] += (ai >= 0 ? 1 - out[ai] : 1) * s[c];
        } else if (L->role[c] == EF_DEEP_COPY && first) {
            out[c] = s[c];
        }
    }
    for (int c = 0; c < L->nch; ++c)
        if (L->role[c] == EF_DEEP_ALPHA)
            out[c] += (1 - out[c]) * s[c];
}

int ef_deep_flatten_pair(const ef_deep_layout *L, const ef_deep_buf *a, const ef_deep_buf *b,
                         double *out)
{
    const int nch = L->nch, S = a->stride;
    double zf = INFINITY, zb = -INFINITY, m[EF_DEEP_STRIDE(EF_DEEP_MAX_CH)];
    for (int c = 0; c < nch; ++c)
        out[c] = 0;
    int i = 0, j = 0, first = 1, in_a = 0;
    while (i < a->n || j < b->n) {
        const double *p = i < a->n ? a->v + (size_t) i * (size_t) S : NULL;
        const double *q = j < b->n ? b->v + (size_t) j * (size_t) S : NULL;
        const double *s;
        int from_a = 1;
        if (p && q && p[nch] == q[nch] && p[nch + 1] == q[nch + 1]) {
            memcpy(m, p, (size_t) S * sizeof *m);
            merge_into(L, m, q);
            s = m;
            ++i, ++j;
        } else {
            const int take_p = p && (!q || p[nch] < q[nch] ||
                                     (p[nch] == q[nch] && p[nch + 1] < q[nch + 1]));
            s = take_p ? p : q;
            from_a = take_p;
            const double *o = take_p ? q : p;
            /* the other list's next sample must not start inside this one */
            if (o && s[nch + 1] > s[nch] && o[nch] < s[nch + 1])
                return 1;
            take_p ? ++i : ++j;
        }
        over(L, s, out, first);
        /* Z and ZBack from a's samples alone: b's (the fog's, which start
         * at the camera) are a medium, no surface a depth merge or a
         * defocus should see */
        if (from_a) {
            zf = fmin(zf, s[nch]);
            zb = fmax(zb, fmax(s[nch], s[nch + 1]));
            in_a = 1;
        }
        first = 0;
    }
    for (int c = 0; c < nch; ++c) {
        if (L->role[c] == EF_DEEP_Z)
            out[c] = zf;
        else if (L->role[c] == EF_DEEP_ZBACK)
            out[c] = in_a ? zb : INFINITY;
    }
    return 0;
}

void ef_deep_flatten(const ef_deep_layout *L, const ef_deep_buf *tidy, double *out)
{
    /* the union with nothing: no sample can start inside another list's */
    ef_deep_buf none;
    ef_deep_buf_init(&none, L->nch);
    ef_deep_flatten_pair(L, tidy, &none, out);
}
