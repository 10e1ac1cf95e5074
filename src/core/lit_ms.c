/* Multiple scattering of a sun or a sky light in fog that is the same
 * along the ground: the plane-parallel solve and the view's gather (ms.h
 * says what is computed and how far it may be off). */
#include "ms.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "lit_int.h"
#include "sky_light.h"
#include "vmath.h"

/* A mode is iterated order by order while its scattering operator's norm
 * (on the node directions) is below this; else solved directly. */
#define MS_ITER_KAPPA 0.9
/* Iterated modes stop where the bound of the orders left out falls below
 * this fraction of the mode's single-scatter source. */
#define MS_TAIL_REL 1e-7
/* The largest |g| solved: 32 directions per hemisphere (64 Legendre
 * terms) hold g 0.95 within 1 % of 64 directions; at 0.98 they fail. */
#define MS_G_MAX 0.95
/* The deepest vertical optical depth solved without a ground. */
#define MS_TAU_DEEP 1e4
/* The table keeps a depth node unless linear interpolation across at most
 * MS_THIN_SPAN nodes reproduces it within MS_THIN (relative). */
#define MS_THIN 1e-3
#define MS_THIN_SPAN 16
/* The fewest directions per hemisphere a solve takes. */
#define MS_NH_MIN 8
/* The direction table: MS_NT values of the propagation direction's
 * sin(theta / 2) (theta its angle from up), uniform over [0, 1]; a sun's
 * MS_NP values of sin(phi / 2) (phi its azimuth from the beam's, [0, pi]:
 * fine where the forward peak is), a sky's MS_NPF azimuths over the full
 * circle; no inverse cosine per pixel for a sun. */
#define MS_NT 121
#define MS_NP 61
#define MS_NPF 120

/* ------------------------------------------------------------ helpers */

/* 1 - (1 - e^-x) / x, the weight of the far end of a linear source over
 * an optical depth x (series where the difference cancels). */
static double w_far(double x)
{
    if (x < 1e-3)
        return x * (0.5 - x * (1.0 / 6 - x * (1.0 / 24 - x / 120)));
    return 1 + expm1(-x) / x;
}

/* Gauss-Legendre nodes and weights on [0, 1], n of them. */
static void gauss01(int n, double *x, double *w)
{
    for (int i = 0; i < n; ++i) {
        double z = cos(PI * (i + 0.75) / (n + 0.5)), dp = 1;
        for (int it = 0; it < 100; ++it) {
            double p0 = 1, p1 = z;
            for (int l = 2; l <= n; ++l) {
                const double p2 = ((2 * l - 1) * z * p1 - (l - 1) * p0) / l;
                p0 = p1;
                p1 = p2;
            }
            dp = n * (z * p1 - p0) / (z * z - 1);
            const double dz = p1 / dp;
            z -= dz;
            if (fabs(dz) < 1e-16)
                break;
        }
        x[i] = 0.5 * (1 + z);
        w[i] = 1 / ((1 - z * z) * dp * dp);   /* 2 / (...) on [-1, 1], halved */
    }
}

void ef_ms_directions(int n, double *x, double *w)
{
    gauss01(n, x, w);
}

/* Lambda_l^m(mu) = sqrt((l-m)!/(l+m)!) P_l^m(mu) for l = m..L-1 into
 * out[l] (out[l] = 0 for l < m). */
static void lambda_m(int m, int L, double mu, double *out)
{
    for (int l = 0; l < m && l < L; ++l)
        out[l] = 0;
    if (m >= L)
        return;
    double s = 1;
    const double st = sqrt(fmax(0, 1 - mu * mu));
    for (int i = 1; i <= m; ++i)
        s *= sqrt((2.0 * i - 1) / (2.0 * i)) * st;
    out[m] = s;
    if (m + 1 < L)
        out[m + 1] = sqrt(2.0 * m + 1) * mu * s;
    for (int l = m + 2; l < L; ++l)
        out[l] = ((2.0 * l - 1) * mu * out[l - 1] -
                  sqrt((double) (l + m - 1) * (l - m - 1)) * out[l - 2]) /
                 sqrt((double) (l + m) * (l - m));
}

void ef_ms_legendre(int L, double x, double *P)
{
    lambda_m(0, L, x, P);
}

/* ------------------------------------------------------------ the solve */

struct ef_ms_solve {
    int n, nh, N, L;
    double *tau;      /* [n] */
    double *a;        /* [n][L]: omega b_l */
    double *M;        /* [2 parities][L modes][n][L]: sum_j w_j Lambda_l^m(mu_j) L^m(k, j),
                       * the cos m phi modes, then (full) the sin m phi ones */
    int full;         /* sin modes too: a sky, not symmetric about any plane */
    double tail;      /* bound of the orders left out, summed over modes */
    int direct, iterated;
};

/* What a mode's solve works with. */
typedef struct mode_ws {
    int n, nh, N, L, m;
    const double *tau, *mu, *w;
    double *lam;        /* [N][L]: Lambda_l^m at the node directions */
    double *C;          /* [n or 1][N][N] */
    int cstride;        /* N*N, or 0 when every node shares one C */
    double *Q;          /* [n][N] the first-order source */
    double *cE, *cA, *cB;   /* [n-1][nh] cell weights */
} mode_ws;

/* L = the transport of source S (both [n][N]) with top[i] (NULL: 0)
 * entering at the top in downward direction nh + i and nothing at the
 * bottom. */
static void transport(const mode_ws *w, const double *S, const double *top, double *Lr)
{
    const int n = w->n, N = w->N, nh = w->nh;
    for (int i = 0; i < nh; ++i) {   /* up: from the bottom */
        Lr[(n - 1) * N + i] = 0;
        for (int k = n - 2; k >= 0; --k) {
            const int c = k * nh + i;
            Lr[k * N + i] = w->cE[c] * Lr[(k + 1) * N + i] + w->cA[c] * S[(k + 1) * N + i] +
                            w->cB[c] * S[k * N + i];
        }
    }
    for (int i = nh; i < N; ++i) {   /* down: from the top */
        Lr[i] = top ? top[i - nh] : 0;
        for (int k = 0; k + 1 < n; ++k) {
            const int c = k * nh + (i - nh);
            Lr[(k + 1) * N + i] = w->cE[c] * Lr[k * N + i] + w->cA[c] * S[k * N + i] +
                                  w->cB[c] * S[(k + 1) * N + i];
        }
    }
}

/* S = C L per node (both [n][N]). */
static void scatter(const mode_ws *w, const double *Lr, double *S)
{
    const int N = w->N;
    for (int k = 0; k < w->n; ++k) {
        const double *C = w->C + (size_t) k * w->cstride, *x = Lr + (size_t) k * N;
        double *y = S + (size_t) k * N;
        for (int i = 0; i < N; ++i) {
            double v = 0;
            for (int j = 0; j < N; ++j)
                v += C[i * N + j] * x[j];
            y[i] = v;
        }
    }
}

/* The largest magnitude of v[0..n). */
static double sup(const double *v, size_t n)
{
    double m = 0;
    for (size_t i = 0; i < n; ++i)
        m = fmax(m, fabs(v[i]));
    return m;
}

/* The mode's diffuse radiance of every order into Lr ([n][N]), directly:
 * one banded system, its rows ordered so that each unknown's own
 * coefficient is on the diagonal (diagonally dominant for omega <= 1 and
 * a positive kernel, so elimination needs no pivots). Returns 0, or -1
 * (out of memory). */
static int solve_direct(const mode_ws *w, const double *top, double *Lr)
{
    const int n = w->n, N = w->N, nh = w->nh;
    const long nt = (long) n * N;
    const int kl = 2 * N - 1, ku = 2 * N - 1, W = kl + ku + 1;
    double *A = calloc((size_t) nt * (size_t) W, sizeof *A);
    if (!A)
        return -1;
#define AT(r, c) A[(size_t) (r) * (size_t) W + (size_t) ((c) - (r) + kl)]
    for (int k = 0; k < n; ++k)
        for (int i = 0; i < N; ++i) {
            const long r = (long) k * N + i;
            const int up = i < nh;
            double *rhs = &Lr[r];
            *rhs = 0;
            AT(r, r) = 1;
            if ((up && k == n - 1) || (!up && k == 0)) {
                if (!up && top)   /* what enters at the top */
                    *rhs = top[i - nh];
                continue;
            }
            /* the cell that ends at k: from s (its start) to k */
            const int s = up ? k + 1 : k - 1, cell = up ? k : k - 1;
            const int ci = cell * nh + (up ? i : i - nh);
            const double E = w->cE[ci], Aw = w->cA[ci], Bw = w->cB[ci];
            const double *Cs = w->C + (size_t) s * w->cstride + (size_t) i * N;
            const double *Ce = w->C + (size_t) k * w->cstride + (size_t) i * N;
            AT(r, (long) s * N + i) -= E;
            for (int j = 0; j < N; ++j) {
                AT(r, (long) s * N + j) -= Aw * Cs[j];
                AT(r, (long) k * N + j) -= Bw * Ce[j];
            }
            *rhs = Aw * w->Q[s * N + i] + Bw * w->Q[k * N + i];
        }
    for (long c = 0; c < nt; ++c) {
        const double piv = AT(c, c);
        const long rend = c + kl < nt - 1 ? c + kl : nt - 1;
        const long cend = c + ku < nt - 1 ? c + ku : nt - 1;
        for (long r = c + 1; r <= rend; ++r) {
            const double f = AT(r, c) / piv;
            if (f == 0)
                continue;
            for (long cc = c + 1; cc <= cend; ++cc)
                AT(r, cc) -= f * AT(c, cc);
            Lr[r] -= f * Lr[c];
        }
    }
    for (long r = nt - 1; r >= 0; --r) {
        double v = Lr[r];
        const long cend = r + ku < nt - 1 ? r + ku : nt - 1;
        for (long cc = r + 1; cc <= cend; ++cc)
            v -= AT(r, cc) * Lr[cc];
        Lr[r] = v / AT(r, r);
    }
#undef AT
    free(A);
    return 0;
}

void ef_ms_solve_free(ef_ms_solve *so)
{
    if (!so)
        return;
    free(so->tau);
    free(so->a);
    free(so->M);
    free(so);
}

ef_ms_solve *ef_ms_slab_solve(const ef_ms_slab *sl, const ef_ms_res *res, ef_ms_flux *flux)
{
    const int n = sl->n, nh = res->nh, N = 2 * nh, L = N;
    ef_ms_solve *so = calloc(1, sizeof *so);
    if (!so || n < 2)
        return free(so), NULL;
    so->n = n;
    so->nh = nh;
    so->N = N;
    so->L = L;
    so->tau = malloc((size_t) n * sizeof *so->tau);
    so->a = calloc((size_t) n * L, sizeof *so->a);
    so->full = sl->top != NULL;
    so->M = calloc((size_t) 2 * L * n * L, sizeof *so->M);
    double *xg = malloc(sizeof(double) * (size_t) nh), *wg = malloc(sizeof(double) * (size_t) nh);
    double *mu = malloc(sizeof(double) * (size_t) N), *wt = malloc(sizeof(double) * (size_t) N);
    mode_ws w = { .n = n, .nh = nh, .N = N, .L = L };
    int shared = 1;
    for (int k = 1; k < n && shared; ++k)
        for (int l = 0; l < sl->nl && shared; ++l)
            shared = sl->a[k * sl->nl + l] == sl->a[l];
    w.cstride = shared ? 0 : N * N;
    w.lam = malloc(sizeof(double) * (size_t) N * L);
    w.C = malloc(sizeof(double) * (size_t) (shared ? 1 : n) * N * N);
    w.Q = malloc(sizeof(double) * (size_t) n * N);
    w.cE = malloc(sizeof(double) * (size_t) (n - 1) * nh);
    w.cA = malloc(sizeof(double) * (size_t) (n - 1) * nh);
    w.cB = malloc(sizeof(double) * (size_t) (n - 1) * nh);
    double *Lr = malloc(sizeof(double) * (size_t) n * N), *Ln = malloc(sizeof(double) * (size_t) n * N);
    double *S = malloc(sizeof(double) * (size_t) n * N), *lb = malloc(sizeof(double) * (size_t) L);
    int ok = so->tau && so->a && so->M && xg && wg && mu && wt && w.lam && w.C && w.Q && w.cE &&
             w.cA && w.cB && Lr && Ln && S && lb;
    if (!ok)
        goto done;
    memcpy(so->tau, sl->tau, (size_t) n * sizeof *so->tau);
    for (int k = 0; k < n; ++k)
        for (int l = 0; l < L && l < sl->nl; ++l)
            so->a[k * L + l] = sl->a[k * sl->nl + l];
    gauss01(nh, xg, wg);
    for (int i = 0; i < nh; ++i) {
        mu[i] = xg[i];
        mu[nh + i] = -xg[i];
        wt[i] = wt[nh + i] = wg[i];
    }
    w.tau = so->tau;
    w.mu = mu;
    w.w = wt;
    for (int k = 0; k + 1 < n; ++k) {
        const double dt = so->tau[k + 1] - so->tau[k];
        for (int i = 0; i < nh; ++i) {
            const double x = dt / xg[i];
            w.cE[k * nh + i] = exp(-x);
            w.cB[k * nh + i] = w_far(x);
            w.cA[k * nh + i] = -expm1(-x) - w.cB[k * nh + i];
        }
    }
    if (flux)
        flux->up_top = flux->down_bottom = 0;
    for (int mp = 0; mp < 2 * L; ++mp) {
        /* mode m, parity cs (0: cos m phi, 1: sin m phi; the beam's light
         * is symmetric about its plane and has cos modes only) */
        const int m = mp % L, cs = mp / L;
        if (cs && (!so->full || m == 0))
            continue;
        const double *top = sl->top ? sl->top + (size_t) (m * 2 + cs) * nh : NULL;
        w.m = m;
        for (int i = 0; i < N; ++i)
            lambda_m(m, L, mu[i], w.lam + (size_t) i * L);
        lambda_m(m, L, -sl->mu_s, lb);
        /* C_k[i][j] = 1/2 sum_l (2l + 1) a_l Lambda_l^m(mu_i) Lambda_l^m(mu_j) w_j */
        for (int k = 0; k < (shared ? 1 : n); ++k) {
            const double *a = so->a + (size_t) k * L;
            double *C = w.C + (size_t) k * N * N;
            for (int i = 0; i < N; ++i)
                for (int j = 0; j < N; ++j) {
                    double v = 0;
                    for (int l = m; l < L; ++l)
                        v += (2 * l + 1) * a[l] * w.lam[i * L + l] * w.lam[j * L + l];
                    C[i * N + j] = 0.5 * v * wt[j];
                }
        }
        /* the beam's first scattering: E e^(-tau/mu_s) p / 4 pi per mode */
        const double fm = (m == 0 ? 1.0 : 2.0) / (4 * PI);
        for (int k = 0; k < n; ++k) {
            const double *a = so->a + (size_t) k * L;
            const double beam = cs || !(sl->E > 0) ? 0 : sl->E * exp(-so->tau[k] / sl->mu_s);
            for (int i = 0; i < N; ++i) {
                double v = 0;
                for (int l = m; l < L; ++l)
                    v += (2 * l + 1) * a[l] * w.lam[i * L + l] * lb[l];
                w.Q[k * N + i] = fm * beam * v;
            }
        }
        const double qn = fmax(sup(w.Q, (size_t) n * N), top ? sup(top, (size_t) nh) : 0);
        if (qn == 0)
            continue;
        double kappa = 0;
        for (int k = 0; k < (shared ? 1 : n); ++k)
            for (int i = 0; i < N; ++i) {
                double r = 0;
                for (int j = 0; j < N; ++j)
                    r += fabs(w.C[(size_t) k * N * N + i * N + j]);
                kappa = fmax(kappa, r);
            }
        if (res->max_order > 0 || kappa < MS_ITER_KAPPA) {
            /* order by order: L_1 from the beam's source and the sky's
             * light as it enters (its uncollided part), J_(n+1) = C L_n */
            memset(Lr, 0, sizeof(double) * (size_t) n * N);
            memcpy(S, w.Q, sizeof(double) * (size_t) n * N);
            double left = 0;
            for (int order = 1;; ++order) {
                transport(&w, S, order == 1 ? top : NULL, Ln);
                for (size_t q = 0; q < (size_t) n * N; ++q)
                    Lr[q] += Ln[q];
                scatter(&w, Ln, S);   /* J_(order + 1) */
                const double sn = sup(S, (size_t) n * N);
                if (res->max_order > 0) {
                    if (order + 1 >= res->max_order)
                        break;
                } else if (sn * kappa / (1 - kappa) <= MS_TAIL_REL * qn || order > 10000) {
                    left = sn * kappa / (1 - kappa);
                    break;
                }
            }
            so->tail += left;
            so->iterated++;
        } else {
            if (solve_direct(&w, top, Lr)) {
                ok = 0;
                goto done;
            }
            so->direct++;
        }
        if (flux && m == 0 && cs == 0)
            for (int i = 0; i < nh; ++i) {
                flux->up_top += 2 * PI * wt[i] * mu[i] * Lr[i];
                flux->down_bottom += 2 * PI * wt[nh + i] * xg[i] * Lr[(n - 1) * N + nh + i];
            }
        /* the moments the view's source is formed from */
        for (int k = 0; k < n; ++k) {
            double *Mk = so->M + ((size_t) mp * n + k) * L;
            for (int l = m; l < L; ++l) {
                double v = 0;
                for (int j = 0; j < N; ++j)
                    v += wt[j] * w.lam[j * L + l] * Lr[k * N + j];
                Mk[l] = v;
            }
        }
    }
done:
    free(xg);
    free(wg);
    free(mu);
    free(wt);
    free(w.lam);
    free(w.C);
    free(w.Q);
    free(w.cE);
    free(w.cA);
    free(w.cB);
    free(Lr);
    free(Ln);
    free(S);
    free(lb);
    if (!ok) {
        ef_ms_solve_free(so);
        return NULL;
    }
    return so;
}

/* Lambda_l^m(mu) for every m, l < L into lam[m * L + l]. */
static void lambda_all(int L, double mu, double *lam)
{
    for (int m = 0; m < L; ++m)
        lambda_m(m, L, mu, lam + (size_t) m * L);
}

/* J's azimuthal modes at node k into jm[0..L-1] (cos m phi) and, for a
 * full solve, jm[L..2L-1] (sin m phi), lam from lambda_all at the
 * direction's propagation cosine. */
static void eval_modes(const ef_ms_solve *so, int k, const double *lam, double *jm)
{
    const int L = so->L, n = so->n;
    const double *a = so->a + (size_t) k * L;
    for (int mp = 0; mp < (so->full ? 2 * L : L); ++mp) {
        const int m = mp % L;
        const double *Mk = so->M + ((size_t) mp * n + k) * L, *lm = lam + (size_t) m * L;
        double v = 0;
        for (int l = m; l < L; ++l)
            v += (2 * l + 1) * a[l] * lm[l] * Mk[l];
        jm[mp] = 0.5 * v;
    }
}

double ef_ms_slab_eval(const ef_ms_solve *so, int k, double mu, double dphi)
{
    double jm[256];
    double *lam = calloc((size_t) so->L * so->L, sizeof *lam);
    if (!lam || so->L > 128 || k < 0 || k >= so->n)
        return free(lam), NAN;
    lambda_all(so->L, mu, lam);
    eval_modes(so, k, lam, jm);
    free(lam);
    double v = 0;
    for (int m = 0; m < so->L; ++m)
        v += jm[m] * cos(m * dphi) + (so->full ? jm[so->L + m] * sin(m * dphi) : 0);
    return v;
}

double ef_ms_slab_tail(const ef_ms_solve *so)
{
    return so->tail;
}

/* ------------------------------------------------ the scene's solve */

/* One depth table: J (per unit irradiance) and its error estimate at each
 * node, polar angle and azimuth, and the largest J + error from each node
 * down (the gather's early stop). */
typedef struct ms_tab {
    int n;
    double *invd;    /* [n - 1]: 1 / (tau[k + 1] - tau[k]) */
    double jmax;     /* the largest J + error: what a cut-off walk leaves */
    double *tau;
    float *v;        /* [MS_NT][np][2][n]: a direction's J at its nodes, then their estimates */
} ms_tab;

struct ef_ms {
    _Atomic int refs;
    double up[3], bh[3], e2[3];   /* bh: the azimuths' origin (a sky: e2 = up x bh) */
    int has_bh;
    int full;                     /* a sky: azimuths over [0, 2 pi) */
    double E[3];
    int tab_of[3];
    int ntab;
    ms_tab tab[3];
    ef_ms_info info;
    ef_vms *vol;                  /* a box or convex volume's solve instead (lit_vms.c) */
};

void ef_ms_ref(ef_ms *m)
{
    if (m)
        atomic_fetch_add(&m->refs, 1);
}

void ef_ms_unref(ef_ms *m)
{
    if (!m || atomic_fetch_sub(&m->refs, 1) != 1)
        return;
    for (int t = 0; t < m->ntab; ++t) {
        free(m->tab[t].invd);
        free(m->tab[t].tau);
        free(m->tab[t].v);
    }
    ef_vms_free(m->vol);
    free(m);
}

void ef_ms_get_info(const ef_ms *m, ef_ms_info *info)
{
    if (m)
        *info = m->info;
    else
        memset(info, 0, sizeof *info);
}

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The Legendre coefficients b_0..b_{L-1} of phase function (phase, g). */
void ef_ms_phase_legendre(int phase, double g, int L, double *b)
{
    for (int l = 0; l < L; ++l)
        b[l] = 0;
    b[0] = 1;
    if (phase == EF_PHASE_HG) {
        for (int l = 1; l < L; ++l)
            b[l] = b[l - 1] * g;
    } else if (phase == EF_PHASE_RAYLEIGH) {
        if (L > 2)
            b[2] = 0.1;
    } else if (phase == EF_PHASE_CS) {
        /* b_l = 2 pi int p(x) P_l(x) dx, by 256-point Gauss over each half */
        enum { NQ = 256 };
        double x[NQ], w[NQ], P[128];
        gauss01(NQ, x, w);
        for (int l = 1; l < L; ++l)
            b[l] = 0;
        for (int h = 0; h < 2; ++h)
            for (int q = 0; q < NQ; ++q) {
                const double c = h ? x[q] : -x[q], f = 2 * PI * w[q] * ef_phase_eval(phase, g, c);
                ef_ms_legendre(L < 128 ? L : 128, c, P);
                for (int l = 1; l < L && l < 128; ++l)
                    b[l] += f * P[l];
            }
    }
}

/* Vertical optical depth per channel from height h (along up) to the top. */
static void vtau(const ef_fog_scene *s, const double up[3], double h, double t[3])
{
    const double p[3] = { h * up[0], h * up[1], h * up[2] };
    ef_lit_tau_from(s, p, up, INFINITY, t);
}

/* The height where channel k's vertical optical depth reaches tau (tau
 * non-increasing in height), by bisection between lo and hi. */
static double height_at(const ef_fog_scene *s, const double up[3], int k, double tau, double lo,
                        double hi)
{
    for (int it = 0; it < 200 && hi - lo > 1e-12 * (1 + fabs(lo) + fabs(hi)); ++it) {
        const double mid = 0.5 * (lo + hi);
        double t[3];
        vtau(s, up, mid, t);
        if (t[k] >= tau)
            lo = mid;
        else
            hi = mid;
    }
    return 0.5 * (lo + hi);
}

/* Depth nodes from 0 to tb, spacing h0 + r d, d the depth from the nearer
 * end (the top, or a ground within MS_TAU_DEEP: the diffuse light has a
 * boundary layer at each, as thin as the grazing directions' cosines);
 * returns how many, into *out (malloc'd), or -1. */
static int depth_grid(double tb, double h0, double r, int ground, double **out)
{
    int cap = 64, n = 0;
    double *t = malloc(sizeof *t * (size_t) cap), x = 0;
    if (!t)
        return -1;
    t[n++] = 0;
    while (x < tb) {
        const double d = ground ? fmin(x, tb - x) : x;
        x += h0 + r * d;
        const double hn = h0 + r * (ground ? fmin(x, fmax(0, tb - x)) : x);
        if (x > tb * (1 - 1e-9) || tb - x < 0.3 * hn)
            x = tb;
        if (n == cap) {
            double *nt = realloc(t, sizeof *t * (size_t) (cap *= 2));
            if (!nt)
                return free(t), -1;
            t = nt;
        }
        t[n++] = x;
    }
    *out = t;
    return n;
}

/* The per-node omega b_l of channel k at the nodes tau (nl terms) into a. */
static void node_coeffs(const ef_fog_scene *s, const double up[3], int k, const double *tau, int n,
                        int nl, double hlo, double hhi, double *a)
{
    double bl[EF_FOG_MAX_COMPONENTS][128];
    for (int c = 0; c < s->ncomp; ++c)
        ef_ms_phase_legendre(s->comp[c].phase, s->comp[c].g, nl, bl[c]);
    for (int i = 0; i < n; ++i) {
        double *ai = a + (size_t) i * nl;
        memset(ai, 0, sizeof *ai * (size_t) nl);
        if (s->ncomp == 1) {
            for (int l = 0; l < nl; ++l)
                ai[l] = albedo(&s->comp[0], k) * bl[0][l];
            continue;
        }
        /* a mixture: each component's share of the extinction at the
         * node's height, from its optical depth over a short vertical step */
        const double h = height_at(s, up, k, tau[i], hlo, hhi), d = 1e-6 * (1 + fabs(h));
        const double p[3] = { (h - d) * up[0], (h - d) * up[1], (h - d) * up[2] };
        ef_ray r = { { up[0], up[1], up[2] }, 2 * d, 2 * d, { p[0], p[1], p[2] } };
        double sum = 0, w[EF_FOG_MAX_COMPONENTS];
        for (int c = 0; c < s->ncomp; ++c) {
            double t[3];
            s->comp[c].model->tau(&s->comp[c], &r, t);
            w[c] = isfinite(t[k]) ? t[k] : 0;
            sum += w[c];
        }
        for (int c = 0; c < s->ncomp && sum > 0; ++c)
            for (int l = 0; l < nl; ++l)
                ai[l] += w[c] / sum * albedo(&s->comp[c], k) * bl[c][l];
        if (!(sum > 0))
            ai[0] = NAN;   /* no fog at the node's height (the top, a gap): filled below */
    }
    /* a node where the fog has no density (tau = 0 at the top lies above
     * it) takes the mixture just below it, the nearest node's that has one */
    for (int i = n - 2; i >= 0; --i)
        if (isnan(a[(size_t) i * nl]) && !isnan(a[(size_t) (i + 1) * nl]))
            memcpy(a + (size_t) i * nl, a + (size_t) (i + 1) * nl, sizeof *a * (size_t) nl);
    for (int i = 1; i < n; ++i)
        if (isnan(a[(size_t) i * nl]))
            memcpy(a + (size_t) i * nl, a + (size_t) (i - 1) * nl, sizeof *a * (size_t) nl);
    for (int i = 0; i < n; ++i)
        if (isnan(a[(size_t) i * nl]))
            memset(a + (size_t) i * nl, 0, sizeof *a * (size_t) nl);
}

/* The table's azimuths: a sun's over [0, pi] (its light is symmetric
 * about the beam's plane) at sin(phi / 2) = j / (MS_NP - 1); a sky's over
 * [0, 2 pi) at 2 pi j / MS_NPF, periodic. */
static int np_of(int full)
{
    return full ? MS_NPF : MS_NP;
}

static double phi_of(int full, int j)
{
    return full ? 2 * PI * j / MS_NPF : 2 * asin((double) j / (MS_NP - 1));
}

/* The direction table of solve so at its nodes: [n][MS_NT][np]. */
static float *dir_table(const ef_ms_solve *so)
{
    const int L = so->L, np = np_of(so->full), nm = so->full ? 2 * L : L;
    float *v = malloc(sizeof *v * (size_t) so->n * MS_NT * np);
    double *lam = malloc(sizeof *lam * (size_t) MS_NT * L * L);
    double *cs = malloc(sizeof *cs * (size_t) np * 2 * L);
    double jm[256];
    if (!v || !lam || !cs || L > 128) {
        free(cs);
        free(lam);
        free(v);
        return NULL;
    }
    for (int j = 0; j < np; ++j)
        for (int m = 0; m < L; ++m) {
            cs[(size_t) j * 2 * L + m] = cos(m * phi_of(so->full, j));
            cs[(size_t) j * 2 * L + L + m] = sin(m * phi_of(so->full, j));
        }
    for (int i = 0; i < MS_NT; ++i)
        lambda_all(L, 1 - 2 * ((double) i / (MS_NT - 1)) * ((double) i / (MS_NT - 1)),
                   lam + (size_t) i * L * L);
    for (int k = 0; k < so->n; ++k)
        for (int i = 0; i < MS_NT; ++i) {
            eval_modes(so, k, lam + (size_t) i * L * L, jm);
            for (int j = 0; j < np; ++j) {
                double x = 0;
                for (int m = 0; m < nm; ++m)
                    x += jm[m] * cs[(size_t) j * 2 * L + m];
                v[((size_t) k * MS_NT + i) * np + j] = (float) x;
            }
        }
    free(cs);
    free(lam);
    return v;
}

/* One channel's table: the solve, a coarser one for the estimate. */
/* A sky's radiance entering at the top for a solve of nh directions per
 * hemisphere, channel k, as ef_ms_slab's top wants it (malloc'd; NULL: out
 * of memory). */
typedef double *(*top_fn)(const void *user, int nh, int k);

static int build_tab(const ef_fog_scene *s, const double up[3], int k, double mu_s, double E,
                     top_fn topf, const void *user, double tb, int ground, double hlo,
                     double hhi, int nh, ms_tab *tab, ef_ms_info *info)
{
    int nl = 2 * nh, ok = 0;
    const double h0 = 0.02 * fmin(1, 4 * mu_s), r = 0.08;
    double *tf = NULL, *tc = NULL, *af = NULL, *ac = NULL;
    ef_ms_solve *sf = NULL, *sc = NULL;
    float *vf = NULL, *vc = NULL, *ef = NULL;
    double *topf_f = NULL, *topf_c = NULL;
    int *keep = NULL;
    const int nf = depth_grid(tb, h0, r, ground, &tf), nc = depth_grid(tb, 2 * h0, 2 * r, ground, &tc);
    const int nhc = nh * 2 / 3 > 4 ? nh * 2 / 3 : 4;
    if (nf < 0 || nc < 0)
        goto out;
    af = malloc(sizeof *af * (size_t) nf * nl);
    ac = malloc(sizeof *ac * (size_t) nc * nl);
    if (!af || !ac)
        goto out;
    node_coeffs(s, up, k, tf, nf, nl, hlo, hhi, af);
    node_coeffs(s, up, k, tc, nc, nl, hlo, hhi, ac);
    if (topf && (!(topf_f = topf(user, nh, k)) || !(topf_c = topf(user, nhc, k))))
        goto out;
    const ef_ms_slab slf = { nf, tf, af, nl, mu_s, E, topf_f };
    const ef_ms_slab slc = { nc, tc, ac, nl, mu_s, E, topf_c };
    const ef_ms_res rf = { nh, 0 }, rc = { nhc, 0 };
    sf = ef_ms_slab_solve(&slf, &rf, NULL);
    sc = ef_ms_slab_solve(&slc, &rc, NULL);
    if (!sf || !sc || !(vf = dir_table(sf)) || !(vc = dir_table(sc)))
        goto out;
    const int full = sf->full, np = np_of(full);
    const size_t plane = (size_t) MS_NT * np;
    ef = malloc(sizeof *ef * (size_t) nf * plane);
    keep = malloc(sizeof *keep * (size_t) nf);
    if (!ef || !keep)
        goto out;
    double jmax = 0, dmax = 0;
    int kc = 0;
    for (int q = 0; q < nf; ++q) {
        while (kc + 2 < nc && tc[kc + 1] < tf[q])
            ++kc;
        const double f = (tf[q] - tc[kc]) / (tc[kc + 1] - tc[kc]);
        const float *vq = vf + q * plane;
        for (int i = 0; i < MS_NT; ++i)
            for (int j = 0; j < np; ++j) {
                const size_t d = (size_t) i * np + j;
                const double J = vq[d];
                const double Jc = (1 - f) * vc[kc * plane + d] + f * vc[(kc + 1) * plane + d];
                /* the bilinear table's own error, from its second differences
                 * (a sun's azimuth mirrors at 0 and pi, a sky's wraps) */
                const int jm = full ? (j + np - 1) % np : j > 0 ? j - 1 : 1;
                const int jp = full ? (j + 1) % np : j + 1 < np ? j + 1 : np - 2;
                double d2 = fabs(vq[i * np + jm] - 2 * J + vq[i * np + jp]);
                if (i > 0 && i + 1 < MS_NT)
                    d2 += fabs(vq[(i - 1) * np + j] - 2 * J + vq[(i + 1) * np + j]);
                /* and the linear interpolation between depth nodes, from
                 * the second derivative the neighbours give */
                if (q > 0 && q + 1 < nf) {
                    const double hm = tf[q] - tf[q - 1], hp = tf[q + 1] - tf[q];
                    const double J2 = 2 * ((vf[(q + 1) * plane + d] - J) / hp -
                                           (J - vf[(q - 1) * plane + d]) / hm) / (hm + hp);
                    d2 += fabs(J2) * fmax(hm, hp) * fmax(hm, hp);
                }
                ef[q * plane + d] = (float) (fabs(J - Jc) + d2 / 8 + sf->tail);
                jmax = fmax(jmax, J);
                dmax = fmax(dmax, fabs(J - Jc));
            }
    }
    /* The gather walks the nodes the table keeps: drop those that linear
     * interpolation between their neighbours kept reproduces within
     * MS_THIN of the larger end (or 1e-6 of the largest J), in every
     * direction; what they would have changed is added to the kept ends'
     * estimates. */
    int nk = 0;
    keep[nk++] = 0;
    for (int a = 0; a < nf - 1;) {
        int b = a + 1;
        while (b + 1 < nf && b - a < MS_THIN_SPAN) {
            /* can a reach b + 1 directly? */
            const int c = b + 1;
            int ok2 = 1;
            for (int m = a + 1; m < c && ok2; ++m) {
                const double w = (tf[m] - tf[a]) / (tf[c] - tf[a]);
                const float *va = vf + a * plane, *vm = vf + m * plane, *vcn = vf + c * plane;
                for (size_t d = 0; d < plane; ++d) {
                    const double lin = va[d] + w * (vcn[d] - va[d]);
                    if (fabs(vm[d] - lin) > MS_THIN * fmax(fabs(va[d]), fabs(vcn[d])) + 1e-6 * jmax) {
                        ok2 = 0;
                        break;
                    }
                }
            }
            if (!ok2)
                break;
            b = c;
        }
        /* the dropped nodes' deviation, per direction, onto both ends */
        for (int m = a + 1; m < b; ++m) {
            const double w = (tf[m] - tf[a]) / (tf[b] - tf[a]);
            for (size_t d = 0; d < plane; ++d) {
                const double lin = vf[a * plane + d] + w * (vf[b * plane + d] - vf[a * plane + d]);
                const float dev = (float) fabs(vf[m * plane + d] - lin) + ef[m * plane + d];
                ef[a * plane + d] = fmaxf(ef[a * plane + d], dev);
                ef[b * plane + d] = fmaxf(ef[b * plane + d], dev);
            }
        }
        keep[nk++] = b;
        a = b;
    }
    /* slack past the last row and node: the gather loads nodes four at a
     * time, the lanes past a walk's end unused */
    tab->v = calloc((size_t) nk * plane * 2 + 8, sizeof *tab->v);
    tab->tau = calloc((size_t) nk + 8, sizeof *tab->tau);
    tab->invd = calloc((size_t) nk + 8, sizeof *tab->invd);
    if (!tab->v || !tab->tau || !tab->invd)
        goto out;
    tab->n = nk;
    for (int q = 0; q + 1 < nk; ++q)
        tab->invd[q] = 1 / (tf[keep[q + 1]] - tf[keep[q]]);
    for (int q = 0; q < nk; ++q) {
        const int src = keep[q];
        tab->tau[q] = tf[src];
        for (size_t d = 0; d < plane; ++d) {
            const float J = vf[src * plane + d], e = ef[src * plane + d];
            tab->v[(d * 2 * (size_t) nk) + q] = J;
            tab->v[(d * 2 * (size_t) nk) + nk + q] = e;
            tab->jmax = fmax(tab->jmax, (double) J + e);
        }
    }
    info->nodes = nf;
    info->kept = nk;
    info->nh = nh;
    info->direct = sf->direct;
    info->iterated = sf->iterated;
    if (jmax > 0) {
        info->tail_rel = fmax(info->tail_rel, sf->tail / jmax);
        info->disc_rel = fmax(info->disc_rel, dmax / jmax);
    }
    ok = 1;
out:
    free(topf_f);
    free(topf_c);
    free(ef);
    free(keep);
    free(tf);
    free(tc);
    free(af);
    free(ac);
    free(vf);
    free(vc);
    ef_ms_solve_free(sf);
    ef_ms_solve_free(sc);
    return ok ? 0 : -1;
}

/* What a solve of scene s needs whatever lights it: the fog's common up,
 * the heights bracketing it (its top, and the ground or where the depth
 * passes MS_TAU_DEEP), each channel's depth at the bottom, and the
 * directions per hemisphere its phases need. */
typedef struct pp_setup {
    double up[3], hhi, hlo, tbot[3];
    int nh;
} pp_setup;

/* Fills P for scene s, what (the light, for messages) with a ground at
 * height ground when has_ground. Returns 1 (solve), 0 (nothing to add:
 * no fog above the ground, or fog that thickens upwards without end), or
 * -1 with a message (fog the solve does not take). */
static int pp_prepare(const ef_fog_scene *s, const char *what, int has_ground, double ground,
                      pp_setup *P, ef_err *err)
{
    /* the common up: every functional of every component along it */
    double *up = P->up;
    memcpy(up, s->ctx.up, sizeof P->up);
    int have = 0;
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (is_uniform(c))
            continue;
        ef_fog_functional fn[16];
        const int nf = c->model->functionals && !c->model->tau_info
                           ? c->model->functionals(c, fn, 16) : -1;
        if (nf < 0 || nf > 16)
            return ef_fail(err, "fog '%s': multiple scattering (%s) is solved for fog that is "
                           "the same along the ground (exp, height, layered, a horizontal "
                           "half-space); this component's density changes across it", c->spec,
                           what);
        for (int f = 0; f < nf; ++f) {
            const double nn = sqrt(dot3(fn[f].n, fn[f].n));
            if (!(nn > 0))
                continue;
            double d[3] = { fn[f].n[0] / nn, fn[f].n[1] / nn, fn[f].n[2] / nn };
            if (!have) {
                const double sg = dot3(d, up) < 0 ? -1 : 1;
                for (int q = 0; q < 3; ++q)
                    up[q] = sg * d[q];
                have = 1;
            }
            if (fabs(fabs(dot3(d, up)) - 1) > 1e-9)
                return ef_fail(err, "fog '%s': multiple scattering (%s) is solved for fog that "
                               "is the same along the ground (exp, height, layered, a "
                               "horizontal half-space); this component changes along another "
                               "direction than the others' up", c->spec, what);
        }
    }
    double gmax = 0;
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].phase == EF_PHASE_HG || s->comp[i].phase == EF_PHASE_CS)
            gmax = fmax(gmax, fabs(s->comp[i].g));
    if (gmax > MS_G_MAX)
        return ef_fail(err, "%s: scattering=multiple solves phases with |g| up to %g (64 "
                       "Legendre terms: at g 0.98 they no longer hold the forward peak and the "
                       "light comes out wrong); this fog has g %g (fog's is 0.8 to 0.9)",
                       what, MS_G_MAX, gmax);
    P->nh = (int) ceil(3 / (1 - fmin(gmax, 0.99)));
    P->nh = P->nh < MS_NH_MIN ? MS_NH_MIN : P->nh > 32 ? 32 : P->nh;
    double hhi = 1, hlo = -1, t[3];
    for (int it = 0; it < 2100; ++it) {
        vtau(s, up, hhi, t);
        if (fmax(t[0], fmax(t[1], t[2])) <= 1e-12 || hhi > 1e300)
            break;
        hhi *= 2;
    }
    vtau(s, up, hhi, t);
    if (!(fmax(t[0], fmax(t[1], t[2])) < 1e-6))
        return 0;   /* the fog thickens upwards without end: no light arrives */
    if (has_ground) {
        hlo = ground;
    } else {
        for (int it = 0; it < 2100; ++it) {
            vtau(s, up, hlo, t);
            if (fmin(t[0], fmin(t[1], t[2])) >= MS_TAU_DEEP || hlo < -1e300)
                break;
            hlo *= 2;
        }
    }
    if (!(hlo < hhi))
        return 0;
    P->hhi = hhi;
    P->hlo = hlo;
    vtau(s, up, hlo, P->tbot);
    return 1;
}

/* Whether channels j and k of s see the same fog (so they may share a
 * solve). */
static int same_fog(const ef_fog_scene *s, const pp_setup *P, int j, int k)
{
    int same = P->tbot[j] == P->tbot[k];
    for (int i = 0; i < s->ncomp && same; ++i)
        same = albedo(&s->comp[i], j) == albedo(&s->comp[i], k);
    for (int q = 0; q < 8 && same; ++q) {
        double t[3];
        vtau(s, P->up, P->hlo + (P->hhi - P->hlo) * q / 7.0, t);
        same = t[j] == t[k];
    }
    return same;
}

/* The tables of m per channel (sharing where same(j, k) says the
 * channels' solves are the same), each by build_tab; returns 0 or -1
 * (out of memory). */
static int build_tabs(const ef_fog_scene *s, const pp_setup *P, ef_ms *m, double mu_s,
                      top_fn topf, const void *user, int (*same)(const void *, int, int),
                      const void *same_user)
{
    for (int k = 0; k < 3; ++k) {
        m->tab_of[k] = -1;
        for (int j = 0; j < k && m->tab_of[k] < 0; ++j)
            if (same(same_user, j, k))
                m->tab_of[k] = m->tab_of[j];
        if (m->tab_of[k] >= 0)
            continue;
        ms_tab *tab = &m->tab[m->ntab];
        m->tab_of[k] = m->ntab++;
        const double tb = fmin(P->tbot[k], MS_TAU_DEEP);
        if (!(tb > 1e-9))
            continue;   /* no fog in this channel: an empty table */
        /* a ground (or the fog's end) within MS_TAU_DEEP: refined there too */
        /* a sun's beam of unit irradiance; none beside a sky's light */
        if (build_tab(s, P->up, k, mu_s, topf ? 0.0 : 1.0, topf, user, tb,
                      P->tbot[k] <= MS_TAU_DEEP, P->hlo, P->hhi, P->nh, tab, &m->info))
            return -1;
    }
    return 0;
}

/* same() for a sun's solves. */
typedef struct same_sun {
    const ef_fog_scene *s;
    const pp_setup *P;
} same_sun;

static int same_for_sun(const void *u, int j, int k)
{
    const same_sun *q = u;
    return same_fog(q->s, q->P, j, k);
}

int ef_ms_build(const ef_fog_scene *s, const ef_light *l, ef_ms **out, ef_err *err)
{
    *out = NULL;
    if (ef_light_at_position(l))
        return ef_fail(err, "light '%s': multiple scattering is solved for the sun only", l->name);
    if (l->planet > 0)
        return ef_fail(err, "light '%s': scattering=multiple is solved over flat ground (no "
                       "planet=)", l->name);
    if (s->ncomp == 1 && s->comp[0].model->convex) {
        /* one box or convex volume: the solve in three dimensions */
        ef_vms *v;
        if (ef_vms_build(s, l, &v, err))
            return -1;
        if (!v)
            return 0;
        ef_ms *m = calloc(1, sizeof *m);
        if (!m) {
            ef_vms_free(v);
            return ef_fail(err, "out of memory for light '%s''s multiple scattering", l->name);
        }
        atomic_init(&m->refs, 1);
        m->vol = v;
        ef_vms_get_info(v, &m->info);
        *out = m;
        return 0;
    }
    struct timespec t0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    char what[96];
    snprintf(what, sizeof what, "light '%s'", l->name);
    pp_setup P;
    const int r = pp_prepare(s, what, l->has_ground, l->ground, &P, err);
    if (r <= 0)
        return r;
    const double mu_s = dot3(l->dir, P.up);
    if (!(mu_s > 1e-6) || (l->e[0] == 0 && l->e[1] == 0 && l->e[2] == 0))
        return 0;   /* no direct light in the plane-parallel fog */
    ef_ms *m = calloc(1, sizeof *m);
    if (!m)
        return ef_fail(err, "out of memory for light '%s''s multiple scattering", l->name);
    atomic_init(&m->refs, 1);
    memcpy(m->up, P.up, sizeof m->up);
    memcpy(m->E, l->e, sizeof m->E);
    /* the beam's horizontal direction (propagation: away from the sun) */
    for (int q = 0; q < 3; ++q)
        m->bh[q] = -l->dir[q] + mu_s * P.up[q];
    const double bn = sqrt(dot3(m->bh, m->bh));
    m->has_bh = bn > 1e-12;
    for (int q = 0; q < 3 && m->has_bh; ++q)
        m->bh[q] /= bn;
    const same_sun ss = { s, &P };
    if (build_tabs(s, &P, m, mu_s, NULL, NULL, same_for_sun, &ss)) {
        ef_ms_unref(m);
        return ef_fail(err, "out of memory for light '%s''s multiple scattering", l->name);
    }
    m->info.seconds = ef_lit_seconds_since(&t0);
    *out = m;
    return 0;
}

/* The sky's radiance entering at the top, per azimuthal mode. */
typedef struct sky_top {
    const ef_fog_scene *s;
    const pp_setup *P;
    double e1[3], e2[3];
} sky_top;

/* top_fn for a sky: the environment towards each downward direction's
 * source (the light propagates down, so it comes from above), in Fourier
 * modes of the azimuth about up from e1 (towards e2), by NQ samples. */
static double *sky_top_modes(const void *user, int nh, int k)
{
    enum { NQ = 512 };
    const sky_top *q = user;
    const int L = 2 * nh;
    double *top = calloc((size_t) L * 2 * nh, sizeof *top), x[64], w[64];
    if (!top || nh > 64)
        return free(top), NULL;
    gauss01(nh, x, w);
    for (int i = 0; i < nh; ++i) {
        const double st = sqrt(fmax(0, 1 - x[i] * x[i]));
        double Lq[NQ];
        for (int j = 0; j < NQ; ++j) {
            const double ph = 2 * PI * j / NQ, cp = cos(ph), sp = sin(ph);
            double d[3], v[3];
            for (int c = 0; c < 3; ++c)   /* from where the light comes: -Omega */
                d[c] = -st * (cp * q->e1[c] + sp * q->e2[c]) + x[i] * q->P->up[c];
            ef_sky_light_env(q->s->sky_light, q->P->up, d, v);
            Lq[j] = v[k];
        }
        for (int m = 0; m < L; ++m) {
            double a = 0, b = 0;
            for (int j = 0; j < NQ; ++j) {
                const double ph = 2 * PI * j / NQ;
                a += Lq[j] * cos(m * ph);
                b += Lq[j] * sin(m * ph);
            }
            top[(size_t) (m * 2) * nh + i] = (m ? 2.0 : 1.0) * a / NQ;
            top[(size_t) (m * 2 + 1) * nh + i] = m ? 2.0 * b / NQ : 0;
        }
    }
    return top;
}

/* same() for a sky's solves: the same fog and the same environment. */
static int same_for_sky(const void *u, int j, int k)
{
    const sky_top *q = u;
    const ef_sky_light *sk = q->s->sky_light;
    return same_fog(q->s, q->P, j, k) &&
           !memcmp(sk->env[j], sk->env[k], sizeof(float) * EF_SKY_ENV_W * EF_SKY_ENV_H);
}

int ef_ms_build_sky(const ef_fog_scene *s, ef_ms **out, ef_err *err)
{
    *out = NULL;
    if (!s->sky_light)
        return 0;
    struct timespec t0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    pp_setup P;
    const int r = pp_prepare(s, "the sky light", s->sky_has_ground, s->sky_ground, &P, err);
    if (r <= 0)
        return r;
    if (fabs(dot3(P.up, s->ctx.up) - 1) > 1e-9)
        return ef_fail(err, "the sky light's multiple scattering needs fog that is the same along "
                       "the scene's ground (--up-axis); this fog's layers lie across another "
                       "axis");
    ef_ms *m = calloc(1, sizeof *m);
    if (!m)
        return ef_fail(err, "out of memory for the sky light's multiple scattering");
    atomic_init(&m->refs, 1);
    memcpy(m->up, P.up, sizeof m->up);
    m->E[0] = m->E[1] = m->E[2] = 1;
    m->full = 1;
    sky_top st = { s, &P, { 0 }, { 0 } };
    ef_sky_frame(P.up, st.e1, st.e2);
    memcpy(m->bh, st.e1, sizeof m->bh);
    memcpy(m->e2, st.e2, sizeof m->e2);
    m->has_bh = 1;
    /* the sky's light reaches the top at every angle: the depth nodes as
     * fine at the top as for a sun 3.6 degrees up */
    if (build_tabs(s, &P, m, 0.0625, sky_top_modes, &st, same_for_sky, &st)) {
        ef_ms_unref(m);
        return ef_fail(err, "out of memory for the sky light's multiple scattering");
    }
    m->info.seconds = ef_lit_seconds_since(&t0);
    *out = m;
    return 0;
}

/* ------------------------------------------------------------ the gather */

/* A direction's bilinear corners and weights in the table. */
typedef struct dir_w {
    size_t at[4];
    double w[4];
} dir_w;

/* A direction's four corners in one table: where their rows of J and of
 * its estimate start, and their weights. */
typedef struct corners {
    const float *J[4], *e[4];
    double w[4];
} corners;

static void corners_of(const ms_tab *tab, const dir_w *dw, corners *cn)
{
    for (int c = 0; c < 4; ++c) {
        cn->J[c] = tab->v + dw->at[c] * (size_t) tab->n * 2;
        cn->e[c] = cn->J[c] + tab->n;
        cn->w[c] = dw->w[c];
    }
}

/* J and its estimate at node q of tab for the direction of cn. */
EF_INLINE void node_val(const corners *cn, int q, double *J, double *e)
{
    *J = cn->w[0] * cn->J[0][q] + cn->w[1] * cn->J[1][q] + cn->w[2] * cn->J[2][q] +
         cn->w[3] * cn->J[3][q];
    *e = cn->w[0] * cn->e[0][q] + cn->w[1] * cn->e[1][q] + cn->w[2] * cn->e[2][q] +
         cn->w[3] * cn->e[3][q];
}

/* J and its estimate at node k, from ab (J and estimate at nodes i and i
 * + 1, already read) where k is one of them. */
EF_INLINE void node_at(const corners *cn, int k, int i, const double ab[4], double *J, double *e)
{
    if (k == i || k == i + 1) {
        *J = ab[2 * (k - i)];
        *e = ab[2 * (k - i) + 1];
    } else {
        node_val(cn, k, J, e);
    }
}

/* The cell of tab's nodes that holds tau in [0, bottom]: i with tau[i] <=
 * tau <= tau[i + 1], 0 <= i <= n - 2. Without branches on the data (the
 * compiler's conditional moves): every ray starts and ends its walk with
 * one, and a binary search's mispredictions cost more than its loads. */
static int cell_of(const ms_tab *tab, double tau)
{
    int base = 0, len = tab->n - 1;
    while (len > 1) {
        const int half = len / 2;
        base = tab->tau[base + half] <= tau ? base + half : base;
        len -= half;
    }
    return base;
}

/* The two series of a walk's cell, written once for a double and for a
 * v4d (GCC's vector operators take a scalar beside a vector):
 * SERIES_A: 1 - e^-x for 0 <= x <= 1/8, to x^10 (the next term below 3e-18
 * of it), in Estrin's scheme (x2, x4, x8 its powers): no call, where most
 * cells of a walk through thin fog lie; SERIES_SLOPE: the slope weight (1
 * - e^-x) / x - e^-x below x = 1e-3, where its two terms cancel. */
#define SERIES_A(x, x2, x4, x8)                                                                    \
    ((x) * ((((1 - (x) * 0.5) + (x2) * (1.0 / 6 - (x) * (1.0 / 24))) +                             \
             (x4) * ((1.0 / 120 - (x) * (1.0 / 720)) + (x2) * (1.0 / 5040 - (x) * (1.0 / 40320)))) + \
            (x8) * (1.0 / 362880 - (x) * (1.0 / 3628800))))
#define SERIES_SLOPE(x) ((x) * (0.5 - (x) * (1.0 / 3 - (x) * (1.0 / 8 - (x) / 30))))

/* One cell of a walk, from a point where e^-s is es to one an optical
 * depth x further, J and its estimate linear from (J0, e0) to (J1, e1):
 * adds es int_0^x e^-y J dy to o[0] (the estimate's to o[1]); returns
 * e^-s at the far end. */
EF_INLINE double cell1(double es, double x, double J0, double J1, double e0, double e1, double o[2])
{
    const double x2 = x * x, x4 = x2 * x2;
    const double a = x < 0.125 ? SERIES_A(x, x2, x4, x4 * x4) : 1 - exp(-x);
    const double gs = x < 1e-3 ? SERIES_SLOPE(x) : a / x - (1 - a);
    o[0] += es * (J0 * a + (J1 - J0) * gs);
    o[1] += es * (e0 * a + (e1 - e0) * gs);
    return es * (1 - a);
}

typedef float v4f __attribute__((vector_size(16)));

/* J and its estimate (if est, else 0) at nodes k .. k + 3 for the
 * direction of cn, in the order node_val sums them. */
EF_INLINE void nodes4(const corners *cn, int k, int est, v4d *J, v4d *e)
{
    v4d j = { 0, 0, 0, 0 }, x = { 0, 0, 0, 0 };
    for (int c = 0; c < 4; ++c) {
        v4f fj;
        memcpy(&fj, cn->J[c] + k, sizeof fj);
        j += cn->w[c] * __builtin_convertvector(fj, v4d);
        if (est) {
            v4f fe;
            memcpy(&fe, cn->e[c] + k, sizeof fe);
            x += cn->w[c] * __builtin_convertvector(fe, v4d);
        }
    }
    *J = j;
    *e = x;
}

/* Up to four cells between consecutive nodes at once: cell l spans nodes
 * k + l and k + l + 1 (l < cnt), walked upwards in the table when up (q >
 * 0: deeper), else downwards, aq = |q|; J and its estimate at the cells'
 * lower nodes are JA and eA, at their upper ones JB and eB; es is e^-s
 * where the ray meets the block. Adds what cell1 would over the cells to o
 * (the estimate's part only if est); returns e^-s at the block's far end.
 * e^-x as cell1 takes it (v_exp's x at most 700: e^-700 lies far below any
 * cell nearer the camera), e^-s at each cell by the product of those
 * before it, 1 / x from the table's inverse spacings; lanes past cnt are
 * cells of no width. */
EF_INLINE double cells4(const ms_tab *tab, const v4d *JA, const v4d *JB, const v4d *eA,
                        const v4d *eB, int k, int cnt, int up, int est, double aq, double es,
                        double o[2])
{
    v4d TA, TB, ID;
    memcpy(&TA, tab->tau + k, sizeof TA);
    memcpy(&TB, tab->tau + k + 1, sizeof TB);
    memcpy(&ID, tab->invd + k, sizeof ID);
    const double iaq = 1 / aq;
    const v4d zero = { 0, 0, 0, 0 }, one = { 1, 1, 1, 1 }, cap = { 700, 700, 700, 700 };
    const v4d lane = { 0, 1, 2, 3 }, vc = { cnt, cnt, cnt, cnt };
    v4di m = lane < vc;
    v4d vx = (TB - TA) * iaq;
    v_sel(&vx, &m, &vx, &zero);
    /* 1 - e^-x from its series where x < 1/8 (every lane of most
     * blocks), from v_exp in the others */
    const v4d x2 = vx * vx, x4 = x2 * x2;
    v4d a = SERIES_A(vx, x2, x4, x4 * x4), ex = one - a;
    const v4d near = { 0.125, 0.125, 0.125, 0.125 };
    m = vx > near;
    if (v_any(&m)) {
        v4d nx, ev;
        const v4di big = vx > cap;
        v_sel(&nx, &big, &cap, &vx);
        nx = -nx;
        v_exp(&nx, &ev);   /* e^-x itself, not 1 - a: far cells' e^-x is tiny */
        const v4d ae = 1 - ev;
        v_sel(&a, &m, &ae, &a);
        v_sel(&ex, &m, &ev, &ex);
    }
    v4d gs = a * (ID * aq) - ex;
    const v4d lim = { 1e-3, 1e-3, 1e-3, 1e-3 };
    m = vx < lim;
    if (v_any(&m)) {
        const v4d gss = SERIES_SLOPE(vx);
        v_sel(&gs, &m, &gss, &gs);
    }
    /* e^-s at each cell's near end: the products of e^-x over the cells
     * the ray met before it in the block (a scan in the order it meets
     * them), and at the block's far end */
    v4d P, Js, Jf, es0, ef0;
    double all;
    if (up) {
        const v4d y = ex * __builtin_shuffle(ex, one, (v4di) { 4, 0, 1, 2 });
        const v4d z = y * __builtin_shuffle(y, one, (v4di) { 4, 4, 0, 1 });
        P = __builtin_shuffle(z, one, (v4di) { 4, 0, 1, 2 });
        all = z[3];
        Js = *JA, Jf = *JB, es0 = *eA, ef0 = *eB;
    } else {
        const v4d y = ex * __builtin_shuffle(ex, one, (v4di) { 1, 2, 3, 4 });
        const v4d z = y * __builtin_shuffle(y, one, (v4di) { 2, 3, 4, 4 });
        P = __builtin_shuffle(z, one, (v4di) { 1, 2, 3, 4 });
        all = z[0];
        Js = *JB, Jf = *JA, es0 = *eB, ef0 = *eA;
    }
    const v4d w = es * P;
    const v4d t0v = w * (Js * a + (Jf - Js) * gs);
    o[0] += (t0v[0] + t0v[1]) + (t0v[2] + t0v[3]);
    if (est) {
        const v4d t1v = w * (es0 * a + (ef0 - es0) * gs);
        o[1] += (t1v[0] + t1v[1]) + (t1v[2] + t1v[3]);
    }
    return es * all;
}

/* int_0^{sD} e^-s J(tauc + q s) ds and its estimate (est; else 0 for a
 * caller that does not want it), J linear between the table's nodes (q:
 * the change of vertical depth per unit of the view's).
 * The cells between nodes go four at a time, the two partial ones at the
 * ends alone; past a block of cells, once what is left (at most e^-s
 * jmax) is below 1e-6 of what was gathered, the walk stops and counts it
 * as error. */
EF_INLINE void walk(const ms_tab *tab, const dir_w *dw, double tauc, double q, double sD,
                    int est, double out[2])
{
    out[0] = out[1] = 0;
    const int n = tab->n;
    const double tbot = tab->tau[n - 1];
    const int horiz = fabs(q) * fmin(sD, 40) <= 1e-12 * (1 + tauc);
    /* the stretch of depth the ray covers inside [0, tbot] */
    double t0 = tauc, s0 = 0, tend = tauc;
    if (!horiz) {
        if (q < 0 && t0 > tbot) {   /* rising from below the bottom */
            s0 = (t0 - tbot) / -q;
            t0 = tbot;
        }
        if ((q > 0 && t0 >= tbot) || s0 >= sD)
            return;
        tend = q > 0 ? tbot : 0;
        const double sEnd = (tend - tauc) / q;   /* where the ray leaves it */
        if (sEnd < sD)
            sD = sEnd;
        else
            tend = tauc + q * sD;
    } else if (!(t0 <= tbot)) {
        return;
    }
    corners cn;
    corners_of(tab, dw, &cn);
    /* J at t0 from its cell */
    const int i = cell_of(tab, t0);
    double Ja, ea, Jb, eb;
    node_val(&cn, i, &Ja, &ea);
    node_val(&cn, i + 1, &Jb, &eb);
    const double f = (t0 - tab->tau[i]) / (tab->tau[i + 1] - tab->tau[i]);
    const double J0 = Ja + f * (Jb - Ja), e0 = ea + f * (eb - ea);
    const double ab[4] = { Ja, ea, Jb, eb };   /* nodes i and i + 1, known */
    if (horiz) {
        const double a = isinf(sD) ? 1 : -expm1(-sD);
        out[0] = a * J0;
        out[1] = a * e0;
        return;
    }
    const double iq = 1 / q;
    const int up = q > 0;
    /* the nodes strictly between t0 and tend: lo .. hi, in the order of
     * the table (none: hi < lo) */
    int lo, hi;
    {
        const int c = cell_of(tab, tend);   /* tau[c] <= tend <= tau[c + 1] */
        if (up) {
            lo = i + 1;
            hi = tab->tau[c] < tend ? c : c - 1;
        } else {
            hi = tab->tau[i] < t0 ? i : i - 1;
            lo = tab->tau[c + 1] > tend ? c + 1 : c + 2;
        }
    }
    double es = s0 > 0 ? exp(-s0) : 1;
    /* J at the last node before tend (Jl; t0's where there is none), and
     * at tend, linear in its cell between that point and the node past it */
    double Jl = J0, el = e0, Jend, eend;
    const int kl = up ? hi : lo;
    {
        const int last = up ? hi + 1 : lo - 1;   /* the node past tend, or at it */
        double Tl = t0;
        if (hi >= lo) {
            Tl = tab->tau[kl];
            node_val(&cn, kl, &Jl, &el);
        }
        if (last >= 0 && last < n) {
            double Jn, en;
            node_at(&cn, last, i, ab, &Jn, &en);
            const double g = tab->tau[last] == Tl ? 1 : (tend - Tl) / (tab->tau[last] - Tl);
            Jend = Jl + g * (Jn - Jl);
            eend = el + g * (en - el);
        } else {
            Jend = Jl;
            eend = el;
        }
    }
    if (hi < lo) {   /* no node between: one cell */
        cell1(es, fmax(0, (tend - t0) * iq), J0, Jend, e0, eend, out);
        return;
    }
    /* t0 to the first node (i + 1 going down in the table, i or i - 1 up) */
    {
        const int k = up ? lo : hi;
        double Jk, ek;
        node_at(&cn, k, i, ab, &Jk, &ek);
        es = cell1(es, fmax(0, (tab->tau[k] - t0) * iq), J0, Jk, e0, ek, out);
    }
    /* the cells between nodes, in the order the ray meets them */
    /* (blocks of four from the ray's far end: the first it meets holds
     * what is left over; each block's nodes past its upper end are the
     * next block's lower ones, up, or the one before's, down) */
    const int ncell = hi - lo;
    const v4di sh = { 1, 2, 3, 4 };
    v4d JL, eL, JU, eU;
    if (up) {
        nodes4(&cn, lo, est, &JL, &eL);
        for (int k = lo; k < hi; k += 4) {
            if (es * tab->jmax <= 1e-6 * out[0]) {
                out[1] += es * tab->jmax;
                return;
            }
            nodes4(&cn, k + 4, est, &JU, &eU);
            const v4d JB = __builtin_shuffle(JL, JU, sh), eB = __builtin_shuffle(eL, eU, sh);
            es = cells4(tab, &JL, &JB, &eL, &eB, k, hi - k < 4 ? hi - k : 4, 1, est, fabs(q), es, out);
            JL = JU;
            eL = eU;
        }
    } else {
        const int first = ncell % 4 ? ncell % 4 : 4;
        nodes4(&cn, hi - first + 4, est, &JU, &eU);
        for (int k = hi - first, cnt = first; k >= lo; k -= 4, cnt = 4) {
            if (es * tab->jmax <= 1e-6 * out[0]) {
                out[1] += es * tab->jmax;
                return;
            }
            nodes4(&cn, k, est, &JL, &eL);
            const v4d JB = __builtin_shuffle(JL, JU, sh), eB = __builtin_shuffle(eL, eU, sh);
            es = cells4(tab, &JL, &JB, &eL, &eB, k, cnt, 0, est, fabs(q), es, out);
            JU = JL;
            eU = eL;
        }
    }
    if (es * tab->jmax <= 1e-6 * out[0]) {
        out[1] += es * tab->jmax;
        return;
    }
    /* the last node to tend */
    cell1(es, fmax(0, (tend - tab->tau[kl]) * iq), Jl, Jend, el, eend, out);
}

void ef_ms_view_clear(ef_ms_view *v)
{
    ef_vms_cam_unref(v->cam);
    memset(v, 0, sizeof *v);
}

void ef_ms_bind(const ef_ms *m, const ef_fog_scene *s, const double org[3], ef_ms_view *v)
{
    /* a volume's table for this camera already (a sequence's next frame
     * from the same place): kept, not traced again */
    if (m && m->vol && v->bound && v->cam && v->org[0] == org[0] && v->org[1] == org[1] &&
        v->org[2] == org[2])
        return;
    ef_ms_view_clear(v);
    if (!m)
        return;
    v->bound = 1;
    memcpy(v->org, org, sizeof v->org);
    if (m->vol) {
        v->cam = ef_vms_bind(m->vol, org);
        return;
    }
    ef_lit_tau_from(s, org, m->up, INFINITY, v->tauc);
}

void ef_ms_gather_view(const ef_ms *m, const ef_ms_view *v, const ef_fog_scene *s,
                       const ef_ray *r, const double *tv, double S[3], double E[3])
{
    if (m && m->vol) {
        const int at = v->bound && r->org[0] == v->org[0] && r->org[1] == v->org[1] &&
                       r->org[2] == v->org[2];
        ef_vms_gather(m->vol, at ? v->cam : NULL, r, S, E);
        return;
    }
    const int cam = v->bound && r->org[0] == v->org[0] && r->org[1] == v->org[1] &&
                    r->org[2] == v->org[2];
    ef_ms_gather(m, s, r, tv, cam ? v->tauc : NULL, S, E);
}

EF_MULTIVERSION void ef_ms_gather(const ef_ms *m, const ef_fog_scene *s, const ef_ray *r, const double *tv,
                  const double *tauc_in, double S[3], double E[3])
{
    S[0] = S[1] = S[2] = 0;
    if (E)
        E[0] = E[1] = E[2] = 0;
    if (!m || !(r->dist > 0))
        return;
    /* the propagation direction towards the camera: -dir */
    const double mu_u = dot3(r->dir, m->up), mu_p = -mu_u;
    /* the table's coordinates: sin of half the polar angle, and of half
     * the azimuth from the beam's (a sun: fine where the forward peak is)
     * or the azimuth itself from the sky's frame (a sky) */
    double c = 1, hz[3], ph = 0;
    for (int q = 0; q < 3; ++q)
        hz[q] = -r->dir[q] - mu_p * m->up[q];
    const double hn = sqrt(dot3(hz, hz));
    if (m->has_bh && hn > 1e-12) {
        c = dot3(hz, m->bh) / hn;
        if (m->full)
            ph = atan2(dot3(hz, m->e2), dot3(hz, m->bh));
    }
    dir_w dw;
    const int np = np_of(m->full);
    const double fi = sqrt(fmax(0, fmin(1, 0.5 * (1 - mu_p)))) * (MS_NT - 1);
    double fj;
    if (m->full) {
        fj = ph / (2 * PI) * np;
        fj -= np * floor(fj / np);
    } else {
        fj = sqrt(fmax(0, fmin(1, 0.5 * (1 - c)))) * (np - 1);
    }
    int i0 = (int) fi, j0 = (int) fj;
    i0 = i0 > MS_NT - 2 ? MS_NT - 2 : i0;
    j0 = m->full ? (j0 >= np ? np - 1 : j0) : j0 > np - 2 ? np - 2 : j0;
    const int j1 = m->full ? (j0 + 1) % np : j0 + 1;
    const double u = fi - i0, v = fj - j0;
    dw.at[0] = (size_t) i0 * np + j0;
    dw.at[1] = (size_t) i0 * np + j1;
    dw.at[2] = dw.at[0] + np;
    dw.at[3] = dw.at[1] + np;
    dw.w[0] = (1 - u) * (1 - v);
    dw.w[1] = (1 - u) * v;
    dw.w[2] = u * (1 - v);
    dw.w[3] = u * v;
    double tauc[3], sD[3];
    if (tauc_in)
        memcpy(tauc, tauc_in, sizeof tauc);
    else
        ef_lit_tau_from(s, r->org, m->up, INFINITY, tauc);
    if (tv)
        memcpy(sD, tv, sizeof sD);
    else
        ef_lit_tau_from(s, r->org, r->dir, r->dist, sD);
    double res[3][2];
    for (int t = 0; t < m->ntab; ++t) {
        int k = 0;
        while (m->tab_of[k] != t)
            ++k;
        /* the estimate's half of the walk only where it is wanted */
        if (m->tab[t].n > 1 && E)
            walk(&m->tab[t], &dw, tauc[k], mu_p, sD[k], 1, res[t]);
        else if (m->tab[t].n > 1)
            walk(&m->tab[t], &dw, tauc[k], mu_p, sD[k], 0, res[t]);
        else
            res[t][0] = res[t][1] = 0;
    }
    for (int k = 0; k < 3; ++k) {
        S[k] = m->E[k] * res[m->tab_of[k]][0];
        if (E)
            E[k] = m->E[k] * res[m->tab_of[k]][1];
    }
}
