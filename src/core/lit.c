/* Lit fog (lit.h): which method serves each light and segment (lit noise
 * fog, a sun's closed form, the quadrature with its lamp closed form), the
 * lights' checks, the sun's closed forms, where a light's in-scatter turns
 * (cuts), and the public entry points per ray and per span. lit_int.h
 * lists the family. */
#include "lit_int.h"
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
    const int one_height = s->ncomp == 1 && s->comp[0].model == &ef_fog_height &&
                           s->comp[0].p[3] > 0;
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
    if (l->kind != EF_LIGHT_SUN || l->planet > 0)
        return 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (is_uniform(c) && c->p[0] > 0 && c->p[1] > 0 && c->p[2] > 0)
            return 1;
    }
    return 0;
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

void ef_lit_sun_planet_tau(const ef_fog_scene *s, const ef_light *l, const double x[3],
                           double tau[3])
{
    const ef_fog_component *c = &s->comp[0];
    const double k = c->p[3], R = l->planet;
    const double y = c->up[0] * x[0] + c->up[1] * x[1] + c->up[2] * x[2];
    const double mu = l->dir[0] * c->up[0] + l->dir[1] * c->up[1] + l->dir[2] * c->up[2];
    const double r0 = R + y;
    tau[0] = tau[1] = tau[2] = INFINITY;
    if (!(r0 > 0) || (mu < 0 && r0 * sqrt((1 - mu) * (1 + mu)) < R))
        return;
    const double ch = ef_light_planet_ch(l, k, mu, y);
    const double e = exp(-k * (y - c->p[4]));
    for (int ch3 = 0; ch3 < 3; ++ch3)
        tau[ch3] = c->p[ch3] == 0 ? 0 : c->p[ch3] * e / k * ch;
}
/* ------------------------------------------------------- the closed forms */

/* tau phi(tau q), phi(x) = -expm1(-x) / x: the integral of e^(linear) over
 * a segment of optical depth tau whose exponent changes by tau q, relative
 * to its larger end. tau phi(x) while x <= 1 (x -> 0 tends to tau exactly),
 * -expm1(-x) / q beyond (tau = inf gives 1 / q). */
static double tau_phi(double tau, double q)
{
    const double x = tau * q;
    if (x == 0)
        return tau;
    if (x <= 1)
        return tau * (-expm1(-x) / x);
    return -expm1(-x) / q;
}

/* The sun in one exponential height fog (k > 0), with its own extinction
 * in the fog: T_sun(x) = e^-(sigma(x) / (k l_up)), and along the view ray
 *   S = albedo p E tau_v e^-min(A, B) phi(|B - A|),
 *   A = sigma(C) / (k l_up), B = tau_v + sigma(P) / (k l_up),
 * phi(x) = -expm1(-x) / x and B - A = tau_v (1 - mu / l_up) exactly (mu the
 * view ray's up component), so no difference of large terms is formed. */
static void sun_height_tau(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                           const double tv[3], double S[3])
{
    const ef_fog_component *c = &s->comp[0];
    const double k = c->p[3];
    const double lu = l->dir[0] * c->up[0] + l->dir[1] * c->up[1] + l->dir[2] * c->up[2];
    const double mu = r->dir[0] * c->up[0] + r->dir[1] * c->up[1] + r->dir[2] * c->up[2];
    S[0] = S[1] = S[2] = 0;
    if (!(lu > 0))
        return;   /* at or below the horizon, the sun crosses unbounded fog */
    double sc[3], sp[3] = { 0, 0, 0 };
    /* the densities at the ends, rho e^-(k (height - base)), in double
     * (one exponential each: the model's own density works in long double
     * for the reference) */
    const double hc = c->up[0] * r->org[0] + c->up[1] * r->org[1] + c->up[2] * r->org[2] - c->p[4];
    const double ec = exp(-k * hc);
    double ep = 0;
    if (isfinite(r->dist))
        ep = exp(-k * (hc + r->dist * mu));
    else if (!(mu > 0))
        ep = INFINITY;
    for (int ch = 0; ch < 3; ++ch) {
        sc[ch] = c->p[ch] == 0 ? 0 : c->p[ch] * ec;
        sp[ch] = c->p[ch] == 0 ? 0 : c->p[ch] * ep;
    }
    const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    const double p = ef_phase_eval(c->phase, c->g, cth), q = fabs(1 - mu / lu);
    double me = 0;   /* m e^-min(A, B) of channel last (-1: none yet) */
    int last = -1;
    for (int ch = 0; ch < 3; ++ch) {
        if (!(tv[ch] > 0) || l->e[ch] == 0 || albedo(c, ch) == 0)
            continue;
        /* grey fog: the same densities, the same factor */
        if (!(last >= 0 && c->p[ch] == c->p[last] && tv[ch] == tv[last])) {
            last = ch;
            const double A = sc[ch] / (k * lu), B = tv[ch] + sp[ch] / (k * lu);
            const double e = exp(-(A < B ? A : B));
            me = e == 0 ? 0 : tau_phi(tv[ch], q) * e;
        }
        S[ch] = me == 0 ? 0 : albedo(c, ch) * p * l->e[ch] * me;
    }
}

/* sun_height with the view segment's optical depth from the model. */
static void sun_height(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3])
{
    double tv[3];
    s->comp[0].model->tau(&s->comp[0], r, tv);
    sun_height_tau(s, l, r, tv, S);
}

int ef_light_sun_span(const ef_fog_scene *s, const ef_light *l)
{
    return l->kind == EF_LIGHT_SUN && !l->shadow && !(l->planet > 0) && s->ncomp == 1 &&
           s->comp[0].model == &ef_fog_height && s->comp[0].p[3] > 0;
}

void ef_light_sun_span_eval(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                            const double tv[3], double S[3])
{
    S[0] = S[1] = S[2] = 0;
    /* as ef_light_inscatter: no segment, no light */
    if (!(r->dist > 0) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return;
    sun_height_tau(s, l, r, tv, S);
}

/* The sun in one half-space fog of any of the three densities sigma(X) of
 * the depth X = -h below the plane (h = n.x + d, n unit, fog where h < 0:
 * constant, linear, Walker's smooth): from x the sun's path in the fog has
 * optical depth tau_sun(x) = Sigma(X) / (n.l), Sigma the density's
 * integral from the plane down, so along the view ray the exponent
 * E(t) = -(tau_v(0, t) + tau_sun(x(t))) has dE/dt = -sigma (1 - s / (n.l))
 * (s = n.u) wherever there is fog, and 0 where there is none:
 *   S = albedo p E int sigma e^E dt = albedo p E (e^E(0) - e^E(D)) / q,
 * q = 1 - s / (n.l), written as tau_v e^max(E(0), E(D)) phi(tau_v |q|)
 * (no difference of large terms; q -> 0 tends to tau_v e^E). Both ends'
 * E come from the model's own closed-form optical depths (the view
 * segment, and the sun's ray from each end). With n.l <= 0 the sun never
 * leaves the fog: no light. */
static void sun_halfspace(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3])
{
    const ef_fog_component *c = &s->comp[0];
    const double *n = c->p;
    const double nl = n[0] * l->dir[0] + n[1] * l->dir[1] + n[2] * l->dir[2];
    const double sv = n[0] * r->dir[0] + n[1] * r->dir[1] + n[2] * r->dir[2];
    S[0] = S[1] = S[2] = 0;
    if (!(nl > 0))
        return;
    double tv[3], ta[3], tb[3] = { 0, 0, 0 };
    c->model->tau(c, r, tv);
    if (c->model == &ef_fog_halfspace) {
        /* constant: Sigma(X) = rho X, from the plane values at the ends */
        const double h0 = n[0] * r->org[0] + n[1] * r->org[1] + n[2] * r->org[2] + n[3];
        const double hb = isfinite(r->dist) ? h0 + sv * r->dist : 0;
        for (int ch = 0; ch < 3; ++ch) {
            ta[ch] = h0 < 0 ? c->p[4 + ch] * -h0 / nl : 0;
            tb[ch] = hb < 0 ? c->p[4 + ch] * -hb / nl : 0;
        }
    } else {
        ef_ray sun = { { l->dir[0], l->dir[1], l->dir[2] }, INFINITY, INFINITY,
                       { r->org[0], r->org[1], r->org[2] } };
        c->model->tau(c, &sun, ta);
        if (isfinite(r->dist)) {
            for (int k = 0; k < 3; ++k)
                sun.org[k] = r->org[k] + r->dist * r->dir[k];
            c->model->tau(c, &sun, tb);
        }
    }
    const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    const double p = ef_phase_eval(c->phase, c->g, cth), q = fabs(1 - sv / nl);
    for (int ch = 0; ch < 3; ++ch) {
        if (!(tv[ch] > 0) || l->e[ch] == 0 || albedo(c, ch) == 0)
            continue;
        const double ya = -ta[ch], yb = -tv[ch] - tb[ch];
        const double e = exp(ya > yb ? ya : yb);
        S[ch] = e == 0 ? 0 : albedo(c, ch) * p * l->e[ch] * tau_phi(tv[ch], q) * e;
    }
}

/* The sun in one constant-density convex volume (box or convex: planes
 * n.x + d < 0, n unit, in c->arr): inside, the sun's path out of the
 * volume is e(t) = min over the planes the sunlight leaves through
 * (n.l > 0) of -(n.x(t) + d) / (n.l), a lower envelope of lines in t, and
 * the fog is only there, so along the view segment's part inside,
 * [t_in, t_out], the exponent -rho (t - t_in + e(t)) is piecewise linear:
 * per piece rho L e^max(ends) phi(|difference|). With no plane facing the
 * sun the sun's path never leaves: no light. */
static void sun_convex(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3])
{
    const ef_fog_component *c = &s->comp[0];
    const int np = (int) c->p[9];
    S[0] = S[1] = S[2] = 0;
    if (np <= 0 || np > 64)
        return;
    double h0[64], sv[64], m[64];
    double tin = 0, tout = r->dist;
    for (int i = 0; i < np; ++i) {
        const double *P = c->arr + 4 * i;
        h0[i] = P[0] * r->org[0] + P[1] * r->org[1] + P[2] * r->org[2] + P[3];
        sv[i] = P[0] * r->dir[0] + P[1] * r->dir[1] + P[2] * r->dir[2];
        m[i] = P[0] * l->dir[0] + P[1] * l->dir[1] + P[2] * l->dir[2];
        if (sv[i] == 0) {
            if (!(h0[i] < 0))
                return;   /* along the plane, outside it */
        } else if (sv[i] < 0) {
            tin = fmax(tin, -h0[i] / sv[i]);
        } else {
            tout = fmin(tout, -h0[i] / sv[i]);
        }
    }
    if (!(tin < tout))
        return;
    /* the length inside from the model's own optical depth, which clips in
     * double-double: a sliver's ends, subtracted in double, would lose it */
    double tv[3], len = tout - tin;
    c->model->tau(c, r, tv);
    for (int ch = 0; ch < 3; ++ch)
        if (c->p[ch] > 0 && isfinite(tv[ch])) {
            len = tv[ch] / c->p[ch];
            break;
        }
    /* e(t) = min_i alpha_i + beta_i t over the planes the sun leaves by */
    int cur = -1;
    double ecur = INFINITY;
    for (int i = 0; i < np; ++i)
        if (m[i] > 0) {
            const double e = -(h0[i] + tin * sv[i]) / m[i];
            if (cur < 0 || e < ecur || (e == ecur && -sv[i] / m[i] < -sv[cur] / m[cur])) {
                cur = i;
                ecur = e;
            }
        }
    if (cur < 0)
        return;   /* no plane faces the sun: its light never gets in */
    const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    const double p = ef_phase_eval(c->phase, c->g, cth);
    /* pieces by their offset from tin (u): the kinks' t only place them,
     * so the lengths add up to len exactly */
    double t = tin, u = 0;
    while (u < len) {
        const double bc = -sv[cur] / m[cur];
        /* the next line to dip below the current one */
        double tn = INFINITY;
        int next = -1;
        for (int i = 0; i < np; ++i) {
            if (!(m[i] > 0) || i == cur)
                continue;
            const double bi = -sv[i] / m[i];
            if (!(bi < bc))
                continue;
            /* alpha_i + bi t = alpha_c + bc t, alpha = -h0 / m */
            const double tx = (-h0[i] / m[i] + h0[cur] / m[cur]) / (bc - bi);
            if (tx > t && tx < tn && tx - tin < len) {
                tn = tx;
                next = i;
            }
        }
        const double e0 = fmax(-(h0[cur] + t * sv[cur]) / m[cur], 0);
        const double un = next < 0 ? len : fmin(fmax(tn - tin, u), len);
        const double L = un - u, q = fabs(1 + bc);
        for (int ch = 0; ch < 3; ++ch) {
            const double rho = c->p[ch];
            if (!(rho > 0) || l->e[ch] == 0 || albedo(c, ch) == 0)
                continue;
            const double y0 = -rho * (u + e0);
            const double y1 = y0 - rho * (1 + bc) * L;
            const double e = isfinite(L) ? exp(y0 > y1 ? y0 : y1) : exp(y0);
            if (e == 0)
                continue;
            S[ch] += albedo(c, ch) * p * l->e[ch] * tau_phi(rho * L, q) * e;
        }
        if (next < 0)
            break;
        cur = next;
        t = tn;
        u = un;
    }
}

/* A closed form f (over a whole ray from its origin) over [a, b] of r:
 * T(0, a) times f along the ray from x(a). */
static void closed_range(void (*f)(const ef_fog_scene *, const ef_light *, const ef_ray *,
                                   double *),
                         const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                         double b, double S[3])
{
    if (a == 0 && b == r->dist) {
        f(s, l, r, S);
        return;
    }
    ef_ray sub = *r;
    for (int k = 0; k < 3; ++k)
        sub.org[k] = r->org[k] + a * r->dir[k];
    sub.dist = sub.planar = b - a;
    double tv[3];
    ef_lit_tau_from(s, r->org, r->dir, a, tv);
    f(s, l, &sub, S);
    for (int k = 0; k < 3; ++k)
        S[k] = S[k] == 0 ? 0 : S[k] * exp(-tv[k]);
}


/* Adds to S the light l scatters in over [a, b] of r (0 <= a < b, b may
 * be INFINITY), T(0, t) counted from the camera, and its error estimate
 * to E: the method that serves the segment (lit noise fog, a sun's closed
 * form, else the quadrature with its point-lamp closed form). */
static void inscatter_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                            double D, double S[3], double E[3])
{
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->tau_info) {
            ef_lit_noise_range(s, l, r, a, D, S, E);
            return;
        }
    if (l->kind == EF_LIGHT_SUN) {
        int uniform = 1;
        for (int i = 0; i < s->ncomp; ++i)
            uniform &= is_uniform(&s->comp[i]);
        if (uniform)
            return;   /* the sun's light never crosses unbounded uniform fog */
        void (*f)(const ef_fog_scene *, const ef_light *, const ef_ray *, double *) = NULL;
        if (s->ncomp == 1 && s->comp[0].model == &ef_fog_height && s->comp[0].p[3] > 0 &&
            !(l->planet > 0))
            f = sun_height;
        if (s->ncomp == 1 && (s->comp[0].model == &ef_fog_halfspace ||
                              s->comp[0].model == &ef_fog_halfspace_linear ||
                              s->comp[0].model == &ef_fog_halfspace_smooth))
            f = sun_halfspace;
        if (s->ncomp == 1 && (s->comp[0].model == &ef_fog_box ||
                              s->comp[0].model == &ef_fog_convex) && s->comp[0].p[9] <= 64)
            f = sun_convex;
        if (f) {
            double v[3];
            closed_range(f, s, l, r, a, D, v);
            for (int k = 0; k < 3; ++k)
                S[k] += v[k];
            return;
        }
    }
    ef_lit_quad_range(s, l, r, a, D, S, E);
}

int ef_light_cuts(const ef_light *l, const ef_ray *r, double a, double b, double *cut, int cap)
{
    double c[MAX_CUTS];
    int n = 0;
    if (l->kind != EF_LIGHT_SUN) {
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
        if (l->kind == EF_LIGHT_SPOT)
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
    if (l->kind != EF_LIGHT_POINT || l->radius != 0 || l->shadow || s->ncomp == 0)
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
    ef_light_inscatter(s, l, &r[j], v, ve);
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
        for (int i = 0; i < nl; ++i)
            one_ray(s, l, r + j0, left[i], Sj, E ? Ej : NULL);
    }
}

void ef_light_inscatter(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3],
                        double err[3])
{
    double E[3] = { 0, 0, 0 };
    S[0] = S[1] = S[2] = 0;
    if (err)
        err[0] = err[1] = err[2] = 0;
    const double D = r->dist;
    if (s->ncomp == 0 || !(D > 0) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return;
    if (!l->shadow) {
        inscatter_range(s, l, r, 0, D, S, E);
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
                inscatter_range(s, l, r, iv[i][0], iv[i][1], S, E);
                continue;
            }
            double Sp[3] = { 0, 0, 0 }, Ep[3] = { 0, 0, 0 };
            inscatter_range(s, l, r, iv[i][0], iv[i][1], Sp, Ep);
            for (int k = 0; k < 3; ++k) {
                S[k] += iv[i][2] * Sp[k];
                E[k] += iv[i][2] * Ep[k];
            }
        }
        if (iv != stack)
            free(iv);
    }
    if (err)
        for (int k = 0; k < 3; ++k)
            err[k] = E[k];
}
