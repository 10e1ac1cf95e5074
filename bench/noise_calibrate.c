/* noise_calibrate.c - the error constants of the adaptive noise method.
 *
 *   noise_calibrate [CHORDS]     (default 2,000,000)
 *
 * For random chords through random lattice cells (a uniform point in the
 * cell and an isotropic direction, so long chords weigh more, which errs on
 * the safe side), integrates Perlin's noise over the chord with q-point
 * Gauss-Legendre, q = 1..8, and with 9 points (exact: the noise is a
 * degree-16 polynomial along a line inside a cell), and prints per q the
 * maximum of |error| / chord length and sqrt(mean error^2 / mean length^2).
 * src/core/noise_plan.c uses these (e_max, e_rms) (times a margin) to pick nodes per octave.
 * It also prints the RMS of the noise's integral over straight stretches of
 * 4, 16 and 64 lattice units divided by sqrt(length) (the octave-dropping
 * rule's constant). Deterministic (fixed seed). */
#include "splitmix.h"
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "noise.h"

static uint64_t rs = 0x243f6a8885a308d3ull;

static double uni(void)
{
    return splitmix_uni(&rs);
}

/* Gauss-Legendre nodes on [-1, 1] (Newton on the recurrence). */
static void gl(int n, double *x, double *w)
{
    for (int i = 0; i < n; ++i) {
        long double z = cosl(3.14159265358979323846264338327950288L * (i + 0.75L) / (n + 0.5L)), dp = 1;
        for (int it = 0; it < 100; ++it) {
            long double p0 = 1, p1 = z;
            for (int j = 2; j <= n; ++j) {
                long double p2 = ((2 * j - 1) * z * p1 - (j - 1) * p0) / j;
                p0 = p1;
                p1 = p2;
            }
            if (n == 1)
                p0 = 1;
            dp = n * (z * p1 - p0) / (z * z - 1);
            long double dz = p1 / dp;
            z -= dz;
            if (fabsl(dz) < 1e-19L)
                break;
        }
        x[i] = (double) z;
        w[i] = (double) (2 / ((1 - z * z) * dp * dp));
    }
}

static double X[17][17], W[17][17];

static double integrate(int q, const double c[3], const double o[3], const double d[3], double ta,
                        double tb)
{
    const double mid = (ta + tb) / 2, half = (tb - ta) / 2;
    double s = 0;
    for (int j = 0; j < q; ++j) {
        const double t = mid + half * X[q][j];
        /* Stay inside the cell: fractions clamped to [0, 1]. */
        double p[3];
        for (int a = 0; a < 3; ++a) {
            double f = o[a] + t * d[a];
            f = f < 0 ? 0 : f > 1 ? 1 : f;
            p[a] = c[a] + f;
        }
        s += W[q][j] * ef_noise3(p[0], p[1], p[2]);
    }
    return half * s;
}

int main(int argc, char **argv)
{
    const long n = argc > 1 ? atol(argv[1]) : 2000000;
    for (int q = 1; q <= 16; ++q)
        gl(q, X[q], W[q]);
    double emax[9] = { 0 }, e2[9] = { 0 }, h2 = 0;
    for (long k = 0; k < n; ++k) {
        double c[3], o[3], d[3];
        for (int a = 0; a < 3; ++a) {
            /* a cell corner well inside the period, offset by a fraction 0.5
             * from the corner so the sample point is the cell's own. */
            c[a] = floor(uni() * 256);
            o[a] = uni();
        }
        double l;
        do {
            for (int a = 0; a < 3; ++a)
                d[a] = 2 * uni() - 1;
            l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        } while (l > 1 || l < 1e-3);
        for (int a = 0; a < 3; ++a)
            d[a] /= l;
        double ta = -INFINITY, tb = INFINITY;
        for (int a = 0; a < 3; ++a) {
            if (d[a] == 0)
                continue;
            double t0 = (0 - o[a]) / d[a], t1 = (1 - o[a]) / d[a];
            if (t0 > t1) {
                double x = t0;
                t0 = t1;
                t1 = x;
            }
            if (t0 > ta)
                ta = t0;
            if (t1 < tb)
                tb = t1;
        }
        const double h = tb - ta, exact = integrate(9, c, o, d, ta, tb);
        h2 += h * h;
        for (int q = 1; q <= 8; ++q) {
            const double e = fabs(integrate(q, c, o, d, ta, tb) - exact);
            if (e / h > emax[q])
                emax[q] = e / h;
            e2[q] += e * e;
        }
    }
    printf("q  max|err|/length  rms err/rms length\n");
    for (int q = 1; q <= 8; ++q)
        printf("%d  %.3g  %.3g\n", q, emax[q], sqrt(e2[q] / h2));
    /* RMS of the integral over straight stretches, per sqrt(length). */
    for (int len = 4; len <= 64; len *= 4) {
        double s2 = 0;
        const int rays = 400;
        for (int r = 0; r < rays; ++r) {
            double o[3], d[3], l;
            for (int a = 0; a < 3; ++a)
                o[a] = uni() * 256;
            do {
                for (int a = 0; a < 3; ++a)
                    d[a] = 2 * uni() - 1;
                l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            } while (l > 1 || l < 1e-3);
            /* 64 midpoint samples per lattice unit: far below 1e-3 of the RMS. */
            const int m = 64 * len;
            double s = 0;
            for (int j = 0; j < m; ++j) {
                const double t = (j + 0.5) * len / m;
                s += ef_noise3(o[0] + t * d[0] / l, o[1] + t * d[1] / l, o[2] + t * d[2] / l);
            }
            s *= (double) len / m;
            s2 += s * s;
        }
        printf("line integral over %d units: rms / sqrt(length) = %.3f\n", len,
               sqrt(s2 / rays) / sqrt(len));
    }
    return 0;
}
