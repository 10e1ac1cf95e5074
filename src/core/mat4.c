#include "mat4.h"

#include <math.h>

/* Row-vector product: (p . a) . b == p . out. */
void ef_mat4_mul(const ef_mat4 *a, const ef_mat4 *b, ef_mat4 *out)
{
    ef_mat4 r; /* out may alias a or b */
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k)
                s += a->m[4 * i + k] * b->m[4 * k + j];
            r.m[4 * i + j] = s;
        }
    *out = r;
}

/* Power of two bringing |x| (> 0) into [0.5, 1), so scaling is exact. */
static long double pow2_scale(long double x)
{
    int e;
    frexpl(x, &e);
    return ldexpl(1.0L, -e);
}

/* Gauss-Jordan in long double on the row- and column-equilibrated matrix:
 * a camera 1e7 units from the origin puts 1e7 next to unit rotations, and
 * without equilibration its honest pivots would look singular. */
int ef_mat4_invert(const ef_mat4 *a, ef_mat4 *out)
{
    if (!ef_mat4_finite(a))
        return -1;
    long double w[4][8], rs[4], cs[4];
    for (int j = 0; j < 4; ++j) {
        long double mx = 0.0L;
        for (int i = 0; i < 4; ++i)
            if (fabsl((long double)a->m[4 * i + j]) > mx)
                mx = fabsl((long double)a->m[4 * i + j]);
        if (mx == 0.0L)
            return -1;
        cs[j] = pow2_scale(mx);
    }
    for (int i = 0; i < 4; ++i) {
        long double mx = 0.0L;
        for (int j = 0; j < 4; ++j) {
            w[i][j] = (long double)a->m[4 * i + j] * cs[j];
            w[i][4 + j] = (i == j) ? 1.0L : 0.0L;
            if (fabsl(w[i][j]) > mx)
                mx = fabsl(w[i][j]);
        }
        if (mx == 0.0L)
            return -1;
        rs[i] = pow2_scale(mx);
        for (int j = 0; j < 4; ++j)
            w[i][j] *= rs[i];
    }
    for (int c = 0; c < 4; ++c) {
        int p = c;
        for (int i = c + 1; i < 4; ++i)
            if (fabsl(w[i][c]) > fabsl(w[p][c]))
                p = i;
        /* Entries are now in [0.5, 1) per row and column: a pivot this small
         * is rank deficiency, not scale. */
        if (!(fabsl(w[p][c]) > 1e-12L))
            return -1;
        if (p != c)
            for (int j = 0; j < 8; ++j) {
                long double t = w[c][j];
                w[c][j] = w[p][j];
                w[p][j] = t;
            }
        const long double inv = 1.0L / w[c][c];
        for (int j = 0; j < 8; ++j)
            w[c][j] *= inv;
        for (int i = 0; i < 4; ++i) {
            if (i == c || w[i][c] == 0.0L)
                continue;
            const long double f = w[i][c];
            for (int j = 0; j < 8; ++j)
                w[i][j] -= f * w[c][j];
        }
    }
    /* (Dr A Dc)^-1 = Dc^-1 A^-1 Dr^-1, so A^-1 = Dc W Dr. */
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            out->m[4 * i + j] = (double)(cs[i] * w[i][4 + j] * rs[j]);
    return ef_mat4_finite(out) ? 0 : -1;
}

/* out_j = sum_i (p, w)_i M[i][j]. */
void ef_mat4_apply(const ef_mat4 *M, const double p[3], double w, double out[4])
{
    const double *m = M->m;
    for (int j = 0; j < 4; ++j)
        out[j] = p[0] * m[j] + p[1] * m[4 + j] + p[2] * m[8 + j] + w * m[12 + j];
}

/* NaN and Inf both fail, so one check guards every later division. */
int ef_mat4_finite(const ef_mat4 *a)
{
    for (int i = 0; i < 16; ++i)
        if (!isfinite(a->m[i]))
            return 0;
    return 1;
}
