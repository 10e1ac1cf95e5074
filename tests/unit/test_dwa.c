/* DWAA/DWAB through the C++ library (src/io/exr_dwa.cpp): files written
 * here with OpenEXRCore (ZIP) are transcoded to DWA and back, and checked
 * against the originals (read by Core) and against the OpenEXR C++
 * library's own decode of the DWA files (tests/refs/dwa_ref.cpp):
 *   - channels DWA stores losslessly (everything but the R, G, B, Y, BY, RY
 *     suffixes) come back bit-exact after ZIP -> DWA;
 *   - after DWA -> ZIP every channel is bit-exact with the reference
 *     decode of the DWA file;
 *   - headers: compression, dwaCompressionLevel, tiles, windows,
 *     attributes;
 *   - memory stays bounded on a 4096 x 2160 frame;
 *   - damaged input fails cleanly. */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "tassert.h"

#include "dwa_ref.h"
#include "exr_dwa.h"
#include "exr_io.h"
#include "testutil.h"

#if defined(__SANITIZE_ADDRESS__)
#define EF_ASAN 1
#else
#define EF_ASAN 0
#endif

/* ------------------------------------------------------------------ */
/* Helpers                                                             */

static uint32_t rng_state = 2463534242u;

static uint32_t rnd_u32(void)
{
    return tu_xorshift32(&rng_state);
}

static double rnd01(void)
{
    return tu_rand01(&rng_state);
}

/* Whether DWA's default channel rules send a channel through the lossy
 * DCT: the suffix after the last '.' is R, G, B, Y, BY or RY (half or
 * float). Everything else (A by RLE, the rest by zlib) is lossless. */
static int dwa_lossy(const char *name)
{
    const char *dot = strrchr(name, '.');
    const char *s = dot ? dot + 1 : name;
    static const char *const lossy[] = { "R", "G", "B", "Y", "BY", "RY" };
    for (int i = 0; i < 6; ++i)
        if (!strcmp(s, lossy[i]))
            return 1;
    return 0;
}

/* Runs ef_dwa_transcode into a new file at out. */
static int transcode(const char *in, const char *out, int dwa_to, int all_to, float level,
                     int threads, char *msg, size_t msglen)
{
    int fd = open(out, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    assert_true(fd >= 0);
    int rc = ef_dwa_transcode(in, fd, out, dwa_to, all_to, level, threads, msg, msglen);
    close(fd);
    return rc;
}

static void must_transcode(const char *in, const char *out, int dwa_to, int all_to, float level,
                           int threads)
{
    char msg[1024] = "";
    if (transcode(in, out, dwa_to, all_to, level, threads, msg, sizeof msg)) {
        print_error("ef_dwa_transcode(%s -> %s): %s\n", in, out, msg);
        fail();
    }
}

static long file_size(const char *path)
{
    struct stat st;
    return stat(path, &st) ? -1 : (long) st.st_size;
}

/* Every channel of part `part` of `ref_path` (read by the C++ library)
 * against the same channel of `img` (read by Core or the C++ library):
 * bit-exact when exact or the channel is not one DWA quantises, else
 * within rel (relative to 1 + |v|). Returns the number of differing
 * samples. */
static long compare_with_ref(const char *ref_path, int part, const tu_image *img, int exact,
                             double rel)
{
    long bad = 0;
    for (int c = 0; c < img->nch; ++c) {
        int w, h;
        uint32_t *ref = dwa_ref_read(ref_path, part, img->ch[c], &w, &h);
        if (!ref || w != img->w || h != img->h) {
            print_error("part %d channel %s: unreadable or wrong size in %s\n", part, img->ch[c],
                        ref_path);
            free(ref);
            ++bad;
            continue;
        }
        const uint32_t *v = img->plane[c];
        const int lossless = exact || !dwa_lossy(img->ch[c]) || img->type[c] == EXR_PIXEL_UINT;
        long nbad = 0;
        for (long i = 0; i < (long) w * h; ++i) {
            int same;
            if (lossless) {
                same = ref[i] == v[i];
            } else {
                float a, b;
                memcpy(&a, &ref[i], 4);
                memcpy(&b, &v[i], 4);
                same = fabs((double) a - b) <= rel * (1 + fabs((double) b));
            }
            if (!same && nbad++ < 3)
                print_error("part %d %s[%ld]: %s has 0x%08x, expected 0x%08x (%s)\n", part,
                            img->ch[c], i, ref_path, ref[i], v[i],
                            lossless ? "bit-exact" : "within tolerance");
        }
        bad += nbad;
        free(ref);
    }
    return bad;
}

/* ------------------------------------------------------------------ */
/* The two-part test file                                              */

enum { W0 = 64, H0 = 40, W1 = 48, H1 = 34 };

typedef struct scene {
    float rgb[3][W0 * H0], a[W0 * H0], z[W0 * H0];
    uint32_t id[W0 * H0];
    float drgb[3][W1 * H1], nx[W1 * H1], pz[W1 * H1], er[W1 * H1];
} scene;

static scene S;

/* Part 0 "beauty": scanline, data window (-3,5)-(60,44), R G B A half, Z
 * float, id uint. Part 1 "aov": tiled 16x16, data window (2,1)-(49,34),
 * diffuse.R/G/B and N.X half, P.Z float, emission.R float. */
static void write_scene(const char *path, int tiled_tile)
{
    rng_state = 12345;
    for (int y = 0; y < H0; ++y)
        for (int x = 0; x < W0; ++x) {
            const int i = y * W0 + x;
            for (int k = 0; k < 3; ++k)
                S.rgb[k][i] = (float) (0.2 + 0.6 * sin(0.1 * x + k) * cos(0.13 * y) *
                                                 sin(0.1 * x + k) +
                                       0.05 * rnd01());
            S.a[i] = (float) rnd01();
            S.z[i] = (float) (1 + 999 * rnd01());
            S.id[i] = rnd_u32();
        }
    for (int i = 0; i < W1 * H1; ++i) {
        for (int k = 0; k < 3; ++k)
            S.drgb[k][i] = (float) (0.5 + 0.3 * sin(0.05 * i + k));
        S.nx[i] = (float) (2 * rnd01() - 1);
        S.pz[i] = (float) (-50 + 100 * rnd01());
        S.er[i] = (float) (0.1 + 0.1 * cos(0.02 * i));
    }
    tu_part p[2];
    tu_part_init(&p[0], W0, H0);
    p[0].name = "beauty";
    const int dw0[4] = { -3, 5, -3 + W0 - 1, 5 + H0 - 1 }, disp[4] = { 0, 0, 63, 47 };
    memcpy(p[0].dw, dw0, sizeof dw0);
    memcpy(p[0].disp, disp, sizeof disp);
    tu_part_add(&p[0], "R", EXR_PIXEL_HALF, S.rgb[0]);
    tu_part_add(&p[0], "G", EXR_PIXEL_HALF, S.rgb[1]);
    tu_part_add(&p[0], "B", EXR_PIXEL_HALF, S.rgb[2]);
    tu_part_add(&p[0], "A", EXR_PIXEL_HALF, S.a);
    tu_part_add(&p[0], "Z", EXR_PIXEL_FLOAT, S.z);
    tu_part_add_uint(&p[0], "id", S.id);
    p[0].str_name = "owner";
    p[0].str_value = "test_dwa";
    p[0].m44[0].name = "worldToCamera";
    for (int k = 0; k < 16; ++k)
        p[0].m44[0].m[k] = (float) (k % 5 == 0) + 0.25f * (float) (k == 13);
    tu_part_init(&p[1], W1, H1);
    p[1].name = "aov";
    const int dw1[4] = { 2, 1, 2 + W1 - 1, 1 + H1 - 1 };
    memcpy(p[1].dw, dw1, sizeof dw1);
    memcpy(p[1].disp, disp, sizeof disp);
    p[1].tile = tiled_tile;
    tu_part_add(&p[1], "diffuse.R", EXR_PIXEL_HALF, S.drgb[0]);
    tu_part_add(&p[1], "diffuse.G", EXR_PIXEL_HALF, S.drgb[1]);
    tu_part_add(&p[1], "diffuse.B", EXR_PIXEL_HALF, S.drgb[2]);
    tu_part_add(&p[1], "N.X", EXR_PIXEL_HALF, S.nx);
    tu_part_add(&p[1], "P.Z", EXR_PIXEL_FLOAT, S.pz);
    tu_part_add(&p[1], "emission.R", EXR_PIXEL_FLOAT, S.er);
    p[1].f[0].name = "CameraFov";
    p[1].f[0].v = 40.0f;
    assert_int_equal(tu_write_exr(path, p, 2), 0);
}

static void read_core(const char *path, int part, tu_image *img)
{
    if (tu_read_image(path, part, img)) {
        print_error("Core cannot read part %d of %s\n", part, path);
        fail();
    }
}

static void check_ref_header(const char *path, int part, int comp, float level, int tiled,
                             const int dw[4])
{
    dwa_ref_info in;
    assert_int_equal(dwa_ref_header(path, part, &in), 0);
    assert_int_equal(in.compression, comp);
    assert_close(in.level, level, 0);
    assert_int_equal(in.tiled, tiled);
    assert_memory_equal(in.dw, dw, sizeof in.dw);
}

/* ------------------------------------------------------------------ */
/* Tests                                                               */

static void test_parse(void **state)
{
    (void) state;
    ef_err err;
    int c, zl;
    float dl;
    assert_int_equal(ef_compression_parse("dwaa", &c, &zl, &dl, &err), 0);
    assert_int_equal(c, EXR_COMPRESSION_DWAA);
    assert_int_equal(zl, -1);
    assert_close(dl, 45, 0);
    assert_int_equal(ef_compression_parse("dwab:100", &c, &zl, &dl, &err), 0);
    assert_int_equal(c, EXR_COMPRESSION_DWAB);
    assert_close(dl, 100, 0);
    assert_int_equal(ef_compression_parse("dwaa:2.5", &c, &zl, &dl, &err), 0);
    assert_close(dl, 2.5, 0);
    assert_int_equal(ef_compression_parse("zip:7", &c, &zl, &dl, &err), 0);
    assert_int_equal(c, EXR_COMPRESSION_ZIP);
    assert_int_equal(zl, 7);
    assert_close(dl, -1, 0);
    assert_int_equal(ef_compression_parse("piz", &c, &zl, &dl, &err), 0);
    assert_int_equal(c, EXR_COMPRESSION_PIZ);
    static const char *const bad[] = { "dwaa:0", "dwaa:-3", "dwab:", "dwaa:x", "dwaa:nan",
                                       "dwaa:inf", "zip:45", "zip:0", "piz:3", "dwac", "" };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        err.msg[0] = '\0';
        assert_int_equal(ef_compression_parse(bad[i], &c, &zl, &dl, &err), -1);
        assert_true(strlen(err.msg) > 20);
    }
    assert_int_equal(ef_compression_parse("dwaa:x", &c, &zl, &dl, &err), -1);
    assert_contains(err.msg, "positive");
    assert_int_equal(ef_compression_parse("lzw", &c, &zl, &dl, &err), -1);
    assert_contains(err.msg, "dwab");
}

/* ZIP -> DWAA (default level) -> ZIP, scanline and tiled parts. */
static void test_roundtrip(void **state)
{
    (void) state;
    char *orig = tu_path("dwa_orig.exr"), *dwa = tu_path("dwa_a.exr"),
         *zip = tu_path("dwa_back.exr");
    write_scene(orig, 16);
    assert_int_equal(ef_exr_dwa_parts_path(orig, NULL), 0);

    must_transcode(orig, dwa, -1, EXR_COMPRESSION_DWAA, -1, 2);
    assert_int_equal(ef_exr_dwa_parts_path(dwa, NULL), 2);
    const int dw0[4] = { -3, 5, 60, 44 }, dw1[4] = { 2, 1, 49, 34 };
    check_ref_header(dwa, 0, EXR_COMPRESSION_DWAA, 45, 0, dw0);
    check_ref_header(dwa, 1, EXR_COMPRESSION_DWAA, 45, 1, dw1);
    /* ZIP -> DWA: the lossless channels bit-exact, colour close. */
    for (int p = 0; p < 2; ++p) {
        tu_image o;
        read_core(orig, p, &o);
        assert_int_equal(compare_with_ref(dwa, p, &o, 0, 0.02), 0);
        tu_image_free(&o);
    }
    /* Something was quantised: DWA is not silently lossless here. */
    {
        int w, h;
        uint32_t *r = dwa_ref_read(dwa, 0, "R", &w, &h);
        tu_image o;
        read_core(orig, 0, &o);
        const uint32_t *orr = o.plane[tu_image_find(&o, "R")];
        long diff = 0;
        for (long i = 0; i < (long) w * h; ++i)
            diff += r[i] != orr[i];
        assert_true(diff > 0);
        free(r);
        tu_image_free(&o);
    }

    /* DWA -> ZIP: every channel bit-exact with the C++ library's decode. */
    must_transcode(dwa, zip, EXR_COMPRESSION_ZIP, -1, -1, 1);
    assert_int_equal(tu_nparts(zip), 2);
    for (int p = 0; p < 2; ++p) {
        tu_image z, o;
        read_core(zip, p, &z);
        read_core(orig, p, &o);
        assert_int_equal(z.comp, EXR_COMPRESSION_ZIP);
        assert_int_equal(z.tiled, p == 1);
        assert_int_equal(tu_compare_layout(&o, &z, -1), 0);
        assert_string_equal(z.name, o.name);
        assert_int_equal(compare_with_ref(dwa, p, &z, 1, 0), 0);
        tu_image_free(&z);
        tu_image_free(&o);
    }
    /* Attributes kept; the DWA level dropped with the compression. */
    ef_exr_file f = { 0 };
    ef_err err;
    assert_int_equal(ef_exr_open(zip, &f, &err), 0);
    const char *owner = NULL;
    int32_t len = 0;
    assert_int_equal(exr_attr_get_string(f.ctx, 0, "owner", &len, &owner), EXR_ERR_SUCCESS);
    assert_string_equal(owner, "test_dwa");
    exr_attr_m44f_t m;
    assert_int_equal(exr_attr_get_m44f(f.ctx, 0, "worldToCamera", &m), EXR_ERR_SUCCESS);
    assert_close(m.m[13], 0.25, 0);
    float fov = 0;
    assert_int_equal(exr_attr_get_float(f.ctx, 1, "CameraFov", &fov), EXR_ERR_SUCCESS);
    assert_close(fov, 40, 0);
    assert_false(ef_exr_has_attr(&f, 0, "dwaCompressionLevel"));
    assert_int_equal(ef_exr_dwa_parts(&f), 0);
    ef_exr_close(&f);
    char why[1024];
    if (tu_check_readback_path(zip, why, sizeof why)) {
        print_error("%s\n", why);
        fail();
    }
    /* OpenImageIO reads the DWA file and the ZIP file as the same pixels. */
    if (system("command -v oiiotool >/dev/null 2>&1") == 0) {
        char cmd[4096];
        for (int p = 0; p < 2; ++p) {
            snprintf(cmd, sizeof cmd,
                     "oiiotool '%s' --subimage %d '%s' --subimage %d --diff >/dev/null 2>&1",
                     dwa, p, zip, p);
            if (system(cmd) != 0) {
                print_error("oiiotool --diff of part %d of %s and %s failed\n", p, dwa, zip);
                fail();
            }
        }
    }
    free(orig);
    free(dwa);
    free(zip);
}

/* ZIP -> DWAB:100, and the level really is used; DWA -> DWA copies raw or
 * re-encodes at a new level. */
static void test_dwab_level(void **state)
{
    (void) state;
    char *orig = tu_path("dwa_orig2.exr"), *b100 = tu_path("dwa_b100.exr"),
         *b45 = tu_path("dwa_b45.exr"), *copy = tu_path("dwa_copy.exr"),
         *b300 = tu_path("dwa_b300.exr");
    write_scene(orig, 8);
    must_transcode(orig, b100, -1, EXR_COMPRESSION_DWAB, 100, 2);
    must_transcode(orig, b45, -1, EXR_COMPRESSION_DWAB, -1, 1);
    const int dw0[4] = { -3, 5, 60, 44 }, dw1[4] = { 2, 1, 49, 34 };
    check_ref_header(b100, 0, EXR_COMPRESSION_DWAB, 100, 0, dw0);
    check_ref_header(b100, 1, EXR_COMPRESSION_DWAB, 100, 1, dw1);
    check_ref_header(b45, 0, EXR_COMPRESSION_DWAB, 45, 0, dw0);
    for (int p = 0; p < 2; ++p) {
        tu_image o;
        read_core(orig, p, &o);
        assert_int_equal(compare_with_ref(b100, p, &o, 0, 0.05), 0);
        tu_image_free(&o);
    }
    print_message("DWAB sizes: level 45 %ld bytes, level 100 %ld bytes\n", file_size(b45),
                  file_size(b100));
    assert_true(file_size(b100) < file_size(b45));

    /* DWAB kept at its own level: chunks copied, pixels identical. */
    must_transcode(b100, copy, -1, -1, -1, 1);
    check_ref_header(copy, 0, EXR_COMPRESSION_DWAB, 100, 0, dw0);
    for (int p = 0; p < 2; ++p) {
        tu_image z;
        dwa_ref_info in;
        assert_int_equal(dwa_ref_header(copy, p, &in), 0);
        /* Read the copy by the reference into a tu_image-like compare. */
        memset(&z, 0, sizeof z);
        z.nch = in.nch;
        z.w = in.dw[2] - in.dw[0] + 1;
        z.h = in.dw[3] - in.dw[1] + 1;
        char *names[DWA_REF_MAX_CH];
        void *planes[DWA_REF_MAX_CH];
        exr_pixel_type_t types[DWA_REF_MAX_CH];
        for (int c = 0; c < in.nch; ++c) {
            int w, h;
            names[c] = in.ch[c];
            types[c] = (exr_pixel_type_t) in.type[c];
            planes[c] = dwa_ref_read(copy, p, in.ch[c], &w, &h);
            assert_non_null(planes[c]);
        }
        z.ch = names;
        z.type = types;
        z.plane = planes;
        assert_int_equal(compare_with_ref(b100, p, &z, 1, 0), 0);
        for (int c = 0; c < in.nch; ++c)
            free(planes[c]);
    }
    /* A new level re-encodes, and the attribute follows. */
    must_transcode(b100, b300, -1, EXR_COMPRESSION_DWAB, 300, 1);
    check_ref_header(b300, 1, EXR_COMPRESSION_DWAB, 300, 1, dw1);
    assert_true(file_size(b300) < file_size(b100));
    free(orig);
    free(b100);
    free(b45);
    free(copy);
    free(b300);
}

/* Truncated and missing inputs: -1 with a message, no crash. */
static void test_damaged(void **state)
{
    (void) state;
    char *orig = tu_path("dwa_orig3.exr"), *dwa = tu_path("dwa_t.exr"),
         *cut = tu_path("dwa_cut.exr"), *out = tu_path("dwa_cut_out.exr");
    write_scene(orig, 16);
    must_transcode(orig, dwa, -1, EXR_COMPRESSION_DWAA, -1, 1);
    FILE *fp = fopen(dwa, "rb");
    assert_non_null(fp);
    static unsigned char buf[1 << 20];
    size_t n = fread(buf, 1, sizeof buf, fp);
    fclose(fp);
    const size_t cuts[] = { n * 3 / 4, n / 2, 400 };
    for (int i = 0; i < 3; ++i) {
        assert_int_equal(tu_write_bytes(cut, buf, cuts[i]), 0);
        char msg[1024] = "";
        assert_int_equal(transcode(cut, out, EXR_COMPRESSION_ZIP, -1, -1, 2, msg, sizeof msg), -1);
        print_message("truncated at %zu of %zu bytes: %s\n", cuts[i], n, msg);
        assert_true(strlen(msg) > 10);
        assert_non_null(strstr(msg, "dwa_cut.exr"));
    }
    char msg[1024] = "";
    assert_int_equal(transcode("/nonexistent/x.exr", out, EXR_COMPRESSION_ZIP, -1, -1, 1, msg,
                               sizeof msg),
                     -1);
    assert_contains(msg, "/nonexistent/x.exr");
    ef_err err;
    assert_int_equal(ef_exr_dwa_parts_path("/nonexistent/x.exr", &err), -1);
    assert_contains(err.msg, "/nonexistent/x.exr");
    free(orig);
    free(dwa);
    free(cut);
    free(out);
}

/* ------------------------------------------------------------------ */
/* Bounded memory on a 4K frame                                        */

enum { BW = 4096, BH = 2160, BL = 16 };

/* A smooth depth with float-precision detail. */
static float big_z(int x, int y)
{
    return (float) (10.0 + 0.01 * x + 0.003 * y + 2.0 * sin(0.01 * x) * cos(0.007 * y));
}

/* Writes a BW x BH ZIP frame (R G B A half, Z float) 16 lines at a time,
 * so the writer itself stays small. */
static void write_big(const char *path)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_context_t f;
    int p;
    assert_int_equal(exr_start_write(&f, path, EXR_WRITE_FILE_DIRECTLY, &init), 0);
    assert_int_equal(exr_add_part(f, NULL, EXR_STORAGE_SCANLINE, &p), 0);
    assert_int_equal(exr_initialize_required_attr_simple(f, p, BW, BH, EXR_COMPRESSION_ZIP), 0);
    static const char *const names[5] = { "A", "B", "G", "R", "Z" };
    for (int c = 0; c < 5; ++c)
        assert_int_equal(exr_add_channel(f, p, names[c], c < 4 ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT,
                                         EXR_PERCEPTUALLY_LINEAR, 1, 1),
                         0);
    assert_int_equal(exr_write_header(f), 0);
    float *buf = malloc(sizeof(float) * BW * BL * 5);
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    for (int y0 = 0; y0 < BH; y0 += BL) {
        for (int y = 0; y < BL; ++y)
            for (int x = 0; x < BW; ++x)
                for (int c = 0; c < 5; ++c)
                    buf[(size_t) c * BW * BL + (size_t) y * BW + x] =
                        c == 4 ? big_z(x, y0 + y)
                               : (float) (0.5 + 0.4 * sin(0.003 * x * (c + 1) + 0.002 * (y0 + y)));
        exr_chunk_info_t ci;
        assert_int_equal(exr_write_scanline_chunk_info(f, p, y0, &ci), 0);
        if (y0 == 0)
            assert_int_equal(exr_encoding_initialize(f, p, &ci, &enc), 0);
        else
            assert_int_equal(exr_encoding_update(f, p, &ci, &enc), 0);
        for (int c = 0; c < enc.channel_count; ++c) {
            int k = 0;
            while (strcmp(names[k], enc.channels[c].channel_name))
                ++k;
            enc.channels[c].encode_from_ptr = (const uint8_t *) (buf + (size_t) k * BW * BL);
            enc.channels[c].user_data_type = EXR_PIXEL_FLOAT;
            enc.channels[c].user_bytes_per_element = 4;
            enc.channels[c].user_pixel_stride = 4;
            enc.channels[c].user_line_stride = 4 * BW;
        }
        if (y0 == 0)
            assert_int_equal(exr_encoding_choose_default_routines(f, p, &enc), 0);
        assert_int_equal(exr_encoding_run(f, p, &enc), 0);
    }
    exr_encoding_destroy(f, &enc);
    assert_int_equal(exr_finish(&f), 0);
    free(buf);
}

/* Peak resident set (VmHWM) in kB, after resetting it when the kernel
 * allows (/proc/self/clear_refs 5). */
static long status_kb(const char *key)
{
    FILE *fp = fopen("/proc/self/status", "r");
    char line[256];
    long kb = -1;
    const size_t n = strlen(key);
    while (fp && fgets(line, sizeof line, fp))
        if (!strncmp(line, key, n))
            kb = strtol(line + n, NULL, 10);
    if (fp)
        fclose(fp);
    return kb;
}

static long vm_hwm_kb(void)
{
    return status_kb("VmHWM:");
}

static long vm_rss_kb(void)
{
    return status_kb("VmRSS:");
}

static int reset_hwm(void)
{
    FILE *fp = fopen("/proc/self/clear_refs", "w");
    if (!fp)
        return -1;
    int ok = fputs("5", fp) >= 0;
    return fclose(fp) == 0 && ok ? 0 : -1;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void measure(const char *in, const char *out, int dwa_to, int all_to, int threads,
                    const char *what, double limit_mb)
{
    if (reset_hwm())
        print_message("(cannot reset VmHWM; the growth below is against the earlier peak)\n");
    const long rss0 = vm_rss_kb(), hwm0 = vm_hwm_kb();
    const double t0 = now_s();
    must_transcode(in, out, dwa_to, all_to, -1, threads);
    const double t = now_s() - t0;
    const long growth = vm_hwm_kb() - (hwm0 > rss0 ? hwm0 : rss0);
    print_message("4096x2160 %s, %d thread(s): %.2f s, peak RSS growth %.1f MB (RSS before "
                  "%.1f MB), output %.1f MB\n",
                  what, threads, t, growth / 1024.0, rss0 / 1024.0, file_size(out) / 1048576.0);
    if (!EF_ASAN)   /* ASan's shadow and quarantine inflate the RSS */
        assert_true(growth < limit_mb * 1024);
}

static void test_memory_4k(void **state)
{
    (void) state;
    char *zip = tu_path("dwa_4k_zip.exr"), *dwa = tu_path("dwa_4k_dwaa.exr"),
         *back = tu_path("dwa_4k_back.exr");
    write_big(zip);
    /* DWAA and ZIP chunks are 32 and 16 lines: a few MB per thread. DWAB
     * chunks are 256 lines, and the library keeps two line buffers (each
     * with its compressor's work space) per thread, so exr_dwa.cpp runs a 4K
     * DWAB frame on one thread (its kThreadBudget). */
    measure(zip, dwa, -1, EXR_COMPRESSION_DWAA, 1, "ZIP -> DWAA", 64);
    measure(zip, dwa, -1, EXR_COMPRESSION_DWAA, 2, "ZIP -> DWAA", 64);
    measure(dwa, back, EXR_COMPRESSION_ZIP, -1, 2, "DWAA -> ZIP", 64);
    measure(zip, dwa, -1, EXR_COMPRESSION_DWAB, 1, "ZIP -> DWAB", 64);
    measure(zip, dwa, -1, EXR_COMPRESSION_DWAB, 2, "ZIP -> DWAB", 64);
    measure(dwa, back, EXR_COMPRESSION_ZIP, -1, 2, "DWAB -> ZIP", 64);
    /* Z went through DWAB losslessly. */
    int w, h;
    float *z = tu_read_channel(back, 0, "Z", &w, &h);
    assert_non_null(z);
    assert_int_equal(w, BW);
    long bad = 0;
    for (int y = 0; y < BH; ++y)
        for (int x = 0; x < BW; ++x)
            bad += z[(size_t) y * BW + x] != big_z(x, y);
    assert_int_equal(bad, 0);
    free(z);
    remove(zip);
    remove(dwa);
    remove(back);
    free(zip);
    free(dwa);
    free(back);
}

/* ------------------------------------------------------------------ */
/* Real files                                                          */

/* A real multi-part render (the Beachball, multi-view, half Z) through
 * DWAB and back; an oiiotool-written DWAA file (another writer) through
 * the transcoder; a deep file refused. */
static void test_real(void **state)
{
    (void) state;
    const char *dir = tu_real_exr_dir();
    if (!dir)
        skip();
    char src[1024];
    snprintf(src, sizeof src, "%s/beachball-multipart.0001.exr", dir);
    if (!tu_exists(src))
        skip();
    char *dwa = tu_path("dwa_real_b.exr"), *zip = tu_path("dwa_real_zip.exr");
    must_transcode(src, dwa, -1, EXR_COMPRESSION_DWAB, -1, 2);
    must_transcode(dwa, zip, EXR_COMPRESSION_ZIP, -1, -1, 2);
    const int np = tu_nparts(src);
    assert_true(np > 1);
    assert_int_equal(tu_nparts(zip), np);
    for (int p = 0; p < np; ++p) {
        tu_image o, z;
        read_core(src, p, &o);
        read_core(zip, p, &z);
        assert_int_equal(tu_compare_layout(&o, &z, -1), 0);
        assert_int_equal(compare_with_ref(dwa, p, &o, 0, 0.05), 0);  /* vs the original */
        assert_int_equal(compare_with_ref(dwa, p, &z, 1, 0), 0);     /* vs the DWA decode */
        tu_image_free(&o);
        tu_image_free(&z);
    }
    if (system("command -v oiiotool >/dev/null 2>&1") == 0) {
        char cmd[4096], *odwa = tu_path("dwa_real_oiio.exr"), *ozip = tu_path("dwa_real_oz.exr");
        char single[1024];
        snprintf(single, sizeof single, "%s/beachball-singlepart.0001.exr", dir);
        snprintf(cmd, sizeof cmd, "oiiotool '%s' --compression dwaa:60 -o '%s' >/dev/null 2>&1",
                 single, odwa);
        if (tu_exists(single) && system(cmd) == 0) {
            must_transcode(odwa, ozip, EXR_COMPRESSION_ZIP, -1, -1, 2);
            tu_image z;
            read_core(ozip, 0, &z);
            assert_int_equal(z.comp, EXR_COMPRESSION_ZIP);
            assert_int_equal(compare_with_ref(odwa, 0, &z, 1, 0), 0);
            tu_image_free(&z);
        }
        free(odwa);
        free(ozip);
    }
    char deep[1024];
    snprintf(deep, sizeof deep, "%s/arnold-deep-representative.exr", dir);
    if (tu_exists(deep)) {
        char msg[1024] = "";
        assert_int_equal(transcode(deep, zip, EXR_COMPRESSION_ZIP, -1, -1, 1, msg, sizeof msg),
                         -1);
        assert_contains(msg, "deep");
    }
    free(dwa);
    free(zip);
}

/* The command line with DWA (issue 9): --compression dwaa:60 writes a
 * DWAA file of level 60 whose depth is the input's bit for bit; that file
 * as INPUT is decoded (by the C++ library) and written back as DWAA level
 * 60, depth again bit-exact; --compression zip on it writes ZIP whose
 * colour is the exp fog of the DWA-decoded colour (checked per pixel). */
static void test_cli_dwa(void **state)
{
    (void) state;
    enum { CW = 64, CH = 40 };
    static float r[CW * CH], g[CW * CH], b[CW * CH], a[CW * CH], z[CW * CH];
    for (int i = 0; i < CW * CH; ++i) {
        const int x = i % CW, y = i / CW;
        r[i] = 0.2f + 0.6f * (float) x / CW;
        g[i] = 0.3f + 0.4f * (float) y / CH;
        b[i] = 0.5f;
        a[i] = 1.0f;
        z[i] = 3.0f + 0.05f * (float) (x + y);
    }
    tu_part p;
    tu_part_init(&p, CW, CH);
    tu_part_add(&p, "R", EXR_PIXEL_HALF, r);
    tu_part_add(&p, "G", EXR_PIXEL_HALF, g);
    tu_part_add(&p, "B", EXR_PIXEL_HALF, b);
    tu_part_add(&p, "A", EXR_PIXEL_HALF, a);
    tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, z);
    static const float id[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    p.m44[0].name = "worldToCamera";
    memcpy(p.m44[0].m, id, sizeof id);
    p.f[0].name = "CameraFov";
    p.f[0].v = 60.0f;
    char *in = tu_path("cli_dwa_in.exr"), *d1 = tu_path("cli_dwa_1.exr"),
         *d2 = tu_path("cli_dwa_2.exr"), *zp = tu_path("cli_dwa_zip.exr"),
         *dec = tu_path("cli_dwa_1_decoded.exr");
    assert_int_equal(tu_write_exr(in, &p, 1), 0);
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.05 --fog-color 0.25,0.5,0.75 "
                             "--compression dwaa:60", in, d1), 0);
    dwa_ref_info info;
    for (int k = 0; k < 2; ++k) {
        if (k)
            assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.05", d1, d2), 0);
        const char *f = k ? d2 : d1;
        assert_int_equal(dwa_ref_header(f, 0, &info), 0);
        assert_int_equal(info.compression, EXR_COMPRESSION_DWAA);
        assert_true(info.level == 60.0f);
        int w, h;
        float *zo = dwa_ref_read(f, 0, "Z", &w, &h);
        assert_non_null(zo);
        assert_int_equal(memcmp(zo, z, sizeof z), 0);
        free(zo);
    }
    /* the DWA input decoded by the reference library, as a ZIP file, is
     * what the fog must start from */
    int w, h;
    float *pl[5];
    static const char *const names[5] = { "R", "G", "B", "A", "Z" };
    tu_part q;
    tu_part_init(&q, CW, CH);
    for (int k = 0; k < 5; ++k) {
        pl[k] = dwa_ref_read(d1, 0, names[k], &w, &h);
        assert_non_null(pl[k]);
        tu_part_add(&q, names[k], k < 4 ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT, pl[k]);
    }
    assert_int_equal(tu_write_exr(dec, &q, 1), 0);
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.05 --fog-color 0.25,0.5,0.75 "
                             "--compression zip", d1, zp), 0);
    tu_pinhole pin;
    const int disp[4] = { 0, 0, CW - 1, CH - 1 };
    tu_pinhole_fov(&pin, disp, 60.0);
    tu_fog_check fc;
    tu_fog_check_init(&fc, dec, zp, &pin, 0.05);
    assert_int_equal(tu_check_fog(&fc), 0);
    assert_true(fc.fogged > 100);
    for (int k = 0; k < 5; ++k)
        free(pl[k]);
    free(in);
    free(d1);
    free(d2);
    free(zp);
    free(dec);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_parse),
        cmocka_unit_test(test_roundtrip),
        cmocka_unit_test(test_dwab_level),
        cmocka_unit_test(test_damaged),
        cmocka_unit_test(test_real),
        cmocka_unit_test(test_cli_dwa),
        cmocka_unit_test(test_memory_4k),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
