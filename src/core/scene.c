#include "scene.h"
#include "camera.h"
#include "shadow.h"
#include "ms.h"
#include "sky_light.h"

#include "expneg.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void ef_scene_init(ef_fog_scene *s)
{
    memset(s, 0, sizeof *s);
    s->color[0] = EF_DEFAULT_FOG_COLOR_R;
    s->color[1] = EF_DEFAULT_FOG_COLOR_G;
    s->color[2] = EF_DEFAULT_FOG_COLOR_B;
    s->sky = EF_SKY_FOG;
    s->sky_distance = INFINITY;
    ef_fog_context_init(&s->ctx);
}

int ef_scene_parse_sky(ef_fog_scene *s, const char *text, ef_err *err)
{
    if (!strcmp(text, "fog")) {
        s->sky = EF_SKY_FOG;
        return 0;
    }
    if (!strcmp(text, "keep")) {
        s->sky = EF_SKY_KEEP;
        return 0;
    }
    if (!strncmp(text, "distance=", 9)) {
        double d;
        if (ef_parse_numbers(text + 9, &d, 1) || !(d > 0))
            return ef_fail(err, "--sky '%s': the distance must be a positive number", text);
        s->sky = EF_SKY_DISTANCE_MODE;
        s->sky_distance = d;
        return 0;
    }
    return ef_fail(err, "--sky '%s' is not fog, keep or distance=D", text);
}

int ef_scene_add(ef_fog_scene *s, const char *spec, ef_err *err)
{
    if (s->ncomp >= EF_FOG_MAX_COMPONENTS)
        return ef_fail(err, "too many fog components (at most %d)", EF_FOG_MAX_COMPONENTS);
    ef_fog_component *c = &s->comp[s->ncomp];
    if (ef_fog_parse(spec, &s->ctx, c, err))
        return -1;
    s->any_color |= c->has_color;
    s->ncomp++;
    return 0;
}

static int ef_scene_name_light(ef_fog_scene *s, ef_light *l, const char *spec, ef_err *err);

int ef_scene_add_light(ef_fog_scene *s, const char *spec, ef_err *err)
{
    if (s->nlight >= EF_MAX_LIGHTS)
        return ef_fail(err, "too many lights (at most %d)", EF_MAX_LIGHTS);
    ef_light *l = &s->light[s->nlight];
    if (ef_light_parse(spec, &s->ctx, l, err))
        return -1;
    if (ef_scene_name_light(s, l, spec, err)) {
        ef_shadow_unref(l->shadow);
        l->shadow = NULL;
        return -1;
    }
    s->nlight++;
    return 0;
}

/* Names l (the next light of s) and its AOV channels; fails when the name
 * is taken. */
static int ef_scene_name_light(ef_fog_scene *s, ef_light *l, const char *spec, ef_err *err)
{
    /* the default name counts the lights of its kind before it */
    int nth = 0;
    for (int i = 0; i < s->nlight; ++i)
        nth += s->light[i].kind == l->kind;
    if (l->name[0] == '\0') {
        snprintf(l->name, sizeof l->name, "%s%d", ef_light_kind_name(l->kind), nth + 1);
    }
    /* from a copy: the name and the channel names share the scene object,
     * which GCC's restrict check cannot tell apart */
    char name[sizeof l->name];
    memcpy(name, l->name, sizeof name);
    for (int k = 0; k < 3; ++k)
        snprintf(l->aov[k], sizeof l->aov[k], "fog_light.%s.%c", name, "RGB"[k]);
    snprintf(l->lit_aov, sizeof l->lit_aov, "fog_lit.%s", name);
    if (!strcmp(l->name, "sky"))
        return ef_fail(err, "--light '%s': the name 'sky' is --sky-light's (its AOV layer is "
                       "fog_light.sky); give another name=", spec);
    for (int i = 0; i < s->nlight; ++i)
        if (!strcmp(s->light[i].name, l->name))
            return ef_fail(err, "--light '%s': the name '%s' is taken by '%s' (name=NAME "
                           "tells lights apart in the light AOVs)", spec, l->name,
                           s->light[i].spec);
    return 0;
}

void ef_scene_bind(ef_fog_scene *s, const double org[3])
{
    for (int i = 0; i < s->ncomp; ++i)
        ef_fog_bind(&s->comp[i], org);
    for (int j = 0; j < s->nlight; ++j) {
        ef_ms_bind(s->light[j].ms, s, org, &s->light[j].ms_view);
        /* out of memory: no table, every ray integrates (the same light) */
        (void) ef_lms_bind(s->light[j].lms, org, &s->light[j].lms_view);
    }
    ef_ms_bind(s->sky_ms, s, org, &s->sky_ms_view);
    for (int j = 0; j < s->nlight && s->ncomp == 1; ++j) {
        const double *up = s->comp[0].up;
        ef_light_bind(&s->light[j], &s->comp[0], up[0] * org[0] + up[1] * org[1] + up[2] * org[2]);
    }
}

void ef_scene_bind_camera(ef_fog_scene *s, const ef_camera *cam)
{
    const double spread = ef_camera_pixel_spread(cam);
    for (int i = 0; i < s->ncomp; ++i)
        s->comp[i].spread = spread;
    ef_scene_bind(s, cam->pos);
}

int ef_scene_copy(ef_fog_scene *dst, const ef_fog_scene *src, int with_spec)
{
    dst->ncomp = 0;
    dst->any_color = src->any_color;
    memcpy(dst->color, src->color, sizeof dst->color);
    dst->ctx = src->ctx;
    dst->sky = src->sky;
    dst->sky_distance = src->sky_distance;
    dst->nlight = src->nlight;
    memcpy(dst->light, src->light, (size_t) src->nlight * sizeof src->light[0]);
    for (int j = 0; j < dst->nlight; ++j) {
        ef_shadow_ref(dst->light[j].shadow);   /* immutable: shared */
        ef_ms_ref(dst->light[j].ms);
        ef_lms_ref(dst->light[j].lms);
        ef_lms_view_ref(dst->light[j].lms_view);
        ef_vms_cam_ref(dst->light[j].ms_view.cam);
    }
    dst->sky_light = src->sky_light;
    ef_sky_light_ref(dst->sky_light);
    dst->sky_multiple = src->sky_multiple;
    dst->sky_has_ground = src->sky_has_ground;
    dst->sky_ground = src->sky_ground;
    dst->sky_ms = src->sky_ms;
    ef_ms_ref(dst->sky_ms);
    dst->sky_ms_view = src->sky_ms_view;
    memcpy(dst->sky_light_spec, src->sky_light_spec, sizeof dst->sky_light_spec);
    for (int i = 0; i < src->ncomp; ++i) {
        ef_fog_component *d = &dst->comp[i];
        const ef_fog_component *c = &src->comp[i];
        int bad;
        if (with_spec) {
            bad = ef_fog_copy(d, c);
        } else {
            /* a copy only evaluated needs no SPEC text */
            *d = *c;
            d->spec = (char *) ef_spec_none;
            d->arr = NULL;
            d->path = NULL;
            d->narr = 0;
            bad = c->narr > 0 && !(d->arr = malloc((size_t) c->narr * sizeof *d->arr));
            if (!bad && c->narr > 0) {
                memcpy(d->arr, c->arr, (size_t) c->narr * sizeof *d->arr);
                d->narr = c->narr;
            }
        }
        if (bad) {
            ef_fog_free(d);
            ef_scene_free(dst);
            return -1;
        }
        dst->ncomp = i + 1;
    }
    return 0;
}

void ef_scene_set_cancel(ef_fog_scene *s, const _Atomic int *cancel)
{
    for (int i = 0; i < s->ncomp; ++i)
        s->comp[i].cancel = cancel;
}

void ef_scene_free(ef_fog_scene *s)
{
    for (int i = 0; i < s->ncomp; ++i)
        ef_fog_free(&s->comp[i]);
    for (int j = 0; j < s->nlight; ++j) {
        ef_shadow_unref(s->light[j].shadow);
        s->light[j].shadow = NULL;
        ef_ms_unref(s->light[j].ms);
        s->light[j].ms = NULL;
        ef_lms_unref(s->light[j].lms);
        s->light[j].lms = NULL;
        ef_lms_view_unref(s->light[j].lms_view);
        s->light[j].lms_view = NULL;
        ef_ms_view_clear(&s->light[j].ms_view);
    }
    ef_sky_light_unref(s->sky_light);
    s->sky_light = NULL;
    ef_ms_unref(s->sky_ms);
    s->sky_ms = NULL;
    s->ncomp = 0;
    s->nlight = 0;
    s->any_color = 0;
}

int ef_scene_set_sky_light(ef_fog_scene *s, const char *spec, ef_err *err)
{
    if (strlen(spec) >= sizeof s->sky_light_spec)
        return ef_fail(err, "--sky-light '%.40s...' is too long", spec);
    char buf[sizeof s->sky_light_spec];
    snprintf(buf, sizeof buf, "%s", spec);
    char *save = NULL, *path = strtok_r(buf, ":", &save);
    if (!path || !path[0])
        return ef_fail(err, "--sky-light '%s': no file (write --sky-light ENV.exr[:rotate=DEG]"
                       "[:intensity=K])", spec);
    double rotate = 0, intensity = 1, ground = 0;
    int multiple = 0;
    unsigned seen = 0;
    for (char *tok = strtok_r(NULL, ":", &save); tok; tok = strtok_r(NULL, ":", &save)) {
        char *eq = strchr(tok, '=');
        double *dst = NULL;
        unsigned bit = 0;
        if (eq) {
            *eq = '\0';
            if (!strcmp(tok, "rotate"))
                dst = &rotate, bit = 1;
            else if (!strcmp(tok, "intensity"))
                dst = &intensity, bit = 2;
            else if (!strcmp(tok, "ground"))
                dst = &ground, bit = 4;
            else if (!strcmp(tok, "scattering"))
                bit = 8;
        }
        if (!dst && bit != 8)
            return ef_fail(err, "--sky-light '%s': '%s' is not rotate=DEG, intensity=K, "
                           "scattering=single|multiple or ground=H", spec, tok);
        if (seen & bit)
            return ef_fail(err, "--sky-light '%s': key '%s' is given twice", spec, tok);
        seen |= bit;
        if (bit == 8) {
            if (strcmp(eq + 1, "single") && strcmp(eq + 1, "multiple"))
                return ef_fail(err, "--sky-light '%s': scattering='%s' is not single or "
                               "multiple", spec, eq + 1);
            multiple = eq[1] == 'm';
            continue;
        }
        if (ef_parse_numbers(eq + 1, dst, 1) || !isfinite(*dst) || (bit == 2 && !(*dst >= 0)))
            return ef_fail(err, "--sky-light '%s': %s='%s' is not %s", spec, tok, eq + 1,
                           bit == 1 ? "an angle in degrees" : bit == 2 ? "a number >= 0"
                                                                     : "a height (scene units)");
    }
    if ((seen & 4) && !multiple)
        return ef_fail(err, "--sky-light '%s': ground= is where multiple scattering stops: it "
                       "needs scattering=multiple", spec);
    /* a turn is a turn: in radians a rotate of 1e308 degrees overflows
     * and turned every pixel NaN (fmod is exact) */
    rotate = fmod(rotate, 360);
    if (!s->ctx.load_sky)
        return ef_fail(err, "--sky-light '%s': environments cannot be read here", spec);
    int phases[EF_FOG_MAX_COMPONENTS];
    double g[EF_FOG_MAX_COMPONENTS];
    int n = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        phases[n] = s->comp[i].phase;
        g[n++] = s->comp[i].g;
    }
    struct ef_sky_light *k = NULL;
    if (s->ctx.load_sky(path, rotate, intensity, phases, g, n, &k, err))
        return -1;
    ef_sky_light_unref(s->sky_light);
    s->sky_light = k;
    snprintf(s->sky_light_spec, sizeof s->sky_light_spec, "%s", spec);
    s->sky_multiple = multiple;
    s->sky_has_ground = (seen & 4) != 0;
    s->sky_ground = ground;
    ef_ms_unref(s->sky_ms);   /* ef_scene_prepare_lights solves it */
    s->sky_ms = NULL;
    return 0;
}

/* With an infinite optical depth, the light that reaches the camera comes
 * from the stretch of the ray before the fog turns opaque, so the colour is
 * the tau-weighted mean over [0, D] where the total tau first reaches 40
 * (T = 4e-18): found by growing D fourfold from one scene unit. For each
 * channel with ninf[k] set, wc[k] becomes that normalised mean. */
static void mix_where_opaque(const ef_fog_scene *s, const ef_ray *r, const int ninf[3],
                             double wc[3])
{
    ef_ray near = *r;
    double sum[3], w[3], wall[3];
    int walls[3];
    for (double D = 1.0;; D *= 4.0) {
        near.dist = D;
        near.planar = isfinite(r->planar) && r->dist > 0 ? r->planar * (D / r->dist) : D;
        for (int k = 0; k < 3; ++k) {
            sum[k] = w[k] = wall[k] = 0;
            walls[k] = 0;
        }
        for (int i = 0; i < s->ncomp; ++i) {
            const ef_fog_component *c = &s->comp[i];
            double t[3];
            c->model->tau(c, &near, t);
            for (int k = 0; k < 3; ++k) {
                const double col = c->has_color ? c->color[k] : s->color[k];
                if (isinf(t[k])) {   /* opaque within D (a wall): its colour alone */
                    walls[k]++;
                    wall[k] += col;
                } else if (t[k] > 0) {
                    sum[k] += t[k];
                    w[k] += t[k] * col;
                }
            }
        }
        int done = 1;
        for (int k = 0; k < 3; ++k)
            done &= !ninf[k] || walls[k] || sum[k] >= 40.0;
        if (done || D > 1e300)
            break;
    }
    for (int k = 0; k < 3; ++k)
        if (ninf[k])
            wc[k] = walls[k] ? wall[k] / walls[k] : sum[k] > 0 ? w[k] / sum[k] : s->color[k];
}

/* Sums the components' optical depths and, with per-component colours, the
 * tau-weighted colour; out->T holds tau until transmit() turns it into T. */
static void sum_tau(const ef_fog_scene *s, const ef_ray *r, ef_fog_sample *out,
                    ef_tau_info *info)
{
    double *acc = out->T, wc[3] = { 0, 0, 0 };
    int ninf[3] = { 0, 0, 0 };
    acc[0] = acc[1] = acc[2] = 0.0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double t[3];
        if (info)
            ef_fog_tau(c, r, t, &info[i]);
        else
            c->model->tau(c, r, t);
        for (int k = 0; k < 3; ++k) {
            acc[k] += t[k];
            if (!s->any_color)
                continue;
            const double col = c->has_color ? c->color[k] : s->color[k];
            if (isinf(t[k]))
                ninf[k]++;
            else if (t[k] > 0)
                wc[k] += t[k] * col;
        }
    }
    if (s->any_color && (ninf[0] || ninf[1] || ninf[2]))
        mix_where_opaque(s, r, ninf, wc);
    for (int k = 0; k < 3; ++k) {
        if (!s->any_color || acc[k] == 0.0)
            out->F[k] = s->color[k];
        else
            out->F[k] = wc[k] / (ninf[k] ? 1.0 : acc[k]);
    }
}

/* e^-tau per channel in place (ef_exp_neg, as apply.c's span-wise path
 * computes it); grey fog (equal taus) needs one, not three. */
static void transmit(double T[3])
{
    const double t0 = T[0], t1 = T[1], t2 = T[2];
    T[0] = ef_exp_neg(t0);
    T[1] = t1 == t0 ? T[0] : ef_exp_neg(t1);
    T[2] = t2 == t0 ? T[0] : t2 == t1 ? T[1] : ef_exp_neg(t2);
}

void ef_scene_eval(const ef_fog_scene *s, const ef_ray *r, ef_fog_sample *surf, ef_fog_sample *inf)
{
    ef_scene_eval_info(s, r, surf, inf, NULL);
}

int ef_scene_far_ray(const ef_fog_scene *s, const ef_ray *r, ef_ray *far)
{
    *far = *r;
    if (s->sky == EF_SKY_DISTANCE_MODE && isfinite(r->dist) && r->dist > 0) {
        /* The background is a shell at sky_distance: "infinity" ends there.
         * Both are finite and positive: fmax's value, without libm's call. */
        const double d = s->sky_distance >= r->dist ? s->sky_distance : r->dist;
        far->planar = r->planar * (d / r->dist);
        far->dist = d;
    } else {
        far->dist = far->planar = INFINITY;
    }
    return far->dist == r->dist;
}

void ef_scene_eval_rays(const ef_fog_scene *s, const ef_ray *r, int n, ef_fog_sample *out)
{
    if (s->any_color) {
        for (int j = 0; j < n; ++j) {
            sum_tau(s, &r[j], &out[j], NULL);
            transmit(out[j].T);
        }
        return;
    }
    /* Component-major, 128 rays at a time: one dispatch per component per
     * chunk; each ray's sum is still 0 + tau_0 + tau_1 + ... as in sum_tau. */
    for (int j0 = 0; j0 < n; j0 += 128) {
        const int m = n - j0 < 128 ? n - j0 : 128;
        double acc[128][3] = { { 0 } };
        for (int i = 0; i < s->ncomp; ++i)
            ef_fog_tau_add(&s->comp[i], r + j0, m, acc);
        for (int j = 0; j < m; ++j) {
            ef_fog_sample *o = &out[j0 + j];
            for (int k = 0; k < 3; ++k) {
                o->T[k] = acc[j][k];
                o->F[k] = s->color[k];
            }
            transmit(o->T);
        }
    }
}

void ef_scene_eval_info(const ef_fog_scene *s, const ef_ray *r, ef_fog_sample *surf,
                        ef_fog_sample *inf, ef_tau_info *info)
{
    if (!inf) {
        sum_tau(s, r, surf, info);
        transmit(surf->T);
        return;
    }
    ef_ray far;
    /* The surface segment's info: the far one when they are the same. */
    const int same = ef_scene_far_ray(s, r, &far);
    sum_tau(s, &far, inf, same ? info : NULL);
    transmit(inf->T);
    if (same) {
        *surf = *inf;
        return;
    }
    sum_tau(s, r, surf, info);
    transmit(surf->T);
}

int ef_scene_prepare_lights(ef_fog_scene *s, ef_err *err)
{
    for (int j = 0; j < s->nlight; ++j) {
        ef_light *l = &s->light[j];
        ef_ms_unref(l->ms);
        l->ms = NULL;
        ef_lms_unref(l->lms);
        l->lms = NULL;
        ef_lms_view_unref(l->lms_view);
        l->lms_view = NULL;
        ef_ms_view_clear(&l->ms_view);
        if (l->multiple && (ef_light_at_position(l) ? ef_lms_build(s, l, &l->lms, err)
                                                     : ef_ms_build(s, l, &l->ms, err)))
            return -1;
    }
    ef_ms_unref(s->sky_ms);
    s->sky_ms = NULL;
    if (s->sky_light && s->sky_multiple && ef_ms_build_sky(s, &s->sky_ms, err))
        return -1;
    return 0;
}
