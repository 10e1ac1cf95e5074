/* noise-separable's default method where the clamp cannot bind (fog_noise.c's
 * family; noise_fog.h): the product of the factors integrated piece by
 * piece between the faces of the octaves it keeps, each factor octave read
 * from its cell polynomial, and the octaves it drops replaced by their mean
 * over the noise's period, with an estimate of what they would have added.
 * Pure: no I/O, no globals.
 *
 * Why this pays: the general path walks every octave of every factor and
 * bisects a pair of Gauss rules on each piece (300 noise evaluations a
 * cell and more), so a long ray across a fine scale cost milliseconds. A
 * factor is a function of one coordinate, so along the ray its octave is a
 * polynomial of degree 6 inside each of its own cells: a fixed Gauss rule
 * per piece is exact for the product, and the pieces are only as many as
 * the kept octaves' faces. A fine octave crossed by many cells adds a sum
 * of many nearly independent cell integrals, whose spread the period's own
 * cells give (sep_stats): that sum is what the drop rule estimates. */
#include "noise_fog.h"

/* The sigmas of the dropped octaves' sum the estimate reports (the
 * calibration: bench/noise_sep_calibrate in bench/noise_sweep.md). */
#define SEP_SIGMAS 3.0
/* The work bound: past this many factor octave evaluations (each a
 * polynomial of degree 6 from its cell's table, about a fourteenth of a
 * noise evaluation's work: 400,000 take about 0.8 ms of one core), or
 * where a segment would take a ray past 1.25 times that, the rest of the
 * ray is one last segment that drops the octaves with the most cells,
 * whatever the budget, until what it takes fits that (at least
 * SEP_FORCE_PIECES pieces), with their estimate in the error output, and
 * the ray is counted over the bound. */
#define SEP_EVAL_CAP 400000
#define SEP_FORCE_PIECES 64
/* envelope exponent over a piece beyond which the piece is split */
#define SEP_ENV_STEP 0.5

void ef_nz_sep_stats(nstate *s, const double *tab)
{
    const int N = s->fbm.octaves;
    for (int k = 0; k < s->naxes; ++k)
        for (int i = 0; i < N; ++i) {
            const double *p = tab + ((size_t) k * (size_t) N + (size_t) i) * 256 * 7;
            double I[256], mu = 0;
            for (int m = 0; m < 256; ++m) {
                const double *q = p + 7 * m;
                double v = 0;
                for (int j = 0; j < 7; ++j)
                    v += q[j] / (j + 1);
                I[m] = v;
                mu += v;
            }
            mu /= 256;
            /* The largest variance per cell of a window's sum over the
             * period, windows of 1 to 128 cells (neighbouring cells share
             * a face, so a window's variance is not n times one cell's). */
            double r = 0;
            for (int n = 1; n <= 128; n *= 2) {
                double v = 0;
                for (int m = 0; m < 256; ++m) {
                    double w = 0;
                    for (int j = 0; j < n; ++j)
                        w += I[(m + j) & 255] - mu;
                    v += w * w;
                }
                v /= 256 * (double) n;
                if (v > r)
                    r = v;
            }
            /* the octave's mean square, 16 points a cell */
            double q2 = 0;
            for (int m = 0; m < 256; ++m)
                for (int g = 0; g < 16; ++g) {
                    const double y = (g + 0.5) / 16, *q = p + 7 * m;
                    const double v = cell_poly_at(q, y);
                    q2 += v * v;
                }
            s->sep_ms[k][i] = q2 / 4096;
            s->sep_mu[k][i] = mu;
            s->sep_r[k][i] = r;
        }
}

/* e^(-a (t - start)) at the n Gauss nodes x of a sub-piece of length h
 * (ah = a h) into e: by its Taylor series where |a h| is small, a loop
 * across the nodes (no exp per node). */
static inline void env_nodes(double ah, const double *x, int n, double *e)
{
    double y[GL_MAX];
    for (int g = 0; g < n; ++g) {
        y[g] = ah * (1 + x[g]) / 2;   /* a (t - start), |y| <= SEP_ENV_STEP */
        e[g] = 1;
    }
    if (ah == 0)
        return;
    if (fabs(ah) <= SEP_ENV_STEP * (1 + 1e-12)) {
        /* e^-y to degree 11: 0.5^12 / 12! = 5e-13 relative at most */
        static const double inv[12] = { 1, 1, 1. / 2, 1. / 3, 1. / 4, 1. / 5, 1. / 6, 1. / 7,
                                        1. / 8, 1. / 9, 1. / 10, 1. / 11 };
        for (int j = 11; j >= 1; --j)
            for (int g = 0; g < n; ++g)
                e[g] = 1 - y[g] * inv[j] * e[g];
        return;
    }
    for (int g = 0; g < n; ++g)
        e[g] = exp(-y[g]);
}

typedef struct sep_line {
    double b, d, cell, next;         /* u = b + t d; the current cell and its exit t */
    const double *poly;              /* the octave's 256 cell polynomials */
    double w;                        /* the octave's weight */
    int slot;                        /* axis slot */
} sep_line;

/* The exit t of the cell L is in (after the caller moved L->cell). */
static inline double line_exit(const sep_line *L)
{
    if (L->d > 0)
        return (L->cell + 1 - L->b) / L->d;
    if (L->d < 0)
        return (L->cell - L->b) / L->d;
    return INFINITY;
}

/* One segment's plan: the factor octaves it drops (by index k N + i),
 * their estimate's square, each factor's constant and the pieces left. */
typedef struct sep_plan {
    double ta, tb, var, pieces, konst[3];
    /* per dropped factor octave: its variance per unit of the integral of
     * h_k^2 env^2 (h_k: what multiplies factor k), and its hard bound;
     * per factor, the dropped octaves' mean square times c^2 */
    double coef[3 * EF_FBM_MAX_OCTAVES], hard[3 * EF_FBM_MAX_OCTAVES], dms[3];
    unsigned char drop[3 * EF_FBM_MAX_OCTAVES];
    int ndrop;
} sep_plan;

/* Plans [P->ta, P->tb]: drops the factor octaves with the most cells
 * first while the root sum of their estimates' squares stays within
 * sqrt(budget2) (with force > 0, past the work bound, also beyond it
 * while the rest take more than force pieces). H[k]: the root mean square
 * of what multiplies factor k. */
static void plan_segment(const rayc *R, const double H[3], double budget2, double force, sep_plan *P)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves, M = s->naxes;
    const double ac = fabs(s->contrast), L = P->tb - P->ta;
    const double Hb = pow(1 + ac * EF_NOISE_BOUND, M - 1);   /* the other factors' bound */
    const double a = s->k > 0 ? R->khs : 0;
    const double e0 = s->k > 0 ? exp(-(R->kh0 + R->khs * P->ta)) : 1;
    const double env_int = (double) ef_nz_env_integral(s, R->h0, R->hs, P->ta, P->tb);
    /* the envelope's mean square over the segment */
    const double ms = a == 0 || a * L == 0 ? e0 * e0 : e0 * e0 * -expm1(-2 * a * L) / (2 * a * L);
    int order[3 * EF_FBM_MAX_OCTAVES], n = 0;
    double cost[3 * EF_FBM_MAX_OCTAVES], e2[3 * EF_FBM_MAX_OCTAVES];
    for (int k = 0; k < M; ++k)
        for (int i = 0; i < N; ++i) {
            const int j = k * N + i;
            const double d = fabs(R->u[s->axis[k] * N + i].dd), cells = d * L;
            cost[j] = cells;
            e2[j] = INFINITY;
            P->coef[j] = 0;
            P->hard[j] = INFINITY;
            if (cells >= 4) {
                /* the sum over cells: sep_r per cell, two more cells for
                 * the partial ones at the ends; in t, each cell is 1/d
                 * long, so the variance is coef times the integral of
                 * h^2 env^2, here taken as H^2 times ms L */
                const double cw = ac * s->fbm.weight[i];
                P->coef[j] = cw * cw * s->sep_r[k][i] * (1 + 2 / cells) / d;
                P->hard[j] = cw * Hb * 2 * EF_NOISE_BOUND * env_int;
                const double x = fmin(SEP_SIGMAS * H[k] * sqrt(P->coef[j] * ms * L), P->hard[j]);
                e2[j] = x * x;
            }
            int p = n++;
            while (p > 0 && cost[order[p - 1]] < cells) {
                order[p] = order[p - 1];
                --p;
            }
            order[p] = j;
        }
    memset(P->drop, 0, sizeof P->drop);
    P->var = 0;
    P->ndrop = 0;
    double left = 0;   /* the pieces the octaves not yet dropped take */
    for (int p = 0; p < n; ++p)
        left += cost[p] + 1;
    for (int p = 0; p < n; ++p) {
        const int j = order[p];
        /* past the work bound: dropped while the rest take more than
         * force pieces, whatever their estimate */
        if (!(P->var + e2[j] <= budget2) && !(force > 0 && isfinite(e2[j]) && left > force))
            break;
        left -= cost[j] + 1;
        P->var += e2[j];
        P->drop[j] = 1;
        P->ndrop += 1;
    }
    P->pieces = 0;
    for (int k = 0; k < M; ++k) {
        P->konst[k] = 0;
        P->dms[k] = 0;
        for (int i = 0; i < N; ++i)
            if (P->drop[k * N + i]) {
                P->konst[k] += s->fbm.weight[i] * s->sep_mu[k][i];
                P->dms[k] += s->contrast * s->contrast * s->fbm.weight[i] * s->fbm.weight[i] *
                             s->sep_ms[k][i];
            } else {
                P->pieces += cost[k * N + i] + 1;
            }
        P->konst[k] = 1 + s->contrast * P->konst[k];
    }
}

/* One ray's walk: the running value, the estimate's square so far, the
 * quadrature's bound, and the cut. */
typedef struct sep_walk {
    ksum acc;
    double var, quad, cut_unit;
    long double cut_at;
} sep_walk;

/* Walks segment P of R piece by piece between the kept octaves' faces,
 * ng Gauss nodes a piece, adding to W's value and quadrature bound, and
 * into Q per factor the integral of h_k^2 env^2 (what the dropped
 * octaves' estimate needs); stops where W's value less its estimate
 * passes W->cut_unit (W->cut_at >= 0 then). Inlined into the caller,
 * so each of its builds (EF_MULTIVERSION) has its own. */
EF_INLINE void walk_segment(rayc *R, const sep_plan *P, int ng, sep_walk *W, double Q[3])
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves, M = s->naxes;
    const double c = s->contrast, a = s->k > 0 ? R->khs : 0;
    const double *gx = s->glx[ng], *gw = s->glw[ng], *konst = P->konst;
    double frac0[3 * EF_FBM_MAX_OCTAVES];
    const double *cp[3 * EF_FBM_MAX_OCTAVES];
    sep_line ln[3 * EF_FBM_MAX_OCTAVES];
    int m = 0;
    for (int k = 0; k < M; ++k)
        for (int i = 0; i < N; ++i) {
            if (P->drop[k * N + i])
                continue;
            const lin *u = &R->u[s->axis[k] * N + i];
            sep_line *l = &ln[m++];
            l->b = u->bd;
            l->d = u->dd;
            const double v = l->b + P->ta * l->d;
            l->cell = floor(v);
            if (l->d < 0 && l->cell == v)
                l->cell -= 1;   /* on a face, moving down: the cell below */
            l->next = line_exit(l);
            l->poly = (const double *) (const void *) s + s->fpoly_off +
                      ((size_t) k * (size_t) N + (size_t) i) * 256 * 7;
            l->w = s->fbm.weight[i];
            l->slot = k;
        }
    double ta = P->ta;
    const double te = P->tb;
    while (ta < te) {
        double tb = te;
        for (int q = 0; q < m; ++q)
            if (ln[q].next < tb)
                tb = ln[q].next;
        if (tb > ta) {
            for (int q = 0; q < m; ++q) {
                const double f = (ln[q].b - ln[q].cell) + ta * ln[q].d;
                frac0[q] = f;
                cp[q] = ln[q].poly + 7 * (size_t) ((int64_t) ln[q].cell & 255);
            }
            /* split where the envelope changes by more than e^SEP_ENV_STEP */
            const double h = tb - ta;
            const int sub = a != 0 && fabs(a) * h > SEP_ENV_STEP ? (int) ceil(fabs(a) * h / SEP_ENV_STEP) : 1;
            const double hs = h / sub;
            double piece = 0, emax = 0;
            for (int z = 0; z < sub; ++z) {
                const double za = ta + z * hs;
                const double ez = s->k > 0 ? exp(-(R->kh0 + R->khs * za)) : 1;
                emax = fmax(emax, a < 0 ? ez * exp(-a * hs) : ez);
                /* the nodes' offsets from ta and their weights times the
                 * envelope's change from za */
                double dt[GL_MAX], wt[GL_MAX], w2[GL_MAX], F[3][GL_MAX];
                env_nodes(a * hs, gx, ng, wt);
                for (int g = 0; g < ng; ++g) {
                    const double en = wt[g];
                    dt[g] = z * hs + (1 + gx[g]) / 2 * hs;
                    wt[g] = gw[g] * en;
                    w2[g] = wt[g] * en;
                }
                for (int k = 0; k < M; ++k)
                    for (int g = 0; g < ng; ++g)
                        F[k][g] = 0;
                for (int q = 0; q < m; ++q) {
                    const double *p = cp[q], f0 = frac0[q], d = ln[q].d, w = ln[q].w;
                    double *Fk = F[ln[q].slot];
                    for (int g = 0; g < ng; ++g) {
                        double y = f0 + dt[g] * d;
                        y = y < 0 ? 0 : y;
                        y = y > 1 ? 1 : y;
                        Fk[g] += w * cell_poly_at(p, y);
                    }
                }
                double sum = 0, q[3] = { 0, 0, 0 };
                for (int g = 0; g < ng; ++g) {
                    double v = wt[g], V2[3];
                    for (int k = 0; k < M; ++k) {
                        const double V = konst[k] + c * F[k][g];
                        v *= V;
                        V2[k] = V * V + P->dms[k];
                    }
                    sum += v;
                    if (M == 1)
                        q[0] += w2[g];
                    else if (M == 2)
                        q[0] += w2[g] * V2[1], q[1] += w2[g] * V2[0];
                    else
                        q[0] += w2[g] * V2[1] * V2[2], q[1] += w2[g] * V2[0] * V2[2],
                        q[2] += w2[g] * V2[0] * V2[1];
                }
                piece += ez * sum * hs / 2;
                for (int k = 0; k < M; ++k)
                    Q[k] += ez * ez * q[k] * hs / 2;
            }
            R->evals += (double) ng * sub * m;
            R->cells += 1;
            kadd(&W->acc, piece);
            if (a != 0) {
                /* The rule is exact for the product times the envelope's
                 * Taylor terms to degree 2 ng - 1 - 6 M = 5; the next,
                 * (a hs)^6 / 6! of the envelope at most, which the rule
                 * and the integral each take at most once. */
                const double y = fabs(a) * hs;
                const double y3 = y * y * y;
                W->quad += 2 * y3 * y3 / 720 * s->bound * h * emax;
            }
        }
        for (int q = 0; q < m; ++q)
            while (ln[q].next <= tb) {
                ln[q].cell += ln[q].d > 0 ? 1 : -1;
                ln[q].next = line_exit(&ln[q]);
            }
        ta = tb;
        if (W->cut_unit < INFINITY && ta < te && kval(&W->acc) - sqrt(W->var) - W->quad >= W->cut_unit) {
            W->cut_at = ta;
            break;
        }
    }
}

/* Segments: each where the envelope falls by at most e^SEP_SEG and the
 * finest factor octave crosses at most SEP_SEG_CELLS cells (at most
 * SEP_SEGS of equal length). */
#define SEP_SEG 1.0
#define SEP_SEG_CELLS 1024
#define SEP_SEGS 256

EF_MULTIVERSION double ef_nz_separable_fast(rayc *R, long double t0l, long double tendl, double tol,
                                            double cut_unit, double *est, long double *cut_at,
                                            double *dropped, int *over_out)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves, M = s->naxes;
    const double t0 = (double) t0l, tend = (double) tendl, L = tend - t0;
    const double c = s->contrast;
    *cut_at = -1;
    *est = 0;
    *dropped = 0;
    if (!(L > 0))
        return 0;
    /* What multiplies a dropped octave of factor k: every other factor,
     * independent of it, whose mean square is 1 + c^2 sum_i w_i^2 ms_i
     * (octaves independent, means 0). */
    double H[3];
    for (int k = 0; k < M; ++k) {
        H[k] = 1;
        for (int o = 0; o < M; ++o) {
            double v = 1;
            for (int i = 0; o != k && i < N; ++i)
                v += c * c * s->fbm.weight[i] * s->fbm.weight[i] * s->sep_ms[o][i];
            H[k] *= v;
        }
        H[k] = sqrt(H[k]);
    }
    /* The segments: where the envelope decays, each where it falls by
     * e^SEP_SEG. Each is planned when the walk reaches it, with its share
     * of the budget's square (its part of the envelope's integral still
     * to come) out of what the segments before left: the budget itself
     * grows with the lower value of tau reached (an error past it moves T
     * by T times as much). A dropped octave's square falls with the
     * envelope's square, its share only with the envelope: far segments
     * drop more. */
    const double a = s->k > 0 ? R->khs : 0;
    double dmax = 0;
    for (int k = 0; k < M; ++k)
        for (int i = 0; i < N; ++i)
            dmax = fmax(dmax, fabs(R->u[s->axis[k] * N + i].dd));
    const double nenv = a > 0 ? a * L / SEP_SEG : 1, ncell = dmax * L / SEP_SEG_CELLS;
    const int nseg = (int) fmax(1, fmin(SEP_SEGS, ceil(fmax(nenv, ncell))));
    const double lo1 = 1 - fabs(c) * EF_NOISE_BOUND;
    const double least = lo1 > 0 ? pow(lo1, M) : 0;   /* the shape's least value */
    int over = 0;
    /* A product of M polynomials of degree 6: 3M + 1 nodes are exact; 2
     * more take the envelope's first terms exactly too. */
    const int ng = a != 0 ? 3 * M + 3 : 3 * M + 1;
    sep_walk W = { { 0, 0 }, 0, 0, cut_unit, -1 };
    for (int sg = 0; sg < nseg && W.cut_at < 0; ++sg) {
        sep_plan P;
        P.ta = sg == 0 ? t0 : t0 + L * sg / nseg;
        P.tb = sg == nseg - 1 ? tend : t0 + L * (sg + 1) / nseg;
        over |= R->evals > SEP_EVAL_CAP;
        if (over) {   /* the rest of the ray as one last segment */
            P.tb = tend;
            sg = nseg - 1;
        }
        const double rest = (double) ef_nz_env_integral(s, R->h0, R->hs, P.ta, tendl);
        const double seg = (double) ef_nz_env_integral(s, R->h0, R->hs, P.ta, P.tb);
        const double lo = kval(&W.acc) - sqrt(W.var) - W.quad + least * rest;
        const double B = sg == 0 ? tol : fmax(tol, ef_nz_ttol_dtau(s, lo));
        const double b = 0.9 * B / s->rho_max;   /* B is in tau of the densest channel */
        const double left = b * b - W.var;
        /* past the work bound: what the rest may still take, a quarter
         * of it, in pieces of every line */
        const double allow = fmax(SEP_FORCE_PIECES, (SEP_EVAL_CAP * 1.25 - R->evals) / (ng * M * N));
        plan_segment(R, H, left > 0 && rest > 0 ? left * fmin(1, seg / rest) : 0, over ? allow : 0, &P);
        if (!over && R->evals + P.pieces * ng * (M * N - P.ndrop) > SEP_EVAL_CAP * 1.25) {
            /* this segment would pass the work bound by more than a
             * quarter: the rest as one last segment, held to that */
            over = 1;
            P.tb = tend;
            sg = nseg - 1;
            plan_segment(R, H, left > 0 ? left : 0, allow, &P);
        }
        if (P.ndrop > *dropped)
            *dropped = P.ndrop;   /* the most any segment dropped */
        W.var += P.var;
        double Q[3] = { 0, 0, 0 };
        walk_segment(R, &P, ng, &W, Q);
        /* the segment's estimate from the factors the walk met (what
         * multiplies a dropped octave on this ray, not its mean over
         * rays), in place of the plan's */
        double post = 0;
        for (int k = 0; k < M; ++k)
            for (int i = 0; i < N; ++i) {
                const int j = k * N + i;
                if (P.drop[j]) {
                    const double x = fmin(SEP_SIGMAS * sqrt(P.coef[j] * Q[k]), P.hard[j]);
                    post += x * x;
                }
            }
        W.var += post - P.var;
    }
    *cut_at = W.cut_at;
    *over_out = over;
    /* rounding: as the exact method's, 1e-13 of tau */
    *est = sqrt(W.var) + W.quad + 1e-13 * fabs(kval(&W.acc));
    return kval(&W.acc);
}
