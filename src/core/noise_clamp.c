/* The clamp's stop-loss tables (noise_clamp.h). */
#include "noise_clamp.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Samples of the noise's distribution, and the half-width of the grid in
 * bins (the grid spans [-EF_NOISE_BOUND, EF_NOISE_BOUND] for a unit sum of
 * weights). */
#define SAMPLES 65536
#define HALF 1024
/* Per table: ymax, var, then m and v at EF_CLAMP_POINTS + 1 points. */
#define REC (2 + 2 * (EF_CLAMP_POINTS + 1))

size_t ef_clamp_tables_size(int octaves)
{
    return (size_t) octaves * REC;
}

/* SplitMix64's next uniform in [0, 1): fixed points, the same tables on
 * every machine. */
static double next01(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return (double) ((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
}

int ef_clamp_tables_build(const ef_fbm *f, double *tab)
{
    const int N = f->octaves, nb = 2 * HALF + 1;
    const double delta = EF_NOISE_BOUND / HALF;
    double *noise = malloc(SAMPLES * sizeof *noise);
    double *p = calloc((size_t) nb, sizeof *p), *q = calloc((size_t) nb, sizeof *q);
    double *h = calloc((size_t) nb, sizeof *h);
    if (!noise || !p || !q || !h) {
        free(noise);
        free(p);
        free(q);
        free(h);
        return -1;
    }
    uint64_t seed = 0x6e6f697365ull;
    for (int k = 0; k < SAMPLES; ++k) {
        const double x = 256 * next01(&seed), y = 256 * next01(&seed), z = 256 * next01(&seed);
        noise[k] = ef_noise3(x, y, z);
    }
    /* X_N = 0; X_j = X_{j+1} + w_j n, by convolution from the finest up */
    p[HALF] = 1;
    for (int j = N - 1; j >= 0; --j) {
        const double w = f->weight[j];
        memset(h, 0, (size_t) nb * sizeof *h);
        int lo = HALF, hi = HALF;
        for (int k = 0; k < SAMPLES; ++k)
            for (int sgn = -1; sgn <= 1; sgn += 2) {
                int b = HALF + (int) lround(sgn * w * noise[k] / delta);
                b = b < 0 ? 0 : b >= nb ? nb - 1 : b;
                h[b] += 0.5 / SAMPLES;
                lo = b < lo ? b : lo;
                hi = b > hi ? b : hi;
            }
        memset(q, 0, (size_t) nb * sizeof *q);
        for (int a = 0; a < nb; ++a) {
            if (p[a] == 0)
                continue;
            for (int b = lo; b <= hi; ++b) {
                const int c = a + b - HALF;
                if (c >= 0 && c < nb)
                    q[c] += p[a] * h[b];
            }
        }
        memcpy(p, q, (size_t) nb * sizeof *p);
        /* the table of X_j */
        double *t = tab + (size_t) j * REC;
        int top = HALF;
        double var = 0;
        for (int a = 0; a < nb; ++a)
            if (p[a] > 0) {
                const double x = (a - HALF) * delta;
                var += p[a] * x * x;
                if (a > top)
                    top = a;
            }
        const double ymax = (top - HALF) * delta;
        t[0] = ymax;
        t[1] = var;
        for (int k = 0; k <= EF_CLAMP_POINTS; ++k) {
            const double y = ymax * k / EF_CLAMP_POINTS;
            double m = 0, v = 0;
            for (int a = top; a >= HALF; --a) {
                const double d = (a - HALF) * delta - y;
                if (d <= 0)
                    break;
                m += p[a] * d;
                v += p[a] * d * d;
            }
            t[2 + k] = m;
            t[2 + EF_CLAMP_POINTS + 1 + k] = v;
        }
    }
    free(noise);
    free(p);
    free(q);
    free(h);
    return 0;
}

/* m and v at y >= 0 by linear interpolation (0 past ymax). */
static double lookup(const double *t, double y, double *v)
{
    const double ymax = t[0];
    if (!(y < ymax)) {
        *v = 0;
        return 0;
    }
    const double u = y / ymax * EF_CLAMP_POINTS;
    int k = (int) u;
    if (k >= EF_CLAMP_POINTS)
        k = EF_CLAMP_POINTS - 1;
    const double f = u - k;
    const double *m = t + 2, *vv = t + 2 + EF_CLAMP_POINTS + 1;
    *v = vv[k] + f * (vv[k + 1] - vv[k]);
    return m[k] + f * (m[k + 1] - m[k]);
}

double ef_clamp_m(const double *tab, int octaves, int j, double y, double *v)
{
    if (j >= octaves) {
        const double r = y < 0 ? -y : 0;
        *v = r * r;
        return r;
    }
    const double *t = tab + (size_t) j * REC;
    if (y >= 0)
        return lookup(t, y, v);
    /* E[max(0, X - y)] = -y + E[max(0, -X + y)] = -y + m(-y) (X symmetric),
     * and E[max(0, X - y)^2] = E[(X - y)^2] - v(-y) = var + y^2 - v(-y) */
    double w;
    const double m = lookup(t, -y, &w);
    *v = t[1] + y * y - w;
    if (*v < 0)
        *v = 0;
    return -y + m;
}

double ef_clamp_var(const double *tab, int octaves, int j)
{
    return j >= octaves ? 0 : tab[(size_t) j * REC + 1];
}

double ef_clamp_ymax(const double *tab, int octaves, int j)
{
    return j >= octaves ? 0 : tab[(size_t) j * REC];
}
