/* grid_calibrate.c - the error constants of the adaptive noise method's grid.
 *
 *   grid_calibrate [LINES]     (default 2,000 per direction class and length)
 *
 * The noise fog integrates an octave along a segment either by
 * walking its lattice cells (per-cell Gauss-Legendre; noise_calibrate.c) or
 * on a grid: the composite midpoint rule with nu nodes per lattice unit and
 * an end correction formed from the nodes themselves (grid_walk). This
 * program runs that very code (noise_grid.c's, through noise_fog.h) on
 * random straight lines through Perlin's noise, against each line integrated exactly (the
 * noise is a degree-16 polynomial along a line inside a cell: 9-point
 * Gauss-Legendre per cell, the cells found on their own here), and prints
 * per nu the root mean square error per square root of the lattice length
 * and the 99.9th percentile and maximum of |error| / that rms, for three
 * direction classes (isotropic, within 3 degrees of an axis, near a
 * diagonal) and lengths 2 to 128 lattice units. grid_rms in noise_fog.h is
 * the largest rms of each column plus 10 %. Deterministic (fixed seed).
 * Calibrated on random lines, not on any scene the tests render. */
#include "noise_fog.h"

#include <stdio.h>
#include "splitmix.h"

static uint64_t rs = 0x243f6a8885a308d3ull;

static double uni(void)
{
    return splitmix_uni(&rs);
}

/* integral of noise over b + t d, t in [0, L], cell by cell exactly */
static double exact_line(const double b[3], const double d[3], double L, const double *gx,
                         const double *gw)
{
    double t = 0, s = 0;
    while (t < L) {
        double tn = L;
        for (int a = 0; a < 3; ++a) {
            if (d[a] == 0)
                continue;
            const double v = b[a] + t * d[a];
            double c = floor(v);
            if (d[a] < 0 && c == v)
                c -= 1;
            double nf = d[a] > 0 ? (c + 1 - b[a]) / d[a] : (c - b[a]) / d[a];
            if (!(nf > t))
                nf = nextafter(t, INFINITY);
            if (nf < tn)
                tn = nf;
        }
        const double h = (tn - t) / 2, m = (tn + t) / 2;
        for (int i = 0; i < 9; ++i) {
            const double u = m + h * gx[i];
            s += h * gw[i] * ef_noise3(b[0] + u * d[0], b[1] + u * d[1], b[2] + u * d[2]);
        }
        t = tn;
    }
    return s;
}

static int cmpd(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return x < y ? -1 : x > y;
}

int main(int argc, char **argv)
{
    const int nl = argc > 1 ? atoi(argv[1]) : 2000;
    if (nl < 10) {
        fprintf(stderr, "usage: grid_calibrate [LINES >= 10]\n");
        return 2;
    }
    double gx[9], gw[9];
    ef_nz_gauss_legendre(9, gx, gw);
    /* a state heading its hash tables, as finish_noise lays them out */
    const size_t head = (sizeof(nstate) + sizeof(double) - 1) / sizeof(double);
    double *arr = calloc(head + GRID_HASH_WORDS / 2, sizeof *arr);
    if (!arr)
        return 1;
    nstate *sp = (nstate *) (void *) arr;
    sp->k = 0;
    sp->hash_off = (int) head;
    ef_nz_grid_tables((uint32_t *) (void *) (arr + head));
    const nstate *stp = sp;
    double *err = malloc(sizeof(double) * (size_t) nl);
    if (!err)
        return 1;
    const double Ls[] = { 2, 4, 8, 32, 128 };
    const char *cls[] = { "isotropic", "near an axis", "near a diagonal" };
    double worst[GRID_N] = { 0 };
    printf("rms error per sqrt(lattice unit) / p99.9 over rms / max over rms, %d lines each\n", nl);
    for (int k = 0; k < 3; ++k) {
        printf("%s:\n", cls[k]);
        for (int li = 0; li < 5; ++li) {
            const double L = Ls[li];
            printf("  L=%-4g", L);
            for (int g = 0; g < GRID_N; ++g) {
                double se = 0;
                for (int r = 0; r < nl; ++r) {
                    double d[3], b[3], nn;
                    if (k == 0) {
                        do {
                            for (int a = 0; a < 3; ++a)
                                d[a] = 2 * uni() - 1;
                            nn = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                        } while (nn > 1 || nn < 0.01);
                    } else if (k == 1) {
                        for (int a = 0; a < 3; ++a)
                            d[a] = 0.05 * (2 * uni() - 1);
                        d[r % 3] = 1;
                        nn = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                    } else {
                        for (int a = 0; a < 3; ++a)
                            d[a] = (uni() < 0.5 ? -1 : 1) + 0.05 * (2 * uni() - 1);
                        nn = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                    }
                    nn = sqrt(nn);
                    rayc R;
                    memset(&R, 0, sizeof R);
                    R.s = stp;
                    for (int a = 0; a < 3; ++a) {
                        d[a] /= nn;
                        b[a] = 256 * uni();
                        R.u[a] = (lin) { b[a], d[a], b[a], d[a] };
                    }
                    const double ex = exact_line(b, d, L, gx, gw);
                    const double v = ef_nz_octave_grid_flat(&R, 0, grid_nu[g], 0, L, NULL);
                    se += (v - ex) * (v - ex);
                    err[r] = fabs(v - ex);
                }
                const double rms = sqrt(se / nl);
                qsort(err, (size_t) nl, sizeof *err, cmpd);
                printf("  nu=%g %.2e/%.1f/%.1f", grid_nu[g], rms / sqrt(L),
                       err[(int) (nl * 0.999)] / rms, err[nl - 1] / rms);
                if (rms / sqrt(L) > worst[g])
                    worst[g] = rms / sqrt(L);
            }
            printf("\n");
        }
    }
    printf("largest rms per sqrt(lattice unit), plus 10 %%:");
    for (int g = 0; g < GRID_N; ++g)
        printf(" %.2g", 1.1 * worst[g]);
    printf("\n");
    free(err);
    free(arr);
    return 0;
}
