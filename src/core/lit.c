/* Lit fog (lit.h): which method serves each light and segment (lit noise
 * fog, a sun's closed form, the quadrature with its lamp closed form), the
 * lights' checks, the sun's closed forms, where a light's in-scatter turns
 * (cuts), and the public entry points per ray and per span. lit_int.h
 * lists the family. */
#include "lit_int.h"
#include "ms.h"
#include "shadow.h"
#include "vmath.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

int ef_lights_check(const ef_fog_scene *s, ef_err *err)
{
    if (s->nlight == 0)
        return 0;
    double rho[3], k, base;
    const int one_height = s->ncomp == 1 && s->comp[0].model->strata &&
                           s->comp[0].model->strata(&s->comp[0], rho, &k, &base);
    for (int j = 0; j < s->nlight; ++j)
        if (s->light[j].planet > 0 && !one_height)
            return ef_fail(err, "--light '%s': planet= takes one exponential height fog "
                           "(height with falloff > 0: the fog a planet's atmosphere "
                           "stratifies)", s->light[j].spec);
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (is_uniform(c))
            continue;
        if (!c->model->functionals || !c->model->density)
            return ef_fail(err, "fog spec '%s': %s fog is a function of the distance from the "
                           "camera, with no density in space for light to cross (use exp, "
                           "height, the half-spaces, layered or the volumes with --light)",
                           c->spec, c->model->name);
    }
    return 0;
}

int ef_light_dark(const ef_fog_scene *s, const ef_light *l)
{
    if (ef_light_at_position(l) || l->planet > 0)
        return 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double sg[3];
        if (uniform_sigma(c, sg) && sg[0] > 0 && sg[1] > 0 && sg[2] > 0)
            return 1;
    }
    return 0;
}

/* ---- a lamp's geometry along a ray, and the uniform medium ---- */

/* sqrt(x^2 + y^2): hypot's care only where the squares could overflow
 * or underflow (hypot costs several times more). */
double ef_lit_len2(double x, double y)
{
    const double ax = fabs(x), ay = fabs(y), m = ax > ay ? ax : ay;   /* (NaN: NaN below) */
    if (m < 1e150 && m > 1e-150)
        return sqrt(x * x + y * y);
    return m == 0 ? 0 : hypot(x, y);
}

/* |(x, y, z)| with one square root where the largest magnitude lies
 * within 1e-150 .. 1e150 (its square then neither overflows nor loses
 * digits that matter), else by len2 twice. lamp_span computes the same
 * plain form on vectors. */
static double len3(double x, double y, double z)
{
    const double ax = fabs(x), ay = fabs(y), az = fabs(z), mxy = ax > ay ? ax : ay,
                 m = mxy > az ? mxy : az;
    if (m < 1e150 && m > 1e-150)
        return sqrt(x * x + y * y + z * z);
    return ef_lit_len2(ef_lit_len2(x, y), z);
}

/* Where lamp l comes closest to the line of r: its parameter *ts along
 * r->dir, and its distance *h from the line by the cross product (no
 * cancellation near the line); w gets lamp - origin. */
void ef_lit_lamp_line(const ef_light *l, const ef_ray *r, double w[3], double *ts, double *h)
{
    for (int k = 0; k < 3; ++k)
        w[k] = l->pos[k] - r->org[k];
    *ts = w[0] * r->dir[0] + w[1] * r->dir[1] + w[2] * r->dir[2];
    const double cx = w[1] * r->dir[2] - w[2] * r->dir[1],
                 cy = w[2] * r->dir[0] - w[0] * r->dir[2],
                 cz = w[0] * r->dir[1] - w[1] * r->dir[0];
    *h = len3(cx, cy, cz);
}

/* The uniform fog's extinction sig (its components' sum, in their order)
 * and isotropic scattering scat per channel, as inscatter_range gives
 * them to lamp_closed. */
void ef_lit_lamp_medium(const ef_fog_scene *s, double sig[3], double scat[3])
{
    for (int k = 0; k < 3; ++k)
        sig[k] = scat[k] = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        double sg[3];
        uniform_sigma(&s->comp[i], sg);   /* every component is uniform here */
        for (int k = 0; k < 3; ++k) {
            sig[k] += sg[k];
            if (sg[k] > 0)
                scat[k] += sg[k] * albedo(&s->comp[i], k) / (4 * PI);
        }
    }
}

/* Total optical depth per channel from p along unit d over len (may be
 * INFINITY), from the models' closed forms. */
void ef_lit_tau_from(const ef_fog_scene *s, const double p[3], const double d[3], double len,
                     double tau[3])
{
    ef_ray r = { { d[0], d[1], d[2] }, len, len, { p[0], p[1], p[2] } };
    tau[0] = tau[1] = tau[2] = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        double t[3];
        s->comp[i].model->tau(&s->comp[i], &r, t);
        for (int k = 0; k < 3; ++k)
            tau[k] += t[k];
    }
}

/* The sun's optical depth from x over a planet of radius l->planet (the
 * scene's one height fog stratified over a sphere whose surface lies at
 * height 0 below x, its centre on x's vertical): sigma(x) H Ch(X, mu), H =
 * 1/k, X = (R + height) / H, mu = l . up; +inf where the planet itself
 * stands between x and the sun (its tangent point below the surface). */
void ef_lit_sun_planet_tau(const ef_fog_scene *s, const ef_light *l, const double x[3],
                           double tau[3])
{
    const ef_fog_component *c = &s->comp[0];
    double rho[3], k, base;
    if (!c->model->strata || !c->model->strata(c, rho, &k, &base)) {
        tau[0] = tau[1] = tau[2] = INFINITY;   /* ef_lights_check refuses it */
        return;
    }
    const double R = l->planet;
    const double y = c->up[0] * x[0] + c->up[1] * x[1] + c->up[2] * x[2];
    const double mu = l->dir[0] * c->up[0] + l->dir[1] * c->up[1] + l->dir[2] * c->up[2];
    const double r0 = R + y;
    tau[0] = tau[1] = tau[2] = INFINITY;
    if (!(r0 > 0) || (mu < 0 && r0 * sqrt((1 - mu) * (1 + mu)) < R))
        return;
    const double ch = ef_light_planet_ch(l, k, mu, y);
    const double e = exp(-k * (y - base));
    for (int ch3 = 0; ch3 < 3; ++ch3)
        tau[ch3] = rho[ch3] == 0 ? 0 : rho[ch3] * e / k * ch;
}

/* ------------------------------------------------------- the closed forms */

/* Sun l as component c's closed form sees it along r (the sun hook, fog.h):
 * its direction, and per channel albedo p E in that order, p the phase at
 * the angle between the sun and r. */
static void sun_light(const ef_fog_component *c, const ef_light *l, const ef_ray *r,
                      ef_sun_light *sl)
{
    memcpy(sl->dir, l->dir, sizeof sl->dir);
    const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    const double p = ef_phase_eval(c->phase, c->g, cth);
    for (int ch = 0; ch < 3; ++ch) {
        sl->w[ch] = albedo(c, ch) * p * l->e[ch];
        sl->live[ch] = !(l->e[ch] == 0 || albedo(c, ch) == 0);
    }
}

/* Sun l through the scene's one component c in closed form along r (tv:
 * the view ray's optical depth, or NULL); 0 when c has none. */
static int sun_closed(const ef_fog_component *c, const ef_light *l, const ef_ray *r,
                      const double *tv, double S[3])
{
    if (!c->model->sun)
        return 0;
    ef_sun_light sl;
    sun_light(c, l, r, &sl);
    return c->model->sun(c, &sl, r, tv, S);
}

/* Adds sun or point lamp l's light scattered twice and more
 * (scattering=multiple) along r to S, and its error estimate to E (may be
 * NULL). */
static void add_multiple(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                         const double *tv, double S[3], double E[3])
{
    if (!l->ms && !l->lms)
        return;
    double Sm[3], Em[3];
    if (l->lms)
        ef_lms_gather_view(l->lms, l->lms_view, r, 0, r->dist, Sm, Em);
    else
        ef_ms_gather_view(l->ms, &l->ms_view, s, r, tv, Sm, Em);
    for (int k = 0; k < 3; ++k) {
        S[k] += Sm[k];
        if (E)
            E[k] += Em[k];
    }
}

int ef_light_sun_span(const ef_fog_scene *s, const ef_light *l)
{
    double rho[3], k, base;
    return !ef_light_at_position(l) && !l->shadow && !(l->planet > 0) && s->ncomp == 1 &&
           s->comp[0].model->sun && s->comp[0].model->strata &&
           s->comp[0].model->strata(&s->comp[0], rho, &k, &base);
}

void ef_light_sun_span_eval(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                            const double tv[3], double S[3])
{
    S[0] = S[1] = S[2] = 0;
    /* as ef_light_inscatter: no segment, no light */
    if (!(r->dist > 0) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return;
    sun_closed(&s->comp[0], l, r, tv, S);
    add_multiple(s, l, r, tv, S, NULL);
}

/* Sun l's closed form over [a, b] of r in the scene's one component: T(0,
 * a) times the closed form along the ray from x(a). Returns 0 (S
 * untouched) when the component has none. */
static int closed_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                        double b, double S[3])
{
    const ef_fog_component *c = &s->comp[0];
    if (a == 0 && b == r->dist)
        return sun_closed(c, l, r, NULL, S);
    ef_ray sub = *r;
    for (int k = 0; k < 3; ++k)
        sub.org[k] = r->org[k] + a * r->dir[k];
    sub.dist = sub.planar = b - a;
    double tv[3];
    ef_lit_tau_from(s, r->org, r->dir, a, tv);
    if (!sun_closed(c, l, &sub, NULL, S))
        return 0;
    for (int k = 0; k < 3; ++k)
        S[k] = S[k] == 0 ? 0 : S[k] * exp(-tv[k]);
    return 1;
}

/* Adds to S the light l scatters in over [a, b] of r (0 <= a < b, b may
 * be INFINITY), T(0, t) counted from the camera, and its error estimate
 * to E: the method that serves the segment (lit noise fog, a sun's closed
 * form, else the quadrature with its point-lamp closed form). */
static void inscatter_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                            double D, double rel, double S[3], double E[3], int est)
{
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->tau_info) {
            ef_lit_noise_range(s, l, r, a, D, S, E);
            return;
        }
    if (!ef_light_at_position(l)) {
        int uniform = 1;
        for (int i = 0; i < s->ncomp; ++i)
            uniform &= is_uniform(&s->comp[i]);
        if (uniform)
            return;   /* the sun's light never crosses unbounded uniform fog */
        /* one component whose model has the sun's closed form (a planet
         * sun's curved path has none) */
        double v[3];
        if (s->ncomp == 1 && !(l->planet > 0) && closed_range(s, l, r, a, D, v)) {
            for (int k = 0; k < 3; ++k)
                S[k] += v[k];
            return;
        }
    }
    ef_lit_quad_range(s, l, r, a, D, rel, S, est ? E : NULL);
}

int ef_light_cuts(const ef_light *l, const ef_ray *r, double a, double b, double *cut, int cap)
{
    double c[MAX_CUTS];
    int n = 0;
    if (ef_light_at_position(l)) {
        double w[3], ts, h;
        ef_lit_lamp_line(l, r, w, &ts, &h);
        const double hq = ef_lit_len2(h, l->radius);
        if (isfinite(ts) && isfinite(hq)) {
            if (ts > a && ts < b)
                c[n++] = ts;
            /* 1 / d^2 halves its slope each doubling of the distance from
             * the closest approach: geometric cuts from there */
            n = ef_lit_steps_around(c, n, ts, a, b, hq > 0 ? hq : 1e-9 * fmax(fabs(ts), 1));
        }
        if (ef_light_coned(l))
            n = ef_lit_cone_cuts(l, r, a, b, c, n);
    }
    if (l->shadow && n < MAX_CUTS - 2) {
        double iv[64][3];
        int m = ef_shadow_pieces(l->shadow, r->org, r->dir, a, b, iv, 64);
        if (m < 0)
            m = -1 - m;
        for (int i = 0; i < m && n < MAX_CUTS - 2; ++i)
            for (int e = 0; e < 2; ++e)
                if (iv[i][e] > a && iv[i][e] < b)
                    c[n++] = iv[i][e];
    }
    qsort(c, (size_t) n, sizeof c[0], cmp_double);
    int m = 0;
    for (int i = 0; i < n && m < cap; ++i)
        if (m == 0 || c[i] > cut[m - 1])
            cut[m++] = c[i];
    return m;
}

/* Lit intervals a view segment holds on the stack; more (foliage, a
 * fence) go to the heap, up to MAX_LIT, beyond which the rest joins the
 * last (shadow.h). */
#define LIT_STACK 256
#define MAX_LIT 65536


/* Whether ef_light_inscatter takes l's light in s from lamp_closed
 * wherever a ray passes beside the lamp: a point lamp of radius 0, no
 * shadow, in fog that is uniform and isotropic throughout. */
static int lamp_batch(const ef_fog_scene *s, const ef_light *l)
{
    if (!(ef_light_at_position(l) && !ef_light_coned(l)) || l->radius != 0 || l->shadow || s->ncomp == 0)
        return 0;
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->tau_info || !is_uniform(&s->comp[i]) ||
            s->comp[i].phase != EF_PHASE_ISO)
            return 0;
    return 1;
}

/* ef_light_inscatter for ray j into S[k][j] and (E not NULL) E[k][j]. */
static void one_ray(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, int j,
                    double *const S[3], double *const E[3])
{
    double v[3], ve[3];
    ef_light_inscatter(s, l, &r[j], v, E ? ve : NULL);
    for (int k = 0; k < 3; ++k) {
        S[k][j] = v[k];
        if (E)
            E[k][j] = ve[k];
    }
}

void ef_light_rays(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, int n,
                   double *const S[3], double *const E[3])
{
    if (!lamp_batch(s, l) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0)) {
        for (int j = 0; j < n; ++j)
            one_ray(s, l, r, j, S, E);
        return;
    }
    double sig[3], scat[3];
    ef_lit_lamp_medium(s, sig, scat);
    for (int j0 = 0; j0 < n; j0 += EF_SPAN) {
        const int m = n - j0 < EF_SPAN ? n - j0 : EF_SPAN;
        double *const Sj[3] = { S[0] + j0, S[1] + j0, S[2] + j0 };
        double *const Ej[3] = { E ? E[0] + j0 : NULL, E ? E[1] + j0 : NULL,
                                E ? E[2] + j0 : NULL };
        int left[EF_SPAN];
        const int nl = ef_lit_lamp_span(l, sig, scat, r + j0, m, Sj, E ? Ej : NULL, left);
        unsigned char whole[EF_SPAN];   /* one_ray adds the multiple scattering itself */
        memset(whole, 0, sizeof whole);
        for (int i = 0; i < nl; ++i) {
            one_ray(s, l, r + j0, left[i], Sj, E ? Ej : NULL);
            whole[left[i]] = 1;
        }
        for (int j = 0; l->lms && j < m; ++j) {
            if (whole[j])
                continue;
            double v[3] = { 0, 0, 0 }, e[3] = { 0, 0, 0 };
            add_multiple(s, l, &r[j0 + j], NULL, v, e);
            for (int k = 0; k < 3; ++k) {
                Sj[k][j] += v[k];
                if (E)
                    Ej[k][j] += e[k];
            }
        }
    }
}

void ef_light_inscatter(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3],
                        double err[3])
{
    ef_light_inscatter_rel(s, l, r, 0, S, err);
}

void ef_light_inscatter_rel(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double rel,
                            double S[3], double err[3])
{
    double E[3] = { 0, 0, 0 };
    const int est = err != NULL;   /* without err, the estimates are not computed */
    S[0] = S[1] = S[2] = 0;
    if (err)
        err[0] = err[1] = err[2] = 0;
    const double D = r->dist;
    if (s->ncomp == 0 || !(D > 0) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return;
    if (!l->shadow) {
        inscatter_range(s, l, r, 0, D, rel, S, E, est);
    } else {
        /* each lit piece at its visibility (1: hard shadows) */
        double stack[LIT_STACK][3], (*iv)[3] = stack;
        int n = ef_shadow_pieces(l->shadow, r->org, r->dir, 0, D, iv, LIT_STACK);
        if (n < 0) {
            double (*heap)[3] = malloc(MAX_LIT * sizeof *heap);
            if (heap) {
                iv = heap;
                n = ef_shadow_pieces(l->shadow, r->org, r->dir, 0, D, iv, MAX_LIT);
            } else {   /* no memory: what fitted, and the estimate says so */
                for (int k = 0; k < 3; ++k)
                    E[k] = INFINITY;
            }
        }
        if (n < 0)
            n = -1 - n;
        for (int i = 0; i < n; ++i) {
            if (iv[i][2] == 1) {
                inscatter_range(s, l, r, iv[i][0], iv[i][1], rel, S, E, est);
                continue;
            }
            double Sp[3] = { 0, 0, 0 }, Ep[3] = { 0, 0, 0 };
            inscatter_range(s, l, r, iv[i][0], iv[i][1], rel, Sp, Ep, est);
            for (int k = 0; k < 3; ++k) {
                S[k] += iv[i][2] * Sp[k];
                E[k] += iv[i][2] * Ep[k];
            }
        }
        if (iv != stack)
            free(iv);
    }
    add_multiple(s, l, r, NULL, S, E);
    if (err)
        for (int k = 0; k < 3; ++k)
            err[k] = E[k];
}

/* ------------------------------------------------- the dense output */

int ef_lit_dense_build(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double rel,
                       ef_lit_dense *d)
{
    d->n = 0;
    d->failed = 0;
    d->nmemo = d->next = 0;
    d->total[0] = d->total[1] = d->total[2] = 0;
    d->aux[0] = d->aux[1] = d->aux[2] = 0;
    if (!ef_light_at_position(l) || s->ncomp == 0)
        return 1;   /* a sun: its closed forms per segment are cheaper */
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->tau_info)
            return 1;   /* noise fog: lit_noise.c's own integrator */
    const double D = r->dist;
    if (!(D > 0) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return 0;
    if (!l->shadow) {
        ef_lit_quad_range_dense(s, l, r, 0, D, 1, rel, d);
    } else {
        double stack[LIT_STACK][3];
        const int n = ef_shadow_pieces(l->shadow, r->org, r->dir, 0, D, stack, LIT_STACK);
        if (n < 0)
            return 1;   /* more lit pieces than the stack: per segment */
        for (int i = 0; i < n && !d->failed; ++i)
            ef_lit_quad_range_dense(s, l, r, stack[i][0], stack[i][1], stack[i][2], rel, d);
    }
    if (d->failed)
        return d->failed == 2 ? -1 : 1;
    double J[3] = { 0, 0, 0 }, E[3] = { 0, 0, 0 };
    for (int i = 0; i < d->n; ++i) {
        ef_lit_leaf *f = &d->leaf[i];
        for (int k = 0; k < 3; ++k) {
            f->J0[k] = J[k];
            f->E0[k] = E[k];
            J[k] += f->r[k];
            E[k] += f->e[k];
        }
    }
    memcpy(d->total, J, sizeof J);
    return 0;
}

static void dense_at(const ef_lit_dense *d, double t, double J[3], double E[3], double Elo[3]);

void ef_lit_dense_at(ef_lit_dense *d, double t, double J[3], double E[3], double Elo[3])
{
    for (int i = 0; i < d->nmemo; ++i)
        if (d->memo[i][0] == t) {
            memcpy(J, d->memo[i] + 1, 3 * sizeof *J);
            memcpy(E, d->memo[i] + 4, 3 * sizeof *E);
            memcpy(Elo, d->memo[i] + 7, 3 * sizeof *Elo);
            return;
        }
    dense_at(d, t, J, E, Elo);
    double *m = d->memo[d->next];
    d->next = (d->next + 1) & 3;
    if (d->nmemo < 4)
        ++d->nmemo;
    m[0] = t;
    memcpy(m + 1, J, 3 * sizeof *J);
    memcpy(m + 4, E, 3 * sizeof *E);
    memcpy(m + 7, Elo, 3 * sizeof *Elo);
}

/* ef_lit_dense_at without the memo. */
static void dense_at(const ef_lit_dense *d, double t, double J[3], double E[3], double Elo[3])
{
    J[0] = J[1] = J[2] = E[0] = E[1] = E[2] = Elo[0] = Elo[1] = Elo[2] = 0;
    if (d->n == 0 || !(t > d->leaf[0].t0))
        return;
    /* the last leaf starting before t */
    int lo = 0, hi = d->n - 1;
    while (lo < hi) {
        const int mid = (lo + hi + 1) / 2;
        if (d->leaf[mid].t0 < t)
            lo = mid;
        else
            hi = mid - 1;
    }
    const ef_lit_leaf *f = &d->leaf[lo];
    if (!(t < f->t1)) {   /* past it: its whole integral */
        for (int k = 0; k < 3; ++k) {
            J[k] = f->J0[k] + f->r[k];
            E[k] = Elo[k] = f->E0[k] + f->e[k];
        }
        return;
    }
    double u;
    switch (f->mode) {
    case 1:
        u = atan((t - f->ts) / f->hq);
        break;
    case 2: {
        const double x = t - f->ts - f->ua;
        u = x / (f->lam + x);
        break;
    }
    case 0:
        u = t - f->ts;
        break;
    default:
        u = t;
    }
    const double h = 0.5 * (f->u1 - f->u0);
    double y = h > 0 ? (u - 0.5 * (f->u0 + f->u1)) / h : 1;
    y = y < -1 ? -1 : y > 1 ? 1 : y;
    _Static_assert(EF_LIT_DENSE_NA == 16, "Estrin below takes 16 coefficients");
    /* the leaf's antiderivative, by Estrin's scheme (a short dependency
     * chain: a deep pixel asks this for every sample's two ends) */
    const double y2 = y * y, y4 = y2 * y2, y8 = y4 * y4;
    double v = 0;
    for (int k = 0; k < 3; ++k) {
        if (k == 0 || !f->grey) {   /* a grey leaf's sum serves every channel */
            const double *a = f->c[k];
            const double q0 = (a[0] + a[1] * y) + (a[2] + a[3] * y) * y2,
                         q1 = (a[4] + a[5] * y) + (a[6] + a[7] * y) * y2,
                         q2 = (a[8] + a[9] * y) + (a[10] + a[11] * y) * y2,
                         q3 = (a[12] + a[13] * y) + (a[14] + a[15] * y) * y2;
            v = (q0 + q1 * y4) + (q2 + q3 * y4) * y8;
        }
        J[k] = f->J0[k] + h * v;
        E[k] = f->E0[k] + f->e[k];
        Elo[k] = f->E0[k];
    }
}

void ef_lit_dense_free(ef_lit_dense *d)
{
    free(d->leaf);
    free(d->fv);
    memset(d, 0, sizeof *d);
}
