/* half <-> float for the stream's planes, with F16C where the processor has
 * it: the same bits as OpenEXRCore's own unpack and pack (Imath's
 * conversions: exact one way, round to nearest even the other, NaN
 * payloads truncated and kept signalling, never quieted), at a fraction of
 * their cost. */
#ifndef EF_HALF_CONV_H
#define EF_HALF_CONV_H

#include <stddef.h>
#include <stdint.h>

/* Whether the stream converts half channels itself: the processor has
 * F16C and AVX, and EXRFOG_F16C is not "0" (the tests compare both ways). */
int ef_half_fast(void);

/* n halves to floats, n floats to halves (any n; F16C when ef_half_fast,
 * else the scalar conversions below). */
void ef_half_to_float(const uint16_t *h, float *f, size_t n);
void ef_float_to_half(const float *f, uint16_t *h, size_t n);

/* One value each way, as bit patterns (the reference the vector paths
 * fall back on for NaN lanes). */
uint32_t ef_half_bits_to_float(uint16_t h);
uint16_t ef_float_bits_to_half(uint32_t x);

#endif
