/* ZIP/ZIPS through libdeflate (see exr_deflate.h). The transforms follow
 * the OpenEXR file format's ZIP definition: split the chunk's bytes into
 * the even-indexed half then the odd-indexed half, replace every byte but
 * the first by (byte - previous + 128) mod 256, then zlib-compress. */
#include "exr_deflate.h"

#include <libdeflate.h>
#include <stdlib.h>
#include <string.h>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

/* ---- byte transforms ---------------------------------------------------- */

/* dst[k] = src[2k] for the first (n+1)/2 bytes, then the odd bytes. */
static void split_halves(uint8_t *dst, const uint8_t *src, uint64_t n)
{
    uint8_t *even = dst, *odd = dst + (n + 1) / 2;
    uint64_t k = 0;
#ifdef __SSE2__
    const __m128i lo = _mm_set1_epi16(0x00ff);
    for (; 2 * k + 32 <= n; k += 16) {
        const __m128i a = _mm_loadu_si128((const __m128i *) (src + 2 * k));
        const __m128i b = _mm_loadu_si128((const __m128i *) (src + 2 * k + 16));
        _mm_storeu_si128((__m128i *) (even + k),
                         _mm_packus_epi16(_mm_and_si128(a, lo), _mm_and_si128(b, lo)));
        _mm_storeu_si128((__m128i *) (odd + k),
                         _mm_packus_epi16(_mm_srli_epi16(a, 8), _mm_srli_epi16(b, 8)));
    }
#endif
    for (; 2 * k < n; ++k) {
        even[k] = src[2 * k];
        if (2 * k + 1 < n)
            odd[k] = src[2 * k + 1];
    }
}

/* buf[i] = buf[i] - buf[i-1] + 128 for i >= 1, in place (back to front, so
 * every difference reads original bytes). */
static void predict(uint8_t *buf, uint64_t n)
{
    uint64_t i = n;
#ifdef __SSE2__
    const __m128i bias = _mm_set1_epi8((char) 0x80);
    for (; i >= 17; i -= 16) {
        const __m128i v = _mm_loadu_si128((const __m128i *) (buf + i - 16));
        const __m128i p = _mm_loadu_si128((const __m128i *) (buf + i - 17));
        _mm_storeu_si128((__m128i *) (buf + i - 16), _mm_add_epi8(_mm_sub_epi8(v, p), bias));
    }
#endif
    for (; i >= 2; --i)
        buf[i - 1] = (uint8_t) (buf[i - 1] - buf[i - 2] + 128);
}

/* The inverse of predict: a running sum, buf[i] += buf[i-1] - 128. */
static void unpredict(uint8_t *buf, uint64_t n)
{
    uint64_t i = 1;
    if (n == 0)
        return;
#ifdef __SSE2__
    /* The first byte has no bias: pre-bias it so the vector loop can treat
     * every byte alike (adding -128 and +128 are the same modulo 256). */
    const __m128i bias = _mm_set1_epi8((char) 0x80);
    __m128i prev = _mm_setzero_si128();
    buf[0] = (uint8_t) (buf[0] + 128);
    for (i = 0; i + 16 <= n; i += 16) {
        __m128i d = _mm_add_epi8(_mm_loadu_si128((const __m128i *) (buf + i)), bias);
        d = _mm_add_epi8(d, _mm_slli_si128(d, 1));
        d = _mm_add_epi8(d, _mm_slli_si128(d, 2));
        d = _mm_add_epi8(d, _mm_slli_si128(d, 4));
        d = _mm_add_epi8(d, _mm_slli_si128(d, 8));
        d = _mm_add_epi8(d, prev);
        _mm_storeu_si128((__m128i *) (buf + i), d);
        /* broadcast byte 15 */
        __m128i last = _mm_srli_si128(d, 15);
        last = _mm_unpacklo_epi8(last, last);
        last = _mm_unpacklo_epi16(last, last);
        prev = _mm_shuffle_epi32(last, 0);
    }
    if (i == 0) {
        buf[0] = (uint8_t) (buf[0] - 128);
        i = 1;
    }
#endif
    for (; i < n; ++i)
        buf[i] = (uint8_t) (buf[i] + buf[i - 1] - 128);
}

/* dst[2k] = buf[k], dst[2k+1] = buf[(n+1)/2 + k]. */
static void interleave_halves(uint8_t *dst, const uint8_t *buf, uint64_t n)
{
    const uint8_t *even = buf, *odd = buf + (n + 1) / 2;
    uint64_t k = 0;
#ifdef __SSE2__
    for (; 2 * k + 32 <= n; k += 16) {
        const __m128i a = _mm_loadu_si128((const __m128i *) (even + k));
        const __m128i b = _mm_loadu_si128((const __m128i *) (odd + k));
        _mm_storeu_si128((__m128i *) (dst + 2 * k), _mm_unpacklo_epi8(a, b));
        _mm_storeu_si128((__m128i *) (dst + 2 * k + 16), _mm_unpackhi_epi8(a, b));
    }
#endif
    for (; 2 * k < n; ++k) {
        dst[2 * k] = even[k];
        if (2 * k + 1 < n)
            dst[2 * k + 1] = odd[k];
    }
}

void ef_zip_deconstruct(uint8_t *dst, const uint8_t *src, uint64_t n)
{
    split_halves(dst, src, n);
    predict(dst, n);
}

void ef_zip_reconstruct(uint8_t *dst, uint8_t *buf, uint64_t n)
{
    unpredict(buf, n);
    interleave_halves(dst, buf, n);
}

/* ---- pipeline hooks ----------------------------------------------------- */

int ef_deflate_level(int zip_level)
{
    if (zip_level <= 0)
        return EF_DEFLATE_DEFAULT_LEVEL;
    return zip_level > 9 ? 9 : zip_level;
}

/* Grows one of a pipeline's buffers as Core does: through the pipeline's
 * allocator when it has one, else malloc/free (the default context's). */
exr_result_t ef_pipeline_reserve(ef_alloc_fn af, ef_free_fn ff,
                                 exr_transcoding_pipeline_buffer_id_t id, void **buf, size_t *cap,
                                 uint64_t need)
{
    if (*buf && *cap >= need)
        return EXR_ERR_SUCCESS;
    if (*buf && *cap > 0) {
        if (ff)
            ff(id, *buf);
        else
            free(*buf);
    }
    *buf = NULL;
    *cap = 0;
    void *p = af ? af(id, (size_t) need) : malloc((size_t) need);
    if (!p)
        return EXR_ERR_OUT_OF_MEMORY;
    *buf = p;
    *cap = (size_t) need;
    return EXR_ERR_SUCCESS;
}

static exr_result_t ld_decompress(exr_decode_pipeline_t *d)
{
    struct libdeflate_decompressor *z = d->decoding_user_data;
    const uint64_t packed = d->chunk.packed_size, unpacked = d->chunk.unpacked_size;
    exr_result_t rv;
    if (d->unpacked_buffer == d->packed_buffer && d->unpacked_alloc_size == 0)
        d->unpacked_buffer = NULL;
    if (packed == unpacked) {
        /* Stored raw (it did not shrink): the bytes are the chunk. */
        if (d->unpacked_buffer && d->unpacked_alloc_size > 0) {
            if (d->free_fn)
                d->free_fn(EXR_TRANSCODE_BUFFER_UNPACKED, d->unpacked_buffer);
            else
                free(d->unpacked_buffer);
        }
        d->unpacked_buffer = d->packed_buffer;
        d->unpacked_alloc_size = 0;
        return EXR_ERR_SUCCESS;
    }
    if (unpacked == 0 || !d->packed_buffer)
        return EXR_ERR_CORRUPT_CHUNK;
    rv = ef_pipeline_reserve(d->alloc_fn, d->free_fn, EXR_TRANSCODE_BUFFER_UNPACKED,
                             &d->unpacked_buffer, &d->unpacked_alloc_size, unpacked);
    if (!rv)
        rv = ef_pipeline_reserve(d->alloc_fn, d->free_fn, EXR_TRANSCODE_BUFFER_SCRATCH1,
                                 &d->scratch_buffer_1, &d->scratch_alloc_size_1, unpacked);
    if (rv)
        return rv;
    /* Exactly unpacked_size bytes, checksum verified, or the chunk is bad. */
    if (libdeflate_zlib_decompress(z, d->packed_buffer, (size_t) packed, d->scratch_buffer_1,
                                   (size_t) unpacked, NULL) != LIBDEFLATE_SUCCESS)
        return EXR_ERR_CORRUPT_CHUNK;
    ef_zip_reconstruct(d->unpacked_buffer, d->scratch_buffer_1, unpacked);
    return EXR_ERR_SUCCESS;
}

static exr_result_t ld_compress(exr_encode_pipeline_t *e)
{
    struct libdeflate_compressor *z = e->encoding_user_data;
    const uint64_t n = e->packed_bytes;
    exr_result_t rv;
    if (e->compressed_buffer == e->packed_buffer && e->compressed_alloc_size == 0)
        e->compressed_buffer = NULL;
    rv = ef_pipeline_reserve(e->alloc_fn, e->free_fn, EXR_TRANSCODE_BUFFER_COMPRESSED,
                             &e->compressed_buffer, &e->compressed_alloc_size, n);
    if (!rv)
        rv = ef_pipeline_reserve(e->alloc_fn, e->free_fn, EXR_TRANSCODE_BUFFER_SCRATCH1,
                                 &e->scratch_buffer_1, &e->scratch_alloc_size_1, n);
    if (rv)
        return rv;
    ef_zip_deconstruct(e->scratch_buffer_1, e->packed_buffer, n);
    /* Only a stream shorter than the raw bytes is kept (libdeflate returns
     * 0 when it does not fit); otherwise the chunk is stored raw. */
    size_t got = n > 1 ? libdeflate_zlib_compress(z, e->scratch_buffer_1, (size_t) n,
                                                  e->compressed_buffer, (size_t) n - 1)
                       : 0;
    if (got == 0) {
        memcpy(e->compressed_buffer, e->packed_buffer, (size_t) n);
        got = (size_t) n;
    }
    e->compressed_bytes = got;
    return EXR_ERR_SUCCESS;
}

static int is_zip(exr_const_context_t ctx, int part)
{
    exr_compression_t c;
    return exr_get_compression(ctx, part, &c) == EXR_ERR_SUCCESS &&
           (c == EXR_COMPRESSION_ZIP || c == EXR_COMPRESSION_ZIPS);
}

exr_result_t ef_deflate_decoding_setup(exr_const_context_t ctx, int part, exr_decode_pipeline_t *dec)
{
    if (!dec->decompress_fn || dec->decompress_fn == ld_decompress || !is_zip(ctx, part))
        return EXR_ERR_SUCCESS;
    struct libdeflate_decompressor *z = libdeflate_alloc_decompressor();
    if (!z)
        return EXR_ERR_OUT_OF_MEMORY;
    dec->decoding_user_data = z;
    dec->decompress_fn = ld_decompress;
    return EXR_ERR_SUCCESS;
}

exr_result_t ef_deflate_encoding_setup(exr_const_context_t ctx, int part, exr_encode_pipeline_t *enc)
{
    int level = -1;
    if (!enc->compress_fn || enc->compress_fn == ld_compress || !is_zip(ctx, part))
        return EXR_ERR_SUCCESS;
    if (exr_get_zip_compression_level(ctx, part, &level))
        return EXR_ERR_INVALID_ARGUMENT;
    struct libdeflate_compressor *z = libdeflate_alloc_compressor(ef_deflate_level(level));
    if (!z)
        return EXR_ERR_OUT_OF_MEMORY;
    enc->encoding_user_data = z;
    enc->compress_fn = ld_compress;
    return EXR_ERR_SUCCESS;
}

exr_result_t ef_deflate_decoding_destroy(exr_const_context_t ctx, exr_decode_pipeline_t *dec)
{
    if (dec->decompress_fn == ld_decompress)
        libdeflate_free_decompressor(dec->decoding_user_data);
    return exr_decoding_destroy(ctx, dec);
}

exr_result_t ef_deflate_encoding_destroy(exr_const_context_t ctx, exr_encode_pipeline_t *enc)
{
    if (enc->compress_fn == ld_compress)
        libdeflate_free_compressor(enc->encoding_user_data);
    return exr_encoding_destroy(ctx, enc);
}
