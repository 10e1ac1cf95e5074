/* Exponential height fog, sigma = rho e^(-k (height - base)), against values
 * integrated by hand. With k = ln 2 the density halves per unit of height,
 * so a vertical unit from the base gives integral_0^1 2^-u du = 1/(2 ln 2),
 * and a ray climbing at rate s over heights u0..u1 gives
 * (2^-u0 - 2^-u1)/(s ln 2). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "fog.h"
#include "tassert.h"
#include "tfog.h"

#define LN2_TEXT "0.6931471805599453"
#define LN2 0.69314718055994530942
#define LN10 2.30258509299404568402
#define SQRT2 1.41421356237309504880
#define SQRT1_2 0.70710678118654752440

/* |a - b| <= rel |b| (b finite). */
#define assert_rel(a, b, rel) assert_close((a), (b), (rel) * fabs((double) (b)))

static void parse(const char *spec, const ef_fog_context *ctx, ef_fog_component *c)
{
    ef_err err;
    if (ef_fog_parse(spec, ctx, c, &err))
        fail_msg("'%s' did not parse: %s", spec, err.msg);
}

static void test_falloff_zero_is_exp(void **state)
{
    (void) state;
    ef_fog_component h, e;
    parse("height:density=0.3:falloff=0:base=5", NULL, &h);
    parse("exp:density=0.3", NULL, &e);
    static const double rays[][7] = {
        { 0, 0, 0, 0.6, 0.8, 0, 7 },     { 1, 2, 3, 0, -1, 0, 12.5 },
        { 0, -50, 0, 0, 1, 0, 1e4 },     { 1e7, 1e7, -1e7, 0.3, -0.2, 0.9, 3 },
        { 0, 5, 0, 1, 0, 0, 2 },         { 0, 0, 0, 0, 1, 0, 0 },
    };
    for (size_t i = 0; i < sizeof rays / sizeof rays[0]; ++i) {
        const double *q = rays[i];
        const double t = tau1(&h, q[0], q[1], q[2], q[3], q[4], q[5], q[6]);
        assert_true(t == 0.3 * q[6]);
        assert_true(t == tau1(&e, q[0], q[1], q[2], q[3], q[4], q[5], q[6]));
    }
    /* Uniform fog never ends: every sky ray is opaque. */
    assert_true(isinf(tau1(&h, 0, 0, 0, 0, 1, 0, INFINITY)));
    assert_true(isinf(tau1(&h, 0, 0, 0, 0, -1, 0, INFINITY)));
    ef_fog_free(&h);
    ef_fog_free(&e);
}

static void test_vertical_and_345(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("height:density=1:falloff=" LN2_TEXT, NULL, &c);
    /* Up one unit from the base, and the same unit downwards. */
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 1), 0.5 / LN2, 4e-16);
    assert_rel(tau1(&c, 0, 1, 0, 0, -1, 0, 1), 0.5 / LN2, 4e-16);
    /* Two units: (1 - 1/4)/ln 2. */
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 2), 0.75 / LN2, 4e-16);
    /* Three units up the density is 1/8. */
    assert_rel(tau1(&c, 5, 3, -2, 0, 1, 0, 1), 0.0625 / LN2, 4e-16);
    /* Below the base the density grows: from -1 to 0 it is (2 - 1)/ln 2. */
    assert_rel(tau1(&c, 0, -1, 0, 0, 1, 0, 1), 1 / LN2, 4e-16);
    /* 3-4-5: climbing 4 over length 5, s = 0.8: (1 - 1/16)/(0.8 ln 2). */
    assert_rel(tau1(&c, 0, 0, 0, 0.6, 0.8, 0, 5), (15.0 / 16.0) / (0.8 * LN2), 1e-15);
    /* The same segment walked downwards. */
    assert_rel(tau1(&c, 3, 4, 0, -0.6, -0.8, 0, 5), (15.0 / 16.0) / (0.8 * LN2), 1e-15);
    /* Horizontal at height 2: density 1/4 all along. */
    assert_rel(tau1(&c, 0, 2, 0, 1, 0, 0, 10), 2.5, 4e-16);
    /* Zero length: nothing. */
    assert_true(tau1(&c, 0, -3000, 0, 0, 1, 0, 0) == 0.0);

    /* base moves the curve: base=10 at y=10 is the base. */
    ef_fog_component b;
    parse("height:density=1:falloff=" LN2_TEXT ":base=10", NULL, &b);
    assert_rel(tau1(&b, 0, 10, 0, 0, 1, 0, 1), 0.5 / LN2, 4e-16);
    assert_rel(tau1(&b, 0, 11, 0, 0, 1, 0, 1), 0.25 / LN2, 4e-16);
    ef_fog_free(&b);
    parse("height:density=1:falloff=" LN2_TEXT ":base=-1", NULL, &b);
    assert_rel(tau1(&b, 0, 0, 0, 0.6, 0.8, 0, 5), 0.5 * (15.0 / 16.0) / (0.8 * LN2), 1e-15);
    ef_fog_free(&c);
    ef_fog_free(&b);
}

static void test_sky(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("height:density=1:falloff=" LN2_TEXT, NULL, &c);
    /* Up-going: rho e^(-k u0)/(k s). */
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, INFINITY), 1 / LN2, 4e-16);
    assert_rel(tau1(&c, 0, 1, 0, 0.6, 0.8, 0, INFINITY), 0.5 / (0.8 * LN2), 1e-15);
    assert_rel(tau1(&c, 0, -2, 0, 0, 1, 0, INFINITY), 4 / LN2, 4e-16);
    /* Down-going and horizontal rays stay in fog forever. */
    assert_true(isinf(tau1(&c, 0, 0, 0, 0.6, -0.8, 0, INFINITY)));
    assert_true(isinf(tau1(&c, 0, 50, 0, 1, 0, 0, INFINITY)));
    /* No fog stays no fog, and channels keep their own limits. */
    ef_fog_free(&c);
    parse("height:density=0,1,2:falloff=" LN2_TEXT, NULL, &c);
    double t[3];
    tau_of(&c, 0, 1, 0, 0, -1, 0, INFINITY, t);
    assert_true(t[0] == 0 && isinf(t[1]) && isinf(t[2]));
    tau_of(&c, 0, 1, 0, 0, 1, 0, INFINITY, t);
    assert_true(t[0] == 0);
    assert_rel(t[1], 0.5 / LN2, 4e-16);
    assert_rel(t[2], 1 / LN2, 4e-16);
    /* A tiny up-going slope: finite, huge. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=1", NULL, &c);
    ef_ray r = { { 1, 1e-300, 0 }, INFINITY, INFINITY, { 0, 0, 0 } };
    c.model->tau(&c, &r, t);
    assert_rel(t[0], 1e300, 1e-15);
    r.dir[1] = 1e-310;       /* k s is subnormal: 1/(k s) overflows */
    c.model->tau(&c, &r, t);
    assert_true(isinf(t[0]));
    r.org[1] = 800;          /* ... but e^-800 brings it back: e^-800 / 1e-310 */
    c.model->tau(&c, &r, t);
    assert_rel(t[0], exp(-800 + 310 * LN10), 1e-12);
    ef_fog_free(&c);
}

static void test_up_axes(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("height:density=1:falloff=" LN2_TEXT ":up=z", NULL, &c);
    assert_rel(tau1(&c, 4, 100, 0, 0, 0, 1, 1), 0.5 / LN2, 4e-16);
    /* Along y is horizontal when z is up: density at z = 1 is 1/2. */
    assert_rel(tau1(&c, 0, 0, 1, 0, 1, 0, 6), 3, 4e-16);
    assert_rel(tau1(&c, 0, 0, 0, 0.8, 0, 0.6, INFINITY), 1 / (0.6 * LN2), 1e-15);

    /* The context's up applies when the spec has none. */
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.up[0] = 0, ctx.up[1] = 0, ctx.up[2] = 1;
    ef_fog_free(&c);
    parse("height:density=1:falloff=" LN2_TEXT, &ctx, &c);
    assert_rel(tau1(&c, 0, 0, 1, 0, 1, 0, 6), 3, 4e-16);
    /* ... and an up= key overrides it. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=" LN2_TEXT ":up=y", &ctx, &c);
    assert_rel(tau1(&c, 0, 1, 7, 1, 0, 0, 6), 3, 4e-16);

    /* -y: height is -y, so going towards -y climbs. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=" LN2_TEXT ":up=-y", NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, -1, 0, 1), 0.5 / LN2, 4e-16);
    assert_rel(tau1(&c, 0, 1, 0, 1, 0, 0, 3), 6, 4e-16);        /* height -1: density 2 */
    assert_true(isinf(tau1(&c, 0, 0, 0, 0, 1, 0, INFINITY)));
    assert_rel(tau1(&c, 0, 0, 0, 0, -1, 0, INFINITY), 1 / LN2, 4e-16);

    /* An oblique up: (1,1,0)/sqrt 2; the ray along x climbs at 1/sqrt 2. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=" LN2_TEXT ":up=1,1,0", NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 1, 0, 0, SQRT2), 0.5 / (SQRT1_2 * LN2), 1e-15);
    ef_fog_free(&c);
}

static void test_extremes(void **state)
{
    (void) state;
    ef_fog_component c;
    double t[3];
    parse("height:density=1:falloff=1", NULL, &c);
    /* e^(1e6) overflows: INFINITY, never NaN. */
    assert_true(isinf(tau1(&c, 0, -1e6, 0, 1, 0, 0, 1)));
    assert_true(isinf(tau1(&c, 0, -1e6, 0, 0, 1, 0, 2e6)));
    assert_true(isinf(tau1(&c, 0, -1e6, 0, 0, 1, 0, INFINITY)));
    assert_true(tau1(&c, 0, -1e6, 0, 0, 1, 0, 0) == 0);
    /* e^(-1e6) underflows: 0. */
    assert_true(tau1(&c, 0, 1e6, 0, 1, 0, 0, 1) == 0);
    assert_true(tau1(&c, 0, 1e6, 0, 0, -1, 0, 1e5) == 0);
    assert_true(tau1(&c, 0, 1e6, 0, 0, 1, 0, INFINITY) == 0);
    /* Very long segment going up from far below: still INFINITY. */
    assert_true(isinf(tau1(&c, 0, -1e6, 0, 0.6, 0.8, 0, 1e300)));
    /* Near the edge of the double range: e^-710 is subnormal, times 1e10
     * must keep its digits. */
    ef_fog_free(&c);
    parse("height:density=1e10:falloff=1", NULL, &c);
    assert_rel(tau1(&c, 0, 710, 0, 1, 0, 0, 1), exp(-710 + 10 * LN10), 1e-12);
    /* ... and e^720 overflows alone but 1e-300 e^720 does not. */
    ef_fog_free(&c);
    parse("height:density=1e-300:falloff=1", NULL, &c);
    assert_rel(tau1(&c, 0, -720, 0, 1, 0, 0, 1), exp(720 - 300 * LN10), 1e-12);
    /* A huge falloff: from the base, integral_0^1 e^(-1e300 t) dt = 1e-300. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=1e300", NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 1), 1e-300, 1e-15);
    assert_true(tau1(&c, 0, 0, 0, 1, 0, 0, 2) == 2.0);
    assert_true(tau1(&c, 0, 1, 0, 1, 0, 0, 2) == 0.0);
    assert_true(isinf(tau1(&c, 0, -1, 0, 1, 0, 0, 2)));
    assert_true(isinf(tau1(&c, 0, -1e10, 0, 0, 1, 0, 2)));
    /* A tiny falloff: integral_0^1 e^(-1e-12 t) dt = 1 - 5e-13 + ... */
    ef_fog_free(&c);
    parse("height:density=1:falloff=1e-12", NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 1), 1 - 5e-13, 3e-16);
    /* Grazing: climbing 1e-12 per unit over 1000, density 2^-(1e-12 t):
     * 1000 (1 - ln2 1e-9 / 2) to first order (the next term is ~1e-19). */
    ef_fog_free(&c);
    parse("height:density=1:falloff=" LN2_TEXT, NULL, &c);
    ef_ray r = { { 1, 1e-12, 0 }, 1000, 1000, { 0, 0, 0 } };
    c.model->tau(&c, &r, t);
    assert_rel(t[0], 1000 * (1 - 0.5 * LN2 * 1e-9), 1e-15);
    /* Far from the origin: base 1e7, camera one unit above it at x, z = 1e7. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=" LN2_TEXT ":base=10000000", NULL, &c);
    assert_rel(tau1(&c, 1e7, 1e7 + 1, -1e7, 0, 1, 0, 1), 0.25 / LN2, 4e-16);
    assert_rel(tau1(&c, 1e7, 1e7 + 1, -1e7, 0.6, 0.8, 0, INFINITY), 0.5 / (0.8 * LN2), 1e-15);
    /* Zero density with an exploding exponent: 0, not 0 * inf. */
    ef_fog_free(&c);
    parse("height:density=0:falloff=1", NULL, &c);
    assert_true(tau1(&c, 0, -1e6, 0, 1, 0, 0, 1) == 0);
    assert_true(tau1(&c, 0, -1e6, 0, 1, 0, 0, INFINITY) == 0);
    ef_fog_free(&c);
}

/* The exact additivity of the optical depth, on a segment split at a
 * point: a property of any density, not of the formula used. */
static void test_split_and_reverse(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("height:density=0.2,0.5,1:falloff=0.3:base=2", NULL, &c);
    const double d[3] = { 0.48, 0.6, 0.64 };     /* unit: 0.2304 + 0.36 + 0.4096 */
    double whole[3], a[3], b[3], back[3];
    tau_of(&c, 1, -3, 2, d[0], d[1], d[2], 10, whole);
    tau_of(&c, 1, -3, 2, d[0], d[1], d[2], 4, a);
    tau_of(&c, 1 + 4 * d[0], -3 + 4 * d[1], 2 + 4 * d[2], d[0], d[1], d[2], 6, b);
    tau_of(&c, 1 + 10 * d[0], -3 + 10 * d[1], 2 + 10 * d[2], -d[0], -d[1], -d[2], 10, back);
    for (int i = 0; i < 3; ++i) {
        assert_rel(a[i] + b[i], whole[i], 1e-14);
        assert_rel(back[i], whole[i], 1e-14);
    }
    /* Its value: rho e^(-0.3 (-5)) (1 - e^(-0.3 * 6))/(0.3 * 0.6). */
    assert_rel(whole[0], 0.2 * exp(1.5) * -expm1(-1.8) / 0.18, 1e-14);
    ef_fog_free(&c);
}

static void test_units_visibility_channels(void **state)
{
    (void) state;
    ef_fog_component c;
    ef_fog_context cm;
    ef_fog_context_init(&cm);
    cm.units_per_meter = 100;
    /* In cm, one metre up from the base is 100 units: same 1/(2 ln 2). */
    parse("height:density=1:falloff=" LN2_TEXT, &cm, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 100), 0.5 / LN2, 1e-15);
    /* base is in scene units: base=100 is one metre. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=" LN2_TEXT ":base=100", &cm, &c);
    assert_rel(tau1(&c, 0, 200, 0, 0, 1, 0, 100), 0.25 / LN2, 1e-15);
    assert_rel(tau1(&c, 0, 200, 0, 0, 1, 0, INFINITY), 0.5 / LN2, 1e-15);
    /* Horizontal at the base: 1 per metre over 250 cm. */
    assert_rel(tau1(&c, 0, 100, 0, 1, 0, 0, 250), 2.5, 1e-15);

    /* visibility=V is density 3.912/V per metre. */
    ef_fog_free(&c);
    parse("height:visibility=3.912:falloff=0", NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 1, 0, 0, 2), 2, 1e-15);
    ef_fog_free(&c);
    parse("height:visibility=3.912,1.956,0.978:falloff=" LN2_TEXT, NULL, &c);
    double t[3];
    tau_of(&c, 0, 0, 0, 0, 1, 0, 1, t);
    assert_rel(t[0], 0.5 / LN2, 1e-15);
    assert_rel(t[1], 1 / LN2, 1e-15);
    assert_rel(t[2], 2 / LN2, 1e-15);
    ef_fog_free(&c);
    parse("height:visibility=391.2:falloff=0", &cm, &c);     /* 0.01 per metre */
    assert_rel(tau1(&c, 0, 0, 0, 1, 0, 0, 500), 0.05, 1e-15);

    ef_fog_free(&c);
    parse("height:density=1,2,4:falloff=" LN2_TEXT ":base=1", NULL, &c);
    tau_of(&c, 0, 1, 0, 0, 1, 0, 1, t);
    assert_rel(t[0], 0.5 / LN2, 4e-16);
    assert_rel(t[1], 1 / LN2, 4e-16);
    assert_rel(t[2], 2 / LN2, 4e-16);
    /* color= is the component's own and does not change tau. */
    ef_fog_free(&c);
    parse("height:density=1:falloff=0:color=1,0.5,0.25", NULL, &c);
    assert_true(c.has_color && c.color[1] == 0.5);
    assert_true(tau1(&c, 0, 0, 0, 1, 0, 0, 3) == 3);
    ef_fog_free(&c);
}

static void test_reference_interface(void **state)
{
    (void) state;
    ef_fog_component c;
    ef_fog_context cm;
    ef_fog_context_init(&cm);
    cm.units_per_meter = 2;
    parse("height:density=3:falloff=0.5:base=7:up=z", &cm, &c);
    ef_fog_functional f[2];
    assert_int_equal(c.model->functionals(&c, f, 2), 1);
    assert_true(f[0].n[0] == 0 && f[0].n[1] == 0 && f[0].n[2] == 1 && f[0].d == -7);
    ef_fog_feature ft[2];
    assert_int_equal(c.model->features(&c, ft, 2), 1);
    /* falloff 0.5 per metre = 0.25 per unit: scale 4 units, at the base. */
    assert_true(ft[0].f == 0 && ft[0].value == 0 && ft[0].scale == 4);
    long double v, out[3];
    v = 0;                      /* at the base: 3 per metre = 1.5 per unit */
    c.model->density(&c, &v, out);
    assert_true(out[0] == 1.5L && out[2] == 1.5L);
    v = 4 * logl(2);            /* k v = ln 2: half of 1.5 */
    c.model->density(&c, &v, out);
    assert_true(fabsl(out[1] - 0.75L) < 1e-17L);
    v = INFINITY;
    c.model->density(&c, &v, out);
    assert_true(out[0] == 0);
    v = -INFINITY;
    c.model->density(&c, &v, out);
    assert_true(isinf(out[0]) && out[0] > 0);

    ef_fog_free(&c);
    parse("height:density=0,2,3:falloff=0", NULL, &c);
    assert_int_equal(c.model->features(&c, ft, 2), 0);
    v = -INFINITY;
    c.model->density(&c, &v, out);
    assert_true(out[0] == 0 && out[1] == 2 && out[2] == 3);
    v = INFINITY;
    c.model->density(&c, &v, out);
    assert_true(out[0] == 0 && out[1] == 2 && out[2] == 3);
    ef_fog_free(&c);
}

static void expect_error(const char *spec, const char *quote)
{
    ef_fog_component c;
    ef_err err;
    assert_int_equal(ef_fog_parse(spec, NULL, &c, &err), -1);
    if (!strstr(err.msg, quote))
        fail_msg("error for '%s' does not say '%s': %s", spec, quote, err.msg);
}

static void test_spec_errors(void **state)
{
    (void) state;
    expect_error("height:falloff=1", "missing density");
    expect_error("height:falloff=1", "height:density=D:falloff=K");
    expect_error("height:density=1", "missing falloff");
    expect_error("height:density=1:visibility=3:falloff=1", "not both");
    expect_error("height:density=1:falloff=-0.5", "falloff='-0.5'");
    expect_error("height:density=1:falloff=-0.5", ">= 0");
    expect_error("height:density=1:falloff=fast", "falloff='fast'");
    expect_error("height:density=1:falloff=1,2,3", "falloff='1,2,3'");
    expect_error("height:density=1:falloff=1:base=low", "base='low'");
    expect_error("height:density=-1:falloff=1", "density='-1'");
    expect_error("height:density=1,2:falloff=1", "density='1,2'");
    expect_error("height:visibility=0:falloff=1", "visibility='0'");
    expect_error("height:density=1:falloff=1:heigth=3", "'heigth'");
    expect_error("height:density=1:falloff=1:up=0,0,0", "up='0,0,0'");
    expect_error("height:density=1:falloff=1:distance=planar", "'distance'");
    expect_error("height:density=1:falloff=1:falloff=2", "twice");
    /* base is optional (0), the rest is enough. */
    ef_fog_component c;
    parse("height:density=1:falloff=1", NULL, &c);
    assert_true(c.p[4] == 0);
    ef_fog_free(&c);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_falloff_zero_is_exp),
        cmocka_unit_test(test_vertical_and_345),
        cmocka_unit_test(test_sky),
        cmocka_unit_test(test_up_axes),
        cmocka_unit_test(test_extremes),
        cmocka_unit_test(test_split_and_reverse),
        cmocka_unit_test(test_units_visibility_channels),
        cmocka_unit_test(test_reference_interface),
        cmocka_unit_test(test_spec_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
