/* Every closed form against the reference integrator (src/core/ref.c),
 * which knows nothing of them but each model's density:
 *   - a seeded random grid of 100,000+ segments per model;
 *   - the explicit extreme set of issue 3 (on the plane, parallel, inside
 *     and outside volumes, sky in every direction, 1e6/1e7 offsets,
 *     densities 1e-9..1e6, Walker sharpness to 0 and infinity, height
 *     falloff 0/1e-12/1e3, zero-length segments);
 * with |dT| <= 1e-10 everywhere and a relative tau error <= 1e-9 wherever
 * tau >= 1e-12. Then the properties: additivity, symmetry, monotonicity
 * and the reductions to exp fog. EXRFOG_COMPARE_SEGMENTS overrides the
 * grid size (for quick local runs). */
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cmocka.h>

#include "ref.h"
#include "scene.h"

#define TOL_T 1e-10
#define TOL_REL 1e-9
#define TAU_FLOOR 1e-12

/* ---- a small seeded generator (splitmix64) ---- */
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

static double loguni(rng *g, double a, double b)
{
    return exp(uni(g, log(a), log(b)));
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
    do {
        for (int i = 0; i < 3; ++i)
            v[i] = uni(g, -1, 1);
    } while (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > 1 || v[0] * v[0] + v[1] * v[1] + v[2] * v[2] < 1e-6);
    unit(v);
}

/* ---- the comparison ---- */
typedef struct tally {
    long segments, checked_rel, failures, unconverged;
    double max_dT, max_rel;
} tally;

static void report(const char *what, const tally *t)
{
    printf("  %-18s %8ld segments, %8ld relative checks, max |dT| %.3g, max rel tau err %.3g%s\n",
           what, t->segments, t->checked_rel, t->max_dT, t->max_rel,
           t->unconverged ? " (reference unconverged on some)" : "");
}

/* A sky ray exactly level in a height fog whose density there underflows. */
static int underflowed(const ef_fog_component *c, const double dir[3], double len)
{
    ef_fog_functional f;
    if (c->model != &ef_fog_height || !isinf(len) || c->model->functionals(c, &f, 1) != 1)
        return 0;
    return f.n[0] * dir[0] + f.n[1] * dir[1] + f.n[2] * dir[2] == 0;
}

/* Compares one segment; prints the first few failures in full. */
static void compare(const ef_fog_component *c, const double org[3], const double dir[3],
                    double len, tally *t)
{
    ef_ray r = { { dir[0], dir[1], dir[2] }, len, len, { org[0], org[1], org[2] } };
    double tc[3];
    long double tr[3];
    ef_ref_stats st;
    c->model->tau(c, &r, tc);
    assert_int_equal(ef_ref_tau(c, &r, tr, &st), 0);
    t->segments++;
    t->unconverged += st.unconverged != 0;
    if (st.unconverged && getenv("EXRFOG_COMPARE_DEBUG"))
        printf("UNCONVERGED %s: org %.17g,%.17g,%.17g dir %.17g,%.17g,%.17g len %.17g: %ld intervals\n",
               c->spec, org[0], org[1], org[2], dir[0], dir[1], dir[2], len, st.intervals);
    for (int k = 0; k < 3; ++k) {
        const double Tc = exp(-tc[k]);
        const long double Tr = expl(-tr[k]);
        double dT = fabs((double) (Tc - Tr));
        int bad = isnan(tc[k]) || tc[k] < 0 || !(dT <= TOL_T);
        double rel = 0;
        if (isinf(tr[k])) {
            bad |= !isinf(tc[k]);
        } else if (isinf(tc[k]) && tr[k] == 0 && underflowed(c, dir, len)) {
            /* Exactly along a height fog's level, forever: the density is
             * positive (an exponential never reaches 0) but below long
             * double's range, so the reference sees 0; the exact tau is
             * infinite. */
            bad = 0;
            dT = 0;
        } else if (tr[k] > (long double) DBL_MAX) {
            bad |= !(tc[k] > 1e300);
        } else if (tr[k] >= TAU_FLOOR) {
            rel = fabs((double) ((tc[k] - tr[k]) / tr[k]));
            bad |= !(rel <= TOL_REL);
            t->checked_rel++;
        }
        if (dT > t->max_dT)
            t->max_dT = dT;
        if (rel > t->max_rel)
            t->max_rel = rel;
        if (bad && t->failures++ < 8)
            printf("FAIL %s ch%d: org %.17g,%.17g,%.17g dir %.17g,%.17g,%.17g len %.17g: "
                   "closed %.17g ref %.20Lg (rel %.3g, dT %.3g, unconverged %d)\n",
                   c->spec, k, org[0], org[1], org[2], dir[0], dir[1], dir[2], len, tc[k], tr[k],
                   rel, dT, st.unconverged);
    }
}

static void parse(const char *spec, ef_fog_component *c)
{
    ef_err err;
    if (ef_fog_parse(spec, NULL, c, &err))
        fail_msg("spec '%s' refused: %s", spec, err.msg);
}

/* ---- random specs, each built around a centre P (the origin or far away) ---- */
static void fmt_density(rng *g, char *buf, size_t n, const char *key, double lo, double hi)
{
    if (chance(g, 0.3))
        snprintf(buf, n, "%s=%.17g,%.17g,%.17g", key, loguni(g, lo, hi), loguni(g, lo, hi),
                 chance(g, 0.2) ? 0.0 : loguni(g, lo, hi));
    else
        snprintf(buf, n, "%s=%.17g", key, loguni(g, lo, hi));
}

/* A plane through a point near P with a random, not necessarily unit, normal. */
static void fmt_plane(rng *g, const double P[3], char *buf, size_t n, double nrm[6])
{
    double q[3];
    sphere(g, nrm);
    if (chance(g, 0.3)) {  /* axis-aligned planes make exact on-plane cases common */
        const int a = (int) (next(g) % 3);
        nrm[0] = nrm[1] = nrm[2] = 0;
        nrm[a] = chance(g, 0.5) ? 1 : -1;
    }
    const double scale = loguni(g, 0.1, 10);
    for (int i = 0; i < 3; ++i)
        q[i] = P[i] + uni(g, -10, 10);
    const double D = -(nrm[0] * q[0] + nrm[1] * q[1] + nrm[2] * q[2]) * scale;
    snprintf(buf, n, "%.17g,%.17g,%.17g,%.17g", nrm[0] * scale, nrm[1] * scale, nrm[2] * scale, D);
}

typedef struct spec_gen {
    const char *model;
    /* Writes a random spec around P, and the direction that segments should
     * sometimes run parallel to (a plane normal or the up axis). */
    void (*gen)(rng *g, const double P[3], char *spec, size_t n, double normal[6]);
    int volume;  /* aim segments at the volume's centre (gen leaves it in normal[3..5]) */
} spec_gen;

static void gen_halfspace(rng *g, const double P[3], char *s, size_t n, double nrm[6])
{
    char pl[160], d[128];
    fmt_plane(g, P, pl, sizeof pl, nrm);
    fmt_density(g, d, sizeof d, "density", 1e-4, 10);
    snprintf(s, n, "halfspace:plane=%s:%s", pl, d);
}

static void gen_halfspace_linear(rng *g, const double P[3], char *s, size_t n, double nrm[6])
{
    char pl[160], d[128];
    fmt_plane(g, P, pl, sizeof pl, nrm);
    fmt_density(g, d, sizeof d, "slope", 1e-4, 10);
    snprintf(s, n, "halfspace-linear:plane=%s:%s", pl, d);
}

static void gen_halfspace_smooth(rng *g, const double P[3], char *s, size_t n, double nrm[6])
{
    char pl[160], d[128], sh[128];
    fmt_plane(g, P, pl, sizeof pl, nrm);
    fmt_density(g, d, sizeof d, "density", 1e-3, 10);
    fmt_density(g, sh, sizeof sh, "sharpness", 1e-6, 1e6);
    snprintf(s, n, "halfspace-smooth:plane=%s:%s:%s", pl, d, sh);
}

static void random_up(rng *g, double up[3], char *buf, size_t n)
{
    if (chance(g, 0.5)) {
        const int a = (int) (next(g) % 3);
        up[0] = up[1] = up[2] = 0;
        up[a] = chance(g, 0.8) ? 1 : -1;
    } else {
        sphere(g, up);
    }
    snprintf(buf, n, "%.17g,%.17g,%.17g", up[0], up[1], up[2]);
}

static void gen_height(rng *g, const double P[3], char *s, size_t n, double up[6])
{
    char u[128], d[128];
    random_up(g, up, u, sizeof u);
    unit(up);
    fmt_density(g, d, sizeof d, "density", 1e-4, 1);
    const double k = chance(g, 0.1) ? 0.0 : loguni(g, 1e-4, 10);
    const double base = up[0] * P[0] + up[1] * P[1] + up[2] * P[2] + uni(g, -10, 10);
    snprintf(s, n, "height:%s:falloff=%.17g:base=%.17g:up=%s", d, k, base, u);
}

static void gen_layered(rng *g, const double P[3], char *s, size_t n, double up[6])
{
    char u[128], hs[512] = "", ds[512] = "";
    random_up(g, up, u, sizeof u);
    unit(up);
    const int m = 1 + (int) (next(g) % 6);
    double h = up[0] * P[0] + up[1] * P[1] + up[2] * P[2] - 10;
    for (int i = 0; i < m; ++i) {
        h += loguni(g, 0.01, 8);
        char e[96];
        snprintf(e, sizeof e, "%s%.17g", i ? "," : "", h);
        strncat(hs, e, sizeof hs - strlen(hs) - 1);
        if (chance(g, 0.2))
            snprintf(e, sizeof e, "%s%.17g/%.17g/%.17g", i ? "," : "", uni(g, 0, 1), uni(g, 0, 1),
                     uni(g, 0, 1));
        else
            snprintf(e, sizeof e, "%s%.17g", i ? "," : "", chance(g, 0.2) ? 0.0 : uni(g, 0, 1));
        strncat(ds, e, sizeof ds - strlen(ds) - 1);
    }
    snprintf(s, n, "layered:heights=%s:densities=%s:up=%s", hs, ds, u);
}

static void gen_box(rng *g, const double P[3], char *s, size_t n, double nrm[6])
{
    double lo[3], hi[3];
    char d[128];
    for (int i = 0; i < 3; ++i) {
        lo[i] = P[i] + uni(g, -6, 4);
        hi[i] = lo[i] + loguni(g, 1e-3, 20);
    }
    nrm[0] = nrm[1] = nrm[2] = 0;
    nrm[next(g) % 3] = 1;
    for (int i = 0; i < 3; ++i)
        nrm[3 + i] = (lo[i] + hi[i]) / 2;
    fmt_density(g, d, sizeof d, "density", 1e-4, 10);
    snprintf(s, n, "box:min=%.17g,%.17g,%.17g:max=%.17g,%.17g,%.17g:%s", lo[0], lo[1], lo[2], hi[0],
             hi[1], hi[2], d);
}

static void gen_convex(rng *g, const double P[3], char *s, size_t n, double nrm[6])
{
    double C[3];
    char planes[2048] = "", d[128];
    for (int i = 0; i < 3; ++i)
        C[i] = P[i] + uni(g, -5, 5);
    const int m = chance(g, 0.2) ? 1 + (int) (next(g) % 3) : 4 + (int) (next(g) % 8);
    for (int j = 0; j < m; ++j) {
        double v[3];
        sphere(g, v);
        const double r = loguni(g, 0.01, 10), scale = loguni(g, 0.5, 2);
        const double D = -(v[0] * C[0] + v[1] * C[1] + v[2] * C[2] + r);
        char e[160];
        snprintf(e, sizeof e, "%s%.17g,%.17g,%.17g,%.17g", j ? "," : "", v[0] * scale, v[1] * scale,
                 v[2] * scale, D * scale);
        strncat(planes, e, sizeof planes - strlen(planes) - 1);
        if (j == 0)
            memcpy(nrm, v, sizeof v);
    }
    memcpy(nrm + 3, C, sizeof C);
    fmt_density(g, d, sizeof d, "density", 1e-4, 10);
    snprintf(s, n, "convex:planes=%s:%s", planes, d);
}

static const spec_gen gens[] = {
    { "halfspace", gen_halfspace, 0 },
    { "halfspace-linear", gen_halfspace_linear, 0 },
    { "halfspace-smooth", gen_halfspace_smooth, 0 },
    { "height", gen_height, 0 },
    { "layered", gen_layered, 0 },
    { "box", gen_box, 1 },
    { "convex", gen_convex, 1 },
};

/* The models compared elsewhere, with where: exp against the others'
 * reductions to it (test_reductions_to_exp); linear and exp2 have no
 * density in space for the reference (test_fog's closed forms by hand);
 * the noise models' tau is not a closed form (test_fog_noise, against the
 * same reference). */
static const char *const compared_elsewhere[] = { "exp", "linear", "exp2", "noise",
                                                  "noise-separable" };

/* Every registered model is in gens or named above (issue 43): a new model
 * cannot be left out of the comparison unnoticed. */
static void test_every_model_compared(void **state)
{
    (void) state;
    for (int m = 0; m < ef_fog_model_count(); ++m) {
        const char *name = ef_fog_model_at(m)->name;
        int found = 0;
        for (size_t i = 0; i < sizeof gens / sizeof gens[0]; ++i)
            found |= !strcmp(gens[i].model, name);
        for (size_t i = 0; i < sizeof compared_elsewhere / sizeof compared_elsewhere[0]; ++i)
            found |= !strcmp(compared_elsewhere[i], name);
        if (!found)
            fail_msg("model %s is not compared with the reference (add a generator to gens, or "
                     "say where it is compared)", name);
    }
}

/* A random segment from near P: any direction, or nearly parallel to the
 * model's plane; lengths from 1e-4 to 1e4, zero, or infinite. */
static void random_segment(rng *g, const double P[3], const double nrm[3], const double *target,
                           double org[3], double dir[3], double *len)
{
    for (int i = 0; i < 3; ++i)
        org[i] = P[i] + uni(g, -20, 20);
    sphere(g, dir);
    if (chance(g, 0.5)) {
        /* Aimed at the model's neighbourhood, or a volume's centre. */
        for (int i = 0; i < 3; ++i)
            dir[i] = (target ? target[i] : P[i] + uni(g, -6, 6)) - org[i];
        unit(dir);
    }
    if (chance(g, 0.15)) {
        /* Parallel or grazing: remove the normal part, add back eps of it. */
        const double d = dir[0] * nrm[0] + dir[1] * nrm[1] + dir[2] * nrm[2];
        const double eps = chance(g, 0.2) ? 0.0 : (chance(g, 0.5) ? 1 : -1) * loguni(g, 1e-15, 1e-2);
        for (int i = 0; i < 3; ++i)
            dir[i] += (eps - d) * nrm[i];
        unit(dir);
    }
    const double u = uni(g, 0, 1);
    *len = u < 0.03 ? 0.0 : u < 0.13 ? INFINITY : loguni(g, 1e-4, 1e4);
}

static long grid_size(void)
{
    const char *e = getenv("EXRFOG_COMPARE_SEGMENTS");
    return e ? atol(e) : 100000;
}

static void test_random_grid(void **state)
{
    (void) state;
    const long want = grid_size();
    long total_fail = 0;
    for (size_t m = 0; m < sizeof gens / sizeof gens[0]; ++m) {
        rng g = { 0x5eed0000ull + m };
        tally t = { 0 };
        const clock_t t0 = clock();
        while (t.segments < want) {
            double P[3] = { 0, 0, 0 }, nrm[6];
            const double u = uni(&g, 0, 1);
            if (u < 0.1) {  /* far from the origin */
                const double off = chance(&g, 0.5) ? 1e6 : 1e7;
                for (int i = 0; i < 3; ++i)
                    P[i] = chance(&g, 0.5) ? off : -off;
            }
            char spec[4096];
            gens[m].gen(&g, P, spec, sizeof spec, nrm);
            ef_fog_component c;
            parse(spec, &c);
            for (int j = 0; j < 100 && t.segments < want; ++j) {
                double org[3], dir[3], len;
                random_segment(&g, P, nrm, gens[m].volume ? nrm + 3 : NULL, org, dir, &len);
                compare(&c, org, dir, len, &t);
            }
            ef_fog_free(&c);
        }
        report(gens[m].model, &t);
        printf("    (%.1f s)\n", (double) (clock() - t0) / CLOCKS_PER_SEC);
        total_fail += t.failures;
    }
    assert_int_equal(total_fail, 0);
}

/* ---- the explicit extreme set ---- */

/* The 26 unit directions to the faces, edges and corners of a cube. */
static int cube_dirs(double out[26][3])
{
    int n = 0;
    for (int x = -1; x <= 1; ++x)
        for (int y = -1; y <= 1; ++y)
            for (int z = -1; z <= 1; ++z)
                if (x || y || z) {
                    double *d = out[n++];
                    d[0] = x;
                    d[1] = y;
                    d[2] = z;
                    unit(d);
                }
    return n;
}

/* Segments around the plane y = c (normal +y) at offset P: camera on it,
 * pixel on it, both, parallel (s = 0, +-1e-12), grazing, zero length, and
 * the sky in 26 directions plus exactly horizontal ones. */
static void plane_cases(const ef_fog_component *c, const double P[3], double cy, tally *t)
{
    static const double dirs[][3] = {
        { 0, -1, 0 }, { 0, 1, 0 }, { 0.6, -0.8, 0 }, { 0.6, 0.8, 0 }, { 0, -0.6, 0.8 },
        { 1, 0, 0 }, { 0, 0, 1 }, { -0.8, 0, 0.6 },                 /* exactly horizontal */
        { 1, 1e-12, 0 }, { 1, -1e-12, 0 }, { 0, 1e-12, -1 },         /* |s| = 1e-12 */
        { 1, 1e-6, 0 }, { 1, -1e-6, 0 }, { 1, -1e-3, 1 },            /* grazing */
    };
    const double heights[] = { 0, 1, -1, 1e-9, -1e-9, 10, -10, 1000 };
    const double lens[] = { 0, 1e-9, 1e-3, 1, 2.5, 10, 1e3, 1e6, INFINITY };
    for (size_t d = 0; d < sizeof dirs / sizeof dirs[0]; ++d) {
        double dir[3] = { dirs[d][0], dirs[d][1], dirs[d][2] };
        unit(dir);
        for (size_t h = 0; h < sizeof heights / sizeof heights[0]; ++h) {
            const double org[3] = { P[0] + 0.25, cy + heights[h], P[2] - 0.5 };
            for (size_t l = 0; l < sizeof lens / sizeof lens[0]; ++l)
                compare(c, org, dir, lens[l], t);
            /* The pixel exactly on the plane (to the rounding of len). */
            if (dir[1] != 0 && heights[h] != 0) {
                const double len = -heights[h] / dir[1];
                if (len > 0)
                    compare(c, org, dir, len, t);
            }
        }
    }
    /* Sky in the 26 directions of a cube, from above, on and below the plane. */
    double cube[26][3];
    for (int d = cube_dirs(cube); d-- > 0;)
        for (size_t h = 0; h < sizeof heights / sizeof heights[0]; ++h) {
            const double org[3] = { P[0], cy + heights[h], P[2] };
            compare(c, org, cube[d], INFINITY, t);
        }
}

static void test_extremes_planes(void **state)
{
    (void) state;
    const double offsets[] = { 0, 1e6, 1e7, -1e7 };
    const double dens[] = { 1e-9, 1e-3, 1, 1e3, 1e6 };
    const double sharp[] = { 1e-12, 1e-6, 1, 1e6, 1e12 };
    tally t[3] = { { 0 } };
    for (size_t o = 0; o < sizeof offsets / sizeof offsets[0]; ++o) {
        const double P[3] = { offsets[o], offsets[o], offsets[o] };
        const double cy = offsets[o] + 2;
        for (size_t d = 0; d < sizeof dens / sizeof dens[0]; ++d) {
            char spec[512];
            ef_fog_component c;
            /* Tilted normal scalings too: the plane y = cy written as 0,3,0,-3cy. */
            snprintf(spec, sizeof spec, "halfspace:plane=0,3,0,%.17g:density=%.17g", -3 * cy, dens[d]);
            parse(spec, &c);
            plane_cases(&c, P, cy, &t[0]);
            ef_fog_free(&c);
            snprintf(spec, sizeof spec, "halfspace-linear:plane=0,1,0,%.17g:slope=%.17g", -cy, dens[d]);
            parse(spec, &c);
            plane_cases(&c, P, cy, &t[1]);
            ef_fog_free(&c);
            for (size_t s = 0; s < sizeof sharp / sizeof sharp[0]; ++s) {
                snprintf(spec, sizeof spec,
                         "halfspace-smooth:plane=0,1,0,%.17g:density=%.17g:sharpness=%.17g", -cy,
                         dens[d], sharp[s]);
                parse(spec, &c);
                plane_cases(&c, P, cy, &t[2]);
                ef_fog_free(&c);
            }
        }
    }
    report("halfspace", &t[0]);
    report("halfspace-linear", &t[1]);
    report("halfspace-smooth", &t[2]);
    assert_int_equal(t[0].failures + t[1].failures + t[2].failures, 0);
}

static void test_extremes_height(void **state)
{
    (void) state;
    const double offsets[] = { 0, 1e6, 1e7, -1e7 };
    const double dens[] = { 1e-9, 1e-3, 1, 1e6 };
    const double falloff[] = { 0, 1e-12, 1e-3, 1, 1e3 };
    tally th = { 0 }, tl = { 0 };
    for (size_t o = 0; o < sizeof offsets / sizeof offsets[0]; ++o) {
        const double P[3] = { offsets[o], offsets[o], offsets[o] };
        const double cy = offsets[o] + 2;
        for (size_t d = 0; d < sizeof dens / sizeof dens[0]; ++d) {
            char spec[512];
            ef_fog_component c;
            for (size_t k = 0; k < sizeof falloff / sizeof falloff[0]; ++k) {
                snprintf(spec, sizeof spec, "height:density=%.17g:falloff=%.17g:base=%.17g",
                         dens[d], falloff[k], cy);
                parse(spec, &c);
                plane_cases(&c, P, cy, &th);
                ef_fog_free(&c);
            }
            snprintf(spec, sizeof spec, "layered:heights=%.17g,%.17g,%.17g:densities=%.17g,%.17g,0",
                     cy - 5, cy, cy + 1e-3, dens[d], dens[d] / 2);
            parse(spec, &c);
            plane_cases(&c, P, cy, &tl);
            ef_fog_free(&c);
        }
    }
    report("height", &th);
    report("layered", &tl);
    assert_int_equal(th.failures + tl.failures, 0);
}

static void test_extremes_volumes(void **state)
{
    (void) state;
    const double offsets[] = { 0, 1e6, 1e7 };
    const double dens[] = { 1e-9, 1, 1e6 };
    const double sizes[] = { 1e-3, 1, 100 };
    tally tb = { 0 }, tc = { 0 };
    for (size_t o = 0; o < sizeof offsets / sizeof offsets[0]; ++o)
        for (size_t d = 0; d < sizeof dens / sizeof dens[0]; ++d)
            for (size_t z = 0; z < sizeof sizes / sizeof sizes[0]; ++z) {
                const double B = offsets[o], S = sizes[z];
                char spec[2048];
                ef_fog_component box, cvx;
                snprintf(spec, sizeof spec,
                         "box:min=%.17g,%.17g,%.17g:max=%.17g,%.17g,%.17g:density=%.17g", B, B, B,
                         B + S, B + 2 * S, B + S, dens[d]);
                parse(spec, &box);
                /* An octahedron |x-cx|+|y-cy|+|z-cz| < S around the same centre. */
                const double cx = B + S / 2, cyy = B + S, cz = B + S / 2;
                char planes[1024] = "";
                for (int k = 0; k < 8; ++k) {
                    const double a = k & 1 ? -1 : 1, b = k & 2 ? -1 : 1, cc = k & 4 ? -1 : 1;
                    char e[200];
                    snprintf(e, sizeof e, "%s%g,%g,%g,%.17g", k ? "," : "", a, b, cc,
                             -(a * cx + b * cyy + cc * cz + S));
                    strncat(planes, e, sizeof planes - strlen(planes) - 1);
                }
                snprintf(spec, sizeof spec, "convex:planes=%s:density=%.17g", planes, dens[d]);
                parse(spec, &cvx);
                /* Cameras inside (centre, near a face, on a face, on an edge) and
                 * outside (beside, far), looking in 26 directions, finite and sky. */
                const double cams[][3] = {
                    { cx, cyy, cz }, { B + 1e-9 * S, cyy, cz }, { B, cyy, cz }, { B, B, cz },
                    { B - S, cyy, cz }, { B + 5 * S, B + 5 * S, B - 3 * S }, { cx, B + 2 * S, cz },
                };
                const double lens[] = { 0, S / 3, S, 3 * S, 1e4 * S, INFINITY };
                double cube[26][3];
                const int nd = cube_dirs(cube);
                for (size_t k = 0; k < sizeof cams / sizeof cams[0]; ++k)
                    for (int d = 0; d < nd; ++d)
                        for (size_t l = 0; l < sizeof lens / sizeof lens[0]; ++l) {
                            compare(&box, cams[k], cube[d], lens[l], &tb);
                            compare(&cvx, cams[k], cube[d], lens[l], &tc);
                        }
                ef_fog_free(&box);
                ef_fog_free(&cvx);
            }
    report("box", &tb);
    report("convex", &tc);
    assert_int_equal(tb.failures + tc.failures, 0);
}

/* ---- properties ---- */

static double tau0(const ef_fog_component *c, const double org[3], const double dir[3], double len)
{
    ef_ray r = { { dir[0], dir[1], dir[2] }, len, len, { org[0], org[1], org[2] } };
    double t[3];
    c->model->tau(c, &r, t);
    return t[0];
}

static int near_rel(double a, double b, double rel, double abs_)
{
    if (isinf(a) || isinf(b))
        return a == b;
    return fabs(a - b) <= rel * fmax(fabs(a), fabs(b)) + abs_;
}

static void test_properties(void **state)
{
    (void) state;
    long bad = 0, n = 0;
    for (size_t m = 0; m < sizeof gens / sizeof gens[0]; ++m) {
        rng g = { 0xabcd00ull + m };
        for (int i = 0; i < 400; ++i) {
            double P[3] = { 0, 0, 0 }, nrm[6];
            char spec[4096];
            gens[m].gen(&g, P, spec, sizeof spec, nrm);
            ef_fog_component c;
            parse(spec, &c);
            for (int j = 0; j < 25; ++j) {
                double org[3], dir[3], len;
                random_segment(&g, P, nrm, gens[m].volume ? nrm + 3 : NULL, org, dir, &len);
                if (!(len > 0) || isinf(len))
                    len = loguni(&g, 1e-2, 1e3);
                const double full = tau0(&c, org, dir, len);
                /* Additivity at M = org + tm dir: the split point is rounded to a
                 * double, so allow what moving an endpoint by an ulp can do. */
                const double tm = uni(&g, 0, len);
                double M[3], back[3], P2[3];
                for (int k = 0; k < 3; ++k)
                    M[k] = org[k] + tm * dir[k];
                const double a = tau0(&c, org, dir, tm), b = tau0(&c, M, dir, len - tm);
                /* Symmetry: from the far end back to the camera. */
                for (int k = 0; k < 3; ++k) {
                    P2[k] = org[k] + len * dir[k];
                    back[k] = -dir[k];
                }
                const double rev = tau0(&c, P2, back, len);
                /* Monotonicity along the ray, up to infinity. */
                const double more = tau0(&c, org, dir, len * 1.5), inf = tau0(&c, org, dir, INFINITY);
                const double slack = 1e-9 * (fabs(full) + 1e-12) + 1e-13 * (1 + len);
                n++;
                if (!near_rel(a + b, full, 1e-9, slack) || !near_rel(rev, full, 1e-9, slack) ||
                    !(more >= full * (1 - 1e-15)) || !(inf >= more * (1 - 1e-15))) {
                    if (bad++ < 8)
                        printf("PROPERTY %s: len %.17g split %.17g+%.17g=%.17g vs %.17g, reverse "
                               "%.17g, 1.5x %.17g, inf %.17g\n",
                               spec, len, a, b, a + b, full, rev, more, inf);
                }
            }
            ef_fog_free(&c);
        }
    }
    printf("  properties: %ld segments checked\n", n);
    assert_int_equal(bad, 0);
}

static void test_reductions_to_exp(void **state)
{
    (void) state;
    rng g = { 42 };
    ef_fog_component ex, hf, hs, ly, cv;
    parse("exp:density=0.037", &ex);
    parse("height:density=0.037:falloff=0:base=12", &hf);       /* falloff 0: uniform */
    parse("halfspace:plane=0.3,0.4,-1.2,-1e9:density=0.037", &hs);  /* plane far behind */
    parse("layered:heights=5:densities=0.037", &ly);            /* one constant layer */
    parse("convex:planes=0,-1,0,-1e9:density=0.037", &cv);      /* a half-space of one plane */
    for (int i = 0; i < 20000; ++i) {
        double org[3], dir[3];
        for (int k = 0; k < 3; ++k)
            org[k] = uni(&g, -100, 100);
        sphere(&g, dir);
        const double len = chance(&g, 0.1) ? INFINITY : loguni(&g, 1e-6, 1e5);
        const double want = tau0(&ex, org, dir, len);
        assert_true(near_rel(tau0(&hf, org, dir, len), want, 1e-15, 0));
        assert_true(near_rel(tau0(&hs, org, dir, isinf(len) ? 1e5 : len),
                             tau0(&ex, org, dir, isinf(len) ? 1e5 : len), 1e-15, 0));
        assert_true(near_rel(tau0(&ly, org, dir, len), want, 1e-15, 0));
        assert_true(near_rel(tau0(&cv, org, dir, isinf(len) ? 1e5 : len),
                             tau0(&ex, org, dir, isinf(len) ? 1e5 : len), 1e-15, 0));
    }
    ef_fog_free(&ex);
    ef_fog_free(&hf);
    ef_fog_free(&hs);
    ef_fog_free(&ly);
    ef_fog_free(&cv);
}

static void test_bound_camera(void **state)
{
    (void) state;
    /* Binding a component to the camera only moves a per-frame constant out
     * of the per-pixel path: rays from the camera give the same bits, and
     * rays from anywhere else are unaffected. */
    long n = 0;
    for (size_t m = 0; m < sizeof gens / sizeof gens[0]; ++m) {
        rng g = { 0xb1d00ull + m };
        for (int i = 0; i < 200; ++i) {
            double P[3] = { 0, 0, 0 }, nrm[6], cam[3];
            if (chance(&g, 0.3))
                P[0] = P[1] = P[2] = 1e7;
            char spec[4096];
            gens[m].gen(&g, P, spec, sizeof spec, nrm);
            ef_fog_component c, b;
            parse(spec, &c);
            assert_int_equal(ef_fog_copy(&b, &c), 0);
            for (int k = 0; k < 3; ++k)
                cam[k] = P[k] + uni(&g, -20, 20);
            ef_fog_bind(&b, cam);
            for (int j = 0; j < 50; ++j) {
                double org[3], dir[3], len, t1[3], t2[3];
                random_segment(&g, P, nrm, gens[m].volume ? nrm + 3 : NULL, org, dir, &len);
                if (j % 2)
                    memcpy(org, cam, sizeof org);
                ef_ray r = { { dir[0], dir[1], dir[2] }, len, len, { org[0], org[1], org[2] } };
                c.model->tau(&c, &r, t1);
                b.model->tau(&b, &r, t2);
                assert_memory_equal(t1, t2, sizeof t1);
                n++;
            }
            ef_fog_free(&c);
            ef_fog_free(&b);
        }
    }
    printf("  bound camera: %ld segments bit-identical\n", n);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_model_compared),
        cmocka_unit_test(test_reductions_to_exp),
        cmocka_unit_test(test_bound_camera),
        cmocka_unit_test(test_properties),
        cmocka_unit_test(test_extremes_planes),
        cmocka_unit_test(test_extremes_height),
        cmocka_unit_test(test_extremes_volumes),
        cmocka_unit_test(test_random_grid),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
