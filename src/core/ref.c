#include "ref.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "exact.h"
#include "gk15.h"

#define MAXF 64          /* functionals per density */
#define MAX_DEPTH 48     /* bisection levels per piece */
#define REL_TOL 1e-14L   /* per-interval |K - G| / |K| */

typedef struct run {
    const ef_ref_density *d;
    int nf;
    long double s[MAXF];
    long double lambda;  /* the infinite tail's length scale, t = lambda u / (1 - u) */
    ef_ref_stats *st;
} run;

static void eval(run *R, const long double *v, long double out[3])
{
    R->d->density(R->d->ctx, v, out);
    R->st->evals++;
}

/* The functionals at offset u of an interval of width w, carried from the
 * nearer end so values next to a crossing keep their relative precision. */
static void values_at(const run *R, const long double *vL, const long double *vR, long double w,
                      long double u, long double *v)
{
    if (u <= w / 2)
        for (int i = 0; i < R->nf; ++i)
            v[i] = vL[i] + R->s[i] * u;
    else
        for (int i = 0; i < R->nf; ++i)
            v[i] = vR[i] - R->s[i] * (w - u);
}

/* Tail points: t = lambda u / (1 - u) past the tail's start vL. Returns dt/du. */
static long double tail_at(const run *R, const long double *vL, long double u, long double *v)
{
    const long double t = R->lambda * u / (1 - u);
    for (int i = 0; i < R->nf; ++i)
        v[i] = R->s[i] == 0 ? vL[i] : vL[i] + R->s[i] * t;
    return R->lambda / ((1 - u) * (1 - u));
}

/* One Gauss-Kronrod interval: [0, w] of a piece, or [u0, u0 + w] of the tail
 * (tail != 0). */
static void gk15(run *R, const long double *vL, const long double *vR, long double u0,
                 long double w, int tail, long double K[3], long double G[3])
{
    const long double h = w / 2;
    long double v[MAXF], f[3];
    long double jac = 1;
    for (int k = 0; k < 3; ++k)
        K[k] = G[k] = 0;
    /* j = 0..7 walks the left half up to the centre, 8..14 mirrors it. */
    for (int j = 0; j < 15; ++j) {
        const int idx = j < 8 ? j : 14 - j;
        const long double x = j < 8 ? -ef_gk15_x[idx] : ef_gk15_x[idx];
        const long double u = h + h * x;
        if (tail)
            jac = tail_at(R, vL, u0 + u, v);
        else
            values_at(R, vL, vR, w, u, v);
        eval(R, v, f);
        for (int k = 0; k < 3; ++k) {
            const long double g = f[k] * jac;
            K[k] += ef_gk15_wk[idx] * g;
            if (idx & 1)   /* the Gauss nodes: 1, 3, 5 and the centre 7 */
                G[k] += ef_gk15_wg[idx / 2] * g;
        }
    }
    for (int k = 0; k < 3; ++k) {
        K[k] *= h;
        G[k] *= h;
    }
}

/* arr with room for element n of a growing array (doubling *cap), or NULL
 * when memory runs out (arr is then still valid). */
static void *grow(void *arr, size_t *cap, size_t n, size_t elem)
{
    if (n < *cap)
        return arr;
    const size_t ncap = *cap ? 2 * *cap : 64;
    void *na = realloc(arr, ncap * elem);
    if (na)
        *cap = ncap;
    return na;
}

/* Global adaptive quadrature (QUADPACK's qag strategy): every interval keeps
 * its Kronrod sum and error estimate |K - G|; the worst one is bisected until
 * the summed error is below REL_TOL of the total. A local test would never
 * settle next to a zero of the density (x^n near 0 looks the same at every
 * scale); the global one does. */
typedef struct ival {
    long double u0, w, K[3], G[3], err;
    size_t iL, iR;       /* the end values in the value store */
    int tail;
} ival;

typedef struct quad {
    run *R;
    ival *heap;          /* max-heap by err */
    size_t n, cap;
    size_t max_n;        /* refinement stops at this many intervals */
    long double *vals;   /* nf values per stored point */
    size_t nvals, capvals;
    long double scale[3];
    long double dinf[3]; /* density at infinity; > 0: that channel diverges */
} quad;

static long double *vals_at(quad *q, size_t i)
{
    return q->vals + i * (size_t) q->R->nf;
}

static long ival_store(quad *q, const long double *v)
{
    const size_t per = (size_t) (q->R->nf ? q->R->nf : 1) * sizeof *q->vals;
    long double *nv = grow(q->vals, &q->capvals, q->nvals, per);
    if (!nv)
        return -1;
    q->vals = nv;
    if (q->R->nf)
        memcpy(vals_at(q, q->nvals), v, (size_t) q->R->nf * sizeof *v);
    return (long) q->nvals++;
}

static long double ival_err(const quad *q, const ival *iv)
{
    long double e = 0;
    for (int k = 0; k < 3; ++k)
        if (isfinite(iv->K[k]) && q->scale[k] > 0) {
            const long double d = fabsl(iv->K[k] - iv->G[k]) / q->scale[k];
            if (!(d <= e))
                e = d;
        }
    return isnan(e) ? INFINITY : e;
}

static void sift_up(ival *h, size_t i)
{
    while (i > 0) {
        const size_t p = (i - 1) / 2;
        if (!(h[p].err < h[i].err))
            break;
        const ival t = h[p];
        h[p] = h[i];
        h[i] = t;
        i = p;
    }
}

static void sift_down(ival *h, size_t n, size_t i)
{
    for (;;) {
        size_t m = i;
        const size_t l = 2 * i + 1, r = l + 1;
        if (l < n && h[l].err > h[m].err)
            m = l;
        if (r < n && h[r].err > h[m].err)
            m = r;
        if (m == i)
            return;
        const ival t = h[m];
        h[m] = h[i];
        h[i] = t;
        i = m;
    }
}

static int ival_push(quad *q, ival iv)
{
    ival *h = grow(q->heap, &q->cap, q->n, sizeof *h);
    if (!h)
        return -1;
    q->heap = h;
    q->heap[q->n] = iv;
    sift_up(q->heap, q->n++);
    return 0;
}

/* Evaluates an interval (its err is set later, once the scale is known). */
static void ival_eval(quad *q, ival *iv)
{
    gk15(q->R, vals_at(q, iv->iL), vals_at(q, iv->iR), iv->u0, iv->w, iv->tail, iv->K, iv->G);
    q->R->st->intervals++;
}

/* Intervals refinement may add beyond 4 per piece. */
#define MAX_INTERVALS 20000

/* Sets the error scale to the current total of each channel and rebuilds
 * the heap; returns the summed relative error. The first estimate of a
 * total can be off by many orders (a steep exponential seen by 15 nodes), so
 * the scale follows the total as it changes. */
static long double rescale(quad *q, long double Ksum[3])
{
    for (int k = 0; k < 3; ++k) {
        Ksum[k] = 0;
        for (size_t i = 0; i < q->n; ++i)
            Ksum[k] += q->heap[i].K[k];
        q->scale[k] = q->dinf[k] > 0 || !isfinite(Ksum[k]) ? 0 : fabsl(Ksum[k]);
    }
    long double total_err = 0;
    for (size_t i = 0; i < q->n; ++i) {
        q->heap[i].err = ival_err(q, &q->heap[i]);
        total_err += q->heap[i].err;
    }
    for (size_t i = q->n / 2 + 1; i-- > 0;)
        sift_down(q->heap, q->n, i);
    return total_err;
}

static int drifted(const quad *q, const long double Ksum[3])
{
    for (int k = 0; k < 3; ++k)
        if (q->scale[k] > 0 && !(Ksum[k] <= 2 * q->scale[k] && Ksum[k] >= q->scale[k] / 2))
            return 1;
    return 0;
}

static int refine(quad *q, long double tau[3])
{
    long double Ksum[3];
    long double total_err = rescale(q, Ksum);
    /* A full rescale costs O(n): space them so that millions of lattice
     * pieces stay linear. */
    long iter = 0, next_rescale = 256;
    while (q->n && total_err > REL_TOL && q->n < q->max_n) {
        ival top = q->heap[0];
        q->heap[0] = q->heap[--q->n];
        sift_down(q->heap, q->n, 0);
        const long double h = top.w / 2;
        ival a = top, b = top;
        a.w = h;
        b.u0 = top.u0 + h;
        b.w = top.w - h;
        if (!(h > 0) || b.u0 == top.u0 || (top.tail && !(b.u0 < 1))) {
            /* Cannot split further: keep it as it is. */
            q->R->st->unconverged++;
            total_err -= top.err;
            top.err = 0;
            if (ival_push(q, top))
                return -1;
            continue;
        }
        if (!top.tail) {
            long double vM[MAXF];
            const long double *vL = vals_at(q, top.iL), *vR = vals_at(q, top.iR);
            for (int i = 0; i < q->R->nf; ++i)
                vM[i] = fabsl(vL[i]) <= fabsl(vR[i]) ? vL[i] + q->R->s[i] * h
                                                     : vR[i] - q->R->s[i] * (top.w - h);
            const long m = ival_store(q, vM);
            if (m < 0)
                return -1;
            a.iR = b.iL = (size_t) m;
            a.u0 = b.u0 = 0;
        }
        ival_eval(q, &a);
        ival_eval(q, &b);
        a.err = ival_err(q, &a);
        b.err = ival_err(q, &b);
        total_err += a.err + b.err - top.err;
        for (int k = 0; k < 3; ++k)
            Ksum[k] += a.K[k] + b.K[k] - top.K[k];
        if (ival_push(q, a) || ival_push(q, b))
            return -1;
        /* Running sums drift, and the totals move: recompute now and then. */
        if (drifted(q, Ksum) || ++iter >= next_rescale || !(total_err >= 0)) {
            total_err = rescale(q, Ksum);
            next_rescale = iter + (long) (q->n / 8 > 256 ? q->n / 8 : 256);
        }
    }
    if (total_err > REL_TOL)
        q->R->st->unconverged++;
    for (size_t i = 0; i < q->n; ++i)
        for (int k = 0; k < 3; ++k)
            tau[k] += q->heap[i].K[k];
    return 0;
}

/* Samples per finite piece in the search for kinks (ef_ref_density.kink). */
#define KINK_SAMPLES 12

/* The functional values at fraction u of the way from vL to vR (the
 * functionals are linear along the ray). */
static void values_between(int nf, const long double *vL, const long double *vR, long double u,
                           long double *v)
{
    for (int i = 0; i < nf; ++i)
        v[i] = vL[i] + u * (vR[i] - vL[i]);
}

/* The fractions of the piece from vL to vR where d's kink function
 * changes sign, in increasing order (at most cap); 0 when there is none. */
static int piece_kinks(const ef_ref_density *d, int nf, const long double *vL,
                       const long double *vR, long double *at, int cap)
{
    long double v[MAXF], g0, g1;
    if (!d->kink(d->ctx, vL, &g0))
        return 0;
    int n = 0;
    long double u0 = 0;
    for (int k = 1; k <= KINK_SAMPLES && n < cap; ++k) {
        const long double u1 = (long double) k / KINK_SAMPLES;
        values_between(nf, vL, vR, u1, v);
        if (!d->kink(d->ctx, v, &g1))
            return 0;
        if ((g0 < 0) != (g1 < 0)) {
            long double a = u0, b = u1, ga = g0;
            for (int it = 0; it < 80 && b - a > 0; ++it) {
                const long double m = (a + b) / 2;
                if (!(m > a && m < b))
                    break;
                long double gm;
                values_between(nf, vL, vR, m, v);
                d->kink(d->ctx, v, &gm);
                if ((gm < 0) == (ga < 0)) {
                    a = m;
                    ga = gm;
                } else {
                    b = m;
                }
            }
            if (a > 0 && a < 1)
                at[n++] = a;
        }
        u0 = u1;
        g0 = g1;
    }
    return n;
}

/* Queues piece [0, w] between stored points iL and iR (or the tail). */
static int add_piece(quad *q, size_t iL, size_t iR, long double w, int tail)
{
    ival iv = { .u0 = 0, .w = w, .iL = iL, .iR = iR, .tail = tail };
    ival_eval(q, &iv);
    q->R->st->pieces++;
    return ival_push(q, iv);  /* err 0 until refine() sets the scale and rebuilds the heap */
}

/* Double-double helpers for the split geometry: offsets of crossings far
 * along a segment (1e7 away, a sliver 1e-6 wide) must keep their relative
 * difference, which long double alone cannot. */
static ef_dd dd_neg(ef_dd a)
{
    return (ef_dd) { -a.hi, -a.lo };
}

static ef_dd dd_mul(ef_dd a, ef_dd b)
{
    ef_dd p = ef_two_prod(a.hi, b.hi);
    p.lo += a.hi * b.lo + a.lo * b.hi;
    return ef_two_sum(p.hi, p.lo);
}

static ef_dd dd_div(ef_dd a, ef_dd b)
{
    const double q1 = a.hi / b.hi;
    ef_dd r = ef_dd_add(a, dd_neg(dd_mul(b, (ef_dd) { q1, 0 })));
    const double q2 = r.hi / b.hi;
    r = ef_dd_add(r, dd_neg(dd_mul(b, (ef_dd) { q2, 0 })));
    const double q3 = r.hi / b.hi;
    return ef_dd_add(ef_two_sum(q1, q2), (ef_dd) { q3, 0 });
}

static long double ld(ef_dd a)
{
    return (long double) a.hi + a.lo;
}

/* A split point: its offset a from the start, and the functional f that has
 * the exact value val there (f < 0: none). */
typedef struct split {
    ef_dd a, val;
    int f;
} split;

static int by_offset(const void *x, const void *y)
{
    const ef_dd a = ((const split *) x)->a, b = ((const split *) y)->a;
    if (a.hi != b.hi)
        return a.hi < b.hi ? -1 : 1;
    return a.lo < b.lo ? -1 : a.lo > b.lo;
}

typedef struct splits {
    split *v;
    size_t n, cap;
} splits;

static int push(splits *S, split p)
{
    split *v = grow(S->v, &S->cap, S->n, sizeof *v);
    if (!v)
        return -1;
    S->v = v;
    S->v[S->n++] = p;
    return 0;
}

/* A functional along the segment in double-double: value at the start, rate. */
typedef struct dline {
    ef_dd h0, s;
} dline;

/* Adds the crossing of functional f with value val if it lies strictly
 * inside [0, len]. */
static int add_crossing(splits *S, const dline *l, int f, ef_dd val, long double len)
{
    if (l->s.hi == 0)
        return 0;
    const ef_dd a = dd_div(ef_dd_add(val, dd_neg(l->h0)), l->s);
    const long double al = ld(a);
    if (!(al > 0 && al < len))
        return 0;
    return push(S, (split) { a, val, f });
}

/* True when val lies strictly between the functional's values at the ends. */
static int within(const ef_line_ld *l, long double val)
{
    return l->s > 0 ? val > l->h0 && val < l->h1 : val < l->h0 && val > l->h1;
}

/* Adds the crossings of lattice lt strictly inside [0, amax] of the
 * segment (to_end: amax is the segment's end); *budget counts down the
 * splits still allowed. Returns 0, or -1 (memory, budget exhausted, or a
 * lattice whose crossings cannot be placed). */
static int add_lattice(splits *S, const dline *D, const ef_line_ld *L, const ef_fog_lattice *lt,
                       long double amax, int to_end, long *budget)
{
    if (!(isfinite(lt->period) && lt->period > 0 && isfinite(lt->phase)))
        return -1;
    const dline *l = &D[lt->f];
    if (l->s.hi == 0)
        return 0;
    /* The functional's range over [0, amax]: its exact end values on a
     * finite segment, else its value at amax (the margin below absorbs the
     * rounding; add_crossing places each crossing exactly). */
    const long double h0 = L[lt->f].h0;
    const long double h1 =
        to_end ? L[lt->f].h1
               : ld(ef_dd_add(l->h0, dd_mul(l->s, (ef_dd) { (double) amax,
                                                           (double) (amax - (double) amax) })));
    const long double lo = fminl(h0, h1), hi = fmaxl(h0, h1);
    const long double klo = floorl((lo - lt->phase) / lt->period);
    const long double khi = ceill((hi - lt->phase) / lt->period);
    if (!(fabsl(klo) < 0x1p53L && fabsl(khi) < 0x1p53L))
        return -1;
    /* Integers strictly between klo and khi: the crossings inside. */
    const long double count = khi - klo - 1;
    if (count > (long double) *budget)
        return -1;
    *budget -= count > 0 ? (long) count : 0;
    for (long double k = klo; k <= khi; k += 1) {
        /* phase + k period in double-double: k (< 2^53) and the product
         * are exact. */
        const ef_dd val = ef_dd_add((ef_dd) { lt->phase, 0 }, ef_two_prod((double) k, lt->period));
        if (add_crossing(S, l, lt->f, val, amax))
            return -1;
    }
    return 0;
}

static void point_values(const run *R, const dline *D, const split *p, long double *v)
{
    for (int i = 0; i < R->nf; ++i)
        v[i] = i == p->f ? ld(p->val) : ld(ef_dd_add(D[i].h0, dd_mul(D[i].s, p->a)));
}

int ef_ref_integrate(const ef_ref_density *d, const double org[3], const double dir[3],
                     double len, long double tau[3], ef_ref_stats *st)
{
    ef_ref_stats dummy;
    run R = { .d = d, .nf = d->nf, .st = st ? st : &dummy };
    memset(R.st, 0, sizeof *R.st);
    tau[0] = tau[1] = tau[2] = 0;
    if (d->nf > MAXF || d->nf < 0)
        return -1;
    if (!(len > 0))
        return 0;
    if (!d->density)
        return -1;
    ef_line_ld L[MAXF];
    dline D[MAXF];
    for (int i = 0; i < d->nf; ++i) {
        ef_line_of_ld(&d->f[i], org, dir, len, &L[i]);
        D[i].h0 = ef_dd_dot3(d->f[i].n, org, d->f[i].d);
        D[i].s = ef_dd_dot3(d->f[i].n, dir, 0.0);
        R.s[i] = L[i].s;
    }

    splits S = { NULL, 0, 0 };
    quad q = { .R = &R };
    R.lambda = 0;
    if (isinf(len)) {
        /* Channels whose density stays positive at infinity diverge; when all
         * do, nothing is left to integrate. */
        long double vinf[MAXF];
        for (int i = 0; i < R.nf; ++i)
            vinf[i] = R.s[i] > 0 ? INFINITY : R.s[i] < 0 ? -INFINITY : L[i].h0;
        eval(&R, vinf, q.dinf);
        if (q.dinf[0] > 0 && q.dinf[1] > 0 && q.dinf[2] > 0) {
            tau[0] = tau[1] = tau[2] = INFINITY;
            return 0;
        }
    }
    for (int j = 0; j < d->nfeat; ++j) {
        const ef_fog_feature *ft = &d->feat[j];
        if (ft->f < 0 || ft->f >= d->nf)
            continue;
        const ef_line_ld *l = &L[ft->f];
        if (add_crossing(&S, &D[ft->f], ft->f, (ef_dd) { ft->value, 0 }, len))
            goto oom;
        if (!(ft->scale > 0) || l->s == 0)
            continue;
        const long double tail_scale = ft->scale / fabsl(l->s);
        if (R.lambda == 0 || tail_scale < R.lambda)
            R.lambda = tail_scale;
        /* Geometric steps away from the feature on both sides: every piece is
         * then no wider than its distance to the feature, whatever the ratio
         * of the feature's scale to the segment's length. */
        /* On an infinite segment the steps stop 64 scales past the start
         * (an exponential feature is down to e^-64 there; lattice splits stop
         * with them); the tail's own substitution (scale lambda) takes over. */
        const long double reach = isinf(len) ? 64 * fmaxl(fabsl(l->h0 - ft->value), ft->scale)
                                             : INFINITY;
        for (int side = -1; side <= 1; side += 2)
            for (int e = 0; e < 4000; ++e) {
                const double step = side * ldexp(ft->scale, e);
                if (!isfinite(step) || fabs(step) > reach)
                    break;
                const ef_dd val = ef_two_sum(ft->value, step);
                if (within(l, ld(val))) {
                    if (add_crossing(&S, &D[ft->f], ft->f, val, len))
                        goto oom;
                } else if (side > 0 ? ld(val) > fmaxl(l->h0, l->h1)
                                    : ld(val) < fminl(l->h0, l->h1)) {
                    break;
                }
            }
    }
    if (R.lambda == 0)
        R.lambda = 1;
    if (d->nlat > 0 && d->lat) {
        /* Lattice seams over the whole of a finite segment; on an infinite
         * one, up to where the tail starts (the farthest split so far). */
        long double amax = len;
        if (isinf(len)) {
            amax = 0;
            for (size_t k = 0; k < S.n; ++k)
                if (ld(S.v[k].a) > amax)
                    amax = ld(S.v[k].a);
        }
        long budget = EF_REF_MAX_LATTICE_SPLITS;
        if (amax > 0)
            for (int j = 0; j < d->nlat; ++j)
                if (d->lat[j].f >= 0 && d->lat[j].f < d->nf &&
                    add_lattice(&S, D, L, &d->lat[j], amax, !isinf(len), &budget))
                    goto oom;
    }
    if (S.n)
        qsort(S.v, S.n, sizeof *S.v, by_offset);

    long double vL[MAXF], vR[MAXF];
    split prev = { { 0, 0 }, { 0, 0 }, -1 };
    for (int i = 0; i < R.nf; ++i)
        vL[i] = L[i].h0;
    long iL = ival_store(&q, vL);
    if (iL < 0)
        goto oom;
    for (size_t k = 0; k <= S.n; ++k) {
        split next;
        if (k < S.n) {
            next = S.v[k];
            point_values(&R, D, &next, vR);
        } else if (isinf(len)) {
            break;
        } else {
            next = (split) { { len, 0 }, { 0, 0 }, -1 };
            for (int i = 0; i < R.nf; ++i)
                vR[i] = L[i].h1;
        }
        const long double w = ld(ef_dd_add(next.a, dd_neg(prev.a)));
        if (!(w > 0))
            continue;
        if (d->kink) {
            /* split at the kinks inside the piece: each sub-piece from the
             * last stored point */
            long double at[KINK_SAMPLES], vk[MAXF], vprev[MAXF];
            memcpy(vprev, vals_at(&q, (size_t) iL), (size_t) R.nf * sizeof *vprev);
            const int nk = piece_kinks(d, R.nf, vprev, vR, at, KINK_SAMPLES);
            long double u_prev = 0;
            for (int k = 0; k < nk; ++k) {
                values_between(R.nf, vprev, vR, at[k], vk);
                const long ik = ival_store(&q, vk);
                if (ik < 0 || add_piece(&q, (size_t) iL, (size_t) ik, w * (at[k] - u_prev), 0))
                    goto oom;
                iL = ik;
                u_prev = at[k];
            }
            const long iR = ival_store(&q, vR);
            if (iR < 0 || add_piece(&q, (size_t) iL, (size_t) iR, w * (1 - u_prev), 0))
                goto oom;
            prev = next;
            iL = iR;
            continue;
        }
        const long iR = ival_store(&q, vR);
        if (iR < 0 || add_piece(&q, (size_t) iL, (size_t) iR, w, 0))
            goto oom;
        prev = next;
        iL = iR;
    }
    if (isinf(len)) {
        /* Past the last split the density is smooth; a channel that diverges
         * (q.dinf) is left out of the error control. */
        if (add_piece(&q, (size_t) iL, (size_t) iL, 1, 1))
            goto oom;
    }
    q.max_n = MAX_INTERVALS + 4 * (size_t) R.st->pieces;
    if (refine(&q, tau))
        goto oom;
    for (int k = 0; k < 3; ++k)
        if (q.dinf[k] > 0)
            tau[k] = INFINITY;
    free(q.heap);
    free(q.vals);
    free(S.v);
    return 0;
oom:
    free(q.heap);
    free(q.vals);
    free(S.v);
    return -1;
}

typedef struct comp_ctx {
    const ef_fog_component *c;
} comp_ctx;

static int comp_kink(const void *ctx, const long double *v, long double *g)
{
    const ef_fog_component *c = ((const comp_ctx *) ctx)->c;
    return c->model->kink(c, v, g);
}

static void comp_density(const void *ctx, const long double *v, long double out[3])
{
    const ef_fog_component *c = ((const comp_ctx *) ctx)->c;
    c->model->density(c, v, out);
}

/* ef_ref_tau's density description of c: feat and lat are allocated
 * (the caller frees both). Returns -1 for models without a density or
 * when memory runs out. */
static int comp_describe(const ef_fog_component *c, ef_fog_functional f[MAXF], comp_ctx *cc,
                         ef_ref_density *d)
{
    const ef_fog_model *m = c->model;
    if (!m->density || !m->functionals || !m->features)
        return -1;
    const int nf = m->functionals(c, f, MAXF);
    const int nfeat = m->features(c, NULL, 0);
    if (nf > MAXF || nf < 0 || nfeat < 0)
        return -1;
    ef_fog_feature *feat = malloc(((size_t) nfeat + 1) * sizeof *feat);
    if (!feat)
        return -1;
    m->features(c, feat, nfeat);
    cc->c = c;
    int nlat = m->lattices ? m->lattices(c, NULL, 0) : 0;
    if (nlat < 0) {
        free(feat);
        return -1;
    }
    ef_fog_lattice *lat = malloc(((size_t) nlat + 1) * sizeof *lat);
    if (!lat) {
        free(feat);
        return -1;
    }
    if (nlat)
        m->lattices(c, lat, nlat);
    *d = (ef_ref_density) { .nf = nf, .f = f, .nfeat = nfeat, .feat = feat,
                            .density = comp_density, .ctx = cc, .nlat = nlat, .lat = lat,
                            .kink = m->kink ? comp_kink : NULL };
    return 0;
}

int ef_ref_tau(const ef_fog_component *c, const ef_ray *r, long double tau[3], ef_ref_stats *st)
{
    ef_fog_functional f[MAXF];
    comp_ctx cc;
    ef_ref_density d;
    if (comp_describe(c, f, &cc, &d) < 0)
        return -1;
    const int rc = ef_ref_integrate(&d, r->org, r->dir, r->dist, tau, st);
    free((void *) d.lat);
    free((void *) d.feat);
    return rc;
}

int ef_ref_tau_long(const ef_fog_component *c, const ef_ray *r, double len, double chunk,
                    double stop, long double tau[3], double *reached, ef_ref_stats *st)
{
    tau[0] = tau[1] = tau[2] = 0;
    if (reached)
        *reached = 0;
    if (!(len >= 0) || !(chunk > 0) || isinf(len))
        return -1;
    ef_fog_functional f[MAXF];
    comp_ctx cc;
    ef_ref_density d;
    if (comp_describe(c, f, &cc, &d) < 0)
        return -1;
    int rc = 0;
    const long double steps = ceill(len / chunk);
    for (long double j = 0; j < steps; ++j) {
        const long double ta = j * chunk, tb = j + 1 >= steps ? len : (j + 1) * chunk;
        double org[3];
        for (int a = 0; a < 3; ++a)
            org[a] = (double) (r->org[a] + ta * (long double) r->dir[a]);
        long double part[3];
        rc = ef_ref_integrate(&d, org, r->dir, (double) (tb - ta), part, st);
        if (rc < 0)
            break;
        int done = 1, any = 0;
        for (int k = 0; k < 3; ++k) {
            tau[k] += part[k];
            if (tau[k] > 0)
                any = 1;
            if (tau[k] > 0 && tau[k] < stop)
                done = 0;
        }
        if (reached)
            *reached = (double) tb;
        if (any && done)
            break;
    }
    free((void *) d.lat);
    free((void *) d.feat);
    return rc;
}

/* ---- lit fog: the in-scattered light, integrated on its own ---- */

/* tau along org + t dir over [0, len] summed over the components: uniform
 * exp by hand (rho len), the rest by ef_ref_tau. */
static int lit_tau(const ef_fog_scene *s, const double org[3], const double dir[3], double len,
                   long double tau[3])
{
    tau[0] = tau[1] = tau[2] = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        long double t[3];
        if (c->model == &ef_fog_exp) {
            for (int k = 0; k < 3; ++k)
                t[k] = c->p[k] == 0 ? 0 : (long double) c->p[k] * len;
        } else {
            const ef_ray r = { { dir[0], dir[1], dir[2] }, len, len, { org[0], org[1], org[2] } };
            if (ef_ref_tau(c, &r, t, NULL) < 0)
                return -1;
        }
        for (int k = 0; k < 3; ++k)
            tau[k] += t[k];
    }
    return 0;
}

/* The sun's optical depth from x over a planet (lit.h's planet=), from its
 * definition: the height fog's density at the heights h(s) = |x' + s l| - R
 * of the straight ray, x' = x placed at radius R + y over the centre below
 * it (y its height), integrated by adaptive Gauss-Kronrod in long double
 * over s, in pieces from the tangent point (where the ray dips) doubling
 * until what is left is below 1e-20 of the sum. +inf where the ray meets
 * the planet. */
typedef struct planet_ray {
    long double r0, mu, R, k;
} planet_ray;

static long double planet_dens(const planet_ray *p, long double s)
{
    /* h = (s^2 + 2 r0 s mu + r0^2 - R^2) / (|x' + s l| + R), r0^2 - R^2
     * = y (2R + y): no difference of radii */
    const long double y = p->r0 - p->R;
    const long double q = s * s + 2 * p->r0 * s * p->mu + y * (2 * p->R + y);
    const long double h = q / (sqrtl(p->r0 * p->r0 + s * s + 2 * p->r0 * s * p->mu) + p->R);
    return expl(-p->k * (h - y));
}

static long double planet_gk(const planet_ray *p, long double a, long double b, long double *e)
{
    const long double c = (a + b) / 2, h = (b - a) / 2;
    long double K = ef_gk15_wk[7] * planet_dens(p, c), G = ef_gk15_wg[3] * planet_dens(p, c);
    for (int j = 0; j < 7; ++j) {
        const long double dx = h * ef_gk15_x[j];
        const long double f = planet_dens(p, c - dx) + planet_dens(p, c + dx);
        K += ef_gk15_wk[j] * f;
        if (j & 1)
            G += ef_gk15_wg[j / 2] * f;
    }
    *e = fabsl((K - G) * h);
    return K * h;
}

static long double planet_adapt(const planet_ray *p, long double a, long double b, long double tol,
                                int depth)
{
    long double e;
    const long double r = planet_gk(p, a, b, &e);
    if (e <= tol || e <= 1e-18L * fabsl(r) || depth >= 30)
        return r;
    const long double m = (a + b) / 2;
    return planet_adapt(p, a, m, tol, depth + 1) + planet_adapt(p, m, b, tol, depth + 1);
}

/* int_0^inf e^-(k (h(s) - y)) ds for the sun ray from x (the integral
 * relative to x's own density), or +inf where the ray meets the planet. */
static long double planet_path(const ef_fog_scene *sc, const ef_light *l, const double x[3])
{
    const ef_fog_component *c = &sc->comp[0];
    planet_ray p;
    const long double y = (long double) c->up[0] * x[0] + (long double) c->up[1] * x[1] +
                          (long double) c->up[2] * x[2];
    p.R = l->planet;
    p.r0 = p.R + y;
    p.k = c->p[3];
    p.mu = (long double) l->dir[0] * c->up[0] + (long double) l->dir[1] * c->up[1] +
           (long double) l->dir[2] * c->up[2];
    if (!(p.r0 > 0) || (p.mu < 0 && p.r0 * sqrtl(1 - p.mu * p.mu) < p.R))
        return INFINITY;
    /* pieces: to the tangent point (where the ray dips), then doubling from
     * a length on the fog's own scale */
    long double a = 0, len = 1 / (8 * p.k), total = 0;
    if (p.mu < 0) {
        const long double st = -p.r0 * p.mu;
        for (long double b = 0; b < st;) {
            const long double e = b + len < st ? b + len : st;
            total += planet_adapt(&p, b, e, 1e-20L * len, 0);
            b = e;
            len *= 2;
        }
        a = st;
        len = 1 / (8 * p.k);
    }
    for (int i = 0; i < 4000; ++i) {
        const long double v = planet_adapt(&p, a, a + len, 1e-20L * (total > len ? total : len), 0);
        total += v;
        a += len;
        len *= 2;
        if (v <= 1e-20L * total && planet_dens(&p, a) <= 1e-20L)
            break;
    }
    return total;
}

typedef struct lit_ref {
    const ef_fog_scene *s;
    const ef_light *l;
    const ef_ray *r;
    long double a, lambda;   /* the infinite tail: t = a + lambda u / (1 - u) */
    int fail;
} lit_ref;

/* The integrand of lit.h's S at t, straight from its definition: the
 * vector to a lamp as (lamp - camera) - t dir in long double (a world point
 * rounded to double would carry an ulp of the ray's length into d). */
static void lit_ref_at(lit_ref *q, long double t, long double out[3])
{
    const ef_ray *r = q->r;
    const ef_light *l = q->l;
    double x[3], ld[3], dl = INFINITY;
    long double E[3], cthl;
    out[0] = out[1] = out[2] = 0;
    for (int a = 0; a < 3; ++a)
        x[a] = (double) (r->org[a] + t * (long double) r->dir[a]);
    if (!ef_light_at_position(l)) {
        for (int a = 0; a < 3; ++a)
            ld[a] = l->dir[a];
        for (int k = 0; k < 3; ++k)
            E[k] = l->e[k];
        cthl = (long double) ld[0] * r->dir[0] + (long double) ld[1] * r->dir[1] +
               (long double) ld[2] * r->dir[2];
    } else {
        long double y[3], d2 = 0, yv = 0, ya = 0;
        for (int a = 0; a < 3; ++a) {
            y[a] = ((long double) l->pos[a] - r->org[a]) - t * r->dir[a];
            d2 += y[a] * y[a];
            yv += y[a] * r->dir[a];
            ya += y[a] * l->dir[a];
        }
        const long double d = sqrtl(d2);
        if (!(d > 0))
            return;
        dl = (double) d;
        for (int a = 0; a < 3; ++a)
            ld[a] = (double) (y[a] / d);
        cthl = yv / d;
        long double f = 1 / (d2 + (long double) l->radius * l->radius);
        if (ef_light_coned(l))
            f *= ef_spot_share(l, (double) (-ya / d));
        for (int k = 0; k < 3; ++k)
            E[k] = l->e[k] * f;
    }
    if (E[0] == 0 && E[1] == 0 && E[2] == 0)
        return;
    const double cth = (double) cthl;
    long double sc[3] = { 0, 0, 0 };
    for (int i = 0; i < q->s->ncomp; ++i) {
        const ef_fog_component *c = &q->s->comp[i];
        long double sg[3];
        if (c->model == &ef_fog_exp) {
            for (int k = 0; k < 3; ++k)
                sg[k] = c->p[k];
        } else {
            ef_fog_functional f[MAXF];
            long double v[MAXF];
            const int nf = c->model->functionals(c, f, MAXF);
            for (int j = 0; j < nf && j < MAXF; ++j)
                v[j] = (long double) f[j].n[0] * x[0] + (long double) f[j].n[1] * x[1] +
                       (long double) f[j].n[2] * x[2] + f[j].d;
            c->model->density(c, v, sg);
        }
        const long double p = ef_phase_eval(c->phase, c->g, cth);
        for (int k = 0; k < 3; ++k)
            if (sg[k] != 0)
                sc[k] += sg[k] * (c->has_albedo ? c->albedo[k] : 1.0L) * p;
    }
    if (sc[0] == 0 && sc[1] == 0 && sc[2] == 0)
        return;
    long double tv[3], tl[3];
    if (lit_tau(q->s, r->org, r->dir, (double) t, tv) < 0 ||
        (!(!ef_light_at_position(l) && l->planet > 0) && lit_tau(q->s, x, ld, dl, tl) < 0)) {
        q->fail = 1;
        return;
    }
    if (!ef_light_at_position(l) && l->planet > 0) {
        /* sigma(x) times the path integral: the density's own form */
        const long double path = planet_path(q->s, l, x);
        const ef_fog_component *c = &q->s->comp[0];
        const long double y = (long double) c->up[0] * x[0] + (long double) c->up[1] * x[1] +
                              (long double) c->up[2] * x[2];
        for (int k = 0; k < 3; ++k)
            tl[k] = c->p[k] == 0 ? 0
                                 : c->p[k] * expl(-(long double) c->p[3] * (y - c->p[4])) * path;
    }
    /* where either leg is opaque the density may have overflowed too:
     * no light, not inf * 0 */
    for (int k = 0; k < 3; ++k) {
        const long double e = expl(-(tv[k] + tl[k]));
        out[k] = sc[k] == 0 || e == 0 ? 0 : sc[k] * E[k] * e;
    }
}

typedef struct lit_iv {
    long double a, b, K[3], err;
} lit_iv;

/* One Kronrod rule over [a, b] in t, or in u on the infinite tail. */
static void lit_gk(lit_ref *q, int tail, lit_iv *iv)
{
    const long double c = (iv->a + iv->b) / 2, h = (iv->b - iv->a) / 2;
    long double K[3] = { 0, 0, 0 }, G[3] = { 0, 0, 0 };
    for (int j = 0; j < 15; ++j) {
        const int idx = j < 8 ? j : 14 - j;
        const long double x = c + h * (j < 8 ? -ef_gk15_x[idx] : ef_gk15_x[idx]);
        long double f[3], w = 1, t = x;
        if (tail) {
            t = q->a + q->lambda * x / (1 - x);
            w = q->lambda / ((1 - x) * (1 - x));
        }
        lit_ref_at(q, t, f);
        for (int k = 0; k < 3; ++k) {
            K[k] += ef_gk15_wk[idx] * f[k] * w;
            if (idx & 1)
                G[k] += ef_gk15_wg[idx / 2] * f[k] * w;
        }
    }
    iv->err = 0;
    for (int k = 0; k < 3; ++k) {
        iv->K[k] = K[k] * h;
        iv->err = fmaxl(iv->err, fabsl((K[k] - G[k]) * h));
    }
}

#define LIT_MAX_IV 4096

/* Global adaptive over the pieces [cut[i], cut[i+1]] (tail: one piece
 * u in [0, 1)) to 1e-14 of the result: the nested optical depths carry
 * ~1e-15 of rounding, which a tighter target would chase. */
static void lit_adapt(lit_ref *q, const long double *cut, int ncut, int tail, long double S[3])
{
    lit_iv *iv = malloc(LIT_MAX_IV * sizeof *iv);
    if (!iv) {
        q->fail = 1;
        return;
    }
    int n = 0;
    for (int i = 0; i + 1 < ncut; ++i)
        if (cut[i + 1] > cut[i]) {
            iv[n] = (lit_iv) { cut[i], cut[i + 1], { 0, 0, 0 }, 0 };
            lit_gk(q, tail, &iv[n++]);
        }
    for (;;) {
        long double R[3] = { 0, 0, 0 }, E = 0;
        int worst = -1;
        for (int i = 0; i < n; ++i) {
            for (int k = 0; k < 3; ++k)
                R[k] += iv[i].K[k];
            E += iv[i].err;
            if (iv[i].b - iv[i].a > 1e-17L * fmaxl(fabsl(iv[i].a), fabsl(iv[i].b)) &&
                (worst < 0 || iv[i].err > iv[worst].err))
                worst = i;
        }
        const long double big = fmaxl(fabsl(R[0]), fmaxl(fabsl(R[1]), fabsl(R[2])));
        if (E <= 1e-14L * big || worst < 0 || n + 1 >= LIT_MAX_IV || q->fail) {
            for (int k = 0; k < 3; ++k)
                S[k] += R[k];
            free(iv);
            return;
        }
        const long double a = iv[worst].a, b = iv[worst].b, m = (a + b) / 2;
        iv[worst].b = m;
        lit_gk(q, tail, &iv[worst]);
        iv[n] = (lit_iv) { m, b, { 0, 0, 0 }, 0 };
        lit_gk(q, tail, &iv[n++]);
    }
}

static int cmp_ld(const void *x, const void *y)
{
    const long double a = *(const long double *) x, b = *(const long double *) y;
    return (a > b) - (a < b);
}

/* cos alpha - c at t: the angle from a spot's aim, in long double. */
static long double spot_cos(const ef_light *l, const ef_ray *r, long double t, long double c)
{
    long double y[3], d2 = 0, ya = 0;
    for (int a = 0; a < 3; ++a) {
        y[a] = ((long double) r->org[a] - l->pos[a]) + t * r->dir[a];
        d2 += y[a] * y[a];
        ya += y[a] * l->dir[a];
    }
    return d2 > 0 ? ya / sqrtl(d2) - c : -1;
}

/* Where the ray crosses a spot's cone edge and its blend band's inner
 * edge, found on their own: a scan of cos alpha over t = L s / (1 - s)
 * (the whole ray) for sign changes, each bisected to long double; the
 * share's second derivative jumps there, which the Kronrod-Gauss
 * difference can miss. Appends to cut (at most cap). */
static int spot_cuts(const ef_light *l, const ef_ray *r, long double *cut, int n, int cap)
{
    long double ww = 0;
    for (int a = 0; a < 3; ++a)
        ww += ((long double) l->pos[a] - r->org[a]) * ((long double) l->pos[a] - r->org[a]);
    const long double L = fmaxl(sqrtl(ww), 1), D = r->dist;
    const long double lv[2] = { l->cos_outer, l->cos_outer + l->smooth };
    enum { NS = 20000 };
    for (int e = 0; e < 2 && (e == 0 || l->smooth > 0); ++e) {
        long double ta = 0, fa = spot_cos(l, r, 0, lv[e]);
        for (int i = 1; i <= NS && n < cap - 1; ++i) {
            const long double sv = (long double) i / (NS + 1), tb = L * sv / (1 - sv);
            const long double fb = spot_cos(l, r, tb, lv[e]);
            if ((fa < 0) != (fb < 0)) {
                long double lo = ta, hi = tb, flo = fa;
                for (int it = 0; it < 200 && hi - lo > 1e-19L * hi; ++it) {
                    const long double m = (lo + hi) / 2, fm = spot_cos(l, r, m, lv[e]);
                    if ((fm < 0) == (flo < 0))
                        lo = m, flo = fm;
                    else
                        hi = m;
                }
                const long double t = (lo + hi) / 2;
                if (t > 0 && t < D)
                    cut[n++] = t;
            }
            if (tb >= D)
                break;
            ta = tb;
            fa = fb;
        }
    }
    return n;
}

/* Functional F along r in long double: its value at the origin and its
 * rate per unit t. */
static void line_of(const ef_fog_functional *F, const ef_ray *r, long double *v0,
                    long double *rate)
{
    *v0 = (long double) F->n[0] * r->org[0] + (long double) F->n[1] * r->org[1] +
          (long double) F->n[2] * r->org[2] + F->d;
    *rate = (long double) F->n[0] * r->dir[0] + (long double) F->n[1] * r->dir[1] +
            (long double) F->n[2] * r->dir[2];
}

int ef_ref_inscatter(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, long double S[3])
{
    S[0] = S[1] = S[2] = 0;
    const double D = r->dist;
    if (!(D > 0) || s->ncomp == 0)
        return 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_model *m = s->comp[i].model;
        if (m != &ef_fog_exp && (!m->functionals || !m->density))
            return -1;
    }
    enum { NCUT = 512 };
    long double cut[NCUT];
    int n = 0;
    cut[n++] = 0;
    /* the densities' features where the view ray crosses them */
    for (int i = 0; i < s->ncomp && n < NCUT - 200; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (c->model == &ef_fog_exp || !c->model->features)
            continue;
        ef_fog_functional f[MAXF];
        const int nf = c->model->functionals(c, f, MAXF), nt = c->model->features(c, NULL, 0);
        ef_fog_feature *ft = malloc(((size_t) nt + 1) * sizeof *ft);
        if (!ft || nf > MAXF) {
            free(ft);
            return -1;
        }
        c->model->features(c, ft, nt);
        for (int j = 0; j < nt && n < NCUT - 200; ++j) {
            long double v0, rate;
            line_of(&f[ft[j].f], r, &v0, &rate);
            const long double t = (ft[j].value - v0) / rate;
            if (t > 0 && t < D)
                cut[n++] = t;
        }
        free(ft);
    }
    /* a noise lattice's faces where the view ray crosses them (the noise
     * is a polynomial between them, so the rule converges there), while
     * they fit: a long ray integrates without them, only slower */
    long double Dl = D;   /* a sky ray: to its last feature (a box's far face) */
    if (!isfinite(D)) {
        Dl = 0;
        for (int i = 1; i < n; ++i)
            Dl = fmaxl(Dl, cut[i]);
    }
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->lattices || !(Dl > 0))
            continue;
        ef_fog_functional f[MAXF];
        const int nf = c->model->functionals(c, f, MAXF), nl = c->model->lattices(c, NULL, 0);
        ef_fog_lattice lt[64];
        if (nf > MAXF || nl > 64)
            continue;
        c->model->lattices(c, lt, nl);
        long double extra = 0;
        for (int j = 0; j < nl; ++j) {
            long double v0, rate;
            line_of(&f[lt[j].f], r, &v0, &rate);
            extra += fabsl(rate) * Dl / lt[j].period + 2;
        }
        if (n + extra > NCUT - 220)
            continue;
        for (int j = 0; j < nl; ++j) {
            long double v0, rate;
            line_of(&f[lt[j].f], r, &v0, &rate);
            if (rate == 0)
                continue;
            const long double v1 = v0 + rate * Dl, lo = fminl(v0, v1), hi = fmaxl(v0, v1);
            for (long double k = ceill((lo - lt[j].phase) / lt[j].period);
                 lt[j].phase + k * lt[j].period < hi && n < NCUT - 220; k += 1) {
                const long double t = (lt[j].phase + k * lt[j].period - v0) / rate;
                if (t > 0 && t < Dl)
                    cut[n++] = t;
            }
        }
    }
    /* a lamp's 1/d^2 peak: geometric steps around its closest approach */
    if (ef_light_at_position(l)) {
        long double w[3], ts = 0, ww = 0;
        for (int a = 0; a < 3; ++a) {
            w[a] = (long double) l->pos[a] - r->org[a];
            ts += w[a] * r->dir[a];
            ww += w[a] * w[a];
        }
        const long double hl = sqrtl(fmaxl(ww - ts * ts, 0)), h = hl + l->radius;
        if (h == 0 && ts >= 0 && ts <= D) {
            for (int k = 0; k < 3; ++k)
                S[k] = l->e[k] > 0 ? INFINITY : 0;
            return 0;
        }
        if (ts > 0 && ts < D)
            cut[n++] = ts;
        /* from the line's own distance: the phase turns over ~that */
        for (long double st = fmaxl(hl > 0 ? hl : h, 1e-300L); st < 1e300L && n < NCUT - 2;
             st *= 4) {
            if (ts + st > 0 && ts + st < D)
                cut[n++] = ts + st;
            if (ts - st > 0 && ts - st < D)
                cut[n++] = ts - st;
            if (st > fabsl(ts) + (isfinite(D) ? D : 0) + 1e3L * h)
                break;
        }
    }
    if (ef_light_coned(l))
        n = spot_cuts(l, r, cut, n, NCUT);
    qsort(cut, (size_t) n, sizeof cut[0], cmp_ld);
    lit_ref q = { s, l, r, 0, 1, 0 };
    if (isfinite(D)) {
        cut[n++] = D;
        lit_adapt(&q, cut, n, 0, S);
    } else {
        lit_adapt(&q, cut, n, 0, S);
        q.a = cut[n - 1];
        q.lambda = fmaxl(q.a, 1);
        const long double u[2] = { 0, 1 };
        lit_adapt(&q, u, 2, 1, S);
    }
    return q.fail ? -1 : 0;
}
