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
 *             their hard bound) fits, every pixel's error estimate reported;
 *             noise-separable where the clamp cannot bind has its own walk
 *             (noise_sep.c: exact per piece, factor octaves dropped by
 *             their period's statistics).
 *   steps     the uniform midpoint ray-march of game engines (steps=N).
 *   preintegrated  (noise-separable) the seed's evaluation: per-axis prefix
 *             integrals and the product of the factors' means over K pieces.
 * Where the clamp cannot bind (linear fbm), the mean part rho integral(env)
 * is its closed form and only the noise is integrated. Rays are cut where
 * the computed tau reaches 60 (T < 1e-26): the rest cannot show.
 *
 * Lattice coordinates are formed in long double from the ray's origin and
 * reduced modulo the noise period 256, so a fraction inside a cell keeps
 * its absolute precision wherever the camera and the offset are.
 *
 * This file holds the models themselves (keys, state, tau's dispatch
 * between the methods, what the reference integrator sees); noise_fog.h
 * lists the files that hold the integrators. */
#include "noise_fog.h"

#include <stdio.h>

enum {
    K_DENSITY, K_VISIBILITY, K_SCALE, K_OCTAVES, K_LACUNARITY, K_GAIN, K_CONTRAST, K_OFFSET,
    K_VELOCITY, K_SEED, K_FALLOFF, K_BASE, K_MIN, K_MAX, K_METHOD, K_TOL, K_TTOL, K_STEPS,
    K_LOD, K_AXES,
    K_PIECES
};

static const char *const noise_keys[] = {
    "density", "visibility", "scale", "octaves", "lacunarity", "gain", "contrast", "offset",
    "velocity", "seed", "falloff", "base", "min", "max", "method", "tol", "ttol", "steps",
    "lod", NULL
};
static const char *const separable_keys[] = {
    "density", "visibility", "scale", "octaves", "lacunarity", "gain", "contrast", "offset",
    "velocity", "seed", "falloff", "base", "min", "max", "method", "tol", "ttol", "steps",
    "lod", "axes",
    "pieces", NULL
};

/* p[] while parsing (finish() moves everything into the state in arr). */
enum {
    P_RHO = 0, P_SCALE = 3, P_OCTAVES, P_LACUNARITY, P_GAIN, P_CONTRAST, P_OFFSET = 8,
    P_VELOCITY = 11, P_SEED = 14, P_FALLOFF, P_BASE, P_MIN = 17, P_MAX = 20, P_METHOD = 23,
    P_TOL, P_STEPS, P_AXES, P_PIECES, P_TTOL, P_LOD
};
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
    case K_LOD:
        if (strcmp(val, "point") && strcmp(val, "pixel"))
            return ef_fail(err, "fog spec '%s': lod='%s' is not point (the density at every "
                           "point, the default) or pixel (octaves finer than the camera's "
                           "pixel footprint fade out with distance)", c->spec, val);
        p[P_LOD] = !strcmp(val, "pixel");
        return 0;
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
void ef_nz_gauss_legendre(int n, double *x, double *w)
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
    const int lod = (c->seen & (1u << K_LOD)) && c->p[P_LOD] > 0;
    if (lod && sep)
        return ef_fail(err, "fog spec '%s': lod=pixel applies to the noise model only; "
                       "noise-separable has no pixel filter (leave lod out)", c->spec);
    if (lod && method != M_ADAPTIVE)
        return ef_fail(err, "fog spec '%s': lod=pixel only applies to method=adaptive (the "
                       "default)", c->spec);

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
    if (lod && s.clamp)
        return ef_fail(err, "fog spec '%s': lod=pixel needs |contrast| <= %.6g, where the clamp "
                       "max(0, 1 + c fbm) never binds (the clamp's statistics know only "
                       "unfiltered octaves); leave lod out for patchy fog", c->spec,
                       1 / EF_NOISE_BOUND);
    s.lod = lod;
    for (int i = 0; i < EF_FBM_MAX_OCTAVES; ++i)
        s.lod_S[i] = INFINITY;   /* until a camera is bound: every octave whole */
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
        ef_nz_gauss_legendre(n, s.glx[n], s.glw[n]);

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
    const size_t nhash = GRID_HASH_WORDS / 2 + ef_nz_ladders_words();
    const size_t nclamp = !sep && s.clamp ? ef_clamp_tables_size(octaves) : 0;
    /* noise-separable, methods that evaluate the factors point by point:
     * each factor octave's cell polynomials (ef_nz_factor_octave) */
    const size_t nfpoly = sep && !mp ? (size_t) s.naxes * (size_t) octaves * 256 * 7 : 0;
    double *arr = calloc(head + ntab + nmerged + nhash + nclamp + nfpoly, sizeof *arr);
    if (!arr)
        return ef_fail(err, "fog spec '%s': out of memory", c->spec);
    s.tab_off = ntab ? (int) head : 0;
    if (ntab)
        ef_nz_build_tables(&s, arr + head);
    if (mp) {
        size_t at = head + ntab;
        s.merged = 1;
        for (int k = 0; k < s.naxes; ++k) {
            const int a = s.axis[k];
            while ((uintptr_t) (arr + at) % 64)   /* each record on one cache line */
                ++at;
            s.m_off[a] = (int) at;
            s.mpa[a] = ef_nz_build_merged(&s, a, arr + at, (int) mp, &s.mtotal[a]);
            if (!s.mpa[a]) {
                free(arr);
                return ef_fail(err, "fog spec '%s': out of memory", c->spec);
            }
            at += MERGED_SIZE(mp);
        }
    }
    s.hash_off = (int) (head + ntab + nmerged);
    ef_nz_grid_tables((uint32_t *) (void *) (arr + s.hash_off));
    s.ladder_off = s.hash_off + GRID_HASH_WORDS / 2;
    ef_nz_ladders_fill(arr + s.ladder_off);
    if (nfpoly) {
        for (int k = 0; k < s.naxes; ++k)
            s.fslot[s.axis[k]] = k;
        s.fpoly_off = (int) (head + ntab + nmerged + nhash + nclamp);
        ef_nz_factor_tables(&s, arr + s.fpoly_off);
        ef_nz_sep_stats(&s, arr + s.fpoly_off);
    }
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
    c->narr = (int) (head + ntab + nmerged + nhash + nclamp + nfpoly);
    return 0;
}

/* Looks up everything about the camera at org that every ray of the frame
 * repeats: the lattice lines' starts and each octave's noise there, or
 * with the merged tables its point in each table and its envelope
 * height's exponential. Rays from elsewhere miss the cache and compute
 * their own; a hit returns the values a lookup would (the span's lanes,
 * serving a far end inside the camera's own piece from that piece's
 * polynomial, may round the last bit differently from the general path
 * there). */
static void bind_noise(ef_fog_component *c, const double org[3])
{
    nstate *s = (nstate *) (void *) c->arr;
    s->cam = s->cam_lines = 0;
    /* lod=pixel: where octave i starts to fade (its cell four footprints
     * wide), from the camera's pixel footprint */
    s->spread = s->lod && c->spread > 0 && isfinite(c->spread) ? c->spread : 0;
    for (int i = 0; i < s->fbm.octaves; ++i)
        s->lod_S[i] = s->spread > 0 ? s->scale / s->fbm.freq[i] / (4 * s->spread) : INFINITY;
    if (!s->merged)
        ef_nz_bind_lines(s, org);
    else
        ef_nz_bind_merged(c, org);
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
        ef_nz_preint_fast(c, s, r, tau, info);
        return;
    }
    if (!info)
        info = &dummy;
    memset(info, 0, sizeof *info);
    long double t0, t1;
    if (!(s->rho_max > 0) || !(r->dist > 0) || !ef_nz_clip_box(s, r, &t0, &t1) ||
        (c->cancel && atomic_load_explicit(c->cancel, memory_order_relaxed)))
        return;
    rayc R;
    ef_nz_ray_setup(s, r, &R);
    const int sky = isinf(t1);
    if (sky && !(s->k > 0 && R.hs > 0)) {
        /* Nothing lets the ray out of the fog: every channel with density
         * is opaque (the clamp's zeros cannot cover a whole infinite ray). */
        for (int k = 0; k < 3; ++k)
            tau[k] = s->rho[k] > 0 ? INFINITY : 0;
        return;
    }
    if (ef_nz_env_overflows(s, (double) R.h0, (double) R.hs, (double) t0, (double) t1)) {
        for (int k = 0; k < 3; ++k)
            tau[k] = s->rho[k] > 0 ? INFINITY : 0;
        return;
    }
    /* lod=pixel: the fast path fades octaves along rays from the bound
     * camera under ttol; any other ray (a light's, or under tol=) takes the
     * faded density point by point, piece by piece (shape_at). */
    const int lod_general =
        s->spread > 0 &&
        !(r->org[0] == s->cam_org[0] && r->org[1] == s->cam_org[1] && r->org[2] == s->cam_org[2] &&
          s->method == M_ADAPTIVE && s->ttol > 0 &&
          (s->k == 0 || (isfinite(R.kh0) && isfinite(R.khs))));
    const int linear = !s->separable && !s->clamp && !lod_general;
    /* the clamped noise model on the adaptive fast path: its linear part
     * plus the clamp's share (clamp_part) */
    const int clamp_fast = !s->separable && s->clamp && s->method == M_ADAPTIVE && s->ttol > 0;
    double unit = 0, err = 0, tail = 0;  /* tau / rho, its error, the dropped tail's bound */
    double stop_err[3];                  /* past the ttol stop: the error output (stopped) */
    int stopped = 0;
    long double tend = t1;
    if (sky) {
        if (s->method == M_ADAPTIVE)
            tend = ef_nz_tail_end(&R, t0, 0, stol / 8);
        else if (s->method == M_EXACT)
            tend = ef_nz_tail_end(&R, t0, 1e-16, 0);
        else
            tend = ef_nz_tail_end(&R, t0, 1e-6, 0);
        const long double a = s->k * R.hs, e_end = env_at(&R, tend);
        tail = (double) (shape_bound(s) * e_end / a);
        if (linear || clamp_fast)
            tail -= (double) (e_end / a);   /* the mean part is exact to infinity */
    }
    const int opaque = ef_nz_opaque_cut(&R, t0, &tend);
    /* The segment walk plans in double: not where k h0 or k hs overflow (a
     * falloff near DBL_MAX), which the general path below handles. */
    if ((linear || clamp_fast) && s->method == M_ADAPTIVE && s->ttol > 0 &&
        (s->k == 0 || (isfinite(R.kh0) && isfinite(R.khs)))) {
        double errk[3];
        unit = ef_nz_adaptive_linear(&R, t0, tend, t1, opaque, tail, info, errk);
        if (unit < 0)
            unit = 0;   /* rounding below an exactly zero density */
        for (int k = 0; k < 3; ++k) {
            tau[k] = s->rho[k] * unit;
            info->err[k] = errk[k];
        }
        info->evals = R.evals;
        info->cells = R.cells;
        /* the node plans' errors are estimates; dropped octaves, the
         * clamp's share and the stop's lower value come from statistics */
        info->kind = info->dropped > 0 || info->over || s->clamp || R.stopped ? EF_ERR_STAT
                                                                               : EF_ERR_QUAD;
        return;
    }
    const double L = (double) (tend - t0);
    const double envmax = (double) fmaxl(env_at(&R, t0), env_at(&R, tend));
    double mean = 0;
    if (linear)
        mean = (double) ef_nz_env_integral(s, R.h0, R.hs, t0, opaque ? tend : t1);
    const double tol = s->ttol > 0 && s->method == M_ADAPTIVE && !(tol_over > 0)
                           ? ef_nz_ttol_budget(&R, t0, tend, L, envmax, linear) : stol;
    /* noise-separable under ttol where the clamp cannot bind: its own
     * walk (noise_sep.c) */
    int done = 0;
    if (s->separable && !s->clamp && s->fpoly_off && s->method == M_ADAPTIVE && s->ttol > 0 &&
        !(tol_over > 0) && (s->k == 0 || (isfinite(R.kh0) && isfinite(R.khs)))) {
        double est;
        long double cut_at, tfast = tend;
        /* where the ray has surely stopped: its lower value (the least
         * factors over the mean fog) past the stop */
        const double cut_unit = ef_nz_tau_stop(s) / ef_nz_rho_min(s);
        const int surely = ef_nz_sure_cut(&R, t0, ef_nz_tau_stop(s), &tfast);
        const double v = ef_nz_separable_fast(&R, t0, tfast, tol, cut_unit, &est, &cut_at,
                                              &info->dropped, &info->over);
        done = 1;
        if (cut_at >= 0 || surely) {
            const double lower = cut_at >= 0 ? v - est : fmax(v - est, cut_unit);
            unit = ef_nz_stop_report(s, lower, (double) ef_nz_env_integral(s, R.h0, R.hs, t0, t1),
                                     stop_err);
            stopped = 1;
        } else {
            unit = v;
            err = est + tail;
        }
    }
    if (!done) switch (s->method) {
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
            if (isfinite(R.kh0) && isfinite(R.khs) && ef_nz_seg_planner_init(&R, &SP) &&
                SP.sp[s->fbm.octaves - 1] * L < 0x1p24)
                ef_nz_plan_segment(&R, &SP, L, envmax, envmax * envmax, NULL, NULL, tol, &P);
            else
                ef_nz_plan_octaves(&R, L, envmax, tol, &P);
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
                                 ? EF_NOISE_BOUND * (double) ef_nz_env_integral(s, R.h0, R.hs, t0, tend)
                                 : envmax * ef_nz_line_est(s, i, L, 3));
            }
        }
        if (over && !linear) {
            unit = ef_nz_march(&R, t0, tend, MARCH_FALLBACK);
            err = ef_nz_march_bound(&R, t0, tend, MARCH_FALLBACK, unit) + tail;
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
        /* Under ttol (the default) the ray stops where T is below ttol/4
         * in every channel, as the fast path does: nothing past it can
         * move T by more; else at OPAQUE_TAU. */
        const int ttol_stop = s->method == M_ADAPTIVE && s->ttol > 0 && !(tol_over > 0);
        double cut_tau = OPAQUE_TAU;
        if (ttol_stop) {
            /* the stop, chunk by chunk at its scale, where the ray surely
             * reaches it (the shape's least value over the mean fog);
             * elsewhere the chunks stay OPAQUE_TAU's, as the stop cannot
             * pay for the pieces their ends split */
            double wsum = 0;
            for (int i = 0; i < s->fbm.octaves; ++i)
                wsum += s->fbm.weight[i];
            const double f = 1 - fabs(s->contrast) * EF_NOISE_BOUND * wsum;
            const double least = f > 0 ? pow(f, s->separable ? s->naxes : 1) : 0;
            const double tau_stop = ef_nz_tau_stop(s);
            if (least * ef_nz_rho_min(s) *
                    (double) ef_nz_env_integral(s, R.h0, R.hs, t0, tend) >= tau_stop)
                cut_tau = tau_stop;
        }
        const long double per = cut_tau / 2 / (s->rho_max * shape_bound(s));
        const int chunked = (double) ef_nz_env_integral(s, R.h0, R.hs, t0, tend) > (double) per * 2;
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
            long double cb = chunked ? ef_nz_env_reach(&R, ca, probe >= 0 ? per / 4 : per) : tend;
            if (!(cb < tend) || !(cb > ca))
                cb = tend;
            if (linear) {
                for (int i = 0; i < s->fbm.octaves; ++i) {
                    const int q = s->method == M_EXACT ? (s->k == 0 ? 9 : 0) : P.q[i];
                    if (over >> i & 1 || (probe >= 0 && i != probe))
                        continue;
                    if (s->method == M_ADAPTIVE && P.nu[i] > 0)
                        kadd(&noise, s->fbm.weight[i] *
                                         ef_nz_octave_grid_any(&R, i, P.nu[i], ca, cb, &ends[i]));
                    else if (q || s->method == M_EXACT)
                        kadd(&noise, s->fbm.weight[i] * ef_nz_octave_integral(&R, i, q, ca, cb, &e));
                }
            } else {
                kadd(&noise, s->method == M_EXACT
                                 ? ef_nz_full_integral(&R, s->separable ? 10 : 9, s->separable ? 14 : 13,
                                                 ca, cb, 0, &e)
                                 : ef_nz_full_integral(&R, 3, 6, ca, cb, tol / 2 / L / s->rho_max, &e));
            }
            ca = cb;
            if (probe >= 0)
                rest = fabs(s->contrast) * envmax * ef_nz_rest_estimate(s, probe, (double) (ca - t0));
            const double sofar = linear ? (double) ef_nz_env_integral(s, R.h0, R.hs, t0, ca) +
                                              s->contrast * kval(&noise) - rest
                                        : kval(&noise);
            if (ca < t1 && chunked && (sofar - (linear ? 0 : e)) * ef_nz_rho_min(s) >= cut_tau) {
                cut = 1;
                break;
            }
        }
        if (probe >= 0 && !cut)
            for (int i = 0; i < s->fbm.octaves; ++i)
                if (i != probe && !(over >> i & 1) && P.q[i])
                    kadd(&noise, s->fbm.weight[i] *
                                     (P.nu[i] > 0
                                          ? ef_nz_octave_grid_any(&R, i, P.nu[i], t0, tend, &ends[i])
                                          : ef_nz_octave_integral(&R, i, P.q[i], t0, tend, &e)));
        if (cut) {
            tend = ca;
            mean = linear ? (double) ef_nz_env_integral(s, R.h0, R.hs, t0, ca) - rest : 0;
        }
        unit = linear ? mean + s->contrast * kval(&noise) : kval(&noise);
        if (cut && cut_tau < OPAQUE_TAU) {
            /* stopped under ttol, as the fast path stops: the lower value
             * reached (the pieces less their error), the mean fog to the
             * end as the estimate */
            unit = ef_nz_stop_report(s, linear ? unit : unit - e,
                                     (double) ef_nz_env_integral(s, R.h0, R.hs, t0, t1), stop_err);
            stopped = 1;
        }
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
        unit = ef_nz_march(&R, t0, tend, s->steps);
        err = ef_nz_march_bound(&R, t0, tend, s->steps, unit) + tail;
        break;
    }
    default: { /* M_PREINT */
        if (s->merged) {
            unit = ef_nz_preintegrated_merged(c, s, r, (double) R.h0, (double) R.hs, (double) t0,
                                        (double) tend, s->pieces);
            R.evals += 2.0 * s->pieces * s->naxes;
            R.cells += (double) s->pieces * s->naxes;
        } else {
            unit = ef_nz_preintegrated(c, &R, t0, tend, s->pieces);
        }
        /* The bound (preint_bound). */
        err = ef_nz_preint_bound(s, (double) R.h0, (double) R.hs, (double) t0, (double) tend, unit) +
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
        /* Past the cut the true T lies in [0, T]: |dT| <= T = T expm1(ln 2);
         * past the ttol stop, ef_nz_stop_report's error. */
        info->err[k] = stopped ? stop_err[k] : err < 0 ? (s->rho[k] > 0 ? LN2 : 0) : s->rho[k] * err;
    }
    info->evals = R.evals;
    info->cells = R.cells;
    /* exact, steps and preintegrated: bounds; the separable walk's
     * quadrature is bounded too; the general adaptive walk's rule pairs
     * and node plans are estimates; dropped octaves and the ttol stop's
     * lower value come from statistics */
    if (s->method == M_ADAPTIVE)
        info->kind = info->dropped > 0 || info->over || stopped ? EF_ERR_STAT
                     : done ? EF_ERR_BOUND : EF_ERR_QUAD;
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
            ef_nz_preint_span(c, s, r + j, n - j < ONE_SPAN ? n - j : ONE_SPAN, acc + j);
        return;
    }
    const int fast = s->method == M_PREINT && s->merged;
    for (int j = 0; j < n; ++j) {
        double t[3] = { 0, 0, 0 };
        if (fast)
            ef_nz_preint_fast(c, s, &r[j], t, NULL);
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
        double f = 0, dist = 0;
        if (s->spread > 0) {   /* lod=pixel: the distance from the bound camera */
            long double d2 = 0;
            for (int a = 0; a < 3; ++a)
                d2 += (v[a] - s->cam_org[a]) * (v[a] - s->cam_org[a]);
            dist = (double) sqrtl(d2);
        }
        for (int i = 0; i < N; ++i) {
            int64_t X[3];
            double fr[3];
            for (int a = 0; a < 3; ++a)
                ef_nz_split_ld(s->fbm.freq[i] * q[a] + (long double) i * ef_fbm_offset[a], &X[a],
                         &fr[a]);
            ef_noise_cell nc;
            ef_noise_cell_at(X[0], X[1], X[2], &nc);
            const double phi = s->spread > 0 ? lod_phi(dist / s->lod_S[i]) : 1;
            f += s->fbm.weight[i] * phi * ef_noise_cell_eval(&nc, fr[0], fr[1], fr[2]);
        }
        x[0] = 1 + (long double) s->contrast * f;
        return 1;
    }
    for (int k = 0; k < s->naxes; ++k) {
        const int a = s->axis[k];
        double f = 0;
        for (int i = 0; i < N; ++i)
            f += s->fbm.weight[i] *
                 ef_nz_factor_octave_ld(s, a, i, s->fbm.freq[i] * q[a] +
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
    if (s->method != M_EXACT || !(s->rho_max > 0) || !(r->dist > 0) || !ef_nz_clip_box(s, r, &t0, &t1))
        return 0;
    rayc R;
    ef_nz_ray_setup(s, r, &R);
    long double tend = t1;
    if (isinf(t1)) {
        if (!(s->k > 0 && R.hs > 0))
            return 0;   /* opaque: nothing is walked */
        tend = ef_nz_tail_end(&R, t0, 1e-16, 0);
    }
    if (ef_nz_env_overflows(s, (double) R.h0, (double) R.hs, (double) t0, (double) t1))
        return 0;
    ef_nz_opaque_cut(&R, t0, &tend);
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
    if (!(s->rho_max > 0) || !(r->dist > 0) || !ef_nz_clip_box(s, r, &t0, &t1))
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
