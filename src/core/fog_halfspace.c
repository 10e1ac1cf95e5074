/* Half-space fog: fog below one plane, where A*x+B*y+C*z+D < 0 (the normal
 * points out of the fog). Three densities of the depth x = -h below the
 * plane (h = the normalised plane's value):
 *   halfspace         rho                      (Lengyel, seed 000)
 *   halfspace-linear  a x                      (Lengyel, seed 000)
 *   halfspace-smooth  D (1 - e^(-S x / D))     (Walker, seed 003)
 * Every closed form starts from the part of the segment inside the fog,
 * found from the exact plane values of ef_line_of, and never subtracts two
 * nearly equal quantities: lengths come from the end value that is exact
 * (-h0/s or h1/s), depth spans from |s| l, and Walker's divided difference
 * is replaced by an expm1 form with a series where that form would cancel. */
#include "exact.h"
#include "expneg.h"
#include "fog.h"

#include <math.h>
#include <string.h>

/* p[] layout, shared by the three models. */
enum {
    P_PLANE = 0,   /* n[3], d: normalised plane, scene units */
    P_DENS = 4,    /* density rho or D (/unit), or slope a (/unit^2), per channel */
    P_SHARP = 7,   /* Walker's S (/unit^2), per channel */
    P_LAMBDA = 10, /* Walker's S/D (/unit), per channel, where D > 0 and S > 0 */
};

static const char *const halfspace_keys[] = { "plane", "density", "visibility", NULL };
static const char *const linear_keys[] = { "plane", "slope", NULL };
static const char *const smooth_keys[] = { "plane", "density", "visibility", "sharpness", NULL };

/* Bits of c->seen, by position in the key lists above. */
enum { K_PLANE = 1u, K_DENSITY = 2u, K_SLOPE = 2u, K_VISIBILITY = 4u, K_SHARPNESS = 8u };

static int set_halfspace(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    switch (k) {
    case 0: return ef_fog_set_plane(c, "plane", val, c->p + P_PLANE, err);
    case 1: return ef_fog_set_density(c, "density", val, c->p + P_DENS, err);
    case 2: return ef_fog_set_visibility(c, "visibility", val, c->p + P_DENS, err);
    default: return ef_fog_set_density(c, "sharpness", val, c->p + P_SHARP, err);
    }
}

static int set_linear(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    if (k == 0)
        return ef_fog_set_plane(c, "plane", val, c->p + P_PLANE, err);
    return ef_fog_set_density(c, "slope", val, c->p + P_DENS, err);
}

static int need_plane(const ef_fog_component *c, const char *rest, ef_err *err)
{
    if (c->seen & K_PLANE)
        return 0;
    return ef_fail(err, "fog spec '%s': missing key 'plane' (write %s:plane=A,B,C,D%s; the fog "
                   "lies where A*x+B*y+C*z+D < 0)", c->spec, c->model->name, rest);
}

/* Exactly one of density= and visibility=, converted to per scene unit. */
static int need_density(ef_fog_component *c, const ef_fog_context *ctx, const char *rest,
                        ef_err *err)
{
    const unsigned given = c->seen & (K_DENSITY | K_VISIBILITY);
    if (!given)
        return ef_fail(err, "fog spec '%s': missing key 'density' (write %s:plane=A,B,C,D%s, "
                       "or visibility=V instead of density)", c->spec, c->model->name, rest);
    if (given == (K_DENSITY | K_VISIBILITY))
        return ef_fail(err, "fog spec '%s': keys 'density' and 'visibility' are both given "
                       "(give one of them)", c->spec);
    for (int i = 0; i < 3; ++i)
        c->p[P_DENS + i] = ef_fog_per_unit(ctx, c->p[P_DENS + i]);
    return 0;
}

static int finish_halfspace(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    static const char rest[] = ":density=RHO";
    return need_plane(c, rest, err) || need_density(c, ctx, rest, err) ? -1 : 0;
}

static int finish_linear(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    if (need_plane(c, ":slope=A", err))
        return -1;
    if (!(c->seen & K_SLOPE))
        return ef_fail(err, "fog spec '%s': missing key 'slope' (write %s:plane=A,B,C,D:slope=A, "
                       "the density per metre of depth, in 1/m^2)", c->spec, c->model->name);
    for (int i = 0; i < 3; ++i)
        c->p[P_DENS + i] = ef_fog_per_unit2(ctx, c->p[P_DENS + i]);
    return 0;
}

static int finish_smooth(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    static const char rest[] = ":density=D:sharpness=S";
    if (need_plane(c, rest, err) || need_density(c, ctx, rest, err))
        return -1;
    if (!(c->seen & K_SHARPNESS))
        return ef_fail(err, "fog spec '%s': missing key 'sharpness' (write %s:plane=A,B,C,D%s, "
                       "S = the density's slope at the plane, in 1/m^2)", c->spec,
                       c->model->name, rest);
    for (int i = 0; i < 3; ++i) {
        const double D = c->p[P_DENS + i];
        const double S = c->p[P_SHARP + i] = ef_fog_per_unit2(ctx, c->p[P_SHARP + i]);
        /* S = 0 or D = 0 is no fog at all (the density's limit). S/D may
         * overflow (the hard step D below the plane) or underflow (the
         * linear density S x): tau_smooth handles both. */
        c->p[P_LAMBDA + i] = D > 0 && S > 0 ? S / D : 0.0;
    }
    return 0;
}

/* The part of a segment inside the fog. */
typedef struct inside {
    double l;           /* its length */
    double xmin, xmax;  /* the depths at its ends, 0 <= xmin <= xmax */
    double dx;          /* xmax - xmin, without cancellation */
} inside;

enum { IN_NONE = 0, IN_FINITE, IN_INFINITE };

/* Finds the part of r's segment where h <= 0 with positive length.
 * IN_INFINITE: a sky ray that stays in the fog forever, at a depth that
 * grows or stays constant and > 0 (every density here is then > 0 far
 * enough along). One ef_line_of decides the common fog-free case. */
EF_INLINE int inside_part(const ef_fog_component *c, const ef_ray *r, inside *in)
{
    const double L = r->dist;
    if (!(L > 0))
        return IN_NONE;
    const ef_fog_functional f = { { c->p[0], c->p[1], c->p[2] }, c->p[3] };
    ef_line ln;
    ef_line_from_rate(ef_cam_h0(c, f.n, f.d, r->org), ef_cam_rate(c, f.n, r->dir), L, &ln);
    const double h0 = ln.h0, h1 = ln.h1, s = ln.s;
    /* Outside, or lying in the plane (h0 = h1 = 0): the density is 0 there. */
    if (h0 >= 0 && h1 >= 0)
        return IN_NONE;
    if (h0 <= 0 && h1 <= 0) {
        /* Infinite here means s < 0, or s == 0 with h0 < 0. */
        if (isinf(L))
            return IN_INFINITE;
        in->l = L;
        in->xmin = -ef_fmax(h0, h1);
        in->xmax = -ef_fmin(h0, h1);
        in->dx = fabs(s) * L;
        return IN_FINITE;
    }
    /* Crossing: the inside length is |h_in|/|s| from the inside end, which
     * is exact, instead of L minus the crossing distance. fmin absorbs a
     * last-bit excess over L (and an s that underflowed to 0). */
    const double hin = h0 < 0 ? h0 : h1;
    const double l = ef_fmin(L, fabs(hin) / fabs(s));
    if (isinf(l))
        return IN_INFINITE;
    in->l = l;
    in->xmin = 0.0;
    in->xmax = -hin;
    in->dx = -hin;
    return IN_FINITE;
}

EF_INLINE void tau_halfspace_one(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    inside in = { 0.0, 0.0, 0.0, 0.0 };
    const int k = inside_part(c, r, &in);
    for (int i = 0; i < 3; ++i) {
        const double rho = c->p[P_DENS + i];
        if (k == IN_NONE || rho == 0.0)
            tau[i] = 0.0;
        else
            tau[i] = k == IN_INFINITE ? INFINITY : rho * in.l;
    }
}

EF_MULTIVERSION static void tau_halfspace(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    tau_halfspace_one(c, r, tau);
}

/* The density at the mean depth times l: Lengyel's both-inside
 * a L (x0 + x1)/2 and his crossing a h_in^2/(2|s|) = a l |h_in|/2 in one. */
EF_INLINE void tau_linear_one(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    inside in = { 0.0, 0.0, 0.0, 0.0 };
    const int k = inside_part(c, r, &in);
    for (int i = 0; i < 3; ++i) {
        const double a = c->p[P_DENS + i];
        if (k == IN_NONE || a == 0.0)
            tau[i] = 0.0;
        else
            tau[i] = k == IN_INFINITE ? INFINITY : a * (0.5 * (in.xmin + in.xmax)) * in.l;
    }
}

EF_MULTIVERSION static void tau_linear(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    tau_linear_one(c, r, tau);
}

/* psi(b)/b for 0 <= b < 1, where psi(b) = 1 - (1 - e^-b)/b: the direct
 * form cancels there, so the alternating series
 * sum_{k>=1} (-1)^(k+1) b^(k-1)/(k+1)! is used; 18 terms leave < 1e-18 at
 * b = 1 (a few ulps in all, measured against a long double series). */
static double psi_over_b(double b)
{
    static const double inv_fact[] = {
        1.0 / 2,
        1.0 / 6,
        1.0 / 24,
        1.0 / 120,
        1.0 / 720,
        1.0 / 5040,
        1.0 / 40320,
        1.0 / 362880,
        1.0 / 3628800,
        1.0 / 39916800,
        1.0 / 479001600,
        1.0 / 6227020800.0,
        1.0 / 87178291200.0,
        1.0 / 1307674368000.0,
        1.0 / 20922789888000.0,
        1.0 / 355687428096000.0,
        1.0 / 6402373705728000.0,
        1.0 / 121645100408832000.0,
    };
    const int n = (int) (sizeof inv_fact / sizeof inv_fact[0]);
    double sum = inv_fact[n - 1];
    for (int k = n - 2; k >= 0; --k)
        sum = inv_fact[k] - b * sum;
    return sum;
}

/* Walker's integral over the inside part, without his divided difference.
 * With lambda = S/D, a = lambda xmin, b = lambda dx:
 *   tau = D l [1 - e^-a phi(b)] = l [D (1 - e^-a) + D e^-a psi(b)],
 * phi(b) = (1 - e^-b)/b, psi = 1 - phi: two non-negative terms. Below 1,
 * each term is written with S instead of D/lambda,
 *   D (1 - e^-a) = S xmin (1 - e^-a)/a,   D psi(b) = S dx psi(b)/b,
 * so S -> 0 gives S l (xmin + dx/2) (the linear model) even when S/D
 * underflows; at and above 1, S -> inf (S/D may overflow) gives D l less
 * the transition layer. Each term is at most D: no spurious overflow.
 * One channel of density D and sharpness S, given a, b and their
 * exponentials ea = e^-a, eb = e^-b (eb only read when b >= 1). */
EF_INLINE double smooth_sum(double D, double S, const inside *in, double a, double b, double ea,
                            double eb)
{
    /* From 1 on, 1 - e^-x as 1 - ef_exp_neg(x): no cancellation there
     * (e^-x <= 1/e), within about an ulp, without libm's calls. */
    const double t1 = a >= 1.0 ? D * (1.0 - ea)
                               : S * in->xmin * (a > 0 ? -expm1(-a) / a : 1.0);
    const double t2 = ea * (b >= 1.0 ? D * (1.0 - (1.0 - eb) / b)
                                     : S * in->dx * psi_over_b(b));
    return (t1 + t2) * in->l;
}

/* smooth_sum per channel along r (grey fog summed once). */
EF_INLINE void tau_smooth_one(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    inside in = { 0.0, 0.0, 0.0, 0.0 };
    const int k = inside_part(c, r, &in);
    for (int i = 0; i < 3; ++i) {
        const double D = c->p[P_DENS + i], S = c->p[P_SHARP + i], lam = c->p[P_LAMBDA + i];
        if (i > 0 && D == c->p[P_DENS + i - 1] && S == c->p[P_SHARP + i - 1]) {
            tau[i] = tau[i - 1];              /* grey fog: the same sum, once */
            continue;
        }
        if (k == IN_NONE || !(D > 0 && S > 0)) {
            tau[i] = 0.0;
            continue;
        }
        if (k == IN_INFINITE) {
            tau[i] = INFINITY;
            continue;
        }
        /* The guards keep an overflowed lambda from 0 * inf. */
        const double a = in.xmin > 0 ? lam * in.xmin : 0.0;
        const double b = in.dx > 0 ? lam * in.dx : 0.0;
        tau[i] = smooth_sum(D, S, &in, a, b, ef_exp_neg(a), b >= 1.0 ? ef_exp_neg(b) : 0.0);
    }
}

EF_MULTIVERSION static void tau_smooth(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    tau_smooth_one(c, r, tau);
}

EF_TAU_ADD(tau_add_halfspace, tau_halfspace)
EF_TAU_ADD(tau_add_linear, tau_linear)
EF_TAU_ADD(tau_add_smooth_each, tau_smooth)
/* tau_add for halfspace-smooth: grey fog (one density and sharpness) a
 * span at a time, so that the exponentials of a span's rays run in vector
 * lanes (ef_exp_neg of every a and b, used where tau_smooth_one uses
 * them); the same operations per ray, so the same bits. Coloured fog
 * goes ray by ray. */
#define SMOOTH_SPAN 32
EF_MULTIVERSION static void tau_add_smooth(const ef_fog_component *c, const ef_ray *r, int n,
                                           double (*acc)[3])
{
    const double D = c->p[P_DENS], S = c->p[P_SHARP], lam = c->p[P_LAMBDA];
    const int grey = D == c->p[P_DENS + 1] && S == c->p[P_SHARP + 1] &&
                     D == c->p[P_DENS + 2] && S == c->p[P_SHARP + 2];
    if (!grey || !(D > 0 && S > 0)) {
        tau_add_smooth_each(c, r, n, acc);
        return;
    }
    for (int j0 = 0; j0 < n; j0 += SMOOTH_SPAN) {
        const int m = n - j0 < SMOOTH_SPAN ? n - j0 : SMOOTH_SPAN;
        inside in[SMOOTH_SPAN];
        int kind[SMOOTH_SPAN];
        double a[SMOOTH_SPAN], b[SMOOTH_SPAN], ea[SMOOTH_SPAN], eb[SMOOTH_SPAN];
        for (int i = 0; i < m; ++i) {
            in[i] = (inside) { 0.0, 0.0, 0.0, 0.0 };
            kind[i] = inside_part(c, &r[j0 + i], &in[i]);
            a[i] = in[i].xmin > 0 ? lam * in[i].xmin : 0.0;
            b[i] = in[i].dx > 0 ? lam * in[i].dx : 0.0;
        }
        for (int i = 0; i < m; ++i) {
            ea[i] = ef_exp_neg(a[i]);
            eb[i] = ef_exp_neg(b[i]);
        }
        for (int i = 0; i < m; ++i) {
            double tau = 0.0;
            if (kind[i] == IN_INFINITE) {
                tau = INFINITY;
            } else if (kind[i] != IN_NONE) {
                tau = smooth_sum(D, S, &in[i], a[i], b[i], ea[i], eb[i]);
            }
            for (int k = 0; k < 3; ++k)
                acc[j0 + i][k] += tau;
        }
    }
}

/* The plane's value at the camera, cached for its rays (exact.h). */
static void bind_plane(ef_fog_component *c, const double org[3])
{
    ef_cam_bind(c, c->p + P_PLANE, c->p[P_PLANE + 3], org);
}

static int one_plane(const ef_fog_component *c, ef_fog_functional *out, int cap)
{
    if (cap >= 1) {
        for (int i = 0; i < 3; ++i)
            out[0].n[i] = c->p[P_PLANE + i];
        out[0].d = c->p[P_PLANE + 3];
    }
    return 1;
}

/* The density jumps (halfspace) or kinks (halfspace-linear) at the plane. */
static int kink_at_plane(const ef_fog_component *c, ef_fog_feature *out, int cap)
{
    (void) c;
    if (cap >= 1)
        out[0] = (ef_fog_feature) { 0, 0.0, 0.0 };
    return 1;
}

/* Walker's density kinks at the plane and saturates over a depth D/S
 * below it: one feature per distinct channel scale (scale 0 when D/S is
 * not a usable length, or when no channel has fog). */
static int smooth_features(const ef_fog_component *c, ef_fog_feature *out, int cap)
{
    double scales[3];
    int n = 0;
    for (int i = 0; i < 3; ++i) {
        if (!(c->p[P_DENS + i] > 0 && c->p[P_SHARP + i] > 0))
            continue;
        double sc = c->p[P_DENS + i] / c->p[P_SHARP + i];
        if (!(sc > 0) || !isfinite(sc))
            sc = 0.0;
        int dup = 0;
        for (int j = 0; j < n; ++j)
            dup |= scales[j] == sc;
        if (!dup)
            scales[n++] = sc;
    }
    if (n == 0)
        scales[n++] = 0.0;
    for (int j = 0; j < n && j < cap; ++j)
        out[j] = (ef_fog_feature) { 0, 0.0, scales[j] };
    return n;
}

/* The densities straight from their definitions, v[0] = h = -depth. */
static void density_halfspace(const ef_fog_component *c, const long double *v,
                              long double out[3])
{
    for (int i = 0; i < 3; ++i)
        out[i] = v[0] < 0 ? (long double) c->p[P_DENS + i] : 0.0L;
}

static void density_linear(const ef_fog_component *c, const long double *v, long double out[3])
{
    const long double x = -v[0];
    for (int i = 0; i < 3; ++i) {
        const long double a = c->p[P_DENS + i];
        out[i] = x > 0 && a > 0 ? a * x : 0.0L;
    }
}

static void density_smooth(const ef_fog_component *c, const long double *v, long double out[3])
{
    const long double x = -v[0];
    for (int i = 0; i < 3; ++i) {
        const long double D = c->p[P_DENS + i], S = c->p[P_SHARP + i];
        /* D (1 - e^(-S x/D)); expm1l keeps it exact near the plane. */
        out[i] = x > 0 && D > 0 && S > 0 ? -D * expm1l(-(S * x) / D) : 0.0L;
    }
}

/* The sun in this half-space fog, of any of the three densities sigma(X) of
 * the depth X = -h below the plane (h = n.x + d, n unit, fog where h < 0:
 * constant, linear, Walker's smooth): from x the sun's path in the fog has
 * optical depth tau_sun(x) = Sigma(X) / (n.l), Sigma the density's
 * integral from the plane down, so along the view ray the exponent
 * E(t) = -(tau_v(0, t) + tau_sun(x(t))) has dE/dt = -sigma (1 - s / (n.l))
 * (s = n.u) wherever there is fog, and 0 where there is none:
 *   S = albedo p E int sigma e^E dt = albedo p E (e^E(0) - e^E(D)) / q,
 * q = 1 - s / (n.l), written as tau_v e^max(E(0), E(D)) phi(tau_v |q|)
 * (no difference of large terms; q -> 0 tends to tau_v e^E). Both ends'
 * E come from the model's own closed-form optical depths (the view
 * segment, and the sun's ray from each end). With n.l <= 0 the sun never
 * leaves the fog: no light. */
static void sun_plane(const ef_fog_component *c, const ef_sun_light *sl, const ef_ray *r,
                      const double *tv_in, int constant, double S[3])
{
    const double *n = c->p;
    const double nl = n[0] * sl->dir[0] + n[1] * sl->dir[1] + n[2] * sl->dir[2];
    const double sv = n[0] * r->dir[0] + n[1] * r->dir[1] + n[2] * r->dir[2];
    S[0] = S[1] = S[2] = 0;
    if (!(nl > 0))
        return;
    double tv[3], ta[3], tb[3] = { 0, 0, 0 };
    if (tv_in)
        memcpy(tv, tv_in, sizeof tv);
    else
        c->model->tau(c, r, tv);
    if (constant) {
        /* constant: Sigma(X) = rho X, from the plane values at the ends */
        const double h0 = n[0] * r->org[0] + n[1] * r->org[1] + n[2] * r->org[2] + n[3];
        const double hb = isfinite(r->dist) ? h0 + sv * r->dist : 0;
        for (int ch = 0; ch < 3; ++ch) {
            ta[ch] = h0 < 0 ? c->p[P_DENS + ch] * -h0 / nl : 0;
            tb[ch] = hb < 0 ? c->p[P_DENS + ch] * -hb / nl : 0;
        }
    } else {
        ef_ray sun = { { sl->dir[0], sl->dir[1], sl->dir[2] }, INFINITY, INFINITY,
                       { r->org[0], r->org[1], r->org[2] } };
        c->model->tau(c, &sun, ta);
        if (isfinite(r->dist)) {
            for (int k = 0; k < 3; ++k)
                sun.org[k] = r->org[k] + r->dist * r->dir[k];
            c->model->tau(c, &sun, tb);
        }
    }
    const double q = fabs(1 - sv / nl);
    for (int ch = 0; ch < 3; ++ch) {
        if (!(tv[ch] > 0) || !sl->live[ch])
            continue;
        const double ya = -ta[ch], yb = -tv[ch] - tb[ch];
        const double e = exp(ya > yb ? ya : yb);
        S[ch] = e == 0 ? 0 : sl->w[ch] * ef_tau_phi(tv[ch], q) * e;
    }
}

/* The sun hooks of the three densities (the constant one from its plane
 * values, the others from their optical depths along the sun's rays). */
static int sun_halfspace(const ef_fog_component *c, const ef_sun_light *sl, const ef_ray *r,
                         const double *tv, double S[3])
{
    sun_plane(c, sl, r, tv, 1, S);
    return 1;
}

static int sun_halfspace_ray(const ef_fog_component *c, const ef_sun_light *sl,
                             const ef_ray *r, const double *tv, double S[3])
{
    sun_plane(c, sl, r, tv, 0, S);
    return 1;
}



const ef_fog_model ef_fog_halfspace = {
    .name = "halfspace", .keys = halfspace_keys, .set = set_halfspace,
    .finish = finish_halfspace, .tau = tau_halfspace, .functionals = one_plane,
    .tau_add = tau_add_halfspace, .bind = bind_plane,
    .features = kink_at_plane, .density = density_halfspace, .sun = sun_halfspace,
};
const ef_fog_model ef_fog_halfspace_linear = {
    .name = "halfspace-linear", .keys = linear_keys, .set = set_linear,
    .finish = finish_linear, .tau = tau_linear, .functionals = one_plane,
    .tau_add = tau_add_linear, .bind = bind_plane,
    .features = kink_at_plane, .density = density_linear, .sun = sun_halfspace_ray,
};
const ef_fog_model ef_fog_halfspace_smooth = {
    .name = "halfspace-smooth", .keys = smooth_keys, .set = set_halfspace,
    .finish = finish_smooth, .tau = tau_smooth, .functionals = one_plane,
    .tau_add = tau_add_smooth, .bind = bind_plane,
    .features = smooth_features, .density = density_smooth, .sun = sun_halfspace_ray,
};
