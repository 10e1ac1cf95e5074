/* The half-space models (halfspace, halfspace-linear, halfspace-smooth)
 * against values worked out by hand from Lengyel's case table (seed 000),
 * Walker's antiderivative (seed 003, evaluated in long double where it is
 * well conditioned) and exact geometry: 3-4-5 triangles, power-of-two
 * offsets and slopes so the hand values are exact. Values marked "mpmath"
 * are Walker's integral D(x1 - x0) - (D^2/S)(e^(-S x0/D) - e^(-S x1/D))
 * evaluated at 50 digits. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "fog.h"
#include "tassert.h"

static int parse_at(const char *spec, double units_per_meter, ef_fog_component *c, ef_err *err)
{
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.units_per_meter = units_per_meter;
    return ef_fog_parse(spec, &ctx, c, err);
}

static void parse_ok(int line, const char *spec, double upm, ef_fog_component *c)
{
    ef_err err = { .file = NULL };
    if (parse_at(spec, upm, c, &err)) {
        print_error("line %d: '%s' failed: %s\n", line, spec, err.msg);
        fail();
    }
}

static void tau_of(const ef_fog_component *c, double ox, double oy, double oz, double dx,
                   double dy, double dz, double len, double t[3])
{
    const ef_ray r = { { dx, dy, dz }, len, len, { ox, oy, oz } };
    c->model->tau(c, &r, t);
}

/* got within rel * |want| of want; infinities and zeros must match exactly. */
static void check_rel(int line, int ch, double got, double want, double rel)
{
    const int ok = isinf(want) || want == 0.0 ? got == want
                                              : fabs(got - want) <= rel * fabs(want);
    if (!ok) {
        print_error("line %d channel %d: tau = %.17g, expected %.17g (rel %g)\n", line, ch, got,
                    want, rel);
        fail();
    }
}

/* tau of spec (1 unit per metre) on one segment, in all three channels. */
static void chk3(int line, const char *spec, double ox, double oy, double oz, double dx,
                 double dy, double dz, double len, double w0, double w1, double w2, double rel)
{
    ef_fog_component c;
    double t[3];
    parse_ok(line, spec, 1.0, &c);
    tau_of(&c, ox, oy, oz, dx, dy, dz, len, t);
    check_rel(line, 0, t[0], w0, rel);
    check_rel(line, 1, t[1], w1, rel);
    check_rel(line, 2, t[2], w2, rel);
    ef_fog_free(&c);
}

#define CHK(spec, ox, oy, oz, dx, dy, dz, len, want, rel)                                     \
    chk3(__LINE__, spec, ox, oy, oz, dx, dy, dz, len, want, want, want, rel)
#define CHK3(spec, ox, oy, oz, dx, dy, dz, len, w0, w1, w2, rel)                              \
    chk3(__LINE__, spec, ox, oy, oz, dx, dy, dz, len, w0, w1, w2, rel)

static const double INF = INFINITY;
/* 2^-10 and 2^-40: a depth and a ray slope whose hand values are exact. */
static const double P10 = 0x1p-10, P40 = 0x1p-40;

/* Lengyel's four cases with plane y = 0, fog below, density 0.1. */
static void test_constant_cases(void **state)
{
    (void) state;
    const char *s = "halfspace:plane=0,1,0,0:density=0.1";
    /* Camera at y = 5 looking down: 3 of 8 units in fog. */
    CHK(s, 0, 5, 0, 0, -1, 0, 8, 0.3, 4e-16);
    CHK(s, 0, 5, 0, 0, -1, 0, 4, 0.0, 0);          /* (a) both outside */
    CHK(s, 0, 5, 0, 0, -1, 0, 5, 0.0, 0);          /* pixel exactly on the plane */
    CHK(s, 0, 5, 0, 0, -1, 0, 0, 0.0, 0);          /* zero length */
    CHK(s, 0, -2, 0, 0, 1, 0, 8, 0.2, 4e-16);      /* (b) camera in fog, leaving */
    CHK(s, 0, -2, 0, 0, -1, 0, 8, 0.8, 4e-16);     /* (d) both inside */
    CHK(s, 0, 0, 0, 0, -1, 0, 8, 0.8, 4e-16);      /* camera exactly on the plane */
    CHK(s, 0, 0, 0, 0, 1, 0, 8, 0.0, 0);
    CHK(s, 3, 0, 1, 1, 0, 0, 8, 0.0, 0);           /* both on the plane */
    CHK(s, 0, -1, 0, 1, 0, 0, 10, 1.0, 4e-16);     /* parallel, inside */
    CHK(s, 0, 1, 0, 1, 0, 0, 10, 0.0, 0);          /* parallel, outside */
    /* Tilted 3-4-5: from y = 4 along (0.6, -0.8) the plane is 5 away. */
    CHK(s, 0, 4, 0, 0.6, -0.8, 0, 10, 0.5, 1e-15);
    CHK(s, 7, -4, 2, -0.6, 0.8, 0, 10, 0.5, 1e-15);
    CHK(s, 7, -4, 2, 0.0, 0.8, -0.6, 3, 0.3, 1e-15);
    /* Densities from 1e-9 to 1e6 scale exactly. */
    CHK("halfspace:plane=0,1,0,0:density=1e-9", 0, 5, 0, 0, -1, 0, 8, 3e-9, 4e-16);
    CHK("halfspace:plane=0,1,0,0:density=1e6", 0, 5, 0, 0, -1, 0, 8, 3e6, 4e-16);
}

/* (A,B,C) need not be unit; the fog is where A x + B y + C z + D < 0. */
static void test_constant_planes(void **state)
{
    (void) state;
    /* 2y - 6 < 0: fog below y = 3. */
    CHK("halfspace:plane=0,2,0,-6:density=0.1", 1, 7, 2, 0, -1, 0, 10, 0.6, 4e-16);
    /* -3y < 0: fog above y = 0. */
    CHK("halfspace:plane=0,-3,0,0:density=0.1", 0, -3, 0, 0, 1, 0, 10, 0.7, 4e-16);
    CHK("halfspace:plane=0,-3,0,0:density=0.1", 0, -3, 0, 0, -1, 0, 10, 0.0, 0);
    /* 3x + 4y - 10 < 0, i.e. 0.6x + 0.8y < 2: from the origin along the
     * normal the plane is 2 away. */
    CHK("halfspace:plane=3,4,0,-10:density=0.1", 0, 0, 0, 0.6, 0.8, 0, 5, 0.2, 1e-15);
    CHK("halfspace:plane=3,4,0,-10:density=0.1", 0, 0, 0, -0.6, -0.8, 0, 5, 0.5, 1e-15);
    /* 5z - 10 < 0: fog below z = 2 (a z-up scene). */
    CHK("halfspace:plane=0,0,5,-10:density=0.1", 0, 0, 6, 0, 0, -1, 10, 0.6, 4e-16);
}

static void test_constant_sky(void **state)
{
    (void) state;
    const char *s = "halfspace:plane=0,1,0,0:density=0.1";
    CHK(s, 0, -2, 0, 0, 1, 0, INF, 0.2, 4e-16);            /* leaves: finite */
    CHK(s, 0, -4, 0, 0.6, 0.8, 0, INF, 0.5, 1e-15);        /* leaves at 5 */
    CHK(s, 0, 5, 0, 0, -1, 0, INF, INF, 0);                /* enters and stays */
    CHK(s, 0, -1, 0, 0, -1, 0, INF, INF, 0);
    CHK(s, 0, -1, 0, 1, 0, 0, INF, INF, 0);                /* exactly horizontal, in fog */
    CHK(s, 0, 1, 0, 1, 0, 0, INF, 0.0, 0);                 /* horizontal, above */
    CHK(s, 0, 0, 0, 1, 0, 0, INF, 0.0, 0);                 /* horizontal, on the plane */
    CHK(s, 0, 0, 0, 0, 1, 0, INF, 0.0, 0);                 /* on the plane, going out */
    CHK(s, 0, 0, 0, 0, -1, 0, INF, INF, 0);                /* on the plane, going in */
    CHK(s, 0, 5, 0, 0, 1, 0, INF, 0.0, 0);
    /* Zero density stays zero over an infinite path. */
    CHK3("halfspace:plane=0,1,0,0:density=0.1,0,0.2", 0, -1, 0, 1, 0, 0, INF, INF, 0.0, INF,
         0);
}

/* Grazing rays (|s| = 2^-40 ~ 1e-12) and cameras 1e7 from the origin. */
static void test_constant_grazing_far(void **state)
{
    (void) state;
    const char *s = "halfspace:plane=0,1,0,0:density=0.1";
    /* 2^-10 above the plane with slope -2^-40: enters at 2^30. */
    CHK(s, 0, P10, 0, 1, -P40, 0, 1e10, 0.1 * (1e10 - 0x1p30), 4e-16);
    CHK(s, 0, P10, 0, 1, -P40, 0, 0x1p30, 0.0, 0);         /* ends exactly on the plane */
    CHK(s, 0, -P10, 0, 1, P40, 0, INF, 0.1 * 0x1p30, 4e-16);
    CHK(s, 0, -P10, 0, 1, P40, 0, 1e10, 0.1 * 0x1p30, 4e-16);
    /* The same 1e7 away in every axis: the plane value is exact. */
    const char *f = "halfspace:plane=0,2,0,-2e7:density=0.1";
    CHK(f, 1e7, 1e7 + 5, -1e7, 0, -1, 0, 8, 0.3, 4e-16);
    CHK(f, -1e7, 1e7 + P10, 1e7, 1, -P40, 0, 1e10, 0.1 * (1e10 - 0x1p30), 4e-16);
    CHK(f, -1e7, 1e7 - P10, 1e7, 1, P40, 0, INF, 0.1 * 0x1p30, 4e-16);
    CHK(f, 1e7, 1e7, 1e7, 1, 0, 0, INF, 0.0, 0);          /* on the far plane */
    CHK(f, 1e7, 1e7 - P10, 1e7, 1, 0, 0, 1e6, 1e5, 4e-16);
    /* A far camera one ulp (2^-29 ~ 1.9e-9) above the plane is not on it. */
    CHK(f, 0, 1e7 + 0x1p-29, 0, 0, -1, 0, 1.0, 0.1 * (1.0 - 0x1p-29), 4e-16);
}

/* A pixel 1e-9 past the plane on a ray at slope -3/4 from y = 1: the fog
 * part is (3L/4 - 1)/(3/4), exact in long double. L minus the crossing
 * distance 4/3 (not a double) would keep only 7 digits of it. */
static void test_entering_cancellation(void **state)
{
    (void) state;
    const double s = -0.75, cx = sqrt(1 - s * s), L = 4.0 / 3.0 + 1e-9;
    const long double depth = 0.75L * L - 1, l = depth / 0.75L;
    CHK("halfspace:plane=0,1,0,0:density=0.1", 0, 1, 0, cx, s, 0, L, (double) (0.1L * l),
        4e-16);
    CHK("halfspace-linear:plane=0,1,0,0:slope=0.1", 0, 1, 0, cx, s, 0, L,
        (double) (0.1L * l * depth / 2), 4e-16);
    /* Walker to second order in S x/D = 0.5 depth ~ 4e-10. */
    CHK("halfspace-smooth:plane=0,1,0,0:density=0.2:sharpness=0.1", 0, 1, 0, cx, s, 0, L,
        (double) (0.1L * l * depth / 2 * (1 - 0.5L * depth / 3)), 4e-16);
}

static void test_constant_keys(void **state)
{
    (void) state;
    /* visibility=V: density 3.912/V, so V = 39.12 is density 0.1. */
    CHK("halfspace:plane=0,1,0,0:visibility=39.12", 0, 5, 0, 0, -1, 0, 8, 0.3, 1e-15);
    CHK3("halfspace:plane=0,1,0,0:density=0.1,0.2,0.4", 0, 5, 0, 0, -1, 0, 8, 0.3, 0.6, 1.2,
         4e-16);
    CHK3("halfspace:plane=0,1,0,0:visibility=39.12,19.56,9.78", 0, 5, 0, 0, -1, 0, 8, 0.3, 0.6,
         1.2, 1e-15);
    CHK("halfspace:plane=0,1,0,0:density=0.1:color=1,0,0", 0, 5, 0, 0, -1, 0, 8, 0.3, 4e-16);
}

/* Lengyel's linear density a x: integrals of a straight line in x. */
static void test_linear(void **state)
{
    (void) state;
    const char *s = "halfspace-linear:plane=0,1,0,0:slope=0.1";
    CHK(s, 0, 5, 0, 0, -1, 0, 8, 0.45, 4e-16);             /* 0.1 * 3^2 / 2 */
    CHK(s, 0, -2, 0, 0, -1, 0, 8, 4.8, 4e-16);             /* 0.1 * 8 * (2 + 10) / 2 */
    CHK(s, 0, -2, 0, 0, 1, 0, 8, 0.2, 4e-16);              /* 0.1 * 2^2 / 2 */
    CHK(s, 0, -2, 0, 0, 1, 0, 1, 0.15, 4e-16);             /* 0.1 * 1 * (2 + 1) / 2 */
    CHK(s, 0, 0, 0, 0, -1, 0, 4, 0.8, 4e-16);              /* camera on the plane */
    CHK(s, 0, -4, 0, 0, 1, 0, 4, 0.8, 4e-16);              /* pixel on the plane */
    CHK(s, 0, 5, 0, 0, -1, 0, 5, 0.0, 0);
    CHK(s, 0, -3, 0, 1, 0, 0, 10, 3.0, 4e-16);             /* parallel at depth 3 */
    CHK(s, 0, 0, 0, 1, 0, 0, 10, 0.0, 0);                  /* parallel on the plane */
    CHK(s, 0, -3, 0, 1, 0, 0, 0, 0.0, 0);
    /* 3-4-5: depth 0 -> 4 over 5 units, 0.1 * 5 * 2. */
    CHK(s, 0, 4, 0, 0.6, -0.8, 0, 10, 1.0, 1e-15);
    /* -5z + 10 < 0: fog above z = 2, depth z - 2; 0.1 * 4 * (0 + 4) / 2. */
    CHK("halfspace-linear:plane=0,0,-5,10:slope=0.1", 0, 0, 0, 0, 0, 1, 6, 0.8, 4e-16);
    CHK3("halfspace-linear:plane=0,1,0,0:slope=0.1,0.2,0", 0, 5, 0, 0, -1, 0, 8, 0.45, 0.9, 0,
         4e-16);
    /* Near-parallel in fog: depth 1 -> 1 + 1000 * 2^-40, mean 1 + 500 * 2^-40. */
    CHK(s, 0, -1, 0, 1, -P40, 0, 1000, 0.1 * 1000 * (1 + 500 * P40), 4e-16);
    /* Leaving a far plane at slope 2^-40 from depth 2^-10: a h0^2/(2 s) = 0.1 * 2^19. */
    CHK("halfspace-linear:plane=0,1,0,-1e7:slope=0.1", 5, 1e7 - P10, -5, 1, P40, 0, INF,
        0.1 * 0x1p19, 4e-16);
}

static void test_linear_sky(void **state)
{
    (void) state;
    const char *s = "halfspace-linear:plane=0,1,0,0:slope=0.1";
    CHK(s, 0, -2, 0, 0, 1, 0, INF, 0.2, 4e-16);
    CHK(s, 0, -4, 0, 0.6, 0.8, 0, INF, 1.0, 1e-15);        /* 0.1 * 5 * 4 / 2 */
    CHK(s, 0, 5, 0, 0.6, -0.8, 0, INF, INF, 0);
    CHK(s, 0, -3, 0, 1, 0, 0, INF, INF, 0);
    CHK(s, 0, 0, 0, 1, 0, 0, INF, 0.0, 0);                 /* on the plane: density 0 */
    CHK(s, 0, 0, 0, 0, 1, 0, INF, 0.0, 0);
    CHK(s, 0, 3, 0, 0, 1, 0, INF, 0.0, 0);
    CHK3("halfspace-linear:plane=0,1,0,0:slope=0.1,0,1", 0, 5, 0, 0, -1, 0, INF, INF, 0, INF, 0);
}

/* Walker's closed form as the seed writes it, in long double, for
 * segments where its divided difference is well conditioned. Walker's
 * depths are positive in the fog: p at the pixel, c at the camera. */
static long double walker_seed(long double D, long double S, long double c, long double p,
                               long double len)
{
    const long double cb = c > 0 ? c : 0, pb = p > 0 ? p : 0;
    if (c == p)
        return len * D * (1 - expl(-S * cb / D));
    const long double Dc = D * (cb + D / S * expl(-S * cb / D));
    const long double Dp = D * (pb + D / S * expl(-S * pb / D));
    return len * (Dc - Dp) / (c - p);
}

static void test_smooth_values(void **state)
{
    (void) state;
    /* D = 0.2, S = 0.1, so S/D = 0.5. */
    const char *s = "halfspace-smooth:plane=0,1,0,0:density=0.2:sharpness=0.1";
    CHK(s, 0, 5, 0, 0, -1, 0, 8, 0.28925206405937193157, 1e-15);   /* mpmath, x 0..3 */
    CHK(s, 0, -2, 0, 0, -1, 0, 8, 1.4555434023310572582, 1e-15);   /* mpmath, x 2..10 */
    CHK(s, 0, -3, 0, 0, 1, 0, 3, 0.28925206405937193157, 1e-15);
    CHK(s, 0, -3, 0, 1, 0, 0, 10, 10 * 0.2 * -expm1(-1.5), 1e-15); /* parallel: L delta(3) */
    CHK(s, 0, 0, 0, 1, 0, 0, 10, 0.0, 0);
    CHK(s, 0, 3, 0, 1, 0, 0, 10, 0.0, 0);
    CHK(s, 0, -3, 0, 0, 1, 0, 0, 0.0, 0);
    /* Near-parallel (slope 2^-40, depth 3 -> 3 + 1000 * 2^-40): mpmath; the
     * seed's divided difference in double keeps only about 6 digits here. */
    CHK(s, 0, -3, 0, 1, -P40, 0, 1000, 155.37396798046081913, 1e-15);
    CHK(s, 0, -4, 0, 0.6, 0.8, 0, INF, 0.56766764161830634595, 1e-15); /* 5/4 * x 0..4 */
    /* Crossings with S x/D = 0.9 and 1.1, either side of the series switch: mpmath. */
    CHK(s, 0, -1.8, 0, 0, 1, 0, 4, 0.12262786389623964475, 1e-15);
    CHK(s, 0, -2.2, 0, 0, 1, 0, 4, 0.17314843347923182132, 1e-15);
    /* visibility=V gives D = 3.912/V; per channel D and S, S = 0 or D = 0 is no fog. */
    CHK("halfspace-smooth:plane=0,1,0,0:visibility=19.56:sharpness=0.1", 0, 5, 0, 0, -1, 0, 8,
        0.28925206405937193157, 1e-15);
    CHK3("halfspace-smooth:plane=0,1,0,0:density=0.2,0.2,0:sharpness=0.1,0,0.1", 0, 5, 0, 0, -1,
         0, 8, 0.28925206405937193157, 0, 0, 1e-15);
    /* Non-unit plane, fog above y = 3: -2y + 6 < 0; depth 0..3 again. */
    CHK("halfspace-smooth:plane=0,-2,0,6:density=0.2:sharpness=0.1", 4, 0, 4, 0, 1, 0, 6,
        0.28925206405937193157, 1e-15);
}

/* The seed's formula where it is well conditioned (|s| >= 0.5). */
static void test_smooth_seed(void **state)
{
    (void) state;
    static const double DS[][2] = { { 0.2, 0.1 }, { 1, 3 }, { 0.05, 2e-3 }, { 3, 0.5 } };
    static const double ys[] = { -7, -2.5, -0.5, 0, 1.5, 6 };
    static const double ss[] = { -1, -0.8, -0.5, 0.5, 0.8, 1 };
    static const double Ls[] = { 0.5, 3, 12 };
    char spec[128];
    for (size_t m = 0; m < sizeof DS / sizeof DS[0]; ++m) {
        ef_fog_component c;
        snprintf(spec, sizeof spec, "halfspace-smooth:plane=0,1,0,0:density=%.17g:sharpness=%.17g",
                 DS[m][0], DS[m][1]);
        parse_ok(__LINE__, spec, 1.0, &c);
        for (size_t i = 0; i < sizeof ys / sizeof ys[0]; ++i)
            for (size_t j = 0; j < sizeof ss / sizeof ss[0]; ++j)
                for (size_t k = 0; k < sizeof Ls / sizeof Ls[0]; ++k) {
                    const double y = ys[i], s = ss[j], L = Ls[k], cx = sqrt(1 - s * s);
                    double t[3];
                    tau_of(&c, 0, y, 0, cx, s, 0, L, t);
                    const long double want = walker_seed(DS[m][0], DS[m][1], -(long double) y,
                                                         -((long double) y + (long double) s * L),
                                                         L);
                    check_rel(__LINE__, (int) (100 * m + 10 * i + j), t[0], (double) want,
                              1e-13);
                }
        ef_fog_free(&c);
    }
}

/* Walker's S -> infinity (a step of height D less a layer D/S thick) and
 * S -> 0 (the linear model with slope S). */
static void test_smooth_limits(void **state)
{
    (void) state;
    /* S/D = 5e6: crossing tau = D l - D^2/(S |s|). */
    const char *hard = "halfspace-smooth:plane=0,1,0,0:density=0.2:sharpness=1e6";
    CHK(hard, 0, 5, 0, 0, -1, 0, 8, 0.6 - 0.04 / 1e6, 1e-15);
    CHK(hard, 0, 4, 0, 0.6, -0.8, 0, 10, 1.0 - 0.04 / 0.8e6, 1e-15);
    CHK(hard, 0, -2, 0, 0, -1, 0, 8, 1.6, 4e-16);          /* deep: D L */
    CHK(hard, 0, -2, 0, 0, 1, 0, INF, 0.4 - 0.04 / 1e6, 1e-15);
    /* S/D overflows: exactly the constant half-space. */
    const char *step = "halfspace-smooth:plane=0,1,0,0:density=1e-10:sharpness=1e300";
    CHK(step, 0, 5, 0, 0, -1, 0, 8, 3e-10, 4e-16);
    CHK(step, 0, -2, 0, 0, -1, 0, 8, 8e-10, 4e-16);
    CHK(step, 0, -3, 0, 0, 1, 0, INF, 3e-10, 4e-16);
    CHK(step, 0, 0, 0, 1, 0, 0, INF, 0.0, 0);
    CHK(step, 0, -1, 0, 0, 1, 0, 1, 1e-10, 4e-16);         /* ends on the plane */
    /* S/D = 1e-9: mpmath, S x^2/2 - S^2 x^3/(6 D) + ... at x = 3. */
    CHK("halfspace-smooth:plane=0,1,0,0:density=1:sharpness=1e-9", 0, 5, 0, 0, -1, 0, 8,
        4.4999999955000000034e-9, 1e-15);
    CHK("halfspace-smooth:plane=0,1,0,0:density=1:sharpness=1e-12", 0, -2, 0, 0, -1, 0, 8,
        4.7999999999834666667e-11, 1e-15);                 /* mpmath, x 2..10 */
    CHK("halfspace-smooth:plane=0,1,0,0:density=1e6:sharpness=0.1", 0, 5, 0, 0, -1, 0, 8,
        0.449999955000003375, 1e-15);                      /* mpmath */
    CHK("halfspace-smooth:plane=0,1,0,0:density=1:sharpness=1e-300", 0, 5, 0, 0, -1, 0, 8,
        4.5e-300, 1e-15);
    /* S/D = 1e-296, so S x/D is subnormal at depth 2^-40: still S x L. */
    CHK("halfspace-smooth:plane=0,1,0,0:density=1e6:sharpness=1e-290", 0, -P40, 0, 1, 0, 0,
        1e295, 1e5 * P40, 1e-15);
    /* S/D underflows to 0: the density is S x exactly. */
    CHK("halfspace-smooth:plane=0,1,0,0:density=1e300:sharpness=1e-300", 0, -3, 0, 1, 0, 0, 10,
        3e-299, 1e-15);
    CHK("halfspace-smooth:plane=0,1,0,0:density=1e300:sharpness=1e-300", 0, 5, 0, 0, -1, 0, 8,
        4.5e-300, 1e-15);
    /* ... which is halfspace-linear with slope S to within S x/(3 D). */
    static const double dirs[][2] = { { 0, -1 }, { 0.6, -0.8 }, { 0.8, 0.6 }, { 1, 0 } };
    for (size_t i = 0; i < sizeof dirs / sizeof dirs[0]; ++i) {
        ef_fog_component sm, li;
        double ts[3], tl[3];
        parse_ok(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=1:sharpness=1e-9", 1.0, &sm);
        parse_ok(__LINE__, "halfspace-linear:plane=0,1,0,0:slope=1e-9", 1.0, &li);
        tau_of(&sm, 0, 2, 0, dirs[i][0], dirs[i][1], 0, 10, ts);
        tau_of(&li, 0, 2, 0, dirs[i][0], dirs[i][1], 0, 10, tl);
        check_rel(__LINE__, (int) i, ts[0], tl[0], 1e-8);
        tau_of(&sm, 0, -2, 0, dirs[i][0], dirs[i][1], 0, 10, ts);
        tau_of(&li, 0, -2, 0, dirs[i][0], dirs[i][1], 0, 10, tl);
        check_rel(__LINE__, (int) i, ts[0], tl[0], 1e-8);
        assert_true(ts[0] < tl[0]);                        /* delta(x) < S x */
        ef_fog_free(&sm);
        ef_fog_free(&li);
    }
}

static void test_smooth_sky(void **state)
{
    (void) state;
    const char *s = "halfspace-smooth:plane=0,1,0,0:density=0.2:sharpness=0.1";
    CHK(s, 0, -3, 0, 0, 1, 0, INF, 0.28925206405937193157, 1e-15);
    CHK(s, 0, 5, 0, 0, -1, 0, INF, INF, 0);
    CHK(s, 0, -3, 0, 1, 0, 0, INF, INF, 0);                /* horizontal at depth 3 */
    CHK(s, 0, -3, 0, 1, -P40, 0, INF, INF, 0);
    CHK(s, 0, 0, 0, 1, 0, 0, INF, 0.0, 0);                 /* on the plane: delta(0) = 0 */
    CHK(s, 0, 0, 0, 0, -1, 0, INF, INF, 0);
    CHK(s, 0, 0, 0, 0, 1, 0, INF, 0.0, 0);
    CHK(s, 0, 2, 0, 1, 0, 0, INF, 0.0, 0);
    /* Leaving a plane 1e7 away at slope 2^-40 from depth 2^-10: mpmath,
     * 2^40 times Walker's integral over x 0..2^-10. */
    CHK("halfspace-smooth:plane=0,1,0,-1e7:density=0.2:sharpness=0.1", 3, 1e7 - P10, 3, 1, P40,
        0, INF, 52420.267708231616351, 1e-15);
    CHK3("halfspace-smooth:plane=0,1,0,0:density=0.2,0,0.2:sharpness=0.1,0.1,0", 0, 5, 0, 0,
         -1, 0, INF, INF, 0, 0, 0);
}

static void chk_units(int line, const char *spec, double upm, double oy, double len,
                      double want, double rel)
{
    ef_fog_component c;
    double t[3];
    parse_ok(line, spec, upm, &c);
    tau_of(&c, 0, oy, 0, 0, -1, 0, len, t);
    for (int i = 0; i < 3; ++i)
        check_rel(line, i, t[i], want, rel);
    ef_fog_free(&c);
}

/* 100 units per metre: the metre scene above, scaled by 100, gives the
 * same optical depths; densities are per metre, the plane in scene units. */
static void test_units(void **state)
{
    (void) state;
    chk_units(__LINE__, "halfspace:plane=0,1,0,0:density=0.1", 100, 500, 800, 0.3, 4e-16);
    chk_units(__LINE__, "halfspace:plane=0,1,0,0:density=10", 100, 500, 800, 30, 4e-16);
    chk_units(__LINE__, "halfspace:plane=0,1,0,0:visibility=39.12", 100, 500, 800, 0.3, 1e-15);
    /* The plane stays at y = 100 units: 400 units in fog at 0.1 per unit. */
    chk_units(__LINE__, "halfspace:plane=0,1,0,-100:density=10", 100, 500, 800, 40, 4e-16);
    chk_units(__LINE__, "halfspace-linear:plane=0,1,0,0:slope=0.1", 100, 500, 800, 0.45, 1e-15);
    chk_units(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=0.2:sharpness=0.1", 100, 500,
              800, 0.28925206405937193157, 1e-15);
    chk_units(__LINE__, "halfspace-smooth:plane=0,1,0,0:visibility=19.56:sharpness=0.1", 100,
              500, 800, 0.28925206405937193157, 1e-15);
    /* 0.01 units per metre (a scene in hectometres). */
    chk_units(__LINE__, "halfspace-linear:plane=0,1,0,0:slope=0.1", 0.01, 0.05, 0.08, 0.45,
              1e-15);
}

static void test_interface(void **state)
{
    (void) state;
    ef_fog_component c;
    ef_fog_functional f[2];
    ef_fog_feature ft[4];
    long double d[3], v[1];

    /* functionals: the one plane, normalised. */
    parse_ok(__LINE__, "halfspace:plane=0,2,0,-6:density=0.1", 1.0, &c);
    assert_int_equal(c.model->functionals(&c, f, 2), 1);
    assert_true(f[0].n[0] == 0 && f[0].n[1] == 1 && f[0].n[2] == 0 && f[0].d == -3);
    assert_int_equal(c.model->functionals(&c, f, 0), 1);
    assert_int_equal(c.model->features(&c, ft, 4), 1);
    assert_true(ft[0].f == 0 && ft[0].value == 0 && ft[0].scale == 0);
    v[0] = -1;
    c.model->density(&c, v, d);
    assert_true(d[0] == (long double) 0.1 && d[2] == (long double) 0.1);
    v[0] = 1;
    c.model->density(&c, v, d);
    assert_true(d[0] == 0);
    v[0] = -INFINITY;
    c.model->density(&c, v, d);
    assert_true(d[1] == (long double) 0.1);
    v[0] = INFINITY;
    c.model->density(&c, v, d);
    assert_true(d[1] == 0);
    ef_fog_free(&c);

    parse_ok(__LINE__, "halfspace:plane=3,4,0,-10:density=0.1", 1.0, &c);
    c.model->functionals(&c, f, 1);
    assert_close(f[0].n[0], 0.6, 1e-16);
    assert_close(f[0].n[1], 0.8, 1e-16);
    assert_close(f[0].d, -2, 4e-16);
    ef_fog_free(&c);

    /* Linear: a x, infinite at infinite depth unless a = 0; kink at 0. */
    parse_ok(__LINE__, "halfspace-linear:plane=0,1,0,0:slope=0.1,0,1", 1.0, &c);
    assert_int_equal(c.model->features(&c, ft, 4), 1);
    assert_true(ft[0].f == 0 && ft[0].value == 0 && ft[0].scale == 0);
    v[0] = -3;
    c.model->density(&c, v, d);
    assert_close((double) d[0], 0.3, 1e-16);
    assert_true(d[1] == 0 && d[2] == 3);
    v[0] = -INFINITY;
    c.model->density(&c, v, d);
    assert_true(isinf(d[0]) && d[1] == 0 && isinf(d[2]));
    v[0] = 2;
    c.model->density(&c, v, d);
    assert_true(d[0] == 0 && d[2] == 0);
    ef_fog_free(&c);

    /* Walker: D (1 - e^(-S x/D)); scales D/S per distinct channel. */
    parse_ok(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=0.2,0.2,0.4:sharpness=0.1", 1.0,
             &c);
    assert_int_equal(c.model->features(&c, ft, 4), 2);
    assert_true(ft[0].f == 0 && ft[0].value == 0 && ft[1].f == 0 && ft[1].value == 0);
    assert_close(ft[0].scale, 2, 4e-16);
    assert_close(ft[1].scale, 4, 8e-16);
    v[0] = -3;
    c.model->density(&c, v, d);
    assert_close((double) d[0], 0.15537396797031403421, 1e-16);     /* mpmath */
    v[0] = -1e-20L;
    c.model->density(&c, v, d);
    assert_close((double) d[0] / 1e-21, 1, 1e-15);          /* S x near the plane */
    v[0] = -INFINITY;
    c.model->density(&c, v, d);
    assert_true(d[0] == (long double) 0.2 && d[2] == (long double) 0.4);
    v[0] = 0;
    c.model->density(&c, v, d);
    assert_true(d[0] == 0);
    v[0] = INFINITY;
    c.model->density(&c, v, d);
    assert_true(d[0] == 0);
    ef_fog_free(&c);

    /* The scale is a length in scene units: 100 times more in centimetres. */
    parse_ok(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=0.2,0.2,0.4:sharpness=0.1", 100,
             &c);
    assert_int_equal(c.model->features(&c, ft, 4), 2);
    assert_close(ft[0].scale, 200, 1e-13);
    assert_close(ft[1].scale, 400, 1e-13);
    assert_int_equal(c.model->features(&c, ft, 1), 2);    /* count even past cap */
    ef_fog_free(&c);

    /* No fog at all: only the plane, scale 0; density 0 everywhere. */
    parse_ok(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=0:sharpness=1", 1.0, &c);
    assert_int_equal(c.model->features(&c, ft, 4), 1);
    assert_true(ft[0].scale == 0);
    v[0] = -INFINITY;
    c.model->density(&c, v, d);
    assert_true(d[0] == 0 && d[1] == 0 && d[2] == 0);
    ef_fog_free(&c);
}

static void expect_error(int line, const char *spec, const char *n1, const char *n2)
{
    ef_fog_component c;
    ef_err err = { .file = NULL };
    if (parse_at(spec, 1.0, &c, &err) == 0) {
        print_error("line %d: '%s' was accepted\n", line, spec);
        fail();
    }
    assert_contains(err.msg, spec);
    assert_contains(err.msg, n1);
    if (n2)
        assert_contains(err.msg, n2);
}

static void test_spec_errors(void **state)
{
    (void) state;
    expect_error(__LINE__, "halfspace:density=0.1", "'plane'", "plane=A,B,C,D");
    expect_error(__LINE__, "halfspace:plane=0,1,0,0", "'density'", "visibility=V");
    expect_error(__LINE__, "halfspace:plane=0,1,0,0:density=0.1:visibility=10", "'density'",
                 "'visibility'");
    expect_error(__LINE__, "halfspace:plane=0,0,0,1:density=0.1", "plane='0,0,0,1'", "zero");
    expect_error(__LINE__, "halfspace:plane=0,1,0:density=0.1", "plane='0,1,0'", "A,B,C,D");
    expect_error(__LINE__, "halfspace:plane=0,1,0,0:density=-1", "density='-1'", ">= 0");
    expect_error(__LINE__, "halfspace:plane=0,1,0,0:visibility=0", "visibility='0'", "> 0");
    expect_error(__LINE__, "halfspace:plane=0,1,0,0:density=0.1:up=y", "'up'", "keys:");
    expect_error(__LINE__, "halfspace:plane=0,1,0,0:density=0.1:distance=planar", "'distance'",
                 NULL);
    expect_error(__LINE__, "halfspace:plane=0,1,0,0:plane=0,1,0,1:density=0.1", "'plane'",
                 "twice");
    expect_error(__LINE__, "halfspace-linear:plane=0,1,0,0", "'slope'", "slope=A");
    expect_error(__LINE__, "halfspace-linear:slope=0.1", "'plane'", "halfspace-linear:plane=");
    expect_error(__LINE__, "halfspace-linear:plane=0,1,0,0:slope=-0.1", "slope='-0.1'", ">= 0");
    expect_error(__LINE__, "halfspace-linear:plane=0,1,0,0:slope=x", "slope='x'", "R,G,B");
    expect_error(__LINE__, "halfspace-linear:plane=0,1,0,0:density=0.1", "'density'", "slope");
    expect_error(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=0.2", "'sharpness'",
                 "sharpness=S");
    expect_error(__LINE__, "halfspace-smooth:plane=0,1,0,0:sharpness=0.1", "'density'",
                 "density=D");
    expect_error(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=0.2:sharpness=-1",
                 "sharpness='-1'", ">= 0");
    expect_error(__LINE__, "halfspace-smooth:plane=0,1,0,0:density=0.2:sharpness=1,2",
                 "sharpness='1,2'", "R,G,B");
    expect_error(__LINE__, "halfspace-smooth:plane=0,1,0,0:visibility=5:density=0.2:sharpness=1",
                 "'density'", "'visibility'");
}

/* tau is additive along a ray, symmetric in its ends and grows with length. */
static void test_properties(void **state)
{
    (void) state;
    static const char *const specs[] = {
        "halfspace:plane=0,1,0,0:density=0.1,1,3",
        "halfspace-linear:plane=0,1,0,0:slope=0.1,1,3",
        "halfspace-smooth:plane=0,1,0,0:density=0.2,1,0.01:sharpness=0.1,1e3,1e-6",
    };
    static const double ys[] = { -3, -0.25, 0, 2 };
    static const double ss[] = { -0.8, -0x1p-40, 0, 0x1p-40, 0.6 };
    static const double Ls[] = { 0, 0.5, 1, 2, 5, 7, 100, INFINITY };
    for (size_t m = 0; m < sizeof specs / sizeof specs[0]; ++m) {
        ef_fog_component c;
        parse_ok(__LINE__, specs[m], 1.0, &c);
        for (size_t i = 0; i < sizeof ys / sizeof ys[0]; ++i)
            for (size_t j = 0; j < sizeof ss / sizeof ss[0]; ++j) {
                const double y = ys[i], s = ss[j], cx = sqrt(1 - s * s);
                double prev[3] = { 0, 0, 0 };
                for (size_t k = 0; k < sizeof Ls / sizeof Ls[0]; ++k) {
                    const double L = Ls[k];
                    double t[3], a[3], b[3], back[3];
                    tau_of(&c, 0, y, 0, cx, s, 0, L, t);
                    /* Split at M = C + tm dir. */
                    const double tm = isinf(L) ? 3.0 : 0.375 * L;
                    const double my = y + tm * s, mx = tm * cx;
                    tau_of(&c, 0, y, 0, cx, s, 0, tm, a);
                    tau_of(&c, mx, my, 0, cx, s, 0, L - tm, b);
                    if (!isinf(L))
                        tau_of(&c, L * cx, y + L * s, 0, -cx, -s, 0, L, back);
                    for (int ch = 0; ch < 3; ++ch) {
                        const int id = (int) (1000 * m + 100 * i + 10 * j + k);
                        assert_true(t[ch] >= prev[ch] * (1 - 1e-15));
                        prev[ch] = t[ch];
                        check_rel(__LINE__, id, a[ch] + b[ch], t[ch], 1e-13);
                        if (!isinf(L))
                            check_rel(__LINE__, id, back[ch], t[ch], 1e-13);
                    }
                }
            }
        ef_fog_free(&c);
    }
}

/* No NaN and no negative tau for extreme inputs. */
static void test_no_nan(void **state)
{
    (void) state;
    static const double dens[] = { 0, 1e-9, 1, 1e6 };
    static const double sharp[] = { 0, 1e-300, 1e-9, 1, 1e6, 1e300 };
    static const double offs[] = { 0, 1e7 };
    static const double hs[] = { 0, 1e-300, -1e-300, 0x1p-40, -0x1p-40, 1e-3, -1e-3, 5, -5,
                                 1e7, -1e7 };
    static const double ss[] = { 0, 1e-12, -1e-12, 0x1p-40, -0x1p-40, 0.6, -0.6, 1, -1 };
    static const double Ls[] = { 0, 1e-300, 1e-3, 1, 1e7, 1e300, 1e305, INFINITY };
    static ef_fog_component cs[32];  /* 4 densities x (1 + 1 + 6 sharpnesses) */
    int n = 0;
    char spec[160];
    for (size_t i = 0; i < sizeof dens / sizeof dens[0]; ++i) {
        snprintf(spec, sizeof spec, "halfspace:plane=0,1,0,-%.17g:density=%.17g", offs[1],
                 dens[i]);
        parse_ok(__LINE__, spec, 1.0, &cs[n++]);
        snprintf(spec, sizeof spec, "halfspace-linear:plane=0,1,0,-%.17g:slope=%.17g", offs[1],
                 dens[i]);
        parse_ok(__LINE__, spec, 1.0, &cs[n++]);
        for (size_t j = 0; j < sizeof sharp / sizeof sharp[0]; ++j) {
            snprintf(spec, sizeof spec,
                     "halfspace-smooth:plane=0,1,0,-%.17g:density=%.17g:sharpness=%.17g",
                     offs[1], dens[i], sharp[j]);
            parse_ok(__LINE__, spec, 1.0, &cs[n++]);
        }
    }
    long count = 0;
    for (int m = 0; m < n; ++m)
        for (size_t o = 0; o < sizeof offs / sizeof offs[0]; ++o)
            for (size_t i = 0; i < sizeof hs / sizeof hs[0]; ++i)
                for (size_t j = 0; j < sizeof ss / sizeof ss[0]; ++j) {
                    const double s = ss[j], cx = sqrt(1 - s * s);
                    /* The plane is at y = 1e7; offs[0] puts the camera far below it. */
                    const double y = offs[1] * (double) o + hs[i];
                    for (size_t k = 0; k < sizeof Ls / sizeof Ls[0]; ++k) {
                        double t[3];
                        tau_of(&cs[m], -offs[o], y, offs[o], cx, s, 0, Ls[k], t);
                        for (int ch = 0; ch < 3; ++ch)
                            if (isnan(t[ch]) || t[ch] < 0) {
                                print_error("%s: camera y %.17g, s %g, L %g: tau %g\n",
                                            cs[m].spec, y, s, Ls[k], t[ch]);
                                fail();
                            }
                        ++count;
                    }
                }
    assert_true(count > 10000);
    for (int m = 0; m < n; ++m)
        ef_fog_free(&cs[m]);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_constant_cases),
        cmocka_unit_test(test_constant_planes),
        cmocka_unit_test(test_constant_sky),
        cmocka_unit_test(test_constant_grazing_far),
        cmocka_unit_test(test_entering_cancellation),
        cmocka_unit_test(test_constant_keys),
        cmocka_unit_test(test_linear),
        cmocka_unit_test(test_linear_sky),
        cmocka_unit_test(test_smooth_values),
        cmocka_unit_test(test_smooth_seed),
        cmocka_unit_test(test_smooth_limits),
        cmocka_unit_test(test_smooth_sky),
        cmocka_unit_test(test_units),
        cmocka_unit_test(test_interface),
        cmocka_unit_test(test_spec_errors),
        cmocka_unit_test(test_properties),
        cmocka_unit_test(test_no_nan),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
