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

/* One span of a row: its rays, and where each pixel's fog is found. */
typedef struct span {
    ef_ray r[EF_RECON_SPAN];
    unsigned char sky[EF_RECON_SPAN];
    double a[EF_RECON_SPAN];             /* alpha as fogged (1 for a damaged one) */
    unsigned char bad_alpha[EF_RECON_SPAN];
    unsigned char need_inf[EF_RECON_SPAN];
    /* Batched evaluation: surf[j] is the fog along r[j]; the far segments
     * that differ from r[j] are q[0..nq), their fog far[], and inf[j] points
     * at pixel j's far fog (surf[j] itself when there is none or it is r[j]). */
    ef_fog_sample surf[EF_RECON_SPAN];
    ef_ray q[EF_RECON_SPAN];
    ef_fog_sample far[EF_RECON_SPAN];
    const ef_fog_sample *inf[EF_RECON_SPAN];
    int nq;
} span;

/* Queues pixel j's far segment when it is another segment than r[j]. */
static void queue_far(const ef_fog_scene *s, span *sp, int j)
{
    sp->inf[j] = &sp->surf[j];
    if (!sp->need_inf[j])
        return;
    ef_ray *far = &sp->q[sp->nq];
    if (ef_scene_far_ray(s, &sp->r[j], far) && far->planar == sp->r[j].planar)
        return;
    sp->inf[j] = &sp->far[sp->nq++];
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
    int any_info = 0, depth_only = 1;
    for (int c = 0; c < s->ncomp; ++c) {
        any_info |= s->comp[c].model->tau_info != NULL;
        depth_only &= s->comp[c].model->depth_only;
    }
    const int want_info = any_info && (stats || (mask & EF_AOV_ERROR));
    /* Without info, every segment of a span is evaluated in one batch. */
    const int batch = !want_info;
    const int need_dir = !depth_only || (mask & EF_AOV_P);
    ef_tau_info info[EF_FOG_MAX_COMPONENTS];
    span *sp = &(span) { .nq = 0 };
    for (int yy = 0; yy < h; ++yy) {
        const int y = y0 + yy;
        for (int xs = 0; xs < w; xs += EF_RECON_SPAN) {
            const int n = w - xs < EF_RECON_SPAN ? w - xs : EF_RECON_SPAN;
            const size_t i0 = (size_t) yy * (size_t) w + (size_t) xs;
            ef_reconstruct_span(pass->cam, pass->conv, x0 + xs, y, n, depth + i0, need_dir, sp->r,
                                sp->sky);
            sp->nq = 0;
            for (int j = 0; j < n; ++j) {
                const size_t i = i0 + (size_t) j;
                ef_ray *r = &sp->r[j];
                if (mask & EF_AOV_P)
                    for (int k = 0; k < 3; ++k)
                        aov->P[k][i] = to_float(aov_p(r, origin, k));
                if (mask & EF_AOV_DISTANCE)
                    aov->dist[i] = to_float(r->dist);
                if (sp->sky[j] && s->sky == EF_SKY_KEEP)
                    continue;
                if (sp->sky[j] && s->sky == EF_SKY_DISTANCE_MODE)
                    ef_ray_at_distance(pass->cam, x0 + xs + j, y, s->sky_distance, r);
                const double a = alpha ? alpha[i] : 1.0;
                /* A NaN or infinite alpha is damaged data: the pixel is
                 * fogged as opaque and its alpha written back as it was,
                 * so no NaN or inf appears that the input did not have. */
                sp->bad_alpha[j] = !isfinite(a);
                sp->a[j] = sp->bad_alpha[j] ? 1.0 : a;
                /* The fog behind only reaches the uncovered part (1 - a) of a pixel. */
                sp->need_inf[j] = fog_uncovered && !(sp->a[j] == 1.0 && isfinite(r->dist));
                if (batch)
                    queue_far(s, sp, j);
            }
            if (batch) {
                /* Pixels kept as they are (--sky keep) cost one wasted
                 * segment each here, no branch per pixel. */
                ef_scene_eval_rays(s, sp->r, n, sp->surf);
                ef_scene_eval_rays(s, sp->q, sp->nq, sp->far);
            }
            for (int j = 0; j < n; ++j) {
                const size_t i = i0 + (size_t) j;
                if (sp->sky[j] && s->sky == EF_SKY_KEEP) {
                    for (int k = 0; k < 4 && (mask & EF_AOV_FOG); ++k)
                        aov->fog[k][i] = 0.0f;
                    for (int k = 0; k < 3 && (mask & EF_AOV_T); ++k)
                        aov->T[k][i] = 1.0f;
                    for (int k = 0; k < 3 && (mask & EF_AOV_ERROR); ++k)
                        aov->err[k][i] = 0.0f;
                    continue;
                }
                ef_fog_sample one, other;
                const ef_fog_sample *surf = &sp->surf[j], *inf = sp->inf[j];
                if (!batch) {
                    ef_scene_eval_info(s, &sp->r[j], &one, sp->need_inf[j] ? &other : NULL,
                                       want_info ? info : NULL);
                    surf = &one;
                    inf = sp->need_inf[j] ? &other : &one;
                }
                double c[3], in[3], a = sp->a[j];
                const double a_in = a;
                for (int k = 0; k < 3; ++k)
                    in[k] = c[k] = rgb[k][i];
                ef_composite(surf, inf, fog_uncovered, c, alpha ? &a : NULL);
                for (int k = 0; k < 3; ++k)
                    rgb[k][i] = to_float(c[k]);
                if (alpha && !sp->bad_alpha[j])
                    alpha[i] = to_float(a);
                if (mask & EF_AOV_FOG) {
                    for (int k = 0; k < 3; ++k)
                        aov->fog[k][i] =
                            to_float(c[k] - (surf->T[k] > 0.0 ? surf->T[k] * in[k] : 0.0));
                    aov->fog[3][i] = alpha ? to_float(a - a_in) : 0.0f;
                }
                if (mask & EF_AOV_T)
                    for (int k = 0; k < 3; ++k)
                        aov->T[k][i] = to_float(surf->T[k]);
                if (mask & EF_AOV_ERROR) {
                    double e[3] = { 0, 0, 0 };
                    for (int nn = 0; want_info && nn < s->ncomp; ++nn)
                        for (int k = 0; k < 3; ++k)
                            e[k] += info[nn].err[k];
                    for (int k = 0; k < 3; ++k)
                        aov->err[k][i] = to_float(aov_err(surf->T[k], e[k]));
                }
                if (stats && want_info)
                    for (int nn = 0; nn < s->ncomp; ++nn)
                        if (s->comp[nn].model->tau_info)
                            ef_tau_stats_add(&stats[nn], &info[nn]);
            }
        }
    }
}

void ef_fog_block(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                  float *alpha, const float *depth)
{
    ef_fog_block_aov(pass, x0, y0, w, h, rgb, alpha, depth, NULL, NULL);
}
