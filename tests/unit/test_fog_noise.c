/* The noise fog models (src/core/fog_noise.c and its noise_*.c
 * integrators) against the reference integrator (src/core/ref.c), which
 * knows only their density and splits at every octave's lattice crossings:
 *   - method=exact within 1e-12 relative on >= 10,000 seeded segments:
 *     axis-parallel, in a coordinate plane, grazing, zero length, camera
 *     inside and outside the box, offsets up to 1e6, sky rays up and down
 *     with and without falloff, both models, clamp binding or not;
 *   - method=adaptive at tol 1e-2, 1e-3, 1e-4, 1e-6: >= 99.9 % of segments
 *     within tol, all within 2 tol, and the reported error covering the
 *     actual one on >= 99.9 %;
 *   - method=steps equal to a midpoint sum of the density written out here,
 *     its reported bound covering the actual error;
 *   - method=preintegrated equal to a product of means each computed by the
 *     reference on one factor alone, exact when one axis varies, converging
 *     as pieces grows;
 *   - translation (offset, velocity * time, seed), clamp, envelope and box
 *     as defined, determinism and continuity in the camera, bad values.
 * EXRFOG_NOISE_SEGMENTS scales the segment counts (quick local runs). */
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

#include "noise.h"
#include "noise_clamp.h"
#include "ref.h"
#include "scene.h"

/* ---- seeded generator (splitmix64) ---- */
typedef struct rng {
    uint64_t s;
} rng;

static uint64_t next(rng *g)
{
    uint64_t z = (g->s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static double uni(rng *g, double a, double b)
{
    return a + (b - a) * ((double) (next(g) >> 11) * 0x1.0p-53);
}

static int chance(rng *g, double p)
{
    return uni(g, 0, 1) < p;
}

static void unit(double v[3])
{
    const double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int i = 0; i < 3; ++i)
        v[i] /= l;
}

static void sphere(rng *g, double v[3])
{
    double l;
    do {
        for (int i = 0; i < 3; ++i)
            v[i] = uni(g, -1, 1);
        l = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    } while (l > 1 || l < 1e-6);
    unit(v);
}

static long scaled(long n)
{
    const char *e = getenv("EXRFOG_NOISE_SEGMENTS");
    if (e && atof(e) > 0)
        return (long) (n * atof(e));
    return n;
}

static void parse(const char *spec, ef_fog_component *c)
{
    ef_err err = { 0 };
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    if (ef_fog_parse(spec, &ctx, c, &err)) {
        print_error("%s: %s\n", spec, err.msg);
        fail();
    }
}

static ef_ray ray(const double o[3], const double d[3], double len)
{
    ef_ray r;
    memcpy(r.org, o, sizeof r.org);
    memcpy(r.dir, d, sizeof r.dir);
    r.dist = r.planar = len;
    return r;
}

/* ---- random segments of every kind the issue names ---- */

/* A segment for a component whose noise scale is about `scale` and whose box
 * (if any) is [bmin, bmax]. */
static ef_ray random_segment(rng *g, double scale, const double *bmin, const double *bmax,
                             double offset_mag)
{
    double o[3], d[3], len;
    for (int a = 0; a < 3; ++a)
        o[a] = uni(g, -2, 2) * scale + offset_mag;
    if (bmin && chance(g, 0.5))    /* the camera inside the box */
        for (int a = 0; a < 3; ++a)
            o[a] = uni(g, bmin[a], bmax[a]);
    const int kind = (int) (next(g) % 6);
    sphere(g, d);
    if (kind == 0) {               /* axis-parallel */
        const int a = (int) (next(g) % 3);
        d[0] = d[1] = d[2] = 0;
        d[a] = chance(g, 0.5) ? 1 : -1;
    } else if (kind == 1) {        /* in a coordinate plane */
        d[next(g) % 3] = 0;
        unit(d);
    } else if (kind == 2) {        /* grazing the up (y) axis */
        d[1] = uni(g, -1e-6, 1e-6);
        unit(d);
    }
    len = chance(g, 0.02) ? 0 : uni(g, 0, 1) < 0.3 ? uni(g, 0, 0.5) * scale : uni(g, 0.5, 4) * scale;
    if (chance(g, 0.08)) {
        /* Sky rays climb or fall at least 1 in 20 here: a grazing one
         * crosses millions of cells before its fog thins (test_opaque). */
        len = INFINITY;
        if (fabs(d[1]) < 0.05) {
            d[1] = d[1] < 0 ? -0.05 : 0.05;
            unit(d);
        }
    }
    return ray(o, d, len);
}

typedef struct tally {
    long n, checked, bad, inf_ok;
    double max_rel, max_abs;
} tally;

/* Where a ray leaves the box [bmin, bmax] for good (0 if it never is in it):
 * past it the density is zero by definition, so the reference integrates a
 * sky ray through a box only that far. */
static double box_exit(const double *bmin, const double *bmax, const ef_ray *r)
{
    double t0 = 0, t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
        if (r->dir[a] == 0) {
            if (r->org[a] < bmin[a] || r->org[a] > bmax[a])
                return 0;
            continue;
        }
        double ta = (bmin[a] - r->org[a]) / r->dir[a], tb = (bmax[a] - r->org[a]) / r->dir[a];
        if (ta > tb) {
            const double x = ta;
            ta = tb;
            tb = x;
        }
        t0 = fmax(t0, ta);
        t1 = fmin(t1, tb);
    }
    return t0 < t1 ? nextafter(t1, INFINITY) * (1 + 1e-12) : 0;
}

/* exact against the reference on one segment; a box bounds sky rays. */
static void check_exact_box(const ef_fog_component *c, const ef_ray *r, const double *bmin,
                            const double *bmax, tally *t)
{
    double tau[3];
    long double ref[3];
    ef_tau_info info;
    ef_fog_tau(c, r, tau, &info);
    ef_ray rr = *r;
    if (bmin && isinf(r->dist)) {
        rr.dist = rr.planar = box_exit(bmin, bmax, r);
        r = &rr;
    }
    if (ef_ref_tau(c, r, ref, NULL)) {
        print_error("%s: the reference failed (len %g org %.17g,%.17g,%.17g dir %.17g,%.17g,%.17g)\n",
                    c->spec, r->dist, r->org[0], r->org[1], r->org[2], r->dir[0], r->dir[1], r->dir[2]);
        fail();
    }
    t->n++;
    for (int k = 0; k < 3; ++k) {
        if (isinf(ref[k]) || isinf(tau[k])) {
            if (!(isinf(ref[k]) && isinf(tau[k])) && t->bad++ < 5)
                printf("  %s: inf mismatch tau %g ref %Lg (len %g dir %g,%g,%g)\n", c->spec,
                       tau[k], ref[k], r->dist, r->dir[0], r->dir[1], r->dir[2]);
            t->inf_ok++;
            continue;
        }
        const double d = fabs(tau[k] - (double) ref[k]);
        if (d > t->max_abs)
            t->max_abs = d;
        if (ref[k] < 1e-300) {
            if (d > 1e-300 && t->bad++ < 5)
                printf("  %s: zero ref, tau %g\n", c->spec, tau[k]);
            continue;
        }
        const double rel = d / (double) ref[k];
        t->checked++;
        if (rel > t->max_rel)
            t->max_rel = rel;
        if (!(rel <= 1e-12) && t->bad++ < 5)
            printf("  %s: tau %.17g ref %.17Lg rel %.3g (len %g org %g,%g,%g dir %g,%g,%g)\n",
                   c->spec, tau[k], ref[k], rel, r->dist, r->org[0], r->org[1], r->org[2],
                   r->dir[0], r->dir[1], r->dir[2]);
    }
}

static void check_exact(const ef_fog_component *c, const ef_ray *r, tally *t)
{
    check_exact_box(c, r, NULL, NULL, t);
}

typedef struct spec_case {
    const char *spec;
    double scale, offset_mag;
    int has_box;
    double bmin[3], bmax[3];
} spec_case;

static const spec_case exact_cases[] = {
    { "noise:density=0.05:scale=4:method=exact", 4, 0, 0, { 0 }, { 0 } },
    { "noise:density=0.02,0.03,0.05:scale=3:octaves=5:lacunarity=2.3:gain=0.6:contrast=0.7:"
      "seed=3:method=exact", 3, 0, 0, { 0 }, { 0 } },
    { "noise:density=0.05:scale=4:falloff=0.2:base=1:method=exact", 4, 0, 0, { 0 }, { 0 } },
    { "noise:density=0.08:scale=2:octaves=3:min=-3,-2,-4:max=3,2,1:method=exact", 2, 0, 1,
      { -3, -2, -4 }, { 3, 2, 1 } },
    { "noise:density=0.05:scale=5:contrast=1.6:method=exact", 5, 0, 0, { 0 }, { 0 } },
    { "noise:density=0.05:scale=4:offset=1e6,-1e6,5e5:velocity=3,0,1:method=exact", 4, 1e6, 0,
      { 0 }, { 0 } },
    { "noise:density=0.04:scale=3:octaves=2:falloff=0.3:contrast=1.3:min=-5,-1,-5:max=5,4,5:"
      "method=exact", 3, 0, 1, { -5, -1, -5 }, { 5, 4, 5 } },
    { "noise-separable:density=0.05:scale=4:method=exact", 4, 0, 0, { 0 }, { 0 } },
    { "noise-separable:density=0.05:scale=4:axes=xyz:octaves=3:falloff=0.15:method=exact", 4, 0,
      0, { 0 }, { 0 } },
    { "noise-separable:density=0.05:scale=3:axes=y:contrast=1.4:octaves=3:method=exact", 3, 0, 0,
      { 0 }, { 0 } },
};

static void test_exact_against_reference(void **state)
{
    (void) state;
    rng g = { 20261123 };
    const int ncase = (int) (sizeof exact_cases / sizeof exact_cases[0]);
    const long per = scaled(1000);
    long total = 0;
    for (int i = 0; i < ncase; ++i) {
        const spec_case *sc = &exact_cases[i];
        ef_fog_component c;
        parse(sc->spec, &c);
        tally t = { 0 };
        for (long k = 0; k < per; ++k) {
            const ef_ray r = random_segment(&g, sc->scale, sc->has_box ? sc->bmin : NULL,
                                            sc->has_box ? sc->bmax : NULL, sc->offset_mag);
            check_exact_box(&c, &r, sc->has_box ? sc->bmin : NULL, sc->has_box ? sc->bmax : NULL,
                            &t);
        }
        printf("  %-60.60s %ld segs, %ld rel-checked, %ld inf, max rel %.2g\n", sc->spec, t.n,
               t.checked, t.inf_ok, t.max_rel);
        assert_int_equal(t.bad, 0);
        total += t.n;
        ef_fog_free(&c);
    }
    assert_true(total >= scaled(10000));
}

/* Sky rays: up-going with a falloff is finite and equals the reference;
 * down-going, level, or without falloff is opaque; a box makes it finite. */
static void test_sky(void **state)
{
    (void) state;
    ef_fog_component up, flat, boxed;
    parse("noise:density=0.05:scale=4:falloff=0.25:base=0:method=exact", &up);
    parse("noise:density=0.05,0,0.02:scale=4:method=exact", &flat);
    parse("noise:density=0.05:scale=4:min=-4,-4,-4:max=4,4,4:method=exact", &boxed);
    const double bmin[3] = { -4, -4, -4 }, bmax[3] = { 4, 4, 4 };
    const double o[3] = { 0.3, 1.7, -0.2 };
    tally t = { 0 };
    for (int k = 0; k < 40; ++k) {
        double d[3] = { cos(k * 0.7), 0.1 + 0.05 * k, sin(k * 0.7) };
        unit(d);
        ef_ray r = ray(o, d, INFINITY);
        check_exact(&up, &r, &t);
        check_exact_box(&boxed, &r, bmin, bmax, &t);
        double tau[3];
        ef_fog_tau(&flat, &r, tau, NULL);
        assert_true(isinf(tau[0]) && tau[1] == 0 && isinf(tau[2]));
        d[1] = -d[1];
        r = ray(o, d, INFINITY);
        ef_fog_tau(&up, &r, tau, NULL);
        assert_true(isinf(tau[0]));
        check_exact_box(&boxed, &r, bmin, bmax, &t);
    }
    assert_int_equal(t.bad, 0);
    ef_fog_free(&up);
    ef_fog_free(&flat);
    ef_fog_free(&boxed);
}

/* method=exact at the extremes of falloff, base and density (issue 47's
 * campaign saw a NaN there; 24 such SPECs here, clamped and separable
 * among them, give none): every channel's tau is a number >= 0 (inf where
 * the fog is opaque) and its error a number, on segments, long rays and
 * sky rays up, down and level, from the ground and from far above. */
static void test_exact_extremes(void **state)
{
    (void) state;
    static const char *const fogs[] = {
        "falloff=50:base=0", "falloff=1e3:base=0", "falloff=1e300:base=0",
        "falloff=1e300:base=1e300", "falloff=1e300:base=-1e300", "falloff=1e-300:base=0",
        "falloff=0.5:base=1e300", "falloff=0.5:base=-1e300",
    };
    static const char *const dens[] = { "density=1e-300", "density=0.05", "density=1e300" };
    static const char *const kinds[] = { "noise:%s:%s:scale=50:octaves=3:method=exact",
                                         "noise:%s:%s:scale=50:octaves=3:contrast=2:method=exact",
                                         "noise-separable:%s:%s:scale=50:octaves=3:method=exact" };
    const double orgs[2][3] = { { 0.3, 1.7, -0.2 }, { 0.3, 1e5, -0.2 } };
    const double dirs[4][3] = { { 0.6, 0.8, 0 }, { 0.6, -0.8, 0 }, { 1, 0, 0 }, { 0.8, 0.01, 0.6 } };
    const double lens[3] = { 5, 800, INFINITY };
    int n = 0;
    for (int k = 0; k < 3; ++k)
        for (int f = 0; f < 8; ++f) {
            char spec[200];
            snprintf(spec, sizeof spec, kinds[k], dens[(f + k) % 3], fogs[f]);
            ef_fog_component c;
            parse(spec, &c);
            for (int o = 0; o < 2; ++o)
                for (int d = 0; d < 4; ++d)
                    for (int l = 0; l < 3; ++l) {
                        double dir[3] = { dirs[d][0], dirs[d][1], dirs[d][2] }, tau[3];
                        unit(dir);
                        const ef_ray r = ray(orgs[o], dir, lens[l]);
                        ef_tau_info info;
                        ef_fog_tau(&c, &r, tau, &info);
                        for (int ch = 0; ch < 3; ++ch) {
                            if (!(tau[ch] >= 0) || info.err[ch] != info.err[ch])
                                print_error("%s along (%g,%g,%g) for %g: tau %g err %g\n", spec,
                                            dir[0], dir[1], dir[2], lens[l], tau[ch], info.err[ch]);
                            assert_true(tau[ch] >= 0);
                            assert_false(info.err[ch] != info.err[ch]);
                        }
                        ++n;
                    }
            ef_fog_free(&c);
        }
    assert_int_equal(n, 24 * 24);
}

/* A grazing sky ray in height fog, or a very long segment, is cut where
 * the fog is opaque (tau >= 60 at the least): T <= e^-60, and the error
 * output (ln 2: the true T lies in [0, T]) says so. */
static void test_opaque(void **state)
{
    (void) state;
    static const char *const specs[] = {
        "noise:density=0.05:scale=4:falloff=0.2:base=1:method=exact",
        "noise:density=0.05:scale=4:falloff=0.2:base=1:tol=0.000244140625",
        "noise:density=0.05,0,0.1:scale=4:method=steps",
        "noise-separable:density=0.05:scale=4:falloff=0.2:method=preintegrated",
    };
    for (int i = 0; i < 4; ++i) {
        ef_fog_component c;
        parse(specs[i], &c);
        const double o[3] = { 0, 1.7, 0 }, d[3] = { 0.6, 1e-7, 0.8 };
        const ef_ray r = ray(o, d, i == 2 ? 1e7 : INFINITY);
        double tau[3];
        ef_tau_info info;
        ef_fog_tau(&c, &r, tau, &info);
        if (!(tau[0] >= 60 && isfinite(tau[0]))) {
            print_error("%s: tau %g\n", specs[i], tau[0]);
            fail();
        }
        /* preintegrated is O(pieces) whatever the length: nothing to cut. */
        /* preintegrated: its bound, max(u, B integral(env)) */
        assert_true(i == 3 ? info.err[0] >= tau[0] : info.err[0] == log(2.0));
        assert_true(info.evals < 1e7);
        if (i == 2) {
            assert_true(tau[1] == 0 && info.err[1] == 0 && tau[2] >= 120);
        }
        ef_fog_free(&c);
    }
    /* The default (ttol=2^-12) stops once T is below 2^-14 in every
     * channel with density: the rest cannot move T by more. Its tau is
     * then the mean fog's to infinity plus the noise walked so far, and
     * the error output reaches from there to T's upper value at the stop
     * (at least ln 2: T itself). */
    ef_fog_component c;
    parse("noise:density=0.05:scale=4:falloff=0.2:base=1", &c);
    const double o[3] = { 0, 1.7, 0 }, d[3] = { 0.6, 1e-7, 0.8 };
    const ef_ray r = ray(o, d, INFINITY);
    double tau[3];
    ef_tau_info info;
    ef_fog_tau(&c, &r, tau, &info);
    assert_true(tau[0] >= log(4 / 0x1p-12) && isfinite(tau[0]));
    /* The true tau, by hand: the ray climbs at 1e-7, so its fog runs to
     * rho e^(-k (1.7 - 1)) / (k 1e-7), about 2e6 (less the noise's
     * c B share): T is 0 to double precision, and the error is T itself,
     * which the error output (T expm1(err) >= T: err >= ln 2) covers. */
    const double tau_hand = 0.05 * exp(-0.2 * 0.7) / (0.2 * 1e-7) * (1 - 0.9 * EF_NOISE_BOUND);
    assert_true(tau_hand > 1e5);
    assert_true(exp(-tau[0]) <= 0x1p-14);
    assert_true(info.err[0] >= log(2.0));
    /* T's upper value at the stop, T e^err, is below 2^-14 */
    assert_true(exp(-tau[0] + info.err[0]) <= 0x1p-14 * (1 + 1e-9));
    assert_true(info.evals < 1e5);
    ef_fog_free(&c);
}

/* Adaptive on segments that turn opaque: the coarsest octave walks ahead
 * alone, and where it, less the 4-sigma estimate of the other octaves,
 * passes tau = 60 the ray is cut with that lower value. So a cut tau is at
 * least 60 and not above the reference (the lower value), the error output
 * is T itself, and the finer octaves' cells are never walked: the walk
 * costs a fraction of the cells a full walk to the cut would cross. */
static void test_opaque_probe(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("noise:density=0.5:scale=4:tol=1e-3", &c);
    rng g = { 4242 };
    const long n = scaled(60);
    long cuts = 0;
    for (long k = 0; k < n; ++k) {
        double o[3], d[3], nd = 0;
        for (int a = 0; a < 3; ++a) {
            o[a] = uni(&g, -50, 50);
            d[a] = uni(&g, -1, 1);
            nd += d[a] * d[a];
        }
        for (int a = 0; a < 3; ++a)
            d[a] /= sqrt(nd);
        const ef_ray r = ray(o, d, uni(&g, 150, 600));   /* tau ~ 75 to 300 */
        long double ref[3];
        assert_int_equal(ef_ref_tau(&c, &r, ref, NULL), 0);
        double tau[3];
        ef_tau_info info;
        ef_fog_tau(&c, &r, tau, &info);
        if (!(info.err[0] == log(2.0))) {
            /* Not cut: integrated to the end, within the tolerance. */
            assert_true(fabs(tau[0] - (double) ref[0]) <= 2e-3);
            continue;
        }
        cuts++;
        if (!(tau[0] >= 60 && tau[0] <= (double) ref[0])) {
            print_error("tau %.17g ref %.17Lg\n", tau[0], ref[0]);
            fail();
        }
        /* A full walk of 4 octaves (frequencies 1, 2, 4, 8 per 4 units) to
         * where the mean fog reaches 60 (120 units at density 0.5). */
        const double l1 = fabs(d[0]) + fabs(d[1]) + fabs(d[2]);
        const double full = 120 * l1 * (1 + 2 + 4 + 8) / 4.0;
        assert_true(info.cells < 0.3 * full);
    }
    assert_true(cuts >= n * 9 / 10);
    ef_fog_free(&c);
}

/* ---- adaptive: the tolerance holds and the error output covers ---- */

static void test_adaptive(void **state)
{
    (void) state;
    static const char *const base[] = {
        "noise:density=0.05:scale=4",
        "noise:density=0.2:scale=2:octaves=6:falloff=0.1",
        "noise:density=0.05:scale=5:contrast=1.5",
        "noise-separable:density=0.05:scale=4:axes=xyz",
    };
    static const double tols[] = { 1e-2, 1e-3, 1e-4, 1e-6 };
    enum { NT = 4 };
    rng g = { 77 };
    for (int b = 0; b < 4; ++b) {
        ef_fog_component c[NT];
        long n = 0, within[NT] = { 0 }, within2[NT] = { 0 }, covered[NT] = { 0 }, cut[NT] = { 0 };
        double worst[NT] = { 0 }, evals[NT] = { 0 };
        for (int ti = 0; ti < NT; ++ti) {
            char spec[256];
            snprintf(spec, sizeof spec, "%s:tol=%g", base[b], tols[ti]);
            parse(spec, &c[ti]);
        }
        /* The reference once per segment, every tolerance on it. */
        const long per = scaled(b < 2 ? 1500 : 300);
        for (long k = 0; k < per; ++k) {
            ef_ray r = random_segment(&g, 4, NULL, NULL, 0);
            r.dist = r.planar = isinf(r.dist) ? 20 * uni(&g, 0, 1) : 3 * r.dist;  /* to ~70 m */
            long double ref[3];
            assert_int_equal(ef_ref_tau(&c[0], &r, ref, NULL), 0);
            n++;
            for (int ti = 0; ti < NT; ++ti) {
                double tau[3];
                ef_tau_info info;
                ef_fog_tau(&c[ti], &r, tau, &info);
                if (info.err[0] == log(2.0)) {
                    /* Cut where the fog turned opaque (tau >= 60, T <= 1e-26):
                     * a lower bound of tau, which no output can tell apart. */
                    assert_true(tau[0] >= 60 && tau[0] <= (double) ref[0] + tols[ti]);
                    cut[ti]++;
                    within[ti]++;
                    within2[ti]++;
                    covered[ti]++;
                    continue;
                }
                const double e = fabs(tau[0] - (double) ref[0]);
                within[ti] += e <= tols[ti];
                within2[ti] += e <= 2 * tols[ti];
                covered[ti] += e <= info.err[0];
                evals[ti] += info.evals;
                if (e > worst[ti])
                    worst[ti] = e;
            }
        }
        for (int ti = 0; ti < NT; ++ti) {
            printf("  %-52s %ld segs: within tol %.2f%%, within 2 tol %.2f%%, error output "
                   "covers %.2f%%, worst %.2g, %.0f evals/seg, %ld cut opaque\n", c[ti].spec, n,
                   100.0 * within[ti] / n, 100.0 * within2[ti] / n, 100.0 * covered[ti] / n,
                   worst[ti], evals[ti] / n, cut[ti]);
            assert_true(within[ti] >= 0.999 * n);
            assert_int_equal(within2[ti], n);
            assert_true(covered[ti] >= 0.999 * n);
            ef_fog_free(&c[ti]);
        }
    }
}

/* ttol=eps bounds |dT| = |e^-tau - e^-tau_ref| instead of |dtau|: at least
 * 99.9 % of segments within eps, all within 2 eps, the error output
 * (T expm1(err), as the error AOV) covering at least 99.9 %, per channel;
 * and on dense segments, where T is small, it costs fewer evaluations than
 * tol=eps (the point of it). Segments reach tau ~ 15, the second spec has
 * one channel thinner than the others. */
static void test_adaptive_ttol(void **state)
{
    (void) state;
    static const char *const base[] = {
        "noise:density=0.2:scale=4",
        "noise:density=0.3,0.3,0.05:scale=2:octaves=6:falloff=0.1",
        "noise:density=0.2:scale=5:contrast=1.5",
        "noise-separable:density=0.2:scale=4:axes=xyz",
    };
    static const double tols[] = { 1e-2, 1e-3, 1e-4 };
    enum { NT = 3 };
    rng g = { 91 };
    for (int b = 0; b < 4; ++b) {
        ef_fog_component c[NT], ct[NT];
        long n = 0, within[NT] = { 0 }, within2[NT] = { 0 }, covered[NT] = { 0 };
        double worst[NT] = { 0 }, ev[NT] = { 0 }, evt[NT] = { 0 };
        for (int ti = 0; ti < NT; ++ti) {
            char spec[256];
            snprintf(spec, sizeof spec, "%s:ttol=%g", base[b], tols[ti]);
            parse(spec, &c[ti]);
            snprintf(spec, sizeof spec, "%s:tol=%g", base[b], tols[ti]);
            parse(spec, &ct[ti]);
        }
        const long per = scaled(b < 2 ? 1000 : 250);
        for (long k = 0; k < per; ++k) {
            ef_ray r = random_segment(&g, 4, NULL, NULL, 0);
            r.dist = r.planar = isinf(r.dist) ? 70 * uni(&g, 0, 1) : 3 * r.dist;
            long double ref[3];
            assert_int_equal(ef_ref_tau(&c[0], &r, ref, NULL), 0);
            n++;
            for (int ti = 0; ti < NT; ++ti) {
                double tau[3], taut[3];
                ef_tau_info info, it;
                ef_fog_tau(&c[ti], &r, tau, &info);
                ef_fog_tau(&ct[ti], &r, taut, &it);
                ev[ti] += info.evals;
                evt[ti] += it.evals;
                double e = 0;
                int cov = 1;
                for (int ch = 0; ch < 3; ++ch) {
                    const double T = exp(-tau[ch]);
                    const double dT = (double) fabsl(expl(-(long double) tau[ch]) - expl(-ref[ch]));
                    cov &= dT <= (T > 0 ? T * expm1(info.err[ch]) : 0);
                    if (dT > e)
                        e = dT;
                }
                within[ti] += e <= tols[ti];
                within2[ti] += e <= 2 * tols[ti];
                covered[ti] += cov;
                if (e > worst[ti])
                    worst[ti] = e;
            }
        }
        for (int ti = 0; ti < NT; ++ti) {
            printf("  %-58s %ld segs: |dT| within ttol %.2f%%, within 2 ttol %.2f%%, error output "
                   "covers %.2f%%, worst %.2g, %.0f evals/seg (tol=%g: %.0f)\n", c[ti].spec, n,
                   100.0 * within[ti] / n, 100.0 * within2[ti] / n, 100.0 * covered[ti] / n,
                   worst[ti], ev[ti] / n, tols[ti], evt[ti] / n);
            assert_true(within[ti] >= 0.999 * n);
            assert_int_equal(within2[ti], n);
            assert_true(covered[ti] >= 0.999 * n);
            if (b < 2)   /* the noise model's budget grows with tau's lower value */
                assert_true(ev[ti] < 0.8 * evt[ti]);
            else   /* no lower value where the clamp can bind: log1p(eps), just below eps */
                assert_true(ev[ti] <= 1.02 * evt[ti]);
            ef_fog_free(&c[ti]);
            ef_fog_free(&ct[ti]);
        }
    }
    /* The key's grammar. */
    ef_fog_component x;
    ef_err err;
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    assert_int_not_equal(ef_fog_parse("noise:density=1:scale=1:ttol=1e-3:tol=1e-3", &ctx, &x, &err), 0);
    assert_non_null(strstr(err.msg, "not both"));
    assert_int_not_equal(ef_fog_parse("noise:density=1:scale=1:ttol=1", &ctx, &x, &err), 0);
    assert_int_not_equal(ef_fog_parse("noise:density=1:scale=1:ttol=0", &ctx, &x, &err), 0);
    assert_int_not_equal(ef_fog_parse("noise:density=1:scale=1:method=exact:ttol=1e-3", &ctx, &x, &err), 0);
}

/* The clamp's stop-loss tables (noise_clamp.h) against an independent
 * estimate: m_j(y) = E[max(0, X_j - y)] and v_j(y) = E[max(0, X_j - y)^2]
 * of X_j = sum_{i >= j} w_i noise_i, the octaves' actual sum (the
 * contract's fbm points, correlations and all) at 400,000 random points
 * (the tables assume independent octaves and sample one). Within 1.5e-3
 * (m) and 3e-4 (v) absolute, or 3 % relative: the sampling error of both
 * and the grid's. */
static void test_clamp_tables(void **state)
{
    (void) state;
    static const struct {
        int octaves;
        double gain;
    } F[] = { { 5, 0.5 }, { 8, 0.5 }, { 3, 0.7 }, { 1, 0.5 } };
    static const double ys[] = { -0.3, -0.05, 0, 0.05, 0.1, 0.2, 0.3, 0.45 };
    enum { NY = sizeof ys / sizeof ys[0], NS = 400000 };
    for (size_t f = 0; f < sizeof F / sizeof F[0]; ++f) {
        ef_fbm fb;
        ef_fbm_init(&fb, F[f].octaves, 2.0, F[f].gain);
        double *tab = malloc(ef_clamp_tables_size(fb.octaves) * sizeof *tab);
        assert_non_null(tab);
        assert_int_equal(ef_clamp_tables_build(&fb, tab), 0);
        const int nj = fb.octaves < 3 ? fb.octaves : 3;
        double m[3][NY] = { { 0 } }, v[3][NY] = { { 0 } }, var[3] = { 0 };
        rng g = { 4100 + f };
        for (long k = 0; k < NS; ++k) {
            double q[3] = { uni(&g, 0, 256), uni(&g, 0, 256), uni(&g, 0, 256) };
            double n[EF_FBM_MAX_OCTAVES];
            for (int i = 0; i < fb.octaves; ++i) {
                double u[3];
                ef_fbm_octave_point(&fb, i, q, u);
                n[i] = ef_noise3(u[0], u[1], u[2]);
            }
            for (int j = 0; j < nj; ++j) {
                double X = 0;
                for (int i = j; i < fb.octaves; ++i)
                    X += fb.weight[i] * n[i];
                var[j] += X * X;
                for (int y = 0; y < NY; ++y) {
                    const double r = X > ys[y] ? X - ys[y] : 0;
                    m[j][y] += r;
                    v[j][y] += r * r;
                }
            }
        }
        for (int j = 0; j < nj; ++j) {
            const double vt = ef_clamp_var(tab, fb.octaves, j), vs = var[j] / NS;
            assert_true(fabs(vt - vs) <= 0.05 * vs);
            for (int y = 0; y < NY; ++y) {
                double vv;
                const double mt = ef_clamp_m(tab, fb.octaves, j, ys[y], &vv);
                const double ms = m[j][y] / NS, vs2 = v[j][y] / NS;
                if (!(fabs(mt - ms) <= fmax(1.5e-3, 0.03 * ms)) ||
                    !(fabs(vv - vs2) <= fmax(3e-4, 0.03 * vs2))) {
                    print_error("octaves %d gain %g j %d y %g: m %g (sampled %g), v %g (%g)\n",
                                fb.octaves, F[f].gain, j, ys[y], mt, ms, vv, vs2);
                    fail();
                }
            }
        }
        /* every octave resolved: X = 0 */
        double vv;
        assert_true(ef_clamp_m(tab, fb.octaves, fb.octaves, -0.25, &vv) == 0.25 && vv == 0.0625);
        assert_true(ef_clamp_m(tab, fb.octaves, fb.octaves, 0.25, &vv) == 0 && vv == 0);
        free(tab);
    }
}

/* The reference splits its pieces at the clamp's kinks (fog.h's kink
 * hook): on a segment through patchy fog (contrast -3, where 1 + c fbm
 * crosses 0 twice), its tau agrees with a plain midpoint sum of the
 * density (fbm from noise.h, 4 million points: error far below 1e-9) to
 * 1e-9, with every interval converged. */
static void test_reference_kinks(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("noise:density=0.25:scale=4:octaves=3:contrast=-3", &c);
    const double o[3] = { 5.9260609530290225, 3.0091770708421, 0.056875511642884291 };
    const double d[3] = { 0, -0.87631366301246527, 0.48174097191091764 };
    const double L = 7.5769752363601626;
    ef_ray r = ray(o, d, L);
    long double ref[3];
    ef_ref_stats st;
    assert_int_equal(ef_ref_tau(&c, &r, ref, &st), 0);
    assert_int_equal(st.unconverged, 0);
    ef_fbm f;
    ef_fbm_init(&f, 3, 2.0, 0.5);
    const long n = scaled(4000000);
    long double sum = 0;
    for (long k = 0; k < n; ++k) {
        const double t = (k + 0.5) * L / n;
        double q[3];
        for (int a = 0; a < 3; ++a)
            q[a] = (o[a] + t * d[a]) / 4;
        const double x = 1 - 3 * ef_fbm_eval(&f, q);
        sum += x > 0 ? x : 0;
    }
    const long double mid = 0.25L * sum * L / n;
    printf("  reference %.12Lg, midpoint sum %.12Lg (%ld pieces)\n", ref[0], mid, st.pieces);
    assert_true(fabsl(ref[0] - mid) <= 1e-9L * mid);
    ef_fog_free(&c);
}

/* The clamped noise model (|c| above 1 / EF_NOISE_BOUND: patchy fog) on the
 * default method's fast path against the reference integrator: |dT| within
 * the default ttol 2^-12 on 99.9 % of segments and within twice it on all,
 * the error output covering the actual error on 99.9 %; and a contrast
 * whose clamp never binds in practice (1.2: fbm stays above -0.7 on 4
 * million sampled points) costs no more than the unclamped 0.9 on the
 * same rays. */
static void test_clamp_fast_path(void **state)
{
    (void) state;
    static const char *const specs[] = {
        "noise:density=0.3:scale=3:contrast=1.2",
        "noise:density=0.3:scale=3:octaves=6:contrast=2:falloff=0.1:base=-2",
        "noise:density=0.2:scale=2:octaves=5:contrast=4",
        "noise:density=0.25,0.2,0.1:scale=4:octaves=3:contrast=-3:min=-6,-4,-6:max=6,4,6",
        "noise:density=0.4:scale=1.5:octaves=8:contrast=2.5:falloff=0.3:base=1",
    };
    rng g = { 4141 };
    for (size_t k = 0; k < sizeof specs / sizeof specs[0]; ++k) {
        ef_fog_component c;
        parse(specs[k], &c);
        const long per = scaled(300);
        long within = 0, within2 = 0, covered = 0;
        double worst = 0, ev = 0;
        const double bmin[3] = { -6, -4, -6 }, bmax[3] = { 6, 4, 6 };
        for (long n = 0; n < per; ++n) {
            ef_ray r = random_segment(&g, 3, k == 3 ? bmin : NULL, k == 3 ? bmax : NULL, 0);
            if (isinf(r.dist))
                r.dist = r.planar = k == 3 ? box_exit(bmin, bmax, &r) : 40 * uni(&g, 0.2, 1);
            long double ref[3];
            assert_int_equal(ef_ref_tau(&c, &r, ref, NULL), 0);
            double tau[3];
            ef_tau_info info;
            ef_fog_tau(&c, &r, tau, &info);
            ev += info.evals;
            double e = 0;
            int cov = 1;
            for (int ch = 0; ch < 3; ++ch) {
                const long double T = expl(-(long double) tau[ch]);
                const double dT = (double) fabsl(T - expl(-ref[ch]));
                cov &= dT <= (double) (T > 0 ? T * expm1l(info.err[ch]) : 0);
                e = fmax(e, dT);
            }
            within += e <= 0x1p-12;
            within2 += e <= 0x1p-11;
            covered += cov;
            worst = fmax(worst, e);
            if (!cov)
                printf("  not covered: org %.17g,%.17g,%.17g dir %.17g,%.17g,%.17g len %.17g: tau "
                       "%.9g ref %.9Lg err %.3g\n", r.org[0], r.org[1], r.org[2], r.dir[0],
                       r.dir[1], r.dir[2], r.dist, tau[0], ref[0], info.err[0]);
        }
        printf("  %-70s %ld segs: within 2^-12 %.2f%%, covered %.2f%%, worst %.2g, %.0f evals/seg\n",
               specs[k], per, 100.0 * within / per, 100.0 * covered / per, worst, ev / per);
        assert_true(within >= 0.999 * per);
        assert_int_equal(within2, per);
        assert_true(covered >= 0.999 * per);
        ef_fog_free(&c);
    }
    /* The clamp that never binds costs nothing. */
    ef_fog_component a, b;
    parse("noise:density=0.05:scale=4:octaves=5:contrast=0.9:falloff=0.05", &a);
    parse("noise:density=0.05:scale=4:octaves=5:contrast=1.2:falloff=0.05", &b);
    double ea = 0, eb = 0;
    rng h = { 77 };
    for (int n = 0; n < 400; ++n) {
        ef_ray r = random_segment(&h, 4, NULL, NULL, 0);
        if (isinf(r.dist))
            r.dist = r.planar = 200;
        double tau[3];
        ef_tau_info ia, ib;
        ef_fog_tau(&a, &r, tau, &ia);
        ef_fog_tau(&b, &r, tau, &ib);
        ea += ia.evals;
        eb += ib.evals;
    }
    printf("  contrast 0.9: %.0f evals/seg, 1.2: %.0f\n", ea / 400, eb / 400);
    assert_true(eb <= 1.3 * ea);
    ef_fog_free(&a);
    ef_fog_free(&b);
}

/* tau of c on r against the reference in channel 0: counts into *bad a
 * ray whose |dT| is over 2^-12 or not covered by the error output, keeps
 * the largest |dT| in *worst, gives the reference's tau in *ref0 (may be
 * NULL); returns the evaluations. */
static double ray_vs_ref(const ef_fog_component *c, const ef_ray *r, double *worst, long *bad,
                         long double *ref0)
{
    long double ref[3];
    assert_int_equal(ef_ref_tau(c, r, ref, NULL), 0);
    double tau[3];
    ef_tau_info in;
    ef_fog_tau(c, r, tau, &in);
    const long double T = expl(-(long double) tau[0]);
    const double dT = (double) fabsl(T - expl(-ref[0]));
    const int cov = dT <= (double) (T > 0 ? T * expm1l(in.err[0]) : 0) || dT == 0;
    *worst = fmax(*worst, dT);
    if (!(dT <= 0x1p-12) || !cov) {
        ++*bad;
        printf("  ray: tau %.9g ref %.9Lg err %.3g\n", tau[0], ref[0], in.err[0]);
    }
    if (ref0)
        *ref0 = ref[0];
    return in.evals;
}

/* Patchy fog that the rays end opaque in (a camera high above steep
 * height fog, looking down into it: the bench sweep's sweep-22). The
 * clamp left every lower value of the ray's depth at 0, so the early thin
 * stretches were integrated as if the pixel stayed clear: 5,293 noise
 * evaluations a pixel where contrast 0.9 took none. The pilot's certified
 * lower bound lets them go. Against the reference: T within 2^-12 and
 * the error output covering it on every ray, sky rays (which the pilot
 * leaves alone) included; and the patchy rays cost at most a few times
 * what the same rays cost at contrast 0.9 (the work, not time). */
static void test_clamp_opaque_pilot(void **state)
{
    (void) state;
    ef_fog_component patchy, smooth;
    parse("noise:density=0.01658:scale=12.5:octaves=7:contrast=2.61:falloff=0.2125:base=52.75",
          &patchy);
    parse("noise:density=0.01658:scale=12.5:octaves=7:contrast=0.9:falloff=0.2125:base=52.75",
          &smooth);
    rng g = { 2261 };
    const long n = scaled(120);
    double ep = 0, es = 0, worst = 0;
    long bad = 0, opaque = 0;
    for (long k = 0; k < n; ++k) {
        const double h = uni(&g, 40, 90), pitch = uni(&g, -0.8, 0.1), yaw = uni(&g, -3, 3);
        ef_ray r = { { cos(pitch) * sin(yaw), sin(pitch), -cos(pitch) * cos(yaw) }, 0, 0,
                     { uni(&g, -50, 50), h, uni(&g, -50, 50) } };
        /* to the ground y = 0, or 300 units into the sky */
        r.dist = r.planar = r.dir[1] < -1e-3 ? h / -r.dir[1] : 300;
        long double ref0;
        ep += ray_vs_ref(&patchy, &r, &worst, &bad, &ref0);
        opaque += ref0 > 20;
        double tau[3];
        ef_tau_info is;
        ef_fog_tau(&smooth, &r, tau, &is);
        es += is.evals;
    }
    printf("  %ld rays (%ld opaque): worst |dT| %.2g; evals/ray contrast 2.61 %.0f, 0.9 %.0f\n", n,
           opaque, worst, ep / n, es / n);
    assert_int_equal(bad, 0);
    assert_true(opaque >= n / 3);
    assert_true(ep <= 4 * es + 200.0 * n);
    ef_fog_free(&patchy);
    ef_fog_free(&smooth);
}

/* noise-separable (no fast path) on rays that end opaque: under ttol the
 * piece-by-piece walk stops where T is surely below ttol/4, as the fast
 * path does, not at tau 60 (sweep-18: 13,040 noise evaluations a pixel
 * to 4,619). Against the reference: T within 2^-12 with the error output
 * covering on every ray; and a fraction of the work of tol= on the same
 * rays (which walks on to tau 60). */
static void test_separable_stop(void **state)
{
    (void) state;
    ef_fog_component d, t;
    parse("noise-separable:density=0.2:scale=6:octaves=3:contrast=0.3:axes=xz", &d);
    parse("noise-separable:density=0.2:scale=6:octaves=3:contrast=0.3:axes=xz:tol=0x1p-12", &t);
    rng g = { 1818 };
    const long n = scaled(60);
    double ed = 0, et = 0, worst = 0;
    long bad = 0;
    for (long k = 0; k < n; ++k) {
        ef_ray r = random_segment(&g, 5, NULL, NULL, 0);
        r.dist = r.planar = uni(&g, 300, 500);   /* tau about 60 to 100 */
        ed += ray_vs_ref(&d, &r, &worst, &bad, NULL);
        double tau[3];
        ef_tau_info it;
        ef_fog_tau(&t, &r, tau, &it);
        et += it.evals;
    }
    printf("  %ld opaque rays: worst |dT| %.2g; evals/ray default %.0f, tol=2^-12 %.0f\n", n, worst,
           ed / n, et / n);
    assert_int_equal(bad, 0);
    assert_true(ed <= 0.4 * et);
    ef_fog_free(&d);
    ef_fog_free(&t);
}

/* Coarser tolerances must cost fewer evaluations (the trade is real). */
static void test_adaptive_cost_falls_with_tol(void **state)
{
    (void) state;
    ef_fog_component fine, coarse, exact;
    parse("noise:density=0.05:scale=4:octaves=6:tol=1e-6", &fine);
    parse("noise:density=0.05:scale=4:octaves=6:tol=1e-2", &coarse);
    parse("noise:density=0.05:scale=4:octaves=6:method=exact", &exact);
    rng g = { 5 };
    double ef = 0, ec = 0, ex = 0, dropped = 0;
    for (int k = 0; k < 200; ++k) {
        double o[3] = { uni(&g, -5, 5), uni(&g, -5, 5), uni(&g, -5, 5) }, d[3];
        sphere(&g, d);
        const ef_ray r = ray(o, d, 80);
        double tau[3];
        ef_tau_info a, b, x;
        ef_fog_tau(&fine, &r, tau, &a);
        ef_fog_tau(&coarse, &r, tau, &b);
        ef_fog_tau(&exact, &r, tau, &x);
        ef += a.evals;
        ec += b.evals;
        ex += x.evals;
        dropped += b.dropped;
    }
    printf("  evals per segment: exact %.0f, tol 1e-6 %.0f, tol 1e-2 %.0f (%.1f octaves dropped)\n",
           ex / 200, ef / 200, ec / 200, dropped / 200);
    assert_true(ec < ef && ef < ex);
    assert_true(dropped > 0);
    ef_fog_free(&fine);
    ef_fog_free(&coarse);
    ef_fog_free(&exact);
}

/* ---- steps: the midpoint sum, written out from the density ---- */

static void test_steps(void **state)
{
    (void) state;
    ef_fog_component c, ex;
    parse("noise:density=0.05:scale=4:falloff=0.05:method=steps:steps=37", &c);
    parse("noise:density=0.05:scale=4:falloff=0.05:method=exact", &ex);
    ef_fog_functional f[8];
    const int nf = c.model->functionals(&c, f, 8);
    assert_int_equal(nf, 4);
    rng g = { 9 };
    for (int k = 0; k < 200; ++k) {
        double o[3] = { uni(&g, -5, 5), uni(&g, -5, 5), uni(&g, -5, 5) }, d[3];
        sphere(&g, d);
        const double L = uni(&g, 1, 60);
        const ef_ray r = ray(o, d, L);
        long double sum = 0;
        for (int j = 0; j < 37; ++j) {
            const long double t = (j + 0.5L) * L / 37;
            long double v[4], out[3];
            for (int i = 0; i < nf; ++i)
                v[i] = f[i].n[0] * (o[0] + t * d[0]) + f[i].n[1] * (o[1] + t * d[1]) +
                       f[i].n[2] * (o[2] + t * d[2]) + f[i].d;
            c.model->density(&c, v, out);
            sum += out[0];
        }
        const double want = (double) (sum * L / 37);
        double tau[3], tx[3];
        ef_tau_info info;
        ef_fog_tau(&c, &r, tau, &info);
        assert_true(fabs(tau[0] - want) <= 1e-12 * want + 1e-300);
        ef_fog_tau(&ex, &r, tx, NULL);
        assert_true(fabs(tau[0] - tx[0]) <= info.err[0]);
        assert_true(info.evals == 37 * 4);
    }
    ef_fog_free(&c);
    ef_fog_free(&ex);
}

/* ---- preintegrated: the seed's product of means ---- */

/* The mean of factor `axis` of c's field over the segment, by the
 * reference integrator on a one-axis component of the same noise. */
static double factor_mean_ref(const char *params, char axis, const ef_ray *r)
{
    char spec[512];
    snprintf(spec, sizeof spec, "noise-separable:density=1:%s:axes=%c:method=exact", params, axis);
    ef_fog_component c;
    parse(spec, &c);
    long double tau[3];
    assert_int_equal(ef_ref_tau(&c, r, tau, NULL), 0);
    ef_fog_free(&c);
    return (double) tau[0] / r->dist;
}

static void test_preintegrated(void **state)
{
    (void) state;
    const char *params = "scale=4:octaves=4:contrast=0.8:seed=2";
    char spec[512];
    rng g = { 11 };
    /* Integer lacunarity: one merged table per axis; else per-octave tables. */
    for (int K = 1; K <= 8; K *= 2) {
        if (K == 8)
            params = "scale=4:octaves=3:contrast=0.8:seed=2:lacunarity=2.5";
        snprintf(spec, sizeof spec, "noise-separable:density=0.07:%s:axes=xz:falloff=0.1:base=1:"
                 "method=preintegrated:pieces=%d", params, K);
        ef_fog_component c;
        parse(spec, &c);
        for (int k = 0; k < 40; ++k) {
            double o[3] = { uni(&g, -9, 9), uni(&g, -3, 3), uni(&g, -9, 9) }, d[3];
            sphere(&g, d);
            const double L = uni(&g, 0.5, 50);
            const ef_ray r = ray(o, d, L);
            /* The envelope e^(-0.1 (y - 1)) averaged over each piece by hand. */
            double want = 0;
            for (int p = 0; p < K; ++p) {
                double op[3];
                for (int a = 0; a < 3; ++a)
                    op[a] = o[a] + d[a] * (L * p / K);
                const ef_ray rp = ray(op, d, L / K);
                const double y0 = op[1], y1 = op[1] + d[1] * L / K;
                const double env = fabs(y1 - y0) < 1e-9
                                       ? exp(-0.1 * (y0 - 1))
                                       : (exp(-0.1 * (y0 - 1)) - exp(-0.1 * (y1 - 1))) /
                                             (0.1 * (y1 - y0));
                want += 0.07 * (L / K) * env * factor_mean_ref(params, 'x', &rp) *
                        factor_mean_ref(params, 'z', &rp);
            }
            double tau[3], unbound[3];
            /* Bound to this ray's origin (the per-frame cache hit, as the
             * CLI's camera rays see it) and to a point elsewhere (a miss):
             * the same bits. */
            const double far[3] = { 1e3, -7, 2e3 };
            ef_fog_bind(&c, o);
            ef_fog_tau(&c, &r, tau, NULL);
            ef_fog_bind(&c, far);
            ef_fog_tau(&c, &r, unbound, NULL);
            assert_memory_equal(tau, unbound, sizeof tau);
            if (!(fabs(tau[0] - want) <= 1e-9 * want)) {
                print_error("K=%d: tau %.17g, product of means %.17g\n", K, tau[0], want);
                fail();
            }
        }
        ef_fog_free(&c);
    }
    params = "scale=4:octaves=4:contrast=0.8:seed=2";
    /* Exact when only one factor varies: a ray along x sees z constant. */
    snprintf(spec, sizeof spec, "noise-separable:density=0.07:%s:axes=xz:method=preintegrated", params);
    ef_fog_component c, ex;
    parse(spec, &c);
    snprintf(spec, sizeof spec, "noise-separable:density=0.07:%s:axes=xz:method=exact", params);
    parse(spec, &ex);
    for (int k = 0; k < 30; ++k) {
        const double o[3] = { uni(&g, -9, 9), uni(&g, -3, 3), uni(&g, -9, 9) };
        const double d[3] = { k % 2 ? 1 : -1, 0, 0 }, dy[3] = { 0, 1, 0 };
        const ef_ray r = ray(o, k % 3 ? d : dy, uni(&g, 1, 80));
        double tau[3];
        long double ref[3];
        ef_fog_tau(&c, &r, tau, NULL);
        assert_int_equal(ef_ref_tau(&ex, &r, ref, NULL), 0);
        assert_true(fabs(tau[0] - (double) ref[0]) <= 1e-9 * (double) ref[0]);
    }
    /* Converges as pieces grows, on oblique rays. */
    double err[4] = { 0, 0, 0, 0 };
    static const int Ks[4] = { 1, 4, 16, 64 };
    for (int ki = 0; ki < 4; ++ki) {
        snprintf(spec, sizeof spec, "noise-separable:density=0.07:%s:axes=xz:method=preintegrated:"
                 "pieces=%d", params, Ks[ki]);
        ef_fog_component p;
        parse(spec, &p);
        rng h = { 3 };
        for (int k = 0; k < 60; ++k) {
            double o[3] = { uni(&h, -9, 9), uni(&h, -3, 3), uni(&h, -9, 9) }, d[3];
            sphere(&h, d);
            const ef_ray r = ray(o, d, 60);
            double tau[3];
            long double ref[3];
            ef_fog_tau(&p, &r, tau, NULL);
            assert_int_equal(ef_ref_tau(&ex, &r, ref, NULL), 0);
            const double e = (tau[0] - (double) ref[0]) / (double) ref[0];
            err[ki] += e * e / 60;
        }
        err[ki] = sqrt(err[ki]);
        ef_fog_free(&p);
    }
    printf("  preintegrated rms relative error at pieces 1, 4, 16, 64: %.2g %.2g %.2g %.2g\n", err[0],
           err[1], err[2], err[3]);
    assert_true(err[1] < err[0] && err[2] < err[1] && err[3] < err[2] && err[3] < 1e-4);
    ef_fog_free(&c);
    ef_fog_free(&ex);
}

/* pieces=1 over spans of camera rays (ef_fog_tau_add, the vector lanes):
 * against the product of means computed on their own (the reference
 * integrator per factor, the envelope's mean by hand) for short rays that
 * end inside the camera's table piece either way, medium ones, long ones,
 * and rays into the table's next or previous period. */
static void test_preintegrated_span(void **state)
{
    (void) state;
    /* The camera 0.05 (in q) below the table's period end on x, 0.81 above
     * its start on z: rays cross from one period into the next. */
    const char *params = "scale=4:octaves=4:contrast=0.8:offset=-1021.3,0,0";
    char spec[512];
    snprintf(spec, sizeof spec, "noise-separable:density=0.07:%s:axes=xz:falloff=0.1:base=1:"
             "method=preintegrated", params);
    ef_fog_component c;
    parse(spec, &c);
    rng g = { 41 };
    enum { N = 160 };
    const double cam[3] = { 2.5, 1.7, -3.25 };
    ef_fog_bind(&c, cam);
    ef_ray r[N];
    for (int j = 0; j < N; ++j) {
        double d[3];
        sphere(&g, d);
        const double L = j % 4 == 0 ? uni(&g, 1e-3, 0.3) : j % 10 == 1 ? uni(&g, 50, 1500)
                                                                        : uni(&g, 0.5, 50);
        r[j] = ray(cam, d, L);
    }
    double acc[N][3];
    memset(acc, 0, sizeof acc);
    ef_fog_tau_add(&c, r, N, acc);
    int short_in = 0;
    for (int j = 0; j < N; ++j) {
        const double L = r[j].dist, y0 = cam[1], y1 = cam[1] + r[j].dir[1] * L;
        const double env = fabs(y1 - y0) < 1e-9 ? exp(-0.1 * (y0 - 1))
                                                : (exp(-0.1 * (y0 - 1)) - exp(-0.1 * (y1 - 1))) /
                                                      (0.1 * (y1 - y0));
        const double want = 0.07 * L * env * factor_mean_ref(params, 'x', &r[j]) *
                            factor_mean_ref(params, 'z', &r[j]);
        short_in += L < 0.3;
        if (!(fabs(acc[j][0] - want) <= 1e-9 * want)) {
            print_error("ray %d (length %.6g): tau %.17g, product of means %.17g\n", j, L,
                        acc[j][0], want);
            fail();
        }
    }
    assert_true(short_in >= N / 4);
    ef_fog_free(&c);
}

/* The span entry (ef_fog_tau_add, what the fog pass calls) adds exactly
 * the bits ef_fog_tau gives ray by ray: camera rays of every kind (ground,
 * sky up and down, zero length, inside and outside a box), bound to the
 * camera and not, for the staged pieces=1 path and the others. */
static void test_span_same_bits(void **state)
{
    (void) state;
    static const char *const specs[] = {
        "noise-separable:density=0.05,0.04,0:scale=4:axes=xz:falloff=0.1:base=1:method=preintegrated",
        "noise-separable:density=0.05:scale=4:axes=xyz:falloff=0.3:method=preintegrated:min=-20,-1,-30:"
        "max=20,6,5",
        "noise-separable:density=0.05:scale=4:axes=y:method=preintegrated:pieces=3",
        "noise-separable:density=0.05:scale=4:falloff=2e3:base=-1:method=preintegrated",
        "noise:density=0.05:scale=4:octaves=2:tol=1e-3",
    };
    rng g = { 29 };
    enum { N = 203 };
    for (size_t si = 0; si < sizeof specs / sizeof *specs; ++si) {
        ef_fog_component c;
        parse(specs[si], &c);
        const double cam[3] = { uni(&g, -5, 5), uni(&g, 0, 3), uni(&g, -5, 5) };
        ef_ray r[N];
        for (int j = 0; j < N; ++j) {
            double d[3];
            sphere(&g, d);
            const double L = j % 7 == 0 ? INFINITY : j % 11 == 0 ? 0 : uni(&g, 0.1, 120);
            r[j] = ray(j % 13 == 0 ? (double[3]) { 1, 2, 3 } : cam, d, L);
        }
        for (int bound = 0; bound < 2; ++bound) {
            if (bound)
                ef_fog_bind(&c, cam);
            double acc[N][3];
            for (int j = 0; j < N; ++j)
                acc[j][0] = acc[j][1] = acc[j][2] = 0.25;
            ef_fog_tau_add(&c, r, N, acc);
            for (int j = 0; j < N; ++j) {
                double t[3];
                ef_fog_tau(&c, &r[j], t, NULL);
                for (int k = 0; k < 3; ++k)
                    if (memcmp(&(double) { 0.25 + t[k] }, &acc[j][k], sizeof(double))) {
                        print_error("%s ray %d channel %d: span %.17g, single %.17g\n", specs[si],
                                    j, k, acc[j][k], 0.25 + t[k]);
                        fail();
                    }
            }
        }
        ef_fog_free(&c);
    }
}

/* ---- the field's definition ---- */

static double tau_exact(const char *spec, const double o[3], const double d[3], double L)
{
    ef_fog_component c;
    parse(spec, &c);
    const ef_ray r = ray(o, d, L);
    double tau[3];
    ef_fog_tau(&c, &r, tau, NULL);
    ef_fog_free(&c);
    return tau[0];
}

/* offset, velocity * time and seed are translations of the field. */
static void test_translations(void **state)
{
    (void) state;
    const double o[3] = { 1.5, 2.25, -3 }, d[3] = { 0.6, 0.0, 0.8 };
    const double base = tau_exact("noise:density=0.1:scale=4:method=exact", o, d, 30);
    const double sh[3] = { 2.5, -1.25, 7 };
    const double o2[3] = { o[0] + sh[0], o[1] + sh[1], o[2] + sh[2] };
    const double off = tau_exact("noise:density=0.1:scale=4:offset=2.5,-1.25,7:method=exact", o2, d, 30);
    assert_true(fabs(off - base) <= 1e-12 * base);
    /* velocity (1, -0.5, 2.8) at time 2.5 is the same shift. */
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.time = 2.5;
    ef_fog_component c;
    ef_err err;
    assert_int_equal(ef_fog_parse("noise:density=0.1:scale=4:velocity=1,-0.5,2.8:method=exact",
                                  &ctx, &c, &err), 0);
    const ef_ray r2 = ray(o2, d, 30);
    double t[3];
    ef_fog_tau(&c, &r2, t, NULL);
    assert_true(fabs(t[0] - base) <= 1e-12 * base);
    ef_fog_free(&c);
    /* seed s adds s S to q: the field moved by -s S scale. */
    const double s = 0.125;
    double o3[3];
    for (int a = 0; a < 3; ++a)
        o3[a] = o[a] - s * ef_noise_seed_dir[a] * 4;
    const double seeded = tau_exact("noise:density=0.1:scale=4:seed=0.125:method=exact", o3, d, 30);
    assert_true(fabs(seeded - base) <= 1e-11 * base);
    /* and a different seed is a different field */
    assert_true(fabs(tau_exact("noise:density=0.1:scale=4:seed=1:method=exact", o, d, 30) - base) >
                1e-3 * base);
}

/* The density at points, from fbm by hand: clamp, envelope and box. */
static void test_density_definition(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("noise:density=0.2:scale=5:contrast=6:falloff=0.5:base=1:min=-10,-10,-10:max=10,10,10",
          &c);
    ef_fbm f;
    ef_fbm_init(&f, 4, 2, 0.5);
    rng g = { 1 };
    int zeros = 0;
    for (int k = 0; k < 2000; ++k) {
        const double p[3] = { uni(&g, -12, 12), uni(&g, -12, 12), uni(&g, -12, 12) };
        const double q[3] = { p[0] / 5, p[1] / 5, p[2] / 5 };
        const double fb = ef_fbm_eval(&f, q);
        const int inside = fabs(p[0]) <= 10 && fabs(p[1]) <= 10 && fabs(p[2]) <= 10;
        const double want = inside ? 0.2 * exp(-0.5 * (p[1] - 1)) * fmax(0, 1 + 6 * fb) : 0;
        const long double v[4] = { p[0], p[1], p[2], p[1] - 1 };
        long double out[3];
        c.model->density(&c, v, out);
        /* q is formed in long double by the model, in double here: the
         * difference is far below 1e-12 of the unclamped scale. */
        const double scale = 0.2 * exp(-0.5 * (p[1] - 1)) * 7.3;
        assert_true(fabs((double) out[0] - want) <= 1e-12 * scale);
        zeros += inside && want == 0;
    }
    assert_true(zeros > 20);   /* the clamp binds somewhere */
    ef_fog_free(&c);
    /* A segment that misses the box has no fog; one inside it equals the
     * same field without the box. */
    const double o[3] = { 20, 0, 0 }, dx[3] = { 0, 1, 0 }, o2[3] = { 1, -2, 3 }, dd[3] = { 0.6, 0.8, 0 };
    assert_true(tau_exact("noise:density=0.2:scale=5:min=-10,-10,-10:max=10,10,10:method=exact",
                          o, dx, 50) == 0);
    const double a = tau_exact("noise:density=0.2:scale=5:min=-10,-10,-10:max=10,10,10:method=exact",
                               o2, dd, 5);
    const double b = tau_exact("noise:density=0.2:scale=5:method=exact", o2, dd, 5);
    assert_true(fabs(a - b) <= 1e-13 * b);
}

/* lod=pixel (the man page's definition): with the camera bound at C and
 * a pixel footprint of w per unit distance, octave i's weight at a point
 * at distance s from C is 1 while its cell lambda_i is at least four
 * footprints (s <= S_i = lambda_i / (4 w)), then e^(-4 (s / S_i - 1)).
 * The model's density against that formula written here from the public
 * fbm (ef_fbm_octave_point, ef_noise3); tau along rays from the camera
 * (the fast path) and from elsewhere (a light's: the faded density piece
 * by piece) against the reference integrator on that density; the
 * refusals. */
static void expect_usage(const char *spec, const char *needle);

static void test_lod_pixel(void **state)
{
    (void) state;
    const double cam[3] = { 3, 2, -1 }, w = 0.01;
    ef_fog_component c;
    parse("noise:density=0.2:scale=5:octaves=5:falloff=0.3:base=1:contrast=0.9:lod=pixel", &c);
    c.spread = w;
    ef_fog_bind(&c, cam);
    ef_fbm f;
    ef_fbm_init(&f, 5, 2, 0.5);
    rng g = { 77 };
    double worst = 0;
    int faded = 0;
    for (int k = 0; k < 3000; ++k) {
        double d[3];
        sphere(&g, d);
        const double s = uni(&g, 0, 400);
        const double p[3] = { cam[0] + s * d[0], cam[1] + s * d[1], cam[2] + s * d[2] };
        const double q[3] = { p[0] / 5, p[1] / 5, p[2] / 5 };
        double fb = 0;
        for (int i = 0; i < 5; ++i) {
            double u[3];
            ef_fbm_octave_point(&f, i, q, u);
            const double S = 5 / f.freq[i] / (4 * w), x = s / S;
            const double phi = x <= 1 ? 1 : exp(-4 * (x - 1));
            faded += phi < 0.5;
            fb += f.weight[i] * phi * ef_noise3(u[0], u[1], u[2]);
        }
        const double env = 0.2 * exp(-0.3 * (p[1] - 1));
        const double want = env * (1 + 0.9 * fb);
        const long double v[4] = { p[0], p[1], p[2], p[1] - 1 };
        long double out[3];
        c.model->density(&c, v, out);
        worst = fmax(worst, fabs((double) out[0] - want) / (env * 1.94));
    }
    printf("  lod=pixel density: %d octave points faded below half, worst |diff| %.2g of the "
           "density's scale\n", faded, worst);
    assert_true(worst <= 1e-12);
    assert_true(faded > 3000);
    /* tau: rays from the camera and from elsewhere */
    long n = 0, within = 0, covered = 0;
    double worst_dT = 0;
    for (int k = 0; k < (int) scaled(400); ++k) {
        const int from_cam = k % 4 != 0;
        double d[3], o[3];
        sphere(&g, d);
        d[1] = -fabs(d[1]) * (chance(&g, 0.5) ? 0.1 : 1);   /* down, many grazing */
        unit(d);
        for (int a = 0; a < 3; ++a)
            o[a] = from_cam ? cam[a] : cam[a] + uni(&g, -40, 40);
        const ef_ray r = ray(o, d, uni(&g, 1, from_cam ? 400 : 120));
        long double ref[3];
        assert_int_equal(ef_ref_tau(&c, &r, ref, NULL), 0);
        double tau[3];
        ef_tau_info info;
        ef_fog_tau(&c, &r, tau, &info);
        double e = 0;
        int cov = 1;
        for (int ch = 0; ch < 3; ++ch) {
            const double T = exp(-tau[ch]);
            const double dT = (double) fabsl(expl(-(long double) tau[ch]) - expl(-ref[ch]));
            cov &= dT <= (T > 0 ? T * expm1(info.err[ch]) : 0) + 1e-12;
            e = fmax(e, dT);
        }
        n++;
        within += e <= 0x1p-12;
        covered += cov;
        worst_dT = fmax(worst_dT, e);
    }
    printf("  lod=pixel tau: %ld rays (a quarter not from the camera): within 2^-12 %ld, error "
           "output covers %ld, worst |dT| %.2g\n", n, within, covered, worst_dT);
    assert_true(within >= 0.999 * n);
    assert_true(covered >= 0.999 * n);
    /* Before a camera is bound (or with no footprint) every octave is whole:
     * the density of lod=point. */
    ef_fog_component p0, q0;
    parse("noise:density=0.2:scale=5:octaves=5:lod=pixel", &p0);
    parse("noise:density=0.2:scale=5:octaves=5", &q0);
    const long double v[4] = { 300, 2, -250, 2 };
    long double a[3], b[3];
    p0.model->density(&p0, v, a);
    q0.model->density(&q0, v, b);
    assert_true(a[0] == b[0]);
    ef_fog_free(&p0);
    ef_fog_free(&q0);
    ef_fog_free(&c);
    expect_usage("noise-separable:density=1:scale=1:lod=pixel", "lod=pixel");
    expect_usage("noise:density=1:scale=1:method=exact:lod=pixel", "lod=pixel");
    expect_usage("noise:density=1:scale=1:contrast=2:lod=pixel", "lod=pixel");
    expect_usage("noise:density=1:scale=1:lod=box", "lod='box'");
}

/* tau moves smoothly with the camera: no stepping beyond the tolerance. */
static void test_continuity(void **state)
{
    (void) state;
    ef_fog_component ex, ad;
    parse("noise:density=0.05:scale=4:method=exact", &ex);
    parse("noise:density=0.05:scale=4:tol=1e-3", &ad);
    const double d[3] = { 0.48, 0.6, 0.64 };
    double prev_e = 0, prev_a = 0, max_de = 0, max_da = 0;
    for (int k = 0; k <= 2000; ++k) {
        const double o[3] = { 1e-4 * k, 0.3, -0.7 };
        const ef_ray r = ray(o, d, 40);
        double te[3], ta[3];
        ef_fog_tau(&ex, &r, te, NULL);
        ef_fog_tau(&ad, &r, ta, NULL);
        if (k) {
            max_de = fmax(max_de, fabs(te[0] - prev_e));
            max_da = fmax(max_da, fabs(ta[0] - prev_a));
        }
        prev_e = te[0];
        prev_a = ta[0];
    }
    /* 1e-4 steps: the density (<= 0.1) changes tau by at most ~2e-5 a step. */
    printf("  largest change per 1e-4 camera step: exact %.2g, adaptive %.2g\n", max_de, max_da);
    assert_true(max_de < 2e-5);
    assert_true(max_da < 2e-5 + 2e-3);
    ef_fog_free(&ex);
    ef_fog_free(&ad);
}

static void expect_usage(const char *spec, const char *needle)
{
    ef_fog_component c;
    ef_err err = { 0 };
    if (ef_fog_parse(spec, NULL, &c, &err) == 0) {
        print_error("'%s' was accepted\n", spec);
        fail();
    }
    if (!strstr(err.msg, needle)) {
        print_error("'%s': message '%s' lacks '%s'\n", spec, err.msg, needle);
        fail();
    }
    if (!strstr(err.msg, spec)) {
        print_error("'%s': message '%s' does not quote the spec\n", spec, err.msg);
        fail();
    }
}

static void test_bad_values(void **state)
{
    (void) state;
    expect_usage("noise:density=1:scale=1:octaves=0", "octaves");
    expect_usage("noise:density=1:scale=1:octaves=17", "octaves");
    expect_usage("noise:density=1:scale=0", "scale");
    expect_usage("noise:density=1:scale=-2", "scale");
    expect_usage("noise:density=1:scale=1:lacunarity=1", "lacunarity");
    expect_usage("noise:density=1:scale=1:gain=0", "gain");
    expect_usage("noise-separable:density=1:scale=1:axes=xw", "axes");
    expect_usage("noise-separable:density=1:scale=1:axes=xx", "axes");
    expect_usage("noise-separable:density=1:scale=1:method=preintegrated:pieces=0", "pieces");
    expect_usage("noise:density=1:scale=1:tol=0", "tol");
    expect_usage("noise:density=1:scale=1:tol=-1", "tol");
    expect_usage("noise:density=1:scale=1:min=0,0,0:max=1,-1,1", "min");
    expect_usage("noise:density=1:scale=1:min=0,0,0", "max");
    expect_usage("noise:density=1", "scale");
    expect_usage("noise:scale=1", "density");
    expect_usage("noise:density=1:scale=1:method=fast", "method");
    expect_usage("noise:density=1:scale=1:method=preintegrated", "method");
    expect_usage("noise:density=1:scale=1:axes=xz", "axes");
    expect_usage("noise:density=1:scale=1:steps=8", "steps");
    expect_usage("noise-separable:density=1:scale=1:contrast=2:method=preintegrated", "contrast");
    expect_usage("noise:density=1:scale=1:contrast=100.5", "from -100 to 100");
    expect_usage("noise:density=1:scale=1e-400", "out of range");
    expect_usage("noise:density=5e-324:scale=1", "out of range");
    expect_usage("noise:density=1:scale=1:offset=1e999,0,0", "out of range");
    ef_fog_component c;
    ef_err err;
    assert_int_equal(ef_fog_parse("noise-separable:visibility=200:scale=10:axes=xyz:pieces=4:"
                                  "method=preintegrated:color=0.5,0.6,0.7:up=z", NULL, &c, &err), 0);
    ef_fog_free(&c);
}

/* Hostile scales and envelopes (issue 8): the work per ray is bounded
 * and tau stays defined. A scale far below the ray's length leaves every
 * octave past CELL_BUDGET cells unwalked, so tau is its mean part, rho L
 * (the noise averages to 0), with a positive error estimate; an envelope
 * that overflows makes the fog opaque. */
static void test_hostile_scales(void **state)
{
    (void) state;
    static const char *const specs[] = {
        "noise:density=0.02:scale=1e-9:method=exact",
        "noise:density=0.02:scale=1e-300",
        "noise:density=0.02:scale=1e-300:contrast=2",
        "noise-separable:density=0.02:scale=1e-300:method=exact",
    };
    const double o[3] = { 0.3, 1.7, -0.2 }, d[3] = { 0.6, 0, -0.8 };
    for (size_t k = 0; k < sizeof specs / sizeof specs[0]; ++k) {
        ef_fog_component c;
        parse(specs[k], &c);
        const ef_ray r = ray(o, d, 100);
        double tau[3];
        ef_tau_info info;
        ef_fog_tau(&c, &r, tau, &info);
        if (!isfinite(tau[0]) || !(tau[0] >= 0) || !(info.err[0] > 0)) {
            print_error("%s: tau %g, error estimate %g\n", specs[k], tau[0], info.err[0]);
            fail();
        }
        if (k < 2) {
            /* linear: the mean part exactly (no falloff: rho L) */
            assert_true(fabs(tau[0] - 0.02 * 100) <= 1e-12 * 2);
            assert_true(info.dropped == 4);
            assert_true(info.evals == 0);
        } else {
            /* clamped or separable: the density lies in [0, rho B] */
            assert_true(tau[0] <= 0.02 * 100 * 4.3);
        }
        ef_fog_free(&c);
    }
    ef_fog_component c;
    parse("noise:density=0.02:scale=10:falloff=0.1:base=1e15", &c);
    const ef_ray r = ray(o, d, 100);
    double tau[3];
    ef_fog_tau(&c, &r, tau, NULL);
    assert_true(isinf(tau[0]) && tau[0] > 0);
    ef_fog_free(&c);
    parse("noise-separable:density=0.02:scale=10:falloff=0.1:base=1e15:method=preintegrated", &c);
    ef_fog_tau(&c, &r, tau, NULL);
    assert_true(isinf(tau[0]) && tau[0] > 0);
    ef_fog_free(&c);
}

/* Copies own their data; results are identical. */
static void test_copy(void **state)
{
    (void) state;
    ef_fog_component a, b;
    parse("noise-separable:density=0.05:scale=4:axes=xyz:method=preintegrated:pieces=3", &a);
    assert_int_equal(ef_fog_copy(&b, &a), 0);
    const double o[3] = { 1, 2, 3 }, d[3] = { 0.6, 0, 0.8 };
    const ef_ray r = ray(o, d, 25);
    double ta[3], tb[3];
    ef_fog_tau(&a, &r, ta, NULL);
    ef_fog_free(&a);
    ef_fog_tau(&b, &r, tb, NULL);
    assert_true(ta[0] == tb[0]);
    ef_fog_free(&b);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bad_values),
        cmocka_unit_test(test_density_definition),
        cmocka_unit_test(test_lod_pixel),
        cmocka_unit_test(test_translations),
        cmocka_unit_test(test_copy),
        cmocka_unit_test(test_sky),
        cmocka_unit_test(test_exact_extremes),
        cmocka_unit_test(test_opaque),
        cmocka_unit_test(test_opaque_probe),
        cmocka_unit_test(test_adaptive_ttol),
        cmocka_unit_test(test_clamp_tables),
        cmocka_unit_test(test_reference_kinks),
        cmocka_unit_test(test_clamp_fast_path),
        cmocka_unit_test(test_clamp_opaque_pilot),
        cmocka_unit_test(test_separable_stop),
        cmocka_unit_test(test_steps),
        cmocka_unit_test(test_continuity),
        cmocka_unit_test(test_adaptive_cost_falls_with_tol),
        cmocka_unit_test(test_preintegrated),
        cmocka_unit_test(test_preintegrated_span),
        cmocka_unit_test(test_span_same_bits),
        cmocka_unit_test(test_adaptive),
        cmocka_unit_test(test_hostile_scales),
        cmocka_unit_test(test_exact_against_reference),
    };
    if (getenv("EXRFOG_TEST_FILTER"))
        cmocka_set_test_filter(getenv("EXRFOG_TEST_FILTER"));
    if (getenv("EXRFOG_TEST_SKIP"))
        cmocka_set_skip_filter(getenv("EXRFOG_TEST_SKIP"));
    return cmocka_run_group_tests(tests, NULL, NULL);
}
