/* The certified integrators of the noise fog (fog_noise.c's family;
 * noise_fog.h): the cell walk in long double over several lattices at
 * once, a pair of Gauss rules bisected until they agree, one octave cell
 * by cell (method=exact, and adaptive's general path), the full density
 * (clamped, or separable factors) piece by piece between every octave's
 * faces, and the midpoint march (method=steps, the work bound's fallback)
 * with its error bound. Pure: no I/O, no globals. */
#include "noise_fog.h"

/* ---- the cell walk: several coordinates crossing integers along t ---- */

typedef struct walk {
    int m;
    const lin *u;
    long double cell[MAXLIN], next[MAXLIN], step[MAXLIN];  /* step: t per cell */
    int ic[MAXLIN];                  /* cell & 255 */
    long double t, t1;
} walk;

static long double next_crossing(const lin *u, long double cell)
{
    if (u->d > 0)
        return (cell + 1 - u->b) / u->d;
    if (u->d < 0)
        return (cell - u->b) / u->d;
    return INFINITY;
}

static void walk_init(walk *w, const lin *u, int m, long double t0, long double t1)
{
    w->m = m;
    w->u = u;
    w->t = t0;
    w->t1 = t1;
    for (int j = 0; j < m; ++j) {
        const long double v = u[j].b + t0 * u[j].d;
        long double c = floor_ld(v);
        if (u[j].d < 0 && c == v)
            c -= 1;   /* on a face, moving down: the cell below */
        w->cell[j] = c;
        w->ic[j] = (int) mod256(c);
        w->next[j] = next_crossing(&u[j], c);
        w->step[j] = u[j].d == 0 ? 0 : fabsl(1 / u[j].d);
    }
}

/* The next piece [*ta, *tb] with every coordinate inside one cell; 0 at the end. */
static int walk_next(walk *w, long double *ta, long double *tb)
{
    if (!(w->t < w->t1))
        return 0;
    long double tn = w->t1;
    for (int j = 0; j < w->m; ++j)
        if (w->next[j] < tn)
            tn = w->next[j];
    if (!(tn > w->t))
        tn = w->t;
    *ta = w->t;
    *tb = tn;
    return 1;
}

/* Moves past the piece that ended at tb. */
static void walk_advance(walk *w, long double tb)
{
    for (int j = 0; j < w->m; ++j)
        while (w->next[j] <= tb) {
            w->cell[j] += w->u[j].d > 0 ? 1 : -1;
            w->ic[j] = (w->ic[j] + (w->u[j].d > 0 ? 1 : 255)) & 255;
            w->next[j] += w->step[j];
        }
    w->t = tb;
    if (tb >= w->t1)
        w->t = w->t1;
}

/* The fraction of coordinate j inside its current cell at t. */
static double walk_frac(const walk *w, int j, long double t)
{
    const double f = (double) ((w->u[j].b - w->cell[j]) + t * w->u[j].d);
    return f < 0 ? 0 : f > 1 ? 1 : f;
}

static void walk_hash(const walk *w, int j0, ef_noise_cell *nc)
{
    ef_noise_cell_at(w->ic[j0], w->ic[j0 + 1], w->ic[j0 + 2], nc);
}

/* ---- adaptive bisection of one piece with a pair of Gauss rules ---- */

typedef double (*piece_fn)(rayc *R, const void *ctx, long double t);

/* n-point Gauss-Legendre of f over [ta, tb]. */
static double gauss(rayc *R, piece_fn f, const void *ctx, int n, long double ta, long double tb)
{
    const nstate *s = R->s;
    const long double mid = (ta + tb) / 2, half = (tb - ta) / 2;
    double sum = 0;
    for (int j = 0; j < n; ++j)
        sum += s->glw[n][j] * f(R, ctx, mid + half * s->glx[n][j]);
    return (double) half * sum;
}

/* Integrates f over [ta, tb] with rules lo and hi, bisecting until they
 * agree within tol (absolute) or depth runs out; adds the hi values to acc
 * and |hi - lo| of accepted pieces to *err. */
static void bisect(rayc *R, piece_fn f, const void *ctx, int lo, int hi, long double ta,
                   long double tb, double tol, int depth, ksum *acc, double *err)
{
    const double a = gauss(R, f, ctx, lo, ta, tb), b = gauss(R, f, ctx, hi, ta, tb);
    const double e = fabs(b - a);
    const long double mid = (ta + tb) / 2;
    if (e <= tol || depth <= 0 || !(mid > ta && mid < tb)) {
        kadd(acc, b);
        *err += e;
        return;
    }
    bisect(R, f, ctx, lo, hi, ta, mid, tol / 2, depth - 1, acc, err);
    bisect(R, f, ctx, lo, hi, mid, tb, tol / 2, depth - 1, acc, err);
}

/* ---- one octave of the noise model, cell by cell ---- */

typedef struct cell_ctx {
    const walk *w;
    int j0;
    ef_noise_cell nc;
} cell_ctx;

/* env * noise inside the current cell of octave j0 / 3. */
static double cell_env_noise(rayc *R, const void *ctx, long double t)
{
    const cell_ctx *cc = ctx;
    R->evals += 1;
    const double n = ef_noise_cell_eval(&cc->nc, walk_frac(cc->w, cc->j0, t),
                                        walk_frac(cc->w, cc->j0 + 1, t),
                                        walk_frac(cc->w, cc->j0 + 2, t));
    return R->s->k == 0 ? n : (double) env_at(R, t) * n;
}

/* integral of env * noise_i over [t0, t1]: n Gauss nodes per cell, or with
 * n == 0 the certified pair (9 and 13 nodes, bisected to tol relative to
 * the cell's envelope bound). *err collects the certified pair's residue.
 * The walk is in long double (exact needs each cell's fractions to full
 * precision wherever the camera is); without an envelope the cells go
 * through the adaptive path's batches, from fractions formed here. */
double ef_nz_octave_integral(rayc *R, int i, int n, long double t0, long double t1,
                             double *err)
{
    const nstate *s = R->s;
    /* The double walk takes the envelope as e^-(kh0 + khs t): not where
     * those overflow (a falloff near DBL_MAX), which the walk in long
     * double below handles. */
    if (n > 0 && s->method == M_ADAPTIVE && (s->k == 0 || (isfinite(R->kh0) && isfinite(R->khs))))
        return s->k == 0 ? ef_nz_octave_integral_fast(R, i, n, (double) t0, (double) t1)
                         : ef_nz_octave_integral_env(R, i, n, (double) t0, (double) t1);
    walk w;
    walk_init(&w, &R->u[3 * i], 3, t0, t1);
    ksum acc = { 0, 0 };
    long double ta, tb;
    cell_ctx cc = { &w, 0, { { 0 } } };
    cell_batch b;
    int m = 0;
    const double d0[3] = { w.u[0].dd, w.u[1].dd, w.u[2].dd };
    while (walk_next(&w, &ta, &tb)) {
        if (tb > ta) {
            walk_hash(&w, 0, &cc.nc);
            R->cells += 1;
            if (n > 0 && s->k == 0) {
                for (int a = 0; a < 3; ++a)
                    b.f[a][m] = (double) ((w.u[a].b - w.cell[a]) + ta * w.u[a].d);
                for (int k = 0; k < 8; ++k)
                    b.g[k][m] = cc.nc.h[k];
                b.hh[m++] = (double) (tb - ta) / 2;
                R->evals += n;
                if (m == CELL_BATCH) {
                    ef_nz_batch_flush(s, d0, n, m, &b, &acc);
                    m = 0;
                }
            } else if (n > 0) {
                kadd(&acc, gauss(R, cell_env_noise, &cc, n, ta, tb));
            } else if (s->k * fabsl(R->hs) * (tb - ta) <= 0.05L) {
                /* The envelope changes by at most 5 % over the cell: 12
                 * nodes are exact for the noise's degree 16 plus 7 orders
                 * of the exponential; the 8th is below 1e-15 of the cell. */
                kadd(&acc, gauss(R, cell_env_noise, &cc, 12, ta, tb));
            } else {
                const double bound = EF_NOISE_BOUND * (double) (tb - ta) *
                                     (double) fmaxl(env_at(R, ta), env_at(R, tb));
                bisect(R, cell_env_noise, &cc, 9, 13, ta, tb, 1e-14 * bound, 30, &acc, err);
            }
        }
        walk_advance(&w, tb);
    }
    if (m > 0)
        ef_nz_batch_flush(s, d0, n, m, &b, &acc);
    return kval(&acc);
}

/* ---- the full density, piece by piece over every octave's cells ---- */

static double full_density(rayc *R, const void *ctx, long double t)
{
    (void) ctx;
    const double v = ef_nz_shape_at(R, t);
    return R->s->k == 0 || v == 0 ? v : (double) env_at(R, t) * v;
}

/* The lattice coordinates the full density's pieces follow. */
static int full_lins(const rayc *R, const lin **u)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    if (!s->separable) {
        *u = R->u;
        return 3 * N;
    }
    /* The separable factors only cross their own axes' cells. */
    return -1;
}

/* Whether the clamp of the noise model binds on [ta, tb] (inside one cell
 * of every octave): from fbm at the middle and the noise's Lipschitz
 * bound, -1 when 1 + c fbm <= 0 throughout (no fog: skipped), 1 when it
 * stays > 0 (a polynomial), 0 when it may cross zero (or for the
 * separable model). Costs one fbm evaluation. */
static int clamp_state(rayc *R, long double ta, long double tb)
{
    const nstate *s = R->s;
    if (s->separable)   /* factors of degree 6 each: a polynomial unless the clamp binds */
        return s->clamp ? 0 : 1;
    const long double mid = (ta + tb) / 2;
    const double half = (double) (tb - ta) / 2;
    double f = 0, dev = 0;
    for (int i = 0; i < s->fbm.octaves; ++i) {
        f += s->fbm.weight[i] * octave_at(R, i, mid);
        const double rate = s->fbm.freq[i] / s->scale;   /* lattice units per unit t */
        dev += s->fbm.weight[i] * fmin(2 * EF_NOISE_BOUND, EF_NOISE_LIPSCHITZ * rate * half);
    }
    const double c = s->contrast, centre = 1 + c * f, spread = fabs(c) * dev;
    if (centre + spread <= 0)
        return -1;
    if (centre - spread > 0)
        return 1;
    return 0;
}
/* The default method's work bound on the piece-by-piece path (the
 * separable model under ttol, the default): past this many noise
 * evaluations on a ray, the rest of it is marched in FULL_MARCH steps with
 * the march's bound as its error. An explicit tol= has no such bound: it
 * asks for that error on every ray. */
#define FULL_BUDGET 24000
#define FULL_MARCH 256

/* integral of env * shape over [t0, t1] with the rule pair (lo, hi) on
 * every piece where all coordinates stay in one cell, bisected until the
 * pair agrees to tol_per_len * length (absolute) or, with tol_per_len = 0,
 * to 1e-14 of the piece's own bound (certified). Under ttol, past
 * FULL_BUDGET evaluations the rest is marched (see there). */
double ef_nz_full_integral(rayc *R, int lo, int hi, long double t0, long double t1,
                           double tol_per_len, double *err)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    lin sel[MAXLIN];
    const lin *u;
    int m = full_lins(R, &u);
    if (m < 0) {
        m = 0;
        for (int k = 0; k < s->naxes; ++k)
            for (int i = 0; i < N; ++i)
                sel[m++] = R->u[s->axis[k] * N + i];
        u = sel;
    }
    walk w;
    walk_init(&w, u, m, t0, t1);
    ksum acc = { 0, 0 };
    long double ta, tb;
    while (walk_next(&w, &ta, &tb)) {
        if (tol_per_len > 0 && R->s->ttol > 0 && R->evals > FULL_BUDGET) {
            const double v = ef_nz_march(R, ta, t1, FULL_MARCH);
            kadd(&acc, v);
            *err += ef_nz_march_bound(R, ta, t1, FULL_MARCH, v);
            break;
        }
        if (tb > ta) {
            R->cells += 1;
            const int clamp = clamp_state(R, ta, tb);
            const double tol = tol_per_len > 0
                                   ? tol_per_len * (double) (tb - ta)
                                   : 1e-14 * shape_bound(s) * (double) (tb - ta) *
                                         (double) fmaxl(env_at(R, ta), env_at(R, tb));
            if (clamp < 0)
                ;   /* the clamp holds the density at zero over the whole piece */
            else if (clamp > 0 && s->k == 0 && tol_per_len == 0)
                kadd(&acc, gauss(R, full_density, NULL, lo, ta, tb));  /* a polynomial: exact */
            else
                bisect(R, full_density, NULL, lo, hi, ta, tb, tol, 30, &acc, err);
        }
        walk_advance(&w, tb);
    }
    return kval(&acc);
}

/* ---- the midpoint ray-march ---- */

double ef_nz_march(rayc *R, long double t0, long double t1, int n)
{
    const long double h = (t1 - t0) / n;
    ksum acc = { 0, 0 };
    for (int j = 0; j < n; ++j)
        kadd(&acc, full_density(R, NULL, t0 + (j + 0.5L) * h));
    R->cells += n;
    return (double) h * kval(&acc);
}

/* A bound of |d2 (env shape) / dt2| along the ray (for the midpoint
 * rule's error h^2 L / 24 max|f''|), from the noise's Lipschitz and
 * curvature bounds per lattice unit. */
static double curvature_bound(const rayc *R, double envmax)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double ac = fabs(s->contrast), B1 = 1 + ac * EF_NOISE_BOUND;
    double d1[3] = { 0, 0, 0 }, d2[3] = { 0, 0, 0 }, D1 = 0, D2 = 0;
    for (int i = 0; i < N; ++i)
        for (int a = 0; a < 3; ++a) {
            const double rate = fabs((double) R->u[s->separable ? a * N + i : 3 * i + a].d);
            d1[a] += ac * s->fbm.weight[i] * EF_NOISE_LIPSCHITZ * rate;
            d2[a] += ac * s->fbm.weight[i] * EF_NOISE_CURVATURE * rate * rate;
        }
    if (!s->separable) {
        /* |grad| over the three rates: the Lipschitz bound covers the sum. */
        D1 = d1[0] + d1[1] + d1[2];
        D2 = d2[0] + d2[1] + d2[2];
    } else {
        const int m = s->naxes;
        for (int x = 0; x < m; ++x) {
            D1 += d1[s->axis[x]] * pow(B1, m - 1);
            D2 += d2[s->axis[x]] * pow(B1, m - 1);
            for (int y = x + 1; y < m; ++y)
                D2 += 2 * d1[s->axis[x]] * d1[s->axis[y]] * pow(B1, m - 2);
        }
    }
    const double B = shape_bound(s), ks = s->k * fabs((double) R->hs);
    return envmax * (D2 + 2 * ks * D1 + ks * ks * B);
}

/* The error of ef_nz_march(R, t0, t1, n) = unit, bounded two ways, the smaller
 * taken. The midpoint rule's: each step's error is h^3/24 |f''| somewhere
 * in it, and |f''| <= env (D2 + 2 |a| D1 + a^2 B) (curvature_bound per unit
 * of envelope), whose largest value on a step is at most e^(|a| h) times
 * its mean there; so the sum is at most h^2/24 e^(|a| h) times that bound
 * times the envelope's integral, its closed form. The trivial one: both
 * unit and the true value lie in [0, B integral(env)]. Using the integral,
 * not the envelope's largest value times the length, keeps the bound near
 * tau on long rays through a thinning envelope. */
double ef_nz_march_bound(const rayc *R, long double t0, long double t1, int n, double unit)
{
    const nstate *s = R->s;
    const double m = (double) ef_nz_env_integral(s, R->h0, R->hs, t0, t1);
    const double h = (double) (t1 - t0) / n, a = fabs(s->k * (double) R->hs);
    if (s->spread > 0)   /* lod=pixel's fade has a kink the curvature bound does not know */
        return fmax(unit, shape_bound(s) * m);
    const double mid = h * h / 24 * exp(a * h) * curvature_bound(R, 1.0) * m;
    return fmin(mid, fmax(unit, shape_bound(s) * m));
}
