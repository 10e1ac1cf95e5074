/* End to end: exrfog renders the sample scene (samples/sample.exr, camera in
 * its header) with each analytic model, and every 5th pixel of the output
 * is checked against an evaluation by the reference integrator:
 * T = exp(-sum of reference taus) to the surface and to infinity, then the
 * compositing formula written out here
 *   rgb' = T rgb + (1 - T) a F + (1 - a)(1 - Tinf) F,
 *   a'   = a + (1 - a) mean(1 - Tinf),
 * to float precision (the output is written as float with -d float). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "exr_io.h"
#include "ref.h"
#include "scene.h"
#include "tassert.h"
#include "testutil.h"

static const double F[3] = { 0.25, 0.5, 0.75 };

/* The allowed |d| per pixel: float precision for the closed forms and
 * method=exact; the method's stated accuracy otherwise (set per check). */
static double pixel_tol_rel = 1e-6, pixel_tol_abs = 1e-7;
/* Check every step-th pixel each way (5 for the closed forms). */
static int pixel_step = 5;

/* Renders sample.exr with the given --fog arguments and checks it. */
static void render_and_check(const char *name, const char *const *specs, int nspec)
{
    char sample[4096], args[8192] = "";
    snprintf(sample, sizeof sample, "%s/samples/sample.exr", getenv("EXRFOG_SOURCE_DIR"));
    char *out = tu_path(name);
    for (int i = 0; i < nspec; ++i) {
        strncat(args, " --fog '", sizeof args - strlen(args) - 1);
        strncat(args, specs[i], sizeof args - strlen(args) - 1);
        strncat(args, "'", sizeof args - strlen(args) - 1);
    }
    assert_run(0, "-d float --fog-color 0.25,0.5,0.75%s %s -o %s", args, sample, out);

    /* The camera as the library reads it (tested on its own in test_camera). */
    ef_exr_file in = { 0 };
    ef_err err;
    ef_channel_plan plan;
    ef_cam_meta meta;
    ef_cam_flags flags;
    ef_camera cam;
    ef_depth_conv conv;
    memset(&flags, 0, sizeof flags);
    assert_int_equal(ef_exr_open(sample, &in, &err), 0);
    assert_int_equal(ef_find_channels(&in, &in, NULL, NULL, &plan, &err), 0);
    assert_int_equal(ef_exr_read_cam_meta(&in, 0, &meta, &err), 0);
    assert_int_equal(ef_camera_resolve(&meta, &flags, &cam, &err), 0);
    assert_int_equal(ef_depth_conv_init(&conv, EF_DEPTH_PLANAR, &cam, &err), 0);

    ef_fog_component comp[8];
    for (int i = 0; i < nspec; ++i)
        assert_int_equal(ef_fog_parse(specs[i], NULL, &comp[i], &err), 0);

    tu_image a, b;
    assert_int_equal(tu_read_image(sample, 0, &a), 0);
    assert_int_equal(tu_read_image(out, 0, &b), 0);
    const float *cin[4] = { tu_image_f(&a, "R"), tu_image_f(&a, "G"), tu_image_f(&a, "B"),
                            tu_image_f(&a, "A") };
    const float *cout[4] = { tu_image_f(&b, "R"), tu_image_f(&b, "G"), tu_image_f(&b, "B"),
                             tu_image_f(&b, "A") };
    const float *Z = tu_image_f(&a, "Z");
    assert_non_null(Z);
    for (int k = 0; k < 4; ++k)
        assert_true(cin[k] && cout[k]);

    long bad = 0, checked = 0, fogged = 0, sky = 0;
    double worst = 0;
    for (int j = 0; j < a.h; j += pixel_step)
        for (int i = 0; i < a.w; i += pixel_step) {
            const size_t idx = (size_t) j * (size_t) a.w + (size_t) i;
            ef_ray r;
            const int is_sky = ef_reconstruct(&cam, &conv, a.dw[0] + i, a.dw[1] + j, Z[idx], &r);
            ef_ray rinf = r;
            rinf.dist = rinf.planar = INFINITY;
            long double tau[3] = { 0, 0, 0 }, tinf[3] = { 0, 0, 0 };
            for (int c = 0; c < nspec; ++c) {
                long double t[3], u[3];
                assert_int_equal(ef_ref_tau(&comp[c], &r, t, NULL), 0);
                assert_int_equal(ef_ref_tau(&comp[c], &rinf, u, NULL), 0);
                for (int k = 0; k < 3; ++k) {
                    tau[k] += t[k];
                    tinf[k] += u[k];
                }
            }
            const double al = cin[3][idx];
            double cover = 0;
            for (int k = 0; k < 3; ++k) {
                const double T = (double) expl(-tau[k]), Ti = (double) expl(-tinf[k]);
                const double want = (T > 0 ? T * cin[k][idx] : 0.0) + (1 - T) * al * F[k] +
                                    (1 - al) * (1 - Ti) * F[k];
                const double got = cout[k][idx], d = fabs(got - want);
                if (d > worst)
                    worst = d;
                if (!(d <= pixel_tol_rel * fabs(want) + pixel_tol_abs) && bad++ < 5)
                    printf("  %s pixel %d,%d ch %d: got %.9g want %.9g (tau %Lg)\n", name, i, j, k,
                           got, want, tau[k]);
                cover += (1 - Ti) / 3;
                fogged += k == 0 && T < 0.99;
            }
            const double wa = al + (1 - al) * cover;
            if (!(fabs(cout[3][idx] - wa) <= 10 * pixel_tol_abs + 1e-6) && bad++ < 5)
                printf("  %s pixel %d,%d alpha: got %.9g want %.9g\n", name, i, j, cout[3][idx], wa);
            checked++;
            sky += is_sky;
        }
    printf("  %-22s %ld pixels (%ld fogged, %ld sky), worst |d| %.3g\n", name, checked, fogged,
           sky, worst);
    /* The scene must actually show the model: fog on a good share of pixels. */
    assert_true(fogged > checked / 20);
    assert_int_equal(bad, 0);
    for (int i = 0; i < nspec; ++i)
        ef_fog_free(&comp[i]);
    tu_image_free(&a);
    tu_image_free(&b);
    ef_exr_close(&in);
    free(out);
}

#define CHECK(name, ...)                                                                     \
    do {                                                                                     \
        const char *const s_[] = { __VA_ARGS__ };                                            \
        render_and_check(name, s_, (int) (sizeof s_ / sizeof s_[0]));                        \
    } while (0)

static void test_halfspace_family(void **state)
{
    (void) state;
    CHECK("halfspace.exr", "halfspace:plane=0,1,0,-1.2:density=0.15");
    CHECK("halfspace_linear.exr", "halfspace-linear:plane=0,2,0,-6:slope=0.05,0.08,0.12");
    CHECK("halfspace_smooth.exr", "halfspace-smooth:plane=0,1,0,-2:density=0.2:sharpness=0.5");
}

static void test_height_layered(void **state)
{
    (void) state;
    CHECK("height.exr", "height:density=0.08:falloff=0.3:base=0");
    CHECK("layered.exr", "layered:heights=0,2,6:densities=0.2,0.05/0.06/0.08,0");
}

static void test_volumes(void **state)
{
    (void) state;
    CHECK("box.exr", "box:min=-3,0,-12:max=3,2.5,-4:density=0.4");
    CHECK("convex.exr",
          /* The octahedron |x-5|+|y-3|+|z+30| < 8 in front of the camera. */
          "convex:planes=1,1,1,14,-1,1,1,24,1,-1,1,20,-1,-1,1,30,1,1,-1,-46,-1,1,-1,-36,"
          "1,-1,-1,-40,-1,-1,-1,-30:density=0.1");
}

static void test_combined(void **state)
{
    (void) state;
    CHECK("combined.exr", "halfspace:plane=0,1,0,-1:density=0.05",
          "height:density=0.02:falloff=0.1:base=0:up=0,1,0", "box:min=-3,0,-12:max=3,2.5,-4:density=0.2",
          "layered:heights=1,4:densities=0.03,0");
}

/* Noise fog, every method, on the sample scene against the reference
 * (without a height envelope: sky rays are then opaque for every method and
 * for the reference, which keeps this test short; envelopes and sky rays
 * are checked segment by segment in test_fog_noise). method=exact holds the
 * closed forms' float-level check; adaptive at tol 1e-4 may move T by
 * 1e-4 relative (|d| <= 1e-4 (|rgb| + F), values here <= ~1); steps=1024
 * and preintegrated pieces=16 are held to what they reach on this scene. */
static void test_noise(void **state)
{
    (void) state;
    pixel_step = 9;
    CHECK("noise_exact.exr", "noise:density=0.03:scale=10:octaves=5:seed=3:method=exact");
    CHECK("noise_sep_exact.exr",
          "noise-separable:density=0.03:scale=10:axes=xyz:contrast=0.8:method=exact");
    pixel_tol_rel = 2e-4;
    pixel_tol_abs = 2e-4;
    CHECK("noise_adaptive.exr", "noise:density=0.03:scale=10:octaves=5:seed=3:tol=1e-4");
    CHECK("noise_steps.exr", "noise:density=0.03:scale=10:method=steps:steps=1024");
    pixel_tol_rel = 5e-3;
    pixel_tol_abs = 5e-3;
    CHECK("noise_preint.exr", "noise-separable:density=0.03:scale=10:method=preintegrated:pieces=16");
    pixel_tol_rel = 1e-6;
    pixel_tol_abs = 1e-7;
    pixel_step = 5;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_noise),
        cmocka_unit_test(test_halfspace_family),
        cmocka_unit_test(test_height_layered),
        cmocka_unit_test(test_volumes),
        cmocka_unit_test(test_combined),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
