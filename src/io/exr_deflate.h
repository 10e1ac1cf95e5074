/* ZIP and ZIPS chunks through libdeflate instead of OpenEXRCore's zlib.
 *
 * The files are standard OpenEXR ZIP: the same byte split (even bytes,
 * then odd bytes), the same delta predictor and a zlib stream, so any
 * OpenEXR reader decodes them; only the DEFLATE encoder differs (libdeflate
 * chooses other matches: the bytes differ from zlib's, the pixels do not).
 * A chunk that does not shrink is stored raw, as Core does.
 *
 * Depends only on OpenEXRCore and libdeflate (bench/floor links it too). */
#ifndef EF_EXR_DEFLATE_H
#define EF_EXR_DEFLATE_H

#include <openexr.h>

/* Which DEFLATE implementation compresses and decompresses ZIP/ZIPS. */
enum { EF_CODEC_LIBDEFLATE = 0, EF_CODEC_ZLIB = 1 };

/* The libdeflate level used for a zip level (exr_get_zip_compression_level:
 * 1..9, or <= 0 for the default). Levels map one to one (libdeflate's 1..9
 * are its zlib-compatible range); the default is EF_DEFLATE_DEFAULT_LEVEL. */
#define EF_DEFLATE_DEFAULT_LEVEL 6
int ef_deflate_level(int zip_level);

/* Call after exr_decoding_choose_default_routines: when part is ZIP or ZIPS
 * and Core chose a decompress step, replaces it with libdeflate's. Returns
 * 0 or an exr_result_t. Release with ef_deflate_decoding_destroy. */
exr_result_t ef_deflate_decoding_setup(exr_const_context_t ctx, int part, exr_decode_pipeline_t *dec);
/* Call after exr_encoding_choose_default_routines: the same for encoding,
 * at the part's zip level. Release with ef_deflate_encoding_destroy. */
exr_result_t ef_deflate_encoding_setup(exr_const_context_t ctx, int part, exr_encode_pipeline_t *enc);

/* exr_decoding_destroy / exr_encoding_destroy, also freeing libdeflate's
 * state when the pipeline has it. */
exr_result_t ef_deflate_decoding_destroy(exr_const_context_t ctx, exr_decode_pipeline_t *dec);
exr_result_t ef_deflate_encoding_destroy(exr_const_context_t ctx, exr_encode_pipeline_t *enc);

/* A pipeline's allocator and its release (Core's alloc_fn / free_fn). */
typedef void *(*ef_alloc_fn)(exr_transcoding_pipeline_buffer_id_t, size_t);
typedef void (*ef_free_fn)(exr_transcoding_pipeline_buffer_id_t, void *);
/* Grows a pipeline buffer (*buf, *cap bytes) to at least need bytes the
 * way Core does, through the pipeline's allocator af/ff when it has one
 * (else malloc/free, the default context's), so that Core reuses or frees
 * it later. Returns 0 or EXR_ERR_OUT_OF_MEMORY. */
exr_result_t ef_pipeline_reserve(ef_alloc_fn af, ef_free_fn ff,
                                 exr_transcoding_pipeline_buffer_id_t id, void **buf, size_t *cap,
                                 uint64_t need);
/* The byte transforms of OpenEXR's ZIP, exposed for the tests:
 * deconstruct: src (n bytes) -> dst, split and predicted (encoder side);
 * reconstruct: buf (n bytes, split and predicted) is un-predicted in place,
 * then interleaved into dst (decoder side). */
void ef_zip_deconstruct(uint8_t *dst, const uint8_t *src, uint64_t n);
void ef_zip_reconstruct(uint8_t *dst, uint8_t *buf, uint64_t n);

#endif
