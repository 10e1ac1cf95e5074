/* ZIP/ZIPS through libdeflate (src/io/exr_deflate.c) and the ordered
 * writer's ring (src/io/exr_ring.c).
 *
 * Files are written here with OpenEXRCore (stock zlib), re-encoded with
 * libdeflate by bench/floor (a transcode, no per-pixel work) and by exrfog
 * --codec libdeflate, and read back by OpenEXRCore's own zlib path
 * (testutil), by the OpenEXR C++ library (exrmaketiled, when installed)
 * and by OpenImageIO (oiiotool --diff, when installed). The byte
 * transforms are checked against a plain reading of the format's ZIP
 * definition; outputs are byte-identical for any --threads; a corrupt
 * chunk is a clean error. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "exr_deflate.h"
#include "exr_ring.h"
#include "testutil.h"

static const char *const CAMERA =
    "--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 50 --fog exp:density=0.02";

static uint32_t rng = 88172645u;
static uint32_t next_rand(void)
{
    return tu_xorshift32(&rng);
}

/* A scratch path unique to this process. */
static char *scratch(const char *name)
{
    char n[128];
    snprintf(n, sizeof n, "codec.%ld.%s", (long) getpid(), name);
    return tu_path(n);
}

/* bench/floor beside the exrfog binary. */
static char *floor_bin(void)
{
    const char *bin = getenv("EXRFOG_BIN");
    assert_non_null(bin);
    const char *slash = strrchr(bin, '/');
    const size_t n = slash ? (size_t) (slash - bin) + 1 : 0;
    char *p = malloc(n + 8);
    memcpy(p, bin, n);
    strcpy(p + n, "floor");
    return p;
}

static int sh(const char *fmt, ...)
{
    char cmd[8192];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    const int st = system(cmd);
    return st == -1 ? -1 : (st >> 8) & 0xff;
}

static int have(const char *tool)
{
    return sh("command -v %s >/dev/null 2>&1", tool) == 0;
}

/* Whole-file bytes equal. */
static int same_bytes(const char *a, const char *b)
{
    return sh("cmp -s '%s' '%s'", a, b) == 0;
}

/* ---- the byte transforms -------------------------------------------- */

/* The format's definition, written plainly: even bytes then odd bytes,
 * then every byte but the first replaced by (b - previous + 128). */
static void reference_deconstruct(uint8_t *dst, const uint8_t *src, size_t n)
{
    uint8_t *t = malloc(n + 1);
    size_t k = 0;
    for (size_t i = 0; i < n; i += 2)
        t[k++] = src[i];
    for (size_t i = 1; i < n; i += 2)
        t[k++] = src[i];
    for (size_t i = 0; i < n; ++i)
        dst[i] = i ? (uint8_t) (t[i] - t[i - 1] + 128) : t[0];
    free(t);
}

static void test_transforms(void **state)
{
    (void) state;
    static const size_t sizes[] = { 0, 1, 2, 3, 15, 16, 17, 31, 32, 33, 34, 47, 63, 64, 65,
                                    100, 257, 1023, 4096, 4099, 65537 };
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; ++s) {
        const size_t n = sizes[s];
        uint8_t *src = malloc(n + 1), *ref = malloc(n + 1), *got = malloc(n + 1),
                *back = malloc(n + 1);
        for (size_t i = 0; i < n; ++i)
            src[i] = (uint8_t) (i % 7 == 0 ? next_rand() : (i * 3) ^ (i >> 5));
        reference_deconstruct(ref, src, n);
        ef_zip_deconstruct(got, src, n);
        assert_memory_equal(ref, got, n);
        ef_zip_reconstruct(back, got, n);
        assert_memory_equal(src, back, n);
        free(src);
        free(ref);
        free(got);
        free(back);
    }
    /* the level map */
    assert_int_equal(ef_deflate_level(-1), EF_DEFLATE_DEFAULT_LEVEL);
    assert_int_equal(ef_deflate_level(1), 1);
    assert_int_equal(ef_deflate_level(9), 9);
}

/* ---- files ---------------------------------------------------------- */

/* A W x H image at data window origin (x0, y0): R half, G float, id uint,
 * B half, Z float; noisy gradients (they compress, not to nothing). When random,
 * every channel is random bits (nothing compresses). */
typedef struct test_image {
    float *r, *g, *b, *z;
    uint32_t *id;
} test_image;

static void make_file(const char *path, int w, int h, int x0, int y0, exr_compression_t comp,
                      int tile, int random, test_image *im)
{
    const size_t n = (size_t) w * (size_t) h;
    im->r = malloc(n * sizeof(float));
    im->g = malloc(n * sizeof(float));
    im->b = malloc(n * sizeof(float));
    im->z = malloc(n * sizeof(float));
    im->id = malloc(n * sizeof(uint32_t));
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const size_t i = (size_t) y * (size_t) w + (size_t) x;
            const float noise = (float) (next_rand() % 1000) * 1e-4f;
            im->r[i] = random ? (float) (next_rand() % 60000) : 0.25f + 0.01f * (float) x + noise;
            im->g[i] = random ? (float) next_rand() * 1e-6f : 0.5f + 0.002f * (float) y + noise;
            im->b[i] = random ? (float) (next_rand() % 1000) : 0.1f + 0.003f * (float) (x ^ y);
            im->z[i] = random ? 1.0f + (float) (next_rand() % 100000) : 5.0f + 0.1f * (float) (x + y);
            im->id[i] = random ? next_rand() : (uint32_t) (x / 4 + 1000 * (y / 4));
        }
    tu_part p;
    tu_part_init(&p, w, h);
    p.dw[0] = x0;
    p.dw[1] = y0;
    p.dw[2] = x0 + w - 1;
    p.dw[3] = y0 + h - 1;
    p.disp[0] = x0 < 0 ? x0 : 0;
    p.disp[1] = y0 < 0 ? y0 : 0;
    p.disp[2] = x0 + w + 3;
    p.disp[3] = y0 + h + 2;
    p.comp = comp;
    p.tile = tile;
    tu_part_add(&p, "R", EXR_PIXEL_HALF, im->r);
    tu_part_add(&p, "G", EXR_PIXEL_FLOAT, im->g);
    tu_part_add(&p, "B", EXR_PIXEL_HALF, im->b);
    tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, im->z);
    tu_part_add_uint(&p, "id", im->id);
    assert_int_equal(tu_write_exr(path, &p, 1), 0);
}

static void free_image(test_image *im)
{
    free(im->r);
    free(im->g);
    free(im->b);
    free(im->z);
    free(im->id);
}

/* b's pixels are a's, by OpenEXRCore (stock zlib), and by the C++ library
 * and OpenImageIO when they are installed. */
static void assert_same_pixels(const char *a, const char *b)
{
    assert_int_equal(tu_compare_files(a, b, -1, NULL), 0);
    if (have("oiiotool"))
        assert_int_equal(sh("oiiotool --diff '%s' '%s' >/dev/null 2>&1", a, b), 0);
    if (have("exrmaketiled")) {
        /* exrmaketiled reads every pixel of b with the OpenEXR C++ library
         * (its own zlib) and writes them tiled, uncompressed. */
        char *t = scratch("cxx.exr");
        assert_int_equal(sh("exrmaketiled -z none '%s' '%s' >/dev/null 2>&1", b, t), 0);
        tu_image ia, it;
        assert_int_equal(tu_read_image(a, 0, &ia), 0);
        assert_int_equal(tu_read_image(t, 0, &it), 0);
        for (int c = 0; c < ia.nch; ++c)
            assert_int_equal(tu_compare_channel(&ia, &it, ia.ch[c], 0.0, 0), 0);
        tu_image_free(&ia);
        tu_image_free(&it);
        unlink(t);
        free(t);
    }
}

/* Every case: libdeflate writes what every reader reads back exactly, and
 * libdeflate reads what zlib wrote exactly. */
static void test_libdeflate_files_read_back(void **state)
{
    (void) state;
    static const struct {
        int w, h, x0, y0, tile;
        exr_compression_t comp;
    } cases[] = {
        { 37, 29, 0, 0, 0, EXR_COMPRESSION_ZIP },      /* odd width */
        { 37, 41, -5, 7, 0, EXR_COMPRESSION_ZIPS },    /* window not at 0 */
        { 53, 70, 11, -9, 16, EXR_COMPRESSION_ZIP },   /* tiled, partial tiles */
        { 45, 33, 3, 2, 32, EXR_COMPRESSION_ZIPS },
        { 1, 1, 0, 0, 0, EXR_COMPRESSION_ZIP },        /* one pixel */
    };
    char *fl = floor_bin();
    char *in = scratch("in.exr"), *ld = scratch("ld.exr"), *raw = scratch("raw.exr");
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
        test_image im;
        make_file(in, cases[k].w, cases[k].h, cases[k].x0, cases[k].y0, cases[k].comp,
                  cases[k].tile, 0, &im);
        /* zlib file -> libdeflate decode -> libdeflate encode */
        assert_int_equal(sh("'%s' --threads 2 --codec libdeflate '%s' '%s'", fl, in, ld), 0);
        assert_same_pixels(in, ld);
        /* exrfog: libdeflate decodes the zlib file exactly as zlib does
         * (uncompressed outputs, every pixel; the headers differ only in
         * the recorded command line) ... */
        assert_run(0, "--codec zlib --compression none %s '%s' -o '%s'", CAMERA, in, raw);
        assert_run(0, "--codec libdeflate --compression none %s '%s' -o '%s'", CAMERA, in, ld);
        assert_int_equal(tu_compare_files(raw, ld, -1, NULL), 0);
        /* ... and the same pixels whichever codec reads and writes */
        assert_run(0, "--codec zlib %s '%s' -o '%s'", CAMERA, in, raw);
        assert_run(0, "--codec libdeflate %s '%s' -o '%s'", CAMERA, in, ld);
        assert_same_pixels(raw, ld);
        free_image(&im);
    }
    unlink(in);
    unlink(ld);
    unlink(raw);
    free(in);
    free(ld);
    free(raw);
    free(fl);
}

/* packed_size of every chunk of a scanline part equals unpacked_size. */
static int all_chunks_raw(const char *path)
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    if (exr_start_read(&f, path, &init))
        return -1;
    exr_attr_box2i_t dw;
    int lines = 1, raw = 1;
    exr_get_data_window(f, 0, &dw);
    exr_get_scanlines_per_chunk(f, 0, &lines);
    for (int y = dw.min.y; y <= dw.max.y; y += lines) {
        exr_chunk_info_t ci;
        if (exr_read_scanline_chunk_info(f, 0, y, &ci) || ci.packed_size != ci.unpacked_size)
            raw = 0;
    }
    exr_finish(&f);
    return raw;
}

/* Random bytes do not shrink: the chunk is stored raw, as Core does. */
static void test_incompressible_stored_raw(void **state)
{
    (void) state;
    char *fl = floor_bin();
    char *in = scratch("rand.exr"), *ld = scratch("rand_ld.exr"), *zl = scratch("rand_zl.exr");
    test_image im;
    make_file(in, 64, 40, 0, 0, EXR_COMPRESSION_ZIPS, 0, 1, &im);
    assert_int_equal(sh("'%s' --codec zlib '%s' '%s'", fl, in, zl), 0);
    assert_int_equal(sh("'%s' --codec libdeflate '%s' '%s'", fl, in, ld), 0);
    assert_int_equal(all_chunks_raw(zl), 1);
    assert_int_equal(all_chunks_raw(ld), 1);
    /* stored raw, the two codecs write the same file */
    assert_true(same_bytes(zl, ld));
    assert_same_pixels(in, ld);
    free_image(&im);
    unlink(in);
    unlink(ld);
    unlink(zl);
    free(in);
    free(ld);
    free(zl);
    free(fl);
}

/* Byte-identical output for any --threads, with both codecs, exrfog and
 * the floor, on files of many units (scanline ZIPS: 1-row chunks; tiled). */
static void test_threads_identical(void **state)
{
    (void) state;
    char *fl = floor_bin();
    char *in = scratch("mt.exr"), *a = scratch("mt1.exr"), *b = scratch("mt2.exr");
    static const char *const codecs[] = { "libdeflate", "zlib" };
    for (int tiled = 0; tiled < 2; ++tiled) {
        test_image im;
        make_file(in, 203, 157, -3, 5, tiled ? EXR_COMPRESSION_ZIP : EXR_COMPRESSION_ZIPS,
                  tiled ? 16 : 0, 0, &im);
        for (int c = 0; c < 2; ++c) {
            assert_run(0, "--threads 1 --codec %s %s '%s' -o '%s'", codecs[c], CAMERA, in, a);
            for (int t = 2; t <= 3; ++t) {
                assert_run(0, "--threads %d --codec %s %s '%s' -o '%s'", t, codecs[c], CAMERA,
                           in, b);
                assert_true(same_bytes(a, b));
            }
            assert_int_equal(sh("'%s' --threads 1 --codec %s '%s' '%s'", fl, codecs[c], in, a), 0);
            assert_int_equal(sh("'%s' --threads 3 --codec %s '%s' '%s'", fl, codecs[c], in, b), 0);
            assert_true(same_bytes(a, b));
        }
        free_image(&im);
    }
    /* --stats reports the ring's wait */
    assert_run(0, "--threads 2 --stats %s '%s' -o '%s'", CAMERA, in, a);
    assert_non_null(strstr(tu_err, ", wait "));
    unlink(in);
    unlink(a);
    unlink(b);
    free(in);
    free(a);
    free(b);
    free(fl);
}

/* Bad --codec values are usage errors. */
static void test_codec_option(void **state)
{
    (void) state;
    assert_true(tu_runf("--codec gzip %s in.exr -o out.exr", CAMERA) != 0);
    assert_non_null(strstr(tu_err, "--codec 'gzip'"));
}

/* A corrupt ZIP chunk: a clean error from exrfog and the floor, whichever
 * codec reads it, and no crash (the suite also runs under ASan). */
static void test_corrupt_chunk(void **state)
{
    (void) state;
    char *fl = floor_bin();
    char *in = scratch("good.exr"), *bad = scratch("bad.exr"), *out = scratch("bad_out.exr");
    test_image im;
    make_file(in, 96, 64, 0, 0, EXR_COMPRESSION_ZIP, 0, 0, &im);
    /* find the second chunk's data and scribble over its middle */
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    assert_int_equal(exr_start_read(&f, in, &init), 0);
    exr_chunk_info_t ci;
    assert_int_equal(exr_read_scanline_chunk_info(f, 0, 16, &ci), 0);
    exr_finish(&f);
    assert_true(ci.packed_size < ci.unpacked_size && ci.packed_size > 16);
    FILE *fp = fopen(in, "rb");
    assert_non_null(fp);
    fseek(fp, 0, SEEK_END);
    const long len = ftell(fp);
    rewind(fp);
    uint8_t *bytes = malloc((size_t) len);
    assert_int_equal(fread(bytes, 1, (size_t) len, fp), (size_t) len);
    fclose(fp);
    static const char *const codecs[] = { "libdeflate", "zlib" };
    for (int mode = 0; mode < 2; ++mode) {
        uint8_t *b = malloc((size_t) len);
        memcpy(b, bytes, (size_t) len);
        if (mode == 0) {       /* garbage in the middle of the stream */
            for (uint64_t i = ci.packed_size / 3; i < ci.packed_size / 3 + 12; ++i)
                b[ci.data_offset + i] ^= 0x5a;
        } else {               /* a stream that decodes short: header kept, rest zeroed */
            memset(b + ci.data_offset + 2, 0, (size_t) ci.packed_size - 2);
        }
        assert_int_equal(tu_write_bytes(bad, b, (size_t) len), 0);
        free(b);
        for (int c = 0; c < 2; ++c) {
            const int st = tu_runf("--codec %s %s '%s' -o '%s'", codecs[c], CAMERA, bad, out);
            assert_int_equal(st, 1);
            assert_non_null(strstr(tu_err, "corrupt"));
            assert_false(tu_exists(out));
            const int fs = sh("'%s' --codec %s '%s' '%s' 2>/dev/null", fl, codecs[c], bad, out);
            assert_int_equal(fs, 1);
        }
    }
    free(bytes);
    free_image(&im);
    unlink(in);
    unlink(bad);
    unlink(out);
    free(in);
    free(bad);
    free(out);
    free(fl);
}

/* The ring alone: units put in any order are written in order, once. */
typedef struct ring_log {
    int order[64], n;
} ring_log;

static int log_write(void *user, int u, const ef_unit_buf *b)
{
    ring_log *l = user;
    assert_int_equal(b->n, 1);
    assert_int_equal(b->y[0], u);
    l->order[l->n++] = u;
    return 0;
}

static void test_ring_order(void **state)
{
    (void) state;
    ef_ring r;
    ring_log l = { { 0 }, 0 };
    assert_int_equal(ef_ring_init(&r, 4, 10, log_write, &l), 0);
    ef_unit_buf b = { 0 };
    int claimed[4];
    for (int i = 0; i < 4; ++i)
        claimed[i] = ef_ring_claim(&r);
    /* finish 3, 1, 2 before 0: nothing is written until 0 is in */
    static const int put[] = { 3, 1, 2 };
    for (int i = 0; i < 3; ++i) {
        assert_int_equal(ef_unit_append(&b, "x", 1, claimed[put[i]], 0), 0);
        assert_int_equal(ef_ring_put(&r, claimed[put[i]], &b), 0);
    }
    assert_int_equal(l.n, 0);
    assert_int_equal(ef_unit_append(&b, "x", 1, claimed[0], 0), 0);
    assert_int_equal(ef_ring_put(&r, claimed[0], &b), 0);
    assert_int_equal(l.n, 4);
    for (int u; (u = ef_ring_claim(&r)) >= 0;) {
        assert_int_equal(ef_unit_append(&b, "x", 1, u, 0), 0);
        assert_int_equal(ef_ring_put(&r, u, &b), 0);
    }
    assert_int_equal(l.n, 10);
    for (int i = 0; i < 10; ++i)
        assert_int_equal(l.order[i], i);
    ef_unit_free(&b);
    ef_ring_destroy(&r);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_transforms),
        cmocka_unit_test(test_ring_order),
        cmocka_unit_test(test_codec_option),
        cmocka_unit_test(test_libdeflate_files_read_back),
        cmocka_unit_test(test_incompressible_stored_raw),
        cmocka_unit_test(test_threads_identical),
        cmocka_unit_test(test_corrupt_chunk),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
