#include "apply.h"

#include <float.h>
#include <math.h>

/* double -> float without the undefined behaviour of an out-of-range cast. */
static float to_float(double v)
{
    if (v > FLT_MAX)
        return INFINITY;
    if (v < -FLT_MAX)
        return -INFINITY;
    return (float) v;
}

/* The reconstructed world point's axis k minus the origin: on a sky ray,
 * dir * inf, which is 0 (not NaN) where dir is 0. */
static double aov_p(const ef_ray *r, const double origin[3], int k)
{
    if (!isfinite(r->dist))
        return r->dir[k] == 0.0 ? 0.0 : r->dir[k] > 0.0 ? INFINITY : -INFINITY;
    return (r->org[k] - origin[k]) + r->dir[k] * r->dist;
}

/* |dT| <= T expm1(e) for |d tau| <= e; T is in [0, 1], so 1 bounds it too. */
static double aov_err(double T, double e)
{
    if (!(e > 0.0))
        return 0.0;
    const double b = T * expm1(e);
    return b < 1.0 ? b : 1.0;   /* also when b is NaN (T = 0, e = inf) */
}

void ef_fog_block_aov(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                      float *alpha, const float *depth, const ef_aov_out *aov,
                      ef_tau_stats *stats)
{
    const ef_fog_scene *s = pass->scene;
    const int fog_uncovered = s->sky != EF_SKY_KEEP;
    const unsigned mask = aov ? aov->mask : 0;
    static const double zero3[3] = { 0, 0, 0 };
    const double *origin = aov ? aov->origin : zero3;
    /* Only the numerical components have info to give. */
    int any_info = 0;
    for (int c = 0; c < s->ncomp; ++c)
        any_info |= s->comp[c].model->tau_info != NULL;
    const int want_info = any_info && (stats || (mask & EF_AOV_ERROR));
    ef_tau_info info[EF_FOG_MAX_COMPONENTS];
    for (int yy = 0; yy < h; ++yy) {
        const int y = y0 + yy;
        for (int xx = 0; xx < w; ++xx) {
            const int x = x0 + xx;
            const size_t i = (size_t) yy * (size_t) w + (size_t) xx;
            ef_ray r;
            const int sky = ef_reconstruct(pass->cam, pass->conv, x, y, depth[i], &r);
            if (mask & EF_AOV_P)
                for (int k = 0; k < 3; ++k)
                    aov->P[k][i] = to_float(aov_p(&r, origin, k));
            if (mask & EF_AOV_DISTANCE)
                aov->dist[i] = to_float(r.dist);
            if (sky && s->sky == EF_SKY_KEEP) {
                for (int k = 0; k < 4 && (mask & EF_AOV_FOG); ++k)
                    aov->fog[k][i] = 0.0f;
                for (int k = 0; k < 3 && (mask & EF_AOV_T); ++k)
                    aov->T[k][i] = 1.0f;
                for (int k = 0; k < 3 && (mask & EF_AOV_ERROR); ++k)
                    aov->err[k][i] = 0.0f;
                continue;
            }
            if (sky && s->sky == EF_SKY_DISTANCE_MODE)
                ef_ray_at_distance(pass->cam, x, y, s->sky_distance, &r);
            ef_fog_sample surf, inf;
            double c[3], in[3], a = alpha ? alpha[i] : 1.0;
            /* A NaN or infinite alpha is damaged data: the pixel is fogged
             * as opaque and its alpha written back as it was, so no NaN or
             * inf appears that the input did not have. */
            const int bad_alpha = !isfinite(a);
            if (bad_alpha)
                a = 1.0;
            const double a_in = a;
            /* The fog behind only reaches the uncovered part (1 - a) of a pixel. */
            const int need_inf = fog_uncovered && !(a == 1.0 && isfinite(r.dist));
            ef_scene_eval_info(s, &r, &surf, need_inf ? &inf : NULL, want_info ? info : NULL);
            if (!need_inf)
                inf = surf;
            for (int k = 0; k < 3; ++k)
                in[k] = c[k] = rgb[k][i];
            ef_composite(&surf, &inf, fog_uncovered, c, alpha ? &a : NULL);
            for (int k = 0; k < 3; ++k)
                rgb[k][i] = to_float(c[k]);
            if (alpha && !bad_alpha)
                alpha[i] = to_float(a);
            if (mask & EF_AOV_FOG) {
                for (int k = 0; k < 3; ++k)
                    aov->fog[k][i] =
                        to_float(c[k] - (surf.T[k] > 0.0 ? surf.T[k] * in[k] : 0.0));
                aov->fog[3][i] = alpha ? to_float(a - a_in) : 0.0f;
            }
            if (mask & EF_AOV_T)
                for (int k = 0; k < 3; ++k)
                    aov->T[k][i] = to_float(surf.T[k]);
            if (mask & EF_AOV_ERROR) {
                double e[3] = { 0, 0, 0 };
                for (int n = 0; want_info && n < s->ncomp; ++n)
                    for (int k = 0; k < 3; ++k)
                        e[k] += info[n].err[k];
                for (int k = 0; k < 3; ++k)
                    aov->err[k][i] = to_float(aov_err(surf.T[k], e[k]));
            }
            if (stats && want_info)
                for (int n = 0; n < s->ncomp; ++n)
                    if (s->comp[n].model->tau_info)
                        ef_tau_stats_add(&stats[n], &info[n]);
        }
    }
}

void ef_fog_block(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                  float *alpha, const float *depth)
{
    ef_fog_block_aov(pass, x0, y0, w, h, rgb, alpha, depth, NULL, NULL);
}
