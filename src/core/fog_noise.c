/* Heterogeneous fog from Perlin noise (seed 004 section 3.2.3, made
 * three-dimensional), with a speed/accuracy trade the user picks and sees.
 *
 *   noise:            sigma = rho env(p) max(0, 1 + c fbm(q))
 *   noise-separable:  sigma = rho env(p) prod_{a in axes} max(0, 1 + c fbm(e_a(q_a)))
 *
 * q = (p - offset - velocity time) / scale + seed S, env = e^(-k (up.p - base)),
 * sigma = 0 outside the box [min, max] when one is given (noise.h has fbm).
 *
 * Methods (method= key):
 *   exact     inside one lattice cell the noise along a line is a polynomial
 *             of degree 16, so Gauss-Legendre with 9 nodes per cell segment is
 *             exact; each octave's cells are walked on their own (a 3D DDA)
 *             and summed with compensated summation. With an envelope, cells
 *             where it varies by <= 5 % take 12 nodes (exact to 1e-15),
 *             others a pair of Gauss rules (9 and 13) bisected until they
 *             agree to 1e-14 of the cell's bound; where the clamp can bind,
 *             pieces between every octave's faces are bounded first (empty:
 *             skipped; clamp-free: 9 nodes) and bisected otherwise.
 *   adaptive  tau to an absolute error tol (the default): per octave the
 *             fewest Gauss nodes per cell whose calibrated error (4 sigma of
 *             independent cell errors, or the worst case if smaller) fits,
 *             fine octaves dropped while 3 sigma of their line integrals (or
 *             their hard bound) fits, every pixel's error estimate reported.
 *   steps     the uniform midpoint ray-march of game engines (steps=N).
 *   preintegrated  (noise-separable) the seed's evaluation: per-axis prefix
 *             integrals and the product of the factors' means over K pieces.
 * Where the clamp cannot bind (linear fbm), the mean part rho integral(env)
 * is its closed form and only the noise is integrated. Rays are cut where
 * the computed tau reaches 60 (T < 1e-26): the rest cannot show.
 *
 * Lattice coordinates are formed in long double from the ray's origin and
 * reduced modulo the noise period 256, so a fraction inside a cell keeps
 * its absolute precision wherever the camera and the offset are. */
#include "exact.h"
#include "expneg.h"
#include "span.h"
#include "fog.h"
#include "noise.h"
#include "noise_clamp.h"

#include <float.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum {
    K_DENSITY, K_VISIBILITY, K_SCALE, K_OCTAVES, K_LACUNARITY, K_GAIN, K_CONTRAST, K_OFFSET,
    K_VELOCITY, K_SEED, K_FALLOFF, K_BASE, K_MIN, K_MAX, K_METHOD, K_TOL, K_TTOL, K_STEPS,
    K_AXES,
    K_PIECES
};

static const char *const noise_keys[] = {
    "density", "visibility", "scale", "octaves", "lacunarity", "gain", "contrast", "offset",
    "velocity", "seed", "falloff", "base", "min", "max", "method", "tol", "ttol", "steps",
    NULL
};
static const char *const separable_keys[] = {
    "density", "visibility", "scale", "octaves", "lacunarity", "gain", "contrast", "offset",
    "velocity", "seed", "falloff", "base", "min", "max", "method", "tol", "ttol", "steps",
    "axes",
    "pieces", NULL
};

/* p[] while parsing (finish() moves everything into the state in arr). */
enum {
    P_RHO = 0, P_SCALE = 3, P_OCTAVES, P_LACUNARITY, P_GAIN, P_CONTRAST, P_OFFSET = 8,
    P_VELOCITY = 11, P_SEED = 14, P_FALLOFF, P_BASE, P_MIN = 17, P_MAX = 20, P_METHOD = 23,
    P_TOL, P_STEPS, P_AXES, P_PIECES, P_TTOL
};

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
} nstate;

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

static const nstate *state(const ef_fog_component *c)
{
    return (const nstate *) (const void *) c->arr;
}

/* ---- parsing ---- */

static int set_vec3(ef_fog_component *c, const char *key, const char *val, double *out,
                    ef_err *err)
{
    if (ef_parse_numbers(val, out, 3))
        return ef_fail(err, "fog spec '%s': %s='%s' is not X,Y,Z (three numbers)", c->spec, key, val);
    return 0;
}

static int set_real(ef_fog_component *c, const char *key, const char *val, double *out,
                    const char *what, int (*ok)(double), ef_err *err)
{
    if (ef_parse_numbers(val, out, 1) || (ok && !ok(*out)))
        return ef_fail(err, "fog spec '%s': %s='%s' %s", c->spec, key, val, what);
    return 0;
}

static int positive(double v) { return v > 0; }
static int nonneg(double v) { return v >= 0; }
static int above_one(double v) { return v > 1; }
static int unit_open(double v) { return v > 0 && v < 1; }
/* Beyond 100 the density is a step function of the noise's sign: nothing
 * more to see, and the clamp's splitting only costs. */
static int contrast_ok(double v) { return fabs(v) <= 100; }

static int set_noise(ef_fog_component *c, int k, const char *val, ef_err *err)
{
    double *p = c->p;
    switch (k) {
    case K_DENSITY:
        return ef_fog_set_density(c, "density", val, p + P_RHO, err);
    case K_VISIBILITY:
        return ef_fog_set_visibility(c, "visibility", val, p + P_RHO, err);
    case K_SCALE:
        return set_real(c, "scale", val, p + P_SCALE, "must be a length > 0 (scene units: the "
                        "size of the coarsest noise cell)", positive, err);
    case K_OCTAVES: {
        char *end;
        long n = strtol(val, &end, 10);
        if (*end || end == val || n < 1 || n > EF_FBM_MAX_OCTAVES)
            return ef_fail(err, "fog spec '%s': octaves='%s' must be a whole number from 1 to %d",
                           c->spec, val, EF_FBM_MAX_OCTAVES);
        p[P_OCTAVES] = (double) n;
        return 0;
    }
    case K_LACUNARITY:
        return set_real(c, "lacunarity", val, p + P_LACUNARITY, "must be a number > 1 (each "
                        "octave's frequency over the previous one; 2 is usual)", above_one, err);
    case K_GAIN:
        return set_real(c, "gain", val, p + P_GAIN, "must be a number > 0 (each octave's "
                        "amplitude over the previous one; 0.5 is usual)", positive, err);
    case K_CONTRAST:
        return set_real(c, "contrast", val, p + P_CONTRAST, "is not a number from -100 to 100 "
                        "(beyond about 1 the clamp at 0 binds: fog in patches)", contrast_ok, err);
    case K_OFFSET:
        return set_vec3(c, "offset", val, p + P_OFFSET, err);
    case K_VELOCITY:
        return set_vec3(c, "velocity", val, p + P_VELOCITY, err);
    case K_SEED:
        return set_real(c, "seed", val, p + P_SEED, "is not a number", NULL, err);
    case K_FALLOFF:
        return set_real(c, "falloff", val, p + P_FALLOFF, "must be a number >= 0 (per metre; 0: "
                        "no height envelope)", nonneg, err);
    case K_BASE:
        return set_real(c, "base", val, p + P_BASE, "is not a number (the height, in scene "
                        "units, where the envelope is 1)", NULL, err);
    case K_MIN:
        return set_vec3(c, "min", val, p + P_MIN, err);
    case K_MAX:
        return set_vec3(c, "max", val, p + P_MAX, err);
    case K_METHOD: {
        static const char *const names[] = { "adaptive", "exact", "steps", "preintegrated" };
        for (int m = 0; m < 4; ++m)
            if (!strcmp(val, names[m]) && (m != M_PREINT || c->model == &ef_fog_noise_separable)) {
                p[P_METHOD] = m;
                return 0;
            }
        return ef_fail(err, "fog spec '%s': method='%s' is not adaptive, exact, steps%s", c->spec,
                       val, c->model == &ef_fog_noise_separable ? " or preintegrated" : "");
    }
    case K_TOL:
        return set_real(c, "tol", val, p + P_TOL, "must be a number > 0 (the absolute error "
                        "allowed in tau, which is the relative error of T)", positive, err);
    case K_TTOL:
        return set_real(c, "ttol", val, p + P_TTOL, "must be a number from 0 to 1, 0 excluded "
                        "(the absolute error allowed in T, each channel)", unit_open, err);
    case K_STEPS:
    case K_PIECES: {
        char *end;
        long n = strtol(val, &end, 10);
        if (*end || end == val || n < 1 || n > 1000000)
            return ef_fail(err, "fog spec '%s': %s='%s' must be a whole number from 1 to 1000000",
                           c->spec, k == K_STEPS ? "steps" : "pieces", val);
        p[k == K_STEPS ? P_STEPS : P_PIECES] = (double) n;
        return 0;
    }
    default: { /* K_AXES */
        int mask = 0;
        for (const char *s = val; *s; ++s) {
            const int bit = *s == 'x' ? 1 : *s == 'y' ? 2 : *s == 'z' ? 4 : 0;
            if (!bit || (mask & bit))
                return ef_fail(err, "fog spec '%s': axes='%s' must be a subset of xyz, each axis "
                               "once (e.g. xz)", c->spec, val);
            mask |= bit;
        }
        p[P_AXES] = mask;
        return 0;
    }
    }
}

/* Gauss-Legendre nodes and weights on [-1, 1] for n points (Newton on the
 * Legendre recurrence in long double). */
static void gauss_legendre(int n, double *x, double *w)
{
    const long double pi = 3.141592653589793238462643383279502884L;
    for (int i = 0; i < n; ++i) {
        long double z = cosl(pi * (i + 0.75L) / (n + 0.5L)), dp = 1;
        for (int it = 0; it < 100; ++it) {
            long double p0 = 1, p1 = z;
            for (int j = 2; j <= n; ++j) {
                const long double p2 = ((2 * j - 1) * z * p1 - (j - 1) * p0) / j;
                p0 = p1;
                p1 = p2;
            }
            if (n == 1)
                p0 = 1, p1 = z;
            dp = n * (z * p1 - p0) / (z * z - 1);
            const long double dz = p1 / dp;
            z -= dz;
            if (fabsl(dz) < 1e-19L)
                break;
        }
        x[i] = (double) -z;
        w[i] = (double) (2 / ((1 - z * z) * dp * dp));
    }
}

static void build_tables(nstate *s, double *tab);
/* The grid's hash tables: 256 x 256 packed second-level hashes, then 512
 * gradient-number pairs (grid_hash). */
#define GRID_HASH_WORDS (65536 + 512)
static void grid_tables(uint32_t *t);
static size_t ladders_words(void);
static void ladders_fill(double *at);
static int build_merged(const nstate *s, int a, double *tab, int cap, double *total);

static int finish_noise(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err)
{
    const int sep = c->model == &ef_fog_noise_separable;
    const unsigned given = c->seen & ((1u << K_DENSITY) | (1u << K_VISIBILITY));
    const char *name = c->model->name;
    if (!given)
        return ef_fail(err, "fog spec '%s': missing density (write %s:density=D:scale=L, or "
                       "visibility=V instead of density)", c->spec, name);
    if (given == ((1u << K_DENSITY) | (1u << K_VISIBILITY)))
        return ef_fail(err, "fog spec '%s': give density or visibility, not both", c->spec);
    if (!(c->seen & (1u << K_SCALE)))
        return ef_fail(err, "fog spec '%s': missing scale (write %s:density=D:scale=L, L the "
                       "coarsest noise cell in scene units)", c->spec, name);
    const int has_min = !!(c->seen & (1u << K_MIN)), has_max = !!(c->seen & (1u << K_MAX));
    if (has_min != has_max)
        return ef_fail(err, "fog spec '%s': give both min=X,Y,Z and max=X,Y,Z for the box, or "
                       "neither", c->spec);
    for (int a = 0; has_min && a < 3; ++a)
        if (!(c->p[P_MIN + a] <= c->p[P_MAX + a]))
            return ef_fail(err, "fog spec '%s': the box's min %g is above its max %g on axis %c",
                           c->spec, c->p[P_MIN + a], c->p[P_MAX + a], "xyz"[a]);
    const int method = (c->seen & (1u << K_METHOD)) ? (int) c->p[P_METHOD] : M_ADAPTIVE;
    if ((c->seen & (1u << K_STEPS)) && method != M_STEPS)
        return ef_fail(err, "fog spec '%s': steps= only applies to method=steps", c->spec);
    if ((c->seen & (1u << K_TOL)) && method != M_ADAPTIVE)
        return ef_fail(err, "fog spec '%s': tol= only applies to method=adaptive", c->spec);
    if ((c->seen & (1u << K_TTOL)) && method != M_ADAPTIVE)
        return ef_fail(err, "fog spec '%s': ttol= only applies to method=adaptive", c->spec);
    if ((c->seen & (1u << K_TTOL)) && (c->seen & (1u << K_TOL)))
        return ef_fail(err, "fog spec '%s': give tol= (the error of tau: relative in T) or "
                       "ttol= (the absolute error of T), not both", c->spec);
    if (sep && (c->seen & (1u << K_PIECES)) && method != M_PREINT)
        return ef_fail(err, "fog spec '%s': pieces= only applies to method=preintegrated", c->spec);

    nstate s;
    memset(&s, 0, sizeof s);
    s.separable = sep;
    s.method = method;
    s.steps = (c->seen & (1u << K_STEPS)) ? (int) c->p[P_STEPS] : DEFAULT_STEPS;
    s.pieces = (c->seen & (1u << K_PIECES)) ? (int) c->p[P_PIECES] : 1;
    /* The default: |dT| <= 2^-12 per channel, what the picture shows. */
    s.ttol = (c->seen & (1u << K_TTOL)) ? c->p[P_TTOL]
             : !(c->seen & (1u << K_TOL)) && method == M_ADAPTIVE ? DEFAULT_TTOL : 0;
    /* Under ttol, tol is what the per-ray budget starts from (T <= 1). */
    s.tol = (c->seen & (1u << K_TOL)) ? c->p[P_TOL] : s.ttol > 0 ? log1p(s.ttol) : DEFAULT_TOL;
    const int axes = sep ? ((c->seen & (1u << K_AXES)) ? (int) c->p[P_AXES] : 5) : 7;
    for (int a = 0; a < 3; ++a)
        if (axes & (1 << a))
            s.axis[s.naxes++] = a;
    const int octaves = (c->seen & (1u << K_OCTAVES)) ? (int) c->p[P_OCTAVES] : 4;
    const double lac = (c->seen & (1u << K_LACUNARITY)) ? c->p[P_LACUNARITY] : 2.0;
    const double gain = (c->seen & (1u << K_GAIN)) ? c->p[P_GAIN] : 0.5;
    ef_fbm_init(&s.fbm, octaves, lac, gain);
    if (!isfinite(s.fbm.norm) || !isfinite(s.fbm.freq[octaves - 1]) || !(s.fbm.weight[octaves - 1] > 0))
        return ef_fail(err, "fog spec '%s': lacunarity %g and gain %g over %d octaves leave the "
                       "range of doubles; use fewer octaves or values nearer 2 and 0.5", c->spec,
                       lac, gain, octaves);
    s.contrast = (c->seen & (1u << K_CONTRAST)) ? c->p[P_CONTRAST] : 0.9;
    s.clamp = fabs(s.contrast) * EF_NOISE_BOUND > 1;
    s.bound = pow(1 + fabs(s.contrast) * EF_NOISE_BOUND, sep ? s.naxes : 1);
    s.scale = c->p[P_SCALE];
    for (int i = 0; i < s.fbm.octaves; ++i)
        s.line_rms[i] = LINE_RMS * sqrt(s.scale / s.fbm.freq[i]);
    s.seed = c->p[P_SEED];
    s.k = ef_fog_per_unit(ctx, c->p[P_FALLOFF]);
    s.base = c->p[P_BASE];
    s.time = ctx->time;
    s.has_box = has_min;
    s.rho_max = 0;
    for (int a = 0; a < 3; ++a) {
        s.rho[a] = ef_fog_per_unit(ctx, c->p[P_RHO + a]);
        if (s.rho[a] > s.rho_max)
            s.rho_max = s.rho[a];
        s.offset[a] = c->p[P_OFFSET + a];
        s.velocity[a] = c->p[P_VELOCITY + a];
        s.bmin[a] = c->p[P_MIN + a];
        s.bmax[a] = c->p[P_MAX + a];
        s.up[a] = c->up[a];
    }
    if (!isfinite(s.k) || !isfinite(s.rho_max))
        return ef_fail(err, "fog spec '%s': a density or falloff leaves the range of doubles",
                       c->spec);
    for (int a = 0; a < 3; ++a)
        if (!isfinite(s.velocity[a] * s.time))
            return ef_fail(err, "fog spec '%s': velocity times --time leaves the range of doubles",
                           c->spec);
    s.inv_scale = 1 / s.scale;
    s.sky_need = log(s.bound / 1e-6);
    for (int a = 0; a < 3; ++a) {
        s.shift[a] = s.offset[a] + s.velocity[a] * s.time;
        s.seedq[a] = s.seed * ef_noise_seed_dir[a];
    }
    if (sep && method == M_PREINT && s.clamp)
        return ef_fail(err, "fog spec '%s': method=preintegrated needs |contrast| <= %.6g, where "
                       "the clamp max(0, 1 + c fbm) never binds (the factors' prefix integrals "
                       "are then exact); use method=adaptive or exact for this contrast", c->spec,
                       1 / EF_NOISE_BOUND);
    /* The separable factors' constant coordinates, as the contract forms them. */
    for (int a = 0; a < 3; ++a)
        for (int i = 0; i < octaves; ++i) {
            static const double e_other[3][2] = { { 0.37, 0.71 }, { 0.37, 0.71 }, { 0.37, 0.71 } };
            int j = 0;
            for (int b = 0; b < 3; ++b)
                if (b != a)
                    s.fixed[a][i][j] = s.fbm.freq[i] * e_other[a][j] + (double) i * ef_fbm_offset[b],
                    ++j;
        }
    for (int n = 1; n <= GL_MAX; ++n)
        gauss_legendre(n, s.glx[n], s.glw[n]);

    const size_t head = (sizeof s + sizeof(double) - 1) / sizeof(double);
    /* One merged table per axis when every octave repeats within 256. */
    long mp = 0;
    if (sep && method == M_PREINT && lac == floor(lac)) {
        mp = 1;
        for (int i = 0; i < octaves && mp <= MERGED_MAX; ++i)
            mp += 256 * (long) s.fbm.freq[i];
        if (mp > MERGED_MAX)
            mp = 0;
    }
    /* Else per-octave prefix tables (only the preintegrated method reads them). */
    const size_t ntab = sep && method == M_PREINT && !mp ? (size_t) 3 * (size_t) octaves * TAB : 0;
    const size_t nmerged = mp ? (size_t) s.naxes * MERGED_SIZE(mp) : 0;
    /* the grid's hash tables (uint32 each) and the planner's ladders */
    const size_t nhash = GRID_HASH_WORDS / 2 + ladders_words();
    const size_t nclamp = !sep && s.clamp ? ef_clamp_tables_size(octaves) : 0;
    double *arr = calloc(head + ntab + nmerged + nhash + nclamp, sizeof *arr);
    if (!arr)
        return ef_fail(err, "fog spec '%s': out of memory", c->spec);
    s.tab_off = ntab ? (int) head : 0;
    if (ntab)
        build_tables(&s, arr + head);
    if (mp) {
        size_t at = head + ntab;
        s.merged = 1;
        for (int k = 0; k < s.naxes; ++k) {
            const int a = s.axis[k];
            while ((uintptr_t) (arr + at) % 64)   /* each record on one cache line */
                ++at;
            s.m_off[a] = (int) at;
            s.mpa[a] = build_merged(&s, a, arr + at, (int) mp, &s.mtotal[a]);
            if (!s.mpa[a]) {
                free(arr);
                return ef_fail(err, "fog spec '%s': out of memory", c->spec);
            }
            at += MERGED_SIZE(mp);
        }
    }
    s.hash_off = (int) (head + ntab + nmerged);
    grid_tables((uint32_t *) (void *) (arr + s.hash_off));
    s.ladder_off = s.hash_off + GRID_HASH_WORDS / 2;
    ladders_fill(arr + s.ladder_off);
    if (nclamp) {
        s.clamp_off = (int) (head + ntab + nmerged + nhash);
        if (ef_clamp_tables_build(&s.fbm, arr + s.clamp_off)) {
            free(arr);
            return ef_fail(err, "fog spec '%s': out of memory", c->spec);
        }
    }
    memcpy(arr, &s, sizeof s);
    free(c->arr);
    c->arr = arr;
    c->narr = (int) (head + ntab + nmerged + nhash + nclamp);
    return 0;
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

static long double mod256(long double u)
{
    return u - 256 * floor_ld(u * (1.0L / 256));
}

/* q_a at the ray's origin and its rate per unit t, in long double. */
static void q_line(const nstate *s, const double org[3], const double dir[3], int a,
                   long double *q0, long double *dq)
{
    const long double sh = (long double) s->seed * ef_noise_seed_dir[a];
    *q0 = (((long double) org[a] - s->offset[a]) - (long double) s->velocity[a] * s->time) /
              s->scale + sh;
    *dq = (long double) dir[a] / s->scale;
}

/* Octave i's coordinate on axis a along the ray. */
static lin octave_line(const nstate *s, int i, long double q0, long double dq, int a)
{
    const long double f = s->fbm.freq[i];
    const long double b = mod256(f * q0 + (long double) i * ef_fbm_offset[a]), d = f * dq;
    return (lin) { b, d, (double) b, (double) d };
}

/* Splits a coordinate into its cell index (& 255) and the fraction in the
 * cell, both from one reduction modulo 256 (the noise's period). */
static void split_ld(long double u, int64_t *cell, double *frac)
{
    const long double r = mod256(u);
    int c = (int) r;          /* r >= 0: truncation is floor */
    if (c > 255) {            /* r rounded up to 256 */
        *cell = 0;
        *frac = 0;
        return;
    }
    const double fr = (double) (r - c);
    *cell = c;
    *frac = fr < 0 ? 0 : fr > 1 ? 1 : fr;
}

/* ---- the cell walk: several coordinates crossing integers along t ---- */

#define MAXLIN (3 * EF_FBM_MAX_OCTAVES)

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

/* A cell's eight corner gradients as numbers, so a node's noise needs no
 * branches: g.(x, y, z) adds the same two non-zero terms as Perlin's grad. */
typedef struct gcell {
    double g[8][3];
} gcell;

/* grad(h, x, y, z) = u +- v with u = h < 8 ? x : y, v = h < 4 ? y : h == 12
 * or 14 ? x : z, as coefficient vectors. */
static const double grad_vec[16][3] = {
    { 1, 1, 0 },  { -1, 1, 0 },  { 1, -1, 0 },  { -1, -1, 0 },
    { 1, 0, 1 },  { -1, 0, 1 },  { 1, 0, -1 },  { -1, 0, -1 },
    { 0, 1, 1 },  { 0, -1, 1 },  { 0, 1, -1 },  { 0, -1, -1 },
    { 1, 1, 0 },  { 0, -1, 1 },  { -1, 1, 0 },  { 0, -1, -1 },
};

static void gcell_of(const ef_noise_cell *nc, gcell *gc)
{
    for (int k = 0; k < 8; ++k)
        memcpy(gc->g[k], grad_vec[nc->h[k] & 15], sizeof gc->g[k]);
}

static inline double gdot(const double g[3], double x, double y, double z)
{
    return g[0] * x + g[1] * y + g[2] * z;
}

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

static double kval(const ksum *k)
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
    int cam;                         /* starts at the bound camera (its lines, cam_n, cam_g) */
} rayc;

static long double env_at(const rayc *R, long double t)
{
    return R->s->k == 0 ? 1 : expl(-R->s->k * (R->h0 + R->hs * t));
}

/* Clips [0, len] to the box; returns 0 when the ray misses it. */
static int clip_box(const nstate *s, const ef_ray *r, long double *t0, long double *t1)
{
    *t0 = 0;
    *t1 = r->dist;
    if (!s->has_box)
        return 1;
    for (int a = 0; a < 3; ++a) {
        const long double o = r->org[a], d = r->dir[a];
        if (d == 0) {
            if (o < s->bmin[a] || o > s->bmax[a])
                return 0;
            continue;
        }
        long double ta = (s->bmin[a] - o) / d, tb = (s->bmax[a] - o) / d;
        if (ta > tb) {
            const long double x = ta;
            ta = tb;
            tb = x;
        }
        if (ta > *t0)
            *t0 = ta;
        if (tb < *t1)
            *t1 = tb;
    }
    return *t0 < *t1;
}

static void ray_setup(const nstate *s, const ef_ray *r, rayc *R)
{
    R->s = s;
    R->evals = R->cells = 0;
    R->cam = 0;
    const ef_fog_functional up = { { s->up[0], s->up[1], s->up[2] }, -s->base };
    const ef_dd h0 = ef_dd_dot3(up.n, r->org, up.d), hs = ef_dd_dot3(up.n, r->dir, 0.0);
    R->h0 = (long double) h0.hi + h0.lo;
    R->hs = (long double) hs.hi + hs.lo;
    R->kh0 = (double) (s->k * R->h0);
    R->khs = (double) (s->k * R->hs);
    if (s->merged)
        return;   /* the merged tables need no lattice lines */
    const int N = s->fbm.octaves;
    const int hit = s->cam_lines && r->org[0] == s->cam_org[0] && r->org[1] == s->cam_org[1] &&
                    r->org[2] == s->cam_org[2];
    R->cam = hit;
    for (int a = 0; a < 3; ++a) {
        long double q0 = 0, dq;
        if (hit)
            dq = (long double) r->dir[a] / s->scale;   /* as q_line */
        else
            q_line(s, r->org, r->dir, a, &q0, &dq);
        for (int i = 0; i < N; ++i) {
            lin l;
            if (hit) {   /* octave_line with the camera's reduced start */
                l.b = s->cam_b[a][i];
                l.d = (long double) s->fbm.freq[i] * dq;
                l.bd = (double) l.b;
                l.dd = (double) l.d;
            } else {
                l = octave_line(s, i, q0, dq, a);
            }
            if (s->separable)
                R->u[a * N + i] = l;
            else
                R->u[3 * i + a] = l;
        }
    }
}

/* ---- densities at a point of the ray ---- */

/* Octave i's noise at t (noise model). */
static double octave_at(rayc *R, int i, long double t)
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

/* Octave i of the factor along axis a, whose own coordinate is split into
 * cell xa and fraction fa (the other two are the factor's constants). */
static double factor_octave_at(const nstate *s, int a, int i, int64_t xa, double fa)
{
    int64_t X[3];
    double f[3];
    int j = 0;
    for (int b = 0; b < 3; ++b) {
        if (b == a) {
            X[b] = xa;
            f[b] = fa;
        } else {
            ef_noise_split(s->fixed[a][i][j++], &X[b], &f[b]);
        }
    }
    ef_noise_cell nc;
    ef_noise_cell_at(X[0], X[1], X[2], &nc);
    return ef_noise_cell_eval(&nc, f[0], f[1], f[2]);
}

/* Octave i of the factor along axis a at its coordinate u (precise: a
 * long double split, for the reference's density). */
static double factor_octave_ld(const nstate *s, int a, int i, long double u)
{
    int64_t x;
    double f;
    split_ld(u, &x, &f);
    return factor_octave_at(s, a, i, x, f);
}

/* Octave i of the factor along axis a at its coordinate u. */
static double factor_octave(const nstate *s, int a, int i, double u)
{
    int64_t x;
    double f;
    ef_noise_split(u, &x, &f);
    return factor_octave_at(s, a, i, x, f);
}

/* max(0, 1 + c fbm) of the noise model, or the product of the separable
 * factors, at t (without rho and the envelope). */
static double shape_at(rayc *R, long double t)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    if (!s->separable) {
        double f = 0;
        for (int i = 0; i < N; ++i)
            f += s->fbm.weight[i] * octave_at(R, i, t);
        const double v = 1 + s->contrast * f;
        return v > 0 ? v : 0;
    }
    double prod = 1;
    for (int k = 0; k < s->naxes; ++k) {
        const int a = s->axis[k];
        double f = 0;
        for (int i = 0; i < N; ++i)
            f += s->fbm.weight[i] *
                 factor_octave(s, a, i, R->u[a * N + i].bd + (double) t * R->u[a * N + i].dd);
        R->evals += N;
        const double v = 1 + s->contrast * f;
        prod *= v > 0 ? v : 0;
    }
    return prod;
}

/* ---- the closed-form mean part: integral of env over [t0, t1] ---- */

/* integral_{t0}^{t1} e^(-k (h0 + hs t)) dt; t1 may be infinite (the caller
 * only asks when the envelope decays along the ray). */
static long double env_integral(const nstate *s, long double h0, long double hs, long double t0,
                                long double t1)
{
    if (s->k == 0 || hs == 0)
        return (t1 - t0) * (s->k == 0 ? 1 : expl(-s->k * h0));
    const long double a = s->k * hs;
    if (isinf(t1))
        return expl(-s->k * (h0 + hs * t0)) / a;
    /* From the lower end of the envelope: e^(-k h_low) (1 - e^-b)/(k |hs|). */
    const long double L = t1 - t0, b = fabsl(a) * L;
    const long double hl = hs > 0 ? h0 + hs * t0 : h0 + hs * t1;
    const long double m = b < 1e-4L ? L * (1 - b / 2 + b * b / 6) : -expm1l(-b) / fabsl(a);
    return expl(-s->k * hl) * m;
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

/* Gauss with n nodes on each of the m cells in b, vectorised across cells:
 * per cell the corners' gradient terms are linear along the chord (value
 * at the entry A, rate B), and the nodes are summed in order. With env,
 * each node's value is weighted by the envelope e^-(kh0 + khs t) there
 * (t = the cell's entry tc plus the node's offset). */
EF_INLINE void batch_gauss(const nstate *s, const double d0[3], int n, int m, cell_batch *b,
                           int env, double kh0, double khs)
{
    const double *x = s->glx[n], *wt = s->glw[n];
    if (m < 8) {
        /* A few cells (a short ray's octave): too few for vector lanes,
         * whose scalar remainder would unpack the gradients bit by bit;
         * the table is what a scalar loop reads fastest. */
        for (int c = 0; c < m; ++c) {
            const double f0 = b->f[0][c], f1 = b->f[1][c], f2 = b->f[2][c];
#define EF_CORNER(k, fx, fy, fz)                                                              \
    do {                                                                                      \
        const double *g = grad_vec[b->g[k][c] & 15];                                          \
        b->A[k][c] = g[0] * (fx) + g[1] * (fy) + g[2] * (fz);                                 \
        b->B[k][c] = g[0] * d0[0] + g[1] * d0[1] + g[2] * d0[2];                              \
    } while (0)
            EF_CORNER(0, f0, f1, f2);
            EF_CORNER(1, f0 - 1, f1, f2);
            EF_CORNER(2, f0, f1 - 1, f2);
            EF_CORNER(3, f0 - 1, f1 - 1, f2);
            EF_CORNER(4, f0, f1, f2 - 1);
            EF_CORNER(5, f0 - 1, f1, f2 - 1);
            EF_CORNER(6, f0, f1 - 1, f2 - 1);
            EF_CORNER(7, f0 - 1, f1 - 1, f2 - 1);
#undef EF_CORNER
        }
    } else {
        for (int k = 0; k < 8; ++k) {
            const double ox = k & 1, oy = (k >> 1) & 1, oz = k >> 2;
            for (int c = 0; c < m; ++c) {
                const unsigned sh = 2 * (b->g[k][c] & 15);
                const double gx = (double) (int) ((GRAD_X1 >> sh) & 3) - 1,
                             gy = (double) (int) ((GRAD_Y1 >> sh) & 3) - 1,
                             gz = (double) (int) ((GRAD_Z1 >> sh) & 3) - 1;
                b->A[k][c] = gx * (b->f[0][c] - ox) + gy * (b->f[1][c] - oy) + gz * (b->f[2][c] - oz);
                b->B[k][c] = gx * d0[0] + gy * d0[1] + gz * d0[2];
            }
        }
    }
    for (int c = 0; c < m; ++c)
        b->sum[c] = 0;
    for (int j = 0; j < n; ++j) {
        const double xj = 1 + x[j], wj = wt[j];
        for (int c = 0; c < m; ++c) {
            const double o = b->hh[c] * xj;
            const double u = ef_noise_fade_(b->f[0][c] + o * d0[0]);
            const double v = ef_noise_fade_(b->f[1][c] + o * d0[1]);
            const double w = ef_noise_fade_(b->f[2][c] + o * d0[2]);
            const double g0 = b->A[0][c] + o * b->B[0][c], g1 = b->A[1][c] + o * b->B[1][c],
                         g2 = b->A[2][c] + o * b->B[2][c], g3 = b->A[3][c] + o * b->B[3][c],
                         g4 = b->A[4][c] + o * b->B[4][c], g5 = b->A[5][c] + o * b->B[5][c],
                         g6 = b->A[6][c] + o * b->B[6][c], g7 = b->A[7][c] + o * b->B[7][c];
            const double x0 = ef_noise_lerp_(v, ef_noise_lerp_(u, g0, g1),
                                             ef_noise_lerp_(u, g2, g3));
            const double x1 = ef_noise_lerp_(v, ef_noise_lerp_(u, g4, g5),
                                             ef_noise_lerp_(u, g6, g7));
            const double val = ef_noise_lerp_(w, x0, x1);
            b->sum[c] += env ? wj * ef_exp_neg(kh0 + khs * (b->tc[c] + o)) * val : wj * val;
        }
    }
}

/* Integrates the m cells of b (with env, weighted by the envelope) and
 * adds them to acc in walk order. */
EF_INLINE void batch_add(const nstate *s, const double d0[3], int n, int m, cell_batch *b,
                         ksum *acc, int env, double kh0, double khs)
{
    batch_gauss(s, d0, n, m, b, env, kh0, khs);
    for (int c = 0; c < m; ++c)
        kadd(acc, b->hh[c] * b->sum[c]);
}

/* batch_add for the long-double walk (exact), with its own vector clone. */
EF_MULTIVERSION static void batch_flush(const nstate *s, const double d0[3], int n, int m,
                                        cell_batch *b, ksum *acc)
{
    batch_add(s, d0, n, m, b, acc, 0, 0, 0);
}

/* integral of noise_i over [t0, t1] with n nodes per cell, walking the cells
 * in double with fractions carried from cell to cell (each axis restarts
 * at 0 or 1 where it crosses): the adaptive method's fast path, whose
 * rounding (~1e-16 per cell) is far below any tolerance it takes. The walk
 * collects CELL_BATCH cells at a time and integrates them side by side;
 * the cells are summed in order. */
EF_INLINE double octave_walk(rayc *R, int i, int n, double t0, double t1, int env)
{
    const nstate *s = R->s;
    double fr[3], d[3], next[3], step[3];
    int ic[3];
    for (int a = 0; a < 3; ++a) {
        const lin *u = &R->u[3 * i + a];
        d[a] = u->dd;
        const double v = u->bd + t0 * u->dd;
        double c = floor(v);
        if (d[a] < 0 && c == v)
            c -= 1;
        fr[a] = v - c;
        ic[a] = (int) (c - 256 * floor(c * (1.0 / 256)));
        step[a] = d[a] == 0 ? INFINITY : fabs(1 / d[a]);
        next[a] = d[a] > 0 ? t0 + (1 - fr[a]) * step[a] : d[a] < 0 ? t0 + fr[a] * step[a] : INFINITY;
    }
    int inc[3];
    double reset[3];
    for (int a = 0; a < 3; ++a) {
        inc[a] = d[a] > 0 ? 1 : 255;
        reset[a] = d[a] > 0 ? 0 : 1;
    }
    ksum acc = { 0, 0 };
    double t = t0;
    long cells = 0;
    cell_batch b;
    int more = t < t1;
    while (more) {
        int m = 0;
        while (m < CELL_BATCH) {
            const double n01 = next[1] < next[0] ? next[1] : next[0];
            const double nm = next[2] < n01 ? next[2] : n01;
            const double tb = nm < t1 ? nm : t1, h = tb - t;
            if (h > 0) {
                for (int a = 0; a < 3; ++a) {
                    b.ic[a][m] = ic[a];
                    b.f[a][m] = fr[a];
                }
                b.tc[m] = t;
                b.hh[m++] = h / 2;
                for (int a = 0; a < 3; ++a)
                    fr[a] += h * d[a];
            }
            if (tb >= t1) {
                more = 0;
                break;
            }
            /* Cross every axis whose face is here, without branches: which
             * axis comes next is what a processor cannot predict. */
            for (int a = 0; a < 3; ++a) {
                const int cross = next[a] <= tb;
                ic[a] = cross ? (ic[a] + inc[a]) & 255 : ic[a];
                fr[a] = cross ? reset[a] : fr[a];
                next[a] = cross ? next[a] + step[a] : next[a];
            }
            t = tb;
            if (!(t < t1)) {
                more = 0;
                break;
            }
        }
        /* The corners' hashes, cell by cell with no branch in between. */
        for (int c = 0; c < m; ++c) {
            ef_noise_cell nc;
            ef_noise_cell_at(b.ic[0][c], b.ic[1][c], b.ic[2][c], &nc);
            for (int k = 0; k < 8; ++k)
                b.g[k][c] = nc.h[k];
        }
        batch_add(s, d, n, m, &b, &acc, env, R->kh0, R->khs);
        cells += m;
    }
    R->cells += cells;
    R->evals += (double) cells * n;
    return kval(&acc);
}

/* octave_walk without an envelope (falloff 0). */
EF_MULTIVERSION static double octave_integral_fast(rayc *R, int i, int n, double t0, double t1)
{
    return octave_walk(R, i, n, t0, t1, 0);
}

/* integral of env * noise_i over [t0, t1] the same way, each node weighted
 * by the envelope (the adaptive method's segments under a falloff). */
EF_MULTIVERSION static double octave_integral_env(rayc *R, int i, int n, double t0, double t1)
{
    return octave_walk(R, i, n, t0, t1, 1);
}

/* ---- the grid: end-corrected composite midpoint along an octave ---- */

/* Octave noise at lattice point x and its derivative along d (d in lattice
 * units per unit t): Perlin's formula differentiated term by term (each
 * corner's gradient term is linear, the fades' derivative 30 t^2 (t-1)^2). */
static double noise_dval(const uint32_t *tab, const double x[3], const double d[3], double *dn)
{
    int C[3];
    double f[3], s[3], ds[3];
    for (int a = 0; a < 3; ++a) {
        /* x is near the ray's start or a segment's: an int64 holds its
         * floor */
        const double fl = floor(x[a]);
        f[a] = x[a] - fl;
        C[a] = (int) ((int64_t) fl & 255);
        s[a] = ef_noise_fade_(f[a]);
        ds[a] = 30 * f[a] * f[a] * (f[a] - 1) * (f[a] - 1) * d[a];
    }
    /* the corners' gradient numbers from the grid's tables (grid_hash) */
    const uint32_t *gp = tab + 65536, q = tab[C[0] << 8 | C[1]];
    const uint32_t c0 = gp[(q & 255) + C[2]], c1 = gp[(q >> 16 & 255) + C[2]],
                   c2 = gp[(q >> 8 & 255) + C[2]], c3 = gp[(q >> 24) + C[2]];
    const unsigned h[8] = { c0 & 15, c1 & 15, c2 & 15, c3 & 15, c0 >> 16, c1 >> 16, c2 >> 16, c3 >> 16 };
    double g[8], dg[8];
    for (int k = 0; k < 8; ++k) {
        const double *G = grad_vec[h[k]];
        g[k] = G[0] * (f[0] - (k & 1)) + G[1] * (f[1] - ((k >> 1) & 1)) + G[2] * (f[2] - (k >> 2));
        dg[k] = G[0] * d[0] + G[1] * d[1] + G[2] * d[2];
    }
    /* lerp(t, a, b) = a + t (b - a), differentiated in each argument */
    double v4[4], dv4[4];
    for (int k = 0; k < 4; ++k) {
        v4[k] = g[2 * k] + s[0] * (g[2 * k + 1] - g[2 * k]);
        dv4[k] = dg[2 * k] + ds[0] * (g[2 * k + 1] - g[2 * k]) + s[0] * (dg[2 * k + 1] - dg[2 * k]);
    }
    double v2[2], dv2[2];
    for (int k = 0; k < 2; ++k) {
        v2[k] = v4[2 * k] + s[1] * (v4[2 * k + 1] - v4[2 * k]);
        dv2[k] = dv4[2 * k] + ds[1] * (v4[2 * k + 1] - v4[2 * k]) +
                 s[1] * (dv4[2 * k + 1] - dv4[2 * k]);
    }
    *dn = dv2[0] + ds[2] * (v2[1] - v2[0]) + s[2] * (dv2[1] - dv2[0]);
    return v2[0] + s[2] * (v2[1] - v2[0]);
}

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
#define GRID_BATCH 64

/* One batch of grid nodes: fractions, cells and the corners' hashes. */
typedef struct grid_batch {
    float f[3][GRID_BATCH];          /* fractions in the cell */
    int ic[3][GRID_BATCH];
    unsigned g[GRID_BATCH];          /* the corners' gradient numbers, packed */
    float v[GRID_BATCH];
} grid_batch;

/* Perlin's permutation twice over (his reference's p[512]), and its
 * gradient numbers (& 15): the grid's hashes need no index masks. */
#define EF_PERM_ID(v) v,
#define EF_PERM_GRAD(v) ((v) & 15),
static const unsigned char perm2[512] = { EF_NOISE_PERM(EF_PERM_ID) EF_NOISE_PERM(EF_PERM_ID) };
static const unsigned char grad2[512] = { EF_NOISE_PERM(EF_PERM_GRAD) EF_NOISE_PERM(EF_PERM_GRAD) };
#undef EF_PERM_ID
#undef EF_PERM_GRAD

/* Fills the grid's hash tables: t[256 x + y] packs Perlin's four
 * second-level hashes of column (x, y), p[p[x] + y], p[p[x] + y + 1],
 * p[p[x + 1] + y], p[p[x + 1] + y + 1], a byte each; t[65536 + i] holds
 * the gradient numbers of i and i + 1 in its two halves. One word and four
 * pair reads then give a node's eight corners, where the permutation alone
 * takes fourteen reads (the same numbers: ef_noise_cell_at's). */
static void grid_tables(uint32_t *t)
{
    const unsigned char *p = perm2, *g = grad2;
    for (int x = 0; x < 256; ++x)
        for (int y = 0; y < 256; ++y) {
            const int A = p[x] + y, B = p[x + 1] + y;
            t[256 * x + y] = (uint32_t) p[A] | (uint32_t) p[A + 1] << 8 |
                             (uint32_t) p[B] << 16 | (uint32_t) p[B + 1] << 24;
        }
    for (int i = 0; i < 512; ++i)
        t[65536 + i] = (uint32_t) g[i] | (uint32_t) (i + 1 < 512 ? g[i + 1] : 0) << 16;
}

/* A component's grid hash tables (the state heads its arr). */
static inline const uint32_t *grid_hash_table(const nstate *s)
{
    return (const uint32_t *) (const void *) ((const double *) (const void *) s + s->hash_off);
}

/* The corners' gradient numbers (hash & 15) of m nodes, packed 4 bits
 * per corner (corner k at bits 4k), from grid_tables' t. Scalar on
 * purpose: GCC turns the table reads into vector gathers, slower here
 * than plain loads. */
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((optimize("no-tree-vectorize")))
#endif
static void grid_hash(const uint32_t *t, grid_batch *b, int m)
{
    const uint32_t *gp = t + 65536;
    for (int c = 0; c < m; ++c) {
        const int z = b->ic[2][c];
        const uint32_t q = t[b->ic[0][c] << 8 | b->ic[1][c]];
        b->g[c] = gp[(q & 255) + z] | gp[(q >> 16 & 255) + z] << 4 | gp[(q >> 8 & 255) + z] << 8 |
                  gp[(q >> 24) + z] << 12;
    }
}

/* The end term's noise and derivative at one end of an octave's segment,
 * kept from the previous segment (which ended where this one starts). */
typedef struct grid_end {
    double t, n, dn, e;              /* e: the envelope there */
    int valid;
} grid_end;

/* env * d/dt noise_i at t, e being the envelope e^-(kh0 + khs t) there
 * (used when env). */
static double grid_fprime(const rayc *R, int i, double t, int env, double e, grid_end *cache)
{
    double n, dn;
    if (cache && cache->valid && cache->t == t) {
        n = cache->n;
        dn = cache->dn;
    } else if (t == 0 && R->cam) {
        /* at the camera: its noise and gradient, bound once per frame */
        const lin *u = &R->u[3 * i];
        const double *g = R->s->cam_g[i];
        n = R->s->cam_n[i];
        dn = g[0] * u[0].dd + g[1] * u[1].dd + g[2] * u[2].dd;
    } else {
        double x[3], d[3];
        for (int a = 0; a < 3; ++a) {
            const lin *u = &R->u[3 * i + a];
            x[a] = u->bd + t * u->dd;
            d[a] = u->dd;
        }
        n = noise_dval(grid_hash_table(R->s), x, d, &dn);
        if (cache)
            *cache = (grid_end) { t, n, dn, e, 1 };
    }
    return env ? e * (dn - R->khs * n) : dn;
}

/* integral of env * noise_i over [t0, t1] by the composite midpoint rule
 * with ceil(nu * lattice length) nodes and the Euler-Maclaurin end term
 * h^2/24 (f'(t1) - f'(t0)): no lattice walk, each node on its own (the
 * error, calibrated by bench/grid_calibrate.c on this code, is an
 * estimate). end: the octave's last end term (the previous segment's t1,
 * reused at t0; t1's replaces it), or NULL. */
EF_INLINE double grid_walk(rayc *R, int i, double nu, double t0, double t1, int env,
                           grid_end *end)
{
    const lin *u = &R->u[3 * i];
    double d[3], b[3], sp = 0;
    for (int a = 0; a < 3; ++a) {
        d[a] = u[a].dd;
        sp += d[a] * d[a];
        /* the start reduced modulo the period, so every node's cell index
         * fits an int */
        const double v = u[a].bd + t0 * d[a];
        b[a] = v - 256 * floor(v * (1.0 / 256));
    }
    const double L = t1 - t0;
    const long n = (long) ceil(sqrt(sp) * L * nu) > 0 ? (long) ceil(sqrt(sp) * L * nu) : 1;
    const double h = L / (double) n;
    const double khs = R->khs;
    /* the envelope at t0 (kept from the previous segment where it ended
     * here), at t1, and at the nodes: e0 rh r^j, rh = e^-(khs h / 2) */
    double e0 = 1, e1 = 1, rh = 1;
    /* where the envelope spans more than e^500 over the segment, products
     * of its values could meet 0 times inf: each node's own then */
    const int direct = env && !(fabs(khs * L) < 500);
    if (env) {
        e0 = end && end->valid && end->t == t0 ? end->e : ef_exp_neg(R->kh0 + khs * t0);
        e1 = ef_exp_neg(R->kh0 + khs * t1);
        rh = ef_exp_neg(khs * h / 2);
    }
    ksum acc = { 0, 0 };
    grid_batch gb;
    double pw[GRID_BATCH], wv[GRID_BATCH], eb = e0 * rh;
    for (long j0 = 0; j0 < n; j0 += GRID_BATCH) {
        const int m = n - j0 < GRID_BATCH ? (int) (n - j0) : GRID_BATCH;
        /* whole vectors of 8 (the nodes past m lie on the same line, their
         * values unused): no scalar tails, which cost more than the nodes
         * on the short rays of a near frame */
        const int mv = (m + 7) & ~7;
        const double o0 = ((double) j0 + 0.5) * h;
        /* plain loops over the batch's arrays, which GCC vectorises */
        for (int c8 = 0; c8 < mv; c8 += 8)
            for (int c = c8; c < c8 + 8; ++c) {
                const double o = o0 + c * h;
                const double x = b[0] + o * d[0], y = b[1] + o * d[1], z = b[2] + o * d[2];
                const double cx = floor(x), cy = floor(y), cz = floor(z);
                gb.f[0][c] = (float) (x - cx);
                gb.f[1][c] = (float) (y - cy);
                gb.f[2][c] = (float) (z - cz);
                gb.ic[0][c] = (int) cx & 255;
                gb.ic[1][c] = (int) cy & 255;
                gb.ic[2][c] = (int) cz & 255;
            }
        grid_hash(grid_hash_table(R->s), &gb, mv);
        /* in single precision, 8 nodes to a vector (IEEE operations in a
         * fixed order: the same bits with or without the vector unit) */
        for (int c8 = 0; c8 < mv; c8 += 8)
            for (int c = c8; c < c8 + 8; ++c) {
                const float fx = gb.f[0][c], fy = gb.f[1][c], fz = gb.f[2][c];
                float g[8];
                for (int k = 0; k < 8; ++k) {
                    const unsigned sh = 2 * ((gb.g[c] >> 4 * k) & 15);
                    const float gx = (float) (int) ((GRAD_X1 >> sh) & 3) - 1,
                                gy = (float) (int) ((GRAD_Y1 >> sh) & 3) - 1,
                                gz = (float) (int) ((GRAD_Z1 >> sh) & 3) - 1;
                    g[k] = gx * (fx - (float) (k & 1)) + gy * (fy - (float) ((k >> 1) & 1)) +
                           gz * (fz - (float) (k >> 2));
                }
                const float uu = fx * fx * fx * (fx * (fx * 6 - 15) + 10),
                            vv = fy * fy * fy * (fy * (fy * 6 - 15) + 10),
                            ww = fz * fz * fz * (fz * (fz * 6 - 15) + 10);
                const float a0 = g[0] + uu * (g[1] - g[0]), a1 = g[2] + uu * (g[3] - g[2]),
                            a2 = g[4] + uu * (g[5] - g[4]), a3 = g[6] + uu * (g[7] - g[6]);
                const float x0 = a0 + vv * (a1 - a0), x1 = a2 + vv * (a3 - a2);
                gb.v[c] = x0 + ww * (x1 - x0);
            }
        double sum = 0;
        if (env) {
            /* r^c in doublings (each within c ulps: far below any
             * tolerance taken here) */
            if (j0 == 0) {
                pw[0] = 1;
                double rr = rh * rh;
                for (int w = 1; w < m; w *= 2) {
                    for (int c = 0; c < w && w + c < GRID_BATCH; ++c)
                        pw[w + c] = pw[c] * rr;
                    rr *= rr;
                }
            }
            if (direct) {
                for (int c = 0; c < m; ++c)
                    wv[c] = (double) gb.v[c] * ef_exp_neg(R->kh0 + khs * (t0 + o0 + c * h));
                for (int c = 0; c < m; ++c)
                    sum += wv[c];
            } else {
                for (int c = 0; c < m; ++c)
                    wv[c] = (double) gb.v[c] * pw[c];
                for (int c = 0; c < m; ++c)
                    sum += wv[c];
                sum *= eb;
                eb *= pw[GRID_BATCH - 1] * (rh * rh);
            }
        } else {
            for (int c = 0; c < m; ++c)
                sum += gb.v[c];
        }
        kadd(&acc, sum);
    }
    R->evals += (double) n;
    const double fa = grid_fprime(R, i, t0, env, e0, end);
    const double fb = grid_fprime(R, i, t1, env, e1, end);
    return h * kval(&acc) + h * h / 24 * (fb - fa);
}

EF_MULTIVERSION static double octave_grid_env(rayc *R, int i, double nu, double t0, double t1,
                                              grid_end *end)
{
    return grid_walk(R, i, nu, t0, t1, 1, end);
}

EF_MULTIVERSION static double octave_grid_flat(rayc *R, int i, double nu, double t0, double t1,
                                               grid_end *end)
{
    return grid_walk(R, i, nu, t0, t1, 0, end);
}

/* The grid over [t0, t1] given in long double (the general path's
 * chunks), with or without the envelope. */
static double octave_grid_any(rayc *R, int i, double nu, long double t0, long double t1,
                              grid_end *end)
{
    return R->s->k > 0 ? octave_grid_env(R, i, nu, (double) t0, (double) t1, end)
                       : octave_grid_flat(R, i, nu, (double) t0, (double) t1, end);
}

/* integral of env * noise_i over [t0, t1]: n Gauss nodes per cell, or with
 * n == 0 the certified pair (9 and 13 nodes, bisected to tol relative to
 * the cell's envelope bound). *err collects the certified pair's residue.
 * The walk is in long double (exact needs each cell's fractions to full
 * precision wherever the camera is); without an envelope the cells go
 * through the adaptive path's batches, from fractions formed here. */
static double octave_integral(rayc *R, int i, int n, long double t0, long double t1,
                              double *err)
{
    const nstate *s = R->s;
    /* The double walk takes the envelope as e^-(kh0 + khs t): not where
     * those overflow (a falloff near DBL_MAX), which the walk in long
     * double below handles. */
    if (n > 0 && s->method == M_ADAPTIVE && (s->k == 0 || (isfinite(R->kh0) && isfinite(R->khs))))
        return s->k == 0 ? octave_integral_fast(R, i, n, (double) t0, (double) t1)
                         : octave_integral_env(R, i, n, (double) t0, (double) t1);
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
                    batch_flush(s, d0, n, m, &b, &acc);
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
        batch_flush(s, d0, n, m, &b, &acc);
    return kval(&acc);
}

/* ---- the full density, piece by piece over every octave's cells ---- */

static double full_density(rayc *R, const void *ctx, long double t)
{
    (void) ctx;
    const double v = shape_at(R, t);
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

/* The bound of shape (max(0, 1 + c fbm), or a product of naxes of them). */
static double shape_bound(const nstate *s)
{
    return s->bound;
}

static double march(rayc *R, long double t0, long double t1, int n);
static double march_bound(const rayc *R, long double t0, long double t1, int n, double unit);

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
static double full_integral(rayc *R, int lo, int hi, long double t0, long double t1,
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
            const double v = march(R, ta, t1, FULL_MARCH);
            kadd(&acc, v);
            *err += march_bound(R, ta, t1, FULL_MARCH, v);
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
static inline double line_est(const nstate *s, int i, double L, double sigmas)
{
    return fmin(EF_NOISE_BOUND * L, sigmas * LINE_RMS * sqrt(L * (s->scale / s->fbm.freq[i])));
}
/* Cells of one octave that exact and adaptive walk along one ray, at most
 * (documented: a scale far below the ray's length is integrated
 * statistically beyond it, so the work per pixel stays bounded). */
#define CELL_BUDGET 65536
/* The same where the density is not linear in the noise (clamp, separable). */
#define CELL_BUDGET_FULL 8192
/* Steps of the midpoint march that replaces a walk past the budget where
 * the density is not linear in the noise (clamp, separable). */
#define MARCH_FALLBACK 4096

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

typedef struct plan {
    int q[EF_FBM_MAX_OCTAVES];       /* 0: dropped; else kept (Gauss nodes per cell if walked) */
    double nu[EF_FBM_MAX_OCTAVES];   /* > 0: integrated on the grid, nodes per lattice unit */
    double est;                      /* the error estimate, in tau of the densest channel */
    int dropped;
} plan;

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
static double plan_evals(const rayc *R, const plan *P, int i, double L)
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
typedef struct ladder {
    int n, kind[PLAN_OPTS];
    double cost[PLAN_OPTS], err[PLAN_OPTS];
    double slope2[PLAN_OPTS];        /* (err[k]^2 - err[k+1]^2) / (cost[k+1] - cost[k]) */
} ladder;

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

static size_t ladders_words(void)
{
    return (LADDER_BINS + 1) * LADDER_WORDS;
}

static void ladders_fill(double *at)
{
    for (int j = 0; j <= LADDER_BINS; ++j)
        ladder_unit(1 + KAPPA_SPAN * j / LADDER_BINS, (ladder *) (void *) (at + j * LADDER_WORDS));
}

/* The per-ray half of adaptive_linear's planner. */
typedef struct seg_planner {
    const ladder *ld;
    double sp[EF_FBM_MAX_OCTAVES];     /* octave i's lattice units per unit t */
    double isp[EF_FBM_MAX_OCTAVES];    /* 1 / sqrt(sp_i) */
    double lrms[EF_FBM_MAX_OCTAVES];   /* 3 LINE_RMS sqrt(lambda_i): the drop rule */
} seg_planner;

/* Fills SP for ray R; 0 where the grid cannot serve it (no direction). */
static int seg_planner_init(const rayc *R, seg_planner *SP)
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
static void plan_segment(const rayc *R, const seg_planner *SP, double L, double emean,
                         double emsq, double tol, plan *P)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double A = s->rho_max * fabs(s->contrast), erms = sqrt(emsq), sqL = sqrt(L);
    const double tol2 = tol * tol;
    double drop2 = 0, quad2 = 0;
    int kept = N;
    P->dropped = 0;
    for (int i = N - 1; i >= 0; --i) {
        const double D =
            A * s->fbm.weight[i] * fmin(EF_NOISE_BOUND * emean * L, SP->lrms[i] * erms * sqL);
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
        sc[i] = A * erms * s->fbm.weight[i] * sqrt(Le) * SP->isp[i];
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
static void plan_octaves(const rayc *R, double L, double envmax, double tol, plan *P)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double A = s->rho_max * fabs(s->contrast) * envmax;
    double drop = 0, quad = 0;
    int kept = N;
    P->dropped = 0;
    for (int i = N - 1; i >= 1; --i) {
        const double D = A * s->fbm.weight[i] * line_est(s, i, L, 3);
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
static double rest_estimate(const nstate *s, int only, double L)
{
    double r = 0;
    for (int i = 0; i < s->fbm.octaves; ++i)
        if (i != only)
            r += s->fbm.weight[i] * line_est(s, i, L, 4);
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
static double ttol_budget(const rayc *R, long double t0, long double t1, double L, double envmax,
                          int linear)
{
    const nstate *s = R->s;
    const double m = (double) env_integral(s, R->h0, R->hs, t0, t1);
    double lo;
    if (linear) {
        lo = m - fabs(s->contrast) * envmax * rest_estimate(s, -1, L);
    } else {
        const double lo1 = 1 - fabs(s->contrast) * EF_NOISE_BOUND;
        lo = lo1 > 0 ? pow(lo1, s->separable ? s->naxes : 1) * m : 0;
    }
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
        sum += s->glw[5][j] * factor_octave_ld(s, a, i, mid + half * s->glx[5][j]);
    return (double) half * sum;
}

/* The prefix tables: entry m of octave (a, i) is the integral of the
 * factor's octave over [0, m] of its own coordinate, m = 0..256; the
 * noise's period 256 gives every other prefix. */
static void build_tables(nstate *s, double *tab)
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
            f += s->fbm.weight[i] * factor_octave(s, a, i, (double) u0);
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
static void cell_poly(const nstate *s, int a, int i, long m, long double p[7])
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

/* Builds factor a's merged table over s in [0, 256): pieces between every
 * octave's cell faces, each with the polynomial (in s - start) of
 * sum_i w_i noise_i and the prefix integral at its start. Returns the
 * number of pieces. */
static int build_merged(const nstate *s, int a, double *tab, int cap, double *total)
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
                cell_poly(s, a, i, m, ql);
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
static double preintegrated_merged(const ef_fog_component *c, const nstate *s, const ef_ray *r,
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

/* Looks up everything about the camera at org that every ray of the frame
 * repeats: its point in each merged table and its envelope height's
 * exponential. Rays from elsewhere miss the cache and compute their own;
 * a hit returns the values a lookup would (the span's lanes, serving a far
 * end inside the camera's own piece from that piece's polynomial, may
 * round the last bit differently from the general path there). */
static void bind_noise(ef_fog_component *c, const double org[3])
{
    nstate *s = (nstate *) (void *) c->arr;
    s->cam = s->cam_lines = 0;
    if (!s->merged) {
        for (int a = 0; a < 3; ++a) {
            long double q0, dq;
            q_line(s, org, (const double[3]) { 0, 0, 0 }, a, &q0, &dq);
            for (int i = 0; i < s->fbm.octaves; ++i)
                s->cam_b[a][i] = octave_line(s, i, q0, dq, a).b;
            s->cam_org[a] = org[a];
        }
        for (int i = 0; i < s->fbm.octaves; ++i) {
            const double x[3] = { (double) s->cam_b[0][i], (double) s->cam_b[1][i],
                                  (double) s->cam_b[2][i] };
            for (int a = 0; a < 3; ++a) {
                const double e[3] = { a == 0, a == 1, a == 2 };
                s->cam_n[i] = noise_dval(grid_hash_table(s), x, e, &s->cam_g[i][a]);
            }
        }
        s->cam_lines = 1;
        return;
    }
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
static double preintegrated(const ef_fog_component *c, rayc *R, long double t0, long double t1,
                            int K)
{
    const nstate *s = R->s;
    ksum acc = { 0, 0 };
    const long double h = (t1 - t0) / K;
    for (int p = 0; p < K; ++p) {
        const long double ta = t0 + p * h, tb = p + 1 == K ? t1 : t0 + (p + 1) * h;
        double v = (double) env_integral(s, R->h0, R->hs, ta, tb);
        for (int k = 0; k < s->naxes; ++k)
            v *= factor_mean(c, R, s->axis[k], ta, tb, &R->evals);
        kadd(&acc, v);
    }
    R->cells += (double) K * s->naxes * s->fbm.octaves;
    return kval(&acc);
}

/* ---- the midpoint ray-march ---- */

static double march(rayc *R, long double t0, long double t1, int n)
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

/* The error of march(R, t0, t1, n) = unit, bounded two ways, the smaller
 * taken. The midpoint rule's: each step's error is h^3/24 |f''| somewhere
 * in it, and |f''| <= env (D2 + 2 |a| D1 + a^2 B) (curvature_bound per unit
 * of envelope), whose largest value on a step is at most e^(|a| h) times
 * its mean there; so the sum is at most h^2/24 e^(|a| h) times that bound
 * times the envelope's integral, its closed form. The trivial one: both
 * unit and the true value lie in [0, B integral(env)]. Using the integral,
 * not the envelope's largest value times the length, keeps the bound near
 * tau on long rays through a thinning envelope. */
static double march_bound(const rayc *R, long double t0, long double t1, int n, double unit)
{
    const nstate *s = R->s;
    const double m = (double) env_integral(s, R->h0, R->hs, t0, t1);
    const double h = (double) (t1 - t0) / n, a = fabs(s->k * (double) R->hs);
    const double mid = h * h / 24 * exp(a * h) * curvature_bound(R, 1.0) * m;
    return fmin(mid, fmax(unit, shape_bound(s) * m));
}

/* ---- the component's tau ---- */

/* Where to stop on a ray whose envelope decays (k hs > 0): past T the
 * density's integral is at most B e^(-k h(T)) / (k hs) <= rel of the mean
 * part's from t0 (or, with abs > 0, at most abs in tau). */
static long double tail_end(const rayc *R, long double t0, double rel, double abs)
{
    const nstate *s = R->s;
    const long double a = s->k * R->hs, B = shape_bound(s);
    const long double e0 = env_at(R, t0);
    long double need;
    if (abs > 0)
        need = logl(s->rho_max * B * e0 / a / abs);
    else
        need = logl(B / rel);
    return t0 + (need > 0 ? need : 0) / a;
}

/* The optical depth past which the rest of a ray is not integrated: T is
 * then below e^-60 (1e-26), which no output format can show. */
#define OPAQUE_TAU 60.0
#define LN2 0.693147180559945309417

/* The smallest non-zero density of the three channels. */
static double rho_min(const nstate *s)
{
    double lo = INFINITY;
    for (int k = 0; k < 3; ++k)
        if (s->rho[k] > 0 && s->rho[k] < lo)
            lo = s->rho[k];
    return lo;
}

/* The t past t0 where the envelope's integral from t0 reaches need
 * (INFINITY if it never does). */
static long double env_reach(const rayc *R, long double t0, long double need)
{
    const nstate *s = R->s;
    const long double e0 = env_at(R, t0), a = s->k * R->hs;
    if (!(e0 > 0))
        return INFINITY;
    if (a == 0)
        return t0 + need / e0;
    if (a > 0) {
        const long double x = need * a / e0;
        return x < 1 ? t0 - log1pl(-x) / a : INFINITY;
    }
    return t0 + log1pl(need * -a / e0) / -a;
}

/* Moves *tend to where tau's lower bound rho_min (1 - |c| bound)^m times
 * the envelope's integral reaches OPAQUE_TAU, if that is sooner (not when
 * the clamp can bind: the density then has no lower bound). Returns 1 if
 * it cut. */
static int opaque_cut(const rayc *R, long double t0, long double *tend)
{
    const nstate *s = R->s;
    const double lo1 = 1 - fabs(s->contrast) * EF_NOISE_BOUND;
    if (!(lo1 > 0))
        return 0;
    const double rho_lo = rho_min(s);
    const long double need = OPAQUE_TAU / (rho_lo * pow(lo1, s->separable ? s->naxes : 1));
    const long double tc = env_reach(R, t0, need);
    if (!(tc < *tend))
        return 0;
    *tend = tc;
    return 1;
}

/* Whether the envelope e^(-k (h - base)) passes e^690 (about 1e300) on
 * [t0, t1] (far below base, or a base far above the scene): the fog is
 * opaque there, and its integral would overflow to inf - inf. The envelope
 * is monotone along a ray, so its largest value is at the lower end; the
 * test is on the exponent, no exp per ray. */
static int env_overflows(const nstate *s, double h0, double hs, double t0, double t1)
{
    if (!(s->k > 0))
        return 0;
    const double hlow = hs > 0 ? h0 + hs * t0 : hs < 0 ? h0 + hs * t1 : h0;
    return !(-s->k * hlow < 690);
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
        if (!clip_box(s, r, &lt0, &lt1))
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
    return env_overflows(s, *h0, *hs, *t0, *t1) ? 1 : 2;
}

#define ONE_SPAN EF_SPAN

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
EF_MULTIVERSION static void preint_span(const ef_fog_component *c, const nstate *s,
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

/* integral over [0, L] of e0 e^(-a t), a >= 0, L finite: e0 L where a L is
 * too small for expm1 to matter. */
static double decay_int(double e0, double a, double L)
{
    const double b = a * L;
    return e0 * (b < 1e-8 ? L : -expm1(-b) / a);
}

/* The preintegrated method's error output, a bound: the method's value u
 * and the true tau / rho both lie in [0, B integral(env)] (the density is
 * at most rho B env), so |u - tau / rho| <= max(u, B integral(env)) over
 * [t0, t1]. Loose, but never misleading: no cheap estimate was found that
 * covers 99 % (bench/preint_calibrate: the change when the pieces double,
 * even times 4 plus 5 % of the mean fog, covered 88 to 94 % of rays on
 * scenes other than the tests'). */
static double preint_bound(const nstate *s, double h0, double hs, double t0, double t1, double u)
{
    const double hl = hs > 0 ? h0 + hs * t0 : h0 + hs * t1;   /* the densest end */
    const double m = decay_int(exp(-s->k * hl), fabs(s->k * hs), t1 - t0);
    return fmax(u, shape_bound(s) * m);
}

/* The seed's evaluation from the merged tables, in plain double: per pixel
 * the cost of a few table lookups (the shared path's long double set-up
 * would cost more than the evaluation). The dropped sky tail's bound and,
 * when asked for, the difference to 2K pieces are the error estimate. */
static void preint_fast(const ef_fog_component *c, const nstate *s, const ef_ray *r,
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
        unit = preintegrated_merged(c, s, r, h0, hs, t0, t1, s->pieces);
    }
    double err = tail;
    if (info) {
        err += preint_bound(s, h0, hs, t0, t1, unit);
        info->evals = 1.0 * s->pieces * s->naxes;
        info->cells = (double) s->pieces * s->naxes;
    }
    for (int k = 0; k < 3; ++k) {
        tau[k] = s->rho[k] * (unit > 0 ? unit : 0);
        if (info)
            info->err[k] = s->rho[k] * err;
    }
}


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
        if (fmax(ym, fmax(ya, yb)) + dlt < -ef_clamp_ymax(tab, N, j) &&
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
                    iv += w * octave_integral_env(R, i, 9, J.a.t, J.b.t);
                    iv8 += w * octave_integral_env(R, i, 8, J.a.t, J.b.t);
                } else {
                    iv += w * octave_integral_fast(R, i, 9, J.a.t, J.b.t);
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
static double adaptive_linear(rayc *R, long double t0, long double tend, long double t1,
                              int opaque, double tail, ef_tau_info *info, double errk[3])
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    const double eps = s->ttol, rmin = rho_min(s);
    const double tau_stop = log(4 / eps);
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
    for (int i = N - 1; i >= 0; --i) {
        if (!(cross[i] * Lwalk <= CELL_BUDGET))
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
    const int grid = seg_planner_init(R, &SP);
    /* E2: the sum of the segments' squared estimates (independent errors
     * of segments that share no cell add in variance); var: what is left
     * of the budget's square, (3/4 eps)^2 (ttol/4 is the stop's). */
    double E2 = 0, var = 0.5625 * eps * eps, mean_sofar = 0;
    int stop = 0, dropped = 0;
    long double t = t0;
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
        /* lo: ulo plus the rest's lower value, its mean less four standard
         * deviations of its noise (noise_sigma4), or (1 - |c| B) times its
         * mean, whichever is larger. */
        const double lo_rest =
            fmax(rest - fabs(s->contrast) * noise_sigma4(R, fmax(e_t, e_tend),
                                                         (double) (tend - t), rest),
                 (1 - fabs(s->contrast) * EF_NOISE_BOUND) * rest);
        const double lo = ulo + (lo_rest > 0 ? lo_rest : 0);
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
            if (grid)
                plan_segment(R, &SP, L, mj / L,
                             decay_int(envmax * envmax, 2 * fabs(a_env), L) / L,
                             s->rho_max * qlin / W, &P);
            else
                plan_octaves(R, L, envmax, s->rho_max * qlin / W, &P);
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
                                      line_est(s, i, L, 3)
                                : 0;
                P.q[i] = 0;
            }
        /* The work bound: the finest kept octaves go first. */
        double need = 0;
        for (int i = 0; i < N; ++i)
            need += plan_evals(R, &P, i, L);
        for (int i = N - 1; i > 0 && R->evals + need > EVAL_BUDGET; --i)
            if (P.q[i]) {
                need -= plan_evals(R, &P, i, L);
                P.q[i] = 0;
                P.est += s->rho_max * fabs(s->contrast) * envmax * s->fbm.weight[i] *
                         line_est(s, i, L, 3);
                info->over = 1;
                P.dropped++;
            }
        if (P.dropped > dropped)
            dropped = P.dropped;

        for (int i = 0; i < N; ++i) {
            if (!P.q[i])
                continue;
            double v;
            if (P.nu[i] > 0)
                v = s->k > 0 ? octave_grid_env(R, i, P.nu[i], (double) t, (double) tb, &ends[i])
                             : octave_grid_flat(R, i, P.nu[i], (double) t, (double) tb, &ends[i]);
            else
                v = s->k > 0 ? octave_integral_env(R, i, P.q[i], (double) t, (double) tb)
                             : octave_integral_fast(R, i, P.q[i], (double) t, (double) tb);
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
    const double E = sqrt(E2);
    const double mean_to = (double) env_integral(s, R->h0, R->hs, t0, opaque ? t : t1);
    double unit = mean_to + s->contrast * kval(&noise) + kval(&corr);
    if (stop) {
        /* True T_k lies in [0, T_up] with T_up = e^-(rho_k ulo): the
         * estimate (the mean fog to the end) is within it, and the error
         * output reaches from it to T_up. The estimate is at most T_up / 2
         * in every channel (at least ln 2 above ulo in tau): the error
         * output, at least T itself, then spans [0, T_up] and no more.
         * Past 600 in tau above ulo, the estimate is held there: still
         * within, and T expm1(err) stays finite in double (T would
         * underflow, expm1 overflow). */
        const double ulo = mean_sofar + s->contrast * kval(&noise) + kval(&corr) - E;
        if (rmin * (unit - ulo) < LN2)
            unit = ulo + LN2 / rmin;
        if (s->rho_max * (unit - ulo) > 600)
            unit = ulo + 600 / s->rho_max;
        for (int k = 0; k < 3; ++k)
            errk[k] = s->rho[k] > 0 ? fmax(LN2, s->rho[k] * (unit - ulo)) : 0;
    } else if (opaque) {
        for (int k = 0; k < 3; ++k)
            errk[k] = s->rho[k] > 0 ? LN2 : 0;
    } else {
        for (int k = 0; k < 3; ++k)
            errk[k] = s->rho[k] * (E + corr_err + tail);
    }
    return unit;
}

/* tau along r with its error and cost; tol_over > 0 replaces the
 * adaptive method's tolerance on tau (tol= or ttol=) for this call. */
static void tau_noise_at(const ef_fog_component *c, const ef_ray *r, double tau[3],
                         ef_tau_info *info, double tol_over)
{
    const nstate *s = state(c);
    const double stol = tol_over > 0 ? tol_over : s->tol;
    ef_tau_info dummy;
    tau[0] = tau[1] = tau[2] = 0;
    if (s->method == M_PREINT && s->merged) {
        if (info)
            memset(info, 0, sizeof *info);
        preint_fast(c, s, r, tau, info);
        return;
    }
    if (!info)
        info = &dummy;
    memset(info, 0, sizeof *info);
    long double t0, t1;
    if (!(s->rho_max > 0) || !(r->dist > 0) || !clip_box(s, r, &t0, &t1) ||
        (c->cancel && atomic_load_explicit(c->cancel, memory_order_relaxed)))
        return;
    rayc R;
    ray_setup(s, r, &R);
    const int sky = isinf(t1);
    if (sky && !(s->k > 0 && R.hs > 0)) {
        /* Nothing lets the ray out of the fog: every channel with density
         * is opaque (the clamp's zeros cannot cover a whole infinite ray). */
        for (int k = 0; k < 3; ++k)
            tau[k] = s->rho[k] > 0 ? INFINITY : 0;
        return;
    }
    if (env_overflows(s, (double) R.h0, (double) R.hs, (double) t0, (double) t1)) {
        for (int k = 0; k < 3; ++k)
            tau[k] = s->rho[k] > 0 ? INFINITY : 0;
        return;
    }
    const int linear = !s->separable && !s->clamp;
    /* the clamped noise model on the adaptive fast path: its linear part
     * plus the clamp's share (clamp_part) */
    const int clamp_fast = !s->separable && s->clamp && s->method == M_ADAPTIVE && s->ttol > 0;
    double unit = 0, err = 0, tail = 0;  /* tau / rho, its error, the dropped tail's bound */
    long double tend = t1;
    if (sky) {
        if (s->method == M_ADAPTIVE)
            tend = tail_end(&R, t0, 0, stol / 8);
        else if (s->method == M_EXACT)
            tend = tail_end(&R, t0, 1e-16, 0);
        else
            tend = tail_end(&R, t0, 1e-6, 0);
        const long double a = s->k * R.hs, e_end = env_at(&R, tend);
        tail = (double) (shape_bound(s) * e_end / a);
        if (linear || clamp_fast)
            tail -= (double) (e_end / a);   /* the mean part is exact to infinity */
    }
    const int opaque = opaque_cut(&R, t0, &tend);
    /* The segment walk plans in double: not where k h0 or k hs overflow (a
     * falloff near DBL_MAX), which the general path below handles. */
    if ((linear || clamp_fast) && s->method == M_ADAPTIVE && s->ttol > 0 &&
        (s->k == 0 || (isfinite(R.kh0) && isfinite(R.khs)))) {
        double errk[3];
        unit = adaptive_linear(&R, t0, tend, t1, opaque, tail, info, errk);
        if (unit < 0)
            unit = 0;   /* rounding below an exactly zero density */
        for (int k = 0; k < 3; ++k) {
            tau[k] = s->rho[k] * unit;
            info->err[k] = errk[k];
        }
        info->evals = R.evals;
        info->cells = R.cells;
        return;
    }
    const double L = (double) (tend - t0);
    const double envmax = (double) fmaxl(env_at(&R, t0), env_at(&R, tend));
    double mean = 0;
    if (linear)
        mean = (double) env_integral(s, R.h0, R.hs, t0, opaque ? tend : t1);
    const double tol = s->ttol > 0 && s->method == M_ADAPTIVE && !(tol_over > 0)
                           ? ttol_budget(&R, t0, tend, L, envmax, linear) : stol;
    switch (s->method) {
    case M_EXACT:
    case M_ADAPTIVE: {
        /* Chunk by chunk when the fog may turn opaque on the way (its upper
         * bound passes OPAQUE_TAU): past tau >= OPAQUE_TAU, computed, the
         * rest cannot show. */
        plan P = { { 0 }, { 0 }, 0, 0 };
        seg_planner SP;
        grid_end ends[EF_FBM_MAX_OCTAVES];
        if (linear && s->method == M_ADAPTIVE) {
            /* the grid where its node indices stay small (as in
             * adaptive_linear; the walk alone otherwise) */
            if (isfinite(R.kh0) && isfinite(R.khs) && seg_planner_init(&R, &SP) &&
                SP.sp[s->fbm.octaves - 1] * L < 0x1p24)
                plan_segment(&R, &SP, L, envmax, envmax * envmax, tol, &P);
            else
                plan_octaves(&R, L, envmax, tol, &P);
            info->dropped = P.dropped;
            for (int i = 0; i < s->fbm.octaves; ++i)
                ends[i].valid = 0;
        }
        /* The work bound: an octave whose cells along this ray number more
         * than CELL_BUDGET (a scale far below the ray's length) is not
         * walked. Linear models: its integral counts as its mean, 0, with
         * three standard deviations of it as the error (an estimate, like
         * the adaptive drop rule). Otherwise: a midpoint march of
         * MARCH_FALLBACK steps with its bound as the error. */
        unsigned over = 0;
        double over_err = 0;
        const double cross = fabs(r->dir[0]) + fabs(r->dir[1]) + fabs(r->dir[2]);
        /* The clamped and separable densities are integrated piece by
         * piece between the faces of every octave (~300 evaluations per
         * finest cell), so their budget is smaller. */
        const double budget = linear ? CELL_BUDGET : CELL_BUDGET_FULL;
        for (int i = 0; i < s->fbm.octaves; ++i) {
            const double lambda = s->scale / s->fbm.freq[i];
            if (!(L * cross / lambda <= budget)) {
                over |= 1u << i;
                /* exact stays certified: the octave's hard bound over the
                 * envelope's integral; adaptive: the drop rule's estimate */
                over_err += fabs(s->contrast) * s->fbm.weight[i] *
                            (s->method == M_EXACT
                                 ? EF_NOISE_BOUND * (double) env_integral(s, R.h0, R.hs, t0, tend)
                                 : envmax * line_est(s, i, L, 3));
            }
        }
        if (over && !linear) {
            unit = march(&R, t0, tend, MARCH_FALLBACK);
            err = march_bound(&R, t0, tend, MARCH_FALLBACK, unit) + tail;
            info->dropped = __builtin_popcount(over);
            break;
        }
        if (over) {
            int n = 0;
            for (int i = 0; i < s->fbm.octaves; ++i) {
                if (over >> i & 1)
                    P.q[i] = 0;
                n += (over >> i & 1) || (s->method == M_ADAPTIVE && P.q[i] == 0);
            }
            info->dropped = n;
        }
        const long double per = OPAQUE_TAU / 2 / (s->rho_max * shape_bound(s));
        const int chunked = (double) env_integral(s, R.h0, R.hs, t0, tend) > (double) per * 2;
        /* A ray that may turn opaque, under adaptive: the coarsest kept
         * octave goes first, alone, chunk by chunk (in quarter chunks: it
         * is cheap), and where it, less the estimate of every other
         * octave's share over the stretch so far (rest_estimate: the drop
         * rule's, at 4 sigma), passes OPAQUE_TAU, the ray is cut with that
         * lower value as tau: the finer octaves, most of the cells, are
         * never walked there. If it does not pass, they follow over the
         * whole stretch. */
        int probe = -1;
        if (chunked && linear && s->method == M_ADAPTIVE)
            for (int i = 0; i < s->fbm.octaves && probe < 0; ++i)
                if (!(over >> i & 1) && P.q[i])
                    probe = i;
        ksum noise = { 0, 0 };
        double e = 0, rest = 0;
        long double ca = t0;
        int cut = 0;
        while (ca < tend) {
            long double cb = chunked ? env_reach(&R, ca, probe >= 0 ? per / 4 : per) : tend;
            if (!(cb < tend) || !(cb > ca))
                cb = tend;
            if (linear) {
                for (int i = 0; i < s->fbm.octaves; ++i) {
                    const int q = s->method == M_EXACT ? (s->k == 0 ? 9 : 0) : P.q[i];
                    if (over >> i & 1 || (probe >= 0 && i != probe))
                        continue;
                    if (s->method == M_ADAPTIVE && P.nu[i] > 0)
                        kadd(&noise, s->fbm.weight[i] *
                                         octave_grid_any(&R, i, P.nu[i], ca, cb, &ends[i]));
                    else if (q || s->method == M_EXACT)
                        kadd(&noise, s->fbm.weight[i] * octave_integral(&R, i, q, ca, cb, &e));
                }
            } else {
                kadd(&noise, s->method == M_EXACT
                                 ? full_integral(&R, s->separable ? 10 : 9, s->separable ? 14 : 13,
                                                 ca, cb, 0, &e)
                                 : full_integral(&R, 3, 6, ca, cb, tol / 2 / L / s->rho_max, &e));
            }
            ca = cb;
            if (probe >= 0)
                rest = fabs(s->contrast) * envmax * rest_estimate(s, probe, (double) (ca - t0));
            const double sofar = linear ? (double) env_integral(s, R.h0, R.hs, t0, ca) +
                                              s->contrast * kval(&noise) - rest
                                        : kval(&noise);
            if (ca < t1 && chunked && sofar * rho_min(s) >= OPAQUE_TAU) {
                cut = 1;
                break;
            }
        }
        if (probe >= 0 && !cut)
            for (int i = 0; i < s->fbm.octaves; ++i)
                if (i != probe && !(over >> i & 1) && P.q[i])
                    kadd(&noise, s->fbm.weight[i] *
                                     (P.nu[i] > 0
                                          ? octave_grid_any(&R, i, P.nu[i], t0, tend, &ends[i])
                                          : octave_integral(&R, i, P.q[i], t0, tend, &e)));
        if (cut) {
            tend = ca;
            mean = linear ? (double) env_integral(s, R.h0, R.hs, t0, ca) - rest : 0;
        }
        unit = linear ? mean + s->contrast * kval(&noise) : kval(&noise);
        if (s->method == M_EXACT)
            /* Rounding: the comparison with the reference saw up to 5.6e-14
             * relative over 10,000 segments; 1e-13 of tau covers it. */
            err = (linear ? fabs(s->contrast) * e : e) + 1e-13 * fabs(unit) + tail + over_err;
        else
            err = (linear ? P.est / s->rho_max : e) + tail + over_err;
        if (cut)
            err = -1;
        break;
    }
    case M_STEPS: {
        unit = march(&R, t0, tend, s->steps);
        err = march_bound(&R, t0, tend, s->steps, unit) + tail;
        break;
    }
    default: { /* M_PREINT */
        if (s->merged) {
            unit = preintegrated_merged(c, s, r, (double) R.h0, (double) R.hs, (double) t0,
                                        (double) tend, s->pieces);
            R.evals += 2.0 * s->pieces * s->naxes;
            R.cells += (double) s->pieces * s->naxes;
        } else {
            unit = preintegrated(c, &R, t0, tend, s->pieces);
        }
        /* The bound (preint_bound). */
        err = preint_bound(s, (double) R.h0, (double) R.hs, (double) t0, (double) tend, unit) +
              tail;
        break;
    }
    }
    if (unit < 0)
        unit = 0;   /* rounding below an exactly zero density */
    if (opaque)
        err = -1;   /* marks the cut: see below */
    for (int k = 0; k < 3; ++k) {
        tau[k] = s->rho[k] * unit;
        /* Past the cut the true T lies in [0, T]: |dT| <= T = T expm1(ln 2). */
        info->err[k] = err < 0 ? (s->rho[k] > 0 ? LN2 : 0) : s->rho[k] * err;
    }
    info->evals = R.evals;
    info->cells = R.cells;
}

static void tau_noise_info(const ef_fog_component *c, const ef_ray *r, double tau[3],
                           ef_tau_info *info)
{
    tau_noise_at(c, r, tau, info, 0);
}

/* The model's tau_tol: tau at an absolute tolerance of its own. */
static void tau_tol_noise(const ef_fog_component *c, const ef_ray *r, double tol, double tau[3],
                          ef_tau_info *info)
{
    tau_noise_at(c, r, tau, info, tol);
}

static void tau_noise(const ef_fog_component *c, const ef_ray *r, double tau[3])
{
    tau_noise_info(c, r, tau, NULL);
}

/* tau_noise over a span of rays, added to acc: the same bits, without a
 * call through the general entry per ray (the preintegrated method's
 * per-ray work is small enough for that to show). */
static void tau_add_noise(const ef_fog_component *c, const ef_ray *r, int n, double (*acc)[3])
{
    const nstate *s = state(c);
    if (s->method == M_PREINT && s->merged && s->pieces == 1) {
        for (int j = 0; j < n; j += ONE_SPAN)
            preint_span(c, s, r + j, n - j < ONE_SPAN ? n - j : ONE_SPAN, acc + j);
        return;
    }
    const int fast = s->method == M_PREINT && s->merged;
    for (int j = 0; j < n; ++j) {
        double t[3] = { 0, 0, 0 };
        if (fast)
            preint_fast(c, s, &r[j], t, NULL);
        else
            tau_noise_info(c, &r[j], t, NULL);
        for (int k = 0; k < 3; ++k)
            acc[j][k] += t[k];
    }
}

/* ---- what the reference integrator sees: the density alone ---- */

/* Functionals: world x, y, z, and the height above base. */
static int functionals_noise(const ef_fog_component *c, ef_fog_functional *out, int cap)
{
    const nstate *s = state(c);
    const ef_fog_functional f[4] = { { { 1, 0, 0 }, 0 }, { { 0, 1, 0 }, 0 }, { { 0, 0, 1 }, 0 },
                                     { { s->up[0], s->up[1], s->up[2] }, -s->base } };
    for (int i = 0; i < 4 && i < cap; ++i)
        out[i] = f[i];
    return 4;
}

/* The box's faces (jumps) and the envelope's scale 1/k around the base. */
static int features_noise(const ef_fog_component *c, ef_fog_feature *out, int cap)
{
    const nstate *s = state(c);
    ef_fog_feature f[7];
    int n = 0;
    for (int a = 0; s->has_box && a < 3; ++a) {
        f[n++] = (ef_fog_feature) { a, s->bmin[a], 0 };
        f[n++] = (ef_fog_feature) { a, s->bmax[a], 0 };
    }
    if (s->k > 0)
        f[n++] = (ef_fog_feature) { 3, 0, 1 / s->k };
    for (int i = 0; i < n && i < cap; ++i)
        out[i] = f[i];
    return n;
}

/* Octave i's cell faces on axis a: l^i q_a + i O_a integer, i.e. world
 * p_a = phase + k scale / l^i. */
static int lattices_noise(const ef_fog_component *c, ef_fog_lattice *out, int cap)
{
    const nstate *s = state(c);
    int n = 0;
    for (int a = 0; a < 3; ++a) {
        if (s->separable) {
            int used = 0;
            for (int k = 0; k < s->naxes; ++k)
                used |= s->axis[k] == a;
            if (!used)
                continue;
        }
        for (int i = 0; i < s->fbm.octaves; ++i) {
            const double f = s->fbm.freq[i];
            if (n < cap)
                out[n] = (ef_fog_lattice) {
                    a,
                    (-(double) i * ef_fbm_offset[a] / f - s->seed * ef_noise_seed_dir[a]) *
                            s->scale + s->offset[a] + s->velocity[a] * s->time,
                    s->scale / f
                };
            n++;
        }
    }
    return n;
}

/* sigma from the definition, with q formed in long double from the world
 * point (so the reference and the integrators see the same field). At
 * infinity (the reference's divergence test): 0 where the box or the
 * envelope ends the fog, else the mean density. */
/* The noise's unclamped factors at a point given by the functional
 * values v (finite): 1 + c fbm, or per separable axis 1 + c fbm_a, into x;
 * returns how many. */
static int shape_factors(const nstate *s, const long double *v, long double x[3])
{
    const int N = s->fbm.octaves;
    long double q[3];
    for (int a = 0; a < 3; ++a)
        q[a] = ((v[a] - s->offset[a]) - (long double) s->velocity[a] * s->time) / s->scale +
               (long double) s->seed * ef_noise_seed_dir[a];
    if (!s->separable) {
        double f = 0;
        for (int i = 0; i < N; ++i) {
            int64_t X[3];
            double fr[3];
            for (int a = 0; a < 3; ++a)
                split_ld(s->fbm.freq[i] * q[a] + (long double) i * ef_fbm_offset[a], &X[a],
                         &fr[a]);
            ef_noise_cell nc;
            ef_noise_cell_at(X[0], X[1], X[2], &nc);
            f += s->fbm.weight[i] * ef_noise_cell_eval(&nc, fr[0], fr[1], fr[2]);
        }
        x[0] = 1 + (long double) s->contrast * f;
        return 1;
    }
    for (int k = 0; k < s->naxes; ++k) {
        const int a = s->axis[k];
        double f = 0;
        for (int i = 0; i < N; ++i)
            f += s->fbm.weight[i] *
                 factor_octave_ld(s, a, i, s->fbm.freq[i] * q[a] +
                                               (long double) i * ef_fbm_offset[a]);
        x[k] = 1 + (long double) s->contrast * f;
    }
    return s->naxes;
}

static void density_noise(const ef_fog_component *c, const long double *v, long double out[3])
{
    const nstate *s = state(c);
    out[0] = out[1] = out[2] = 0;
    if (s->has_box)
        for (int a = 0; a < 3; ++a)
            if (!(v[a] >= s->bmin[a] && v[a] <= s->bmax[a]))
                return;
    long double env = 1;
    if (s->k > 0) {
        if (isinf(v[3]))
            env = v[3] > 0 ? 0 : INFINITY;
        else
            env = expl(-s->k * v[3]);
    }
    if (env == 0)
        return;
    long double shape = 1;
    if (isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2])) {
        long double x[3];
        const int n = shape_factors(s, v, x);
        for (int k = 0; k < n; ++k)
            shape *= x[k] > 0 ? x[k] : 0;
    }
    for (int k = 0; k < 3; ++k)
        out[k] = s->rho[k] == 0 ? 0 : s->rho[k] * env * shape;
}

/* The clamp's kinks for the reference: the product of the unclamped
 * factors changes sign where one of them crosses 0. */
static int kink_noise(const ef_fog_component *c, const long double *v, long double *g)
{
    const nstate *s = state(c);
    if (!s->clamp)
        return 0;
    long double x[3], p = 1;
    if (!isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2])) {
        *g = 1;
        return 1;
    }
    const int n = shape_factors(s, v, x);
    for (int k = 0; k < n; ++k)
        p *= x[k];
    *g = p;
    return 1;
}

/* method=exact's evaluations along r, predicted from the part of r it
 * walks (to the box, the opaque cut or, on a sky ray, where the envelope's
 * tail drops below 1e-16 of the bound): per octave its cells times 9
 * Gauss nodes (13 under an envelope, whose cells take the bisected pair),
 * an octave past the cell budget at the budget's fallback instead. The
 * clamped and separable densities cost more per cell (their pieces); the
 * estimate leaves that out, so it errs low. */
static double work_noise(const ef_fog_component *c, const ef_ray *r)
{
    const nstate *s = state(c);
    long double t0, t1;
    if (s->method != M_EXACT || !(s->rho_max > 0) || !(r->dist > 0) || !clip_box(s, r, &t0, &t1))
        return 0;
    rayc R;
    ray_setup(s, r, &R);
    long double tend = t1;
    if (isinf(t1)) {
        if (!(s->k > 0 && R.hs > 0))
            return 0;   /* opaque: nothing is walked */
        tend = tail_end(&R, t0, 1e-16, 0);
    }
    if (env_overflows(s, (double) R.h0, (double) R.hs, (double) t0, (double) t1))
        return 0;
    opaque_cut(&R, t0, &tend);
    const double L = (double) (tend - t0), nodes = s->k > 0 ? 13 : 9;
    const double cross = fabs(r->dir[0]) + fabs(r->dir[1]) + fabs(r->dir[2]);
    const int linear = !s->separable && !s->clamp;
    double evals = 0;
    for (int i = 0; i < s->fbm.octaves; ++i) {
        const double cells = L * cross * s->fbm.freq[i] / s->scale;
        evals += cells <= (linear ? CELL_BUDGET : CELL_BUDGET_FULL)
                     ? (cells + 1) * nodes
                     : (linear ? 0 : MARCH_FALLBACK);
    }
    return evals;
}

/* A bound on |d sigma/dt| along r over [0, r->dist] (inside the box; the
 * box's faces are jumps, which the caller splits at): sigma = rho env S,
 * S the shape (noise: max(0, 1 + c fbm); separable: the product over m
 * axes of such factors), so |sigma'| <= rho_max (|env'| B_S + env |S'|)
 * with |env'| = k |hs| env, B_S the shape's bound, and |S'| at most
 * |c| sum_i w_i l^i L / scale per factor (L: the noise's Lipschitz
 * constant per lattice unit; the clamp only lowers it), times
 * m (1 + |c| B)^(m - 1) for a product; env at its largest on the segment. */
static double dsigma_noise(const ef_fog_component *c, const ef_ray *r)
{
    const nstate *s = state(c);
    long double t0, t1;
    if (!(s->rho_max > 0) || !(r->dist > 0) || !clip_box(s, r, &t0, &t1))
        return 0;
    double h0 = -s->base, hs = 0;
    for (int a = 0; a < 3; ++a) {
        h0 += s->up[a] * r->org[a];
        hs += s->up[a] * r->dir[a];
    }
    const double hlo = fmin(h0 + hs * (double) t0, h0 + hs * (double) t1);
    const double env = s->k > 0 ? exp(-s->k * hlo) : 1;
    double rate = 0;
    for (int i = 0; i < s->fbm.octaves; ++i)
        rate += s->fbm.weight[i] * s->fbm.freq[i];
    rate *= fabs(s->contrast) * EF_NOISE_LIPSCHITZ / s->scale;
    if (s->separable && s->naxes > 1)
        rate *= s->naxes * pow(1 + fabs(s->contrast) * EF_NOISE_BOUND, s->naxes - 1);
    const double d = s->rho_max * env * (s->k * fabs(hs) * shape_bound(s) + rate);
    return d == d ? d : INFINITY;
}

/* The relative accuracy of lit fog through this noise: the adaptive
 * method's tol (its tau's error, i.e. T's relative one), 1e-8 for exact
 * (its tau is exact; lit fog's quadrature still converges only so fast),
 * the default tol for the approximations (steps, preintegrated), whose own
 * error the error AOV reports beside it. */
static double lit_tol_noise(const ef_fog_component *c)
{
    const nstate *s = state(c);
    return s->method == M_ADAPTIVE ? s->tol : s->method == M_EXACT ? 1e-8 : DEFAULT_TOL;
}

const ef_fog_model ef_fog_noise = {
    .name = "noise", .keys = noise_keys, .set = set_noise, .finish = finish_noise,
    .tau = tau_noise, .functionals = functionals_noise, .features = features_noise,
    .dsigma_max = dsigma_noise,
    .density = density_noise, .kink = kink_noise, .tau_info = tau_noise_info,
    .lattices = lattices_noise,
    .tau_add = tau_add_noise, .bind = bind_noise, .work = work_noise, .lit_tol = lit_tol_noise,
    .tau_tol = tau_tol_noise, .uses_up = 1
};

const ef_fog_model ef_fog_noise_separable = {
    .name = "noise-separable", .keys = separable_keys, .set = set_noise, .finish = finish_noise,
    .tau = tau_noise, .functionals = functionals_noise, .features = features_noise,
    .dsigma_max = dsigma_noise,
    .density = density_noise, .kink = kink_noise, .tau_info = tau_noise_info,
    .lattices = lattices_noise,
    .tau_add = tau_add_noise, .bind = bind_noise, .work = work_noise, .lit_tol = lit_tol_noise,
    .tau_tol = tau_tol_noise, .uses_up = 1
};
