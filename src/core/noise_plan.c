/* The adaptive method's planner (fog_noise.c's family; noise_fog.h): from
 * a tolerance on tau, which octaves are dropped (their line integrals'
 * spread or hard bound fits) and how each kept one is integrated (Gauss
 * nodes per cell, or the grid's nodes per lattice unit), buying error at
 * the best rate per nanosecond on a ladder made once per component; and
 * the error budget ttol gives a ray. Pure: no I/O, no globals. */
#include "noise_fog.h"

/* ---- adaptive: nodes per octave and octaves kept, from the tolerance ---- */

/* Per-cell Gauss-Legendre error of integral(noise) per unit of chord length
 * with q nodes, q = 1..8 (9 is exact): the maximum and the root mean square
 * over cells, measured by bench/noise_calibrate on 10^6 random chords
 * through random cells (length-weighted, which errs on the safe side),
 * times 1.5. */
static const double e_max[9] = { 0, 0.66, 0.30, 0.087, 0.0173, 2.4e-3, 2.45e-4, 1.56e-5, 5.7e-7 };
static const double e_rms[9] = { 0, 0.149, 0.034, 6.0e-3, 7.2e-4, 6.8e-5, 5.0e-6, 2.3e-7, 6.4e-9 };


/* What octave i can add to the integral of the noise (before its weight)
 * over a stretch of length L: the hard bound, or `sigmas` standard
 * deviations of its line integral, whichever is smaller (an estimate). */
double ef_nz_line_est(const nstate *s, int i, double L, double sigmas)
{
    return fmin(EF_NOISE_BOUND * L, sigmas * LINE_RMS * sqrt(L * (s->scale / s->fbm.freq[i])));
}
/* The error estimate of octave i's quadrature with q nodes per cell on a
 * stretch of length L crossing cells of mean chord hbar: the smaller of the
 * worst case (every cell at its maximum error, one sign) and four standard
 * deviations of a sum of independent cell errors (sum of chord^2 taken as
 * 2 L hbar: chords vary; three fell short of 99.9 % coverage at tol 1e-6),
 * with S = sqrt(2 L hbar) taken once per octave. */
static inline double quad_est_s(double A, double L, double S, int q)
{
    if (q >= 9)
        return 0;
    const double a = e_max[q] * L, b = 4 * e_rms[q] * S;
    return A * (b < a ? b : a);
}

/* The planner's cost model, in ns on the machine of bench/noise.md: a
 * walked cell (the 3D DDA, its hashes and corner terms) and a Gauss node
 * in it; a grid node (its hashes and value); a grid segment's end term. */
#define COST_CELL 20.0
#define COST_NODE 8.0
#define COST_GRID 12.0
#define COST_GRID_END 40.0
#define PLAN_OPTS (9 + GRID_N)

static void plan_set(plan *P, int i, int kind)
{
    P->q[i] = kind > 0 ? kind : 1;
    P->nu[i] = kind > 0 ? 0 : grid_nu[-kind - 1];
}

/* Evaluations octave i's plan costs over a stretch of length L. */
double ef_nz_plan_evals(const rayc *R, const plan *P, int i, double L)
{
    const lin *u = &R->u[3 * i];
    const double dx = u[0].dd, dy = u[1].dd, dz = u[2].dd;
    if (!P->q[i])
        return 0;
    if (P->nu[i] > 0)
        return ceil(sqrt(dx * dx + dy * dy + dz * dz) * L * P->nu[i]);
    return P->q[i] * ((fabs(dx) + fabs(dy) + fabs(dz)) * L + 1);
}

/* The ways an octave can be integrated, per unit: integrating octave i
 * over a stretch of length L one way costs cost[k] sp_i L ns and errs by
 * an estimated err[k] A_i sqrt(L / sp_i) (A_i its amplitude in tau, sp_i
 * its lattice units per unit t). The walk's cells are kappa sp_i L
 * (kappa = the ray's |d|_1 / |d|_2, the same for every octave), with
 * 4 e_rms[q] sqrt(2 L hbar), hbar = 1 / (kappa sp_i); the grid's nodes
 * nu sp_i L, GRID_SIGMAS grid_rms sqrt(sp_i L) / sp_i. So one ladder
 * serves every octave and segment of a ray: the lower convex hull of
 * (cost, err), the cheapest first, each further step buying error at a
 * worse rate. kind > 0: walk with kind Gauss nodes per cell (9: exact);
 * kind < 0: the grid at grid_nu[-kind - 1]. */
struct ladder {
    int n, kind[PLAN_OPTS];
    double cost[PLAN_OPTS], err[PLAN_OPTS];
    double slope2[PLAN_OPTS];        /* (err[k]^2 - err[k+1]^2) / (cost[k+1] - cost[k]) */
};

static void ladder_unit(double kappa, ladder *ld)
{
    int kind[PLAN_OPTS];
    double cost[PLAN_OPTS], err[PLAN_OPTS];
    int m = 0, a = 1, g = 0;
    /* merge the two ladders (each rising in cost) by cost */
    while (a <= 9 || g < GRID_N) {
        const double ca = a <= 9 ? kappa * (COST_CELL + a * COST_NODE) : INFINITY;
        const double cg = g < GRID_N ? grid_nu[g] * COST_GRID : INFINITY;
        if (ca <= cg) {
            kind[m] = a;
            cost[m] = ca;
            err[m++] = 4 * e_rms[a < 9 ? a : 0] * sqrt(2 / kappa) * (a < 9);
            a++;
        } else {
            kind[m] = -(g + 1);
            cost[m] = cg;
            err[m++] = GRID_SIGMAS * grid_rms[g];
            g++;
        }
    }
    ld->n = 0;
    for (int j = 0; j < m; ++j) {
        if (ld->n > 0 && !(err[j] < ld->err[ld->n - 1]))
            continue;   /* costs more and errs no less */
        while (ld->n >= 2) {
            const int p = ld->n - 1, q = ld->n - 2;
            /* drop p when going straight from q to j buys error at a
             * better rate than through p */
            if ((ld->err[q] - ld->err[p]) * (cost[j] - ld->cost[q]) <=
                (ld->err[q] - err[j]) * (ld->cost[p] - ld->cost[q]))
                ld->n--;
            else
                break;
        }
        ld->kind[ld->n] = kind[j];
        ld->cost[ld->n] = cost[j];
        ld->err[ld->n++] = err[j];
    }
    for (int k = 0; k + 1 < ld->n; ++k)
        ld->slope2[k] = (ld->err[k] * ld->err[k] - ld->err[k + 1] * ld->err[k + 1]) /
                        (ld->cost[k + 1] - ld->cost[k]);
}

/* The ladders for kappa in [1, sqrt 3] (every direction's |d|_1 / |d|_2),
 * at LADDER_BINS + 1 evenly spaced values: a ray takes the one at or
 * below its kappa, whose walk costs no more and errs no less than its own
 * (the estimates stay on the safe side; only the choice may differ). */
#define LADDER_BINS 32
#define LADDER_WORDS ((sizeof(ladder) + sizeof(double) - 1) / sizeof(double))
#define KAPPA_SPAN 0.7320508075688772   /* sqrt 3 - 1 */

size_t ef_nz_ladders_words(void)
{
    return (LADDER_BINS + 1) * LADDER_WORDS;
}

void ef_nz_ladders_fill(double *at)
{
    for (int j = 0; j <= LADDER_BINS; ++j)
        ladder_unit(1 + KAPPA_SPAN * j / LADDER_BINS, (ladder *) (void *) (at + j * LADDER_WORDS));
}

/* Fills SP for ray R; 0 where the grid cannot serve it (no direction). */
int ef_nz_seg_planner_init(const rayc *R, seg_planner *SP)
{
    const nstate *s = R->s;
    double kappa = 1;
    SP->ld = NULL;
    for (int i = 0; i < s->fbm.octaves; ++i) {
        const lin *u = &R->u[3 * i];
        const double dx = u[0].dd, dy = u[1].dd, dz = u[2].dd;
        SP->sp[i] = sqrt(dx * dx + dy * dy + dz * dz);
        if (!(SP->sp[i] > 0) || !isfinite(SP->sp[i]))
            return 0;
        SP->isp[i] = 1 / sqrt(SP->sp[i]);
        SP->lrms[i] = 3 * s->line_rms[i];
        if (i == 0)
            kappa = (fabs(dx) + fabs(dy) + fabs(dz)) / SP->sp[0];
    }
    int bin = (int) ((kappa - 1) * (LADDER_BINS / KAPPA_SPAN));
    bin = bin < 0 ? 0 : bin > LADDER_BINS ? LADDER_BINS : bin;
    SP->ld = (const ladder *) (const void *) ((const double *) (const void *) s + s->ladder_off +
                                              (size_t) bin * LADDER_WORDS);
    return 1;
}

/* plan_octaves for one segment of adaptive_linear, from the ray's ladder.
 * Every estimate here is statistical (k standard deviations of an error
 * that is a sum over many cells, or the hard bound where smaller), and
 * the octaves' errors are independent (each its own lattice), so they add
 * in variance: the segment's estimate is the root sum of squares of the
 * dropped octaves' (three standard deviations of their line integrals, or
 * their hard bound; at most tol/2 in all) and the kept ones' quadrature
 * estimates, and it stays within tol. The envelope enters as it weighs
 * the noise: a sum of independent errors weighted by env has the variance
 * of the unweighted one times the mean of env^2 (emsq), a hard bound
 * scales with the mean of env (emean); the largest value would overstate
 * both where the envelope falls tenfold over a segment. From each kept
 * octave's cheapest way, the step that buys the most variance per ns is
 * taken until the sum fits. A stretch under 2 lattice units counts as 2
 * (where the grid's calibration stops). */
void ef_nz_plan_segment(const rayc *R, const seg_planner *SP, double L, double emean,
                        double emsq, const double *fm, const double *fq, double tol, plan *P)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double A = s->rho_max * fabs(s->contrast), erms = sqrt(emsq), sqL = sqrt(L);
    const double tol2 = tol * tol;
    double drop2 = 0, quad2 = 0;
    int kept = N;
    P->dropped = 0;
    for (int i = N - 1; i >= 0; --i) {
        const double m = fm ? fm[i] : 1, q = fq ? fq[i] : 1;
        const double D =
            A * s->fbm.weight[i] * fmin(EF_NOISE_BOUND * emean * m * L, SP->lrms[i] * erms * q * sqL);
        if (drop2 + D * D > tol2 / 4)
            break;
        drop2 += D * D;
        kept = i;
        P->dropped++;
    }
    const ladder *ld = SP->ld;
    double sc[EF_FBM_MAX_OCTAVES], rate[EF_FBM_MAX_OCTAVES];
    int pos[EF_FBM_MAX_OCTAVES];
    for (int i = 0; i < N; ++i) {
        P->q[i] = 0;
        P->nu[i] = 0;
        if (i >= kept)
            continue;
        const double Le = L * SP->sp[i] < 2 ? 2 / SP->sp[i] : L;
        sc[i] = A * erms * (fq ? fq[i] : 1) * s->fbm.weight[i] * sqrt(Le) * SP->isp[i];
        rate[i] = sc[i] * sc[i] / (SP->sp[i] * L);   /* variance per ns, per unit */
        pos[i] = 0;
        plan_set(P, i, ld->kind[0]);
        quad2 += sc[i] * sc[i] * ld->err[0] * ld->err[0];
    }
    const double room = tol2 - drop2;
    while (quad2 > room) {
        int best = -1;
        double bg = 0;
        for (int i = 0; i < kept; ++i) {
            const int p = pos[i];
            if (p + 1 >= ld->n)
                continue;
            const double gn = rate[i] * ld->slope2[p];
            if (best < 0 || gn > bg) {
                best = i;
                bg = gn;
            }
        }
        if (best < 0)
            break;
        const double e0 = ld->err[pos[best]], e1 = ld->err[pos[best] + 1];
        quad2 -= sc[best] * sc[best] * (e0 * e0 - e1 * e1);
        pos[best]++;
        plan_set(P, best, ld->kind[pos[best]]);
    }
    P->est = sqrt(drop2 + (quad2 > 0 ? quad2 : 0));
}

/* Chooses how each octave is integrated for tau within tol over a stretch
 * of length L whose envelope is at most envmax. Octaves are dropped from
 * the finest while three standard deviations of their line integrals (or
 * their hard bound, if smaller) sum to at most tol/4; then, from each
 * kept octave's cheapest way, the step that buys the most error per ns
 * is taken until the estimates (quad_est_s: 4 sigma of the walk's cells;
 * the walk's cells) sum to tol/2. */
void ef_nz_plan_octaves(const rayc *R, double L, double envmax, double tol, plan *P)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double A = s->rho_max * fabs(s->contrast) * envmax;
    double drop = 0, quad = 0;
    int kept = N;
    P->dropped = 0;
    for (int i = N - 1; i >= 1; --i) {
        const double D = A * s->fbm.weight[i] * ef_nz_line_est(s, i, L, 3);
        if (drop + D > tol / 4)
            break;
        drop += D;
        kept = i;
        P->dropped++;
    }
    ladder ld[EF_FBM_MAX_OCTAVES];
    int pos[EF_FBM_MAX_OCTAVES];
    for (int i = 0; i < N; ++i) {
        P->q[i] = 0;
        P->nu[i] = 0;
        if (i >= kept)
            continue;
        const double Ai = A * s->fbm.weight[i];
        /* the walk's ladder, q = 1..9 (9: exact), step by step */
        const lin *u = &R->u[3 * i];
        const double ncell = (double) ((fabsl(u[0].d) + fabsl(u[1].d) + fabsl(u[2].d)) * L) + 1;
        const double S = sqrt(2 * L * (L / ncell));
        ld[i].n = 9;
        for (int q = 1; q <= 9; ++q) {
            ld[i].kind[q - 1] = q;
            ld[i].cost[q - 1] = ncell * q;
            ld[i].err[q - 1] = quad_est_s(Ai, L, S, q);
        }
        pos[i] = 0;
        plan_set(P, i, ld[i].kind[0]);
        quad += ld[i].err[0];
    }
    while (quad > tol / 2) {
        int best = -1;
        double bg = 0;
        for (int i = 0; i < kept; ++i) {
            const ladder *l = &ld[i];
            if (pos[i] + 1 >= l->n)
                continue;
            const double gn = (l->err[pos[i]] - l->err[pos[i] + 1]) /
                              (l->cost[pos[i] + 1] - l->cost[pos[i]]);
            if (best < 0 || gn > bg) {
                best = i;
                bg = gn;
            }
        }
        if (best < 0)
            break;
        quad -= ld[best].err[pos[best]];
        pos[best]++;
        quad += ld[best].err[pos[best]];
        plan_set(P, best, ld[best].kind[pos[best]]);
    }
    P->est = drop + (quad > 0 ? quad : 0);
}

/* The estimate, per unit of |contrast| times the envelope, of what every
 * octave but `only` adds to tau over a stretch of length L: each one's
 * hard bound or four standard deviations of its line integral, whichever
 * is smaller (the drop rule's estimate, with quad_est_s's 4 sigma). */
double ef_nz_rest_estimate(const nstate *s, int only, double L)
{
    double r = 0;
    for (int i = 0; i < s->fbm.octaves; ++i)
        if (i != only)
            r += s->fbm.weight[i] * ef_nz_line_est(s, i, L, 4);
    return r;
}

/* Under ttol=eps, the error of tau (densest channel) this ray may have:
 * |dT| <= T expm1(dtau) and T <= e^-lo, so dtau = log1p(eps e^lo) per
 * channel keeps |dT| <= eps, lo being a lower value of the channel's tau
 * over [t0, t1]: the mean part less the noise part's estimate
 * (rest_estimate over every octave: 4 sigma or the hard bound) for the
 * noise model, (1 - |c| bound)^m times the envelope's integral for the
 * clamped and separable densities (0 where the clamp can bind). Dense
 * fog earns a large budget: where T is small, tau's error hardly shows. */
double ef_nz_ttol_budget(const rayc *R, long double t0, long double t1, double L, double envmax,
                         int linear)
{
    const nstate *s = R->s;
    const double m = (double) ef_nz_env_integral(s, R->h0, R->hs, t0, t1);
    double lo;
    if (linear) {
        lo = m - fabs(s->contrast) * envmax * ef_nz_rest_estimate(s, -1, L);
    } else {
        const double lo1 = 1 - fabs(s->contrast) * EF_NOISE_BOUND;
        lo = lo1 > 0 ? pow(lo1, s->separable ? s->naxes : 1) * m : 0;
    }
    return ef_nz_ttol_dtau(s, lo);
}

double ef_nz_ttol_dtau(const nstate *s, double lo)
{
    if (!(lo > 0))
        lo = 0;
    double tol = INFINITY;
    for (int k = 0; k < 3; ++k) {
        if (!(s->rho[k] > 0))
            continue;
        /* log1p(eps e^x) as softplus(log eps + x): no overflow. */
        const double x = log(s->ttol) + s->rho[k] * lo;
        const double dk = (x > 36 ? x : log1p(exp(x))) * (s->rho_max / s->rho[k]);
        if (dk < tol)
            tol = dk;
    }
    return tol;
}
