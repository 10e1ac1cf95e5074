/* Lit fog through a rough component (noise) (lit_int.h): the in-scatter
 * stepped along the ray in each component's own optical depth, with
 * Richardson's difference and the noise calls' estimates as its error. */
#include "lit_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------- lit noise fog
 *
 * Where a component's optical depth is not a closed form (noise), the
 * integrand sigma T is as rough as the noise, but what light adds to it is
 * not: S = sum_c int h_c dmu_c, with mu_c the component's own share of the
 * view ray's extinction (dmu_c = sigma_c T_c(0,t) dt, its pieces from the
 * model's optical depths, so within the noise method's tolerance) and h_c
 * = albedo_c p_c(theta) E T_light V T_rest(0,t), smooth between the cuts
 * (T_rest: the other components' transmittance). Steps forward along the
 * ray: each step's quarters give h at five points placed at their own
 * coordinates s = mu(t) (known), the quadratic through three of them
 * integrated in s over each half and over the whole, and Richardson's
 * difference of the two levels the step's estimate; a step whose estimate
 * passes tol of its own light (plus 2^-6 of what came before) is halved,
 * the next grows with the fifth root of the margin. The noise calls'
 * estimates (4 sigma each, independent) add in quadrature. */

#define NZ_STEPS 4096
/* The work bound of one light along one ray, in noise evaluations (the
 * view's pieces and the light's paths): past it the rest of the ray's
 * light is its bound in the error output, as the unlit model's work bound
 * does (noise-separable with a lamp took 130 ms a pixel, and cheap unlit
 * SPECs minutes once lit). About 20 to 100 ms of one core. */
#define NZ_BUDGET 2e6

typedef struct nz_pt {
    double t, cth, G[3], gerr;   /* E T_light (spot share) per channel, T_light's tau error */
    double evals;                /* noise evaluations its light's path cost */
} nz_pt;

/* The point at t of r for light l: its light before scattering. */
static void nz_point(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double t,
                     nz_pt *p)
{
    p->t = t;
    p->gerr = 0;
    p->evals = 0;
    p->G[0] = p->G[1] = p->G[2] = 0;
    p->cth = 0;
    double x[3], ld[3], dl = INFINITY, f = 1;
    for (int a = 0; a < 3; ++a)
        x[a] = r->org[a] + t * r->dir[a];
    if (!ef_light_at_position(l)) {
        memcpy(ld, l->dir, sizeof ld);
        p->cth = ld[0] * r->dir[0] + ld[1] * r->dir[1] + ld[2] * r->dir[2];
    } else {
        double y[3], d2 = 0;
        for (int a = 0; a < 3; ++a) {
            y[a] = (l->pos[a] - r->org[a]) - t * r->dir[a];
            d2 += y[a] * y[a];
        }
        dl = sqrt(d2);
        if (!(dl > 0))
            return;
        for (int a = 0; a < 3; ++a)
            ld[a] = y[a] / dl;
        p->cth = ld[0] * r->dir[0] + ld[1] * r->dir[1] + ld[2] * r->dir[2];
        f = 1 / (d2 + l->radius * l->radius);
        if (ef_light_coned(l))
            f *= ef_spot_share(l, -(ld[0] * l->dir[0] + ld[1] * l->dir[1] + ld[2] * l->dir[2]));
        if (f == 0)
            return;
    }
    double tl[3] = { 0, 0, 0 };
    ef_ray lr = { { ld[0], ld[1], ld[2] }, dl, dl, { x[0], x[1], x[2] } };
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double v[3];
        if (c->model->tau_info) {
            ef_tau_info in;
            c->model->tau_info(c, &lr, v, &in);
            p->gerr += fmax(in.err[0], fmax(in.err[1], in.err[2]));
            p->evals += in.evals;
        } else {
            c->model->tau(c, &lr, v);
        }
        for (int k = 0; k < 3; ++k)
            tl[k] += v[k];
    }
    for (int k = 0; k < 3; ++k) {
        const double e = exp(-tl[k]);
        p->G[k] = e == 0 || l->e[k] == 0 ? 0 : l->e[k] * f * e;
    }
}

/* Optical depth of each component over [t0, t1] of r into tau (ncomp x
 * 3), the noise methods' error estimates summed into *err and their
 * evaluations into *evals (may be NULL). The view ray's
 * pieces go at 1/16 of each model's tolerance: their errors add up along
 * the ray in T(0, t) (over ~100 steps, to ~10 tol at the model's own),
 * where the light paths' errors are independent and average out. */
static void nz_taus(const ef_fog_scene *s, const ef_ray *r, double t0, double t1,
                    double (*tau)[3], double *err, double *evals)
{
    ef_ray sub = *r;
    for (int a = 0; a < 3; ++a)
        sub.org[a] = r->org[a] + t0 * r->dir[a];
    sub.dist = sub.planar = t1 - t0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (c->model->tau_tol && c->model->lit_tol) {
            ef_tau_info in;
            c->model->tau_tol(c, &sub, c->model->lit_tol(c) / 16, tau[i], &in);
            *err += fmax(in.err[0], fmax(in.err[1], in.err[2]));
            if (evals)
                *evals += in.evals;
        } else if (c->model->tau_info) {
            ef_tau_info in;
            c->model->tau_info(c, &sub, tau[i], &in);
            *err += fmax(in.err[0], fmax(in.err[1], in.err[2]));
            if (evals)
                *evals += in.evals;
        } else {
            c->model->tau(c, &sub, tau[i]);
        }
    }
}

/* int h ds over [0, S] from h0, h1, h2 at s = 0, p, S: the quadratic's
 * integral, or the two trapezoids where p leaves one side too thin for it
 * (and *low set). */
static double nz_rule(double h0, double h1, double h2, double p, double S, int *low)
{
    if (!(p > 0.05 * S && p < 0.95 * S)) {
        *low = 1;
        return 0.5 * (h0 + h1) * p + 0.5 * (h1 + h2) * (S - p);
    }
    const double x = p / S;   /* in (0.05, 0.95): no overflow, no underflow */
    return S * ((3 * x - 1) / (6 * x) * h0 + h1 / (6 * x * (1 - x)) +
                (2 - 3 * x) / (6 * (1 - x)) * h2);
}

/* The relative accuracy lit fog aims at through s's rough components:
 * the finest their models promise (each model's lit_tol). */
static double nz_tol(const ef_fog_scene *s)
{
    double rel = INFINITY;
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].model->lit_tol)
            rel = fmin(rel, s->comp[i].model->lit_tol(&s->comp[i]));
    return isfinite(rel) ? fmax(rel, 1e-12) : EF_NOISE_DEFAULT_TOL;
}

/* Adds to S light l's in-scatter over [a, D] of r (T counted from r's
 * origin; D may be INFINITY) with a rough component in s, and its error
 * estimate to E. */
void ef_lit_noise_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                        double D, double S[3], double E[3])
{
    const int nc = s->ncomp;
    double cum[EF_FOG_MAX_COMPONENTS][3], tq[4][EF_FOG_MAX_COMPONENTS][3];
    double cum_var = 0, hb = 0;   /* the running tau error's square, a bound on h / T */
    double rss[3] = { 0, 0, 0 };  /* the independent errors' squares */
    const double rel = nz_tol(s);
    if (a > 0) {
        nz_taus(s, r, 0, a, cum, &cum_var, NULL);   /* one call: its estimate, squared */
        cum_var *= cum_var;
    } else {
        for (int i = 0; i < nc; ++i)
            cum[i][0] = cum[i][1] = cum[i][2] = 0;
    }
    /* the cuts: the densities' features, and a lamp's closest approach
     * with geometric steps around it (and a spot's cone); hb bounds h / T */
    double cut[MAX_CUTS];
    int n = 0;
    cut[n++] = a;
    n = ef_lit_feature_cuts(s, r, a, D, cut, n);
    double pmax = 0, amax = 0;
    for (int i = 0; i < nc; ++i) {
        pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, 1));
        pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, -1));
        pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, 0));
        for (int k = 0; k < 3; ++k)
            amax = fmax(amax, albedo(&s->comp[i], k));
    }
    double emax = fmax(l->e[0], fmax(l->e[1], l->e[2]));
    if (ef_light_at_position(l)) {
        double w[3], ts, h;
        ef_lit_lamp_line(l, r, w, &ts, &h);
        const double hq = ef_lit_len2(h, l->radius);
        if (!isfinite(ts) || !(hq <= DBL_MAX / 64))
            return;
        if (hq == 0 && ts >= a && ts <= D) {
            for (int k = 0; k < 3; ++k)
                if (l->e[k] > 0)
                    S[k] = INFINITY;
            return;
        }
        if (ts > a && ts < D)
            cut[n++] = ts;
        n = ef_lit_steps_around(cut, n, ts, a, D, hq > 0 ? hq : 1e-9 * fmax(fabs(ts), 1));
        if (ef_light_coned(l))
            n = ef_lit_cone_cuts(l, r, a, D, cut, n);
        emax /= hq * hq;
    }
    hb = amax * pmax * emax;
    if (isfinite(D))
        cut[n++] = D;
    qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
    /* Steps of at most a quarter of the rough components' coarsest
     * lattice cell at the default tol (the whole cell from 16 times it,
     * a sixteenth from 1/16 of it): the light's transmittance varies over
     * the noise's own scales (the light's path crosses other features as
     * the point moves), and Richardson's estimate only sees what a step's
     * five points resolve. Measured against the reference and tight-tol
     * runs (tests/unit/test_lit_noise.c; a quarter cell: within 5e-5 on a
     * 10-unit ray at the ground where the whole cell was 0.4 % off). */
    double cap = INFINITY;
    for (int i = 0; i < nc; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->tau_info || !c->model->lattices)
            continue;
        ef_fog_lattice lt[64];
        const int nl = c->model->lattices(c, lt, 64);
        double big = 0;
        for (int j = 0; j < nl && j < 64; ++j)
            big = fmax(big, lt[j].period);
        if (big > 0)
            cap = fmin(cap, big * fmin(1, fmax(0.0625, 0.25 * sqrt(rel / EF_NOISE_DEFAULT_TOL))));
    }
    double Sum[3] = { 0, 0, 0 }, rest[3] = { 0, 0, 0 };
    double last_mass = INFINITY;   /* the last step's share of extinction */
    nz_pt pa;
    nz_point(s, l, r, a, &pa);
    double dt = 0, work = pa.evals;
    int steps = 0;
    for (int ci = 0; ci < n && steps < NZ_STEPS; ++ci) {
        if (ci + 1 == n && isfinite(D))
            break;
        const double c0 = cut[ci], c1 = ci + 1 < n ? cut[ci + 1] : INFINITY;
        if (!(c1 > c0))
            continue;
        double t = c0;
        dt = dt > 0 ? fmin(dt, c1 - c0) : isfinite(c1) ? c1 - c0 : fmax(c0, 1);
        last_mass = INFINITY;   /* past a cut (a box's face) the cap holds again */
        while (t < c1 && steps < NZ_STEPS) {
            /* what is left cannot show: T(0, t) times the bound on h */
            double T0max = 0;
            for (int k = 0; k < 3; ++k) {
                double tt = 0;
                for (int i = 0; i < nc; ++i)
                    tt += cum[i][k];
                T0max = fmax(T0max, exp(-tt));
            }
            double left = hb * T0max;
            if (isinf(c1)) {
                /* the infinite tail: what is left of the ray's own
                 * extinction from t on, per channel */
                ef_ray tail = *r;
                for (int q = 0; q < 3; ++q)
                    tail.org[q] = r->org[q] + t * r->dir[q];
                tail.dist = tail.planar = INFINITY;
                rest[0] = rest[1] = rest[2] = 0;
                for (int i = 0; i < nc; ++i) {
                    double v[3];
                    s->comp[i].model->tau(&s->comp[i], &tail, v);
                    for (int k = 0; k < 3; ++k)
                        rest[k] += v[k];
                }
                left = 0;
                for (int k = 0; k < 3; ++k) {
                    double tt = 0;
                    for (int i = 0; i < nc; ++i)
                        tt += cum[i][k];
                    left = fmax(left, hb * exp(-tt) * -expm1(-fmax(rest[k], 0)));
                }
            }
            double smax = fmax(Sum[0], fmax(Sum[1], Sum[2]));
            /* (past the work bound too, at the default tolerance: the rest
             * is its bound; an explicit finer tol asks for it everywhere) */
            if (!(left > 0.25 * rel * smax) || left < 1e-300 ||
                (work > NZ_BUDGET && rel >= log1p(EF_NOISE_DEFAULT_TOL))) {
                for (int k = 0; k < 3; ++k)
                    E[k] += left;
                t = INFINITY;
                ci = n;
                break;
            }
            /* where a step can no longer matter, the cap is lifted */
            const double smax_ = fmax(Sum[0], fmax(Sum[1], Sum[2]));
            double b = t + (hb * last_mass <= 0x1p-6 * rel * smax_ ? dt : fmin(dt, cap));
            if (!(b < c1) || c1 - b < 1e-3 * dt)
                b = c1;
            ++steps;
            /* the step's quarters: each component's optical depth over
             * each, the light at their ends */
            double terr = 0;
            nz_pt pq[5];
            pq[0] = pa;
            for (int j = 1; j <= 4; ++j) {
                const double tj = j == 4 ? b : t + 0.25 * j * (b - t);
                nz_taus(s, r, j == 1 ? t : t + 0.25 * (j - 1) * (b - t), tj, tq[j - 1], &terr,
                        &work);
                nz_point(s, l, r, tj, &pq[j]);
                work += pq[j].evals;
            }
            double Q[3] = { 0, 0, 0 }, Qe[3] = { 0, 0, 0 }, hm[3] = { 0, 0, 0 };
            for (int i = 0; i < nc; ++i) {
                const ef_fog_component *c = &s->comp[i];
                double ph[5];
                for (int j = 0; j < 5; ++j)
                    ph[j] = ef_phase_eval(c->phase, c->g, pq[j].cth);
                for (int k = 0; k < 3; ++k) {
                    double other = 0, own = cum[i][k], h[5], mu[4];
                    for (int q = 0; q < nc; ++q)
                        other += q == i ? 0 : cum[q][k];
                    const double al = albedo(c, k), Ta = exp(-cum[i][k]);
                    double hmax = 0;
                    for (int j = 0; j < 5; ++j) {
                        if (j > 0) {
                            /* its share of the quarter's extinction */
                            mu[j - 1] = exp(-own) * -expm1(-tq[j - 1][i][k]);
                            for (int q = 0; q < nc; ++q)
                                other += q == i ? 0 : tq[j - 1][q][k];
                            own += tq[j - 1][i][k];
                        }
                        /* the other components' transmittance there (0
                         * light where they or the light's path are opaque:
                         * no inf * 0) */
                        const double tr = exp(-other);
                        h[j] = tr == 0 || pq[j].G[k] == 0 ? 0 : al * ph[j] * pq[j].G[k] * tr;
                        hmax = fmax(hmax, h[j]);
                    }
                    const double S2 = mu[0] + mu[1], S4 = S2 + mu[2] + mu[3];
                    if (!(S4 > 0))
                        continue;
                    int low = 0;
                    const double coarse = nz_rule(h[0], h[2], h[4], S2, S4, &low);
                    const double fine = nz_rule(h[0], h[1], h[2], mu[0], S2, &low) +
                                        nz_rule(h[2], h[3], h[4], mu[2], mu[2] + mu[3], &low);
                    Q[k] += fine;
                    /* Richardson: the order-4 rules' difference over 15;
                     * where a side was too thin for the quadratic, the
                     * trapezoids' (order 2) over 3 */
                    Qe[k] += fabs(fine - coarse) / (low ? 3 : 15);
                    hm[k] = fmax(hm[k], hmax * Ta);
                }
            }
            int ok = 1;
            for (int k = 0; k < 3; ++k)
                ok &= Qe[k] <= rel * (fabs(Q[k]) + 0x1p-6 * fabs(Sum[k])) + 1e-300 ||
                      !isfinite(Qe[k]);
            if (!ok && (b - t) > 1e-9 * fmax(fabs(t), 1) && steps < NZ_STEPS) {
                dt = 0.5 * (b - t);
                continue;
            }
            /* accepted: the step's light, its estimates, the next step.
             * The noise methods' estimates are 4 sigma of independent
             * errors: over many calls they add in quadrature. */
            double gerr = 0;
            for (int j = 0; j < 5; ++j)
                gerr = fmax(gerr, pq[j].gerr);
            for (int k = 0; k < 3; ++k) {
                Sum[k] += Q[k];
                E[k] += Qe[k] + fabs(Q[k]) * expm1(sqrt(cum_var));
                rss[k] += Q[k] * Q[k] * gerr * gerr + hm[k] * hm[k] * terr * terr;
            }
            cum_var += terr * terr;
            last_mass = 0;
            for (int k = 0; k < 3; ++k) {
                double before = 0, d = 0;
                for (int i = 0; i < nc; ++i) {
                    before += cum[i][k];
                    d += tq[0][i][k] + tq[1][i][k] + tq[2][i][k] + tq[3][i][k];
                }
                last_mass = fmax(last_mass, exp(-before) * -expm1(-d));
            }
            for (int i = 0; i < nc; ++i)
                for (int k = 0; k < 3; ++k) {
                    cum[i][k] += tq[0][i][k] + tq[1][i][k] + tq[2][i][k] + tq[3][i][k];
                }
            double worst = 0;
            for (int k = 0; k < 3; ++k) {
                const double room = rel * (fabs(Q[k]) + 0x1p-6 * fabs(Sum[k])) + 1e-300;
                worst = fmax(worst, Qe[k] / room);
            }
            const double grow = worst > 0 ? 0.8 * pow(worst, -0.2) : 4;
            dt = (b - t) * fmin(4, fmax(0.5, grow));
            t = b;
            pa = pq[4];
        }
    }
    for (int k = 0; k < 3; ++k) {
        S[k] += Sum[k];
        E[k] += sqrt(rss[k]);
    }
    if (steps >= NZ_STEPS)
        for (int k = 0; k < 3; ++k)
            E[k] += hb;   /* the step budget ran out: say so */
}
