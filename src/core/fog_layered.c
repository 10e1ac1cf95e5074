/* Layered fog (seed 004, "layered fog" with a pre-integrated lookup): the
 * density depends on height alone, piecewise linear between knots and
 * constant beyond the ends. The knots come from the spec
 * (heights=...:densities=...) or from a profile file (file=), read through
 * the context's read_file (the core does no I/O).
 *
 * Finished layout (c->arr, c->narr = 10 n for n knots):
 *   arr[0, n)                  knot heights, strictly increasing (scene units)
 *   per channel ch, at n + 3 n ch:
 *     d[n]                     densities per scene unit
 *     ghi[n], glo[n]           G(h_i) = integral of sigma from h_0 to h_i, as a
 *                              double-double so differences stay accurate
 * Before finish, heights= and densities= are kept in arr as [heights | R,G,B
 * triples] with p[0], p[1] their counts; file= keeps its path in c->path. */
#include "exact.h"
#include "fog.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LAYERED_MAX 4096

enum { K_HEIGHTS, K_DENSITIES, K_FILE };

static const char *const layered_keys[] = { "heights", "densities", "file", NULL };

#define CLIP 160

/* s itself, or its first CLIP characters and "...": a long list would
 * otherwise push the point of a message out of ef_err's buffer. */
static const char *clip(const char *s, char buf[CLIP + 4])
{
    if (strlen(s) <= CLIP)
        return s;
    memcpy(buf, s, CLIP);
    memcpy(buf + CLIP, "...", 4);
    return buf;
}

/* ef_fail with "fog spec 'SPEC': " in front (the spec clipped). */
#if defined(__GNUC__)
__attribute__((format(printf, 3, 4)))
#endif
static int lfail(const ef_fog_component *c, ef_err *err, const char *fmt, ...)
{
    char msg[768], sb[CLIP + 4];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return ef_fail(err, "fog spec '%s': %s", clip(c->spec, sb), msg);
}

/* Replaces arr by [h | d] (the pre-finish layout). */
static int store_lists(ef_fog_component *c, const double *h, int nh, const double *d, int nd,
                       ef_err *err)
{
    const size_t len = (size_t) nh + 3 * (size_t) nd;
    double *a = malloc((len ? len : 1) * sizeof *a);
    if (!a)
        return lfail(c, err, "out of memory");
    if (nh)
        memcpy(a, h, (size_t) nh * sizeof *a);
    if (nd)
        memcpy(a + nh, d, 3 * (size_t) nd * sizeof *a);
    free(c->arr);
    c->arr = a;
    c->narr = (int) len;
    c->p[0] = nh;
    c->p[1] = nd;
    return 0;
}

static int count_entries(const char *val)
{
    int n = 1;
    for (const char *q = val; *q; ++q)
        n += *q == ',';
    return n;
}

/* One finite number at s, followed by optional spaces; *end past them. */
static int parse_number(const char *s, const char **end, double *out)
{
    char *e;
    double v;
    if (ef_parse_real(s, &e, &v, 0))
        return -1;
    while (*e == ' ')
        ++e;
    *out = v;
    *end = e;
    return 0;
}

/* n comma-separated entries, each D or R/G/B, into out[3 n]. */
static int parse_densities(const char *val, double *out, int n)
{
    const char *s = val;
    for (int i = 0; i < n; ++i) {
        double *o = out + 3 * i;
        if (parse_number(s, &s, &o[0]))
            return -1;
        if (*s == '/') {
            if (parse_number(s + 1, &s, &o[1]) || *s != '/' || parse_number(s + 1, &s, &o[2]))
                return -1;
        } else
            o[1] = o[2] = o[0];
        if (i + 1 < n) {
            if (*s != ',')
                return -1;
            ++s;
        }
    }
    return *s == '\0' ? 0 : -1;
}

static int set_heights(ef_fog_component *c, const char *val, ef_err *err)
{
    char vb[CLIP + 4];
    const int n = count_entries(val);
    if (n > LAYERED_MAX)
        return lfail(c, err, "heights= has %d points (at most %d)", n, LAYERED_MAX);
    double *h = malloc((size_t) n * sizeof *h);
    if (!h)
        return lfail(c, err, "out of memory");
    int rc = 0;
    if (ef_parse_numbers(val, h, n))
        rc = lfail(c, err, "heights='%s' is not a list of numbers (write heights=H0,H1,... in "
                   "scene units, bottom to top)", clip(val, vb));
    for (int i = 1; i < n && !rc; ++i)
        if (!(h[i] > h[i - 1]))
            rc = lfail(c, err, "heights='%s' do not increase strictly (point %d, %.15g, is not "
                       "above %.15g; list them bottom to top)", clip(val, vb), i + 1, h[i],
                       h[i - 1]);
    if (!rc)
        rc = store_lists(c, h, n, c->arr, (int) c->p[1], err);
    free(h);
    return rc;
}

static int set_densities(ef_fog_component *c, const char *val, ef_err *err)
{
    char vb[CLIP + 4];
    const int n = count_entries(val);
    if (n > LAYERED_MAX)
        return lfail(c, err, "densities= has %d points (at most %d)", n, LAYERED_MAX);
    double *d = malloc(3 * (size_t) n * sizeof *d);
    if (!d)
        return lfail(c, err, "out of memory");
    int rc = 0;
    if (parse_densities(val, d, n))
        rc = lfail(c, err, "densities='%s' is not a list of densities (write densities=D0,D1,... "
                   "per metre; an entry may be R/G/B, e.g. densities=0.1,0.2/0.3/0.4)",
                   clip(val, vb));
    for (int i = 0; i < 3 * n && !rc; ++i)
        if (d[i] < 0)
            rc = lfail(c, err, "densities='%s': entry %d is negative (densities must be >= 0)",
                       clip(val, vb), i / 3 + 1);
    if (!rc)
        rc = store_lists(c, c->arr, (int) c->p[0], d, n, err);
    free(d);
    return rc;
}

static int set_layered(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    const unsigned lists = (1u << K_HEIGHTS) | (1u << K_DENSITIES);
    if ((k == K_FILE && (c->seen & lists)) || (k != K_FILE && (c->seen & (1u << K_FILE))))
        return lfail(c, err, "file= and heights=/densities= are exclusive (give a profile file "
                     "or the two lists, not both)");
    if (k == K_HEIGHTS)
        return set_heights(c, val, err);
    if (k == K_DENSITIES)
        return set_densities(c, val, err);
    if (!(c->path = strdup(val)))
        return lfail(c, err, "out of memory");
    return 0;
}

/* Builds the finished layout from n knots h and R,G,B triples d (per metre),
 * replacing arr. h and d may point into the old arr. */
static int build_profile(ef_fog_component *c, const ef_fog_context *ctx, const double *h,
                         const double *d, int n, ef_err *err)
{
    if (!isfinite(h[n - 1] - h[0]))
        return lfail(c, err, "the heights span %.15g to %.15g, too far apart for a double",
                     h[0], h[n - 1]);
    double *a = malloc(10 * (size_t) n * sizeof *a);
    if (!a)
        return lfail(c, err, "out of memory");
    memcpy(a, h, (size_t) n * sizeof *a);
    for (int ch = 0; ch < 3; ++ch) {
        double *dc = a + n + 3 * n * ch, *ghi = dc + n, *glo = ghi + n;
        for (int i = 0; i < n; ++i)
            dc[i] = ef_fog_per_unit(ctx, d[3 * i + ch]);
        ef_dd g = { 0.0, 0.0 };
        ghi[0] = glo[0] = 0.0;
        /* Each piece's trapezoid (h_{i+1} - h_i)(d_i + d_{i+1})/2 with the
         * difference and the sum kept exact, accumulated in double-double. */
        for (int i = 0; i + 1 < n; ++i) {
            const ef_dd w = ef_two_sum(h[i + 1], -h[i]), sm = ef_two_sum(dc[i], dc[i + 1]);
            ef_dd t = ef_two_prod(w.hi, sm.hi);
            t.lo += w.hi * sm.lo + w.lo * sm.hi;
            t.hi *= 0.5;
            t.lo *= 0.5;
            g = ef_dd_add(g, t);
            ghi[i + 1] = g.hi;
            glo[i + 1] = g.lo;
        }
        if (!isfinite(g.hi) || !isfinite(g.lo)) {
            free(a);
            return lfail(c, err, "the profile's integral overflows a double (heights %.15g to "
                         "%.15g)", h[0], h[n - 1]);
        }
    }
    free(c->arr);
    c->arr = a;
    c->narr = 10 * n;
    return 0;
}

/* Formats "fog spec 'S': profile 'P' line N: ..." and names the profile in
 * err->file (a copy: c->path goes when the failed component is freed). */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static int profile_fail(const ef_fog_component *c, ef_err *err, int line, const char *fmt, ...)
{
    char msg[512], pb[CLIP + 4];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    const char *path = clip(c->path, pb);
    ef_err_set_file(err, c->path);
    if (line > 0)
        return lfail(c, err, "profile '%s' line %d: %s", path, line, msg);
    return lfail(c, err, "profile '%s' %s", path, msg);
}

static int is_space(char ch)
{
    return ch == ' ' || ch == '\t' || ch == '\r' || ch == '\v' || ch == '\f';
}

/* Reads "height density" or "height r g b" lines ('#' comments, blank
 * lines; values separated by whitespace or one comma) into h[] and the
 * R,G,B triples d[]. Returns the number of points or -1. */
static int parse_profile(const ef_fog_component *c, const char *text, double *h, double *d,
                         ef_err *err)
{
    int n = 0, line = 0, ncol = 0, ncol_line = 0, prev_line = 0;
    const char *s = text;
    while (*s) {
        ++line;
        const char *eol = strchr(s, '\n');
        if (!eol)
            eol = s + strlen(s);
        const char *hash = memchr(s, '#', (size_t) (eol - s));
        const char *end = hash ? hash : eol, *q = s;
        double v[4];
        int nv = 0;
        while (q < end && is_space(*q))
            ++q;
        while (q < end) {
            const char *t0 = q;
            while (q < end && !is_space(*q) && *q != ',')
                ++q;
            if (q == t0)
                return profile_fail(c, err, line, "an empty value before ',' (separate values "
                                    "by spaces or one comma)");
            char tok[64];
            const int tlen = (int) (q - t0);
            snprintf(tok, sizeof tok, "%.*s", tlen < 63 ? tlen : 63, t0);
            if (nv == 4)
                return profile_fail(c, err, line, "more than 4 values at '%s' (write 'height "
                                    "density' or 'height r g b')", tok);
            char *e;
            const int rc = ef_parse_real(tok, &e, &v[nv], 0);
            if (rc == -2 && !*e)
                return profile_fail(c, err, line, "'%s' is out of range (0 or between 2.2e-308 "
                                    "and 1.8e308 in magnitude)", tok);
            if (tlen > 63 || rc || *e)
                return profile_fail(c, err, line, "'%s' is not a number", tok);
            ++nv;
            while (q < end && is_space(*q))
                ++q;
            if (q < end && *q == ',') {
                ++q;
                while (q < end && is_space(*q))
                    ++q;
                if (q == end)
                    return profile_fail(c, err, line, "ends with ',' (a value is missing)");
            }
        }
        s = *eol ? eol + 1 : eol;
        if (nv == 0)
            continue;
        if (nv != 2 && nv != 4)
            return profile_fail(c, err, line, "has %d value%s (write 'height density' or "
                                "'height r g b')", nv, nv == 1 ? "" : "s");
        if (ncol && nv != ncol)
            return profile_fail(c, err, line, "has %d values but line %d has %d (use the same "
                                "columns on every line)", nv, ncol_line, ncol);
        ncol = nv;
        ncol_line = line;
        for (int i = 1; i < nv; ++i)
            if (v[i] < 0)
                return profile_fail(c, err, line, "density %.15g is negative (densities must "
                                    "be >= 0)", v[i]);
        if (n && !(v[0] > h[n - 1]))
            return profile_fail(c, err, line, "height %.15g is not above %.15g on line %d "
                                "(heights must increase strictly, bottom to top)", v[0],
                                h[n - 1], prev_line);
        if (n == LAYERED_MAX)
            return profile_fail(c, err, line, "is past the limit of %d points", LAYERED_MAX);
        h[n] = v[0];
        for (int ch = 0; ch < 3; ++ch)
            d[3 * n + ch] = v[nv == 2 ? 1 : 1 + ch];
        prev_line = line;
        ++n;
    }
    if (n == 0)
        return profile_fail(c, err, 0, "has no points (write one 'height density' or 'height "
                            "r g b' line per point; '#' starts a comment)");
    return n;
}

static int finish_file(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    if (!ctx->read_file)
        return lfail(c, err, "file= cannot be read here (give the profile as heights=H0,...:"
                     "densities=D0,... instead)");
    char *text = NULL;
    /* read_file sets err, err->file included. */
    if (ctx->read_file(c->path, &text, err)) {
        free(text);
        return -1;
    }
    double *buf = malloc(4 * (size_t) LAYERED_MAX * sizeof *buf);
    if (!buf) {
        free(text);
        return lfail(c, err, "out of memory");
    }
    const int n = parse_profile(c, text, buf, buf + LAYERED_MAX, err);
    free(text);
    int rc = -1;
    if (n > 0) {
        rc = build_profile(c, ctx, buf, buf + LAYERED_MAX, n, err);
        if (rc)
            ef_err_set_file(err, c->path);
    }
    free(buf);
    return rc;
}

static int finish_layered(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    if (c->seen & (1u << K_FILE))
        return finish_file(c, ctx, err);
    if (!(c->seen & (1u << K_HEIGHTS)))
        return lfail(c, err, "missing heights (write layered:heights=H0,...:densities=D0,... "
                     "or layered:file=PROFILE)");
    if (!(c->seen & (1u << K_DENSITIES)))
        return lfail(c, err, "missing densities (write layered:heights=H0,...:densities=D0,..., "
                     "one density per height)");
    const int nh = (int) c->p[0], nd = (int) c->p[1];
    if (nh != nd)
        return lfail(c, err, "%d heights but %d densities (give one density per height)", nh,
                     nd);
    return build_profile(c, ctx, c->arr, c->arr + nh, nh, err);
}

/* ---- evaluation ---- */

typedef struct profile {
    int n;
    const double *h, *d[3], *ghi[3], *glo[3];
} profile;

static profile profile_of(const ef_fog_component *c)
{
    profile p;
    p.n = c->narr / 10;
    p.h = c->arr;
    for (int ch = 0; ch < 3; ++ch) {
        p.d[ch] = c->arr + p.n + 3 * p.n * ch;
        p.ghi[ch] = p.d[ch] + p.n;
        p.glo[ch] = p.ghi[ch] + p.n;
    }
    return p;
}

/* Index of the first knot above the double-double u (n if none); the low
 * part decides when u.hi is a knot, so a height a hair off a knot is put on
 * its side. */
EF_INLINE int first_above(const double *h, int n, ef_dd u)
{
    int lo = 0, hi = n;
    while (lo < hi) {
        const int mid = lo + (hi - lo) / 2;
        if (h[mid] > u.hi || (h[mid] == u.hi && u.lo < 0))
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

/* Index of the first knot at or above u (n if none). */
EF_INLINE int first_not_below(const double *h, int n, ef_dd u)
{
    int lo = 0, hi = n;
    while (lo < hi) {
        const int mid = lo + (hi - lo) / 2;
        if (h[mid] > u.hi || (h[mid] == u.hi && u.lo <= 0))
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

/* Where the double-double height u lies: between knots j-1 and j, with
 * weights wl (of knot j-1) and wr (of knot j), each from u's distance to
 * the other knot so neither cancels next to a knot; j = 0 or n: beyond an
 * end. */
typedef struct where {
    int j;
    double wl, wr;
} where;

EF_INLINE where locate(const profile *p, int j, ef_dd u)
{
    where at = { j, 0.0, 0.0 };
    if (j > 0 && j < p->n) {
        const double h0 = p->h[j - 1], h1 = p->h[j], width = h1 - h0;
        at.wl = ef_fmax(0.0, ((h1 - u.hi) - u.lo) / width);
        at.wr = ef_fmax(0.0, ((u.hi - h0) + u.lo) / width);
    }
    return at;
}

EF_INLINE double sigma_at(const profile *p, int ch, where at)
{
    const double *d = p->d[ch];
    if (at.j == 0)
        return d[0];
    if (at.j == p->n)
        return d[p->n - 1];
    /* two non-negative terms: accurate to a few ulps, zero at a zero knot */
    return d[at.j - 1] * at.wl + d[at.j] * at.wr;
}

/* a * b with 0 * inf = 0: a zero density over an infinite stretch is none. */
static double mul0(double a, double b)
{
    return a == 0 || b == 0 ? 0.0 : a * b;
}

/* Optical depth between heights a <= b (double-doubles) crossed at rate
 * |s| = as, per channel. L > 0: the segment's length (used whole when no
 * knot lies strictly between a and b, so s -> 0 stays exact); L < 0: not
 * known (the sky's finite part). Pieces cut by knots are trapezoids of
 * their height span; runs of whole pieces come from the prefix table. */
EF_INLINE void integrate(const profile *p, ef_dd a, ef_dd b, double as, double L, double tau[3])
{
    const int ia = first_above(p->h, p->n, a), ib = first_not_below(p->h, p->n, b) - 1;
    const where wa = locate(p, ia, a), wb = locate(p, ib + 1, b);
    if (ia > ib) {
        const double len = L >= 0 ? L : ((b.hi - a.hi) + (b.lo - a.lo)) / as;
        for (int ch = 0; ch < 3; ++ch)
            tau[ch] = mul0(len, 0.5 * (sigma_at(p, ch, wa) + sigma_at(p, ch, wb)));
        return;
    }
    const double ha = ef_fmax(0.0, (p->h[ia] - a.hi) - a.lo);
    const double hb = ef_fmax(0.0, (b.hi - p->h[ib]) + b.lo);
    for (int ch = 0; ch < 3; ++ch) {
        const double *d = p->d[ch];
        const double first = mul0(ha, 0.5 * (sigma_at(p, ch, wa) + d[ia]));
        const double last = mul0(hb, 0.5 * (d[ib] + sigma_at(p, ch, wb)));
        const double run = (p->ghi[ch][ib] - p->ghi[ch][ia]) + (p->glo[ch][ib] - p->glo[ch][ia]);
        tau[ch] = (first + run + last) / as;
    }
}

EF_INLINE void tau_layered_one(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const profile p = profile_of(c);
    const double L = r->dist;
    if (p.n == 1) {
        /* constant everywhere: exactly exp fog */
        for (int ch = 0; ch < 3; ++ch)
            tau[ch] = mul0(p.d[ch][0], L);
        return;
    }
    if (!(L > 0)) {
        tau[0] = tau[1] = tau[2] = 0;
        return;
    }
    /* Heights kept as double-doubles so the pieces' spans next to a knot
     * do not cancel, far from the origin included. */
    const ef_dd u0 = ef_cam_h0(c, c->up, 0.0, r->org), sd = ef_cam_rate(c, c->up, r->dir);
    const double s = sd.hi + sd.lo;
    if (s == 0) {
        const where at = locate(&p, first_above(p.h, p.n, u0), u0);
        for (int ch = 0; ch < 3; ++ch)
            tau[ch] = mul0(sigma_at(&p, ch, at), L);
        return;
    }
    const double as = fabs(s);
    if (isinf(L)) {
        /* Up-going rays stay in d_n forever above the top knot, down-going
         * ones in d_0 below the bottom one; the rest is finite. */
        const int up = s > 0;
        const double top = p.h[p.n - 1], bottom = p.h[0];
        if (up ? u0.hi > top || (u0.hi == top && u0.lo >= 0)
               : u0.hi < bottom || (u0.hi == bottom && u0.lo <= 0))
            tau[0] = tau[1] = tau[2] = 0;
        else if (up)
            integrate(&p, u0, (ef_dd) { top, 0.0 }, as, -1.0, tau);
        else
            integrate(&p, (ef_dd) { bottom, 0.0 }, u0, as, -1.0, tau);
        for (int ch = 0; ch < 3; ++ch)
            if ((up ? p.d[ch][p.n - 1] : p.d[ch][0]) > 0)
                tau[ch] = INFINITY;
        return;
    }
    const ef_dd u1 = ef_dd_affine(u0, sd, L);
    if (s > 0)
        integrate(&p, u0, u1, as, L, tau);
    else
        integrate(&p, u1, u0, as, L, tau);
}

EF_MULTIVERSION static void tau_layered(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    tau_layered_one(c, r, tau);
}

EF_TAU_ADD(tau_add_layered, tau_layered)

/* The camera's height, cached for its rays (exact.h). */
static void bind_layered(ef_fog_component *c, const double org[3])
{
    ef_cam_bind(c, c->up, 0.0, org);
}

/* The reference sees heights relative to the first knot, so that a profile
 * 1e7 above the origin keeps long double's resolution next to its knots. */
static int functionals_layered(const ef_fog_component *c, ef_fog_functional *out, int cap)
{
    const profile p = profile_of(c);
    if (cap > 0)
        out[0] = (ef_fog_functional) { { c->up[0], c->up[1], c->up[2] }, -p.h[0] };
    return 1;
}

/* Every knot is a kink (or the start of a constant end). */
static int features_layered(const ef_fog_component *c, ef_fog_feature *out, int cap)
{
    const profile p = profile_of(c);
    for (int i = 0; i < p.n && i < cap; ++i)
        out[i] = (ef_fog_feature) { 0, (double) ((long double) p.h[i] - p.h[0]), 0.0 };
    return p.n;
}

/* The interpolant straight from the knots, in long double. */
static void density_layered(const ef_fog_component *c, const long double *v, long double out[3])
{
    const profile p = profile_of(c);
    const long double u = v[0], base = p.h[0];   /* u: height above the first knot */
    int j = 0, hi = p.n;          /* j: the first knot above u */
    while (j < hi) {
        const int mid = j + (hi - j) / 2;
        if ((long double) p.h[mid] - base > u)
            hi = mid;
        else
            j = mid + 1;
    }
    for (int ch = 0; ch < 3; ++ch) {
        const double *d = p.d[ch];
        if (j == 0)
            out[ch] = d[0];
        else if (j == p.n)
            out[ch] = d[p.n - 1];
        else {
            const long double h0 = p.h[j - 1] - base, h1 = p.h[j] - base;
            const long double w = (u - h0) / (h1 - h0);
            out[ch] = (long double) d[j - 1] * (1 - w) + (long double) d[j] * w;
        }
    }
}

const ef_fog_model ef_fog_layered = { .name = "layered", .keys = layered_keys,
                                      .set = set_layered, .finish = finish_layered,
                                      .tau = tau_layered,
                                      .tau_add = tau_add_layered, .bind = bind_layered, .functionals = functionals_layered,
                                      .features = features_layered,
                                      .density = density_layered, .uses_up = 1 };
