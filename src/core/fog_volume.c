/* Constant-density convex fog volumes: box and convex (seed 002, the stencil
 * fog-volume note). The note finds, per pixel, the front face the view ray
 * enters through by rendering each face into the stencil buffer; here the
 * same question is answered analytically by clipping the segment against
 * the volume's planes, so tau = rho * (length of the segment inside).
 *
 * Both models store their planes (A,B,C,D, unit normal, fog where
 * A*x+B*y+C*z+D < 0) in c->arr and share one clipping routine; a box is its
 * six planes x - max < 0 and -x + min < 0 per axis.
 *
 * Exactness: plane values and rates are the fma double-double dot products
 * of exact.h (as ef_line_of, keeping the low parts), and the crossing
 * parameters t = -h0/s are double-doubles, so picking the entry/exit plane
 * and subtracting the two crossings does not cancel even for a sliver of a
 * volume 1e7 from the camera. A length that ends at the segment's end is
 * taken from the end's own plane value (len - t = h1/s), so a pixel on or
 * near a face is exact. A plain-double pass with proven error bounds decides
 * the signs and the binding planes first, so only those one or two planes
 * pay for double-doubles on nearly every pixel. */
#include "exact.h"
#include "fog.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_PLANES 64

/* p[] layout: p[0..2] = density per channel (per metre until finish, then per
 * scene unit); box only: p[3..5] = min, p[6..8] = max (scene units). */
enum { P_RHO = 0, P_MIN = 3, P_MAX = 6, P_NP = 9, P_CAM = 10, P_ORG = 11, P_SLAB = 14 };

/* p[P_NP] = the number of planes (c->arr starts with them, A,B,C,D each).
 * Once bound to a camera (bind_volume), p[P_CAM] = 1, p[P_ORG..] is the
 * camera and c->arr continues with CACHE doubles per plane: what
 * clip_fast and crossing_of compute from the plane and the ray's origin
 * alone, for rays from that camera (the same operations, done once).
 * p[P_SLAB] = 1 when the planes are three slabs +e_a, -e_a in axis order
 * (every box) and the camera is certainly off each plane: clip_slabs. */
enum { C_H0 = 0, C_EH, C_HI, C_LO, C_AXIS, C_ZAX, CACHE = 8 };

static int nplanes(const ef_fog_component *c)
{
    return (int) c->p[P_NP];
}

static const char *const box_keys[] = { "min", "max", "density", "visibility", NULL };
enum { BOX_MIN, BOX_MAX, BOX_DENSITY, BOX_VISIBILITY };
static const char *const convex_keys[] = { "planes", "density", "visibility", NULL };
enum { CVX_PLANES, CVX_DENSITY, CVX_VISIBILITY };

/* ---- parsing ---- */

/* The shortest of %.15g..%.17g that reads back as v, for messages. */
static void fmt_num(char *buf, size_t len, double v)
{
    for (int prec = 15; prec <= 17; ++prec) {
        snprintf(buf, len, "%.*g", prec, v);
        if (strtod(buf, NULL) == v)
            return;
    }
}

static int set_box(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    switch (k) {
    case BOX_MIN:
    case BOX_MAX:
        if (ef_parse_numbers(val, &c->p[k == BOX_MIN ? P_MIN : P_MAX], 3))
            return ef_fail(err, "fog spec '%s': %s='%s' is not X,Y,Z (three numbers)", c->spec,
                           box_keys[k], val);
        return 0;
    case BOX_DENSITY:
        return ef_fog_set_density(c, "density", val, &c->p[P_RHO], err);
    default:
        return ef_fog_set_visibility(c, "visibility", val, &c->p[P_RHO], err);
    }
}

/* Normalises plane pl (A,B,C,D) in place as ef_fog_set_plane does, scaling
 * by the largest |A|,|B|,|C| first when A^2+B^2+C^2 would overflow or lose
 * bits to underflow. Returns 0, -1 for a zero normal, or -2 when D over the
 * normal's length overflows. */
static int normalise_plane(double pl[4])
{
    const double ss = pl[0] * pl[0] + pl[1] * pl[1] + pl[2] * pl[2];
    if (ss >= DBL_MIN && ss <= DBL_MAX) {
        const double len = sqrt(ss);
        for (int i = 0; i < 4; ++i)
            pl[i] /= len;
    } else {
        const double m = fmax(fabs(pl[0]), fmax(fabs(pl[1]), fabs(pl[2])));
        if (m == 0.0)
            return -1;
        for (int i = 0; i < 4; ++i)
            pl[i] /= m;
        const double len = sqrt(pl[0] * pl[0] + pl[1] * pl[1] + pl[2] * pl[2]);
        for (int i = 0; i < 4; ++i)
            pl[i] /= len;
    }
    return isfinite(pl[3]) ? 0 : -2;
}

/* planes=A,B,C,D,...: 1..64 planes, each stored normalised in c->arr. */
static int set_planes(ef_fog_component *c, const char *val, ef_err *err)
{
    int n = 1;
    for (const char *q = val; *q; ++q)
        n += *q == ',';
    if (n > 4 * MAX_PLANES)
        return ef_fail(err, "fog spec '%s': planes='%.40s...' has %d numbers, more than %d "
                       "planes of A,B,C,D (use at most %d planes, or split the volume into "
                       "several components)", c->spec, val, n, MAX_PLANES, MAX_PLANES);
    double *pl = malloc((size_t) n * sizeof *pl);
    if (!pl)
        return ef_fail(err, "fog spec '%s': out of memory", c->spec);
    const char *s = val;
    for (int i = 0; i < n; ++i) {
        const char *e = strchr(s, ',');
        if (!e)
            e = s + strlen(s);
        char *end;
        double v = 0;
        const int rc = ef_parse_real(s, &end, &v, 0);
        while (end < e && *end == ' ')
            ++end;
        if (rc || end == s || end != e) {
            free(pl);
            if (rc == -2 && end == e)
                return ef_fail(err, "fog spec '%s': planes= number %d ('%.*s') is out of range "
                               "(0 or between 2.2e-308 and 1.8e308 in magnitude)", c->spec,
                               i + 1, (int) (e - s), s);
            return ef_fail(err, "fog spec '%s': planes= number %d ('%.*s') is not a finite "
                           "number (write planes=A,B,C,D,A,B,C,D,...)", c->spec, i + 1,
                           (int) (e - s), s);
        }
        pl[i] = v;
        s = *e ? e + 1 : e;
    }
    if (n % 4) {
        free(pl);
        return ef_fail(err, "fog spec '%s': planes='%s' has %d numbers, not a multiple of 4 "
                       "(give A,B,C,D for each plane)", c->spec, val, n);
    }
    /* Walk the text again to quote the offending plane. */
    s = val;
    for (int p = 0; p < n / 4; ++p) {
        const char *start = s;
        for (int j = 0; j < 4; ++j) {
            const char *e = strchr(s, ',');
            s = e ? e + 1 : s + strlen(s);
        }
        const int rc = normalise_plane(pl + 4 * p);
        if (rc) {
            int w = (int) (s - start);
            if (w > 0 && start[w - 1] == ',')
                --w;
            free(pl);
            return ef_fail(err, rc == -1 ? "fog spec '%s': planes= plane %d (%.*s) has a zero "
                                           "normal (A,B,C must not all be 0)"
                                         : "fog spec '%s': planes= plane %d (%.*s) is out of "
                                           "range (D is too large for its normal A,B,C)",
                           c->spec, p + 1, w, start);
        }
    }
    free(c->arr);
    c->arr = pl;
    c->narr = n;
    return 0;
}

static int set_convex(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    switch (k) {
    case CVX_PLANES:
        return set_planes(c, val, err);
    case CVX_DENSITY:
        return ef_fog_set_density(c, "density", val, &c->p[P_RHO], err);
    default:
        return ef_fog_set_visibility(c, "visibility", val, &c->p[P_RHO], err);
    }
}

/* Exactly one of density/visibility (bits dbit, dbit+1 of c->seen), then
 * converted to per scene unit. */
static int finish_density(ef_fog_component *c, const ef_fog_context *ctx, int dbit,
                          const char *example, ef_err *err)
{
    const unsigned given = (c->seen >> dbit) & 3u;
    if (!given)
        return ef_fail(err, "fog spec '%s': missing density (write %s:density=D or "
                       "visibility=V)", c->spec, example);
    if (given == 3u)
        return ef_fail(err, "fog spec '%s': give density or visibility, not both", c->spec);
    for (int i = 0; i < 3; ++i)
        c->p[P_RHO + i] = ef_fog_per_unit(ctx, c->p[P_RHO + i]);
    return 0;
}

static int finish_box(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    static const char axis[3] = { 'x', 'y', 'z' };
    for (int k = BOX_MIN; k <= BOX_MAX; ++k)
        if (!(c->seen & (1u << k)))
            return ef_fail(err, "fog spec '%s': missing %s (write box:min=X,Y,Z:max=X,Y,Z:"
                           "density=D)", c->spec, box_keys[k]);
    for (int a = 0; a < 3; ++a)
        if (!(c->p[P_MIN + a] < c->p[P_MAX + a])) {
            char lo[32], hi[32];
            fmt_num(lo, sizeof lo, c->p[P_MIN + a]);
            fmt_num(hi, sizeof hi, c->p[P_MAX + a]);
            return ef_fail(err, "fog spec '%s': min %c = %s is not less than max %c = %s (each "
                           "min coordinate must be below the max one; swap them or widen the "
                           "box)", c->spec, axis[a], lo, axis[a], hi);
        }
    if (finish_density(c, ctx, BOX_DENSITY, "box:min=X,Y,Z:max=X,Y,Z", err))
        return -1;
    double *pl = malloc(24 * sizeof *pl);
    if (!pl)
        return ef_fail(err, "fog spec '%s': out of memory", c->spec);
    /* Per axis: x - max < 0, then -x + min < 0. Unit normals, no rounding. */
    for (int a = 0; a < 3; ++a) {
        double *hi = pl + 8 * a, *lo = hi + 4;
        for (int i = 0; i < 3; ++i)
            hi[i] = lo[i] = 0.0;
        hi[a] = 1.0;
        hi[3] = -c->p[P_MAX + a];
        lo[a] = -1.0;
        lo[3] = c->p[P_MIN + a];
    }
    free(c->arr);
    c->arr = pl;
    c->narr = 24;
    c->p[P_NP] = 6;
    return 0;
}

static int finish_convex(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    if (!(c->seen & (1u << CVX_PLANES)) || c->narr < 4)
        return ef_fail(err, "fog spec '%s': missing planes (write convex:planes=A,B,C,D,...:"
                       "density=D; fog is where every A*x+B*y+C*z+D < 0)", c->spec);
    c->p[P_NP] = c->narr / 4;
    return finish_density(c, ctx, CVX_DENSITY, "convex:planes=A,B,C,D,...", err);
}

/* ---- clipping ----
 *
 * Along the ray, plane i has value h0 + s t (h1 at t = len) and the fog is
 * where every value is < 0. A plane with s > 0 is left at t = -h0/s, one with
 * s < 0 entered there; the segment inside is [max entries, min exits] within
 * [0, len]. A plane whose value is >= 0 at both ends rejects the segment.
 *
 * Two passes: a plain-double pass with rigorous error bounds settles every
 * sign and picks the binding entry/exit planes when the bounds separate them
 * (nearly every pixel), and the exact double-double pass decides the rest
 * (camera or pixel on a face's plane, grazing rays, ties at edges). Either
 * way the final length comes from double-doubles of the binding planes. */

/* One plane along the ray, in double-double (hi = the rounded value). */
typedef struct crossing {
    ef_dd h0, s, h1;
} crossing;

static inline ef_dd dd_neg(ef_dd a)
{
    return (ef_dd) { -a.hi, -a.lo };
}

/* a < b for normalised double-doubles (hi = fl(hi + lo)). */
static inline int dd_less(ef_dd a, ef_dd b)
{
    return a.hi < b.hi || (a.hi == b.hi && a.lo < b.lo);
}

/* a / b to about 2^-100 relative, normalised; b.hi != 0. The remainder of
 * the rounded quotient, a.hi - q*b.hi, is exact with fma. */
static inline ef_dd dd_div(ef_dd a, ef_dd b)
{
    const double q = a.hi / b.hi;
    if (!isfinite(q) || q == 0.0)
        return (ef_dd) { q, 0.0 };
    const double r = fma(-q, b.hi, a.hi) + (a.lo - q * b.lo);
    return ef_two_sum(q, r / b.hi);
}

/* As ef_line_of, keeping the double-double parts; h1 only when asked for
 * (len finite). An axis-aligned unit normal (every box plane) needs one
 * two_sum: +-org[a] and +-dir[a] are exact. */
static inline void crossing_of(const double *p, const double org[3], const double dir[3],
                               double len, int want_h1, crossing *x)
{
    const int a = ef_unit_axis(p);
    if (a >= 0) {
        x->h0 = ef_two_sum(p[a] * org[a], p[3]);
        x->s = (ef_dd) { p[a] * dir[a], 0.0 };
    } else {
        x->h0 = ef_dd_dot3(p, org, p[3]);
        x->s = ef_dd_dot3(p, dir, 0.0);
    }
    x->h1 = (ef_dd) { 0.0, 0.0 };
    if (want_h1) {
        x->h1 = ef_dd_affine(x->h0, x->s, len);
        if (!isfinite(x->h1.hi))              /* s * len overflowed: no NaN from the dd parts */
            x->h1 = (ef_dd) { x->h0.hi + x->s.hi * len, 0.0 };
    }
}

/* The inside length once the binding entering plane in (or -1: entry at 0)
 * and leaving plane out (or -1: exit at len) are known, with their
 * crossings xi, xo (xi->h1 needed when out < 0 and len is finite). */
EF_INLINE double bound_length(const double *pl, int in, const crossing *xi, int out,
                           const crossing *xo, double len)
{
    if (out < 0) {
        if (in < 0 || isinf(len))
            return len;                       /* inside to the end (INFINITY for the sky) */
        /* len - t_in = h1/s of the entering plane: the end's own value, no
         * cancellation when the pixel is near that face. */
        return dd_div(xi->h1, xi->s).hi;
    }
    const ef_dd t_out = dd_div(dd_neg(xo->h0), xo->s);
    if (in < 0 || isinf(t_out.hi))
        return t_out.hi;
    const double *pi = pl + 4 * in, *po = pl + 4 * out;
    ef_dd d;
    if (pi[0] == -po[0] && pi[1] == -po[1] && pi[2] == -po[2])
        /* Opposite faces of a slab: h_in + h_out = D_in + D_out everywhere, so
         * the length is the width over the rate, however far away it lies. */
        d = dd_div(dd_neg(ef_two_sum(pi[3], po[3])), xo->s);
    else
        d = ef_dd_add(t_out, dd_neg(dd_div(dd_neg(xi->h0), xi->s)));
    return d.hi > 0.0 ? d.hi : 0.0;
}

/* The exact pass: every plane in double-double. */
EF_MULTIVERSION static double inside_length_exact(const double *pl, int np, const double org[3],
                                  const double dir[3], double len)
{
    const int sky = isinf(len);
    int in = -1, out = -1;                    /* binding entering / leaving plane */
    ef_dd t_in = { 0, 0 }, t_out = { 0, 0 };
    crossing xi = { { 0, 0 }, { 0, 0 }, { 0, 0 } }, xo = xi;
    for (int k = 0; k < np; ++k) {
        crossing x;
        crossing_of(pl + 4 * k, org, dir, len, !sky, &x);
        if (x.s.hi == 0.0) {
            if (x.h0.hi >= 0.0)
                return 0.0;                   /* parallel, on or outside the plane */
            continue;
        }
        if (x.s.hi > 0.0) {
            if (x.h0.hi >= 0.0)
                return 0.0;                   /* starts outside and goes further out */
            if (!sky && x.h1.hi <= 0.0)
                continue;                     /* ends inside (or on) it: no exit before len */
            const ef_dd t = dd_div(dd_neg(x.h0), x.s);
            if (out < 0 || dd_less(t, t_out)) {
                out = k;
                t_out = t;
                xo = x;
            }
        } else {
            if (!sky && x.h1.hi >= 0.0)
                return 0.0;                   /* ends outside (or on) it, came from further out */
            if (x.h0.hi <= 0.0)
                continue;                     /* starts inside (or on) it: no entry after 0 */
            const ef_dd t = dd_div(dd_neg(x.h0), x.s);
            if (in < 0 || dd_less(t_in, t)) {
                in = k;
                t_in = t;
                xi = x;
            }
        }
    }
    if (in >= 0 && out >= 0 && !dd_less(t_in, t_out))
        return 0.0;
    return bound_length(pl, in, &xi, out, &xo, len);
}

/* Error bounds of the plain-double pass: a 3-product dot plus a constant
 * has at most 4 roundings on any path (fma contraction only removes some),
 * so |error| <= gamma_4 * sum |terms| < 2^-50 * sum; plus a few subnormal
 * roundings. Derived bounds get a 2^-20 relative margin for their own
 * rounding. */
#define EPS_DOT 0x1p-50
#define EPS_TINY 0x1p-1069
#define MARGIN (1.0 + 0x1p-20)

enum { CLIP_EMPTY, CLIP_BOUND, CLIP_UNSURE };

/* The planes bound so far in the plain-double pass: the best entry
 * (largest t) and exit (smallest t) with their error bounds, and the most
 * competitive bound among the other planes. */
typedef struct clip_state {
    int in, out;
    double t_in, e_in, other_in, t_out, e_out, other_out;
} clip_state;

/* Adds plane k, whose value at the origin is h0 (within eh) and whose rate
 * along the ray is s (within es, s not exactly 0), to st. Returns
 * CLIP_EMPTY or CLIP_UNSURE as clip_fast does, else CLIP_BOUND (go on). */
EF_INLINE int clip_plane(clip_state *st, int k, double h0, double eh, double s, double es,
                         double len)
{
    if (!(fabs(s) > es))
        return CLIP_UNSURE;
    if (s > 0.0 && h0 > 0.0)
        return CLIP_EMPTY;                    /* starts outside and goes further out */
    if (!isinf(len)) {
        const double h1 = h0 + s * len;
        const double eh1 = (eh + es * len + (fabs(h0) + fabs(s) * len) * 0x1p-51) * MARGIN;
        if (!(fabs(h1) > eh1))
            return CLIP_UNSURE;
        if (s < 0.0 && h1 > 0.0)
            return CLIP_EMPTY;                /* ends outside, came from further out */
        if (s > 0.0 && h1 < 0.0)
            return CLIP_BOUND;                /* ends inside: no exit before len */
    }
    if (s < 0.0 && h0 < 0.0)
        return CLIP_BOUND;                    /* starts inside: no entry after 0 */
    /* The exact t = -h0x/sx, where |h0x - h0| <= eh and |sx - s| <= es: it
     * differs from -h0/s by at most (eh + |t| es)/(|s| - es), which is below
     * (eh + |t| es)/|s| * (1 + 2^-19) when es/|s| <= 2^-20 (else too
     * grazing to decide here); t itself has two roundings. */
    const double inv = 1.0 / s, t = -h0 * inv;
    if (!(es * fabs(inv) <= 0x1p-20))
        return CLIP_UNSURE;
    const double et = ((eh + fabs(t) * es) * fabs(inv) * (1.0 + 0x1p-19) +
                       fabs(t) * 0x1p-51) * MARGIN;
    if (!isfinite(t) || !isfinite(et))
        return CLIP_UNSURE;
    if (s > 0.0) {
        if (st->out < 0 || t < st->t_out) {
            if (st->out >= 0)
                st->other_out = ef_fmin(st->other_out, st->t_out - st->e_out);
            st->out = k;
            st->t_out = t;
            st->e_out = et;
        } else
            st->other_out = ef_fmin(st->other_out, t - et);
    } else {
        if (st->in < 0 || t > st->t_in) {
            if (st->in >= 0)
                st->other_in = ef_fmax(st->other_in, st->t_in + st->e_in);
            st->in = k;
            st->t_in = t;
            st->e_in = et;
        } else
            st->other_in = ef_fmax(st->other_in, t + et);
    }
    return CLIP_BOUND;
}

/* The verdict once every plane is in st (see clip_fast). */
EF_INLINE int clip_verdict(const clip_state *st, int *in_, int *out_)
{
    if (st->in >= 0 && !(st->other_in < st->t_in - st->e_in))
        return CLIP_UNSURE;                   /* two entries tie within rounding */
    if (st->out >= 0 && !(st->other_out > st->t_out + st->e_out))
        return CLIP_UNSURE;
    if (st->in >= 0 && st->out >= 0) {
        if (st->t_in - st->e_in > st->t_out + st->e_out)
            return CLIP_EMPTY;
        if (!(st->t_in + st->e_in < st->t_out - st->e_out))
            return CLIP_UNSURE;
    }
    *in_ = st->in;
    *out_ = st->out;
    return CLIP_BOUND;
}

#define CLIP_START { -1, -1, 0, 0, -INFINITY, 0, 0, INFINITY }

/* The plain-double pass. CLIP_EMPTY: the segment certainly misses the
 * volume. CLIP_BOUND: *in, *out are certainly the binding planes (-1: none)
 * and entry < exit. CLIP_UNSURE: a sign or a choice is within rounding. */
EF_INLINE int clip_fast(const double *pl, int np, const double org[3], const double dir[3],
                        double len, int *in_, int *out_)
{
    clip_state st = CLIP_START;
    for (int k = 0; k < np; ++k) {
        const double *p = pl + 4 * k;
        const double a0 = p[0] * org[0], a1 = p[1] * org[1], a2 = p[2] * org[2];
        const double b0 = p[0] * dir[0], b1 = p[1] * dir[1], b2 = p[2] * dir[2];
        const double h0 = a0 + a1 + a2 + p[3];
        const double eh = (fabs(a0) + fabs(a1) + fabs(a2) + fabs(p[3])) * EPS_DOT + EPS_TINY;
        if (!(fabs(h0) > eh))
            return CLIP_UNSURE;
        if (b0 == 0.0 && b1 == 0.0 && b2 == 0.0) {
            /* Exactly parallel (as the double-double pass sees it too). */
            if (h0 > 0.0)
                return CLIP_EMPTY;
            continue;
        }
        const double s = b0 + b1 + b2;
        const double es = (fabs(b0) + fabs(b1) + fabs(b2)) * EPS_DOT + EPS_TINY;
        const int v = clip_plane(&st, k, h0, eh, s, es, len);
        if (v != CLIP_BOUND)
            return v;
    }
    return clip_verdict(&st, in_, out_);
}

/* clip_fast for a ray from the bound camera: the plane values at the
 * origin (h0 and its bound eh) come from the cache, and a plane whose
 * normal has two zero components (every box plane) has s = its one product
 * and es = |s| EPS_DOT + EPS_TINY, the same values as the three-term sums
 * (adding zeros is exact; a zero s is decided before its sign matters).
 * dir must be finite (then those zero products are zeros). */
EF_INLINE int clip_fast_cam(const double *pl, const double *cache, int np, const double dir[3],
                            double len, int *in_, int *out_)
{
    clip_state st = CLIP_START;
    for (int k = 0; k < np; ++k) {
        const double *p = pl + 4 * k, *ca = cache + CACHE * k;
        const double h0 = ca[C_H0], eh = ca[C_EH];
        if (!(fabs(h0) > eh))
            return CLIP_UNSURE;
        const int ax = (int) ca[C_ZAX];
        double s, es;
        if (ax >= 0) {
            s = p[ax] * dir[ax];
            if (s == 0.0) {
                if (h0 > 0.0)
                    return CLIP_EMPTY;
                continue;
            }
            es = fabs(s) * EPS_DOT + EPS_TINY;
        } else {
            const double b0 = p[0] * dir[0], b1 = p[1] * dir[1], b2 = p[2] * dir[2];
            if (b0 == 0.0 && b1 == 0.0 && b2 == 0.0) {
                if (h0 > 0.0)
                    return CLIP_EMPTY;
                continue;
            }
            s = b0 + b1 + b2;
            es = (fabs(b0) + fabs(b1) + fabs(b2)) * EPS_DOT + EPS_TINY;
        }
        const int v = clip_plane(&st, k, h0, eh, s, es, len);
        if (v != CLIP_BOUND)
            return v;
    }
    return clip_verdict(&st, in_, out_);
}

/* clip_fast_cam for three axis slabs (p[P_SLAB]): plane 2a is +e_a, plane
 * 2a+1 is -e_a, so their rates are dir[a] and -dir[a] exactly (es = 0) and
 * one division serves both. Branch-light: every plane's crossing
 * t = -h0/s is a candidate, the entering ones (s < 0) against an entry at
 * 0 and the leaving ones (s > 0) against an exit at len. A plane the ray
 * starts inside has an entry t < 0, one it starts outside of and leaves
 * has an exit t < 0, one it ends inside has an exit t > len: each loses to
 * 0 or len or empties the segment, as clip_plane's sign tests decide them.
 * The binding entry and exit must win by their error bounds (as
 * clip_verdict); |t - t_exact| <= (eh |1/s| (1 + 2^-19) + |t| 2^-51) with
 * MARGIN for the bound's own rounding, and a 2^-1070 floor for a
 * subnormal t. Any infinite bound (a zero or subnormal rate) is
 * CLIP_UNSURE: clip_fast_cam decides those. */
EF_INLINE int clip_slabs(const double *cache, const double dir[3], double len, int *in_,
                         int *out_)
{
    double t_in = 0.0, e_in = 0.0, other_in = -INFINITY;
    double t_out = len, e_out = 0.0, other_out = INFINITY, e_sum = 0.0;
    int in = -1, out = -1;
    for (int a = 0; a < 3; ++a) {
        const double *ch = cache + CACHE * 2 * a, *cl = ch + CACHE;
        const double d = dir[a], inv = 1.0 / d, ainv = fabs(inv) * (1.0 + 0x1p-19);
        const double th = -ch[C_H0] * inv, tl = cl[C_H0] * inv;
        const double eh = (ch[C_EH] * ainv + fabs(th) * 0x1p-51 + 0x1p-1070) * MARGIN;
        const double el = (cl[C_EH] * ainv + fabs(tl) * 0x1p-51 + 0x1p-1070) * MARGIN;
        const int pos = d > 0.0;              /* leaving +e_a's face, entering -e_a's */
        const double te = pos ? tl : th, ee = pos ? el : eh;
        const double tx = pos ? th : tl, ex = pos ? eh : el;
        e_sum += eh + el;
        if (te > t_in) {
            other_in = ef_fmax(other_in, t_in + e_in);
            t_in = te;
            e_in = ee;
            in = 2 * a + pos;
        } else
            other_in = ef_fmax(other_in, te + ee);
        if (tx < t_out) {
            other_out = ef_fmin(other_out, t_out - e_out);
            t_out = tx;
            e_out = ex;
            out = 2 * a + !pos;
        } else
            other_out = ef_fmin(other_out, tx - ex);
    }
    if (!(e_sum < INFINITY))
        return CLIP_UNSURE;
    if (t_in - e_in > t_out + e_out)
        return CLIP_EMPTY;
    if (!(other_in < t_in - e_in) || !(other_out > t_out + e_out) ||
        !(t_in + e_in < t_out - e_out))
        return CLIP_UNSURE;
    *in_ = in;
    *out_ = out;
    return CLIP_BOUND;
}

/* crossing_of with h0 from the cache (the same double-double). */
static inline void crossing_cam(const double *p, const double *ca, const double dir[3],
                                double len, int want_h1, crossing *x)
{
    const int a = (int) ca[C_AXIS];
    x->h0 = (ef_dd) { ca[C_HI], ca[C_LO] };
    if (a >= 0)
        x->s = (ef_dd) { p[a] * dir[a], 0.0 };
    else
        x->s = ef_dd_dot3(p, dir, 0.0);
    x->h1 = (ef_dd) { 0.0, 0.0 };
    if (want_h1) {
        x->h1 = ef_dd_affine(x->h0, x->s, len);
        if (!isfinite(x->h1.hi))
            x->h1 = (ef_dd) { x->h0.hi + x->s.hi * len, 0.0 };
    }
}

/* The length of the part of [0, len] (len may be INFINITY) of the ray
 * org + t dir where every plane's value is < 0: 0 when none, INFINITY when
 * the ray stays inside forever. */
EF_INLINE double inside_length(const double *pl, int np, const double org[3], const double dir[3],
                            double len)
{
    int in, out;
    switch (clip_fast(pl, np, org, dir, len, &in, &out)) {
    case CLIP_EMPTY:
        return 0.0;
    case CLIP_UNSURE:
        return inside_length_exact(pl, np, org, dir, len);
    default:
        break;
    }
    crossing xi = { { 0, 0 }, { 0, 0 }, { 0, 0 } }, xo = xi;
    if (in >= 0)
        crossing_of(pl + 4 * in, org, dir, len, out < 0 && !isinf(len), &xi);
    if (out >= 0)
        crossing_of(pl + 4 * out, org, dir, len, 0, &xo);
    return bound_length(pl, in, &xi, out, &xo, len);
}

/* inside_length for a ray from the bound camera. */
EF_INLINE double inside_length_cam(const ef_fog_component *c, const double dir[3],
                                                double len)
{
    const int np = nplanes(c);
    const double *pl = c->arr, *cache = c->arr + 4 * np;
    int in, out;
    int v = c->p[P_SLAB] != 0.0 ? clip_slabs(cache, dir, len, &in, &out) : CLIP_UNSURE;
    if (v == CLIP_UNSURE)
        v = clip_fast_cam(pl, cache, np, dir, len, &in, &out);
    switch (v) {
    case CLIP_EMPTY:
        return 0.0;
    case CLIP_UNSURE:
        return inside_length_exact(pl, np, c->p + P_ORG, dir, len);
    default:
        break;
    }
    crossing xi = { { 0, 0 }, { 0, 0 }, { 0, 0 } }, xo = xi;
    if (in >= 0)
        crossing_cam(pl + 4 * in, cache + CACHE * in, dir, len, out < 0 && !isinf(len), &xi);
    if (out >= 0)
        crossing_cam(pl + 4 * out, cache + CACHE * out, dir, len, 0, &xo);
    return bound_length(pl, in, &xi, out, &xo, len);
}

EF_INLINE void tau_volume_one(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const double *rho = &c->p[P_RHO];
    tau[0] = tau[1] = tau[2] = 0.0;
    if (rho[0] == 0.0 && rho[1] == 0.0 && rho[2] == 0.0)
        return;
    const double *o = c->p + P_ORG;
    const double l = c->p[P_CAM] != 0.0 && r->org[0] == o[0] && r->org[1] == o[1] &&
                     r->org[2] == o[2] && isfinite(r->dir[0]) && isfinite(r->dir[1]) &&
                     isfinite(r->dir[2])
                   ? inside_length_cam(c, r->dir, r->dist)
                   : inside_length(c->arr, nplanes(c), r->org, r->dir, r->dist);
    if (l == 0.0)
        return;
    for (int i = 0; i < 3; ++i)
        tau[i] = rho[i] == 0.0 ? 0.0 : rho[i] * l;  /* 0 * inf stays 0 */
}

EF_MULTIVERSION static void tau_volume(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    tau_volume_one(c, r, tau);
}

EF_TAU_ADD(tau_add_volume, tau_volume)

/* The camera's part of every plane, as clip_fast and crossing_of compute it. */
static void bind_volume(ef_fog_component *c, const double org[3])
{
    const int np = nplanes(c);
    c->p[P_CAM] = 0.0;
    if (c->narr < (4 + CACHE) * np) {
        double *a = realloc(c->arr, (size_t) (4 + CACHE) * (size_t) np * sizeof *a);
        if (!a)
            return;                           /* unbound: still exact, just slower */
        c->arr = a;
        c->narr = (4 + CACHE) * np;
    }
    for (int k = 0; k < np; ++k) {
        const double *p = c->arr + 4 * k;
        double *ca = c->arr + 4 * np + CACHE * k;
        const double a0 = p[0] * org[0], a1 = p[1] * org[1], a2 = p[2] * org[2];
        ca[C_H0] = a0 + a1 + a2 + p[3];
        ca[C_EH] = (fabs(a0) + fabs(a1) + fabs(a2) + fabs(p[3])) * EPS_DOT + EPS_TINY;
        crossing x;
        crossing_of(p, org, org, 0.0, 0, &x);
        ca[C_HI] = x.h0.hi;
        ca[C_LO] = x.h0.lo;
        ca[C_ZAX] = ef_normal_axis(p);
        ca[C_AXIS] = ef_unit_axis(p);
        for (int i = C_ZAX + 1; i < CACHE; ++i)
            ca[i] = 0.0;
    }
    memcpy(c->p + P_ORG, org, 3 * sizeof *org);
    c->p[P_CAM] = 1.0;
    int slabs = np == 6;
    for (int k = 0; k < np && slabs; ++k) {
        const double *p = c->arr + 4 * k, *ca = c->arr + 4 * np + CACHE * k;
        slabs = ca[C_AXIS] == k / 2 && p[k / 2] == (k % 2 ? -1.0 : 1.0) &&
                fabs(ca[C_H0]) > ca[C_EH];
    }
    c->p[P_SLAB] = slabs;
}

/* ---- for the reference integrator ---- */

static int functionals_volume(const ef_fog_component *c, ef_fog_functional *out, int cap)
{
    const int n = nplanes(c);
    for (int i = 0; i < n && i < cap; ++i) {
        const double *p = c->arr + 4 * i;
        out[i] = (ef_fog_functional) { { p[0], p[1], p[2] }, p[3] };
    }
    return n;
}

/* The density jumps on every plane. */
static int features_volume(const ef_fog_component *c, ef_fog_feature *out, int cap)
{
    const int n = nplanes(c);
    for (int i = 0; i < n && i < cap; ++i)
        out[i] = (ef_fog_feature) { i, 0.0, 0.0 };
    return n;
}

/* rho strictly inside every plane, 0 on or outside any of them. */
static void density_volume(const ef_fog_component *c, const long double *v, long double out[3])
{
    int inside = 1;
    for (int i = 0; i < nplanes(c); ++i)
        inside &= v[i] < 0.0L;
    for (int k = 0; k < 3; ++k)
        out[k] = inside ? (long double) c->p[P_RHO + k] : 0.0L;
}

/* The sun in this constant-density convex volume (box or convex: planes
 * n.x + d < 0, n unit, in c->arr): inside, the sun's path out of the
 * volume is e(t) = min over the planes the sunlight leaves through
 * (n.l > 0) of -(n.x(t) + d) / (n.l), a lower envelope of lines in t, and
 * the fog is only there, so along the view segment's part inside,
 * [t_in, t_out], the exponent -rho (t - t_in + e(t)) is piecewise linear:
 * per piece rho L e^max(ends) phi(|difference|). With no plane facing the
 * sun the sun's path never leaves: no light. */
static void sun_planes(const ef_fog_component *c, const ef_sun_light *sl, const ef_ray *r,
                       const double *tv_in, double S[3])
{
    const int np = nplanes(c);
    S[0] = S[1] = S[2] = 0;
    if (np <= 0 || np > 64)
        return;
    double h0[64], sv[64], m[64];
    double tin = 0, tout = r->dist;
    for (int i = 0; i < np; ++i) {
        const double *P = c->arr + 4 * i;
        h0[i] = P[0] * r->org[0] + P[1] * r->org[1] + P[2] * r->org[2] + P[3];
        sv[i] = P[0] * r->dir[0] + P[1] * r->dir[1] + P[2] * r->dir[2];
        m[i] = P[0] * sl->dir[0] + P[1] * sl->dir[1] + P[2] * sl->dir[2];
        if (sv[i] == 0) {
            if (!(h0[i] < 0))
                return;   /* along the plane, outside it */
        } else if (sv[i] < 0) {
            tin = fmax(tin, -h0[i] / sv[i]);
        } else {
            tout = fmin(tout, -h0[i] / sv[i]);
        }
    }
    if (!(tin < tout))
        return;
    /* the length inside from the model's own optical depth, which clips in
     * double-double: a sliver's ends, subtracted in double, would lose it */
    double tv[3], len = tout - tin;
    if (tv_in)
        memcpy(tv, tv_in, sizeof tv);
    else
        tau_volume(c, r, tv);
    for (int ch = 0; ch < 3; ++ch)
        if (c->p[P_RHO + ch] > 0 && isfinite(tv[ch])) {
            len = tv[ch] / c->p[P_RHO + ch];
            break;
        }
    /* e(t) = min_i alpha_i + beta_i t over the planes the sun leaves by */
    int cur = -1;
    double ecur = INFINITY;
    for (int i = 0; i < np; ++i)
        if (m[i] > 0) {
            const double e = -(h0[i] + tin * sv[i]) / m[i];
            if (cur < 0 || e < ecur || (e == ecur && -sv[i] / m[i] < -sv[cur] / m[cur])) {
                cur = i;
                ecur = e;
            }
        }
    if (cur < 0)
        return;   /* no plane faces the sun: its light never gets in */
    /* pieces by their offset from tin (u): the kinks' t only place them,
     * so the lengths add up to len exactly */
    double t = tin, u = 0;
    while (u < len) {
        const double bc = -sv[cur] / m[cur];
        /* the next line to dip below the current one */
        double tn = INFINITY;
        int next = -1;
        for (int i = 0; i < np; ++i) {
            if (!(m[i] > 0) || i == cur)
                continue;
            const double bi = -sv[i] / m[i];
            if (!(bi < bc))
                continue;
            /* alpha_i + bi t = alpha_c + bc t, alpha = -h0 / m */
            const double tx = (-h0[i] / m[i] + h0[cur] / m[cur]) / (bc - bi);
            if (tx > t && tx < tn && tx - tin < len) {
                tn = tx;
                next = i;
            }
        }
        const double e0 = fmax(-(h0[cur] + t * sv[cur]) / m[cur], 0);
        const double un = next < 0 ? len : fmin(fmax(tn - tin, u), len);
        const double L = un - u, q = fabs(1 + bc);
        for (int ch = 0; ch < 3; ++ch) {
            const double rho = c->p[P_RHO + ch];
            if (!(rho > 0) || !sl->live[ch])
                continue;
            const double y0 = -rho * (u + e0);
            const double y1 = y0 - rho * (1 + bc) * L;
            const double e = isfinite(L) ? exp(y0 > y1 ? y0 : y1) : exp(y0);
            if (e == 0)
                continue;
            S[ch] += sl->w[ch] * ef_tau_phi(rho * L, q) * e;
        }
        if (next < 0)
            break;
        cur = next;
        t = tn;
        u = un;
    }
}

/* The convex hook (fog.h): the planes c->arr starts with. */
static int convex_volume(const ef_fog_component *c, double rho[3], const double **planes, int *n)
{
    for (int k = 0; k < 3; ++k)
        rho[k] = c->p[P_RHO + k];
    *planes = c->arr;
    *n = nplanes(c);
    return 1;
}

/* The sun hook: in closed form up to 64 planes (lit fog integrates more). */
static int sun_volume(const ef_fog_component *c, const ef_sun_light *sl, const ef_ray *r,
                      const double *tv, double S[3])
{
    if (nplanes(c) > 64)
        return 0;
    sun_planes(c, sl, r, tv, S);
    return 1;
}

const ef_fog_model ef_fog_box = { .name = "box", .keys = box_keys, .set = set_box,
                                  .finish = finish_box, .tau = tau_volume,
                                  .tau_add = tau_add_volume, .bind = bind_volume,
                                  .functionals = functionals_volume,
                                  .features = features_volume, .density = density_volume,
                                  .sun = sun_volume, .convex = convex_volume };
const ef_fog_model ef_fog_convex = { .name = "convex", .keys = convex_keys, .set = set_convex,
                                     .finish = finish_convex, .tau = tau_volume,
                                     .tau_add = tau_add_volume, .bind = bind_volume,
                                     .functionals = functionals_volume,
                                     .features = features_volume, .density = density_volume,
                                     .sun = sun_volume, .convex = convex_volume };
