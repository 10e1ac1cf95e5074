/* A program outside the project using the installed libexrfog (built by
 * tests/scripts/install_check.sh through pkg-config and through find_package).
 * usage: use_exrfog SAMPLE.exr OUTDIR; exit 0 when every check holds. */
#include <exrfog.h>

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

static int failures;

static void check(int ok, const char *what)
{
    if (!ok) {
        fprintf(stderr, "use_exrfog: FAILED: %s\n", what);
        ++failures;
    }
}

static int cancel_first(void *user, double fraction)
{
    (void) fraction;
    ++*(int *) user;
    return 1;
}

int main(int argc, char **argv)
{
    if (argc != 3)
        return 2;
    exrfog_context *ctx = exrfog_context_create();
    check(!strcmp(exrfog_version(), EXRFOG_VERSION), "library version equals the header's");

    /* a scene, and a bad one with its message */
    exrfog_scene *scene = NULL, *bad = NULL;
    const char *specs[] = { "exp:density=0.1" };
    const double white[3] = { 1, 1, 1 };
    check(exrfog_scene_create(ctx, specs, 1, NULL, white, &scene) == EXRFOG_OK, "scene");
    const char *bogus[] = { "bogus:density=1" };
    check(exrfog_scene_create(ctx, bogus, 1, NULL, NULL, &bad) == EXRFOG_USAGE && !bad,
          "a bad SPEC is a usage error");
    check(strstr(exrfog_error(ctx), "bogus") != NULL, "the error names the bad model");

    /* 4x1 pixels of a 90-degree camera at the origin, depth 2, colour 0.5:
     * T = exp(-0.1 * 2 * sqrt(dx^2 + 1)), dx = 2 (x + 0.5) / 4 - 1 */
    const double c2w[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    const int win[4] = { 0, 0, 3, 0 };
    exrfog_camera *cam = NULL;
    check(exrfog_camera_from_matrix(ctx, c2w, "exr", 90.0, win, &cam) == EXRFOG_OK, "camera");
    float r[4], g[4], b[4], a[4], z[4], T[3][4];
    for (int i = 0; i < 4; ++i) {
        r[i] = g[i] = b[i] = 0.5f;
        a[i] = 1.0f;
        z[i] = 2.0f;
    }
    exrfog_image img;
    memset(&img, 0, sizeof img);
    img.size = sizeof img;
    img.width = 4;
    img.height = 1;
    img.stride = 4;
    img.rgb[0] = r;
    img.rgb[1] = g;
    img.rgb[2] = b;
    img.alpha = a;
    img.depth = z;
    for (int k = 0; k < 3; ++k)
        img.T[k] = T[k];
    check(cam && exrfog_fog_pixels(ctx, scene, cam, &img) == EXRFOG_OK, "fog_pixels");
    for (int i = 0; i < 4; ++i) {
        const double dx = 2.0 * (i + 0.5) / 4.0 - 1.0;
        const double t = exp(-0.1 * 2.0 * sqrt(dx * dx + 1.0));
        check(fabs(T[0][i] - t) < 1e-6, "fog_T by hand");
        check(fabs(r[i] - (t * 0.5 + (1 - t) * 1.0)) < 1e-6, "colour by hand");
    }

    /* the whole run, an error, and a cancelled run */
    char out[4096];
    snprintf(out, sizeof out, "%s/run.exr", argv[2]);
    const char *run[] = { "exrfog", argv[1], "-o", out, "--fog", "exp:density=0.02" };
    check(exrfog_run(ctx, 6, run) == EXRFOG_OK && access(out, F_OK) == 0, "exrfog_run");
    const char *missing[] = { "exrfog", "/no/such.exr", "-o", out, "--fog", "exp:density=0.02" };
    check(exrfog_run(ctx, 6, missing) == EXRFOG_ERROR, "a missing input fails");
    check(strstr(exrfog_error(ctx), "/no/such.exr") != NULL, "the error names the input");
    int calls = 0;
    snprintf(out, sizeof out, "%s/cancelled.exr", argv[2]);
    exrfog_set_progress(ctx, cancel_first, &calls);
    check(exrfog_run(ctx, 6, (const char *[]){ "exrfog", argv[1], "-o", out, "--fog",
                                               "exp:density=0.02" }) == EXRFOG_CANCELLED,
          "a cancelled run says so");
    check(calls >= 1 && access(out, F_OK) != 0, "the progress callback ran; nothing written");

    exrfog_camera_destroy(cam);
    exrfog_scene_destroy(scene);
    exrfog_context_destroy(ctx);
    if (!failures)
        printf("use_exrfog: all checks passed\n");
    return failures ? 1 : 0;
}
