/* noise_sep_calibrate.c - the estimate of noise-separable's default method
 * (src/core/noise_sep.c) against the reference integrator, on fog and rays
 * that are not the sweep's.
 *
 *   noise_sep_calibrate [SPECS [RAYS]]     (default 48 and 200)
 *
 * Draws SPECS random noise-separable fogs from a fixed seed (one to three
 * axes, 2 to 7 octaves, scale 0.5 to 40, |contrast| up to 0.96 where the
 * clamp cannot bind, for half of them an envelope falling by e over 2 to
 * 20 scales, density so that a
 * ray's tau is 0.05 to 10), and per fog RAYS rays (an origin within two
 * scales of the lattice's origin, isotropic, axis-parallel or in a
 * coordinate plane, 0.1 to 40 scales long, a tenth to the sky at 11
 * degrees or more where the envelope falls). Per ray the
 * default method's T and error output against ef_ref_tau_long. Prints,
 * over the rays whose octaves were dropped (where the estimate is a
 * statistical one): the share of rays whose |dT| exceeds the error output
 * as the error AOV gives it, T expm1(err) (uncovered), the quantiles of
 * |dT| over it, and of |dT| against 2^-12. Deterministic. Nothing
 * asserts. */
#include "splitmix.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fog.h"
#include "ref.h"

static uint64_t rs = 0x5eb1ab1e0ddba11ull;

static double uni(double a, double b)
{
    return a + (b - a) * splitmix_uni(&rs);
}

static int cmp_d(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return x < y ? -1 : x > y;
}

static double quantile(double *v, int n, double q)
{
    if (n == 0)
        return NAN;
    qsort(v, (size_t) n, sizeof *v, cmp_d);
    int i = (int) ceil(q * n) - 1;
    return v[i < 0 ? 0 : i >= n ? n - 1 : i];
}

int main(int argc, char **argv)
{
    const int nspec = argc > 1 ? atoi(argv[1]) : 48, nray = argc > 2 ? atoi(argv[2]) : 200;
    double *ratio = malloc((size_t) nspec * (size_t) nray * sizeof *ratio);
    double *dts = malloc((size_t) nspec * (size_t) nray * sizeof *dts);
    if (!ratio || !dts)
        return 1;
    int nd = 0, all = 0, uncovered = 0, over = 0;
    static const char *const axes[] = { "x", "y", "z", "xz", "xy", "yz", "xyz" };
    for (int sp = 0; sp < nspec; ++sp) {
        const char *ax = axes[(int) uni(0, 7)];
        const int m = (int) strlen(ax), oct = (int) uni(2, 8);
        const double scale = exp(uni(log(0.5), log(40)));
        const double c = uni(-0.96, 0.96) / 1.0363538;
        /* an envelope that falls by e over 2 to 20 scales */
        const double fall = uni(0, 1) < 0.5 ? 0 : 1 / (uni(2, 20) * scale);
        const double tau_target = exp(uni(log(0.05), log(10)));
        const double len = uni(2, 40) * scale;
        const double rho = tau_target / len;
        char spec[256];
        snprintf(spec, sizeof spec, "noise-separable:density=%.6g:scale=%.6g:octaves=%d:contrast=%.4g:axes=%s%s",
                 rho, scale, oct, c, ax, fall > 0 ? "" : "");
        if (fall > 0)
            snprintf(spec + strlen(spec), sizeof spec - strlen(spec), ":falloff=%.4g:base=%.4g", fall,
                     uni(-2, 2) * scale);
        ef_fog_component comp;
        ef_err err = { 0 };
        if (ef_fog_parse(spec, NULL, &comp, &err)) {
            fprintf(stderr, "%s: %s\n", spec, err.msg);
            return 1;
        }
        (void) m;
        int sd = 0, su = 0, so = 0;
        for (int k = 0; k < nray; ++k) {
            ef_ray r;
            memset(&r, 0, sizeof r);
            double d[3], n2 = 0;
            for (int a = 0; a < 3; ++a) {
                r.org[a] = uni(-2, 2) * scale;
                d[a] = uni(-1, 1);
            }
            const int kind = (int) uni(0, 4);
            if (kind == 0) {
                d[0] = d[1] = d[2] = 0;
                d[(int) uni(0, 3)] = uni(0, 1) < 0.5 ? 1 : -1;
            } else if (kind == 1) {
                d[(int) uni(0, 3)] = 0;
            }
            for (int a = 0; a < 3; ++a)
                n2 += d[a] * d[a];
            if (!(n2 > 1e-6))
                d[0] = n2 = 1;
            for (int a = 0; a < 3; ++a)
                r.dir[a] = d[a] / sqrt(n2);
            r.dist = r.planar = uni(0, 1) < 0.1 && fall > 0 ? INFINITY : uni(0.05, 1) * len;
            if (isinf(r.dist) && fabs(r.dir[1]) < 0.2) {   /* sky rays climb or fall */
                r.dir[1] = r.dir[1] < 0 ? -0.2 : 0.2;
                const double h = sqrt(r.dir[0] * r.dir[0] + r.dir[2] * r.dir[2]);
                const double sc = sqrt(1 - 0.04) / (h > 0 ? h : 1);
                r.dir[0] *= h > 0 ? sc : 0;
                r.dir[2] *= h > 0 ? sc : 0;
                if (!(h > 0))
                    r.dir[1] = r.dir[1] < 0 ? -1 : 1;
            }
            /* CALIBRATE_ONLY=I: fog I alone (the same draws) */
            const char *only = getenv("CALIBRATE_ONLY");
            if (only && atoi(only) != sp + 1)
                continue;
            double tau[3];
            ef_tau_info info;
            ef_fog_tau(&comp, &r, tau, &info);
            long double ref[3];
            double reached = 0;
            const double rl = isinf(r.dist) ? 60 / (fall * fabs(r.dir[1])) + 2 * len : r.dist;
            if (ef_ref_tau_long(&comp, &r, rl, 4096, 30, ref, &reached, NULL))
                continue;
            if (reached < rl)
                continue;   /* the reference stopped: T below e^-30 either way */
            ++all;
            const double dtau = fabs((double) (ref[0] - tau[0]));
            const double dT = (double) fabsl(expl(-(long double) tau[0]) - expl(-ref[0]));
            if (dT > 0x1p-12) {
                ++over, ++so;
                if (getenv("CALIBRATE_DEBUG"))
                    fprintf(stderr, "  over: dir %.17g %.17g %.17g dist %g: tau %.12g ref %.12Lg err %.3g dropped %g evals %g\n",
                            r.dir[0], r.dir[1], r.dir[2], r.dist, tau[0], ref[0], info.err[0], info.dropped, info.evals);
            }
            if (!(info.dropped > 0))
                continue;
            ++sd;
            /* the error output as the error AOV has it: |dT| <= T expm1(err) */
            const double bound = (double) (expl(-(long double) tau[0]) * expm1l(info.err[0]));
            ratio[nd] = bound > 0 ? dT / bound : dT > 0 ? INFINITY : 0;
            dts[nd++] = dT;
            (void) dtau;
            if (!(dT <= bound)) {
                ++su, ++uncovered;
                if (getenv("CALIBRATE_DEBUG"))
                    fprintf(stderr, "  uncovered: org %g %g %g dir %.17g %.17g %.17g dist %g: tau %.12g ref %.12Lg err %.3g dropped %g\n",
                            r.org[0], r.org[1], r.org[2], r.dir[0], r.dir[1], r.dir[2], r.dist, tau[0],
                            ref[0], info.err[0], info.dropped);
            }
        }
        printf("%-100s rays with octaves dropped %3d, uncovered %d, |dT| > 2^-12 %d\n", spec, sd, su, so);
        fflush(stdout);
        ef_fog_free(&comp);
    }
    printf("\n%d rays, %d with octaves dropped: uncovered %d (%.3f %%); |dT| / error output: "
           "median %.3g, 99th %.3g, 99.9th %.3g, max %.3g; |dT| > 2^-12 on %d rays of all\n",
           all, nd, uncovered, nd ? 100.0 * uncovered / nd : 0.0, quantile(ratio, nd, 0.5),
           quantile(ratio, nd, 0.99), quantile(ratio, nd, 0.999), quantile(ratio, nd, 1), over);
    printf("|dT| on the dropped rays: median %.3g, 99.9th %.3g, max %.3g\n", quantile(dts, nd, 0.5),
           quantile(dts, nd, 0.999), quantile(dts, nd, 1));
    free(ratio);
    free(dts);
    return 0;
}
