/* vmath.h's four-lane exp, expm1, log, log1p, atan2, sincos and tan against libm's
 * scalar functions (glibc's, within an ulp of the true value), over the
 * ranges their callers feed them, with random and edge arguments: each
 * within a few ulp. And each lane's value the same bits whatever the other
 * lanes hold (the lamp's batches and its single rays rely on it). */
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "vmath.h"

typedef void (*vfn)(const v4d *x, const v4d *y, v4d *o);

static void f_exp(const v4d *x, const v4d *y, v4d *o)
{
    (void) y;
    v_exp(x, o);
}
static void f_expm1(const v4d *x, const v4d *y, v4d *o)
{
    (void) y;
    v_expm1(x, o);
}
static void f_tan(const v4d *x, const v4d *y, v4d *o)
{
    (void) y;
    v_tan(x, o);
}
static void f_log(const v4d *x, const v4d *y, v4d *o)
{
    (void) y;
    v_log(x, o);
}
static void f_log1p(const v4d *x, const v4d *y, v4d *o)
{
    (void) y;
    v_log1p(x, o);
}
static void f_atan2(const v4d *x, const v4d *y, v4d *o)
{
    v_atan2(y, x, o);
}
static void f_sin(const v4d *x, const v4d *y, v4d *o)
{
    (void) y;
    v4d c;
    v_sincos(x, o, &c);
}
static void f_cos(const v4d *x, const v4d *y, v4d *o)
{
    (void) y;
    v4d s;
    v_sincos(x, &s, o);
}

static double l_atan2(double x, double y)
{
    return atan2(y, x);
}
/* libm's one-argument functions in the two-argument form */
#define LIBM1(f)                                                                                  \
    static double l_##f(double x, double y)                                                     \
    {                                                                                            \
        (void) y;                                                                                \
        return f(x);                                                                             \
    }
LIBM1(exp)
LIBM1(expm1)
LIBM1(tan)
LIBM1(log)
LIBM1(log1p)
LIBM1(sin)
LIBM1(cos)

static uint64_t rng = 88172645463325252ull;
static double uniform(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double) (rng >> 11) / 9007199254740992.0;
}

/* |v - ref| in units of the last place of ref (of the smallest normal
 * where ref is 0 or subnormal) */
static double ulps(double v, double ref)
{
    const double a = fabs(ref) < DBL_MIN ? DBL_MIN : fabs(ref);
    int e;
    frexp(a, &e);
    return fabs(v - ref) / ldexp(1.0, e - 53);
}

/* Over n arguments from gen: the largest ulp error against lib; each lane
 * also recomputed with its neighbours scrambled, which must not change
 * its bits. An absolute floor abs (in units of 2^-53) applies where the
 * function's value passes through 0 (log near 1, sin, cos near pi/2). */
static double worst(vfn f, double (*lib)(double, double), void (*gen)(double *, double *),
                    int n, double abs_floor)
{
    double w = 0;
    for (int i = 0; i < n; i += 4) {
        v4d x, y, o, o2;
        for (int k = 0; k < 4; ++k)
            gen(&x[k], &y[k]);
        f(&x, &y, &o);
        v4d x2 = x, y2 = y;
        for (int k = 1; k < 4; ++k) {   /* lane 0 kept, the others replaced */
            gen(&x2[k], &y2[k]);
        }
        f(&x2, &y2, &o2);
        assert_true(memcmp(&o[0], &o2[0], sizeof o[0]) == 0);
        for (int k = 0; k < 4; ++k) {
            const double ref = lib(x[k], y[k]);
            double u = ulps(o[k], ref);
            if (abs_floor > 0 && fabs(o[k] - ref) <= abs_floor * 0x1p-53)
                u = 0;
            if (u > w)
                w = u;
        }
    }
    return w;
}

static void g_exp(double *x, double *y)
{
    *y = 0;
    const double u = uniform();
    *x = u < 0.1 ? 1e-3 * (2 * uniform() - 1) : 1416 * uniform() - 708;
}
/* expm1 where lit fog takes it: tiny, around the series' edge at 1/2,
 * and out to -708 .. 700 */
static void g_expm1(double *x, double *y)
{
    *y = 0;
    const double u = uniform();
    *x = u < 0.2 ? 1e-9 * (2 * uniform() - 1)
       : u < 0.5 ? 0.52 * (2 * uniform() - 1)
       : u < 0.6 ? -800 * uniform()
                 : 1408 * uniform() - 708;
}
/* tan over the quadrature's angles (-pi/2, pi/2), many near the ends */
static void g_tan(double *x, double *y)
{
    *y = 0;
    const double u = uniform(), pio2 = 1.5707963267948966;
    *x = u < 0.3 ? (2 * uniform() - 1) * pio2
       : u < 0.6 ? (uniform() < 0.5 ? -1 : 1) * (pio2 - pow(10, -15 * uniform()))
       : (2 * uniform() - 1) * 1e-6;
}
static void g_log(double *x, double *y)
{
    *y = 0;
    const double u = uniform();
    *x = u < 0.2 ? 1 + 0.3 * (2 * uniform() - 1)
       : u < 0.3 ? 1 + 1e-12 * (2 * uniform() - 1)
                 : pow(10, 600 * uniform() - 300);
}
static void g_log1p(double *x, double *y)
{
    *y = 0;
    const double u = uniform();
    *x = u < 0.2 ? 1e-9 * (2 * uniform() - 1)
       : u < 0.4 ? -1 + pow(10, -15 * uniform())
       : u < 0.6 ? 2 * uniform() - 1
                 : pow(10, 300 * uniform());
}
static void g_atan2(double *x, double *y)
{
    const double u = uniform();
    *x = (2 * uniform() - 1) * pow(10, 40 * uniform() - 20);
    *y = (2 * uniform() - 1) * pow(10, 40 * uniform() - 20);
    if (u < 0.1)
        *y = *x * (1 + 1e-9 * uniform());   /* near the diagonal */
    if (u > 0.9)
        *y = 1e-12 * *x * uniform();        /* near the axis */
}
static void g_trig(double *x, double *y)
{
    *y = 0;
    *x = 3.2 * uniform() - 1.6;
}

static void test_accuracy(void **state)
{
    (void) state;
    const int n = 400000;
    const double e = worst(f_exp, l_exp, g_exp, n, 0);
    const double l = worst(f_log, l_log, g_log, n, 2);
    const double l1 = worst(f_log1p, l_log1p, g_log1p, n, 0);
    const double a = worst(f_atan2, l_atan2, g_atan2, n, 0);
    /* cos near pi/2 is 1 - x^2 c(x^2): an ulp of 1 (the lamp's formula
     * needs it absolute, against |V|) */
    const double s = worst(f_sin, l_sin, g_trig, n, 4);
    const double c = worst(f_cos, l_cos, g_trig, n, 4);
    const double em = worst(f_expm1, l_expm1, g_expm1, n, 0);
    const double t = worst(f_tan, l_tan, g_tan, n, 0);
    printf("worst ulps against libm: exp %.2f, log %.2f, log1p %.2f, atan2 %.2f, sin %.2f, "
           "cos %.2f, expm1 %.2f, tan %.2f\n",
           e, l, l1, a, s, c, em, t);
    assert_true(em <= 4);
    assert_true(t <= 4);
    assert_true(e <= 3);
    assert_true(l <= 3);
    assert_true(l1 <= 4);
    assert_true(a <= 3);
    assert_true(s <= 3);
    assert_true(c <= 3);
}

/* Values by hand: the edges of each range. */
static void test_edges(void **state)
{
    (void) state;
    const v4d x = { 0.0, 708.0, -708.0, 1.0 };
    v4d o;
    v_exp(&x, &o);
    assert_true(o[0] == 1.0);
    assert_true(ulps(o[1], exp(708.0)) <= 3 && ulps(o[2], exp(-708.0)) <= 3);
    assert_true(ulps(o[3], 2.718281828459045) <= 2);
    const v4d lx = { 1.0, 2.0, DBL_MIN, DBL_MAX };
    v_log(&lx, &o);
    assert_true(o[0] == 0.0);
    assert_true(ulps(o[1], 0.6931471805599453) <= 2);
    assert_true(ulps(o[2], -708.3964185322641) <= 2 && ulps(o[3], 709.782712893384) <= 2);
    const v4d px = { 0.0, 1e-300, -0.5, 1e300 };
    v_log1p(&px, &o);
    assert_true(o[0] == 0.0 && o[1] == 1e-300);
    assert_true(ulps(o[2], -0.6931471805599453) <= 2 && ulps(o[3], 690.7755278982137) <= 2);
    /* the octants' edges: atan2(1, 1) = pi/4, (1, 0) = pi/2, (0, -1) = pi,
     * (-1, -1) = -3 pi/4 */
    const v4d ay = { 1.0, 1.0, 0.0, -1.0 }, ax = { 1.0, 0.0, -1.0, -1.0 };
    v_atan2(&ay, &ax, &o);
    assert_true(ulps(o[0], 0.7853981633974483) <= 1 && ulps(o[1], 1.5707963267948966) <= 1);
    assert_true(ulps(o[2], 3.141592653589793) <= 1 && ulps(o[3], -2.356194490192345) <= 1);
    const v4d t = { 0.0, 1.5, -1.6, 1e-10 };
    v4d sn, cs;
    v_sincos(&t, &sn, &cs);
    assert_true(sn[0] == 0.0 && cs[0] == 1.0 && sn[3] == 1e-10 && cs[3] == 1.0);
    assert_true(ulps(sn[1], 0.9974949866040544) <= 2 && fabs(cs[1] - 0.0707372016677029) <= 0x1p-52);
    assert_true(ulps(sn[2], -0.9995736030415051) <= 2);
    /* expm1 at 0, its smallest and largest arguments, and -0.5 (the
     * series' edge); tan at 0, pi/4, pi/2's double (1.633e16) and the
     * one below it */
    const v4d mx = { 0.0, -800.0, 700.0, -0.5 };
    v_expm1(&mx, &o);
    assert_true(o[0] == 0.0 && o[1] == -1.0);
    assert_true(ulps(o[2], expm1(700.0)) <= 3 && ulps(o[3], -0.3934693402873666) <= 2);
    const v4d tx = { 0.0, 0.7853981633974483, 1.5707963267948966, -1.5707963267948963 };
    v_tan(&tx, &o);
    assert_true(o[0] == 0.0 && ulps(o[1], 0.99999999999999989) <= 2);
    assert_true(ulps(o[2], 1.633123935319537e16) <= 2 && ulps(o[3], -3530114321217157.5) <= 4);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_accuracy),
        cmocka_unit_test(test_edges),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
