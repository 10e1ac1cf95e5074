/* Shadow maps for lit fog (issue 25, shafts) against geometry computed on
 * its own: occluders whose footprint falls on texel boundaries (plates
 * facing the light), where the map is exact, give lit intervals equal to
 * the analytic ones from slab tests in the light's camera space, and lit
 * light equal to the reference integrator's over those intervals; a
 * sphere, which no map holds exactly, converges to its analytic shadow
 * (a cylinder and the ball) as the map's resolution grows; the CLI reads
 * maps from files and refuses the wrong ones with a message. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "lit.h"
#include "mat4.h"
#include "ref.h"
#include "shadow.h"
#include "tassert.h"
#include "testutil.h"

#define PI 3.14159265358979323846
#define MAXI 64

/* ---- a light camera, built on its own ---- */

typedef struct lcam {
    double org[3], X[3], Y[3], Z[3];   /* position, unit axes (Z forward) */
    int ortho;
    double half;                        /* ortho: half width; perspective: tan(fov / 2) */
    int n;                              /* n x n texels */
} lcam;

static void unit(double v[3])
{
    const double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int a = 0; a < 3; ++a)
        v[a] /= n;
}

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* A camera at org looking along fwd. */
static lcam lcam_make(const double org[3], const double fwd[3], int ortho, double half, int n)
{
    lcam c;
    memcpy(c.org, org, sizeof c.org);
    memcpy(c.Z, fwd, sizeof c.Z);
    unit(c.Z);
    double up[3] = { 0, 0, 1 };
    if (fabs(c.Z[2]) > 0.9) {
        up[1] = 1;
        up[2] = 0;
    }
    /* X = up x Z, Y = Z x X */
    c.X[0] = up[1] * c.Z[2] - up[2] * c.Z[1];
    c.X[1] = up[2] * c.Z[0] - up[0] * c.Z[2];
    c.X[2] = up[0] * c.Z[1] - up[1] * c.Z[0];
    unit(c.X);
    c.Y[0] = c.Z[1] * c.X[2] - c.Z[2] * c.X[1];
    c.Y[1] = c.Z[2] * c.X[0] - c.Z[0] * c.X[2];
    c.Y[2] = c.Z[0] * c.X[1] - c.Z[1] * c.X[0];
    c.ortho = ortho;
    c.half = half;
    c.n = n;
    return c;
}

/* Camera-space coordinates of world x. */
static void to_cam(const lcam *c, const double x[3], double o[3])
{
    const double d[3] = { x[0] - c->org[0], x[1] - c->org[1], x[2] - c->org[2] };
    o[0] = dot3(d, c->X);
    o[1] = dot3(d, c->Y);
    o[2] = dot3(d, c->Z);
}

/* worldToCamera and worldToNDC (row vectors), as a renderer writes them. */
static void lcam_matrices(const lcam *c, ef_mat4 *w2c, ef_mat4 *w2ndc)
{
    ef_mat4 c2w = { { 0 } }, c2n = { { 0 } };
    for (int a = 0; a < 3; ++a) {
        c2w.m[0 + a] = c->X[a];
        c2w.m[4 + a] = c->Y[a];
        c2w.m[8 + a] = c->Z[a];
        c2w.m[12 + a] = c->org[a];
    }
    c2w.m[15] = 1;
    assert_int_equal(ef_mat4_invert(&c2w, w2c), 0);
    /* ndc x = 0.5 + X / (2 half [Z]), y = 0.5 - Y / (2 half [Z]) */
    const double k = 1 / (2 * c->half);
    c2n.m[0] = k;
    c2n.m[5] = -k;
    if (c->ortho) {
        c2n.m[12] = 0.5;
        c2n.m[13] = 0.5;
        c2n.m[10] = 1e-3;
        c2n.m[15] = 1;
    } else {
        c2n.m[8] = 0.5;
        c2n.m[9] = 0.5;
        c2n.m[10] = 1.001;
        c2n.m[14] = -0.1;
        c2n.m[11] = 1;
    }
    ef_mat4_mul(w2c, &c2n, w2ndc);
}

/* Where texel coordinate u (0..n) lies on the camera's image plane: ortho
 * X, perspective X / Z (y flipped). */
static double plane_of(const lcam *c, double u)
{
    return (2 * u / c->n - 1) * c->half;
}

static ef_shadow *lcam_build(const lcam *c, const float *depth, double bias, double slope,
                             int outside_lit)
{
    ef_shadow_src src;
    memset(&src, 0, sizeof src);
    src.path = "synthetic";
    src.width = src.height = c->n;
    src.disp[2] = src.disp[3] = c->n - 1;
    src.depth = depth;
    src.has_w2c = src.has_proj = 1;
    src.proj_name = "worldToNDC";
    lcam_matrices(c, &src.w2c, &src.proj);
    ef_err err;
    const ef_shadow_opts o = { bias, slope, outside_lit, 0, NULL };
    ef_shadow *m = ef_shadow_build(&src, &o, &err);
    if (!m)
        fail_msg("the map did not build: %s", err.msg);
    return m;
}

/* ---- plates: occluders facing the light, on texel boundaries ---- */

typedef struct plate {
    int i0, i1, j0, j1;   /* texels [i0, i1) x [j0, j1) */
    double depth;
} plate;

static float *plates_map(const lcam *c, const plate *p, int np)
{
    float *z = malloc((size_t) c->n * (size_t) c->n * sizeof *z);
    for (int i = 0; i < c->n * c->n; ++i)
        z[i] = INFINITY;
    for (int k = 0; k < np; ++k)
        for (int j = p[k].j0; j < p[k].j1; ++j)
            for (int i = p[k].i0; i < p[k].i1; ++i)
                if (p[k].depth < z[(size_t) j * (size_t) c->n + (size_t) i])
                    z[(size_t) j * (size_t) c->n + (size_t) i] = (float) p[k].depth;
    return z;
}

/* Narrows [lo, hi] to where c0 + t c1 >= 0 (the test's own slab step). */
static void slab(double c0, double c1, double *lo, double *hi)
{
    if (c1 == 0) {
        if (c0 < 0)
            *hi = -1;
        return;
    }
    const double r = -c0 / c1;
    if (c1 > 0)
        *lo = fmax(*lo, r);
    else
        *hi = fmin(*hi, r);
}

/* The lit intervals of [0, D]: the complement of the union of the ns
 * shadowed intervals sh (sorted here). Returns their count. */
static int complement(double (*sh)[2], int ns, double D, double (*iv)[2])
{
    for (int i = 1; i < ns; ++i)
        for (int j = i; j > 0 && sh[j][0] < sh[j - 1][0]; --j) {
            double t0 = sh[j][0], t1 = sh[j][1];
            sh[j][0] = sh[j - 1][0], sh[j][1] = sh[j - 1][1];
            sh[j - 1][0] = t0, sh[j - 1][1] = t1;
        }
    int n = 0;
    double t = 0;
    for (int i = 0; i < ns; ++i) {
        if (sh[i][0] > t)
            iv[n][0] = t, iv[n][1] = sh[i][0], ++n;
        t = fmax(t, sh[i][1]);
    }
    if (D > t)
        iv[n][0] = t, iv[n][1] = D, ++n;
    return n;
}

/* The lit intervals of [0, D] in a world of plates: a point is shadowed
 * when it lies behind a plate (depth beyond it) within its footprint,
 * found with slabs in camera space (perspective: X - u Z >= 0 for Z > 0).
 * Returns the count. */
static int plates_lit(const lcam *c, const plate *p, int np, double bias, const double org[3],
                      const double dir[3], double D, double (*iv)[2])
{
    double o[3], e[3], sh[MAXI][2];
    int ns = 0;
    to_cam(c, org, o);
    e[0] = dot3(dir, c->X);
    e[1] = dot3(dir, c->Y);
    e[2] = dot3(dir, c->Z);
    for (int k = 0; k < np; ++k) {
        double lo = 0, hi = D;
        const double x0 = plane_of(c, p[k].i0), x1 = plane_of(c, p[k].i1);
        const double y1 = -plane_of(c, p[k].j0), y0 = -plane_of(c, p[k].j1);
        const double w0 = c->ortho ? 1 : o[2], wu = c->ortho ? 0 : e[2];
        slab(o[0] - x0 * w0, e[0] - x0 * wu, &lo, &hi);
        slab(x1 * w0 - o[0], x1 * wu - e[0], &lo, &hi);
        slab(o[1] - y0 * w0, e[1] - y0 * wu, &lo, &hi);
        slab(y1 * w0 - o[1], y1 * wu - e[1], &lo, &hi);
        slab(o[2] - (p[k].depth + bias), e[2], &lo, &hi);   /* behind it */
        if (lo < hi)
            sh[ns][0] = lo, sh[ns][1] = hi, ++ns;
    }
    return complement(sh, ns, D, iv);
}

static uint32_t rng = 12345;

static double urand(double a, double b)
{
    return a + (b - a) * tu_rand01(&rng);
}

/* Random view rays near the plates: the lit intervals equal the analytic
 * ones (ends within rounding), for an orthographic and a perspective map,
 * inside and outside the map, in front of and behind a spot. */
static void check_plates(const lcam *c, double bias)
{
    const plate p[3] = { { 10, 30, 12, 20, 60 }, { 25, 40, 15, 44, 75 }, { 50, 51, 3, 60, 40 } };
    float *z = plates_map(c, p, 3);
    ef_shadow *m = lcam_build(c, z, bias, 1, 1);   /* flat plates: no slope bias */
    free(z);
    long compared = 0;
    for (int trial = 0; trial < 3000; ++trial) {
        /* from a point near the plates' world, any direction */
        double org[3], dir[3];
        const double centre = c->ortho ? 70 : 50;
        for (int a = 0; a < 3; ++a) {
            org[a] = c->org[a] + c->Z[a] * urand(0.3, 1.5) * centre +
                     (c->X[a] + c->Y[a]) * urand(-20, 20);
            dir[a] = urand(-1, 1);
        }
        unit(dir);
        const double D = trial % 4 == 0 ? INFINITY : urand(1, 200);
        double got[256][2], want[MAXI][2];
        const int ng = ef_shadow_lit(m, org, dir, 0, D, got, 256);
        const int nw = plates_lit(c, p, 3, bias, org, dir, D, want);
        /* intervals shorter than rounding may merge or vanish on one side */
        int ok = ng == nw;
        for (int i = 0; ok && i < ng; ++i)
            for (int e = 0; e < 2; ++e) {
                const double a = got[i][e], b = want[i][e];
                ok &= a == b || fabs(a - b) <= 1e-9 * (1 + fabs(b));
            }
        if (!ok) {
            double tiny = 1e300;
            for (int i = 0; i < nw; ++i)
                tiny = fmin(tiny, want[i][1] - want[i][0]);
            if (tiny < 1e-7)
                continue;
            fprintf(stderr, "trial %d: %d intervals, want %d; org %.17g,%.17g,%.17g dir "
                    "%.17g,%.17g,%.17g D %.17g\n", trial, ng, nw, org[0], org[1], org[2], dir[0],
                    dir[1], dir[2], D);
            for (int i = 0; i < ng || i < nw; ++i)
                fprintf(stderr, "  got [%.17g, %.17g]  want [%.17g, %.17g]\n",
                        i < ng ? got[i][0] : NAN, i < ng ? got[i][1] : NAN,
                        i < nw ? want[i][0] : NAN, i < nw ? want[i][1] : NAN);
            fail_msg("lit intervals differ from the analytic ones");
        }
        compared += ng;
    }
    assert_true(compared >= 2900);
    ef_shadow_unref(m);
}

static void test_plates_ortho(void **state)
{
    (void) state;
    const double sun[3] = { 0.3, 1, 0.2 }, at[3] = { 0.3 * 100, 100, 0.2 * 100 };
    const double fwd[3] = { -sun[0], -sun[1], -sun[2] };
    lcam c = lcam_make(at, fwd, 1, 30, 64);
    check_plates(&c, 0);
    check_plates(&c, 2.5);
}

static void test_plates_perspective(void **state)
{
    (void) state;
    const double at[3] = { 0, 10, 0 }, fwd[3] = { 0.1, -1, 0.05 };
    lcam c = lcam_make(at, fwd, 0, tan(30 * PI / 180), 64);
    check_plates(&c, 0);
    check_plates(&c, 0.75);
}

/* ---- lit light over the analytic intervals, against the reference ---- */

static void scene_one(ef_fog_scene *s, const char *spec, const char *light)
{
    ef_err err;
    ef_scene_init(s);
    if (ef_scene_add(s, spec, &err) || ef_scene_add_light(s, light, &err) ||
        ef_lights_check(s, &err))
        fail_msg("scene refused: %s", err.msg);
}

/* The reference over the lit intervals: T(0, a) from ef_ref_tau times
 * ef_ref_inscatter along the sub-ray [a, b]. */
static void ref_lit(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double (*iv)[2],
                    int n, long double S[3])
{
    S[0] = S[1] = S[2] = 0;
    for (int i = 0; i < n; ++i) {
        ef_ray sub = *r, to = *r;
        for (int a = 0; a < 3; ++a)
            sub.org[a] = r->org[a] + iv[i][0] * r->dir[a];
        sub.dist = sub.planar = iv[i][1] - iv[i][0];
        to.dist = to.planar = iv[i][0];
        long double tau[3] = { 0, 0, 0 }, part[3];
        if (s->comp[0].model == &ef_fog_exp)   /* uniform: by hand */
            for (int k = 0; k < 3; ++k)
                tau[k] = (long double) s->comp[0].p[k] * iv[i][0];
        else if (iv[i][0] > 0)
            assert_int_equal(ef_ref_tau(&s->comp[0], &to, tau, NULL), 0);
        assert_int_equal(ef_ref_inscatter(s, l, &sub, part), 0);
        for (int k = 0; k < 3; ++k)
            S[k] += part[k] * expl(-tau[k]);
    }
}

static void check_lit(const char *spec, const char *light, const lcam *c, double dscale,
                      double rel)
{
    const plate p[2] = { { 10, 30, 12, 20, 60 * dscale }, { 25, 40, 15, 44, 75 * dscale } };
    ef_fog_scene s;
    scene_one(&s, spec, light);
    float *z = plates_map(c, p, 2);
    s.light[0].shadow = lcam_build(c, z, 0, 1, 1);
    free(z);
    int shadowed = 0;
    for (int trial = 0; trial < 24; ++trial) {
        double org[3] = { urand(-5, 5), urand(1, 4), urand(-5, 5) }, dir[3];
        /* rays that cross the plates' shadows on the way to the ground
         * around where the map's axis meets it */
        const double g = -c->org[1] / c->Z[1];
        const double aim[3] = { c->org[0] + g * c->Z[0] + urand(-15, 15), 0,
                                c->org[2] + g * c->Z[2] + urand(-15, 15) };
        for (int a = 0; a < 3; ++a)
            dir[a] = aim[a] - org[a];
        unit(dir);
        const double D = trial % 3 == 0 ? INFINITY : -org[1] / dir[1];
        ef_ray r = { { dir[0], dir[1], dir[2] }, D, D, { org[0], org[1], org[2] } };
        ef_scene_bind(&s, r.org);
        double iv[MAXI][2], S[3], E[3];
        const int n = plates_lit(c, p, 2, 0, org, dir, D, iv);
        shadowed += n != 1 || iv[0][0] != 0 || iv[0][1] != D;
        long double R[3];
        ref_lit(&s, &s.light[0], &r, iv, n, R);
        ef_light_inscatter(&s, &s.light[0], &r, S, E);
        for (int k = 0; k < 3; ++k) {
            const double d = fabs(S[k] - (double) R[k]);
            if (!(d <= rel * fabsl(R[k]) + 1e-300))
                fail_msg("%s, %s, trial %d channel %d: S %.17g ref %.17Lg (rel %.3g)", spec,
                         light, trial, k, S[k], R[k], (double) (d / fabsl(R[k])));
        }
    }
    assert_true(shadowed >= 8);
    ef_scene_free(&s);
}

static void test_lit_reference(void **state)
{
    (void) state;
    /* the sun in height fog and in a half-space (closed forms per lit
     * interval), through an orthographic map along the sunlight */
    const double sun[3] = { 0.3, 1, 0.2 };
    double at[3] = { 30, 100, 20 }, fwd[3] = { -sun[0], -sun[1], -sun[2] };
    lcam c = lcam_make(at, fwd, 1, 30, 64);
    check_lit("height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.5",
              "sun:towards=0.3,1,0.2:intensity=3", &c, 1, 1e-12);
    check_lit("halfspace:density=0.04:plane=0,1,0,-6", "sun:towards=0.3,1,0.2", &c, 1, 1e-12);
    /* a spot in uniform fog (quadrature per lit interval) through a
     * perspective map from the spot */
    const double sp[3] = { 2, 12, -1 }, aim[3] = { 0.05, -1, 0.1 };
    lcam cp = lcam_make(sp, aim, 0, tan(35 * PI / 180), 64);
    char light[256];
    snprintf(light, sizeof light, "spot:position=2,12,-1:aim=0.05,-1,0.1:cone=80:blend=0.2:"
             "intensity=40");
    /* plates 6 and 7.5 from the spot, above the ground 12 below it */
    check_lit("exp:density=0.03:phase=hg:g=0.3", light, &cp, 0.1, 1e-10);
    /* the sun in a box (the general quadrature, per lit interval) */
    check_lit("box:density=0.05:min=-40,0,-40:max=40,9,40", "sun:towards=0.3,1,0.2", &c, 1,
              1e-9);
}

/* ---- a sphere: convergence with the map's resolution ---- */

typedef struct sph {
    double C[3], R;
} sph;

/* The sphere's depth render at texel centres (the first hit along the
 * axis), inf where the texel misses it. */
static float *sphere_map(const lcam *c, const sph *b)
{
    float *z = malloc((size_t) c->n * (size_t) c->n * sizeof *z);
    double cc[3];
    to_cam(c, b->C, cc);
    for (int j = 0; j < c->n; ++j)
        for (int i = 0; i < c->n; ++i) {
            const double x = plane_of(c, i + 0.5), y = -plane_of(c, j + 0.5);
            const double dx = x - cc[0], dy = y - cc[1], q = b->R * b->R - dx * dx - dy * dy;
            z[(size_t) j * (size_t) c->n + (size_t) i] = q >= 0 ? (float) (cc[2] - sqrt(q))
                                                                 : INFINITY;
        }
    return z;
}

/* The sphere's true shadow along the ray: behind its front surface within
 * the cylinder of its silhouette (sunlight along -l): the ball, and the
 * half-cylinder beyond its centre plane. Lit intervals of [0, D]. */
static int sphere_lit(const sph *b, const double l[3], const double org[3], const double dir[3],
                      double D, double (*iv)[2])
{
    double w[3], sh[2][2];
    int ns = 0;
    for (int a = 0; a < 3; ++a)
        w[a] = org[a] - b->C[a];
    /* ball: |w + t u|^2 <= R^2 */
    {
        const double B = dot3(w, dir), C = dot3(w, w) - b->R * b->R, disc = B * B - C;
        if (disc > 0) {
            const double lo = fmax(0, -B - sqrt(disc)), hi = fmin(D, -B + sqrt(disc));
            if (lo < hi)
                sh[ns][0] = lo, sh[ns][1] = hi, ++ns;
        }
    }
    /* cylinder: |p - (p.l) l|^2 <= R^2 with p.l <= 0, p = w + t u */
    {
        double wp[3], up[3];
        const double wl = dot3(w, l), ul = dot3(dir, l);
        for (int a = 0; a < 3; ++a) {
            wp[a] = w[a] - wl * l[a];
            up[a] = dir[a] - ul * l[a];
        }
        const double A = dot3(up, up), B = dot3(wp, up), C = dot3(wp, wp) - b->R * b->R;
        double lo = 0, hi = D;
        if (A > 0) {
            const double disc = B * B - A * C;
            if (disc <= 0) {
                hi = -1;
            } else {
                lo = fmax(lo, (-B - sqrt(disc)) / A);
                hi = fmin(hi, (-B + sqrt(disc)) / A);
            }
        } else if (C > 0) {
            hi = -1;
        }
        slab(-wl, -ul, &lo, &hi);
        if (lo < hi)
            sh[ns][0] = lo, sh[ns][1] = hi, ++ns;
    }
    return complement(sh, ns, D, iv);
}

/* The sun in height fog over [a, b]: the test's own adaptive Simpson of
 * sigma(x) albedo p E T(0, t) T_sun(x), with the height fog's optical
 * depths written out (rho e^-(k h), and its integrals along a line). */
typedef struct hf {
    double rho, k, E, p, lu, o[3], u[3];
} hf;

static double hf_f(const hf *q, double t)
{
    const double h0 = q->o[1], mu = q->u[1], h = h0 + t * mu;
    const double sig = q->rho * exp(-q->k * h);
    const double tv = fabs(mu * q->k * t) < 1e-8
                          ? q->rho * exp(-q->k * h0) * t
                          : q->rho * exp(-q->k * h0) * -expm1(-q->k * mu * t) / (q->k * mu);
    return sig * q->p * q->E * exp(-tv - sig / (q->k * q->lu));
}

static double simpson(const hf *q, double a, double b, double fa, double fm, double fb, double whole,
                      double tol, int depth)
{
    const double m = 0.5 * (a + b), l = hf_f(q, 0.5 * (a + m)), r = hf_f(q, 0.5 * (m + b));
    const double left = (b - a) / 12 * (fa + 4 * l + fm), right = (b - a) / 12 * (fm + 4 * r + fb);
    if (depth > 40 || fabs(left + right - whole) <= 15 * tol)
        return left + right + (left + right - whole) / 15;
    return simpson(q, a, m, fa, l, fm, left, tol / 2, depth + 1) +
           simpson(q, m, b, fm, r, fb, right, tol / 2, depth + 1);
}

static double hf_integral(const hf *q, double a, double b)
{
    if (!isfinite(b))
        b = a + 400;   /* T(0, t) < e^-40 beyond on these rays */
    double sum = 0;
    const int pieces = 32;
    for (int i = 0; i < pieces; ++i) {
        const double x0 = a + (b - a) * i / pieces, x1 = a + (b - a) * (i + 1) / pieces;
        const double f0 = hf_f(q, x0), fm = hf_f(q, 0.5 * (x0 + x1)), f1 = hf_f(q, x1);
        sum += simpson(q, x0, x1, f0, fm, f1, (x1 - x0) / 6 * (f0 + 4 * fm + f1), 1e-12, 0);
    }
    return sum;
}

static void test_sphere_convergence(void **state)
{
    (void) state;
    double l[3] = { 0.3, 1, 0.2 };
    unit(l);
    const sph b = { { 0, 6, -20 }, 3 };
    const double at[3] = { b.C[0] + 60 * l[0], b.C[1] + 60 * l[1], b.C[2] + 60 * l[2] };
    const double fwd[3] = { -l[0], -l[1], -l[2] };
    ef_fog_scene s;
    scene_one(&s, "height:density=0.05:falloff=0.15:base=0", "sun:towards=0.3,1,0.2:intensity=1");
    const int res[3] = { 64, 256, 1024 };
    double errs[3];
    for (int ri = 0; ri < 3; ++ri) {
        lcam c = lcam_make(at, fwd, 1, 8, res[ri]);
        float *z = sphere_map(&c, &b);
        ef_shadow_unref(s.light[0].shadow);
        s.light[0].shadow = lcam_build(&c, z, 0, 1, 1);
        free(z);
        rng = 99;
        double num = 0, den = 0;
        for (int trial = 0; trial < 150; ++trial) {
            /* from the camera at (0, 1.7, 0) to the ground around the shadow */
            double org[3] = { 0, 1.7, 0 }, dir[3];
            const double g[3] = { urand(-6, 6), 0, urand(-30, -20) };
            for (int a = 0; a < 3; ++a)
                dir[a] = g[a] - org[a];
            unit(dir);
            const double D = -org[1] / dir[1];
            ef_ray r = { { dir[0], dir[1], dir[2] }, D, D, { org[0], org[1], org[2] } };
            ef_scene_bind(&s, r.org);
            double S[3], E[3], iv[4][2];
            ef_light_inscatter(&s, &s.light[0], &r, S, E);
            const int n = sphere_lit(&b, l, org, dir, D, iv);
            hf q = { 0.05, 0.15, 1, 1 / (4 * PI), l[1], { 0, 1.7, 0 }, { 0, 0, 0 } };
            memcpy(q.u, dir, sizeof q.u);
            double want = 0;
            for (int i = 0; i < n; ++i)
                want += hf_integral(&q, iv[i][0], iv[i][1]);
            num += fabs(S[1] - want);
            den += want;
        }
        errs[ri] = num / den;
        print_message("sphere shadow, %4d^2 map: mean |S - exact| / mean S = %.3g\n", res[ri],
                      errs[ri]);
    }
    /* the texel edges misplace the silhouette by up to half a texel: the
     * error falls about as the resolution grows */
    assert_true(errs[1] < errs[0] / 2.5);
    assert_true(errs[2] < errs[1] / 2.5);
    assert_true(errs[2] < 2e-3);
    ef_scene_free(&s);
}

/* ---- penumbrae from the sun's disc (filtered, against the true disc) ---- */

/* The overlap of two discs of radii a and b whose centres lie d apart. */
static double disc_overlap(double a, double b, double d)
{
    if (d >= a + b)
        return 0;
    if (d <= fabs(a - b))
        return PI * fmin(a, b) * fmin(a, b);
    const double ca = (d * d + a * a - b * b) / (2 * d * a),
                 cb = (d * d + b * b - a * a) / (2 * d * b);
    return a * a * acos(ca) + b * b * acos(cb) -
           0.5 * sqrt((-d + a + b) * (d + a - b) * (d - a + b) * (d + a + b));
}

/* The fraction of a sun disc of angular radius rho about l that the
 * sphere leaves visible from x (the two discs as cones about x, their
 * overlap in the tangent plane: small angles), 0 inside the ball. */
static double sphere_vis(const sph *b, const double l[3], double rho, const double x[3])
{
    const double v[3] = { b->C[0] - x[0], b->C[1] - x[1], b->C[2] - x[2] };
    const double dist = sqrt(dot3(v, v));
    if (dist <= b->R)
        return 0;
    const double beta = asin(b->R / dist);
    const double delta = acos(fmax(-1, fmin(1, dot3(v, l) / dist)));
    return 1 - disc_overlap(rho, beta, delta) / (PI * rho * rho);
}

/* The sun in height fog times the true visibility along the ray: the
 * test's own Simpson over 4000 pieces (V is continuous). */
static double soft_integral(const hf *q, const sph *b, const double l[3], double rho, double D)
{
    const int n = 4000;
    double sum = 0;
    for (int i = 0; i <= 2 * n; ++i) {
        const double t = D * i / (2 * n);
        double x[3];
        for (int a = 0; a < 3; ++a)
            x[a] = q->o[a] + t * q->u[a];
        const double wgt = i == 0 || i == 2 * n ? 1 : i % 2 ? 4 : 2;
        sum += wgt * hf_f(q, t) * sphere_vis(b, l, rho, x);
    }
    return sum * D / (6 * n);
}

/* angle= with a shadow map: the copies' visibility against the fraction
 * of the sun's disc a sphere truly leaves, point by point and along rays
 * in height fog; more directions, closer; and the hard map's error
 * against the same soft truth, for scale. A sloped ground under the sun
 * stays lit just above it (the copies' resampling keeps its plane). */
static void test_penumbra(void **state)
{
    (void) state;
    double l[3] = { 0.3, 1, 0.2 };
    unit(l);
    const sph b = { { 0, 6, -20 }, 3 };
    const double angle = 4 * PI / 180, rho = angle / 2;
    const double at[3] = { b.C[0] + 60 * l[0], b.C[1] + 60 * l[1], b.C[2] + 60 * l[2] };
    const double fwd[3] = { -l[0], -l[1], -l[2] };
    lcam c = lcam_make(at, fwd, 1, 8, 1024);
    float *z = sphere_map(&c, &b);
    const int dirs[3] = { 0, 16, 64 };
    double perr[3], rerr[3];
    for (int di = 0; di < 3; ++di) {
        ef_shadow *m = lcam_build(&c, z, 0, 1, 1);
        ef_err err;
        if (dirs[di])
            assert_int_equal(ef_shadow_soften(m, angle, dirs[di], &err), 0);
        /* points behind the ball across its penumbra: 4 to 30 units past
         * its centre plane, within the disc's reach of its silhouette */
        rng = 7;
        double num = 0;
        int npts = 0;
        for (int trial = 0; trial < 3000; ++trial) {
            const double s = urand(4, 30), ph = urand(0, 2 * PI);
            const double rr = b.R / cos(rho) + urand(-1.2, 1.2) * s * tan(rho);
            double x[3];
            for (int a = 0; a < 3; ++a)
                x[a] = b.C[a] - s * l[a] + rr * (cos(ph) * c.X[a] + sin(ph) * c.Y[a]);
            const double want = sphere_vis(&b, l, rho, x), got = ef_shadow_point_vis(m, x);
            num += fabs(got - want);
            ++npts;
        }
        perr[di] = num / npts;
        /* rays from a camera under the ball through its penumbra */
        ef_fog_scene sc;
        scene_one(&sc, "height:density=0.05:falloff=0.15:base=0",
                  "sun:towards=0.3,1,0.2:intensity=1");
        sc.light[0].shadow = m;
        double rnum = 0, rden = 0;
        for (int trial = 0; trial < 60; ++trial) {
            double org[3] = { urand(-2, 2), 1.7, urand(-8, -4) }, dir[3];
            const double g[3] = { urand(-8, 8), 0, urand(-34, -26) };
            for (int a = 0; a < 3; ++a)
                dir[a] = g[a] - org[a];
            unit(dir);
            const double D = -org[1] / dir[1];
            ef_ray r = { { dir[0], dir[1], dir[2] }, D, D, { org[0], org[1], org[2] } };
            ef_scene_bind(&sc, r.org);
            double S[3], E[3];
            ef_light_inscatter(&sc, &sc.light[0], &r, S, E);
            hf q = { 0.05, 0.15, 1, 1 / (4 * PI), l[1], { org[0], org[1], org[2] },
                     { dir[0], dir[1], dir[2] } };
            const double want = soft_integral(&q, &b, l, rho, D);
            rnum += fabs(S[1] - want);
            rden += want;
        }
        rerr[di] = rnum / rden;
        print_message("penumbra, %2d directions (0: hard): mean |V - disc| %.4f over %d points; "
                      "light along 60 rays: mean |S - exact| / mean S = %.3g\n",
                      dirs[di], perr[di], npts, rerr[di]);
        ef_scene_free(&sc);   /* drops m */
    }
    free(z);
    /* the hard map is off by the penumbra itself; the copies approach the
     * disc as the directions grow */
    assert_true(perr[1] < perr[0] / 3);
    assert_true(perr[2] < perr[1]);
    assert_true(perr[2] < 0.02);
    assert_true(rerr[1] < rerr[0] / 3);
    assert_true(rerr[2] < 3e-4);

    /* a ground plane under a sun 20 degrees up, and points just above it:
     * lit in every copy */
    double l2[3] = { 0, sin(20 * PI / 180), cos(20 * PI / 180) };
    const double at2[3] = { 80 * l2[0], 80 * l2[1], 80 * l2[2] };
    const double fwd2[3] = { -l2[0], -l2[1], -l2[2] };
    lcam g = lcam_make(at2, fwd2, 1, 20, 512);
    float *zg = malloc((size_t) g.n * (size_t) g.n * sizeof *zg);
    for (int j = 0; j < g.n; ++j)
        for (int i = 0; i < g.n; ++i) {
            /* the texel centre's line along the axis meets y = 0 */
            double o[3];
            const double x = plane_of(&g, i + 0.5), y = -plane_of(&g, j + 0.5);
            for (int a = 0; a < 3; ++a)
                o[a] = g.org[a] + x * g.X[a] + y * g.Y[a];
            zg[(size_t) j * (size_t) g.n + (size_t) i] = (float) (-o[1] / g.Z[1]);
        }
    ef_shadow *mg = lcam_build(&g, zg, 0, 1, 1);
    ef_err err;
    assert_int_equal(ef_shadow_soften(mg, 0.53 * PI / 180, 16, &err), 0);
    rng = 3;
    int dark = 0;
    for (int trial = 0; trial < 20000; ++trial) {
        const double x[3] = { urand(-10, 10), urand(0.02, 0.5), urand(-10, 10) };
        dark += ef_shadow_point_vis(mg, x) < 1;
    }
    print_message("penumbra over a ground 20 degrees to the sun: %d of 20000 points just "
                  "above it not fully lit\n", dark);
    assert_int_equal(dark, 0);
    ef_shadow_unref(mg);
    free(zg);
}

/* ---- a fence: more lit intervals than the stack holds ---- */

/* A map whose every other texel column is a post (an orthographic sun
 * straight down): a ray under the posts along the fence is lit in 512
 * pieces, past the 256 kept on the stack. Its light in a half-space fog
 * equals the reference summed over the analytic gaps. */
static void test_fence(void **state)
{
    (void) state;
    const double at[3] = { 0, 100, 0 }, fwd[3] = { 0, -1, 0 };
    lcam c = lcam_make(at, fwd, 1, 51.2, 1024);   /* 0.1 units per texel */
    float *z = malloc((size_t) 1024 * 1024 * sizeof *z);
    for (int j = 0; j < 1024; ++j)
        for (int i = 0; i < 1024; ++i)
            z[(size_t) j * 1024 + i] = i % 2 == 0 ? 10.0f : INFINITY;   /* posts at y = 90 */
    ef_fog_scene s;
    scene_one(&s, "halfspace:density=0.02:plane=0,1,0,-95", "sun:towards=0,1,0:intensity=2");
    s.light[0].shadow = lcam_build(&c, z, 0, 0, 1);
    free(z);
    /* along the map's x axis (which lcam_make set), under the posts */
    const double org[3] = { -51.2 * c.X[0], 50, -51.2 * c.X[2] + 0.05 * c.Y[2] };
    const double dir[3] = { c.X[0], 0, c.X[2] };
    const double D = 102.4;
    double iv[600][2];
    int n = 0;
    for (int i = 1; i < 1024; i += 2) {
        /* the gap between post columns i - 1 and i + 1 */
        iv[n][0] = i * 0.1;
        iv[n][1] = (i + 1) * 0.1;
        ++n;
    }
    double got[256][2];
    assert_true(ef_shadow_lit(s.light[0].shadow, org, dir, 0, D, got, 256) < 0);
    ef_ray r = { { dir[0], dir[1], dir[2] }, D, D, { org[0], org[1], org[2] } };
    ef_scene_bind(&s, r.org);
    double S[3], E[3];
    long double R[3];
    ef_light_inscatter(&s, &s.light[0], &r, S, E);
    ref_lit(&s, &s.light[0], &r, iv, n, R);
    assert_true(fabs(S[0] - (double) R[0]) <= 1e-9 * fabsl(R[0]));
    ef_scene_free(&s);
}

/* ---- acne: a low sun on the ground ---- */

/* The ground y = 0 seen by a sun 8 degrees up: its texels' depths span
 * width / tan(8 deg) each, so without the slope bias fog just above the
 * ground is shadowed in stripes; with it (the default) a point a
 * thousandth of a texel's depth span above the ground is lit everywhere,
 * and points a texel's depth span below the ground stay shadowed (the bias
 * lets light a texel's depth span into a surface, no deeper). */
static void test_acne(void **state)
{
    (void) state;
    const double el = 8 * PI / 180;
    double l[3] = { 0.3 * cos(el), sin(el), -cos(el) };
    unit(l);
    const double at[3] = { 50 * l[0], 50 * l[1], -20 + 50 * l[2] };
    const double fwd[3] = { -l[0], -l[1], -l[2] };
    lcam c = lcam_make(at, fwd, 1, 10, 256);
    float *z = malloc(256 * 256 * sizeof *z);
    for (int j = 0; j < 256; ++j)
        for (int i = 0; i < 256; ++i) {
            /* the ground under the texel centre, along the axis */
            double p[3];
            for (int a = 0; a < 3; ++a)
                p[a] = c.org[a] + c.X[a] * plane_of(&c, i + 0.5) - c.Y[a] * plane_of(&c, j + 0.5);
            const double t = -p[1] / c.Z[1];
            z[(size_t) j * 256 + (size_t) i] = t > 0 ? (float) t : INFINITY;
        }
    ef_shadow *plain = lcam_build(&c, z, 0, 0, 1), *sloped = lcam_build(&c, z, 0, 1, 1);
    const double span = 2 * 10.0 / 256 / tan(el);   /* a texel's depth span */
    int acne = 0, lit = 0, n = 0, below = 0;
    rng = 5;
    for (int k = 0; k < 20000; ++k) {
        const double x[3] = { urand(-6, 6), 1e-3 * span * sin(el), -20 + urand(-6, 6) };
        const double y[3] = { x[0], -1.5 * span * sin(el), x[2] };   /* a span down */
        acne += !ef_shadow_point_lit(plain, x);
        lit += ef_shadow_point_lit(sloped, x);
        below += !ef_shadow_point_lit(sloped, y);
        ++n;
    }
    print_message("low sun on the ground: %.1f %% of points just above it shadowed without the "
                  "slope bias, %.2f %% with it\n", 100.0 * acne / n, 100.0 * (n - lit) / n);
    assert_true(acne > n / 4);
    assert_int_equal(lit, n);
    assert_int_equal(below, n);
    ef_shadow_unref(plain);
    ef_shadow_unref(sloped);
    free(z);
}

/* ---- the command line ---- */

/* Writes c's map of depths z (n x n) with its camera as float matrices, as
 * a renderer would; channel NULL: no depth channel; no_cam: no matrices. */
static void write_map(const char *path, const lcam *c, const float *z, const char *channel,
                      int no_cam)
{
    tu_part p;
    tu_part_init(&p, c->n, c->n);
    float *other = NULL;
    if (channel) {
        tu_part_add(&p, channel, EXR_PIXEL_FLOAT, z);
    } else {
        other = calloc((size_t) c->n * (size_t) c->n, sizeof *other);
        tu_part_add(&p, "R", EXR_PIXEL_HALF, other);
    }
    if (!no_cam) {
        ef_mat4 w2c, w2n;
        lcam_matrices(c, &w2c, &w2n);
        p.m44[0].name = "worldToCamera";
        p.m44[1].name = "worldToNDC";
        for (int i = 0; i < 16; ++i) {
            p.m44[0].m[i] = (float) w2c.m[i];
            p.m44[1].m[i] = (float) w2n.m[i];
        }
    }
    assert_int_equal(tu_write_exr(path, &p, 1), 0);
    free(other);
}

static int same_channel(const char *a, const char *b, const char *ch)
{
    int w, h, w2, h2;
    float *x = tu_read_channel(a, 0, ch, &w, &h), *y = tu_read_channel(b, 0, ch, &w2, &h2);
    const int same = x && y && w == w2 && h == h2 && !memcmp(x, y, (size_t) w * h * sizeof *x);
    free(x);
    free(y);
    return same;
}

static void test_cli(void **state)
{
    (void) state;
    char in[4096];
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    snprintf(in, sizeof in, "%s/samples/sample.exr", src ? src : ".");
    /* a ball over the sample's ground, seen by the sun along 0.3,1,0.2 */
    double l[3] = { 0.3, 1, 0.2 };
    unit(l);
    const sph b = { { 0, 6, -12 }, 2.5 };
    const double at[3] = { b.C[0] + 80 * l[0], b.C[1] + 80 * l[1], b.C[2] + 80 * l[2] };
    const double fwd[3] = { -l[0], -l[1], -l[2] };
    lcam c = lcam_make(at, fwd, 1, 6, 256);
    float *z = sphere_map(&c, &b), *none = malloc(256 * 256 * sizeof *none);
    for (int i = 0; i < 256 * 256; ++i)
        none[i] = INFINITY;
    char *map = tu_path("shadow_ball.exr"), *empty = tu_path("shadow_none.exr");
    char *nocam = tu_path("shadow_nocam.exr"), *noz = tu_path("shadow_noz.exr");
    char *a = tu_path("shadow_a.exr"), *bb = tu_path("shadow_b.exr"), *cc = tu_path("shadow_c.exr");
    write_map(map, &c, z, "Z", 0);
    write_map(empty, &c, none, "depth.Z", 0);
    write_map(nocam, &c, z, "Z", 1);
    write_map(noz, &c, z, NULL, 0);
    const char *fog = "--fog height:density=0.08:falloff=0.25:base=0";
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3", in, a,
                             fog), 0);
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                             "shadow='%s'", in, bb, fog, map), 0);
    /* an empty map (nothing casts) changes no bit */
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                             "shadow='%s':outside=lit", in, cc, fog, empty), 0);
    assert_true(same_channel(a, cc, "R") && same_channel(a, cc, "B"));
    /* the ball's shadow darkens the fog, and nothing brightens */
    int w, h;
    float *ra = tu_read_channel(a, 0, "R", &w, &h), *rb = tu_read_channel(bb, 0, "R", &w, &h);
    assert_true(ra && rb);
    long darker = 0;
    for (int i = 0; i < w * h; ++i) {
        assert_true(rb[i] <= ra[i]);
        darker += rb[i] < ra[i] * 0.999f;
    }
    assert_true(darker > w * h / 50);
    free(ra);
    free(rb);
    /* --aov lit: the share of the sun's light past the ball, which is the
     * ratio of its light layer with and without the map */
    char *la = tu_path("shadow_la.exr"), *lb = tu_path("shadow_lb.exr");
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3 "
                             "--aov light", in, la, fog), 0);
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                             "shadow='%s' --aov light,lit", in, lb, fog, map), 0);
    tu_image A, B;
    assert_int_equal(tu_read_image(la, 0, &A), 0);
    assert_int_equal(tu_read_image(lb, 0, &B), 0);
    const float *lit = tu_image_f(&B, "fog_lit.sun1");
    assert_non_null(lit);
    long partial = 0;
    for (int i = 0; i < A.w * A.h; ++i) {
        double un = 0, sh = 0;
        for (int k = 0; k < 3; ++k) {
            static const char *const ch[3] = { "fog_light.sun1.R", "fog_light.sun1.G",
                                               "fog_light.sun1.B" };
            un += tu_image_f(&A, ch[k])[i];
            sh += tu_image_f(&B, ch[k])[i];
        }
        assert_true(lit[i] >= 0 && lit[i] <= 1);
        if (un > 1e-6)
            assert_close(lit[i], sh / un, 1e-5);
        partial += lit[i] < 0.99f;
    }
    assert_true(partial > A.w * A.h / 50);
    tu_image_free(&A);
    tu_image_free(&B);
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2 --aov lit", in, cc,
                             fog), 2);
    assert_non_null(strstr(tu_err, "no --light has a shadow= map"));
    free(la);
    free(lb);
    /* angle= softens the ball's shadow (16 directions by default): never
     * brighter than no map, unlike the hard shadow in places, and its lit
     * fraction in [0, 1]; penumbra=0 is the hard shadow bit for bit */
    {
        char *sa = tu_path("shadow_soft.exr"), *s0 = tu_path("shadow_soft0.exr");
        assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                                 "angle=3:shadow='%s' --aov lit", in, sa, fog, map), 0);
        assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                                 "angle=3:penumbra=0:shadow='%s'", in, s0, fog, map), 0);
        assert_true(same_channel(bb, s0, "R") && same_channel(bb, s0, "B"));
        float *ua = tu_read_channel(a, 0, "R", &w, &h), *uh = tu_read_channel(bb, 0, "R", &w, &h);
        float *us = tu_read_channel(sa, 0, "R", &w, &h);
        float *ul = tu_read_channel(sa, 0, "fog_lit.sun1", &w, &h);
        assert_true(ua && uh && us && ul);
        long differ = 0;
        for (int i = 0; i < w * h; ++i) {
            assert_true(us[i] <= ua[i] * 1.0001f + 1e-6f);
            assert_true(ul[i] >= 0 && ul[i] <= 1);
            differ += fabsf(us[i] - uh[i]) > 1e-4f * ua[i];
        }
        assert_true(differ > w * h / 200);
        free(ua);
        free(uh);
        free(us);
        free(ul);
        assert_int_equal(tu_runf("'%s' --explain %s --light sun:towards=0.3,1,0.2:angle=3:"
                                 "penumbra=8:shadow='%s'", in, fog, map), 0);
        assert_non_null(strstr(tu_out, "penumbra: 8 directions"));
        /* penumbra= without angle= or a map, out of range, on a lamp: usage */
        const char *const usage[] = {
            "sun:towards=0.3,1,0.2:penumbra=8:shadow='%s'",
            "sun:towards=0.3,1,0.2:angle=1:penumbra=8",
            "sun:towards=0.3,1,0.2:angle=1:penumbra=65:shadow='%s'",
            "sun:towards=0.3,1,0.2:angle=1:penumbra=2.5:shadow='%s'",
            "point:position=0,8,0:penumbra=8",
        };
        remove(cc);
        for (size_t i = 0; i < sizeof usage / sizeof usage[0]; ++i) {
            char light[1024];
            snprintf(light, sizeof light, usage[i], map);
            assert_int_equal(tu_runf("'%s' -o '%s' %s --light %s", in, cc, fog, light), 2);
            assert_non_null(strstr(tu_err, "penumbra"));
            assert_false(tu_exists(cc));
        }
        free(sa);
        free(s0);
    }
    /* outside=shadow darkens everything the map does not cover */
    remove(cc);
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                             "shadow='%s':outside=shadow", in, cc, fog, empty), 0);
    assert_false(same_channel(a, cc, "R"));
    /* a scene file's light takes the same keys */
    char *js = tu_path("shadow_scene.json");
    FILE *f = fopen(js, "w");
    assert_non_null(f);
    fprintf(f, "{\"fog\": [{\"model\": \"height\", \"density\": 0.08, \"falloff\": 0.25, "
            "\"base\": 0}], \"lights\": [{\"kind\": \"sun\", \"towards\": [0.3, 1, 0.2], "
            "\"intensity\": 3, \"shadow\": \"%s\"}]}", map);
    fclose(f);
    remove(cc);
    assert_int_equal(tu_runf("'%s' -o '%s' --scene '%s'", in, cc, js), 0);
    assert_true(same_channel(bb, cc, "R"));
    /* files at fault: exit 1, the file named, no output */
    remove(cc);
    const struct { const char *light; const char *want; } bad[] = {
        { "sun:towards=0.3,1,0.2:shadow=/nonexistent/map.exr", "/nonexistent/map.exr" },
        { "sun:towards=0.3,1,0.2:shadow='%s'", "worldToCamera" },
        { "sun:towards=0.3,1,0.2:shadow='%s'", "no depth channel" },
        { "sun:towards=0.3,1.2,0.2:shadow='%s'", "another direction" },
        { "spot:position=0,8,0:aim=0,-1,0:cone=40:shadow='%s'", "orthographic" },
    };
    const char *files[] = { NULL, nocam, noz, map, map };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        char light[1024];
        snprintf(light, sizeof light, bad[i].light, files[i] ? files[i] : "");
        assert_int_equal(tu_runf("'%s' -o '%s' %s --light %s", in, cc, fog, light), 1);
        if (!strstr(tu_err, bad[i].want) || strncmp(tu_err, "exrfog: ", 8))
            fail_msg("--light %s: '%s' lacks '%s'", light, tu_err, bad[i].want);
        assert_false(tu_exists(cc));
    }
    /* --explain names each light's map and how it reads it */
    assert_int_equal(tu_runf("'%s' --explain --json %s --light sun:towards=0.3,1,0.2:"
                             "shadow='%s':slope=0.5", in, fog, map), 0);
    assert_non_null(strstr(tu_out, "\"projection\": \"orthographic\""));
    assert_non_null(strstr(tu_out, "\"slope\": 0.5"));
    assert_non_null(strstr(tu_out, "\"penumbra\": 0"));
    /* hostile maps: a map of NaN depths casts nothing (no bit changes), a
     * 1 x 1 map and a map whose camera is not finite or singular are read
     * or refused, never crash; a truncated map is refused */
    {
        lcam c1 = lcam_make(at, fwd, 1, 6, 1);
        float one = 5.0f, *nans = malloc(256 * 256 * sizeof *nans);
        for (int i = 0; i < 256 * 256; ++i)
            nans[i] = NAN;
        char *m1 = tu_path("shadow_1x1.exr"), *mn = tu_path("shadow_nan.exr");
        char *mt = tu_path("shadow_trunc.exr");
        write_map(m1, &c1, &one, "Z", 0);
        write_map(mn, &c, nans, "Z", 0);
        /* hard, then with penumbrae: the NaN map casts nothing either way,
         * the 1 x 1 map runs (with 64 directions), and so does a disc 170
         * degrees wide (a shear past the map) */
        static const char *const soft[2] = { "", "angle=2:penumbra=64:" };
        for (int p = 0; p < 2; ++p) {
            remove(cc);
            assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                                     "%sshadow='%s'", in, cc, fog, soft[p], mn), 0);
            assert_true(same_channel(a, cc, "R"));
            remove(cc);
            assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                                     "%sshadow='%s'", in, cc, fog, soft[p], m1), 0);
        }
        remove(cc);
        assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:intensity=3:"
                                 "angle=170:penumbra=3:shadow='%s' --aov lit", in, cc, fog, map),
                         0);
        float *lw = tu_read_channel(cc, 0, "fog_lit.sun1", &w, &h);
        assert_non_null(lw);
        for (int i = 0; i < w * h; ++i)
            assert_true(lw[i] >= 0 && lw[i] <= 1);
        free(lw);
        /* the first 300 bytes of a map */
        FILE *src_f = fopen(map, "rb");
        assert_non_null(src_f);
        char head[300];
        assert_int_equal(fread(head, 1, sizeof head, src_f), sizeof head);
        fclose(src_f);
        assert_int_equal(tu_write_bytes(mt, head, sizeof head), 0);
        remove(cc);
        assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:shadow='%s'", in,
                                 cc, fog, mt), 1);
        assert_non_null(strstr(tu_err, mt));
        assert_false(tu_exists(cc));
        /* a singular and a non-finite camera */
        tu_part p;
        tu_part_init(&p, 256, 256);
        tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, z);
        p.m44[0].name = "worldToCamera";
        p.m44[1].name = "worldToNDC";
        for (int bad = 0; bad < 2; ++bad) {
            memset(p.m44[0].m, 0, sizeof p.m44[0].m);
            memset(p.m44[1].m, 0, sizeof p.m44[1].m);
            if (bad)
                for (int i = 0; i < 16; ++i)
                    p.m44[0].m[i] = p.m44[1].m[i] = i % 5 == 0 ? INFINITY : 0.0f;
            assert_int_equal(tu_write_exr(mt, &p, 1), 0);
            assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0.3,1,0.2:"
                                     "shadow='%s'", in, cc, fog, mt), 1);
            if (!strstr(tu_err, bad ? "not finite" : "singular"))
                fail_msg("a %s camera: '%s'", bad ? "non-finite" : "singular", tu_err);
            assert_false(tu_exists(cc));
        }
        free(nans);
        free(m1);
        free(mn);
        free(mt);
    }
    /* usage: exit 2 */
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light point:position=0,3,-5:shadow='%s'", in, cc,
                             fog, map), 2);
    assert_int_equal(tu_runf("'%s' -o '%s' %s --light sun:towards=0,1,0:bias=-1:shadow='%s'", in,
                             cc, fog, map), 2);
    assert_false(tu_exists(cc));
    free(z);
    free(none);
    free(map);
    free(empty);
    free(nocam);
    free(noz);
    free(a);
    free(bb);
    free(cc);
    free(js);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_plates_ortho),
        cmocka_unit_test(test_plates_perspective),
        cmocka_unit_test(test_lit_reference),
        cmocka_unit_test(test_sphere_convergence),
        cmocka_unit_test(test_penumbra),
        cmocka_unit_test(test_fence),
        cmocka_unit_test(test_acne),
        cmocka_unit_test(test_cli),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
