#include "apply.h"
#include "ms.h"
#include "sky_light.h"

#include "exact.h"
#include "expneg.h"
#include "lit.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

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

/* A light's share over a pixel's coverage: a S along the surface segment
 * plus (1 - a) S_far along the far one where it shows (a share of 0 takes
 * nothing, even an infinite S). One expression for every path, so the
 * span path and the per-pixel path give the same bits. */
static inline double coverage_sum(double a, int shows, double S, double Sf)
{
    return (a > 0.0 ? a * S : 0.0) + (shows && a < 1.0 ? (1.0 - a) * Sf : 0.0);
}

/* add[j] += coverage_sum(a[j], shows[j], S[j], Sf[j]) for j < n, in a
 * loop the compiler vectorises (the arrays do not overlap add) */
EF_INLINE void span_coverage(int n, const double *restrict a,
                             const unsigned char *restrict shows, const double *restrict S,
                             const double *restrict Sf, double *restrict add)
{
    for (int j = 0; j < n; ++j)
        add[j] += coverage_sum(a[j], shows[j], S[j], Sf[j]);
}

/* One light's a S + (1 - a) S_far (far: the far segment when it differs
 * from r; need_inf: the far part shows), and the same sum of their error
 * estimates in ve (NULL: not wanted). */
static void coverage_light(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                           const ef_ray *far, double a, int need_inf, double v[3], double ve[3])
{
    double S[3], Sf[3], E[3], Ef[3];
    ef_light_inscatter(s, l, r, S, E);
    memcpy(Sf, S, sizeof Sf);
    memcpy(Ef, E, sizeof Ef);
    if (far)
        ef_light_inscatter(s, l, far, Sf, Ef);
    for (int k = 0; k < 3; ++k) {
        v[k] = coverage_sum(a, need_inf, S[k], Sf[k]);
        if (ve)
            ve[k] = coverage_sum(a, need_inf, E[k], Ef[k]);
    }
}

/* Every light's S and E along a span's rays and along their far segments
 * (Sf, Ef: S and E where the far segment is the ray's own), from
 * ef_light_rays: coverage_light's values, the same bits. */
typedef struct light_cache {
    double S[3][EF_RECON_SPAN], E[3][EF_RECON_SPAN], Sf[3][EF_RECON_SPAN], Ef[3][EF_RECON_SPAN];
} light_cache;

/* Fills lc[l] for every light over r[0..n) (need_inf[j]: pixel j's far
 * part shows; skip[j]: a kept pixel, not evaluated); the estimates E and
 * Ef only with want_err (else 0: the error output is not asked for, and a
 * lamp's multiple scattering skips its estimate's reads). */
static void light_cache_fill(const ef_fog_scene *s, const ef_ray *r, int n,
                             const unsigned char *need_inf, const unsigned char *skip,
                             int want_err, light_cache *lc)
{
    ef_ray far[EF_RECON_SPAN];
    int fj[EF_RECON_SPAN], nf = 0;
    for (int j = 0; j < n; ++j)
        if (!skip[j] && need_inf[j] && !ef_scene_far_ray(s, &r[j], &far[nf]))
            fj[nf++] = j;
    for (int l = 0; l < s->nlight; ++l) {
        light_cache *c = &lc[l];
        double *const S[3] = { c->S[0], c->S[1], c->S[2] }, *const E[3] = { c->E[0], c->E[1], c->E[2] };
        if (!want_err)
            for (int k = 0; k < 3; ++k)
                memset(c->E[k], 0, (size_t) n * sizeof c->E[k][0]);
        ef_light_rays(s, &s->light[l], r, n, S, want_err ? E : NULL);
        for (int k = 0; k < 3; ++k) {
            memcpy(c->Sf[k], c->S[k], (size_t) n * sizeof c->S[k][0]);
            memcpy(c->Ef[k], c->E[k], (size_t) n * sizeof c->E[k][0]);
        }
        if (nf) {
            double Sq[3][EF_RECON_SPAN], Eq[3][EF_RECON_SPAN];
            double *const Sqk[3] = { Sq[0], Sq[1], Sq[2] }, *const Eqk[3] = { Eq[0], Eq[1], Eq[2] };
            ef_light_rays(s, &s->light[l], far, nf, Sqk, want_err ? Eqk : NULL);
            for (int m = 0; m < nf; ++m)
                for (int k = 0; k < 3; ++k) {
                    c->Sf[k][fj[m]] = Sq[k][m];
                    c->Ef[k][fj[m]] = want_err ? Eq[k][m] : 0;
                }
        }
    }
}

/* The lights' in-scattered light over the pixel's coverage: a S along the
 * surface segment plus (1 - a) S along the far one (need_inf: it shows),
 * from lc (pixel j of the span) where given. With the lit AOV, a shadowed
 * light's share that passes its occluders: the same sum without the map
 * in the denominator. */
static void add_lights(const ef_fog_scene *s, const ef_ray *r, double a, int need_inf,
                       double c[3], const ef_aov_out *aov, size_t i, double lerr[3],
                       const light_cache *lc, int j)
{
    ef_ray far;
    const int other = !lc && need_inf && !ef_scene_far_ray(s, r, &far);
    double sum[3] = { 0, 0, 0 };
    /* light by light (each its own AOV layer), summed in the scene's order */
    for (int l = 0; l < s->nlight; ++l) {
        const int lit = aov && aov->lit[l];
        double v[3], ve[3], u[3] = { 0, 0, 0 };
        if (lc)
            for (int k = 0; k < 3; ++k) {
                v[k] = coverage_sum(a, need_inf, lc[l].S[k][j], lc[l].Sf[k][j]);
                ve[k] = coverage_sum(a, need_inf, lc[l].E[k][j], lc[l].Ef[k][j]);
            }
        else
            coverage_light(s, &s->light[l], r, other ? &far : NULL, a, need_inf, v, ve);
        for (int k = 0; k < 3; ++k)
            lerr[k] += ve[k];
        if (lit) {
            ef_light bare = s->light[l];
            bare.shadow = NULL;
            ef_ray f2;
            const int o2 = need_inf && !ef_scene_far_ray(s, r, &f2);
            coverage_light(s, &bare, r, o2 ? &f2 : NULL, a, need_inf, u, NULL);
            const double num = v[0] + v[1] + v[2], den = u[0] + u[1] + u[2];
            aov->lit[l][i] = den > 0 && isfinite(den) ? to_float(num / den) : 1.0f;
        }
        for (int k = 0; k < 3; ++k) {
            sum[k] += v[k];
            if (aov && aov->light[l][k])
                aov->light[l][k][i] = to_float(v[k]);
        }
    }
    for (int k = 0; k < 3; ++k)
        c[k] += sum[k];
}

/* The sky light scattered in along a segment of direction r->dir whose
 * transmittance is T (r: for the components' optical depths when they
 * scatter differently): sum_c albedo_c C_c(u) (share_c of 1 - T); with
 * scattering=multiple, the sky carried through the fog instead, and its
 * estimate into err (may be NULL; else untouched). */
static void sky_segment(const ef_fog_scene *s, const ef_ray *r, const double T[3], double out[3],
                        double err[3])
{
    const double *up = s->ctx.up;
    out[0] = out[1] = out[2] = 0;
    if (s->sky_multiple) {   /* carried through the fog, every order (ms.h) */
        ef_ms_gather_view(s->sky_ms, &s->sky_ms_view, s, r, NULL, out, err);
        return;
    }
    int same = 1;
    for (int c = 1; c < s->ncomp; ++c) {
        const ef_fog_component *a = &s->comp[0], *b = &s->comp[c];
        same &= a->phase == b->phase && a->g == b->g && a->has_albedo == b->has_albedo &&
                (!a->has_albedo || !memcmp(a->albedo, b->albedo, sizeof a->albedo));
    }
    double tau[EF_FOG_MAX_COMPONENTS][3], tot[3] = { 0, 0, 0 };
    if (!same)
        for (int c = 0; c < s->ncomp; ++c) {
            s->comp[c].model->tau(&s->comp[c], r, tau[c]);
            for (int k = 0; k < 3; ++k)
                tot[k] += tau[c][k];
        }
    for (int c = 0; c < (same ? 1 : s->ncomp); ++c) {
        const ef_fog_component *m = &s->comp[c];
        double C[3];
        ef_sky_light_eval(s->sky_light, m->phase, m->g, up, r->dir, C);
        for (int k = 0; k < 3; ++k) {
            const double a = m->has_albedo ? m->albedo[k] : 1.0, e = 1.0 - T[k];
            double share = e;
            if (!same)   /* by optical depth; among the opaque ones where it is infinite */
                share = isinf(tot[k]) ? (isinf(tau[c][k]) ? e : 0.0)
                        : tot[k] > 0  ? e * tau[c][k] / tot[k] : 0.0;
            out[k] += a * C[k] * share;
        }
    }
    if (!same)
        for (int k = 0; k < 3; ++k) {
            int ninf = 0;
            for (int c = 0; c < s->ncomp; ++c)
                ninf += isinf(tau[c][k]);
            if (ninf > 1)
                out[k] /= ninf;
        }
}

/* The sky light over the pixel's coverage: a S along the surface segment
 * (transmittance surf->T) plus (1 - a) S along the far one (inf->T). */
static void add_sky(const ef_fog_scene *s, const ef_ray *r, const ef_fog_sample *surf,
                    const ef_fog_sample *inf, double a, int need_inf, double c[3],
                    const ef_aov_out *aov, size_t i, double lerr[3])
{
    double S[3], Sf[3] = { 0, 0, 0 }, E[3] = { 0, 0, 0 }, Ef[3] = { 0, 0, 0 };
    ef_ray far;
    sky_segment(s, r, surf->T, S, E);
    if (need_inf && a < 1.0) {
        if (ef_scene_far_ray(s, r, &far))
            far = *r;
        sky_segment(s, &far, inf->T, Sf, Ef);
    }
    for (int k = 0; k < 3; ++k) {
        lerr[k] += coverage_sum(a, need_inf, E[k], Ef[k]);
        const double v = coverage_sum(a, need_inf, S[k], Sf[k]);
        c[k] += v;
        if (aov && aov->sky[k])
            aov->sky[k][i] = to_float(v);
    }
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

/* The common case, a span at a time with no per-pixel dispatch: no AOV,
 * no error info, one scene colour. Rays as ef_reconstruct_span builds them,
 * every component's tau added over the span (ef_fog_tau_add), T = e^-tau,
 * and compositing in branch-free loops over arrays that the compiler
 * vectorises. The same operations in the same order as ef_scene_eval_rays,
 * ef_scene_far_ray and ef_composite per pixel: the same bits. */
typedef struct fast_span {
    ef_ray r[EF_RECON_SPAN];
    ef_ray q[EF_RECON_SPAN];             /* far segments that differ from r[j] */
    double acc[EF_RECON_SPAN][3];        /* tau along r[j], then along q[m] */
    double planar[EF_RECON_SPAN], dist[EF_RECON_SPAN];   /* the distance path's rays */
    double tau[3][EF_RECON_SPAN];
    double T[3][EF_RECON_SPAN], Ti[3][EF_RECON_SPAN];
    int qj[EF_RECON_SPAN];               /* pixel of q[m] */
    unsigned char sky[EF_RECON_SPAN];
    unsigned char need_inf[EF_RECON_SPAN];
    /* a light's (fast_block with lit): along r[j], along q[m], along the
     * far segments; the surface rays' tau; and what each pixel adds over
     * its coverage (the lights' or the sky's) */
    double S[3][EF_RECON_SPAN], Sq[3][EF_RECON_SPAN], Sf[3][EF_RECON_SPAN];
    double taur[3][EF_RECON_SPAN], add[3][EF_RECON_SPAN];
    double a[EF_RECON_SPAN];             /* alpha as fogged, and whether the far */
    unsigned char shows[EF_RECON_SPAN];  /* part shows (lit spans only) */
} fast_span;

/* Sums the components' taus along r[0..n) into acc (from 0, in component
 * order as sum_tau does). */
static void fast_tau(const ef_fog_scene *s, const ef_ray *r, int n, double (*acc)[3])
{
    for (int j = 0; j < n; ++j)
        acc[j][0] = acc[j][1] = acc[j][2] = 0.0;
    for (int i = 0; i < s->ncomp; ++i)
        ef_fog_tau_add(&s->comp[i], r, n, acc);
}

/* transmit() of scene.c into the planes T[k][j] from tau planes: ef_exp_neg
 * is a function of tau alone, so computing every channel and selecting
 * gives its bits, in loops the compiler vectorises. A grey span (returns 0)
 * has T[0] only, copied to the others when copy_grey. */
EF_MULTIVERSION static int fast_transmit(double (*tau)[EF_RECON_SPAN], int n,
                                         double (*T)[EF_RECON_SPAN], int copy_grey)
{
    int colour = 0;
    for (int j = 0; j < n; ++j)
        colour |= (tau[1][j] != tau[0][j]) | (tau[2][j] != tau[0][j]);
    for (int j = 0; j < n; ++j)
        T[0][j] = ef_exp_neg(tau[0][j]);
    if (!colour) {
        if (copy_grey) {
            memcpy(T[1], T[0], (size_t) n * sizeof T[0][0]);
            memcpy(T[2], T[0], (size_t) n * sizeof T[0][0]);
        }
        return 0;
    }
    for (int j = 0; j < n; ++j) {
        T[1][j] = ef_exp_neg(tau[1][j]);
        T[2][j] = ef_exp_neg(tau[2][j]);
    }
    return 1;
}

/* fast_tau's sums as planes, and their transmittance (fast_transmit: 0 for
 * a grey span, whose T[0] alone is set unless copy_grey). */
static int fast_tau_transmit(const ef_fog_scene *s, const ef_ray *r, int n, fast_span *sp,
                             double (*T)[EF_RECON_SPAN], int copy_grey)
{
    fast_tau(s, r, n, sp->acc);
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < n; ++j)
            sp->tau[k][j] = sp->acc[j][k];
    return fast_transmit(sp->tau, n, T, copy_grey);
}

/* The distance path's tau: every component's tau_dist over the planes, in
 * component order from 0, as sum_tau adds them (the first writes, so the
 * planes need no clearing). */
static void dist_tau(const ef_fog_scene *s, const double *planar, const double *dist, int n,
                     double (*tau)[EF_RECON_SPAN])
{
    double *const t[3] = { tau[0], tau[1], tau[2] };
    if (s->ncomp == 0)
        for (int k = 0; k < 3; ++k)
            memset(tau[k], 0, (size_t) n * sizeof tau[k][0]);
    for (int i = 0; i < s->ncomp; ++i)
        s->comp[i].model->tau_dist(&s->comp[i], planar, dist, n, i == 0, t);
}

/* to_float without branches: under IEC 60559 (Annex F) a double at least
 * half an ulp beyond FLT_MAX converts to an infinity, and one just above
 * FLT_MAX would round down to it, so |v| > FLT_MAX is doubled first. The
 * same value as to_float for every v (NaN included); the factor is a select
 * of constants, so the loops vectorise without narrowing masks to floats. */
#if !defined(__STDC_IEC_559__) && !defined(__GCC_IEC_559)
#error "to_float_sel needs IEC 60559 floating point (C11 Annex F)"
#endif
static inline float to_float_sel(double v)
{
    const double k = fabs(v) > FLT_MAX ? 2.0 : 1.0;
    return (float) (v * k);
}

/* Whether the scene takes the distance path: every component reads the
 * distances alone (tau_dist), and the background is not a shell at a
 * distance (whose far segments differ per pixel). Then the far segment of
 * every pixel is the ray to infinity, one value per frame, and no ray is
 * built. Also whether a component needs the true distance (not only the
 * planar one). */
static int dist_path(const ef_fog_scene *s, int *need_dist)
{
    *need_dist = 0;
    if (s->sky == EF_SKY_DISTANCE_MODE)
        return 0;
    for (int c = 0; c < s->ncomp; ++c) {
        if (!s->comp[c].model->tau_dist)
            return 0;
        *need_dist |= s->comp[c].distance != EF_DIST_PLANAR;
    }
    return 1;
}

/* One channel of a pixel: ef_composite's value, or the input where the
 * pixel is kept. omTi = 1 - Ti, the far segment's. */
static inline float span_channel(double c, double t, double a, double omTi, double f, int keep,
                                 int keep_sky, int lit, double add)
{
    const double tc = t * c;   /* unconditional: the select vectorises */
    double v = (t > 0.0 ? tc : 0.0) + (1.0 - t) * a * f;
    if (!keep_sky)
        v = v + (1.0 - a) * omTi * f;
    if (lit)   /* the light after the composite, as add_lights adds it */
        v = v + add;
    return to_float_sel(keep ? c : v);
}

/* span_composite's loop for constant flags, so that each instance is one
 * branch-free loop the compiler vectorises. With const_ti, the far
 * segment's T is the same for every pixel (omTi and cover given), else
 * Ti[k][j] per pixel. */
static inline void span_composite_loop(const double *restrict T0, const double *restrict T1,
                                       const double *restrict T2, const double *restrict Ti0,
                                       const double *restrict Ti1, const double *restrict Ti2,
                                       const double omTi[3], double cover_c, const double F[3],
                                       int n, float *restrict pr, float *restrict pg,
                                       float *restrict pb, float *restrict pa,
                                       const unsigned char *restrict sky, int has_alpha,
                                       int keep_sky, int const_ti, const double *restrict A0,
                                       const double *restrict A1, const double *restrict A2,
                                       int lit)
{
    const double f0 = F[0], f1 = F[1], f2 = F[2];
    for (int j = 0; j < n; ++j) {
        const double ain = has_alpha ? pa[j] : 1.0;
        const int bad = !isfinite(ain);
        const double a = bad ? 1.0 : ain;
        const int keep = keep_sky && sky[j];
        const double o0 = const_ti ? omTi[0] : 1.0 - Ti0[j];
        const double o1 = const_ti ? omTi[1] : 1.0 - Ti1[j];
        const double o2 = const_ti ? omTi[2] : 1.0 - Ti2[j];
        pr[j] = span_channel(pr[j], T0[j], a, o0, f0, keep, keep_sky, lit, lit ? A0[j] : 0.0);
        pg[j] = span_channel(pg[j], T1[j], a, o1, f1, keep, keep_sky, lit, lit ? A1[j] : 0.0);
        pb[j] = span_channel(pb[j], T2[j], a, o2, f2, keep, keep_sky, lit, lit ? A2[j] : 0.0);
        if (has_alpha) {
            const double cover =
                const_ti ? cover_c : (3.0 - Ti0[j] - Ti1[j] - Ti2[j]) / 3.0;
            const double av = keep_sky ? a : a + (1.0 - a) * cover;
            pa[j] = to_float_sel(keep || bad ? ain : av);
        }
    }
}

/* Composites one span in place, from the floats to the floats: ef_composite
 * per pixel (T[k] to the surface, the far segment's Ti[k] or, when Ti is
 * NULL, one far T per frame given as omTi = 1 - Ti and the alpha's cover),
 * plus add[k][j] where add is given (a sun's or the sky light's term, as
 * add_lights or add_sky adds it), then
 * pixels kept (sky with --sky keep) and damaged alphas written back as
 * they were. The same operations in the same order: the same bits. */
EF_MULTIVERSION static void span_composite(const double *const T[3], const double *const Ti[3],
                                           const double omTi[3], double cover, const double F[3],
                                           int n, float *pr, float *pg, float *pb, float *pa,
                                           const unsigned char *sky, int keep_sky,
                                           double (*add)[EF_RECON_SPAN])
{
#define SPAN_COMPOSITE(has_alpha, keep, const_ti, lit)                                       \
    span_composite_loop(T[0], T[1], T[2], Ti ? Ti[0] : NULL, Ti ? Ti[1] : NULL,             \
                        Ti ? Ti[2] : NULL, omTi, cover, F, n, pr, pg, pb, pa, sky, has_alpha, \
                        keep, const_ti, add ? add[0] : NULL, add ? add[1] : NULL,            \
                        add ? add[2] : NULL, lit)
#define SPAN_LIT(has_alpha, keep)                                                            \
    (add ? (ct ? SPAN_COMPOSITE(has_alpha, keep, 1, 1) : SPAN_COMPOSITE(has_alpha, keep, 0, 1)) \
         : (ct ? SPAN_COMPOSITE(has_alpha, keep, 1, 0) : SPAN_COMPOSITE(has_alpha, keep, 0, 0)))
    const int ct = Ti == NULL;
    if (pa && keep_sky)
        SPAN_LIT(1, 1);
    else if (pa)
        SPAN_LIT(1, 0);
    else if (keep_sky)
        SPAN_LIT(0, 1);
    else
        SPAN_LIT(0, 0);
#undef SPAN_LIT
#undef SPAN_COMPOSITE
}

/* Light l along r[0..n) into S[k][j]: a sun in one height fog from the
 * optical depths tau[k][j] the span computed (ef_light_sun_span_eval),
 * any other light by ef_light_rays; either is ef_light_inscatter's S, the
 * same bits. */
static void light_rays(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, int n,
                       double (*tau)[EF_RECON_SPAN], double (*S)[EF_RECON_SPAN])
{
    if (!ef_light_sun_span(s, l)) {
        double *const Sk[3] = { S[0], S[1], S[2] };
        ef_light_rays(s, l, r, n, Sk, NULL);
        return;
    }
    for (int j = 0; j < n; ++j) {
        const double tv[3] = { tau[0][j], tau[1][j], tau[2][j] };
        double v[3];
        ef_light_sun_span_eval(s, l, &r[j], tv, v);
        for (int k = 0; k < 3; ++k)
            S[k][j] = v[k];
    }
}

/* The span path of the unlit scenes, of lights without the sky light
 * (lit: light_rays per light, a sun in one height fog from the span's
 * optical depths) and of the sky light without lights (sky):
 * reconstruction, the components' optical depths, T, the light (or
 * sky_segment from T), and
 * span_composite, with add_lights', add_sky's and ef_composite's
 * operations in their order: the per-pixel path's bits. */
EF_MULTIVERSION static void fast_block(const ef_fog_pass *pass, int x0, int y0, int w, int h,
                                       float *const rgb[3], float *alpha, const float *depth,
                                       int depth_only, int lit, int sky,
                                       fast_span *sp)
{
    const ef_fog_scene *s = pass->scene;
    const int fog_uncovered = s->sky != EF_SKY_KEEP, keep_sky = s->sky == EF_SKY_KEEP;
    for (int yy = 0; yy < h; ++yy) {
        const int y = y0 + yy;
        for (int xs = 0; xs < w; xs += EF_RECON_SPAN) {
            const int n = w - xs < EF_RECON_SPAN ? w - xs : EF_RECON_SPAN;
            const size_t i0 = (size_t) yy * (size_t) w + (size_t) xs;
            float *const pr = rgb[0] + i0, *const pg = rgb[1] + i0, *const pb = rgb[2] + i0;
            float *const pa = alpha ? alpha + i0 : NULL;
            ef_reconstruct_span(pass->cam, pass->conv, x0 + xs, y, n, depth + i0, !depth_only,
                                sp->r, sp->sky);
            if (s->sky == EF_SKY_DISTANCE_MODE)
                for (int j = 0; j < n; ++j)
                    if (sp->sky[j])
                        ef_ray_at_distance(pass->cam, x0 + xs + j, y, s->sky_distance, &sp->r[j]);
            /* The far segment is needed where the pixel is not opaque (a
             * NaN or infinite alpha is fogged as opaque) or its ray is
             * infinite, and it is looked for only where it may be another
             * segment than the pixel's own: a ray to infinity both ways is
             * its own far segment (ef_scene_far_ray, whatever the sky). */
            int ninf = 0;
            if (fog_uncovered)
                for (int j = 0; j < n; ++j) {
                    const double a = pa ? pa[j] : 1.0, d = sp->r[j].dist, p = sp->r[j].planar;
                    const int need = !(((a == 1.0) | !isfinite(a)) & isfinite(d)) &
                                     !((d == INFINITY) & (p == INFINITY));
                    sp->need_inf[j] = (unsigned char) need;
                    ninf += need;
                }
            const int colour = fast_tau_transmit(s, sp->r, n, sp, sp->T, 0);
            const double *const T[3] = { sp->T[0], sp->T[colour], sp->T[2 * colour] };
            const double *Ti[3] = { T[0], T[1], T[2] };
            /* the surface rays' depths, for a sun's closed form: tau, or a
             * copy where the far segments' depths overwrite it */
            double (*taur)[EF_RECON_SPAN] = sp->tau;
            int nq = 0;
            for (int j = 0; ninf && j < n; ++j) {
                if (!sp->need_inf[j])
                    continue;
                ef_ray *far = &sp->q[nq];
                if (ef_scene_far_ray(s, &sp->r[j], far) && far->planar == sp->r[j].planar)
                    continue;
                sp->qj[nq++] = j;
            }
            if (nq) {
                if (lit) {
                    for (int k = 0; k < 3; ++k)
                        memcpy(sp->taur[k], sp->tau[k], (size_t) n * sizeof sp->taur[k][0]);
                    taur = sp->taur;
                }
                /* Ti: T, then the far segments' T where they differ. */
                double Tq[3][EF_RECON_SPAN];
                fast_tau_transmit(s, sp->q, nq, sp, Tq, 1);
                for (int k = 0; k < 3; ++k) {
                    memcpy(sp->Ti[k], T[k], (size_t) n * sizeof sp->Ti[k][0]);
                    for (int m = 0; m < nq; ++m)
                        sp->Ti[k][sp->qj[m]] = Tq[k][m];
                    Ti[k] = sp->Ti[k];
                }
            }
            /* the pixel's alpha as fogged (1 where damaged) and whether its
             * far part shows: add_lights' and add_sky's a and need_inf */
            for (int j = 0; (lit || sky) && j < n; ++j) {
                const double ain = pa ? pa[j] : 1.0;
                sp->a[j] = isfinite(ain) ? ain : 1.0;
                sp->shows[j] = (unsigned char) (fog_uncovered &&
                                                !(sp->a[j] == 1.0 && isfinite(sp->r[j].dist)));
            }
            if (lit) {
                /* add_lights: per light in the scene's order, from 0, a S +
                 * (1 - a) S_far, S_far being S where the far segment is
                 * the pixel's own, which covers every pixel whose far part
                 * shows but was not gathered above (a ray infinite both
                 * ways) */
                for (int k = 0; k < 3; ++k)
                    for (int j = 0; j < n; ++j)
                        sp->add[k][j] = 0.0;
                for (int l = 0; l < s->nlight; ++l) {
                    light_rays(s, &s->light[l], sp->r, n, taur, sp->S);
                    double (*Sf)[EF_RECON_SPAN] = sp->S;
                    if (nq) {
                        Sf = sp->Sf;
                        for (int k = 0; k < 3; ++k)
                            memcpy(Sf[k], sp->S[k], (size_t) n * sizeof Sf[k][0]);
                        light_rays(s, &s->light[l], sp->q, nq, sp->tau, sp->Sq);
                        for (int m = 0; m < nq; ++m)
                            for (int k = 0; k < 3; ++k)
                                Sf[k][sp->qj[m]] = sp->Sq[k][m];
                    }
                    for (int k = 0; k < 3; ++k)
                        span_coverage(n, sp->a, sp->shows, sp->S[k], Sf[k], sp->add[k]);
                }
            } else if (sky) {
                /* add_sky: sky_segment along the surface segment with its T,
                 * and where the far part shows along the far one with Ti */
                for (int j = 0; j < n; ++j) {
                    const double a = sp->a[j];
                    const int shows = sp->shows[j];
                    const double Tj[3] = { T[0][j], T[1][j], T[2][j] };
                    double S[3], Sf[3] = { 0, 0, 0 };
                    sky_segment(s, &sp->r[j], Tj, S, NULL);
                    if (shows && a < 1.0) {
                        ef_ray far;
                        if (ef_scene_far_ray(s, &sp->r[j], &far))
                            far = sp->r[j];
                        const double Tf[3] = { Ti[0][j], Ti[1][j], Ti[2][j] };
                        sky_segment(s, &far, Tf, Sf, NULL);
                    }
                    for (int k = 0; k < 3; ++k)
                        sp->add[k][j] = coverage_sum(a, shows, S[k], Sf[k]);
                }
            }
            /* Pixels kept as they are (--sky keep) were evaluated too, and
             * are not written back. */
            span_composite(T, Ti, NULL, 0.0, s->color, n, pr, pg, pb, pa, sp->sky, keep_sky,
                           lit || sky ? sp->add : NULL);
        }
    }
}

/* The distance path (dist_path): per span the distances
 * (ef_reconstruct_dist), the tau planes, T, and span_composite. Where a
 * pixel's far segment is another than its own ray, it is the ray to
 * infinity (ef_scene_far_ray), of one T per frame, Tinf. Where it is not,
 * either the ray is that ray, or the pixel's alpha is 1 and its term
 * (1 - a)(1 - Ti) f is +-0 whatever Ti in [0, 1]: Tinf for every pixel
 * gives fast_block's bits. */
EF_MULTIVERSION static void dist_block(const ef_fog_pass *pass, int x0, int y0, int w, int h,
                                       float *const rgb[3], float *alpha, const float *depth,
                                       int need_dist, fast_span *sp)
{
    const ef_fog_scene *s = pass->scene;
    const int keep_sky = s->sky == EF_SKY_KEEP;
    const double inf = INFINITY;
    double Ti[3], omTi[3];
    dist_tau(s, &inf, &inf, 1, sp->tau);
    for (int k = 0; k < 3; ++k) {
        Ti[k] = ef_exp_neg(sp->tau[k][0]);
        omTi[k] = 1.0 - Ti[k];
    }
    const double cover = (3.0 - Ti[0] - Ti[1] - Ti[2]) / 3.0;
    for (int yy = 0; yy < h; ++yy) {
        const int y = y0 + yy;
        for (int xs = 0; xs < w; xs += EF_RECON_SPAN) {
            const int n = w - xs < EF_RECON_SPAN ? w - xs : EF_RECON_SPAN;
            const size_t i0 = (size_t) yy * (size_t) w + (size_t) xs;
            ef_reconstruct_dist(pass->cam, pass->conv, x0 + xs, y, n, depth + i0, need_dist,
                                sp->planar, sp->dist, sp->sky);
            dist_tau(s, sp->planar, sp->dist, n, sp->tau);
            const int colour = fast_transmit(sp->tau, n, sp->T, 0);
            const double *const T[3] = { sp->T[0], sp->T[colour], sp->T[2 * colour] };
            span_composite(T, NULL, omTi, cover, s->color, n, rgb[0] + i0, rgb[1] + i0,
                           rgb[2] + i0, alpha ? alpha + i0 : NULL, sp->sky, keep_sky, NULL);
        }
    }
}

void ef_fog_block_aov(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                      float *alpha, const float *depth, const ef_aov_out *aov,
                      ef_tau_stats *stats)
{
    const ef_fog_scene *s = pass->scene;
    const unsigned mask = aov ? aov->mask : 0;
    /* Only the numerical components have info to give. */
    int any_info = 0, depth_only = 1;
    for (int c = 0; c < s->ncomp; ++c) {
        any_info |= s->comp[c].model->tau_info != NULL;
        depth_only &= s->comp[c].model->depth_only;
    }
    const int want_info = any_info && (stats || (mask & EF_AOV_ERROR));
    /* lights without the sky light: light_rays in the span path too */
    const int lit = s->nlight > 0 && !s->sky_light;
    /* the sky light without lights: its term from T alone, in the span too */
    const int sky_only = s->nlight == 0 && s->sky_light != NULL;
    if (!mask && !s->any_color && !want_info && (!ef_scene_lit(s) || lit || sky_only)) {
        fast_span sp;
        int need_dist;
        if (!lit && !sky_only && dist_path(s, &need_dist))
            dist_block(pass, x0, y0, w, h, rgb, alpha, depth, need_dist, &sp);
        else
            fast_block(pass, x0, y0, w, h, rgb, alpha, depth, depth_only && !lit && !sky_only,
                       lit, sky_only, &sp);
        return;
    }
    const int fog_uncovered = s->sky != EF_SKY_KEEP;
    static const double zero3[3] = { 0, 0, 0 };
    const double *origin = aov ? aov->origin : zero3;
    /* Without info, every segment of a span is evaluated in one batch. */
    const int batch = !want_info;
    const int need_dir = !depth_only || (mask & EF_AOV_P) || ef_scene_lit(s);
    ef_tau_info info[EF_FOG_MAX_COMPONENTS];
    /* --stats with the caller's clocks: each pixel's fog time, ns (-1: none) */
    double wall[EF_RECON_SPAN];
    double (*const clk)(void) = stats && !batch ? stats[0].clock_ns : NULL;
    double (*const cpu)(void) = clk ? stats[0].cpu_ns : NULL;
    span *sp = &(span) { .nq = 0 };
    /* the lights along each span at once (ef_light_rays: lamps on
     * vectors); without the memory, pixel by pixel, the same bits */
    light_cache *lc = s->nlight ? malloc((size_t) s->nlight * sizeof *lc) : NULL;
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
            if (lc) {
                unsigned char skip[EF_RECON_SPAN];
                for (int j = 0; j < n; ++j)
                    skip[j] = sp->sky[j] && s->sky == EF_SKY_KEEP;
                light_cache_fill(s, sp->r, n, sp->need_inf, skip, (mask & EF_AOV_ERROR) != 0, lc);
            }
            const double cpu0 = cpu ? cpu() : 0;
            for (int j = 0; j < n; ++j)
                wall[j] = -1;
            for (int j = 0; j < n; ++j) {
                const size_t i = i0 + (size_t) j;
                if (sp->sky[j] && s->sky == EF_SKY_KEEP) {
                    for (int k = 0; k < 4 && (mask & EF_AOV_FOG); ++k)
                        aov->fog[k][i] = 0.0f;
                    for (int k = 0; k < 3 && (mask & EF_AOV_T); ++k)
                        aov->T[k][i] = 1.0f;
                    for (int k = 0; k < 3 && (mask & EF_AOV_ERROR); ++k)
                        aov->err[k][i] = 0.0f;
                    for (int k = 0; k < 3 && (mask & EF_AOV_LIGHT); ++k) {
                        aov->ambient[k][i] = 0.0f;
                        for (int l = 0; l < s->nlight; ++l)
                            aov->light[l][k][i] = 0.0f;
                        if (aov->sky[k])
                            aov->sky[k][i] = 0.0f;
                    }
                    for (int l = 0; l < s->nlight && (mask & EF_AOV_LIT); ++l)
                        if (aov->lit[l])
                            aov->lit[l][i] = 1.0f;   /* no fog, nothing shadowed */
                    continue;
                }
                ef_fog_sample one, other;
                const ef_fog_sample *surf = &sp->surf[j], *inf = sp->inf[j];
                if (!batch) {
                    const double c0 = clk ? clk() : 0;
                    ef_scene_eval_info(s, &sp->r[j], &one, sp->need_inf[j] ? &other : NULL,
                                       want_info ? info : NULL);
                    if (clk)
                        wall[j] = clk() - c0;
                    surf = &one;
                    inf = sp->need_inf[j] ? &other : &one;
                }
                double c[3], in[3], a = sp->a[j];
                const double a_in = a;
                for (int k = 0; k < 3; ++k)
                    in[k] = c[k] = rgb[k][i];
                ef_composite(surf, inf, fog_uncovered, c, alpha ? &a : NULL);
                if (mask & EF_AOV_LIGHT)
                    for (int k = 0; k < 3; ++k)
                        aov->ambient[k][i] =
                            to_float(c[k] - (surf->T[k] > 0.0 ? surf->T[k] * in[k] : 0.0));
                double lerr[3] = { 0, 0, 0 };
                if (s->nlight)
                    add_lights(s, &sp->r[j], a_in, sp->need_inf[j], c, aov, i, lerr, lc, j);
                if (s->sky_light)
                    add_sky(s, &sp->r[j], surf, inf, a_in, sp->need_inf[j], c, aov, i, lerr);
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
                    /* the lights' in-scatter estimates add in the image's
                     * units: the composite moves by |dT| |surface - fog|
                     * plus them */
                    for (int k = 0; k < 3; ++k)
                        aov->err[k][i] = to_float(aov_err(surf->T[k], e[k]) + lerr[k]);
                }
                if (stats && want_info)
                    for (int nn = 0; nn < s->ncomp; ++nn)
                        if (s->comp[nn].model->tau_info)
                            ef_tau_stats_add(&stats[nn], &info[nn], surf->T);
            }
            if (clk) {
                /* no pixel of the span took more CPU than the whole span */
                const double span_cpu = cpu ? cpu() - cpu0 : INFINITY;
                double sum = 0;
                for (int j = 0; j < n; ++j)
                    sum += wall[j] >= 0 ? wall[j] : 0;
                /* descheduled: the pixels' wall times exceed the span's CPU
                 * time (by more than the clock reads' own cost) */
                const int clean = cpu && sum <= span_cpu + 10000;
                int slow = -1;
                for (int j = 0; j < n; ++j)
                    if (wall[j] >= 0) {
                        ef_tau_stats_time(&stats[0], wall[j] < span_cpu ? wall[j] : span_cpu, clean);
                        if (slow < 0 || wall[j] > wall[slow])
                            slow = j;
                    }
                /* The costliest pixel, measured apart from the machine's
                 * noise: where the span's slowest pixel beats the largest
                 * re-timed cost so far, it is evaluated twice more and the
                 * least of its three times counts (an interrupt or a
                 * descheduling rarely hits the same pixel three times). */
                if (slow >= 0 && wall[slow] > stats[0].time_max_retimed) {
                    double best = wall[slow];
                    for (int rep = 0; rep < 2; ++rep) {
                        ef_fog_sample one, other;
                        const double c0 = clk();
                        ef_scene_eval_info(s, &sp->r[slow], &one,
                                           sp->need_inf[slow] ? &other : NULL,
                                           want_info ? info : NULL);
                        const double d = clk() - c0;
                        if (d < best)
                            best = d;
                    }
                    ef_tau_stats_retimed(&stats[0], best);
                }
            }
        }
    }
    free(lc);
}

void ef_fog_block(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                  float *alpha, const float *depth)
{
    ef_fog_block_aov(pass, x0, y0, w, h, rgb, alpha, depth, NULL, NULL);
}
