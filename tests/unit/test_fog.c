/* Fog models, the SPEC grammar and premultiplied compositing, against
 * values worked out by hand from glFog (seed 001) and the compositing
 * formula of the foundation issue. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "expneg.h"
#include "scene.h"
#include "tassert.h"

static ef_ray ray(double dist, double planar)
{
    ef_ray r = { { 0, 0, 1 }, dist, planar, { 0, 0, 0 } };
    return r;
}

static void scene_with(ef_fog_scene *s, const char *spec)
{
    ef_err err;
    ef_scene_init(s);
    assert_int_equal(ef_scene_add(s, spec, &err), 0);
}

static void expect_T(const ef_fog_scene *s, ef_ray r, double t0, double t1, double t2)
{
    ef_fog_sample surf, inf;
    ef_scene_eval(s, &r, &surf, &inf);
    const double *T = surf.T;
    assert_true(fabs(T[0] - t0) <= 1e-15);
    assert_true(fabs(T[1] - t1) <= 1e-15);
    assert_true(fabs(T[2] - t2) <= 1e-15);
}

/* The transmittance's e^-x: within 1 ulp of expl's e^-x on 10^6 values
 * spread over [0, 746] and its small end (normal results), the special
 * values exactly, and monotone. */
static void test_exp_neg(void **state)
{
    (void) state;
    uint64_t g = 88172645463325252ull;
    double worst = 0;
    for (long i = 0; i < 1000000; ++i) {
        g ^= g << 13;
        g ^= g >> 7;
        g ^= g << 17;
        const double u = (double) (g >> 11) * 0x1.0p-53;
        const double x = i % 3 == 0 ? u * 700 : i % 3 == 1 ? u * 5 : pow(10, -20 + 22 * u);
        const long double e = expl(-(long double) x);
        const double ulp = nextafter((double) e, INFINITY) - (double) e;
        const double err = (double) fabsl((long double) ef_exp_neg(x) - e) / ulp;
        if (err > worst)
            worst = err;
    }
    printf("  ef_exp_neg: worst %.3f ulp\n", worst);
    assert_true(worst <= 1.0);
    assert_true(ef_exp_neg(0) == 1.0);
    assert_true(ef_exp_neg(-0.0) == 1.0);
    assert_true(ef_exp_neg(INFINITY) == 0.0);
    assert_true(ef_exp_neg(746) == 0.0);
    assert_true(ef_exp_neg(745) > 0 && ef_exp_neg(745) < 1e-323);
    assert_true(isnan(ef_exp_neg(NAN)));
    assert_true(fabs(ef_exp_neg(1) - 0.36787944117144233) <= 0x1p-54);
    assert_true(ef_exp_neg(-1) > 2.718281828459045 - 1e-15 && ef_exp_neg(-1) < 2.718281828459046);
    for (double x = 0; x < 40; x += 0.001)
        assert_true(ef_exp_neg(x + 0.001) <= ef_exp_neg(x));
}

static void test_exp(void **state)
{
    (void) state;
    ef_fog_scene s;
    scene_with(&s, "exp:density=0.1");
    expect_T(&s, ray(10, 8), 0.36787944117144233, 0.36787944117144233, 0.36787944117144233);
    expect_T(&s, ray(0, 0), 1, 1, 1);
    ef_scene_free(&s);
    scene_with(&s, "exp:density=0.1:distance=planar");
    expect_T(&s, ray(10, 8), 0.44932896411722156, 0.44932896411722156, 0.44932896411722156);
    ef_scene_free(&s);
}

static void test_exp2(void **state)
{
    (void) state;
    ef_fog_scene s;
    scene_with(&s, "exp2:density=0.1");
    expect_T(&s, ray(10, 10), 0.36787944117144233, 0.36787944117144233, 0.36787944117144233);
    expect_T(&s, ray(20, 20), 0.018315638888734179, 0.018315638888734179, 0.018315638888734179);
    ef_scene_free(&s);
}

static void test_linear(void **state)
{
    (void) state;
    ef_fog_scene s;
    scene_with(&s, "linear:start=10:end=30");
    expect_T(&s, ray(20, 20), 0.5, 0.5, 0.5);
    expect_T(&s, ray(25, 25), 0.25, 0.25, 0.25);
    expect_T(&s, ray(5, 5), 1, 1, 1);     /* clamped to 1 before start */
    expect_T(&s, ray(40, 40), 0, 0, 0);   /* clamped to 0 beyond end */
    expect_T(&s, ray(INFINITY, INFINITY), 0, 0, 0);
    ef_scene_free(&s);
}

static void test_per_channel_and_sum(void **state)
{
    (void) state;
    ef_fog_scene s;
    scene_with(&s, "exp:density=0.1,0.2,0.3");
    expect_T(&s, ray(10, 10), exp(-1.0), exp(-2.0), exp(-3.0));
    /* Two components: optical depths add. */
    ef_err err;
    assert_int_equal(ef_scene_add(&s, "exp:density=0.05", &err), 0);
    expect_T(&s, ray(10, 10), exp(-1.5), exp(-2.5), exp(-3.5));
    ef_scene_free(&s);
}

static void test_sky_limits(void **state)
{
    (void) state;
    ef_fog_scene s;
    ef_fog_sample surf, inf;
    const double *T = surf.T, *Tinf = inf.T;
    ef_ray sky = ray(INFINITY, INFINITY);
    scene_with(&s, "exp:density=0.1,0,0.2");
    ef_scene_eval(&s, &sky, &surf, &inf);
    /* A zero density stays fog-free at infinity (no 0*inf NaN). */
    assert_true(T[0] == 0.0 && T[1] == 1.0 && T[2] == 0.0);
    assert_memory_equal(T, Tinf, sizeof T);
    /* Background as a shell at 100: Tinf ends there. */
    ef_scene_free(&s);
    scene_with(&s, "exp:density=0.01");
    ef_err err;
    assert_int_equal(ef_scene_parse_sky(&s, "distance=100", &err), 0);
    ef_ray near = ray(5, 5);
    ef_scene_eval(&s, &near, &surf, &inf);
    assert_true(fabs(Tinf[0] - exp(-1.0)) < 1e-15);
    assert_true(fabs(T[0] - exp(-0.05)) < 1e-15);
    ef_scene_free(&s);
}

static void test_composite(void **state)
{
    (void) state;
    const ef_fog_sample T = { { 0.5, 0.5, 0.5 }, { 1, 0.5, 0.25 } };
    const ef_fog_sample Tinf = { { 0.1, 0.1, 0.1 }, { 1, 0.5, 0.25 } };
    /* alpha = 1: exactly glFog, C' = f C + (1 - f) F; alpha stays 1. */
    double rgb[3] = { 0.2, 0.4, 0.8 }, a = 1.0;
    ef_composite(&T, &Tinf, 1, rgb, &a);
    assert_true(fabs(rgb[0] - 0.6) < 1e-15 && fabs(rgb[1] - 0.45) < 1e-15 &&
                fabs(rgb[2] - 0.525) < 1e-15 && a == 1.0);
    /* alpha = 0.5, premultiplied colour 0.2: 0.5*0.2 + 0.5*0.5*F + 0.5*0.9*F. */
    double h[3] = { 0.2, 0.2, 0.2 };
    a = 0.5;
    ef_composite(&T, &Tinf, 1, h, &a);
    assert_true(fabs(h[0] - 0.8) < 1e-15 && fabs(h[1] - 0.45) < 1e-15 &&
                fabs(h[2] - 0.275) < 1e-15);
    assert_true(fabs(a - 0.95) < 1e-15);
    /* alpha = 0 (nothing rendered): only the fog in front of the background. */
    double z[3] = { 0, 0, 0 };
    a = 0.0;
    ef_composite(&Tinf, &Tinf, 1, z, &a);
    assert_true(fabs(z[0] - 0.9) < 1e-15 && fabs(z[1] - 0.45) < 1e-15 && fabs(a - 0.9) < 1e-15);
    /* --sky keep drops the last term and leaves alpha alone. */
    double k[3] = { 0.2, 0.2, 0.2 };
    a = 0.5;
    ef_composite(&T, &Tinf, 0, k, &a);
    assert_true(fabs(k[0] - 0.35) < 1e-15 && a == 0.5);
    /* No alpha channel: alpha = 1. */
    double n[3] = { 0.2, 0.4, 0.8 };
    ef_composite(&T, &Tinf, 1, n, NULL);
    assert_true(fabs(n[0] - 0.6) < 1e-15);
}

static void expect_usage(const char *spec, const char *quote)
{
    ef_fog_component c;
    ef_err err;
    assert_int_equal(ef_fog_parse(spec, NULL, &c, &err), -1);
    if (!strstr(err.msg, quote))
        fail_msg("error for '%s' does not quote '%s': %s", spec, quote, err.msg);
}

static void test_spec_errors(void **state)
{
    (void) state;
    expect_usage("fogg:density=1", "'fogg'");
    expect_usage("exp:densty=1", "'densty'");
    expect_usage("exp:density", "'density'");
    expect_usage("exp:density=", "'density'");
    expect_usage("exp", "missing density");
    expect_usage("exp:density=-0.5", "'-0.5'");
    expect_usage("exp:density=0.1,-1,0.1", "negative");
    expect_usage("exp:density=abc", "'abc'");
    expect_usage("exp:density=nan", "'nan'");
    expect_usage("linear:start=30:end=10", "end (10) is less than start (30)");
    expect_usage("linear:start=1", "missing end");
    expect_usage("exp:density=1:density=2", "twice");
    expect_usage("exp:density=1:distance=manhattan", "'manhattan'");
    expect_usage("", "empty");
}

static void test_spec_ok(void **state)
{
    (void) state;
    ef_fog_component c;
    ef_err err;
    assert_int_equal(ef_fog_parse("exp2:density=1e-3,2e-3,3e-3:distance=planar", NULL, &c, &err), 0);
    assert_true(c.model == &ef_fog_exp2 && c.distance == EF_DIST_PLANAR);
    assert_true(c.p[0] == 1e-3 && c.p[1] == 2e-3 && c.p[2] == 3e-3);
    ef_fog_free(&c);
    assert_int_equal(ef_fog_parse("linear:end=5", NULL, &c, &err), 0);
    assert_true(c.p[0] == 0.0 && c.p[1] == 5.0);
    ef_fog_free(&c);
}

static void test_colour_mix_at_infinity(void **state)
{
    (void) state;
    /* Two uniform fogs with their own colours: along any stretch of the ray
     * their optical depths are in the ratio of their densities, so the
     * in-scattered colour is (r1 c1 + r2 c2) / (r1 + r2), at a finite
     * distance and for the sky alike (where both taus are infinite). */
    ef_fog_scene s;
    ef_err err;
    scene_with(&s, "exp:density=0.02:color=1,0.5,0");
    assert_int_equal(ef_scene_add(&s, "exp:density=0.05:color=0,0.5,1", &err), 0);
    const double want[3] = { 0.02 / 0.07, 0.5, 0.05 / 0.07 };
    ef_fog_sample surf, inf;
    ef_ray near = ray(10, 10), sky = ray(INFINITY, INFINITY);
    ef_scene_eval(&s, &near, &surf, &inf);
    for (int k = 0; k < 3; ++k) {
        assert_close(surf.F[k], want[k], 1e-15);
        assert_close(inf.F[k], want[k], 1e-15);
    }
    ef_scene_eval(&s, &sky, &surf, NULL);
    for (int k = 0; k < 3; ++k)
        assert_close(surf.F[k], want[k], 1e-15);
    /* A glFog wall (linear end) in front of the sky takes the colour. */
    ef_scene_free(&s);
    scene_with(&s, "linear:start=0:end=5:color=0.1,0.2,0.3");
    assert_int_equal(ef_scene_add(&s, "exp:density=0.001:color=1,1,1", &err), 0);
    ef_scene_eval(&s, &sky, &surf, NULL);
    assert_close(surf.F[0], 0.1, 1e-15);
    assert_close(surf.F[2], 0.3, 1e-15);
    ef_scene_free(&s);
}

static void test_huge_plane_coefficients(void **state)
{
    (void) state;
    /* 3e200 y - 6e200 < 0 is y < 2: the normal's length must not overflow. */
    ef_fog_component c;
    ef_err err;
    assert_int_equal(ef_fog_parse("halfspace:plane=0,3e200,0,-6e200:density=1", NULL, &c, &err), 0);
    ef_ray r = { { 0, -1, 0 }, 2, 2, { 0, 3, 0 } };
    double t[3];
    c.model->tau(&c, &r, t);
    assert_close(t[0], 1.0, 1e-15);
    ef_fog_free(&c);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_exp_neg),
        cmocka_unit_test(test_exp),
        cmocka_unit_test(test_exp2),
        cmocka_unit_test(test_linear),
        cmocka_unit_test(test_per_channel_and_sum),
        cmocka_unit_test(test_sky_limits),
        cmocka_unit_test(test_composite),
        cmocka_unit_test(test_spec_errors),
        cmocka_unit_test(test_spec_ok),
        cmocka_unit_test(test_colour_mix_at_infinity),
        cmocka_unit_test(test_huge_plane_coefficients),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
