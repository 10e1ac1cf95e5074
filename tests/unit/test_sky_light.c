/* --sky-light (issue 25): a lat-long environment's single scattering,
 * checked against values found independently: the phase functions'
 * convolution of environments with known transforms (a constant one
 * stays itself: the phases are normalised; L = 1 + l.a becomes
 * 1 + gbar u.a, gbar the phase's mean cosine, g for Henyey-Greenstein),
 * a brute-force sum over every texel of a random environment, the
 * documented orientation (a bright spot lands where the formula says, and
 * rotate= turns it about up), and the composite through the CLI against
 * albedo C(u) (1 - T) from the fog's own T and position AOVs. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "light.h"
#include "sky_light.h"
#include "tassert.h"
#include "testutil.h"

#define PI 3.14159265358979323846

/* The documented direction of map texel (x + 0.5, y + 0.5) of w x h in a
 * scene of up axis up (y or z), written out on its own here. */
static void map_dir(int upz, double x, double y, int w, int h, double rot_deg, double d[3])
{
    const double th = PI * y / h, ph = PI - 2 * PI * x / w + rot_deg * PI / 180;
    /* e1 = x; e2 = up x e1: +y for z up, -z for y up */
    const double a = sin(th) * cos(ph), b = sin(th) * sin(ph), c = cos(th);
    if (upz) {
        d[0] = a, d[1] = b, d[2] = c;
    } else {
        d[0] = a, d[1] = c, d[2] = -b;
    }
}

typedef struct env {
    int w, h;
    float *p[3];
} env;

static env env_make(int w, int h)
{
    env e = { w, h, { NULL, NULL, NULL } };
    for (int c = 0; c < 3; ++c)
        e.p[c] = calloc((size_t) w * (size_t) h, sizeof(float));
    return e;
}

static void env_free(env *e)
{
    for (int c = 0; c < 3; ++c)
        free(e->p[c]);
}

/* A 512 x 256 y-up map whose channel c is c0[c] + k[c] v, v = 1 + l.a the
 * dipole (l the texel's direction). */
static env env_dipole(const double a[3], const double k[3], const double c0[3])
{
    env e = env_make(512, 256);
    for (int y = 0; y < e.h; ++y)
        for (int x = 0; x < e.w; ++x) {
            double d[3];
            map_dir(0, x + 0.5, y + 0.5, e.w, e.h, 0, d);
            const double v = 1 + a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
            for (int c = 0; c < 3; ++c)
                e.p[c][(size_t) y * e.w + x] = (float) (c0[c] + k[c] * v);
        }
    return e;
}

/* ef_env_src's row reader over an env's planes, in order only. */
static int env_rows(void *user, int y, float *const out[3])
{
    const env *e = user;
    static _Thread_local int next = 0;
    if (y == 0)
        next = 0;
    if (y != next++)
        return -1;
    for (int c = 0; c < 3; ++c)
        memcpy(out[c], e->p[c] + (size_t) y * e->w, (size_t) e->w * sizeof(float));
    return 0;
}

/* The sky light of e, built from its planes; built again streaming its
 * rows (as a file is read), which must give the same grids bit for bit. */
static ef_sky_light *build(const env *e, int phase, double g, double rot)
{
    ef_env_src src = { "synthetic", e->w, e->h, { e->p[0], e->p[1], e->p[2] }, NULL, NULL };
    ef_err err;
    ef_sky_light *k = ef_sky_light_build(&src, rot, 1.0, &phase, &g, 1, &err);
    if (!k)
        fail_msg("build: %s", err.msg);
    ef_env_src rows = { "synthetic", e->w, e->h, { NULL, NULL, NULL }, env_rows, (void *) e };
    ef_sky_light *k2 = ef_sky_light_build(&rows, rot, 1.0, &phase, &g, 1, &err);
    if (!k2)
        fail_msg("build from rows: %s", err.msg);
    assert_int_equal(k->nconv, k2->nconv);
    for (int j = 0; j < k->nconv; ++j)
        for (int c = 0; c < 3; ++c)
            assert_memory_equal(k->conv[j].c[c], k2->conv[j].c[c],
                                (size_t) k->conv[j].w * (size_t) k->conv[j].h * sizeof(float));
    ef_sky_light_unref(k2);
    return k;
}

static uint32_t rng = 777;

static void rand_dir(double d[3])
{
    double n;
    do {
        for (int a = 0; a < 3; ++a)
            d[a] = 2 * tu_rand01(&rng) - 1;
        n = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    } while (n > 1 || n < 1e-3);
    for (int a = 0; a < 3; ++a)
        d[a] /= n;
}

/* Mean cosine of a phase: the first moment any L = 1 + l.a picks up. */
static double gbar(int phase, double g)
{
    return phase == EF_PHASE_HG ? g
         : phase == EF_PHASE_CS ? 3 * g * (4 + g * g) / (5 * (2 + g * g)) : 0;
}

/* Constant and dipole environments: C = L0, and 1 + gbar u.a. */
static void test_known_transforms(void **state)
{
    (void) state;
    const double up_y[3] = { 0, 1, 0 };
    const double a[3] = { 0.3, 0.5, -0.6 };
    const struct { int phase; double g, tol; } ph[] = {
        { EF_PHASE_ISO, 0, 1e-6 },     { EF_PHASE_RAYLEIGH, 0, 2e-3 }, { EF_PHASE_HG, 0.3, 2e-3 },
        { EF_PHASE_HG, 0.8, 3e-3 },    { EF_PHASE_HG, -0.6, 6e-3 },    { EF_PHASE_CS, 0.7, 3e-3 },
        { EF_PHASE_HG, 0.95, 1e-2 },
    };
    const double k[3] = { 1, 0, 2 }, c0[3] = { 0, 2, 0 };   /* R = v, G = 2, B = 2 v */
    env e = env_dipole(a, k, c0);
    for (size_t i = 0; i < sizeof ph / sizeof ph[0]; ++i) {
        ef_sky_light *k = build(&e, ph[i].phase, ph[i].g, 0);
        double worst = 0;
        for (int t = 0; t < 400; ++t) {
            double u[3], C[3];
            rand_dir(u);
            assert_int_equal(ef_sky_light_eval(k, ph[i].phase, ph[i].g, up_y, u, C), 0);
            const double want = 1 + gbar(ph[i].phase, ph[i].g) * (a[0] * u[0] + a[1] * u[1] +
                                                                  a[2] * u[2]);
            worst = fmax(worst, fabs(C[0] - want) / want);
            worst = fmax(worst, fabs(C[1] - 2) / 2);
            worst = fmax(worst, fabs(C[2] - 2 * want) / (2 * want));
        }
        print_message("phase %d g %g: grid %d x %d, worst relative error %.2e\n", ph[i].phase,
                      ph[i].g, k->conv[0].w, k->conv[0].h, worst);
        assert_true(worst <= ph[i].tol);
        ef_sky_light_unref(k);
    }
    env_free(&e);
}

/* A random smooth environment with a few lobes: against the sum over
 * every texel of the map (exact solid angles, the phase at the texel
 * centres), z up. */
static void test_brute_force(void **state)
{
    (void) state;
    const double up_z[3] = { 0, 0, 1 };
    env e = env_make(128, 64);
    double lobe[4][3];
    for (int j = 0; j < 4; ++j)
        rand_dir(lobe[j]);
    for (int y = 0; y < e.h; ++y)
        for (int x = 0; x < e.w; ++x) {
            double d[3];
            map_dir(1, x + 0.5, y + 0.5, e.w, e.h, 0, d);
            double v = 0.2;
            for (int j = 0; j < 4; ++j)
                v += (j + 1) * exp(-(1 - (d[0] * lobe[j][0] + d[1] * lobe[j][1] +
                                          d[2] * lobe[j][2])) / 0.05);
            for (int c = 0; c < 3; ++c)
                e.p[c][(size_t) y * e.w + x] = (float) (v * (1 + 0.3 * c));
        }
    const double gs[3] = { 0.2, 0.6, 0.85 };
    for (int gi = 0; gi < 3; ++gi) {
        ef_sky_light *k = build(&e, EF_PHASE_HG, gs[gi], 0);
        double worst = 0, mean = 0;
        for (int t = 0; t < 100; ++t) {
            double u[3], C[3];
            rand_dir(u);
            ef_sky_light_eval(k, EF_PHASE_HG, gs[gi], up_z, u, C);
            double want = 0;
            for (int y = 0; y < e.h; ++y) {
                const double dom = (cos(PI * y / e.h) - cos(PI * (y + 1) / e.h)) * 2 * PI / e.w;
                for (int x = 0; x < e.w; ++x) {
                    double d[3];
                    map_dir(1, x + 0.5, y + 0.5, e.w, e.h, 0, d);
                    const double c = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
                    want += dom * ef_phase_eval(EF_PHASE_HG, gs[gi], c) *
                            e.p[0][(size_t) y * e.w + x];
                }
            }
            const double r = fabs(C[0] - want) / want;
            worst = fmax(worst, r);
            mean += r / 100;
        }
        print_message("HG g %.2f against the texel sum: mean %.2e, worst %.2e relative\n",
                      gs[gi], mean, worst);
        assert_true(worst < 3e-2 && mean < 1e-2);
        ef_sky_light_unref(k);
    }
    env_free(&e);
}

/* A bright spot at a known texel: C peaks towards it (g 0.9), in y-up and
 * z-up scenes, and rotate= turns it about up. */
static void test_orientation(void **state)
{
    (void) state;
    env e = env_make(256, 128);
    for (int c = 0; c < 3; ++c)
        for (int i = 0; i < e.w * e.h; ++i)
            e.p[c][i] = 0.01f;
    const int sx = 40, sy = 50;   /* the spot */
    for (int c = 0; c < 3; ++c)
        e.p[c][(size_t) sy * e.w + sx] = 1000.0f;
    const double ups[2][3] = { { 0, 1, 0 }, { 0, 0, 1 } };
    for (int upz = 0; upz < 2; ++upz)
        for (int r = 0; r < 2; ++r) {
            const double rot = r ? 70 : 0;
            ef_sky_light *k = build(&e, EF_PHASE_HG, 0.9, rot);
            double d[3], C[3], best = -1, bestdot = 0;
            map_dir(upz, sx + 0.5, sy + 0.5, e.w, e.h, rot, d);
            /* the brightest of 4000 random directions lies within a few
             * degrees of the spot */
            for (int t = 0; t < 4000; ++t) {
                double u[3];
                rand_dir(u);
                ef_sky_light_eval(k, EF_PHASE_HG, 0.9, ups[upz], u, C);
                if (C[0] > best) {
                    best = C[0];
                    bestdot = u[0] * d[0] + u[1] * d[1] + u[2] * d[2];
                }
            }
            ef_sky_light_eval(k, EF_PHASE_HG, 0.9, ups[upz], d, C);
            double away[3] = { -d[0], -d[1], -d[2] }, Ca[3];
            ef_sky_light_eval(k, EF_PHASE_HG, 0.9, ups[upz], away, Ca);
            assert_true(bestdot > cos(8 * PI / 180));
            assert_true(C[0] > 100 * Ca[0]);
            ef_sky_light_unref(k);
        }
    env_free(&e);
}

/* ---- through the CLI ---- */

static void write_env(const char *path, const env *e)
{
    tu_part p;
    tu_part_init(&p, e->w, e->h);
    tu_part_add(&p, "R", EXR_PIXEL_FLOAT, e->p[0]);
    tu_part_add(&p, "G", EXR_PIXEL_FLOAT, e->p[1]);
    tu_part_add(&p, "B", EXR_PIXEL_FLOAT, e->p[2]);
    assert_int_equal(tu_write_exr(path, &p, 1), 0);
}

static void test_cli(void **state)
{
    (void) state;
    char in[4096];
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    snprintf(in, sizeof in, "%s/samples/sample.exr", src ? src : ".");
    /* the dipole 1 + l.a (y up), so that C = 1 + g u.a exactly */
    const double a[3] = { 0.2, 0.6, -0.5 };
    const double k[3] = { 1, 2, 3 }, c0[3] = { 0, 0, 0 };
    env e = env_dipole(a, k, c0);
    char *envp = tu_path("sky_env.exr"), *out = tu_path("sky_out.exr");
    char *out2 = tu_path("sky_out2.exr");
    write_env(envp, &e);
    env_free(&e);
    const double g = 0.6, alb = 0.8, rho = 0.03;
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=%g:phase=hg:g=%g:albedo=%g "
                             "--sky-light '%s' --aov light,T,P -d float", in, out, rho, g, alb,
                             envp), 0);
    tu_image img;
    assert_int_equal(tu_read_image(out, 0, &img), 0);
    const char *names[3] = { "fog_light.sky.R", "fog_light.sky.G", "fog_light.sky.B" };
    const float *T = tu_image_f(&img, "fog_T.R"), *P[3] = { tu_image_f(&img, "fog_P.X"),
                                                            tu_image_f(&img, "fog_P.Y"),
                                                            tu_image_f(&img, "fog_P.Z") };
    int wa, ha;   /* the input's coverage: the output's alpha has the fog's added */
    float *A = tu_read_channel(in, 0, "A", &wa, &ha);
    assert_true(T && P[0] && P[1] && P[2] && A && wa == img.w && ha == img.h);
    long checked = 0;
    double worst = 0;
    for (int i = 0; i < img.w * img.h; ++i) {
        if (!isfinite(P[0][i]) || A[i] < 1)
            continue;
        /* the sample's camera is at (0, 1.7, 0) (make_sample) */
        double u[3] = { P[0][i], P[1][i] - 1.7, P[2][i] };
        const double n = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        for (int k = 0; k < 3; ++k)
            u[k] /= n;
        for (int c = 0; c < 3; ++c) {
            const double C = (c + 1) * (1 + g * (a[0] * u[0] + a[1] * u[1] + a[2] * u[2]));
            const double want = alb * C * (1 - T[i]);
            const double got = tu_image_f(&img, names[c])[i];
            if (want > 1e-3)
                worst = fmax(worst, fabs(got - want) / want);
        }
        ++checked;
    }
    print_message("sky light through the CLI: %ld surface pixels, worst relative %.2e\n",
                  checked, worst);
    assert_true(checked > img.w * img.h / 2);
    assert_true(worst < 3e-3);
    free(A);
    tu_image_free(&img);
    /* the same from a scene file */
    char *js = tu_path("sky_scene.json");
    FILE *f = fopen(js, "w");
    assert_non_null(f);
    fprintf(f, "{\"fog\": [\"exp:density=%g:phase=hg:g=%g:albedo=%g\"], \"sky_light\": \"%s\"}",
            rho, g, alb, envp);
    fclose(f);
    char *out3 = tu_path("sky_out3.exr");
    assert_int_equal(tu_runf("'%s' -o '%s' --scene '%s' --aov light -d float", in, out3, js), 0);
    float *x = NULL, *y = NULL;
    int w1, h1, w2, h2;
    x = tu_read_channel(out, 0, "fog_light.sky.G", &w1, &h1);
    y = tu_read_channel(out3, 0, "fog_light.sky.G", &w2, &h2);
    assert_true(x && y && w1 == w2 && h1 == h2);
    assert_memory_equal(x, y, (size_t) w1 * h1 * sizeof *x);
    free(x);
    free(y);
    /* Without lights or AOVs the sky light runs in the span path (its term
     * from the span's T); an AOV takes the per-pixel path checked above.
     * The same bits, alpha edges, kept sky and a sky shell included. */
    static const char *const skies[] = { "", "--sky keep", "--sky distance=500" };
    char *fast = tu_path("sky_fast.exr"), *slow = tu_path("sky_slow.exr");
    for (int m = 0; m < 3; ++m) {
        assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=%g:phase=hg:g=%g:albedo=%g "
                                 "--sky-light '%s' %s", in, fast, rho, g, alb, envp, skies[m]), 0);
        assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=%g:phase=hg:g=%g:albedo=%g "
                                 "--sky-light '%s' %s --aov T", in, slow, rho, g, alb, envp,
                                 skies[m]), 0);
        for (int c = 0; c < 4; ++c) {
            const char *ch = (const char *[]) { "R", "G", "B", "A" }[c];
            x = tu_read_channel(fast, 0, ch, &w1, &h1);
            y = tu_read_channel(slow, 0, ch, &w2, &h2);
            assert_true(x && y && w1 == w2 && h1 == h2);
            assert_memory_equal(x, y, (size_t) w1 * h1 * sizeof *x);
            free(x);
            free(y);
        }
    }
    free(fast);
    free(slow);
    /* errors: a missing map (exit 1, named), bad keys (exit 2), twice */
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 --sky-light /nonexistent/e.exr",
                             in, out2), 1);
    assert_non_null(strstr(tu_err, "/nonexistent/e.exr"));
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 --sky-light '%s':spin=3", in,
                             out2, envp), 2);
    assert_non_null(strstr(tu_err, "is not rotate=DEG, intensity=K, scattering=single|multiple or ground=H"));
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 --sky-light '%s' --sky-light "
                             "'%s'", in, out2, envp, envp), 2);
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 --sky-light '%s' --light "
                             "sun:towards=0,1,0:name=sky", in, out2, envp), 2);
    assert_false(tu_exists(out2));
    /* hostile environments: 1 x 1 is refused; NaN, inf and negative
     * texels count as 0 (nothing to scatter), never a NaN in the output */
    {
        env t = env_make(1, 1);
        char *tp = tu_path("sky_tiny.exr");
        write_env(tp, &t);
        env_free(&t);
        assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 --sky-light '%s'", in,
                                 out2, tp), 1);
        assert_non_null(strstr(tu_err, "too small"));
        env b = env_make(64, 32);
        for (int i = 0; i < 64 * 32; ++i)
            for (int c = 0; c < 3; ++c)
                b.p[c][i] = i % 7 == 0 ? NAN : i % 7 == 1 ? INFINITY : i % 7 == 2 ? -5.0f : 1.0f;
        write_env(tp, &b);
        env_free(&b);
        assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02:phase=hg:g=0.5 "
                                 "--sky-light '%s' -d float", in, out2, tp), 0);
        int w, h;
        float *R = tu_read_channel(out2, 0, "R", &w, &h);
        assert_non_null(R);
        for (int i = 0; i < w * h; ++i)
            assert_true(isfinite(R[i]) && R[i] >= 0);
        free(R);
        remove(out2);
        free(tp);
    }
    free(envp);
    free(out);
    free(out2);
    free(out3);
    free(js);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_known_transforms),
        cmocka_unit_test(test_brute_force),
        cmocka_unit_test(test_orientation),
        cmocka_unit_test(test_cli),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
