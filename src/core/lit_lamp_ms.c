/* Multiple scattering of a point lamp in uniform fog (ms.h's ef_lms): the
 * spherically symmetric problem about the lamp, solved once per albedo and
 * phase in optical units, and gathered along each view ray.
 *
 * In optical units (extinction 1) a lamp of intensity 1 lights the fog
 * with E_0 = e^-r / r^2; its first scattering is exrfog's single
 * scattering. What is solved here is Q, the source of the second and later
 * orders per unit volume and solid angle at distance r from the lamp and
 * propagation direction of cosine nu from the outward radial. By symmetry
 * Q depends on (r, nu) alone:
 *
 *   psi_n(r, nu) = int_0^inf e^-s Q_n(r'(s), nu'(s)) ds     (order n radiance)
 *   Q_{n+1}     = omega int p psi_n dOmega'                  (Legendre moments)
 *
 * along the backward ray from the point; with s = s_c + h sinh w about the
 * ray's closest approach to the lamp (s_c = r nu, h = r sin beta) the
 * distance is r' = h cosh w, the cosine nu' = -tanh w and ds = r' dw, so
 * the integrand r' Q is what the table holds (finite at the lamp, where Q
 * grows as 1 / r). psi_1 comes from E_0 by adaptive quadrature in the
 * angle about the closest approach (no table); the orders from 2 on are
 * one linear system in the Legendre moments of the radiance, solved by
 * GMRES. Physical units: extinction sigma scales Q by sigma^3 and the
 * gather by sigma^2. Pure C, no I/O. */
#include "ms.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gk15.h"
#include "lit_int.h"
#include "vmath.h"

/* |g| above this: the phase's Legendre series needs more than LMS_L_MAX
 * terms (0.9^128 = 1.4e-6). */
#define LMS_G_MAX 0.9
/* Albedo above this: in unbounded fog light that is hardly absorbed
 * wanders without end (at 1 the scattered energy has no bound and the
 * solve does not converge; 0.999 takes 600 GMRES iterations). */
#define LMS_ALBEDO_MAX 0.999
#define LMS_L_MAX 128
/* The radial grid: r = RS (e^(u lg) - 1), u uniform on [0, 1]. */
#define LMS_RS 0.05
/* How far (optical depth) a characteristic or a view ray is followed:
 * e^-40 of it is left. */
#define LMS_REACH 40.0
/* GMRES: restart length, and the residual it stops at (relative to the
 * right-hand side). */
#define LMS_KRYLOV 60
/* The planes where the fog drops that the leak estimate reads, at most
 * (ef_lms_local_node); and its weight at albedo 0.9, calibrated against
 * Cycles on bench/ms_lamp_box.sh's three calib scenes (two boxes and a
 * half-space: every block covered on each; 0.9 leaves 1 % of one). */
#define LEAK_MAX 64
#define LEAK_C 1.0
/* E_2 tabulated over [0, LEAK_E2_X] for the leak estimate (linear between
 * points: within 3e-3 at one step from 0, where its second derivative
 * e^-x / x is largest) */
#define LEAK_E2_N 2048
#define LEAK_E2_X 40.0
/* Gauss-Legendre nodes of the mean over a piece of layered profile */
#define PROF_NG 8
#define LMS_GMRES_TOL 1e-9

/* One resolution of the solve. */
typedef struct lms_res {
    int nr;      /* radial nodes */
    int npp;     /* direction nodes per panel */
    int nw;      /* nodes per characteristic piece */
    int nx;      /* table directions (x = sin(beta / 2) uniform) */
    double rmax; /* the domain's radius (vacuum beyond) */
} lms_res;

typedef struct lms_tab {
    double omega;
    int phase, max_order;
    double g;
    int nr, nx;
    double lg, rmax;
    double *q;       /* [nr][nx]: r Q(r, x) of orders 2 and up */
    double *e;       /* [nr][nx]: its error estimate */
    double resid;    /* GMRES's relative residual */
    int iters;
    /* a spot's (ef_lms_spot): the cone's share averaged over where the
     * light reaching a point first scattered, and its estimate, against
     * the optical distance and the angle from the axis ([SPOT_NR][SPOT_NA]) */
    double *fb, *fbe, spot_u;
    double *qb;      /* [nr][2]: r Q's mean over directions (both columns) */
    /* the lamp's images (lamp_images): r Q's mean over directions at
     * optical distance rmax (i / (IMG_N - 1))^2, linear between */
    double *im;
} lms_tab;

/* A layered profile along h = n.x + d: its knots, the density per
 * channel at each (linear between, constant beyond the ends), and per
 * knot i the knot of the least density over i and above (up) and over i
 * and below (dn). */
typedef struct lms_prof {
    double n[3], d;
    int nk;
    double *h, *den[3];
    int *up[3], *dn[3];
    void *mem;   /* one block holding the arrays */
} lms_prof;

struct ef_lms {
    _Atomic int refs;
    /* 1: fog that is not uniform; the table is read at each node of the
     * lit quadrature with the optical distance from the lamp
     * (ef_lms_local_node), and the gathers below add nothing */
    int local;
    int ntab, tab_of[3];
    lms_tab tab[3];
    double sig[3];   /* extinction per channel */
    double scale[3]; /* e_k sigma_k^2: the gather's factor per channel */
    double pos[3];
    int L;
    ef_ms_info info;
    /* a spot (ef_lms_spot): its aim and cone, for the share (light.h) */
    int spot, scaled;   /* scaled: the fog is not uniform */
    ef_light cone;
    /* where a component's density drops at a plane (ef_lms_local_node's
     * leak): the plane n.x + d = 0 (n unit), the component's density on
     * its negative and positive sides near it, and the component (a
     * convex volume's planes: a node outside any of them is not in it);
     * nleak < 0: more than LEAK_MAX, every node fully exposed */
    int nleak;
    double leak[LEAK_MAX][4], dneg[LEAK_MAX][3], dpos[LEAK_MAX][3];
    /* per plane: where its component's planes end (a component's are
     * consecutive), and whether it is a convex volume's */
    int leak_end[LEAK_MAX], leak_convex[LEAK_MAX];
    double lamp_leak[3];   /* the lamp's own exposure per channel */
    /* the lamp's images across those planes (lamp_images): per channel its
     * place beyond the extrapolated boundary and the drop's share */
    int nimg;
    double imx[3][LEAK_MAX], imy[3][LEAK_MAX], imz[3][LEAK_MAX], ims[3][LEAK_MAX];
    double leak_w[3];      /* the leak term's weight per channel (LEAK_C and the albedo's) */
    /* exponential strata (height fog): where the fog thins, e-fold by
     * e-fold, along up (its density rho e^-(k (up.x - base))) */
    int nstrata, strata_only;   /* strata_only: they are the fog's one component */
    /* layered profiles (a component of one functional whose features are
     * kinks: layered fog), where the fog thins along them up or down */
    int nprof;
    struct lms_prof *prof;
    double st_up[EF_FOG_MAX_COMPONENTS][3], st_rho[EF_FOG_MAX_COMPONENTS][3];
    double st_k[EF_FOG_MAX_COMPONENTS], st_base[EF_FOG_MAX_COMPONENTS];
    float e2[LEAK_E2_N + 1];   /* E_2 at LEAK_E2_X j / LEAK_E2_N (linear between) */
    double glx[PROF_NG], glw[PROF_NG];   /* prof_walk's nodes on [0, 1] (weights sum to 1) */
};

/* ------------------------------------------------------------ the grids */

/* The radius of node i of nr on the grid of growth lg (node 0: the lamp). */
static double rho_at(double lg, int nr, int i)
{
    return LMS_RS * expm1(lg * i / (nr - 1));
}

/* Directions of the moments' quadrature: panels in beta, finer towards
 * beta = 0 where psi_1 peaks as 1 / beta (its weight sin beta takes that
 * out). beta, and weight 2 pi sin(beta) dbeta. */
static const double lms_panel[] = { 0, 0.01, 0.05, 0.2, 0.6, 1.4, PI };
#define LMS_NPANEL 6

/* npp Gauss nodes on each panel: angles into beta, weights into W. */
static void beta_nodes(int npp, double *beta, double *W)
{
    double x[256], w[256];
    ef_ms_directions(npp, x, w);
    for (int p = 0; p < LMS_NPANEL; ++p) {
        const double a = lms_panel[p], b = lms_panel[p + 1];
        for (int j = 0; j < npp; ++j) {
            const double be = a + (b - a) * x[j];
            beta[p * npp + j] = be;
            W[p * npp + j] = 2 * PI * (b - a) * w[j] * sin(be);
        }
    }
}

/* --------------------------------------------- the first order, exactly */

/* An integrand of the Kronrod rule below: its value at x, and into *e a
 * second function integrated alongside (an estimate's). */
typedef double (*gk_fn)(const void *q, double x, double *e);

/* One Kronrod rule over [a, b]: the integral into R, |K - G| into E and
 * the second function's integral into X. */
static void gk15_rule(gk_fn f, const void *q, double a, double b, double *R, double *E, double *X)
{
    const double c = 0.5 * (a + b), hw = 0.5 * (b - a);
    double ec;
    const double fc = f(q, c, &ec);
    double rk = (double) ef_gk15_wk[7] * fc, rg = (double) ef_gk15_wg[3] * fc,
           xk = (double) ef_gk15_wk[7] * ec;
    for (int j = 0; j < 7; ++j) {
        const double dx = hw * (double) ef_gk15_x[j];
        double e1, e2;
        const double f1 = f(q, c - dx, &e1), f2 = f(q, c + dx, &e2);
        rk += (double) ef_gk15_wk[j] * (f1 + f2);
        xk += (double) ef_gk15_wk[j] * (e1 + e2);
        if (j & 1)
            rg += (double) ef_gk15_wg[j / 2] * (f1 + f2);
    }
    *R = rk * hw;
    *E = fabs((rk - rg) * hw);
    *X = xk * hw;
}

typedef struct p1_q {
    int phase;
    double g, sc, h;
} p1_q;

/* e^-s p(-sin th) e^-(h / cos th), s = sc + h tan th (gk_fn; no second
 * function) */
static double p1_f(const void *qv, double th, double *e)
{
    const p1_q *q = qv;
    *e = 0;
    const double c = cos(th);
    if (!(c > 0))
        return 0;
    const double s = q->sc + q->h * tan(th), rp = q->h / c;
    return exp(-s - rp) * ef_phase_eval(q->phase, q->g, -sin(th));
}

/* int f over the pieces [cut[i], cut[i+1]] (nc cuts) by global adaptive
 * Gauss-Kronrod, the worst piece bisected until the summed |K - G| is at
 * most rel of the result (or NI pieces); the second function's integral
 * plus that estimate into *e. */
static double gk15_adapt(gk_fn f, const void *q, const double *cut, int nc, double rel, double *e)
{
    enum { NI = 200 };
    double A[NI], B[NI], R[NI], E[NI], X[NI];
    int n = 0;
    for (int i = 0; i + 1 < nc; ++i, ++n) {
        A[n] = cut[i];
        B[n] = cut[i + 1];
        gk15_rule(f, q, A[n], B[n], &R[n], &E[n], &X[n]);
    }
    double tot, et, xt;
    for (;;) {
        tot = et = xt = 0;
        int worst = 0;
        for (int k = 0; k < n; ++k) {
            tot += R[k];
            et += E[k];
            xt += X[k];
            if (E[k] > E[worst])
                worst = k;
        }
        if (et <= rel * fabs(tot) || n >= NI)
            break;
        const double mid = 0.5 * (A[worst] + B[worst]);
        A[n] = mid;
        B[n] = B[worst];
        B[worst] = mid;
        gk15_rule(f, q, A[worst], B[worst], &R[worst], &E[worst], &X[worst]);
        gk15_rule(f, q, A[n], B[n], &R[n], &E[n], &X[n]);
        ++n;
    }
    *e = xt + et;
    return tot;
}

/* psi_1(r, beta) / omega: the once-scattered radiance of a lamp of
 * intensity 1 at distance r, looking back at angle beta from the lamp's
 * direction (propagation cosine nu = cos beta from the outward radial),
 * to about 1e-10 (adaptive Gauss-Kronrod in the angle about the closest
 * approach, where ds / r'^2 = dth / h). */
static double psi1(int phase, double g, double r, double beta)
{
    p1_q q = { phase, g, r * cos(beta), r * sin(beta) };
    if (!(q.h > 0))
        q.h = 1e-300;
    const double ta = atan2(-q.sc, q.h), tb = atan2(LMS_REACH - q.sc, q.h);
    /* the closest approach and the forward peak's side apart */
    double cut[3] = { ta, tb, tb };
    int nc = 2;
    if (ta < 0 && tb > 0) {
        cut[1] = 0;
        nc = 3;
    }
    double e;
    return gk15_adapt(p1_f, &q, cut, nc, 1e-10, &e) / q.h;
}

/* ------------------------------------------------------------ the solve */

/* A characteristic's sample: the table corner (r index * nx + x index) it
 * interpolates from, its fractions, and its weight. */
typedef struct lms_smp {
    int at;          /* the first of four rows' corner */
    float fx;        /* the fraction towards the next direction */
    float wr[4];     /* the rows' weights (cubic in u) */
    double wt;
} lms_smp;

typedef struct lms_sys {
    int nr, nb, nx, L;
    double lg, rmax, omega;
    double *beta, *W;
    double *Pm;      /* [L][nb]: W_j P_l(cos beta_j) (the moments) */
    double *Ps;      /* [L][nx]: c_l P_l(nu_k) (the synthesis) */
    lms_smp *smp;
    int *first;      /* [nr * nb + 1]: each point's samples */
    double *tq, *psi;/* scratch: table [nr][nx], radiance [nr][nb] */
} lms_sys;

/* Frees what sys_init allocated (any of it may be NULL). */
static void sys_free(lms_sys *S)
{
    free(S->beta);
    free(S->W);
    free(S->Pm);
    free(S->Ps);
    free(S->smp);
    free(S->first);
    free(S->tq);
    free(S->psi);
    memset(S, 0, sizeof *S);
}

/* The four radial rows (from *row0) and their weights for grid position u
 * in [0, nr - 1]: Lagrange's cubic through four rows about u (r Q is smooth
 * in u; the linear interpolation's error on the log grid was 3 % of the
 * scattered energy at 72 rows). */
EF_INLINE void rows4(double u, int nr, int *row0, double w[4])
{
    int r0 = (int) u - 1;
    if (r0 < 0)
        r0 = 0;
    if (r0 > nr - 4)
        r0 = nr - 4;
    /* (products by 1/6 and 1/2, not quotients: every node of a lamp's
     * quadrature comes here, and a division's latency was most of it) */
    const double t = u - r0, a = t - 1, b = t - 2, c = t - 3;
    w[0] = -(a * b * c) * (1.0 / 6);
    w[1] = t * b * c * 0.5;
    w[2] = -(t * a * c) * 0.5;
    w[3] = t * a * b * (1.0 / 6);
    *row0 = r0;
}

/* tab_col's column and fraction from its grid position x = sqrt(...)
 * (nx - 1). */
EF_INLINE void tab_col_at(int nx, double x, int *k, double *fx)
{
    *k = (int) x;
    if (*k > nx - 2)
        *k = nx - 2;
    *fx = x - *k;
}

/* The table's direction column k and the fraction fx towards k + 1 for
 * cosine nu (x = sin(beta / 2) uniform over nx columns). */
static void tab_col(int nx, double nu, int *k, double *fx)
{
    tab_col_at(nx, sqrt(fmax(0, fmin(1, 0.5 * (1 - nu)))) * (nx - 1), k, fx);
}

/* The rows about optical distance r and their cubic weights (rows4);
 * 0 past rmax (the table's value is 0 there). */
static int tab_rows(int nr, double lg, double r, int *r0, double w[4])
{
    const double u = log1p(r * (1 / LMS_RS)) * ((nr - 1) / lg);
    if (!(u <= nr - 1))
        return 0;
    rows4(u, nr, r0, w);
    return 1;
}

/* tab_row's sum over rows r0 to r0 + 3 with weights w. */
EF_INLINE double tab_sum(const double *tq, int nx, int r0, const double w[4], int k, double fx,
                      double *ev, const double *te)
{
    double v = 0, e = 0;
    for (int j = 0; j < 4; ++j) {
        const size_t a = (size_t) (r0 + j) * nx + k;
        v += w[j] * ((1 - fx) * tq[a] + fx * tq[a + 1]);
        if (ev)
            e += w[j] * ((1 - fx) * te[a] + fx * te[a + 1]);
    }
    if (ev)
        *ev = fabs(e);
    return v;
}

/* Table value r Q at radius r in column (k, fx), cubic in the radial
 * position; with ev, te's the same way (its absolute value); 0 past
 * rmax. */
static double tab_row(const double *tq, int nr, int nx, double lg, double r, int k, double fx,
                      double *ev, const double *te)
{
    if (ev)
        *ev = 0;
    double w[4];
    int r0;
    if (!tab_rows(nr, lg, r, &r0, w))
        return 0;
    return tab_sum(tq, nx, r0, w, k, fx, ev, te);
}

/* Table value r Q at (r, nu), cubic in the radial position and linear in
 * direction; 0 past rmax. */
static double tab_at(const double *tq, int nr, int nx, double lg, double r, double nu, double *ev,
                     const double *te)
{
    int k;
    double fx;
    tab_col(nx, nu, &k, &fx);
    return tab_row(tq, nr, nx, lg, r, k, fx, ev, te);
}

/* The samples of every characteristic (they depend on the grids alone). */
static int build_samples(lms_sys *S, int nw)
{
    double x[64], w[64];
    ef_ms_directions(nw, x, w);
    const size_t npts = (size_t) S->nr * S->nb;
    S->first = malloc((npts + 1) * sizeof *S->first);
    S->smp = malloc(npts * 2 * (size_t) nw * sizeof *S->smp);
    if (!S->first || !S->smp)
        return -1;
    size_t m = 0;
    for (int i = 0; i < S->nr; ++i)
        for (int j = 0; j < S->nb; ++j) {
            S->first[(size_t) i * S->nb + j] = (int) m;
            const double r = rho_at(S->lg, S->nr, i);
            if (i == 0)
                continue;   /* the lamp's own point: no moments there */
            const double sc = r * cos(S->beta[j]), h = fmax(r * sin(S->beta[j]), 1e-300);
            /* s in [0, REACH]: its part before the closest approach and
             * the part after (either may be empty) */
            double wl[2], wh[2];
            int np = 0;
            if (sc > 0) {
                wl[np] = asinh(-sc / h);
                wh[np++] = sc < LMS_REACH ? 0 : asinh((LMS_REACH - sc) / h);
            }
            if (sc < LMS_REACH) {
                wl[np] = sc > 0 ? 0 : asinh(-sc / h);
                wh[np++] = asinh((LMS_REACH - sc) / h);
            }
            for (int p = 0; p < np; ++p)
                for (int q = 0; q < nw; ++q) {
                    const double ww = wl[p] + (wh[p] - wl[p]) * x[q];
                    const double sh = sinh(ww), ch = cosh(ww);
                    const double s = sc + h * sh, rp = h * ch, nu = -tanh(ww);
                    double u = log1p(rp / LMS_RS) / S->lg * (S->nr - 1);
                    if (!(u <= S->nr - 1) || !(s >= 0))
                        continue;
                    double xx = sqrt(fmax(0, fmin(1, 0.5 * (1 - nu)))) * (S->nx - 1), wr[4];
                    int ix = (int) xx, r0;
                    if (ix > S->nx - 2)
                        ix = S->nx - 2;
                    rows4(u, S->nr, &r0, wr);
                    lms_smp *sm = &S->smp[m++];
                    sm->at = r0 * S->nx + ix;
                    sm->fx = (float) (xx - ix);
                    for (int j = 0; j < 4; ++j)
                        sm->wr[j] = (float) wr[j];
                    sm->wt = (wh[p] - wl[p]) * w[q] * exp(-s);
                }
        }
    S->first[npts] = (int) m;
    return 0;
}

/* The grids, the moment and synthesis matrices and every characteristic's
 * samples of one resolution. Returns 0, or -1 without memory (sys_free
 * then). */
static int sys_init(lms_sys *S, double omega, const double *b, int L, const lms_res *res)
{
    memset(S, 0, sizeof *S);
    S->nr = res->nr;
    S->nb = LMS_NPANEL * res->npp;
    S->nx = res->nx;
    S->L = L;
    S->omega = omega;
    S->rmax = res->rmax;
    S->lg = log1p(res->rmax / LMS_RS);
    S->beta = malloc((size_t) S->nb * sizeof *S->beta);
    S->W = malloc((size_t) S->nb * sizeof *S->W);
    S->Pm = malloc((size_t) L * S->nb * sizeof *S->Pm);
    S->Ps = malloc((size_t) L * S->nx * sizeof *S->Ps);
    S->tq = malloc((size_t) S->nr * S->nx * sizeof *S->tq);
    S->psi = malloc((size_t) S->nr * S->nb * sizeof *S->psi);
    if (!S->beta || !S->W || !S->Pm || !S->Ps || !S->tq || !S->psi)
        return -1;
    beta_nodes(res->npp, S->beta, S->W);
    double P[LMS_L_MAX];
    for (int j = 0; j < S->nb; ++j) {
        ef_ms_legendre(L, cos(S->beta[j]), P);
        for (int l = 0; l < L; ++l)
            S->Pm[(size_t) l * S->nb + j] = S->W[j] * P[l];
    }
    for (int k = 0; k < S->nx; ++k) {
        const double x = (double) k / (S->nx - 1), nu = 1 - 2 * x * x;
        ef_ms_legendre(L, nu, P);
        for (int l = 0; l < L; ++l)
            S->Ps[(size_t) l * S->nx + k] = omega * (2 * l + 1) * b[l] / (4 * PI) * P[l];
    }
    return build_samples(S, res->nw);
}

/* The table r Q from radiance moments m ([L][nr]) into tq; with at_lamp,
 * row 0 (r = 0) takes row 1's value (the second order's r Q tends to a
 * finite limit there), else 0 (the later orders' Q is finite there). */
static void synth(const lms_sys *S, const double *m, double *tq, int at_lamp)
{
    for (int i = 1; i < S->nr; ++i) {
        const double r = rho_at(S->lg, S->nr, i);
        double *row = tq + (size_t) i * S->nx;
        for (int k = 0; k < S->nx; ++k)
            row[k] = 0;
        for (int l = 0; l < S->L; ++l) {
            const double c = r * m[(size_t) l * S->nr + i];
            const double *ps = S->Ps + (size_t) l * S->nx;
            for (int k = 0; k < S->nx; ++k)
                row[k] += c * ps[k];
        }
    }
    if (at_lamp)
        memcpy(tq, tq + S->nx, (size_t) S->nx * sizeof *tq);
    else
        memset(tq, 0, (size_t) S->nx * sizeof *tq);
}

/* Radiance moments m' of the radiance that the source Q = synth(m) sends
 * to every grid point: one order of scattering. */
static void apply_A(const lms_sys *S, const double *m, double *out, int at_lamp)
{
    synth(S, m, S->tq, at_lamp);
    const int nx = S->nx;
    for (int p = 0; p < S->nr * S->nb; ++p) {
        double acc = 0;
        for (int t = S->first[p]; t < S->first[p + 1]; ++t) {
            const lms_smp *sm = &S->smp[t];
            const double *a = S->tq + sm->at;
            const double fx = sm->fx;
            double v = 0;
            for (int j = 0; j < 4; ++j, a += nx)
                v += sm->wr[j] * ((1 - fx) * a[0] + fx * a[1]);
            acc += sm->wt * v;
        }
        S->psi[p] = acc;
    }
    for (int l = 0; l < S->L; ++l)
        for (int i = 0; i < S->nr; ++i) {
            double acc = 0;
            const double *pm = S->Pm + (size_t) l * S->nb, *ps = S->psi + (size_t) i * S->nb;
            for (int j = 0; j < S->nb; ++j)
                acc += pm[j] * ps[j];
            out[(size_t) l * S->nr + i] = i ? acc : 0;
        }
}

/* D A D^-1 z into out: A on moments scaled by each radial node's share of
 * the scattered energy (r^2 dr/du), so that the residual GMRES drives
 * down weighs the far field, where most of the light of the high orders
 * is, as much as the near (unscaled, a residual of 1e-7 left the total
 * 2 % short at albedo 0.99). */
static void apply_B(const lms_sys *S, const double *d, const double *z, double *tmp, double *out)
{
    const size_t n = (size_t) S->L * S->nr;
    for (size_t i = 0; i < n; ++i)
        tmp[i] = z[i] / d[i % (size_t) S->nr];
    apply_A(S, tmp, out, 0);
    for (size_t i = 0; i < n; ++i)
        out[i] *= d[i % (size_t) S->nr];
}

/* Solves (I - A) y = rhs by restarted GMRES (modified Gram-Schmidt) in
 * the energy-scaled unknowns; returns the final relative residual there
 * (its iterations into *its), or -1 without memory. */
static double gmres(const lms_sys *S, const double *rhs_in, double *y, int *its)
{
    const size_t n = (size_t) S->L * S->nr;
    double *d = malloc((size_t) S->nr * sizeof *d), *rhs = malloc(n * sizeof *rhs),
           *tmp = malloc(n * sizeof *tmp);
    if (!d || !rhs || !tmp) {
        free(d);
        free(rhs);
        free(tmp);
        return -1;
    }
    for (int i = 0; i < S->nr; ++i) {
        const double r = rho_at(S->lg, S->nr, i > 0 ? i : 1);
        d[i] = r * r * (r + LMS_RS);
    }
    for (size_t i = 0; i < n; ++i)
        rhs[i] = rhs_in[i] * d[i % (size_t) S->nr];
    const int M = LMS_KRYLOV;
    double *V = malloc((size_t) (M + 1) * n * sizeof *V), *w = malloc(n * sizeof *w);
    double H[LMS_KRYLOV + 1][LMS_KRYLOV], cs[LMS_KRYLOV], sn[LMS_KRYLOV], gv[LMS_KRYLOV + 1];
    if (!V || !w) {
        free(V);
        free(w);
        free(d);
        free(rhs);
        free(tmp);
        return -1;
    }
    double bn = 0;
    for (size_t i = 0; i < n; ++i)
        bn += rhs[i] * rhs[i];
    bn = sqrt(bn);
    memset(y, 0, n * sizeof *y);
    *its = 0;
    double rel = bn > 0 ? 1 : 0;
    for (int restart = 0; restart < 20 && rel > LMS_GMRES_TOL; ++restart) {
        /* r = rhs - (y - A y) */
        apply_B(S, d, y, tmp, w);
        double rn = 0;
        for (size_t i = 0; i < n; ++i) {
            V[i] = rhs[i] - y[i] + w[i];
            rn += V[i] * V[i];
        }
        rn = sqrt(rn);
        if (!(rn > 0)) {
            rel = 0;
            break;
        }
        for (size_t i = 0; i < n; ++i)
            V[i] /= rn;
        gv[0] = rn;
        int k = 0;
        for (; k < M; ++k) {
            double *vk = V + (size_t) k * n, *vn = V + (size_t) (k + 1) * n;
            apply_B(S, d, vk, tmp, w);
            ++*its;
            for (size_t i = 0; i < n; ++i)
                vn[i] = vk[i] - w[i];
            for (int j = 0; j <= k; ++j) {
                const double *vj = V + (size_t) j * n;
                double d = 0;
                for (size_t i = 0; i < n; ++i)
                    d += vj[i] * vn[i];
                H[j][k] = d;
                for (size_t i = 0; i < n; ++i)
                    vn[i] -= d * vj[i];
            }
            double hn = 0;
            for (size_t i = 0; i < n; ++i)
                hn += vn[i] * vn[i];
            hn = sqrt(hn);
            H[k + 1][k] = hn;
            if (hn > 0)
                for (size_t i = 0; i < n; ++i)
                    vn[i] /= hn;
            for (int j = 0; j < k; ++j) {
                const double t = cs[j] * H[j][k] + sn[j] * H[j + 1][k];
                H[j + 1][k] = -sn[j] * H[j][k] + cs[j] * H[j + 1][k];
                H[j][k] = t;
            }
            const double d = hypot(H[k][k], H[k + 1][k]);
            cs[k] = H[k][k] / d;
            sn[k] = H[k + 1][k] / d;
            H[k][k] = d;
            H[k + 1][k] = 0;
            gv[k + 1] = -sn[k] * gv[k];
            gv[k] = cs[k] * gv[k];
            rel = fabs(gv[k + 1]) / bn;
            if (rel <= LMS_GMRES_TOL || !(hn > 0)) {
                ++k;
                break;
            }
        }
        /* y += V z, H z = g */
        double z[LMS_KRYLOV];
        for (int j = k - 1; j >= 0; --j) {
            double t = gv[j];
            for (int c = j + 1; c < k; ++c)
                t -= H[j][c] * z[c];
            z[j] = t / H[j][j];
        }
        for (int j = 0; j < k; ++j) {
            const double *vj = V + (size_t) j * n;
            for (size_t i = 0; i < n; ++i)
                y[i] += z[j] * vj[i];
        }
    }
    for (size_t i = 0; i < n; ++i)
        y[i] /= d[i % (size_t) S->nr];
    free(V);
    free(w);
    free(d);
    free(rhs);
    free(tmp);
    return rel;
}

/* One solve at resolution res: the table r Q of orders 2 and up (or of
 * order 2 alone with max_order 2) into tq ([nr][nx]); the moments of the
 * orders' radiance into phi0 ([nr]: scalar flux of orders 2 and up, may
 * be NULL) and of the first order into phi1 (may be NULL). Returns 0, or
 * -1 without memory. */
static int solve(double omega, int phase, double g, const double *b, int L, const lms_res *res,
                 int max_order, double *tq, double *phi0, double *phi1, double *resid, int *its)
{
    lms_sys S;
    if (sys_init(&S, omega, b, L, res)) {
        sys_free(&S);
        return -1;
    }
    const size_t n = (size_t) L * S.nr;
    double *m1 = calloc(n, sizeof *m1), *rhs = malloc(n * sizeof *rhs), *y = calloc(n, sizeof *y);
    if (!m1 || !rhs || !y) {
        free(m1);
        free(rhs);
        free(y);
        sys_free(&S);
        return -1;
    }
    /* the first order's moments, from psi_1 itself */
    for (int i = 1; i < S.nr; ++i) {
        const double r = rho_at(S.lg, S.nr, i);
        for (int j = 0; j < S.nb; ++j)
            S.psi[(size_t) i * S.nb + j] = omega * psi1(phase, g, r, S.beta[j]);
        for (int l = 0; l < L; ++l) {
            double acc = 0;
            for (int j = 0; j < S.nb; ++j)
                acc += S.Pm[(size_t) l * S.nb + j] * S.psi[(size_t) i * S.nb + j];
            m1[(size_t) l * S.nr + i] = acc;
        }
    }
    *resid = 0;
    *its = 0;
    if (max_order != 2) {
        apply_A(&S, m1, rhs, 1);   /* the second order's moments */
        *resid = gmres(&S, rhs, y, its);
        if (*resid < 0) {
            free(m1);
            free(rhs);
            free(y);
            sys_free(&S);
            return -1;
        }
    }
    if (phi0)
        for (int i = 0; i < S.nr; ++i)
            phi0[i] = y[i];
    if (phi1)
        for (int i = 0; i < S.nr; ++i)
            phi1[i] = m1[i];
    synth(&S, y, tq, 0);
    synth(&S, m1, S.tq, 1);
    for (size_t a = 0; a < (size_t) S.nr * S.nx; ++a)
        tq[a] += S.tq[a];
    free(m1);
    free(rhs);
    free(y);
    sys_free(&S);
    return 0;
}

/* ----------------------------------------------------------- the object */

void ef_lms_ref(ef_lms *m)
{
    if (m)
        atomic_fetch_add(&m->refs, 1);
}

void ef_lms_unref(ef_lms *m)
{
    if (!m || atomic_fetch_sub(&m->refs, 1) != 1)
        return;
    for (int t = 0; t < m->ntab; ++t) {
        free(m->tab[t].q);
        free(m->tab[t].e);
        free(m->tab[t].fb);
        free(m->tab[t].fbe);
        free(m->tab[t].qb);
        free(m->tab[t].im);
    }
    for (int j = 0; j < m->nprof; ++j)
        free(m->prof[j].mem);
    free(m->prof);
    free(m);
}

void ef_lms_get_info(const ef_lms *m, ef_ms_info *info)
{
    memset(info, 0, sizeof *info);
    if (m)
        *info = m->info;
}

/* The phase's Legendre coefficients into b (LMS_L_MAX of them) and how
 * many the solve keeps: up to the last above 1e-7, at least 2. */
static int phase_terms(int phase, double g, double *b)
{
    ef_ms_phase_legendre(phase, g, LMS_L_MAX, b);
    int L = 2;
    for (int l = 2; l < LMS_L_MAX; ++l)
        if (fabs(b[l]) > 1e-7)
            L = l + 1;
    return L;
}

/* The solve's resolution for albedo omega and L Legendre terms (fine: the
 * table; coarse: the estimate's second solve). */
static lms_res res_for(double omega, double g, int L, int coarse)
{
    /* the diffusion length in mean free paths sets how far light wanders */
    const double ld = 1 / sqrt(fmax(3 * (1 - omega) * (1 - omega * g), 1e-6));
    lms_res r = { 72, L / 2 + 12, 24, 257, 24 + LMS_REACH + 8 * ld };
    if (r.npp > 76)
        r.npp = 76;
    if (r.rmax > 2000)
        r.rmax = 2000;
    if (coarse) {
        r.nr = r.nr * 2 / 3;
        r.npp = r.npp * 2 / 3;
        r.nw = r.nw * 2 / 3;
        r.nx = 129;
        r.rmax *= 0.8;
    }
    return r;
}

/* One albedo's table with its estimate: the fine solve, and the
 * difference from the coarse one at each node; the fine solve's scalar
 * fluxes into phi0 and phi1 (may be NULL; ef_lms_build_albedo's). */
static int build_tab(lms_tab *t, double omega, int phase, double g, const double *b, int L,
                     int max_order, double *phi0, double *phi1)
{
    const lms_res rf = res_for(omega, g, L, 0), rc = res_for(omega, g, L, 1);
    t->omega = omega;
    t->phase = phase;
    t->g = g;
    t->max_order = max_order;
    t->nr = rf.nr;
    t->nx = rf.nx;
    t->rmax = rf.rmax;
    t->lg = log1p(rf.rmax / LMS_RS);
    t->q = malloc((size_t) rf.nr * rf.nx * sizeof *t->q);
    t->e = malloc((size_t) rf.nr * rf.nx * sizeof *t->e);
    double *qc = malloc((size_t) rc.nr * rc.nx * sizeof *qc), rc_res;
    int its_c;
    if (!t->q || !t->e || !qc ||
        solve(omega, phase, g, b, L, &rf, max_order, t->q, phi0, phi1, &t->resid, &t->iters) ||
        solve(omega, phase, g, b, L, &rc, max_order, qc, NULL, NULL, &rc_res, &its_c)) {
        free(qc);
        return -1;
    }
    const double lgc = log1p(rc.rmax / LMS_RS);
    double qmax = 0;
    for (size_t a = 0; a < (size_t) rf.nr * rf.nx; ++a)
        qmax = fmax(qmax, fabs(t->q[a]));
    for (int i = 0; i < rf.nr; ++i) {
        const double r = rho_at(t->lg, rf.nr, i);
        for (int k = 0; k < rf.nx; ++k) {
            const double x = (double) k / (rf.nx - 1), nu = 1 - 2 * x * x;
            const double v = tab_at(qc, rc.nr, rc.nx, lgc, r, nu, NULL, NULL);
            const size_t a = (size_t) i * rf.nx + k;
            /* the coarse solve's difference, and GMRES's residual through
             * the series (its operator's norm is at most omega) */
            t->e[a] = fabs(t->q[a] - v) + t->resid / (1 - fmin(omega, 0.999999)) * qmax;
        }
    }
    free(qc);
    return 0;
}

int ef_lms_build_albedo(double omega, int phase, double g, int max_order, ef_lms **out,
                        double *phi0, double *phi1, int *nr, double *lg)
{
    ef_lms *m = calloc(1, sizeof *m);
    if (!m)
        return -1;
    atomic_init(&m->refs, 1);
    double b[LMS_L_MAX];
    const int L = m->L = phase_terms(phase, g, b);
    m->ntab = 1;
    m->tab_of[0] = m->tab_of[1] = m->tab_of[2] = 0;
    m->sig[0] = m->sig[1] = m->sig[2] = 1;
    m->scale[0] = m->scale[1] = m->scale[2] = 1;
    lms_tab *t = &m->tab[0];
    if (build_tab(t, omega, phase, g, b, L, max_order, phi0, phi1)) {
        ef_lms_unref(m);
        return -1;
    }
    m->info.iterated = t->iters;
    m->info.tail_rel = t->resid;
    m->info.nodes = t->nr;
    if (nr)
        *nr = t->nr;
    if (lg)
        *lg = t->lg;
    *out = m;
    return 0;
}

double ef_lms_rho(int nr, double lg, int i)
{
    return rho_at(lg, nr, i);
}

double ef_lms_eval(const ef_lms *m, double r, double nu, double *err)
{
    const lms_tab *t = &m->tab[0];
    double e;
    const double v = tab_at(t->q, t->nr, t->nx, t->lg, r, nu, &e, t->e);
    if (err)
        *err = e;
    return v;
}

/* Whether every component of s is uniform: their extinctions summed into
 * sig. */
static int all_uniform(const ef_fog_scene *s, double sig[3])
{
    sig[0] = sig[1] = sig[2] = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        double sg[3];
        if (!uniform_sigma(&s->comp[i], sg))
            return 0;
        for (int k = 0; k < 3; ++k)
            sig[k] += sg[k];
    }
    return s->ncomp > 0;
}

/* Why s's fog has no lamp's multiple scattering (its message into err),
 * or 0: the components must scatter alike (one albedo per channel, one
 * phase), since one table serves the medium they make together; fog that
 * is not uniform (local) takes no shadow map. */
static int lms_refuse(const ef_fog_scene *s, const ef_light *l, int local, ef_err *err)
{
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i], *c0 = &s->comp[0];
        if (c->model->tau_info)
            return ef_fail(err, "--light '%s': a lamp's multiple scattering is not solved in "
                           "noise fog (its light is integrated per ray, with no field about "
                           "the lamp to carry further orders); use scattering=single with "
                           "this fog", l->spec);
        int same = c->phase == c0->phase && c->g == c0->g;
        for (int k = 0; k < 3; ++k)
            same &= albedo(c, k) == albedo(c0, k);
        if (!same)
            return ef_fail(err, "--light '%s': a lamp's multiple scattering takes fog whose "
                           "components share one albedo and one phase (one table of the "
                           "scattered light serves them all); give them the same albedo=, "
                           "phase= and g=, or use scattering=single", l->spec);
    }
    const int coned = ef_light_coned(l);
    if (local && l->shadow)
        return ef_fail(err, "--light '%s': %s is read along the quadrature a shadow map cuts "
                       "(it would be shadowed with the single scattering); drop shadow= or use "
                       "%s", l->spec,
                       coned ? "a spot's multiple scattering"
                             : "a lamp's multiple scattering in fog that is not uniform",
                       coned ? "scattering=single" : "uniform (exp) fog");
    return 0;
}


/* Fills p's tables from its knots h and densities den (already set). */
static void prof_tables(lms_prof *p)
{
    const int n = p->nk;
    for (int k = 0; k < 3; ++k) {
        const double *D = p->den[k];
        p->up[k][n - 1] = n - 1;
        for (int i = n - 2; i >= 0; --i)
            p->up[k][i] = D[i] <= D[p->up[k][i + 1]] ? i : p->up[k][i + 1];
        p->dn[k][0] = 0;
        for (int i = 1; i < n; ++i)
            p->dn[k][i] = D[i] <= D[p->dn[k][i - 1]] ? i : p->dn[k][i - 1];
    }
}

/* Adds profile c's knots (its features; a layered fog's) to m->prof as a
 * profile along functional f; on no memory, every node fully exposed. */
static void leak_profile(ef_lms *m, const ef_fog_component *c, const ef_fog_functional *f,
                         const ef_fog_feature *ft, int nt)
{
    lms_prof *np = realloc(m->prof, (size_t) (m->nprof + 1) * sizeof *np);
    if (!np) {
        m->nleak = -1;
        return;
    }
    m->prof = np;
    lms_prof *p = &np[m->nprof];
    memset(p, 0, sizeof *p);
    const size_t n = (size_t) nt;
    p->mem = malloc(n * (4 * sizeof(double) + 6 * sizeof(int)));
    if (!p->mem) {
        m->nleak = -1;
        return;
    }
    double *a = p->mem;
    p->h = a;
    for (int k = 0; k < 3; ++k)
        p->den[k] = a + (1 + k) * n;
    int *ia = (int *) (a + 4 * n);
    for (int k = 0; k < 3; ++k) {
        p->up[k] = ia + k * n;
        p->dn[k] = ia + (3 + k) * n;
    }
    /* the knots in order (features come sorted; duplicates dropped) */
    int m_ = 0;
    for (int j = 0; j < nt; ++j) {
        if (m_ > 0 && !(ft[j].value > p->h[m_ - 1]))
            continue;
        long double v = ft[j].value, dv[3];
        c->model->density(c, &v, dv);
        p->h[m_] = ft[j].value;
        for (int k = 0; k < 3; ++k)
            p->den[k][m_] = (double) dv[k];
        ++m_;
    }
    if (m_ < 2) {
        free(p->mem);
        return;
    }
    p->nk = m_;
    memcpy(p->n, f->n, sizeof p->n);
    p->d = f->d;
    prof_tables(p);
    ++m->nprof;
}

/* Where the fog drops or thins, for the leak estimate
 * (ef_lms_local_node): the planes where a component's density drops (its
 * features of scale 0 with different densities either side: a box's or
 * convex volume's faces, a half-space's plane) into m->leak with those
 * densities, the exponential strata (height fog) into m->st_*, and a
 * component of one functional whose features are kinks (layered fog) as
 * a profile (leak_profile). A component of several functionals other
 * than a convex volume is passed over. */
static void leak_planes(const ef_fog_scene *s, ef_lms *m)
{
    m->nleak = 0;
    m->nstrata = 0;
    m->nprof = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        double rho[3], kk, base;
        if (c->model->strata && c->model->strata(c, rho, &kk, &base) && kk > 0) {
            const int j = m->nstrata++;
            memcpy(m->st_up[j], c->up, sizeof m->st_up[j]);
            memcpy(m->st_rho[j], rho, sizeof rho);
            m->st_k[j] = kk;
            m->st_base[j] = base;
            m->strata_only = s->ncomp == 1;
            continue;
        }
        if (!c->model->functionals || !c->model->features || !c->model->density)
            continue;
        ef_fog_functional fn[LEAK_MAX];
        const int nf = c->model->functionals(c, fn, LEAK_MAX);
        const int convex = c->model->convex != NULL, first = m->nleak;
        if (nf != 1 && !convex)
            continue;
        /* every feature (a profile's thousands of knots, which are kinks,
         * need not fit LEAK_MAX; the drops do) */
        const int nt = c->model->features(c, NULL, 0);
        ef_fog_feature *ft = nt > 0 ? malloc(sizeof *ft * (size_t) nt) : NULL;
        if (nf > LEAK_MAX || (nt > 0 && !ft)) {
            free(ft);
            m->nleak = -1;   /* every node fully exposed: the estimate errs wide */
            return;
        }
        if (nt > 0)
            c->model->features(c, ft, nt);
        int kinks = 0, smooth = 0;
        for (int j = 0; j < nt; ++j) {
            smooth |= ft[j].scale != 0;
            if (ft[j].scale != 0 || ft[j].f < 0 || ft[j].f >= nf)
                continue;
            const ef_fog_functional *f = &fn[ft[j].f];
            const double nn = sqrt(f->n[0] * f->n[0] + f->n[1] * f->n[1] + f->n[2] * f->n[2]);
            if (!(nn > 0))
                continue;
            /* the density just either side of the plane (inside a convex
             * volume's other faces), at two offsets: a drop differs as much
             * at both, a kink a thousand times more at the wider */
            long double v[LEAK_MAX], lo[3], hi[3], lo2[3], hi2[3];
            for (int a = 0; a < nf; ++a)
                v[a] = -INFINITY;
            const double dl = 1e-9 * (1 + fabs(ft[j].value));
            v[ft[j].f] = ft[j].value - dl;
            c->model->density(c, v, lo);
            v[ft[j].f] = ft[j].value + dl;
            c->model->density(c, v, hi);
            v[ft[j].f] = ft[j].value - 1000 * dl;
            c->model->density(c, v, lo2);
            v[ft[j].f] = ft[j].value + 1000 * dl;
            c->model->density(c, v, hi2);
            int drop = 0;
            for (int q = 0; q < 3; ++q)
                drop |= fabsl(hi[q] - lo[q]) > 0.5L * fabsl(hi2[q] - lo2[q]) && hi[q] != lo[q];
            if (!drop) {
                ++kinks;
                continue;   /* a kink, not a drop */
            }
            if (m->nleak == LEAK_MAX) {
                free(ft);
                m->nleak = -1;
                return;
            }
            const int k = m->nleak++;
            for (int q = 0; q < 3; ++q) {
                m->leak[k][q] = f->n[q] / nn;
                m->dneg[k][q] = (double) lo[q];
                m->dpos[k][q] = (double) hi[q];
            }
            m->leak[k][3] = (f->d - ft[j].value) / nn;
            m->leak_convex[k] = convex;
        }
        /* a profile of kinks alone, linear between them (layered fog) */
        if (nf == 1 && !convex && kinks >= 2 && m->nleak == first && !smooth)
            leak_profile(m, c, &fn[0], ft, nt);
        free(ft);
        if (m->nleak < 0)
            return;
        for (int j = first; j < m->nleak; ++j)
            m->leak_end[j] = m->nleak;
    }
}

/* r Q's mean over directions in row i of t: columns at x = sin(beta / 2)
 * uniform, nu = 1 - 2 x^2, the mean (1/2) int dnu = int 2 x dx
 * (trapezoid). */
static double row_mean(const lms_tab *t, int i)
{
    double sum = 0;
    for (int k = 0; k + 1 < t->nx; ++k) {
        const double x0 = (double) k / (t->nx - 1), x1 = (double) (k + 1) / (t->nx - 1);
        sum += (x1 - x0) * (x0 * t->q[(size_t) i * t->nx + k] + x1 * t->q[(size_t) i * t->nx + k + 1]);
    }
    return sum;
}

/* Points of the images' table (lms_tab's im) */
#define IMG_N 4096

/* Fills t->im (IMG_N points) from t's rows' means; -1 without memory. */
static int image_table(lms_tab *t)
{
    double *qm = malloc((size_t) t->nr * 2 * sizeof *qm);
    t->im = malloc(IMG_N * sizeof *t->im);
    if (!qm || !t->im) {
        free(qm);
        return -1;
    }
    for (int i = 0; i < t->nr; ++i)
        qm[2 * i] = qm[2 * i + 1] = row_mean(t, i);
    for (int i = 0; i < IMG_N; ++i) {
        const double u = (double) i / (IMG_N - 1);
        t->im[i] = tab_row(qm, t->nr, 2, t->lg, t->rmax * u * u, 0, 0, NULL, NULL);
    }
    free(qm);
    return 0;
}

/* Profile p's density in channel k at height v, and into *jp the last
 * knot at or below v (-1 below them all). */
static double prof_at(const lms_prof *p, int k, double v, int *jp)
{
    const double *H = p->h, *D = p->den[k];
    const int n = p->nk;
    int lo = -1, hi = n;
    while (hi - lo > 1) {
        const int mid = (lo + hi) / 2;
        if (H[mid] <= v)
            lo = mid;
        else
            hi = mid;
    }
    *jp = lo;
    if (lo < 0)
        return D[0];
    if (lo == n - 1)
        return D[n - 1];
    return D[lo] + (v - H[lo]) / (H[lo + 1] - H[lo]) * (D[lo + 1] - D[lo]);
}

/* The density's falls in channel k of profile p going from height v up
 * (dir 1) or down (-1), summed into *fall, and their mean height (each
 * piece's fall at its middle) into *hm; 0 and v where there is none. */
static void prof_fall(const lms_prof *p, int k, double v, int dir, double *fall, double *hm)
{
    const double *H = p->h, *D = p->den[k];
    const int n = p->nk;
    int j;
    const double dv = prof_at(p, k, v, &j);
    double f = 0, m = 0, ha = v, da = dv;
    for (int i = dir > 0 ? j + 1 : j; i >= 0 && i < n; i += dir) {
        if (da > D[i]) {
            f += da - D[i];
            m += (da - D[i]) * 0.5 * (ha + H[i]);
        }
        ha = H[i];
        da = D[i];
    }
    *fall = f;
    *hm = f > 0 ? m / f : v;
}

/* Diffusion's extrapolated boundary beyond a free surface, in transport
 * mean free paths (Milne's problem: 0.7104) */
#define IMG_ZB 0.7104

/* The lamp's images (m->img): across each plane where the fog holding the
 * lamp drops (a half-space's plane, the faces of a box or convex volume
 * the lamp is in), the lamp mirrored beyond the extrapolated boundary
 * IMG_ZB / (sigma (1 - albedo g1)) past it (sigma the extinction at the
 * lamp, g1 the phase's mean cosine), weighted by the drop's share of
 * sigma: the field of a source near a free surface less its image's, as
 * diffusion theory takes it; a layered profile's falls up and down from
 * the lamp as a plane each (prof_fall), height fog's one e-fold from it.
 * Then the images of images across planes square to each other or facing
 * (a box's corners and opposite faces), of the opposite sign and at half
 * their weight: a box's series alternates, and the mean of its first two
 * partial sums came nearest Cycles (bench/ms_lamp_box.md). */
/* Whether outward planes u_i and u_j (lamp_images') give an image of
 * images: square to each other (once, i < j: a box's corner) or facing (a
 * slab's or box's opposite faces, both orders). */
static int image_pair(const double (*u)[4], int i, int j)
{
    const double c = u[i][0] * u[j][0] + u[i][1] * u[j][1] + u[i][2] * u[j][2];
    return i != j && ((fabs(c) < 1e-9 && i < j) || c < -1 + 1e-9);
}

static void lamp_images(ef_lms *m, const double sl[3], const double om[3], double g1)
{
    m->nimg = 0;
    if (m->nleak < 0)
        return;
    const double *s = m->pos;
    /* the planes of the fog holding the lamp, outward (u . x + c = 0, the
     * lamp's side negative) and the drop's share per channel; the
     * extrapolated boundary per channel */
    double u[LEAK_MAX][4], sh[LEAK_MAX][3], zb[3];
    for (int k = 0; k < 3; ++k)
        zb[k] = sl[k] > 0 ? IMG_ZB / (sl[k] * fmax(1 - om[k] * g1, 1e-3)) : 0;
    int np = 0;
    for (int i = 0; i < m->nleak;) {
        const int end = m->leak_end[i];
        double sd[LEAK_MAX];
        int in = 1;
        for (int j = i; j < end; ++j) {
            sd[j] = m->leak[j][0] * s[0] + m->leak[j][1] * s[1] + m->leak[j][2] * s[2] + m->leak[j][3];
            in &= !m->leak_convex[i] || sd[j] < 0;
        }
        for (; in && i < end; ++i) {
            const double o = sd[i] < 0 ? 1 : -1;
            int any = 0;
            for (int k = 0; k < 3; ++k) {
                const double here = sd[i] < 0 ? m->dneg[i][k] : m->dpos[i][k];
                const double beyond = sd[i] < 0 ? m->dpos[i][k] : m->dneg[i][k];
                sh[np][k] = here > beyond && sl[k] > 0 ? fmin(1, (here - beyond) / sl[k]) : 0;
                any |= sh[np][k] > 0;
            }
            for (int a = 0; a < 4; ++a)
                u[np][a] = o * m->leak[i][a];
            np += any;
        }
        i = end;
    }
    /* a layered profile's falls up and down from the lamp, as one plane
     * each at their mean height (weighted by the fall), their share summed
     * (at most 1) */
    for (int j = 0; j < m->nprof && np + 2 <= LEAK_MAX; ++j) {
        const lms_prof *p = &m->prof[j];
        const double v = p->n[0] * s[0] + p->n[1] * s[1] + p->n[2] * s[2] + p->d;
        for (int dir = 1; dir >= -1; dir -= 2) {
            double fall[3] = { 0, 0, 0 }, hm[3] = { 0, 0, 0 };
            for (int k = 0; k < 3; ++k)
                prof_fall(p, k, v, dir, &fall[k], &hm[k]);
            int any = 0;
            for (int k = 0; k < 3; ++k) {
                sh[np][k] = sl[k] > 0 && fall[k] > 0 ? fmin(1, fall[k] / sl[k]) : 0;
                any |= sh[np][k] > 0;
            }
            if (!any)
                continue;
            /* one plane for every channel: at the falls' mean height in the
             * channel of the largest */
            const int kk = fall[1] > fall[0] ? (fall[2] > fall[1] ? 2 : 1) : (fall[2] > fall[0] ? 2 : 0);
            for (int a = 0; a < 3; ++a)
                u[np][a] = dir * p->n[a];
            u[np][3] = dir * (p->d - hm[kk]);
            ++np;
        }
    }
    /* height fog's fall, above the lamp (below where it thickens upwards),
     * as one plane at its mean height, one e-fold away */
    for (int j = 0; j < m->nstrata && np < LEAK_MAX; ++j) {
        const double *up = m->st_up[j], kk = m->st_k[j];
        const double hs = up[0] * s[0] + up[1] * s[1] + up[2] * s[2];
        int any = 0;
        for (int k = 0; k < 3; ++k) {
            const double sc = m->st_rho[j][k] * exp(-kk * (hs - m->st_base[j]));
            sh[np][k] = sl[k] > 0 && sc > 0 ? fmin(1, sc / sl[k]) : 0;
            any |= sh[np][k] > 0;
        }
        if (!any || !(kk != 0))
            continue;
        const double o = kk > 0 ? 1 : -1;
        for (int a = 0; a < 3; ++a)
            u[np][a] = o * up[a];
        u[np][3] = -o * (hs + 1 / kk);
        ++np;
    }
    /* first images, then the second across planes square to each other
     * (a box's 12 corners, once each) or facing (a slab's or box's
     * opposite faces, both orders), of the opposite sign, where they fit */
    int pairs = 0;
    for (int i = 0; i < np; ++i)
        for (int j = 0; j < np; ++j)
            pairs += image_pair((const double (*)[4]) u, i, j);
    const int second = np + pairs <= LEAK_MAX;
    for (int i = 0; i < np; ++i)
        for (int j = -1; j < (second ? np : 0); ++j) {
            if (j >= 0 && !image_pair((const double (*)[4]) u, i, j))
                continue;
            for (int k = 0; k < 3; ++k) {
                double p[3];
                memcpy(p, s, sizeof p);
                const int pl[2] = { i, j };
                for (int q = 0; q < (j < 0 ? 1 : 2); ++q) {
                    const double *n = u[pl[q]];
                    const double h = n[0] * p[0] + n[1] * p[1] + n[2] * p[2] + n[3];
                    for (int a = 0; a < 3; ++a)
                        p[a] += 2 * (zb[k] - h) * n[a];
                }
                m->imx[k][m->nimg] = p[0];
                m->imy[k][m->nimg] = p[1];
                m->imz[k][m->nimg] = p[2];
                m->ims[k][m->nimg] = j < 0 ? sh[i][k] : -0.5 * sh[i][k] * sh[j][k];
            }
            ++m->nimg;
        }
}

/* The images' part of a node's value (ef_lms_local_node's units: sigma
 * tau (rQ)(tau) for the lamp itself) at x, each at the lamp's mean
 * extinction tl / d over its own distance, from the table's mean over
 * directions (a first form read each image's direction from the full
 * table: twice the cost, the same errors against Cycles but one). */
EF_INLINE double image_part(const ef_lms *m, const lms_tab *tb, int k, double tl, double sg,
                            double d, const double x[3])
{
    /* the distances and the table's places first, a loop the compiler
     * puts on vectors; the reads after (tl / taup = d / dp) */
    const int n = m->nimg;
    const double *px = m->imx[k], *py = m->imy[k], *pz = m->imz[k], *ps = m->ims[k];
    double u[LEAK_MAX], rd[LEAK_MAX];
    const double c = tl / (d * tb->rmax);
    for (int j = 0; j < n; ++j) {
        const double a = x[0] - px[j], b = x[1] - py[j], e = x[2] - pz[j];
        const double dp = sqrt(a * a + b * b + e * e);
        u[j] = sqrt(c * dp) * (IMG_N - 1);
        rd[j] = 1 / dp;
    }
    double v = 0;
    for (int j = 0; j < n; ++j) {
        if (!(u[j] < IMG_N - 1) || !(rd[j] < INFINITY) || ps[j] == 0)
            continue;
        const int i = (int) u[j];
        const double f = u[j] - i;
        v += ps[j] * rd[j] * (tb->im[i] + f * (tb->im[i + 1] - tb->im[i]));
    }
    return v * sg * tl * d;
}

/* E_2(x) / 2 from m's table (linear between its points), 0 past it
 * (E_2(40) < 1e-19). */
static double half_e2(const ef_lms *m, double x)
{
    const double u = x * (LEAK_E2_N / LEAK_E2_X);
    if (!(u < LEAK_E2_N))
        return 0;
    const int j = (int) u;
    return 0.5 * (m->e2[j] + (u - j) * (m->e2[j + 1] - m->e2[j]));
}

/* The pieces of a profile prof_walk takes one by one before the rest is
 * taken at the walk's end. */
#define PROF_WALK 64

/* One direction of prof_exposure: from x (density dv, height v) through
 * the profile's points hs[0..n) (densities ds, going away from x), every
 * fall of the density counted as planes are (its share of sg times E_2 of
 * the optical depth to it, over 2), the mean over a linear piece by
 * Gauss-Legendre (the depth quadratic along it); past PROF_WALK pieces or
 * LEAK_E2_X of depth, the fall still to come (to the least, rest_min) at
 * the depth reached. */
static double prof_walk(const ef_lms *m, double v, double dv, const double *hs, const double *ds,
                        int step, int n, double rest_min, double sg, double rest)
{
    double e = 0, tau = 0, ha = v, da = dv;
    for (int i = 0; i < n; ++i) {
        const double hb = hs[i * step], db = ds[i * step], L = fabs(hb - ha);
        if (i >= PROF_WALK || !(tau < LEAK_E2_X)) {
            if (da > rest_min)
                e += (da - rest_min) / sg * half_e2(m, tau);
            return e;
        }
        if (db < da && L > 0) {
            double mean = 0;
            for (int g = 0; g < PROF_NG; ++g) {
                const double u = m->glx[g] * L;
                mean += m->glw[g] * half_e2(m, tau + (da + rest) * u + (db - da) * u * u / (2 * L));
            }
            e += (da - db) / sg * mean;
        }
        tau += (0.5 * (da + db) + rest) * L;
        ha = hb;
        da = db;
    }
    return e;
}

/* Profile p's part of leak_exposure at x (channel k, extinction sg):
 * where the density falls going up or down from x, each fall as planes'
 * drops are counted (prof_walk), the rest of sg (the other components)
 * taken as at x. */
static double prof_exposure(const lms_prof *p, const ef_lms *m, const double x[3], int k,
                            double sg)
{
    const double v = p->n[0] * x[0] + p->n[1] * x[1] + p->n[2] * x[2] + p->d;
    const double *H = p->h, *D = p->den[k];
    const int n = p->nk;
    int j;   /* the last knot at or below v (-1 below them all) */
    const double dv = prof_at(p, k, v, &j);
    const double rest = fmax(0, sg - dv);
    double e = 0;
    if (j + 1 < n)   /* up: knots j + 1 and above */
        e += fmin(1, prof_walk(m, v, dv, H + j + 1, D + j + 1, 1, n - j - 1,
                               D[p->up[k][j + 1]], sg, rest));
    if (j >= 0)   /* down: knots j and below */
        e += fmin(1, prof_walk(m, v, dv, H + j, D + j, -1, j + 1, D[p->dn[k][j]], sg, rest));
    return e;
}

/* The exposure in channel k of a point x of extinction sg to where the
 * fog drops or thins: over the planes of the components whose fog holds
 * x, the share of sg that drops there times E_2(sg dist) / 2 (the mean
 * over directions of the transmittance to the plane); over height fogs,
 * their share of sg times E_2(sg / falloff) / 2 (one e-fold up); at most
 * 1. */
static double leak_exposure(const ef_lms *m, const double x[3], int k, double sg)
{
    if (m->nleak < 0)
        return 1;
    if (!(sg > 0))
        return 0;
    double e = 0, sd[LEAK_MAX];
    for (int i = 0; i < m->nleak; ++i)
        sd[i] = m->leak[i][0] * x[0] + m->leak[i][1] * x[1] + m->leak[i][2] * x[2] + m->leak[i][3];
    for (int i = 0; i < m->nleak;) {
        const int end = m->leak_end[i];
        int in = 1;   /* a volume's faces: x inside every one of them */
        for (int j = i; m->leak_convex[i] && j < end && in; ++j)
            in = sd[j] < 0;
        for (; in && i < end; ++i) {
            const double here = sd[i] < 0 ? m->dneg[i][k] : m->dpos[i][k];
            const double beyond = sd[i] < 0 ? m->dpos[i][k] : m->dneg[i][k];
            if (here > beyond)
                e += fmin(1, (here - beyond) / sg) * half_e2(m, sg * fabs(sd[i]));
        }
        i = end;
    }
    /* layered fog thins wherever its profile falls, above or below x:
     * each fall's share of sg at the optical depth to it (prof_exposure) */
    for (int j = 0; j < m->nprof; ++j)
        e += prof_exposure(&m->prof[j], m, x, k, sg);
    /* height fog thins upwards: its share of sg, at an optical depth sg / k
     * (one e-fold) */
    for (int j = 0; j < m->nstrata; ++j) {
        const double *up = m->st_up[j];
        const double sc = m->strata_only ? sg
                          : m->st_rho[j][k] * exp(-m->st_k[j] * (up[0] * x[0] + up[1] * x[1] +
                                                                 up[2] * x[2] - m->st_base[j]));
        if (sc > 0)
            e += fmin(1, sc / sg) * half_e2(m, sg / m->st_k[j]);
    }
    return fmin(e, 1);
}

int ef_lms_build(const ef_fog_scene *s, const ef_light *l, ef_lms **out, ef_err *err)
{
    struct timespec t0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    *out = NULL;
    double sig[3];
    if (s->ncomp == 0)
        return ef_fail(err, "--light '%s': scattering=multiple needs fog (--fog)", l->spec);
    /* a spot's cone breaks the symmetry the gather needs: read at the
     * lit quadrature's nodes as fog that is not uniform is */
    const int uniform = all_uniform(s, sig), local = !uniform || ef_light_coned(l);
    if ((local || s->ncomp > 1) && lms_refuse(s, l, local, err))
        return -1;
    const ef_fog_component *c = &s->comp[0];
    if (fabs(c->g) > LMS_G_MAX && (c->phase == EF_PHASE_HG || c->phase == EF_PHASE_CS))
        return ef_fail(err, "--light '%s': a lamp's multiple scattering takes |g| up to %g "
                       "(the phase's series needs more terms beyond); the fog's g is %g",
                       l->spec, LMS_G_MAX, c->g);
    if (local)   /* a table for every channel that scatters anywhere */
        for (int k = 0; k < 3; ++k)
            sig[k] = 1;
    for (int k = 0; k < 3; ++k)
        if (albedo(c, k) > LMS_ALBEDO_MAX && sig[k] > 0)
            return ef_fail(err, "--light '%s': a lamp's multiple scattering takes albedo up to "
                           "%g in unbounded fog (light that is never absorbed wanders without "
                           "end); the fog's albedo is %g", l->spec, LMS_ALBEDO_MAX, albedo(c, k));
    ef_lms *m = calloc(1, sizeof *m);
    if (!m)
        return ef_fail(err, "out of memory for a lamp's multiple scattering");
    atomic_init(&m->refs, 1);
    m->local = local;
    m->scaled = !uniform;
    memcpy(m->pos, l->pos, sizeof m->pos);
    if (local) {
        for (int j = 0; j <= LEAK_E2_N; ++j)
            m->e2[j] = (float) ef_lit_e2(LEAK_E2_X * j / LEAK_E2_N);
        ef_ms_directions(PROF_NG, m->glx, m->glw);
        leak_planes(s, m);
        /* the lamp's own exposure, at the extinction where it stands (0
         * outside the fog), and the term's weight per channel */
        double sl[3];
        ef_lit_sigma_at(s, l->pos, sl);
        double om[3], b1[LMS_L_MAX];
        for (int k = 0; k < 3; ++k) {
            m->lamp_leak[k] = leak_exposure(m, l->pos, k, sl[k]);
            m->leak_w[k] = LEAK_C * sqrt(0.1 / fmax(1 - albedo(c, k), 1e-3));
            om[k] = albedo(c, k);
        }
        phase_terms(c->phase, c->g, b1);
        lamp_images(m, sl, om, b1[1]);
    }
    double b[LMS_L_MAX];
    const int L = m->L = phase_terms(c->phase, c->g, b);
    for (int k = 0; k < 3; ++k) {
        m->sig[k] = sig[k];
        m->scale[k] = l->e[k] * sig[k] * sig[k];
        const double om = albedo(c, k);
        int t = 0;
        while (t < m->ntab && m->tab[t].omega != om)
            ++t;
        if (t == m->ntab) {
            if (!(om > 0) || !(sig[k] > 0) || l->e[k] == 0) {
                m->tab_of[k] = -1;
                continue;
            }
            if (build_tab(&m->tab[t], om, c->phase, c->g, b, L, 0, NULL, NULL)) {
                ef_lms_unref(m);
                return ef_fail(err, "out of memory for a lamp's multiple scattering");
            }
            ++m->ntab;
            if (m->nimg && image_table(&m->tab[t])) {
                ef_lms_unref(m);
                return ef_fail(err, "out of memory for a lamp's multiple scattering");
            }
        }
        m->tab_of[k] = t;
    }
    if (ef_light_coned(l) && ef_lms_spot(m, l)) {
        ef_lms_unref(m);
        return ef_fail(err, "out of memory for a spot's multiple scattering");
    }
    m->info.nodes = m->tab[0].nr;
    m->info.kept = m->tab[0].nx;
    m->info.nh = L;
    m->info.iterated = m->tab[0].iters;
    m->info.tail_rel = m->tab[0].resid;
    double emax = 0, qmax = 0;
    for (int t = 0; t < m->ntab; ++t)
        for (size_t a = 0; a < (size_t) m->tab[t].nr * m->tab[t].nx; ++a) {
            emax = fmax(emax, m->tab[t].e[a]);
            qmax = fmax(qmax, fabs(m->tab[t].q[a]));
        }
    m->info.disc_rel = qmax > 0 ? emax / qmax : 0;
    m->info.seconds = ef_lit_seconds_since(&t0);
    *out = m;
    return 0;
}

/* ------------------------------------------------------------ the gather */

typedef struct g_q {
    const lms_tab *t;
    double sc, h;
} g_q;

/* e^-s (r Q)(r, nu) at s = sc + h sinh w, and its estimate into e */
static double g_f(const void *qv, double w, double *e)
{
    const g_q *q = qv;
    const double sh = sinh(w), ch = sqrt(1 + sh * sh);
    const double s = q->sc + q->h * sh, r = q->h * ch, ex = exp(-s);
    double ev;
    const double v = tab_at(q->t->q, q->t->nr, q->t->nx, q->t->lg, r, -sh / ch, &ev, q->t->e);
    *e = ex * ev;
    return ex * v;
}

/* One Kronrod rule over [a, b] in w (gk15_rule of g_f). */
static void g_gk(const g_q *q, double a, double b, double *R, double *E, double *X)
{
    gk15_rule(g_f, q, a, b, R, E, X);
}

/* int_a^b e^-s Q ds of table t along a ray whose closest approach to the
 * lamp is at sc (optical depth along the ray) at distance h: in w pieces
 * either side of the closest approach, adaptive Gauss-Kronrod to 1e-6 of
 * the result; the table's estimate gathered the same way, plus the
 * quadrature's, into *e. */
static double gather_tab(const lms_tab *t, double sc, double h, double a, double b, double *e)
{
    g_q q = { t, sc, fmax(h, 1e-12 * (1 + fabs(sc))) };
    const double wa = asinh((a - sc) / q.h), wb = asinh((b - sc) / q.h);
    double cut[3] = { wa, wb, wb };
    int nc = 2;
    if (a < sc && sc < b) {
        cut[1] = 0;
        nc = 3;
    }
    return gk15_adapt(g_f, &q, cut, nc, 1e-6, e);
}

void ef_lms_gather(const ef_lms *m, const ef_ray *r, double a, double b, double S[3],
                   double E[3])
{
    S[0] = S[1] = S[2] = 0;
    if (E)
        E[0] = E[1] = E[2] = 0;
    if (!m || m->local || !(b > a))
        return;
    double d[3], along = 0, perp2 = 0;
    for (int k = 0; k < 3; ++k) {
        d[k] = m->pos[k] - r->org[k];
        along += d[k] * r->dir[k];
    }
    for (int k = 0; k < 3; ++k) {
        const double p = d[k] - along * r->dir[k];
        perp2 += p * p;
    }
    const double perp = sqrt(perp2);
    double res[3][2];
    int done[3] = { 0, 0, 0 };
    for (int k = 0; k < 3; ++k) {
        const int t = m->tab_of[k];
        if (t < 0)
            continue;
        const double sg = m->sig[k];
        /* channels with the same table and extinction share the gather */
        int same = -1;
        for (int j = 0; j < k; ++j)
            if (done[j] && m->tab_of[j] == t && m->sig[j] == sg)
                same = j;
        if (same >= 0) {
            res[k][0] = res[same][0];
            res[k][1] = res[same][1];
        } else {
            const double sa = sg * a, sb = fmin(sg * b, sa + LMS_REACH);
            /* past the reach, e^-40 of the light at a is left out */
            res[k][0] = gather_tab(&m->tab[t], sg * along, sg * perp, sa, sb, &res[k][1]);
        }
        done[k] = 1;
        S[k] = m->scale[k] * res[k][0];
        if (E)
            E[k] = m->scale[k] * res[k][1];
    }
}

/* ------------------------------------------------- bound to a camera */

/* Every ray from one camera is fixed, for a lamp's gather, by its angle
 * alpha from the direction to the lamp and its depth: the gather along it
 * is tabulated once per camera against alpha (LV_NA nodes uniform in z =
 * asinh(alpha / a0) + LV_K alpha: relative steps of about 6 % towards the
 * lamp, where the glow grows as log(1 / alpha), and under a degree beyond)
 * and, per
 * alpha, against the hyperbolic angle w about the ray's closest approach
 * to the lamp, in two pieces (camera to closest approach, on to the
 * reach) of LV_NP nodes each, so that the camera, the closest approach
 * and the reach sit at the same nodes for every alpha. A pixel then reads
 * G cubic (Hermite) in w and linear in alpha. */
#define LV_NA 320
#define LV_NP 64
#define LV_K 3.0

typedef struct lv_group {
    double sig;
    const lms_tab *t;
    double a0, zlo, zhi; /* nodes uniform in z(alpha) over [zlo, zhi] */
    double *G;           /* [LV_NA][2][LV_NP + 1][3]: G, dG/df, estimate */
} lv_group;

struct ef_lms_view {
    _Atomic int refs;
    double org[3], dhat[3], DL;
    int ng, group_of[3];
    lv_group g[3];
};

void ef_lms_view_ref(ef_lms_view *v)
{
    if (v)
        atomic_fetch_add(&v->refs, 1);
}

void ef_lms_view_unref(ef_lms_view *v)
{
    if (!v || atomic_fetch_sub(&v->refs, 1) != 1)
        return;
    for (int i = 0; i < v->ng; ++i)
        free(v->g[i].G);
    free(v);
}

/* A ray's geometry about the lamp at alpha: closest approach sc, distance
 * h, and its pieces' ends in w: [w0, w1] (camera to closest approach,
 * empty when the lamp is behind) and [w1, w2] (on to the reach). */
static void lv_geom(double sDL, double alpha, double *sc, double *h, double w[3])
{
    *sc = sDL * cos(alpha);
    *h = fmax(sDL * sin(alpha), 1e-12 * (1 + sDL));
    w[0] = asinh(-*sc / *h);
    w[1] = fmax(w[0], 0);
    w[2] = fmax(w[1], asinh((LMS_REACH - *sc) / *h));
}

/* The table's angular coordinate of alpha (increasing). */
static double lv_z(const lv_group *g, double alpha)
{
    return asinh(alpha / g->a0) + LV_K * alpha;
}

/* alpha at node i (z increases with alpha: bisection) */
static double lv_alpha(const lv_group *g, int i)
{
    const double z = g->zlo + (g->zhi - g->zlo) * i / (LV_NA - 1);
    double lo = 0, hi = PI;
    for (int it = 0; it < 80; ++it) {
        const double mid = 0.5 * (lo + hi);
        if (lv_z(g, mid) < z)
            lo = mid;
        else
            hi = mid;
    }
    return 0.5 * (lo + hi);
}

int ef_lms_bind(const ef_lms *m, const double org[3], ef_lms_view **out)
{
    ef_lms_view_unref(*out);
    *out = NULL;
    if (!m || m->local)
        return 0;
    ef_lms_view *v = calloc(1, sizeof *v);
    if (!v)
        return -1;
    atomic_init(&v->refs, 1);
    memcpy(v->org, org, sizeof v->org);
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
        v->dhat[k] = m->pos[k] - org[k];
        d2 += v->dhat[k] * v->dhat[k];
    }
    v->DL = sqrt(d2);
    if (!(v->DL > 0)) {   /* the camera at the lamp: every ray integrates */
        free(v);
        return 0;
    }
    for (int k = 0; k < 3; ++k)
        v->dhat[k] /= v->DL;
    for (int k = 0; k < 3; ++k) {
        v->group_of[k] = -1;
        if (m->tab_of[k] < 0)
            continue;
        int gi = 0;
        while (gi < v->ng && !(v->g[gi].t == &m->tab[m->tab_of[k]] && v->g[gi].sig == m->sig[k]))
            ++gi;
        if (gi == v->ng) {
            lv_group *g = &v->g[v->ng++];
            g->sig = m->sig[k];
            g->t = &m->tab[m->tab_of[k]];
            const double sDL = g->sig * v->DL;
            /* h = sDL sin alpha reaches 1e-3 optical depths at a0 */
            g->a0 = fmin(0.5, 1e-3 / sDL);
            g->zlo = lv_z(g, 2e-6 / sDL);
            g->zhi = lv_z(g, PI);
            g->G = malloc((size_t) LV_NA * 2 * (LV_NP + 1) * 3 * sizeof *g->G);
            if (!g->G) {
                ef_lms_view_unref(v);
                return -1;
            }
            for (int i = 0; i < LV_NA; ++i) {
                double sc, h, w[3];
                lv_geom(sDL, lv_alpha(g, i), &sc, &h, w);
                g_q q = { g->t, sc, h };
                double acc = 0, acce = 0;
                for (int p = 0; p < 2; ++p) {
                    double *row = g->G + ((size_t) i * 2 + p) * (LV_NP + 1) * 3;
                    const double wa = w[p], wb = w[p + 1], dw = (wb - wa) / LV_NP;
                    for (int j = 0; j <= LV_NP; ++j) {
                        const double wj = wa + dw * j;
                        if (j > 0 && dw > 0) {
                            double R, E, X;
                            g_gk(&q, wj - dw, wj, &R, &E, &X);
                            acc += R;
                            acce += X + E;
                        }
                        double ev;
                        row[3 * j] = acc;
                        row[3 * j + 1] = dw > 0 ? g_f(&q, wj, &ev) * (wb - wa) : 0;
                        row[3 * j + 2] = acce;
                    }
                }
            }
            /* the linear interpolation in alpha: its second differences
             * (at the same node of w) into the estimate */
            for (int i = 1; i + 1 < LV_NA; ++i)
                for (size_t a = 0; a < 2 * (LV_NP + 1); ++a) {
                    const double *lo = g->G + ((size_t) (i - 1) * 2 * (LV_NP + 1) + a) * 3;
                    const double *mi = g->G + ((size_t) i * 2 * (LV_NP + 1) + a) * 3;
                    const double *hi = g->G + ((size_t) (i + 1) * 2 * (LV_NP + 1) + a) * 3;
                    g->G[((size_t) i * 2 * (LV_NP + 1) + a) * 3 + 2] +=
                        0.5 * fabs(lo[0] - 2 * mi[0] + hi[0]);
                }
        }
        v->group_of[k] = gi;
    }
    *out = v;
    return 0;
}

/* G and its estimate at fraction f of piece p of alpha node i (Hermite in
 * f from the nodes' values and slopes). */
static void lv_read(const lv_group *g, int i, int p, double f, double *G, double *X)
{
    const double *row = g->G + ((size_t) i * 2 + p) * (LV_NP + 1) * 3;
    double x = f * LV_NP;
    int j = (int) x;
    if (j > LV_NP - 1)
        j = LV_NP - 1;
    if (j < 0)
        j = 0;
    const double t = x - j, h = 1.0 / LV_NP;
    const double *a = row + 3 * j, *b = a + 3;
    const double t2 = t * t, t3 = t2 * t;
    *G = (2 * t3 - 3 * t2 + 1) * a[0] + (t3 - 2 * t2 + t) * h * a[1] + (-2 * t3 + 3 * t2) * b[0] +
         (t3 - t2) * h * b[1];
    *X = a[2] + t * (b[2] - a[2]);
}

void ef_lms_gather_view(const ef_lms *m, const ef_lms_view *v, const ef_ray *r, double a,
                        double b, double S[3], double E[3])
{
    if (!v || !(a == 0) || r->org[0] != v->org[0] || r->org[1] != v->org[1] ||
        r->org[2] != v->org[2]) {
        ef_lms_gather(m, r, a, b, S, E);
        return;
    }
    S[0] = S[1] = S[2] = 0;
    if (E)
        E[0] = E[1] = E[2] = 0;
    if (!(b > 0))
        return;
    const double c = r->dir[0] * v->dhat[0] + r->dir[1] * v->dhat[1] + r->dir[2] * v->dhat[2];
    const double ts = sqrt(fmax(0, fmin(1, 0.5 * (1 - c))));
    const double alpha = 2 * asin(ts);
    double res[3][2];
    for (int gi = 0; gi < v->ng; ++gi) {
        const lv_group *g = &v->g[gi];
        const double sDL = g->sig * v->DL;
        double fi = (lv_z(g, alpha) - g->zlo) / (g->zhi - g->zlo) * (LV_NA - 1);
        if (!(fi >= 0))
            fi = 0;
        int i = (int) fi;
        if (i > LV_NA - 2)
            i = LV_NA - 2;
        const double fa = fi - i;
        /* the pixel's own place along its ray: its piece and the fraction
         * of it, read at the same fraction at both alpha nodes */
        double sc, h, w[3];
        lv_geom(sDL, alpha, &sc, &h, w);
        const double sD = g->sig * b;
        int p = 1;
        double f = 1;
        if (sD < LMS_REACH) {
            const double wD = asinh((sD - sc) / h);
            if (wD < w[1]) {
                p = 0;
                f = w[1] > w[0] ? (wD - w[0]) / (w[1] - w[0]) : 1;
            } else {
                f = w[2] > w[1] ? (wD - w[1]) / (w[2] - w[1]) : 1;
            }
            f = fmax(0, fmin(1, f));
        }
        double G0, X0, G1, X1;
        lv_read(g, i, p, f, &G0, &X0);
        lv_read(g, i + 1, p, f, &G1, &X1);
        res[gi][0] = (1 - fa) * G0 + fa * G1;
        res[gi][1] = (1 - fa) * X0 + fa * X1;
    }
    for (int k = 0; k < 3; ++k) {
        const int gi = v->group_of[k];
        if (gi < 0)
            continue;
        S[k] = m->scale[k] * res[gi][0];
        if (E)
            E[k] = m->scale[k] * res[gi][1];
    }
}

/* ------------------------------------------------------------- spots */

/* A spot's light is a point lamp's times its cone's share f(omega) of the
 * direction it leaves in. Transport is linear, so the source of orders 2
 * and up at x is the point lamp's, Q, times the mean of f over the
 * directions in which the light that reaches x first left the lamp,
 * weighted by what each first scattering point y contributes to x:
 *
 *   w(y) = e^-s p(y) [omega p_x e^-d / d^2 + Q(d)]   (s = |y|, d = |x - y|)
 *
 * (optical units; p(y) the phase at y towards x, the bracket what a point
 * lamp at y sends to x: its once-scattered light and Q). With isotropic
 * phase that is exact: the light leaving y is a point lamp's. With a
 * phase that is not, the light that leaves y and scatters again before x
 * left towards x (p(y)) if x is near, any way (1 / (4 pi)) if x is many
 * transport mean free paths away (1 / (1 - g) each, over which the
 * direction is lost): p(y) fading as e^-(1 - g) d is taken, and the
 * spread of other weightings (spot_kernel's var) is the estimate.
 * Tabulated against |x| and the angle of x from the axis: y's angle theta
 * from x's direction has the marginal
 *
 *   K(theta) = (2 pi / r) int e^-s p(y) [omega p_x e^-d + d^2 Q(d)] dpsi
 *
 * (s = r cos theta + h tan psi, d = h / cos psi, h = r sin theta), and f
 * averaged about x's direction at theta is A(alpha, theta). p_x and Q are
 * their means over directions (the table's direction is left as the point
 * lamp's). An order-2 table (max_order 2) keeps the once-scattered term
 * alone: Q then is the third order. */
#define SPOT_NR 40       /* optical distances, log-spaced from SPOT_RMIN to rmax */
#define SPOT_RMIN 1e-3
#define SPOT_NA 256      /* angles from the axis, 0 to pi */
#define SPOT_NT 512      /* kernel angles (midpoints) */
#define SPOT_NPHI 128    /* azimuths of A (midpoints over [0, pi]) */
#define SPOT_NPSI 24     /* Gauss nodes on each of psi's pieces */
#define SPOT_NV 8        /* the weightings (spot_kernel's var) */

/* K(theta_j) of table t at r for SPOT_NT midpoints, for the weightings
 * var 0 .. nv - 1 into K + var SPOT_NT (the constant 2 pi / r dropped).
 * var 0: as above, the multiple part's p(y) fading to 1 / (4 pi) over a
 * transport mean free path from y; 1: 1 / (4 pi) there, 7: p(y) there;
 * 2 and 3: p_x of the light travelling outwards along the radial, or back
 * (a view along the lamp's line, against the mean over views); 4:
 * isotropic phase throughout (how much the phase moves it at all); 5 and
 * 6: p_x of a view across the radial, the light's sideways part towards it
 * or away (a halo beside the cone is seen so). qb: the table's r Q
 * averaged over directions ([nr][2], both alike). One pass serves every
 * weighting: the node's geometry, attenuation and table read are theirs
 * in common (each weighting's sum is the same operations in the same
 * order as on its own, so the same bits). */
static void spot_kernel(const lms_tab *t, const double *qb, double r, int nv, const double *gx,
                        const double *gw, double *K)
{
    const double pm = 1 / (4 * PI);
    for (int j = 0; j < SPOT_NT; ++j) {
        const double th = (j + 0.5) * PI / SPOT_NT, c = cos(th), h = r * sin(th);
        const double p0 = atan2(-r * c, h);
        /* psi's pieces: from the lamp (s = 0) to x's foot, and on to pi/2 */
        const double piece[3] = { p0, fmax(p0, 0), PI / 2 };
        double sum[SPOT_NV] = { 0 };
        for (int pc = 0; pc < 2; ++pc) {
            const double a = piece[pc], b = piece[pc + 1];
            for (int i = 0; b > a && i < SPOT_NPSI; ++i) {
                const double ps = a + (b - a) * gx[i], cp = cos(ps);
                if (!(cp > 0))
                    continue;
                const double s = fmax(0, r * c + h * tan(ps)), d = h / cp;
                const double pyp = ef_phase_eval(t->phase, t->g, -sin(ps));
                /* the once-scattered light's direction at x against the
                 * outward radial: (r - s cos theta) / d */
                const double ux = (r - s * c) / d;
                /* (5 and 6: a view across the radial, the light's
                 * sideways part towards it or away) */
                const double uy = sqrt(fmax(0, 1 - ux * ux));
                const double ea = exp(-(s + d));
                double base = 0, mem = 0;
                if (t->max_order != 2) {
                    const double rq = tab_row(qb, t->nr, 2, t->lg, d, 0, 0, NULL, NULL);
                    /* (var 0: the direction y sends it in is kept over
                     * a transport mean free path, 1 / (1 - g), then lost) */
                    mem = exp(-(1 - t->g) * d);
                    base = exp(-s) * d * rq;
                }
                for (int var = 0; var < nv; ++var) {
                    const double py = var == 4 ? pm : pyp;
                    const double px = var < 2 || var == 4 ? pm
                                      : var < 4 ? ef_phase_eval(t->phase, t->g, var == 2 ? ux : -ux)
                                                : ef_phase_eval(t->phase, t->g, var == 5 ? uy : -uy);
                    double v = t->omega * px * ea;
                    if (t->max_order != 2) {
                        const double keep = var == 1   ? pm / py
                                            : var == 7 ? 1
                                                       : mem + (1 - mem) * pm / py;
                        v += base * keep;
                    }
                    sum[var] += (b - a) * gw[i] * py * v;
                }
            }
        }
        for (int var = 0; var < nv; ++var)
            K[var * SPOT_NT + j] = sum[var] > 0 ? sum[var] : 0;
    }
}

int ef_lms_spot(ef_lms *m, const ef_light *l)
{
    m->spot = 1;
    m->local = 1;
    m->cone = (ef_light) { .kind = l->kind, .cos_outer = l->cos_outer, .smooth = l->smooth,
                           .cosine = l->cosine };
    double gx[SPOT_NPSI], gw[SPOT_NPSI];
    ef_ms_directions(SPOT_NPSI, gx, gw);
    /* A(alpha_i, theta_j): the share about a direction at alpha from the
     * axis, averaged over the circle at theta from it */
    double *A = malloc((size_t) SPOT_NA * SPOT_NT * sizeof *A);
    double *K = malloc(SPOT_NV * SPOT_NT * sizeof *K);
    if (!A || !K) {
        free(A);
        free(K);
        return -1;
    }
    double cph[SPOT_NPHI];
    for (int k = 0; k < SPOT_NPHI; ++k)
        cph[k] = cos((k + 0.5) * PI / SPOT_NPHI);
    for (int i = 0; i < SPOT_NA; ++i) {
        const double al = i * PI / (SPOT_NA - 1), ca = cos(al), sa = sin(al);
        for (int j = 0; j < SPOT_NT; ++j) {
            const double th = (j + 0.5) * PI / SPOT_NT, c = ca * cos(th), sn = sa * sin(th);
            double sum = 0;
            for (int k = 0; k < SPOT_NPHI; ++k)
                sum += ef_spot_share(&m->cone, c + sn * cph[k]);
            A[(size_t) i * SPOT_NT + j] = sum / SPOT_NPHI;
        }
    }
    int rc = 0;
    for (int ti = 0; ti < m->ntab && !rc; ++ti) {
        lms_tab *t = &m->tab[ti];
        double *qb = t->qb = malloc((size_t) t->nr * 2 * sizeof *qb);
        t->fb = malloc((size_t) SPOT_NR * SPOT_NA * sizeof *t->fb);
        t->fbe = malloc((size_t) SPOT_NR * SPOT_NA * sizeof *t->fbe);
        if (!qb || !t->fb || !t->fbe) {
            rc = -1;
            break;
        }
        for (int i = 0; i < t->nr; ++i)
            qb[2 * i] = qb[2 * i + 1] = row_mean(t, i);
        /* with a phase that is not isotropic, seven more weightings
         * whose spread from the first is the estimate */
        const int nv = t->phase != EF_PHASE_ISO && t->g != 0 ? SPOT_NV : 1;
        const double lr = log(t->rmax / SPOT_RMIN);
        t->spot_u = (SPOT_NR - 1) / lr;   /* spot_share_uv's rows per unit of log r */
        for (int ir = 0; ir < SPOT_NR; ++ir) {
            const double r = SPOT_RMIN * exp(lr * ir / (SPOT_NR - 1));
            double nk[SPOT_NV];
            spot_kernel(t, qb, r, nv, gx, gw, K);
            for (int v = 0; v < nv; ++v) {
                nk[v] = 0;
                for (int j = 0; j < SPOT_NT; ++j)
                    nk[v] += K[v * SPOT_NT + j];
            }
            for (int i = 0; i < SPOT_NA; ++i) {
                const double *a = A + (size_t) i * SPOT_NT;
                double f[SPOT_NV] = { 0 }, dev = 0;
                for (int v = 0; v < nv; ++v) {
                    for (int j = 0; j < SPOT_NT; ++j)
                        f[v] += K[v * SPOT_NT + j] * a[j];
                    f[v] = nk[v] > 0 ? f[v] / nk[v] : 0;
                }
                for (int v = 1; v < nv; ++v)
                    dev = fmax(dev, fabs(f[v] - f[0]));
                t->fb[(size_t) ir * SPOT_NA + i] = f[0];
                t->fbe[(size_t) ir * SPOT_NA + i] = dev;
            }
        }
    }
    free(A);
    free(K);
    return rc;
}

/* The spot's averaged share at optical distance r and angle al from the
 * axis, bilinear in log r and the angle, at the table's positions: u =
 * log(r / SPOT_RMIN) in rows, al in columns (node_places); *e its estimate
 * (e NULL: not read). */
EF_INLINE double spot_share_uv(const lms_tab *t, double u, double al, double *e)
{
    if (!(u < SPOT_NR - 1))
        u = SPOT_NR - 1;
    const int i0 = u >= SPOT_NR - 2 ? SPOT_NR - 2 : (int) u;
    const int j0 = al >= SPOT_NA - 2 ? SPOT_NA - 2 : (int) al;
    const double fu = u - i0, fa = al - j0;
    const size_t a = (size_t) i0 * SPOT_NA + j0, b = a + SPOT_NA;
    const double v = (1 - fu) * ((1 - fa) * t->fb[a] + fa * t->fb[a + 1]) +
                     fu * ((1 - fa) * t->fb[b] + fa * t->fb[b + 1]);
    if (e)
        *e = (1 - fu) * ((1 - fa) * t->fbe[a] + fa * t->fbe[a + 1]) +
             fu * ((1 - fa) * t->fbe[b] + fa * t->fbe[b + 1]);
    return v;
}

/* ------------------------------------------- fog that is not uniform */

int ef_lms_is_local(const ef_lms *m)
{
    return m && m->local;
}

int ef_lms_is_spot(const ef_lms *m)
{
    return m && m->spot;
}

int ef_lms_is_scaled(const ef_lms *m)
{
    return m && m->scaled;
}

int ef_lms_same_table(const ef_lms *m, int j, int k)
{
    return m->tab_of[j] == m->tab_of[k];
}

double ef_lms_leak_exposure(const ef_lms *m, const double x[3], int k, double sg)
{
    return m->nleak || m->nstrata || m->nprof ? leak_exposure(m, x, k, sg) : 0;
}

/* A node's value from the field's v0 and its images' vi (image_part):
 * less them, never below 0, times a spot's share at its places sp
 * (node_places). */
EF_INLINE double node_less_images(const ef_lms *m, const lms_tab *tb, double v0, double vi,
                                  const double sp[2])
{
    const double v = vi > 0 ? (v0 - vi > 0 ? v0 - vi : 0) : v0;
    if (!m->spot)
        return v;
    return v * spot_share_uv(tb, sp[0], sp[1], NULL);
}

/* The table's places of four nodes (a lane not live reads 1 and 0, inside
 * every function's domain): U the rows' (tab_rows' u), X the column's
 * (tab_col's x), and a spot's (spot_share_uv's u and al) into sp, by
 * vmath.h's log1p, sqrt, log and atan2 (acos as atan2 of sin and cos, 1 -
 * c^2 as (1 - c)(1 + c), which keeps the digits near the axis). A lane's
 * places are the same bits whatever its neighbours and whichever clone
 * runs (vmath.h), so a node read alone (ef_lms_local_node) and four at a
 * time (ef_lms_local_node4) agree bit for bit. */
EF_INLINE void node_places(const ef_lms *m, const lms_tab *tb, const double tl[4],
                           const double nu[4], const double ca[4], const int live[4], double U[4],
                           double X[4], double sp[4][2])
{
    v4d L, Z, S, C;
    /* (clamps by comparison, as fmin and fmax give them, NaN included:
     * libm's calls from the x86-64-v3 clone cost a transition each) */
    for (int i = 0; i < 4; ++i) {
        const double z = 0.5 * (1 - nu[i]), zc = z < 1 ? z : 1, c = ca[i] < 1 ? ca[i] : 1;
        L[i] = live[i] && tl[i] < 1e300 ? tl[i] * (1 / LMS_RS) : 1;
        Z[i] = live[i] && zc > 0 ? zc : 0;
        S[i] = live[i] ? (tl[i] > SPOT_RMIN ? tl[i] : SPOT_RMIN) * (1 / SPOT_RMIN) : 1;
        C[i] = (live[i] ? (c > -1 ? c : -1) : 1) + 0.0;   /* (-0 to +0) */
    }
    v4d u, x, us = { 0, 0, 0, 0 }, al = us;
    v_log1p(&L, &u);
    u = u * ((tb->nr - 1) / tb->lg);
    v_sqrt(&Z, &x);
    x = x * (tb->nx - 1);
    if (m->spot) {
        v_log(&S, &us);
        us = us * tb->spot_u;
        const v4d s2 = (1.0 - C) * (1.0 + C);
        v4d sn;
        v_sqrt(&s2, &sn);
        v_atan2(&sn, &C, &al);
        al = al / PI * (SPOT_NA - 1);
    }
    for (int i = 0; i < 4; ++i) {
        U[i] = u[i];
        X[i] = x[i];
        sp[i][0] = us[i];
        sp[i][1] = al[i];
    }
}

double ef_lms_local_node(const ef_lms *m, int k, double tl, double sg, double d, double nu,
                         double ca, const double x[3], double expo, double *est)
{
    if (est)
        *est = 0;
    const int t = m->tab_of[k];
    if (t < 0 || !(sg > 0) || !(tl > 0) || !(d > 0))
        return 0;
    const lms_tab *tb = &m->tab[t];
    double ev;
    /* the light's optical distance from the lamp, its mean extinction
     * tl / d for the 1 / d^2 that sets the field's scale; and the local
     * medium's own scale instead: the spread of the two is the estimate of
     * what a field that is not symmetric about the lamp does */
    const double sd = sg * d;
    /* the places as ef_lms_local_node4 takes them, lane 0 of four */
    const double tl4[4] = { tl }, nu4[4] = { nu }, ca4[4] = { ca };
    const int live[4] = { 1 };
    double U[4], X[4], sp[4][2];
    node_places(m, tb, tl4, nu4, ca4, live, U, X, sp);
    int col;
    double fx;
    tab_col_at(tb->nx, X[0], &col, &fx);
    /* tl's rows serve the value and the view's mean; sd's are tl's in
     * uniform fog, where the two distances agree to rounding */
    double wt[4];
    int r0 = 0;
    const int in = tl < 1e300 && U[0] <= tb->nr - 1;
    if (in)
        rows4(U[0], tb->nr, &r0, wt);
    ev = 0;
    /* less the images' field where the fog ends at planes (lamp_images) */
    const double vi = x && m->nimg ? image_part(m, tb, k, tl, sg, d, x) : 0;
    if (!est) {   /* the value alone: no estimate's reads */
        const double v = in ? sg * tl * tab_sum(tb->q, tb->nx, r0, wt, col, fx, NULL, NULL) : 0;
        return node_less_images(m, tb, v, vi, sp[0]);
    }
    const double v0 = in ? sg * tl * tab_sum(tb->q, tb->nx, r0, wt, col, fx, &ev, tb->e) : 0;
    const double v = vi > 0 ? fmax(0, v0 - vi) : v0, fac = v0 > 0 ? v / v0 : 1;
    const double wl = fabs(sd - tl) <= 1e-12 * tl
                          ? v
                          : fac * sg * sd *
                                tab_row(tb->q, tb->nr, tb->nx, tb->lg, sd, col, fx, NULL, NULL);
    *est = fabs(v - wl) + sg * tl * ev * fac;
    /* light the unbounded fog's field scatters back from beyond a plane
     * where this fog drops, seen from the node and from the lamp: the more,
     * the further the light wanders (the diffusion length grows as
     * (1 - albedo)^-1/2) */
    if (m->nleak || m->nstrata || m->nprof)   /* (on the field before its images) */
        *est += m->leak_w[k] * fabs(v0) * fmin(1, expo + m->lamp_leak[k]);
    if (m->spot) {   /* the cone's share where the light first scattered */
        double fe;
        const double f = spot_share_uv(tb, sp[0][0], sp[0][1], &fe);
        *est = *est * f + fabs(v) * fe;
        /* the view's dependence is the point lamp's, whose light at the
         * node travels out from the lamp; a spot's may come from its
         * beam, across: what the view would take from light of no
         * preferred direction, the table's mean, bounds the spread */
        if (tb->phase != EF_PHASE_ISO && tb->g != 0)
            *est += f * fabs(v - fac * (in ? sg * tl * tab_sum(tb->qb, 2, r0, wt, 0, 0, NULL, NULL)
                                           : 0));
        return v * f;
    }
    return v;
}

EF_MULTIVERSION void ef_lms_local_node4(const ef_lms *m, int k, const double tl[4],
                                        const double sg[4], const double d[4],
                                        const double nu[4], const double ca[4],
                                        const double (*x)[3], double f[4])
{
    const int t = m->tab_of[k];
    int live[4], any = 0;
    for (int i = 0; i < 4; ++i) {
        f[i] = 0;
        live[i] = t >= 0 && sg[i] > 0 && tl[i] > 0 && d[i] > 0;
        any |= live[i];
    }
    if (!any)
        return;
    const lms_tab *tb = &m->tab[t];
    double U[4], X[4], sp[4][2];
    node_places(m, tb, tl, nu, ca, live, U, X, sp);
    for (int i = 0; i < 4; ++i) {
        if (!live[i])
            continue;
        double v0 = 0, wt[4], fx;
        int r0, col;
        if (tl[i] < 1e300 && U[i] <= tb->nr - 1) {
            rows4(U[i], tb->nr, &r0, wt);
            tab_col_at(tb->nx, X[i], &col, &fx);
            v0 = sg[i] * tl[i] * tab_sum(tb->q, tb->nx, r0, wt, col, fx, NULL, NULL);
        }
        const double vi = x && m->nimg ? image_part(m, tb, k, tl[i], sg[i], d[i], x[i]) : 0;
        f[i] = node_less_images(m, tb, v0, vi, sp[i]);
    }
}
