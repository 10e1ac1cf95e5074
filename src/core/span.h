/* Span-wise helpers for the per-pixel loops: a span's rays as arrays, and
 * four 64-byte records as vector lanes, so that the loops over a span
 * vectorise (GCC vector extensions; lowered to SSE2 in the baseline clone). */
#ifndef EF_SPAN_H
#define EF_SPAN_H

#include "exact.h"
#include "recon.h"

/* The most rays a span-wise tau_add works on at once. */
#define EF_SPAN 64

typedef double v4d __attribute__((vector_size(32)));
typedef double v4du __attribute__((vector_size(32), aligned(8), may_alias));

/* Four records of 8 doubles (at p[0..3]) as 8 vectors of four lanes: the
 * i-th double of record j in lane j of col[i]. Whole-line loads and
 * shuffles instead of 32 scalar loads. */
EF_INLINE void transpose4x8(const double *const p[4], v4d col[8])
{
    for (int h = 0; h < 2; ++h) {
        v4d A[4];
        for (int i = 0; i < 4; ++i)
            A[i] = ((const v4du *) (const void *) p[i])[h];
        const v4d t0 = __builtin_shufflevector(A[0], A[1], 0, 4, 2, 6);
        const v4d t1 = __builtin_shufflevector(A[0], A[1], 1, 5, 3, 7);
        const v4d t2 = __builtin_shufflevector(A[2], A[3], 0, 4, 2, 6);
        const v4d t3 = __builtin_shufflevector(A[2], A[3], 1, 5, 3, 7);
        col[4 * h + 0] = __builtin_shufflevector(t0, t2, 0, 1, 4, 5);
        col[4 * h + 1] = __builtin_shufflevector(t1, t3, 0, 1, 4, 5);
        col[4 * h + 2] = __builtin_shufflevector(t0, t2, 2, 3, 6, 7);
        col[4 * h + 3] = __builtin_shufflevector(t1, t3, 2, 3, 6, 7);
    }
}

/* The rays' fields as arrays, F[field][j] with the fields in ef_ray's
 * order, so that loops over them vectorise. */
enum { EF_F_DIR = 0, EF_F_DIST = 3, EF_F_PLANAR = 4, EF_F_ORG = 5 };

EF_INLINE void rays_soa(const ef_ray *r, int n, double F[8][EF_SPAN])
{
    _Static_assert(sizeof(ef_ray) == 8 * sizeof(double), "ef_ray is 8 doubles");
    int j = 0;
    for (; j + 4 <= n; j += 4) {
        const double *const p[4] = { r[j].dir, r[j + 1].dir, r[j + 2].dir, r[j + 3].dir };
        v4d col[8];
        transpose4x8(p, col);
        for (int i = 0; i < 8; ++i)
            *(v4du *) (void *) &F[i][j] = col[i];
    }
    for (; j < n; ++j) {
        const double f[8] = { r[j].dir[0], r[j].dir[1], r[j].dir[2], r[j].dist, r[j].planar,
                              r[j].org[0], r[j].org[1], r[j].org[2] };
        for (int i = 0; i < 8; ++i)
            F[i][j] = f[i];
    }
}

#endif
