/* The noise contract (issue 7), checked independently of noise.c's own
 * reasoning: Perlin's golden values, zeros on the lattice (huge coordinates
 * included), the period 256, the cell-split evaluation against ef_noise3 bit
 * for bit, fbm's construction and values, and the two fog densities at spot
 * points. Values marked "perlin_ref.py" come from tests/refs/perlin_ref.py, a
 * plain-Python implementation of the contract (the noise_reference test
 * compares 1.2e5 random points with it bit for bit). This file is built with
 * -ffp-contract=off: noise.h's inline cell evaluation is part of the
 * contract. */
#include <float.h>
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
#include "noise.h"
#include "tassert.h"

static int same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

#define assert_bits(got, want)                                                          \
    do {                                                                                \
        const double g_ = (got), w_ = (want);                                           \
        if (!same_bits(g_, w_)) {                                                       \
            print_error("%s = %.17g (%a), expected %.17g (%a)\n", #got, g_, g_, w_, w_); \
            fail();                                                                     \
        }                                                                               \
    } while (0)

/* A small deterministic generator (xorshift64*), uniform doubles in [0, 1). */
static uint64_t rng_state = 0x9e3779b97f4a7c15u;

static double urand(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (double) ((rng_state * 2685821657736338717u) >> 11) * 0x1p-53;
}

/* Mixed magnitudes and signs, integers and near-integers. */
static double mixed(void)
{
    const double u = urand();
    switch ((int) (urand() * 6)) {
    case 0:
        return 2 * u - 1;
    case 1:
        return 600 * u - 300;
    case 2:
        return 2e6 * u - 1e6;
    case 3:
        return (u < 0.5 ? -1 : 1) * pow(10, urand() * 18 - 12);
    case 4:
        return nextafter(floor(2e5 * u - 1e5), urand() < 0.5 ? -INFINITY : INFINITY);
    default:
        return floor(2e6 * u - 1e6) + 0.5;
    }
}

static void test_golden(void **state)
{
    (void) state;
    /* Perlin's reference with the 2003 gradients. The first alone would also
     * hold for the older gradient table; the other three would not (it gives
     * 0.188416 and -0.125 for the second and third). */
    assert_bits(ef_noise3(3.14, 42, 7), 0.13691995878400012);
    assert_bits(ef_noise3(-4.2, 10, 6), 0.14208000000000043);
    assert_bits(ef_noise3(0.5, 0.5, 0.5), -0.25);
    assert_bits(ef_noise3(0.1, 0.1, 0.1), 0.1861607143544832);
}

static void test_zero_on_lattice(void **state)
{
    (void) state;
    /* Every combination of these integers, small to the end of the doubles. */
    static const double ints[] = { 0, 1, -1, 2, 7, -13, 255, 256, -256, 257, 1000, -65537,
                                   2147483647.0, 2147483648.0, -2147483649.0, 0x1p52, 0x1p53,
                                   -0x1p53 - 2, 1e15, -1e15, 0x1p60, -0x1p63, 0x1p63, 1e300,
                                   -1e300, DBL_MAX, -DBL_MAX };
    const size_t n = sizeof ints / sizeof ints[0];
    for (size_t i = 0; i < n; ++i)
        for (size_t j = 0; j < n; ++j)
            for (size_t k = 0; k < n; ++k)
                if (ef_noise3(ints[i], ints[j], ints[k]) != 0) {
                    print_error("noise3(%.17g, %.17g, %.17g) = %.17g, not 0\n", ints[i], ints[j],
                                ints[k], ef_noise3(ints[i], ints[j], ints[k]));
                    fail();
                }
    /* And a dense block of small lattice points. */
    for (int x = -20; x <= 20; ++x)
        for (int y = -20; y <= 20; ++y)
            for (int z = -20; z <= 20; ++z)
                assert_true(ef_noise3(x, y, z) == 0);
}

static void test_period_256(void **state)
{
    (void) state;
    /* Points on a 2^-10 grid moved by 256 k stay exact, so their fractions
     * are the same bits: the noise must repeat exactly. */
    for (int n = 0; n < 20000; ++n) {
        double p[3], s[3];
        for (int a = 0; a < 3; ++a)
            p[a] = ldexp(floor((2 * urand() - 1) * 0x1p20), -10);
        const double k = floor((2 * urand() - 1) * 0x1p30) * 256;
        const int axis = n % 4;   /* 3: all axes at once */
        for (int a = 0; a < 3; ++a)
            s[a] = p[a] + (axis == a || axis == 3 ? k : 0);
        assert_bits(ef_noise3(s[0], s[1], s[2]), ef_noise3(p[0], p[1], p[2]));
    }
    /* Anywhere else, to the rounding of the moved coordinate. */
    for (int n = 0; n < 20000; ++n) {
        const double x = mixed(), y = 600 * urand() - 300, z = 600 * urand() - 300;
        if (fabs(x) > 1e5)
            continue;
        const double d = ef_noise3(x + 256, y, z) - ef_noise3(x, y, z);
        assert_true(fabs(d) <= EF_NOISE_LIPSCHITZ * 4 * DBL_EPSILON * (fabs(x) + 256));
    }
}

static void test_split_and_cell_eval(void **state)
{
    (void) state;
    /* ef_noise_split is floor(v) mod 256 and v - floor(v), for every finite
     * v (fmod is exact), and the cell form reproduces ef_noise3 bit for bit. */
    static const double special[] = { 0.0, -0.0, 1e-300, -1e-300, 0.5, -0.5, 255.999, 256.0,
                                      -256.0, -0.0001, 0x1p52 + 1, -0x1p52 - 1, 0x1p62, -0x1p62,
                                      0x1p62 - 1024, 1e300, -1e300, DBL_MAX, -DBL_MAX };
    for (size_t i = 0; i < sizeof special / sizeof special[0] + 200000; ++i) {
        const double v = i < sizeof special / sizeof special[0] ? special[i] : mixed();
        int64_t cell;
        double frac;
        ef_noise_split(v, &cell, &frac);
        double m = fmod(floor(v), 256);
        if (m < 0)
            m += 256;
        assert_int_equal(cell, (int64_t) m);
        assert_bits(frac, v - floor(v));
    }
    for (int n = 0; n < 100000; ++n) {
        const double x = mixed(), y = mixed(), z = mixed();
        int64_t X, Y, Z;
        double fx, fy, fz;
        ef_noise_split(x, &X, &fx);
        ef_noise_split(y, &Y, &fy);
        ef_noise_split(z, &Z, &fz);
        ef_noise_cell c;
        ef_noise_cell_at(X, Y, Z, &c);
        assert_bits(ef_noise_cell_eval(&c, fx, fy, fz), ef_noise3(x, y, z));
        /* Cells are taken modulo 256 whatever the index's range. */
        ef_noise_cell c2;
        ef_noise_cell_at(X - 256 * 1000003, Y + 256 * 77, Z - 256, &c2);
        assert_memory_equal(c.h, c2.h, sizeof c.h);
    }
}

static void test_bounds(void **state)
{
    (void) state;
    ef_fbm f;
    ef_fbm_init(&f, 5, 2, 0.5);
    for (int n = 0; n < 100000; ++n) {
        const double p[3] = { mixed(), mixed(), mixed() };
        const double v = ef_noise3(p[0], p[1], p[2]);
        assert_true(fabs(v) <= EF_NOISE_BOUND);
        assert_true(fabs(ef_fbm_eval(&f, p)) <= EF_NOISE_BOUND);
    }
    /* The bound is nearly reached near (0.48, 0.355, 0.5) in some cell. */
    double best = 0;
    for (int c = 0; c < 256; ++c)
        for (int d = 0; d < 8; ++d) {
            const double v = ef_noise3(c + 0.48, (c * 7 + d) % 256 + 0.355, d * 31 % 256 + 0.5);
            best = fmax(best, fabs(v));
        }
    assert_true(best > 0.8 && best <= EF_NOISE_BOUND);
}

static void test_fbm_contract(void **state)
{
    (void) state;
    assert_true(ef_fbm_offset[0] == 31.416 && ef_fbm_offset[1] == 27.183 &&
                ef_fbm_offset[2] == 14.142);
    assert_true(ef_noise_seed_dir[0] == 12.9898 && ef_noise_seed_dir[1] == 78.233 &&
                ef_noise_seed_dir[2] == 37.719);
    /* freq and amp by repeated multiplication from 1, the norm summed in
     * order, the weights amp / norm. */
    static const double lac[] = { 2, 1.5, 2.5, 3, 1.01, 4 }, gain[] = { 0.5, 0.3, 0.7, 1, 1.2 };
    for (size_t a = 0; a < sizeof lac / sizeof lac[0]; ++a)
        for (size_t b = 0; b < sizeof gain / sizeof gain[0]; ++b)
            for (int oct = 1; oct <= EF_FBM_MAX_OCTAVES; ++oct) {
                ef_fbm f;
                ef_fbm_init(&f, oct, lac[a], gain[b]);
                assert_int_equal(f.octaves, oct);
                double fr = 1, am = 1, norm = 0;
                for (int i = 0; i < oct; ++i) {
                    assert_bits(f.freq[i], fr);
                    assert_bits(f.amp[i], am);
                    norm += am;
                    fr *= lac[a];
                    am *= gain[b];
                }
                assert_bits(f.norm, norm);
                for (int i = 0; i < oct; ++i)
                    assert_bits(f.weight[i], f.amp[i] / norm);
                const double q[3] = { mixed(), mixed(), mixed() };
                double sum = 0;
                for (int i = 0; i < oct; ++i) {
                    double u[3];
                    ef_fbm_octave_point(&f, i, q, u);
                    for (int k = 0; k < 3; ++k)
                        assert_bits(u[k], f.freq[i] * q[k] + (double) i * ef_fbm_offset[k]);
                    sum += f.amp[i] * ef_noise3(u[0], u[1], u[2]);
                }
                assert_bits(ef_fbm_eval(&f, q), sum / norm);
            }
    /* One octave is the noise itself. */
    ef_fbm one;
    ef_fbm_init(&one, 1, 2, 0.5);
    for (int n = 0; n < 1000; ++n) {
        const double q[3] = { mixed(), mixed(), mixed() };
        assert_bits(ef_fbm_eval(&one, q), ef_noise3(q[0], q[1], q[2]));
    }
    /* Spot values from perlin_ref.py. */
    static const struct {
        double q[3];
        int octaves;
        double lacunarity, gain, want;
    } spot[] = {
        { { 0.3, 1.7, -2.2 }, 4, 2.0, 0.5, -0.18095062800319983 /* -0x1.72963e2bb71a0p-3 */ },
        { { 1000.25, -77.125, 500000.0 }, 8, 2.5, 0.7, 0.08794068234644868 /* 0x1.68347d2aa79d7p-4 */ },
        { { 12.5, 0.5, -3.75 }, 16, 1.5, 1.2, -0.0030880508049236977 /* -0x1.94c1ca6e5a70dp-9 */ },
        { { -0.001, 3.999999, 250.0 }, 3, 3.0, 0.3, -0.07070320452330348 /* -0x1.2199aef266598p-4 */ },
        /* A lattice point: octave 0 is 0 there, the rest is not. */
        { { 7.0, -8.0, 9.0 }, 4, 2.0, 0.5, 0.06749660308796349 /* 0x1.1477516da98eap-4 */ },
    };
    for (size_t i = 0; i < sizeof spot / sizeof spot[0]; ++i) {
        ef_fbm f;
        ef_fbm_init(&f, spot[i].octaves, spot[i].lacunarity, spot[i].gain);
        assert_bits(ef_fbm_eval(&f, spot[i].q), spot[i].want);
    }
}

/* ---- the fog densities -------------------------------------------------- */

typedef struct density_case {
    const char *spec;
    double time;
    long double sigma[11][3];
} density_case;

/* From perlin_ref.py (its densities command): sigma per channel, per metre
 * (units_per_meter 1), in exact arithmetic from the definitions. */
static const double POINTS[11][3] = {
    { 0.0, 0.0, 0.0 },
    { 12.3, -4.56, 7.89 },
    { -33.25, 18.5, 61.125 },
    { 79.9, 89.5, -69.0 },
    { 80.0, 90.0, 100.0 },
    { -50.0, -60.0, -70.0 },
    { 80.5, 0.0, 0.0 },
    { 3.75, -1.5, 2.25 },
    { -41.0, 5.0, 33.3 },
    { 35.78, 5.43, -53.5 },
    { -66.8, 90.68, 78.9 },
};

static const density_case CASES[5] = {
    { "noise:density=0.02:scale=10",
      0.0,
      {
          { 1.88428471307882407226e-02L, 1.88428471307882407226e-02L, 1.88428471307882407226e-02L },
          { 1.87971705203650481242e-02L, 1.87971705203650481242e-02L, 1.87971705203650481242e-02L },
          { 2.21501052226834027614e-02L, 2.21501052226834027614e-02L, 2.21501052226834027614e-02L },
          { 1.98928613855118667508e-02L, 1.98928613855118667508e-02L, 1.98928613855118667508e-02L },
          { 2.06764829853415647853e-02L, 2.06764829853415647853e-02L, 2.06764829853415647853e-02L },
          { 2.05879849718831296757e-02L, 2.05879849718831296757e-02L, 2.05879849718831296757e-02L },
          { 1.79123342036118377019e-02L, 1.79123342036118377019e-02L, 1.79123342036118377019e-02L },
          { 2.33544510753746561993e-02L, 2.33544510753746561993e-02L, 2.33544510753746561993e-02L },
          { 1.84352768403733824343e-02L, 1.84352768403733824343e-02L, 1.84352768403733824343e-02L },
          { 2.38380104386367377978e-02L, 2.38380104386367377978e-02L, 2.38380104386367377978e-02L },
          { 1.85310900320744195713e-02L, 1.85310900320744195713e-02L, 1.85310900320744195713e-02L },
      } },
    { "noise:density=0.01,0.02,0.03:scale=3.5:octaves=6:lacunarity=2.3:gain=0.6:contras"
      "t=2.5:offset=100,-20,5:velocity=1,2,-3:seed=7:falloff=0.05:base=-2:up=0,0,1:min="
      "-50,-60,-70:max=80,90,100",
      2.5,
      {
          { 3.55823732744409365961e-03L, 7.11647465488818731921e-03L, 1.06747119823322814125e-02L },
          { 3.22353322518621277296e-03L, 6.44706645037242554591e-03L, 9.67059967555863701782e-03L },
          { 5.11348900178887387849e-04L, 1.02269780035777477570e-03L, 1.53404670053666194671e-03L },
          { 4.65205964603164212612e-01L, 9.30411929206328425224e-01L, 1.39561789380949252681e+00L },
          { 5.19417656177931723977e-05L, 1.03883531235586344795e-04L, 1.55825296853379503641e-04L },
          { 2.47548349957260244159e-01L, 4.95096699914520488317e-01L, 7.42645049871780704720e-01L },
          { 0.00000000000000000000e+00L, 0.00000000000000000000e+00L, 0.00000000000000000000e+00L },
          { 1.02861561885973194774e-02L, 2.05723123771946389549e-02L, 3.08584685657919584323e-02L },
          { 3.08397433155196661406e-03L, 6.16794866310393322811e-03L, 9.25192299465590027585e-03L },
          { 0.00000000000000000000e+00L, 0.00000000000000000000e+00L, 0.00000000000000000000e+00L },
          { 0.00000000000000000000e+00L, 0.00000000000000000000e+00L, 0.00000000000000000000e+00L },
      } },
    { "noise-separable:density=0.05:scale=20:contrast=0.8",
      0.0,
      {
          { 5.14883472511934933702e-02L, 5.14883472511934933702e-02L, 5.14883472511934933702e-02L },
          { 3.84863256425433952757e-02L, 3.84863256425433952757e-02L, 3.84863256425433952757e-02L },
          { 3.89641564355127437147e-02L, 3.89641564355127437147e-02L, 3.89641564355127437147e-02L },
          { 4.23321593501736412324e-02L, 4.23321593501736412324e-02L, 4.23321593501736412324e-02L },
          { 4.75837369768867951558e-02L, 4.75837369768867951558e-02L, 4.75837369768867951558e-02L },
          { 4.60741671886352593956e-02L, 4.60741671886352593956e-02L, 4.60741671886352593956e-02L },
          { 4.45859508046250671565e-02L, 4.45859508046250671565e-02L, 4.45859508046250671565e-02L },
          { 4.42513039480503522771e-02L, 4.42513039480503522771e-02L, 4.42513039480503522771e-02L },
          { 6.27061611026643317413e-02L, 6.27061611026643317413e-02L, 6.27061611026643317413e-02L },
          { 5.09468593256232130106e-02L, 5.09468593256232130106e-02L, 5.09468593256232130106e-02L },
          { 4.22944504803395779358e-02L, 4.22944504803395779358e-02L, 4.22944504803395779358e-02L },
      } },
    { "noise-separable:density=0.04,0.05,0.06:scale=7:axes=xyz:octaves=3:lacunarity=2.7"
      ":gain=0.45:contrast=1.6:offset=-3,4,5.5:velocity=0.5,0,-1:seed=3:falloff=0.1:bas"
      "e=1",
      -1.25,
      {
          { 4.94206240842985020101e-02L, 6.17757801053731223084e-02L, 7.41309361264477495457e-02L },
          { 1.32381760879024725636e-02L, 1.65477201098780911381e-02L, 1.98572641318537079780e-02L },
          { 6.82361962824437184166e-03L, 8.52952453530546501892e-03L, 1.02354294423665573288e-02L },
          { 5.18480511147620648618e-06L, 6.48100638934525789597e-06L, 7.77720766721430845872e-06L },
          { 7.10548339845521425407e-06L, 8.88185424806901760583e-06L, 1.06582250976828201106e-05L },
          { 1.03476214661354664059e+01L, 1.29345268326693343397e+01L, 1.55214321992031987207e+01L },
          { 4.21705722728623680351e-02L, 5.27132153410779652480e-02L, 6.32558584092935555221e-02L },
          { 5.63026084582403316126e-02L, 7.03782605728004162504e-02L, 8.44539126873604939494e-02L },
          { 5.04058839349253648421e-02L, 6.30073549186567077873e-02L, 7.56088259023880437937e-02L },
          { 2.31499018030366342236e-02L, 2.89373772537957936468e-02L, 3.47248527045549496006e-02L },
          { 0.00000000000000000000e+00L, 0.00000000000000000000e+00L, 0.00000000000000000000e+00L },
      } },
    { "noise-separable:density=0.03:scale=5:axes=y",
      0.0,
      {
          { 2.68175256110780822760e-02L, 2.68175256110780822760e-02L, 2.68175256110780822760e-02L },
          { 2.86539441539417558125e-02L, 2.86539441539417558125e-02L, 2.86539441539417558125e-02L },
          { 3.78167386595071736144e-02L, 3.78167386595071736144e-02L, 3.78167386595071736144e-02L },
          { 3.30703122982599559410e-02L, 3.30703122982599559410e-02L, 3.30703122982599559410e-02L },
          { 3.24788642657796514102e-02L, 3.24788642657796514102e-02L, 3.24788642657796514102e-02L },
          { 3.17700546578439865786e-02L, 3.17700546578439865786e-02L, 3.17700546578439865786e-02L },
          { 2.68175256110780822760e-02L, 2.68175256110780822760e-02L, 2.68175256110780822760e-02L },
          { 3.05826279952712727639e-02L, 3.05826279952712727639e-02L, 3.05826279952712727639e-02L },
          { 2.69112398306774157353e-02L, 2.69112398306774157353e-02L, 2.69112398306774157353e-02L },
          { 2.71941528629019400876e-02L, 2.71941528629019400876e-02L, 2.71941528629019400876e-02L },
          { 3.62224613904281039778e-02L, 3.62224613904281039778e-02L, 3.62224613904281039778e-02L },
      } },
};

static void parse(const char *spec, const ef_fog_context *ctx, ef_fog_component *c)
{
    ef_err err;
    if (ef_fog_parse(spec, ctx, c, &err))
        fail_msg("'%s' did not parse: %s", spec, err.msg);
}

/* The model's functional values at world point p: x, y, z and the height
 * above base. */
static void values_at(const ef_fog_component *c, const double p[3], long double v[4])
{
    ef_fog_functional f[8];
    assert_int_equal(c->model->functionals(c, f, 8), 4);
    for (int i = 0; i < 4; ++i) {
        v[i] = f[i].d;
        for (int k = 0; k < 3; ++k)
            v[i] += (long double) f[i].n[k] * p[k];
    }
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k)
            assert_true(f[i].n[k] == (i == k) && f[i].d == 0);
}

static void test_density_spot_values(void **state)
{
    (void) state;
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; ++i) {
        ef_fog_context ctx;
        ef_fog_context_init(&ctx);
        ctx.time = CASES[i].time;
        ef_fog_component c;
        parse(CASES[i].spec, &ctx, &c);
        assert_non_null(c.model->density);
        /* noise forms every octave's cell fraction in long double: its
         * density matches to rounding. noise-separable's factors take the
         * moving coordinate as a double reduced to [0, 256) (2.8e-14 apart
         * there) and the fixed ones (l^i 0.37 + i O) rounded to doubles, so
         * they carry up to ~2e-14 (measured 2.2e-14 here). */
        const long double rel = strncmp(CASES[i].spec, "noise-separable:", 16) ? 2e-15L : 5e-14L;
        for (size_t j = 0; j < sizeof POINTS / sizeof POINTS[0]; ++j) {
            long double v[4], got[3];
            values_at(&c, POINTS[j], v);
            c.model->density(&c, v, got);
            for (int k = 0; k < 3; ++k) {
                const long double want = CASES[i].sigma[j][k];
                const int ok = want == 0 ? got[k] == 0
                                         : fabsl(got[k] - want) <= rel * want;
                if (!ok) {
                    print_error("%s at (%g, %g, %g) channel %d: sigma %.20Lg, want %.20Lg "
                                "(rel %.2Lg)\n",
                                CASES[i].spec, POINTS[j][0], POINTS[j][1], POINTS[j][2], k,
                                got[k], want, want ? (got[k] - want) / want : got[k]);
                    fail();
                }
            }
        }
        ef_fog_free(&c);
    }
}

static long double sigma_at(const ef_fog_component *c, const double p[3])
{
    long double v[4], out[3];
    values_at(c, p, v);
    c->model->density(c, v, out);
    return out[0];
}

static void parse_time(const char *spec, double time, ef_fog_component *c)
{
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.time = time;
    parse(spec, &ctx, c);
}

#define assert_rel_ld(got, want, rel)                                                   \
    do {                                                                                \
        const long double g_ = (got), w_ = (want);                                      \
        if (!(fabsl(g_ - w_) <= (rel) * fabsl(w_))) {                                   \
            print_error("%s = %.20Lg, expected %.20Lg\n", #got, g_, w_);               \
            fail();                                                                     \
        }                                                                               \
    } while (0)

static void test_density_properties(void **state)
{
    (void) state;
    /* Offsets, velocity x time and the seed move the field; the envelope
     * scales it; the box cuts it; the clamp keeps it >= 0 exactly where
     * 1 + c fbm(q) <= 0. Points on a dyadic grid keep the moves exact. */
    static const char *const models[] = { "noise", "noise-separable" };
    for (int mi = 0; mi < 2; ++mi) {
        char spec[512];
        ef_fog_component base, off, vel, seed, env, box, clamp;
        snprintf(spec, sizeof spec, "%s:density=0.5:scale=4:octaves=5", models[mi]);
        parse_time(spec, 0, &base);
        snprintf(spec, sizeof spec, "%s:density=0.5:scale=4:octaves=5:offset=100.5,-20.25,5.125",
                 models[mi]);
        parse_time(spec, 0, &off);
        snprintf(spec, sizeof spec, "%s:density=0.5:scale=4:octaves=5:velocity=1.5,-2,0.25",
                 models[mi]);
        parse_time(spec, 3.5, &vel);
        snprintf(spec, sizeof spec, "%s:density=0.5:scale=4:octaves=5:seed=2", models[mi]);
        parse_time(spec, 0, &seed);
        snprintf(spec, sizeof spec, "%s:density=0.5:scale=4:octaves=5:falloff=0.125:base=-3:up=0,0,1",
                 models[mi]);
        parse_time(spec, 0, &env);
        snprintf(spec, sizeof spec, "%s:density=0.5:scale=4:octaves=5:min=-10,-20,-30:max=10,20,30",
                 models[mi]);
        parse_time(spec, 0, &box);
        snprintf(spec, sizeof spec, "%s:density=0.5:scale=4:octaves=5:contrast=3", models[mi]);
        parse_time(spec, 0, &clamp);
        ef_fbm fbm;
        ef_fbm_init(&fbm, 5, 2, 0.5);
        int zeros = 0;
        for (int n = 0; n < 2000; ++n) {
            double p[3], m[3];
            for (int a = 0; a < 3; ++a)
                p[a] = ldexp(floor((2 * urand() - 1) * 0x1p16), -10);   /* |p| < 64 */
            const long double s0 = sigma_at(&base, p);
            for (int a = 0; a < 3; ++a)
                m[a] = p[a] + (const double[]) { 100.5, -20.25, 5.125 }[a];
            assert_rel_ld(sigma_at(&off, m), s0, 1e-13L);
            for (int a = 0; a < 3; ++a)
                m[a] = p[a] + 3.5 * (const double[]) { 1.5, -2, 0.25 }[a];
            assert_rel_ld(sigma_at(&vel, m), s0, 1e-13L);
            /* seed 2 adds 2 S to q: the unseeded field at p + 2 S scale. */
            for (int a = 0; a < 3; ++a)
                m[a] = p[a] + 2 * ef_noise_seed_dir[a] * 4;
            assert_rel_ld(sigma_at(&seed, p), sigma_at(&base, m), 1e-12L);
            assert_rel_ld(sigma_at(&env, p), s0 * expl(-0.125L * (p[2] + 3)), 1e-14L);
            const int inside = fabs(p[0]) <= 10 && fabs(p[1]) <= 20 && fabs(p[2]) <= 30;
            if (inside)
                assert_rel_ld(sigma_at(&box, p), s0, 0);
            else
                assert_true(sigma_at(&box, p) == 0);
            /* The clamp, against fbm in the contract's double arithmetic. */
            const long double sc = sigma_at(&clamp, p);
            assert_true(sc >= 0);
            long double shape = 1;
            if (mi == 0) {
                const double q[3] = { p[0] / 4, p[1] / 4, p[2] / 4 };
                shape = fmaxl(0, 1 + 3 * (long double) ef_fbm_eval(&fbm, q));
            } else {
                /* The default axes xz: e_x(s) = (s, 0.37, 0.71), e_z(s) = (0.37, 0.71, s). */
                const double qx[3] = { p[0] / 4, 0.37, 0.71 }, qz[3] = { 0.37, 0.71, p[2] / 4 };
                shape = fmaxl(0, 1 + 3 * (long double) ef_fbm_eval(&fbm, qx)) *
                        fmaxl(0, 1 + 3 * (long double) ef_fbm_eval(&fbm, qz));
            }
            assert_true(fabsl(sc - 0.5L * shape) <= 1e-12L);
            zeros += sc == 0;
        }
        /* contrast 3 binds somewhere, but not everywhere. */
        assert_true(zeros > 20 && zeros < 1900);
        ef_fog_free(&base);
        ef_fog_free(&off);
        ef_fog_free(&vel);
        ef_fog_free(&seed);
        ef_fog_free(&env);
        ef_fog_free(&box);
        ef_fog_free(&clamp);
    }
}

static void test_density_lattices(void **state)
{
    (void) state;
    /* Every lattice the model gives the reference integrator is where one
     * octave's noise coordinate l^i q_a + i O_a is an integer, q from the
     * definition; and each octave of each axis the density uses has one. */
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; ++i) {
        ef_fog_context ctx;
        ef_fog_context_init(&ctx);
        ctx.time = CASES[i].time;
        ef_fog_component c;
        parse(CASES[i].spec, &ctx, &c);
        assert_non_null(c.model->lattices);
        const int n = c.model->lattices(&c, NULL, 0);
        ef_fog_lattice lat[3 * EF_FBM_MAX_OCTAVES];
        assert_true(n > 0 && n <= 3 * EF_FBM_MAX_OCTAVES);
        assert_int_equal(c.model->lattices(&c, lat, n), n);
        /* The SPEC's own numbers, read back from the parsed text. */
        const char *s = CASES[i].spec;
        double scale = 0, lac = 2, seed = 0, off[3] = { 0, 0, 0 }, vel[3] = { 0, 0, 0 };
        int octaves = 4;
        const char *k;
        if ((k = strstr(s, ":scale=")))
            scale = strtod(k + 7, NULL);
        if ((k = strstr(s, ":lacunarity=")))
            lac = strtod(k + 12, NULL);
        if ((k = strstr(s, ":seed=")))
            seed = strtod(k + 6, NULL);
        if ((k = strstr(s, ":octaves=")))
            octaves = atoi(k + 9);
        if ((k = strstr(s, ":offset=")))
            assert_int_equal(sscanf(k + 8, "%lf,%lf,%lf", &off[0], &off[1], &off[2]), 3);
        if ((k = strstr(s, ":velocity=")))
            assert_int_equal(sscanf(k + 10, "%lf,%lf,%lf", &vel[0], &vel[1], &vel[2]), 3);
        int axes = 7;
        if (!strncmp(s, "noise-separable:", 16)) {
            axes = 5;
            if ((k = strstr(s, ":axes="))) {
                axes = 0;
                for (k += 6; *k == 'x' || *k == 'y' || *k == 'z'; ++k)
                    axes |= 1 << (*k - 'x');
            }
        }
        unsigned seen[3] = { 0, 0, 0 };
        for (int j = 0; j < n; ++j) {
            const int a = lat[j].f;
            assert_true(a >= 0 && a < 3 && (axes >> a & 1));
            /* Which octave: period = scale / l^i. */
            int oct = -1;
            long double fr = 1;
            for (int o = 0; o < octaves; ++o, fr *= lac)
                if (fabsl(lat[j].period - scale / fr) <= 1e-14L * lat[j].period)
                    oct = o;
            assert_true(oct >= 0);
            seen[a] |= 1u << oct;
            fr = powl(lac, oct);
            for (int m = -3; m <= 3; ++m) {
                const long double p = lat[j].phase + (long double) m * 1000.5 * 2 * lat[j].period;
                const long double q = ((p - off[a]) - (long double) vel[a] * ctx.time) / scale +
                                      (long double) seed * ef_noise_seed_dir[a];
                const long double u = fr * q + (long double) oct * ef_fbm_offset[a];
                assert_true(fabsl(u - roundl(u)) < 1e-9L);
            }
        }
        for (int a = 0; a < 3; ++a)
            assert_int_equal(seen[a], (axes >> a & 1) ? (1u << octaves) - 1 : 0);
        ef_fog_free(&c);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_golden),
        cmocka_unit_test(test_zero_on_lattice),
        cmocka_unit_test(test_period_256),
        cmocka_unit_test(test_split_and_cell_eval),
        cmocka_unit_test(test_bounds),
        cmocka_unit_test(test_fbm_contract),
        cmocka_unit_test(test_density_spot_values),
        cmocka_unit_test(test_density_properties),
        cmocka_unit_test(test_density_lattices),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
