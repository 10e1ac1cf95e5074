/* I/O round trips: small EXRs written here with known pixels and a known
 * camera go through the exrfog binary (or ef_exr_stream directly) and the
 * result is read back and checked channel by channel.
 *
 * Every expected value is computed here from the test's own pinhole model:
 * pixel (x, y) of a display window W x H has NDC u = (x + 0.5 - disp.xmin) / W,
 * v = (y + 0.5 - disp.ymin) / H; the camera-space ray is
 * ((u - cu) / a, -(v - cv) / b, 1) for the NDC matrix u = a X/Z + cu,
 * v = -b Y/Z + cv; the radial distance is planar Z times its length; with
 * exp fog of density rho, T = exp(-rho d), Tinf = 0, and
 *   out = T in + (1 - T) alpha F + (1 - alpha) F,  alpha_out = 1. */
#include <dirent.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "tassert.h"

#include "exr_io.h"
#include "testutil.h"

#define PI 3.14159265358979323846

/* ------------------------------------------------------------------ */
/* Small helpers                                                       */

static uint32_t rng_state = 2463534242u;

static void rng_seed(uint32_t s)
{
    rng_state = s ? s : 1u;
}

static uint32_t rnd_u32(void)
{
    return tu_xorshift32(&rng_state);
}

static double rnd01(void)
{
    return tu_rand01(&rng_state);
}





static void read_image(const char *path, int part, tu_image *img)
{
    if (tu_read_image(path, part, img)) {
        print_error("cannot read part %d of %s\n", part, path);
        fail();
    }
}

/* No leftovers of a failed run: neither the output nor its hidden temp. */
static void assert_no_output(const char *out)
{
    assert_false(tu_exists(out));
    const char *slash = strrchr(out, '/');
    char dir[1024], prefix[512];
    snprintf(dir, sizeof dir, "%.*s", (int) (slash - out), out);
    snprintf(prefix, sizeof prefix, ".%s.exrfog-", slash + 1);
    DIR *d = opendir(dir);
    assert_non_null(d);
    struct dirent *e;
    while ((e = readdir(d)))
        if (!strncmp(e->d_name, prefix, strlen(prefix))) {
            print_error("temporary file %s left behind\n", e->d_name);
            closedir(d);
            fail();
        }
    closedir(d);
}

/* ------------------------------------------------------------------ */
/* The test camera                                                     */

typedef struct cam {
    tu_pinhole pin;           /* NDC: u = a X/Z + cu, v = -b Y/Z + cv */
    float w2c[16], w2ndc[16];
    double hfov;
} cam;

/* A camera at (2, -1, 12), turned 30 degrees about world Y and tilted 10
 * degrees, horizontal fov hfov over the display window, NDC centre moved by
 * (su, sv) (lens shift). Matrices are row-vector (Imath) and float. */
static void cam_make(cam *c, const int disp[4], double hfov, double su, double sv)
{
    tu_pinhole_fov(&c->pin, disp, hfov);
    c->pin.cu += su;
    c->pin.cv += sv;
    c->hfov = hfov;
    /* Camera axes in world (rows): yaw 30 about Y, then pitch 10 about X. */
    const double yw = 30.0 * PI / 180.0, pt = 10.0 * PI / 180.0;
    const double ex[3] = { cos(yw), 0.0, -sin(yw) };
    const double ey0[3] = { 0.0, 1.0, 0.0 }, ez0[3] = { sin(yw), 0.0, cos(yw) };
    double ey[3], ez[3];
    for (int k = 0; k < 3; ++k) {
        ey[k] = cos(pt) * ey0[k] - sin(pt) * ez0[k];
        ez[k] = sin(pt) * ey0[k] + cos(pt) * ez0[k];
    }
    const double C[3] = { 2.0, -1.0, 12.0 };
    const double *e[3] = { ex, ey, ez };
    double w2c[16] = { 0 };
    for (int j = 0; j < 3; ++j) {
        for (int i = 0; i < 3; ++i)
            w2c[4 * i + j] = e[j][i];
        w2c[12 + j] = -(C[0] * e[j][0] + C[1] * e[j][1] + C[2] * e[j][2]);
    }
    w2c[15] = 1.0;
    /* camera -> NDC, D3D-style depth with near 0.1, far 1000. */
    const double n = 0.1, f = 1000.0;
    const tu_pinhole *q = &c->pin;
    const double P[16] = { q->a, 0, 0, 0,  0, -q->b, 0, 0,  q->cu, q->cv, f / (f - n), 1,
                           0, 0, -f * n / (f - n), 0 };
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double s = 0;
            for (int k = 0; k < 4; ++k)
                s += w2c[4 * i + k] * P[4 * k + j];
            c->w2ndc[4 * i + j] = (float) s;
            c->w2c[4 * i + j] = (float) w2c[4 * i + j];
        }
}

/* The camera in the header of p (worldToCamera + a true-NDC worldToNDC). */
static void cam_attach(const cam *c, tu_part *p)
{
    p->m44[0].name = "worldToCamera";
    memcpy(p->m44[0].m, c->w2c, sizeof c->w2c);
    p->m44[1].name = "worldToNDC";
    memcpy(p->m44[1].m, c->w2ndc, sizeof c->w2ndc);
}

/* The same camera as command-line flags (only for cameras without shift). */
static void cam_flags(const cam *c, char *buf, size_t len)
{
    int n = snprintf(buf, len, "--world-to-camera ");
    for (int i = 0; i < 16; ++i)
        n += snprintf(buf + n, len - (size_t) n, "%s%.9g", i ? "," : "", (double) c->w2c[i]);
    snprintf(buf + n, len - (size_t) n, " --fov %.17g", c->hfov);
}

/* ------------------------------------------------------------------ */
/* Test images                                                         */

/* Colour, depth and AOVs over a data window. */
typedef struct scene {
    int dw[4], disp[4], w, h;
    float *R, *G, *B, *A, *Z, *NX, *NY, *NZ, *spec;
    uint32_t *id;
} scene;

static float *fplane(const scene *s)
{
    float *p = malloc(sizeof(float) * (size_t) s->w * (size_t) s->h);
    assert_non_null(p);
    return p;
}

/* Deterministic pseudo-random pixels. About one pixel in 11 is sky (Z = 0,
 * 1e30 or +inf); alpha covers 0, 1 and values between. */
static void scene_make(scene *s, const int dw[4], const int disp[4], uint32_t seed)
{
    memset(s, 0, sizeof *s);
    memcpy(s->dw, dw, sizeof s->dw);
    memcpy(s->disp, disp, sizeof s->disp);
    s->w = dw[2] - dw[0] + 1;
    s->h = dw[3] - dw[1] + 1;
    s->R = fplane(s); s->G = fplane(s); s->B = fplane(s); s->A = fplane(s); s->Z = fplane(s);
    s->NX = fplane(s); s->NY = fplane(s); s->NZ = fplane(s); s->spec = fplane(s);
    s->id = malloc(sizeof(uint32_t) * (size_t) s->w * (size_t) s->h);
    assert_non_null(s->id);
    rng_seed(seed);
    for (int i = 0; i < s->w * s->h; ++i) {
        double a = rnd01();
        a = a < 0.15 ? 0.0 : a > 0.8 ? 1.0 : a;
        s->A[i] = (float) a;
        s->R[i] = (float) (a * 2.0 * rnd01());
        s->G[i] = (float) (a * 2.0 * rnd01());
        s->B[i] = (float) (a * 2.0 * rnd01());
        s->Z[i] = (float) (0.5 + 60.0 * rnd01());
        const uint32_t k = rnd_u32() % 33u;
        if (k == 0)
            s->Z[i] = 0.0f;
        else if (k == 1)
            s->Z[i] = 1e30f;
        else if (k == 2)
            s->Z[i] = INFINITY;
        s->NX[i] = (float) (2.0 * rnd01() - 1.0);
        s->NY[i] = (float) (2.0 * rnd01() - 1.0);
        s->NZ[i] = (float) (2.0 * rnd01() - 1.0);
        s->spec[i] = (float) (4.0 * rnd01());
        s->id[i] = 16777217u + rnd_u32() % 4000000000u;   /* > 2^24 */
    }
}

static void scene_free(scene *s)
{
    free(s->R); free(s->G); free(s->B); free(s->A); free(s->Z);
    free(s->NX); free(s->NY); free(s->NZ); free(s->spec); free(s->id);
}

static void part_geometry(tu_part *p, const scene *s)
{
    tu_part_init(p, 1, 1);
    memcpy(p->dw, s->dw, sizeof p->dw);
    memcpy(p->disp, s->disp, sizeof p->disp);
}

/* A single part with R,G,B,A (ct), Z (zt) and the AOVs N.X/N.Y/N.Z (float),
 * id (uint), spec.R (half). */
static void scene_part(tu_part *p, const scene *s, exr_pixel_type_t ct, exr_pixel_type_t zt)
{
    part_geometry(p, s);
    tu_part_add(p, "R", ct, s->R);
    tu_part_add(p, "G", ct, s->G);
    tu_part_add(p, "B", ct, s->B);
    tu_part_add(p, "A", ct, s->A);
    tu_part_add(p, "Z", zt, s->Z);
    tu_part_add(p, "N.X", EXR_PIXEL_FLOAT, s->NX);
    tu_part_add(p, "N.Y", EXR_PIXEL_FLOAT, s->NY);
    tu_part_add(p, "N.Z", EXR_PIXEL_FLOAT, s->NZ);
    tu_part_add_uint(p, "id", s->id);
    tu_part_add(p, "spec.R", EXR_PIXEL_HALF, s->spec);
}

static void write_exr(const char *path, const tu_part *parts, int n)
{
    int rv = tu_write_exr(path, parts, n);
    if (rv) {
        print_error("tu_write_exr(%s) failed: %s\n", path, exr_get_error_code_as_string(rv));
        fail();
    }
}

/* ------------------------------------------------------------------ */
/* Checks                                                              */

/* Same channel names, order, windows; types as given (see tu_compare_layout). */
static void check_channels(const tu_image *in, const tu_image *out, int pixel_type)
{
    assert_int_equal(tu_compare_layout(in, out, pixel_type), 0);
}

static void check_same(const tu_image *in, const tu_image *out, const char *name, double rel,
                       int as_half)
{
    assert_int_equal(tu_compare_channel(in, out, name, rel, as_half), 0);
}

/* Every part and channel of in comes back in out, bit-exact, except the
 * listed channels of part skip_part. */
static void check_files(const char *in, const char *out, int skip_part, const char *const *skip)
{
    assert_int_equal(tu_compare_files(in, out, skip_part, skip), 0);
}

static const char *const RGBA[] = { "R", "G", "B", "A", NULL };

typedef tu_fog_check fog_check;

static void check_fog(fog_check *fc)
{
    assert_int_equal(tu_check_fog(fc), 0);
    /* The test images must exercise fogged surfaces. */
    assert_true(fc->fogged > 0);
}

static void fog_check_init(fog_check *fc, const char *in, const char *out, const cam *c)
{
    tu_fog_check_init(fc, in, out, &c->pin, 0.05);
}

#define FOG "--fog exp:density=0.05 --fog-color 0.25,0.5,0.75"

/* ------------------------------------------------------------------ */
/* Compression                                                         */

static const char *const comp_names[] = { "none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a" };
static const exr_compression_t comp_ids[] = {
    EXR_COMPRESSION_NONE, EXR_COMPRESSION_RLE, EXR_COMPRESSION_ZIPS, EXR_COMPRESSION_ZIP,
    EXR_COMPRESSION_PIZ, EXR_COMPRESSION_PXR24, EXR_COMPRESSION_B44, EXR_COMPRESSION_B44A,
};

/* Checks one round trip of the standard scene part; comp is the output's
 * compression (lossy ones get slack on the channel types they alter). */
static void check_scene_roundtrip(const char *in_path, const char *out_path, const cam *c,
                                  exr_compression_t comp)
{
    tu_image a, b;
    read_image(in_path, 0, &a);
    read_image(out_path, 0, &b);
    check_channels(&a, &b, -1);
    assert_int_equal(b.comp, comp);
    const int pxr = comp == EXR_COMPRESSION_PXR24;
    const int b44 = comp == EXR_COMPRESSION_B44 || comp == EXR_COMPRESSION_B44A;
    static const char *const aovs[] = { "Z", "N.X", "N.Y", "N.Z", "id", "spec.R" };
    for (size_t i = 0; i < sizeof aovs / sizeof aovs[0]; ++i) {
        const exr_pixel_type_t t = a.type[tu_image_find(&a, aovs[i])];
        double rel = 0.0;
        if (pxr && t == EXR_PIXEL_FLOAT)
            rel = 4e-5;                     /* 24-bit floats */
        if (b44 && t == EXR_PIXEL_HALF)
            rel = 0.3;                      /* B44 is lossy (coarsely) on half only */
        check_same(&a, &b, aovs[i], rel, 0);
    }
    const exr_pixel_type_t ct = a.type[tu_image_find(&a, "R")];
    tu_image_free(&a);
    tu_image_free(&b);
    fog_check fc;
    fog_check_init(&fc, in_path, out_path, c);
    if (pxr && ct == EXR_PIXEL_FLOAT)
        fc.extra_rel = 4e-5;
    if (b44 && ct == EXR_PIXEL_HALF) {
        /* B44 quantises 4x4 blocks of noisy data coarsely: only a sanity bound. */
        fc.extra_rel = 0.3;
        fc.extra_abs = 0.3;
    }
    check_fog(&fc);
}

static void test_compression_output(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 60, 46 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 101);
    cam_make(&c, dw, 90.0, 0.0, 0.0);
    scene_part(&p, &s, EXR_PIXEL_FLOAT, EXR_PIXEL_FLOAT);
    cam_attach(&c, &p);
    char *in = tu_path("io_comp_out_in.exr");
    write_exr(in, &p, 1);
    for (size_t i = 0; i < sizeof comp_names / sizeof comp_names[0]; ++i) {
        char name[64];
        snprintf(name, sizeof name, "io_comp_out_%s.exr", comp_names[i]);
        char *out = tu_path(name);
        print_message("--compression %s\n", comp_names[i]);
        assert_run(0, "'%s' -o '%s' " FOG " --compression %s --threads 3", in, out, comp_names[i]);
        check_scene_roundtrip(in, out, &c, comp_ids[i]);
        free(out);
    }
    free(in);
    scene_free(&s);
}

static void test_compression_input(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 52, 70 };
    scene s;
    cam c;
    scene_make(&s, dw, dw, 202);
    cam_make(&c, dw, 70.0, 0.0, 0.0);
    for (size_t i = 0; i < sizeof comp_names / sizeof comp_names[0]; ++i) {
        tu_part p;
        scene_part(&p, &s, EXR_PIXEL_HALF, EXR_PIXEL_FLOAT);
        cam_attach(&c, &p);
        p.comp = comp_ids[i];
        char name[64];
        snprintf(name, sizeof name, "io_comp_in_%s.exr", comp_names[i]);
        char *in = tu_path(name);
        snprintf(name, sizeof name, "io_comp_in_%s.out.exr", comp_names[i]);
        char *out = tu_path(name);
        write_exr(in, &p, 1);
        print_message("input compression %s\n", comp_names[i]);
        assert_run(0, "'%s' -o '%s' " FOG, in, out);
        check_scene_roundtrip(in, out, &c, comp_ids[i]);
        /* and into another compression (other chunk heights: 1, 16, 32) */
        const size_t o = (i + 3) % (sizeof comp_names / sizeof comp_names[0]);
        print_message("input compression %s -> %s\n", comp_names[i], comp_names[o]);
        assert_run(0, "'%s' -o '%s' " FOG " --compression %s", in, out, comp_names[o]);
        check_scene_roundtrip(in, out, &c, comp_ids[o]);
        free(in);
        free(out);
    }
    scene_free(&s);
}

/* ------------------------------------------------------------------ */
/* Tiles                                                               */

static void test_tiled(void **state)
{
    (void) state;
    /* tile sizes: dividing the image, not dividing it, larger than it;
     * the last with an overscan window and PIZ. */
    static const struct { int tile, tile_h; int dw[4]; exr_compression_t comp; } cases[] = {
        { 16, 0, { 0, 0, 63, 47 }, EXR_COMPRESSION_ZIP },
        { 7, 0, { 0, 0, 63, 47 }, EXR_COMPRESSION_ZIP },
        { 13, 0, { 0, 0, 63, 47 }, EXR_COMPRESSION_NONE },
        { 100, 0, { 0, 0, 63, 47 }, EXR_COMPRESSION_RLE },
        { 9, 0, { -5, -3, 68, 50 }, EXR_COMPRESSION_PIZ },
        { 20, 3, { 0, 0, 63, 47 }, EXR_COMPRESSION_ZIPS },   /* not square */
        { 5, 11, { 2, 4, 60, 44 }, EXR_COMPRESSION_ZIP },
    };
    const int disp[4] = { 0, 0, 63, 47 };
    cam c;
    cam_make(&c, disp, 80.0, 0.02, -0.03);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        scene s;
        tu_part p;
        scene_make(&s, cases[i].dw, disp, 400 + (uint32_t) i);
        scene_part(&p, &s, i % 2 ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT, EXR_PIXEL_FLOAT);
        cam_attach(&c, &p);
        p.tile = cases[i].tile;
        p.tile_h = cases[i].tile_h;
        p.comp = cases[i].comp;
        const int th = cases[i].tile_h ? cases[i].tile_h : cases[i].tile;
        char name[64];
        snprintf(name, sizeof name, "io_tiled_%dx%d.exr", cases[i].tile, th);
        char *in = tu_path(name);
        snprintf(name, sizeof name, "io_tiled_%dx%d.out.exr", cases[i].tile, th);
        char *out = tu_path(name);
        write_exr(in, &p, 1);
        print_message("tile %dx%d\n", cases[i].tile, th);
        assert_run(0, "'%s' -o '%s' " FOG " --threads 4", in, out);
        tu_image b;
        read_image(out, 0, &b);
        assert_true(b.tiled);
        assert_int_equal(b.tile_x, cases[i].tile);
        assert_int_equal(b.tile_y, th);
        tu_image_free(&b);
        check_scene_roundtrip(in, out, &c, cases[i].comp);
        free(in);
        free(out);
        scene_free(&s);
    }
}

/* Degenerate sizes: one pixel, one row, one column; scanline and tiled. */
static void test_tiny_images(void **state)
{
    (void) state;
    static const struct { int dw[4]; int tile; } cases[] = {
        { { 0, 0, 0, 0 }, 0 },   { { 0, 0, 0, 0 }, 4 },   { { 3, 2, 40, 2 }, 0 },
        { { 3, 2, 40, 2 }, 16 }, { { 7, -5, 7, 30 }, 0 }, { { 7, -5, 7, 30 }, 8 },
    };
    const int disp[4] = { 0, 0, 47, 31 };
    cam c;
    cam_make(&c, disp, 90.0, 0.0, 0.0);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        scene s;
        tu_part p;
        scene_make(&s, cases[i].dw, disp, 1500 + (uint32_t) i);
        for (int k = 0; k < s.w * s.h; ++k)
            s.Z[k] = 10.0f + (float) k;      /* no sky: every pixel must fog */
        scene_part(&p, &s, EXR_PIXEL_FLOAT, EXR_PIXEL_FLOAT);
        cam_attach(&c, &p);
        p.tile = cases[i].tile;
        char name[64];
        snprintf(name, sizeof name, "io_tiny_%zu.exr", i);
        char *in = tu_path(name);
        snprintf(name, sizeof name, "io_tiny_%zu.out.exr", i);
        char *out = tu_path(name);
        write_exr(in, &p, 1);
        print_message("%dx%d at (%d,%d), tile %d\n", s.w, s.h, s.dw[0], s.dw[1], p.tile);
        assert_run(0, "'%s' -o '%s' " FOG " --threads 4", in, out);
        check_scene_roundtrip(in, out, &c, EXR_COMPRESSION_ZIP);
        free(in);
        free(out);
        scene_free(&s);
    }
}

/* ------------------------------------------------------------------ */
/* Multi-part                                                          */

static void test_multipart_nuke(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 47, 35 };
    scene s;
    cam c;
    scene_make(&s, dw, dw, 505);
    cam_make(&c, dw, 75.0, 0.0, 0.0);
    tu_part parts[3];
    /* An AOV part first, then the colour, then depth (Nuke names and views). */
    part_geometry(&parts[0], &s);
    parts[0].name = "aov.main";
    tu_part_add(&parts[0], "N.X", EXR_PIXEL_FLOAT, s.NX);
    tu_part_add(&parts[0], "N.Y", EXR_PIXEL_FLOAT, s.NY);
    tu_part_add(&parts[0], "N.Z", EXR_PIXEL_FLOAT, s.NZ);   /* a look-alike of Z */
    tu_part_add_uint(&parts[0], "id", s.id);
    parts[0].str_name = "view";
    parts[0].str_value = "main";
    part_geometry(&parts[1], &s);
    parts[1].name = "rgba.main";
    tu_part_add(&parts[1], "R", EXR_PIXEL_HALF, s.R);
    tu_part_add(&parts[1], "G", EXR_PIXEL_HALF, s.G);
    tu_part_add(&parts[1], "B", EXR_PIXEL_HALF, s.B);
    tu_part_add(&parts[1], "A", EXR_PIXEL_HALF, s.A);
    parts[1].str_name = "view";
    parts[1].str_value = "main";
    cam_attach(&c, &parts[1]);
    part_geometry(&parts[2], &s);
    parts[2].name = "depth.main";
    tu_part_add(&parts[2], "Z", EXR_PIXEL_FLOAT, s.Z);
    parts[2].str_name = "view";
    parts[2].str_value = "main";
    parts[2].comp = EXR_COMPRESSION_PIZ;
    char *in = tu_path("io_nuke_mp.exr"), *out = tu_path("io_nuke_mp.out.exr");
    write_exr(in, parts, 3);

    assert_run(0, "--explain '%s'", in);
    assert_contains(tu_out, "depth: depth.Z (part 2)");
    assert_contains(tu_out, "colour: rgba.R, rgba.G, rgba.B, alpha rgba.A (part 1)");

    assert_run(0, "'%s' -o '%s' " FOG " --threads 2", in, out);
    check_files(in, out, 1, RGBA);
    for (int p = 0; p < 3; ++p) {
        exr_context_t f;
        exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
        const char *v = NULL;
        int32_t vl = 0;
        assert_int_equal(exr_start_read(&f, out, &init), EXR_ERR_SUCCESS);
        assert_int_equal(exr_attr_get_string(f, p, "view", &vl, &v), EXR_ERR_SUCCESS);
        assert_int_equal(vl, 4);
        assert_memory_equal(v, "main", 4);
        exr_finish(&f);
    }
    fog_check fc;
    fog_check_init(&fc, in, out, &c);
    fc.in_part = fc.out_part = 1;
    fc.depth = in;
    fc.depth_part = 2;
    check_fog(&fc);

    /* Changing compression and pixel type applies to every part (and the
     * chunk tables follow: 1-line NONE chunks instead of 16/32-line ones). */
    assert_run(0, "'%s' -o '%s' " FOG " --compression none -d float", in, out);
    assert_int_equal(tu_nparts(out), 3);
    for (int p = 0; p < 3; ++p) {
        tu_image a, b;
        read_image(in, p, &a);
        read_image(out, p, &b);
        assert_string_equal(a.name, b.name);
        check_channels(&a, &b, EXR_PIXEL_FLOAT);
        assert_int_equal(b.comp, EXR_COMPRESSION_NONE);
        for (int k = 0; p != 1 && k < a.nch; ++k)
            check_same(&a, &b, a.ch[k], 0.0, 0);
        tu_image_free(&a);
        tu_image_free(&b);
    }
    check_fog(&fc);
    free(in);
    free(out);
    scene_free(&s);
}

/* ------------------------------------------------------------------ */
/* Data windows                                                        */

static void window_case(const char *tag, const int dw[4], const int disp[4], int flags,
                        int tile)
{
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, disp, 600 + (uint32_t) dw[0] * 7u + (uint32_t) disp[1]);
    cam_make(&c, disp, 90.0, flags ? 0.0 : 0.04, flags ? 0.0 : 0.025);
    scene_part(&p, &s, EXR_PIXEL_FLOAT, EXR_PIXEL_FLOAT);
    if (!flags)
        cam_attach(&c, &p);
    p.tile = tile;
    char name[80];
    snprintf(name, sizeof name, "io_window_%s.exr", tag);
    char *in = tu_path(name);
    snprintf(name, sizeof name, "io_window_%s.out.exr", tag);
    char *out = tu_path(name);
    write_exr(in, &p, 1);
    char cf[1024] = "";
    if (flags)
        cam_flags(&c, cf, sizeof cf);
    print_message("window %s: dw (%d,%d)-(%d,%d) disp (%d,%d)-(%d,%d)\n", tag, dw[0], dw[1],
                  dw[2], dw[3], disp[0], disp[1], disp[2], disp[3]);
    assert_run(0, "'%s' -o '%s' " FOG " %s --threads 3", in, out, cf);
    check_scene_roundtrip(in, out, &c, EXR_COMPRESSION_ZIP);
    free(in);
    free(out);
    scene_free(&s);
}

static void test_window_crop(void **state)
{
    (void) state;
    const int dw[4] = { 10, 5, 50, 30 }, disp[4] = { 0, 0, 63, 39 };
    window_case("crop", dw, disp, 0, 0);
    window_case("crop_flags", dw, disp, 1, 0);
    window_case("crop_tiled", dw, disp, 0, 8);
}

static void test_window_overscan(void **state)
{
    (void) state;
    const int dw[4] = { -12, -7, 75, 46 }, disp[4] = { 0, 0, 63, 39 };
    window_case("overscan", dw, disp, 0, 0);
    window_case("overscan_flags", dw, disp, 1, 0);
}

/* A display window that does not start at the origin. */
static void test_window_display_offset(void **state)
{
    (void) state;
    const int dw[4] = { 95, 40, 170, 95 }, disp[4] = { 100, 50, 163, 89 };
    window_case("dispoff", dw, disp, 0, 0);
    window_case("dispoff_flags", dw, disp, 1, 11);
}

/* ------------------------------------------------------------------ */
/* Metadata                                                            */

static const exr_attribute_t *get_attr(exr_context_t f, int part, const char *name)
{
    const exr_attribute_t *a = NULL;
    if (exr_get_attribute_by_name(f, part, name, &a) != EXR_ERR_SUCCESS) {
        print_error("attribute %s missing\n", name);
        fail();
    }
    return a;
}

static void test_metadata_passthrough(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 31, 23 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 707);
    cam_make(&c, dw, 65.0, 0.0, 0.0);
    scene_part(&p, &s, EXR_PIXEL_HALF, EXR_PIXEL_FLOAT);
    cam_attach(&c, &p);
    const float mine[16] = { 1.5f, -2, 3, 0, 0.25f, 5, 6, 0, 7, 8, 9.75f, 0, 10, 11, 12, 1 };
    p.m44[2].name = "myStudio/matrix";
    memcpy(p.m44[2].m, mine, sizeof mine);
    p.f[0].name = "CameraFov";          /* ignored: the NDC matrix wins */
    p.f[0].v = 65.0f;
    p.f[1].name = "myStudio/exposure";
    p.f[1].v = -1.625f;
    p.f[2].name = "arnold/camera/near_clip";
    p.f[2].v = 0.125f;
    p.str_name = "comments";
    p.str_value = "shot 042, take 3";
    char *in = tu_path("io_meta.exr"), *out = tu_path("io_meta.out.exr");
    write_exr(in, &p, 1);
    assert_run(0, "'%s' -o '%s' " FOG " --threads 1", in, out);

    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    assert_int_equal(exr_start_read(&f, out, &init), EXR_ERR_SUCCESS);
    const exr_attribute_t *a;
    a = get_attr(f, 0, "worldToCamera");
    assert_int_equal(a->type, EXR_ATTR_M44F);
    assert_memory_equal(a->m44f->m, c.w2c, sizeof c.w2c);
    a = get_attr(f, 0, "worldToNDC");
    assert_int_equal(a->type, EXR_ATTR_M44F);
    assert_memory_equal(a->m44f->m, c.w2ndc, sizeof c.w2ndc);
    a = get_attr(f, 0, "myStudio/matrix");
    assert_int_equal(a->type, EXR_ATTR_M44F);
    assert_memory_equal(a->m44f->m, mine, sizeof mine);
    a = get_attr(f, 0, "CameraFov");
    assert_int_equal(a->type, EXR_ATTR_FLOAT);
    assert_true(a->f == 65.0f);
    a = get_attr(f, 0, "myStudio/exposure");
    assert_int_equal(a->type, EXR_ATTR_FLOAT);
    assert_true(a->f == -1.625f);
    a = get_attr(f, 0, "arnold/camera/near_clip");
    assert_int_equal(a->type, EXR_ATTR_FLOAT);
    assert_true(a->f == 0.125f);
    a = get_attr(f, 0, "comments");
    assert_int_equal(a->type, EXR_ATTR_STRING);
    assert_int_equal(a->string->length, (int) strlen("shot 042, take 3"));
    assert_memory_equal(a->string->str, "shot 042, take 3", strlen("shot 042, take 3"));
    a = get_attr(f, 0, "exrfog/parameters");
    assert_int_equal(a->type, EXR_ATTR_STRING);
    char params[4096];
    snprintf(params, sizeof params, "%.*s", a->string->length, a->string->str);
    print_message("exrfog/parameters: %s\n", params);
    assert_contains(params, "--fog exp:density=0.05");
    assert_contains(params, "--fog-color 0.25,0.5,0.75");
    /* Options that cannot change the file stay out, so equal outputs are equal bytes. */
    assert_null(strstr(params, "--threads"));
    exr_finish(&f);
    check_scene_roundtrip(in, out, &c, EXR_COMPRESSION_ZIP);

    /* Fogging the result again records the new parameters, not the old. */
    char *out2 = tu_path("io_meta.out2.exr");
    assert_run(0, "'%s' -o '%s' --fog exp2:density=0.01", out, out2);
    assert_int_equal(exr_start_read(&f, out2, &init), EXR_ERR_SUCCESS);
    a = get_attr(f, 0, "exrfog/parameters");
    snprintf(params, sizeof params, "%.*s", a->string->length, a->string->str);
    assert_contains(params, "--fog exp2:density=0.01");
    assert_null(strstr(params, "exp:density=0.05"));
    a = get_attr(f, 0, "myStudio/matrix");
    assert_memory_equal(a->m44f->m, mine, sizeof mine);
    exr_finish(&f);
    free(out2);
    free(in);
    free(out);
    scene_free(&s);
}

/* ------------------------------------------------------------------ */
/* Output pixel types                                                  */

static void test_data_type(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 40, 33 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 808);
    cam_make(&c, dw, 85.0, 0.0, 0.0);
    /* half colour, float Z; AOVs float, uint and half. */
    scene_part(&p, &s, EXR_PIXEL_HALF, EXR_PIXEL_FLOAT);
    cam_attach(&c, &p);
    char *in = tu_path("io_dtype.exr");
    write_exr(in, &p, 1);
    static const struct { const char *flag, *file; int type; } cases[] = {
        { "", "io_dtype_keep.exr", -1 },
        { "-d float", "io_dtype_float.exr", EXR_PIXEL_FLOAT },
        { "--data-type half", "io_dtype_half.exr", EXR_PIXEL_HALF },
    };
    for (int i = 0; i < 3; ++i) {
        char *out = tu_path(cases[i].file);
        print_message("data type '%s'\n", cases[i].flag);
        assert_run(0, "'%s' -o '%s' " FOG " %s", in, out, cases[i].flag);
        tu_image a, b;
        read_image(in, 0, &a);
        read_image(out, 0, &b);
        const int to_h = cases[i].type == EXR_PIXEL_HALF;
        if (to_h) {
            /* -d half never demotes depth (Z stays float: the sample's sky
             * depth 1e10 would become inf); normals and colour go half. */
            static const struct { const char *ch; exr_pixel_type_t t; } want[] = {
                { "R", EXR_PIXEL_HALF },   { "G", EXR_PIXEL_HALF },   { "B", EXR_PIXEL_HALF },
                { "A", EXR_PIXEL_HALF },   { "Z", EXR_PIXEL_FLOAT },  { "N.X", EXR_PIXEL_HALF },
                { "N.Y", EXR_PIXEL_HALF }, { "N.Z", EXR_PIXEL_HALF }, { "spec.R", EXR_PIXEL_HALF },
                { "id", EXR_PIXEL_UINT },
            };
            assert_int_equal(a.nch, b.nch);
            for (size_t k = 0; k < sizeof want / sizeof want[0]; ++k) {
                const int at = tu_image_find(&b, want[k].ch);
                if (at < 0 || b.type[at] != want[k].t)
                    fail_msg("-d half: channel %s has type %d, want %d", want[k].ch,
                             at < 0 ? -1 : (int) b.type[at], (int) want[k].t);
            }
        } else {
            check_channels(&a, &b, cases[i].type);
        }
        assert_int_equal(b.type[tu_image_find(&b, "id")], EXR_PIXEL_UINT);
        static const char *const aovs[] = { "Z", "N.X", "N.Y", "N.Z", "id", "spec.R" };
        for (int k = 0; k < 6; ++k)
            check_same(&a, &b, aovs[k], 0.0, to_h && k != 0);
        tu_image_free(&a);
        tu_image_free(&b);
        fog_check fc;
        fog_check_init(&fc, in, out, &c);
        check_fog(&fc);
        free(out);
    }
    free(in);
    scene_free(&s);
}

/* ------------------------------------------------------------------ */
/* Depth from a second file                                            */

static void test_depth_file(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 63, 47 };
    scene s;
    cam c;
    scene_make(&s, dw, dw, 909);
    cam_make(&c, dw, 90.0, 0.0, 0.0);
    /* Colour file: RGBA + AOVs, no depth. */
    tu_part cp;
    part_geometry(&cp, &s);
    tu_part_add(&cp, "R", EXR_PIXEL_FLOAT, s.R);
    tu_part_add(&cp, "G", EXR_PIXEL_FLOAT, s.G);
    tu_part_add(&cp, "B", EXR_PIXEL_FLOAT, s.B);
    tu_part_add(&cp, "A", EXR_PIXEL_FLOAT, s.A);
    tu_part_add_uint(&cp, "id", s.id);
    tu_part_add(&cp, "spec.R", EXR_PIXEL_HALF, s.spec);
    cam_attach(&c, &cp);
    /* Depth file: tiled, PIZ, Z plus a decoy. */
    tu_part dp;
    part_geometry(&dp, &s);
    tu_part_add(&dp, "N.Z", EXR_PIXEL_FLOAT, s.NZ);
    tu_part_add(&dp, "Z", EXR_PIXEL_FLOAT, s.Z);
    dp.tile = 10;
    dp.comp = EXR_COMPRESSION_PIZ;
    char *in = tu_path("io_depthfile_rgb.exr"), *dep = tu_path("io_depthfile_z.exr");
    char *out = tu_path("io_depthfile.out.exr");
    write_exr(in, &cp, 1);
    write_exr(dep, &dp, 1);

    /* Without --depth there is no depth: exit 1. */
    remove(out);
    assert_run(1, "'%s' -o '%s' " FOG, in, out);
    assert_contains(tu_err, "--depth");
    assert_no_output(out);

    assert_run(0, "--explain '%s' --depth '%s'", in, dep);
    assert_contains(tu_out, "depth: Z (part 0 of ");
    assert_run(0, "'%s' --depth '%s' -o '%s' " FOG " --threads 3", in, dep, out);
    check_files(in, out, 0, RGBA);
    fog_check fc;
    fog_check_init(&fc, in, out, &c);
    fc.depth = dep;
    check_fog(&fc);

    /* A depth file whose data window is shifted: exit 1, both windows named. */
    scene s2;
    const int dw2[4] = { 2, 1, 65, 48 };
    scene_make(&s2, dw2, dw, 910);
    tu_part dp2;
    part_geometry(&dp2, &s2);
    tu_part_add(&dp2, "Z", EXR_PIXEL_FLOAT, s2.Z);
    char *dep2 = tu_path("io_depthfile_z2.exr");
    write_exr(dep2, &dp2, 1);
    remove(out);
    assert_run(1, "'%s' --depth '%s' -o '%s' " FOG, in, dep2, out);
    assert_contains(tu_err, "(2,1)-(65,48)");
    assert_contains(tu_err, "(0,0)-(63,47)");
    assert_no_output(out);

    /* A smaller one too. */
    scene s3;
    const int dw3[4] = { 0, 0, 62, 47 };
    scene_make(&s3, dw3, dw, 911);
    tu_part dp3;
    part_geometry(&dp3, &s3);
    tu_part_add(&dp3, "Z", EXR_PIXEL_FLOAT, s3.Z);
    write_exr(dep2, &dp3, 1);
    assert_run(1, "'%s' --depth '%s' -o '%s' " FOG, in, dep2, out);
    assert_contains(tu_err, "(0,0)-(62,47)");
    assert_contains(tu_err, "(0,0)-(63,47)");
    assert_no_output(out);

    free(in);
    free(dep);
    free(dep2);
    free(out);
    scene_free(&s);
    scene_free(&s2);
    scene_free(&s3);
}

/* ------------------------------------------------------------------ */
/* Finding the channels                                                */

static float *const_plane(const scene *s, float v)
{
    float *p = fplane(s);
    for (int i = 0; i < s->w * s->h; ++i)
        p[i] = v;
    return p;
}

static void test_channels_blender(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 29, 19 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 1001);
    cam_make(&c, dw, 60.0, 0.0, 0.0);
    part_geometry(&p, &s);
    tu_part_add(&p, "ViewLayer.Combined.R", EXR_PIXEL_FLOAT, s.R);
    tu_part_add(&p, "ViewLayer.Combined.G", EXR_PIXEL_FLOAT, s.G);
    tu_part_add(&p, "ViewLayer.Combined.B", EXR_PIXEL_FLOAT, s.B);
    tu_part_add(&p, "ViewLayer.Combined.A", EXR_PIXEL_FLOAT, s.A);
    tu_part_add(&p, "ViewLayer.Depth.Z", EXR_PIXEL_FLOAT, s.Z);
    tu_part_add(&p, "ViewLayer.Normal.X", EXR_PIXEL_FLOAT, s.NX);
    tu_part_add(&p, "ViewLayer.Normal.Y", EXR_PIXEL_FLOAT, s.NY);
    tu_part_add(&p, "ViewLayer.Normal.Z", EXR_PIXEL_FLOAT, s.spec);  /* positive decoy */
    p.str_name = "BlenderMultiChannel";
    p.str_value = "Blender V2.55.1 and newer";
    char *in = tu_path("io_blender.exr"), *out = tu_path("io_blender.out.exr");
    write_exr(in, &p, 1);
    char cf[1024];
    cam_flags(&c, cf, sizeof cf);
    assert_run(0, "--explain '%s' %s", in, cf);
    assert_contains(tu_out, "depth: ViewLayer.Depth.Z (part 0)");
    assert_contains(tu_out, "colour: ViewLayer.Combined.R, ViewLayer.Combined.G, "
                           "ViewLayer.Combined.B, alpha ViewLayer.Combined.A");
    assert_run(0, "'%s' -o '%s' " FOG " %s", in, out, cf);
    static const char *const combined[] = { "ViewLayer.Combined.R", "ViewLayer.Combined.G",
                                            "ViewLayer.Combined.B", "ViewLayer.Combined.A",
                                            NULL };
    check_files(in, out, 0, combined);
    fog_check fc;
    fog_check_init(&fc, in, out, &c);
    fc.rgba[0] = "ViewLayer.Combined.R";
    fc.rgba[1] = "ViewLayer.Combined.G";
    fc.rgba[2] = "ViewLayer.Combined.B";
    fc.rgba[3] = "ViewLayer.Combined.A";
    fc.z = "ViewLayer.Depth.Z";
    check_fog(&fc);

    /* Two view layers: whichever colour layer is used, the depth is that
     * layer's own, never the other layer's. */
    float *z2 = const_plane(&s, 7.0f);
    tu_part_add(&p, "Back.Combined.R", EXR_PIXEL_HALF, s.NX);
    tu_part_add(&p, "Back.Combined.G", EXR_PIXEL_HALF, s.NY);
    tu_part_add(&p, "Back.Combined.B", EXR_PIXEL_HALF, s.NZ);
    tu_part_add(&p, "Back.Combined.A", EXR_PIXEL_HALF, s.A);
    tu_part_add(&p, "Back.Depth.Z", EXR_PIXEL_FLOAT, z2);
    write_exr(in, &p, 1);
    assert_run(0, "--explain '%s' %s", in, cf);
    if (strstr(tu_out, "colour: Back.Combined.R"))
        assert_contains(tu_out, "depth: Back.Depth.Z (part 0)");
    else
        assert_contains(tu_out, "depth: ViewLayer.Depth.Z (part 0)");
    assert_run(0, "--explain '%s' %s --layer ViewLayer.Combined", in, cf);
    assert_contains(tu_out, "colour: ViewLayer.Combined.R");
    assert_contains(tu_out, "depth: ViewLayer.Depth.Z (part 0)");
    assert_run(0, "--explain '%s' %s --layer Back.Combined", in, cf);
    assert_contains(tu_out, "colour: Back.Combined.R");
    assert_contains(tu_out, "depth: Back.Depth.Z (part 0)");
    assert_run(0, "'%s' -o '%s' " FOG " %s --layer Back.Combined", in, out, cf);
    static const char *const back[] = { "Back.Combined.R", "Back.Combined.G", "Back.Combined.B",
                                        "Back.Combined.A", NULL };
    check_files(in, out, 0, back);
    fog_check_init(&fc, in, out, &c);
    fc.rgba[0] = back[0];
    fc.rgba[1] = back[1];
    fc.rgba[2] = back[2];
    fc.rgba[3] = back[3];
    fc.z = "Back.Depth.Z";
    check_fog(&fc);
    free(z2);
    free(in);
    free(out);
    scene_free(&s);
}

static void test_channels_nuke_single(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 33, 21 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 1102);
    cam_make(&c, dw, 60.0, 0.0, 0.0);
    float *cz = const_plane(&s, 3.0f), *ozb = const_plane(&s, 4.0f);
    float *pz = const_plane(&s, 5.0f);
    part_geometry(&p, &s);
    /* Look-alikes before and after the real one. */
    tu_part_add(&p, "character.Z", EXR_PIXEL_HALF, cz);
    tu_part_add(&p, "N.Z", EXR_PIXEL_FLOAT, s.spec);
    tu_part_add(&p, "R", EXR_PIXEL_HALF, s.R);
    tu_part_add(&p, "G", EXR_PIXEL_HALF, s.G);
    tu_part_add(&p, "B", EXR_PIXEL_HALF, s.B);
    tu_part_add(&p, "A", EXR_PIXEL_HALF, s.A);
    tu_part_add(&p, "depth.Z", EXR_PIXEL_FLOAT, s.Z);
    tu_part_add(&p, "other.ZBack", EXR_PIXEL_HALF, ozb);
    tu_part_add(&p, "P.Z", EXR_PIXEL_FLOAT, pz);
    tu_part_add(&p, "character.ZBack", EXR_PIXEL_HALF, ozb);
    char *in = tu_path("io_nuke_sp.exr"), *out = tu_path("io_nuke_sp.out.exr");
    write_exr(in, &p, 1);
    char cf[1024];
    cam_flags(&c, cf, sizeof cf);
    assert_run(0, "--explain '%s' %s", in, cf);
    assert_contains(tu_out, "depth: depth.Z (part 0)");
    assert_contains(tu_out, "colour: R, G, B, alpha A");
    assert_run(0, "'%s' -o '%s' " FOG " %s", in, out, cf);
    check_files(in, out, 0, RGBA);
    fog_check fc;
    fog_check_init(&fc, in, out, &c);
    fc.z = "depth.Z";
    check_fog(&fc);
    free(cz);
    free(ozb);
    free(pz);
    free(in);
    free(out);
    scene_free(&s);
}

/* --layer and --depth-channel choose explicitly. */
static void test_channels_explicit(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 35, 27 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 1203);
    cam_make(&c, dw, 60.0, 0.0, 0.0);
    float *zalt = fplane(&s);
    for (int i = 0; i < s.w * s.h; ++i)
        zalt[i] = 2.0f + (float) (i % 37);
    part_geometry(&p, &s);
    tu_part_add(&p, "R", EXR_PIXEL_FLOAT, s.R);
    tu_part_add(&p, "G", EXR_PIXEL_FLOAT, s.G);
    tu_part_add(&p, "B", EXR_PIXEL_FLOAT, s.B);
    tu_part_add(&p, "A", EXR_PIXEL_FLOAT, s.A);
    tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, s.Z);
    tu_part_add(&p, "alt.Z", EXR_PIXEL_FLOAT, zalt);
    tu_part_add(&p, "diffuse.R", EXR_PIXEL_HALF, s.NX);
    tu_part_add(&p, "diffuse.G", EXR_PIXEL_HALF, s.NY);
    tu_part_add(&p, "diffuse.B", EXR_PIXEL_HALF, s.spec);
    cam_attach(&c, &p);
    char *in = tu_path("io_explicit.exr"), *out = tu_path("io_explicit.out.exr");
    write_exr(in, &p, 1);

    /* Automatic: R,G,B,A with Z. */
    assert_run(0, "--explain '%s'", in);
    assert_contains(tu_out, "depth: Z (part 0)");
    assert_contains(tu_out, "colour: R, G, B, alpha A");

    /* --depth-channel alt.Z: the beauty fogged with alt.Z. */
    assert_run(0, "--explain '%s' --depth-channel alt.Z", in);
    assert_contains(tu_out, "depth: alt.Z (part 0)");
    assert_run(0, "'%s' -o '%s' " FOG " --depth-channel alt.Z", in, out);
    check_files(in, out, 0, RGBA);
    fog_check fc;
    fog_check_init(&fc, in, out, &c);
    fc.z = "alt.Z";
    check_fog(&fc);

    /* --layer diffuse --depth-channel Z: only diffuse.* fogged, alpha 1. */
    assert_run(0, "--explain '%s' --layer diffuse --depth-channel Z", in);
    assert_contains(tu_out, "colour: diffuse.R, diffuse.G, diffuse.B, no alpha");
    assert_contains(tu_out, "depth: Z (part 0)");
    assert_run(0, "'%s' -o '%s' " FOG " --layer diffuse --depth-channel Z", in, out);
    static const char *const diffuse[] = { "diffuse.R", "diffuse.G", "diffuse.B", NULL };
    check_files(in, out, 0, diffuse);
    fog_check_init(&fc, in, out, &c);
    fc.rgba[0] = "diffuse.R";
    fc.rgba[1] = "diffuse.G";
    fc.rgba[2] = "diffuse.B";
    fc.rgba[3] = NULL;
    check_fog(&fc);
    free(zalt);
    free(in);
    free(out);
    scene_free(&s);
}

/* A UINT channel chosen as depth (integer depths, e.g. millimetres or
 * slices) must be read as the numbers it holds, or refused with a message;
 * never its bits taken for a float. */
static void test_uint_depth_channel(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 39, 29 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 1401);
    cam_make(&c, dw, 60.0, 0.0, 0.0);
    uint32_t *zi = malloc(sizeof(uint32_t) * (size_t) s.w * (size_t) s.h);
    assert_non_null(zi);
    for (int i = 0; i < s.w * s.h; ++i)
        zi[i] = i % 19 == 0 ? 0u : 1u + (uint32_t) (i % 60);
    part_geometry(&p, &s);
    tu_part_add(&p, "R", EXR_PIXEL_FLOAT, s.R);
    tu_part_add(&p, "G", EXR_PIXEL_FLOAT, s.G);
    tu_part_add(&p, "B", EXR_PIXEL_FLOAT, s.B);
    tu_part_add(&p, "A", EXR_PIXEL_FLOAT, s.A);
    tu_part_add_uint(&p, "zi", zi);
    cam_attach(&c, &p);
    char *in = tu_path("io_uintdepth.exr"), *out = tu_path("io_uintdepth.out.exr");
    write_exr(in, &p, 1);
    remove(out);
    /* A uint depth holds distances as integers: read as numbers, not bits. */
    assert_run(0, "'%s' -o '%s' " FOG " --depth-channel zi", in, out);
    fog_check fc;
    fog_check_init(&fc, in, out, &c);
    fc.z = "zi";
    check_fog(&fc);
    check_files(in, out, 0, RGBA);
    free(zi);
    free(in);
    free(out);
    scene_free(&s);
}

/* A UINT colour layer picked with --layer (object ids, counts) is fogged as
 * the numbers it holds and written back as the nearest integers; never
 * float bits stored as integers. */
static void test_uint_colour_layer(void **state)
{
    (void) state;
    const int dw[4] = { 0, 0, 23, 17 };
    scene s;
    cam c;
    tu_part p;
    scene_make(&s, dw, dw, 1402);
    cam_make(&c, dw, 60.0, 0.0, 0.0);
    const size_t n = (size_t) s.w * (size_t) s.h;
    uint32_t *v[3];
    for (int k = 0; k < 3; ++k) {
        v[k] = malloc(sizeof(uint32_t) * n);
        assert_non_null(v[k]);
        for (size_t i = 0; i < n; ++i)
            v[k][i] = (uint32_t) ((i * (3 + (size_t) k) * 37) % 1000);
    }
    for (size_t i = 0; i < n; ++i)
        s.Z[i] = 5.0f + (float) (i % 13);
    part_geometry(&p, &s);
    tu_part_add_uint(&p, "count.R", v[0]);
    tu_part_add_uint(&p, "count.G", v[1]);
    tu_part_add_uint(&p, "count.B", v[2]);
    tu_part_add(&p, "count.Z", EXR_PIXEL_FLOAT, s.Z);
    cam_attach(&c, &p);
    char *in = tu_path("io_uintcolour.exr"), *out = tu_path("io_uintcolour.out.exr");
    write_exr(in, &p, 1);
    remove(out);
    /* Fogged as the numbers they hold, written back as the nearest integers. */
    assert_run(0, "'%s' -o '%s' " FOG " --layer count", in, out);
    {
        tu_image b;
        read_image(out, 0, &b);
        long bad = 0;
        static const double F[3] = { 0.25, 0.5, 0.75 };
        for (int k = 0; k < 3; ++k) {
            const char *name = k == 0 ? "count.R" : k == 1 ? "count.G" : "count.B";
            const uint32_t *o = tu_image_u(&b, name);
            assert_non_null(o);
            for (int y = 0; y < s.h; ++y)
                for (int x = 0; x < s.w; ++x) {
                    const size_t i = (size_t) y * (size_t) s.w + (size_t) x;
                    const double T = exp(-0.05 * s.Z[i] * tu_pinhole_ray_len(&c.pin, x, y));
                    const double want = T * v[k][i] + (1.0 - T) * F[k];
                    if (!(fabs((double) o[i] - want) <= 1.0) && bad++ < 5)
                        print_message("%s at (%d,%d): %u, expected %.3f\n", name, x, y, o[i],
                                      want);
                }
        }
        tu_image_free(&b);
        assert_int_equal(bad, 0);
    }
    for (int k = 0; k < 3; ++k)
        free(v[k]);
    free(in);
    free(out);
    scene_free(&s);
}

/* ------------------------------------------------------------------ */
/* ef_exr_stream directly: chunk geometry                              */

/* The callback checks that each pixel arrives once with its own colour
 * and depth, then writes its absolute coordinates into R and G and its
 * depth into B, so the output shows where every value went. */
typedef struct geo {
    int dw[4], w, h;
    const float *R, *Z;       /* expected input R and depth, data window */
    atomic_int *visits;
    atomic_long bad;
} geo;

static void geo_fn(void *user, const ef_chunk *ck)
{
    geo *g = user;
    for (int yy = 0; yy < ck->h; ++yy)
        for (int xx = 0; xx < ck->w; ++xx) {
            const int x = ck->x0 + xx, y = ck->y0 + yy;
            const size_t i = (size_t) yy * (size_t) ck->w + (size_t) xx;
            if (x < g->dw[0] || x > g->dw[2] || y < g->dw[1] || y > g->dw[3]) {
                atomic_fetch_add(&g->bad, 1);
                continue;
            }
            const size_t k = (size_t) (y - g->dw[1]) * (size_t) g->w + (size_t) (x - g->dw[0]);
            atomic_fetch_add(&g->visits[k], 1);
            if (memcmp(&ck->depth[i], &g->Z[k], sizeof(float)) ||
                memcmp(&ck->rgb[0][i], &g->R[k], sizeof(float)))
                atomic_fetch_add(&g->bad, 1);
            ck->rgb[0][i] = (float) x;
            ck->rgb[1][i] = (float) y;
            ck->rgb[2][i] = ck->depth[i];
        }
}

/* Streams in (depth from dep, or in when NULL) to out with the given
 * options and checks coverage, placement, and every untouched channel. */
static void geo_case(const char *in, const char *dep, const char *out, int colour_part,
                     int depth_part, const char *zname, const ef_stream_opts *so)
{
    ef_exr_file fi = { 0 }, fd = { 0 };
    ef_err err = {0};
    ef_channel_plan plan;
    if (ef_exr_open(in, &fi, &err) || (dep && ef_exr_open(dep, &fd, &err)) ||
        ef_find_channels(&fi, dep ? &fd : &fi, NULL, NULL, &plan, &err)) {
        print_error("%s\n", err.msg);
        fail();
    }
    assert_int_equal(plan.rgb[0].part, colour_part);
    assert_int_equal(plan.depth.part, depth_part);
    tu_image cimg, dimg;
    read_image(in, colour_part, &cimg);
    read_image(dep ? dep : in, depth_part, &dimg);
    geo g;
    memcpy(g.dw, cimg.dw, sizeof g.dw);
    g.w = cimg.w;
    g.h = cimg.h;
    g.R = cimg.plane[plan.rgb[0].index];
    g.Z = tu_image_f(&dimg, zname);
    assert_non_null(g.Z);
    g.visits = calloc((size_t) g.w * (size_t) g.h, sizeof *g.visits);
    assert_non_null(g.visits);
    atomic_init(&g.bad, 0);
    ef_stream_stats st;
    if (ef_exr_stream_file(&fi, dep ? &fd : &fi, &plan, out, so, geo_fn, &g, &st, &err)) {
        print_error("ef_exr_stream: %s\n", err.msg);
        fail();
    }
    char why[4200];
    if (tu_check_readback_path(out, why, sizeof why)) {
        print_error("%s\n", why);
        fail();
    }
    ef_exr_close(&fi);
    ef_exr_close(&fd);
    long unvisited = 0;
    for (int i = 0; i < g.w * g.h; ++i)
        unvisited += atomic_load(&g.visits[i]) != 1;
    free(g.visits);
    if (unvisited || atomic_load(&g.bad)) {
        print_error("%ld pixels not visited exactly once, %ld with wrong input\n", unvisited,
                    (long) atomic_load(&g.bad));
        fail();
    }
    /* Output: coordinates where they belong; other parts/channels untouched. */
    const int n = tu_nparts(in);
    assert_int_equal(tu_nparts(out), n);
    for (int p = 0; p < n; ++p) {
        tu_image a, b;
        read_image(in, p, &a);
        read_image(out, p, &b);
        assert_string_equal(a.name, b.name);
        check_channels(&a, &b, so->pixel_type);
        assert_int_equal(a.tiled, b.tiled);
        assert_int_equal(a.tile_x, b.tile_x);
        assert_int_equal(a.tile_y, b.tile_y);
        assert_int_equal(b.comp, so->compression >= 0 ? (exr_compression_t) so->compression
                                                       : a.comp);
        for (int c = 0; c < a.nch; ++c) {
            if (p == colour_part && (c == plan.rgb[0].index || c == plan.rgb[1].index ||
                                     c == plan.rgb[2].index))
                continue;
            check_same(&a, &b, a.ch[c], 0.0, 0);
        }
        if (p == colour_part) {
            const float *R = b.plane[plan.rgb[0].index], *G = b.plane[plan.rgb[1].index];
            const float *B = b.plane[plan.rgb[2].index];
            long bad = 0;
            for (int j = 0; j < b.h; ++j)
                for (int i = 0; i < b.w; ++i) {
                    const size_t k = (size_t) j * (size_t) b.w + (size_t) i;
                    if (R[k] != (float) (b.dw[0] + i) || G[k] != (float) (b.dw[1] + j) ||
                        memcmp(&B[k], &g.Z[k], sizeof(float))) {
                        if (bad++ < 5)
                            print_message("pixel (%d,%d): R %g G %g B %g, depth %g\n",
                                          b.dw[0] + i, b.dw[1] + j, (double) R[k], (double) G[k],
                                          (double) B[k], (double) g.Z[k]);
                    }
                }
            if (bad) {
                print_error("%ld pixels misplaced in the output\n", bad);
                fail();
            }
        }
        tu_image_free(&a);
        tu_image_free(&b);
    }
    tu_image_free(&cimg);
    tu_image_free(&dimg);
}

static void test_stream_geometry(void **state)
{
    (void) state;
    const int disp[4] = { 0, 0, 63, 47 };
    ef_stream_opts so = { .threads = 3, .compression = -1, .zip_level = -1, .pixel_type = -1,
                          .param_attr = "geometry test" };

    /* Scanline ZIP (16-line chunks), overscan window; output PIZ (32-line
     * chunks), then NONE (1 line). */
    {
        const int dw[4] = { -3, -2, 40, 57 };
        scene s;
        tu_part p;
        scene_make(&s, dw, disp, 1301);
        scene_part(&p, &s, EXR_PIXEL_FLOAT, EXR_PIXEL_FLOAT);
        char *in = tu_path("io_geo_scan.exr"), *out = tu_path("io_geo_scan.out.exr");
        write_exr(in, &p, 1);
        so.compression = EXR_COMPRESSION_PIZ;
        print_message("scanline, overscan, zip -> piz\n");
        geo_case(in, NULL, out, 0, 0, "Z", &so);
        /* and back to one line per chunk */
        so.compression = EXR_COMPRESSION_NONE;
        print_message("scanline, overscan, zip -> none\n");
        geo_case(in, NULL, out, 0, 0, "Z", &so);
        so.compression = -1;
        free(in);
        free(out);
        scene_free(&s);
    }
    /* Tiled 7x7 with an offset window, 4 threads. */
    {
        const int dw[4] = { 5, 9, 47, 40 };
        scene s;
        tu_part p;
        scene_make(&s, dw, disp, 1302);
        scene_part(&p, &s, EXR_PIXEL_FLOAT, EXR_PIXEL_FLOAT);
        p.tile = 7;
        char *in = tu_path("io_geo_tile.exr"), *out = tu_path("io_geo_tile.out.exr");
        write_exr(in, &p, 1);
        so.threads = 4;
        print_message("tiled 7, offset window\n");
        geo_case(in, NULL, out, 0, 0, "Z", &so);
        p.tile_h = 3;
        write_exr(in, &p, 1);
        print_message("tiled 7x3, offset window\n");
        geo_case(in, NULL, out, 0, 0, "Z", &so);
        free(in);
        free(out);
        scene_free(&s);
    }
    /* Multi-part: AOV part, tiled colour part, scanline PIZ depth part. */
    {
        const int dw[4] = { -4, 3, 50, 44 };
        scene s;
        scene_make(&s, dw, disp, 1303);
        tu_part parts[3];
        part_geometry(&parts[0], &s);
        parts[0].name = "aov";
        tu_part_add(&parts[0], "N.Z", EXR_PIXEL_FLOAT, s.NZ);
        tu_part_add_uint(&parts[0], "id", s.id);
        parts[0].tile = 5;
        part_geometry(&parts[1], &s);
        parts[1].name = "rgba";
        tu_part_add(&parts[1], "R", EXR_PIXEL_FLOAT, s.R);
        tu_part_add(&parts[1], "G", EXR_PIXEL_FLOAT, s.G);
        tu_part_add(&parts[1], "B", EXR_PIXEL_FLOAT, s.B);
        tu_part_add(&parts[1], "A", EXR_PIXEL_HALF, s.A);
        parts[1].tile = 9;
        part_geometry(&parts[2], &s);
        parts[2].name = "depth";
        tu_part_add(&parts[2], "Z", EXR_PIXEL_FLOAT, s.Z);
        parts[2].comp = EXR_COMPRESSION_PIZ;
        char *in = tu_path("io_geo_mp.exr"), *out = tu_path("io_geo_mp.out.exr");
        write_exr(in, parts, 3);
        so.threads = 3;
        print_message("multi-part, depth in a scanline part\n");
        geo_case(in, NULL, out, 1, 2, "Z", &so);
        /* and with the depth part tiled and the colour scanline */
        parts[1].tile = 0;
        parts[2].tile = 6;
        parts[2].comp = EXR_COMPRESSION_ZIP;
        write_exr(in, parts, 3);
        print_message("multi-part, depth in a tiled part\n");
        geo_case(in, NULL, out, 1, 2, "Z", &so);
        free(in);
        free(out);
        scene_free(&s);
    }
    /* A separate depth file: colour scanline NONE (1 line per chunk), depth
     * tiled 6 with RLE; output pixel type forced to float. */
    {
        const int dw[4] = { 0, 0, 63, 47 };
        scene s;
        scene_make(&s, dw, disp, 1304);
        tu_part cp, dp;
        part_geometry(&cp, &s);
        tu_part_add(&cp, "R", EXR_PIXEL_FLOAT, s.R);
        tu_part_add(&cp, "G", EXR_PIXEL_FLOAT, s.G);
        tu_part_add(&cp, "B", EXR_PIXEL_FLOAT, s.B);
        tu_part_add(&cp, "spec.R", EXR_PIXEL_HALF, s.spec);
        cp.comp = EXR_COMPRESSION_NONE;
        part_geometry(&dp, &s);
        tu_part_add(&dp, "Z", EXR_PIXEL_FLOAT, s.Z);
        dp.tile = 6;
        dp.tile_h = 4;
        dp.comp = EXR_COMPRESSION_RLE;
        char *in = tu_path("io_geo_sep.exr"), *dep = tu_path("io_geo_sep_z.exr");
        char *out = tu_path("io_geo_sep.out.exr");
        write_exr(in, &cp, 1);
        write_exr(dep, &dp, 1);
        so.threads = 2;
        so.pixel_type = EXR_PIXEL_FLOAT;
        print_message("separate depth file\n");
        geo_case(in, dep, out, 0, 0, "Z", &so);
        so.pixel_type = -1;
        free(in);
        free(dep);
        free(out);
        scene_free(&s);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_compression_output),
        cmocka_unit_test(test_compression_input),
        cmocka_unit_test(test_tiled),
        cmocka_unit_test(test_tiny_images),
        cmocka_unit_test(test_multipart_nuke),
        cmocka_unit_test(test_window_crop),
        cmocka_unit_test(test_window_overscan),
        cmocka_unit_test(test_window_display_offset),
        cmocka_unit_test(test_metadata_passthrough),
        cmocka_unit_test(test_data_type),
        cmocka_unit_test(test_depth_file),
        cmocka_unit_test(test_channels_blender),
        cmocka_unit_test(test_channels_nuke_single),
        cmocka_unit_test(test_channels_explicit),
        cmocka_unit_test(test_uint_depth_channel),
        cmocka_unit_test(test_uint_colour_layer),
        cmocka_unit_test(test_stream_geometry),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
