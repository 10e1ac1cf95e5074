/* noise-separable's preintegrated evaluation, the seed's method
 * (fog_noise.c's family; noise_fog.h): per axis prefix integrals of the
 * factor (per octave, or one merged table of the whole fbm over its
 * period when the lacunarity is whole), the product of the factors' means
 * over K pieces, a span of rays at a time, with its error bound. Pure: no
 * I/O, no globals. */
#include "noise_fog.h"

/* A cell's eight corner gradients as numbers, so a node's noise needs no
 * branches: g.(x, y, z) adds the same two non-zero terms as Perlin's grad. */
typedef struct gcell {
    double g[8][3];
} gcell;

static void gcell_of(const ef_noise_cell *nc, gcell *gc)
{
    for (int k = 0; k < 8; ++k)
        memcpy(gc->g[k], grad_vec[nc->h[k] & 15], sizeof gc->g[k]);
}

static inline double gdot(const double g[3], double x, double y, double z)
{
    return g[0] * x + g[1] * y + g[2] * z;
}

/* ---- the seed's preintegrated evaluation (noise-separable) ---- */

static const double *table(const ef_fog_component *c, int a, int i)
{
    const nstate *s = state(c);
    return c->arr + s->tab_off + ((size_t) a * (size_t) s->fbm.octaves + (size_t) i) * TAB;
}

/* integral of factor octave (a, i) over [x0, x1] inside cell m (5 nodes:
 * exact for its degree-6 polynomial). */
static double cell_part(const nstate *s, int a, int i, long double x0, long double x1)
{
    const long double mid = (x0 + x1) / 2, half = (x1 - x0) / 2;
    double sum = 0;
    for (int j = 0; j < 5; ++j)
        sum += s->glw[5][j] * ef_nz_factor_octave_ld(s, a, i, mid + half * s->glx[5][j]);
    return (double) half * sum;
}

/* The prefix tables: entry m of octave (a, i) is the integral of the
 * factor's octave over [0, m] of its own coordinate, m = 0..256; the
 * noise's period 256 gives every other prefix. */
void ef_nz_build_tables(nstate *s, double *tab)
{
    const int N = s->fbm.octaves;
    for (int a = 0; a < 3; ++a)
        for (int i = 0; i < N; ++i) {
            double *t = tab + ((size_t) a * (size_t) N + (size_t) i) * TAB;
            ksum acc = { 0, 0 };
            t[0] = 0;
            for (int m = 0; m < 256; ++m) {
                kadd(&acc, cell_part(s, a, i, m, m + 1));
                t[m + 1] = kval(&acc);
            }
        }
}

/* integral of octave (a, i) of the factor over [u0, u1] of its coordinate:
 * in one cell directly, else from the table (whole periods, whole cells and
 * the two partial cells). */
static double octave_span(const ef_fog_component *c, int a, int i, long double u0, long double u1)
{
    const nstate *s = state(c);
    const long double c0 = floor_ld(u0), c1 = floor_ld(u1);
    if (c0 == c1)
        return cell_part(s, a, i, u0, u1);
    const double *t = table(c, a, i);
    const long double k0 = floor_ld(c0 / 256), k1 = floor_ld(c1 / 256);
    const int m0 = (int) (c0 - 256 * k0), m1 = (int) (c1 - 256 * k1);
    const double whole = (double) (k1 - k0) * t[256] + (t[m1] - t[m0]);
    return whole + cell_part(s, a, i, c1, u1) - cell_part(s, a, i, c0, u0);
}

/* The mean of factor a over [ta, tb] of the ray. */
static double factor_mean(const ef_fog_component *c, const rayc *R, int a, long double ta,
                          long double tb, double *evals)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    double f = 0;
    for (int i = 0; i < N; ++i) {
        const lin *u = &R->u[a * N + i];
        const long double u0 = u->b + ta * u->d, u1 = u->b + tb * u->d;
        if (u1 == u0) {
            f += s->fbm.weight[i] * ef_nz_factor_octave(s, a, i, (double) u0);
            *evals += 1;
        } else {
            const long double lo = u0 < u1 ? u0 : u1, hi = u0 < u1 ? u1 : u0;
            f += s->fbm.weight[i] * octave_span(c, a, i, lo, hi) / (double) (hi - lo);
            *evals += 10;
        }
    }
    return 1 + s->contrast * f;
}

/* ---- merged tables: the whole factor's fbm part over its period ---- */

/* Perlin's blend with the three fades given: linear in each fade. */
static double blend_fades(const gcell *c, double x, double y, double z, double u, double v,
                          double w)
{
    const double x1 = x - 1, y1 = y - 1, z1 = z - 1;
    const double a = ef_noise_lerp_(u, gdot(c->g[0], x, y, z), gdot(c->g[1], x1, y, z));
    const double b = ef_noise_lerp_(u, gdot(c->g[2], x, y1, z), gdot(c->g[3], x1, y1, z));
    const double d = ef_noise_lerp_(u, gdot(c->g[4], x, y, z1), gdot(c->g[5], x1, y, z1));
    const double e = ef_noise_lerp_(u, gdot(c->g[6], x, y1, z1), gdot(c->g[7], x1, y1, z1));
    return ef_noise_lerp_(w, ef_noise_lerp_(v, a, b), ef_noise_lerp_(v, d, e));
}

/* Octave i of factor a inside cell m of its own coordinate, as the
 * polynomial sum_j p[j] x^j (x the fraction, degree 6): the noise there is
 * E(x, fade(x)) with E bilinear in the coordinate and its fade. */
void ef_nz_cell_poly(const nstate *s, int a, int i, long m, long double p[7])
{
    int64_t X[3];
    double f[3];
    int j = 0;
    for (int b = 0; b < 3; ++b) {
        if (b == a) {
            X[b] = (int64_t) (((m % 256) + 256) % 256);
            f[b] = 0;
        } else {
            ef_noise_split(s->fixed[a][i][j++], &X[b], &f[b]);
        }
    }
    ef_noise_cell nc;
    gcell gc;
    ef_noise_cell_at(X[0], X[1], X[2], &nc);
    gcell_of(&nc, &gc);
    double E[2][2];
    for (int xa = 0; xa < 2; ++xa)
        for (int fa = 0; fa < 2; ++fa) {
            double c3[3] = { f[0], f[1], f[2] }, fd[3];
            c3[a] = xa;
            for (int b = 0; b < 3; ++b)
                fd[b] = b == a ? fa : ef_noise_fade_(f[b]);
            E[xa][fa] = blend_fades(&gc, c3[0], c3[1], c3[2], fd[0], fd[1], fd[2]);
        }
    const long double al = E[0][0], be = E[1][0] - E[0][0], ga = E[0][1] - E[0][0];
    const long double de = E[1][1] - E[1][0] - E[0][1] + E[0][0];
    /* al + be x + (10 x^3 - 15 x^4 + 6 x^5)(ga + de x) */
    p[0] = al;
    p[1] = be;
    p[2] = 0;
    p[3] = 10 * ga;
    p[4] = 10 * de - 15 * ga;
    p[5] = 6 * ga - 15 * de;
    p[6] = 6 * de;
}

/* Fills the separable factors' cell polynomials (noise_fog.h: FPOLY_*):
 * per axis slot k, octave i and cell m, the 7 coefficients of
 * ef_nz_cell_poly in double. */
void ef_nz_factor_tables(const nstate *s, double *tab)
{
    const int N = s->fbm.octaves;
    for (int k = 0; k < s->naxes; ++k)
        for (int i = 0; i < N; ++i)
            for (long m = 0; m < 256; ++m) {
                long double p[7];
                ef_nz_cell_poly(s, s->axis[k], i, m, p);
                double *q = tab + (((size_t) k * (size_t) N + (size_t) i) * 256 + (size_t) m) * 7;
                for (int c = 0; c < 7; ++c)
                    q[c] = (double) p[c];
            }
}

/* Builds factor a's merged table over s in [0, 256): pieces between every
 * octave's cell faces, each with the polynomial (in s - start) of
 * sum_i w_i noise_i and the prefix integral at its start. Returns the
 * number of pieces. */
int ef_nz_build_merged(const nstate *s, int a, double *tab, int cap, double *total)
{
    const int N = s->fbm.octaves;
    long double *br = malloc(2 * ((size_t) cap + 2) * sizeof *br), *all = br + cap + 2;
    int n = 0, run[EF_FBM_MAX_OCTAVES + 1];
    if (!br)
        return 0;
    /* Each octave's faces in increasing order, one run per octave ... */
    for (int i = 0; i < N; ++i) {
        run[i] = n;
        const long double f = s->fbm.freq[i], o = (long double) i * ef_fbm_offset[a];
        for (long m = (long) ceill(o); n < cap; ++m) {
            const long double b = (m - o) / f;
            if (b >= 256)
                break;
            if (b > 0)
                all[n++] = b;
        }
    }
    run[N] = n;
    /* ... merged (faster than sorting them), 0 first and near-coincident
     * faces (within 1e-12) once. */
    int head[EF_FBM_MAX_OCTAVES], P = 0;
    for (int i = 0; i < N; ++i)
        head[i] = run[i];
    br[P++] = 0;
    for (;;) {
        int best = -1;
        for (int i = 0; i < N; ++i)
            if (head[i] < run[i + 1] && (best < 0 || all[head[i]] < all[head[best]]))
                best = i;
        if (best < 0)
            break;
        const long double b = all[head[best]++];
        if (b - br[P - 1] > 1e-12L)
            br[P++] = b;
    }
    br[P] = 256;
    double *rec = tab, *start = tab + MERGED_STARTS(P);
    int32_t *hint = (int32_t *) (tab + MERGED_HINT(P));
    /* Each octave's last cell polynomial: the pieces of one cell follow
     * each other. */
    long last[EF_FBM_MAX_OCTAVES];
    double qs[EF_FBM_MAX_OCTAVES][7];
    long double acc = 0;
    for (int p = 0; p < P; ++p) {
        const long double s0 = br[p], L = br[p + 1] - br[p], mid = s0 + L / 2;
        /* The shifts in double (x87 long double would cost most of the
         * build): each coefficient within a few ulps, the pieces' values
         * within about 1e-15 of their size, far inside the table's 1e-10. */
        double c[7] = { 0, 0, 0, 0, 0, 0, 0 };
        for (int i = 0; i < N; ++i) {
            const long double f = s->fbm.freq[i], o = (long double) i * ef_fbm_offset[a];
            const long m = (long) floor_ld(f * mid + o);
            const double xp = (double) (f * s0 + o - m);
            double *q = qs[i];
            if (p == 0 || m != last[i]) {
                long double ql[7];
                ef_nz_cell_poly(s, a, i, m, ql);
                for (int k = 0; k < 7; ++k)
                    q[k] = (double) ql[k];
                last[i] = m;
            }
            /* q(xp + f y) = sum_k t_k (f y)^k: the Taylor shift by xp, by
             * repeated synthetic division (21 multiply-adds, no binomials). */
            double t[7];
            for (int k = 0; k < 7; ++k)
                t[k] = q[k];
            for (int a0 = 0; a0 < 6; ++a0)
                for (int j = 5; j >= a0; --j)
                    t[j] += xp * t[j + 1];
            double fk = s->fbm.weight[i];
            const double fd = (double) f;
            for (int k = 0; k < 7; ++k) {
                c[k] += t[k] * fk;
                fk *= fd;
            }
        }
        start[p] = (double) s0;
        rec[8 * p + 7] = (double) acc;
        long double integral = 0, Lp = L;
        for (int k = 0; k < 7; ++k) {
            rec[8 * p + k] = c[k] / (k + 1);
            integral += c[k] * Lp / (k + 1);
            Lp *= L;
        }
        acc += integral;
    }
    *total = (double) acc;
    start[P] = 256;   /* the sentinel: the start past the last piece */
    /* Lookup bins: the piece holding each bin's start, widened by a margin
     * past the rounding of r times the bins (which can put r a few ulps
     * outside its bin); -1 - p where the widened bin holds two starts or
     * more, for which one comparison cannot find the piece. */
    const double margin = 1e-9;
    for (int b = 0, p = 0; b < MERGED_BINS * P; ++b) {
        const double lo = 256.0 * b / (MERGED_BINS * P) - margin,
                     hi = 256.0 * (b + 1) / (MERGED_BINS * P) + margin;
        while (p + 1 < P && start[p + 1] <= lo)
            ++p;
        hint[b] = p + 2 <= P && start[p + 2] <= hi ? -1 - p : p;
    }
    free(br);
    return P;
}

/* The antiderivative of a merged piece from its start to y: the table
 * holds its coefficients (of y^1..y^7), so no division per lookup. */
static inline double piece_int(const double *ic, double y)
{
    /* Estrin's scheme: a third of Horner's dependent chain, and this is the
     * per-pixel latency of the preintegrated method. */
    const double y2 = y * y, y4 = y2 * y2;
    const double a = ic[0] + ic[1] * y, b = ic[2] + ic[3] * y, c = ic[4] + ic[5] * y;
    return ((a + b * y2) + (c + ic[6] * y2) * y4) * y;
}

/* The piece's value at y, the antiderivative's derivative. */
static double piece_val(const double *ic, double y)
{
    double v = 7 * ic[6];
    for (int k = 5; k >= 0; --k)
        v = v * y + (k + 1) * ic[k];
    return v;
}

/* Axis a's merged table, as offsets into arr resolved for one ray. */
typedef struct mview {
    const double *rec;               /* per piece: its 7 coefficients, its prefix */
    const double *start;             /* per piece, and the sentinel 256 */
    const int32_t *hint;
    int P;
    double bins;                     /* hint bins per unit of r */
} mview;

#define M_START(m, p) ((m)->start[p])
#define M_COEF(m, p) ((m)->rec + 8 * (p))
#define M_PREFIX(m, p) ((m)->rec[8 * (p) + 7])

static inline mview mview_of(const ef_fog_component *c, int a)
{
    const nstate *s = state(c);
    const double *tab = c->arr + s->m_off[a];
    const int P = s->mpa[a];
    return (mview) { tab, tab + MERGED_STARTS(P), (const int32_t *) (tab + MERGED_HINT(P)), P,
                     (double) MERGED_BINS * P / 256 };
}

/* The lookup bin of r in [0, 256) (clamped: rounding may reach the ends). */
static inline int bin_of(const mview *m, double r)
{
    const int nb = MERGED_BINS * m->P, b = (int) (r * m->bins);
    return b < 0 ? 0 : b >= nb ? nb - 1 : b;
}

/* The bin's piece for r in [0, 256): the bin's first piece, or the next
 * if that starts at or before r; right unless *unsure (a bin holding two
 * starts: rare). */
static inline int piece_guess(const mview *m, double r, int *unsure)
{
    const int32_t h = m->hint[bin_of(m, r)];
    const int hp = h < 0 ? -1 - h : h;
    *unsure = h < 0;
    return hp + (M_START(m, hp + 1) <= r);
}

/* The piece holding r in [0, 256), and r's offset into it. */
static inline int piece_of(const mview *m, double r, double *y)
{
    const int P = m->P;
    int unsure;
    int p = piece_guess(m, r, &unsure);
    while (unsure && p + 1 < P && M_START(m, p + 1) <= r)
        ++p;
    while (unsure && p > 0 && M_START(m, p) > r)
        --p;
    *y = r - M_START(m, p);
    return p;
}

/* floor(v / 256) and v modulo 256, without floor's libm call or a branch
 * (so a loop of it runs straight): a truncating conversion where
 * |v / 256| < 2^62, and beyond that v / 256 is an integer already. */
static inline double period_split(double v, double *r)
{
    const double x = v * (1.0 / 256);
    const int small = fabs(x) < 0x1p62;
    const double xc = small ? x : 0.0;
    double k = (double) (long long) xc;
    k -= k > xc;
    k = small ? k : x;
    const double rr = v - 256 * k;
    const int over = rr >= 256;   /* rounding */
    *r = over ? rr - 256 : rr;
    return over ? k + 1 : k;
}

/* Where q_a = s falls in axis a's merged table: the period, the piece, the
 * offset into it and the piece's antiderivative there. */
typedef struct mpoint mpoint;

static inline void merged_point(const nstate *st, const mview *m, int a, double s, mpoint *out)
{
    if (st->cam && s == st->cam_s[a]) {
        *out = st->cam_pt[a];   /* the camera's point, looked up once per frame */
        return;
    }
    double r;
    out->k = period_split(s, &r);
    out->p = piece_of(m, r, &out->y);
    out->I = piece_int(M_COEF(m, out->p), out->y);
}

/* Factor a's fbm part over q_a from s0 to s0 + *ds: its integral over
 * |*ds| (and *ds made |*ds|); or, when the extent is too small for that,
 * its value at the middle with *ds set to 0. Both ends are looked up as
 * given, so the camera's end hits the per-frame cache whichever way the
 * ray runs. */
static inline double merged_int_in(const nstate *s, const mview *mv, int a, double s0, double *pds)
{
    const double ds = fabs(*pds), slo = *pds < 0 ? s0 + *pds : s0, shi = *pds < 0 ? s0 : s0 + *pds;
    *pds = ds;
    mpoint lo, hi;
    merged_point(s, mv, a, slo, &lo);
    if (ds < 1e-6) {  /* no extent: the value at the middle */
        *pds = 0;
        return piece_val(M_COEF(mv, lo.p), lo.y + ds / 2);
    }
    const double pend = M_START(mv, lo.p + 1) - M_START(mv, lo.p);
    if (lo.y + ds <= pend)   /* one piece: the antiderivative's difference */
        return piece_int(M_COEF(mv, lo.p), lo.y + ds) - lo.I;
    merged_point(s, mv, a, shi, &hi);
    return (hi.k - lo.k) * s->mtotal[a] + (M_PREFIX(mv, hi.p) - M_PREFIX(mv, lo.p)) + (hi.I - lo.I);
}

static inline double merged_int(const ef_fog_component *c, int a, double s0, double *pds)
{
    const mview m = mview_of(c, a);
    return merged_int_in(state(c), &m, a, s0, pds);
}

/* e^(-k h) for the envelope, from the per-frame cache at the camera's
 * height. */
static double env_exp(const nstate *s, double h)
{
    return s->cam && h == s->cam_h ? s->cam_eh : exp(-s->k * h);
}

/* 1 - e^(-b) for |b| < 1/2: the series of (1 - e^-b) / b to b^15 (the
 * remainder is below 1e-19 relative there), by Estrin's scheme. */
static inline double ome_series(double b)
{
    /* c_n = (-1)^n / (n + 1)! */
    static const double c[16] = {
        1.0, -1.0 / 2, 1.0 / 6, -1.0 / 24, 1.0 / 120, -1.0 / 720, 1.0 / 5040, -1.0 / 40320,
        1.0 / 362880, -1.0 / 3628800, 1.0 / 39916800, -1.0 / 479001600, 1.0 / 6227020800.0,
        -1.0 / 87178291200.0, 1.0 / 1307674368000.0, -1.0 / 20922789888000.0
    };
    const double b2 = b * b, b4 = b2 * b2, b8 = b4 * b4;
    double p[8];
    for (int i = 0; i < 8; ++i)
        p[i] = c[2 * i] + c[2 * i + 1] * b;
    const double q0 = p[0] + p[1] * b2, q1 = p[2] + p[3] * b2, q2 = p[4] + p[5] * b2,
                 q3 = p[6] + p[7] * b2;
    return b * ((q0 + q1 * b4) + (q2 + q3 * b4) * b8);
}

/* 1 - e^(-b), to a few ulps, at a fraction of expm1's cost (the envelope's
 * mean takes one per ray): ome_series where |b| < 1/2, else
 * 1 - ef_exp_neg(b), whose cancellation costs at most 2.6 ulps beyond its
 * 1. Both are formed and one is picked, so a loop of it vectorises. */
static inline double one_minus_exp_neg(double b)
{
    const double series = ome_series(b), direct = 1 - ef_exp_neg(b);
    return fabs(b) < 0.5 ? series : direct;
}

/* The mean envelope over [ta, tb] times its length, as num / den (see
 * preintegrated_merged). */
static inline void env_piece(const nstate *s, double h0, double hs, double ta, double tb,
                             double *num, double *den)
{
    const double L = tb - ta;
    if (s->k > 0 && hs != 0) {
        /* mean envelope e^(-k h(ta)) (1 - e^(-b)) / b with b = k hs L,
         * signed: from the near end, whose e^(-k h) is the camera's
         * (cached) on the first piece, while expm1(|b|) stays finite and
         * that end's exponential normal; else from the low end,
         * e^(-k h_low) (1 - e^-|b|) / |b|, which cannot overflow. */
        const double b = s->k * hs * L, ha = h0 + hs * ta;
        const double ea = fabs(b) <= 700 ? env_exp(s, ha) : 0;
        if (fabs(b) <= 1e-12) {
            *num *= env_exp(s, hs > 0 ? ha : h0 + hs * tb) * (1 - fabs(b) / 2);
        } else if (ea >= DBL_MIN) {
            *num *= ea * one_minus_exp_neg(b);
            *den = b;
        } else {
            *num *= env_exp(s, hs > 0 ? ha : h0 + hs * tb) * one_minus_exp_neg(fabs(b));
            *den = fabs(b);
        }
    } else if (s->k > 0) {
        *num *= env_exp(s, h0);
    }
}

/* pieces=1 in three stages, so that a span of rays can run each stage
 * over all its rays (tau_add_noise): the table lookups of one ray are a
 * chain of dependent loads, and independent rays side by side let the
 * processor overlap them. One ray through the three stages is the same
 * arithmetic. */
typedef struct one_ray {
    double num, den;                 /* L times the envelope's mean, as num / den */
    double s0[3], ds[3];             /* per factor: the start on q_a and the signed extent */
    double G[3], w[3];               /* per factor: the fbm part's integral (or value) and its extent */
} one_ray;

static inline void one_setup(const nstate *s, const ef_ray *r, double h0, double hs, double t0,
                             double t1, one_ray *o)
{
    const double L = t1 - t0;
    o->num = L;
    o->den = 1;
    env_piece(s, h0, hs, t0, t1, &o->num, &o->den);
    for (int k = 0; k < s->naxes; ++k) {
        const int a = s->axis[k];
        const double dq = r->dir[a] * s->inv_scale;
        o->ds[k] = L * dq;
        o->s0[k] = ((r->org[a] - s->shift[a]) * s->inv_scale + s->seedq[a]) + t0 * dq;
    }
}

static inline void one_axis(const nstate *s, const mview *m, int k, one_ray *o)
{
    double ds = o->ds[k];
    o->G[k] = merged_int_in(s, m, s->axis[k], o->s0[k], &ds);
    o->w[k] = ds;
}

static inline double one_value(const nstate *s, const one_ray *o)
{
    /* L env prod(1 + c G_a / ds_a) as L env prod(ds_a + c G_a) / prod ds_a:
     * one division, not one per factor */
    double num = o->num, den = o->den;
    for (int k = 0; k < s->naxes; ++k) {
        if (o->w[k] > 0) {
            num *= o->w[k] + s->contrast * o->G[k];
            den *= o->w[k];
        } else {
            num *= 1 + s->contrast * o->G[k];
        }
    }
    return num / den;
}

/* tau / rho of K equal pieces of [t0, t1] from the merged tables. */
double ef_nz_preintegrated_merged(const ef_fog_component *c, const nstate *s, const ef_ray *r,
                                  double h0, double hs, double t0, double t1, int K)
{
    if (K == 1) {
        one_ray o;
        one_setup(s, r, h0, hs, t0, t1, &o);
        for (int k = 0; k < s->naxes; ++k) {
            const mview m = mview_of(c, s->axis[k]);
            one_axis(s, &m, k, &o);
        }
        return one_value(s, &o);
    }
    double q0[3], dq[3];
    for (int k = 0; k < s->naxes; ++k) {
        const int a = s->axis[k];
        q0[a] = (r->org[a] - s->shift[a]) * s->inv_scale + s->seedq[a];
        dq[a] = r->dir[a] * s->inv_scale;
    }
    const double h = (t1 - t0) / K;
    ksum acc = { 0, 0 };
    for (int p = 0; p < K; ++p) {
        const double ta = t0 + p * h, tb = p + 1 == K ? t1 : t0 + (p + 1) * h, L = tb - ta;
        /* L env prod(1 + c G_a / ds_a) as L env prod(ds_a + c G_a) / prod ds_a:
         * one division per piece, not one per factor */
        double num = L, den = 1;
        env_piece(s, h0, hs, ta, tb, &num, &den);
        for (int k = 0; k < s->naxes; ++k) {
            const int a = s->axis[k];
            double ds = L * dq[a];
            const double G = merged_int(c, a, q0[a] + ta * dq[a], &ds);
            if (ds > 0) {
                num *= ds + s->contrast * G;
                den *= ds;
            } else {
                num *= 1 + s->contrast * G;
            }
        }
        kadd(&acc, num / den);
    }
    return kval(&acc);
}

/* The camera at org in the merged tables: its point in each and its
 * envelope height's exponential, looked up once per frame. */
void ef_nz_bind_merged(ef_fog_component *c, const double org[3])
{
    nstate *s = (nstate *) (void *) c->arr;
    nstate t = *s;
    for (int k = 0; k < t.naxes; ++k) {
        const int a = t.axis[k];
        t.cam_s[a] = (org[a] - t.shift[a]) * t.inv_scale + t.seedq[a];
        const mview m = mview_of(c, a);
        merged_point(&t, &m, a, t.cam_s[a], &t.cam_pt[a]);
    }
    t.cam_h = t.up[0] * org[0] + t.up[1] * org[1] + t.up[2] * org[2] - t.base;
    memcpy(t.cam_org, org, sizeof t.cam_org);
    t.cam_eh = exp(-t.k * t.cam_h);
    t.cam = 1;
    *s = t;
}

/* tau / rho of K equal pieces of [t0, t1]: per piece the mean envelope
 * times the product of the factors' means. */
double ef_nz_preintegrated(const ef_fog_component *c, rayc *R, long double t0, long double t1,
                           int K)
{
    const nstate *s = R->s;
    ksum acc = { 0, 0 };
    const long double h = (t1 - t0) / K;
    for (int p = 0; p < K; ++p) {
        const long double ta = t0 + p * h, tb = p + 1 == K ? t1 : t0 + (p + 1) * h;
        double v = (double) ef_nz_env_integral(s, R->h0, R->hs, ta, tb);
        for (int k = 0; k < s->naxes; ++k)
            v *= factor_mean(c, R, s->axis[k], ta, tb, &R->evals);
        kadd(&acc, v);
    }
    R->cells += (double) K * s->naxes * s->fbm.octaves;
    return kval(&acc);
}


/* What the merged tables' evaluation does with ray r: 0 no fog, 1 every
 * channel with density opaque, 2 integrate [*t0, *t1] (a sky ray whose
 * envelope lets it out is cut where the rest is below 1e-6 of the mean
 * part; *tail, when asked for, bounds that rest). h0 and hs are the
 * envelope's height at the origin and its rate. */
static inline int preint_prepare(const nstate *s, const ef_ray *r, double *h0, double *hs,
                                 double *t0, double *t1, double *tail)
{
    if (!(s->rho_max > 0) || !(r->dist > 0))
        return 0;
    if (s->has_box) {
        long double lt0, lt1;
        if (!ef_nz_clip_box(s, r, &lt0, &lt1))
            return 0;
        *t0 = (double) lt0;
        *t1 = (double) lt1;
    } else {
        *t0 = 0;
        *t1 = r->dist;
    }
    *h0 = s->up[0] * r->org[0] + s->up[1] * r->org[1] + s->up[2] * r->org[2] - s->base;
    *hs = s->up[0] * r->dir[0] + s->up[1] * r->dir[1] + s->up[2] * r->dir[2];
    if (isinf(*t1)) {
        if (!(s->k > 0 && *hs > 0))
            return 1;
        const double a = s->k * *hs;
        *t1 = *t0 + s->sky_need / a;
        if (tail)
            *tail = shape_bound(s) * exp(-s->k * (*h0 + *hs * *t1)) / a;
    }
    return ef_nz_env_overflows(s, *h0, *hs, *t0, *t1) ? 1 : 2;
}

/* piece_int at y for four rays, and their prefixes: their records
 * transposed into lanes, then piece_int's operations lane by lane (the
 * same bits as four calls). */
EF_INLINE void piece_int4(const mview *m, const int *q, const double *y, double *I, double *pre)
{
    const double *const p[4] = { M_COEF(m, q[0]), M_COEF(m, q[1]), M_COEF(m, q[2]),
                                 M_COEF(m, q[3]) };
    v4d ic[8];
    transpose4x8(p, ic);
    const v4d yv = *(const v4du *) (const void *) y;
    const v4d y2 = yv * yv, y4 = y2 * y2;
    const v4d a = ic[0] + ic[1] * yv, b = ic[2] + ic[3] * yv, c = ic[4] + ic[5] * yv;
    const v4d Iv = ((a + b * y2) + (c + ic[6] * y2) * y4) * yv;
    *(v4du *) (void *) I = Iv;
    *(v4du *) (void *) pre = ic[7];
}

/* What preint1_units does with a ray. */
enum { P1_NONE = 0, P1_OPAQUE, P1_LANE, P1_SCALAR };

/* pieces=1's tau / rho for rays r[0..n) (n <= ONE_SPAN) into unit[], and
 * what[] per ray: P1_NONE no fog (unit 0), P1_OPAQUE every channel with
 * density opaque, else unit holds the value. Most rays of a frame start at
 * the bound camera, end unclipped (no box) and have a normal envelope:
 * those are worked in loops over the span that the compiler vectorises,
 * the table lookups in short scalar loops between them, each ray's far end
 * the only point looked up (the camera's is cached) and the cam's own
 * piece, whose polynomial is at hand, serving rays that end inside it. The
 * others (a box, a bin holding two piece starts, an extent below 1e-6, an
 * envelope past its normal range) take preint_prepare and one_*, as before.
 * Which way a ray goes depends on the ray alone, and the lanes do the same
 * operations as one ray would, so tau is the same bits whatever the span
 * and whichever clone runs. */
EF_MULTIVERSION static void preint1_units(const ef_fog_component *c, const nstate *s,
                                          const ef_ray *r, int n, double *unit, int *what)
{
    double L[ONE_SPAN], num[ONE_SPAN], den[ONE_SPAN], F[8][ONE_SPAN];
    const double *const D[3] = { F[EF_F_DIR], F[EF_F_DIR + 1], F[EF_F_DIR + 2] },
                 *const O[3] = { F[EF_F_ORG], F[EF_F_ORG + 1], F[EF_F_ORG + 2] };
    int ok[ONE_SPAN];
    rays_soa(r, n, F);
    const int lanes = s->cam && !s->has_box;
    const double k = s->k, ce = s->cam_eh, cam_h = s->cam_h, rho_max = s->rho_max;
    const double up0 = s->up[0], up1 = s->up[1], up2 = s->up[2];
    const double sky_need = s->sky_need;
    const double co0 = s->cam_org[0], co1 = s->cam_org[1], co2 = s->cam_org[2];
    /* Classification, as preint_prepare decides, and the envelope. A ray
     * from the camera has the camera's height h0 = cam_h (and q = cam_s:
     * the same operations on the same numbers); others go the general way. */
    double bv[ONE_SPAN];
    int var[ONE_SPAN], nser = 0, ndir = 0;
    for (int j = 0; j < n; ++j) {
        const double d = F[EF_F_DIST][j];
        const int atcam = (O[0][j] == co0) & (O[1][j] == co1) & (O[2][j] == co2);
        const double h0 = cam_h;
        const double hs = up0 * D[0][j] + up1 * D[1][j] + up2 * D[2][j];
        const int sky = !(d < INFINITY);
        const double a = k * hs;
        const double t1 = sky ? 0 + sky_need / a : d;
        const int out = (!sky) | ((k > 0) & (hs > 0));
        const double hlow = hs < 0 ? h0 + hs * t1 : h0;
        const int over = (k > 0) & !(-k * hlow < 690);
        const int w = ((!(rho_max > 0)) | (!(d > 0))) ? P1_NONE
                      : ((!out) | over)               ? P1_OPAQUE
                                                      : P1_LANE;
        const double b = k * hs * t1;
        /* the envelope as env_piece forms it from the camera's end */
        const int varies = (k > 0) & (hs != 0);
        const int normal = (!varies) | ((fabs(b) > 1e-12) & (fabs(b) <= 700) & (ce >= DBL_MIN));
        bv[j] = b;
        var[j] = varies;
        nser += varies & (fabs(b) < 0.5);
        ndir += varies & !(fabs(b) < 0.5);
        L[j] = t1;
        num[j] = varies ? t1 : k > 0 ? t1 * ce : t1;
        den[j] = varies ? b : 1;
        ok[j] = lanes & atcam & ((w != P1_LANE) | normal);
        what[j] = w;
    }
    /* t1 (ce (1 - e^-b)) where the envelope varies: one_minus_exp_neg's
     * value, the series or the exponential only where the span needs no
     * other. */
    if (nser && ndir)
        for (int j = 0; j < n; ++j)
            num[j] *= var[j] ? ce * one_minus_exp_neg(bv[j]) : 1;
    else if (ndir)
        for (int j = 0; j < n; ++j)
            num[j] *= var[j] ? ce * (1 - ef_exp_neg(bv[j])) : 1;
    else if (nser)
        for (int j = 0; j < n; ++j)
            num[j] *= var[j] ? ce * ome_series(bv[j]) : 1;
    for (int x = 0; x < s->naxes; ++x) {
        const int a = s->axis[x];
        const mview mv = mview_of(c, a);
        const mpoint cp = s->cam_pt[a];
        const double *cc = M_COEF(&mv, cp.p);
        const double cend = M_START(&mv, cp.p + 1) - M_START(&mv, cp.p), cs = s->cam_s[a];
        const double inv = s->inv_scale;
        double ds[ONE_SPAN], rr[ONE_SPAN], pk[ONE_SPAN], y[ONE_SPAN], I[ONE_SPAN], pre[ONE_SPAN];
        int bin[ONE_SPAN], q[ONE_SPAN];
        for (int j = 0; j < n; ++j) {
            const double dsj = L[j] * (D[a][j] * inv);
            ds[j] = dsj;
            /* period_split's values, by floor: it vectorises where the
             * processor rounds in vector lanes (x86-64-v3), where
             * period_split's 64-bit conversion does not */
            const double v = cs + dsj, kk = floor(v * (1.0 / 256)), r0 = v - 256 * kk;
            const int wrap = r0 >= 256;
            rr[j] = wrap ? r0 - 256 : r0;
            pk[j] = wrap ? kk + 1 : kk;
            bin[j] = bin_of(&mv, rr[j]);
            ok[j] &= (what[j] != P1_LANE) | (fabs(dsj) >= 1e-6);
        }
        for (int j = 0; j < n; ++j) {
            const int32_t h = mv.hint[bin[j]];
            ok[j] &= (what[j] != P1_LANE) | (h >= 0);
            const int hp = h < 0 ? 0 : h;
            q[j] = hp + (M_START(&mv, hp + 1) <= rr[j]);
        }
        for (int j = 0; j < n; ++j)
            y[j] = rr[j] - M_START(&mv, q[j]);
        int j0 = 0;
        for (; j0 + 4 <= n; j0 += 4)
            piece_int4(&mv, q + j0, y + j0, I + j0, pre + j0);
        for (int j = j0; j < n; ++j) {
            I[j] = piece_int(M_COEF(&mv, q[j]), y[j]);
            pre[j] = M_PREFIX(&mv, q[j]);
        }
        const double cpre = M_PREFIX(&mv, cp.p);
        double g[ONE_SPAN];
        int incam = 0;
        for (int j = 0; j < n; ++j) {
            const double yc = cp.y + ds[j];
            incam |= (yc >= 0) & (yc <= cend);
            g[j] = (pk[j] - cp.k) * s->mtotal[a] + (pre[j] - cpre) + (I[j] - cp.I);
        }
        if (incam)
            for (int j = 0; j < n; ++j) {
                /* far end in the camera's piece: its polynomial between
                 * the two (no rounding of the far end's period position) */
                const double yc = cp.y + ds[j];
                const double g1 = piece_int(cc, yc) - cp.I;
                g[j] = ((yc >= 0) & (yc <= cend)) ? g1 : g[j];
            }
        for (int j = 0; j < n; ++j) {
            const double G = ds[j] < 0 ? -g[j] : g[j], w = fabs(ds[j]);
            num[j] *= w + s->contrast * G;
            den[j] *= w;
        }
    }
    for (int j = 0; j < n; ++j) {
        const double u = num[j] / den[j];
        unit[j] = what[j] == P1_LANE && u > 0 ? u : 0;
    }
    for (int j = 0; j < n; ++j) {
        if (ok[j])
            continue;
        /* the general way */
        double h0, hs, t0, t1;
        what[j] = preint_prepare(s, &r[j], &h0, &hs, &t0, &t1, NULL);
        unit[j] = 0;
        if (what[j] == 2) {
            one_ray o;
            one_setup(s, &r[j], h0, hs, t0, t1, &o);
            for (int x = 0; x < s->naxes; ++x) {
                const mview mv = mview_of(c, s->axis[x]);
                one_axis(s, &mv, x, &o);
            }
            const double u = one_value(s, &o);
            unit[j] = u > 0 ? u : 0;
            what[j] = P1_SCALAR;
        }
    }
}

/* preint1_units over a span, tau added to acc. */
EF_MULTIVERSION void ef_nz_preint_span(const ef_fog_component *c, const nstate *s,
                                       const ef_ray *r, int n, double (*acc)[3])
{
    double unit[ONE_SPAN];
    int what[ONE_SPAN];
    preint1_units(c, s, r, n, unit, what);
    const double r0 = s->rho[0], r1 = s->rho[1], r2 = s->rho[2];
    const double i0 = r0 > 0 ? INFINITY : 0, i1 = r1 > 0 ? INFINITY : 0, i2 = r2 > 0 ? INFINITY : 0;
    for (int j = 0; j < n; ++j) {
        const int op = what[j] == P1_OPAQUE;
        const double u = unit[j];
        acc[j][0] += op ? i0 : r0 * u;
        acc[j][1] += op ? i1 : r1 * u;
        acc[j][2] += op ? i2 : r2 * u;
    }
}

/* The preintegrated method's error output, a bound: the method's value u
 * and the true tau / rho both lie in [0, B integral(env)] (the density is
 * at most rho B env), so |u - tau / rho| <= max(u, B integral(env)) over
 * [t0, t1]. Loose, but never misleading: no cheap estimate was found that
 * covers 99 % (bench/preint_calibrate: the change when the pieces double,
 * even times 4 plus 5 % of the mean fog, covered 88 to 94 % of rays on
 * scenes other than the tests'). */
double ef_nz_preint_bound(const nstate *s, double h0, double hs, double t0, double t1, double u)
{
    const double hl = hs > 0 ? h0 + hs * t0 : h0 + hs * t1;   /* the densest end */
    const double m = decay_int(exp(-s->k * hl), fabs(s->k * hs), t1 - t0);
    return fmax(u, shape_bound(s) * m);
}

/* The seed's evaluation from the merged tables, in plain double: per pixel
 * the cost of a few table lookups (the shared path's long double set-up
 * would cost more than the evaluation). The dropped sky tail's bound and,
 * when asked for, the difference to 2K pieces are the error estimate. */
void ef_nz_preint_fast(const ef_fog_component *c, const nstate *s, const ef_ray *r,
                       double tau[3], ef_tau_info *info)
{
    double h0, hs, t0, t1, tail = 0;
    const int what = preint_prepare(s, r, &h0, &hs, &t0, &t1, info ? &tail : NULL);
    if (what < 2) {
        for (int k = 0; k < 3; ++k)
            tau[k] = what && s->rho[k] > 0 ? INFINITY : 0;
        return;
    }
    double unit;
    if (s->pieces == 1) {   /* the span's way, for the same bits */
        int w;
        preint1_units(c, s, r, 1, &unit, &w);
    } else {
        unit = ef_nz_preintegrated_merged(c, s, r, h0, hs, t0, t1, s->pieces);
    }
    double err = tail;
    if (info) {
        err += ef_nz_preint_bound(s, h0, hs, t0, t1, unit);
        info->evals = 1.0 * s->pieces * s->naxes;
        info->cells = (double) s->pieces * s->naxes;
    }
    for (int k = 0; k < 3; ++k) {
        tau[k] = s->rho[k] * (unit > 0 ? unit : 0);
        if (info)
            info->err[k] = s->rho[k] * err;
    }
}
