/* The reference integrator itself, on densities whose integrals are known
 * in closed form from calculus (not from the project's closed forms):
 * polynomials, features far narrower than the segment, Walker's transition
 * at extreme sharpness, exponential tails to infinity, cameras far from the
 * origin. */
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include "ref.h"
#include "tassert.h"

typedef long double (*fn1)(const void *p, long double v);

/* A one-functional density with the same value on all three channels. */
typedef struct one {
    fn1 f;
    const void *p;
} one;

static void one_density(const void *ctx, const long double *v, long double out[3])
{
    const one *o = ctx;
    out[0] = out[1] = out[2] = o->f(o->p, v[0]);
}

static long double integrate(fn1 f, const void *p, const ef_fog_functional *fn, int nfeat,
                             const ef_fog_feature *feat, const double org[3], const double dir[3],
                             double len, ef_ref_stats *st)
{
    one o = { f, p };
    ef_ref_density d = { .nf = 1, .f = fn, .nfeat = nfeat, .feat = feat, .density = one_density, .ctx = &o };
    long double tau[3];
    assert_int_equal(ef_ref_integrate(&d, org, dir, len, tau, st), 0);
    assert_true(tau[0] == tau[1] && tau[1] == tau[2]);
    return tau[0];
}

static void assert_rel(long double got, long double want, long double rel)
{
    if (!(fabsl(got - want) <= rel * fabsl(want))) {
        print_error("got %.21Lg, want %.21Lg (rel %Lg)\n", got, want, rel);
        fail();
    }
}

static const ef_fog_functional X = { { 1, 0, 0 }, 0 };
static const double O[3] = { 0, 0, 0 }, EX[3] = { 1, 0, 0 };

static long double power(const void *p, long double v)
{
    return powl(v, *(const int *) p);
}

static void test_polynomials(void **state)
{
    (void) state;
    /* Gauss 7 is exact to degree 13, so K = G there and one interval does;
     * beyond, bisection runs until the two agree. */
    for (int n = 0; n <= 30; ++n) {
        ef_ref_stats st;
        const long double got = integrate(power, &n, &X, 0, NULL, O, EX, 1.0, &st);
        assert_rel(got, 1.0L / (n + 1), 1e-17L);
        if (n <= 13)
            assert_int_equal(st.intervals, 1);
        assert_int_equal(st.unconverged, 0);
    }
}

typedef struct bump {
    long double c, w;
} bump;

static long double gauss(const void *p, long double v)
{
    const bump *b = p;
    const long double z = (v - b->c) / b->w;
    return expl(-z * z);
}

static void test_narrow_bump(void **state)
{
    (void) state;
    /* A bump 1e-9 wide on a segment 1000 long integrates to w sqrt(pi). Its
     * feature (centre, scale) makes the integrator split around it; without
     * it, all 15 first nodes miss the bump and the integral looks like 0,
     * which is why models must declare their features. The bump sits where
     * its functional is 0, as a density's features do at a plane. */
    const bump b = { 0, 1e-9L };
    const ef_fog_feature f = { 0, 0, 1e-9 };
    const double org[3] = { -333.3333333, 0, 0 };
    const long double want = 1e-9L * sqrtl(acosl(-1.0L));
    assert_rel(integrate(gauss, &b, &X, 1, &f, org, EX, 1000.0, NULL), want, 1e-14L);
    assert_true(integrate(gauss, &b, &X, 0, NULL, org, EX, 1000.0, NULL) < 1e-3L * want);
}

typedef struct walker {
    long double D, S;
} walker;

/* Walker's density at depth x = -v below the plane v = 0. */
static long double walker_density(const void *p, long double v)
{
    const walker *w = p;
    return v >= 0 ? 0 : w->D * -expm1l(-w->S * -v / w->D);
}

static void test_walker_extremes(void **state)
{
    (void) state;
    /* Straight down from depth -1 to +1: integral over x in [0, 1] of
     * D(1 - e^(-S x / D)) = D - D^2 (1 - e^(-S/D)) / S. */
    const ef_fog_functional Y = { { 0, 1, 0 }, 0 };
    const double org[3] = { 0, 1, 0 }, down[3] = { 0, -1, 0 };
    const double S[] = { 1e-9, 1e-3, 1, 1e3, 1e9, 1e12 };
    for (size_t i = 0; i < sizeof S / sizeof S[0]; ++i) {
        const walker w = { 1, S[i] };
        const ef_fog_feature f = { 0, 0, 1.0 / S[i] };
        const long double Sl = S[i];
        /* 1 - (1 - e^-S)/S, by its series where that difference cancels. */
        const long double want = Sl < 1e-3L ? Sl / 2 - Sl * Sl / 6 + Sl * Sl * Sl / 24
                                            : 1 - (-expm1l(-Sl)) / Sl;
        assert_rel(integrate(walker_density, &w, &Y, 1, &f, org, down, 2.0, NULL), want, 1e-14L);
    }
}

typedef struct expo {
    long double rho, k;
} expo;

static long double exponential(const void *p, long double v)
{
    const expo *e = p;
    return e->rho * expl(-e->k * v);
}

static void test_exponential_to_infinity(void **state)
{
    (void) state;
    /* Height fog up to infinity: rho e^(-k h0) / (k mu). */
    const ef_fog_functional Y = { { 0, 1, 0 }, 0 };
    const double mu = 0.6, dir[3] = { 0.8, mu, 0 };
    const double org[3] = { 3, 2, -1 };
    const double ks[] = { 1e-12, 1e-3, 1, 1e3 };
    for (size_t i = 0; i < sizeof ks / sizeof ks[0]; ++i) {
        const expo e = { 0.25, ks[i] };
        const ef_fog_feature f = { 0, 0, 1.0 / ks[i] };
        const long double want = 0.25L * expl(-(long double) ks[i] * 2) / ((long double) ks[i] * mu);
        assert_rel(integrate(exponential, &e, &Y, 1, &f, org, dir, INFINITY, NULL), want, 1e-13L);
    }
    /* Down-going: the density grows without bound, tau is infinite. */
    const expo e = { 0.25, 0.1 };
    const ef_fog_feature f = { 0, 0, 10 };
    const double down[3] = { 0.8, -0.6, 0 };
    assert_true(isinf(integrate(exponential, &e, &Y, 1, &f, org, down, INFINITY, NULL)));
}

static long double below(const void *p, long double v)
{
    (void) p;
    return v < 0 ? 1 : 0;
}

static void test_far_from_origin(void **state)
{
    (void) state;
    /* A camera 1e7 from the origin, 1 above the plane y = 0, going down at
     * 3-4-5: it enters after 1.25 and stays in for 8.75 of its 10. */
    const ef_fog_functional Y = { { 0, 1, 0 }, 0 };
    const ef_fog_feature f = { 0, 0, 0 };
    const double org[3] = { 1e7, 1, -1e7 }, dir[3] = { 0.6, -0.8, 0 };
    assert_rel(integrate(below, NULL, &Y, 1, &f, org, dir, 10.0, NULL), 8.75L, 1e-15L);
    /* The plane itself 1e7 away: y = 1e7 - 1 with the camera at 1e7. */
    const ef_fog_functional Yf = { { 0, 1, 0 }, -(1e7 - 1) };
    const double org2[3] = { 5, 1e7, 5 };
    assert_rel(integrate(below, NULL, &Yf, 1, &f, org2, dir, 10.0, NULL), 8.75L, 1e-15L);
    /* Grazing: |s| = 1e-12 from 1e-13 above the plane; enters after 0.1. */
    const double graze[3] = { 1, -1e-12, 0 };
    const double org3[3] = { 0, 1e-13, 0 };
    assert_rel(integrate(below, NULL, &Y, 1, &f, org3, graze, 1.0, NULL), 0.9L, 1e-12L);
}

static void test_zero_and_constant(void **state)
{
    (void) state;
    int zero = 0;
    assert_true(integrate(power, &zero, &X, 0, NULL, O, EX, 0.0, NULL) == 0);
    /* Constant density at infinity diverges. */
    assert_true(isinf(integrate(power, &zero, &X, 0, NULL, O, EX, INFINITY, NULL)));
}

/* ---- Periodic lattices: seams the integrator must split at ----------------
 *
 * The densities below are sums over the three world axes of a per-axis term
 * that repeats with period P from phase phi: term_a(v_a) is a polynomial of
 * the cell fraction u = frac((v_a - phi) / P) whose coefficients depend on
 * the cell index. Along a line the integral of a sum splits into the axes'
 * own integrals, (1/s_a) times the integral of the term over [x0, x1]; the
 * whole cells between add up exactly and the partial end cells come from
 * the antiderivative. None of this uses the integrator's own geometry. */

#define LMAXC 13   /* coefficients of a cell's polynomial, degree <= 12 */

typedef enum { LAT_PERLIN, LAT_STEP, LAT_KINK } lat_kind;

typedef struct lat_axis {
    double phase, period;
    long double alpha, beta;   /* LAT_PERLIN: alpha n + beta n^2; LAT_KINK: alpha u(1 - u) */
} lat_axis;

typedef struct lat_density {
    lat_kind kind;
    long double base;          /* constant added to the sum */
    lat_axis ax[3];
    long double env;           /* > 0: the sum is multiplied by e^(-env y) */
} lat_density;

/* The 1D gradient of lattice point k: a dyadic value in [-1, 1), period 256. */
static long double lat_grad(int64_t k)
{
    const uint32_t h = (uint32_t) (k & 255) * 2654435761u;
    return (long double) ((h >> 16) & 255) / 128 - 1;
}

/* The cell polynomial of axis a in cell k, coefficients c[0..LMAXC). */
static void lat_cell_poly(const lat_density *L, const lat_axis *A, int64_t k, long double c[LMAXC])
{
    for (int i = 0; i < LMAXC; ++i)
        c[i] = 0;
    switch (L->kind) {
    case LAT_PERLIN: {
        /* n(u) = g0 u (1 - s) + g1 (u - 1) s, s = 6u^5 - 15u^4 + 10u^3:
         * n = g0 u - 10 g1 u^3 + (25 g1 - 10 g0) u^4 + (15 g0 - 21 g1) u^5
         *     + 6 (g1 - g0) u^6. */
        const long double g0 = lat_grad(k), g1 = lat_grad(k + 1);
        long double n[7] = { 0, g0, 0, -10 * g1, 25 * g1 - 10 * g0, 15 * g0 - 21 * g1,
                             6 * (g1 - g0) };
        for (int i = 0; i < 7; ++i) {
            c[i] += A->alpha * n[i];
            for (int j = 0; j < 7; ++j)
                c[i + j] += A->beta * n[i] * n[j];
        }
        break;
    }
    case LAT_STEP:
        /* Constant per cell, 1..4: jumps at the seams. */
        c[0] = 1 + (long double) ((uint32_t) (k & 255) * 2654435761u >> 29 & 3);
        break;
    case LAT_KINK:
        /* alpha u (1 - u): continuous, its slope jumps at every seam. */
        c[1] = A->alpha;
        c[2] = -A->alpha;
        break;
    }
}

static long double poly_at(const long double c[LMAXC], long double u)
{
    long double r = 0;
    for (int i = LMAXC; i-- > 0;)
        r = r * u + c[i];
    return r;
}

/* The integral of the cell polynomial over [0, u]. */
static long double poly_int(const long double c[LMAXC], long double u)
{
    long double r = 0;
    for (int i = LMAXC; i-- > 0;)
        r = r * u + c[i] / (i + 1);
    return r * u;
}

/* Cell index and fraction of the value hi + lo on axis A: the remainder
 * hi - k P is formed by one fused operation, so the fraction keeps its
 * precision 1e6 or 3e7 from the origin (cell indices up to 2^32). */
static int64_t lat_cell2(const lat_axis *A, long double hi, long double lo, long double *u)
{
    long double k = floorl((hi + lo - A->phase) / A->period);
    long double f = (fmal(-k, A->period, hi) + lo - A->phase) / A->period;
    if (f < 0) {
        k -= 1;
        f += 1;
    } else if (f >= 1) {
        k += 1;
        f -= 1;
    }
    *u = f;
    return (int64_t) k;
}

/* The same for the density, whose value v is only a long double anyway. */
static int64_t lat_cell(const lat_axis *A, long double v, long double *u)
{
    const long double w = (v - A->phase) / A->period, k = floorl(w);
    *u = w - k;
    return (int64_t) k;
}

/* The cell polynomials repeat every 256 cells: a memo keeps the integrand
 * cheap enough for hundreds of thousands of evaluations under ASan. */
typedef struct lat_memo {
    int valid;
    lat_kind kind;
    long double alpha, beta;
    long double c[LMAXC];
} lat_memo;

static lat_memo memo[3][256];

static long double lat_term(const lat_density *L, int a, long double v)
{
    long double u;
    const lat_axis *A = &L->ax[a];
    const int64_t k = lat_cell(A, v, &u);
    lat_memo *m = &memo[a][k & 255];
    if (!m->valid || m->kind != L->kind || m->alpha != A->alpha || m->beta != A->beta) {
        lat_cell_poly(L, A, k, m->c);
        m->valid = 1;
        m->kind = L->kind;
        m->alpha = A->alpha;
        m->beta = A->beta;
    }
    return poly_at(m->c, u);
}

static void lat_density_fn(const void *ctx, const long double *v, long double out[3])
{
    const lat_density *L = ctx;
    long double s = L->base;
    for (int a = 0; a < 3; ++a)
        s += lat_term(L, a, v[a]);
    if (L->env > 0)
        s *= expl(-L->env * v[1]);
    out[0] = out[1] = out[2] = s;
}

/* x0 + s len as hi + lo (x0 far from the origin). */
static void end_value2(double x0, double s, double len, long double *hi, long double *lo)
{
    const double p = s * len, pe = fma(s, len, -p);
    const double h = x0 + p, hb = h - x0;
    *hi = h;
    *lo = ((long double) (x0 - (h - hb)) + (p - hb)) + pe;
}

static long double end_value(double x0, double s, double len)
{
    long double hi, lo;
    end_value2(x0, s, len, &hi, &lo);
    return hi + lo;
}

/* The exact integral over t in [0, len] of axis a's term along x0 + s t
 * (no envelope). */
static long double lat_axis_integral(const lat_density *L, int a, double x0, double s, double len)
{
    const lat_axis *A = &L->ax[a];
    if (s == 0)
        return lat_term(L, a, x0) * len;
    /* The ends in increasing order, each as hi + lo. */
    long double e[2][2] = { { x0, 0 } };
    end_value2(x0, s, len, &e[1][0], &e[1][1]);
    const int up = s > 0;
    long double u0, u1, c[LMAXC];
    const int64_t k0 = lat_cell2(A, e[!up][0], e[!up][1], &u0);
    const int64_t k1 = lat_cell2(A, e[up][0], e[up][1], &u1);
    long double sum = 0;
    if (k0 == k1) {
        lat_cell_poly(L, A, k0, c);
        sum = poly_int(c, u1) - poly_int(c, u0);
    } else {
        lat_cell_poly(L, A, k0, c);
        sum = poly_int(c, 1) - poly_int(c, u0);
        for (int64_t k = k0 + 1; k < k1; ++k) {
            lat_cell_poly(L, A, k, c);
            sum += poly_int(c, 1);
        }
        lat_cell_poly(L, A, k1, c);
        sum += poly_int(c, u1);
    }
    return sum * A->period / fabsl((long double) s);
}

static long double lat_integral(const lat_density *L, const double org[3], const double dir[3],
                                double len)
{
    long double sum = L->base * len;
    for (int a = 0; a < 3; ++a)
        sum += lat_axis_integral(L, a, org[a], dir[a], len);
    return sum;
}

static const ef_fog_functional AXES[3] = { { { 1, 0, 0 }, 0 }, { { 0, 1, 0 }, 0 }, { { 0, 0, 1 }, 0 } };

static int lat_run(const lat_density *L, int use_lattices, int nfeat, const ef_fog_feature *feat,
                   const double org[3], const double dir[3], double len, long double *tau,
                   ef_ref_stats *st)
{
    ef_fog_lattice lat[3];
    for (int a = 0; a < 3; ++a)
        lat[a] = (ef_fog_lattice) { a, L->ax[a].phase, L->ax[a].period };
    const ef_ref_density d = { .nf = 3, .f = AXES, .nfeat = nfeat, .feat = feat,
                               .density = lat_density_fn, .ctx = L,
                               .nlat = use_lattices ? 3 : 0, .lat = lat };
    long double t[3];
    const int rc = ef_ref_integrate(&d, org, dir, len, t, st);
    *tau = t[0];
    if (rc == 0)
        assert_true(t[0] == t[1] && t[1] == t[2]);
    return rc;
}

/* Crossings of axis a strictly inside the segment, counted in cell units. */
static long lat_crossings(const lat_axis *A, double x0, double s, double len)
{
    if (s == 0)
        return 0;
    const long double x1 = end_value(x0, s, len);
    long double u0, u1;
    const int64_t k0 = lat_cell(A, fminl(x0, x1), &u0), k1 = lat_cell(A, fmaxl(x0, x1), &u1);
    return (long) (k1 - k0);
}

static const double OBLIQUE[3] = { 0.48, -0.64, 0.6 };

static void test_lattice_perlin_seams(void **state)
{
    (void) state;
    /* Perlin's 1D gradient noise per axis, alpha n + beta n^2 (C2 seams, a
     * degree-12 polynomial per cell; the n^2 part does not telescope), over
     * thousands of cells of an oblique segment 1e6 from the origin, with
     * partial first and last cells. Split at the seams, every piece is a
     * polynomial Gauss 7 integrates exactly: one interval per piece. */
    const lat_density L = { LAT_PERLIN, 1.0L,
                            { { 0.3, 0.25, 0.5L, 2.0L },
                              { -0.17, 0.375, 0.25L, 3.0L },
                              { 0.05, 0.5, -0.5L, 1.5L } },
                            0 };
    const double org[3] = { 1e6 + 0.123, -1e6 + 0.456, 1e6 - 0.789 };
    const double len = 1000.0 + 1.0 / 3;
    const long double want = lat_integral(&L, org, OBLIQUE, len);
    long crossings = 0;
    for (int a = 0; a < 3; ++a)
        crossings += lat_crossings(&L.ax[a], org[a], OBLIQUE[a], len);
    assert_true(crossings > 4500);

    ef_ref_stats st, st0;
    long double got, got0;
    assert_int_equal(lat_run(&L, 1, 0, NULL, org, OBLIQUE, len, &got, &st), 0);
    const long double err = fabsl(got - want) / want;
    assert_int_equal(st.unconverged, 0);
    assert_int_equal(st.pieces, crossings + 1);
    assert_int_equal(st.intervals, st.pieces);
    assert_rel(got, want, 1e-13L);

    /* Without the lattices the same integral needs far more evaluations
     * and still ends less accurate. */
    assert_int_equal(lat_run(&L, 0, 0, NULL, org, OBLIQUE, len, &got0, &st0), 0);
    const long double err0 = fabsl(got0 - want) / want;
    print_message("perlin seams: %ld cells; split: rel err %.2Lg, %ld evals; unsplit: rel err "
                  "%.2Lg, %ld evals, %d unconverged\n",
                  crossings + 1, err, st.evals, err0, st0.evals, st0.unconverged);
    assert_true(st0.evals > 3 * st.evals);
    assert_true(err0 > 10 * err || st0.unconverged > 0);
}

static void test_lattice_kinks(void **state)
{
    (void) state;
    /* Periodic kinks, alpha u (1 - u) per axis, periods 1e-2 .. 3e-2: split
     * at the seams, every piece is a quadratic, one interval each. */
    const lat_density L = { LAT_KINK, 0.5L,
                            { { 0.004, 0.01, 1.0L, 0 },
                              { -0.0031, 0.03, 2.0L, 0 },
                              { 0.0123, 0.02, 0.5L, 0 } },
                            0 };
    const double org[3] = { 1000 + 0.0123456, 1000 - 0.0654321, -1000 + 0.0111 };
    const double len = 20.0 + 1.0 / 7;
    const long double want = lat_integral(&L, org, OBLIQUE, len);
    long crossings = 0;
    for (int a = 0; a < 3; ++a)
        crossings += lat_crossings(&L.ax[a], org[a], OBLIQUE[a], len);
    ef_ref_stats st, st0;
    long double got, got0;
    assert_int_equal(lat_run(&L, 1, 0, NULL, org, OBLIQUE, len, &got, &st), 0);
    assert_int_equal(st.unconverged, 0);
    assert_int_equal(st.pieces, crossings + 1);
    assert_int_equal(st.intervals, st.pieces);
    assert_rel(got, want, 1e-13L);
    assert_int_equal(lat_run(&L, 0, 0, NULL, org, OBLIQUE, len, &got0, &st0), 0);
    print_message("kinks: %ld cells; split: rel err %.2Lg, %ld evals; unsplit: rel err "
                  "%.2Lg, %ld evals, %d unconverged\n",
                  crossings + 1, fabsl(got - want) / want, st.evals, fabsl(got0 - want) / want,
                  st0.evals, st0.unconverged);
    assert_true(fabsl(got0 - want) > 1e-12L * want);
    assert_true(st0.evals > 10 * st.evals);

    /* The same 1e6 from the origin (cell indices about 1e8). A long double
     * resolves a value there to 6e-14, about 6e-12 of a cell, so the
     * density's own rounding keeps |K - G| above the 1e-14 target and
     * refinement runs to its limit (reported as unconverged); the splits
     * still land on the seams and the integral stays within 1e-13. */
    const double far[3] = { 1e6 + 0.0123456, 1e6 - 0.0654321, -1e6 + 0.0111 };
    const long double wantf = lat_integral(&L, far, OBLIQUE, len);
    assert_int_equal(lat_run(&L, 1, 0, NULL, far, OBLIQUE, len, &got, &st), 0);
    assert_rel(got, wantf, 1e-13L);
    print_message("kinks at 1e6: split: rel err %.2Lg, %ld evals, %d unconverged\n",
                  fabsl(got - wantf) / wantf, st.evals, st.unconverged);
}

static void test_lattice_steps_far(void **state)
{
    (void) state;
    /* Jumps at every seam (a constant 1..4 per cell), period 1e-2 at values
     * about 1e6 and up to 3e7: the integral is exact only if every split
     * sits on its seam, since a misplaced one moves density across a jump
     * where no node sees it. Axis-parallel, in-plane and oblique. */
    const lat_density L = { LAT_STEP, 0,
                            { { 0.0025, 0.01, 0, 0 },
                              { 0.001, 0.03, 0, 0 },
                              { -0.007, 0.02, 0, 0 } },
                            0 };
    const double orgs[][3] = { { 1e6 + 0.0123456, 1e6 - 0.0654321, -1e6 + 0.0111 },
                               { 3e7 + 0.0031, -2.9e7 - 0.011, 1e5 + 0.3 } };
    const double dirs[][3] = { { 1, 0, 0 }, { 0, -0.6, 0.8 }, { 0.48, -0.64, 0.6 },
                               { -0.267261241912424, 0.534522483824849, 0.801783725737273 } };
    for (size_t i = 0; i < sizeof orgs / sizeof orgs[0]; ++i)
        for (size_t j = 0; j < sizeof dirs / sizeof dirs[0]; ++j) {
            const double len = 10.0 + 1.0 / 3;
            const long double want = lat_integral(&L, orgs[i], dirs[j], len);
            ef_ref_stats st;
            long double got;
            assert_int_equal(lat_run(&L, 1, 0, NULL, orgs[i], dirs[j], len, &got, &st), 0);
            assert_int_equal(st.unconverged, 0);
            assert_int_equal(st.intervals, st.pieces);
            /* Far better than 1e-13: the seams sit where double-double
             * arithmetic puts them, and the pieces are constants. */
            assert_rel(got, want, 1e-16L);
        }
    /* Unsplit, the jumps defeat the quadrature. */
    long double got0;
    ef_ref_stats st0;
    assert_int_equal(lat_run(&L, 0, 0, NULL, orgs[0], dirs[2], 10.0 + 1.0 / 3, &got0, &st0), 0);
    const long double want = lat_integral(&L, orgs[0], dirs[2], 10.0 + 1.0 / 3);
    print_message("steps at 1e6 unsplit: rel err %.2Lg, %ld evals\n", fabsl(got0 - want) / want,
                  st0.evals);
    assert_true(fabsl(got0 - want) > 1e-9L * want);
}

/* The integral over [t0, t1] of e^(-c t) (p0 + p1 t + p2 t^2), c > 0. */
static long double exp_poly(long double c, long double p0, long double p1, long double p2,
                            long double t0, long double t1)
{
    /* -e^(-ct) (p/c + p'/c^2 + p''/c^3) between the ends. */
    long double F[2];
    const long double t[2] = { t0, t1 };
    for (int i = 0; i < 2; ++i) {
        const long double p = p0 + t[i] * (p1 + t[i] * p2), dp = p1 + 2 * p2 * t[i];
        F[i] = -expl(-c * t[i]) * (p / c + dp / (c * c) + 2 * p2 / (c * c * c));
    }
    return F[1] - F[0];
}

static void test_lattice_infinite(void **state)
{
    (void) state;
    /* Height fog e^(-y) times (1 + kinks in x) up an oblique sky ray: the
     * lattice splits stop where the envelope's geometric steps do (y = 128,
     * 64 times the larger of the start's height and the scale),
     * the tail takes the rest. In t, cell j of x is [t_j, t_j+1] and u is
     * linear in t there, so each cell is e^(-ct) times a quadratic. */
    const lat_density L = { LAT_KINK, 1.0L,
                            { { 0.01, 0.05, 0.75L, 0 }, { 0, 1, 0, 0 }, { 0, 1, 0, 0 } },
                            1.0L };
    const double org[3] = { 1000.003, 2.0, -7.0 }, dir[3] = { 0.8, 0.6, 0 };
    const ef_fog_feature feat = { 1, 0, 1.0 };
    /* Want: sum over cells while the envelope matters. */
    const lat_axis *A = &L.ax[0];
    const long double c = 0.6L, sx = 0.8L, y0 = 2.0L;
    long double u0;
    int64_t k = lat_cell(A, org[0], &u0);
    long double want = 0, t0 = 0;
    for (;; ++k) {
        /* u = (x0 + sx t - phase) / P - k: u = a + b t. */
        const long double b = sx / A->period, a = ((long double) org[0] - A->phase) / A->period - k;
        const long double t1 = (1 - a) / b;
        /* 1 + alpha u (1 - u) = 1 + alpha (a + b t) - alpha (a + b t)^2. */
        const long double al = A->alpha;
        const long double p0 = 1 + al * a - al * a * a, p1 = al * b - 2 * al * a * b,
                          p2 = -al * b * b;
        want += expl(-y0) * exp_poly(c, p0, p1, p2, t0, t1);
        t0 = t1;
        if (c * t0 > 200)
            break;
    }
    ef_ref_stats st;
    long double got;
    /* The y and z terms are constant 0 (period 1, alpha 0) but still split:
     * y crosses its lattice too. Leave only x's lattice in play. */
    ef_fog_lattice lat = { 0, A->phase, A->period };
    const ef_ref_density d = { .nf = 3, .f = AXES, .nfeat = 1, .feat = &feat,
                               .density = lat_density_fn, .ctx = &L, .nlat = 1, .lat = &lat };
    long double t3[3];
    assert_int_equal(ef_ref_integrate(&d, org, dir, INFINITY, t3, &st), 0);
    got = t3[0];
    assert_int_equal(st.unconverged, 0);
    assert_rel(got, want, 1e-13L);
    /* x crossings up to y = 128, where the tail starts. */
    const double tmax = (128 - 2.0) / 0.6;
    const long lat_splits = lat_crossings(A, org[0], 0.8, tmax);
    print_message("infinite: %ld lattice splits, %ld pieces, rel err %.2Lg\n", lat_splits, st.pieces,
                  fabsl(got - want) / want);
    assert_true(st.pieces >= lat_splits && st.pieces <= lat_splits + 16);
    /* With no feature there is no finite tail start: no lattice splits. */
    const ef_ref_density d0 = { .nf = 3, .f = AXES, .density = lat_density_fn, .ctx = &L,
                                .nlat = 1, .lat = &lat };
    assert_int_equal(ef_ref_integrate(&d0, org, dir, INFINITY, t3, &st), 0);
    assert_int_equal(st.pieces, 1);
}

static void test_lattice_guards(void **state)
{
    (void) state;
    const lat_density L = { LAT_KINK, 1.0L, { { 0, 0.01, 1, 0 }, { 0, 1, 0, 0 }, { 0, 1, 0, 0 } }, 0 };
    ef_fog_lattice lat = { 0, 0, 0.01 };
    const ef_ref_density d = { .nf = 3, .f = AXES, .density = lat_density_fn, .ctx = &L,
                               .nlat = 1, .lat = &lat };
    const double org[3] = { 0.5, 0, 0 };
    long double tau[3];
    /* 1e7 seams: over the limit, refused before any work. */
    ef_ref_stats st;
    assert_int_equal(ef_ref_integrate(&d, org, EX, 1e5, tau, &st), -1);
    assert_int_equal(st.evals, 0);
    /* Crossing indices past 2^53 cannot be placed. */
    const double far[3] = { 1e14, 0, 0 };
    assert_int_equal(ef_ref_integrate(&d, far, EX, 1.0, tau, NULL), -1);
    /* Periods must be finite and positive, phases finite. */
    const double bad[][2] = { { 0, 0 }, { 0, -1 }, { 0, INFINITY }, { 0, NAN }, { NAN, 1 } };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        lat.phase = bad[i][0];
        lat.period = bad[i][1];
        assert_int_equal(ef_ref_integrate(&d, org, EX, 1.0, tau, NULL), -1);
    }
    /* A lattice on a functional the segment does not cross adds nothing,
     * and one whose functional index is out of range is ignored. */
    lat = (ef_fog_lattice) { 1, 0.5, 0.01 };
    assert_int_equal(ef_ref_integrate(&d, org, EX, 1.0, tau, &st), 0);
    assert_int_equal(st.pieces, 1);
    lat.f = 7;
    assert_int_equal(ef_ref_integrate(&d, org, EX, 1.0, tau, &st), 0);
    assert_int_equal(st.pieces, 1);
}

/* A fog model that exists only here, to see ef_ref_tau fetch its lattices. */
static int fake_functionals(const ef_fog_component *c, ef_fog_functional *out, int cap)
{
    (void) c;
    for (int i = 0; i < 3 && i < cap; ++i)
        out[i] = AXES[i];
    return 3;
}

static int fake_features(const ef_fog_component *c, ef_fog_feature *out, int cap)
{
    (void) c;
    (void) out;
    (void) cap;
    return 0;
}

static const lat_density FAKE = { LAT_PERLIN, 1.0L,
                                  { { 0.3, 0.25, 0.5L, 2.0L },
                                    { -0.17, 0.375, 0.25L, 3.0L },
                                    { 0.05, 0.5, -0.5L, 1.5L } },
                                  0 };

static int fake_lattices(const ef_fog_component *c, ef_fog_lattice *out, int cap)
{
    (void) c;
    for (int i = 0; i < 3 && i < cap; ++i)
        out[i] = (ef_fog_lattice) { i, FAKE.ax[i].phase, FAKE.ax[i].period };
    return 3;
}

static void fake_density(const ef_fog_component *c, const long double *v, long double out[3])
{
    (void) c;
    lat_density_fn(&FAKE, v, out);
}

static void test_lattice_from_model(void **state)
{
    (void) state;
    ef_fog_model m = { .name = "fake", .functionals = fake_functionals,
                       .features = fake_features, .density = fake_density,
                       .lattices = fake_lattices };
    static ef_fog_component c;
    c.model = &m;
    ef_ray r = { .dir = { 0.48, -0.64, 0.6 }, .dist = 200.5, .org = { 12.5, 3.25, -40.125 } };
    const long double want = lat_integral(&FAKE, r.org, r.dir, r.dist);
    long double tau[3];
    ef_ref_stats st;
    assert_int_equal(ef_ref_tau(&c, &r, tau, &st), 0);
    assert_rel(tau[0], want, 1e-13L);
    assert_int_equal(st.intervals, st.pieces);
    assert_true(st.pieces > 900);
    /* Without lattices() the model gets no seam splits. */
    m.lattices = NULL;
    assert_int_equal(ef_ref_tau(&c, &r, tau, &st), 0);
    assert_int_equal(st.pieces, 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_polynomials),
        cmocka_unit_test(test_narrow_bump),
        cmocka_unit_test(test_walker_extremes),
        cmocka_unit_test(test_exponential_to_infinity),
        cmocka_unit_test(test_far_from_origin),
        cmocka_unit_test(test_zero_and_constant),
        cmocka_unit_test(test_lattice_perlin_seams),
        cmocka_unit_test(test_lattice_kinks),
        cmocka_unit_test(test_lattice_steps_far),
        cmocka_unit_test(test_lattice_infinite),
        cmocka_unit_test(test_lattice_guards),
        cmocka_unit_test(test_lattice_from_model),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
