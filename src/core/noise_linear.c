/* The default method of the noise model (fog_noise.c's family;
 * noise_fog.h): tau under ttol segment by segment, each segment planned
 * within its share of the budget (noise_plan.c), the clamp's share where
 * max(0, 1 + c fbm) can bind worked out on a tree of stretches from the
 * unresolved octaves' stop-loss statistics (noise_clamp.h), and the ray
 * stopped where the rest can no longer show. Pure: no I/O, no globals. */
#include "noise_fog.h"

/* ---- adaptive, density linear in the noise: segment by segment ---- */

/* The envelope e^-(kh0 + khs t) in double, for planning the segments (the
 * closed-form mean part that enters tau stays env_integral's, in long
 * double). adaptive_linear runs only where kh0 and khs are finite, and
 * the exponent stays below 690 on the ray (env_overflows). */
static inline double env_d(const rayc *R, double t)
{
    return R->s->k > 0 ? exp(-(R->kh0 + R->khs * t)) : 1;
}

/* The integral of the envelope over a stretch of length L where it starts
 * at e and decays at rate a (grows where a < 0), and its value at the end
 * (one expm1, and an exp where the end is far below the start). */
static double env_step(double e, double a, double L, double *e_end)
{
    const double b = a * L;
    if (fabs(b) < 1e-8) {
        *e_end = e;
        return e * L;
    }
    const double x = expm1(-b);
    *e_end = b > 1 ? e * exp(-b) : e * (1 + x);
    return -e * x / a;
}

/* env_reach_d with the envelope at t0 given (e0). */
static double env_reach_e(const rayc *R, double e0, double t0, double need)
{
    const double a = R->s->k > 0 ? R->khs : 0;
    if (!(e0 > 0))
        return INFINITY;
    if (a == 0)
        return t0 + need / e0;
    if (a > 0) {
        const double x = need * a / e0;
        return x < 1 ? t0 - log1p(-x) / a : INFINITY;
    }
    return t0 + log1p(need * -a / e0) / -a;
}

/* env_reach in double: the t past t0 where the envelope's integral from t0 reaches need
 * (INFINITY if it never does). */
static double env_reach_d(const rayc *R, double t0, double need)
{
    return env_reach_e(R, env_d(R, t0), t0, need);
}

/* Four standard deviations of the fbm's part, integral(env fbm), over a
 * stretch of length L whose envelope is at most emax (and monotone; m:
 * its integral there), octave by octave: the line
 * integral of octave i weighted by the envelope has a variance of about
 * LINE_RMS^2 lambda_i integral(env^2) (cells far apart are independent),
 * or its hard bound B m if smaller. Along a thinning envelope this is far
 * below the largest envelope times the flat estimate over the length. */
static double noise_sigma4(const rayc *R, double emax, double L, double m)
{
    const nstate *s = R->s;
    const double i2 = decay_int(emax * emax, s->k > 0 ? 2 * fabs(R->khs) : 0, L);
    const double si2 = sqrt(i2);
    double r = 0;
    for (int i = 0; i < s->fbm.octaves; ++i)
        r += s->fbm.weight[i] * fmin(EF_NOISE_BOUND * m, 4 * s->line_rms[i] * si2);
    return r;
}

/* The adaptive method's work bound per ray, in node evaluations (cells
 * times nodes over every octave): under a millisecond of one core. Past
 * it, the finest octaves still kept are dropped with three standard
 * deviations of their line integrals as the error, and the pixel is
 * counted as over the budget (--stats). */
#define EVAL_BUDGET 40000
/* A segment's mean optical depth (densest channel), and its length in
 * cells of the coarsest octave, at most. (A depth of 3 rather than 1: a
 * tenth faster on the horizon shot, 7 % more evaluations but fewer
 * segments, each with its own planning and end terms.) */
#define SEG_TAU 3.0
#define SEG_CELLS 16.0
/* Segments per ray, at most (they then grow past SEG_CELLS). */
#define MAX_SEGS 256

/* ---- the clamp on the fast path ----
 *
 * max(0, D) = D + max(0, -D) with D = 1 + c fbm: the clamped density is
 * the linear one, which adaptive_linear integrates as for |c| <= 0.9649,
 * plus the clamp's share env max(0, -D), zero wherever D > 0. The share
 * is worked out on a binary tree of stretches of the segment. On a
 * stretch, the octaves whose cells are at least twice its length are
 * resolved (smooth there: known at its ends and middle), the finer ones
 * are not, and enter through their distribution (noise_clamp.h): the
 * share's expectation given the resolved octaves' sum F is |c| m_j(y),
 * y = (1 + c F) / |c|. Where y is linear in t, its integral is exact
 * whatever the kink: m_j = -v_j' / 2, so the integral of m_j(y(t)) over
 * [a, b] is (v_j(y_a) - v_j(y_b)) / (2 y'). The rule takes y linear
 * between the ends, and between each end and the middle; their difference
 * is the deterministic part of the error (y's curvature), with the
 * envelope's variation over the stretch times the share's. The realised
 * share differs from its expectation by a zero-mean error whose variance
 * is the pointwise variance times the length times a correlation length
 * (that of the coarsest unresolved octave's noise, CLAMP_CORR of its
 * cell): four standard deviations of it are the statistical part, added in
 * quadrature over stretches. Stretches are halved (resolving more
 * octaves) until both parts fit the stretch's share of the budget; once
 * every octave is resolved, X = 0 and the same rule integrates max(0, -y)
 * exactly for linear y. Where the clamp cannot bind at all (m_j = 0 over
 * the stretch, by the resolved octaves' Lipschitz spread between the
 * points) the share is 0 with no error: a shot whose |c| is just above 1
 * costs nothing, its fbm never reaching -1/c. At the work bound a stretch
 * is taken as it is, with its error. */

/* The correlation length of one octave's noise along a line, in its cells:
 * LINE_RMS^2 / Var(noise) = 0.0625 / 0.0731 (noise-anchors.md; the
 * variance measured over 4 million points). */
#define CLAMP_CORR 0.86
/* Halvings of one segment, at most (2^-40 of it: rounding below that). */
#define CLAMP_DEPTH 40
/* A stretch clamped throughout has its share integrated exactly, cell by
 * cell, only while at most this many octaves are resolved (long stretches,
 * coarse cells); deeper in the tree the rule's three points cost less
 * than 17 evaluations a cell of every resolved octave (corner-c4-8oct:
 * 14,516 -> 11,138 evaluations a pixel, 88 -> 96 % of pixels within
 * 2^-12 as fewer reach the work bound, though 18 % more CPU: the rule's
 * points cost more than the walk's nodes; sweep-19 3,316 -> 2,854 and 6 %
 * less CPU; sweep-01 576 -> 647). */
#define CLAMP_EXACT_J 2


/* A point of the tree: t, the sum of its first j octaves, and j. */
typedef struct clamp_pt {
    double t, F;
    int j;
} clamp_pt;

typedef struct clamp_job {
    clamp_pt a, b;
    int depth;
} clamp_job;

/* The clamp tree's books: the share so far, its two error parts, and what
 * is left of the budget and of the segment (see clamp_part). */
typedef struct clamp_books {
    ksum acc;
    double dsum, s2, dleft, vleft, lenleft;
} clamp_books;

/* Takes a stretch of length len with value v, deterministic error d and
 * squared statistical error s2. */
static void clamp_take(clamp_books *B, double v, double d, double s2, double len)
{
    kadd(&B->acc, v);
    B->dsum += d;
    B->s2 += s2;
    B->dleft -= d;
    B->vleft -= s2;
    B->lenleft -= len;
}

/* Brings p's sum to the first j octaves. */
static void clamp_extend(rayc *R, clamp_pt *p, int j)
{
    for (int i = p->j; i < j; ++i)
        p->F += R->s->fbm.weight[i] * octave_at(R, i, p->t);
    if (j > p->j)
        p->j = j;
}

/* The integral over [a, b] of m_j(y(t)), y linear from ya to yb. */
static double clamp_lin(const double *tab, int N, int j, double a, double b, double ya,
                        double yb)
{
    const double L = b - a, dy = yb - ya;
    double va, vb;
    const double ma = ef_clamp_m(tab, N, j, ya, &va), mb = ef_clamp_m(tab, N, j, yb, &vb);
    if (fabs(dy) <= 1e-9 * (1 + fabs(ya)))
        return 0.5 * (ma + mb) * L;
    const double r = (va - vb) / (2 * dy) * L;
    return r > 0 ? r : 0;
}

/* The clamp's share, integral of env max(0, -(1 + c fbm)) over [t0, t1],
 * to within tgt (absolute, in tau / rho) where the work bound allows;
 * adds its deterministic error to *det and the square of its statistical
 * estimate (four standard deviations) to *stat2. */
static double clamp_part(rayc *R, double t0, double t1, double tgt, double *det, double *stat2)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double *tab = (const double *) (const void *) s + s->clamp_off;   /* arr holds s first */
    const double c = s->contrast, ac = fabs(c);
    const double a_env = s->k > 0 ? R->khs : 0, Lseg = t1 - t0;
    if (!(Lseg > 0))
        return 0;
    /* the first j octaves' Lipschitz and curvature bounds, per unit t */
    double lipj[EF_FBM_MAX_OCTAVES + 1] = { 0 }, curvj[EF_FBM_MAX_OCTAVES + 1] = { 0 };
    for (int i = 0; i < N; ++i) {
        const double r = s->fbm.freq[i] / s->scale;
        lipj[i + 1] = lipj[i] + s->fbm.weight[i] * EF_NOISE_LIPSCHITZ * r;
        curvj[i + 1] = curvj[i] + s->fbm.weight[i] * EF_NOISE_CURVATURE * r * r;
    }
    clamp_job stack[CLAMP_DEPTH + 2];
    int sp = 0;
    stack[sp++] = (clamp_job) { { t0, 0, 0 }, { t1, 0, 0 }, 0 };
    /* What is left of the budget (0.7 tgt for the deterministic part, half
     * of tgt^2 for the statistical one) and of the segment: stretches are
     * taken left to right, and one that uses less than its share of what is
     * left (most: the clamp cannot bind there) leaves the rest to the
     * stretches after it. */
    clamp_books B = { { 0, 0 }, 0, 0, 0.7 * tgt, 0.5 * tgt * tgt, Lseg };
    while (sp > 0) {
        clamp_job J = stack[--sp];
        const double len = J.b.t - J.a.t, h = 0.5 * len;
        /* the resolved octaves: the first j, cells at least twice the stretch */
        int j = 0;
        while (j < N && s->scale / s->fbm.freq[j] >= 2 * len)
            ++j;
        /* how far y may leave the chords between the points: by the
         * resolved octaves' curvature (|y''| <= K: h^2 / 8 on a half of
         * length h) or their Lipschitz bound (h / 2), whichever is less */
        const double dlt = fmin(curvj[j] * h * h / 8, lipj[j] * h / 2);
        clamp_pt mid = { J.a.t + h, 0, 0 };
        clamp_extend(R, &J.a, j);
        clamp_extend(R, &J.b, j);
        clamp_extend(R, &mid, j);
        const double ya = (1 + c * J.a.F) / ac, yb = (1 + c * J.b.F) / ac, ym = (1 + c * mid.F) / ac;
        double v;
        if (ef_clamp_m(tab, N, j, fmin(ym, fmin(ya, yb)) - dlt, &v) == 0) {
            B.lenleft -= len;
            continue;   /* the clamp cannot bind on this stretch */
        }
        const double ea = env_d(R, J.a.t);
        double em, eb;
        const double m1 = env_step(ea, a_env, h, &em), m2 = env_step(em, a_env, h, &eb);
        const double share = B.lenleft > len ? len / B.lenleft : 1;
        const int leaf = J.depth >= CLAMP_DEPTH || R->evals > EVAL_BUDGET;
        const double corr = j < N ? CLAMP_CORR * s->scale / s->fbm.freq[j] : 0;
        /* the unresolved octaves' line integral: four standard deviations */
        const double sd_deep = 4 * fmax(ea, eb) * ac *
                               sqrt(ef_clamp_var(tab, N, j) * len * fmin(len, corr));
        if (j <= CLAMP_EXACT_J && fmax(ym, fmax(ya, yb)) + dlt < -ef_clamp_ymax(tab, N, j) &&
            (sd_deep * sd_deep <= fmax(B.vleft, 0) * share || leaf)) {
            /* clamped throughout, whatever the unresolved octaves do: the
             * share is -(integral(env) + c sum_i w_i integral(env n_i)),
             * the resolved octaves' integrals cell by cell (9 Gauss nodes
             * per cell piece: exact without an envelope; with one, the
             * change from 8 nodes bounds what is left), the unresolved
             * ones' 0 with four standard deviations of their line
             * integral (as the linear part's drop rule) */
            double iv = 0, iv8 = 0;
            for (int i = 0; i < j; ++i) {
                const double w = s->fbm.weight[i];
                if (s->k > 0) {
                    iv += w * ef_nz_octave_integral_env(R, i, 9, J.a.t, J.b.t);
                    iv8 += w * ef_nz_octave_integral_env(R, i, 8, J.a.t, J.b.t);
                } else {
                    iv += w * ef_nz_octave_integral_fast(R, i, 9, J.a.t, J.b.t);
                }
            }
            const double sh = -(m1 + m2 + c * iv);
            const double e9 = (s->k > 0 ? ac * fabs(iv - iv8) : 0) + 1e-13 * (m1 + m2 + ac * fabs(iv));
            clamp_take(&B, sh > 0 ? sh : 0, e9, sd_deep * sd_deep, len);
            continue;
        }
        /* y's chords through the three points, shifted by -dlt (the most
         * the share can be, m_j decreasing) and +dlt (the least) */
        double rule[3];
        for (int k = 0; k < 3; ++k) {
            const double sh = (k - 1) * dlt;
            rule[k] = m1 / h * clamp_lin(tab, N, j, J.a.t, mid.t, ya + sh, ym + sh) +
                      m2 / h * clamp_lin(tab, N, j, mid.t, J.b.t, ym + sh, yb + sh);
        }
        const double two = rule[1];
        double var_g = 0, gmax = 0, gmin = INFINITY;
        const double ys[3] = { ya, ym, yb };
        for (int k = 0; k < 3; ++k) {
            double vk;
            const double mk = ef_clamp_m(tab, N, j, ys[k], &vk);
            const double vg = vk - mk * mk;
            var_g = fmax(var_g, vg > 0 ? vg : 0);
            gmax = fmax(gmax, mk);
            gmin = fmin(gmin, mk);
        }
        /* the bracket's far side, and the envelope's spread over each half
         * times the share's */
        const double emax = fmax(ea, eb), emin = fmin(ea, eb);
        const double d = ac * (fmax(rule[0] - two, two - rule[2]) +
                               0.5 * (emax - emin) * (gmax - gmin + 2 * dlt) * len);
        const double sig4 = 4 * emax * ac * sqrt(var_g * len * fmin(len, corr));
        if ((d <= fmax(B.dleft, 0) * share && sig4 * sig4 <= fmax(B.vleft, 0) * share) || leaf) {
            clamp_take(&B, ac * two, d, sig4 * sig4, len);
            continue;
        }
        stack[sp++] = (clamp_job) { mid, J.b, J.depth + 1 };
        stack[sp++] = (clamp_job) { J.a, mid, J.depth + 1 };
    }
    *det += B.dsum;
    *stat2 += B.s2;
    return kval(&B.acc);
}

/* ---- lod=pixel on the fast path ----
 *
 * Along a ray from the bound camera the distance is t, and octave i's
 * weight is 1 up to S_i and e^(-LOD_RATE (t / S_i - 1)) past it: times
 * the envelope e^-(kh0 + khs t), again an exponential,
 * e^-((kh0 - LOD_RATE) + (khs + LOD_RATE / S_i) t). So past S_i the octave
 * goes through the same cell walk or grid with that envelope (their error
 * calibrations hold for any exponential weight), and a segment that
 * straddles S_i is integrated in two parts (each smooth; the weight's kink
 * is at their join). The planner sees each octave's faded moments. */

/* Octave i's fade reaches e^-36 (2e-16) at this many S_i. */
#define LOD_REACH 10.0

/* Octave i over [a, b] with plan P's way, the envelope as R has it now
 * (env: weighted by it). */
static double plan_octave(rayc *R, const plan *P, int i, double a, double b, grid_end *end,
                          int env)
{
    if (P->nu[i] > 0)
        return env ? ef_nz_octave_grid_env(R, i, P->nu[i], a, b, end)
                   : ef_nz_octave_grid_flat(R, i, P->nu[i], a, b, end);
    return env ? ef_nz_octave_integral_env(R, i, P->q[i], a, b)
               : ef_nz_octave_integral_fast(R, i, P->q[i], a, b);
}

/* integral over [t, tb] of octave i times its fade and the envelope. */
static double lod_octave(rayc *R, const plan *P, int i, double t, double tb, grid_end *end)
{
    const double S = R->s->lod_S[i];
    double v = 0;
    if (t < S)
        v += plan_octave(R, P, i, t, tb < S ? tb : S, end, R->s->k > 0);
    if (tb > S) {
        const double kh0 = R->kh0, khs = R->khs;
        R->kh0 = kh0 - LOD_RATE;
        R->khs = khs + LOD_RATE / S;
        v += plan_octave(R, P, i, t > S ? t : S, tb, end, 1);
        R->kh0 = kh0;
        R->khs = khs;
    }
    return v;
}

/* Each octave's faded envelope over [t, tb] against the envelope's own
 * (e_t: the envelope at t, m: its integral there): fm[i] the ratio of the
 * integrals, fq[i] the square root of the ratio of the integrals of the
 * squares. Returns 0 when no octave fades on the segment (fm, fq unset). */
static int lod_moments(const rayc *R, double t, double tb, double e_t, double m, double *fm,
                       double *fq)
{
    const nstate *s = R->s;
    const double a = s->k > 0 ? R->khs : 0;
    int any = 0;
    double e_end, q;
    if (!(m > 0))
        return 0;
    const double Q = env_step(e_t * e_t, 2 * a, tb - t, &e_end);
    for (int i = 0; i < s->fbm.octaves; ++i) {
        const double S = s->lod_S[i];
        if (!(tb > S)) {
            fm[i] = fq[i] = 1;
            continue;
        }
        any = 1;
        /* [t, S] whole, then from x0 = max(t, S) the faded exponential */
        const double x0 = t > S ? t : S;
        double m1 = 0, q1 = 0;
        if (t < S) {
            m1 = env_step(e_t, a, S - t, &e_end);
            q1 = env_step(e_t * e_t, 2 * a, S - t, &e_end);
        }
        const double e0 = e_t * exp(-a * (x0 - t)) * lod_phi(x0 / S);
        const double m2 = env_step(e0, a + LOD_RATE / S, tb - x0, &e_end);
        q = env_step(e0 * e0, 2 * (a + LOD_RATE / S), tb - x0, &e_end);
        fm[i] = fmin(1, (m1 + m2) / m);
        fq[i] = Q > 0 ? sqrt(fmin(1, (q1 + q) / Q)) : 1;
    }
    return any;
}

/* ---- a certified lower bound of what is still to come ----
 *
 * A segment's error d in tau moves the final T by at most W d, W from a
 * lower value of the whole ray's tau. Ahead of the segments, that lower
 * value is the rest's mean less four standard deviations of its noise, or
 * (1 - |c| B) times its mean: with the clamp (|c| B > 1) and the fog
 * gathered in a few cells (a ray descending into steep height fog) both
 * are 0, so every early segment is integrated as if the ray stayed clear,
 * though it ends opaque (a contrast of 2.61 took 5,293 noise evaluations
 * a pixel where 0.9 takes none). The pilot bounds the rest from below
 * with certainty, from its densest end: on stretches of length h, the
 * first j octaves at the middle (cells coarse enough that |c| times the
 * finer octaves' bound is at most 1/2), less |c| times their Lipschitz
 * spread over h/2 (1/4) and the finer octaves' bound, times the least
 * envelope there: max(0, D) >= that wherever it is positive. It runs only
 * where the mean fog alone would stop the ray and the walk it could spare
 * is longer than itself, not under lod=pixel (whose faded weights it does
 * not know), and at most PILOT_N stretches. */
#define PILOT_N 48
/* Evaluations a walked cell costs at least (a grid's node or a walk's
 * piece), for the pilot's gate. */
#define PILOT_CELL_EVALS 2.0

typedef struct pilot {
    int n;
    double a[PILOT_N], v[PILOT_N];   /* a stretch's start and its lower bound (tau / rho) */
} pilot;

/* A lower value of tau / rho over a stretch of length L whose envelope is
 * at most emax and whose mean fog is m: m less four standard deviations of
 * its noise (noise_sigma4), or (1 - |c| B) m, whichever is larger (either
 * may be negative: nothing known). */
static double rest_lower(const rayc *R, double emax, double L, double m)
{
    const double ac = fabs(R->s->contrast);
    return fmax(m - ac * noise_sigma4(R, emax, L, m), (1 - ac * EF_NOISE_BOUND) * m);
}

/* Fills P over [t0, t1] (finite) until its sum reaches goal. */
static void pilot_run(rayc *R, double t0, double t1, double goal, pilot *P)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double ac = fabs(s->contrast);
    P->n = 0;
    int j = 0;
    double bx = 0;
    for (int i = 0; i < N; ++i)
        bx += s->fbm.weight[i] * EF_NOISE_BOUND;
    while (j < N && ac * bx > 0.5)
        bx -= s->fbm.weight[j++] * EF_NOISE_BOUND;
    if (j == N)
        bx = 0;
    double lip = 0;
    const double nd = sqrt(R->dir[0] * R->dir[0] + R->dir[1] * R->dir[1] + R->dir[2] * R->dir[2]);
    for (int i = 0; i < j; ++i)
        lip += s->fbm.weight[i] * EF_NOISE_LIPSCHITZ * s->fbm.freq[i] / s->scale * nd;
    const double L = t1 - t0;
    double h = lip > 0 ? 0.5 / (ac * lip) : L;
    if (!(L > 0) || !(h > 0))
        return;
    if (h > L)
        h = L;
    const int back = s->k > 0 && R->khs < 0;   /* the envelope grows along the ray */
    double sum = 0;
    for (int k = 0; k < PILOT_N && sum < goal; ++k) {
        const double a = back ? t1 - (k + 1) * h : t0 + k * h, b = a + h;
        if (a < t0 - 1e-9 * L || b > t1 + 1e-9 * L)
            break;
        double F = 0;
        for (int i = 0; i < j; ++i)
            F += s->fbm.weight[i] * octave_at(R, i, a + 0.5 * h);
        const double d = 1 + s->contrast * F - 0.25 - ac * bx;
        const double v = d > 0 ? fmin(env_d(R, a), env_d(R, b)) * d * h : 0;
        P->a[P->n] = a;
        P->v[P->n++] = v;
        sum += v;
    }
}

/* P's bound of what lies past t. */
static double pilot_rest(const pilot *P, double t)
{
    double r = 0;
    for (int k = 0; k < P->n; ++k)
        if (P->a[k] >= t)
            r += P->v[k];
    return r;
}

double ef_nz_stop_report(const nstate *s, double lo, double est, double errk[3])
{
    /* The estimate lies within [0, T_up]; at least ln 2 above lo it is at
     * most T_up / 2, so the error output, at least T itself, spans
     * [0, T_up]. Past 600 above lo it is held there: still within, and T
     * would underflow and expm1 overflow. */
    const double rmin = ef_nz_rho_min(s);
    double unit = est;
    if (rmin * (unit - lo) < LN2)
        unit = lo + LN2 / rmin;
    if (s->rho_max * (unit - lo) > 600)
        unit = lo + 600 / s->rho_max;
    for (int k = 0; k < 3; ++k)
        errk[k] = s->rho[k] > 0 ? fmax(LN2, s->rho[k] * (unit - lo)) : 0;
    return unit;
}

/* The noise part's integral for the linear density (noise, |c| <= 0.9649)
 * under ttol (the default) over [t0, tend], segment by segment, and
 * tau / rho (the closed-form mean to t1 plus c times it). Each segment gets
 * a share of the budget, 3/4 ttol in T: an error d in tau anywhere on the
 * ray moves the final T by T d, so by at most W d, W = max over channels
 * of rho_k e^-(rho_k lo), lo a lower value of the whole ray's tau / rho;
 * on a ray whose T ends small every segment, the first too, may drop
 * octaves and nodes.
 * Segments share no cell, so their estimates (each a 3 or 4 sigma figure)
 * add in variance: the share of the budget's square is the segment's part
 * of the mean fog still to come that can show (up to where T falls below
 * ttol/4), taken from what is left, so the squares never sum past it (the
 * reported error is their root sum of squares). The ray stops where
 * T_k is below ttol/4 in every channel: the rest can move T by no more.
 * errk receives the error per channel in tau (the LN2 marker's meaning
 * where it stopped: T_k itself may be the error). */
double ef_nz_adaptive_linear(rayc *R, long double t0, long double tend, long double t1,
                             int opaque, double tail, ef_tau_info *info, double errk[3])
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double eps = s->ttol, rmin = ef_nz_rho_min(s);
    const double tau_stop = ef_nz_tau_stop(s);
    double cross[EF_FBM_MAX_OCTAVES];
    for (int i = 0; i < N; ++i)
        cross[i] = (double) (fabsl(R->u[3 * i].d) + fabsl(R->u[3 * i + 1].d) +
                             fabsl(R->u[3 * i + 2].d));
    /* An octave whose cells number more than CELL_BUDGET (a scale far
     * below the ray's length) is never walked: each segment counts its
     * integral as its mean, 0, with the drop rule's estimate. The length
     * that counts: up to where the mean fog alone reaches four times the
     * stop's depth (the ray has all but certainly stopped by then; if not,
     * the work bound takes over), since a slowly climbing sky ray's tail
     * is far longer than what it walks. */
    double Lwalk = (double) (tend - t0);
    {
        const double lo1 = 1 - fabs(s->contrast) * EF_NOISE_BOUND;
        const double need = 4 * tau_stop / (rmin * (lo1 > 0.25 ? lo1 : 0.25));
        const double reach = env_reach_d(R, (double) t0, need) - (double) t0;
        if (reach < Lwalk)
            Lwalk = reach;
    }
    unsigned over = 0;
    int first = N;
    /* lod=pixel: octave i counts to where its fade is e^-36 */
    const int lod = s->spread > 0;
    for (int i = N - 1; i >= 0; --i) {
        const double Li = lod ? fmin(Lwalk, LOD_REACH * s->lod_S[i]) : Lwalk;
        if (!(cross[i] * Li <= CELL_BUDGET))
            over |= 1u << i;
        else
            first = i;
    }
    long double Lmax = first < N && cross[first] > 0 ? SEG_CELLS / cross[first] : Lwalk;
    if (Lmax < Lwalk / MAX_SEGS)
        Lmax = Lwalk / MAX_SEGS;
    ksum noise = { 0, 0 }, corr = { 0, 0 };   /* corr: the clamp's share */
    double corr_err = 0;
    grid_end ends[EF_FBM_MAX_OCTAVES];
    for (int i = 0; i < N; ++i)
        ends[i].valid = 0;
    seg_planner SP;
    const int grid = ef_nz_seg_planner_init(R, &SP);
    /* E2: the sum of the segments' squared estimates (independent errors
     * of segments that share no cell add in variance); var: what is left
     * of the budget's square, (3/4 eps)^2 (ttol/4 is the stop's). */
    double E2 = 0, var = 0.5625 * eps * eps, mean_sofar = 0;
    int stop = 0, dropped = 0;
    long double t = t0;
    /* the pilot, where the mean fog alone would stop the ray but neither
     * lower value of the rest can show it (the clamp) */
    pilot PL = { 0, { 0 }, { 0 } };
    if (!lod && 1 - fabs(s->contrast) * EF_NOISE_BOUND < 0.25) {
        const double mean = (double) ef_nz_env_integral(s, R->h0, R->hs, t0, tend);
        const double lo_rest =
            rest_lower(R, fmax(env_d(R, (double) t0), env_d(R, (double) tend)),
                       (double) (tend - t0), mean);
        /* The pilot can only spare the walk of octaves it lets drop: at
         * most every octave's cells up to where the mean fog alone stops
         * the ray. Where that walk is shorter than the pilot's own worst
         * (PILOT_N points), it costs more than it can save, and the
         * octaves it drops widen the stop's margin, which the ray then
         * walks on to cover (sweep-10: 3.4 segments a ray without it, 11
         * with). */
        double cells = 0;
        if (rmin * mean >= tau_stop && !(rmin * lo_rest >= tau_stop)) {
            const double Ls = fmin(env_reach_d(R, (double) t0, tau_stop / rmin) - (double) t0,
                                   (double) (tend - t0));
            for (int i = 0; i < N; ++i)
                cells += cross[i] * Ls;
        }
        if (cells * PILOT_CELL_EVALS > PILOT_N)
            pilot_run(R, (double) t0, (double) tend, (tau_stop + 25) / rmin, &PL);
    }
    /* The envelope at the segment's start, carried from the previous
     * segment's end, and at the end of the stretch (the planning's
     * exponentials, one or two per segment). */
    const double a_env = s->k > 0 ? R->khs : 0, e_tend = env_d(R, (double) tend);
    double e_t = env_d(R, (double) t0);
    int rest_try = 0;   /* the last segment dropped every octave */
    while (t < tend) {
        const double rest =
            decay_int(a_env > 0 ? e_t : e_tend, fabs(a_env), (double) (tend - t));
        const double E = sqrt(E2);
        const double ulo = mean_sofar + s->contrast * kval(&noise) + kval(&corr) - E;
        /* lo: ulo plus the rest's lower value (rest_lower, or the pilot's) */
        const double lo_rest = rest_lower(R, fmax(e_t, e_tend), (double) (tend - t), rest);
        const double lo_pilot = PL.n ? pilot_rest(&PL, (double) t) : 0;
        const double lo = ulo + fmax(lo_rest > 0 ? lo_rest : 0, lo_pilot);
        /* done: T_k = e^-(rho_k ulo) <= eps/4 in every channel; W: the
         * largest rho_k e^-(rho_k lo), one exponential per distinct rho */
        int done = t > t0;
        double W = 0;
        for (int k = 0; k < 3; ++k) {
            if (!(s->rho[k] > 0))
                continue;
            done &= s->rho[k] * (ulo > 0 ? ulo : 0) >= tau_stop;
            if ((k < 1 || s->rho[k] != s->rho[0]) && (k < 2 || s->rho[k] != s->rho[1]))
                W = fmax(W, s->rho[k] * exp(-s->rho[k] * (lo > 0 ? lo : 0)));
        }
        if (done) {
            stop = 1;
            break;
        }
        const double togo = (tau_stop - rmin * ulo) / rmin;
        /* Where the last segment dropped every octave and the envelope
         * only thins from here, the whole rest is tried as one segment
         * first, up to where the mean fog would take the ray twice past
         * its stop (which the next step then finds): if its noise fits the
         * budget too, a sky ray's long tail costs one plan, not a segment
         * per stretch. */
        long double tb;
        double e_tb, mj, L, envmax, cquota = 0;
        plan P;
        for (int whole = rest_try && a_env >= 0;; whole = 0) {
            tb = t + Lmax;
            const long double tr = env_reach_e(R, e_t, (double) t, SEG_TAU / s->rho_max);
            if (tr < tb)
                tb = tr;
            if (whole) {
                tb = env_reach_e(R, e_t, (double) t, 2 * togo);
                if (!(tb > t + Lmax))
                    tb = t + Lmax;
            }
            if (!(tb < tend) || !(tb > t))
                tb = tend;
            mj = env_step(e_t, a_env, (double) (tb - t), &e_tb);
            const double vis = fmin(rest, 2 * fmax(togo, mj));
            const double share = vis > mj ? mj / vis : 1;
            const double quota =
                sqrt((var > eps * eps / 4096 ? var : eps * eps / 4096) * share);
            L = (double) (tb - t);
            envmax = fmax(e_t, e_tb);
            /* with the clamp, the linear part takes 0.8 of the quota and
             * the clamp's share 0.6 (their squares sum to it) */
            const double qlin = s->clamp ? 0.8 * quota : quota;
            /* lod=pixel: each octave's share of the envelope's moments */
            double fm[EF_FBM_MAX_OCTAVES], fq[EF_FBM_MAX_OCTAVES];
            const int faded = lod && lod_moments(R, (double) t, (double) tb, e_t, mj, fm, fq);
            if (grid)
                ef_nz_plan_segment(R, &SP, L, mj / L,
                                   decay_int(envmax * envmax, 2 * fabs(a_env), L) / L,
                                   faded ? fm : NULL, faded ? fq : NULL, s->rho_max * qlin / W,
                                   &P);
            else
                ef_nz_plan_octaves(R, L, envmax, s->rho_max * qlin / W, &P);
            cquota = 0.6 * quota / W;
            if (!whole || P.dropped == N)
                break;
        }
        rest_try = P.dropped == N;
        /* An octave over the cell budget is not walked: its estimate here
         * is the drop rule's, segment by segment like any other. */
        for (int i = 0; i < N; ++i)
            if (over >> i & 1) {
                P.est += P.q[i] ? s->rho_max * fabs(s->contrast) * envmax * s->fbm.weight[i] *
                                      ef_nz_line_est(s, i, L, 3)
                                : 0;
                P.q[i] = 0;
            }
        /* The work bound: the finest kept octaves go first. */
        double need = 0;
        for (int i = 0; i < N; ++i)
            need += ef_nz_plan_evals(R, &P, i, L);
        for (int i = N - 1; i > 0 && R->evals + need > EVAL_BUDGET; --i)
            if (P.q[i]) {
                need -= ef_nz_plan_evals(R, &P, i, L);
                P.q[i] = 0;
                P.est += s->rho_max * fabs(s->contrast) * envmax * s->fbm.weight[i] *
                         ef_nz_line_est(s, i, L, 3);
                info->over = 1;
                P.dropped++;
            }
        if (P.dropped > dropped)
            dropped = P.dropped;

        for (int i = 0; i < N; ++i) {
            if (!P.q[i])
                continue;
            double v;
            if (lod)
                v = lod_octave(R, &P, i, (double) t, (double) tb, &ends[i]);
            else if (P.nu[i] > 0)
                v = s->k > 0 ? ef_nz_octave_grid_env(R, i, P.nu[i], (double) t, (double) tb, &ends[i])
                             : ef_nz_octave_grid_flat(R, i, P.nu[i], (double) t, (double) tb, &ends[i]);
            else
                v = s->k > 0 ? ef_nz_octave_integral_env(R, i, P.q[i], (double) t, (double) tb)
                             : ef_nz_octave_integral_fast(R, i, P.q[i], (double) t, (double) tb);
            kadd(&noise, s->fbm.weight[i] * v);
        }
        double used = P.est / s->rho_max;
        if (s->clamp) {
            double cd = 0, cs2 = 0;
            kadd(&corr, clamp_part(R, (double) t, (double) tb, cquota, &cd, &cs2));
            corr_err += cd;
            used = sqrt(used * used + cd * cd + cs2);
        }
        E2 += used * used;
        var -= (W * used) * (W * used);
        mean_sofar += mj;
        t = tb;
        e_t = e_tb;
    }
    info->dropped = dropped > __builtin_popcount(over) ? dropped : __builtin_popcount(over);
    R->stopped = stop;
    const double E = sqrt(E2);
    const double mean_to = (double) ef_nz_env_integral(s, R->h0, R->hs, t0, opaque ? t : t1);
    double unit = mean_to + s->contrast * kval(&noise) + kval(&corr);
    if (stop) {
        /* True T_k lies in [0, T_up] with T_up = e^-(rho_k ulo) */
        const double ulo = mean_sofar + s->contrast * kval(&noise) + kval(&corr) - E;
        unit = ef_nz_stop_report(s, ulo, unit, errk);
    } else if (opaque) {
        for (int k = 0; k < 3; ++k)
            errk[k] = s->rho[k] > 0 ? LN2 : 0;
    } else {
        for (int k = 0; k < 3; ++k)
            errk[k] = s->rho[k] * (E + corr_err + tail);
    }
    return unit;
}
