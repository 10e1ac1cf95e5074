/* One octave of the noise integrated cell by cell with Gauss-Legendre
 * nodes (fog_noise.c's family; noise_fog.h): the cells are walked in
 * double with fractions carried across faces, collected CELL_BATCH at a
 * time and integrated side by side in vector lanes, summed in walk order
 * with compensation. Exact with 9 nodes per cell (the noise along a line
 * inside a cell is a polynomial of degree 16); fewer nodes per cell are
 * the adaptive method's cheaper rungs. Pure: no I/O, no globals. */
#include "noise_fog.h"

/* Gauss with n nodes on each of the m cells in b, vectorised across cells:
 * per cell the corners' gradient terms are linear along the chord (value
 * at the entry A, rate B), and the nodes are summed in order. With env,
 * each node's value is weighted by the envelope e^-(kh0 + khs t) there
 * (t = the cell's entry tc plus the node's offset). */
EF_INLINE void batch_gauss(const nstate *s, const double d0[3], int n, int m, cell_batch *b,
                           int env, double kh0, double khs)
{
    const double *x = s->glx[n], *wt = s->glw[n];
    if (m < 8) {
        /* A few cells (a short ray's octave): too few for vector lanes,
         * whose scalar remainder would unpack the gradients bit by bit;
         * the table is what a scalar loop reads fastest. */
        for (int c = 0; c < m; ++c) {
            const double f0 = b->f[0][c], f1 = b->f[1][c], f2 = b->f[2][c];
#define EF_CORNER(k, fx, fy, fz)                                                              \
    do {                                                                                      \
        const double *g = grad_vec[b->g[k][c] & 15];                                          \
        b->A[k][c] = g[0] * (fx) + g[1] * (fy) + g[2] * (fz);                                 \
        b->B[k][c] = g[0] * d0[0] + g[1] * d0[1] + g[2] * d0[2];                              \
    } while (0)
            EF_CORNER(0, f0, f1, f2);
            EF_CORNER(1, f0 - 1, f1, f2);
            EF_CORNER(2, f0, f1 - 1, f2);
            EF_CORNER(3, f0 - 1, f1 - 1, f2);
            EF_CORNER(4, f0, f1, f2 - 1);
            EF_CORNER(5, f0 - 1, f1, f2 - 1);
            EF_CORNER(6, f0, f1 - 1, f2 - 1);
            EF_CORNER(7, f0 - 1, f1 - 1, f2 - 1);
#undef EF_CORNER
        }
    } else {
        for (int k = 0; k < 8; ++k) {
            const double ox = k & 1, oy = (k >> 1) & 1, oz = k >> 2;
            for (int c = 0; c < m; ++c) {
                const unsigned sh = 2 * (b->g[k][c] & 15);
                const double gx = (double) (int) ((GRAD_X1 >> sh) & 3) - 1,
                             gy = (double) (int) ((GRAD_Y1 >> sh) & 3) - 1,
                             gz = (double) (int) ((GRAD_Z1 >> sh) & 3) - 1;
                b->A[k][c] = gx * (b->f[0][c] - ox) + gy * (b->f[1][c] - oy) + gz * (b->f[2][c] - oz);
                b->B[k][c] = gx * d0[0] + gy * d0[1] + gz * d0[2];
            }
        }
    }
    for (int c = 0; c < m; ++c)
        b->sum[c] = 0;
    for (int j = 0; j < n; ++j) {
        const double xj = 1 + x[j], wj = wt[j];
        for (int c = 0; c < m; ++c) {
            const double o = b->hh[c] * xj;
            const double u = ef_noise_fade_(b->f[0][c] + o * d0[0]);
            const double v = ef_noise_fade_(b->f[1][c] + o * d0[1]);
            const double w = ef_noise_fade_(b->f[2][c] + o * d0[2]);
            const double g0 = b->A[0][c] + o * b->B[0][c], g1 = b->A[1][c] + o * b->B[1][c],
                         g2 = b->A[2][c] + o * b->B[2][c], g3 = b->A[3][c] + o * b->B[3][c],
                         g4 = b->A[4][c] + o * b->B[4][c], g5 = b->A[5][c] + o * b->B[5][c],
                         g6 = b->A[6][c] + o * b->B[6][c], g7 = b->A[7][c] + o * b->B[7][c];
            const double x0 = ef_noise_lerp_(v, ef_noise_lerp_(u, g0, g1),
                                             ef_noise_lerp_(u, g2, g3));
            const double x1 = ef_noise_lerp_(v, ef_noise_lerp_(u, g4, g5),
                                             ef_noise_lerp_(u, g6, g7));
            const double val = ef_noise_lerp_(w, x0, x1);
            b->sum[c] += env ? wj * ef_exp_neg(kh0 + khs * (b->tc[c] + o)) * val : wj * val;
        }
    }
}

/* Integrates the m cells of b (with env, weighted by the envelope) and
 * adds them to acc in walk order. */
EF_INLINE void batch_add(const nstate *s, const double d0[3], int n, int m, cell_batch *b,
                         ksum *acc, int env, double kh0, double khs)
{
    batch_gauss(s, d0, n, m, b, env, kh0, khs);
    for (int c = 0; c < m; ++c)
        kadd(acc, b->hh[c] * b->sum[c]);
}

/* batch_add for the long-double walk (exact), with its own vector clone. */
EF_MULTIVERSION void ef_nz_batch_flush(const nstate *s, const double d0[3], int n, int m,
                                       cell_batch *b, ksum *acc)
{
    batch_add(s, d0, n, m, b, acc, 0, 0, 0);
}

/* integral of noise_i over [t0, t1] with n nodes per cell, walking the cells
 * in double with fractions carried from cell to cell (each axis restarts
 * at 0 or 1 where it crosses): the adaptive method's fast path, whose
 * rounding (~1e-16 per cell) is far below any tolerance it takes. The walk
 * collects CELL_BATCH cells at a time and integrates them side by side;
 * the cells are summed in order. */
EF_INLINE double octave_walk(rayc *R, int i, int n, double t0, double t1, int env)
{
    const nstate *s = R->s;
    double fr[3], d[3], next[3], step[3];
    int ic[3];
    for (int a = 0; a < 3; ++a) {
        const lin *u = &R->u[3 * i + a];
        d[a] = u->dd;
        const double v = u->bd + t0 * u->dd;
        double c = floor(v);
        if (d[a] < 0 && c == v)
            c -= 1;
        fr[a] = v - c;
        ic[a] = (int) (c - 256 * floor(c * (1.0 / 256)));
        step[a] = d[a] == 0 ? INFINITY : fabs(1 / d[a]);
        next[a] = d[a] > 0 ? t0 + (1 - fr[a]) * step[a] : d[a] < 0 ? t0 + fr[a] * step[a] : INFINITY;
    }
    int inc[3];
    double reset[3];
    for (int a = 0; a < 3; ++a) {
        inc[a] = d[a] > 0 ? 1 : 255;
        reset[a] = d[a] > 0 ? 0 : 1;
    }
    ksum acc = { 0, 0 };
    double t = t0;
    long cells = 0;
    cell_batch b;
    int more = t < t1;
    while (more) {
        int m = 0;
        while (m < CELL_BATCH) {
            const double n01 = next[1] < next[0] ? next[1] : next[0];
            const double nm = next[2] < n01 ? next[2] : n01;
            const double tb = nm < t1 ? nm : t1, h = tb - t;
            if (h > 0) {
                for (int a = 0; a < 3; ++a) {
                    b.ic[a][m] = ic[a];
                    b.f[a][m] = fr[a];
                }
                b.tc[m] = t;
                b.hh[m++] = h / 2;
                for (int a = 0; a < 3; ++a)
                    fr[a] += h * d[a];
            }
            if (tb >= t1) {
                more = 0;
                break;
            }
            /* Cross every axis whose face is here, without branches: which
             * axis comes next is what a processor cannot predict. */
            for (int a = 0; a < 3; ++a) {
                const int cross = next[a] <= tb;
                ic[a] = cross ? (ic[a] + inc[a]) & 255 : ic[a];
                fr[a] = cross ? reset[a] : fr[a];
                next[a] = cross ? next[a] + step[a] : next[a];
            }
            t = tb;
            if (!(t < t1)) {
                more = 0;
                break;
            }
        }
        /* The corners' hashes, cell by cell with no branch in between. */
        for (int c = 0; c < m; ++c) {
            ef_noise_cell nc;
            ef_noise_cell_at(b.ic[0][c], b.ic[1][c], b.ic[2][c], &nc);
            for (int k = 0; k < 8; ++k)
                b.g[k][c] = nc.h[k];
        }
        batch_add(s, d, n, m, &b, &acc, env, R->kh0, R->khs);
        cells += m;
    }
    R->cells += cells;
    R->evals += (double) cells * n;
    return kval(&acc);
}

/* octave_walk without an envelope (falloff 0). */
EF_MULTIVERSION double ef_nz_octave_integral_fast(rayc *R, int i, int n, double t0, double t1)
{
    return octave_walk(R, i, n, t0, t1, 0);
}

/* integral of env * noise_i over [t0, t1] the same way, each node weighted
 * by the envelope (the adaptive method's segments under a falloff). */
EF_MULTIVERSION double ef_nz_octave_integral_env(rayc *R, int i, int n, double t0, double t1)
{
    return octave_walk(R, i, n, t0, t1, 1);
}
