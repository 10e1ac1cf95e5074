/* One octave of the noise integrated on a grid (fog_noise.c's family;
 * noise_fog.h): the composite midpoint rule with nu nodes per lattice
 * unit and the Euler-Maclaurin end term from the noise's derivative, each
 * node on its own (no lattice walk), in single precision eight to a
 * vector. Its error is statistical, calibrated by bench/grid_calibrate.c
 * (grid_rms in noise_fog.h). Pure: no I/O, no globals. */
#include "noise_fog.h"

/* ---- the grid: end-corrected composite midpoint along an octave ---- */

/* Octave noise at lattice point x and its derivative along d (d in lattice
 * units per unit t): Perlin's formula differentiated term by term (each
 * corner's gradient term is linear, the fades' derivative 30 t^2 (t-1)^2). */
double ef_nz_noise_dval(const uint32_t *tab, const double x[3], const double d[3], double *dn)
{
    int C[3];
    double f[3], s[3], ds[3];
    for (int a = 0; a < 3; ++a) {
        /* x is near the ray's start or a segment's: an int64 holds its
         * floor */
        const double fl = floor(x[a]);
        f[a] = x[a] - fl;
        C[a] = (int) ((int64_t) fl & 255);
        s[a] = ef_noise_fade_(f[a]);
        ds[a] = 30 * f[a] * f[a] * (f[a] - 1) * (f[a] - 1) * d[a];
    }
    /* the corners' gradient numbers from the grid's tables (grid_hash) */
    const uint32_t *gp = tab + 65536, q = tab[C[0] << 8 | C[1]];
    const uint32_t c0 = gp[(q & 255) + C[2]], c1 = gp[(q >> 16 & 255) + C[2]],
                   c2 = gp[(q >> 8 & 255) + C[2]], c3 = gp[(q >> 24) + C[2]];
    const unsigned h[8] = { c0 & 15, c1 & 15, c2 & 15, c3 & 15, c0 >> 16, c1 >> 16, c2 >> 16, c3 >> 16 };
    double g[8], dg[8];
    for (int k = 0; k < 8; ++k) {
        const double *G = grad_vec[h[k]];
        g[k] = G[0] * (f[0] - (k & 1)) + G[1] * (f[1] - ((k >> 1) & 1)) + G[2] * (f[2] - (k >> 2));
        dg[k] = G[0] * d[0] + G[1] * d[1] + G[2] * d[2];
    }
    /* lerp(t, a, b) = a + t (b - a), differentiated in each argument */
    double v4[4], dv4[4];
    for (int k = 0; k < 4; ++k) {
        v4[k] = g[2 * k] + s[0] * (g[2 * k + 1] - g[2 * k]);
        dv4[k] = dg[2 * k] + ds[0] * (g[2 * k + 1] - g[2 * k]) + s[0] * (dg[2 * k + 1] - dg[2 * k]);
    }
    double v2[2], dv2[2];
    for (int k = 0; k < 2; ++k) {
        v2[k] = v4[2 * k] + s[1] * (v4[2 * k + 1] - v4[2 * k]);
        dv2[k] = dv4[2 * k] + ds[1] * (v4[2 * k + 1] - v4[2 * k]) +
                 s[1] * (dv4[2 * k + 1] - dv4[2 * k]);
    }
    *dn = dv2[0] + ds[2] * (v2[1] - v2[0]) + s[2] * (dv2[1] - dv2[0]);
    return v2[0] + s[2] * (v2[1] - v2[0]);
}

#define GRID_BATCH 64

/* One batch of grid nodes: fractions, cells and the corners' hashes. */
typedef struct grid_batch {
    float f[3][GRID_BATCH];          /* fractions in the cell */
    int ic[3][GRID_BATCH];
    unsigned g[GRID_BATCH];          /* the corners' gradient numbers, packed */
    float v[GRID_BATCH];
} grid_batch;

/* Perlin's permutation twice over (his reference's p[512]), and its
 * gradient numbers (& 15): the grid's hashes need no index masks. */
#define EF_PERM_ID(v) v,
#define EF_PERM_GRAD(v) ((v) & 15),
static const unsigned char perm2[512] = { EF_NOISE_PERM(EF_PERM_ID) EF_NOISE_PERM(EF_PERM_ID) };
static const unsigned char grad2[512] = { EF_NOISE_PERM(EF_PERM_GRAD) EF_NOISE_PERM(EF_PERM_GRAD) };
#undef EF_PERM_ID
#undef EF_PERM_GRAD

/* Fills the grid's hash tables: t[256 x + y] packs Perlin's four
 * second-level hashes of column (x, y), p[p[x] + y], p[p[x] + y + 1],
 * p[p[x + 1] + y], p[p[x + 1] + y + 1], a byte each; t[65536 + i] holds
 * the gradient numbers of i and i + 1 in its two halves. One word and four
 * pair reads then give a node's eight corners, where the permutation alone
 * takes fourteen reads (the same numbers: ef_noise_cell_at's). */
void ef_nz_grid_tables(uint32_t *t)
{
    const unsigned char *p = perm2, *g = grad2;
    for (int x = 0; x < 256; ++x)
        for (int y = 0; y < 256; ++y) {
            const int A = p[x] + y, B = p[x + 1] + y;
            t[256 * x + y] = (uint32_t) p[A] | (uint32_t) p[A + 1] << 8 |
                             (uint32_t) p[B] << 16 | (uint32_t) p[B + 1] << 24;
        }
    for (int i = 0; i < 512; ++i)
        t[65536 + i] = (uint32_t) g[i] | (uint32_t) (i + 1 < 512 ? g[i + 1] : 0) << 16;
}
/* The corners' gradient numbers (hash & 15) of m nodes, packed 4 bits
 * per corner (corner k at bits 4k), from grid_tables' t. Scalar on
 * purpose: GCC turns the table reads into vector gathers, slower here
 * than plain loads. */
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((optimize("no-tree-vectorize")))
#endif
static void grid_hash(const uint32_t *t, grid_batch *b, int m)
{
    const uint32_t *gp = t + 65536;
    for (int c = 0; c < m; ++c) {
        const int z = b->ic[2][c];
        const uint32_t q = t[b->ic[0][c] << 8 | b->ic[1][c]];
        b->g[c] = gp[(q & 255) + z] | gp[(q >> 16 & 255) + z] << 4 | gp[(q >> 8 & 255) + z] << 8 |
                  gp[(q >> 24) + z] << 12;
    }
}

/* env * d/dt noise_i at t, e being the envelope e^-(kh0 + khs t) there
 * (used when env). */
static double grid_fprime(const rayc *R, int i, double t, int env, double e, grid_end *cache)
{
    double n, dn;
    if (cache && cache->valid && cache->t == t) {
        n = cache->n;
        dn = cache->dn;
    } else if (t == 0 && R->cam) {
        /* at the camera: its noise and gradient, bound once per frame */
        const lin *u = &R->u[3 * i];
        const double *g = R->s->cam_g[i];
        n = R->s->cam_n[i];
        dn = g[0] * u[0].dd + g[1] * u[1].dd + g[2] * u[2].dd;
    } else {
        double x[3], d[3];
        for (int a = 0; a < 3; ++a) {
            const lin *u = &R->u[3 * i + a];
            x[a] = u->bd + t * u->dd;
            d[a] = u->dd;
        }
        n = ef_nz_noise_dval(grid_hash_table(R->s), x, d, &dn);
        if (cache)
            *cache = (grid_end) { t, n, dn, e, 1 };
    }
    return env ? e * (dn - R->khs * n) : dn;
}

/* integral of env * noise_i over [t0, t1] by the composite midpoint rule
 * with ceil(nu * lattice length) nodes and the Euler-Maclaurin end term
 * h^2/24 (f'(t1) - f'(t0)): no lattice walk, each node on its own (the
 * error, calibrated by bench/grid_calibrate.c on this code, is an
 * estimate). end: the octave's last end term (the previous segment's t1,
 * reused at t0; t1's replaces it), or NULL. */
EF_INLINE double grid_walk(rayc *R, int i, double nu, double t0, double t1, int env,
                           grid_end *end)
{
    const lin *u = &R->u[3 * i];
    double d[3], b[3], sp = 0;
    for (int a = 0; a < 3; ++a) {
        d[a] = u[a].dd;
        sp += d[a] * d[a];
        /* the start reduced modulo the period, so every node's cell index
         * fits an int */
        const double v = u[a].bd + t0 * d[a];
        b[a] = v - 256 * floor(v * (1.0 / 256));
    }
    const double L = t1 - t0;
    const long n = (long) ceil(sqrt(sp) * L * nu) > 0 ? (long) ceil(sqrt(sp) * L * nu) : 1;
    const double h = L / (double) n;
    const double khs = R->khs;
    /* the envelope at t0 (kept from the previous segment where it ended
     * here), at t1, and at the nodes: e0 rh r^j, rh = e^-(khs h / 2) */
    double e0 = 1, e1 = 1, rh = 1;
    /* where the envelope spans more than e^500 over the segment, products
     * of its values could meet 0 times inf: each node's own then */
    const int direct = env && !(fabs(khs * L) < 500);
    if (env) {
        e0 = end && end->valid && end->t == t0 ? end->e : ef_exp_neg(R->kh0 + khs * t0);
        e1 = ef_exp_neg(R->kh0 + khs * t1);
        rh = ef_exp_neg(khs * h / 2);
    }
    ksum acc = { 0, 0 };
    grid_batch gb;
    double pw[GRID_BATCH], wv[GRID_BATCH], eb = e0 * rh;
    for (long j0 = 0; j0 < n; j0 += GRID_BATCH) {
        const int m = n - j0 < GRID_BATCH ? (int) (n - j0) : GRID_BATCH;
        /* whole vectors of 8 (the nodes past m lie on the same line, their
         * values unused): no scalar tails, which cost more than the nodes
         * on the short rays of a near frame */
        const int mv = (m + 7) & ~7;
        const double o0 = ((double) j0 + 0.5) * h;
        /* plain loops over the batch's arrays, which GCC vectorises */
        for (int c8 = 0; c8 < mv; c8 += 8)
            for (int c = c8; c < c8 + 8; ++c) {
                const double o = o0 + c * h;
                const double x = b[0] + o * d[0], y = b[1] + o * d[1], z = b[2] + o * d[2];
                const double cx = floor(x), cy = floor(y), cz = floor(z);
                gb.f[0][c] = (float) (x - cx);
                gb.f[1][c] = (float) (y - cy);
                gb.f[2][c] = (float) (z - cz);
                gb.ic[0][c] = (int) cx & 255;
                gb.ic[1][c] = (int) cy & 255;
                gb.ic[2][c] = (int) cz & 255;
            }
        grid_hash(grid_hash_table(R->s), &gb, mv);
        /* in single precision, 8 nodes to a vector (IEEE operations in a
         * fixed order: the same bits with or without the vector unit) */
        for (int c8 = 0; c8 < mv; c8 += 8)
            for (int c = c8; c < c8 + 8; ++c) {
                const float fx = gb.f[0][c], fy = gb.f[1][c], fz = gb.f[2][c];
                float g[8];
                for (int k = 0; k < 8; ++k) {
                    const unsigned sh = 2 * ((gb.g[c] >> 4 * k) & 15);
                    const float gx = (float) (int) ((GRAD_X1 >> sh) & 3) - 1,
                                gy = (float) (int) ((GRAD_Y1 >> sh) & 3) - 1,
                                gz = (float) (int) ((GRAD_Z1 >> sh) & 3) - 1;
                    g[k] = gx * (fx - (float) (k & 1)) + gy * (fy - (float) ((k >> 1) & 1)) +
                           gz * (fz - (float) (k >> 2));
                }
                const float uu = fx * fx * fx * (fx * (fx * 6 - 15) + 10),
                            vv = fy * fy * fy * (fy * (fy * 6 - 15) + 10),
                            ww = fz * fz * fz * (fz * (fz * 6 - 15) + 10);
                const float a0 = g[0] + uu * (g[1] - g[0]), a1 = g[2] + uu * (g[3] - g[2]),
                            a2 = g[4] + uu * (g[5] - g[4]), a3 = g[6] + uu * (g[7] - g[6]);
                const float x0 = a0 + vv * (a1 - a0), x1 = a2 + vv * (a3 - a2);
                gb.v[c] = x0 + ww * (x1 - x0);
            }
        double sum = 0;
        if (env) {
            /* r^c in doublings (each within c ulps: far below any
             * tolerance taken here) */
            if (j0 == 0) {
                pw[0] = 1;
                double rr = rh * rh;
                for (int w = 1; w < m; w *= 2) {
                    for (int c = 0; c < w && w + c < GRID_BATCH; ++c)
                        pw[w + c] = pw[c] * rr;
                    rr *= rr;
                }
            }
            if (direct) {
                for (int c = 0; c < m; ++c)
                    wv[c] = (double) gb.v[c] * ef_exp_neg(R->kh0 + khs * (t0 + o0 + c * h));
                for (int c = 0; c < m; ++c)
                    sum += wv[c];
            } else {
                for (int c = 0; c < m; ++c)
                    wv[c] = (double) gb.v[c] * pw[c];
                for (int c = 0; c < m; ++c)
                    sum += wv[c];
                sum *= eb;
                eb *= pw[GRID_BATCH - 1] * (rh * rh);
            }
        } else {
            for (int c = 0; c < m; ++c)
                sum += gb.v[c];
        }
        kadd(&acc, sum);
    }
    R->evals += (double) n;
    const double fa = grid_fprime(R, i, t0, env, e0, end);
    const double fb = grid_fprime(R, i, t1, env, e1, end);
    return h * kval(&acc) + h * h / 24 * (fb - fa);
}

EF_MULTIVERSION double ef_nz_octave_grid_env(rayc *R, int i, double nu, double t0, double t1,
                                             grid_end *end)
{
    return grid_walk(R, i, nu, t0, t1, 1, end);
}

EF_MULTIVERSION double ef_nz_octave_grid_flat(rayc *R, int i, double nu, double t0, double t1,
                                              grid_end *end)
{
    return grid_walk(R, i, nu, t0, t1, 0, end);
}

/* The grid over [t0, t1] given in long double (the general path's
 * chunks), with or without the envelope. */
double ef_nz_octave_grid_any(rayc *R, int i, double nu, long double t0, long double t1,
                             grid_end *end)
{
    return R->s->k > 0 ? ef_nz_octave_grid_env(R, i, nu, (double) t0, (double) t1, end)
                       : ef_nz_octave_grid_flat(R, i, nu, (double) t0, (double) t1, end);
}
