/* Unbounded exponential height fog (Unreal's exponential height fog, Inigo
 * Quilez's fog): sigma = rho e^(-k (height - base)), height measured along
 * the up axis. Its optical depth has a closed form on every segment and on
 * up-going rays to infinity; falloff 0 is exactly uniform (exp) fog.
 *
 * p[0..2] = rho per channel, p[3] = falloff k, p[4] = base (scene units);
 * rho and k arrive per metre and finish() converts them per scene unit. */
#include "exact.h"
#include "fog.h"

#include <float.h>
#include <math.h>

enum { K_DENSITY, K_VISIBILITY, K_FALLOFF, K_BASE };

static const char *const height_keys[] = { "density", "visibility", "falloff", "base", NULL };

static int set_height(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    switch (k) {
    case K_DENSITY:
        return ef_fog_set_density(c, "density", val, c->p, err);
    case K_VISIBILITY:
        return ef_fog_set_visibility(c, "visibility", val, c->p, err);
    case K_FALLOFF:
        if (ef_parse_numbers(val, &c->p[3], 1) || c->p[3] < 0)
            return ef_fail(err, "fog spec '%s': falloff='%s' is not a number >= 0 (per metre; "
                           "0 is uniform fog)", c->spec, val);
        return 0;
    default:
        if (ef_parse_numbers(val, &c->p[4], 1))
            return ef_fail(err, "fog spec '%s': base='%s' is not a number (the height, in scene "
                           "units, where the density is the one given)", c->spec, val);
        return 0;
    }
}

static int finish_height(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    const unsigned given = c->seen & ((1u << K_DENSITY) | (1u << K_VISIBILITY));
    if (!given)
        return ef_fail(err, "fog spec '%s': missing density (write height:density=D:falloff=K"
                       "[:base=H] or visibility=V instead of density)", c->spec);
    if (given == ((1u << K_DENSITY) | (1u << K_VISIBILITY)))
        return ef_fail(err, "fog spec '%s': give density or visibility, not both", c->spec);
    if (!(c->seen & (1u << K_FALLOFF)))
        return ef_fail(err, "fog spec '%s': missing falloff (write height:density=D:falloff=K"
                       "[:base=H], K per metre; falloff=0 is uniform fog)", c->spec);
    for (int i = 0; i < 3; ++i)
        c->p[i] = ef_fog_per_unit(ctx, c->p[i]);
    c->p[3] = ef_fog_per_unit(ctx, c->p[3]);
    return 0;
}

static ef_fog_functional height_functional(const ef_fog_component *c)
{
    return (ef_fog_functional) { { c->up[0], c->up[1], c->up[2] }, -c->p[4] };
}

/* e^(-k u) for a double-double height u, with x = -k u: the product is kept
 * exact, so a large exponent (k u ~ 700) does not cost its ~|k u| ulp. */
EF_INLINE double exp_neg(double k, ef_dd u, double *x)
{
    ef_dd p = ef_two_prod(k, u.hi);
    *x = -p.hi;
    if (!(fabs(p.hi) < 1000))       /* saturated (or infinite): no correction */
        return exp(*x);
    p.lo += k * u.lo;
    return exp(*x) * (1 - p.lo);
}

/* rho * m * e for rho, m > 0 and e = e^x (x possibly +-INFINITY). When the
 * direct product leaves the normal range, logarithms give INFINITY or 0
 * instead of inf * 0 (keeping ~|x| ulp there). */
EF_INLINE double scaled_exp(double rho, double m, double e, double x)
{
    if (e >= DBL_MIN && e <= DBL_MAX) {
        const double t = rho * m * e;
        if (t >= DBL_MIN && t <= DBL_MAX)
            return t;
    }
    const double y = x + log(rho) + log(m);
    /* inf - inf only when m underflowed against an overflowing exponent,
     * k near DBL_MAX: the length factor vanished, so does tau. */
    return isnan(y) ? 0.0 : exp(y);
}

/* Segment: tau = rho L e^(-k u_low) phi(k |s| L), phi(b) = -expm1(-b)/b,
 * u_low the lower end's height. The length factor m = L phi(b) is taken as
 * L phi(b) while b is small (so b -> 0 tends to L exactly, and a tiny k|s|
 * cannot spoil it) and as (1 - e^-b)/(k|s|) beyond (so b = inf is 1/(k|s|)).
 * Sky: only an up-going ray with k > 0 leaves the fog; its limit is
 * rho e^(-k u0)/(k s). Heights are the functional's double-double values
 * (ef_line_of's before rounding). */
EF_INLINE void tau_height_one(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    const ef_fog_functional f = height_functional(c);
    const double k = c->p[3], L = r->dist;
    const ef_dd u0 = ef_cam_h0(c, f.n, f.d, r->org), sd = ef_cam_rate(c, f.n, r->dir);
    const double s = sd.hi + sd.lo;
    double x = 0.0;
    if (isinf(L)) {
        const int leaves = s > 0 && k > 0;
        const double q = k * s, e = leaves ? exp_neg(k, u0, &x) : 0.0;
        for (int i = 0; i < 3; ++i) {
            const double rho = c->p[i];
            if (rho == 0)
                tau[i] = 0;
            else if (!leaves)
                tau[i] = INFINITY;
            else if (q >= DBL_MIN)
                tau[i] = scaled_exp(rho, 1 / q, e, x);
            else /* k s underflows: its logarithm from the factors */
                tau[i] = exp(x + log(rho) - log(k) - log(s));
        }
        return;
    }
    if (!(L > 0)) {
        tau[0] = tau[1] = tau[2] = 0;
        return;
    }
    const double as = fabs(s), b = k * (as * L);
    double m;
    if (b == 0)
        m = L;
    else if (b <= 1)
        m = L * (-expm1(-b) / b);
    else
        m = -expm1(-b) / (k * as);
    const double e = exp_neg(k, s >= 0 ? u0 : ef_dd_affine(u0, sd, L), &x);
    for (int i = 0; i < 3; ++i)
        tau[i] = c->p[i] == 0 ? 0 : scaled_exp(c->p[i], m, e, x);
}

EF_MULTIVERSION static void tau_height(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    tau_height_one(c, r, tau);
}

EF_TAU_ADD(tau_add_height, tau_height)

/* The camera's height, cached for its rays (exact.h). */
static void bind_height(ef_fog_component *c, const double org[3])
{
    const ef_fog_functional f = height_functional(c);
    ef_cam_bind(c, f.n, f.d, org);
}

static int functionals_height(const ef_fog_component *c, ef_fog_functional *out, int cap)
{
    if (cap > 0)
        out[0] = height_functional(c);
    return 1;
}

/* The density varies on the scale 1/k around the base; falloff 0 has no
 * feature at all. */
static int features_height(const ef_fog_component *c, ef_fog_feature *out, int cap)
{
    if (!(c->p[3] > 0))
        return 0;
    if (cap > 0)
        out[0] = (ef_fog_feature) { 0, 0.0, 1 / c->p[3] };
    return 1;
}

/* Straight from the definition; the limits at v = +-inf follow from expl
 * (k = 0 is handled first so 0 * inf never occurs). */
static void density_height(const ef_fog_component *c, const long double *v, long double out[3])
{
    const long double k = c->p[3];
    for (int i = 0; i < 3; ++i) {
        const long double rho = c->p[i];
        if (rho == 0)
            out[i] = 0;
        else if (k == 0)
            out[i] = rho;
        else
            out[i] = rho * expl(-k * v[0]);
    }
}

/* Exponential strata (lit fog's planet sun): falloff > 0. */
static int strata_height(const ef_fog_component *c, double rho[3], double *k, double *base)
{
    if (!(c->p[3] > 0))
        return 0;
    for (int ch = 0; ch < 3; ++ch)
        rho[ch] = c->p[ch];
    *k = c->p[3];
    *base = c->p[4];
    return 1;
}

/* The sun in this exponential height fog (k > 0), with its own extinction
 * in the fog: T_sun(x) = e^-(sigma(x) / (k l_up)), and along the view ray
 *   S = albedo p E tau_v e^-min(A, B) phi(|B - A|),
 *   A = sigma(C) / (k l_up), B = tau_v + sigma(P) / (k l_up),
 * phi(x) = -expm1(-x) / x and B - A = tau_v (1 - mu / l_up) exactly (mu the
 * view ray's up component), so no difference of large terms is formed. */
static int sun_height(const ef_fog_component *c, const ef_sun_light *sl, const ef_ray *r,
                      const double *tv_in, double S[3])
{
    const double k = c->p[3];
    if (!(k > 0))
        return 0;
    double tvb[3];
    const double *tv = tv_in;
    if (!tv) {
        tau_height(c, r, tvb);
        tv = tvb;
    }
    const double lu = sl->dir[0] * c->up[0] + sl->dir[1] * c->up[1] + sl->dir[2] * c->up[2];
    const double mu = r->dir[0] * c->up[0] + r->dir[1] * c->up[1] + r->dir[2] * c->up[2];
    S[0] = S[1] = S[2] = 0;
    if (!(lu > 0))
        return 1;   /* at or below the horizon, the sun crosses unbounded fog */
    double sc[3], sp[3] = { 0, 0, 0 };
    /* the densities at the ends, rho e^-(k (height - base)), in double
     * (one exponential each: the model's own density works in long double
     * for the reference) */
    const double hc = c->up[0] * r->org[0] + c->up[1] * r->org[1] + c->up[2] * r->org[2] - c->p[4];
    const double ec = exp(-k * hc);
    double ep = 0;
    if (isfinite(r->dist))
        ep = exp(-k * (hc + r->dist * mu));
    else if (!(mu > 0))
        ep = INFINITY;
    for (int ch = 0; ch < 3; ++ch) {
        sc[ch] = c->p[ch] == 0 ? 0 : c->p[ch] * ec;
        sp[ch] = c->p[ch] == 0 ? 0 : c->p[ch] * ep;
    }
    const double q = fabs(1 - mu / lu);
    double me = 0;   /* m e^-min(A, B) of channel last (-1: none yet) */
    int last = -1;
    for (int ch = 0; ch < 3; ++ch) {
        if (!(tv[ch] > 0) || !sl->live[ch])
            continue;
        /* grey fog: the same densities, the same factor */
        if (!(last >= 0 && c->p[ch] == c->p[last] && tv[ch] == tv[last])) {
            last = ch;
            const double A = sc[ch] / (k * lu), B = tv[ch] + sp[ch] / (k * lu);
            const double e = exp(-(A < B ? A : B));
            me = e == 0 ? 0 : ef_tau_phi(tv[ch], q) * e;
        }
        S[ch] = me == 0 ? 0 : sl->w[ch] * me;
    }
    return 1;
}

const ef_fog_model ef_fog_height = { .name = "height", .keys = height_keys, .set = set_height,
                                     .finish = finish_height, .tau = tau_height,
                                     .tau_add = tau_add_height, .bind = bind_height,
                                     .functionals = functionals_height,
                                     .features = features_height, .density = density_height,
                                     .strata = strata_height, .sun = sun_height, .uses_up = 1 };
