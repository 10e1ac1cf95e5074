/* See half_conv.h. The vector paths convert 8 values at a time and redo
 * NaN lanes with the scalar rule: F16C quiets a NaN, OpenEXR keeps its
 * payload's top bits as they are. */
#include "half_conv.h"

#include <stdlib.h>
#include <string.h>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#if defined(__clang__)
#include <cpuid.h>
#endif
#define EF_HAVE_F16C 1
#endif

uint32_t ef_half_bits_to_float(uint16_t h)
{
    const uint32_t s = (uint32_t) (h & 0x8000) << 16, m = h & 0x3ff;
    int e = (h >> 10) & 0x1f;
    if (e == 0x1f)
        return s | 0x7f800000u | (m << 13);   /* inf, or NaN with its payload */
    if (e == 0) {
        if (m == 0)
            return s;
        /* subnormal: normalise (value m 2^-24) */
        uint32_t mm = m;
        e = 1;
        while (!(mm & 0x400)) {
            mm <<= 1;
            --e;
        }
        return s | ((uint32_t) (e + 112) << 23) | ((mm & 0x3ff) << 13);
    }
    return s | ((uint32_t) (e + 112) << 23) | (m << 13);
}

uint16_t ef_float_bits_to_half(uint32_t x)
{
    const uint16_t s = (uint16_t) ((x >> 16) & 0x8000);
    const uint32_t a = x & 0x7fffffffu;
    if (a >= 0x7f800000u) {
        if (a == 0x7f800000u)
            return s | 0x7c00;
        const uint32_t m = (a & 0x7fffff) >> 13;   /* NaN: the payload's top, never 0 */
        return (uint16_t) (s | 0x7c00 | m | (m == 0));
    }
    if (a >= 0x477ff000u)   /* from 65520 on, nearest even is past 65504 */
        return s | 0x7c00;
    if (a >= 0x38800000u) {   /* a normal half: rebias, round to nearest even */
        const uint32_t b = a - 0x38000000u;
        return (uint16_t) (s | ((b + 0xfff + ((b >> 13) & 1)) >> 13));
    }
    if (a <= 0x33000000u)   /* at most half the smallest subnormal: 0 (a tie goes to even) */
        return s;
    /* a subnormal half: the value in units of 2^-24, to nearest even */
    const int e = (int) (a >> 23), sh = 126 - e;
    const uint32_t m = (a & 0x7fffff) | 0x800000, half = 1u << (sh - 1);
    uint32_t r = m >> sh;
    const uint32_t rem = m & ((1u << sh) - 1);
    r += rem > half || (rem == half && (r & 1));
    return (uint16_t) (s | r);
}

static void h2f_scalar(const uint16_t *h, float *f, size_t n)
{
    for (size_t i = 0; i < n; ++i) {
        const uint32_t b = ef_half_bits_to_float(h[i]);
        memcpy(f + i, &b, sizeof b);
    }
}

static void f2h_scalar(const float *f, uint16_t *h, size_t n)
{
    for (size_t i = 0; i < n; ++i) {
        uint32_t b;
        memcpy(&b, f + i, sizeof b);
        h[i] = ef_float_bits_to_half(b);
    }
}

#ifdef EF_HAVE_F16C
__attribute__((target("avx,f16c"))) static void h2f_f16c(const uint16_t *h, float *f, size_t n)
{
    const __m128i abs = _mm_set1_epi16(0x7fff), inf = _mm_set1_epi16(0x7c00);
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        const __m128i v = _mm_loadu_si128((const __m128i *) (h + i));
        _mm256_storeu_ps(f + i, _mm256_cvtph_ps(v));
        if (_mm_movemask_epi8(_mm_cmpgt_epi16(_mm_and_si128(v, abs), inf)))
            h2f_scalar(h + i, f + i, 8);   /* a NaN among them */
    }
    h2f_scalar(h + i, f + i, n - i);
}

__attribute__((target("avx,f16c"))) static void f2h_f16c(const float *f, uint16_t *h, size_t n)
{
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        const __m256 v = _mm256_loadu_ps(f + i);
        _mm_storeu_si128((__m128i *) (h + i),
                         _mm256_cvtps_ph(v, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC));
        if (_mm256_movemask_ps(_mm256_cmp_ps(v, v, _CMP_UNORD_Q)))
            f2h_scalar(f + i, h + i, 8);
    }
    f2h_scalar(f + i, h + i, n - i);
}
#endif

/* Whether this processor runs the F16C paths. */
static int f16c_ok(void)
{
#if defined(EF_HAVE_F16C) && defined(__clang__)
    /* clang's __builtin_cpu_supports knows no "f16c" (the fuzzers build
     * with clang): CPUID leaf 1, ECX bit 28 AVX, bit 29 F16C */
    unsigned a, b, c, d;
    return __get_cpuid(1, &a, &b, &c, &d) && (c >> 28 & 1) && (c >> 29 & 1);
#elif defined(EF_HAVE_F16C)
    return __builtin_cpu_supports("avx") && __builtin_cpu_supports("f16c");
#else
    return 0;
#endif
}

int ef_half_fast(void)
{
    const char *e = getenv("EXRFOG_F16C");
    return !(e && !strcmp(e, "0")) && f16c_ok();
}

void ef_half_to_float(const uint16_t *h, float *f, size_t n)
{
#ifdef EF_HAVE_F16C
    if (f16c_ok())
        h2f_f16c(h, f, n);
    else
#endif
        h2f_scalar(h, f, n);
}

void ef_float_to_half(const float *f, uint16_t *h, size_t n)
{
#ifdef EF_HAVE_F16C
    if (f16c_ok())
        f2h_f16c(f, h, n);
    else
#endif
        f2h_scalar(f, h, n);
}
