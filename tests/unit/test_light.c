/* Lit fog (issue 25) against values found independently: the phase
 * functions' normalisation and mean cosines by quadrature over the sphere
 * and their known closed forms; the in-scattered light of every method
 * against the reference integrator (ef_ref_inscatter: the formula
 * integrated on its own in long double, both transmittances by nested
 * quadrature) at the extremes, and against limits worked by hand; the
 * composite of the fog pass against the pass without lights plus the
 * reference's S; the SPEC and --light errors. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "apply.h"
#include "chapman.h"
#include "lit.h"
#include "ref.h"
#include "tassert.h"
#include "tlit.h"
#include "testutil.h"

#define PI 3.14159265358979323846

/* ---- phase functions ---- */

/* 2 pi int_-1^1 f(mu) p(mu) dmu by composite Simpson in s, mu = 1 - 2 s^2
 * (nodes crowd at mu = 1, where a strongly forward phase peaks). */
static double sphere_moment(int phase, double g, int moment)
{
    const int n = 200000;
    double sum = 0;
    for (int i = 0; i <= n; ++i) {
        const double s = (double) i / n, mu = 1 - 2 * s * s, jac = 4 * s;
        const double w = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
        sum += w * ef_phase_eval(phase, g, mu) * (moment ? mu : 1) * jac;
    }
    return 2 * PI * sum / (3.0 * n);
}

static void test_phase(void **state)
{
    (void) state;
    const double gs[] = { -0.9, -0.5, 0, 0.3, 0.8, 0.95 };
    for (int ph = EF_PHASE_ISO; ph <= EF_PHASE_CS; ++ph)
        for (size_t i = 0; i < sizeof gs / sizeof gs[0]; ++i) {
            const double g = ph >= EF_PHASE_HG ? gs[i] : 0;
            assert_close(sphere_moment(ph, g, 0), 1.0, 1e-9);
            /* mean cosines: HG's is g; Cornette-Shanks' 3g(4 + g^2) / (5(2 + g^2)) */
            const double mc = ph == EF_PHASE_HG ? g
                            : ph == EF_PHASE_CS ? 3 * g * (4 + g * g) / (5 * (2 + g * g)) : 0;
            assert_close(sphere_moment(ph, g, 1), mc, 1e-9);
        }
    /* HG at g = 0 is isotropic; Cornette-Shanks at g = 0 is Rayleigh */
    for (double c = -1; c <= 1; c += 0.125) {
        assert_close(ef_phase_eval(EF_PHASE_HG, 0, c), 1 / (4 * PI), 1e-17);
        assert_close(ef_phase_eval(EF_PHASE_CS, 0, c), 3 / (16 * PI) * (1 + c * c), 1e-17);
    }
    /* HG's peak, where 1 + g^2 - 2g must not cancel: (1 + g) / (4 pi (1 - g)^2) */
    const double g = 0.999999;
    assert_close(ef_phase_eval(EF_PHASE_HG, g, 1.0) / ((1 + g) / (4 * PI * (1 - g) * (1 - g))),
                 1.0, 1e-9);
}

/* ---- against the reference ---- */

typedef struct lit_case {
    const char *specs[3];
    const char *light;
    double org[3], dir[3], dist;
} lit_case;

/* |S - ref| <= rel |ref| per channel, and the error estimate covers it up
 * to the reference's own accuracy at these extremes (1e-12 relative: it
 * aims at 1e-14 and reached 1.4e-13 with a lamp 1e-7 off the ray). */
static void check_cases(const lit_case *cs, size_t n, double rel)
{
    for (size_t i = 0; i < n; ++i) {
        const lit_case *c = &cs[i];
        ef_fog_scene s;
        scene_of(&s, c->specs, c->light);
        const ef_ray r = ray_of(c->org, c->dir[0], c->dir[1], c->dir[2], c->dist);
        ef_scene_bind(&s, r.org);
        double S[3], E[3];
        long double R[3];
        ef_light_inscatter(&s, &s.light[0], &r, S, E);
        assert_int_equal(ef_ref_inscatter(&s, &s.light[0], &r, R), 0);
        for (int k = 0; k < 3; ++k) {
            const double d = fabs(S[k] - (double) R[k]);
            if (!(d <= rel * fabsl(R[k])) || !(d <= E[k] + 1e-12 * fabsl(R[k])))
                fail_msg("case %zu (%s, %s) channel %d: S %.17g ref %.17Lg (rel %.3g, "
                         "estimate %.3g)", i, c->specs[0], c->light, k, S[k], R[k],
                         (double) (d / fabsl(R[k])), E[k]);
        }
        ef_scene_free(&s);
    }
}

static void test_sun_height(void **state)
{
    (void) state;
    const lit_case cs[] = {
        /* to the ground, and to the sky above and below the horizon */
        { { "height:density=0.05:falloff=0.3:base=0" }, "sun:towards=0,0.3,-1:intensity=5",
          { 0, 1.7, 0 }, { 0, -0.05, -1 }, 34 },
        { { "height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.6" },
          "sun:towards=0.2,0.3,-1:intensity=5:color=1,0.9,0.7", { 0, 1.7, 0 }, { 0, 0.1, -1 },
          INFINITY },
        { { "height:density=0.05:falloff=0.3:base=0" }, "sun:towards=0,0.3,-1",
          { 0, 1.7, 0 }, { 0, -0.1, -1 }, INFINITY },
        /* the sun 0.5 degrees up, and the view ray along it (B - A = 0) */
        { { "height:density=0.05:falloff=0.3:base=0:phase=cs:g=0.7" },
          "sun:towards=0,0.00872653549837393,0.99996192306417128", { 0, 1.7, 0 },
          { 0, 0.00872653549837393, 0.99996192306417128 }, INFINITY },
        { { "height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.9" },
          "sun:towards=0.3,0.4,-1", { 0, 1.7, 0 }, { 0.3, 0.4, -1 }, 80 },
        /* grazing view rays, a camera high above and one deep below base */
        { { "height:density=0.05:falloff=0.3:base=0" }, "sun:towards=1,0.2,0",
          { 0, 1.7, 0 }, { 0, 1e-9, -1 }, 3000 },
        { { "height:density=0.02:falloff=0.1:base=0:albedo=0.9,0.8,0.7" },
          "sun:towards=-1,0.5,-1", { 3, 40, -2 }, { 0.1, -0.3, -1 }, 120 },
        { { "height:density=0.02:falloff=0.5:base=0:phase=rayleigh" }, "sun:towards=0,1,1",
          { 1, -6, 2 }, { 0, 0.5, -1 }, 25 },
        /* chromatic density, a channel of albedo 0 between two that scatter */
        { { "height:density=0.05,0.03,0.03:falloff=0.2:albedo=1,0,1" }, "sun:towards=0,0.4,-1",
          { 0, 1.7, 0 }, { 0.1, -0.02, -1 }, 60 },
        /* densities 1e-9 and 1e3 */
        { { "height:density=1e-9:falloff=0.3:base=0:phase=hg:g=0.7" },
          "sun:towards=0,0.3,-1:intensity=5", { 0, 1.7, 0 }, { 0.3, 0.01, -1 }, INFINITY },
        { { "height:density=1e3:falloff=2:base=0" }, "sun:towards=0,0.6,-1",
          { 0, 12, 0 }, { 0, -0.2, -1 }, 50 },
    };
    check_cases(cs, sizeof cs / sizeof cs[0], 1e-12);
}

/* A low sun over a planet (planet=): Chapman's function against its
 * asymptotic series at the horizon, Ch(X, 90 deg) = X e^X K1(X) =
 * sqrt(pi X / 2) (1 + 3/(8X) - 15/(128 X^2) + 105/(1024 X^3) - ...), and
 * overhead (1); the lit fog against the reference, which integrates the
 * sun's path through the sphere's heights itself (nested, long double), to
 * the general quadrature's 1e-10: suns 0.5 deg up, at the horizon and 0.02
 * deg below it (light the flat model has not), one below the planet's limb
 * (none), a huge planet equal to the flat closed form. */
static void test_sun_planet(void **state)
{
    (void) state;
    const double X[3] = { 1e4, 1e5, 6.4e7 };
    for (int i = 0; i < 3; ++i) {
        const double x = X[i];
        const double want = sqrt(PI * x / 2) *
                            (1 + 3 / (8 * x) - 15 / (128 * x * x) + 105 / (1024 * x * x * x));
        const double got = ef_chapman(x, 0);
        if (!(fabs(got - want) <= 1e-13 * want))
            fail_msg("Ch(%g, 0) = %.17g, series %.17g", x, got, want);
        assert_true(ef_chapman(x, 1) == 1);
        /* far above the horizon the flat model's 1 / mu, less O(1/X) */
        assert_true(fabs(ef_chapman(x, 0.5) - 2) < 10 / x);
    }
    /* sin(0.5 deg), cos; sin(0.02 deg) */
    const double s05 = 0.0087265354983739347, c05 = 0.99996192306417128;
    const double s002 = 3.4906585032932658e-4, c002 = 0.99999993907651005;
    char up05[128], horizon[128], below[128], limb[128];
    snprintf(up05, sizeof up05, "sun:towards=0,%.17g,%.17g:intensity=5:planet=earth", s05, -c05);
    snprintf(horizon, sizeof horizon, "sun:towards=0.3,0,-1:intensity=5:planet=earth");
    snprintf(below, sizeof below, "sun:towards=0,%.17g,%.17g:intensity=5:planet=earth", -s002,
             -c002);
    snprintf(limb, sizeof limb, "sun:towards=0,-0.01,-1:planet=earth");
    const lit_case cs[] = {
        { { "height:density=0.05:falloff=0.3:base=0" }, up05, { 0, 1.7, 0 }, { 0, -0.05, -1 },
          34 },
        { { "height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.8" }, up05, { 0, 1.7, 0 },
          { 0, 0.01, -1 }, INFINITY },
        { { "height:density=0.02:falloff=0.1:base=0:albedo=0.9,0.8,0.7" }, horizon,
          { 0, 3, 0 }, { 0.2, -0.02, -1 }, 150 },
        { { "height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.6" }, below, { 0, 1.7, 0 },
          { 0, 0, -1 }, 400 },
        { { "height:density=0.05:falloff=0.3:base=0" }, below, { 0, 40, 0 }, { 0, -0.3, -1 },
          INFINITY },
    };
    check_cases(cs, sizeof cs / sizeof cs[0], 1e-10);
    /* light the flat model has not: the sun just below the horizon */
    ef_fog_scene s, f;
    const char *hf[] = { "height:density=0.05:falloff=0.3:base=0", NULL };
    double S[3], E[3], F[3];
    scene_of(&s, hf, below);
    const ef_ray r = ray_of((double[3]) { 0, 1.7, 0 }, 0, 0, -1, 400);
    ef_scene_bind(&s, r.org);
    ef_light_inscatter(&s, &s.light[0], &r, S, E);
    assert_true(S[0] > 0);
    ef_scene_free(&s);
    /* the frame's Chebyshev table of Ch gives what ef_chapman gives */
    scene_of(&s, hf, up05);
    const ef_ray r3 = ray_of((double[3]) { 0, 1.7, 0 }, 0.2, -0.01, -1, INFINITY);
    ef_scene_bind(&s, r3.org);
    assert_int_equal(s.light[0].ch_ok, 1);
    ef_light_inscatter(&s, &s.light[0], &r3, S, E);
    s.light[0].ch_ok = 0;
    ef_light_inscatter(&s, &s.light[0], &r3, F, E);
    for (int k = 0; k < 3; ++k)
        if (!(fabs(S[k] - F[k]) <= 1e-13 * F[k]))
            fail_msg("table %.17g, direct %.17g", S[k], F[k]);
    ef_scene_free(&s);
    /* past the limb the planet itself shades every point of the ray */
    scene_of(&s, hf, limb);
    ef_scene_bind(&s, r.org);
    ef_light_inscatter(&s, &s.light[0], &r, S, E);
    assert_true(S[0] == 0 && S[1] == 0 && S[2] == 0);
    ef_scene_free(&s);
    /* a planet of 1e13 units 8 deg up: the flat closed form to 1e-9 */
    scene_of(&s, hf, "sun:towards=0,0.14054083470239145,-0.99007484:intensity=5:planet=1e13");
    scene_of(&f, hf, "sun:towards=0,0.14054083470239145,-0.99007484:intensity=5");
    const ef_ray r2 = ray_of((double[3]) { 0, 1.7, 0 }, 0.1, -0.01, -1, 200);
    ef_scene_bind(&s, r2.org);
    ef_scene_bind(&f, r2.org);
    ef_light_inscatter(&s, &s.light[0], &r2, S, E);
    ef_light_inscatter(&f, &f.light[0], &r2, F, E);
    for (int k = 0; k < 3; ++k)
        if (!(fabs(S[k] - F[k]) <= 1e-9 * F[k]))
            fail_msg("huge planet %.17g, flat %.17g", S[k], F[k]);
    ef_scene_free(&s);
    ef_scene_free(&f);
}

/* The sun in a constant half-space fog (closed form): from inside and
 * outside the layer, rays staying in it to infinity, leaving it, grazing
 * its plane, a low sun, and a sun below the layer's plane (no light). */
static void test_sun_halfspace(void **state)
{
    (void) state;
    const lit_case cs[] = {
        /* the linear (Lengyel) and smooth (Walker) densities: the same form */
        { { "halfspace-linear:plane=0,1,0,-6:slope=0.02" }, "sun:towards=0.2,1,-1",
          { 0, 1.7, 0 }, { 0.1, -0.05, -1 }, 60 },
        { { "halfspace-linear:plane=0,1,0,-6:slope=0.02:phase=hg:g=0.6" },
          "sun:towards=0.3,0.02,-1:intensity=3", { 0, 1.7, 0 }, { 0.3, 0.015, -1 }, INFINITY },
        { { "halfspace-linear:plane=0,1,0,-6:slope=0.02" }, "sun:towards=0,0.3,-1",
          { 0, 10, 0 }, { 0, -0.3, -1 }, INFINITY },
        { { "halfspace-smooth:plane=0,1,0,-6:density=0.08:sharpness=0.05" },
          "sun:towards=0.2,1,-1:color=1,0.8,0.6", { 0, 1.7, 0 }, { 0.1, -0.02, -1 }, 80 },
        { { "halfspace-smooth:plane=0.1,1,0.2,-4:density=0.08:sharpness=0.3:phase=cs:g=0.5" },
          "sun:towards=-0.5,0.4,-1", { 0, 1.7, 0 }, { -0.2, 0.01, -1 }, INFINITY },
        { { "halfspace:plane=0,1,0,-3:density=0.1" }, "sun:towards=0.2,1,-1", { 0, 1.7, 0 },
          { 0, 0, -1 }, INFINITY },
        { { "halfspace:plane=0,1,0,-3:density=0.1:phase=hg:g=0.7" }, "sun:towards=0.2,0.5,-1",
          { 0, 1.7, 0 }, { 0, 0.3, -1 }, INFINITY },
        { { "halfspace:plane=0,1,0,-3:density=0.1,0.2,0.05:albedo=0.9,0.5,1" },
          "sun:towards=0,1,1", { 0, 8, 0 }, { 0, -0.4, -1 }, 30 },
        { { "halfspace:plane=0,1,0,-3:density=0.1" }, "sun:towards=0,1,-1", { 0, 8, 0 },
          { 0, -0.1, -1 }, INFINITY },
        { { "halfspace:plane=0,1,0,-3:density=0.05:phase=cs:g=0.3" },
          "sun:towards=0,0.00872653549837393,-0.99996192306417128", { 0, 1.7, 0 },
          { 0, 1e-9, -1 }, 500 },
        { { "halfspace:plane=0.3,1,0.2,-3:density=2" }, "sun:towards=1,1,0", { 0, 1.7, 0 },
          { 0.3, 1, 0.2 }, 40 },
        { { "halfspace:plane=0,1,0,-3:density=1e-9" }, "sun:towards=0,0.3,-1", { 0, 1.7, 0 },
          { 0, 0.01, -1 }, 100 },
    };
    check_cases(cs, sizeof cs / sizeof cs[0], 1e-12);
    /* the sun below the layer's plane: its light never leaves the fog */
    ef_fog_scene s;
    const char *h[] = { "halfspace:plane=0,1,0,-3:density=0.1", NULL };
    scene_of(&s, h, "sun:towards=0,-0.2,1");
    const double org[3] = { 0, 1.7, 0 };
    const ef_ray r = ray_of(org, 0, 0, -1, 50);
    double S[3];
    ef_light_inscatter(&s, &s.light[0], &r, S, NULL);
    assert_true(S[0] == 0 && S[1] == 0 && S[2] == 0);
    ef_scene_free(&s);
}

static void test_point_uniform(void **state)
{
    (void) state;
    const lit_case cs[] = {
        { { "exp:density=0.02" }, "point:position=2,3,-20:intensity=100", { 0, 1.7, 0 },
          { 0, 0, -1 }, 30 },
        { { "exp:density=0.02" }, "point:position=2,3,-20:intensity=100:color=1,0.5,0.25",
          { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
        /* the lamp 1e-6 off the ray with a radius, and 1e-7 off without */
        { { "exp:density=0.02:phase=hg:g=0.8" },
          "point:position=0,1.7,-20.000001:intensity=100:radius=0.01", { 0, 1.7, 0 },
          { 0, 0, -1 }, INFINITY },
        { { "exp:density=0.02:phase=hg:g=0.8" }, "point:position=0,1.7000001,-20:intensity=100",
          { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
        /* behind the camera, on the ray's line and off it */
        { { "exp:density=0.02" }, "point:position=0,1.7,20:intensity=100", { 0, 1.7, 0 },
          { 0, 0, -1 }, 50 },
        { { "exp:density=0.05:phase=cs:g=-0.5" }, "point:position=0.5,1,4000:intensity=1e6",
          { 0, 1.7, 0 }, { 0, 0.01, -1 }, INFINITY },
        /* densities 1e3 and 1e-9, per-channel densities and albedo */
        { { "exp:density=1e3" }, "point:position=0,1.7,-0.01:intensity=100", { 0, 1.7, 0 },
          { 0, 0.01, -1 }, 50 },
        { { "exp:density=1e-9:phase=rayleigh" }, "point:position=3,1.7,-5:intensity=100",
          { 0, 1.7, 0 }, { 0, 0.01, -1 }, 50 },
        { { "exp:density=0.01,0.02,0.04:albedo=0.5,0.7,0.9", "exp:density=0.03:phase=hg:g=0.4" },
          "point:position=-4,2,-30:intensity=50", { 0, 1.7, 0 }, { -0.1, 0, -1 }, 45 },
        /* the isotropic closed form (Sun et al., radius 0): a lamp 1e-7
         * off the ray, far behind the camera, densities 1e-9 and chromatic,
         * short segments far from the lamp (the ends cancel: integrated) */
        { { "exp:density=0.02" }, "point:position=0,1.7000001,-20:intensity=100",
          { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
        { { "exp:density=0.05" }, "point:position=0.5,1,4000:intensity=1e6", { 0, 1.7, 0 },
          { 0, 0.01, -1 }, INFINITY },
        { { "exp:density=1e-9" }, "point:position=3,1.7,-5:intensity=100", { 0, 1.7, 0 },
          { 0, 0.01, -1 }, 50 },
        { { "exp:density=0.01,0.02,0.04:albedo=0.5,0.7,0.9", "exp:density=0.03" },
          "point:position=-4,2,-30:intensity=50", { 0, 1.7, 0 }, { -0.1, 0, -1 }, 45 },
        { { "exp:density=0.02" }, "point:position=2,3,-200:intensity=100", { 0, 1.7, 0 },
          { 0, -0.2, -1 }, 0.5 },
        { { "exp:density=3" }, "point:position=0.3,2,-1:intensity=100", { 0, 1.7, 0 },
          { 0, 0.3, -1 }, INFINITY },
        /* the continued fraction near the imaginary axis (z = 0.032 -
         * 1.6i at the camera end: 123 terms, rescaled every
         * fourth), and at both ends of a segment past a lamp */
        { { "exp:density=0.02" }, "point:position=80,1.7,-2000:intensity=1e6", { 0, 1.7, 0 },
          { 0, 0, -1 }, INFINITY },
        { { "exp:density=0.02" }, "point:position=80,1.7,-2000:intensity=1e6", { 0, 1.7, 0 },
          { 0, 0, -1 }, 1500 },
        { { "exp:density=0.05" }, "point:position=40,1.7,-30:intensity=1e4", { 0, 1.7, 0 },
          { 0, 0, -1 }, 200 },
        /* a spot in uniform fog, its cone crossing the ray */
        { { "exp:density=0.03" },
          "spot:position=0,6,-20:aim=0,-1,0:cone=40:blend=0.2:intensity=100", { 0, 1.7, 0 },
          { 0, 0, -1 }, 100 },
    };
    check_cases(cs, sizeof cs / sizeof cs[0], 1e-12);
    /* Random isotropic lamps of radius 0 (the closed form's series pair
     * where both ends lie within |z| < 1.5, its continued fraction, and the
     * integration where they cancel): segments from 0.01 to 80 units, lamps
     * up to 60 away on either side of the camera, densities 1e-4 to 0.5 */
    unsigned seed = 2511;
    for (int i = 0; i < 60; ++i) {
        double v[8];
        for (int j = 0; j < 8; ++j) {
            seed = seed * 1103515245u + 12345u;
            v[j] = (double) ((seed >> 8) & 0xffffff) / 16777216.0;
        }
        char spec[64], light[128];
        snprintf(spec, sizeof spec, "exp:density=%.6g", 1e-4 * pow(5000, v[0]));
        snprintf(light, sizeof light, "point:position=%.6g,%.6g,%.6g:intensity=100",
                 40 * v[1] - 20, 10 * v[2] - 2, -80 * v[3] + 20);
        const lit_case c = { { spec }, light, { 0, 1.7, 0 }, { 0.6 * v[4] - 0.3, 0.4 * v[5] - 0.2, -1 },
                             0.01 * pow(8000, v[6]) };
        check_cases(&c, 1, 1e-12);
    }
}

/* ef_light_rays over r[0..n) equals ef_light_inscatter ray by ray, S and
 * E bit for bit. */
static void rays_match(const ef_fog_scene *s, const ef_light *lp, const ef_ray *r, int n)
{
    double Sv[3][EF_RECON_SPAN], Ev[3][EF_RECON_SPAN];
    double *const Sk[3] = { Sv[0], Sv[1], Sv[2] }, *const Ek[3] = { Ev[0], Ev[1], Ev[2] };
    ef_light_rays(s, lp, r, n, Sk, Ek);
    for (int j = 0; j < n; ++j) {
        double S[3], E[3];
        ef_light_inscatter(s, lp, &r[j], S, E);
        for (int k = 0; k < 3; ++k) {
            assert_memory_equal(&S[k], &Sv[k][j], sizeof S[k]);
            assert_memory_equal(&E[k], &Ev[k][j], sizeof E[k]);
        }
    }
}

/* ef_light_rays against ef_light_inscatter ray by ray: the same bits, S
 * and E, for rays batched four at a time on vectors whatever their
 * neighbours (shuffled, and a batch left partial), among them rays the
 * batch leaves to the scalar path (through the lamp, of length 0) and
 * every method of the closed form (the series pair, the ends' series, the
 * continued fraction at far ends, a lamp behind the camera, ends that
 * cancel and are integrated). The values themselves are
 * test_point_uniform's (ef_light_inscatter against the reference). */
static void test_rays_batch(void **state)
{
    (void) state;
    static const char *const fogs[][3] = {
        { "exp:density=0.02" },
        { "exp:density=0.01,0.02,0.04:albedo=0.5,0.7,0.9", "exp:density=0.03" },
        { "exp:density=1e-9" },
        { "exp:density=3" },
    };
    static const char *const lamps[] = { "point:position=2,3,-20:intensity=100",
                                         "point:position=0.5,1,40:intensity=1e4" };
    unsigned seed = 99;
    for (size_t f = 0; f < sizeof fogs / sizeof fogs[0]; ++f)
        for (size_t l = 0; l < 2; ++l) {
            ef_fog_scene s;
            scene_of(&s, fogs[f], lamps[l]);
            const double org[3] = { 0, 1.7, 0 };
            ef_scene_bind(&s, org);
            ef_ray r[EF_RECON_SPAN];
            for (int j = 0; j < EF_RECON_SPAN; ++j) {
                double v[4];
                for (int i = 0; i < 4; ++i) {
                    seed = seed * 1103515245u + 12345u;
                    v[i] = (double) ((seed >> 8) & 0xffffff) / 16777216.0;
                }
                const double dists[] = { INFINITY, 0.01 + 0.5 * v[3], 5 + 40 * v[3],
                                         300 + 2000 * v[3], 0 };
                r[j] = ray_of(org, 0.8 * v[0] - 0.4, 0.4 * v[1] - 0.2, -1 + 2 * (v[2] < 0.1),
                              dists[(int) (v[3] * 4.999)]);
            }
            /* a ray through the lamp itself (h = 0: the scalar path) */
            const ef_light *lp = &s.light[0];
            r[7] = ray_of(org, lp->pos[0] - org[0], lp->pos[1] - org[1], lp->pos[2] - org[2],
                          INFINITY);
            for (int n = EF_RECON_SPAN; n >= 13; n -= EF_RECON_SPAN - 13) {
                rays_match(&s, lp, r, n);
                /* shuffled: each ray's bits whatever its neighbours */
                for (int j = n - 1; j > 0; --j) {
                    seed = seed * 1103515245u + 12345u;
                    const int i = (int) ((seed >> 8) % (unsigned) (j + 1));
                    const ef_ray t = r[i];
                    r[i] = r[j];
                    r[j] = t;
                }
                rays_match(&s, lp, r, n);
            }
            ef_scene_free(&s);
        }
}

/* The sun in one constant convex volume (closed form per piece of the
 * sun's exit path): from outside through the box, from inside, a low sun,
 * a sun along a face (n.l = 0), a view ray along a face, a sliver, a
 * rotated convex volume (a wedge), chromatic density and albedo, the sun
 * below every face facing it (none: no light). */
static void test_sun_convex(void **state)
{
    (void) state;
    const lit_case cs[] = {
        { { "box:min=-10,0,-60:max=10,8,-10:density=0.1:phase=hg:g=0.5" },
          "sun:towards=0.2,1,-1:intensity=1", { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
        { { "box:min=-10,0,-60:max=10,8,-10:density=0.1" }, "sun:towards=0.2,1,-1",
          { 0, 1.7, 0 }, { 0.1, 0.05, -1 }, 40 },
        { { "box:min=-10,0,-60:max=10,8,10:density=0.05:phase=cs:g=0.7" },
          "sun:towards=0.3,0.02,-1", { 0, 1.7, 0 }, { 0.2, -0.03, -1 }, INFINITY },
        { { "box:min=-10,0,-60:max=10,8,10:density=0.05" }, "sun:towards=1,0,0",
          { 0, 1.7, 0 }, { 0.3, 0.1, -1 }, INFINITY },
        { { "box:min=-10,0,-60:max=10,8,-10:density=0.2" }, "sun:towards=0.2,1,0.3",
          { 0, 8, 0 }, { 0, 0, -1 }, 100 },
        { { "box:min=-10,0,-60:max=10,8,-10:density=0.2" }, "sun:towards=-0.4,1,0.3",
          { 0, 1.7, 0 }, { 0, 6.2999, -10 }, INFINITY },
        { { "convex:planes=0,1,0,-6,0.6,-0.8,0,-2,-0.6,-0.8,0,-2,0,0,1,10,0,0,-1,-60:"
            "density=0.08,0.05,0.02:albedo=0.9,0.8,0.5:phase=hg:g=0.3" },
          "sun:towards=0.3,1,-0.5:intensity=2:color=1,0.9,0.8", { 0, 1.7, 0 },
          { 0.05, 0.03, -1 }, INFINITY },
        { { "box:min=-10,0,-60:max=10,8,-10:density=1000" }, "sun:towards=0.2,1,-1",
          { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
        { { "box:min=-10,0,-60:max=10,8,-10:density=1e-9" }, "sun:towards=0.2,1,-1",
          { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
    };
    check_cases(cs, sizeof cs / sizeof cs[0], 1e-12);
}

static void test_general(void **state)
{
    (void) state;
    const lit_case cs[] = {
        { { "box:min=-10,0,-60:max=10,8,-10:density=0.1" },
          "point:position=2,3,-20:intensity=100", { 0, 1.7, 0 }, { 0, 0, -1 }, 100 },
        { { "box:min=-10,0,-60:max=10,8,-10:density=0.1:phase=hg:g=0.5" },
          "sun:towards=0.2,1,-1:intensity=1", { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
        { { "halfspace:plane=0,1,0,-3:density=0.1" }, "sun:towards=0.2,1,-1:intensity=1",
          { 0, 1.7, 0 }, { 0, 0, -1 }, INFINITY },
        { { "height:density=0.05:falloff=0.3:base=0", "exp:density=0.01" },
          "spot:position=0,6,-20:aim=0,-1,0:cone=40:blend=0.2:intensity=100", { 0, 1.7, 0 },
          { 0, 0, -1 }, 100 },
        { { "height:density=0.05:falloff=0.3:base=0", "box:min=-3,0,-40:max=3,4,-25:density=0.5" },
          "sun:towards=0.5,0.6,-1:intensity=3", { 0, 1.7, 0 }, { 0.05, 0.02, -1 }, INFINITY },
    };
    check_cases(cs, sizeof cs / sizeof cs[0], 1e-9);
}

/* The general quadrature's exponential strata (height fog's optical
 * depths in plain double, a rule's nodes at a time) against the reference
 * integrator where they are easiest to get wrong: a lamp below the ray
 * (the light's height factor of the other sign), a camera far from the
 * origin, falloffs whose exponents pass 700 (the model answers there),
 * channels of zero density, a spot, the sun through mixed fog from above
 * and from below the view, and two strata at once. */
static void test_strata(void **state)
{
    (void) state;
    const lit_case cs[] = {
        { { "height:density=0.05:falloff=0.3:base=0" }, "point:position=1,-4,-20:intensity=100",
          { 0, 1.7, 0 }, { 0.05, -0.02, -1 }, 60 },
        { { "height:density=0.05:falloff=0.3:base=2" }, "point:position=100003,9,-199975:intensity=80",
          { 1e5, 1.7, -2e5 }, { 0.1, 0.05, 1 }, INFINITY },
        { { "height:density=0.05:falloff=30:base=0" }, "point:position=0,0.5,-10:intensity=50",
          { 0, 30, 0 }, { 0, -1, -0.4 }, 40 },
        { { "height:density=0.05:falloff=3:base=0" }, "point:position=0,0.5,-10:intensity=50",
          { 0, 30, 0 }, { 0, -1, -0.4 }, 40 },
        { { "height:density=0.05,0,0.02:falloff=0.2:base=0:albedo=0.9,1,0.5" },
          "point:position=-2,5,-15:intensity=60:color=1,0.5,0.2", { 0, 1.7, 0 }, { 0, 0.2, -1 },
          INFINITY },
        { { "height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.7" },
          "spot:position=0,6,-20:aim=0,-1,0.2:cone=40:blend=0.2:intensity=100", { 0, 1.7, 0 },
          { 0, 0, -1 }, 100 },
        { { "height:density=0.05:falloff=0.3:base=0", "box:min=-3,0,-40:max=3,4,-25:density=0.5" },
          "sun:towards=0.5,-0.6,-1:intensity=3", { 0, 1.7, 0 }, { 0.05, 0.02, -1 }, INFINITY },
        { { "height:density=0.05:falloff=0.3:base=0", "height:density=0.01:falloff=0.02:base=-5" },
          "point:position=3,8,-30:intensity=100", { 0, 1.7, 0 }, { 0, 0.1, -1 }, INFINITY },
        /* two coloured strata and a lamp behind the camera, sky rays
         * climbing slowly: the steep one's factor underflows far out
         * while the gentle one still scatters there, across the lamp's
         * leg through the steep one */
        { { "height:density=0.05,0.03,0.02:falloff=0.3:albedo=0.9,1,0.6:phase=hg:g=0.7",
            "height:density=0.01:falloff=0.02:base=-5" },
          "point:position=1,3,20:intensity=100:color=1,0.5,0.2", { 0, 1.7, 0 }, { 0.1, 0.15, -1 },
          INFINITY },
        { { "height:density=0.05,0.03,0.02:falloff=0.3:albedo=0.9,1,0.6:phase=hg:g=0.7",
            "height:density=0.01:falloff=0.02:base=-5" },
          "point:position=1,3,20:intensity=100:color=1,0.5,0.2", { 0, 1.7, 0 }, { -0.2, 0.03, -1 },
          INFINITY },
        /* height fog and uniform fog together, a lamp ahead */
        { { "height:density=0.05:falloff=0.3:base=0", "exp:density=0.01" },
          "point:position=0,3,-20:intensity=50", { 0, 1.7, 0 }, { 0.02, 0.04, -1 }, INFINITY },
        /* convex volumes with height fog (lamp_v's clipped legs): a lamp
         * inside a box the ray crosses, one outside it behind the camera,
         * a coloured box seen from inside, a tilted convex volume */
        { { "height:density=0.05:falloff=0.3:base=0", "box:min=-10,0,-60:max=10,8,-10:density=0.1" },
          "point:position=2,3,-20:intensity=100", { 0, 1.7, 0 }, { 0.05, 0.02, -1 }, INFINITY },
        { { "height:density=0.05:falloff=0.3:base=0", "box:min=-10,0,-60:max=10,8,-10:density=0.1" },
          "point:position=1,4,12:intensity=100", { 0, 1.7, 0 }, { -0.1, -0.02, -1 }, 80 },
        { { "box:min=-10,0,-60:max=10,8,5:density=0.1,0.05,0.02:albedo=0.9,0.8,1" },
          "spot:position=0,7,-30:aim=0,-1,0.1:cone=40:blend=0.2:intensity=300", { 0, 1.7, 0 },
          { 0.1, 0.1, -1 }, INFINITY },
        { { "convex:planes=1,1,0,-20,-1,0,0,-15,0,-1,0,0,0,0,1,5,0,0,-1,-80:density=0.08",
            "height:density=0.02:falloff=0.1:base=0" },
          "point:position=-3,2,-30:intensity=80", { 0, 1.7, 0 }, { 0.2, -0.01, -1 }, 120 },
    };
    check_cases(cs, sizeof cs / sizeof cs[0], 1e-9);
}

/* The dense output (lit.h): one quadrature along a whole ray, from which
 * a deep fog sample's light over [a, b) is (J(b) - J(a)) / T(0, a). Against
 * ef_light_inscatter over each segment on its own (the per-segment
 * quadrature, or a lamp's closed form in uniform fog): lamps and a spot in
 * height, mixed and uniform fog, a lamp with a radius, coloured fog and
 * light, finite and infinite rays, 300 random segments each (a few reaching infinity). Where the
 * segment's front is still visible (T(0, a) >= 1e-3, where deep fog
 * samples are split), the two agree within 1e-7 of the segment's light
 * plus 1e-10 of the whole ray's seen from a. */
static void test_dense(void **state)
{
    (void) state;
    static const struct {
        const char *fog[2], *light;
        double dir[3], D;
    } cs[] = {
        { { "height:density=0.05:falloff=0.3:base=0", NULL }, "point:position=1,3,-20:intensity=100",
          { 0.05, -0.02, -1 }, 100 },
        { { "height:density=0.05:falloff=0.3:base=0", "exp:density=0.01" },
          "spot:position=0,6,-20:aim=0,-1,0:cone=40:blend=0.2:intensity=100", { 0, 0, -1 }, 100 },
        { { "exp:density=0.03", NULL }, "point:position=2,2,-15:intensity=50", { 0.1, 0.05, -1 },
          INFINITY },
        { { "height:density=0.2:falloff=0.5:base=0:phase=hg:g=0.6", NULL },
          "point:position=-1,1,-8:intensity=30:radius=0.5", { 0, -0.03, -1 }, INFINITY },
        { { "box:min=-10,0,-60:max=10,8,-10:density=0.1", NULL },
          "point:position=2,3,-20:intensity=100", { 0, 0, -1 }, 80 },
        /* channels apart (leaves that are not grey) */
        { { "height:density=0.05,0.03,0.02:falloff=0.3:base=0:albedo=0.9,1,0.6", NULL },
          "point:position=1,3,-20:intensity=100:color=1,0.5,0.2", { 0.05, -0.02, -1 }, 100 },
    };
    /* pass 0 at the flat path's accuracy; pass 1 at what deep output
     * builds for the default --deep-tol (1e-7, deep.c's dense_rel), whose
     * promise is a composite error within 1e-6 of the pixel's light */
    for (int pass = 0; pass < 2; ++pass) {
    const double rel = pass ? 1e-7 : 0;
    uint64_t seed = 12345;
    double worst_piece = 0, worst_total = 0;
    int n = 0;
    for (size_t c = 0; c < sizeof cs / sizeof cs[0]; ++c) {
        ef_fog_scene s;
        ef_err err;
        ef_scene_init(&s);
        for (int i = 0; i < 2 && cs[c].fog[i]; ++i)
            assert_int_equal(ef_scene_add(&s, cs[c].fog[i], &err), 0);
        assert_int_equal(ef_scene_add_light(&s, cs[c].light, &err), 0);
        double d[3] = { cs[c].dir[0], cs[c].dir[1], cs[c].dir[2] };
        const double dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        ef_ray r = { { d[0] / dn, d[1] / dn, d[2] / dn }, cs[c].D, cs[c].D, { 0, 1.7, 0 } };
        ef_lit_dense dense = { 0 };
        assert_int_equal(ef_lit_dense_build(&s, &s.light[0], &r, rel, &dense), 0);
        double Jt[3], Et[3], Lt[3];
        ef_lit_dense_at(&dense, INFINITY, Jt, Et, Lt);
        double whole[3], we[3];
        ef_light_inscatter(&s, &s.light[0], &r, whole, we);
        for (int k = 0; k < 3; ++k)
            assert_true(fabs(Jt[k] - whole[k]) <= (pass ? 1e-6 : 1e-9) * whole[k] + 1e-300);
        const double span = isfinite(cs[c].D) ? cs[c].D : 200;
        for (int i = 0; i < 300; ++i) {
            seed = seed * 6364136223846793005ull + 1442695040888963407ull;
            double a = span * (double) (seed >> 11) * 0x1p-53;
            seed = seed * 6364136223846793005ull + 1442695040888963407ull;
            double b = a + (span - a) * ((double) (seed >> 11) * 0x1p-53) * ((i % 3) ? 0.05 : 1);
            if (!isfinite(cs[c].D) && i % 50 == 0)
                b = INFINITY;
            if (!(b > a))
                continue;
            /* T(0, a), and the segment's light on its own */
            double tau[3] = { 0, 0, 0 };
            ef_ray front = r;
            front.dist = front.planar = a;
            for (int j = 0; j < s.ncomp; ++j) {
                double t[3];
                ef_fog_tau(&s.comp[j], &front, t, NULL);
                for (int k = 0; k < 3; ++k)
                    tau[k] += t[k];
            }
            ef_ray seg = r;
            for (int k = 0; k < 3; ++k)
                seg.org[k] = r.org[k] + a * r.dir[k];
            seg.dist = seg.planar = b - a;
            double want[3], e[3], Ja[3], Jb[3], x[3], y[3];
            ef_light_inscatter(&s, &s.light[0], &seg, want, e);
            ef_lit_dense_at(&dense, a, Ja, x, y);
            ef_lit_dense_at(&dense, b, Jb, x, y);
            for (int k = 0; k < 3; ++k) {
                const double Ta = exp(-tau[k]);
                if (!(Ta >= 1e-3))
                    continue;
                const double got = (Jb[k] - Ja[k]) / Ta, diff = fabs(got - want[k]);
                worst_piece = fmax(worst_piece, want[k] > 0 ? diff / want[k] : diff);
                worst_total = fmax(worst_total, diff * Ta / Jt[k]);
                if (!(pass ? diff * Ta <= 1e-6 * Jt[k]
                           : diff <= 1e-7 * want[k] + 1e-10 * Jt[k] / Ta))
                    fail_msg("pass %d case %zu [%g, %g) channel %d: dense %.17g, per segment "
                             "%.17g", pass, c, a, b, k, got, want[k]);
                ++n;
            }
        }
        ef_lit_dense_free(&dense);
        ef_scene_free(&s);
    }
    printf("dense in-scatter at rel %g: %d segments; worst relative to the segment %.2e, to "
           "the ray's light %.2e\n", rel, n, worst_piece, worst_total);
    }
}

/* Limits worked by hand. A horizontal view ray at height y in height fog
 * sees a constant sigma and a constant sun transmittance e^-A:
 * S = p E e^-A (1 - e^-(sigma D)). A lamp in optically thin uniform fog
 * (iso, radius 0) gives sigma I / (4 pi h) (atan((D - ts) / h) + atan(ts / h))
 * up to O(sigma (t + d)) relative. */
static void test_by_hand(void **state)
{
    (void) state;
    ef_fog_scene s;
    const char *h[] = { "height:density=0.05:falloff=0.3:base=0", NULL };
    scene_of(&s, h, "sun:towards=0,0.6,-0.8:intensity=2");
    const double org[3] = { 0, 1.7, 0 };
    ef_ray r = ray_of(org, 1, 0, 0, 40);
    ef_scene_bind(&s, r.org);
    double S[3];
    ef_light_inscatter(&s, &s.light[0], &r, S, NULL);
    const double sig = 0.05 * exp(-0.3 * 1.7), A = sig / (0.3 * 0.6);
    assert_close(S[0], 2 / (4 * PI) * exp(-A) * -expm1(-sig * 40), 1e-15);
    ef_scene_free(&s);

    const char *e[] = { "exp:density=1e-9", NULL };
    scene_of(&s, e, "point:position=0,4.7,-20:intensity=100");
    r = ray_of(org, 0, 0, -1, 50);
    ef_light_inscatter(&s, &s.light[0], &r, S, NULL);
    const double hh = 3, ts = 20;
    const double thin = 1e-9 * 100 / (4 * PI * hh) * (atan((50 - ts) / hh) + atan(ts / hh));
    assert_close(S[0], thin, 1e-7 * thin);
    ef_scene_free(&s);

    /* the sun in unbounded uniform fog never arrives; below the horizon of
     * a height fog neither */
    scene_of(&s, e, "sun:towards=0,1,0");
    ef_light_inscatter(&s, &s.light[0], &r, S, NULL);
    assert_true(S[0] == 0 && S[1] == 0 && S[2] == 0);
    ef_scene_free(&s);
    scene_of(&s, h, "sun:towards=0,-0.1,1");
    ef_light_inscatter(&s, &s.light[0], &r, S, NULL);
    assert_true(S[0] == 0);
    ef_scene_free(&s);

    /* a lamp of radius 0 on the segment: infinite; with a radius, finite */
    scene_of(&s, e, "point:position=0,1.7,-20");
    ef_light_inscatter(&s, &s.light[0], &r, S, NULL);
    assert_true(isinf(S[0]));
    ef_scene_free(&s);
    scene_of(&s, e, "point:position=0,1.7,-20:radius=0.5");
    ef_light_inscatter(&s, &s.light[0], &r, S, NULL);
    assert_true(isfinite(S[0]) && S[0] > 0);
    ef_scene_free(&s);
}

/* Extreme lights and fogs: never NaN, never negative (an infinite S only
 * where a lamp of radius 0 sits on the segment), and an answer in bounded
 * time. Found by a sweep of the CLI: inf * 0 of a dense fog's sigma times a
 * near lamp's weight, and a radius whose square overflows. */
static void test_hostile(void **state)
{
    (void) state;
    const char *fogs[] = { "exp:density=1e300", "height:density=1e-300:falloff=1e300",
                           "height:density=0.05:falloff=0.3", "exp:density=0.02",
                           "box:min=-1e300,-1,-1e300:max=1e300,1,1e300:density=1e3",
                           "exp:density=1e300:phase=hg:g=0.999999" };
    const char *lights[] = { "point:position=1e300,1e300,1e300:intensity=1e300",
                             "point:position=0,1.7,-1e-9:intensity=1e300",
                             "point:position=0,1.7000001,0:radius=1e-300",
                             "point:position=0,1.7,-5:radius=1e300:intensity=1e300",
                             "point:position=0,1.7,-5:radius=1e200",
                             "sun:towards=1e-300,1,0:intensity=1e300", "sun:towards=0,-1,0",
                             "spot:position=0,5,-10:aim=0,-1,0:cone=1e-300",
                             "spot:position=1e300,5,-10:aim=0,-1,0:cone=30:radius=1e308" };
    const double org[3] = { -1.08e-9, 1.69999990512, 1.03e-8 };
    const double dirs[][4] = { { -0.4, -0.037, -0.915, 8.5e7 }, { 0, 0.1, -1, INFINITY },
                               { 0, -0.2, -1, 8.5 }, { 0.3, 0, 1, 1e300 } };
    for (size_t f = 0; f < sizeof fogs / sizeof fogs[0]; ++f)
        for (size_t l = 0; l < sizeof lights / sizeof lights[0]; ++l) {
            const char *specs[] = { fogs[f], NULL };
            ef_fog_scene s;
            scene_of(&s, specs, lights[l]);
            for (size_t d = 0; d < sizeof dirs / sizeof dirs[0]; ++d) {
                const ef_ray r = ray_of(org, dirs[d][0], dirs[d][1], dirs[d][2], dirs[d][3]);
                double S[3], E[3];
                ef_light_inscatter(&s, &s.light[0], &r, S, E);
                for (int k = 0; k < 3; ++k)
                    if (isnan(S[k]) || S[k] < 0 || isnan(E[k]))
                        fail_msg("%s with %s, ray %zu: S %g, estimate %g", fogs[f], lights[l], d,
                                 S[k], E[k]);
            }
            ef_scene_free(&s);
        }
}

/* ---- the fog pass ---- */

#define W 6
#define H 4

static void test_composite(void **state)
{
    (void) state;
    ef_camera cam;
    memset(&cam, 0, sizeof cam);
    const double rot[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 };
    memcpy(cam.rot, rot, sizeof rot);
    cam.pos[1] = 1.7;
    const double f = 4.0;
    const double ray[9] = { 1 / f, 0, 0, 0, -1 / f, 0, -W / 2.0 / f, H / 2.0 / f, 1 };
    memcpy(cam.ray, ray, sizeof ray);
    cam.unit = 1.0;
    ef_depth_conv conv;
    ef_err err;
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_PLANAR, &cam, &err), 0);
    const char *specs[] = { "height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.5",
                            "box:min=-2,0,-30:max=2,3,-10:density=0.2", NULL };
    ef_fog_scene lit, dark;
    scene_of(&lit, specs, "sun:towards=0.3,0.5,-1:intensity=3");
    ef_err e2;
    assert_int_equal(ef_scene_add_light(&lit, "point:position=1,2,-15:intensity=40:name=lamp",
                                        &e2), 0);
    scene_of(&dark, specs, NULL);
    ef_scene_bind(&lit, cam.pos);
    ef_scene_bind(&dark, cam.pos);
    float in[3][W * H], out[3][W * H], ref[3][W * H], alpha[W * H], a2[W * H], a0[W * H],
        depth[W * H];
    /* partial and zero alphas, and the sky, on the upper rows, whose rays
     * climb out of the height fog (a ray down to infinity is opaque) */
    for (int i = 0; i < W * H; ++i) {
        const int up = i < W * H / 2;
        /* the lower rows' rays end above y = -4: deeper, the height fog is
         * opaque and the reference crawls through densities of e^10 */
        depth[i] = up && i % 4 == 3 ? 1e10f : (float) (2 + 1.5 * (i % W) + (up ? 20 : 0));
        alpha[i] = !up || i % 3 == 0 ? 1.0f : i % 3 == 1 ? 0.5f : 0.0f;
        for (int k = 0; k < 3; ++k)
            in[k][i] = (float) (0.1 * (k + 1) + 0.01 * i);
    }
    memcpy(out, in, sizeof in);
    memcpy(ref, in, sizeof in);
    memcpy(a2, alpha, sizeof alpha);
    memcpy(a0, alpha, sizeof alpha);
    float *po[3] = { out[0], out[1], out[2] }, *pr[3] = { ref[0], ref[1], ref[2] };
    const ef_fog_pass pl = { &cam, &conv, &lit }, pd = { &cam, &conv, &dark };
    ef_fog_block(&pl, 0, 0, W, H, po, alpha, depth);
    ef_fog_block(&pd, 0, 0, W, H, pr, a2, depth);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int i = y * W + x;
            ef_ray r;
            ef_reconstruct(&cam, &conv, x, y, depth[i], &r);
            ef_ray far = r;
            far.dist = far.planar = INFINITY;
            const double av = a0[i];   /* the input's coverage */
            long double Ss[3] = { 0, 0, 0 }, Sf[3] = { 0, 0, 0 };
            for (int j = 0; j < lit.nlight; ++j) {
                long double a[3], b[3] = { 0, 0, 0 };
                assert_int_equal(ef_ref_inscatter(&lit, &lit.light[j], &r, a), 0);
                if (av < 1 && isfinite(r.dist))
                    assert_int_equal(ef_ref_inscatter(&lit, &lit.light[j], &far, b), 0);
                else
                    memcpy(b, a, sizeof b);
                for (int k = 0; k < 3; ++k) {
                    Ss[k] += a[k];
                    Sf[k] += b[k];
                }
            }
            for (int k = 0; k < 3; ++k) {
                /* the pass without lights in float, plus the lights */
                const double want = ref[k][i] + av * (double) Ss[k] + (1 - av) * (double) Sf[k];
                assert_close(out[k][i], want, 2e-7 * fabs(want) + 1e-7);
            }
            assert_true(alpha[i] == a2[i]);   /* lights do not change coverage */
        }
    ef_scene_free(&lit);
    ef_scene_free(&dark);
}

/* ---- errors ---- */

static void expect_light_error(const char *light, const char *spec, const char *want)
{
    ef_fog_scene s;
    ef_err err;
    ef_scene_init(&s);
    int rc = spec ? ef_scene_add(&s, spec, &err) : 0;
    if (!rc && light)
        rc = ef_scene_add_light(&s, light, &err);
    if (!rc)
        rc = ef_lights_check(&s, &err);
    if (rc == 0)
        fail_msg("'%s' / '%s' was accepted", light ? light : "", spec ? spec : "");
    if (!strstr(err.msg, want))
        fail_msg("'%s' / '%s': message '%s' lacks '%s'", light ? light : "", spec ? spec : "",
                 err.msg, want);
    ef_scene_free(&s);
}

static void test_errors(void **state)
{
    (void) state;
    expect_light_error("moon:towards=0,1,0", NULL, "not sun, point or spot");
    expect_light_error("sun", NULL, "missing towards");
    expect_light_error("sun:towards=0,0,0", NULL, "towards='0,0,0'");
    expect_light_error("sun:towards=0,1,0:position=1,2,3", NULL, "unknown key 'position'");
    expect_light_error("sun:towards=0,1,0:intensity=-1", NULL, "intensity='-1'");
    expect_light_error("point:position=0,1,0:shadow=a.exr", NULL, "takes no shadow= map");
    expect_light_error("sun:towards=0,1,0:bias=0.1", NULL, "need shadow=FILE.exr");
    expect_light_error("spot:position=0,1,0:aim=0,-1,0:cone=30:cosine=2", NULL,
                       "cosine='2' is not 0 or 1");
    expect_light_error("point:position=0,1,0:cosine=1", NULL, "unknown key 'cosine'");
    expect_light_error("spot:position=0,1,0:aim=0,-1,0:cone=30:outside=dark", NULL,
                       "outside='dark' is not lit or shadow");
    expect_light_error("point:intensity=3", NULL, "missing position");
    expect_light_error("point:position=1,2", NULL, "position='1,2'");
    expect_light_error("point:position=1,2,3:radius=-1", NULL, "radius='-1'");
    expect_light_error("point:position=1,2,3:name=a b", NULL, "name='a b'");
    expect_light_error("point:position=1,2,3:color=1,2,3:color=1,1,1", NULL, "twice");
    expect_light_error("spot:position=1,2,3:aim=0,-1,0", NULL, "aim=X,Y,Z and cone=DEG");
    expect_light_error("spot:position=1,2,3:aim=0,-1,0:cone=181", NULL, "cone='181'");
    expect_light_error("spot:position=1,2,3:aim=0,-1,0:cone=30:blend=2", NULL, "blend='2'");
    expect_light_error("point:position=1,2,3", "exp2:density=0.1", "function of the distance");
    expect_light_error("point:position=1,2,3", "linear:start=1:end=9", "function of the distance");
    expect_light_error("point:position=1,2,3", "exp:density=0.1:distance=planar",
                       "function of the distance");
    expect_light_error(NULL, "exp:density=0.1:g=0.5", "phase=hg or phase=cs only");
    expect_light_error(NULL, "exp:density=0.1:phase=mie", "phase='mie'");
    expect_light_error(NULL, "exp:density=0.1:phase=hg:g=1", "g='1'");
    expect_light_error(NULL, "exp:density=0.1:albedo=1.5", "albedo='1.5'");
    expect_light_error("sun:towards=0,0.1,-1:planet=-5", "height:density=0.1:falloff=0.2",
                       "planet='-5'");
    expect_light_error("sun:towards=0,0.1,-1:planet=earth", "exp:density=0.1",
                       "one exponential height fog");
    expect_light_error("point:position=1,2,3:planet=earth", NULL, "unknown key 'planet'");
    /* two lights of one name */
    ef_fog_scene s;
    ef_err err;
    ef_scene_init(&s);
    assert_int_equal(ef_scene_add_light(&s, "point:position=1,2,3", &err), 0);
    assert_string_equal(s.light[0].name, "point1");
    assert_int_equal(ef_scene_add_light(&s, "sun:towards=0,1,0", &err), 0);
    assert_string_equal(s.light[1].name, "sun1");
    assert_int_equal(ef_scene_add_light(&s, "point:position=1,2,3:name=point1", &err), -1);
    assert_non_null(strstr(err.msg, "taken"));
}

/* ---- the command line ---- */

/* Every channel of part 0 equal bit for bit (the headers differ: they
 * record the command line). */
static int same_pixels(const char *a, const char *b)
{
    tu_image A, B;
    if (tu_read_image(a, 0, &A) || tu_read_image(b, 0, &B))
        return 0;
    int same = A.nch == B.nch && A.w == B.w && A.h == B.h;
    for (int c = 0; same && c < A.nch; ++c)
        same = !strcmp(A.ch[c], B.ch[c]) &&
               !memcmp(A.plane[c], B.plane[c], (size_t) A.w * (size_t) A.h * 4);
    tu_image_free(&A);
    tu_image_free(&B);
    return same;
}

static void test_cli(void **state)
{
    (void) state;
    char in[4096];
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    snprintf(in, sizeof in, "%s/samples/sample.exr", src ? src : ".");
    char *a = tu_path("light_a.exr"), *b = tu_path("light_b.exr"), *c = tu_path("light_c.exr");
    /* without lights, the scattering keys change no pixel's bits */
    assert_int_equal(tu_runf("'%s' -o '%s' --fog height:density=0.05:falloff=0.3:base=0", in, a), 0);
    assert_int_equal(tu_runf("'%s' -o '%s' --fog height:density=0.05:falloff=0.3:base=0:"
                             "albedo=0.5,0.6,0.7:phase=hg:g=0.7", in, b), 0);
    assert_true(same_pixels(a, b));
    /* A sun over exp fog adds nothing (its light crosses infinite fog to
     * get in): a warning names it, and the picture is the unlit one
     * (issue 42); over height fog, or a lamp in exp fog, no warning. */
    char *e = tu_path("light_e.exr"), *fl = tu_path("light_f.exr");
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02", in, e), 0);
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 "
                             "--light sun:towards=0,1,0.3:intensity=3:name=noon", in, fl), 0);
    assert_non_null(strstr(tu_err, "warning: --light 'sun:towards=0,1,0.3:intensity=3:name=noon' "
                                    "adds nothing"));
    assert_true(same_pixels(e, fl));
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 -q "
                             "--light sun:towards=0,1,0.3:intensity=3", in, fl), 0);
    assert_null(strstr(tu_err, "adds nothing"));
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 "
                             "--light point:position=2,3,-20:intensity=50", in, fl), 0);
    assert_null(strstr(tu_err, "adds nothing"));
    free(e);
    free(fl);
    /* with a light the picture brightens somewhere and darkens nowhere */
    assert_int_equal(tu_runf("'%s' -o '%s' --fog height:density=0.05:falloff=0.3:base=0 "
                             "--light sun:towards=0,0.3,-1:intensity=2 "
                             "--light point:position=2,3,-20:intensity=50:name=lamp", in, c), 0);
    assert_null(strstr(tu_err, "adds nothing"));
    int w, h, w2, h2;
    float *ra = tu_read_channel(a, 0, "R", &w, &h), *rc = tu_read_channel(c, 0, "R", &w2, &h2);
    assert_non_null(ra);
    assert_non_null(rc);
    assert_int_equal(w * h, w2 * h2);
    long brighter = 0;
    for (int i = 0; i < w * h; ++i) {
        assert_true(rc[i] >= ra[i]);
        brighter += rc[i] > ra[i];
    }
    assert_true(brighter > w * h / 2);
    free(ra);
    free(rc);
    /* --aov light: the fog AOV is the ambient layer plus one per light */
    char *d = tu_path("light_d.exr"), *js = tu_path("light_scene.json");
    FILE *f = fopen(js, "w");
    assert_non_null(f);
    fputs("{\"fog\": [{\"model\": \"height\", \"density\": 0.05, \"falloff\": 0.3, "
          "\"base\": 0}], \"lights\": [{\"kind\": \"sun\", \"towards\": [0, 0.3, -1], "
          "\"intensity\": 2}, \"point:position=2,3,-20:intensity=50:name=lamp\"]}", f);
    fclose(f);
    assert_int_equal(tu_runf("'%s' -o '%s' --scene '%s' --aov fog,light,error", in, d, js), 0);
    tu_image img;
    assert_int_equal(tu_read_image(d, 0, &img), 0);
    const float *fr = tu_image_f(&img, "fog.R"), *am = tu_image_f(&img, "fog_ambient.R"),
                *l1 = tu_image_f(&img, "fog_light.sun1.R"), *l2 = tu_image_f(&img, "fog_light.lamp.R"),
                *rd = tu_image_f(&img, "R"), *er = tu_image_f(&img, "fog_error.R");
    assert_true(fr && am && l1 && l2 && rd && er);
    long estimated = 0;
    for (int i = 0; i < img.w * img.h; ++i) {
        const double sum = (double) am[i] + l1[i] + l2[i];
        assert_close(fr[i], sum, 1e-6 * fabs(sum) + 1e-7);
        assert_true(l1[i] >= 0 && l2[i] >= 0);
        /* the error AOV: height fog's T is a closed form (no error), the
         * sun's light too; the lamp in height fog is integrated by
         * Gauss-Kronrod to 1e-10 relative per piece, and its estimate is
         * what remains: within 1e-9 of its layer, the bound the reference
         * comparisons above hold the general quadrature to */
        assert_true(er[i] >= 0 && er[i] <= 1e-9 * (double) l2[i] + 1e-30);
        estimated += er[i] > 0;
    }
    assert_true(estimated > img.w * img.h / 2);
    /* the same picture as the flags give */
    float *rr = tu_read_channel(c, 0, "R", &w2, &h2);
    assert_non_null(rr);
    for (int i = 0; i < w * h; ++i)
        assert_true(rr[i] == rd[i]);
    free(rr);
    tu_image_free(&img);
    free(d);
    free(js);
    /* One sun in one height fog runs in the span path (its closed form
     * from the optical depths the span already has); any AOV takes the
     * per-pixel path, which the reference comparisons above check. Both
     * give the same bits, alpha edges, kept sky and a sky shell included. */
    /* So do every other light without the sky light (ef_light_rays per
     * light, point lamps in uniform isotropic fog four rays at a time on
     * vectors, the rest ray by ray): two lamps in chromatic fog, a
     * lamp behind the camera with a spot, a lamp in height fog beside a
     * sun (the general quadrature). */
    static const char *const skies[] = { "", "--sky keep", "--sky distance=500" };
    static const char *const fogs[] = {
        "--fog height:density=0.05,0.06,0.08:falloff=0.3:base=0:phase=hg:g=0.6:"
        "albedo=0.9,0.8,0.7 --light sun:towards=0.2,0.3,-1:intensity=3:color=1,0.9,0.8",
        "--fog exp:density=0.02,0.03,0.05:albedo=0.9,0.8,0.7 --fog exp:density=0.01 "
        "--light point:position=2,3,-20:intensity=100 "
        "--light point:position=-6,2,-60:intensity=200:color=1,0.5,0.2",
        "--fog exp:density=0.04 --light point:position=1,2.5,6:intensity=100 "
        "--light spot:position=0,6,-20:aim=0,-1,0:cone=40:blend=0.2:intensity=300",
        "--fog height:density=0.05:falloff=0.3:base=0 --light point:position=2,3,-20:"
        "intensity=50 --light sun:towards=0,0.3,-1:intensity=2",
    };
    for (int k = 0; k < 12; ++k) {
        const char *fog = fogs[k / 3];
        if (k / 3 == 3 && k % 3)   /* the quadrature's scene once */
            continue;
        assert_int_equal(tu_runf("'%s' -o '%s' %s %s", in, a, fog, skies[k % 3]), 0);
        assert_int_equal(tu_runf("'%s' -o '%s' %s %s --aov T", in, b, fog, skies[k % 3]), 0);
        for (int ch = 0; ch < 4; ++ch) {
            const char *name = (const char *[]) { "R", "G", "B", "A" }[ch];
            float *x = tu_read_channel(a, 0, name, &w, &h), *y = tu_read_channel(b, 0, name, &w2, &h2);
            assert_true(x && y && w * h == w2 * h2);
            for (int i = 0; i < w * h; ++i)
                assert_true(memcmp(&x[i], &y[i], sizeof x[i]) == 0);
            free(x);
            free(y);
        }
    }
    /* many lights, every AOV: 35 channels beside the colour (the writer
     * once took 16 and failed with an internal error) */
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 --light point:position=1,2,-5 "
                             "--light point:position=-1,2,-9 --light point:position=3,1,-14 "
                             "--light point:position=0,3,-20 --light point:position=2,2,-30 "
                             "--light point:position=-3,1,-40:name=far "
                             "--aov fog,T,error,P,distance,light -d float", in, c), 0);
    tu_image many;
    assert_int_equal(tu_read_image(c, 0, &many), 0);
    assert_non_null(tu_image_f(&many, "fog_light.far.B"));
    assert_non_null(tu_image_f(&many, "fog_light.point1.R"));
    assert_non_null(tu_image_f(&many, "fog_distance.Z"));
    tu_image_free(&many);
    /* usage errors: exit 2, a message, no output */
    remove(c);
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp2:density=0.05 --light sun:towards=0,1,0", in,
                             c), 2);
    assert_non_null(strstr(tu_err, "no density in space"));
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.05 --light lamp:position=0,1,0",
                             in, c), 2);
    assert_non_null(strstr(tu_err, "not sun, point or spot"));
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.05 --aov light", in, c), 2);
    assert_non_null(strstr(tu_err, "there is no --light"));
    assert_false(tu_exists(c));
    free(a);
    free(b);
    free(c);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_phase),        cmocka_unit_test(test_sun_height),
        cmocka_unit_test(test_sun_halfspace), cmocka_unit_test(test_sun_planet),
        cmocka_unit_test(test_point_uniform), cmocka_unit_test(test_rays_batch),
        cmocka_unit_test(test_general),
        cmocka_unit_test(test_strata),
        cmocka_unit_test(test_dense),
        cmocka_unit_test(test_sun_convex),
        cmocka_unit_test(test_by_hand),      cmocka_unit_test(test_composite),
        cmocka_unit_test(test_errors),       cmocka_unit_test(test_cli),
        cmocka_unit_test(test_hostile),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
