/* preint_calibrate.c - the error estimate of noise-separable's preintegrated
 * method (issue 21).
 *
 *   preint_calibrate [RAYS]     (default 4,000 per scene)
 *
 * The method's tau is the seed's product of per-axis means over K pieces;
 * its raw estimate is d = |tau(2K) - tau(K)|. On scenes that are not the
 * tests' or the benchmark's (other scales, octaves, contrasts, falloffs,
 * axes), for random camera-like rays (start within 2 units of the ground,
 * directions over the sphere, lengths log-uniform from 1 to 500 units, and
 * sky rays), it compares tau(K) with method=exact's tau of the same SPEC
 * and prints, per K, the quantiles of the ratio |error| / d and of the
 * relative error |error| / tau. src/core/noise_preint.c's estimate,
 * C d + R tau, takes C and R from here (with a margin) so that it covers
 * at least 99 % of rays. Deterministic (fixed seed). */
#include "splitmix.h"
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "scene.h"

static uint64_t rs = 0x13198a2e03707344ull;

static double uni(void)
{
    return splitmix_uni(&rs);
}

static int cmp(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return (x > y) - (x < y);
}

static double quant(double *v, long n, double q)
{
    qsort(v, (size_t) n, sizeof *v, cmp);
    long i = (long) ceil(q * (double) n) - 1;
    return v[i < 0 ? 0 : i];
}

static const char *const scenes[] = {
    "noise-separable:density=0.03:scale=7:octaves=3:axes=xz:falloff=0.08:contrast=0.6",
    "noise-separable:density=0.1:scale=3:octaves=5:axes=xyz:contrast=0.95",
    "noise-separable:density=0.01:scale=25:octaves=4:axes=xz:falloff=0.01:contrast=0.9:gain=0.6",
    "noise-separable:density=0.05:scale=12:octaves=2:axes=y:falloff=0.2:contrast=0.8",
};

int main(int argc, char **argv)
{
    const long n = argc > 1 ? atol(argv[1]) : 4000;
    static const int Ks[] = { 1, 4, 16 };
    for (int ki = 0; ki < 3; ++ki) {
        double *ratio = malloc((size_t) n * 4 * sizeof *ratio), *rel = malloc((size_t) n * 4 * sizeof *rel);
        double *dd = malloc((size_t) n * 4 * sizeof *dd), *mm = malloc((size_t) n * 4 * sizeof *mm),
               *ee = malloc((size_t) n * 4 * sizeof *ee);
        long m = 0;
        for (int sc = 0; sc < 4; ++sc) {
            ef_err err;
            ef_fog_context ctx;
            ef_fog_context_init(&ctx);
            ef_fog_component pc, ec, mc;
            char spec[512];
            snprintf(spec, sizeof spec, "%s:method=preintegrated:pieces=%d", scenes[sc], Ks[ki]);
            if (ef_fog_parse(spec, &ctx, &pc, &err)) {
                fprintf(stderr, "%s\n", err.msg);
                return 1;
            }
            snprintf(spec, sizeof spec, "%s:method=exact", scenes[sc]);
            if (ef_fog_parse(spec, &ctx, &ec, &err)) {
                fprintf(stderr, "%s\n", err.msg);
                return 1;
            }
            /* the mean fog (contrast 0: rho times the envelope's integral) */
            snprintf(spec, sizeof spec, "%s:contrast=0:method=preintegrated:pieces=1", scenes[sc]);
            char *cpos = strstr(spec, ":contrast=0.");
            if (cpos) {   /* drop the scene's own contrast */
                char *end = strchr(cpos + 1, ':');
                memmove(cpos, end, strlen(end) + 1);
            }
            if (ef_fog_parse(spec, &ctx, &mc, &err)) {
                fprintf(stderr, "%s\n", err.msg);
                return 1;
            }
            for (long k = 0; k < n; ++k) {
                ef_ray r;
                double l = 0;
                for (int a = 0; a < 3; ++a) {
                    r.dir[a] = uni() * 2 - 1;
                    l += r.dir[a] * r.dir[a];
                }
                l = sqrt(l);
                for (int a = 0; a < 3; ++a)
                    r.dir[a] /= l;
                r.org[0] = uni() * 200 - 100;
                r.org[1] = uni() * 2;
                r.org[2] = uni() * 200 - 100;
                r.dist = uni() < 0.2 && r.dir[1] > 0.05 ? INFINITY : exp(log(1) + uni() * log(500));
                r.planar = r.dist;
                double tp[3], te[3];
                ef_tau_info info;
                ef_fog_tau(&pc, &r, tp, &info);
                ef_fog_tau(&ec, &r, te, NULL);
                double tm[3];
                ef_fog_tau(&mc, &r, tm, NULL);
                if (!(te[0] > 0) || !isfinite(te[0]) || !isfinite(tp[0]))
                    continue;
                const double e = fabs(tp[0] - te[0]);
                ratio[m] = info.err[0] > 0 ? e / info.err[0] : (e > 0 ? INFINITY : 0);
                rel[m] = e / te[0];
                dd[m] = info.err[0];
                mm[m] = tm[0];
                ee[m] = e;
                m++;
            }
            ef_fog_free(&pc);
            ef_fog_free(&ec);
            ef_fog_free(&mc);
        }
        static const double Cs[] = { 2, 4 }, Rs[] = { 0.005, 0.01, 0.02, 0.05 };
        for (int ci = 0; ci < 2; ++ci)
            for (int ri = 0; ri < 4; ++ri) {
                long cov = 0;
                for (long j = 0; j < m; ++j)
                    cov += ee[j] <= Cs[ci] * dd[j] + Rs[ri] * mm[j];
                printf("  pieces=%d: C %g R %g covers %.2f %%\n", Ks[ki], Cs[ci], Rs[ri], 100.0 * cov / m);
            }
        free(dd);
        free(mm);
        free(ee);
        printf("pieces=%d (%ld rays): |error| / |tau(2K) - tau(K)|: median %.3g, 90%% %.3g, 99%% %.3g, "
               "99.5%% %.3g; |error| / tau: median %.3g, 99%% %.3g, 99.5%% %.3g\n",
               Ks[ki], m, quant(ratio, m, 0.5), quant(ratio, m, 0.9), quant(ratio, m, 0.99),
               quant(ratio, m, 0.995), quant(rel, m, 0.5), quant(rel, m, 0.99), quant(rel, m, 0.995));
        free(ratio);
        free(rel);
    }
    return 0;
}
