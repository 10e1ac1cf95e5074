/* splitmix.h - the calibration programs' random numbers: SplitMix64
 * (Steele, Lea and Flood, 2014), a uniform double in [0, 1) from its top
 * 53 bits. Deterministic per seed, so every calibration run repeats. */
#ifndef EF_BENCH_SPLITMIX_H
#define EF_BENCH_SPLITMIX_H

#include <stdint.h>

static inline double splitmix_uni(uint64_t *state)
{
    uint64_t z = (*state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return (double) ((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
}

#endif
