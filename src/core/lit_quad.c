/* Lit fog's general quadrature (lit_int.h): global adaptive
 * Gauss-Kronrod (QUADPACK's estimate) over the pieces between the
 * density's features, a lamp's closest approach (in its angle there) and a
 * spot's cones, an infinite ray's tail, with the integrand's densities
 * from the models and the optical depths from their closed forms. */
#include "lit_int.h"
#include "gk15.h"
#include "ms.h"
#include "shadow.h"
#include "vmath.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Extinction of component c at x per channel, from its functionals. */
static void sigma_at(const ef_fog_component *c, const double x[3], double out[3])
{
    if (uniform_sigma(c, out))
        return;
    /* (exponential strata take theirs from strata_legs, in plain double;
     * they come here only where its exponents leave +-700) */
    ef_fog_functional fs[64], *f = fs;
    long double vs[64], *v = vs;
    const int n = c->model->functionals(c, NULL, 0);
    if (n > 64) {
        f = malloc((size_t) n * sizeof *f);
        v = malloc((size_t) n * sizeof *v);
        if (!f || !v) {   /* no memory: no light from here (the caller's estimate) */
            free(f);
            free(v);
            out[0] = out[1] = out[2] = 0;
            return;
        }
    }
    c->model->functionals(c, f, n);
    for (int i = 0; i < n; ++i)
        v[i] = (long double) f[i].n[0] * x[0] + (long double) f[i].n[1] * x[1] +
               (long double) f[i].n[2] * x[2] + f[i].d;
    long double o[3];
    c->model->density(c, v, o);
    for (int k = 0; k < 3; ++k)
        out[k] = (double) o[k];
    if (f != fs) {
        free(f);
        free(v);
    }
}

void ef_lit_sigma_at(const ef_fog_scene *s, const double x[3], double out[3])
{
    out[0] = out[1] = out[2] = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        double sg[3];
        sigma_at(&s->comp[i], x, sg);
        for (int k = 0; k < 3; ++k)
            out[k] += sg[k];
    }
}

/* ----------------------------------------------------- the quadrature */

/* An integrand at n nodes u into out[j] per channel. */
typedef void (*lit_fn)(const void *q, const double *u, int n, double (*out)[3]);

typedef struct gk_iv {
    double a, b, r[3], e[3];
    double x[3];   /* the Kronrod rule of the integrand's side values (aux) */
} gk_iv;

/* The Kronrod and Gauss sums of the 15 values v (times h: the rules). */
static void kg_sums(const double (*v)[3], double rk[3], double rg[3])
{
    for (int k = 0; k < 3; ++k) {
        rk[k] = (double) ef_gk15_wk[7] * v[7][k];
        rg[k] = (double) ef_gk15_wg[3] * v[7][k];
    }
    for (int j = 0; j < 7; ++j)
        for (int k = 0; k < 3; ++k) {
            rk[k] += (double) ef_gk15_wk[j] * (v[j][k] + v[14 - j][k]);
            if (j & 1)
                rg[k] += (double) ef_gk15_wg[j / 2] * (v[j][k] + v[14 - j][k]);
        }
}

/* The five-node rule on the Gauss nodes 0, +-xgk[3] and +-xgk[1], exact
 * to degree 5 (w0 + 2 w3 + 2 w1 = 2, 2 w3 x3^2 + 2 w1 x1^2 = 2/3, the
 * same with x^4 = 2/5): against the Gauss rule, the side part's estimate
 * where only the Gauss nodes carry it. */
static const double r5_w[3] = { 0.8550618162163684751, 0.5196089047921329057,
                                0.05286018709968285677 };   /* w0, w3, w1 */

/* One Kronrod rule over [a, b]; e: |Kronrod - Gauss| per channel; the 15
 * values, in node order (fvo[3 i + k]), into fvo when not NULL. With aux
 * (30 rows f fills beside its values: a lamp's multiple scattering in fog
 * that is not uniform, its estimate at each node in rows 0-14 and its
 * part of the value in rows 15-29), e is the rest's alone and x takes the
 * estimate's Kronrod integral plus that part's |K - G|: the table it
 * reads is linear in direction between columns, and a rule held to the
 * single scattering's 1e-10 would chase every column's kink. With
 * side_gauss (and aux), the side part (aux's rows 15-29) is read at
 * the seven Gauss nodes alone (odd j; the integrand leaves it 0 at the
 * others): its integral is the Gauss rule's, its estimate the Gauss
 * estimate's integral plus |Gauss - r5_w's rule|. */
static void gk15_fv(lit_fn f, const void *q, gk_iv *iv, double *fvo, const double (*aux)[3],
                    int side_gauss)
{
    const double c = 0.5 * (iv->a + iv->b), h = 0.5 * (iv->b - iv->a);
    double fv[15][3], u[15], rk[3], rg[3], dv[15][3], dk[3], dg[3];
    u[7] = c;
    for (int j = 0; j < 7; ++j) {
        const double dx = h * (double) ef_gk15_x[j];
        u[j] = c - dx;
        u[14 - j] = c + dx;
    }
    f(q, u, 15, fv);
    kg_sums((const double (*)[3]) fv, rk, rg);
    /* what steers the refinement: the values less the side part */
    const double (*d)[3] = (const double (*)[3]) fv;
    if (aux) {
        for (int j = 0; j < 15; ++j)
            for (int k = 0; k < 3; ++k)
                dv[j][k] = fv[j][k] - aux[15 + j][k];
        kg_sums((const double (*)[3]) dv, dk, dg);
        d = (const double (*)[3]) dv;
    } else {
        memcpy(dk, rk, sizeof dk);
        memcpy(dg, rg, sizeof dg);
    }
    /* QUADPACK's qk15 estimate: |K - G| scaled by (200 |K - G| / resasc)^1.5
     * (resasc: the integral of |f - its mean|), which on a smooth piece
     * tracks the Kronrod rule's own error rather than the Gauss rule's */
    for (int k = 0; k < 3; ++k) {
        const double mean = dk[k] * 0.5;
        double asc = (double) ef_gk15_wk[7] * fabs(d[7][k] - mean);
        for (int j = 0; j < 7; ++j)
            asc += (double) ef_gk15_wk[j] * (fabs(d[j][k] - mean) + fabs(d[14 - j][k] - mean));
        asc *= fabs(h);
        double e = fabs((dk[k] - dg[k]) * h);
        if (asc != 0 && e != 0) {
            const double x = 200 * e / asc;   /* x^1.5 as x sqrt(x): no pow per channel */
            e = asc * fmin(1, x * sqrt(x));
        }
        iv->r[k] = rk[k] * h;
        iv->e[k] = fmax(e, 50 * 0x1p-52 * fabs(iv->r[k]));
    }
    if (fvo)
        memcpy(fvo, fv, sizeof fv);
    if (aux && side_gauss) {
        for (int k = 0; k < 3; ++k) {
            const double (*sv)[3] = aux + 15;
            double g7 = (double) ef_gk15_wg[3] * sv[7][k], x = (double) ef_gk15_wg[3] * aux[7][k];
            for (int j = 1; j < 7; j += 2) {
                g7 += (double) ef_gk15_wg[j / 2] * (sv[j][k] + sv[14 - j][k]);
                x += (double) ef_gk15_wg[j / 2] * (aux[j][k] + aux[14 - j][k]);
            }
            const double r5 = r5_w[0] * sv[7][k] + r5_w[1] * (sv[3][k] + sv[11][k]) +
                              r5_w[2] * (sv[1][k] + sv[13][k]);
            iv->r[k] = (dk[k] + g7) * h;
            iv->x[k] = (x + fabs(g7 - r5)) * fabs(h);
        }
        return;
    }
    for (int k = 0; k < 3; ++k) {
        double x = 0;
        for (int j = 0; aux && j < 15; ++j)
            x += (double) ef_gk15_wk[j < 8 ? j : 14 - j] * aux[j][k];
        if (aux)
            x += fabs((rk[k] - dk[k]) - (rg[k] - dg[k]));
        iv->x[k] = x * fabs(h);
    }
}

static void gk15(lit_fn f, const void *q, gk_iv *iv, const double (*aux)[3])
{
    gk15_fv(f, q, iv, NULL, aux, 0);
}

#define GK_MAX 512

/* A record of an adaptive run's final intervals for the dense output
 * (below): its leaves, and each interval's 15 values while it runs. */
typedef struct dense_rec dense_rec;
static void dense_keep(dense_rec *rec, const gk_iv *iv, int n);
/* The values of interval i (rec's scratch), or NULL without a record. */
static double *rec_fv(dense_rec *rec, int i);

/* Global adaptive Gauss-Kronrod over the pieces [cut[i], cut[i+1]] until
 * the summed error estimate is at most rel of the result plus S in every
 * channel (or GK_MAX intervals): adds the result to S and its estimate to
 * E, and with rec its final intervals as leaves (dense_keep); with aux
 * (gk15_fv's), the final intervals' side integrals to X. */
static void gk_adapt_rec(lit_fn f, const void *q, const double *cut, int ncut, double rel,
                         double S[3], double E[3], dense_rec *rec, const double (*aux)[3],
                         double X[3])
{
    gk_iv iv[GK_MAX];
    int n = 0;
    for (int i = 0; i + 1 < ncut && n < GK_MAX; ++i) {
        if (!(cut[i + 1] > cut[i]))
            continue;
        iv[n].a = cut[i];
        iv[n].b = cut[i + 1];
        gk15_fv(f, q, &iv[n], rec_fv(rec, n), aux, aux && !rec);
        ++n;
    }
    for (;;) {
        double R[3] = { 0, 0, 0 }, Er[3] = { 0, 0, 0 };
        for (int i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k) {
                R[k] += iv[i].r[k];
                Er[k] += iv[i].e[k];
            }
        int done = 1;
        /* relative to what S already holds too: a far piece of a ray
         * whose light was collected before need not resolve its own
         * near-zero to 1e-13 of itself */
        for (int k = 0; k < 3; ++k)
            done &= Er[k] <= rel * fabs(R[k] + S[k]) || !isfinite(R[k]);
        /* the interval of the largest error relative to its channel's total */
        int worst = -1;
        double we = -1;
        for (int i = 0; i < n; ++i) {
            const double m = 0x1p-20 * (iv[i].b - iv[i].a) < 0x1p-52 * fmax(fabs(iv[i].a),
                                                                            fabs(iv[i].b))
                                 ? 0 : 1;   /* too narrow to split further */
            for (int k = 0; k < 3; ++k) {
                const double w = m * iv[i].e[k] / (fabs(R[k] + S[k]) + 1e-300);
                if (w > we) {
                    we = w;
                    worst = i;
                }
            }
        }
        if (done || n + 1 >= GK_MAX || worst < 0 || !(we > 0)) {
            for (int k = 0; k < 3; ++k) {
                S[k] += R[k];
                E[k] += Er[k];
                for (int i = 0; aux && i < n; ++i)
                    X[k] += iv[i].x[k];
            }
            if (rec)
                dense_keep(rec, iv, n);
            return;
        }
        const double a = iv[worst].a, b = iv[worst].b, m = 0.5 * (a + b);
        iv[worst].b = m;
        gk15_fv(f, q, &iv[worst], rec_fv(rec, worst), aux, aux && !rec);
        iv[n].a = m;
        iv[n].b = b;
        gk15_fv(f, q, &iv[n], rec_fv(rec, n), aux, aux && !rec);
        ++n;
    }
}

/* ------------------------------------------------------ the integrands */

/* A component as lamp_v takes it: uniform (rho its extinction),
 * exponential strata (its factor at the camera and at the lamp, e^x0 and
 * e^xl) or a convex volume of constant rho (its planes, and the view
 * ray's stretch inside, [tin, tout]). */
enum { VC_UNIFORM, VC_STRATA, VC_CONVEX };
typedef struct vcomp {
    int kind;
    double rho[3], k, x0, xl, E0, EL, iks, ksv, sv, wu;
    const double *pl;
    int np;
    double tin, tout;
} vcomp;

typedef struct lit_q {
    const ef_fog_scene *s;
    const ef_light *l;
    const ef_ray *r;
    int equi;                 /* 1: u = xi, t = ts + hq tan(xi), E dt = e / hq dxi; 2: the tail v; 0: t (sun) or t - ts (lamp) */
    double ts, hq, h;         /* the lamp's closest approach along the ray, its distances */
    double w[3], wa, va;      /* lamp - camera; w . aim and dir . aim (spots) */
    double W;                 /* xi within W of the closest approach, t beyond */
    double ua, lam;           /* an infinite ray's tail: u = ua + lam v / (1 - v) */
    int uniform;              /* every component uniform: sig per channel */
    double sig[3];
    const vcomp *vc;          /* a lamp whose fog lamp_v takes: its components (else NULL) */
    /* a lamp's multiple scattering in fog that is not uniform (ms.h's
     * local mode: its table read at every node), else NULL; its estimate
     * and its part of the value per node into aux (gk15_fv's 30 rows) */
    const ef_lms *lms;
    int est;                  /* 0: the caller wants no estimate (lms_node skips its reads) */
    int ms_gauss;             /* 1: the side part at a rule's Gauss nodes alone (gk15_fv) */
    double (*aux)[3];
} lit_q;
/* One node's geometry: t along the ray, the substitution's weight, the
 * lamp's distance dl (INFINITY for the sun), the phase's cosine, and a
 * spot's share (1 for other lights; the single scattering's factor, not
 * in the weight) with the cosine from its aim; 0 where the node carries
 * no light (outside a spot's cone unless it scatters multiply). For a lamp,
 * its distance and the phase's angle come from u - ts and the line's
 * distance h (both exact at the closest approach), not from a world point
 * rounded to double, whose rounding (an ulp of the ray's length) would be
 * a large share of d where the lamp is near the ray. */
static int node_geom(const lit_q *q, double u, double *tp, double *wgtp, double *dlp,
                     double *cthp, double *shp, double *cap)
{
    const ef_light *l = q->l;
    const ef_ray *r = q->r;
    double t = u, ur = 0, wgt = 1;
    if (q->equi == 1) {
        ur = q->hq * tan(u);
        t = q->ts + ur;
        wgt = 1 / q->hq;
    } else if (q->equi == 2) {
        if (!(u < 1))
            return 0;
        ur = q->ua + q->lam * u / (1 - u);
        t = q->ts + ur;
        wgt = q->lam / ((1 - u) * (1 - u)) / (ur * ur + q->hq * q->hq);
    } else if (ef_light_at_position(l)) {
        /* a lamp's pieces in t are in u = t - ts: nodes near the lamp
         * keep their full precision */
        ur = u;
        t = q->ts + u;
        wgt = 1 / (ur * ur + q->hq * q->hq);
    }
    if (!(t >= 0))
        t = 0;
    double dl = INFINITY, cth, sh = 1, ca = 1;
    if (!ef_light_at_position(l)) {
        cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
    } else {
        dl = sqrt(ur * ur + q->h * q->h);
        if (!(dl > 0))
            return 0;
        cth = -ur / dl;
        if (ef_light_coned(l)) {
            ca = -(q->wa - t * q->va) / dl;
            sh = ef_spot_share(l, ca);
            /* (a spot's multiple scattering reaches outside its cone) */
            if (sh == 0 && !q->lms)
                return 0;
        }
    }
    *shp = sh;
    *cap = ca;
    *tp = t;
    *wgtp = wgt;
    *dlp = dl;
    *cthp = cth;
    return 1;
}

/* The unit direction from the node at t towards the light (the sun's
 * own; for a lamp from w, lamp - camera), for the models whose optical
 * depth to the light takes a ray. */
static void light_dir(const lit_q *q, double t, double ld[3])
{
    if (!ef_light_at_position(q->l)) {
        memcpy(ld, q->l->dir, 3 * sizeof *ld);
        return;
    }
    double y[3], yn = 0;
    for (int a = 0; a < 3; ++a) {
        y[a] = q->w[a] - t * q->r->dir[a];
        yn += y[a] * y[a];
    }
    const double iy = yn > 0 ? 1 / sqrt(yn) : 0;
    for (int a = 0; a < 3; ++a)
        ld[a] = y[a] * iy;
}

/* Exponential strata (fog.h's strata: rho e^(-k (up.x - base)), k > 0)
 * at the m nodes t[j] of the view ray, in plain double: the density
 * factor E[j] = e^(-k (height - base)), the view's optical depth from the
 * camera added per channel to tv, and (tl not NULL) the light's from the
 * node (a lamp at dl[j]; the sun to infinity) to tl. One expm1 gives a
 * node's density and its view depth (both e^(-k s t) from the camera's
 * height), one more a lamp's depth: rho E dl phi(k dh), phi(c) = (1 -
 * e^-c) / c of either sign, dh the lamp's height over the node's; the
 * sun's is rho E / (k s_l). The model's own optical depths (double-double
 * heights, the saturation's care) cost four times this for nothing the
 * quadrature's 1e-10 can see. A node far above the base (its density
 * factor below e^-700, where sky rays' last nodes lie) keeps this path:
 * there a lamp's leg is rho dl (E - E_lamp) / (k dh) from the lamp's own
 * factor, which stays finite where phi's would overflow. Returns 0
 * (nothing added) where the camera's or the lamp's factor, or a node's
 * below them, leaves e^+-700, for the model to answer. */
static int strata_legs(const ef_fog_component *c, const lit_q *q, const double rho[3], double k,
                       double base, int m, const double *t, const double *dl, double *E,
                       double (*tv)[3], double (*tl)[3])
{
    const ef_ray *r = q->r;
    const ef_light *l = q->l;
    const double *up = c->up;
    const double h0 = up[0] * r->org[0] + up[1] * r->org[1] + up[2] * r->org[2] - base;
    const double sv = up[0] * r->dir[0] + up[1] * r->dir[1] + up[2] * r->dir[2];
    const double x0 = -k * h0;
    const int lamp = ef_light_at_position(l);
    /* the lamp's height over the camera's (w is lamp - camera); the sun's
     * length factor, the same at every node */
    const double wu = up[0] * q->w[0] + up[1] * q->w[1] + up[2] * q->w[2];
    const double sl = up[0] * l->dir[0] + up[1] * l->dir[1] + up[2] * l->dir[2];
    const double lsun = sl > 0 ? 1 / (k * sl) : INFINITY;
    double em[15];
    const double iks = sv != 0 ? -1 / (k * sv) : 0;   /* (a level view: b is 0) */
    const double xl = x0 - k * wu;   /* the lamp's exponent */
    if (!(fabs(x0) < 700) || (lamp && tl && !(fabs(xl) < 700)))
        return 0;
    for (int j = 0; j < m; ++j) {
        const double b = k * sv * t[j];
        if (!(x0 - b < 700) || !(-b < 700))   /* (em would overflow) */
            return 0;
        em[j] = expm1(-b);
    }
    const double E0 = exp(x0), EL = lamp && tl ? exp(xl) : 0;
    for (int j = 0; j < m; ++j) {
        const double b = k * sv * t[j];
        /* 1 + em loses e^b of its digits for b > 0: e^(x0 - b) there */
        E[j] = b > 0.5 ? exp(x0 - b) : E0 * (1 + em[j]);
        const double lv = b == 0 ? t[j] : em[j] * iks;   /* the view's length factor */
        for (int ch = 0; ch < 3; ++ch)
            if (rho[ch] != 0)
                tv[j][ch] += rho[ch] * E0 * lv;
        if (!tl)
            continue;
        double EL_ = lsun * E[j];   /* the light's length factor times E */
        if (lamp) {
            /* E phi(cc), or above the lamp (cc < -1/2) from the lamp's own
             * factor, (E_lamp - E) / -cc: there E phi may overflow, and E
             * underflow where the lamp's leg is still dense (another
             * component's light then crosses it) */
            const double cc = k * (wu - t[j] * sv);
            EL_ = cc == 0 ? dl[j] * E[j]
                  : cc > -0.5 ? dl[j] * E[j] * (-expm1(-cc) / cc)
                              : dl[j] * (EL - E[j]) / (-cc);
        }
        for (int ch = 0; ch < 3; ++ch)
            if (rho[ch] != 0)
                tl[j][ch] += rho[ch] * EL_;
    }
    return 1;
}

/* The phase function at cosines c, four lanes: ef_phase_eval's
 * expressions in its order (the same values but for sqrt's lanes, which
 * are correctly rounded alike). */
EF_INLINE void v_phase(int phase, double g, const v4d *c, v4d *o)
{
    const double pi = 3.14159265358979323846;
    if (phase == EF_PHASE_RAYLEIGH) {
        *o = 3 / (16 * pi) * (1 + *c * *c);
        return;
    }
    if (phase != EF_PHASE_HG && phase != EF_PHASE_CS) {
        const double iso = 1 / (4 * pi);
        *o = (v4d) { iso, iso, iso, iso };
        return;
    }
    const double ag = fabs(g), om = (1 - ag) * (1 - ag);
    v4d ac, qa, qb, qq, sq, d;
    v_abs(c, &ac);
    qa = om + 2 * ag * (1 - ac);
    qb = 1 + g * g - 2 * g * *c;
    const v4di pos = g * *c >= 0;
    v_sel(&qq, &pos, &qa, &qb);
    v_sqrt(&qq, &sq);
    d = qq * sq;
    if (phase == EF_PHASE_HG)
        *o = (1 - g * g) / (4 * pi * d);
    else
        *o = 3 / (8 * pi) * (1 - g * g) * (1 + *c * *c) / ((2 + g * g) * d);
}

/* The stretch [*tin, *tout] of r (t >= 0) inside the np planes pl (fog
 * where A x + B y + C z + D < 0); *tin > *tout where it misses. */
static void convex_span(const double *pl, int np, const ef_ray *r, double *tin, double *tout)
{
    double a = 0, b = INFINITY;
    for (int i = 0; i < np; ++i) {
        const double *P = pl + 4 * i;
        const double h0 = P[0] * r->org[0] + P[1] * r->org[1] + P[2] * r->org[2] + P[3];
        const double sv = P[0] * r->dir[0] + P[1] * r->dir[1] + P[2] * r->dir[2];
        if (sv == 0) {
            if (!(h0 < 0))
                b = -1;
        } else if (sv > 0) {
            b = fmin(b, -h0 / sv);
        } else {
            a = fmax(a, -h0 / sv);
        }
    }
    *tin = a;
    *tout = b;
}

/* Whether every component of s is exponential strata or uniform, with
 * exponents in the range strata_legs keeps: their constants into vc. */
static int lamp_v_comps(const lit_q *q, vcomp *vc)
{
    const ef_fog_scene *s = q->s;
    const ef_ray *r = q->r;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        vcomp *v = &vc[i];
        double base;
        if (uniform_sigma(c, v->rho)) {
            v->kind = VC_UNIFORM;
            continue;
        }
        if (c->model->convex && c->model->convex(c, v->rho, &v->pl, &v->np)) {
            v->kind = VC_CONVEX;
            convex_span(v->pl, v->np, r, &v->tin, &v->tout);
            continue;
        }
        if (!c->model->strata || !c->model->strata(c, v->rho, &v->k, &base))
            return 0;
        const double *up = c->up;
        const double h0 = up[0] * r->org[0] + up[1] * r->org[1] + up[2] * r->org[2] - base;
        v->kind = VC_STRATA;
        v->sv = up[0] * r->dir[0] + up[1] * r->dir[1] + up[2] * r->dir[2];
        v->wu = up[0] * q->w[0] + up[1] * q->w[1] + up[2] * q->w[2];
        v->x0 = -v->k * h0;
        v->xl = v->x0 - v->k * v->wu;
        if (!(fabs(v->x0) < 700) || !(fabs(v->xl) < 700))
            return 0;
        v->E0 = exp(v->x0);
        v->EL = exp(v->xl);
        v->iks = v->sv != 0 ? -1 / (v->k * v->sv) : 0;
        v->ksv = v->k * v->sv;
    }
    return 1;
}

/* A convex volume v at the nodes t of q's ray, four lanes: *in 1 where a
 * node lies inside (else 0), *len the length of the view's leg [0, t] and
 * of the lamp's leg from the node (dl long) inside it, *llen the lamp's
 * alone (plain double: the quadrature cuts at the faces, so no node sits
 * on one). */
EF_INLINE void convex_legs(const lit_q *q, const vcomp *v, const v4d *t, const v4d *dl, v4d *in,
                             v4d *len, v4d *llen)
{
    const ef_ray *r = q->r;
    const v4d zero = { 0, 0, 0, 0 }, one = { 1, 1, 1, 1 };
    /* the view's leg: [max(0, tin), min(t, tout)] */
    v4d hi = *t, lo = { v->tin, v->tin, v->tin, v->tin };
    const v4d tout = { v->tout, v->tout, v->tout, v->tout };
    const v4di past = hi > tout;
    v_sel(&hi, &past, &tout, &hi);
    v4d lv = hi - lo;
    const v4di none = ~(lv > 0.0);
    v_sel(&lv, &none, &zero, &lv);
    /* the lamp's leg x + s (L - x), s in [0, 1]: the planes it enters and
     * leaves by */
    v4d sin = zero, sout = one;
    v4di inside = { -1, -1, -1, -1 }, empty = { 0, 0, 0, 0 };
    for (int i = 0; i < v->np; ++i) {
        const double *P = v->pl + 4 * i;
        const double h0 = P[0] * r->org[0] + P[1] * r->org[1] + P[2] * r->org[2] + P[3];
        const double sv = P[0] * r->dir[0] + P[1] * r->dir[1] + P[2] * r->dir[2];
        const double hl = h0 + P[0] * q->w[0] + P[1] * q->w[1] + P[2] * q->w[2];
        const v4d hx = h0 + sv * *t;
        const v4di xin = hx < 0.0;
        inside &= xin;
        const v4d ss = hx / (hx - hl);
        if (hl < 0) {   /* the lamp inside this plane: entered where x is out */
            v4d m = sin;
            const v4di gt = ss > sin;
            v_sel(&m, &gt, &ss, &sin);
            v_sel(&sin, &xin, &sin, &m);
        } else {        /* the lamp outside: left where x is in, else empty */
            v4d m = sout;
            const v4di lt = ss < sout;
            v_sel(&m, &lt, &ss, &sout);
            v_sel(&sout, &xin, &m, &sout);
            empty |= ~xin;
        }
    }
    v4d ll = sout - sin;
    const v4di no = empty | ~(ll > 0.0);
    v_sel(&ll, &no, &zero, &ll);
    *llen = ll * *dl;
    *len = lv + *llen;
    v_sel(in, &inside, &one, &zero);
}

/* A lamp's multiple scattering at one node in fog that is not uniform
 * (q->lms, ms.h's local mode), per channel: the view's optical depth tv to
 * the node, the lamp's tl from it, the extinction there sg, the lamp's
 * distance d and the cosine nu (the phase's: the light leaving towards
 * the camera against the outward radial), wgt the substitution's weight
 * (1 / d^2 and the Jacobian), x the node. Its value into v and its
 * estimate into e, both attenuated to the camera; a channel like the one
 * before it (grey fog) copies it. ex: the leak
 * term's exposure per channel, read here where ex[3] is 0 (the caller
 * clears it every four nodes). */
static void lms_node(const lit_q *q, const double x[3], const double tv[3], const double tl[3],
                     const double sg[3], double d, double nu, double ca, double wgt, double v[3],
                     double e[3], double ex[4])
{
    /* the leak term's exposure, once per four nodes (at the first of them:
     * it is smooth over a rule's span); ex[3] 0 asks for it */
    if (!ex[3] && q->est) {
        for (int k = 0; k < 3; ++k)
            ex[k] = k > 0 && sg[k] == sg[k - 1] ? ex[k - 1] : ef_lms_leak_exposure(q->lms, x, k, sg[k]);
        ex[3] = 1;
    }
    const ef_light *l = q->l;
    for (int k = 0; k < 3; ++k) {
        if (k > 0 && tv[k] == tv[k - 1] && tl[k] == tl[k - 1] && sg[k] == sg[k - 1] &&
            l->e[k] == l->e[k - 1] && ef_lms_same_table(q->lms, k, k - 1)) {
            v[k] = v[k - 1];
            e[k] = e[k - 1];
            continue;
        }
        v[k] = e[k] = 0;
        if (!(sg[k] > 0) || !(tv[k] < 708) || l->e[k] == 0)
            continue;
        double est = 0;
        const double f = ef_lms_local_node(q->lms, k, tl[k], sg[k], d, nu, ca, x, ex[k],
                                           q->est ? &est : NULL);
        /* (e^-tv as lms_pack takes it, so a value read here is the same
         * bits as one read four at a time) */
        const v4d mt = { -tv[k], 0, 0, 0 };
        v4d et;
        v_exp(&mt, &et);
        const double w = et[0] * wgt * l->e[k];
        v[k] = f * w;
        e[k] = est * w;
    }
}

/* The nodes of one lamp_v call that take a lamp's multiple scattering
 * (the value alone), gathered over its groups of four so that the table's
 * places go four at a time: each node's index j, t, the lamp's distance,
 * the phase's cosine, a spot's ca, the weight, and per channel the optical
 * depth (view and lamp), the lamp's leg and the extinction. */
typedef struct lms_pk {
    int n, j[16];
    double t[16], dl[16], cth[16], ca[16], wgt[16], tau[3][16], tl[3][16], sg[3][16];
} lms_pk;

/* lms_node's values (no estimate) at pk's nodes, four at a time: each
 * added to out and kept in aux's rows 15-29 (the part that does not steer
 * the refinement; its estimate rows stay 0). */
EF_INLINE void lms_pack(const lit_q *q, const lms_pk *pk, double (*out)[3])
{
    const ef_light *l = q->l;
    for (int p = 0; p < pk->n; p += 4) {
        double x[4][3], D[4], N[4], A[4], mv[3][4];
        int live[4];
        for (int i = 0; i < 4; ++i) {
            const int a = p + i < pk->n ? p + i : p;
            live[i] = p + i < pk->n;
            for (int k = 0; k < 3; ++k)
                x[i][k] = q->r->org[k] + pk->t[a] * q->r->dir[k];
            D[i] = pk->dl[a];
            N[i] = pk->cth[a];
            A[i] = pk->ca[a];
        }
        for (int k = 0; k < 3; ++k) {
            /* a channel like the one before it (grey fog) copies it */
            int same = k > 0 && l->e[k] == l->e[k - 1] && ef_lms_same_table(q->lms, k, k - 1);
            for (int i = 0; same && i < 4 && p + i < pk->n; ++i)
                same = pk->tau[k][p + i] == pk->tau[k - 1][p + i] &&
                       pk->tl[k][p + i] == pk->tl[k - 1][p + i] &&
                       pk->sg[k][p + i] == pk->sg[k - 1][p + i];
            if (same) {
                memcpy(mv[k], mv[k - 1], sizeof mv[k]);
                continue;
            }
            double TL[4], SG[4], F[4];
            v4d mt;
            for (int i = 0; i < 4; ++i) {
                const int a = p + i < pk->n ? p + i : p;
                const double tv = pk->tau[k][a] - pk->tl[k][a];
                const int on = live[i] && pk->sg[k][a] > 0 && tv < 708 && l->e[k] != 0;
                TL[i] = pk->tl[k][a];
                SG[i] = on ? pk->sg[k][a] : 0;
                mt[i] = on ? -tv : 0;
            }
            ef_lms_local_node4(q->lms, k, TL, SG, D, N, A, (const double (*)[3]) x, F);
            v4d et;
            v_exp(&mt, &et);
            for (int i = 0; i < 4; ++i)
                mv[k][i] = SG[i] > 0 ? F[i] * (et[i] * pk->wgt[p + i < pk->n ? p + i : p] * l->e[k])
                                     : 0;
        }
        for (int i = 0; i < 4 && p + i < pk->n; ++i)
            for (int k = 0; k < 3; ++k) {
                out[pk->j[p + i]][k] += mv[k][i];
                q->aux[15 + pk->j[p + i]][k] = mv[k][i];
            }
    }
}

/* lit_integrand for a lamp in fog whose components are all exponential
 * strata, uniform or convex volumes (most lit fog), four nodes at a time
 * on vectors: node_geom, strata_legs' legs (a uniform component's are its
 * extinction times the lengths, a volume's its density times the lengths
 * inside) and the transmittance, with vmath.h's tan, expm1 and
 * exp for libm's (a few ulp apart, far below the quadrature's 1e-10).
 * Returns 0 where a node's exponent leaves the range strata_legs keeps;
 * the scalar path then answers (it writes every node again). */
EF_MULTIVERSION static int lamp_v(const lit_q *q, const vcomp *vc, const double *u, int n,
                                  double (*out)[3])
{
    const ef_fog_scene *s = q->s;
    const ef_light *l = q->l;
    const int coned = ef_light_coned(l);
    const v4d m708 = { -708, -708, -708, -708 }, zero = { 0, 0, 0, 0 };
    double ex[4];   /* lms_node's exposure, once per four nodes */
    lms_pk pk;
    pk.n = 0;
    for (int g = 0; g * 4 < n; ++g) {
        ex[3] = 0;
        v4d U;
        for (int i = 0; i < 4; ++i)
            U[i] = u[4 * g + i < n ? 4 * g + i : 4 * g];
        /* the node's place, the lamp's distance and the phase's cosine */
        v4d ur = U, t, wgt;
        v4di dd = { 0, 0, 0, 0 };
        if (q->equi == 1) {
            v4d tn;
            v_tan(&U, &tn);
            ur = q->hq * tn;
            const double iw = 1 / q->hq;
            wgt = (v4d) { iw, iw, iw, iw };
        } else if (q->equi == 2) {
            dd = ~(U < 1.0);
            const v4d um = 1.0 - U;
            ur = q->ua + q->lam * U / um;
            wgt = q->lam / (um * um) / (ur * ur + q->hq * q->hq);
        } else {
            wgt = 1 / (ur * ur + q->hq * q->hq);
        }
        t = q->ts + ur;
        const v4di neg = ~(t >= 0.0);
        v_sel(&t, &neg, &zero, &t);
        v4d dl;
        const v4d d2 = ur * ur + q->h * q->h;
        v_sqrt(&d2, &dl);
        dd |= ~(dl > 0.0);
        const v4d cth = -ur / dl;
        /* a spot's share (sh) and cosine from its aim (ca); its multiple
         * scattering reaches outside the cone */
        v4d sh = { 1, 1, 1, 1 }, ca = sh;
        if (coned)
            for (int i = 0; i < 4; ++i)
                if (!dd[i]) {
                    ca[i] = -(q->wa - t[i] * q->va) / dl[i];
                    sh[i] = ef_spot_share(l, ca[i]);
                    dd[i] = sh[i] == 0 && !q->lms ? -1 : 0;
                }
        for (int i = 0; q->aux && i < 4 && 4 * g + i < n; ++i)
            for (int k = 0; k < 3; ++k)
                q->aux[4 * g + i][k] = q->aux[15 + 4 * g + i][k] = 0;
        if (dd[0] && dd[1] && dd[2] && dd[3]) {   /* (outside a spot's cone) */
            for (int i = 0; i < 4 && 4 * g + i < n; ++i)
                out[4 * g + i][0] = out[4 * g + i][1] = out[4 * g + i][2] = 0;
            continue;
        }
        /* per component: the scattering, the view's and the lamp's legs
         * (the lamp's and the extinction apart for a lamp's multiple
         * scattering) */
        v4d acc[3] = { zero, zero, zero }, tau[3] = { zero, zero, zero };
        v4d tlv[3] = { zero, zero, zero }, sgv[3] = { zero, zero, zero };
        for (int i = 0; i < s->ncomp; ++i) {
            const ef_fog_component *c = &s->comp[i];
            const vcomp *v = &vc[i];
            v4d p;
            v_phase(c->phase, c->g, &cth, &p);
            if (v->kind == VC_UNIFORM) {
                for (int ch = 0; ch < 3; ++ch)
                    if (v->rho[ch] > 0) {
                        acc[ch] += v->rho[ch] * albedo(c, ch) * p;
                        tau[ch] += v->rho[ch] * t + v->rho[ch] * dl;
                        tlv[ch] += v->rho[ch] * dl;
                        sgv[ch] += v->rho[ch];
                    }
                continue;
            }
            if (v->kind == VC_CONVEX) {
                v4d in, len, llen;
                convex_legs(q, v, &t, &dl, &in, &len, &llen);
                for (int ch = 0; ch < 3; ++ch)
                    if (v->rho[ch] > 0) {
                        acc[ch] += v->rho[ch] * albedo(c, ch) * p * in;
                        tau[ch] += v->rho[ch] * len;
                        tlv[ch] += v->rho[ch] * llen;
                        sgv[ch] += v->rho[ch] * in;
                    }
                continue;
            }
            const v4d b = v->ksv * t, mb = -b;
            const v4di off = ~(v->x0 - b < 700.0) | ~(mb < 700.0);
            for (int k = 0; k < 4; ++k)
                if (off[k] && !dd[k])
                    return 0;
            v4d em, xb = v->x0 - b, eb;
            v_expm1(&mb, &em);
            /* the density factor: past b = 1/2, e^(x0 - b) (1 + em loses
             * digits there); below e^-708, 0 */
            v4d E = v->E0 * (1 + em);
            const v4di under = xb < -708.0, bpos = b > 0.5;
            if (v_any(&bpos)) {
                v_sel(&xb, &under, &m708, &xb);
                v_exp(&xb, &eb);
                v_sel(&eb, &under, &zero, &eb);
                v_sel(&E, &bpos, &eb, &E);
            }
            v4d lv = em * v->iks;   /* the view's length factor */
            const v4di b0 = b == 0.0;
            v_sel(&lv, &b0, &t, &lv);
            /* the lamp's leg times E: E phi(cc), or above the lamp
             * (E_lamp - E) / -cc (strata_legs) */
            const v4d cc = v->k * (v->wu - t * v->sv), mc = -cc;
            v4d ec;
            v_expm1(&mc, &ec);
            v4d le = dl * E * (-ec / cc);
            const v4d far = dl * (v->EL - E) / mc, dE = dl * E;
            const v4di isfar = ~(cc > -0.5), c0 = cc == 0.0;
            v_sel(&le, &isfar, &far, &le);
            v_sel(&le, &c0, &dE, &le);
            for (int ch = 0; ch < 3; ++ch)
                if (v->rho[ch] != 0) {
                    acc[ch] += v->rho[ch] * E * albedo(c, ch) * p;
                    tau[ch] += v->rho[ch] * v->E0 * lv + v->rho[ch] * le;
                    tlv[ch] += v->rho[ch] * le;
                    sgv[ch] += v->rho[ch] * E;
                }
        }
        v4d et = zero;
        v4di gone = { 0, 0, 0, 0 };
        for (int ch = 0; ch < 3; ++ch) {
            if (ch == 0 || tau[ch][0] != tau[ch - 1][0] || tau[ch][1] != tau[ch - 1][1] ||
                tau[ch][2] != tau[ch - 1][2] || tau[ch][3] != tau[ch - 1][3]) {
                /* e^-tau (0 past 708, where the light is gone anyway);
                 * grey fog's channels share it */
                v4d mt = -tau[ch];
                gone = ~(tau[ch] <= 708.0);
                v_sel(&mt, &gone, &m708, &mt);
                v_exp(&mt, &et);
            }
            const v4d o = acc[ch] * et * wgt * sh * l->e[ch];
            for (int i = 0; i < 4 && 4 * g + i < n; ++i)
                out[4 * g + i][ch] = dd[i] || gone[i] || acc[ch][i] == 0 ? 0 : o[i];
        }
        for (int i = 0; q->lms && !q->est && i < 4 && 4 * g + i < n; ++i) {
            /* (the value alone: gathered for lms_pack below) */
            const int j = 4 * g + i;
            if (dd[i] || (q->ms_gauss && !(j & 1)))
                continue;
            const int a = pk.n++;
            pk.j[a] = j;
            pk.t[a] = t[i];
            pk.dl[a] = dl[i];
            pk.cth[a] = cth[i];
            pk.ca[a] = ca[i];
            pk.wgt[a] = wgt[i];
            for (int ch = 0; ch < 3; ++ch) {
                pk.tau[ch][a] = tau[ch][i];
                pk.tl[ch][a] = tlv[ch][i];
                pk.sg[ch][a] = sgv[ch][i];
            }
        }
        for (int i = 0; q->lms && q->est && i < 4 && 4 * g + i < n; ++i) {
            if (dd[i] || (q->ms_gauss && !((4 * g + i) & 1)))
                continue;
            double tv[3], tl[3], sg[3], mv[3], me[3];
            for (int ch = 0; ch < 3; ++ch) {
                tv[ch] = tau[ch][i] - tlv[ch][i];
                tl[ch] = tlv[ch][i];
                sg[ch] = sgv[ch][i];
            }
            const double xi[3] = { q->r->org[0] + t[i] * q->r->dir[0],
                                   q->r->org[1] + t[i] * q->r->dir[1],
                                   q->r->org[2] + t[i] * q->r->dir[2] };
            lms_node(q, xi, tv, tl, sg, dl[i], cth[i], ca[i], wgt[i], mv, me, ex);
            for (int ch = 0; ch < 3; ++ch) {
                out[4 * g + i][ch] += mv[ch];
                q->aux[4 * g + i][ch] = me[ch];
                q->aux[15 + 4 * g + i][ch] = mv[ch];
            }
        }
    }
    if (pk.n)
        lms_pack(q, &pk, out);
    return 1;
}

/* The integrand at the n <= 15 nodes u (t or xi), light included, into
 * out. The general fog's optical depths come a rule's nodes at a time:
 * strata from strata_legs, other models from ef_fog_tau_add (the view's
 * along one ray to every node, the light's from every node); a planet
 * sun's light leg from ef_lit_sun_planet_tau alone. */
static void lit_integrand(const void *qv, const double *u, int n, double (*out)[3])
{
    const lit_q *q = qv;
    const ef_light *l = q->l;
    const ef_ray *r = q->r;
    const ef_fog_scene *s = q->s;
    if (q->vc && lamp_v(q, q->vc, u, n, out))
        return;   /* a lamp in height, uniform and convex fog, most lit fog */
    double tn[15], wgt[15], dl[15], cth[15], sh[15], ca[15];
    int live[15], m = 0;
    for (int j = 0; j < n; ++j) {
        out[j][0] = out[j][1] = out[j][2] = 0;
        if (q->aux)
            for (int k = 0; k < 3; ++k)
                q->aux[j][k] = q->aux[15 + j][k] = 0;
        if (!node_geom(q, u[j], &tn[m], &wgt[m], &dl[m], &cth[m], &sh[m], &ca[m]))
            continue;
        if (q->uniform && !q->lms) {
            /* T(0,t) T_l = e^-(sig (t + d)); one phase per component, one
             * exponential per distinct density */
            const double t = tn[m], d = dl[m];
            double a[3] = { 0, 0, 0 };
            for (int i = 0; i < s->ncomp; ++i) {
                const ef_fog_component *c = &s->comp[i];
                const double p = ef_phase_eval(c->phase, c->g, cth[m]);
                double sg[3];
                uniform_sigma(c, sg);
                for (int k = 0; k < 3; ++k)
                    if (sg[k] > 0)
                        a[k] += sg[k] * albedo(c, k) * p;
            }
            double e[3];
            e[0] = exp(-q->sig[0] * (t + d));
            e[1] = q->sig[1] == q->sig[0] ? e[0] : exp(-q->sig[1] * (t + d));
            e[2] = q->sig[2] == q->sig[0] ? e[0] : exp(-q->sig[2] * (t + d));
            /* the transmittance first: where it is 0 a dense fog's sigma
             * times a near lamp's weight may overflow, and inf * 0 is no
             * answer */
            for (int k = 0; k < 3; ++k)
                out[j][k] =
                    q->sig[k] == 0 || e[k] == 0 ? 0 : a[k] * e[k] * wgt[m] * sh[m] * l->e[k];
            continue;
        }
        live[m++] = j;
    }
    if (m == 0)
        return;
    /* per node: the scattering (acc), the view's and the light's optical
     * depths, component by component */
    const int planet = !ef_light_at_position(l) && l->planet > 0;
    double acc[15][3], tv[15][3], tl[15][3], x[15][3], sgt[15][3];
    double ex[4] = { 0, 0, 0, 0 };   /* lms_node's exposure, once per four nodes */
    memset(acc, 0, sizeof acc[0] * (size_t) m);
    memset(sgt, 0, sizeof sgt[0] * (size_t) m);
    memset(tv, 0, sizeof tv[0] * (size_t) m);
    memset(tl, 0, sizeof tl[0] * (size_t) m);
    for (int j = 0; j < m; ++j)
        for (int a = 0; a < 3; ++a)
            x[j][a] = r->org[a] + tn[j] * r->dir[a];
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double rho[3], k, base, E[15];
        if (c->model->strata && c->model->strata(c, rho, &k, &base) &&
            strata_legs(c, q, rho, k, base, m, tn, dl, E, tv, planet ? NULL : tl)) {
            for (int j = 0; j < m; ++j) {
                const double p = ef_phase_eval(c->phase, c->g, cth[j]);
                for (int ch = 0; ch < 3; ++ch) {
                    acc[j][ch] += rho[ch] == 0 ? 0 : rho[ch] * E[j] * albedo(c, ch) * p;
                    sgt[j][ch] += rho[ch] == 0 ? 0 : rho[ch] * E[j];
                }
            }
            continue;
        }
        ef_ray vr[15], lr[15];
        for (int j = 0; j < m; ++j) {
            double sg[3];
            sigma_at(c, x[j], sg);
            if (sg[0] != 0 || sg[1] != 0 || sg[2] != 0) {
                const double p = ef_phase_eval(c->phase, c->g, cth[j]);
                for (int ch = 0; ch < 3; ++ch) {
                    acc[j][ch] += sg[ch] == 0 ? 0 : sg[ch] * albedo(c, ch) * p;
                    sgt[j][ch] += sg[ch];
                }
            }
            vr[j] = (ef_ray) { { r->dir[0], r->dir[1], r->dir[2] }, tn[j], tn[j],
                               { r->org[0], r->org[1], r->org[2] } };
            if (!planet) {
                double ld[3];
                light_dir(q, tn[j], ld);
                lr[j] = (ef_ray) { { ld[0], ld[1], ld[2] }, dl[j], dl[j],
                                   { x[j][0], x[j][1], x[j][2] } };
            }
        }
        ef_fog_tau_add(c, vr, m, tv);
        if (!planet)
            ef_fog_tau_add(c, lr, m, tl);
    }
    for (int j = 0; j < m; ++j) {
        if (acc[j][0] == 0 && acc[j][1] == 0 && acc[j][2] == 0)
            continue;
        if (planet)
            ef_lit_sun_planet_tau(s, l, x[j], tl[j]);
        /* where either leg is opaque the density may have overflowed too:
         * no light, not inf * 0 */
        double tau[3], e[3];
        for (int k = 0; k < 3; ++k)
            tau[k] = tv[j][k] + tl[j][k];
        e[0] = exp(-tau[0]);
        e[1] = tau[1] == tau[0] ? e[0] : exp(-tau[1]);
        e[2] = tau[2] == tau[0] ? e[0] : exp(-tau[2]);
        for (int k = 0; k < 3; ++k)
            out[live[j]][k] =
                acc[j][k] == 0 || e[k] == 0 ? 0 : acc[j][k] * e[k] * wgt[j] * sh[j] * l->e[k];
        if (q->lms && j % 4 == 0)
            ex[3] = 0;
        if (q->lms && !(q->ms_gauss && !(live[j] & 1))) {
            double mv[3], me[3];
            lms_node(q, x[j], tv[j], tl[j], sgt[j], dl[j], cth[j], ca[j], wgt[j], mv, me, ex);
            for (int k = 0; k < 3; ++k) {
                out[live[j]][k] += mv[k];
                q->aux[live[j]][k] = me[k];
                q->aux[15 + live[j]][k] = mv[k];
            }
        }
    }
}

/* ----------------------------------------------- the dense output */

struct dense_rec {
    ef_lit_dense *d;
    const lit_q *q;
    double w;                 /* the visibility the leaves are weighted by */
};

static double *rec_fv(dense_rec *rec, int i)
{
    if (!rec || rec->d->failed)
        return NULL;
    ef_lit_dense *d = rec->d;
    if (d->fvcap < GK_MAX) {
        double *fv = realloc(d->fv, (size_t) GK_MAX * 45 * sizeof *fv);
        if (!fv) {
            d->failed = 2;
            return NULL;
        }
        d->fv = fv;
        d->fvcap = GK_MAX;
    }
    return d->fv + (size_t) i * 45;
}

/* t at u of a leaf (lit_integrand's mappings; mode 3: u = t). */
static double leaf_t(const ef_lit_leaf *f, double u)
{
    switch (f->mode) {
    case 1:
        return f->ts + f->hq * tan(u);
    case 2:
        return u >= 1 ? INFINITY : f->ts + f->ua + f->lam * u / (1 - u);
    case 0:
        return f->ts + u;
    default:
        return u;
    }
}

/* q[i][n]: node i's part in the y^n coefficient of a leaf's
 * antiderivative. The integrand's Legendre series has coefficients
 * c_m = (2m + 1) / 2 sum_i w_i f_i P_m(y_i) over the 15 Kronrod nodes; its
 * integral from -1 to y is sum_m c_m I_m(y), I_0 = y + 1 and
 * I_m = (P_{m+1} - P_{m-1}) / (2m + 1), written here in powers of y (the
 * series converges on every kept leaf, so its high terms are small and
 * the powers' larger coefficients cost no digits that matter: test_light's
 * dense tests hold it to the segment quadrature). */
static void dense_node_weights(double q[15][EF_LIT_DENSE_NA])
{
    /* Legendre's polynomials P_0 .. P_NC in powers of y */
    double P[EF_LIT_DENSE_NC + 1][EF_LIT_DENSE_NA] = { { 0 } };
    P[0][0] = 1;
    P[1][1] = 1;
    for (int m = 1; m < EF_LIT_DENSE_NC; ++m)
        for (int n = 0; n < EF_LIT_DENSE_NA; ++n)
            P[m + 1][n] = (n > 0 ? lg_A[m] * P[m][n - 1] : 0) - lg_B[m] * P[m - 1][n];
    double I[EF_LIT_DENSE_NC][EF_LIT_DENSE_NA] = { { 0 } };
    I[0][0] = I[0][1] = 1;
    for (int m = 1; m < EF_LIT_DENSE_NC; ++m)
        for (int n = 0; n < EF_LIT_DENSE_NA; ++n)
            I[m][n] = (P[m + 1][n] - P[m - 1][n]) * lg_I[m];
    double y[15], W[15];
    for (int j = 0; j < 7; ++j) {
        y[j] = -(double) ef_gk15_x[j];
        y[14 - j] = (double) ef_gk15_x[j];
        W[j] = W[14 - j] = (double) ef_gk15_wk[j];
    }
    y[7] = 0;
    W[7] = (double) ef_gk15_wk[7];
    for (int i = 0; i < 15; ++i) {
        /* w_i (2m + 1) / 2 P_m(y_i), by the recurrence */
        double pm[EF_LIT_DENSE_NC], p0 = 1, p1 = y[i];
        pm[0] = 0.5 * W[i];
        for (int m = 1; m < EF_LIT_DENSE_NC; ++m) {
            pm[m] = p1 * 0.5 * W[i] / lg_I[m];
            const double pn = lg_A[m] * y[i] * p1 - lg_B[m] * p0;
            p0 = p1;
            p1 = pn;
        }
        for (int n = 0; n < EF_LIT_DENSE_NA; ++n) {
            double v = 0;
            for (int m = 0; m < EF_LIT_DENSE_NC; ++m)
                v += pm[m] * I[m][n];
            q[i][n] = v;
        }
    }
}

/* Appends an adaptive run's final intervals to the record as leaves, in
 * order along the ray, each with its integrand's integral from the leaf's
 * start as a polynomial in y (dense_node_weights). */
static void dense_keep(dense_rec *rec, const gk_iv *iv, int n)
{
    ef_lit_dense *d = rec->d;
    if (d->failed || n <= 0)
        return;
    if (d->n + n > d->cap) {
        const int cap = d->n + n > 2 * d->cap ? d->n + n : 2 * d->cap;
        ef_lit_leaf *l = realloc(d->leaf, (size_t) cap * sizeof *l);
        if (!l) {
            d->failed = 2;
            return;
        }
        d->leaf = l;
        d->cap = cap;
    }
    /* sort by start, carrying each interval's values */
    int ord[GK_MAX];
    for (int i = 0; i < n; ++i)
        ord[i] = i;
    for (int i = 1; i < n; ++i)   /* insertion: runs are short and nearly sorted */
        for (int j = i; j > 0 && iv[ord[j - 1]].a > iv[ord[j]].a; --j) {
            const int t = ord[j];
            ord[j] = ord[j - 1];
            ord[j - 1] = t;
        }
    const lit_q *q = rec->q;
    const int mode = q->equi == 1 ? 1 : q->equi == 2 ? 2 : ef_light_at_position(q->l) ? 0 : 3;
    if (!d->qready)
        dense_node_weights(d->q);
    d->qready = 1;
    for (int o = 0; o < n; ++o) {
        const gk_iv *v = &iv[ord[o]];
        const double *fv = d->fv + (size_t) ord[o] * 45;
        ef_lit_leaf *f = &d->leaf[d->n++];
        f->u0 = v->a;
        f->u1 = v->b;
        f->mode = mode;
        f->ts = q->ts;
        f->hq = q->hq;
        f->ua = q->ua;
        f->lam = q->lam;
        f->t0 = leaf_t(f, v->a);
        f->t1 = leaf_t(f, v->b);
        for (int k = 0; k < 3; ++k) {
            f->r[k] = rec->w * v->r[k];
            f->e[k] = rec->w * v->e[k];
            for (int m = 0; m < EF_LIT_DENSE_NA; ++m) {
                double c = 0;
                for (int i = 0; i < 15; ++i)
                    c += fv[3 * i + k] * d->q[i][m];
                f->c[k][m] = rec->w * c;
            }
        }
        f->grey = !memcmp(f->c[0], f->c[1], sizeof f->c[0]) &&
                  !memcmp(f->c[0], f->c[2], sizeof f->c[0]);
    }
}

/* Where the view segment [0, D) crosses the components' features (the
 * density's jumps, kinks and fronts), appended to cut. */
int ef_lit_feature_cuts(const ef_fog_scene *s, const ef_ray *r, double a, double D, double *cut,
                        int n)
{
    for (int i = 0; i < s->ncomp && n < MAX_CUTS - 8; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->features || !c->model->functionals)
            continue;
        const int nf = c->model->functionals(c, NULL, 0), nt = c->model->features(c, NULL, 0);
        if (nf <= 0 || nt <= 0 || nf > 256 || nt > 256)
            continue;
        ef_fog_functional f[256];
        ef_fog_feature ft[256];
        c->model->functionals(c, f, nf);
        c->model->features(c, ft, nt);
        for (int j = 0; j < nt && n < MAX_CUTS - 8; ++j) {
            const ef_fog_functional *F = &f[ft[j].f];
            const double v0 = F->n[0] * r->org[0] + F->n[1] * r->org[1] + F->n[2] * r->org[2] + F->d;
            const double rate = F->n[0] * r->dir[0] + F->n[1] * r->dir[1] + F->n[2] * r->dir[2];
            const double t = (ft[j].value - v0) / rate;
            if (t > a && t < D)
                cut[n++] = t;
        }
    }
    return n;
}

/* Cuts at ts +- st 4^j inside (a, D), from st until past the segment. */
int ef_lit_steps_around(double *cut, int n, double ts, double a, double D, double st)
{
    for (; n < MAX_CUTS - 4; st *= 4) {
        if (ts + st > a && ts + st < D)
            cut[n++] = ts + st;
        if (ts - st > a && ts - st < D)
            cut[n++] = ts - st;
        if (!(st < 1e300) || st > fabs(ts) + (isfinite(D) ? D : 0))
            break;
    }
    return n;
}

/* Where the ray crosses the spot's cones cos alpha = c (c = its edge, and
 * its blend band's inner edge), appended to cut. */
int ef_lit_cone_cuts(const ef_light *l, const ef_ray *r, double a, double D, double *cut, int n)
{
    double w[3];
    for (int a = 0; a < 3; ++a)
        w[a] = r->org[a] - l->pos[a];   /* y(t) = w + t v, from the lamp */
    const double a0 = w[0] * l->dir[0] + w[1] * l->dir[1] + w[2] * l->dir[2];
    const double a1 = r->dir[0] * l->dir[0] + r->dir[1] * l->dir[1] + r->dir[2] * l->dir[2];
    const double ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    const double wv = w[0] * r->dir[0] + w[1] * r->dir[1] + w[2] * r->dir[2];
    const double cs[2] = { l->cos_outer, l->cos_outer + l->smooth };
    for (int i = 0; i < 2; ++i) {
        const double c = cs[i], c2 = c * c;
        /* (a0 + a1 t)^2 = c^2 |w + t v|^2 */
        const double A = a1 * a1 - c2, B = 2 * (a0 * a1 - c2 * wv), C = a0 * a0 - c2 * ww;
        double roots[2];
        int nr = 0;
        if (fabs(A) > 1e-300) {
            const double disc = B * B - 4 * A * C;
            if (disc >= 0) {
                const double sq = sqrt(disc), qq = -0.5 * (B + (B >= 0 ? sq : -sq));
                roots[nr++] = qq / A;
                if (qq != 0)
                    roots[nr++] = C / qq;
            }
        } else if (B != 0) {
            roots[nr++] = -C / B;
        }
        for (int j = 0; j < nr; ++j)
            if (roots[j] > a && roots[j] < D && (a0 + a1 * roots[j]) * c >= 0 && n < MAX_CUTS)
                cut[n++] = roots[j];
    }
    return n;
}

/* Relative accuracy aimed at: the uniform fog's integrand costs a few
 * exponentials, the general one optical depths along two rays per node. */
#define REL_UNIFORM 1e-13
#define REL_GENERAL 1e-10

/* The general quadrature of light l over [a, D] of r into S and E (what
 * inscatter_range leaves to it: no rough component, no sun closed form):
 * the pieces between the features, a lamp's closest approach and cones,
 * in t or in the lamp's angle, with a point lamp in uniform isotropic fog
 * by its closed form first. */
static void quad_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                       double D, double S[3], double E[3], ef_lit_dense *dense, double vis,
                       double rel_in, int est)
{
    lit_q q = { .s = s, .l = l, .r = r, .uniform = 1, .est = est };
    vcomp vc[EF_FOG_MAX_COMPONENTS];
    double aux[30][3], X[3] = { 0, 0, 0 };
    if (ef_lms_is_local(l->lms) && ef_light_at_position(l)) {
        q.lms = l->lms;
        q.aux = aux;
        /* (a dense output keeps every node's value: gk_adapt_rec) */
        q.ms_gauss = !dense;
    }
    dense_rec rec_ = { dense, &q, vis }, *rec = dense ? &rec_ : NULL;
    for (int i = 0; i < s->ncomp; ++i) {
        double sg[3];
        if (!uniform_sigma(&s->comp[i], sg)) {
            q.uniform = 0;
            continue;
        }
        for (int k = 0; k < 3; ++k)
            q.sig[k] += sg[k];
    }
    double cut[MAX_CUTS];
    int n = 0;
    cut[n++] = a;
    if (!q.uniform)
        n = ef_lit_feature_cuts(s, r, a, D, cut, n);
    if (ef_light_coned(l))
        n = ef_lit_cone_cuts(l, r, a, D, cut, n);
    if (ef_light_at_position(l)) {
        /* the lamp's closest approach along the line, and its distance
         * there from the cross product (no cancellation near the line) */
        double *w = q.w;
        ef_lit_lamp_line(l, r, w, &q.ts, &q.h);
        q.wa = w[0] * l->dir[0] + w[1] * l->dir[1] + w[2] * l->dir[2];
        q.va = r->dir[0] * l->dir[0] + r->dir[1] * l->dir[1] + r->dir[2] * l->dir[2];
        q.hq = ef_lit_len2(q.h, l->radius);
        if (!(q.hq <= DBL_MAX / 64) || !isfinite(q.ts))
            return;   /* a lamp beyond 1e306 units: e / d^2 is no light at all */
        /* the components' constants for the vector integrand, once per ray */
        if (lamp_v_comps(&q, vc))
            q.vc = vc;
        if (q.hq == 0) {
            if (q.ts >= a && q.ts <= D) {
                /* a lamp of radius 0 on the segment: its 1/d^2 does not
                 * integrate */
                for (int k = 0; k < 3; ++k)
                    if (l->e[k] > 0 && (q.uniform ? q.sig[k] > 0 : 1))
                        S[k] = INFINITY;
                return;
            }
            /* on the line beyond an end: the substitution's hq from a
             * billionth of its least distance, which changes 1/d^2 by
             * (hq / d)^2 <= 1e-18 */
            q.hq = 1e-9 * (q.ts < a ? a - q.ts : q.ts - D);
        }
        int iso = 1;
        for (int i = 0; i < s->ncomp; ++i)
            iso &= s->comp[i].phase == EF_PHASE_ISO;
        if (!rec && !q.lms && (ef_light_at_position(l) && !ef_light_coned(l)) && q.uniform && iso &&
            l->radius == 0 && q.h > 0) {
            double sig[3], scat[3];
            ef_lit_lamp_medium(s, sig, scat);
            if (ef_lit_lamp_closed(sig, scat, l->e, q.ts, q.h, a, D, S, E) == 0)
                return;
            /* The two ends cancelled: a segment short beside its distance
             * from the lamp, where the integrand is smooth in t. One
             * Kronrod rule in u = t - ts, kept where its estimate meets
             * the closed form's 1e-13 (else the pieces below). */
            if (isfinite(D)) {
                gk_iv iv = { .a = a - q.ts, .b = D - q.ts };
                gk15(lit_integrand, &q, &iv, NULL);
                int ok = 1;
                for (int k = 0; k < 3; ++k)
                    ok &= iv.e[k] <= REL_UNIFORM * fabs(iv.r[k]) && isfinite(iv.r[k]);
                if (ok) {
                    for (int k = 0; k < 3; ++k) {
                        S[k] += iv.r[k];
                        E[k] += iv.e[k];
                    }
                    return;
                }
            }
        }
        q.equi = 1;
        /* Within W of the closest approach the substitution makes 1/d^2
         * flat; past it, t - ts itself, in pieces of geometric length (a
         * xi crowded against +-pi/2 would lose the pieces to rounding).
         * The closest approach itself is a cut (where h is 0 the phase
         * jumps there); where the radius is far wider than the line's
         * distance h, the phase still turns from forward to back over ~h:
         * geometric steps from h inside W too. */
        const double W = 64 * q.hq;
        if (q.ts > a && q.ts < D)
            cut[n++] = q.ts;
        const double h0 = q.h < q.hq / 16 ? fmax(q.h, 1e-6 * q.hq) : W;
        n = ef_lit_steps_around(cut, n, q.ts, a, D, h0);
        if (h0 < W)
            n = ef_lit_steps_around(cut, n, q.ts, a, D, W);
        q.W = W;
    }
    if (isfinite(D))
        cut[n++] = D;
    const double rel = rel_in > 0 ? rel_in : q.uniform ? REL_UNIFORM : REL_GENERAL;
    const double rel_general = rel_in > 0 ? rel_in : REL_GENERAL;
    if (q.equi) {
        /* pieces within W of the lamp in xi = atan((t - ts) / hq), the
         * others in u = t - ts; an infinite ray's last piece in v, u =
         * ua + lam v / (1 - v), lam its start's distance from the lamp */
        qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
        const double W = q.W;
        double run[MAX_CUTS];
        for (int i = 0; i + 1 < n;) {
            const int in = cut[i] >= q.ts - W && cut[i + 1] <= q.ts + W;
            int m = 0, j = i;
            run[m++] = in ? atan((cut[i] - q.ts) / q.hq) : cut[i] - q.ts;
            for (; j + 1 < n; ++j) {
                if ((cut[j] >= q.ts - W && cut[j + 1] <= q.ts + W) != in)
                    break;
                run[m++] = in ? atan((cut[j + 1] - q.ts) / q.hq) : cut[j + 1] - q.ts;
            }
            q.equi = in;
            gk_adapt_rec(lit_integrand, &q, run, m, rel, S, E, rec, q.aux, X);
            i = j;
        }
        if (!isfinite(D)) {
            q.equi = 2;
            q.ua = cut[n - 1] - q.ts;
            q.lam = fmax(fabs(q.ua), q.hq);
            const double v[2] = { 0, 1 };
            gk_adapt_rec(lit_integrand, &q, v, 2, rel, S, E, rec, q.aux, X);
        }
    } else if (isfinite(D)) {
        qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
        gk_adapt_rec(lit_integrand, &q, cut, n, rel, S, E, rec, q.aux, X);
    } else {
        /* The sun on an infinite ray: pieces doubling in length past the
         * last cut until what is left is below the tolerance: its integral
         * is at most max(albedo p) E T(0,t) (1 - T(t,inf)) per channel,
         * which joins the error estimate. */
        qsort(cut, (size_t) n, sizeof cut[0], cmp_double);
        gk_adapt_rec(lit_integrand, &q, cut, n, rel_general, S, E, rec, q.aux, X);
        const double cth = l->dir[0] * r->dir[0] + l->dir[1] * r->dir[1] + l->dir[2] * r->dir[2];
        double pmax = 0;
        for (int i = 0; i < s->ncomp; ++i)
            pmax = fmax(pmax, ef_phase_eval(s->comp[i].phase, s->comp[i].g, cth));
        double ta = cut[n - 1], len = fmax(ta, 1.0);
        for (int it = 0; it < 2100; ++it) {
            double x[3], tv[3], tr[3], tail[3];
            for (int k = 0; k < 3; ++k)
                x[k] = r->org[k] + ta * r->dir[k];
            ef_lit_tau_from(s, r->org, r->dir, ta, tv);
            ef_lit_tau_from(s, x, r->dir, INFINITY, tr);
            int done = 1;
            for (int k = 0; k < 3; ++k) {
                tail[k] = pmax * l->e[k] * exp(-tv[k]) * -expm1(-tr[k]);
                done &= !(tail[k] > rel_general * fabs(S[k])) || tail[k] < 1e-300;
            }
            if (done || !(ta + len < 1e300)) {
                for (int k = 0; k < 3; ++k)
                    E[k] += tail[k] > 0 ? tail[k] : 0;
                break;
            }
            const double piece[2] = { ta, ta + len };
            gk_adapt_rec(lit_integrand, &q, piece, 2, rel_general, S, E, rec, q.aux, X);
            ta += len;
            len *= 2;
        }
    }
    /* the multiple scattering's estimate in fog that is not uniform: the
     * segment's error; a dense output keeps the whole ray's apart */
    for (int k = 0; k < 3; ++k) {
        E[k] += X[k];
        if (dense)
            dense->aux[k] += vis * X[k];
    }
}

void ef_lit_quad_range(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                       double D, double rel, double S[3], double E[3])
{
    /* without E, the estimates' sums go to a scratch the caller never sees */
    double Es[3] = { 0, 0, 0 };
    quad_range(s, l, r, a, D, S, E ? E : Es, NULL, 1, rel, E != NULL);
}

void ef_lit_quad_range_dense(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double a,
                             double D, double w, double rel, ef_lit_dense *d)
{
    double S[3] = { 0, 0, 0 }, E[3] = { 0, 0, 0 };
    quad_range(s, l, r, a, D, S, E, d, w, rel, 1);
    /* a lamp on the segment itself (inf) has no leaves to hold it */
    for (int k = 0; k < 3; ++k)
        if (!isfinite(S[k]) && !d->failed)
            d->failed = 1;
}
