/* Layered fog (seed 004): density piecewise linear in height between knots,
 * constant beyond the ends. Expected values are trapezoids worked out by
 * hand: a segment climbing at rate s over heights u0..u1 has optical depth
 * (integral of sigma from u0 to u1) / s. The ramp used most is
 * heights=0,10:densities=0,1, i.e. sigma(u) = u/10 on [0,10], 0 below and 1
 * above, so integral_a^b sigma = (b^2 - a^2)/20 inside it. */
#include <errno.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "fog.h"
#include "tassert.h"
#include "tfog.h"
#include "testutil.h"

#define RAMP "layered:heights=0,10:densities=0,1"

#define assert_rel(a, b, rel) assert_close((a), (b), (rel) * fabs((double) (b)))

/* Parses spec into c, releasing what c held (c starts zeroed). */
static void parse(const char *spec, const ef_fog_context *ctx, ef_fog_component *c)
{
    ef_err err;
    ef_fog_free(c);
    if (ef_fog_parse(spec, ctx, c, &err))
        fail_msg("'%s' did not parse: %s", spec, err.msg);
}

static void test_ramp(void **state)
{
    (void) state;
    ef_fog_component c = { 0 };
    parse(RAMP, NULL, &c);
    /* Vertical: 0..10 is 100/20 = 5; 0..20 adds 10 at density 1. */
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 10), 5, 1e-15);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 20), 15, 1e-15);
    /* -5..15: nothing below 0, 5 in the ramp, 5 above. */
    assert_rel(tau1(&c, 0, -5, 0, 0, 1, 0, 20), 10, 1e-15);
    /* Down from 10 to 0 is the same as up. */
    assert_rel(tau1(&c, 0, 10, 0, 0, -1, 0, 10), 5, 1e-15);
    /* 3-4-5 inside the ramp: heights 0..4, (16/20)/0.8 = 1. */
    assert_rel(tau1(&c, 0, 0, 0, 0.6, 0.8, 0, 5), 1, 1e-15);
    /* Crossing the top knot: heights 5..13 = 75/20 + 3 = 6.75, / 0.8. */
    assert_rel(tau1(&c, 0, 5, 0, 0.6, 0.8, 0, 10), 8.4375, 1e-15);
    assert_rel(tau1(&c, 6, 13, 0, -0.6, -0.8, 0, 10), 8.4375, 1e-15);
    /* Crossing both knots at s = 0.8: heights -4..12 = 5 + 2, / 0.8. */
    assert_rel(tau1(&c, 0, -4, 0, 0, 0.8, 0.6, 20), 8.75, 1e-15);
    /* Zero length. */
    assert_true(tau1(&c, 0, 5, 0, 0, 1, 0, 0) == 0);

    /* The paper's thin ground layer: 0 at 0, 2 from 1 to 2, 0 at 3. */
    parse("layered:heights=0,1,2,3:densities=0,2,2,0", NULL, &c);
    /* Whole profile: 1 + 2 + 1 = 4; slanted s = 0.8: 5. */
    assert_rel(tau1(&c, 0, -1, 0, 0, 1, 0, 5), 4, 1e-15);
    assert_rel(tau1(&c, 0, -1, 0, 0.6, 0.8, 0, 5), 5, 1e-15);
    /* 0.5..2.5: (1 - 0.25) + 2 + (1 - 0.25) = 3.5. */
    assert_rel(tau1(&c, 0, 0.5, 0, 0, 1, 0, 2), 3.5, 1e-15);
    /* Starting and ending exactly on knots: 1..2 = 2. */
    assert_rel(tau1(&c, 0, 1, 0, 0, 1, 0, 1), 2, 1e-15);
    assert_rel(tau1(&c, 0, 2, 0, 0, -1, 0, 1), 2, 1e-15);
    ef_fog_free(&c);
}

static void test_ends_and_horizontal(void **state)
{
    (void) state;
    ef_fog_component c = { 0 };
    parse("layered:heights=0,10:densities=0.5,1", NULL, &c);
    /* Constant beyond the ends: 0.5 below, 1 above. */
    assert_rel(tau1(&c, 0, -100, 0, 1, 0, 0, 7), 3.5, 1e-15);
    assert_rel(tau1(&c, 0, 100, 0, 0, 0, 1, 7), 7, 1e-15);
    assert_rel(tau1(&c, 0, -50, 0, 0, 1, 0, 10), 5, 1e-15);
    /* -10..20: 10 * 0.5 + 10 * 0.75 + 10 * 1 = 22.5. */
    assert_rel(tau1(&c, 0, -10, 0, 0, 1, 0, 30), 22.5, 1e-15);
    /* Horizontal inside: sigma(2.5) = 0.5 + 0.25 * 0.5 = 0.625. */
    assert_rel(tau1(&c, 3, 2.5, -1, 1, 0, 1, 8), 5, 1e-15);
    /* Horizontal exactly on a knot. */
    assert_rel(tau1(&c, 0, 10, 0, 1, 0, 0, 3), 3, 1e-15);
    parse(RAMP, NULL, &c);
    assert_true(tau1(&c, 0, -3, 0, 1, 0, 0, 4) == 0);
    assert_true(tau1(&c, 0, 0, 0, 1, 0, 0, 4) == 0);
    assert_rel(tau1(&c, 0, 2.5, 0, 1, 0, 0, 4), 1, 1e-15);
    ef_fog_free(&c);
}

static void test_sky(void **state)
{
    (void) state;
    ef_fog_component c = { 0 };
    parse(RAMP, NULL, &c);
    /* Density 1 above the top: going up never ends. */
    assert_true(isinf(tau1(&c, 0, 5, 0, 0, 1, 0, INFINITY)));
    assert_true(isinf(tau1(&c, 0, -5, 0, 0.6, 0.8, 0, INFINITY)));
    /* Down to density 0 below the bottom: 25/20 = 1.25, slanted / 0.8. */
    assert_rel(tau1(&c, 0, 5, 0, 0, -1, 0, INFINITY), 1.25, 1e-15);
    assert_rel(tau1(&c, 0, 5, 0, 0.6, -0.8, 0, INFINITY), 1.5625, 1e-15);
    /* From above the top: the whole ramp (5) plus 2 at density 1. */
    assert_rel(tau1(&c, 0, 12, 0, 0, -1, 0, INFINITY), 7, 1e-15);
    /* Already below: nothing. */
    assert_true(tau1(&c, 0, -1, 0, 0, -1, 0, INFINITY) == 0);
    /* Horizontal: opaque where sigma > 0, clear where it is 0. */
    assert_true(isinf(tau1(&c, 0, 5, 0, 1, 0, 0, INFINITY)));
    assert_true(tau1(&c, 0, -1, 0, 1, 0, 0, INFINITY) == 0);
    assert_true(tau1(&c, 0, 0, 0, 1, 0, 0, INFINITY) == 0);

    /* Thinning upwards to 0: up-going rays leave it. */
    parse("layered:heights=0,10:densities=1,0", NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, INFINITY), 5, 1e-15);
    assert_rel(tau1(&c, 0, 0, 0, 0.6, 0.8, 0, INFINITY), 6.25, 1e-15);
    /* From -3: 3 at density 1, then the ramp. */
    assert_rel(tau1(&c, 0, -3, 0, 0, 1, 0, INFINITY), 8, 1e-15);
    assert_true(tau1(&c, 0, 20, 0, 0, 1, 0, INFINITY) == 0);
    assert_true(tau1(&c, 0, 10, 0, 1, 0, 0, INFINITY) == 0);
    assert_true(isinf(tau1(&c, 0, 9, 0, 1, 0, 0, INFINITY)));
    assert_true(isinf(tau1(&c, 0, 20, 0, 0, -1, 0, INFINITY)));

    /* A layer between 1 and 3, clear above and below: finite both ways. */
    parse("layered:heights=1,2,3:densities=0,4,0", NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, INFINITY), 4, 1e-15);
    assert_rel(tau1(&c, 0, 10, 0, 0.6, -0.8, 0, INFINITY), 5, 1e-15);
    assert_rel(tau1(&c, 0, 2, 0, 0, 1, 0, INFINITY), 2, 1e-15);
    ef_fog_free(&c);
}

static void test_channels(void **state)
{
    (void) state;
    ef_fog_component c = { 0 };
    double t[3];
    /* R ramps 0 -> 1, G is 1 throughout, B goes 2 -> 1. */
    parse("layered:heights=0,10:densities=0/1/2,1", NULL, &c);
    tau_of(&c, 0, 0, 0, 0, 1, 0, 10, t);
    assert_rel(t[0], 5, 1e-15);
    assert_rel(t[1], 10, 1e-15);
    assert_rel(t[2], 15, 1e-15);
    tau_of(&c, 0, 10, 0, 0, -1, 0, INFINITY, t);
    assert_rel(t[0], 5, 1e-15);
    assert_true(isinf(t[1]) && isinf(t[2]));
    tau_of(&c, 0, -1, 0, 1, 0, 0, INFINITY, t);
    assert_true(t[0] == 0 && isinf(t[1]) && isinf(t[2]));
    tau_of(&c, 0, 0, 0, 1, 0, 0, 2, t);
    assert_true(t[0] == 0);
    assert_rel(t[1], 2, 1e-15);
    assert_rel(t[2], 4, 1e-15);
    /* Spaces after numbers are accepted as in the other lists. */
    parse("layered:heights=0, 10:densities=0 /1 /2 , 1", NULL, &c);
    tau_of(&c, 0, 0, 0, 0, 1, 0, 10, t);
    assert_rel(t[2], 15, 1e-15);
    ef_fog_free(&c);
}

static void test_one_knot_is_exp(void **state)
{
    (void) state;
    ef_fog_component l = { 0 }, e = { 0 };
    parse("layered:heights=3:densities=0.25", NULL, &l);
    parse("exp:density=0.25", NULL, &e);
    static const double rays[][7] = {
        { 0, 0, 0, 0.6, 0.8, 0, 7 },     { 1, 2, 3, 0, -1, 0, 12.5 },
        { 0, -50, 0, 0, 1, 0, 1e4 },     { 1e7, 1e7, -1e7, 0.3, -0.2, 0.9, 3 },
        { 0, 5, 0, 1, 0, 0, 2 },         { 0, 0, 0, 0, 1, 0, 0 },
        { 0, 0, 0, 0, 1, 0, INFINITY },
    };
    for (size_t i = 0; i < sizeof rays / sizeof rays[0]; ++i) {
        const double *q = rays[i];
        const double t = tau1(&l, q[0], q[1], q[2], q[3], q[4], q[5], q[6]);
        assert_true(t == 0.25 * q[6]);
        assert_true(t == tau1(&e, q[0], q[1], q[2], q[3], q[4], q[5], q[6]));
    }
    parse("layered:heights=3:densities=0", NULL, &l);
    assert_true(tau1(&l, 0, 0, 0, 0, -1, 0, INFINITY) == 0);
    ef_fog_free(&l);
    ef_fog_free(&e);
}

static void test_grazing_and_far(void **state)
{
    (void) state;
    ef_fog_component c = { 0 };
    double t[3];
    parse(RAMP, NULL, &c);
    /* Climbing 1e-12 per unit over 1000 from height 5: no knot inside, the
     * trapezoid in t: 1000 (0.5 + 0.5 + 1e-10)/2. */
    ef_ray r = { { 1, 1e-12, 0 }, 1000, 1000, { 0, 5, 0 } };
    c.model->tau(&c, &r, t);
    assert_rel(t[0], 500.00000005, 1e-15);
    /* Exactly horizontal, same place. */
    r.dir[1] = 0;
    c.model->tau(&c, &r, t);
    assert_rel(t[0], 500, 1e-15);
    /* Crossing the top knot at 1e-12 per unit, from delta below it:
     * [delta - delta^2/20 + (1e-9 - delta)]/1e-12 = 1000 - delta^2/(20e-12). */
    const double y0 = 10 - 1e-10, delta = 10 - y0;
    r.dir[1] = 1e-12;
    r.org[1] = y0;
    c.model->tau(&c, &r, t);
    assert_rel(t[0], 1000 - delta * delta / 20e-12, 1e-15);
    /* The same, walked back down from the far end. */
    r.org[0] = 1000;
    r.org[1] = y0 + 1e-9;
    r.dir[0] = -1;
    r.dir[1] = -1e-12;
    const double delta2 = r.org[1] - 10;    /* the part above the knot */
    c.model->tau(&c, &r, t);
    assert_rel(t[0], 1000 - (1e-9 - delta2) * (1e-9 - delta2) / 20e-12, 1e-13);

    /* Far from the origin: the ramp at 1e7, camera at x, z = 1e7. */
    parse("layered:heights=10000000,10000010:densities=0,1", NULL, &c);
    assert_rel(tau1(&c, 1e7, 1e7, -1e7, 0, 1, 0, 10), 5, 1e-15);
    assert_rel(tau1(&c, 1e7, 1e7 + 5, 1e7, 0.6, 0.8, 0, 10), 8.4375, 1e-15);
    assert_rel(tau1(&c, -1e7, 1e7 + 5, 1e7, 0, -1, 0, INFINITY), 1.25, 1e-15);
    /* A short hop across the knot at 1e7 + 10: 0.25 below it, 0.75 above
     * over 1 unit: (0.25 (0.975 + 1) + 0.75)/1 ... heights 9.75..10.75. */
    assert_rel(tau1(&c, 0, 1e7 + 9.75, 0, 0, 1, 0, 1), 0.25 * (0.975 + 1) / 2 + 0.75, 1e-14);
    ef_fog_free(&c);
}

static void test_up_and_units(void **state)
{
    (void) state;
    ef_fog_component c = { 0 };
    parse(RAMP ":up=z", NULL, &c);
    assert_rel(tau1(&c, 5, 5, 0, 0, 0, 1, 10), 5, 1e-15);
    assert_rel(tau1(&c, 0, 0, 5, 0, 1, 0, 4), 2, 1e-15);
    assert_true(isinf(tau1(&c, 0, 0, 5, 0, 0, 1, INFINITY)));
    /* The scene's up applies without up=. */
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.up[0] = 0, ctx.up[1] = 0, ctx.up[2] = 1;
    parse(RAMP, &ctx, &c);
    assert_rel(tau1(&c, 0, 0, 5, 0, 1, 0, 4), 2, 1e-15);
    /* -y: height is -y. */
    parse(RAMP ":up=-y", NULL, &c);
    assert_rel(tau1(&c, 0, -5, 0, 1, 0, 0, 2), 1, 1e-15);
    assert_rel(tau1(&c, 0, 0, 0, 0, -1, 0, 10), 5, 1e-15);
    assert_rel(tau1(&c, 0, -5, 0, 0, 1, 0, INFINITY), 1.25, 1e-15);

    /* cm: densities per metre (1/m = 0.01/unit), heights in scene units. */
    ef_fog_context cm;
    ef_fog_context_init(&cm);
    cm.units_per_meter = 100;
    parse("layered:heights=0,1000:densities=0,1", &cm, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 1000), 5, 1e-15);
    assert_rel(tau1(&c, 0, 2000, 0, 1, 0, 0, 300), 3, 1e-15);
    ef_fog_free(&c);
}

static void test_reference_interface(void **state)
{
    (void) state;
    ef_fog_component c = { 0 };
    ef_fog_context cm;
    ef_fog_context_init(&cm);
    cm.units_per_meter = 2;
    parse("layered:heights=-1,0,4:densities=2,0/1/2,6:up=z", &cm, &c);
    ef_fog_functional f[2];
    assert_int_equal(c.model->functionals(&c, f, 2), 1);
    /* Heights are measured from the first knot (-1), for precision far away. */
    assert_true(f[0].n[0] == 0 && f[0].n[1] == 0 && f[0].n[2] == 1 && f[0].d == 1);
    ef_fog_feature ft[4];
    assert_int_equal(c.model->features(&c, ft, 4), 3);
    assert_true(ft[0].value == 0 && ft[1].value == 1 && ft[2].value == 5);
    assert_true(ft[0].scale == 0 && ft[2].scale == 0 && ft[1].f == 0);
    assert_int_equal(c.model->features(&c, ft, 1), 3);    /* count even past cap */
    /* Densities per unit are half the per-metre ones. */
    long double v, out[3];
    v = -INFINITY;
    c.model->density(&c, &v, out);
    assert_true(out[0] == 1 && out[1] == 1 && out[2] == 1);
    v = INFINITY;
    c.model->density(&c, &v, out);
    assert_true(out[0] == 3 && out[2] == 3);
    v = 2;      /* height 1: a quarter of the way from 0 to 4 */
    c.model->density(&c, &v, out);
    assert_true(fabsl(out[0] - 0.75L) < 1e-18L && fabsl(out[1] - 1.125L) < 1e-18L &&
                fabsl(out[2] - 1.5L) < 1e-18L);
    v = 0.5;    /* height -0.5 */
    c.model->density(&c, &v, out);
    assert_true(fabsl(out[0] - 0.5L) < 1e-18L && fabsl(out[2] - 1.0L) < 1e-18L);

    /* A copy owns its own table. */
    ef_fog_component d;
    assert_int_equal(ef_fog_copy(&d, &c), 0);
    ef_fog_free(&c);
    double t[3];
    tau_of(&d, 0, 0, 0, 0, 0, 1, 4, t);     /* 4 (0 + 3)/2, 4 (0.5 + 3)/2, 4 (1 + 3)/2 */
    assert_rel(t[0], 6, 1e-15);
    assert_rel(t[1], 7, 1e-15);
    assert_rel(t[2], 8, 1e-15);
    ef_fog_free(&d);
}

static void expect_error(const char *spec, const ef_fog_context *ctx, const char *quote)
{
    ef_fog_component c = { 0 };
    ef_err err;
    err.file = NULL;
    assert_int_equal(ef_fog_parse(spec, ctx, &c, &err), -1);
    if (!strstr(err.msg, quote))
        fail_msg("error for '%s' does not say '%s': %s", spec, quote, err.msg);
}

static void test_spec_errors(void **state)
{
    (void) state;
    expect_error("layered:heights=0,0:densities=1,1", NULL, "heights='0,0'");
    expect_error("layered:heights=0,0:densities=1,1", NULL, "increase strictly");
    expect_error("layered:heights=0,2,1:densities=1,1,1", NULL, "point 3, 1, is not above 2");
    expect_error("layered:heights=0,1:densities=1,-1", NULL, "densities='1,-1'");
    expect_error("layered:heights=0,1:densities=1,-1", NULL, "negative");
    expect_error("layered:heights=0,1:densities=1,0.1/-2/0.1", NULL, "entry 2 is negative");
    expect_error("layered:heights=0,1:densities=1", NULL, "2 heights but 1 densities");
    expect_error("layered:heights=0,1", NULL, "missing densities");
    expect_error("layered:densities=1", NULL, "missing heights");
    expect_error("layered", NULL, "missing heights");
    expect_error("layered:heights=0,a:densities=1,1", NULL, "heights='0,a'");
    expect_error("layered:heights=0,,1:densities=1,1,1", NULL, "heights='0,,1'");
    expect_error("layered:heights=0,1:densities=1,2/3", NULL, "densities='1,2/3'");
    expect_error("layered:heights=0,1:densities=1,2/3/4/5", NULL, "R/G/B");
    expect_error("layered:heights=0,1:densities=1,", NULL, "densities='1,'");
    expect_error("layered:heights=0,1:densities=1,2:densities=1,2", NULL, "twice");
    expect_error("layered:file=p.txt:heights=0", NULL, "exclusive");
    expect_error("layered:heights=0:densities=1:file=p.txt", NULL, "exclusive");
    expect_error("layered:heights=-1e308,1e308:densities=1,1", NULL, "too far apart");
    expect_error("layered:heights=0,1e300:densities=1e10,1e10", NULL, "overflows");
    expect_error("layered:heights=0:densities=1:falloff=1", NULL, "'falloff'");
    /* The core does no I/O: without a reader, file= is refused. */
    expect_error("layered:file=p.txt", NULL, "file= cannot be read here");
}

/* Long lists (the spec may hold thousands of characters): a comb of 1000
 * knots, density 0 at even heights and 1 at odd ones, integrates to 0.5 per
 * unit; an error late in a long list still names the point. */
static void test_long_lists(void **state)
{
    (void) state;
    static char spec[8192];
    size_t len = (size_t) snprintf(spec, sizeof spec, "layered:heights=");
    for (int i = 0; i < 1000; ++i)
        len += (size_t) snprintf(spec + len, sizeof spec - len, "%s%d", i ? "," : "", i);
    len += (size_t) snprintf(spec + len, sizeof spec - len, ":densities=");
    for (int i = 0; i < 1000; ++i)
        len += (size_t) snprintf(spec + len, sizeof spec - len, "%s%d", i ? "," : "", i % 2);
    assert_true(len < sizeof spec - 1);
    ef_fog_component c = { 0 };
    parse(spec, NULL, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 999), 499.5, 1e-15);
    /* 10.5 .. 990.25: 0.5 * (979.75) corrected at both partial ends:
     * [10.5, 11]: sigma from 0.5 to 1, 0.375; [990, 990.25]: 0 to 0.25,
     * 0.03125; whole pieces 11..990: 489.5. */
    assert_rel(tau1(&c, 0, 10.5, 0, 0.6, 0.8, 0, (990.25 - 10.5) / 0.8),
               (0.375 + 489.5 + 0.03125) / 0.8, 1e-14);
    assert_true(isinf(tau1(&c, 0, 500, 0, 0, 1, 0, INFINITY)));
    assert_rel(tau1(&c, 0, 500, 0, 0, -1, 0, INFINITY), 250, 1e-15);
    ef_fog_free(&c);
    /* The last height falls back: the message names the point. */
    char *q = strstr(spec, ",999:");
    memcpy(q, ",997", 4);
    ef_err err;
    assert_int_equal(ef_fog_parse(spec, NULL, &c, &err), -1);
    assert_contains(err.msg, "point 1000, 997, is not above 998");
    assert_contains(err.msg, "heights='0,1,2,3");
}

/* ---- profile files ---- */

static int reads;

/* The test's reader: the whole file with stdio; fails like the CLI's does
 * (err->file names the file). */
static int read_text(const char *path, char **text, ef_err *err)
{
    ++reads;
    *text = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) {
        ef_err_set_file(err, path);
        return ef_fail(err, "cannot open (%s)", strerror(errno));
    }
    size_t cap = 256, len = 0;
    char *buf = malloc(cap);
    for (size_t got; (got = fread(buf + len, 1, cap - len - 1, f)) > 0;) {
        len += got;
        if (len + 1 == cap)
            buf = realloc(buf, cap *= 2);
    }
    fclose(f);
    buf[len] = '\0';
    *text = buf;
    return 0;
}

static char *write_profile(const char *name, const char *text)
{
    char *path = tu_path(name);
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
    return path;
}

static void file_spec(char *spec, size_t len, const char *path, const char *extra)
{
    snprintf(spec, len, "layered:file=%s%s", path, extra);
}

static void test_file_profiles(void **state)
{
    (void) state;
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.read_file = read_text;
    char spec[2048];
    ef_fog_component c = { 0 };
    double t[3];

    /* The ramp again, with comments, blank lines, commas and CRLF. */
    char *p = write_profile("layered_ramp.txt", "# ground fog\r\n\r\n0, 0\r\n   \n"
                                                "10\t1   # top\n# end");
    file_spec(spec, sizeof spec, p, "");
    reads = 0;
    parse(spec, &ctx, &c);
    assert_int_equal(reads, 1);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 10), 5, 1e-15);
    assert_rel(tau1(&c, 0, 5, 0, 0.6, 0.8, 0, 10), 8.4375, 1e-15);
    assert_rel(tau1(&c, 0, 5, 0, 0, -1, 0, INFINITY), 1.25, 1e-15);
    ef_fog_free(&c);
    /* up= and units apply to files too. */
    file_spec(spec, sizeof spec, p, ":up=z");
    ctx.units_per_meter = 0.5;      /* 1 per metre = 2 per unit */
    parse(spec, &ctx, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 0, 1, 10), 10, 1e-15);
    ef_fog_free(&c);
    ctx.units_per_meter = 1;
    free(p);

    /* Four columns: per-channel. */
    p = write_profile("layered_rgb.txt", "0 0 1 2\n10,1,1,1\n");
    file_spec(spec, sizeof spec, p, "");
    parse(spec, &ctx, &c);
    tau_of(&c, 0, 0, 0, 0, 1, 0, 10, t);
    assert_rel(t[0], 5, 1e-15);
    assert_rel(t[1], 10, 1e-15);
    assert_rel(t[2], 15, 1e-15);
    ef_fog_free(&c);
    free(p);

    /* A path longer than 255 characters (./ repeated), and the same long
     * path missing: err->file still names it whole. */
    char longp[1024];
    char *dir = tu_path("");
    int at = snprintf(longp, sizeof longp, "%s", dir);
    for (int i = 0; i < 150; ++i)
        at += snprintf(longp + at, sizeof longp - (size_t) at, "./");
    free(dir);
    snprintf(longp + at, sizeof longp - (size_t) at, "layered_ramp.txt");
    assert_true(strlen(longp) > 300);
    file_spec(spec, sizeof spec, longp, ":color=1,1,1");
    parse(spec, &ctx, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 10), 5, 1e-15);
    ef_fog_free(&c);
    snprintf(longp + at, sizeof longp - (size_t) at, "layered_no_such_profile.txt");
    file_spec(spec, sizeof spec, longp, "");
    ef_err err;
    err.file = NULL;
    assert_int_equal(ef_fog_parse(spec, &ctx, &c, &err), -1);
    assert_non_null(err.file);
    assert_string_equal(err.file, longp);

    /* Many points: a sampled parabola sigma = u^2 on [0, 1] in 1000 steps;
     * the interpolant's integral is 1/3 + 1/(6 * 1000^2) (each chord
     * overshoots by h^3/6 per piece). */
    size_t cap = 64 * 1001, len = 0;
    char *text = malloc(cap);
    for (int i = 0; i <= 1000; ++i)
        len += (size_t) snprintf(text + len, cap - len, "%.17g %.17g\n", i / 1000.0,
                                 (i / 1000.0) * (i / 1000.0));
    p = write_profile("layered_many.txt", text);
    free(text);
    file_spec(spec, sizeof spec, p, "");
    parse(spec, &ctx, &c);
    assert_rel(tau1(&c, 0, 0, 0, 0, 1, 0, 1), 1.0 / 3 + 1.0 / 6e6, 1e-13);
    /* -1..2 at s = 0.8: nothing below 0, the parabola, 1 above 1. */
    assert_rel(tau1(&c, 0, -1, 0, 0.6, 0.8, 0, 3.75), (1.0 / 3 + 1.0 / 6e6 + 1) / 0.8, 1e-13);
    ef_fog_free(&c);
    free(p);
}

/* Parses a profile file with content text; expects failure with every
 * needle in the message and err.file naming the file. */
static void expect_file_error(const char *name, const char *text, const char *n1,
                              const char *n2)
{
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.read_file = read_text;
    char *p = write_profile(name, text), spec[256];
    file_spec(spec, sizeof spec, p, "");
    ef_fog_component c = { 0 };
    ef_err err;
    err.file = NULL;
    assert_int_equal(ef_fog_parse(spec, &ctx, &c, &err), -1);
    if (!strstr(err.msg, n1) || !strstr(err.msg, n2) || !strstr(err.msg, p))
        fail_msg("error for %s does not say '%s', '%s' and the path: %s", name, n1, n2, err.msg);
    assert_non_null(err.file);
    assert_string_equal(err.file, p);
    free(p);
}

static void test_file_errors(void **state)
{
    (void) state;
    expect_file_error("layered_nonmono.txt", "0 0\n5 1\n5 2\n", "line 3",
                      "5 is not above 5 on line 2");
    expect_file_error("layered_down.txt", "# c\n0 0\n\n-1 2\n", "line 4", "-1 is not above 0");
    expect_file_error("layered_badnum.txt", "0 0\n# comment\n1 abc\n", "line 3", "'abc'");
    expect_file_error("layered_badnum2.txt", "0 0\n1 1.5.2\n", "line 2", "'1.5.2'");
    expect_file_error("layered_inf.txt", "0 inf\n", "line 1", "'inf'");
    expect_file_error("layered_empty.txt", "", "has no points", "height density");
    expect_file_error("layered_comments.txt", "# nothing\n\n   # here\n", "has no points", "#");
    expect_file_error("layered_neg.txt", "0 1\n1 -0.5\n", "line 2", "negative");
    expect_file_error("layered_neg_rgb.txt", "0 1 1 1\n1 1 -2 1\n", "line 2", "negative");
    expect_file_error("layered_cols.txt", "0 1 2\n", "line 1", "has 3 values");
    expect_file_error("layered_one.txt", "0 0\n7\n", "line 2", "has 1 value ");
    expect_file_error("layered_five.txt", "0 0 0 0 0\n", "line 1", "more than 4 values");
    expect_file_error("layered_mixed.txt", "0 1\n1 1 1 1\n", "line 2", "but line 1 has 2");
    expect_file_error("layered_comma.txt", "0,,1\n", "line 1", "empty value");
    expect_file_error("layered_trail.txt", "0 1\n1 1,\n", "line 2", "ends with ','");

    /* A file that cannot be read: the reader's error and err->file stay. */
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.read_file = read_text;
    char *p = tu_path("layered_missing_no_such_file.txt"), spec[256];
    remove(p);
    file_spec(spec, sizeof spec, p, "");
    ef_fog_component c = { 0 };
    ef_err err;
    err.file = NULL;
    assert_int_equal(ef_fog_parse(spec, &ctx, &c, &err), -1);
    assert_contains(err.msg, "cannot open");
    assert_non_null(err.file);
    assert_string_equal(err.file, p);
    free(p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ramp),
        cmocka_unit_test(test_ends_and_horizontal),
        cmocka_unit_test(test_sky),
        cmocka_unit_test(test_channels),
        cmocka_unit_test(test_one_knot_is_exp),
        cmocka_unit_test(test_grazing_and_far),
        cmocka_unit_test(test_up_and_units),
        cmocka_unit_test(test_reference_interface),
        cmocka_unit_test(test_spec_errors),
        cmocka_unit_test(test_long_lists),
        cmocka_unit_test(test_file_profiles),
        cmocka_unit_test(test_file_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
