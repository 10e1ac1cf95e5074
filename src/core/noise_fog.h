/* The noise fog models' private header: the component's state, a ray's
 * set-up, the shared small helpers, and what each file of the family
 * offers the others. Not part of any interface outside src/core/noise_*.c
 * and fog_noise.c (bench/grid_calibrate.c reads it too).
 *
 *   fog_noise.c     the models: keys, state, tau's dispatch, the reference's view
 *   noise_line.c    a ray through the lattices: lines, point densities, the envelope
 *   noise_cells.c   one octave cell by cell, batched across vector lanes
 *   noise_grid.c    one octave on a grid of nodes with an end correction
 *   noise_exact.c   piece by piece between every octave's faces, and the march
 *   noise_plan.c    the adaptive planner: nodes per octave, octaves dropped
 *   noise_linear.c  the default method: segments, the clamp's share, the stop
 *   noise_preint.c  noise-separable's preintegrated evaluation
 *   noise_sep.c     noise-separable's default method where the clamp cannot bind
 *
 * The static inline helpers here are on every hot path; the ef_nz_
 * functions cross files (those defined EF_MULTIVERSION are declared here
 * without it: a caller elsewhere calls the ifunc, whose clones are the
 * defining file's). */
#ifndef EF_NOISE_FOG_H
#define EF_NOISE_FOG_H

#include "exact.h"
#include "expneg.h"
#include "span.h"
#include "fog.h"
#include "noise.h"
#include "noise_clamp.h"

#include <float.h>
#include <stdint.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

enum { M_ADAPTIVE = 0, M_EXACT, M_STEPS, M_PREINT };

/* The default tolerance: 2^-12 in tau keeps |dT| = T |dtau| below half an
 * ulp of a half float for every T, so half output cannot tell. */
#define DEFAULT_TOL EF_NOISE_DEFAULT_TOL
#define DEFAULT_TTOL EF_NOISE_DEFAULT_TOL
#define DEFAULT_STEPS 64
/* RMS of integral(noise) over a straight stretch of l lattice units, per
 * sqrt(l): 0.235-0.245 measured by the same program (noise-anchors.md has
 * 0.23). */
#define LINE_RMS 0.25
#define GL_MAX 16
#define TAB 257          /* prefix entries per octave over one period of 256 cells */

/* Everything a component needs per evaluation, stored in c->arr (plain
 * numbers only, so ef_fog_copy's memcpy duplicates it); the preintegrated
 * tables follow it. */
typedef struct nstate {
    int separable, method, steps, pieces, naxes, axis[3], has_box, clamp;
    double rho[3], rho_max;          /* per scene unit */
    double scale, contrast, seed, k, base, tol, time;
    double ttol;                     /* adaptive: |dT| allowed per channel (0: tol on tau) */
    double offset[3], velocity[3], bmin[3], bmax[3], up[3];
    double bound;                    /* the shape's bound: (1 + |c| noise bound)^m */
    double line_rms[EF_FBM_MAX_OCTAVES];   /* LINE_RMS sqrt(lambda_i) (adaptive) */
    double fixed[3][EF_FBM_MAX_OCTAVES][2];   /* separable: the two constant noise coordinates */
    ef_fbm fbm;
    double glx[GL_MAX + 1][GL_MAX], glw[GL_MAX + 1][GL_MAX];   /* Gauss-Legendre on [-1, 1] */
    int tab_off;                     /* separable: index in arr of the prefix tables, or 0 */
    int hash_off;                    /* index in arr of the grid's hash tables (grid_tables) */
    int ladder_off;                  /* index in arr of the planner's ladders (ladders_fill) */
    int clamp_off;                   /* noise, clamp able to bind: index in arr of the clamp's
                                      * stop-loss tables (noise_clamp.h), else 0 */
    /* preintegrated with an integer lacunarity: per axis one table of the
     * whole fbm factor over its period 256, piece by piece (merged.c below) */
    int merged, mpa[3];              /* pieces per period, per axis */
    int m_off[3];                    /* index in arr of axis a's table */
    double mtotal[3];                /* the fbm part's integral over one period */
    double inv_scale, shift[3], seedq[3];   /* merged: q = (p - shift) inv_scale + seedq */
    double sky_need;                 /* preintegrated sky rays: log(bound / 1e-6) */
    /* The camera bound by bind_noise (merged tables): its q and where
     * that falls per axis, its envelope height and e^(-k h) there. */
    int cam, cam_lines;
    double cam_s[3], cam_h, cam_eh;
    /* The noise model's lattice lines start where the camera is: each
     * octave's reduced coordinate there, per axis (rays from cam_org). */
    double cam_org[3];
    long double cam_b[3][EF_FBM_MAX_OCTAVES];
    /* each octave's noise and gradient there (the grid's end terms at t = 0) */
    double cam_n[EF_FBM_MAX_OCTAVES], cam_g[EF_FBM_MAX_OCTAVES][3];
    struct mpoint { double k, y, I; int p; } cam_pt[3];
    /* lod=pixel (noise only): octave i's weight at distance s from the bound
     * camera is lod_phi(s / lod_S[i]); lod_S[i] = lambda_i / (4 spread), the
     * distance where its cell is four pixel footprints wide (INFINITY: no
     * camera bound, or lod=point) */
    int lod;
    double spread, lod_S[EF_FBM_MAX_OCTAVES];
    /* noise-separable: index in arr of each factor's cell polynomials
     * (ef_nz_factor_tables: [axis slot][octave][cell][7]), and axis a's
     * slot; 0 when none */
    int fpoly_off, fslot[3];
    /* noise-separable, per axis slot and octave: the mean of the factor
     * octave over its period, and the largest variance per cell of a
     * window's sum of its cell integrals, and its mean square
     * (ef_nz_sep_stats) */
    double sep_mu[3][EF_FBM_MAX_OCTAVES], sep_r[3][EF_FBM_MAX_OCTAVES];
    double sep_ms[3][EF_FBM_MAX_OCTAVES];
} nstate;

/* lod=pixel's fade of an octave at x = s / S: 1 up to x = 1 (the cell at
 * least four footprints wide), then e^(-4 (x - 1)): 0.018 where the cell
 * is two footprints wide, 3.4e-4 at four thirds of one. An exponential
 * in s, so along a ray from the camera it joins the envelope's. */
#define LOD_RATE 4.0
static inline double lod_phi(double x)
{
    return x <= 1 ? 1 : exp(-LOD_RATE * (x - 1));
}

/* A merged table's layout from m_off (64-byte aligned where built): per
 * piece one record of 8 doubles, the 7 coefficients of its antiderivative
 * and the prefix integral at its start (one cache line per lookup); then
 * the mp starts and a sentinel 256 (a small array, which the choice
 * between a bin's two pieces reads); then 4 mp lookup bins of one int32
 * each (see build_merged). Plus 8 doubles of alignment slack. */
#define MERGED_SIZE(P) ((size_t) (P) * 11 + 17)
#define MERGED_STARTS(P) (8 * (size_t) (P))                /* offsets in a table */
#define MERGED_HINT(P) (MERGED_STARTS(P) + (size_t) (P) + 1)
#define MERGED_BINS 4    /* lookup bins per piece */
#define MERGED_MAX 65536

/* The component's state: arr starts with it. */
static inline const nstate *state(const ef_fog_component *c)
{
    return (const nstate *) (const void *) c->arr;
}

/* The grid's hash tables: 256 x 256 packed second-level hashes, then 512
 * gradient-number pairs (grid_hash). */
#define GRID_HASH_WORDS (65536 + 512)

/* A factor octave's cell polynomial (ef_nz_cell_poly's 7 coefficients)
 * at fraction y of its cell. */
static inline double cell_poly_at(const double *p, double y)
{
    return (((((p[6] * y + p[5]) * y + p[4]) * y + p[3]) * y + p[2]) * y + p[1]) * y + p[0];
}

/* ---- lattice coordinates along a ray ---- */

/* A noise coordinate along the ray: u(t) = b + t d, b reduced modulo 256. */
typedef struct lin {
    long double b, d;
    double bd, dd;                   /* the same rounded, for per-node work */
} lin;

/* floorl(x), without the x87 rounding-mode switches floorl costs: adding
 * and removing 1.5 2^63 rounds to an integer where long double's ulp is 1
 * (|x| < 2^62), then one step down if that went up. Zero keeps its sign
 * through floorl itself. */
static inline long double floor_ld(long double x)
{
    if (x != 0 && fabsl(x) < 0x1p62L) {
        const long double t = (x + 0x1.8p63L) - 0x1.8p63L;
        return t > x ? t - 1 : t;
    }
    return floorl(x);
}

/* u modulo 256, in [0, 256] (256 only by rounding). */
static inline long double mod256(long double u)
{
    return u - 256 * floor_ld(u * (1.0L / 256));
}

#define MAXLIN (3 * EF_FBM_MAX_OCTAVES)

/* grad(h, x, y, z) = u +- v with u = h < 8 ? x : y, v = h < 4 ? y : h == 12
 * or 14 ? x : z, as coefficient vectors. */
static const double grad_vec[16][3] = {
    { 1, 1, 0 },  { -1, 1, 0 },  { 1, -1, 0 },  { -1, -1, 0 },
    { 1, 0, 1 },  { -1, 0, 1 },  { 1, 0, -1 },  { -1, 0, -1 },
    { 0, 1, 1 },  { 0, -1, 1 },  { 0, 1, -1 },  { 0, -1, -1 },
    { 1, 1, 0 },  { 0, -1, 1 },  { -1, 1, 0 },  { 0, -1, -1 },
};

/* ---- compensated summation ---- */

typedef struct ksum {
    double s, c;
} ksum;

/* Knuth's branch-free TwoSum: the rounding error of s + v exactly, the
 * same value Neumaier's ordered pair gives, without a branch the
 * processor cannot predict (this runs once per lattice cell). */
static inline void kadd(ksum *k, double v)
{
    const double t = k->s + v, bv = t - k->s;
    k->c += (k->s - (t - bv)) + (v - bv);
    k->s = t;
}

/* The compensated sum's value. */
static inline double kval(const ksum *k)
{
    return k->s + k->c;
}

/* ---- one ray's setup ---- */

typedef struct rayc {
    const nstate *s;
    long double t0, t1;              /* the stretch in fog (box-clipped; t1 may be finite for sky) */
    long double h0, hs;              /* envelope height at t = 0 and its rate */
    double kh0, khs;                 /* k h0 and k hs: the envelope is e^-(kh0 + khs t) */
    lin u[MAXLIN];                   /* noise: octave i axis a at 3 i + a; separable: a * N + i */
    double evals, cells;
    double org[3], dir[3];           /* the ray (lod=pixel's distance from the camera) */
    int cam;                         /* starts at the bound camera (its lines, cam_n, cam_g) */
    int stopped;                     /* adaptive_linear ended at the ttol stop */
} rayc;

/* The envelope at t, in long double. */
static inline long double env_at(const rayc *R, long double t)
{
    return R->s->k == 0 ? 1 : expl(-R->s->k * (R->h0 + R->hs * t));
}

/* Octave i's noise at t (noise model). */
static inline double octave_at(rayc *R, int i, long double t)
{
    int64_t X[3];
    double f[3];
    const double td = (double) t;
    for (int a = 0; a < 3; ++a)
        ef_noise_split(R->u[3 * i + a].bd + td * R->u[3 * i + a].dd, &X[a], &f[a]);
    ef_noise_cell nc;
    ef_noise_cell_at(X[0], X[1], X[2], &nc);
    R->evals += 1;
    return ef_noise_cell_eval(&nc, f[0], f[1], f[2]);
}

/* The bound of shape (max(0, 1 + c fbm), or a product of naxes of them). */
static inline double shape_bound(const nstate *s)
{
    return s->bound;
}

/* integral over [0, L] of e0 e^(-a t), a >= 0, L finite: e0 L where a L is
 * too small for expm1 to matter. */
static inline double decay_int(double e0, double a, double L)
{
    const double b = a * L;
    return e0 * (b < 1e-8 ? L : -expm1(-b) / a);
}

/* A batch of cells of one octave (octave_integral and its fast path), laid
 * out so the nodes run across cells (one cell per vector lane). */
#define CELL_BATCH 32
typedef struct cell_batch {
    double f[3][CELL_BATCH];         /* fractions at each cell's entry */
    double hh[CELL_BATCH];           /* half the chord, in t */
    int ic[3][CELL_BATCH];           /* each cell's lattice index (mod 256) */
    unsigned g[8][CELL_BATCH];       /* the corners' hashes (gradient number: & 15) */
    double A[8][CELL_BATCH], B[8][CELL_BATCH];   /* the corners' gradient terms */
    double sum[CELL_BATCH];
    double tc[CELL_BATCH];           /* each cell's entry t (with an envelope) */
} cell_batch;

/* grad_vec's components plus one, two bits per gradient number h (h = 0
 * lowest): a component is (G >> 2h & 3) - 1, a shift vector lanes do. */
#define GRAD_X1 0x46552222u
#define GRAD_Y1 0x2222550au
#define GRAD_Z1 0x190a0a55u

/* Nodes per lattice unit the grid may take, and the root mean square error
 * of its integral of one octave (amplitude 1) per square root of the
 * lattice length: bench/grid_calibrate.c, 2,000 random lines per direction
 * class (random, near an axis, near a diagonal) and length (2 to 128
 * lattice units) against every cell integrated exactly; the largest rms of
 * those, plus 10 %. Its 99.9th percentile there was 2.6 to 5.5 rms. */
#define GRID_N 7
static const double grid_nu[GRID_N] = { 1, 1.5, 2, 3, 4, 6, 8 };
static const double grid_rms[GRID_N] = { 0.077, 0.023, 0.0036, 7.6e-4, 2.4e-4, 4.9e-5, 1.6e-5 };
/* The estimate the planner and the error output use: rms times this. */
#define GRID_SIGMAS 4.5

/* A component's grid hash tables (the state heads its arr). */
static inline const uint32_t *grid_hash_table(const nstate *s)
{
    return (const uint32_t *) (const void *) ((const double *) (const void *) s + s->hash_off);
}

/* The end term's noise and derivative at one end of an octave's segment,
 * kept from the previous segment (which ended where this one starts). */
typedef struct grid_end {
    double t, n, dn, e;              /* e: the envelope there */
    int valid;
} grid_end;

/* Cells of one octave that exact and adaptive walk along one ray, at most
 * (documented: a scale far below the ray's length is integrated
 * statistically beyond it, so the work per pixel stays bounded). */
#define CELL_BUDGET 65536
/* The same where the density is not linear in the noise (clamp, separable). */
#define CELL_BUDGET_FULL 8192
/* Steps of the midpoint march that replaces a walk past the budget where
 * the density is not linear in the noise (clamp, separable). */
#define MARCH_FALLBACK 4096

/* How the adaptive method integrates each octave over a stretch. */
typedef struct plan {
    int q[EF_FBM_MAX_OCTAVES];       /* 0: dropped; else kept (Gauss nodes per cell if walked) */
    double nu[EF_FBM_MAX_OCTAVES];   /* > 0: integrated on the grid, nodes per lattice unit */
    double est;                      /* the error estimate, in tau of the densest channel */
    int dropped;
} plan;

/* One direction's ways of integrating an octave, cheapest first (noise_plan.c). */
typedef struct ladder ladder;

/* The per-ray half of adaptive_linear's planner. */
typedef struct seg_planner {
    const ladder *ld;
    double sp[EF_FBM_MAX_OCTAVES];     /* octave i's lattice units per unit t */
    double isp[EF_FBM_MAX_OCTAVES];    /* 1 / sqrt(sp_i) */
    double lrms[EF_FBM_MAX_OCTAVES];   /* 3 LINE_RMS sqrt(lambda_i): the drop rule */
} seg_planner;

/* The optical depth past which the rest of a ray is not integrated: T is
 * then below e^-60 (1e-26), which no output format can show. */
#define OPAQUE_TAU 60.0
#define LN2 0.693147180559945309417

/* Rays per span of the preintegrated method's batched evaluation. */
#define ONE_SPAN EF_SPAN

/* ---- fog_noise.c ---- */

/* Gauss-Legendre nodes and weights on [-1, 1] for n points. */
void ef_nz_gauss_legendre(int n, double *x, double *w);

/* ---- noise_line.c: the ray through the lattices ---- */

/* q_a at the ray's origin and its rate per unit t, in long double. */
void ef_nz_q_line(const nstate *s, const double org[3], const double dir[3], int a,
                  long double *q0, long double *dq);
/* Octave i's coordinate on axis a along the ray. */
lin ef_nz_octave_line(const nstate *s, int i, long double q0, long double dq, int a);
/* A coordinate's cell index (& 255) and fraction, from one reduction. */
void ef_nz_split_ld(long double u, int64_t *cell, double *frac);
/* Clips [0, len] to the box; 0 when the ray misses it. */
int ef_nz_clip_box(const nstate *s, const ef_ray *r, long double *t0, long double *t1);
/* The ray's envelope terms and lattice lines. */
void ef_nz_ray_setup(const nstate *s, const ef_ray *r, rayc *R);
/* Octave i of the separable factor along axis a at u (long double split). */
double ef_nz_factor_octave_ld(const nstate *s, int a, int i, long double u);
/* The same with a double split. */
double ef_nz_factor_octave(const nstate *s, int a, int i, double u);
/* The shape (without rho and the envelope) at t. */
double ef_nz_shape_at(rayc *R, long double t);
/* integral of the envelope over [t0, t1], t1 possibly infinite. */
long double ef_nz_env_integral(const nstate *s, long double h0, long double hs, long double t0,
                               long double t1);
/* Where a sky ray whose envelope decays may stop. */
long double ef_nz_tail_end(const rayc *R, long double t0, double rel, double abs);
/* The smallest non-zero density of the three channels. */
double ef_nz_rho_min(const nstate *s);
/* Where the envelope's integral from t0 reaches need. */
long double ef_nz_env_reach(const rayc *R, long double t0, long double need);
/* Moves *tend to where the fog is certainly opaque; 1 if it cut. */
int ef_nz_opaque_cut(const rayc *R, long double t0, long double *tend);
/* Moves *tend to where tau's lower bound (rho_min (1 - |c| bound)^m times
 * the envelope's integral) reaches tau, if sooner; 1 if it cut. */
int ef_nz_sure_cut(const rayc *R, long double t0, double tau, long double *tend);
/* Whether the envelope passes e^690 on [t0, t1]. */
int ef_nz_env_overflows(const nstate *s, double h0, double hs, double t0, double t1);
/* Binds the camera at org: each octave's lattice lines and noise there. */
void ef_nz_bind_lines(nstate *s, const double org[3]);

/* ---- noise_cells.c: one octave cell by cell, in batches ---- */

/* Integrates the m cells of b with n Gauss nodes each into acc. */
void ef_nz_batch_flush(const nstate *s, const double d0[3], int n, int m,
                       cell_batch *b, ksum *acc);
/* integral of noise_i over [t0, t1], n nodes per cell (no envelope). */
double ef_nz_octave_integral_fast(rayc *R, int i, int n, double t0, double t1);
/* integral of env * noise_i over [t0, t1], n nodes per cell. */
double ef_nz_octave_integral_env(rayc *R, int i, int n, double t0, double t1);

/* ---- noise_grid.c: one octave on a grid of nodes ---- */

/* Octave noise at lattice point x and its derivative along d. */
double ef_nz_noise_dval(const uint32_t *tab, const double x[3], const double d[3], double *dn);
/* Fills the grid's hash tables (GRID_HASH_WORDS words). */
void ef_nz_grid_tables(uint32_t *t);
/* The grid's integral of env * noise_i over [t0, t1] (nu nodes per lattice unit). */
double ef_nz_octave_grid_env(rayc *R, int i, double nu, double t0, double t1,
                             grid_end *end);
/* The same without an envelope. */
double ef_nz_octave_grid_flat(rayc *R, int i, double nu, double t0, double t1,
                              grid_end *end);
/* Either, for bounds given in long double. */
double ef_nz_octave_grid_any(rayc *R, int i, double nu, long double t0, long double t1,
                             grid_end *end);

/* ---- noise_exact.c: piece by piece, and the march ---- */

/* integral of env * noise_i over [t0, t1] (n nodes per cell; 0: certified). */
double ef_nz_octave_integral(rayc *R, int i, int n, long double t0, long double t1,
                             double *err);
/* integral of env * shape over [t0, t1] piece by piece between every octave's faces. */
double ef_nz_full_integral(rayc *R, int lo, int hi, long double t0, long double t1,
                           double tol_per_len, double *err);
/* The midpoint march of env * shape with n steps. */
double ef_nz_march(rayc *R, long double t0, long double t1, int n);
/* A bound on the march's error. */
double ef_nz_march_bound(const rayc *R, long double t0, long double t1, int n, double unit);

/* ---- noise_sep.c: noise-separable where the clamp cannot bind ---- */

/* Fills sep_mu and sep_r from the factor cell polynomials tab. */
void ef_nz_sep_stats(nstate *s, const double *tab);
/* integral of env * shape over [t0, tend] with the octaves whose cells
 * are many dropped while SEP_SIGMAS standard deviations of their sum fit
 * 9/10 of tol (in tau of the densest channel), segment by segment, the
 * rest piece by piece; *est the estimate of the error (the dropped
 * octaves', and a bound of the quadrature's); *dropped the most
 * factor octaves a segment dropped; *over whether the work bound made
 * later segments drop more. With cut_unit finite, stops where the value
 * reached less *est passes it (*cut_at >= 0 then). */
double ef_nz_separable_fast(rayc *R, long double t0, long double tend, double tol,
                            double cut_unit, double *est, long double *cut_at, double *dropped,
                            int *over);

/* ---- noise_plan.c: nodes per octave and octaves kept ---- */

/* What octave i can add over a stretch of length L (hard bound or sigmas sd). */
double ef_nz_line_est(const nstate *s, int i, double L, double sigmas);
/* Evaluations octave i's plan costs over a stretch of length L. */
double ef_nz_plan_evals(const rayc *R, const plan *P, int i, double L);
/* Doubles the planner's ladders take in arr. */
size_t ef_nz_ladders_words(void);
/* Fills the planner's ladders. */
void ef_nz_ladders_fill(double *at);
/* Fills SP for ray R; 0 where the grid cannot serve it. */
int ef_nz_seg_planner_init(const rayc *R, seg_planner *SP);
/* The plan of one segment of adaptive_linear within tol; fm and fq (or
 * NULL: 1) scale octave i's mean envelope and its rms (lod=pixel's fade). */
void ef_nz_plan_segment(const rayc *R, const seg_planner *SP, double L, double emean,
                        double emsq, const double *fm, const double *fq, double tol, plan *P);
/* The plan of a whole stretch within tol (no grid). */
void ef_nz_plan_octaves(const rayc *R, double L, double envmax, double tol, plan *P);
/* The estimate of what every octave but `only` adds over L. */
double ef_nz_rest_estimate(const nstate *s, int only, double L);
/* Under ttol, the error of tau this ray may have. */
double ef_nz_ttol_budget(const rayc *R, long double t0, long double t1, double L, double envmax,
                         int linear);
/* The same for a ray whose tau / rho is at least lo. */
double ef_nz_ttol_dtau(const nstate *s, double lo);

/* ---- noise_linear.c: the default method, segment by segment ---- */

/* The optical depth past which a ray under ttol stops: T below ttol/4 in
 * every channel, which nothing past it can move by more. */
static inline double ef_nz_tau_stop(const nstate *s)
{
    return log(4 / s->ttol);
}

/* A ray stopped under ttol, whose true tau / rho is at least lo: the tau
 * / rho to report, est (the mean fog to the end) held at least ln 2
 * above lo in every channel (T at most T_up / 2) and at most 600 above
 * (T expm1(err) stays finite in double), and into errk the error output
 * per channel, which then spans [0, T_up] and no more. */
double ef_nz_stop_report(const nstate *s, double lo, double est, double errk[3]);

/* tau / rho of the noise model under ttol, with its error per channel. */
double ef_nz_adaptive_linear(rayc *R, long double t0, long double tend, long double t1,
                             int opaque, double tail, ef_tau_info *info, double errk[3]);

/* ---- noise_preint.c: the seed's preintegrated evaluation ---- */

/* The per-octave prefix tables. */
void ef_nz_build_tables(nstate *s, double *tab);
/* Octave i of factor a inside its cell m as a polynomial of degree 6 in
 * the fraction (exact in long double). */
void ef_nz_cell_poly(const nstate *s, int a, int i, long m, long double p[7]);
/* The separable factors' cell polynomials, naxes * octaves * 256 * 7 doubles. */
void ef_nz_factor_tables(const nstate *s, double *tab);
/* Factor a's merged table; returns its pieces (0: out of memory). */
int ef_nz_build_merged(const nstate *s, int a, double *tab, int cap, double *total);
/* Binds the camera at org in the merged tables. */
void ef_nz_bind_merged(ef_fog_component *c, const double org[3]);
/* tau / rho of K equal pieces of [t0, t1] from the merged tables. */
double ef_nz_preintegrated_merged(const ef_fog_component *c, const nstate *s, const ef_ray *r,
                                  double h0, double hs, double t0, double t1, int K);
/* tau / rho of K equal pieces from the prefix tables. */
double ef_nz_preintegrated(const ef_fog_component *c, rayc *R, long double t0, long double t1,
                           int K);
/* pieces=1 over a span of rays, tau added to acc. */
void ef_nz_preint_span(const ef_fog_component *c, const nstate *s,
                       const ef_ray *r, int n, double (*acc)[3]);
/* The preintegrated method's error bound. */
double ef_nz_preint_bound(const nstate *s, double h0, double hs, double t0, double t1, double u);
/* The merged tables' evaluation of one ray, in plain double. */
void ef_nz_preint_fast(const ef_fog_component *c, const nstate *s, const ef_ray *r,
                       double tau[3], ef_tau_info *info);

#endif
