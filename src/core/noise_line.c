/* A ray through the noise's lattices (fog_noise.c's family; noise_fog.h):
 * each octave's lattice coordinate along the ray in long double reduced
 * modulo the period, the ray's set-up (box, envelope, lines from the
 * bound camera), the density's shape at a point, the envelope's closed
 * forms (its integral, where it reaches a depth, where a sky ray may stop,
 * where the fog is certainly opaque). Pure: no I/O, no globals. */
#include "noise_fog.h"

/* q_a at the ray's origin and its rate per unit t, in long double. */
void ef_nz_q_line(const nstate *s, const double org[3], const double dir[3], int a,
                  long double *q0, long double *dq)
{
    const long double sh = (long double) s->seed * ef_noise_seed_dir[a];
    *q0 = (((long double) org[a] - s->offset[a]) - (long double) s->velocity[a] * s->time) /
              s->scale + sh;
    *dq = (long double) dir[a] / s->scale;
}

/* Octave i's coordinate on axis a along the ray. */
lin ef_nz_octave_line(const nstate *s, int i, long double q0, long double dq, int a)
{
    const long double f = s->fbm.freq[i];
    const long double b = mod256(f * q0 + (long double) i * ef_fbm_offset[a]), d = f * dq;
    return (lin) { b, d, (double) b, (double) d };
}

/* Splits a coordinate into its cell index (& 255) and the fraction in the
 * cell, both from one reduction modulo 256 (the noise's period). */
void ef_nz_split_ld(long double u, int64_t *cell, double *frac)
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

/* Clips [0, len] to the box; returns 0 when the ray misses it. */
int ef_nz_clip_box(const nstate *s, const ef_ray *r, long double *t0, long double *t1)
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

void ef_nz_ray_setup(const nstate *s, const ef_ray *r, rayc *R)
{
    R->s = s;
    R->evals = R->cells = 0;
    R->cam = 0;
    R->stopped = 0;
    memcpy(R->org, r->org, sizeof R->org);
    memcpy(R->dir, r->dir, sizeof R->dir);
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
            ef_nz_q_line(s, r->org, r->dir, a, &q0, &dq);
        for (int i = 0; i < N; ++i) {
            lin l;
            if (hit) {   /* octave_line with the camera's reduced start */
                l.b = s->cam_b[a][i];
                l.d = (long double) s->fbm.freq[i] * dq;
                l.bd = (double) l.b;
                l.dd = (double) l.d;
            } else {
                l = ef_nz_octave_line(s, i, q0, dq, a);
            }
            if (s->separable)
                R->u[a * N + i] = l;
            else
                R->u[3 * i + a] = l;
        }
    }
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
double ef_nz_factor_octave_ld(const nstate *s, int a, int i, long double u)
{
    int64_t x;
    double f;
    ef_nz_split_ld(u, &x, &f);
    return factor_octave_at(s, a, i, x, f);
}

/* Octave i of the factor along axis a at its coordinate u: from the cell's
 * polynomial where the tables are built (a fifth of the 3-D noise's
 * work, equal to it to rounding), else the noise itself. */
double ef_nz_factor_octave(const nstate *s, int a, int i, double u)
{
    int64_t x;
    double f;
    ef_noise_split(u, &x, &f);
    if (s->fpoly_off) {
        const double *p = (const double *) (const void *) s + s->fpoly_off +
                          (((size_t) s->fslot[a] * (size_t) s->fbm.octaves + (size_t) i) * 256 +
                           (size_t) (x & 255)) * 7;
        return cell_poly_at(p, f);
    }
    return factor_octave_at(s, a, i, x, f);
}

/* max(0, 1 + c fbm) of the noise model, or the product of the separable
 * factors, at t (without rho and the envelope). */
double ef_nz_shape_at(rayc *R, long double t)
{
    const nstate *s = R->s;
    const int N = s->fbm.octaves;
    if (!s->separable) {
        double f = 0;
        if (s->spread > 0) {
            /* lod=pixel: each octave faded by the distance from the camera */
            double d2 = 0;
            for (int a = 0; a < 3; ++a) {
                const double x = R->org[a] + (double) t * R->dir[a] - s->cam_org[a];
                d2 += x * x;
            }
            const double dist = sqrt(d2);
            for (int i = 0; i < N; ++i)
                f += s->fbm.weight[i] * lod_phi(dist / s->lod_S[i]) * octave_at(R, i, t);
        } else {
            for (int i = 0; i < N; ++i)
                f += s->fbm.weight[i] * octave_at(R, i, t);
        }
        const double v = 1 + s->contrast * f;
        return v > 0 ? v : 0;
    }
    double prod = 1;
    for (int k = 0; k < s->naxes; ++k) {
        const int a = s->axis[k];
        double f = 0;
        for (int i = 0; i < N; ++i)
            f += s->fbm.weight[i] *
                 ef_nz_factor_octave(s, a, i, R->u[a * N + i].bd + (double) t * R->u[a * N + i].dd);
        R->evals += N;
        const double v = 1 + s->contrast * f;
        prod *= v > 0 ? v : 0;
    }
    return prod;
}

/* ---- the closed-form mean part: integral of env over [t0, t1] ---- */

/* integral_{t0}^{t1} e^(-k (h0 + hs t)) dt; t1 may be infinite (the caller
 * only asks when the envelope decays along the ray). */
long double ef_nz_env_integral(const nstate *s, long double h0, long double hs, long double t0,
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

/* ---- the component's tau ---- */

/* Where to stop on a ray whose envelope decays (k hs > 0): past T the
 * density's integral is at most B e^(-k h(T)) / (k hs) <= rel of the mean
 * part's from t0 (or, with abs > 0, at most abs in tau). */
long double ef_nz_tail_end(const rayc *R, long double t0, double rel, double abs)
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
/* The smallest non-zero density of the three channels. */
double ef_nz_rho_min(const nstate *s)
{
    double lo = INFINITY;
    for (int k = 0; k < 3; ++k)
        if (s->rho[k] > 0 && s->rho[k] < lo)
            lo = s->rho[k];
    return lo;
}

/* The t past t0 where the envelope's integral from t0 reaches need
 * (INFINITY if it never does). */
long double ef_nz_env_reach(const rayc *R, long double t0, long double need)
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
int ef_nz_opaque_cut(const rayc *R, long double t0, long double *tend)
{
    return ef_nz_sure_cut(R, t0, OPAQUE_TAU, tend);
}

/* Moves *tend to where that lower bound reaches tau, if sooner; 1 if it cut. */
int ef_nz_sure_cut(const rayc *R, long double t0, double tau, long double *tend)
{
    const nstate *s = R->s;
    const double lo1 = 1 - fabs(s->contrast) * EF_NOISE_BOUND;
    if (!(lo1 > 0))
        return 0;
    const double rho_lo = ef_nz_rho_min(s);
    const long double need = tau / (rho_lo * pow(lo1, s->separable ? s->naxes : 1));
    const long double tc = ef_nz_env_reach(R, t0, need);
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
int ef_nz_env_overflows(const nstate *s, double h0, double hs, double t0, double t1)
{
    if (!(s->k > 0))
        return 0;
    const double hlow = hs > 0 ? h0 + hs * t0 : hs < 0 ? h0 + hs * t1 : h0;
    return !(-s->k * hlow < 690);
}

/* The camera at org for the noise model: each octave's reduced lattice
 * coordinate there, and its noise and gradient (the grid's end terms at
 * t = 0), so the frame's rays start from them. */
void ef_nz_bind_lines(nstate *s, const double org[3])
{
    for (int a = 0; a < 3; ++a) {
        long double q0, dq;
        ef_nz_q_line(s, org, (const double[3]) { 0, 0, 0 }, a, &q0, &dq);
        for (int i = 0; i < s->fbm.octaves; ++i)
            s->cam_b[a][i] = ef_nz_octave_line(s, i, q0, dq, a).b;
        s->cam_org[a] = org[a];
    }
    for (int i = 0; i < s->fbm.octaves; ++i) {
        const double x[3] = { (double) s->cam_b[0][i], (double) s->cam_b[1][i],
                              (double) s->cam_b[2][i] };
        for (int a = 0; a < 3; ++a) {
            const double e[3] = { a == 0, a == 1, a == 2 };
            s->cam_n[i] = ef_nz_noise_dval(grid_hash_table(s), x, e, &s->cam_g[i][a]);
        }
    }
    s->cam_lines = 1;
}
