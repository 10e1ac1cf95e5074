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
    ef_ref_density d = { 1, fn, nfeat, feat, one_density, &o };
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

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_polynomials),
        cmocka_unit_test(test_narrow_bump),
        cmocka_unit_test(test_walker_extremes),
        cmocka_unit_test(test_exponential_to_infinity),
        cmocka_unit_test(test_far_from_origin),
        cmocka_unit_test(test_zero_and_constant),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
