/* The stream's own half <-> float conversion (src/io/half_conv.c) against
 * Imath's (what OpenEXRCore's unpack and pack use): every half one way,
 * 2^24 spread floats and every NaN pattern the other, scalar and vector;
 * then whole files fogged with and without it (EXRFOG_F16C=0) must be the
 * same bytes, through half channels full of NaN payloads, infinities,
 * subnormals and rounding ties, in every compression, scanline and tiled. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

/* the bit-twiddling half to float (the table the library may use holds its
 * results); no link to libImath needed */
#define IMATH_HALF_NO_LOOKUP_TABLE
#include <Imath/half.h>

#include "half_conv.h"
#include "tassert.h"
#include "testutil.h"

static uint32_t fbits(float f)
{
    uint32_t b;
    memcpy(&b, &f, sizeof b);
    return b;
}

static float bitsf(uint32_t b)
{
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

/* Every half to float, scalar and vector (in runs of odd lengths, so the
 * vector loop's tail is exercised too), bit for bit as Imath. */
static void test_every_half(void **state)
{
    (void) state;
    uint16_t *h = malloc(65536 * sizeof *h);
    float *f = malloc(65536 * sizeof *f);
    assert_non_null(h);
    assert_non_null(f);
    for (uint32_t i = 0; i < 65536; ++i)
        h[i] = (uint16_t) i;
    for (size_t at = 0; at < 65536;) {
        const size_t n = at + 13 <= 65536 ? 13 : 65536 - at;
        ef_half_to_float(h + at, f + at, n);
        at += n;
    }
    for (uint32_t i = 0; i < 65536; ++i) {
        const uint32_t want = fbits(imath_half_to_float((imath_half_bits_t) i));
        assert_int_equal(ef_half_bits_to_float((uint16_t) i), want);
        assert_int_equal(fbits(f[i]), want);
    }
    free(h);
    free(f);
}

/* Floats to half: every 256th bit pattern (2^24 of them, all exponents,
 * signs and NaN classes), every float NaN and infinity pattern whose low
 * 13 payload bits are 0 or 1, and the values next to every half rounding
 * tie, scalar and vector, bit for bit as Imath's imath_float_to_half. */
static void test_floats_to_half(void **state)
{
    (void) state;
    enum { N = 1 << 16 };
    float *f = malloc(N * sizeof *f);
    uint16_t *h = malloc(N * sizeof *h);
    assert_non_null(f);
    assert_non_null(h);
    long checked = 0;
    for (uint64_t base = 0; base < (1ull << 32); base += (uint64_t) N * 256) {
        for (uint32_t i = 0; i < N; ++i)
            f[i] = bitsf((uint32_t) (base + (uint64_t) i * 256 + (i % 251)));
        ef_float_to_half(f, h, N);
        for (uint32_t i = 0; i < N; ++i) {
            const uint16_t want = imath_float_to_half(f[i]);
            assert_int_equal(ef_float_bits_to_half(fbits(f[i])), want);
            assert_int_equal(h[i], want);
        }
        checked += N;
    }
    /* NaN and infinity patterns, both signs */
    for (uint32_t m = 0; m < (1u << 10); ++m)
        for (int low = 0; low < 2; ++low)
            for (int s = 0; s < 2; ++s) {
                const float x = bitsf((s ? 0x80000000u : 0) | 0x7f800000u | (m << 13) | (uint32_t) low);
                uint16_t v[9];
                float xs[9];
                for (int k = 0; k < 9; ++k)
                    xs[k] = k == 4 ? x : 1.0f;
                ef_float_to_half(xs, v, 9);
                assert_int_equal(v[4], imath_float_to_half(x));
                assert_int_equal(ef_float_bits_to_half(fbits(x)), imath_float_to_half(x));
                checked++;
            }
    /* around every half: its value and the midpoints to its neighbours */
    for (uint32_t i = 0; i < 0x7c00; ++i) {
        const float a = imath_half_to_float((imath_half_bits_t) i),
                    b = imath_half_to_float((imath_half_bits_t) (i + 1));
        const float mid = (float) (((double) a + (double) b) / 2);
        const float xs[8] = { a, mid, nextafterf(mid, 0), nextafterf(mid, INFINITY),
                              -a, -mid, -nextafterf(mid, 0), -nextafterf(mid, INFINITY) };
        uint16_t v[8];
        ef_float_to_half(xs, v, 8);
        for (int k = 0; k < 8; ++k) {
            assert_int_equal(v[k], imath_float_to_half(xs[k]));
            assert_int_equal(ef_float_bits_to_half(fbits(xs[k])), imath_float_to_half(xs[k]));
        }
        checked += 8;
    }
    printf("  %ld floats to half, all as Imath\n", checked);
    free(f);
    free(h);
}

/* A value for pixel i of a half channel that stresses the conversion:
 * NaNs sparse enough that most runs of 8 have none (a run with one is
 * converted by the scalar rule, the rest by F16C). */
static float nasty(uint32_t *g, long i)
{
    switch (i % 61) {
    case 0:   /* a NaN of any payload (half signalling ones included) and sign */
        return bitsf((tu_xorshift32(g) & 0x80000000u) | 0x7f800000u |
                     ((tu_xorshift32(g) & 0x3ff) << 13) | 0x2000);
    case 1:
        return (i & 1) ? INFINITY : -INFINITY;
    case 2:
    case 3:
    case 4:   /* half subnormals */
        return (float) ((double) (tu_xorshift32(g) & 0x3ff) * 0x1p-24);
    case 5:
        return (i & 1) ? 65504.0f : -0.0f;
    default:  /* magnitudes over many binades */
        return (float) (tu_rand01(g) * pow(2.0, (double) (i % 23) - 11));
    }
}

/* exrfog with and without its own conversion: the same output bytes. With
 * it, the stream also unpacks and packs the chunk layout itself (half,
 * float and uint channels, every row segment), so the Core path compared
 * against covers that too: as written (half out), -d half, -d float (half
 * channels written as float) and AOV channels added among the others. */
static void test_same_files(void **state)
{
    (void) state;
    static const exr_compression_t comps[] = { EXR_COMPRESSION_NONE, EXR_COMPRESSION_ZIP,
                                               EXR_COMPRESSION_PIZ, EXR_COMPRESSION_RLE };
    const int w = 67, hgt = 45;
    const long n = (long) w * hgt;
    float *pl[6];
    uint32_t *ids = malloc((size_t) n * sizeof *ids);
    assert_non_null(ids);
    uint32_t g = 12345;
    for (long i = 0; i < n; ++i)
        ids[i] = tu_xorshift32(&g);
    for (int c = 0; c < 6; ++c) {
        pl[c] = malloc((size_t) n * sizeof(float));
        assert_non_null(pl[c]);
        for (long i = 0; i < n; ++i)
            pl[c][i] = c == 5 ? (float) (1 + tu_rand01(&g) * 50) : nasty(&g, i + c);
    }
    for (int k = 0; k < 8; ++k) {
        tu_part p;
        tu_part_init(&p, w, hgt);
        p.comp = comps[k % 4];
        p.tile = k >= 4 ? 16 : 0;
        tu_part_add(&p, "R", EXR_PIXEL_HALF, pl[0]);
        tu_part_add(&p, "G", EXR_PIXEL_HALF, pl[1]);
        tu_part_add(&p, "B", EXR_PIXEL_HALF, pl[2]);
        tu_part_add(&p, "A", EXR_PIXEL_HALF, pl[3]);
        tu_part_add(&p, "extra.X", EXR_PIXEL_HALF, pl[4]);
        tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, pl[5]);
        tu_part_add_uint(&p, "id", ids);
        char name[64], o1[64], o2[64];
        snprintf(name, sizeof name, "half_in%d.exr", k);
        snprintf(o1, sizeof o1, "half_own%d.exr", k);
        snprintf(o2, sizeof o2, "half_core%d.exr", k);
        char *in = tu_path(name), *a = tu_path(o1), *b = tu_path(o2);
        assert_int_equal(tu_write_exr(in, &p, 1), 0);
        for (int d = 0; d < 4; ++d) {
            static const char *const variants[] = { "", "-d half", "-d float",
                                                    "--aov fog,T,distance" };
            const char *flags = variants[d];
            assert_run(0, "--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 40 "
                          "--fog exp:density=0.05 %s '%s' -o '%s'", flags, in, a);
            assert_int_equal(setenv("EXRFOG_F16C", "0", 1), 0);
            assert_run(0, "--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 40 "
                          "--fog exp:density=0.05 %s '%s' -o '%s'", flags, in, b);
            unsetenv("EXRFOG_F16C");
            char cmd[1024];
            snprintf(cmd, sizeof cmd, "cmp -s '%s' '%s'", a, b);
            if (system(cmd) != 0) {
                print_error("%s (%s): outputs differ with and without F16C\n", name, flags);
                fail();
            }
        }
        free(in);
        free(a);
        free(b);
    }
    for (int c = 0; c < 6; ++c)
        free(pl[c]);
    free(ids);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_half),
        cmocka_unit_test(test_floats_to_half),
        cmocka_unit_test(test_same_files),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
